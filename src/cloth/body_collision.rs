//! Collision of the cloth with a moving body given as a triangle mesh (a
//! skinned avatar, one pose per frame).
//!
//! Per frame: the body moves linearly from its previous pose to the new one
//! over the frame's substeps. A [`AabbTree`] over the triangles is refitted to
//! the boxes the triangles sweep during the frame; every cloth vertex gathers
//! the triangles whose swept box meets its own predicted sweep (`x` to
//! `x + v dt`, widened by the thickness and a slack), once per frame. Each
//! substep a vertex then looks for its closest point on the body *at that
//! substep's time* among its candidates only, and is pushed out to the
//! thickness along the outside direction; friction acts on its motion
//! relative to the body surface point, so a moving limb drags cloth along.
//! A vertex that strays outside the box it gathered for queries the tree
//! directly (counted in [`BodyStats::fallbacks`]), and so does a cloth edge
//! with such an end.
//!
//! Inside or outside is decided by the angle-weighted pseudo-normal of the
//! closest feature (face, edge or vertex; Bærentzen and Aanæs 2005), which
//! is exact for a closed, consistently wound mesh, also at edges and corners
//! where a face normal alone misjudges. Because contacts are resolved every
//! substep against the body at that substep's pose, a limb moving at speed
//! `s` sinks at most `s h` (h the substep) into the cloth before it is
//! pushed out: 8 mm at 10 m/s with 20 substeps at 60 Hz, well below a limb's
//! radius, so the nearest feature stays on the side the vertex came from.

use glam::Vec3;

use super::bvh::{Aabb, AabbTree};
use super::self_collision::{MAX_PAIRS_PER_VERTEX, cap_and_sort, gathered_side, pairs_of, track_side};

/// A body mesh moving from pose to pose, one pose per frame.
#[derive(Clone, Debug)]
pub struct BodyMesh {
    triangles: Vec<[u32; 3]>,
    /// Triangle across edge `k` (from corner `k` to `k + 1`), `u32::MAX` on a border.
    adjacent: Vec<[u32; 3]>,
    start: Vec<Vec3>,
    end: Vec<Vec3>,
    /// Face and angle-weighted vertex normals at the start and end pose.
    face_n: [Vec<Vec3>; 2],
    vert_n: [Vec<Vec3>; 2],
    boxes: Vec<Aabb>,
    tree: AabbTree,
    /// Per-vertex candidate triangles (CSR) and the box they were gathered for.
    cand_start: Vec<u32>,
    cand: Vec<u32>,
    query: Vec<Aabb>,
    /// Per cloth edge, the candidate triangles (CSR) for edge contacts.
    edge_cand_start: Vec<u32>,
    edge_cand: Vec<u32>,
    /// Per cloth vertex, its distance to the body at this substep's vertex contact, or a lower
    /// bound (its candidates' reach) where none is that near; 0 for a pinned vertex; infinite
    /// until the frame's first vertex contacts.
    clearance: Vec<f32>,
    /// Per cloth vertex, its last distance this frame to the nearest of its candidates, found
    /// outside the body: `(distance, where the vertex was, s)`; `None` until found.
    last_outside: Vec<Option<(f32, Vec3, f32)>>,
    /// How far any body vertex moves over this frame: with `last_outside`, a lower bound on a
    /// vertex's distance later in the frame.
    body_travel: f32,
    /// Tree over the cloth triangles (built on the first frame), their boxes,
    /// and the `(body vertex, cloth triangle, side)` pairs of this frame and
    /// the last, sorted.
    cloth_tree: Option<AabbTree>,
    cloth_boxes: Vec<Aabb>,
    vt_pairs: Vec<(u32, u32, f32)>,
    vt_previous: Vec<(u32, u32, f32)>,
    pub stats: BodyStats,
}

/// Seam groups welded into one point each, as a contact must move them: per vertex its group
/// (`u32::MAX` when not sewn).
pub(crate) struct Welds<'a> {
    pub group_of: &'a [u32],
    pub groups: &'a [Vec<u32>],
}

impl Welds<'_> {
    fn group(&self, v: usize) -> Option<&[u32]> {
        self.groups.get(self.group_of[v] as usize).map(Vec::as_slice)
    }

    /// The vertices welded into one point with `v`, `v` among them (`v` alone when not sewn).
    pub fn members(&self, v: u32) -> impl Iterator<Item = u32> + '_ {
        let group = self.group(v as usize);
        group.into_iter().flatten().copied().chain(group.is_none().then_some(v))
    }

    /// Whether `v` is sewn to another vertex.
    pub fn is_sewn(&self, v: u32) -> bool {
        self.group(v as usize).is_some()
    }

    /// `w` with each group's vertices carrying the group's inverse mass, 1 / Σ (1 / w): how
    /// hard the group as a whole is to move (zero when one of them is pinned, its mass
    /// infinite).
    pub fn inv_masses(&self, w: &[f32]) -> Vec<f32> {
        let mut out = w.to_vec();
        for g in self.groups {
            let mass: f32 = g.iter().map(|&v| 1.0 / w[v as usize]).sum();
            g.iter().for_each(|&v| out[v as usize] = 1.0 / mass);
        }
        out
    }
}

/// Work counters of the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct BodyStats {
    /// Vertex-triangle candidates gathered.
    pub candidates: usize,
    /// Substep queries of vertices that left their gathered box.
    pub fallbacks: usize,
    /// Substep vertex contacts not looked at: the vertex was too far out to reach the body.
    pub skipped: usize,
    /// Vertices pushed out (summed over substeps).
    pub contacts: usize,
    /// Body-vertex / cloth-triangle pairs gathered.
    pub vertex_pairs: usize,
    /// Body vertices that met more than [`MAX_PAIRS_PER_VERTEX`] cloth triangles and kept
    /// the nearest.
    pub vertex_pairs_capped: usize,
    /// Cloth-edge / body-triangle candidates gathered.
    pub edge_candidates: usize,
    /// Cloth edges pushed off a body edge (summed over substeps).
    pub edge_contacts: usize,
    /// Cloth triangles pushed off a body vertex (summed over substeps).
    pub triangle_contacts: usize,
}

/// The feature of a triangle that holds a closest point.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Feature {
    Vertex(u8),
    /// Edge from corner `k` to corner `k + 1`.
    Edge(u8),
    Face,
}

/// Closest point on triangle `abc` to `p` with its barycentric coordinates
/// and feature (Ericson, Real-Time Collision Detection, 5.1.5).
pub fn closest_point_feature(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> (Vec3, [f32; 3], Feature) {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return (a, [1.0, 0.0, 0.0], Feature::Vertex(0));
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return (b, [0.0, 1.0, 0.0], Feature::Vertex(1));
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        let v = d1 / (d1 - d3);
        return (a + ab * v, [1.0 - v, v, 0.0], Feature::Edge(0));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return (c, [0.0, 0.0, 1.0], Feature::Vertex(2));
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        let w = d2 / (d2 - d6);
        return (a + ac * w, [1.0 - w, 0.0, w], Feature::Edge(2));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        let w = (d4 - d3) / ((d4 - d3) + (d5 - d6));
        return (b + (c - b) * w, [0.0, 1.0 - w, w], Feature::Edge(1));
    }
    let denom = 1.0 / (va + vb + vc);
    let (v, w) = (vb * denom, vc * denom);
    (a + ab * v + ac * w, [1.0 - v - w, v, w], Feature::Face)
}

/// Closest points of segments `ab` and `cd` (Ericson, Real-Time Collision Detection, 5.1.9):
/// their parameters along `ab` and `cd`, and their squared distance.
pub fn segment_closest_params(a: Vec3, b: Vec3, c: Vec3, d: Vec3) -> (f32, f32, f32) {
    let (d1, d2, r) = (b - a, d - c, a - c);
    let (aa, ee, f) = (d1.dot(d1), d2.dot(d2), d2.dot(r));
    let eps = 1e-12;
    let (s, t) = if aa <= eps && ee <= eps {
        (0.0, 0.0)
    } else if aa <= eps {
        (0.0, (f / ee).clamp(0.0, 1.0))
    } else {
        let cc = d1.dot(r);
        if ee <= eps {
            ((-cc / aa).clamp(0.0, 1.0), 0.0)
        } else {
            let bb = d1.dot(d2);
            let denom = aa * ee - bb * bb;
            let mut s = if denom > eps { ((bb * f - cc * ee) / denom).clamp(0.0, 1.0) } else { 0.0 };
            let mut t = (bb * s + f) / ee;
            if t < 0.0 {
                t = 0.0;
                s = (-cc / aa).clamp(0.0, 1.0);
            } else if t > 1.0 {
                t = 1.0;
                s = ((bb - cc) / aa).clamp(0.0, 1.0);
            }
            (s, t)
        }
    };
    (s, t, (a + d1 * s).distance_squared(c + d2 * t))
}

/// Items a thread takes at a time in the frame start's search for candidate triangles.
const CANDIDATE_CHUNK: usize = 512;

/// Distance from `p` to the segment `ab`.
fn point_segment_distance(p: Vec3, a: Vec3, b: Vec3) -> f32 {
    p.distance(super::collider::closest_point_on_segment(p, a, b))
}

/// Face normals (unit) and angle-weighted vertex normals of a mesh.
fn normals(pos: &[Vec3], tris: &[[u32; 3]], face: &mut Vec<Vec3>, vert: &mut Vec<Vec3>) {
    face.clear();
    vert.clear();
    vert.resize(pos.len(), Vec3::ZERO);
    for t in tris {
        let p = t.map(|i| pos[i as usize]);
        let n = (p[1] - p[0]).cross(p[2] - p[0]).normalize_or_zero();
        face.push(n);
        for k in 0..3 {
            let e1 = (p[(k + 1) % 3] - p[k]).normalize_or_zero();
            let e2 = (p[(k + 2) % 3] - p[k]).normalize_or_zero();
            let angle = e1.dot(e2).clamp(-1.0, 1.0).acos();
            vert[t[k] as usize] += n * angle;
        }
    }
}

/// Triangles' boxes a thread takes at a time when the frame starts.
const BOX_CHUNK: usize = 4096;

/// Vertices a thread takes at a time in [`BodyMesh::collide`]; fewer than two chunks run on the
/// calling thread alone.
const CONTACT_CHUNK: usize = 512;

/// One vertex's contact in a substep: its clearance (a lower bound where no body triangle is
/// within its candidates' reach; zero for a pinned vertex, which is not looked at),
/// whether its candidates did not cover it (a fallback search), and where the contact moved it.
struct VertexContact {
    clearance: f32,
    fallback: bool,
    skipped: bool,
    moved_to: Option<Vec3>,
    /// The distance to the nearest candidate, where that is outside the body.
    outside: Option<f32>,
}

/// The body's nearest point: `(signed distance, outward unit normal, triangle, barycentrics)`.
type Nearest = (f32, Vec3, u32, [f32; 3]);

/// A cloth edge's contact with the body: the point at `f` along the edge moves `depth` along
/// `n`, off triangle `t` at `bary`; `wsum` is the two vertices' weight for that point.
struct EdgeContact {
    f: f32,
    n: Vec3,
    depth: f32,
    t: u32,
    bary: [f32; 3],
    wsum: f32,
}

/// What a vertex's distance bound must exceed the thickness by before its contact is skipped
/// (m): vertices resting at the thickness come out a few hundred nanometres either side of it
/// from one computation to the next.
const ROUNDING: f32 = 1e-5;

/// How deep inside the body (m) a cloth vertex beyond its candidates' reach is still pushed
/// back out by the body's nearest surface. Deeper (a limb moved through the cloth, a drape
/// started on another pose) the nearest surface is as likely the wrong one.
const DEEPEST_CONTACT: f32 = 0.02;

impl BodyMesh {
    /// A body at rest in `positions` (metres; triangles CCW seen from outside).
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>) -> Self {
        assert!(triangles.iter().flatten().all(|&i| (i as usize) < positions.len()), "body index out of range");
        let mut half: Vec<(u32, u32, u32, u32)> = Vec::with_capacity(3 * triangles.len());
        for (t, tri) in triangles.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                half.push((a.min(b), a.max(b), t as u32, k as u32));
            }
        }
        half.sort_unstable();
        let mut adjacent = vec![[u32::MAX; 3]; triangles.len()];
        for w in half.windows(2) {
            if w[0].0 == w[1].0 && w[0].1 == w[1].1 {
                adjacent[w[0].2 as usize][w[0].3 as usize] = w[1].2;
                adjacent[w[1].2 as usize][w[1].3 as usize] = w[0].2;
            }
        }
        let boxes: Vec<Aabb> = triangles.iter().map(|t| Aabb::from_points(&t.map(|i| positions[i as usize]))).collect();
        let tree = AabbTree::build(&boxes);
        let mut body = BodyMesh {
            triangles,
            adjacent,
            start: positions.clone(),
            end: positions,
            face_n: [Vec::new(), Vec::new()],
            vert_n: [Vec::new(), Vec::new()],
            boxes,
            tree,
            cand_start: Vec::new(),
            cand: Vec::new(),
            query: Vec::new(),
            edge_cand_start: Vec::new(),
            edge_cand: Vec::new(),
            clearance: Vec::new(),
            last_outside: Vec::new(),
            body_travel: 0.0,
            cloth_tree: None,
            cloth_boxes: Vec::new(),
            vt_pairs: Vec::new(),
            vt_previous: Vec::new(),
            stats: BodyStats::default(),
        };
        let [f0, f1] = &mut body.face_n;
        let [v0, v1] = &mut body.vert_n;
        normals(&body.end, &body.triangles, f1, v1);
        f0.clone_from(f1);
        v0.clone_from(v1);
        body
    }

    /// The body as a [`crate::mesh::Mesh`] gives it (a node's collision input).
    pub fn from_mesh(mesh: &crate::mesh::Mesh) -> Self {
        let tris = mesh.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        BodyMesh::new(mesh.positions.clone(), tris)
    }

    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
    /// The last frame's `(body vertex, cloth triangle, side)` pairs: the sides the next frame
    /// keeps.
    pub(crate) fn sides(&self) -> &[(u32, u32, f32)] {
        &self.vt_pairs
    }

    /// Puts back the sides a saved cloth's last frame recorded.
    pub(crate) fn set_sides(&mut self, sides: &[(u32, u32, f32)]) {
        self.vt_pairs = sides.to_vec();
    }

    /// The pose at the end of the last (or coming) frame.
    pub fn positions(&self) -> &[Vec3] {
        &self.end
    }

    /// Sets the pose the body reaches at the end of the next frame; it moves
    /// there linearly from the current pose over that frame.
    pub fn move_to(&mut self, positions: &[Vec3]) {
        assert_eq!(positions.len(), self.end.len(), "a body pose needs one position per body vertex");
        self.end.copy_from_slice(positions);
        let [_, f1] = &mut self.face_n;
        let [_, v1] = &mut self.vert_n;
        normals(&self.end, &self.triangles, f1, v1);
    }

    /// Refits the tree to the frame's sweep and gathers each free vertex's
    /// candidate triangles. `radius` is the thickness plus slack.
    #[allow(clippy::too_many_arguments)] // the cloth's state, as the simulator keeps it
    pub(crate) fn begin_frame(
        &mut self,
        x: &[Vec3],
        v: &[Vec3],
        inv_mass: &[f32],
        cloth_triangles: &[[u32; 3]],
        cloth_edges: &[[u32; 2]],
        dt: f32,
        thickness: f32,
        radius: f32,
    ) {
        self.stats = BodyStats::default();
        let (triangles, start, end) = (&self.triangles, &self.start, &self.end);
        crate::core::parallel::for_each_chunk(&mut self.boxes, BOX_CHUNK, 0, |chunk, out| {
            for (j, out) in out.iter_mut().enumerate() {
                let [a, b, c] = triangles[chunk * BOX_CHUNK + j].map(|i| i as usize);
                *out = Aabb::from_points(&[start[a], start[b], start[c]])
                    .union(Aabb::from_points(&[end[a], end[b], end[c]]));
            }
        });
        self.tree.refit(&self.boxes);
        self.body_travel = self.start.iter().zip(&self.end).map(|(a, b)| a.distance(*b)).fold(0.0, f32::max);
        self.last_outside.clear();
        self.last_outside.resize(x.len(), None);
        let all = self.tree.bounds();
        self.query.clear();
        // Predicted sweep, a little longer than the velocity says.
        self.query.extend((0..x.len()).map(|i| Aabb::from_points(&[x[i], x[i] + v[i] * (1.25 * dt)]).inflate(radius)));
        let (tree, boxes, query) = (&self.tree, &self.boxes, &self.query);
        crate::core::parallel::csr_in_chunks(
            x.len(),
            CANDIDATE_CHUNK,
            &mut self.cand_start,
            &mut self.cand,
            |i, cand| {
                let q = query[i];
                if inv_mass[i] > 0.0 && q.overlaps(&all) {
                    tree.query(&q, |t| {
                        if boxes[t as usize].overlaps(&q) {
                            cand.push(t)
                        }
                    });
                }
            },
        );
        self.stats.candidates = self.cand.len();
        // Edges: the union of their ends' sweeps. Only edges with an end near the body can
        // cross it between their ends (a chord sags L^2 / 8R, under the slack for the
        // edge lengths a body-sized garment has).
        let cand_start = &self.cand_start;
        crate::core::parallel::csr_in_chunks(
            cloth_edges.len(),
            CANDIDATE_CHUNK,
            &mut self.edge_cand_start,
            &mut self.edge_cand,
            |k, cand| {
                let [a, b] = cloth_edges[k].map(|i| i as usize);
                let near = |i: usize| cand_start[i] < cand_start[i + 1];
                if (inv_mass[a] > 0.0 || inv_mass[b] > 0.0) && (near(a) || near(b)) {
                    let q = query[a].union(query[b]);
                    // The box of a slanted edge is mostly far from it: keep the triangles whose
                    // bounding sphere comes within reach of the segment (its ends' sweeps included).
                    let sweep = (v[a].length().max(v[b].length())) * (1.25 * dt) + radius;
                    let (pa, pb) = (x[a], x[b]);
                    tree.query(&q, |t| {
                        let bx = &boxes[t as usize];
                        if bx.overlaps(&q) && point_segment_distance(bx.center(), pa, pb) <= bx.half_diagonal() + sweep
                        {
                            cand.push(t)
                        }
                    });
                }
            },
        );
        self.stats.edge_candidates = self.edge_cand.len();
        self.clearance.clear();
        self.clearance.resize(x.len(), f32::INFINITY);
        self.gather_vertex_pairs(x, v, inv_mass, cloth_triangles, dt, thickness, radius);
    }

    /// Body vertices against cloth triangles: the body must not poke through
    /// the cloth between cloth vertices (a stretched cloth wrapped around a
    /// limb, a sharp body edge under a coarse cloth). Each pair records the
    /// side of the triangle the body vertex is on at the frame start (or, in
    /// contact, the side of last frame's pair).
    #[allow(clippy::too_many_arguments)]
    fn gather_vertex_pairs(
        &mut self,
        x: &[Vec3],
        v: &[Vec3],
        inv_mass: &[f32],
        tris: &[[u32; 3]],
        dt: f32,
        thickness: f32,
        radius: f32,
    ) {
        let sweep = |i: usize| Aabb::from_points(&[x[i], x[i] + v[i] * (1.25 * dt)]);
        self.cloth_boxes.resize(tris.len(), Aabb::EMPTY);
        crate::core::parallel::for_each_chunk(&mut self.cloth_boxes, BOX_CHUNK, 0, |chunk, out| {
            for (j, out) in out.iter_mut().enumerate() {
                let [a, b, c] = tris[chunk * BOX_CHUNK + j].map(|i| i as usize);
                *out = sweep(a).union(sweep(b)).union(sweep(c)).inflate(0.5 * radius);
            }
        });
        let tree = self.cloth_tree.get_or_insert_with(|| AabbTree::build(&self.cloth_boxes));
        tree.refit(&self.cloth_boxes);
        std::mem::swap(&mut self.vt_pairs, &mut self.vt_previous);
        let all = tree.bounds();
        // Each body vertex's pairs on the cores in chunks, appended in vertex order: the same
        // for any thread count.
        let (tree, boxes, previous, (start, end)) =
            (&*tree, &self.cloth_boxes, &self.vt_previous, (&self.start, &self.end));
        let out = &mut self.vt_pairs;
        let capped = crate::core::parallel::flat_in_chunks(end.len(), CANDIDATE_CHUNK, out, |b, pairs| {
            let q = Aabb::from_points(&[start[b], end[b]]).inflate(0.5 * radius);
            if !q.overlaps(&all) {
                return false;
            }
            let first = pairs.len();
            tree.query(&q, |t| {
                if boxes[t as usize].overlaps(&q) && tris[t as usize].iter().any(|&i| inv_mass[i as usize] > 0.0) {
                    pairs.push((b as u32, t, 0.0));
                }
            });
            let p = start[b];
            // A cloth that sped up (a heap, a caught hem) sweeps boxes over the whole body:
            // keep the nearest triangles, as self-collision does, so pairs stay bounded.
            if pairs.len() - first > MAX_PAIRS_PER_VERTEX {
                for pair in &mut pairs[first..] {
                    let [a, bb, c] = tris[pair.1 as usize].map(|j| x[j as usize]);
                    pair.2 = p.distance(super::collider::closest_point_on_triangle(p, a, bb, c));
                }
            }
            let capped = cap_and_sort(pairs, first);
            let had = pairs_of(previous, b);
            for pair in &mut pairs[first..] {
                pair.2 = gathered_side(had, pair.1, p, tris[pair.1 as usize].map(|j| x[j as usize]), thickness);
            }
            capped
        });
        self.stats.vertex_pairs_capped += capped;
        self.stats.vertex_pairs = self.vt_pairs.len();
    }

    /// Pushes cloth triangles off the body vertices at time `s` (the body
    /// does not move): the body vertex ends `thickness` from the triangle on
    /// its recorded side. Which pairs act is found on the cores first, as in
    /// [`BodyMesh::push_edges`].
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn push_triangles(
        &mut self,
        x: &mut [Vec3],
        prev: &[Vec3],
        w: &[f32],
        tris: &[[u32; 3]],
        s0: f32,
        s: f32,
        thickness: f32,
    ) {
        let mut acts = vec![false; self.vt_pairs.len()];
        {
            let (this, x) = (&*self, &*x);
            crate::core::parallel::for_each_chunk(&mut acts, 4 * CONTACT_CHUNK, 0, |c, out| {
                for (j, flag) in out.iter_mut().enumerate() {
                    let mut pair = this.vt_pairs[c * 4 * CONTACT_CHUNK + j];
                    let side = pair.2;
                    *flag = this.triangle_contact(&mut pair, x, prev, w, tris, s0, s, thickness).is_some()
                        || pair.2 != side;
                }
            });
        }
        let mut moved = vec![false; x.len()];
        for k in 0..self.vt_pairs.len() {
            let [ia, ib, ic] = tris[self.vt_pairs[k].1 as usize].map(|j| j as usize);
            if !acts[k] && !moved[ia] && !moved[ib] && !moved[ic] {
                continue;
            }
            let mut pair = self.vt_pairs[k];
            let contact = self.triangle_contact(&mut pair, x, prev, w, tris, s0, s, thickness);
            self.vt_pairs[k] = pair;
            let Some((n, step, [ba, bu, bv])) = contact else { continue };
            // The triangle moves against n by (thickness - d) at the body point.
            x[ia] -= n * (w[ia] * ba * step);
            x[ib] -= n * (w[ib] * bu * step);
            x[ic] -= n * (w[ic] * bv * step);
            (moved[ia], moved[ib], moved[ic]) = (true, true, true);
            self.stats.triangle_contacts += 1;
        }
    }

    /// A body-vertex / cloth-triangle pair's push at time `s` (normal, step per inverse mass,
    /// barycentrics), its side tracked.
    #[allow(clippy::too_many_arguments)]
    fn triangle_contact(
        &self,
        pair: &mut (u32, u32, f32),
        x: &[Vec3],
        prev: &[Vec3],
        w: &[f32],
        tris: &[[u32; 3]],
        s0: f32,
        s: f32,
        thickness: f32,
    ) -> Option<(Vec3, f32, [f32; 3])> {
        let (b, t) = (pair.0, pair.1);
        let p = self.corner(b, s);
        let [ia, ib, ic] = tris[t as usize].map(|j| j as usize);
        let moved = |i: usize| x[i].distance(prev[i]);
        let reach = || thickness + p.distance(self.corner(b, s0)) + moved(ia).max(moved(ib)).max(moved(ic));
        let (n, d, [ba, bu, bv]) = track_side(p, [x[ia], x[ib], x[ic]], &mut pair.2, thickness, reach)?;
        let wsum = w[ia] * ba * ba + w[ib] * bu * bu + w[ic] * bv * bv;
        if wsum == 0.0 {
            return None;
        }
        Some((n, (thickness - d) / wsum, [ba, bu, bv]))
    }

    /// Pushes cloth edges off the body at time `s`: where body edges (ridges of the body)
    /// come within `thickness` of a cloth edge between its ends, or poke through it, the
    /// points of the cloth edge nearest them are judged by the body's nearest point (inside or
    /// outside as for vertices), and the deepest is moved out to `thickness`, the two cloth
    /// vertices sharing the move by their barycentric weight and inverse mass.
    ///
    /// Gauss-Seidel in edge order, but few edges are in contact in a substep: which are is
    /// found on the cores from the positions before the pass, and the pass in order visits
    /// those and the edges with a vertex an earlier contact of the pass moved; an edge's
    /// contact depends only on its vertices, so the result is the one of visiting every edge.
    ///
    /// With `welds`, a welded seam group moves as one: a contact moving one of its vertices
    /// moves them all, weighed by the group's mass (`w` then holds the groups' inverse
    /// masses, see [`Welds`]).
    ///
    /// Returns the vertices the pass moved, or `None` when no contact acted. A pass again at
    /// the same `s` gives them as `since`: an edge with neither vertex among them is as the
    /// pass left it, out of contact, and is not looked at.
    #[allow(clippy::too_many_arguments)] // the cloth's state, as the simulator keeps it
    pub(crate) fn push_edges(
        &mut self,
        x: &mut [Vec3],
        prev: &[Vec3],
        w: &[f32],
        edges: &[[u32; 2]],
        welds: Option<&Welds>,
        since: Option<&[bool]>,
        s0: f32,
        s: f32,
        thickness: f32,
        friction: f32,
    ) -> Option<Vec<bool>> {
        let mut in_contact = vec![false; edges.len()];
        {
            let (this, x) = (&*self, &*x);
            crate::core::parallel::for_each_chunk(&mut in_contact, CONTACT_CHUNK, 0, |c, out| {
                for (j, flag) in out.iter_mut().enumerate() {
                    let k = c * CONTACT_CHUNK + j;
                    let [ia, ib] = edges[k];
                    let changed = since.is_none_or(|m| m[ia as usize] || m[ib as usize]);
                    *flag = changed && this.edge_contact(k, edges[k], x, w, s, thickness).is_some();
                }
            });
        }
        let mut moved = vec![false; x.len()];
        let mut applied = 0;
        for (k, &[ia, ib]) in edges.iter().enumerate() {
            let (ia, ib) = (ia as usize, ib as usize);
            if !in_contact[k] && !moved[ia] && !moved[ib] {
                continue;
            }
            let Some(EdgeContact { f, n, depth, t, bary, wsum }) = self.edge_contact(k, edges[k], x, w, s, thickness)
            else {
                continue;
            };
            // The edge point moves by `delta`, its vertices (their groups, a vertex not sewn
            // being a group of one) by their share.
            let apply = |delta: Vec3, x: &mut [Vec3], moved: &mut [bool]| {
                for (v, share) in [(ia, w[ia] * (1.0 - f) / wsum), (ib, w[ib] * f / wsum)] {
                    let alone = [v as u32];
                    for &u in welds.and_then(|g| g.group(v)).unwrap_or(&alone) {
                        x[u as usize] += delta * share;
                        moved[u as usize] = true;
                    }
                }
            };
            apply(n * depth, x, &mut moved);
            let moved_by = (x[ia] - prev[ia]).lerp(x[ib] - prev[ib], f);
            apply(-self.friction_cut(t, bary, s0, s, n, moved_by, depth, friction), x, &mut moved);
            applied += 1;
        }
        self.stats.edge_contacts += applied;
        (applied > 0).then_some(moved)
    }

    /// Cloth edge `k`'s contact with the body at time `s` (what [`BodyMesh::push_edges`]
    /// applies), from its vertices' positions in `x`.
    fn edge_contact(
        &self,
        k: usize,
        [ia, ib]: [u32; 2],
        x: &[Vec3],
        w: &[f32],
        s: f32,
        thickness: f32,
    ) -> Option<EdgeContact> {
        let (ia, ib) = (ia as usize, ib as usize);
        let (a, b) = (x[ia], x[ib]);
        let reach = 0.25 * a.distance(b) + thickness;
        // An edge whose ends are both farther from the body than it can sag is clear of it
        // (a body ridge sharp enough to poke through it anyway meets the cloth triangles
        // as body-vertex contacts).
        if self.clearance[ia].min(self.clearance[ib]) > reach {
            return None;
        }
        // An end that left the box it gathered for (a fast limb dragged it farther than its
        // velocity at the frame start said) may have left the edge's candidates behind: the
        // edge asks the tree where it is now, as such a vertex does.
        let near: Vec<u32>;
        let cands = if self.query[ia].margin(a).min(self.query[ib].margin(b)) < reach {
            near = self.triangles_meeting(&Aabb::from_points(&[a, b]).inflate(reach));
            &near[..]
        } else {
            &self.edge_cand[self.edge_cand_start[k] as usize..self.edge_cand_start[k + 1] as usize]
        };
        if cands.is_empty() {
            return None;
        }
        // The points of the cloth edge nearest each body edge that comes within `thickness`
        // of it by that edge's pseudo-normal. That sign holds only where the body edge is the
        // body's nearest feature: beside a body vertex that pokes through the cloth edge, a
        // body edge a centimetre off to the side read deeper than the vertex. So each such
        // point is judged by the body's nearest point (the candidates around the edge, however
        // deep: they all come within a sweep of the segment, and a ridge through the edge is
        // pushed back by the surfaces around it, not by another part of the body that happens
        // to be nearer a deep point, an arm through the torso), and the deepest acts.
        let mut best: Option<(f32, Nearest)> = None;
        let mut judged = [f32::NAN; 8];
        let mut n_judged = 0;
        for &t in cands {
            let c = self.triangles[t as usize].map(|i| self.corner(i, s));
            let centre = (c[0] + c[1] + c[2]) / 3.0;
            let r = centre.distance(c[0]).max(centre.distance(c[1])).max(centre.distance(c[2]));
            if point_segment_distance(centre, a, b) > r + reach {
                continue;
            }
            // A body edge shared by two candidates is met twice: cheaper than looking for
            // the other among the candidates, and its point is judged once (below).
            for j in 0..3 {
                let (f, g, d2) = segment_closest_params(a, b, c[j], c[(j + 1) % 3]);
                // At an end of the cloth edge the vertex contacts act; a body edge farther
                // than a chord can sag over a limb is another part of the body.
                if !(0.01..=0.99).contains(&f) || d2 > reach * reach {
                    continue;
                }
                let q = c[j].lerp(c[(j + 1) % 3], g);
                let n = self.pseudo_normal(t, Feature::Edge(j as u8), s).normalize_or_zero();
                if (a.lerp(b, f) - q).dot(n) >= thickness {
                    continue;
                }
                // Body edges that meet at a vertex share their nearest point: judge it once.
                if judged[..n_judged].iter().any(|&u| (u - f).abs() < 1e-4) {
                    continue;
                }
                if n_judged < judged.len() {
                    judged[n_judged] = f;
                    n_judged += 1;
                }
                let local = f32::INFINITY;
                let Some(hit) = self.closest(a.lerp(b, f), s, cands.iter().copied(), local, local) else {
                    continue;
                };
                if best.is_none_or(|(_, deepest)| hit.0 < deepest.0) {
                    best = Some((f, hit));
                }
            }
        }
        let (f, (d, n, t, bary)) = best?;
        let wsum = w[ia] * (1.0 - f) * (1.0 - f) + w[ib] * f * f;
        if d >= thickness || wsum == 0.0 {
            return None;
        }
        Some(EdgeContact { f, n, depth: thickness - d, t, bary, wsum })
    }

    /// The frame is done: its end pose is the next frame's start.
    pub(crate) fn end_frame(&mut self) {
        self.start.copy_from_slice(&self.end);
        let [f0, f1] = &mut self.face_n;
        f0.clone_from(f1);
        let [v0, v1] = &mut self.vert_n;
        v0.clone_from(v1);
    }

    fn corner(&self, i: u32, s: f32) -> Vec3 {
        self.start[i as usize].lerp(self.end[i as usize], s)
    }

    /// Outward pseudo-normal (not unit) of `feature` of triangle `t` at time `s`.
    fn pseudo_normal(&self, t: u32, feature: Feature, s: f32) -> Vec3 {
        let face = |t: u32| self.face_n[0][t as usize].lerp(self.face_n[1][t as usize], s);
        match feature {
            Feature::Face => face(t),
            Feature::Edge(k) => {
                let other = self.adjacent[t as usize][k as usize];
                if other == u32::MAX { face(t) } else { face(t) + face(other) }
            }
            Feature::Vertex(k) => {
                let v = self.triangles[t as usize][k as usize] as usize;
                self.vert_n[0][v].lerp(self.vert_n[1][v], s)
            }
        }
    }

    /// The body's closest point to `p` at time `s` (0 = frame start, 1 = frame end): `(signed
    /// distance, outward unit normal, triangle, barycentrics)`, where `tris` holds every
    /// triangle within `covered` of `p`. Only the body's nearest point has a trustworthy side
    /// (its pseudo-normal's): the nearest of `tris` beyond `covered` may be a far triangle seen
    /// from behind while a nearer one is missing, which read points 10 cm out as 24 cm inside
    /// and pushed them through the body. Beyond `covered`, an outside point is out of contact
    /// (`None`), and an inside one is checked against the body's triangles out to `reach`:
    /// deeper than that it is left alone (`None`).
    fn closest(&self, p: Vec3, s: f32, tris: impl Iterator<Item = u32>, covered: f32, reach: f32) -> Option<Nearest> {
        let hit = self.closest_among(p, s, tris)?;
        self.trusted(p, s, hit, covered, reach)
    }

    /// `hit`, the nearest of triangles covering `p` out to `covered`, judged as
    /// [`BodyMesh::closest`] does.
    fn trusted(&self, p: Vec3, s: f32, hit: Nearest, covered: f32, reach: f32) -> Option<Nearest> {
        if hit.0.abs() <= covered {
            return Some(hit);
        }
        if hit.0 > 0.0 || reach <= covered {
            return None;
        }
        let r = (-hit.0).min(reach);
        let q = Aabb::around(p, r);
        self.closest_among(p, s, self.triangles_meeting(&q).into_iter()).filter(|h| h.0.abs() <= r)
    }

    /// The triangles whose swept box this frame meets `q`.
    fn triangles_meeting(&self, q: &Aabb) -> Vec<u32> {
        let mut found = Vec::new();
        self.tree.query(q, |t| {
            if self.boxes[t as usize].overlaps(q) {
                found.push(t)
            }
        });
        found
    }

    /// Closest body point to `p` among `tris` at time `s`, as [`BodyMesh::closest`].
    fn closest_among(&self, p: Vec3, s: f32, tris: impl Iterator<Item = u32>) -> Option<Nearest> {
        let mut best: Option<(f32, u32, Vec3, [f32; 3], Feature)> = None;
        for t in tris {
            // The frame's swept box holds the triangle at any `s`: a box farther than the best
            // so far cannot hold a nearer point (nor a tie, which the lower index would win).
            if best.is_some_and(|(bd, ..)| self.boxes[t as usize].distance_squared(p) > bd) {
                continue;
            }
            let [a, b, c] = self.triangles[t as usize].map(|i| self.corner(i, s));
            let (q, bary, feature) = closest_point_feature(p, a, b, c);
            let d2 = p.distance_squared(q);
            if best.is_none_or(|(bd, bt, ..)| d2 < bd || (d2 == bd && t < bt)) {
                best = Some((d2, t, q, bary, feature));
            }
        }
        let (d2, t, q, bary, feature) = best?;
        let pn = self.pseudo_normal(t, feature, s);
        let d = d2.sqrt();
        let outside = (p - q).dot(pn) >= 0.0;
        let n = if d > 1e-7 { (p - q) / d } else { pn.normalize_or(Vec3::Y) };
        Some(if outside { (d, n, t, bary) } else { (-d, -n, t, bary) })
    }

    /// Pushes the free vertices `which` out to `thickness` at time `s1` and
    /// applies friction to their motion since `prev` relative to the body's
    /// motion since `s0`. Each vertex at most once in `which` (all of them, or the welded
    /// groups' disjoint members): the contacts are found from the positions before any move.
    ///
    /// Without `exact_clearance`, a vertex whose last distance outside the body this frame,
    /// less its own and the body's motion since, still exceeds `thickness` is not looked at
    /// (it cannot be in contact): its clearance is then that lower bound. The edge contacts,
    /// which read the clearances, need them exact.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn collide(
        &mut self,
        which: impl Iterator<Item = u32>,
        x: &mut [Vec3],
        prev: &[Vec3],
        inv_mass: &[f32],
        s0: f32,
        s1: f32,
        thickness: f32,
        friction: f32,
        exact_clearance: bool,
    ) {
        let which: Vec<u32> = which.collect();
        // Each vertex's contact depends on it and the body alone: found on the cores in
        // chunks, applied in order, so the result is the same for any thread count.
        let (this, positions) = (&*self, &*x);
        let contacts = crate::core::parallel::map_in_chunks(which.len(), CONTACT_CHUNK, |k| {
            let i = which[k] as usize;
            this.vertex_contact(i, positions, prev, inv_mass, s0, s1, thickness, friction, exact_clearance)
        });
        for (&i, contact) in which.iter().zip(&contacts) {
            let i = i as usize;
            self.clearance[i] = contact.clearance;
            if let Some(d) = contact.outside {
                self.last_outside[i] = Some((d, x[i], s1));
            }
            self.stats.fallbacks += usize::from(contact.fallback);
            self.stats.skipped += usize::from(contact.skipped);
            if let Some(xi) = contact.moved_to {
                self.stats.contacts += 1;
                x[i] = xi;
            }
        }
    }

    /// Vertex `i`'s contact with the body this substep (what [`BodyMesh::collide`] applies).
    #[allow(clippy::too_many_arguments)]
    fn vertex_contact(
        &self,
        i: usize,
        x: &[Vec3],
        prev: &[Vec3],
        inv_mass: &[f32],
        s0: f32,
        s1: f32,
        thickness: f32,
        friction: f32,
        exact_clearance: bool,
    ) -> VertexContact {
        let mut out = VertexContact { clearance: 0.0, fallback: false, skipped: false, moved_to: None, outside: None };
        if inv_mass[i] == 0.0 {
            return out;
        }
        let p = x[i];
        let covered = self.query[i].margin(p);
        if !exact_clearance
            && covered >= thickness
            && let Some((d, at, s)) = self.last_outside[i]
        {
            // Distance to a set of triangles changes no faster than the point and the
            // triangles' corners move.
            let bound = d - p.distance(at) - self.body_travel * (s1 - s);
            if bound > thickness + ROUNDING {
                out.clearance = bound;
                out.skipped = true;
                return out;
            }
        }
        // No hit: no body triangle within the candidates' reach. The edge contacts read this
        // as how far the body is at least; infinity let a chord between two vertices 5 mm
        // out (beyond their reach) skip its check while a body ridge poked through it.
        out.clearance = covered.max(0.0);
        let hit = if covered >= thickness {
            let (a, b) = (self.cand_start[i] as usize, self.cand_start[i + 1] as usize);
            if a == b {
                return out;
            }
            let nearest = self.closest_among(p, s1, self.cand[a..b].iter().copied());
            out.outside = nearest.map(|h| h.0).filter(|&d| d > 0.0);
            nearest.and_then(|h| self.trusted(p, s1, h, covered, DEEPEST_CONTACT))
        } else {
            out.fallback = true;
            out.clearance = 2.0 * thickness;
            let near = self.triangles_meeting(&Aabb::around(p, 2.0 * thickness));
            self.closest(p, s1, near.into_iter(), 2.0 * thickness, DEEPEST_CONTACT)
        };
        let Some((dist, n, t, bary)) = hit else {
            return out;
        };
        out.clearance = dist.max(thickness);
        if dist < thickness {
            let depth = thickness - dist;
            let xi = p + n * depth;
            out.moved_to = Some(xi - self.friction_cut(t, bary, s0, s1, n, xi - prev[i], depth, friction));
        }
        out
    }

    /// PBD Coulomb friction of a contact pushed `depth` out along `n` at barycentrics `bary` of
    /// triangle `t`: the part of `moved` (the contact point's motion this substep) tangential
    /// to the body's motion under it from `s0` to `s1`, cut to at most `friction * depth`. The
    /// caller subtracts it.
    #[allow(clippy::too_many_arguments)]
    fn friction_cut(
        &self,
        t: u32,
        bary: [f32; 3],
        s0: f32,
        s1: f32,
        n: Vec3,
        moved: Vec3,
        depth: f32,
        friction: f32,
    ) -> Vec3 {
        let tri = self.triangles[t as usize];
        let body_motion: Vec3 = (0..3).map(|k| (self.corner(tri[k], s1) - self.corner(tri[k], s0)) * bary[k]).sum();
        let rel = moved - body_motion;
        let tangential = rel - n * rel.dot(n);
        let tl = tangential.length();
        if tl > 0.0 { tangential * (friction * depth / tl).min(1.0) } else { Vec3::ZERO }
    }

    /// Where `p` goes to be `thickness` outside the body (end pose), along the body's normal at
    /// its nearest point; `None` when it already is, or is deeper inside than `reach`.
    pub fn pushed_out(&self, p: Vec3, thickness: f32, reach: f32) -> Option<Vec3> {
        let mut near = Vec::new();
        self.tree.query(&Aabb::around(p, reach.max(thickness)), |t| near.push(t));
        let (d, n, ..) = self.closest(p, 1.0, near.into_iter(), thickness, reach)?;
        (d < thickness).then(|| p + n * (thickness - d))
    }

    /// Smallest signed distance of any of `points` to the body (end pose), or
    /// `None` when none is within `max_distance`.
    pub fn min_clearance(&self, points: &[Vec3], max_distance: f32) -> Option<f32> {
        let mut best: Option<f32> = None;
        let mut near = Vec::new();
        for &p in points {
            near.clear();
            let q = Aabb::around(p, max_distance);
            self.tree.query(&q, |t| near.push(t));
            // `closest` keeps only a nearest point within `max_distance`.
            if let Some((d, ..)) = self.closest(p, 1.0, near.iter().copied(), max_distance, max_distance) {
                best = Some(best.map_or(d, |b: f32| b.min(d)));
            }
        }
        best
    }

    /// Indices of the segments `[a, b]` (cloth edges) that cross a body
    /// triangle (end pose).
    pub fn crossings(&self, x: &[Vec3], edges: &[[u32; 2]]) -> Vec<usize> {
        (0..edges.len())
            .filter(|&i| self.segment_crosses(x[edges[i][0] as usize], x[edges[i][1] as usize], &self.end))
            .collect()
    }

    /// Whether the segment `a`-`b` crosses a body triangle with its corners at `corners` (the
    /// frame's start or end pose).
    fn segment_crosses(&self, a: Vec3, b: Vec3, corners: &[Vec3]) -> bool {
        let mut hit = false;
        self.tree.query(&Aabb::from_points(&[a, b]), |t| {
            if !hit {
                let [p0, p1, p2] = self.triangles[t as usize].map(|i| corners[i as usize]);
                hit = super::intersections::segment_hits_triangle(a, b, p0, p1, p2);
            }
        });
        hit
    }

    /// Where a seam pair at `a` and `b` is to meet when the body, as the frame starts, lies
    /// between them: their midpoint, moved out of the body to `thickness` when it is inside or
    /// nearer; and the body's outward normal at each of the two vertices where the body is
    /// within `reach` of it (zero where not). `None` when the segment misses the body: the pair
    /// closes along it.
    pub(crate) fn seam_meeting(&self, a: Vec3, b: Vec3, thickness: f32, reach: f32) -> Option<(Vec3, [Vec3; 2])> {
        if !self.segment_crosses(a, b, &self.start) {
            return None;
        }
        let m = 0.5 * (a + b);
        // The segment crosses the surface within half its length of `m`, so the nearest
        // surface point is among these triangles.
        let near = self.triangles_meeting(&Aabb::around(m, 0.5 * a.distance(b) + thickness));
        let (d, n, ..) = self.closest_among(m, 0.0, near.into_iter())?;
        let at = if d < thickness { m + n * (thickness - d) } else { m };
        let normal = |p: Vec3| {
            let near = self.triangles_meeting(&Aabb::around(p, reach));
            self.closest_among(p, 0.0, near.into_iter()).filter(|h| h.0 <= reach).map_or(Vec3::ZERO, |h| h.1)
        };
        Some((at, [normal(a), normal(b)]))
    }
}

/// Closed box mesh, each face an `n` x `n` grid of quads (two triangles
/// each, CCW seen from outside), with `rotation` applied about its centre.
/// A body mesh's vertices are what stops the body poking through the cloth
/// between cloth vertices, so a box body wants `n` of about its edge length
/// over the cloth's edge length.
pub fn box_mesh(center: Vec3, half: Vec3, rotation: glam::Quat, n: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let n = n.max(1);
    let mut pos: Vec<Vec3> = Vec::new();
    let mut tris = Vec::new();
    let mut index = std::collections::HashMap::new();
    // Each face: the outward axis and two tangent axes with u x v = normal.
    let faces = [
        (Vec3::X, Vec3::Y, Vec3::Z),
        (-Vec3::X, Vec3::Z, Vec3::Y),
        (Vec3::Y, Vec3::Z, Vec3::X),
        (-Vec3::Y, Vec3::X, Vec3::Z),
        (Vec3::Z, Vec3::X, Vec3::Y),
        (-Vec3::Z, Vec3::Y, Vec3::X),
    ];
    for (normal, u, v) in faces {
        let mut id = |i: u32, j: u32| -> u32 {
            // Integer lattice key, so shared edge vertices are welded.
            let unit = normal + u * (2.0 * i as f32 / n as f32 - 1.0) + v * (2.0 * j as f32 / n as f32 - 1.0);
            let key = (unit * n as f32).round().as_ivec3().to_array();
            *index.entry(key).or_insert_with(|| {
                pos.push(center + rotation * (unit * half));
                (pos.len() - 1) as u32
            })
        };
        for i in 0..n {
            for j in 0..n {
                let (a, b, c, d) = (id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1));
                tris.push([a, b, c]);
                tris.push([a, c, d]);
            }
        }
    }
    (pos, tris)
}

/// Closed capsule mesh around the segment `a`-`b` (a limb): a cylinder of
/// `rings` bands with hemispherical caps, `segments` around, CCW outside.
pub fn capsule_mesh(a: Vec3, b: Vec3, radius: f32, rings: u32, segments: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let axis = (b - a).normalize();
    let (u, w) = axis.any_orthonormal_pair();
    let cap_rings = (segments / 4).max(2);
    // Profile from the pole at `a` to the pole at `b`: (point on axis, radius).
    let mut profile: Vec<(Vec3, f32)> = Vec::new();
    for k in 1..=cap_rings {
        let t = std::f32::consts::FRAC_PI_2 * k as f32 / cap_rings as f32;
        profile.push((a - axis * (radius * t.cos()), radius * t.sin()));
    }
    for k in 1..rings {
        profile.push((a.lerp(b, k as f32 / rings as f32), radius));
    }
    for k in 0..cap_rings {
        let t = std::f32::consts::FRAC_PI_2 * k as f32 / cap_rings as f32;
        profile.push((b + axis * (radius * t.sin()), radius * t.cos()));
    }
    let mut pos = vec![a - axis * radius];
    for &(c, r) in &profile {
        for s in 0..segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            pos.push(c + (u * phi.cos() + w * phi.sin()) * r);
        }
    }
    pos.push(b + axis * radius);
    (pos, super::collider::pole_ring_triangles(profile.len() as u32, segments))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Signed volume: positive when the mesh is closed and wound CCW outside.
    fn volume(pos: &[Vec3], tris: &[[u32; 3]]) -> f32 {
        tris.iter().map(|t| pos[t[0] as usize].dot(pos[t[1] as usize].cross(pos[t[2] as usize])) / 6.0).sum()
    }

    #[test]
    fn segment_closest_points() {
        // Skew perpendicular segments: nearest at (0.25, 0, 0) and (0.25, 0, 1).
        let (s, t, d2) =
            segment_closest_params(Vec3::ZERO, Vec3::X, Vec3::new(0.25, -1.0, 1.0), Vec3::new(0.25, 3.0, 1.0));
        assert!((s - 0.25).abs() < 1e-6 && (t - 0.25).abs() < 1e-6 && (d2 - 1.0).abs() < 1e-6, "{s} {t} {d2}");
        // Past the end of the first: clamped to its end.
        let (s, t, d2) =
            segment_closest_params(Vec3::ZERO, Vec3::X, Vec3::new(2.0, -1.0, 0.0), Vec3::new(2.0, 1.0, 0.0));
        assert!(s == 1.0 && (t - 0.5).abs() < 1e-6 && (d2 - 1.0).abs() < 1e-6, "{s} {t} {d2}");
        // Parallel: any pair at the common distance.
        let (.., d2) = segment_closest_params(Vec3::ZERO, Vec3::X, Vec3::new(0.5, 0.0, 2.0), Vec3::new(1.5, 0.0, 2.0));
        assert!((d2 - 4.0).abs() < 1e-6, "{d2}");
    }

    /// A box moving 1 cm into a grid of resting vertices 3 to 12 mm in front of it: the
    /// vertices skipped by their distance bound end every substep where looking at each
    /// would have put them.
    #[test]
    fn skipping_far_vertices_moves_nothing_differently() {
        let (p, t) = box_mesh(Vec3::ZERO, Vec3::splat(0.1), glam::Quat::IDENTITY, 4);
        let moved: Vec<Vec3> = p.iter().map(|&q| q + Vec3::new(0.01, 0.0, 0.0)).collect();
        let mut skipping = BodyMesh::new(p, t);
        skipping.move_to(&moved);
        let n = 10;
        let mut x = Vec::new();
        for i in 0..n {
            for j in 0..2 {
                x.push(Vec3::new(0.103 + 0.001 * i as f32, 0.01 * j as f32, 0.0));
            }
        }
        let cloth_tris: Vec<[u32; 3]> = (0..n as u32 - 1).map(|i| [2 * i, 2 * i + 2, 2 * i + 1]).collect();
        let (v, w) = (vec![Vec3::ZERO; x.len()], vec![1.0; x.len()]);
        let (dt, th) = (1.0 / 60.0, 0.0025);
        skipping.begin_frame(&x, &v, &w, &cloth_tris, &[], dt, th, 3.0 * th);
        let mut exact = skipping.clone();
        let mut y = x.clone();
        let substeps = 20;
        for k in 0..substeps {
            let (s0, s1) = (k as f32 / substeps as f32, (k + 1) as f32 / substeps as f32);
            let (prev_x, prev_y) = (x.clone(), y.clone());
            let all = 0..x.len() as u32;
            skipping.collide(all.clone(), &mut x, &prev_x, &w, s0, s1, th, 0.5, false);
            exact.collide(all, &mut y, &prev_y, &w, s0, s1, th, 0.5, true);
            assert_eq!(x, y, "substep {k}");
        }
        assert!(skipping.stats.skipped > 20, "{:?}", skipping.stats);
        assert_eq!(exact.stats.skipped, 0);
        assert!(x.iter().all(|q| q.x > 0.11 + 0.99 * th), "every vertex pushed ahead of the box: {x:?}");
    }

    #[test]
    fn shapes_are_closed_and_outward() {
        for n in [1, 3] {
            let (p, t) = box_mesh(Vec3::ONE, Vec3::new(0.5, 1.0, 1.5), glam::Quat::from_rotation_y(0.3), n);
            assert!((volume(&p, &t) - 6.0).abs() < 1e-4);
            assert_eq!(p.len() as u32, 6 * n * n + 2, "welded");
            assert!(BodyMesh::new(p, t).adjacent.iter().flatten().all(|&a| a != u32::MAX), "closed");
        }
        let (p, t) = capsule_mesh(Vec3::ZERO, Vec3::new(0.0, 0.0, 1.0), 0.1, 8, 32);
        let exact = std::f32::consts::PI * 0.01 * (1.0 + 4.0 / 3.0 * 0.1);
        let v = volume(&p, &t);
        assert!(v > 0.95 * exact && v < exact, "{v} vs {exact}");
        let body = BodyMesh::new(p, t);
        assert!(body.adjacent.iter().flatten().all(|&a| a != u32::MAX), "closed");
        // Signs from pseudo-normals: inside a thin limb and beside its caps.
        let all = 0..body.triangles.len() as u32;
        assert!(
            body.closest(Vec3::new(0.05, 0.0, 0.5), 1.0, all.clone(), f32::INFINITY, f32::INFINITY).unwrap().0 < 0.0
        );
        let (d, n, ..) =
            body.closest(Vec3::new(0.0, 0.0, 1.2), 1.0, all.clone(), f32::INFINITY, f32::INFINITY).unwrap();
        assert!((d - 0.1).abs() < 2e-3 && n.z > 0.99, "{d} {n}");
        // 0.086 from the cap's centre: inside its 0.1 radius.
        let (d, ..) = body.closest(Vec3::new(0.0, 0.07, 1.05), 1.0, all, f32::INFINITY, f32::INFINITY).unwrap();
        assert!(d < 0.0, "{d}");
    }
}

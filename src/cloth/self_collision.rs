//! Cloth-cloth contact: vertex-triangle pairs with a recorded side.
//!
//! Once per frame an [`AabbTree`] over the cloth triangles is refitted to the
//! boxes the triangles are predicted to sweep (`x` to `x + v dt`, widened by
//! the thickness and a slack), and every vertex gathers the triangles (not
//! its own, nor those the cloth excludes as its neighbours on the surface at
//! rest) whose sweep meets its own, keeping at most [`MAX_PAIRS_PER_VERTEX`],
//! those it can reach first. Each pair records on which side of the
//! triangle the vertex is: the side it had at the start of the frame, or, for
//! a pair already in contact (closer than the thickness to the plane) that
//! was a pair last frame, the side recorded then. Each substep a pair whose
//! vertex lies over the triangle closer than the thickness on the recorded
//! side, or anywhere on the wrong side, is pushed apart to the thickness on
//! the recorded side (a PBD contact between the vertex and the three
//! triangle corners, weighted by inverse mass and barycentrics). The side
//! never flips while the pair lives, so a vertex cannot pass through a
//! triangle it was gathered against; a pair the cap left out for a frame
//! comes back with the side it then has.

use glam::Vec3;

use super::bvh::{Aabb, AabbTree};

/// The most triangles one vertex is paired with in a frame (those it can reach soonest kept:
/// distance less what the two can close this frame). Regular cloth
/// meets a handful; where a crumpled heap or a burst of speed makes every vertex meet every
/// triangle, pairs would otherwise grow with the square of the mesh (gigabytes at 1 cm edges).
pub const MAX_PAIRS_PER_VERTEX: usize = 64;

/// Vertices a thread takes at a time in [`SelfCollision::begin_frame`]'s pair search
/// (`parallel::map_in_chunks`).
const PAIR_CHUNK: usize = 512;

/// One vertex's pairs `pairs[first..]` `(vertex, triangle, key)`: keeps the
/// [`MAX_PAIRS_PER_VERTEX`] of smallest key (ties by triangle) and sorts them by triangle.
/// Returns whether any were dropped.
pub(crate) fn cap_and_sort(pairs: &mut Vec<(u32, u32, f32)>, first: usize) -> bool {
    let capped = pairs.len() - first > MAX_PAIRS_PER_VERTEX;
    if capped {
        let smallest = |a: &(u32, u32, f32), b: &(u32, u32, f32)| a.2.total_cmp(&b.2).then(a.1.cmp(&b.1));
        pairs[first..].select_nth_unstable_by(MAX_PAIRS_PER_VERTEX - 1, smallest);
        pairs.truncate(first + MAX_PAIRS_PER_VERTEX);
    }
    pairs[first..].sort_unstable_by_key(|p| p.1);
    capped
}

#[derive(Clone, Debug)]
pub struct SelfCollision {
    tree: AabbTree,
    boxes: Vec<Aabb>,
    /// `(vertex, triangle, side)`, sorted by vertex then triangle.
    pairs: Vec<(u32, u32, f32)>,
    previous: Vec<(u32, u32, f32)>,
    pub stats: SelfStats,
}

/// Work counters of the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SelfStats {
    pub pairs: usize,
    /// Pair projections that moved vertices (summed over substeps).
    pub contacts: usize,
    /// Vertices that met more than [`MAX_PAIRS_PER_VERTEX`] triangles and kept the soonest.
    pub capped: usize,
}

impl SelfCollision {
    pub fn new(x: &[Vec3], triangles: &[[u32; 3]]) -> Self {
        let boxes: Vec<Aabb> = triangles.iter().map(|t| Aabb::from_points(&t.map(|i| x[i as usize]))).collect();
        SelfCollision {
            tree: AabbTree::build(&boxes),
            boxes,
            pairs: Vec::new(),
            previous: Vec::new(),
            stats: SelfStats::default(),
        }
    }

    /// The last frame's pairs `(vertex, triangle, side)`: the sides the next frame keeps.
    pub(crate) fn sides(&self) -> &[(u32, u32, f32)] {
        &self.pairs
    }

    /// `new` for a cloth saved mid-run, with the sides its last frame recorded.
    pub(crate) fn with_sides(x: &[Vec3], triangles: &[[u32; 3]], sides: &[(u32, u32, f32)]) -> Self {
        SelfCollision { pairs: sides.to_vec(), ..SelfCollision::new(x, triangles) }
    }

    #[allow(clippy::too_many_arguments)] // the cloth's state, as the simulator keeps it
    pub(crate) fn begin_frame(
        &mut self,
        x: &[Vec3],
        v: &[Vec3],
        inv_mass: &[f32],
        rep: &[u32],
        excluded: &[(u32, u32)],
        triangles: &[[u32; 3]],
        dt: f32,
        thickness: f32,
        slack: f32,
    ) {
        self.stats = SelfStats::default();
        let sweep = |i: usize| Aabb::from_points(&[x[i], x[i] + v[i] * (1.25 * dt)]);
        let r = 0.5 * (thickness + slack);
        for (k, t) in triangles.iter().enumerate() {
            let [a, b, c] = t.map(|i| i as usize);
            self.boxes[k] = sweep(a).union(sweep(b)).union(sweep(c)).inflate(r);
        }
        self.tree.refit(&self.boxes);
        std::mem::swap(&mut self.pairs, &mut self.previous);
        self.pairs.clear();
        // Each vertex's pairs (its query of the tree, capped and sorted) on the cores in chunks,
        // then appended and given their sides in vertex order: the same for any thread count.
        let (tree, boxes) = (&self.tree, &self.boxes);
        let found = crate::core::parallel::map_in_chunks(x.len(), PAIR_CHUNK, |i| {
            let q = sweep(i).inflate(r);
            let mut pairs = Vec::new();
            tree.query(&q, |t| {
                let tri = triangles[t as usize];
                // Not its own triangles, nor those of the vertices it is sewn to.
                if tri.iter().any(|&j| rep[j as usize] == rep[i]) || !boxes[t as usize].overlaps(&q) {
                    return;
                }
                if inv_mass[i] == 0.0 && tri.iter().all(|&j| inv_mass[j as usize] == 0.0) {
                    return;
                }
                if !excluded.is_empty() && excluded.binary_search(&(i as u32, t)).is_ok() {
                    return;
                }
                // Near enough at the frame start for what the two can close
                // in on each other this frame.
                let [a, b, c] = tri.map(|j| j as usize);
                let closing = (v[i] - (v[a] + v[b] + v[c]) / 3.0).length() * (1.25 * dt);
                let q_near = super::collider::closest_point_on_triangle(x[i], x[a], x[b], x[c]);
                let d = x[i].distance(q_near);
                if d <= thickness + slack + closing {
                    // How soon the two can meet (distance less closing) rides in the side's
                    // place until the side is set below: the cap keeps the soonest.
                    pairs.push((i as u32, t, d - closing));
                }
            });
            let capped = cap_and_sort(&mut pairs, 0);
            (pairs, capped)
        });
        let mut prev_k = 0;
        for (i, (pairs, capped)) in found.into_iter().enumerate() {
            let start = self.pairs.len();
            self.pairs.extend(pairs);
            if capped {
                self.stats.capped += 1;
            }
            for pair in &mut self.pairs[start..] {
                let [a, b, c] = triangles[pair.1 as usize].map(|j| x[j as usize]);
                let n = (b - a).cross(c - a).normalize_or_zero();
                let d = (x[i] - a).dot(n);
                let mut side = if d >= 0.0 { 1.0 } else { -1.0 };
                if d.abs() < thickness {
                    while prev_k < self.previous.len()
                        && (self.previous[prev_k].0, self.previous[prev_k].1) < (pair.0, pair.1)
                    {
                        prev_k += 1;
                    }
                    if let Some(p) = self.previous.get(prev_k).filter(|p| (p.0, p.1) == (pair.0, pair.1)) {
                        side = p.2;
                    }
                }
                pair.2 = side;
            }
        }
        self.stats.pairs = self.pairs.len();
    }

    /// One Gauss-Seidel sweep over the pairs.
    /// `prev` are the positions at the substep's start: a vertex can get
    /// behind a triangle by at most what the two moved.
    pub(crate) fn solve(&mut self, x: &mut [Vec3], prev: &[Vec3], w: &[f32], triangles: &[[u32; 3]], thickness: f32) {
        for pair in &mut self.pairs {
            let (i, t) = (pair.0 as usize, pair.1);
            let [ia, ib, ic] = triangles[t as usize].map(|j| j as usize);
            let moved = |k: usize| x[k].distance(prev[k]);
            let reach = thickness + moved(i) + moved(ia).max(moved(ib)).max(moved(ic));
            let Some((n, d, [ba, bu, bv])) = track_side(x[i], [x[ia], x[ib], x[ic]], &mut pair.2, thickness, reach)
            else {
                continue;
            };
            let wsum = w[i] + w[ia] * ba * ba + w[ib] * bu * bu + w[ic] * bv * bv;
            if wsum == 0.0 {
                continue;
            }
            let s = (thickness - d) / wsum;
            x[i] += n * (w[i] * s);
            x[ia] -= n * (w[ia] * ba * s);
            x[ib] -= n * (w[ib] * bu * s);
            x[ic] -= n * (w[ic] * bv * s);
            self.stats.contacts += 1;
        }
    }
}

/// The side tracking shared by vertex-triangle pairs: returns the unit
/// normal pointing to the recorded `side`, the distance `d` of `p` along it
/// and the projection's barycentrics when `p` must be pushed (over the
/// triangle, closer than `thickness` on the recorded side or behind it by
/// less than `reach`, what the two moved this substep). Where `p` is not over
/// the triangle, or farther behind than it can have got by passing through
/// it, the side is updated instead: `p` went around the border.
#[inline]
pub(crate) fn track_side(
    p: Vec3,
    tri: [Vec3; 3],
    side: &mut f32,
    thickness: f32,
    reach: f32,
) -> Option<(Vec3, f32, [f32; 3])> {
    let [a, b, c] = tri;
    let (e1, e2) = (b - a, c - a);
    let cross = e1.cross(e2);
    let len2 = cross.length_squared();
    if len2 < 1e-20 {
        return None;
    }
    let n = cross / len2.sqrt();
    let rel = p - a;
    let d_raw = rel.dot(n);
    let d = d_raw * *side;
    if d >= thickness {
        return None;
    }
    let inv = 1.0 / len2;
    let bu = rel.cross(e2).dot(cross) * inv;
    let bv = e1.cross(rel).dot(cross) * inv;
    let ba = 1.0 - bu - bv;
    let eps = -0.05;
    if ba < eps || bu < eps || bv < eps || d < -reach {
        if d_raw != 0.0 {
            *side = d_raw.signum();
        }
        return None;
    }
    Some((n * *side, d, [ba, bu, bv]))
}

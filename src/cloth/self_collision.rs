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
//! comes back with the side it then has. A vertex that moves out of the region
//! its pairs cover within the frame (faster than predicted) has the pairs near
//! it gathered again from the substep's start ([`SelfCollision::gather`]),
//! by the same rule for sides.
//!
//! What got through anyway (a seam closing across a folded panel pulls harder than the
//! contacts) would be held there by the same rule, so each frame also looks for cloth edges
//! crossing cloth triangles and forces the pairs of what is through back to the other side
//! ([`SelfCollision::untangle`]); an end of a crossing edge found through is also pushed
//! along the triangle's normal while the edge crosses, since its pairs act only over the
//! triangle. Vertices sewn together are one point there: judged and pushed together.

use glam::Vec3;

use super::body_collision::Welds;
use super::bvh::{Aabb, AabbTree};

/// The most triangles one vertex is paired with in a frame (those it can reach soonest kept:
/// distance less what the two can close this frame). Regular cloth
/// meets a handful; where a crumpled heap or a burst of speed makes every vertex meet every
/// triangle, pairs would otherwise grow with the square of the mesh (gigabytes at 1 cm edges).
pub const MAX_PAIRS_PER_VERTEX: usize = 64;

/// A recorded side of this magnitude (times the sign) marks a pair whose vertex went through
/// its triangle: [`track_side`] pushes it back to that side from any depth.
const FORCED: f32 = 2.0;

/// Vertices a thread takes at a time in the pair search ([`SelfCollision::gather`])
/// (`parallel::map_in_chunks`).
const PAIR_CHUNK: usize = 512;

/// Triangles' and vertices' boxes a thread takes at a time in [`SelfCollision::gather`].
const BOX_CHUNK: usize = 4096;

/// Pairs a thread takes at a time in [`SelfCollision::solve`]'s search for those that act.
const SOLVE_CHUNK: usize = 2048;

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

/// Vertex `v`'s pairs in `pairs` (sorted by vertex, then triangle).
pub(crate) fn pairs_of(pairs: &[(u32, u32, f32)], v: usize) -> &[(u32, u32, f32)] {
    let from = pairs.partition_point(|p| (p.0 as usize) < v);
    &pairs[from..from + pairs[from..].partition_point(|p| p.0 as usize == v)]
}

/// The side a point `p` gathered against triangle `t` (corners `tri`) takes: in contact
/// (closer than `thickness` to its plane), the side of its pair with `t` among `had` (its pairs
/// of the last gather, sorted by triangle) where it had one; else the side it is on.
pub(crate) fn gathered_side(had: &[(u32, u32, f32)], t: u32, p: Vec3, tri: [Vec3; 3], thickness: f32) -> f32 {
    let [a, b, c] = tri;
    let d = (p - a).dot((b - a).cross(c - a).normalize_or_zero());
    // Most gathered pairs are farther than the thickness: no search for those.
    let kept = (d.abs() < thickness).then(|| had.binary_search_by_key(&t, |p| p.1).ok()).flatten();
    kept.map_or(if d >= 0.0 { 1.0 } else { -1.0 }, |k| had[k].2)
}

/// Vertices that left the region their pairs cover within a frame ([`SelfCollision::escaped`]),
/// and where every vertex is now.
#[derive(Clone, Copy)]
pub(crate) struct Escape<'a> {
    pub now: &'a [Vec3],
    pub escaped: &'a [u32],
}

#[derive(Clone, Debug)]
pub struct SelfCollision {
    tree: AabbTree,
    boxes: Vec<Aabb>,
    /// `(vertex, triangle, side)`, sorted by vertex then triangle.
    pairs: Vec<(u32, u32, f32)>,
    previous: Vec<(u32, u32, f32)>,
    /// Each vertex's neighbours on the mesh (CSR) and the mesh's edges, for untangling.
    ring_start: Vec<u32>,
    ring: Vec<u32>,
    /// The edge (index into `edges`) of each `ring` entry.
    ring_edge: Vec<u32>,
    edges: Vec<[u32; 2]>,
    /// Where each vertex may go before the frame's pairs no longer cover it: its predicted
    /// sweep widened by half the slack ([`SelfCollision::escaped`]).
    reach: Vec<Aabb>,
    /// Each vertex's and each triangle's pattern piece.
    piece: Vec<u32>,
    tri_piece: Vec<u32>,
    /// This frame's vertices found through a triangle that a cloth edge from them crosses:
    /// `(vertex, the edge's other end, triangle, side it belongs on)`
    /// ([`SelfCollision::untangle`]).
    through_edges: Vec<(u32, u32, u32, f32)>,
    pub stats: SelfStats,
}

/// Work counters of the last frame.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SelfStats {
    /// Pairs, the most at any point of the frame (they are gathered again within it).
    pub pairs: usize,
    /// Pair projections that moved vertices (summed over substeps).
    pub contacts: usize,
    /// Vertices that met more than [`MAX_PAIRS_PER_VERTEX`] triangles and kept the soonest.
    pub capped: usize,
    /// Times the pairs were gathered again within the frame ([`SelfCollision::escaped`]).
    pub regathers: usize,
    /// Cloth edges found crossing cloth triangles at the frame start.
    pub crossings: usize,
    /// Pairs whose vertex was found through its triangle and is pulled back (see
    /// [`SelfCollision::untangle`]).
    pub forced: usize,
}

impl SelfCollision {
    /// `edges`: the mesh's edges, each once; `pieces`: each vertex's pattern piece (empty: one
    /// piece).
    pub fn new(x: &[Vec3], triangles: &[[u32; 3]], edges: &[[u32; 2]], pieces: &[u32]) -> Self {
        let boxes: Vec<Aabb> = triangles.iter().map(|t| Aabb::from_points(&t.map(|i| x[i as usize]))).collect();
        let mut ring_start = vec![0u32; x.len() + 1];
        for &[a, b] in edges {
            ring_start[a as usize + 1] += 1;
            ring_start[b as usize + 1] += 1;
        }
        for i in 0..x.len() {
            ring_start[i + 1] += ring_start[i];
        }
        let mut fill = ring_start.clone();
        let mut ring = vec![0u32; 2 * edges.len()];
        let mut ring_edge = vec![0u32; 2 * edges.len()];
        for (k, &[a, b]) in edges.iter().enumerate() {
            for (from, to) in [(a, b), (b, a)] {
                ring[fill[from as usize] as usize] = to;
                ring_edge[fill[from as usize] as usize] = k as u32;
                fill[from as usize] += 1;
            }
        }
        let tri_piece = triangles.iter().map(|t| pieces.get(t[0] as usize).copied().unwrap_or(0)).collect();
        SelfCollision {
            tree: AabbTree::build(&boxes),
            boxes,
            pairs: Vec::new(),
            previous: Vec::new(),
            ring_start,
            ring,
            ring_edge,
            edges: edges.to_vec(),
            reach: Vec::new(),
            piece: pieces.to_vec(),
            tri_piece,
            through_edges: Vec::new(),
            stats: SelfStats::default(),
        }
    }

    /// The last frame's pairs `(vertex, triangle, side)`: the sides the next frame keeps.
    pub(crate) fn sides(&self) -> &[(u32, u32, f32)] {
        &self.pairs
    }

    /// `new` for a cloth saved mid-run, with the sides its last frame recorded.
    pub(crate) fn with_sides(
        x: &[Vec3],
        triangles: &[[u32; 3]],
        edges: &[[u32; 2]],
        pieces: &[u32],
        sides: &[(u32, u32, f32)],
    ) -> Self {
        SelfCollision { pairs: sides.to_vec(), ..SelfCollision::new(x, triangles, edges, pieces) }
    }

    /// The pairs over the next `dt` from `x` moving at `v` (see the module's doc).
    ///
    /// At the frame start (`within` is `None`): every vertex's (the simulator then untangles,
    /// [`SelfCollision::untangle`], once the seams have closed). Within the frame, for the vertices that
    /// [`SelfCollision::escaped`] (`x` then the positions at the substep's start, before the
    /// escape, each vertex still on its side, and `dt` what is left of the frame): only those
    /// of the vertices near the triangles around an escaped vertex (the others keep theirs; all
    /// when many escaped), their sweeps also taking in where they are now. Pairs a vertex had
    /// keep their sides while in contact (as at a frame's start); the others and new ones take
    /// the side they have in `x`.
    #[allow(clippy::too_many_arguments)] // the cloth's state, as the simulator keeps it
    pub(crate) fn gather(
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
        within: Option<Escape>,
    ) {
        match within {
            None => {
                self.stats = SelfStats::default();
                self.through_edges.clear();
            }
            Some(_) => self.stats.regathers += 1,
        }
        let sweep = |i: usize| {
            let predicted = Aabb::from_points(&[x[i], x[i] + v[i] * (1.25 * dt)]);
            within.map_or(predicted, |w| predicted.grow(w.now[i]))
        };
        let r = 0.5 * (thickness + slack);
        crate::core::parallel::for_each_chunk(&mut self.boxes, BOX_CHUNK, 0, |chunk, out| {
            for (j, out) in out.iter_mut().enumerate() {
                let [a, b, c] = triangles[chunk * BOX_CHUNK + j].map(|i| i as usize);
                *out = sweep(a).union(sweep(b)).union(sweep(c)).inflate(r);
            }
        });
        self.tree.refit(&self.boxes);
        // Those near the triangles around an escaped vertex (as far as its longest edge).
        // Many escaped: every vertex, as cheap as finding them one by one.
        let affected = within.filter(|w| w.escaped.len() * 8 <= x.len()).map(|w| {
            let mut affected = vec![false; x.len()];
            for &e in w.escaped {
                let e = e as usize;
                let ring = &self.ring[self.ring_start[e] as usize..self.ring_start[e + 1] as usize];
                let arm = ring.iter().map(|&u| x[u as usize].distance(x[e])).fold(0.0, f32::max);
                affected[e] = true;
                let q = sweep(e).inflate(r + arm);
                self.tree.query(&q, |t| {
                    if self.boxes[t as usize].overlaps(&q) {
                        triangles[t as usize].iter().for_each(|&c| affected[c as usize] = true)
                    }
                });
            }
            affected
        });
        let gathered = |i: usize| affected.as_ref().is_none_or(|a| a[i]);
        if within.is_none() || self.reach.len() != x.len() {
            self.reach.clear();
            self.reach.resize(x.len(), Aabb::EMPTY);
        }
        crate::core::parallel::for_each_chunk(&mut self.reach, BOX_CHUNK, 0, |chunk, out| {
            for (j, reach) in out.iter_mut().enumerate() {
                let i = chunk * BOX_CHUNK + j;
                if gathered(i) {
                    *reach = sweep(i).inflate(0.5 * slack);
                }
            }
        });
        std::mem::swap(&mut self.pairs, &mut self.previous);
        // Each vertex's pairs (its query of the tree, capped and sorted, with their sides) on
        // the cores in chunks, then appended in vertex order: the same for any thread count.
        let (tree, boxes, previous) = (&self.tree, &self.boxes, &self.previous);
        let capped = crate::core::parallel::flat_in_chunks(x.len(), PAIR_CHUNK, &mut self.pairs, |i, pairs| {
            let had = pairs_of(previous, i);
            if !gathered(i) {
                // Not gathered again: the pairs it has.
                pairs.extend_from_slice(had);
                return false;
            }
            let q = sweep(i).inflate(r);
            let first = pairs.len();
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
            let capped = cap_and_sort(pairs, first);
            for pair in &mut pairs[first..] {
                // In contact, the side last frame had (a pair forced back by the untangling
                // deeper than that is forced again while its crossing is found). The same
                // within a frame: keeping deeper sides there too (all, or the forced ones)
                // pulled vertices back from depth, and the walk gate test's shirt had cloth
                // through cloth in 618 (all) or 148 (forced) of its 630 frames, against 58.
                let tri = triangles[pair.1 as usize].map(|j| x[j as usize]);
                pair.2 = gathered_side(had, pair.1, x[i], tri, thickness);
            }
            capped
        });
        self.stats.capped += capped;
        self.stats.pairs = self.stats.pairs.max(self.pairs.len());
    }

    /// The vertices at `x` that have left the region their frame's pairs were gathered for (their
    /// predicted sweep, widened by half the slack): a fold springing open or a hard push moves
    /// cloth faster than the frame start's velocities said, onto triangles it was not paired
    /// with, and through them. The simulator then gathers again ([`SelfCollision::gather`]).
    pub(crate) fn escaped(&self, x: &[Vec3]) -> Vec<u32> {
        if self.reach.len() != x.len() {
            return Vec::new();
        }
        (0..x.len() as u32).filter(|&i| self.reach[i as usize].margin(x[i as usize]) < 0.0).collect()
    }

    /// Run after the frame start's [`SelfCollision::gather`] once the seams have closed (while
    /// they close, panels pass each other on their way); `welds`: the seam groups, each one point.
    ///
    /// Finds the cloth's edges that cross its triangles at the frame start and pulls what went
    /// through back. Side tracking keeps a vertex on the side it was gathered on, so cloth that
    /// got through (pulled by a seam closing across a folded panel, or out of the pairs' reach
    /// for a frame) would be held on the wrong side for good. Two ways find what is through,
    /// a local form of Baraff, Witkin and Kass's global intersection analysis (2003):
    /// - the crossing edges cut a panel's mesh (sewn vertices block the fill too, as the seam
    ///   bounds a panel); where they cut off a part, the smaller part is through the other
    ///   surface, and each of its vertices' pairs with a triangle near the crossing (a crossed
    ///   triangle of its own piece; of another piece, one sharing a corner with a crossed
    ///   triangle or with a corner in a part that is through) is given the other side;
    /// - an end of a crossing edge whose mesh neighbours lie mostly on the other side of the
    ///   triangle's plane is through it (a sewn end: the neighbours of all the vertices sewn
    ///   there), and so are the vertices sewn to it. Besides its pairs, such an end is pushed
    ///   along the triangle's normal while its edge crosses ([`SelfCollision::solve`]): an
    ///   edge crossing near the triangle's border has its ends off the triangle, where the
    ///   pairs do not act.
    ///
    /// Such pairs are forced: pushed back however deep (a thickness per pair and substep at
    /// most) until back on their side or off the triangle's border, in the frames their
    /// crossing is found (and while within a thickness of the triangle).
    pub(crate) fn untangle(&mut self, x: &[Vec3], rep: &[u32], welds: &Welds, triangles: &[[u32; 3]]) {
        // The candidates of an edge are the triangles its ends are paired with: a crossing
        // farther from both ends than the pairs reach (long edges) is not found.
        let mut first = vec![0u32; x.len() + 1];
        for p in &self.pairs {
            first[p.0 as usize + 1] += 1;
        }
        for i in 0..x.len() {
            first[i + 1] += first[i];
        }
        let (edges, pairs) = (&self.edges, &self.pairs);
        let of = |v: u32| &pairs[first[v as usize] as usize..first[v as usize + 1] as usize];
        let found = crate::core::parallel::map_in_chunks(edges.len(), PAIR_CHUNK, |k| {
            let [ia, ib] = edges[k];
            let (a, b) = (x[ia as usize], x[ib as usize]);
            let ends = [rep[ia as usize], rep[ib as usize]];
            let mut hits: Vec<u32> = Vec::new();
            for &(_, t, _) in of(ia).iter().chain(of(ib)) {
                let tri = triangles[t as usize];
                if hits.contains(&t) || tri.iter().any(|&j| ends.contains(&rep[j as usize])) {
                    continue;
                }
                let [p0, p1, p2] = tri.map(|j| x[j as usize]);
                if super::intersections::segment_hits_triangle(a, b, p0, p1, p2) {
                    hits.push(t);
                }
            }
            hits.sort_unstable();
            hits
        });
        let crossing: Vec<(usize, u32)> =
            found.iter().enumerate().flat_map(|(k, hits)| hits.iter().map(move |&t| (k, t))).collect();
        self.stats.crossings = crossing.len();
        if crossing.is_empty() {
            return;
        }
        let n = x.len();
        let range = |v: u32| first[v as usize] as usize..first[v as usize + 1] as usize;
        // Pairs to force: (index in `pairs`, side it belongs on).
        let mut force: Vec<(usize, f32)> = Vec::new();

        // The parts the crossing edges cut off.
        let mut cut = vec![false; edges.len()];
        for &(k, _) in &crossing {
            cut[k] = true;
        }
        let sewn = |v: u32| welds.is_sewn(v);
        let mut part = vec![u32::MAX; n];
        let mut sizes: Vec<usize> = Vec::new();
        let mut stack = Vec::new();
        for &(k, _) in &crossing {
            for v in edges[k] {
                if sewn(v) || part[v as usize] != u32::MAX {
                    continue;
                }
                let id = sizes.len() as u32;
                part[v as usize] = id;
                stack.push(v);
                let mut size = 0;
                while let Some(u) = stack.pop() {
                    size += 1;
                    let (lo, hi) = (self.ring_start[u as usize] as usize, self.ring_start[u as usize + 1] as usize);
                    for j in lo..hi {
                        let w = self.ring[j];
                        if !cut[self.ring_edge[j] as usize] && !sewn(w) && part[w as usize] == u32::MAX {
                            part[w as usize] = id;
                            stack.push(w);
                        }
                    }
                }
                sizes.push(size);
            }
        }
        // Of a cut edge whose ends fell into two parts, the smaller part is through.
        let mut through_part = vec![false; sizes.len()];
        for &(k, _) in &crossing {
            let [a, b] = edges[k].map(|v| part[v as usize]);
            if a != u32::MAX && b != u32::MAX && a != b {
                let smaller = if sizes[a as usize] <= sizes[b as usize] { a } else { b };
                through_part[smaller as usize] = true;
            }
        }
        if through_part.iter().any(|&t| t) {
            // Near the crossing: the crossed triangles, those sharing a corner with them, and
            // those with a corner in a part that is through.
            let mut near_vertex = vec![false; n];
            for &(_, t) in &crossing {
                for v in triangles[t as usize] {
                    near_vertex[v as usize] = true;
                }
            }
            let crossed: std::collections::HashSet<u32> = crossing.iter().map(|c| c.1).collect();
            let in_through = |v: u32| part[v as usize] != u32::MAX && through_part[part[v as usize] as usize];
            for v in 0..n as u32 {
                if !in_through(v) {
                    continue;
                }
                for k in range(v) {
                    let t = self.pairs[k].1;
                    let tri = triangles[t as usize];
                    // Within its own piece only a crossed triangle: the rest of the piece
                    // around it is flat beside it, not across.
                    let other_piece = self.tri_piece[t as usize] != self.piece.get(v as usize).copied().unwrap_or(0);
                    let near = crossed.contains(&t)
                        || (other_piece && tri.iter().any(|&c| near_vertex[c as usize] || in_through(c)));
                    if !near {
                        continue;
                    }
                    let [a, b, c] = tri.map(|j| x[j as usize]);
                    let d = (x[v as usize] - a).dot((b - a).cross(c - a));
                    if d != 0.0 {
                        force.push((k, -d.signum()));
                    }
                }
            }
        }

        // Ends of crossing edges through the triangle by their neighbours.
        // Such an end (with the vertices sewn there with it) is also pushed along the
        // triangle's normal while its edge crosses: its pairs act only over the triangle, and
        // an edge crossing near the border has its ends off it.
        let mut through: Vec<u32> = Vec::new();
        for &(k, t) in &crossing {
            let tri = triangles[t as usize];
            for (v, other) in [(edges[k][0], edges[k][1]), (edges[k][1], edges[k][0])] {
                if let Some(side) = self.through_side(x, rep, welds, v, tri) {
                    through.push(v);
                    self.through_edges.extend(welds.members(v).map(|m| (m, other, t, side)));
                }
            }
        }
        through.sort_unstable();
        through.dedup();
        for v in through {
            for k in range(v) {
                if let Some(side) = self.through_side(x, rep, welds, v, triangles[self.pairs[k].1 as usize]) {
                    force.push((k, side));
                }
            }
        }
        // A sewn vertex goes through with the vertices it is sewn to: forced alone, the others'
        // pairs with the triangle held it where it was.
        for i in 0..force.len() {
            let (k, side) = force[i];
            let (v, t) = (self.pairs[k].0, self.pairs[k].1);
            for u in welds.members(v).filter(|&u| u != v) {
                let of_u = &self.pairs[range(u)];
                if let Ok(j) = of_u.binary_search_by_key(&t, |p| p.1) {
                    force.push((first[u as usize] as usize + j, side));
                }
            }
        }
        // A pair found both ways once (both give the side opposite the vertex's).
        force.sort_unstable_by_key(|f| f.0);
        force.dedup_by_key(|f| f.0);
        for (k, side) in force {
            self.pairs[k].2 = FORCED * side;
            self.stats.forced += 1;
        }
    }

    /// The side of `tri`'s plane that a point of the garment (vertex `v` with the vertices
    /// welded to it) belongs on, when it is on the other: at least two thirds of its mesh
    /// neighbours (two or more, not sewn to the triangle) are there.
    fn through_side(&self, x: &[Vec3], rep: &[u32], welds: &Welds, v: u32, tri: [u32; 3]) -> Option<f32> {
        let [a, b, c] = tri.map(|j| x[j as usize]);
        let n = (b - a).cross(c - a);
        let side = |p: Vec3| (p - a).dot(n);
        let own = side(x[v as usize]);
        if own == 0.0 {
            return None;
        }
        let corners = tri.map(|j| rep[j as usize]);
        let (mut counted, mut other) = (0, 0);
        for m in welds.members(v) {
            for &u in &self.ring[self.ring_start[m as usize] as usize..self.ring_start[m as usize + 1] as usize] {
                if corners.contains(&rep[u as usize]) {
                    continue;
                }
                counted += 1;
                other += usize::from(side(x[u as usize]) * own < 0.0);
            }
        }
        (counted >= 2 && 3 * other >= 2 * counted).then(|| -own.signum())
    }

    /// One Gauss-Seidel sweep over the pairs.
    /// `prev` are the positions at the substep's start: a vertex can get
    /// behind a triangle by at most what the two moved.
    ///
    /// Few pairs act in a substep: which would (push, or set their side) is found on the cores
    /// from the positions before the sweep, and the sweep in order visits those and the pairs
    /// with a vertex an earlier contact of the sweep moved. A pair's action depends only on its
    /// four vertices and its side, so the result is the one of visiting every pair.
    pub(crate) fn solve(&mut self, x: &mut [Vec3], prev: &[Vec3], w: &[f32], triangles: &[[u32; 3]], thickness: f32) {
        let mut acts = vec![false; self.pairs.len()];
        {
            let (pairs, x) = (&self.pairs, &*x);
            crate::core::parallel::for_each_chunk(&mut acts, SOLVE_CHUNK, 0, |c, out| {
                for (j, flag) in out.iter_mut().enumerate() {
                    let mut pair = pairs[c * SOLVE_CHUNK + j];
                    let side = pair.2;
                    *flag = pair_contact(&mut pair, x, prev, w, triangles, thickness).is_some() || pair.2 != side;
                }
            });
        }
        let mut moved = vec![false; x.len()];
        for (k, pair) in self.pairs.iter_mut().enumerate() {
            let (i, t) = (pair.0 as usize, pair.1 as usize);
            let [ia, ib, ic] = triangles[t].map(|j| j as usize);
            if !acts[k] && !moved[i] && !moved[ia] && !moved[ib] && !moved[ic] {
                continue;
            }
            let Some((n, s, [ba, bu, bv])) = pair_contact(pair, x, prev, w, triangles, thickness) else {
                continue;
            };
            x[i] += n * (w[i] * s);
            x[ia] -= n * (w[ia] * ba * s);
            x[ib] -= n * (w[ib] * bu * s);
            x[ic] -= n * (w[ic] * bv * s);
            for v in [i, ia, ib, ic] {
                moved[v] = true;
            }
            self.stats.contacts += 1;
        }
        for &(v, other, t, side) in &self.through_edges {
            let tri = triangles[t as usize];
            let [a, b, c] = tri.map(|j| x[j as usize]);
            let p = x[v as usize];
            // Where the edge crosses carries the triangle's share.
            let Some(bary) = super::intersections::segment_triangle_hit(p, x[other as usize], a, b, c) else {
                continue;
            };
            let n = (b - a).cross(c - a).normalize_or_zero() * side;
            let dp = (p - a).dot(n);
            if dp >= 0.0 {
                continue;
            }
            let wsum = w[v as usize] + (0..3).map(|j| w[tri[j] as usize] * bary[j] * bary[j]).sum::<f32>();
            if wsum == 0.0 {
                continue;
            }
            let step = (thickness - dp).min(thickness) / wsum;
            x[v as usize] += n * (w[v as usize] * step);
            for j in 0..3 {
                x[tri[j] as usize] -= n * (w[tri[j] as usize] * bary[j] * step);
            }
            // Its pair with the triangle, if it has one, goes with it.
            if let Ok(k) = self.pairs.binary_search_by_key(&(v, t), |p| (p.0, p.1)) {
                self.pairs[k].2 = FORCED * side;
            }
            self.stats.contacts += 1;
        }
    }
}

/// A self-contact pair's push (normal, step along it per inverse mass, barycentrics), with its
/// side tracked ([`track_side`]).
#[inline]
fn pair_contact(
    pair: &mut (u32, u32, f32),
    x: &[Vec3],
    prev: &[Vec3],
    w: &[f32],
    triangles: &[[u32; 3]],
    thickness: f32,
) -> Option<(Vec3, f32, [f32; 3])> {
    let (i, t) = (pair.0 as usize, pair.1);
    let [ia, ib, ic] = triangles[t as usize].map(|j| j as usize);
    let moved = |k: usize| x[k].distance(prev[k]);
    let reach = || thickness + moved(i) + moved(ia).max(moved(ib)).max(moved(ic));
    let forced = pair.2.abs() > 1.0;
    let (n, d, [ba, bu, bv]) = track_side(x[i], [x[ia], x[ib], x[ic]], &mut pair.2, thickness, reach)?;
    let wsum = w[i] + w[ia] * ba * ba + w[ib] * bu * bu + w[ic] * bv * bv;
    if wsum == 0.0 {
        return None;
    }
    // What went through comes back a thickness a substep at most, not in one jump.
    let push = if forced { (thickness - d).min(thickness) } else { thickness - d };
    Some((n, push / wsum, [ba, bu, bv]))
}

/// The side tracking shared by vertex-triangle pairs: returns the unit
/// normal pointing to the recorded `side`, the distance `d` of `p` along it
/// and the projection's barycentrics when `p` must be pushed (over the
/// triangle, closer than `thickness` on the recorded side or behind it by
/// less than `reach`, what the two moved this substep, asked only then: most pairs are
/// farther than the thickness, and the four distances cost more than the rest). Where `p` is not over
/// the triangle, or farther behind than it can have got by passing through
/// it, the side is updated instead: `p` went around the border.
#[inline]
pub(crate) fn track_side(
    p: Vec3,
    tri: [Vec3; 3],
    side: &mut f32,
    thickness: f32,
    reach: impl FnOnce() -> f32,
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
    let forced = side.abs() > 1.0;
    let sign = side.signum();
    let d = d_raw * sign;
    if forced && d >= 0.0 {
        // Back on its side: an ordinary pair again.
        *side = sign;
    }
    if d >= thickness {
        return None;
    }
    let inv = 1.0 / len2;
    let bu = rel.cross(e2).dot(cross) * inv;
    let bv = e1.cross(rel).dot(cross) * inv;
    let ba = 1.0 - bu - bv;
    let eps = -0.05;
    if ba < eps || bu < eps || bv < eps {
        // Around the border: an ordinary side again (a forced one too, or it would push the
        // vertex through from wherever it comes back over the triangle).
        if d_raw != 0.0 {
            *side = d_raw.signum();
        }
        return None;
    }
    if side.abs() <= 1.0 && d < -reach() {
        if d_raw != 0.0 {
            *side = d_raw.signum();
        }
        return None;
    }
    Some((n * sign, d, [ba, bu, bv]))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::cloth::intersections::count_self_crossings;

    const CM: f32 = 0.01;

    /// Triangle 0 1 2 (piece 1) in the plane z = 0 and vertex 3 half a millimetre under it just
    /// off its border, with an edge 3-4 up through the triangle (the rest of piece 0 around
    /// 3 lies above): 3 is through, and not over the triangle, so its pair never pushes it.
    /// `sewn`: 3 has one neighbour above and one below, and a vertex of piece 2 sewn to it has
    /// two above: only the two together say where the point belongs.
    fn crossing_off_the_border(sewn: bool) -> (Vec<Vec3>, Vec<[u32; 3]>, Vec<u32>, Vec<u32>) {
        let p = |x: f32, y: f32, z_mm: f32| Vec3::new(x * CM, y * CM, z_mm * 0.001);
        let mut x = vec![p(0.0, 0.0, 0.0), p(2.0, 0.0, 0.0), p(0.0, 2.0, 0.0), p(-0.1, 0.6, -0.5), p(1.0, 0.6, 2.0)];
        let (triangles, pieces, rep);
        if sewn {
            x.extend([p(-2.0, 0.9, -0.5), x[3], p(-0.6, 0.2, 2.5), p(-1.0, 0.6, 2.5)]);
            triangles = vec![[0, 1, 2], [3, 4, 5], [6, 7, 8]];
            pieces = vec![1, 1, 1, 0, 0, 0, 2, 2, 2];
            rep = vec![0, 1, 2, 3, 4, 5, 3, 7, 8];
        } else {
            x.extend([p(-0.6, 1.0, 2.5), p(-0.6, 0.2, 2.5)]);
            triangles = vec![[0, 1, 2], [3, 4, 5], [3, 6, 4]];
            pieces = vec![1, 1, 1, 0, 0, 0, 0];
            rep = (0..7).collect();
        }
        (x, triangles, pieces, rep)
    }

    /// Three frames of 20 substeps of the scene's contacts, from the tangled start: no edge
    /// crosses after, and `through` are over the triangle's plane again.
    fn assert_untangled(sewn: bool, through: &[usize]) {
        let (mut x, triangles, pieces, rep) = crossing_off_the_border(sewn);
        let mut edges: Vec<[u32; 2]> = triangles
            .iter()
            .flat_map(|t| [[t[0], t[1]], [t[1], t[2]], [t[2], t[0]]])
            .map(|[a, b]| [a.min(b), a.max(b)])
            .collect();
        edges.sort_unstable();
        edges.dedup();
        let before = count_self_crossings(&x, &rep, &edges, &triangles);
        let (n, thickness) = (x.len(), 0.002);
        let (v, w) = (vec![Vec3::ZERO; n], vec![1.0; n]);
        let mut group_of = vec![u32::MAX; n];
        let groups: Vec<Vec<u32>> = if sewn { vec![vec![3, 6]] } else { Vec::new() };
        groups.iter().flatten().for_each(|&v| group_of[v as usize] = 0);
        let welds = Welds { group_of: &group_of, groups: &groups };
        let mut sc = SelfCollision::new(&x, &triangles, &edges, &pieces);
        for _ in 0..3 {
            sc.gather(&x, &v, &w, &rep, &[], &triangles, 1.0 / 60.0, thickness, 0.001, None);
            sc.untangle(&x, &rep, &welds, &triangles);
            for _ in 0..20 {
                let prev = x.clone();
                sc.solve(&mut x, &prev, &w, &triangles, thickness);
                // The weld, as the simulator keeps sewn vertices together.
                if sewn {
                    let mid = (x[3] + x[6]) * 0.5;
                    (x[3], x[6]) = (mid, mid);
                }
            }
        }
        let after = count_self_crossings(&x, &rep, &edges, &triangles);
        assert!(before > 0, "the scene starts tangled");
        assert_eq!(after, 0, "{before} crossings at the start");
        let normal = (x[1] - x[0]).cross(x[2] - x[0]).normalize();
        for &v in through {
            assert!((x[v] - x[0]).dot(normal) > 0.0, "vertex {v} at {} is back over the triangle's plane", x[v]);
        }
    }

    #[test]
    fn a_vertex_through_a_triangle_off_its_border_is_pushed_back_along_its_edge() {
        assert_untangled(false, &[3]);
    }

    #[test]
    fn sewn_vertices_are_judged_and_pushed_as_one_point() {
        assert_untangled(true, &[3, 6]);
    }
}

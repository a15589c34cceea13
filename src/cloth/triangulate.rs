//! Constrained Delaunay triangulation of a simple polygon with extra points.
//!
//! The outline corners are ear-clipped first, so the boundary is exactly the
//! polygon (the triangulation always covers its area, also for concave
//! outlines). Boundary subdivision points and interior points are then
//! inserted one by one with Lawson flips; boundary edges have no neighbour and
//! are therefore never flipped, which makes the result the constrained
//! Delaunay triangulation of all points. All arithmetic is f64 and the order
//! of operations is fixed, so the output is deterministic.

use glam::DVec2;

const NONE: u32 = u32::MAX;

#[derive(Clone, Copy, Debug)]
struct Tri {
    /// Vertices, counter-clockwise.
    v: [u32; 3],
    /// `n[k]` is the triangle across edge `(v[k], v[(k + 1) % 3])`, or `NONE`
    /// on the polygon boundary.
    n: [u32; 3],
}

fn orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

/// Positive when `d` lies strictly inside the circumcircle of CCW `(a, b, c)`.
fn incircle(a: DVec2, b: DVec2, c: DVec2, d: DVec2) -> f64 {
    let (ad, bd, cd) = (a - d, b - d, c - d);
    let (a2, b2, c2) = (ad.length_squared(), bd.length_squared(), cd.length_squared());
    ad.x * (bd.y * c2 - b2 * cd.y) - ad.y * (bd.x * c2 - b2 * cd.x) + a2 * (bd.x * cd.y - bd.y * cd.x)
}

/// Which kind of point is being inserted.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Kind {
    /// On a known boundary edge of the outline.
    Boundary,
    /// Strictly inside the polygon.
    Interior,
}

pub(crate) struct Triangulator {
    pts: Vec<DVec2>,
    tris: Vec<Tri>,
    /// Length scale used to make the geometric tolerances relative.
    scale: f64,
    /// Triangle where the last point location ended; the next walk starts here.
    hint: u32,
    stack: Vec<(u32, usize)>,
}

#[derive(Debug)]
pub(crate) enum TriangulateError {
    TooFewCorners,
    NotCounterClockwise,
    /// Ear clipping found no ear: the outline self-intersects.
    NotSimple,
    /// A point could not be located inside the polygon.
    PointOutside,
}

impl Triangulator {
    /// Triangulates the outline (CCW, no repeated closing vertex). Vertex ids
    /// `0..outline.len()` are the corners.
    pub(crate) fn new(outline: &[DVec2]) -> Result<Self, TriangulateError> {
        let m = outline.len();
        if m < 3 {
            return Err(TriangulateError::TooFewCorners);
        }
        let area2: f64 = (0..m).map(|i| outline[i].perp_dot(outline[(i + 1) % m])).sum();
        if area2 <= 0.0 {
            return Err(TriangulateError::NotCounterClockwise);
        }
        let (lo, hi) = outline.iter().fold((outline[0], outline[0]), |(lo, hi), &p| (lo.min(p), hi.max(p)));
        let scale = (hi - lo).max_element().max(f64::MIN_POSITIVE);
        let mut t = Triangulator { pts: outline.to_vec(), tris: Vec::new(), scale, hint: 0, stack: Vec::new() };
        if !is_simple(outline) {
            return Err(TriangulateError::NotSimple);
        }
        let ears = ear_clip(outline, scale)?;
        t.tris = ears.into_iter().map(|v| Tri { v, n: [NONE; 3] }).collect();
        t.link_adjacency();
        // Make the ear-clipped triangulation constrained-Delaunay before
        // inserting points, so every later insertion starts from a CDT.
        for ti in 0..t.tris.len() as u32 {
            for k in 0..3 {
                t.stack.push((ti, k));
            }
        }
        t.drain_flips();
        Ok(t)
    }

    pub(crate) fn points(&self) -> &[DVec2] {
        &self.pts
    }

    pub(crate) fn triangles(&self) -> impl Iterator<Item = [u32; 3]> + '_ {
        self.tris.iter().map(|t| t.v)
    }

    /// Rebuilds neighbour links from scratch by sorting directed edges; only
    /// used once after ear clipping.
    fn link_adjacency(&mut self) {
        let mut edges: Vec<(u32, u32, u32, usize)> = Vec::with_capacity(self.tris.len() * 3);
        for (ti, t) in self.tris.iter().enumerate() {
            for k in 0..3 {
                let (a, b) = (t.v[k], t.v[(k + 1) % 3]);
                edges.push((a.min(b), a.max(b), ti as u32, k));
            }
        }
        edges.sort_unstable();
        for w in edges.windows(2) {
            if w[0].0 == w[1].0 && w[0].1 == w[1].1 {
                self.tris[w[0].2 as usize].n[w[0].3] = w[1].2;
                self.tris[w[1].2 as usize].n[w[1].3] = w[0].2;
            }
        }
    }

    fn replace_neighbor(&mut self, t: u32, old: u32, new: u32) {
        if t == NONE {
            return;
        }
        let tri = &mut self.tris[t as usize];
        for k in 0..3 {
            if tri.n[k] == old {
                tri.n[k] = new;
                return;
            }
        }
    }

    /// Flips edges from the stack until all of them are locally Delaunay.
    fn drain_flips(&mut self) {
        let eps = 1e-12 * self.scale.powi(4);
        while let Some((t, k)) = self.stack.pop() {
            let tri = self.tris[t as usize];
            let u = tri.n[k];
            if u == NONE {
                continue;
            }
            let ut = self.tris[u as usize];
            let Some(ku) = (0..3).find(|&j| ut.n[j] == t) else {
                continue;
            };
            let (a, b, c) = (tri.v[k], tri.v[(k + 1) % 3], tri.v[(k + 2) % 3]);
            let d = ut.v[(ku + 2) % 3];
            let p = |i: u32| self.pts[i as usize];
            if incircle(p(a), p(b), p(c), p(d)) <= eps {
                continue;
            }
            let n_bc = tri.n[(k + 1) % 3];
            let n_ca = tri.n[(k + 2) % 3];
            let n_ad = ut.n[(ku + 1) % 3];
            let n_db = ut.n[(ku + 2) % 3];
            // Quad a, d, b, c (CCW) gets the diagonal c-d.
            self.tris[t as usize] = Tri { v: [c, a, d], n: [n_ca, n_ad, u] };
            self.tris[u as usize] = Tri { v: [d, b, c], n: [n_db, n_bc, t] };
            self.replace_neighbor(n_ad, u, t);
            self.replace_neighbor(n_bc, t, u);
            self.stack.extend([(t, 0), (t, 1), (u, 0), (u, 1)]);
        }
    }

    /// Barycentric-sign location of `p` in triangle `t`: the signed
    /// orientations of `p` against the three edges.
    fn edge_orients(&self, t: u32, p: DVec2) -> [f64; 3] {
        let v = self.tris[t as usize].v;
        let q = |i: usize| self.pts[v[i] as usize];
        [orient(q(0), q(1), p), orient(q(1), q(2), p), orient(q(2), q(0), p)]
    }

    /// Finds a triangle containing `p` (edges included): a visibility walk
    /// from the previous hit, with a brute-force scan as fallback (the walk
    /// can leave a concave domain or, rarely, cycle).
    fn locate(&self, p: DVec2) -> Option<u32> {
        let eps = 1e-12 * self.scale * self.scale;
        let mut t = self.hint.min(self.tris.len() as u32 - 1);
        let limit = 4 * (self.tris.len() as f64).sqrt() as usize + 64;
        'walk: for step in 0..limit {
            let o = self.edge_orients(t, p);
            for j in 0..3 {
                // Rotate the start edge so the walk does not cycle on ties.
                let k = (j + step) % 3;
                if o[k] < -eps {
                    let next = self.tris[t as usize].n[k];
                    if next == NONE {
                        break 'walk;
                    }
                    t = next;
                    continue 'walk;
                }
            }
            return Some(t);
        }
        (0..self.tris.len() as u32).find(|&t| self.edge_orients(t, p).iter().all(|&o| o >= -eps))
    }

    /// Inserts a point on outline edge `(a, b)` (`a`→`b` CCW along the
    /// boundary, the point strictly between them). Returns its vertex id.
    pub(crate) fn insert_on_boundary(&mut self, p: DVec2, a: u32, b: u32) -> Result<u32, TriangulateError> {
        let found = self.tris.iter().enumerate().find_map(|(ti, t)| {
            (0..3).find(|&k| t.v[k] == a && t.v[(k + 1) % 3] == b && t.n[k] == NONE).map(|k| (ti as u32, k))
        });
        let (t, k) = found.ok_or(TriangulateError::PointOutside)?;
        Ok(self.split_edge(t, k, p, Kind::Boundary))
    }

    /// Inserts a point strictly inside the polygon. Returns its vertex id.
    pub(crate) fn insert_interior(&mut self, p: DVec2) -> Result<u32, TriangulateError> {
        let t = self.locate(p).ok_or(TriangulateError::PointOutside)?;
        self.hint = t;
        let o = self.edge_orients(t, p);
        let v = self.tris[t as usize].v;
        // A point (numerically) on an edge splits that edge instead of making
        // a zero-area triangle.
        for k in 0..3 {
            let len = (self.pts[v[(k + 1) % 3] as usize] - self.pts[v[k] as usize]).length();
            if o[k].abs() <= 1e-9 * self.scale * len {
                if self.tris[t as usize].n[k] == NONE {
                    return Err(TriangulateError::PointOutside);
                }
                return Ok(self.split_edge(t, k, p, Kind::Interior));
            }
        }
        let id = self.push_point(p);
        let tri = self.tris[t as usize];
        let [a, b, c] = tri.v;
        let [n_ab, n_bc, n_ca] = tri.n;
        let t1 = self.tris.len() as u32;
        let t2 = t1 + 1;
        self.tris[t as usize] = Tri { v: [a, b, id], n: [n_ab, t1, t2] };
        self.tris.push(Tri { v: [b, c, id], n: [n_bc, t2, t] });
        self.tris.push(Tri { v: [c, a, id], n: [n_ca, t, t1] });
        self.replace_neighbor(n_bc, t, t1);
        self.replace_neighbor(n_ca, t, t2);
        self.stack.extend([(t, 0), (t1, 0), (t2, 0)]);
        self.drain_flips();
        Ok(id)
    }

    fn push_point(&mut self, p: DVec2) -> u32 {
        self.pts.push(p);
        (self.pts.len() - 1) as u32
    }

    /// Splits edge `k` of triangle `t` at `p` (and the neighbour across it,
    /// if any).
    fn split_edge(&mut self, t: u32, k: usize, p: DVec2, kind: Kind) -> u32 {
        let id = self.push_point(p);
        let tri = self.tris[t as usize];
        let (a, b, c) = (tri.v[k], tri.v[(k + 1) % 3], tri.v[(k + 2) % 3]);
        let u = tri.n[k];
        let n_bc = tri.n[(k + 1) % 3];
        let n_ca = tri.n[(k + 2) % 3];
        let t2 = self.tris.len() as u32;
        debug_assert!(kind == Kind::Interior || u == NONE);
        if u == NONE {
            self.tris[t as usize] = Tri { v: [a, id, c], n: [NONE, t2, n_ca] };
            self.tris.push(Tri { v: [id, b, c], n: [NONE, n_bc, t] });
            self.replace_neighbor(n_bc, t, t2);
            self.stack.extend([(t, 2), (t2, 1)]);
        } else {
            let ut = self.tris[u as usize];
            let ku = (0..3).find(|&j| ut.n[j] == t).expect("adjacency is symmetric");
            let d = ut.v[(ku + 2) % 3];
            let n_ad = ut.n[(ku + 1) % 3];
            let n_db = ut.n[(ku + 2) % 3];
            let u2 = t2 + 1;
            self.tris[t as usize] = Tri { v: [a, id, c], n: [u2, t2, n_ca] };
            self.tris.push(Tri { v: [id, b, c], n: [u, n_bc, t] });
            self.tris[u as usize] = Tri { v: [b, id, d], n: [t2, u2, n_db] };
            self.tris.push(Tri { v: [id, a, d], n: [t, n_ad, u] });
            self.replace_neighbor(n_bc, t, t2);
            self.replace_neighbor(n_ad, u, u2);
            self.stack.extend([(t, 2), (t2, 1), (u, 2), (u2, 1)]);
        }
        self.drain_flips();
        id
    }
}

/// Ear clipping of a CCW simple polygon. Near-collinear corners are clipped
/// last; the Lawson pass afterwards removes the slivers they leave.
fn ear_clip(outline: &[DVec2], scale: f64) -> Result<Vec<[u32; 3]>, TriangulateError> {
    let m = outline.len();
    let mut prev: Vec<usize> = (0..m).map(|i| (i + m - 1) % m).collect();
    let mut next: Vec<usize> = (0..m).map(|i| (i + 1) % m).collect();
    let mut alive = m;
    let mut out = Vec::with_capacity(m - 2);
    let eps = 1e-12 * scale * scale;
    let mut cur = 0;
    while alive > 3 {
        let mut best: Option<(usize, f64)> = None;
        let mut i = cur;
        for _ in 0..alive {
            let (a, b, c) = (prev[i], i, next[i]);
            let o = orient(outline[a], outline[b], outline[c]);
            if o > eps && !any_inside(outline, &next, a, b, c, eps) {
                best = Some((i, o));
                break;
            }
            i = next[i];
        }
        let Some((ear, _)) = best else {
            return Err(TriangulateError::NotSimple);
        };
        out.push([prev[ear] as u32, ear as u32, next[ear] as u32]);
        next[prev[ear]] = next[ear];
        prev[next[ear]] = prev[ear];
        cur = next[ear];
        alive -= 1;
    }
    let (a, b, c) = (prev[cur], cur, next[cur]);
    if orient(outline[a], outline[b], outline[c]) <= eps {
        return Err(TriangulateError::NotSimple);
    }
    out.push([a as u32, b as u32, c as u32]);
    Ok(out)
}

/// O(m²) check that no two non-adjacent outline edges touch. Outlines are
/// hand-made corner lists, so m is small.
fn is_simple(outline: &[DVec2]) -> bool {
    let m = outline.len();
    let seg = |i: usize| (outline[i], outline[(i + 1) % m]);
    for i in 0..m {
        for j in i + 1..m {
            let adjacent = j == i + 1 || (i == 0 && j == m - 1);
            let (a, b) = seg(i);
            let (c, d) = seg(j);
            if adjacent {
                // Adjacent edges may only share their common corner; they
                // overlap when the outline folds back on itself.
                let (shared, p, q) = if j == i + 1 { (b, a, d) } else { (a, b, c) };
                let (u, w) = (p - shared, q - shared);
                if u.perp_dot(w) == 0.0 && u.dot(w) > 0.0 {
                    return false;
                }
                continue;
            }
            if segments_touch(a, b, c, d) {
                return false;
            }
        }
    }
    true
}

fn segments_touch(a: DVec2, b: DVec2, c: DVec2, d: DVec2) -> bool {
    let (o1, o2) = (orient(a, b, c), orient(a, b, d));
    let (o3, o4) = (orient(c, d, a), orient(c, d, b));
    let on = |p: DVec2, q: DVec2, r: DVec2| {
        r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
        return true;
    }
    (o1 == 0.0 && on(a, b, c)) || (o2 == 0.0 && on(a, b, d)) || (o3 == 0.0 && on(c, d, a)) || (o4 == 0.0 && on(c, d, b))
}

/// True when another remaining polygon vertex lies inside or on triangle
/// `(a, b, c)`; such a vertex would be cut off or left on a diagonal.
fn any_inside(outline: &[DVec2], next: &[usize], a: usize, b: usize, c: usize, eps: f64) -> bool {
    let (pa, pb, pc) = (outline[a], outline[b], outline[c]);
    let mut j = next[c];
    while j != a {
        let p = outline[j];
        if p != pa
            && p != pb
            && p != pc
            && orient(pa, pb, p) >= -eps
            && orient(pb, pc, p) >= -eps
            && orient(pc, pa, p) >= -eps
        {
            return true;
        }
        j = next[j];
    }
    false
}

#[cfg(test)]
mod tests {
    use super::*;

    fn area(t: &Triangulator) -> f64 {
        t.triangles()
            .map(|[a, b, c]| {
                let p = t.points();
                0.5 * orient(p[a as usize], p[b as usize], p[c as usize])
            })
            .sum()
    }

    #[test]
    fn concave_outline_is_covered_exactly() {
        // An L shape: the reflex corner must not be cut off.
        let l = [(0.0, 0.0), (2.0, 0.0), (2.0, 1.0), (1.0, 1.0), (1.0, 2.0), (0.0, 2.0)].map(|(x, y)| DVec2::new(x, y));
        let mut t = Triangulator::new(&l).unwrap();
        assert!((area(&t) - 3.0).abs() < 1e-12);
        t.insert_interior(DVec2::new(0.5, 0.5)).unwrap();
        t.insert_interior(DVec2::new(0.5, 1.5)).unwrap();
        // The midpoint of an existing interior edge takes the edge-split
        // path (four triangles replace two); splitting the containing
        // triangle in three instead would leave a zero-area sliver.
        let (ti, k) = (0..t.tris.len())
            .flat_map(|ti| (0..3).map(move |k| (ti, k)))
            .find(|&(ti, k)| t.tris[ti].n[k] != NONE)
            .unwrap();
        let v = t.tris[ti].v;
        let mid = 0.5 * (t.pts[v[k] as usize] + t.pts[v[(k + 1) % 3] as usize]);
        let before = t.tris.len();
        t.insert_interior(mid).unwrap();
        assert_eq!(t.tris.len(), before + 2);
        for tri in &t.tris {
            let [a, b, c] = tri.v.map(|i| t.pts[i as usize]);
            assert!(orient(a, b, c) > 1e-6);
        }
        t.insert_on_boundary(DVec2::new(1.0, 0.0), 0, 1).unwrap();
        assert!((area(&t) - 3.0).abs() < 1e-12);
        for [a, b, c] in t.triangles() {
            let p = t.points();
            assert!(orient(p[a as usize], p[b as usize], p[c as usize]) > 0.0);
        }
        // Euler for a disc: T = 2 * interior + boundary - 2.
        assert_eq!(t.triangles().count(), 2 * 3 + 7 - 2);
    }

    #[test]
    fn rejects_clockwise_and_self_intersecting() {
        let cw = [(0.0, 0.0), (0.0, 1.0), (1.0, 1.0), (1.0, 0.0)].map(|(x, y)| DVec2::new(x, y));
        assert!(matches!(Triangulator::new(&cw), Err(TriangulateError::NotCounterClockwise)));
        // A bow tie whose net signed area is positive, so only the
        // simplicity check can reject it.
        let bow = [(0.0, 0.0), (4.0, 0.0), (0.0, 3.0), (1.0, 4.0)].map(|(x, y)| DVec2::new(x, y));
        assert!(matches!(Triangulator::new(&bow), Err(TriangulateError::NotSimple)));
    }
}

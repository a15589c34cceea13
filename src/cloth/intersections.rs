//! Measures of a cloth state: edges crossing the body or the cloth itself,
//! clearance, speed. GarmentCode's quality gate counts the same crossings
//! (it fails a drape above 35 body and 300 self crossings); here the
//! target is zero.

use glam::Vec3;

use super::bvh::{Aabb, AabbTree};

/// Whether segment `a`-`b` crosses triangle `p0 p1 p2` (Möller-Trumbore;
/// touching within float precision counts as crossing, a segment in the
/// triangle's plane does not).
pub fn segment_hits_triangle(a: Vec3, b: Vec3, p0: Vec3, p1: Vec3, p2: Vec3) -> bool {
    segment_triangle_hit(a, b, p0, p1, p2).is_some()
}

/// Where segment `a`-`b` crosses triangle `p0 p1 p2`, as the triangle's barycentrics there (by
/// [`segment_hits_triangle`]'s rule).
pub fn segment_triangle_hit(a: Vec3, b: Vec3, p0: Vec3, p1: Vec3, p2: Vec3) -> Option<[f32; 3]> {
    let d = b - a;
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    let pv = d.cross(e2);
    let det = e1.dot(pv);
    if det.abs() < 1e-14 {
        return None;
    }
    let inv = 1.0 / det;
    let tv = a - p0;
    let u = tv.dot(pv) * inv;
    if !(0.0..=1.0).contains(&u) {
        return None;
    }
    let qv = tv.cross(e1);
    let v = d.dot(qv) * inv;
    if v < 0.0 || u + v > 1.0 {
        return None;
    }
    let t = e2.dot(qv) * inv;
    (0.0..=1.0).contains(&t).then_some([1.0 - u - v, u, v])
}

/// Number of `edges` of a mesh that cross one of its `triangles` not sharing
/// a vertex with the edge (self-intersections of a cloth). `rep` maps each
/// vertex to a representative: vertices sewn together share one, so an edge
/// does not cross the triangles around its own seam.
pub fn count_self_crossings(x: &[Vec3], rep: &[u32], edges: &[[u32; 2]], triangles: &[[u32; 3]]) -> usize {
    let boxes: Vec<Aabb> = triangles.iter().map(|t| Aabb::from_points(&t.map(|i| x[i as usize]))).collect();
    let tree = AabbTree::build(&boxes);
    let mut n = 0;
    for e in edges {
        let (a, b) = (x[e[0] as usize], x[e[1] as usize]);
        let q = Aabb::from_points(&[a, b]);
        let mut hit = false;
        let ends = e.map(|v| rep[v as usize]);
        tree.query(&q, |t| {
            let tri = triangles[t as usize].map(|v| rep[v as usize]);
            if hit || tri.contains(&ends[0]) || tri.contains(&ends[1]) || !boxes[t as usize].overlaps(&q) {
                return;
            }
            let [p0, p1, p2] = tri.map(|i| x[i as usize]);
            hit = segment_hits_triangle(a, b, p0, p1, p2);
        });
        n += hit as usize;
    }
    n
}

/// Largest speed (m/s) in `v`.
pub fn max_speed(v: &[Vec3]) -> f32 {
    v.iter().map(|v| v.length()).fold(0.0, f32::max)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn segment_triangle() {
        let (p0, p1, p2) = (Vec3::ZERO, Vec3::X, Vec3::Y);
        let c = Vec3::new(0.25, 0.25, 0.0);
        assert!(segment_hits_triangle(c + Vec3::Z, c - Vec3::Z, p0, p1, p2));
        assert!(!segment_hits_triangle(c + Vec3::Z, c + Vec3::Z * 0.1, p0, p1, p2));
        assert!(!segment_hits_triangle(Vec3::new(1.0, 1.0, 1.0), Vec3::new(1.0, 1.0, -1.0), p0, p1, p2));
    }

    #[test]
    fn sewn_vertices_do_not_count_as_crossings() {
        // Two panels folded at a seam, vertices 1 and 3 sewn together (one place): the other
        // panel's edge 3-4 touches triangle 0-1-2 only at the sewn point.
        let x = [Vec3::ZERO, Vec3::X, Vec3::Y, Vec3::X, Vec3::new(1.0, 0.5, 1.0)];
        let (edges, tris) = ([[3, 4]], [[0, 1, 2]]);
        assert_eq!(count_self_crossings(&x, &[0, 1, 2, 3, 4], &edges, &tris), 1, "apart, the touch counts");
        assert_eq!(count_self_crossings(&x, &[0, 1, 2, 1, 4], &edges, &tris), 0, "sewn, it does not");
    }
}

//! Static colliders. Each answers "how far outside am I, and which way is
//! out" for a point; the solver pushes cloth vertices out to the cloth
//! thickness along that direction.

use glam::{Quat, Vec3};

/// A static collision shape (metres).
#[derive(Clone, Debug)]
pub enum Collider {
    Sphere {
        center: Vec3,
        radius: f32,
    },
    /// Segment `a`–`b` swept by a sphere.
    Capsule {
        a: Vec3,
        b: Vec3,
        radius: f32,
    },
    /// Oriented box; `rotation` maps box-local axes to world axes (identity
    /// for an axis-aligned box).
    Box {
        center: Vec3,
        half_extents: Vec3,
        rotation: Quat,
    },
    /// Ring of radius `major_radius` around `axis` (unit) through `center`,
    /// with tube radius `minor_radius`.
    Torus {
        center: Vec3,
        axis: Vec3,
        major_radius: f32,
        minor_radius: f32,
    },
    Mesh(TriMeshCollider),
}

/// Result of a proximity query: signed distance to the surface (negative
/// inside) and the unit direction that leads out.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Contact {
    pub distance: f32,
    pub normal: Vec3,
}

/// Unit vector perpendicular to `v`, chosen deterministically; used where a
/// direction is undefined (a point exactly on a centre line).
fn any_perpendicular(v: Vec3) -> Vec3 {
    v.any_orthonormal_vector()
}

impl Collider {
    /// Signed distance and outward direction at `p`, or `None` when the
    /// collider knows `p` is farther than `max_distance` outside (only the
    /// mesh collider prunes; the analytic shapes always answer).
    pub fn contact(&self, p: Vec3, max_distance: f32) -> Option<Contact> {
        match self {
            Collider::Sphere { center, radius } => {
                let d = p - *center;
                let len = d.length();
                let normal = if len > 0.0 { d / len } else { Vec3::Y };
                Some(Contact { distance: len - radius, normal })
            }
            Collider::Capsule { a, b, radius } => {
                let ab = *b - *a;
                let d = p - closest_point_on_segment(p, *a, *b);
                let len = d.length();
                let normal = if len > 0.0 {
                    d / len
                } else if ab.length_squared() > 0.0 {
                    any_perpendicular(ab.normalize())
                } else {
                    Vec3::Y
                };
                Some(Contact { distance: len - radius, normal })
            }
            Collider::Box { center, half_extents, rotation } => {
                let q = rotation.inverse() * (p - *center);
                let d = q.abs() - *half_extents;
                let outside = d.max(Vec3::ZERO);
                let out_len = outside.length();
                if out_len > 0.0 {
                    let n = outside * q.signum() / out_len;
                    Some(Contact { distance: out_len, normal: *rotation * n })
                } else {
                    // Inside: leave through the nearest face.
                    let (axis, depth) = if d.x >= d.y && d.x >= d.z {
                        (Vec3::X, d.x)
                    } else if d.y >= d.z {
                        (Vec3::Y, d.y)
                    } else {
                        (Vec3::Z, d.z)
                    };
                    let s = if q.dot(axis) < 0.0 { -1.0 } else { 1.0 };
                    Some(Contact { distance: depth, normal: *rotation * (axis * s) })
                }
            }
            Collider::Torus { center, axis, major_radius, minor_radius } => {
                let q = p - *center;
                let radial = q - *axis * q.dot(*axis);
                let r_len = radial.length();
                let dir = if r_len > 0.0 { radial / r_len } else { any_perpendicular(*axis) };
                let d = p - (*center + dir * *major_radius);
                let len = d.length();
                let normal = if len > 0.0 { d / len } else { dir };
                Some(Contact { distance: len - minor_radius, normal })
            }
            Collider::Mesh(m) => m.contact(p, max_distance),
        }
    }
}

/// Triangle mesh collider with a uniform grid over triangle bounding boxes.
///
/// The sign of the distance comes from the closest triangle's face normal
/// (CCW winding = outside), so the mesh need not be closed; points more than
/// `depth` behind the surface are ignored, which lets thin one-sided sheets
/// work and avoids teleporting vertices through a closed mesh.
#[derive(Clone, Debug)]
pub struct TriMeshCollider {
    positions: Vec<Vec3>,
    triangles: Vec<[u32; 3]>,
    normals: Vec<Vec3>,
    depth: f32,
    origin: Vec3,
    cell: f32,
    dims: [u32; 3],
    /// CSR layout: triangles of cell `c` are `cell_tris[cell_start[c]..cell_start[c + 1]]`.
    cell_start: Vec<u32>,
    cell_tris: Vec<u32>,
}

impl TriMeshCollider {
    /// Builds the grid. `depth` is how far behind the surface a point is
    /// still pushed out (metres); use a few cloth thicknesses.
    pub fn new(positions: Vec<Vec3>, triangles: Vec<[u32; 3]>, depth: f32) -> Self {
        assert!(!triangles.is_empty(), "mesh collider needs triangles");
        assert!(
            triangles.iter().flatten().all(|&i| (i as usize) < positions.len()),
            "mesh collider index out of range"
        );
        let normals: Vec<Vec3> = triangles
            .iter()
            .map(|t| {
                let [a, b, c] = t.map(|i| positions[i as usize]);
                (b - a).cross(c - a).normalize_or_zero()
            })
            .collect();
        let (lo, hi) =
            triangles.iter().flatten().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), &i| {
                (lo.min(positions[i as usize]), hi.max(positions[i as usize]))
            });
        // Cells about twice the mean edge length: few triangles per cell,
        // few cells per query. Capped so huge sparse meshes stay bounded.
        let mean_edge =
            triangles.iter().map(|t| positions[t[0] as usize].distance(positions[t[1] as usize])).sum::<f32>()
                / triangles.len() as f32;
        let extent = (hi - lo).max(Vec3::splat(1e-6));
        let mut cell = (2.0 * mean_edge).max(depth).max(extent.max_element() / 256.0);
        while (extent / cell).ceil().element_product() > 4.0e6 {
            cell *= 1.5;
        }
        let dims = ((extent / cell).ceil().max(Vec3::ONE)).as_uvec3().to_array();
        let n_cells = (dims[0] * dims[1] * dims[2]) as usize;
        let mut grid = TriMeshCollider {
            positions,
            triangles,
            normals,
            depth,
            origin: lo,
            cell,
            dims,
            cell_start: vec![0; n_cells + 1],
            cell_tris: Vec::new(),
        };
        // Two passes (count, fill) keep the CSR arrays in triangle order.
        let ranges: Vec<([u32; 3], [u32; 3])> = (0..grid.triangles.len())
            .map(|t| {
                let [a, b, c] = grid.triangles[t].map(|i| grid.positions[i as usize]);
                (grid.cell_of(a.min(b).min(c)), grid.cell_of(a.max(b).max(c)))
            })
            .collect();
        for (lo, hi) in &ranges {
            for_cells(grid.dims, *lo, *hi, |c| grid.cell_start[c + 1] += 1);
        }
        for c in 0..n_cells {
            grid.cell_start[c + 1] += grid.cell_start[c];
        }
        let mut fill = grid.cell_start.clone();
        grid.cell_tris = vec![0; grid.cell_start[n_cells] as usize];
        for (t, (lo, hi)) in ranges.iter().enumerate() {
            let dims = grid.dims;
            for_cells(dims, *lo, *hi, |c| {
                grid.cell_tris[fill[c] as usize] = t as u32;
                fill[c] += 1;
            });
        }
        grid
    }

    pub fn positions(&self) -> &[Vec3] {
        &self.positions
    }
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }

    fn cell_of(&self, p: Vec3) -> [u32; 3] {
        let c = ((p - self.origin) / self.cell).floor();
        [0, 1, 2].map(|k| (c[k].max(0.0) as u32).min(self.dims[k] - 1))
    }

    fn for_cells(&self, lo: [u32; 3], hi: [u32; 3], f: impl FnMut(usize)) {
        for_cells(self.dims, lo, hi, f)
    }

    /// Closest triangle within `max_distance` in front of, or `depth`
    /// behind, the surface.
    fn contact(&self, p: Vec3, max_distance: f32) -> Option<Contact> {
        let r = max_distance.max(self.depth);
        let lo = p - Vec3::splat(r);
        let hi = p + Vec3::splat(r);
        let grid_hi = self.origin + self.cell * glam::UVec3::from(self.dims).as_vec3();
        if lo.cmpgt(grid_hi).any() || hi.cmplt(self.origin).any() {
            return None;
        }
        let mut best: Option<(f32, u32, Vec3)> = None;
        self.for_cells(self.cell_of(lo), self.cell_of(hi), |c| {
            for &t in &self.cell_tris[self.cell_start[c] as usize..self.cell_start[c + 1] as usize] {
                let [a, b, cc] = self.triangles[t as usize].map(|i| self.positions[i as usize]);
                let q = closest_point_on_triangle(p, a, b, cc);
                let d2 = p.distance_squared(q);
                // Ties go to the lower triangle id so the answer does not
                // depend on cell visiting order.
                let better = match best {
                    None => true,
                    Some((bd, bt, _)) => d2 < bd || (d2 == bd && t < bt),
                };
                if better {
                    best = Some((d2, t, q));
                }
            }
        });
        let (d2, t, q) = best?;
        let n = self.normals[t as usize];
        let side = (p - q).dot(n);
        let dist = d2.sqrt();
        let distance = if side < 0.0 { -dist } else { dist };
        if distance > max_distance || distance < -self.depth {
            return None;
        }
        Some(Contact { distance, normal: n })
    }
}

fn for_cells(dims: [u32; 3], lo: [u32; 3], hi: [u32; 3], mut f: impl FnMut(usize)) {
    for z in lo[2]..=hi[2] {
        for y in lo[1]..=hi[1] {
            for x in lo[0]..=hi[0] {
                f(((z * dims[1] + y) * dims[0] + x) as usize);
            }
        }
    }
}

/// Closest point on the segment `ab` to `p` (`a` when the segment is a point).
pub fn closest_point_on_segment(p: Vec3, a: Vec3, b: Vec3) -> Vec3 {
    let ab = b - a;
    let len2 = ab.length_squared();
    let t = if len2 > 0.0 { ((p - a).dot(ab) / len2).clamp(0.0, 1.0) } else { 0.0 };
    a + ab * t
}

/// Closest point on triangle `abc` to `p` (Ericson, Real-Time Collision
/// Detection, 5.1.5).
pub(crate) fn closest_point_on_triangle(p: Vec3, a: Vec3, b: Vec3, c: Vec3) -> Vec3 {
    let ab = b - a;
    let ac = c - a;
    let ap = p - a;
    let d1 = ab.dot(ap);
    let d2 = ac.dot(ap);
    if d1 <= 0.0 && d2 <= 0.0 {
        return a;
    }
    let bp = p - b;
    let d3 = ab.dot(bp);
    let d4 = ac.dot(bp);
    if d3 >= 0.0 && d4 <= d3 {
        return b;
    }
    let vc = d1 * d4 - d3 * d2;
    if vc <= 0.0 && d1 >= 0.0 && d3 <= 0.0 {
        return a + ab * (d1 / (d1 - d3));
    }
    let cp = p - c;
    let d5 = ab.dot(cp);
    let d6 = ac.dot(cp);
    if d6 >= 0.0 && d5 <= d6 {
        return c;
    }
    let vb = d5 * d2 - d1 * d6;
    if vb <= 0.0 && d2 >= 0.0 && d6 <= 0.0 {
        return a + ac * (d2 / (d2 - d6));
    }
    let va = d3 * d6 - d5 * d4;
    if va <= 0.0 && (d4 - d3) >= 0.0 && (d5 - d6) >= 0.0 {
        return b + (c - b) * ((d4 - d3) / ((d4 - d3) + (d5 - d6)));
    }
    let denom = 1.0 / (va + vb + vc);
    a + ab * (vb * denom) + ac * (vc * denom)
}

/// Closed triangle mesh of a UV sphere (CCW seen from outside); handy as a
/// mesh-collider test body and for comparing against the analytic sphere.
pub fn uv_sphere_mesh(center: Vec3, radius: f32, rings: u32, segments: u32) -> (Vec<Vec3>, Vec<[u32; 3]>) {
    let mut pos = vec![center + Vec3::Y * radius];
    for r in 1..rings {
        let theta = std::f32::consts::PI * r as f32 / rings as f32;
        for s in 0..segments {
            let phi = std::f32::consts::TAU * s as f32 / segments as f32;
            let dir = Vec3::new(theta.sin() * phi.cos(), theta.cos(), theta.sin() * phi.sin());
            pos.push(center + dir * radius);
        }
    }
    pos.push(center - Vec3::Y * radius);
    (pos, pole_ring_triangles(rings - 1, segments))
}

/// The triangles of a closed surface of revolution laid out as vertex 0 (the first pole),
/// `rings` rings of `segments` vertices, then the last pole; wound outward.
pub(crate) fn pole_ring_triangles(rings: u32, segments: u32) -> Vec<[u32; 3]> {
    let last = 1 + rings * segments;
    let ring = |r: u32, s: u32| 1 + r * segments + s % segments;
    let mut tris = Vec::new();
    for s in 0..segments {
        tris.push([0, ring(0, s + 1), ring(0, s)]);
        tris.push([last, ring(rings - 1, s), ring(rings - 1, s + 1)]);
    }
    for r in 0..rings - 1 {
        for s in 0..segments {
            let (a, b, c, d) = (ring(r, s), ring(r, s + 1), ring(r + 1, s), ring(r + 1, s + 1));
            tris.push([a, b, d]);
            tris.push([a, d, c]);
        }
    }
    tris
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn analytic_distances() {
        let s = Collider::Sphere { center: Vec3::ZERO, radius: 1.0 };
        let c = s.contact(Vec3::new(0.0, 2.0, 0.0), 1.0).unwrap();
        assert_eq!(c.distance, 1.0);
        assert_eq!(c.normal, Vec3::Y);

        let cap = Collider::Capsule { a: Vec3::ZERO, b: Vec3::X * 2.0, radius: 0.5 };
        let c = cap.contact(Vec3::new(1.0, 0.25, 0.0), 1.0).unwrap();
        assert!((c.distance + 0.25).abs() < 1e-6 && c.normal == Vec3::Y);

        let rot = Quat::from_rotation_z(std::f32::consts::FRAC_PI_4);
        let bx = Collider::Box { center: Vec3::ZERO, half_extents: Vec3::ONE, rotation: rot };
        let c = bx.contact(rot * Vec3::new(0.0, 0.9, 0.0), 1.0).unwrap();
        assert!((c.distance + 0.1).abs() < 1e-5);
        assert!(c.normal.distance(rot * Vec3::Y) < 1e-5);
        let c = bx.contact(rot * Vec3::new(2.0, 2.0, 0.0), 10.0).unwrap();
        assert!((c.distance - 2f32.sqrt()).abs() < 1e-5);

        let torus = Collider::Torus { center: Vec3::ZERO, axis: Vec3::Y, major_radius: 2.0, minor_radius: 0.5 };
        let c = torus.contact(Vec3::new(0.0, 1.0, 2.0), 1.0).unwrap();
        assert!((c.distance - 0.5).abs() < 1e-6 && c.normal.distance(Vec3::Y) < 1e-6);
        // The hole's centre is outside the tube.
        let c = torus.contact(Vec3::ZERO, 1.0).unwrap();
        assert!((c.distance - 1.5).abs() < 1e-6);
    }

    #[test]
    fn mesh_sphere_matches_analytic_sphere() {
        let (pos, tris) = uv_sphere_mesh(Vec3::new(0.1, 0.2, 0.3), 0.5, 24, 48);
        let mesh = TriMeshCollider::new(pos, tris, 0.05);
        let analytic = Collider::Sphere { center: Vec3::new(0.1, 0.2, 0.3), radius: 0.5 };
        let mut hits = 0;
        for i in 0..200 {
            // Deterministic points scattered in a shell around the surface.
            let f = i as f32;
            let dir = Vec3::new((f * 1.7).sin(), (f * 2.3).cos(), (f * 0.7).sin()).normalize();
            let p = Vec3::new(0.1, 0.2, 0.3) + dir * (0.5 + 0.03 * (f * 0.37).sin());
            let a = analytic.contact(p, 0.1).unwrap();
            let m = Collider::Mesh(mesh.clone()).contact(p, 0.1).unwrap();
            // Chord error of a 24x48 sphere is about r(1-cos(pi/48)) = 1 mm.
            assert!((a.distance - m.distance).abs() < 2.5e-3, "{} vs {}", a.distance, m.distance);
            assert!(a.normal.dot(m.normal) > 0.95);
            hits += 1;
        }
        assert_eq!(hits, 200);
        // Far away or deep inside: no contact.
        assert!(mesh.contact(Vec3::new(3.0, 0.0, 0.0), 0.1).is_none());
        assert!(mesh.contact(Vec3::new(0.1, 0.2, 0.3), 0.1).is_none());
    }
}

//! Fitting a directional light's shadow tile to what the camera sees (issue 34): the receivers
//! that matter are the part of the scene inside the view frustum, so each light's
//! orthographic tile spans only their projection instead of the whole scene's bounding sphere.
//! Casters keep the whole scene's depth range, so an occluder outside the view still shadows
//! a visible receiver.
//!
//! The visible receivers are the intersection of two convex hexahedra, the view frustum and
//! the scene's bounding box: every face of each, clipped by the planes of both, leaves the
//! vertices of the intersection polytope.

use glam::{Mat4, Vec2, Vec3, Vec4};

use crate::ibl::shadow::light_view;

pub use crate::render::scene::box_corners;

/// A hexahedron's corners, corner k at (x, y, z) = (k & 1, k & 2, k & 4) of its unit cube.
pub type Hexahedron = [Vec3; 8];

/// The view frustum's corners in world space from the inverse of its view-projection
/// (wgpu clip space: x, y in [-1, 1], depth in [0, 1]).
pub fn frustum_corners(inv_view_proj: Mat4) -> Hexahedron {
    std::array::from_fn(|k| {
        let ndc = Vec3::new(
            if k & 1 == 0 { -1.0 } else { 1.0 },
            if k & 2 == 0 { -1.0 } else { 1.0 },
            if k & 4 == 0 { 0.0 } else { 1.0 },
        );
        inv_view_proj.project_point3(ndc)
    })
}

/// The six faces of a hexahedron as quads of corner indices (each face fixes one coordinate bit).
const FACES: [[usize; 4]; 6] = [[0, 2, 6, 4], [1, 3, 7, 5], [0, 1, 5, 4], [2, 3, 7, 6], [0, 1, 3, 2], [4, 5, 7, 6]];

fn faces(h: &Hexahedron) -> impl Iterator<Item = Vec<Vec3>> + '_ {
    FACES.iter().map(|f| f.iter().map(|&i| h[i]).collect())
}

/// The hexahedron's face planes (xyz the unit normal pointing inward, w the offset: a point p
/// is inside where n . p + w >= 0). Degenerate faces are left out.
fn inward_planes(h: &Hexahedron) -> Vec<Vec4> {
    let centre = h.iter().copied().sum::<Vec3>() / 8.0;
    FACES
        .iter()
        .filter_map(|f| {
            let [a, b, c, d] = f.map(|i| h[i]);
            // The quad's normal from its diagonals (robust for a slightly non-planar quad).
            let n = (c - a).cross(d - b).normalize_or_zero();
            if n == Vec3::ZERO {
                return None;
            }
            let mid = (a + b + c + d) / 4.0;
            let n = if n.dot(centre - mid) < 0.0 { -n } else { n };
            Some(n.extend(-n.dot(mid)))
        })
        .collect()
}

/// The polygon `poly` clipped to the half-space of `plane` (Sutherland-Hodgman).
fn clip(poly: &[Vec3], plane: Vec4, eps: f32) -> Vec<Vec3> {
    let side = |p: Vec3| plane.truncate().dot(p) + plane.w;
    let mut out = Vec::with_capacity(poly.len() + 1);
    for (i, &p) in poly.iter().enumerate() {
        let q = poly[(i + 1) % poly.len()];
        let (sp, sq) = (side(p), side(q));
        if sp >= -eps {
            out.push(p);
        }
        if (sp >= -eps) != (sq >= -eps) {
            out.push(p + (q - p) * (sp / (sp - sq)));
        }
    }
    out
}

/// The vertices of the intersection of two convex hexahedra (empty when they are disjoint).
pub fn intersection_points(a: &Hexahedron, b: &Hexahedron) -> Vec<Vec3> {
    let planes: Vec<Vec4> = inward_planes(a).into_iter().chain(inward_planes(b)).collect();
    let size = a.iter().chain(b).map(|p| p.abs().max_element()).fold(1.0f32, f32::max);
    let eps = 1e-5 * size;
    faces(a)
        .chain(faces(b))
        .flat_map(|face| {
            planes.iter().fold(face, |poly, &plane| if poly.is_empty() { poly } else { clip(&poly, plane, eps) })
        })
        .collect()
}

/// The square (centre in light-view x, y; half width) around `receivers` seen along
/// -`direction` in the frame of [`light_view`] for the sphere (c, r), for
/// [`tile_view_proj`](crate::ibl::shadow::tile_view_proj); None without receivers.
pub fn receiver_square(direction: Vec3, center: Vec3, radius: f32, receivers: &[Vec3]) -> Option<(Vec2, f32)> {
    if receivers.is_empty() {
        return None;
    }
    let view = light_view(direction, center, radius);
    let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
    for p in receivers {
        let q = view.transform_point3(*p);
        lo = lo.min(q);
        hi = hi.max(q);
    }
    // Never wider than the sphere (the receivers lie in the scene's box, inside it), never
    // narrower than a thousandth of it.
    let half = ((hi.x - lo.x).max(hi.y - lo.y) / 2.0).clamp(1e-3 * radius, radius);
    Some(((lo.truncate() + hi.truncate()) / 2.0, half))
}

/// Tile sizes in texels (multiples of 8, from `min` (at least 16) to `max`) for lights that
/// want `wants[i]` texels across (infinite: as many as there are), all scaled by one common
/// factor, the largest whose tiles' areas sum to at most `budget` texels (or all at `min`).
pub fn allocate_tiles(wants: &[f32], budget: u64, min: u32, max: u32) -> Vec<u32> {
    let min = min.max(16).div_ceil(8) * 8;
    let max = max.max(min) / 8 * 8;
    let sizes = |f: f64| -> Vec<u32> {
        wants
            .iter()
            .map(|&w| {
                let s = (f * w.clamp(1.0, 1e9) as f64).min(max as f64);
                ((s as u32) / 8 * 8).clamp(min, max)
            })
            .collect()
    };
    let area = |sizes: &[u32]| sizes.iter().map(|&s| s as u64 * s as u64).sum::<u64>();
    // Bisection on log f: small enough that every finite want is below 16, large enough that
    // every one is at the maximum.
    let largest = wants.iter().map(|w| w.clamp(1.0, 1e9)).fold(1.0f32, f32::max) as f64;
    let (mut lo, mut hi) = ((min as f64 / largest).ln() - 1.0, (max as f64).ln() + 1.0);
    if area(&sizes(hi.exp())) <= budget {
        return sizes(hi.exp());
    }
    for _ in 0..60 {
        let mid = (lo + hi) / 2.0;
        if area(&sizes(mid.exp())) <= budget { lo = mid } else { hi = mid }
    }
    sizes(lo.exp())
}

/// [`allocate_tiles`] and [`pack_tiles`] with the packed atlas, gaps included, within
/// `budget` texels where the minimum sizes allow: the budget shrinks by the packing's
/// overhead until the atlas fits (a few tries).
pub fn allocate_and_pack(wants: &[f32], budget: u64, min: u32, max: u32) -> (Vec<u32>, Vec<[u32; 2]>, u32, u32) {
    let mut target = budget;
    loop {
        let sizes = allocate_tiles(wants, target, min, max);
        let (origins, width, height) = pack_tiles(&sizes);
        let area = width as u64 * height as u64;
        let smallest = sizes.iter().all(|&s| s <= min.max(16).div_ceil(8) * 8);
        if area <= budget || smallest || target < budget / 2 {
            return (sizes, origins, width, height);
        }
        target = target * budget / area - 1;
    }
}

/// Packs square tiles of `sizes` (multiples of 8) into an atlas: the tiles sorted by size,
/// each put where the skyline of 8-texel columns is lowest (leftmost among equals), for the
/// atlas width from the square's to one largest tile more that gives the smallest area (the
/// squarer, then the wider one on ties).
/// Returns each tile's origin and the atlas's width and height. Equal sizes t give the
/// ceil(sqrt(n)) columns grid.
pub fn pack_tiles(sizes: &[u32]) -> (Vec<[u32; 2]>, u32, u32) {
    let largest = sizes.iter().copied().max().unwrap_or(16);
    let area: u64 = sizes.iter().map(|&s| s as u64 * s as u64).sum();
    let mut order: Vec<usize> = (0..sizes.len()).collect();
    order.sort_by_key(|&i| std::cmp::Reverse(sizes[i]));
    let pack = |width: u32| -> (Vec<[u32; 2]>, u32) {
        let mut skyline = vec![0u32; (width / 8) as usize];
        let mut origins = vec![[0u32; 2]; sizes.len()];
        for &i in &order {
            let w = (sizes[i] / 8) as usize;
            let (x, y) = (0..=skyline.len() - w)
                .map(|x| (x, skyline[x..x + w].iter().copied().max().unwrap_or(0)))
                .min_by_key(|&(x, y)| (y, x))
                .expect("the atlas is at least as wide as the largest tile");
            skyline[x..x + w].fill(y + sizes[i]);
            origins[i] = [x as u32 * 8, y];
        }
        (origins, skyline.into_iter().max().unwrap_or(0))
    };
    // Widths from the square's (narrower ones make tall strips) to one largest tile more.
    let square = ((area as f64).sqrt() as u32) / 8 * 8;
    let mut best: Option<(Vec<[u32; 2]>, u32, u32)> = None;
    for width in (square.max(largest)..=square + largest).step_by(8) {
        let (origins, height) = pack(width);
        let better = best.as_ref().is_none_or(|(_, bw, bh)| {
            let (a, b) = (width as u64 * height as u64, *bw as u64 * *bh as u64);
            a < b || (a == b && (width.abs_diff(height), height) < (bw.abs_diff(*bh), *bh))
        });
        if better {
            best = Some((origins, width, height));
        }
    }
    best.expect("one width at least")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_box_inside_another_is_their_intersection() {
        let outer = box_corners(Vec3::splat(-2.0), Vec3::splat(2.0));
        let inner = box_corners(Vec3::new(-1.0, 0.0, 0.5), Vec3::new(1.0, 1.5, 1.0));
        let points = intersection_points(&outer, &inner);
        let (lo, hi) = points.iter().fold((Vec3::MAX, Vec3::MIN), |(a, b), p| (a.min(*p), b.max(*p)));
        assert!((lo - Vec3::new(-1.0, 0.0, 0.5)).abs().max_element() < 1e-5, "{lo}");
        assert!((hi - Vec3::new(1.0, 1.5, 1.0)).abs().max_element() < 1e-5, "{hi}");
        // Overlapping boxes meet in the box of their overlap; disjoint ones not at all.
        let shifted = box_corners(Vec3::new(1.0, -3.0, -1.0), Vec3::new(5.0, 0.5, 3.0));
        let points = intersection_points(&outer, &shifted);
        let (lo, hi) = points.iter().fold((Vec3::MAX, Vec3::MIN), |(a, b), p| (a.min(*p), b.max(*p)));
        assert!((lo - Vec3::new(1.0, -2.0, -1.0)).abs().max_element() < 1e-5, "{lo}");
        assert!((hi - Vec3::new(2.0, 0.5, 2.0)).abs().max_element() < 1e-5, "{hi}");
        let far = box_corners(Vec3::splat(3.0), Vec3::splat(4.0));
        assert!(intersection_points(&outer, &far).is_empty());
    }

    #[test]
    fn a_frustum_clipped_by_a_floor_slab_gives_the_visible_floor() {
        // A camera 2 above a 20 x 20 floor slab (0.01 thick), looking down at 45 degrees with
        // a 40-degree field: the visible floor spans from 65 to 25 degrees below the horizon.
        let camera = crate::render::scene::Camera {
            eye: Vec3::new(0.0, 2.0, 0.0),
            target: Vec3::new(0.0, 0.0, -2.0),
            up: Vec3::Y,
            fov_y_degrees: 40.0,
            near: 0.1,
            far: 1000.0,
        };
        let view = crate::render::scene::View::new(&camera, 100, 100);
        let frustum = frustum_corners(view.inv_view_proj);
        let slab = box_corners(Vec3::new(-10.0, -0.01, -10.0), Vec3::new(10.0, 0.0, 10.0));
        let points = intersection_points(&frustum, &slab);
        let (lo, hi) = points.iter().fold((Vec3::MAX, Vec3::MIN), |(a, b), p| (a.min(*p), b.max(*p)));
        // Nearest visible floor: 65 degrees below the horizon, 2 / tan(65) in front.
        let near_z = -2.0 / 65f32.to_radians().tan();
        assert!((hi.z - near_z).abs() < 1e-3, "{hi} vs {near_z}");
        let far_z = -2.01 / 25f32.to_radians().tan();
        assert!((lo.z - far_z).abs() < 1e-3, "{lo} vs {far_z}");
        assert!(hi.x - lo.x < 20.0, "clipped sideways too: {lo} {hi}");
        // Every point is on the slab and inside the frustum.
        for p in &points {
            let c = view.view_proj.project_point3(*p);
            assert!(p.y > -0.011 && p.y < 1e-4 && c.x.abs() <= 1.0 + 1e-3 && c.y.abs() <= 1.0 + 1e-3, "{p} {c}");
        }
    }

    #[test]
    fn the_fitted_tile_covers_the_receivers_and_is_no_wider_than_the_sphere() {
        let (c, r) = (Vec3::ZERO, 4.0);
        let dir = Vec3::new(0.3, 0.9, 0.2).normalize();
        let receivers = [Vec3::new(0.5, 0.0, 0.5), Vec3::new(1.0, 0.0, 1.5), Vec3::new(0.2, 0.3, 1.0)];
        let square = receiver_square(dir, c, r, &receivers).expect("receivers");
        let (vp, half) = (crate::ibl::shadow::tile_view_proj(dir, c, r, square, 64, 4), square.1);
        assert!(half < r / 2.0, "{half}");
        for p in receivers {
            let q = vp.project_point3(p);
            assert!(
                q.x.abs() <= 60.0 / 64.0 + 0.05 && q.y.abs() <= 60.0 / 64.0 + 0.05 && (0.0..=1.0).contains(&q.z),
                "{q}"
            );
        }
        // The same depth range as the whole-scene fit.
        let whole = crate::ibl::shadow::light_view_proj(dir, c, r, 64, 4);
        for p in [c + dir * r, c - dir * r, c] {
            assert!((vp.project_point3(p).z - whole.project_point3(p).z).abs() < 1e-5);
        }
        assert!(receiver_square(dir, c, r, &[]).is_none());
    }

    #[test]
    fn tiles_share_the_budget_in_proportion_and_pack_without_overlap() {
        // Equal wants: the uniform grid of today's atlas.
        assert_eq!(allocate_tiles(&[100.0; 16], 16 * 64 * 64, 16, 1024), vec![64; 16]);
        let (origins, w, h) = pack_tiles(&[64; 16]);
        assert_eq!((w, h), (256, 256));
        assert!(origins.contains(&[192, 192]));
        let (_, w, h) = pack_tiles(&[32; 5]);
        assert_eq!((w, h), (96, 64));
        // A sharp light (infinite want) takes what the blurred ones leave.
        let mut wants = vec![40.0; 15];
        wants.push(f32::INFINITY);
        let sizes = allocate_tiles(&wants, 16 * 64 * 64, 16, 1024);
        let area: u64 = sizes.iter().map(|&s| s as u64 * s as u64).sum();
        assert!(area <= 16 * 64 * 64 && area > 14 * 64 * 64, "{sizes:?}");
        assert!(sizes[15] >= 192 && sizes[..15].iter().all(|&s| (16..=64).contains(&s)), "{sizes:?}");
        // In proportion: twice the want, twice the size (to the multiple of 8 below).
        let sizes = allocate_tiles(&[50.0, 100.0], 100 * 100 + 50 * 50, 16, 1024);
        assert!(sizes[1] >= 2 * sizes[0] - 8 && sizes[1] <= 2 * sizes[0] + 8, "{sizes:?}");
        // A floor of 32: the sharp light gets what is left above it.
        let sizes = allocate_tiles(&wants, 16 * 64 * 64, 32, 1024);
        assert!(sizes[..15].iter().all(|&s| s == 32) && sizes[15] == 224, "{sizes:?}");
        // Packed, gaps included, within the budget.
        let (sizes, _, w, h) = allocate_and_pack(&wants, 16 * 64 * 64, 32, 1024);
        assert!((w * h) as u64 <= 16 * 64 * 64 && sizes[15] >= 192, "{sizes:?} in {w}x{h}");
        for sizes in [vec![256, 32, 32, 32, 64, 16, 16, 128, 40, 40, 40], vec![16], vec![1024, 16]] {
            let (origins, w, h) = pack_tiles(&sizes);
            let area: u64 = sizes.iter().map(|&s| s as u64 * s as u64).sum();
            assert!((w as u64 * h as u64) < 2 * area, "{sizes:?}: {w}x{h} for {area} texels");
            for (a, (oa, sa)) in origins.iter().zip(&sizes).enumerate() {
                assert!(oa[0] + sa <= w && oa[1] + sa <= h);
                for (ob, sb) in origins[a + 1..].iter().zip(&sizes[a + 1..]) {
                    let apart =
                        oa[0] + sa <= ob[0] || ob[0] + sb <= oa[0] || oa[1] + sa <= ob[1] || ob[1] + sb <= oa[1];
                    assert!(apart, "{sizes:?}: tiles at {oa:?} and {ob:?} overlap");
                }
            }
        }
    }
}

//! Which item covers each pixel: a ray from the eye through each pixel's centre, intersected
//! with the exported triangles (double-sided, nearest hit). Each triangle is tested only for the
//! pixels of its projected bounding box, so a scene of 10k triangles at 320x240 takes a fraction
//! of a second. The same rays are what the path tracer samples (its pixel filter is a point at
//! the centre), and what the rasterizer covers up to its edge rules.

use glam::{Vec2, Vec3, Vec4Swizzles as _};

use crate::mesh::Mesh;
use crate::render::scene::{Camera, View};

/// Per pixel (row-major, top row first): the item index (-1: nothing), and where an item is hit
/// the world position, the albedo (base colour times texture) and the geometric normal.
pub struct PixelIds {
    pub width: u32,
    pub height: u32,
    pub id: Vec<i32>,
    pub position: Vec<Vec3>,
    pub albedo: Vec<Vec3>,
    /// Region masks (`scene::region_masks`); empty until computed.
    pub regions: Vec<u32>,
}

/// How an item's albedo is looked up: base colour times an optional sRGB texture.
pub struct Albedo<'a> {
    pub base_color: Vec3,
    /// (width, height, RGBA8 sRGB-encoded), sampled bilinearly with repeat at uv * uv_scale.
    pub texture: Option<(u32, u32, &'a [u8], bool)>,
    pub uv_scale: f32,
}

impl Albedo<'_> {
    pub fn at(&self, uv: Vec2) -> Vec3 {
        let Some((w, h, rgba, srgb)) = self.texture else { return self.base_color };
        let p = uv * self.uv_scale * Vec2::new(w as f32, h as f32) - 0.5;
        let (x0, y0) = (p.x.floor(), p.y.floor());
        let (fx, fy) = (p.x - x0, p.y - y0);
        let texel = |x: f32, y: f32| {
            let (x, y) = ((x as i64).rem_euclid(w as i64) as usize, (y as i64).rem_euclid(h as i64) as usize);
            let i = 4 * (y * w as usize + x);
            let d = |c: u8| if srgb { crate::color::srgb_to_linear(c as f32 / 255.0) } else { c as f32 / 255.0 };
            Vec3::new(d(rgba[i]), d(rgba[i + 1]), d(rgba[i + 2]))
        };
        let top = texel(x0, y0).lerp(texel(x0 + 1.0, y0), fx);
        let bottom = texel(x0, y0 + 1.0).lerp(texel(x0 + 1.0, y0 + 1.0), fx);
        self.base_color * top.lerp(bottom, fy)
    }
}

/// The ray through pixel (x, y)'s centre: origin and unit direction.
pub fn pixel_ray(view: &View, x: u32, y: u32) -> (Vec3, Vec3) {
    let ndc =
        Vec2::new((x as f32 + 0.5) / view.width as f32 * 2.0 - 1.0, 1.0 - (y as f32 + 0.5) / view.height as f32 * 2.0);
    let far = view.inv_view_proj.project_point3(ndc.extend(1.0));
    (view.eye, (far - view.eye).normalize())
}

/// Where `p` lands in pixels (x right, y down, centres at .5); None behind the eye.
pub fn project(view: &View, p: Vec3) -> Option<Vec2> {
    let clip = view.view_proj * p.extend(1.0);
    (clip.w > 1e-6).then(|| {
        let ndc = clip.xy() / clip.w;
        Vec2::new((ndc.x + 1.0) * 0.5 * view.width as f32, (1.0 - ndc.y) * 0.5 * view.height as f32)
    })
}

/// Casts one ray per pixel against `mesh`; `item_of` gives the item of a triangle index and
/// `albedo` each item's albedo lookup.
pub fn cast(
    camera: &Camera,
    width: u32,
    height: u32,
    mesh: &Mesh,
    item_of: &dyn Fn(usize) -> usize,
    albedo: &[Albedo<'_>],
) -> PixelIds {
    let view = View::new(camera, width, height);
    let n = (width * height) as usize;
    let rays: Vec<Vec3> = (0..n).map(|i| pixel_ray(&view, i as u32 % width, i as u32 / width).1).collect();
    let mut depth = vec![f32::INFINITY; n];
    let mut hit: Vec<Option<(usize, f32, f32)>> = vec![None; n];
    let eye = view.eye;
    for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
        let [a, b, c] = [tri[0], tri[1], tri[2]].map(|i| mesh.positions[i as usize]);
        // The pixels the triangle can cover: its projected bounds, or all when a vertex is
        // behind the eye.
        let projected: Option<Vec<Vec2>> = [a, b, c].iter().map(|&p| project(&view, p)).collect();
        let (x0, x1, y0, y1) = match projected {
            Some(ps) => {
                let lo = ps.iter().fold(Vec2::splat(f32::MAX), |m, p| m.min(*p));
                let hi = ps.iter().fold(Vec2::splat(f32::MIN), |m, p| m.max(*p));
                if hi.x < 0.0 || hi.y < 0.0 || lo.x > width as f32 || lo.y > height as f32 {
                    continue;
                }
                let clamp = |v: f32, n: u32| (v.max(0.0) as u32).min(n - 1);
                (
                    clamp(lo.x - 1.0, width),
                    clamp(hi.x + 1.0, width),
                    clamp(lo.y - 1.0, height),
                    clamp(hi.y + 1.0, height),
                )
            }
            None => (0, width - 1, 0, height - 1),
        };
        let (e1, e2) = (b - a, c - a);
        for y in y0..=y1 {
            for x in x0..=x1 {
                let i = (y * width + x) as usize;
                let d = rays[i];
                // Moller-Trumbore, both sides.
                let p = d.cross(e2);
                let det = e1.dot(p);
                if det.abs() < 1e-12 {
                    continue;
                }
                let inv = 1.0 / det;
                let s = eye - a;
                let u = s.dot(p) * inv;
                if !(0.0..=1.0).contains(&u) {
                    continue;
                }
                let q = s.cross(e1);
                let v = d.dot(q) * inv;
                if v < 0.0 || u + v > 1.0 {
                    continue;
                }
                let dist = e2.dot(q) * inv;
                if dist > camera.near && dist < depth[i] {
                    depth[i] = dist;
                    hit[i] = Some((t, u, v));
                }
            }
        }
    }
    let mut out = PixelIds {
        width,
        height,
        id: vec![-1; n],
        position: vec![Vec3::ZERO; n],
        albedo: vec![Vec3::ZERO; n],
        regions: Vec::new(),
    };
    for (i, h) in hit.iter().enumerate() {
        let Some((t, u, v)) = *h else { continue };
        let item = item_of(t);
        out.id[i] = item as i32;
        out.position[i] = eye + rays[i] * depth[i];
        let idx = &mesh.indices[3 * t..3 * t + 3];
        let uv = if mesh.uvs.len() == mesh.positions.len() {
            let [ta, tb, tc] = [idx[0], idx[1], idx[2]].map(|k| mesh.uvs[k as usize]);
            ta * (1.0 - u - v) + tb * u + tc * v
        } else {
            Vec2::ZERO
        };
        out.albedo[i] = albedo.get(item).map_or(Vec3::ONE, |a| a.at(uv));
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_ray_through_the_centre_hits_what_projects_there() {
        let camera = Camera {
            eye: Vec3::new(0.0, 0.0, 3.0),
            target: Vec3::ZERO,
            up: Vec3::Y,
            fov_y_degrees: 40.0,
            near: 0.05,
            far: 100.0,
        };
        // A quad at z = 0 covering [-0.5, 0.5]^2 and one behind it.
        let quad =
            |z: f32, s: f32| vec![Vec3::new(-s, -s, z), Vec3::new(s, -s, z), Vec3::new(s, s, z), Vec3::new(-s, s, z)];
        let mut positions = quad(0.0, 0.5);
        positions.extend(quad(-1.0, 5.0));
        let indices = vec![0, 1, 2, 0, 2, 3, 4, 5, 6, 4, 6, 7];
        let mesh = Mesh::from_raw(positions, Vec::new(), Vec::new(), Vec::new(), Vec::new(), indices);
        let albedo = [
            Albedo { base_color: Vec3::X, texture: None, uv_scale: 1.0 },
            Albedo { base_color: Vec3::Y, texture: None, uv_scale: 1.0 },
        ];
        let ids = cast(&camera, 64, 48, &mesh, &|t| t / 2, &albedo);
        let view = View::new(&camera, 64, 48);
        let corner = project(&view, Vec3::new(0.5, 0.5, 0.0)).unwrap();
        // The near quad's corner projects where the ids switch from 0 to 1.
        let (cx, cy) = (corner.x.floor() as u32, corner.y.ceil() as u32);
        assert_eq!(ids.id[(cy * 64 + cx - 1) as usize], 0);
        assert_eq!(ids.id[((cy - 2) * 64 + cx + 2) as usize], 1);
        assert_eq!(ids.id[(24 * 64 + 32) as usize], 0);
        assert_eq!(ids.albedo[0], Vec3::Y);
        assert!(ids.position[(24 * 64 + 32) as usize].z.abs() < 1e-4);
    }
}

//! Cube maps on the CPU: the face convention the shaders share (shaders/ibl/cube.wgsl), texel
//! directions and solid angles, and equirectangular light probes loaded and resampled.
//!
//! Faces are in wgpu's layer order +X, -X, +Y, -Y, +Z, -Z with the sampling convention of
//! Vulkan/D3D (what `textureSample` on a `texture_cube` does): on face `f`, texel column `x`
//! grows with `u` and row `y` grows with `v`, where `u, v` in [-1, 1] and [`face_dir`] gives
//! the (unnormalized) direction. World +Y is up.

use std::path::Path;

use anyhow::bail;
use glam::{Vec3, Vec4};

/// The direction through face `face` at face coordinates `u, v` in [-1, 1] (unnormalized;
/// `u, v` outside [-1, 1] point into the neighbouring faces, which the filters rely on).
pub fn face_dir(face: usize, u: f32, v: f32) -> Vec3 {
    match face {
        0 => Vec3::new(1.0, -v, -u),
        1 => Vec3::new(-1.0, -v, u),
        2 => Vec3::new(u, 1.0, v),
        3 => Vec3::new(u, -1.0, -v),
        4 => Vec3::new(u, -v, 1.0),
        _ => Vec3::new(-u, -v, -1.0),
    }
}

/// The face a direction falls on and its face coordinates in [-1, 1] (inverse of
/// [`face_dir`]; ties between faces go to X, then Y, as the hardware does).
pub fn dir_to_face(d: Vec3) -> (usize, f32, f32) {
    let a = d.abs();
    if a.x >= a.y && a.x >= a.z {
        if d.x >= 0.0 { (0, -d.z / a.x, -d.y / a.x) } else { (1, d.z / a.x, -d.y / a.x) }
    } else if a.y >= a.z {
        if d.y >= 0.0 { (2, d.x / a.y, d.z / a.y) } else { (3, d.x / a.y, -d.z / a.y) }
    } else if d.z >= 0.0 {
        (4, d.x / a.z, -d.y / a.z)
    } else {
        (5, -d.x / a.z, -d.y / a.z)
    }
}

/// The texel of a `size`-wide cube map that direction `d` falls in: (face, column, row).
pub fn nearest_texel(size: usize, d: Vec3) -> (usize, usize, usize) {
    let (face, u, v) = dir_to_face(d);
    let texel = |c: f32| (((c + 1.0) * 0.5 * size as f32) as usize).min(size - 1);
    (face, texel(u), texel(v))
}

/// Face coordinate of the centre of texel `i` of a face `size` texels wide.
pub fn texel_center(size: usize, i: usize) -> f32 {
    (2.0 * (i as f32 + 0.5)) / size as f32 - 1.0
}

/// The unit direction through the centre of texel (`x`, `y`) of face `face`.
pub fn texel_dir(size: usize, face: usize, x: usize, y: usize) -> Vec3 {
    face_dir(face, texel_center(size, x), texel_center(size, y)).normalize()
}

/// The exact solid angle of texel (`x`, `y`) of a face `size` texels wide (the same on every
/// face): the area element of the unit cube's face projected onto the sphere, integrated
/// in closed form, atan(uv / sqrt(u^2 + v^2 + 1)) at the four corners.
pub fn texel_solid_angle(size: usize, x: usize, y: usize) -> f32 {
    let corner = |u: f64, v: f64| (u * v).atan2((u * u + v * v + 1.0).sqrt());
    let step = 2.0 / size as f64;
    let (u0, v0) = (x as f64 * step - 1.0, y as f64 * step - 1.0);
    let (u1, v1) = (u0 + step, v0 + step);
    (corner(u1, v1) - corner(u0, v1) - corner(u1, v0) + corner(u0, v0)) as f32
}

/// A cube map's texels on the CPU: `size` x `size` per face, faces in layer order, rows top
/// to bottom. RGBA, linear radiance (alpha unused but kept, as on the GPU).
#[derive(Clone, Debug, PartialEq)]
pub struct CubeImage {
    pub size: usize,
    pub texels: Vec<Vec4>,
}

impl CubeImage {
    pub fn new(size: usize) -> CubeImage {
        CubeImage { size, texels: vec![Vec4::ZERO; 6 * size * size] }
    }

    /// Every texel `f(face, x, y)`.
    pub fn from_fn(size: usize, mut f: impl FnMut(usize, usize, usize) -> Vec4) -> CubeImage {
        let mut texels = Vec::with_capacity(6 * size * size);
        for face in 0..6 {
            for y in 0..size {
                for x in 0..size {
                    texels.push(f(face, x, y));
                }
            }
        }
        CubeImage { size, texels }
    }

    /// [`CubeImage::from_fn`] with the rows computed on every core (the same texels).
    pub fn from_fn_parallel(size: usize, f: impl Fn(usize, usize, usize) -> Vec4 + Sync) -> CubeImage {
        let mut texels = vec![Vec4::ZERO; 6 * size * size];
        crate::core::parallel::for_each_chunk(&mut texels, size.max(1), 0, |row, out| {
            let (face, y) = (row / size, row % size);
            for (x, t) in out.iter_mut().enumerate() {
                *t = f(face, x, y);
            }
        });
        CubeImage { size, texels }
    }

    pub fn index(&self, face: usize, x: usize, y: usize) -> usize {
        (face * self.size + y) * self.size + x
    }

    pub fn texel(&self, face: usize, x: usize, y: usize) -> Vec4 {
        self.texels[self.index(face, x, y)]
    }

    /// Bilinear lookup along `d`, seamless like the hardware's cube sampling: a tap that falls
    /// off the face is taken from the neighbouring face (the texel nearest to where the tap's
    /// direction lands). shaders/ibl/cube.wgsl `cube_bilinear` does the same with `textureLoad`.
    pub fn sample(&self, d: Vec3) -> Vec4 {
        let (face, u, v) = dir_to_face(d);
        let s = self.size as f32;
        let px = (u + 1.0) * 0.5 * s - 0.5;
        let py = (v + 1.0) * 0.5 * s - 0.5;
        let (fx, fy) = (px.floor(), py.floor());
        let (tx, ty) = (px - fx, py - fy);
        let (x0, y0) = (fx as i64, fy as i64);
        let top = self.tap(face, x0, y0).lerp(self.tap(face, x0 + 1, y0), tx);
        let bottom = self.tap(face, x0, y0 + 1).lerp(self.tap(face, x0 + 1, y0 + 1), tx);
        top.lerp(bottom, ty)
    }

    /// Texel (`x`, `y`) of `face`, where a coordinate one past the edge continues onto the
    /// neighbouring face.
    fn tap(&self, face: usize, x: i64, y: i64) -> Vec4 {
        let n = self.size as i64;
        if (0..n).contains(&x) && (0..n).contains(&y) {
            return self.texel(face, x as usize, y as usize);
        }
        let centre = |i: i64| (2.0 * (i as f32 + 0.5)) / n as f32 - 1.0;
        let (f, u, v) = dir_to_face(face_dir(face, centre(x), centre(y)));
        let nearest = |c: f32| (((c + 1.0) * 0.5 * n as f32).floor() as i64).clamp(0, n - 1) as usize;
        self.texel(f, nearest(u), nearest(v))
    }
}

/// An equirectangular (latitude-longitude) light probe: linear RGB, rows from the zenith
/// (+Y) down. Column `u` in [0, 1) is the azimuth; see [`equirect_uv`].
#[derive(Clone, Debug)]
pub struct EquirectImage {
    pub width: usize,
    pub height: usize,
    pub rgb: Vec<Vec3>,
}

/// Where direction `d` falls in an equirectangular map: u = 0.5 + atan2(x, -z) / 2pi (so
/// the map's centre column looks down -Z, the default camera's view), v = acos(y) / pi.
pub fn equirect_uv(d: Vec3) -> (f32, f32) {
    let d = d.normalize();
    let u = 0.5 + d.x.atan2(-d.z) / std::f32::consts::TAU;
    let v = d.y.clamp(-1.0, 1.0).acos() / std::f32::consts::PI;
    (u, v)
}

/// The direction at equirectangular coordinates (u, v): the inverse of [`equirect_uv`]
/// (shaders/ibl/cube.wgsl `equirect_dir`).
pub fn equirect_dir(u: f32, v: f32) -> Vec3 {
    let (phi, theta) = ((u - 0.5) * std::f32::consts::TAU, v * std::f32::consts::PI);
    Vec3::new(theta.sin() * phi.sin(), theta.cos(), -theta.sin() * phi.cos())
}

impl EquirectImage {
    /// Loads a Radiance .hdr or an OpenEXR .exr (RGB(A), any float type the decoder reads).
    pub fn load(path: &Path) -> anyhow::Result<EquirectImage> {
        let ext = path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase);
        if !matches!(ext.as_deref(), Some("hdr" | "exr")) {
            bail!("{}: unsupported light probe format (use an equirectangular .hdr or .exr)", path.display());
        }
        if !path.exists() {
            bail!("{}: no such file", path.display());
        }
        let decoded = image::open(path).map_err(|e| {
            let text = e.to_string();
            // The exr crate reads no DWAA/DWAB (lossy, DCT-based) files; say so and how to fix it.
            if text.to_ascii_lowercase().contains("dwa") || text.contains("compression") {
                anyhow::anyhow!(
                    "{}: {text}; this EXR's compression is not supported by the decoder (DWAA/DWAB are not); \
                     re-save it with ZIP or PIZ compression, or use an .hdr",
                    path.display()
                )
            } else {
                anyhow::anyhow!("{}: {text}", path.display())
            }
        })?;
        let img = decoded.into_rgb32f();
        let (width, height) = (img.width() as usize, img.height() as usize);
        if width < 2 || height < 1 {
            bail!("{}: a {width}x{height} image is too small for a light probe", path.display());
        }
        let rgb = img.pixels().map(|p| Vec3::new(p.0[0], p.0[1], p.0[2])).collect::<Vec<_>>();
        if let Some(i) = rgb.iter().position(|c| !c.is_finite() || c.min_element() < 0.0) {
            bail!(
                "{}: pixel ({}, {}) is {:?}: radiance must be finite and non-negative",
                path.display(),
                i % width,
                i / width,
                rgb[i]
            );
        }
        Ok(EquirectImage { width, height, rgb })
    }

    pub fn pixel(&self, x: usize, y: usize) -> Vec3 {
        self.rgb[y * self.width + x]
    }

    /// Bilinear lookup along `d`: wraps in azimuth, clamps at the poles.
    pub fn sample(&self, d: Vec3) -> Vec3 {
        let (u, v) = equirect_uv(d);
        let px = u * self.width as f32 - 0.5;
        let py = (v * self.height as f32 - 0.5).clamp(0.0, self.height as f32 - 1.0);
        let (fx, fy) = (px.floor(), py.floor());
        let (tx, ty) = (px - fx, py - fy);
        let w = self.width as i64;
        let wrap = |i: f32| (i as i64).rem_euclid(w) as usize;
        let (x0, x1) = (wrap(fx), wrap(fx + 1.0));
        let (y0, y1) = (fy as usize, (fy as usize + 1).min(self.height - 1));
        let top = self.pixel(x0, y0).lerp(self.pixel(x1, y0), tx);
        let bottom = self.pixel(x0, y1).lerp(self.pixel(x1, y1), tx);
        top.lerp(bottom, ty)
    }
}

/// Rotation of the probe about +Y by `degrees` (the EnvironmentMap node's `rotation`): the
/// cube texel in direction `d` shows the probe's radiance from `rotate_y(d, -degrees)`.
pub fn rotate_y(d: Vec3, degrees: f32) -> Vec3 {
    glam::Quat::from_rotation_y(degrees.to_radians()) * d
}

/// Supersampling per cube texel when resampling a probe (SUPERSAMPLE^2 bilinear lookups):
/// a 1024-wide probe has about 2.4 texels per 128-texel cube texel, so a single lookup would
/// skip some of a small sun's texels and change its energy.
pub const SUPERSAMPLE: usize = 4;

/// A probe resampled into a cube map (what `EnvironmentMap` uploads): each texel the mean of SUPERSAMPLE^2
/// bilinear lookups spread evenly over it, times `intensity`.
pub fn cube_from_equirect(eq: &EquirectImage, size: usize, rotation_deg: f32, intensity: f32) -> CubeImage {
    resample_rotated(size, rotation_deg, intensity, |d| eq.sample(d))
}

impl CubeImage {
    /// This map turned about +Y by `degrees` as `EnvironmentMap`'s rotation turns a probe (a
    /// texel towards `d` shows this map along `rotate_y(d, -degrees)`), resampled like
    /// [`cube_from_equirect`]: for environments rotated in real time (BtfShading's HEM).
    pub fn rotated_y(&self, degrees: f32) -> CubeImage {
        resample_rotated(self.size, degrees, 1.0, |d| self.sample(d).truncate())
    }
}

/// A `size` cube map whose texel towards `d` is the mean of SUPERSAMPLE^2 lookups of `radiance`
/// along `rotate_y(d', -rotation_deg)` over the texel, times `intensity`.
fn resample_rotated(
    size: usize,
    rotation_deg: f32,
    intensity: f32,
    radiance: impl Fn(Vec3) -> Vec3 + Sync,
) -> CubeImage {
    let n = SUPERSAMPLE;
    CubeImage::from_fn_parallel(size, |face, x, y| {
        let mut sum = Vec3::ZERO;
        for j in 0..n {
            for i in 0..n {
                let u = (2.0 * (x as f32 + (i as f32 + 0.5) / n as f32)) / size as f32 - 1.0;
                let v = (2.0 * (y as f32 + (j as f32 + 0.5) / n as f32)) / size as f32 - 1.0;
                sum += radiance(rotate_y(face_dir(face, u, v), -rotation_deg));
            }
        }
        (sum * (intensity / (n * n) as f32)).extend(1.0)
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_parallel_build_gives_the_serial_texels() {
        let f = |face: usize, x: usize, y: usize| Vec4::new(face as f32, x as f32, y as f32, (x * y) as f32);
        assert_eq!(CubeImage::from_fn_parallel(5, f), CubeImage::from_fn(5, f));
    }

    #[test]
    fn face_dir_and_dir_to_face_are_inverse() {
        for face in 0..6 {
            for &(u, v) in &[(0.0, 0.0), (0.5, -0.25), (-0.9, 0.9), (0.3, 0.7)] {
                let (f, u2, v2) = dir_to_face(face_dir(face, u, v) * 2.5);
                assert_eq!(f, face);
                assert!((u - u2).abs() < 1e-6 && (v - v2).abs() < 1e-6, "face {face}: {u},{v} -> {u2},{v2}");
            }
        }
    }

    #[test]
    fn faces_follow_the_hardware_convention() {
        // Spot checks against the Vulkan cube map table (major axis, sc, tc).
        assert_eq!(dir_to_face(Vec3::new(1.0, 0.5, 0.25)), (0, -0.25, -0.5));
        assert_eq!(dir_to_face(Vec3::new(0.25, 1.0, 0.5)), (2, 0.25, 0.5));
        assert_eq!(dir_to_face(Vec3::new(0.25, -0.5, -1.0)), (5, -0.25, 0.5));
        // Every face has the same handedness: u x v points back toward the cube centre.
        for face in 0..6 {
            let c = face_dir(face, 0.0, 0.0);
            let du = face_dir(face, 1.0, 0.0) - c;
            let dv = face_dir(face, 0.0, 1.0) - c;
            assert!(du.cross(dv).dot(c) < 0.0, "face {face} is mirrored relative to the others");
        }
    }

    #[test]
    fn solid_angles_cover_the_sphere() {
        for size in [1, 2, 7, 64] {
            let total: f64 = (0..size)
                .flat_map(|y| (0..size).map(move |x| (x, y)))
                .map(|(x, y)| texel_solid_angle(size, x, y) as f64)
                .sum::<f64>()
                * 6.0;
            assert!((total - 4.0 * std::f64::consts::PI).abs() < 1e-4, "size {size}: {total}");
        }
        // A corner texel is smaller than a centre one (by about 3^-1.5 for small texels).
        assert!(texel_solid_angle(64, 0, 0) < 0.25 * texel_solid_angle(64, 32, 32));
    }

    #[test]
    fn equirect_uv_matches_the_documented_convention() {
        let (u, v) = equirect_uv(Vec3::new(0.0, 0.0, -1.0));
        assert!((u - 0.5).abs() < 1e-6 && (v - 0.5).abs() < 1e-6);
        let (u, _) = equirect_uv(Vec3::new(1.0, 0.0, 0.0));
        let d = Vec3::new(0.3, -0.4, 0.5).normalize();
        let (du, dv) = equirect_uv(d);
        assert!((equirect_dir(du, dv) - d).length() < 1e-5);
        assert!((u - 0.75).abs() < 1e-6);
        assert!(equirect_uv(Vec3::Y).1 < 1e-6);
    }

    #[test]
    fn a_constant_probe_gives_a_constant_cube() {
        let eq = EquirectImage { width: 8, height: 4, rgb: vec![Vec3::splat(2.0); 32] };
        let cube = cube_from_equirect(&eq, 4, 30.0, 0.5);
        assert!(cube.texels.iter().all(|t| (t.truncate() - Vec3::ONE).abs().max_element() < 1e-6));
    }
}

//! Median cut (Debevec 2008; dissertation §3.2.1, eqs. 3.33-3.34): the cube map's texels split
//! into `n` regions of equal energy, each texel in exactly one region, one directional light
//! per region (used for shadows only; shading uses the partial environment maps).
//!
//! Conventions (the GPU node `MedianCut` must mirror these to give the same regions):
//! - Energy of a texel = Rec. 709 luminance (0.2126 r + 0.7152 g + 0.0722 b) x
//!   [`texel_solid_angle`], summed in f64.
//! - Texels are points in equal-area cylindrical coordinates of their centre direction `d`:
//!   `phi = atan2(d.x, -d.z)` in (-pi, pi] (the azimuth of [`equirect_uv`](super::cube::equirect_uv),
//!   so the cut seam is the equirect map's left/right edge, +Z) and `z = d.y`. Equal area means
//!   equal extents in (phi, z) are equal solid angles, so a cut in these coordinates does not
//!   favour the poles.
//! - A region that must hold `k` lights splits into `k1 = k / 2` (floor) and `k - k1`. The cut
//!   runs across the axis of larger extent measured as arc length on the sphere: the phi
//!   extent times the largest `sqrt(1 - z^2)` in the region (the widest circle of latitude it
//!   touches) against the z extent converted to a polar angle, `acos(z_min) - acos(z_max)`.
//!   Arc lengths, not raw coordinate extents, because a z extent of 0.1 near the pole spans
//!   a much larger angle than near the equator; cutting the longer side keeps regions
//!   roughly square on the sphere, so each light stands for a compact patch.
//! - The texels are sorted by (coordinate, texel index) (deterministic), and the cut goes
//!   where the cumulative energy is closest to `E * k1 / k` (ties: the earlier position), so
//!   each cut is within one texel's energy of its target, and a leaf's energy is within
//!   (cut depth) x (max texel energy) of `E / n`. Each side keeps at least as many texels as
//!   lights. A region with zero energy splits by texel count (`len * k1 / k`).

use anyhow::bail;
use glam::Vec3;

use super::cube::{CubeImage, texel_dir, texel_solid_angle};
use crate::color::luminance;

/// One region's light.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RegionLight {
    /// Unit energy-weighted mean direction of the region's texels (the solid-angle-weighted
    /// one if the region's energy is 0; the first texel's direction if the mean vanishes).
    pub direction: Vec3,
    /// Sum of rgb x solid angle: the region's integral of radiance (the lights sum to the
    /// map's integral).
    pub color: Vec3,
    pub solid_angle: f32,
    pub energy: f32,
    pub texels: u32,
}

/// The median cut's result: a region id per texel and a light per region.
#[derive(Clone, Debug, PartialEq)]
pub struct Regions {
    /// The cube's face size.
    pub size: usize,
    /// Region id per texel, in [`CubeImage`] index order.
    pub ids: Vec<u32>,
    pub lights: Vec<RegionLight>,
}

struct Point {
    phi: f32,
    z: f32,
    energy: f64,
}

/// Splits `cube` into `n` regions of equal energy (see the module doc for the rules).
pub fn median_cut(cube: &CubeImage, n: usize) -> anyhow::Result<Regions> {
    let size = cube.size;
    let count = cube.texels.len();
    if n == 0 {
        bail!("median cut into 0 regions: need at least 1");
    }
    if n > count {
        bail!(
            "median cut into {n} regions: the {size}x{size} cube map has only {count} texels (at most one region per texel)"
        );
    }
    let mut points = Vec::with_capacity(count);
    let mut dirs = Vec::with_capacity(count);
    let mut omegas = Vec::with_capacity(count);
    for face in 0..6 {
        for y in 0..size {
            for x in 0..size {
                let d = texel_dir(size, face, x, y);
                let omega = texel_solid_angle(size, x, y);
                let c = cube.texel(face, x, y).truncate();
                points.push(Point { phi: d.x.atan2(-d.z), z: d.y, energy: luminance(c) as f64 * omega as f64 });
                dirs.push(d);
                omegas.push(omega);
            }
        }
    }
    let mut order: Vec<u32> = (0..count as u32).collect();
    let mut ids = vec![0u32; count];
    let mut next_id = 0u32;
    split(&points, &mut order, n, &mut ids, &mut next_id);
    debug_assert_eq!(next_id as usize, n);

    let mut acc = vec![(Vec3::ZERO, Vec3::ZERO, Vec3::ZERO, 0.0f64, 0.0f64, 0u32, usize::MAX); n];
    for i in 0..count {
        let a = &mut acc[ids[i] as usize];
        let c = cube.texels[i].truncate();
        let (e, w) = (points[i].energy, omegas[i]);
        a.0 += dirs[i] * e as f32;
        a.1 += dirs[i] * w;
        a.2 += c * w;
        a.3 += e;
        a.4 += w as f64;
        a.5 += 1;
        a.6 = a.6.min(i);
    }
    let lights = acc
        .into_iter()
        .map(|(de, dw, color, energy, omega, texels, first)| {
            let mean = if energy > 0.0 { de } else { dw };
            RegionLight {
                direction: mean.try_normalize().unwrap_or(dirs[first]),
                color,
                solid_angle: omega as f32,
                energy: energy as f32,
                texels,
            }
        })
        .collect();
    Ok(Regions { size, ids, lights })
}

fn split(points: &[Point], texels: &mut [u32], k: usize, ids: &mut [u32], next_id: &mut u32) {
    if k == 1 {
        for &t in texels.iter() {
            ids[t as usize] = *next_id;
        }
        *next_id += 1;
        return;
    }
    let (mut phi0, mut phi1, mut z0, mut z1) = (f32::MAX, f32::MIN, f32::MAX, f32::MIN);
    for &t in texels.iter() {
        let p = &points[t as usize];
        phi0 = phi0.min(p.phi);
        phi1 = phi1.max(p.phi);
        z0 = z0.min(p.z);
        z1 = z1.max(p.z);
    }
    // The widest circle of latitude the region touches: z closest to 0.
    let z_wide = if z0 <= 0.0 && z1 >= 0.0 { 0.0 } else { z0.abs().min(z1.abs()) };
    let phi_arc = (phi1 - phi0) * (1.0 - z_wide * z_wide).max(0.0).sqrt();
    let z_arc = z0.clamp(-1.0, 1.0).acos() - z1.clamp(-1.0, 1.0).acos();
    let key = |t: u32| if phi_arc >= z_arc { points[t as usize].phi } else { points[t as usize].z };
    texels.sort_unstable_by(|&a, &b| key(a).total_cmp(&key(b)).then(a.cmp(&b)));

    let k1 = k / 2;
    let k2 = k - k1;
    let len = texels.len();
    let total: f64 = texels.iter().map(|&t| points[t as usize].energy).sum();
    // Cut position = texels in the first part, keeping at least k1 and k2 texels per side.
    let (lo, hi) = (k1, len - k2);
    let cut = if total > 0.0 {
        let target = total * k1 as f64 / k as f64;
        let mut cum = 0.0f64;
        let mut best = (f64::MAX, lo);
        for (i, &t) in texels.iter().enumerate().take(hi) {
            cum += points[t as usize].energy;
            let pos = i + 1;
            if pos >= lo {
                let err = (cum - target).abs();
                if err < best.0 {
                    best = (err, pos);
                }
            }
        }
        best.1
    } else {
        (len * k1 / k).clamp(lo, hi)
    };
    let (a, b) = texels.split_at_mut(cut);
    split(points, a, k1, ids, next_id);
    split(points, b, k2, ids, next_id);
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ibl::cube::dir_to_face;
    use glam::Vec4;

    fn sun_dir() -> Vec3 {
        Vec3::new(0.3, 0.6, -0.5).normalize()
    }

    /// A sky gradient plus a small bright sun (about 1.5 degrees wide, 5000x the sky).
    fn sky_with_sun(size: usize) -> CubeImage {
        CubeImage::from_fn(size, |f, x, y| {
            let d = texel_dir(size, f, x, y);
            let sky = Vec3::new(0.3, 0.5, 0.9) * (0.2 + 0.8 * d.y.max(0.0)) + Vec3::splat(0.05);
            let sun = if d.dot(sun_dir()) > 0.9997 { Vec3::new(5000.0, 4500.0, 4000.0) } else { Vec3::ZERO };
            (sky + sun).extend(1.0)
        })
    }

    fn texel_energies(cube: &CubeImage) -> Vec<f64> {
        let s = cube.size;
        (0..cube.texels.len())
            .map(|i| {
                let (x, y) = (i % s, (i / s) % s);
                luminance(cube.texels[i].truncate()) as f64 * texel_solid_angle(s, x, y) as f64
            })
            .collect()
    }

    #[test]
    fn regions_hold_equal_energy_and_partition_the_texels() {
        let cube = sky_with_sun(32);
        let energies = texel_energies(&cube);
        let total: f64 = energies.iter().sum();
        let max_texel = energies.iter().cloned().fold(0.0, f64::max);
        for n in [1, 3, 5, 12, 64, 256] {
            let r = median_cut(&cube, n).unwrap();
            assert_eq!(r.lights.len(), n);
            assert_eq!(r.ids.len(), cube.texels.len());
            // Disjoint and complete: every texel has one id < n, and the per-region texel
            // counts sum to the texel count.
            assert!(r.ids.iter().all(|&i| (i as usize) < n));
            assert_eq!(r.lights.iter().map(|l| l.texels as usize).sum::<usize>(), cube.texels.len());
            let mut per = vec![0.0f64; n];
            for (i, &id) in r.ids.iter().enumerate() {
                per[id as usize] += energies[i];
            }
            let depth = (n as f64).log2().ceil();
            for (i, e) in per.iter().enumerate() {
                assert!(
                    (e - total / n as f64).abs() <= depth * max_texel * (1.0 + 1e-6) + 1e-9,
                    "n {n} region {i}: energy {e} vs {} (max texel {max_texel})",
                    total / n as f64
                );
                assert!((r.lights[i].energy as f64 - e).abs() <= 1e-4 * e.max(1e-6));
                assert!((r.lights[i].direction.length() - 1.0).abs() < 1e-5);
            }
        }
    }

    #[test]
    fn light_colours_sum_to_the_map_integral() {
        let cube = sky_with_sun(16);
        let s = cube.size;
        let mut integral = glam::DVec3::ZERO;
        for (i, t) in cube.texels.iter().enumerate() {
            integral += t.truncate().as_dvec3() * texel_solid_angle(s, i % s, (i / s) % s) as f64;
        }
        for n in [1, 7, 64] {
            let r = median_cut(&cube, n).unwrap();
            let sum: glam::DVec3 = r.lights.iter().map(|l| l.color.as_dvec3()).sum();
            assert!((sum - integral).abs().max_element() < 1e-4 * integral.max_element(), "n {n}: {sum} vs {integral}");
            let omega: f64 = r.lights.iter().map(|l| l.solid_angle as f64).sum();
            assert!((omega - 4.0 * std::f64::consts::PI).abs() < 1e-3);
        }
    }

    #[test]
    fn bright_areas_get_small_regions() {
        let cube = sky_with_sun(32);
        let n = 64;
        let r = median_cut(&cube, n).unwrap();
        let (f, u, v) = dir_to_face(sun_dir());
        let px = |c: f32| (((c + 1.0) * 0.5 * 32.0) as usize).min(31);
        let id = r.ids[cube.index(f, px(u), px(v))] as usize;
        let mean = 4.0 * std::f32::consts::PI / n as f32;
        let sun_region = r.lights[id].solid_angle;
        assert!(sun_region < 0.02 * mean, "sun region {sun_region} sr vs mean {mean} sr");
        assert!(r.lights[id].direction.dot(sun_dir()) > 0.999);
    }

    #[test]
    fn the_cut_is_deterministic() {
        let cube = sky_with_sun(16);
        assert_eq!(median_cut(&cube, 12).unwrap(), median_cut(&cube, 12).unwrap());
    }

    #[test]
    fn a_black_map_splits_by_texel_count() {
        let cube = CubeImage::new(8);
        let r = median_cut(&cube, 6).unwrap();
        for l in &r.lights {
            assert_eq!(l.texels, 64, "{l:?}");
            assert!((l.direction.length() - 1.0).abs() < 1e-5);
        }
        // One region per texel works too.
        let r = median_cut(&CubeImage::from_fn(2, |_, _, _| Vec4::ONE), 24).unwrap();
        assert!(r.lights.iter().all(|l| l.texels == 1));
    }

    #[test]
    fn too_many_regions_is_an_error() {
        let cube = CubeImage::new(4);
        let e = median_cut(&cube, 97).unwrap_err().to_string();
        assert!(e.contains("97 regions") && e.contains("96 texels"), "{e}");
        assert!(median_cut(&cube, 0).is_err());
    }
}

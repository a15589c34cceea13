//! Bidirectional texture functions of cloth (Sattler, Sarlette and Klein, "Efficient and
//! realistic visualization of cloth", 2003): the measured directions and the weights that blend
//! them ([`directions`]), the project's BTF file ([`container`]), per-view PCA compression
//! ([`pca`]) and its upload for rendering ([`gpu`]), BTFs baked from woven yarn geometry
//! ([`bake`]) and measured ones read from folders of images ([`measured`]). See `docs/btf.md`.

pub mod bake;
pub mod container;
pub mod directions;
pub mod gpu;
pub mod hem;
pub mod measured;
pub mod pca;
pub mod pca_file;

use directions::{Dir, Sampling};

/// A BTF in memory: for every view and light direction of `sampling`, one `width x height` RGB
/// image of reflected radiance under unit irradiance from the light (cos theta_i included).
///
/// Texel (column c, row r) shows the point `((c + 0.5) / width, 1 - (r + 0.5) / height)` of the
/// tile, in units of the tile and in the tangent frame of [`directions`] (x along the warp, y
/// towards the bitangent): row 0 is the top of an image seen from above, x to the right, y up.
#[derive(Clone, Debug, PartialEq)]
pub struct Btf {
    pub width: usize,
    pub height: usize,
    /// Views and lights share one sampling, as in the paper's measurement.
    pub sampling: Sampling,
    /// View-major, then light, then rows top to bottom, texels, RGB.
    pub data: Vec<f32>,
}

impl Btf {
    /// Values per image.
    pub fn image_len(&self) -> usize {
        self.width * self.height * 3
    }

    /// The light images of view slot `view`, concatenated (the rows of eq. 1's matrix).
    pub fn slot(&self, view: usize) -> &[f32] {
        let n = self.sampling.len();
        &self.data[view * n * self.image_len()..][..n * self.image_len()]
    }

    /// The analytic Lambertian BTF `N = rho / pi cos(theta_i)`, with albedo `rho(x, y)`, the
    /// same in every view.
    pub fn lambertian(sampling: Sampling, width: usize, height: usize, rho: impl Fn(usize, usize) -> [f32; 3]) -> Btf {
        let dirs = sampling.directions();
        let mut data = Vec::with_capacity(dirs.len() * dirs.len() * width * height * 3);
        for _view in &dirs {
            for light in &dirs {
                let cos = light.theta.to_radians().cos() as f32;
                for y in 0..height {
                    for x in 0..width {
                        data.extend(rho(x, y).map(|r| r / std::f32::consts::PI * cos));
                    }
                }
            }
        }
        Btf { width, height, sampling, data }
    }

    /// The plain texture of the frontal view that the paper compares against (Figs. 2, 13): the
    /// image of the frontal view and light, `N(0, 0)`, lit by cos(theta_i) alone in every view,
    /// i.e. [`Btf::lambertian`] with albedo `pi N(0, 0)` (the stored values include cos 0 = 1).
    /// The mesostructure's parallax, self-shadowing and highlights are gone. Fails without a
    /// frontal direction (a first ring at theta 0).
    pub fn frontal(&self) -> anyhow::Result<Btf> {
        check_frontal(&self.sampling)?;
        // View 0 and light 0 are both the pole.
        let image = &self.data[..self.image_len()];
        let width = self.width;
        Ok(Btf::lambertian(self.sampling.clone(), self.width, self.height, |x, y| {
            let t = &image[(y * width + x) * 3..][..3];
            [t[0], t[1], t[2]].map(|v| v * std::f32::consts::PI)
        }))
    }

    /// The index of the direction of the sampling at `d` (within 0.5 deg; any phi at the pole).
    pub fn direction_index(&self, d: Dir) -> Option<usize> {
        self.sampling.directions().iter().position(|m| {
            let dphi = (m.phi - d.phi).rem_euclid(360.0);
            (m.theta - d.theta).abs() < 0.5 && (m.theta == 0.0 || dphi.min(360.0 - dphi) < 0.5)
        })
    }

    /// The image at any view and light direction from the uncompressed images: the light weights
    /// of eq. 3 inside the view weights of eq. 5, both from [`Sampling::weights`].
    pub fn blend(&self, view: Dir, light: Dir) -> Vec<f32> {
        let (n, len) = (self.sampling.len(), self.image_len());
        let mut out = vec![0.0f64; len];
        for (j, wv) in self.sampling.weights(view) {
            for (i, wl) in self.sampling.weights(light) {
                let w = wv * wl;
                if w == 0.0 {
                    continue;
                }
                for (o, &x) in out.iter_mut().zip(&self.data[(j * n + i) * len..][..len]) {
                    *o += w * x as f64;
                }
            }
        }
        out.into_iter().map(|x| x as f32).collect()
    }
}

/// Whether a BTF on `sampling` has the frontal direction [`Btf::frontal`] needs.
pub fn check_frontal(sampling: &Sampling) -> anyhow::Result<()> {
    anyhow::ensure!(
        sampling.rings.first().is_some_and(|r| r.theta == 0.0),
        "the BTF has no frontal direction (its first ring is not at theta 0)"
    );
    Ok(())
}

/// The exposure of the paper's 8-bit error metric (Fig. 6): the 99.5th percentile of `data`
/// maps to 255. Over 16 M values the percentile is that of every k-th value (at most 16 M of
/// them), so the 256² tier's 1.3 G values need no 5 GB copy.
pub fn exposure8(data: &[f32]) -> f64 {
    const MOST: usize = 1 << 24;
    let stride = data.len().div_ceil(MOST).max(1);
    let mut values: Vec<f32> = data.iter().step_by(stride).copied().filter(|x| x.is_finite()).collect();
    if values.is_empty() {
        return 1.0;
    }
    let rank = ((values.len() as f64 * 0.995) as usize).min(values.len() - 1);
    let p995 = *values.select_nth_unstable_by(rank, f32::total_cmp).1;
    if p995 > 0.0 { 255.0 / p995 as f64 } else { 1.0 }
}

/// Per texel of two RGB images, the length of the 8-bit RGB error vector (Fig. 6): both scaled
/// by `exposure` and clamped to [0, 255].
pub fn error8(a: &[f32], b: &[f32], exposure: f64) -> Vec<f64> {
    let to8 = |x: f32| (x as f64 * exposure).clamp(0.0, 255.0);
    a.chunks_exact(3)
        .zip(b.chunks_exact(3))
        .map(|(p, q)| p.iter().zip(q).map(|(&x, &y)| (to8(x) - to8(y)).powi(2)).sum::<f64>().sqrt())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_frontal_texture_is_the_frontal_image_lit_by_the_cosine() {
        // Every image differs: the frontal one must be picked, and only its texels kept.
        let sampling = Sampling::h2_tests();
        let n = sampling.len();
        let data: Vec<f32> = (0..n * n * 2 * 2 * 3).map(|k| (k % 97) as f32 / 97.0).collect();
        let btf = Btf { width: 2, height: 2, sampling, data };
        let plain = btf.frontal().unwrap();
        let dirs = plain.sampling.directions();
        for (j, _) in dirs.iter().enumerate() {
            for (i, light) in dirs.iter().enumerate() {
                let cos = light.theta.to_radians().cos() as f32;
                let got = &plain.data[(j * n + i) * 12..][..12];
                for (g, f) in got.iter().zip(&btf.data[..12]) {
                    assert!((g - f * cos).abs() < 1e-6, "view {j}, light {i}: {g} against {}", f * cos);
                }
            }
        }
        let no_pole = Btf {
            width: 1,
            height: 1,
            sampling: Sampling { rings: vec![directions::Ring { theta: 10.0, count: 2 }] },
            data: vec![0.0; 12],
        };
        assert!(no_pole.frontal().is_err());
    }

    #[test]
    fn directions_are_found_within_half_a_degree_and_at_the_pole_at_any_phi() {
        let btf = Btf { width: 1, height: 1, sampling: Sampling::h2(), data: Vec::new() };
        assert_eq!(btf.direction_index(Dir { theta: 0.0, phi: 123.0 }), Some(0));
        assert_eq!(btf.direction_index(Dir { theta: 15.0, phi: 60.2 }), Some(2));
        // The wrap: 359.8 deg is 0 on the 15 deg ring.
        assert_eq!(btf.direction_index(Dir { theta: 15.0, phi: 359.8 }), Some(1));
        let i = btf.direction_index(Dir { theta: 75.0, phi: 45.0 }).unwrap();
        assert_eq!(btf.sampling.directions()[i], Dir { theta: 75.0, phi: 45.0 });
        assert_eq!(btf.direction_index(Dir { theta: 15.0, phi: 30.0 }), None);
        assert_eq!(btf.direction_index(Dir { theta: 20.0, phi: 0.0 }), None);
    }
}

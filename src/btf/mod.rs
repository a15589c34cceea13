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

/// The exposure of the paper's 8-bit error metric (Fig. 6): the 99.5th percentile of `data`
/// maps to 255.
pub fn exposure8(data: &[f32]) -> f64 {
    let mut sorted: Vec<f32> = data.iter().copied().filter(|x| x.is_finite()).collect();
    sorted.sort_by(f32::total_cmp);
    let p995 = sorted.get((sorted.len() as f64 * 0.995) as usize).or(sorted.last()).copied().unwrap_or(1.0);
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

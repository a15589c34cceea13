//! Bidirectional texture functions of cloth (Sattler, Sarlette and Klein, "Efficient and
//! realistic visualization of cloth", 2003): the measured directions and the weights that blend
//! them ([`directions`]), the project's BTF file ([`container`]), per-view PCA compression
//! ([`pca`]) and its upload for rendering ([`gpu`]). See `docs/btf.md`.

pub mod container;
pub mod directions;
pub mod gpu;
pub mod pca;

use directions::Sampling;

/// A BTF in memory: for every view and light direction of `sampling`, one `width x height` RGB
/// image of reflected radiance under unit irradiance from the light (cos theta_i included).
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
}

//! Partial environment maps (dissertation §3.2.1, §5.2.1; eqs. 3.39-3.42): the 5x5 mip filter
//! kernels, the CPU twin of the GPU mip filter, the glossiness-to-level calibration by lobe
//! volume matching, the lobe error of Figs. 5.19/5.20 and the memory formula of Table 5.1.
//!
//! # The filter (mirrored exactly by the GPU shader)
//! Level k+1 (face size S/2) from level k (face size S): for face f and texel (x, y), the centre
//! `uc = texel_center(S/2, x)`, `vc = texel_center(S/2, y)` and the source texel step
//! `h = 2/S`; for b in -2..=2 (outer), a in -2..=2 (inner):
//! `sum += w[b+2][a+2] * level_k.sample(face_dir(f, uc + a*h, vc + b*h))` (face coordinates may
//! leave [-1, 1]: the direction then falls on the neighbouring face, which is how the filter
//! crosses seams); the texel is `sum / sum_of_weights`. `sample` is the bilinear lookup clamped
//! within the face the direction falls on ([`CubeImage::sample`]). With the `none` kernel the
//! one tap lies on the corner of four level-k texels, so a level is their 2x2 average: a plain
//! mip chain.
//!
//! # Calibration (eqs. 3.39-3.42, lobe volume matching)
//! Glossiness g in [0, 1] gives the Phong exponent s = 1/(1-g); the shader looks up along
//! r' = n(1-g) + r g at level L(s). The lobe of a (fractional) level L is the response to an
//! impulse: texel ([`impulse_texel`]) of face +Z of level 0 set to 1, all others 0, filtered
//! into a chain, then looked up with `CubeImage::sample` along every level-0 texel direction,
//! with linear interpolation between the two levels around L (what trilinear sampling does).
//! Its volume is the integral over the sphere (sum of response x `texel_solid_angle` over the
//! level-0 texels) divided by its peak (the largest looked-up value, computed on the
//! interpolated response, not interpolated between levels). The Phong lobe max(0, cos)^s has
//! peak 1 and volume 2 pi/(s+1). L(s) is the fractional level whose volume equals it, found
//! by bisection within the first pair of levels whose volumes bracket it, clamped to
//! [0, top level]. The table holds L at s = 2^(i * 10/32), i in 0..33.

use std::collections::HashMap;
use std::f64::consts::PI;
use std::sync::{Arc, LazyLock, Mutex};

use glam::Vec4;

use super::cube::{CubeImage, face_dir, texel_center, texel_dir, texel_solid_angle};

crate::choice!(
    /// The 5x5 kernel applied at every mip generation step (§3.2.1: "Gaussian, cosine, cosine
    /// powers, box, and square root of cosine"); see [`weights`].
    pub enum Kernel {
        None = "none",
        Box = "box",
        Gaussian = "gaussian",
        Cosine = "cosine",
        SqrtCosine = "sqrt_cosine",
        /// Not a 5x5 kernel: each level is level 0 convolved with a Phong lobe ([`phong_level`]).
        Phong = "phong",
    }
);

impl Kernel {
    pub const ALL: [Kernel; 6] =
        [Kernel::None, Kernel::Box, Kernel::Gaussian, Kernel::Cosine, Kernel::SqrtCosine, Kernel::Phong];
}

/// The Phong prefilter: the only kernel that meets the lobe-error aim (docs/ibl.md); the
/// dissertation's choice, sqrt_cosine, stays selectable.
impl Default for Kernel {
    fn default() -> Kernel {
        Kernel::Phong
    }
}

/// The 5x5 weights, indexed `[b + 2][a + 2]` for tap offsets a (along u) and b (along v) in
/// -2..=2 source texels, with rho = sqrt(a^2 + b^2): none: 1 at the centre, 0 elsewhere;
/// box: 1; gaussian: exp(-rho^2/2) (sigma = 1 texel); cosine: cos(pi/2 * rho/3) (support
/// radius 3 texels, so every tap, rho <= sqrt 8, is positive); sqrt_cosine: the square root
/// of the cosine weight. Not normalized (the filter divides by their sum).
pub fn weights(kernel: Kernel) -> [[f32; 5]; 5] {
    let mut w = [[0.0f32; 5]; 5];
    for (bi, row) in w.iter_mut().enumerate() {
        for (ai, wt) in row.iter_mut().enumerate() {
            let (a, b) = (ai as f32 - 2.0, bi as f32 - 2.0);
            let rho = (a * a + b * b).sqrt();
            let cosine = (std::f32::consts::FRAC_PI_2 * rho / 3.0).cos();
            *wt = match kernel {
                Kernel::None => {
                    if ai == 2 && bi == 2 {
                        1.0
                    } else {
                        0.0
                    }
                }
                Kernel::Box => 1.0,
                Kernel::Gaussian => (-rho * rho / 2.0).exp(),
                Kernel::Cosine => cosine,
                Kernel::SqrtCosine => cosine.sqrt(),
                // Unused: phong levels are not made from the level above (see filter_chain).
                Kernel::Phong => f32::from(ai == 2 && bi == 2),
            };
        }
    }
    w
}

/// One filter step (see the module doc): the next mip level, face size `src.size / 2`.
///
/// # Panics
/// If `src.size` is odd or below 2.
pub fn filter_level(src: &CubeImage, kernel: Kernel) -> CubeImage {
    assert!(src.size >= 2 && src.size.is_multiple_of(2), "filter_level: face size {} is not even and >= 2", src.size);
    let w = weights(kernel);
    let wsum: f32 = w.iter().flatten().sum();
    let n = src.size / 2;
    let h = 2.0 / src.size as f32;
    let mut out = CubeImage::new(n);
    if kernel == Kernel::None {
        // The one tap at the texel's centre lies on the corner of four source texels of the
        // same face: their average (shaders/ibl/pem_filter.wgsl box).
        for (face, texels) in out.texels.chunks_mut(n * n).enumerate() {
            let at = |x: usize, y: usize| src.texels[(face * src.size + y) * src.size + x];
            for y in 0..n {
                for x in 0..n {
                    let sum = at(2 * x, 2 * y) + at(2 * x + 1, 2 * y) + at(2 * x, 2 * y + 1) + at(2 * x + 1, 2 * y + 1);
                    texels[y * n + x] = 0.25 * sum;
                }
            }
        }
        return out;
    }
    let run = |face: usize, texels: &mut [Vec4]| {
        for y in 0..n {
            let vc = texel_center(n, y);
            for x in 0..n {
                let uc = texel_center(n, x);
                let mut sum = Vec4::ZERO;
                for (bi, row) in w.iter().enumerate() {
                    let v = vc + (bi as f32 - 2.0) * h;
                    for (ai, &wt) in row.iter().enumerate() {
                        if wt != 0.0 {
                            let u = uc + (ai as f32 - 2.0) * h;
                            sum += wt * src.sample(face_dir(face, u, v));
                        }
                    }
                }
                texels[y * n + x] = sum / wsum;
            }
        }
    };
    if n >= 16 {
        std::thread::scope(|s| {
            for (face, texels) in out.texels.chunks_mut(n * n).enumerate() {
                s.spawn(move || run(face, texels));
            }
        });
    } else {
        for (face, texels) in out.texels.chunks_mut(n * n).enumerate() {
            run(face, texels);
        }
    }
    out
}

/// The whole chain: `level0` (cloned) and every filtered level down to 1x1 per face.
///
/// # Panics
/// If `level0.size` is not a power of two.
pub fn filter_chain(level0: &CubeImage, kernel: Kernel) -> Vec<CubeImage> {
    assert!(level0.size.is_power_of_two(), "filter_chain: face size {} is not a power of two", level0.size);
    if kernel == Kernel::Phong {
        let plain = filter_chain(level0, Kernel::None);
        let mut chain = vec![level0.clone()];
        chain.extend((1..plain.len()).map(|l| phong_level(&plain, l)));
        return chain;
    }
    let mut chain = vec![level0.clone()];
    while chain.last().unwrap().size > 1 {
        let next = filter_level(chain.last().unwrap(), kernel);
        chain.push(next);
    }
    chain
}

/// Lobe volume of a Phong level, in texels of that level: the lobe spans several texels so
/// that bilinear lookups reconstruct its shape (a plain mip chain's lobe spans about two).
pub const PHONG_TEXELS_PER_LOBE: f32 = 54.0;

/// Phong levels this small (face size) sum over the whole sphere; larger ones over a window.
pub const PHONG_FULL_SPHERE_SIZE: usize = 16;

/// The Phong exponent stored at mip level `level` of a chain whose level 0 is `size` wide:
/// the lobe whose volume 2 pi/(s+1) is [`PHONG_TEXELS_PER_LOBE`] texels of that level (a
/// texel subtends about 4 pi/(6 S^2) = 2 pi/(3 S^2) at face size S), so
/// s = 3 S^2/16 - 1, at least 1 (the diffuse lobe); infinite at level 0 (the map itself).
pub fn phong_exponent(size: usize, level: usize) -> f32 {
    if level == 0 {
        return f32::INFINITY;
    }
    let s = (size >> level).max(1) as f32;
    (3.0 * s * s / PHONG_TEXELS_PER_LOBE - 1.0).max(1.0)
}

/// Half-width in texels of the window a Phong level of face size `n` and exponent `s` sums:
/// 1.25 tan(theta) / (2/n) + 1, theta where cos^s falls to 1% of its peak (the 1.25 covers
/// the gnomonic plane's compression away from the face centre).
pub fn phong_window(n: usize, s: f32) -> i32 {
    let theta = ((0.01f32).ln() / s).exp().clamp(-1.0, 1.0).acos();
    ((1.25 * theta.tan() * n as f32 / 2.0).ceil() as i32 + 1).min(64)
}

/// The plain-chain level a Phong level `level` of a chain whose level 0 is `size` wide reads.
/// Windowed levels read the next coarser level: with [`PHONG_TEXELS_PER_LOBE`] texels per lobe
/// volume the lobe's sigma spans about 1.5 texels there, and the window holds 2.6x fewer
/// taps (13^2 instead of 21^2). Summing texel centres adds no lookup blur, and the 2x2 box
/// pre-filter widens the lobe by about 2%, which the calibration measures with the rest.
/// Whole-sphere levels (small, and wide lobes) read their own level.
pub fn phong_source(size: usize, level: usize) -> usize {
    if (size >> level) > PHONG_FULL_SPHERE_SIZE { level + 1 } else { level }
}

/// The source texel of a face of size `src` holding the centre of texel `i` of a face of size
/// `dst` (`src` divides `dst`): the centre of a Phong window, whose taps are source texel
/// centres.
pub fn window_centre(i: usize, dst: usize, src: usize) -> usize {
    i * src / dst
}

/// The solid angle of a point sample at face coordinates (u, v) spaced `h` apart on a face
/// plane: h^2 / (1 + u^2 + v^2)^(3/2).
fn plane_solid_angle(u: f32, v: f32, h: f32) -> f32 {
    h * h / (1.0 + u * u + v * v).powf(1.5)
}

/// Level `level` of the Phong prefilter: per texel with direction r, the normalized integral
/// of the plain (2x2 box) chain's level [`phong_source`] against max(0, r.w)^s, s =
/// [`phong_exponent`]: a quadrature over that level's texels, each weighted by the lobe and its
/// solid angle. Destination faces of [`PHONG_FULL_SPHERE_SIZE`] or less sum every source texel
/// of all six faces; larger ones sum a (2w+1)^2 window ([`phong_window`]) of source texel
/// centres around the one holding the texel's centre ([`window_centre`]), extended past
/// the face's edges on its plane into the neighbouring faces and read there with the seamless
/// bilinear lookup. The weights depend only on geometry, so PEMs filtered this way still sum
/// to the filtered map.
/// shaders/ibl/pem_phong.wgsl `fs_phong` is the GPU version.
pub fn phong_level(plain: &[CubeImage], level: usize) -> CubeImage {
    let size = plain[0].size;
    phong_convolve(&plain[phong_source(size, level)], (size >> level).max(1), phong_exponent(size, level))
}

/// `src` convolved with the normalized lobe max(0, r.w)^s into a cube of face size `n` (the
/// quadrature of [`phong_level`]).
fn phong_convolve(src: &CubeImage, n: usize, s: f32) -> CubeImage {
    let m = src.size;
    let h = 2.0 / m as f32;
    let run = |face: usize, texels: &mut [Vec4]| {
        for y in 0..n {
            for x in 0..n {
                let (uc, vc) = (texel_center(n, x), texel_center(n, y));
                let r = face_dir(face, uc, vc).normalize();
                let (mut sum, mut total) = (Vec4::ZERO, 0.0f32);
                if n <= PHONG_FULL_SPHERE_SIZE {
                    for (i, t) in src.texels.iter().enumerate() {
                        let (f, tx, ty) = (i / (m * m), i % m, (i / m) % m);
                        let (u, v) = (texel_center(m, tx), texel_center(m, ty));
                        let c = r.dot(face_dir(f, u, v).normalize());
                        if c > 0.0 {
                            let w = c.powf(s) * plane_solid_angle(u, v, h);
                            sum += w * *t;
                            total += w;
                        }
                    }
                } else {
                    let win = phong_window(m, s);
                    let (cx, cy) = (window_centre(x, n, m) as i32, window_centre(y, n, m) as i32);
                    let plane = |t: i32| 2.0 * (t as f32 + 0.5) / m as f32 - 1.0;
                    for b in -win..=win {
                        for a in -win..=win {
                            let (u, v) = (plane(cx + a), plane(cy + b));
                            let d = face_dir(face, u, v).normalize();
                            let c = r.dot(d);
                            if c > 0.0 {
                                let w = c.powf(s) * plane_solid_angle(u, v, h);
                                sum += w * src.sample(d);
                                total += w;
                            }
                        }
                    }
                }
                texels[y * n + x] = sum / total;
            }
        }
    };
    let mut out = CubeImage::new(n);
    std::thread::scope(|sc| {
        for (face, texels) in out.texels.chunks_mut(n * n).enumerate() {
            sc.spawn(move || run(face, texels));
        }
    });
    out
}

/// Face size of the diffuse end ([`diffuse_end`]); at most the map's.
pub const DIFFUSE_SIZE: usize = 16;

/// The chain's face size where shading hands over from the diffuse end to the chain
/// ([`Handover`]).
pub const HANDOVER_SIZE: usize = 8;

/// The diffuse end of a map's filtering: level 0 convolved with the cosine lobe (s = 1, a
/// Lambertian surface's irradiance / pi) at face size min([`DIFFUSE_SIZE`], size), summed over
/// the whole sphere from the plain chain's level of that size (`plain`, from
/// `filter_chain(level0, Kernel::None)`). A chain's own s = 1 level is far coarser (4^2 faces
/// for phong at 128^2, 2^2 for the 5x5 kernels), and bilinear lookups between texels that far
/// apart flatten the irradiance's maximum: a Lambertian floor under the forest probe lost 4-7%
/// of its light. At 16^2 the texel centres are under 4 degrees from any direction.
pub fn diffuse_end(plain: &[CubeImage]) -> CubeImage {
    let d = plain[0].size.min(DIFFUSE_SIZE);
    let src = plain.iter().find(|c| c.size == d).expect("a plain chain reaches every power of two");
    phong_convolve(src, d, 1.0)
}

/// Where shading hands over from the diffuse end to the chain: for exponents s in [1,
/// `exponent`) the lookup blends the diffuse end with the chain at `level` (face size
/// [`HANDOVER_SIZE`]), whose calibrated exponent is `exponent`, by lobe volume
/// ([`Handover::diffuse_weight`]); from `exponent` on it is the chain alone, at the calibrated
/// level (equal at the handover).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Handover {
    pub level: f32,
    pub exponent: f32,
}

impl Handover {
    /// The diffuse end's weight at exponent s: the blend of a cosine lobe (volume 2 pi/2) and
    /// the handover level's lobe (2 pi/(s_b + 1)) whose volume is the Phong lobe's, 2 pi/(s + 1).
    pub fn diffuse_weight(&self, s: f32) -> f32 {
        if s >= self.exponent {
            return 0.0;
        }
        let chain = (1.0 / (s.max(1.0) + 1.0) - 0.5) / (1.0 / (self.exponent + 1.0) - 0.5);
        1.0 - chain.clamp(0.0, 1.0)
    }
}

/// The impulse of the lobe measurements: texel (size/2, size/2) of face +Z (index 4), the
/// texel just below and right of the face centre (a single texel cannot sit on the centre).
pub fn impulse_texel(size: usize) -> (usize, usize, usize) {
    (4, size / 2, size / 2)
}

/// The impulse response of a kernel's chain, looked up along every level-0 texel direction.
struct LobeModel {
    omegas: Vec<f32>,
    /// cos of the angle between each level-0 texel direction and the impulse direction.
    cosines: Vec<f32>,
    /// Per level: the response (red channel) along each level-0 texel direction.
    responses: Vec<Vec<f32>>,
    /// Per level: the response's integral over the sphere.
    integrals: Vec<f64>,
    /// Per level l: the texels that can hold the peak of a blend of levels l and l + 1 (see
    /// [`peak_candidates`]); the bisections of [`LobeModel::level_for_volume`] ask for
    /// hundreds of peaks.
    peak_candidates: Vec<Vec<u32>>,
}

/// The texels where (1 - t) a + t b can peak for some t in [0, 1]: with a, b >= 0, a texel
/// below half of both maxima stays below max((1 - t) max a, t max b), which the argmax of a
/// (or of b) reaches. Every texel where a response is negative.
fn peak_candidates(a: &[f32], b: &[f32]) -> Vec<u32> {
    if a.iter().chain(b).any(|&v| v < 0.0) {
        return (0..a.len() as u32).collect();
    }
    let (ha, hb) = (a.iter().fold(0.0f32, |m, &v| m.max(v)) * 0.5, b.iter().fold(0.0f32, |m, &v| m.max(v)) * 0.5);
    (0..a.len()).filter(|&i| a[i] >= ha || b[i] >= hb).map(|i| i as u32).collect()
}

impl LobeModel {
    fn new(kernel: Kernel, size: usize) -> LobeModel {
        let (face, ix, iy) = impulse_texel(size);
        let mut impulse = CubeImage::new(size);
        let i = impulse.index(face, ix, iy);
        impulse.texels[i] = Vec4::ONE;
        let d0 = texel_dir(size, face, ix, iy);
        let chain = filter_chain(&impulse, kernel);
        let mut dirs = Vec::with_capacity(6 * size * size);
        let mut omegas = Vec::with_capacity(6 * size * size);
        for f in 0..6 {
            for y in 0..size {
                for x in 0..size {
                    dirs.push(texel_dir(size, f, x, y));
                    omegas.push(texel_solid_angle(size, x, y));
                }
            }
        }
        let cosines = dirs.iter().map(|d| d.dot(d0)).collect();
        let responses: Vec<Vec<f32>> =
            chain.iter().map(|level| dirs.iter().map(|&d| level.sample(d).x).collect()).collect();
        let integrals =
            responses.iter().map(|r| r.iter().zip(&omegas).map(|(&v, &w)| v as f64 * w as f64).sum()).collect();
        let top = responses.len() - 1;
        let peak_candidates =
            (0..top.max(1)).map(|l| peak_candidates(&responses[l], &responses[(l + 1).min(top)])).collect();
        LobeModel { omegas, cosines, responses, integrals, peak_candidates }
    }

    fn top(&self) -> usize {
        self.responses.len() - 1
    }

    /// The levels around `level` and the fraction between them.
    fn bracket(&self, level: f32) -> (usize, usize, f32) {
        let level = level.clamp(0.0, self.top() as f32);
        let l = (level.floor() as usize).min(self.top().saturating_sub(1));
        let l1 = (l + 1).min(self.top());
        (l, l1, level - l as f32)
    }

    fn for_each_response(&self, level: f32, mut f: impl FnMut(usize, f32)) {
        let (l, l1, t) = self.bracket(level);
        let (a, b) = (&self.responses[l], &self.responses[l1]);
        for i in 0..a.len() {
            f(i, (1.0 - t) * a[i] + t * b[i]);
        }
    }

    fn peak(&self, level: f32) -> f32 {
        let (l, l1, t) = self.bracket(level);
        let (a, b) = (&self.responses[l], &self.responses[l1]);
        self.peak_candidates[l].iter().map(|&i| (1.0 - t) * a[i as usize] + t * b[i as usize]).fold(0.0, f32::max)
    }

    fn integral(&self, level: f32) -> f64 {
        let (l, l1, t) = self.bracket(level);
        (1.0 - t as f64) * self.integrals[l] + t as f64 * self.integrals[l1]
    }

    /// Integral over peak of the (interpolated) response at `level`.
    fn volume(&self, level: f32) -> f64 {
        self.integral(level) / self.peak(level) as f64
    }

    /// The fractional level whose volume is `target` (see the module doc).
    fn level_for_volume(&self, target: f64) -> f32 {
        let top = self.top();
        let volumes: Vec<f64> = (0..=top).map(|l| self.volume(l as f32)).collect();
        if target <= volumes[0] {
            return 0.0;
        }
        let Some(l) = (0..top).find(|&l| volumes[l] <= target && target <= volumes[l + 1]) else {
            return top as f32;
        };
        let (mut lo, mut hi) = (0.0f32, 1.0f32);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if self.volume(l as f32 + mid) < target {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        l as f32 + 0.5 * (lo + hi)
    }

    /// Relative L1 difference between the peak-normalized response at `level` and
    /// max(0, cos)^s, in units of the Phong volume 2 pi/(s+1).
    fn shape_error(&self, level: f32, s: f32) -> f64 {
        let peak = self.peak(level);
        let mut sum = 0.0f64;
        self.for_each_response(level, |i, r| {
            let phong = self.cosines[i].max(0.0).powf(s);
            sum += ((r / peak - phong).abs() * self.omegas[i]) as f64;
        });
        sum / phong_volume(s)
    }
}

/// The volume of the Phong lobe max(0, cos)^s (peak 1): 2 pi/(s+1).
pub fn phong_volume(s: f32) -> f64 {
    2.0 * PI / (s as f64 + 1.0)
}

/// Memo per (kernel, face size).
type Memo<T> = LazyLock<Mutex<HashMap<(Kernel, usize), Arc<T>>>>;

static MODELS: Memo<LobeModel> = LazyLock::new(Default::default);

fn lobe_model(kernel: Kernel, size: usize) -> Arc<LobeModel> {
    if let Some(m) = MODELS.lock().unwrap().get(&(kernel, size)) {
        return m.clone();
    }
    // Built outside the lock (two racing builds give the same model).
    let m = Arc::new(LobeModel::new(kernel, size));
    MODELS.lock().unwrap().entry((kernel, size)).or_insert(m).clone()
}

/// Entries of the calibration table: s = 2^(i * 10/(TABLE-1)), i in 0..TABLE (1 to 1024).
pub const TABLE: usize = 33;

/// The exponent of table entry `i`.
pub fn table_exponent(i: usize) -> f32 {
    (i as f32 * 10.0 / (TABLE - 1) as f32).exp2()
}

/// Glossiness to mip level for one kernel and face size (see the module doc).
#[derive(Clone, Debug, PartialEq)]
pub struct Calibration {
    pub kernel: Kernel,
    pub size: usize,
    /// L at s = [`table_exponent`]`(i)`.
    pub levels: Vec<f32>,
}

impl Calibration {
    /// # Panics
    /// If `size` is not a power of two.
    pub fn compute(kernel: Kernel, size: usize) -> Calibration {
        let model = lobe_model(kernel, size);
        let levels = (0..TABLE).map(|i| model.level_for_volume(phong_volume(table_exponent(i)))).collect();
        Calibration { kernel, size, levels }
    }

    /// The level for Phong exponent `s`: linear in log2 s between table entries; below s = 1
    /// the s = 1 level; beyond the table's end extrapolated with the last segment's slope
    /// (a volume-matched level falls by about 1/2 per doubling of s), clamped at 0.
    pub fn level_for_exponent(&self, s: f32) -> f32 {
        let x = s.max(1.0).log2() * (TABLE - 1) as f32 / 10.0;
        if !x.is_finite() {
            return 0.0;
        }
        let i = (x.floor() as usize).min(TABLE - 2);
        let t = x - i as f32;
        let l = self.levels[i] + (self.levels[i + 1] - self.levels[i]) * t;
        l.max(0.0)
    }

    /// The handover from the diffuse end to the chain ([`Handover`]) and the exponent the
    /// table gives its level (bisection in log2 s). Phong: the level of face size
    /// [`HANDOVER_SIZE`] (its coarser levels all hold s = 1, too coarse to look up). A 5x5
    /// kernel: the whole level at or finer than its s = 1 level, so its glossy lobes stay the
    /// dissertation's (blending its coarse lobes with a cosine lobe over a wide range of s
    /// made a glossy ball 10 points farther from Cycles). None where the map is smaller than
    /// [`DIFFUSE_SIZE`] or the level holds s = 1 itself.
    pub fn handover(&self) -> Option<Handover> {
        if self.size < DIFFUSE_SIZE {
            return None;
        }
        let level = match self.kernel {
            Kernel::Phong => (self.size / HANDOVER_SIZE).ilog2() as f32,
            _ => self.levels[0].floor(),
        };
        if self.levels[0] <= level {
            return None;
        }
        let (mut lo, mut hi) = (0.0f32, 10.0f32);
        for _ in 0..40 {
            let mid = 0.5 * (lo + hi);
            if self.level_for_exponent(mid.exp2()) > level {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        Some(Handover { level, exponent: (0.5 * (lo + hi)).exp2() })
    }

    /// The level for glossiness `g` (s = 1/(1-g); g >= 1 is the mirror: level 0).
    pub fn level_for_glossiness(&self, g: f32) -> f32 {
        if g >= 1.0 {
            return 0.0;
        }
        self.level_for_exponent(1.0 / (1.0 - g.max(0.0)))
    }
}

static CALIBRATIONS: Memo<Calibration> = LazyLock::new(Default::default);

/// Tables of [`Calibration::compute`] as f32 bits, for the kernels and face sizes the bundled
/// graphs use: computing one takes a CPU Phong filter of an impulse and lookups along every
/// texel (about 0.2 s in a release build, on the first frame). A test recomputes each.
const PRECOMPUTED: &[(Kernel, usize, [u32; TABLE])] = &[
    (
        Kernel::Phong,
        128,
        [
            1084227108, 1083889752, 1083478148, 1083004528, 1082372032, 1081957178, 1081664076, 1081323944, 1080898868,
            1080366806, 1079699528, 1078860622, 1077901744, 1077560556, 1077136586, 1076609670, 1075954686, 1075140322,
            1074127496, 1073314911, 1072551139, 1071600711, 1070417421, 1068943306, 1067105478, 1065332806, 1065297216,
            1065253020, 1065198132, 1065129970, 1065045318, 1064940188, 1064809626,
        ],
    ),
    (
        Kernel::SqrtCosine,
        128,
        [
            1086550428, 1086288406, 1086173346, 1086023202, 1085824560, 1085556916, 1085187290, 1084659048, 1084162704,
            1083987494, 1083757034, 1083448918, 1083027864, 1082434940, 1081924456, 1081557944, 1081093802, 1080503078,
            1079746444, 1078769358, 1077803572, 1077472916, 1077060302, 1076544812, 1075899840, 1075091370, 1074075604,
            1073170047, 1072472183, 1071604401, 1070524987, 1069181802, 1067509566,
        ],
    ),
];

/// [`Calibration::compute`], memoized per (kernel, size), from [`PRECOMPUTED`] where it holds one.
pub fn calibration(kernel: Kernel, size: usize) -> Arc<Calibration> {
    if let Some(c) = CALIBRATIONS.lock().unwrap().get(&(kernel, size)) {
        return c.clone();
    }
    let c = match PRECOMPUTED.iter().find(|(k, n, _)| (*k, *n) == (kernel, size)) {
        Some((_, _, bits)) => Arc::new(Calibration { kernel, size, levels: bits.map(f32::from_bits).to_vec() }),
        None => Arc::new(Calibration::compute(kernel, size)),
    };
    CALIBRATIONS.lock().unwrap().entry((kernel, size)).or_insert(c).clone()
}

/// The lobe error of Figs. 5.19/5.20 for one kernel, face size and exponent.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct LobeError {
    /// The level the calibration table gives for s (what the shader uses).
    pub level: f32,
    /// volume(level) / (2 pi/(s+1)) - 1: nonzero where the table's interpolation or the
    /// clamp to [0, top] misses the exact match.
    pub volume_error: f32,
    /// integral |response/peak - max(0, cos)^s| dOmega / (2 pi/(s+1)): the relative L1
    /// difference of the two lobes at (nearly) equal volume, centred on the impulse direction.
    pub shape_error: f32,
}

/// Measures [`LobeError`] (the impulse response against the Phong lobe about the impulse
/// texel's direction).
pub fn lobe_error(kernel: Kernel, size: usize, s: f32) -> LobeError {
    let model = lobe_model(kernel, size);
    let level = calibration(kernel, size).level_for_exponent(s);
    LobeError {
        level,
        volume_error: (model.volume(level) / phong_volume(s) - 1.0) as f32,
        shape_error: model.shape_error(level, s) as f32,
    }
}

/// The exponents of `werkstatt bench pem-lobes`.
pub const BENCH_EXPONENTS: [f32; 11] = [1.0, 2.0, 3.0, 5.0, 10.0, 20.0, 50.0, 100.0, 200.0, 500.0, 1000.0];

/// GPU memory of `n` PEMs at face size `res` (RGBA16F, 8 B per texel, six faces, the full
/// mip chain down to 1x1): n x 6 x 8 B x sum_k (res >> k)^2 = n x 6 x res^2 x 8 B x 4/3
/// (exactly (4 res^2 - 1)/3 texels per face for a power of two). Table 5.1 of the
/// dissertation uses x2 instead of x4/3, so its cells are 3/2 of these.
pub fn pem_memory_bytes(n: u64, res: u64) -> u64 {
    let mut texels = 0u64;
    let mut r = res;
    while r > 0 {
        texels += r * r;
        if r == 1 {
            break;
        }
        r /= 2;
    }
    n * 6 * 8 * texels
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Each precomputed table is what Calibration::compute gives (to the bit where it was made;
    /// libm's powf may differ by an ulp elsewhere). On failure it prints the tables to paste
    /// into PRECOMPUTED.
    #[test]
    fn the_precomputed_calibrations_are_computed_ones() {
        let computed: Vec<(Kernel, usize, Vec<u32>)> = [(Kernel::Phong, 128), (Kernel::SqrtCosine, 128)]
            .iter()
            .map(|&(k, n)| (k, n, Calibration::compute(k, n).levels.iter().map(|l| l.to_bits()).collect()))
            .collect();
        let literal: String = computed.iter().map(|(k, n, b)| format!("    (Kernel::{k:?}, {n}, {b:?}),\n")).collect();
        assert_eq!(PRECOMPUTED.len(), computed.len(), "PRECOMPUTED should be:\n{literal}");
        for ((k, n, bits), (ck, cn, cbits)) in PRECOMPUTED.iter().zip(&computed) {
            assert_eq!((k, n), (ck, cn), "PRECOMPUTED should be:\n{literal}");
            for (a, b) in bits.iter().zip(cbits) {
                let (a, b) = (f32::from_bits(*a), f32::from_bits(*b));
                assert!(
                    (a - b).abs() <= 1e-5 * b.abs(),
                    "{k:?} {n}: {a} against {b}; PRECOMPUTED should be:\n{literal}"
                );
            }
        }
    }

    fn integral(c: &CubeImage) -> f64 {
        let s = c.size;
        c.texels.iter().enumerate().map(|(i, t)| t.x as f64 * texel_solid_angle(s, i % s, (i / s) % s) as f64).sum()
    }

    #[test]
    fn the_peak_of_a_level_blend_is_the_brute_force_maximum() {
        for kernel in [Kernel::Phong, Kernel::SqrtCosine, Kernel::Box] {
            let m = lobe_model(kernel, 16);
            for i in 0..=40 {
                let level = i as f32 * m.top() as f32 / 40.0;
                let mut brute = 0.0f32;
                m.for_each_response(level, |_, r| brute = brute.max(r));
                assert_eq!(m.peak(level), brute, "{kernel:?} at level {level}");
            }
        }
        // A blend can peak where neither level does.
        assert_eq!(peak_candidates(&[1.0, 0.6, 0.0], &[0.0, 0.6, 1.0]), vec![0, 1, 2]);
        assert_eq!(peak_candidates(&[1.0, 0.4, 0.0], &[0.0, 0.4, 1.0]), vec![0, 2]);
    }

    #[test]
    fn the_filter_keeps_a_constant_map_constant() {
        for kernel in Kernel::ALL {
            let chain = filter_chain(&CubeImage::from_fn(16, |_, _, _| Vec4::splat(0.75)), kernel);
            assert_eq!(chain.len(), 5);
            for (l, level) in chain.iter().enumerate() {
                assert_eq!(level.size, 16 >> l);
                for t in &level.texels {
                    assert!((*t - Vec4::splat(0.75)).abs().max_element() < 1e-5, "{kernel:?} level {l}: {t}");
                }
            }
        }
    }

    #[test]
    fn the_filter_roughly_conserves_the_integral() {
        // A smooth but uneven map: every level's solid-angle-weighted integral within 1% of
        // level 0's down to 8x8 faces, within 6% at 4x4 and below (the filter weighs texels,
        // not solid angles, and a 1x1 face is one value for a sixth of the sphere; measured:
        // at most 0.4% at 8x8, 2.1% at 2x2, 4.6% at 1x1, for the gaussian).
        let map = CubeImage::from_fn(32, |f, x, y| {
            let d = texel_dir(32, f, x, y);
            Vec4::splat(1.0 + d.x + 2.0 * d.y.max(0.0).powi(4))
        });
        let i0 = integral(&map);
        for kernel in Kernel::ALL {
            for (l, level) in filter_chain(&map, kernel).iter().enumerate() {
                let il = integral(level);
                let tolerance = if level.size >= 8 { 0.01 } else { 0.06 };
                assert!((il / i0 - 1.0).abs() < tolerance, "{kernel:?} level {l}: {il} vs {i0}");
            }
        }
    }

    #[test]
    fn no_kernel_is_a_2x2_box_mip() {
        let map = CubeImage::from_fn(16, |f, x, y| Vec4::new((f * 7 + x * 3 + y * y) as f32, x as f32, y as f32, 1.0));
        let l1 = filter_level(&map, Kernel::None);
        for f in 0..6 {
            for y in 1..7 {
                for x in 1..7 {
                    let want = (map.texel(f, 2 * x, 2 * y)
                        + map.texel(f, 2 * x + 1, 2 * y)
                        + map.texel(f, 2 * x, 2 * y + 1)
                        + map.texel(f, 2 * x + 1, 2 * y + 1))
                        / 4.0;
                    assert!((l1.texel(f, x, y) - want).abs().max_element() < 1e-4, "face {f} ({x}, {y})");
                }
            }
        }
    }

    #[test]
    fn weights_are_positive_where_defined() {
        for kernel in Kernel::ALL {
            let w = weights(kernel);
            assert!(w.iter().flatten().all(|&x| x >= 0.0), "{kernel:?}");
            assert_eq!(w[2][2], 1.0, "{kernel:?}: the centre weight is 1");
            // Symmetric under a <-> b and a <-> -a.
            #[allow(clippy::needless_range_loop)]
            for b in 0..5 {
                for a in 0..5 {
                    assert_eq!(w[b][a], w[a][b]);
                    assert_eq!(w[b][a], w[b][4 - a]);
                }
            }
        }
        assert!(weights(Kernel::Cosine)[0][0] > 0.0);
        assert!((weights(Kernel::SqrtCosine)[0][0] - weights(Kernel::Cosine)[0][0].sqrt()).abs() < 1e-7);
    }

    #[test]
    fn the_calibration_is_monotone() {
        for kernel in [Kernel::SqrtCosine, Kernel::Box] {
            let c = calibration(kernel, 32);
            assert_eq!(c.levels.len(), TABLE);
            for w in c.levels.windows(2) {
                assert!(w[1] <= w[0] + 1e-6, "{kernel:?}: {:?}", c.levels);
            }
            assert!(c.levels[0] > c.levels[TABLE - 1] + 1.0, "{kernel:?}: {:?}", c.levels);
            assert!(c.levels.iter().all(|&l| (0.0..=5.0).contains(&l)));
            assert_eq!(c.level_for_glossiness(0.0), c.levels[0]);
            assert_eq!(c.level_for_exponent(1.0), c.levels[0]);
            assert!((c.level_for_exponent(table_exponent(7)) - c.levels[7]).abs() < 1e-5);
            assert_eq!(c.level_for_glossiness(1.0), 0.0);
            let mut prev = f32::MAX;
            for g in [0.0, 0.25, 0.5, 0.75, 0.9, 0.99, 0.999, 0.9999] {
                let l = c.level_for_glossiness(g);
                assert!(l <= prev && l >= 0.0, "{kernel:?} g {g}: {l}");
                prev = l;
            }
        }
    }

    #[test]
    fn the_calibrated_level_matches_the_volume() {
        let model = lobe_model(Kernel::SqrtCosine, 32);
        for s in [1.0, 4.0, 30.0] {
            let l = model.level_for_volume(phong_volume(s));
            assert!((model.volume(l) / phong_volume(s) - 1.0).abs() < 1e-4, "s {s}: level {l}");
        }
    }

    #[test]
    fn inverse_volume_between_levels_is_measured_not_assumed() {
        // With a peak at the same texel on both levels, 1/volume = peak/integral would be
        // linear in the fraction; the calibration does not rely on it. Report how far off.
        let model = lobe_model(Kernel::SqrtCosine, 32);
        let mut worst = 0.0f64;
        for l in 0..model.top() {
            let (a, b) = (1.0 / model.volume(l as f32), 1.0 / model.volume(l as f32 + 1.0));
            let mid = 1.0 / model.volume(l as f32 + 0.5);
            worst = worst.max((mid / (0.5 * (a + b)) - 1.0).abs());
        }
        eprintln!("1/volume at mid-level vs linear: worst relative deviation {worst:.4}");
        assert!(worst < 0.3, "{worst}");
    }

    #[test]
    fn the_lobe_error_detects_a_bad_filter() {
        // A plain mip chain's lobe is a blocky, off-centre box: far from the Phong lobe.
        let bad = lobe_error(Kernel::None, 32, 100.0);
        let good = lobe_error(Kernel::SqrtCosine, 32, 100.0);
        assert!(bad.shape_error > 0.5, "{bad:?}");
        assert!(good.shape_error < bad.shape_error, "{good:?} vs {bad:?}");
        assert!(bad.volume_error.abs() < 0.02 && good.volume_error.abs() < 0.02);
    }

    #[test]
    fn memory_matches_table_5_1_up_to_its_mip_factor() {
        const MIB: f64 = 1024.0 * 1024.0;
        // Table 5.1: 12 PEMs at 128^2 = 18 MB, 1 PEM at 256^2 = 6 MB, both with x2 for mips.
        for (n, res, table_mb) in [(12, 128, 18.0), (1, 256, 6.0), (256, 256, 1536.0)] {
            let ours = pem_memory_bytes(n, res) as f64 / MIB;
            assert!((ours * 1.5 / table_mb - 1.0).abs() < 1e-4, "{n} x {res}: {ours} MiB");
        }
        assert_eq!(pem_memory_bytes(1, 1), 48);
        assert_eq!(pem_memory_bytes(2, 4), 2 * 6 * 8 * 21);
    }

    /// Irradiance / pi at normal n: the cosine-weighted integral over every texel of `cube`.
    fn irradiance(cube: &CubeImage, n: glam::Vec3) -> f32 {
        let mut e = 0.0f64;
        for f in 0..6 {
            for y in 0..cube.size {
                for x in 0..cube.size {
                    let c = texel_dir(cube.size, f, x, y).normalize().dot(n);
                    if c > 0.0 {
                        e += (cube.texel(f, x, y).y * c * texel_solid_angle(cube.size, x, y)) as f64;
                    }
                }
            }
        }
        (e / PI) as f32
    }

    #[test]
    fn the_diffuse_end_gives_lambertian_surfaces_their_irradiance() {
        use crate::ibl::cube::{EquirectImage, cube_from_equirect};
        let probe = EquirectImage::load(std::path::Path::new("assets/hdri/forest.hdr")).unwrap();
        let cube = cube_from_equirect(&probe, 64, 30.0, 1.0);
        let plain = filter_chain(&cube, Kernel::None);
        let diffuse = diffuse_end(&plain);
        assert_eq!(diffuse.size, DIFFUSE_SIZE);
        let phong = filter_chain(&cube, Kernel::Phong);
        let l = calibration(Kernel::Phong, 64).level_for_exponent(1.0).round() as usize;
        let mut worst = (0.0f32, 0.0f32);
        for n in
            [glam::Vec3::Y, glam::Vec3::X, glam::vec3(0.3, 0.8, -0.5), glam::vec3(-0.7, -0.2, 0.4), glam::Vec3::NEG_Y]
        {
            let n = n.normalize();
            let want = irradiance(&cube, n);
            let ours = (diffuse.sample(n).y / want - 1.0).abs();
            let chain = (phong[l].sample(n).y / want - 1.0).abs();
            eprintln!("n {n}: irradiance/pi {want:.4}, diffuse end {ours:.4}, chain level {l} {chain:.4}");
            worst = (worst.0.max(ours), worst.1.max(chain));
        }
        assert!(worst.0 < 0.01, "the diffuse end is {:.2}% off", 100.0 * worst.0);
        // What it replaces: the chain's own s = 1 level (4^2 faces here) misses by several %.
        assert!(worst.1 > 0.03, "the chain's s = 1 level is only {:.2}% off", 100.0 * worst.1);
    }

    #[test]
    fn the_handover_meets_the_chain_at_its_calibrated_level() {
        for (kernel, size) in [(Kernel::Phong, 128), (Kernel::Phong, 64), (Kernel::SqrtCosine, 128), (Kernel::Box, 64)]
        {
            let c = calibration(kernel, size);
            let h = c.handover().expect("maps of 16^2 and more hand over");
            eprintln!("{kernel:?} {size}: {h:?}, s = 1 at level {}", c.levels[0]);
            if kernel == Kernel::Phong {
                assert_eq!(size >> h.level as usize, HANDOVER_SIZE);
            } else {
                assert_eq!(h.level, c.levels[0].floor());
            }
            assert!((c.level_for_exponent(h.exponent) - h.level).abs() < 1e-3, "{kernel:?} {size}: {h:?}");
            assert_eq!(h.diffuse_weight(1.0), 1.0);
            assert_eq!(h.diffuse_weight(h.exponent), 0.0);
            let mut last = 1.0;
            for i in 1..20 {
                let w = h.diffuse_weight(1.0 + (h.exponent - 1.0) * i as f32 / 20.0);
                assert!(w < last && w > 0.0, "{kernel:?}: weight {w} after {last}");
                last = w;
            }
        }
        // Phong stores exponent 3 * 8^2 / 54 - 1 = 2.56 at face size 8; the bilinear lookups widen
        // its lobe a little, so the volume-matched exponent is near it (2.79).
        let h = calibration(Kernel::Phong, 128).handover().unwrap();
        assert!((h.exponent / phong_exponent(128, 4) - 1.0).abs() < 0.1, "{h:?}");
        assert_eq!(calibration(Kernel::Phong, 8).handover(), None);
    }
}

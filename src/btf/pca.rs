//! Per-view PCA of a BTF (Sattler et al., eq. 1) and the symmetric eigen-solver it needs.
//!
//! For one view slot j the n light images are the rows of X (n x d, d = 3 w h). The Gram matrix
//! G = Y Y^T (n x n, in f64) is decomposed as G v_k = lambda_k v_k; the eigentextures are
//! B_k = Y^T v_k / sqrt(lambda_k) (orthonormal) and the coefficients p_ik = Y_i . B_k =
//! sqrt(lambda_k) v_k[i]. Keeping c components leaves the squared Frobenius error
//! sum_{k >= c} lambda_k.
//!
//! **Mean.** The paper's text minimises the error "onto the affine subspace", and its eqs. (4)
//! and (11) start at k = 0, while eq. (1) has no mean. With [`Centring::Mean`] (the default)
//! Y = X - mean and the mean image is the k = 0 term (B_0 = mean, gamma_0 = sum of the light
//! weights); with [`Centring::None`], Y = X as eq. (1) is written. The mean costs one more image
//! per slot and captures the largest component at once, so c components reconstruct better.

/// Whether the light images are centred on their mean before the decomposition.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default)]
pub enum Centring {
    #[default]
    Mean,
    None,
}

/// The eigen-decomposition of a symmetric n x n matrix (row-major) by cyclic Jacobi rotations:
/// eigenvalues in descending order and the eigenvectors as rows (`vectors[k * n..][..n]`).
/// Exact to rounding for the small matrices here (n <= 81, a few ms).
pub fn symmetric_eigen(matrix: &[f64], n: usize) -> (Vec<f64>, Vec<f64>) {
    assert_eq!(matrix.len(), n * n, "symmetric_eigen: {n}x{n} matrix expected");
    let mut a = matrix.to_vec();
    // v holds the eigenvectors as columns while rotating.
    let mut v = vec![0.0; n * n];
    for i in 0..n {
        v[i * n + i] = 1.0;
    }
    let total: f64 = a.iter().map(|x| x * x).sum();
    for _sweep in 0..100 {
        let off: f64 = (0..n)
            .flat_map(|p| (0..n).filter(move |&q| q != p).map(move |q| (p, q)))
            .map(|(p, q)| a[p * n + q].powi(2))
            .sum();
        if off <= total * 1e-30 || off == 0.0 {
            break;
        }
        for p in 0..n {
            for q in p + 1..n {
                let apq = a[p * n + q];
                if apq == 0.0 {
                    continue;
                }
                // The rotation that zeroes a_pq: t = tan(angle), the smaller root of
                // t^2 + 2 theta t - 1 = 0.
                let theta = (a[q * n + q] - a[p * n + p]) / (2.0 * apq);
                let t = theta.signum() / (theta.abs() + (theta * theta + 1.0).sqrt());
                let c = 1.0 / (t * t + 1.0).sqrt();
                let s = t * c;
                for k in 0..n {
                    let (akp, akq) = (a[k * n + p], a[k * n + q]);
                    a[k * n + p] = c * akp - s * akq;
                    a[k * n + q] = s * akp + c * akq;
                }
                for k in 0..n {
                    let (apk, aqk) = (a[p * n + k], a[q * n + k]);
                    a[p * n + k] = c * apk - s * aqk;
                    a[q * n + k] = s * apk + c * aqk;
                }
                for k in 0..n {
                    let (vkp, vkq) = (v[k * n + p], v[k * n + q]);
                    v[k * n + p] = c * vkp - s * vkq;
                    v[k * n + q] = s * vkp + c * vkq;
                }
            }
        }
    }
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by(|&i, &j| a[j * n + j].total_cmp(&a[i * n + i]));
    let values = order.iter().map(|&i| a[i * n + i]).collect();
    let vectors = order.iter().flat_map(|&i| (0..n).map(move |k| (k, i))).map(|(k, i)| v[k * n + i]).collect();
    (values, vectors)
}

/// One view slot, compressed.
#[derive(Clone, Debug, PartialEq)]
pub struct SlotPca {
    /// Texel values per image (3 w h).
    pub dim: usize,
    /// The mean image (empty with [`Centring::None`]).
    pub mean: Vec<f32>,
    /// The kept eigentextures B_k, `dim` values each, concatenated.
    pub basis: Vec<f32>,
    /// p_ik, row-major: light i, component k.
    pub coeffs: Vec<f32>,
    /// Every eigenvalue of the Gram matrix, descending (negative rounding clamped to 0): the
    /// squared error of keeping c components is the sum from c on.
    pub eigenvalues: Vec<f64>,
}

impl SlotPca {
    /// The number of kept components (at most the asked c, and only those with a nonzero
    /// eigenvalue: a rank-r slot keeps at most r).
    pub fn components(&self) -> usize {
        self.basis.len().checked_div(self.dim).unwrap_or(0)
    }

    /// B_k.
    pub fn eigentexture(&self, k: usize) -> &[f32] {
        &self.basis[k * self.dim..][..self.dim]
    }

    /// The weighted sum of light images `sum_i w_i N_i` from the compressed slot (eqs. 3, 10:
    /// the coefficients are blended first, then one pass over the eigentextures).
    pub fn blend(&self, weights: &[(usize, f64)]) -> Vec<f32> {
        let c = self.components();
        let mut gamma = vec![0.0f64; c];
        let mut total = 0.0;
        for &(i, w) in weights {
            total += w;
            for (g, p) in gamma.iter_mut().zip(&self.coeffs[i * c..][..c]) {
                *g += w * *p as f64;
            }
        }
        let mut out: Vec<f64> = if self.mean.is_empty() {
            vec![0.0; self.dim]
        } else {
            self.mean.iter().map(|&m| total * m as f64).collect()
        };
        for (k, g) in gamma.iter().enumerate() {
            for (o, b) in out.iter_mut().zip(self.eigentexture(k)) {
                *o += g * *b as f64;
            }
        }
        out.into_iter().map(|x| x as f32).collect()
    }

    /// Light image i, reconstructed.
    pub fn reconstruct(&self, i: usize) -> Vec<f32> {
        self.blend(&[(i, 1.0)])
    }

    /// The stored size in values (mean, basis, coefficients).
    pub fn stored_values(&self) -> usize {
        self.mean.len() + self.basis.len() + self.coeffs.len()
    }
}

/// Compresses one view slot: `images` holds n light images of `dim` values each, concatenated;
/// keep at most `c` components.
pub fn compress_slot(images: &[f32], dim: usize, c: usize, centring: Centring) -> SlotPca {
    assert!(
        dim > 0 && images.len().is_multiple_of(dim),
        "compress_slot: {} values are not whole images of {dim}",
        images.len()
    );
    let n = images.len() / dim;
    let row = |i: usize| &images[i * dim..][..dim];
    let mean: Vec<f64> = match centring {
        Centring::None => Vec::new(),
        Centring::Mean => {
            let mut m = vec![0.0f64; dim];
            for i in 0..n {
                for (a, &x) in m.iter_mut().zip(row(i)) {
                    *a += x as f64;
                }
            }
            m.iter_mut().for_each(|a| *a /= n as f64);
            m
        }
    };
    let y: Vec<f64> = (0..n)
        .flat_map(|i| {
            row(i).iter().enumerate().map(|(t, &x)| x as f64 - mean.get(t).copied().unwrap_or(0.0)).collect::<Vec<_>>()
        })
        .collect();
    let yrow = |i: usize| &y[i * dim..][..dim];
    let mut gram = vec![0.0f64; n * n];
    for a in 0..n {
        for b in a..n {
            let g: f64 = yrow(a).iter().zip(yrow(b)).map(|(p, q)| p * q).sum();
            gram[a * n + b] = g;
            gram[b * n + a] = g;
        }
    }
    let (mut values, vectors) = symmetric_eigen(&gram, n);
    values.iter_mut().for_each(|l| *l = l.max(0.0));
    // Components with eigenvalues at rounding level have no direction to normalise.
    let floor = values.first().copied().unwrap_or(0.0) * 1e-12;
    let keep = values.iter().take(c).take_while(|&&l| l > floor && l > 0.0).count();
    let mut basis = Vec::with_capacity(keep * dim);
    let mut coeffs = vec![0.0f32; n * keep];
    for (k, lambda) in values.iter().take(keep).enumerate() {
        let vk = &vectors[k * n..][..n];
        let norm = lambda.sqrt();
        let mut b = vec![0.0f64; dim];
        for (i, &w) in vk.iter().enumerate() {
            for (o, &x) in b.iter_mut().zip(yrow(i)) {
                *o += w * x;
            }
            coeffs[i * keep + k] = (w * norm) as f32;
        }
        basis.extend(b.iter().map(|x| (x / norm) as f32));
    }
    SlotPca { dim, mean: mean.into_iter().map(|x| x as f32).collect(), basis, coeffs, eigenvalues: values }
}

/// The paper's Fig. 7: eigenvalue curves (descending, one per view slot) on a log scale, as SVG.
/// Eigenvalues at or below 1e-12 of the largest are left off (the log scale has no zero).
pub fn eigenvalue_svg(curves: &[(String, Vec<f64>)], title: &str) -> String {
    let chart =
        crate::io::svg::Chart { width: 720.0, height: 420.0, left: 70.0, right: 150.0, top: 40.0, bottom: 50.0 };
    let (w, h, left, right, top, bottom) =
        (chart.width, chart.height, chart.left, chart.right, chart.top, chart.bottom);
    let largest = curves.iter().flat_map(|c| c.1.iter().copied()).fold(0.0f64, f64::max).max(1e-30);
    let floor = largest * 1e-12;
    let smallest = curves.iter().flat_map(|c| c.1.iter().copied()).filter(|&l| l > floor).fold(largest, f64::min);
    let (hi, lo) = (largest.log10().ceil(), smallest.log10().floor().min(largest.log10().ceil() - 1.0));
    let count = curves.iter().map(|c| c.1.len()).max().unwrap_or(1).max(2);
    let x = |k: usize| left + k as f64 / (count - 1) as f64 * (w - left - right);
    let y = |l: f64| top + (hi - l.log10()) / (hi - lo) * (h - top - bottom);
    let mut svg = chart.open(title);
    let mut e = lo;
    while e <= hi + 1e-9 {
        let yy = y(10f64.powf(e));
        svg += &format!(
            "<line x1=\"{left}\" y1=\"{yy:.1}\" x2=\"{:.1}\" y2=\"{yy:.1}\" stroke=\"#ddd\"/><text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"end\">1e{e}</text>\n",
            w - right,
            left - 6.0,
            yy + 4.0
        );
        e += 1.0;
    }
    for k in (0..count).step_by(10) {
        svg += &format!("<text x=\"{:.1}\" y=\"{:.1}\" text-anchor=\"middle\">{k}</text>\n", x(k), h - bottom + 16.0);
    }
    svg += &chart.axis_titles("component k", "eigenvalue (log)");
    for (i, (name, values)) in curves.iter().enumerate() {
        let colour = ["#1f4fd6", "#d62728", "#2ca02c", "#000000"][i % 4];
        let points = values.iter().enumerate().filter(|(_, l)| **l > floor).map(|(k, &l)| (x(k), y(l)));
        svg += &chart.series(i, name, colour, "", points);
    }
    svg + "</svg>\n"
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::directions::Sampling;

    #[test]
    fn the_eigenvalue_plot_has_a_curve_per_slot_without_zero_eigenvalues() {
        let curves = vec![("a".to_string(), vec![10.0, 1.0, 0.1, 0.0]), ("b".to_string(), vec![5.0, 0.5, 0.05, 0.005])];
        let svg = eigenvalue_svg(&curves, "t");
        let lines: Vec<&str> = svg.lines().filter(|l| l.starts_with("<polyline")).collect();
        assert_eq!(lines.len(), 2);
        // The zero eigenvalue has no place on the log scale: 3 points, then 4.
        let points = |l: &str| l.split("points=\"").nth(1).unwrap().split('"').next().unwrap().split(' ').count();
        assert_eq!((points(lines[0]), points(lines[1])), (3, 4));
        // Decades from 1e-3 (below 0.005) to 1e1 (above 10).
        assert!(svg.contains(">1e-3<") && svg.contains(">1e1<") && !svg.contains(">1e2<"));
        assert!(svg.ends_with("</svg>\n"));
    }

    /// A deterministic pseudo-random slot: n images of dim values in [0, 1).
    fn noise(n: usize, dim: usize, seed: u64) -> Vec<f32> {
        let mut s = seed;
        (0..n * dim)
            .map(|_| {
                s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
                (s >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect()
    }

    fn sq_error(images: &[f32], pca: &SlotPca) -> f64 {
        let n = images.len() / pca.dim;
        (0..n)
            .map(|i| {
                pca.reconstruct(i)
                    .iter()
                    .zip(&images[i * pca.dim..][..pca.dim])
                    .map(|(a, &b)| (*a as f64 - b as f64).powi(2))
                    .sum::<f64>()
            })
            .sum()
    }

    /// A BTF whose images are not rank 1: the Lambertian one plus a texel pattern that moves
    /// with the light.
    fn textured() -> crate::btf::Btf {
        let mut btf = crate::btf::Btf::lambertian(Sampling::h2_tests(), 8, 8, |x, y| {
            [0.3 + 0.05 * x as f32, 0.4, 0.2 + 0.05 * y as f32]
        });
        let dim = btf.image_len();
        for (k, x) in btf.data.iter_mut().enumerate() {
            let (image, t) = (k / dim, k % dim);
            *x += 0.05 * ((image * 7 + t * 13) % 17) as f32 / 17.0;
        }
        btf
    }

    #[test]
    fn compressing_a_btf_reports_the_dropped_energy() {
        let btf = textured();
        let full = compress(&btf, 19, Centring::Mean);
        let r = full.report(&btf);
        assert!(r.relative_error < 1e-5 && r.error8_max < 0.5, "full rank: {r:?}");
        let few = compress(&btf, 3, Centring::Mean);
        let r3 = few.report(&btf);
        let dropped: f64 = few.slots.iter().map(|s| s.eigenvalues[3..].iter().sum::<f64>()).sum();
        let energy: f64 = btf.data.iter().map(|&x| (x as f64).powi(2)).sum();
        assert!((r3.relative_error - (dropped / energy).sqrt()).abs() < 1e-4, "{r3:?} against dropped {dropped}");
        assert!(r3.error8_mean > 0.0 && r3.error8_p99 <= r3.error8_max);
        assert_eq!(r3.raw_bytes, btf.data.len() * 2);
        // 19 slots x (mean + 3 eigentextures + 19 x 3 coefficients).
        assert_eq!(r3.compressed_bytes, 19 * (4 * btf.image_len() + 19 * 3) * 2);
        assert_eq!(few, compress(&btf, 3, Centring::Mean), "compression is deterministic");
    }

    #[test]
    fn jacobi_diagonalises_a_symmetric_matrix() {
        let n = 12;
        let r = noise(n, n, 7);
        let m: Vec<f64> = (0..n * n).map(|i| (r[i] + r[(i % n) * n + i / n]) as f64).collect();
        let (values, vectors) = symmetric_eigen(&m, n);
        for k in 0..n {
            let v = &vectors[k * n..][..n];
            for (row, vr) in v.iter().enumerate() {
                let mv: f64 = v.iter().enumerate().map(|(c, vc)| m[row * n + c] * vc).sum();
                assert!((mv - values[k] * vr).abs() < 1e-10, "M v != lambda v for k = {k}");
            }
            let dot: f64 = v.iter().map(|x| x * x).sum();
            assert!((dot - 1.0).abs() < 1e-12);
        }
        assert!(values.windows(2).all(|w| w[0] >= w[1]), "eigenvalues not descending: {values:?}");
    }

    #[test]
    fn pca_is_exact_at_full_rank_and_its_error_is_the_dropped_eigenvalues() {
        let (n, dim) = (19, 3 * 8 * 8);
        let x = noise(n, dim, 1);
        for centring in [Centring::Mean, Centring::None] {
            let energy: f64 = x.iter().map(|&v| (v as f64).powi(2)).sum();
            let full = compress_slot(&x, dim, n, centring);
            let rel = (sq_error(&x, &full) / energy).sqrt();
            assert!(rel < 1e-5, "{centring:?}: full rank relative error {rel}");
            let mut last = f64::INFINITY;
            for c in [1, 2, 5, 10, 16] {
                let pca = compress_slot(&x, dim, c, centring);
                assert_eq!(pca.components(), c);
                let err = sq_error(&x, &pca);
                let dropped: f64 = pca.eigenvalues[c..].iter().sum();
                assert!(
                    (err - dropped).abs() < 1e-4 * energy,
                    "{centring:?} c = {c}: error {err}, dropped eigenvalues {dropped}"
                );
                assert!(err <= last, "error not monotone in c");
                last = err;
                for k in 0..c {
                    for l in 0..c {
                        let dot: f64 = pca
                            .eigentexture(k)
                            .iter()
                            .zip(pca.eigentexture(l))
                            .map(|(a, b)| (*a as f64) * (*b as f64))
                            .sum();
                        let want = if k == l { 1.0 } else { 0.0 };
                        assert!((dot - want).abs() < 1e-5, "B_{k} . B_{l} = {dot}");
                    }
                }
            }
        }
    }

    /// `lambertian` in closed form against `compress` of the BTF it stands for.
    #[test]
    fn the_closed_form_lambertian_pca_equals_the_decomposition() {
        let sampling = Sampling::h2_tests();
        let rho = |x: usize, y: usize| [0.2 + 0.1 * x as f32, 0.5 - 0.05 * y as f32, 0.3];
        let btf = crate::btf::Btf::lambertian(sampling.clone(), 5, 4, rho);
        let image: Vec<f32> = btf.data[..btf.image_len()].to_vec();
        let closed = lambertian(&sampling, &image);
        let decomposed = compress(&btf, 4, Centring::Mean);
        for (a, b) in closed.slots.iter().zip(&decomposed.slots) {
            assert_eq!((a.components(), b.components()), (1, 1));
            assert!((a.eigenvalues[0] - b.eigenvalues[0]).abs() < 1e-6 * b.eigenvalues[0]);
            for i in 0..sampling.len() {
                let worst =
                    a.reconstruct(i).iter().zip(b.reconstruct(i)).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max);
                assert!(worst < 1e-6, "light {i}: off by {worst}");
            }
        }
    }

    /// N = rho / pi cos(theta_i): every slot is rank 1, and blending it with the light weights
    /// gives rho / pi cos(theta) up to the linear interpolation between 15 deg rings.
    #[test]
    fn a_lambertian_btf_has_rank_one_and_matches_the_cosine() {
        let sampling = Sampling::h2();
        let lights = sampling.directions();
        let dim = 3 * 4 * 4;
        let rho: Vec<f32> = noise(1, dim, 3).iter().map(|r| 0.1 + 0.8 * r).collect();
        let lambert =
            |cos: f64| -> Vec<f32> { rho.iter().map(|&r| (r as f64 / std::f64::consts::PI * cos) as f32).collect() };
        let x: Vec<f32> = lights.iter().flat_map(|l| lambert(l.theta.to_radians().cos())).collect();
        for centring in [Centring::Mean, Centring::None] {
            let pca = compress_slot(&x, dim, 16, centring);
            let ratio = pca.eigenvalues[1] / pca.eigenvalues[0];
            assert!(ratio < 1e-10, "{centring:?}: lambda_2 / lambda_1 = {ratio}");
            assert_eq!(pca.components(), 1, "{centring:?}: a rank-1 slot keeps one component");
            for (theta, phi) in [(0.0, 0.0), (30.0, 30.0), (37.0, 111.0), (52.5, 200.0), (70.0, 359.0)] {
                let d = crate::btf::directions::Dir { theta, phi };
                let got = pca.blend(&sampling.weights(d));
                let want = lambert(f64::to_radians(theta).cos());
                // cos is concave: linear interpolation over 15 deg is off by at most
                // (15 deg)^2 / 8 = 0.0086 of its scale.
                let err = got.iter().zip(&want).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
                assert!(err < 0.0086 / std::f32::consts::PI, "{centring:?} at ({theta}, {phi}): error {err}");
            }
        }
    }
}

/// A whole BTF compressed per view slot.
#[derive(Clone, Debug, PartialEq)]
pub struct Compressed {
    pub components: usize,
    pub centring: Centring,
    /// One per view, in the sampling's order.
    pub slots: Vec<SlotPca>,
}

/// Compresses every view slot of `btf` with at most `c` components, slots spread over the
/// available threads (each slot alone is deterministic, so the result does not depend on them).
pub fn compress(btf: &super::Btf, c: usize, centring: Centring) -> Compressed {
    let slots =
        crate::core::parallel::map(btf.sampling.len(), 0, |j| compress_slot(btf.slot(j), btf.image_len(), c, centring));
    Compressed { components: c, centring, slots }
}

/// The PCA centred on the mean of the Lambertian BTF [`super::Btf::lambertian`] whose albedo over
/// pi is the image `a` (`rho / pi`, 3 values per texel), in closed form: every view slot's light
/// images are `cos(theta_i) a`, rank one once centred, so each slot keeps the mean
/// `mean(cos) a`, one eigentexture `a / |a|` and `p_i = (cos(theta_i) - mean(cos)) |a|`, whose
/// eigenvalue `|a|^2 sum_i (cos(theta_i) - mean(cos))^2` is all of the energy. Equals
/// [`compress`] of the BTF (up to the eigentexture's sign) without making its n^2 images: the
/// frontal comparison of a 256² BTF would take 5 GB.
pub fn lambertian(sampling: &super::directions::Sampling, a: &[f32]) -> Compressed {
    let cosines: Vec<f64> =
        sampling.directions().iter().map(|d| f64::from(d.theta.to_radians().cos() as f32)).collect();
    let n = cosines.len();
    let mean_cos = cosines.iter().sum::<f64>() / n as f64;
    let norm = a.iter().map(|&x| f64::from(x).powi(2)).sum::<f64>().sqrt();
    let spread: f64 = cosines.iter().map(|c| (c - mean_cos).powi(2)).sum();
    let keep = norm > 0.0 && spread > 0.0;
    let mut eigenvalues = vec![0.0; n];
    eigenvalues[0] = norm * norm * spread;
    let slot = SlotPca {
        dim: a.len(),
        mean: a.iter().map(|&x| (f64::from(x) * mean_cos) as f32).collect(),
        basis: if keep { a.iter().map(|&x| (f64::from(x) / norm) as f32).collect() } else { Vec::new() },
        coeffs: if keep { cosines.iter().map(|c| ((c - mean_cos) * norm) as f32).collect() } else { Vec::new() },
        eigenvalues,
    };
    Compressed { components: 1, centring: Centring::Mean, slots: vec![slot; n] }
}

/// How well a [`Compressed`] BTF reproduces the original.
#[derive(Clone, Debug, PartialEq)]
pub struct Report {
    /// Sizes in bytes with every value stored as f16.
    pub raw_bytes: usize,
    pub compressed_bytes: usize,
    /// `||X - X_c||_F / ||X||_F` over all slots.
    pub relative_error: f64,
    /// The exposure of the 8-bit metric: the 99.5th percentile of the data maps to 255.
    pub exposure: f64,
    /// The length of the 8-bit RGB error vector per texel (the paper's Fig. 6 metric), over all
    /// images: mean, 99th percentile and maximum.
    pub error8_mean: f64,
    pub error8_p99: f64,
    pub error8_max: f64,
}

impl Compressed {
    /// Compares the reconstruction of every image with `btf`, the BTF it was made from.
    pub fn report(&self, btf: &super::Btf) -> Report {
        let exposure = super::exposure8(&btf.data);
        let (mut err2, mut energy) = (0.0f64, 0.0f64);
        // The lengths lie in [0, 255 sqrt(3)]: a histogram of 1/64 bins gives the percentile
        // without holding one f64 per texel (3.4 GB for the 256² tier).
        const BINS_PER_UNIT: f64 = 64.0;
        let last_bin = (442.0 * BINS_PER_UNIT) as usize;
        let mut histogram = vec![0u64; last_bin + 1];
        let (mut count, mut sum, mut max) = (0u64, 0.0f64, 0.0f64);
        let n = btf.sampling.len();
        for (j, slot) in self.slots.iter().enumerate() {
            let original = btf.slot(j);
            for i in 0..n {
                let recon = slot.reconstruct(i);
                let orig = &original[i * slot.dim..][..slot.dim];
                for (a, b) in recon.iter().zip(orig) {
                    err2 += (*a as f64 - *b as f64).powi(2);
                    energy += (*b as f64).powi(2);
                }
                for length in super::error8(&recon, orig, exposure) {
                    histogram[((length * BINS_PER_UNIT) as usize).min(last_bin)] += 1;
                    (count, sum, max) = (count + 1, sum + length, max.max(length));
                }
            }
        }
        // The upper edge of the bin holding the 99th percentile (within 1/64 of it, at most the maximum).
        let rank = (count as f64 * 0.99) as u64;
        let mut seen = 0;
        let bin = histogram.iter().position(|&h| {
            seen += h;
            seen > rank
        });
        let p99 = bin.map_or(0.0, |b| ((b + 1) as f64 / BINS_PER_UNIT).min(max));
        Report {
            raw_bytes: btf.data.len() * 2,
            compressed_bytes: self.slots.iter().map(|s| s.stored_values()).sum::<usize>() * 2,
            relative_error: if energy > 0.0 { (err2 / energy).sqrt() } else { 0.0 },
            exposure,
            error8_mean: sum / count.max(1) as f64,
            error8_p99: p99,
            error8_max: max,
        }
    }
}

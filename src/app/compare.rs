//! Comparing outputs with references: images (8-bit PNG and float EXR) by a per-pixel
//! threshold with a budget of failing pixels, PSNR and structural similarity (SSIM: PSNR
//! averages a small lost detail away, SSIM sees the missing structure), geometry and other text files number by
//! number, values with an absolute tolerance. `werkstatt test` and the golden-image tests of
//! the test suite both use these.

use serde::{Deserialize, Serialize};

/// How far an image may be from its reference.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ImageTolerance {
    /// A pixel fails when a channel differs by more than this: 8-bit levels (0-255) for PNG,
    /// absolute value for EXR.
    pub threshold: f64,
    /// The share of failing pixels allowed (0.005: half a percent).
    pub max_failing: f64,
    /// Lowest accepted PSNR in dB, over RGB and, separately, over alpha. The peak is 255 for
    /// PNG and the reference's largest colour value (at least 1) for EXR.
    pub min_psnr: f64,
    /// Lowest accepted mean SSIM (8x8 windows, the worst of R, G and B; 1 is identical).
    pub min_ssim: f64,
}

impl ImageTolerance {
    /// The SSIM bound of the defaults: rounding noise stays far above it, a lost edge or
    /// texture falls below. SSIM barely sees soft shading: the default graph without its
    /// shadows still scores 0.998, which the pixel budget catches (tests/suite/regression.rs).
    pub const MIN_SSIM: f64 = 0.98;
}

impl Default for ImageTolerance {
    /// The golden images' tolerance: 0.5% of the pixels off by more than 3 levels, 40 dB,
    /// SSIM 0.98.
    fn default() -> Self {
        ImageTolerance { threshold: 3.0, max_failing: 0.005, min_psnr: 40.0, min_ssim: Self::MIN_SSIM }
    }
}

/// The result of comparing two images of the same size.
#[derive(Debug)]
pub struct ImageDiff {
    pub psnr: f64,
    pub psnr_alpha: f64,
    /// Mean SSIM of the colour channels (the worst channel), 1 for identical images.
    pub ssim: f64,
    pub failing: usize,
    pub pixels: usize,
    /// Differences scaled so that the largest is white (see `diff_scale`), an alpha
    /// difference as a blue tint; opaque.
    pub diff: image::RgbaImage,
    /// The factor the diff image's 8-bit levels were multiplied by (1 to 255).
    pub diff_scale: f64,
}

impl ImageDiff {
    pub fn failing_share(&self) -> f64 {
        self.failing as f64 / self.pixels.max(1) as f64
    }

    /// Why the difference exceeds `tol`, or None when it is within it.
    pub fn verdict(&self, tol: &ImageTolerance) -> Option<String> {
        let share = self.failing_share();
        let failed = self.psnr < tol.min_psnr
            || self.psnr_alpha < tol.min_psnr
            || self.ssim < tol.min_ssim
            || share > tol.max_failing;
        failed.then(|| {
            format!(
                "PSNR {:.1} dB, alpha {:.1} dB (min {}), SSIM {:.4} (min {}), {:.2}% of pixels differ by more than {} (max {:.2}%)",
                self.psnr,
                self.psnr_alpha,
                tol.min_psnr,
                self.ssim,
                tol.min_ssim,
                share * 100.0,
                tol.threshold,
                tol.max_failing * 100.0
            )
        })
    }

    /// A one-line summary of the metrics.
    pub fn summary(&self) -> String {
        format!(
            "PSNR {:.1} dB, SSIM {:.4}, {} of {} pixels over the threshold",
            self.psnr, self.ssim, self.failing, self.pixels
        )
    }
}

/// Compares two RGBA images given as channel values on the same scale; `peak` is the PSNR's
/// peak and `threshold` the per-channel difference above which a pixel fails, both on that
/// scale (255 and levels for 8-bit images).
pub fn compare_channels(
    reference: &[f32],
    current: &[f32],
    (width, height): (u32, u32),
    peak: f64,
    threshold: f64,
) -> ImageDiff {
    assert_eq!(reference.len(), current.len(), "compare_channels needs images of one size");
    let (mut sq, mut sq_alpha, mut failing) = (0f64, 0f64, 0usize);
    // Per pixel: the colour differences and the alpha difference, for the diff image.
    let mut deltas = Vec::with_capacity(reference.len());
    for (a, e) in current.chunks_exact(4).zip(reference.chunks_exact(4)) {
        let mut worst = 0f64;
        let mut pixel = [0f64; 4];
        for c in 0..4 {
            // NaN compares as a maximal difference rather than slipping through.
            let delta = (a[c] as f64 - e[c] as f64).abs();
            let delta = if delta.is_nan() { f64::INFINITY } else { delta };
            if c < 3 {
                sq += delta.min(peak).powi(2);
            } else {
                sq_alpha += delta.min(peak).powi(2);
            }
            pixel[c] = delta.min(peak);
            worst = worst.max(delta);
        }
        deltas.push(pixel);
        if worst > threshold {
            failing += 1;
        }
    }
    // The diff image is scaled so that its largest difference is white: a small regression is
    // as visible as a large one (the factor is reported beside it).
    let to_levels = 255.0 / peak;
    let largest = deltas.iter().flatten().fold(0f64, |m, &d| m.max(d)) * to_levels;
    let diff_scale = if largest > 0.0 { (255.0 / largest).clamp(1.0, 255.0) } else { 1.0 };
    let byte = |d: f64| (d * to_levels * diff_scale).round().clamp(0.0, 255.0) as u8;
    let mut diff = image::RgbaImage::new(width, height);
    for (d, p) in diff.pixels_mut().zip(&deltas) {
        *d = image::Rgba([byte(p[0]), byte(p[1]), byte(p[2]).max(byte(p[3])), 255]);
    }
    let pixels = (width * height) as usize;
    let n = pixels.max(1) as f64;
    let psnr_of = |mse: f64| if mse == 0.0 { f64::INFINITY } else { 10.0 * (peak * peak / mse).log10() };
    ImageDiff {
        psnr: psnr_of(sq / (n * 3.0)),
        psnr_alpha: psnr_of(sq_alpha / n),
        ssim: ssim(reference, current, (width, height), peak),
        failing,
        pixels,
        diff,
        diff_scale,
    }
}

/// Mean SSIM of the colour channels of two RGBA images on a scale of `peak`, quantized to 8
/// bits (image-compare's MSSIM: 8x8 windows, the worst of R, G and B).
fn ssim(reference: &[f32], current: &[f32], (width, height): (u32, u32), peak: f64) -> f64 {
    let rgb8 = |px: &[f32]| {
        let bytes = px
            .chunks_exact(4)
            .flat_map(|p| p[..3].iter().map(|&v| (v as f64 / peak * 255.0).round().clamp(0.0, 255.0) as u8))
            .collect();
        image::RgbImage::from_raw(width, height, bytes).expect("sized by the caller")
    };
    if reference == current {
        return 1.0;
    }
    image_compare::rgb_similarity_structure(&image_compare::Algorithm::MSSIMSimple, &rgb8(reference), &rgb8(current))
        // Only a size mismatch fails, and the callers compare images of one size.
        .map_or(0.0, |s| s.score)
}

/// Compares two 8-bit images (levels 0-255).
pub fn compare_rgba8(reference: &image::RgbaImage, current: &image::RgbaImage, threshold: f64) -> ImageDiff {
    let f = |img: &image::RgbaImage| img.as_raw().iter().map(|&b| b as f32).collect::<Vec<f32>>();
    compare_channels(&f(reference), &f(current), current.dimensions(), 255.0, threshold)
}

/// Compares two float images: the peak is the reference's largest finite colour value, at
/// least 1.
pub fn compare_rgba32f(reference: &image::Rgba32FImage, current: &image::Rgba32FImage, threshold: f64) -> ImageDiff {
    let peak = reference
        .as_raw()
        .chunks_exact(4)
        .flat_map(|p| p[..3].iter().copied())
        .filter(|v| v.is_finite())
        .fold(1.0f32, f32::max) as f64;
    compare_channels(reference.as_raw(), current.as_raw(), current.dimensions(), peak, threshold)
}

/// Compares two text files (OBJ, CSV, JSON, ...) word by word: words that parse as numbers
/// may differ by `tolerance`, every other word must be equal. Returns the first difference.
pub fn compare_text(reference: &str, current: &str, tolerance: f64) -> Result<(), String> {
    let (mut r, mut c) = (reference.lines(), current.lines());
    let mut line = 0;
    loop {
        line += 1;
        let (a, b) = match (r.next(), c.next()) {
            (None, None) => return Ok(()),
            (Some(_), None) => return Err(format!("ends at line {line}, the reference goes on")),
            (None, Some(_)) => return Err(format!("line {line} is new: the reference ends before it")),
            (Some(a), Some(b)) => (a, b),
        };
        let (wa, wb): (Vec<&str>, Vec<&str>) = (a.split_whitespace().collect(), b.split_whitespace().collect());
        let same = wa.len() == wb.len()
            && wa.iter().zip(&wb).all(|(x, y)| match (x.parse::<f64>(), y.parse::<f64>()) {
                (Ok(x), Ok(y)) => (x - y).abs() <= tolerance || x == y,
                _ => x == y,
            });
        if !same {
            return Err(format!("line {line}: \"{b}\", reference \"{a}\" (numbers may differ by {tolerance})"));
        }
    }
}

/// Compares a series of values (one per frame): the first index that differs by more than
/// `tolerance`, as a message.
pub fn compare_values(reference: &[f64], current: &[f64], tolerance: f64) -> Result<(), String> {
    if reference.len() != current.len() {
        return Err(format!("{} value(s), the reference has {}", current.len(), reference.len()));
    }
    for (i, (r, c)) in reference.iter().zip(current).enumerate() {
        let ok = (r - c).abs() <= tolerance || r == c || (r.is_nan() && c.is_nan());
        if !ok {
            return Err(format!("value {i} is {c}, the reference {r} (tolerance {tolerance})"));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_pixel_over_the_threshold_counts_and_shows_in_the_diff() {
        let a = image::RgbaImage::from_pixel(4, 2, image::Rgba([10, 10, 10, 255]));
        let mut b = a.clone();
        b.put_pixel(1, 1, image::Rgba([14, 10, 10, 255]));
        let d = compare_rgba8(&a, &b, 3.0);
        assert_eq!(d.failing, 1);
        // Auto-scaled: the largest difference (4 levels) is white.
        assert_eq!((d.diff.get_pixel(1, 1)[0], d.diff_scale), (255, 255.0 / 4.0));
        assert_eq!(d.diff.get_pixel(0, 0)[0], 0);
        assert!(d.verdict(&ImageTolerance::default()).is_some(), "1 of 8 pixels is over the 0.5% budget");
        assert_eq!(compare_rgba8(&a, &b, 4.0).failing, 0);
    }

    #[test]
    fn ssim_keeps_rounding_and_catches_lost_structure() {
        // A shaded ramp with a dark band across it, as a shadow on a lit surface.
        let lit = image::RgbaImage::from_fn(48, 36, |x, y| {
            let v = (60 + 3 * x + y) as u8;
            image::Rgba(if (14..22).contains(&y) && x > 8 { [v / 3, v / 3, v / 3, 255] } else { [v, v, v, 255] })
        });
        let same = compare_rgba8(&lit, &lit, 3.0);
        assert_eq!(same.ssim, 1.0);
        assert_eq!(same.diff_scale, 1.0);
        // One level of rounding on every other pixel: still the same picture.
        let rounded = image::RgbaImage::from_fn(48, 36, |x, y| {
            let mut p = *lit.get_pixel(x, y);
            p[0] = p[0].saturating_add(((x + y) % 2) as u8);
            p
        });
        assert!(compare_rgba8(&lit, &rounded, 3.0).ssim > ImageTolerance::MIN_SSIM);
        let unshadowed = image::RgbaImage::from_fn(48, 36, |x, y| {
            let v = (60 + 3 * x + y) as u8;
            image::Rgba([v, v, v, 255])
        });
        let lost = compare_rgba8(&lit, &unshadowed, 3.0);
        assert!(lost.ssim < ImageTolerance::MIN_SSIM, "SSIM {}", lost.ssim);
        let ssim_only = ImageTolerance { threshold: 255.0, max_failing: 1.0, min_psnr: 0.0, ..Default::default() };
        assert!(lost.verdict(&ssim_only).unwrap().contains("SSIM"));
    }

    #[test]
    fn text_numbers_within_tolerance_match() {
        assert!(compare_text("v 1.0 2\nf 1 2 3", "v 1.00001 2\nf 1 2 3", 1e-4).is_ok());
        assert!(compare_text("v 1.0 2", "v 1.1 2", 1e-4).unwrap_err().contains("line 1"));
        assert!(compare_text("o a", "o b", 1.0).is_err());
        assert!(compare_text("v 1", "v 1\nv 2", 1.0).unwrap_err().contains("new"));
    }

    #[test]
    fn values_compare_per_frame() {
        assert!(compare_values(&[1.0, 2.0], &[1.0, 2.00001], 1e-3).is_ok());
        assert!(compare_values(&[1.0], &[1.5], 1e-3).unwrap_err().contains("value 0"));
        assert!(compare_values(&[1.0], &[1.0, 2.0], 1e-3).is_err());
    }
}

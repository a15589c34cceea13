//! Comparing outputs with references: images (8-bit PNG and float EXR) by a per-pixel
//! threshold with a budget of failing pixels and PSNR, geometry and other text files number by
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
}

impl Default for ImageTolerance {
    /// The golden images' tolerance: 0.5% of the pixels off by more than 3 levels, 40 dB.
    fn default() -> Self {
        ImageTolerance { threshold: 3.0, max_failing: 0.005, min_psnr: 40.0 }
    }
}

/// The result of comparing two images of the same size.
#[derive(Debug)]
pub struct ImageDiff {
    pub psnr: f64,
    pub psnr_alpha: f64,
    pub failing: usize,
    pub pixels: usize,
    /// Differences x8 (in 8-bit levels), an alpha difference as a blue tint; opaque.
    pub diff: image::RgbaImage,
}

impl ImageDiff {
    pub fn failing_share(&self) -> f64 {
        self.failing as f64 / self.pixels.max(1) as f64
    }

    /// Why the difference exceeds `tol`, or None when it is within it.
    pub fn verdict(&self, tol: &ImageTolerance) -> Option<String> {
        let share = self.failing_share();
        (self.psnr < tol.min_psnr || self.psnr_alpha < tol.min_psnr || share > tol.max_failing).then(|| {
            format!(
                "PSNR {:.1} dB, alpha {:.1} dB (min {}), {:.2}% of pixels differ by more than {} (max {:.2}%)",
                self.psnr,
                self.psnr_alpha,
                tol.min_psnr,
                share * 100.0,
                tol.threshold,
                tol.max_failing * 100.0
            )
        })
    }

    /// A one-line summary of the metrics.
    pub fn summary(&self) -> String {
        format!("PSNR {:.1} dB, {} of {} pixels over the threshold", self.psnr, self.failing, self.pixels)
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
    let mut diff = image::RgbaImage::new(width, height);
    let to_levels = 255.0 / peak;
    let byte = |d: f64| (d * to_levels * 8.0).round().clamp(0.0, 255.0) as u8;
    for ((a, e), d) in current.chunks_exact(4).zip(reference.chunks_exact(4)).zip(diff.pixels_mut()) {
        let mut worst = 0f64;
        for c in 0..4 {
            // NaN compares as a maximal difference rather than slipping through.
            let delta = (a[c] as f64 - e[c] as f64).abs();
            let delta = if delta.is_nan() { f64::INFINITY } else { delta };
            if c < 3 {
                sq += delta.min(peak).powi(2);
                d[c] = byte(delta);
            } else {
                sq_alpha += delta.min(peak).powi(2);
            }
            worst = worst.max(delta);
        }
        d[2] = d[2].max(byte((a[3] as f64 - e[3] as f64).abs()));
        d[3] = 255;
        if worst > threshold {
            failing += 1;
        }
    }
    let pixels = (width * height) as usize;
    let n = pixels.max(1) as f64;
    let psnr_of = |mse: f64| if mse == 0.0 { f64::INFINITY } else { 10.0 * (peak * peak / mse).log10() };
    ImageDiff { psnr: psnr_of(sq / (n * 3.0)), psnr_alpha: psnr_of(sq_alpha / n), failing, pixels, diff }
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
        assert_eq!(d.diff.get_pixel(1, 1)[0], 32);
        assert_eq!(d.diff.get_pixel(0, 0)[0], 0);
        assert!(d.verdict(&ImageTolerance::default()).is_some(), "1 of 8 pixels is over the 0.5% budget");
        assert_eq!(compare_rgba8(&a, &b, 4.0).failing, 0);
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

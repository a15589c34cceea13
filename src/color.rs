//! Colour encodings.

/// Linear to sRGB-encoded, one channel in [0, 1] (IEC 61966-2-1).
pub fn linear_to_srgb(c: f32) -> f32 {
    if c <= 0.0031308 { 12.92 * c } else { 1.055 * c.powf(1.0 / 2.4) - 0.055 }
}

/// Rec. 709 luminance of a linear RGB colour.
/// The inverse of [`linear_to_srgb`].
pub fn srgb_to_linear(c: f32) -> f32 {
    if c <= 0.04045 { c / 12.92 } else { ((c + 0.055) / 1.055).powf(2.4) }
}

pub fn luminance(c: glam::Vec3) -> f32 {
    0.2126 * c.x + 0.7152 * c.y + 0.0722 * c.z
}

#[cfg(test)]
mod tests {
    #[test]
    fn srgb_encoding_is_continuous_and_hits_the_ends() {
        assert_eq!(super::linear_to_srgb(0.0), 0.0);
        assert!((super::linear_to_srgb(1.0) - 1.0).abs() < 1e-6);
        let (a, b) = (super::linear_to_srgb(0.0031308), super::linear_to_srgb(0.0031309));
        assert!((a - b).abs() < 1e-4);
        assert!((super::linear_to_srgb(0.5) - 0.7354).abs() < 1e-3);
    }
}

//! Writing read-back images: PNG (8-bit) and OpenEXR (32-bit float).

use std::path::Path;

use anyhow::Context as _;

use crate::gpu::Pixels;

/// Writes 8-bit PNG. LDR pixels are stored as they are (already display-encoded);
/// HDR values are clamped to [0, 1] and sRGB-encoded.
pub fn write_png(path: &Path, px: &Pixels) -> anyhow::Result<()> {
    let bytes = to_rgba8(px);
    let img = image::RgbaImage::from_raw(px.width, px.height, bytes).context("pixel buffer has the wrong size")?;
    let tmp = path.with_extension("png.tmp");
    img.save_with_format(&tmp, image::ImageFormat::Png).with_context(|| format!("cannot write {}", path.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))
}

pub fn to_rgba8(px: &Pixels) -> Vec<u8> {
    px.rgba
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let v = if px.is_ldr || i % 4 == 3 { v } else { crate::nodes::scene::linear_to_srgb(v.clamp(0.0, 1.0)) };
            (v.clamp(0.0, 1.0) * 255.0).round() as u8
        })
        .collect()
}

/// Writes float RGBA OpenEXR, values as they are.
pub fn write_exr(path: &Path, px: &Pixels) -> anyhow::Result<()> {
    let img = image::Rgba32FImage::from_raw(px.width, px.height, px.rgba.clone())
        .context("pixel buffer has the wrong size")?;
    let tmp = path.with_extension("exr.tmp");
    img.save_with_format(&tmp, image::ImageFormat::OpenExr)
        .with_context(|| format!("cannot write {}", path.display()))?;
    std::fs::rename(&tmp, path).with_context(|| format!("cannot write {}", path.display()))
}

//! Writing read-back images: PNG (8-bit) and OpenEXR (32-bit float), atomically: a write that
//! fails leaves neither a partial image nor a temporary file behind.

use std::io::Cursor;
use std::path::Path;

use anyhow::Context as _;

use crate::gpu::Pixels;

crate::choice!(
    /// The image file formats `render` writes; the option names are the file extensions.
    pub enum ImageFormat {
        Png = "png",
        Exr = "exr",
    }
);

/// Writes `px` to `path` in `format`.
pub fn write_image(path: &Path, px: &Pixels, format: ImageFormat) -> anyhow::Result<()> {
    match format {
        ImageFormat::Png => write_png(path, px),
        ImageFormat::Exr => write_exr(path, px),
    }
}

/// Writes 8-bit PNG. LDR pixels are stored as they are (already display-encoded);
/// HDR values are clamped to [0, 1] and sRGB-encoded.
pub fn write_png(path: &Path, px: &Pixels) -> anyhow::Result<()> {
    let bytes = to_rgba8(px);
    let img = image::RgbaImage::from_raw(px.width, px.height, bytes).context("pixel buffer has the wrong size")?;
    let mut encoded = Cursor::new(Vec::new());
    img.write_to(&mut encoded, image::ImageFormat::Png).context("cannot encode PNG")?;
    crate::atomic::write_atomic(path, encoded.get_ref()).with_context(|| format!("cannot write {}", path.display()))
}

/// Tone maps HDR colour (not alpha) with x / (1 + x) so a float texture dumped as PNG keeps
/// its highlights instead of clipping at 1; negative values go to 0. LDR pixels are left as
/// they are.
pub fn tonemap_for_png(px: &mut Pixels) {
    if px.is_ldr {
        return;
    }
    for (i, v) in px.rgba.iter_mut().enumerate() {
        if i % 4 != 3 {
            let x = v.max(0.0);
            *v = x / (1.0 + x);
        }
    }
}

pub fn to_rgba8(px: &Pixels) -> Vec<u8> {
    px.rgba
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let v = if px.is_ldr || i % 4 == 3 { v } else { crate::color::linear_to_srgb(v.clamp(0.0, 1.0)) };
            (v.clamp(0.0, 1.0) * 255.0).round() as u8
        })
        .collect()
}

/// Writes float RGBA OpenEXR, values as they are.
pub fn write_exr(path: &Path, px: &Pixels) -> anyhow::Result<()> {
    let img = image::Rgba32FImage::from_raw(px.width, px.height, px.rgba.clone())
        .context("pixel buffer has the wrong size")?;
    let mut encoded = Cursor::new(Vec::new());
    img.write_to(&mut encoded, image::ImageFormat::OpenExr).context("cannot encode OpenEXR")?;
    crate::atomic::write_atomic(path, encoded.get_ref()).with_context(|| format!("cannot write {}", path.display()))
}

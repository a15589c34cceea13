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
    crate::io::atomic::write_atomic(path, encoded.get_ref()).with_context(|| format!("cannot write {}", path.display()))
}

/// Averages each `n` x `n` block into one pixel (a box filter: supersampling's resolve).
/// Display-encoded (LDR) colour is averaged in linear light and encoded again, so edges do
/// not come out too dark; alpha and HDR values are averaged as they are.
pub fn downsample_box(px: &Pixels, n: u32) -> Pixels {
    if n <= 1 {
        return Pixels { width: px.width, height: px.height, rgba: px.rgba.clone(), is_ldr: px.is_ldr };
    }
    let (w, h) = (px.width / n, px.height / n);
    let decode = |i: usize, v: f32| if px.is_ldr && i % 4 != 3 { crate::color::srgb_to_linear(v) } else { v };
    let mut rgba = vec![0.0f32; (w * h * 4) as usize];
    for y in 0..h {
        for x in 0..w {
            let out = ((y * w + x) * 4) as usize;
            for sy in 0..n {
                for sx in 0..n {
                    let src = (((y * n + sy) * px.width + x * n + sx) * 4) as usize;
                    for c in 0..4 {
                        rgba[out + c] += decode(c, px.rgba[src + c]);
                    }
                }
            }
        }
    }
    let scale = 1.0 / (n * n) as f32;
    for (i, v) in rgba.iter_mut().enumerate() {
        *v *= scale;
        if px.is_ldr && i % 4 != 3 {
            *v = crate::color::linear_to_srgb(*v);
        }
    }
    Pixels { width: w, height: h, rgba, is_ldr: px.is_ldr }
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
    crate::io::atomic::write_atomic(path, encoded.get_ref()).with_context(|| format!("cannot write {}", path.display()))
}

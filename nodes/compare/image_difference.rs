//! `ImageDifference`: the difference of two images, as a picture and as numbers (the
//! dissertation's Fig. 5.13 shows tessellation without and with warping and their difference).

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::gpu::{FullscreenPass, GpuImage, read_back};
use crate::nodes::render::tonemap::LDR_FORMAT;

pub static IMAGE_DIFFERENCE: NodeSpec = NodeSpec {
    kind: "ImageDifference",
    category: Category::Render,
    doc: "The per-channel absolute difference |a - b| of two images of one size: a visible image (times gain, clamped, sRGB) and the largest and mean difference (read back every evaluation; counts: differing pixels, those with a channel difference over 1/255).",
    inputs: &[
        PortSpec::required("a", PortType::Texture, "The first image."),
        PortSpec::required("b", PortType::Texture, "The second image, the size of the first."),
    ],
    outputs: &[
        PortSpec::output("image", PortType::Texture, "gain x |a - b|, clamped to [0, 1], Rgba8UnormSrgb."),
        PortSpec::output("max", PortType::Scalar, "The largest channel difference (RGB), in the inputs' values."),
        PortSpec::output("mean", PortType::Scalar, "The mean channel difference (RGB) over all pixels."),
    ],
    params: &[ParamSpec::new(
        "gain",
        ParamKind::Float { default: 8.0, min: 0.0, max: 1e4 },
        "Scale of the visible difference (small differences become visible).",
    )],
    capabilities: Capabilities::NONE,
    create: || Box::new(ImageDifferenceNode::default()),
};

#[derive(Default)]
struct ImageDifferenceNode {
    pass: Option<FullscreenPass>,
}

/// Largest and mean RGB difference, and the pixels with a channel difference over `threshold`.
fn statistics(raw: &[f32], threshold: f32) -> (f64, f64, usize) {
    let (mut max, mut sum, mut differing) = (0.0f32, 0.0f64, 0);
    let pixels = raw.len() / 4;
    for px in raw.chunks_exact(4) {
        let m = px[..3].iter().copied().fold(0.0f32, f32::max);
        max = max.max(m);
        sum += px[..3].iter().map(|&v| f64::from(v)).sum::<f64>();
        differing += usize::from(m > threshold);
    }
    (f64::from(max), sum / (3 * pixels.max(1)) as f64, differing)
}

impl Node for ImageDifferenceNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let a: Arc<GpuImage> = cx.input("a")?;
        let b: Arc<GpuImage> = cx.input("b")?;
        if (a.width, a.height) != (b.width, b.height) {
            return Err(NodeError::msg(format!(
                "input a is {}x{} but input b is {}x{}: the images must be the same size",
                a.width, a.height, b.width, b.height
            )));
        }
        let pass = self.pass.get_or_insert_with(|| FullscreenPass::new("image_difference.wgsl"));
        // `Params` in shaders/compare/image_difference.wgsl: the gain, padded to 16 bytes.
        let settings = [cx.f32("gain"), 0.0, 0.0, 0.0];
        let visible = GpuImage::target(gpu, "difference", a.width, a.height, LDR_FORMAT);
        let raw = GpuImage::target(gpu, "difference (raw)", a.width, a.height, gpu.formats().hdr);
        pass.run_mrt(gpu, bytemuck::bytes_of(&settings), &[&a, &b], &[&visible, &raw])?;
        let pixels = read_back(gpu, &raw).map_err(|e| NodeError::msg(format!("{e:#}")))?;
        let (max, mean, differing) = statistics(&pixels.rgba, 1.0 / 255.0);
        cx.count("differing_pixels", differing);
        cx.set("image", Arc::new(visible));
        cx.set("max", max);
        cx.set("mean", mean);
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::statistics;

    #[test]
    fn statistics_take_rgb_only() {
        // Two pixels: one differs by 0.5 in green (alpha 1 is ignored), one not at all.
        let raw = [0.0, 0.5, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0];
        let (max, mean, differing) = statistics(&raw, 1.0 / 255.0);
        assert_eq!(max, 0.5);
        assert!((mean - 0.5 / 6.0).abs() < 1e-12);
        assert_eq!(differing, 1);
    }
}

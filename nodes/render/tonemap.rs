//! Exposure and tone mapping to an 8-bit sRGB image.

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::gpu::GpuImage;

use crate::gpu::FullscreenPass;

pub const LDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8UnormSrgb;
crate::choice!(
    /// The tone curves; the index is what shaders/render/tonemap.wgsl switches on.
    enum ToneCurve {
        None = "none",
        Reinhard = "reinhard",
        Aces = "aces",
        Filmic = "filmic",
    }
);

pub static TONEMAP: NodeSpec = NodeSpec {
    kind: "Tonemap",
    category: Category::Render,
    doc: "Applies exposure (in stops) and a tone curve (Reinhard, ACES fit, Hable filmic) and encodes sRGB. With auto_exposure the image's log-average luminance is brought to the key value first (Reinhard et al. 2002), so a bright studio probe does not wash albedos out.",
    inputs: &[PortSpec::required("image", PortType::Texture, "Linear HDR input.")],
    outputs: &[
        PortSpec::output("image", PortType::Texture, "Display-ready Rgba8UnormSrgb."),
        PortSpec::output("stops", PortType::Scalar, "The exposure applied, in stops (auto and manual together)."),
    ],
    params: &[
        ParamSpec::new(
            "auto_exposure",
            ParamKind::Bool { default: false },
            "Scale the image so that its log-average luminance exp(mean(ln(1e-4 + L))) equals key (reads the image back to the CPU once per evaluation).",
        ),
        ParamSpec::new(
            "key",
            ParamKind::Float { default: 0.18, min: 0.001, max: 10.0 },
            "The log-average luminance auto_exposure aims for: 0.18 middle grey; lower for a low-key, higher for a high-key picture.",
        ),
        ParamSpec::new(
            "exposure",
            ParamKind::Float { default: 0.0, min: -20.0, max: 20.0 },
            "Exposure in stops (multiplies by 2^exposure); with auto_exposure, a correction on top of it.",
        ),
        ParamSpec::new(
            "operator",
            ParamKind::Choice { default: "aces", options: ToneCurve::OPTIONS },
            "The tone curve.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(TonemapNode::default()),
};

/// `Params` in shaders/render/tonemap.wgsl, field for field.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct TonemapUniform {
    /// 2^stops.
    exposure: f32,
    /// The `ToneCurve` index.
    curve: u32,
    pad: [f32; 2],
}

#[derive(Default)]
struct TonemapNode {
    pass: Option<FullscreenPass>,
}

impl Node for TonemapNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let input: Arc<GpuImage> = cx.input("image")?;
        if self.pass.is_none() {
            self.pass = Some(FullscreenPass::new("tonemap.wgsl"));
        }
        let op = cx.choice::<ToneCurve>("operator") as u32;
        let mut stops = cx.f64("exposure");
        if cx.bool("auto_exposure") {
            let pixels = crate::gpu::read_back(gpu, &input)?;
            stops += auto_exposure_stops(&pixels.rgba, cx.f64("key"));
        }
        cx.set("stops", stops);
        let settings = TonemapUniform { exposure: stops.exp2() as f32, curve: op, pad: [0.0; 2] };
        let out = GpuImage::target(gpu, "tonemapped", input.width, input.height, LDR_FORMAT);
        self.pass.as_mut().expect("created above").run(gpu, bytemuck::bytes_of(&settings), &[&input], &out)?;
        cx.set("image", Arc::new(out));
        Ok(())
    }
}

/// The stops that bring the log-average luminance of linear RGBA pixels to `key` (Reinhard
/// et al. 2002, eq. 1: exp(mean(ln(delta + L))), delta = 1e-4 against black pixels). Pixels
/// that are not finite are left out; an image without any gives 0.
fn auto_exposure_stops(rgba: &[f32], key: f64) -> f64 {
    let (sum, n) = rgba
        .chunks_exact(4)
        .map(|p| 0.2126 * p[0] as f64 + 0.7152 * p[1] as f64 + 0.0722 * p[2] as f64)
        .filter(|l| l.is_finite() && *l >= 0.0)
        .fold((0.0, 0usize), |(s, n), l| (s + (1e-4 + l).ln(), n + 1));
    if n == 0 {
        return 0.0;
    }
    (key / (sum / n as f64).exp()).log2()
}

#[cfg(test)]
mod tests {
    #[test]
    fn auto_exposure_brings_the_log_average_to_the_key() {
        // A uniform grey of 0.72 needs two stops down to reach 0.18.
        let grey = [0.72f32, 0.72, 0.72, 1.0].repeat(16);
        assert!((super::auto_exposure_stops(&grey, 0.18) + 2.0).abs() < 1e-3);
        // Half at 0.045, half at 0.72: log-average 0.18, no change.
        let mixed: Vec<f32> = [[0.045f32, 0.045, 0.045, 1.0], [0.72, 0.72, 0.72, 1.0]].concat().repeat(8);
        assert!(super::auto_exposure_stops(&mixed, 0.18).abs() < 5e-3);
        // NaN is left out; nothing finite: no change.
        let nan = [f32::NAN, 0.0, 0.0, 1.0].repeat(4);
        assert_eq!(super::auto_exposure_stops(&nan, 0.18), 0.0);
    }
}

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
    doc: "Applies exposure (in stops) and a tone curve (Reinhard, ACES fit, Hable filmic) and encodes sRGB.",
    inputs: &[PortSpec::required("image", PortType::Texture, "Linear HDR input.")],
    outputs: &[PortSpec::output("image", PortType::Texture, "Display-ready Rgba8UnormSrgb.")],
    params: &[
        ParamSpec::new(
            "exposure",
            ParamKind::Float { default: 0.0, min: -20.0, max: 20.0 },
            "Exposure in stops (multiplies by 2^exposure).",
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
        let settings = TonemapUniform { exposure: cx.f32("exposure").exp2(), curve: op, pad: [0.0; 2] };
        let out = GpuImage::target(gpu, "tonemapped", input.width, input.height, LDR_FORMAT);
        self.pass.as_mut().expect("created above").run(gpu, bytemuck::bytes_of(&settings), &[&input], &out)?;
        cx.set("image", Arc::new(out));
        Ok(())
    }
}

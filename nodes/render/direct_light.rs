//! Direct lighting over the G-buffer until image-based lighting arrives.

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::gpu::GpuImage;
use crate::render::scene::GBuffer;

use crate::gpu::FullscreenPass;

pub const HDR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

pub static DIRECT_LIGHT: NodeSpec = NodeSpec {
    kind: "DirectLight",
    category: Category::Lighting,
    doc: "Shades the G-buffer with one directional light (Lambert + normalized Blinn-Phong from glossiness) and a sky/ground hemisphere ambient.",
    inputs: &[PortSpec::required("gbuffer", PortType::GBuffer, "The G-buffer to shade.")],
    outputs: &[PortSpec::output("image", PortType::Texture, "Linear HDR radiance, Rgba16Float.")],
    params: &[
        ParamSpec::new(
            "sun_direction",
            ParamKind::Vec3 { default: [-0.4, -1.0, -0.6] },
            "Direction the light travels.",
        ),
        ParamSpec::new("sun_color", ParamKind::Color { default: [1.0, 0.96, 0.9] }, "Light colour."),
        ParamSpec::new("sun_intensity", ParamKind::Float { default: 3.0, min: 0.0, max: 1e5 }, "Irradiance scale."),
        ParamSpec::new("sky_color", ParamKind::Color { default: [0.35, 0.4, 0.5] }, "Ambient from above."),
        ParamSpec::new("ground_color", ParamKind::Color { default: [0.15, 0.13, 0.12] }, "Ambient from below."),
        ParamSpec::new(
            "background",
            ParamKind::Color { default: [0.05, 0.05, 0.06] },
            "Colour where nothing was drawn.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(DirectLightNode::default()),
};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct LightUniform {
    inv_view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    sun_dir: [f32; 4],
    sun: [f32; 4],
    sky: [f32; 4],
    ground: [f32; 4],
    background: [f32; 4],
    size: [f32; 4],
}

#[derive(Default)]
struct DirectLightNode {
    pass: Option<FullscreenPass>,
}

impl Node for DirectLightNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let g: Arc<GBuffer> = cx.input("gbuffer")?;
        let dir =
            cx.vec3("sun_direction").try_normalize().ok_or_else(|| NodeError::msg("sun_direction must not be zero"))?;
        if self.pass.is_none() {
            self.pass = Some(FullscreenPass::new("direct_light.wgsl"));
        }
        let (w, h) = (g.width(), g.height());
        let rgb = |v: glam::Vec3| [v.x, v.y, v.z, 0.0];
        let uniform = LightUniform {
            inv_view_proj: g.view.inv_view_proj.to_cols_array_2d(),
            eye: rgb(g.view.eye),
            sun_dir: rgb(dir),
            sun: rgb(cx.vec3("sun_color") * cx.f32("sun_intensity")),
            sky: rgb(cx.vec3("sky_color")),
            ground: rgb(cx.vec3("ground_color")),
            background: rgb(cx.vec3("background")),
            size: [0.0, w as f32, h as f32, 0.0],
        };
        let out = GpuImage::target(gpu, "direct light", w, h, gpu.formats().hdr);
        let pass = self.pass.as_mut().expect("created above");
        pass.run(gpu, bytemuck::bytes_of(&uniform), &[&g.color, &g.normal, &g.depth], &out)?;
        cx.set("image", Arc::new(out));
        Ok(())
    }
}

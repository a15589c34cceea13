//! `Bounce`: one bounce of diffuse light in screen space (issue 34), after the indirect part
//! of screen-space directional occlusion (Ritschel et al. 2009), estimated by marched
//! cosine-weighted directions (shaders/occlusion/bounce.wgsl).
//! The lit image supplies each sender's radiance, so light reflected off a red torus reddens
//! the floor next to it, and contact regions get the light their neighbours send back.

use std::sync::Arc;

use super::GatherResolve;
use crate::core::node::prelude::*;
use crate::gpu::GpuImage;
use crate::render::scene::GBuffer;

pub static BOUNCE: NodeSpec = NodeSpec {
    kind: "Bounce",
    category: Category::Lighting,
    doc: "One bounce of diffuse light in screen space (after the indirect part of screen-space directional occlusion, Ritschel et al. 2009, \
estimated by directions): per pixel, `samples` cosine-weighted directions of the hemisphere above its point are marched in 8 steps up to `radius` \
(world units); where a step first passes behind the surface the camera sees (by less than the radius), that surface sends its radiance L_s from \
the lit image if it faces the point: E = pi / samples x sum L_s, and the image gains strength x albedo x E / pi. The directions are rotated per \
pixel with a 4x4 interleaved pattern and E is averaged over each 4x4 tile, edge-aware. Only what the screen shows sends light (senders off \
screen or hidden are missing), and the bounce itself is not shadowed. Deterministic: no time-based noise.",
    inputs: &[
        PortSpec::required("gbuffer", PortType::GBuffer, "The G-buffer (depth, normals, albedo)."),
        PortSpec::required(
            "image",
            PortType::Texture,
            "The lit image (linear radiance, the G-buffer's size): the senders' radiance, and what the bounce is added to.",
        ),
    ],
    outputs: &[PortSpec::output("image", PortType::Texture, "The image with one bounce of diffuse light added.")],
    params: &[
        ParamSpec::new(
            "radius",
            ParamKind::Float { default: 0.5, min: 1e-4, max: 1e4 },
            "How far light travels from sender to receiver, world units.",
        ),
        ParamSpec::new(
            "samples",
            ParamKind::Int { default: 8, min: 1, max: 256 },
            "Directions per pixel, 8 steps each (a 4x4 tile uses 16 times as many directions).",
        ),
        ParamSpec::new(
            "strength",
            ParamKind::Float { default: 1.0, min: 0.0, max: 8.0 },
            "Multiplies the bounce (1: physically scaled; 0: the image unchanged).",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(BounceNode::default()),
};

/// shaders/occlusion/bounce.wgsl `Bounce`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct BounceUniform {
    proj: [[f32; 4]; 4],
    view: [[f32; 4]; 4],
    size: [f32; 4],
    radius: f32,
    /// Was the sample count, now the shader's SAMPLES constant.
    unused: f32,
    strength: f32,
    plane_tolerance: f32,
}

#[derive(Default)]
struct BounceNode {
    passes: Option<GatherResolve>,
}

impl Node for BounceNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let g: Arc<GBuffer> = cx.input("gbuffer")?;
        let image: Arc<GpuImage> = cx.input("image")?;
        super::check_image_size(&image, &g)?;
        let radius = cx.f32("radius");
        let u = BounceUniform {
            proj: g.view.proj.to_cols_array_2d(),
            view: g.view.view.to_cols_array_2d(),
            size: [g.width() as f32, g.height() as f32, 0.0, 0.0],
            radius,
            unused: 0.0,
            strength: cx.f32("strength"),
            plane_tolerance: 0.1 * radius,
        };
        let passes = self.passes.get_or_insert_with(|| GatherResolve::new("bounce.wgsl"));
        // A constant, not a uniform: lavapipe compiled the pass again on every draw whose loop
        // bound was a uniform.
        let samples = cx.int("samples").clamp(1, 256) as u32;
        let out = passes.run(gpu, "bounce", &g, &image, bytemuck::bytes_of(&u), &[], &[("SAMPLES", samples)])?;
        cx.set("image", Arc::new(out));
        Ok(())
    }
}

//! `ReferenceOcclusion`: ray-traced ambient occlusion of the G-buffer's pixels against the
//! whole scene on the CPU (src/occlusion/reference.rs), to measure SSAO and hybrid occlusion
//! against instead of judging them by eye.

use std::sync::Arc;

use glam::Vec3;

use crate::core::node::prelude::*;
use crate::gpu::{GpuImage, read_back};
use crate::occlusion::reference::{ReferenceSettings, SceneBvh, reference_occlusion};
use crate::render::scene::{DrawItem, GBuffer};

pub static REFERENCE_OCCLUSION: NodeSpec = NodeSpec {
    kind: "ReferenceOcclusion",
    category: Category::Lighting,
    doc: "Ray-traced ambient occlusion (CPU) of the G-buffer's pixels against every triangle of the scene: per pixel, `samples` \
cosine-weighted rays about the G-buffer normal from the reconstructed world position (moved 0.001 along the normal); a ray is occluded \
when it hits a triangle within `max_distance` (world units, the counterpart of Ssao's radius). Output: the unoccluded fraction \
(1 = unoccluded, the cosine-weighted visibility), Rgba32Float. Rays follow a rank-1 (R2) sequence rotated per pixel by a hash of \
the pixel and `seed`, so the same input gives the same bytes, whatever the thread count. Plain meshes only: deferred-warped \
attachments are not traced. Slow (seconds); meant for tests and benches.",
    inputs: &[
        PortSpec::required("scene", PortType::Scene, "The geometry that occludes (every triangle, world space)."),
        PortSpec::required("gbuffer", PortType::GBuffer, "The pixels: positions from its depth and view, its normals."),
    ],
    outputs: &[PortSpec::output(
        "occlusion",
        PortType::Texture,
        "The visibility factor in rgb (1 = unoccluded), Rgba32Float.",
    )],
    params: &[
        ParamSpec::new("samples", ParamKind::Int { default: 256, min: 1, max: 65536 }, "Rays per pixel."),
        ParamSpec::new(
            "max_distance",
            ParamKind::Float { default: 1.0, min: 1e-4, max: 1e6 },
            "Hits farther than this (world units) do not occlude.",
        ),
        ParamSpec::new("seed", ParamKind::Int { default: 0, min: 0, max: 1 << 31 }, "Seed of the ray directions."),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(ReferenceOcclusionNode),
};

struct ReferenceOcclusionNode;

impl Node for ReferenceOcclusionNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let scene: Arc<Vec<DrawItem>> = cx.input("scene")?;
        let g: Arc<GBuffer> = cx.input("gbuffer")?;
        let settings = ReferenceSettings {
            samples: cx.int("samples").max(1) as u32,
            max_distance: cx.f32("max_distance"),
            seed: cx.int("seed") as u64,
        };
        let depth = read_back(gpu, &g.depth)?;
        let normal = read_back(gpu, &g.normal)?;
        let dc = (depth.rgba.len() / (depth.width * depth.height) as usize).max(1);
        let nc = (normal.rgba.len() / (normal.width * normal.height) as usize).max(1);
        let depth: Vec<f32> = depth.rgba.iter().step_by(dc).copied().collect();
        let normals: Vec<Vec3> = normal.rgba.chunks_exact(nc).map(|c| Vec3::new(c[0], c[1], c[2])).collect();
        let bvh = SceneBvh::new(&scene);
        let mut view = g.view;
        (view.width, view.height) = (g.width(), g.height());
        let vis = reference_occlusion(&bvh, &view, &depth, &normals, &settings);
        let texels: Vec<f32> = vis.iter().flat_map(|&v| [v, v, v, 1.0]).collect();
        let out = GpuImage::upload(
            gpu,
            "reference occlusion",
            g.width(),
            g.height(),
            wgpu::TextureFormat::Rgba32Float,
            16,
            bytemuck::cast_slice(&texels),
        );
        cx.set("occlusion", Arc::new(out));
        Ok(())
    }
}

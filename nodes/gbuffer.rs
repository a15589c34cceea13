//! The G-buffer pass of the deferred renderer (dissertation section 4.2): plain meshes and
//! deferred-warped detail geometry (instanced through the matrix texture) into the same targets.

use std::sync::Arc;

use crate::gpu::pass::{Bindings, texture_entry, uniform_entry};
use crate::gpu::{Bind, ComputePass, GpuContext, GpuImage, RenderPipelineDesc, SamplerKind};
use crate::mesh::Vertex;
use crate::node::prelude::*;
use crate::scene::{Camera, DrawItem, GBuffer, Image8};
use crate::warp::InstanceData;

pub static GBUFFER_PASS: NodeSpec = NodeSpec {
    kind: "GBufferPass",
    category: Category::Render,
    doc: "Rasterizes a scene into the G-buffer: colour + glossiness, normal + coarse/detail flag, linear depth. Attached (deferred-warped) items are drawn instanced through their matrix texture.",
    inputs: &[
        PortSpec::required("scene", PortType::Scene, "What to draw."),
        PortSpec::required("camera", PortType::Camera, "The view."),
    ],
    outputs: &[
        PortSpec::output("gbuffer", PortType::GBuffer, "All targets, for lighting passes."),
        PortSpec::output("color", PortType::Texture, "Linear base colour (rgb) and glossiness (a)."),
        PortSpec::output("normal", PortType::Texture, "World normal (rgb) and detail flag (a)."),
        PortSpec::output("depth", PortType::Texture, "Linear view depth; 0 where empty."),
    ],
    params: &[] as &[ParamSpec],
    is_output: false,
    create: || Box::new(GBufferPassNode::default()),
};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct FrameUniform {
    view_proj: [[f32; 4]; 4],
    view: [[f32; 4]; 4],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ObjectUniform {
    model: [[f32; 4]; 4],
    normal_matrix: [[f32; 4]; 4],
    base_color: [f32; 4],
    params: [f32; 4],
    extra: [f32; 4],
}

/// What the G-buffer pass keeps between frames: per group and item, its uniform buffers and
/// cached bind groups (the pipelines live in the context's cache).
pub struct Pipelines {
    frame: Bindings,
    objects: Vec<Bindings>,
    warps: Vec<Bindings>,
    white: Image8,
    resolver: InstanceResolver,
}

#[derive(Default)]
pub struct GBufferPassNode {
    pipelines: Option<Pipelines>,
}

/// Group 2 of shaders/warp.wgsl: the matrix texture's three columns, the warp settings
/// (`uniform`, from `WarpSettings::uniform`) and the seam map.
pub fn warp_binds<'a>(m: &'a crate::warp::MatrixTexture, uniform: &'a [f32; 4]) -> [Bind<'a>; 5] {
    [
        Bind::Texture(&m.col_u),
        Bind::Texture(&m.col_n),
        Bind::Texture(&m.col_v),
        Bind::Uniform(bytemuck::cast_slice(uniform)),
        Bind::Texture(&m.seams),
    ]
}

/// The layout of [`warp_binds`], as seen from `visibility`.
pub fn warp_layout(gpu: &GpuContext, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayout {
    gpu.bind_group_layout(&[
        texture_entry(0, visibility, false),
        texture_entry(1, visibility, false),
        texture_entry(2, visibility, false),
        uniform_entry(3, visibility),
        texture_entry(4, visibility, false),
    ])
}

/// Looks up point attachments' frames once per instance (shaders/attach_resolve.wgsl).
pub struct InstanceResolver {
    pass: ComputePass,
}

impl Default for InstanceResolver {
    fn default() -> Self {
        InstanceResolver { pass: ComputePass::new("attach_resolve.wgsl", "main") }
    }
}

impl InstanceResolver {
    pub fn new(_gpu: &GpuContext) -> anyhow::Result<Self> {
        Ok(InstanceResolver::default())
    }

    /// A new instance buffer with each instance's frame filled in.
    pub fn resolve(
        &mut self,
        gpu: &GpuContext,
        raw: &wgpu::Buffer,
        draw: &crate::warp::AttachedDraw,
    ) -> anyhow::Result<wgpu::Buffer> {
        let out = gpu.create_buffer(
            "resolved instances",
            raw.size(),
            wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let uniform = draw.settings.uniform(false);
        let warp = warp_binds(&draw.matrix, &uniform);
        let io = [Bind::Storage(raw), Bind::StorageRw(&out)];
        self.pass.dispatch(gpu, &[&io, &[], &warp], ComputePass::groups_for(draw.instances.len(), 64))?;
        Ok(out)
    }
}

impl Pipelines {
    fn new(gpu: &GpuContext) -> anyhow::Result<Pipelines> {
        Ok(Pipelines {
            frame: Bindings::new(wgpu::ShaderStages::VERTEX),
            objects: Vec::new(),
            warps: Vec::new(),
            white: Image8::new(1, 1, vec![255; 4]),
            resolver: InstanceResolver::new(gpu)?,
        })
    }
}

fn object_uniform(item: &DrawItem) -> ObjectUniform {
    let m = &item.material;
    ObjectUniform {
        model: item.model.to_cols_array_2d(),
        normal_matrix: item.model.inverse().transpose().to_cols_array_2d(),
        base_color: [m.base_color.x, m.base_color.y, m.base_color.z, m.glossiness],
        params: [
            m.uv_scale,
            f32::from(u8::from(m.texture.is_some())),
            f32::from(u8::from(item.detail)),
            f32::from(u8::from(m.gloss_map.is_some())),
        ],
        extra: [m.gloss_min, 0.0, 0.0, 0.0],
    }
}

/// Renders `items` into a new G-buffer of `w` x `h` (pooled targets; recorded, submitted
/// with the frame). Shared by the node and the benchmarks.
pub fn render_gbuffer(
    gpu: &GpuContext,
    pipelines: &mut Option<Pipelines>,
    items: &[DrawItem],
    camera: crate::scene::Camera,
    w: u32,
    h: u32,
) -> anyhow::Result<GBuffer> {
    if pipelines.is_none() {
        *pipelines = Some(Pipelines::new(gpu)?);
    }
    let p = pipelines.as_mut().expect("created above");
    let formats = *gpu.formats();
    let color = GpuImage::target(gpu, "gbuffer color", w, h, formats.hdr);
    let normal = GpuImage::target(gpu, "gbuffer normal", w, h, formats.hdr);
    let depth = GpuImage::target(gpu, "gbuffer depth", w, h, formats.linear_depth);
    let depth_buffer = GpuImage::target(gpu, "gbuffer depth buffer", w, h, formats.depth);

    let view = camera.view();
    let view_proj = camera.projection(w as f32 / h as f32) * view;
    let frame_uniform = FrameUniform { view_proj: view_proj.to_cols_array_2d(), view: view.to_cols_array_2d() };
    let frame_binds = [Bind::Uniform(bytemuck::bytes_of(&frame_uniform))];
    let frame_layout = p.frame.layout(gpu, &frame_binds);
    let frame_bg = p.frame.bind_group(gpu, &frame_layout, &frame_binds);

    let sampler = SamplerKind::LinearRepeat;
    let object_shape = {
        let white = p.white.gpu(gpu);
        [Bind::Uniform(&[]), Bind::Texture(white), Bind::Sampler(sampler), Bind::Texture(white)]
    };
    let objects = Bindings::new(wgpu::ShaderStages::VERTEX_FRAGMENT);
    let object_layout = objects.layout(gpu, &object_shape);
    // The attached pipeline only where something is attached: the node then depends on attach.wgsl.
    let warp_layout = items.iter().any(|i| i.attached.is_some()).then(|| warp_layout(gpu, wgpu::ShaderStages::VERTEX));
    let targets = [formats.hdr, formats.hdr, formats.linear_depth];
    let depth_test = Some((formats.depth, wgpu::CompareFunction::Less));
    let vertex = [Some(Vertex::layout())];
    let plain = gpu.render_pipeline(&RenderPipelineDesc {
        depth: depth_test,
        ..RenderPipelineDesc::new("gbuffer.wgsl", &[Some(&frame_layout), Some(&object_layout)], &vertex, &targets)
    })?;
    let attached = match &warp_layout {
        Some(warp_layout) => Some(gpu.render_pipeline(&RenderPipelineDesc {
            depth: depth_test,
            ..RenderPipelineDesc::new(
                "attach.wgsl",
                &[Some(&frame_layout), Some(&object_layout), Some(warp_layout)],
                &[Some(Vertex::layout()), Some(InstanceData::layout())],
                &targets,
            )
        })?),
        None => None,
    };

    while p.objects.len() < items.len() {
        p.objects.push(Bindings::new(wgpu::ShaderStages::VERTEX_FRAGMENT));
        p.warps.push(Bindings::new(wgpu::ShaderStages::VERTEX));
    }
    let mut object_bgs = Vec::with_capacity(items.len());
    let mut warp_bgs: Vec<Option<(wgpu::BindGroup, wgpu::Buffer)>> = Vec::with_capacity(items.len());
    for (i, item) in items.iter().enumerate() {
        let m = &item.material;
        let uniform = object_uniform(item);
        let tex = m.texture.as_deref().unwrap_or(&p.white).gpu(gpu);
        let gloss = m.gloss_map.as_deref().unwrap_or(&p.white).gpu(gpu);
        let binds = [
            Bind::Uniform(bytemuck::bytes_of(&uniform)),
            Bind::Texture(tex),
            Bind::Sampler(sampler),
            Bind::Texture(gloss),
        ];
        object_bgs.push(p.objects[i].bind_group(gpu, &object_layout, &binds));
        warp_bgs.push(match (&item.attached, &warp_layout) {
            (Some(a), Some(layout)) => {
                let resolver = &mut p.resolver;
                let buffer = a.draw_buffer(gpu, |raw| resolver.resolve(gpu, raw, a))?.clone();
                let uniform = a.settings.uniform(a.per_instance_frames());
                Some((p.warps[i].bind_group(gpu, layout, &warp_binds(&a.matrix, &uniform)), buffer))
            }
            _ => None,
        });
    }

    gpu.record(|enc| {
        let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("gbuffer"),
            color_attachments: &[color.clear_attachment(), normal.clear_attachment(), depth.clear_attachment()],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth_buffer.view,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                stencil_ops: None,
            }),
            timestamp_writes: gpu.pass_timestamps(),
            occlusion_query_set: None,
            multiview_mask: None,
        });
        pass.set_bind_group(0, &frame_bg, &[]);
        for ((item, bg), warp_bg) in items.iter().zip(&object_bgs).zip(&warp_bgs) {
            let mesh = item.mesh.gpu(gpu);
            pass.set_bind_group(1, bg, &[]);
            pass.set_vertex_buffer(0, mesh.vertices.slice(..));
            pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
            match (&item.attached, warp_bg, &attached) {
                (Some(a), Some((wbg, buffer)), Some(pipeline)) => {
                    if a.instances.is_empty() {
                        continue;
                    }
                    pass.set_pipeline(pipeline);
                    pass.set_bind_group(2, wbg, &[]);
                    pass.set_vertex_buffer(1, buffer.slice(..));
                    pass.draw_indexed(0..mesh.index_count, 0, 0..a.instances.len() as u32);
                }
                _ => {
                    pass.set_pipeline(&plain);
                    pass.draw_indexed(0..mesh.index_count, 0, 0..1);
                }
            }
        }
    });
    Ok(GBuffer { color, normal, depth, depth_buffer, camera })
}

impl Node for GBufferPassNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let items: Arc<Vec<DrawItem>> = cx.input("scene")?;
        let camera: Camera = cx.input("camera")?;
        let gbuffer =
            Arc::new(render_gbuffer(gpu, &mut self.pipelines, &items, camera, cx.settings.width, cx.settings.height)?);
        // The per-channel ports are further handles to the same textures.
        cx.set("color", Arc::new(gbuffer.color.share()));
        cx.set("normal", Arc::new(gbuffer.normal.share()));
        cx.set("depth", Arc::new(gbuffer.depth.share()));
        cx.set("gbuffer", gbuffer);
        Ok(())
    }
}

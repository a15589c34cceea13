//! The G-buffer pass of the deferred renderer (dissertation section 4.2): plain meshes and
//! deferred-warped detail geometry (instanced through the matrix texture) into the same targets.

use std::sync::Arc;

use wgpu::util::DeviceExt;

use crate::gpu::{GpuContext, GpuImage};
use crate::mesh::Vertex;
use crate::node::prelude::*;
use crate::scene::{Camera, DrawItem, GBuffer, Image8};
use crate::warp::InstanceData;

pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
pub const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;

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

pub struct Pipelines {
    plain: wgpu::RenderPipeline,
    attached: wgpu::RenderPipeline,
    frame_layout: wgpu::BindGroupLayout,
    object_layout: wgpu::BindGroupLayout,
    warp_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    white: Image8,
    resolver: InstanceResolver,
}

#[derive(Default)]
pub struct GBufferPassNode {
    pipelines: Option<Pipelines>,
}

pub fn uniform_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

pub fn texture_entry(binding: u32, visibility: wgpu::ShaderStages, filterable: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Texture {
            sample_type: wgpu::TextureSampleType::Float { filterable },
            view_dimension: wgpu::TextureViewDimension::D2,
            multisampled: false,
        },
        count: None,
    }
}

/// Group 2 of shaders/warp.wgsl: the matrix texture's three columns and the warp settings.
pub fn warp_layout(gpu: &GpuContext, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayout {
    gpu.device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
        label: Some("warp"),
        entries: &[
            texture_entry(0, visibility, false),
            texture_entry(1, visibility, false),
            texture_entry(2, visibility, false),
            uniform_entry(3, visibility),
            texture_entry(4, visibility, false),
        ],
    })
}

/// `resolved`: the instances carry per-instance frames (see `InstanceResolver`).
pub fn warp_bind_group(
    gpu: &GpuContext,
    layout: &wgpu::BindGroupLayout,
    draw: &crate::warp::AttachedDraw,
    resolved: bool,
) -> wgpu::BindGroup {
    let uniform = gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("warp settings"),
        contents: bytemuck::cast_slice(&draw.settings.uniform(resolved)),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let m = &draw.matrix;
    gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("warp"),
        layout,
        entries: &[
            wgpu::BindGroupEntry { binding: 0, resource: wgpu::BindingResource::TextureView(&m.col_u.view) },
            wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&m.col_n.view) },
            wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&m.col_v.view) },
            wgpu::BindGroupEntry { binding: 3, resource: uniform.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 4, resource: wgpu::BindingResource::TextureView(&m.seams.view) },
        ],
    })
}

/// Looks up point attachments' frames once per instance (shaders/attach_resolve.wgsl).
pub struct InstanceResolver {
    pipeline: wgpu::ComputePipeline,
    io_layout: wgpu::BindGroupLayout,
    warp_layout: wgpu::BindGroupLayout,
}

pub fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility: wgpu::ShaderStages::COMPUTE,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A compute pipeline over the warp (shaders/warp.wgsl): its own buffers in group 0, the
/// matrix texture and warp settings in group 2. Returns the pipeline and both layouts.
pub fn warp_compute_pipeline(
    gpu: &GpuContext,
    shader: &'static str,
    io_entries: &[wgpu::BindGroupLayoutEntry],
) -> anyhow::Result<(wgpu::ComputePipeline, wgpu::BindGroupLayout, wgpu::BindGroupLayout)> {
    let module = gpu.shader(shader)?;
    let io_layout = gpu
        .device
        .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(shader), entries: io_entries });
    let warp_layout = warp_layout(gpu, wgpu::ShaderStages::COMPUTE);
    let layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(shader),
        bind_group_layouts: &[Some(&io_layout), None, Some(&warp_layout)],
        immediate_size: 0,
    });
    let pipeline = gpu.checked(shader, || {
        gpu.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(shader),
            layout: Some(&layout),
            module: &module,
            entry_point: Some("main"),
            compilation_options: Default::default(),
            cache: None,
        })
    })?;
    Ok((pipeline, io_layout, warp_layout))
}

impl InstanceResolver {
    pub fn new(gpu: &GpuContext) -> anyhow::Result<Self> {
        let (pipeline, io_layout, warp_layout) =
            warp_compute_pipeline(gpu, "attach_resolve.wgsl", &[storage_entry(0, true), storage_entry(1, false)])?;
        Ok(InstanceResolver { pipeline, io_layout, warp_layout })
    }

    /// A new instance buffer with each instance's frame filled in.
    pub fn resolve(
        &self,
        gpu: &GpuContext,
        raw: &wgpu::Buffer,
        draw: &crate::warp::AttachedDraw,
    ) -> anyhow::Result<wgpu::Buffer> {
        let out = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("resolved instances"),
            size: raw.size(),
            usage: wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let io = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("instance resolve io"),
            layout: &self.io_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: raw.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: out.as_entire_binding() },
            ],
        });
        let warp = warp_bind_group(gpu, &self.warp_layout, draw, false);
        let groups = draw.instances.len().div_ceil(64).max(1) as u32;
        let mut enc =
            gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("instance resolve") });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("instance resolve"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &io, &[]);
            pass.set_bind_group(2, &warp, &[]);
            pass.dispatch_workgroups(groups.min(65535), groups.div_ceil(65535), 1);
        }
        gpu.queue.submit([enc.finish()]);
        Ok(out)
    }
}

impl Pipelines {
    fn new(gpu: &GpuContext) -> anyhow::Result<Pipelines> {
        let device = &gpu.device;
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("gbuffer frame"),
            entries: &[uniform_entry(0, wgpu::ShaderStages::VERTEX)],
        });
        let object_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("gbuffer object"),
            entries: &[
                uniform_entry(0, wgpu::ShaderStages::VERTEX_FRAGMENT),
                texture_entry(1, wgpu::ShaderStages::FRAGMENT, true),
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
                texture_entry(3, wgpu::ShaderStages::FRAGMENT, true),
            ],
        });
        let warp_layout = warp_layout(gpu, wgpu::ShaderStages::VERTEX);
        let plain = Self::pipeline(
            gpu,
            "gbuffer.wgsl",
            &[Some(&frame_layout), Some(&object_layout)],
            &[Some(Vertex::layout())],
        )?;
        let attached = Self::pipeline(
            gpu,
            "attach.wgsl",
            &[Some(&frame_layout), Some(&object_layout), Some(&warp_layout)],
            &[Some(Vertex::layout()), Some(InstanceData::layout())],
        )?;
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("base map"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        Ok(Pipelines {
            plain,
            attached,
            frame_layout,
            object_layout,
            warp_layout,
            sampler,
            white: Image8::new(1, 1, vec![255; 4]),
            resolver: InstanceResolver::new(gpu)?,
        })
    }

    fn pipeline(
        gpu: &GpuContext,
        shader: &'static str,
        groups: &[Option<&wgpu::BindGroupLayout>],
        buffers: &[Option<wgpu::VertexBufferLayout<'_>>],
    ) -> anyhow::Result<wgpu::RenderPipeline> {
        let module = gpu.shader(shader)?;
        let layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(shader),
            bind_group_layouts: groups,
            immediate_size: 0,
        });
        let target = |format| Some(wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL });
        gpu.checked(shader, || {
            gpu.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(shader),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_main"),
                    buffers,
                    compilation_options: Default::default(),
                },
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    targets: &[target(COLOR_FORMAT), target(NORMAL_FORMAT), target(DEPTH_FORMAT)],
                    compilation_options: Default::default(),
                }),
                primitive: wgpu::PrimitiveState { cull_mode: None, ..Default::default() },
                depth_stencil: Some(wgpu::DepthStencilState {
                    format: wgpu::TextureFormat::Depth32Float,
                    depth_write_enabled: Some(true),
                    depth_compare: Some(wgpu::CompareFunction::Less),
                    stencil: Default::default(),
                    bias: Default::default(),
                }),
                multisample: Default::default(),
                multiview_mask: None,
                cache: None,
            })
        })
    }

    fn object_bind_group(&self, gpu: &GpuContext, item: &DrawItem) -> wgpu::BindGroup {
        let m = &item.material;
        let uniform = ObjectUniform {
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
        };
        let buf = gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("gbuffer object"),
            contents: bytemuck::bytes_of(&uniform),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let tex = m.texture.as_deref().unwrap_or(&self.white).gpu(gpu);
        let gloss = m.gloss_map.as_deref().unwrap_or(&self.white).gpu(gpu);
        gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("gbuffer object"),
            layout: &self.object_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: buf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&tex.view) },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::Sampler(&self.sampler) },
                wgpu::BindGroupEntry { binding: 3, resource: wgpu::BindingResource::TextureView(&gloss.view) },
            ],
        })
    }
}

/// Renders `items` into a new G-buffer of `w` x `h`. Shared by the node and the benchmarks.
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
    let p = pipelines.as_ref().expect("created above");
    let color = GpuImage::target(gpu, "gbuffer color", w, h, COLOR_FORMAT);
    let normal = GpuImage::target(gpu, "gbuffer normal", w, h, NORMAL_FORMAT);
    let depth = GpuImage::target(gpu, "gbuffer depth", w, h, DEPTH_FORMAT);
    let depth_buffer = GpuImage::target(gpu, "gbuffer depth buffer", w, h, wgpu::TextureFormat::Depth32Float);

    let view = camera.view();
    let view_proj = camera.projection(w as f32 / h as f32) * view;
    let frame_buf = gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some("gbuffer frame"),
        contents: bytemuck::bytes_of(&FrameUniform {
            view_proj: view_proj.to_cols_array_2d(),
            view: view.to_cols_array_2d(),
        }),
        usage: wgpu::BufferUsages::UNIFORM,
    });
    let frame_bg = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
        label: Some("gbuffer frame"),
        layout: &p.frame_layout,
        entries: &[wgpu::BindGroupEntry { binding: 0, resource: frame_buf.as_entire_binding() }],
    });
    let object_bgs: Vec<wgpu::BindGroup> = items.iter().map(|item| p.object_bind_group(gpu, item)).collect();
    let mut warp_bgs: Vec<Option<(wgpu::BindGroup, &wgpu::Buffer)>> = Vec::with_capacity(items.len());
    for item in items {
        warp_bgs.push(match &item.attached {
            Some(a) => {
                let buffer = a.draw_buffer(gpu, |raw| p.resolver.resolve(gpu, raw, a))?;
                Some((warp_bind_group(gpu, &p.warp_layout, a, a.per_instance_frames()), buffer))
            }
            None => None,
        });
    }

    let mut enc = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("gbuffer") });
    {
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
            match (&item.attached, warp_bg) {
                (Some(a), Some((wbg, buffer))) => {
                    if a.instances.is_empty() {
                        continue;
                    }
                    pass.set_pipeline(&p.attached);
                    pass.set_bind_group(2, wbg, &[]);
                    pass.set_vertex_buffer(1, buffer.slice(..));
                    pass.draw_indexed(0..mesh.index_count, 0, 0..a.instances.len() as u32);
                }
                _ => {
                    pass.set_pipeline(&p.plain);
                    pass.draw_indexed(0..mesh.index_count, 0, 0..1);
                }
            }
        }
    }
    gpu.queue.submit([enc.finish()]);
    let errors = gpu.take_errors();
    if !errors.is_empty() {
        anyhow::bail!("GPU error: {}", errors.join("; "));
    }
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

//! The G-buffer pass of the deferred renderer (dissertation section 4.2).

use std::sync::Arc;

use wgpu::util::DeviceExt;

use crate::eval::{EvalCx, Node, NodeError};
use crate::gpu::{GpuContext, GpuImage};
use crate::mesh::Vertex;
use crate::scene::{GBuffer, Image8};
use crate::spec::{Category, NodeSpec, ParamSpec, PortSpec, PortType};
use crate::value::Value;

pub const COLOR_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
pub const NORMAL_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;
pub const DEPTH_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::R32Float;

pub static GBUFFER_PASS: NodeSpec = NodeSpec {
    kind: "GBufferPass",
    category: Category::Render,
    doc: "Rasterizes a scene into the G-buffer: colour + glossiness, normal + coarse/detail flag, linear depth.",
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
}

struct Pipeline {
    pipeline: wgpu::RenderPipeline,
    frame_layout: wgpu::BindGroupLayout,
    object_layout: wgpu::BindGroupLayout,
    sampler: wgpu::Sampler,
    white: Image8,
}

#[derive(Default)]
pub struct GBufferPassNode {
    pipeline: Option<Pipeline>,
}

fn uniform_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
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

impl Pipeline {
    fn new(gpu: &GpuContext) -> anyhow::Result<Pipeline> {
        let shader = gpu.shader("gbuffer.wgsl")?;
        let device = &gpu.device;
        let frame_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("gbuffer frame"),
            entries: &[uniform_entry(0, wgpu::ShaderStages::VERTEX)],
        });
        let object_layout = device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor {
            label: Some("gbuffer object"),
            entries: &[
                uniform_entry(0, wgpu::ShaderStages::VERTEX_FRAGMENT),
                wgpu::BindGroupLayoutEntry {
                    binding: 1,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Texture {
                        sample_type: wgpu::TextureSampleType::Float { filterable: true },
                        view_dimension: wgpu::TextureViewDimension::D2,
                        multisampled: false,
                    },
                    count: None,
                },
                wgpu::BindGroupLayoutEntry {
                    binding: 2,
                    visibility: wgpu::ShaderStages::FRAGMENT,
                    ty: wgpu::BindingType::Sampler(wgpu::SamplerBindingType::Filtering),
                    count: None,
                },
            ],
        });
        let layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some("gbuffer"),
            bind_group_layouts: &[Some(&frame_layout), Some(&object_layout)],
            immediate_size: 0,
        });
        let target = |format| Some(wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL });
        let pipeline = gpu.checked("gbuffer pipeline", || {
            device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some("gbuffer"),
                layout: Some(&layout),
                vertex: wgpu::VertexState {
                    module: &shader,
                    entry_point: Some("vs_main"),
                    buffers: &[Some(Vertex::layout())],
                    compilation_options: Default::default(),
                },
                fragment: Some(wgpu::FragmentState {
                    module: &shader,
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
        })?;
        let sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("base map"),
            address_mode_u: wgpu::AddressMode::Repeat,
            address_mode_v: wgpu::AddressMode::Repeat,
            mag_filter: wgpu::FilterMode::Linear,
            min_filter: wgpu::FilterMode::Linear,
            ..Default::default()
        });
        Ok(Pipeline { pipeline, frame_layout, object_layout, sampler, white: Image8::new(1, 1, vec![255; 4]) })
    }
}

impl Node for GBufferPassNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let Value::Scene(items) = cx.required("scene")? else {
            return Err(NodeError::msg("scene input is not a scene"));
        };
        let Value::Camera(camera) = cx.required("camera")? else {
            return Err(NodeError::msg("camera input is not a camera"));
        };
        let (items, camera) = (items.clone(), *camera);
        if self.pipeline.is_none() {
            self.pipeline = Some(Pipeline::new(gpu)?);
        }
        let p = self.pipeline.as_ref().expect("created above");
        let (w, h) = (cx.settings.width, cx.settings.height);
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
        let object_bgs: Vec<wgpu::BindGroup> = items
            .iter()
            .map(|item| {
                let m = &item.material;
                let uniform = ObjectUniform {
                    model: item.model.to_cols_array_2d(),
                    normal_matrix: item.model.inverse().transpose().to_cols_array_2d(),
                    base_color: [m.base_color.x, m.base_color.y, m.base_color.z, m.glossiness],
                    params: [
                        m.uv_scale,
                        f32::from(u8::from(m.texture.is_some())),
                        f32::from(u8::from(item.detail)),
                        0.0,
                    ],
                };
                let buf = gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("gbuffer object"),
                    contents: bytemuck::bytes_of(&uniform),
                    usage: wgpu::BufferUsages::UNIFORM,
                });
                let tex = m.texture.as_deref().unwrap_or(&p.white).gpu(gpu);
                gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                    label: Some("gbuffer object"),
                    layout: &p.object_layout,
                    entries: &[
                        wgpu::BindGroupEntry { binding: 0, resource: buf.as_entire_binding() },
                        wgpu::BindGroupEntry { binding: 1, resource: wgpu::BindingResource::TextureView(&tex.view) },
                        wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::Sampler(&p.sampler) },
                    ],
                })
            })
            .collect();

        let mut enc = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("gbuffer") });
        {
            let clear = |view| {
                Some(wgpu::RenderPassColorAttachment {
                    view,
                    depth_slice: None,
                    resolve_target: None,
                    ops: wgpu::Operations {
                        load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT),
                        store: wgpu::StoreOp::Store,
                    },
                })
            };
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("gbuffer"),
                color_attachments: &[clear(&color.view), clear(&normal.view), clear(&depth.view)],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_buffer.view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: gpu.pass_timestamps(),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&p.pipeline);
            pass.set_bind_group(0, &frame_bg, &[]);
            for (item, bg) in items.iter().zip(&object_bgs) {
                let mesh = item.mesh.gpu(gpu);
                pass.set_bind_group(1, bg, &[]);
                pass.set_vertex_buffer(0, mesh.vertices.slice(..));
                pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
                pass.draw_indexed(0..mesh.index_count, 0, 0..1);
            }
        }
        gpu.queue.submit([enc.finish()]);
        let errors = gpu.take_errors();
        if !errors.is_empty() {
            return Err(NodeError::msg(format!("GPU error: {}", errors.join("; "))));
        }
        let gbuffer = Arc::new(GBuffer { color, normal, depth, depth_buffer, camera });
        // The per-channel ports share the G-buffer's textures through cheap re-wrapping.
        cx.set("color", Value::Texture(Arc::new(share(gpu, &gbuffer.color))));
        cx.set("normal", Value::Texture(Arc::new(share(gpu, &gbuffer.normal))));
        cx.set("depth", Value::Texture(Arc::new(share(gpu, &gbuffer.depth))));
        cx.set("gbuffer", Value::GBuffer(gbuffer));
        Ok(())
    }
}

/// Another handle to the same texture (wgpu textures are reference counted).
fn share(_gpu: &GpuContext, img: &GpuImage) -> GpuImage {
    GpuImage {
        texture: img.texture.clone(),
        view: img.view.clone(),
        format: img.format,
        width: img.width,
        height: img.height,
    }
}

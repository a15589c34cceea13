//! A full-screen pass: one uniform block plus textures read with `textureLoad`, drawn
//! as a single triangle into one or more targets. Lighting, tone mapping and later screen-space
//! passes are all of this shape.

use wgpu::util::DeviceExt;

use crate::gpu::{GpuContext, GpuImage};

pub struct FullscreenPass {
    pipeline: wgpu::RenderPipeline,
    layout: wgpu::BindGroupLayout,
    name: &'static str,
}

impl FullscreenPass {
    /// `shader` must define `vs_fullscreen` and `fs_main`, with the uniform at binding 0
    /// and `textures` textures at bindings 1.. of group 0.
    pub fn new(
        gpu: &GpuContext,
        shader: &'static str,
        textures: usize,
        targets: &[wgpu::TextureFormat],
    ) -> anyhow::Result<Self> {
        let module = gpu.shader(shader)?;
        let mut entries = vec![wgpu::BindGroupLayoutEntry {
            binding: 0,
            visibility: wgpu::ShaderStages::FRAGMENT,
            ty: wgpu::BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            count: None,
        }];
        for i in 0..textures {
            entries.push(wgpu::BindGroupLayoutEntry {
                binding: 1 + i as u32,
                visibility: wgpu::ShaderStages::FRAGMENT,
                ty: wgpu::BindingType::Texture {
                    sample_type: wgpu::TextureSampleType::Float { filterable: false },
                    view_dimension: wgpu::TextureViewDimension::D2,
                    multisampled: false,
                },
                count: None,
            });
        }
        let layout = gpu
            .device
            .create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(shader), entries: &entries });
        let pipeline_layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(shader),
            bind_group_layouts: &[Some(&layout)],
            immediate_size: 0,
        });
        let color_targets: Vec<Option<wgpu::ColorTargetState>> = targets
            .iter()
            .map(|&format| Some(wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL }))
            .collect();
        let pipeline = gpu.checked(shader, || {
            gpu.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
                label: Some(shader),
                layout: Some(&pipeline_layout),
                vertex: wgpu::VertexState {
                    module: &module,
                    entry_point: Some("vs_fullscreen"),
                    buffers: &[],
                    compilation_options: Default::default(),
                },
                fragment: Some(wgpu::FragmentState {
                    module: &module,
                    entry_point: Some("fs_main"),
                    targets: &color_targets,
                    compilation_options: Default::default(),
                }),
                primitive: Default::default(),
                depth_stencil: None,
                multisample: Default::default(),
                multiview_mask: None,
                cache: None,
            })
        })?;
        Ok(FullscreenPass { pipeline, layout, name: shader })
    }

    pub fn run(
        &self,
        gpu: &GpuContext,
        uniform: &[u8],
        textures: &[&GpuImage],
        target: &GpuImage,
    ) -> anyhow::Result<()> {
        self.run_mrt(gpu, uniform, textures, &[target])
    }

    /// Like `run`, writing several targets (multiple render targets).
    pub fn run_mrt(
        &self,
        gpu: &GpuContext,
        uniform: &[u8],
        textures: &[&GpuImage],
        targets: &[&GpuImage],
    ) -> anyhow::Result<()> {
        let buf = gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some(self.name),
            contents: uniform,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let mut entries = vec![wgpu::BindGroupEntry { binding: 0, resource: buf.as_entire_binding() }];
        for (i, t) in textures.iter().enumerate() {
            entries.push(wgpu::BindGroupEntry {
                binding: 1 + i as u32,
                resource: wgpu::BindingResource::TextureView(&t.view),
            });
        }
        let bind_group = gpu.checked(self.name, || {
            gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some(self.name),
                layout: &self.layout,
                entries: &entries,
            })
        })?;
        let attachments: Vec<_> = targets.iter().map(|t| t.clear_attachment()).collect();
        let mut enc = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some(self.name) });
        {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some(self.name),
                color_attachments: &attachments,
                depth_stencil_attachment: None,
                timestamp_writes: gpu.pass_timestamps(),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.draw(0..3, 0..1);
        }
        gpu.queue.submit([enc.finish()]);
        let errors = gpu.take_errors();
        if !errors.is_empty() {
            anyhow::bail!("{}: {}", self.name, errors.join("; "));
        }
        Ok(())
    }
}

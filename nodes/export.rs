//! Exports warped detail geometry (and plain meshes) as OBJ or PLY, computed by the same
//! warp code as rendering (shaders/warp.wgsl, run as a compute pass): "the geometry can be
//! post-processed or even exported without rendering output" (paper section 6).

use std::sync::Arc;

use anyhow::Context as _;
use glam::Vec3;
use wgpu::util::DeviceExt;

use crate::geometry_io::GeometryFormat;
use crate::gpu::GpuContext;
use crate::mesh::{GpuMesh, Mesh};
use crate::node::prelude::*;
use crate::scene::DrawItem;
use crate::warp::{AttachedDraw, InstanceData, WarpedVertex};

use super::gbuffer::{InstanceResolver, storage_entry, uniform_entry, warp_bind_group, warp_compute_pipeline};

pub static EXPORT_GEOMETRY: NodeSpec = NodeSpec {
    kind: "ExportGeometry",
    category: Category::Output,
    doc: "Writes a scene's geometry, attachments warped on the GPU by the rendering code, as <out>/<node id>_<frame>.obj or .ply; outlier vertices' triangles are left out, as rendering discards them.",
    inputs: &[PortSpec::required("scene", PortType::Scene, "What to export.")],
    outputs: &[PortSpec::output("mesh", PortType::Mesh, "The exported geometry as one mesh.")],
    params: &[
        ParamSpec::new(
            "format",
            ParamKind::Choice { default: "obj", options: GeometryFormat::OPTIONS },
            "File format (PLY is binary little-endian).",
        ),
        ParamSpec::new(
            "frame",
            ParamKind::Int { default: -1, min: -1, max: i64::MAX },
            "Only export at this frame (-1: every frame).",
        ),
    ],
    is_output: true,
    create: || Box::new(ExportNode::default()),
};

#[derive(Default)]
struct ExportNode {
    warper: Option<GpuWarper>,
}

impl Node for ExportNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let items: Arc<Vec<DrawItem>> = cx.input("scene")?;
        let wanted = cx.int("frame");
        // Only a chosen frame makes the node read the time (and re-run every frame).
        let export = wanted < 0 || cx.time().frame == wanted;
        if self.warper.is_none() {
            self.warper = Some(GpuWarper::new(gpu)?);
        }
        let warper = self.warper.as_ref().expect("created above");
        let mesh = Arc::new(flatten(gpu, warper, &items)?);
        if export {
            cx.emit(Product::Geometry { mesh: mesh.clone(), format: cx.choice("format") });
        }
        cx.set("mesh", mesh);
        Ok(())
    }
}

/// The warp as a compute pass.
pub struct GpuWarper {
    pipeline: wgpu::ComputePipeline,
    io_layout: wgpu::BindGroupLayout,
    warp_layout: wgpu::BindGroupLayout,
    resolver: InstanceResolver,
}

impl GpuWarper {
    pub fn new(gpu: &GpuContext) -> anyhow::Result<GpuWarper> {
        let io = [
            storage_entry(0, true),
            storage_entry(1, true),
            storage_entry(2, false),
            uniform_entry(3, wgpu::ShaderStages::COMPUTE),
        ];
        let (pipeline, io_layout, warp_layout) = warp_compute_pipeline(gpu, "attach_export.wgsl", &io)?;
        Ok(GpuWarper { pipeline, io_layout, warp_layout, resolver: InstanceResolver::new(gpu)? })
    }

    /// Warps every instance of `mesh`; the result is instance-major.
    pub fn warp(&self, gpu: &GpuContext, mesh: &Mesh, draw: &AttachedDraw) -> anyhow::Result<Vec<WarpedVertex>> {
        let gm: &GpuMesh = mesh.gpu(gpu);
        let nv = mesh.positions.len();
        let per_instance = (nv * 32) as u64;
        let max_binding = gpu.limits.max_storage_buffer_binding_size.min(gpu.limits.max_buffer_size);
        let chunk = ((max_binding / per_instance.max(1)) as usize).clamp(1, 1 << 20);
        // The same instance data as rendering: point frames resolved once per instance.
        let resolved = draw.per_instance_frames();
        let instances: Vec<InstanceData> = if resolved {
            let buffer = draw.draw_buffer(gpu, |raw| self.resolver.resolve(gpu, raw, draw))?;
            // An empty draw uploads one placeholder instance; keep only the real ones.
            let mut all: Vec<InstanceData> = read_buffer(gpu, buffer)?;
            all.truncate(draw.instances.len());
            all
        } else {
            draw.instances.to_vec()
        };
        let warp_bg = warp_bind_group(gpu, &self.warp_layout, draw, resolved);
        let mut out = Vec::with_capacity(nv * instances.len());
        for insts in instances.chunks(chunk) {
            out.extend(self.warp_chunk(gpu, gm, nv, insts, &warp_bg)?);
        }
        Ok(out)
    }

    fn warp_chunk(
        &self,
        gpu: &GpuContext,
        gm: &GpuMesh,
        nv: usize,
        insts: &[InstanceData],
        warp_bg: &wgpu::BindGroup,
    ) -> anyhow::Result<Vec<WarpedVertex>> {
        let total = nv * insts.len();
        let instances = gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("export instances"),
            contents: bytemuck::cast_slice(insts),
            usage: wgpu::BufferUsages::STORAGE,
        });
        let size = (total * 32) as u64;
        let output = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("export output"),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let read = gpu.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("export read"),
            size,
            usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            mapped_at_creation: false,
        });
        let counts = gpu.device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("export counts"),
            contents: bytemuck::cast_slice(&[nv as u32, insts.len() as u32, 0, 0]),
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let io = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("warp export io"),
            layout: &self.io_layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: gm.vertices.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: instances.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: output.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: counts.as_entire_binding() },
            ],
        });
        let groups = total.div_ceil(64) as u32;
        let mut enc = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("warp export") });
        {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("warp export"),
                timestamp_writes: None,
            });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &io, &[]);
            pass.set_bind_group(2, warp_bg, &[]);
            // The shader folds y into the index in steps of 65535 workgroups.
            pass.dispatch_workgroups(groups.min(65535), groups.div_ceil(65535), 1);
        }
        enc.copy_buffer_to_buffer(&output, 0, &read, 0, size);
        gpu.queue.submit([enc.finish()]);
        let slice = read.slice(..);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        gpu.wait_idle();
        rx.recv().context("read-back was cancelled")?.context("cannot map the export buffer")?;
        let errors = gpu.take_errors();
        if !errors.is_empty() {
            anyhow::bail!("GPU error: {}", errors.join("; "));
        }
        let data = slice.get_mapped_range().map_err(|e| anyhow::anyhow!("{e}"))?;
        let floats: &[f32] = bytemuck::cast_slice(&data);
        let out = floats
            .chunks_exact(8)
            .map(|v| WarpedVertex {
                position: Vec3::new(v[0], v[1], v[2]),
                normal: Vec3::new(v[4], v[5], v[6]),
                valid: v[3] > 0.5,
            })
            .collect();
        drop(data);
        read.unmap();
        Ok(out)
    }
}

/// Copies a GPU buffer of plain-old-data values to the CPU.
fn read_buffer<T: bytemuck::Pod>(gpu: &GpuContext, buffer: &wgpu::Buffer) -> anyhow::Result<Vec<T>> {
    let read = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("read back"),
        size: buffer.size(),
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("read back") });
    enc.copy_buffer_to_buffer(buffer, 0, &read, 0, buffer.size());
    gpu.queue.submit([enc.finish()]);
    map_read(gpu, &read)
}

fn map_read<T: bytemuck::Pod>(gpu: &GpuContext, read: &wgpu::Buffer) -> anyhow::Result<Vec<T>> {
    let slice = read.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    gpu.wait_idle();
    rx.recv().context("read-back was cancelled")?.context("cannot map a read-back buffer")?;
    let errors = gpu.take_errors();
    if !errors.is_empty() {
        anyhow::bail!("GPU error: {}", errors.join("; "));
    }
    let data = slice.get_mapped_range().map_err(|e| anyhow::anyhow!("{e}"))?;
    let out = bytemuck::cast_slice(&data).to_vec();
    drop(data);
    read.unmap();
    Ok(out)
}

/// One mesh of everything the scene draws: plain items transformed by their model matrix,
/// attached items warped per instance; triangles touching an outlier vertex are left out.
pub fn flatten(gpu: &GpuContext, warper: &GpuWarper, items: &[DrawItem]) -> anyhow::Result<Mesh> {
    let (mut positions, mut normals, mut uvs, mut indices) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for item in items {
        let m = &item.mesh;
        match &item.attached {
            None => {
                let base = positions.len() as u32;
                let nm = item.model.inverse().transpose();
                positions.extend(m.positions.iter().map(|p| item.model.transform_point3(*p)));
                normals.extend(m.normals.iter().map(|n| nm.transform_vector3(*n).normalize_or_zero()));
                uvs.extend_from_slice(&m.uvs);
                indices.extend(m.indices.iter().map(|i| i + base));
            }
            Some(a) => {
                let warped = warper.warp(gpu, m, a)?;
                let nv = m.positions.len();
                for inst in warped.chunks(nv) {
                    let base = positions.len() as u32;
                    positions.extend(inst.iter().map(|w| w.position));
                    normals.extend(inst.iter().map(|w| w.normal));
                    uvs.extend_from_slice(&m.uvs);
                    for t in m.indices.chunks_exact(3) {
                        if t.iter().all(|&i| inst[i as usize].valid) {
                            indices.extend(t.iter().map(|i| i + base));
                        }
                    }
                }
            }
        }
    }
    if indices.is_empty() {
        anyhow::bail!("nothing to export: the scene has no visible triangles");
    }
    Mesh::build(positions, Some(uvs), Some(normals), indices)
}

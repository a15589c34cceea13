//! Exports warped detail geometry (and plain meshes) as OBJ or PLY, computed by the same
//! warp code as rendering (shaders/warp.wgsl, run as a compute pass): "the geometry can be
//! post-processed or even exported without rendering output" (paper section 6).

use std::sync::Arc;

use glam::Vec3;

use crate::geometry_io::GeometryFormat;
use crate::gpu::readback::read_buffer_range;
use crate::gpu::{Bind, BufferRing, ComputePass, GpuContext, read_buffer};
use crate::mesh::{GpuMesh, Mesh};
use crate::node::prelude::*;
use crate::scene::DrawItem;
use crate::warp::{AttachedDraw, InstanceData, WarpedVertex};

use crate::draw::{InstanceResolver, warp_binds};

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
    warper: GpuWarper,
    /// The last export, the `mesh` output on frames a fixed-frame export skips.
    last: Option<Arc<Mesh>>,
}

impl Node for ExportNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let items: Arc<Vec<DrawItem>> = cx.input("scene")?;
        let wanted = cx.int("frame");
        // Only a chosen frame makes the node read the time (and re-run every frame).
        let export = wanted < 0 || cx.time().frame == wanted;
        // A fixed-frame export skips the warp on other frames (the batch runner warns when
        // its frame is outside the rendered range); `mesh` is then the last export, or the
        // scene of this frame before the first one.
        let mesh = match &self.last {
            Some(last) if !export => last.clone(),
            _ => Arc::new(flatten(gpu, &mut self.warper, &items)?),
        };
        if export {
            cx.count("triangles", mesh.triangle_count());
            cx.emit(Product::Geometry { mesh: mesh.clone(), format: cx.choice("format") });
            self.last = Some(mesh.clone());
        }
        cx.set("mesh", mesh);
        Ok(())
    }
}

/// The warp as a compute pass.
pub struct GpuWarper {
    pass: ComputePass,
    resolver: InstanceResolver,
    /// Per-chunk instances and counts, written each run.
    instances: BufferRing,
    /// The warped vertices, grown as needed.
    output: Option<wgpu::Buffer>,
}

impl Default for GpuWarper {
    fn default() -> Self {
        GpuWarper {
            pass: ComputePass::new("attach_export.wgsl", "main"),
            resolver: InstanceResolver::default(),
            instances: BufferRing::new("export instances", wgpu::BufferUsages::STORAGE),
            output: None,
        }
    }
}

impl GpuWarper {
    /// Warps every instance of `mesh`; the result is instance-major.
    pub fn warp(&mut self, gpu: &GpuContext, mesh: &Mesh, draw: &AttachedDraw) -> anyhow::Result<Vec<WarpedVertex>> {
        let nv = mesh.positions.len();
        let per_instance = (nv * 32) as u64;
        let max_binding = gpu.limits.max_storage_buffer_binding_size.min(gpu.limits.max_buffer_size);
        let chunk = ((max_binding / per_instance.max(1)) as usize).clamp(1, 1 << 20);
        // The same instance data as rendering: point frames resolved once per instance.
        let resolved = draw.per_instance_frames();
        let instances: Vec<InstanceData> = if resolved {
            let resolver = &mut self.resolver;
            let buffer = draw.draw_buffer(gpu, |raw| resolver.resolve(gpu, raw, draw))?;
            // An empty draw uploads one placeholder instance; keep only the real ones.
            let mut all: Vec<InstanceData> = read_buffer(gpu, buffer)?;
            all.truncate(draw.instances.len());
            all
        } else {
            draw.instances.to_vec()
        };
        let uniform = draw.settings.uniform(resolved);
        let mut out = Vec::with_capacity(nv * instances.len());
        for insts in instances.chunks(chunk) {
            out.extend(self.warp_chunk(gpu, mesh, insts, &warp_binds(&draw.matrix, &uniform))?);
        }
        Ok(out)
    }

    fn warp_chunk(
        &mut self,
        gpu: &GpuContext,
        mesh: &Mesh,
        insts: &[InstanceData],
        warp: &[Bind<'_>],
    ) -> anyhow::Result<Vec<WarpedVertex>> {
        let gm: &GpuMesh = mesh.gpu(gpu);
        let nv = mesh.positions.len();
        let total = nv * insts.len();
        let size = (total * 32) as u64;
        if self.output.as_ref().is_none_or(|b| b.size() < size) {
            let usage = wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC;
            self.output = Some(gpu.create_buffer("export output", size.next_power_of_two(), usage));
        }
        let output = self.output.as_ref().expect("made above");
        let instances = self.instances.write(gpu, bytemuck::cast_slice(insts)).clone();
        let counts = [nv as u32, insts.len() as u32, 0, 0];
        let io = [
            Bind::Storage(&gm.vertices),
            Bind::Storage(&instances),
            Bind::StorageRw(output),
            Bind::Uniform(bytemuck::cast_slice(&counts)),
        ];
        self.pass.dispatch(gpu, &[&io, &[], warp], ComputePass::groups_for(total, 64))?;
        let floats: Vec<f32> = read_buffer_range(gpu, output, size)?;
        Ok(floats
            .chunks_exact(8)
            .map(|v| WarpedVertex {
                position: Vec3::new(v[0], v[1], v[2]),
                normal: Vec3::new(v[4], v[5], v[6]),
                valid: v[3] > 0.5,
            })
            .collect())
    }
}

/// One mesh of everything the scene draws: plain items transformed by their model matrix,
/// attached items warped per instance; triangles touching an outlier vertex are left out.
pub fn flatten(gpu: &GpuContext, warper: &mut GpuWarper, items: &[DrawItem]) -> anyhow::Result<Mesh> {
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

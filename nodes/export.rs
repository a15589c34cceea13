//! Exports warped detail geometry (and plain meshes) as OBJ or PLY, computed by the same
//! warp code as rendering (shaders/warp.wgsl, run as a compute pass): "the geometry can be
//! post-processed or even exported without rendering output" (paper section 6).

use std::io::Write as _;
use std::path::Path;
use std::sync::Arc;

use anyhow::Context as _;
use glam::Vec3;

use crate::eval::{EvalCx, Node, NodeError};
use crate::gpu::readback::read_buffer_range;
use crate::gpu::{Bind, BufferRing, ComputePass, GpuContext, read_buffer};
use crate::mesh::{GpuMesh, Mesh};
use crate::scene::DrawItem;
use crate::spec::{Category, NodeSpec, ParamKind, ParamSpec, PortSpec, PortType};
use crate::value::Value;
use crate::warp::{AttachedDraw, InstanceData, WarpedVertex};

use super::gbuffer::{InstanceResolver, warp_binds};

pub static EXPORT_GEOMETRY: NodeSpec = NodeSpec {
    kind: "ExportGeometry",
    category: Category::Output,
    doc: "Writes a scene's geometry, attachments warped on the GPU by the rendering code, as <out>/<node id>_<frame>.obj or .ply; outlier vertices' triangles are left out, as rendering discards them.",
    inputs: &[PortSpec::required("scene", PortType::Scene, "What to export.")],
    outputs: &[PortSpec::output("mesh", PortType::Mesh, "The exported geometry as one mesh.")],
    params: &[
        ParamSpec::new(
            "format",
            ParamKind::Choice { default: "obj", options: &["obj", "ply"] },
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
        let Value::Scene(items) = cx.required("scene")? else {
            return Err(NodeError::msg("scene input is not a scene"));
        };
        let items = items.clone();
        let wanted = cx.int("frame");
        // Only a batch render writes files, and only then does the frame matter: while editing
        // the node does not read the time, so it does not re-run every frame.
        let frame = if cx.settings.out_dir.is_some() { cx.time().frame } else { 0 };
        if self.warper.is_none() {
            self.warper = Some(GpuWarper::new(gpu)?);
        }
        let warper = self.warper.as_mut().expect("created above");
        let mesh = Arc::new(flatten(gpu, warper, &items)?);
        if (wanted < 0 || wanted == frame)
            && let Some(dir) = &cx.settings.out_dir
        {
            let ext = cx.str("format").to_string();
            let path = dir.join(format!("{}_{frame:04}.{ext}", cx.node_id));
            if ext == "ply" { write_ply(&path, &mesh) } else { write_obj(&path, &mesh) }
                .map_err(|e| NodeError::msg(format!("{e:#}")))?;
        }
        cx.set("mesh", Value::Mesh(mesh));
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

impl GpuWarper {
    pub fn new(gpu: &GpuContext) -> anyhow::Result<GpuWarper> {
        Ok(GpuWarper {
            pass: ComputePass::new("attach_export.wgsl", "main"),
            resolver: InstanceResolver::new(gpu)?,
            instances: BufferRing::new("export instances", wgpu::BufferUsages::STORAGE),
            output: None,
        })
    }

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

pub fn write_obj(path: &Path, mesh: &Mesh) -> anyhow::Result<()> {
    let mut out = std::io::BufWriter::new(Vec::new());
    writeln!(out, "# werkstatt export: {} vertices, {} triangles", mesh.positions.len(), mesh.triangle_count())?;
    for p in &mesh.positions {
        writeln!(out, "v {} {} {}", p.x, p.y, p.z)?;
    }
    for t in &mesh.uvs {
        // OBJ's v points up.
        writeln!(out, "vt {} {}", t.x, 1.0 - t.y)?;
    }
    for n in &mesh.normals {
        writeln!(out, "vn {} {} {}", n.x, n.y, n.z)?;
    }
    for t in mesh.indices.chunks_exact(3) {
        let [a, b, c] = [t[0] + 1, t[1] + 1, t[2] + 1];
        writeln!(out, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")?;
    }
    let bytes = out.into_inner().map_err(|e| anyhow::anyhow!("{e}"))?;
    crate::graph::write_atomic(path, &bytes).with_context(|| format!("cannot write {}", path.display()))
}

pub fn write_ply(path: &Path, mesh: &Mesh) -> anyhow::Result<()> {
    let mut out = Vec::new();
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment werkstatt export\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float s\nproperty float t\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangle_count()
    )?;
    for i in 0..mesh.positions.len() {
        for f in mesh.positions[i]
            .to_array()
            .into_iter()
            .chain(mesh.normals[i].to_array())
            .chain([mesh.uvs[i].x, 1.0 - mesh.uvs[i].y])
        {
            out.extend_from_slice(&f.to_le_bytes());
        }
    }
    for t in mesh.indices.chunks_exact(3) {
        out.push(3);
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    crate::graph::write_atomic(path, &out).with_context(|| format!("cannot write {}", path.display()))
}

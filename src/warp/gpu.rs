//! The warp on the GPU outside the draw: point attachments' frames resolved once per instance,
//! and the warp as a compute pass (with its threaded CPU twin) for exports, "the geometry can
//! be post-processed or even exported without rendering output" (paper section 6).

use glam::{Vec2, Vec3};

use crate::gpu::pass::{texture_entry, uniform_entry};
use crate::gpu::readback::read_buffer_with;
use crate::gpu::{Bind, BufferRing, ComputePass, GpuContext, PooledBuffer, read_back, read_buffer};
use crate::mesh::{GpuMesh, Mesh, has_area};

use super::{
    AttachedDraw, InstanceData, MatrixTexels, MatrixTexture, TexelFrame, WarpUniform, WarpedLayout, WarpedVertex,
};

/// Group 2 of shaders/warp/warp.wgsl: the matrix texture's three columns, the warp settings
/// (`uniform`, from `WarpSettings::uniform`) and the seam map.
pub fn warp_binds<'a>(m: &'a MatrixTexture, uniform: &'a WarpUniform) -> [Bind<'a>; 5] {
    [
        Bind::Texture(&m.col_u),
        Bind::Texture(&m.col_n),
        Bind::Texture(&m.col_v),
        Bind::Uniform(bytemuck::bytes_of(uniform)),
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

/// Looks up point attachments' frames once per instance (shaders/warp/attach_resolve.wgsl).
pub struct InstanceResolver {
    pass: ComputePass,
}

impl Default for InstanceResolver {
    fn default() -> Self {
        InstanceResolver { pass: ComputePass::new("attach_resolve.wgsl", "main") }
    }
}

impl InstanceResolver {
    /// A new instance buffer with each instance's frame filled in.
    pub fn resolve(
        &mut self,
        gpu: &GpuContext,
        raw: &wgpu::Buffer,
        draw: &AttachedDraw,
    ) -> anyhow::Result<PooledBuffer> {
        let out = gpu.scratch_pooled(
            "resolved instances",
            raw.size(),
            wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let uniform = draw.settings.uniform();
        let warp = warp_binds(&draw.matrix, &uniform);
        let io = [Bind::Storage(raw), Bind::StorageRw(&out)];
        let groups = ComputePass::groups_for(draw.instances.len(), 64);
        self.pass.dispatch_specialized(gpu, &[&io, &[], &warp], groups, &draw.settings.constants(false))?;
        Ok(out)
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

crate::choice!(
    /// Where `ExportGeometry` warps attachments.
    pub enum WarpDevice {
        Auto = "auto",
        Gpu = "gpu",
        Cpu = "cpu",
    }
);

impl WarpDevice {
    /// `Auto` made concrete: on a CPU adapter (lavapipe, llvmpipe) the compute shader runs on
    /// the same cores as the threaded CPU twin, which `werkstatt bench export` measured
    /// faster there; on a real GPU the compute pass.
    pub fn resolve(self, gpu: &GpuContext) -> WarpDevice {
        match self {
            WarpDevice::Auto if gpu.info.device_type == wgpu::DeviceType::Cpu => WarpDevice::Cpu,
            WarpDevice::Auto => WarpDevice::Gpu,
            concrete => concrete,
        }
    }
}

/// The mesh of warped instances of `mesh`: vertices as warped, each instance's UVs, and its
/// triangles except those touching an outlier vertex. No tangents (an exported mesh is drawn
/// or written, not parametrized again). Instances are split over the CPU's threads; each
/// chunk writes its kept triangles at the start of its own region, which are then moved
/// together.
pub fn assemble(mesh: &Mesh, warped: WarpedLayout) -> anyhow::Result<Mesh> {
    let nv = mesh.positions.len();
    let n = warped.positions.len();
    anyhow::ensure!(nv > 0 && n.is_multiple_of(nv), "{n} warped vertices are not whole instances of {nv}");
    let per_instance = mesh.indices.len();
    if per_instance == 0 {
        return Ok(Mesh::from_raw(
            warped.positions,
            warped.normals,
            vec![Vec2::ZERO; n],
            Vec::new(),
            Vec::new(),
            Vec::new(),
        ));
    }
    let chunk = super::instances_per_thread(n / nv);
    // A mesh without one UV per vertex exports zeros.
    let instance_uvs = if mesh.uvs.len() == nv { mesh.uvs.clone() } else { vec![Vec2::ZERO; nv] };
    let mut indices = vec![0u32; per_instance * (n / nv)];
    let mut uvs: Vec<Vec2> = bytemuck::zeroed_vec(n);
    let (positions, valid, instance_uvs) = (&warped.positions, &warped.valid, &instance_uvs);
    let kept: Vec<usize> = std::thread::scope(|scope| {
        let threads: Vec<_> = indices
            .chunks_mut(chunk * per_instance)
            .zip(uvs.chunks_mut(chunk * nv))
            .enumerate()
            .map(|(c, (region, uvs))| {
                scope.spawn(move || {
                    let mut kept = 0;
                    for (k, uvs) in uvs.chunks_mut(nv).enumerate() {
                        uvs.copy_from_slice(instance_uvs);
                        let first = (c * chunk + k) * nv;
                        let (valid, positions) = (&valid[first..first + nv], &positions[first..first + nv]);
                        for t in mesh.indices.chunks_exact(3) {
                            let local = [t[0], t[1], t[2]];
                            if local.iter().all(|&i| valid[i as usize]) && has_area(positions, local) {
                                let base = first as u32;
                                region[kept..kept + 3].copy_from_slice(&[
                                    local[0] + base,
                                    local[1] + base,
                                    local[2] + base,
                                ]);
                                kept += 3;
                            }
                        }
                    }
                    kept
                })
            })
            .collect();
        threads.into_iter().map(|t| t.join().unwrap_or_else(|e| std::panic::resume_unwind(e))).collect()
    });
    let mut end = 0;
    for (c, count) in kept.into_iter().enumerate() {
        let start = c * chunk * per_instance;
        indices.copy_within(start..start + count, end);
        end += count;
    }
    indices.truncate(end);
    Ok(Mesh::from_raw(warped.positions, warped.normals, uvs, Vec::new(), Vec::new(), indices))
}

impl GpuWarper {
    /// Warps every instance of `mesh`; the result is instance-major.
    pub fn warp(&mut self, gpu: &GpuContext, mesh: &Mesh, draw: &AttachedDraw) -> anyhow::Result<Vec<WarpedVertex>> {
        Ok(self.warp_layout(gpu, mesh, draw)?.vertices())
    }

    /// Warps every instance of `mesh` into the exported layout on `device`: the compute pass,
    /// or the CPU twin on the matrix texture read back (the same geometry).
    pub fn warp_layout_on(
        &mut self,
        gpu: &GpuContext,
        mesh: &Mesh,
        draw: &AttachedDraw,
        device: WarpDevice,
    ) -> anyhow::Result<WarpedLayout> {
        if device.resolve(gpu) == WarpDevice::Cpu {
            let texels = read_matrix(gpu, &draw.matrix)?;
            return Ok(super::warp_layout_cpu(&texels, &draw.settings, mesh, &draw.instances));
        }
        self.warp_layout(gpu, mesh, draw)
    }

    /// Warps every instance of `mesh` with the compute pass straight into the exported
    /// layout (instance-major).
    pub fn warp_layout(&mut self, gpu: &GpuContext, mesh: &Mesh, draw: &AttachedDraw) -> anyhow::Result<WarpedLayout> {
        let nv = mesh.positions.len();
        let per_instance = (nv * 28) as u64;
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
        let uniform = draw.settings.uniform();
        let constants = draw.settings.constants(resolved);
        let mut out = WarpedLayout::with_len(nv * instances.len());
        for (c, insts) in instances.chunks(chunk).enumerate() {
            let start = c * chunk * nv;
            let warp = warp_binds(&draw.matrix, &uniform);
            self.warp_chunk(gpu, mesh, insts, (&warp, &constants), &mut out, start)?;
        }
        Ok(out)
    }

    fn warp_chunk(
        &mut self,
        gpu: &GpuContext,
        mesh: &Mesh,
        insts: &[InstanceData],
        (warp, constants): (&[Bind<'_>], &[(&str, u32)]),
        out: &mut WarpedLayout,
        start: usize,
    ) -> anyhow::Result<()> {
        let gm: &GpuMesh = mesh.gpu(gpu);
        let nv = mesh.positions.len();
        let total = nv * insts.len();
        let size = (total * 28) as u64;
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
        self.pass.dispatch_specialized(gpu, &[&io, &[], warp], ComputePass::groups_for(total, 64), constants)?;
        let range = start..start + total;
        read_buffer_with(gpu, output, size, |bytes| {
            let (p, rest) = bytes.split_at(total * 12);
            let (n, v) = rest.split_at(total * 12);
            bytemuck::cast_slice_mut::<Vec3, u8>(&mut out.positions[range.clone()]).copy_from_slice(p);
            bytemuck::cast_slice_mut::<Vec3, u8>(&mut out.normals[range.clone()]).copy_from_slice(n);
            for (slot, f) in out.valid[range].iter_mut().zip(v.chunks_exact(4)) {
                *slot = f32::from_le_bytes([f[0], f[1], f[2], f[3]]) > 0.5;
            }
        })
    }
}

/// Copies a matrix texture to the CPU.
pub fn read_matrix(gpu: &GpuContext, m: &MatrixTexture) -> anyhow::Result<MatrixTexels> {
    let (u, n, v) = (read_back(gpu, &m.col_u)?, read_back(gpu, &m.col_n)?, read_back(gpu, &m.col_v)?);
    let v3 = |px: &[f32], i: usize| glam::Vec3::new(px[4 * i], px[4 * i + 1], px[4 * i + 2]);
    let frames = (0..(m.resolution * m.resolution) as usize)
        .map(|i| TexelFrame {
            tu: v3(&u.rgba, i),
            n: v3(&n.rgba, i),
            tv: v3(&v.rgba, i),
            p: glam::Vec3::new(u.rgba[4 * i + 3], n.rgba[4 * i + 3], v.rgba[4 * i + 3]),
        })
        .collect();
    let seams = read_back(gpu, &m.seams)?.rgba.chunks_exact(4).map(|c| [c[0], c[1], c[2], c[3]]).collect();
    Ok(MatrixTexels { resolution: m.resolution, frames, seams })
}

#[cfg(test)]
mod tests {
    use glam::{Vec2, Vec3};

    use super::assemble;
    use crate::mesh::Mesh;
    use crate::warp::WarpedLayout;

    /// Five instances of a quad (split over threads where there are several): an outlier
    /// vertex drops the triangles touching it, a collapsed instance drops all, and the kept
    /// triangles of later instances move down in order with their own vertex numbers.
    #[test]
    fn assembly_drops_outliers_and_collapsed_triangles_in_instance_order() {
        let quad = [Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, 1.0), Vec3::Z];
        let uvs = vec![Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y];
        let mesh = Mesh::from_raw(quad.to_vec(), vec![Vec3::Y; 4], uvs.clone(), vec![], vec![], vec![0, 1, 2, 0, 2, 3]);
        let mut warped = WarpedLayout::with_len(20);
        for k in 0..5 {
            for (v, p) in quad.iter().enumerate() {
                let collapsed = k == 3;
                warped.positions[4 * k + v] = if collapsed { Vec3::ONE } else { *p + Vec3::Y * k as f32 };
                warped.valid[4 * k + v] = !(k == 1 && v == 3);
            }
        }
        let out = assemble(&mesh, warped).unwrap();
        assert_eq!(out.indices, [0, 1, 2, 0, 2, 3, 4, 5, 6, 8, 9, 10, 8, 10, 11, 16, 17, 18, 16, 18, 19]);
        assert_eq!(out.uvs, uvs.repeat(5));
    }
}

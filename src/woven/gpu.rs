//! The woven tessellation in compute (`shaders/tessellation/woven.wgsl`, the twin of [`super::tess`]):
//! the CPU plans the frame, per patch only (its level, its neighbours' levels for the edge
//! states, whether it is culled, where its vertices and indices go), and the GPU evaluates every
//! vertex and index of the panel, weft and warp layers; each layer is drawn with indirect
//! arguments like `Tessellate`'s output. The vertex order is the CPU's, so the two compare
//! vertex for vertex.

use glam::{DMat4, DVec3, DVec4};

use super::lod::{LodState, Morph, Scale, along_points, level_from_distance};
use super::panel::{Panel, bernstein};
use super::tess::Woven;
use crate::gpu::{Bind, ComputePass, GpuContext, PooledBuffer};
use crate::mesh::Vertex;

/// Bytes of one `DrawIndexedIndirectArgs`.
const INDIRECT_BYTES: usize = 20;

/// Vertices and indices one patch adds to its layer(s) at level `l`: the panel layer, or the
/// weft and the warp layers (each that many).
pub fn patch_counts(w: &Woven<'_>, l: f64) -> (Scale, usize, usize) {
    let st = LodState::at(l, Morph::Continuous);
    match st.scale {
        Scale::Panel => {
            let g = st.panel_res();
            (Scale::Panel, (g + 1) * (g + 1), 6 * g * g)
        }
        scale => {
            let (sa, sr) = LodState::tube_res(st.grid);
            let rings = along_points(sa, w.yarn.nodes).len();
            let blocks = w.yarn.nodes * if scale == Scale::Fibre { w.yarn.fibres } else { 1 };
            (scale, blocks * rings * sr, blocks * (rings - 1) * sr * 6)
        }
    }
}

/// Each patch's level: `fixed`, or eq. 16 from the eye (patch size c: its diagonal over √2,
/// distance from its centre); `None` outside the pattern piece.
pub fn patch_levels(panel: &Panel, inside: &[bool], fixed: Option<f64>, coef: f64, eye: DVec3) -> Vec<Option<f64>> {
    (0..panel.patches_v)
        .flat_map(|pj| (0..panel.patches_u).map(move |pi| (pi, pj)))
        .zip(inside)
        .map(|((pi, pj), &inside)| {
            inside.then(|| {
                fixed.unwrap_or_else(|| {
                    let c = panel.position(pi, pj, 0.0, 0.0).distance(panel.position(pi, pj, 1.0, 1.0))
                        / std::f64::consts::SQRT_2;
                    level_from_distance(c, coef, panel.position(pi, pj, 0.5, 0.5).distance(eye))
                })
            })
        })
        .collect()
}

/// [`patch_culled`] for every patch (none without a view).
pub fn culled_patches(w: &Woven<'_>, view_proj: Option<&DMat4>) -> Vec<bool> {
    let pu = w.panel.patches_u;
    (0..pu * w.panel.patches_v).map(|k| view_proj.is_some_and(|vp| patch_culled(w, k % pu, k / pu, vp))).collect()
}

/// Whether the sphere around patch (pi, pj) (its Bézier points, grown by the yarns' reach) lies
/// wholly outside one plane of the frustum of `view_proj`.
pub fn patch_culled(w: &Woven<'_>, pi: usize, pj: usize, view_proj: &DMat4) -> bool {
    let q = &w.panel.patch(pi, pj).q;
    let points = q.iter().flatten();
    let centre = points.clone().copied().sum::<DVec3>() / 16.0;
    let reach = w.yarn.crimp + w.yarn.radius;
    let radius = points.map(|p| p.distance(centre)).fold(0.0, f64::max) + reach;
    let m = view_proj.transpose();
    let (r0, r1, r2, r3) = (m.x_axis, m.y_axis, m.z_axis, m.w_axis);
    // Gribb-Hartmann planes; wgpu's clip z is [0, w].
    let planes = [r3 + r0, r3 - r0, r3 + r1, r3 - r1, r2, r3 - r2];
    planes.iter().any(|p: &DVec4| {
        let n = p.truncate();
        let len = n.length();
        len > 0.0 && (n.dot(centre) + p.w) / len < -radius
    })
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    patches_u: u32,
    patches_v: u32,
    nodes: u32,
    fibres: u32,
    weave_w: u32,
    weave_h: u32,
    flip: u32,
    spacing: f32,
    crimp: f32,
    radius: f32,
    fibre_radius: f32,
    ring_radius: f32,
    migration: f32,
    omega: f32,
    /// The tube layer's yarns: 0 weft, 1 warp.
    dir: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
struct Plan {
    /// Patch, first vertex, first index, vertices.
    ids: [u32; 4],
    /// Level, indices (as bits), unused.
    level: [f32; 4],
    /// Levels of the left, right, bottom and top neighbours; negative: none.
    edges: [f32; 4],
}

/// One layer's buffers: written by the compute pass, drawn with `indirect`.
pub struct GpuLayer {
    pub vertices: PooledBuffer,
    pub indices: PooledBuffer,
    pub indirect: PooledBuffer,
    pub vertex_count: u64,
    pub index_count: u64,
}

impl std::fmt::Debug for GpuLayer {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "GpuLayer({} vertices, {} indices)", self.vertex_count, self.index_count)
    }
}

impl GpuLayer {
    /// The vertices and indices the compute pass wrote.
    pub fn read_back(&self, gpu: &GpuContext) -> anyhow::Result<(Vec<Vertex>, Vec<u32>)> {
        use crate::gpu::readback::read_buffer_range;
        let vertices =
            read_buffer_range(gpu, &self.vertices, self.vertex_count * std::mem::size_of::<Vertex>() as u64)?;
        let indices = read_buffer_range(gpu, &self.indices, self.index_count * 4)?;
        Ok((vertices, indices))
    }

    /// The same as a mesh: positions, normals, UVs and the triangles.
    pub fn read_back_mesh(&self, gpu: &GpuContext) -> anyhow::Result<crate::mesh::Mesh> {
        let (vertices, indices) = self.read_back(gpu)?;
        Ok(crate::mesh::Mesh::from_raw(
            vertices.iter().map(|v| v.position.into()).collect(),
            vertices.iter().map(|v| v.normal.into()).collect(),
            vertices.iter().map(|v| v.uv.into()).collect(),
            Vec::new(),
            Vec::new(),
            indices,
        ))
    }
}

/// A frame's woven layers on the GPU (panel, weft, warp; `None` where a layer is empty), the
/// patches per scale and the patches culled.
#[derive(Debug, Default)]
pub struct GpuWovenFrame {
    pub layers: [Option<GpuLayer>; 3],
    pub scales: [usize; 3],
    pub culled: usize,
}

/// The compute passes of `woven.wgsl`, kept between frames.
pub struct GpuWoven {
    /// Vertices and indices of the panel layer, then of the tube layers.
    passes: [[ComputePass; 2]; 2],
}

impl Default for GpuWoven {
    fn default() -> Self {
        let pass = |entry| ComputePass::new("woven.wgsl", entry);
        GpuWoven {
            passes: [[pass("panel_vertices"), pass("panel_indices")], [pass("tube_vertices"), pass("tube_indices")]],
        }
    }
}

/// Quads an index pass's workgroup row handles per patch before another row is added: 64
/// invocations, 16 each. The vertex passes take one vertex (panel) or ring (tubes) an
/// invocation, 64 a row: on lavapipe a loop runs its body once more than it iterates, masked.
const QUADS_PER_ROW: usize = 64 * 16;
const VERTICES_PER_ROW: usize = 64;

/// The lowest level whose tubes morph toward a coarser tube grid (and the fibre scale lies
/// above it): the ring pass of the patches under it is compiled without either.
const MORPH_LEVEL: f32 = 6.0;

/// Each patch's 9 x 9 lattice, the patch at (a / 8, b / 8) at 81 p + 9 b + a: the corners of
/// every bilinear panel grid the morphs blend toward (eq. 18 with 1, 2, 4 or 8 cells a side).
/// Only the patches with `drawn` set are evaluated (the shader reads a drawn patch's own).
fn lattice(panel: &Panel, drawn: &[bool]) -> Vec<[f32; 4]> {
    let weights: [[f64; 4]; 9] = std::array::from_fn(|k| bernstein(k as f64 / 8.0));
    let mut out = vec![[0.0; 4]; 81 * panel.patches.len()];
    for (patch, points) in
        panel.patches.iter().zip(out.chunks_exact_mut(81)).zip(drawn).filter(|(_, d)| **d).map(|(x, _)| x)
    {
        // The patch's columns of Bézier points combined along t at each lattice row, then
        // across: 36 + 81 four-term sums instead of 81 sixteen-term ones.
        let rows: [[DVec3; 4]; 9] =
            std::array::from_fn(|b| std::array::from_fn(|i| (0..4).map(|j| weights[b][j] * patch.q[i][j]).sum()));
        for (k, point) in points.iter_mut().enumerate() {
            let (wa, row) = (&weights[k % 9], &rows[k / 9]);
            let p: DVec3 = (0..4).map(|i| wa[i] * row[i]).sum();
            *point = p.as_vec3().extend(1.0).to_array();
        }
    }
    out
}

impl GpuWoven {
    /// Records the tessellation of `w` with `levels` (as [`Woven::tessellate`] with the levels
    /// rounded to f32) into the current frame; patches with `culled[k]` set are not drawn but keep their level for their
    /// neighbours' edges. Nothing is read back.
    pub fn run(
        &mut self,
        gpu: &GpuContext,
        w: &Woven<'_>,
        levels: &[Option<f64>],
        culled: &[bool],
    ) -> anyhow::Result<GpuWovenFrame> {
        use wgpu::BufferUsages as U;
        anyhow::ensure!(w.morph == Morph::Continuous, "the GPU evaluates the continuous morph only");
        let (pu, pv) = (w.panel.patches_u, w.panel.patches_v);
        w.check_levels(levels, culled)?;
        let level_at = |i: isize, j: isize| w.neighbour(levels, i, j).map_or(-1.0, |l| l as f32);
        // Plans of the panel layer and of the tube layers (weft and warp share theirs).
        let mut plans: [Vec<Plan>; 2] = Default::default();
        let mut totals = [[0usize; 2]; 2];
        // The largest patch of each layer in the items of its vertex pass (vertices of the
        // panel, rings of the tubes) and of its index pass (quads).
        let mut largest = [[0usize; 2]; 2];
        // The most rings of a tube patch under MORPH_LEVEL and of one at or above it.
        let mut largest_rings = [0usize; 2];
        let mut out = GpuWovenFrame::default();
        anyhow::ensure!(pu * pv <= 65535, "{pu}x{pv} patches are more than one dispatch holds (65535)");
        for pj in 0..pv {
            for pi in 0..pu {
                let k = pj * pu + pi;
                let Some(l) = levels[k] else { continue };
                // The shader sees the level in f32: plan with that one, or a level just under an
                // integer (3.9999999999) would be planned at one scale and drawn at the next.
                let l = f64::from(l as f32);
                if culled[k] {
                    out.culled += 1;
                    continue;
                }
                let (scale, nv, ni) = patch_counts(w, l);
                let layer = usize::from(scale != Scale::Panel);
                out.scales[scale as usize] += 1;
                let (i, j) = (pi as isize, pj as isize);
                plans[layer].push(Plan {
                    ids: [k as u32, totals[layer][0] as u32, totals[layer][1] as u32, nv as u32],
                    level: [l as f32, f32::from_bits(ni as u32), 0.0, 0.0],
                    edges: [level_at(i - 1, j), level_at(i + 1, j), level_at(i, j - 1), level_at(i, j + 1)],
                });
                totals[layer][0] += nv;
                totals[layer][1] += ni;
                let items = match scale {
                    Scale::Panel => nv,
                    _ => {
                        let rings = nv / LodState::tube_res(LodState::at(l, Morph::Continuous).grid).1;
                        let fine = usize::from(l as f32 >= MORPH_LEVEL);
                        largest_rings[fine] = largest_rings[fine].max(rings);
                        rings
                    }
                };
                largest[layer] = [largest[layer][0].max(items), largest[layer][1].max(ni / 6)];
            }
        }
        let limits = gpu.device.limits();
        let limit = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        for t in &totals {
            let bytes = (t[0] * std::mem::size_of::<Vertex>()).max(t[1] * 4) as u64;
            anyhow::ensure!(
                bytes <= limit && t[0] < u32::MAX as usize && t[1] < u32::MAX as usize,
                "the levels need {} MB in one buffer, more than this GPU's {} MB: lower the level",
                bytes >> 20,
                limit >> 20
            );
        }
        // The lattice: 81 points of 16 bytes per patch.
        let lattice_bytes = (81 * 16 * pu * pv) as u64;
        anyhow::ensure!(
            lattice_bytes <= limit,
            "{pu}x{pv} patches need a {} MB lattice, more than this GPU's {} MB in one buffer",
            lattice_bytes >> 20,
            limit >> 20
        );
        let bezier: Vec<[f32; 4]> = w
            .panel
            .patches
            .iter()
            .flat_map(|p| p.q.iter().flatten().map(|q| q.as_vec3().extend(1.0).to_array()))
            .collect();
        let (ww, wh) = (w.weave.width(), w.weave.height());
        let weave: Vec<i32> = (0..wh)
            .flat_map(|j| (0..ww).map(move |i| (i, j)))
            .map(|(i, j)| w.weave.eta(i as i64, j as i64) as i32)
            .collect();
        anyhow::ensure!(
            largest[0][0].max(largest[1][0]).div_ceil(VERTICES_PER_ROW) <= 65535,
            "a patch of {} tube rings is more than one dispatch holds: lower the level",
            largest[1][0]
        );
        // The ring pass runs twice, the patches under MORPH_LEVEL first (their order in the
        // layer is their ids', not the plans').
        plans[1].sort_by_key(|p| p.level[0] >= MORPH_LEVEL);
        let coarse = plans[1].partition_point(|p| p.level[0] < MORPH_LEVEL);
        let y = w.yarn;
        let drawn: Vec<bool> = levels.iter().zip(culled).map(|(l, &c)| l.is_some() && !c).collect();
        let lattice = gpu.upload_pooled("woven lattice", bytemuck::cast_slice(&lattice(w.panel, &drawn)), U::STORAGE);
        let bezier = gpu.upload_pooled("woven bezier", bytemuck::cast_slice(&bezier), U::STORAGE);
        let weave = gpu.upload_pooled("woven weave", bytemuck::cast_slice(&weave), U::STORAGE);
        // Each pass's plans, uploaded once: the weft and the warp share the tubes'.
        let plan_buffers = plans
            .each_ref()
            .map(|p| (!p.is_empty()).then(|| gpu.upload_pooled("woven plans", bytemuck::cast_slice(p), U::STORAGE)));
        // The ring pass's two groups of patches: (patches, their plans, MORPHS).
        let ring_groups: Vec<(u32, PooledBuffer, usize)> = [&plans[1][..coarse], &plans[1][coarse..]]
            .into_iter()
            .enumerate()
            .filter(|(_, g)| !g.is_empty())
            .map(|(fine, g)| {
                let buffer = gpu.upload_pooled("woven ring plans", bytemuck::cast_slice(g), U::STORAGE);
                (g.len() as u32, buffer, fine)
            })
            .collect();
        for (layer, name) in [(0usize, "panel"), (1, "weft"), (2, "warp")] {
            let p = usize::from(layer > 0);
            let Some(plan) = &plan_buffers[p] else { continue };
            let params = Params {
                patches_u: pu as u32,
                patches_v: pv as u32,
                nodes: y.nodes as u32,
                fibres: y.fibres as u32,
                weave_w: ww as u32,
                weave_h: wh as u32,
                flip: u32::from(w.panel.flip),
                spacing: y.spacing as f32,
                crimp: y.crimp as f32,
                radius: y.radius as f32,
                fibre_radius: y.fibre_radius() as f32,
                ring_radius: y.ring_radius() as f32,
                migration: y.migration as f32,
                omega: y.omega() as f32,
                dir: u32::from(layer == 2),
            };
            let [nv, ni] = totals[p];
            let params = gpu.upload_pooled("woven params", bytemuck::bytes_of(&params), U::STORAGE);
            let vertices = gpu.scratch_pooled(
                &format!("woven {name} vertices"),
                (nv * std::mem::size_of::<Vertex>()) as u64,
                U::STORAGE | U::VERTEX | U::COPY_SRC,
            );
            let indices = gpu.scratch_pooled(
                &format!("woven {name} indices"),
                (ni * 4) as u64,
                U::STORAGE | U::INDEX | U::COPY_SRC,
            );
            // DrawIndexedIndirectArgs: index count, one instance, from the start.
            let args: [u32; INDIRECT_BYTES / 4] = [ni as u32, 1, 0, 0, 0];
            let indirect = gpu.upload_pooled(
                &format!("woven {name} indirect"),
                bytemuck::cast_slice(&args),
                U::STORAGE | U::INDIRECT | U::COPY_SRC,
            );
            let binds = |plan| {
                [
                    Bind::Storage(&params),
                    Bind::Storage(&bezier),
                    Bind::Storage(plan),
                    Bind::Storage(&weave),
                    Bind::StorageRw(&vertices),
                    Bind::StorageRw(&indices),
                    Bind::Storage(&lattice),
                ]
            };
            let [vertex_pass, index_pass] = &mut self.passes[p];
            let rows = |items: usize, per_row| items.div_ceil(per_row).clamp(1, 65535) as u32;
            if p == 0 {
                let workgroups = [plans[0].len() as u32, rows(largest[0][0], VERTICES_PER_ROW), 1];
                vertex_pass.dispatch(gpu, &[&binds(plan)], workgroups)?;
            } else {
                for (patches, group, fine) in &ring_groups {
                    let workgroups = [*patches, rows(largest_rings[*fine], VERTICES_PER_ROW), 1];
                    vertex_pass.dispatch_specialized(gpu, &[&binds(group)], workgroups, &[("MORPHS", *fine as u32)])?;
                }
            }
            index_pass.dispatch(
                gpu,
                &[&binds(plan)],
                [plans[p].len() as u32, rows(largest[p][1], QUADS_PER_ROW), 1],
            )?;
            out.layers[layer] =
                Some(GpuLayer { vertices, indices, indirect, vertex_count: nv as u64, index_count: ni as u64 });
        }
        Ok(out)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::woven::panel::ControlGrid;
    use crate::woven::weave::Weave;
    use crate::woven::yarn::YarnParams;

    fn flat(n: usize) -> Panel {
        let points = (0..=n).flat_map(|j| (0..=n).map(move |i| DVec3::new(i as f64, 0.0, j as f64))).collect();
        Panel::new(&ControlGrid::new(n + 1, n + 1, points).unwrap())
    }

    fn yarn() -> YarnParams {
        YarnParams { nodes: 4, spacing: 0.25, crimp: 0.02, radius: 0.02, fibres: 3, migration: 0.3, twist: 0.5 }
    }

    /// The plan's counts are the CPU tessellation's, patch by patch, at every scale.
    #[test]
    fn planned_counts_are_the_tessellations() {
        let (panel, weave, yarn) = (flat(1), Weave::plain(), yarn());
        let w = Woven { panel: &panel, weave: &weave, yarn: &yarn, morph: Morph::Continuous, snap: true };
        for l in [0.0, 1.5, 3.9, 4.2, 5.0, 6.5, 9.0, 9.5, 12.0] {
            let t = w.tessellate(&[Some(l)]).unwrap();
            let (scale, nv, ni) = patch_counts(&w, l);
            let layer = if scale == Scale::Panel { &t.panel } else { &t.weft };
            assert_eq!((layer.positions.len(), layer.indices.len()), (nv, ni), "L = {l}");
            if scale != Scale::Panel {
                assert_eq!((t.warp.positions.len(), t.warp.indices.len()), (nv, ni), "L = {l}");
            }
        }
    }

    /// A camera above patch (0, 0) looking straight down sees it and its neighbours' near
    /// edges, not the far patches; a view away from the cloth culls everything.
    #[test]
    fn patches_outside_the_view_are_culled() {
        let (panel, weave, yarn) = (flat(6), Weave::plain(), yarn());
        let w = Woven { panel: &panel, weave: &weave, yarn: &yarn, morph: Morph::Continuous, snap: true };
        // The render layer's camera (wgpu's depth range), built here: woven sits below render.
        let camera = |eye: glam::Vec3, target: glam::Vec3| {
            let proj = glam::Mat4::perspective_rh(40f32.to_radians(), 1.0, 0.01, 100.0);
            (proj * glam::Mat4::look_at_rh(eye, target, glam::Vec3::Z)).as_dmat4()
        };
        let down = camera(glam::Vec3::new(0.5, 1.0, 0.5), glam::Vec3::new(0.5, 0.0, 0.5));
        let culled = culled_patches(&w, Some(&down));
        assert!(!culled[0] && !culled[1] && !culled[6], "{culled:?}");
        assert!(culled[35] && culled[5 * 6 + 3], "{culled:?}");
        let away = camera(glam::Vec3::new(3.0, 1.0, 3.0), glam::Vec3::new(3.0, 5.0, 3.0));
        assert!(culled_patches(&w, Some(&away)).iter().all(|&c| c));
        assert!(culled_patches(&w, None).iter().all(|&c| !c));
    }
}

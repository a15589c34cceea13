//! Environment light on a BTF-shaded mesh as the paper does it (sections 5.2-5.4, eqs. 9-13):
//! per-vertex visibility maps, the per-vertex light sums `g_i`, the weight sets `U` of eq. 12
//! and the eigen-weightsets of eq. 13 that rotate the environment in real time.
//!
//! - [`Hemicube`]: the hemisphere over a vertex as the upper half of a cube map around the
//!   normal, with each pixel's exact solid angle.
//! - [`Visibility`] (section 5.2): per vertex and hemicube pixel, the environment texel it sees,
//!   or none where the mesh hides it (rays against an obvhs BVH of the mesh instead of drawing
//!   hemicubes). The pixels' 4 nearest light directions and weights (Fig. 11's "direction
//!   patterns") are the same for every vertex, since the hemicube is built in the vertex's
//!   tangent frame; they are kept once.
//! - [`Visibility::light_sums`] (eq. 10's `g_i`): per vertex, the environment gathered onto the
//!   BTF's light directions. [`WeightTable::weight_sets`]: `U`, eq. 12, all `gamma*_kj` for every
//!   vertex, view slot and component. [`WeightTable::vertex_texture`] reconstructs eq. 11.
//! - [`EigenWeightsets`] (section 5.4): a PCA over the weight sets of several environments
//!   (rotations of one), so that a new rotation is a sum of `e` stored sets.
//!
//! See docs/btf.md, "Environment light (HEM)".

use std::time::Duration;

use anyhow::{bail, ensure};
use glam::{DVec3, Vec3, Vec3A};
use obvhs::BvhBuildParams;
use obvhs::cwbvh::builder::build_cwbvh_from_tris;
use obvhs::triangle::Triangle;

use super::directions::{Dir, Sampling};
use super::pca::Compressed;
use crate::core::parallel;
use crate::ibl::cube::{CubeImage, face_dir, nearest_texel, texel_center, texel_solid_angle};

/// The hemisphere around +z as the upper half of a cube map `res` texels wide (`res` even):
/// the +z face and the upper halves of the four side faces, `3 res^2` pixels.
#[derive(Clone, Debug)]
pub struct Hemicube {
    pub res: usize,
    /// Unit directions through the pixel centres, in the vertex's frame (z: the normal).
    pub dirs: Vec<DVec3>,
    /// Exact solid angles; they sum to 2 pi.
    pub solid_angles: Vec<f64>,
}

impl Hemicube {
    pub fn new(res: usize) -> anyhow::Result<Hemicube> {
        ensure!(res >= 2 && res.is_multiple_of(2), "the hemicube resolution must be even and at least 2, not {res}");
        let (mut dirs, mut solid_angles) = (Vec::new(), Vec::new());
        for face in 0..6 {
            for y in 0..res {
                for x in 0..res {
                    let d = face_dir(face, texel_center(res, x), texel_center(res, y)).as_dvec3();
                    // An even resolution splits the side faces at a texel boundary.
                    if d.z > 0.0 {
                        dirs.push(d.normalize());
                        solid_angles.push(texel_solid_angle(res, x, y) as f64);
                    }
                }
            }
        }
        Ok(Hemicube { res, dirs, solid_angles })
    }

    pub fn len(&self) -> usize {
        self.dirs.len()
    }

    pub fn is_empty(&self) -> bool {
        self.dirs.is_empty()
    }
}

/// A vertex's BTF frame: x along increasing u, y towards decreasing v (up the BTF's images),
/// z the normal; the frame BtfShading builds per pixel (docs/btf.md, "The tangent frame").
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub x: DVec3,
    pub y: DVec3,
    pub z: DVec3,
}

impl Frame {
    /// From a vertex normal and its dP/du and dP/dv (`Mesh::tangents_u`, `tangents_v`).
    pub fn from_tangents(normal: Vec3, tangent_u: Vec3, tangent_v: Vec3) -> Frame {
        let z = normal.as_dvec3().normalize_or(DVec3::Z);
        let x = (tangent_u.as_dvec3() - z * z.dot(tangent_u.as_dvec3()))
            .try_normalize()
            .unwrap_or_else(|| z.any_orthonormal_vector());
        let y = z.cross(x);
        let y = if y.dot(tangent_v.as_dvec3()) > 0.0 { -y } else { y };
        Frame { x, y, z }
    }

    pub fn to_world(&self, local: DVec3) -> DVec3 {
        self.x * local.x + self.y * local.y + self.z * local.z
    }

    pub fn to_local(&self, world: DVec3) -> DVec3 {
        DVec3::new(world.dot(self.x), world.dot(self.y), world.dot(self.z))
    }

    /// The frame with the weave turned by `radians` from x towards y about the normal, as
    /// BtfShading's `rotation` turns it per pixel.
    pub fn turned(&self, radians: f64) -> Frame {
        let (s, c) = radians.sin_cos();
        Frame { x: self.x * c + self.y * s, y: self.y * c - self.x * s, z: self.z }
    }
}

/// A mesh's vertices in world space (`model` applied) and their BTF frames (from its normals
/// and UV tangents), turned by the weave's `rotation` (radians): what [`Visibility::compute`]
/// takes for the mesh as BtfShading draws it.
pub fn mesh_frames(mesh: &crate::mesh::Mesh, model: glam::Mat4, rotation: f64) -> (Vec<Vec3>, Vec<Frame>) {
    let normal_matrix = glam::Mat3::from_mat4(model).inverse().transpose();
    let positions = mesh.positions.iter().map(|&p| model.transform_point3(p)).collect();
    let frames = (0..mesh.positions.len())
        .map(|v| {
            let at = |t: &[Vec3]| t.get(v).map_or(Vec3::ZERO, |&t| model.transform_vector3(t));
            let normal = mesh.normals.get(v).map_or(Vec3::Z, |&n| normal_matrix * n);
            Frame::from_tangents(normal, at(&mesh.tangents_u), at(&mesh.tangents_v)).turned(rotation)
        })
        .collect();
    (positions, frames)
}

/// The factor of a light at `cos_l` past the sampling's outermost ring: the weights clamp theta
/// there, so the outermost ring's images (which contain its cosine) are scaled by
/// `cos(theta) / cos(theta_last)`, fading to 0 at the horizon. `grazing` in
/// shaders/btf/btf_shading.wgsl does the same.
pub fn grazing(sampling: &Sampling, cos_l: f64) -> f64 {
    let c_last = sampling.rings.last().map_or(0.0, |r| r.theta.to_radians().cos());
    if cos_l <= 0.0 {
        0.0
    } else if cos_l >= c_last || c_last < 1e-4 {
        1.0
    } else {
        cos_l / c_last
    }
}

/// The light directions and weights of a direction `local` in the BTF frame: eq. 3's 4 nearest
/// directions, each weighted by `solid_angle` and [`grazing`] (the data contain cos theta_i, so
/// eq. 9's G is only the solid angle here).
pub fn light_pattern(sampling: &Sampling, local: DVec3, solid_angle: f64) -> [(u16, f32); 4] {
    let scale = solid_angle * grazing(sampling, local.z);
    sampling.weights(Dir::from_vec(local)).map(|(i, w)| (i as u16, (w * scale) as f32))
}

/// Per vertex, which environment texel each hemicube pixel sees (section 5.2).
#[derive(Clone, Debug)]
pub struct Visibility {
    pub hemicube: Hemicube,
    /// The light directions (the BTF's sampling).
    pub sampling: Sampling,
    /// The environment cube maps' size this was built for.
    pub env_size: usize,
    /// Per hemicube pixel, its 4 light directions and weights (Fig. 11).
    patterns: Vec<[(u16, f32); 4]>,
    /// Per vertex and hemicube pixel: the environment texel's index ([`CubeImage::index`]) or
    /// [`HIDDEN`].
    texels: Vec<u32>,
}

/// Rows (vertex and channel) of the light sums multiplied together in [`WeightTable::weight_sets`],
/// and the width of the output tile: 12 rows of 256 f32 (12 KiB) stay in the first-level cache.
const BLOCK_ROWS: usize = 12;
const TILE: usize = 256;

/// A hemicube pixel that the mesh hides.
const HIDDEN: u32 = u32::MAX;

impl Visibility {
    /// Casts a ray per vertex and hemicube pixel against the mesh (`indices`: triangles), on
    /// `threads` threads (0: all cores). Rays start a hair off the surface along the normal.
    pub fn compute(
        positions: &[Vec3],
        frames: &[Frame],
        indices: &[u32],
        sampling: &Sampling,
        hemicube_res: usize,
        env_size: usize,
        threads: usize,
    ) -> anyhow::Result<Visibility> {
        ensure!(positions.len() == frames.len(), "{} positions but {} frames", positions.len(), frames.len());
        ensure!(env_size > 0, "the environment's cube size must be positive");
        ensure!(6 * env_size * env_size < HIDDEN as usize, "an environment cube of {env_size} texels is too large");
        if let Some(&bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
            bail!("triangle index {bad} is past the {} vertices", positions.len());
        }
        if positions.iter().any(|p| !p.is_finite()) {
            bail!("the mesh has a vertex position that is not finite");
        }
        sampling.check().map_err(anyhow::Error::msg)?;
        let hemicube = Hemicube::new(hemicube_res)?;
        let patterns =
            hemicube.dirs.iter().zip(&hemicube.solid_angles).map(|(&d, &w)| light_pattern(sampling, d, w)).collect();
        let tris: Vec<Triangle> = indices
            .chunks_exact(3)
            .filter(|t| crate::mesh::has_area(positions, [t[0], t[1], t[2]]))
            .map(|t| {
                let at = |i: u32| -> Vec3A { positions[i as usize].into() };
                Triangle { v0: at(t[0]), v1: at(t[1]), v2: at(t[2]) }
            })
            .collect();
        let (lo, hi) = positions.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let offset = 1e-4 * (hi - lo).length().max(1e-6);
        let mut texels = vec![HIDDEN; positions.len() * hemicube.len()];
        let bvh = (!tris.is_empty())
            .then(|| build_cwbvh_from_tris(&tris, BvhBuildParams::medium_build(), &mut Duration::default()));
        let pixels = hemicube.len();
        parallel::for_each_chunk(&mut texels, pixels, threads, |v, out| {
            let frame = &frames[v];
            let origin = positions[v] + frame.z.as_vec3() * offset;
            for (texel, &local) in out.iter_mut().zip(&hemicube.dirs) {
                let dir = frame.to_world(local).as_vec3();
                let open = bvh.as_ref().is_none_or(|bvh| {
                    let ray = super::bake::tilted_ray(origin, dir, 0.0, f32::INFINITY);
                    bvh.ray_traverse_miss(ray, |r, id| tris[bvh.primitive_indices[id] as usize].intersect(r))
                });
                if open {
                    let (face, x, y) = nearest_texel(env_size, dir);
                    *texel = ((face * env_size + y) * env_size + x) as u32;
                }
            }
        });
        Ok(Visibility { hemicube, sampling: sampling.clone(), env_size, patterns, texels })
    }

    pub fn vertices(&self) -> usize {
        self.texels.len() / self.hemicube.len().max(1)
    }

    /// The share of vertex `v`'s hemicube pixels that see the environment.
    pub fn open_fraction(&self, v: usize) -> f64 {
        let px = &self.texels[v * self.hemicube.len()..][..self.hemicube.len()];
        px.iter().filter(|&&t| t != HIDDEN).count() as f64 / px.len() as f64
    }

    /// The bytes of the per-vertex maps.
    pub fn bytes(&self) -> usize {
        self.texels.len() * 4 + self.patterns.len() * 4 * 6
    }

    /// Eq. 10's `g_i` for every vertex: `sum_alpha V L(alpha) h_{d_k}` over the hemicube pixels,
    /// `h` including the solid angle (RGB, so that a BTF value times `g_i` is radiance). Layout:
    /// vertex, channel, light direction.
    pub fn light_sums(&self, env: &CubeImage, threads: usize) -> anyhow::Result<Vec<f32>> {
        ensure!(
            env.size == self.env_size,
            "the environment is a cube of {} texels, but the visibility maps were built for {}",
            env.size,
            self.env_size
        );
        let (n, pixels) = (self.sampling.len(), self.hemicube.len());
        let mut g = vec![0.0f32; self.vertices() * 3 * n];
        parallel::for_each_chunk(&mut g, 3 * n, threads, |v, out| {
            for (&texel, pattern) in self.texels[v * pixels..][..pixels].iter().zip(&self.patterns) {
                if texel == HIDDEN {
                    continue;
                }
                let l = env.texels[texel as usize];
                for &(i, h) in pattern {
                    let i = i as usize;
                    out[i] += h * l.x;
                    out[n + i] += h * l.y;
                    out[2 * n + i] += h * l.z;
                }
            }
        });
        Ok(g)
    }
}

/// The compressed BTF's coefficients as one matrix (eq. 10's `P_ikj`): row i (a light
/// direction), column `j (c + 1) + k` (view slot j, component k, k = 0 the mean image).
#[derive(Clone, Debug)]
pub struct WeightTable {
    /// The BTF's sampling (its views and lights).
    pub sampling: Sampling,
    pub lights: usize,
    pub views: usize,
    /// Components per slot, the mean included: c + 1.
    pub per_slot: usize,
    coeffs: Vec<f32>,
}

impl WeightTable {
    /// From a BTF of `sampling` compressed per view slot, with `components` eigentextures per
    /// slot as drawn (the GPU's layers per slot less one; a slot keeping fewer has zeros).
    pub fn new(compressed: &Compressed, sampling: &Sampling, components: usize) -> anyhow::Result<WeightTable> {
        let (views, lights) = (compressed.slots.len(), sampling.len());
        ensure!(views == lights, "{views} compressed view slots for a sampling of {lights} directions");
        let per_slot = components + 1;
        let mut coeffs = vec![0.0f32; lights * views * per_slot];
        for (j, slot) in compressed.slots.iter().enumerate() {
            let (stored, c) = (slot.components(), slot.components().min(components));
            for i in 0..lights {
                let row = &mut coeffs[(i * views + j) * per_slot..][..per_slot];
                // The mean's weight is the sum of the light weights (eq. 4's k = 0).
                row[0] = if slot.mean.is_empty() { 0.0 } else { 1.0 };
                row[1..=c].copy_from_slice(&slot.coeffs[i * stored..][..c]);
            }
        }
        Ok(WeightTable { sampling: sampling.clone(), lights, views, per_slot, coeffs })
    }

    /// Values per vertex of a weight set: 3 channels x views x (c + 1).
    pub fn set_len(&self) -> usize {
        3 * self.views * self.per_slot
    }

    /// `U` of eq. 12 from the light sums `g` ([`Visibility::light_sums`]): per vertex, channel,
    /// view slot j and component k, `gamma*_kj = sum_i g_i P_ikj`, a product of the (vertices x
    /// 3) x n matrix of light sums with the table. Blocked so that the table is read once per
    /// [`BLOCK_ROWS`] rows and each tile of output rows stays in the first-level cache.
    pub fn weight_sets(&self, g: &[f32], threads: usize) -> Vec<f32> {
        let (n, row) = (self.lights, self.views * self.per_slot);
        let rows = g.len() / n.max(1);
        let mut u = vec![0.0f32; rows * row];
        parallel::for_each_chunk(&mut u, BLOCK_ROWS * row, threads, |block, out| {
            let g = &g[block * BLOCK_ROWS * n..][..out.len() / row * n];
            for start in (0..row).step_by(TILE) {
                let width = TILE.min(row - start);
                for i in 0..n {
                    let p = &self.coeffs[i * row + start..][..width];
                    for (r, out) in out.chunks_exact_mut(row).enumerate() {
                        let gi = g[r * n + i];
                        if gi != 0.0 {
                            out[start..][..width].iter_mut().zip(p).for_each(|(x, &p)| *x += gi * p);
                        }
                    }
                }
            }
        });
        u
    }

    /// Eq. 11 with eq. 5's view blending at vertex `v`: `f sum_m omega_m sum_k gamma*_{k j_m}
    /// B_{k j_m}` (per channel), from the weight sets `u`, for a view direction `view` in the
    /// vertex's frame. An RGB image of the BTF's size.
    pub fn vertex_texture(&self, compressed: &Compressed, u: &[f32], v: usize, view: Dir, exposure: f32) -> Vec<f32> {
        let set = &u[v * self.set_len()..][..self.set_len()];
        let row = self.views * self.per_slot;
        let dim = compressed.slots.first().map_or(0, |s| s.dim);
        let mut out = vec![0.0f64; dim];
        for (j, omega) in self.sampling.weights(view) {
            if omega == 0.0 {
                continue;
            }
            let slot = &compressed.slots[j];
            let gamma = |ch: usize, k: usize| set[ch * row + j * self.per_slot + k] as f64;
            for (t, o) in out.iter_mut().enumerate() {
                let ch = t % 3;
                let mut x = if slot.mean.is_empty() { 0.0 } else { gamma(ch, 0) * slot.mean[t] as f64 };
                for k in 0..slot.components() {
                    x += gamma(ch, k + 1) * slot.eigentexture(k)[t] as f64;
                }
                *o += omega * x;
            }
        }
        out.into_iter().map(|x| (x * exposure as f64) as f32).collect()
    }
}

/// Section 5.4: the weight sets `U_a` of A environments (rotations of one), decomposed by PCA
/// into eigen-weightsets `W_k`, so that `U_a ~= sum_{k<e} o_ak W_k` (eq. 13).
///
/// The Gram matrix `U_a . U_b` is computed without forming the `U_a` (3 c n N values each):
/// `U_a = g_a P`, so `U_a . U_b = sum (g_a R^T)(R g_b)` per vertex and channel with `R^T R = P
/// P^T` (n x n). The eigenvectors then give `W_k = (sum_a v_ak g_a) P / sqrt(lambda_k)`,
/// orthonormal in the space of the `U`, exactly the paper's PCA. No mean is subtracted (eq. 13
/// has none).
#[derive(Clone, Debug)]
pub struct EigenWeightsets {
    /// All A eigenvalues of the Gram matrix, descending.
    pub eigenvalues: Vec<f64>,
    /// `o_ak`, row-major: environment a, component k (k < e).
    pub weights: Vec<f64>,
    /// The kept `W_k`, each a whole weight set (vertices x [`WeightTable::set_len`]).
    pub sets: Vec<Vec<f32>>,
}

impl EigenWeightsets {
    /// From the light sums of A environments (`light_sums[a]`, [`Visibility::light_sums`]),
    /// keeping `e` eigen-weightsets.
    pub fn new(table: &WeightTable, light_sums: &[Vec<f32>], e: usize, threads: usize) -> anyhow::Result<Self> {
        let a_count = light_sums.len();
        ensure!(a_count > 0, "no environments to decompose");
        ensure!((1..=a_count).contains(&e), "keep between 1 and {a_count} eigen-weightsets, not {e}");
        let n = table.lights;
        let len = light_sums[0].len();
        ensure!(light_sums.iter().all(|g| g.len() == len), "the environments' light sums differ in size");
        // R with R^T R = P P^T, from the eigen-decomposition of P P^T (n x n, f64).
        let row = table.views * table.per_slot;
        let mut ppt = vec![0.0f64; n * n];
        for a in 0..n {
            for b in a..n {
                let (pa, pb) = (&table.coeffs[a * row..][..row], &table.coeffs[b * row..][..row]);
                let dot: f64 = pa.iter().zip(pb).map(|(&x, &y)| x as f64 * y as f64).sum();
                ppt[a * n + b] = dot;
                ppt[b * n + a] = dot;
            }
        }
        let (values, vectors) = super::pca::symmetric_eigen(&ppt, n);
        // Row k of R: sqrt(lambda_k) v_k.
        let r: Vec<f64> = (0..n)
            .flat_map(|k| {
                let s = values[k].max(0.0).sqrt();
                (0..n).map(move |i| (k, i, s))
            })
            .map(|(k, i, s)| s * vectors[k * n + i])
            .collect();
        let projected: Vec<Vec<f64>> = parallel::map(a_count, threads, |a| {
            light_sums[a]
                .chunks_exact(n)
                .flat_map(|g| (0..n).map(move |k| (k, g)))
                .map(|(k, g)| r[k * n..][..n].iter().zip(g).map(|(&x, &y)| x * y as f64).sum::<f64>())
                .collect()
        });
        let mut gram = vec![0.0f64; a_count * a_count];
        for a in 0..a_count {
            for b in a..a_count {
                let dot: f64 = projected[a].iter().zip(&projected[b]).map(|(x, y)| x * y).sum();
                gram[a * a_count + b] = dot;
                gram[b * a_count + a] = dot;
            }
        }
        let (eigenvalues, v) = super::pca::symmetric_eigen(&gram, a_count);
        let eigenvalues: Vec<f64> = eigenvalues.into_iter().map(|l| l.max(0.0)).collect();
        let kept = (0..e).take_while(|&k| eigenvalues[k] > eigenvalues[0] * 1e-12).count().max(1);
        let mut weights = vec![0.0f64; a_count * e];
        let mut sets = Vec::with_capacity(kept);
        for k in 0..kept {
            let s = eigenvalues[k].sqrt();
            for a in 0..a_count {
                weights[a * e + k] = s * v[k * a_count + a];
            }
            let mut g = vec![0.0f32; len];
            for (a, sums) in light_sums.iter().enumerate() {
                let w = (v[k * a_count + a] / s) as f32;
                g.iter_mut().zip(sums).for_each(|(x, &y)| *x += w * y);
            }
            sets.push(table.weight_sets(&g, threads));
        }
        Ok(EigenWeightsets { eigenvalues, weights, sets })
    }

    /// The environments decomposed (A).
    pub fn environments(&self) -> usize {
        self.eigenvalues.len()
    }

    /// The weight set at a fractional environment index `a` in [0, A), the coefficients `o_ak`
    /// interpolated linearly between neighbours and wrapping (for rotations in equal steps over
    /// 360 deg: `a = angle / step`): `sum_k o_k(a) W_k`, e weight sets summed.
    pub fn weight_set_at(&self, a: f64, threads: usize) -> Vec<f32> {
        let count = self.environments();
        let e = self.weights.len() / count;
        let a = a.rem_euclid(count as f64);
        let (a0, t) = (a.floor() as usize % count, a.fract());
        let a1 = (a0 + 1) % count;
        let o: Vec<f32> = (0..self.sets.len())
            .map(|k| ((1.0 - t) * self.weights[a0 * e + k] + t * self.weights[a1 * e + k]) as f32)
            .collect();
        let mut u = vec![0.0f32; self.sets.first().map_or(0, Vec::len)];
        let chunk = 4096;
        parallel::for_each_chunk(&mut u, chunk, threads, |c, out| {
            for (set, &o) in self.sets.iter().zip(&o) {
                out.iter_mut().zip(&set[c * chunk..]).for_each(|(x, &w)| *x += o * w);
            }
        });
        u
    }

    /// The bytes of the kept sets (f32).
    pub fn bytes(&self) -> usize {
        self.sets.iter().map(|s| s.len() * 4).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::Btf;
    use crate::btf::pca::{Centring, compress};
    use glam::Vec4;

    /// A deterministic BTF of noise (4x4 texels), so every coefficient matters.
    fn noise_btf(sampling: Sampling) -> Btf {
        let n = sampling.len();
        let mut state = 0x2545_f491_4f6c_dd1du64;
        let data = (0..n * n * 4 * 4 * 3)
            .map(|_| {
                state ^= state << 13;
                state ^= state >> 7;
                state ^= state << 17;
                (state >> 40) as f32 / (1u64 << 24) as f32
            })
            .collect();
        Btf { width: 4, height: 4, sampling, data }
    }

    /// A ground grid (z = 0, `cells` x `cells` over [-1, 1]^2, normal +z, u along x) plus
    /// extra triangles; the extra triangles' vertices get frames from their triangle.
    struct Scene {
        positions: Vec<Vec3>,
        frames: Vec<Frame>,
        indices: Vec<u32>,
    }

    fn ground(cells: u32) -> Scene {
        let mut s = Scene { positions: Vec::new(), frames: Vec::new(), indices: Vec::new() };
        for y in 0..=cells {
            for x in 0..=cells {
                let at = |i: u32| -1.0 + 2.0 * i as f32 / cells as f32;
                s.positions.push(Vec3::new(at(x), at(y), 0.0));
                s.frames.push(Frame::from_tangents(Vec3::Z, Vec3::X, -Vec3::Y));
            }
        }
        for y in 0..cells {
            for x in 0..cells {
                let i = y * (cells + 1) + x;
                s.indices.extend([i, i + 1, i + cells + 2, i, i + cells + 2, i + cells + 1]);
            }
        }
        s
    }

    fn add_sphere(s: &mut Scene, center: Vec3, radius: f32) {
        let (pos, tris) = crate::cloth::collider::uv_sphere_mesh(center, radius, 8, 12);
        let base = s.positions.len() as u32;
        for p in &pos {
            let n = (*p - center).normalize();
            let t = Vec3::Z.cross(n).try_normalize().unwrap_or(Vec3::X);
            s.positions.push(*p);
            s.frames.push(Frame::from_tangents(n, t, n.cross(t)));
        }
        s.indices.extend(tris.iter().flatten().map(|i| i + base));
    }

    /// A square roof of half-size `half` at height `height` over the ground's centre.
    fn add_roof(s: &mut Scene, half: f32, height: f32) {
        let base = s.positions.len() as u32;
        for (x, y) in [(-half, -half), (half, -half), (half, half), (-half, half)] {
            s.positions.push(Vec3::new(x, y, height));
            s.frames.push(Frame::from_tangents(-Vec3::Z, Vec3::X, Vec3::Y));
        }
        s.indices.extend([base, base + 2, base + 1, base, base + 3, base + 2]);
    }

    /// A sky that varies with direction (so visibility and rotation show), turned by `turn` rad
    /// about z.
    fn sky(size: usize, turn: f32) -> CubeImage {
        CubeImage::from_fn(size, |face, x, y| {
            let d = crate::ibl::cube::texel_dir(size, face, x, y);
            let d = glam::Quat::from_rotation_z(-turn) * d;
            Vec4::new(1.0 + d.x, 0.5 + 0.5 * d.z.max(0.0), 0.2 + (3.0 * d.y).sin().abs(), 1.0)
        })
    }

    /// Brute force: whether the ray hits any triangle (Moller-Trumbore over all of them).
    fn open(s: &Scene, origin: DVec3, dir: DVec3) -> bool {
        !s.indices.chunks_exact(3).any(|t| {
            let [a, b, c] = [0, 1, 2].map(|k| s.positions[t[k] as usize].as_dvec3());
            let (e1, e2) = (b - a, c - a);
            let p = dir.cross(e2);
            let det = e1.dot(p);
            if det.abs() < 1e-12 {
                return false;
            }
            let tv = origin - a;
            let u = tv.dot(p) / det;
            let q = tv.cross(e1);
            let v = dir.dot(q) / det;
            u >= 0.0 && v >= 0.0 && u + v <= 1.0 && e2.dot(q) / det > 0.0
        })
    }

    fn offset(s: &Scene) -> f64 {
        let (lo, hi) = s.positions.iter().fold((Vec3::MAX, Vec3::MIN), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        1e-4 * (hi - lo).length() as f64
    }

    #[test]
    fn the_hemicube_covers_the_hemisphere() {
        let cube = Hemicube::new(32).unwrap();
        assert_eq!(cube.len(), 3 * 32 * 32);
        let (sum, cos): (f64, f64) = cube
            .dirs
            .iter()
            .zip(&cube.solid_angles)
            .map(|(d, w)| (*w, w * d.z))
            .fold((0.0, 0.0), |(a, b), (x, y)| (a + x, b + y));
        assert!((sum - std::f64::consts::TAU).abs() < 1e-5, "solid angles sum to {sum}");
        assert!((cos / std::f64::consts::PI - 1.0).abs() < 1e-3, "cos-weighted: {cos}");
        assert!(cube.dirs.iter().all(|d| d.z > 0.0));
        assert!(Hemicube::new(7).is_err() && Hemicube::new(0).is_err());
    }

    #[test]
    fn weight_sets_and_textures_match_a_brute_force_evaluation() {
        let sampling = Sampling::h2_tests();
        let btf = noise_btf(sampling.clone());
        let compressed = compress(&btf, sampling.len(), Centring::Mean);
        let table = WeightTable::new(&compressed, &sampling, compressed.components).unwrap();
        let mut scene = ground(4);
        add_sphere(&mut scene, Vec3::new(0.1, -0.2, 0.45), 0.35);
        let (res, env_size) = (6, 8);
        let vis =
            Visibility::compute(&scene.positions, &scene.frames, &scene.indices, &sampling, res, env_size, 2).unwrap();
        let env = sky(env_size, 0.3);
        let u = table.weight_sets(&vis.light_sums(&env, 3).unwrap(), 2);
        let hemicube = Hemicube::new(res).unwrap();
        let eps = offset(&scene);
        // A ground vertex under the sphere, one beside it, and a sphere vertex.
        for v in [12, 6, 25 + 30] {
            let frame = scene.frames[v];
            let origin = scene.positions[v].as_dvec3() + frame.z * eps;
            let mut gamma = vec![0.0f64; table.set_len()];
            let view = Dir { theta: 22.0, phi: 130.0 };
            let mut texture = vec![0.0f64; btf.image_len()];
            let mut hidden = 0;
            for (&local, &w) in hemicube.dirs.iter().zip(&hemicube.solid_angles) {
                let world = frame.to_world(local);
                if !open(&scene, origin, world) {
                    hidden += 1;
                    continue;
                }
                let (face, x, y) = nearest_texel(env_size, world.as_vec3());
                let l = env.texel(face, x, y);
                let scale = w * grazing(&sampling, local.z);
                let light = Dir::from_vec(local);
                for (i, h) in sampling.weights(light) {
                    for (j, slot) in compressed.slots.iter().enumerate() {
                        let c = slot.components();
                        for (ch, l) in [l.x, l.y, l.z].into_iter().enumerate() {
                            let at = ch * table.views * table.per_slot + j * table.per_slot;
                            gamma[at] += scale * h * l as f64;
                            for k in 0..c {
                                gamma[at + 1 + k] += scale * h * l as f64 * slot.coeffs[i * c + k] as f64;
                            }
                        }
                    }
                }
                for (t, x) in btf.blend(view, light).iter().enumerate() {
                    texture[t] += scale * [l.x, l.y, l.z][t % 3] as f64 * *x as f64;
                }
            }
            assert!(v == 6 || hidden > 0, "vertex {v} should be partly hidden");
            let got = &u[v * table.set_len()..][..table.set_len()];
            let scale = gamma.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            for (k, (a, b)) in got.iter().zip(&gamma).enumerate() {
                assert!((*a as f64 - b).abs() < 1e-5 * scale, "vertex {v}, entry {k}: {a} against brute force {b}");
            }
            // Full rank: eq. 11 equals the uncompressed BTF blended at every hemicube pixel.
            let tex = table.vertex_texture(&compressed, &u, v, view, 1.0);
            let scale = texture.iter().fold(0.0f64, |m, x| m.max(x.abs()));
            for (a, b) in tex.iter().zip(&texture) {
                assert!((*a as f64 - b).abs() < 1e-4 * scale, "vertex {v}: texture {a} against {b}");
            }
        }
    }

    fn lambert_texture_mean(scene: &Scene, vertex: usize, view: Dir) -> f64 {
        let sampling = Sampling::h2_tests();
        let btf = Btf::lambertian(sampling.clone(), 2, 2, |_, _| [1.0; 3]);
        let compressed = compress(&btf, 2, Centring::Mean);
        let table = WeightTable::new(&compressed, &sampling, compressed.components).unwrap();
        let vis = Visibility::compute(&scene.positions, &scene.frames, &scene.indices, &sampling, 32, 4, 0).unwrap();
        let env = CubeImage::from_fn(4, |_, _, _| Vec4::ONE);
        let u = table.weight_sets(&vis.light_sums(&env, 0).unwrap(), 0);
        let tex = table.vertex_texture(&compressed, &u, vertex, view, 1.0);
        tex.iter().map(|&x| x as f64).sum::<f64>() / tex.len() as f64
    }

    #[test]
    fn a_white_lambertian_btf_in_a_white_furnace_gives_one() {
        let mut scene = Scene { positions: Vec::new(), frames: Vec::new(), indices: Vec::new() };
        add_sphere(&mut scene, Vec3::ZERO, 1.0);
        for (v, view) in [(0, Dir { theta: 0.0, phi: 0.0 }), (30, Dir { theta: 20.0, phi: 100.0 })] {
            let got = lambert_texture_mean(&scene, v, view);
            // The cosine interpolated linearly between rings 15 deg apart: (15 deg)^2 / 8.
            assert!((got - 1.0).abs() < 0.0086, "vertex {v}: {got}");
        }
    }

    #[test]
    fn a_roof_takes_its_view_factor_from_the_furnace() {
        let mut scene = ground(4);
        let (half, height) = (1.0f64, 1.0f64);
        add_roof(&mut scene, half as f32, height as f32);
        // The view factor of a parallel square centred over a point: four corner rectangles.
        let x = half / height;
        let corner = 2.0 * x / (1.0 + x * x).sqrt() * (x / (1.0 + x * x).sqrt()).atan() / std::f64::consts::TAU;
        let want = 1.0 - 4.0 * corner;
        let got = lambert_texture_mean(&scene, 12, Dir { theta: 0.0, phi: 0.0 });
        assert!((got - want).abs() < 0.012, "under the roof: {got}, analytic {want:.4}");
        // A corner of the ground sees more sky.
        assert!(lambert_texture_mean(&scene, 0, Dir { theta: 0.0, phi: 0.0 }) > got + 0.1);
    }

    #[test]
    fn eigen_weightsets_are_exact_with_all_components_and_converge() {
        let sampling = Sampling::h2_tests();
        let compressed = compress(&noise_btf(sampling.clone()), 5, Centring::Mean);
        let table = WeightTable::new(&compressed, &sampling, compressed.components).unwrap();
        let mut scene = ground(3);
        add_sphere(&mut scene, Vec3::new(0.0, 0.0, 0.5), 0.4);
        let vis = Visibility::compute(&scene.positions, &scene.frames, &scene.indices, &sampling, 8, 8, 0).unwrap();
        let count = 6;
        let sums: Vec<Vec<f32>> = (0..count)
            .map(|a| vis.light_sums(&sky(8, a as f32 * std::f32::consts::TAU / count as f32), 0).unwrap())
            .collect();
        let direct: Vec<Vec<f32>> = sums.iter().map(|g| table.weight_sets(g, 0)).collect();
        let norm2 = |u: &[f32]| u.iter().map(|&x| x as f64 * x as f64).sum::<f64>();
        let energy: f64 = direct.iter().map(|u| norm2(u)).sum();
        let full = EigenWeightsets::new(&table, &sums, count, 2).unwrap();
        // The Gram matrix through R^T R = P P^T holds the U_a's energy.
        let total: f64 = full.eigenvalues.iter().sum();
        assert!((total / energy - 1.0).abs() < 1e-6, "eigenvalues sum to {total}, |U_a|^2 to {energy}");
        let error = |eig: &EigenWeightsets, a: usize| {
            let u = eig.weight_set_at(a as f64, 0);
            let diff: Vec<f32> = u.iter().zip(&direct[a]).map(|(x, y)| x - y).collect();
            (norm2(&diff) / norm2(&direct[a])).sqrt()
        };
        for a in 0..count {
            assert!(error(&full, a) < 1e-5, "rotation {a}: relative error {}", error(&full, a));
        }
        let errors: Vec<f64> = (1..=count)
            .map(|e| {
                let eig = EigenWeightsets::new(&table, &sums, e, 0).unwrap();
                (0..count).map(|a| error(&eig, a).powi(2)).sum::<f64>()
            })
            .collect();
        assert!(errors.windows(2).all(|w| w[1] <= w[0] + 1e-9), "errors do not fall with e: {errors:?}");
        // Between two steps the coefficients are interpolated linearly.
        let half = full.weight_set_at(2.5, 0);
        for ((h, x), y) in half.iter().zip(&direct[2]).zip(&direct[3]) {
            assert!((h - 0.5 * (x + y)).abs() < 1e-4 * (x.abs() + y.abs()).max(1.0));
        }
        assert!(EigenWeightsets::new(&table, &sums, count + 1, 0).is_err());
        assert!(vis.light_sums(&sky(4, 0.0), 0).is_err(), "an environment of another size");
    }
}

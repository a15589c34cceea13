//! CPU meshes: what Mesh and Surface ports carry. GPU buffers are created once per mesh,
//! on first draw, and live as long as the mesh.

use std::sync::OnceLock;

use anyhow::{Context as _, bail};
use glam::{Vec2, Vec3};

#[derive(Default)]
pub struct Mesh {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    /// dP/du and dP/dv, orthogonalized against the normal and normalized (t_u, t_v).
    pub tangents_u: Vec<Vec3>,
    pub tangents_v: Vec<Vec3>,
    pub indices: Vec<u32>,
    /// Pattern piece of each vertex (Surfaces); empty for plain meshes.
    pub piece_ids: Vec<u32>,
    /// Vertex pairs sewn together across pieces (Surfaces): the same point of the garment on
    /// two pattern pieces. The matrix texture blends across them.
    pub seams: Vec<[u32; 2]>,
    /// Notes about repairs made while building the mesh, shown as node warnings.
    pub repairs: Vec<String>,
    gpu: OnceLock<GpuMesh>,
    /// [`Mesh::bounds`], computed once like the GPU copy: a mesh is not changed once used.
    bounds: OnceLock<(Vec3, Vec3)>,
}

impl Clone for Mesh {
    fn clone(&self) -> Self {
        Mesh {
            positions: self.positions.clone(),
            normals: self.normals.clone(),
            uvs: self.uvs.clone(),
            tangents_u: self.tangents_u.clone(),
            tangents_v: self.tangents_v.clone(),
            indices: self.indices.clone(),
            piece_ids: self.piece_ids.clone(),
            seams: self.seams.clone(),
            repairs: self.repairs.clone(),
            gpu: OnceLock::new(),
            bounds: OnceLock::new(),
        }
    }
}

impl std::fmt::Debug for Mesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Mesh({} vertices, {} triangles)", self.positions.len(), self.triangle_count())
    }
}

/// Whether triangle `t` has an area (a collapsed one is left out of exports, as `Mesh::build` does).
#[inline]
pub fn has_area(positions: &[Vec3], t: [u32; 3]) -> bool {
    let (a, b, c) = (positions[t[0] as usize], positions[t[1] as usize], positions[t[2] as usize]);
    (b - a).cross(c - a).length() > f32::MIN_POSITIVE
}

/// The interleaved vertex layout shared by every mesh shader.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct Vertex {
    pub position: [f32; 3],
    pub normal: [f32; 3],
    pub tangent_u: [f32; 3],
    pub uv: [f32; 2],
    pub tangent_v: [f32; 3],
}

impl Vertex {
    pub const ATTRIBUTES: [wgpu::VertexAttribute; 5] =
        wgpu::vertex_attr_array![0 => Float32x3, 1 => Float32x3, 2 => Float32x3, 3 => Float32x2, 4 => Float32x3];
    /// What the G-buffer and depth passes read (shaders/common/vertex_in.wgsl `MeshVertexIn`): position,
    /// normal and UV, leaving locations 2 and 4 to per-item data.
    pub const SHADING_ATTRIBUTES: [wgpu::VertexAttribute; 3] = [
        wgpu::VertexAttribute { format: wgpu::VertexFormat::Float32x3, offset: 0, shader_location: 0 },
        wgpu::VertexAttribute {
            format: wgpu::VertexFormat::Float32x3,
            offset: std::mem::offset_of!(Vertex, normal) as u64,
            shader_location: 1,
        },
        wgpu::VertexAttribute {
            format: wgpu::VertexFormat::Float32x2,
            offset: std::mem::offset_of!(Vertex, uv) as u64,
            shader_location: 3,
        },
    ];
    /// Floats per vertex, for shaders that read the vertex buffer as storage.
    pub const FLOATS: usize = 14;
    pub fn layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout {
            array_stride: std::mem::size_of::<Vertex>() as u64,
            step_mode: wgpu::VertexStepMode::Vertex,
            attributes: &Self::ATTRIBUTES,
        }
    }

    /// [`Vertex::SHADING_ATTRIBUTES`] of the same buffer.
    pub fn shading_layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout { attributes: &Self::SHADING_ATTRIBUTES, ..Self::layout() }
    }
}

pub struct GpuMesh {
    pub vertices: crate::gpu::PooledBuffer,
    pub indices: crate::gpu::PooledBuffer,
    pub index_count: u32,
}

impl Mesh {
    pub fn triangle_count(&self) -> usize {
        self.indices.len() / 3
    }

    /// Builds a mesh from positions, optional UVs and normals, and triangle indices:
    /// checks indices, repairs what can be repaired (NaN positions, degenerate triangles,
    /// missing normals, tangents from UV gradients) and records what it did in `repairs`.
    pub fn build(
        positions: Vec<Vec3>,
        uvs: Option<Vec<Vec2>>,
        normals: Option<Vec<Vec3>>,
        indices: Vec<u32>,
    ) -> anyhow::Result<Mesh> {
        let n = positions.len();
        if n == 0 {
            bail!("the mesh has no vertices");
        }
        if !indices.len().is_multiple_of(3) {
            bail!("the index count {} is not a multiple of 3", indices.len());
        }
        if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
            bail!("index {bad} is out of range (the mesh has {n} vertices)");
        }
        let mut repairs = Vec::new();
        let bad_positions: Vec<bool> = positions.iter().map(|p| !p.is_finite()).collect();
        let nan_count = bad_positions.iter().filter(|b| **b).count();
        if nan_count == n {
            bail!("every vertex position is NaN or infinite");
        }
        let mut kept = Vec::with_capacity(indices.len());
        let mut degenerate = 0;
        let mut dropped_nan = 0;
        for t in indices.chunks_exact(3) {
            let [a, b, c] = [t[0] as usize, t[1] as usize, t[2] as usize];
            if bad_positions[a] || bad_positions[b] || bad_positions[c] {
                dropped_nan += 1;
                continue;
            }
            let area2 = (positions[b] - positions[a]).cross(positions[c] - positions[a]).length();
            if a == b || b == c || a == c || area2 <= f32::MIN_POSITIVE {
                degenerate += 1;
                continue;
            }
            kept.extend_from_slice(t);
        }
        if dropped_nan > 0 {
            repairs.push(format!(
                "{nan_count} vertices had NaN or infinite positions; dropped the {dropped_nan} triangles using them"
            ));
        }
        if degenerate > 0 {
            repairs.push(format!("dropped {degenerate} degenerate (zero-area) triangles"));
        }
        if kept.is_empty() {
            bail!("no triangle is left after removing degenerate and NaN triangles");
        }
        let positions: Vec<Vec3> = positions.into_iter().map(|p| if p.is_finite() { p } else { Vec3::ZERO }).collect();
        let uvs = match uvs {
            Some(u) if u.len() == n && u.iter().all(|x| x.is_finite()) => u,
            Some(_) => {
                repairs.push(REPAIR_BAD_UVS.into());
                planar_uvs(&positions)
            }
            None => {
                repairs.push(REPAIR_NO_UVS.into());
                planar_uvs(&positions)
            }
        };
        let normals = match normals {
            Some(nr) if nr.len() == n && nr.iter().all(|x| x.is_finite() && x.length_squared() > 0.0) => {
                nr.into_iter().map(|v| v.normalize()).collect()
            }
            Some(_) => {
                repairs.push("normals were incomplete or invalid; recomputed from faces".into());
                vertex_normals(&positions, &kept)
            }
            None => vertex_normals(&positions, &kept),
        };
        let (tangents_u, tangents_v) = uv_tangents(&positions, &normals, &uvs, &kept);
        Ok(Mesh {
            positions,
            normals,
            uvs,
            tangents_u,
            tangents_v,
            indices: kept,
            piece_ids: Vec::new(),
            seams: Vec::new(),
            repairs,
            gpu: OnceLock::new(),
            bounds: OnceLock::new(),
        })
    }

    /// A mesh from arrays the caller vouches for (same lengths, valid indices), with no
    /// checks or derived data: for hot paths such as the CPU warp benchmark.
    pub fn from_raw(
        positions: Vec<Vec3>,
        normals: Vec<Vec3>,
        uvs: Vec<Vec2>,
        tangents_u: Vec<Vec3>,
        tangents_v: Vec<Vec3>,
        indices: Vec<u32>,
    ) -> Mesh {
        Mesh { positions, normals, uvs, tangents_u, tangents_v, indices, ..Default::default() }
    }

    /// A mesh from complete data whose topology must be kept as it is (a simulator's frame):
    /// no repairs, no triangles dropped; normals computed when `normals` is None; tangents
    /// from the UV gradients. Checks lengths, index range and finiteness.
    pub fn from_parts(
        positions: Vec<Vec3>,
        normals: Option<Vec<Vec3>>,
        uvs: Vec<Vec2>,
        indices: Vec<u32>,
        piece_ids: Vec<u32>,
    ) -> anyhow::Result<Mesh> {
        let n = positions.len();
        if n == 0 || indices.is_empty() {
            bail!("the mesh has no vertices or no triangles");
        }
        if !indices.len().is_multiple_of(3) {
            bail!("the index count {} is not a multiple of 3", indices.len());
        }
        if uvs.len() != n || !(piece_ids.is_empty() || piece_ids.len() == n) {
            bail!("{n} positions but {} UVs and {} piece ids", uvs.len(), piece_ids.len());
        }
        if let Some(bad) = indices.iter().find(|&&i| i as usize >= n) {
            bail!("index {bad} is out of range (the mesh has {n} vertices)");
        }
        if let Some(i) = positions.iter().position(|p| !p.is_finite()) {
            bail!("vertex {i} has a NaN or infinite position");
        }
        if let Some(i) = uvs.iter().position(|p| !p.is_finite()) {
            bail!("vertex {i} has a NaN or infinite UV");
        }
        let normals = match normals {
            Some(nr) if nr.len() == n => nr
                .into_iter()
                .enumerate()
                .map(|(i, v)| {
                    v.try_normalize().ok_or_else(|| anyhow::anyhow!("vertex {i} has a zero or invalid normal"))
                })
                .collect::<anyhow::Result<Vec<Vec3>>>()?,
            Some(nr) => bail!("{n} positions but {} normals", nr.len()),
            None => vertex_normals(&positions, &indices),
        };
        let (tangents_u, tangents_v) = uv_tangents(&positions, &normals, &uvs, &indices);
        Ok(Mesh {
            positions,
            normals,
            uvs,
            tangents_u,
            tangents_v,
            indices,
            piece_ids,
            seams: Vec::new(),
            repairs: Vec::new(),
            gpu: OnceLock::new(),
            bounds: OnceLock::new(),
        })
    }

    /// The axis-aligned bounding box of the positions (computed once).
    pub fn bounds(&self) -> (Vec3, Vec3) {
        *self.bounds.get_or_init(|| {
            self.positions
                .iter()
                .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)))
        })
    }

    /// Whether `build` made the UVs up (a planar projection): such a mesh has no pattern
    /// coordinates to attach detail by.
    pub fn uvs_generated(&self) -> bool {
        self.repairs.iter().any(|r| r == REPAIR_NO_UVS || r == REPAIR_BAD_UVS)
    }

    /// Each pattern piece's UV bounding rectangle `(piece, lo, hi)`, by piece id; a mesh
    /// without piece ids is one piece 0. Where to put placements, in numbers.
    pub fn piece_uv_rects(&self) -> Vec<(u32, glam::Vec2, glam::Vec2)> {
        let mut rects: std::collections::BTreeMap<u32, (glam::Vec2, glam::Vec2)> = Default::default();
        for (i, uv) in self.uvs.iter().enumerate() {
            let piece = self.piece_ids.get(i).copied().unwrap_or(0);
            let r = rects.entry(piece).or_insert((*uv, *uv));
            *r = (r.0.min(*uv), r.1.max(*uv));
        }
        rects.into_iter().map(|(p, (lo, hi))| (p, lo, hi)).collect()
    }

    /// Piece `piece`'s UV bounding rectangle `(lo, hi)`; the error names the pieces there are.
    pub fn piece_uv_rect(&self, piece: u32) -> Result<(glam::Vec2, glam::Vec2), String> {
        let rects = self.piece_uv_rects();
        match rects.iter().find(|r| r.0 == piece) {
            Some(&(_, lo, hi)) => Ok((lo, hi)),
            None => {
                let known: Vec<String> = rects.iter().map(|r| r.0.to_string()).collect();
                Err(format!("the surface has no piece {piece}; its pieces are {}", known.join(", ")))
            }
        }
    }

    pub fn gpu(&self, gpu: &crate::gpu::GpuContext) -> &GpuMesh {
        self.gpu.get_or_init(|| {
            let verts: Vec<Vertex> = (0..self.positions.len())
                .map(|i| Vertex {
                    position: self.positions[i].to_array(),
                    normal: self.normals[i].to_array(),
                    // A mesh without tangents (an exported one) uploads zero tangents.
                    tangent_u: self.tangents_u.get(i).map_or([0.0; 3], |t| t.to_array()),
                    uv: self.uvs[i].to_array(),
                    tangent_v: self.tangents_v.get(i).map_or([0.0; 3], |t| t.to_array()),
                })
                .collect();
            // Pooled: a simulated mesh is a new mesh of the same size every frame.
            let vertices = gpu.upload_pooled(
                "mesh vertices",
                bytemuck::cast_slice(&verts),
                wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE,
            );
            let indices = gpu.upload_pooled(
                "mesh indices",
                bytemuck::cast_slice(&self.indices),
                wgpu::BufferUsages::INDEX | wgpu::BufferUsages::STORAGE,
            );
            GpuMesh { vertices, indices, index_count: self.indices.len() as u32 }
        })
    }
}

/// Area-weighted vertex normals.
pub fn vertex_normals(positions: &[Vec3], indices: &[u32]) -> Vec<Vec3> {
    let mut normals = vec![Vec3::ZERO; positions.len()];
    for t in indices.chunks_exact(3) {
        let [a, b, c] = [t[0] as usize, t[1] as usize, t[2] as usize];
        let n = (positions[b] - positions[a]).cross(positions[c] - positions[a]);
        normals[a] += n;
        normals[b] += n;
        normals[c] += n;
    }
    normals.into_iter().map(|n| n.try_normalize().unwrap_or(Vec3::Y)).collect()
}

/// Per-vertex t_u = dP/du and t_v = dP/dv from the UV gradients of the adjacent triangles,
/// Gram-Schmidt orthogonalized against the normal. Where the UVs are degenerate, an
/// arbitrary frame around the normal is used.
pub fn uv_tangents(positions: &[Vec3], normals: &[Vec3], uvs: &[Vec2], indices: &[u32]) -> (Vec<Vec3>, Vec<Vec3>) {
    let mut tu = vec![Vec3::ZERO; positions.len()];
    let mut tv = vec![Vec3::ZERO; positions.len()];
    for t in indices.chunks_exact(3) {
        let [a, b, c] = [t[0] as usize, t[1] as usize, t[2] as usize];
        let (e1, e2) = (positions[b] - positions[a], positions[c] - positions[a]);
        let (d1, d2) = (uvs[b] - uvs[a], uvs[c] - uvs[a]);
        let det = d1.x * d2.y - d2.x * d1.y;
        if det.abs() < 1e-12 {
            continue;
        }
        let r = 1.0 / det;
        // Solve [e1 e2] = [dP/du dP/dv] [d1 d2].
        let du = (e1 * d2.y - e2 * d1.y) * r;
        let dv = (e2 * d1.x - e1 * d2.x) * r;
        for i in [a, b, c] {
            tu[i] += du;
            tv[i] += dv;
        }
    }
    for i in 0..positions.len() {
        let n = normals[i];
        let u = (tu[i] - n * n.dot(tu[i])).try_normalize().unwrap_or_else(|| n.any_orthonormal_vector());
        let v = (tv[i] - n * n.dot(tv[i]) - u * u.dot(tv[i])).try_normalize().unwrap_or_else(|| n.cross(u));
        tu[i] = u;
        tv[i] = v;
    }
    (tu, tv)
}

const REPAIR_NO_UVS: &str = "no UVs; generated a planar projection";
const REPAIR_BAD_UVS: &str = "UVs were incomplete or not finite; replaced by a planar projection";

/// Sets one pattern piece per part (OBJ object or group, glTF primitive), from each part's
/// first vertex, as MeshSequence does for OBJ objects; a single part is no piece list.
/// `build` keeps every vertex, so the ids line up.
fn with_pieces(mut mesh: Mesh, part_starts: &[usize]) -> Mesh {
    if part_starts.len() > 1 {
        let n = mesh.positions.len();
        mesh.piece_ids = (0..n).map(|v| (part_starts.partition_point(|&s| s <= v) - 1) as u32).collect();
    }
    mesh
}

/// UVs from the two largest extents of the bounding box.
fn planar_uvs(positions: &[Vec3]) -> Vec<Vec2> {
    let (lo, hi) =
        positions.iter().fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    let ext = (hi - lo).max(Vec3::splat(1e-9));
    let (a, b) = if ext.x.min(ext.y).min(ext.z) == ext.x {
        (2, 1)
    } else if ext.y <= ext.z {
        (0, 2)
    } else {
        (0, 1)
    };
    positions.iter().map(|p| Vec2::new((p[a] - lo[a]) / ext[a], (p[b] - lo[b]) / ext[b])).collect()
}

/// Loads an OBJ file (all its models merged) with `tobj`.
pub fn load_obj(path: &std::path::Path) -> anyhow::Result<Mesh> {
    let (models, _) =
        tobj::load_obj(path, &tobj::LoadOptions { triangulate: true, single_index: true, ..Default::default() })
            .with_context(|| format!("cannot parse OBJ file {}", path.display()))?;
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    let mut normals = Vec::new();
    let mut indices = Vec::new();
    let (mut all_uvs, mut all_normals) = (true, true);
    let mut part_starts = Vec::new();
    for m in models.iter().filter(|m| !m.mesh.positions.is_empty()) {
        let mesh = &m.mesh;
        part_starts.push(positions.len());
        let base = positions.len() as u32;
        let count = mesh.positions.len() / 3;
        positions.extend(mesh.positions.chunks_exact(3).map(|p| Vec3::new(p[0], p[1], p[2])));
        if mesh.texcoords.len() == count * 2 {
            // OBJ's v axis points up; textures here have v down.
            uvs.extend(mesh.texcoords.chunks_exact(2).map(|t| Vec2::new(t[0], 1.0 - t[1])));
        } else {
            all_uvs = false;
        }
        if mesh.normals.len() == count * 3 {
            normals.extend(mesh.normals.chunks_exact(3).map(|n| Vec3::new(n[0], n[1], n[2])));
        } else {
            all_normals = false;
        }
        indices.extend(mesh.indices.iter().map(|i| i + base));
    }
    if positions.is_empty() {
        bail!("{} contains no geometry", path.display());
    }
    Mesh::build(positions, all_uvs.then_some(uvs), all_normals.then_some(normals), indices)
        .map(|m| with_pieces(m, &part_starts))
        .with_context(|| format!("invalid mesh in {}", path.display()))
}

/// The glTF extension for Draco-compressed primitives, decoded here with `draco-oxide-decoder`.
const DRACO: &str = "KHR_draco_mesh_compression";

/// Opens a .gltf or .glb with its buffers (not its images). The `gltf` crate refuses files
/// that require an extension it does not know; Draco is decoded here, so it is let through.
fn import_gltf(path: &std::path::Path) -> anyhow::Result<(gltf::Document, Vec<gltf::buffer::Data>)> {
    let bytes = std::fs::read(path)?;
    let gltf::Gltf { document, blob } = gltf::Gltf::from_slice_without_validation(&bytes)?;
    let mut json = document.into_json();
    let draco = json.extensions_used.iter().any(|e| e == DRACO);
    json.extensions_required.retain(|e| e != DRACO);
    // A Draco primitive's accessors have no bufferView (the data is in the Draco stream), which
    // the crate's validation calls missing; everything else it finds is still an error.
    let document = match gltf::Document::from_json(json.clone()) {
        Err(gltf::Error::Validation(errors))
            if draco
                && errors.iter().all(|(path, e)| {
                    matches!(e, gltf::json::validation::Error::Missing)
                        && path.to_string().starts_with("accessors[")
                        && path.to_string().ends_with("].bufferView")
                }) =>
        {
            gltf::Document::from_json_without_validation(json)
        }
        other => other?,
    };
    let buffers = gltf::import_buffers(&document, path.parent(), blob)?;
    Ok((document, buffers))
}

/// One primitive's vertices (positions, then UVs and normals where it has them) and triangles.
type Primitive = (Vec<Vec3>, Option<Vec<Vec2>>, Option<Vec<Vec3>>, Vec<u32>);

/// A Draco-compressed primitive (`ext`: its KHR_draco_mesh_compression object), decoded.
fn draco_primitive(
    doc: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    ext: &serde_json::Value,
) -> anyhow::Result<Primitive> {
    use draco_oxide_core::attribute::{Attribute, ComponentDataType};
    let view = ext["bufferView"].as_u64().with_context(|| format!("{DRACO} names no bufferView"))?;
    let view = doc
        .views()
        .nth(view as usize)
        .with_context(|| format!("{DRACO} names bufferView {view}, which is not there"))?;
    let data = &buffers[view.buffer().index()];
    let bytes = data
        .get(view.offset()..view.offset().saturating_add(view.length()))
        .context("the Draco bufferView runs past its buffer")?;
    // The decoder is young (alpha): a crash on bad data is an error here, not a crash.
    let mesh = std::panic::catch_unwind(|| draco_oxide_decoder::decode_mesh(bytes))
        .map_err(|_| anyhow::anyhow!("the Draco decoder failed on the compressed data"))?
        .map_err(|e| anyhow::anyhow!("the Draco data cannot be decoded: {e}"))?;
    let by_name = |name: &str| -> Option<&Attribute> {
        let id = ext["attributes"][name].as_u64()?;
        mesh.attributes.iter().find(|a| a.get_id().as_usize() as u64 == id)
    };
    let position = by_name("POSITION").context("the Draco data has no POSITION")?;
    let points = position.len();
    // Each point's value: the attribute's float values through its point-to-value map.
    let values = |a: &Attribute, n: usize, name: &str| -> anyhow::Result<Vec<f32>> {
        if a.get_component_type() != ComponentDataType::F32 || a.get_num_components() != n || a.len() != points {
            bail!("the Draco {name} is not {n} floats for each of the {points} points");
        }
        let unique: Vec<f32> =
            a.get_data_as_bytes().chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect();
        let value = |p: usize| a.point_map_as_slice().map_or(Some(p), |m| m.get(p).map(|&v| usize::from(v)));
        let mut out = Vec::with_capacity(points * n);
        for p in 0..points {
            let v = value(p).filter(|&v| (v + 1) * n <= unique.len());
            out.extend_from_slice(
                &unique[v.with_context(|| format!("the Draco {name} of point {p} is missing"))? * n..][..n],
            );
        }
        Ok(out)
    };
    let positions = values(position, 3, "POSITION")?.chunks_exact(3).map(Vec3::from_slice).collect();
    let uvs = match by_name("TEXCOORD_0") {
        Some(a) => Some(values(a, 2, "TEXCOORD_0")?.chunks_exact(2).map(Vec2::from_slice).collect()),
        None => None,
    };
    let normals = match by_name("NORMAL") {
        Some(a) => Some(values(a, 3, "NORMAL")?.chunks_exact(3).map(Vec3::from_slice).collect()),
        None => None,
    };
    let indices: Vec<u32> = mesh.faces.iter().flatten().map(|&p| usize::from(p) as u32).collect();
    if let Some(bad) = indices.iter().find(|&&i| i as usize >= points) {
        bail!("a Draco face uses point {bad} of {points}");
    }
    Ok((positions, uvs, normals, indices))
}

/// The instance transforms of a node with `EXT_mesh_gpu_instancing` (float TRANSLATION,
/// ROTATION and SCALE, each optional), or None without the extension.
fn gpu_instances(
    doc: &gltf::Document,
    buffers: &[gltf::buffer::Data],
    node: &gltf::Node,
) -> anyhow::Result<Option<Vec<glam::Mat4>>> {
    let Some(ext) = node.extension_value("EXT_mesh_gpu_instancing") else { return Ok(None) };
    let read = |name: &str, width: usize| -> anyhow::Result<Option<Vec<f32>>> {
        let Some(index) = ext["attributes"].get(name) else { return Ok(None) };
        let accessor = index
            .as_u64()
            .and_then(|i| doc.accessors().nth(i as usize))
            .with_context(|| format!("{name}: no accessor {index}"))?;
        let kind = if width == 4 { gltf::accessor::Dimensions::Vec4 } else { gltf::accessor::Dimensions::Vec3 };
        anyhow::ensure!(
            accessor.data_type() == gltf::accessor::DataType::F32 && accessor.dimensions() == kind,
            "{name}: accessor {} is not float VEC{width}",
            accessor.index()
        );
        // The gltf crate's iterator takes one element off an empty accessor's length.
        anyhow::ensure!(accessor.count() > 0, "{name}: accessor {} is empty", accessor.index());
        let data = |b: gltf::Buffer| buffers.get(b.index()).map(|d| &d[..]);
        let unreadable = || format!("{name}: accessor {} cannot be read", accessor.index());
        let floats: Vec<f32> = if width == 4 {
            gltf::accessor::Iter::<[f32; 4]>::new(accessor.clone(), data).with_context(unreadable)?.flatten().collect()
        } else {
            gltf::accessor::Iter::<[f32; 3]>::new(accessor.clone(), data).with_context(unreadable)?.flatten().collect()
        };
        anyhow::ensure!(floats.len() == width * accessor.count(), "{name}: accessor {} is short", accessor.index());
        Ok(Some(floats))
    };
    let (t, r, s) = (read("TRANSLATION", 3)?, read("ROTATION", 4)?, read("SCALE", 3)?);
    let count = [t.as_ref().map(|v| v.len() / 3), r.as_ref().map(|v| v.len() / 4), s.as_ref().map(|v| v.len() / 3)];
    let Some(n) = count.iter().flatten().next().copied() else { anyhow::bail!("no instance attributes") };
    anyhow::ensure!(count.iter().flatten().all(|&c| c == n), "instance attributes differ in count: {count:?}");
    Ok(Some(
        (0..n)
            .map(|i| {
                let t = t.as_ref().map_or(Vec3::ZERO, |v| Vec3::from_slice(&v[3 * i..]));
                let r = r.as_ref().map_or(glam::Quat::IDENTITY, |v| glam::Quat::from_slice(&v[4 * i..]).normalize());
                let s = s.as_ref().map_or(Vec3::ONE, |v| Vec3::from_slice(&v[3 * i..]));
                glam::Mat4::from_scale_rotation_translation(s, r, t)
            })
            .collect(),
    ))
}

/// Loads every mesh of a glTF file's default scene (node transforms applied) with `gltf`;
/// Draco-compressed primitives (`KHR_draco_mesh_compression`) with `draco-oxide-decoder`.
pub fn load_gltf(path: &std::path::Path) -> anyhow::Result<Mesh> {
    let (doc, buffers) = import_gltf(path).with_context(|| format!("cannot parse glTF file {}", path.display()))?;
    let mut positions = Vec::new();
    let mut uvs = Vec::new();
    let mut normals = Vec::new();
    let mut indices = Vec::new();
    let (mut all_uvs, mut all_normals) = (true, true);
    let mut part_starts = Vec::new();
    let scene = doc
        .default_scene()
        .or_else(|| doc.scenes().next())
        .with_context(|| format!("{} has no scene", path.display()))?;
    // Depth first in document order (a stack popped from its end holds siblings reversed),
    // so parts come in the order an exporter wrote its objects.
    let mut stack: Vec<(gltf::Node, glam::Mat4)> = scene.nodes().map(|n| (n, glam::Mat4::IDENTITY)).collect();
    stack.reverse();
    while let Some((node, parent)) = stack.pop() {
        let world = parent * glam::Mat4::from_cols_array_2d(&node.transform().matrix());
        let children: Vec<_> = node.children().map(|c| (c, world)).collect();
        stack.extend(children.into_iter().rev());
        let Some(mesh) = node.mesh() else { continue };
        let instances = gpu_instances(&doc, &buffers, &node)
            .with_context(|| format!("{}: node {} (EXT_mesh_gpu_instancing)", path.display(), node.index()))?;
        let mut prims = Vec::new();
        for prim in mesh.primitives() {
            if prim.mode() != gltf::mesh::Mode::Triangles {
                continue;
            }
            let (pos, prim_uvs, prim_normals, prim_indices) = match prim.extension_value(DRACO) {
                Some(ext) => draco_primitive(&doc, &buffers, ext)
                    .with_context(|| format!("{}: mesh {} primitive {}", path.display(), mesh.index(), prim.index()))?,
                None => {
                    let reader = prim.reader(|b| buffers.get(b.index()).map(|d| &d[..]));
                    let Some(pos) = reader.read_positions() else { continue };
                    let pos: Vec<Vec3> = pos.map(Vec3::from).collect();
                    let count = pos.len() as u32;
                    (
                        pos,
                        reader.read_tex_coords(0).map(|t| t.into_f32().map(Vec2::from).collect()),
                        reader.read_normals().map(|n| n.map(Vec3::from).collect()),
                        match reader.read_indices() {
                            Some(i) => i.into_u32().collect(),
                            None => (0..count).collect(),
                        },
                    )
                }
            };
            prims.push((pos, prim_uvs, prim_normals, prim_indices));
        }
        // Each instance (one without the extension) is a pattern piece per primitive.
        for instance in instances.unwrap_or_else(|| vec![glam::Mat4::IDENTITY]) {
            let world = world * instance;
            let normal_matrix = glam::Mat3::from_mat4(world).inverse().transpose();
            for (pos, prim_uvs, prim_normals, prim_indices) in &prims {
                let base = positions.len() as u32;
                part_starts.push(positions.len());
                positions.extend(pos.iter().map(|p| world.transform_point3(*p)));
                match prim_uvs {
                    Some(t) => uvs.extend_from_slice(t),
                    None => all_uvs = false,
                }
                match prim_normals {
                    Some(n) => normals.extend(n.iter().map(|n| normal_matrix * *n)),
                    None => all_normals = false,
                }
                indices.extend(prim_indices.iter().map(|i| i + base));
            }
        }
    }
    if positions.is_empty() {
        bail!("{} contains no triangle geometry", path.display());
    }
    Mesh::build(positions, all_uvs.then_some(uvs), all_normals.then_some(normals), indices)
        .map(|m| with_pieces(m, &part_starts))
        .with_context(|| format!("invalid mesh in {}", path.display()))
}

/// Loads a mesh file by its extension: .obj, .gltf or .glb.
pub fn load_mesh_file(path: &std::path::Path) -> anyhow::Result<Mesh> {
    match path.extension().and_then(|e| e.to_str()).map(str::to_ascii_lowercase).as_deref() {
        Some("obj") => load_obj(path),
        Some("gltf" | "glb") => load_gltf(path),
        _ => bail!("{}: unsupported mesh format (use .obj, .gltf or .glb)", path.display()),
    }
}

//! The avatar technique: MakeHuman's base mesh with its helper geometry hidden, skinned by its
//! default skeleton and weights ([`rig`], LBS or DQS), posed from BVH motions ([`bvh`])
//! retargeted through joint maps ([`retarget`]), and `.mhclo` proxy garments fitted to the
//! posed body ([`mhclo`]). See docs/avatar.md.

pub mod bvh;
pub mod mhclo;
pub mod obj;
pub mod retarget;
pub mod rig;
pub mod walk;

use std::path::Path;

use anyhow::Context as _;
use glam::{Vec2, Vec3};

use crate::mesh::{Mesh, vertex_normals};
use obj::{Obj, SplitMesh, is_helper_group};

/// A skeleton's joints (its bones' heads) where the body stands at rest, in metres, by bone name:
/// what a garment fits its sleeves to (`Avatar`'s `joints` output).
#[derive(Clone, Debug, PartialEq)]
pub struct Joints {
    pub names: Vec<String>,
    pub rest: Vec<Vec3>,
}

impl Joints {
    /// The rest position of the head of bone `name`.
    pub fn rest_head(&self, name: &str) -> Option<Vec3> {
        self.names.iter().position(|n| n == name).map(|i| self.rest[i])
    }
}

/// The base mesh: every vertex (helpers included: joints and proxies refer to them), the
/// visible faces split by UV, and the visible faces as a welded triangle mesh for collisions.
#[derive(Clone, Debug)]
pub struct Body {
    pub obj: Obj,
    /// Visible faces, split where UVs differ (the drawn Surface).
    pub surface: SplitMesh,
    /// Base vertices the visible faces use, ascending (the collision mesh's vertices).
    pub collision_vertices: Vec<u32>,
    /// The visible triangles over `collision_vertices`.
    pub collision_indices: Vec<u32>,
    /// Faces hidden as helper geometry, and the number of visible faces.
    pub hidden_faces: usize,
    pub visible_faces: usize,
}

impl Body {
    pub fn load(path: &Path) -> anyhow::Result<Body> {
        Body::from_obj(Obj::load(path)?).with_context(|| format!("in {}", path.display()))
    }

    pub fn from_obj(obj: Obj) -> anyhow::Result<Body> {
        let visible = |f: &obj::Face| !is_helper_group(&obj.groups[f.group as usize]);
        let surface = SplitMesh::new(&obj, visible);
        anyhow::ensure!(!surface.indices.is_empty(), "every face is helper geometry");
        let visible_faces = obj.faces.iter().filter(|f| visible(f)).count();
        let mut used = vec![u32::MAX; obj.positions.len()];
        let mut collision_vertices: Vec<u32> = surface.welded.clone();
        collision_vertices.sort_unstable();
        collision_vertices.dedup();
        for (k, v) in collision_vertices.iter().enumerate() {
            used[*v as usize] = k as u32;
        }
        let collision_indices = surface.welded.iter().map(|v| used[*v as usize]).collect();
        Ok(Body {
            hidden_faces: obj.faces.len() - visible_faces,
            visible_faces,
            obj,
            surface,
            collision_vertices,
            collision_indices,
        })
    }

    /// The lowest visible point at rest (the feet), to stand the body on y = 0.
    pub fn floor(&self) -> f32 {
        self.collision_vertices.iter().map(|v| self.obj.positions[*v as usize].y).fold(f32::INFINITY, f32::min)
    }
}

/// A Surface of `split` over base-mesh positions `posed`, each placed by `place`; normals are
/// computed on the welded triangles (smooth across UV seams). Triangles with a corner in
/// `hidden` are left out.
pub fn split_surface(
    split: &SplitMesh,
    posed: &[Vec3],
    place: impl Fn(Vec3) -> Vec3,
    hidden: Option<&[bool]>,
) -> anyhow::Result<Mesh> {
    let placed: Vec<Vec3> = posed.iter().map(|p| place(*p)).collect();
    let normals = vertex_normals(&placed, &split.welded);
    let positions: Vec<Vec3> = split.source.iter().map(|v| placed[*v as usize]).collect();
    let nrm: Vec<Vec3> = split.source.iter().map(|v| normals[*v as usize].normalize_or(Vec3::Y)).collect();
    let indices: Vec<u32> = match hidden {
        None => split.indices.clone(),
        Some(h) => split
            .indices
            .chunks_exact(3)
            .zip(split.welded.chunks_exact(3))
            .filter(|(_, w)| !w.iter().any(|v| h.get(*v as usize).copied().unwrap_or(false)))
            .flat_map(|(t, _)| t.iter().copied())
            .collect(),
    };
    let uvs: Vec<Vec2> = split.uvs.clone();
    let pieces = vec![0; positions.len()];
    Mesh::from_parts(positions, Some(nrm), uvs, indices, pieces)
}

/// The collision mesh of `body` at base-mesh positions `posed`: the visible triangles, welded,
/// the same vertices and triangles every frame.
pub fn collision_mesh(body: &Body, posed: &[Vec3], place: impl Fn(Vec3) -> Vec3) -> anyhow::Result<Mesh> {
    let positions = body.collision_vertices.iter().map(|v| place(posed[*v as usize])).collect();
    Mesh::build(positions, None, None, body.collision_indices.clone())
}

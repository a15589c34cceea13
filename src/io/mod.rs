//! Writing files: atomically, images (PNG, EXR), charts (SVG) and geometry (OBJ, PLY, glTF, USD ASCII); reading
//! mesh caches: USD (text and binary) and Alembic.

use glam::{Vec2, Vec3};

pub mod alembic;
pub mod atomic;
pub mod geometry;
pub mod image;
pub mod svg;
pub mod usd;
pub mod usda;
pub mod usdc;

/// No index (a corner without a UV or normal).
pub const NONE: u32 = u32::MAX;

/// One polygon mesh of a cache at one time, in world space (Y up, metres) with
/// counter-clockwise faces.
#[derive(Debug, Clone)]
pub struct PolySample {
    pub positions: Vec<Vec3>,
    /// Corners per face.
    pub face_counts: Vec<u32>,
    /// Per corner (faces one after another): position index, UV index, normal index (or NONE).
    pub corners: Vec<[u32; 3]>,
    /// UVs as stored (v up); `has_uvs`: the mesh has UVs (even if there are none now).
    pub uvs: Vec<Vec2>,
    pub has_uvs: bool,
    pub normals: Vec<Vec3>,
}

//! Mesh nodes: primitives, mesh files and transforms, the skinned avatar, mesh sequences, the
//! live link.

pub mod avatar;
pub mod geometry;
pub mod live_link;
pub mod mesh_sequence;

//! Mesh nodes: primitives, mesh files and transforms, mesh sequences, the live link.

pub mod geometry;
pub mod live_link;
pub mod mesh_sequence;

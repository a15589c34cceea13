//! Tessellation nodes (src/tessellation/).

pub mod tessellate;

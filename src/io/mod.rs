//! Writing files: atomically, images (PNG, EXR) and geometry (OBJ, PLY).

pub mod atomic;
pub mod geometry;
pub mod image;

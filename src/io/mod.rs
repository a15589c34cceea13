//! Writing files: atomically, images (PNG, EXR) and geometry (OBJ, PLY, glTF, USD ASCII); reading
//! USD ASCII and Alembic caches.

pub mod alembic;
pub mod atomic;
pub mod geometry;
pub mod image;
pub mod usda;

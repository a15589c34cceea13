//! Cuboid nodes (src/cuboid/): cuboids, grids of them, deformation.

#[allow(clippy::module_inception)]
pub mod cuboid;
pub mod cuboid_grid;

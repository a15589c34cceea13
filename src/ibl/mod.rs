//! Image-based lighting on the CPU: cube map conventions and probes ([`cube`]), the median
//! cut into equal-energy regions ([`median_cut`]), partial environment maps' filter kernels
//! and glossiness calibration ([`pem`]), and the Monte-Carlo reference ([`reference`]).
//! The GPU nodes (nodes/ibl/environment_map.rs, nodes/ibl/median_cut.rs, nodes/ibl/pems.rs,
//! nodes/ibl/ibl_shading.rs) run the same algorithms; these are their twins and their tests.

pub mod cube;
pub mod gpu;
pub mod median_cut;
pub mod pem;
pub mod reference;
pub mod shadow;
pub mod shadow_fit;

//! Occlusion nodes (src/occlusion/): SSAO, the ray-traced reference, hybrid occlusion.

pub mod hybrid_occlusion;
pub mod reference_occlusion;
pub mod ssao;

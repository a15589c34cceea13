//! Occlusion nodes (src/occlusion/): SSAO, the ray-traced reference, hybrid occlusion, and the
//! screen-space bounce of diffuse light and screen-space reflections.

pub mod bounce;
pub mod hybrid_occlusion;
pub mod reference_occlusion;
pub mod ssao;
pub mod ssr;

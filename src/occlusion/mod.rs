//! Ambient occlusion: screen-space (SSAO, [`ssao`]) and the ray-traced reference it is measured
//! against ([`reference`]). The nodes (nodes/occlusion/) run them and combine them with the
//! shadowed IBL result (hybrid occlusion).

pub mod reference;
pub mod ssao;

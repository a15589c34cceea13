//! Image-based lighting nodes (src/ibl/): environment maps, median-cut lights, prefiltered environment maps, the shadow atlas, IBL shading.

pub mod environment_map;
pub mod ibl_shading;
pub mod median_cut;
pub mod pems;
pub mod shadow_atlas;
pub mod sun_light;

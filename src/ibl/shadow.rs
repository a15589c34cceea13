//! The shadow atlas value that flows from `ShadowAtlas` (nodes/ibl/shadow_atlas.rs) to
//! `IblShading`: here, below the port table, so the port types need no node module.

use glam::{Mat4, Vec3};

use crate::gpu::GpuImage;

/// One light's tile of an atlas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShadowLight {
    /// Unit direction toward the light.
    pub direction: Vec3,
    /// World to the light's clip space (orthographic; depth 0..1 across the bounding sphere).
    pub view_proj: Mat4,
    /// World to atlas coordinates: x, y in [0, 1] over the whole atlas, z the light's depth.
    pub to_atlas: Mat4,
    /// The tile in texels: x, y, width, height (guard included).
    pub rect: [u32; 4],
    /// The blur's standard deviation in texels.
    pub sigma: f32,
}

/// Lookup settings carried with the atlas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VsmParams {
    pub min_variance: f32,
    pub bleed_reduction: f32,
    /// Jitter radius in texels (0 = off).
    pub jitter: f32,
    /// World units along the normal.
    pub normal_offset: f32,
    /// Depth units (0..1 spans 2R).
    pub depth_bias: f32,
}

/// `ShadowAtlas`'s output: the moments texture and every light's tile.
pub struct ShadowAtlas {
    /// Rg16Float moments (c, c^2) of the centred depth c = d - 1/2, blurred per tile.
    pub atlas: GpuImage,
    pub lights: Vec<ShadowLight>,
    pub tile_size: u32,
    pub guard: u32,
    pub columns: u32,
    /// Bounding sphere of the occluders.
    pub center: Vec3,
    pub radius: f32,
    /// World size of one texel.
    pub texel_world: f32,
    pub params: VsmParams,
    pub bytes: u64,
}

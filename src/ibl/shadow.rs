//! The shadow atlas value that flows from `ShadowAtlas` (nodes/ibl/shadow_atlas.rs) to
//! `IblShading`: here, below the port table, so the port types need no node module.

use glam::{Mat4, Vec2, Vec3};

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
    /// World size of one of the tile's texels.
    pub texel_world: f32,
    /// The lookup point's offset along the normal, world units (VsmParams::normal_offset texels).
    pub normal_offset: f32,
}

/// Lookup settings carried with the atlas.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct VsmParams {
    pub min_variance: f32,
    pub bleed_reduction: f32,
    /// Jitter radius in texels (0 = off).
    pub jitter: f32,
    /// Texels of each light's tile along the normal (ShadowLight::normal_offset in world units).
    pub normal_offset: f32,
    /// Depth units (0..1 spans 2R).
    pub depth_bias: f32,
}

/// `ShadowAtlas`'s output: the moments texture and every light's tile.
pub struct ShadowAtlas {
    /// Rg16Float moments (c, c^2) of the centred depth c = d - 1/2, blurred per tile.
    pub atlas: GpuImage,
    pub lights: Vec<ShadowLight>,
    /// The tile_size parameter (tiles sized by penumbra differ; see each light's rect).
    pub tile_size: u32,
    /// The widest guard band.
    pub guard: u32,
    /// Bounding sphere of the occluders.
    pub center: Vec3,
    pub radius: f32,
    /// World size of the coarsest light's texel (the normal offset's unit).
    pub texel_world: f32,
    pub params: VsmParams,
    pub bytes: u64,
}

impl ShadowAtlas {
    /// Light `k`'s tile in atlas coordinates, inset by half a texel (x0, y0, x1, y1): where a
    /// bilinear lookup clamped to it reads only that tile.
    pub fn lookup_rect(&self, k: usize) -> [f32; 4] {
        let (w, h) = (self.atlas.width as f32, self.atlas.height as f32);
        let [x, y, tw, th] = self.lights[k].rect.map(|v| v as f32);
        [(x + 0.5) / w, (y + 0.5) / h, (x + tw - 0.5) / w, (y + th - 0.5) / h]
    }
}

/// A directional light as the shaders that read its tile themselves take it
/// (shaders/ibl/shadowed_light.wgsl `Light`: BtfShading, ScreenSpaceReflections).
#[repr(C)]
#[derive(Clone, Copy, Debug, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuLight {
    /// xyz towards the light; w a code of the shader that reads it.
    pub dir: [f32; 4],
    /// rgb: irradiance on a surface facing it.
    pub color: [f32; 4],
    /// World to its tile's atlas coordinates (zero: unshadowed).
    pub to_atlas: [[f32; 4]; 4],
    /// Its tile in atlas coordinates, inset by half a texel.
    pub rect: [f32; 4],
    /// x: 1 where shadowed, y: the lookup's normal offset (world units).
    pub shadow: [f32; 4],
}

impl GpuLight {
    pub fn unshadowed(dir: [f32; 4], color: [f32; 4]) -> GpuLight {
        GpuLight { dir, color, ..bytemuck::Zeroable::zeroed() }
    }

    /// This light with the visibility of `atlas`'s light `k`.
    pub fn shadowed_by(self, atlas: &ShadowAtlas, k: usize) -> GpuLight {
        GpuLight {
            to_atlas: atlas.lights[k].to_atlas.to_cols_array_2d(),
            rect: atlas.lookup_rect(k),
            shadow: [1.0, atlas.lights[k].normal_offset, 0.0, 0.0],
            ..self
        }
    }
}

/// `lights` (a MedianCut's or SunLight's, RegionLight colours scaled by `scale`, `code` in
/// dir.w) for the shaders, each with its tile of `atlas` where one is given; an atlas of another
/// number of lights is an error naming the two inputs, `shadows` and `lights`.
pub fn gpu_lights(
    lights: &[crate::ibl::median_cut::RegionLight],
    atlas: Option<&ShadowAtlas>,
    code: f32,
    scale: f32,
) -> Result<Vec<GpuLight>, String> {
    if let Some(a) = atlas
        && a.lights.len() != lights.len()
    {
        return Err(format!(
            "input \"shadows\" holds {} lights but input \"lights\" has {}: feed both from the same MedianCut or SunLight",
            a.lights.len(),
            lights.len()
        ));
    }
    Ok(lights
        .iter()
        .enumerate()
        .map(|(k, l)| {
            let light =
                GpuLight::unshadowed(l.direction.extend(code).to_array(), (l.color * scale).extend(0.0).to_array());
            atlas.map_or(light, |a| light.shadowed_by(a, k))
        })
        .collect())
}

/// `vsm` of shaders/ibl/shadowed_light.wgsl: the atlas's minimum variance, bleed reduction and
/// depth bias (zero without an atlas).
pub fn vsm_settings(atlas: Option<&ShadowAtlas>) -> [f32; 3] {
    atlas.map_or([0.0; 3], |a| [a.params.min_variance, a.params.bleed_reduction, a.params.depth_bias])
}

/// A light's view: looking along -`direction` at the sphere (c, r) from 2r away.
pub fn light_view(direction: Vec3, center: Vec3, radius: f32) -> Mat4 {
    let l = direction.normalize_or(Vec3::Y);
    let up = if l.y.abs() > 0.99 { Vec3::Z } else { Vec3::Y };
    Mat4::look_at_rh(center + l * 2.0 * radius, center, up)
}

/// The orthographic view of a light along -`direction` fitted to the sphere (c, r), its
/// inner square [-r, r] mapped to the tile minus `guard` texels per side.
pub fn light_view_proj(direction: Vec3, center: Vec3, radius: f32, tile: u32, guard: u32) -> Mat4 {
    tile_view_proj(direction, center, radius, (Vec2::ZERO, radius), tile, guard)
}

/// The orthographic view of a light in the frame of [`light_view`] (depth 0..1 across the
/// sphere (c, r)) whose inner square, centre `square.0` (light-view x, y) and half width
/// `square.1`, maps to the tile minus `guard` texels per side. The centre is snapped to whole
/// texels, so a moving camera with the same extent does not make the shadow's edges crawl.
pub fn tile_view_proj(direction: Vec3, center: Vec3, radius: f32, square: (Vec2, f32), tile: u32, guard: u32) -> Mat4 {
    let ext = square.1 * tile as f32 / (tile - 2 * guard).max(1) as f32;
    let texel = 2.0 * ext / tile as f32;
    let c = (square.0 / texel).round() * texel;
    Mat4::orthographic_rh(c.x - ext, c.x + ext, c.y - ext, c.y + ext, radius, 3.0 * radius)
        * light_view(direction, center, radius)
}

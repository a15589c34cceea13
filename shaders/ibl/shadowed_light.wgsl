// A directional light that carries its shadow-atlas tile (src/ibl/shadow.rs `GpuLight`), for
// the passes that read the tiles themselves (BtfShading, ScreenSpaceReflections): dir.xyz
// towards the light (dir.w: the reading shader's code), color.rgb its irradiance on a surface
// facing it; where shadow.x is 1, its visibility comes from its tile: world to atlas
// coordinates, the tile inset by half a texel, the lookup moved shadow.y along the normal.

// #include "vsm_visibility.wgsl"

struct Light {
    dir: vec4<f32>,
    color: vec4<f32>,
    to_atlas: mat4x4<f32>,
    rect: vec4<f32>,
    shadow: vec4<f32>,
};

// VIS of `light` at world position p with normal n (1 where unshadowed), as IblShading's
// `visibility` without jitter; vsm: the atlas's min variance, bleed reduction and depth bias.
fn light_visibility(light: Light, atlas: texture_2d<f32>, samp: sampler, p: vec3<f32>, n: vec3<f32>, vsm: vec3<f32>) -> f32 {
    if light.shadow.x < 0.5 {
        return 1.0;
    }
    let c = light.to_atlas * vec4<f32>(p + n * light.shadow.y, 1.0);
    let uv = clamp(c.xy, light.rect.xy, light.rect.zw);
    let m = textureSampleLevel(atlas, samp, uv, 0.0).xy;
    return chebyshev_visibility(m, c.z - vsm.z, vsm.x, vsm.y);
}

// IblShading (shaders/ibl/ibl_shading_common.wgsl) sampling the cube maps with the hardware's
// seamless trilinear filtering: the faces (+X -X +Y -Y +Z -Z, shaders/ibl/cube.wgsl) are laid
// out as Vulkan, Metal and D3D select cube faces, so one textureSampleLevel replaces the eight
// taps of cube_trilinear. ibl_shading.wgsl is its reference twin.

@group(0) @binding(5) var env: texture_cube<f32>;
@group(0) @binding(6) var pem0: texture_cube<f32>;
@group(0) @binding(7) var pem1: texture_cube<f32>;
@group(0) @binding(8) var pem2: texture_cube<f32>;
@group(0) @binding(9) var pem3: texture_cube<f32>;
@group(0) @binding(10) var pem4: texture_cube<f32>;
@group(0) @binding(11) var pem5: texture_cube<f32>;
@group(0) @binding(12) var pem6: texture_cube<f32>;
@group(0) @binding(13) var pem7: texture_cube<f32>;

// `samp` (binding 16) is trilinear; the address mode does not apply to cube maps.
fn lookup(tex: texture_cube<f32>, d: vec3<f32>, lod: f32) -> vec3<f32> {
    return textureSampleLevel(tex, samp, d, lod).rgb;
}

// The diffuse ends of the pass's PEMs as a cube array (PEM k is cube k), or of the full map.
@group(0) @binding(17) var diffuse_ends: texture_cube_array<f32>;

// The sampler finds the texels itself.
fn diffuse_taps(d: vec3<f32>) -> CubeTaps {
    return CubeTaps();
}

fn diffuse_end(k: u32, d: vec3<f32>, taps: CubeTaps) -> vec3<f32> {
    return textureSampleLevel(diffuse_ends, samp, d, i32(k), 0.0).rgb;
}

// #include "ibl_shading_common.wgsl"

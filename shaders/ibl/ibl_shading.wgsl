// IblShading (shaders/ibl/ibl_shading_common.wgsl) reading the cube maps with textureLoad and
// the seamless lookups of cube.wgsl: the reference twin of ibl_shading_hw.wgsl, and the path
// where the faces cannot be viewed as a cube (wgpu's GL backend, see src/gpu/texture.rs).

// Cube maps as six-layer arrays with mips (shaders/ibl/cube.wgsl).
@group(0) @binding(5) var env: texture_2d_array<f32>;
@group(0) @binding(6) var pem0: texture_2d_array<f32>;
@group(0) @binding(7) var pem1: texture_2d_array<f32>;
@group(0) @binding(8) var pem2: texture_2d_array<f32>;
@group(0) @binding(9) var pem3: texture_2d_array<f32>;
@group(0) @binding(10) var pem4: texture_2d_array<f32>;
@group(0) @binding(11) var pem5: texture_2d_array<f32>;
@group(0) @binding(12) var pem6: texture_2d_array<f32>;
@group(0) @binding(13) var pem7: texture_2d_array<f32>;

// Levels read by a counted loop (cube_trilinear_counted): set on wgpu's GL backend only.
override COUNTED_LEVELS: bool = false;

fn lookup(tex: texture_2d_array<f32>, d: vec3<f32>, lod: f32) -> vec3<f32> {
    if COUNTED_LEVELS {
        return cube_trilinear_counted(tex, u32(ibl.face_size), ibl.top_level, d, lod).rgb;
    }
    return cube_trilinear(tex, u32(ibl.face_size), ibl.top_level, d, lod).rgb;
}

// The diffuse ends of the pass's PEMs (PEM k at layers 6k..6k+5), or of the full map.
@group(0) @binding(17) var diffuse_ends: texture_2d_array<f32>;

// The diffuse end's four texels along d: found once per pixel, read for every PEM.
fn diffuse_taps(d: vec3<f32>) -> CubeTaps {
    return cube_taps(u32(ibl.diffuse.x), d);
}

fn diffuse_end(k: u32, d: vec3<f32>, taps: CubeTaps) -> vec3<f32> {
    return cube_gather(diffuse_ends, 0, 6u * k, taps).rgb;
}

// #include "ibl_shading_common.wgsl"

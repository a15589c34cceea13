// A cube map shown as an equirectangular (latitude-longitude) image, for the viewport and
// --dump: the probe as loaded, a PEM, their mip levels.

struct Params {
    size: vec2<f32>,
    level: f32,
    scale: f32,
    // Face size of level 0, last mip level.
    face_size: u32,
    top: f32,
    pad: vec2<f32>,
};

@group(0) @binding(0) var<uniform> p: Params;
@group(0) @binding(1) var cube: texture_2d_array<f32>;

// #include "fullscreen.wgsl"
// #include "cube.wgsl"

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let d = equirect_dir(frag.xy / p.size);
    return vec4<f32>(cube_trilinear(cube, p.face_size, p.top, d, p.level).rgb * p.scale, 1.0);
}

// Variance shadow maps (nodes/ibl/shadow_atlas.rs): the moments of each tile's depth; the
// per-tile blur is shaders/ibl/vsm_blur.wgsl.

// #include "fullscreen.wgsl"

// Binding 0 (a uniform) is unused: FullscreenPass binds one first.
@group(0) @binding(0) var<uniform> unused: vec4<f32>;
// Bound as unfilterable float, not texture_depth_2d: GLSL cannot texelFetch a depth texture.
@group(0) @binding(1) var depth_tiles: texture_2d<f32>;

// The moments (c, c^2) of the centred light depth c = d - 1/2 (d in [0, 1]; texels outside
// every tile hold d = 1). Centring keeps the scene's depths near zero, where the half floats
// of the atlas are finest: the variance m2 - m1^2 cancels less, so deep shadows leak less
// (Chebyshev's bound is the same for any shift of the depths).
@fragment
fn fs_moments(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let c = textureLoad(depth_tiles, vec2<i32>(frag.xy), 0).x - 0.5;
    return vec4<f32>(c, c * c, 0.0, 0.0);
}

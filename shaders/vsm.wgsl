// Variance shadow maps (nodes/shadow_atlas.rs): the moments of each tile's depth; the
// per-tile blur is shaders/vsm_blur.wgsl.

// #include "fullscreen.wgsl"

// Binding 0 (a uniform) is unused: FullscreenPass binds one first.
@group(0) @binding(0) var<uniform> unused: vec4<f32>;
@group(0) @binding(1) var depth_tiles: texture_depth_2d;

// (d, d^2) of the orthographic light depth d in [0, 1]; texels outside every tile hold 1.
@fragment
fn fs_moments(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let d = textureLoad(depth_tiles, vec2<i32>(frag.xy), 0);
    return vec4<f32>(d, d * d, 0.0, 0.0);
}

// Hybrid occlusion (nodes/occlusion/hybrid_occlusion.rs): an image modulated by the local occlusion
// factor, once, after all lights (dissertation §3.2.2): out = image x factor (rgb).

// #include "fullscreen.wgsl"

@group(0) @binding(0) var<uniform> unused: vec4<f32>;
@group(0) @binding(1) var image: texture_2d<f32>;
@group(0) @binding(2) var factor: texture_2d<f32>;

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let px = vec2<i32>(frag.xy);
    let c = textureLoad(image, px, 0);
    return vec4<f32>(c.rgb * textureLoad(factor, px, 0).rgb, c.a);
}

// The per-channel difference of two images (nodes/compare/image_difference.rs): a visible version
// (|a - b| times a gain, clamped, for an sRGB target) and the raw one (linear, unclamped).

struct Params {
    // The visible image's gain.
    gain: f32,
    // Scalars, not a vec3: a vec3 aligns to 16 bytes and would make the struct 32.
    pad0: f32,
    pad1: f32,
    pad2: f32,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var image_a: texture_2d<f32>;
@group(0) @binding(2) var image_b: texture_2d<f32>;

// #include "fullscreen.wgsl"

struct DifferenceOut {
    @location(0) visible: vec4<f32>,
    @location(1) raw: vec4<f32>,
};

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> DifferenceOut {
    let texel = vec2<i32>(frag.xy);
    let d = abs(textureLoad(image_a, texel, 0) - textureLoad(image_b, texel, 0));
    var out: DifferenceOut;
    out.visible = vec4<f32>(clamp(d.rgb * params.gain, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
    out.raw = d;
    return out;
}

// Exposure and tone mapping of an HDR image to display range; the sRGB target encodes.

struct Params {
    // 2^stops.
    exposure: f32,
    // 0 none, 1 Reinhard, 2 ACES, 3 filmic.
    curve: u32,
    pad: vec2<f32>,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var hdr: texture_2d<f32>;

// #include "fullscreen.wgsl"

// Narkowicz's fit of the ACES filmic curve.
fn aces(x: vec3<f32>) -> vec3<f32> {
    return clamp((x * (2.51 * x + 0.03)) / (x * (2.43 * x + 0.59) + 0.14), vec3<f32>(0.0), vec3<f32>(1.0));
}

// Hable's Uncharted 2 curve, white point 11.2.
fn hable(x: vec3<f32>) -> vec3<f32> {
    let a = 0.15; let b = 0.50; let c = 0.10; let d = 0.20; let e = 0.02; let f = 0.30;
    return ((x * (a * x + c * b) + d * e) / (x * (a * x + b) + d * f)) - e / f;
}

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let c = textureLoad(hdr, vec2<i32>(frag.xy), 0).rgb * params.exposure;
    let op = params.curve;
    var mapped = c;
    if op == 1 {
        mapped = c / (1.0 + c);
    } else if op == 2 {
        mapped = aces(c);
    } else if op == 3 {
        mapped = hable(2.0 * c) / hable(vec3<f32>(11.2));
    }
    return vec4<f32>(clamp(mapped, vec3<f32>(0.0), vec3<f32>(1.0)), 1.0);
}

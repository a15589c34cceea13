// The editor viewport: any viewable texture converted to gamma-encoded Rgba8Unorm, which is
// what egui samples (mode 0 linear colour, 1 already encoded, 2 one channel of distances).
struct Settings { mode: u32, pad0: u32, pad1: u32, pad2: u32 };
@group(0) @binding(0) var<uniform> settings: Settings;
@group(0) @binding(1) var src: texture_2d<f32>;

// #include "fullscreen.wgsl"

fn gamma(c: vec3<f32>) -> vec3<f32> {
    let x = clamp(c, vec3<f32>(0.0), vec3<f32>(1.0));
    let lo = x * 12.92;
    let hi = 1.055 * pow(x, vec3<f32>(1.0 / 2.4)) - 0.055;
    return select(hi, lo, x <= vec3<f32>(0.0031308));
}

@fragment
fn fs_main(@builtin(position) p: vec4<f32>) -> @location(0) vec4<f32> {
    let t = textureLoad(src, vec2<i32>(p.xy), 0);
    switch settings.mode {
        // Linear colour (sRGB textures read as linear, HDR floats): encode for display.
        case 0u: { return vec4<f32>(gamma(t.rgb), 1.0); }
        // Already display-encoded.
        case 1u: { return vec4<f32>(t.rgb, 1.0); }
        // One channel of distances: map [0, inf) to [0, 1).
        default: {
            let v = max(t.r, 0.0);
            return vec4<f32>(gamma(vec3<f32>(v / (v + 1.0))), 1.0);
        }
    }
}

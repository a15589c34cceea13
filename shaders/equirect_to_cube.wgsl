// An equirectangular light probe resampled into one face of a cube map's level 0: each
// texel the mean of 4x4 bilinear lookups spread over it (src/ibl/cube.rs
// cube_from_equirect is the CPU twin), rotated about +Y and scaled by the intensity.

struct Params {
    face: u32,
    size: u32,
    probe_width: u32,
    probe_height: u32,
    // cos and sin of minus the rotation about +Y; the intensity.
    rotation: vec2<f32>,
    intensity: f32,
    pad: f32,
};

@group(0) @binding(0) var<uniform> p: Params;
// Rgba32Float: read with textureLoad so the lookup is the CPU twin's, not the sampler's.
@group(0) @binding(1) var probe: texture_2d<f32>;

// #include "fullscreen.wgsl"
// #include "cube.wgsl"

const SUPERSAMPLE: u32 = 4u;

fn probe_texel(x: i32, y: i32) -> vec3<f32> {
    return textureLoad(probe, vec2<i32>(x, y), 0).rgb;
}

// EquirectImage::sample: wraps in azimuth, clamps at the poles.
fn probe_bilinear(d: vec3<f32>) -> vec3<f32> {
    let uv = equirect_uv(d);
    let w = i32(p.probe_width);
    let h = f32(p.probe_height);
    let px = uv.x * f32(p.probe_width) - 0.5;
    let py = clamp(uv.y * h - 0.5, 0.0, h - 1.0);
    let fx = floor(px);
    let fy = floor(py);
    let t = vec2<f32>(px - fx, py - fy);
    let x0 = ((i32(fx) % w) + w) % w;
    let x1 = ((i32(fx) + 1) % w + w) % w;
    let y0 = i32(fy);
    let y1 = min(y0 + 1, i32(p.probe_height) - 1);
    let top = mix(probe_texel(x0, y0), probe_texel(x1, y0), t.x);
    let bottom = mix(probe_texel(x0, y1), probe_texel(x1, y1), t.x);
    return mix(top, bottom, t.y);
}

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let texel = vec2<f32>(floor(frag.xy));
    let s = f32(p.size);
    let n = f32(SUPERSAMPLE);
    var sum = vec3<f32>(0.0);
    for (var j = 0u; j < SUPERSAMPLE; j++) {
        for (var i = 0u; i < SUPERSAMPLE; i++) {
            let uv = 2.0 * (texel + (vec2<f32>(f32(i), f32(j)) + vec2<f32>(0.5)) / n) / s - vec2<f32>(1.0);
            let d = face_dir(p.face, uv.x, uv.y);
            // rotate_y(d, -rotation): a rotation about +Y by the angle whose cos, sin are given.
            let c = p.rotation.x;
            let sn = p.rotation.y;
            let r = vec3<f32>(c * d.x + sn * d.z, d.y, -sn * d.x + c * d.z);
            sum += probe_bilinear(r);
        }
    }
    return vec4<f32>(sum * (p.intensity / (n * n)), 1.0);
}

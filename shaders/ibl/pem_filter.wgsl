// Partial environment maps (dissertation section 3.2.1): level 0 of a PEM is the cube map
// with the texels outside one median-cut region black (mask); every further level is a 5x5
// kernel over the level above (filter), taps spaced one source texel apart around the
// destination texel's centre, each a bilinear lookup along its direction, so the kernel
// crosses cube edges into the neighbouring faces. src/ibl/pem.rs filter_level is the CPU twin.
// The plain chain (kernel none) is the 2x2 box: its one tap at the destination texel's centre
// falls on the corner of four source texels of the same face, so box reads those four.
//
// cs_*: one compute dispatch per level for all six faces (z = face); as six render passes per
// level, the per-pass cost of a software rasterizer dominated. fs_*: a render pass per face,
// for GL, whose storage writes into these textures read back black.

struct Params {
    // fs_*: the face drawn.
    face: u32,
    // Face size of the source level.
    src_size: u32,
    // The region this PEM keeps (mask).
    region: u32,
    pad: u32,
    // The 25 weights, row by row (b = -2..2, a = -2..2), normalized to sum 1.
    weights: array<vec4<f32>, 7>,
};

@group(0) @binding(0) var<uniform> p: Params;
// filter: the source level (one mip, all six faces); mask: level 0 of the full map.
@group(0) @binding(1) var src: texture_2d_array<f32>;
// mask: region ids of level 0, faces stacked vertically (row y of face f at y + f * size).
@group(0) @binding(2) var regions: texture_2d<u32>;
// cs_*: the destination level, all six faces (src/ibl/gpu.rs CUBE_FORMAT).
@group(1) @binding(0) var dst: texture_storage_2d_array<rgba16float, write>;

// #include "fullscreen.wgsl"
// #include "cube.wgsl"

fn weight(i: u32) -> f32 {
    return p.weights[i / 4u][i % 4u];
}

fn filtered(face: u32, xy: vec2<u32>) -> vec4<f32> {
    let size = p.src_size / 2u;
    let uc = texel_center(size, xy.x);
    let vc = texel_center(size, xy.y);
    let h = 2.0 / f32(p.src_size);
    var sum = vec4<f32>(0.0);
    for (var b = 0u; b < 5u; b++) {
        for (var a = 0u; a < 5u; a++) {
            let w = weight(b * 5u + a);
            if w != 0.0 {
                let d = face_dir(face, uc + (f32(a) - 2.0) * h, vc + (f32(b) - 2.0) * h);
                sum += w * cube_bilinear(src, p.src_size, d);
            }
        }
    }
    return sum;
}

fn box(face: u32, xy: vec2<u32>) -> vec4<f32> {
    let at = vec2<i32>(xy) * 2;
    let f = i32(face);
    let sum = textureLoad(src, at, f, 0) + textureLoad(src, at + vec2<i32>(1, 0), f, 0)
        + textureLoad(src, at + vec2<i32>(0, 1), f, 0) + textureLoad(src, at + vec2<i32>(1, 1), f, 0);
    return 0.25 * sum;
}

fn masked(face: u32, xy: vec2<u32>) -> vec4<f32> {
    let at = vec2<i32>(xy);
    let id = textureLoad(regions, vec2<i32>(at.x, at.y + i32(face * p.src_size)), 0).r;
    let texel = textureLoad(src, at, i32(face), 0);
    return select(vec4<f32>(0.0), texel, id == p.region);
}

@compute @workgroup_size(8, 8, 1)
fn cs_filter(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < p.src_size / 2u && id.y < p.src_size / 2u {
        textureStore(dst, id.xy, id.z, filtered(id.z, id.xy));
    }
}

@compute @workgroup_size(8, 8, 1)
fn cs_box(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < p.src_size / 2u && id.y < p.src_size / 2u {
        textureStore(dst, id.xy, id.z, box(id.z, id.xy));
    }
}

@compute @workgroup_size(8, 8, 1)
fn cs_mask(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < p.src_size && id.y < p.src_size {
        textureStore(dst, id.xy, id.z, masked(id.z, id.xy));
    }
}

@fragment
fn fs_filter(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    return filtered(p.face, vec2<u32>(frag.xy));
}

@fragment
fn fs_box(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    return box(p.face, vec2<u32>(frag.xy));
}

@fragment
fn fs_mask(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    return masked(p.face, vec2<u32>(frag.xy));
}

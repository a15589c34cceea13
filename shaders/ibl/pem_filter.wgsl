// Partial environment maps (dissertation section 3.2.1): level 0 of a PEM is the cube map
// with the texels outside one median-cut region black (fs_mask); every further level is a
// 5x5 kernel over the level above (fs_filter), taps spaced one source texel apart around
// the destination texel's centre, each a bilinear lookup along its direction, so the kernel
// crosses cube edges into the neighbouring faces. src/ibl/pem.rs filter_level is the CPU twin.

struct Params {
    face: u32,
    // Face size of the source level.
    src_size: u32,
    // The region this PEM keeps (fs_mask).
    region: u32,
    pad: u32,
    // The 25 weights, row by row (b = -2..2, a = -2..2), normalized to sum 1.
    weights: array<vec4<f32>, 7>,
};

@group(0) @binding(0) var<uniform> p: Params;
// fs_filter: the source level (one mip, all six faces); fs_mask: level 0 of the full map.
@group(0) @binding(1) var src: texture_2d_array<f32>;

// #include "fullscreen.wgsl"
// #include "cube.wgsl"

fn weight(i: u32) -> f32 {
    return p.weights[i / 4u][i % 4u];
}

@fragment
fn fs_filter(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let dst = p.src_size / 2u;
    let xy = vec2<u32>(frag.xy);
    let uc = texel_center(dst, xy.x);
    let vc = texel_center(dst, xy.y);
    let h = 2.0 / f32(p.src_size);
    var sum = vec4<f32>(0.0);
    for (var b = 0u; b < 5u; b++) {
        for (var a = 0u; a < 5u; a++) {
            let w = weight(b * 5u + a);
            if w != 0.0 {
                let d = face_dir(p.face, uc + (f32(a) - 2.0) * h, vc + (f32(b) - 2.0) * h);
                sum += w * cube_bilinear(src, p.src_size, d);
            }
        }
    }
    return sum;
}

// Region ids of level 0, faces stacked vertically (row y of face f at y + f * size).
@group(0) @binding(2) var regions: texture_2d<u32>;

@fragment
fn fs_mask(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let xy = vec2<i32>(frag.xy);
    let id = textureLoad(regions, vec2<i32>(xy.x, xy.y + i32(p.face * p.src_size)), 0).r;
    let texel = textureLoad(src, xy, i32(p.face), 0);
    return select(vec4<f32>(0.0), texel, id == p.region);
}

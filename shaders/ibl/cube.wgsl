// Cube map conventions, mirrored from src/ibl/cube.rs (faces +X -X +Y -Y +Z -Z, face
// coordinates u, v in [-1, 1] growing with texel column and row), and the seamless bilinear
// lookup that the PEM filters and their CPU twin share.

fn face_dir(face: u32, u: f32, v: f32) -> vec3<f32> {
    switch face {
        case 0u: { return vec3<f32>(1.0, -v, -u); }
        case 1u: { return vec3<f32>(-1.0, -v, u); }
        case 2u: { return vec3<f32>(u, 1.0, v); }
        case 3u: { return vec3<f32>(u, -1.0, -v); }
        case 4u: { return vec3<f32>(u, -v, 1.0); }
        default: { return vec3<f32>(-u, -v, -1.0); }
    }
}

struct FaceUv {
    face: u32,
    uv: vec2<f32>,
};

fn dir_to_face(d: vec3<f32>) -> FaceUv {
    let a = abs(d);
    if a.x >= a.y && a.x >= a.z {
        if d.x >= 0.0 { return FaceUv(0u, vec2<f32>(-d.z, -d.y) / a.x); }
        return FaceUv(1u, vec2<f32>(d.z, -d.y) / a.x);
    }
    if a.y >= a.z {
        if d.y >= 0.0 { return FaceUv(2u, vec2<f32>(d.x, d.z) / a.y); }
        return FaceUv(3u, vec2<f32>(d.x, -d.z) / a.y);
    }
    if d.z >= 0.0 { return FaceUv(4u, vec2<f32>(d.x, -d.y) / a.z); }
    return FaceUv(5u, vec2<f32>(-d.x, -d.y) / a.z);
}

// Face coordinate of the centre of texel `i` of a face `size` texels wide.
fn texel_center(size: u32, i: u32) -> f32 {
    return 2.0 * (f32(i) + 0.5) / f32(size) - 1.0;
}

// Cube maps are stored as 2D arrays of six layers (faces in the order above) with mips:
// every pass reads them with textureLoad, so no backend has to reinterpret a cube texture
// as an array (OpenGL cannot), and CPU twins reproduce the lookups exactly.

// The texel a tap (x, y) of `face` lands on, as (x, y, face), for a face `size` texels wide:
// itself on the face; a coordinate one past the edge continues onto the neighbouring face
// (CubeImage::tap).
fn cube_wrap(size: u32, face: u32, x: i32, y: i32) -> vec3<i32> {
    let n = i32(size);
    if x >= 0 && x < n && y >= 0 && y < n {
        return vec3<i32>(x, y, i32(face));
    }
    let centre = (2.0 * (vec2<f32>(f32(x), f32(y)) + vec2<f32>(0.5))) / f32(size) - vec2<f32>(1.0);
    let f = dir_to_face(face_dir(face, centre.x, centre.y));
    let t = clamp(vec2<i32>(floor((f.uv + vec2<f32>(1.0)) * 0.5 * f32(size))), vec2<i32>(0), vec2<i32>(n - 1));
    return vec3<i32>(t, i32(f.face));
}

// The four texels (x, y, face) of a seamless bilinear lookup along a direction in a cube of
// face size `size`, and the weights between them: shared by every cube read along it.
struct CubeTaps {
    t00: vec3<i32>,
    t10: vec3<i32>,
    t01: vec3<i32>,
    t11: vec3<i32>,
    weight: vec2<f32>,
};

fn cube_taps(size: u32, d: vec3<f32>) -> CubeTaps {
    let f = dir_to_face(d);
    let p = (f.uv + vec2<f32>(1.0)) * 0.5 * f32(size) - vec2<f32>(0.5);
    let fl = floor(p);
    let x0 = i32(fl.x);
    let y0 = i32(fl.y);
    return CubeTaps(
        cube_wrap(size, f.face, x0, y0),
        cube_wrap(size, f.face, x0 + 1, y0),
        cube_wrap(size, f.face, x0, y0 + 1),
        cube_wrap(size, f.face, x0 + 1, y0 + 1),
        p - fl,
    );
}

// The bilinear lookup of `taps` at mip `level` of the cube whose faces are layers
// first..first+5 (CubeImage::sample).
fn cube_gather(tex: texture_2d_array<f32>, level: i32, first: u32, taps: CubeTaps) -> vec4<f32> {
    let l = i32(first);
    let top = mix(
        textureLoad(tex, taps.t00.xy, taps.t00.z + l, level),
        textureLoad(tex, taps.t10.xy, taps.t10.z + l, level),
        taps.weight.x,
    );
    let bottom = mix(
        textureLoad(tex, taps.t01.xy, taps.t01.z + l, level),
        textureLoad(tex, taps.t11.xy, taps.t11.z + l, level),
        taps.weight.x,
    );
    return mix(top, bottom, taps.weight.y);
}

// Seamless bilinear lookup along `d` at mip `level` (face size `size`) of the cube whose faces
// are layers first..first+5: taps off the face come from the neighbouring face.
fn cube_bilinear_layers(tex: texture_2d_array<f32>, size: u32, level: i32, first: u32, d: vec3<f32>) -> vec4<f32> {
    return cube_gather(tex, level, first, cube_taps(size, d));
}

// The same for a six-layer cube map (shaders/ibl/cube.wgsl's storage).
fn cube_bilinear_level(tex: texture_2d_array<f32>, size: u32, level: i32, d: vec3<f32>) -> vec4<f32> {
    return cube_bilinear_layers(tex, size, level, 0u, d);
}

// Level 0 of a view (the one-mip views the filters read).
fn cube_bilinear(tex: texture_2d_array<f32>, size: u32, d: vec3<f32>) -> vec4<f32> {
    return cube_bilinear_level(tex, size, 0, d);
}

// Trilinear lookup at fractional `lod` in a chain whose level 0 is `size` wide and whose
// last level is `top` (pem::sample_chain).
fn cube_trilinear(tex: texture_2d_array<f32>, size: u32, top: f32, d: vec3<f32>, lod: f32) -> vec4<f32> {
    let l = clamp(lod, 0.0, top);
    let l0 = u32(floor(l));
    let l1 = min(l0 + 1u, u32(top));
    let a = cube_bilinear_level(tex, max(size >> l0, 1u), i32(l0), d);
    let b = cube_bilinear_level(tex, max(size >> l1, 1u), i32(l1), d);
    return mix(a, b, l - f32(l0));
}

// cube_trilinear for wgpu's GL backend on llvmpipe. That backend guards every textureLoad with
// `textureSize(tex, level)`, and llvmpipe answers the query with the level of the first pixel of
// the group it shades at once, so where such pixels read different levels (a glossy silhouette
// beside the background) a pixel whose level is finer than the first's read zeros. Here each
// load's level is the counter of a loop counting up from 0, the same in every pixel still
// looping, and one that stopped earlier holds a smaller one: the query then sees a level at most
// the pixel's own, whose size admits its texels. Costs l1 + 1 bilinear lookups instead of two: on
// llvmpipe's GL the default graph's IblShading took 368 ms a frame instead of 177.
fn cube_trilinear_counted(tex: texture_2d_array<f32>, size: u32, top: f32, d: vec3<f32>, lod: f32) -> vec4<f32> {
    let l = clamp(lod, 0.0, top);
    let l0 = i32(floor(l));
    let l1 = min(l0 + 1, i32(top));
    var a = vec4<f32>(0.0);
    var b = vec4<f32>(0.0);
    for (var k = 0; k <= l1; k++) {
        let texel = cube_gather(tex, k, 0u, cube_taps(max(size >> u32(k), 1u), d));
        if k == l0 {
            a = texel;
        }
        if k == l1 {
            b = texel;
        }
    }
    return mix(a, b, l - f32(l0));
}

// textureLoad at a level that may differ between pixels, on wgpu's GL backend: the level is the
// counter of a loop counting up, as in cube_trilinear_counted. Costs level + 1 masked loads.
fn load_counted(tex: texture_2d_array<f32>, t: vec3<i32>, level: i32) -> vec4<f32> {
    var texel = vec4<f32>(0.0);
    for (var k = 0; k <= level; k++) {
        if k == level {
            texel = textureLoad(tex, t.xy, t.z, k);
        }
    }
    return texel;
}

const TAU: f32 = 6.28318530718;
const PI_F: f32 = 3.14159265359;

// The direction at equirectangular coordinates `uv` (inverse of src/ibl/cube.rs equirect_uv).
fn equirect_dir(uv: vec2<f32>) -> vec3<f32> {
    let phi = (uv.x - 0.5) * TAU;
    let theta = uv.y * PI_F;
    return vec3<f32>(sin(theta) * sin(phi), cos(theta), -sin(theta) * cos(phi));
}

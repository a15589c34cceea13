// The Phong prefilter (src/ibl/pem.rs phong_level): per destination texel with direction r,
// the lobe max(0, r.w)^s times each sample's solid angle, normalized, over a source level of
// the plain chain: every texel of all faces (small destinations) or a window of points one
// source texel apart on the face's plane, read with the seamless bilinear lookup.
//
// On the whole-sphere levels the normalization (the sum of the weights) depends only on the
// geometry, so fs_phong_norm computes it once per level and fs_phong sums only the source
// texels inside `bounds`: a PEM is black outside its region, and skipped texels would add
// exact zeros; on the windowed levels, destination texels outside a cone around the region
// are black without summing. With N regions, N PEMs cost about one full map instead of N.
struct Phong {
    face: u32,
    dst_size: u32,
    src_size: u32,
    // 1: sum the whole sphere; 0: the window.
    full_sphere: u32,
    exponent: f32,
    window: i32,
    pad: vec2<f32>,
    // Per source face, the texels that may be non-zero: (x0, y0, x1, y1) inclusive; empty
    // when x0 > x1.
    bounds: array<vec4<u32>, 6>,
    // Windowed levels: outside this cone (axis, cos of the half-angle) the window cannot
    // reach a non-zero texel, so the sum is exactly zero.
    cone: vec4<f32>,
};

@group(0) @binding(0) var<uniform> ph: Phong;
// The source level (one mip of the plain chain, all six faces).
@group(0) @binding(1) var src: texture_2d_array<f32>;
// fs_phong on whole-sphere levels: fs_phong_norm's output for this level (one mip).
@group(0) @binding(2) var norm: texture_2d_array<f32>;

// #include "fullscreen.wgsl"
// #include "cube.wgsl"

fn plane_solid_angle(u: f32, v: f32, h: f32) -> f32 {
    return h * h / pow(1.0 + u * u + v * v, 1.5);
}

// The lobe weight of source texel (f, tx, ty) seen from direction r; 0 behind r.
fn lobe_weight(r: vec3<f32>, f: u32, tx: u32, ty: u32) -> f32 {
    let m = ph.src_size;
    let u = texel_center(m, tx);
    let v = texel_center(m, ty);
    let c = dot(r, normalize(face_dir(f, u, v)));
    if c > 0.0 {
        return pow(c, ph.exponent) * plane_solid_angle(u, v, 2.0 / f32(m));
    }
    return 0.0;
}

fn dst_dir(frag: vec4<f32>) -> vec3<f32> {
    let xy = vec2<u32>(frag.xy);
    return normalize(face_dir(ph.face, texel_center(ph.dst_size, xy.x), texel_center(ph.dst_size, xy.y)));
}

@fragment
fn fs_phong_norm(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let r = dst_dir(frag);
    var total = 0.0;
    for (var f = 0u; f < 6u; f++) {
        for (var ty = 0u; ty < ph.src_size; ty++) {
            for (var tx = 0u; tx < ph.src_size; tx++) {
                total += lobe_weight(r, f, tx, ty);
            }
        }
    }
    return vec4<f32>(total, 0.0, 0.0, 1.0);
}

@fragment
fn fs_phong(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let r = dst_dir(frag);
    var sum = vec4<f32>(0.0);
    if ph.full_sphere == 1u {
        for (var f = 0u; f < 6u; f++) {
            let b = ph.bounds[f];
            for (var ty = b.y; ty <= b.w && b.x <= b.z; ty++) {
                for (var tx = b.x; tx <= b.z; tx++) {
                    let w = lobe_weight(r, f, tx, ty);
                    if w > 0.0 {
                        sum += w * textureLoad(src, vec2<u32>(tx, ty), f, 0);
                    }
                }
            }
        }
        return sum / textureLoad(norm, vec2<u32>(frag.xy), ph.face, 0).r;
    }
    if dot(r, ph.cone.xyz) < ph.cone.w {
        return vec4<f32>(0.0);
    }
    let uc = texel_center(ph.dst_size, u32(frag.x));
    let vc = texel_center(ph.dst_size, u32(frag.y));
    let h = 2.0 / f32(ph.src_size);
    var total = 0.0;
    for (var b = -ph.window; b <= ph.window; b++) {
        for (var a = -ph.window; a <= ph.window; a++) {
            let u = uc + f32(a) * h;
            let v = vc + f32(b) * h;
            let d = normalize(face_dir(ph.face, u, v));
            let c = dot(r, d);
            if c > 0.0 {
                let w = pow(c, ph.exponent) * plane_solid_angle(u, v, h);
                sum += w * cube_bilinear(src, ph.src_size, d);
                total += w;
            }
        }
    }
    return sum / total;
}

// The Phong prefilter (src/ibl/pem.rs phong_level): per destination texel with direction r,
// the lobe max(0, r.w)^s times each sample's solid angle, normalized, over a source level of
// the plain chain: every texel of all faces (small destinations) or a window of source texel
// centres around the one holding the destination texel's centre, extended past the face's
// edges on its plane and read there with the seamless bilinear lookup. cs_pad makes those
// lookups once per level: the windowed levels read a copy of the source level padded by the
// window's half-width on every side, holding the lookup at each tap past a face's edge, so
// every tap is one load (the lookups across edges were three quarters of a PEM's cost).
//
// The normalization (the sum of the weights) depends only on the geometry, so fs_phong_norm
// computes it once per level and fs_phong sums only the source texels inside `bounds`: a PEM
// is black outside its region, and skipped texels would add exact zeros. On the windowed
// levels, destination texels outside a cone around the region are black without summing,
// and a window inside its face visits only its overlap with the region's rectangle there.
// With N regions, N PEMs cost about one full map instead of N.
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
    // The same for one lookup (window 0): a tap outside it reads exact zeros.
    tap_cone: vec4<f32>,
};

@group(0) @binding(0) var<uniform> ph: Phong;
// The source level (one mip of the plain chain, all six faces); on the windowed levels of
// cs_phong and fs_phong, padded by `window` texels on every side (cs_pad's output).
@group(0) @binding(1) var src: texture_2d_array<f32>;
// fs_phong on whole-sphere levels: fs_phong_norm's output for this level (one mip).
@group(0) @binding(2) var norm: texture_2d_array<f32>;
// cs_phong: the level written, all six faces.
@group(1) @binding(0) var dst: texture_storage_2d_array<rgba16float, write>;

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

fn dst_dir(face: u32, xy: vec2<u32>) -> vec3<f32> {
    return normalize(face_dir(face, texel_center(ph.dst_size, xy.x), texel_center(ph.dst_size, xy.y)));
}

// The window's lobe weight at offset (a, b) source texels from `centre`, the source texel
// holding the destination texel's centre, with the tap's direction: taps are source texel
// centres, extended past the face's edges on its plane. 0 behind r, and 0 outside
// `tap_cone`, where the source is exactly zero: across face edges each tap is a seamless
// lookup, the costly part, and a PEM's window mostly reaches outside its region.
struct WindowTap {
    d: vec3<f32>,
    w: f32,
};

fn window_tap(face: u32, r: vec3<f32>, centre: vec2<i32>, a: i32, b: i32) -> WindowTap {
    let h = 2.0 / f32(ph.src_size);
    let u = (f32(centre.x + a) + 0.5) * h - 1.0;
    let v = (f32(centre.y + b) + 0.5) * h - 1.0;
    let d = normalize(face_dir(face, u, v));
    let c = dot(r, d);
    var w = 0.0;
    if c > 0.0 && dot(d, ph.tap_cone.xyz) >= ph.tap_cone.w {
        w = pow(c, ph.exponent) * plane_solid_angle(u, v, h);
    }
    return WindowTap(d, w);
}

// The source texel holding the centre of destination texel `xy` (pem.rs window_centre).
fn window_centre(xy: vec2<u32>) -> vec2<i32> {
    return vec2<i32>(xy) * i32(ph.src_size) / i32(ph.dst_size);
}

@fragment
fn fs_phong_norm(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let r = dst_dir(ph.face, vec2<u32>(frag.xy));
    var total = 0.0;
    if ph.full_sphere == 0u {
        let centre = window_centre(vec2<u32>(frag.xy));
        for (var b = -ph.window; b <= ph.window; b++) {
            for (var a = -ph.window; a <= ph.window; a++) {
                total += window_tap(ph.face, r, centre, a, b).w;
            }
        }
        return vec4<f32>(total, 0.0, 0.0, 1.0);
    }
    for (var f = 0u; f < 6u; f++) {
        for (var ty = 0u; ty < ph.src_size; ty++) {
            for (var tx = 0u; tx < ph.src_size; tx++) {
                total += lobe_weight(r, f, tx, ty);
            }
        }
    }
    return vec4<f32>(total, 0.0, 0.0, 1.0);
}

// Level texel `xy` of face `face`.
fn phong(face: u32, xy: vec2<u32>) -> vec4<f32> {
    let r = dst_dir(face, xy);
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
        return sum / textureLoad(norm, xy, face, 0).r;
    }
    if dot(r, ph.cone.xyz) < ph.cone.w {
        return vec4<f32>(0.0);
    }
    let centre = window_centre(xy);
    let last = i32(ph.src_size) - 1;
    let total = textureLoad(norm, xy, face, 0).r;
    // A window inside its face: its taps are source texels, and only those inside the region's
    // rectangle on this face can be non-zero.
    if all(centre - vec2<i32>(ph.window) >= vec2<i32>(0)) && all(centre + vec2<i32>(ph.window) <= vec2<i32>(last)) {
        let bounds = ph.bounds[face];
        let lo = max(centre - vec2<i32>(ph.window), vec2<i32>(bounds.xy));
        let hi = min(centre + vec2<i32>(ph.window), vec2<i32>(bounds.zw));
        for (var y = lo.y; y <= hi.y; y++) {
            for (var x = lo.x; x <= hi.x; x++) {
                let tap = window_tap(face, r, centre, x - centre.x, y - centre.y);
                if tap.w > 0.0 {
                    sum += tap.w * textureLoad(src, vec2<i32>(x, y) + ph.window, face, 0);
                }
            }
        }
        return sum / total;
    }
    for (var b = -ph.window; b <= ph.window; b++) {
        for (var a = -ph.window; a <= ph.window; a++) {
            let tap = window_tap(face, r, centre, a, b);
            if tap.w > 0.0 {
                sum += tap.w * textureLoad(src, centre + vec2<i32>(a, b) + ph.window, face, 0);
            }
        }
    }
    return sum / total;
}

// Texel `xy` of face `face` of the source level padded by `window` texels: the texel itself
// inside the face, past its edges the seamless lookup at the tap there (window_tap's d).
fn padded(face: u32, xy: vec2<u32>) -> vec4<f32> {
    let at = vec2<i32>(xy) - ph.window;
    let n = i32(ph.src_size);
    if all(at >= vec2<i32>(0)) && all(at < vec2<i32>(n)) {
        return textureLoad(src, at, face, 0);
    }
    let h = 2.0 / f32(ph.src_size);
    let uv = (vec2<f32>(at) + 0.5) * h - 1.0;
    return cube_bilinear(src, ph.src_size, normalize(face_dir(face, uv.x, uv.y)));
}

// The padded copy of a windowed level's source, all six faces (z); `dst` is
// src_size + 2 window texels wide.
@compute @workgroup_size(8, 8, 1)
fn cs_pad(@builtin(global_invocation_id) id: vec3<u32>) {
    let size = ph.src_size + 2u * u32(ph.window);
    if id.x < size && id.y < size {
        textureStore(dst, id.xy, id.z, padded(id.z, id.xy));
    }
}

@fragment
fn fs_pad(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    return padded(ph.face, vec2<u32>(frag.xy));
}

// One dispatch per level for all six faces (z); GL, whose storage writes into these arrays
// read back black, draws fs_phong per face instead.
@compute @workgroup_size(8, 8, 1)
fn cs_phong(@builtin(global_invocation_id) id: vec3<u32>) {
    if id.x < ph.dst_size && id.y < ph.dst_size {
        textureStore(dst, id.xy, id.z, phong(id.z, id.xy));
    }
}

@fragment
fn fs_phong(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    return phong(ph.face, vec2<u32>(frag.xy));
}

// Deferred warping, pass 2 (paper eqs. 1-12): the transform of one detail vertex onto the
// surface through the matrix texture. Shared by the G-buffer attachment pass (attach.wgsl)
// and the geometry export (attach_export.wgsl), so exported vertices are the rendered ones.

@group(2) @binding(0) var mt_u: texture_2d<f32>;
@group(2) @binding(1) var mt_n: texture_2d<f32>;
@group(2) @binding(2) var mt_v: texture_2d<f32>;

// The mapping, per pipeline (src/warp/mod.rs `WarpSettings::constants`): lavapipe compiles a
// shader again on every draw whose branches depend on uniforms alone, and a scene's attachments
// differ in mode. 0 point, 1 area, 2 curve, 3 curve aligned to the curve normal,
// 4 no surface: plain instancing, M_tex's translation as the xz offset; a benchmark baseline,
// 5 point with the frame resolved once per instance by attach_resolve.wgsl.
override MODE: u32 = 0u;
// Fur gravity bends the hairs (`gravity` > 0).
override GRAVITY: bool = false;

// src/warp/mod.rs `WarpUniform`. Time-dependent mappings (spin) are baked into each
// instance's M_tex / M_tan by the nodes.
struct Warp {
    _unused: f32,
    // Fur gravity c (eq. 11).
    gravity: f32,
    // Lowest valid-texel weight.
    min_weight: f32,
    _pad: f32,
};

@group(2) @binding(3) var<uniform> warp: Warp;
// Seam map: for gutter texels beside a sewn edge, the partner piece's UV (xy), the angle of
// the map from this piece's UV directions to the partner's (z) and +1/-1 for a rotation or a
// reflection (w); zero elsewhere (src/warp/mod.rs `seam_map`).
@group(2) @binding(4) var seam_map: texture_2d<f32>;

// Per-instance placement: M_tex (2x3, rows), M_tan (4x4, columns), a cubic Bezier in UV space
// and the curve-parameter range this instance covers.
struct Instance {
    m_tex0: vec4<f32>,
    m_tex1: vec4<f32>,
    m_tan0: vec4<f32>,
    m_tan1: vec4<f32>,
    m_tan2: vec4<f32>,
    m_tan3: vec4<f32>,
    curve01: vec4<f32>,
    curve23: vec4<f32>,
    // x, y: curve parameters t0, t1; z, w: the detail mesh's z extent mapped onto them.
    range: vec4<f32>,
};

struct SurfaceFrame {
    tu: vec3<f32>,
    n: vec3<f32>,
    tv: vec3<f32>,
    p: vec3<f32>,
    valid: bool,
    // dp/du and dp/dv in world units per UV unit: the derivative of the interpolated
    // position field (the local UV-to-world scale and shear that area and curve attachments
    // are stretched by); the frame's unit tangents where no pair of covered texels gives it.
    dpdu: vec3<f32>,
    dpdv: vec3<f32>,
};

struct Texel {
    tu: vec3<f32>,
    n: vec3<f32>,
    tv: vec3<f32>,
    p: vec3<f32>,
    valid: bool,
};

fn load_texel(q: vec2<i32>) -> Texel {
    let cu = textureLoad(mt_u, q, 0);
    let cn = textureLoad(mt_n, q, 0);
    let cv = textureLoad(mt_v, q, 0);
    return Texel(cu.xyz, cn.xyz, cv.xyz, vec3<f32>(cu.w, cn.w, cv.w), dot(cn.xyz, cn.xyz) >= 0.25);
}

// Whether the partner reads are compiled in (src/render/draw/ builds a variant without them for
// surfaces without seams: lavapipe runs the masked branch below for every footprint texel,
// which doubled the cost of area and curve attachments).
override SEAMS: bool = true;

// A footprint texel's frame: its own where a piece covers it; in the gutter beside a seam, the
// partner piece's frame with its tangents turned into this piece's UV directions, so lookups
// blend both pieces across the seam (dissertation section 4.1.2, "Outliers and Seams").
fn texel_or_partner(q: vec2<i32>, dims: vec2<i32>) -> Texel {
    let own = load_texel(q);
    if own.valid || !SEAMS {
        return own;
    }
    // A surface without seams binds a 1x1 placeholder.
    if textureDimensions(seam_map).x == 1u {
        return own;
    }
    let seam = textureLoad(seam_map, q, 0);
    if seam.w == 0.0 {
        return own;
    }
    // The partner point, interpolated bilinearly over the partner's covered texels (not its
    // nearest texel, which would quantize positions by up to 0.7 texel).
    var b = partner_bilinear(seam.xy, dims);
    let c = cos(seam.z);
    let s = sin(seam.z);
    let tu = b.tu;
    if seam.w > 0.0 {
        b.tu = c * tu + s * b.tv;
        b.tv = -s * tu + c * b.tv;
    } else {
        b.tu = c * tu + s * b.tv;
        b.tv = s * tu - c * b.tv;
    }
    return b;
}

// A bilinear lookup over covered texels only (no seam map: one step across a seam), for the
// partner point of a gutter texel; invalid when no covered texel is in its footprint.
fn partner_bilinear(uv: vec2<f32>, dims: vec2<i32>) -> Texel {
    let st = uv * vec2<f32>(dims) - 0.5;
    let base = vec2<i32>(floor(st));
    let f = st - floor(st);
    var acc = Texel(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), false);
    var weight = 0.0;
    for (var k = 0; k < 4; k = k + 1) {
        let o = vec2<i32>(k & 1, k >> 1);
        let q = base + o;
        if q.x < 0 || q.y < 0 || q.x >= dims.x || q.y >= dims.y {
            continue;
        }
        let t = load_texel(q);
        if !t.valid {
            continue;
        }
        let w = select(1.0 - f.x, f.x, o.x == 1) * select(1.0 - f.y, f.y, o.y == 1);
        acc.tu = acc.tu + w * t.tu;
        acc.n = acc.n + w * t.n;
        acc.tv = acc.tv + w * t.tv;
        acc.p = acc.p + w * t.p;
        weight = weight + w;
    }
    if weight <= 0.0 {
        return acc;
    }
    let inv = 1.0 / weight;
    return Texel(acc.tu * inv, acc.n * inv, acc.tv * inv, acc.p * inv, true);
}

// f_mt (eq. 3) with bilinear interpolation done by hand over the valid texels, so it works
// on Rgba32Float without FLOAT32_FILTERABLE. Empty (zero) texels get no weight; a lookup whose
// valid weight is below the threshold, or whose averaged axes are far from unit length
// (frames of folds averaged together), is an outlier (section 4.1.2, "Outliers and Seams").
fn lookup_frame(uv: vec2<f32>) -> SurfaceFrame {
    let dims = vec2<i32>(textureDimensions(mt_n));
    let st = uv * vec2<f32>(dims) - 0.5;
    let base = vec2<i32>(floor(st));
    let f = st - floor(st);
    // The four footprint texels, unrolled (no private array: llvmpipe spills those).
    let t00 = footprint_texel(base, dims);
    let t10 = footprint_texel(base + vec2<i32>(1, 0), dims);
    let t01 = footprint_texel(base + vec2<i32>(0, 1), dims);
    let t11 = footprint_texel(base + vec2<i32>(1, 1), dims);
    let w00 = select(0.0, (1.0 - f.x) * (1.0 - f.y), t00.valid);
    let w10 = select(0.0, f.x * (1.0 - f.y), t10.valid);
    let w01 = select(0.0, (1.0 - f.x) * f.y, t01.valid);
    let w11 = select(0.0, f.x * f.y, t11.valid);
    let weight = w00 + w10 + w01 + w11;
    let su = w00 * t00.tu + w10 * t10.tu + w01 * t01.tu + w11 * t11.tu;
    let sn = w00 * t00.n + w10 * t10.n + w01 * t01.n + w11 * t11.n;
    let sv = w00 * t00.tv + w10 * t10.tv + w01 * t01.tv + w11 * t11.tv;
    let sp = w00 * t00.p + w10 * t10.p + w01 * t01.p + w11 * t11.p;
    var frame: SurfaceFrame;
    frame.valid = weight >= max(warp.min_weight, 1e-6);
    let inv = 1.0 / max(weight, 1e-6);
    let n = sn * inv;
    let u = su * inv;
    frame.valid = frame.valid && abs(length(n) - 1.0) < 0.25 && abs(length(u) - 1.0) < 0.25;
    frame.n = normalize(n);
    frame.tu = normalize(u - frame.n * dot(frame.n, u));
    let v = sv * inv;
    frame.tv = normalize(v - frame.n * dot(frame.n, v) - frame.tu * dot(frame.tu, v));
    frame.p = sp * inv;
    // The derivative of the bilinear position field: differences along each axis between
    // covered texel pairs, weighted as the interpolation weights them.
    let wu0 = select(0.0, 1.0 - f.y, t00.valid && t10.valid);
    let wu1 = select(0.0, f.y, t01.valid && t11.valid);
    let wv0 = select(0.0, 1.0 - f.x, t00.valid && t01.valid);
    let wv1 = select(0.0, f.x, t10.valid && t11.valid);
    let du = wu0 * (t10.p - t00.p) + wu1 * (t11.p - t01.p);
    let dv = wv0 * (t01.p - t00.p) + wv1 * (t11.p - t10.p);
    let d = uv_derivatives(du, wu0 + wu1, dv, wv0 + wv1, vec2<f32>(dims), frame);
    frame.dpdu = d[0];
    frame.dpdv = d[1];
    return frame;
}

// A footprint texel (its own frame or its seam partner's), invalid outside the texture.
fn footprint_texel(q: vec2<i32>, dims: vec2<i32>) -> Texel {
    if q.x < 0 || q.y < 0 || q.x >= dims.x || q.y >= dims.y {
        return Texel(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0), false);
    }
    return texel_or_partner(q, dims);
}

// dp/du and dp/dv in world per UV unit from texel differences `du`, `dv` with their weight
// sums, projected onto the tangent plane of the interpolated normal (a difference between
// texels is a chord of the surface, up to half a texel's turn off the plane at the lookup
// point; the smooth surface's derivative lies in it). An axis without a covered pair takes
// the other axis's scale along its unit tangent; with neither the unit tangents stand in
// (scale unknown).
fn uv_derivatives(du: vec3<f32>, wu: f32, dv: vec3<f32>, wv: f32, dims: vec2<f32>, f: SurfaceFrame) -> array<vec3<f32>, 2> {
    var a = f.tu;
    var b = f.tv;
    if wu > 1e-6 { a = du * (dims.x / wu); }
    if wv > 1e-6 { b = dv * (dims.y / wv); }
    a = a - f.n * dot(f.n, a);
    b = b - f.n * dot(f.n, b);
    if wu <= 1e-6 && wv > 1e-6 { a = f.tu * length(b); }
    if wv <= 1e-6 && wu > 1e-6 { b = f.tv * length(a); }
    return array<vec3<f32>, 2>(a, b);
}

fn bezier(c: Instance, t: f32) -> vec2<f32> {
    let s = 1.0 - t;
    return s * s * s * c.curve01.xy + 3.0 * s * s * t * c.curve01.zw + 3.0 * s * t * t * c.curve23.xy + t * t * t * c.curve23.zw;
}

fn bezier_tangent(c: Instance, t: f32) -> vec2<f32> {
    let s = 1.0 - t;
    return 3.0 * s * s * (c.curve01.zw - c.curve01.xy) + 6.0 * s * t * (c.curve23.xy - c.curve01.zw) + 3.0 * t * t * (c.curve23.zw - c.curve23.xy);
}

struct Warped {
    position: vec3<f32>,
    normal: vec3<f32>,
    valid: bool,
};

// The normal transform of a 3x3 matrix: its cofactor matrix (the inverse transpose times the
// determinant) with the determinant's sign, so a flattened M_tan (height 0) still maps the
// normal to n instead of dividing by zero. Normals are normalized afterwards.
fn normal_matrix(m: mat3x3<f32>) -> mat3x3<f32> {
    let c0 = cross(m[1], m[2]);
    let c1 = cross(m[2], m[0]);
    let c2 = cross(m[0], m[1]);
    return mat3x3<f32>(c0, c1, c2) * select(1.0, -1.0, dot(m[0], c0) < 0.0);
}

// A curve's direction in UV at t; where the control polygon is degenerate (c1 = c0 or
// c2 = c3, common in SVG), the limit of the tangent's direction at that end: c2 - c0 at
// t = 0, c3 - c1 at t = 1; c3 - c0 when three control points coincide.
fn curve_direction(inst: Instance, t: f32) -> vec2<f32> {
    var d = bezier_tangent(inst, t);
    if dot(d, d) < 1e-16 {
        d = select(inst.curve23.zw - inst.curve01.zw, inst.curve23.xy - inst.curve01.xy, t < 0.5);
    }
    if dot(d, d) < 1e-16 {
        d = inst.curve23.zw - inst.curve01.xy;
    }
    if dot(d, d) < 1e-16 {
        return vec2<f32>(0.0, 1.0);
    }
    return normalize(d);
}

// A world vector in frame coordinates (t_u, n, t_v).
fn to_frame(f: SurfaceFrame, w: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(dot(f.tu, w), dot(f.n, w), dot(f.tv, w));
}

// The world vector of a UV-space direction (du, dv) through M_tex's 2x2 part and the surface's
// dp/du, dp/dv, in frame coordinates.
fn uv_to_frame(f: SurfaceFrame, inst: Instance, d: vec2<f32>) -> vec3<f32> {
    let e = vec2<f32>(dot(inst.m_tex0.xy, d), dot(inst.m_tex1.xy, d));
    return to_frame(f, f.dpdu * e.x + f.dpdv * e.y);
}

// Fur gravity (eqs. 11-12) in frame coordinates: the vertex q (height b = q.y over its foot
// (q.x, 0, q.z)) is pulled down by c b^2 along world up and put back at distance |b| from
// the foot: q'' = foot + b u, u = w / |w|, w = n - c b up. Returns q'' and, in the last
// column, d q'' / d b = u - b c (up - u (u . up)) / |w| (the other columns are the identity's),
// which bends the normals with the hairs.
fn fur_bend(f: SurfaceFrame, q: vec3<f32>, c: f32) -> mat2x3<f32> {
    let up = vec3<f32>(f.tu.y, f.n.y, f.tv.y);
    let b = q.y;
    let w = vec3<f32>(0.0, 1.0, 0.0) - c * b * up;
    let lw = length(w);
    if lw < 1e-10 {
        return mat2x3<f32>(q, vec3<f32>(0.0, 1.0, 0.0));
    }
    let u = w / lw;
    let bent = vec3<f32>(q.x, 0.0, q.z) + b * u;
    let db = u - b * c * (up - u * dot(u, up)) / lw;
    return mat2x3<f32>(bent, db);
}

fn warp_vertex(p: vec3<f32>, normal: vec3<f32>, inst: Instance) -> Warped {
    let mode = i32(MODE);
    var uv_in = vec2<f32>(0.0);         // f_uv(p), without the homogeneous 1
    var f_map = vec4<f32>(p, 1.0);      // eq. (5)
    var t = 0.0;
    var nc = vec2<f32>(1.0, 0.0);
    if mode == 1 {
        uv_in = p.xz;                                   // eq. (6)
        f_map = vec4<f32>(0.0, p.y, 0.0, 1.0);          // eq. (7)
    } else if mode == 2 || mode == 3 {
        let s = (p.z - inst.range.z) / max(inst.range.w - inst.range.z, 1e-12);
        t = mix(inst.range.x, inst.range.y, s);
        uv_in = bezier(inst, t);                        // eq. (8)
        f_map = vec4<f32>(p.x, p.y, 0.0, 1.0);          // eq. (9)
        if mode == 3 {
            let d = curve_direction(inst, t);
            // The curve normal in UV, turned so that a curve along +v gives eq. (9) (x on +u).
            nc = vec2<f32>(d.y, -d.x);
            f_map = vec4<f32>(nc.x * p.x, p.y, nc.y * p.x, 1.0);   // eq. (10)
        }
    }
    // eq. (1): M_tex . f_uv
    let uv = vec2<f32>(dot(inst.m_tex0.xyz, vec3<f32>(uv_in, 1.0)), dot(inst.m_tex1.xyz, vec3<f32>(uv_in, 1.0)));
    var frame: SurfaceFrame;
    if mode == 5 {
        // A point attachment's frame is the same for all its vertices: looked up once per instance.
        frame = SurfaceFrame(inst.m_tex0.xyz, inst.m_tex1.xyz, inst.curve01.xyz, vec3<f32>(inst.m_tex0.w, inst.m_tex1.w, inst.curve01.w), inst.curve23.x > 0.5, inst.m_tex0.xyz, inst.curve01.xyz);
    } else if mode == 4 {
        frame = SurfaceFrame(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(0.0, 0.0, 1.0), vec3<f32>(uv.x, 0.0, uv.y), true, vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(0.0, 0.0, 1.0));
    } else {
        frame = lookup_frame(uv);
    }
    let m_tan = mat4x4<f32>(inst.m_tan0, inst.m_tan1, inst.m_tan2, inst.m_tan3);
    var q = (m_tan * f_map).xyz;
    // The Jacobian of the whole map from the detail mesh's (x, y, z) to frame coordinates:
    // its cofactor transforms the normals (decal angle, spin and the UV-to-world scale live in
    // M_tex and dp/du, dp/dv; the arc-length stretch in the curve's speed).
    var jac = mat3x3<f32>(inst.m_tan0.xyz, inst.m_tan1.xyz, inst.m_tan2.xyz);
    if mode == 1 {
        jac = mat3x3<f32>(uv_to_frame(frame, inst, vec2<f32>(1.0, 0.0)), inst.m_tan1.xyz, uv_to_frame(frame, inst, vec2<f32>(0.0, 1.0)));
    } else if mode == 2 || mode == 3 {
        let speed = max(length(bezier_tangent(inst, t)), 1e-6) * (inst.range.y - inst.range.x) / max(inst.range.w - inst.range.z, 1e-12);
        let along = uv_to_frame(frame, inst, curve_direction(inst, t) * speed);
        jac = mat3x3<f32>(nc.x * inst.m_tan0.xyz + nc.y * inst.m_tan2.xyz, inst.m_tan1.xyz, along);
    }
    // Fur gravity (eqs. 11-12): every hair vertex keeps its distance to the surface point
    // p_s below it (its foot on the tangent plane); normals bend with the hairs.
    let c = warp.gravity;
    if GRAVITY {
        let bend = fur_bend(frame, q, c);
        q = bend[0];
        jac = mat3x3<f32>(vec3<f32>(1.0, 0.0, 0.0), bend[1], vec3<f32>(0.0, 0.0, 1.0)) * jac;
    }
    // eq. (2): p_w = M_mt . M_tan . f_map(p), M_mt = [t_u n t_v p]
    var out: Warped;
    out.position = frame.tu * q.x + frame.n * q.y + frame.tv * q.z + frame.p;
    let nt = normal_matrix(jac) * normal;
    out.normal = normalize(frame.tu * nt.x + frame.n * nt.y + frame.tv * nt.z);
    out.valid = frame.valid;
    return out;
}

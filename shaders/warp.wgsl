// Deferred warping, pass 2 (paper eqs. 1-12): the transform of one detail vertex onto the
// surface through the matrix texture. Shared by the G-buffer attachment pass (attach.wgsl)
// and the geometry export (attach_export.wgsl), so exported vertices are the rendered ones.

@group(2) @binding(0) var mt_u: texture_2d<f32>;
@group(2) @binding(1) var mt_n: texture_2d<f32>;
@group(2) @binding(2) var mt_v: texture_2d<f32>;

struct Warp {
    // x: mode (0 point, 1 area, 2 curve, 3 curve aligned to the curve normal,
    //    4 no surface: plain instancing, M_tex's translation as the xz offset; a benchmark baseline,
    //    5 point with the frame resolved once per instance by attach_resolve.wgsl),
    // y: fur gravity c (eq. 11), z: lowest valid-texel weight, w: time in seconds.
    params: vec4<f32>,
};

@group(2) @binding(3) var<uniform> warp: Warp;
// Seam map: for gutter texels beside a sewn edge, the partner piece's UV (xy), the angle of
// the map from this piece's UV directions to the partner's (z) and +1/-1 for a rotation or a
// reflection (w); zero elsewhere (src/warp.rs `seam_map`).
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

// A footprint texel's frame: its own where a piece covers it; in the gutter beside a seam, the
// partner piece's frame with its tangents turned into this piece's UV directions, so lookups
// blend both pieces across the seam (dissertation section 4.1.2, "Outliers and Seams").
fn texel_or_partner(q: vec2<i32>, dims: vec2<i32>) -> Texel {
    let own = load_texel(q);
    if own.valid {
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
    let pq = clamp(vec2<i32>(seam.xy * vec2<f32>(dims)), vec2<i32>(0), dims - 1);
    var b = load_texel(pq);
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

// f_mt (eq. 3) with bilinear interpolation done by hand over the valid texels, so it works
// on Rgba32Float without FLOAT32_FILTERABLE. Empty (zero) texels get no weight; a lookup whose
// valid weight is below the threshold, or whose averaged axes are far from unit length
// (frames of folds averaged together), is an outlier (section 4.1.2, "Outliers and Seams").
fn lookup_frame(uv: vec2<f32>) -> SurfaceFrame {
    let dims = vec2<i32>(textureDimensions(mt_n));
    let st = uv * vec2<f32>(dims) - 0.5;
    let base = vec2<i32>(floor(st));
    let f = st - floor(st);
    var su = vec3<f32>(0.0);
    var sn = vec3<f32>(0.0);
    var sv = vec3<f32>(0.0);
    var sp = vec3<f32>(0.0);
    var weight = 0.0;
    for (var k = 0; k < 4; k = k + 1) {
        let o = vec2<i32>(k & 1, k >> 1);
        let q = base + o;
        if q.x < 0 || q.y < 0 || q.x >= dims.x || q.y >= dims.y {
            continue;
        }
        let t = texel_or_partner(q, dims);
        if !t.valid {
            continue;
        }
        let w = select(1.0 - f.x, f.x, o.x == 1) * select(1.0 - f.y, f.y, o.y == 1);
        su = su + w * t.tu;
        sn = sn + w * t.n;
        sv = sv + w * t.tv;
        sp = sp + w * t.p;
        weight = weight + w;
    }
    var frame: SurfaceFrame;
    frame.valid = weight >= max(warp.params.z, 1e-6);
    let inv = 1.0 / max(weight, 1e-6);
    let n = sn * inv;
    let u = su * inv;
    frame.valid = frame.valid && abs(length(n) - 1.0) < 0.25 && abs(length(u) - 1.0) < 0.25;
    frame.n = normalize(n);
    frame.tu = normalize(u - frame.n * dot(frame.n, u));
    let v = sv * inv;
    frame.tv = normalize(v - frame.n * dot(frame.n, v) - frame.tu * dot(frame.tu, v));
    frame.p = sp * inv;
    return frame;
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
    // The surface point the vertex hangs from (p_s of eq. 12).
    anchor: vec3<f32>,
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
// c2 = c3, common in SVG), the chord towards the far control points.
fn curve_direction(inst: Instance, t: f32) -> vec2<f32> {
    var d = bezier_tangent(inst, t);
    if dot(d, d) < 1e-16 {
        d = inst.curve23.xy - inst.curve01.xy;
    }
    if dot(d, d) < 1e-16 {
        d = inst.curve23.zw - inst.curve01.xy;
    }
    if dot(d, d) < 1e-16 {
        return vec2<f32>(0.0, 1.0);
    }
    return normalize(d);
}

fn warp_vertex(p: vec3<f32>, normal: vec3<f32>, inst: Instance) -> Warped {
    let mode = i32(warp.params.x + 0.5);
    var uv_in = vec2<f32>(0.0);         // f_uv(p), without the homogeneous 1
    var f_map = vec4<f32>(p, 1.0);      // eq. (5)
    var n_local = normal;
    if mode == 1 {
        uv_in = p.xz;                                   // eq. (6)
        f_map = vec4<f32>(0.0, p.y, 0.0, 1.0);          // eq. (7)
    } else if mode == 2 || mode == 3 {
        let s = (p.z - inst.range.z) / max(inst.range.w - inst.range.z, 1e-12);
        let t = mix(inst.range.x, inst.range.y, s);
        uv_in = bezier(inst, t);                        // eq. (8)
        f_map = vec4<f32>(p.x, p.y, 0.0, 1.0);          // eq. (9)
        if mode == 3 {
            let d = curve_direction(inst, t);
            // The curve normal in UV, turned so that a curve along +v gives eq. (9) (x on +u).
            let nc = vec2<f32>(d.y, -d.x);
            f_map = vec4<f32>(nc.x * p.x, p.y, nc.y * p.x, 1.0);   // eq. (10)
            // The same rotation for the normal: x -> n_c, z -> curve direction.
            n_local = normal.x * vec3<f32>(nc.x, 0.0, nc.y) + vec3<f32>(0.0, normal.y, 0.0)
                + normal.z * vec3<f32>(d.x, 0.0, d.y);
        }
    }
    // eq. (1): M_tex . f_uv
    let uv = vec2<f32>(dot(inst.m_tex0.xyz, vec3<f32>(uv_in, 1.0)), dot(inst.m_tex1.xyz, vec3<f32>(uv_in, 1.0)));
    var frame: SurfaceFrame;
    if mode == 5 {
        // A point attachment's frame is the same for all its vertices: looked up once per instance.
        frame = SurfaceFrame(inst.m_tex0.xyz, inst.m_tex1.xyz, inst.curve01.xyz, vec3<f32>(inst.m_tex0.w, inst.m_tex1.w, inst.curve01.w), inst.curve23.x > 0.5);
    } else if mode == 4 {
        frame = SurfaceFrame(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 0.0), vec3<f32>(0.0, 0.0, 1.0), vec3<f32>(uv.x, 0.0, uv.y), true);
    } else {
        frame = lookup_frame(uv);
    }
    let m_tan = mat4x4<f32>(inst.m_tan0, inst.m_tan1, inst.m_tan2, inst.m_tan3);
    let q = m_tan * f_map;
    // eq. (2): p_w = M_mt . M_tan . f_map(p), M_mt = [t_u n t_v p]
    var out: Warped;
    out.position = frame.tu * q.x + frame.n * q.y + frame.tv * q.z + frame.p;
    out.anchor = frame.p;
    let nt = normal_matrix(mat3x3<f32>(inst.m_tan0.xyz, inst.m_tan1.xyz, inst.m_tan2.xyz)) * n_local;
    out.normal = normalize(frame.tu * nt.x + frame.n * nt.y + frame.tv * nt.z);
    out.valid = frame.valid;
    // Fur gravity (eqs. 11-12): pull down by c * height^2, then restore the distance to the
    // surface point p_s below the vertex (its foot on the tangent plane), so every hair of a
    // patch keeps its length.
    let c = warp.params.y;
    if c > 0.0 {
        let foot = frame.p + frame.tu * q.x + frame.tv * q.z;
        let bent = out.position - vec3<f32>(0.0, c * q.y * q.y, 0.0);
        let len = length(out.position - foot);
        let dir = bent - foot;
        if dot(dir, dir) > 1e-20 {
            out.position = foot + len * normalize(dir);
        }
        out.anchor = foot;
    }
    return out;
}

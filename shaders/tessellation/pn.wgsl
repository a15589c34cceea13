// PN triangles [VPBM01] (src/tessellation/mod.rs pn_edge, pn_normal, interior_vertex): the cubic
// position and quadratic normal of the patch over corners (p0, n0), (p1, n1), (p2, n2) at
// barycentrics w. Shared by the tessellation (shaders/tessellation/tessellate.wgsl) and the per-pixel PN
// depth of the G-buffer (shaders/tessellation/gbuffer_pn.wgsl).

fn normalize_or_zero(v: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    if l > 0.0 {
        return v / l;
    }
    return vec3<f32>(0.0);
}

fn pn_edge(pi: vec3<f32>, ni: vec3<f32>, pj: vec3<f32>) -> vec3<f32> {
    return (2.0 * pi + pj - dot(pj - pi, ni) * ni) / 3.0;
}

fn pn_normal(pi: vec3<f32>, ni: vec3<f32>, pj: vec3<f32>, nj: vec3<f32>) -> vec3<f32> {
    let d = pj - pi;
    let dd = dot(d, d);
    var v = 0.0;
    if dd > 0.0 {
        v = 2.0 * dot(d, ni + nj) / dd;
    }
    return normalize_or_zero(ni + nj - v * d);
}

fn pn_position(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, n0: vec3<f32>, n1: vec3<f32>, n2: vec3<f32>,
               w: vec3<f32>) -> vec3<f32> {
    let u = w.x;
    let v = w.y;
    let x = w.z;
    let b210 = pn_edge(p0, n0, p1);
    let b120 = pn_edge(p1, n1, p0);
    let b021 = pn_edge(p1, n1, p2);
    let b012 = pn_edge(p2, n2, p1);
    let b102 = pn_edge(p2, n2, p0);
    let b201 = pn_edge(p0, n0, p2);
    let e = (b210 + b120 + b021 + b012 + b102 + b201) / 6.0;
    let b111 = e + (e - (p0 + p1 + p2) / 3.0) / 2.0;
    return p0 * (u * u * u) + p1 * (v * v * v) + p2 * (x * x * x) + b210 * (3.0 * u * u * v)
        + b120 * (3.0 * u * v * v) + b021 * (3.0 * v * v * x) + b012 * (3.0 * v * x * x)
        + b102 * (3.0 * u * x * x) + b201 * (3.0 * u * u * x) + b111 * (6.0 * u * v * x);
}

// Not normalized.
fn pn_normal_at(p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>, n0: vec3<f32>, n1: vec3<f32>, n2: vec3<f32>,
                w: vec3<f32>) -> vec3<f32> {
    let u = w.x;
    let v = w.y;
    let x = w.z;
    return n0 * (u * u) + n1 * (v * v) + n2 * (x * x) + pn_normal(p0, n0, p1, n1) * (u * v)
        + pn_normal(p1, n1, p2, n2) * (v * x) + pn_normal(p2, n2, p0, n0) * (u * x);
}

// G-buffer pass with per-pixel PN depth (dissertation 4.1.3 and 5.1.3, Figs. 4.8/5.17;
// docs/tessellation.md): the coarse mesh is rasterized as it is, and each fragment evaluates
// the PN patch of its triangle where the pixel's ray meets it (found from the pixel's
// perspective-correct barycentrics by fixed-point steps). The patch's normal and depth are
// written (view depth and depth buffer), so SSAO sees smooth depth on coarse cloth. The triangle's corners come from the mesh's buffers (drawn without vertex buffers:
// vertex i is corner i % 3 of triangle i / 3).

// #include "gbuffer_common.wgsl"
// #include "pn.wgsl"

@group(2) @binding(0) var<storage, read> mesh_vertices: array<f32>;
@group(2) @binding(1) var<storage, read> mesh_indices: array<u32>;

const FLOATS: u32 = 14u;

struct PnVertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) bary: vec3<f32>,
    @location(1) @interpolate(flat) triangle: u32,
};

struct PnGBufferOut {
    @location(0) color: vec4<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) depth: f32,
    @location(3) surface: vec4<u32>,
    @builtin(frag_depth) frag_depth: f32,
};

fn corner_attr(v: u32, k: u32) -> vec3<f32> {
    let o = v * FLOATS + k;
    return vec3<f32>(mesh_vertices[o], mesh_vertices[o + 1u], mesh_vertices[o + 2u]);
}

fn world_position(v: u32) -> vec3<f32> {
    return (object.model * vec4<f32>(corner_attr(v, 0u), 1.0)).xyz;
}

fn world_normal(v: u32) -> vec3<f32> {
    return normalize_or_zero((object.normal_matrix * vec4<f32>(corner_attr(v, 3u), 0.0)).xyz);
}

// Barycentrics, in triangle (p0, p1, p2), of where the line from `eye` through `x` meets its plane.
fn flat_barycentrics(eye: vec3<f32>, x: vec3<f32>, p0: vec3<f32>, p1: vec3<f32>, p2: vec3<f32>) -> vec3<f32> {
    let e1 = p1 - p0;
    let e2 = p2 - p0;
    let nf = cross(e1, e2);
    let d = x - eye;
    let denom = dot(d, nf);
    var q = x;
    if abs(denom) > 1e-12 {
        q = eye + d * (dot(p0 - eye, nf) / denom);
    }
    let area = dot(nf, nf);
    let b1 = dot(cross(q - p0, e2), nf) / area;
    let b2 = dot(cross(e1, q - p0), nf) / area;
    return vec3<f32>(1.0 - b1 - b2, b1, b2);
}

@vertex
fn vs_main(@builtin(vertex_index) vi: u32) -> PnVertexOut {
    // A PN item draws alone: its object is the first of the draw's range.
    use_object(0u);
    let k = vi % 3u;
    var out: PnVertexOut;
    out.clip = frame.view_proj * vec4<f32>(world_position(mesh_indices[vi]), 1.0);
    out.bary = vec3<f32>(f32(k == 0u), f32(k == 1u), f32(k == 2u));
    out.triangle = vi / 3u;
    return out;
}

@fragment
fn fs_main(in: PnVertexOut, @builtin(front_facing) front: bool) -> PnGBufferOut {
    use_object(0u);
    let i0 = mesh_indices[in.triangle * 3u];
    let i1 = mesh_indices[in.triangle * 3u + 1u];
    let i2 = mesh_indices[in.triangle * 3u + 2u];
    let p0 = world_position(i0);
    let p1 = world_position(i1);
    let p2 = world_position(i2);
    let n0 = world_normal(i0);
    let n1 = world_normal(i1);
    let n2 = world_normal(i2);
    let b = in.bary / (in.bary.x + in.bary.y + in.bary.z);
    // The patch point at the pixel's barycentrics lies off the pixel's ray. Fixed-point steps
    // move the barycentrics until the patch point projects (from the eye, onto the flat
    // triangle) to the pixel: the depth is then the PN surface's along the ray.
    let r = mat3x3<f32>(frame.view[0].xyz, frame.view[1].xyz, frame.view[2].xyz);
    let eye = -(transpose(r) * frame.view[3].xyz);
    var w = b;
    for (var k = 0; k < 4; k++) {
        let q = flat_barycentrics(eye, pn_position(p0, p1, p2, n0, n1, n2, w), p0, p1, p2);
        w = max(w + (b - q), vec3<f32>(0.0));
        w = w / (w.x + w.y + w.z);
    }
    let p = pn_position(p0, p1, p2, n0, n1, n2, w);
    let n = pn_normal_at(p0, p1, p2, n0, n1, n2, w);
    let uv0 = vec2<f32>(mesh_vertices[i0 * FLOATS + 9u], mesh_vertices[i0 * FLOATS + 10u]);
    let uv1 = vec2<f32>(mesh_vertices[i1 * FLOATS + 9u], mesh_vertices[i1 * FLOATS + 10u]);
    let uv2 = vec2<f32>(mesh_vertices[i2 * FLOATS + 9u], mesh_vertices[i2 * FLOATS + 10u]);
    let g = write_gbuffer(p, n, uv0 * w.x + uv1 * w.y + uv2 * w.z, -(frame.view * vec4<f32>(p, 1.0)).z, front);
    let clip = frame.view_proj * vec4<f32>(p, 1.0);
    var out: PnGBufferOut;
    out.color = g.color;
    out.normal = g.normal;
    out.depth = g.depth;
    out.surface = g.surface;
    out.frag_depth = clamp(clip.z / clip.w, 0.0, 1.0);
    return out;
}

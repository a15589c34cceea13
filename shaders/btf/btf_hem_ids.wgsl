// BtfShading's environment light (HEM, docs/btf.md "Environment light"): the BTF-shaded
// meshes drawn again, writing per pixel the triangle it shows (+1; 0: none) and the barycentric
// weights of its second and third corners, so the deferred pass can interpolate the per-vertex
// weight sets of eq. 12. Corners are world positions, three per triangle, drawn unindexed.

struct Params {
    view_proj: mat4x4<f32>,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> corners: array<vec4<f32>>;

struct Varyings {
    @builtin(position) position: vec4<f32>,
    @location(0) @interpolate(flat) triangle: u32,
    @location(1) bary: vec2<f32>,
};

@vertex
fn vs_main(@builtin(vertex_index) i: u32) -> Varyings {
    var out: Varyings;
    out.position = params.view_proj * vec4<f32>(corners[i].xyz, 1.0);
    out.triangle = i / 3u;
    let corner = i % 3u;
    out.bary = vec2<f32>(select(0.0, 1.0, corner == 1u), select(0.0, 1.0, corner == 2u));
    return out;
}

@fragment
fn fs_main(in: Varyings) -> @location(0) vec4<u32> {
    return vec4<u32>(in.triangle + 1u, bitcast<u32>(in.bary.x), bitcast<u32>(in.bary.y), 0u);
}

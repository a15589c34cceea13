// The warp of attach.wgsl as a compute pass: writes the world-space vertices of every
// instance, for export and for tests, through exactly the rendering code path, straight into
// the exported layout: all positions (3 floats each), then all normals, then a valid flag per
// vertex (outliers' positions and normals are zero), so the CPU copies each region once.

// #include "warp.wgsl"

// Vertex buffer read as floats: position(3) normal(3) tangent_u(3) uv(2) tangent_v(3).
@group(0) @binding(0) var<storage, read> vertices: array<f32>;
@group(0) @binding(1) var<storage, read> instances: array<Instance>;
@group(0) @binding(2) var<storage, read_write> out_vertices: array<f32>;
@group(0) @binding(3) var<uniform> counts: vec4<u32>;

@compute @workgroup_size(64)
fn main(@builtin(global_invocation_id) id: vec3<u32>) {
    let vertex_count = counts.x;
    let total = vertex_count * counts.y;
    let k = id.x + id.y * 65535u * 64u;
    if k >= total {
        return;
    }
    let inst = instances[k / vertex_count];
    let v = (k % vertex_count) * 14u;
    let p = vec3<f32>(vertices[v], vertices[v + 1u], vertices[v + 2u]);
    let n = vec3<f32>(vertices[v + 3u], vertices[v + 4u], vertices[v + 5u]);
    let w = warp_vertex(p, n, inst);
    let keep = select(0.0, 1.0, w.valid);
    for (var c = 0u; c < 3u; c = c + 1u) {
        out_vertices[3u * k + c] = w.position[c] * keep;
        out_vertices[3u * (total + k) + c] = w.normal[c] * keep;
    }
    out_vertices[6u * total + k] = keep;
}

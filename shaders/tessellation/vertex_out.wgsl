// The 14-float vertex of src/mesh.rs `Vertex` (position, normal, tangent u, uv, tangent v) as
// the compute passes that build meshes write it: one copy for tessellate.wgsl and woven.wgsl.
// The includer declares `out_vertices: array<f32>` (read_write storage).

const FLOATS: u32 = 14u;

fn store_vertex(v: u32, p: vec3<f32>, n: vec3<f32>, tu: vec3<f32>, uv: vec2<f32>, tv: vec3<f32>) {
    let o = v * FLOATS;
    out_vertices[o] = p.x;
    out_vertices[o + 1u] = p.y;
    out_vertices[o + 2u] = p.z;
    out_vertices[o + 3u] = n.x;
    out_vertices[o + 4u] = n.y;
    out_vertices[o + 5u] = n.z;
    out_vertices[o + 6u] = tu.x;
    out_vertices[o + 7u] = tu.y;
    out_vertices[o + 8u] = tu.z;
    out_vertices[o + 9u] = uv.x;
    out_vertices[o + 10u] = uv.y;
    out_vertices[o + 11u] = tv.x;
    out_vertices[o + 12u] = tv.y;
    out_vertices[o + 13u] = tv.z;
}

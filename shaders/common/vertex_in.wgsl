// The mesh vertex layout (src/mesh.rs `Vertex`), shared by every pass that reads meshes.
struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent_u: vec3<f32>,
    @location(3) uv: vec2<f32>,
    @location(4) tangent_v: vec3<f32>,
};

// What the G-buffer and depth passes read of a mesh vertex (src/mesh.rs
// `Vertex::SHADING_ATTRIBUTES`): no tangents, whose locations (2, 4) carry a single cuboid's
// coefficients instead (item_in.wgsl `CuboidItemIn`).
struct MeshVertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(3) uv: vec2<f32>,
};

// G-buffer pass for items under a non-linear cuboid transform (src/draw.rs): the vertex lands
// at cuboid(cell map * model * p); the fragment stage is the plain G-buffer's.

// #include "gbuffer_common.wgsl"
// #include "item_in.wgsl"
// #include "cuboid.wgsl"

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) view_depth: f32,
    @location(3) @interpolate(flat) object: u32,
};

// One instance per item of the draw (`index` picks its object for the fragment stage).
fn cuboid_vertex(v: VertexIn, item: ItemIn, index: u32, direct_normals: bool) -> VertexOut {
    let d = cuboid_deform(item_point(item, v.position).xyz, item.grid);
    let world = vec4<f32>(d.position, 1.0);
    var out: VertexOut;
    out.clip = frame.view_proj * world;
    // Normalized per vertex: J scales normals differently at each vertex.
    out.normal = normalize(cuboid_normal(d.jacobian, item_normal(item, v.normal), direct_normals));
    out.uv = v.uv;
    out.view_depth = -(frame.view * world).z;
    out.object = index;
    return out;
}

// One entry point per normal method (NormalMethod in src/cuboid.rs).
@vertex
fn vs_tangent_space(v: VertexIn, item: ItemIn, @builtin(instance_index) index: u32) -> VertexOut {
    return cuboid_vertex(v, item, index, false);
}

@vertex
fn vs_direct(v: VertexIn, item: ItemIn, @builtin(instance_index) index: u32) -> VertexOut {
    return cuboid_vertex(v, item, index, true);
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> GBufferOut {
    use_object(in.object);
    return write_gbuffer(in.normal, in.uv, in.view_depth, front);
}

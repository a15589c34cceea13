// G-buffer pass for items under a non-linear cuboid transform (src/draw.rs): the vertex lands
// at cuboid(model * p); the fragment stage is the plain G-buffer's.

// #include "gbuffer_common.wgsl"
// #include "cuboid.wgsl"

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) view_depth: f32,
    @location(3) @interpolate(flat) object: u32,
};

// One instance per item of the draw.
fn cuboid_vertex(v: VertexIn, item: u32, direct_normals: bool) -> VertexOut {
    use_object(item);
    let d = cuboid_deform((object.model * vec4<f32>(v.position, 1.0)).xyz);
    let world = vec4<f32>(d.position, 1.0);
    var out: VertexOut;
    out.clip = frame.view_proj * world;
    // Normalized per vertex: J scales normals differently at each vertex.
    let n = (object.normal_matrix * vec4<f32>(v.normal, 0.0)).xyz;
    out.normal = normalize(cuboid_normal(d.jacobian, n, direct_normals));
    out.uv = v.uv;
    out.view_depth = -(frame.view * world).z;
    out.object = item;
    return out;
}

// One entry point per normal method (NormalMethod in src/cuboid.rs).
@vertex
fn vs_tangent_space(v: VertexIn, @builtin(instance_index) item: u32) -> VertexOut {
    return cuboid_vertex(v, item, false);
}

@vertex
fn vs_direct(v: VertexIn, @builtin(instance_index) item: u32) -> VertexOut {
    return cuboid_vertex(v, item, true);
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> GBufferOut {
    use_object(in.object);
    return write_gbuffer(in.normal, in.uv, in.view_depth, front);
}

// G-buffer pass (dissertation section 4.2) for plain meshes.

// #include "gbuffer_common.wgsl"
// #include "item_in.wgsl"

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) view_depth: f32,
    @location(3) @interpolate(flat) object: u32,
    @location(4) world: vec3<f32>,
};

// One instance per item of the draw (`index` picks its object for the fragment stage).
@vertex
fn vs_main(v: MeshVertexIn, item: ItemIn, @builtin(instance_index) index: u32) -> VertexOut {
    let world = item_point(item, v.position);
    var out: VertexOut;
    out.clip = frame.view_proj * world;
    out.normal = item_normal(item, v.normal);
    out.uv = v.uv;
    out.view_depth = -(frame.view * world).z;
    out.object = index;
    out.world = world.xyz;
    return out;
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> GBufferOut {
    use_object(in.object);
    return write_gbuffer(in.world, in.normal, in.uv, in.view_depth, front);
}

// G-buffer pass (dissertation section 4.2) for plain meshes.

// #include "gbuffer_common.wgsl"

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) view_depth: f32,
    @location(3) @interpolate(flat) object: u32,
};

// One instance per item of the draw.
@vertex
fn vs_main(v: VertexIn, @builtin(instance_index) item: u32) -> VertexOut {
    use_object(item);
    let world = object.model * vec4<f32>(v.position, 1.0);
    var out: VertexOut;
    out.clip = frame.view_proj * world;
    out.normal = (object.normal_matrix * vec4<f32>(v.normal, 0.0)).xyz;
    out.uv = v.uv;
    out.view_depth = -(frame.view * world).z;
    out.object = item;
    return out;
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> GBufferOut {
    use_object(in.object);
    return write_gbuffer(in.normal, in.uv, in.view_depth, front);
}

// Attached detail geometry into the G-buffer: each instance's vertices are warped onto the
// surface through the matrix texture (warp.wgsl); outlier vertices discard their fragments.

// #include "gbuffer_common.wgsl"
// #include "warp.wgsl"
// #include "instance_in.wgsl"

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) view_depth: f32,
    // 1 where a vertex of the primitive is an outlier.
    @location(3) outlier: f32,
    @location(4) world: vec3<f32>,
};

@vertex
fn vs_main(v: VertexIn, i: InstanceIn) -> VertexOut {
    let inst = Instance(i.m_tex0, i.m_tex1, i.m_tan0, i.m_tan1, i.m_tan2, i.m_tan3, i.curve01, i.curve23, i.range);
    let w = warp_vertex(v.position, v.normal, inst);
    let world = vec4<f32>(w.position, 1.0);
    var out: VertexOut;
    out.clip = frame.view_proj * world;
    out.normal = w.normal;
    out.uv = v.uv;
    out.view_depth = -(frame.view * world).z;
    out.outlier = select(1.0, 0.0, w.valid);
    out.world = w.position;
    return out;
}

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> GBufferOut {
    // An attached item draws alone: its object is the first of the draw's range.
    use_object(0u);
    // Written before the discard: the tangent frame's derivatives need uniform control flow.
    let g = write_gbuffer(in.world, in.normal, in.uv, in.view_depth, front);
    if in.outlier > 0.0 {
        discard;
    }
    return g;
}

// Depth only, into tiles of one texture, one view per tile (src/render/draw/ `depth_tiles`):
// shadow maps of many lights in one pass. Each draw fills one tile (group 3), which the pass's
// scissor keeps it inside: plain meshes instanced over the draw's items, without a fragment
// stage, attached items over their attachments.

// #include "vertex_in.wgsl"
// #include "item_in.wgsl"
// #include "warp.wgsl"
// #include "instance_in.wgsl"
// #include "depth_tiles.wgsl"

@vertex
fn vs_plain(v: MeshVertexIn, item: ItemIn) -> @builtin(position) vec4<f32> {
    return views.tiles[draw_tile.x].to_tile * item_point(item, v.position);
}

struct AttachedOut {
    @builtin(position) clip: vec4<f32>,
    // 1 where a vertex of the primitive is an outlier.
    @location(0) outlier: f32,
};

@vertex
fn vs_attached(v: VertexIn, i: InstanceIn) -> AttachedOut {
    let inst = Instance(i.m_tex0, i.m_tex1, i.m_tan0, i.m_tan1, i.m_tan2, i.m_tan3, i.curve01, i.curve23, i.range);
    let w = warp_vertex(v.position, v.normal, inst);
    var out: AttachedOut;
    out.clip = views.tiles[draw_tile.x].to_tile * vec4<f32>(w.position, 1.0);
    out.outlier = select(1.0, 0.0, w.valid);
    return out;
}

// Drops the primitives of outlier attachments.
@fragment
fn fs_attached(in: AttachedOut) {
    if in.outlier > 0.0 {
        discard;
    }
}

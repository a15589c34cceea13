// Depth only, into tiles of one texture, one view per tile (src/render/draw/ `depth_tiles`):
// shadow maps of many lights in one pass. Each draw fills one tile (group 3): plain meshes
// instanced over the draw's items, attached items over their attachments.

// #include "vertex_in.wgsl"
// #include "item_in.wgsl"
// #include "warp.wgsl"
// #include "instance_in.wgsl"
// #include "depth_tiles.wgsl"

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) tile: u32,
    // 1 where a vertex of the primitive is an outlier (attachments).
    @location(1) outlier: f32,
};

@vertex
fn vs_plain(v: MeshVertexIn, item: ItemIn) -> VertexOut {
    let tile = draw_tile.x;
    var out: VertexOut;
    out.clip = views.tiles[tile].to_tile * item_point(item, v.position);
    out.tile = tile;
    out.outlier = 0.0;
    return out;
}

@vertex
fn vs_attached(v: VertexIn, i: InstanceIn) -> VertexOut {
    let inst = Instance(i.m_tex0, i.m_tex1, i.m_tan0, i.m_tan1, i.m_tan2, i.m_tan3, i.curve01, i.curve23, i.range);
    let w = warp_vertex(v.position, v.normal, inst);
    let tile = draw_tile.x;
    var out: VertexOut;
    out.clip = views.tiles[tile].to_tile * vec4<f32>(w.position, 1.0);
    out.tile = tile;
    out.outlier = select(1.0, 0.0, w.valid);
    return out;
}

@fragment
fn fs_main(in: VertexOut) {
    let r = views.tiles[in.tile].rect;
    let p = in.clip.xy;
    if in.outlier > 0.0 || p.x < r.x || p.y < r.y || p.x >= r.z || p.y >= r.w {
        discard;
    }
}

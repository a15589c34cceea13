// Depth tiles (shaders/depth.wgsl) for items under a non-linear cuboid transform: drawn
// instanced over the draw's items like plain meshes, the vertex deformed by the grid first.

// #include "object.wgsl"
// #include "vertex_in.wgsl"
// #include "item_in.wgsl"
// #include "cuboid.wgsl"
// #include "depth_tiles.wgsl"

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) tile: u32,
};

@vertex
fn vs_main(v: VertexIn, item: ItemIn) -> VertexOut {
    let tile = draw_tile.x;
    let d = cuboid_deform(item_point(item, v.position).xyz, item.grid);
    var out: VertexOut;
    out.clip = views.tiles[tile].to_tile * vec4<f32>(d.position, 1.0);
    out.tile = tile;
    return out;
}

@fragment
fn fs_main(in: VertexOut) {
    let r = views.tiles[in.tile].rect;
    let p = in.clip.xy;
    if p.x < r.x || p.y < r.y || p.x >= r.z || p.y >= r.w {
        discard;
    }
}

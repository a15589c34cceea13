// Depth tiles (shaders/render/depth.wgsl) for items under a non-linear cuboid transform: drawn
// instanced over the draw's items like plain meshes, the vertex deformed by the grid first.

// #include "vertex_in.wgsl"
// #include "item_in.wgsl"
// #include "cuboid.wgsl"
// #include "depth_tiles.wgsl"

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) tile: u32,
};

@vertex
fn vs_main(v: MeshVertexIn, item: ItemIn) -> VertexOut {
    return tile_vertex(cuboid_deform(item_point(item, v.position).xyz, item.grid).position);
}

// A single cuboid (item_in.wgsl `CuboidItemIn`).
@vertex
fn vs_cuboid(v: MeshVertexIn, c: CuboidItemIn) -> VertexOut {
    let rows = CellRows(c.x_left, c.x_right, c.y_left, c.y_right, c.z_left, c.z_right);
    return tile_vertex(cuboid_eval(item_point(cuboid_item(c), v.position).xyz, rows).position);
}

fn tile_vertex(world: vec3<f32>) -> VertexOut {
    let tile = draw_tile.x;
    var out: VertexOut;
    out.clip = views.tiles[tile].to_tile * vec4<f32>(world, 1.0);
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

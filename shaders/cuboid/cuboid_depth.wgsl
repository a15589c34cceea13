// Depth tiles (shaders/render/depth.wgsl) for items under a non-linear cuboid transform: drawn
// instanced over the draw's items like plain meshes, the vertex deformed by the grid first.

// #include "vertex_in.wgsl"
// #include "item_in.wgsl"
// #include "cuboid.wgsl"
// #include "depth_tiles.wgsl"

// Depth only: no fragment stage (the pass's scissor keeps a draw inside its tile).

@vertex
fn vs_main(v: MeshVertexIn, item: ItemIn) -> @builtin(position) vec4<f32> {
    return tile_clip(cuboid_deform(item_point(item, v.position).xyz, item.grid).position);
}

// A single cuboid (item_in.wgsl `CuboidItemIn`).
@vertex
fn vs_cuboid(v: MeshVertexIn, c: CuboidItemIn) -> @builtin(position) vec4<f32> {
    let rows = CellRows(c.x_left, c.x_right, c.y_left, c.y_right, c.z_left, c.z_right);
    return tile_clip(cuboid_eval(item_point(cuboid_item(c), v.position).xyz, rows).position);
}

fn tile_clip(world: vec3<f32>) -> vec4<f32> {
    return views.tiles[draw_tile.x].to_tile * vec4<f32>(world, 1.0);
}

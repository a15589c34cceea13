// The views of a depth-tiles pass (src/render/draw/target.rs `TileUniform`), shared by depth.wgsl and
// cuboid_depth.wgsl.

struct TileView {
    // The view's projection folded with the map of its clip space into the tile.
    to_tile: mat4x4<f32>,
};

struct Tiles {
    tiles: array<TileView, 64>,
};

@group(0) @binding(0) var<uniform> views: Tiles;
// x: the tile this draw fills (a draw per tile: wgpu has no geometry shader, and an instance
// per item and tile would need the items' instance-rate transforms repeated per tile).
@group(3) @binding(0) var<uniform> draw_tile: vec4<u32>;

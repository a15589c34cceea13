// The views of a depth-tiles pass (src/draw.rs `TileUniform`), shared by depth.wgsl and
// cuboid_depth.wgsl.

struct TileView {
    // The view's projection folded with the map of its clip space into the tile.
    to_tile: mat4x4<f32>,
    // The tile in texels: x0, y0, x1, y1.
    rect: vec4<f32>,
};

struct Tiles {
    tiles: array<TileView, 64>,
    // x: the number of tiles. Plain and cuboid draws have that many instances per item:
    // instance i draws item i / count into tile i % count.
    count: vec4<u32>,
};

@group(0) @binding(0) var<uniform> views: Tiles;

//! What differs between the targets a scene is drawn into: group 0 (the camera, or the views of
//! the tiles), group 3 (a tile's index), the attachments, and how often each draw is recorded.

use glam::{Mat4, Vec4};

/// The most tiles one depth draw fills (the size of the views array in shaders/render/depth_tiles.wgsl).
pub const MAX_TILES: usize = 64;

/// One tile of a depth target: the view drawn into it and where it lies in the texture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tile {
    pub view_proj: Mat4,
    /// The tile's rectangle in texels: x, y, width, height.
    pub rect: [u32; 4],
}

/// shaders/render/gbuffer.wgsl's frame uniform.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct FrameUniform {
    pub view_proj: [[f32; 4]; 4],
    pub view: [[f32; 4]; 4],
}

/// shaders/render/depth_tiles.wgsl `TileView`: a tile's view-projection folded with the map from clip
/// space into its rectangle of the texture (the pass's scissor clips each draw to the rectangle).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TileUniform {
    to_tile: [[f32; 4]; 4],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct TilesUniform {
    pub tiles: [TileUniform; MAX_TILES],
}

impl TilesUniform {
    pub fn new(tiles: &[Tile], width: u32, height: u32) -> TilesUniform {
        let mut uniform = TilesUniform { tiles: [TileUniform { to_tile: [[0.0; 4]; 4] }; MAX_TILES] };
        for (u, t) in uniform.tiles.iter_mut().zip(tiles) {
            *u = tile_uniform(t, width, height);
        }
        uniform
    }
}

/// The map from a view's clip space into its tile: NDC [-1, 1]^2 onto the tile's rectangle
/// of the whole texture's NDC (y up in NDC, texel rows down).
fn tile_uniform(t: &Tile, width: u32, height: u32) -> TileUniform {
    let (w, h) = (width as f32, height as f32);
    let [x, y, tw, th] = t.rect.map(|v| v as f32);
    let (x0, x1) = (2.0 * x / w - 1.0, 2.0 * (x + tw) / w - 1.0);
    let (y1, y0) = (1.0 - 2.0 * y / h, 1.0 - 2.0 * (y + th) / h);
    let scale_bias = Mat4::from_cols(
        Vec4::new((x1 - x0) / 2.0, 0.0, 0.0, 0.0),
        Vec4::new(0.0, (y1 - y0) / 2.0, 0.0, 0.0),
        Vec4::new(0.0, 0.0, 1.0, 0.0),
        Vec4::new((x0 + x1) / 2.0, (y0 + y1) / 2.0, 0.0, 1.0),
    );
    TileUniform { to_tile: (scale_bias * t.view_proj).to_cols_array_2d() }
}

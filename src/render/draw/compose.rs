//! Each item's transform after the linear fast path, the vertex stage that draws it, and the
//! draws a pass makes: consecutive items that share a mesh, maps and vertex stage draw as one
//! instanced draw. The cells of every non-linear grid lie in one texture per pass.

use std::sync::Arc;

use glam::{DMat3, DMat4, DVec3, Mat4};

use crate::cuboid::{CuboidGrid, NormalMethod, fast_path};
use crate::gpu::pass::WriteSlots;
use crate::gpu::{GpuContext, GpuImage, TextureDesc};
use crate::render::scene::{DrawItem, Image8};

use super::objects::OBJECT_SIZE;

/// shaders/common/item_in.wgsl `ItemIn`: an item's vertex-stage transform, one entry of the
/// instance-rate vertex buffer of all items of a pass (lavapipe fetches it once per batch of
/// vertices; read from the objects' storage buffer, it was a gather per vertex).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct ItemVertex {
    /// The model matrix, or under a non-linear grid the grid's cell map after it.
    transform: [[f32; 4]; 4],
    /// The model's inverse transpose (xyz of each column), under a non-linear grid scaled as
    /// its normal method needs ([`CuboidGrid::normal_scale`]).
    normal: [[f32; 4]; 3],
    /// A non-linear grid of several cells: cells per axis, and its first cell in the pass's cell
    /// texture. Zero without one.
    grid: [u32; 4],
    /// A single cuboid's (a grid of one cell) coefficient matrix C, by rows as in
    /// shaders/cuboid/cuboid.wgsl (zero otherwise): read as instance attributes, where a grid's cells
    /// cost a texel load per row and vertex.
    cuboid: [[f32; 4]; 6],
}

pub const ITEM_BYTES: u64 = std::mem::size_of::<ItemVertex>() as u64;

impl ItemVertex {
    const ATTRIBUTES: [wgpu::VertexAttribute; 8] = wgpu::vertex_attr_array![
        5 => Float32x4, 6 => Float32x4, 7 => Float32x4, 8 => Float32x4,
        9 => Float32x4, 10 => Float32x4, 11 => Float32x4, 12 => Uint32x4
    ];

    /// shaders/common/item_in.wgsl `CuboidItemIn`: the transform and normal, then C's rows at
    /// locations 2, 4 and 12-15.
    const CUBOID_ATTRIBUTES: [wgpu::VertexAttribute; 13] = {
        let mut a =
            [wgpu::VertexAttribute { format: wgpu::VertexFormat::Float32x4, offset: 0, shader_location: 0 }; 13];
        let c_locations = [2, 4, 12, 13, 14, 15];
        let c_offset = std::mem::offset_of!(ItemVertex, cuboid) as u64;
        let mut i = 0;
        while i < 13 {
            a[i] = if i < 7 {
                wgpu::VertexAttribute { offset: 16 * i as u64, shader_location: 5 + i as u32, ..a[i] }
            } else {
                wgpu::VertexAttribute {
                    offset: c_offset + 16 * (i - 7) as u64,
                    shader_location: c_locations[i - 7],
                    ..a[i]
                }
            };
            i += 1;
        }
        a
    };

    /// Items drawn plainly or under a grid of several cells.
    pub fn layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout {
            array_stride: ITEM_BYTES,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &Self::ATTRIBUTES,
        }
    }

    /// Items under a single cuboid.
    pub fn cuboid_layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout { attributes: &Self::CUBOID_ATTRIBUTES, ..Self::layout() }
    }

    /// `t.model` after the fast path; a remaining non-linear grid's cell map is folded after it
    /// (in f64), so the vertex stage maps a vertex into cell coordinates with one matrix.
    pub fn new(t: &ComposedItem) -> ItemVertex {
        let model = t.model.as_dmat4();
        let normal = DMat3::from_mat4(model).inverse().transpose();
        let (mut grid, mut cuboid) = ([0; 4], [[0.0; 4]; 6]);
        let (transform, normal) = match &t.grid {
            None => (model, normal),
            Some(g) => {
                let to_cells = if t.stage() == VertexStage::Grid(g.normals) {
                    let [x, y, z] = g.cells.map(|n| n as u32);
                    grid = [x, y, z, t.grid_cell];
                    g.cell_map()
                } else {
                    // Into the unit cube of the one cell the item lies in.
                    let [x, y, z] = t.cell.unwrap_or([0; 3]);
                    cuboid = g.cell_rows(x, y, z);
                    DMat4::from_translation(-DVec3::new(x as f64, y as f64, z as f64)) * g.cell_map()
                };
                (to_cells * model, DMat3::from_diagonal(g.normal_scale()) * normal)
            }
        };
        let normal = normal.as_mat3();
        ItemVertex {
            transform: transform.as_mat4().to_cols_array_2d(),
            normal: [normal.x_axis, normal.y_axis, normal.z_axis].map(|c| c.extend(0.0).to_array()),
            grid,
            cuboid,
        }
    }
}

/// The items' transforms after the linear fast path, tested once per composed transform right
/// before drawing, and the draws they make. The cells of all non-linear grids lie in one
/// texture per pass ([`CellTextures`]).
pub struct Composed {
    pub transforms: Vec<ComposedItem>,
    pub draws: Vec<DrawRange>,
    /// Every non-linear grid's cells, [`CuboidGrid::ROWS_PER_CELL`] rows each.
    pub rows: Vec<[f32; 4]>,
}

/// Consecutive items drawn by one draw call.
#[derive(Clone, Copy)]
pub struct DrawRange {
    pub first: usize,
    pub count: usize,
}

/// One item's transform after the fast path.
pub struct ComposedItem {
    pub model: Mat4,
    /// The grid that stays non-linear, and its first cell in the pass's cell texture.
    pub grid: Option<Arc<CuboidGrid>>,
    grid_cell: u32,
    /// The one cell of a grid of several that all of the item's vertices fall in, if so: the
    /// item then draws as that cell's single cuboid, with no per-vertex cell loads.
    cell: Option<[usize; 3]>,
}

/// The vertex stage that draws an item: its transform alone (linear), through a grid's cells
/// in the cell texture, or through a single cuboid whose coefficients are instance data; the
/// latter two with one entry point per normal method.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum VertexStage {
    Linear,
    Grid(NormalMethod),
    Cuboid(NormalMethod),
}

impl ComposedItem {
    /// `item`'s transform after the fast path.
    pub fn new(item: &DrawItem) -> ComposedItem {
        let (model, grid) = fast_path(item.model, item.cuboid.clone());
        // Vertices that may leave the mesh's bounds are not tested against one cell; a grid of
        // one cell is a single cuboid already.
        let cell = match &grid {
            Some(g) if !item.kind.leaves_mesh_bounds() && g.cells != [1, 1, 1] => {
                let (lo, hi) = item.mesh.bounds();
                let (lo, hi) = box_after(model, lo, hi);
                g.cell_holding(lo, hi)
            }
            _ => None,
        };
        ComposedItem { model, grid, grid_cell: 0, cell }
    }

    pub fn stage(&self) -> VertexStage {
        match &self.grid {
            None => VertexStage::Linear,
            Some(g) if g.cells == [1, 1, 1] || self.cell.is_some() => VertexStage::Cuboid(g.normals),
            Some(g) => VertexStage::Grid(g.normals),
        }
    }
}

/// The axis-aligned box that holds the box `lo..hi` after `m` (in f64).
fn box_after(m: Mat4, lo: glam::Vec3, hi: glam::Vec3) -> (DVec3, DVec3) {
    let m = m.as_dmat4();
    (0..8).fold((DVec3::MAX, DVec3::MIN), |(a, b), i| {
        let corner = DVec3::new(
            if i & 1 == 0 { lo.x } else { hi.x } as f64,
            if i & 2 == 0 { lo.y } else { hi.y } as f64,
            if i & 4 == 0 { lo.z } else { hi.z } as f64,
        );
        let p = m.transform_point3(corner);
        (a.min(p), b.max(p))
    })
}

/// Cells per texel row of a pass's cell texture (shaders/cuboid/cuboid.wgsl `CELLS_PER_ROW`), each
/// cell [`CuboidGrid::ROWS_PER_CELL`] texels.
const CELLS_PER_ROW: usize = 1024;

/// Whether `b` can join the instanced draw of `a`: kinds that instance, one vertex stage, on
/// one mesh with the same maps (one object group) and one G-buffer pipeline (whether a BTF
/// shades them, [`crate::render::scene::MaterialFeatures`]).
fn same_draw(a: (&DrawItem, &ComposedItem), b: (&DrawItem, &ComposedItem)) -> bool {
    let same_map = |x: &Option<Arc<Image8>>, y: &Option<Arc<Image8>>| match (x, y) {
        (None, None) => true,
        (Some(x), Some(y)) => Arc::ptr_eq(x, y),
        _ => false,
    };
    let ((ai, at), (bi, bt)) = (a, b);
    ai.kind.instanced()
        && bi.kind.instanced()
        && Arc::ptr_eq(&ai.mesh, &bi.mesh)
        && same_map(&ai.material.texture, &bi.material.texture)
        && same_map(&ai.material.gloss_map, &bi.material.gloss_map)
        && ai.material.features() == bi.material.features()
        && at.stage() == bt.stage()
}

impl Composed {
    pub fn new(gpu: &GpuContext, items: &[DrawItem]) -> anyhow::Result<Composed> {
        let max_range = gpu.limits.max_storage_buffer_binding_size;
        let mut transforms: Vec<ComposedItem> = items.iter().map(ComposedItem::new).collect();
        let mut rows: Vec<[f32; 4]> = Vec::new();
        let mut draws: Vec<DrawRange> = Vec::new();
        // The last grid placed and its first cell: consecutive items that share a grid (a
        // group's transform over many objects) share its cells.
        let mut last_grid: Option<(Arc<CuboidGrid>, u32)> = None;
        for i in 0..items.len() {
            let joins = draws.last().is_some_and(|d| {
                let first = d.first;
                same_draw((&items[first], &transforms[first]), (&items[i], &transforms[i]))
                    && (d.count as u64 + 1) * OBJECT_SIZE <= max_range
            });
            if !joins {
                draws.push(DrawRange { first: i, count: 0 });
            }
            draws.last_mut().expect("pushed above").count += 1;
            let t = &mut transforms[i];
            if let (VertexStage::Grid(_), Some(grid)) = (t.stage(), &t.grid) {
                match &last_grid {
                    Some((placed, cell)) if Arc::ptr_eq(placed, grid) => t.grid_cell = *cell,
                    _ => {
                        t.grid_cell = u32::try_from(rows.len() / CuboidGrid::ROWS_PER_CELL)?;
                        grid.append_cells(&mut rows);
                        last_grid = Some((grid.clone(), t.grid_cell));
                    }
                }
            }
        }
        let (cells, side) = (rows.len() / CuboidGrid::ROWS_PER_CELL, gpu.limits.max_texture_dimension_2d as usize);
        let most = if CELLS_PER_ROW * CuboidGrid::ROWS_PER_CELL <= side { CELLS_PER_ROW * side } else { 0 };
        anyhow::ensure!(
            cells <= most,
            "the scene's cuboid grids have {cells} cells; a pass on this device holds at most {most} \
             (textures of {side} texels a side)"
        );
        let most = gpu.limits.max_buffer_size.min(u64::from(u32::MAX));
        let bytes = items.len() as u64 * OBJECT_SIZE;
        anyhow::ensure!(
            bytes <= most,
            "the scene's {} items need {bytes} bytes of objects; a pass holds at most {most}",
            items.len()
        );
        Ok(Composed { transforms, draws, rows })
    }

    /// Whether any item is drawn through grid cells (and the pass needs its cell texture).
    pub fn any_grid(&self) -> bool {
        !self.rows.is_empty()
    }
}

/// A pass's cell texture (shaders/cuboid/cuboid.wgsl `cuboid_cells`: rgba32float, a row of C per
/// texel, [`CELLS_PER_ROW`] cells per texel row), one per pass until the next submit
/// ([`WriteSlots`]). Lavapipe loads a texel for each vertex with a few vector instructions; a
/// storage buffer indexed per vertex costs it a loop over the lanes with a branch per
/// component.
#[derive(Default)]
pub struct CellTextures {
    slots: WriteSlots<GpuImage>,
}

impl CellTextures {
    pub fn write(&mut self, gpu: &GpuContext, rows: &[[f32; 4]]) -> &GpuImage {
        let row_texels = CELLS_PER_ROW * CuboidGrid::ROWS_PER_CELL;
        let height = rows.len().div_ceil(row_texels).max(1) as u32;
        let image = self.slots.next(
            gpu,
            |image| image.height >= height,
            |_| {
                let usage = wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST;
                let format = wgpu::TextureFormat::Rgba32Float;
                GpuImage::create(
                    gpu,
                    "cuboid grid cells",
                    TextureDesc::d2(row_texels as u32, height.next_power_of_two(), format, usage),
                )
            },
        );
        let texture = &image.texture;
        // Whole texel rows, then the last, partial one.
        let (full, rest) = rows.split_at(rows.len() / row_texels * row_texels);
        for (y, part, width) in [(0, full, row_texels), (full.len() / row_texels, rest, rest.len())] {
            if part.is_empty() {
                continue;
            }
            gpu.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d { x: 0, y: y as u32, z: 0 },
                    aspect: wgpu::TextureAspect::All,
                },
                bytemuck::cast_slice(part),
                wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(width as u32 * 16), rows_per_image: None },
                wgpu::Extent3d { width: width as u32, height: (part.len() / width) as u32, depth_or_array_layers: 1 },
            );
        }
        image
    }
}

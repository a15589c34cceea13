//! The scene drawer: the one place that draws a Scene (plain meshes and deferred-warped
//! attachments, warped the same way everywhere) into a target. Targets:
//!
//! - [`SceneDrawer::gbuffer`]: the deferred renderer's G-buffer (dissertation section 4.2);
//! - [`SceneDrawer::depth_tiles`]: depth only, into tiles of one depth texture, one view per
//!   tile (shadow maps: a light per tile of an atlas). Each draw is recorded once per tile (the
//!   tile's index in group 3, wgpu having no geometry shader). A fragment outside its tile is
//!   discarded, so a tile never spills into its neighbours.

use std::sync::Arc;

use glam::{DMat3, DMat4, DVec3, Mat4, Vec4};

use crate::cuboid::{CuboidGrid, NormalMethod, fast_path};
use crate::gpu::pass::{Bindings, WriteSlots, dynamic_storage_entry, texture_entry, uniform_entry};
use crate::gpu::{
    Bind, BufferRing, ComputePass, GpuContext, GpuImage, PooledBuffer, RenderPipelineDesc, SamplerKind, TextureDesc,
};
use crate::mesh::Vertex;
use crate::scene::{DrawItem, GBuffer, Image8, View};
use crate::warp::{AttachedDraw, InstanceData, MatrixTexture};

/// The most tiles one depth draw fills (the size of the views array in shaders/depth.wgsl).
pub const MAX_TILES: usize = 64;

/// One tile of a depth target: the view drawn into it and where it lies in the texture.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Tile {
    pub view_proj: Mat4,
    /// The tile's rectangle in texels: x, y, width, height.
    pub rect: [u32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct FrameUniform {
    view_proj: [[f32; 4]; 4],
    view: [[f32; 4]; 4],
}

/// shaders/object.wgsl `Object`: one entry of the storage buffer of all objects of a pass
/// (material, and the model matrix for per-pixel PN depth, whose fragment stage needs it).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuObject {
    model: [[f32; 4]; 4],
    normal_matrix: [[f32; 4]; 4],
    base_color: [f32; 4],
    params: [f32; 4],
    extra: [f32; 4],
    unused: [[f32; 4]; 5],
}

/// shaders/item_in.wgsl `ItemIn`: an item's vertex-stage transform, one entry of the
/// instance-rate vertex buffer of all items of a pass (lavapipe fetches it once per batch of
/// vertices; read from the objects' storage buffer, it was a gather per vertex).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ItemVertex {
    /// The model matrix, or under a non-linear grid the grid's cell map after it.
    transform: [[f32; 4]; 4],
    /// The model's inverse transpose (xyz of each column), under a non-linear grid scaled as
    /// its normal method needs ([`CuboidGrid::normal_scale`]).
    normal: [[f32; 4]; 3],
    /// A non-linear grid of several cells: cells per axis, and its first cell in the pass's cell
    /// texture. Zero without one.
    grid: [u32; 4],
    /// A single cuboid's (a grid of one cell) coefficient matrix C, by rows as in
    /// shaders/cuboid.wgsl (zero otherwise): read as instance attributes, where a grid's cells
    /// cost a texel load per row and vertex.
    cuboid: [[f32; 4]; 6],
}

const ITEM_BYTES: u64 = std::mem::size_of::<ItemVertex>() as u64;

impl ItemVertex {
    const ATTRIBUTES: [wgpu::VertexAttribute; 8] = wgpu::vertex_attr_array![
        5 => Float32x4, 6 => Float32x4, 7 => Float32x4, 8 => Float32x4,
        9 => Float32x4, 10 => Float32x4, 11 => Float32x4, 12 => Uint32x4
    ];

    /// shaders/item_in.wgsl `CuboidItemIn`: the transform and normal, then C's rows at
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
    fn layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout {
            array_stride: ITEM_BYTES,
            step_mode: wgpu::VertexStepMode::Instance,
            attributes: &Self::ATTRIBUTES,
        }
    }

    /// Items under a single cuboid.
    fn cuboid_layout() -> wgpu::VertexBufferLayout<'static> {
        wgpu::VertexBufferLayout { attributes: &Self::CUBOID_ATTRIBUTES, ..Self::layout() }
    }

    /// `t.model` after the fast path; a remaining non-linear grid's cell map is folded after it
    /// (in f64), so the vertex stage maps a vertex into cell coordinates with one matrix.
    fn new(t: &ComposedItem) -> ItemVertex {
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

/// An object's size in the storage buffer of all objects: a multiple of every storage offset
/// alignment an adapter may ask (at most 256), so a draw's range can start at any item.
const OBJECT_SIZE: u64 = std::mem::size_of::<GpuObject>() as u64;
const _: () = assert!(OBJECT_SIZE == 256);

/// shaders/depth.wgsl `TileView`: a tile's view-projection folded with the map from clip
/// space into its rectangle of the texture, and that rectangle in texels (x0, y0, x1, y1) for
/// the fragment test.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct TileUniform {
    to_tile: [[f32; 4]; 4],
    rect: [f32; 4],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct TilesUniform {
    tiles: [TileUniform; MAX_TILES],
}

/// Group 2 of shaders/warp.wgsl: the matrix texture's three columns, the warp settings
/// (`uniform`, from `WarpSettings::uniform`) and the seam map.
pub fn warp_binds<'a>(m: &'a MatrixTexture, uniform: &'a [f32; 4]) -> [Bind<'a>; 5] {
    [
        Bind::Texture(&m.col_u),
        Bind::Texture(&m.col_n),
        Bind::Texture(&m.col_v),
        Bind::Uniform(bytemuck::cast_slice(uniform)),
        Bind::Texture(&m.seams),
    ]
}

/// The layout of [`warp_binds`], as seen from `visibility`.
pub fn warp_layout(gpu: &GpuContext, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayout {
    gpu.bind_group_layout(&[
        texture_entry(0, visibility, false),
        texture_entry(1, visibility, false),
        texture_entry(2, visibility, false),
        uniform_entry(3, visibility),
        texture_entry(4, visibility, false),
    ])
}

/// Looks up point attachments' frames once per instance (shaders/attach_resolve.wgsl).
pub struct InstanceResolver {
    pass: ComputePass,
}

impl Default for InstanceResolver {
    fn default() -> Self {
        InstanceResolver { pass: ComputePass::new("attach_resolve.wgsl", "main") }
    }
}

impl InstanceResolver {
    /// A new instance buffer with each instance's frame filled in.
    pub fn resolve(
        &mut self,
        gpu: &GpuContext,
        raw: &wgpu::Buffer,
        draw: &AttachedDraw,
    ) -> anyhow::Result<PooledBuffer> {
        let out = gpu.scratch_pooled(
            "resolved instances",
            raw.size(),
            wgpu::BufferUsages::VERTEX | wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
        );
        let uniform = draw.settings.uniform(false);
        let warp = warp_binds(&draw.matrix, &uniform);
        let io = [Bind::Storage(raw), Bind::StorageRw(&out)];
        self.pass.dispatch(gpu, &[&io, &[], &warp], ComputePass::groups_for(draw.instances.len(), 64))?;
        Ok(out)
    }
}

/// `t.model` is the item's own matrix, or the composed one where the linear fast path folded
/// an affine cuboid grid into it. Only per-pixel PN depth reads the matrices here (vertex
/// stages take [`ItemVertex`]), so other items skip the inverse.
fn gpu_object(item: &DrawItem, t: &ComposedItem) -> GpuObject {
    let (model, m) = (t.model, &item.material);
    let pn = item.pn_pixels;
    GpuObject {
        model: if pn { model } else { Mat4::ZERO }.to_cols_array_2d(),
        normal_matrix: if pn { model.inverse().transpose() } else { Mat4::ZERO }.to_cols_array_2d(),
        base_color: [m.base_color.x, m.base_color.y, m.base_color.z, m.glossiness],
        params: [
            m.uv_scale,
            f32::from(u8::from(m.texture.is_some())),
            f32::from(u8::from(item.detail)),
            f32::from(u8::from(m.gloss_map.is_some())),
        ],
        extra: [m.gloss_min, 0.0, 0.0, 0.0],
        unused: [[0.0; 4]; 5],
    }
}

/// One draw's bind groups: its object group, for an attachment the warp group and the
/// instance buffer, for per-pixel PN depth the mesh's buffers.
struct Prepared {
    /// The object group, and its dynamic offset: the draw's first object.
    object: wgpu::BindGroup,
    offset: u32,
    warp: Option<(wgpu::BindGroup, wgpu::Buffer)>,
    /// Which vertex stage draws the draw's items.
    stage: VertexStage,
    /// Per-pixel PN depth: the mesh's vertex and index buffers (group 2 of gbuffer_pn.wgsl).
    pn: Option<wgpu::BindGroup>,
}

/// The items' transforms after the linear fast path, tested once per composed transform right
/// before drawing, and the draws they make: consecutive items that share a mesh, maps and
/// pipeline draw as one instanced draw, each instance reading its own object and transform.
/// The cells of all non-linear grids lie in one texture per pass ([`CellTextures`]).
struct Composed {
    transforms: Vec<ComposedItem>,
    draws: Vec<DrawRange>,
    /// Every non-linear grid's cells, [`CuboidGrid::ROWS_PER_CELL`] rows each.
    rows: Vec<[f32; 4]>,
}

/// Consecutive items drawn by one draw call.
#[derive(Clone, Copy)]
struct DrawRange {
    first: usize,
    count: usize,
}

/// The layouts of a pass's per-item groups: the object group, with the grids' cells (where any
/// item is under a non-linear grid), the warp group (where anything is attached) and the
/// per-pixel PN group (G-buffer only).
#[derive(Clone, Copy)]
struct ItemLayouts<'a> {
    object: &'a wgpu::BindGroupLayout,
    object_cells: Option<&'a wgpu::BindGroupLayout>,
    warp: Option<&'a wgpu::BindGroupLayout>,
    pn: Option<&'a wgpu::BindGroupLayout>,
}

/// One item's transform after the fast path.
struct ComposedItem {
    model: Mat4,
    /// The grid that stays non-linear, and its first cell in the pass's cell texture.
    grid: Option<Arc<CuboidGrid>>,
    grid_cell: u32,
    /// The one cell of a grid of several that all of the item's vertices fall in, if so: the
    /// item then draws as that cell's single cuboid, with no per-vertex cell loads.
    cell: Option<[usize; 3]>,
}

/// The vertex stage that draws an item: its transform alone (linear), through a grid's cells
/// in the cell texture, or through a single cuboid whose coefficients are instance data; the
/// latter two with one entry point per normal method.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum VertexStage {
    Linear,
    Grid(NormalMethod),
    Cuboid(NormalMethod),
}

impl ComposedItem {
    fn stage(&self) -> VertexStage {
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

/// Cells per texel row of a pass's cell texture (shaders/cuboid.wgsl `CELLS_PER_ROW`), each
/// cell [`CuboidGrid::ROWS_PER_CELL`] texels.
const CELLS_PER_ROW: usize = 1024;

/// Whether `b` can join the instanced draw of `a`: one vertex stage, on one mesh with the
/// same maps (one object group).
fn same_draw(a: (&DrawItem, &ComposedItem), b: (&DrawItem, &ComposedItem)) -> bool {
    let alone = |i: &DrawItem| i.attached.is_some() || i.tessellated.is_some() || i.pn_pixels;
    let same_map = |x: &Option<Arc<Image8>>, y: &Option<Arc<Image8>>| match (x, y) {
        (None, None) => true,
        (Some(x), Some(y)) => Arc::ptr_eq(x, y),
        _ => false,
    };
    let ((ai, at), (bi, bt)) = (a, b);
    !alone(ai)
        && !alone(bi)
        && Arc::ptr_eq(&ai.mesh, &bi.mesh)
        && same_map(&ai.material.texture, &bi.material.texture)
        && same_map(&ai.material.gloss_map, &bi.material.gloss_map)
        && at.stage() == bt.stage()
}

impl Composed {
    fn new(gpu: &GpuContext, items: &[DrawItem]) -> anyhow::Result<Composed> {
        let max_range = gpu.limits.max_storage_buffer_binding_size;
        let mut transforms: Vec<ComposedItem> = items
            .iter()
            .map(|item| {
                let (model, grid) = fast_path(item.model, item.cuboid.clone());
                // Tessellated vertices leave the coarse mesh's bounds; a grid of one cell is
                // a single cuboid already.
                let cell = match &grid {
                    Some(g) if item.tessellated.is_none() && g.cells != [1, 1, 1] => {
                        let (lo, hi) = item.mesh.bounds();
                        let (lo, hi) = box_after(model, lo, hi);
                        g.cell_holding(lo, hi)
                    }
                    _ => None,
                };
                ComposedItem { model, grid, grid_cell: 0, cell }
            })
            .collect();
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
    fn any_grid(&self) -> bool {
        !self.rows.is_empty()
    }

    /// Whether any item is drawn through a single cuboid.
    fn any_cuboid(&self) -> bool {
        self.transforms.iter().any(|t| matches!(t.stage(), VertexStage::Cuboid(_)))
    }
}

/// A pass's cell texture (shaders/cuboid.wgsl `cuboid_cells`: rgba32float, a row of C per
/// texel, [`CELLS_PER_ROW`] cells per texel row), one per pass until the next submit
/// ([`WriteSlots`]). Lavapipe loads a texel for each vertex with a few vector instructions; a
/// storage buffer indexed per vertex costs it a loop over the lanes with a branch per
/// component.
#[derive(Default)]
struct CellTextures {
    slots: WriteSlots<GpuImage>,
}

impl CellTextures {
    fn write(&mut self, gpu: &GpuContext, rows: &[[f32; 4]]) -> &GpuImage {
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

/// What a pass that draws scenes keeps between frames: the buffers of objects and grid cells,
/// per draw its cached bind groups, and the point-attachment resolver (the pipelines live in the
/// context's cache, so a shader reload reaches them).
pub struct SceneDrawer {
    frame: Bindings,
    tiles: Bindings,
    tile_index: Bindings,
    /// All items' objects, one buffer per pass; per draw its object group (cached while the
    /// buffer and its maps stay: a cache shared by all draws would thrash with many maps).
    objects: BufferRing,
    object_groups: Vec<Bindings>,
    warps: Vec<Bindings>,
    pn_meshes: Vec<Bindings>,
    /// The cells (coefficient matrices) of every non-linear grid a pass uses.
    grid_cells: CellTextures,
    /// All items' vertex-stage transforms ([`ItemVertex`]), one instance-rate vertex buffer
    /// per pass; each draw binds its items' range.
    item_vertices: BufferRing,
    white: Image8,
    resolver: InstanceResolver,
    /// The draws the last pass recorded (an attached item counts once).
    draw_count: usize,
}

impl Default for SceneDrawer {
    fn default() -> Self {
        SceneDrawer {
            frame: Bindings::new(wgpu::ShaderStages::VERTEX_FRAGMENT),
            tiles: Bindings::new(wgpu::ShaderStages::VERTEX_FRAGMENT),
            tile_index: Bindings::new(wgpu::ShaderStages::VERTEX),
            objects: BufferRing::new("objects", wgpu::BufferUsages::STORAGE),
            object_groups: Vec::new(),
            warps: Vec::new(),
            pn_meshes: Vec::new(),
            grid_cells: CellTextures::default(),
            item_vertices: BufferRing::new("item transforms", wgpu::BufferUsages::VERTEX),
            white: Image8::new(1, 1, vec![255; 4]),
            resolver: InstanceResolver::default(),
            draw_count: 0,
        }
    }
}

const OBJECT_VISIBILITY: wgpu::ShaderStages = wgpu::ShaderStages::VERTEX_FRAGMENT;

impl SceneDrawer {
    /// The draws the last pass recorded: items that share a mesh, maps and pipeline count once
    /// (an attached item counts once, whatever its tiles).
    pub fn draw_count(&self) -> usize {
        self.draw_count
    }

    /// The layout of group 1 (the objects of a draw, base map, sampler, gloss map) and, for
    /// items under a non-linear grid, binding 4: the pass's cell texture. One group per draw
    /// on both paths: a third group rebound for every trilinear draw cost lavapipe a few
    /// percent.
    fn object_layout(&self, gpu: &GpuContext, with_cells: bool) -> wgpu::BindGroupLayout {
        let white = self.white.gpu(gpu);
        let shape =
            [Bind::Uniform(&[]), Bind::Texture(white), Bind::Sampler(SamplerKind::LinearRepeat), Bind::Texture(white)];
        let mut entries = Bindings::new(OBJECT_VISIBILITY).layout_entries(&shape);
        entries[0] = dynamic_storage_entry(0, OBJECT_VISIBILITY, OBJECT_SIZE);
        if with_cells {
            entries.push(texture_entry(4, wgpu::ShaderStages::VERTEX, false));
        }
        gpu.bind_group_layout(&entries)
    }

    /// Bind groups for every draw (resolving point attachments' frames on first use), and the
    /// buffer of the items' transforms.
    fn prepare(
        &mut self,
        gpu: &GpuContext,
        items: &[DrawItem],
        composed: &Composed,
        layouts: ItemLayouts<'_>,
    ) -> anyhow::Result<(Vec<Prepared>, wgpu::Buffer)> {
        let Composed { transforms, draws, rows } = composed;
        self.draw_count = draws.len();
        while self.object_groups.len() < draws.len() {
            self.object_groups.push(Bindings::new(OBJECT_VISIBILITY));
            self.warps.push(Bindings::new(wgpu::ShaderStages::VERTEX));
            self.pn_meshes.push(Bindings::new(OBJECT_VISIBILITY));
        }
        let cells = (!rows.is_empty()).then(|| self.grid_cells.write(gpu, rows).share());
        // Every item's object in one buffer, one write per pass (a write per item made wgpu
        // allocate a staging buffer each: most of a frame of thousands of small objects).
        let objects: Vec<GpuObject> = items.iter().zip(transforms).map(|(item, t)| gpu_object(item, t)).collect();
        let object_buffer = self.objects.write(gpu, bytemuck::cast_slice(&objects)).clone();
        let item_vertices: Vec<ItemVertex> = transforms.iter().map(ItemVertex::new).collect();
        let item_buffer = self.item_vertices.write(gpu, bytemuck::cast_slice(&item_vertices)).clone();
        let mut prepared = Vec::with_capacity(draws.len());
        for (d, draw) in draws.iter().enumerate() {
            let (item, t) = (&items[draw.first], &transforms[draw.first]);
            let m = &item.material;
            let tex = m.texture.as_deref().unwrap_or(&self.white).gpu(gpu);
            let gloss = m.gloss_map.as_deref().unwrap_or(&self.white).gpu(gpu);
            // Each draw binds its own items' objects only: lavapipe copies a bound range for
            // every draw.
            let mut binds = vec![
                Bind::DynamicStorage(&object_buffer, draw.count as u64 * OBJECT_SIZE),
                Bind::Texture(tex),
                Bind::Sampler(SamplerKind::LinearRepeat),
                Bind::Texture(gloss),
            ];
            let offset = u32::try_from(draw.first as u64 * OBJECT_SIZE)?;
            let mut layout = layouts.object;
            let stage = t.stage();
            if let (VertexStage::Grid(_), Some(cells), Some(with_cells)) = (stage, &cells, layouts.object_cells) {
                binds.push(Bind::Texture(cells));
                layout = with_cells;
            }
            let object = self.object_groups[d].bind_group(gpu, layout, &binds);
            let warp = match (&item.attached, layouts.warp) {
                (Some(a), Some(layout)) => {
                    let resolver = &mut self.resolver;
                    let buffer = a.draw_buffer(gpu, |raw| resolver.resolve(gpu, raw, a))?.clone();
                    let uniform = a.settings.uniform(a.per_instance_frames());
                    Some((self.warps[d].bind_group(gpu, layout, &warp_binds(&a.matrix, &uniform)), buffer))
                }
                _ => None,
            };
            // Per-pixel PN depth reads the mesh as it is: an item under a non-linear grid draws
            // through the grid instead.
            let pn = match layouts.pn {
                Some(layout) if item.pn_pixels && stage == VertexStage::Linear => {
                    // The mesh's own buffers, as gbuffer_pn.wgsl's group 2 reads them.
                    let mesh = item.mesh.gpu(gpu);
                    let binds = [Bind::Storage(&mesh.vertices), Bind::Storage(&mesh.indices)];
                    Some(self.pn_meshes[d].bind_group(gpu, layout, &binds))
                }
                _ => None,
            };
            prepared.push(Prepared { object, offset, warp, stage, pn });
        }
        Ok((prepared, item_buffer))
    }

    /// Draws `items` into a new G-buffer of the view's size (pooled targets; recorded, submitted
    /// with the frame).
    pub fn gbuffer(
        &mut self,
        gpu: &GpuContext,
        items: &[DrawItem],
        camera: crate::scene::Camera,
        view: View,
    ) -> anyhow::Result<GBuffer> {
        let (w, h) = (view.width, view.height);
        let formats = *gpu.formats();
        let color = GpuImage::target(gpu, "gbuffer color", w, h, formats.hdr);
        let normal = GpuImage::target(gpu, "gbuffer normal", w, h, formats.hdr);
        let depth = GpuImage::target(gpu, "gbuffer depth", w, h, formats.linear_depth);
        let depth_buffer = GpuImage::target(gpu, "gbuffer depth buffer", w, h, formats.depth);

        let frame_uniform =
            FrameUniform { view_proj: view.view_proj.to_cols_array_2d(), view: view.view.to_cols_array_2d() };
        let frame_binds = [Bind::Uniform(bytemuck::bytes_of(&frame_uniform))];
        let frame_layout = self.frame.layout(gpu, &frame_binds);
        let frame_bg = self.frame.bind_group(gpu, &frame_layout, &frame_binds);
        let object_layout = self.object_layout(gpu, false);
        // The attached pipeline only where something is attached: the node then depends on attach.wgsl.
        let warp_layout =
            items.iter().any(|i| i.attached.is_some()).then(|| warp_layout(gpu, wgpu::ShaderStages::VERTEX));
        let targets = [formats.hdr, formats.hdr, formats.linear_depth];
        let depth_test = Some((formats.depth, wgpu::CompareFunction::Less));
        let vertex = [Some(Vertex::shading_layout()), Some(ItemVertex::layout())];
        let plain = gpu.render_pipeline(&RenderPipelineDesc {
            depth: depth_test,
            ..RenderPipelineDesc::new("gbuffer.wgsl", &[Some(&frame_layout), Some(&object_layout)], &vertex, &targets)
        })?;
        let attached = match &warp_layout {
            Some(warp_layout) => attached_variants(items, |constants| {
                gpu.render_pipeline(&RenderPipelineDesc {
                    depth: depth_test,
                    constants,
                    ..RenderPipelineDesc::new(
                        "attach.wgsl",
                        &[Some(&frame_layout), Some(&object_layout), Some(warp_layout)],
                        &[Some(Vertex::layout()), Some(InstanceData::layout())],
                        &targets,
                    )
                })
            })?,
            None => [None, None],
        };
        let composed = Composed::new(gpu, items)?;
        let object_cells_layout = composed.any_grid().then(|| self.object_layout(gpu, true));
        let cuboid_vertex = [Some(Vertex::shading_layout()), Some(ItemVertex::cuboid_layout())];
        let trilinear =
            |layout: &wgpu::BindGroupLayout, vertex: &[Option<wgpu::VertexBufferLayout<'_>>], entries: [&str; 2]| {
                let groups = [Some(&frame_layout), Some(layout)];
                let pipeline = |vertex_entry| {
                    gpu.render_pipeline(&RenderPipelineDesc {
                        vertex_entry,
                        depth: depth_test,
                        ..RenderPipelineDesc::new("cuboid_gbuffer.wgsl", &groups, vertex, &targets)
                    })
                };
                anyhow::Ok([pipeline(entries[0])?, pipeline(entries[1])?])
            };
        let grid = match &object_cells_layout {
            Some(layout) => Some(trilinear(layout, &vertex, ["vs_tangent_space", "vs_direct"])?),
            None => None,
        };
        let cuboid = match composed.any_cuboid() {
            true => Some(trilinear(&object_layout, &cuboid_vertex, ["vs_cuboid_tangent_space", "vs_cuboid_direct"])?),
            false => None,
        };
        let pn_layout = items.iter().find(|i| i.pn_pixels).map(|item| {
            let mesh = item.mesh.gpu(gpu);
            Bindings::new(OBJECT_VISIBILITY).layout(gpu, &[Bind::Storage(&mesh.vertices), Bind::Storage(&mesh.indices)])
        });
        let pn = match &pn_layout {
            Some(layout) => Some(gpu.render_pipeline(&RenderPipelineDesc {
                depth: depth_test,
                ..RenderPipelineDesc::new(
                    "gbuffer_pn.wgsl",
                    &[Some(&frame_layout), Some(&object_layout), Some(layout)],
                    &[],
                    &targets,
                )
            })?),
            None => None,
        };
        let layouts = ItemLayouts {
            object: &object_layout,
            object_cells: object_cells_layout.as_ref(),
            warp: warp_layout.as_ref(),
            pn: pn_layout.as_ref(),
        };
        let (prepared, item_buffer) = self.prepare(gpu, items, &composed, layouts)?;

        gpu.record(|enc| {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("gbuffer"),
                color_attachments: &[color.clear_attachment(), normal.clear_attachment(), depth.clear_attachment()],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &depth_buffer.view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: gpu.pass_timestamps(),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_bind_group(0, &frame_bg, &[]);
            let pipelines = Pipelines {
                plain: &plain,
                attached: [attached[0].as_ref(), attached[1].as_ref()],
                grid: grid.as_ref().map(|[tangent, direct]| [tangent, direct]),
                cuboid: cuboid.as_ref().map(|[tangent, direct]| [tangent, direct]),
                pn: pn.as_ref(),
            };
            draw_items(gpu, &mut pass, items, &composed.draws, &prepared, &pipelines, &item_buffer, &[]);
        });
        Ok(GBuffer { color, normal, depth, depth_buffer, camera, view })
    }

    /// Draws `items` depth-only into a new `width` x `height` depth texture (the context's depth
    /// format, sampleable), one view per tile. Texels outside every tile stay at 1 (far).
    pub fn depth_tiles(
        &mut self,
        gpu: &GpuContext,
        items: &[DrawItem],
        tiles: &[Tile],
        width: u32,
        height: u32,
    ) -> anyhow::Result<GpuImage> {
        anyhow::ensure!(
            (1..=MAX_TILES).contains(&tiles.len()),
            "a depth draw fills 1 to {MAX_TILES} tiles, not {}",
            tiles.len()
        );
        if let Some(t) = tiles.iter().find(|t| t.rect[0] + t.rect[2] > width || t.rect[1] + t.rect[3] > height) {
            anyhow::bail!("tile {:?} lies outside the {width}x{height} texture", t.rect);
        }
        let format = gpu.formats().depth;
        let target = gpu.acquire(
            "depth tiles",
            TextureDesc::d2(
                width,
                height,
                format,
                wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
            ),
        );
        let mut uniform = TilesUniform { tiles: [TileUniform { to_tile: [[0.0; 4]; 4], rect: [0.0; 4] }; MAX_TILES] };
        for (u, t) in uniform.tiles.iter_mut().zip(tiles) {
            *u = tile_uniform(t, width, height);
        }
        let tile_binds = [Bind::Uniform(bytemuck::bytes_of(&uniform))];
        let tiles_layout = self.tiles.layout(gpu, &tile_binds);
        let tiles_bg = self.tiles.bind_group(gpu, &tiles_layout, &tile_binds);
        let object_layout = self.object_layout(gpu, false);
        let any_attached = items.iter().any(|i| i.attached.is_some());
        let warp_layout = any_attached.then(|| warp_layout(gpu, wgpu::ShaderStages::VERTEX));
        let index_layout = self.tile_index.layout(gpu, &[Bind::Uniform(&[0u8; 16])]);
        let depth_test = Some((format, wgpu::CompareFunction::Less));
        let vertex = [Some(Vertex::shading_layout()), Some(ItemVertex::layout())];
        // Group 2 is the warp group of attached items; plain ones leave it empty.
        let plain = gpu.render_pipeline(&RenderPipelineDesc {
            vertex_entry: "vs_plain",
            depth: depth_test,
            ..RenderPipelineDesc::new(
                "depth.wgsl",
                &[Some(&tiles_layout), Some(&object_layout), None, Some(&index_layout)],
                &vertex,
                &[],
            )
        })?;
        let attached = match &warp_layout {
            Some(warp_layout) => attached_variants(items, |constants| {
                gpu.render_pipeline(&RenderPipelineDesc {
                    vertex_entry: "vs_attached",
                    depth: depth_test,
                    constants,
                    ..RenderPipelineDesc::new(
                        "depth.wgsl",
                        &[Some(&tiles_layout), Some(&object_layout), Some(warp_layout), Some(&index_layout)],
                        &[Some(Vertex::layout()), Some(InstanceData::layout())],
                        &[],
                    )
                })
            })?,
            None => [None, None],
        };
        let composed = Composed::new(gpu, items)?;
        let object_cells_layout = composed.any_grid().then(|| self.object_layout(gpu, true));
        let cuboid_vertex = [Some(Vertex::shading_layout()), Some(ItemVertex::cuboid_layout())];
        let trilinear =
            |layout: &wgpu::BindGroupLayout, vertex: &[Option<wgpu::VertexBufferLayout<'_>>], vertex_entry| {
                gpu.render_pipeline(&RenderPipelineDesc {
                    vertex_entry,
                    depth: depth_test,
                    ..RenderPipelineDesc::new(
                        "cuboid_depth.wgsl",
                        &[Some(&tiles_layout), Some(layout), None, Some(&index_layout)],
                        vertex,
                        &[],
                    )
                })
            };
        let grid = match &object_cells_layout {
            Some(layout) => Some(trilinear(layout, &vertex, "vs_main")?),
            None => None,
        };
        let cuboid = match composed.any_cuboid() {
            true => Some(trilinear(&object_layout, &cuboid_vertex, "vs_cuboid")?),
            false => None,
        };
        let layouts = ItemLayouts {
            object: &object_layout,
            object_cells: object_cells_layout.as_ref(),
            warp: warp_layout.as_ref(),
            pn: None,
        };
        let (prepared, item_buffer) = self.prepare(gpu, items, &composed, layouts)?;
        // Each draw is recorded once per tile and reads its tile index from group 3.
        let index_bgs: Vec<wgpu::BindGroup> = (0..tiles.len() as u32)
            .map(|t| {
                let index = [t, 0, 0, 0];
                self.tile_index.bind_group(gpu, &index_layout, &[Bind::Uniform(bytemuck::bytes_of(&index))])
            })
            .collect();

        gpu.record(|enc| {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some("depth tiles"),
                color_attachments: &[],
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &target.view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: gpu.pass_timestamps(),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_bind_group(0, &tiles_bg, &[]);
            // Depth only: no normals, one pipeline for both methods.
            let pipelines = Pipelines {
                plain: &plain,
                attached: [attached[0].as_ref(), attached[1].as_ref()],
                grid: grid.as_ref().map(|p| [p, p]),
                cuboid: cuboid.as_ref().map(|p| [p, p]),
                pn: None,
            };
            draw_items(gpu, &mut pass, items, &composed.draws, &prepared, &pipelines, &item_buffer, &index_bgs);
        });
        Ok(target)
    }
}

/// The attached-item pipelines a pass needs, by whether the surface has seams (index 1): the
/// variant without seams compiles the partner reads out (`SEAMS` in shaders/warp.wgsl); each is
/// built only if some item needs it.
fn attached_variants(
    items: &[DrawItem],
    build: impl Fn(&[(&str, u32)]) -> Result<wgpu::RenderPipeline, crate::gpu::ShaderError>,
) -> Result<[Option<wgpu::RenderPipeline>; 2], crate::gpu::ShaderError> {
    let needs = |seams: bool| items.iter().any(|i| i.attached.as_ref().is_some_and(|a| a.matrix.has_seams() == seams));
    let variant = |seams: bool| needs(seams).then(|| build(&[("SEAMS", u32::from(seams))])).transpose();
    Ok([variant(false)?, variant(true)?])
}

/// The pipelines of one target: plain meshes, deferred-warped attachments and items under a
/// non-linear cuboid transform (the latter two only where the scene has such items).
struct Pipelines<'a> {
    plain: &'a wgpu::RenderPipeline,
    /// Attached items by whether their surface has seams (the variant without seams compiles
    /// the partner reads out).
    attached: [Option<&'a wgpu::RenderPipeline>; 2],
    /// Items under grids of several cells, by normal method: tangent space, direct.
    grid: Option<[&'a wgpu::RenderPipeline; 2]>,
    /// Items under a single cuboid, by normal method.
    cuboid: Option<[&'a wgpu::RenderPipeline; 2]>,
    /// Per-pixel PN depth (G-buffer only; elsewhere such items draw plainly).
    pn: Option<&'a wgpu::RenderPipeline>,
}

/// Records the draws of `items`, each item's transform from `item_buffer`: each draw once, or
/// where `tiles` has bind groups (a depth target's tile indices), once per tile with its group
/// bound as group 3.
#[allow(clippy::too_many_arguments)]
fn draw_items(
    gpu: &GpuContext,
    pass: &mut wgpu::RenderPass<'_>,
    items: &[DrawItem],
    draws: &[DrawRange],
    prepared: &[Prepared],
    pipelines: &Pipelines<'_>,
    item_buffer: &wgpu::Buffer,
    tiles: &[wgpu::BindGroup],
) {
    let each_tile = |pass: &mut wgpu::RenderPass<'_>, draw: &dyn Fn(&mut wgpu::RenderPass<'_>)| {
        if tiles.is_empty() {
            draw(pass);
        }
        for group in tiles {
            pass.set_bind_group(3, group, &[]);
            draw(pass);
        }
    };
    let mut bound = Bound::default();
    for (draw, p) in draws.iter().zip(prepared) {
        let item = &items[draw.first];
        pass.set_bind_group(1, &p.object, &[p.offset]);
        let trilinear = match (p.stage, pipelines.grid, pipelines.cuboid) {
            (VertexStage::Grid(normals), Some(grid), _) => Some(grid[normals as usize]),
            (VertexStage::Cuboid(normals), _, Some(cuboid)) => Some(cuboid[normals as usize]),
            _ => None,
        };
        let transforms =
            item_buffer.slice(draw.first as u64 * ITEM_BYTES..(draw.first + draw.count) as u64 * ITEM_BYTES);
        if let Some(t) = &item.tessellated {
            // Written by the compute pass this frame: counts never come back to the CPU.
            pass.set_vertex_buffer(0, t.vertices.slice(..));
            pass.set_vertex_buffer(1, transforms);
            pass.set_index_buffer(t.indices.slice(..), wgpu::IndexFormat::Uint32);
            bound.pipeline(pass, trilinear.unwrap_or(pipelines.plain));
            each_tile(pass, &|pass| pass.draw_indexed_indirect(&t.indirect, 0));
            continue;
        }
        let mesh = item.mesh.gpu(gpu);
        if let (Some(group), Some(pipeline)) = (&p.pn, pipelines.pn) {
            // No vertex buffers: the shader reads the triangle's corners from group 2.
            bound.pipeline(pass, pipeline);
            bound.group2(pass, group);
            pass.draw(0..mesh.index_count, 0..1);
            continue;
        }
        pass.set_vertex_buffer(0, mesh.vertices.slice(..));
        pass.set_index_buffer(mesh.indices.slice(..), wgpu::IndexFormat::Uint32);
        let attached = item.attached.as_ref().and_then(|a| pipelines.attached[usize::from(a.matrix.has_seams())]);
        match (trilinear, &item.attached, &p.warp, attached) {
            (None, Some(a), Some((warp_bg, buffer)), Some(pipeline)) => {
                if a.instances.is_empty() {
                    continue;
                }
                bound.pipeline(pass, pipeline);
                bound.group2(pass, warp_bg);
                pass.set_vertex_buffer(1, buffer.slice(..));
                let instances = 0..a.instances.len() as u32;
                each_tile(pass, &|pass| pass.draw_indexed(0..mesh.index_count, 0, instances.clone()));
            }
            _ => {
                pass.set_vertex_buffer(1, transforms);
                bound.pipeline(pass, trilinear.unwrap_or(pipelines.plain));
                let instances = 0..draw.count as u32;
                each_tile(pass, &|pass| pass.draw_indexed(0..mesh.index_count, 0, instances.clone()));
            }
        }
    }
}

/// What a pass has bound: a row of draws with the same pipeline or group 2 binds it once
/// (lavapipe copies descriptor state per bind). Group 2 stays bound across pipelines whose
/// layouts agree on it, as WebGPU specifies.
#[derive(Default)]
struct Bound {
    pipeline: Option<wgpu::RenderPipeline>,
    group2: Option<wgpu::BindGroup>,
}

impl Bound {
    fn pipeline(&mut self, pass: &mut wgpu::RenderPass<'_>, pipeline: &wgpu::RenderPipeline) {
        if self.pipeline.as_ref() != Some(pipeline) {
            pass.set_pipeline(pipeline);
            self.pipeline = Some(pipeline.clone());
        }
    }

    fn group2(&mut self, pass: &mut wgpu::RenderPass<'_>, group: &wgpu::BindGroup) {
        if self.group2.as_ref() != Some(group) {
            pass.set_bind_group(2, group, &[]);
            self.group2 = Some(group.clone());
        }
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
    TileUniform { to_tile: (scale_bias * t.view_proj).to_cols_array_2d(), rect: [x, y, x + tw, y + th] }
}

/// What `werkstatt bench` and tests share with the G-buffer node: one drawer per call site.
pub fn render_gbuffer(
    gpu: &GpuContext,
    drawer: &mut SceneDrawer,
    items: &[DrawItem],
    camera: crate::scene::Camera,
    w: u32,
    h: u32,
) -> anyhow::Result<GBuffer> {
    drawer.gbuffer(gpu, items, camera, View::new(&camera, w, h))
}

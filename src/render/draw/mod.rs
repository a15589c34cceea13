//! The scene drawer: the one place that draws a Scene into a target. Targets
//! ([`kind::TargetKind`]):
//!
//! - [`SceneDrawer::gbuffer`]: the deferred renderer's G-buffer (dissertation section 4.2);
//! - [`SceneDrawer::depth_tiles`]: depth only, into tiles of one depth texture, one view per
//!   tile (shadow maps: a light per tile of an atlas). Each draw is recorded once per tile (the
//!   tile's index in group 3, wgpu having no geometry shader), scissored to the tile, so a tile
//!   never spills into its neighbours. Without a fragment test the pipelines of plain meshes
//!   have no fragment stage: lavapipe then bins and depth-tests only the tile's texels.
//!
//! Both go through one function, [`SceneDrawer::draw`]: it composes the items' transforms
//! ([`compose`]), writes their objects ([`objects`]) and asks each item's kind
//! ([`kind::ItemKind`], one file per kind in [`kinds`]) for its pipeline, bind groups and
//! draw call. [`export`] asks the same kinds for the geometry they draw.

pub mod compose;
pub mod export;
pub mod kind;
pub mod kinds;
mod objects;
mod target;

use std::cell::RefCell;

use crate::gpu::pass::Bindings;
use crate::gpu::{Bind, BufferRing, GpuContext, GpuImage, TextureDesc};
use crate::render::scene::{DrawItem, GBuffer, Image8, View};
use crate::warp::gpu::InstanceResolver;

use compose::{CellTextures, Composed, DrawRange, ITEM_BYTES, ItemVertex};
use kind::{DrawCall, KindDraw, PassCx, PrepareCx, TargetKind};
use objects::{GpuObject, OBJECT_SIZE, OBJECT_VISIBILITY, object_layout};
use target::{FrameUniform, TilesUniform};
pub use target::{MAX_TILES, Tile};

/// The G-buffer's surface target (shaders/common/surface.wgsl): UV and tangent bits, renderable
/// on every backend (GL renders no 32-bit float targets).
pub const SURFACE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba32Uint;

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
    /// Per draw, its kind's group 2.
    kind_groups: Vec<Bindings>,
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
            tiles: Bindings::new(wgpu::ShaderStages::VERTEX),
            tile_index: Bindings::new(wgpu::ShaderStages::VERTEX),
            objects: BufferRing::new("objects", wgpu::BufferUsages::STORAGE),
            object_groups: Vec::new(),
            kind_groups: Vec::new(),
            grid_cells: CellTextures::default(),
            item_vertices: BufferRing::new("item transforms", wgpu::BufferUsages::VERTEX),
            white: Image8::new(1, 1, vec![255; 4]),
            resolver: InstanceResolver::default(),
            draw_count: 0,
        }
    }
}

/// A target as [`SceneDrawer::draw`] fills it.
struct Target<'a> {
    kind: TargetKind,
    label: &'static str,
    group0: (wgpu::BindGroupLayout, wgpu::BindGroup),
    /// Depth tiles: the layout of group 3 and each tile's draw state; each draw is recorded
    /// once per tile.
    tile_index: Option<(wgpu::BindGroupLayout, Vec<TileDraw>)>,
    colors: &'a [&'a GpuImage],
    depth: &'a GpuImage,
}

/// A tile of a depth-tiles target as its draws bind it: group 3 (its index) and its scissor
/// rectangle (x, y, width, height).
type TileDraw = (wgpu::BindGroup, [u32; 4]);

/// One draw as prepared: its items, their object group and the kind's draw.
struct Prepared {
    range: DrawRange,
    object: wgpu::BindGroup,
    /// The object group's dynamic offset: the draw's first object.
    offset: u32,
    draw: KindDraw,
}

impl SceneDrawer {
    /// The draws the last pass recorded: items that share a mesh, maps and pipeline count once
    /// (an attached item counts once, whatever its tiles).
    pub fn draw_count(&self) -> usize {
        self.draw_count
    }

    /// Draws `items` into a new G-buffer of the view's size (pooled targets; recorded, submitted
    /// with the frame).
    pub fn gbuffer(
        &mut self,
        gpu: &GpuContext,
        items: &[DrawItem],
        camera: crate::render::scene::Camera,
        view: View,
    ) -> anyhow::Result<GBuffer> {
        if let Some(mismatch) = kinds::attached::surface_transform_mismatch(items) {
            anyhow::bail!(mismatch);
        }
        let (w, h) = (view.width, view.height);
        let formats = *gpu.formats();
        let color = GpuImage::target(gpu, "gbuffer color", w, h, formats.hdr);
        let normal = GpuImage::target(gpu, "gbuffer normal", w, h, formats.hdr);
        let depth = GpuImage::target(gpu, "gbuffer depth", w, h, formats.linear_depth);
        let surface = GpuImage::target(gpu, "gbuffer surface", w, h, SURFACE_FORMAT);
        let depth_buffer = GpuImage::target(gpu, "gbuffer depth buffer", w, h, formats.depth);
        let frame_uniform =
            FrameUniform { view_proj: view.view_proj.to_cols_array_2d(), view: view.view.to_cols_array_2d() };
        let binds = [Bind::Uniform(bytemuck::bytes_of(&frame_uniform))];
        let layout = self.frame.layout(gpu, &binds);
        let group = self.frame.bind_group(gpu, &layout, &binds);
        let target = Target {
            kind: TargetKind::GBuffer,
            label: "gbuffer",
            group0: (layout, group),
            tile_index: None,
            colors: &[&color, &normal, &depth, &surface],
            depth: &depth_buffer,
        };
        self.draw(gpu, items, &target)?;
        Ok(GBuffer { color, normal, depth, surface, depth_buffer, camera, view })
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
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        let texture = gpu.acquire("depth tiles", TextureDesc::d2(width, height, gpu.formats().depth, usage));
        let uniform = TilesUniform::new(tiles, width, height);
        let binds = [Bind::Uniform(bytemuck::bytes_of(&uniform))];
        let layout = self.tiles.layout(gpu, &binds);
        let group = self.tiles.bind_group(gpu, &layout, &binds);
        let index_layout = self.tile_index.layout(gpu, &[Bind::Uniform(&[0u8; 16])]);
        let index_groups = (0..tiles.len() as u32)
            .zip(tiles)
            .map(|(t, tile)| {
                let index = [t, 0, 0, 0];
                let group =
                    self.tile_index.bind_group(gpu, &index_layout, &[Bind::Uniform(bytemuck::bytes_of(&index))]);
                (group, tile.rect)
            })
            .collect();
        let target = Target {
            kind: TargetKind::DepthTiles,
            label: "depth tiles",
            group0: (layout, group),
            tile_index: Some((index_layout, index_groups)),
            colors: &[],
            depth: &texture,
        };
        self.draw(gpu, items, &target)?;
        Ok(texture)
    }

    /// Draws `items` into `target`: every kind through its own pipeline, bind groups and call.
    fn draw(&mut self, gpu: &GpuContext, items: &[DrawItem], target: &Target<'_>) -> anyhow::Result<()> {
        let composed = Composed::new(gpu, items)?;
        let object = object_layout(gpu, &self.white, false);
        let object_cells = composed.any_grid().then(|| object_layout(gpu, &self.white, true));
        let colors: Vec<wgpu::TextureFormat> = target.colors.iter().map(|c| c.desc.format).collect();
        let pass = PassCx {
            gpu,
            target: target.kind,
            group0: &target.group0.0,
            tile_index: target.tile_index.as_ref().map(|(layout, _)| layout),
            object: &object,
            object_cells: object_cells.as_ref(),
            colors: &colors,
            depth: target.depth.desc.format,
            built: RefCell::default(),
        };
        let (prepared, item_buffer) = self.prepare(&pass, items, &composed)?;
        let tiles = target.tile_index.as_ref().map_or(&[][..], |(_, groups)| groups);
        gpu.record(|enc| {
            let mut render = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some(target.label),
                color_attachments: &target.colors.iter().map(|c| c.clear_attachment()).collect::<Vec<_>>(),
                depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                    view: &target.depth.view,
                    depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(1.0), store: wgpu::StoreOp::Store }),
                    stencil_ops: None,
                }),
                timestamp_writes: gpu.pass_timestamps(),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            render.set_bind_group(0, &target.group0.1, &[]);
            record(&mut render, &prepared, &item_buffer, tiles);
        });
        Ok(())
    }

    /// Bind groups and kind draws for every draw (resolving point attachments' frames on first
    /// use), and the buffer of the items' transforms.
    fn prepare(
        &mut self,
        pass: &PassCx<'_>,
        items: &[DrawItem],
        composed: &Composed,
    ) -> anyhow::Result<(Vec<Prepared>, wgpu::Buffer)> {
        let gpu = pass.gpu;
        let Composed { transforms, draws, rows } = composed;
        self.draw_count = draws.len();
        while self.object_groups.len() < draws.len() {
            self.object_groups.push(Bindings::new(OBJECT_VISIBILITY));
            self.kind_groups.push(Bindings::new(OBJECT_VISIBILITY));
        }
        let cells = (!rows.is_empty()).then(|| self.grid_cells.write(gpu, rows).share());
        // Every item's object in one buffer, one write per pass (a write per item made wgpu
        // allocate a staging buffer each: most of a frame of thousands of small objects).
        let objects: Vec<GpuObject> = items.iter().zip(transforms).map(|(item, t)| GpuObject::new(item, t)).collect();
        let object_buffer = self.objects.write(gpu, bytemuck::cast_slice(&objects)).clone();
        let item_vertices: Vec<ItemVertex> = transforms.iter().map(ItemVertex::new).collect();
        let item_buffer = self.item_vertices.write(gpu, bytemuck::cast_slice(&item_vertices)).clone();
        let mut prepared = Vec::with_capacity(draws.len());
        for (d, range) in draws.iter().enumerate() {
            let (item, t) = (&items[range.first], &transforms[range.first]);
            let m = &item.material;
            let tex = m.texture.as_deref().unwrap_or(&self.white).gpu(gpu);
            let gloss = m.gloss_map.as_deref().unwrap_or(&self.white).gpu(gpu);
            // Each draw binds its own items' objects only: lavapipe copies a bound range for
            // every draw.
            let mut binds = vec![
                Bind::DynamicStorage(&object_buffer, range.count as u64 * OBJECT_SIZE),
                Bind::Texture(tex),
                Bind::Sampler(crate::gpu::SamplerKind::LinearRepeat),
                Bind::Texture(gloss),
            ];
            let offset = u32::try_from(range.first as u64 * OBJECT_SIZE)?;
            let stage = t.stage();
            let mut layout = pass.object;
            if let (compose::VertexStage::Grid(_), Some(cells), Some(with_cells)) = (stage, &cells, pass.object_cells) {
                binds.push(Bind::Texture(cells));
                layout = with_cells;
            }
            let object = self.object_groups[d].bind_group(gpu, layout, &binds);
            let mut cx = PrepareCx { pass, group2: &mut self.kind_groups[d], resolver: &mut self.resolver };
            let kind_draw = item
                .kind
                .prepare(&mut cx, item, stage)
                .map_err(|e| e.context(format!("drawing item {} ({})", range.first, item.kind.name())))?;
            if let Some(draw) = kind_draw {
                prepared.push(Prepared { range: *range, object, offset, draw });
            }
        }
        Ok((prepared, item_buffer))
    }
}

/// Records the prepared draws, each item's transform from `item_buffer`: each draw once, or
/// where `tiles` has bind groups (a depth target's tile indices), once per tile with its group
/// bound as group 3 and the scissor on its rectangle.
fn record(pass: &mut wgpu::RenderPass<'_>, prepared: &[Prepared], item_buffer: &wgpu::Buffer, tiles: &[TileDraw]) {
    let mut bound = Bound::default();
    for p in prepared {
        let (range, k) = (p.range, &p.draw);
        pass.set_bind_group(1, &p.object, &[p.offset]);
        bound.pipeline(pass, &k.pipeline);
        if let Some(group) = &k.group2 {
            bound.group2(pass, group);
        }
        if let Some((vertices, indices)) = &k.mesh {
            pass.set_vertex_buffer(0, vertices.slice(..));
            pass.set_index_buffer(indices.slice(..), wgpu::IndexFormat::Uint32);
        }
        let instances = match &k.instances {
            Some((buffer, count)) => {
                pass.set_vertex_buffer(1, buffer.slice(..));
                *count
            }
            None => {
                if k.mesh.is_some() {
                    let items = range.first as u64 * ITEM_BYTES..(range.first + range.count) as u64 * ITEM_BYTES;
                    pass.set_vertex_buffer(1, item_buffer.slice(items));
                }
                range.count as u32
            }
        };
        let call = |pass: &mut wgpu::RenderPass<'_>| match &k.call {
            DrawCall::Indexed { indices } => pass.draw_indexed(0..*indices, 0, 0..instances),
            DrawCall::IndexedIndirect(args) => pass.draw_indexed_indirect(args, 0),
            DrawCall::Vertices { vertices } => pass.draw(0..*vertices, 0..1),
        };
        if tiles.is_empty() {
            call(pass);
        }
        for (group, [x, y, w, h]) in tiles {
            pass.set_bind_group(3, group, &[]);
            pass.set_scissor_rect(*x, *y, *w, *h);
            call(pass);
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

/// What `werkstatt bench` and tests share with the G-buffer node: one drawer per call site.
pub fn render_gbuffer(
    gpu: &GpuContext,
    drawer: &mut SceneDrawer,
    items: &[DrawItem],
    camera: crate::render::scene::Camera,
    w: u32,
    h: u32,
) -> anyhow::Result<GBuffer> {
    drawer.gbuffer(gpu, items, camera, View::new(&camera, w, h))
}

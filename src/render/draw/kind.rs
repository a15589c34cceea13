//! The item-kind abstraction: how one kind of drawable (a plain mesh, deferred-warped
//! attachments, a GPU tessellation, per-pixel PN depth, ...) is drawn and exported. Each kind
//! is one file in `kinds/` implementing [`ItemKind`]; the scene drawer and the export path only
//! talk to this trait, so a new kind touches nothing else.
//!
//! A kind supplies, per target (G-buffer or depth tiles):
//! - its vertex stage and pipeline ([`ItemKind::prepare`] through [`PassCx::pipeline`]);
//! - its own bind group 2 (the warp group, a mesh's storage buffers);
//! - its draw call ([`KindDraw`]);
//! - its export ([`ItemKind::export`]): the geometry that draw produces.

use std::any::Any;
use std::cell::RefCell;
use std::collections::HashMap;

use crate::gpu::pass::Bindings;
use crate::gpu::{GpuContext, RenderPipelineDesc};
use crate::mesh::Mesh;
use crate::render::scene::{DrawItem, MaterialFeatures};

use super::compose::{ItemVertex, VertexStage};
use crate::warp::gpu::{GpuWarper, InstanceResolver};

/// One kind of drawable. Items carry theirs as `DrawItem::kind`.
pub trait ItemKind: Any + Send + Sync {
    /// The kind's name in errors and statistics ("mesh", "attached", ...).
    fn name(&self) -> &'static str;

    /// Whether neighbouring items of this kind that share a mesh, maps and vertex stage may be
    /// drawn as one instanced draw (each instance reading its own object and transform).
    fn instanced(&self) -> bool {
        false
    }

    /// Whether the drawn vertices can leave the item mesh's bounds (a tessellation's PN
    /// patches do): such items never take the single-cell shortcut under a grid.
    fn leaves_mesh_bounds(&self) -> bool {
        false
    }

    /// Whether the item's `mesh` under its model matrix (and grid) is the surface drawn, so
    /// CPU consumers (camera framing, the ray-traced reference) may use it as the item's shape.
    /// Attachments draw instances of their mesh elsewhere.
    fn places_mesh(&self) -> bool {
        true
    }

    /// Whether the item's object must carry its model matrix and inverse transpose (only a
    /// fragment stage that transforms vertices itself needs them).
    fn object_model(&self) -> bool {
        false
    }

    /// The triangles one draw of `item` rasterizes (every instance's), for budgets such as
    /// the shadow atlas's.
    fn drawn_triangles(&self, item: &DrawItem) -> usize {
        item.mesh.triangle_count()
    }

    /// The draw of `item` (vertex stage `stage`, after the linear fast path) into the pass's
    /// target: its pipeline, group 2, buffers and call. `None`: nothing to draw.
    fn prepare(
        &self,
        cx: &mut PrepareCx<'_, '_>,
        item: &DrawItem,
        stage: VertexStage,
    ) -> anyhow::Result<Option<KindDraw>>;

    /// The geometry this kind draws for `item`, in the item's own space (then placed by its
    /// model matrix and grid, as the vertex stage places it) or as world-space instances. A kind that
    /// cannot export returns an error saying why; it never exports something else.
    fn export(&self, cx: &mut ExportCx<'_>, item: &DrawItem) -> anyhow::Result<Exported>;
}

/// What a kind's export produced.
pub enum Exported {
    /// In the item's space: placed by its model matrix and grid (eq. 3.4), like its vertex stage.
    Local(Mesh),
    /// Instances of the item's mesh in world space, instance-major: instance k owns vertices
    /// `k * per_instance..(k + 1) * per_instance` and its triangles follow instance k - 1's.
    /// Exports keep each instance apart (an OBJ object, a glTF node).
    /// `placements`: each instance's affine map of the item's mesh where the instances are
    /// rigid copies of it (see [`crate::warp::rigid_placements`]) and the export asked for them.
    Instances { mesh: Mesh, per_instance: usize, placements: Option<Vec<glam::Mat4>> },
}

/// Where an export computes what the GPU would: the GPU itself (read back), or the CPU twin of
/// the same shader code. Both give the same geometry (tested per kind).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum ExportDevice {
    Gpu,
    Cpu,
}

/// What a kind's export may use.
pub struct ExportCx<'a> {
    pub gpu: &'a GpuContext,
    pub device: ExportDevice,
    /// The attachment warp as a compute pass (kept between exports).
    pub warper: &'a mut GpuWarper,
    /// Whether attachments report their instances' placements (glTF instancing).
    pub placements: bool,
}

/// The targets a scene is drawn into.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TargetKind {
    /// The deferred renderer's G-buffer (colour, normal, linear depth).
    GBuffer,
    /// Depth only, into tiles of one texture (shadow maps): each draw recorded once per tile.
    DepthTiles,
}

/// How a draw is called.
pub enum DrawCall {
    /// `indices` of the index buffer, for each instance ([`KindDraw::instances`]).
    Indexed { indices: u32 },
    /// Arguments written on the GPU (one instance).
    IndexedIndirect(wgpu::Buffer),
    /// No vertex or index buffers: the shader reads its geometry from group 2.
    Vertices { vertices: u32 },
}

/// One draw, as a kind prepared it.
pub struct KindDraw {
    pub pipeline: wgpu::RenderPipeline,
    pub group2: Option<wgpu::BindGroup>,
    /// Vertex buffer 0 and the index buffer (u32); `None` with [`DrawCall::Vertices`].
    pub mesh: Option<(wgpu::Buffer, wgpu::Buffer)>,
    /// Vertex buffer 1: the kind's own instances, or `None` for the items' transforms
    /// ([`ItemVertex`], one per item of the draw).
    pub instances: Option<(wgpu::Buffer, u32)>,
    pub call: DrawCall,
}

/// A pipeline as a kind asks for it; the pass builds each once.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct PipelineKey {
    pub shader: &'static str,
    pub entry: &'static str,
    /// The fragment entry point; `None` for depth only.
    pub fragment: Option<&'static str>,
    /// Group 1 with the pass's cell texture (items under grids of several cells).
    pub cells: bool,
    /// Names the vertex buffer layouts and group 2 layout given with the key.
    pub inputs: &'static str,
    pub constants: Vec<(&'static str, u32)>,
    /// Faces culled: `None` (two-sided) for everything but closed surfaces drawn by their fronts.
    pub cull: Option<wgpu::Face>,
    /// What the draw's material needs of a G-buffer pipeline ([`MaterialFeatures`]).
    pub material: MaterialFeatures,
}

/// What every draw of a pass shares: the target and its bind group layouts. Kinds build their
/// pipelines through it.
pub struct PassCx<'a> {
    pub gpu: &'a GpuContext,
    pub target: TargetKind,
    pub(super) group0: &'a wgpu::BindGroupLayout,
    /// Group 3 of depth tiles: the tile index.
    pub(super) tile_index: Option<&'a wgpu::BindGroupLayout>,
    pub(super) object: &'a wgpu::BindGroupLayout,
    pub(super) object_cells: Option<&'a wgpu::BindGroupLayout>,
    pub(super) colors: &'a [wgpu::TextureFormat],
    pub(super) depth: wgpu::TextureFormat,
    pub(super) built: RefCell<HashMap<PipelineKey, wgpu::RenderPipeline>>,
}

impl PassCx<'_> {
    /// The pipeline of `key` (built on first use in the pass): group 0 the target's, group 1
    /// the objects (with cells where `key.cells`), group 2 `group2`, group 3 the tile index.
    pub fn pipeline(
        &self,
        key: PipelineKey,
        group2: Option<&wgpu::BindGroupLayout>,
        vertex: &[Option<wgpu::VertexBufferLayout<'_>>],
    ) -> anyhow::Result<wgpu::RenderPipeline> {
        if let Some(p) = self.built.borrow().get(&key) {
            return Ok(p.clone());
        }
        let object = match (key.cells, self.object_cells) {
            (true, Some(cells)) => cells,
            (true, None) => anyhow::bail!("{} needs the pass's cell texture, which it has not made", key.entry),
            (false, _) => self.object,
        };
        let groups = [Some(self.group0), Some(object), group2, self.tile_index];
        let used = if self.tile_index.is_some() {
            4
        } else if group2.is_some() {
            3
        } else {
            2
        };
        let mut constants = key.constants.clone();
        if self.target == TargetKind::GBuffer {
            let MaterialFeatures { maps, tangents } = key.material;
            constants.extend([("MAPS", u32::from(maps)), ("TANGENTS", u32::from(tangents))]);
        }
        let pipeline = self.gpu.render_pipeline(&RenderPipelineDesc {
            vertex_entry: key.entry,
            fragment_entry: key.fragment,
            depth: Some((self.depth, wgpu::CompareFunction::Less)),
            constants: &constants,
            cull: key.cull,
            ..RenderPipelineDesc::new(key.shader, &groups[..used], vertex, self.colors)
        })?;
        self.built.borrow_mut().insert(key, pipeline.clone());
        Ok(pipeline)
    }

    /// The pipeline that draws a mesh (vertex buffer of [`crate::mesh::Vertex`], the items'
    /// transforms as instances) through `stage` into this target: plain meshes, tessellations
    /// and every kind drawn as its mesh somewhere.
    pub fn mesh_pipeline(
        &self,
        stage: VertexStage,
        material: MaterialFeatures,
    ) -> anyhow::Result<wgpu::RenderPipeline> {
        self.mesh_pipeline_culled(stage, None, material)
    }

    /// [`PassCx::mesh_pipeline`] culling `cull` faces: for closed surfaces whose fronts face out.
    pub fn mesh_pipeline_culled(
        &self,
        stage: VertexStage,
        cull: Option<wgpu::Face>,
        material: MaterialFeatures,
    ) -> anyhow::Result<wgpu::RenderPipeline> {
        use crate::cuboid::NormalMethod::{Direct, TangentSpace};
        let (shader, entry, cells) = match (self.target, stage) {
            (TargetKind::GBuffer, VertexStage::Linear) => ("gbuffer.wgsl", "vs_main", false),
            (TargetKind::GBuffer, VertexStage::Grid(TangentSpace)) => ("cuboid_gbuffer.wgsl", "vs_tangent_space", true),
            (TargetKind::GBuffer, VertexStage::Grid(Direct)) => ("cuboid_gbuffer.wgsl", "vs_direct", true),
            (TargetKind::GBuffer, VertexStage::Cuboid(TangentSpace)) => {
                ("cuboid_gbuffer.wgsl", "vs_cuboid_tangent_space", false)
            }
            (TargetKind::GBuffer, VertexStage::Cuboid(Direct)) => ("cuboid_gbuffer.wgsl", "vs_cuboid_direct", false),
            (TargetKind::DepthTiles, VertexStage::Linear) => ("depth.wgsl", "vs_plain", false),
            // Depth only: no normals, one entry point for both methods.
            (TargetKind::DepthTiles, VertexStage::Grid(_)) => ("cuboid_depth.wgsl", "vs_main", true),
            (TargetKind::DepthTiles, VertexStage::Cuboid(_)) => ("cuboid_depth.wgsl", "vs_cuboid", false),
        };
        let cuboid = matches!(stage, VertexStage::Cuboid(_));
        let items = if cuboid { ItemVertex::cuboid_layout() } else { ItemVertex::layout() };
        let vertex = [Some(crate::mesh::Vertex::shading_layout()), Some(items)];
        // Depth tiles need no fragment stage: the scissor keeps each draw inside its tile.
        let fragment = (self.target == TargetKind::GBuffer).then_some("fs_main");
        let key = PipelineKey { shader, entry, fragment, cells, inputs: "mesh", constants: Vec::new(), cull, material };
        self.pipeline(key, None, &vertex)
    }
}

/// What a kind's `prepare` may use: the pass, and this draw's cached group 2 and the point
/// attachments' frame resolver.
pub struct PrepareCx<'a, 'p> {
    pub pass: &'a PassCx<'p>,
    /// This draw's group 2, cached between frames while its resources stay.
    pub group2: &'a mut Bindings,
    pub resolver: &'a mut InstanceResolver,
}

impl DrawItem {
    /// The item's kind as `K`, if it is one.
    pub fn kind_as<K: ItemKind>(&self) -> Option<&K> {
        (&*self.kind as &dyn Any).downcast_ref::<K>()
    }
}

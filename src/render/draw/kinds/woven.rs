//! Woven cloth at the panel, yarn or fibre scale (Zhang et al. 2012; `WovenCloth`, src/woven/):
//! one layer of the tessellation (panel quads, or the weft or warp tubes of one colour). On the
//! GPU path the compute pass of `src/woven/gpu.rs` wrote the layer's vertices and indices and
//! it is drawn with indirect arguments (the item's mesh is then the coarse panel, one quad per
//! patch, for bounds and framing); on the CPU path the item's mesh is the tessellation itself.
//! Either is exported as exactly the triangles drawn.

use std::sync::Arc;

use crate::render::draw::compose::VertexStage;
use crate::render::draw::kind::{
    DrawCall, ExportCx, ExportDevice, Exported, ItemKind, KindDraw, PrepareCx, TargetKind,
};
use crate::render::draw::kinds::mesh::{local_copy, mesh_draw_culled};
use crate::render::scene::DrawItem;
use crate::woven::gpu::GpuLayer;

/// A layer evaluated on the GPU and how to evaluate the same triangles on the CPU (for export
/// on a CPU adapter).
pub struct WovenGpu {
    pub layer: GpuLayer,
    pub cpu_reference: Box<dyn Fn() -> anyhow::Result<crate::mesh::Mesh> + Send + Sync>,
}

impl std::fmt::Debug for WovenGpu {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        self.layer.fmt(f)
    }
}

/// The layers' names, in the order the tessellation gives them.
pub const LAYER_NAMES: [&str; 3] = ["panel", "weft", "warp"];

/// The kind of a `WovenCloth` item: which layer it is, and how many patches each scale drew.
#[derive(Clone, Debug)]
pub struct WovenLayer {
    /// One of [`LAYER_NAMES`]: "panel", "weft" or "warp".
    pub layer: &'static str,
    /// Patches at the panel, yarn and fibre scales over the whole cloth.
    pub scales: [usize; 3],
    /// Patches outside the view, not drawn.
    pub culled: usize,
    /// The layer's buffers when the compute pass evaluated it.
    pub gpu: Option<Arc<WovenGpu>>,
}

impl WovenLayer {
    /// The item drawing layer `k` (of [`LAYER_NAMES`]) as the compute pass wrote it, with no CPU
    /// evaluation to export on a CPU adapter (benches, tests).
    pub fn gpu_item(
        k: usize,
        layer: GpuLayer,
        scales: [usize; 3],
        material: Arc<crate::render::scene::Material>,
    ) -> DrawItem {
        let gpu = WovenGpu { layer, cpu_reference: Box::new(|| anyhow::bail!("no CPU evaluation kept")) };
        DrawItem::plain(Arc::new(crate::mesh::Mesh::default()), material, glam::Mat4::IDENTITY).with_kind(WovenLayer {
            layer: LAYER_NAMES[k],
            scales,
            culled: 0,
            gpu: Some(Arc::new(gpu)),
        })
    }

    /// The faces left out of `item`'s draw: the tubes' hidden halves in the G-buffer. Every tube
    /// (ribbons too, whose two sides are two triangles each) is closed but at the cloth's border
    /// and wound with its fronts outwards; where a tube folds on itself the reversed triangles
    /// lie inside it. The panel layer is a sheet, seen from both sides; a mirroring transform
    /// turns the fronts inwards (cull the other side), and a cuboid deformation can turn some
    /// cells over (cull nothing).
    pub fn culled_faces(&self, target: TargetKind, item: &DrawItem, stage: VertexStage) -> Option<wgpu::Face> {
        let tubes = self.layer == LAYER_NAMES[1] || self.layer == LAYER_NAMES[2];
        if !tubes || target != TargetKind::GBuffer || stage != VertexStage::Linear {
            return None;
        }
        Some(if item.model.determinant() < 0.0 { wgpu::Face::Front } else { wgpu::Face::Back })
    }
}

impl ItemKind for WovenLayer {
    fn name(&self) -> &'static str {
        "woven"
    }

    fn leaves_mesh_bounds(&self) -> bool {
        self.gpu.is_some()
    }

    fn drawn_triangles(&self, item: &DrawItem) -> usize {
        match &self.gpu {
            Some(g) => (g.layer.index_count / 3) as usize,
            None => item.mesh.triangle_count(),
        }
    }

    fn prepare(
        &self,
        cx: &mut PrepareCx<'_, '_>,
        item: &DrawItem,
        stage: VertexStage,
    ) -> anyhow::Result<Option<KindDraw>> {
        if let Some(g) = &self.gpu {
            if g.layer.index_count == 0 {
                return Ok(None);
            }
            // Written by the compute pass this frame; the counts are the plan's.
            return Ok(Some(KindDraw {
                pipeline: cx.pass.mesh_pipeline_culled(
                    stage,
                    self.culled_faces(cx.pass.target, item, stage),
                    item.material.features(),
                )?,
                group2: None,
                mesh: Some(((*g.layer.vertices).clone(), (*g.layer.indices).clone())),
                instances: None,
                call: DrawCall::IndexedIndirect((*g.layer.indirect).clone()),
            }));
        }
        if item.mesh.indices.is_empty() {
            return Ok(None);
        }
        mesh_draw_culled(cx, &item.mesh, &item.material, stage, self.culled_faces(cx.pass.target, item, stage))
            .map(Some)
    }

    fn export(&self, cx: &mut ExportCx<'_>, item: &DrawItem) -> anyhow::Result<Exported> {
        let m = match (&self.gpu, cx.device) {
            (Some(g), ExportDevice::Gpu) => g.layer.read_back_mesh(cx.gpu)?,
            (Some(g), ExportDevice::Cpu) => (g.cpu_reference)()?,
            (None, _) => local_copy(&item.mesh),
        };
        Ok(Exported::Local(m))
    }
}

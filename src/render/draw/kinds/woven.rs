//! Woven cloth at the panel, yarn or fibre scale (Zhang et al. 2012; `WovenCloth`, src/woven/):
//! the item's mesh is the tessellation the CPU evaluated this frame (panel quads, or the weft or
//! warp tubes of one colour), drawn through the plain-mesh vertex stages like any mesh, and
//! exported as exactly those triangles.

use crate::render::draw::compose::VertexStage;
use crate::render::draw::kind::{ExportCx, Exported, ItemKind, KindDraw, PrepareCx};
use crate::render::draw::kinds::mesh::mesh_draw;
use crate::render::scene::DrawItem;

/// The kind of a `WovenCloth` item: which layer it is, and how many patches each scale drew.
#[derive(Clone, Debug)]
pub struct WovenLayer {
    /// "panel", "weft" or "warp".
    pub layer: &'static str,
    /// Patches at the panel, yarn and fibre scales over the whole cloth.
    pub scales: [usize; 3],
}

impl ItemKind for WovenLayer {
    fn name(&self) -> &'static str {
        "woven"
    }

    fn prepare(
        &self,
        cx: &mut PrepareCx<'_, '_>,
        item: &DrawItem,
        stage: VertexStage,
    ) -> anyhow::Result<Option<KindDraw>> {
        if item.mesh.indices.is_empty() {
            return Ok(None);
        }
        mesh_draw(cx, &item.mesh, stage).map(Some)
    }

    fn export(&self, _: &mut ExportCx<'_>, item: &DrawItem) -> anyhow::Result<Exported> {
        let m = &item.mesh;
        Ok(Exported::Local(crate::mesh::Mesh::from_raw(
            m.positions.clone(),
            m.normals.clone(),
            m.uvs.clone(),
            Vec::new(),
            Vec::new(),
            m.indices.clone(),
        )))
    }
}

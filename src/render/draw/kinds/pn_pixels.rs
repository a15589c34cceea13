//! Per-pixel PN depth (dissertation 4.1.3): the G-buffer evaluates the PN patch of each
//! triangle per fragment (shaders/tessellation/gbuffer_pn.wgsl), reading the triangle's corners from the
//! mesh's storage buffers; other targets, and items under a non-linear grid, draw the mesh as
//! it is.

use crate::gpu::Bind;
use crate::render::draw::compose::VertexStage;
use crate::render::draw::kind::{DrawCall, ExportCx, Exported, ItemKind, KindDraw, PipelineKey, PrepareCx, TargetKind};
use crate::render::draw::kinds::mesh::mesh_draw;
use crate::render::scene::DrawItem;

/// The kind of an item drawn with per-pixel PN depth (`Tessellate` with `per_pixel`).
pub struct PnPixels;

impl ItemKind for PnPixels {
    fn name(&self) -> &'static str {
        "per-pixel PN"
    }

    fn object_model(&self) -> bool {
        true
    }

    fn prepare(
        &self,
        cx: &mut PrepareCx<'_, '_>,
        item: &DrawItem,
        stage: VertexStage,
    ) -> anyhow::Result<Option<KindDraw>> {
        if cx.pass.target != TargetKind::GBuffer || stage != VertexStage::Linear {
            return mesh_draw(cx, &item.mesh, &item.material, stage).map(Some);
        }
        let gpu = cx.pass.gpu;
        let mesh = item.mesh.gpu(gpu);
        let binds = [Bind::Storage(&mesh.vertices), Bind::Storage(&mesh.indices)];
        let layout = cx.group2.layout(gpu, &binds);
        let group = cx.group2.bind_group(gpu, &layout, &binds);
        let key = PipelineKey {
            shader: "gbuffer_pn.wgsl",
            entry: "vs_main",
            fragment: Some("fs_main"),
            cells: false,
            inputs: "pn mesh",
            constants: Vec::new(),
            cull: None,
            material: item.material.features(),
        };
        Ok(Some(KindDraw {
            pipeline: cx.pass.pipeline(key, Some(&layout), &[])?,
            group2: Some(group),
            mesh: None,
            instances: None,
            call: DrawCall::Vertices { vertices: mesh.index_count },
        }))
    }

    fn export(&self, _: &mut ExportCx<'_>, _: &DrawItem) -> anyhow::Result<Exported> {
        anyhow::bail!(
            "an item drawn with per-pixel PN depth has no mesh to export (its surface exists per pixel only); \
             export a `Tessellate` node with `per_pixel` off and `pn` on for the PN surface as triangles"
        )
    }
}

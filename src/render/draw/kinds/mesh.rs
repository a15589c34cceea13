//! A plain mesh: its own vertex and index buffers, placed by each item's transform (model
//! matrix, grid or single cuboid). Items that share a mesh and maps draw as one instanced draw.

use crate::mesh::Mesh;
use crate::render::draw::compose::VertexStage;
use crate::render::draw::kind::{DrawCall, ExportCx, Exported, ItemKind, KindDraw, PrepareCx};
use crate::render::scene::{DrawItem, Material};

/// The kind of [`DrawItem::plain`].
pub struct PlainMesh;

impl ItemKind for PlainMesh {
    fn name(&self) -> &'static str {
        "mesh"
    }

    fn instanced(&self) -> bool {
        true
    }

    fn prepare(
        &self,
        cx: &mut PrepareCx<'_, '_>,
        item: &DrawItem,
        stage: VertexStage,
    ) -> anyhow::Result<Option<KindDraw>> {
        mesh_draw(cx, &item.mesh, &item.material, stage).map(Some)
    }

    fn export(&self, _: &mut ExportCx<'_>, item: &DrawItem) -> anyhow::Result<Exported> {
        Ok(Exported::Local(local_copy(&item.mesh)))
    }
}

/// `mesh` drawn through `stage` in the draw's `material`, one instance per item of the draw.
pub fn mesh_draw(
    cx: &mut PrepareCx<'_, '_>,
    mesh: &Mesh,
    material: &Material,
    stage: VertexStage,
) -> anyhow::Result<KindDraw> {
    mesh_draw_culled(cx, mesh, material, stage, None)
}

/// [`mesh_draw`] culling `cull` faces (closed surfaces wound with their fronts outwards).
pub fn mesh_draw_culled(
    cx: &mut PrepareCx<'_, '_>,
    mesh: &Mesh,
    material: &Material,
    stage: VertexStage,
    cull: Option<wgpu::Face>,
) -> anyhow::Result<KindDraw> {
    let gpu_mesh = mesh.gpu(cx.pass.gpu);
    Ok(KindDraw {
        pipeline: cx.pass.mesh_pipeline_culled(stage, cull, material.features())?,
        group2: None,
        mesh: Some(((*gpu_mesh.vertices).clone(), (*gpu_mesh.indices).clone())),
        instances: None,
        call: DrawCall::Indexed { indices: gpu_mesh.index_count },
    })
}

/// What a drawn mesh exports: positions, normals, UVs and triangles (tangents are derived data).
pub(crate) fn local_copy(mesh: &Mesh) -> Mesh {
    Mesh::from_raw(
        mesh.positions.clone(),
        mesh.normals.clone(),
        mesh.uvs.clone(),
        Vec::new(),
        Vec::new(),
        mesh.indices.clone(),
    )
}

//! Deferred-warped detail geometry (Knuth et al., "Deferred Warping"): instances of a detail
//! mesh warped through the matrix texture in the vertex stage (shaders/warp/attach.wgsl, or
//! shaders/render/depth.wgsl `vs_attached`), and exported through the same warp run as a compute pass
//! or its CPU twin.

use crate::mesh::Vertex;
use crate::render::draw::compose::VertexStage;
use crate::render::draw::kind::{
    DrawCall, ExportCx, ExportDevice, Exported, ItemKind, KindDraw, PipelineKey, PrepareCx, TargetKind,
};
use crate::render::scene::DrawItem;
use crate::warp::gpu::{WarpDevice, assemble, read_matrix, warp_binds, warp_layout};
use crate::warp::{AttachedDraw, InstanceData};

impl ItemKind for AttachedDraw {
    fn name(&self) -> &'static str {
        "attached"
    }

    fn places_mesh(&self) -> bool {
        false
    }

    fn drawn_triangles(&self, item: &DrawItem) -> usize {
        self.instances.len() * item.mesh.triangle_count()
    }

    fn prepare(
        &self,
        cx: &mut PrepareCx<'_, '_>,
        item: &DrawItem,
        stage: VertexStage,
    ) -> anyhow::Result<Option<KindDraw>> {
        anyhow::ensure!(
            stage == VertexStage::Linear,
            "attachments follow their surface through the matrix texture and cannot be drawn under a non-linear grid"
        );
        if self.instances.is_empty() {
            return Ok(None);
        }
        let gpu = cx.pass.gpu;
        let resolver = &mut *cx.resolver;
        let instances = self.draw_buffer(gpu, |raw| resolver.resolve(gpu, raw, self))?.clone();
        let layout = warp_layout(gpu, wgpu::ShaderStages::VERTEX);
        let uniform = self.settings.uniform();
        let group = cx.group2.bind_group(gpu, &layout, &warp_binds(&self.matrix, &uniform));
        // Depth: a fragment stage only to drop the primitives of outlier instances.
        let (shader, entry, fragment) = match cx.pass.target {
            TargetKind::GBuffer => ("attach.wgsl", "vs_main", "fs_main"),
            TargetKind::DepthTiles => ("depth.wgsl", "vs_attached", "fs_attached"),
        };
        // The variant without seams compiles the partner reads out (`SEAMS` in shaders/warp/warp.wgsl).
        let mut constants = vec![("SEAMS", u32::from(self.matrix.has_seams()))];
        constants.extend(self.settings.constants(self.per_instance_frames()));
        let material = item.material.features();
        let key = PipelineKey {
            shader,
            entry,
            fragment: Some(fragment),
            cells: false,
            inputs: "attached",
            constants,
            cull: None,
            material,
        };
        let vertex = [Some(Vertex::layout()), Some(InstanceData::layout())];
        let mesh = item.mesh.gpu(gpu);
        Ok(Some(KindDraw {
            pipeline: cx.pass.pipeline(key, Some(&layout), &vertex)?,
            group2: Some(group),
            mesh: Some(((*mesh.vertices).clone(), (*mesh.indices).clone())),
            instances: Some((instances, self.instances.len() as u32)),
            call: DrawCall::Indexed { indices: mesh.index_count },
        }))
    }

    fn export(&self, cx: &mut ExportCx<'_>, item: &DrawItem) -> anyhow::Result<Exported> {
        let device = match cx.device {
            ExportDevice::Gpu => WarpDevice::Gpu,
            ExportDevice::Cpu => WarpDevice::Cpu,
        };
        let warped = cx.warper.warp_layout_on(cx.gpu, &item.mesh, self, device)?;
        let placements = match cx.placements {
            true => crate::warp::rigid_placements(&read_matrix(cx.gpu, &self.matrix)?, &self.settings, &self.instances),
            false => None,
        };
        let mesh = assemble(&item.mesh, warped)?;
        Ok(Exported::Instances { mesh, per_instance: item.mesh.positions.len(), placements })
    }
}

/// Attachments whose matrix texture was rendered with another transform than the item that
/// draws its surface: they would float away from it. The message says which transforms and
/// how to give the surface one.
pub fn surface_transform_mismatch(items: &[DrawItem]) -> Option<String> {
    use crate::render::scene::{describe_transform, same_transform};
    items.iter().filter_map(|i| i.kind_as::<AttachedDraw>()).find_map(|attached| {
        let (surface, placed) = attached.matrix.placed_on.as_ref()?;
        let drawn: Vec<_> = items.iter().filter(|i| i.draws(surface)).map(|i| i.model).collect();
        let first = *drawn.first()?;
        (!drawn.iter().any(|m| same_transform(*m, *placed))).then(|| {
            format!(
                "attachments sit on a surface whose MatrixTexture has {} while the item that draws it has {}: \
                 the attachments would leave the surface; link the Draw's scene into the MatrixTexture's \
                 `drawn` input (it then takes the Draw's transform) and clear its translate, rotate and scale",
                describe_transform(*placed),
                describe_transform(first)
            )
        })
    })
}

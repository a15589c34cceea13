//! A tessellation that lives on the GPU (the `Tessellate` node, dissertation 4.1): vertex and
//! index buffers written by the compute pass, drawn with indirect arguments through the same
//! vertex stages as plain meshes, and exported by reading them back or by the CPU reference.

use crate::gpu::readback::read_buffer_range;
use crate::gpu::{GpuContext, read_buffer};
use crate::mesh::{Mesh, Vertex};
use crate::render::draw::compose::VertexStage;
use crate::render::draw::kind::{DrawCall, ExportCx, ExportDevice, Exported, ItemKind, KindDraw, PrepareCx};
use crate::render::scene::DrawItem;
use crate::tessellation::{TessMesh, cpu_vertex_levels, tessellate, welded_mesh};

impl ItemKind for TessMesh {
    fn name(&self) -> &'static str {
        "tessellated"
    }

    fn leaves_mesh_bounds(&self) -> bool {
        true
    }

    fn prepare(
        &self,
        cx: &mut PrepareCx<'_, '_>,
        item: &DrawItem,
        stage: VertexStage,
    ) -> anyhow::Result<Option<KindDraw>> {
        // Written by the compute pass this frame: counts never come back to the CPU.
        Ok(Some(KindDraw {
            pipeline: cx.pass.mesh_pipeline(stage, item.material.features())?,
            group2: None,
            mesh: Some(((*self.vertices).clone(), (*self.indices).clone())),
            instances: None,
            call: DrawCall::IndexedIndirect((*self.indirect).clone()),
        }))
    }

    fn export(&self, cx: &mut ExportCx<'_>, item: &DrawItem) -> anyhow::Result<Exported> {
        let (vertices, indices) = match cx.device {
            ExportDevice::Gpu => self.read_back(cx.gpu)?,
            ExportDevice::Cpu => self.cpu_reference(&item.mesh),
        };
        Ok(Exported::Local(welded_mesh(&vertices, &indices)?))
    }
}

impl TessMesh {
    /// The triangles the compute pass wrote (as drawn: vertices not shared between patches).
    pub fn read_back(&self, gpu: &GpuContext) -> anyhow::Result<(Vec<Vertex>, Vec<u32>)> {
        // DrawIndexedIndirectArgs: index count, instance count, first index, base vertex, first instance.
        let args: Vec<u32> = read_buffer(gpu, &self.indirect)?;
        let count = args[0] as u64;
        anyhow::ensure!(
            count <= self.index_capacity && args[2] == 0 && args[3] == 0,
            "the tessellation's draw arguments {args:?} do not fit its {} indices",
            self.index_capacity
        );
        if count == 0 {
            return Ok((Vec::new(), Vec::new()));
        }
        let indices: Vec<u32> = read_buffer_range(gpu, &self.indices, count * 4)?;
        let used = indices.iter().max().map_or(0, |&m| u64::from(m) + 1);
        anyhow::ensure!(used <= self.vertex_capacity, "the tessellation's indices reach past its vertices");
        let vertices = read_buffer_range(gpu, &self.vertices, used * std::mem::size_of::<Vertex>() as u64)?;
        Ok((vertices, indices))
    }

    /// The same triangles from the CPU reference of the compute pass (levels from the view it
    /// was made with, or the levels given).
    pub fn cpu_reference(&self, coarse: &Mesh) -> (Vec<Vertex>, Vec<u32>) {
        let levels = match &self.given_levels {
            Some(l) => l.clone(),
            None => cpu_vertex_levels(coarse, &self.view),
        };
        tessellate(coarse, &levels, &self.settings)
    }
}

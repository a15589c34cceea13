//! Exports warped detail geometry (and plain meshes) as OBJ, PLY or binary glTF, computed by the same
//! warp code as rendering (shaders/warp/warp.wgsl, run as a compute pass): "the geometry can be
//! post-processed or even exported without rendering output" (paper section 6).

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::io::geometry::{GeometryFormat, GeometryPart};
use crate::mesh::Mesh;
use crate::render::draw::kind::{ExportCx, ExportDevice};
use crate::render::scene::DrawItem;
use crate::warp::gpu::{GpuWarper, WarpDevice};

pub static EXPORT_GEOMETRY: NodeSpec = NodeSpec {
    kind: "ExportGeometry",
    category: Category::Output,
    doc: "Writes a scene's geometry as it renders (attachments warped, tessellations refined, items under cuboid grids deformed by eq. 3.4) as <out>/<node id>_<frame>.obj, .ply or .glb, or the whole rendered frame range as one USD ASCII cache <out>/<node id>.usda (points and normals time-sampled per frame, one mesh). OBJ and glb keep the scene apart: an object (OBJ `o`, glTF node) per item and per attachment instance, named by the node that made the item and the instance index (`buttons_17`), counted in the header; glb adds a material per item (base colour, glossiness as roughness). Outlier vertices' triangles are left out, as rendering discards them. A kind of item that cannot be exported (per-pixel PN depth) is an error.",
    inputs: &[PortSpec::required("scene", PortType::Scene, "What to export.")],
    outputs: &[PortSpec::output("mesh", PortType::Mesh, "The exported geometry as one mesh.")],
    params: &[
        ParamSpec::new(
            "format",
            ParamKind::Choice { default: "obj", options: GeometryFormat::OPTIONS },
            "File format (PLY is binary little-endian; GLB is binary glTF 2.0 with materials; USDA is one animated cache of the frame range).",
        ),
        ParamSpec::new(
            "attachments",
            ParamKind::Choice { default: "realized", options: Attachments::OPTIONS },
            "How .glb writes attachments: realized (a node per instance with its own vertices) or instanced (the detail mesh once, its instances' translations, rotations and scales as EXT_mesh_gpu_instancing; for point attachments without fur gravity, whose instances are rigid copies; other attachments stay realized). Other formats always realize.",
        ),
        ParamSpec::new(
            "warp",
            ParamKind::Choice { default: "auto", options: WarpDevice::OPTIONS },
            "Where the exported geometry is computed: on the GPU (attachments by the warp's compute pass, tessellations read back), or by the CPU twins of the same shaders (the same geometry); auto takes the CPU on a CPU adapter such as lavapipe, where it is faster (werkstatt bench export).",
        ),
        ParamSpec::new(
            "frame",
            ParamKind::Int { default: -1, min: -1, max: i64::MAX },
            "Only export at this frame (-1: every frame).",
        ),
    ],
    capabilities: Capabilities::OUTPUT,
    create: || Box::new(ExportNode::default()),
};

crate::choice!(
    /// How a .glb holds attachment instances.
    enum Attachments {
        Realized = "realized",
        Instanced = "instanced",
    }
);

#[derive(Default)]
struct ExportNode {
    warper: GpuWarper,
    /// The last export and its material parts, the `mesh` output on frames a fixed-frame
    /// export skips.
    last: Option<(Arc<Mesh>, Arc<[GeometryPart]>)>,
}

impl Node for ExportNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let items: Arc<Vec<DrawItem>> = cx.input("scene")?;
        let wanted = cx.int("frame");
        // Only a chosen frame makes the node read the time (and re-run every frame).
        let export = wanted < 0 || cx.time().frame == wanted;
        // A fixed-frame export skips the warp on other frames (the batch runner warns when
        // its frame is outside the rendered range); `mesh` is then the last export, or the
        // scene of this frame before the first one.
        let (mesh, parts) = match &self.last {
            Some(last) if !export => last.clone(),
            _ => {
                let device = match WarpDevice::resolve(cx.choice("warp"), gpu) {
                    WarpDevice::Cpu => ExportDevice::Cpu,
                    _ => ExportDevice::Gpu,
                };
                let placements = cx.choice::<Attachments>("attachments") == Attachments::Instanced;
                let mut export = ExportCx { gpu, device, warper: &mut self.warper, placements };
                let (mesh, parts) = crate::render::draw::export::flatten_parts(&mut export, &items)?;
                (Arc::new(mesh), parts.into())
            }
        };
        if export {
            cx.count("triangles", mesh.triangle_count());
            cx.emit(Product::Geometry { mesh: mesh.clone(), parts: parts.clone(), format: cx.choice("format") });
            self.last = Some((mesh.clone(), parts));
        }
        cx.set("mesh", mesh);
        Ok(())
    }
}

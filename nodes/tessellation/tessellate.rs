//! `Tessellate`: adaptive refinement of a mesh in compute (dissertation 3.1.3, 4.1.3, 5.1.3;
//! src/tessellation/mod.rs and shaders/tessellation/tessellate.wgsl). The output stays on the GPU and is drawn
//! with indirect arguments by every pass that draws a scene (G-buffer, shadow atlas).

use std::sync::Arc;

use glam::{Mat4, Vec3};

use crate::core::node::prelude::*;
use crate::mesh::Mesh;
use crate::render::scene::{Camera, DrawItem, Material, View};
use crate::tessellation::{GpuTessellator, Lod, Metric, Mode, Settings, ViewLod};

pub static TESSELLATE: NodeSpec = NodeSpec {
    kind: "Tessellate",
    category: Category::Geometry,
    doc: "Refines a mesh adaptively on the GPU (compute; no read-back): per-vertex levels from camera distance and silhouette or from screen edge length, crack-free edge levels, the dissertation's pattern with barycentric warping (or uniform / dyadic for comparison), PN-triangle smoothing. Outputs a scene item drawn with indirect arguments.",
    inputs: &[
        PortSpec::required("mesh", PortType::Mesh, "The coarse mesh or surface."),
        PortSpec::required("camera", PortType::Camera, "The view the levels are chosen for."),
        PortSpec::optional("material", PortType::Material, "Its material (default: light grey)."),
    ],
    outputs: &[
        PortSpec::output("scene", PortType::Scene, "One draw item: the refined mesh, GPU-resident."),
        PortSpec::output(
            "wireframe",
            PortType::Mesh,
            "The refined mesh's edges as thin ribbons, from the CPU reference (for figures; empty unless linked).",
        ),
        PortSpec::output(
            "mesh",
            PortType::Mesh,
            "The refined mesh from the CPU reference, welded (for attachments' detail meshes, refined once and then warped like any mesh; empty unless linked).",
        ),
    ],
    params: &[
        ParamSpec::new(
            "mode",
            ParamKind::Choice { default: "pattern_warp", options: Mode::OPTIONS },
            "uniform: every edge at max_level; dyadic: semi-uniform with snapping [DRS09]; pattern: section 3.1.3; pattern_warp: with barycentric warping (Fig. 5.11).",
        ),
        ParamSpec::new(
            "metric",
            ParamKind::Choice { default: "distance", options: Metric::OPTIONS },
            "distance: log falloff between near and far, raised at silhouettes; edge_length: longest screen edge / max_edge_px (Fig. 5.15).",
        ),
        ParamSpec::new(
            "max_level",
            ParamKind::Int { default: 8, min: 1, max: 64 },
            "The highest edge level (segments per edge); uniform mode's level.",
        ),
        ParamSpec::new(
            "near",
            ParamKind::Float { default: 1.0, min: 1e-4, max: 1e5 },
            "Distance at which vertices get max_level.",
        ),
        ParamSpec::new(
            "far",
            ParamKind::Float { default: 20.0, min: 1e-4, max: 1e5 },
            "Distance at which vertices get level 1.",
        ),
        ParamSpec::new(
            "silhouette",
            ParamKind::Float { default: 1.0, min: 0.0, max: 16.0 },
            "Level gain at grazing angles: level x (1 + silhouette (1 - |view . normal|)).",
        ),
        ParamSpec::new(
            "max_edge_px",
            ParamKind::Float { default: 16.0, min: 0.5, max: 4096.0 },
            "edge_length metric: the screen length an edge should not exceed, in pixels.",
        ),
        ParamSpec::new("pn", ParamKind::Bool { default: true }, "Smooth with PN triangles [VPBM01] (else flat)."),
        ParamSpec::new(
            "per_pixel",
            ParamKind::Bool { default: false },
            "Per-pixel PN depth (sections 4.1.3/5.1.3): no refinement; the G-buffer evaluates each triangle's PN patch per fragment, so SSAO sees smooth depth on coarse cloth. Shadow tiles draw the coarse mesh.",
        ),
        ParamSpec::new(
            "fixed_levels",
            ParamKind::Vec3 { default: [0.0, 0.0, 0.0] },
            "If any is positive: vertex i gets level fixed_levels[i mod 3] instead of the metric (figures of one triangle, Figs. 3.7-3.11).",
        ),
        ParamSpec::new(
            "wire_width",
            ParamKind::Float { default: 0.005, min: 1e-5, max: 1.0 },
            "Width of the wireframe output's ribbons, in scene units.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(TessellateNode::default()),
};

#[derive(Default)]
struct TessellateNode {
    gpu: GpuTessellator,
}

impl Node for TessellateNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let mesh: Arc<Mesh> = cx.input("mesh")?;
        let camera: Camera = cx.input("camera")?;
        let material = cx.optional("material").unwrap_or_else(|| Arc::new(Material::default()));
        let (near, far) = (cx.f32("near"), cx.f32("far"));
        if far <= near {
            return Err(NodeError::msg(format!("far ({far}) must be greater than near ({near})")));
        }
        let max_level = cx.int("max_level") as u32;
        let settings = Settings { mode: cx.choice("mode"), max_level, pn: cx.bool("pn") };
        let (w, h) = cx.frame_size();
        let view = View::new(&camera, w, h);
        let lod = ViewLod {
            view_proj: view.view_proj,
            eye: camera.eye,
            width: view.width as f32,
            height: view.height as f32,
            lod: Lod { near, far, max_level: max_level as f32, silhouette: cx.f32("silhouette") },
            metric: cx.choice("metric"),
            max_edge_px: cx.f32("max_edge_px"),
        };
        let plain = DrawItem::plain(mesh.clone(), material, Mat4::IDENTITY).named(cx.node_id);
        if cx.bool("per_pixel") {
            let item = plain.with_kind(crate::render::draw::kinds::pn_pixels::PnPixels);
            cx.count("patches", mesh.triangle_count());
            cx.set("scene", Arc::new(vec![item]));
            cx.set("wireframe", Arc::new(Mesh::default()));
            cx.set("mesh", Arc::new(Mesh::default()));
            return Ok(());
        }
        let fixed = cx.vec3("fixed_levels");
        let fixed_levels: Option<Vec<f32>> = (fixed.max_element() > 0.0).then(|| {
            let f = fixed.max(Vec3::ONE).to_array();
            (0..mesh.positions.len()).map(|i| f[i % 3]).collect()
        });
        let tess = self.gpu.run(gpu, &mesh, fixed_levels.as_deref(), &lod, &settings)?;
        cx.count("patches", mesh.triangle_count());
        cx.count("max_triangles", (tess.index_capacity / 3) as usize);
        let item = plain.with_kind(tess);
        cx.set("scene", Arc::new(vec![item]));
        let (wire, refined) = (cx.output_linked("wireframe"), cx.output_linked("mesh"));
        let cpu = (wire || refined).then(|| {
            let levels = match &fixed_levels {
                Some(l) => l.clone(),
                None => crate::tessellation::cpu_vertex_levels(&mesh, &lod),
            };
            crate::tessellation::tessellate(&mesh, &levels, &settings)
        });
        // Outputs nobody reads stay empty rather than cost a CPU tessellation per run.
        let empty = || Arc::new(Mesh::default());
        match (&cpu, wire) {
            (Some((v, i)), true) => {
                cx.set("wireframe", Arc::new(crate::tessellation::wireframe(v, i, cx.f32("wire_width"))?))
            }
            _ => cx.set("wireframe", empty()),
        }
        match (&cpu, refined) {
            (Some((v, i)), true) => cx.set("mesh", Arc::new(crate::tessellation::welded_mesh(v, i)?)),
            _ => cx.set("mesh", empty()),
        }
        Ok(())
    }
}

//! The G-buffer pass of the deferred renderer (dissertation section 4.2): plain meshes and
//! deferred-warped detail geometry (instanced through the matrix texture) into the same
//! targets, drawn by the engine's scene drawer (`src/render/draw/`).

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::render::draw::SceneDrawer;
use crate::render::scene::{Camera, DrawItem, View};

pub static GBUFFER_PASS: NodeSpec = NodeSpec {
    kind: "GBufferPass",
    category: Category::Render,
    doc: "Rasterizes a scene into the G-buffer: colour + glossiness, normal + coarse/detail flag, linear depth, and the surface (UV, the tangent frame of the UVs from screen-space derivatives, the material's btf_id) for BtfShading (the tangent frame only for materials with a btf_id). Attached (deferred-warped) items are drawn instanced through their matrix texture.",
    inputs: &[
        PortSpec::required("scene", PortType::Scene, "What to draw."),
        PortSpec::required("camera", PortType::Camera, "The view."),
    ],
    outputs: &[
        PortSpec::output("gbuffer", PortType::GBuffer, "All targets, for lighting passes."),
        PortSpec::output("color", PortType::Texture, "Linear base colour (rgb) and glossiness (a)."),
        PortSpec::output("normal", PortType::Texture, "World normal (rgb) and detail flag (a)."),
        PortSpec::output("depth", PortType::Texture, "Linear view depth; 0 where empty."),
    ],
    params: &[] as &[ParamSpec],
    capabilities: Capabilities::NONE,
    create: || Box::new(GBufferPassNode::default()),
};

#[derive(Default)]
pub struct GBufferPassNode {
    drawer: SceneDrawer,
}

impl Node for GBufferPassNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let items: Arc<Vec<DrawItem>> = cx.input("scene")?;
        let camera: Camera = cx.input("camera")?;
        let (w, h) = cx.frame_size();
        let view = View::new(&camera, w, h);
        let gbuffer = Arc::new(self.drawer.gbuffer(gpu, &items, camera, view)?);
        // The per-channel ports are further handles to the same textures.
        cx.set("color", Arc::new(gbuffer.color.share()));
        cx.set("normal", Arc::new(gbuffer.normal.share()));
        cx.set("depth", Arc::new(gbuffer.depth.share()));
        cx.set("gbuffer", gbuffer);
        Ok(())
    }
}

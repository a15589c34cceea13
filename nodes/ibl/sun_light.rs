//! `SunLight`: one directional light as `Lights`, so that a sun can have its cast shadows drawn
//! by a `ShadowAtlas` (one tile) and be shaded through them (BtfShading's `lights`).

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::ibl::gpu::Lights;
use crate::ibl::median_cut::RegionLight;

pub static SUN_LIGHT: NodeSpec = NodeSpec {
    kind: "SunLight",
    category: Category::Lighting,
    doc: "One directional light (a sun) as a list of lights: for a ShadowAtlas, whose tile then holds its cast shadows, and for BtfShading's `lights` with that atlas as `shadows`. Its colour is the irradiance on a surface facing it; its solid angle (a disc of `angular_diameter`) sets the atlas's penumbra blur. It carries no regions, so Pems refuses it.",
    inputs: &[],
    outputs: &[PortSpec::output("lights", PortType::Lights, "The sun, one light.")],
    params: &[
        ParamSpec::new("direction", ParamKind::Vec3 { default: [-0.4, -1.0, -0.6] }, "Direction the light travels."),
        ParamSpec::new("color", ParamKind::Color { default: [1.0, 0.96, 0.9] }, "Colour."),
        ParamSpec::new(
            "intensity",
            ParamKind::Float { default: 3.0, min: 0.0, max: 1e5 },
            "Irradiance on a surface facing the light.",
        ),
        ParamSpec::new(
            "angular_diameter",
            ParamKind::Float { default: 0.53, min: 0.0, max: 90.0 },
            "Degrees across the sun's disc (the sun's 0.53): its solid angle sets the atlas's penumbra blur.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(SunLightNode),
};

struct SunLightNode;

impl Node for SunLightNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let towards = -cx
            .vec3("direction")
            .try_normalize()
            .ok_or_else(|| NodeError::msg("parameter \"direction\" must not be zero"))?;
        let color = cx.vec3("color") * cx.f32("intensity");
        let radius = (cx.f32("angular_diameter") / 2.0).to_radians();
        let light = RegionLight {
            direction: towards,
            color,
            solid_angle: std::f32::consts::TAU * (1.0 - radius.cos()),
            energy: crate::color::luminance(color),
            texels: 1,
        };
        cx.set("lights", Arc::new(Lights { lights: vec![light], regions: None, preview: None }));
        Ok(())
    }
}

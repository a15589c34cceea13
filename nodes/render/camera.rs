//! Cameras.

use glam::Vec3;

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::render::scene::{Camera, DrawItem};

/// World bounds of a scene's plain items (model matrix applied to their box corners);
/// attached detail lies on a surface that is itself drawn, so it is left out. None when empty.
pub fn scene_bounds(items: &[DrawItem]) -> Option<(Vec3, Vec3)> {
    crate::render::scene::scene_box(items.iter().filter(|i| i.kind.places_mesh()))
}

pub static ORBIT_CAMERA: NodeSpec = NodeSpec {
    kind: "OrbitCamera",
    category: Category::Scene,
    doc: "A perspective camera orbiting a target; with orbit_speed it turns around the object over the frames.",
    inputs: &[PortSpec::optional(
        "fit",
        PortType::Scene,
        "When linked, the camera frames this scene: it looks at the centre of its bounds, from the distance at which their bounding sphere fills the view (target and distance are ignored; yaw, pitch and the turntable apply). Attachments count by the surface they sit on.",
    )],
    outputs: &[PortSpec::output("camera", PortType::Camera, "The camera.")],
    params: &[
        ParamSpec::new("target", ParamKind::Vec3 { default: [0.0, 0.0, 0.0] }, "The point looked at."),
        ParamSpec::new("distance", ParamKind::Float { default: 3.0, min: 1e-3, max: 1e5 }, "Distance from the target."),
        ParamSpec::new(
            "yaw",
            ParamKind::Float { default: 30.0, min: -3600.0, max: 3600.0 },
            "Angle around +Y in degrees (0 looks along -Z).",
        ),
        ParamSpec::new("pitch", ParamKind::Float { default: 20.0, min: -89.0, max: 89.0 }, "Elevation in degrees."),
        ParamSpec::new(
            "fov",
            ParamKind::Float { default: 40.0, min: 1.0, max: 170.0 },
            "Vertical field of view in degrees.",
        ),
        ParamSpec::new(
            "orbit_speed",
            ParamKind::Float { default: 0.0, min: -3600.0, max: 3600.0 },
            "Degrees of yaw added per second of animation.",
        ),
        ParamSpec::new(
            "turntable",
            ParamKind::Bool { default: false },
            "Exactly one revolution over the rendered frames (`render --frames A..B`: frame A at yaw, B one step short of a full turn; the editor's play range), instead of orbit_speed.",
        ),
        ParamSpec::new("near", ParamKind::Float { default: 0.05, min: 1e-5, max: 1e4 }, "Near clipping distance."),
        ParamSpec::new("far", ParamKind::Float { default: 100.0, min: 1e-3, max: 1e7 }, "Far clipping distance."),
    ],
    capabilities: Capabilities::ORBIT_CAMERA,
    create: || Box::new(OrbitCameraNode),
};

struct OrbitCameraNode;
impl Node for OrbitCameraNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let speed = cx.f64("orbit_speed");
        // Only an animated camera reads the time, so a still one is not re-run every frame.
        let turn = if cx.bool("turntable") {
            let frame = cx.time().frame;
            let Some((first, last)) = cx.frame_range() else {
                return Err(NodeError::msg("turntable needs a frame range, and this evaluation has none"));
            };
            360.0 * (frame - first) as f64 / (last - first + 1) as f64
        } else if speed != 0.0 {
            speed * cx.time().seconds()
        } else {
            0.0
        };
        let yaw = cx.f64("yaw") + turn;
        let (near, far) = (cx.f32("near"), cx.f32("far"));
        if near >= far {
            return Err(NodeError::msg(format!("near ({near}) must be less than far ({far})")));
        }
        let (yaw, pitch) = ((yaw as f32).to_radians(), cx.f32("pitch").to_radians());
        let dir = Vec3::new(yaw.sin() * pitch.cos(), pitch.sin(), yaw.cos() * pitch.cos());
        let fov = cx.f32("fov");
        let (target, distance) = match cx.optional::<Arc<Vec<DrawItem>>>("fit") {
            Some(scene) => {
                let (lo, hi) = scene_bounds(&scene)
                    .ok_or_else(|| NodeError::msg("input \"fit\": the scene has no plain geometry to frame"))?;
                let radius = ((hi - lo).length() * 0.5).max(1e-4);
                ((lo + hi) * 0.5, radius / (fov.to_radians() * 0.5).sin())
            }
            None => (cx.vec3("target"), cx.f32("distance")),
        };
        cx.set(
            "camera",
            Value::Camera(Camera { eye: target + dir * distance, target, up: Vec3::Y, fov_y_degrees: fov, near, far }),
        );
        Ok(())
    }
}

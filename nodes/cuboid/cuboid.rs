//! The cuboid scene graph's single cuboid and its grouping node (dissertation section 3.1.1,
//! src/cuboid/mod.rs): `Cuboid` makes a trilinear transform of 8 corners, `Deform` applies a
//! cuboid transform or grid to a sub-scene, so transforms nest.

use std::sync::Arc;

use glam::DVec3;

use crate::core::node::prelude::*;
use crate::cuboid::{Cuboid, CuboidGrid, NormalMethod, Transform, compose, unit_corner};
use crate::render::scene::DrawItem;

crate::choice!(
    pub enum Normals {
        TangentSpace = "tangent_space",
        Direct = "direct",
    }
);

impl Normals {
    pub fn method(self) -> NormalMethod {
        match self {
            Normals::TangentSpace => NormalMethod::TangentSpace,
            Normals::Direct => NormalMethod::Direct,
        }
    }
}

/// The parameters every cuboid node shares: the content's box and the normal method.
pub const BOX_MIN: ParamSpec = ParamSpec::new(
    "box_min",
    ParamKind::Vec3 { default: [-1.0, -1.0, -1.0] },
    "Minimum of the content's bounding box, mapped onto the unit cube of the cuboid.",
);
pub const BOX_MAX: ParamSpec =
    ParamSpec::new("box_max", ParamKind::Vec3 { default: [1.0, 1.0, 1.0] }, "Maximum of the content's bounding box.");
pub const NORMALS: ParamSpec = ParamSpec::new(
    "normals",
    ParamKind::Choice { default: "tangent_space", options: Normals::OPTIONS },
    "Normals (Fig. 4.5): tangent_space (orthogonal, C0 seams show) or direct (J n, smoother, not orthogonal).",
);

/// The box parameters, checked.
pub fn content_box(cx: &EvalCx<'_>) -> Result<(DVec3, DVec3), NodeError> {
    let (lo, hi) = (cx.vec3("box_min").as_dvec3(), cx.vec3("box_max").as_dvec3());
    if !(hi - lo).cmpgt(DVec3::ZERO).all() {
        return Err(NodeError::msg(format!(
            "box_max {:?} must exceed box_min {:?} on every axis",
            hi.to_array(),
            lo.to_array()
        )));
    }
    Ok((lo, hi))
}

const OFFSETS: [&str; 8] = ["offset0", "offset1", "offset2", "offset3", "offset4", "offset5", "offset6", "offset7"];

macro_rules! offset_param {
    ($name:literal, $corner:literal) => {
        ParamSpec::new(
            $name,
            ParamKind::Vec3 { default: [0.0, 0.0, 0.0] },
            concat!(
                "Offset of corner ",
                $corner,
                " after the affine part (corner i = (i&1, i>>1&1, i>>2&1) of the box)."
            ),
        )
    };
}

pub static CUBOID: NodeSpec = NodeSpec {
    kind: "Cuboid",
    category: Category::Scene,
    doc: "A trilinear transform (eq. 3.1/3.4): the content box's 8 corners scaled, rotated XYZ (degrees) and translated, then each moved by its offset. Zero offsets give an affine transform (the linear fast path).",
    inputs: &[],
    outputs: &[PortSpec::output("transform", PortType::CuboidTransform, "The cuboid, or its affine map when linear.")],
    params: &[
        ParamSpec::new("translate", ParamKind::Vec3 { default: [0.0, 0.0, 0.0] }, "Translation."),
        ParamSpec::new("rotate", ParamKind::Vec3 { default: [0.0, 0.0, 0.0] }, "Rotation about X, Y, Z in degrees."),
        ParamSpec::new("scale", ParamKind::Scale { default: [1.0, 1.0, 1.0] }, "Scale per axis."),
        offset_param!("offset0", "0"),
        offset_param!("offset1", "1"),
        offset_param!("offset2", "2"),
        offset_param!("offset3", "3"),
        offset_param!("offset4", "4"),
        offset_param!("offset5", "5"),
        offset_param!("offset6", "6"),
        offset_param!("offset7", "7"),
        BOX_MIN,
        BOX_MAX,
        NORMALS,
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(CuboidNode),
};

struct CuboidNode;
impl Node for CuboidNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let (lo, hi) = content_box(cx)?;
        let model = crate::nodes::mesh::geometry::model_matrix(cx)?.as_dmat4();
        let corners = std::array::from_fn(|i| {
            model.transform_point3(lo + unit_corner(i) * (hi - lo)) + cx.vec3(OFFSETS[i]).as_dvec3()
        });
        let grid = CuboidGrid::single(lo, hi, Cuboid { corners }, cx.choice::<Normals>("normals").method())
            .map_err(NodeError::msg)?;
        cx.set("transform", Arc::new(Transform::from_grid(grid)));
        Ok(())
    }
}

pub static DEFORM_SURFACE: NodeSpec = NodeSpec {
    kind: "DeformSurface",
    category: Category::Geometry,
    doc: "Moves a surface's vertices through a cuboid transform or grid on the CPU (positions, tangents by the Jacobian, normals by the grid's method), keeping UVs and pieces: a body bent by a grid can carry a matrix texture, attachments and anchors, which Deform's draw-time transform cannot.",
    inputs: &[
        PortSpec::required("surface", PortType::Surface, "The surface."),
        PortSpec::required("transform", PortType::CuboidTransform, "What to apply to it."),
    ],
    outputs: &[PortSpec::output("surface", PortType::Surface, "The deformed surface.")],
    params: &[],
    capabilities: Capabilities::NONE,
    create: || Box::new(DeformSurfaceNode),
};

struct DeformSurfaceNode;
impl Node for DeformSurfaceNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let surface: Arc<crate::mesh::Mesh> = cx.input("surface")?;
        let transform: Arc<Transform> = cx.input("transform")?;
        cx.set("surface", Arc::new(transform.deform_mesh(&surface)));
        Ok(())
    }
}

pub static DEFORM: NodeSpec = NodeSpec {
    kind: "Deform",
    category: Category::Scene,
    doc: "Applies a cuboid transform or grid to a sub-scene (a group of the cuboid scene graph): affine after affine multiplies, a grid after a grid is resampled at the finer resolution, and a composed grid that is affine falls back to the plain model matrix.",
    inputs: &[
        PortSpec::required("scene", PortType::Scene, "The sub-scene."),
        PortSpec::required("transform", PortType::CuboidTransform, "What to apply to it."),
    ],
    outputs: &[PortSpec::output("scene", PortType::Scene, "The sub-scene, transformed.")],
    params: &[],
    capabilities: Capabilities::NONE,
    create: || Box::new(DeformNode),
};

struct DeformNode;
impl Node for DeformNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let scene: Arc<Vec<DrawItem>> = cx.input("scene")?;
        let transform: Arc<Transform> = cx.input("transform")?;
        let mut skipped = 0;
        let items: Vec<DrawItem> = scene
            .iter()
            .map(|item| {
                // Deferred-warped attachments place their instances through the matrix texture.
                if !item.kind.places_mesh() && !transform.is_linear() {
                    skipped += 1;
                    return item.clone();
                }
                let mut out = item.clone();
                if let (false, Transform::Affine(a)) = (item.kind.places_mesh(), &*transform) {
                    out.model = a.as_mat4() * item.model;
                    return out;
                }
                let (model, grid) = compose(item.model, item.cuboid.as_ref(), &transform);
                out.model = model;
                out.cuboid = grid;
                out
            })
            .collect();
        if skipped > 0 {
            cx.warn(format!("{skipped} attached item(s) left undeformed: a non-linear cuboid applies to plain meshes"));
        }
        cx.set("scene", Arc::new(items));
        Ok(())
    }
}

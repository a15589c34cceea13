//! `CuboidGrid`: a uniform grid of cuboids (dissertation section 3.1.1, "Approximating
//! Arbitrary Deformations") sampled from an analytic deformation, or driven by an array of
//! anchors on a deforming mesh (section 4.1.1, Fig. 4.6).

use std::sync::Arc;

use glam::{DVec2, DVec3};

use super::cuboid::{BOX_MAX, BOX_MIN, NORMALS, Normals, content_box};
use crate::core::node::prelude::*;
use crate::cuboid::{Anchor, CuboidGrid, Lift, Transform, anchor_grid, anchor_row, bend, torus, twist};
use crate::mesh::Mesh;

crate::choice!(
    pub enum Source {
        Bend = "bend",
        Twist = "twist",
        Torus = "torus",
        Anchors = "anchors",
        AnchorRow = "anchor_row",
    }
);

pub static CUBOID_GRID: NodeSpec = NodeSpec {
    kind: "CuboidGrid",
    category: Category::Scene,
    doc: "A uniform grid of trilinear cuboids over the content box: sampled from a bend, a twist or a torus wrap, or driven by a 2D array or a row of anchors (barycentric on the mesh's triangles, found by UV) that follow a deforming mesh.",
    inputs: &[PortSpec::optional(
        "mesh",
        PortType::Mesh,
        "The deforming body the anchors sit on (source = anchors or anchor_row); it needs UVs.",
    )],
    outputs: &[PortSpec::output("transform", PortType::CuboidTransform, "The grid, or its affine map when linear.")],
    params: &[
        ParamSpec::new(
            "source",
            ParamKind::Choice { default: "bend", options: Source::OPTIONS },
            "What the corners sample: bend, twist, torus, a 2D array of anchors on the mesh, or a row of them.",
        ),
        ParamSpec::new("cells_x", ParamKind::Int { default: 4, min: 1, max: 256 }, "Cells along x."),
        ParamSpec::new("cells_y", ParamKind::Int { default: 1, min: 1, max: 256 }, "Cells along y."),
        ParamSpec::new(
            "cells_z",
            ParamKind::Int { default: 1, min: 1, max: 256 },
            "Cells along z (anchors: always 1).",
        ),
        ParamSpec::new(
            "amount",
            ParamKind::Float { default: 90.0, min: -3600.0, max: 3600.0 },
            "Degrees: the bend's arc, the twist from bottom to top, the torus's share of its major circle.",
        ),
        ParamSpec::new(
            "speed",
            ParamKind::Float { default: 0.0, min: -3600.0, max: 3600.0 },
            "Degrees per second added to amount (animates the deformation).",
        ),
        ParamSpec::new("radius", ParamKind::Float { default: 2.0, min: 1e-3, max: 1e4 }, "Torus: major radius."),
        ParamSpec::new("minor_radius", ParamKind::Float { default: 0.7, min: 1e-3, max: 1e4 }, "Torus: tube radius."),
        ParamSpec::new(
            "uv_min",
            ParamKind::Vec3 { default: [0.25, 0.25, 0.0] },
            "Anchors: UV of the first anchor (x = u, y = v).",
        ),
        ParamSpec::new(
            "uv_max",
            ParamKind::Vec3 { default: [0.75, 0.75, 0.0] },
            "Anchors: UV of the last anchor; the cells_x+1 by cells_y+1 anchors span uv_min..uv_max (a row: cells_x+1 anchors on the line between them).",
        ),
        ParamSpec::new(
            "width",
            ParamKind::Float { default: 0.2, min: 1e-6, max: 1e4 },
            "Anchor row: the grid's width across the row, centred on it.",
        ),
        ParamSpec::new(
            "height",
            ParamKind::Float { default: 0.2, min: -1e4, max: 1e4 },
            "Anchors: the grid's top layer lies this far along each anchor's normal (or their mean normal, see lift); negative: against it.",
        ),
        ParamSpec::new(
            "lift",
            ParamKind::Choice { default: "normal", options: Lift::OPTIONS },
            "Anchors (2D array): lift the top layer along each anchor's own normal (follows the surface; splays where it curves fast), or along their mean normal (parallel layers: a shoe on a sole that curves up at its rim).",
        ),
        BOX_MIN,
        BOX_MAX,
        NORMALS,
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(CuboidGridNode),
};

struct CuboidGridNode;
impl Node for CuboidGridNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let (lo, hi) = content_box(cx)?;
        let normals = cx.choice::<Normals>("normals").method();
        let cells = [cx.int("cells_x"), cx.int("cells_y"), cx.int("cells_z")].map(|n| n.max(1) as usize);
        let speed = cx.f64("speed");
        // Only an animated grid depends on the time (and re-runs every frame).
        let amount = cx.f64("amount") + if speed != 0.0 { speed * cx.time().seconds() } else { 0.0 };
        let grid = match cx.choice::<Source>("source") {
            Source::Bend => sampled(lo, hi, cells, normals, bend(lo, hi, amount)),
            Source::Twist => sampled(lo, hi, cells, normals, twist(lo, hi, amount)),
            Source::Torus => {
                sampled(lo, hi, cells, normals, torus(lo, hi, amount, cx.f64("radius"), cx.f64("minor_radius")))
            }
            Source::Anchors => {
                let mesh: Arc<Mesh> = cx
                    .optional("mesh")
                    .ok_or_else(|| NodeError::msg("source = \"anchors\" needs a mesh on input \"mesh\""))?;
                let (cols, rows) = (cells[0] + 1, cells[1] + 1);
                let (a, b) = (cx.vec3("uv_min").as_dvec3().truncate(), cx.vec3("uv_max").as_dvec3().truncate());
                let frames = anchor_frames(&mesh, a, b, cols, rows)?;
                anchor_grid(&frames, cols, rows, cx.f64("height"), cx.choice("lift"), lo, hi, normals)
            }
            Source::AnchorRow => {
                let mesh: Arc<Mesh> = cx
                    .optional("mesh")
                    .ok_or_else(|| NodeError::msg("source = \"anchor_row\" needs a mesh on input \"mesh\""))?;
                let (a, b) = (cx.vec3("uv_min").as_dvec3().truncate(), cx.vec3("uv_max").as_dvec3().truncate());
                let frames = anchor_row_frames(&mesh, a, b, cells[0] + 1)?;
                anchor_row(&frames, cx.f64("width"), cx.f64("height"), lo, hi, normals)
            }
        }
        .map_err(NodeError::msg)?;
        cx.set("transform", Arc::new(Transform::from_grid(grid)));
        Ok(())
    }
}

fn sampled(
    lo: DVec3,
    hi: DVec3,
    cells: [usize; 3],
    normals: crate::cuboid::NormalMethod,
    f: impl Fn(DVec3) -> DVec3,
) -> Result<CuboidGrid, String> {
    CuboidGrid::from_fn(lo, hi, cells, normals, |u| f(lo + u * (hi - lo)))
}

/// The frames of `count` anchors on the line from UV `a` to `b`, tangents along the line.
pub fn anchor_row_frames(
    mesh: &Mesh,
    a: DVec2,
    b: DVec2,
    count: usize,
) -> Result<Vec<crate::cuboid::Frame>, NodeError> {
    if a.distance(b) < 1e-9 {
        return Err(NodeError::msg("an anchor row needs uv_min and uv_max apart: they give its direction"));
    }
    let step = (b - a) / count as f64 * 0.25;
    (0..count)
        .map(|i| {
            let uv = a + (b - a) * (i as f64 / (count - 1) as f64);
            let anchor = Anchor::at_uv_towards(mesh, uv, step).map_err(NodeError::msg)?;
            anchor.frame(mesh).map_err(NodeError::msg)
        })
        .collect()
}

/// The frames of a `cols` x `rows` array of anchors spanning UVs `a..b` (u fastest), each
/// anchor's tangent point a small step along u.
pub fn anchor_frames(
    mesh: &Mesh,
    a: DVec2,
    b: DVec2,
    cols: usize,
    rows: usize,
) -> Result<Vec<crate::cuboid::Frame>, NodeError> {
    let du = ((b.x - a.x).abs() / cols as f64).max(1e-4) * 0.25;
    let mut frames = Vec::with_capacity(cols * rows);
    for j in 0..rows {
        for i in 0..cols {
            let t = DVec2::new(i as f64 / (cols - 1) as f64, j as f64 / (rows - 1) as f64);
            let uv = a + (b - a) * t;
            let anchor = Anchor::at_uv(mesh, uv, du).map_err(NodeError::msg)?;
            frames.push(anchor.frame(mesh).map_err(NodeError::msg)?);
        }
    }
    Ok(frames)
}

//! Curves in pattern coordinates without a script: a pattern piece's landmarks (its centre
//! line, an edge offset inward) and a polyline typed in (docs/warping.md, "Placing
//! attachments").

use std::sync::Arc;

use glam::Vec2;

use crate::core::node::prelude::*;
use crate::mesh::Mesh;
use crate::nodes::warp::placements::Coordinates;
use crate::warp::Curves;
use crate::warp::landmarks::{Landmark, parse_points, piece_landmark, polyline_segments};

const CURVES: PortSpec = PortSpec::output("curves", PortType::Curves, "The line, in UV space (v down).");

pub static PATTERN_LANDMARKS: NodeSpec = NodeSpec {
    kind: "PatternLandmarks",
    category: Category::Attachment,
    doc: "A line of a pattern piece, found from its UV outline: its centre line (halfway between its left and right outline, top to bottom), or its left, right, top or bottom edge moved inward by `offset`; ends kept `margin` inside the piece. For CurvePlacement (buttons down a front) or CurveAttachment.",
    inputs: &[PortSpec::required("surface", PortType::Surface, "The surface whose pieces' UV outlines are measured.")],
    outputs: &[CURVES],
    params: &[
        ParamSpec::new(
            "piece",
            ParamKind::Int { default: 0, min: 0, max: u32::MAX as i64 },
            "The piece id (Garment: the file's panel order; a mesh without pieces is piece 0).",
        ),
        ParamSpec::new(
            "landmark",
            ParamKind::Choice { default: "centre", options: Landmark::OPTIONS },
            "centre: top to bottom through the middle; left_edge / right_edge: top to bottom along that side; top_edge / bottom_edge: left to right (top is small v).",
        ),
        ParamSpec::new(
            "offset",
            ParamKind::Float { default: 0.0, min: -1.0, max: 1.0 },
            "UV distance inward from the edge; for the centre line, a shift towards +u.",
        ),
        ParamSpec::new(
            "margin",
            ParamKind::Float { default: 0.0, min: 0.0, max: 1.0 },
            "UV distance the line's ends stay inside the piece's extent along it.",
        ),
        ParamSpec::new(
            "samples",
            ParamKind::Int { default: 32, min: 2, max: 4096 },
            "Points measured along the line (it is a polyline through them).",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(PatternLandmarksNode),
};

struct PatternLandmarksNode;
impl Node for PatternLandmarksNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let surface: Arc<Mesh> = cx.input("surface")?;
        let points = piece_landmark(
            &surface,
            cx.int("piece") as u32,
            cx.choice::<Landmark>("landmark"),
            cx.f32("offset"),
            cx.f32("margin"),
            cx.int("samples") as usize,
        )
        .map_err(|e| NodeError::msg(format!("parameter \"piece\": {e}")))?;
        cx.set("curves", Arc::new(Curves { paths: vec![polyline_segments(&points)] }));
        Ok(())
    }
}

pub static POLYLINE: NodeSpec = NodeSpec {
    kind: "Polyline",
    category: Category::Attachment,
    doc: "A polyline typed in pattern coordinates (\"u v; u v; ...\", v down as in images): atlas UVs, or 0-1 across one piece's UV rectangle (`coordinates: piece`, with the surface). For CurvePlacement or CurveAttachment.",
    inputs: &[PortSpec::optional(
        "surface",
        PortType::Surface,
        "The surface whose piece the coordinates are relative to (coordinates: piece).",
    )],
    outputs: &[CURVES],
    params: &[
        ParamSpec::new(
            "points",
            ParamKind::Text { default: "0.5 0.1; 0.5 0.9" },
            "Points \"u v\", separated by ';' or new lines (at least two).",
        ),
        ParamSpec::new(
            "coordinates",
            ParamKind::Choice { default: "atlas", options: Coordinates::OPTIONS },
            "atlas: u, v are the surface's UVs; piece: 0-1 across the piece's UV bounding rectangle.",
        ),
        ParamSpec::new(
            "piece",
            ParamKind::Int { default: 0, min: 0, max: u32::MAX as i64 },
            "The piece of coordinates: piece.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(PolylineNode),
};

struct PolylineNode;
impl Node for PolylineNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let mut points: Vec<Vec2> = parse_points::<2>(cx.str("points"), "points")
            .map_err(NodeError::msg)?
            .into_iter()
            .map(Vec2::from)
            .collect();
        if points.len() < 2 {
            return Err(NodeError::msg(format!(
                "parameter \"points\" has {} point(s); a polyline needs at least two",
                points.len()
            )));
        }
        if cx.choice::<Coordinates>("coordinates") == Coordinates::Piece {
            let Some(surface) = cx.optional::<Arc<Mesh>>("surface") else {
                return Err(NodeError::msg(
                    "coordinates: piece needs the surface input, whose piece's UV rectangle the points are relative to",
                ));
            };
            let (lo, hi) = surface
                .piece_uv_rect(cx.int("piece") as u32)
                .map_err(|e| NodeError::msg(format!("parameter \"piece\": {e}")))?;
            points.iter_mut().for_each(|p| *p = lo + (hi - lo) * *p);
        }
        let path = polyline_segments(&points);
        if path.is_empty() {
            return Err(NodeError::msg("parameter \"points\": all points are the same; the polyline has no length"));
        }
        cx.set("curves", Arc::new(Curves { paths: vec![path] }));
        Ok(())
    }
}

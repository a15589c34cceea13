//! GarmentCode v2 sewing patterns (`*_specification.json`, maria-korosteleva/GarmentCode).
//!
//! - `pattern.panels`: a map by name; each panel has 2D `vertices`, `edges`
//!   (`{endpoints: [i, j], curvature?, label?}`) forming a closed loop, `translation` and
//!   `rotation` (XYZ Euler degrees, R = Rz Ry Rx, `pygarment/pattern/rotation.py`); a world
//!   point is R (x, y, 0) + t. The loop's orientation sets the fabric's front: the side from
//!   which it runs counter-clockwise.
//! - Curvature (`curvature_coords: "relative"`): `quadratic` (one control point) and `cubic`
//!   (two), each `[u, v]` with u along the edge and v along its left normal (-dy, dx), both in
//!   units of the edge length (`pygarment/pattern/utils.py` `rel_to_abs_2d`); `circle`
//!   `[radius, large_arc, right]`, an SVG arc whose sweep flag is `right` in the panel's y-up
//!   frame (`pygarment/meshgen/boxmeshgen.py`, `Edge.init_curve`); a bare `[u, v]` is an older
//!   file's quadratic.
//! - `pattern.stitches`: `[{panel, edge}, {panel, edge}]` with an optional third element
//!   `"right_wrong"`; by default the end of the first edge meets the start of the second
//!   (`boxmeshgen.py` `Seam.swap`).
//! - `properties.units_in_meter`: lengths are in 1/units_in_meter metres (100: centimetres).

use std::path::Path;

use glam::{DVec2, DVec3};
use serde_json::Value;

use super::{Edge, GarmentError, Panel, Pattern, Placement, Stitch, curve, euler_xyz_degrees, mirror_panel};

/// Reads a GarmentCode JSON file.
pub fn load(path: &Path) -> Result<Pattern, GarmentError> {
    let file = path.display().to_string();
    let text = std::fs::read_to_string(path)
        .map_err(|e| GarmentError::Format { file: file.clone(), message: format!("cannot read: {e}") })?;
    parse(&text, &file)
}

/// Parses GarmentCode JSON; `file` names it in messages.
pub fn parse(text: &str, file: &str) -> Result<Pattern, GarmentError> {
    let format = |message: String| GarmentError::Format { file: file.to_string(), message };
    let root: Value = serde_json::from_str(text).map_err(|e| format(format!("not JSON: {e}")))?;
    let spec = root.get("pattern").ok_or_else(|| format("no \"pattern\" object".into()))?;
    let panels =
        spec.get("panels").and_then(Value::as_object).ok_or_else(|| format("no \"pattern.panels\" map".into()))?;
    let props = root.get("properties");
    let units = match props.and_then(|p| p.get("units_in_meter")) {
        None => 100.0,
        Some(v) => v
            .as_f64()
            .filter(|u| u.is_finite() && *u > 0.0)
            .ok_or_else(|| format(format!("properties.units_in_meter must be a positive number, not {v}")))?,
    };
    if let Some(c) = props.and_then(|p| p.get("curvature_coords")).and_then(Value::as_str)
        && c != "relative"
    {
        return Err(format(format!("curvature_coords \"{c}\" is not supported (only \"relative\")")));
    }
    // Centimetres per file unit.
    let to_cm = 100.0 / units;

    // Panels in `panel_order` (the file's order of the garment), then any it leaves out by name.
    let mut names: Vec<String> = Vec::new();
    if let Some(order) = spec.get("panel_order").and_then(Value::as_array) {
        for n in order.iter().filter_map(Value::as_str) {
            if panels.contains_key(n) && !names.iter().any(|m| m == n) {
                names.push(n.to_string());
            }
        }
    }
    let mut rest: Vec<&String> = panels.keys().filter(|k| !names.contains(k)).collect();
    rest.sort();
    names.extend(rest.into_iter().cloned());

    let mut out = Vec::with_capacity(names.len());
    for name in &names {
        out.push(panel(&panels[name], name, file, to_cm)?);
    }

    let stitches_json = spec.get("stitches").and_then(Value::as_array).map(Vec::as_slice).unwrap_or(&[]);
    let mut stitches = Vec::with_capacity(stitches_json.len());
    for (k, s) in stitches_json.iter().enumerate() {
        let bad = |why: &str| format(format!("stitch {k}: {why}"));
        let items = s.as_array().ok_or_else(|| bad("not a list"))?;
        if items.len() < 2 || items.len() > 3 {
            return Err(bad("needs two sides ({panel, edge}) and optionally \"right_wrong\""));
        }
        let right_wrong = match items.get(2) {
            None => false,
            Some(Value::String(s)) if s == "right_wrong" => true,
            Some(other) => return Err(bad(&format!("unknown third element {other} (only \"right_wrong\")"))),
        };
        let side = |v: &Value| -> Result<(usize, usize), GarmentError> {
            let panel = v.get("panel").and_then(Value::as_str).ok_or_else(|| bad("a side has no \"panel\" name"))?;
            let edge = v.get("edge").and_then(Value::as_u64).ok_or_else(|| bad("a side has no \"edge\" number"))?;
            let p = names.iter().position(|n| n == panel).ok_or_else(|| GarmentError::MissingPanel {
                file: file.into(),
                stitch: k,
                panel: panel.into(),
            })?;
            let e = out[p].edge_index(edge as usize).ok_or_else(|| GarmentError::MissingEdge {
                file: file.into(),
                stitch: k,
                panel: panel.into(),
                edge: edge as usize,
                count: out[p].edges.len(),
            })?;
            Ok((p, e))
        };
        let (a, b) = (side(&items[0])?, side(&items[1])?);
        stitches.push(Stitch { a, b, end_to_start: !right_wrong });
    }
    let pattern = Pattern { file: file.to_string(), panels: out, stitches };
    pattern.validate()?;
    Ok(pattern)
}

fn vec_of<const N: usize>(v: Option<&Value>) -> Option<[f64; N]> {
    let a = v?.as_array()?;
    if a.len() != N {
        return None;
    }
    let mut out = [0.0; N];
    for (o, x) in out.iter_mut().zip(a) {
        *o = x.as_f64().filter(|f| f.is_finite())?;
    }
    Some(out)
}

fn panel(v: &Value, name: &str, file: &str, to_cm: f64) -> Result<Panel, GarmentError> {
    let format =
        |message: String| GarmentError::Format { file: file.into(), message: format!("panel \"{name}\": {message}") };
    let empty = |why: &str| GarmentError::EmptyPanel { file: file.into(), panel: name.into(), why: why.into() };
    let vertices: Vec<DVec2> = match v.get("vertices").and_then(Value::as_array) {
        None => return Err(empty("no \"vertices\"")),
        Some(list) => list
            .iter()
            .enumerate()
            .map(|(i, p)| {
                vec_of::<2>(Some(p))
                    .map(|[x, y]| DVec2::new(x, y) * to_cm)
                    .ok_or_else(|| format(format!("vertex {i} is not two finite numbers")))
            })
            .collect::<Result<_, _>>()?,
    };
    let edges_json = v.get("edges").and_then(Value::as_array).ok_or_else(|| empty("no \"edges\""))?;
    if edges_json.is_empty() || vertices.is_empty() {
        return Err(empty("no edges or no vertices"));
    }
    let translation = vec_of::<3>(v.get("translation")).ok_or_else(|| format("no translation [x, y, z]".into()))?;
    let rotation = vec_of::<3>(v.get("rotation")).ok_or_else(|| format("no rotation [x, y, z] (degrees)".into()))?;
    let mut edges = Vec::with_capacity(edges_json.len());
    for (i, e) in edges_json.iter().enumerate() {
        let bad = |message: String| GarmentError::BadEdge { file: file.into(), panel: name.into(), edge: i, message };
        let ends = e.get("endpoints").and_then(Value::as_array).ok_or_else(|| bad("no \"endpoints\"".into()))?;
        let idx: Vec<usize> = ends.iter().filter_map(Value::as_u64).map(|x| x as usize).collect();
        if idx.len() != 2 || idx.iter().any(|&j| j >= vertices.len()) {
            return Err(bad(format!("endpoints {ends:?} are not two of the {} vertices", vertices.len())));
        }
        let (a, b) = (vertices[idx[0]], vertices[idx[1]]);
        let points = edge_points(a, b, e.get("curvature"), to_cm).map_err(bad)?;
        let label = e.get("label").and_then(Value::as_str).map(str::to_string);
        edges.push(Edge { id: i, points, label });
    }
    let label = v.get("label").and_then(Value::as_str).map(str::to_string);
    let placement = Placement {
        rotation: euler_xyz_degrees(DVec3::from_array(rotation)),
        translation: DVec3::from_array(translation) * to_cm,
    };
    let mut panel = Panel { name: name.to_string(), edges, placement, label, buttons: Vec::new() };
    if panel.signed_area() < 0.0 {
        // Clockwise: the front faces -z. Mirror it in the plane so the outline runs
        // counter-clockwise, as the triangulator needs; the placement keeps it in place.
        mirror_panel(&mut panel);
    }
    Ok(panel)
}

/// The edge `a`-`b` (centimetres) with its curvature, flattened.
fn edge_points(a: DVec2, b: DVec2, curvature: Option<&Value>, to_cm: f64) -> Result<Vec<DVec2>, String> {
    let d = b - a;
    // u along the edge, v along its left normal, both in edge lengths.
    let rel = |uv: [f64; 2]| a + d * uv[0] + DVec2::new(-d.y, d.x) * uv[1];
    let Some(c) = curvature else {
        return Ok(vec![a, b]);
    };
    if c.is_array() {
        let uv = vec_of::<2>(Some(c)).ok_or("curvature [u, v] is not two numbers")?;
        return Ok(curve::quadratic(a, rel(uv), b));
    }
    let kind = c.get("type").and_then(Value::as_str).ok_or("curvature has no \"type\"")?;
    let params = c.get("params").and_then(Value::as_array).ok_or("curvature has no \"params\"")?;
    let point = |i: usize| -> Result<[f64; 2], String> {
        vec_of::<2>(params.get(i)).ok_or_else(|| format!("{kind} control point {i} is not [u, v]"))
    };
    match kind {
        "quadratic" => Ok(curve::quadratic(a, rel(point(0)?), b)),
        "cubic" => Ok(curve::cubic(a, rel(point(0)?), rel(point(1)?), b)),
        "circle" => {
            let num = |i: usize| params.get(i).and_then(Value::as_f64).filter(|f| f.is_finite());
            let flag = |i: usize| params.get(i).and_then(|v| v.as_bool().or_else(|| v.as_f64().map(|f| f != 0.0)));
            let (Some(r), Some(large), Some(right)) = (num(0), flag(1), flag(2)) else {
                return Err("circle params are not [radius, large_arc, right]".into());
            };
            curve::arc(a, b, r * to_cm, large, right)
                .ok_or_else(|| format!("circle of radius {r} between coincident or invalid ends"))
        }
        other => Err(format!("unknown curvature type \"{other}\" (quadratic, cubic, circle)")),
    }
}

//! FreeSewing SVG patterns with a RON sidecar that says how they are sewn.
//!
//! A FreeSewing SVG (`freesewing` attribute on the root; mm, y down) draws each part in a group
//! whose id ends in `-part-<design>.<part>`, with its seam line as a `path` of class `fabric`.
//! It names no seams: which edges of which parts are sewn together, and where each part sits on
//! the body, is the sidecar's (docs/garments.md):
//!
//! ```ron
//! (
//!     svg: "freesewing-simon-shirt.svg", // relative to the sidecar
//!     units_per_cm: 10.0,                 // SVG user units per centimetre (FreeSewing: mm)
//!     panels: [
//!         // One panel per piece of fabric: a part, mirrored for the second of a mirrored pair.
//!         (name: "front_left", part: "frontLeft", cuts: [0, 1, 4, 7, 8, 9],
//!          translation: (0, 143, 22), rotation: (0, 0, 0)),
//!     ],
//!     stitches: [(a: ("front_left", 1), b: ("back_left", 1), same_direction: true)],
//! )
//! ```
//!
//! - A part's seam path is a loop of segments (each `L`, `C` or `Q` command, and the closing
//!   line of `z` when it has length). `cuts` split the loop into the panel's edges: a cut `k.f`
//!   is a fraction `f` of segment `k`'s arc length, and edge `i` runs from cut `i` to cut
//!   `i + 1` (the last one back to the first). Without cuts every segment is an edge.
//! - `path`: which of the part's closed `fabric` paths is the seam line (default 0, the first).
//! - The panel's frame is the part's SVG frame in centimetres with y up; `mirror` flips x (the
//!   other piece of a pair cut mirrored). The drawn side is the fabric's front, facing +z.
//!   Placement is like GarmentCode's: a world point is R (x, y, 0) + translation, R from XYZ
//!   Euler degrees (R = Rz Ry Rx), all in centimetres.
//! - A stitch sews edge `a` to edge `b` (panel name, edge number). By default the start of `a`
//!   meets the end of `b` (two pieces side by side whose outlines run the same way);
//!   `same_direction: true` makes the starts meet. Directions are those of the SVG path.

use std::path::{Path, PathBuf};

use glam::{DVec2, DVec3};
use serde::Deserialize;

use super::{Edge, GarmentError, Panel, Pattern, Placement, Stitch, curve, euler_xyz_degrees};

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Sidecar {
    pub svg: String,
    #[serde(default = "default_units")]
    pub units_per_cm: f64,
    pub panels: Vec<SidecarPanel>,
    #[serde(default)]
    pub stitches: Vec<SidecarStitch>,
}

fn default_units() -> f64 {
    10.0
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SidecarPanel {
    pub name: String,
    pub part: String,
    #[serde(default)]
    pub path: usize,
    /// Empty: every segment is an edge.
    #[serde(default)]
    pub cuts: Vec<f64>,
    #[serde(default)]
    pub mirror: bool,
    #[serde(default)]
    pub translation: (f64, f64, f64),
    #[serde(default)]
    pub rotation: (f64, f64, f64),
}

#[derive(Debug, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SidecarStitch {
    pub a: (String, usize),
    pub b: (String, usize),
    #[serde(default)]
    pub same_direction: bool,
}

/// Reads a sidecar (`.ron`) and the SVG it names.
pub fn load(sidecar: &Path) -> Result<Pattern, GarmentError> {
    let file = sidecar.display().to_string();
    let format = |message: String| GarmentError::Format { file: file.clone(), message };
    let text = std::fs::read_to_string(sidecar).map_err(|e| format(format!("cannot read: {e}")))?;
    let car: Sidecar = ron::from_str(&text).map_err(|e| format(format!("not a sewing sidecar: {e}")))?;
    let svg_path: PathBuf = sidecar.parent().unwrap_or(Path::new(".")).join(&car.svg);
    let svg = std::fs::read_to_string(&svg_path)
        .map_err(|e| format(format!("cannot read the SVG {}: {e}", svg_path.display())))?;
    build(&car, &svg, &file, &svg_path.display().to_string())
}

/// A part's seam path as segments, each a flattened polyline in SVG units.
fn part_paths(doc: &roxmltree::Document<'_>, part: &str, svg_name: &str) -> Result<Vec<Vec<Vec<DVec2>>>, String> {
    let suffix = format!(".{part}");
    let group = doc
        .descendants()
        .find(|n| {
            n.has_tag_name("g") && n.attribute("id").is_some_and(|id| id.contains("-part-") && id.ends_with(&suffix))
        })
        .ok_or_else(|| format!("{svg_name} has no part \"{part}\" (a group with id ...-part-<design>.{part})"))?;
    let mut closed = Vec::new();
    for node in group.descendants().filter(|n| n.has_tag_name("path")) {
        let is_fabric = node.attribute("class").is_some_and(|c| c.split_whitespace().eq(["fabric"]));
        let Some(d) = node.attribute("d").filter(|_| is_fabric) else {
            continue;
        };
        if let Some(segments) = path_segments(d).map_err(|e| format!("part \"{part}\": {e}"))? {
            closed.push(segments);
        }
    }
    Ok(closed)
}

/// The positions (SVG units) of a part's button snippets (`<use href="#button">`; FreeSewing
/// writes their `transform` as a scale about the point, 1 for buttons).
fn part_buttons(doc: &roxmltree::Document<'_>, part: &str) -> Vec<DVec2> {
    const XLINK: &str = "http://www.w3.org/1999/xlink";
    let suffix = format!(".{part}");
    let Some(group) = doc.descendants().find(|n| {
        n.has_tag_name("g") && n.attribute("id").is_some_and(|id| id.contains("-part-") && id.ends_with(&suffix))
    }) else {
        return Vec::new();
    };
    group
        .descendants()
        .filter(|n| n.has_tag_name("use"))
        .filter(|n| n.attribute((XLINK, "href")).or(n.attribute("href")) == Some("#button"))
        .filter_map(|n| {
            let coord = |name: &str| n.attribute(name).unwrap_or("0").trim().parse::<f64>().ok();
            Some(DVec2::new(coord("x")?, coord("y")?))
        })
        .collect()
}

/// The segments of a closed path (`None` for an open one or one with several subpaths).
fn path_segments(d: &str) -> Result<Option<Vec<Vec<DVec2>>>, String> {
    use svgtypes::SimplePathSegment as S;
    let mut segments: Vec<Vec<DVec2>> = Vec::new();
    let (mut start, mut cur) = (None::<DVec2>, DVec2::ZERO);
    let mut closed = false;
    for seg in svgtypes::SimplifyingPathParser::from(d) {
        let seg = seg.map_err(|e| format!("bad path data: {e}"))?;
        if closed {
            // Only single closed outlines are seam lines.
            return Ok(None);
        }
        match seg {
            S::MoveTo { x, y } => {
                if start.is_some() {
                    return Ok(None);
                }
                start = Some(DVec2::new(x, y));
                cur = DVec2::new(x, y);
            }
            S::LineTo { x, y } => {
                let p = DVec2::new(x, y);
                segments.push(vec![cur, p]);
                cur = p;
            }
            S::CurveTo { x1, y1, x2, y2, x, y } => {
                let p = DVec2::new(x, y);
                segments.push(curve::cubic(cur, DVec2::new(x1, y1), DVec2::new(x2, y2), p));
                cur = p;
            }
            S::Quadratic { x1, y1, x, y } => {
                let p = DVec2::new(x, y);
                segments.push(curve::quadratic(cur, DVec2::new(x1, y1), p));
                cur = p;
            }
            S::ClosePath => {
                let s = start.ok_or("ClosePath before MoveTo")?;
                if cur.distance(s) > 1e-9 {
                    segments.push(vec![cur, s]);
                }
                cur = s;
                closed = true;
            }
        }
    }
    let Some(s) = start else { return Ok(None) };
    // FreeSewing ends some seam lines at their start without a `z`.
    if !(closed || (segments.len() >= 2 && cur.distance(s) <= 1e-6)) || segments.is_empty() {
        return Ok(None);
    }
    if let Some(last) = segments.last_mut() {
        *last.last_mut().expect("a segment has points") = s;
    }
    Ok(Some(segments))
}

/// Builds the pattern from a parsed sidecar and the SVG text; `file` and `svg_name` name them.
pub fn build(car: &Sidecar, svg: &str, file: &str, svg_name: &str) -> Result<Pattern, GarmentError> {
    let format = |message: String| GarmentError::Format { file: file.to_string(), message };
    let doc = roxmltree::Document::parse(svg).map_err(|e| format(format!("{svg_name} is not XML: {e}")))?;
    if !(car.units_per_cm.is_finite() && car.units_per_cm > 0.0) {
        return Err(format(format!("units_per_cm must be positive, not {}", car.units_per_cm)));
    }
    let mut panels: Vec<Panel> = Vec::with_capacity(car.panels.len());
    // Panels whose loop was reversed to run counter-clockwise: their edges run backwards.
    let mut reversed = Vec::with_capacity(car.panels.len());
    for sp in &car.panels {
        if panels.iter().any(|p| p.name == sp.name) {
            return Err(format(format!("two panels are named \"{}\"", sp.name)));
        }
        let empty = |why: String| GarmentError::EmptyPanel { file: file.to_string(), panel: sp.name.clone(), why };
        let paths = part_paths(&doc, &sp.part, svg_name).map_err(format)?;
        let segments = paths.get(sp.path).ok_or_else(|| {
            empty(format!("part \"{}\" has {} closed fabric path(s), not a path {}", sp.part, paths.len(), sp.path))
        })?;
        let flip = if sp.mirror { -1.0 } else { 1.0 };
        let to_panel = |p: DVec2| DVec2::new(flip * p.x, -p.y) / car.units_per_cm;
        let segments: Vec<Vec<DVec2>> = segments.iter().map(|s| s.iter().map(|p| to_panel(*p)).collect()).collect();
        let cuts = if sp.cuts.is_empty() { (0..segments.len()).map(|k| k as f64).collect() } else { sp.cuts.clone() };
        let edges = cut_edges(&segments, &cuts).map_err(|e| format(format!("panel \"{}\": {e}", sp.name)))?;
        let (t, r) = (sp.translation, sp.rotation);
        let placement = Placement {
            rotation: euler_xyz_degrees(DVec3::new(r.0, r.1, r.2)),
            translation: DVec3::new(t.0, t.1, t.2),
        };
        let buttons = part_buttons(&doc, &sp.part).into_iter().map(to_panel).collect();
        let mut panel = Panel { name: sp.name.clone(), edges, placement, label: None, buttons };
        let backwards = panel.signed_area() < 0.0;
        if backwards {
            // The drawn side is the front, so reverse the loop rather than mirror the panel.
            panel.edges.reverse();
            for e in &mut panel.edges {
                e.points.reverse();
            }
        }
        panels.push(panel);
        reversed.push(backwards);
    }
    let mut stitches = Vec::with_capacity(car.stitches.len());
    for (k, s) in car.stitches.iter().enumerate() {
        let side = |(name, edge): &(String, usize)| -> Result<(usize, usize), GarmentError> {
            let p = panels.iter().position(|p| p.name == *name).ok_or_else(|| GarmentError::MissingPanel {
                file: file.to_string(),
                stitch: k,
                panel: name.clone(),
            })?;
            let e = panels[p].edge_index(*edge).ok_or_else(|| GarmentError::MissingEdge {
                file: file.to_string(),
                stitch: k,
                panel: name.clone(),
                edge: *edge,
                count: panels[p].edges.len(),
            })?;
            Ok((p, e))
        };
        let (a, b) = (side(&s.a)?, side(&s.b)?);
        // In SVG directions the default is start-to-end; a reversed panel flips its edge.
        let end_to_start = !s.same_direction ^ reversed[a.0] ^ reversed[b.0];
        stitches.push(Stitch { a, b, end_to_start });
    }
    let pattern = Pattern { file: file.to_string(), panels, stitches };
    pattern.validate()?;
    Ok(pattern)
}

/// The loop of `segments` split at `cuts` (segment index plus arc-length fraction) into edges.
fn cut_edges(segments: &[Vec<DVec2>], cuts: &[f64]) -> Result<Vec<Edge>, String> {
    let n = segments.len() as f64;
    if cuts.len() < 2 {
        return Err("needs at least two cuts".into());
    }
    for w in cuts.windows(2) {
        if w[0].partial_cmp(&w[1]) != Some(std::cmp::Ordering::Less) {
            return Err(format!("cuts must increase: {} then {}", w[0], w[1]));
        }
    }
    if cuts.iter().any(|c| !(c.is_finite() && *c >= 0.0 && *c < n)) {
        return Err(format!("cuts must lie in 0 to {n} (the path has {} segments)", segments.len()));
    }
    // Every point of the loop with its parameter: segment index plus arc-length fraction.
    let mut params: Vec<(f64, DVec2)> = Vec::new();
    for (k, seg) in segments.iter().enumerate() {
        let len = curve::polyline_length(seg);
        let mut walked = 0.0;
        for (i, p) in seg.iter().enumerate().take(seg.len() - 1) {
            if i > 0 {
                walked += seg[i - 1].distance(*p);
            }
            let f = if len > 0.0 { walked / len } else { 0.0 };
            params.push((k as f64 + f, *p));
        }
    }
    let total = params.len();
    // The point at loop parameter c (in [0, n)).
    let at = |c: f64| -> DVec2 {
        let i = params.partition_point(|(t, _)| *t <= c) - 1;
        let (t0, p0) = params[i];
        let (t1, p1) = if i + 1 < total { params[i + 1] } else { (n, params[0].1) };
        if t1 > t0 { p0.lerp(p1, (c - t0) / (t1 - t0)) } else { p0 }
    };
    let m = cuts.len();
    let mut edges = Vec::with_capacity(m);
    for i in 0..m {
        let c0 = cuts[i];
        // The last edge wraps past the loop's start.
        let c1 = if i + 1 < m { cuts[i + 1] } else { cuts[0] + n };
        let mut pts = vec![at(c0)];
        for round in [0.0, n] {
            pts.extend(params.iter().filter(|(t, _)| *t + round > c0 && *t + round < c1).map(|(_, p)| *p));
        }
        pts.push(at(c1 % n));
        pts.dedup_by(|a, b| a.distance(*b) <= 1e-12);
        edges.push(Edge { id: i, points: pts, label: None });
    }
    Ok(edges)
}

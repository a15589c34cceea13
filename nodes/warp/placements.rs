//! Where detail geometry goes: placement generators (scatter, grid, along curves) and a
//! designer's placement file.

use std::path::Path;
use std::sync::Arc;

use anyhow::{Context as _, bail};
use glam::{Vec2, Vec3};

use crate::core::node::prelude::*;
use crate::mesh::Mesh;
use crate::warp::{ArcTable, Curves, Placement, bezier, curve_direction, landmarks};

const REGION: [ParamSpec; 4] = [
    ParamSpec::new("u_min", ParamKind::Float { default: 0.0, min: 0.0, max: 1.0 }, "Region: lowest u."),
    ParamSpec::new("u_max", ParamKind::Float { default: 1.0, min: 0.0, max: 1.0 }, "Region: highest u."),
    ParamSpec::new("v_min", ParamKind::Float { default: 0.0, min: 0.0, max: 1.0 }, "Region: lowest v."),
    ParamSpec::new("v_max", ParamKind::Float { default: 1.0, min: 0.0, max: 1.0 }, "Region: highest v."),
];

/// Which pattern piece covers a UV point: a uniform grid over the surface's UV triangles.
pub struct UvCoverage<'a> {
    mesh: &'a Mesh,
    cells: Vec<Vec<u32>>,
    n: usize,
}

impl<'a> UvCoverage<'a> {
    pub fn new(mesh: &'a Mesh) -> Self {
        let n = ((mesh.triangle_count() as f64).sqrt() as usize).clamp(1, 512);
        let mut cells = vec![Vec::new(); n * n];
        for (t, tri) in mesh.indices.chunks_exact(3).enumerate() {
            let uv = [mesh.uvs[tri[0] as usize], mesh.uvs[tri[1] as usize], mesh.uvs[tri[2] as usize]];
            let lo = uv[0].min(uv[1]).min(uv[2]);
            let hi = uv[0].max(uv[1]).max(uv[2]);
            let cell = |x: f32| ((x * n as f32) as isize).clamp(0, n as isize - 1) as usize;
            for cy in cell(lo.y)..=cell(hi.y) {
                for cx in cell(lo.x)..=cell(hi.x) {
                    cells[cy * n + cx].push(t as u32);
                }
            }
        }
        UvCoverage { mesh, cells, n }
    }

    /// The piece id at `uv`, if a triangle covers it.
    pub fn piece_at(&self, uv: Vec2) -> Option<u32> {
        if !(0.0..=1.0).contains(&uv.x) || !(0.0..=1.0).contains(&uv.y) {
            return None;
        }
        let cell = |x: f32| ((x * self.n as f32) as usize).min(self.n - 1);
        for &t in &self.cells[cell(uv.y) * self.n + cell(uv.x)] {
            let i = &self.mesh.indices[3 * t as usize..3 * t as usize + 3];
            let [a, b, c] = [self.mesh.uvs[i[0] as usize], self.mesh.uvs[i[1] as usize], self.mesh.uvs[i[2] as usize]];
            let d = (b - a).perp_dot(c - a);
            if d.abs() < 1e-20 {
                continue;
            }
            let (l1, l2) = ((uv - a).perp_dot(c - a) / d, (b - a).perp_dot(uv - a) / d);
            if l1 >= 0.0 && l2 >= 0.0 && l1 + l2 <= 1.0 {
                return Some(self.mesh.piece_ids.get(i[0] as usize).copied().unwrap_or(0));
            }
        }
        None
    }
}

/// The piece under `uv`, or piece 0 everywhere when no surface restricts placements.
fn piece_at(coverage: &Option<UvCoverage<'_>>, uv: Vec2) -> Option<u32> {
    match coverage {
        Some(c) => c.piece_at(uv),
        None => Some(0),
    }
}

fn region(cx: &EvalCx<'_>) -> Result<(Vec2, Vec2), NodeError> {
    let lo = Vec2::new(cx.f32("u_min"), cx.f32("v_min"));
    let hi = Vec2::new(cx.f32("u_max"), cx.f32("v_max"));
    if lo.x >= hi.x || lo.y >= hi.y {
        return Err(NodeError::msg("the region is empty: u_min must be below u_max and v_min below v_max"));
    }
    Ok((lo, hi))
}

fn surface_input(cx: &EvalCx<'_>) -> Option<Arc<Mesh>> {
    cx.optional("surface")
}

const PLACEMENTS: PortSpec = PortSpec::output("placements", PortType::Instances, "The placements.");
const COUNT: PortSpec = PortSpec::output("count", PortType::Scalar, "How many placements there are.");

/// Sets the outputs and reports the count; `dropped` placements fell off the surface's
/// pieces, which a user must hear about (a grid over the whole UV square silently lost
/// most of its buttons on the flag).
fn finish(cx: &mut EvalCx<'_>, out: Vec<Placement>, dropped: usize, surface: Option<&Mesh>) {
    if dropped > 0
        && let Some(mesh) = surface
    {
        let rects: Vec<String> = mesh
            .piece_uv_rects()
            .iter()
            .map(|(p, lo, hi)| format!("piece {p}: u {:.3}-{:.3}, v {:.3}-{:.3}", lo.x, hi.x, lo.y, hi.y))
            .collect();
        cx.warn(format!(
            "{dropped} of {} placements fall off the pattern pieces and were dropped; the pieces cover {}",
            out.len() + dropped,
            rects.join("; ")
        ));
    }
    cx.count("placements", out.len());
    cx.set("count", out.len() as f64);
    cx.set("placements", Arc::new(out));
}

pub static SCATTER: NodeSpec = NodeSpec {
    kind: "Scatter",
    category: Category::Attachment,
    doc: "Random placements in a UV region with a minimum spacing (dart throwing, seeded); with a surface, only where a pattern piece covers the point.",
    inputs: &[PortSpec::optional(
        "surface",
        PortType::Surface,
        "Keeps placements on the pieces and records their piece id.",
    )],
    outputs: &[PLACEMENTS, COUNT],
    params: &[
        ParamSpec::new(
            "count",
            ParamKind::Int { default: 500, min: 0, max: 10_000_000 },
            "How many placements to try to make.",
        ),
        ParamSpec::new(
            "min_spacing",
            ParamKind::Float { default: 0.0, min: 0.0, max: 1.0 },
            "Minimum UV distance between placements (0 = none).",
        ),
        ParamSpec::new("seed", ParamKind::Int { default: 1, min: 0, max: i64::MAX }, "Random seed."),
        ParamSpec::new("scale_min", ParamKind::Float { default: 1.0, min: 0.0, max: 1e3 }, "Smallest random scale."),
        ParamSpec::new("scale_max", ParamKind::Float { default: 1.0, min: 0.0, max: 1e3 }, "Largest random scale."),
        ParamSpec::new("random_angle", ParamKind::Bool { default: true }, "Random rotation about the normal."),
        REGION[0],
        REGION[1],
        REGION[2],
        REGION[3],
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(ScatterNode),
};

struct ScatterNode;
impl Node for ScatterNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let (lo, hi) = region(cx)?;
        let surface = surface_input(cx);
        let coverage = surface.as_deref().map(UvCoverage::new);
        let count = cx.int("count") as usize;
        let spacing = cx.f32("min_spacing");
        let (smin, smax) = (cx.f32("scale_min"), cx.f32("scale_max").max(cx.f32("scale_min")));
        let mut rng = crate::core::rng::SplitMix64::new(cx.int("seed") as u64);
        // Spatial hash of accepted points for the spacing test.
        let cell = spacing.max(1e-6);
        let mut grid: std::collections::BTreeMap<(i32, i32), Vec<Vec2>> = Default::default();
        let mut out = Vec::with_capacity(count);
        let mut dropped = 0;
        let attempts = count.saturating_mul(if spacing > 0.0 { 30 } else { 4 }).max(count);
        for _ in 0..attempts {
            if out.len() >= count {
                break;
            }
            let uv = lo + (hi - lo) * Vec2::new(rng.next_f32(), rng.next_f32());
            let (angle, scale) = (rng.next_f32() * 360.0, smin + (smax - smin) * rng.next_f32());
            let Some(piece) = piece_at(&coverage, uv) else {
                dropped += 1;
                continue;
            };
            if spacing > 0.0 {
                let key = ((uv.x / cell).floor() as i32, (uv.y / cell).floor() as i32);
                let near = (-1..=1).any(|dy| {
                    (-1..=1).any(|dx| {
                        grid.get(&(key.0 + dx, key.1 + dy))
                            .is_some_and(|pts| pts.iter().any(|p| p.distance(uv) < spacing))
                    })
                });
                if near {
                    continue;
                }
                grid.entry(key).or_default().push(uv);
            }
            out.push(Placement {
                piece,
                u: uv.x,
                v: uv.y,
                angle: if cx.bool("random_angle") { angle } else { 0.0 },
                scale,
            });
        }
        if out.len() < count {
            cx.warn(format!("placed {} of {count}: the region is full at this spacing or coverage", out.len()));
        }
        // Scatter retries misses, so only a region with no piece in it counts as falling off.
        let dropped = if out.is_empty() { dropped } else { 0 };
        finish(cx, out, dropped, surface.as_deref());
        Ok(())
    }
}

pub static GRID_PLACEMENT: NodeSpec = NodeSpec {
    kind: "GridPlacement",
    category: Category::Attachment,
    doc: "Placements on a regular grid over a UV region (cell centres); with a surface, only where a piece covers the point.",
    inputs: &[PortSpec::optional(
        "surface",
        PortType::Surface,
        "Keeps placements on the pieces and records their piece id.",
    )],
    outputs: &[PLACEMENTS, COUNT],
    params: &[
        ParamSpec::new("columns", ParamKind::Int { default: 8, min: 1, max: 100_000 }, "Cells along u."),
        ParamSpec::new("rows", ParamKind::Int { default: 8, min: 1, max: 100_000 }, "Cells along v."),
        ParamSpec::new(
            "angle",
            ParamKind::Float { default: 0.0, min: -3600.0, max: 3600.0 },
            "Rotation about the normal, degrees.",
        ),
        ParamSpec::new("scale", ParamKind::Float { default: 1.0, min: 0.0, max: 1e3 }, "Scale of each placement."),
        REGION[0],
        REGION[1],
        REGION[2],
        REGION[3],
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(GridNode),
};

struct GridNode;
impl Node for GridNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let (lo, hi) = region(cx)?;
        let surface = surface_input(cx);
        let coverage = surface.as_deref().map(UvCoverage::new);
        let (cols, rows) = (cx.int("columns") as usize, cx.int("rows") as usize);
        if cols * rows > 10_000_000 {
            return Err(NodeError::msg(format!("{cols} x {rows} placements is more than the limit of 10 million")));
        }
        let mut out = Vec::with_capacity(cols * rows);
        let mut dropped = 0;
        for r in 0..rows {
            for c in 0..cols {
                let uv = lo + (hi - lo) * Vec2::new((c as f32 + 0.5) / cols as f32, (r as f32 + 0.5) / rows as f32);
                let Some(piece) = piece_at(&coverage, uv) else {
                    dropped += 1;
                    continue;
                };
                out.push(Placement { piece, u: uv.x, v: uv.y, angle: cx.f32("angle"), scale: cx.f32("scale") });
            }
        }
        finish(cx, out, dropped, surface.as_deref());
        Ok(())
    }
}

pub static CURVE_PLACEMENT: NodeSpec = NodeSpec {
    kind: "CurvePlacement",
    category: Category::Attachment,
    doc: "Placements at equal arc-length steps along curves (buttons along a placket), turned to the curve direction: every `spacing` from each curve's start, or `count` evenly from its start to its end.",
    inputs: &[
        PortSpec::required("curves", PortType::Curves, "Curves in UV space."),
        PortSpec::optional(
            "surface",
            PortType::Surface,
            "Records each placement's piece and drops those off every piece.",
        ),
    ],
    outputs: &[PLACEMENTS, COUNT],
    params: &[
        ParamSpec::new(
            "spacing",
            ParamKind::Float { default: 0.05, min: 1e-5, max: 1.0 },
            "UV distance between placements (when count is 0).",
        ),
        ParamSpec::new(
            "count",
            ParamKind::Int { default: 0, min: 0, max: 1_000_000 },
            "Placements per curve, evenly spaced from its start to its end (1: its midpoint); 0: use spacing.",
        ),
        ParamSpec::new(
            "angle",
            ParamKind::Float { default: 0.0, min: -3600.0, max: 3600.0 },
            "Added rotation, degrees.",
        ),
        ParamSpec::new("scale", ParamKind::Float { default: 1.0, min: 0.0, max: 1e3 }, "Scale of each placement."),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(CurvePlacementNode),
};

struct CurvePlacementNode;
impl Node for CurvePlacementNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let curves: Arc<Curves> = cx.input("curves")?;
        let surface = surface_input(cx);
        let coverage = surface.as_deref().map(UvCoverage::new);
        let (spacing, count) = (cx.f32("spacing"), cx.int("count") as usize);
        let mut out = Vec::new();
        let mut dropped = 0;
        for path in &curves.paths {
            let table = ArcTable::new(path, 32);
            let arc_lengths: Vec<f32> = match count {
                0 => (0..=(table.length() / spacing).floor() as usize).map(|i| i as f32 * spacing).collect(),
                1 => vec![0.5 * table.length()],
                n => (0..n).map(|i| table.length() * i as f32 / (n - 1) as f32).collect(),
            };
            for s in arc_lengths {
                let (seg, t) = table.at(s);
                let p = bezier(&path[seg], t);
                // The tangent's direction, or its limit where a control point equals an end
                // point (common in SVG paths), where the tangent itself vanishes.
                let d = curve_direction(&path[seg], t);
                // Angle about the normal from +u towards +v, as point attachments read it.
                let angle = d.y.atan2(d.x).to_degrees() + cx.f32("angle");
                let Some(piece) = piece_at(&coverage, p) else {
                    dropped += 1;
                    continue;
                };
                out.push(Placement { piece, u: p.x, v: p.y, angle, scale: cx.f32("scale") });
            }
        }
        finish(cx, out, dropped, surface.as_deref());
        Ok(())
    }
}

pub static SURFACE_POINTS: NodeSpec = NodeSpec {
    kind: "SurfacePoints",
    category: Category::Attachment,
    doc: "Placements at the surface points nearest 3D points given in the surface's model space: a list, and/or a straight row of `count` points from `from` to `to`; each gets the UV and piece of its nearest point. A point farther than `max_distance` from the surface is an error naming it.",
    inputs: &[PortSpec::required("surface", PortType::Surface, "The surface to place on (its model space).")],
    outputs: &[PLACEMENTS, COUNT],
    params: &[
        ParamSpec::new("points", ParamKind::Text { default: "" }, "Points \"x y z\", separated by ';' or new lines."),
        ParamSpec::new("from", ParamKind::Vec3 { default: [0.0, 0.0, 0.0] }, "The row's first point."),
        ParamSpec::new("to", ParamKind::Vec3 { default: [0.0, 1.0, 0.0] }, "The row's last point."),
        ParamSpec::new(
            "count",
            ParamKind::Int { default: 0, min: 0, max: 100_000 },
            "Points in the row from `from` to `to`, evenly spaced (1: `from` alone); 0: no row.",
        ),
        ParamSpec::new(
            "max_distance",
            ParamKind::Float { default: 0.05, min: 0.0, max: 1e6 },
            "How far (model units) a point may be from the surface.",
        ),
        ParamSpec::new(
            "hold",
            ParamKind::Bool { default: true },
            "Keep the UVs found on the first evaluated surface while its vertex and triangle counts stay, so placements ride a moving surface instead of sliding to the points' nearest spots.",
        ),
        ParamSpec::new(
            "angle",
            ParamKind::Float { default: 0.0, min: -3600.0, max: 3600.0 },
            "Rotation about the normal, degrees.",
        ),
        ParamSpec::new("scale", ParamKind::Float { default: 1.0, min: 0.0, max: 1e3 }, "Scale of each placement."),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(SurfacePointsNode::default()),
};

#[derive(Default)]
struct SurfacePointsNode {
    /// The placements found, with the parameters and surface counts they were found for.
    held: Option<(String, Vec<Placement>)>,
}

impl Node for SurfacePointsNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let surface: Arc<Mesh> = cx.input("surface")?;
        let (from, to, count, max_distance) = (cx.vec3("from"), cx.vec3("to"), cx.int("count"), cx.f32("max_distance"));
        let (angle, scale) = (cx.f32("angle"), cx.f32("scale"));
        let key = format!(
            "{:?} {from} {to} {count} {max_distance} {angle} {scale} {} {}",
            cx.str("points"),
            surface.positions.len(),
            surface.indices.len()
        );
        if cx.bool("hold")
            && let Some((k, out)) = &self.held
            && *k == key
        {
            finish(cx, out.clone(), 0, None);
            return Ok(());
        }
        let mut points: Vec<(String, Vec3)> = landmarks::parse_points::<3>(cx.str("points"), "points")
            .map_err(NodeError::msg)?
            .into_iter()
            .enumerate()
            .map(|(i, p)| (format!("point {} of \"points\"", i + 1), Vec3::from(p)))
            .collect();
        let count = count as usize;
        for i in 0..count {
            let t = if count == 1 { 0.0 } else { i as f32 / (count - 1) as f32 };
            points.push((format!("row point {}", i + 1), from.lerp(to, t)));
        }
        if points.is_empty() {
            return Err(NodeError::msg("no points: write some in \"points\" or set a row's \"count\""));
        }
        let nearest = landmarks::NearestPoint::new(&surface);
        let mut out = Vec::with_capacity(points.len());
        for (name, p) in &points {
            let Some(hit) = nearest.nearest(*p, max_distance) else {
                let (lo, hi) = surface.bounds();
                let far = nearest.nearest(*p, (hi - lo).length() + p.distance(lo));
                return Err(NodeError::msg(format!(
                    "{name} ({}, {}, {}) is {} from the surface, farther than max_distance {max_distance}",
                    p.x,
                    p.y,
                    p.z,
                    far.map_or("far".to_string(), |h| format!("{:.4}", h.distance))
                )));
            };
            out.push(Placement { piece: hit.piece, u: hit.uv.x, v: hit.uv.y, angle, scale });
        }
        self.held = Some((key, out.clone()));
        finish(cx, out, 0, None);
        Ok(())
    }
}

pub static PLACEMENT_FILE: NodeSpec = NodeSpec {
    kind: "PlacementFile",
    category: Category::Attachment,
    doc: "Loads a designer's layout: CSV with a header `piece,u,v,angle,scale` (angle in degrees), or RON: a list of (piece, u, v, angle, scale). `coordinates: atlas`: u, v are packed-pattern UVs and, with a surface, the piece column is checked; `piece`: u, v run 0-1 across that piece's UV rectangle (needs the surface).",
    inputs: &[PortSpec::optional(
        "surface",
        PortType::Surface,
        "The surface whose pattern pieces the rows name: maps piece-local coordinates, checks atlas ones.",
    )],
    outputs: &[PLACEMENTS, COUNT],
    params: &[
        ParamSpec::new("path", ParamKind::Path { default: "", extensions: &["csv", "ron"] }, "The layout file."),
        ParamSpec::new(
            "coordinates",
            ParamKind::Choice { default: "atlas", options: Coordinates::OPTIONS },
            "What u, v mean: packed-pattern (atlas) UVs, or 0-1 across the row's piece (its UV bounding rectangle).",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(PlacementFileNode),
};

crate::choice!(
    pub enum Coordinates {
        Atlas = "atlas",
        Piece = "piece",
    }
);

struct PlacementFileNode;
impl Node for PlacementFileNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        if cx.str("path").is_empty() {
            return Err(NodeError::msg("parameter \"path\" is empty: name a .csv or .ron layout"));
        }
        let path = cx.path("path");
        let placements = cx.load(&path, load_placements)?;
        let surface = surface_input(cx);
        let piece_local = cx.choice::<Coordinates>("coordinates") == Coordinates::Piece;
        let Some(mesh) = surface.as_deref() else {
            if piece_local {
                return Err(NodeError::msg(
                    "coordinates: piece needs the surface input, whose pieces' UV rectangles the rows are relative to",
                ));
            }
            finish(cx, (*placements).clone(), 0, None);
            return Ok(());
        };
        let (out, dropped, mismatched) = place_on_pieces(&placements, mesh, piece_local).map_err(NodeError::msg)?;
        if mismatched > 0 {
            cx.warn(format!(
                "{mismatched} rows name a piece other than the one under their (u, v); with piece-local coordinates set coordinates: piece"
            ));
        }
        finish(cx, out, dropped, Some(mesh));
        Ok(())
    }
}

/// A layout's rows on `mesh`'s pieces: with `piece_local`, (u, v) maps from 0-1 across the
/// row's piece UV rectangle into the atlas; rows whose point no piece covers are dropped,
/// and rows whose piece column names another piece than the one under the point are
/// counted. Returns (placements, dropped, mismatched); an error names a row's unknown piece.
pub fn place_on_pieces(
    rows: &[Placement],
    mesh: &Mesh,
    piece_local: bool,
) -> Result<(Vec<Placement>, usize, usize), String> {
    let coverage = UvCoverage::new(mesh);
    let (mut out, mut dropped, mut mismatched) = (Vec::with_capacity(rows.len()), 0, 0);
    for (i, row) in rows.iter().enumerate() {
        let mut p = *row;
        if piece_local {
            let (lo, hi) = mesh.piece_uv_rect(row.piece).map_err(|e| format!("row {}: {e}", i + 1))?;
            let uv = lo + (hi - lo) * Vec2::new(row.u, row.v);
            (p.u, p.v) = (uv.x, uv.y);
        }
        match coverage.piece_at(Vec2::new(p.u, p.v)) {
            None => dropped += 1,
            Some(piece) => {
                if piece != row.piece {
                    mismatched += 1;
                }
                p.piece = piece;
                out.push(p);
            }
        }
    }
    Ok((out, dropped, mismatched))
}

/// Parses a placement file; errors name the file and line.
pub fn load_placements(path: &Path) -> anyhow::Result<Vec<Placement>> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let rows: Vec<(u32, f32, f32, f32, f32)> = if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("ron")) {
        ron::from_str(&text).map_err(|e| anyhow::anyhow!("{}:{}: {}", path.display(), e.span.start, e.code))?
    } else {
        let mut rows = Vec::new();
        for (i, line) in text.lines().enumerate() {
            let line = line.trim();
            let line = line.trim_start_matches('\u{feff}');
            if line.is_empty() || line.starts_with('#') || (i == 0 && line.starts_with("piece")) {
                continue;
            }
            let f: Vec<&str> = line.split(',').map(str::trim).collect();
            if f.len() != 5 {
                bail!("{}:{}: expected 5 fields piece,u,v,angle,scale, found {}", path.display(), i + 1, f.len());
            }
            let num = |k: usize| -> anyhow::Result<f32> {
                f[k].parse::<f32>().ok().filter(|x| x.is_finite()).with_context(|| {
                    format!("{}:{}: field {} (\"{}\") is not a number", path.display(), i + 1, k + 1, f[k])
                })
            };
            let piece = f[0]
                .parse::<u32>()
                .with_context(|| format!("{}:{}: piece \"{}\" is not a whole number", path.display(), i + 1, f[0]))?;
            rows.push((piece, num(1)?, num(2)?, num(3)?, num(4)?));
        }
        rows
    };
    rows.into_iter()
        .enumerate()
        .map(|(i, (piece, u, v, angle, scale))| {
            if !(angle.is_finite() && scale.is_finite() && scale > 0.0) {
                bail!(
                    "{}: placement {} needs a finite angle and a positive scale (found {angle}, {scale})",
                    path.display(),
                    i + 1
                );
            }
            if !(0.0..=1.0).contains(&u) || !(0.0..=1.0).contains(&v) {
                bail!("{}: placement {} has (u, v) = ({u}, {v}) outside [0, 1]", path.display(), i + 1);
            }
            Ok(Placement { piece, u, v, angle, scale })
        })
        .collect()
}

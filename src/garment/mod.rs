//! Sewing patterns from files, sewn into one cloth mesh (issue 28).
//!
//! Two readers make a [`Pattern`]: [`garmentcode`] (GarmentCode v2 JSON: panels with straight,
//! quadratic, cubic and circle edges, stitches, 3D placement) and [`freesewing`] (a FreeSewing
//! SVG plus a RON sidecar naming the seams, which the SVG does not carry). A pattern is panels
//! whose outlines are loops of edges, each edge a densely flattened polyline in centimetres, and
//! stitches pairing whole edges. [`Pattern::sew`] resamples every edge by arc length at a target
//! length (a stitched pair gets the count of the longer edge, so both sides have equal vertex
//! counts), triangulates the panels into one [`PatternMesh`] whose seams are the stitched vertex
//! pairs, and places each vertex in 3D by its panel's placement; [`sleeves`] then slides the
//! sleeves along the body's arms. See docs/garments.md.

pub mod curve;
pub mod drape;
pub mod freesewing;
pub mod garmentcode;
pub mod sleeves;

use glam::{DMat3, DVec2, DVec3, Vec2, Vec3};

use crate::cloth::{EdgeRef, PatternError, PatternMesh, Piece, Seam};

/// What went wrong with a pattern file: each names the file and, where it applies, the panel,
/// edge and stitch.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum GarmentError {
    #[error("{file}: {message}")]
    Format { file: String, message: String },
    #[error("{file}: stitch {stitch} names panel \"{panel}\", which the pattern does not have")]
    MissingPanel { file: String, stitch: usize, panel: String },
    #[error("{file}: stitch {stitch} names edge {edge} of panel \"{panel}\", which has {count} edges (0 to {})", count.saturating_sub(1))]
    MissingEdge { file: String, stitch: usize, panel: String, edge: usize, count: usize },
    #[error("{file}: edge {edge} of panel \"{panel}\" is stitched twice, in stitches {first} and {second}")]
    StitchedTwice { file: String, panel: String, edge: usize, first: usize, second: usize },
    #[error("{file}: stitch {stitch} sews edge {edge} of panel \"{panel}\" to itself")]
    StitchedToItself { file: String, stitch: usize, panel: String, edge: usize },
    #[error("{file}: panel \"{panel}\" is empty: {why}")]
    EmptyPanel { file: String, panel: String, why: String },
    #[error("{file}: panel \"{panel}\" intersects itself: edge {a} crosses edge {b}")]
    SelfIntersecting { file: String, panel: String, a: usize, b: usize },
    #[error("{file}: panel \"{panel}\", edge {edge}: {message}")]
    BadEdge { file: String, panel: String, edge: usize, message: String },
    #[error("{file}: {message}")]
    Mesh { file: String, message: String },
}

/// One edge of a panel outline: a polyline (centimetres) from its start corner to its end
/// corner, which is the next edge's start.
#[derive(Clone, Debug, PartialEq)]
pub struct Edge {
    /// The edge's number in the file (for messages; a reader may reorder edges).
    pub id: usize,
    pub points: Vec<DVec2>,
    /// The file's label for the edge (GarmentCode: `lower_interface`, collars, ...).
    pub label: Option<String>,
}

impl Edge {
    pub fn length(&self) -> f64 {
        curve::polyline_length(&self.points)
    }
}

/// Where a panel sits: a world point (centimetres) is `rotation * (x, y, 0) + translation`.
/// `rotation` may include a mirror (a reader flips a panel so its outline runs counter-clockwise).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Placement {
    pub rotation: DMat3,
    pub translation: DVec3,
}

impl Placement {
    pub fn apply(&self, p: DVec2) -> DVec3 {
        self.rotation * DVec3::new(p.x, p.y, 0.0) + self.translation
    }
}

/// A flat pattern piece: a counter-clockwise loop of edges, placed in 3D.
#[derive(Clone, Debug, PartialEq)]
pub struct Panel {
    pub name: String,
    pub edges: Vec<Edge>,
    pub placement: Placement,
    /// Body part the panel belongs to, where the file says (GarmentCode `label`).
    pub label: Option<String>,
    /// Button marks (centimetres, in the panel's frame), where the file has them (FreeSewing
    /// `#button` snippets).
    pub buttons: Vec<DVec2>,
}

impl Panel {
    /// The file's edge number `id` as an index into `edges`.
    pub fn edge_index(&self, id: usize) -> Option<usize> {
        self.edges.iter().position(|e| e.id == id)
    }

    /// The outline as one closed polyline (no repeated first point), with the edge index of
    /// each segment.
    fn outline(&self) -> (Vec<DVec2>, Vec<usize>) {
        let mut pts = Vec::new();
        let mut owner = Vec::new();
        for (i, e) in self.edges.iter().enumerate() {
            let n = e.points.len().saturating_sub(1);
            for p in &e.points[..n] {
                // Repeated points (a Bézier whose control point is its end) would make
                // zero-length segments that touch their neighbours' neighbours.
                if pts.last().is_none_or(|q: &DVec2| q.distance(*p) > 1e-9) {
                    pts.push(*p);
                    owner.push(i);
                }
            }
        }
        while pts.len() > 1 && pts[0].distance(*pts.last().unwrap()) <= 1e-9 {
            pts.pop();
            owner.pop();
        }
        (pts, owner)
    }

    /// Signed area (cm², positive when counter-clockwise) of the flattened outline.
    pub fn signed_area(&self) -> f64 {
        let (p, _) = self.outline();
        0.5 * (0..p.len()).map(|i| p[i].perp_dot(p[(i + 1) % p.len()])).sum::<f64>()
    }
}

/// Two whole edges sewn together, by index into the panels and their edges.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Stitch {
    pub a: (usize, usize),
    pub b: (usize, usize),
    /// The end of `a` meets the start of `b` (GarmentCode's default: right side to right side
    /// for two counter-clockwise panels); otherwise the starts meet.
    pub end_to_start: bool,
}

/// A sewing pattern read from a file.
#[derive(Clone, Debug, PartialEq)]
pub struct Pattern {
    /// The file it came from (for messages).
    pub file: String,
    pub panels: Vec<Panel>,
    pub stitches: Vec<Stitch>,
}

/// Stitched edges whose lengths differ by more than this fraction of the longer one get a
/// warning: sewing stretches the shorter one (a gathered or eased seam is meant to differ a
/// little; GarmentCode's own patterns stay within 1 %).
pub const LENGTH_MISMATCH_WARNING: f64 = 0.05;

/// How the pattern's placement is fitted to the body it is sewn on: a world point (metres) is
/// `(scale * p + offset) / 100` for a placed pattern point `p` in centimetres (`scale` per axis).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Fit {
    pub scale: DVec3,
    /// Centimetres, after scaling.
    pub offset: DVec3,
}

impl Fit {
    /// GarmentCode's placements on MakeHuman, as the `Garment` node takes them by default:
    /// scaled from GarmentCode's 172 cm body to MakeHuman's 166.6 cm, and 3 cm forward, which
    /// centres the panels on MakeHuman's chest.
    pub const ON_MAKEHUMAN: Fit = Fit { scale: DVec3::splat(0.969), offset: DVec3::new(0.0, 0.0, 3.0) };
}

impl Default for Fit {
    fn default() -> Self {
        Fit { scale: DVec3::ONE, offset: DVec3::ZERO }
    }
}

/// A sewn pattern: the cloth mesh (rest shapes from the flat panels, seams from the stitches)
/// and where each vertex starts in 3D.
#[derive(Clone, Debug)]
pub struct Sewn {
    pub mesh: PatternMesh,
    /// Start positions (metres), one per mesh vertex.
    pub positions: Vec<Vec3>,
    /// Panel names, by piece id.
    pub piece_names: Vec<String>,
    /// `[panel][edge]`: the mesh vertices along the edge, start to end.
    pub edge_vertices: Vec<Vec<Vec<u32>>>,
    /// Per stitch: its two edges' vertices in the order they are sewn (`a[k]` meets `b[k]`).
    pub stitched: Vec<(Vec<u32>, Vec<u32>)>,
    /// Warnings about the pattern (stitched edges of different lengths).
    pub warnings: Vec<String>,
    /// The panels' button marks in the UV atlas: (piece id, UV), v down.
    pub buttons: Vec<(u32, Vec2)>,
}

impl Pattern {
    fn panel_edge(&self, (p, e): (usize, usize)) -> (&str, usize) {
        (&self.panels[p].name, self.panels[p].edges[e].id)
    }

    /// Checks the pattern: no panel empty or self-intersecting, no edge stitched twice or to
    /// itself. Returns warnings for stitched edges of very different lengths.
    pub fn validate(&self) -> Result<Vec<String>, GarmentError> {
        let file = || self.file.clone();
        if self.panels.is_empty() {
            return Err(GarmentError::Format { file: file(), message: "the pattern has no panels".into() });
        }
        for panel in &self.panels {
            let empty = |why: String| GarmentError::EmptyPanel { file: file(), panel: panel.name.clone(), why };
            if panel.edges.len() < 2 {
                return Err(empty(format!("{} edge(s)", panel.edges.len())));
            }
            let area = panel.signed_area();
            let (pts, owner) = panel.outline();
            if pts.len() < 3 || area.is_nan() || area.abs() <= 1e-6 {
                return Err(empty(format!("its outline encloses no area ({area:.3} cm²)")));
            }
            for (i, e) in panel.edges.iter().enumerate() {
                let next = &panel.edges[(i + 1) % panel.edges.len()];
                if e.points.len() < 2 || e.points.iter().any(|p| !p.is_finite()) {
                    return Err(GarmentError::BadEdge {
                        file: file(),
                        panel: panel.name.clone(),
                        edge: e.id,
                        message: "no finite points".into(),
                    });
                }
                if e.points.last().unwrap().distance(next.points[0]) > 1e-6 {
                    return Err(GarmentError::BadEdge {
                        file: file(),
                        panel: panel.name.clone(),
                        edge: e.id,
                        message: format!(
                            "its end is not the start of edge {}: the outline is not a closed loop",
                            next.id
                        ),
                    });
                }
            }
            if let Some((a, b)) = curve::first_crossing(&pts, &owner) {
                return Err(GarmentError::SelfIntersecting {
                    file: file(),
                    panel: panel.name.clone(),
                    a: panel.edges[a].id,
                    b: panel.edges[b].id,
                });
            }
        }
        let mut used: std::collections::BTreeMap<(usize, usize), usize> = Default::default();
        let mut warnings = Vec::new();
        for (k, s) in self.stitches.iter().enumerate() {
            if s.a == s.b {
                let (panel, edge) = self.panel_edge(s.a);
                return Err(GarmentError::StitchedToItself { file: file(), stitch: k, panel: panel.into(), edge });
            }
            for side in [s.a, s.b] {
                if let Some(first) = used.insert(side, k) {
                    let (panel, edge) = self.panel_edge(side);
                    return Err(GarmentError::StitchedTwice {
                        file: file(),
                        panel: panel.into(),
                        edge,
                        first,
                        second: k,
                    });
                }
            }
            let la = self.panels[s.a.0].edges[s.a.1].length();
            let lb = self.panels[s.b.0].edges[s.b.1].length();
            if (la - lb).abs() > LENGTH_MISMATCH_WARNING * la.max(lb) {
                let ((pa, ea), (pb, eb)) = (self.panel_edge(s.a), self.panel_edge(s.b));
                warnings.push(format!(
                    "{}: stitch {k} sews edge {ea} of panel \"{pa}\" ({la:.1} cm) to edge {eb} of panel \"{pb}\" ({lb:.1} cm): lengths differ by {:.0} %",
                    self.file,
                    100.0 * (la - lb).abs() / la.max(lb)
                ));
            }
        }
        Ok(warnings)
    }

    /// Sews the pattern at a target edge length of `edge_length` cm: see the module docs.
    pub fn sew(&self, edge_length: f64, fit: Fit) -> Result<Sewn, GarmentError> {
        let warnings = self.validate()?;
        let mesh_err = |message: String| GarmentError::Mesh { file: self.file.clone(), message };
        if !(edge_length.is_finite() && edge_length > 0.0) {
            return Err(mesh_err(format!("the target edge length must be positive, not {edge_length}")));
        }
        // Segments per edge: at most `edge_length` long; a stitched pair takes the longer edge's.
        let mut counts: Vec<Vec<usize>> = self
            .panels
            .iter()
            .map(|p| p.edges.iter().map(|e| ((e.length() / edge_length).ceil() as usize).max(1)).collect())
            .collect();
        for s in &self.stitches {
            let la = self.panels[s.a.0].edges[s.a.1].length();
            let lb = self.panels[s.b.0].edges[s.b.1].length();
            let n = if la >= lb { counts[s.a.0][s.a.1] } else { counts[s.b.0][s.b.1] };
            counts[s.a.0][s.a.1] = n;
            counts[s.b.0][s.b.1] = n;
        }
        // Outlines: each edge's start corner and its interior samples; `first[p][e]` is the
        // outline index of edge e's start.
        let mut pieces = Vec::with_capacity(self.panels.len());
        let mut first: Vec<Vec<usize>> = Vec::with_capacity(self.panels.len());
        for (pi, panel) in self.panels.iter().enumerate() {
            let mut outline: Vec<Vec2> = Vec::new();
            let mut starts = Vec::with_capacity(panel.edges.len());
            for (ei, e) in panel.edges.iter().enumerate() {
                starts.push(outline.len());
                let samples = curve::resample(&e.points, counts[pi][ei]);
                outline.extend(samples[..samples.len() - 1].iter().map(|p| p.as_vec2()));
            }
            pieces.push(Piece::new(panel.name.clone(), outline));
            first.push(starts);
        }
        let mut seams = Vec::new();
        for s in &self.stitches {
            let n = counts[s.a.0][s.a.1];
            for k in 0..n {
                let a = EdgeRef { piece: s.a.0, edge: first[s.a.0][s.a.1] + k };
                let b = if s.end_to_start {
                    EdgeRef { piece: s.b.0, edge: first[s.b.0][s.b.1] + n - 1 - k }
                } else {
                    EdgeRef { piece: s.b.0, edge: first[s.b.0][s.b.1] + k }
                };
                seams.push(Seam { a, b, reversed: s.end_to_start });
            }
        }
        let mesh = PatternMesh::build_sampled(pieces, seams, edge_length as f32).map_err(|e| match e {
            PatternError::NotSimple(p) | PatternError::NotCounterClockwise(p) | PatternError::TooFewCorners(p) => {
                mesh_err(format!(
                    "panel \"{}\" cannot be triangulated at {edge_length} cm edges: {e}",
                    self.panels[p].name
                ))
            }
            other => mesh_err(other.to_string()),
        })?;

        let edge_vertices: Vec<Vec<Vec<u32>>> = self
            .panels
            .iter()
            .enumerate()
            .map(|(pi, panel)| {
                let chains = &mesh.piece_meshes()[pi].edge_chains;
                (0..panel.edges.len())
                    .map(|ei| {
                        let start = first[pi][ei];
                        let mut v: Vec<u32> = (0..counts[pi][ei]).map(|k| chains[start + k][0]).collect();
                        v.push(*chains[start + counts[pi][ei] - 1].last().expect("a chain has two ends"));
                        v
                    })
                    .collect()
            })
            .collect();
        let stitched = self
            .stitches
            .iter()
            .map(|s| {
                let a = edge_vertices[s.a.0][s.a.1].clone();
                let mut b = edge_vertices[s.b.0][s.b.1].clone();
                if s.end_to_start {
                    b.reverse();
                }
                (a, b)
            })
            .collect();

        let mut positions = Vec::with_capacity(mesh.vertex_count());
        for (v, rest) in mesh.rest_positions().iter().enumerate() {
            let panel = &self.panels[mesh.piece_ids()[v] as usize];
            let p = panel.placement.apply(rest.as_dvec2());
            positions.push(((p * fit.scale + fit.offset) * 0.01).as_vec3());
        }
        // A panel point goes into the atlas as its rest positions do (`PatternMesh::pack_atlas`):
        // from the piece's box, y mirrored to v down, at the atlas scale.
        let mut buttons = Vec::new();
        for (pi, panel) in self.panels.iter().enumerate() {
            let pm = &mesh.piece_meshes()[pi];
            let rest = &mesh.rest_positions()[pm.vertices.start as usize..pm.vertices.end as usize];
            let (lo, hi) = rest.iter().fold((rest[0], rest[0]), |(lo, hi), &p| (lo.min(p), hi.max(p)));
            for b in &panel.buttons {
                let local = Vec2::new(b.x as f32 - lo.x, hi.y - b.y as f32);
                buttons.push((pi as u32, pm.uv_min + local * mesh.uv_per_cm()));
            }
        }
        Ok(Sewn {
            buttons,
            piece_names: self.panels.iter().map(|p| p.name.clone()).collect(),
            mesh,
            positions,
            edge_vertices,
            stitched,
            warnings,
        })
    }
}

/// The rotation `Rz(z) Ry(y) Rx(x)` of XYZ Euler angles in degrees (GarmentCode's convention,
/// `pygarment/pattern/rotation.py` `euler_xyz_to_R`).
pub fn euler_xyz_degrees(angles: DVec3) -> DMat3 {
    let r = angles * (std::f64::consts::PI / 180.0);
    DMat3::from_rotation_z(r.z) * DMat3::from_rotation_y(r.y) * DMat3::from_rotation_x(r.x)
}

/// Mirrors a panel across its local y axis (x -> -x) without moving it in 3D: the outline's
/// orientation flips, the placement absorbs the mirror.
pub(crate) fn mirror_panel(panel: &mut Panel) {
    for e in &mut panel.edges {
        for p in &mut e.points {
            p.x = -p.x;
        }
    }
    panel.placement.rotation *= DMat3::from_diagonal(DVec3::new(-1.0, 1.0, 1.0));
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn euler_angles_compose_as_rz_ry_rx() {
        // pygarment's euler_xyz_to_R: Rz(z) Ry(y) Rx(x). With x = 90 and y = 90 degrees, +y goes
        // to +z under Rx, then +z to +x under Ry; the opposite order would give +z.
        let r = euler_xyz_degrees(DVec3::new(90.0, 90.0, 0.0));
        assert!((r * DVec3::Y).distance(DVec3::X) < 1e-12, "{}", r * DVec3::Y);
        let r = euler_xyz_degrees(DVec3::new(0.0, 90.0, 90.0));
        // Ry(90) takes +x to -z; Rz leaves z alone.
        assert!((r * DVec3::X).distance(-DVec3::Z) < 1e-12, "{}", r * DVec3::X);
        assert!((r * DVec3::Z).distance(DVec3::Y) < 1e-12, "{}", r * DVec3::Z);
    }
}

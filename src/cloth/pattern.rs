//! Flat sewing patterns: pieces, their triangulation, the UV atlas and seams.
//!
//! Pattern coordinates are centimetres. A piece's UVs are its pattern
//! coordinates under one uniform scale shared by all pieces plus a per-piece
//! offset, so texture density is the same on every piece and aspect ratios
//! are preserved.

use std::fmt;
use std::ops::Range;

use glam::{DVec2, Vec2};

use super::triangulate::{TriangulateError, Triangulator};

/// One flat pattern piece.
#[derive(Clone, Debug, PartialEq)]
pub struct Piece {
    pub name: String,
    /// Simple polygon in centimetres, counter-clockwise, without a repeated
    /// closing corner. Edge `i` runs from corner `i` to corner `i + 1`.
    pub outline: Vec<Vec2>,
}

impl Piece {
    pub fn new(name: impl Into<String>, outline: Vec<Vec2>) -> Self {
        Piece { name: name.into(), outline }
    }

    /// Shoelace area in cm² (positive for CCW outlines).
    pub fn area(&self) -> f32 {
        let o = &self.outline;
        let n = o.len();
        0.5 * (0..n).map(|i| o[i].perp_dot(o[(i + 1) % n])).sum::<f32>()
    }

    fn edge(&self, i: usize) -> (Vec2, Vec2) {
        (self.outline[i], self.outline[(i + 1) % self.outline.len()])
    }
}

/// An outline edge of a piece.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord)]
pub struct EdgeRef {
    pub piece: usize,
    pub edge: usize,
}

/// Sews edge `a` to edge `b`. Without `reversed`, the start corners of both
/// edges meet; with it, the start of `a` meets the end of `b` (the usual case
/// for two CCW pieces laid side by side).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Seam {
    pub a: EdgeRef,
    pub b: EdgeRef,
    pub reversed: bool,
}

#[derive(Debug, Clone, PartialEq)]
pub enum PatternError {
    NoPieces,
    BadEdgeLength,
    /// The piece's outline has fewer than three corners.
    TooFewCorners(usize),
    /// The piece's outline is clockwise or has zero area.
    NotCounterClockwise(usize),
    /// The piece's outline self-intersects.
    NotSimple(usize),
    /// A seam names a piece or edge that does not exist, or sews an edge to itself.
    BadSeam(usize),
    /// Internal failure to place a point inside the piece (should not happen
    /// for valid outlines).
    Triangulation(usize),
}

impl fmt::Display for PatternError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            PatternError::NoPieces => write!(f, "pattern has no pieces"),
            PatternError::BadEdgeLength => {
                write!(f, "target edge length must be positive and finite")
            }
            PatternError::TooFewCorners(p) => write!(f, "piece {p} has fewer than 3 corners"),
            PatternError::NotCounterClockwise(p) => write!(f, "piece {p} is not counter-clockwise"),
            PatternError::NotSimple(p) => write!(f, "piece {p} self-intersects"),
            PatternError::BadSeam(s) => write!(f, "seam {s} references an invalid edge"),
            PatternError::Triangulation(p) => write!(f, "triangulation of piece {p} failed"),
        }
    }
}

impl std::error::Error for PatternError {}

/// Per-piece bookkeeping of a [`PatternMesh`].
#[derive(Clone, Debug)]
pub struct PieceMesh {
    /// Global vertex ids of this piece.
    pub vertices: Range<u32>,
    /// Global triangle ids of this piece.
    pub triangles: Range<u32>,
    /// For each outline edge `i`, the global vertex ids from corner `i` to
    /// corner `i + 1` inclusive, in boundary order.
    pub edge_chains: Vec<Vec<u32>>,
    /// UV rectangle of the piece's bounding box in the atlas.
    pub uv_min: Vec2,
    pub uv_max: Vec2,
}

/// Triangulated pattern with its UV atlas and seam vertex pairs.
#[derive(Clone, Debug)]
pub struct PatternMesh {
    pieces: Vec<Piece>,
    seams: Vec<Seam>,
    rest: Vec<Vec2>,
    uvs: Vec<Vec2>,
    piece_ids: Vec<u32>,
    triangles: Vec<[u32; 3]>,
    piece_meshes: Vec<PieceMesh>,
    seam_pairs: Vec<[u32; 2]>,
    edge_length: f32,
    uv_per_cm: f32,
}

/// Area of an equilateral triangle with unit edges.
const EQUILATERAL_AREA: f32 = 0.433_012_7;

impl PatternMesh {
    /// Target edge length (cm) that gives roughly `triangles` triangles over
    /// the total pattern area.
    pub fn edge_length_for(pieces: &[Piece], triangles: usize) -> f32 {
        let area: f32 = pieces.iter().map(Piece::area).sum();
        (area / (triangles.max(1) as f32 * EQUILATERAL_AREA)).sqrt()
    }

    /// Triangulates every piece with roughly equilateral triangles of edge
    /// `edge_length` cm, packs the UV atlas and pairs the seam vertices.
    pub fn build(pieces: Vec<Piece>, seams: Vec<Seam>, edge_length: f32) -> Result<Self, PatternError> {
        Self::check(&pieces, &seams, edge_length)?;
        let segments = segment_counts(&pieces, &seams, edge_length);
        Self::build_segmented(pieces, seams, edge_length, segments)
    }

    /// Like [`PatternMesh::build`], but every outline edge is one boundary segment: for
    /// outlines that are already sampled at the target edge length (curved edges resampled by
    /// arc length, `crate::garment`). Sewn outline edges pair one-to-one.
    pub fn build_sampled(pieces: Vec<Piece>, seams: Vec<Seam>, edge_length: f32) -> Result<Self, PatternError> {
        Self::check(&pieces, &seams, edge_length)?;
        let segments = pieces.iter().map(|p| vec![1; p.outline.len()]).collect();
        Self::build_segmented(pieces, seams, edge_length, segments)
    }

    fn check(pieces: &[Piece], seams: &[Seam], edge_length: f32) -> Result<(), PatternError> {
        if pieces.is_empty() {
            return Err(PatternError::NoPieces);
        }
        if !(edge_length.is_finite() && edge_length > 0.0) {
            return Err(PatternError::BadEdgeLength);
        }
        for (i, s) in seams.iter().enumerate() {
            let ok = |e: EdgeRef| e.piece < pieces.len() && e.edge < pieces[e.piece].outline.len();
            if !ok(s.a) || !ok(s.b) || s.a == s.b {
                return Err(PatternError::BadSeam(i));
            }
        }
        Ok(())
    }

    fn build_segmented(
        pieces: Vec<Piece>,
        seams: Vec<Seam>,
        edge_length: f32,
        segments: Vec<Vec<usize>>,
    ) -> Result<Self, PatternError> {
        let mut mesh = PatternMesh {
            pieces: Vec::new(),
            seams: seams.clone(),
            rest: Vec::new(),
            uvs: Vec::new(),
            piece_ids: Vec::new(),
            triangles: Vec::new(),
            piece_meshes: Vec::new(),
            seam_pairs: Vec::new(),
            edge_length,
            uv_per_cm: 0.0,
        };
        for (pi, piece) in pieces.iter().enumerate() {
            let local = triangulate_piece(piece, &segments[pi], edge_length as f64).map_err(|e| match e {
                TriangulateError::TooFewCorners => PatternError::TooFewCorners(pi),
                TriangulateError::NotCounterClockwise => PatternError::NotCounterClockwise(pi),
                TriangulateError::NotSimple => PatternError::NotSimple(pi),
                TriangulateError::PointOutside => PatternError::Triangulation(pi),
            })?;
            let v0 = mesh.rest.len() as u32;
            let t0 = mesh.triangles.len() as u32;
            mesh.rest.extend(local.points.iter().map(|p| p.as_vec2()));
            mesh.piece_ids.extend(std::iter::repeat_n(pi as u32, local.points.len()));
            mesh.triangles.extend(local.triangles.iter().map(|t| t.map(|i| i + v0)));
            mesh.piece_meshes.push(PieceMesh {
                vertices: v0..mesh.rest.len() as u32,
                triangles: t0..mesh.triangles.len() as u32,
                edge_chains: local.edge_chains.iter().map(|c| c.iter().map(|i| i + v0).collect()).collect(),
                uv_min: Vec2::ZERO,
                uv_max: Vec2::ZERO,
            });
        }
        mesh.pieces = pieces;
        mesh.pack_atlas();
        mesh.pair_seams();
        Ok(mesh)
    }

    /// The topology of a garment that exists only in 3D (a fitted proxy, an OBJ from another
    /// tool), for [`super::Cloth::new_shaped`], whose rest shape is its start positions: no
    /// pieces, seams or flat rest coordinates (`rest_positions` is empty), one UV and piece id
    /// per vertex. `edge_length` (cm) is the mesh's typical edge.
    pub fn shaped(triangles: Vec<[u32; 3]>, uvs: Vec<Vec2>, piece_ids: Vec<u32>, edge_length: f32) -> Self {
        assert_eq!(uvs.len(), piece_ids.len(), "one UV and piece id per vertex");
        assert!(triangles.iter().flatten().all(|&i| (i as usize) < uvs.len()), "triangle index out of range");
        PatternMesh {
            pieces: Vec::new(),
            seams: Vec::new(),
            rest: Vec::new(),
            uvs,
            piece_ids,
            triangles,
            piece_meshes: Vec::new(),
            seam_pairs: Vec::new(),
            edge_length,
            uv_per_cm: 0.0,
        }
    }

    pub fn pieces(&self) -> &[Piece] {
        &self.pieces
    }
    pub fn seams(&self) -> &[Seam] {
        &self.seams
    }
    /// Per-vertex pattern coordinates (cm, in the piece's own frame); empty for a
    /// [`PatternMesh::shaped`] mesh.
    pub fn rest_positions(&self) -> &[Vec2] {
        &self.rest
    }
    /// Per-vertex atlas coordinates in [0,1]².
    pub fn uvs(&self) -> &[Vec2] {
        &self.uvs
    }
    pub fn piece_ids(&self) -> &[u32] {
        &self.piece_ids
    }
    /// Triangles, CCW in pattern space.
    pub fn triangles(&self) -> &[[u32; 3]] {
        &self.triangles
    }
    pub fn piece_meshes(&self) -> &[PieceMesh] {
        &self.piece_meshes
    }
    /// Vertex pairs joined by seams, each `[lower id, higher id]`, sorted.
    pub fn seam_pairs(&self) -> &[[u32; 2]] {
        &self.seam_pairs
    }
    /// The target edge length the mesh was built with (cm).
    pub fn edge_length(&self) -> f32 {
        self.edge_length
    }
    /// Atlas scale: UV units per centimetre, the same for every piece.
    pub fn uv_per_cm(&self) -> f32 {
        self.uv_per_cm
    }
    pub fn vertex_count(&self) -> usize {
        self.uvs.len()
    }

    /// Shelf packing of the piece bounding boxes. The shelf width is chosen
    /// among the prefix sums of the (height-sorted) widths so that the
    /// square atlas is filled best; the scale is then uniform.
    fn pack_atlas(&mut self) {
        let boxes: Vec<(Vec2, Vec2)> = self
            .piece_meshes
            .iter()
            .map(|pm| {
                let r = &self.rest[pm.vertices.start as usize..pm.vertices.end as usize];
                r.iter().fold((r[0], r[0]), |(lo, hi), &p| (lo.min(p), hi.max(p)))
            })
            .collect();
        let sizes: Vec<Vec2> = boxes.iter().map(|(lo, hi)| *hi - *lo).collect();
        let largest = sizes.iter().fold(0.0f32, |m, s| m.max(s.max_element()));
        let gutter = 0.02 * largest;
        let mut order: Vec<usize> = (0..sizes.len()).collect();
        order.sort_by(|&a, &b| sizes[b].y.total_cmp(&sizes[a].y).then(a.cmp(&b)));
        let max_w = sizes.iter().fold(0.0f32, |m, s| m.max(s.x));

        let shelf = |width: f32| -> (Vec<Vec2>, f32) {
            let mut offsets = vec![Vec2::ZERO; sizes.len()];
            let (mut x, mut y, mut row_h, mut used_w) = (0.0f32, 0.0f32, 0.0f32, 0.0f32);
            for &i in &order {
                let s = sizes[i];
                if x > 0.0 && x + s.x > width {
                    y += row_h + gutter;
                    x = 0.0;
                    row_h = 0.0;
                }
                offsets[i] = Vec2::new(x, y);
                used_w = used_w.max(x + s.x);
                x += s.x + gutter;
                row_h = row_h.max(s.y);
            }
            (offsets, used_w.max(y + row_h))
        };
        let mut best: Option<(Vec<Vec2>, f32)> = None;
        let mut width = 0.0f32;
        for &i in &order {
            width += sizes[i].x + if width > 0.0 { gutter } else { 0.0 };
            let candidate = shelf(width.max(max_w));
            if best.as_ref().is_none_or(|b| candidate.1 < b.1) {
                best = Some(candidate);
            }
        }
        let (offsets, extent) = best.expect("at least one piece");
        let scale = 1.0 / (extent + 2.0 * gutter);
        self.uv_per_cm = scale;
        self.uvs = vec![Vec2::ZERO; self.rest.len()];
        for (pi, pm) in self.piece_meshes.iter_mut().enumerate() {
            let origin = (Vec2::splat(gutter) + offsets[pi]) * scale;
            for v in pm.vertices.clone() {
                // Pattern y points up, texture v down (as OBJ's v is flipped on load): mirror
                // within the piece's box so (t_u, n, t_v) is right-handed with n = t_v x t_u,
                // the frame deferred warping needs to attach geometry unmirrored.
                let r = self.rest[v as usize];
                let local = Vec2::new(r.x - boxes[pi].0.x, boxes[pi].1.y - r.y);
                let uv = origin + local * scale;
                // Guard against the last ulp of rounding at the atlas border.
                self.uvs[v as usize] = uv.clamp(Vec2::ZERO, Vec2::ONE);
            }
            pm.uv_min = origin;
            pm.uv_max = (origin + sizes[pi] * scale).min(Vec2::ONE);
        }
    }

    /// Segment counts of sewn edges are equalised before meshing, so seam
    /// chains pair one-to-one.
    fn pair_seams(&mut self) {
        let mut pairs = Vec::new();
        for s in &self.seams {
            let ca = &self.piece_meshes[s.a.piece].edge_chains[s.a.edge];
            let cb = &self.piece_meshes[s.b.piece].edge_chains[s.b.edge];
            debug_assert_eq!(ca.len(), cb.len());
            let n = ca.len();
            for (k, &va) in ca.iter().enumerate() {
                let vb = if s.reversed { cb[n - 1 - k] } else { cb[k] };
                if va != vb {
                    pairs.push([va.min(vb), va.max(vb)]);
                }
            }
        }
        pairs.sort_unstable();
        pairs.dedup();
        self.seam_pairs = pairs;
    }
}

/// Number of boundary segments for every outline edge: about one per target
/// edge length, made equal across each seam (and transitively along chains
/// of seams).
fn segment_counts(pieces: &[Piece], seams: &[Seam], h: f32) -> Vec<Vec<usize>> {
    let mut counts: Vec<Vec<usize>> = pieces
        .iter()
        .map(|p| {
            (0..p.outline.len())
                .map(|i| {
                    let (a, b) = p.edge(i);
                    ((a.distance(b) / h).round() as usize).max(1)
                })
                .collect()
        })
        .collect();
    let mut changed = true;
    while changed {
        changed = false;
        for s in seams {
            let (a, b) = (counts[s.a.piece][s.a.edge], counts[s.b.piece][s.b.edge]);
            if a != b {
                let m = a.max(b);
                counts[s.a.piece][s.a.edge] = m;
                counts[s.b.piece][s.b.edge] = m;
                changed = true;
            }
        }
    }
    counts
}

struct LocalMesh {
    points: Vec<DVec2>,
    triangles: Vec<[u32; 3]>,
    edge_chains: Vec<Vec<u32>>,
}

/// Outline corners, evenly subdivided outline edges and a hexagonal lattice
/// of interior points (dropped within half an edge of the boundary), joined
/// by a constrained Delaunay triangulation.
fn triangulate_piece(piece: &Piece, segments: &[usize], h: f64) -> Result<LocalMesh, TriangulateError> {
    let outline: Vec<DVec2> = piece.outline.iter().map(|p| p.as_dvec2()).collect();
    let m = outline.len();
    let mut tri = Triangulator::new(&outline)?;

    let mut edge_chains = Vec::with_capacity(m);
    for (i, &n) in segments.iter().enumerate() {
        let (a, b) = (outline[i], outline[(i + 1) % m]);
        let (ia, ib) = (i as u32, ((i + 1) % m) as u32);
        let mut chain = vec![ia];
        // Each new point splits the boundary edge (previous point, b).
        let mut prev = ia;
        for k in 1..n {
            let p = a.lerp(b, k as f64 / n as f64);
            prev = tri.insert_on_boundary(p, prev, ib)?;
            chain.push(prev);
        }
        chain.push(ib);
        edge_chains.push(chain);
    }

    let (lo, hi) = outline.iter().fold((outline[0], outline[0]), |(lo, hi), &p| (lo.min(p), hi.max(p)));
    let dy = h * 3f64.sqrt() / 2.0;
    let (nx, ny) = (((hi.x - lo.x) / h) as i64, ((hi.y - lo.y) / dy) as i64);
    // Centre the lattice in the bounding box so symmetric pieces get
    // symmetric meshes.
    let x0 = lo.x + 0.5 * ((hi.x - lo.x) - nx as f64 * h) - 0.25 * h;
    let y0 = lo.y + 0.5 * ((hi.y - lo.y) - ny as f64 * dy);
    let margin = 0.5 * h;
    for j in 0..=ny {
        let y = y0 + j as f64 * dy;
        let shift = if j % 2 == 0 { 0.0 } else { 0.5 * h };
        // Serpentine order keeps consecutive points adjacent for the walk.
        for i in 0..=nx + 1 {
            let i = if j % 2 == 0 { i } else { nx + 1 - i };
            let p = DVec2::new(x0 + i as f64 * h + shift, y);
            if inside(&outline, p) && boundary_distance(&outline, p) >= margin {
                tri.insert_interior(p)?;
            }
        }
    }

    let points = tri.points().to_vec();
    let mut triangles: Vec<[u32; 3]> = tri.triangles().collect();
    // Order triangles by their lowest vertex for memory locality in the solver.
    triangles.sort_by_key(|t| (t[0].min(t[1]).min(t[2]), t[0], t[1], t[2]));
    Ok(LocalMesh { points, triangles, edge_chains })
}

/// Even-odd point-in-polygon test.
fn inside(poly: &[DVec2], p: DVec2) -> bool {
    let n = poly.len();
    let mut c = false;
    for i in 0..n {
        let (a, b) = (poly[i], poly[(i + 1) % n]);
        if (a.y > p.y) != (b.y > p.y) && p.x < a.x + (p.y - a.y) * (b.x - a.x) / (b.y - a.y) {
            c = !c;
        }
    }
    c
}

fn boundary_distance(poly: &[DVec2], p: DVec2) -> f64 {
    let n = poly.len();
    (0..n)
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % n]);
            let ab = b - a;
            let t = ((p - a).dot(ab) / ab.length_squared()).clamp(0.0, 1.0);
            p.distance(a + ab * t)
        })
        .fold(f64::INFINITY, f64::min)
}

/// Regular `n`-gon approximating a circle (CCW), e.g. for round pieces.
pub fn circle_outline(center: Vec2, radius: f32, n: usize) -> Vec<Vec2> {
    (0..n)
        .map(|i| {
            let a = std::f32::consts::TAU * i as f32 / n as f32;
            center + radius * Vec2::new(a.cos(), a.sin())
        })
        .collect()
}

/// Axis-aligned rectangle `w` × `h` cm with its lower-left corner at the
/// origin. Edges: 0 bottom, 1 right, 2 top, 3 left.
pub fn rectangle_outline(w: f32, h: f32) -> Vec<Vec2> {
    vec![Vec2::ZERO, Vec2::new(w, 0.0), Vec2::new(w, h), Vec2::new(0.0, h)]
}

/// Symmetric trapezoid with bottom width `bottom`, top width `top` and
/// height `h`. Edges: 0 hem, 1 right side, 2 top, 3 left side.
pub fn trapezoid_outline(bottom: f32, top: f32, h: f32) -> Vec<Vec2> {
    let inset = 0.5 * (bottom - top);
    vec![Vec2::ZERO, Vec2::new(bottom, 0.0), Vec2::new(bottom - inset, h), Vec2::new(inset, h)]
}

//! Finding places on a surface without a script: the surface point nearest a 3D point (with
//! its UV and piece), landmarks of a pattern piece's UV outline (its centre line, an edge
//! offset inward), and lists of points written as text. Placements are described, with the
//! v-down convention, in docs/warping.md ("Placing attachments").

use glam::{Vec2, Vec3};

use crate::cloth::body_collision::closest_point_feature;
use crate::cloth::bvh::{Aabb, AabbTree};
use crate::mesh::Mesh;

/// The surface point nearest a query point.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SurfaceHit {
    pub position: Vec3,
    pub distance: f32,
    /// Pattern coordinates (v down), interpolated from the triangle's corners.
    pub uv: Vec2,
    pub piece: u32,
    pub triangle: u32,
}

/// Nearest-point queries on a mesh's triangles through a bounding-volume hierarchy.
pub struct NearestPoint<'a> {
    mesh: &'a Mesh,
    tree: AabbTree,
}

impl<'a> NearestPoint<'a> {
    pub fn new(mesh: &'a Mesh) -> Self {
        let boxes: Vec<Aabb> = mesh
            .indices
            .chunks_exact(3)
            .map(|t| Aabb::from_points(&[0, 1, 2].map(|k| mesh.positions[t[k] as usize])))
            .collect();
        NearestPoint { mesh, tree: AabbTree::build(&boxes) }
    }

    /// The nearest surface point within `max_distance` of `p` (the first triangle wins a tie).
    pub fn nearest(&self, p: Vec3, max_distance: f32) -> Option<SurfaceHit> {
        let m = self.mesh;
        let mut best: Option<SurfaceHit> = None;
        self.tree.query(&Aabb::around(p, max_distance), |t| {
            let i = &m.indices[3 * t as usize..3 * t as usize + 3];
            let [a, b, c] = [0, 1, 2].map(|k| m.positions[i[k] as usize]);
            let (q, w, _) = closest_point_feature(p, a, b, c);
            let d = q.distance(p);
            if d <= max_distance && best.is_none_or(|h| d < h.distance || (d == h.distance && t < h.triangle)) {
                let uv = m.uvs[i[0] as usize] * w[0] + m.uvs[i[1] as usize] * w[1] + m.uvs[i[2] as usize] * w[2];
                let piece = m.piece_ids.get(i[0] as usize).copied().unwrap_or(0);
                best = Some(SurfaceHit { position: q, distance: d, uv, piece, triangle: t });
            }
        });
        best
    }
}

crate::choice!(
    /// A line of a pattern piece found from its UV outline.
    pub enum Landmark {
        /// Halfway between the piece's left and right outline, top to bottom; the offset
        /// shifts it towards +u.
        Centre = "centre",
        /// The left outline (smallest u) moved right by the offset, top to bottom.
        LeftEdge = "left_edge",
        /// The right outline (largest u) moved left by the offset, top to bottom.
        RightEdge = "right_edge",
        /// The top outline (smallest v: v points down) moved down by the offset, left to right.
        TopEdge = "top_edge",
        /// The bottom outline (largest v) moved up by the offset, left to right.
        BottomEdge = "bottom_edge",
    }
);

/// The polyline of `landmark` on `piece`: `samples` scanlines across the piece (rows of
/// constant v for the centre and the left and right edges, columns of constant u for the top
/// and bottom ones), kept `margin` (UV units) inside the piece's extent along the line; on
/// each, the span the piece's triangles cover gives the point. Scanlines where the offset
/// crosses the far side are left out. Errors name the piece (and the known ones).
pub fn piece_landmark(
    mesh: &Mesh,
    piece: u32,
    landmark: Landmark,
    offset: f32,
    margin: f32,
    samples: usize,
) -> Result<Vec<Vec2>, String> {
    let (lo, hi) = mesh.piece_uv_rect(piece)?;
    // Scan along axis `a`, measure across axis `b`.
    let rows = matches!(landmark, Landmark::Centre | Landmark::LeftEdge | Landmark::RightEdge);
    let (a, b) = if rows { (1, 0) } else { (0, 1) };
    let (a_lo, a_hi) = (lo[a] + margin, hi[a] - margin);
    if a_lo >= a_hi {
        return Err(format!(
            "the margin {margin} leaves nothing of piece {piece}, which spans {:.4} in {}",
            hi[a] - lo[a],
            if rows { "v" } else { "u" }
        ));
    }
    let samples = samples.max(2);
    let line = |k: usize| a_lo + (a_hi - a_lo) * k as f32 / (samples - 1) as f32;
    let mut spans = vec![(f32::MAX, f32::MIN); samples];
    for t in mesh.indices.chunks_exact(3) {
        if mesh.piece_ids.get(t[0] as usize).copied().unwrap_or(0) != piece {
            continue;
        }
        let uv = [0, 1, 2].map(|k| mesh.uvs[t[k] as usize]);
        let (t_lo, t_hi) = (uv[0][a].min(uv[1][a]).min(uv[2][a]), uv[0][a].max(uv[1][a]).max(uv[2][a]));
        // The scanlines this triangle's extent along `a` reaches.
        let step = (a_hi - a_lo) / (samples - 1) as f32;
        let first = (((t_lo - a_lo) / step).ceil().max(0.0)) as usize;
        let last = (((t_hi - a_lo) / step).floor()).min((samples - 1) as f32);
        if last < 0.0 {
            continue;
        }
        for (k, span) in spans.iter_mut().enumerate().take(last as usize + 1).skip(first) {
            let s = line(k);
            for e in 0..3 {
                let (p, q) = (uv[e], uv[(e + 1) % 3]);
                if (p[a] - s) * (q[a] - s) > 0.0 {
                    continue;
                }
                let x = if p[a] == q[a] { p[b].min(q[b]) } else { p[b] + (q[b] - p[b]) * (s - p[a]) / (q[a] - p[a]) };
                let y = if p[a] == q[a] { p[b].max(q[b]) } else { x };
                *span = (span.0.min(x), span.1.max(y));
            }
        }
    }
    let mut out = Vec::with_capacity(samples);
    for (k, &(lo_b, hi_b)) in spans.iter().enumerate() {
        if lo_b > hi_b {
            continue;
        }
        // An edge is measured inward; a negative offset moves the edge itself outward.
        let inward = offset.max(0.0);
        let measured = match landmark {
            Landmark::Centre => 0.5 * (lo_b + hi_b),
            Landmark::LeftEdge | Landmark::TopEdge => lo_b + inward,
            Landmark::RightEdge | Landmark::BottomEdge => hi_b - inward,
        };
        if !(lo_b..=hi_b).contains(&measured) {
            continue;
        }
        let across = match landmark {
            Landmark::Centre => measured + offset,
            Landmark::LeftEdge | Landmark::TopEdge => measured + offset.min(0.0),
            Landmark::RightEdge | Landmark::BottomEdge => measured - offset.min(0.0),
        };
        let mut p = Vec2::ZERO;
        p[a] = line(k);
        p[b] = across;
        out.push(p);
    }
    if out.len() < 2 {
        return Err(format!(
            "piece {piece} is narrower than twice the offset {offset} along the whole line (it spans {:.4} x {:.4} in UV)",
            hi.x - lo.x,
            hi.y - lo.y
        ));
    }
    Ok(out)
}

/// A polyline as cubic segments (each a straight line), for `Curves`.
pub fn polyline_segments(points: &[Vec2]) -> Vec<[Vec2; 4]> {
    points
        .windows(2)
        .filter(|w| w[0].distance(w[1]) > 1e-9)
        .map(|w| [w[0], w[0].lerp(w[1], 1.0 / 3.0), w[0].lerp(w[1], 2.0 / 3.0), w[1]])
        .collect()
}

/// Parses a list of points of `N` numbers each, separated by `;` or new lines, numbers by
/// spaces or commas ("0.1 0.2; 0.3, 0.4"). Empty entries are skipped. Errors name the
/// parameter and the entry (1-based) and what is wrong with it.
pub fn parse_points<const N: usize>(text: &str, param: &str) -> Result<Vec<[f32; N]>, String> {
    let mut out = Vec::new();
    for (i, entry) in text.split([';', '\n']).enumerate() {
        let entry = entry.trim();
        if entry.is_empty() {
            continue;
        }
        let fields: Vec<&str> = entry.split([' ', ',', '\t']).filter(|f| !f.is_empty()).collect();
        if fields.len() != N {
            return Err(format!(
                "parameter \"{param}\": entry {} (\"{entry}\") has {} numbers, expected {N}",
                i + 1,
                fields.len()
            ));
        }
        let mut p = [0.0; N];
        for (k, f) in fields.iter().enumerate() {
            p[k] = f.parse::<f32>().ok().filter(|x| x.is_finite()).ok_or_else(|| {
                format!("parameter \"{param}\": entry {} (\"{entry}\"): \"{f}\" is not a finite number", i + 1)
            })?;
        }
        out.push(p);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parse_points_reads_separators_and_names_bad_entries() {
        let p = parse_points::<2>("0.1 0.2; 0.3,0.4\n\n 0.5\t0.6 ;", "points").unwrap();
        assert_eq!(p, vec![[0.1, 0.2], [0.3, 0.4], [0.5, 0.6]]);
        let e = parse_points::<2>("0.1 0.2; 0.3", "points").unwrap_err();
        assert!(e.contains("\"points\"") && e.contains("entry 2") && e.contains("expected 2"), "{e}");
        let e = parse_points::<3>("1 2 x", "points").unwrap_err();
        assert!(e.contains("entry 1") && e.contains("\"x\""), "{e}");
        let e = parse_points::<2>("1 nan", "uv").unwrap_err();
        assert!(e.contains("\"uv\"") && e.contains("\"nan\""), "{e}");
    }
}

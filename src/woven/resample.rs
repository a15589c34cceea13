//! A Surface resampled per pattern piece into a regular quad control grid in UV space: the
//! woven patches need a regular control mesh (Zhang et al. 2012 treat regular grids only).
//!
//! Each piece's UV rectangle is cut into patches of about `patch_size` world units a side
//! (`nodes x spacing`), measured with the piece's mean |dP/du| and |dP/dv|; the grid vertices
//! are the surface's points at those UVs (barycentric in the triangle holding them). A patch
//! with a corner outside the piece is not drawn; grid vertices outside the piece take the
//! nearest point of the piece, so the patches along a curved outline still have their 16
//! handle vertices.

use glam::{DVec2, DVec3};

use super::panel::ControlGrid;
use crate::mesh::Mesh;

/// The most patches one piece may have (a guard against a spacing far too small for the cloth).
pub const MAX_PATCHES: usize = 1 << 16;

/// One piece's control grid.
pub struct PieceGrid {
    pub piece: u32,
    pub grid: ControlGrid,
    /// Per patch (row by row): whether all its corners lie in the piece.
    pub inside: Vec<bool>,
    /// Whether the surface's normals face -(∂u x ∂v) of the grid (see `Panel::flip`).
    pub flipped: bool,
}

pub fn resample(mesh: &Mesh, patch_size: f64) -> anyhow::Result<Vec<PieceGrid>> {
    anyhow::ensure!(patch_size > 0.0 && patch_size.is_finite(), "the patch size must be positive (got {patch_size})");
    anyhow::ensure!(
        mesh.uvs.len() == mesh.positions.len() && !mesh.indices.is_empty(),
        "the surface has no UVs or no triangles"
    );
    let piece_of = |v: u32| mesh.piece_ids.get(v as usize).copied().unwrap_or(0);
    let mut out = Vec::new();
    for (piece, lo, hi) in mesh.piece_uv_rects() {
        let tris: Vec<[u32; 3]> =
            mesh.indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).filter(|t| piece_of(t[0]) == piece).collect();
        if tris.is_empty() {
            continue;
        }
        let (lo, hi) = (lo.as_dvec2(), hi.as_dvec2());
        let ext = hi - lo;
        if ext.x <= 0.0 || ext.y <= 0.0 {
            continue;
        }
        let (du, dv) = mean_gradients(mesh, &tris);
        let cells = |len: f64| ((len / patch_size).round() as usize).max(1);
        let (cu, cv) = (cells(ext.x * du), cells(ext.y * dv));
        anyhow::ensure!(
            cu * cv <= MAX_PATCHES,
            "piece {piece} would need {cu}x{cv} patches of {patch_size} (at most {MAX_PATCHES}): raise the spacing"
        );
        let locator = Locator::new(mesh, tris, lo, hi);
        let mut points = Vec::with_capacity((cu + 1) * (cv + 1));
        let mut corner_inside = Vec::with_capacity((cu + 1) * (cv + 1));
        let mut normals = Vec::with_capacity((cu + 1) * (cv + 1));
        for j in 0..=cv {
            for i in 0..=cu {
                let uv = lo + ext * DVec2::new(i as f64 / cu as f64, j as f64 / cv as f64);
                let (p, n, inside) = locator.point(uv);
                points.push(p);
                normals.push(n);
                corner_inside.push(inside);
            }
        }
        // Orientation: the grid's ∂u x ∂v against the surface's normals, summed over the grid.
        let at_p = |i: usize, j: usize| points[j * (cu + 1) + i];
        let mut facing = 0.0;
        for j in 0..=cv {
            for i in 0..=cu {
                let du = at_p((i + 1).min(cu), j) - at_p(i.saturating_sub(1), j);
                let dv = at_p(i, (j + 1).min(cv)) - at_p(i, j.saturating_sub(1));
                facing += du.cross(dv).dot(normals[j * (cu + 1) + i]);
            }
        }
        let at = |i: usize, j: usize| corner_inside[j * (cu + 1) + i];
        let inside = (0..cv)
            .flat_map(|j| (0..cu).map(move |i| (i, j)))
            .map(|(i, j)| at(i, j) && at(i + 1, j) && at(i, j + 1) && at(i + 1, j + 1))
            .collect();
        out.push(PieceGrid { piece, grid: ControlGrid::new(cu + 1, cv + 1, points)?, inside, flipped: facing < 0.0 });
    }
    anyhow::ensure!(!out.is_empty(), "the surface has no pattern piece with a UV area");
    Ok(out)
}

/// Area-weighted mean lengths of dP/du and dP/dv over the triangles.
fn mean_gradients(mesh: &Mesh, tris: &[[u32; 3]]) -> (f64, f64) {
    let (mut su, mut sv, mut w) = (0.0, 0.0, 0.0);
    for t in tris {
        let p = t.map(|i| mesh.positions[i as usize].as_dvec3());
        let q = t.map(|i| mesh.uvs[i as usize].as_dvec2());
        let (e1, e2) = (p[1] - p[0], p[2] - p[0]);
        let (d1, d2) = (q[1] - q[0], q[2] - q[0]);
        let det = d1.x * d2.y - d2.x * d1.y;
        if det.abs() < 1e-18 {
            continue;
        }
        let dpdu = (e1 * d2.y - e2 * d1.y) / det;
        let dpdv = (e2 * d1.x - e1 * d2.x) / det;
        let area = e1.cross(e2).length();
        su += area * dpdu.length();
        sv += area * dpdv.length();
        w += area;
    }
    if w == 0.0 { (1.0, 1.0) } else { (su / w, sv / w) }
}

/// Triangles of a piece bucketed in UV for point location.
struct Locator<'a> {
    mesh: &'a Mesh,
    tris: Vec<[u32; 3]>,
    lo: DVec2,
    cell: DVec2,
    n: usize,
    buckets: Vec<Vec<usize>>,
}

impl<'a> Locator<'a> {
    fn new(mesh: &'a Mesh, tris: Vec<[u32; 3]>, lo: DVec2, hi: DVec2) -> Locator<'a> {
        let n = ((tris.len() as f64).sqrt().ceil() as usize).clamp(1, 256);
        let cell = (hi - lo) / n as f64;
        let mut buckets = vec![Vec::new(); n * n];
        for (k, t) in tris.iter().enumerate() {
            let q = t.map(|i| mesh.uvs[i as usize].as_dvec2());
            let (a, b) = (q[0].min(q[1]).min(q[2]), q[0].max(q[1]).max(q[2]));
            let idx = |x: DVec2| {
                let c = ((x - lo) / cell).floor();
                (c.x.clamp(0.0, (n - 1) as f64) as usize, c.y.clamp(0.0, (n - 1) as f64) as usize)
            };
            let ((i0, j0), (i1, j1)) = (idx(a), idx(b));
            for j in j0..=j1 {
                for i in i0..=i1 {
                    buckets[j * n + i].push(k);
                }
            }
        }
        Locator { mesh, tris, lo, cell, n, buckets }
    }

    /// Barycentric coordinates of `uv` in triangle `k`.
    fn bary(&self, k: usize, uv: DVec2) -> Option<[f64; 3]> {
        let q = self.tris[k].map(|i| self.mesh.uvs[i as usize].as_dvec2());
        let (d1, d2, d) = (q[1] - q[0], q[2] - q[0], uv - q[0]);
        let det = d1.x * d2.y - d2.x * d1.y;
        if det.abs() < 1e-18 {
            return None;
        }
        let b1 = (d.x * d2.y - d2.x * d.y) / det;
        let b2 = (d1.x * d.y - d.x * d1.y) / det;
        Some([1.0 - b1 - b2, b1, b2])
    }

    /// The position and normal at barycentrics `b` of triangle `k` (the face normal where the
    /// mesh has no vertex normals).
    fn eval(&self, k: usize, b: [f64; 3]) -> (DVec3, DVec3) {
        let p = self.tris[k].map(|i| self.mesh.positions[i as usize].as_dvec3());
        let n = match self.mesh.normals.len() == self.mesh.positions.len() {
            true => {
                let n = self.tris[k].map(|i| self.mesh.normals[i as usize].as_dvec3());
                b[0] * n[0] + b[1] * n[1] + b[2] * n[2]
            }
            false => (p[1] - p[0]).cross(p[2] - p[0]),
        };
        (b[0] * p[0] + b[1] * p[1] + b[2] * p[2], n)
    }

    /// The surface point at `uv` and whether `uv` lies in the piece; outside, the point of the
    /// nearest triangle (barycentrics clamped).
    fn point(&self, uv: DVec2) -> (DVec3, DVec3, bool) {
        const EPS: f64 = 1e-9;
        let c = ((uv - self.lo) / self.cell).floor();
        let (i, j) = (c.x.clamp(0.0, (self.n - 1) as f64) as usize, c.y.clamp(0.0, (self.n - 1) as f64) as usize);
        for &k in &self.buckets[j * self.n + i] {
            if let Some(b) = self.bary(k, uv).filter(|b| b.iter().all(|&x| x >= -EPS)) {
                let (p, n) = self.eval(k, b);
                return (p, n, true);
            }
        }
        let mut best = (f64::MAX, (DVec3::ZERO, DVec3::Y));
        for k in 0..self.tris.len() {
            let Some(b) = self.bary(k, uv) else { continue };
            let mut c = b.map(|x| x.max(0.0));
            let s: f64 = c.iter().sum();
            c = c.map(|x| x / s);
            let q = self.tris[k].map(|i| self.mesh.uvs[i as usize].as_dvec2());
            let near = c[0] * q[0] + c[1] * q[1] + c[2] * q[2];
            let d = near.distance_squared(uv);
            if d < best.0 {
                best = (d, self.eval(k, c));
            }
        }
        (best.1.0, best.1.1, false)
    }
}

//! The panel scale (Zhang et al. 2012, section 4.1): Hassan et al.'s ternary interpolatory
//! 4-point scheme (CAGD 19(1), 2002) with μ = 4/45, approximated on each face of a regular
//! quad control grid by a bicubic Bézier "woven patch" that interpolates the 16 points of one
//! refinement step (eqs. 6-8), and the panel frame (eqs. 9-10).
//!
//! The 1D rule of [26] inserts two points per interval and keeps the old ones:
//! `p'(3i) = p(i)`, `p'(3i+1) = a0 p(i-1) + a1 p(i) + a2 p(i+1) + a3 p(i+2)`, `p'(3i+2)` mirrored,
//! with `a0 = -1/18 - μ/6, a1 = 13/18 + μ/2, a2 = 7/18 - μ/2, a3 = -1/18 + μ/6`
//! (C2 for 1/15 < μ < 1/9; μ = 4/45 is the middle of that range, as the paper says). The
//! surface rule is its tensor product, so `M_R = A ⊗ A` with `A` the 4x4 map from the four
//! control points of a line to the values at t = 0, 1/3, 2/3, 1, and `M_Q = B ⊗ B` with `B` the
//! cubic Bernstein basis at those parameters; eq. 7 is `Q = (B⁻¹A) ⊗ (B⁻¹A) R`.

use glam::DVec3;

/// The paper's tension parameter.
pub const MU: f64 = 4.0 / 45.0;

/// The weights `(a0, a1, a2, a3)` of the first inserted point, `p'(3i+1)`, on `p(i-1..=i+2)`.
pub fn ternary_weights(mu: f64) -> [f64; 4] {
    [-1.0 / 18.0 - mu / 6.0, 13.0 / 18.0 + mu / 2.0, 7.0 / 18.0 - mu / 2.0, -1.0 / 18.0 + mu / 6.0]
}

/// One ternary refinement step of the open polyline `p` (3n - 2 points from n): the old points
/// and two new ones per interval. The intervals next to the ends use the linear ghosts
/// `2 p(0) - p(1)` and `2 p(n-1) - p(n-2)` (the boundary rule used everywhere in this module).
pub fn refine(p: &[DVec3], mu: f64) -> Vec<DVec3> {
    let n = p.len();
    if n < 2 {
        return p.to_vec();
    }
    let at = |i: isize| -> DVec3 {
        if i < 0 {
            2.0 * p[0] - p[1]
        } else if i as usize >= n {
            2.0 * p[n - 1] - p[n - 2]
        } else {
            p[i as usize]
        }
    };
    let a = ternary_weights(mu);
    let mut out = Vec::with_capacity(3 * n - 2);
    for i in 0..n as isize - 1 {
        let s = [at(i - 1), at(i), at(i + 1), at(i + 2)];
        out.push(s[1]);
        out.push(a[0] * s[0] + a[1] * s[1] + a[2] * s[2] + a[3] * s[3]);
        out.push(a[3] * s[0] + a[2] * s[1] + a[1] * s[2] + a[0] * s[3]);
    }
    out.push(p[n - 1]);
    out
}

/// `A`: the four control points of a line (p(-1), p(0), p(1), p(2)) to the refined values at
/// t = 0, 1/3, 2/3, 1 of the interval p(0)..p(1).
fn refinement_matrix(mu: f64) -> [[f64; 4]; 4] {
    let a = ternary_weights(mu);
    [[0.0, 1.0, 0.0, 0.0], a, [a[3], a[2], a[1], a[0]], [0.0, 0.0, 1.0, 0.0]]
}

/// Cubic Bernstein basis at `t`.
pub fn bernstein(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    [s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t]
}

/// Derivative of the cubic Bernstein basis at `t`.
pub fn bernstein_d(t: f64) -> [f64; 4] {
    let s = 1.0 - t;
    [-3.0 * s * s, 3.0 * s * s - 6.0 * s * t, 6.0 * s * t - 3.0 * t * t, 3.0 * t * t]
}

/// `B⁻¹ A`: the 1D mask from a line's four control points to its four Bézier points. Row 0 is
/// the vertex mask, rows 1 and 2 the inner points (eq. 7 in 1D); the surface masks are its
/// tensor products (interior `q1 ⊗ q1`, edge `e ⊗ q1` with `e` the vertex row, vertex `e ⊗ e`).
pub fn bezier_mask(mu: f64) -> [[f64; 4]; 4] {
    // M_Q in 1D: Bernstein at the refinement parameters, solved by Gauss-Jordan (it is
    // well conditioned; the inverse is not written out so that the masks follow from μ).
    let mut m = [[0.0; 8]; 4];
    for (r, row) in m.iter_mut().enumerate() {
        row[..4].copy_from_slice(&bernstein(r as f64 / 3.0));
        row[4 + r] = 1.0;
    }
    for c in 0..4 {
        let pivot = (c..4).max_by(|&a, &b| m[a][c].abs().total_cmp(&m[b][c].abs())).unwrap_or(c);
        m.swap(c, pivot);
        let d = m[c][c];
        m[c].iter_mut().for_each(|x| *x /= d);
        for r in 0..4 {
            if r != c {
                let f = m[r][c];
                let pivot_row = m[c];
                m[r].iter_mut().zip(pivot_row).for_each(|(x, p)| *x -= f * p);
            }
        }
    }
    let a = refinement_matrix(mu);
    let mut out = [[0.0; 4]; 4];
    for (i, row) in out.iter_mut().enumerate() {
        for (j, x) in row.iter_mut().enumerate() {
            *x = (0..4).map(|k| m[i][4 + k] * a[k][j]).sum();
        }
    }
    out
}

/// A bicubic Bézier woven patch: `q[i][j]`, i along u, j along v.
#[derive(Clone, Debug)]
pub struct BezierPatch {
    pub q: [[DVec3; 4]; 4],
}

impl BezierPatch {
    /// Eq. 7: the patch of the face between `r[1][1]` and `r[2][2]` of the 4x4 control points
    /// `r[i][j]` (i along u).
    pub fn from_controls(r: &[[DVec3; 4]; 4], mask: &[[f64; 4]; 4]) -> BezierPatch {
        let mut q = [[DVec3::ZERO; 4]; 4];
        for (i, qi) in q.iter_mut().enumerate() {
            for (j, qij) in qi.iter_mut().enumerate() {
                let mut s = DVec3::ZERO;
                for (k, rk) in r.iter().enumerate() {
                    for (l, rkl) in rk.iter().enumerate() {
                        s += mask[i][k] * mask[j][l] * *rkl;
                    }
                }
                *qij = s;
            }
        }
        BezierPatch { q }
    }

    /// Eq. 8: the position at local parameters (s, t) in [0,1]^2.
    pub fn position(&self, s: f64, t: f64) -> DVec3 {
        self.combine(bernstein(s), bernstein(t))
    }

    /// ∂/∂s and ∂/∂t: the Bézier combination of the control tangents (eqs. 9-10 with M_τ the
    /// derivative of the patch, which the paper does not print).
    pub fn derivatives(&self, s: f64, t: f64) -> (DVec3, DVec3) {
        (self.combine(bernstein_d(s), bernstein(t)), self.combine(bernstein(s), bernstein_d(t)))
    }

    fn combine(&self, bu: [f64; 4], bv: [f64; 4]) -> DVec3 {
        let mut p = DVec3::ZERO;
        for (bi, row) in bu.iter().zip(&self.q) {
            for (bj, q) in bv.iter().zip(row) {
                p += bi * bj * *q;
            }
        }
        p
    }
}

/// An orthonormal frame (tangent, normal, binormal): x along the tangent, y the normal, z the
/// binormal, as the paper's `float3x3(tau, n, b)` with `mul(l, M)`. `apply` maps local to world.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Frame {
    pub t: DVec3,
    pub n: DVec3,
    pub b: DVec3,
}

impl Frame {
    pub const IDENTITY: Frame = Frame { t: DVec3::X, n: DVec3::Y, b: DVec3::Z };

    pub fn apply(&self, l: DVec3) -> DVec3 {
        l.x * self.t + l.y * self.n + l.z * self.b
    }

    /// The frame of `other` expressed in this one, composed (M_self M_other).
    pub fn compose(&self, other: &Frame) -> Frame {
        Frame { t: self.apply(other.t), n: self.apply(other.n), b: self.apply(other.b) }
    }

    /// The panel frame from the two surface derivatives: τ along ∂u, n = ∂u x ∂v, b = n x τ, all
    /// unit (the paper's eq. 10 builds n = τ x b from unnormalised Bézier combinations; a
    /// "unit base matrix" needs them orthonormal).
    pub fn from_derivatives(du: DVec3, dv: DVec3) -> Frame {
        let t = du.try_normalize().unwrap_or(DVec3::X);
        let n = du.cross(dv).try_normalize().unwrap_or_else(|| t.any_orthonormal_vector());
        Frame { t, n, b: n.cross(t) }
    }

    /// max |MᵀM - I| entry.
    pub fn orthonormality_error(&self) -> f64 {
        let c = [self.t, self.n, self.b];
        let mut e: f64 = 0.0;
        for i in 0..3 {
            for j in 0..3 {
                e = e.max((c[i].dot(c[j]) - if i == j { 1.0 } else { 0.0 }).abs());
            }
        }
        e
    }
}

/// A regular grid of control vertices (`nu` x `nv`, i along u), one pattern piece. Faces are
/// patches; control points outside the grid are linear ghosts (`2 p(0) - p(1)` per direction).
#[derive(Clone, Debug)]
pub struct ControlGrid {
    pub nu: usize,
    pub nv: usize,
    pub points: Vec<DVec3>,
}

impl ControlGrid {
    pub fn new(nu: usize, nv: usize, points: Vec<DVec3>) -> anyhow::Result<ControlGrid> {
        anyhow::ensure!(nu >= 2 && nv >= 2, "a control grid needs at least 2x2 vertices (got {nu}x{nv})");
        anyhow::ensure!(points.len() == nu * nv, "{nu}x{nv} grid but {} points", points.len());
        anyhow::ensure!(points.iter().all(|p| p.is_finite()), "the control grid has NaN or infinite points");
        Ok(ControlGrid { nu, nv, points })
    }

    /// Patches along u and v.
    pub fn patches(&self) -> (usize, usize) {
        (self.nu - 1, self.nv - 1)
    }

    /// The control point (i, j), extrapolated linearly outside the grid.
    pub fn at(&self, i: isize, j: isize) -> DVec3 {
        let (nu, nv) = (self.nu as isize, self.nv as isize);
        if j < 0 {
            return self.at(i, 0) - j as f64 * (self.at(i, 0) - self.at(i, 1));
        }
        if j >= nv {
            return self.at(i, nv - 1) + (j - nv + 1) as f64 * (self.at(i, nv - 1) - self.at(i, nv - 2));
        }
        if i < 0 {
            return self.at(0, j) - i as f64 * (self.at(0, j) - self.at(1, j));
        }
        if i >= nu {
            return self.at(nu - 1, j) + (i - nu + 1) as f64 * (self.at(nu - 1, j) - self.at(nu - 2, j));
        }
        self.points[(j * nu + i) as usize]
    }

    /// The 16 handle vertices R of patch (pi, pj): its 4 corners and the 12 around them.
    pub fn handles(&self, pi: usize, pj: usize) -> [[DVec3; 4]; 4] {
        let mut r = [[DVec3::ZERO; 4]; 4];
        for (k, rk) in r.iter_mut().enumerate() {
            for (l, rkl) in rk.iter_mut().enumerate() {
                *rkl = self.at(pi as isize - 1 + k as isize, pj as isize - 1 + l as isize);
            }
        }
        r
    }

    /// Every patch, row by row (index `pj * patches_u + pi`).
    pub fn bezier_patches(&self, mu: f64) -> Vec<BezierPatch> {
        let mask = bezier_mask(mu);
        let (pu, pv) = self.patches();
        (0..pv)
            .flat_map(|pj| (0..pu).map(move |pi| (pi, pj)))
            .map(|(pi, pj)| BezierPatch::from_controls(&self.handles(pi, pj), &mask))
            .collect()
    }
}

/// The patches of a control grid with the frame shared along patch borders: the patches are
/// only C0 across edges, so a frame from one side alone would open cracks between the yarns of
/// neighbouring patches. On a border the cross derivative is the mean of both sides'.
pub struct Panel {
    pub patches_u: usize,
    pub patches_v: usize,
    pub patches: Vec<BezierPatch>,
    /// Whether the normal is -(∂u x ∂v): the side the input surface's normals face, so that
    /// "up" (η = +1, the weft) is on the surface's front.
    pub flip: bool,
}

impl Panel {
    pub fn new(grid: &ControlGrid) -> Panel {
        let (patches_u, patches_v) = grid.patches();
        Panel { patches_u, patches_v, patches: grid.bezier_patches(MU), flip: false }
    }

    pub fn patch(&self, pi: usize, pj: usize) -> &BezierPatch {
        &self.patches[pj * self.patches_u + pi]
    }

    /// Position at local (s, t) of patch (pi, pj).
    pub fn position(&self, pi: usize, pj: usize, s: f64, t: f64) -> DVec3 {
        self.patch(pi, pj).position(s, t)
    }

    /// The panel frame M_p at local (s, t) of patch (pi, pj), shared on borders.
    pub fn frame(&self, pi: usize, pj: usize, s: f64, t: f64) -> Frame {
        let (mut du, mut dv) = self.patch(pi, pj).derivatives(s, t);
        if s == 0.0 && pi > 0 {
            du = 0.5 * (du + self.patch(pi - 1, pj).derivatives(1.0, t).0);
        } else if s == 1.0 && pi + 1 < self.patches_u {
            du = 0.5 * (du + self.patch(pi + 1, pj).derivatives(0.0, t).0);
        }
        if t == 0.0 && pj > 0 {
            dv = 0.5 * (dv + self.patch(pi, pj - 1).derivatives(s, 1.0).1);
        } else if t == 1.0 && pj + 1 < self.patches_v {
            dv = 0.5 * (dv + self.patch(pi, pj + 1).derivatives(s, 0.0).1);
        }
        let f = Frame::from_derivatives(du, dv);
        if self.flip { Frame { t: f.t, n: -f.n, b: -f.b } } else { f }
    }
}

//! Adaptive tessellation with barycentric warping (dissertation sections 3.1.3, 4.1.3, 5.1.3;
//! `docs/tessellation.md`): the CPU reference of `shaders/tessellation/tessellate.wgsl`, which mirrors it
//! function by function.
//!
//! A triangle with three edge levels (edge `e` runs from corner `e` to corner `e + 1`) is
//! refined into a list of [`PatchPoint`]s and triangles by [`refine`]:
//!
//! - the dissertation's pattern: rotated so the lowest edge is the base, split into a uniform
//!   triangle at the base level (top) and a trapezoid strip (bottom) whose vertical lines carry
//!   the remaining levels, snapped along the vertical axis only; two equal low edges and one
//!   high edge rotate the strip onto the high edge (Fig. 3.9);
//! - dyadic semi-uniform refinement ([DRS09]): a uniform grid at the highest edge level rounded
//!   up to a power of two, edge vertices snapped to their edge's (power-of-two) level.
//!
//! Each point is then evaluated by [`eval_point`]: corners are copied, points on an edge are
//! computed from that edge's two end vertices in one canonical orientation (from the lower
//! mesh index to the higher), so both triangles sharing an edge produce bit-identical
//! vertices; interior points go through the barycentric warp (eqs. 3.21-3.32 in the quadratic
//! Bezier form, see [`warp`]) and the PN triangle [VPBM01].

use glam::{Vec2, Vec3};

use crate::mesh::Vertex;

crate::choice!(
    /// The refinement modes of Fig. 5.11.
    pub enum Mode {
        /// Every triangle at one level (the PN-triangle scheme's uniform refinement).
        Uniform = "uniform",
        /// Dyadic semi-uniform adaptive refinement with edge snapping [DRS09].
        Dyadic = "dyadic",
        /// The dissertation's pattern (uniform triangle + trapezoid strip), no warping.
        Pattern = "pattern",
        /// The pattern with barycentric warping toward the higher-level vertices.
        PatternWarp = "pattern_warp",
    }
);

crate::choice!(
    /// How vertex levels are chosen on the GPU.
    pub enum Metric {
        /// [`vertex_level`]: logarithmic distance falloff and silhouette.
        Distance = "distance",
        /// Each vertex: its longest incident edge on screen over the maximum edge length (Fig. 5.15).
        EdgeLength = "edge_length",
    }
);

impl Mode {
    /// The mode's number in shaders/tessellation/tessellate.wgsl.
    pub fn index(self) -> u32 {
        match self {
            Mode::Uniform => 0,
            Mode::Dyadic => 1,
            Mode::Pattern => 2,
            Mode::PatternWarp => 3,
        }
    }

    pub fn warps(self) -> bool {
        self == Mode::PatternWarp
    }
}

/// A vertex of a refined triangle, named so that shared vertices are computed alike.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum PatchPoint {
    /// Corner 0, 1 or 2 of the triangle.
    Corner(u32),
    /// Vertex `i` (0 < i < level) of edge `edge`, counted from corner `edge` at that edge's level.
    Edge { edge: u32, i: u32 },
    /// A point inside: barycentric coordinates of corners 0, 1, 2 (before warping).
    Interior([f32; 3]),
}

/// A refined triangle: points and counter-clockwise triangles (indices into `points`), in
/// the order the compute shader writes them.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Patch {
    pub points: Vec<PatchPoint>,
    pub triangles: Vec<[u32; 3]>,
}

/// The smallest power of two at or above `n` (at least 1).
pub fn dyadic(n: u32) -> u32 {
    n.max(1).next_power_of_two()
}

/// `round(a + (b - a) * i / k)` in integers, halves rounded up (exact on CPU and GPU).
fn lerp_round(a: u32, b: u32, i: u32, k: u32) -> u32 {
    (2 * (a * (k - i) + b * i) + k) / (2 * k)
}

/// How the pattern splits a triangle with edge levels `n` (see [`refine`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
struct Split {
    /// The corner the base edge starts at (A); B = rot + 1, C = rot + 2.
    rot: u32,
    /// The special case (two equal low edges, one high edge): the strip lies on the base.
    special: bool,
    base: u32,
    right: u32,
    left: u32,
    /// The level of the uniform top triangle.
    m: u32,
    /// Generic case: segments of the strip's left and right sides; special case: its rows.
    s_left: u32,
    s_right: u32,
    rows: u32,
}

fn split(n: [u32; 3]) -> Split {
    let mut rot = 0;
    for e in 1..3 {
        if n[e as usize] < n[rot as usize] {
            rot = e;
        }
    }
    let low = n[rot as usize];
    let (r1, r2) = (n[((rot + 1) % 3) as usize], n[((rot + 2) % 3) as usize]);
    let high = if r2 == low && r1 > low {
        Some((rot + 1) % 3)
    } else if r1 == low && r2 > low {
        Some((rot + 2) % 3)
    } else {
        None
    };
    match high {
        Some(h) => {
            // Fig. 3.9: the high edge becomes the base; its strip's rows fall from the high
            // level to the top triangle's over `rows` rows of the two low sides.
            let rows = (low / 2).max(1);
            Split {
                rot: h,
                special: true,
                base: n[h as usize],
                right: low,
                left: low,
                m: low - rows,
                s_left: 0,
                s_right: 0,
                rows,
            }
        }
        None => Split {
            rot,
            special: false,
            base: low,
            right: r1,
            left: r2,
            m: low,
            s_left: r2 - low,
            s_right: r1 - low,
            rows: 0,
        },
    }
}

/// Barycentrics (corners 0, 1, 2) of a point given in the rotated frame (A, B, C).
fn unrotate(rot: u32, abc: [f32; 3]) -> [f32; 3] {
    let mut out = [0.0; 3];
    out[rot as usize] = abc[0];
    out[((rot + 1) % 3) as usize] = abc[1];
    out[((rot + 2) % 3) as usize] = abc[2];
    out
}

/// Points named in the rotated frame.
struct Frame {
    s: Split,
}

impl Frame {
    fn corner(&self, k: u32) -> PatchPoint {
        PatchPoint::Corner((self.s.rot + k) % 3)
    }
    /// Vertex `i` of the base A -> B.
    fn base(&self, i: u32) -> PatchPoint {
        match i {
            0 => self.corner(0),
            i if i == self.s.base => self.corner(1),
            i => PatchPoint::Edge { edge: self.s.rot, i },
        }
    }
    /// Vertex `i` of the right edge B -> C.
    fn right(&self, i: u32) -> PatchPoint {
        match i {
            0 => self.corner(1),
            i if i == self.s.right => self.corner(2),
            i => PatchPoint::Edge { edge: (self.s.rot + 1) % 3, i },
        }
    }
    /// Vertex `i` of the left edge counted from A (the edge itself runs C -> A).
    fn left(&self, i: u32) -> PatchPoint {
        match i {
            0 => self.corner(0),
            i if i == self.s.left => self.corner(2),
            i => PatchPoint::Edge { edge: (self.s.rot + 2) % 3, i: self.s.left - i },
        }
    }
    fn interior(&self, abc: [f32; 3]) -> PatchPoint {
        PatchPoint::Interior(unrotate(self.s.rot, abc))
    }
}

fn lerp3(a: [f32; 3], b: [f32; 3], t: f32) -> [f32; 3] {
    [a[0] * (1.0 - t) + b[0] * t, a[1] * (1.0 - t) + b[1] * t, a[2] * (1.0 - t) + b[2] * t]
}

/// The uniform top triangle of level `m` over (bl, br, C), `bl`/`br` its bottom corners in the
/// rotated frame and `up_left`/`up_right` the left/right edge indices of its bottom corners.
fn top_point(f: &Frame, m: u32, row: u32, c: u32, bl: [f32; 3], br: [f32; 3], up: (u32, u32)) -> PatchPoint {
    if row == m {
        f.corner(2)
    } else if c == 0 {
        f.left(up.0 + row)
    } else if c == m - row {
        f.right(up.1 + row)
    } else if row == 0 && up == (0, 0) {
        f.base(c)
    } else {
        let (fm, fr, fc) = (m as f32, row as f32, c as f32);
        let (wl, wr, wc) = ((fm - fr - fc) / fm, fc / fm, fr / fm);
        f.interior([wl * bl[0] + wr * br[0], wl * bl[1] + wr * br[1], wl * bl[2] + wr * br[2] + wc])
    }
}

/// Appends the uniform grid triangles of level `m` whose vertex (row, c) is `first + index`.
fn grid_triangles(m: u32, first: u32, tris: &mut Vec<[u32; 3]>) {
    let index = |row: u32, c: u32| first + grid_row_start(m, row) + c;
    for row in 0..m {
        for c in 0..(m - row) {
            tris.push([index(row, c), index(row, c + 1), index(row + 1, c)]);
            if c + 1 < m - row {
                tris.push([index(row, c + 1), index(row + 1, c + 1), index(row + 1, c)]);
            }
        }
    }
}

/// Index of the first vertex of `row` in a uniform grid of level `m` (row r has m - r + 1).
fn grid_row_start(m: u32, row: u32) -> u32 {
    row * (m + 1) - (row * (row + 1) / 2 - row)
}

/// Triangulates the band between polyline `a` (s segments, its vertex q at `a0 + q`, except
/// that vertex s is `a_last`) and polyline `b` (t segments, likewise), merging by parameter.
/// Counter-clockwise when `b` lies to the right of `a` walking along it: the generic case's
/// vertical lines pass (left, right), the special case's rows (upper, lower).
fn strip(a: (u32, u32, u32), b: (u32, u32, u32), tris: &mut Vec<[u32; 3]>) {
    let ((a0, s, a_last), (b0, t, b_last)) = (a, b);
    let av = |q: u32| if q == s { a_last } else { a0 + q };
    let bv = |q: u32| if q == t { b_last } else { b0 + q };
    let (mut i, mut k) = (0, 0);
    while i < s || k < t {
        if k == t || (i < s && (i + 1) * t <= (k + 1) * s) {
            tris.push([av(i), bv(k), av(i + 1)]);
            i += 1;
        } else {
            tris.push([av(i), bv(k), bv(k + 1)]);
            k += 1;
        }
    }
}

/// Vertex and triangle counts of [`refine`] without building it (the compute shader's first pass).
pub fn counts(n: [u32; 3], dyadic_mode: bool) -> (u32, u32) {
    if dyadic_mode {
        let m = dyadic(n.into_iter().max().unwrap_or(1));
        return ((m + 1) * (m + 2) / 2, m * m);
    }
    let s = split(n);
    let (mut v, mut t) = ((s.m + 1) * (s.m + 2) / 2, s.m * s.m);
    if s.special {
        for i in 0..s.rows {
            let (c, c1) = (lerp_round(s.base, s.m, i, s.rows), lerp_round(s.base, s.m, i + 1, s.rows));
            v += c + 1;
            t += c + c1;
        }
    } else {
        for j in 0..=s.base {
            let sj = lerp_round(s.s_left, s.s_right, j, s.base);
            v += sj;
            if j < s.base {
                t += sj + lerp_round(s.s_left, s.s_right, j + 1, s.base);
            }
        }
    }
    (v, t)
}

/// Refines a triangle with edge levels `n` (each at least 1). `flip[e]`: edge `e` runs against
/// its canonical orientation (only dyadic snapping needs it).
pub fn refine(n: [u32; 3], dyadic_mode: bool, flip: [bool; 3]) -> Patch {
    let mut p = Patch::default();
    if dyadic_mode {
        refine_dyadic(n, flip, &mut p);
        return p;
    }
    let s = split(n);
    let f = Frame { s };
    let m = s.m;
    // The top triangle's bottom corners and their indices on the left and right edges.
    let (bl, br, up) = if s.special {
        let h = s.rows as f32 / s.left as f32;
        ([1.0 - h, 0.0, h], [0.0, 1.0 - h, h], (s.rows, s.rows))
    } else {
        let (hl, hr) = (s.s_left as f32 / s.left as f32, s.s_right as f32 / s.right as f32);
        ([1.0 - hl, 0.0, hl], [0.0, 1.0 - hr, hr], (s.s_left, s.s_right))
    };
    for row in 0..=m {
        for c in 0..=(m - row) {
            p.points.push(top_point(&f, m, row, c, bl, br, up));
        }
    }
    grid_triangles(m, 0, &mut p.triangles);
    let mut first = p.points.len() as u32;
    if s.special {
        // Rows i = 0..rows across the two low sides, from the high base up to the triangle.
        let b = s.left as f32;
        let mut prev: Option<(u32, u32)> = None;
        for i in 0..s.rows {
            let c = lerp_round(s.base, m, i, s.rows);
            let fi = i as f32 / b;
            let (li, ri) = ([1.0 - fi, 0.0, fi], [0.0, 1.0 - fi, fi]);
            for q in 0..=c {
                p.points.push(if i == 0 {
                    f.base(q)
                } else if q == 0 {
                    f.left(i)
                } else if q == c {
                    f.right(i)
                } else {
                    f.interior(lerp3(li, ri, q as f32 / c as f32))
                });
            }
            if let Some((a0, ac)) = prev {
                strip((first, c, first + c), (a0, ac, a0 + ac), &mut p.triangles);
            }
            prev = Some((first, c));
            first += c + 1;
        }
        if let Some((a0, ac)) = prev {
            strip((0, m, m), (a0, ac, a0 + ac), &mut p.triangles);
        }
    } else {
        // Vertical lines j = 0..=base from the base to the cut; line j's top is the top
        // triangle's bottom vertex j.
        let b = s.base as f32;
        let mut prev: Option<(u32, u32, u32)> = None;
        for j in 0..=s.base {
            let sj = lerp_round(s.s_left, s.s_right, j, s.base);
            let fj = j as f32 / b;
            let bottom = [1.0 - fj, fj, 0.0];
            let top = lerp3(bl, br, fj);
            for k in 0..sj {
                p.points.push(if j == 0 {
                    f.left(k)
                } else if j == s.base {
                    f.right(k)
                } else if k == 0 {
                    f.base(j)
                } else {
                    f.interior(lerp3(bottom, top, k as f32 / sj as f32))
                });
            }
            let line = (first, sj, j);
            if let Some((a0, sa, ja)) = prev {
                strip((a0, sa, ja), line, &mut p.triangles);
            }
            prev = Some(line);
            first += sj;
        }
    }
    p
}

fn refine_dyadic(n: [u32; 3], flip: [bool; 3], p: &mut Patch) {
    let nd = n.map(dyadic);
    let m = nd.into_iter().max().unwrap_or(1);
    // Vertex `i` of edge `e` on the level-m grid, snapped to the edge's level in canonical order.
    let snap = |e: u32, i: u32| -> PatchPoint {
        let ne = nd[e as usize];
        let ic = if flip[e as usize] { m - i } else { i };
        let sc = (2 * ic * ne + m) / (2 * m);
        let s = if flip[e as usize] { ne - sc } else { sc };
        match s {
            0 => PatchPoint::Corner(e),
            s if s == ne => PatchPoint::Corner((e + 1) % 3),
            s => PatchPoint::Edge { edge: e, i: s },
        }
    };
    for row in 0..=m {
        for c in 0..=(m - row) {
            p.points.push(if row == 0 {
                snap(0, c)
            } else if c == 0 {
                snap(2, m - row)
            } else if c == m - row {
                snap(1, row)
            } else {
                let fm = m as f32;
                PatchPoint::Interior([(m - row - c) as f32 / fm, c as f32 / fm, row as f32 / fm])
            });
        }
    }
    grid_triangles(m, 0, &mut p.triangles);
}

/// Barycentric warping (eqs. 3.21-3.32) with the quadratic Bezier triangle of degree two:
/// f = C200 u^2 + C020 v^2 + C002 w^2 + 2 (C110 uv + C011 vw + C101 uw). The printed eqs.
/// 3.18-3.20 (no factor 2) do not give the identity at equal levels, which Fig. 3.11 requires.
/// `l` are the corners' vertex levels (positive).
pub fn warp(b: [f32; 3], l: [f32; 3]) -> [f32; 3] {
    let [u, v, w] = b;
    let w210 = l[0] / (l[0] + l[1]);
    let w120 = l[1] / (l[0] + l[1]);
    let w021 = l[1] / (l[1] + l[2]);
    let w012 = l[2] / (l[1] + l[2]);
    let w201 = l[0] / (l[2] + l[0]);
    let w102 = l[2] / (l[2] + l[0]);
    [
        u * u + 2.0 * (w210 * u * v + w201 * u * w),
        v * v + 2.0 * (w120 * u * v + w021 * v * w),
        w * w + 2.0 * (w012 * v * w + w102 * u * w),
    ]
}

/// The warp restricted to an edge from a (level `la`) to b (level `lb`): the parameter
/// `t` (0 at a) maps to t^2 + 2 W_b t (1 - t), W_b = lb / (la + lb) (eq. 3.25 on that edge).
pub fn warp_edge(t: f32, la: f32, lb: f32) -> f32 {
    let wb = lb / (la + lb);
    t * t + 2.0 * wb * t * (1.0 - t)
}

/// The level a vertex asks for (section 4.1.3; the formula is this project's choice, see
/// docs/tessellation.md): logarithmic in the camera distance `d` between `near` (max level)
/// and `far` (level 1), raised by up to `silhouette` times at grazing view angles.
pub fn vertex_level(p: Vec3, n: Vec3, eye: Vec3, lod: &Lod) -> f32 {
    let to = p - eye;
    let d = to.length().max(1e-6);
    let near = lod.near.max(1e-6);
    let far = lod.far.max(near * (1.0 + 1e-6));
    let f = ((far / d).ln() / (far / near).ln()).clamp(0.0, 1.0);
    let distance = 1.0 + (lod.max_level - 1.0) * f;
    let grazing = 1.0 - (to / d).dot(n.normalize_or_zero()).abs();
    (distance * (1.0 + lod.silhouette * grazing)).clamp(1.0, lod.max_level)
}

/// The level of an edge from its two vertex levels: symmetric, so neighbours agree.
pub fn edge_level(la: f32, lb: f32, max_level: u32) -> u32 {
    ((0.5 * (la + lb)).ceil() as u32).clamp(1, max_level.max(1))
}

/// Level-of-detail settings shared with the compute shader.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Lod {
    pub near: f32,
    pub far: f32,
    pub max_level: f32,
    pub silhouette: f32,
}

/// A triangle's corners, for evaluation.
#[derive(Clone, Copy, Debug)]
pub struct Corner {
    pub p: Vec3,
    pub n: Vec3,
    pub uv: Vec2,
    pub tu: Vec3,
    pub tv: Vec3,
    /// The vertex level (warping).
    pub level: f32,
}

impl Corner {
    pub fn of(mesh: &crate::mesh::Mesh, i: usize, level: f32) -> Corner {
        let get3 = |v: &Vec<Vec3>| v.get(i).copied().unwrap_or(Vec3::ZERO);
        Corner {
            p: mesh.positions[i],
            n: get3(&mesh.normals),
            uv: mesh.uvs.get(i).copied().unwrap_or(Vec2::ZERO),
            tu: get3(&mesh.tangents_u),
            tv: get3(&mesh.tangents_v),
            level,
        }
    }
    fn vertex(&self) -> Vertex {
        Vertex {
            position: self.p.to_array(),
            normal: self.n.to_array(),
            tangent_u: self.tu.to_array(),
            uv: self.uv.to_array(),
            tangent_v: self.tv.to_array(),
        }
    }
}

/// The PN triangle [VPBM01] edge control point next to `pi` toward `pj`.
fn pn_edge(pi: Vec3, ni: Vec3, pj: Vec3) -> Vec3 {
    (2.0 * pi + pj - (pj - pi).dot(ni) * ni) / 3.0
}

/// The PN triangle's quadratic normal control point of edge i-j.
fn pn_normal(pi: Vec3, ni: Vec3, pj: Vec3, nj: Vec3) -> Vec3 {
    let d = pj - pi;
    let dd = d.dot(d);
    let v = if dd > 0.0 { 2.0 * d.dot(ni + nj) / dd } else { 0.0 };
    (ni + nj - v * d).normalize_or_zero()
}

/// A point on the edge a -> b at (warped) parameter t, from the edge's data alone.
fn edge_vertex(a: &Corner, b: &Corner, t: f32, pn: bool) -> Vertex {
    let s = 1.0 - t;
    let (p, n) = if pn {
        let b210 = pn_edge(a.p, a.n, b.p);
        let b120 = pn_edge(b.p, b.n, a.p);
        let p = a.p * (s * s * s) + b210 * (3.0 * s * s * t) + b120 * (3.0 * s * t * t) + b.p * (t * t * t);
        let n110 = pn_normal(a.p, a.n, b.p, b.n);
        (p, a.n * (s * s) + n110 * (s * t) + b.n * (t * t))
    } else {
        (a.p * s + b.p * t, a.n * s + b.n * t)
    };
    Vertex {
        position: p.to_array(),
        normal: n.normalize_or_zero().to_array(),
        tangent_u: (a.tu * s + b.tu * t).normalize_or_zero().to_array(),
        uv: (a.uv * s + b.uv * t).to_array(),
        tangent_v: (a.tv * s + b.tv * t).normalize_or_zero().to_array(),
    }
}

/// A point inside the triangle at (warped) barycentrics `w`.
fn interior_vertex(c: &[Corner; 3], w: [f32; 3], pn: bool) -> Vertex {
    let [u, v, x] = w;
    let lin3 = |f: fn(&Corner) -> Vec3| f(&c[0]) * u + f(&c[1]) * v + f(&c[2]) * x;
    let (p, n) = if pn {
        let (p0, p1, p2) = (c[0].p, c[1].p, c[2].p);
        let (n0, n1, n2) = (c[0].n, c[1].n, c[2].n);
        let b210 = pn_edge(p0, n0, p1);
        let b120 = pn_edge(p1, n1, p0);
        let b021 = pn_edge(p1, n1, p2);
        let b012 = pn_edge(p2, n2, p1);
        let b102 = pn_edge(p2, n2, p0);
        let b201 = pn_edge(p0, n0, p2);
        let e = (b210 + b120 + b021 + b012 + b102 + b201) / 6.0;
        let b111 = e + (e - (p0 + p1 + p2) / 3.0) / 2.0;
        let p = p0 * (u * u * u)
            + p1 * (v * v * v)
            + p2 * (x * x * x)
            + b210 * (3.0 * u * u * v)
            + b120 * (3.0 * u * v * v)
            + b021 * (3.0 * v * v * x)
            + b012 * (3.0 * v * x * x)
            + b102 * (3.0 * u * x * x)
            + b201 * (3.0 * u * u * x)
            + b111 * (6.0 * u * v * x);
        let n = n0 * (u * u)
            + n1 * (v * v)
            + n2 * (x * x)
            + pn_normal(p0, n0, p1, n1) * (u * v)
            + pn_normal(p1, n1, p2, n2) * (v * x)
            + pn_normal(p2, n2, p0, n0) * (u * x);
        (p, n)
    } else {
        (lin3(|c| c.p), lin3(|c| c.n))
    };
    Vertex {
        position: p.to_array(),
        normal: n.normalize_or_zero().to_array(),
        tangent_u: lin3(|c| c.tu).normalize_or_zero().to_array(),
        uv: (c[0].uv * u + c[1].uv * v + c[2].uv * x).to_array(),
        tangent_v: lin3(|c| c.tv).normalize_or_zero().to_array(),
    }
}

/// Evaluates a patch point of the triangle with corners `c` (mesh indices `ids`) and edge
/// levels `n`: corners copied, edge points from the edge alone in canonical orientation
/// (lower mesh index first), interior points warped (if `warping`) and PN-evaluated (if `pn`).
pub fn eval_point(point: PatchPoint, c: &[Corner; 3], ids: [u32; 3], n: [u32; 3], warping: bool, pn: bool) -> Vertex {
    match point {
        PatchPoint::Corner(k) => c[k as usize].vertex(),
        PatchPoint::Edge { edge, i } => {
            let (e0, e1) = (edge as usize, ((edge + 1) % 3) as usize);
            let level = n[e0];
            let (a, b, ic) = if ids[e0] < ids[e1] { (e0, e1, i) } else { (e1, e0, level - i) };
            let mut t = ic as f32 / level as f32;
            if warping {
                t = warp_edge(t, c[a].level, c[b].level);
            }
            edge_vertex(&c[a], &c[b], t, pn)
        }
        PatchPoint::Interior(b) => {
            let w = if warping { warp(b, [c[0].level, c[1].level, c[2].level]) } else { b };
            interior_vertex(c, w, pn)
        }
    }
}

/// Settings of one tessellation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Settings {
    pub mode: Mode,
    /// The level of every edge in uniform mode, and the cap on edge levels in the others.
    pub max_level: u32,
    pub pn: bool,
}

/// The edge levels of triangle `ids` (edge e from corner e to e + 1) from vertex levels
/// (rounded up to powers of two in dyadic mode).
pub fn triangle_edge_levels(levels: &[f32], ids: [u32; 3], s: &Settings) -> [u32; 3] {
    if s.mode == Mode::Uniform {
        return [s.max_level.max(1); 3];
    }
    let n =
        std::array::from_fn(|e| edge_level(levels[ids[e] as usize], levels[ids[(e + 1) % 3] as usize], s.max_level));
    if s.mode == Mode::Dyadic { n.map(dyadic) } else { n }
}

/// The CPU reference of the whole compute pass: every triangle of `mesh` refined with the
/// given per-vertex levels; vertices are not shared between triangles (as on the GPU).
pub fn tessellate(mesh: &crate::mesh::Mesh, levels: &[f32], s: &Settings) -> (Vec<Vertex>, Vec<u32>) {
    let (mut vertices, mut indices) = (Vec::new(), Vec::new());
    for tri in mesh.indices.chunks_exact(3) {
        let ids = [tri[0], tri[1], tri[2]];
        let c = ids.map(|i| Corner::of(mesh, i as usize, levels[i as usize]));
        let n = triangle_edge_levels(levels, ids, s);
        let flip = std::array::from_fn(|e| ids[e] > ids[(e + 1) % 3]);
        let patch = refine(n, s.mode == Mode::Dyadic, flip);
        let first = vertices.len() as u32;
        vertices.extend(patch.points.iter().map(|&p| eval_point(p, &c, ids, n, s.mode.warps(), s.pn)));
        indices.extend(patch.triangles.iter().flatten().map(|i| first + i));
    }
    (vertices, indices)
}

/// What the level metrics look at: the camera and the viewport.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ViewLod {
    pub view_proj: glam::Mat4,
    pub eye: Vec3,
    pub width: f32,
    pub height: f32,
    pub lod: Lod,
    pub metric: Metric,
    /// The edge-length metric's target, in pixels.
    pub max_edge_px: f32,
}

/// The vertex levels the compute shader's first passes choose (`vertex_levels`,
/// `edge_lengths`), on the CPU: for the wireframe output and tests.
pub fn cpu_vertex_levels(mesh: &crate::mesh::Mesh, view: &ViewLod) -> Vec<f32> {
    match view.metric {
        Metric::Distance => (0..mesh.positions.len())
            .map(|i| {
                vertex_level(mesh.positions[i], mesh.normals.get(i).copied().unwrap_or(Vec3::ZERO), view.eye, &view.lod)
            })
            .collect(),
        Metric::EdgeLength => {
            let screen = |p: Vec3| {
                let c = view.view_proj * p.extend(1.0);
                Vec2::new(c.x, c.y) / c.w.max(1e-4) * 0.5 * Vec2::new(view.width, view.height)
            };
            let mut levels = vec![1.0f32; mesh.positions.len()];
            for t in mesh.indices.chunks_exact(3) {
                for e in 0..3 {
                    let (a, b) = (t[e] as usize, t[(e + 1) % 3] as usize);
                    let len = screen(mesh.positions[a]).distance(screen(mesh.positions[b]));
                    let l = (len / view.max_edge_px.max(1e-3)).clamp(1.0, view.lod.max_level);
                    levels[a] = levels[a].max(l);
                    levels[b] = levels[b].max(l);
                }
            }
            levels
        }
    }
}

/// A triangle list as a mesh, vertices with bit-identical attributes merged (the tessellation's
/// shared edge vertices are bit-identical, so neighbouring patches join up).
pub fn welded_mesh(vertices: &[Vertex], indices: &[u32]) -> anyhow::Result<crate::mesh::Mesh> {
    let mut first: std::collections::HashMap<[u32; 14], u32> = std::collections::HashMap::new();
    let (mut p, mut n, mut uv, mut remap) = (Vec::new(), Vec::new(), Vec::new(), Vec::with_capacity(vertices.len()));
    for v in vertices {
        let key: [u32; 14] = bytemuck::cast(*v);
        let id = *first.entry(key).or_insert_with(|| {
            p.push(Vec3::from(v.position));
            n.push(Vec3::from(v.normal));
            uv.push(Vec2::from(v.uv));
            p.len() as u32 - 1
        });
        remap.push(id);
    }
    let idx = indices.iter().map(|&i| remap[i as usize]).collect();
    crate::mesh::Mesh::build(p, Some(uv), Some(n), idx)
}

/// Every edge of a triangle list as a thin ribbon of `width`, lifted by half its width along
/// the vertex normals so that it lies on top of the surface (wireframe figures).
pub fn wireframe(vertices: &[Vertex], indices: &[u32], width: f32) -> anyhow::Result<crate::mesh::Mesh> {
    let mut seen = std::collections::HashSet::new();
    let (mut p, mut n, mut idx) = (Vec::new(), Vec::new(), Vec::new());
    for t in indices.chunks_exact(3) {
        for e in 0..3 {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            if !seen.insert((a.min(b), a.max(b))) {
                continue;
            }
            let (va, vb) = (&vertices[a as usize], &vertices[b as usize]);
            let (pa, pb) = (Vec3::from(va.position), Vec3::from(vb.position));
            let normal = (Vec3::from(va.normal) + Vec3::from(vb.normal)).normalize_or(Vec3::Y);
            let side = (pb - pa).cross(normal).normalize_or_zero() * (0.5 * width);
            let lift = normal * (0.5 * width);
            let first = p.len() as u32;
            p.extend([pa - side + lift, pa + side + lift, pb + side + lift, pb - side + lift]);
            n.extend([normal; 4]);
            idx.extend([first, first + 1, first + 2, first, first + 2, first + 3]);
        }
    }
    anyhow::ensure!(!p.is_empty(), "nothing to draw a wireframe of");
    let mut mesh = crate::mesh::Mesh::build(p, None, Some(n), idx)?;
    mesh.repairs.clear();
    Ok(mesh)
}

/// shaders/tessellation/tessellate.wgsl `Params`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    lod: [f32; 4],
    screen: [f32; 4],
    mode: u32,
    max_level: u32,
    pn: u32,
    metric: u32,
    tri_count: u32,
    vertex_count: u32,
    pad: [u32; 2],
}

/// Bytes of one `DrawIndexedIndirectArgs`.
const INDIRECT_BYTES: u64 = 20;

/// A tessellated mesh that lives on the GPU only: vertex and index buffers written by the
/// compute pass and indirect draw arguments (one instance; a depth target draws it once per
/// tile).
pub struct TessMesh {
    pub vertices: crate::gpu::PooledBuffer,
    pub indices: crate::gpu::PooledBuffer,
    pub indirect: crate::gpu::PooledBuffer,
    /// The vertex levels used (f32), for inspection.
    pub levels: crate::gpu::PooledBuffer,
    /// Per input triangle its first output vertex and index (after the scan).
    pub offsets: crate::gpu::PooledBuffer,
    pub vertex_capacity: u64,
    pub index_capacity: u64,
    /// What it was made with, so the CPU reference can redo it (export on a CPU adapter).
    pub settings: Settings,
    pub view: ViewLod,
    /// Levels given per vertex instead of the view's metric.
    pub given_levels: Option<Vec<f32>>,
}

impl std::fmt::Debug for TessMesh {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "TessMesh(capacity {} vertices, {} indices)", self.vertex_capacity, self.index_capacity)
    }
}

/// The most vertices and triangles one triangle can produce at `max_level` in `mode`: the
/// uniform grid of that level bounds the pattern (tested in `counts_are_bounded_by_the_uniform_grid`).
pub fn patch_capacity(mode: Mode, max_level: u32) -> (u32, u32) {
    let m = if mode == Mode::Dyadic { dyadic(max_level) } else { max_level.max(1) };
    ((m + 1) * (m + 2) / 2, m * m)
}

/// The compute passes of shaders/tessellation/tessellate.wgsl, kept between frames.
pub struct GpuTessellator {
    vertex_levels: crate::gpu::ComputePass,
    edge_lengths: crate::gpu::ComputePass,
    count: crate::gpu::ComputePass,
    scan: crate::gpu::ComputePass,
    generate: crate::gpu::ComputePass,
}

impl Default for GpuTessellator {
    fn default() -> Self {
        use crate::gpu::ComputePass;
        GpuTessellator {
            vertex_levels: ComputePass::new("tessellate.wgsl", "vertex_levels"),
            edge_lengths: ComputePass::new("tessellate.wgsl", "edge_lengths"),
            count: ComputePass::new("tessellate.wgsl", "count"),
            scan: ComputePass::new("tessellate.wgsl", "scan"),
            generate: ComputePass::new("tessellate.wgsl", "generate"),
        }
    }
}

impl GpuTessellator {
    /// Records the tessellation of `mesh` into the current frame: vertex levels from `view`
    /// (or `levels`, one per vertex, where given), then counts, offsets and the patches.
    /// Nothing is read back; draw the result with its indirect arguments.
    pub fn run(
        &mut self,
        gpu: &crate::gpu::GpuContext,
        mesh: &crate::mesh::Mesh,
        levels: Option<&[f32]>,
        view: &ViewLod,
        s: &Settings,
    ) -> anyhow::Result<TessMesh> {
        use crate::gpu::{Bind, ComputePass};
        use wgpu::BufferUsages as U;
        let tris = mesh.triangle_count();
        let verts = mesh.positions.len();
        anyhow::ensure!(tris > 0, "the mesh has no triangles to tessellate");
        anyhow::ensure!((1..=64).contains(&s.max_level), "max_level must be 1 to 64, not {}", s.max_level);
        let (pv, pt) = patch_capacity(s.mode, s.max_level);
        let vertex_capacity = tris as u64 * u64::from(pv);
        let index_capacity = tris as u64 * u64::from(pt) * 3;
        let vertex_bytes = vertex_capacity * std::mem::size_of::<Vertex>() as u64;
        let limits = gpu.device.limits();
        let limit = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
        if vertex_bytes.max(index_capacity * 4) > limit {
            anyhow::bail!(
                "{tris} triangles at max_level {} ({}) may need {} MB of vertices, more than this GPU's {} MB \
                 per buffer: lower max_level or tessellate a coarser mesh",
                s.max_level,
                crate::core::param::Choice::name(s.mode),
                vertex_bytes >> 20,
                limit >> 20
            );
        }
        let metric = match (levels, view.metric) {
            (Some(_), _) => 2,
            (None, Metric::Distance) => 0,
            (None, Metric::EdgeLength) => 1,
        };
        let params = Params {
            view_proj: view.view_proj.to_cols_array_2d(),
            eye: view.eye.extend(1.0).to_array(),
            lod: [view.lod.near, view.lod.far, view.lod.max_level.max(1.0), view.lod.silhouette],
            screen: [view.width, view.height, view.max_edge_px, 0.0],
            mode: s.mode.index(),
            max_level: s.max_level,
            pn: u32::from(s.pn),
            metric,
            tri_count: tris as u32,
            vertex_count: verts as u32,
            pad: [0; 2],
        };
        let source = mesh.gpu(gpu);
        let level_buffer = match levels {
            Some(l) => {
                anyhow::ensure!(l.len() == verts, "{} vertex levels for {verts} vertices", l.len());
                anyhow::ensure!(
                    l.iter().all(|x| x.is_finite() && *x >= 1.0),
                    "vertex levels must be finite and at least 1"
                );
                gpu.upload_pooled("tessellation levels", bytemuck::cast_slice(l), U::STORAGE | U::COPY_SRC)
            }
            None => gpu.scratch_pooled("tessellation levels", verts as u64 * 4, U::STORAGE | U::COPY_SRC),
        };
        let offsets = gpu.scratch_pooled("tessellation offsets", tris as u64 * 8, U::STORAGE | U::COPY_SRC);
        let vertices = gpu.scratch_pooled("tessellated vertices", vertex_bytes, U::STORAGE | U::VERTEX | U::COPY_SRC);
        let indices =
            gpu.scratch_pooled("tessellated indices", index_capacity * 4, U::STORAGE | U::INDEX | U::COPY_SRC);
        let indirect =
            gpu.scratch_pooled("tessellation indirect", INDIRECT_BYTES, U::STORAGE | U::INDIRECT | U::COPY_SRC);
        let binds = [
            Bind::Uniform(bytemuck::bytes_of(&params)),
            Bind::Storage(&source.vertices),
            Bind::Storage(&source.indices),
            Bind::StorageRw(&level_buffer),
            Bind::StorageRw(&offsets),
            Bind::StorageRw(&vertices),
            Bind::StorageRw(&indices),
            Bind::StorageRw(&indirect),
        ];
        let per_vertex = ComputePass::groups_for(verts, 64);
        let per_triangle = ComputePass::groups_for(tris, 64);
        if metric != 2 {
            self.vertex_levels.dispatch(gpu, &[&binds], per_vertex)?;
        }
        if metric == 1 {
            self.edge_lengths.dispatch(gpu, &[&binds], per_triangle)?;
        }
        self.count.dispatch(gpu, &[&binds], per_triangle)?;
        self.scan.dispatch(gpu, &[&binds], [1, 1, 1])?;
        self.generate.dispatch(gpu, &[&binds], per_triangle)?;
        Ok(TessMesh {
            vertices,
            indices,
            indirect,
            levels: level_buffer,
            offsets,
            vertex_capacity,
            index_capacity,
            settings: *s,
            view: *view,
            given_levels: levels.map(<[f32]>::to_vec),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    fn bary_of(p: PatchPoint, n: [u32; 3]) -> [f32; 3] {
        match p {
            PatchPoint::Corner(k) => {
                let mut b = [0.0; 3];
                b[k as usize] = 1.0;
                b
            }
            PatchPoint::Edge { edge, i } => {
                let t = i as f32 / n[edge as usize] as f32;
                let mut b = [0.0; 3];
                b[edge as usize] = 1.0 - t;
                b[((edge + 1) % 3) as usize] = t;
                b
            }
            PatchPoint::Interior(b) => b,
        }
    }

    /// Signed doubled area of a patch triangle in the (b1, b2) plane.
    fn area(p: &Patch, n: [u32; 3], t: [u32; 3]) -> f32 {
        let q = t.map(|i| bary_of(p.points[i as usize], n));
        (q[1][1] - q[0][1]) * (q[2][2] - q[0][2]) - (q[1][2] - q[0][2]) * (q[2][1] - q[0][1])
    }

    #[test]
    fn all_edges_at_level_n_give_n_squared_triangles() {
        for n in 1..=12 {
            for dy in [false, true] {
                let p = refine([n; 3], dy, [false; 3]);
                let m = if dy { dyadic(n) } else { n };
                assert_eq!(p.triangles.len() as u32, m * m, "level {n} dyadic {dy}");
                assert_eq!(counts([n; 3], dy), (p.points.len() as u32, m * m));
            }
        }
    }

    #[test]
    fn levels_1_8_8_give_15_triangles_where_semi_uniform_gives_64() {
        for rot in 0..3 {
            let mut n = [8; 3];
            n[rot] = 1;
            assert_eq!(refine(n, false, [false; 3]).triangles.len(), 15);
            assert_eq!(refine(n, true, [false; 3]).triangles.len(), 64);
        }
    }

    /// The patch covers the triangle exactly once, every triangle counter-clockwise and not
    /// degenerate (pattern modes), every edge of level n has its n + 1 uniform vertices.
    fn check_patch(n: [u32; 3]) {
        let p = refine(n, false, [false; 3]);
        assert_eq!(counts(n, false), (p.points.len() as u32, p.triangles.len() as u32), "{n:?}");
        let mut total = 0.0;
        for &t in &p.triangles {
            let a = area(&p, n, t);
            assert!(a > 1e-7, "{n:?}: triangle {t:?} has area {a}");
            total += a;
        }
        assert!((total - 1.0).abs() < 1e-4, "{n:?}: area {total}");
        for e in 0..3u32 {
            let mut on: Vec<u32> = p
                .points
                .iter()
                .filter_map(|q| match *q {
                    PatchPoint::Edge { edge, i } if edge == e => Some(i),
                    _ => None,
                })
                .collect();
            on.sort();
            on.dedup();
            assert_eq!(on, (1..n[e as usize]).collect::<Vec<_>>(), "{n:?} edge {e}");
        }
        // Boundary edges of the patch (used once) lie on the triangle's edges and number
        // the sum of the levels: no T-junctions inside, no gaps.
        let mut count = std::collections::HashMap::new();
        for t in &p.triangles {
            for k in 0..3 {
                let (a, b) = (t[k], t[(k + 1) % 3]);
                *count.entry((a.min(b), a.max(b))).or_insert(0) += 1;
            }
        }
        let boundary = count.values().filter(|&&c| c == 1).count() as u32;
        assert!(count.values().all(|&c| c <= 2), "{n:?}");
        let (v, t) = counts(n, false);
        let cap = patch_capacity(Mode::Pattern, n.into_iter().max().unwrap());
        assert!(v <= cap.0 && t <= cap.1, "{n:?}: {v} vertices, {t} triangles over the capacity {cap:?}");
        assert_eq!(boundary, n.iter().sum::<u32>(), "{n:?}");
    }

    /// Also checks the counts are bounded by the uniform grid (`patch_capacity`).
    #[test]
    fn the_pattern_tiles_the_triangle_for_all_small_levels() {
        for a in 1..=9 {
            for b in 1..=9 {
                for c in 1..=9 {
                    check_patch([a, b, c]);
                }
            }
        }
    }

    #[test]
    fn two_low_edges_and_one_high_edge_put_the_strip_on_the_high_edge() {
        let s = split([2, 8, 2]);
        assert!(s.special);
        assert_eq!((s.rot, s.base, s.m, s.rows), (1, 8, 1, 1));
        // 1 top triangle + a strip of 8 + 1 triangles, no fan of 7 from one corner.
        assert_eq!(refine([2, 8, 2], false, [false; 3]).triangles.len(), 10);
        assert!(!split([2, 8, 8]).special && !split([3, 3, 3]).special);
    }

    proptest! {
        #[test]
        fn warped_barycentrics_sum_to_one_stay_non_negative_and_on_their_edge(
            u in 0.0f32..1.0, v in 0.0f32..1.0, l0 in 1.0f32..64.0, l1 in 1.0f32..64.0, l2 in 1.0f32..64.0,
        ) {
            let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
            let b = [u, v, 1.0 - u - v];
            let w = warp(b, [l0, l1, l2]);
            prop_assert!((w[0] + w[1] + w[2] - 1.0).abs() < 1e-6);
            prop_assert!(w.iter().all(|&x| x >= 0.0));
            // On edge w = 0 the third coordinate stays exactly 0 and the edge warp agrees.
            let e = warp([u / (u + v), v / (u + v), 0.0], [l0, l1, l2]);
            prop_assert_eq!(e[2], 0.0);
            prop_assert!((e[1] - warp_edge(v / (u + v), l0, l1)).abs() < 1e-6);
        }

        #[test]
        fn equal_levels_leave_barycentrics_unchanged(u in 0.0f32..1.0, v in 0.0f32..1.0, l in 1.0f32..64.0) {
            let (u, v) = if u + v > 1.0 { (1.0 - u, 1.0 - v) } else { (u, v) };
            let b = [u, v, 1.0 - u - v];
            let w = warp(b, [l; 3]);
            for k in 0..3 {
                prop_assert!((w[k] - b[k]).abs() < 1e-6, "{:?} -> {:?}", b, w);
            }
        }
    }

    /// TECHNIQUES.md's erratum: eqs. 3.18-3.20 as printed (no factor 2) are not the identity
    /// at equal levels (f_u = u (1 + u) / 2), so Fig. 3.11's property needs the Bezier form.
    #[test]
    fn the_printed_warp_is_not_the_identity_at_equal_levels() {
        let printed = |[u, v, w]: [f32; 3]| u * u + 0.5 * u * v + 0.5 * u * w;
        let b = [0.2, 0.3, 0.5];
        assert!((printed(b) - b[0]).abs() > 0.05);
        assert!((warp(b, [3.0; 3])[0] - b[0]).abs() < 1e-6);
    }

    #[test]
    fn raising_a_vertex_level_pulls_vertices_toward_it() {
        let mean_b0 = |l0: f32| {
            let p = refine([6, 6, 6], false, [false; 3]);
            let s: f32 = p.points.iter().map(|&q| warp(bary_of(q, [6; 3]), [l0, 2.0, 2.0])[0]).sum();
            s / p.points.len() as f32
        };
        let (a, b, c) = (mean_b0(2.0), mean_b0(4.0), mean_b0(8.0));
        assert!(a < b && b < c, "{a} {b} {c}");
    }

    /// Two triangles sharing an edge, refined uniformly to level n and welded: (n + 1)^2
    /// vertices, so the shared edge's vertices are the same from both sides.
    #[test]
    fn a_welded_uniform_quad_has_n_plus_1_squared_vertices() {
        let quad = crate::mesh::Mesh::build(
            vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 0.0, 1.0), Vec3::Z],
            None,
            Some(vec![Vec3::Y; 4]),
            vec![0, 3, 1, 1, 3, 2],
        )
        .unwrap();
        for mode in [Mode::Uniform, Mode::PatternWarp] {
            for n in [1, 2, 5, 8] {
                let s = Settings { mode, max_level: n, pn: true };
                let (v, i) = tessellate(&quad, &[n as f32; 4], &s);
                let m = welded_mesh(&v, &i).unwrap();
                assert_eq!(m.positions.len() as u32, (n + 1) * (n + 1), "{mode:?} level {n}");
                assert_eq!(m.triangle_count() as u32, 2 * n * n);
            }
        }
    }

    #[test]
    fn dyadic_edges_snap_to_their_level() {
        let p = refine([1, 8, 8], true, [false; 3]);
        assert!(p.points.iter().all(|q| !matches!(q, PatchPoint::Edge { edge: 0, .. })));
        let p = refine([2, 8, 5], true, [false, false, true]);
        let on2: std::collections::BTreeSet<u32> = p
            .points
            .iter()
            .filter_map(|q| match *q {
                PatchPoint::Edge { edge: 2, i } => Some(i),
                _ => None,
            })
            .collect();
        assert_eq!(on2, (1..8).collect());
    }
}

//! Tessellation of a woven panel (Zhang et al. 2012, section 5): each patch at its own level L,
//! geomorphed (eqs. 17-20, see `lod`) and snapped at its borders against its neighbours (eq. 21).
//!
//! Crack snapping uses one state per shared edge: both patches evaluate the edge's vertices at
//! `L_edge = min(L_self, L_neighbour)`, on the edge's grid, with the edge's morph factors. The
//! printed eq. 21 rounds the coordinate across the edge and uses each patch's own morph, which
//! would reopen the cracks while the two sides morph differently. A tube ring on an edge whose
//! state is the panel scale collapses onto the panel's edge vertex, so no yarn hangs over a
//! panel-scale neighbour.

use std::f64::consts::TAU;

use glam::DVec3;

use super::lod::{LodState, MAX_LEVEL, Morph, Scale, along_points, bracket};
use super::panel::Panel;
use super::weave::Weave;
use super::yarn::{Dir, YarnParams, compose, fibre, height, yarn_frame, yarn_offset};

/// Triangles of one colour: the panel, the wefts or the warps.
#[derive(Clone, Debug, Default)]
pub struct Layer {
    pub positions: Vec<DVec3>,
    pub normals: Vec<DVec3>,
    /// The panel parameter (u, v) over the whole grid, in [0, 1].
    pub uvs: Vec<[f64; 2]>,
    pub indices: Vec<u32>,
    /// Whether each vertex lies on the panel's outer boundary (for the crack checks).
    pub outer: Vec<bool>,
}

impl Layer {
    pub fn triangles(&self) -> usize {
        self.indices.len() / 3
    }

    fn push(&mut self, p: DVec3, n: DVec3, uv: [f64; 2], outer: bool) -> u32 {
        self.positions.push(p);
        self.normals.push(n);
        self.uvs.push(uv);
        self.outer.push(outer);
        (self.positions.len() - 1) as u32
    }
}

/// A woven panel's triangles, and how many patches each scale drew.
#[derive(Clone, Debug, Default)]
pub struct Tessellation {
    pub panel: Layer,
    pub weft: Layer,
    pub warp: Layer,
    /// Patches at the panel, yarn and fibre scales.
    pub scales: [usize; 3],
}

impl Tessellation {
    pub fn triangles(&self) -> usize {
        self.panel.triangles() + self.weft.triangles() + self.warp.triangles()
    }
}

/// One yarn of one patch: `index` in 0..nodes counts wefts along v (warps along u).
#[derive(Clone, Copy, Debug)]
pub struct YarnRef {
    pub dir: Dir,
    pub pi: usize,
    pub pj: usize,
    pub index: usize,
}

/// Everything that defines a woven panel's geometry.
pub struct Woven<'a> {
    pub panel: &'a Panel,
    pub weave: &'a Weave,
    pub yarn: &'a YarnParams,
    pub morph: Morph,
    /// Eq. 21's crack snapping at shared patch borders; off (for Fig. 9 only), every border is
    /// evaluated as an outer one and T-junctions open.
    pub snap: bool,
}

impl Woven<'_> {
    fn n(&self) -> f64 {
        self.yarn.nodes as f64
    }

    /// The panel's drawn vertex at (s, t) of patch (pi, pj) in state `st` (eqs. 17/18) and its
    /// normal.
    pub fn panel_vertex(&self, pi: usize, pj: usize, s: f64, t: f64, st: &LodState) -> (DVec3, DVec3) {
        (self.panel_term(pi, pj, s, t, st), self.panel.frame(pi, pj, s, t).n)
    }

    /// Eq. 18: the panel on a g x g grid, bilinearly.
    fn panel_bilinear(&self, pi: usize, pj: usize, s: f64, t: f64, g: f64) -> DVec3 {
        let (s0, t0) = (((s * g).floor()).min(g - 1.0), ((t * g).floor()).min(g - 1.0));
        let (ws, wt) = (s * g - s0, t * g - t0);
        let at = |a: f64, b: f64| self.panel.position(pi, pj, a / g, b / g);
        let (p00, p10, p01, p11) = (at(s0, t0), at(s0 + 1.0, t0), at(s0, t0 + 1.0), at(s0 + 1.0, t0 + 1.0));
        (1.0 - wt) * ((1.0 - ws) * p00 + ws * p10) + wt * ((1.0 - ws) * p01 + ws * p11)
    }

    /// The morphed panel point at (s, t): at the panel scale toward the next coarser panel grid
    /// (eq. 17), at the yarn scale the panel term l~_p under the yarns (toward the finest grid).
    fn panel_term(&self, pi: usize, pj: usize, s: f64, t: f64, st: &LodState) -> DVec3 {
        let exact = self.panel.position(pi, pj, s, t);
        let (w, g) = match st.scale {
            Scale::Panel if st.grid > 0 => (st.alpha, (st.panel_res() / 2) as f64),
            Scale::Panel => (0.0, 1.0),
            Scale::Yarn | Scale::Fibre => (st.alpha_panel, 8.0),
        };
        if w > 0.0 { (1.0 - w) * exact + w * self.panel_bilinear(pi, pj, s, t, g) } else { exact }
    }

    /// Patch-local (s, t) of a point of a yarn at yarn parameter `u` (relative to the patch's first node).
    fn yarn_st(&self, y: YarnRef, u: f64) -> (f64, f64) {
        let n = self.n();
        let (along, across) = ((u + 0.5) / n, (y.index as f64 + 0.5) / n);
        match y.dir {
            Dir::Weft => (along, across),
            Dir::Warp => (across, along),
        }
    }

    /// Eq. 19 at a tube point: yarn `y` (fibre `f` at the fibre scale), yarn parameter `u`, shell
    /// angle θ, unmorphed. `flat`: the ring is two-sided (two vertices), so its normal is the
    /// yarn's.
    pub fn tube_point(
        &self,
        y: YarnRef,
        f: Option<usize>,
        u: f64,
        theta: f64,
        st: &LodState,
        flat: bool,
    ) -> (DVec3, DVec3) {
        let p = self.yarn;
        let nodes = p.nodes;
        let (s, t) = self.yarn_st(y, u);
        let lp = self.panel_term(y.pi, y.pj, s, t, st);
        let mp = self.panel.frame(y.pi, y.pj, s, t);
        let (line, first) = match y.dir {
            Dir::Weft => (y.pj * nodes + y.index, y.pi * nodes),
            Dir::Warp => (y.pi * nodes + y.index, y.pj * nodes),
        };
        let ug = first as f64 + u;
        let (h, dh) = height(self.weave, y.dir, line as i64, ug);
        let my = yarn_frame(y.dir, p.spacing, p.crimp, dh);
        let ly = yarn_offset(p.crimp, h);
        let axial = p.spacing.hypot(p.crimp * dh);
        let fp = f.filter(|_| st.beta_f > 0.0).map(|i| fibre(p, i, ug, axial, st.beta_f));
        let k = if fp.is_some() { (1.0 - st.beta_f) * p.radius + st.beta_f * p.fibre_radius() } else { p.radius };
        let (pos, dir) = compose(lp, &mp, st.beta_y, ly, &my, fp.as_ref(), k, theta);
        (pos, if flat { mp.compose(&my).n } else { dir })
    }

    /// A drawn tube vertex: eq. 17 applied to the composed position, toward the bilinear
    /// interpolation (eq. 18, in u and θ) of the coarser tube grid.
    pub fn tube_vertex(&self, y: YarnRef, f: Option<usize>, u: f64, theta: f64, st: &LodState) -> (DVec3, DVec3) {
        let ring = LodState::tube_res(st.grid).1;
        let (p, n) = self.tube_point(y, f, u, theta, st, ring == 2);
        if st.alpha <= 0.0 || st.grid <= 5 {
            return (p, n);
        }
        let (ca, cr) = LodState::tube_res(st.grid - 1);
        let pts = along_points(ca, self.yarn.nodes);
        let (i, wu) = bracket(&pts, u);
        let x = theta * cr as f64 / TAU;
        let k0 = x.floor();
        let wt = x - k0;
        let th = |k: f64| k * TAU / cr as f64;
        let flat = cr == 2;
        let c = |a: f64, b: f64| self.tube_point(y, f, a, th(b), st, flat);
        let (p00, n00) = c(pts[i], k0);
        let (p10, n10) = c(pts[i + 1], k0);
        let (p01, n01) = c(pts[i], k0 + 1.0);
        let (p11, n11) = c(pts[i + 1], k0 + 1.0);
        let bil = |a: DVec3, b: DVec3, c: DVec3, d: DVec3| {
            (1.0 - wt) * ((1.0 - wu) * a + wu * b) + wt * ((1.0 - wu) * c + wu * d)
        };
        let pb = bil(p00, p10, p01, p11);
        let nb = bil(n00, n10, n01, n11);
        let a = st.alpha;
        ((1.0 - a) * p + a * pb, ((1.0 - a) * n + a * nb).try_normalize().unwrap_or(n))
    }

    /// Tessellates every patch at its level (`levels[pj * patches_u + pi]`; `None`: a patch
    /// outside the pattern piece, not drawn, its edges outer boundary).
    pub fn tessellate(&self, levels: &[Option<f64>]) -> anyhow::Result<Tessellation> {
        self.tessellate_culled(levels, &vec![false; levels.len()])
    }

    /// One level (or none) and one culled flag per patch, each level within [0, MAX_LEVEL]:
    /// what the CPU and the GPU tessellation both take.
    pub fn check_levels(&self, levels: &[Option<f64>], culled: &[bool]) -> anyhow::Result<()> {
        let (pu, pv) = (self.panel.patches_u, self.panel.patches_v);
        anyhow::ensure!(
            levels.len() == pu * pv && culled.len() == pu * pv,
            "{} levels for {pu}x{pv} patches",
            levels.len()
        );
        if let Some(l) = levels.iter().flatten().find(|l| !(0.0..=MAX_LEVEL).contains(*l)) {
            anyhow::bail!("level of detail {l} is outside [0, {MAX_LEVEL}]");
        }
        Ok(())
    }

    /// Like [`Woven::tessellate`], leaving out the patches with `culled[k]` set (outside the
    /// view); they keep their level for their neighbours' edges.
    pub fn tessellate_culled(&self, levels: &[Option<f64>], culled: &[bool]) -> anyhow::Result<Tessellation> {
        let (pu, pv) = (self.panel.patches_u, self.panel.patches_v);
        self.check_levels(levels, culled)?;
        let mut out = Tessellation::default();
        for pj in 0..pv {
            for pi in 0..pu {
                if let (Some(l), false) = (levels[pj * pu + pi], culled[pj * pu + pi]) {
                    self.tessellate_patch(pi, pj, l, levels, &mut out);
                }
            }
        }
        Ok(out)
    }

    /// The triangles one patch makes at level `l` (before degenerate ones are dropped).
    pub fn patch_triangles(&self, l: f64) -> usize {
        let st = LodState::at(l, self.morph);
        match st.scale {
            Scale::Panel => 2 * st.panel_res() * st.panel_res(),
            Scale::Yarn | Scale::Fibre => {
                let (sa, sr) = LodState::tube_res(st.grid);
                let segments = along_points(sa, self.yarn.nodes).len() - 1;
                let fibres = if st.scale == Scale::Fibre { self.yarn.fibres } else { 1 };
                2 * self.yarn.nodes * segments * sr * 2 * fibres
            }
        }
    }

    /// The level of the neighbour across an edge, if there is one (none without snapping).
    pub fn neighbour(&self, levels: &[Option<f64>], pi: isize, pj: isize) -> Option<f64> {
        let (pu, pv) = (self.panel.patches_u as isize, self.panel.patches_v as isize);
        let inside = self.snap && pi >= 0 && pj >= 0 && pi < pu && pj < pv;
        inside.then(|| levels[(pj * pu + pi) as usize]).flatten()
    }

    fn tessellate_patch(&self, pi: usize, pj: usize, l: f64, levels: &[Option<f64>], out: &mut Tessellation) {
        let (pu, pv) = (self.panel.patches_u, self.panel.patches_v);
        let st = LodState::at(l, self.morph);
        let (ii, jj) = (pi as isize, pj as isize);
        // Edge states: left, right, bottom, top (None on the outer boundary).
        let edge = |di: isize, dj: isize| {
            self.neighbour(levels, ii + di, jj + dj).map(|ln| LodState::at(l.min(ln), self.morph))
        };
        let edges = [edge(-1, 0), edge(1, 0), edge(0, -1), edge(0, 1)];
        let uv = |s: f64, t: f64| [(pi as f64 + s) / pu as f64, (pj as f64 + t) / pv as f64];
        match st.scale {
            Scale::Panel => {
                out.scales[0] += 1;
                let g = st.panel_res();
                let layer = &mut out.panel;
                let base = layer.positions.len() as u32;
                for b in 0..=g {
                    for a in 0..=g {
                        let (s, t) = (a as f64 / g as f64, b as f64 / g as f64);
                        let corner = (a == 0 || a == g) && (b == 0 || b == g);
                        let side = [a == 0, a == g, b == 0, b == g];
                        let outer = (0..4).any(|e| side[e] && edges[e].is_none());
                        let snapped = (0..4).find(|&e| side[e] && !corner).and_then(|e| edges[e].map(|se| (e, se)));
                        let (p, n) = match snapped {
                            Some((e, se)) => {
                                let ge = se.panel_res() as f64;
                                let snap = |x: f64| (x * ge).round() / ge;
                                let (s2, t2) = if e < 2 { (s, snap(t)) } else { (snap(s), t) };
                                self.panel_vertex(pi, pj, s2, t2, &se)
                            }
                            None => self.panel_vertex(pi, pj, s, t, &st),
                        };
                        layer.push(p, n, uv(s, t), outer);
                    }
                }
                let row = (g + 1) as u32;
                for b in 0..g as u32 {
                    for a in 0..g as u32 {
                        let v = base + b * row + a;
                        // Fronts along cross(du, dv), or reversed where the panel's normals
                        // are flipped: the fronts face the way the normals do.
                        let quad = if self.panel.flip {
                            [v, v + row + 1, v + 1, v, v + row, v + row + 1]
                        } else {
                            [v, v + 1, v + row + 1, v, v + row + 1, v + row]
                        };
                        layer.indices.extend_from_slice(&quad);
                    }
                }
            }
            Scale::Yarn | Scale::Fibre => {
                out.scales[if st.scale == Scale::Yarn { 1 } else { 2 }] += 1;
                let (sa, sr) = LodState::tube_res(st.grid);
                let along = along_points(sa, self.yarn.nodes);
                let fibres: Vec<Option<usize>> = match st.scale {
                    Scale::Fibre => (0..self.yarn.fibres).map(Some).collect(),
                    _ => vec![None],
                };
                for dir in [Dir::Weft, Dir::Warp] {
                    // The edges a yarn of this direction crosses: its start and its end.
                    let (start, end) = match dir {
                        Dir::Weft => (edges[0], edges[1]),
                        Dir::Warp => (edges[2], edges[3]),
                    };
                    let layer = match dir {
                        Dir::Weft => &mut out.weft,
                        Dir::Warp => &mut out.warp,
                    };
                    for index in 0..self.yarn.nodes {
                        let y = YarnRef { dir, pi, pj, index };
                        for &f in &fibres {
                            let base = layer.positions.len() as u32;
                            for (ai, &u) in along.iter().enumerate() {
                                let border = if ai == 0 {
                                    Some(start)
                                } else if ai + 1 == along.len() {
                                    Some(end)
                                } else {
                                    None
                                };
                                let (s, t) = self.yarn_st(y, u);
                                for k in 0..sr {
                                    let theta = k as f64 * TAU / sr as f64;
                                    let (p, n) = match border {
                                        Some(Some(se)) => self.edge_ring_vertex(y, f, u, theta, &se),
                                        _ => self.tube_vertex(y, f, u, theta, &st),
                                    };
                                    layer.push(p, n, uv(s, t), border.is_some_and(|e| e.is_none()));
                                }
                            }
                            let r = sr as u32;
                            for ai in 0..along.len() as u32 - 1 {
                                for k in 0..r {
                                    let k1 = (k + 1) % r;
                                    let (v00, v10) = (base + ai * r + k, base + (ai + 1) * r + k);
                                    let (v01, v11) = (base + ai * r + k1, base + (ai + 1) * r + k1);
                                    // Fronts outwards: the weft's rings run round its tubes
                                    // the other way than the warp's, and the warp's along
                                    // -dv, against its rings' order, where the panel is not
                                    // flipped.
                                    let quad = if dir == Dir::Weft || !self.panel.flip {
                                        [v00, v11, v10, v00, v01, v11]
                                    } else {
                                        [v00, v10, v11, v00, v11, v01]
                                    };
                                    layer.indices.extend_from_slice(&quad);
                                }
                            }
                        }
                    }
                }
            }
        }
    }

    /// A ring vertex on a shared edge, in the edge's state: θ snapped to the edge's ring (eq. 21);
    /// at the panel scale the ring collapses onto the panel's edge vertex.
    fn edge_ring_vertex(&self, y: YarnRef, f: Option<usize>, u: f64, theta: f64, se: &LodState) -> (DVec3, DVec3) {
        match se.scale {
            Scale::Panel => {
                let (s, t) = self.yarn_st(y, u);
                let ge = se.panel_res() as f64;
                let snap = |x: f64| (x * ge).round() / ge;
                let (s2, t2) = match y.dir {
                    Dir::Weft => (s, snap(t)),
                    Dir::Warp => (snap(s), t),
                };
                self.panel_vertex(y.pi, y.pj, s2, t2, se)
            }
            Scale::Yarn | Scale::Fibre => {
                let re = LodState::tube_res(se.grid).1 as f64;
                let th = (theta * re / TAU).round() * TAU / re;
                let f = if se.scale == Scale::Fibre { f } else { None };
                self.tube_vertex(y, f, u, th, se)
            }
        }
    }
}

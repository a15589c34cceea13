// Woven cloth at three scales in compute (Zhang et al. 2012, IDSS; docs/woven.md). The twin of
// src/woven/tess.rs, lod.rs, panel.rs and yarn.rs: each function here has the name and the
// arithmetic of its Rust original (f32 here, f64 there), but for the panel's bilinear grids,
// read from the lattice the CPU evaluates, and the border frames' neighbour derivatives, which
// read only the two columns of Bézier points next to the edge. The CPU plans the frame (src/woven/gpu.rs:
// each drawn patch's level, its four edge levels, its first vertex and index); four entry points
// fill one layer's buffers, one workgroup column per patch, as many rows (y of the dispatch) as
// the pass's largest patch needs; invocations stride by 64 x the rows:
//   panel_vertices  the patch's geomorphed, crack-snapped vertices, one invocation each;
//   tube_vertices   the same, one invocation per ring (no stride): the ring's panel point,
//                   frames and morph rings are evaluated once and shared by its vertices (they
//                   differ in θ only); dispatched twice, with MORPHS off for the patches under
//                   level 6;
//   panel_indices, tube_indices    its triangles, a quad per loop iteration.
// Lavapipe (llvmpipe), which CI and most users without a GPU run, executes both sides of every
// branch under a mask and a loop's body once more than it iterates: the cost of a ring is all the
// code it could take. So the panel's bilinear grids are read from a lattice, a border frame
// reads one neighbour per direction, a collapsed ring goes through the same evaluation as the
// others, and what only levels 6 and up need is compiled out by MORPHS.
// The parameters (the tube layer's direction too) sit in a storage buffer, not a uniform block:
// lavapipe specializes shaders on uniforms that branches read and would recompile this one per
// parameter change. Morph taps are loops with a run-time count, so the heavy tube point is
// compiled once, not once per tap (lavapipe's compile time grows with the inlined copies).

const TAU: f32 = 6.283185307179586;
const PI: f32 = 3.141592653589793;

struct Params {
    patches_u: u32,
    patches_v: u32,
    nodes: u32,
    fibres: u32,
    weave_w: u32,
    weave_h: u32,
    flip: u32,
    spacing: f32,
    crimp: f32,
    radius: f32,
    fibre_radius: f32,
    ring_radius: f32,
    migration: f32,
    omega: f32,
    // The tube layer's yarns: 0 weft, 1 warp.
    dir: u32,
}

// One drawn patch of this layer: (patch index, first vertex, first index, vertices), (level,
// indices, -, -) and the levels of its left, right, bottom and top neighbours (negative: none).
struct Plan {
    ids: vec4<u32>,
    level: vec4<f32>,
    edges: vec4<f32>,
}

@group(0) @binding(0) var<storage, read> params: Params;
// 16 Bézier points per patch, q[i][j] at 16 p + 4 i + j (i along u).
@group(0) @binding(1) var<storage, read> bezier: array<vec4<f32>>;
@group(0) @binding(2) var<storage, read> plans: array<Plan>;
// η row-major by weft, +1 weft over.
@group(0) @binding(3) var<storage, read> weave: array<i32>;
@group(0) @binding(4) var<storage, read_write> out_vertices: array<f32>;
@group(0) @binding(5) var<storage, read_write> out_indices: array<u32>;
// 9 x 9 points per patch, the patch at (a / 8, b / 8) at 81 p + 9 b + a: the corners of every
// bilinear panel the morphs blend toward (grids of 1, 2, 4 and 8 cells), read instead of
// evaluated (four Bézier evaluations a vertex).
@group(0) @binding(6) var<storage, read> lattice: array<vec4<f32>>;

// Whether this dispatch's patches may morph along their tubes or reach the fibre scale (level
// 6 or more): lavapipe runs both sides of every branch, so the coarse rings and the fibre terms
// are compiled out of the dispatch of the patches that need neither.
override MORPHS: bool = true;

// #include "vertex_out.wgsl"

// ---- panel.rs ----

fn bernstein(t: f32) -> vec4<f32> {
    let s = 1.0 - t;
    return vec4<f32>(s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t);
}

fn bernstein_d(t: f32) -> vec4<f32> {
    let s = 1.0 - t;
    return vec4<f32>(-3.0 * s * s, 3.0 * s * s - 6.0 * s * t, 6.0 * s * t - 3.0 * t * t, 3.0 * t * t);
}

fn patch_id(pi: u32, pj: u32) -> u32 {
    return pj * params.patches_u + pi;
}

struct Frame {
    t: vec3<f32>,
    n: vec3<f32>,
    b: vec3<f32>,
}

fn apply(f: Frame, l: vec3<f32>) -> vec3<f32> {
    return l.x * f.t + l.y * f.n + l.z * f.b;
}

fn compose_frames(a: Frame, o: Frame) -> Frame {
    return Frame(apply(a, o.t), apply(a, o.n), apply(a, o.b));
}

fn safe_normalize(v: vec3<f32>, fallback: vec3<f32>) -> vec3<f32> {
    let l = length(v);
    if l > 0.0 {
        return v / l;
    }
    return fallback;
}

fn from_derivatives(du: vec3<f32>, dv: vec3<f32>) -> Frame {
    let t = safe_normalize(du, vec3<f32>(1.0, 0.0, 0.0));
    var side_axis = vec3<f32>(0.0, 1.0, 0.0);
    if abs(t.y) > 0.9 {
        side_axis = vec3<f32>(0.0, 0.0, 1.0);
    }
    let n = safe_normalize(cross(du, dv), normalize(cross(t, side_axis)));
    return Frame(t, n, cross(n, t));
}

// The point and both derivatives of patch (pi, pj) at (s, t), each Bézier point read once
// (the sums of position, deriv_u and deriv_v, term for term).
struct Eval {
    p: vec3<f32>,
    du: vec3<f32>,
    dv: vec3<f32>,
}

fn evaluate(pi: u32, pj: u32, s: f32, t: f32) -> Eval {
    let pid = patch_id(pi, pj);
    let bu = bernstein(s);
    let bv = bernstein(t);
    let du = bernstein_d(s);
    let dv = bernstein_d(t);
    var e = Eval(vec3<f32>(0.0), vec3<f32>(0.0), vec3<f32>(0.0));
    for (var i = 0u; i < 4u; i++) {
        for (var j = 0u; j < 4u; j++) {
            let q = bezier[16u * pid + 4u * i + j].xyz;
            e.p += bu[i] * bv[j] * q;
            e.du += du[i] * bv[j] * q;
            e.dv += bu[i] * dv[j] * q;
        }
    }
    return e;
}

// The derivative of patch `pid` across one of its edges, at parameter x along it: only the
// two rows of Bézier points next to the edge weigh. `across`/`along`: the index steps of the
// two directions (4, 1 for deriv_u on s = 0 or 1; 1, 4 for deriv_v on t = 0 or 1); `far`: the
// edge at 1.
fn edge_deriv(pid: u32, far: bool, x: f32, across: u32, along: u32) -> vec3<f32> {
    let b = bernstein(x);
    let first = 16u * pid + select(0u, 2u, far) * across;
    var d = vec3<f32>(0.0);
    for (var k = 0u; k < 4u; k++) {
        d += b[k] * (bezier[first + across + k * along].xyz - bezier[first + k * along].xyz);
    }
    return 3.0 * d;
}

// Panel::frame from the patch's own derivatives at (s, t): the cross derivative on a border is
// the mean of both patches'. One neighbour per direction is read, picked before the read.
fn panel_frame_of(pi: u32, pj: u32, s: f32, t: f32, du_own: vec3<f32>, dv_own: vec3<f32>) -> Frame {
    var du = du_own;
    var dv = dv_own;
    let left = s == 0.0 && pi > 0u;
    let right = s == 1.0 && pi + 1u < params.patches_u;
    if left || right {
        let ni = select(min(pi + 1u, params.patches_u - 1u), pi - 1u, left);
        du = 0.5 * (du + edge_deriv(patch_id(ni, pj), left, t, 4u, 1u));
    }
    let below = t == 0.0 && pj > 0u;
    let above = t == 1.0 && pj + 1u < params.patches_v;
    if below || above {
        let nj = select(min(pj + 1u, params.patches_v - 1u), pj - 1u, below);
        dv = 0.5 * (dv + edge_deriv(patch_id(pi, nj), below, s, 1u, 4u));
    }
    let f = from_derivatives(du, dv);
    if params.flip != 0u {
        return Frame(f.t, -f.n, -f.b);
    }
    return f;
}

// ---- lod.rs (the corrected morph only) ----

const PANEL: u32 = 0u;
const YARN: u32 = 1u;
const FIBRE: u32 = 2u;

struct LodState {
    scale: u32,
    grid: u32,
    alpha: f32,
    beta_y: f32,
    beta_f: f32,
    alpha_panel: f32,
}

fn lod_at(level: f32) -> LodState {
    let l = clamp(level, 0.0, 14.0);
    let frac = l - floor(l);
    let n = u32(floor(l));
    if l < 4.0 {
        var alpha = 1.0 - frac;
        if n == 0u {
            alpha = 0.0;
        }
        return LodState(PANEL, n, alpha, 0.0, 0.0, 0.0);
    }
    let grid = clamp(n, 5u, 14u);
    var alpha = 1.0 - frac;
    if l < 6.0 {
        alpha = 0.0;
    }
    let beta_y = min(l - 4.0, 1.0);
    let beta_f = clamp(l - 9.0, 0.0, 1.0);
    var alpha_panel = 0.0;
    if l < 5.0 {
        alpha_panel = 1.0 - beta_y;
    }
    var scale = YARN;
    if beta_f > 0.0 {
        scale = FIBRE;
    }
    return LodState(scale, grid, alpha, beta_y, beta_f, alpha_panel);
}

fn panel_res(grid: u32) -> u32 {
    return 1u << min(grid, 4u);
}

// (along, around) segments per node of tube level `grid`.
fn tube_res(grid: u32) -> vec2<u32> {
    let k = max(grid, 5u) - 4u;
    return vec2<u32>(1u << (k / 2u), 1u << ((k + 1u) / 2u));
}

fn along_count(along: u32) -> u32 {
    if along == 1u {
        return params.nodes + 2u;
    }
    return params.nodes * along + 1u;
}

fn along_point(along: u32, k: u32) -> f32 {
    if along == 1u {
        if k == 0u {
            return -0.5;
        }
        if k == params.nodes + 1u {
            return f32(params.nodes) - 0.5;
        }
        return f32(k - 1u);
    }
    return -0.5 + f32(k) / f32(along);
}

// lod::bracket over along_points: the interval holding x (its lower point's index).
fn bracket_index(along: u32, x: f32) -> u32 {
    let last = along_count(along) - 2u;
    if along == 1u {
        if x < 0.0 {
            return 0u;
        }
        return min(u32(floor(x)) + 1u, last);
    }
    return min(u32(max(floor((x + 0.5) * f32(along)), 0.0)), last);
}

// ---- yarn.rs ----

// i's Euclidean remainder by n, without `%` of a negative operand (the yarns' half-node ends
// at u = -0.5), which GLSL, the GL backend's target, leaves undefined: floor division, then
// one step back into [0, n) where an inexact divide (GPUs may multiply by a reciprocal) landed
// a multiple of n one off.
fn wrap(i: i32, n: i32) -> i32 {
    var r = i - n * i32(floor(f32(i) / f32(n)));
    r = select(r, r - n, r >= n);
    return select(r, r + n, r < 0);
}

fn eta(i: i32, j: i32) -> f32 {
    let w = i32(params.weave_w);
    let h = i32(params.weave_h);
    return f32(weave[wrap(j, h) * w + wrap(i, w)]);
}

// Eq. 11: (h, dh/du); dir 0 weft, 1 warp.
fn height(dir: u32, line: i32, u: f32) -> vec2<f32> {
    let f = floor(u);
    let c = ceil(u);
    var hf: f32;
    var hc: f32;
    if dir == 0u {
        hf = eta(i32(f), line);
        hc = eta(i32(c), line);
    } else {
        hf = -eta(line, i32(f));
        hc = -eta(line, i32(c));
    }
    let x = (u - f) * PI;
    return vec2<f32>(0.5 * (hf + hc) + 0.5 * (hf - hc) * cos(x), -0.5 * (hf - hc) * PI * sin(x));
}

fn yarn_frame(dir: u32, dh: f32) -> Frame {
    var a = vec3<f32>(1.0, 0.0, 0.0);
    if dir == 1u {
        a = vec3<f32>(0.0, 0.0, 1.0);
    }
    let y = vec3<f32>(0.0, 1.0, 0.0);
    let t = normalize(params.spacing * a + params.crimp * dh * y);
    let n = normalize(params.spacing * y - params.crimp * dh * a);
    return Frame(t, n, cross(t, n));
}

struct FibrePoint {
    offset: vec3<f32>,
    frame: Frame,
}

fn fibre(i: u32, u: f32, axial: f32, beta_f: f32) -> FibrePoint {
    let w = params.omega;
    let phi = TAU * f32(i) / f32(params.fibres);
    var r0 = params.ring_radius;
    if params.fibres < 2u {
        r0 = 0.0;
    }
    let m = params.migration;
    let mig = 0.5 * w * u + phi;
    let r = r0 * (1.0 - 0.5 * m * (1.0 - cos(mig)));
    let dr = -r0 * 0.5 * m * sin(mig) * 0.5 * w;
    let psi = phi + w * u;
    let offset = vec3<f32>(0.0, r * sin(psi), r * cos(psi));
    let d = vec3<f32>(0.0, dr * sin(psi) + r * w * cos(psi), dr * cos(psi) - r * w * sin(psi));
    let t = normalize(vec3<f32>(axial, 0.0, 0.0) + beta_f * d);
    let y = vec3<f32>(0.0, 1.0, 0.0);
    let n = normalize(y - dot(y, t) * t);
    return FibrePoint(beta_f * offset, Frame(t, n, cross(t, n)));
}

// ---- tess.rs ----

struct Pn {
    p: vec3<f32>,
    n: vec3<f32>,
}

// The patch's bilinear panel of g x g cells (g of 1, 2, 4 or 8) at (s, t), from the lattice.
fn panel_bilinear(pi: u32, pj: u32, s: f32, t: f32, g: f32) -> vec3<f32> {
    let s0 = min(floor(s * g), g - 1.0);
    let t0 = min(floor(t * g), g - 1.0);
    let ws = s * g - s0;
    let wt = t * g - t0;
    let step = u32(8.0 / g);
    let at = 81u * patch_id(pi, pj) + 9u * u32(t0) * step + u32(s0) * step;
    let bottom = mix(lattice[at].xyz, lattice[at + step].xyz, ws);
    let top = mix(lattice[at + 9u * step].xyz, lattice[at + 9u * step + step].xyz, ws);
    return mix(bottom, top, wt);
}

// The morphed panel point from the exact one at (s, t): at the panel scale toward the next
// coarser panel grid (eq. 17), at the yarn scale the panel term of eq. 19.
fn panel_term(pi: u32, pj: u32, s: f32, t: f32, st: LodState, exact: vec3<f32>) -> vec3<f32> {
    var w = st.alpha_panel;
    var g = 8.0;
    if st.scale == PANEL {
        w = select(0.0, st.alpha, st.grid > 0u);
        g = f32(max(panel_res(st.grid) / 2u, 1u));
    }
    if w > 0.0 {
        return (1.0 - w) * exact + w * panel_bilinear(pi, pj, s, t, g);
    }
    return exact;
}

fn panel_vertex(pi: u32, pj: u32, s: f32, t: f32, st: LodState) -> Pn {
    let e = evaluate(pi, pj, s, t);
    return Pn(panel_term(pi, pj, s, t, st, e.p), panel_frame_of(pi, pj, s, t, e.du, e.dv).n);
}

struct Yarn {
    dir: u32,
    pi: u32,
    pj: u32,
    index: u32,
}

fn yarn_st(y: Yarn, u: f32) -> vec2<f32> {
    let n = f32(params.nodes);
    let along = (u + 0.5) / n;
    let across = (f32(y.index) + 0.5) / n;
    if y.dir == 0u {
        return vec2<f32>(along, across);
    }
    return vec2<f32>(across, along);
}

// Eq. 19 at a tube point (f < 0: no fibre), unmorphed, split as tess.rs's tube_point: the
// ring's terms (the panel point and frames, which do not depend on θ) once per ring, then each
// θ of the ring from them (ring_point).
struct Ring {
    // l_p + β_y M_p l_y + M_py l_f.
    base: vec3<f32>,
    // The frame the cross-section turns in (M_py, or M_pyf with fibres) and its radius.
    m: Frame,
    k: f32,
    // M_py's normal: the normal of a two-sided (ribbon) ring.
    n: vec3<f32>,
}

// `at`: where on the patch the panel is evaluated, the yarn's own (s, t) or, for a ring
// collapsed onto the panel's edge (a panel-scale state), that edge's vertex; such a ring is its
// panel point with the panel's normal.
fn ring_at(y: Yarn, f: i32, u: f32, st: LodState, at: vec2<f32>) -> Ring {
    let nodes = params.nodes;
    let e = evaluate(y.pi, y.pj, at.x, at.y);
    let lp = panel_term(y.pi, y.pj, at.x, at.y, st, e.p);
    let mp = panel_frame_of(y.pi, y.pj, at.x, at.y, e.du, e.dv);
    var line = y.pj * nodes + y.index;
    var first = y.pi * nodes;
    if y.dir == 1u {
        line = y.pi * nodes + y.index;
        first = y.pj * nodes;
    }
    let ug = f32(first) + u;
    let h = height(y.dir, i32(line), ug);
    let my = yarn_frame(y.dir, h.y);
    let ly = vec3<f32>(0.0, params.crimp * h.x, 0.0);
    let axial = length(vec2<f32>(params.spacing, params.crimp * h.y));
    let mpy = compose_frames(mp, my);
    var m = mpy;
    var lf = vec3<f32>(0.0);
    var k = params.radius;
    if MORPHS && f >= 0 && st.beta_f > 0.0 {
        let fp = fibre(u32(f), ug, axial, st.beta_f);
        lf = fp.offset;
        m = compose_frames(mpy, fp.frame);
        k = (1.0 - st.beta_f) * params.radius + st.beta_f * params.fibre_radius;
    }
    if st.scale == PANEL {
        return Ring(lp, mp, 0.0, mp.n);
    }
    return Ring(lp + st.beta_y * apply(mp, ly) + apply(mpy, lf), m, k, mpy.n);
}

fn ring_point(r: Ring, theta: f32, two_sided: bool) -> Pn {
    let dir = apply(r.m, vec3<f32>(0.0, sin(theta), cos(theta)));
    let p = r.base + r.k * dir;
    if two_sided {
        return Pn(p, r.n);
    }
    return Pn(p, dir);
}

// Eq. 17's coarser tube grid (eq. 18 in u) around along point u: the coarse ring counts, the
// coarse along points u0, u1 that bracket u and u's weight between them. No morph: `taps` 1.
struct Coarse {
    res: vec2<u32>,
    u0: f32,
    u1: f32,
    wu: f32,
    taps: u32,
}

fn coarse_of(u: f32, st: LodState) -> Coarse {
    let morph = MORPHS && st.alpha > 0.0 && st.grid > 5u;
    var res = vec2<u32>(1u, 2u);
    var taps = 1u;
    if morph {
        res = tube_res(st.grid - 1u);
        taps = 5u;
    }
    let i = bracket_index(res.x, u);
    let u0 = along_point(res.x, i);
    let u1 = along_point(res.x, i + 1u);
    let wu = clamp((u - u0) / (u1 - u0), 0.0, 1.0);
    return Coarse(res, u0, u1, wu, taps);
}

// Eq. 17 on the composed position, toward the coarser tube grid (eq. 18 in u and θ): `own` is
// the fine ring at u, `r0` and `r1` the coarse rings at c.u0 and c.u1. Tap 0 is the point
// itself, taps 1-4 the coarse grid's corners around it; `ring`: the fine ring's vertices.
fn tube_vertex(own: Ring, r0: Ring, r1: Ring, c: Coarse, ring: u32, theta: f32, st: LodState) -> Pn {
    let cr = f32(c.res.y);
    let x = theta * cr / TAU;
    let k0 = floor(x);
    let wt = x - k0;
    let q = ring_point(own, theta, ring == 2u);
    if c.taps == 1u {
        return q;
    }
    var pb = vec3<f32>(0.0);
    var nb = vec3<f32>(0.0);
    for (var k = 1u; k < c.taps; k++) {
        let a = (k - 1u) & 1u;
        let b = (k - 1u) >> 1u;
        let th = (k0 + f32(b)) * TAU / cr;
        let w = select(1.0 - c.wu, c.wu, a == 1u) * select(1.0 - wt, wt, b == 1u);
        var r = r0;
        if a == 1u {
            r = r1;
        }
        let t = ring_point(r, th, c.res.y == 2u);
        pb += w * t.p;
        nb += w * t.n;
    }
    let a = st.alpha;
    return Pn((1.0 - a) * q.p + a * pb, safe_normalize((1.0 - a) * q.n + a * nb, q.n));
}

// Rust's round (halves away from zero) for x >= 0; WGSL's round takes halves to even.
fn snap(x: f32, g: f32) -> f32 {
    return floor(x * g + 0.5) / g;
}

fn write_vertex(v: u32, p: vec3<f32>, n: vec3<f32>, uv: vec2<f32>) {
    store_vertex(v, p, safe_normalize(n, vec3<f32>(0.0, 1.0, 0.0)), vec3<f32>(0.0), uv, vec3<f32>(0.0));
}

fn patch_uv(pi: u32, pj: u32, s: f32, t: f32) -> vec2<f32> {
    return vec2<f32>((f32(pi) + s) / f32(params.patches_u), (f32(pj) + t) / f32(params.patches_v));
}

fn edge_state(plan: Plan, e: u32) -> LodState {
    return lod_at(min(plan.level.x, plan.edges[e]));
}

fn panel_vertex_at(plan: Plan, pi: u32, pj: u32, v: u32) {
    let st = lod_at(plan.level.x);
    let g = panel_res(st.grid);
    let a = v % (g + 1u);
    let b = v / (g + 1u);
    let s = f32(a) / f32(g);
    let t = f32(b) / f32(g);
    // The first side the vertex lies on (left, right, bottom, top): a vertex on a shared edge
    // but not at a corner takes the edge's state, snapped to its grid.
    let corner = (a == 0u || a == g) && (b == 0u || b == g);
    let side = select(select(select(select(4u, 3u, b == g), 2u, b == 0u), 1u, a == g), 0u, a == 0u);
    var at = vec2<f32>(s, t);
    var se = st;
    if !corner && side < 4u && plan.edges[min(side, 3u)] >= 0.0 {
        se = edge_state(plan, side);
        let ge = f32(panel_res(se.grid));
        if side < 2u {
            at.y = snap(t, ge);
        } else {
            at.x = snap(s, ge);
        }
    }
    let drawn = panel_vertex(pi, pj, at.x, at.y, se);
    write_vertex(plan.ids.y + v, drawn.p, drawn.n, patch_uv(pi, pj, s, t));
}

fn fibres_of(st: LodState) -> u32 {
    if st.scale == FIBRE {
        return params.fibres;
    }
    return 1u;
}

// One ring of a tube patch: its terms once (and the coarse rings' when it morphs), then each
// of its vertices.
fn tube_ring_at(plan: Plan, pi: u32, pj: u32, r: u32) {
    let st = lod_at(plan.level.x);
    let res = tube_res(st.grid);
    let count = along_count(res.x);
    let nf = fibres_of(st);
    let block = r / count;
    let index = block / nf;
    var f = -1;
    if st.scale == FIBRE {
        f = i32(block % nf);
    }
    let ai = r % count;
    let dir = params.dir;
    let y = Yarn(dir, pi, pj, index);
    let u = along_point(res.x, ai);
    let st2 = yarn_st(y, u);
    let uv = patch_uv(pi, pj, st2.x, st2.y);
    let first = plan.ids.y + r * res.y;
    // The edges a yarn crosses: weft left/right, warp bottom/top.
    var e = 4u;
    if ai == 0u {
        e = 2u * dir;
    } else if ai + 1u == count {
        e = 2u * dir + 1u;
    }
    // A ring on a shared edge takes the edge's state (eq. 21, one state per edge): θ snapped
    // to the edge's ring, or at the panel scale collapsed onto the panel's edge vertex.
    var s = st;
    var snapped = 0u;
    var at = st2;
    if e < 4u && plan.edges[e] >= 0.0 {
        s = edge_state(plan, e);
        if s.scale == PANEL {
            let ge = f32(panel_res(s.grid));
            if dir == 0u {
                at.y = snap(st2.y, ge);
            } else {
                at.x = snap(st2.x, ge);
            }
        } else {
            snapped = tube_res(s.grid).y;
        }
        if s.scale != FIBRE {
            f = -1;
        }
    }
    let own = ring_at(y, f, u, s, at);
    let c = coarse_of(u, s);
    var r0 = own;
    var r1 = own;
    if c.taps > 1u {
        r0 = ring_at(y, f, c.u0, s, yarn_st(y, c.u0));
        r1 = ring_at(y, f, c.u1, s, yarn_st(y, c.u1));
    }
    for (var k = 0u; k < res.y; k++) {
        var theta = f32(k) * TAU / f32(res.y);
        if snapped > 0u {
            let re = f32(snapped);
            theta = floor(theta * re / TAU + 0.5) * TAU / re;
        }
        let drawn = tube_vertex(own, r0, r1, c, tube_res(s.grid).y, theta, s);
        write_vertex(first + k, drawn.p, drawn.n, uv);
    }
}

@compute @workgroup_size(64)
fn panel_vertices(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let plan = plans[wg.x];
    let pi = plan.ids.x % params.patches_u;
    let pj = plan.ids.x / params.patches_u;
    let v = wg.y * 64u + lid;
    if v < plan.ids.w {
        panel_vertex_at(plan, pi, pj, v);
    }
}

@compute @workgroup_size(64)
fn tube_vertices(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let plan = plans[wg.x];
    let pi = plan.ids.x % params.patches_u;
    let pj = plan.ids.x / params.patches_u;
    let rings = plan.ids.w / tube_res(lod_at(plan.level.x).grid).y;
    // One ring an invocation (the rows cover the largest patch): a loop would run its heavy
    // body once more, masked, on lavapipe.
    let r = wg.y * 64u + lid;
    if r < rings {
        tube_ring_at(plan, pi, pj, r);
    }
}

// Quad corners: 0 (0,0), 1 (1,0), 2 (0,1), 3 (1,1); triangles 0 1 3, 0 3 2 (fronts along
// cross(du, dv)), or wound the other way, 0 3 1, 0 2 3, so that the fronts face the way the
// normals do: the panel where its normals are flipped, the weft's tubes always, the warp's
// where the panel is not flipped (as tess.rs).
const QUAD_CORNERS = array<u32, 6>(0u, 1u, 3u, 0u, 3u, 2u);
const QUAD_CORNERS_REVERSED = array<u32, 6>(0u, 3u, 1u, 0u, 2u, 3u);

// Writes quad q's two triangles at `first`: corner c of the quad is vertex `corner_ids[c]`.
fn write_quad(first: u32, corner_ids: vec4<u32>, reversed: bool) {
    var corners = QUAD_CORNERS;
    if reversed {
        corners = QUAD_CORNERS_REVERSED;
    }
    for (var k = 0u; k < 6u; k++) {
        out_indices[first + k] = corner_ids[corners[k]];
    }
}

@compute @workgroup_size(64)
fn panel_indices(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let plan = plans[wg.x];
    let quads = bitcast<u32>(plan.level.y) / 6u;
    let g = panel_res(lod_at(plan.level.x).grid);
    let row = g + 1u;
    for (var q = wg.y * 64u + lid; q < quads; q += 64u * groups.y) {
        let v = plan.ids.y + (q / g) * row + q % g;
        write_quad(plan.ids.z + 6u * q, vec4<u32>(v, v + 1u, v + row, v + row + 1u), params.flip != 0u);
    }
}

@compute @workgroup_size(64)
fn tube_indices(
    @builtin(workgroup_id) wg: vec3<u32>,
    @builtin(num_workgroups) groups: vec3<u32>,
    @builtin(local_invocation_index) lid: u32,
) {
    let plan = plans[wg.x];
    let count = bitcast<u32>(plan.level.y) / 6u;
    let res = tube_res(lod_at(plan.level.x).grid);
    let rings = along_count(res.x);
    let quads = (rings - 1u) * res.y;
    for (var q = wg.y * 64u + lid; q < count; q += 64u * groups.y) {
        // Corner c: ring ai + (c & 1), around k + (c >> 1), wrapping.
        let block = q / quads;
        let r = q % quads;
        let ai = r / res.y;
        let k = r % res.y;
        let k1 = (k + 1u) % res.y;
        let v = plan.ids.y + block * rings * res.y + ai * res.y;
        let ids = vec4<u32>(v + k, v + res.y + k, v + k1, v + res.y + k1);
        write_quad(plan.ids.z + 6u * q, ids, params.dir == 0u || params.flip == 0u);
    }
}

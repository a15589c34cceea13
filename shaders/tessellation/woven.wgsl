// Woven cloth at three scales in compute (Zhang et al. 2012, IDSS; docs/woven.md). The twin of
// src/woven/tess.rs, lod.rs, panel.rs and yarn.rs: each function here has the name and the
// arithmetic of its Rust original (f32 here, f64 there). The CPU plans the frame (src/woven/gpu.rs:
// each drawn patch's level, its four edge levels, its first vertex and index); four entry points
// fill one layer's buffers, one workgroup row per patch:
//   panel_vertices, tube_vertices  the patch's geomorphed, crack-snapped vertices;
//   panel_indices, tube_indices    its triangles.
// The parameters (the tube layer's direction too) sit in a storage buffer, not a uniform block:
// lavapipe specializes shaders on uniforms that branches read and would recompile this one per
// parameter change. Morph taps are loops with a run-time count, so the heavy tube point is
// compiled once, not once per tap (lavapipe's compile time grows with the inlined copies).

const TAU: f32 = 6.283185307179586;
const PI: f32 = 3.141592653589793;
const FLOATS: u32 = 14u;

struct Params {
    patches_u: u32,
    patches_v: u32,
    nodes: u32,
    fibres: u32,
    weave_w: u32,
    weave_h: u32,
    flip: u32,
    // Workgroup rows per patch (y of the dispatch): invocations stride by 64 x slices.
    slices: u32,
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

// ---- panel.rs ----

fn bernstein(t: f32) -> vec4<f32> {
    let s = 1.0 - t;
    return vec4<f32>(s * s * s, 3.0 * s * s * t, 3.0 * s * t * t, t * t * t);
}

fn bernstein_d(t: f32) -> vec4<f32> {
    let s = 1.0 - t;
    return vec4<f32>(-3.0 * s * s, 3.0 * s * s - 6.0 * s * t, 6.0 * s * t - 3.0 * t * t, 3.0 * t * t);
}

fn combine(pid: u32, bu: vec4<f32>, bv: vec4<f32>) -> vec3<f32> {
    var p = vec3<f32>(0.0);
    for (var i = 0u; i < 4u; i++) {
        for (var j = 0u; j < 4u; j++) {
            p += bu[i] * bv[j] * bezier[16u * pid + 4u * i + j].xyz;
        }
    }
    return p;
}

fn patch_id(pi: u32, pj: u32) -> u32 {
    return pj * params.patches_u + pi;
}

fn position(pi: u32, pj: u32, s: f32, t: f32) -> vec3<f32> {
    return combine(patch_id(pi, pj), bernstein(s), bernstein(t));
}

fn deriv_u(pi: u32, pj: u32, s: f32, t: f32) -> vec3<f32> {
    return combine(patch_id(pi, pj), bernstein_d(s), bernstein(t));
}

fn deriv_v(pi: u32, pj: u32, s: f32, t: f32) -> vec3<f32> {
    return combine(patch_id(pi, pj), bernstein(s), bernstein_d(t));
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

// Panel::frame: the cross derivative on a border is the mean of both patches'.
fn panel_frame(pi: u32, pj: u32, s: f32, t: f32) -> Frame {
    var du = deriv_u(pi, pj, s, t);
    var dv = deriv_v(pi, pj, s, t);
    if s == 0.0 && pi > 0u {
        du = 0.5 * (du + deriv_u(pi - 1u, pj, 1.0, t));
    } else if s == 1.0 && pi + 1u < params.patches_u {
        du = 0.5 * (du + deriv_u(pi + 1u, pj, 0.0, t));
    }
    if t == 0.0 && pj > 0u {
        dv = 0.5 * (dv + deriv_v(pi, pj - 1u, s, 1.0));
    } else if t == 1.0 && pj + 1u < params.patches_v {
        dv = 0.5 * (dv + deriv_v(pi, pj + 1u, s, 0.0));
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

fn eta(i: i32, j: i32) -> f32 {
    let w = i32(params.weave_w);
    let h = i32(params.weave_h);
    let ii = ((i % w) + w) % w;
    let jj = ((j % h) + h) % h;
    return f32(weave[jj * w + ii]);
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

fn panel_bilinear(pi: u32, pj: u32, s: f32, t: f32, g: f32) -> vec3<f32> {
    let s0 = min(floor(s * g), g - 1.0);
    let t0 = min(floor(t * g), g - 1.0);
    let ws = s * g - s0;
    let wt = t * g - t0;
    var p = vec3<f32>(0.0);
    for (var c = 0u; c < 4u; c++) {
        let a = f32(c & 1u);
        let b = f32(c >> 1u);
        let w = mix(1.0 - ws, ws, a) * mix(1.0 - wt, wt, b);
        p += w * position(pi, pj, (s0 + a) / g, (t0 + b) / g);
    }
    return p;
}

fn panel_vertex(pi: u32, pj: u32, s: f32, t: f32, st: LodState) -> Pn {
    var p = position(pi, pj, s, t);
    if st.alpha > 0.0 && st.grid > 0u {
        let g = f32(panel_res(st.grid) / 2u);
        p = (1.0 - st.alpha) * p + st.alpha * panel_bilinear(pi, pj, s, t, g);
    }
    return Pn(p, panel_frame(pi, pj, s, t).n);
}

fn panel_term(pi: u32, pj: u32, s: f32, t: f32, st: LodState) -> vec3<f32> {
    let exact = position(pi, pj, s, t);
    if st.alpha_panel > 0.0 {
        return (1.0 - st.alpha_panel) * exact + st.alpha_panel * panel_bilinear(pi, pj, s, t, 8.0);
    }
    return exact;
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

// Eq. 19 at a tube point (f < 0: no fibre), unmorphed.
fn tube_point(y: Yarn, f: i32, u: f32, theta: f32, st: LodState, two_sided: bool) -> Pn {
    let nodes = params.nodes;
    let st2 = yarn_st(y, u);
    let lp = panel_term(y.pi, y.pj, st2.x, st2.y, st);
    let mp = panel_frame(y.pi, y.pj, st2.x, st2.y);
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
    if f >= 0 && st.beta_f > 0.0 {
        let fp = fibre(u32(f), ug, axial, st.beta_f);
        lf = fp.offset;
        m = compose_frames(mpy, fp.frame);
        k = (1.0 - st.beta_f) * params.radius + st.beta_f * params.fibre_radius;
    }
    let dir = apply(m, vec3<f32>(0.0, sin(theta), cos(theta)));
    let p = lp + st.beta_y * apply(mp, ly) + apply(mpy, lf) + k * dir;
    if two_sided {
        return Pn(p, mpy.n);
    }
    return Pn(p, dir);
}

// Eq. 17 on the composed position, toward the coarser tube grid (eq. 18 in u and θ). Tap 0 is
// the point itself, taps 1-4 the coarse grid's corners around it.
fn tube_vertex(y: Yarn, f: i32, u: f32, theta: f32, st: LodState) -> Pn {
    let ring = tube_res(st.grid).y;
    let morph = st.alpha > 0.0 && st.grid > 5u;
    var coarse = vec2<u32>(1u, 2u);
    var taps = 1u;
    if morph {
        coarse = tube_res(st.grid - 1u);
        taps = 5u;
    }
    let i = bracket_index(coarse.x, u);
    let u0 = along_point(coarse.x, i);
    let u1 = along_point(coarse.x, i + 1u);
    let wu = clamp((u - u0) / (u1 - u0), 0.0, 1.0);
    let cr = f32(coarse.y);
    let x = theta * cr / TAU;
    let k0 = floor(x);
    let wt = x - k0;
    var own = Pn(vec3<f32>(0.0), vec3<f32>(0.0));
    var pb = vec3<f32>(0.0);
    var nb = vec3<f32>(0.0);
    for (var k = 0u; k < taps; k++) {
        var uu = u;
        var th = theta;
        var two_sided = ring == 2u;
        var w = 1.0;
        if k > 0u {
            let a = (k - 1u) & 1u;
            let b = (k - 1u) >> 1u;
            uu = select(u0, u1, a == 1u);
            th = (k0 + f32(b)) * TAU / cr;
            two_sided = coarse.y == 2u;
            w = select(1.0 - wu, wu, a == 1u) * select(1.0 - wt, wt, b == 1u);
        }
        let q = tube_point(y, f, uu, th, st, two_sided);
        if k == 0u {
            own = q;
        } else {
            pb += w * q.p;
            nb += w * q.n;
        }
    }
    if !morph {
        return own;
    }
    let a = st.alpha;
    return Pn((1.0 - a) * own.p + a * pb, safe_normalize((1.0 - a) * own.n + a * nb, own.n));
}

// Rust's round (halves away from zero) for x >= 0; WGSL's round takes halves to even.
fn snap(x: f32, g: f32) -> f32 {
    return floor(x * g + 0.5) / g;
}

fn write_vertex(v: u32, p: vec3<f32>, n: vec3<f32>, uv: vec2<f32>) {
    let o = v * FLOATS;
    let nn = safe_normalize(n, vec3<f32>(0.0, 1.0, 0.0));
    out_vertices[o] = p.x;
    out_vertices[o + 1u] = p.y;
    out_vertices[o + 2u] = p.z;
    out_vertices[o + 3u] = nn.x;
    out_vertices[o + 4u] = nn.y;
    out_vertices[o + 5u] = nn.z;
    for (var k = 6u; k < 9u; k++) {
        out_vertices[o + k] = 0.0;
    }
    out_vertices[o + 9u] = uv.x;
    out_vertices[o + 10u] = uv.y;
    for (var k = 11u; k < 14u; k++) {
        out_vertices[o + k] = 0.0;
    }
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
    let corner = (a == 0u || a == g) && (b == 0u || b == g);
    var side = array<bool, 4>(a == 0u, a == g, b == 0u, b == g);
    var snapped = 4u;
    for (var e = 0u; e < 4u; e++) {
        if side[e] && !corner {
            if plan.edges[e] >= 0.0 {
                snapped = e;
            }
            break;
        }
    }
    var drawn: Pn;
    if snapped < 4u {
        let se = edge_state(plan, snapped);
        let ge = f32(panel_res(se.grid));
        if snapped < 2u {
            drawn = panel_vertex(pi, pj, s, snap(t, ge), se);
        } else {
            drawn = panel_vertex(pi, pj, snap(s, ge), t, se);
        }
    } else {
        drawn = panel_vertex(pi, pj, s, t, st);
    }
    write_vertex(plan.ids.y + v, drawn.p, drawn.n, patch_uv(pi, pj, s, t));
}

fn fibres_of(st: LodState) -> u32 {
    if st.scale == FIBRE {
        return params.fibres;
    }
    return 1u;
}

fn tube_vertex_at(plan: Plan, pi: u32, pj: u32, v: u32) {
    let st = lod_at(plan.level.x);
    let res = tube_res(st.grid);
    let count = along_count(res.x);
    let nf = fibres_of(st);
    let ring = count * res.y;
    let block = v / ring;
    let index = block / nf;
    var f = -1;
    if st.scale == FIBRE {
        f = i32(block % nf);
    }
    let ai = (v % ring) / res.y;
    let k = v % res.y;
    let dir = params.dir;
    let y = Yarn(dir, pi, pj, index);
    let u = along_point(res.x, ai);
    let st2 = yarn_st(y, u);
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
    var theta = f32(k) * TAU / f32(res.y);
    var drawn: Pn;
    var on_panel = false;
    if e < 4u && plan.edges[e] >= 0.0 {
        s = edge_state(plan, e);
        if s.scale == PANEL {
            on_panel = true;
            let ge = f32(panel_res(s.grid));
            if dir == 0u {
                drawn = panel_vertex(pi, pj, st2.x, snap(st2.y, ge), s);
            } else {
                drawn = panel_vertex(pi, pj, snap(st2.x, ge), st2.y, s);
            }
        } else {
            let re = f32(tube_res(s.grid).y);
            theta = floor(theta * re / TAU + 0.5) * TAU / re;
            if s.scale != FIBRE {
                f = -1;
            }
        }
    }
    if !on_panel {
        drawn = tube_vertex(y, f, u, theta, s);
    }
    write_vertex(plan.ids.y + v, drawn.p, drawn.n, patch_uv(pi, pj, st2.x, st2.y));
}

@compute @workgroup_size(64)
fn panel_vertices(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let plan = plans[wg.x];
    let pi = plan.ids.x % params.patches_u;
    let pj = plan.ids.x / params.patches_u;
    for (var v = wg.y * 64u + lid; v < plan.ids.w; v += 64u * params.slices) {
        panel_vertex_at(plan, pi, pj, v);
    }
}

@compute @workgroup_size(64)
fn tube_vertices(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let plan = plans[wg.x];
    let pi = plan.ids.x % params.patches_u;
    let pj = plan.ids.x / params.patches_u;
    for (var v = wg.y * 64u + lid; v < plan.ids.w; v += 64u * params.slices) {
        tube_vertex_at(plan, pi, pj, v);
    }
}

// Quad corners: 0 (0,0), 1 (1,0), 2 (0,1), 3 (1,1); triangles 0 1 3, 0 3 2 (as tess.rs).
const QUAD_CORNERS = array<u32, 6>(0u, 1u, 3u, 0u, 3u, 2u);

@compute @workgroup_size(64)
fn panel_indices(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let plan = plans[wg.x];
    let count = bitcast<u32>(plan.level.y);
    let g = panel_res(lod_at(plan.level.x).grid);
    let row = g + 1u;
    for (var i = wg.y * 64u + lid; i < count; i += 64u * params.slices) {
        let q = i / 6u;
        var corners = QUAD_CORNERS;
        let c = corners[i % 6u];
        let v = (q / g) * row + q % g + (c & 1u) + (c >> 1u) * row;
        out_indices[plan.ids.z + i] = plan.ids.y + v;
    }
}

@compute @workgroup_size(64)
fn tube_indices(@builtin(workgroup_id) wg: vec3<u32>, @builtin(local_invocation_index) lid: u32) {
    let plan = plans[wg.x];
    let count = bitcast<u32>(plan.level.y);
    let res = tube_res(lod_at(plan.level.x).grid);
    let rings = along_count(res.x);
    let quads = (rings - 1u) * res.y;
    for (var i = wg.y * 64u + lid; i < count; i += 64u * params.slices) {
        let q = i / 6u;
        var corners = QUAD_CORNERS;
        let c = corners[i % 6u];
        // Corner c: ring ai + (c & 1), around k + (c >> 1), wrapping.
        let block = q / quads;
        let r = q % quads;
        let ai = r / res.y + (c & 1u);
        let k = (r % res.y + (c >> 1u)) % res.y;
        out_indices[plan.ids.z + i] = plan.ids.y + block * rings * res.y + ai * res.y + k;
    }
}

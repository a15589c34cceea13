// Adaptive tessellation in compute (dissertation 3.1.3; docs/tessellation.md). The twin of
// src/tessellation/mod.rs: every function here has the same name and the same arithmetic there.
// Five entry points, dispatched in order into one mesh's output:
//   vertex_levels (per vertex)   the level each vertex asks for (distance and silhouette);
//   edge_lengths  (per triangle) edge-length metric: the largest screen length / max per vertex;
//   count         (per triangle) vertices and indices of its patch;
//   scan          (one group)    exclusive prefix sums -> each patch's first vertex and index,
//                                and the indirect draw arguments;
//   generate      (per triangle) the patch's vertices and indices.

struct Params {
    view_proj: mat4x4<f32>,
    // xyz: camera position.
    eye: vec4<f32>,
    // near, far, max level, silhouette gain.
    lod: vec4<f32>,
    // viewport width, height (pixels), max edge length (pixels), unused.
    screen: vec4<f32>,
    // 0 uniform, 1 dyadic, 2 pattern, 3 pattern with warping.
    mode: u32,
    max_level: u32,
    pn: u32,
    // 0 distance + silhouette, 1 screen edge length, 2 levels given (written by the CPU).
    metric: u32,
    tri_count: u32,
    vertex_count: u32,
    _pad0: u32,
    _pad1: u32,
}

// #include "pn.wgsl"
// #include "vertex_out.wgsl"

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var<storage, read> src: array<f32>;
@group(0) @binding(2) var<storage, read> tri_indices: array<u32>;
// Vertex levels as f32 bits (positive floats order like their bits: atomicMax works).
@group(0) @binding(3) var<storage, read_write> levels: array<atomic<u32>>;
// Per triangle: (vertices, indices), then after `scan` (first vertex, first index).
@group(0) @binding(4) var<storage, read_write> counts: array<vec2<u32>>;
@group(0) @binding(5) var<storage, read_write> out_vertices: array<f32>;
@group(0) @binding(6) var<storage, read_write> out_indices: array<u32>;
// DrawIndexedIndirectArgs of one instance (a depth target draws it once per tile).
@group(0) @binding(7) var<storage, read_write> indirect: array<u32>;

fn invocation(gid: vec3<u32>) -> u32 {
    return gid.x + gid.y * 65535u * 64u;
}

fn load3(v: u32, k: u32) -> vec3<f32> {
    let o = v * FLOATS + k;
    return vec3<f32>(src[o], src[o + 1u], src[o + 2u]);
}

fn level_of(v: u32) -> f32 {
    return bitcast<f32>(atomicLoad(&levels[v]));
}

// ---- levels (src/tessellation/mod.rs vertex_level, edge_level) ----

fn vertex_level(p: vec3<f32>, n: vec3<f32>) -> f32 {
    let to = p - params.eye.xyz;
    let d = max(length(to), 1e-6);
    let near = max(params.lod.x, 1e-6);
    let far = max(params.lod.y, near * (1.0 + 1e-6));
    let max_level = params.lod.z;
    let f = clamp(log(far / d) / log(far / near), 0.0, 1.0);
    let distance = 1.0 + (max_level - 1.0) * f;
    var nn = vec3<f32>(0.0);
    if dot(n, n) > 0.0 {
        nn = normalize(n);
    }
    let grazing = 1.0 - abs(dot(to / d, nn));
    return clamp(distance * (1.0 + params.lod.w * grazing), 1.0, max_level);
}

fn edge_level(la: f32, lb: f32) -> u32 {
    return clamp(u32(ceil(0.5 * (la + lb))), 1u, max(params.max_level, 1u));
}

@compute @workgroup_size(64)
fn vertex_levels(@builtin(global_invocation_id) gid: vec3<u32>) {
    let v = invocation(gid);
    if v >= params.vertex_count {
        return;
    }
    var l = 1.0;
    if params.metric == 0u {
        l = vertex_level(load3(v, 0u), load3(v, 3u));
    }
    atomicStore(&levels[v], bitcast<u32>(l));
}

fn screen_point(p: vec3<f32>) -> vec2<f32> {
    let c = params.view_proj * vec4<f32>(p, 1.0);
    return c.xy / max(c.w, 1e-4) * 0.5 * params.screen.xy;
}

@compute @workgroup_size(64)
fn edge_lengths(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = invocation(gid);
    if t >= params.tri_count {
        return;
    }
    for (var e = 0u; e < 3u; e++) {
        let a = tri_indices[t * 3u + e];
        let b = tri_indices[t * 3u + (e + 1u) % 3u];
        let len = length(screen_point(load3(a, 0u)) - screen_point(load3(b, 0u)));
        let l = clamp(len / max(params.screen.z, 1e-3), 1.0, params.lod.z);
        atomicMax(&levels[a], bitcast<u32>(l));
        atomicMax(&levels[b], bitcast<u32>(l));
    }
}

// ---- refinement (src/tessellation/mod.rs split, refine, counts) ----

fn dyadic(n: u32) -> u32 {
    var m = 1u;
    while m < n {
        m *= 2u;
    }
    return m;
}

fn lerp_round(a: u32, b: u32, i: u32, k: u32) -> u32 {
    return (2u * (a * (k - i) + b * i) + k) / (2u * k);
}

struct Split {
    rot: u32,
    special: bool,
    base: u32,
    right: u32,
    left: u32,
    m: u32,
    s_left: u32,
    s_right: u32,
    rows: u32,
}

fn split(n: array<u32, 3>) -> Split {
    var rot = 0u;
    for (var e = 1u; e < 3u; e++) {
        if n[e] < n[rot] {
            rot = e;
        }
    }
    let low = n[rot];
    let r1 = n[(rot + 1u) % 3u];
    let r2 = n[(rot + 2u) % 3u];
    var h = 3u;
    if r2 == low && r1 > low {
        h = (rot + 1u) % 3u;
    } else if r1 == low && r2 > low {
        h = (rot + 2u) % 3u;
    }
    if h < 3u {
        let rows = max(low / 2u, 1u);
        return Split(h, true, n[h], low, low, low - rows, 0u, 0u, rows);
    }
    return Split(rot, false, low, r1, r2, low, r2 - low, r1 - low, 0u);
}

fn uniform_counts(m: u32) -> vec2<u32> {
    return vec2<u32>((m + 1u) * (m + 2u) / 2u, m * m);
}

fn patch_counts(n: array<u32, 3>, dyadic_mode: bool) -> vec2<u32> {
    if dyadic_mode {
        return uniform_counts(dyadic(max(n[0], max(n[1], n[2]))));
    }
    let s = split(n);
    var c = uniform_counts(s.m);
    if s.special {
        for (var i = 0u; i < s.rows; i++) {
            let ci = lerp_round(s.base, s.m, i, s.rows);
            c += vec2<u32>(ci + 1u, ci + lerp_round(s.base, s.m, i + 1u, s.rows));
        }
    } else {
        for (var j = 0u; j <= s.base; j++) {
            let sj = lerp_round(s.s_left, s.s_right, j, s.base);
            c.x += sj;
            if j < s.base {
                c.y += sj + lerp_round(s.s_left, s.s_right, j + 1u, s.base);
            }
        }
    }
    return c;
}

// ---- the triangle being generated ----

struct Corner {
    p: vec3<f32>,
    n: vec3<f32>,
    uv: vec2<f32>,
    tu: vec3<f32>,
    tv: vec3<f32>,
    level: f32,
}

var<private> corners: array<Corner, 3>;
var<private> ids: array<u32, 3>;
var<private> lv: array<u32, 3>;
var<private> sp: Split;
var<private> next_vertex: u32;
var<private> first_vertex: u32;
var<private> next_index: u32;

fn corner_of(v: u32) -> Corner {
    let o = v * FLOATS;
    return Corner(load3(v, 0u), load3(v, 3u), vec2<f32>(src[o + 9u], src[o + 10u]), load3(v, 6u), load3(v, 11u),
                  level_of(v));
}

fn triangle_levels() -> array<u32, 3> {
    if params.mode == 0u {
        let u = max(params.max_level, 1u);
        return array<u32, 3>(u, u, u);
    }
    var n = array<u32, 3>(edge_level(corners[0].level, corners[1].level),
                          edge_level(corners[1].level, corners[2].level),
                          edge_level(corners[2].level, corners[0].level));
    if params.mode == 1u {
        for (var e = 0u; e < 3u; e++) {
            n[e] = dyadic(n[e]);
        }
    }
    return n;
}

fn load_triangle(t: u32) {
    for (var k = 0u; k < 3u; k++) {
        ids[k] = tri_indices[t * 3u + k];
        corners[k] = corner_of(ids[k]);
    }
    lv = triangle_levels();
}

@compute @workgroup_size(64)
fn count(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = invocation(gid);
    if t >= params.tri_count {
        return;
    }
    load_triangle(t);
    let c = patch_counts(lv, params.mode == 1u);
    counts[t] = vec2<u32>(c.x, 3u * c.y);
}

var<workgroup> sums: array<vec2<u32>, 256>;

@compute @workgroup_size(256)
fn scan(@builtin(local_invocation_index) li: u32) {
    let n = params.tri_count;
    let chunk = (n + 255u) / 256u;
    let start = min(li * chunk, n);
    let end = min(start + chunk, n);
    var s = vec2<u32>(0u);
    for (var i = start; i < end; i++) {
        s += counts[i];
    }
    sums[li] = s;
    workgroupBarrier();
    for (var off = 1u; off < 256u; off *= 2u) {
        var v = sums[li];
        if li >= off {
            v += sums[li - off];
        }
        workgroupBarrier();
        sums[li] = v;
        workgroupBarrier();
    }
    var run = vec2<u32>(0u);
    if li > 0u {
        run = sums[li - 1u];
    }
    for (var i = start; i < end; i++) {
        let c = counts[i];
        counts[i] = run;
        run += c;
    }
    if li == 255u {
        indirect[0] = sums[255].y;
        indirect[1] = 1u;
        indirect[2] = 0u;
        indirect[3] = 0u;
        indirect[4] = 0u;
    }
}

// ---- evaluation (src/tessellation/mod.rs warp, warp_edge, edge_vertex, interior_vertex, eval_point) ----

fn warp(b: vec3<f32>, l: vec3<f32>) -> vec3<f32> {
    let u = b.x;
    let v = b.y;
    let w = b.z;
    let w210 = l.x / (l.x + l.y);
    let w120 = l.y / (l.x + l.y);
    let w021 = l.y / (l.y + l.z);
    let w012 = l.z / (l.y + l.z);
    let w201 = l.x / (l.z + l.x);
    let w102 = l.z / (l.z + l.x);
    return vec3<f32>(
        u * u + 2.0 * (w210 * u * v + w201 * u * w),
        v * v + 2.0 * (w120 * u * v + w021 * v * w),
        w * w + 2.0 * (w012 * v * w + w102 * u * w),
    );
}

fn warp_edge(t: f32, la: f32, lb: f32) -> f32 {
    let wb = lb / (la + lb);
    return t * t + 2.0 * wb * t * (1.0 - t);
}

fn write_vertex(p: vec3<f32>, n: vec3<f32>, tu: vec3<f32>, uv: vec2<f32>, tv: vec3<f32>) {
    store_vertex(next_vertex, p, n, tu, uv, tv);
    next_vertex += 1u;
}

fn edge_vertex(a: Corner, b: Corner, t: f32) {
    let s = 1.0 - t;
    var p = a.p * s + b.p * t;
    var n = a.n * s + b.n * t;
    if params.pn != 0u {
        let b210 = pn_edge(a.p, a.n, b.p);
        let b120 = pn_edge(b.p, b.n, a.p);
        p = a.p * (s * s * s) + b210 * (3.0 * s * s * t) + b120 * (3.0 * s * t * t) + b.p * (t * t * t);
        let n110 = pn_normal(a.p, a.n, b.p, b.n);
        n = a.n * (s * s) + n110 * (s * t) + b.n * (t * t);
    }
    write_vertex(p, normalize_or_zero(n), normalize_or_zero(a.tu * s + b.tu * t), a.uv * s + b.uv * t,
                 normalize_or_zero(a.tv * s + b.tv * t));
}

fn interior_vertex(w: vec3<f32>) {
    let c0 = corners[0];
    let c1 = corners[1];
    let c2 = corners[2];
    let u = w.x;
    let v = w.y;
    let x = w.z;
    var p = c0.p * u + c1.p * v + c2.p * x;
    var n = c0.n * u + c1.n * v + c2.n * x;
    if params.pn != 0u {
        p = pn_position(c0.p, c1.p, c2.p, c0.n, c1.n, c2.n, w);
        n = pn_normal_at(c0.p, c1.p, c2.p, c0.n, c1.n, c2.n, w);
    }
    write_vertex(p, normalize_or_zero(n), normalize_or_zero(c0.tu * u + c1.tu * v + c2.tu * x),
                 c0.uv * u + c1.uv * v + c2.uv * x, normalize_or_zero(c0.tv * u + c1.tv * v + c2.tv * x));
}

fn put_corner(k: u32) {
    let c = corners[k];
    write_vertex(c.p, c.n, c.tu, c.uv, c.tv);
}

// Vertex i of edge e (from corner e), computed from the edge alone in canonical orientation.
fn put_edge(e: u32, i: u32) {
    let e1 = (e + 1u) % 3u;
    let level = lv[e];
    var a = e;
    var b = e1;
    var ic = i;
    if ids[e] > ids[e1] {
        a = e1;
        b = e;
        ic = level - i;
    }
    var t = f32(ic) / f32(level);
    if params.mode == 3u {
        t = warp_edge(t, corners[a].level, corners[b].level);
    }
    edge_vertex(corners[a], corners[b], t);
}

fn put_interior(b: vec3<f32>) {
    var w = b;
    if params.mode == 3u {
        w = warp(b, vec3<f32>(corners[0].level, corners[1].level, corners[2].level));
    }
    interior_vertex(w);
}

// Points named in the rotated frame (A = corner rot, B = rot + 1, C = rot + 2).
fn put_rot_corner(k: u32) {
    put_corner((sp.rot + k) % 3u);
}

fn put_base(i: u32) {
    if i == 0u {
        put_rot_corner(0u);
    } else if i == sp.base {
        put_rot_corner(1u);
    } else {
        put_edge(sp.rot, i);
    }
}

fn put_right(i: u32) {
    if i == 0u {
        put_rot_corner(1u);
    } else if i == sp.right {
        put_rot_corner(2u);
    } else {
        put_edge((sp.rot + 1u) % 3u, i);
    }
}

fn put_left(i: u32) {
    if i == 0u {
        put_rot_corner(0u);
    } else if i == sp.left {
        put_rot_corner(2u);
    } else {
        put_edge((sp.rot + 2u) % 3u, sp.left - i);
    }
}

fn unrotate(rot: u32, abc: vec3<f32>) -> vec3<f32> {
    if rot == 0u {
        return abc;
    } else if rot == 1u {
        return vec3<f32>(abc.z, abc.x, abc.y);
    }
    return vec3<f32>(abc.y, abc.z, abc.x);
}

fn put_rot_interior(abc: vec3<f32>) {
    put_interior(unrotate(sp.rot, abc));
}

fn put_top(m: u32, row: u32, c: u32, bl: vec3<f32>, br: vec3<f32>, up: vec2<u32>) {
    if row == m {
        put_rot_corner(2u);
    } else if c == 0u {
        put_left(up.x + row);
    } else if c == m - row {
        put_right(up.y + row);
    } else if row == 0u && up.x == 0u && up.y == 0u {
        put_base(c);
    } else {
        let fm = f32(m);
        let fr = f32(row);
        let fc = f32(c);
        let wl = (fm - fr - fc) / fm;
        let wr = fc / fm;
        let wc = fr / fm;
        put_rot_interior(vec3<f32>(wl * bl.x + wr * br.x, wl * bl.y + wr * br.y, wl * bl.z + wr * br.z + wc));
    }
}

fn tri(a: u32, b: u32, c: u32) {
    out_indices[next_index] = first_vertex + a;
    out_indices[next_index + 1u] = first_vertex + b;
    out_indices[next_index + 2u] = first_vertex + c;
    next_index += 3u;
}

fn grid_row_start(m: u32, row: u32) -> u32 {
    return row * (m + 1u) - (row * (row + 1u) / 2u - row);
}

fn grid_triangles(m: u32) {
    for (var row = 0u; row < m; row++) {
        for (var c = 0u; c < m - row; c++) {
            let i0 = grid_row_start(m, row) + c;
            let i1 = grid_row_start(m, row + 1u) + c;
            tri(i0, i0 + 1u, i1);
            if c + 1u < m - row {
                tri(i0 + 1u, i1 + 1u, i1);
            }
        }
    }
}

fn strip_vertex(first: u32, q: u32, segments: u32, last: u32) -> u32 {
    if q == segments {
        return last;
    }
    return first + q;
}

fn strip(a0: u32, s: u32, a_last: u32, b0: u32, t: u32, b_last: u32) {
    var i = 0u;
    var k = 0u;
    while i < s || k < t {
        if k == t || (i < s && (i + 1u) * t <= (k + 1u) * s) {
            tri(strip_vertex(a0, i, s, a_last), strip_vertex(b0, k, t, b_last), strip_vertex(a0, i + 1u, s, a_last));
            i += 1u;
        } else {
            tri(strip_vertex(a0, i, s, a_last), strip_vertex(b0, k, t, b_last), strip_vertex(b0, k + 1u, t, b_last));
            k += 1u;
        }
    }
}

fn lerp3(a: vec3<f32>, b: vec3<f32>, t: f32) -> vec3<f32> {
    return vec3<f32>(a.x * (1.0 - t) + b.x * t, a.y * (1.0 - t) + b.y * t, a.z * (1.0 - t) + b.z * t);
}

fn snap(e: u32, i: u32, m: u32) {
    let ne = lv[e];
    let flip = ids[e] > ids[(e + 1u) % 3u];
    var ic = i;
    if flip {
        ic = m - i;
    }
    let sc = (2u * ic * ne + m) / (2u * m);
    var s = sc;
    if flip {
        s = ne - sc;
    }
    if s == 0u {
        put_corner(e);
    } else if s == ne {
        put_corner((e + 1u) % 3u);
    } else {
        put_edge(e, s);
    }
}

fn refine_dyadic() {
    let m = dyadic(max(lv[0], max(lv[1], lv[2])));
    let fm = f32(m);
    for (var row = 0u; row <= m; row++) {
        for (var c = 0u; c <= m - row; c++) {
            if row == 0u {
                snap(0u, c, m);
            } else if c == 0u {
                snap(2u, m - row, m);
            } else if c == m - row {
                snap(1u, row, m);
            } else {
                put_interior(vec3<f32>(f32(m - row - c) / fm, f32(c) / fm, f32(row) / fm));
            }
        }
    }
    grid_triangles(m);
}

fn refine_pattern() {
    sp = split(lv);
    let m = sp.m;
    var bl: vec3<f32>;
    var br: vec3<f32>;
    var up: vec2<u32>;
    if sp.special {
        let h = f32(sp.rows) / f32(sp.left);
        bl = vec3<f32>(1.0 - h, 0.0, h);
        br = vec3<f32>(0.0, 1.0 - h, h);
        up = vec2<u32>(sp.rows, sp.rows);
    } else {
        let hl = f32(sp.s_left) / f32(sp.left);
        let hr = f32(sp.s_right) / f32(sp.right);
        bl = vec3<f32>(1.0 - hl, 0.0, hl);
        br = vec3<f32>(0.0, 1.0 - hr, hr);
        up = vec2<u32>(sp.s_left, sp.s_right);
    }
    for (var row = 0u; row <= m; row++) {
        for (var c = 0u; c <= m - row; c++) {
            put_top(m, row, c, bl, br, up);
        }
    }
    grid_triangles(m);
    var first = next_vertex - first_vertex;
    if sp.special {
        let b = f32(sp.left);
        var prev_first = 0u;
        var prev_c = 0u;
        for (var i = 0u; i < sp.rows; i++) {
            let c = lerp_round(sp.base, m, i, sp.rows);
            let fi = f32(i) / b;
            let li = vec3<f32>(1.0 - fi, 0.0, fi);
            let ri = vec3<f32>(0.0, 1.0 - fi, fi);
            for (var q = 0u; q <= c; q++) {
                if i == 0u {
                    put_base(q);
                } else if q == 0u {
                    put_left(i);
                } else if q == c {
                    put_right(i);
                } else {
                    put_rot_interior(lerp3(li, ri, f32(q) / f32(c)));
                }
            }
            if i > 0u {
                strip(first, c, first + c, prev_first, prev_c, prev_first + prev_c);
            }
            prev_first = first;
            prev_c = c;
            first += c + 1u;
        }
        strip(0u, m, m, prev_first, prev_c, prev_first + prev_c);
    } else {
        let b = f32(sp.base);
        var prev_first = 0u;
        var prev_s = 0u;
        for (var j = 0u; j <= sp.base; j++) {
            let sj = lerp_round(sp.s_left, sp.s_right, j, sp.base);
            let fj = f32(j) / b;
            let bottom = vec3<f32>(1.0 - fj, fj, 0.0);
            let top = lerp3(bl, br, fj);
            for (var k = 0u; k < sj; k++) {
                if j == 0u {
                    put_left(k);
                } else if j == sp.base {
                    put_right(k);
                } else if k == 0u {
                    put_base(j);
                } else {
                    put_rot_interior(lerp3(bottom, top, f32(k) / f32(sj)));
                }
            }
            if j > 0u {
                strip(prev_first, prev_s, j - 1u, first, sj, j);
            }
            prev_first = first;
            prev_s = sj;
            first += sj;
        }
    }
}

@compute @workgroup_size(64)
fn generate(@builtin(global_invocation_id) gid: vec3<u32>) {
    let t = invocation(gid);
    if t >= params.tri_count {
        return;
    }
    load_triangle(t);
    let at = counts[t];
    first_vertex = at.x;
    next_vertex = at.x;
    next_index = at.y;
    if params.mode == 1u {
        refine_dyadic();
    } else {
        refine_pattern();
    }
}

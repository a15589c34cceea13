// Screen-space helpers shared by ssao.wgsl and bounce.wgsl. The including shader declares a
// uniform `u` with `proj` (view to clip), `view` (world to view), `size` (xy: the G-buffer's
// size in pixels) and `plane_tolerance` (world units), and the textures `g_depth` and `g_normal`.

const PI: f32 = 3.14159265;
const GOLDEN_ANGLE: f32 = 2.39996323;
const INV_PHI: f32 = 0.61803399;

// The 4x4 interleaving pattern: each pixel of a 4x4 tile takes one of 16 rotations of the kernel.
const BAYER: array<u32, 16> = array<u32, 16>(0u, 8u, 2u, 10u, 12u, 4u, 14u, 6u, 3u, 11u, 1u, 9u, 15u, 7u, 13u, 5u);

fn pattern(q: vec2<i32>) -> u32 {
    return BAYER[u32(q.x & 3) + 4u * u32(q.y & 3)];
}

fn gsize() -> vec2<f32> {
    return u.size.xy;
}

fn inside(p: vec2<i32>) -> bool {
    let s = vec2<i32>(gsize());
    return p.x >= 0 && p.y >= 0 && p.x < s.x && p.y < s.y;
}

fn depth_at(p: vec2<i32>) -> f32 {
    return textureLoad(g_depth, p, 0).r;
}

// The view-space point at G-buffer pixel position `pix` (pixel units, y down) and depth d.
fn view_pos(pix: vec2<f32>, d: f32) -> vec3<f32> {
    let ndc = vec2<f32>(pix.x / gsize().x * 2.0 - 1.0, 1.0 - pix.y / gsize().y * 2.0);
    let x = (ndc.x + u.proj[2][0]) * d / u.proj[0][0];
    let y = (ndc.y + u.proj[2][1]) * d / u.proj[1][1];
    return vec3<f32>(x, y, -d);
}

// The G-buffer pixel position (pixel units, y down) a view-space point projects to.
fn to_pixel(q: vec3<f32>) -> vec2<f32> {
    let c = u.proj * vec4<f32>(q, 1.0);
    let ndc = c.xy / c.w;
    return vec2<f32>((ndc.x * 0.5 + 0.5) * gsize().x, (0.5 - ndc.y * 0.5) * gsize().y);
}

fn view_normal(p: vec2<i32>) -> vec3<f32> {
    let n = textureLoad(g_normal, p, 0).xyz;
    return normalize((u.view * vec4<f32>(n, 0.0)).xyz);
}

// How much G-buffer pixel `go` belongs to the surface of the point `p` with view normal `n`:
// its point must lie within the plane tolerance of p's tangent plane (so slanted planes keep
// their whole neighbourhood) and face the same way (weight (n . n_o)^4); 0 on background.
fn surface_similarity(p: vec3<f32>, n: vec3<f32>, go: vec2<i32>) -> f32 {
    let d = depth_at(go);
    if d <= 0.0 {
        return 0.0;
    }
    let po = view_pos(vec2<f32>(go) + 0.5, d);
    let plane = clamp(1.0 - abs(dot(po - p, n)) / u.plane_tolerance, 0.0, 1.0);
    let facing = pow(clamp(dot(view_normal(go), n), 0.0, 1.0), 4.0);
    return plane * facing;
}

// An orthonormal basis (t, b) around the unit vector n.
fn basis(n: vec3<f32>) -> mat3x3<f32> {
    let a = select(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 0.0), abs(n.x) > 0.9);
    let t = normalize(cross(a, n));
    return mat3x3<f32>(t, cross(n, t), n);
}

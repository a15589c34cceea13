// One bounce of diffuse light in screen space (nodes/occlusion/bounce.rs), in the spirit of
// the indirect part of screen-space directional occlusion (Ritschel et al. 2009), estimated
// by directions rather than by area: N cosine-weighted directions of the hemisphere above a
// pixel's point p are marched in 8 steps up to the radius R; where a step first passes
// behind the surface the camera sees (by less than R), that surface is the sender, and its
// radiance L_s (the lit image) arrives from that direction if it faces p:
//   E = pi / N sum L_s,  L_out += albedo E / pi.
// Two entry points: fs_gather writes E (rgb, unfiltered, one of 16 kernel rotations per pixel
// of a 4x4 tile) and fs_resolve averages E over the 4x4 tile, edge-aware, and adds
// strength * albedo * E / pi to the image.

struct Bounce {
    // View to clip (the G-buffer's projection).
    proj: mat4x4<f32>,
    // World to view (for the G-buffer's world normals).
    view: mat4x4<f32>,
    // xy: G-buffer size in pixels.
    size: vec4<f32>,
    radius: f32,
    // Unused (the sample count is SAMPLES).
    _unused: f32,
    strength: f32,
    // Of the resolve's edge test (world units).
    plane_tolerance: f32,
};

@group(0) @binding(0) var<uniform> u: Bounce;
@group(0) @binding(1) var g_depth: texture_2d<f32>;
@group(0) @binding(2) var g_normal: texture_2d<f32>;
@group(0) @binding(3) var g_color: texture_2d<f32>;
// fs_gather: the lit image (the senders' radiance); fs_resolve: the image the bounce is added to.
@group(0) @binding(4) var image: texture_2d<f32>;
// fs_resolve: fs_gather's output.
@group(0) @binding(5) var gathered: texture_2d<f32>;

// #include "fullscreen.wgsl"

// #include "screen_space.wgsl"

// Steps per direction.
const STEPS: u32 = 8u;
// Directions per pixel (the node's `samples`): a pipeline constant, since lavapipe compiles a
// shader again on every draw whose loop bound reads a uniform.
override SAMPLES: u32 = 8u;

@fragment
fn fs_gather(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let q = vec2<i32>(frag.xy);
    let d = depth_at(q);
    if d <= 0.0 {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    let p = view_pos(vec2<f32>(q) + 0.5, d);
    let n = view_normal(q);
    let frame = basis(n);
    let count = SAMPLES;
    let b = pattern(q);
    let total = f32(count * 16u);
    let bias = 0.02 * u.radius;
    var e = vec3<f32>(0.0);
    for (var k = 0u; k < count; k++) {
        // Direction 16k + b of a cosine-weighted Fibonacci set on the hemisphere.
        let i = f32(k * 16u + b);
        let u1 = (i + 0.5) / total;
        let r = sqrt(u1);
        let phi = i * GOLDEN_ANGLE;
        let dir = frame * vec3<f32>(r * cos(phi), r * sin(phi), sqrt(1.0 - u1));
        let jitter = fract((f32(k) + 0.5) * INV_PHI + (f32(b) + 0.5) / 16.0);
        for (var j = 0u; j < STEPS; j++) {
            let x = p + dir * (u.radius * (f32(j) + jitter) / f32(STEPS));
            let sp = vec2<i32>(floor(to_pixel(x)));
            if !inside(sp) || x.z >= 0.0 {
                break;
            }
            let sd = depth_at(sp);
            // The march passed behind the surface the camera sees there: that surface is the
            // sender, unless it lies more than a radius in front (the ray passes behind it).
            let behind = -x.z - sd;
            if sd <= 0.0 || behind <= bias || all(sp == q) {
                continue;
            }
            if behind < u.radius && dot(view_normal(sp), dir) < 0.0 {
                e += textureLoad(image, sp, 0).rgb;
            }
            break;
        }
    }
    // E = pi / N sum L over cosine-weighted directions.
    return vec4<f32>(e * (PI / f32(count)), 1.0);
}

@fragment
fn fs_resolve(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let q = vec2<i32>(frag.xy);
    let own = textureLoad(image, q, 0);
    let d = depth_at(q);
    if d <= 0.0 {
        return own;
    }
    let p = view_pos(vec2<f32>(q) + 0.5, d);
    let n = view_normal(q);
    var sum = vec3<f32>(0.0);
    var weight = 0.0;
    // The 4x4 tile around the pixel (offsets -2..1): every kernel rotation once.
    for (var y = -2; y <= 1; y++) {
        for (var x = -2; x <= 1; x++) {
            let o = q + vec2<i32>(x, y);
            if !inside(o) {
                continue;
            }
            let w = surface_similarity(p, n, o);
            sum += w * textureLoad(gathered, o, 0).rgb;
            weight += w;
        }
    }
    let albedo = textureLoad(g_color, q, 0).rgb;
    let e = sum / max(weight, 1e-6);
    return vec4<f32>(own.rgb + u.strength * albedo * e / PI, own.a);
}

// Screen-space ambient occlusion on the G-buffer (nodes/occlusion/ssao.rs), five entry points:
//   fs_sphere   the dissertation's depth-only sphere sampling (§3.2.2, §4.2.2),
//   fs_horizon  a horizon-based, normal-aware variant after GTAO (Jimenez et al. 2016),
//   fs_blur     the edge-aware (plane- and normal-aware) 4x4 filter that removes the dither,
//   fs_upsample the depth-aware upsampling of a half-resolution result,
//   fs_apply    an image times the factor.
// Every pass writes the visibility factor v in [0, 1] (1 = unoccluded) to rgb, alpha 1.
// Positions are reconstructed in view space from the G-buffer's linear depth (-z_view).
// An AO texel q stands for G-buffer pixel q * scale (scale 1, or 2 at half resolution).

// The sample count and whether the blur follows, set per pipeline
// (FullscreenPass::draw_specialized): lavapipe compiles a shader again on every draw whose loops
// or branches depend on uniforms alone.
override SAMPLES: u32 = 8u;
// The blur follows: the estimate is written unclamped, the blur clamps and applies the
// strength (the tile's average is then exactly the 16N-sample estimate).
override BLUR: bool = true;

struct Ssao {
    // View to clip (the G-buffer's projection).
    proj: mat4x4<f32>,
    // World to view (for the G-buffer's world normals).
    view: mat4x4<f32>,
    // xy: G-buffer size in pixels; zw: size of the AO texture this pass reads or writes.
    size: vec4<f32>,
    // World units.
    radius: f32,
    _unused0: f32,
    // The exponent.
    strength: f32,
    // 1, or 2 at half resolution.
    scale: f32,
    depth_bias: f32,
    // How far in front of a sample an occluder may be.
    range: f32,
    // Of the blur and upsampling.
    plane_tolerance: f32,
    _unused1: f32,
};

@group(0) @binding(0) var<uniform> u: Ssao;
@group(0) @binding(1) var g_depth: texture_2d<f32>;
@group(0) @binding(2) var g_normal: texture_2d<f32>;
// fs_blur, fs_upsample, fs_apply: the AO texture read.
@group(0) @binding(3) var ao_in: texture_2d<f32>;
// fs_apply: the image multiplied.
@group(0) @binding(4) var image: texture_2d<f32>;

// #include "fullscreen.wgsl"

// #include "screen_space.wgsl"

// The G-buffer pixel (integer) an AO texel stands for.
fn gpixel(q: vec2<i32>) -> vec2<i32> {
    return min(q * i32(u.scale), vec2<i32>(gsize()) - 1);
}

fn output(v: f32) -> vec4<f32> {
    return vec4<f32>(v, v, v, 1.0);
}

// Clamped to [0, 1] and raised to the strength (pow(0, 0) is undefined in WGSL: 1e-4 floor).
fn strengthen(v: f32) -> f32 {
    return pow(clamp(v, 1e-4, 1.0), u.strength);
}

// The estimate's output: as it is when the blur follows, else clamped and raised to the strength.
fn finish(v: f32) -> vec4<f32> {
    if BLUR {
        return output(v);
    }
    return output(strengthen(v));
}

const OPEN: u32 = 0u;
const OCCLUDED: u32 = 1u;
// On the surface within the bias: undecided, not counted (symmetric, so a plane still
// occludes exactly half of the decided samples).
const UNDECIDED: u32 = 2u;
const OFF_SCREEN: u32 = 3u;

// A sphere sample at view-space `q`: occluded when the G-buffer's depth where it projects is
// in front of it by more than the bias and by less than the range.
fn sample_state(q: vec3<f32>, bias: f32) -> u32 {
    let sp = vec2<i32>(floor(to_pixel(q)));
    if !inside(sp) || q.z >= 0.0 {
        return OFF_SCREEN;
    }
    let scene = depth_at(sp);
    let diff = -q.z - scene;
    if scene > 0.0 && abs(diff) <= bias {
        return UNDECIDED;
    }
    return select(OPEN, OCCLUDED, scene > 0.0 && diff > 0.0 && diff < u.range);
}

// Depth-only sphere sampling. N samples fill a sphere of radius R around the pixel's point;
// sample k of the pixel with pattern value b (0..15) takes direction 16k + b of a spherical
// Fibonacci set of 16N directions and radius R t, t = fract((k + 0.5) / phi + (b + 0.5) / 16)
// (uniform in radius: the volume density falls as 1/r^2, denser toward the centre). A sample
// is occluded when the G-buffer's depth where it projects is in front of it by more than the
// bias and by less than the range; samples within the bias of the surface in front or behind
// (undecided) are not counted; a sample off screen is replaced by its mirror image through the
// point, with the opposite outcome (not counted when that one is off screen too). With f the occluded
// fraction, v = clamp(2 (1 - f), 0, 1): a plane occludes half the sphere and gives 1.
@fragment
fn fs_sphere(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let q = vec2<i32>(frag.xy);
    let gp = gpixel(q);
    let d = depth_at(gp);
    if d <= 0.0 {
        return output(1.0);
    }
    let p = view_pos(vec2<f32>(gp) + 0.5, d);
    let radius = u.radius;
    let n = SAMPLES;
    let b = pattern(q);
    let total = f32(n * 16u);
    // The larger of the bias parameter and one G-buffer pixel's footprint at this depth
    // (a neighbouring pixel's centre depth differs from the sample ray's by about that much).
    let bias = max(u.depth_bias, 2.0 * d / (u.proj[1][1] * gsize().y));
    var occluded = 0.0;
    var counted = 0.0;
    for (var k = 0u; k < n; k++) {
        let i = f32(k * 16u + b);
        let z = 1.0 - 2.0 * (i + 0.5) / total;
        let s = sqrt(max(1.0 - z * z, 0.0));
        let phi = i * GOLDEN_ANGLE;
        let t = fract((f32(k) + 0.5) * INV_PHI + (f32(b) + 0.5) / 16.0);
        let offset = vec3<f32>(s * cos(phi), s * sin(phi), z) * (radius * t);
        var state = sample_state(p + offset, bias);
        if state == OFF_SCREEN {
            // Near the borders half of the sphere projects off screen, and which half is not
            // symmetric about the surface: skipping those samples darkens a band there. The
            // sample mirrored through p stands in for it, with the opposite outcome (exact
            // on a plane, where exactly one of a mirrored pair lies below the surface).
            let mirrored = sample_state(p - offset, bias);
            state = select(mirrored, 1u - mirrored, mirrored <= OCCLUDED);
        }
        if state > OCCLUDED {
            continue;
        }
        counted += 1.0;
        occluded += f32(state);
    }
    if counted == 0.0 {
        return output(1.0);
    }
    return finish(2.0 * (1.0 - occluded / counted));
}

// Horizon-based, normal-aware occlusion after GTAO. Two slices per pixel, their angles
// rotated by the 4x4 pattern (32 directions over a tile); on each side of a slice, samples/4
// steps out to the radius's projection (squared spacing, jittered by the pattern) find the
// horizon: the highest sample seen from the point within the world radius (a linear fade over
// the last quarter). The cosine-weighted visibility between the two horizons is integrated
// analytically about the normal projected into the slice (the paper's eq. 10), times the
// projected normal's length, and averaged over the slices: 1 on an open plane, 1/2 at a
// 90-degree concave edge, 1/4 in a corner.
@fragment
fn fs_horizon(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let q = vec2<i32>(frag.xy);
    let gp = gpixel(q);
    let d = depth_at(gp);
    if d <= 0.0 {
        return output(1.0);
    }
    let centre = vec2<f32>(gp) + 0.5;
    let p = view_pos(centre, d);
    let v = normalize(-p);
    let normal = view_normal(gp);
    let radius = u.radius;
    // The radius's length in G-buffer pixels at this depth.
    let radius_px = radius * u.proj[1][1] * 0.5 * gsize().y / d;
    if radius_px < 1.0 {
        return output(1.0);
    }
    let slices = 2u;
    let steps = max(SAMPLES / 4u, 1u);
    let b = f32(pattern(q));
    let jitter = fract((b + 0.5) * INV_PHI);
    var visibility = 0.0;
    for (var s = 0u; s < slices; s++) {
        let phi = (f32(s) + (b + 0.5) / 16.0) * PI / f32(slices);
        let dir = vec3<f32>(cos(phi), sin(phi), 0.0);
        // Screen y points down, view y up.
        let screen_dir = vec2<f32>(dir.x, -dir.y);
        let ortho = normalize(dir - dot(dir, v) * v);
        let axis = normalize(cross(ortho, v));
        let projected = normal - axis * dot(normal, axis);
        let len = length(projected);
        if len < 1e-4 {
            visibility += 1.0;
            continue;
        }
        let cos_n = clamp(dot(projected, v) / len, -1.0, 1.0);
        let n_angle = sign(dot(ortho, projected)) * acos(cos_n);
        // The lowest horizons: the tangent plane's in the slice.
        let low0 = cos(n_angle + 0.5 * PI);
        let low1 = cos(n_angle - 0.5 * PI);
        var h_cos0 = low0;
        var h_cos1 = low1;
        for (var j = 0u; j < steps; j++) {
            let t = (f32(j) + jitter) / f32(steps);
            let offset = max(radius_px * t * t, f32(j) + 1.0);
            for (var side = 0; side < 2; side++) {
                let sign_side = select(-1.0, 1.0, side == 0);
                let sp = vec2<i32>(floor(centre + sign_side * screen_dir * offset));
                if !inside(sp) {
                    continue;
                }
                let sd = depth_at(sp);
                if sd <= 0.0 {
                    continue;
                }
                let delta = view_pos(vec2<f32>(sp) + 0.5, sd) - p;
                let dist = length(delta);
                if dist < 1e-6 {
                    continue;
                }
                // Samples within 3 degrees of the tangent plane count as on it: pixel-centre
                // taps off the slice and half-float normals would otherwise darken a plane.
                if dot(delta, normal) < 0.05 * dist {
                    continue;
                }
                let c = dot(delta / dist, v);
                let fade = clamp((radius - dist) / (0.25 * radius), 0.0, 1.0);
                if side == 0 {
                    h_cos0 = max(h_cos0, mix(low0, c, fade));
                } else {
                    h_cos1 = max(h_cos1, mix(low1, c, fade));
                }
            }
        }
        var h0 = -acos(clamp(h_cos1, -1.0, 1.0));
        var h1 = acos(clamp(h_cos0, -1.0, 1.0));
        h0 = n_angle + clamp(h0 - n_angle, -0.5 * PI, 0.5 * PI);
        h1 = n_angle + clamp(h1 - n_angle, -0.5 * PI, 0.5 * PI);
        let sin_n = sin(n_angle);
        let arc0 = (cos_n + 2.0 * h0 * sin_n - cos(2.0 * h0 - n_angle)) * 0.25;
        let arc1 = (cos_n + 2.0 * h1 * sin_n - cos(2.0 * h1 - n_angle)) * 0.25;
        visibility += len * (arc0 + arc1);
    }
    return finish(visibility / f32(slices));
}

// How much neighbour AO texel `o` belongs to the surface of the point `p` with normal `n`
// (screen_space.wgsl, at the G-buffer pixel the texel stands for).
fn similarity(p: vec3<f32>, n: vec3<f32>, o: vec2<i32>) -> f32 {
    return surface_similarity(p, n, gpixel(o));
}

// The edge-aware filter over the 4x4 tile (offsets -2..1): exactly one pixel of each pattern
// value, so a uniform region's average is the full 16N-sample estimate.
@fragment
fn fs_blur(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let q = vec2<i32>(frag.xy);
    let gp = gpixel(q);
    let d = depth_at(gp);
    let own = textureLoad(ao_in, q, 0).r;
    if d <= 0.0 {
        return output(strengthen(own));
    }
    let p = view_pos(vec2<f32>(gp) + 0.5, d);
    let n = view_normal(gp);
    let size = vec2<i32>(u.size.zw);
    var sum = 0.0;
    var weight = 0.0;
    for (var y = -2; y <= 1; y++) {
        for (var x = -2; x <= 1; x++) {
            let o = q + vec2<i32>(x, y);
            if o.x < 0 || o.y < 0 || o.x >= size.x || o.y >= size.y {
                continue;
            }
            var w = 1.0;
            if x != 0 || y != 0 {
                w = similarity(p, n, o);
            }
            sum += w * textureLoad(ao_in, o, 0).r;
            weight += w;
        }
    }
    return output(strengthen(sum / weight));
}

// Half resolution to full: the four nearest half-resolution texels, bilinear weights times
// their similarity to this pixel's surface; the nearest texel where none is similar.
@fragment
fn fs_upsample(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let px = vec2<i32>(frag.xy);
    let d = depth_at(px);
    let half_pos = vec2<f32>(px) / u.scale;
    let base = vec2<i32>(floor(half_pos));
    let f = half_pos - vec2<f32>(base);
    let size = vec2<i32>(u.size.zw);
    let nearest = textureLoad(ao_in, min(vec2<i32>(round(half_pos)), size - 1), 0).r;
    if d <= 0.0 {
        return output(nearest);
    }
    let p = view_pos(vec2<f32>(px) + 0.5, d);
    let n = view_normal(px);
    var sum = 0.0;
    var weight = 0.0;
    for (var y = 0; y <= 1; y++) {
        for (var x = 0; x <= 1; x++) {
            let o = min(base + vec2<i32>(x, y), size - 1);
            let bilinear = select(1.0 - f.x, f.x, x == 1) * select(1.0 - f.y, f.y, y == 1);
            let w = bilinear * similarity(p, n, o);
            sum += w * textureLoad(ao_in, o, 0).r;
            weight += w;
        }
    }
    if weight < 1e-4 {
        return output(nearest);
    }
    return output(sum / weight);
}

@fragment
fn fs_apply(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let px = vec2<i32>(frag.xy);
    let c = textureLoad(image, px, 0);
    return vec4<f32>(c.rgb * textureLoad(ao_in, px, 0).r, c.a);
}

// Screen-space reflections with the environment as fallback (nodes/occlusion/ssr.rs, issue
// 34). IblShading reflects only the probe: c = albedo * sum_i VIS_i PEM_i(r', level(g)). Where
// the lobe about r' sees the scene instead (a ball above a lit floor), this pass swaps the
// probe for what the screen shows there. Per glossy pixel, K directions d_k of the Phong lobe
// cos^s about r' (s = 1/(1-g), IblShading's lobe) are marched against the G-buffer's depth;
// a ray that crosses a visible surface facing it takes the lit image's radiance L_k there,
// with weight h_k (1, fading over the end of the march); one that leaves the screen meets the
// edge pixel's tangent plane (`beyond`, h_k fading with the distance off screen). What is
// not hit escapes to the environment, whose radiance E_k along d_k weighs it. Then
//   out = image * m + albedo * (1/K) sum_k h_k L_k,   m = sum_k (1 - h_k) lum(E_k) / sum_k lum(E_k),
// so m is the share of the lobe's environment light that still arrives: IblShading's result
// (with its shadows and occlusion) is kept for that share, exactly where every ray escapes.
// fs_gather writes (1/K sum h L, m) with one of 16 lobe rotations per pixel of a 4x4 tile;
// fs_resolve averages over the tile, edge-aware, and fades in with glossiness above the
// threshold.

struct Ssr {
    // View to clip (the G-buffer's projection).
    proj: mat4x4<f32>,
    // World to view (rigid: its transpose turns view directions back into world ones).
    view: mat4x4<f32>,
    // xy: G-buffer size in pixels; z: the environment's face size; w: its top mip level.
    size: vec4<f32>,
    max_distance: f32,
    thickness: f32,
    samples: f32,
    threshold: f32,
    // Of the resolve's edge test (world units).
    plane_tolerance: f32,
    // How far beyond the screen the edge pixels' tangent planes reach, pixels (0: not at all).
    extend: f32,
    _pad: vec2<f32>,
    // Loop counts: march steps (16), bisections (4), resolve taps (16). They come from here
    // because llvmpipe runs every iteration of an unrolled constant-count loop even for pixels
    // that returned early (the node's cost with no glossy pixel fell from 25 to 18 ms).
    loops: vec4<u32>,
    // The hidden ground: rgb its albedo, w its height (world y).
    ground: vec4<f32>,
    // The shadow atlas's min variance, bleed reduction and depth bias.
    vsm: vec4<f32>,
};

// Lights of the hidden ground (0: no ground).
override LIGHTS: u32 = 0u;

@group(0) @binding(0) var<uniform> u: Ssr;
@group(0) @binding(1) var g_depth: texture_2d<f32>;
@group(0) @binding(2) var g_normal: texture_2d<f32>;
@group(0) @binding(3) var g_color: texture_2d<f32>;
// The lit image: the radiance of what rays hit, and what the reflections go into.
@group(0) @binding(4) var image: texture_2d<f32>;
// fs_resolve: fs_gather's output.
@group(0) @binding(5) var gathered: texture_2d<f32>;
// The environment cube (six-layer array, 2x2-box mip chain: shaders/ibl/cube.wgsl).
@group(0) @binding(6) var env: texture_2d_array<f32>;
// The ground's lights (shadowed_light.wgsl), their shadow atlas and its bilinear sampler.
@group(0) @binding(7) var<storage, read> lights: array<Light>;
@group(0) @binding(8) var atlas: texture_2d<f32>;
@group(0) @binding(9) var atlas_sampler: sampler;

// #include "fullscreen.wgsl"

// #include "screen_space.wgsl"

// #include "cube.wgsl"

// #include "shadowed_light.wgsl"

// Glossiness over which the reflections fade in above the threshold.
const GLOSS_FADE: f32 = 0.1;
// Share of the march, at its end, over which hits fade out.
const END_FADE: f32 = 0.2;

fn luminance(c: vec3<f32>) -> f32 {
    return dot(c, vec3<f32>(0.2126, 0.7152, 0.0722));
}

// World units one pixel spans at view depth d.
fn pixel_size(d: f32) -> f32 {
    return 2.0 * d / (u.proj[1][1] * gsize().y);
}

// 1 at the end of the march's first part, falling to 0 at max_distance.
fn end_weight(t: f32) -> f32 {
    return clamp((1.0 - t / u.max_distance) / END_FADE, 0.0, 1.0);
}

struct Hit {
    // Radiance times weight (0 where nothing was hit).
    radiance: vec3<f32>,
    weight: f32,
};

// A ray that leaves the screen: the surface at the edge pixel it left through is taken to go
// on as its tangent plane (a floor stays a floor), radiance and all; such hits fade out with
// their distance beyond the screen over u.extend pixels. Surfaces drawn there are no better
// known than SSAO's mirrored off-screen samples, but the ground plane just below the screen's
// bottom edge (what a ball near it reflects) is found, where the probe's ground is dark.
fn beyond(o: vec3<f32>, d: vec3<f32>, sp: vec2<i32>) -> Hit {
    var none: Hit;
    none.radiance = vec3<f32>(0.0);
    none.weight = 0.0;
    let e = clamp(sp, vec2<i32>(0), vec2<i32>(gsize()) - vec2<i32>(1));
    let de = depth_at(e);
    if de <= 0.0 || u.extend <= 0.0 {
        return none;
    }
    let pe = view_pos(vec2<f32>(e) + 0.5, de);
    let ne = view_normal(e);
    let facing = dot(d, ne);
    if facing >= -1e-4 {
        return none;
    }
    let t = dot(pe - o, ne) / facing;
    let x = o + d * t;
    if t <= 0.0 || t >= u.max_distance || x.z >= -1e-3 {
        return none;
    }
    let pix = to_pixel(x);
    let off = length(max(max(-pix, pix - gsize()), vec2<f32>(0.0)));
    let w = clamp(1.0 - off / u.extend, 0.0, 1.0) * end_weight(t);
    let at = clamp(vec2<i32>(floor(pix)), vec2<i32>(0), vec2<i32>(gsize()) - vec2<i32>(1));
    var hit: Hit;
    hit.radiance = w * textureLoad(image, at, 0).rgb;
    hit.weight = w;
    return hit;
}

// The hidden ground (the node's `ground`): where the world-space ray (wo, wd) goes down to the
// plane y = u.ground.w within the march's reach, the plane's radiance there, lit by the lights
// through their shadow tiles, albedo / pi sum_i VIS_i E_i max(0, l_i . y); it fades like hits.
fn ground_hit(wo: vec3<f32>, wd: vec3<f32>) -> Hit {
    var none: Hit;
    none.radiance = vec3<f32>(0.0);
    none.weight = 0.0;
    if wd.y >= -1e-4 {
        return none;
    }
    let t = (u.ground.w - wo.y) / wd.y;
    if t <= 0.0 || t >= u.max_distance {
        return none;
    }
    let x = wo + wd * t;
    var e = vec3<f32>(0.0);
    for (var i = 0u; i < LIGHTS; i++) {
        let light = lights[i];
        if light.dir.y > 0.0 {
            e += light.color.rgb * light.dir.y * light_visibility(light, atlas, atlas_sampler, x, vec3<f32>(0.0, 1.0, 0.0), u.vsm.xyz);
        }
    }
    var hit: Hit;
    let w = end_weight(t);
    hit.radiance = w * u.ground.rgb / PI * e;
    hit.weight = w;
    return hit;
}

// Marches view-space direction `d` from `o` (the pixel's point `q`) against the depth buffer.
fn march(o: vec3<f32>, d: vec3<f32>, q: vec2<i32>, jitter: f32) -> Hit {
    var none: Hit;
    none.radiance = vec3<f32>(0.0);
    none.weight = 0.0;
    var prev_t = 0.0;
    // Whether the previous step was behind the visible surface: a ray that starts or runs
    // behind an occluder may not hit it from there (it passes behind, or cannot be seen).
    var prev_behind = false;
    // Steps spaced quadratically: fine near the surface.
    for (var j = 0u; j < u.loops.x; j++) {
        let s = (f32(j) + jitter) / f32(u.loops.x);
        let t = u.max_distance * s * s;
        let x = o + d * t;
        if x.z >= -1e-3 {
            return none;
        }
        let pix = to_pixel(x);
        let sp = vec2<i32>(floor(pix));
        if !inside(sp) {
            return beyond(o, d, sp);
        }
        let sd = depth_at(sp);
        if sd <= 0.0 || all(sp == q) {
            prev_behind = false;
            prev_t = t;
            continue;
        }
        let behind = -x.z - sd;
        let tolerance = u.thickness + abs(d.z) * (t - prev_t);
        if behind > pixel_size(sd) && !prev_behind && behind < tolerance {
            // Bisect the last step for the crossing.
            var lo = prev_t;
            var hi = t;
            for (var i = 0u; i < u.loops.y; i++) {
                let mid = 0.5 * (lo + hi);
                let xm = o + d * mid;
                let sm = vec2<i32>(floor(to_pixel(xm)));
                if inside(sm) && depth_at(sm) > 0.0 && -xm.z > depth_at(sm) {
                    hi = mid;
                } else {
                    lo = mid;
                }
            }
            let sh = vec2<i32>(floor(to_pixel(o + d * hi)));
            // A surface facing away (the ray's own surface, met again through the depth
            // buffer's steps) is passed behind.
            if inside(sh) && depth_at(sh) > 0.0 && dot(view_normal(sh), d) < 0.0 {
                var hit: Hit;
                let w = end_weight(hi);
                hit.radiance = w * textureLoad(image, sh, 0).rgb;
                hit.weight = w;
                return hit;
            }
        }
        prev_behind = behind > pixel_size(sd);
        prev_t = t;
    }
    return none;
}

// The environment's texel along world direction `d` at the mip level nearest `level`: these
// are weights only, and the seamless trilinear lookup (cube_trilinear) cost llvmpipe 7 ms
// more at every pixel.
fn env_texel(d: vec3<f32>, level: f32) -> vec3<f32> {
    let l = u32(round(level));
    let size = max(u32(u.size.z) >> l, 1u);
    let f = dir_to_face(d);
    let t = clamp(vec2<i32>(floor((f.uv + vec2<f32>(1.0)) * 0.5 * f32(size))), vec2<i32>(0), vec2<i32>(i32(size) - 1));
    return textureLoad(env, t, i32(f.face), i32(l)).rgb;
}

@fragment
fn fs_gather(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let q = vec2<i32>(frag.xy);
    let d = depth_at(q);
    let color = textureLoad(g_color, q, 0);
    let g = clamp(color.a, 0.0, 1.0);
    if d <= 0.0 || g <= u.threshold {
        return vec4<f32>(0.0, 0.0, 0.0, 1.0);
    }
    let p = view_pos(vec2<f32>(q) + 0.5, d);
    let n = view_normal(q);
    let r = reflect(normalize(p), n);
    // IblShading's lobe: cos^s about r' = n (1 - g) + r g.
    let axis = normalize(n * (1.0 - g) + r * g);
    let s = select(1.0 / (1.0 - g), 1e6, g >= 1.0);
    let frame = basis(axis);
    let to_world = transpose(mat3x3<f32>(u.view[0].xyz, u.view[1].xyz, u.view[2].xyz));
    let count = u32(u.samples);
    let b = pattern(q);
    let total = f32(count * 16u);
    // As in filtered importance sampling (Colbert and Krivanek 2007), each direction reads the
    // environment at the level whose texels cover its share of the lobe's solid angle.
    let texel = 4.0 * PI / (6.0 * u.size.z * u.size.z);
    let o = p + n * (2.0 * pixel_size(d));
    let world_origin = to_world * (o - u.view[3].xyz);
    var hits = vec3<f32>(0.0);
    var env_all = 0.0;
    var env_missed = 0.0;
    for (var k = 0u; k < count; k++) {
        // Direction 16k + b of a Fibonacci set distributed as cos^s about the axis.
        let i = f32(k * 16u + b);
        let u1 = (i + 0.5) / total;
        let cos_t = pow(u1, 1.0 / (s + 1.0));
        let sin_t = sqrt(max(1.0 - cos_t * cos_t, 0.0));
        let phi = i * GOLDEN_ANGLE;
        var dir = frame * vec3<f32>(sin_t * cos(phi), sin_t * sin(phi), cos_t);
        // Directions under the surface (a wide lobe near the horizon) are mirrored above it.
        let below = dot(dir, n);
        if below < 0.0 {
            dir -= 2.0 * below * n;
        }
        let pdf = (s + 1.0) / (2.0 * PI) * pow(cos_t, s);
        let level = clamp(0.5 * log2(1.0 / (f32(count) * pdf * texel)) + 1.0, 0.0, u.size.w);
        let e = luminance(env_texel(to_world * dir, level));
        let jitter = fract((f32(k) + 0.5) * INV_PHI + (f32(b) + 0.5) / 16.0);
        var hit = march(o, dir, q, jitter);
        if LIGHTS > 0u && hit.weight < 1.0 {
            // What the screen did not show of a ray going down: the ground.
            let ground = ground_hit(world_origin, to_world * dir);
            hit.radiance += (1.0 - hit.weight) * ground.radiance;
            hit.weight += (1.0 - hit.weight) * ground.weight;
        }
        hits += hit.radiance;
        env_all += e;
        env_missed += (1.0 - hit.weight) * e;
    }
    let missed = select(env_missed / env_all, 1.0, env_all <= 0.0);
    return vec4<f32>(hits / f32(count), missed);
}

@fragment
fn fs_resolve(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let q = vec2<i32>(frag.xy);
    let own = textureLoad(image, q, 0);
    let d = depth_at(q);
    let color = textureLoad(g_color, q, 0);
    let g = clamp(color.a, 0.0, 1.0);
    if d <= 0.0 || g <= u.threshold {
        return own;
    }
    let p = view_pos(vec2<f32>(q) + 0.5, d);
    let n = view_normal(q);
    var sum = vec4<f32>(0.0);
    var weight = 0.0;
    // The 4x4 tile around the pixel (offsets -2..1): every lobe rotation once; neighbours
    // below the threshold gathered nothing.
    for (var t = 0u; t < u.loops.z; t++) {
        let o = q + vec2<i32>(i32(t & 3u) - 2, i32(t >> 2u) - 2);
        if !inside(o) || textureLoad(g_color, o, 0).a <= u.threshold {
            continue;
        }
        let w = surface_similarity(p, n, o);
        sum += w * textureLoad(gathered, o, 0);
        weight += w;
    }
    let mean = sum / max(weight, 1e-6);
    let reflected = own.rgb * mean.a + color.rgb * mean.rgb;
    let fade = smoothstep(u.threshold, u.threshold + GLOSS_FADE, g);
    return vec4<f32>(mix(own.rgb, reflected, fade), own.a);
}

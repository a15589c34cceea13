// Screen-space reflections with the environment as fallback (nodes/occlusion/ssr.rs, issue
// 34). IblShading reflects only the probe: c = albedo * sum_i VIS_i PEM_i(r', level(g)), a
// Phong lobe cos^s about r' = n (1 - g) + r g, s = 1/(1-g). Where the lobe sees the scene
// instead (a ball above a lit floor), this pass swaps the probe for what the screen shows
// there. Per glossy pixel, K rays follow the GGX lobe of the same width (alpha^2 = 2/(4s + 2),
// the exporter's material for Cycles), drawn by its visible normals (Heitz 2018) with weights
// w_k = G2/G1; they are marched against the G-buffer's depth; a ray that crosses a visible
// surface facing it takes the lit image's radiance L_k there, with weight h_k (1, fading over
// the end of the march); one that leaves the screen meets the edge pixel's tangent plane
// (`beyond`, h_k fading with the distance off screen). What is not hit escapes to the
// environment, whose radiance E_k along the ray weighs it. Then
//   out = image * m + albedo * sum_k w_k h_k L_k / sum_k w_k,
//   m = [sum_k w_k (1 - h_k) E_k / sum_k w_k E_k] * [GGX(E) / PHONG(E)],
// the first factor the share of the lobe's environment light that still arrives, the second
// what the GGX lobe reads of the environment over what IblShading's Phong lobe read (under the
// surface's horizon included), each by ENV_RAYS x K environment-only directions. So
// IblShading's result (its shadows and occlusion) is kept for the escaped share, reshaped to
// the GGX lobe: unchanged under a uniform probe. The weights are normalised, as if multiple
// scattering returned the energy single scattering loses (Cycles' multiscatter GGX, in white).
// fs_gather writes (sum w h L / sum w, m) with one of 16 lobe rotations per pixel of a 4x4
// tile; fs_resolve averages over the tile, edge-aware, and fades in with glossiness above the
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
// The environment's levels read by a counted loop (load_counted, shaders/ibl/cube.wgsl): set on
// wgpu's GL backend only.
override COUNTED_LEVELS: bool = false;

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

// Environment-only directions per marched ray.
const ENV_RAYS: u32 = 4u;

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
    if COUNTED_LEVELS {
        return load_counted(env, vec3<i32>(t, i32(f.face)), i32(l)).rgb;
    }
    return textureLoad(env, t, i32(f.face), i32(l)).rgb;
}

// The environment level for a direction drawn with density pdf among count.
fn env_level(pdf: f32, count: u32, texel: f32) -> f32 {
    return clamp(0.5 * log2(1.0 / (f32(count) * max(pdf, 1e-6) * texel)) + 1.0, 0.0, u.size.w);
}

// Smith's Lambda for GGX at cos theta c.
fn smith_lambda(c: f32, alpha: f32) -> f32 {
    let t2 = max(1.0 - c * c, 0.0) / max(c * c, 1e-8);
    return 0.5 * (-1.0 + sqrt(1.0 + alpha * alpha * t2));
}

// The GGX normal distribution D(h) at cos theta_h c.
fn ggx_ndf(c: f32, alpha: f32) -> f32 {
    let a2 = alpha * alpha;
    let k = c * c * (a2 - 1.0) + 1.0;
    return a2 / (PI * k * k);
}

// A GGX visible normal for the view ve (tangent space, z the normal), Heitz 2018.
fn sample_vndf(ve: vec3<f32>, alpha: f32, u1: f32, u2: f32) -> vec3<f32> {
    let vh = normalize(vec3<f32>(alpha * ve.x, alpha * ve.y, max(ve.z, 1e-4)));
    let len2 = vh.x * vh.x + vh.y * vh.y;
    let t1_axis = select(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(-vh.y, vh.x, 0.0) / sqrt(len2), len2 > 1e-12);
    let t2_axis = cross(vh, t1_axis);
    let rad = sqrt(u1);
    let phi = 2.0 * PI * u2;
    let t1 = rad * cos(phi);
    let sv = 0.5 * (1.0 + vh.z);
    let t2 = (1.0 - sv) * sqrt(max(1.0 - t1 * t1, 0.0)) + sv * rad * sin(phi);
    let nh = t1 * t1_axis + t2 * t2_axis + sqrt(max(1.0 - t1 * t1 - t2 * t2, 0.0)) * vh;
    return normalize(vec3<f32>(alpha * nh.x, alpha * nh.y, max(nh.z, 1e-6)));
}

// A GGX ray for the view ve (tangent space): its direction, its weight G2 / G1 (0 where the
// reflection falls under the surface) and its density D_v(h) / (4 v.h) = G1(v) D(h) / (4 v.n).
struct GgxRay {
    dir: vec3<f32>,
    weight: f32,
    pdf: f32,
};

fn ggx_ray(ve: vec3<f32>, alpha: f32, lambda_v: f32, u1: f32, u2: f32) -> GgxRay {
    let h = sample_vndf(ve, alpha, u1, u2);
    var ray: GgxRay;
    ray.dir = reflect(-ve, h);
    ray.weight = select(0.0, (1.0 + lambda_v) / (1.0 + lambda_v + smith_lambda(ray.dir.z, alpha)), ray.dir.z > 0.0);
    ray.pdf = ggx_ndf(h.z, alpha) / (4.0 * max(ve.z, 1e-4) * (1.0 + lambda_v));
    return ray;
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
    // IblShading's lobe: cos^s about r'.
    let axis = normalize(n * (1.0 - g) + r * g);
    let s = select(1.0 / (1.0 - g), 1e6, g >= 1.0);
    let phong_frame = basis(axis);
    // The GGX lobe of the same width (alpha^2 = 2 / (4 s + 2), as Blinn-Phong 4 s; Walter et al.
    // 2007): the rays follow it, sampled by its visible normals (Heitz 2018).
    let alpha = max(sqrt(2.0 / (4.0 * s + 2.0)), 1e-3);
    let frame = basis(n);
    let ve = transpose(frame) * -normalize(p);
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
    var weights = 0.0;
    var env_seen = 0.0;
    var env_missed = 0.0;
    let lambda_v = smith_lambda(max(ve.z, 1e-4), alpha);
    for (var k = 0u; k < count; k++) {
        // Direction 16k + b of a Fibonacci set: a visible normal of the GGX lobe, the view
        // reflected about it, weighed by G2 / G1 (BRDF x cos over the VNDF's pdf, colour aside).
        let i = f32(k * 16u + b);
        let ray = ggx_ray(ve, alpha, lambda_v, (i + 0.5) / total, fract(i * (1.0 - INV_PHI)));
        if ray.weight <= 0.0 {
            continue;
        }
        let dir = frame * ray.dir;
        let e = luminance(env_texel(to_world * dir, env_level(ray.pdf, count, texel)));
        let jitter = fract((f32(k) + 0.5) * INV_PHI + (f32(b) + 0.5) / 16.0);
        var hit = march(o, dir, q, jitter);
        if LIGHTS > 0u && hit.weight < 1.0 {
            // What the screen did not show of a ray going down: the ground.
            let ground = ground_hit(world_origin, to_world * dir);
            hit.radiance += (1.0 - hit.weight) * ground.radiance;
            hit.weight += (1.0 - hit.weight) * ground.weight;
        }
        hits += ray.weight * hit.radiance;
        weights += ray.weight;
        env_seen += ray.weight * e;
        env_missed += ray.weight * (1.0 - hit.weight) * e;
    }
    // What the two lobes read of the environment alone, by ENV_RAYS times as many directions
    // (no march: cheap): IblShading's Phong lobe cos^s about r' (under the surface's horizon
    // included, as its PEM lookup) and the GGX lobe.
    let env_count = count * ENV_RAYS;
    let env_total = f32(env_count * 16u);
    var phong_env = 0.0;
    var ggx_env = 0.0;
    var ggx_weights = 0.0;
    for (var k = 0u; k < env_count; k++) {
        let i = f32(k * 16u + b);
        let u1 = (i + 0.5) / env_total;
        let u2 = fract(i * (1.0 - INV_PHI));
        let cos_t = pow(u1, 1.0 / (s + 1.0));
        let sin_t = sqrt(max(1.0 - cos_t * cos_t, 0.0));
        let phi = 2.0 * PI * u2;
        let dp = phong_frame * vec3<f32>(sin_t * cos(phi), sin_t * sin(phi), cos_t);
        let pdf_p = (s + 1.0) / (2.0 * PI) * pow(cos_t, s);
        phong_env += luminance(env_texel(to_world * dp, env_level(pdf_p, env_count, texel)));
        let ray = ggx_ray(ve, alpha, lambda_v, u1, u2);
        if ray.weight > 0.0 {
            ggx_env += ray.weight * luminance(env_texel(to_world * (frame * ray.dir), env_level(ray.pdf, env_count, texel)));
            ggx_weights += ray.weight;
        }
    }
    // Normalised to the rays' total weight: the energy multiple scattering returns (Cycles'
    // multiscatter GGX) is taken as white. m, the share of IblShading's result that stays (its
    // shadows and occlusion kept): the marched rays' missed share of their environment light,
    // times the GGX lobe's environment light over what the Phong lobe read.
    let norm = max(weights, 1e-6);
    let missed_share = select(env_missed / env_seen, 1.0, env_seen <= 0.0);
    let reshape = select((ggx_env / ggx_weights) / (phong_env / f32(env_count)), 1.0, phong_env <= 0.0 || ggx_weights <= 0.0);
    return vec4<f32>(select(hits / norm, vec3<f32>(0.0), weights <= 0.0), missed_share * reshape);
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

// Image-based lighting with partial environment maps, eq. 3.43 of the dissertation:
//   c(x, y) = albedo * sum_i VIS_i(x, y) * PEM_i(r', level(g)),  r' = n (1 - g) + r g,
// g the G-buffer's glossiness, level(g) the mip level whose filtered lobe matches the volume
// of the Phong lobe of exponent s = 1 / (1 - g) (src/ibl/pem.rs Calibration). Up to 8 PEMs
// per pass; passes accumulate through `previous`, so any number of regions works.
// VIS_i is 1 without a shadow atlas; with one (nodes/ibl/shadow_atlas.rs), Chebyshev's upper
// bound on the blurred moments of light i's tile, with light-bleeding reduction.
// Below the chain's 8^2 level a lookup blends in the map's diffuse end (the cosine lobe at 16^2,
// src/ibl/pem.rs Handover): a chain's own diffuse level is too coarse for bilinear lookups.
// The pass is included by one of two files that declare the cube maps `env`, `pem0`..`pem7`
// (bindings 5..13), the diffuse ends (binding 17), `lookup(cube, direction, lod)`,
// `diffuse_taps(direction)` and `diffuse_end(k, direction, taps)`: ibl_shading_hw.wgsl
// (hardware cube sampling) and ibl_shading.wgsl (textureLoad, its reference twin).

// The pass's switches, set per pipeline (FullscreenPass::draw_specialized) instead of read from
// the uniform block: lavapipe compiles a shader again on every draw whose branches depend on
// uniforms alone.
// PEMs bound in this pass (0..8).
override PEMS: u32 = 8u;
// Shade with the full filtered map (one lookup, no partition).
override FULL_MAP: bool = false;
// The background shows the environment map (else `background.rgb`).
override BACKGROUND_ENV: bool = false;
// A shadow atlas is bound (else VIS_i = 1).
override SHADOWS: bool = false;
// Shadow lookups are jittered.
override JITTER: bool = false;
// The diffuse ends are bound and blended in below the handover.
override DIFFUSE_ENDS: bool = false;

struct Ibl {
    inv_view_proj: mat4x4<f32>,
    // x: width, y: height, z unused, w: 1 on the first pass (which writes; later passes add to
    // `previous`). Read through `select`, not a branch, so every pass of a frame shares one
    // pipeline (a pipeline of this shader took lavapipe about 1.5 s to compile).
    size: vec4<f32>,
    // rgb: background colour (w unused).
    background: vec4<f32>,
    background_level: f32,
    top_level: f32,
    _unused: f32,
    // Face size of level 0.
    face_size: f32,
    // Mip level for s = 2^(i * 10 / 32), i = 0..32 (33 entries).
    levels: array<vec4<f32>, 9>,
    // x: the diffuse ends' face size, y: the handover level, z: its exponent (w unused).
    diffuse: vec4<f32>,
};

@group(0) @binding(0) var<uniform> ibl: Ibl;
@group(0) @binding(1) var g_color: texture_2d<f32>;
@group(0) @binding(2) var g_normal: texture_2d<f32>;
@group(0) @binding(3) var g_depth: texture_2d<f32>;
@group(0) @binding(4) var previous: texture_2d<f32>;
@group(0) @binding(14) var atlas: texture_2d<f32>;

struct Shadow {
    // World to atlas coordinates (xy in [0, 1] over the atlas, z the light's depth), per PEM of the pass.
    to_atlas: array<mat4x4<f32>, 8>,
    // Each tile in atlas coordinates, inset by half a texel: x0, y0, x1, y1.
    rect: array<vec4<f32>, 8>,
    min_variance: f32,
    bleed_reduction: f32,
    // In texels.
    jitter: f32,
    _unused: f32,
    // Each light's lookup offset along the normal (world units: its tile's texels).
    normal_offset: array<vec4<f32>, 2>,
    // x, y: atlas size (texels), z: unused, w: depth bias.
    bias: vec4<f32>,
    eye: vec4<f32>,
    forward: vec4<f32>,
};
@group(0) @binding(15) var<uniform> shadow: Shadow;
// Bilinear lookups of the shadow atlas's moments.
@group(0) @binding(16) var samp: sampler;

// #include "fullscreen.wgsl"
// #include "cube.wgsl"
// #include "vsm_visibility.wgsl"

fn table(i: u32) -> f32 {
    return ibl.levels[i / 4u][i % 4u];
}

// The calibrated mip level for glossiness g (Calibration::level_for_glossiness): s = 1/(1-g),
// linear in log2 s between table entries, extrapolated past the last one with its slope,
// clamped to [0, top]; g = 1 is the mirror, level 0.
fn level_for_glossiness(g: f32) -> f32 {
    if g >= 1.0 {
        return 0.0;
    }
    let s = 1.0 / (1.0 - max(g, 0.0));
    let x = max(log2(max(s, 1.0)), 0.0) * 3.2;
    let i = min(u32(floor(x)), 31u);
    let l = table(i) + (table(i + 1u) - table(i)) * (x - f32(i));
    return clamp(l, 0.0, ibl.top_level);
}

// The diffuse end's weight at glossiness g (Handover::diffuse_weight): from 1 at s = 1 to 0 at
// the handover exponent, matching lobe volumes; 0 beyond.
fn diffuse_weight(g: f32) -> f32 {
    if !DIFFUSE_ENDS || g >= 1.0 {
        return 0.0;
    }
    let s = max(1.0 / (1.0 - max(g, 0.0)), 1.0);
    if s >= ibl.diffuse.z {
        return 0.0;
    }
    let chain = (1.0 / (s + 1.0) - 0.5) / (1.0 / (ibl.diffuse.z + 1.0) - 0.5);
    return 1.0 - clamp(chain, 0.0, 1.0);
}

// PEM k's (or the full map's, k = 0) radiance along d: the chain's lookup blended with the
// diffuse end by weight wd (`taps`: diffuse_taps(d), the same for every PEM).
fn with_diffuse(k: u32, chain: vec3<f32>, d: vec3<f32>, taps: CubeTaps, wd: f32) -> vec3<f32> {
    if wd <= 0.0 {
        return chain;
    }
    return mix(chain, diffuse_end(k, d, taps), wd);
}

fn hash2(p: vec2<u32>, k: u32) -> vec2<f32> {
    var h = p.x * 73856093u ^ p.y * 19349663u ^ k * 83492791u;
    h = (h ^ (h >> 16u)) * 0x45d9f3bu;
    h = (h ^ (h >> 16u)) * 0x45d9f3bu;
    h = h ^ (h >> 16u);
    return vec2<f32>(f32(h & 0xffffu), f32(h >> 16u)) / 65535.0;
}

// VIS_k of the pass's light k at world position p with normal n (pixel px for the jitter).
fn visibility(k: u32, p: vec3<f32>, n: vec3<f32>, px: vec2<i32>) -> f32 {
    if !SHADOWS {
        return 1.0;
    }
    let c = shadow.to_atlas[k] * vec4<f32>(p + n * shadow.normal_offset[k / 4u][k % 4u], 1.0);
    var uv = c.xy;
    if JITTER {
        // A 4x4 tiled hash per light (Fig. 4.13): a different pattern for each light.
        let n = hash2(vec2<u32>(px) % vec2<u32>(4u), k + 1u) * 2.0 - 1.0;
        uv += n * shadow.jitter / shadow.bias.xy;
    }
    let r = shadow.rect[k];
    uv = clamp(uv, r.xy, r.zw);
    let m = textureSampleLevel(atlas, samp, uv, 0.0).xy;
    return chebyshev_visibility(m, c.z - shadow.bias.w, shadow.min_variance, shadow.bleed_reduction);
}

// Light k's term: its PEM's radiance times its visibility. The shadow lookup is skipped where
// the PEM is black along the lobe (most of many small regions for glossy pixels); the term is
// then zero either way.
fn lit(k: u32, radiance: vec3<f32>, p: vec3<f32>, n: vec3<f32>, px: vec2<i32>) -> vec3<f32> {
    if all(radiance == vec3<f32>(0.0)) {
        return radiance;
    }
    return visibility(k, p, n, px) * radiance;
}

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let px = vec2<i32>(frag.xy);
    let first = ibl.size.w > 0.5;
    let prior = select(textureLoad(previous, px, 0).rgb, vec3<f32>(0.0), first);

    // The view ray through this pixel.
    let ndc = vec2<f32>(frag.x / ibl.size.x * 2.0 - 1.0, 1.0 - frag.y / ibl.size.y * 2.0);
    let far_h = ibl.inv_view_proj * vec4<f32>(ndc, 1.0, 1.0);
    let near_h = ibl.inv_view_proj * vec4<f32>(ndc, 0.0, 1.0);
    let ray = normalize(far_h.xyz / far_h.w - near_h.xyz / near_h.w);

    let depth = textureLoad(g_depth, px, 0).r;
    if depth <= 0.0 {
        // The first pass writes the background; later ones keep it.
        var background = ibl.background.rgb;
        if BACKGROUND_ENV {
            background = lookup(env, ray, ibl.background_level);
        }
        return vec4<f32>(select(prior, background, first), 1.0);
    }
    let color = textureLoad(g_color, px, 0);
    let n = normalize(textureLoad(g_normal, px, 0).xyz);
    let g = clamp(color.a, 0.0, 1.0);
    let r = reflect(ray, n);
    // Eq. 3.39: the sample vector blends from the normal (diffuse) to the mirror direction.
    let sample_dir = n * (1.0 - g) + r * g;
    let wd = diffuse_weight(g);
    // Blending with the diffuse end, the chain is read at the handover level.
    let level = select(level_for_glossiness(g), ibl.diffuse.y, wd > 0.0);
    var taps: CubeTaps;
    if wd > 0.0 {
        taps = diffuse_taps(sample_dir);
    }

    var sum = vec3<f32>(0.0);
    if FULL_MAP {
        sum = with_diffuse(0u, lookup(env, sample_dir, level), sample_dir, taps, wd);
    } else {
        let count = PEMS;
        // World position: depth is the linear view depth along the camera's forward axis.
        let p = shadow.eye.xyz + ray * (depth / dot(ray, shadow.forward.xyz));
        let d = sample_dir;
        // Eq. 3.43 (VIS_i = 1 exactly without an atlas: the products are then exact).
        // One `if` per binding, not a loop over a switch: llvmpipe runs every case of a
        // switch in a loop (8x the lookups).
        if count > 0u { sum += lit(0u, with_diffuse(0u, lookup(pem0, d, level), d, taps, wd), p, n, px); }
        if count > 1u { sum += lit(1u, with_diffuse(1u, lookup(pem1, d, level), d, taps, wd), p, n, px); }
        if count > 2u { sum += lit(2u, with_diffuse(2u, lookup(pem2, d, level), d, taps, wd), p, n, px); }
        if count > 3u { sum += lit(3u, with_diffuse(3u, lookup(pem3, d, level), d, taps, wd), p, n, px); }
        if count > 4u { sum += lit(4u, with_diffuse(4u, lookup(pem4, d, level), d, taps, wd), p, n, px); }
        if count > 5u { sum += lit(5u, with_diffuse(5u, lookup(pem5, d, level), d, taps, wd), p, n, px); }
        if count > 6u { sum += lit(6u, with_diffuse(6u, lookup(pem6, d, level), d, taps, wd), p, n, px); }
        if count > 7u { sum += lit(7u, with_diffuse(7u, lookup(pem7, d, level), d, taps, wd), p, n, px); }
    }
    return vec4<f32>(prior + color.rgb * sum, 1.0);
}

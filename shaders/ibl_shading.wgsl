// Image-based lighting with partial environment maps, eq. 3.43 of the dissertation:
//   c(x, y) = albedo * sum_i VIS_i(x, y) * PEM_i(r', level(g)),  r' = n (1 - g) + r g,
// g the G-buffer's glossiness, level(g) the mip level whose filtered lobe matches the volume
// of the Phong lobe of exponent s = 1 / (1 - g) (src/ibl/pem.rs Calibration). Up to 8 PEMs
// per pass; passes accumulate through `previous`, so any number of regions works.
// Until the shadow atlas lands every VIS_i is 1.

struct Ibl {
    inv_view_proj: mat4x4<f32>,
    // x: width, y: height, z: PEMs bound in this pass (0..8), w: 1 on the first pass.
    size: vec4<f32>,
    // rgb: background colour; w: background mode (0 colour, 1 the environment map).
    background: vec4<f32>,
    // x: background mip level, y: top mip level, z: 1 to shade with the full filtered map
    // (one lookup, no partition), w: face size of level 0.
    misc: vec4<f32>,
    // Mip level for s = 2^(i * 10 / 32), i = 0..32 (33 entries).
    levels: array<vec4<f32>, 9>,
};

@group(0) @binding(0) var<uniform> ibl: Ibl;
@group(0) @binding(1) var g_color: texture_2d<f32>;
@group(0) @binding(2) var g_normal: texture_2d<f32>;
@group(0) @binding(3) var g_depth: texture_2d<f32>;
@group(0) @binding(4) var previous: texture_2d<f32>;
// Cube maps as six-layer arrays with mips (shaders/cube.wgsl).
@group(0) @binding(5) var env: texture_2d_array<f32>;
@group(0) @binding(6) var pem0: texture_2d_array<f32>;
@group(0) @binding(7) var pem1: texture_2d_array<f32>;
@group(0) @binding(8) var pem2: texture_2d_array<f32>;
@group(0) @binding(9) var pem3: texture_2d_array<f32>;
@group(0) @binding(10) var pem4: texture_2d_array<f32>;
@group(0) @binding(11) var pem5: texture_2d_array<f32>;
@group(0) @binding(12) var pem6: texture_2d_array<f32>;
@group(0) @binding(13) var pem7: texture_2d_array<f32>;

// #include "fullscreen.wgsl"
// #include "cube.wgsl"

fn lookup(tex: texture_2d_array<f32>, d: vec3<f32>, lod: f32) -> vec3<f32> {
    return cube_trilinear(tex, u32(ibl.misc.w), ibl.misc.y, d, lod).rgb;
}

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
    return clamp(l, 0.0, ibl.misc.y);
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
        if !first {
            return vec4<f32>(prior, 1.0);
        }
        if ibl.background.w > 0.5 {
            return vec4<f32>(lookup(env, ray, ibl.misc.x), 1.0);
        }
        return vec4<f32>(ibl.background.rgb, 1.0);
    }
    let color = textureLoad(g_color, px, 0);
    let n = normalize(textureLoad(g_normal, px, 0).xyz);
    let g = clamp(color.a, 0.0, 1.0);
    let r = reflect(ray, n);
    // Eq. 3.39: the sample vector blends from the normal (diffuse) to the mirror direction.
    let sample_dir = n * (1.0 - g) + r * g;
    let level = level_for_glossiness(g);

    var sum = vec3<f32>(0.0);
    if ibl.misc.z > 0.5 {
        sum = lookup(env, sample_dir, level);
    } else {
        let count = u32(ibl.size.z);
        // Eq. 3.43 with VIS_i = 1.
        if count > 0u { sum += lookup(pem0, sample_dir, level); }
        if count > 1u { sum += lookup(pem1, sample_dir, level); }
        if count > 2u { sum += lookup(pem2, sample_dir, level); }
        if count > 3u { sum += lookup(pem3, sample_dir, level); }
        if count > 4u { sum += lookup(pem4, sample_dir, level); }
        if count > 5u { sum += lookup(pem5, sample_dir, level); }
        if count > 6u { sum += lookup(pem6, sample_dir, level); }
        if count > 7u { sum += lookup(pem7, sample_dir, level); }
    }
    return vec4<f32>(prior + color.rgb * sum, 1.0);
}

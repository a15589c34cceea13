// Direct lighting over the G-buffer: one directional light with normalized Blinn-Phong
// specular from the stored glossiness, plus a sky/ground hemisphere ambient term.
// Image-based lighting replaces this pass later; it keeps graphs looking right until then.

struct Light {
    inv_view_proj: mat4x4<f32>,
    eye: vec4<f32>,
    // xyz: direction the light travels, normalized.
    sun_dir: vec4<f32>,
    // rgb: colour x intensity.
    sun: vec4<f32>,
    sky: vec4<f32>,
    ground: vec4<f32>,
    background: vec4<f32>,
    // x: camera forward-axis scale for reconstructing positions from linear depth (unused), y: width, z: height.
    size: vec4<f32>,
};

@group(0) @binding(0) var<uniform> light: Light;
@group(0) @binding(1) var g_color: texture_2d<f32>;
@group(0) @binding(2) var g_normal: texture_2d<f32>;
@group(0) @binding(3) var g_depth: texture_2d<f32>;

// #include "fullscreen.wgsl"

const PI: f32 = 3.14159265;

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let px = vec2<i32>(frag.xy);
    let depth = textureLoad(g_depth, px, 0).r;
    if depth <= 0.0 {
        return vec4<f32>(light.background.rgb, 1.0);
    }
    let color = textureLoad(g_color, px, 0);
    let n = normalize(textureLoad(g_normal, px, 0).xyz);

    // The view ray through this pixel; its point at linear depth `depth`.
    let ndc = vec2<f32>(frag.x / light.size.y * 2.0 - 1.0, 1.0 - frag.y / light.size.z * 2.0);
    let far_h = light.inv_view_proj * vec4<f32>(ndc, 1.0, 1.0);
    let near_h = light.inv_view_proj * vec4<f32>(ndc, 0.0, 1.0);
    let ray = normalize(far_h.xyz / far_h.w - near_h.xyz / near_h.w);
    let v = -ray;

    let albedo = color.rgb;
    let gloss = clamp(color.a, 0.0, 1.0);
    let l = -light.sun_dir.xyz;
    let ndl = max(dot(n, l), 0.0);
    let h = normalize(l + v);
    let exponent = exp2(1.0 + 11.0 * gloss);
    let fresnel = 0.04 + 0.96 * pow(1.0 - max(dot(h, v), 0.0), 5.0);
    let specular = (exponent + 8.0) / (8.0 * PI) * pow(max(dot(n, h), 0.0), exponent) * fresnel * gloss;
    let direct = (albedo / PI + vec3<f32>(specular)) * light.sun.rgb * ndl;
    let hemi = mix(light.ground.rgb, light.sky.rgb, 0.5 + 0.5 * n.y);
    let ambient = albedo * hemi;
    return vec4<f32>(direct + ambient, 1.0);
}

// What every G-buffer writer shares: the per-frame camera, the per-object material, and
// the write of colour + glossiness, normal + detail flag, linear depth, and the surface
// (UV, tangent frame, BTF id; surface.wgsl).

struct Frame {
    view_proj: mat4x4<f32>,
    view: mat4x4<f32>,
};

@group(0) @binding(0) var<uniform> frame: Frame;

// What the draw's material needs (src/render/scene.rs `MaterialFeatures`): a base or a gloss
// map; a tangent frame in the surface target (a BTF shades it). Lavapipe runs both sides of a
// branch, so what is not needed is compiled out rather than skipped.
override MAPS: bool = true;
override TANGENTS: bool = true;

// #include "object.wgsl"

// #include "vertex_in.wgsl"

// #include "surface.wgsl"

struct GBufferOut {
    @location(0) color: vec4<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) depth: f32,
    @location(3) surface: vec4<u32>,
};

// `world`: the fragment's world position (for the tangent frame's derivatives). Call in uniform
// control flow.
fn write_gbuffer(world: vec3<f32>, world_normal: vec3<f32>, uv: vec2<f32>, view_depth: f32, front: bool) -> GBufferOut {
    var albedo = object.base_color.rgb;
    if MAPS && object.has_texture > 0.5 {
        albedo = albedo * textureSample(base_map, base_sampler, uv * object.uv_scale).rgb;
    }
    // Cloth is two-sided: light the back face with the flipped normal.
    var n = normalize(world_normal);
    if !front {
        n = -n;
    }
    var gloss = object.base_color.a;
    if MAPS && object.has_gloss_map > 0.5 {
        gloss = mix(object.gloss_min, gloss, textureSample(gloss_map, base_sampler, uv * object.uv_scale).r);
    }
    var out: GBufferOut;
    out.color = vec4<f32>(albedo, gloss);
    out.normal = vec4<f32>(n, object.detail);
    out.depth = view_depth;
    // Without a BTF the tangent frame is not read: the UV only, no tangent, id 0.
    out.surface = vec4<u32>(bitcast<u32>(uv.x), bitcast<u32>(uv.y), 0u, 0u);
    if TANGENTS {
        out.surface = encode_surface(world, n, uv, object.btf_id);
    }
    return out;
}

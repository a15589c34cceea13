// What every G-buffer writer shares: the per-frame camera, the per-object material, and
// the write of colour + glossiness, normal + detail flag, linear depth.

struct Frame {
    view_proj: mat4x4<f32>,
    view: mat4x4<f32>,
};

struct Object {
    model: mat4x4<f32>,
    // Inverse transpose of the model matrix, for normals and tangents.
    normal_matrix: mat4x4<f32>,
    // rgb: linear base colour, a: glossiness.
    base_color: vec4<f32>,
    // x: uv scale, y: 1 if a texture is bound, z: detail flag, w: 1 if a gloss map is bound.
    params: vec4<f32>,
    // x: glossiness where the gloss map is 0.
    extra: vec4<f32>,
};

@group(0) @binding(0) var<uniform> frame: Frame;
@group(1) @binding(0) var<uniform> object: Object;
@group(1) @binding(1) var base_map: texture_2d<f32>;
@group(1) @binding(2) var base_sampler: sampler;
// Glossiness parameter map (dissertation Fig. 5.23), red channel.
@group(1) @binding(3) var gloss_map: texture_2d<f32>;

// #include "vertex_in.wgsl"

struct GBufferOut {
    @location(0) color: vec4<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) depth: f32,
};

fn write_gbuffer(world_normal: vec3<f32>, uv: vec2<f32>, view_depth: f32, front: bool) -> GBufferOut {
    var albedo = object.base_color.rgb;
    if object.params.y > 0.5 {
        albedo = albedo * textureSample(base_map, base_sampler, uv * object.params.x).rgb;
    }
    // Cloth is two-sided: light the back face with the flipped normal.
    var n = normalize(world_normal);
    if !front {
        n = -n;
    }
    var gloss = object.base_color.a;
    if object.params.w > 0.5 {
        gloss = mix(object.extra.x, gloss, textureSample(gloss_map, base_sampler, uv * object.params.x).r);
    }
    var out: GBufferOut;
    out.color = vec4<f32>(albedo, gloss);
    out.normal = vec4<f32>(n, object.params.z);
    out.depth = view_depth;
    return out;
}

// G-buffer pass (dissertation section 4.2): rasterizes meshes into multiple render targets:
// linear base colour + glossiness, world normal + coarse/detail flag, linear view depth.

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
    // x: uv scale, y: 1 if a texture is bound, z: detail flag, w: unused.
    params: vec4<f32>,
};

@group(0) @binding(0) var<uniform> frame: Frame;
@group(1) @binding(0) var<uniform> object: Object;
@group(1) @binding(1) var base_map: texture_2d<f32>;
@group(1) @binding(2) var base_sampler: sampler;

struct VertexIn {
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent_u: vec3<f32>,
    @location(3) uv: vec2<f32>,
};

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) normal: vec3<f32>,
    @location(1) uv: vec2<f32>,
    @location(2) view_depth: f32,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    let world = object.model * vec4<f32>(v.position, 1.0);
    var out: VertexOut;
    out.clip = frame.view_proj * world;
    out.normal = (object.normal_matrix * vec4<f32>(v.normal, 0.0)).xyz;
    out.uv = v.uv;
    out.view_depth = -(frame.view * world).z;
    return out;
}

struct GBufferOut {
    @location(0) color: vec4<f32>,
    @location(1) normal: vec4<f32>,
    @location(2) depth: f32,
};

@fragment
fn fs_main(in: VertexOut, @builtin(front_facing) front: bool) -> GBufferOut {
    var albedo = object.base_color.rgb;
    if object.params.y > 0.5 {
        albedo = albedo * textureSample(base_map, base_sampler, in.uv * object.params.x).rgb;
    }
    // Cloth is two-sided: light the back face with the flipped normal.
    var n = normalize(in.normal);
    if !front {
        n = -n;
    }
    var out: GBufferOut;
    out.color = vec4<f32>(albedo, object.base_color.a);
    out.normal = vec4<f32>(n, object.params.z);
    out.depth = in.view_depth;
    return out;
}

// Deferred warping, pass 1 (paper eq. 3; Algorithm 4.1.2.1 lines 1-7): rasterize the surface
// in UV space and write, per texel, the 3x4 matrix [t_u n t_v p]: the orthonormalized
// tangent frame and the world position. Texels no piece covers keep the cleared zero matrix.

// #include "vertex_in.wgsl"

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) position: vec3<f32>,
    @location(1) normal: vec3<f32>,
    @location(2) tangent_u: vec3<f32>,
    @location(3) tangent_v: vec3<f32>,
};

@vertex
fn vs_main(v: VertexIn) -> VertexOut {
    var out: VertexOut;
    // UV (0,0) is the texture's top-left texel.
    out.clip = vec4<f32>(v.uv.x * 2.0 - 1.0, 1.0 - v.uv.y * 2.0, 0.0, 1.0);
    out.position = v.position;
    out.normal = v.normal;
    out.tangent_u = v.tangent_u;
    out.tangent_v = v.tangent_v;
    return out;
}

struct MatrixOut {
    // Columns of eq. (3), each with one position component in w.
    @location(0) col_u: vec4<f32>,
    @location(1) col_n: vec4<f32>,
    @location(2) col_v: vec4<f32>,
};

@fragment
fn fs_main(in: VertexOut) -> MatrixOut {
    return matrix(in);
}

// Where 32-bit float targets cannot be rendered (llvmpipe's OpenGL), the same values are
// written as their bits into Rgba32Uint targets, which the node copies into the float texture.
struct MatrixBits {
    @location(0) col_u: vec4<u32>,
    @location(1) col_n: vec4<u32>,
    @location(2) col_v: vec4<u32>,
};

@fragment
fn fs_bits(in: VertexOut) -> MatrixBits {
    let m = matrix(in);
    return MatrixBits(bitcast<vec4<u32>>(m.col_u), bitcast<vec4<u32>>(m.col_n), bitcast<vec4<u32>>(m.col_v));
}

fn matrix(in: VertexOut) -> MatrixOut {
    // Gram-Schmidt keeps n and the directions of dP/du and dP/dv; the frame is orthonormal
    // so attached geometry is never sheared (paper section 3.2).
    let n = normalize(in.normal);
    let tu = normalize(in.tangent_u - n * dot(n, in.tangent_u));
    let tv = normalize(in.tangent_v - n * dot(n, in.tangent_v) - tu * dot(tu, in.tangent_v));
    var out: MatrixOut;
    out.col_u = vec4<f32>(tu, in.position.x);
    out.col_n = vec4<f32>(n, in.position.y);
    out.col_v = vec4<f32>(tv, in.position.z);
    return out;
}

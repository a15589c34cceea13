// Deferred warping, pass 1 (paper eq. 3; Algorithm 4.1.2.1 lines 1-7): rasterize the surface
// in UV space and write, per texel, the 3x4 matrix [t_u n t_v p]: the orthonormalized
// tangent frame and the world position. Texels no piece covers keep the cleared zero matrix.

// #include "vertex_in.wgsl"
// #include "matrix_out.wgsl"

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

@fragment
fn fs_main(in: VertexOut) -> MatrixOut {
    return matrix(in);
}

@fragment
fn fs_bits(in: VertexOut) -> MatrixBits {
    return matrix_bits(matrix(in));
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

// The matrix texture's render targets (src/warp/mod.rs `MatrixTexture`), shared by the pass that
// rasterizes it and the filter: the three columns of eq. (3), each with one position
// component in w; or, where 32-bit float targets cannot be rendered (llvmpipe's OpenGL), the
// same values as their bits into Rgba32Uint targets, which the node copies into the float
// texture.

struct MatrixOut {
    @location(0) col_u: vec4<f32>,
    @location(1) col_n: vec4<f32>,
    @location(2) col_v: vec4<f32>,
};

struct MatrixBits {
    @location(0) col_u: vec4<u32>,
    @location(1) col_n: vec4<u32>,
    @location(2) col_v: vec4<u32>,
};

fn matrix_bits(m: MatrixOut) -> MatrixBits {
    return MatrixBits(bitcast<vec4<u32>>(m.col_u), bitcast<vec4<u32>>(m.col_n), bitcast<vec4<u32>>(m.col_v));
}

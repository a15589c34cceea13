// The pattern piece of each matrix texture texel (piece id + 1; 0 where no piece covers it),
// rendered in UV space like matrix_texture.wgsl, so the orientation filter
// (matrix_filter.wgsl) never mixes two pieces.

struct VertexOut {
    @builtin(position) clip: vec4<f32>,
    @location(0) @interpolate(flat) piece: f32,
};

@vertex
fn vs_main(@location(0) uv_piece: vec3<f32>) -> VertexOut {
    var out: VertexOut;
    out.clip = vec4<f32>(uv_piece.x * 2.0 - 1.0, 1.0 - uv_piece.y * 2.0, 0.0, 1.0);
    out.piece = uv_piece.z;
    return out;
}

@fragment
fn fs_main(in: VertexOut) -> @location(0) vec4<f32> {
    return vec4<f32>(in.piece, 0.0, 0.0, 1.0);
}

// Low-pass filter of the matrix texture's orientation field (paper section 6, "Flexibility"):
// a separable box filter over the covered texels of the same pattern piece within the radius
// (piece_map.wgsl; neighbouring pieces across the atlas gutter are never mixed), positions
// left as they are, frames re-orthonormalized. It smooths sudden orientation changes that make
// tall attached geometry intersect itself.

// #include "fullscreen.wgsl"
// #include "matrix_out.wgsl"

struct Params {
    // xy: step direction in texels, z: radius in texels.
    dir_radius: vec4<f32>,
};

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var col_u: texture_2d<f32>;
@group(0) @binding(2) var col_n: texture_2d<f32>;
@group(0) @binding(3) var col_v: texture_2d<f32>;
// Piece id + 1 per texel (piece_map.wgsl); a 1x1 placeholder for a surface of one piece.
@group(0) @binding(4) var pieces: texture_2d<f32>;

fn piece_of(q: vec2<i32>) -> f32 {
    if textureDimensions(pieces).x == 1u {
        return 1.0;
    }
    return textureLoad(pieces, q, 0).x;
}

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> MatrixOut {
    return filtered(frag);
}

@fragment
fn fs_bits(@builtin(position) frag: vec4<f32>) -> MatrixBits {
    return matrix_bits(filtered(frag));
}

fn filtered(frag: vec4<f32>) -> MatrixOut {
    let px = vec2<i32>(frag.xy);
    let dims = vec2<i32>(textureDimensions(col_n));
    let centre_n = textureLoad(col_n, px, 0);
    var out: MatrixOut;
    out.col_u = textureLoad(col_u, px, 0);
    out.col_n = centre_n;
    out.col_v = textureLoad(col_v, px, 0);
    if dot(centre_n.xyz, centre_n.xyz) < 0.25 {
        return out; // empty texel stays zero
    }
    let radius = i32(params.dir_radius.z);
    let dir = vec2<i32>(params.dir_radius.xy);
    var su = vec3<f32>(0.0);
    var sn = vec3<f32>(0.0);
    var sv = vec3<f32>(0.0);
    let piece = piece_of(px);
    for (var k = -radius; k <= radius; k = k + 1) {
        let q = clamp(px + dir * k, vec2<i32>(0), dims - 1);
        let n = textureLoad(col_n, q, 0).xyz;
        if dot(n, n) < 0.25 || piece_of(q) != piece {
            continue;
        }
        su = su + textureLoad(col_u, q, 0).xyz;
        sn = sn + n;
        sv = sv + textureLoad(col_v, q, 0).xyz;
    }
    let n = normalize(sn);
    let tu = normalize(su - n * dot(n, su));
    let tv = normalize(sv - n * dot(n, sv) - tu * dot(tu, sv));
    out.col_u = vec4<f32>(tu, out.col_u.w);
    out.col_n = vec4<f32>(n, centre_n.w);
    out.col_v = vec4<f32>(tv, out.col_v.w);
    return out;
}

// The separable Gaussian of the shadow atlas (nodes/ibl/shadow_atlas.rs): per tile its own sigma
// (an area light of the region's solid angle), taps clamped to the tile, guard band included,
// so no tile reads another. Weights are normalised by their sum: a constant tile stays exact.

// #include "fullscreen.wgsl"

struct Blur {
    // x: tile size (texels), y: columns of tiles, z: tiles in this texture, w: 0 horizontal, 1 vertical.
    grid: vec4<f32>,
    // Sigma (texels) per tile, 4 per entry.
    sigma: array<vec4<f32>, 16>,
};

@group(0) @binding(0) var<uniform> blur: Blur;
@group(0) @binding(1) var moments: texture_2d<f32>;

@fragment
fn fs_blur(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let px = vec2<i32>(frag.xy);
    let t = i32(blur.grid.x);
    let tile = px / t;
    let j = tile.y * i32(blur.grid.y) + tile.x;
    if j >= i32(blur.grid.z) {
        // No tile: far (centred depth 1/2, shaders/ibl/vsm.wgsl).
        return vec4<f32>(0.5, 0.25, 0.0, 0.0);
    }
    let sigma = blur.sigma[j / 4][j % 4];
    let r = min(i32(ceil(3.0 * sigma)), t);
    if r <= 0 || sigma <= 0.0 {
        return textureLoad(moments, px, 0);
    }
    let lo = tile * t;
    let hi = lo + vec2<i32>(t - 1);
    let dir = select(vec2<i32>(1, 0), vec2<i32>(0, 1), blur.grid.w > 0.5);
    var sum = vec2<f32>(0.0);
    var wsum = 0.0;
    for (var k = -r; k <= r; k++) {
        let q = clamp(px + dir * k, lo, hi);
        let w = exp(-f32(k * k) / (2.0 * sigma * sigma));
        sum += w * textureLoad(moments, q, 0).xy;
        wsum += w;
    }
    return vec4<f32>(sum / wsum, 0.0, 0.0);
}

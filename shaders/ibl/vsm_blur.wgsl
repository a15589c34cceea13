// The separable Gaussian of the shadow atlas (nodes/ibl/shadow_atlas.rs): per tile its own sigma
// (an area light of the region's solid angle), taps clamped to the tile, guard band included,
// so no tile reads another. Weights are normalised by their sum: a constant tile stays exact.
// Tiles may differ in size (shadow_fit.rs pack_tiles), so each texel finds its tile's rectangle.

// #include "fullscreen.wgsl"

struct Blur {
    // Each tile's texels: x0, y0, x1, y1 (exclusive).
    rect: array<vec4<f32>, 64>,
    // Sigma (texels) per tile, 4 per entry.
    sigma: array<vec4<f32>, 16>,
    // x: tiles in this texture, y: 0 horizontal, 1 vertical.
    info: vec4<f32>,
};

@group(0) @binding(0) var<uniform> blur: Blur;
@group(0) @binding(1) var moments: texture_2d<f32>;

@fragment
fn fs_blur(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let px = vec2<i32>(frag.xy);
    let p = vec2<f32>(px) + 0.5;
    var j = -1;
    for (var k = 0; k < i32(blur.info.x); k++) {
        let r = blur.rect[k];
        if p.x > r.x && p.y > r.y && p.x < r.z && p.y < r.w {
            j = k;
            break;
        }
    }
    if j < 0 {
        // No tile: far (centred depth 1/2, shaders/ibl/vsm.wgsl).
        return vec4<f32>(0.5, 0.25, 0.0, 0.0);
    }
    let sigma = blur.sigma[j / 4][j % 4];
    let lo = vec2<i32>(blur.rect[j].xy);
    let hi = vec2<i32>(blur.rect[j].zw) - 1;
    let r = min(i32(ceil(3.0 * sigma)), hi.x - lo.x + 1);
    if r <= 0 || sigma <= 0.0 {
        return textureLoad(moments, px, 0);
    }
    let dir = select(vec2<i32>(1, 0), vec2<i32>(0, 1), blur.info.y > 0.5);
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

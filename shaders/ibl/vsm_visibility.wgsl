// VIS of a light at a receiver from its shadow-atlas tile (nodes/ibl/shadow_atlas.rs), shared by
// IblShading and BtfShading: Chebyshev's upper bound on the tile's blurred moments
// m = (mu, E[c^2]) of the centred depth c = d - 1/2 (shaders/ibl/vsm.wgsl), at the receiver's
// light depth d (bias already subtracted); 1 for c <= mu, else
// linstep(bleed_reduction, 1, var / (var + (c - mu)^2)), var = max(E[c^2] - mu^2, min_variance).
fn chebyshev_visibility(m: vec2<f32>, d: f32, min_variance: f32, bleed_reduction: f32) -> f32 {
    let t = d - 0.5;
    if t <= m.x {
        return 1.0;
    }
    let variance = max(m.y - m.x * m.x, min_variance);
    let e = t - m.x;
    let p_max = variance / (variance + e * e);
    let b = bleed_reduction;
    return clamp((p_max - b) / (1.0 - b), 0.0, 1.0);
}

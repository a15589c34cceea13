// BtfShading (nodes/btf/btf_shading.rs; docs/btf.md, "Rendering"): deferred BTF shading of
// Sattler et al. 2003. Per pixel of the G-buffer whose material carries this node's id: the
// view and every light in the cloth's tangent frame (surface.wgsl), the 4 nearest view slots
// (eq. 5) and per light the 4 nearest light directions (eq. 3), both weighted as
// `Sampling::weights` (src/btf/directions.rs) does, line for line below. Per view slot the
// coefficients are blended over lights first (gamma_k, RGB with the lights' colours: eqs. 3, 10),
// then the slot's mean and eigentextures are summed once (eq. 4); exposure f (eq. 11).
// Environment light by the paper's per-vertex weight sets (HEM, eq. 12) where HEM is set: the
// pixel's triangle and barycentrics (btf_hem_ids.wgsl) interpolate the corners' gamma*_kj.

// #include "fullscreen.wgsl"
// #include "surface.wgsl"
// #include "shadowed_light.wgsl"

// Mean + at most 32 eigentextures per slot (src/btf/gpu.rs MAX_COMPONENTS).
const MAX_LAYERS: u32 = 33u;
const MAX_RINGS: u32 = 16u;
// Lights whose shadow visibility is kept per pixel (fs_main).
const CACHED: u32 = 32u;
const DEG: f32 = 57.29577951308232;
const PI: f32 = 3.14159265358979;

// Fixed for many frames, so pipeline constants rather than uniforms (tests/suite/shader_lint.rs).
// Directions of the sampling (views = lights), layers per view slot (c + 1), rings.
override DIRECTIONS: u32 = 1u;
override PER_SLOT: u32 = 1u;
override RINGS: u32 = 1u;
// The directional lights in `lights`.
override LIGHTS: u32 = 0u;
// Whether `base_image` is bound (else the background colour).
override BASE: bool = false;
// Whether the per-vertex weight sets (hem_ids, hem_corners, hem_sets) are bound.
override HEM: bool = false;
// Whether a shadow atlas of the `lights` input's lights is bound (shadow_atlas).
override SHADOWS: bool = false;

struct Params {
    inv_view_proj: mat4x4<f32>,
    eye: vec4<f32>,
    // width, height, environment intensity (HEM), material id
    size: vec4<f32>,
    // with SHADOWS the atlas's min variance, bleed reduction and depth bias; exposure in w
    btf: vec4<f32>,
    // tiles per UV unit, cos(rotation), sin(rotation), alpha of eq. 6 (radians)
    tiling: vec4<f32>,
    // rgb: where nothing is shaded and no base image is bound
    background: vec4<f32>,
    // theta (degrees), count, first direction, 0
    rings: array<vec4<f32>, MAX_RINGS>,
};

// The lights (shadowed_light.wgsl): dir.w 1 where eq. 6's boundary applies, 2 where the
// triangles' facing cuts it (a shadow volume's hard boundary, Fig. 8 left), 0 none.

@group(0) @binding(0) var<uniform> params: Params;
@group(0) @binding(1) var g_normal: texture_2d<f32>;
@group(0) @binding(2) var g_depth: texture_2d<f32>;
@group(0) @binding(3) var g_surface: texture_2d<u32>;
@group(0) @binding(4) var base_image: texture_2d<f32>;
@group(0) @binding(5) var btf_images: texture_2d_array<f32>;
@group(0) @binding(6) var btf_sampler: sampler;
@group(0) @binding(7) var shadow_ramp: texture_2d<f32>;
@group(0) @binding(8) var ramp_sampler: sampler;
@group(0) @binding(9) var<storage, read> coeffs: array<f32>;
@group(0) @binding(10) var<storage, read> lights: array<Light>;
// HEM: per pixel the triangle (+1; 0: none) and the bits of its 2nd and 3rd barycentrics; per
// triangle corner its vertex; per vertex its weight set U (view slot, component, channel).
@group(0) @binding(11) var hem_ids: texture_2d<u32>;
@group(0) @binding(12) var<storage, read> hem_corners: array<u32>;
@group(0) @binding(13) var<storage, read> hem_sets: array<f32>;
// The moments of the lights' shadow maps (ShadowAtlas), read bilinearly through ramp_sampler.
@group(0) @binding(14) var shadow_atlas: texture_2d<f32>;
// Per layer of btf_images its offset and scale (rgb): value = offset + scale * texel (src/btf/gpu.rs;
// identity for f16 layers, the layer's range for 8-bit ones).
@group(0) @binding(15) var<storage, read> layer_affine: array<vec4<f32>>;

struct RingWeights {
    index: vec2<u32>,
    weight: vec2<f32>,
};

struct Weights {
    index: vec4<u32>,
    weight: vec4<f32>,
};

// `on_ring` of Sampling::weights: phi between two neighbouring directions of ring i.
fn on_ring(i: u32, phi: f32) -> RingWeights {
    let n = u32(params.rings[i].y);
    let start = u32(params.rings[i].z);
    var out: RingWeights;
    if n == 1u {
        out.index = vec2<u32>(start, start);
        out.weight = vec2<f32>(1.0, 0.0);
        return out;
    }
    let x = (phi - 360.0 * floor(phi / 360.0)) * f32(n) / 360.0;
    let k0 = min(u32(floor(x)), n - 1u);
    let s = clamp(x - f32(k0), 0.0, 1.0);
    out.index = vec2<u32>(start + k0, start + (k0 + 1u) % n);
    out.weight = vec2<f32>(1.0 - s, s);
    return out;
}

// Sampling::weights: theta (clamped to the rings) bracketed between rings a and b, linear t;
// on each ring linear in phi; weights (1-t)(1-s_a), (1-t)s_a, t(1-s_b), t s_b.
fn direction_weights(theta_in: f32, phi: f32) -> Weights {
    let last = RINGS - 1u;
    let theta = clamp(theta_in, params.rings[0].x, params.rings[last].x);
    var b = last;
    for (var r = 0u; r <= last; r++) {
        if params.rings[r].x >= theta {
            b = r;
            break;
        }
    }
    b = min(max(b, 1u), last);
    let a = select(b - 1u, 0u, b == 0u);
    var t = 0.0;
    if a != b {
        t = clamp((theta - params.rings[a].x) / (params.rings[b].x - params.rings[a].x), 0.0, 1.0);
    }
    let ra = on_ring(a, phi);
    let rb = on_ring(b, phi);
    var w: Weights;
    w.index = vec4<u32>(ra.index, rb.index);
    w.weight = vec4<f32>((1.0 - t) * ra.weight, t * rb.weight);
    return w;
}

// Dir::from_vec: (theta, phi) in degrees of a tangent-frame vector, phi in [0, 360).
fn to_direction(v: vec3<f32>) -> vec2<f32> {
    let u = normalize(v);
    let theta = acos(clamp(u.z, -1.0, 1.0)) * DEG;
    let phi = atan2(u.y, u.x) * DEG;
    return vec2<f32>(theta, phi - 360.0 * floor(phi / 360.0));
}

// Past the outermost ring a light keeps that ring's images (the weights clamp theta), scaled
// by cos(theta_i) / cos(theta_last): the data contain cos(theta_i), which this carries on to 0
// at the horizon instead of a jump there. Below the horizon: 0.
fn grazing(cos_l: f32) -> f32 {
    let c_last = cos(params.rings[RINGS - 1u].x / DEG);
    if cos_l <= 0.0 {
        return 0.0;
    }
    if cos_l >= c_last || c_last < 1e-4 {
        return 1.0;
    }
    return cos_l / c_last;
}

// Eq. 6: u = (1 + cos(alpha + angle(n, l))) / 2 into the half-black, half-white (blurred)
// 1D texture; per pixel from the interpolated normal (the paper interpolates u per vertex:
// both assume the smooth surface the normals describe). alpha + angle stops at pi, so a large
// alpha never lights the far side.
fn smooth_shadow(cos_l: f32) -> f32 {
    let angle = acos(clamp(cos_l, -1.0, 1.0));
    let u = (1.0 + cos(min(params.tiling.w + angle, PI))) / 2.0;
    return textureSampleLevel(shadow_ramp, ramp_sampler, vec2<f32>(u, 0.5), 0.0).r;
}

// The world position of pixel q from its view depth (0: nothing there).
fn world_at(q: vec2<i32>) -> vec3<f32> {
    let ndc = vec2<f32>((f32(q.x) + 0.5) / params.size.x * 2.0 - 1.0, 1.0 - (f32(q.y) + 0.5) / params.size.y * 2.0);
    let far_h = params.inv_view_proj * vec4<f32>(ndc, 1.0, 1.0);
    let near_h = params.inv_view_proj * vec4<f32>(ndc, 0.0, 1.0);
    let near = near_h.xyz / near_h.w;
    let dir = normalize(far_h.xyz / far_h.w - near);
    // The view axis: the ray through the centre of the screen.
    let c_far = params.inv_view_proj * vec4<f32>(0.0, 0.0, 1.0, 1.0);
    let c_near = params.inv_view_proj * vec4<f32>(0.0, 0.0, 0.0, 1.0);
    let axis = normalize(c_far.xyz / c_far.w - c_near.xyz / c_near.w);
    let depth = textureLoad(g_depth, q, 0).r;
    return near + dir * ((depth - dot(near - params.eye.xyz, axis)) / dot(dir, axis));
}

// Whether pixel q shows this node's material (inside the image).
fn shaded_here(q: vec2<i32>) -> bool {
    if any(q < vec2<i32>(0)) || q.x >= i32(params.size.x) || q.y >= i32(params.size.y) {
        return false;
    }
    let id = textureLoad(g_surface, q, 0).w & SURFACE_ID_MASK;
    return textureLoad(g_depth, q, 0).r > 0.0 && id == u32(params.size.w);
}

// The weave's texture coordinates at a surface texel: the UV tiled and turned by the rotation
// from the tangent (u) towards the BTF's y (up its images, decreasing v).
fn weave_coords(uv: vec2<f32>) -> vec2<f32> {
    let c = params.tiling.y;
    let sn = params.tiling.z;
    let p = vec2<f32>(uv.x, -uv.y) * params.tiling.x;
    let w = vec2<f32>(c * p.x + sn * p.y, -sn * p.x + c * p.y);
    return vec2<f32>(w.x, -w.y);
}

// The step of the weave's coordinates (in texels) from pixel px to its neighbour px + d or
// px - d, whichever is shorter among those on this material (a UV seam on one side does not
// count); a very long step where neither is.
fn texel_step(px: vec2<i32>, d: vec2<i32>, tex: vec2<f32>, size: vec2<f32>) -> f32 {
    var best = 1e30;
    for (var side = -1; side <= 1; side += 2) {
        let q = px + d * side;
        if shaded_here(q) {
            let bits = textureLoad(g_surface, q, 0);
            let t = weave_coords(vec2<f32>(bitcast<f32>(bits.x), bitcast<f32>(bits.y)));
            best = min(best, length((t - tex) * size));
        }
    }
    return best;
}

// The mip level of the eigentextures at pixel px, as trilinear filtering picks it (log2 of the
// longer texel step per pixel), from the G-buffer's UVs at the neighbours: a deferred pass has
// no derivatives of the weave's coordinates, and the branch on the material is not uniform.
// 0 (the finest) where the pixel has no neighbour on this material.
fn mip_level(px: vec2<i32>, tex: vec2<f32>) -> f32 {
    let size = vec2<f32>(textureDimensions(btf_images).xy);
    let rho = max(texel_step(px, vec2<i32>(1, 0), tex, size), texel_step(px, vec2<i32>(0, 1), tex, size));
    if rho > 1e29 {
        return 0.0;
    }
    return max(log2(max(rho, 1e-8)), 0.0);
}

// The geometric normal at pixel px (towards the side of `n`): the plane through its world
// position and those of a horizontal and a vertical neighbour on the same material (right or
// left, below or above). Within a triangle that is the triangle's plane; a pixel beside an edge
// may take a chord across it. 0 where the pixel has no such neighbours.
fn face_normal(px: vec2<i32>, n: vec3<f32>) -> vec3<f32> {
    let p = world_at(px);
    var sx = 1;
    if !shaded_here(px + vec2<i32>(1, 0)) {
        sx = -1;
    }
    var sy = 1;
    if !shaded_here(px + vec2<i32>(0, 1)) {
        sy = -1;
    }
    let qx = px + vec2<i32>(sx, 0);
    let qy = px + vec2<i32>(0, sy);
    if !shaded_here(qx) || !shaded_here(qy) {
        return vec3<f32>(0.0);
    }
    let f = cross(world_at(qx) - p, world_at(qy) - p);
    if dot(f, f) < 1e-30 {
        return vec3<f32>(0.0);
    }
    return normalize(f) * select(1.0, -1.0, dot(f, n) < 0.0);
}

@fragment
fn fs_main(@builtin(position) frag: vec4<f32>) -> @location(0) vec4<f32> {
    let px = vec2<i32>(frag.xy);
    var base = vec4<f32>(params.background.rgb, 1.0);
    if BASE {
        base = textureLoad(base_image, px, 0);
    }
    let depth = textureLoad(g_depth, px, 0).r;
    let bits = textureLoad(g_surface, px, 0);
    if depth <= 0.0 || (bits.w & SURFACE_ID_MASK) != u32(params.size.w) {
        return base;
    }
    let n = normalize(textureLoad(g_normal, px, 0).xyz);
    let ndc = vec2<f32>(frag.x / params.size.x * 2.0 - 1.0, 1.0 - frag.y / params.size.y * 2.0);
    let far_h = params.inv_view_proj * vec4<f32>(ndc, 1.0, 1.0);
    let near_h = params.inv_view_proj * vec4<f32>(ndc, 0.0, 1.0);
    let v = -normalize(far_h.xyz / far_h.w - near_h.xyz / near_h.w);

    // The weave's frame and coordinates: tiled, and turned by the rotation from the tangent
    // (u) towards the BTF's y (up its images, decreasing v).
    let s = decode_surface(bits, n);
    let c = params.tiling.y;
    let sn = params.tiling.z;
    let tex = weave_coords(s.uv);
    let lod = mip_level(px, tex);
    let fx = c * s.x + sn * s.y;
    let fy = -sn * s.x + c * s.y;

    let vd = to_direction(vec3<f32>(dot(v, fx), dot(v, fy), dot(v, n)));
    let wv = direction_weights(vd.x, vd.y);
    var radiance = vec3<f32>(0.0);
    // The shadow volume's test (Fig. 8 left) for lights whose boundary is the triangles' facing.
    var face = vec3<f32>(0.0);
    for (var li = 0u; li < LIGHTS; li++) {
        if lights[li].dir.w > 1.5 {
            face = face_normal(px, n);
            break;
        }
    }
    // The shadowed lights' visibility, looked up once per pixel rather than per view slot (the
    // first CACHED lights; any beyond look theirs up in the slot loop).
    var p = vec3<f32>(0.0);
    var vis: array<f32, CACHED>;
    if SHADOWS {
        p = world_at(px);
        for (var li = 0u; li < min(LIGHTS, CACHED); li++) {
            vis[li] = light_visibility(lights[li], shadow_atlas, ramp_sampler, p, n, params.btf.xyz);
        }
    }
    // HEM: the pixel's triangle corners and barycentric weights.
    var hem_vertex = vec3<u32>(0u);
    var hem_weight = vec3<f32>(0.0);
    if HEM {
        let id = textureLoad(hem_ids, px, 0);
        if id.x > 0u {
            let b = vec2<f32>(bitcast<f32>(id.y), bitcast<f32>(id.z));
            let corner = 3u * (id.x - 1u);
            hem_vertex = vec3<u32>(hem_corners[corner], hem_corners[corner + 1u], hem_corners[corner + 2u]);
            hem_weight = vec3<f32>(1.0 - b.x - b.y, b.x, b.y) * params.size.z;
        }
    }
    for (var m = 0u; m < 4u; m++) {
        let wm = wv.weight[m];
        if wm <= 0.0 {
            continue;
        }
        let j = wv.index[m];
        var gamma: array<vec3<f32>, MAX_LAYERS>;
        if HEM {
            // Eq. 12's gamma*_kj of the corners, interpolated (all zero where no triangle).
            for (var c = 0u; c < 3u; c++) {
                let at = 3u * PER_SLOT * (hem_vertex[c] * DIRECTIONS + j);
                for (var k = 0u; k < PER_SLOT; k++) {
                    let o = at + 3u * k;
                    gamma[k] += hem_weight[c] * vec3<f32>(hem_sets[o], hem_sets[o + 1u], hem_sets[o + 2u]);
                }
            }
        }
        for (var li = 0u; li < LIGHTS; li++) {
            let light = lights[li];
            let l = light.dir.xyz;
            let cos_l = dot(n, l);
            var scale = light.color.rgb * grazing(cos_l);
            if light.dir.w > 1.5 {
                scale = scale * select(0.0, 1.0, dot(face, l) > 0.0);
            } else if light.dir.w > 0.5 {
                scale = scale * smooth_shadow(cos_l);
            }
            if all(scale <= vec3<f32>(0.0)) {
                continue;
            }
            if SHADOWS {
                if li < CACHED {
                    scale = scale * vis[li];
                } else {
                    scale = scale * light_visibility(light, shadow_atlas, ramp_sampler, p, n, params.btf.xyz);
                }
            }
            let ld = to_direction(vec3<f32>(dot(l, fx), dot(l, fy), cos_l));
            let wl = direction_weights(ld.x, ld.y);
            for (var q = 0u; q < 4u; q++) {
                let wq = wl.weight[q];
                if wq <= 0.0 {
                    continue;
                }
                let row = (j * DIRECTIONS + wl.index[q]) * PER_SLOT;
                for (var k = 0u; k < PER_SLOT; k++) {
                    gamma[k] += scale * (wq * coeffs[row + k]);
                }
            }
        }
        for (var k = 0u; k < PER_SLOT; k++) {
            let layer = j * PER_SLOT + k;
            let texel = textureSampleLevel(btf_images, btf_sampler, tex, i32(layer), lod).rgb;
            radiance += wm * gamma[k] * (layer_affine[2u * layer].rgb + layer_affine[2u * layer + 1u].rgb * texel);
        }
    }
    return vec4<f32>(radiance * params.btf.w, 1.0);
}

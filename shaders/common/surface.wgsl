// The G-buffer's surface target (Rgba32Uint; src/render/scene.rs `GBuffer::surface`): what a
// deferred pass needs to shade in the tangent frame of the item's UVs.
//   x, y: the UV (f32 bits), before the material's uv_scale;
//   z: the tangent (the direction of increasing u, across the surface) octahedral-encoded as
//      two snorm16;
//   w: bits 0..15 the material's BTF id (0: none), bit 16 the handedness (set where the
//      direction of decreasing v is -cross(n, tangent) instead of +cross(n, tangent)), bit 17
//      set where the UVs gave a tangent (clear: no UVs, or degenerate ones). Materials without
//      a BTF id get no tangent frame (gbuffer_common.wgsl `TANGENTS`): z and w are 0.
// Cleared to 0: nothing drawn, no BTF.

const SURFACE_ID_MASK: u32 = 0xffffu;
const SURFACE_FLIPPED: u32 = 0x10000u;
const SURFACE_HAS_TANGENT: u32 = 0x20000u;

fn oct_encode(v: vec3<f32>) -> vec2<f32> {
    let p = v.xy / max(abs(v.x) + abs(v.y) + abs(v.z), 1e-20);
    if v.z < 0.0 {
        return (1.0 - abs(p.yx)) * select(vec2<f32>(-1.0), vec2<f32>(1.0), p >= vec2<f32>(0.0));
    }
    return p;
}

fn oct_decode(e: vec2<f32>) -> vec3<f32> {
    var v = vec3<f32>(e, 1.0 - abs(e.x) - abs(e.y));
    if v.z < 0.0 {
        v = vec3<f32>((1.0 - abs(v.yx)) * select(vec2<f32>(-1.0), vec2<f32>(1.0), v.xy >= vec2<f32>(0.0)), v.z);
    }
    return normalize(v);
}

// The surface texel of a fragment at world position `world` with shading normal `n` (already
// flipped towards the viewer on back faces) and UV `uv`. The tangent frame comes from the
// screen-space derivatives of position and UV within the triangle (Schüler's cotangent frame):
// the mesh passes have no vertex attribute left for per-vertex tangents (16 of 16 are used),
// and the same code serves every kind of item, simulated meshes included, with no CPU work.
// Called in uniform control flow (the derivatives need it).
fn encode_surface(world: vec3<f32>, n: vec3<f32>, uv: vec2<f32>, btf_id: f32) -> vec4<u32> {
    let dp1 = dpdx(world);
    let dp2 = dpdy(world);
    let duv1 = dpdx(uv);
    let duv2 = dpdy(uv);
    let dp2perp = cross(dp2, n);
    let dp1perp = cross(n, dp1);
    // The surface gradients of u and v, up to the positive factor 1 / |det| (the sign of det
    // turns with the screen's orientation of the triangle).
    let orientation = select(1.0, -1.0, dot(dp1, dp2perp) < 0.0);
    let gu = (dp2perp * duv1.x + dp1perp * duv2.x) * orientation;
    let gv = (dp2perp * duv1.y + dp1perp * duv2.y) * orientation;
    var bits = u32(clamp(btf_id, 0.0, 65535.0));
    var t = vec3<f32>(0.0);
    let len2 = dot(gu, gu);
    if len2 > 1e-30 && dot(gv, gv) > 1e-30 {
        t = gu * inverseSqrt(len2);
        bits = bits | SURFACE_HAS_TANGENT;
        // The BTF's y axis points up its images, towards decreasing v.
        if dot(cross(n, t), -gv) < 0.0 {
            bits = bits | SURFACE_FLIPPED;
        }
    }
    return vec4<u32>(bitcast<u32>(uv.x), bitcast<u32>(uv.y), pack2x16snorm(oct_encode(t)), bits);
}

// A decoded surface texel: the UV, and the tangent frame (x along u, y towards decreasing v,
// both perpendicular to `n`); `valid` is false where the item had no usable UVs (then x, y
// are an arbitrary frame around `n`).
struct Surface {
    uv: vec2<f32>,
    x: vec3<f32>,
    y: vec3<f32>,
    id: u32,
    valid: bool,
};

fn decode_surface(s: vec4<u32>, n: vec3<f32>) -> Surface {
    var out: Surface;
    out.uv = vec2<f32>(bitcast<f32>(s.x), bitcast<f32>(s.y));
    out.id = s.w & SURFACE_ID_MASK;
    out.valid = (s.w & SURFACE_HAS_TANGENT) != 0u;
    var t = oct_decode(unpack2x16snorm(s.z));
    if !out.valid {
        t = select(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 0.0), abs(n.x) > 0.9);
    }
    // Orthogonal to the normal again: the tangent is the triangle's, the normal interpolated.
    t = t - n * dot(n, t);
    if dot(t, t) < 1e-12 {
        t = select(vec3<f32>(1.0, 0.0, 0.0), vec3<f32>(0.0, 1.0, 0.0), abs(n.x) > 0.9);
        t = t - n * dot(n, t);
    }
    out.x = normalize(t);
    out.y = cross(n, out.x);
    if (s.w & SURFACE_FLIPPED) != 0u {
        out.y = -out.y;
    }
    return out;
}

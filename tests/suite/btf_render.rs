//! Drawing BTFs (issue 32, docs/btf.md "Rendering"): the G-buffer's tangent frame follows the
//! UVs; BtfShading's WGSL weights (eqs. 3-5) reproduce `Sampling::weights` on the CPU at every
//! shaded pixel; an analytic Lambertian BTF shades like DirectLight's Lambert term; a white
//! furnace of median-cut lights gives about 1; bad input gives errors naming the parameter.

use std::sync::Arc;

use glam::{DVec3, Vec3};

use crate::common::*;
use werkstatt::btf::directions::{Dir, Sampling};
use werkstatt::core::eval::{Evaluator, NodeStatus};
use werkstatt::core::graph::Graph;
use werkstatt::core::port::Value;
use werkstatt::gpu::{Pixels, read_back};
use werkstatt::nodes::btf::btf_resource::directions_colour;
use werkstatt::render::scene::GBuffer;

/// A sphere drawn with a material of btf_id 1, seen by `gbuffer`; `nodes` and `links` add the
/// shading (a node "out" of kind Preview must show the result).
fn sphere_graph(nodes: &str, links: &str) -> Graph {
    sphere_graph_of(48, 24, 20.0, 25.0, nodes, links)
}

/// `sphere_graph` with `segments` around and along the sphere, seen from `yaw` and `pitch`.
fn sphere_graph_of(around: u32, along: u32, yaw: f64, pitch: f64, nodes: &str, links: &str) -> Graph {
    let text = format!(
        r#"(version: 2, nodes: {{
            "sphere": (kind: "Primitive", params: {{ "shape": "sphere", "radius": 0.5, "segments_u": {around}, "segments_v": {along} }}),
            "fabric": (kind: "Material", params: {{ "base_color": [0.6, 0.5, 0.4], "glossiness": 0.0, "btf_id": 1 }}),
            "draw": (kind: "Draw"),
            "camera": (kind: "OrbitCamera", params: {{ "distance": 2.0, "yaw": {yaw:?}, "pitch": {pitch:?}, "fov": 40.0 }}),
            "gbuffer": (kind: "GBufferPass"),
            "out": (kind: "Preview"),
            {nodes}
        }}, links: [
            ("sphere.mesh", "draw.mesh"), ("fabric.material", "draw.material"), ("draw.scene", "gbuffer.scene"),
            ("camera.camera", "gbuffer.camera"),
            {links}
        ])"#
    );
    Graph::load_str(&text, "btf-render-test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

fn gbuffer_of(ev: &Evaluator) -> Arc<GBuffer> {
    match ev.output("gbuffer", "gbuffer") {
        Some(Value::GBuffer(g)) => g.clone(),
        _ => panic!("no G-buffer"),
    }
}

/// `a`'s brightest colour channel, and the largest and mean absolute difference of `b` from `a`
/// over every channel.
fn differences(a: &Pixels, b: &Pixels) -> (f32, f32, f32) {
    let peak = a.rgba.chunks_exact(4).flat_map(|p| &p[..3]).fold(0.0f32, |m, &x| m.max(x));
    let (mut worst, mut sum) = (0.0f32, 0.0f32);
    for (x, y) in a.rgba.iter().zip(&b.rgba) {
        worst = worst.max((x - y).abs());
        sum += (x - y).abs();
    }
    (peak, worst, sum / a.rgba.len() as f32)
}

fn image(ev: &Evaluator, node: &str) -> Pixels {
    read_back(gpu(), ev.output(node, "image").and_then(Value::as_texture).expect("an image")).unwrap()
}

/// One shaded pixel as the CPU sees it in the G-buffer: its normal, view direction, and the
/// tangent frame decoded as shaders/common/surface.wgsl does.
struct Texel {
    n: DVec3,
    v: DVec3,
    x: DVec3,
    y: DVec3,
    id: u32,
    has_tangent: bool,
}

fn unpack_snorm(bits: u32) -> f64 {
    (f64::from(bits as u16 as i16) / 32767.0).clamp(-1.0, 1.0)
}

fn oct_decode(e: [f64; 2]) -> DVec3 {
    let mut v = DVec3::new(e[0], e[1], 1.0 - e[0].abs() - e[1].abs());
    if v.z < 0.0 {
        let sign = |a: f64| if a >= 0.0 { 1.0 } else { -1.0 };
        v = DVec3::new((1.0 - v.y.abs()) * sign(v.x), (1.0 - v.x.abs()) * sign(v.y), v.z);
    }
    v.normalize()
}

/// Every covered pixel's texel (None where nothing was drawn).
fn texels(g: &GBuffer) -> Vec<Option<Texel>> {
    let normal = read_back(gpu(), &g.normal).unwrap();
    let surface = read_back(gpu(), &g.surface).unwrap();
    let depth = read_back(gpu(), &g.depth).unwrap();
    let (w, h) = (g.width(), g.height());
    (0..(w * h) as usize)
        .map(|i| {
            let d = depth.rgba[i * 4];
            if d <= 0.0 {
                return None;
            }
            let (px, py) = (i as u32 % w, i as u32 / w);
            let p = werkstatt::occlusion::reference::world_position(&g.view, px, py, d).as_dvec3();
            let n = Vec3::from_slice(&normal.rgba[i * 4..][..3]).as_dvec3().normalize();
            let bits: Vec<u32> = surface.rgba[i * 4..][..4].iter().map(|x| x.to_bits()).collect();
            let t = oct_decode([unpack_snorm(bits[2] & 0xffff), unpack_snorm(bits[2] >> 16)]);
            let x = (t - n * n.dot(t)).normalize();
            let flipped = bits[3] & 0x10000 != 0;
            let y = if flipped { -n.cross(x) } else { n.cross(x) };
            Some(Texel {
                n,
                v: (g.view.eye.as_dvec3() - p).normalize(),
                x,
                y,
                id: bits[3] & 0xffff,
                has_tangent: bits[3] & 0x20000 != 0,
            })
        })
        .collect()
}

fn local(t: &Texel, d: DVec3) -> Dir {
    Dir::from_vec(DVec3::new(d.dot(t.x), d.dot(t.y), d.dot(t.n)))
}

/// On the sphere (P(u, v) = r (sin(pi v) sin(2 pi u), cos(pi v), sin(pi v) cos(2 pi u))) the
/// frame's x is the direction of increasing u, dP/du, and its y that of decreasing v, -dP/dv
/// (up the sphere), at every pixel away from the poles.
#[test]
fn the_gbuffer_carries_the_tangent_frame_of_the_uvs() {
    let graph = sphere_graph(
        r#""light": (kind: "DirectLight"),"#,
        r#"("gbuffer.gbuffer", "light.gbuffer"), ("light.image", "out.image"),"#,
    );
    let ev = run_graph(&graph, 64, 64);
    let g = gbuffer_of(&ev);
    let (mut checked, mut worst) = (0, 0.0f64);
    let depth = read_back(gpu(), &g.depth).unwrap();
    for (i, t) in texels(&g).iter().enumerate() {
        let Some(t) = t else { continue };
        assert!(t.id == 1 && t.has_tangent, "pixel {i}: id {} tangent {}", t.id, t.has_tangent);
        let (px, py) = (i as u32 % 64, i as u32 / 64);
        let p = werkstatt::occlusion::reference::world_position(&g.view, px, py, depth.rgba[i * 4]).as_dvec3();
        let q = p.normalize();
        // Away from the poles (where u turns fast) and the silhouette (interpolated normals).
        if q.y.abs() > 0.8 || t.n.dot(t.v) < 0.3 {
            continue;
        }
        let du = DVec3::new(q.z, 0.0, -q.x).normalize();
        let up = (DVec3::Y - q * q.y).normalize();
        worst = worst.max((t.x - du).length()).max((t.y - up).length());
        checked += 1;
    }
    assert!(checked > 500, "only {checked} pixels checked");
    // The frame is the flat triangle's (48 x 24 segments: 7.5 deg apart), orthogonalised
    // against the interpolated normal.
    assert!(worst < 0.12, "tangent frame off by {worst}");
}

/// The diagnostic BTF (a flat colour per (view, light) pair) under one sun: at every shaded
/// pixel the GPU's result equals `sum_m omega_m sum_l tau_l N(j_m, i_l)` with the weights of
/// `Sampling::weights`, the frame read from the G-buffer and the weave turned by 30 deg.
#[test]
fn btf_shading_blends_views_and_lights_as_the_cpu_weights_do() {
    let sun = Vec3::new(-0.3, -1.0, -0.5);
    let nodes = format!(
        r#""btf": (kind: "Btf", params: {{ "source": "directions", "resolution": 2, "components": 16 }}),
        "shade": (kind: "BtfShading", params: {{ "sun_direction": [{}, {}, {}], "sun_color": [1.0, 1.0, 1.0],
            "sun_intensity": 1.0, "alpha": 0.0, "shadow_blur": 0.0, "rotation": 30.0, "tiling": 3.0 }}),"#,
        sun.x, sun.y, sun.z
    );
    let graph = sphere_graph(
        &nodes,
        r#"("gbuffer.gbuffer", "shade.gbuffer"), ("btf.btf", "shade.btf"), ("shade.image", "out.image"),"#,
    );
    let ev = run_graph(&graph, 72, 72);
    let out = image(&ev, "shade");
    let sampling = Sampling::h2();
    let l = -sun.as_dvec3().normalize();
    let (rot_c, rot_s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let (mut checked, mut worst) = (0, 0.0f64);
    for (i, t) in texels(&gbuffer_of(&ev)).iter().enumerate() {
        let Some(t) = t else { continue };
        let cos_l = t.n.dot(l);
        // Clear of the terminator (eq. 6's texel there) and of grazing views (f16 normals).
        if cos_l < 0.02 || t.n.dot(t.v) < 0.05 {
            continue;
        }
        let turned = Texel { x: t.x * rot_c + t.y * rot_s, y: t.y * rot_c - t.x * rot_s, ..*t };
        let (view, light) = (local(&turned, t.v), local(&turned, l));
        // Past the last ring (75 deg) the light's images fade with cos(theta) / cos(75 deg).
        let grazing = if light.theta > 75.0 { cos_l / 75f64.to_radians().cos() } else { 1.0 };
        let mut want = DVec3::ZERO;
        for (j, wv) in sampling.weights(view) {
            for (k, wl) in sampling.weights(light) {
                want += DVec3::from(directions_colour(j, k).map(f64::from)) * wv * wl * grazing;
            }
        }
        let got = DVec3::new(out.rgba[i * 4] as f64, out.rgba[i * 4 + 1] as f64, out.rgba[i * 4 + 2] as f64);
        worst = worst.max((got - want).abs().max_element());
        checked += 1;
    }
    assert!(checked > 1000, "only {checked} pixels checked");
    // f16 eigentextures and output (values up to 0.9), f32 angles on the GPU.
    assert!(worst < 4e-3, "GPU and CPU blends differ by up to {worst}");
}

/// `BtfShading` with `btf` params and `shade` params beside `DirectLight` (sun from
/// (-0.4, -1, -0.6) at intensity 3, no ambient) on the test sphere at `size`^2, `DirectLight`
/// as the base image: the two images and, per pixel, whether the sphere covers it.
fn shade_against_direct(btf: &str, shade: &str, size: usize) -> (Pixels, Pixels, Vec<bool>) {
    let nodes = format!(
        r#""btf": (kind: "Btf", params: {{ {btf} }}),
        "direct": (kind: "DirectLight", params: {{ "sun_direction": [-0.4, -1.0, -0.6], "sun_intensity": 3.0,
            "sky_color": [0.0, 0.0, 0.0], "ground_color": [0.0, 0.0, 0.0] }}),
        "shade": (kind: "BtfShading", params: {{ "sun_direction": [-0.4, -1.0, -0.6], "sun_intensity": 3.0, {shade} }}),"#
    );
    let links = r#"("gbuffer.gbuffer", "shade.gbuffer"), ("gbuffer.gbuffer", "direct.gbuffer"), ("btf.btf", "shade.btf"),
        ("direct.image", "shade.base"), ("shade.image", "out.image"),"#;
    let ev = run_graph(&sphere_graph(&nodes, links), size as u32, size as u32);
    let depth = read_back(gpu(), &gbuffer_of(&ev).depth).unwrap();
    let covered = (0..size * size).map(|i| depth.rgba[i * 4] > 0.0).collect();
    (image(&ev, "shade"), image(&ev, "direct"), covered)
}

/// rho / pi cos(theta_i) under the sun against DirectLight's Lambert term (no ambient, no
/// gloss): equal up to the linear interpolation of the cosine between the 15 deg rings,
/// (15 deg)^2 / 8 = 0.0086 of rho E / pi, and f16 rounding.
#[test]
fn a_lambertian_btf_shades_like_lambert() {
    let (btf, direct, lit) = shade_against_direct(
        r#""source": "lambert", "albedo": [0.6, 0.5, 0.4], "resolution": 2"#,
        r#""alpha": 0.0, "shadow_blur": 0.0, "rotation": 10.0"#,
        64,
    );
    let (mut covered, mut worst) = (0, 0.0f32);
    for (i, &lit) in lit.iter().enumerate() {
        if !lit {
            // The base image shows through where nothing is shaded.
            assert_eq!(&btf.rgba[i * 4..][..3], &direct.rgba[i * 4..][..3], "pixel {i}");
            continue;
        }
        covered += 1;
        for c in 0..3 {
            worst = worst.max((btf.rgba[i * 4 + c] - direct.rgba[i * 4 + c]).abs());
        }
    }
    let bound = 0.0086 * 0.6 * 3.0 / std::f32::consts::PI + 2e-3;
    assert!(covered > 1000, "only {covered} pixels covered");
    assert!(worst < bound, "BTF Lambert and DirectLight differ by {worst} (bound {bound})");
}

/// Eq. 6 and Fig. 8 on a coarse sphere (7 x 5 segments) lit from the side, seen head-on. With a
/// Lambertian BTF the sun's boundary factor is the ratio of two renders against a hard eq. 6
/// boundary at alpha = 0 ("flat": 1 wherever the interpolated normal faces the sun):
/// - smooth, alpha = 30 deg, blur 256 texels: at every lit pixel the factor is the 1D texture
///   (`shadow_ramp`, linearly filtered) at u = (1 + cos(alpha + angle(n, l))) / 2 of the
///   G-buffer's normal, over the blurred stretch 45.5-74.5 deg as well as beyond it;
/// - faces: the factor is 0 or 1 (a step), and it cuts off lit pixels near the terminator where
///   a triangle faces away while its interpolated normal faces the sun (the zigzag).
#[test]
fn the_sun_boundary_follows_eq_6_or_steps_at_the_triangles() {
    let sun = r#""sun_direction": [-1.0, -0.45, 0.1], "sun_intensity": 2.0"#;
    let nodes = format!(
        r#""btf": (kind: "Btf", params: {{ "source": "lambert", "albedo": [0.8, 0.8, 0.8], "resolution": 2 }}),
        "flat": (kind: "BtfShading", params: {{ {sun}, "alpha": 0.0, "shadow_blur": 0.0 }}),
        "soft": (kind: "BtfShading", params: {{ {sun}, "alpha": 30.0, "shadow_blur": 256.0 }}),
        "faces": (kind: "BtfShading", params: {{ {sun}, "sun_boundary": "faces" }}),
        "out2": (kind: "Preview"), "out3": (kind: "Preview"),"#
    );
    let links = r#"("gbuffer.gbuffer", "flat.gbuffer"), ("gbuffer.gbuffer", "soft.gbuffer"), ("gbuffer.gbuffer", "faces.gbuffer"),
        ("btf.btf", "flat.btf"), ("btf.btf", "soft.btf"), ("btf.btf", "faces.btf"),
        ("flat.image", "out.image"), ("soft.image", "out2.image"), ("faces.image", "out3.image"),"#;
    let ev = run_graph(&sphere_graph_of(7, 5, 0.0, 0.0, &nodes, links), 64, 64);
    let (flat, soft, faces) = (image(&ev, "flat"), image(&ev, "soft"), image(&ev, "faces"));
    let g = gbuffer_of(&ev);
    let normals = read_back(gpu(), &g.normal).unwrap();
    let depth = read_back(gpu(), &g.depth).unwrap();
    let l = DVec3::new(1.0, 0.45, -0.1).normalize();
    let ramp = werkstatt::btf::gpu::shadow_ramp(1024, 256.0);
    // The texture as the sampler reads it: linear between texel centres, clamped at the ends.
    let texture = |u: f64| {
        let x = (u * 1024.0 - 0.5).clamp(0.0, 1023.0);
        let (k, s) = (x.floor() as usize, x.fract());
        ramp[k] as f64 * (1.0 - s) + ramp[(k + 1).min(1023)] as f64 * s
    };
    let (mut blurred, mut cut, mut worst) = (0, 0, 0.0f64);
    for i in 0..64 * 64 {
        let reference = flat.rgba[i * 4] as f64;
        if depth.rgba[i * 4] <= 0.0 || reference < 0.02 {
            continue;
        }
        let n = DVec3::new(normals.rgba[i * 4] as f64, normals.rgba[i * 4 + 1] as f64, normals.rgba[i * 4 + 2] as f64)
            .normalize();
        let angle = n.dot(l).clamp(-1.0, 1.0).acos();
        let u = (1.0 + (30f64.to_radians() + angle).min(std::f64::consts::PI).cos()) / 2.0;
        let expected = texture(u);
        worst = worst.max((soft.rgba[i * 4] as f64 / reference - expected).abs());
        if expected > 0.05 && expected < 0.95 {
            blurred += 1;
        }
        let step = faces.rgba[i * 4] as f64 / reference;
        assert!(step < 0.01 || (step - 1.0).abs() < 0.01, "pixel {i}: faces gives {step} of the lit value");
        if step < 0.01 {
            cut += 1;
            assert!(n.dot(l) < 0.7, "pixel {i}: cut at cos {} far from the terminator", n.dot(l));
        }
    }
    assert!(blurred > 100, "only {blurred} pixels on the blurred stretch");
    assert!(worst < 0.01, "the smooth boundary departs from eq. 6's texture by {worst}");
    assert!(cut > 20, "faces cut only {cut} lit pixels: no zigzag");
}

/// A white BTF (rho = 1) under a white environment of radiance 1, as 256 median-cut lights:
/// 1 everywhere on the sphere, within 1% on average and 2% at any pixel. What remains is the discretisation into 256 lights (the
/// hemisphere's edge cuts regions) and the cosine's interpolation between rings.
#[test]
fn a_white_furnace_of_median_cut_lights_gives_one() {
    let out = out_dir("btf-furnace");
    let probe = out.join("white.hdr");
    write_probe(&probe, 32, 16, |_, _| Vec3::ONE);
    let nodes = format!(
        r#""btf": (kind: "Btf", params: {{ "source": "lambert", "albedo": [1.0, 1.0, 1.0], "resolution": 2 }}),
        "env": (kind: "EnvironmentMap", params: {{ "path": {:?}, "size": 16 }}),
        "cut": (kind: "MedianCut", params: {{ "count": 256 }}),
        "shade": (kind: "BtfShading", params: {{ "sun_intensity": 0.0 }}),"#,
        probe.display().to_string()
    );
    let links = r#"("gbuffer.gbuffer", "shade.gbuffer"), ("btf.btf", "shade.btf"), ("env.environment", "cut.environment"),
        ("cut.lights", "shade.lights"), ("shade.image", "out.image"),"#;
    let ev = run_graph(&sphere_graph(&nodes, links), 48, 48);
    let img = image(&ev, "shade");
    let depth = read_back(gpu(), &gbuffer_of(&ev).depth).unwrap();
    let values: Vec<f32> = (0..48 * 48).filter(|&i| depth.rgba[i * 4] > 0.0).map(|i| img.rgba[i * 4 + 1]).collect();
    assert!(values.len() > 500);
    let mean = values.iter().sum::<f32>() / values.len() as f32;
    let worst = values.iter().map(|v| (v - 1.0).abs()).fold(0.0, f32::max);
    eprintln!("furnace: mean {mean:.4}, worst pixel off by {worst:.4}, {} pixels", values.len());
    // Measured: mean 0.9946, worst pixel 0.0088 off (without the fade past the last ring,
    // 1.061 and 0.072).
    assert!((mean - 1.0).abs() < 0.01, "furnace mean {mean}");
    assert!(worst < 0.02, "a furnace pixel is off by {worst}");
}

/// The sphere graph with a BtfShading node "shade" lit only by the probe `probe` through HEM
/// (the Draw node's scene, an 8² hemicube per vertex); `btf` is the Btf node's parameters.
fn hem_graph(probe: &std::path::Path, btf: &str, shade: &str) -> Graph {
    let nodes = format!(
        r#""btf": (kind: "Btf", params: {{ {btf} }}),
        "env": (kind: "EnvironmentMap", params: {{ "path": {:?}, "size": 8 }}),
        "shade": (kind: "BtfShading", params: {{ "sun_intensity": 0.0, "hemicube": 8, {shade} }}),"#,
        probe.display().to_string()
    );
    let links = r#"("gbuffer.gbuffer", "shade.gbuffer"), ("btf.btf", "shade.btf"), ("env.environment", "shade.environment"),
        ("draw.scene", "shade.scene"), ("shade.image", "out.image"),"#;
    sphere_graph(&nodes, links)
}

/// The closest triangle of `mesh` along the ray from `eye` towards `p`, with the barycentric
/// weights of its three corners.
fn hit_triangle(mesh: &werkstatt::mesh::Mesh, eye: DVec3, p: DVec3) -> Option<([u32; 3], DVec3)> {
    let dir = (p - eye).normalize();
    let mut best: Option<(f64, [u32; 3], DVec3)> = None;
    for t in mesh.indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| mesh.positions[i as usize].as_dvec3());
        let (e1, e2) = (b - a, c - a);
        let q = dir.cross(e2);
        let det = e1.dot(q);
        if det.abs() < 1e-12 {
            continue;
        }
        let s = eye - a;
        let (u, r) = (s.dot(q) / det, s.cross(e1));
        let v = dir.dot(r) / det;
        let dist = e2.dot(r) / det;
        let inside = u >= -1e-6 && v >= -1e-6 && u + v <= 1.0 + 1e-6 && dist > 0.0;
        if inside && best.is_none_or(|(d, ..)| dist < d) {
            best = Some((dist, [t[0], t[1], t[2]], DVec3::new(1.0 - u - v, u, v)));
        }
    }
    best.map(|(_, t, b)| (t, b))
}

/// Environment light by the paper's per-vertex weight sets (HEM, eqs. 10-12): at sampled
/// pixels, the GPU's result equals the CPU's `U` (Visibility, light sums, eq. 12 on the same
/// mesh, probe and BTF) interpolated at the pixel's barycentrics (found by a ray here) and
/// reconstructed by eq. 11 for the pixel's view (`WeightTable::vertex_texture`). The diagnostic
/// BTF makes every view slot and component count; the weave is turned by 30 deg.
#[test]
fn hem_shading_matches_the_cpu_weight_sets() {
    use werkstatt::btf::hem::{Visibility, WeightTable, mesh_frames};
    use werkstatt::btf::pca::{Centring, compress};
    let out = out_dir("btf-hem");
    let probe = out.join("sky.hdr");
    write_probe(&probe, 32, 16, |x, y| Vec3::new(0.2 + x as f32 / 16.0, 1.5 - y as f32 / 12.0, 0.5));
    let btf = r#""source": "directions", "resolution": 2, "components": 16"#;
    let ev = run_graph(&hem_graph(&probe, btf, r#""rotation": 30.0, "environment_intensity": 0.5"#), 48, 48);
    let shaded = image(&ev, "shade");
    let Some(Value::Surface(mesh)) = ev.output("sphere", "mesh") else { panic!("no mesh") };
    let Some(Value::Environment(env)) = ev.output("env", "environment") else { panic!("no environment") };
    let sampling = Sampling::h2();
    let compressed =
        compress(&werkstatt::nodes::btf::btf_resource::directions_btf(sampling.clone(), 2), 16, Centring::Mean);
    let table = WeightTable::new(&compressed, &sampling, compressed.components).unwrap();
    let (positions, frames) = mesh_frames(mesh, glam::Mat4::IDENTITY, 30f64.to_radians());
    let vis = Visibility::compute(&positions, &frames, &mesh.indices, &sampling, 8, env.size(), 0).unwrap();
    let u = table.weight_sets(&vis.light_sums(&env.texels, 0).unwrap(), 0);
    let g = gbuffer_of(&ev);
    let depth = read_back(gpu(), &g.depth).unwrap();
    let (rot_c, rot_s) = (30f64.to_radians().cos(), 30f64.to_radians().sin());
    let (mut checked, mut worst, mut largest) = (0, 0.0f64, 0.0f64);
    for (i, t) in texels(&g).iter().enumerate().step_by(5) {
        let Some(t) = t else { continue };
        if t.n.dot(t.v) < 0.1 {
            continue;
        }
        let p =
            werkstatt::occlusion::reference::world_position(&g.view, i as u32 % 48, i as u32 / 48, depth.rgba[i * 4]);
        let Some((corners, bary)) = hit_triangle(mesh, g.view.eye.as_dvec3(), p.as_dvec3()) else { continue };
        let len = table.set_len();
        let mut set = vec![0.0f32; len];
        for (&v, b) in corners.iter().zip(bary.to_array()) {
            set.iter_mut().zip(&u[v as usize * len..][..len]).for_each(|(s, &x)| *s += b as f32 * x);
        }
        let turned = Texel { x: t.x * rot_c + t.y * rot_s, y: t.y * rot_c - t.x * rot_s, ..*t };
        let want = table.vertex_texture(&compressed, &set, 0, local(&turned, t.v), 0.5);
        for (&got, &want) in shaded.rgba[i * 4..][..3].iter().zip(&want) {
            worst = worst.max((got as f64 - want as f64).abs());
            largest = largest.max(want as f64);
        }
        checked += 1;
    }
    eprintln!("HEM: {checked} pixels, GPU against CPU off by up to {worst:.2e} of values up to {largest:.3}");
    assert!(checked > 100, "only {checked} pixels checked");
    // f16 eigentextures and output.
    assert!(worst < 4e-3 * largest.max(1.0), "GPU and CPU HEM differ by up to {worst} (values up to {largest})");
}

/// A white Lambertian BTF lit through HEM by a white probe of radiance 1 gives 1 on the sphere
/// (convex: every hemicube pixel open), up to the cosine's interpolation between rings.
#[test]
fn a_white_furnace_through_hem_gives_one() {
    let out = out_dir("btf-hem-furnace");
    let probe = out.join("white.hdr");
    write_probe(&probe, 32, 16, |_, _| Vec3::ONE);
    let btf = r#""source": "lambert", "albedo": [1.0, 1.0, 1.0], "resolution": 2"#;
    let ev = run_graph(&hem_graph(&probe, btf, ""), 32, 32);
    let img = image(&ev, "shade");
    let depth = read_back(gpu(), &gbuffer_of(&ev).depth).unwrap();
    let values: Vec<f32> = (0..32 * 32).filter(|&i| depth.rgba[i * 4] > 0.0).map(|i| img.rgba[i * 4 + 1]).collect();
    let mean = values.iter().sum::<f32>() / values.len() as f32;
    let worst = values.iter().map(|v| (v - 1.0).abs()).fold(0.0, f32::max);
    eprintln!("HEM furnace: mean {mean:.4}, worst pixel off by {worst:.4}, {} pixels", values.len());
    assert!(values.len() > 200);
    assert!((mean - 1.0).abs() < 0.01 && worst < 0.02, "furnace mean {mean}, worst pixel off by {worst}");
}

fn failure(ev: &Evaluator, node: &str) -> String {
    match ev.report(node).map(|r| r.status) {
        Some(NodeStatus::Failed(m)) => m.clone(),
        other => panic!("node {node} did not fail: {other:?}"),
    }
}

#[test]
fn bad_btf_input_gives_errors_naming_the_parameter() {
    let dir = out_dir("btf-bad-input");
    let wrong = dir.join("wrong.btf");
    std::fs::write(&wrong, b"{\"format\":\"other\"}\n").unwrap();
    let cases = [
        (format!(r#""source": "file", "path": {:?}"#, dir.join("absent.btf").display().to_string()), "absent.btf"),
        (format!(r#""source": "file", "path": {:?}"#, wrong.display().to_string()), "wrong.btf"),
        (r#""source": "file""#.to_string(), "parameter \"path\" is empty"),
        (r#""source": "lambert", "sampling": "h2_tests", "components": 20"#.to_string(), "19 light directions"),
    ];
    for (params, want) in cases {
        let nodes = format!(r#""btf": (kind: "Btf", params: {{ {params} }}), "shade": (kind: "BtfShading"),"#);
        let links = r#"("gbuffer.gbuffer", "shade.gbuffer"), ("btf.btf", "shade.btf"), ("shade.image", "out.image"),"#;
        let ev = evaluate_graph(&sphere_graph(&nodes, links), 16, 16);
        let msg = failure(&ev, "btf");
        let parameter = if want.contains("light directions") { "\"components\"" } else { "\"path\"" };
        assert!(
            msg.contains(want) && msg.contains(parameter),
            "{params}: {msg:?} should say {want:?} and name {parameter}"
        );
        assert!(!msg.contains("panicked"), "{msg}");
    }
    // HEM needs both the scene and the environment.
    let nodes = r#""btf": (kind: "Btf", params: { "resolution": 2 }), "shade": (kind: "BtfShading"),"#;
    let links = r#"("gbuffer.gbuffer", "shade.gbuffer"), ("btf.btf", "shade.btf"), ("draw.scene", "shade.scene"),
        ("shade.image", "out.image"),"#;
    let msg = failure(&evaluate_graph(&sphere_graph(nodes, links), 16, 16), "shade");
    assert!(msg.contains("\"environment\"") && msg.contains("\"scene\""), "{msg}");
}

/// Figs. 6 and 7 (`BtfSlot`): the original image is the bake's (view, light) image at the
/// metric's exposure, a full-rank reconstruction (18 components: the rank of 19 images less
/// their mean) is the original and has no 8-bit error (all green), c = 5 has some, and the
/// eigenvalues written to stats.json sum to the slot's centred energy.
#[test]
fn btf_slot_shows_the_image_its_reconstruction_and_the_eigenvalues() {
    use werkstatt::btf::bake::{BakeParams, Pattern, Tier, bake};
    use werkstatt::btf::pca::{Centring, compress_slot};
    use werkstatt::core::node::Product;
    let slot = |id: &str, c: usize| {
        format!(
            r#""{id}": (kind: "BtfSlot", params: {{ "view_theta": 15.0, "view_phi": 60.0, "light_theta": 30.0, "light_phi": 90.0, "components": {c} }}),"#
        )
    };
    let text = format!(
        r#"(version: 2, nodes: {{
            "btf": (kind: "Btf", params: {{ "source": "bake", "weave": "twill", "resolution": 8, "sampling": "h2_tests", "supersample": 1, "components": 4 }}),
            {} {}
        }}, links: [("btf.btf", "full.btf"), ("btf.btf", "five.btf")])"#,
        slot("full", 18),
        slot("five", 5)
    );
    let graph = Graph::load_str(&text, "btf-slot-test.ron".as_ref()).unwrap();
    let ev = run_graph(&graph, 8, 8);
    let scalar = |id: &str, port: &str| match ev.output(id, port) {
        Some(Value::Scalar(x)) => *x,
        _ => panic!("{id}.{port} is not a scalar"),
    };
    let read =
        |id: &str, port: &str| read_back(gpu(), ev.output(id, port).and_then(Value::as_texture).unwrap()).unwrap();

    let params = BakeParams {
        size: 8,
        sampling: Sampling::h2_tests(),
        supersample: 1,
        ..BakeParams::tier(Pattern::Twill, Tier::Test)
    };
    let btf = bake(&params, 2).unwrap();
    let (view, light) = (
        btf.direction_index(Dir { theta: 15.0, phi: 60.0 }).unwrap(),
        btf.direction_index(Dir { theta: 30.0, phi: 90.0 }).unwrap(),
    );
    let (n, dim) = (btf.sampling.len(), btf.image_len());
    let exposure = werkstatt::btf::exposure8(&btf.data);
    let expected = &btf.slot(view)[light * dim..][..dim];
    let (original, rebuilt) = (read("full", "original"), read("full", "reconstruction"));
    for (t, rgb) in expected.chunks_exact(3).enumerate() {
        for (ch, &value) in rgb.iter().enumerate() {
            let want = (f64::from(value) * exposure / 255.0) as f32;
            for (name, image) in [("original", &original), ("reconstruction", &rebuilt)] {
                let got = image.rgba[t * 4 + ch];
                assert!(
                    (got - want).abs() <= 2e-3 * want.max(1.0),
                    "{name}, texel {t}, channel {ch}: {got} against {want}"
                );
            }
        }
    }
    // Full rank: exact up to f32 rounding, so every texel is green.
    assert!(scalar("full", "error_max") < 0.5, "full rank error {}", scalar("full", "error_max"));
    let heat = read("full", "error");
    assert!(heat.rgba.chunks_exact(4).all(|p| p[0] < 0.01 && p[1] > 0.99), "the full-rank heatmap is not all green");
    let (mean5, p99, max5) = (scalar("five", "error_mean"), scalar("five", "error_p99"), scalar("five", "error_max"));
    eprintln!("c = 5: 8-bit error mean {mean5:.2}, p99 {p99:.2}, max {max5:.2}");
    assert!(mean5 > 0.5 && p99 <= max5);
    // c = 5 is the library's PCA of the slot with 5 components, and its error the metric's.
    let pca = compress_slot(btf.slot(view), dim, 5, Centring::Mean);
    let five = pca.reconstruct(light);
    let image5 = read("five", "reconstruction");
    for (t, &value) in five.iter().enumerate() {
        let want = (f64::from(value) * exposure / 255.0) as f32;
        let got = image5.rgba[t / 3 * 4 + t % 3];
        assert!((got - want).abs() <= 2e-3 * want.abs().max(1.0), "c = 5, value {t}: {got} against {want}");
    }
    let errors = werkstatt::btf::error8(expected, &five, exposure);
    let want = errors.iter().sum::<f64>() / errors.len() as f64;
    assert!((mean5 - want).abs() < 1e-6 * want, "c = 5: mean error {mean5} against {want}");

    // The eigenvalues: all n, descending, summing to the trace of the centred Gram matrix.
    let values: Vec<f64> =
        ev.products("five").iter().filter_map(|p| if let Product::Value(v) = p { Some(*v) } else { None }).collect();
    assert_eq!(values.len(), n);
    assert!(values.windows(2).all(|w| w[0] >= w[1]));
    let images = btf.slot(view);
    let mean: Vec<f64> =
        (0..dim).map(|t| (0..n).map(|i| f64::from(images[i * dim + t])).sum::<f64>() / n as f64).collect();
    let energy: f64 = (0..n)
        .flat_map(|i| (0..dim).map(move |t| (i, t)))
        .map(|(i, t)| (f64::from(images[i * dim + t]) - mean[t]).powi(2))
        .sum();
    let sum: f64 = values.iter().sum();
    assert!((sum - energy).abs() <= 1e-6 * energy, "eigenvalues sum to {sum}, the slot's centred energy is {energy}");
}

/// Mip maps of the eigentextures: a weave of stripes 1 texel wide, tiled 64 times per UV unit on
/// the sphere (several texels per pixel), shades like Lambert with the stripes' mean albedo,
/// where sampling level 0 alone aliases to one stripe or the other (an error of about 0.2).
#[test]
fn a_minified_weave_shows_its_mean_colour() {
    // The stripes' mean, [0.6, 0.5, 0.4], is the sphere material's colour that DirectLight uses.
    let (btf, direct, lit) = shade_against_direct(
        r#""source": "lambert", "albedo": [0.9, 0.7, 0.5], "stripe_albedo": [0.3, 0.3, 0.3], "stripes": 4, "resolution": 8"#,
        r#""alpha": 0.0, "shadow_blur": 0.0, "tiling": 64.0"#,
        48,
    );
    let (mut covered, mut worst, mut sum) = (0, 0.0f32, 0.0f32);
    for i in (0..48 * 48).filter(|&i| lit[i]) {
        covered += 1;
        for c in 0..3 {
            let d = (btf.rgba[i * 4 + c] - direct.rgba[i * 4 + c]).abs();
            worst = worst.max(d);
            sum += d;
        }
    }
    eprintln!(
        "minified weave against Lambert of the mean: worst {worst:.4}, mean {:.5}, {covered} pixels",
        sum / (3 * covered) as f32
    );
    assert!(covered > 500, "only {covered} pixels covered");
    // The cosine's interpolation between rings (0.0086 rho E / pi) and f16, as for Lambert.
    assert!(worst < 0.0086 * 0.6 * 3.0 / std::f32::consts::PI + 4e-3, "the minified weave is off by {worst}");
}

/// A BtfSlot direction the BTF did not measure, more components than lights, and a tile too
/// large for the node to bake are errors naming the parameters.
#[test]
fn btf_slot_and_the_bake_name_their_bad_parameters() {
    let text = r#"(version: 2, nodes: {
        "btf": (kind: "Btf", params: { "source": "lambert", "sampling": "h2_tests", "resolution": 2 }),
        "off_grid": (kind: "BtfSlot", params: { "view_theta": 20.0 }),
        "too_many": (kind: "BtfSlot", params: { "components": 20 }),
        "big": (kind: "Btf", params: { "source": "bake", "resolution": 64 }),
        "big_slot": (kind: "BtfSlot"),
    }, links: [("btf.btf", "off_grid.btf"), ("btf.btf", "too_many.btf"), ("big.btf", "big_slot.btf")])"#;
    let graph = Graph::load_str(text, "btf-slot-errors.ron".as_ref()).unwrap();
    let ev = evaluate_graph(&graph, 8, 8);
    let m = failure(&ev, "off_grid");
    assert!(m.contains("\"view_theta\"") && m.contains("(20, 0)") && m.contains("30 deg x 12"), "{m}");
    let m = failure(&ev, "too_many");
    assert!(m.contains("\"components\" is 20") && m.contains("19 light directions"), "{m}");
    let m = failure(&ev, "big");
    assert!(m.contains("\"resolution\" is 64") && m.contains("werkstatt btf bake"), "{m}");
}

/// A compressed file (`werkstatt btf compress --out`, 8-bit images) shades like the BTF it was
/// compressed from, within the quantisation: a baked twill at the test tier, read both ways.
#[test]
fn a_compressed_btf_file_shades_like_its_images() {
    use werkstatt::btf::bake::{BakeParams, Pattern, Tier};
    use werkstatt::btf::pca::{Centring, compress};
    let dir = std::env::temp_dir().join(format!("werkstatt-btfc-render-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let params = BakeParams { size: 16, supersample: 1, ..BakeParams::tier(Pattern::Twill, Tier::Test) };
    let btf = werkstatt::btf::bake::bake(&params, 2).unwrap();
    let (images, packed) = (dir.join("twill.btf"), dir.join("twill.btfc"));
    werkstatt::btf::container::save(&btf, &images).unwrap();
    // The file keeps 12 components, the node draws 8 of them: the images, coefficients and HEM
    // weight sets must all take the first 8.
    let pca = compress(&btf, 12, Centring::Mean);
    werkstatt::btf::pca_file::save(&pca, &btf.sampling, btf.width, btf.height, &packed).unwrap();
    let probe = dir.join("sky.hdr");
    write_probe(&probe, 32, 16, |x, y| Vec3::new(0.3 + x as f32 / 16.0, 1.5 - y as f32 / 12.0, 0.6));
    let shade = |path: &std::path::Path| {
        let btf = format!(r#""source": "file", "path": {:?}, "components": 8"#, path.to_str().unwrap());
        image(&run_graph(&hem_graph(&probe, &btf, r#""tiling": 2.0"#), 48, 48), "shade")
    };
    let (a, b) = (shade(&images), shade(&packed));
    let (peak, worst, mean) = differences(&a, &b);
    eprintln!("compressed file against images: worst {worst:.5}, mean {mean:.6}, peak {peak:.4}");
    assert!(peak > 0.05, "nothing lit");
    // 8-bit images: each eigentexture channel is off by at most half of 1/255 of its range.
    assert!(worst < 0.03 * peak && mean < 0.003 * peak, "worst {worst}, mean {mean} of peak {peak}");
    assert!(worst > 0.0, "the 8-bit file rendered bit for bit like f16 images: was it read at all?");

    // BtfSlot compares against images, which a compressed file does not have.
    let text = format!(
        r#"(version: 2, nodes: {{
            "btf": (kind: "Btf", params: {{ "source": "file", "path": {:?}, "components": 8 }}),
            "slot": (kind: "BtfSlot", params: {{ "components": 8 }}),
        }}, links: [("btf.btf", "slot.btf")])"#,
        packed.to_str().unwrap()
    );
    let ev = evaluate_graph(&Graph::load_str(&text, "btfc-slot.ron".as_ref()).unwrap(), 8, 8);
    let m = failure(&ev, "slot");
    assert!(m.contains("read compressed (.btfc)") && m.contains("input \"btf\""), "{m}");
}

/// A SunLight shadowed through a ShadowAtlas: a ball above a BTF-shaded floor, the sun at 45
/// deg, seen from above. The ball's shadow is the disc's projection along the sun, an ellipse
/// of semi-axes r and r sqrt(2) (area pi r^2 sqrt(2)) beside the ball; pixels outside it are
/// exactly as without the atlas (VIS = 1 where the receiver is nearer than the moments' mean).
#[test]
fn a_sun_shadowed_through_the_atlas_casts_the_balls_shadow_on_the_btf_floor() {
    let graph = |shadowed: bool| {
        let (shadow_node, shadow_link) = if shadowed {
            (
                r#""atlas": (kind: "ShadowAtlas", params: { "tile_size": 256, "blur_scale": 0.0 }),"#,
                r#"("scene.scene", "atlas.scene"), ("sun.lights", "atlas.lights"), ("atlas.shadows", "shade.shadows"),"#,
            )
        } else {
            ("", "")
        };
        let text = format!(
            r#"(version: 2, nodes: {{
                "floor": (kind: "Primitive", params: {{ "shape": "plane", "size": 2.0 }}),
                "fabric": (kind: "Material", params: {{ "base_color": [0.6, 0.5, 0.4], "btf_id": 1 }}),
                "draw_floor": (kind: "Draw"),
                "ball": (kind: "Primitive", params: {{ "shape": "sphere", "radius": 0.25 }}),
                "grey": (kind: "Material", params: {{ "base_color": [0.5, 0.5, 0.5] }}),
                "draw_ball": (kind: "Draw", params: {{ "translate": [-0.3, 0.6, 0.0] }}),
                "scene": (kind: "Merge"),
                "camera": (kind: "OrbitCamera", params: {{ "distance": 3.0, "yaw": 0.0, "pitch": 89.0, "fov": 40.0 }}),
                "gbuffer": (kind: "GBufferPass"),
                "sun": (kind: "SunLight", params: {{ "direction": [1.0, -1.0, 0.0], "intensity": 3.0 }}),
                "btf": (kind: "Btf", params: {{ "source": "lambert", "albedo": [0.6, 0.5, 0.4], "resolution": 2 }}),
                "shade": (kind: "BtfShading", params: {{ "sun_intensity": 0.0, "lights_boundary": "smooth", "alpha": 0.0, "shadow_blur": 0.0 }}),
                {shadow_node}
                "out": (kind: "Preview"),
            }}, links: [
                ("floor.mesh", "draw_floor.mesh"), ("fabric.material", "draw_floor.material"),
                ("ball.mesh", "draw_ball.mesh"), ("grey.material", "draw_ball.material"),
                ("draw_floor.scene", "scene.a"), ("draw_ball.scene", "scene.b"),
                ("scene.scene", "gbuffer.scene"), ("camera.camera", "gbuffer.camera"),
                ("gbuffer.gbuffer", "shade.gbuffer"), ("btf.btf", "shade.btf"), ("sun.lights", "shade.lights"),
                {shadow_link}
                ("shade.image", "out.image"),
            ])"#
        );
        Graph::load_str(&text, "btf-sun-shadow.ron".as_ref()).unwrap_or_else(|e| panic!("{e}\n{text}"))
    };
    let size = 96usize;
    let lit = image(&run_graph(&graph(false), size as u32, size as u32), "shade");
    let shadowed = image(&run_graph(&graph(true), size as u32, size as u32), "shade");
    let (mut floor, mut dark, mut same) = (0, 0, 0);
    for i in 0..size * size {
        let (a, b) = (lit.rgba[i * 4], shadowed.rgba[i * 4]);
        // The floor's BTF pixels (the ball and the background are the background colour).
        if a < 0.2 {
            continue;
        }
        floor += 1;
        if b < 0.3 * a {
            dark += 1;
        } else if (b - a).abs() <= 1e-6 {
            same += 1;
        }
    }
    // The view spans 2 x 3 tan(20 deg) = 2.18 m across 96 pixels.
    let pixels_per_m2 = (size as f64 / (6.0 * 20f64.to_radians().tan())).powi(2);
    let expected = std::f64::consts::PI * 0.25 * 0.25 * 2f64.sqrt() * pixels_per_m2;
    eprintln!("sun shadow: {dark} dark pixels (ellipse {expected:.0}), {same} unchanged of {floor} floor pixels");
    assert!(floor > 4000, "only {floor} floor pixels");
    assert!(
        (dark as f64 - expected).abs() < 0.25 * expected,
        "{dark} shadowed pixels, the ellipse covers {expected:.0}"
    );
    let open = floor - dark;
    assert!(same as f64 > 0.9 * open as f64, "{same} of {open} unshadowed floor pixels unchanged");
}

/// Section 5.4: turning the environment through eigen-weightsets. With all A = 15 of them kept,
/// the sets at a step (24 deg) are the weight sets of the probe turned there (PCA at full rank);
/// with e = 5 (the paper's) between steps (36 deg) they approximate it. Turning changes the image.
#[test]
fn hem_turns_the_environment_through_eigen_weightsets() {
    let out = out_dir("btf-hem-eigen");
    let probe = out.join("lobe.hdr");
    // A bright patch of sky on one side: the image depends on the azimuth.
    write_probe(&probe, 32, 16, |x, y| if x < 8 && y < 7 { Vec3::new(4.0, 3.0, 2.0) } else { Vec3::splat(0.2) });
    let btf = r#""source": "lambert", "albedo": [0.8, 0.6, 0.4], "resolution": 2"#;
    let render = |shade: &str| {
        let ev = run_graph(&hem_graph(&probe, btf, shade), 32, 32);
        let depth = read_back(gpu(), &gbuffer_of(&ev).depth).unwrap();
        let img = image(&ev, "shade");
        (0..32 * 32)
            .filter(|&i| depth.rgba[i * 4] > 0.0)
            .flat_map(|i| img.rgba[i * 4..][..3].to_vec())
            .collect::<Vec<f32>>()
    };
    let relative = |a: &[f32], b: &[f32]| {
        let diff: f32 = a.iter().zip(b).map(|(x, y)| (x - y).powi(2)).sum();
        (diff / b.iter().map(|y| y * y).sum::<f32>()).sqrt()
    };
    let still = render("");
    let direct = render(r#""environment_rotation": 24.0"#);
    let full = render(r#""environment_rotation": 24.0, "rotation_steps": 15, "eigen_sets": 15"#);
    let direct_between = render(r#""environment_rotation": 36.0"#);
    let few = render(r#""environment_rotation": 36.0, "rotation_steps": 15, "eigen_sets": 5"#);
    let (turned, at_step, between) =
        (relative(&direct, &still), relative(&full, &direct), relative(&few, &direct_between));
    eprintln!(
        "HEM turned 24 deg: {turned:.4} from unturned; eigen (all 15) {at_step:.2e}; e = 5 at 36 deg {between:.4}"
    );
    assert!(still.len() > 600 && turned > 0.05, "turning the environment changed the image by only {turned}");
    assert!(at_step < 2e-3, "all eigen-weightsets at a step differ from the turned probe's weight sets by {at_step}");
    assert!(
        between < 0.1 * turned,
        "5 eigen-weightsets between steps are off by {between} (the turn itself: {turned})"
    );

    // A new angle on the same node (the eigen-weightsets and corner buffers kept, the weight
    // sets rewritten in place) gives what a fresh node gives at that angle.
    use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime};
    let turned_graph = |degrees: f64| {
        hem_graph(
            &probe,
            btf,
            &format!(r#""environment_rotation": {degrees:?}, "rotation_steps": 15, "eigen_sets": 5"#),
        )
    };
    let mut ev = Evaluator::new(&turned_graph(24.0), &[]).unwrap();
    let res = werkstatt::core::resources::Resources::new(false);
    let settings = FrameSettings { width: 32, height: 32, base_dir: root(), frames: None };
    for degrees in [24.0, 36.0] {
        ev.update(&turned_graph(degrees), &[]).unwrap();
        while ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, Some(gpu()), &res, &settings).pending > 0 {
            wait_idle(&res);
        }
    }
    let depth = read_back(gpu(), &gbuffer_of(&ev).depth).unwrap();
    let img = image(&ev, "shade");
    let again: Vec<f32> =
        (0..32 * 32).filter(|&i| depth.rgba[i * 4] > 0.0).flat_map(|i| img.rgba[i * 4..][..3].to_vec()).collect();
    assert_eq!(again, few, "turning a running node differs from a fresh one at the same angle");
}

/// `storage: "8bit"`: the mean and eigentextures as RGBA8 with each layer's range (half the GPU
/// memory of f16) shade like f16 layers within the 8-bit steps.
#[test]
fn eight_bit_layers_shade_like_half_floats_in_half_the_memory() {
    let render = |storage: &str| {
        let nodes = format!(
            r#""btf": (kind: "Btf", params: {{ "source": "bake", "weave": "twill", "resolution": 16, "supersample": 1, "sampling": "h2_tests", "components": 8, "storage": "{storage}" }}),
            "shade": (kind: "BtfShading", params: {{ "tiling": 2.0 }}),"#
        );
        let links = r#"("gbuffer.gbuffer", "shade.gbuffer"), ("btf.btf", "shade.btf"), ("shade.image", "out.image"),"#;
        let ev = run_graph(&sphere_graph(&nodes, links), 48, 48);
        let Some(Value::Btf(btf)) = ev.output("btf", "btf") else { panic!("no BTF") };
        (image(&ev, "shade"), btf.images.desc.format, btf.bytes)
    };
    let ((half, half_format, half_bytes), (byte, byte_format, byte_bytes)) = (render("f16"), render("8bit"));
    assert_eq!((half_format, byte_format), (wgpu::TextureFormat::Rgba16Float, wgpu::TextureFormat::Rgba8Unorm));
    let (peak, worst, mean) = differences(&half, &byte);
    eprintln!(
        "8-bit layers against f16: worst {worst:.5}, mean {mean:.6}, peak {peak:.4}; {byte_bytes} against {half_bytes} bytes"
    );
    assert!(peak > 0.05, "nothing lit");
    assert!(worst > 0.0 && worst < 0.03 * peak && mean < 0.003 * peak, "worst {worst}, mean {mean} of peak {peak}");
    assert!((byte_bytes as f64) < 0.55 * half_bytes as f64, "{byte_bytes} bytes against {half_bytes}");
}

/// `WovenCloth`'s panel layer under a BTF (graphs/fig10_woven_btf.ron): the far patches, at the
/// panel scale, carry `panel_btf_id` into the G-buffer and BtfShading shades them; the near
/// ones, yarns, are geometry and keep the DirectLight image; with `panel_btf_id` 0 no pixel is
/// the BTF's.
#[test]
fn the_woven_panel_scale_is_shaded_by_the_btf_of_its_weave() {
    let path = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/graphs/fig10_woven_btf.ron"));
    for panel_btf_id in [1, 0] {
        let mut graph = Graph::load(path).unwrap();
        graph.set_from_cli(&format!("cloth.panel_btf_id={panel_btf_id}")).unwrap();
        let ev = evaluate_graph(&graph, 160, 120);
        let texels = texels(&gbuffer_of(&ev));
        let (lit, shaded) = (image(&ev, "light"), image(&ev, "shade"));
        let (mut panel, mut yarns, mut panel_changed, mut yarns_kept) = (0, 0, 0, 0);
        for (i, t) in texels.iter().enumerate() {
            let Some(t) = t else { continue };
            let same = (0..3).all(|c| (lit.rgba[i * 4 + c] - shaded.rgba[i * 4 + c]).abs() < 1e-6);
            if t.id == 1 {
                assert!(t.has_tangent, "pixel {i}: a BTF pixel without a tangent frame");
                panel += 1;
                panel_changed += usize::from(!same);
            } else {
                yarns += 1;
                yarns_kept += usize::from(same);
            }
        }
        eprintln!(
            "panel_btf_id {panel_btf_id}: {panel} BTF pixels ({panel_changed} shaded), {yarns} others ({yarns_kept} kept)"
        );
        assert_eq!(yarns_kept, yarns, "pixels outside the BTF's material changed");
        if panel_btf_id == 1 {
            assert!(panel > 1000 && yarns > 1000, "{panel} panel and {yarns} yarn pixels");
            assert!(panel_changed * 10 > panel * 9, "BtfShading shaded {panel_changed} of {panel} panel pixels");
        } else {
            assert_eq!(panel, 0);
        }
    }
}

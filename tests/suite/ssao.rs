//! Local occlusion (issue 11): `Ssao` against the analytic values of its documented
//! normalisation, in both modes, at full and half resolution; `ReferenceOcclusion` against
//! the cosine-weighted form factor of a square, and its determinism.
//!
//! Scenes are made of planes (Primitive plane, 8 x 8, seen from inside the open region) so
//! each expected value holds exactly at the edge line or corner point. Pixels are picked by
//! their world position (reconstructed from the G-buffer's depth) and at least 15% of the
//! image away from its borders.

use glam::Vec3;

use crate::common::*;
use werkstatt::core::graph::Graph;
use werkstatt::core::port::Value;
use werkstatt::gpu::read_back;
use werkstatt::occlusion::reference::SceneBvh;

/// A plane's (translate, rotate) for Draw.
type Plane = ([f32; 3], [f32; 3]);
/// The floor y = 0.
const FLOOR: Plane = ([0.0; 3], [0.0; 3]);
/// The plane x = 0 above the floor (normal +x).
const WALL_X: Plane = ([0.0, 4.0, 0.0], [0.0, 0.0, -90.0]);
/// The plane z = 0 above the floor (normal +z).
const WALL_Z: Plane = ([0.0, 4.0, 0.0], [90.0, 0.0, 0.0]);

/// Planes (translate, rotate) of size 8, plus `extra` nodes and links, seen by an orbit
/// camera (`camera` params), its G-buffer feeding "ssao" (`ssao` params) and, with `reference`
/// params, "reference" (ReferenceOcclusion).
#[allow(clippy::too_many_arguments)]
fn graph(
    planes: &[Plane],
    extra_nodes: &str,
    extra_links: &str,
    extra_draws: &[&str],
    camera: &str,
    ssao: &str,
    reference: Option<&str>,
) -> Graph {
    let mut nodes = format!(
        r#""plane": (kind: "Primitive", params: {{ "shape": "plane", "size": 8.0, "segments_u": 1, "segments_v": 1 }}),
        "camera": (kind: "OrbitCamera", params: {{ {camera} }}),
        "gbuffer": (kind: "GBufferPass"),
        "ssao": (kind: "Ssao", params: {{ {ssao} }}),
        "out": (kind: "Preview"),
        {extra_nodes}"#
    );
    let mut links = format!(
        r#"("camera.camera", "gbuffer.camera"), ("gbuffer.gbuffer", "ssao.gbuffer"), ("ssao.occlusion", "out.image"),
        {extra_links}"#
    );
    let mut scenes: Vec<String> = Vec::new();
    for (i, (t, r)) in planes.iter().enumerate() {
        let params = format!(r#""translate": {t:?}, "rotate": {r:?}"#);
        nodes += &format!(r#""p{i}": (kind: "Draw", params: {{ {params} }}),"#);
        links += &format!(r#"("plane.mesh", "p{i}.mesh"),"#);
        scenes.push(format!("p{i}"));
    }
    scenes.extend(extra_draws.iter().map(|s| s.to_string()));
    assert!(scenes.len() <= 4);
    nodes += r#""all": (kind: "Merge"),"#;
    for (s, port) in scenes.iter().zip(["a", "b", "c", "d"]) {
        links += &format!(r#"("{s}.scene", "all.{port}"),"#);
    }
    links += r#"("all.scene", "gbuffer.scene"),"#;
    if let Some(params) = reference {
        nodes += &format!(
            r#""reference": (kind: "ReferenceOcclusion", params: {{ {params} }}),
            "reference_out": (kind: "ImageWrite", params: {{ "format": "exr" }}),"#
        );
        links += r#"("all.scene", "reference.scene"), ("gbuffer.gbuffer", "reference.gbuffer"),
            ("reference.occlusion", "reference_out.image"),"#;
    }
    let text = format!("(version: 1, nodes: {{ {nodes} }}, links: [ {links} ])");
    Graph::load_str(&text, "ssao-test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// Mean, min and count of `values` over the pixels whose position passes `pick`.
fn stats(values: &[f32], pos: &[Option<Vec3>], pick: impl Fn(Vec3) -> bool) -> (f32, f32, usize) {
    let picked: Vec<f32> = values.iter().zip(pos).filter(|(_, p)| p.is_some_and(&pick)).map(|(v, _)| *v).collect();
    assert!(!picked.is_empty(), "no pixel picked");
    let mean = picked.iter().sum::<f32>() / picked.len() as f32;
    (mean, picked.iter().copied().fold(f32::INFINITY, f32::min), picked.len())
}

/// Prints the mean of `values` in bins of `dist` (0.01 wide) up to 0.15: the profile away
/// from an edge or corner, for the record.
fn profile(label: &str, values: &[f32], pos: &[Option<Vec3>], dist: impl Fn(Vec3) -> f32) {
    let mut bins = [(0.0f32, 0usize); 15];
    for (v, p) in values.iter().zip(pos) {
        let Some(p) = p else { continue };
        let b = (dist(*p) / 0.01) as usize;
        if b < bins.len() {
            bins[b].0 += v;
            bins[b].1 += 1;
        }
    }
    let text: Vec<String> =
        bins.iter().map(|(s, n)| if *n > 0 { format!("{:.3}", s / *n as f32) } else { "-".into() }).collect();
    eprintln!("{label}: {}", text.join(" "));
}

const MODES: [&str; 2] = ["sphere", "horizon"];

/// Both modes at full and half resolution.
fn variants() -> Vec<String> {
    let mut v = Vec::new();
    for mode in MODES {
        for half in [false, true] {
            v.push(format!(r#""mode": "{mode}", "half_resolution": {half}"#));
            if std::env::var("SSAO_RAW").is_ok() {
                v.push(format!(r#""mode": "{mode}", "half_resolution": {half}, "blur": false"#));
            }
        }
    }
    v
}

/// How far an edge or corner value may be from the analytic one: the 4x4 filter mixes in
/// pixels up to 2 pixels (4 at half resolution) from the line or point, where the factor is
/// already higher, and 16 samples per pixel leave noise where the filter has few neighbours.
fn tolerance(variant: &str) -> f32 {
    if variant.contains(r#""half_resolution": true"#) { 0.1 } else { 0.06 }
}

const SIZE: (u32, u32) = (160, 120);
/// Edges and corners: finer pixels, so some lie within 0.01 of the line or point.
const FINE: (u32, u32) = (320, 240);

#[test]
fn an_open_plane_is_unoccluded_in_both_modes() {
    for ssao in variants() {
        let g = graph(&[FLOOR], "", "", &[], r#""distance": 3.0, "pitch": 40.0, "yaw": 20.0"#, &ssao, None);
        let ev = run_graph(&g, SIZE.0, SIZE.1);
        let pos = world_positions(&ev, 15);
        let (mean, min, n) = stats(&channel0(&ev, "ssao", "occlusion"), &pos, |_| true);
        eprintln!("plane {ssao}: mean {mean:.4}, min {min:.4} over {n} pixels");
        assert!(n > 5000);
        // Sphere mode's estimate is unbiased at half the samples occluded, so its noise
        // straddles 1 and the clamp keeps the lower half: 1 within 0.02 (mean), 0.05 (any pixel).
        assert!(mean > 0.98 && min > 0.95, "{ssao}: an open plane gives mean {mean}, min {min} (expected 1)");
    }
}

/// Issue 34: the open floor stays unoccluded up to the screen's left and right borders, where
/// half of a sample sphere projects off screen (a band of 0.9 there before the fix).
#[test]
fn an_open_plane_stays_unoccluded_at_the_screen_borders() {
    for ssao in variants() {
        let ssao = format!(r#"{ssao}, "radius": 0.25"#);
        let g = graph(&[FLOOR], "", "", &[], r#""distance": 4.0, "pitch": 25.0, "yaw": 20.0"#, &ssao, None);
        let ev = run_graph(&g, SIZE.0, SIZE.1);
        let values = channel0(&ev, "ssao", "occlusion");
        let all = world_positions(&ev, 0);
        let band = SIZE.0 as usize / 10;
        let at_border: Vec<Option<Vec3>> = all
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let x = i % SIZE.0 as usize;
                if x < band || x >= SIZE.0 as usize - band { *p } else { None }
            })
            .collect();
        let (mean, _, n) = stats(&values, &at_border, |_| true);
        let low = values.iter().zip(&at_border).filter(|(v, p)| p.is_some() && **v < 0.95).count();
        eprintln!("borders {ssao}: mean {mean:.4}, {low} of {n} below 0.95");
        assert!(n > 1000);
        assert!(
            mean > 0.98 && low * 50 < n,
            "{ssao}: the open floor at the borders: mean {mean}, {low} of {n} pixels below 0.95"
        );
    }
}

/// The floor and the wall x = 0 seen from the open quarter space (x > 0, y > 0).
/// Edges and corners use a radius of 0.6 (the planes are 8 wide): 64 pixels at 320 x 240.
fn edge_values(ssao: &str) -> (f32, f32, usize) {
    let ssao = &format!(r#"{ssao}, "radius": 0.6"#);
    let g = graph(&[FLOOR, WALL_X], "", "", &[], r#""distance": 3.0, "pitch": 35.0, "yaw": 90.0"#, ssao, None);
    let ev = run_graph(&g, FINE.0, FINE.1);
    let pos = world_positions(&ev, 15);
    // Within 0.01 (1/30 of the radius) of the edge line, away from the planes' ends.
    let values = channel0(&ev, "ssao", "occlusion");
    profile(&format!("edge profile {ssao}"), &values, &pos, |p| if p.z.abs() < 0.8 { p.x.hypot(p.y) } else { 1.0 });
    stats(&values, &pos, |p| p.x.hypot(p.y) < 0.01 && p.z.abs() < 0.8)
}

#[test]
fn a_90_degree_concave_edge_gives_one_half_in_both_modes() {
    // Sphere mode: the solid fills 3/4 of the sample sphere, so 2 (1 - 3/4) = 1/2. Horizon
    // mode: the wall cuts the cosine-weighted hemisphere in half: 1/2 as well.
    let mut bad = Vec::new();
    for ssao in variants() {
        let (mean, min, n) = edge_values(&ssao);
        eprintln!("edge {ssao}: mean {mean:.4}, min {min:.4} over {n} pixels");
        assert!(n >= 10, "{ssao}: only {n} pixels on the edge");
        if (mean - 0.5).abs() >= tolerance(&ssao) {
            bad.push(format!("{ssao}: {mean}"));
        }
    }
    assert!(bad.is_empty(), "a concave edge does not give 0.5: {bad:?}");
}

#[test]
fn a_corner_gives_one_quarter_in_both_modes() {
    // Sphere mode: the solid fills 7/8 of the sphere, 2 (1 - 7/8) = 1/4. Horizon mode: an
    // octant is a quarter of the hemisphere, and symmetric about the normal: 1/4.
    let mut bad = Vec::new();
    for ssao in variants() {
        let camera = r#""distance": 3.0, "pitch": 35.26, "yaw": 45.0"#;
        let ssao = format!(r#"{ssao}, "radius": 0.6"#);
        let g = graph(&[FLOOR, WALL_X, WALL_Z], "", "", &[], camera, &ssao, None);
        let ev = run_graph(&g, FINE.0, FINE.1);
        let pos = world_positions(&ev, 15);
        let values = channel0(&ev, "ssao", "occlusion");
        profile(&format!("corner profile {ssao}"), &values, &pos, |p| p.length());
        let (mean, min, n) = stats(&values, &pos, |p| p.length() < 0.02);
        eprintln!("corner {ssao}: mean {mean:.4}, min {min:.4} over {n} pixels");
        if (mean - 0.25).abs() >= tolerance(&ssao) {
            bad.push(format!("{ssao}: {mean}"));
        }
    }
    assert!(bad.is_empty(), "a corner does not give 0.25: {bad:?}");
}

#[test]
fn a_convex_sphere_is_unoccluded_in_both_modes() {
    for ssao in variants() {
        let sphere = r#""ball": (kind: "Primitive", params: { "shape": "sphere", "radius": 0.6, "segments_u": 96, "segments_v": 48 }),
            "ball_draw": (kind: "Draw"),"#;
        let link = r#"("ball.mesh", "ball_draw.mesh"),"#;
        let g = graph(&[], sphere, link, &["ball_draw"], r#""distance": 3.0, "pitch": 20.0"#, &ssao, None);
        let ev = run_graph(&g, SIZE.0, SIZE.1);
        let pos = world_positions(&ev, 15);
        let values = channel0(&ev, "ssao", "occlusion");
        let (mean, min, n) = stats(&values, &pos, |_| true);
        eprintln!("sphere {ssao}: mean {mean:.4}, min {min:.4} over {n} pixels");
        assert!(n > 1000);
        // A few silhouette pixels see the background's missing depth and the sphere's far side.
        let low = values.iter().zip(&pos).filter(|(v, p)| p.is_some() && **v < 0.95).count();
        assert!(
            mean > 0.99 && min > 0.85 && low * 100 < n,
            "{ssao}: a convex sphere gives mean {mean}, min {min}, {low} of {n} pixels below 0.95 (expected 1)"
        );
    }
}

#[test]
fn ssao_is_deterministic_and_multiplies_an_image() {
    let ssao = r#""mode": "sphere""#;
    let g = graph(&[FLOOR, WALL_X], "", "", &[], r#""distance": 3.0, "pitch": 35.0, "yaw": 90.0"#, ssao, None);
    let a = channel0(&run_graph(&g, SIZE.0, SIZE.1), "ssao", "occlusion");
    let b = channel0(&run_graph(&g, SIZE.0, SIZE.1), "ssao", "occlusion");
    assert_eq!(a, b);
    // The G-buffer's colour times the factor.
    let mut g = g;
    g.links.push(werkstatt::core::graph::Link {
        from: werkstatt::core::graph::PortRef { node: "gbuffer".into(), port: "color".into() },
        to: werkstatt::core::graph::PortRef { node: "ssao".into(), port: "image".into() },
    });
    let ev = run_graph(&g, SIZE.0, SIZE.1);
    let color = read_back(gpu(), ev.output("gbuffer", "color").and_then(Value::as_texture).unwrap()).unwrap();
    let product = read_back(gpu(), ev.output("ssao", "image").and_then(Value::as_texture).unwrap()).unwrap();
    for (i, v) in a.iter().enumerate() {
        let want = color.rgba[i * 4] * v;
        assert!((product.rgba[i * 4] - want).abs() <= 2e-3 * want.max(1.0), "pixel {i}");
    }
}

/// The share of the cosine-weighted hemisphere at a point that a parallel square of half-size
/// `s` centred `h` above it covers (four corner rectangles of the unit form factor):
/// (4 / pi) A / sqrt(1 + A^2) atan(A / sqrt(1 + A^2)), A = s / h.
fn square_form_factor(s: f32, h: f32) -> f32 {
    let a = s / h;
    let k = a / (1.0 + a * a).sqrt();
    4.0 / std::f32::consts::PI * k * k.atan()
}

#[test]
fn reference_occlusion_matches_the_form_factor_of_a_square_and_one_on_a_plane() {
    assert!((square_form_factor(1e6, 1.0) - 1.0).abs() < 1e-4);
    let reference = r#""samples": 256, "max_distance": 2.0"#;
    // A plane alone: no ray can hit anything.
    let g = graph(&[FLOOR], "", "", &[], r#""distance": 3.0, "pitch": 40.0"#, "", Some(reference));
    let ev = run_graph(&g, 64, 48);
    let vis = channel0(&ev, "reference", "occlusion");
    assert!(vis.iter().all(|&v| v == 1.0), "an open plane is occluded somewhere");
    // A unit box whose bottom face is 0.5 above the floor, seen from low enough to see under it.
    let boxes = r#""cube": (kind: "Primitive", params: { "shape": "box", "size": 1.0 }),
        "cube_draw": (kind: "Draw", params: { "translate": [0.0, 1.0, 0.0] }),"#;
    let link = r#"("cube.mesh", "cube_draw.mesh"),"#;
    let camera = r#""distance": 3.0, "pitch": 8.0, "fov": 30.0"#;
    let g = graph(&[FLOOR], boxes, link, &["cube_draw"], camera, "", Some(reference));
    let ev = run_graph(&g, 160, 120);
    let pos = world_positions(&ev, 15);
    let vis = channel0(&ev, "reference", "occlusion");
    let want = 1.0 - square_form_factor(0.5, 0.5);
    let (mean, _, n) = stats(&vis, &pos, |p| p.y.abs() < 1e-3 && p.x.hypot(p.z) < 0.05);
    eprintln!("under the box: {mean:.4} over {n} pixels, expected {want:.4}");
    assert!((mean - want).abs() < 0.02, "under the box {mean}, expected {want}");
    // The same point traced directly, with many rays.
    let scene = match ev.output("all", "scene") {
        Some(Value::Scene(s)) => s.clone(),
        _ => panic!("no scene"),
    };
    let bvh = SceneBvh::new(&scene);
    assert_eq!(bvh.triangle_count(), 2 + 12);
    let v = bvh.visibility(Vec3::ZERO, Vec3::Y, 16384, 2.0, 1);
    eprintln!("at the origin: {v:.4}, expected {want:.4}");
    assert!((v - want).abs() < 0.005, "at the origin {v}, expected {want}");
    // Only the bottom face is within reach: with max_distance below 0.5 nothing occludes.
    assert_eq!(bvh.visibility(Vec3::ZERO, Vec3::Y, 4096, 0.45, 1), 1.0);
}

#[test]
fn reference_occlusion_is_deterministic() {
    let reference = r#""samples": 32, "max_distance": 1.0, "seed": 7"#;
    let g = graph(
        &[FLOOR, WALL_X, WALL_Z],
        "",
        "",
        &[],
        r#""distance": 3.0, "pitch": 35.26, "yaw": 45.0"#,
        "",
        Some(reference),
    );
    let a = channel0(&run_graph(&g, 64, 48), "reference", "occlusion");
    let b = channel0(&run_graph(&g, 64, 48), "reference", "occlusion");
    assert_eq!(a, b, "the same input gave different values");
    assert!(a.iter().any(|&v| v < 0.5), "the corner is not occluded");
    let mut g = g;
    g.nodes.get_mut("reference").unwrap().params.insert("seed".into(), werkstatt::core::param::ParamValue::Int(8));
    let c = channel0(&run_graph(&g, 64, 48), "reference", "occlusion");
    assert_ne!(a, c, "the seed changes nothing");
}

#[test]
fn fig5_25_graph_ssao_is_closer_to_the_ray_traced_reference_than_no_occlusion() {
    let out = out_dir("ssao_fig5_25");
    let (w, h) = (320, 240);
    render_graph(&root().join("graphs/fig5_25_occlusion.ron"), &out, (0, 0), (w, h), &[], &[]).unwrap();
    let reference = read_exr(&out.join("ray_traced_0000.exr"));
    let mse = |name: &str| -> f64 {
        let img = read_exr(&out.join(format!("{name}_0000.exr")));
        let sum: f64 = img
            .rgba
            .chunks_exact(4)
            .zip(reference.rgba.chunks_exact(4))
            .map(|(a, b)| ((a[0] - b[0]) as f64).powi(2))
            .sum();
        sum / (w * h) as f64
    };
    let none: f64 = reference.rgba.chunks_exact(4).map(|b| ((1.0 - b[0]) as f64).powi(2)).sum::<f64>() / (w * h) as f64;
    let (sphere, horizon) = (mse("local"), mse("local_horizon"));
    eprintln!("MSE against the reference: no occlusion {none:.5}, sphere {sphere:.5}, horizon {horizon:.5}");
    assert!(none > 1e-3, "the reference shows no occlusion");
    assert!(sphere < none && horizon < none, "SSAO is farther from the reference than no occlusion at all");
}

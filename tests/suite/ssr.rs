//! `ScreenSpaceReflections` (issue 34): a glossy white sphere above a lit white floor under a
//! probe whose sky is bright and whose ground is dark. IblShading alone makes the sphere's
//! lower part reflect the probe's dark ground; with the node it reflects the floor, about
//! albedo x the floor's radiance. Where every ray leaves the screen (the sphere alone) the
//! environment fallback returns IblShading's image, rescaled only by what the GGX lobe reads of
//! the probe against IblShading's Phong lobe; at or below the glossiness threshold the image is
//! unchanged.

use glam::Vec3;
use werkstatt::core::graph::Graph;
use werkstatt::core::port::Value;

use crate::common::*;

const SIZE: (u32, u32) = (160, 120);
const CENTRE: Vec3 = Vec3::new(0.0, 0.5, 0.0);
const RADIUS: f32 = 0.3;
const SPHERE_ALBEDO: f32 = 0.8;

fn graph(probe: &std::path::Path, floor: bool, glossiness: f32) -> Graph {
    graph_lit_by(probe, floor, glossiness, "light.image", false)
}

/// `graph` with `image` (a texture output) as the node's lit image, and with `ground` the
/// node's hidden ground at y = 0 (albedo 0.5) lit by 16 median-cut lights.
fn graph_lit_by(probe: &std::path::Path, floor: bool, glossiness: f32, image: &str, ground: bool) -> Graph {
    let text = graph_text(probe, floor, glossiness, image, ground);
    Graph::load_str(&text, "ssr-test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

/// The text of `graph_lit_by`'s graph.
fn graph_text(probe: &std::path::Path, floor: bool, glossiness: f32, image: &str, ground: bool) -> String {
    let (ssr_params, count, ground_link) = if ground {
        (
            r#"params: { "ground": true, "ground_height": 0.0, "ground_albedo": [0.5, 0.5, 0.5] }"#,
            16,
            r#"("cut.lights", "ssr.lights"),"#,
        )
    } else {
        ("", 1, "")
    };
    let floor_nodes = if floor {
        r#""plane": (kind: "Primitive", params: { "shape": "plane", "size": 8.0, "segments_u": 1, "segments_v": 1 }),
        "white": (kind: "Material", params: { "base_color": [0.5, 0.5, 0.5], "glossiness": 0.0 }),
        "floor": (kind: "Draw"),"#
    } else {
        ""
    };
    let floor_links = if floor {
        r#"("plane.mesh", "floor.mesh"), ("white.material", "floor.material"), ("floor.scene", "all.b"),"#
    } else {
        ""
    };
    format!(
        r#"(version: 2, nodes: {{
        "sphere": (kind: "Primitive", params: {{ "shape": "sphere", "radius": {RADIUS:?} }}),
        "glossy": (kind: "Material", params: {{ "base_color": [{SPHERE_ALBEDO:?}, {SPHERE_ALBEDO:?}, {SPHERE_ALBEDO:?}], "glossiness": {glossiness:?} }}),
        "ball": (kind: "Draw", params: {{ "translate": [{}, {}, {}] }}),
        {floor_nodes}
        "all": (kind: "Merge"),
        "camera": (kind: "OrbitCamera", params: {{ "distance": 3.0, "pitch": 10.0, "yaw": 0.0, "target": [0.0, 0.4, 0.0] }}),
        "gbuffer": (kind: "GBufferPass"),
        "environment": (kind: "EnvironmentMap", params: {{ "path": {probe:?}, "size": 32 }}),
        "cut": (kind: "MedianCut", params: {{ "count": {count} }}),
        "pems": (kind: "Pems"),
        "light": (kind: "IblShading", params: {{ "mode": "full" }}),
        "ssr": (kind: "ScreenSpaceReflections", {ssr_params}),
        "out": (kind: "Preview"),
    }}, links: [
        ("sphere.mesh", "ball.mesh"), ("glossy.material", "ball.material"), ("ball.scene", "all.a"),
        {floor_links}
        ("all.scene", "gbuffer.scene"), ("camera.camera", "gbuffer.camera"),
        ("environment.environment", "cut.environment"), ("environment.environment", "pems.environment"),
        ("cut.lights", "pems.lights"), ("pems.pems", "light.pems"), ("gbuffer.gbuffer", "light.gbuffer"),
        ("gbuffer.gbuffer", "ssr.gbuffer"), ("{image}", "ssr.image"), ("environment.environment", "ssr.environment"),
        ("ssr.image", "out.image"), {ground_link}
    ])"#,
        CENTRE.x, CENTRE.y, CENTRE.z
    )
}

/// Sky 1 above the horizon, ground 0.05 below.
fn probe(name: &str) -> std::path::PathBuf {
    let path = out_dir(name).join("probe.hdr");
    write_probe(&path, 32, 16, |_, y| if y < 8 { Vec3::ONE } else { Vec3::splat(0.05) });
    path
}

fn rgb(ev: &werkstatt::core::eval::Evaluator, node: &str) -> Vec<Vec3> {
    let value = ev.output(node, "image").and_then(Value::as_texture).expect("a texture");
    werkstatt::gpu::read_back(gpu(), value).unwrap().rgba.chunks_exact(4).map(|c| Vec3::new(c[0], c[1], c[2])).collect()
}

fn eye(ev: &werkstatt::core::eval::Evaluator) -> Vec3 {
    match ev.output("gbuffer", "gbuffer") {
        Some(Value::GBuffer(g)) => g.view.eye,
        _ => panic!("no G-buffer"),
    }
}

fn mean(v: impl Iterator<Item = Vec3>) -> Vec3 {
    let (sum, n) = v.fold((Vec3::ZERO, 0), |(s, n), x| (s + x, n + 1));
    sum / n.max(1) as f32
}

/// The sphere's pixels whose mirror direction points well down (at the floor), away from the
/// silhouette (whose 4x4 tile mixes in the floor).
fn lower_sphere(eye: Vec3, pos: &[Option<Vec3>]) -> Vec<usize> {
    let down = |p: Vec3| {
        let n = (p - CENTRE).normalize();
        let v = (p - eye).normalize();
        (p - CENTRE).length() < RADIUS * 1.05 && (v - 2.0 * v.dot(n) * n).y < -0.5 && -v.dot(n) > 0.4
    };
    (0..pos.len()).filter(|&i| pos[i].is_some_and(down)).collect()
}

#[test]
fn a_glossy_sphere_reflects_the_lit_floor_below_it() {
    let ev = run_graph(&graph(&probe("ssr_floor"), true, 0.95), SIZE.0, SIZE.1);
    let (eye, pos) = (eye(&ev), world_positions(&ev, 5));
    let (lit, out) = (rgb(&ev, "light"), rgb(&ev, "ssr"));
    let sphere = lower_sphere(eye, &pos);
    let floor: Vec<usize> = (0..pos.len()).filter(|&i| pos[i].is_some_and(|p| p.y.abs() < 1e-3)).collect();
    assert!(sphere.len() > 30 && floor.len() > 1000, "{} sphere, {} floor pixels", sphere.len(), floor.len());
    let floor_radiance = mean(floor.iter().map(|&i| lit[i]));
    let floor_out = mean(floor.iter().map(|&i| out[i]));
    let (before, after) = (mean(sphere.iter().map(|&i| lit[i])), mean(sphere.iter().map(|&i| out[i])));
    let expected = SPHERE_ALBEDO * floor_radiance;
    eprintln!("floor {floor_radiance}; lower sphere: without {before}, with {after}, albedo x floor {expected}");
    assert_eq!(floor_radiance, floor_out, "the floor (glossiness 0) changed");
    assert!(before.x < 0.3 * expected.x, "without reflections the sphere should show the dark ground: {before}");
    assert!(
        after.x > 0.9 * expected.x && after.x < 1.05 * expected.x,
        "the sphere's lower part should reflect the floor: {after} against {expected}"
    );
    assert!(out.iter().all(|c| c.is_finite()), "non-finite output");
}

/// The hidden ground: no floor is drawn, but the node's ground plane at y = 0 (albedo 0.5, lit
/// by 16 median-cut lights of a sky of radiance 1, so about 0.5 * pi / pi = 0.5) is what the
/// sphere's lower part reflects instead of the probe's dark ground (0.05).
#[test]
fn the_hidden_ground_is_reflected_where_the_screen_shows_no_floor() {
    let ev = run_graph(&graph_lit_by(&probe("ssr_floor"), false, 0.95, "light.image", true), SIZE.0, SIZE.1);
    let (eye, pos) = (eye(&ev), world_positions(&ev, 5));
    let (lit, out) = (rgb(&ev, "light"), rgb(&ev, "ssr"));
    let sphere = lower_sphere(eye, &pos);
    let (before, after) = (mean(sphere.iter().map(|&i| lit[i])), mean(sphere.iter().map(|&i| out[i])));
    let expected = SPHERE_ALBEDO * 0.5;
    eprintln!("hidden ground: lower sphere without {before}, with {after}, albedo x 0.5 = {expected}");
    assert!(sphere.len() > 30, "{} sphere pixels", sphere.len());
    assert!(before.x < 0.3 * expected, "without the ground the sphere should show the dark ground: {before}");
    assert!(
        after.x > 0.85 * expected && after.x < 1.15 * expected,
        "the sphere's lower part should reflect the ground: {after} against {expected}"
    );
    // A ground without its lights is an error naming both.
    let text = graph_text(&probe("ssr_floor"), false, 0.95, "light.image", true)
        .replace(r#"("cut.lights", "ssr.lights"),"#, "");
    let ev = evaluate_graph(&Graph::load_str(&text, "ssr-no-lights.ron".as_ref()).unwrap(), SIZE.0, SIZE.1);
    match &ev.report("ssr").unwrap().status {
        werkstatt::core::eval::NodeStatus::Failed(m) => {
            assert!(m.contains("\"ground\"") && m.contains("\"lights\""), "{m}")
        }
        other => panic!("a ground without lights was accepted: {other:?}"),
    }
}

#[test]
fn escaped_rays_keep_the_image_up_to_the_lobes_shape_and_low_glossiness_keeps_it() {
    // The sphere alone: every ray leaves for the background, the environment answers them all.
    // Under a uniform probe the GGX lobe reads what IblShading's Phong lobe read: no change.
    let uniform = out_dir("ssr_uniform").join("probe.hdr");
    write_probe(&uniform, 32, 16, |_, _| Vec3::splat(0.5));
    let ev = run_graph(&graph(&uniform, false, 0.95), SIZE.0, SIZE.1);
    let (lit, out) = (rgb(&ev, "light"), rgb(&ev, "ssr"));
    let change = |a: &Vec3, b: &Vec3| ((*b - *a) / a.max(Vec3::splat(1e-3))).abs().max_element();
    let worst = lit.iter().zip(&out).map(|(a, b)| change(a, b)).fold(0.0, f32::max);
    assert!(worst < 0.01, "an open scene under a uniform probe changed by {:.3}%", 100.0 * worst);
    // Under the bright sky and dark ground: where the mirror direction points well up (away
    // from the silhouette) both lobes see sky but for the GGX lobe's longer tails (a few
    // percent); towards the silhouette the Phong lobe dips under the horizon into the dark
    // ground, which the GGX lobe does not reflect, so the sphere brightens there (by 6%
    // on average where n.v < 0.3).
    let probe = probe("ssr_open");
    let ev = run_graph(&graph(&probe, false, 0.95), SIZE.0, SIZE.1);
    let (lit, out, pos, eye) = (rgb(&ev, "light"), rgb(&ev, "ssr"), world_positions(&ev, 5), eye(&ev));
    let up = |p: Vec3| {
        let (n, v) = ((p - CENTRE).normalize(), (p - eye).normalize());
        (v - 2.0 * v.dot(n) * n).y > 0.7 && -v.dot(n) > 0.5
    };
    let top: Vec<usize> = (0..pos.len()).filter(|&i| pos[i].is_some_and(up)).collect();
    assert!(top.len() > 20, "{} top pixels", top.len());
    let worst_top = top.iter().map(|&i| change(&lit[i], &out[i])).fold(0.0, f32::max);
    assert!(worst_top < 0.05, "the sphere's top changed by {:.3}%", 100.0 * worst_top);
    let rim = |p: Vec3| -(p - eye).normalize().dot((p - CENTRE).normalize()) < 0.3;
    let silhouette: Vec<usize> = (0..pos.len()).filter(|&i| pos[i].is_some_and(rim)).collect();
    let (before, after) = (mean(silhouette.iter().map(|&i| lit[i])), mean(silhouette.iter().map(|&i| out[i])));
    assert!(
        silhouette.len() > 20 && after.x > 1.04 * before.x,
        "{} silhouette pixels: {before} -> {after}",
        silhouette.len()
    );
    // Glossiness at the threshold (0.3): nothing changes, floor or sphere.
    let ev = run_graph(&graph(&probe, true, 0.3), SIZE.0, SIZE.1);
    assert_eq!(rgb(&ev, "light"), rgb(&ev, "ssr"), "glossiness 0.3 changed the image");
}

#[test]
fn an_image_of_another_size_than_the_gbuffer_is_refused() {
    use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
    // The probe's preview (64x32) as the lit image of a 160x120 G-buffer.
    let graph = graph_lit_by(&probe("ssr_size"), true, 0.95, "environment.preview", false);
    let mut ev = Evaluator::new(&graph, &[]).unwrap();
    let res = werkstatt::core::resources::Resources::new(false);
    let settings = FrameSettings { width: SIZE.0, height: SIZE.1, base_dir: root(), frames: None };
    while ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, Some(gpu()), &res, &settings).pending > 0 {
        wait_idle(&res);
    }
    match &ev.report("ssr").unwrap().status {
        NodeStatus::Failed(m) => assert!(m.contains("\"image\" is 64x32") && m.contains("160x120"), "{m}"),
        other => panic!("a 64x32 image on a 160x120 G-buffer was accepted: {other:?}"),
    }
}

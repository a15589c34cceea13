//! `Bounce` (issue 34): one bounce of diffuse light in screen space, on a white floor beside a
//! red wall under a uniform sky. The wall sends red light only, so the floor near it gains red
//! and nothing else, about albedo_wall x F of its own radiance, F the cosine-weighted fraction
//! of the floor point's hemisphere the wall fills within the radius (at most 1/2); the floor
//! farther than the radius gains nothing; a floor alone (coplanar senders) gains nothing.

use glam::Vec3;
use werkstatt::core::graph::Graph;
use werkstatt::core::port::Value;

use crate::common::*;

const SIZE: (u32, u32) = (160, 120);
const RADIUS: f32 = 0.5;

fn graph(probe: &std::path::Path, wall: bool, strength: f32) -> Graph {
    let wall_nodes = if wall {
        r#""red": (kind: "Material", params: { "base_color": [0.8, 0.0, 0.0], "glossiness": 0.0 }),
        "wall": (kind: "Draw", params: { "translate": [0.0, 4.0, 0.0], "rotate": [0.0, 0.0, -90.0] }),"#
    } else {
        ""
    };
    let wall_links = if wall {
        r#"("plane.mesh", "wall.mesh"), ("red.material", "wall.material"), ("wall.scene", "all.b"),"#
    } else {
        ""
    };
    let text = format!(
        r#"(version: 2, nodes: {{
        "plane": (kind: "Primitive", params: {{ "shape": "plane", "size": 8.0, "segments_u": 1, "segments_v": 1 }}),
        "white": (kind: "Material", params: {{ "base_color": [0.5, 0.5, 0.5], "glossiness": 0.0 }}),
        "floor": (kind: "Draw"),
        {wall_nodes}
        "all": (kind: "Merge"),
        "camera": (kind: "OrbitCamera", params: {{ "distance": 3.0, "pitch": 35.0, "yaw": 90.0 }}),
        "gbuffer": (kind: "GBufferPass"),
        "environment": (kind: "EnvironmentMap", params: {{ "path": {probe:?}, "size": 16 }}),
        "cut": (kind: "MedianCut", params: {{ "count": 1 }}),
        "pems": (kind: "Pems"),
        "light": (kind: "IblShading", params: {{ "mode": "full" }}),
        "bounce": (kind: "Bounce", params: {{ "radius": {RADIUS:?}, "strength": {strength:?} }}),
        "out": (kind: "Preview"),
    }}, links: [
        ("plane.mesh", "floor.mesh"), ("white.material", "floor.material"), ("floor.scene", "all.a"),
        {wall_links}
        ("all.scene", "gbuffer.scene"), ("camera.camera", "gbuffer.camera"),
        ("environment.environment", "cut.environment"), ("environment.environment", "pems.environment"),
        ("cut.lights", "pems.lights"), ("pems.pems", "light.pems"), ("gbuffer.gbuffer", "light.gbuffer"),
        ("gbuffer.gbuffer", "bounce.gbuffer"), ("light.image", "bounce.image"), ("bounce.image", "out.image"),
    ])"#
    );
    Graph::load_str(&text, "bounce-test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

fn rgb(ev: &werkstatt::core::eval::Evaluator, node: &str) -> Vec<Vec3> {
    let value = ev.output(node, "image").and_then(Value::as_texture).expect("a texture");
    werkstatt::gpu::read_back(gpu(), value).unwrap().rgba.chunks_exact(4).map(|c| Vec3::new(c[0], c[1], c[2])).collect()
}

/// Per floor pixel picked by `pick` (world position): the image before and after the bounce.
fn floor_pixels(ev: &werkstatt::core::eval::Evaluator, pick: impl Fn(Vec3) -> bool) -> Vec<(Vec3, Vec3)> {
    let pos = world_positions(ev, 5);
    let (lit, bounced) = (rgb(ev, "light"), rgb(ev, "bounce"));
    pos.iter()
        .zip(lit.iter().zip(&bounced))
        .filter(|(p, _)| p.is_some_and(|p| p.y.abs() < 1e-3 && p.z.abs() < 1.0 && pick(p)))
        .map(|(_, (a, b))| (*a, *b))
        .collect()
}

#[test]
fn a_red_wall_reddens_the_floor_beside_it_and_only_within_the_radius() {
    let out = out_dir("bounce");
    let probe = out.join("sky.hdr");
    write_probe(&probe, 32, 16, |_, _| Vec3::ONE);
    let ev = run_graph(&graph(&probe, true, 1.0), SIZE.0, SIZE.1);
    let near = floor_pixels(&ev, |p| p.x > 0.03 && p.x < 0.1);
    let far = floor_pixels(&ev, |p| p.x > 1.5 * RADIUS && p.x < 1.5);
    assert!(near.len() > 20 && far.len() > 200, "{} near, {} far", near.len(), far.len());
    let gain = |pixels: &[(Vec3, Vec3)]| {
        let (a, b) = pixels.iter().fold((Vec3::ZERO, Vec3::ZERO), |(a, b), (x, y)| (a + *x, b + *y));
        (b - a) / a
    };
    let (near_gain, far_gain) = (gain(&near), gain(&far));
    eprintln!("relative gain near the wall {near_gain}, beyond the radius {far_gain}");
    // Red only, about 0.8 F with F just under 1/2 this close to the wall.
    assert!((0.15..0.45).contains(&near_gain.x), "the red the wall sends: {near_gain}");
    assert!(near_gain.y.abs() < 1e-3 && near_gain.z.abs() < 1e-3, "a red wall sent green or blue: {near_gain}");
    assert!(far_gain.abs().max_element() < 1e-3, "light travelled beyond the radius: {far_gain}");
}

#[test]
fn a_lone_floor_gains_nothing_and_strength_zero_changes_nothing() {
    let out = out_dir("bounce_floor");
    let probe = out.join("sky.hdr");
    write_probe(&probe, 32, 16, |_, _| Vec3::ONE);
    let ev = run_graph(&graph(&probe, false, 1.0), SIZE.0, SIZE.1);
    let worst =
        floor_pixels(&ev, |_| true).iter().map(|(a, b)| ((*b - *a) / *a).abs().max_element()).fold(0.0, f32::max);
    assert!(worst < 1e-3, "coplanar senders lit the floor: {worst}");
    let ev = run_graph(&graph(&probe, true, 0.0), SIZE.0, SIZE.1);
    assert_eq!(rgb(&ev, "light"), rgb(&ev, "bounce"), "strength 0 changed the image");
}

//! `WovenCloth` (Zhang et al. 2012, IDSS; src/woven/): its items export exactly the triangles the
//! CPU evaluation gives, and bad parameters fail with the port named.

use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
use werkstatt::core::graph::Graph;
use werkstatt::core::port::Value;
use werkstatt::mesh::has_area;
use werkstatt::nodes::mesh::geometry::plane;
use werkstatt::render::draw::kinds::woven::WovenLayer;
use werkstatt::woven::lod::Morph;
use werkstatt::woven::panel::Panel;
use werkstatt::woven::resample::resample;
use werkstatt::woven::tess::Woven;
use werkstatt::woven::weave::Weave;
use werkstatt::woven::yarn::YarnParams;

use crate::common::{gpu, root};

const GRAPH: &str = r#"(version: 1, nodes: {
    "plane": (kind: "Primitive", params: {"shape": "plane", "size": 2.0, "segments_u": 4, "segments_v": 4}),
    "woven": (kind: "WovenCloth", params: {"weave": "twill", "nodes": 8, "spacing": 0.125, "crimp": 0.03,
        "radius": 0.03, "level": 7.5, "fibres": 3}),
    "camera": (kind: "OrbitCamera", params: {"distance": 3.0}),
    "out": (kind: "ExportGeometry", params: {}),
}, links: [("plane.mesh", "woven.surface"), ("woven.scene", "out.scene")])"#;

fn evaluate(text: &str, overrides: &[(&str, &str)]) -> Evaluator {
    let mut text = text.to_string();
    for (from, to) in overrides {
        assert!(text.contains(from), "{from}");
        text = text.replace(from, to);
    }
    let graph = Graph::load_str(&text, "woven.ron".as_ref()).unwrap();
    let mut ev = Evaluator::new(&graph, &[]).unwrap();
    let resources = werkstatt::core::resources::Resources::new(false);
    let settings = FrameSettings { width: 64, height: 64, base_dir: root(), frames: None };
    ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, Some(gpu()), &resources, &settings);
    ev
}

#[test]
fn a_woven_item_exports_the_triangles_the_cpu_evaluation_gives() {
    let ev = evaluate(GRAPH, &[]);
    let status = ev.report("out").map(|r| r.status.clone());
    assert!(matches!(status, Some(NodeStatus::Ok)), "{status:?}");
    let (Some(Value::Mesh(exported)), Some(Value::Scene(items))) =
        (ev.output("out", "mesh").cloned(), ev.output("woven", "scene").cloned())
    else {
        panic!("no export")
    };
    // Level 7.5 everywhere: yarns only, wefts and warps.
    let kinds: Vec<&str> = items.iter().map(|i| i.kind_as::<WovenLayer>().expect("a woven item").layer).collect();
    assert_eq!(kinds, ["weft", "warp"]);
    assert_eq!(items[0].kind_as::<WovenLayer>().unwrap().scales, [0, 4, 0]);

    // The same cloth evaluated here: the plane resampled into 2x2 patches of 8 x 0.125.
    let surface = plane(2.0, 4, 4).unwrap();
    let grids = resample(&surface, 1.0).unwrap();
    assert_eq!(grids.len(), 1);
    let panel = Panel { flip: grids[0].flipped, ..Panel::new(&grids[0].grid) };
    assert_eq!((panel.patches_u, panel.patches_v), (2, 2));
    let weave = Weave::twill(2, 1).unwrap();
    let yarn =
        YarnParams { nodes: 8, spacing: 0.125, crimp: 0.03, radius: 0.03, fibres: 3, migration: 0.3, twist: 0.5 };
    let woven = Woven { panel: &panel, weave: &weave, yarn: &yarn, morph: Morph::Continuous };
    let t = woven.tessellate(&[Some(7.5); 4]).unwrap();
    let (mut positions, mut indices) = (Vec::new(), Vec::new());
    for layer in [&t.weft, &t.warp] {
        let base = positions.len() as u32;
        positions.extend(layer.positions.iter().map(|p| p.as_vec3()));
        indices.extend(layer.indices.iter().map(|i| i + base));
    }
    let kept: Vec<u32> =
        indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).filter(|&t| has_area(&positions, t)).flatten().collect();
    assert_eq!(exported.positions.len(), positions.len());
    let worst = exported.positions.iter().zip(&positions).map(|(a, b)| a.distance(*b)).fold(0.0, f32::max);
    assert!(worst < 1e-6, "exported vertices differ from the CPU evaluation by up to {worst}");
    assert_eq!(exported.indices, kept);
    // 8x8 nodes per patch at level 7: 2 x 8 yarns x 16 segments x 4 around x 2 triangles.
    assert_eq!(t.triangles(), 4 * 2 * 8 * 16 * 4 * 2);
}

#[test]
fn bad_parameters_fail_naming_the_port() {
    for (overrides, port, words) in [
        (vec![(r#""spacing": 0.125"#, r#""spacing": 0.0"#)], "spacing", "positive"),
        (vec![(r#""level": 7.5"#, r#""level": 40.0"#)], "level", "above the finest level"),
        (vec![(r#""weave": "twill""#, r#""weave": "custom", "pattern": " / ""#)], "pattern", "empty"),
        (vec![(r#""weave": "twill""#, r#""weave": "custom", "pattern": "10/2""#)], "pattern", "only 0"),
        (vec![(r#""weave": "twill""#, r#""weave": "satin", "satin_n": 6"#)], "satin_n", "no regular satin"),
        (vec![(r#""level": 7.5"#, r#""level": -1.0"#)], "camera", "need a camera"),
        (vec![(r#""level": 7.5"#, r#""level": 14.0, "max_triangles": 100000"#)], "level", "more than max_triangles"),
    ] {
        let ev = evaluate(GRAPH, &overrides);
        let status = ev.report("woven").map(|r| r.status.clone());
        let Some(NodeStatus::Failed(msg)) = status else { panic!("{overrides:?}: {status:?}") };
        assert!(msg.contains(&format!("port \"{port}\"")) && msg.contains(words), "{overrides:?}: {msg}");
    }
    // With a camera, adaptive levels work: the nearer patches get the higher levels.
    let text = GRAPH.replace(
        r#"("woven.scene", "out.scene")"#,
        r#"("woven.scene", "out.scene"), ("camera.camera", "woven.camera")"#,
    );
    let ev = evaluate(&text, &[(r#""level": 7.5"#, r#""level": -1.0, "lod_c": 0.1"#)]);
    assert!(matches!(ev.report("woven").map(|r| r.status.clone()), Some(NodeStatus::Ok)));
}

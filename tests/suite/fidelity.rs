//! werkstatt against Blender Cycles (issue 34, docs/fidelity.md), without Blender: the default
//! graph's scene rendered by werkstatt at 320x240 and measured against the Cycles renders
//! committed under tests/data/fidelity/ (made by `werkstatt fidelity export` and
//! tools/fidelity/cycles.py, 1024 samples). The bounds are today's figures with a small margin,
//! so a change that moves the image away from the path tracer fails here; tighten them as the
//! renderer gets closer (the aims of issue 34: relative MAE 5% or less, each region ratio
//! within 0.05 of Cycles, a glossy ball within 10%).

use werkstatt::app::fidelity::metrics::read_exr;
use werkstatt::app::fidelity::{ExportOptions, Metrics, SceneInfo, capture, measure};

use crate::common::{gpu, root};

/// Renders the committed case's graph (its --set overrides) and measures it against its
/// Cycles image; checks first that the scene is the one Cycles rendered.
fn measure_case(case: &str) -> Metrics {
    measure_graph(case, None)
}

/// `measure_case` with another graph (the case's scene with other nodes after the lighting).
fn measure_graph(case: &str, graph: Option<&str>) -> Metrics {
    let dir = root().join("tests/data/fidelity").join(case);
    let committed = SceneInfo::load(&dir.join("scene.json")).unwrap();
    let opts = ExportOptions {
        graph_path: root().join(graph.unwrap_or(&committed.graph)),
        sets: committed.sets.clone(),
        unlinks: committed.unlinks.clone(),
        frame: committed.frame,
        fps: committed.fps,
        width: committed.width,
        height: committed.height,
    };
    let cap = capture(&opts, gpu()).unwrap();
    let scene = &cap.scene;
    // A changed camera, item list or geometry makes the committed render stale: re-export and
    // re-render (docs/fidelity.md) rather than compare different scenes.
    assert_eq!(scene.camera, committed.camera, "{case}: the camera changed since the Cycles render");
    let shape = |s: &SceneInfo| s.items.iter().map(|i| (i.name.clone(), i.triangles)).collect::<Vec<_>>();
    assert_eq!(shape(scene), shape(&committed), "{case}: the scene's items changed since the Cycles render");
    for (a, b) in scene.items.iter().zip(&committed.items) {
        let close = |x: [f32; 3], y: [f32; 3]| x.iter().zip(&y).all(|(p, q)| (p - q).abs() < 1e-4);
        assert!(
            close(a.bounds_min, b.bounds_min) && close(a.bounds_max, b.bounds_max),
            "{case}: item {} moved",
            a.name
        );
        assert_eq!(
            (a.base_color, a.glossiness),
            (b.base_color, b.glossiness),
            "{case}: item {} changed material",
            a.name
        );
    }
    assert!(
        scene.ids_gbuffer_mismatch.unwrap() < 0.005,
        "{case}: the ray-cast ids disagree with the G-buffer on {:.2}% of the pixels",
        100.0 * scene.ids_gbuffer_mismatch.unwrap()
    );
    let cycles = read_exr(&dir.join("cycles.exr")).unwrap();
    let m = measure(scene, &cap.ids, &cap.image, &cycles).unwrap();
    println!("{case}:\n{}", m.table());
    m
}

fn region<'a>(m: &'a Metrics, name: &str) -> &'a werkstatt::app::fidelity::metrics::RegionRatio {
    m.regions.iter().find(|r| r.name == name).unwrap_or_else(|| panic!("no region {name}"))
}

fn item<'a>(m: &'a Metrics, name: &str) -> &'a werkstatt::app::fidelity::metrics::ItemError {
    m.items.iter().find(|i| i.name == name).unwrap_or_else(|| panic!("no item {name}"))
}

#[test]
fn the_default_scene_is_no_farther_from_cycles_than_today() {
    let m = measure_case("default_lambert");
    // The Cycles far floor is the probe's analytic open-floor value less what the objects
    // hide of the sky: a check of the reference itself.
    let analytic = m.open_floor_analytic.unwrap() as f64;
    assert!((m.far_floor_cycles / analytic - 1.0).abs() < 0.05, "far floor {} against {analytic}", m.far_floor_cycles);
    // Today (docs/fidelity.md, "after"; 10.0% before the shadow atlas fitted its tiles to the
    // view and sized them by penumbra and SSAO mirrored off-screen samples, 8.0% before the
    // PEMs' diffuse ends, 6.9% before the default graph's narrower atlas blur, lower
    // bleed reduction and smaller SSAO radius, 5.7% with 16 lights before 22): relative MAE
    // 4.7%, under the aim of 5%, which is the bound.
    assert!(m.rel_mae < 0.05, "relative MAE {:.1}% (today 4.7%, aim 5%)", 100.0 * m.rel_mae);
    for (name, today) in [("torus", 0.124), ("floor", 0.029), ("ball", 0.110)] {
        let e = item(&m, name).rel_mae;
        assert!(e < today + 0.01, "{name}: relative MAE {:.1}% (today {:.1}%)", 100.0 * e, 100.0 * today);
    }
    // The open floor: the diffuse ends give it the probe's irradiance (3.8% under the
    // analytic value before, with IBL alone); Cycles' far floor still has a little occlusion.
    // Today 1.0% under Cycles' (0.3% against the render before the checker was filtered in
    // linear values on both sides, which moved Cycles' floor and its noise).
    let floor = m.far_floor_werkstatt / m.far_floor_cycles;
    assert!(
        (floor - 1.0).abs() < 0.015,
        "far floor: werkstatt {:.4} against Cycles {:.4}",
        m.far_floor_werkstatt,
        m.far_floor_cycles
    );
    // Region ratios: werkstatt's distance from Cycles within the aim, 0.05 (the ball's
    // sun shadow was 0.153 apart, under the ball 0.080, behind the torus 0.054 before the
    // narrower blur; the ball's shadow 0.091 with 16 lights).
    let today = [("under ball", 0.019), ("under torus", 0.002), ("shadow of torus", 0.017), ("shadow of ball", 0.024)];
    for (name, today) in today {
        let r = region(&m, name);
        let d = (r.werkstatt - r.cycles).abs();
        assert!(d < 0.05, "{name}: werkstatt {:.3} against Cycles {:.3} (today {today} apart)", r.werkstatt, r.cycles);
    }
    // SSAO's bands at the screen's left and right edges: open floor darker than Cycles' by
    // more than 5%, pixel by pixel (each image over its far floor's mean). 19.5% before SSAO
    // mirrored its off-screen samples (3.1% without SSAO); today 3.3%.
    assert!(
        m.edge_below_cycles < 0.05,
        "open floor at the edges: {:.1}% below 0.95 of Cycles (today 3.3%)",
        100.0 * m.edge_below_cycles
    );
}

#[test]
fn a_glossy_ball_is_no_farther_from_cycles_than_today() {
    let m = measure_case("default_glossy_ball");
    let ball = item(&m, "ball");
    // 28.6% with the sqrt_cosine PEM kernel the default graph used before phong.
    assert!(ball.rel_mae < 0.255, "glossy ball: relative MAE {:.1}% (today 24.4%)", 100.0 * ball.rel_mae);
}

/// graphs/ssr.ron: the default graph with ScreenSpaceReflections after HybridOcclusion. The
/// glossy ball reflects the lit floor where IblShading alone shows the probe's dark ground
/// (docs/fidelity.md); Lambertian surfaces are left exactly as they were.
#[test]
fn screen_space_reflections_bring_the_glossy_ball_closer_to_cycles() {
    let m = measure_graph("default_glossy_ball", Some("graphs/ssr.ron"));
    let ball = item(&m, "ball");
    eprintln!(
        "figure: SSR glossy ball {:.2}%, overall {:.2}%, fifths {:?}, mean {:.4} / {:.4}",
        100.0 * ball.rel_mae,
        100.0 * m.rel_mae,
        ball.fifths,
        ball.mean_werkstatt,
        ball.mean_cycles
    );
    // The aim. 16.6% with sqrt_cosine, 13.0% before the hidden ground, 12.0% before the
    // rays followed the GGX lobe.
    assert!(ball.rel_mae < 0.10, "glossy ball with SSR: relative MAE {:.1}% (today 9.5%)", 100.0 * ball.rel_mae);
    let (with, without) = (measure_graph("default_lambert", Some("graphs/ssr.ron")), measure_case("default_lambert"));
    assert_eq!(with.rel_mae, without.rel_mae, "SSR changed the Lambertian scene");
}

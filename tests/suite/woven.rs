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
    // The CPU path exports its own meshes; the GPU path reads back what the compute pass wrote.
    for (evaluate_on, tolerance) in [("cpu", 1e-6), ("gpu", 1e-4)] {
        exports_the_cpu_evaluation(evaluate_on, tolerance);
    }
}

fn exports_the_cpu_evaluation(evaluate_on: &str, tolerance: f32) {
    let with = format!(r#""level": 7.5, "evaluate": "{evaluate_on}""#);
    let ev = evaluate(GRAPH, &[(r#""level": 7.5"#, &with)]);
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
    let woven = Woven { panel: &panel, weave: &weave, yarn: &yarn, morph: Morph::Continuous, snap: true };
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
    assert!(worst < tolerance, "{evaluate_on}: exported vertices differ from the CPU evaluation by up to {worst}");
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

/// The compute shader (shaders/tessellation/woven.wgsl) against its CPU twin (src/woven/tess.rs)
/// on a curved 3x2-patch grid with every scale, morphs within and across scales and every kind
/// of shared edge: vertex for vertex, the same triangles, and culled patches left out.
#[test]
fn the_gpu_tessellation_matches_the_cpu_twin() {
    use werkstatt::woven::gpu::{GpuWoven, patch_counts};
    use werkstatt::woven::panel::ControlGrid;
    let points = (0..3)
        .flat_map(|j| (0..4).map(move |i| (i as f64, j as f64)))
        .map(|(x, z)| glam::DVec3::new(x, 0.3 * (0.9 * x).sin() * (0.7 * z).cos(), z))
        .collect();
    let grid = ControlGrid::new(4, 3, points).unwrap();
    let panel = Panel { flip: true, ..Panel::new(&grid) };
    let weave = Weave::twill(2, 1).unwrap();
    let yarn = YarnParams { nodes: 4, spacing: 0.25, crimp: 0.04, radius: 0.05, fibres: 3, migration: 0.3, twist: 0.5 };
    let woven = Woven { panel: &panel, weave: &weave, yarn: &yarn, morph: Morph::Continuous, snap: true };
    let g = gpu();
    let mut runner = GpuWoven::default();
    // The third set lies just under integers that f32 rounds up, across scale boundaries too:
    // the GPU draws the rounded levels, at the scale and resolution it plans.
    let under = 1e-10;
    for levels in [
        [2.5, 3.7, 4.5, 6.3, 9.6, 10.2],
        [1.0, 0.4, 3.2, 5.5, 7.0, 8.75],
        [4.0 - under, 5.0, 7.0 - under, 3.5, 10.0 - under, 9.0 - under],
    ] {
        let levels: Vec<Option<f64>> = levels.iter().map(|&l| Some(l)).collect();
        let rounded: Vec<Option<f64>> = levels.iter().map(|l| l.map(|l| f64::from(l as f32))).collect();
        let cpu = woven.tessellate(&rounded).unwrap();
        let start = std::time::Instant::now();
        let frame = runner.run(g, &woven, &levels, &[false; 6]).unwrap();
        g.submit_checked().unwrap();
        g.wait_idle();
        println!("GPU run (with pipeline compiles the first time): {:.2} s", start.elapsed().as_secs_f64());
        assert_eq!(frame.scales, cpu.scales, "{levels:?}");
        for (k, layer) in [&cpu.panel, &cpu.weft, &cpu.warp].into_iter().enumerate() {
            let Some(gl) = &frame.layers[k] else {
                assert!(layer.indices.is_empty(), "layer {k} missing on the GPU");
                continue;
            };
            let (v, i) = gl.read_back(g).unwrap();
            assert_eq!(v.len(), layer.positions.len(), "layer {k} {levels:?}");
            assert_eq!(i, layer.indices, "layer {k} {levels:?}");
            let mut worst = [0.0f64; 3];
            for (k2, gv) in v.iter().enumerate() {
                let p = glam::Vec3::from(gv.position).as_dvec3();
                let n = glam::Vec3::from(gv.normal).as_dvec3();
                worst[0] = worst[0].max(p.distance(layer.positions[k2]));
                worst[1] = worst[1].max(n.distance(layer.normals[k2].normalize()));
                let uv = layer.uvs[k2];
                worst[2] = worst[2].max((gv.uv[0] as f64 - uv[0]).abs().max((gv.uv[1] as f64 - uv[1]).abs()));
            }
            println!(
                "layer {k} {levels:?}: {} vertices, position {:.2e}, normal {:.2e}, uv {:.2e}",
                v.len(),
                worst[0],
                worst[1],
                worst[2]
            );
            // Patches are 1 unit wide: single precision keeps 1e-4 of a patch.
            assert!(worst[0] < 1e-4 && worst[1] < 2e-3 && worst[2] < 1e-6, "layer {k} {levels:?}: {worst:?}");
        }
        let counts: usize = levels.iter().flatten().map(|&l| patch_counts(&woven, l).2).sum();
        assert!(counts > 0);
    }
    // A culled patch draws nothing but still sets its neighbours' edges.
    let levels: Vec<Option<f64>> = [6.3; 6].iter().map(|&l| Some(l)).collect();
    let mut culled = [false; 6];
    culled[0] = true;
    let frame = runner.run(g, &woven, &levels, &culled).unwrap();
    g.submit_checked().unwrap();
    assert_eq!((frame.culled, frame.scales), (1, [0, 5, 0]));
    let one = patch_counts(&woven, 6.3);
    assert_eq!(frame.layers[1].as_ref().unwrap().index_count as usize, 5 * one.2);
}

/// Background pixels of a `w` x `h` coverage mask that the image border cannot reach through
/// background: holes inside the silhouette.
fn holes(drawn: &[bool], w: usize, h: usize) -> usize {
    let mut reached = vec![false; w * h];
    let mut stack: Vec<usize> =
        (0..w * h).filter(|&k| k % w == 0 || k % w == w - 1 || k < w || k >= w * (h - 1)).collect();
    while let Some(k) = stack.pop() {
        if drawn[k] || reached[k] {
            continue;
        }
        reached[k] = true;
        let (x, y) = (k % w, k / w);
        if x > 0 {
            stack.push(k - 1);
        }
        if x + 1 < w {
            stack.push(k + 1);
        }
        if y > 0 {
            stack.push(k - w);
        }
        if y + 1 < h {
            stack.push(k + w);
        }
    }
    (0..w * h).filter(|&k| !drawn[k] && !reached[k]).count()
}

/// 4x4 patches over [0, 4]^2 on the height field `amp sin(fx x) cos(fz z + 0.4)`.
fn bumpy_panel(amp: f64, fx: f64, fz: f64) -> Panel {
    let points = (0..5)
        .flat_map(|j| (0..5).map(move |i| (i as f64, j as f64)))
        .map(|(x, z)| glam::DVec3::new(x, amp * (fx * x).sin() * (fz * z + 0.4).cos(), z))
        .collect();
    Panel::new(&werkstatt::woven::panel::ControlGrid::new(5, 5, points).unwrap())
}

/// Issue 33's render check of cracks: a curved 4x4 patch grid at random non-integer panel
/// levels, evaluated by the compute pass and drawn as it is on screen, seen obliquely through an
/// orthographic camera over an empty (the "red") background. Every background pixel must join
/// the image border: none shows through inside the silhouette. Without eq. 21's snapping the
/// T-junctions open into holes (42 pixels with `snap` off, 46 with `snap` in woven.wgsl
/// returning its argument).
#[test]
fn an_orthographic_render_of_random_levels_shows_no_background_inside() {
    use std::sync::Arc;
    use werkstatt::render::scene::{Camera, DrawItem, Material, View};
    use werkstatt::woven::gpu::GpuWoven;
    // A bumpy height field: the chords of coarse edges leave its fine neighbours' points.
    let panel = bumpy_panel(0.45, 1.9, 1.7);
    let weave = Weave::plain();
    let yarn = YarnParams { nodes: 4, spacing: 0.25, crimp: 0.04, radius: 0.05, fibres: 3, migration: 0.3, twist: 0.5 };
    // Levels in (0, 4) from a fixed LCG, alternating low and high so neighbours differ.
    let mut state = 0x2545_f491_4f6c_dd1d_u64;
    let levels: Vec<Option<f64>> = (0..16)
        .map(|k| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            let r = (state >> 11) as f64 / (1u64 << 53) as f64;
            Some(if (k + k / 4) % 2 == 0 { 0.1 + 1.8 * r } else { 2.1 + 1.8 * r })
        })
        .collect();
    assert!(levels.iter().flatten().all(|l| l.fract() != 0.0 && *l < 4.0));
    let mut tess = GpuWoven::default();
    let mut drawer = werkstatt::render::draw::SceneDrawer::default();
    let mut render = |snap: bool| {
        let woven = Woven { panel: &panel, weave: &weave, yarn: &yarn, morph: Morph::Continuous, snap };
        let frame = tess.run(gpu(), &woven, &levels, &[false; 16]).unwrap();
        let material = Arc::new(Material::default());
        let items: Vec<DrawItem> = frame
            .layers
            .into_iter()
            .flatten()
            .map(|layer| WovenLayer::gpu_item(0, layer, frame.scales, material.clone()))
            .collect();
        assert_eq!(items.len(), 1, "panel levels draw the panel layer only");
        let (w, h) = (96u32, 72u32);
        let camera = Camera {
            eye: glam::Vec3::new(2.0, 4.0, 6.5),
            target: glam::Vec3::new(2.0, 0.0, 2.0),
            up: glam::Vec3::Y,
            fov_y_degrees: 40.0,
            near: 0.1,
            far: 20.0,
        };
        let mut view = View::new(&camera, w, h);
        view.proj = glam::Mat4::orthographic_rh(-2.3, 2.3, -1.725, 1.725, camera.near, camera.far);
        view.view_proj = view.proj * view.view;
        view.inv_proj = view.proj.inverse();
        view.inv_view_proj = view.view_proj.inverse();
        let gb = drawer.gbuffer(gpu(), &items, camera, view).unwrap();
        gpu().submit_checked().unwrap();
        let depth = werkstatt::gpu::read_back(gpu(), &gb.depth).unwrap();
        let drawn: Vec<bool> = depth.rgba.chunks(4).map(|d| d[0] > 0.0).collect();
        let covered = drawn.iter().filter(|&&d| d).count();
        (covered, holes(&drawn, w as usize, h as usize))
    };
    let (covered, inside) = render(true);
    let (_, cracks) = render(false);
    println!("levels {levels:?}: {covered} pixels drawn, {inside} background pixels inside ({cracks} unsnapped)");
    assert!(covered > 96 * 72 / 2, "the cloth covers only {covered} pixels");
    assert_eq!(inside, 0, "background shows through {inside} pixels inside the silhouette");
    assert!(cracks > 0, "without snapping the check sees no crack: it could not fail");
}

/// The tube layers are drawn into the G-buffer with their back faces culled; that must hide
/// nothing seen. A curved 4x4 patch grid at random yarn and fibre levels (morphing, ribbons,
/// fibres, snapped edges), evaluated by the compute pass, is drawn once as `WovenLayer` items
/// (culled) and once as the same triangles read back into plain two-sided meshes, looking at
/// the middle patches from above and from below: no pixel may show through. A tube wound
/// inwards anywhere would open where it is seen and show what lies behind it (culling front
/// faces instead: 356 pixels from above). The views leave out the cloth's outer boundary,
/// where the tubes end open and culling lets one see into them (uncapped yarn ends: docs/woven.md).
#[test]
fn culling_the_tubes_back_faces_hides_nothing_seen() {
    use std::sync::Arc;
    use werkstatt::render::scene::{Camera, DrawItem, Material};
    use werkstatt::woven::gpu::GpuWoven;
    let panel = bumpy_panel(0.3, 1.3, 1.1);
    let weave = Weave::twill(2, 1).unwrap();
    let yarn = YarnParams { nodes: 4, spacing: 0.25, crimp: 0.06, radius: 0.07, fibres: 3, migration: 0.3, twist: 0.5 };
    let mut state = 0x9e37_79b9_7f4a_7c15_u64;
    let levels: Vec<Option<f64>> = (0..16)
        .map(|_| {
            state = state.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            Some(4.2 + 6.6 * ((state >> 11) as f64 / (1u64 << 53) as f64))
        })
        .collect();
    let woven = Woven { panel: &panel, weave: &weave, yarn: &yarn, morph: Morph::Continuous, snap: true };
    let frame = GpuWoven::default().run(gpu(), &woven, &levels, &[false; 16]).unwrap();
    assert!(frame.scales[1] > 0 && frame.scales[2] > 0, "yarn and fibre patches: {:?}", frame.scales);
    let material = Arc::new(Material::default());
    let mut culled = Vec::new();
    let mut two_sided = Vec::new();
    for (k, layer) in frame.layers.into_iter().enumerate() {
        let Some(layer) = layer else { continue };
        let mesh = layer.read_back_mesh(gpu()).unwrap();
        two_sided.push(DrawItem::plain(Arc::new(mesh), material.clone(), glam::Mat4::IDENTITY));
        culled.push(WovenLayer::gpu_item(k, layer, frame.scales, material.clone()));
    }
    assert_eq!(culled.len(), 2, "tubes only: the weft and the warp");
    // The items drawn here do cull (the comparison would pass trivially if they did not), and a
    // mirrored one culls the other side.
    use werkstatt::render::draw::compose::VertexStage;
    use werkstatt::render::draw::kind::TargetKind;
    for item in &culled {
        let kind = item.kind_as::<WovenLayer>().unwrap();
        let faces = |item: &DrawItem| kind.culled_faces(TargetKind::GBuffer, item, VertexStage::Linear);
        assert_eq!(faces(item), Some(wgpu::Face::Back), "{}", kind.layer);
        let mut mirrored = item.clone();
        mirrored.model = glam::Mat4::from_scale(glam::Vec3::new(-1.0, 1.0, 1.0));
        assert_eq!(faces(&mirrored), Some(wgpu::Face::Front));
        assert_eq!(kind.culled_faces(TargetKind::DepthTiles, item, VertexStage::Linear), None);
    }
    let mut drawer = werkstatt::render::draw::SceneDrawer::default();
    let (w, h) = (160u32, 120u32);
    for eye in [glam::Vec3::new(2.0, 1.6, 3.6), glam::Vec3::new(2.3, -1.6, 3.4)] {
        let camera = Camera {
            eye,
            target: glam::Vec3::new(2.0, 0.0, 2.0),
            up: glam::Vec3::Y,
            fov_y_degrees: 30.0,
            near: 0.1,
            far: 20.0,
        };
        let mut depth = |items: &[DrawItem]| {
            let g = werkstatt::render::draw::render_gbuffer(gpu(), &mut drawer, items, camera, w, h).unwrap();
            gpu().submit_checked().unwrap();
            werkstatt::gpu::read_back(gpu(), &g.depth).unwrap().rgba.chunks(4).map(|d| d[0]).collect::<Vec<f32>>()
        };
        let (a, b) = (depth(&culled), depth(&two_sided));
        let covered = b.iter().filter(|&&d| d > 0.0).count();
        // Background, or deeper by more than a yarn's diameter: something behind shows through.
        // (Shallower steps are the faceted tubes' own non-convex quads at grazing angles: up
        // to 0.7 radii in 9 pixels from below.)
        let through = |(&x, &y): (&f32, &f32)| y > 0.0 && (x == 0.0 || x - y > 2.0 * yarn.radius as f32);
        let differ = a.iter().zip(&b).filter(|&p| through(p)).count();
        println!("eye {eye}: {covered} pixels drawn, {differ} show through when culled");
        assert!(covered > (w * h) as usize / 2, "the cloth covers only {covered} pixels");
        assert_eq!(differ, 0, "{differ} of {covered} pixels show through when culled");
    }
}

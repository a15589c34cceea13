//! The graphs that reproduce the deferred-warping paper's Fig. 1 (a-e) on the built-in cloth:
//! each renders, its attached detail geometry covers the measured share of the image (the
//! G-buffer's detail flag) and lies on the cloth, exports have exact sizes, and the output is
//! deterministic.

use crate::common::*;

const FIGURES: [&str; 6] =
    ["fig1a_fur", "fig1b_embroidery", "fig1c_buttons_seam", "fig1d_knitwear", "fig1e_stickers", "placements"];

/// The figure's graph with only the cloth in its scene: the merge node ("scene" in every
/// figure) gets the drawn cloth alone (Fig. 1d draws none, so a plain Draw is added).
fn cloth_only_graph(name: &str, out: &std::path::Path) -> std::path::PathBuf {
    use werkstatt::core::graph::{Graph, Link, NodeDoc, PortRef};
    let mut g = Graph::load(&root().join(format!("graphs/{name}.ron"))).unwrap();
    let port = |s: &str| PortRef::parse(s).unwrap();
    g.links.retain(|l| l.to.node != "scene");
    if !g.nodes.contains_key("draw_cloth") {
        g.nodes
            .insert("draw_cloth".into(), NodeDoc { kind: "Draw".into(), pos: [0.0, 0.0], params: Default::default() });
        g.links.push(Link { from: port("cloth.surface"), to: port("draw_cloth.mesh") });
    }
    g.links.push(Link { from: port("draw_cloth.scene"), to: port("scene.a") });
    // Saved outside graphs/: the files it names, relative to graphs/, made absolute.
    for node in g.nodes.values_mut() {
        for value in node.params.values_mut() {
            if let werkstatt::core::param::ParamValue::Str(text) = value
                && text.starts_with("../")
            {
                *text = root().join("graphs").join(&*text).display().to_string();
            }
        }
    }
    let path = out.join(format!("{name}_cloth_only.ron"));
    g.save(&path).unwrap();
    path
}

/// Per figure: the share of the 96x96 image its attached geometry covers (frame 0, measured
/// on lavapipe when the test was written), and the share of those pixels that must lie on
/// the cloth (or within a pixel of its silhouette: fur and buttons stand off the surface).
const COVERAGE: [(&str, f64, f64); 6] = [
    ("fig1a_fur", 0.07617, 0.96),
    ("fig1b_embroidery", 0.00673, 0.98),
    ("fig1c_buttons_seam", 0.00532, 0.98),
    ("fig1d_knitwear", 0.10319, 0.98),
    ("fig1e_stickers", 0.05935, 0.98),
    ("placements", 0.01063, 0.98),
];

#[test]
fn every_figure_renders_with_its_attachments_on_the_cloth() {
    assert_eq!(COVERAGE.map(|c| c.0), FIGURES);
    let mut failures = Vec::new();
    for (name, expected, on_cloth) in COVERAGE {
        let out = out_dir(&format!("figure-{name}"));
        let graph = root().join(format!("graphs/{name}.ron"));
        render_graph(&graph, &out, (0, 0), (96, 96), &[], &["gbuffer.normal"])
            .unwrap_or_else(|e| panic!("{name}: {e:#}"));
        let normal = read_exr(&out.join("gbuffer.normal_0000.exr"));
        let cloth_out = out_dir(&format!("figure-{name}-cloth"));
        render_graph(&cloth_only_graph(name, &cloth_out), &cloth_out, (0, 0), (96, 96), &[], &["gbuffer.depth"])
            .unwrap_or_else(|e| panic!("{name} (cloth only): {e:#}"));
        let depth = read_exr(&cloth_out.join("gbuffer.depth_0000.exr"));
        let (w, h) = (normal.width as i64, normal.height as i64);
        let cloth = |x: i64, y: i64| x >= 0 && y >= 0 && x < w && y < h && depth.rgba[((y * w + x) * 4) as usize] > 0.0;
        let (mut detail, mut near_cloth) = (0usize, 0usize);
        for y in 0..h {
            for x in 0..w {
                if normal.rgba[((y * w + x) * 4 + 3) as usize] > 0.5 {
                    detail += 1;
                    if (-1..=1).any(|dy| (-1..=1).any(|dx| cloth(x + dx, y + dy))) {
                        near_cloth += 1;
                    }
                }
            }
        }
        let share = detail as f64 / (w * h) as f64;
        let on = near_cloth as f64 / detail.max(1) as f64;
        eprintln!("{name}: detail covers {:.3}% of the image, {:.2}% of it on the cloth", share * 100.0, on * 100.0);
        // Within 10% of the measured share: a misplaced, mis-scaled or half-missing
        // attachment changes it by more (the cloth covers about a third of the image).
        if (share - expected).abs() > 0.1 * expected {
            failures.push(format!(
                "{name}: attached geometry covers {:.3}% of the image, expected {:.3}% ± 10%",
                share * 100.0,
                expected * 100.0
            ));
        }
        if on < on_cloth {
            failures.push(format!(
                "{name}: only {:.2}% of the attached pixels lie on the cloth (min {:.2}%)",
                on * 100.0,
                on_cloth * 100.0
            ));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n"));
}

#[test]
fn knitwear_replaces_the_surface() {
    // Fig. 1d draws no cloth: everything on the garment is attached knit geometry. The loops
    // leave gaps, so the knit covers about three quarters of the pixels the cloth would
    // (73% measured on lavapipe); a missing or shifted tiling covers far fewer.
    let out = out_dir("figure-knit-only");
    render_graph(&root().join("graphs/fig1d_knitwear.ron"), &out, (0, 0), (96, 96), &[], &["gbuffer.normal"]).unwrap();
    let normal = read_exr(&out.join("gbuffer.normal_0000.exr"));
    let cloth_out = out_dir("figure-knit-only-cloth");
    render_graph(
        &cloth_only_graph("fig1d_knitwear", &cloth_out),
        &cloth_out,
        (0, 0),
        (96, 96),
        &[],
        &["gbuffer.depth"],
    )
    .unwrap();
    let depth = read_exr(&cloth_out.join("gbuffer.depth_0000.exr"));
    let cloth: Vec<usize> = (0..depth.rgba.len() / 4).filter(|&i| depth.rgba[i * 4] > 0.0).collect();
    let covered = cloth.iter().filter(|&&i| normal.rgba[i * 4 + 3] > 0.5).count();
    let share = covered as f64 / cloth.len() as f64;
    assert!(cloth.len() > 500 && share > 0.65, "the knit covers {:.2}% of the cloth", share * 100.0);
}

#[test]
fn animated_figure_is_deterministic_and_exports_its_geometry() {
    let graph = root().join("graphs/fig1e_stickers.ron");
    let (a, b) = (out_dir("figure-e-a"), out_dir("figure-e-b"));
    let stats = render_graph(&graph, &a, (0, 2), (80, 60), &[], &[]).unwrap();
    render_graph(&graph, &b, (0, 2), (80, 60), &[], &[]).unwrap();
    // The runner writes and counts what the output nodes emit: three images, one export.
    let mut files = stats.files.clone();
    files.sort();
    assert_eq!(files, ["export_0000.obj", "image_0000.png", "image_0001.png", "image_0002.png"]);
    for f in ["image_0000.png", "image_0002.png", "export_0000.obj"] {
        assert!(std::fs::read(a.join(f)).unwrap() == std::fs::read(b.join(f)).unwrap(), "{f} differs between runs");
    }
    // The flag moves and the logo spins: frames differ.
    assert_ne!(std::fs::read(a.join("image_0000.png")).unwrap(), std::fs::read(a.join("image_0002.png")).unwrap());
    // Exported once (frame 0): the flag plus two warped 16x16-quad stickers, outliers removed.
    assert!(!a.join("export_0001.obj").exists());
    let obj = std::fs::read_to_string(a.join("export_0000.obj")).unwrap();
    // Exact counts, measured when the test was written: the flag's triangles plus the
    // stickers' 16x16 quads whose vertices all found a frame. A sticker lost, doubled or
    // cut by wrong outliers changes them.
    let faces = obj.lines().filter(|l| l.starts_with("f ")).count();
    let vertices = obj.lines().filter(|l| l.starts_with("v ")).count();
    assert_eq!((faces, vertices), (5960, 3288), "faces and vertices of the export");
    // An object per item and per sticker: the flag, each of the two sticker attachments' one
    // instance, the three colliders.
    let header = "# werkstatt export: 3288 vertices, 5960 triangles; 6 items, 2 attachment instances, 6 objects\n";
    assert!(obj.starts_with(header), "{}", obj.lines().next().unwrap());
    let objects: Vec<&str> = obj.lines().filter_map(|l| l.strip_prefix("o ")).collect();
    assert_eq!(
        objects,
        ["draw_cloth", "logo_0", "sticker_0", "cloth_collider_0", "cloth_collider_1", "cloth_collider_2"]
    );
}

#[test]
fn placement_file_errors_name_file_and_line() {
    let dir = out_dir("placement-file");
    let bad = dir.join("bad.csv");
    std::fs::write(&bad, "piece,u,v,angle,scale\n0,0.5,0.5,0,1\n0,0.5,oops,0,1\n").unwrap();
    let e = werkstatt::nodes::warp::placements::load_placements(&bad).unwrap_err().to_string();
    assert!(e.contains("bad.csv:3") && e.contains("oops"), "{e}");
    std::fs::write(&bad, "0,1.5,0.5,0,1\n").unwrap();
    let e = werkstatt::nodes::warp::placements::load_placements(&bad).unwrap_err().to_string();
    assert!(e.contains("outside [0, 1]"), "{e}");
    let good =
        werkstatt::nodes::warp::placements::load_placements(&root().join("assets/placements/buttons.csv")).unwrap();
    assert_eq!(good.len(), 5);
    let ron = dir.join("layout.ron");
    std::fs::write(&ron, "[(0, 0.25, 0.5, 45.0, 2.0)]").unwrap();
    assert_eq!(werkstatt::nodes::warp::placements::load_placements(&ron).unwrap()[0].angle, 45.0);
}

#[test]
fn cloth_presets_animate_deterministically() {
    for (graph, sets) in [
        ("tablecloth", vec![]),
        ("fig1a_fur", vec!["scatter.count=10", "cloth.warmup=0"]),
        ("fig1e_stickers", vec!["cloth.warmup=0"]),
    ] {
        let path = root().join(format!("graphs/{graph}.ron"));
        let (a, b) = (out_dir(&format!("preset-{graph}-a")), out_dir(&format!("preset-{graph}-b")));
        render_graph(&path, &a, (0, 6), (64, 48), &sets, &[]).unwrap_or_else(|e| panic!("{graph}: {e:#}"));
        render_graph(&path, &b, (0, 6), (64, 48), &sets, &[]).unwrap();
        let frame = |dir: &std::path::Path, f: i64| std::fs::read(dir.join(format!("image_{f:04}.png"))).unwrap();
        assert_ne!(frame(&a, 0), frame(&a, 6), "{graph}: the cloth does not move");
        for f in 0..=6 {
            assert!(frame(&a, f) == frame(&b, f), "{graph}: frame {f} differs between two runs");
        }
    }
}

/// What ExportGeometry writes from the GPU's warp is the CPU twin's warp of the same
/// attachments (src/warp/mod.rs, threaded, no GPU): the same triangles kept, every vertex where the
/// CPU puts it; with `warp: cpu` it is the twin's exactly. An export that dropped, shifted or
/// mis-ordered instances, or kept outliers, fails here.
#[test]
fn exported_vertices_match_the_cpu_warp_of_the_same_attachments() {
    use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime};
    use werkstatt::core::port::Value;
    use werkstatt::warp::gpu::assemble;
    let gpu = gpu();
    let text = r#"(version: 1, nodes: {
        "cloth": (kind: "ClothSim", params: {"triangles": 400}),
        "matrix": (kind: "MatrixTexture", params: {"resolution": 128}),
        "grid": (kind: "GridPlacement", params: {"columns": 5, "rows": 4}),
        "button": (kind: "Primitive", params: {"shape": "disc", "radius": 0.5, "height": 0.2, "segments_u": 16}),
        "buttons": (kind: "PointAttachment", params: {"scale": 0.1}),
        "out": (kind: "ExportGeometry", params: {"warp": "gpu"}),
        "out_cpu": (kind: "ExportGeometry", params: {"warp": "cpu"}),
    }, links: [("cloth.surface", "matrix.surface"), ("cloth.surface", "grid.surface"),
        ("matrix.matrix", "buttons.matrix"), ("button.mesh", "buttons.mesh"),
        ("grid.placements", "buttons.placements"), ("buttons.scene", "out.scene"),
        ("buttons.scene", "out_cpu.scene")])"#;
    let graph = werkstatt::core::graph::Graph::load_str(text, "export.ron".as_ref()).unwrap();
    let mut ev = Evaluator::new(&graph, &[]).unwrap();
    let resources = werkstatt::core::resources::Resources::new(false);
    let settings = FrameSettings { width: 64, height: 64, base_dir: root(), frames: None };
    let summary = ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, Some(gpu), &resources, &settings);
    assert_eq!((summary.failed, summary.pending), (0, 0), "{:?}", ev.report("out").map(|r| r.status.clone()));
    let (Some(Value::Mesh(exported)), Some(Value::Scene(items))) =
        (ev.output("out", "mesh").cloned(), ev.output("buttons", "scene").cloned())
    else {
        panic!("no export")
    };
    let item = &items[0];
    let draw = item.kind_as::<werkstatt::warp::AttachedDraw>().expect("attached buttons");
    let texels = werkstatt::warp::gpu::read_matrix(gpu, &draw.matrix).unwrap();
    let cpu =
        assemble(&item.mesh, werkstatt::warp::warp_layout_cpu(&texels, &draw.settings, &item.mesh, &draw.instances))
            .unwrap();
    use werkstatt::warp::gpu::WarpDevice;
    assert_eq!((WarpDevice::Gpu.resolve(gpu), WarpDevice::Cpu.resolve(gpu)), (WarpDevice::Gpu, WarpDevice::Cpu));
    let cpu_adapter = gpu.info.device_type == wgpu::DeviceType::Cpu;
    assert_eq!(WarpDevice::Auto.resolve(gpu), if cpu_adapter { WarpDevice::Cpu } else { WarpDevice::Gpu });
    let Some(Value::Mesh(exported_on_cpu)) = ev.output("out_cpu", "mesh") else { panic!("no CPU export") };
    assert!(
        (&exported_on_cpu.positions, &exported_on_cpu.normals, &exported_on_cpu.indices)
            == (&cpu.positions, &cpu.normals, &cpu.indices),
        "warp: cpu exports other geometry than the CPU twin"
    );
    let per_button = item.mesh.triangle_count();
    assert_eq!(draw.instances.len(), 20, "every placement is on the cloth");
    assert!(
        exported.triangle_count() >= 18 * per_button,
        "at least 18 of 20 buttons exported whole: {} triangles of {per_button} each",
        exported.triangle_count()
    );
    assert_eq!(exported.indices, cpu.indices, "the export keeps other triangles than the CPU twin");
    assert_eq!(exported.positions.len(), cpu.positions.len());
    let worst = exported.positions.iter().zip(&cpu.positions).map(|(a, b)| a.distance(*b)).fold(0.0f32, f32::max);
    let worst_normal = exported.normals.iter().zip(&cpu.normals).map(|(a, b)| a.distance(*b)).fold(0.0f32, f32::max);
    eprintln!("export vs CPU twin: positions within {worst:.2e}, normals within {worst_normal:.2e}");
    assert!(worst < 1e-4, "an exported vertex is {worst} from the CPU twin's");
    assert!(worst_normal < 1e-3, "an exported normal is {worst_normal} from the CPU twin's");
}

//! The command line as users and CI see it: exit codes and messages.

use std::process::Command;

fn werkstatt(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_werkstatt"))
        .args(args)
        .current_dir(env!("CARGO_MANIFEST_DIR"))
        .output()
        .unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn docs_node_reference_is_up_to_date() {
    let expected = werkstatt::app::docs::markdown();
    let actual = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/nodes.md")).unwrap_or_default();
    assert!(actual == expected, "docs/nodes.md is out of date: run `cargo run -- nodes --markdown > docs/nodes.md`");
}

#[test]
fn nodes_kind_describes_one_node_in_full() {
    let (code, out, err) = werkstatt(&["nodes", "GridPlacement"]);
    assert_eq!(code, 0, "{err}");
    assert!(out.starts_with("GridPlacement (Attachment)"), "{out}");
    assert!(out.contains("surface  Surface (optional)"), "{out}");
    assert!(out.contains("columns  int = 8 in [1, 100000]  Cells along u."), "{out}");
    let (code, out, _) = werkstatt(&["nodes", "Draw"]);
    assert_eq!(code, 0);
    assert!(out.contains("mesh      Mesh (required)"), "{out}");
    let (code, _, err) = werkstatt(&["nodes", "Matrial"]);
    assert_eq!(code, 1);
    assert!(err.contains("unknown node kind \"Matrial\"; did you mean \"Material\"?"), "{err}");
    // The listing marks optional inputs.
    let (_, out, _) = werkstatt(&["nodes"]);
    assert!(out.contains("in (mesh: Mesh, material?: Material)"), "{out}");
}

#[test]
fn nodes_json_lists_every_kind_with_its_parameters() {
    let (code, out, err) = werkstatt(&["nodes", "--json"]);
    assert_eq!(code, 0, "{err}");
    let all: serde_json::Value = serde_json::from_str(&out).unwrap();
    assert_eq!(all.as_array().unwrap().len(), werkstatt::core::spec::all().len());
    let material = all.as_array().unwrap().iter().find(|n| n["kind"] == "Material").unwrap();
    let gloss = material["params"].as_array().unwrap().iter().find(|p| p["name"] == "glossiness").unwrap();
    assert_eq!(
        (gloss["type"].as_str(), gloss["min"].as_f64(), gloss["max"].as_f64()),
        (Some("float"), Some(0.0), Some(1.0))
    );
    let (_, one, _) = werkstatt(&["nodes", "Material", "--json"]);
    assert_eq!(&serde_json::from_str::<serde_json::Value>(&one).unwrap(), material);
}

#[test]
fn nodes_markdown_prints_or_writes_the_reference() {
    let (code, out, _) = werkstatt(&["nodes", "--markdown"]);
    assert_eq!((code, out == werkstatt::app::docs::markdown()), (0, true));
    let dir = temp("nodes-markdown");
    let file = dir.join("nodes.md");
    let (code, out, err) = werkstatt(&["nodes", "--markdown", "--out", file.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.is_empty());
    assert_eq!(std::fs::read_to_string(&file).unwrap(), werkstatt::app::docs::markdown());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn docs_presets_are_up_to_date() {
    let expected = werkstatt::nodes::cloth::node::presets_markdown().unwrap();
    let actual = std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/docs/presets.md")).unwrap_or_default();
    assert!(
        actual == expected,
        "docs/presets.md is out of date: run `cargo run -- nodes --presets --out docs/presets.md`"
    );
    // The flag's one piece covers only part of the UV square: the number the issue asked for.
    assert!(expected.contains("## `flag`"), "{expected}");
}

#[test]
fn every_node_kind_is_documented_and_used_by_a_graph() {
    let graphs: String = std::fs::read_dir(concat!(env!("CARGO_MANIFEST_DIR"), "/graphs"))
        .unwrap()
        .map(|e| std::fs::read_to_string(e.unwrap().path()).unwrap())
        .collect();
    let mut kinds = std::collections::BTreeSet::new();
    for spec in werkstatt::core::spec::all() {
        assert!(kinds.insert(spec.kind), "kind {} registered twice", spec.kind);
        assert!(!spec.doc.is_empty(), "{} has no doc", spec.kind);
        for p in spec.params {
            assert!(!p.doc.is_empty(), "{}.{} has no doc", spec.kind, p.name);
            assert!(p.kind.check(&p.kind.default_value()).is_ok(), "{}.{}: default is invalid", spec.kind, p.name);
        }
        assert!(graphs.contains(&format!("kind: \"{}\"", spec.kind)), "no graph in graphs/ uses {}", spec.kind);
    }
}

#[test]
fn check_passes_good_graphs_and_fails_bad_ones() {
    let (code, out, _) = werkstatt(&["check", "graphs/still_life.ron"]);
    assert_eq!(code, 0);
    assert!(out.contains("ok: graphs/still_life.ron"));
    let (code, _, err) = werkstatt(&["check", "graphs/still_life.ron", "tests/data/bad/unknown_kind.ron"]);
    assert_eq!(code, 1);
    assert!(
        err.contains("tests/data/bad/unknown_kind.ron:5:9: error in node \"cam\": unknown node kind \"OrbitCamra\""),
        "{err}"
    );
    assert!(err.contains("1 of 2 graph(s) have errors"), "{err}");
}

#[test]
fn fmt_check_reports_non_canonical_files() {
    let dir = std::env::temp_dir().join(format!("werkstatt-fmt-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join("g.ron");
    std::fs::write(&path, r#"(version: 1, nodes: {"n": (kind: "Number")}, links: [])"#).unwrap();
    let p = path.to_str().unwrap();
    let (code, out, _) = werkstatt(&["fmt", "--check", p]);
    assert_eq!((code, out.contains("not canonical")), (1, true));
    assert_eq!(werkstatt(&["fmt", p]).0, 0);
    assert_eq!(werkstatt(&["fmt", "--check", p]).0, 0);
    assert_eq!(werkstatt(&["fmt", "--check", "graphs/still_life.ron"]).0, 0);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn render_rejects_bad_arguments_before_rendering() {
    for (args, needle) in [
        (vec!["render", "graphs/still_life.ron", "--frames", "5..2"], "--frames"),
        (vec!["render", "graphs/still_life.ron", "--size", "big"], "--size"),
        (vec!["render", "graphs/still_life.ron", "--set", "camera.fov=500"], "out of range"),
        (vec!["render", "tests/data/bad/cycle.ron"], "cycle"),
        (vec!["render", "graphs/still_life.ron", "--size", "0x48"], "each 1..=8192"),
        (vec!["render", "graphs/still_life.ron", "--size", "8193x10"], "each 1..=8192"),
        (vec!["render", "graphs/still_life.ron", "--fps", "0"], "--fps must be a positive number"),
        (vec!["render", "graphs/still_life.ron", "--fps=-30"], "--fps must be a positive number"),
        (vec!["render", "graphs/still_life.ron", "--frames", "0..10000000"], "--frames"),
    ] {
        let (code, _, err) = werkstatt(&args);
        assert_eq!(code, 1, "{args:?}");
        assert!(err.contains(needle), "{args:?}: {err}");
    }
}

#[test]
fn render_writes_frames_and_stats() {
    let out = std::env::temp_dir().join(format!("werkstatt-cli-render-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&out);
    let (code, _, err) = werkstatt(&[
        "render",
        "graphs/still_life.ron",
        "--frames",
        "0..2",
        "--size",
        "64x48",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{err}");
    let images = ["image_0000.png", "image_0001.png", "image_0002.png"];
    for f in images {
        let png = image::open(out.join(f)).unwrap_or_else(|e| panic!("{f}: {e}"));
        assert_eq!((png.width(), png.height()), (64, 48), "{f}");
    }
    // Exactly the images and stats.json, no temporary left behind.
    let mut written: Vec<String> =
        std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    written.sort();
    assert_eq!(written, [&images[..], &["stats.json"]].concat());

    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("stats.json")).unwrap()).unwrap();
    assert_eq!((stats["width"].as_u64(), stats["height"].as_u64()), (Some(64), Some(48)));
    let frames: Vec<i64> =
        stats["frames"].as_array().expect("frames").iter().map(|f| f["frame"].as_i64().unwrap()).collect();
    assert_eq!(frames, [0, 1, 2]);
    for f in stats["frames"].as_array().unwrap() {
        assert_eq!(f["nodes"]["image"]["ran"], true, "the output node runs every frame: {f}");
    }
    let mut files: Vec<&str> = stats["files"].as_array().expect("files").iter().map(|f| f.as_str().unwrap()).collect();
    files.sort();
    assert_eq!(files, images);
    let graph = werkstatt::core::graph::Graph::load(std::path::Path::new(concat!(
        env!("CARGO_MANIFEST_DIR"),
        "/graphs/still_life.ron"
    )))
    .unwrap();
    let hash = format!("{:016x}", werkstatt::core::hash::fnv1a(graph.to_ron().as_bytes()));
    assert_eq!(stats["graph_hash"].as_str(), Some(hash.as_str()));
    let adapter = stats["adapter"].as_str().expect("adapter");
    assert!(!adapter.is_empty());
    let summary = format!("rendered 3 frame(s) on {adapter}: 3 file(s) and stats.json in {}", out.display());
    assert!(err.lines().any(|l| l == summary), "no line \"{summary}\" in:\n{err}");
    std::fs::remove_dir_all(out).unwrap();
}

/// `render --set a..b:n --contact-sheet`: a folder per value, each a full render, and a
/// labelled montage whose cells brighten with the swept light.
#[test]
fn render_sweeps_into_folders_and_writes_a_contact_sheet() {
    let out = temp("sweep");
    let out_arg = out.to_str().unwrap();
    let args = ["render", "graphs/spot.ron", "--size", "64x48", "--out", out_arg];
    let (code, _, err) =
        werkstatt(&[&args[..], &["--set", "light.sun_intensity=0.5..2:3", "--contact-sheet"]].concat());
    assert_eq!(code, 0, "{err}");
    let mut means = Vec::new();
    for value in ["0.5", "1.25", "2"] {
        let dir = out.join(format!("light.sun_intensity={value}"));
        let stats = read_stats(&dir);
        assert_eq!(stats["sets"][0].as_str(), Some(format!("light.sun_intensity={value}").as_str()));
        let png = image::open(dir.join("preview_0000.png")).unwrap().to_rgba8();
        means.push(png.pixels().map(|p| p[0] as f64 + p[1] as f64 + p[2] as f64).sum::<f64>());
    }
    assert!(means[0] < means[1] && means[1] < means[2], "brighter with the sun: {means:?}");
    let sheet = image::open(out.join("contact_sheet.png")).unwrap().to_rgba8();
    assert_eq!(sheet.width(), 6 + 3 * (96 + 6), "three cells in a row (64 px images in 96 px cells for their labels)");
    assert!(sheet.height() > 48 + 8, "room for a label under the images");
    assert!(err.contains("contact sheet: "), "{err}");

    // No sweep, no sheet; a bad value fails before anything renders.
    let (code, _, err) = werkstatt(&[&args[..], &["--contact-sheet"]].concat());
    assert_ne!(code, 0);
    assert!(err.contains("--contact-sheet needs a sweep"), "{err}");
    let bad = temp("sweep-bad");
    let (code, _, err) = werkstatt(&[
        "render",
        "graphs/spot.ron",
        "--size",
        "64x48",
        "--out",
        bad.to_str().unwrap(),
        "--set",
        "light.sun_intensity=1,oops",
    ]);
    assert_ne!(code, 0);
    assert!(err.contains("oops"), "{err}");
    assert!(!bad.join("light.sun_intensity=1/preview_0000.png").exists(), "nothing renders before every variant loads");
}

/// A temporary folder named after the test, emptied first.
fn temp(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("werkstatt-cli-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

#[test]
fn a_graph_without_an_output_node_is_refused() {
    let dir = temp("no-output");
    let graph = dir.join("g.ron");
    std::fs::write(&graph, r#"(version: 1, nodes: {"n": (kind: "Number")}, links: [])"#).unwrap();
    let out = dir.join("out");
    let (code, _, err) = werkstatt(&["render", graph.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("has no output node"), "{err}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// A frame that fails stops the render with exit code 1, and stats.json keeps the frames
/// before it (and the failed one) for CI.
#[test]
fn stats_are_kept_when_a_later_frame_fails() {
    let dir = temp("later-frame-fails");
    let graph = dir.join("g.ron");
    // The time passes the Watch's maximum at frame 2 (2/30 s > 0.05).
    std::fs::write(
        &graph,
        r#"(version: 1, nodes: {"t": (kind: "Time"), "w": (kind: "Watch", params: {"max": 0.05})}, links: [("t.seconds", "w.value")])"#,
    )
    .unwrap();
    let out = dir.join("out");
    let (code, _, err) =
        werkstatt(&["render", graph.to_str().unwrap(), "--frames", "0..4", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("frame 2") && err.contains("outside the accepted range"), "{err}");
    let stats: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("stats.json")).unwrap()).unwrap();
    let frames: Vec<i64> = stats["frames"].as_array().unwrap().iter().map(|f| f["frame"].as_i64().unwrap()).collect();
    assert_eq!(frames, [0, 1, 2]);
    let values: Vec<f64> = stats["values"]["w"].as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert_eq!(values, [0.0, 1.0 / 30.0]);
    let error = stats["error"].as_str().expect("a failed run records its error");
    assert!(error.contains("frame 2") && error.contains("outside the accepted range"), "{error}");
    std::fs::remove_dir_all(dir).unwrap();
}

fn read_stats(out: &std::path::Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(out.join("stats.json")).unwrap()).unwrap()
}

/// stats.json alone says how the run was made: command line, overrides, frames, fps, version.
#[test]
fn stats_describe_the_run() {
    let dir = temp("stats-describe");
    let out = dir.join("out");
    let args = [
        "render",
        "graphs/still_life.ron",
        "--frames",
        "1..2",
        "--fps",
        "24",
        "--size",
        "32x24",
        "--set",
        "camera.fov=40",
        "--out",
        out.to_str().unwrap(),
    ];
    let (code, _, err) = werkstatt(&args);
    assert_eq!(code, 0, "{err}");
    let stats = read_stats(&out);
    let command: Vec<&str> = stats["command"].as_array().unwrap().iter().map(|a| a.as_str().unwrap()).collect();
    assert_eq!(command[1..], args);
    assert_eq!(stats["sets"], serde_json::json!(["camera.fov=40"]));
    assert_eq!(stats["frame_range"], serde_json::json!([1, 2]));
    assert_eq!(stats["fps"], 24.0);
    assert_eq!(stats["version"], env!("CARGO_PKG_VERSION"));
    // Built from a checkout here; a build outside git leaves the field out.
    if let Some(commit) = stats["git_commit"].as_str() {
        assert!(commit.len() == 40 && commit.chars().all(|c| c.is_ascii_hexdigit()), "{commit}");
    }
    assert!(stats.get("error").is_none(), "{stats}");
    // The frame's phases account for all of it: they sum to total_ms, the nodes' CPU time is
    // part of the evaluation, and the written images were read back and encoded.
    for frame in stats["frames"].as_array().unwrap() {
        let f = |k: &str| frame[k].as_f64().unwrap_or_else(|| panic!("no {k} in {frame}"));
        let p = |k: &str| frame["phases"][k].as_f64().unwrap_or_else(|| panic!("no phases.{k} in {frame}"));
        let parts = ["evaluate_ms", "loads_ms", "gpu_wait_ms", "readback_ms", "write_ms", "other_ms"];
        let sum: f64 = parts.iter().map(|k| p(k)).sum();
        assert!((sum - f("total_ms")).abs() <= 1e-6 * f("total_ms"), "phases sum to {sum}: {frame}");
        assert!(parts.iter().all(|k| p(k) >= 0.0), "{frame}");
        assert!(f("wall_ms") <= f("total_ms"), "{frame}");
        let node_cpu: f64 = frame["nodes"].as_object().unwrap().values().map(|n| n["cpu_ms"].as_f64().unwrap()).sum();
        assert!(node_cpu <= p("evaluate_ms"), "nodes' CPU {node_cpu} ms beyond the evaluation: {frame}");
        assert!(p("readback_ms") > 0.0 && p("write_ms") > 0.0, "{frame}");
    }
    std::fs::remove_dir_all(dir).unwrap();
}

/// A run whose graph does not load still leaves a stats.json that says why.
#[test]
fn stats_record_a_run_that_fails_before_rendering() {
    let dir = temp("stats-load-error");
    let out = dir.join("out");
    let (code, _, err) = werkstatt(&["render", "tests/data/bad/unknown_kind.ron", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 1, "{err}");
    let stats = read_stats(&out);
    assert!(stats["error"].as_str().unwrap().contains("unknown node kind \"OrbitCamra\""), "{stats}");
    assert_eq!(stats["frames"], serde_json::json!([]));
    std::fs::remove_dir_all(dir).unwrap();
}

/// A plane drawn and exported at one fixed frame.
const EXPORT_GRAPH: &str = r#"(version: 1, nodes: {
    "plane": (kind: "Primitive", params: {"shape": "plane", "segments_u": 2, "segments_v": 2}),
    "draw": (kind: "Draw"),
    "export": (kind: "ExportGeometry", params: {"frame": 1}),
}, links: [("plane.mesh", "draw.mesh"), ("draw.scene", "export.scene")])"#;

#[test]
fn a_fixed_frame_export_is_written_counted_and_listed() {
    let dir = temp("fixed-export");
    let graph = dir.join("g.ron");
    std::fs::write(&graph, EXPORT_GRAPH).unwrap();
    let out = dir.join("out");
    let (code, _, err) =
        werkstatt(&["render", graph.to_str().unwrap(), "--frames", "0..2", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(out.join("export_0001.obj").exists());
    assert!(!out.join("export_0000.obj").exists() && !out.join("export_0002.obj").exists());
    let stats = read_stats(&out);
    assert_eq!(stats["files"], serde_json::json!(["export_0001.obj"]));
    let counts: Vec<&serde_json::Value> =
        stats["frames"].as_array().unwrap().iter().map(|f| &f["nodes"]["export"]["counts"]).collect();
    // 2 x 2 cells of two triangles, counted on the frame it exports.
    assert_eq!(counts[1]["triangles"], 8, "{stats}");
    assert!(counts[0].is_null() && counts[2].is_null(), "{stats}");
    assert_eq!(stats["frames"][0]["nodes"]["draw"]["counts"]["triangles"], 8);
    assert!(err.contains(": 1 file(s) and stats.json in"), "{err}");
    assert!(stats["warnings"].as_array().unwrap().is_empty(), "{stats}");

    // Outside the range it writes nothing, and says so.
    let (code, _, err) =
        werkstatt(&["render", graph.to_str().unwrap(), "--frames", "2..3", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    let warning = "node \"export\" (ExportGeometry) writes only frame 1, outside the rendered frames 2..3";
    assert!(err.contains(warning), "{err}");
    assert!(read_stats(&out)["warnings"][0].as_str().unwrap().contains(warning));
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn two_processes_render_the_same_bytes() {
    let dir = temp("two-processes");
    let render = |name: &str| {
        let out = dir.join(name);
        let args =
            ["render", "graphs/still_life.ron", "--frames", "0..1", "--size", "64x48", "--out", out.to_str().unwrap()];
        let (code, _, err) = werkstatt(&args);
        assert_eq!(code, 0, "{err}");
        out
    };
    let (a, b) = (render("a"), render("b"));
    for f in ["image_0000.png", "image_0001.png"] {
        assert!(
            std::fs::read(a.join(f)).unwrap() == std::fs::read(b.join(f)).unwrap(),
            "{f} differs between processes"
        );
    }
    assert_ne!(std::fs::read(a.join("image_0000.png")).unwrap(), std::fs::read(a.join("image_0001.png")).unwrap());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn help_exists_for_every_command() {
    for cmd in ["render", "test", "report", "check", "fmt", "nodes", "info", "bench"] {
        let (code, out, _) = werkstatt(&[cmd, "--help"]);
        assert_eq!(code, 0, "{cmd}");
        assert!(out.contains("Usage"), "{cmd}");
    }
}

#[test]
fn every_shader_file_is_embedded() {
    // shaders/FAMILY/NAME.wgsl, one folder deep.
    let root = std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/shaders"));
    let mut files: Vec<String> = std::fs::read_dir(root)
        .unwrap()
        .map(|e| e.unwrap().path())
        .flat_map(
            |p| if p.is_dir() { std::fs::read_dir(p).unwrap().map(|e| e.unwrap().path()).collect() } else { vec![p] },
        )
        .filter(|p| p.extension().is_some_and(|x| x == "wgsl"))
        .map(|p| p.strip_prefix(root).unwrap().to_string_lossy().replace('\\', "/"))
        .collect();
    files.sort();
    let mut embedded: Vec<String> = werkstatt::gpu::shaders::paths().map(str::to_string).collect();
    embedded.sort();
    assert_eq!(files, embedded, "shaders/ and the embedded list in src/gpu/shaders.rs differ");
}

/// Writes `text` as g.ron in a fresh folder named after the test.
fn graph_file(name: &str, text: &str) -> (std::path::PathBuf, std::path::PathBuf) {
    let dir = temp(name);
    let graph = dir.join("g.ron");
    std::fs::write(&graph, text).unwrap();
    (dir, graph)
}

#[test]
fn a_link_of_the_wrong_type_names_the_port_that_fits() {
    let (dir, graph) = graph_file(
        "link-type-help",
        r#"(version: 1, nodes: {"mat": (kind: "Material"), "draw": (kind: "Draw")}, links: [("mat.material", "draw.mesh")])"#,
    );
    let (code, _, err) = werkstatt(&["check", graph.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains("cannot link mat.material (Material) to draw.mesh (Mesh)"), "{err}");
    assert!(err.contains("did you mean draw.material? (it takes a Material)"), "{err}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// `check --message-format json`: one object per problem, with the position, node, port and
/// help that CI annotations need; warnings too, marked as such.
#[test]
fn check_prints_one_json_object_per_problem() {
    let (dir, graph) = graph_file(
        "check-json",
        "(version: 1, nodes: {\n    \"mat\": (kind: \"Material\"),\n    \"draw\": (kind: \"Draw\"),\n    \"sim\": (kind: \"LiveLink\"),\n}, links: [\n    (\"mat.material\", \"draw.mesh\"),\n])",
    );
    let (code, out, _) = werkstatt(&["check", "--message-format", "json", graph.to_str().unwrap()]);
    assert_eq!(code, 1);
    let problems: Vec<serde_json::Value> = out.lines().map(|l| serde_json::from_str(l).unwrap()).collect();
    let link = problems.iter().find(|p| p["port"] == "mesh").unwrap_or_else(|| panic!("{out}"));
    assert_eq!(link["file"], graph.display().to_string());
    assert_eq!((link["line"].as_u64(), link["column"].as_u64()), (Some(6), Some(5)), "{link}");
    assert_eq!((&link["node"], &link["level"]), (&serde_json::json!("draw"), &serde_json::json!("error")));
    assert!(link["message"].as_str().unwrap().contains("cannot link mat.material"), "{link}");
    assert!(link["help"].as_str().unwrap().contains("draw.material"), "{link}");

    // A valid graph's warnings: the LiveLink, at its line.
    std::fs::write(&graph, "(version: 1, nodes: {\n    \"sim\": (kind: \"LiveLink\"),\n}, links: [])").unwrap();
    let (code, out, _) = werkstatt(&["check", "--message-format", "json", graph.to_str().unwrap()]);
    assert_eq!(code, 0, "{out}");
    let w: serde_json::Value = serde_json::from_str(out.trim()).unwrap_or_else(|e| panic!("{e}: {out}"));
    assert_eq!(
        (&w["level"], &w["node"], &w["line"]),
        (&serde_json::json!("warning"), &serde_json::json!("sim"), &serde_json::json!(2))
    );
    assert!(w["help"].as_str().unwrap().contains("record"), "{w}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// The command line of `werkstatt test`: exit code 1 on a regression (here a missing
/// reference), 0 after --bless; `report merge` of one shard.
#[test]
fn test_command_exits_non_zero_on_a_regression() {
    let dir = temp("test-command");
    let (refs, out) = (dir.join("refs"), dir.join("out"));
    let args = |extra: &[&str]| -> Vec<String> {
        let mut a: Vec<String> =
            ["test", "graphs/scalars.ron", "--references", refs.to_str().unwrap(), "--out", out.to_str().unwrap()]
                .iter()
                .map(|s| s.to_string())
                .collect();
        a.extend(extra.iter().map(|s| s.to_string()));
        a
    };
    let run = |a: Vec<String>| werkstatt(&a.iter().map(String::as_str).collect::<Vec<_>>());
    let (code, _, err) = run(args(&[]));
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("no reference for case \"scalars\""), "{err}");
    assert_eq!(run(args(&["--bless"])).0, 0);
    let (code, _, err) = run(args(&["--shard", "0/1"]));
    assert_eq!(code, 0, "{err}");
    let (code, _, err) = run(args(&["--shard", "1/1"]));
    assert_eq!(code, 1);
    assert!(err.contains("shard 1 of 1 does not exist"), "{err}");
    let merged = dir.join("merged");
    let (code, _, err) = werkstatt(&["report", "merge", out.to_str().unwrap(), "--out", merged.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(merged.join("junit.xml").is_file() && merged.join("scalars/stats.json").is_file());
    std::fs::remove_dir_all(dir).unwrap();
}

const MISSING_MESH: &str = r#"(version: 1, nodes: {
    "m": (kind: "MeshFile", params: {"path": "garmnet.obj"}),
    "draw": (kind: "Draw"),
    "export": (kind: "ExportGeometry"),
}, links: [("m.mesh", "draw.mesh"), ("draw.scene", "export.scene")])"#;

/// A misspelt file fails `check` and `render` at once, at its line and column, with the
/// closest name in its folder.
#[test]
fn a_missing_file_is_an_error_in_check_and_render_with_a_did_you_mean() {
    let (dir, graph) = graph_file("missing-file", MISSING_MESH);
    std::fs::write(dir.join("garment.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let (code, _, err) = werkstatt(&["check", graph.to_str().unwrap()]);
    assert_eq!(code, 1, "{err}");
    let missing = dir.join("garmnet.obj");
    let error = format!(
        "{}:2:38: error: node \"m\" (MeshFile): parameter \"path\": no such file: {}; did you mean \"garment.obj\"?",
        graph.display(),
        missing.display()
    );
    assert!(err.contains(&error), "expected {error} in:\n{err}");
    let out = dir.join("out");
    let (code, _, err) = werkstatt(&["render", graph.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert_eq!(code, 1);
    assert!(err.contains(&error.replace(": error:", ":")), "{err}");
    assert!(!out.join("export_0000.obj").exists());
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn check_warns_about_a_live_link_in_batch() {
    let (dir, graph) = graph_file("live-link-check", r#"(version: 1, nodes: {"sim": (kind: "LiveLink")}, links: [])"#);
    let (code, _, err) = werkstatt(&["check", graph.to_str().unwrap()]);
    assert_eq!(code, 0, "{err}");
    assert!(err.contains("node \"sim\" (LiveLink): waits for a simulator"), "{err}");
    assert!(err.contains("record"), "the warning says how to record a session: {err}");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn set_typos_get_did_you_mean() {
    for (set, needle) in [
        ("camra.fov=40", "there is no node \"camra\"; did you mean \"camera\"?"),
        ("camera.fow=40", "has no parameter \"fow\"; did you mean \"fov\"?"),
    ] {
        let (code, _, err) = werkstatt(&["render", "graphs/still_life.ron", "--set", set]);
        assert_eq!(code, 1, "{set}");
        assert!(err.contains(needle), "{set}: {err}");
    }
}

#[test]
fn dump_format_chooses_png_tone_mapped_or_exr() {
    let dir = temp("dump-format");
    let render = |extra: &[&str]| {
        let out = dir.join(extra.join("-"));
        let mut args = vec!["render", "graphs/still_life.ron", "--size", "32x24", "--dump", "gbuffer.depth"];
        args.extend_from_slice(extra);
        args.extend_from_slice(&["--out", out.to_str().unwrap()]);
        let (code, _, err) = werkstatt(&args);
        assert_eq!(code, 0, "{err}");
        out
    };
    // Float textures default to EXR.
    assert!(render(&[]).join("gbuffer.depth_0000.exr").exists());
    let png = image::open(render(&["--dump-format", "png"]).join("gbuffer.depth_0000.png")).unwrap().to_rgba8();
    // Depths of a few metres would all clip to white; tone mapped they stay below it.
    let covered: Vec<u8> = png.pixels().map(|p| p[0]).filter(|&r| r > 0).collect();
    assert!(!covered.is_empty() && covered.iter().all(|&r| r < 255), "{covered:?}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// --ssaa renders at N x the size and writes images at the asked size, box-filtered: a
/// silhouette gets intermediate values that a 1-sample render never has.
#[test]
fn ssaa_writes_the_asked_size_with_smoothed_edges() {
    let dir = temp("ssaa");
    let total_variation = |ssaa: &str| {
        let out = dir.join(ssaa);
        let args =
            ["render", "graphs/still_life.ron", "--size", "40x30", "--ssaa", ssaa, "--out", out.to_str().unwrap()];
        let (code, _, err) = werkstatt(&args);
        assert_eq!(code, 0, "{err}");
        let png = image::open(out.join("image_0000.png")).unwrap().to_rgba8();
        assert_eq!((png.width(), png.height()), (40, 30));
        assert_eq!(read_stats(&out)["ssaa"], ssaa.parse::<u64>().unwrap());
        // Total variation: the sum of steps between horizontal neighbours; stair steps add to it.
        let mut tv = 0u64;
        for y in 0..png.height() {
            for x in 1..png.width() {
                let (a, b) = (png.get_pixel(x - 1, y).0, png.get_pixel(x, y).0);
                tv += (0..3).map(|c| a[c].abs_diff(b[c]) as u64).sum::<u64>();
            }
        }
        tv
    };
    let (plain, smooth) = (total_variation("1"), total_variation("3"));
    assert!(smooth * 10 < plain * 9, "total variation {plain} without SSAA, {smooth} with");
    let (code, _, err) = werkstatt(&["render", "graphs/still_life.ron", "--size", "4000x100", "--ssaa", "3"]);
    assert_eq!(code, 1);
    assert!(err.contains("over the limit of 8192"), "{err}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// A load that never finishes (a FIFO nobody writes, as a hung network mount would behave)
/// fails the frame after --pending-timeout with a message naming the node and the file,
/// instead of hanging the CI job.
#[cfg(unix)]
#[test]
fn a_load_that_never_finishes_fails_after_the_pending_timeout() {
    let dir = temp("pending-timeout");
    let fifo = dir.join("hung.obj");
    let made = Command::new("mkfifo").arg(&fifo).status().expect("mkfifo runs");
    assert!(made.success());
    let graph = dir.join("g.ron");
    std::fs::write(
        &graph,
        r#"(version: 1, nodes: {
            "mesh": (kind: "MeshFile", params: {"path": "hung.obj"}),
            "draw": (kind: "Draw"),
            "export": (kind: "ExportGeometry"),
        }, links: [("mesh.mesh", "draw.mesh"), ("draw.scene", "export.scene")])"#,
    )
    .unwrap();
    let out = dir.join("out");
    let started = std::time::Instant::now();
    let (code, _, err) =
        werkstatt(&["render", graph.to_str().unwrap(), "--pending-timeout", "0.5", "--out", out.to_str().unwrap()]);
    assert_eq!(code, 1, "{err}");
    assert!(
        err.contains("frame 0: still pending after 0.5 s (--pending-timeout)")
            && err.contains("node \"mesh\" (MeshFile) is still waiting for")
            && err.contains("hung.obj"),
        "{err}"
    );
    // Not a timed assertion on speed: only that the 120 s default did not apply.
    assert!(started.elapsed() < std::time::Duration::from_secs(100), "the timeout was not applied");
    let (code, _, err) = werkstatt(&["render", graph.to_str().unwrap(), "--pending-timeout=-1"]);
    assert_eq!(code, 1);
    assert!(err.contains("--pending-timeout must be a number of seconds"), "{err}");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn bench_all_writes_every_benchs_rows_and_a_summary_within_its_budget() {
    let dir = temp("bench-all");
    let d = dir.to_str().unwrap();
    let (code, out, err) = werkstatt(&["bench", "all", "--json", d, "--preset", "small", "--only", "ssao,pem-memory"]);
    assert_eq!(code, 0, "{out}\n{err}");
    let all: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("all.json")).unwrap()).unwrap();
    assert_eq!(all["preset"], "small");
    let benches = all["benches"].as_array().unwrap();
    // The fixed order, whatever the order of --only.
    let names: Vec<&str> = benches.iter().map(|b| b["name"].as_str().unwrap()).collect();
    assert_eq!(names, ["pem-memory", "ssao"]);
    assert!(benches.iter().all(|b| b["status"] == "ok"), "{benches:?}");
    let ssao: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("ssao.json")).unwrap()).unwrap();
    let rows = ssao.as_array().unwrap();
    assert_eq!(rows.len(), 4, "two modes at full and half resolution");
    assert!(rows.iter().all(|r| r["ms_per_frame"].as_f64().unwrap() > 0.0));
    let summary = std::fs::read_to_string(dir.join("summary.md")).unwrap();
    assert!(summary.contains("## ssao") && summary.contains("under 1 ms"), "{summary}");
    assert!(summary.contains("| 256 | 256.00 | 384 | 1024.00 | 1536 |"), "Table 5.1's last row: {summary}");

    // A spent budget skips what would start after it, and says so.
    let (code, out, err) = werkstatt(&["bench", "all", "--json", d, "--only", "ssao", "--budget-s", "0"]);
    assert_eq!(code, 0, "{out}\n{err}");
    let all: serde_json::Value = serde_json::from_slice(&std::fs::read(dir.join("all.json")).unwrap()).unwrap();
    assert!(all["benches"][0]["status"].as_str().unwrap().starts_with("skipped"), "{all}");
    assert!(std::fs::read_to_string(dir.join("summary.md")).unwrap().contains("Not measured: skipped"));

    let (code, _, err) = werkstatt(&["bench", "all", "--json", d, "--only", "ssoa"]);
    assert_ne!(code, 0);
    assert!(err.contains("\"ssoa\"") && err.contains("attachments, table1"), "{err}");
}

/// `bench editor` plays a graph's loop through the editor's evaluation: every frame of the
/// first loop evaluated, the replay from kept pictures, the turning view at half size.
#[cfg(feature = "editor")]
#[test]
fn bench_editor_measures_the_first_loop_the_replay_and_the_turning_view() {
    let dir = temp("bench-editor");
    let json = dir.join("editor.json");
    let (code, out, err) = werkstatt(&[
        "bench",
        "editor",
        "--graph",
        "graphs/still_life.ron",
        "--size",
        "64x48",
        "--frames",
        "3",
        "--orbit-steps",
        "2",
        "--json",
        json.to_str().unwrap(),
    ]);
    assert_eq!(code, 0, "{out}\n{err}");
    assert!(out.contains("| replay (kept pictures) | 64x48 | 3 | 0 |"), "{out}");
    let rows: serde_json::Value = serde_json::from_slice(&std::fs::read(&json).unwrap()).unwrap();
    let field = |i: usize, name: &str| rows[i][name].as_u64().unwrap();
    let phases: Vec<&str> = rows.as_array().unwrap().iter().map(|r| r["phase"].as_str().unwrap()).collect();
    assert_eq!(phases.len(), 5, "{phases:?}");
    // Frames 1 and 2 evaluated once each; the replay of 0..3 all from kept pictures.
    assert_eq!((field(1, "samples"), field(1, "evaluations")), (2, 2), "{rows}");
    assert_eq!((field(2, "samples"), field(2, "evaluations")), (3, 0), "{rows}");
    // Each turn of the view is one evaluation, at half size while turning.
    assert_eq!((field(3, "width"), field(3, "height"), field(3, "evaluations")), (32, 24, 2), "{rows}");
    assert_eq!((field(4, "width"), field(4, "evaluations")), (64, 2), "{rows}");
    assert!(rows.as_array().unwrap().iter().all(|r| r["median_ms"].as_f64().unwrap() > 0.0), "{rows}");

    // A graph without an orbit camera is refused, naming it.
    let (code, _, err) = werkstatt(&["bench", "editor", "--graph", "graphs/scalars.ron", "--frames", "2"]);
    assert_ne!(code, 0);
    assert!(err.contains("scalars.ron") && err.contains("no orbit camera"), "{err}");
    std::fs::remove_dir_all(dir).unwrap();
}

//! `werkstatt test` (werkstatt::app::regress): every graph in graphs/ against its references in
//! tests/references (the project's own image regression, run by `cargo test`), and the
//! command's behaviour on small graphs: a changed parameter fails with a diff image and a
//! JUnit failure, `--bless` accepts it, shards merge to the unsharded run, a missing reference
//! is a clear error.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use werkstatt::app::regress::{self, Status, TestOptions, TestRun};

use crate::common::*;

fn run(opts: &TestOptions) -> TestRun {
    regress::run(opts, gpu(), |_| {}).unwrap_or_else(|e| panic!("werkstatt test: {e:#}"))
}

fn failures(run: &TestRun) -> String {
    run.cases
        .iter()
        .filter(|c| matches!(c.status, Status::Failed | Status::Error))
        .map(|c| format!("{}: {}", c.name, c.message.as_deref().unwrap_or("")))
        .collect::<Vec<_>>()
        .join("\n")
}

/// The project's CI: `werkstatt test tests/references/manifest.ron` over graphs/ passes on
/// lavapipe. After an intended change, look at target/test-out/regression-graphs/report.html,
/// then re-bless: `cargo run -- test tests/references/manifest.ron --bless`.
#[test]
fn every_graph_matches_its_references() {
    let out = out_dir("regression-graphs");
    let opts = TestOptions::new(vec![root().join("tests/references/manifest.ron")], out.clone());
    let result = run(&opts);
    let graphs = std::fs::read_dir(root().join("graphs"))
        .unwrap()
        .filter(|e| e.as_ref().unwrap().path().extension().is_some_and(|x| x == "ron"))
        .count();
    assert_eq!(result.cases.len(), graphs, "one case per graph in graphs/");
    assert!(
        !result.regressed(),
        "{}\n{}\nsee {}/report.html; if the change is intended: cargo run -- test tests/references/manifest.ron --bless",
        result.summary(),
        failures(&result),
        out.display()
    );
    let livelink = result.cases.iter().find(|c| c.name == "livelink").unwrap();
    assert_eq!(livelink.status, Status::Passed, "livelink.ron fails at once, as the manifest expects");
    assert!(std::fs::read_to_string(out.join("junit.xml")).unwrap().contains("failures=\"0\" errors=\"0\""));
}

/// A folder of references for `graphs` (copies of graphs/ files), blessed once.
fn blessed(name: &str, graphs: &[&str], sets: &[&str]) -> (PathBuf, TestOptions) {
    let dir = out_dir(name);
    let mut opts = TestOptions::new(graphs.iter().map(|g| root().join("graphs").join(g)).collect(), dir.join("out"));
    opts.references = dir.join("references");
    std::fs::create_dir_all(&opts.references).unwrap();
    // Timings are flagged against the references', never in these tests' results.
    std::fs::write(opts.references.join("manifest.ron"), "(size: (32, 24), tolerance: (slowdown: 1e9))").unwrap();
    opts.sets = sets.iter().map(|s| s.to_string()).collect();
    opts.bless = true;
    let r = run(&opts);
    assert_eq!(r.count(Status::Blessed), r.cases.len(), "{}", failures(&r));
    opts.bless = false;
    (dir, opts)
}

#[test]
fn a_changed_parameter_fails_with_a_diff_image_and_a_junit_failure_and_bless_accepts_it() {
    let (_dir, mut opts) = blessed("regression-changed", &["spot.ron"], &[]);
    assert!(!run(&opts).regressed(), "the blessed outputs pass");
    opts.sets = vec!["light.sun_intensity=0.5".into()];
    let r = run(&opts);
    assert!(r.regressed());
    let case = &r.cases[0];
    assert_eq!(case.status, Status::Failed);
    let failing: Vec<&str> = case.outputs.iter().filter(|o| !o.passed).map(|o| o.name.as_str()).collect();
    assert!(failing.contains(&"preview_0000.png") && failing.contains(&"hdr_0000.exr"), "{failing:?}");
    let preview = case.outputs.iter().find(|o| o.name == "preview_0000.png").unwrap();
    assert!(preview.detail.contains("PSNR"), "{}", preview.detail);
    let [reference, current, diff] = preview.images.clone().unwrap();
    for view in [&reference, &current, &diff] {
        assert!(opts.out_dir.join(view).is_file(), "{view} was not written");
    }
    let diff = read_png(&opts.out_dir.join(diff));
    assert!(diff.pixels().any(|p| p[0] > 0 || p[1] > 0 || p[2] > 0), "the diff image is black");
    let junit = std::fs::read_to_string(opts.out_dir.join("junit.xml")).unwrap();
    assert!(junit.contains("failures=\"1\"") && junit.contains("<failure message=\""), "{junit}");
    assert!(junit.contains("preview_0000.png: PSNR"), "{junit}");
    let html = std::fs::read_to_string(opts.out_dir.join("report.html")).unwrap();
    assert_eq!(html.matches("data:image/png;base64,").count(), 6, "reference, current and diff of both images");

    opts.bless = true;
    assert_eq!(run(&opts).count(Status::Blessed), 1);
    opts.bless = false;
    let r = run(&opts);
    assert!(!r.regressed(), "after --bless the changed outputs are the references: {}", failures(&r));
}

/// Deleting the still life's shadow link loses every shadow: the project's own regression
/// case for still_life.ron fails on it, at the manifest's tolerances and at the defaults (by the
/// pixel budget: soft shadows cost little PSNR and almost no SSIM, 42.6 dB and 0.9988 here).
/// The report names the overrides and that the graph changed since the bless.
#[test]
fn losing_every_shadow_of_the_still_life_fails_its_regression_case() {
    let dir = out_dir("regression-shadows");
    let manifest = regress::Manifest::load(&root().join("tests/references/manifest.ron")).unwrap();
    let case = &manifest.cases["still_life"];
    let graph = dir.join("still_life.ron");
    // A copy outside graphs/: its relative asset paths made absolute.
    let original = std::fs::read_to_string(root().join("graphs/still_life.ron"))
        .unwrap()
        .replace("\"../assets/", &format!("\"{}/", root().join("assets").display()));
    let link = "(\"shadow_atlas.shadows\", \"light.shadows\"),";
    assert!(original.contains(link), "graphs/still_life.ron feeds the light its shadows");
    std::fs::write(&graph, &original).unwrap();
    let mut opts = TestOptions::new(vec![graph.clone()], dir.join("out"));
    opts.references = dir.join("references");
    opts.sets = case.sets.clone();
    std::fs::create_dir_all(&opts.references).unwrap();
    let write_manifest = |tolerance: &str| {
        let (w, h) = manifest.size;
        let text = format!("(size: ({w}, {h}), tolerance: ({tolerance}slowdown: 1e9))");
        std::fs::write(opts.references.join("manifest.ron"), text).unwrap();
    };
    let t = manifest.tolerance.image;
    write_manifest(&format!(
        "image: (threshold: {}, max_failing: {}, min_psnr: {}, min_ssim: {}), ",
        t.threshold, t.max_failing, t.min_psnr, t.min_ssim
    ));
    opts.bless = true;
    run(&opts);
    opts.bless = false;
    let same = run(&opts);
    assert!(!same.regressed(), "{}", failures(&same));
    assert_eq!(same.cases[0].graph_changed, Some(false));

    std::fs::write(&graph, original.replace(link, "")).unwrap();
    let check = |r: &TestRun| {
        let c = &r.cases[0];
        assert_eq!(c.status, Status::Failed, "{}", failures(r));
        assert_eq!(c.graph_changed, Some(true));
        assert_eq!(c.sets, case.sets);
        let image = c.outputs.iter().find(|o| o.name.ends_with(".png") && !o.passed).expect("a failing image");
        assert!(image.detail.contains("SSIM") && image.detail.contains("% of pixels"), "{}", image.detail);
        let junit = std::fs::read_to_string(opts.out_dir.join("junit.xml")).unwrap();
        assert!(junit.contains("changed since the last bless") && junit.contains(&case.sets[0]), "{junit}");
    };
    check(&run(&opts));
    write_manifest("");
    check(&run(&opts));
}

#[test]
fn a_missing_reference_is_a_clear_error() {
    let dir = out_dir("regression-missing");
    let mut opts = TestOptions::new(vec![root().join("graphs/scalars.ron")], dir.join("out"));
    opts.references = dir.join("references");
    let r = run(&opts);
    assert!(r.regressed());
    let case = &r.cases[0];
    assert_eq!(case.status, Status::Error);
    let msg = case.message.clone().unwrap();
    let expected = dir.join("references/scalars/reference.ron");
    assert!(
        msg.contains("no reference for case \"scalars\"") && msg.contains(&expected.display().to_string()),
        "{msg}"
    );
    assert!(msg.contains("--bless"), "{msg}");
    let junit = std::fs::read_to_string(opts.out_dir.join("junit.xml")).unwrap();
    assert!(junit.contains("errors=\"1\"") && junit.contains("<error message=\"no reference"), "{junit}");
}

/// The reports with their timings blanked out: everything else is deterministic.
fn without_timings(path: &Path) -> String {
    let text = std::fs::read_to_string(path).unwrap();
    let mut out = String::new();
    for line in text.lines() {
        let mut l = line.to_string();
        for key in [
            "time=\"",
            "\"render_ms\": ",
            "\"compare_ms\": ",
            "\"reference_ms\": ",
            "time: ",
            "<td>",
            "render ",
            "compare ",
        ] {
            let mut from = 0;
            while let Some(i) = l[from..].find(key).map(|i| i + from + key.len()) {
                let end = l[i..].find(|c: char| !(c.is_ascii_digit() || c == '.')).map_or(l.len(), |e| i + e);
                l.replace_range(i..end, "#");
                from = i;
            }
        }
        out.push_str(&l);
        out.push('\n');
    }
    out
}

fn drop_timings(v: &mut serde_json::Value) {
    match v {
        serde_json::Value::Object(o) => {
            // `gpu_created` counts the textures and buffers a frame had to create: it depends on
            // what the device's pools kept from earlier work (tests share devices), like a timing.
            o.retain(|k, _| {
                !["wall_ms", "total_ms", "phases", "cpu_ms", "gpu_ms", "gpu_created"].contains(&k.as_str())
            });
            o.values_mut().for_each(drop_timings);
        }
        serde_json::Value::Array(a) => a.iter_mut().for_each(drop_timings),
        _ => {}
    }
}

/// Every file of the case folders under `dir`; stats.json without its timings.
fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut out = BTreeMap::new();
    for case in std::fs::read_dir(dir).unwrap() {
        let case = case.unwrap().path();
        if case.is_dir() {
            for f in std::fs::read_dir(&case).unwrap() {
                let f = f.unwrap().path();
                let name = f.strip_prefix(dir).unwrap().display().to_string();
                let mut bytes = std::fs::read(&f).unwrap();
                // stats.json holds the run's timings; the rest of it must match too.
                if name.ends_with("stats.json") {
                    let mut json: serde_json::Value = serde_json::from_slice(&bytes).unwrap();
                    drop_timings(&mut json);
                    bytes = json.to_string().into_bytes();
                }
                out.insert(name, bytes);
            }
        }
    }
    out
}

#[test]
fn shards_merge_to_the_unsharded_run_and_sweeps_name_their_variants() {
    let sweep = ["light.sun_intensity=1,2", "camera.fov=30,50"];
    let (dir, opts) = blessed("regression-shards", &["spot.ron", "scalars.ron", "tablecloth.ron"], &[]);
    let mut opts = opts;
    // A sweep of spot.ron on its own references; scalars and tablecloth have no such nodes.
    opts.inputs = vec![root().join("graphs/spot.ron")];
    opts.sets = sweep.iter().map(|s| s.to_string()).collect();
    opts.bless = true;
    run(&opts);
    opts.bless = false;
    opts.inputs = ["spot.ron", "scalars.ron", "tablecloth.ron"].iter().map(|g| root().join("graphs").join(g)).collect();
    opts.sets.clear();
    let sweep_file = dir.join("sweep.ron");
    std::fs::write(&sweep_file, "[\"light.sun_intensity=1,2\", \"camera.fov=30,50\"]").unwrap();

    // The sweep's cases, in order: first axis slowest.
    let mut spot = opts.clone();
    spot.inputs = vec![root().join("graphs/spot.ron")];
    spot.sweep_file = Some(sweep_file.clone());
    let names: Vec<String> = regress::plan(&spot).unwrap().into_iter().map(|c| c.name).collect();
    assert_eq!(
        names,
        [
            "spot@light.sun_intensity=1+camera.fov=30",
            "spot@light.sun_intensity=1+camera.fov=50",
            "spot@light.sun_intensity=2+camera.fov=30",
            "spot@light.sun_intensity=2+camera.fov=50"
        ]
    );

    // Unsharded: the plain graphs and the sweep, all against their references.
    let whole = dir.join("whole");
    let mut all = vec![opts.clone(), spot.clone()];
    all[0].out_dir = whole.join("plain");
    all[1].out_dir = whole.join("sweep");
    for o in &all {
        let r = run(o);
        assert!(!r.regressed(), "{}", failures(&r));
    }
    for (label, base) in [("plain", &opts), ("sweep", &spot)] {
        for n in [2, 3] {
            let shards: Vec<PathBuf> = (0..n)
                .map(|i| {
                    let mut o = base.clone();
                    o.shard = (i, n);
                    o.out_dir = dir.join(format!("{label}-shard-{i}-of-{n}"));
                    let r = run(&o);
                    assert!(r.cases.len() < r.plan.len() || n == 1, "a shard runs part of the plan");
                    o.out_dir
                })
                .collect();
            let merged = dir.join(format!("{label}-merged-{n}"));
            let m = regress::merge(&shards, &merged).unwrap();
            let unsharded = whole.join(label);
            assert_eq!(m.cases.len(), m.plan.len());
            let (a, b) = (files(&merged), files(&unsharded));
            assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>(), "{label}, {n} shards");
            for (name, bytes) in &a {
                assert!(*bytes == b[name], "{label}, {n} shards: {name} differs from the unsharded run's");
            }
            for report in ["results.json", "junit.xml", "report.html"] {
                assert_eq!(
                    without_timings(&merged.join(report)),
                    without_timings(&unsharded.join(report)),
                    "{label}, {n} shards: {report}"
                );
            }
            // A missing shard is an error that names the cases it would have run.
            let err = regress::merge(&shards[1..], &dir.join("partial")).unwrap_err();
            assert!(format!("{err:#}").contains("in none of the shards"), "{err:#}");
        }
    }
}

/// The manifest shown in docs/ci.md is one that `werkstatt test` reads.
#[test]
fn the_manifest_in_the_docs_parses() {
    let doc = std::fs::read_to_string(root().join("docs/ci.md")).unwrap();
    let start = doc.find("```ron\n").expect("a ron block in docs/ci.md") + 7;
    let text = &doc[start..start + doc[start..].find("```").unwrap()];
    let path = out_dir("regression-doc-manifest").join("manifest.ron");
    std::fs::write(&path, text).unwrap();
    let m = regress::Manifest::load(&path).unwrap_or_else(|e| panic!("{e:#}"));
    assert_eq!(m.size, (48, 36));
    assert_eq!(m.cases["spot"].outputs["hdr_0000.exr"].exr.threshold, 0.05);
    assert_eq!(m.cases["default"].size, Some((64, 48)));
}

/// A slowdown is flagged, not failed, unless asked for. (A `slowdown` tolerance of 0 makes
/// every render "slower than its reference", so nothing here depends on the machine's speed.)
#[test]
fn a_slowdown_is_flagged_and_fails_only_when_asked() {
    let (_dir, mut opts) = blessed("regression-slow", &["scalars.ron"], &[]);
    std::fs::write(opts.references.join("manifest.ron"), "(size: (32, 24), tolerance: (slowdown: 0.0))").unwrap();
    let r = run(&opts);
    assert!(r.cases[0].slow && !r.regressed(), "{}", failures(&r));
    assert!(std::fs::read_to_string(opts.out_dir.join("report.html")).unwrap().contains("class=\"slow\""));
    opts.fail_on_slowdown = true;
    let r = run(&opts);
    assert_eq!(r.cases[0].status, Status::Failed);
    assert!(r.cases[0].message.as_deref().unwrap().contains("--fail-on-slowdown"), "{}", failures(&r));
}

/// `frames_per_case` splits a graph's frames into cases (so shards share out animations):
/// named by their frames, each rendering what one run over all frames renders (ClothSim
/// replays the frames before a case's first).
#[test]
fn frames_split_into_cases_render_what_one_run_renders() {
    let dir = out_dir("regression-frames");
    let mut opts = TestOptions::new(vec![root().join("graphs/tablecloth.ron")], dir.join("split"));
    opts.references = dir.join("references");
    std::fs::create_dir_all(&opts.references).unwrap();
    std::fs::write(
        opts.references.join("manifest.ron"),
        "(size: (32, 24), frames: (0, 3), frames_per_case: 2, tolerance: (slowdown: 1e9))",
    )
    .unwrap();
    let names: Vec<String> = regress::plan(&opts).unwrap().into_iter().map(|c| c.name).collect();
    assert_eq!(names, ["tablecloth@frames=0-1", "tablecloth@frames=2-3"]);
    opts.bless = true;
    run(&opts);
    opts.bless = false;
    let split = run(&opts);
    assert!(!split.regressed(), "{}", failures(&split));
    let whole = dir.join("whole");
    let out = render_graph(&root().join("graphs/tablecloth.ron"), &whole, (0, 3), (32, 24), &[], &[]).unwrap();
    assert_eq!(out.files.len(), 4);
    for (case, images) in [
        ("tablecloth@frames=0-1", ["image_0000.png", "image_0001.png"]),
        ("tablecloth@frames=2-3", ["image_0002.png", "image_0003.png"]),
    ] {
        let mut written: Vec<String> = std::fs::read_dir(opts.out_dir.join(case))
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".png"))
            .collect();
        written.sort();
        assert_eq!(written, images, "{case} renders its frames only");
    }
    for (case, frame) in [("tablecloth@frames=0-1", 1), ("tablecloth@frames=2-3", 2), ("tablecloth@frames=2-3", 3)] {
        let file = format!("image_{frame:04}.png");
        assert!(
            std::fs::read(opts.out_dir.join(case).join(&file)).unwrap() == std::fs::read(whole.join(&file)).unwrap(),
            "{case}: {file} differs from a run over frames 0..3"
        );
    }
}

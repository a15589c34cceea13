//! Pull-from-outputs and caching, checked by counting node executions.

use std::time::{Duration, Instant};

use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
use werkstatt::core::graph::Graph;
use werkstatt::core::resources::Resources;

use crate::common::wait_idle;

fn graph(text: &str) -> Graph {
    Graph::load_str(text, "test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}"))
}

fn runs(ev: &Evaluator, id: &str) -> u64 {
    ev.report(id).map_or(0, |r| r.runs)
}

fn frame(n: i64) -> FrameTime {
    FrameTime { frame: n, fps: 30.0 }
}

const DIAMOND: &str = r#"(
    version: 1,
    nodes: {
        "x": (kind: "Number", params: {"value": 2.0}),
        "y": (kind: "Number", params: {"value": 3.0}),
        "sum": (kind: "Math", params: {"op": "add"}),
        "double": (kind: "Math", params: {"op": "multiply", "b": 2.0}),
        "unused": (kind: "Math", params: {"op": "add"}),
        "out": (kind: "Watch"),
        "time": (kind: "Time"),
        "wave": (kind: "Math", params: {"op": "sin", "b": 1.0}),
        "out_time": (kind: "Watch"),
    },
    links: [
        ("x.value", "sum.a"),
        ("y.value", "sum.b"),
        ("sum.result", "double.a"),
        ("double.result", "out.value"),
        ("x.value", "unused.a"),
        ("time.seconds", "wave.a"),
        ("wave.result", "out_time.value"),
    ],
)"#;

fn scalar(ev: &Evaluator, id: &str) -> f64 {
    match ev.output(id, "value") {
        Some(werkstatt::core::port::Value::Scalar(v)) => *v,
        _ => panic!("{id} has no scalar"),
    }
}

#[test]
fn only_nodes_feeding_an_output_run() {
    let g = graph(DIAMOND);
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    ev.evaluate(frame(0), None, &res, &FrameSettings::default());
    assert_eq!(runs(&ev, "unused"), 0, "a node that feeds no output must not run");
    assert_eq!(runs(&ev, "double"), 1);
    assert_eq!(scalar(&ev, "out"), 10.0);
    assert!(!ev.planned().any(|id| id == "unused"));
}

#[test]
fn unchanged_frames_skip_everything_but_time_readers() {
    let g = graph(DIAMOND);
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let s = FrameSettings::default();
    let first = ev.evaluate(frame(0), None, &res, &s);
    assert_eq!(first.ran, 8);
    // Same frame again: nothing runs.
    let again = ev.evaluate(frame(0), None, &res, &s);
    assert_eq!(again.ran, 0);
    // Next frame: only Time and what depends on it.
    let next = ev.evaluate(frame(1), None, &res, &s);
    assert_eq!(next.ran, 3);
    for id in ["x", "y", "sum", "double", "out"] {
        assert_eq!(runs(&ev, id), 1, "{id} re-ran although nothing it depends on changed");
    }
    for id in ["time", "wave", "out_time"] {
        assert_eq!(runs(&ev, id), 2, "{id} must re-run when the time changes");
    }
    assert!((scalar(&ev, "out_time") - (1.0f64 / 30.0).sin()).abs() < 1e-12);
}

#[test]
fn changing_one_parameter_reruns_that_node_and_its_dependents_only() {
    let mut g = graph(DIAMOND);
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let s = FrameSettings::default();
    ev.evaluate(frame(0), None, &res, &s);
    g.set_from_cli("y.value=5").unwrap();
    ev.update(&g, &[]).unwrap();
    let summary = ev.evaluate(frame(0), None, &res, &s);
    assert_eq!(summary.ran, 4, "y, sum, double, out");
    assert_eq!((runs(&ev, "x"), runs(&ev, "y"), runs(&ev, "sum"), runs(&ev, "out")), (1, 2, 2, 2));
    assert_eq!((runs(&ev, "time"), runs(&ev, "wave")), (1, 1));
    assert_eq!(scalar(&ev, "out"), 14.0);
}

#[test]
fn rewiring_reruns_the_consumer() {
    let mut g = graph(DIAMOND);
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let s = FrameSettings::default();
    ev.evaluate(frame(0), None, &res, &s);
    // Feed sum.b from x instead of y.
    g.links.retain(|l| l.to.to_string() != "sum.b");
    g.links.push(werkstatt::core::graph::Link {
        from: werkstatt::core::graph::PortRef::parse("x.value").unwrap(),
        to: werkstatt::core::graph::PortRef::parse("sum.b").unwrap(),
    });
    ev.update(&g, &[]).unwrap();
    ev.evaluate(frame(0), None, &res, &s);
    assert_eq!((runs(&ev, "x"), runs(&ev, "sum"), runs(&ev, "double")), (1, 2, 2));
    assert_eq!(runs(&ev, "y"), 1, "y no longer feeds an output and must not re-run");
    assert_eq!(scalar(&ev, "out"), 8.0);
}

#[test]
fn still_camera_is_not_time_dependent_but_orbiting_one_is() {
    let text = |speed: f64| {
        format!(
            r#"(version: 1, nodes: {{"cam": (kind: "OrbitCamera", params: {{"orbit_speed": {speed:?}}})}}, links: [])"#
        )
    };
    let res = Resources::new(false);
    let s = FrameSettings::default();
    for (speed, expected) in [(0.0, 1), (30.0, 3)] {
        let g = graph(&text(speed));
        let mut ev = Evaluator::new(&g, &["cam".to_string()]).unwrap();
        for f in 0..3 {
            ev.evaluate(frame(f), None, &res, &s);
        }
        assert_eq!(runs(&ev, "cam"), expected, "orbit_speed {speed}");
    }
}

#[test]
fn a_failing_node_blocks_its_consumers_and_recovers() {
    let mut g = graph(
        r#"(version: 1, nodes: {
            "div": (kind: "Math", params: {"op": "divide", "a": 1.0, "b": 0.0}),
            "out": (kind: "Watch"),
        }, links: [("div.result", "out.value")])"#,
    );
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let s = FrameSettings::default();
    let sum = ev.evaluate(frame(0), None, &res, &s);
    assert_eq!(sum.failed, 1);
    assert!(matches!(ev.report("div").unwrap().status, NodeStatus::Failed(m) if m.contains("division by zero")));
    assert!(matches!(ev.report("out").unwrap().status, NodeStatus::Blocked(m) if m.contains("\"div\"")));
    // A failed node is not retried every frame while nothing changes.
    ev.evaluate(frame(0), None, &res, &s);
    assert_eq!(runs(&ev, "div"), 1);
    g.set_from_cli("div.b=4").unwrap();
    ev.update(&g, &[]).unwrap();
    ev.evaluate(frame(0), None, &res, &s);
    assert_eq!(scalar(&ev, "out"), 0.25);
}

#[test]
fn watch_range_violation_fails() {
    let g = graph(
        r#"(version: 1, nodes: {"n": (kind: "Number", params: {"value": 5.0}), "w": (kind: "Watch", params: {"max": 1.0})}, links: [("n.value", "w.value")])"#,
    );
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    ev.evaluate(frame(0), None, &Resources::new(false), &FrameSettings::default());
    assert!(
        matches!(ev.report("w").unwrap().status, NodeStatus::Failed(m) if m.contains("outside the accepted range"))
    );
}

const TRIANGLE_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nf 1/1 2/2 3/3\n";
const QUAD_OBJ: &str = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nf 1 2 3 4\n";

/// How long a test waits for loads and file events before it fails.
const WAIT: Duration = Duration::from_secs(20);

/// Replaces `path` the way editors save: a complete temporary file renamed over it, so no
/// reader ever sees a truncated file.
fn save_by_rename(path: &std::path::Path, text: &str) {
    let tmp = path.with_extension("tmp~");
    std::fs::write(&tmp, text).unwrap();
    std::fs::rename(&tmp, path).unwrap();
}

fn temp_dir(name: &str) -> std::path::PathBuf {
    let dir = std::env::temp_dir().join(format!("werkstatt-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

fn mesh_graph(path: &std::path::Path) -> Graph {
    graph(&format!(
        r#"(version: 1, nodes: {{"mesh": (kind: "MeshFile", params: {{"path": {:?}, "normalize": false}})}}, links: [])"#,
        path.display().to_string()
    ))
}

fn triangles(ev: &Evaluator) -> usize {
    match ev.output("mesh", "mesh") {
        Some(werkstatt::core::port::Value::Mesh(m)) => m.triangle_count(),
        _ => 0,
    }
}

#[test]
fn resources_load_lazily_then_the_node_reruns() {
    let dir = temp_dir("lazy");
    let path = dir.join("tri.obj");
    std::fs::write(&path, TRIANGLE_OBJ).unwrap();
    let g = mesh_graph(&path);
    let mut ev = Evaluator::new(&g, &["mesh".to_string()]).unwrap();
    let res = Resources::new(false);
    let s = FrameSettings::default();
    let first = ev.evaluate(frame(0), None, &res, &s);
    // The interactive loop does not wait: the node is pending (unless the load won the race).
    if first.pending == 1 {
        assert!(matches!(ev.report("mesh").unwrap().status, NodeStatus::Pending(_)));
        wait_idle(&res);
        ev.evaluate(frame(0), None, &res, &s);
    }
    assert_eq!(ev.report("mesh").unwrap().status, &NodeStatus::Ok);
    assert_eq!(triangles(&ev), 1);
    let runs_now = runs(&ev, "mesh");
    ev.evaluate(frame(1), None, &res, &s);
    assert_eq!(runs(&ev, "mesh"), runs_now, "a loaded resource does not re-run its node");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn missing_and_corrupt_files_are_errors_naming_the_path() {
    let dir = temp_dir("corrupt");
    let bad = dir.join("bad.obj");
    std::fs::write(&bad, "v 0 0 0\nf 1 2 7\n").unwrap();
    for path in [dir.join("missing.obj"), bad] {
        let g = mesh_graph(&path);
        let mut ev = Evaluator::new(&g, &["mesh".to_string()]).unwrap();
        let res = Resources::new(false);
        ev.evaluate(frame(0), None, &res, &FrameSettings::default());
        wait_idle(&res);
        ev.evaluate(frame(0), None, &res, &FrameSettings::default());
        match ev.report("mesh").unwrap().status {
            NodeStatus::Failed(m) => assert!(m.contains(&path.display().to_string()), "{m}"),
            other => panic!("expected an error, got {other:?}"),
        }
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn edited_files_reload_in_watch_mode() {
    let dir = temp_dir("reload");
    let path = dir.join("shape.obj");
    std::fs::write(&path, TRIANGLE_OBJ).unwrap();
    let g = mesh_graph(&path);
    let mut ev = Evaluator::new(&g, &["mesh".to_string()]).unwrap();
    let res = Resources::new(true);
    let s = FrameSettings::default();
    ev.evaluate(frame(0), None, &res, &s);
    wait_idle(&res);
    ev.evaluate(frame(0), None, &res, &s);
    assert_eq!(triangles(&ev), 1);
    // Saved by rename (one complete file, as editors save), then polled until the reload is
    // in: no assumption about how many events arrive or in which order loads finish.
    save_by_rename(&path, QUAD_OBJ);
    let deadline = Instant::now() + WAIT;
    while triangles(&ev) != 2 {
        assert!(
            Instant::now() < deadline,
            "the edited file was not reloaded within {WAIT:?}; status {:?}",
            ev.report("mesh").unwrap().status
        );
        std::thread::sleep(Duration::from_millis(20));
        ev.evaluate(frame(0), None, &res, &s);
    }
    assert_eq!(ev.report("mesh").unwrap().status, &NodeStatus::Ok);
    std::fs::remove_dir_all(dir).unwrap();
}

/// Two quick edits start two loads of one file; the one that read the older text may finish
/// last and must not replace the newer value.
#[test]
fn an_older_load_finishing_last_keeps_the_newer_value() {
    use std::sync::atomic::{AtomicBool, Ordering};
    static OLD_READ: AtomicBool = AtomicBool::new(false);
    fn slow_on_old(path: &std::path::Path) -> anyhow::Result<String> {
        let text = std::fs::read_to_string(path)?;
        if text == "old" {
            OLD_READ.store(true, Ordering::SeqCst);
            std::thread::sleep(Duration::from_millis(600));
        }
        Ok(text)
    }
    let dir = temp_dir("load-order");
    let path = std::path::absolute(dir.join("value.txt")).unwrap();
    std::fs::write(&path, "old").unwrap();
    let res = Resources::new(false);
    let _ = res.request(&path, slow_on_old);
    let deadline = Instant::now() + WAIT;
    while !OLD_READ.load(Ordering::SeqCst) {
        assert!(Instant::now() < deadline, "the first load never started");
        std::thread::sleep(Duration::from_millis(5));
    }
    save_by_rename(&path, "new");
    res.reload(&path);
    wait_idle(&res);
    let (_, value) = res.request(&path, slow_on_old);
    assert_eq!(value.unwrap().as_str(), "new", "the older load overwrote the newer one");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn idle_frames_of_a_large_graph_run_nothing() {
    let g = werkstatt::app::chain_graph(200);
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let s = FrameSettings::default();
    assert_eq!(ev.evaluate(frame(0), None, &res, &s).ran, 201);
    assert_eq!(scalar(&ev, "watch"), 200.0);
    for f in 1..50 {
        assert_eq!(ev.evaluate(frame(f), None, &res, &s).ran, 0);
    }
}

#[test]
fn a_refused_update_leaves_the_evaluator_working() {
    let g = graph(DIAMOND);
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let settings = FrameSettings::default();
    ev.evaluate(frame(0), None, &res, &settings);
    let before = runs(&ev, "sum");
    // An unconnected required input: the update is refused...
    let mut broken = g.clone();
    broken.links.retain(|l| l.to.node != "out");
    assert!(ev.update(&broken, &[]).is_err());
    assert!(ev.update(&g, &["nope".to_string()]).is_err());
    // ...and the evaluator still runs the graph it had, with its caches.
    ev.evaluate(frame(1), None, &res, &settings);
    assert_eq!(runs(&ev, "sum"), before);
    assert_eq!(ev.report("out").map(|r| r.status.clone()), Some(NodeStatus::Ok));
}

/// How many nodes the plan of `ev` ran in the last frame, by id.
fn ran_ids(ev: &Evaluator, ids: &[&str]) -> Vec<String> {
    ids.iter().filter(|id| ev.report(id).is_some_and(|r| r.ran)).map(|id| id.to_string()).collect()
}

#[test]
fn a_new_folder_reruns_every_planned_node_and_a_new_size_none_that_ignores_it() {
    let g = graph(DIAMOND);
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let planned = ["x", "y", "sum", "double", "out", "time", "wave", "out_time"];
    let small = FrameSettings { width: 64, height: 48, ..FrameSettings::default() };
    assert_eq!(ev.evaluate(frame(0), None, &res, &small).ran, planned.len());
    assert_eq!(ev.evaluate(frame(0), None, &res, &small).ran, 0, "the same settings run nothing");
    // Another size: no node here reads it (`EvalCx::frame_size`), so none re-runs.
    let wider = FrameSettings { width: 65, ..small.clone() };
    assert_eq!(ev.evaluate(frame(0), None, &res, &wider).ran, 0, "a new size");
    // Another folder: any node may resolve a path against it, so all re-run once.
    let moved = FrameSettings { base_dir: "elsewhere".into(), ..wider.clone() };
    assert_eq!(ev.evaluate(frame(0), None, &res, &moved).ran, planned.len(), "a new base folder");
    assert_eq!(ran_ids(&ev, &planned).len(), planned.len());
    assert_eq!(ev.evaluate(frame(0), None, &res, &moved).ran, 0);
    assert_eq!(scalar(&ev, "out"), 10.0);
}

#[test]
fn a_link_moved_to_another_output_of_the_same_node_reruns_its_consumer() {
    let text = r#"(version: 1, nodes: {"t": (kind: "Time"), "w": (kind: "Watch")}, links: [("t.seconds", "w.value")])"#;
    let mut g = graph(text);
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let s = FrameSettings::default();
    ev.evaluate(frame(60), None, &res, &s);
    assert_eq!(scalar(&ev, "w"), 2.0, "60 frames at 30 fps");
    g.links[0].from.port = "frame".into();
    ev.update(&g, &[]).unwrap();
    ev.evaluate(frame(60), None, &res, &s);
    assert_eq!(scalar(&ev, "w"), 60.0, "the consumer reads the other output now");
    assert_eq!(runs(&ev, "w"), 2);
}

#[test]
fn a_kind_change_under_the_same_id_gets_a_new_node() {
    let mut g = graph(
        r#"(version: 1, nodes: {"src": (kind: "Number", params: {"value": 5.0}), "w": (kind: "Watch")}, links: [("src.value", "w.value")])"#,
    );
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let s = FrameSettings::default();
    ev.evaluate(frame(90), None, &res, &s);
    assert_eq!(scalar(&ev, "w"), 5.0);
    // Same id, another kind (and so another output): the old instance must not be reused.
    let src = g.nodes.get_mut("src").unwrap();
    src.kind = "Time".into();
    src.params.clear();
    g.links[0].from.port = "seconds".into();
    ev.update(&g, &[]).unwrap();
    ev.evaluate(frame(90), None, &res, &s);
    assert_eq!(ev.report("src").unwrap().kind, "Time");
    assert_eq!(ev.report("src").unwrap().status, &NodeStatus::Ok);
    assert_eq!(scalar(&ev, "w"), 3.0, "90 frames at 30 fps");
}

#[test]
fn unlinking_an_optional_input_falls_back_to_the_parameter() {
    let mut g = graph(DIAMOND);
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let s = FrameSettings::default();
    ev.evaluate(frame(0), None, &res, &s);
    assert_eq!(scalar(&ev, "out"), 10.0, "(2 + 3) * 2");
    let sum_runs = runs(&ev, "sum");
    // sum.b loses its link: the parameter b (default 0) stands in.
    g.links.retain(|l| !(l.to.node == "sum" && l.to.port == "b"));
    ev.update(&g, &[]).unwrap();
    ev.evaluate(frame(0), None, &res, &s);
    assert_eq!(scalar(&ev, "out"), 4.0, "(2 + 0) * 2");
    assert_eq!(runs(&ev, "sum"), sum_runs + 1);
    // Linked again: the input wins over the parameter.
    g.set_from_cli("sum.b=100").unwrap();
    g.links.push(werkstatt::core::graph::Link {
        from: werkstatt::core::graph::PortRef::parse("y.value").unwrap(),
        to: werkstatt::core::graph::PortRef::parse("sum.b").unwrap(),
    });
    ev.update(&g, &[]).unwrap();
    ev.evaluate(frame(0), None, &res, &s);
    assert_eq!(scalar(&ev, "out"), 10.0);
}

#[test]
fn a_loader_that_panics_fails_its_file_with_a_message() {
    fn crashing(_: &std::path::Path) -> anyhow::Result<u32> {
        panic!("a bug in a loader")
    }
    let dir = temp_dir("loader-panic");
    let path = std::path::absolute(dir.join("any.bin")).unwrap();
    std::fs::write(&path, b"x").unwrap();
    let res = Resources::new(false);
    let _ = res.request(&path, crashing);
    wait_idle(&res);
    match res.request(&path, crashing).1 {
        Err(werkstatt::core::resources::LoadError::Failed(m)) => {
            assert!(m.contains("any.bin") && m.contains("the loader crashed"), "{m}")
        }
        other => panic!("expected a failed load, got {other:?}"),
    }
    // The worker survived: another file still loads.
    let other = dir.join("other.txt");
    std::fs::write(&other, "fine").unwrap();
    fn text(p: &std::path::Path) -> anyhow::Result<String> {
        Ok(std::fs::read_to_string(p)?)
    }
    let _ = res.request(&other, text);
    wait_idle(&res);
    assert_eq!(res.request(&other, text).1.unwrap().as_str(), "fine");
    std::fs::remove_dir_all(dir).unwrap();
}

/// A file saved broken and then fixed: the node shows the load error naming the file, then
/// recovers with the fixed contents.
#[test]
fn a_failed_reload_recovers_when_the_file_is_fixed() {
    let dir = temp_dir("recover");
    let path = dir.join("shape.obj");
    std::fs::write(&path, TRIANGLE_OBJ).unwrap();
    let g = mesh_graph(&path);
    let mut ev = Evaluator::new(&g, &["mesh".to_string()]).unwrap();
    let res = Resources::new(true);
    until(&mut ev, &res, "the first load", &|ev| triangles(ev) == 1);
    save_by_rename(&path, "v 0 0 0\nf 1 2 7\n");
    let name = path.display().to_string();
    until(
        &mut ev,
        &res,
        "the broken file's error",
        &|ev| matches!(ev.report("mesh").unwrap().status, NodeStatus::Failed(m) if m.contains(&name)),
    );
    save_by_rename(&path, QUAD_OBJ);
    until(&mut ev, &res, "the fixed file", &|ev| triangles(ev) == 2);
    assert_eq!(ev.report("mesh").unwrap().status, &NodeStatus::Ok);
    std::fs::remove_dir_all(dir).unwrap();
}

/// Evaluates frame 0 until `done`, failing with `what` and the mesh node's status after `WAIT`.
fn until(ev: &mut Evaluator, res: &Resources, what: &str, done: &dyn Fn(&Evaluator) -> bool) {
    let deadline = Instant::now() + WAIT;
    loop {
        ev.evaluate(frame(0), None, res, &FrameSettings::default());
        if done(ev) {
            return;
        }
        assert!(Instant::now() < deadline, "{what}: status {:?}", ev.report("mesh").unwrap().status);
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// A watched file deleted: the node fails saying the file is gone (not a parser's wording);
/// written again, it recovers.
#[test]
fn a_deleted_file_is_an_error_until_it_is_back() {
    let dir = temp_dir("deleted");
    let path = dir.join("shape.obj");
    std::fs::write(&path, TRIANGLE_OBJ).unwrap();
    let mut ev = Evaluator::new(&mesh_graph(&path), &["mesh".to_string()]).unwrap();
    let res = Resources::new(true);
    until(&mut ev, &res, "the first load", &|ev| triangles(ev) == 1);
    std::fs::remove_file(&path).unwrap();
    until(
        &mut ev,
        &res,
        "the deleted file's error",
        &|ev| matches!(ev.report("mesh").unwrap().status, NodeStatus::Failed(m) if m.contains("no such file") && m.contains("shape.obj")),
    );
    save_by_rename(&path, QUAD_OBJ);
    until(&mut ev, &res, "the file written again", &|ev| triangles(ev) == 2);
    std::fs::remove_dir_all(dir).unwrap();
}

/// Two saves in quick succession (closer than any debounce): the node ends with the second.
#[test]
fn two_quick_edits_end_with_the_second() {
    let dir = temp_dir("quick-edits");
    let path = dir.join("shape.obj");
    std::fs::write(&path, TRIANGLE_OBJ).unwrap();
    let mut ev = Evaluator::new(&mesh_graph(&path), &["mesh".to_string()]).unwrap();
    let res = Resources::new(true);
    until(&mut ev, &res, "the first load", &|ev| triangles(ev) == 1);
    let three = format!("{QUAD_OBJ}f 1 3 4\n");
    save_by_rename(&path, QUAD_OBJ);
    save_by_rename(&path, &three);
    until(&mut ev, &res, "the second edit", &|ev| triangles(ev) == 3);
    // Nothing older lands afterwards: the value stays while later events drain.
    for _ in 0..10 {
        std::thread::sleep(Duration::from_millis(20));
        ev.evaluate(frame(0), None, &res, &FrameSettings::default());
        assert_eq!(triangles(&ev), 3, "an older load replaced the second edit");
    }
    std::fs::remove_dir_all(dir).unwrap();
}

/// The camera's eye at `frame` of a turntable rendered over `range`.
fn turntable_eye(range: (i64, i64), frame_no: i64) -> glam::Vec3 {
    let g = graph(
        r#"(version: 1, nodes: {"cam": (kind: "OrbitCamera", params: {"turntable": true, "yaw": 0.0, "pitch": 0.0, "distance": 2.0})}, links: [])"#,
    );
    let mut ev = Evaluator::new(&g, &["cam".to_string()]).unwrap();
    let settings = FrameSettings { frames: Some(range), ..FrameSettings::default() };
    ev.evaluate(frame(frame_no), None, &Resources::new(false), &settings);
    match ev.output("cam", "camera") {
        Some(werkstatt::core::port::Value::Camera(c)) => c.eye,
        _ => panic!("no camera output"),
    }
}

#[test]
fn a_turntable_turns_once_over_the_rendered_frames() {
    let close = |a: glam::Vec3, b: glam::Vec3| a.distance(b) < 1e-4;
    // Frames 10..13: four steps of 90 degrees, the last one short of the start.
    assert!(close(turntable_eye((10, 13), 10), glam::Vec3::new(0.0, 0.0, 2.0)));
    assert!(close(turntable_eye((10, 13), 11), glam::Vec3::new(2.0, 0.0, 0.0)));
    assert!(close(turntable_eye((10, 13), 12), glam::Vec3::new(0.0, 0.0, -2.0)));
    // A longer range turns slower: a quarter turn takes 25 of 100 frames.
    assert!(close(turntable_eye((0, 99), 25), glam::Vec3::new(2.0, 0.0, 0.0)));
}

#[test]
fn a_grid_over_the_whole_uv_square_reports_what_fell_off_the_flag() {
    let g = graph(
        r#"(version: 1, nodes: {
            "cloth": (kind: "ClothSim", params: {"preset": "flag", "triangles": 100, "warmup": 0.0}),
            "grid": (kind: "GridPlacement", params: {"columns": 8, "rows": 5}),
            "out": (kind: "Watch"),
        }, links: [("cloth.surface", "grid.surface"), ("grid.count", "out.value")])"#,
    );
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    ev.evaluate(frame(0), None, &Resources::new(false), &FrameSettings::default());
    let count = match ev.output("grid", "count") {
        Some(werkstatt::core::port::Value::Scalar(n)) => *n,
        _ => panic!("no count output"),
    };
    let report = ev.report("grid").unwrap();
    assert!(count > 0.0 && count < 40.0, "{count}");
    assert_eq!(report.counts, [("placements", count as u64)]);
    let warning = report.warnings.iter().find(|w| w.contains("fall off the pattern pieces")).expect("a warning");
    assert!(warning.starts_with(&format!("{} of 40 placements", 40 - count as usize)), "{warning}");
    assert!(warning.contains("the pieces cover piece 0: u "), "{warning}");
}

/// Two UV-mapped OBJ objects: "left" covers u 0-0.5 (all of v), "right" u 0.5-1, v 0.5-1 (v down).
const TWO_PIECE_OBJ: &str = "o left\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 0.5 0\nvt 0.5 1\nvt 0 1\nf 1/1 2/2 3/3 4/4\n\
o right\nv 2 0 0\nv 3 0 0\nv 3 1 0\nv 2 1 0\nvt 0.5 0\nvt 1 0\nvt 1 0.5\nvt 0.5 0.5\nf 5/5 6/6 7/7 8/8\n";

/// Evaluates until the loads settle; returns the grid's report text (count and warnings) or the failure.
fn grid_on_mesh_file(obj: &str, name: &str) -> Result<(f64, Vec<String>), String> {
    let dir = std::env::temp_dir().join(format!("werkstatt-meshfile-{name}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    std::fs::write(dir.join("garment.obj"), obj).unwrap();
    let g = graph(
        r#"(version: 1, nodes: {
            "m": (kind: "MeshFile", params: {"path": "garment.obj", "normalize": false}),
            "grid": (kind: "GridPlacement", params: {"columns": 2, "rows": 2}),
            "out": (kind: "Watch"),
        }, links: [("m.surface", "grid.surface"), ("grid.count", "out.value")])"#,
    );
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let settings = FrameSettings { base_dir: dir.clone(), ..FrameSettings::default() };
    ev.evaluate(frame(0), None, &res, &settings);
    wait_idle(&res);
    ev.evaluate(frame(0), None, &res, &settings);
    let _ = std::fs::remove_dir_all(&dir);
    if let NodeStatus::Failed(m) = ev.report("m").unwrap().status {
        return Err(m.clone());
    }
    match ev.output("grid", "count") {
        Some(werkstatt::core::port::Value::Scalar(n)) => Ok((*n, ev.report("grid").unwrap().warnings.to_vec())),
        _ => panic!("no count output"),
    }
}

#[test]
fn a_uv_mapped_mesh_file_is_a_surface_with_a_piece_per_object() {
    let (count, warnings) = grid_on_mesh_file(TWO_PIECE_OBJ, "pieces").unwrap();
    // Cell centres (0.25, 0.25) and (0.25, 0.75) are on "left", (0.75, 0.75) on "right".
    assert_eq!(count, 3.0);
    assert_eq!(
        warnings,
        [
            "1 of 4 placements fall off the pattern pieces and were dropped; the pieces cover piece 0: u 0.000-0.500, v 0.000-1.000; piece 1: u 0.500-1.000, v 0.500-1.000"
        ]
    );
    let no_uvs = "o flat\nv 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n";
    let err = grid_on_mesh_file(no_uvs, "no-uvs").unwrap_err();
    assert!(err.contains("garment.obj has no UVs, so it cannot be a surface"), "{err}");
}

#[test]
fn an_orbit_camera_with_fit_frames_the_scene_bounds() {
    let g = graph(
        r#"(version: 1, nodes: {
            "box": (kind: "Primitive", params: {"shape": "box", "size": 2.0}),
            "draw": (kind: "Draw", params: {"translate": [5.0, 1.0, 0.0]}),
            "cam": (kind: "OrbitCamera", params: {"yaw": 0.0, "pitch": 0.0, "fov": 60.0, "target": [9.0, 9.0, 9.0]}),
        }, links: [("box.mesh", "draw.mesh"), ("draw.scene", "cam.fit")])"#,
    );
    let mut ev = Evaluator::new(&g, &["cam".to_string()]).unwrap();
    ev.evaluate(frame(0), None, &Resources::new(false), &FrameSettings::default());
    let Some(werkstatt::core::port::Value::Camera(c)) = ev.output("cam", "camera") else { panic!("no camera output") };
    // A 2 m cube at (5, 1, 0): bounding sphere radius sqrt(3), seen at 60 degrees from 2 sqrt(3).
    assert!(c.target.distance(glam::Vec3::new(5.0, 1.0, 0.0)) < 1e-4, "{:?}", c.target);
    assert!((c.eye.distance(c.target) - 2.0 * 3f32.sqrt()).abs() < 1e-3, "{:?}", c.eye);
}

/// An export fixed at frame 0 does not warp again on later frames: its `mesh` stays the
/// frame-0 export while the cloth moves on.
#[test]
fn a_fixed_frame_export_skips_its_work_on_other_frames() {
    use werkstatt::core::port::Value;
    let g = graph(
        r#"(version: 1, nodes: {
            "cloth": (kind: "ClothSim", params: {"preset": "flag", "triangles": 100}),
            "draw": (kind: "Draw"),
            "export": (kind: "ExportGeometry", params: {"frame": 0}),
        }, links: [("cloth.surface", "draw.mesh"), ("draw.scene", "export.scene")])"#,
    );
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let (res, settings, gpu) = (Resources::new(false), FrameSettings::default(), crate::common::gpu());
    let positions = |ev: &Evaluator, id: &str, port: &str| match ev.output(id, port) {
        Some(Value::Mesh(m) | Value::Surface(m)) => m.positions.clone(),
        _ => panic!("no {id}.{port}"),
    };
    ev.evaluate(frame(0), Some(gpu), &res, &settings);
    let (export0, cloth0) = (positions(&ev, "export", "mesh"), positions(&ev, "cloth", "surface"));
    ev.evaluate(frame(3), Some(gpu), &res, &settings);
    assert!(positions(&ev, "cloth", "surface") != cloth0, "the flag should move in the wind");
    assert!(positions(&ev, "export", "mesh") == export0, "the export ran again on frame 3");
}

/// A new frame size re-runs the nodes that read it (the G-buffer pass) and what they feed, and
/// nothing upstream: the mesh, the material, the draw and the camera keep their results.
#[test]
fn a_new_size_reruns_the_nodes_that_read_it_and_their_consumers_only() {
    let g = graph(
        r#"(version: 1, nodes: {
        "sphere": (kind: "Primitive", params: { "shape": "sphere" }),
        "m": (kind: "Material"),
        "d": (kind: "Draw"),
        "camera": (kind: "OrbitCamera"),
        "gbuffer": (kind: "GBufferPass"),
        "out": (kind: "Preview"),
    }, links: [
        ("sphere.mesh", "d.mesh"), ("m.material", "d.material"), ("d.scene", "gbuffer.scene"),
        ("camera.camera", "gbuffer.camera"), ("gbuffer.color", "out.image"),
    ])"#,
    );
    let mut ev = Evaluator::new(&g, &[]).unwrap();
    let res = Resources::new(false);
    let gpu = crate::common::gpu();
    let small = FrameSettings { width: 32, height: 24, ..FrameSettings::default() };
    assert_eq!(ev.evaluate(frame(0), Some(gpu), &res, &small).ran, 6);
    let wider = FrameSettings { width: 40, ..small.clone() };
    ev.evaluate(frame(0), Some(gpu), &res, &wider);
    assert_eq!(ran_ids(&ev, &["sphere", "m", "d", "camera", "gbuffer", "out"]), ["gbuffer", "out"]);
    let color = ev.output("gbuffer", "color").and_then(|v| v.as_texture()).expect("a colour target");
    assert_eq!((color.width, color.height), (40, 24), "the G-buffer has the new size");
    assert_eq!(ev.evaluate(frame(0), Some(gpu), &res, &wider).ran, 0, "the same size again");
}

//! MeshSequence: OBJ frame sequences played back against the frame time: interpolation,
//! topology checks, time modes, bounded memory, and batch rendering of graphs/sequence.ron.

use std::path::{Path, PathBuf};
use std::sync::Arc;

use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
use werkstatt::core::graph::Graph;
use werkstatt::core::port::Value;
use werkstatt::core::resources::Resources;
use werkstatt::mesh::Mesh;
use werkstatt::nodes::mesh::mesh_sequence::{Mode, bracket, load_frame, parse_obj};

use crate::common;

fn tablecloth() -> PathBuf {
    common::root().join("tests/data/sequence")
}

pub(crate) fn temp_dir(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("werkstatt-seq-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

/// A graph with one MeshSequence node "seq"; `params` is RON text like `"fps": 15.0`.
pub(crate) fn sequence_graph(path: &Path, params: &str) -> Evaluator {
    let text = format!(
        r#"(version: 1, nodes: {{"seq": (kind: "MeshSequence", params: {{"path": {:?}, {params}}})}}, links: [])"#,
        path.display().to_string()
    );
    let g = Graph::load_str(&text, "test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}"));
    Evaluator::new(&g, &["seq".to_string()]).unwrap()
}

/// Evaluates frame `f` the way batch rendering does: waiting for loads until nothing is pending.
pub(crate) fn settle(ev: &mut Evaluator, res: &Resources, f: i64) -> NodeStatus {
    let time = FrameTime { frame: f, fps: 30.0 };
    for _ in 0..20 {
        let s = ev.evaluate(time, None, res, &FrameSettings::default());
        if s.pending == 0 {
            break;
        }
        crate::common::wait_idle(res);
    }
    ev.report("seq").unwrap().status.clone()
}

pub(crate) fn surface(ev: &Evaluator) -> Arc<Mesh> {
    match ev.output("seq", "surface") {
        Some(Value::Surface(m)) => m.clone(),
        _ => panic!("no surface; status {:?}", ev.report("seq").unwrap().status),
    }
}

/// The height of the synthetic grid (every vertex has the same y).
fn height(ev: &Evaluator) -> f32 {
    surface(ev).positions[0].y
}

/// A 3 x 3 vertex grid in XZ at height y, with UVs: `f` lines as v/vt.
fn grid_obj(y: f32) -> String {
    let mut s = String::from("o cloth\n");
    for j in 0..3 {
        for i in 0..3 {
            s += &format!("v {i} {y} {j}\nvt {} {}\n", i as f32 / 2.0, j as f32 / 2.0);
        }
    }
    for j in 0..2 {
        for i in 0..2 {
            let a = j * 3 + i + 1;
            let (b, c, d) = (a + 1, a + 3, a + 4);
            s += &format!("f {a}/{a} {c}/{c} {b}/{b}\nf {b}/{b} {c}/{c} {d}/{d}\n");
        }
    }
    s
}

/// Frames `numbers` of the grid at height 10 n.
fn write_grid_sequence(dir: &Path, numbers: impl IntoIterator<Item = i64>) {
    for n in numbers {
        std::fs::write(dir.join(format!("frame_{n:04}.obj")), grid_obj(10.0 * n as f32)).unwrap();
    }
}

#[test]
fn loads_the_tablecloth_frames() {
    let mut ev = sequence_graph(&tablecloth(), r#""fps": 24.0"#);
    let res = Resources::new(false);
    assert_eq!(settle(&mut ev, &res, 0), NodeStatus::Ok);
    let m = surface(&ev);
    assert_eq!((m.positions.len(), m.triangle_count()), (1764, 3362));
    assert!(m.piece_ids.is_empty(), "one OBJ object is one piece");
    assert!(m.uvs.iter().all(|uv| (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y)));
    assert!(m.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4));
    // Time 0 shows the first file, frame_0011.obj, unchanged.
    let first = load_frame(&tablecloth().join("frame_0011.obj")).unwrap();
    assert_eq!(m.positions, first.mesh.positions);
    // The cloth is draped (not flat): frame 11 lies between y = 0.155 and 0.258.
    let (lo, hi) = m.bounds();
    assert!((lo.y - 0.155).abs() < 1e-3 && (hi.y - 0.257).abs() < 1e-3, "{lo} {hi}");
}

#[test]
fn a_half_frame_is_the_average_of_its_two_frames() {
    // Sequence fps 30 = render fps: render frame 1 is sequence frame 12, halfway between the
    // files 11 and 13 (the tablecloth has every second frame).
    let mut ev = sequence_graph(&tablecloth(), r#""fps": 30.0"#);
    let res = Resources::new(false);
    assert_eq!(settle(&mut ev, &res, 1), NodeStatus::Ok);
    let m = surface(&ev);
    let a = load_frame(&tablecloth().join("frame_0011.obj")).unwrap().mesh;
    let b = load_frame(&tablecloth().join("frame_0013.obj")).unwrap().mesh;
    for i in 0..m.positions.len() {
        let avg = (a.positions[i] + b.positions[i]) * 0.5;
        assert!((m.positions[i] - avg).length() < 1e-6, "vertex {i}: {} vs {avg}", m.positions[i]);
        let n = (a.normals[i] + b.normals[i]).normalize();
        assert!((m.normals[i] - n).length() < 1e-5, "normal {i}");
        assert!(m.tangents_u[i].dot(m.normals[i]).abs() < 1e-4, "tangent {i} is not orthogonal to the normal");
    }
    assert_eq!(m.uvs, a.uvs);
    assert_eq!(m.indices, a.indices);
    assert_ne!(m.positions, a.positions);
    assert_ne!(m.positions, b.positions);

    // The same on a synthetic sequence at a half frame of the render: fps 15, frame 1 = 1.5.
    let dir = temp_dir("half");
    write_grid_sequence(&dir, 1..=3);
    let mut ev = sequence_graph(&dir, r#""fps": 15.0"#);
    settle(&mut ev, &res, 1);
    assert_eq!(height(&ev), 15.0);
    settle(&mut ev, &res, 3);
    assert_eq!(height(&ev), 25.0);
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn a_topology_change_is_an_error_naming_the_frame() {
    let dir = temp_dir("topology");
    write_grid_sequence(&dir, 1..=2);
    let flipped = grid_obj(30.0).replace("f 1/1 4/4 2/2\nf 2/2 4/4 5/5", "f 1/1 4/4 5/5\nf 1/1 5/5 2/2");
    assert_ne!(flipped, grid_obj(30.0));
    let cases = [
        (flipped, "other triangles"),
        (grid_obj(30.0).replace("vt 0.5 0.5", "vt 0.25 0.5"), "other UVs"),
        (grid_obj(30.0) + "v 9 9 9\nvt 1 1\nf 1/1 10/10 2/2\n", "10 vertices instead of 9"),
        (grid_obj(30.0).replace("f 5/5 7/7 8/8\n", ""), "7 triangles instead of 8"),
    ];
    for (text, why) in cases {
        let bad = dir.join("frame_0003.obj");
        std::fs::write(&bad, text).unwrap();
        let res = Resources::new(false);
        let mut ev = sequence_graph(&dir, r#""fps": 30.0"#);
        assert_eq!(settle(&mut ev, &res, 0), NodeStatus::Ok);
        // Frames 1 and 2 play; frame 3 is refused with its file and the reason.
        match settle(&mut ev, &res, 2) {
            NodeStatus::Failed(m) => {
                assert!(m.contains(&bad.display().to_string()) && m.contains("frame_0001.obj"), "{m}");
                assert!(m.contains(why), "expected \"{why}\" in: {m}");
            }
            other => panic!("expected an error for {why}, got {other:?}"),
        }
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn obj_frames_keep_seams_and_pieces_and_ignore_normal_numbering() {
    // Two triangles sharing the edge 2-3; position 2 has two UVs (a seam); two objects.
    let a = "v 0 0 0\nv 1 0 0\nv 0 0 1\nv 1 0 1\nvt 0 0\nvt 1 0\nvt 0 1\nvt 1 1\nvt 0.5 0.5\nvn 0 1 0\n\
             o front\nf 1/1/1 3/3/1 2/2/1\no back\nf 2/5/1 3/3/1 4/4/1\n";
    let m = parse_obj(a).unwrap();
    assert_eq!(m.positions.len(), 5, "one vertex per (position, UV) pair: position 2 is on a seam");
    assert_eq!(m.indices, [0, 1, 2, 3, 1, 4]);
    assert_eq!(m.piece_ids, [0, 0, 0, 1, 1]);
    assert_eq!(m.positions[2], m.positions[3]);
    assert_eq!(m.normals[2], m.normals[3], "the seam does not show in the shading");
    // The same frame with per-face normals numbered differently has the same topology.
    let b = a.replace("vn 0 1 0\n", "vn 0 1 0\nvn 0 1 0\n").replace("4/4/1", "4/4/2");
    let mb = parse_obj(&b).unwrap();
    assert_eq!((mb.indices.clone(), mb.uvs.clone()), (m.indices.clone(), m.uvs.clone()));
    // OBJ's v points up; a Surface's v points down.
    assert_eq!(m.uvs[1], glam::Vec2::new(0.0, 0.0));
    assert_eq!(m.uvs[0], glam::Vec2::new(0.0, 1.0));
    let err = parse_obj("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap_err();
    assert!(format!("{err:#}").contains("no texture coordinates"), "{err:#}");
    let err = parse_obj("v 0 0 0\nvt 0 0\nf 1/1 2/1 3/1\n").unwrap_err();
    assert!(format!("{err:#}").contains("line 3") && format!("{err:#}").contains("out of range"), "{err:#}");
}

#[test]
fn clamp_loop_and_hold_modes() {
    let dir = temp_dir("modes");
    write_grid_sequence(&dir, 1..=4);
    let res = Resources::new(false);
    let heights = |params: &str, frames: &[i64]| -> Vec<f32> {
        let mut ev = sequence_graph(&dir, params);
        let mut out = Vec::new();
        for &f in frames {
            assert_eq!(settle(&mut ev, &res, f), NodeStatus::Ok, "{params}, frame {f}");
            out.push(height(&ev));
        }
        out
    };
    // Sequence frame = 1 + render frame (fps 30 = render fps), files 1..4 at heights 10..40.
    assert_eq!(heights(r#""fps": 30.0, "mode": "clamp""#, &[-3, 0, 2, 3, 10]), [10.0, 10.0, 30.0, 40.0, 40.0]);
    // Loop: period 4, the last file blends into the first over one spacing.
    assert_eq!(heights(r#""fps": 30.0, "mode": "loop""#, &[3, 4, 5, 9, -1]), [40.0, 10.0, 20.0, 20.0, 40.0]);
    assert_eq!(heights(r#""fps": 15.0, "mode": "loop""#, &[7]), [25.0]);
    // start_frame moves time 0.
    assert_eq!(heights(r#""fps": 30.0, "start_frame": 3"#, &[0, 1]), [30.0, 40.0]);
    // No interpolation: the file at or before the time.
    assert_eq!(heights(r#""fps": 15.0, "interpolate": false"#, &[1, 2, 3]), [10.0, 20.0, 20.0]);
    // Hold: a still of start_frame that does not depend on the time, so it runs once.
    let mut ev = sequence_graph(&dir, r#""mode": "hold", "start_frame": 3"#);
    for f in 0..5 {
        settle(&mut ev, &res, f);
        assert_eq!(height(&ev), 30.0);
    }
    let runs = ev.report("seq").unwrap().runs;
    assert!(runs <= 3, "hold re-ran {runs} times over 5 frames (only loads should re-run it)");
    // Past the end, clamp re-runs (it reads the time) but hands on the same mesh.
    let mut ev = sequence_graph(&dir, r#""fps": 30.0"#);
    settle(&mut ev, &res, 10);
    let m = surface(&ev);
    settle(&mut ev, &res, 11);
    assert!(Arc::ptr_eq(&m, &surface(&ev)));
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn bracket_handles_gaps_and_wraps() {
    let n = [11, 13, 15];
    assert_eq!(bracket(&n, 12.0, Mode::Clamp), (0, 1, 0.5));
    assert_eq!(bracket(&n, 13.0, Mode::Clamp), (1, 2, 0.0));
    assert_eq!(bracket(&n, 16.0, Mode::Clamp), (2, 2, 0.0));
    assert_eq!(bracket(&n, 2.0, Mode::Clamp), (0, 0, 0.0));
    // Period 15 - 11 + 2 = 6: 16 is between the last file (15) and the first again (17).
    assert_eq!(bracket(&n, 16.0, Mode::Loop), (2, 0, 0.5));
    assert_eq!(bracket(&n, 18.0, Mode::Loop), (0, 1, 0.5));
    assert_eq!(bracket(&n, 6.0, Mode::Loop), (0, 1, 0.5));
    assert_eq!(bracket(&[5], 100.0, Mode::Loop), (0, 0, 0.0));
}

#[test]
fn memory_stays_bounded_while_playing() {
    let dir = temp_dir("bounded");
    write_grid_sequence(&dir, 1..=30);
    let res = Resources::new(false);
    let mut ev = sequence_graph(&dir, r#""fps": 30.0, "mode": "loop""#);
    let mut most = 0;
    for f in 0..70 {
        assert_eq!(settle(&mut ev, &res, f), NodeStatus::Ok);
        assert_eq!(height(&ev), 10.0 * (1 + f % 30) as f32);
        most = most.max(res.resident());
    }
    // The folder listing, the two frames, the prefetched next one, one still loading.
    assert!(most <= 5, "{most} resources held while playing 30 frames");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn folders_and_patterns_select_the_files() {
    let dir = temp_dir("patterns");
    write_grid_sequence(&dir, [1, 2, 3]);
    std::fs::write(dir.join("notes.txt"), "not a frame").unwrap();
    let res = Resources::new(false);
    for path in [dir.clone(), dir.join("frame_%04d.obj"), dir.join("frame_####.obj"), dir.join("frame_*.obj")] {
        let mut ev = sequence_graph(&path, r#""fps": 30.0"#);
        assert_eq!(settle(&mut ev, &res, 1), NodeStatus::Ok, "{}", path.display());
        assert_eq!(height(&ev), 20.0);
    }
    // A second sequence in the folder: the folder is ambiguous, a pattern is not.
    std::fs::write(dir.join("take2_0001.obj"), grid_obj(0.0)).unwrap();
    let res = Resources::new(false); // the folder's listing above is cached
    let mut ev = sequence_graph(&dir, r#""fps": 30.0"#);
    match settle(&mut ev, &res, 0) {
        NodeStatus::Failed(m) => assert!(m.contains("more than one sequence") && m.contains("take2_"), "{m}"),
        other => panic!("{other:?}"),
    }
    let mut ev = sequence_graph(&dir.join("take2_%04d.obj"), r#""fps": 30.0"#);
    assert_eq!(settle(&mut ev, &res, 0), NodeStatus::Ok);
    // Nothing matches: the error names the path.
    let missing = dir.join("nothing_%04d.obj");
    let mut ev = sequence_graph(&missing, "");
    match settle(&mut ev, &res, 0) {
        NodeStatus::Failed(m) => assert!(m.contains("no frame files") && m.contains("nothing_%04d.obj"), "{m}"),
        other => panic!("{other:?}"),
    }
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn batch_render_of_the_sequence_graph_moves_and_is_deterministic() {
    let graph = common::root().join("graphs/sequence.ron");
    let (a, b) = (common::out_dir("sequence-a"), common::out_dir("sequence-b"));
    for out in [&a, &b] {
        let stats = common::render_graph(&graph, out, (0, 2), (96, 72), &[], &[]).unwrap();
        assert_eq!(stats.files, ["image_0000.png", "image_0001.png", "image_0002.png"]);
    }
    let read = |dir: &Path, f: &str| std::fs::read(dir.join(f)).unwrap();
    for f in ["image_0000.png", "image_0001.png", "image_0002.png"] {
        assert!(read(&a, f) == read(&b, f), "{f} differs between two runs");
    }
    let first = common::read_png(&a.join("image_0000.png"));
    let last = common::read_png(&a.join("image_0002.png"));
    let changed = first.pixels().zip(last.pixels()).filter(|(p, q)| p != q).count();
    assert!(changed > 100, "the cloth should move between frames 0 and 2: {changed} pixels changed");
}

#[test]
fn bad_sequences_are_errors_naming_the_file() {
    let fails = |path: &Path, needles: &[&str]| {
        let res = Resources::new(false);
        let mut ev = sequence_graph(path, r#""fps": 30.0"#);
        match settle(&mut ev, &res, 0) {
            NodeStatus::Failed(m) => assert!(needles.iter().all(|n| m.contains(n)), "{needles:?} not all in: {m}"),
            other => panic!("{}: expected an error, got {other:?}", path.display()),
        }
    };
    // Two files with one frame number.
    let dir = temp_dir("duplicates");
    write_grid_sequence(&dir, [1, 2]);
    std::fs::write(dir.join("frame_001.obj"), grid_obj(5.0)).unwrap();
    fails(&dir.join("frame_*.obj"), &["frame_001.obj", "frame_0001.obj", "the same frame number 1"]);
    // A frame without faces, and one without UVs.
    let dir = temp_dir("no-faces");
    write_grid_sequence(&dir, [2]);
    std::fs::write(dir.join("frame_0001.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\n").unwrap();
    fails(&dir, &["frame_0001.obj", "no faces"]);
    let dir = temp_dir("no-uvs");
    write_grid_sequence(&dir, [2]);
    std::fs::write(dir.join("frame_0001.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    fails(&dir, &["frame_0001.obj", "no texture coordinates"]);
}

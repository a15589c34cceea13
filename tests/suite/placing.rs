//! Placing attachments without scripts: 3D points snapped to the nearest surface point
//! (`SurfacePoints`), pattern landmarks (`PatternLandmarks`), typed polylines (`Polyline`) and
//! counted rows along curves (`CurvePlacement`), down to the worksuit's ten front buttons.

use std::path::Path;
use std::sync::Arc;

use glam::{Vec2, Vec3};
use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
use werkstatt::core::graph::{Graph, Link, NodeDoc, PortRef};
use werkstatt::core::port::Value;
use werkstatt::mesh::Mesh;
use werkstatt::warp::landmarks::{Landmark, NearestPoint, piece_landmark};
use werkstatt::warp::{Curves, Placement};

use crate::common;

fn graph(text: &str) -> Graph {
    Graph::load_str(text, "test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}"))
}

/// Evaluates frame 0 until nothing is pending, with paths relative to `base_dir`; unlike
/// `common::run_graph` a failed node is left for the test to look at.
fn evaluate(graph: &Graph, base_dir: &Path) -> Evaluator {
    let mut ev = Evaluator::new(graph, &[]).unwrap();
    let res = werkstatt::core::resources::Resources::new(false);
    let settings = FrameSettings { width: 8, height: 8, base_dir: base_dir.to_path_buf(), frames: None };
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(300);
    while ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, Some(common::gpu()), &res, &settings).pending > 0 {
        assert!(std::time::Instant::now() < deadline, "the graph did not finish within 300 s");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    ev
}

fn placements(ev: &Evaluator, node: &str) -> Vec<Placement> {
    match ev.output(node, "placements") {
        Some(Value::Instances(p)) => (**p).clone(),
        _ => panic!("no placements on {node}: {:?}", ev.report(node).map(|r| r.status.clone())),
    }
}

fn curves(ev: &Evaluator, node: &str) -> Arc<Curves> {
    match ev.output(node, "curves") {
        Some(Value::Curves(c)) => c.clone(),
        _ => panic!("no curves on {node}: {:?}", ev.report(node).map(|r| r.status.clone())),
    }
}

fn failure(ev: &Evaluator, node: &str) -> String {
    match &ev.report(node).unwrap().status {
        NodeStatus::Failed(m) => m.clone(),
        other => panic!("{node} did not fail: {other:?}"),
    }
}

fn close(a: Vec2, b: Vec2) -> bool {
    a.distance(b) < 1e-5
}

/// The two-piece test garment (tests/data/mirrored_piece.obj): piece 0 is the square x, y in
/// 0-1 at z = 0 with u = x / 2, v = 1 - y (OBJ's v flipped on load); piece 1 is x in 2-3 with
/// u = 1 - (x - 2) / 2, v = (1 - y) / 2.
const TWO_PIECES: &str =
    r#""m": (kind: "MeshFile", params: {"path": "tests/data/mirrored_piece.obj", "normalize": false}),"#;

fn surface_points(params: &str) -> Evaluator {
    let g = graph(&format!(
        r#"(version: 2, nodes: {{ {TWO_PIECES}
            "sp": (kind: "SurfacePoints", params: {{ {params} }}),
            "out": (kind: "Watch"),
        }}, links: [("m.surface", "sp.surface"), ("sp.count", "out.value")])"#
    ));
    evaluate(&g, &common::root())
}

/// Points off the pieces snap to their nearest surface points, which carry the UV and piece
/// of that spot; a row's samples snap one by one.
#[test]
fn surface_points_land_on_the_nearest_surface_point() {
    let ev = surface_points(
        r#""points": "0.5 0.25 0.3; 2.5 0.5 -0.2; 3.5 0.5 0", "from": [0.1, 0.5, 0.1], "to": [0.9, 0.5, 0.1], "count": 5, "max_distance": 0.6"#,
    );
    let got: Vec<(u32, Vec2)> = placements(&ev, "sp").iter().map(|p| (p.piece, Vec2::new(p.u, p.v))).collect();
    // The third point lies beyond piece 1's edge x = 3: its nearest point is on that edge.
    let want = [(0, Vec2::new(0.25, 0.75)), (1, Vec2::new(0.75, 0.25)), (1, Vec2::new(0.5, 0.25))]
        .into_iter()
        .chain((0..5).map(|i| (0, Vec2::new(0.05 + 0.1 * i as f32, 0.5))));
    for ((gp, guv), (wp, wuv)) in got.iter().zip(want) {
        assert!(*gp == wp && close(*guv, wuv), "got {got:?}");
    }
    assert_eq!(got.len(), 8);
}

/// On a finely tessellated sphere the nearest point of a point outside lies near the ray
/// through it (within a facet) and on the sphere (within the tessellation's sagitta), and the
/// BVH finds what a search of every triangle finds.
#[test]
fn surface_points_on_a_sphere_match_the_ray_and_a_full_search() {
    let sphere = werkstatt::nodes::mesh::geometry::sphere(1.0, 96, 48).unwrap();
    let nearest = NearestPoint::new(&sphere);
    let brute = |p: Vec3| -> (f32, u32) {
        let mut best = (f32::MAX, 0);
        for (t, i) in sphere.indices.chunks_exact(3).enumerate() {
            let [a, b, c] = [0, 1, 2].map(|k| sphere.positions[i[k] as usize]);
            let (q, _, _) = werkstatt::cloth::body_collision::closest_point_feature(p, a, b, c);
            if q.distance(p) < best.0 {
                best = (q.distance(p), t as u32);
            }
        }
        best
    };
    for (k, d) in [Vec3::X, Vec3::new(0.3, 0.8, -0.5), Vec3::new(-0.7, -0.2, 0.6), Vec3::new(0.1, -0.9, 0.1)]
        .into_iter()
        .enumerate()
    {
        let d = d.normalize();
        let p = d * (1.5 + 0.5 * k as f32);
        let hit = nearest.nearest(p, 10.0).expect("within reach");
        let facet = std::f32::consts::PI / 48.0;
        assert!(hit.position.angle_between(d) < facet, "{d}: {}", hit.position);
        assert!(hit.position.length() <= 1.0 + 1e-5 && hit.position.length() > (0.5 * facet).cos() - 1e-5);
        assert!((hit.distance - brute(p).0).abs() < 1e-6, "the BVH missed the nearest triangle");
        // The UV is the barycentric mix of the triangle's corners: the point the UV names is
        // the hit point.
        let i = &sphere.indices[3 * hit.triangle as usize..3 * hit.triangle as usize + 3];
        let back = uv_to_position(&sphere, i, hit.uv).expect("inside its triangle");
        assert!(back.distance(hit.position) < 1e-4);
    }
    assert!(nearest.nearest(Vec3::new(3.0, 0.0, 0.0), 1.0).is_none(), "max distance is a limit");
}

/// The position at `uv` inside triangle `i`, if the UV lies in it.
fn uv_to_position(mesh: &Mesh, i: &[u32], uv: Vec2) -> Option<Vec3> {
    let [a, b, c] = [0, 1, 2].map(|k| mesh.uvs[i[k] as usize]);
    let d = (b - a).perp_dot(c - a);
    let (l1, l2) = ((uv - a).perp_dot(c - a) / d, (b - a).perp_dot(uv - a) / d);
    let l0 = 1.0 - l1 - l2;
    (l0.min(l1).min(l2) > -1e-4).then(|| {
        mesh.positions[i[0] as usize] * l0 + mesh.positions[i[1] as usize] * l1 + mesh.positions[i[2] as usize] * l2
    })
}

/// The surface position the UV names (the first piece triangle holding it).
fn position_at_uv(mesh: &Mesh, uv: Vec2) -> Option<Vec3> {
    mesh.indices.chunks_exact(3).find_map(|i| uv_to_position(mesh, i, uv))
}

#[test]
fn a_point_beyond_max_distance_is_an_error_naming_it() {
    let ev = surface_points(r#""points": "0.5 0.5 0.01; 0.5 0.5 0.4", "max_distance": 0.1"#);
    let e = failure(&ev, "sp");
    assert!(e.contains("point 2 of \"points\" (0.5, 0.5, 0.4) is 0.4000 from the surface"), "{e}");
    let ev = surface_points(r#""points": "0.5 0.5; 1 2 3""#);
    let e = failure(&ev, "sp");
    assert!(e.contains("parameter \"points\": entry 1 (\"0.5 0.5\") has 2 numbers, expected 3"), "{e}");
    let e = failure(&surface_points(""), "sp");
    assert!(e.contains("no points"), "{e}");
}

fn landmarks(params: &str, placement: &str) -> Evaluator {
    let g = graph(&format!(
        r#"(version: 2, nodes: {{ {TWO_PIECES}
            "lm": (kind: "PatternLandmarks", params: {{ {params} }}),
            "row": (kind: "CurvePlacement", params: {{ {placement} }}),
            "out": (kind: "Watch"),
        }}, links: [("m.surface", "lm.surface"), ("m.surface", "row.surface"), ("lm.curves", "row.curves"), ("row.count", "out.value")])"#
    ));
    evaluate(&g, &common::root())
}

fn uvs(p: &[Placement]) -> Vec<(u32, Vec2)> {
    p.iter().map(|p| (p.piece, Vec2::new(p.u, p.v))).collect()
}

/// Piece 0 is the rectangle u 0-0.5, v 0-1: its centre line runs down u = 0.25 from the
/// margin to the margin, and five placements counted along it are 0.2 apart in v.
#[test]
fn the_centre_line_of_a_rectangle_piece() {
    let ev = landmarks(r#""piece": 0, "margin": 0.1"#, r#""count": 5"#);
    let c = curves(&ev, "lm");
    assert_eq!(c.paths.len(), 1);
    for seg in &c.paths[0] {
        assert!(seg.iter().all(|p| (p.x - 0.25).abs() < 1e-5), "{seg:?}");
    }
    let want: Vec<(u32, Vec2)> = (0..5).map(|i| (0, Vec2::new(0.25, 0.1 + 0.2 * i as f32))).collect();
    let got = uvs(&placements(&ev, "row"));
    assert!(got.len() == 5 && got.iter().zip(&want).all(|(g, w)| g.0 == w.0 && close(g.1, w.1)), "{got:?}");
}

/// Each edge moved inward by the offset: left and right of piece 0 (u 0-0.5), top and
/// bottom of piece 1 (v 0-0.5; top is small v).
#[test]
fn offset_edges_lie_at_the_offset() {
    for (piece, landmark, across) in
        [(0, "left_edge", 0.1), (0, "right_edge", 0.4), (1, "top_edge", 0.1), (1, "bottom_edge", 0.4)]
    {
        // A small margin: piece 1's top edge would end where it touches piece 0 at u = 0.5.
        let params = format!(r#""piece": {piece}, "landmark": "{landmark}", "offset": 0.1, "margin": 0.01"#);
        let ev = landmarks(&params, r#""count": 3"#);
        let got = uvs(&placements(&ev, "row"));
        assert_eq!(got.len(), 3, "{landmark}");
        for (p, uv) in &got {
            let coord = if landmark.ends_with("top_edge") || landmark.ends_with("bottom_edge") { uv.y } else { uv.x };
            assert!(*p == piece && (coord - across).abs() < 1e-5, "{landmark}: {got:?}");
        }
    }
}

/// The centre line follows the outline, not the bounding rectangle: on a triangle piece
/// (0, 0), (1, 0), (0, 1) the row at v spans u 0 to 1 - v.
#[test]
fn the_centre_line_follows_a_slanted_outline() {
    let mesh = Mesh::from_parts(
        vec![Vec3::ZERO, Vec3::X, Vec3::Y],
        None,
        vec![Vec2::ZERO, Vec2::X, Vec2::Y],
        vec![0, 1, 2],
        vec![3; 3],
    )
    .unwrap();
    let line = piece_landmark(&mesh, 3, Landmark::Centre, 0.0, 0.05, 11).unwrap();
    assert_eq!(line.len(), 11);
    for p in &line {
        assert!((p.x - 0.5 * (1.0 - p.y)).abs() < 1e-5, "{p}");
    }
    let edge = piece_landmark(&mesh, 3, Landmark::RightEdge, 0.1, 0.05, 11).unwrap();
    for p in &edge {
        assert!((p.x - (0.9 - p.y)).abs() < 1e-5, "{p}");
    }
    let e = piece_landmark(&mesh, 7, Landmark::Centre, 0.0, 0.0, 8).unwrap_err();
    assert_eq!(e, "the surface has no piece 7; its pieces are 3");
}

#[test]
fn an_unknown_piece_is_an_error_listing_the_known_ones() {
    let ev = landmarks(r#""piece": 5"#, "");
    let e = failure(&ev, "lm");
    assert!(e.contains("parameter \"piece\": the surface has no piece 5; its pieces are 0, 1"), "{e}");
}

fn polyline(params: &str, with_surface: bool) -> Evaluator {
    let link = if with_surface { r#"("m.surface", "pl.surface"), "# } else { "" };
    let g = graph(&format!(
        r#"(version: 2, nodes: {{ {TWO_PIECES}
            "pl": (kind: "Polyline", params: {{ {params} }}),
            "row": (kind: "CurvePlacement", params: {{"count": 3}}),
            "out": (kind: "Watch"),
        }}, links: [{link}("pl.curves", "row.curves"), ("row.count", "out.value")])"#
    ));
    evaluate(&g, &common::root())
}

/// A typed polyline is the curve through its points, in atlas UVs or 0-1 across a piece.
#[test]
fn polylines_are_typed_in_pattern_coordinates() {
    let ev = polyline(r#""points": "0.1 0.2; 0.3,0.2\n0.3 0.6""#, false);
    let got = uvs(&placements(&ev, "row"));
    // Three placements counted along it: its ends and halfway along its 0.6 of length.
    let want = [Vec2::new(0.1, 0.2), Vec2::new(0.3, 0.3), Vec2::new(0.3, 0.6)];
    assert!(got.iter().zip(want).all(|(g, w)| close(g.1, w)), "{got:?}");
    // Piece 1 spans u 0.5-1, v 0-0.5.
    let ev = polyline(r#""points": "0 0; 1 1", "coordinates": "piece", "piece": 1"#, true);
    let got = uvs(&placements(&ev, "row"));
    let want = [Vec2::new(0.5, 0.0), Vec2::new(0.75, 0.25), Vec2::new(1.0, 0.5)];
    assert!(got.iter().zip(want).all(|(g, w)| close(g.1, w)), "{got:?}");
}

#[test]
fn bad_polylines_are_errors_naming_the_parameter() {
    for (params, surface, wanted) in [
        (
            r#""points": "0.1 0.2; 0.3 zero""#,
            false,
            r#"parameter "points": entry 2 ("0.3 zero"): "zero" is not a finite number"#,
        ),
        (r#""points": "0.1 0.2""#, false, r#"parameter "points" has 1 point(s); a polyline needs at least two"#),
        (r#""points": "0 0; 1 1", "coordinates": "piece""#, false, "coordinates: piece needs the surface input"),
        (r#""points": "0 0; 1 1", "coordinates": "piece", "piece": 4"#, true, "its pieces are 0, 1"),
        (r#""points": "0.2 0.2; 0.2 0.2""#, false, "the polyline has no length"),
    ] {
        let e = failure(&polyline(params, surface), "pl");
        assert!(e.contains(wanted), "{params}: {e}");
    }
}

/// The first-day task, graphs/worksuit_buttons.ron: its ten buttons, placed by a row of 3D
/// points down the front, land on the worksuit's front centre (x = 0, in front of the body)
/// from top to bottom, each at the UV of that spot.
#[test]
fn the_worksuit_buttons_run_down_the_front_centre() {
    let dir = common::root().join("graphs");
    let full = Graph::load(&dir.join("worksuit_buttons.ron")).unwrap_or_else(|e| panic!("{e}"));
    // The graph's avatar and row with a Watch on the count: no rendering needed.
    let mut g = full.clone();
    g.nodes.retain(|id, _| id == "avatar" || id == "front_row");
    g.links.retain(|l| g.nodes.contains_key(&l.from.node) && g.nodes.contains_key(&l.to.node));
    let watch = NodeDoc { kind: "Watch".into(), pos: [0.0, 0.0], params: Default::default() };
    g.nodes.insert("out".into(), watch);
    let port = |text: &str| PortRef::parse(text).unwrap();
    g.links.push(Link { from: port("front_row.count"), to: port("out.value") });
    let ev = evaluate(&g, &dir);
    let buttons = placements(&ev, "front_row");
    assert_eq!(buttons.len(), 10);
    let suit = match ev.output("avatar", "clothes") {
        Some(Value::Surface(m)) => m.clone(),
        _ => panic!("no clothes"),
    };
    let mut last_y = f32::MAX;
    for b in &buttons {
        let p = position_at_uv(&suit, Vec2::new(b.u, b.v)).expect("on the suit");
        assert!(p.x.abs() < 0.01 && p.z > 0.1, "button at {p} is off the front centre");
        assert!(p.y < last_y, "buttons run top to bottom");
        last_y = p.y;
    }
}

/// FreeSewing's Simon draws eight `#button` snippets on the right front's centre line (SVG
/// x = 0, 31.5 mm inside the cut-on placket's edge, the part's largest x), 79.27 mm apart: the
/// sewn pattern has them on piece 1 (the sidecar's second panel) 3.15 cm inside that edge,
/// equally spaced down v, in SVG order.
#[test]
fn freesewing_button_marks_land_on_the_centre_front_edge() {
    let pattern =
        werkstatt::garment::freesewing::load(&common::root().join("assets/patterns/freesewing-simon-shirt.ron"))
            .unwrap_or_else(|e| panic!("{e}"));
    let sewn = pattern.sew(4.0, werkstatt::garment::Fit::default()).unwrap();
    assert_eq!(sewn.buttons.len(), 8, "{:?}", sewn.buttons);
    let m = &sewn.mesh;
    let edge_u =
        (0..m.vertex_count()).filter(|&v| m.piece_ids()[v] == 1).map(|v| m.uvs()[v].x).fold(f32::MIN, f32::max);
    let step = 7.927 * m.uv_per_cm();
    let mut v: Vec<f32> = Vec::new();
    for &(piece, uv) in &sewn.buttons {
        let want_u = edge_u - 3.15 * m.uv_per_cm();
        assert!(piece == 1 && (uv.x - want_u).abs() < 1e-5, "{:?} against u {want_u}", sewn.buttons);
        v.push(uv.y);
    }
    // SVG order: 154.06, 233.33, ..., 629.68, then 114.43 mm.
    let top = v.pop().unwrap();
    assert!((v[0] - top - 3.963 * m.uv_per_cm()).abs() < 1e-4, "{top} {v:?}");
    for w in v.windows(2) {
        assert!((w[1] - w[0] - step).abs() < 1e-4, "{v:?}");
    }
}

/// With `hold` the UVs found on the first frame stay while the worksuit walks (the buttons
/// ride the cloth); without, each frame snaps the fixed 3D row anew and the UVs move.
#[test]
fn held_surface_points_keep_their_uvs_on_a_moving_surface() {
    let dir = common::root().join("graphs");
    let uvs_at = |hold: bool| -> Vec<Vec<Vec2>> {
        let g = graph(&format!(
            r#"(version: 2, nodes: {{
                "avatar": (kind: "Avatar", params: {{"clothes": "../assets/avatar/male_worksuit01.mhclo", "motion": "../assets/avatar/walk1.bvh", "joint_map": "../assets/avatar/makehuman-old-rig.ron"}}),
                "sp": (kind: "SurfacePoints", params: {{"from": [0.0, 1.3, 0.16], "to": [0.0, 0.95, 0.16], "count": 4, "max_distance": 0.2, "hold": {hold}}}),
                "out": (kind: "Watch"),
            }}, links: [("avatar.clothes", "sp.surface"), ("sp.count", "out.value")])"#
        ));
        let mut ev = Evaluator::new(&g, &[]).unwrap();
        let res = werkstatt::core::resources::Resources::new(false);
        let settings = FrameSettings { width: 8, height: 8, base_dir: dir.clone(), frames: None };
        [0, 7]
            .into_iter()
            .map(|frame| {
                while ev.evaluate(FrameTime { frame, fps: 30.0 }, Some(common::gpu()), &res, &settings).pending > 0 {
                    std::thread::sleep(std::time::Duration::from_millis(5));
                }
                placements(&ev, "sp").iter().map(|p| Vec2::new(p.u, p.v)).collect()
            })
            .collect()
    };
    let held = uvs_at(true);
    assert_eq!(held[0], held[1]);
    let snapped = uvs_at(false);
    assert_eq!(snapped[0], held[0], "the first frame finds the same spots");
    assert_ne!(snapped[0], snapped[1], "the walk moves the cloth under the fixed row");
}

//! Sewing patterns (werkstatt::garment, the `Garment` node): the four GarmentCode patterns and
//! the FreeSewing shirt load and sew with equal vertex counts on stitched edges into manifold
//! panels; placement and stitch directions agree with the data; each kind of broken pattern
//! gets its error naming file, panel and edge; a short drape on the avatar closes the seams.

use std::collections::BTreeMap;
use std::path::PathBuf;

use glam::{DVec2, Vec3};
use serde_json::Value;

use werkstatt::avatar::walk::WalkingAvatar;
use werkstatt::cloth::collider::closest_point_on_segment;
use werkstatt::cloth::{BodyMesh, SimParams};
use werkstatt::garment::drape::{Drape, DrapeParams};
use werkstatt::garment::sleeves::{ArmAxis, SleeveFit, fit_sleeves};
use werkstatt::garment::{Fit, GarmentError, Pattern, Sewn, freesewing, garmentcode};

use crate::common::root;
use std::sync::Arc;
use werkstatt::mesh::Mesh;

fn pattern_path(name: &str) -> PathBuf {
    root().join("assets/patterns/garmentcode").join(format!("{name}_specification.json"))
}

const PATTERNS: [&str; 4] = ["shirt_mean", "hoody_mean", "dress_pencil", "js_mean_all"];

fn simon() -> Pattern {
    freesewing::load(&root().join("assets/patterns/freesewing-simon-shirt.ron")).unwrap()
}

/// Every panel's triangles form a disc: each edge in one or two triangles, the boundary edges
/// one closed loop, every vertex's triangle fan connected, V - E + F = 1.
fn assert_manifold(sewn: &Sewn, what: &str) {
    let tris = sewn.mesh.triangles();
    for (pi, pm) in sewn.mesh.piece_meshes().iter().enumerate() {
        let name = format!("{what}: panel {}", sewn.piece_names[pi]);
        let t = &tris[pm.triangles.start as usize..pm.triangles.end as usize];
        let mut edges: BTreeMap<(u32, u32), usize> = BTreeMap::new();
        for tri in t {
            assert!(tri.iter().all(|v| pm.vertices.contains(v)), "{name}: a triangle leaves the panel");
            for k in 0..3 {
                let (a, b) = (tri[k], tri[(k + 1) % 3]);
                *edges.entry((a.min(b), a.max(b))).or_default() += 1;
            }
        }
        assert!(edges.values().all(|&n| n <= 2), "{name}: an edge in more than two triangles");
        let v = pm.vertices.len() as i64;
        assert_eq!(v - edges.len() as i64 + t.len() as i64, 1, "{name}: not a disc (V - E + F)");
        // Boundary: every vertex on it has exactly two boundary edges (one loop, no pinch).
        let mut degree: BTreeMap<u32, usize> = BTreeMap::new();
        for (&(a, b), &n) in &edges {
            if n == 1 {
                *degree.entry(a).or_default() += 1;
                *degree.entry(b).or_default() += 1;
            }
        }
        assert!(degree.values().all(|&d| d == 2), "{name}: the boundary is not a simple loop");
        assert_eq!(degree.len(), sewn.edge_vertices[pi].iter().map(|e| e.len() - 1).sum::<usize>(), "{name}");
    }
}

/// Stitched edges have equal vertex counts, no edge is in two stitches, and sewn vertices
/// are the seam pairs of the mesh.
fn assert_stitches(p: &Pattern, sewn: &Sewn) {
    let mut seen = std::collections::BTreeSet::new();
    for (k, s) in p.stitches.iter().enumerate() {
        assert!(seen.insert(s.a) && seen.insert(s.b), "{}: stitch {k} reuses an edge", p.file);
        let (a, b) = &sewn.stitched[k];
        assert_eq!(a.len(), b.len(), "{}: stitch {k} has unequal vertex counts", p.file);
        assert_eq!(a.len(), sewn.edge_vertices[s.a.0][s.a.1].len());
        // A dart's two edges share their tip: that vertex is sewn to itself.
        for (x, y) in a.iter().zip(b).filter(|(x, y)| x != y) {
            let pair = [*x.min(y), *x.max(y)];
            assert!(sewn.mesh.seam_pairs().binary_search(&pair).is_ok(), "{}: stitch {k} pair not sewn", p.file);
        }
    }
}

/// Mean 3D distance (cm) between the vertices a stitch sews, as placed, and with the pairing
/// run the other way along one edge.
fn stitch_gaps(sewn: &Sewn, k: usize) -> (f32, f32) {
    let (a, b) = &sewn.stitched[k];
    let x = &sewn.positions;
    let n = a.len() as f32;
    let d = |i: &u32, j: &u32| x[*i as usize].distance(x[*j as usize]) * 100.0;
    let along: f32 = a.iter().zip(b).map(|(i, j)| d(i, j)).sum::<f32>() / n;
    let against: f32 = a.iter().zip(b.iter().rev()).map(|(i, j)| d(i, j)).sum::<f32>() / n;
    (along, against)
}

#[test]
fn garmentcode_patterns_load_and_sew_into_manifold_panels() {
    let counts = [(8, 18), (6, 12), (6, 23), (12, 57)];
    for (name, (panels, stitches)) in PATTERNS.iter().zip(counts) {
        let p = garmentcode::load(&pattern_path(name)).unwrap();
        assert_eq!((p.panels.len(), p.stitches.len()), (panels, stitches), "{name}");
        let sewn = p.sew(2.0, Fit::default()).unwrap();
        assert_stitches(&p, &sewn);
        assert_manifold(&sewn, name);
        // Boundary edges are at most the target length along every edge (resampled by arc
        // length, the chords are a little shorter).
        for (pi, panel) in sewn.edge_vertices.iter().enumerate() {
            for chain in panel {
                for w in chain.windows(2) {
                    let r = sewn.mesh.rest_positions();
                    let len = r[w[0] as usize].distance(r[w[1] as usize]);
                    assert!(len <= 2.0 + 1e-3, "{name} panel {pi}: boundary edge {len} cm");
                }
            }
        }
        assert!(sewn.positions.iter().all(|p| p.is_finite()));
    }
}

#[test]
fn placement_and_stitch_directions_bring_sewn_edges_together() {
    // GarmentCode lays panels around the body in 3D (R = Rz Ry Rx, XYZ degrees); a stitch sews
    // the end of its first edge to the start of its second. With both right, the sewn vertices
    // of the shirt are closer along the stitch than with the pairing reversed, for every stitch.
    let p = garmentcode::load(&pattern_path("shirt_mean")).unwrap();
    let sewn = p.sew(2.0, Fit::default()).unwrap();
    for k in 0..p.stitches.len() {
        let (along, against) = stitch_gaps(&sewn, k);
        assert!(along < against, "stitch {k}: {along} cm along, {against} cm reversed");
        // The panels stand at most 45 cm apart (front z = 25, back z = -20).
        assert!(along < 46.0, "stitch {k}: {along} cm");
    }
    // The side seam between the left front and back: front at z = 25, back at -20, same heights.
    let side = p
        .stitches
        .iter()
        .position(|s| p.panels[s.a.0].name == "left_ftorso" && p.panels[s.b.0].name == "left_btorso" && s.a.1 == 1)
        .unwrap();
    let (a, b) = &sewn.stitched[side];
    for (i, j) in a.iter().zip(b) {
        let (pa, pb) = (sewn.positions[*i as usize], sewn.positions[*j as usize]);
        assert!((pa.z - 0.25).abs() < 1e-5 && (pb.z + 0.20).abs() < 1e-5, "{pa} {pb}");
        assert!((pa.y - pb.y).abs() < 0.01, "sewn at different heights: {pa} {pb}");
    }
    // The hood stands sideways (rotation y = 90): in the plane x = translation x.
    let hoody = garmentcode::load(&pattern_path("hoody_mean")).unwrap();
    let hs = hoody.sew(2.0, Fit::default()).unwrap();
    let hood = hs.piece_names.iter().position(|n| n == "left_hood").unwrap() as u32;
    for (v, p) in hs.positions.iter().enumerate() {
        if hs.mesh.piece_ids()[v] == hood {
            assert!((p.x - 0.108188).abs() < 1e-5, "{p}");
        }
    }
}

#[test]
fn circle_and_bezier_edges_follow_garmentcode() {
    // hoody_mean left_ftorso edge 4 is a circle arc (radius 11.56, large_arc 0, right 0)
    // scooping the neckline into the panel: the arc's middle lies inside the straight chord's
    // polygon, at the sagitta of the radius below the chord.
    let p = garmentcode::load(&pattern_path("hoody_mean")).unwrap();
    let panel = p.panels.iter().find(|p| p.name == "left_ftorso").unwrap();
    let e = &panel.edges[panel.edge_index(4).unwrap()];
    let (a, b) = (e.points[0], *e.points.last().unwrap());
    let mid = e.points[e.points.len() / 2];
    let chord = a.distance(b);
    let r = 11.564126734773824;
    let sagitta = r - (r * r - chord * chord / 4.0).sqrt();
    let d = (b - a).perp_dot(mid - a) / chord;
    // Left of the edge (positive) is inside a counter-clockwise panel.
    assert!((d - sagitta).abs() < 1e-3, "arc middle {d} cm off the chord, sagitta {sagitta}");
    for q in &e.points {
        let c = (a + b) * 0.5 + DVec2::new(-(b - a).y, (b - a).x).normalize() * (sagitta - r);
        assert!((q.distance(c) - r).abs() < 1e-9);
    }
    // A quadratic's middle is at half its relative control point: shirt left_ftorso edge 5,
    // params [0.5, 0.3]: 0.15 edge lengths left of the chord's middle.
    let s = garmentcode::load(&pattern_path("shirt_mean")).unwrap();
    let panel = s.panels.iter().find(|p| p.name == "left_ftorso").unwrap();
    let e = &panel.edges[5];
    let (a, b) = (e.points[0], *e.points.last().unwrap());
    let mid = e.points[e.points.len() / 2];
    let want = (a + b) * 0.5 + DVec2::new(-(b - a).y, (b - a).x) * 0.15;
    assert!(mid.distance(want) < 1e-9, "{mid} against {want}");
}

/// The shirt's JSON, changed by `edit`, parsed as `file`.
fn broken(file: &str, edit: impl FnOnce(&mut Value)) -> GarmentError {
    let text = std::fs::read_to_string(pattern_path("shirt_mean")).unwrap();
    let mut v: Value = serde_json::from_str(&text).unwrap();
    edit(&mut v);
    garmentcode::parse(&v.to_string(), file).unwrap_err()
}

#[test]
fn broken_patterns_get_errors_naming_file_panel_and_edge() {
    // Stitch 7 sews left_ftorso edge 1; stitch 0 is made to sew it too.
    let e = broken("twice.json", |v| {
        v["pattern"]["stitches"][0][0] = serde_json::json!({"panel": "left_ftorso", "edge": 1})
    });
    assert!(
        matches!(e, GarmentError::StitchedTwice { ref panel, edge: 1, first: 0, second: 7, .. } if panel == "left_ftorso"),
        "{e}"
    );
    assert!(e.to_string().starts_with("twice.json: edge 1 of panel \"left_ftorso\" is stitched twice"), "{e}");

    let e = broken("no_panel.json", |v| v["pattern"]["stitches"][3][1]["panel"] = "pocket".into());
    assert_eq!(e.to_string(), "no_panel.json: stitch 3 names panel \"pocket\", which the pattern does not have");

    let e = broken("no_edge.json", |v| v["pattern"]["stitches"][2][1]["edge"] = 9.into());
    assert_eq!(
        e.to_string(),
        "no_edge.json: stitch 2 names edge 9 of panel \"left_ftorso\", which has 7 edges (0 to 6)"
    );

    // Swap two corners of the back: its outline crosses itself.
    let e = broken("crossing.json", |v| {
        let verts = v["pattern"]["panels"]["left_btorso"]["vertices"].as_array_mut().unwrap();
        verts.swap(0, 1);
    });
    assert!(matches!(e, GarmentError::SelfIntersecting { ref panel, .. } if panel == "left_btorso"), "{e}");
    assert!(e.to_string().starts_with("crossing.json: panel \"left_btorso\" intersects itself: edge "), "{e}");

    // All corners at one point.
    let e = broken("empty.json", |v| {
        for p in v["pattern"]["panels"]["right_sleeve_f"]["vertices"].as_array_mut().unwrap() {
            *p = serde_json::json!([1.0, 2.0]);
        }
    });
    assert!(e.to_string().starts_with("empty.json: panel \"right_sleeve_f\" is empty"), "{e}");
    let e = broken("no_edges.json", |v| v["pattern"]["panels"]["right_sleeve_f"]["edges"] = serde_json::json!([]));
    assert!(e.to_string().starts_with("no_edges.json: panel \"right_sleeve_f\" is empty"), "{e}");

    let e = broken("curve.json", |v| {
        v["pattern"]["panels"]["left_ftorso"]["edges"][5]["curvature"]["type"] = "spline".into()
    });
    assert_eq!(
        e.to_string(),
        "curve.json: panel \"left_ftorso\", edge 5: unknown curvature type \"spline\" (quadratic, cubic, circle)"
    );

    // Different lengths are a warning, not an error: shorten the left front's side seam.
    let text = std::fs::read_to_string(pattern_path("shirt_mean")).unwrap();
    let mut v: Value = serde_json::from_str(&text).unwrap();
    v["pattern"]["panels"]["left_ftorso"]["vertices"][2][1] = 16.0.into();
    let p = garmentcode::parse(&v.to_string(), "short.json").unwrap();
    let w = p.validate().unwrap();
    // The moved corner also lengthens the armhole edge 2 (stitch 3).
    assert_eq!(w.len(), 2, "{w:?}");
    assert!(w[0].starts_with("short.json: stitch 3 sews edge 2 of panel \"left_sleeve_b\" (0.8 cm) to edge 2 of panel \"left_ftorso\" (10.2 cm)"), "{}", w[0]);
    assert!(w[1].starts_with("short.json: stitch 7 sews edge 1 of panel \"left_ftorso\" (16.0 cm) to edge 5 of panel \"left_btorso\" (26.1 cm)"), "{}", w[1]);
    // The unchanged patterns raise none, except where the design sews unequal edges.
    assert!(garmentcode::load(&pattern_path("shirt_mean")).unwrap().validate().unwrap().is_empty());
}

#[test]
fn simon_shirt_sews_from_svg_and_sidecar() {
    let p = simon();
    assert_eq!((p.panels.len(), p.stitches.len()), (7, 15));
    let w = p.validate().unwrap();
    assert!(w.is_empty(), "{w:?}");
    let sewn = p.sew(2.0, Fit::default()).unwrap();
    assert_stitches(&p, &sewn);
    assert_manifold(&sewn, "simon");
    // The SVG is in mm: the front's hem edge is 269.6 mm.
    let front = &p.panels[0];
    assert!((front.edges[0].length() - 26.96).abs() < 1e-9, "{}", front.edges[0].length());
    // Placement and directions: every stitch's sewn vertices are closer as paired than
    // reversed (or within 5 mm: the 9 cm cap-to-yoke edges lie crosswise 14 cm apart in the
    // flat layout), and no sewn pair starts farther apart than the front is from the back.
    for k in 0..p.stitches.len() {
        let (along, against) = stitch_gaps(&sewn, k);
        assert!(along < against + 0.5, "stitch {k}: {along} cm along, {against} cm reversed");
        assert!(along < 40.0, "stitch {k}: {along} cm apart");
    }
    // The drawn side is the fabric's front: the fronts' triangles face +z, the back's -z.
    let x = &sewn.positions;
    let normal = |piece: &str| {
        let id = sewn.piece_names.iter().position(|n| n == piece).unwrap() as u32;
        let t = sewn.mesh.triangles().iter().find(|t| sewn.mesh.piece_ids()[t[0] as usize] == id).unwrap();
        let [a, b, c] = t.map(|i| x[i as usize]);
        (b - a).cross(c - a).normalize()
    };
    assert!(normal("front_left").z > 0.99 && normal("front_right").z > 0.99);
    assert!(normal("back_left").z < -0.99 && normal("back_right").z < -0.99 && normal("yoke").z < -0.99);
}

#[test]
fn sidecar_errors_name_the_sidecar_panel_and_edge() {
    let svg = std::fs::read_to_string(root().join("assets/patterns/freesewing-simon-shirt.svg")).unwrap();
    let parse = |ron: &str| -> GarmentError {
        let car: freesewing::Sidecar = ron::from_str(ron).unwrap();
        freesewing::build(&car, &svg, "car.ron", "simon.svg").unwrap_err()
    };
    let e = parse(r#"(svg: "x", panels: [(name: "a", part: "pocket")])"#);
    assert!(e.to_string().contains("simon.svg has no part \"pocket\""), "{e}");
    let e = parse(
        r#"(svg: "x", panels: [(name: "a", part: "cuff"), (name: "b", part: "cuff")],
            stitches: [(a: ("a", 0), b: ("b", 2)), (a: ("b", 2), b: ("a", 4))])"#,
    );
    assert_eq!(e.to_string(), "car.ron: edge 2 of panel \"b\" is stitched twice, in stitches 0 and 1");
    let e = parse(r#"(svg: "x", panels: [(name: "a", part: "cuff")], stitches: [(a: ("a", 0), b: ("a", 6))])"#);
    assert_eq!(e.to_string(), "car.ron: stitch 0 names edge 6 of panel \"a\", which has 6 edges (0 to 5)");
}

/// The bundled avatar (walking by the bundled BVH).
fn avatar() -> WalkingAvatar {
    WalkingAvatar::load(&root().join("assets/avatar")).unwrap()
}

/// MakeHuman's base body at rest (metres, feet on y = 0) and its arms.
fn rest_avatar() -> (BodyMesh, [ArmAxis; 2]) {
    let a = avatar();
    (a.rest_body(), ArmAxis::of_avatar(&a).unwrap())
}

/// The shirt at 3 cm edges (the node's default is 1 cm), fitted to MakeHuman as the node's
/// defaults do, its sleeves slid up the arms when on the body.
fn shirt_on(arms: Option<&[ArmAxis]>) -> (Sewn, Vec<SleeveFit>) {
    let p = garmentcode::load(&pattern_path("shirt_mean")).unwrap();
    let fit = Fit::ON_MAKEHUMAN;
    let mut sewn = p.sew(3.0, fit).unwrap();
    let fits = arms.map(|a| fit_sleeves(&mut sewn, a)).unwrap_or_default();
    (sewn, fits)
}

#[test]
fn a_one_piece_sleeve_is_wrapped_round_the_whole_arm() {
    let (body, arms) = rest_avatar();
    let mut sewn = simon().sew(2.0, Fit::default()).unwrap();
    let flat = sewn.clone();
    let fits = fit_sleeves(&mut sewn, &arms);
    assert_eq!(fits.len(), 2, "{fits:?}");
    assert!(fits.iter().all(|f| f.wrapped), "{fits:?}");
    let ids = sewn.mesh.piece_ids();
    for (k, arm) in arms.iter().enumerate() {
        let side = if k == 0 { "left" } else { "right" };
        let piece = sewn.piece_names.iter().position(|n| *n == format!("sleeve_{side}")).unwrap() as u32;
        let on_sleeve = |v: &u32| ids[*v as usize] == piece;
        // The underarm seam: its edges start a sleeve's width apart when laid flat, and meet
        // under the arm once wrapped.
        let (a, b) = sewn.stitched.iter().find(|(a, b)| on_sleeve(&a[0]) && on_sleeve(&b[0])).unwrap();
        let gap = |s: &Sewn| {
            a.iter()
                .zip(b)
                .map(|(&x, &y)| s.positions[x as usize].distance(s.positions[y as usize]))
                .fold(0.0, f32::max)
        };
        assert!(
            gap(&flat) > 0.2 && gap(&sewn) < 1e-3,
            "{side}: underarm seam {} m apart flat, {} m wrapped",
            gap(&flat),
            gap(&sewn)
        );
        // The sleeve goes round the arm, elbow and forearm included: no vertex within 3 cm of
        // the bones, and the joints inside the tube (the sleeve's nearest vertices to each are
        // on all sides of it).
        let sleeve: Vec<Vec3> =
            (0..sewn.positions.len() as u32).filter(on_sleeve).map(|v| sewn.positions[v as usize]).collect();
        let bone = |p: Vec3| {
            let d = |a, b| p.distance(closest_point_on_segment(p, a, b));
            d(arm.shoulder, arm.elbow).min(d(arm.elbow, arm.wrist))
        };
        let nearest = sleeve.iter().map(|&p| bone(p)).fold(f32::MAX, f32::min);
        assert!(nearest > 0.03, "{side}: a sleeve vertex {nearest} m from the arm's bones");
        for joint in [arm.elbow, (arm.elbow + arm.wrist) * 0.5] {
            let ring: Vec<Vec3> = sleeve.iter().filter(|p| p.distance(joint) < 0.1).map(|p| *p - joint).collect();
            let mean = ring.iter().sum::<Vec3>() / ring.len().max(1) as f32;
            assert!(
                ring.len() > 10 && mean.length() < 0.02,
                "{side}: the sleeve near {joint} is centred {mean} off it"
            );
        }
        // Longer than the arm, it is turned back before the wrist, not pulled over the hand;
        // and none of it starts in the body.
        let forearm = (arm.wrist - arm.elbow).normalize();
        let past = sleeve.iter().map(|p| (*p - arm.wrist).dot(forearm)).fold(f32::MIN, f32::max);
        let clearance = body.min_clearance(&sleeve, 0.05);
        eprintln!("{side}: {past} m past the wrist, clearance {clearance:?} m");
        assert!(past < 0.0, "{side}: the sleeve reaches {past} m past the wrist");
        assert!(clearance.is_none_or(|d| d > 0.0), "{side}: a sleeve vertex {clearance:?} m from the body");
    }
    // Round the upper arm, above the bend at the elbow, the flat panel is only rolled: every
    // edge keeps its length (the bend and the turned-back end start strained, and the cloth
    // eases them: `a_panel_placed_stretched_eases_into_its_rest_lengths_as_the_seams_close`).
    let rest = sewn.mesh.rest_positions();
    let on_upper_arm = |v: u32| {
        let p = sewn.positions[v as usize];
        arms.iter().any(|arm| {
            let axis = arm.elbow - arm.shoulder;
            let t = (p - arm.shoulder).dot(axis) / axis.length_squared();
            (0.0..0.4).contains(&t) && (p - arm.shoulder - axis * t).length() < 0.12
        })
    };
    let (mut worst, mut edges) = (0.0f32, 0);
    for t in sewn.mesh.triangles() {
        if !(sewn.piece_names[ids[t[0] as usize] as usize].starts_with("sleeve") && t.iter().all(|&v| on_upper_arm(v)))
        {
            continue;
        }
        for (i, j) in [(0, 1), (1, 2), (2, 0)] {
            let (x, y) = (t[i] as usize, t[j] as usize);
            let strain = sewn.positions[x].distance(sewn.positions[y]) / (rest[x].distance(rest[y]) * 0.01) - 1.0;
            worst = worst.max(strain.abs());
            edges += 1;
        }
    }
    assert!(edges > 300 && worst < 0.01, "{edges} sleeve edges round the upper arms, one strained {worst}");
}

/// The shirt draped for `frames` frames with or without the rest-pose avatar.
fn drape_shirt(on_body: bool, params: &DrapeParams, frames: u32) -> Drape {
    let avatar = on_body.then(rest_avatar);
    let (sewn, _) = shirt_on(avatar.as_ref().map(|(_, arms)| &arms[..]));
    let mut drape = Drape::new(&sewn, params, avatar.map(|(body, _)| body));
    assert!(drape.max_seam_gap() > 0.3, "the panels start apart ({} m)", drape.max_seam_gap());
    for _ in 0..frames {
        drape.step(None);
    }
    let c = &drape.cloth;
    assert!(c.positions().iter().chain(c.velocities()).all(|v| v.is_finite()), "NaN after the drape");
    drape
}

/// Finer garments take more substeps, so that the solver holds their stretch as it holds a
/// 1 cm garment's (at 0.5 cm with 20 the shirt stretched 38 % and slid off the shoulders).
#[test]
fn finer_garments_take_more_substeps() {
    let n = |edge| DrapeParams::substeps_for(edge, DrapeParams::SUBSTEPS_PER_CM);
    assert_eq!((n(3.0), n(1.5), n(1.0)), (20, 20, 20), "coarse garments keep the 20 the graphs were made with");
    assert_eq!((n(0.5), n(0.25)), (40, 80));
    // The node's knob: 40 per cm doubles them at 1 cm; never under 20.
    assert_eq!((DrapeParams::substeps_for(1.0, 40.0), DrapeParams::substeps_for(1.0, 5.0)), (40, 20));
}

#[test]
fn sewing_closes_the_seams() {
    // Gravity off throughout: the seams close over 0.4 s (24 frames) and settle.
    let params = DrapeParams { sewing_frames: 60, ..DrapeParams::default() };
    let drape = drape_shirt(false, &params, 60);
    let gap = drape.max_seam_gap();
    assert!(gap < 0.001, "sewn vertices {gap} m apart after 60 frames");
    let strain = drape.cloth.max_strain();
    assert!(strain < 0.5, "edge strain {strain}");
}

#[test]
fn sleeves_slide_up_the_arms_to_the_armholes() {
    let (_, arms) = rest_avatar();
    let (flat, _) = shirt_on(None);
    let (sewn, fits) = shirt_on(Some(&arms));
    // Both sleeves (front and back panel each) move together, about 14 cm up their arm.
    assert_eq!(fits.len(), 2, "{fits:?}");
    for f in &fits {
        let side = if f.arm == 0 { "left" } else { "right" };
        let mut panels = f.panels.clone();
        panels.sort();
        assert_eq!(panels, [format!("{side}_sleeve_b"), format!("{side}_sleeve_f")]);
        assert!((0.10..0.18).contains(&f.slide), "{side} sleeve slid {} m", f.slide);
    }
    // After the slide the caps' tops are level with the armholes' tops along each arm; the
    // sleeves moved rigidly along the arm axis and nothing else moved.
    let ids = sewn.mesh.piece_ids();
    for (k, arm) in arms.iter().enumerate() {
        let axis = (arm.elbow - arm.shoulder).normalize();
        let along = |v: u32| (sewn.positions[v as usize] - arm.shoulder).dot(axis);
        let side = if k == 0 { "left" } else { "right" };
        let is = |v: u32, what: &str| sewn.piece_names[ids[v as usize] as usize].starts_with(&format!("{side}_{what}"));
        let (mut cap, mut hole) = (f32::MAX, f32::MAX);
        for (a, b) in &sewn.stitched {
            if is(a[0], "sleeve") && is(b[0], "") && !is(b[0], "sleeve") {
                cap = a.iter().map(|&v| along(v)).fold(cap, f32::min);
                hole = b.iter().map(|&v| along(v)).fold(hole, f32::min);
            }
        }
        assert!(cap < f32::MAX && (cap - hole).abs() < 1e-5, "{side}: cap top {cap} m, armhole top {hole} m");
        let slide = fits.iter().find(|f| f.arm == k).unwrap().slide;
        for (v, (p, q)) in sewn.positions.iter().zip(&flat.positions).enumerate() {
            let other_sleeve = !is(v as u32, "sleeve") && sewn.piece_names[ids[v] as usize].contains("sleeve");
            let expect = if is(v as u32, "sleeve") { *q - axis * slide } else { *q };
            if other_sleeve {
                continue;
            }
            assert!(p.distance(expect) < 1e-5, "vertex {v}: {p} not {expect}");
        }
    }
}

#[test]
fn a_short_drape_on_the_avatar_closes_the_seams() {
    // Settled: a cloth edge held across the shoulder by friction comes free after frame 60.
    let drape = drape_shirt(true, &DrapeParams::default(), 70);
    let c = &drape.cloth;
    let gap = drape.max_seam_gap();
    let th = c.params().body_thickness;
    let clearance = c.body_clearance(0.05).expect("the shirt rests on the body");
    let p99 = c.strain_percentile(0.99);
    eprintln!(
        "after 70 frames: seam gap {gap} m, body crossings {}, self crossings {}, clearance {clearance} m (thickness {th} m), p99 strain {p99}, max speed {}",
        c.body_crossings(),
        c.self_crossings(),
        c.max_speed()
    );
    assert!(gap < 0.001, "sewn vertices {gap} m apart after 70 frames");
    assert_eq!(c.body_crossings(), 0, "cloth edges crossing the body");
    assert!(clearance >= 0.9 * th, "a vertex {clearance} m from the body (thickness {th} m)");
}

#[test]
fn the_shirt_stays_outside_the_body_through_the_walk() {
    // The arms spread 30 degrees: without it they pass through the torso at the armpits.
    let mut avatar = avatar();
    avatar.arm_spread = 30f64.to_radians();
    let pose_at = |seconds: f64| avatar.collision_vertices(&avatar.walk_pose(seconds));
    let (rest_body, arms) = (avatar.rest_body(), ArmAxis::of_avatar(&avatar).unwrap());
    let rest = rest_body.positions().to_vec();
    let (sewn, _) = shirt_on(Some(&arms));
    let params = DrapeParams {
        sim: SimParams { self_collision: true, untangle: true, ..DrapeParams::default().sim },
        ..DrapeParams::default()
    };
    let mut drape = Drape::new(&sewn, &params, Some(rest_body));
    for _ in 0..40 {
        drape.step(None);
    }
    // Half a second from the rest pose to the walk's first frame, then four seconds of walking
    // (four strides; the ten seconds of `werkstatt bench drape --frames 630` took 43 s of CI).
    let first = pose_at(0.0);
    let th = params.sim.body_thickness;
    for f in 0..270 {
        let body: Vec<Vec3> = if f < 30 {
            rest.iter().zip(&first).map(|(r, w)| r.lerp(*w, (f + 1) as f32 / 30.0)).collect()
        } else {
            pose_at((f - 30) as f64 / 60.0)
        };
        drape.step(Some(&body));
        let c = &drape.cloth;
        // Where the body is crossed: the crossing edges' midpoints.
        let crossings: Vec<Vec3> = c
            .body_crossing_edges()
            .iter()
            .map(|&e| c.edges()[e].map(|v| c.positions()[v as usize]))
            .map(|[a, b]| (a + b) * 0.5)
            .collect();
        let (gap, clearance) = (drape.max_seam_gap(), c.body_clearance(0.05));
        if f % 30 == 29 {
            // What the asserts do not cover, every half second (each a pass over the whole shirt).
            let (self_crossings, strain) = (c.self_crossings(), c.strain_percentile(0.99));
            let speed = c.max_speed();
            eprintln!("frame {f}: self crossings {self_crossings}, p99 strain {strain}, max speed {speed}");
        }
        assert!(c.positions().iter().chain(c.velocities()).all(|v| v.is_finite()), "NaN at frame {f}");
        assert!(gap < 0.001, "frame {f}: sewn vertices {gap} m apart");
        assert!(crossings.is_empty(), "frame {f}: cloth edges crossing the body at {crossings:?}");
        assert!(clearance.is_none_or(|d| d >= 0.9 * th), "frame {f}: a vertex {clearance:?} m from the body");
    }
}

/// `graph` (its paths relative to graphs/) evaluated at frame 0 for `targets`, loads waited for,
/// without a GPU; nodes may fail (see their reports).
fn frame_0(graph: &werkstatt::core::graph::Graph, targets: &[&str]) -> werkstatt::core::eval::Evaluator {
    use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime};
    let targets: Vec<String> = targets.iter().map(|t| t.to_string()).collect();
    let mut ev = Evaluator::new(graph, &targets).unwrap();
    let res = werkstatt::core::resources::Resources::new(false);
    let settings = FrameSettings { base_dir: root().join("graphs"), ..Default::default() };
    for _ in 0..50 {
        if ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, None, &res, &settings).pending == 0 {
            break;
        }
        crate::common::wait_idle(&res);
    }
    ev
}

/// The Garment node's surface at frame 0 (nothing simulated yet) for the shirt at 3 cm edges on
/// the resting Avatar node, with or without the avatar's joints linked.
fn garment_node_at_rest(joints: bool) -> Vec<Vec3> {
    let link = if joints { r#", ("avatar.joints", "garment.joints")"# } else { "" };
    let text = format!(
        r#"(version: 2, nodes: {{
            "avatar": (kind: "Avatar", params: {{}}),
            "garment": (kind: "Garment", params: {{"pattern": "../assets/patterns/garmentcode/shirt_mean_specification.json", "edge_length": 3.0}}),
        }}, links: [("avatar.collision", "garment.body"){link}])"#
    );
    let graph = werkstatt::core::graph::Graph::load_str(&text, &root().join("graphs/test.ron")).unwrap();
    let ev = frame_0(&graph, &["garment"]);
    let status = format!("{:?}", ev.report("garment").unwrap().status);
    match ev.output("garment", "surface") {
        Some(werkstatt::core::port::Value::Surface(m)) => m.positions.clone(),
        _ => panic!("no garment surface: {status}"),
    }
}

/// Positions as a sorted list, to compare meshes whose vertex order may differ.
fn sorted(mut p: Vec<Vec3>) -> Vec<Vec3> {
    p.sort_by(|a, b| a.to_array().partial_cmp(&b.to_array()).unwrap());
    p
}

#[test]
fn the_garment_node_fits_its_sleeves_to_the_avatars_joints() {
    let (_, arms) = rest_avatar();
    let (fitted, fits) = shirt_on(Some(&arms));
    assert_eq!(fits.len(), 2);
    let (unfitted, _) = shirt_on(None);
    let (with, without) = (sorted(garment_node_at_rest(true)), sorted(garment_node_at_rest(false)));
    let close = |a: &[Vec3], b: &[Vec3]| a.len() == b.len() && a.iter().zip(b).all(|(x, y)| x.distance(*y) < 1e-5);
    assert!(close(&with, &sorted(fitted.positions.clone())), "the node's sleeves are not fit_sleeves'");
    // Without joints the sleeves start where the pattern puts them, through the arms: only
    // their vertices inside the body are pushed out (`Cloth::start_outside_body`).
    let bits = |p: &Vec3| p.to_array().map(f32::to_bits);
    let kept: std::collections::HashSet<[u32; 3]> = without.iter().map(bits).collect();
    let moved = unfitted.positions.iter().filter(|p| !kept.contains(&bits(p))).count();
    assert!(moved > 0 && moved < unfitted.positions.len() / 10, "{moved} of {} vertices moved", without.len());
    assert!(!close(&with, &without));
}

/// `pattern` (under assets/patterns/garmentcode) on graphs/garment_shirt.ron's avatar (arms
/// spread 30 degrees) at 4 cm edges with self-collision, rest shortened to 1 s, evaluated frame
/// by frame at 60 fps (one simulator step each, the body moving between them) to 2.5 s: 1 s at
/// rest, 0.5 s of blend, 1 s of walk. `offset` is the Garment node's (cm). Returns the garment's
/// bounds, mean height and seam gap.
fn worn_through_rest_blend_and_walk(pattern: &str, offset: [f32; 3]) -> (Vec3, Vec3, f32, f32) {
    use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime};
    use werkstatt::core::port::Value;
    let text = format!(
        r#"(version: 2, nodes: {{
        "avatar": (kind: "Avatar", params: {{"joint_map": "../assets/avatar/makehuman-old-rig.ron", "motion": "../assets/avatar/walk1.bvh", "rest": 1.0, "arm_spread": 30.0}}),
        "garment": (kind: "Garment", params: {{"pattern": "../assets/patterns/garmentcode/{pattern}", "edge_length": 4.0, "self_collision": true, "offset": {offset:?}}}),
    }}, links: [("avatar.collision", "garment.body"), ("avatar.joints", "garment.joints")])"#
    );
    let graph = werkstatt::core::graph::Graph::load_str(&text, &root().join("graphs/test.ron")).unwrap();
    let mut ev = Evaluator::new(&graph, &["garment".to_string()]).unwrap();
    let res = werkstatt::core::resources::Resources::new(false);
    let settings = FrameSettings { base_dir: root().join("graphs"), ..Default::default() };
    for frame in 0..=150 {
        for _ in 0..50 {
            if ev.evaluate(FrameTime { frame, fps: 60.0 }, None, &res, &settings).pending == 0 {
                break;
            }
            crate::common::wait_idle(&res);
        }
    }
    let status = format!("{:?}", ev.report("garment").unwrap().status);
    let (Some(Value::Surface(garment)), Some(Value::Scalar(gap))) =
        (ev.output("garment", "surface"), ev.output("garment", "seam_gap"))
    else {
        panic!("no garment from {pattern}: {status}");
    };
    let (lo, hi) = garment.bounds();
    let mean_y = garment.positions.iter().map(|p| p.y).sum::<f32>() / garment.positions.len() as f32;
    eprintln!("{pattern}: bounds {lo} {hi}, mean y {mean_y}, seam gap {gap}");
    assert!(garment.positions.iter().all(|p| p.is_finite()), "{pattern}: NaN");
    (lo, hi, mean_y, *gap as f32)
}

#[test]
fn the_shirt_graph_keeps_the_shirt_on_through_rest_blend_and_walk() {
    let (lo, hi, mean_y, gap) = worn_through_rest_blend_and_walk("shirt_mean_specification.json", [0.0, 0.0, 3.0]);
    assert!(gap < 1e-3, "the seams opened to {gap} m");
    assert!(lo.y > 0.8 && hi.y < 1.6 && mean_y > 1.1, "the shirt is not on the torso: {lo} {hi}, mean y {mean_y}");
}

#[test]
fn the_hoodie_stays_on_through_rest_blend_and_walk() {
    // Torso below the hips' top, hood over the head (MakeHuman's crown at 1.67 m).
    let (lo, hi, mean_y, gap) = worn_through_rest_blend_and_walk("hoody_mean_specification.json", [0.0, 0.0, 3.0]);
    assert!(gap < 1e-3, "the seams opened to {gap} m");
    assert!(
        lo.y > 0.8 && (1.6..1.9).contains(&hi.y) && mean_y > 1.2,
        "the hoodie is not on: {lo} {hi}, mean y {mean_y}"
    );
}

#[test]
fn the_pencil_dress_hangs_from_its_shoulder_straps_through_rest_blend_and_walk() {
    // graphs/garment_dress.ron's placement, 4 cm above the shirt's: the straps' seams close over
    // the shoulders (MakeHuman's are at about 1.40 m) rather than through them.
    let (lo, hi, mean_y, gap) = worn_through_rest_blend_and_walk("dress_pencil_specification.json", [0.0, 4.0, 3.0]);
    assert!(gap < 1e-3, "the seams opened to {gap} m");
    assert!(
        (1.35..1.55).contains(&hi.y) && lo.y > 0.05 && mean_y > 0.7,
        "the dress is not hanging from the shoulders: {lo} {hi}, mean y {mean_y}"
    );
}

/// A drape saved mid-run and restored into a fresh drape goes on exactly as the run it was saved
/// from: positions, velocities, time, frame and the self-contacts' sides are what one frame
/// hands the next (the shirt at 3 cm on the rest-pose avatar, self-collision on, walking body
/// frames after the save).
#[test]
fn a_saved_drape_goes_on_as_the_run_it_was_saved_from() {
    use werkstatt::garment::drape::DrapeState;
    let params =
        DrapeParams { sim: SimParams { self_collision: true, ..DrapeParams::default().sim }, ..Default::default() };
    let (body, arms) = rest_avatar();
    let (sewn, _) = shirt_on(Some(&arms));
    let new_drape = || Drape::new(&sewn, &params, Some(body.clone()));
    let key = Drape::key(&sewn, &params, Some(body.positions().len()));
    let mut run = new_drape();
    for _ in 0..40 {
        run.step(None);
    }
    let saved = DrapeState::from_bytes(&run.state(key).to_bytes()).unwrap();
    assert_eq!(saved, run.state(key), "the file round trip changed the state");
    assert!(!saved.cloth.sides.is_empty(), "no self-contacts recorded after 40 frames");
    let mut restored = new_drape();
    restored.restore(&saved).unwrap();
    for _ in 0..20 {
        run.step(None);
        restored.step(None);
    }
    let worst =
        run.cloth.positions().iter().zip(restored.cloth.positions()).map(|(a, b)| a.distance(*b)).fold(0.0, f32::max);
    assert_eq!(worst, 0.0, "the restored drape drifted {worst} m from the run it was saved from");
    // A fresh drape sewn from the flat panels is elsewhere: the comparison can fail.
    let mut fresh = new_drape();
    for _ in 0..20 {
        fresh.step(None);
    }
    let apart =
        run.cloth.positions().iter().zip(fresh.cloth.positions()).map(|(a, b)| a.distance(*b)).fold(0.0, f32::max);
    assert!(apart > 0.01, "a fresh drape is only {apart} m from the saved run");
    // Another garment's key differs (the same pattern at another edge length).
    let other = garmentcode::load(&pattern_path("shirt_mean")).unwrap().sew(4.0, Fit::default()).unwrap();
    assert_ne!(key, Drape::key(&other, &params, Some(body.positions().len())));
}

#[test]
fn broken_drape_states_get_clear_errors() {
    use werkstatt::cloth::ClothState;
    use werkstatt::garment::drape::DrapeState;
    let cloth = ClothState {
        positions: vec![Vec3::X, Vec3::Y],
        velocities: vec![Vec3::ZERO; 2],
        time: 0.05,
        frame: 3,
        sides: vec![(0, 0, 1.0)],
        body_sides: Vec::new(),
    };
    let state = DrapeState { key: 7, cloth };
    let bytes = state.to_bytes();
    assert_eq!(DrapeState::from_bytes(&bytes).unwrap(), state);
    let err = |b: &[u8]| format!("{:#}", DrapeState::from_bytes(b).unwrap_err());
    assert!(err(&bytes[..bytes.len() - 4]).contains("cut short"), "{}", err(&bytes[..bytes.len() - 4]));
    assert!(err(&bytes[..10]).contains("too short"), "{}", err(&bytes[..10]));
    let mut wrong = bytes.clone();
    wrong[0] = b'X';
    assert!(err(&wrong).contains("not a werkstatt drape state"), "{}", err(&wrong));
    let mut nan = bytes.clone();
    let at = bytes.len() - 12 * 2 - 12;
    nan[at..at + 4].copy_from_slice(&f32::NAN.to_le_bytes());
    assert!(err(&nan).contains("non-finite"), "{}", err(&nan));
    // A state for another cloth is refused by name.
    let (sewn, _) = shirt_on(None);
    let mut drape = Drape::new(&sewn, &DrapeParams::default(), None);
    let msg = format!("{:#}", drape.restore(&state).unwrap_err());
    assert!(msg.contains("does not fit") && msg.contains("2 positions"), "{msg}");
}

/// graphs/default.ron starts its shirt from the drape saved by graphs/garment_shirt.ron at
/// the end of its rest and blend (assets/drapes/garment_shirt_walk.drape): on the torso at frame
/// 0, where without the state the panels would be flat and apart; four buttons down its front.
/// With another edge length the state does not fit: a warning says so and the shirt is sewn from
/// the panels.
#[test]
fn the_walk_graph_starts_from_its_saved_drape() {
    use werkstatt::core::port::Value;
    let run = |edge: Option<f64>| {
        let mut graph = werkstatt::core::graph::Graph::load(&root().join("graphs/default.ron")).unwrap();
        if let Some(edge) = edge {
            graph
                .nodes
                .get_mut("garment")
                .unwrap()
                .params
                .insert("edge_length".into(), werkstatt::core::param::ParamValue::Float(edge));
        }
        let ev = frame_0(&graph, &["garment", "button_row"]);
        // Four buttons down the right front panel (piece 3 in GarmentCode's panel order).
        if let Some(Value::Instances(buttons)) = ev.output("button_row", "placements") {
            assert!(buttons.len() == 4 && buttons.iter().all(|b| b.piece == 3), "buttons {buttons:?}");
        } else {
            panic!("no buttons: {:?}", ev.report("button_row").unwrap().status);
        }
        let report = ev.report("garment").unwrap();
        let warnings = report.warnings.join("\n");
        let Some(Value::Surface(shirt)) = ev.output("garment", "surface") else {
            panic!("no garment: {:?}", report.status);
        };
        let Some(Value::Scalar(gap)) = ev.output("garment", "seam_gap") else { panic!("no seam gap") };
        (shirt.bounds(), *gap, warnings)
    };
    let ((lo, hi), gap, warnings) = run(None);
    assert!(warnings.is_empty(), "{warnings}");
    assert!(gap < 1e-3, "the saved shirt's seams are {gap} m open");
    assert!(lo.y > 0.8 && hi.y < 1.6, "the shirt is not on the torso at frame 0: {lo} {hi}");
    let (_, gap, warnings) = run(Some(4.0));
    assert!(warnings.contains("start_state") && warnings.contains("sewing from the flat panels"), "{warnings}");
    assert!(gap > 0.05, "the panels should start apart without the state: {gap} m");
}

#[test]
fn saving_over_the_start_state_is_refused() {
    use werkstatt::core::eval::NodeStatus;
    use werkstatt::core::param::ParamValue;
    let mut graph = werkstatt::core::graph::Graph::load(&root().join("graphs/default.ron")).unwrap();
    let same = graph.nodes["garment"].params["start_state"].clone();
    graph.nodes.get_mut("garment").unwrap().params.insert("save_state".into(), same);
    graph.nodes.get_mut("garment").unwrap().params.insert("save_at".into(), ParamValue::Float(1.0));
    let ev = frame_0(&graph, &["garment"]);
    match &ev.report("garment").unwrap().status {
        NodeStatus::Failed(m) => assert!(m.contains("same file"), "{m}"),
        other => panic!("saving over the start state was accepted: {other:?}"),
    }
}

#[test]
fn the_clearance_is_the_distance_to_the_bodys_nearest_point() {
    // Points around the walking body's torso and arms: where the nearest body point is within
    // 5 cm, the clearance is its distance (signed); farther out there is none. A nearest among
    // the triangles whose boxes reach the point only (a far triangle seen from behind) read
    // points 10 cm in front of the belly as 24 cm inside.
    use werkstatt::cloth::body_collision::closest_point_feature;
    let avatar = avatar();
    let x = avatar.collision_vertices(&avatar.walk_pose(0.5));
    let tris = avatar.rest_body().triangles().to_vec();
    let body = BodyMesh::new(x.clone(), tris.clone());
    let max = 0.05;
    let (mut near, mut checked) = (0, 0);
    for i in 0..14 {
        for j in 0..14 {
            for k in 0..10 {
                let p = Vec3::new(
                    -0.35 + 0.7 * i as f32 / 13.0,
                    0.9 + 0.6 * j as f32 / 13.0,
                    -0.25 + 0.55 * k as f32 / 9.0,
                );
                let nearest = tris
                    .iter()
                    .map(|t| {
                        let [a, b, c] = t.map(|v| x[v as usize]);
                        p.distance(closest_point_feature(p, a, b, c).0)
                    })
                    .fold(f32::INFINITY, f32::min);
                if (nearest - max).abs() < 1e-4 {
                    continue;
                }
                checked += 1;
                match body.min_clearance(&[p], max) {
                    Some(d) => {
                        assert!(
                            (d.abs() - nearest).abs() < 1e-5,
                            "at {p}: clearance {d} m, the nearest body point {nearest} m"
                        );
                        near += 1;
                    }
                    None => assert!(nearest > max, "at {p}: no clearance, the nearest body point {nearest} m"),
                }
            }
        }
    }
    assert!(near > 100 && checked > 1900, "{near} of {checked} points near the body");
}

/// Avatar (`extra` params) wearing the bundled worksuit, its clothes settled by `SettleSurface`
/// at `frame` (60 fps): the fitted suit, the settled suit and the collision body.
fn settled_worksuit(extra: &str, frame: i64) -> (Arc<Mesh>, Arc<Mesh>, Arc<Mesh>) {
    use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime};
    use werkstatt::core::port::Value;
    let text = format!(
        r#"(version: 2, nodes: {{
        "avatar": (kind: "Avatar", params: {{"clothes": "../assets/avatar/male_worksuit01.mhclo", "joint_map": "../assets/avatar/makehuman-old-rig.ron", "motion": "../assets/avatar/walk1.bvh", {extra}}}),
        "settle": (kind: "SettleSurface", params: {{}}),
    }}, links: [("avatar.clothes", "settle.surface"), ("avatar.collision", "settle.body")])"#
    );
    let graph = werkstatt::core::graph::Graph::load_str(&text, &root().join("graphs/test.ron")).unwrap();
    let mut ev = Evaluator::new(&graph, &["settle".to_string()]).unwrap();
    let res = werkstatt::core::resources::Resources::new(false);
    let settings = FrameSettings { base_dir: root().join("graphs"), ..Default::default() };
    for _ in 0..50 {
        if ev.evaluate(FrameTime { frame, fps: 60.0 }, None, &res, &settings).pending == 0 {
            break;
        }
        crate::common::wait_idle(&res);
    }
    let status = format!("{:?}", ev.report("settle").unwrap().status);
    let (Some(Value::Surface(fitted)), Some(Value::Surface(settled)), Some(Value::Mesh(body))) =
        (ev.output("avatar", "clothes"), ev.output("settle", "surface"), ev.output("avatar", "collision"))
    else {
        panic!("no settled suit: {status}");
    };
    (fitted.clone(), settled.clone(), body.clone())
}

/// Body crossings (cloth edges through the body's triangles), the smallest clearance (m) and
/// each edge's length, of a garment surface on a body.
fn on_body(garment: &Mesh, body: &Mesh) -> (usize, f32, Vec<f32>) {
    let b = BodyMesh::from_mesh(body);
    let mut edges: Vec<[u32; 2]> = garment
        .indices
        .chunks_exact(3)
        .flat_map(|t| (0..3).map(move |k| [t[k].min(t[(k + 1) % 3]), t[k].max(t[(k + 1) % 3])]))
        .collect();
    edges.sort_unstable();
    edges.dedup();
    let x = &garment.positions;
    let lengths = edges.iter().map(|e| x[e[0] as usize].distance(x[e[1] as usize])).collect();
    (b.crossings(x, &edges).len(), b.min_clearance(x, 0.05).unwrap_or(f32::INFINITY), lengths)
}

/// The worksuit fitted by its .mhclo to the rest-pose body cuts into it (about 90 edges cross,
/// 4.7 mm deep); four quasi-static steps push it out to the body thickness, its shape kept.
#[test]
fn settling_pushes_the_fitted_worksuit_out_of_the_body_and_keeps_its_shape() {
    let (fitted, settled, body) = settled_worksuit(r#""rest": 1.0"#, 0);
    let (before, clear_before, rest) = on_body(&fitted, &body);
    let (after, clear_after, lengths) = on_body(&settled, &body);
    let mut strain: Vec<f32> = lengths.iter().zip(&rest).map(|(l, r)| (l / r - 1.0).abs()).collect();
    strain.sort_by(f32::total_cmp);
    let p99 = strain[strain.len() * 99 / 100];
    let moved = fitted.positions.iter().zip(&settled.positions).map(|(a, b)| a.distance(*b)).fold(0.0, f32::max);
    eprintln!(
        "crossings {before} -> {after}, clearance {clear_before} -> {clear_after} m, p99 strain {p99}, moved {moved} m"
    );
    assert!(before > 50 && clear_before < -0.003, "the fit no longer cuts in: {before} crossings, {clear_before} m");
    assert_eq!(after, 0, "settled, {after} edges still cross the body");
    assert!(clear_after >= 0.9 * SimParams::default().body_thickness, "settled clearance {clear_after} m");
    assert!(p99 < 0.05, "the settle changed edge lengths by {p99} (99th percentile)");
    assert!(moved < 0.02, "a vertex moved {moved} m");
    assert_eq!(settled.uvs, fitted.uvs);
    assert_eq!(settled.indices, fitted.indices);
}

/// In a walking pose (arms spread 30 degrees) the fit cuts deeper than contacts reach (2 cm):
/// the settle removes most crossings, not all.
#[test]
fn settling_the_worksuit_on_the_walk_removes_most_crossings() {
    let (fitted, settled, body) = settled_worksuit(r#""arm_spread": 30.0"#, 0);
    let (before, _, _) = on_body(&fitted, &body);
    let (after, _, _) = on_body(&settled, &body);
    eprintln!("walk: crossings {before} -> {after}");
    assert!(after * 2 < before, "crossings {before} -> {after}");
}

//! The cuboid scene graph (dissertation section 3.1.1, src/cuboid/mod.rs): eq. 3.1 against eq.
//! 3.4, the linear fast path, C0 grids, composition against an analytic bend, anchors under a
//! rigid motion, the nodes, and the trilinear vertex stage against the CPU transform.

use crate::common;

use std::sync::Arc;

use glam::{DMat4, DQuat, DVec2, DVec3, Mat4, Vec3};
use proptest::prelude::*;
use werkstatt::core::graph::Graph;
use werkstatt::core::port::Value;
use werkstatt::cuboid::{
    Anchor, Cuboid, CuboidGrid, LINEAR_TOLERANCE, Lift, NormalMethod, Transform, anchor_grid, anchor_row, bend,
    compose, unit_corner,
};
use werkstatt::gpu::read_back;
use werkstatt::mesh::Mesh;
use werkstatt::render::draw::SceneDrawer;
use werkstatt::render::scene::{DrawItem, Material, View};

fn vec3() -> impl Strategy<Value = DVec3> {
    (-10.0..10.0f64, -10.0..10.0f64, -10.0..10.0f64).prop_map(|(x, y, z)| DVec3::new(x, y, z))
}

fn affine() -> impl Strategy<Value = DMat4> {
    (vec3(), vec3(), 0.2..3.0f64, 0.2..3.0f64, 0.2..3.0f64).prop_map(|(axis, t, sx, sy, sz)| {
        let rotation = DQuat::from_scaled_axis(axis * 0.3);
        DMat4::from_translation(t) * DMat4::from_quat(rotation) * DMat4::from_scale(DVec3::new(sx, sy, sz))
    })
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(200))]

    #[test]
    fn corners_map_to_their_points_and_eq_3_1_equals_eq_3_4(
        corners in prop::array::uniform8(vec3()),
        points in prop::collection::vec((0.0..1.0f64, 0.0..1.0f64, 0.0..1.0f64), 50),
    ) {
        let c = Cuboid { corners };
        for (i, p) in corners.iter().enumerate() {
            prop_assert!(c.eval(unit_corner(i)).distance(*p) < 1e-9);
        }
        for (x, y, z) in points {
            let p = DVec3::new(x, y, z);
            prop_assert!(c.eval(p).distance(c.eval_corners(p)) < 1e-6);
        }
    }

    #[test]
    fn affine_corners_have_a_zero_left_half_and_one_moved_corner_switches_the_path(
        m in affine(),
        corner in 0usize..8,
        nudge in vec3(),
        points in prop::collection::vec((0.0..1.0f64, 0.0..1.0f64, 0.0..1.0f64), 20),
    ) {
        let c = Cuboid::from_affine(m);
        let coefficients = c.coefficients();
        for column in &coefficients.0[..4] {
            prop_assert!(column.length() < 1e-6, "left half {:?}", coefficients.0);
        }
        let fast = c.as_affine(LINEAR_TOLERANCE).expect("an affine cuboid takes the fast path");
        prop_assert!(fast.abs_diff_eq(m, 1e-9));
        for (x, y, z) in points {
            let p = DVec3::new(x, y, z);
            prop_assert!(fast.transform_point3(p).distance(c.eval(p)) < 1e-9);
        }
        // A corner moved by 1e-3 of the cuboid's size makes it trilinear.
        let mut moved = c;
        let size = m.x_axis.length().max(m.y_axis.length()).max(m.z_axis.length());
        moved.corners[corner] += nudge.normalize_or(DVec3::X) * 1e-3 * size;
        prop_assert!(moved.as_affine(LINEAR_TOLERANCE).is_none());
        let grid = CuboidGrid::single(-DVec3::ONE, DVec3::ONE, moved, NormalMethod::Direct).unwrap();
        prop_assert!(matches!(Transform::from_grid(grid), Transform::Grid(_)));
    }
}

#[test]
fn affine_after_affine_is_the_matrix_product_and_a_grid_that_becomes_affine_drops_to_the_fast_path() {
    let a = DMat4::from_rotation_y(0.4) * DMat4::from_translation(DVec3::new(1.0, 2.0, 3.0));
    let b = DMat4::from_scale(DVec3::new(2.0, 1.0, 0.5));
    let model = Mat4::from_translation(Vec3::new(0.5, 0.0, 0.0));
    let (m1, g1) = compose(model, None, &Transform::Affine(b));
    let (m2, g2) = compose(m1, g1.as_ref(), &Transform::Affine(a));
    assert!(g2.is_none());
    assert!(m2.abs_diff_eq((a * b).as_mat4() * model, 1e-5));
    // A twisted cuboid, then its own corners moved back onto a parallelepiped by an affine
    // map, is still a grid; a grid whose corners are affine images is folded into the model.
    let lo = -DVec3::ONE;
    let affine_grid =
        CuboidGrid::from_fn(lo, DVec3::ONE, [3, 2, 2], NormalMethod::Direct, |u| a.transform_point3(lo + 2.0 * u))
            .unwrap();
    let (m3, g3) = compose(model, None, &Transform::Grid(Arc::new(affine_grid)));
    assert!(g3.is_none(), "an affine 3x2x2 grid takes the fast path");
    assert!(m3.abs_diff_eq(a.as_mat4() * model, 1e-5));
}

#[test]
fn points_on_a_face_shared_by_two_cells_map_identically_from_both() {
    let (lo, hi) = (DVec3::new(-2.0, -0.5, -0.5), DVec3::new(2.0, 0.5, 0.5));
    let grid =
        CuboidGrid::from_fn(lo, hi, [2, 1, 1], NormalMethod::TangentSpace, |u| bend(lo, hi, 120.0)(lo + u * (hi - lo)))
            .unwrap();
    let (left, right) = (grid.cell(0, 0, 0), grid.cell(1, 0, 0));
    let mut worst: f64 = 0.0;
    for i in 0..=20 {
        for j in 0..=20 {
            let (y, z) = (i as f64 / 20.0, j as f64 / 20.0);
            let a = left.eval(DVec3::new(1.0, y, z));
            let b = right.eval(DVec3::new(0.0, y, z));
            worst = worst.max(a.distance(b));
        }
    }
    assert!(worst < 1e-12, "cells disagree on their shared face by {worst}");
    // Just off the face the two cells' polynomials differ (C0, not C1): the check above sees a
    // real seam, not two copies of one cell.
    let d = left.coefficients().jacobian(DVec3::new(1.0, 0.5, 0.5))
        - right.coefficients().jacobian(DVec3::new(0.0, 0.5, 0.5));
    assert!(d.x_axis.length() > 1e-3, "the cells' x derivatives agree: {d:?}");
}

#[test]
fn composition_error_against_an_analytic_bend_falls_as_the_grid_is_refined() {
    // Inner: a mildly trilinear cuboid over a small box; outer: a bend grid over a larger box.
    let (lo, hi) = (DVec3::new(-2.0, -0.5, -0.5), DVec3::new(2.0, 0.5, 0.5));
    let mut inner_cuboid = Cuboid::from_affine(
        DMat4::from_translation(DVec3::new(-1.5, -0.4, -0.4)) * DMat4::from_scale(DVec3::new(3.0, 0.8, 0.8)),
    );
    inner_cuboid.corners[7] += DVec3::new(0.1, 0.05, 0.0);
    let inner = CuboidGrid::single(DVec3::ZERO, DVec3::ONE, inner_cuboid, NormalMethod::Direct).unwrap();
    let exact = bend(lo, hi, 150.0);
    let mut errors = Vec::new();
    for n in [2usize, 4, 8, 16] {
        let outer =
            CuboidGrid::from_fn(lo, hi, [n, n, 1], NormalMethod::Direct, |u| exact(lo + u * (hi - lo))).unwrap();
        let composed = inner.then_grid(&outer);
        assert_eq!(composed.cells, [n, n, 1], "composition keeps the finer resolution");
        let mut worst: f64 = 0.0;
        for i in 0..=30 {
            for j in 0..=6 {
                let p = DVec3::new(i as f64 / 30.0, j as f64 / 6.0, 0.37);
                worst = worst.max(composed.eval(p).distance(exact(inner.eval(p))));
            }
        }
        errors.push(worst);
    }
    assert!(errors.windows(2).all(|w| w[1] < w[0]), "errors {errors:?} do not fall");
    assert!(errors[3] < errors[0] / 10.0, "errors {errors:?} fall too slowly");
}

fn rotate_mesh(mesh: &Mesh, r: DQuat, t: DVec3) -> Mesh {
    let mut moved = mesh.clone();
    for p in &mut moved.positions {
        *p = (r * p.as_dvec3() + t).as_vec3();
    }
    moved
}

#[test]
fn a_rigid_motion_of_the_base_mesh_moves_the_anchored_object_rigidly() {
    let body = werkstatt::nodes::mesh::geometry::sphere(1.0, 24, 16).unwrap();
    let (cols, rows) = (3, 3);
    let frames_on = |mesh: &Mesh| {
        let mut frames = Vec::new();
        for j in 0..rows {
            for i in 0..cols {
                let uv = DVec2::new(0.3 + 0.05 * i as f64, 0.4 + 0.05 * j as f64);
                let anchor = Anchor::at_uv(&body, uv, 0.01).unwrap();
                frames.push(anchor.frame(mesh).unwrap());
            }
        }
        frames
    };
    let grid_on = |mesh: &Mesh, lift: Lift| {
        anchor_grid(&frames_on(mesh), cols, rows, 0.2, lift, -DVec3::ONE, DVec3::ONE, NormalMethod::TangentSpace)
            .unwrap()
    };
    let (r, t) = (DQuat::from_scaled_axis(DVec3::new(0.3, -1.1, 0.5)), DVec3::new(0.7, -2.0, 1.3));
    for lift in [Lift::Normal, Lift::MeanNormal] {
        let before = grid_on(&body, lift);
        let after = grid_on(&rotate_mesh(&body, r, t), lift);
        assert!(before.as_affine(LINEAR_TOLERANCE).is_none(), "the anchored grid follows the sphere's curvature");
        let object = werkstatt::nodes::mesh::geometry::cube(1.5).unwrap();
        let size = before.corners.iter().fold(0.0f64, |m, c| m.max(c.length()));
        let mut worst: f64 = 0.0;
        for p in &object.positions {
            let expected = r * before.eval(p.as_dvec3()) + t;
            worst = worst.max(after.eval(p.as_dvec3()).distance(expected) / size);
        }
        assert!(worst < 1e-5, "{lift:?}: relative error {worst}");
    }
}

/// Lifted along the mean normal, a tall anchor grid on a curved surface is a slab: every
/// corner's column is `height` times the same unit vector, the normalized mean of the anchors'
/// normals; lifted along each anchor's normal, the columns splay (by the sphere's curvature).
#[test]
fn an_anchor_grid_lifted_along_the_mean_normal_has_parallel_columns() {
    let body = werkstatt::nodes::mesh::geometry::sphere(1.0, 48, 32).unwrap();
    let (cols, rows, height) = (3, 3, 0.5);
    let frames: Vec<_> = (0..cols * rows)
        .map(|k| {
            let uv = DVec2::new(0.3 + 0.08 * (k % cols) as f64, 0.35 + 0.08 * (k / cols) as f64);
            Anchor::at_uv(&body, uv, 0.01).unwrap().frame(&body).unwrap()
        })
        .collect();
    let mean = frames.iter().map(|f| f.normal).sum::<DVec3>().normalize();
    let columns = |lift: Lift| {
        let g = anchor_grid(&frames, cols, rows, height, lift, -DVec3::ONE, DVec3::ONE, NormalMethod::Direct).unwrap();
        let n = cols * rows;
        (0..n).map(|i| g.corners[n + i] - g.corners[i]).collect::<Vec<_>>()
    };
    for c in columns(Lift::MeanNormal) {
        assert!(c.distance(mean * height) < 1e-12, "column {c} is not {}", mean * height);
    }
    let splay = columns(Lift::Normal).iter().map(|c| c.angle_between(mean).to_degrees()).fold(0.0, f64::max);
    assert!(splay > 10.0, "per-anchor normals on this patch splay by {splay} degrees");
}

/// A row of anchors across a flat plane (y = 0, normal +y) gives the affine grid it should:
/// content x runs along the row from its first anchor to its last, y across it over `width`
/// (along the bitangent n x t = -z), z up the normal over `height`. On a sphere the row's grid
/// bends, and it moves rigidly with the sphere.
#[test]
fn a_row_of_anchors_drives_a_one_dimensional_grid() {
    use werkstatt::nodes::cuboid::cuboid_grid::anchor_row_frames;
    let plane = werkstatt::nodes::mesh::geometry::plane(2.0, 8, 8).unwrap();
    let (a, b) = (DVec2::new(0.2, 0.5), DVec2::new(0.8, 0.5));
    let frames = anchor_row_frames(&plane, a, b, 4).unwrap();
    for f in &frames {
        assert!(f.normal.distance(DVec3::Y) < 1e-9 && f.tangent.distance(DVec3::X) < 1e-9, "{f:?}");
    }
    let (width, height) = (0.4, 0.3);
    let grid = anchor_row(&frames, width, height, -DVec3::ONE, DVec3::ONE, NormalMethod::TangentSpace).unwrap();
    assert_eq!(grid.cells, [3, 1, 1]);
    let expected = |p: DVec3| DVec3::new(0.6 * p.x, height * (p.z + 1.0) / 2.0, -width / 2.0 * p.y);
    let cube = werkstatt::nodes::mesh::geometry::cube(2.0).unwrap();
    let worst =
        cube.positions.iter().map(|p| grid.eval(p.as_dvec3()).distance(expected(p.as_dvec3()))).fold(0.0, f64::max);
    assert!(worst < 1e-6, "the row's grid is off its analytic map by {worst}");
    assert!(grid.as_affine(LINEAR_TOLERANCE).is_some(), "a row on a plane is affine: the fast path applies");

    let body = werkstatt::nodes::mesh::geometry::sphere(1.0, 24, 16).unwrap();
    let (r, t) = (DQuat::from_scaled_axis(DVec3::new(0.3, -1.1, 0.5)), DVec3::new(0.7, -2.0, 1.3));
    let row_on = |mesh: &Mesh| {
        let anchors: Vec<Anchor> = (0..5)
            .map(|i| {
                Anchor::at_uv_towards(&body, DVec2::new(0.2 + 0.1 * i as f64, 0.45), DVec2::new(0.02, 0.0)).unwrap()
            })
            .collect();
        let frames: Vec<_> = anchors.iter().map(|an| an.frame(mesh).unwrap()).collect();
        anchor_row(&frames, width, height, -DVec3::ONE, DVec3::ONE, NormalMethod::TangentSpace).unwrap()
    };
    let (before, after) = (row_on(&body), row_on(&rotate_mesh(&body, r, t)));
    assert!(before.as_affine(LINEAR_TOLERANCE).is_none(), "the row follows the sphere's curvature");
    let worst = cube
        .positions
        .iter()
        .map(|p| after.eval(p.as_dvec3()).distance(r * before.eval(p.as_dvec3()) + t))
        .fold(0.0, f64::max);
    assert!(worst < 1e-5, "a rigid motion of the body moves the row's object by {worst} more than rigidly");
}

fn graph(text: &str) -> Graph {
    Graph::load_str(text, &common::root().join("graphs/test.ron")).unwrap()
}

/// Evaluates frame 0 of `text`, pulling from `targets`.
fn evaluate(text: &str, targets: &[&str]) -> werkstatt::core::eval::Evaluator {
    let targets: Vec<String> = targets.iter().map(|t| t.to_string()).collect();
    let mut ev = werkstatt::core::eval::Evaluator::new(&graph(text), &targets).unwrap();
    let res = werkstatt::core::resources::Resources::new(false);
    let settings = werkstatt::core::eval::FrameSettings { width: 8, height: 8, base_dir: common::root(), frames: None };
    ev.evaluate(werkstatt::core::eval::FrameTime { frame: 0, fps: 30.0 }, None, &res, &settings);
    ev
}

/// A sphere under a Cuboid node with the given corner-7 offset, through Deform.
fn deformed_scene(offset7: [f64; 3]) -> Arc<Vec<DrawItem>> {
    let text = format!(
        r#"(version: 1, nodes: {{
            "mesh": (kind: "Primitive", pos: (0.0, 0.0), params: {{}}),
            "draw": (kind: "Draw", pos: (0.0, 0.0), params: {{}}),
            "cuboid": (kind: "Cuboid", pos: (0.0, 0.0), params: {{"rotate": [0.0, 30.0, 0.0], "offset7": {offset7:?}}}),
            "deform": (kind: "Deform", pos: (0.0, 0.0), params: {{}}),
        }}, links: [("mesh.mesh", "draw.mesh"), ("draw.scene", "deform.scene"), ("cuboid.transform", "deform.transform")])"#
    );
    let ev = evaluate(&text, &["deform"]);
    let Some(Value::Scene(scene)) = ev.output("deform", "scene").cloned() else { panic!("no scene") };
    scene
}

#[test]
fn the_deform_node_takes_the_fast_path_until_a_corner_moves() {
    let linear = deformed_scene([0.0, 0.0, 0.0]);
    assert!(linear[0].cuboid.is_none());
    assert!(linear[0].model.abs_diff_eq(Mat4::from_rotation_y(30f32.to_radians()), 1e-5));
    let trilinear = deformed_scene([0.0, 0.5, 0.0]);
    let grid = trilinear[0].cuboid.as_ref().expect("a moved corner keeps the grid");
    assert!(
        grid.eval(DVec3::ONE).distance(
            DMat4::from_rotation_y(30f64.to_radians()).transform_point3(DVec3::ONE) + DVec3::new(0.0, 0.5, 0.0)
        ) < 1e-6
    );
}

#[test]
fn bad_cuboid_parameters_are_node_errors() {
    let text = r#"(version: 1, nodes: {
        "grid": (kind: "CuboidGrid", pos: (0.0, 0.0), params: {"source": "anchors"}),
        "box": (kind: "Cuboid", pos: (0.0, 0.0), params: {"box_min": [1.0, 0.0, 0.0], "box_max": [0.0, 1.0, 1.0]}),
    }, links: [])"#;
    let ev = evaluate(text, &["grid", "box"]);
    for (node, needle) in [("grid", "needs a mesh"), ("box", "must exceed box_min")] {
        let status = format!("{:?}", ev.report(node).unwrap().status);
        assert!(status.contains(needle), "{node}: {status}");
    }
}

/// A tessellated plate under a bend grid, under a single bent cuboid (whose coefficients the
/// vertex stage takes as instance data, not from the cell texture), and small inside one cell
/// of the grid (drawn as that cell's single cuboid): drawn by the trilinear vertex stage, and
/// drawn again as a mesh deformed on the CPU, must give the same G-buffer depth and normals
/// (and the same shadow-tile depth).
#[test]
fn the_trilinear_vertex_stage_matches_the_cpu_transform() {
    let gpu = common::gpu();
    let plate = werkstatt::nodes::mesh::geometry::plane(2.0, 24, 24).unwrap();
    let whole = Mat4::from_rotation_x(0.3);
    // Inside cell (1, 1, 0) of the 3x2x1 grid.
    let small = Mat4::from_translation(Vec3::new(0.0, 0.3, 0.0)) * whole * Mat4::from_scale(Vec3::splat(0.25));
    let (lo, hi) = (DVec3::new(-1.0, -0.6, -1.0), DVec3::new(1.0, 0.6, 1.0));
    let camera = common::camera_toward_origin(Vec3::new(0.3, 2.2, 3.0), 45.0, 20.0);
    let (w, h) = (64u32, 64u32);
    let view = View::new(&camera, w, h);
    let methods = [NormalMethod::TangentSpace, NormalMethod::Direct];
    // (cells, model, the least pixels the plate covers)
    let cases = [([3, 2, 1], whole, 800), ([1, 1, 1], whole, 800), ([3, 2, 1], small, 60)];
    for ((cells, model, least), method) in cases.into_iter().flat_map(|c| methods.map(|m| (c, m))) {
        let grid = Arc::new(
            CuboidGrid::from_fn(lo, hi, cells, method, |u| {
                let b = bend(lo, hi, 100.0)(lo + u * (hi - lo));
                b + DVec3::new(0.0, 0.15 * (6.0 * u.z).sin() * u.x, 0.0)
            })
            .unwrap(),
        );
        let mut cpu = plate.clone();
        for ((p, n), p0) in cpu.positions.iter_mut().zip(&mut cpu.normals).zip(&plate.positions) {
            let q = model.as_dmat4().transform_point3(p0.as_dvec3());
            let n0 = model.as_dmat4().inverse().transpose().transform_vector3(n.as_dvec3());
            *p = grid.eval(q).as_vec3();
            *n = grid.normal(q, n0).as_vec3();
        }
        let material = Arc::new(Material::default());
        let item = |mesh: Mesh, model: Mat4, cuboid| DrawItem {
            cuboid,
            ..DrawItem::plain(Arc::new(mesh), material.clone(), model)
        };
        // Drawn after another non-linear grid (of the other normal method) that puts its copy
        // beyond the far plane: both grids share one corner buffer, so the plate's grid must
        // be read from its own first corner with its own header.
        let other = if method == NormalMethod::Direct { NormalMethod::TangentSpace } else { NormalMethod::Direct };
        let beyond_far = Arc::new(
            CuboidGrid::from_fn(lo, hi, [2, 2, 2], other, |u| {
                bend(lo, hi, 40.0)(lo + u * (hi - lo)) - 100.0 * DVec3::Z
            })
            .unwrap(),
        );
        let on_gpu = [item(plate.clone(), model, Some(beyond_far)), item(plate.clone(), model, Some(grid.clone()))];
        let on_cpu = [item(cpu, Mat4::IDENTITY, None)];
        let mut drawer = SceneDrawer::default();
        let a = drawer.gbuffer(gpu, &on_gpu, camera, view).unwrap();
        let b = drawer.gbuffer(gpu, &on_cpu, camera, view).unwrap();
        let tile = [werkstatt::render::draw::Tile { view_proj: view.view_proj, rect: [0, 0, w, h] }];
        let sa = drawer.depth_tiles(gpu, &on_gpu, &tile, w, h).unwrap();
        let sb = drawer.depth_tiles(gpu, &on_cpu, &tile, w, h).unwrap();
        gpu.submit_checked().unwrap();
        let (da, db) = (read_back(gpu, &a.depth).unwrap().rgba, read_back(gpu, &b.depth).unwrap().rgba);
        let (na, nb) = (read_back(gpu, &a.normal).unwrap().rgba, read_back(gpu, &b.normal).unwrap().rgba);
        let (covered, mut mismatched, mut worst_depth, mut worst_normal) =
            (da.chunks(4).filter(|c| c[0] > 0.0).count(), 0, 0.0f32, 0.0f32);
        for px in 0..(w * h) as usize {
            let (za, zb) = (da[4 * px], db[4 * px]);
            if (za > 0.0) != (zb > 0.0) {
                mismatched += 1;
                continue;
            }
            if za > 0.0 {
                worst_depth = worst_depth.max((za - zb).abs() / zb);
                let (ma, mb) = (Vec3::from_slice(&na[4 * px..]), Vec3::from_slice(&nb[4 * px..]));
                worst_normal = worst_normal.max(ma.distance(mb));
            }
        }
        assert!(covered > least, "{cells:?} {method:?}: the plate covers only {covered} pixels");
        assert!(mismatched <= 4, "{cells:?} {method:?}: coverage differs in {mismatched} pixels");
        assert!(worst_depth < 1e-3, "{cells:?} {method:?}: depth differs by {worst_depth} (relative)");
        // Normals are interpolated per vertex in both; Rgba16Float stores them to ~1e-3.
        assert!(worst_normal < 1e-2, "{cells:?} {method:?}: normals differ by {worst_normal}");
        let (ta, tb) = (read_back(gpu, &sa).unwrap().rgba, read_back(gpu, &sb).unwrap().rgba);
        let worst_tile = ta.iter().zip(&tb).map(|(x, y)| (x - y).abs()).fold(0.0f32, f32::max);
        let diff = ta.iter().zip(&tb).filter(|(x, y)| (*x - *y).abs() > 1e-4).count();
        assert!(diff <= 4, "{cells:?} {method:?}: shadow-tile depth differs in {diff} texels (worst {worst_tile})");
    }
}

/// Items that share a mesh and maps draw as one instanced draw per run of equal pipelines, each
/// instance with its own transform, grid (or single cuboid) and colour: the G-buffer and the
/// depth tiles must equal, to the bit, those of the same items drawn one by one (each with its
/// own copy of the mesh).
#[test]
fn items_sharing_a_mesh_draw_instanced_as_if_drawn_one_by_one() {
    let gpu = common::gpu();
    let ball = Arc::new(werkstatt::nodes::mesh::geometry::sphere(0.5, 12, 6).unwrap());
    // A twisted grid over lo..hi (content space: after the item's model matrix).
    let grid = |k: usize, cells, (lo, hi): (DVec3, DVec3), method| {
        let (twist, centre) = (0.4 + 0.3 * k as f64, (lo + hi) / 2.0);
        Arc::new(
            CuboidGrid::from_fn(lo, hi, cells, method, |u| {
                let p = lo + u * (hi - lo) - centre;
                centre + DQuat::from_rotation_y(twist * p.y).mul_vec3(p) + DVec3::new(0.1 * p.y * p.y, 0.0, 0.0)
            })
            .unwrap(),
        )
    };
    let position = |k: usize| Vec3::new(-2.1 + 0.6 * k as f32, 0.2 * (k % 3) as f32, 0.0);
    let around = |k: usize| (position(k).as_dvec3() - 0.6, position(k).as_dvec3() + 0.6);
    // Eight items in a row: plain, plain, three across the cells of grids (tangent space), one
    // beyond its grid, in the extrapolation of one border cell, so drawn as that cell's single
    // cuboid (direct normals), plain, plain. Runs of equal pipelines make four draws.
    let kinds = [None, None, Some(NormalMethod::TangentSpace), Some(NormalMethod::TangentSpace)];
    let kinds = kinds.iter().chain(&[Some(NormalMethod::TangentSpace), Some(NormalMethod::Direct), None, None]);
    // Items 3 and 4 share one grid (and so its cells).
    let shared_grid =
        grid(3, [2, 1, 2], (DVec3::new(-0.9, -0.6, -0.6), DVec3::new(0.9, 0.8, 0.6)), NormalMethod::TangentSpace);
    let shared: Vec<DrawItem> = kinds
        .enumerate()
        .map(|(k, kind)| {
            let material =
                Material { base_color: Vec3::new(0.1 * k as f32, 0.5, 1.0 - 0.1 * k as f32), ..Default::default() };
            let model = Mat4::from_translation(position(k)) * Mat4::from_rotation_z(0.3 * k as f32);
            let cuboid = kind.map(|method| match k {
                3 | 4 => shared_grid.clone(),
                5 => grid(k, [2, 1, 1], (DVec3::new(-3.5, -0.5, -0.5), DVec3::new(-2.5, 0.5, 0.5)), method),
                _ => grid(k, [2, 1, 2], around(k), method),
            });
            DrawItem {
                mesh: ball.clone(),
                material: Arc::new(material),
                cuboid,
                ..DrawItem::plain(ball.clone(), Arc::default(), model)
            }
        })
        .collect();
    let separate: Vec<DrawItem> =
        shared.iter().map(|item| DrawItem { mesh: Arc::new((*item.mesh).clone()), ..item.clone() }).collect();
    let camera = common::camera_toward_origin(Vec3::new(0.0, 0.5, 4.0), 60.0, 20.0);
    let (w, h) = (96u32, 48u32);
    let view = View::new(&camera, w, h);
    let tiles = [
        werkstatt::render::draw::Tile { view_proj: view.view_proj, rect: [0, 0, w / 2, h] },
        werkstatt::render::draw::Tile {
            view_proj: Mat4::from_rotation_y(0.4) * view.view_proj,
            rect: [w / 2, 0, w / 2, h],
        },
    ];
    let mut drawer = SceneDrawer::default();
    let mut draw = |items: &[DrawItem]| {
        let g = drawer.gbuffer(gpu, items, camera, view).unwrap();
        let draws = drawer.draw_count();
        let shadow = drawer.depth_tiles(gpu, items, &tiles, w, h).unwrap();
        assert_eq!(drawer.draw_count(), draws, "both targets draw the same runs");
        gpu.submit_checked().unwrap();
        let images = [&g.color, &g.normal, &g.depth, &shadow].map(|image| read_back(gpu, image).unwrap().rgba);
        (draws, images)
    };
    let (shared_draws, shared_images) = draw(&shared);
    let (separate_draws, separate_images) = draw(&separate);
    assert_eq!(separate_draws, shared.len());
    assert_eq!(shared_draws, 4, "plain x2, tangent-space grids x3, direct single cuboid, plain x2");
    let covered = shared_images[2].iter().step_by(4).filter(|&&z| z > 0.0).count();
    assert!(covered > 400, "the balls cover only {covered} pixels");
    for (name, (a, b)) in
        ["colour", "normal", "depth", "shadow depth"].iter().zip(shared_images.iter().zip(&separate_images))
    {
        let differing = a.iter().zip(b).filter(|(x, y)| x.to_bits() != y.to_bits()).count();
        assert_eq!(differing, 0, "{name}: {differing} values differ between instanced and separate draws");
    }
}

/// Fig. 4.5: a tube along x through a 2x1 bend grid, its seam at x = 0. Across the seam only
/// the Jacobian's x column jumps (the y and z columns are derivatives within the shared face).
/// The direct method, J n, uses only those columns for the tube's normals (n_x = 0), so it is
/// continuous there; the tangent-space method, cof(J) n, involves the x column and shows the
/// seam, but stays orthogonal to the deformed surface, which J n does not. Both by exactly
/// the angles the cells' chords give.
#[test]
fn at_a_cell_seam_direct_normals_are_continuous_and_tangent_space_normals_are_orthogonal() {
    let (lo, hi) = (DVec3::new(-1.0, -0.5, -0.5), DVec3::new(1.0, 0.5, 0.5));
    let grid =
        |method| CuboidGrid::from_fn(lo, hi, [2, 1, 1], method, |u| bend(lo, hi, 120.0)(lo + u * (hi - lo))).unwrap();
    let (direct, tangent) = (grid(NormalMethod::Direct), grid(NormalMethod::TangentSpace));
    let angle = |a: DVec3, b: DVec3| a.normalize().dot(b.normalize()).clamp(-1.0, 1.0).acos().to_degrees();
    let (mut direct_jump, mut tangent_jump, mut tangent_skew, mut direct_skew) = (0.0f64, 0.0f64, 0.0f64, 0.0f64);
    for k in 0..16 {
        let phi = k as f64 * std::f64::consts::TAU / 16.0;
        let n = DVec3::new(0.0, phi.cos(), phi.sin());
        let p = 0.3 * n;
        let (left, right) = (p - 1e-9 * DVec3::X, p + 1e-9 * DVec3::X);
        direct_jump = direct_jump.max(angle(direct.normal(left, n), direct.normal(right, n)));
        tangent_jump = tangent_jump.max(angle(tangent.normal(left, n), tangent.normal(right, n)));
        // The tube's tangents at p: along x and around it.
        for t in [DVec3::X, DVec3::new(0.0, -phi.sin(), phi.cos())] {
            for side in [left, right] {
                let image = direct.jacobian(side) * t;
                tangent_skew = tangent_skew.max((90.0 - angle(tangent.normal(side, n), image)).abs());
                direct_skew = direct_skew.max((90.0 - angle(direct.normal(side, n), image)).abs());
            }
        }
    }
    eprintln!(
        "seam: direct jumps {direct_jump:.2e} deg, tangent space {tangent_jump:.2} deg; off-orthogonal: tangent space {tangent_skew:.2e} deg, direct {direct_skew:.2} deg"
    );
    assert!(direct_jump < 1e-5, "direct normals jump by {direct_jump} degrees at the seam");
    // Each cell's x edges are chords of its 60 degrees of the 120 degree arc: the surface turns
    // by the angle between neighbouring chords at the seam, and J n (the face's direction at
    // the seam) leans half of it from either chord's normal.
    assert!((tangent_jump - 60.0).abs() < 1e-6, "tangent-space normals jump {tangent_jump} degrees, not 60");
    assert!(tangent_skew < 1e-6, "tangent-space normals leave the surface's normal by {tangent_skew} degrees");
    assert!((direct_skew - 30.0).abs() < 1e-6, "direct normals lean {direct_skew} degrees, not 30");
}

/// DeformSurface moves a Surface on the CPU to where Deform's draw-time transform puts the
/// same mesh (two code paths, one map); the tangent-space normals stay orthogonal to the bent
/// surface (face normals of the fine result agree with its vertex normals); UVs and pieces are
/// kept, so the result feeds a matrix texture, whose frames then follow the bend.
#[test]
fn deform_surface_bends_a_surface_that_a_matrix_texture_and_anchors_can_use() {
    let text = r#"(version: 1, nodes: {
        "body": (kind: "Primitive", pos: (0.0, 0.0), params: {"shape": "cylinder", "radius": 0.3, "height": 1.6, "segments_u": 48, "segments_v": 48}),
        "bend": (kind: "CuboidGrid", pos: (0.0, 0.0), params: {"source": "bend", "amount": 40.0, "cells_x": 8, "cells_y": 2,
            "box_min": [-0.8, -0.8, -0.4], "box_max": [0.8, 0.8, 0.4]}),
        "bent": (kind: "DeformSurface", pos: (0.0, 0.0), params: {}),
        "draw": (kind: "Draw", pos: (0.0, 0.0), params: {}),
        "deform": (kind: "Deform", pos: (0.0, 0.0), params: {}),
        "matrix": (kind: "MatrixTexture", pos: (0.0, 0.0), params: {}),
    }, links: [("body.mesh", "bent.surface"), ("bend.transform", "bent.transform"), ("body.mesh", "draw.mesh"),
               ("draw.scene", "deform.scene"), ("bend.transform", "deform.transform"), ("bent.surface", "matrix.surface")])"#;
    let ev = evaluate(text, &["bent", "deform"]);
    let (Some(Value::Surface(bent)), Some(Value::Surface(body)), Some(Value::Scene(scene))) = (
        ev.output("bent", "surface").cloned(),
        ev.output("body", "mesh").cloned(),
        ev.output("deform", "scene").cloned(),
    ) else {
        panic!("no outputs: {:?}", ev.report("bent").map(|r| r.status.clone()))
    };
    let item = &scene[0];
    let grid = item.cuboid.as_deref().expect("an 80 degree bend is not linear");
    let worst = body
        .positions
        .iter()
        .zip(&bent.positions)
        .map(|(p, q)| werkstatt::cuboid::place_point(item.model, Some(grid), *p).distance(q.as_dvec3()))
        .fold(0.0, f64::max);
    assert!(worst < 1e-5, "DeformSurface and Deform disagree by {worst}");
    assert_eq!((&bent.uvs, &bent.indices, &bent.piece_ids), (&body.uvs, &body.indices, &body.piece_ids));
    let mut worst_angle = 0.0f32;
    for t in bent.indices.chunks(3) {
        let [a, b, c] = [0, 1, 2].map(|k| t[k] as usize);
        let face = (bent.positions[b] - bent.positions[a]).cross(bent.positions[c] - bent.positions[a]).normalize();
        let vertex = (bent.normals[a] + bent.normals[b] + bent.normals[c]).normalize();
        worst_angle = worst_angle.max(face.dot(vertex).clamp(-1.0, 1.0).acos().to_degrees());
    }
    eprintln!("DeformSurface: vertex normals within {worst_angle:.2} degrees of the bent faces");
    // Faceting alone: the straight cylinder's are within 1.3 degrees, the bent one's 2.0;
    // untransformed normals would be 14 degrees off.
    assert!(worst_angle < 3.0, "vertex normals leave the bent faces by {worst_angle} degrees");
    let moved = body.positions.iter().zip(&bent.positions).map(|(p, q)| p.distance(*q)).fold(0.0, f32::max);
    assert!(moved > 0.05, "the cylinder is bent (its vertices moved at most {moved})");
    assert!(
        matches!(ev.report("matrix").map(|r| r.status.clone()), Some(werkstatt::core::eval::NodeStatus::NotRun)),
        "the matrix texture only needs a GPU; the link type-checks"
    );
}

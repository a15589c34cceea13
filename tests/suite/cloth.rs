//! Conservation-style checks on patterns, presets and the solver. Every
//! tolerance is stated next to its assertion together with the reason for
//! its size. Resolutions are kept small so the whole suite runs in seconds
//! in release mode.

use glam::{Vec2, Vec3};
use werkstatt::cloth::collider::uv_sphere_mesh;
use werkstatt::cloth::pattern::{circle_outline, rectangle_outline, trapezoid_outline};
use werkstatt::cloth::presets::TABLE_TORUS;
use werkstatt::cloth::*;

fn tablecloth() -> Preset {
    Preset::Tablecloth(TableclothParams { triangles: 2500, seed: 7, ..Default::default() })
}
fn flag() -> Preset {
    Preset::Flag(FlagParams { triangles: 2000, seed: 7, ..Default::default() })
}
fn skirt() -> Preset {
    Preset::Skirt(SkirtParams { triangles: 2500, seed: 7, panels: 4 })
}

fn run(preset: &Preset, frames: u32) -> Cloth {
    let mut c = preset.build();
    for _ in 0..frames {
        c.step_frame(FRAME_DT);
    }
    c
}

fn tri_area(a: Vec2, b: Vec2, c: Vec2) -> f32 {
    0.5 * (b - a).perp_dot(c - a)
}

/// Smallest signed distance of any cloth vertex to any collider surface.
fn min_clearance(c: &Cloth) -> f32 {
    let mut m = f32::INFINITY;
    for &p in c.positions() {
        for col in c.colliders() {
            if let Some(ct) = col.contact(p, 1.0) {
                m = m.min(ct.distance);
            }
        }
    }
    m
}

fn strains(c: &Cloth) -> Vec<f32> {
    let x = c.positions();
    let mut s: Vec<f32> = c
        .edges()
        .iter()
        .zip(c.rest_edge_lengths())
        .map(|(e, &r)| x[e[0] as usize].distance(x[e[1] as usize]) / r - 1.0)
        .collect();
    s.sort_by(|a, b| b.total_cmp(a));
    s
}

// ---------------------------------------------------------------- pattern

#[test]
fn triangulation_covers_polygon_area() {
    let notched: Vec<Vec2> =
        [(0.0, 0.0), (40.0, 0.0), (40.0, 30.0), (25.0, 30.0), (20.0, 12.0), (15.0, 30.0), (0.0, 30.0)]
            .iter()
            .map(|&(x, y)| Vec2::new(x, y))
            .collect();
    let shapes = [
        ("rectangle", rectangle_outline(120.0, 80.0)),
        ("trapezoid", trapezoid_outline(45.0, 20.0, 60.0)),
        ("circle", circle_outline(Vec2::new(30.0, 30.0), 30.0, 48)),
        ("notched", notched),
    ];
    for (name, outline) in shapes {
        let piece = Piece::new(name, outline);
        let area = piece.area();
        let mesh = PatternMesh::build(vec![piece], vec![], 3.0).unwrap();
        let r = mesh.rest_positions();
        let mut sum = 0.0;
        let mut min_angle = 180.0f32;
        for t in mesh.triangles() {
            let [a, b, c] = t.map(|i| r[i as usize]);
            let ta = tri_area(a, b, c);
            assert!(ta > 0.0, "{name}: every triangle is CCW with positive area");
            sum += ta;
            for (p, q, s) in [(a, b, c), (b, c, a), (c, a, b)] {
                min_angle = min_angle.min((q - p).angle_to(s - p).abs().to_degrees());
            }
        }
        // Constrained triangulation of the exact outline: only float
        // rounding separates the sums; 2% is the contract, 1e-4 the reality.
        assert!((sum - area).abs() / area < 1e-4, "{name}: area {sum} vs {area}");
        // Lattice + Delaunay keeps triangles well shaped (worst seen ~25°);
        // 15° leaves margin for other outlines.
        assert!(min_angle > 15.0, "{name}: min angle {min_angle}");
        // Roughly uniform: edge count near area / equilateral area.
        let expected = area / (0.433 * 9.0);
        let n = mesh.triangles().len() as f32;
        assert!((n / expected - 1.0).abs() < 0.25, "{name}: {n} triangles, expected about {expected}");
    }
}

#[test]
fn edge_chains_follow_outline_edges() {
    let piece = Piece::new("trap", trapezoid_outline(45.0, 20.0, 60.0));
    let outline = piece.outline.clone();
    let mesh = PatternMesh::build(vec![piece], vec![], 4.0).unwrap();
    let r = mesh.rest_positions();
    for (i, chain) in mesh.piece_meshes()[0].edge_chains.iter().enumerate() {
        let (a, b) = (outline[i], outline[(i + 1) % 4]);
        assert_eq!(r[chain[0] as usize], a);
        assert_eq!(r[*chain.last().unwrap() as usize], b);
        for w in chain.windows(2) {
            let (p, q) = (r[w[0] as usize], r[w[1] as usize]);
            // On the edge line (to float precision) and advancing along it.
            assert!((q - a).perp_dot(b - a).abs() / (b - a).length() < 1e-3);
            assert!((q - p).dot(b - a) > 0.0);
        }
    }
}

#[test]
fn uv_atlas_is_disjoint_in_unit_square_and_keeps_aspect() {
    let pieces = vec![
        Piece::new("big", rectangle_outline(150.0, 100.0)),
        Piece::new("tall", rectangle_outline(30.0, 120.0)),
        Piece::new("trap", trapezoid_outline(45.0, 20.0, 60.0)),
        Piece::new("disc", circle_outline(Vec2::ZERO, 25.0, 32)),
        Piece::new("small", rectangle_outline(10.0, 10.0)),
    ];
    let mesh = PatternMesh::build(pieces, vec![], 5.0).unwrap();
    let uv = mesh.uvs();
    let r = mesh.rest_positions();
    let s = mesh.uv_per_cm();
    assert!(uv.iter().all(|u| u.x >= 0.0 && u.y >= 0.0 && u.x <= 1.0 && u.y <= 1.0));
    let pms = mesh.piece_meshes();
    for (i, a) in pms.iter().enumerate() {
        // Same scale for every piece: UV distances are pattern distances
        // times one factor (relative error at f32 precision), with v mirrored
        // (pattern y up, texture v down) so the frame is right-handed.
        let v0 = a.vertices.start as usize;
        for v in a.vertices.clone() {
            let (du, dr) = (uv[v as usize] - uv[v0], r[v as usize] - r[v0]);
            assert!((du - Vec2::new(dr.x, -dr.y) * s).length() < 1e-5, "piece {i} is not a uniform scale");
        }
        for b in &pms[i + 1..] {
            let apart = a.uv_max.x < b.uv_min.x
                || b.uv_max.x < a.uv_min.x
                || a.uv_max.y < b.uv_min.y
                || b.uv_max.y < a.uv_min.y;
            assert!(apart, "atlas rectangles overlap");
        }
    }
    // No triangle of one piece overlaps any triangle of another: their UV
    // boxes are disjoint, which the per-piece rectangle test implies, but
    // check the actual vertex extents against the recorded rectangles too.
    for pm in pms {
        for v in pm.vertices.clone() {
            let u = uv[v as usize];
            assert!(u.cmpge(pm.uv_min - 1e-6).all() && u.cmple(pm.uv_max + 1e-6).all());
        }
    }
    // The packing uses the atlas reasonably: at least a quarter of it.
    let used: f32 = pms.iter().map(|p| (p.uv_max - p.uv_min).element_product()).sum();
    assert!(used > 0.25, "atlas fill {used}");
}

#[test]
fn seams_pair_equal_vertex_counts_and_reject_bad_input() {
    // Edges of different lengths still pair one-to-one.
    let pieces = vec![Piece::new("a", rectangle_outline(30.0, 50.0)), Piece::new("b", rectangle_outline(30.0, 35.0))];
    let seam = Seam { a: EdgeRef { piece: 0, edge: 1 }, b: EdgeRef { piece: 1, edge: 3 }, reversed: true };
    let mesh = PatternMesh::build(pieces.clone(), vec![seam], 4.0).unwrap();
    let ca = &mesh.piece_meshes()[0].edge_chains[1];
    let cb = &mesh.piece_meshes()[1].edge_chains[3];
    assert_eq!(ca.len(), cb.len());
    assert_eq!(mesh.seam_pairs().len(), ca.len());
    let ids = mesh.piece_ids();
    assert!(mesh.seam_pairs().iter().all(|p| ids[p[0] as usize] == 0 && ids[p[1] as usize] == 1));

    let cw = Piece::new("cw", rectangle_outline(10.0, 10.0).into_iter().rev().collect());
    assert_eq!(PatternMesh::build(vec![cw], vec![], 2.0).unwrap_err(), PatternError::NotCounterClockwise(0));
    let bow = Piece::new("bow", [(0.0, 0.0), (4.0, 0.0), (0.0, 3.0), (1.0, 4.0)].map(Vec2::from).to_vec());
    assert_eq!(PatternMesh::build(vec![bow], vec![], 0.5).unwrap_err(), PatternError::NotSimple(0));
    let bad = Seam { a: EdgeRef { piece: 0, edge: 9 }, ..seam };
    assert_eq!(PatternMesh::build(pieces, vec![bad], 4.0).unwrap_err(), PatternError::BadSeam(0));
}

// ---------------------------------------------------------------- solver

#[test]
fn runs_are_bit_identical() {
    for preset in [tablecloth(), flag(), skirt()] {
        let a = run(&preset, 45);
        let b = run(&preset, 45);
        let bits = |c: &Cloth| c.positions().iter().flat_map(|p| p.to_array()).map(f32::to_bits).collect::<Vec<_>>();
        assert_eq!(bits(&a), bits(&b), "{preset:?}");
        // The convenience entry point re-simulates and matches too.
        assert_eq!(simulate_to_frame(&preset, 45), a.surface());
    }
}

#[test]
fn pinned_vertices_stay_exactly_put() {
    let preset = flag();
    let start = preset.build();
    let pins = start.pinned_vertices().to_vec();
    assert!(pins.len() > 10, "the flag's hoist edge is pinned");
    let end = run(&preset, 120);
    for &i in &pins {
        // Bitwise: pins have zero inverse mass and are skipped everywhere.
        assert_eq!(
            start.positions()[i as usize].to_array().map(f32::to_bits),
            end.positions()[i as usize].to_array().map(f32::to_bits)
        );
    }
}

#[test]
fn tablecloth_drapes_over_torus() {
    let c = run(&tablecloth(), 240);
    let th = c.params().thickness;
    // Collisions are projected last in every substep, so only colliders
    // fighting each other could leave a vertex short of the full thickness;
    // half of it is the stated tolerance.
    assert!(min_clearance(&c) >= 0.5 * th, "clearance {}", min_clearance(&c));
    // Draped: the four corners hang well below the top of the tube (12 cm).
    let Collider::Torus { minor_radius, .. } = TABLE_TORUS else { unreachable!() };
    let corners = &c.pattern().piece_meshes()[0].edge_chains;
    for chain in corners {
        let y = c.positions()[chain[0] as usize].y;
        assert!(y < minor_radius - 0.15, "corner at {y}");
    }
    // Resting on the torus, not fallen through: the cloth's top is near the
    // tube top.
    let top = c.positions().iter().map(|p| p.y).fold(f32::MIN, f32::max);
    assert!((top - (minor_radius + th)).abs() < 0.02, "top {top}");
    // Stretch bound: XPBD with 20 substeps leaves some residual stretch
    // where the hanging cloth pulls over the tube; at this resolution the
    // worst edge is 1.7% (measured), bound 10%. It grows with resolution
    // (see NOTES.md).
    let s = strains(&c);
    assert!(s[0] < 0.10, "max strain {}", s[0]);
    // Settled: nothing moves faster than 0.2 m/s after four seconds
    // (measured 0.08 m/s).
    let vmax = c.velocities().iter().map(|v| v.length()).fold(0.0, f32::max);
    assert!(vmax < 0.2, "still moving at {vmax} m/s");
}

#[test]
fn flag_flutters_downwind_within_stretch_bounds() {
    let mut c = run(&flag(), 90);
    let free: Vec<u32> = c.pattern().piece_meshes()[0].edge_chains[1].clone();
    let mut max_strain = 0.0f32;
    let mut moved = Vec::new();
    for _ in 0..60 {
        let before = c.positions().to_vec();
        c.step_frame(FRAME_DT);
        let d = c.positions().iter().zip(&before).map(|(a, b)| a.distance(*b)).fold(0.0, f32::max);
        moved.push(d);
        max_strain = max_strain.max(strains(&c)[0]);
    }
    // Flutter: every frame something moves by more than 5 mm (the gusts
    // never stop), and the motion is not a steady translation: it varies.
    assert!(moved.iter().all(|&d| d > 0.005), "frame displacements {moved:?}");
    let (lo, hi) = moved.iter().fold((f32::MAX, 0.0f32), |(l, h), &d| (l.min(d), h.max(d)));
    assert!(hi > 1.5 * lo);
    // Downwind: the free edge streams out along +x.
    let mean_x = free.iter().map(|&i| c.positions()[i as usize].x).sum::<f32>() / free.len() as f32;
    assert!(mean_x > 0.9, "free edge at x = {mean_x}");
    // Snapping folds at the free edge briefly overstretch single edges; the
    // bound is 20% for the worst edge in any frame (measured 9%) ...
    assert!(max_strain < 0.20, "max strain {max_strain}");
    // ... while 99% of the edges stay within 5% (measured 1.2%).
    let s = strains(&c);
    assert!(s[s.len() / 100] < 0.05, "p99 strain {}", s[s.len() / 100]);
    assert!(min_clearance(&c) >= 0.5 * c.params().thickness);
}

#[test]
fn skirt_seams_close_and_skirt_rests_on_hips() {
    let start = skirt().build();
    let x0 = start.positions();
    let initial_gap =
        start.seam_pairs().iter().map(|p| x0[p[0] as usize].distance(x0[p[1] as usize])).fold(0.0, f32::max);
    assert!(initial_gap > 0.02, "seams start open ({initial_gap} m)");
    assert!(start.pattern().pieces().len() == 4 && start.seam_pairs().len() > 40);

    let c = run(&skirt(), 240);
    let x = c.positions();
    let th = c.params().thickness;
    // Zero-length seam constraints are solved before collisions, which may
    // push the two sides apart by up to the thickness; 2 mm is the bound
    // (measured 0.6 mm).
    let gap = c.seam_pairs().iter().map(|p| x[p[0] as usize].distance(x[p[1] as usize])).fold(0.0, f32::max);
    assert!(gap < 0.002, "seam gap {gap}");
    assert!(min_clearance(&c) >= 0.5 * th, "clearance {}", min_clearance(&c));
    // Resting on the hips: the waist is near where the body's girth matches
    // it (y ≈ 1.02), not slid down to the legs or still in the air.
    let top = x.iter().map(|p| p.y).fold(f32::MIN, f32::max);
    assert!((0.98..1.05).contains(&top), "waist at {top}");
    let vmax = c.velocities().iter().map(|v| v.length()).fold(0.0, f32::max);
    assert!(vmax < 0.3, "still moving at {vmax} m/s");
    // Stretch bound at this resolution (measured 2.4%; the worst edges sit
    // at the waist where the seams meet the hips), bound 10%.
    let s = strains(&c);
    assert!(s[0] < 0.10, "max strain {}", s[0]);
    // The waist loop holds its length (1% slack for the contact offset).
    let (nodes, rest) = c.length_loops().next().unwrap();
    let centre = |n: &Vec<u32>| n.iter().map(|&v| x[v as usize]).sum::<Vec3>() / n.len() as f32;
    let m = nodes.len();
    let len: f32 = (0..m).map(|k| centre(&nodes[k]).distance(centre(&nodes[(k + 1) % m]))).sum();
    assert!(len < rest * 1.03, "waist {len} m for a {rest} m waistband");
}

#[test]
fn surface_frame_is_consistent() {
    let c = run(&skirt(), 20);
    let f = c.surface();
    let n = c.vertex_count();
    assert_eq!(f.positions.len(), n);
    assert_eq!(f.normals.len(), n);
    assert_eq!(f.uvs.len(), n);
    assert_eq!(f.piece_ids.len(), n);
    assert_eq!(f.indices.len(), 3 * c.triangle_count());
    assert!(f.indices.iter().all(|&i| (i as usize) < n));
    for nrm in &f.normals {
        assert!((Vec3::from(*nrm).length() - 1.0).abs() < 1e-4);
    }
    // Normals are built from the winding, so each face agrees with the
    // average of its vertex normals except across sharp folds.
    let mut agree = 0;
    for t in f.indices.chunks(3) {
        let p = t.iter().map(|&i| Vec3::from(f.positions[i as usize])).collect::<Vec<_>>();
        let face = (p[1] - p[0]).cross(p[2] - p[0]);
        let avg: Vec3 = t.iter().map(|&i| Vec3::from(f.normals[i as usize])).sum();
        if face.dot(avg) > 0.0 {
            agree += 1;
        }
    }
    assert!(agree as f32 > 0.99 * c.triangle_count() as f32);
    // The pattern's CCW front faces away from the body: normals point away
    // from the vertical axis nearly everywhere (folds may turn a few).
    let outward = (0..n)
        .filter(|&i| {
            let radial = Vec3::new(f.positions[i][0], 0.0, f.positions[i][2]).normalize();
            Vec3::from(f.normals[i]).dot(radial) > 0.5
        })
        .count();
    assert!(outward as f32 > 0.95 * n as f32, "{outward} of {n} normals face outwards");
}

/// A square of cloth pinned at one corner hangs along its diagonal, which
/// shears the warp/weft grid. With soft stretch, the shear constraints are
/// what keeps warp and weft perpendicular.
#[test]
fn shear_constraints_resist_shearing() {
    let shear_of = |shear_compliance: f32| {
        let mesh = PatternMesh::build(vec![Piece::new("sq", rectangle_outline(40.0, 40.0))], vec![], 3.0).unwrap();
        let pos = mesh.rest_positions().iter().map(|p| Vec3::new(p.x, p.y, 0.0) * CM).collect();
        let corner = mesh.piece_meshes()[0].edge_chains[3][0];
        let params = SimParams { stretch_compliance: 0.05, shear_compliance, tethers: false, ..SimParams::default() };
        let mut c = Cloth::new(mesh, pos, params);
        c.pin(&[corner]);
        for _ in 0..150 {
            c.step_frame(FRAME_DT);
        }
        let (r, x) = (c.pattern().rest_positions(), c.positions());
        let mut total = 0.0;
        for t in c.pattern().triangles() {
            let [a, b, d] = t.map(|i| i as usize);
            let dm = glam::Mat2::from_cols(r[b] - r[a], r[d] - r[a]).inverse();
            let (e1, e2) = (x[b] - x[a], x[d] - x[a]);
            let fu = e1 * dm.col(0).x + e2 * dm.col(0).y;
            let fv = e1 * dm.col(1).x + e2 * dm.col(1).y;
            total += (fu.normalize().dot(fv.normalize())).abs();
        }
        total / c.triangle_count() as f32
    };
    let stiff = shear_of(1e-7);
    let soft = shear_of(1.0);
    // Mean |cos| of the warp/weft angle (0 = perpendicular). Measured:
    // soft 0.029 (about 1.6° average shear), stiff 0.002.
    assert!(soft > 0.015, "soft shear {soft}");
    assert!(stiff < 0.25 * soft, "stiff {stiff} vs soft {soft}");
}

/// A horizontal strip clamped at one end: stiffer bending holds the free
/// end up.
#[test]
fn bending_constraints_hold_a_cantilever() {
    let tip_height = |bend_compliance: f32| {
        let mesh = PatternMesh::build(vec![Piece::new("strip", rectangle_outline(15.0, 5.0))], vec![], 1.0).unwrap();
        let pos = mesh.rest_positions().iter().map(|p| Vec3::new(p.x, 0.0, -p.y) * CM).collect();
        // Clamp the first 2 cm so the root cannot hinge.
        let clamp: Vec<u32> =
            (0..mesh.vertex_count() as u32).filter(|&i| mesh.rest_positions()[i as usize].x < 2.0).collect();
        let tip: Vec<u32> = mesh.piece_meshes()[0].edge_chains[1].clone();
        let params = SimParams { bend_compliance, damping: 2.0, ..SimParams::default() };
        let mut c = Cloth::new(mesh, pos, params);
        c.pin(&clamp);
        for _ in 0..180 {
            c.step_frame(FRAME_DT);
        }
        tip.iter().map(|&i| c.positions()[i as usize].y).sum::<f32>() / tip.len() as f32
    };
    let stiff = tip_height(1.0);
    let soft = tip_height(1e6);
    // Floppy: the 13 cm overhang hangs nearly straight down (~ -0.13 m).
    assert!(soft < -0.11, "soft tip {soft}");
    // Stiff: much higher. Gauss-Seidel with 20 substeps caps the effective
    // stiffness (measured tip -0.086 m for any compliance below ~10; 100
    // substeps would give -0.005 m), so the bound is a 3 cm difference.
    assert!(stiff > soft + 0.03, "stiff tip {stiff} vs soft tip {soft}");
}

#[test]
fn cloth_rests_on_mesh_collider() {
    let (pos, tris) = uv_sphere_mesh(Vec3::ZERO, 0.3, 16, 32);
    let mesh_collider = TriMeshCollider::new(pos, tris, 0.03);
    let mesh = PatternMesh::build(vec![Piece::new("sq", rectangle_outline(60.0, 60.0))], vec![], 3.0).unwrap();
    let start: Vec<Vec3> =
        mesh.rest_positions().iter().map(|p| Vec3::new(p.x - 30.0, 0.0, 30.0 - p.y) * CM + Vec3::Y * 0.35).collect();
    let params = SimParams { friction: 0.6, ..SimParams::default() };
    let mut c = Cloth::new(mesh, start, params);
    c.add_collider(Collider::Mesh(mesh_collider));
    for _ in 0..150 {
        c.step_frame(FRAME_DT);
    }
    let th = c.params().thickness;
    assert!(min_clearance(&c) >= 0.5 * th, "clearance {}", min_clearance(&c));
    // Against the true sphere the only extra error is the tessellation:
    // chord sag r(1 - cos(pi/16)) ≈ 5.8 mm inside the analytic surface.
    let sphere = Collider::Sphere { center: Vec3::ZERO, radius: 0.3 };
    let worst = c.positions().iter().map(|&p| sphere.contact(p, 1.0).unwrap().distance).fold(f32::MAX, f32::min);
    assert!(worst > 0.5 * th - 0.006, "vertex {worst} m from the sphere");
    // Draped, not fallen through: the top rests on the sphere.
    let top = c.positions().iter().map(|p| p.y).fold(f32::MIN, f32::max);
    assert!((0.29..0.32).contains(&top), "top at {top}");
}

#[test]
fn wind_is_deterministic_and_gusty() {
    let w = Wind::new(Vec3::new(5.0, 0.0, 0.0), 3);
    let p = Vec3::new(0.5, 1.5, 0.2);
    assert_eq!(w.velocity_at(p, 1.25), Wind::new(Vec3::new(5.0, 0.0, 0.0), 3).velocity_at(p, 1.25));
    let speeds: Vec<f32> = (0..200).map(|k| w.velocity_at(p, k as f32 * 0.05).length()).collect();
    let (lo, hi) = speeds.iter().fold((f32::MAX, 0.0f32), |(l, h), &s| (l.min(s), h.max(s)));
    // Gust strength 0.4 around 5 m/s: speeds swing by well over 2 m/s.
    assert!(hi - lo > 2.0 && lo > 0.0, "speeds {lo}..{hi}");
    assert_ne!(w.velocity_at(p, 0.0), Wind::new(Vec3::new(5.0, 0.0, 0.0), 4).velocity_at(p, 0.0));
}

#[test]
fn cloth_rests_on_box_sphere_and_capsule() {
    let mesh = PatternMesh::build(vec![Piece::new("sq", rectangle_outline(80.0, 80.0))], vec![], 4.0).unwrap();
    let start: Vec<Vec3> =
        mesh.rest_positions().iter().map(|p| Vec3::new(p.x - 40.0, 0.0, 40.0 - p.y) * CM + Vec3::Y * 0.45).collect();
    let mut c = Cloth::new(mesh, start, SimParams::default());
    // A tilted box with a ball and a bar on top: edges, corners and curved
    // surfaces all touch the cloth.
    c.add_collider(Collider::Box {
        center: Vec3::ZERO,
        half_extents: Vec3::new(0.25, 0.2, 0.2),
        rotation: glam::Quat::from_rotation_y(0.4) * glam::Quat::from_rotation_z(0.15),
    });
    c.add_collider(Collider::Sphere { center: Vec3::new(0.1, 0.3, 0.05), radius: 0.1 });
    c.add_collider(Collider::Capsule { a: Vec3::new(-0.3, 0.25, -0.1), b: Vec3::new(0.0, 0.25, -0.15), radius: 0.04 });
    for _ in 0..150 {
        c.step_frame(FRAME_DT);
    }
    let th = c.params().thickness;
    assert!(min_clearance(&c) >= 0.5 * th, "clearance {}", min_clearance(&c));
    // Held up by the sphere (top at 0.40 m), not fallen past the box.
    let top = c.positions().iter().map(|p| p.y).fold(f32::MIN, f32::max);
    assert!((0.39..0.42).contains(&top), "top at {top}");
    assert!(c.positions().iter().all(|p| p.is_finite()));
}

/// The ClothSim node in an evaluator (its surface as an extra root), at `triangles`.
fn cloth_node(seed: i64) -> werkstatt::core::eval::Evaluator {
    let text = format!(
        r#"(version: 1, nodes: {{"cloth": (kind: "ClothSim", params: {{"preset": "flag", "triangles": 300, "warmup": 0.0, "seed": {seed}}})}}, links: [])"#
    );
    let g = werkstatt::core::graph::Graph::load_str(&text, "test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}"));
    werkstatt::core::eval::Evaluator::new(&g, &["cloth".to_string()]).unwrap()
}

/// The node's surface positions at `frame` (30 fps).
fn positions_at(ev: &mut werkstatt::core::eval::Evaluator, frame: i64) -> Vec<Vec3> {
    let res = werkstatt::core::resources::Resources::new(false);
    let time = werkstatt::core::eval::FrameTime { frame, fps: 30.0 };
    ev.evaluate(time, None, &res, &werkstatt::core::eval::FrameSettings::default());
    match ev.output("cloth", "surface") {
        Some(werkstatt::core::port::Value::Surface(m)) => m.positions.clone(),
        _ => panic!("no surface at frame {frame}: {:?}", ev.report("cloth").map(|r| r.status.clone())),
    }
}

#[test]
fn scrubbing_backwards_equals_a_fresh_run() {
    let mut scrubbed = cloth_node(1);
    for f in [0, 4, 12] {
        positions_at(&mut scrubbed, f);
    }
    let back = positions_at(&mut scrubbed, 6);
    let fresh = positions_at(&mut cloth_node(1), 6);
    assert!(back == fresh, "frame 6 after frame 12 differs from a fresh run to frame 6");
    assert!(back != positions_at(&mut cloth_node(1), 12), "the flag moves between frames 6 and 12");
    // Forward again from the replayed state: still the fresh run's frames.
    assert!(positions_at(&mut scrubbed, 9) == positions_at(&mut cloth_node(1), 9));
}

#[test]
fn a_new_seed_rebuilds_the_simulation() {
    let mut ev = cloth_node(1);
    let seed_1 = positions_at(&mut ev, 10);
    let mut g = werkstatt::core::graph::Graph::load_str(
        r#"(version: 1, nodes: {"cloth": (kind: "ClothSim", params: {"preset": "flag", "triangles": 300, "warmup": 0.0, "seed": 2})}, links: [])"#,
        "test.ron".as_ref(),
    )
    .unwrap();
    ev.update(&g, &["cloth".to_string()]).unwrap();
    let seed_2 = positions_at(&mut ev, 10);
    assert!(seed_2 != seed_1, "the seed changes the gusts");
    assert!(seed_2 == positions_at(&mut cloth_node(2), 10), "a changed seed must replay from the start");
    // Another preset under the same node: rebuilt too (another vertex count).
    g.set_from_cli("cloth.preset=tablecloth").unwrap();
    ev.update(&g, &["cloth".to_string()]).unwrap();
    let table = positions_at(&mut ev, 10);
    assert_ne!(table.len(), 0);
    assert!(table != seed_2);
}

/// A flat pattern given to [`Cloth::new_shaped`] as its placed 3D shape (turned and moved, UVs
/// the atlas's) is the same cloth as the pattern: the same rest lengths and, pinned at a corner
/// under gravity, the same motion up to rounding. Fails if a shaped triangle's grain is not
/// along its u, or lengths are measured off the surface.
#[test]
fn a_flat_pattern_given_as_a_shape_is_the_same_cloth() {
    let mesh = PatternMesh::build(vec![Piece::new("r", rectangle_outline(40.0, 30.0))], vec![], 3.0).unwrap();
    let turn = glam::Quat::from_axis_angle(Vec3::new(1.0, 2.0, 3.0).normalize(), 0.7);
    let placed: Vec<Vec3> = mesh
        .rest_positions()
        .iter()
        .map(|p| turn * Vec3::new(p.x, p.y, 0.0) * CM + Vec3::new(0.1, 1.0, -0.2))
        .collect();
    let shaped_mesh =
        PatternMesh::shaped(mesh.triangles().to_vec(), mesh.uvs().to_vec(), mesh.piece_ids().to_vec(), 3.0);
    let corner = mesh.piece_meshes()[0].edge_chains[3][0];
    let params = SimParams { stretch_compliance: 1e-3, shear_compliance: 1e-2, ..SimParams::default() };
    let mut flat = Cloth::new(mesh, placed.clone(), params.clone());
    let corners: Vec<[Vec2; 3]> =
        shaped_mesh.triangles().iter().map(|t| t.map(|i| shaped_mesh.uvs()[i as usize])).collect();
    let mut shaped = Cloth::new_shaped(shaped_mesh, placed, &corners, params);
    let worst_rest =
        flat.rest_edge_lengths().iter().zip(shaped.rest_edge_lengths()).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
    assert!(worst_rest < 1e-6, "rest lengths differ by {worst_rest} m");
    flat.pin(&[corner]);
    shaped.pin(&[corner]);
    for _ in 0..60 {
        flat.step_frame(FRAME_DT);
        shaped.step_frame(FRAME_DT);
    }
    let apart = flat.positions().iter().zip(shaped.positions()).map(|(a, b)| a.distance(*b)).fold(0.0, f32::max);
    let fallen = flat.positions().iter().map(|p| 1.0 - p.y).fold(0.0, f32::max);
    assert!(fallen > 0.1, "the cloth did not swing down ({fallen} m)");
    assert!(apart < 1e-3, "the shaped cloth moved {apart} m away from the flat one");
}

/// A shaped cloth at rest, no gravity, stays as it is: its curved shape is its rest (the
/// bending constraint keeps the rest curvature; with a flat rest it would unroll).
#[test]
fn a_shaped_cylinder_stays_at_rest() {
    let mesh = PatternMesh::build(vec![Piece::new("r", rectangle_outline(40.0, 30.0))], vec![], 3.0).unwrap();
    // Wrapped half way round a 10 cm cylinder, pattern x around it.
    let radius = 0.1;
    let wrapped: Vec<Vec3> = mesh
        .rest_positions()
        .iter()
        .map(|p| {
            let a = p.x * CM / radius;
            Vec3::new(radius * a.sin(), p.y * CM, radius * a.cos())
        })
        .collect();
    let shaped_mesh =
        PatternMesh::shaped(mesh.triangles().to_vec(), mesh.uvs().to_vec(), mesh.piece_ids().to_vec(), 3.0);
    let params = SimParams { gravity: Vec3::ZERO, bend_compliance: 1e-2, ..SimParams::default() };
    let corners: Vec<[Vec2; 3]> =
        shaped_mesh.triangles().iter().map(|t| t.map(|i| shaped_mesh.uvs()[i as usize])).collect();
    let mut cloth = Cloth::new_shaped(shaped_mesh, wrapped.clone(), &corners, params);
    for _ in 0..60 {
        cloth.step_frame(FRAME_DT);
    }
    let moved = cloth.positions().iter().zip(&wrapped).map(|(a, b)| a.distance(*b)).fold(0.0, f32::max);
    assert!(moved < 1e-3, "the cylinder moved {moved} m from its rest shape");
}

//! Body-mesh and self collision of the cloth simulator (issue 28): numbers,
//! not pictures. Every scene counts cloth edges crossing the body and the
//! cloth itself with the same measures the node reports.

use glam::{Quat, Vec3};
use werkstatt::cloth::body_collision::{box_mesh, capsule_mesh};
use werkstatt::cloth::collider::uv_sphere_mesh;
use werkstatt::cloth::pattern::rectangle_outline;
use werkstatt::cloth::*;

/// A `w` x `h` cm sheet with edges of about `edge` cm.
fn sheet(w: f32, h: f32, edge: f32) -> PatternMesh {
    PatternMesh::build(vec![Piece::new("sheet", rectangle_outline(w, h))], vec![], edge).unwrap()
}

/// A horizontal sheet centred over the origin at height `y` (front up).
fn horizontal(mesh: &PatternMesh, w: f32, h: f32, y: f32) -> Vec<Vec3> {
    mesh.rest_positions().iter().map(|p| Vec3::new(p.x - 0.5 * w, 0.0, 0.5 * h - p.y) * CM + Vec3::Y * y).collect()
}

fn assert_finite(c: &Cloth) {
    assert!(c.positions().iter().chain(c.velocities()).all(|p| p.is_finite()), "NaN or infinite state");
}

/// Drops a 60 cm sheet onto `body` (static) and checks every 10 frames that
/// no cloth edge crosses the body or the cloth, and at the end that every
/// vertex near the body keeps 90 % of the thickness.
fn drop_onto(body: (Vec<Vec3>, Vec<[u32; 3]>), frames: u32) -> Cloth {
    let mesh = sheet(60.0, 60.0, 2.0);
    let start = horizontal(&mesh, 60.0, 60.0, 0.27);
    let params = SimParams { self_collision: true, ..SimParams::default() };
    let mut c = Cloth::new(mesh, start, params);
    c.set_body(Some(BodyMesh::new(body.0, body.1)));
    for f in 1..=frames {
        c.step_frame(FRAME_DT);
        if f % 10 == 0 {
            assert_eq!(c.body_crossings(), 0, "cloth edges crossing the body at frame {f}");
        }
    }
    assert_finite(&c);
    let th = c.params().body_thickness;
    let clearance = c.body_clearance(0.05).expect("the cloth rests on the body");
    // The last operation of every substep pushes each vertex to the full
    // thickness; 10 % covers a vertex pushed off one face towards another
    // (a box edge) in the same substep.
    assert!(clearance >= 0.9 * th, "clearance {clearance} m, thickness {th} m");
    assert_eq!(c.self_crossings(), 0, "cloth crossing itself");
    c
}

#[test]
fn cloth_dropped_on_a_sphere_body_stays_outside() {
    let c = drop_onto(uv_sphere_mesh(Vec3::ZERO, 0.2, 24, 48), 90);
    // Draped: resting on the sphere's top (0.2 m + thickness), hanging down.
    let top = c.positions().iter().map(|p| p.y).fold(f32::MIN, f32::max);
    assert!((0.2..0.215).contains(&top), "top at {top}");
    let bottom = c.positions().iter().map(|p| p.y).fold(f32::MAX, f32::min);
    assert!(bottom < 0.05, "bottom at {bottom}: did not drape");
}

#[test]
fn cloth_dropped_on_a_box_body_stays_outside() {
    let c = drop_onto(box_mesh(Vec3::ZERO, Vec3::new(0.15, 0.2, 0.12), Quat::from_rotation_y(0.5), 24), 90);
    let top = c.positions().iter().map(|p| p.y).fold(f32::MIN, f32::max);
    assert!((0.2..0.215).contains(&top), "top at {top}");
}

/// A 60 cm curtain (1.5 cm edges) pinned along its top edge, with a limb (capsule, 5 cm radius,
/// 90 cm long) swinging through it about a vertical axis; the tip peaks at
/// about 9 m/s.
struct LimbScene {
    cloth: Cloth,
    rest: Vec<Vec3>,
    pivot: Vec3,
}

const SWING_AMPLITUDE: f32 = 1.1;
const SWING_HZ: f32 = 1.5;

impl LimbScene {
    fn new(self_collision: bool) -> LimbScene {
        let mesh = sheet(60.0, 60.0, 1.5);
        let start: Vec<Vec3> =
            mesh.rest_positions().iter().map(|p| Vec3::new(p.x - 30.0, p.y, 0.0) * CM + Vec3::Y * 0.2).collect();
        let top = mesh.piece_meshes()[0].edge_chains[2].clone();
        // No tethers: they pull the pinned curtain back through the limb; a
        // garment on a body has no pins anyway.
        let params = SimParams { self_collision, tethers: false, ..SimParams::default() };
        let mut cloth = Cloth::new(mesh, start, params);
        cloth.pin(&top);
        let pivot = Vec3::new(-0.6, 0.45, -0.3);
        let (rest, tris) = capsule_mesh(pivot, pivot + Vec3::X * 0.9, 0.05, 45, 24);
        cloth.set_body(Some(BodyMesh::new(rest.clone(), tris)));
        LimbScene { cloth, rest, pivot }
    }

    /// Limb angle (radians about -y, towards +z) at time `t`.
    fn angle(t: f32) -> f32 {
        SWING_AMPLITUDE * (1.0 - (std::f32::consts::TAU * SWING_HZ * t).cos())
    }

    fn step(&mut self) {
        let t = (self.cloth.frame() + 1) as f32 * FRAME_DT;
        let r = Quat::from_rotation_y(-Self::angle(t));
        let pose: Vec<Vec3> = self.rest.iter().map(|p| self.pivot + r * (*p - self.pivot)).collect();
        self.cloth.body_mut().unwrap().move_to(&pose);
        self.cloth.step_frame(FRAME_DT);
    }
}

#[test]
fn a_fast_limb_swinging_through_a_curtain_never_crosses_it() {
    let peak_tip_speed = 0.9 * SWING_AMPLITUDE * std::f32::consts::TAU * SWING_HZ;
    assert!(peak_tip_speed > 9.0);
    // Frame 11 is where, with edge contacts only among the edges' frame-start candidates, the
    // curtain dragged over the limb's tip had 5 edges through it (the tip had carried the
    // cloth past what its frame-start velocity predicted).
    let mut s = LimbScene::new(true);
    let start = s.cloth.positions().to_vec();
    let mut pushed = 0.0f32;
    for f in 1..=50 {
        s.step();
        assert_eq!(s.cloth.body_crossings(), 0, "cloth edges crossing the limb after frame {f}");
        assert_finite(&s.cloth);
        pushed = pushed.max(s.cloth.positions().iter().map(|p| p.z).fold(f32::MIN, f32::max));
    }
    // The limb really went through: it pushed the curtain at least 20 cm forward.
    assert!(pushed > 0.2, "curtain pushed only {pushed} m");
    assert_ne!(start, s.cloth.positions());
    // Velocities are clamped to the speed limit.
    assert!(s.cloth.max_speed() <= s.cloth.params().max_speed * 1.0001, "speed {}", s.cloth.max_speed());
}

#[test]
#[ignore = "known failure: the curtain the limb whips crosses itself (up to 378 edges at frame 17, 35 at frame 50)"]
fn the_curtain_a_fast_limb_whips_never_crosses_itself() {
    let mut s = LimbScene::new(true);
    for f in 1..=50 {
        s.step();
        assert_eq!(s.cloth.self_crossings(), 0, "cloth edges crossing the curtain after frame {f}");
    }
}

#[test]
fn collision_runs_are_bit_identical() {
    // The limb's first frames, where body and self contacts both act: twice through the whole
    // swing would double the fast-limb test's time in CI.
    let run = || {
        let mut s = LimbScene::new(true);
        for _ in 0..14 {
            s.step();
        }
        (s.cloth.positions().to_vec(), s.cloth.velocities().to_vec())
    };
    let (a, b) = (run(), run());
    assert!(a.0.iter().zip(&b.0).all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits)));
    assert!(a.1.iter().zip(&b.1).all(|(p, q)| p.to_array().map(f32::to_bits) == q.to_array().map(f32::to_bits)));
}

/// A 60 x 20 cm strip folded in two (a U lying on its side: 2 cm between
/// the layers) on a floor; the top layer falls onto the bottom one.
fn folded_strip(self_collision: bool, frames: u32) -> (Cloth, usize) {
    let (w, h) = (60.0, 20.0);
    let mesh = sheet(w, h, 1.5);
    let gap = 0.02;
    let half = 0.5 * w * CM;
    let r = 0.5 * gap;
    let start: Vec<Vec3> = mesh
        .rest_positions()
        .iter()
        .map(|p| {
            let (s, z) = (p.x * CM, (p.y - 0.5 * h) * CM);
            let fold_len = std::f32::consts::PI * r;
            let lead = half - 0.5 * fold_len;
            let y0 = 0.01;
            if s < lead {
                Vec3::new(s - lead, y0, z)
            } else if s < lead + fold_len {
                let a = (s - lead) / r;
                Vec3::new(r * a.sin(), y0 + r - r * a.cos(), z)
            } else {
                Vec3::new(-(s - lead - fold_len), y0 + gap, z)
            }
        })
        .collect();
    let params = SimParams { self_collision, bend_compliance: 1e3, ..SimParams::default() };
    let mut c = Cloth::new(mesh, start, params);
    let (floor, tris) = box_mesh(Vec3::new(0.0, -0.1, 0.0), Vec3::new(1.0, 0.1, 1.0), Quat::IDENTITY, 1);
    c.set_body(Some(BodyMesh::new(floor, tris)));
    let mut worst = 0;
    for _ in 0..frames {
        c.step_frame(FRAME_DT);
        worst = worst.max(c.self_crossings());
    }
    (c, worst)
}

/// Highest point the strip reaches over `frames` frames.
fn highest(self_collision: bool, frames: u32) -> (Cloth, usize, f32) {
    let (mut c, mut worst) = folded_strip(self_collision, 0);
    let mut top = f32::MIN;
    for _ in 0..frames {
        c.step_frame(FRAME_DT);
        worst = worst.max(c.self_crossings());
        top = top.max(c.positions().iter().map(|p| p.y).fold(f32::MIN, f32::max));
    }
    (c, worst, top)
}

#[test]
fn a_folded_strip_settles_without_crossing_itself() {
    let (c, worst, top) = highest(true, 60);
    assert_finite(&c);
    assert_eq!(worst, 0, "cloth edges crossing the cloth (worst frame)");
    assert_eq!(c.body_crossings(), 0);
    // The 1 cm fold springs open (its rest shape is flat and this strip bends stiffly,
    // 1e3): the top layer rises to about 13 cm with or without self-collision. The
    // self contacts must not add to that: resting contacts that pushed overlap out
    // as velocity would throw the strip higher.
    let (_, without, top_without) = highest(false, 60);
    assert!(top < top_without + 0.005, "top at {top} m with self contacts, {top_without} m without");
    // Without self-collision the same scene does cross itself: the measure sees it.
    assert!(without > 0, "the scene needs self-collision");
}

#[test]
fn speed_limit_bounds_free_fall() {
    let mesh = sheet(30.0, 30.0, 3.0);
    let start = horizontal(&mesh, 30.0, 30.0, 2.0);
    let params = SimParams { max_speed: 2.0, ..SimParams::default() };
    let mut c = Cloth::new(mesh, start, params);
    for _ in 0..30 {
        c.step_frame(FRAME_DT);
    }
    // Free fall for 0.5 s would reach 4.9 m/s.
    let v = c.max_speed();
    assert!(v <= 2.0 * 1.0001 && v > 1.9, "max speed {v}");
    assert_finite(&c);
}

/// Two 30 cm sheets 5 mm apart, the lower one's middle pushed up through the upper one: side
/// tracking alone would hold the bump where it starts, on the wrong side; the untangling
/// finds the crossing edges, the part they cut off, and pulls it back under.
#[test]
fn a_patch_pushed_through_another_sheet_is_pulled_back() {
    let (w, edge) = (30.0, 2.0);
    let pieces = vec![Piece::new("under", rectangle_outline(w, w)), Piece::new("over", rectangle_outline(w, w))];
    let mesh = PatternMesh::build(pieces, vec![], edge).unwrap();
    let ids = mesh.piece_ids().to_vec();
    let start: Vec<Vec3> = mesh
        .rest_positions()
        .iter()
        .zip(&ids)
        .map(|(p, &id)| {
            let flat = Vec3::new(p.x - 0.5 * w, 0.0, 0.5 * w - p.y) * CM;
            let y = if id == 1 {
                0.105
            } else if flat.length() < 0.05 {
                0.112
            } else {
                0.1
            };
            flat + Vec3::Y * y
        })
        .collect();
    let params = SimParams { self_collision: true, untangle: true, ..SimParams::default() };
    let mut c = Cloth::new(mesh, start, params);
    c.set_gravity(Vec3::ZERO);
    let before = c.self_crossings();
    assert!(before > 0, "the scene starts tangled");
    for _ in 0..60 {
        c.step_frame(FRAME_DT);
    }
    assert_finite(&c);
    assert_eq!(c.self_crossings(), 0, "{before} crossing edges at the start");
    let (bump_under, over) = c.positions().iter().zip(&ids).fold((f32::MIN, f32::MAX), |(u, o), (p, &id)| {
        if id == 0 && Vec3::new(p.x, 0.0, p.z).length() < 0.03 {
            (u.max(p.y), o)
        } else if id == 1 && Vec3::new(p.x, 0.0, p.z).length() < 0.03 {
            (u, o.min(p.y))
        } else {
            (u, o)
        }
    });
    assert!(bump_under < over, "the bump (top {bump_under} m) is back under the sheet over it (lowest {over} m)");
}

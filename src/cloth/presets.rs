//! Ready-made scenes. Each takes a target triangle count (resolution) and a
//! seed for the small random perturbations that break perfect symmetry.

use std::f32::consts::TAU;

use glam::{Quat, Vec2, Vec3};

use super::collider::Collider;
use super::pattern::{EdgeRef, PatternMesh, Piece, Seam, rectangle_outline, trapezoid_outline};
use super::sim::{CM, Cloth, SimParams, Wind};
use crate::core::rng::SplitMix64;

/// Square tablecloth dropped onto a torus (the draping scene of the
/// garment-visualisation dissertation's Fig. 5.14).
#[derive(Clone, Debug, PartialEq)]
pub struct TableclothParams {
    pub triangles: usize,
    pub seed: u64,
    /// Side length of the cloth (cm).
    pub size_cm: f32,
}

impl Default for TableclothParams {
    fn default() -> Self {
        TableclothParams { triangles: 5000, seed: 1, size_cm: 140.0 }
    }
}

/// Rectangular flag pinned to a pole along its left edge.
#[derive(Clone, Debug, PartialEq)]
pub struct FlagParams {
    pub triangles: usize,
    pub seed: u64,
    /// Mean wind speed (m/s) along +x.
    pub wind_speed: f32,
}

impl Default for FlagParams {
    fn default() -> Self {
        FlagParams { triangles: 3000, seed: 1, wind_speed: 6.0 }
    }
}

/// A-line skirt of `panels` trapezoids sewn into a tube, falling onto a
/// capsule body.
#[derive(Clone, Debug, PartialEq)]
pub struct SkirtParams {
    pub triangles: usize,
    pub seed: u64,
    /// Number of panels (at least 2).
    pub panels: usize,
}

impl Default for SkirtParams {
    fn default() -> Self {
        SkirtParams { triangles: 4000, seed: 1, panels: 4 }
    }
}

/// Any preset, for [`crate::cloth::simulate_to_frame`].
#[derive(Clone, Debug, PartialEq)]
pub enum Preset {
    Tablecloth(TableclothParams),
    Flag(FlagParams),
    Skirt(SkirtParams),
}

impl Preset {
    pub fn build(&self) -> Cloth {
        match self {
            Preset::Tablecloth(p) => tablecloth_over_torus(p),
            Preset::Flag(p) => flag_in_wind(p),
            Preset::Skirt(p) => skirt_on_body(p),
        }
    }
}

/// Torus used by [`tablecloth_over_torus`]: 35 cm ring, 12 cm tube, axis up.
pub const TABLE_TORUS: Collider =
    Collider::Torus { center: Vec3::ZERO, axis: Vec3::Y, major_radius: 0.35, minor_radius: 0.12 };

/// A square cloth held flat 8 cm above the torus top, slightly rotated
/// (seeded) so it drapes into asymmetric folds.
pub fn tablecloth_over_torus(p: &TableclothParams) -> Cloth {
    let size = p.size_cm;
    let pieces = vec![Piece::new("tablecloth", rectangle_outline(size, size))];
    let h = PatternMesh::edge_length_for(&pieces, p.triangles);
    let mesh = PatternMesh::build(pieces, Vec::new(), h).expect("valid tablecloth pattern");
    let mut rng = SplitMix64::new(p.seed);
    let spin = Quat::from_rotation_y(0.2 * rng.next_signed());
    let positions = mesh
        .rest_positions()
        .iter()
        .map(|q| {
            let c = (*q - Vec2::splat(0.5 * size)) * CM;
            // Pattern y runs towards -z so the CCW front side faces up.
            let jitter = 0.001 * rng.next_signed();
            spin * Vec3::new(c.x, 0.20 + jitter, -c.y)
        })
        .collect();
    let params = SimParams { friction: 0.5, ..SimParams::default() };
    let mut cloth = Cloth::new(mesh, positions, params);
    cloth.add_collider(TABLE_TORUS);
    cloth
}

/// A 150 × 100 cm flag pinned along its left edge next to a pole, in gusty
/// wind along +x.
pub fn flag_in_wind(p: &FlagParams) -> Cloth {
    let (w, hgt) = (150.0, 100.0);
    let pieces = vec![Piece::new("flag", rectangle_outline(w, hgt))];
    let h = PatternMesh::edge_length_for(&pieces, p.triangles);
    let mesh = PatternMesh::build(pieces, Vec::new(), h).expect("valid flag pattern");
    let base = Vec3::new(0.0, 1.5, 0.0);
    let mut rng = SplitMix64::new(p.seed);
    let positions = mesh
        .rest_positions()
        .iter()
        .map(|q| base + Vec3::new(q.x, q.y, 0.0) * CM + Vec3::Z * (0.002 * rng.next_signed()))
        .collect();
    // Edge 3 of the rectangle is its left side.
    let pins = mesh.piece_meshes()[0].edge_chains[3].clone();
    let params = SimParams {
        damping: 0.1,
        wind: Some(Wind::new(Vec3::new(p.wind_speed, 0.0, 0.0), rng.next_u64())),
        ..SimParams::default()
    };
    let mut cloth = Cloth::new(mesh, positions, params);
    cloth.pin(&pins);
    cloth.add_collider(Collider::Capsule {
        a: Vec3::new(-0.03, 0.0, 0.0),
        b: Vec3::new(-0.03, 2.6, 0.0),
        radius: 0.02,
    });
    cloth
}

/// Capsule body used by [`skirt_on_body`] (metres, y up, facing +z): a
/// torso, two hip capsules slanting outwards and down (so the body widens
/// steadily below the waist, like a pelvis, and a flared skirt can rest on
/// it without being stretched), and two legs.
pub fn capsule_body() -> Vec<Collider> {
    let cap = |a: [f32; 3], b: [f32; 3], radius| Collider::Capsule { a: a.into(), b: b.into(), radius };
    vec![
        cap([0.0, 1.02, 0.0], [0.0, 1.42, 0.0], 0.11),
        cap([-0.03, 0.98, 0.0], [-0.09, 0.78, 0.0], 0.11),
        cap([0.03, 0.98, 0.0], [0.09, 0.78, 0.0], 0.11),
        cap([-0.09, 0.78, 0.0], [-0.09, 0.08, 0.0], 0.075),
        cap([0.09, 0.78, 0.0], [0.09, 0.08, 0.0], 0.075),
    ]
}

/// Panels start on a cone around the body just above the hips. The cone
/// fits the waist exactly but is 2 cm wider than the sewn skirt at the hem,
/// so the side seams start closed at the waist and open by up to 3 cm at
/// the hem; the seam constraints close them while the skirt drops onto the
/// hips and settles.
pub fn skirt_on_body(p: &SkirtParams) -> Cloth {
    assert!(p.panels >= 2, "a skirt needs at least two panels");
    let n = p.panels;
    // An 80 cm waist comes to rest on the upper hips (the torso is 69 cm
    // round, the hips reach 110 cm); a 180 cm hem keeps the skirt wider than
    // the body everywhere below the waist.
    let (top, bottom, len) = (80.0 / n as f32, 180.0 / n as f32, 60.0);
    let pieces: Vec<Piece> =
        (0..n).map(|k| Piece::new(format!("panel {k}"), trapezoid_outline(bottom, top, len))).collect();
    // Right side (edge 1, hem to waist) of panel k meets the left side
    // (edge 3, waist to hem) of the next panel.
    let seams = (0..n)
        .map(|k| Seam { a: EdgeRef { piece: k, edge: 1 }, b: EdgeRef { piece: (k + 1) % n, edge: 3 }, reversed: true })
        .collect();
    let h = PatternMesh::edge_length_for(&pieces, p.triangles);
    let mesh = PatternMesh::build(pieces, seams, h).expect("valid skirt pattern");

    let hem_gap = 0.02;
    let r_top = n as f32 * top * CM / TAU;
    let r_bottom = n as f32 * bottom * CM / TAU + hem_gap;
    let len_m = len * CM;
    let drop = (len_m * len_m - (r_bottom - r_top).powi(2)).sqrt();
    // Clear of the torso (11 cm) and of the hip capsule tops at this height.
    let waist_y = 1.06;
    let mut rng = SplitMix64::new(p.seed);
    let positions = mesh
        .rest_positions()
        .iter()
        .zip(mesh.piece_ids())
        .map(|(q, &piece)| {
            let s = q.y / len;
            let r = r_bottom + (r_top - r_bottom) * s;
            // Pattern x grows with the angle so the CCW front faces outwards.
            let angle = TAU * piece as f32 / n as f32 + (q.x - 0.5 * bottom) * CM / r;
            let y = waist_y - drop * (1.0 - s);
            let r = r + 0.001 * rng.next_signed();
            Vec3::new(r * angle.sin(), y, r * angle.cos())
        })
        .collect();
    let params = SimParams {
        // The waist contact holds the whole skirt; more substeps keep the
        // cloth around it from stretching while it lands.
        substeps: 24,
        friction: 0.7,
        seam_close_time: 0.4,
        ..SimParams::default()
    };
    // The waist: every panel's top edge, in order around the body (a top
    // edge runs right to left, i.e. against the panel order).
    let waist: Vec<u32> = mesh.piece_meshes().iter().rev().flat_map(|pm| pm.edge_chains[2].iter().copied()).collect();
    let mut cloth = Cloth::new(mesh, positions, params);
    cloth.add_length_loop(&waist);
    for c in capsule_body() {
        cloth.add_collider(c);
    }
    cloth
}

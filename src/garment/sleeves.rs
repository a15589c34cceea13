//! Fitting sleeves to the body's arms along the arm axis.
//!
//! A pattern placed for another body may hold its sleeves at the right angle but at the wrong
//! height on the arm: GarmentCode's shirt, scaled to MakeHuman, has its sleeve caps about 15 cm
//! down the upper arm while the torso's armholes start at the shoulder, so the seams begin 10 cm
//! or more apart with the arm between their sewn vertices. [`fit_sleeves`] slides each sleeve
//! along its arm's axis (shoulder joint to elbow joint) until the top of its cap (the point of
//! the edges sewn to non-sleeve panels nearest the shoulder along the axis) is level with the
//! top of the armhole it is sewn to. See docs/garments.md.

use glam::Vec3;

use super::Sewn;

/// One arm of the body a garment is fitted to: the shoulder joint (the upper arm's head) and the
/// elbow joint (the forearm's head), in the garment's world frame (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArmAxis {
    pub shoulder: Vec3,
    pub elbow: Vec3,
}

impl ArmAxis {
    /// Both arms of a MakeHuman default skeleton (`upperarm01` and `lowerarm01`, left then
    /// right) from `head`, a bone's head position in the world by name.
    pub fn makehuman_arms(head: impl Fn(&str) -> Option<Vec3>) -> anyhow::Result<[ArmAxis; 2]> {
        let at = |name: &str| head(name).ok_or_else(|| anyhow::anyhow!("the skeleton has no bone \"{name}\""));
        Ok([
            ArmAxis { shoulder: at("upperarm01.L")?, elbow: at("lowerarm01.L")? },
            ArmAxis { shoulder: at("upperarm01.R")?, elbow: at("lowerarm01.R")? },
        ])
    }

    /// The arms of the bundled avatar at rest, in metres as it stands.
    pub fn of_avatar(avatar: &crate::avatar::walk::WalkingAvatar) -> anyhow::Result<[ArmAxis; 2]> {
        let heads = avatar.rest_heads();
        ArmAxis::makehuman_arms(|name| avatar.skeleton.index(name).map(|i| avatar.place(heads[i].as_vec3())))
    }

    /// The arms of an `Avatar` node's joints.
    pub fn of_joints(joints: &crate::avatar::Joints) -> anyhow::Result<[ArmAxis; 2]> {
        ArmAxis::makehuman_arms(|name| joints.rest_head(name))
    }

    fn direction(&self) -> Vec3 {
        (self.elbow - self.shoulder).normalize_or_zero()
    }

    /// Distance from `p` to the segment shoulder-elbow.
    fn distance(&self, p: Vec3) -> f32 {
        p.distance(crate::cloth::collider::closest_point_on_segment(p, self.shoulder, self.elbow))
    }
}

/// Whether a panel is a sleeve: its name contains "sleeve" (GarmentCode's `left_sleeve_f`,
/// FreeSewing sidecars' `sleeve_left`), in any case.
pub fn is_sleeve(name: &str) -> bool {
    name.to_ascii_lowercase().contains("sleeve")
}

/// A sleeve slid along its arm by [`fit_sleeves`].
#[derive(Clone, Debug, PartialEq)]
pub struct SleeveFit {
    /// The sleeve's panels (names).
    pub panels: Vec<String>,
    /// Index of the arm in the `arms` given.
    pub arm: usize,
    /// How far the sleeve moved towards the shoulder along the arm axis (m; negative: towards
    /// the elbow).
    pub slide: f32,
}

/// Slides the sleeves of `sewn` along `arms` (see the module docs). Each sleeve panel goes with
/// the arm nearest its centroid; all sleeve panels of one arm move together (the slide is
/// measured over all their cap edges), so the seams between them stay as placed. Arms without a
/// sleeve, and sleeves with no edge sewn to a non-sleeve panel, are left alone. Returns the
/// slides, one per arm that has a sleeve.
pub fn fit_sleeves(sewn: &mut Sewn, arms: &[ArmAxis]) -> Vec<SleeveFit> {
    if arms.is_empty() {
        return Vec::new();
    }
    let piece = |v: u32| sewn.mesh.piece_ids()[v as usize] as usize;
    let ranges: Vec<std::ops::Range<usize>> =
        sewn.mesh.piece_meshes().iter().map(|m| m.vertices.start as usize..m.vertices.end as usize).collect();
    // The arm of each sleeve panel.
    let arm_of: Vec<Option<usize>> = (0..ranges.len())
        .map(|p| {
            if !is_sleeve(&sewn.piece_names[p]) {
                return None;
            }
            let c = sewn.positions[ranges[p].clone()].iter().sum::<Vec3>() / ranges[p].len().max(1) as f32;
            (0..arms.len()).min_by(|&a, &b| arms[a].distance(c).total_cmp(&arms[b].distance(c)))
        })
        .collect();
    let mut fits = Vec::new();
    let mut moves = Vec::new();
    for (k, arm) in arms.iter().enumerate() {
        let axis = arm.direction();
        let along = |v: u32| (sewn.positions[v as usize] - arm.shoulder).dot(axis);
        // Tops (nearest the shoulder along the axis) of the caps and of the armholes they meet.
        let (mut cap, mut hole) = (f32::INFINITY, f32::INFINITY);
        for (a, b) in &sewn.stitched {
            let (Some(&va), Some(&vb)) = (a.first(), b.first()) else { continue };
            let (sa, sb) = (arm_of[piece(va)] == Some(k), arm_of[piece(vb)] == Some(k));
            let (sleeve_side, other) = match (sa, sb) {
                (true, false) if arm_of[piece(vb)].is_none() => (a, b),
                (false, true) if arm_of[piece(va)].is_none() => (b, a),
                _ => continue,
            };
            cap = sleeve_side.iter().map(|&v| along(v)).fold(cap, f32::min);
            hole = other.iter().map(|&v| along(v)).fold(hole, f32::min);
        }
        if !(cap.is_finite() && hole.is_finite()) || axis == Vec3::ZERO {
            continue;
        }
        let slide = cap - hole;
        let members: Vec<usize> = (0..ranges.len()).filter(|&p| arm_of[p] == Some(k)).collect();
        moves.extend(members.iter().map(|&p| (ranges[p].clone(), axis * slide)));
        fits.push(SleeveFit { panels: members.iter().map(|&p| sewn.piece_names[p].clone()).collect(), arm: k, slide });
    }
    for (r, by) in moves {
        for x in &mut sewn.positions[r] {
            *x -= by;
        }
    }
    fits
}

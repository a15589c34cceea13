//! Fitting sleeves to the body's arms along the arm axis.
//!
//! A pattern placed for another body may hold its sleeves at the right angle but at the wrong
//! height on the arm: GarmentCode's shirt, scaled to MakeHuman, has its sleeve caps about 15 cm
//! down the upper arm while the torso's armholes start at the shoulder, so the seams begin 10 cm
//! or more apart with the arm between their sewn vertices. [`fit_sleeves`] slides each sleeve
//! along its arm's axis (shoulder joint to elbow joint) until the top of its cap (the point of
//! the edges sewn to non-sleeve panels nearest the shoulder along the axis) is level with the
//! top of the armhole it is sewn to.
//!
//! A one-piece sleeve (a panel sewn to itself along its underarm seam, as FreeSewing's) is first
//! wrapped round its arm, shoulder to wrist: laid flat over the arm, its underarm edges start
//! on either side of the arm, so closing the seam pulled them through it, and a forearm bent
//! away from the upper arm left its flat sleeve altogether. See docs/garments.md.

use glam::{Quat, Vec2, Vec3};

use super::Sewn;

/// One arm of the body a garment is fitted to: the shoulder joint (the upper arm's head), the
/// elbow joint (the forearm's head) and the wrist joint (the hand's head), in the garment's
/// world frame (metres).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ArmAxis {
    pub shoulder: Vec3,
    pub elbow: Vec3,
    pub wrist: Vec3,
}

impl ArmAxis {
    /// Both arms of a MakeHuman default skeleton (`upperarm01`, `lowerarm01` and `wrist`, left
    /// then right) from `head`, a bone's head position in the world by name.
    pub fn makehuman_arms(head: impl Fn(&str) -> Option<Vec3>) -> anyhow::Result<[ArmAxis; 2]> {
        let at = |name: &str| head(name).ok_or_else(|| anyhow::anyhow!("the skeleton has no bone \"{name}\""));
        Ok([
            ArmAxis { shoulder: at("upperarm01.L")?, elbow: at("lowerarm01.L")?, wrist: at("wrist.L")? },
            ArmAxis { shoulder: at("upperarm01.R")?, elbow: at("lowerarm01.R")?, wrist: at("wrist.R")? },
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
    /// Whether the sleeve was wrapped round the arm (a one-piece sleeve) rather than only slid.
    pub wrapped: bool,
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
    // One-piece sleeves: wrapped round their arm, cap top at the shoulder joint for a start.
    let wraps: Vec<Option<SleeveWrap>> = (0..ranges.len())
        .map(|p| {
            let k = arm_of[p]?;
            let seam = sewn.stitched.iter().find(|(a, b)| {
                a.first().is_some_and(|&v| piece(v) == p) && b.first().is_some_and(|&v| piece(v) == p)
            })?;
            SleeveWrap::new(sewn, ranges[p].clone(), seam, &arms[k])
        })
        .collect();
    for w in wraps.iter().flatten() {
        w.apply(&mut sewn.positions, 0.0);
    }
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
        // A wrapped sleeve slides along the bent arm (its cap stays on the upper arm's axis);
        // the others move straight.
        let wrapped = members.iter().all(|&p| wraps[p].is_some());
        for &p in &members {
            match &wraps[p] {
                Some(w) if wrapped => w.apply(&mut sewn.positions, -slide),
                _ => moves.push((ranges[p].clone(), axis * slide)),
            }
        }
        let panels = members.iter().map(|&p| sewn.piece_names[p].clone()).collect();
        fits.push(SleeveFit { panels, arm: k, slide, wrapped });
    }
    for (r, by) in moves {
        for x in &mut sewn.positions[r] {
            *x -= by;
        }
    }
    fits
}

/// A one-piece sleeve's flat panel mapped onto a tube round its arm: each vertex at `s` along the
/// sleeve from its cap's top (towards the hem) and `u` across it from the centre line, both
/// measured on the flat panel, goes to the arm's centre line at `s` and round it by the angle
/// `u / r(s)`, where `2π r(s)` is the sleeve's width across its underarm seam there. The seam's
/// two edges then meet under the arm, and every length across the sleeve is kept; lengths
/// along it are kept on the centre line and change by at most `r / BEND_RADII_PER_SLEEVE_RADIUS`
/// round the elbow's bend.
struct SleeveWrap {
    vertices: std::ops::Range<usize>,
    /// Per vertex: (s, u) in metres.
    flat: Vec<Vec2>,
    /// (s, r) in metres, ascending in s: the tube's radius at the seam's pairs.
    radii: Vec<Vec2>,
    /// The centre line's direction at the top of the arm (the sleeve's centre line goes there),
    /// and the direction of increasing u there; both perpendicular to the upper arm.
    top: Vec3,
    side: Vec3,
    arm: ArmCurve,
}

/// Where a sleeve longer than the arm is turned back: this far (m) before the wrist joint; and
/// how far (m) the turned-back layer starts outside the sleeve under it.
const WRIST_ROOM: f32 = 0.02;
const FOLD_GAP: f32 = 0.01;

/// The bend round the elbow is a circular arc this many sleeve radii in radius: its inside is
/// compressed and its outside stretched by one over this (a sharper bend crushes the inside of
/// the sleeve; a wider one cuts the elbow's corner).
const BEND_RADII_PER_SLEEVE_RADIUS: f32 = 4.0;

impl SleeveWrap {
    /// The wrap of the panel whose vertices are `vertices`, sewn to itself by `seam`, round `arm`;
    /// `None` when the panel or the arm is degenerate.
    fn new(sewn: &Sewn, vertices: std::ops::Range<usize>, seam: &(Vec<u32>, Vec<u32>), arm: &ArmAxis) -> Option<Self> {
        let rest = sewn.mesh.rest_positions();
        let placed = &sewn.positions[vertices.clone()];
        let flat_cm = &rest[vertices.clone()];
        let (m_to, k) = placement_map(flat_cm, placed)?;
        // The seam's centre line, from its first pair's midpoint to its last's.
        let pairs: Vec<(Vec2, Vec2)> =
            seam.0.iter().zip(&seam.1).map(|(&a, &b)| (rest[a as usize], rest[b as usize])).collect();
        let mid = |(a, b): (Vec2, Vec2)| (a + b) * 0.5;
        let (m0, m1) = (mid(*pairs.first()?), mid(*pairs.last()?));
        let along = (m1 - m0).try_normalize()?;
        // The cap is at the end the panel reaches farthest past the seam.
        let (lo, hi) = flat_cm
            .iter()
            .map(|p| (*p - m0).dot(along))
            .fold((f32::INFINITY, f32::NEG_INFINITY), |(l, h), t| (l.min(t), h.max(t)));
        let seam_end = (m1 - m0).length();
        let (s_dir, cap_top) = if -lo > hi - seam_end { (along, lo) } else { (-along, -hi) };
        let across = s_dir.perp();
        let flat: Vec<Vec2> =
            flat_cm.iter().map(|p| Vec2::new((*p - m0).dot(s_dir) - cap_top, (*p - m0).dot(across)) * k).collect();
        let mut radii: Vec<Vec2> = pairs
            .iter()
            .map(|&(a, b)| {
                Vec2::new((mid((a, b)) - m0).dot(s_dir) - cap_top, a.distance(b) / std::f32::consts::TAU) * k
            })
            .collect();
        radii.sort_by(|a, b| a.x.total_cmp(&b.x));
        let r_max = radii.iter().map(|r| r.y).fold(0.0, f32::max);
        let curve = ArmCurve::new(arm, BEND_RADII_PER_SLEEVE_RADIUS * r_max)?;
        // The top of the arm: where the placed panel lies off the upper arm's axis (up if on it).
        let centroid = placed.iter().sum::<Vec3>() / placed.len() as f32;
        let off = centroid - arm.shoulder;
        let d1 = curve.d1;
        let top = (off - d1 * off.dot(d1)).try_normalize().or_else(|| (Vec3::Y - d1 * d1.y).try_normalize())?;
        // Keep the panel's faces turned as placed: its normal (s × u) points off the arm or into
        // it as it did, and so does the tube's at the top.
        let placed_normal = m_to(s_dir).cross(m_to(across));
        let side = if placed_normal.dot(top) >= 0.0 { top.cross(d1) } else { d1.cross(top) };
        Some(SleeveWrap { vertices, flat, radii, top, side, arm: curve })
    }

    /// The tube's radius at `s` (metres), the nearest pair's past the seam's ends.
    fn radius(&self, s: f32) -> f32 {
        let i = self.radii.partition_point(|r| r.x < s);
        match (i.checked_sub(1).map(|j| self.radii[j]), self.radii.get(i)) {
            (Some(a), Some(b)) if b.x > a.x => a.y + (b.y - a.y) * (s - a.x) / (b.x - a.x),
            (Some(a), _) => a.y,
            (None, Some(b)) => b.y,
            (None, None) => 0.0,
        }
    }

    /// Writes the wrapped positions with the cap's top `start` metres along the arm from the
    /// shoulder joint (negative: before it, towards the neck).
    fn apply(&self, positions: &mut [Vec3], start: f32) {
        // A sleeve longer than the arm would go over the hand, its hem through the fingers: it
        // is turned back at the wrist instead, as a rolled-up sleeve, over itself (the fold a
        // half circle `FOLD_GAP` across, lengths along the sleeve kept).
        let fold = self.arm.wrist() - WRIST_ROOM;
        let half = FOLD_GAP * 0.5;
        for (x, f) in positions[self.vertices.clone()].iter_mut().zip(&self.flat) {
            let r = self.radius(f.x).max(1e-4);
            let angle = f.y / r;
            let past = start + f.x - fold;
            let (along, lift) = if past <= 0.0 {
                (start + f.x, 0.0)
            } else if past <= std::f32::consts::PI * half {
                let phi = past / half;
                (fold + half * phi.sin(), half * (1.0 - phi.cos()))
            } else {
                (fold - (past - std::f32::consts::PI * half), FOLD_GAP)
            };
            // The turned-back layer goes round the sleeve under it, which widens up the arm.
            let under = if lift > 0.0 { self.radius(along - start).max(r) } else { r };
            let (centre, turn) = self.arm.at(along);
            *x = centre + turn * ((under + lift) * (angle.cos() * self.top + angle.sin() * self.side));
        }
    }
}

/// The best affine map of a panel's flat points (cm) to their placed positions (m), as its
/// linear part (cm to m) and its scale (m per cm); `None` for a degenerate panel.
fn placement_map(flat: &[Vec2], placed: &[Vec3]) -> Option<(impl Fn(Vec2) -> Vec3, f32)> {
    let n = flat.len() as f32;
    let (fc, pc) = (flat.iter().sum::<Vec2>() / n, placed.iter().sum::<Vec3>() / n);
    // Least squares: M = (Σ p fᵀ)(Σ f fᵀ)⁻¹ over centred points.
    let (mut ff, mut pf_x, mut pf_y) = (glam::Mat2::ZERO, Vec3::ZERO, Vec3::ZERO);
    for (f, p) in flat.iter().zip(placed) {
        let (f, p) = (*f - fc, *p - pc);
        ff += glam::Mat2::from_cols(f * f.x, f * f.y);
        pf_x += p * f.x;
        pf_y += p * f.y;
    }
    if ff.determinant().abs() < 1e-6 {
        return None;
    }
    let inv = ff.inverse();
    let (col_x, col_y) = (pf_x * inv.x_axis.x + pf_y * inv.x_axis.y, pf_x * inv.y_axis.x + pf_y * inv.y_axis.y);
    let scale = (col_x.length() * col_y.length()).sqrt();
    (scale > 0.0 && scale.is_finite()).then_some((move |v: Vec2| col_x * v.x + col_y * v.y, scale))
}

/// An arm's centre line by arc length from the shoulder joint: the upper arm's axis (extended
/// before the shoulder), a circular bend round the elbow, then the forearm's axis (extended past
/// the wrist).
struct ArmCurve {
    shoulder: Vec3,
    d1: Vec3,
    d2: Vec3,
    /// Where the bend starts along the upper arm, and its length.
    bend_start: f32,
    bend_length: f32,
    /// The bend's angle (radians), about `bend_axis`.
    angle: f32,
    bend_axis: Vec3,
    radius: f32,
    /// The forearm's straight part's length, from the bend to the wrist joint.
    forearm: f32,
}

impl ArmCurve {
    fn new(arm: &ArmAxis, radius: f32) -> Option<Self> {
        let (upper, fore) = (arm.elbow - arm.shoulder, arm.wrist - arm.elbow);
        let (d1, d2) = (upper.try_normalize()?, fore.try_normalize()?);
        let angle = d1.dot(d2).clamp(-1.0, 1.0).acos();
        let bend_axis = d1.cross(d2).try_normalize().unwrap_or(Vec3::ZERO);
        // The bend's tangents reach at most 90 % of each bone's length.
        let half = (angle * 0.5).tan();
        let radius = if half > 1e-4 { radius.min(0.9 * upper.length().min(fore.length()) / half) } else { 0.0 };
        let bend_start = upper.length() - radius * half;
        let forearm = fore.length() - radius * half;
        Some(ArmCurve {
            shoulder: arm.shoulder,
            d1,
            d2,
            bend_start,
            bend_length: radius * angle,
            angle,
            bend_axis,
            radius,
            forearm,
        })
    }

    /// How far along the line (m) the wrist joint is.
    fn wrist(&self) -> f32 {
        self.bend_start + self.bend_length + self.forearm
    }

    /// The point `sigma` metres along the line, and the rotation of the upper arm's
    /// perpendicular frame to the line's there.
    fn at(&self, sigma: f32) -> (Vec3, Quat) {
        if sigma <= self.bend_start || self.bend_length <= 0.0 {
            return (self.shoulder + self.d1 * sigma, Quat::IDENTITY);
        }
        let start = self.shoulder + self.d1 * self.bend_start;
        let inward = self.bend_axis.cross(self.d1);
        let phi = ((sigma - self.bend_start) / self.radius).min(self.angle);
        let on_bend = start + self.radius * (phi.sin() * self.d1 + (1.0 - phi.cos()) * inward);
        let past = (sigma - self.bend_start - self.bend_length).max(0.0);
        (on_bend + self.d2 * past, Quat::from_axis_angle(self.bend_axis, phi))
    }
}

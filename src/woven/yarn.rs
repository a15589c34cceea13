//! The yarn and fibre scales (Zhang et al. 2012, sections 4.2-4.4, eqs. 11-15) and their
//! composition into the panel (eqs. 5/19). Frames are orthonormal (see `Frame`); eq. 13's
//! printed normal `(H h', S, 0)` is not orthogonal to its tangent `(S, H h', 0)`, so the normal
//! used is `(-H h', S, 0)`, normalised.

use std::f64::consts::{PI, TAU};

use glam::DVec3;

use super::panel::Frame;
use super::weave::Weave;

/// Yarn and fibre parameters, in world units where they are lengths.
#[derive(Clone, Debug, PartialEq)]
pub struct YarnParams {
    /// Interlaced nodes per patch side (the paper's 16).
    pub nodes: usize,
    /// S: the mean distance between neighbouring nodes.
    pub spacing: f64,
    /// H: the crimp amplitude (the yarn's offset along the panel normal at a node).
    pub crimp: f64,
    /// K of the yarn scale: the yarn radius.
    pub radius: f64,
    /// Fibres per yarn, on one ring (1: the fibre is the yarn).
    pub fibres: usize,
    /// Radial migration, 0..1: r(u) swings between (1 - migration) r0 and r0.
    pub migration: f64,
    /// Turns of each fibre around the yarn axis per node spacing (ω = 2π twist per unit u).
    pub twist: f64,
}

impl YarnParams {
    pub fn validate(&self) -> anyhow::Result<()> {
        anyhow::ensure!(self.nodes >= 1, "nodes per patch must be at least 1");
        anyhow::ensure!(
            self.spacing > 0.0 && self.spacing.is_finite(),
            "spacing must be positive (got {})",
            self.spacing
        );
        anyhow::ensure!(
            self.crimp >= 0.0 && self.crimp.is_finite(),
            "crimp must be zero or positive (got {})",
            self.crimp
        );
        anyhow::ensure!(self.radius > 0.0 && self.radius.is_finite(), "radius must be positive (got {})", self.radius);
        anyhow::ensure!(self.fibres >= 1, "fibre count must be at least 1");
        anyhow::ensure!((0.0..=1.0).contains(&self.migration), "migration must be in [0, 1] (got {})", self.migration);
        anyhow::ensure!(self.twist.is_finite(), "twist must be finite");
        Ok(())
    }

    /// The fibre radius: `fibres` circles packed on one ring inside the yarn, touching their
    /// neighbours and the yarn's surface.
    pub fn fibre_radius(&self) -> f64 {
        if self.fibres < 2 {
            return self.radius;
        }
        let s = (PI / self.fibres as f64).sin();
        self.radius * s / (1.0 + s)
    }

    /// r0: the distance of a fibre's axis from the yarn axis before migration.
    pub fn ring_radius(&self) -> f64 {
        self.radius - self.fibre_radius()
    }

    /// ω of eq. 14, radians per unit u.
    pub fn omega(&self) -> f64 {
        TAU * self.twist
    }
}

/// Which yarns: wefts run along u, warps along v.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Dir {
    Weft,
    Warp,
}

/// Eq. 11: the normalised height h and dh/du of yarn `line` at yarn parameter `u` (nodes at
/// integer u). Wefts take +η, warps -η (section 4.2.1).
pub fn height(weave: &Weave, dir: Dir, line: i64, u: f64) -> (f64, f64) {
    let (f, c) = (u.floor(), u.ceil());
    let eta = |k: f64| match dir {
        Dir::Weft => weave.eta(k as i64, line),
        Dir::Warp => -weave.eta(line, k as i64),
    };
    let (hf, hc) = (eta(f), eta(c));
    let x = (u - f) * PI;
    (0.5 * (hf + hc) + 0.5 * (hf - hc) * x.cos(), -0.5 * (hf - hc) * PI * x.sin())
}

/// Eq. 12: the yarn's offset in the panel frame.
pub fn yarn_offset(crimp: f64, h: f64) -> DVec3 {
    DVec3::new(0.0, crimp * h, 0.0)
}

/// Eq. 13, corrected: the yarn frame M_y in panel coordinates (x = τ_p along u, y = n_p,
/// z = b_p along v). Tangent `S a + H h' y`, normal `S y - H h' a` (a: the yarn's axis).
pub fn yarn_frame(dir: Dir, spacing: f64, crimp: f64, dh: f64) -> Frame {
    let a = match dir {
        Dir::Weft => DVec3::X,
        Dir::Warp => DVec3::Z,
    };
    let t = (spacing * a + crimp * dh * DVec3::Y).normalize();
    let n = (spacing * DVec3::Y - crimp * dh * a).normalize();
    Frame { t, n, b: t.cross(n) }
}

/// A fibre at yarn parameter u (eq. 14 after Sriprateep and Bohez): its offset l_f in the yarn
/// frame scaled by β_f, the frame M_f of that (scaled) path, r(u) and the phase ψ = φ + ω u.
pub struct FibrePoint {
    pub offset: DVec3,
    pub frame: Frame,
    pub r: f64,
    pub phase: f64,
}

/// Fibre `i` of `params.fibres`: phase φ_i = 2π i / n, radius
/// `r(u) = r0 (1 - m (1 - cos(ω u / 2 + φ_i)) / 2)` (one migration cycle per two turns: the
/// paper does not give r(u)). `axial` is the
/// yarn axis' length per unit u; `beta_f` scales the offset (interscale geomorphing, eq. 19), and
/// the frame follows the scaled path, so at β_f = 0 it is the identity.
pub fn fibre(params: &YarnParams, i: usize, u: f64, axial: f64, beta_f: f64) -> FibrePoint {
    let w = params.omega();
    let phi = TAU * i as f64 / params.fibres as f64;
    let r0 = if params.fibres < 2 { 0.0 } else { params.ring_radius() };
    let m = params.migration;
    let mig = 0.5 * w * u + phi;
    let r = r0 * (1.0 - 0.5 * m * (1.0 - mig.cos()));
    let dr = -r0 * 0.5 * m * mig.sin() * 0.5 * w;
    let psi = phi + w * u;
    let offset = DVec3::new(0.0, r * psi.sin(), r * psi.cos());
    let d = DVec3::new(0.0, dr * psi.sin() + r * w * psi.cos(), dr * psi.cos() - r * w * psi.sin());
    let t = (DVec3::new(axial, 0.0, 0.0) + beta_f * d).normalize();
    // Rotation-minimising with respect to the yarn: the yarn's normal made orthogonal to τ_f.
    let n = (DVec3::Y - DVec3::Y.dot(t) * t).normalize();
    FibrePoint { offset: beta_f * offset, frame: Frame { t, n, b: t.cross(n) }, r, phase: psi }
}

/// Eq. 15: the shell of radius K at angle θ (θ = 0 beside the axis along the binormal, π/2 on
/// the normal side).
pub fn shell(k: f64, theta: f64) -> DVec3 {
    DVec3::new(0.0, k * theta.sin(), k * theta.cos())
}

/// Eq. 19 with orthonormal frames: `l_p + β_y M_p l_y + β_f M_p M_y l_f + M_p M_y M_f l_s`,
/// returning the position and the shell's outward unit direction (the tube normal).
#[allow(clippy::too_many_arguments)]
pub fn compose(
    lp: DVec3,
    mp: &Frame,
    beta_y: f64,
    ly: DVec3,
    my: &Frame,
    fibre: Option<&FibrePoint>,
    k: f64,
    theta: f64,
) -> (DVec3, DVec3) {
    let mpy = mp.compose(my);
    let (lf, mf) = match fibre {
        Some(f) => (f.offset, f.frame),
        None => (DVec3::ZERO, Frame::IDENTITY),
    };
    let m = mpy.compose(&mf);
    let dir = m.apply(shell(1.0, theta));
    (lp + beta_y * mp.apply(ly) + mpy.apply(lf) + k * dir, dir)
}

//! A sewn pattern as cloth: the XPBD simulator (`crate::cloth`) with the panels at their
//! placed positions, the stitched vertex pairs as seam constraints whose rest length closes
//! from the initial gap to zero (`SimParams::seam_close_time`), gravity off while the seams
//! close, and optionally a moving body mesh to collide with.

use glam::Vec3;

use super::Sewn;
use crate::cloth::{BodyMesh, Cloth, FRAME_DT, SimParams};

/// Drape settings.
#[derive(Clone, Debug, PartialEq)]
pub struct DrapeParams {
    pub sim: SimParams,
    /// Frames with gravity off at the start, while the seams close (GarmentCode: 10).
    pub sewing_frames: u64,
}

impl Default for DrapeParams {
    fn default() -> Self {
        // GarmentCode drapes with 2.5 mm body thickness, friction 0.5, speed limit 25 m/s
        // (SimParams' defaults); the seams close over 0.4 s with gravity off for 0.5 s. Two
        // sweeps per substep: with one, the corners where three or four panels meet (the
        // armpits) stay 1.2 mm open after a second of sewing the shirt; with two, under 1 mm.
        DrapeParams {
            sim: SimParams { seam_close_time: 0.4, iterations: 2, ..SimParams::default() },
            sewing_frames: 30,
        }
    }
}

/// A garment being sewn and draped.
pub struct Drape {
    pub cloth: Cloth,
    gravity: Vec3,
    sewing_frames: u64,
}

impl Drape {
    pub fn new(sewn: &Sewn, params: &DrapeParams, body: Option<BodyMesh>) -> Drape {
        let gravity = params.sim.gravity;
        let mut cloth = Cloth::new(sewn.mesh.clone(), sewn.positions.clone(), params.sim.clone());
        cloth.set_body(body);
        if params.sewing_frames > 0 {
            cloth.set_gravity(Vec3::ZERO);
        }
        Drape { cloth, gravity, sewing_frames: params.sewing_frames }
    }

    /// One frame of [`FRAME_DT`]; `body` is the body's pose at the end of the frame (the same
    /// vertices and triangles as the body the drape was made with).
    pub fn step(&mut self, body: Option<&[Vec3]>) {
        if let (Some(pose), Some(b)) = (body, self.cloth.body_mut()) {
            b.move_to(pose);
        }
        if self.cloth.frame() >= self.sewing_frames {
            self.cloth.set_gravity(self.gravity);
        }
        self.cloth.step_frame(FRAME_DT);
    }

    /// The largest distance (m) between two sewn vertices.
    pub fn max_seam_gap(&self) -> f32 {
        let x = self.cloth.positions();
        self.cloth.seam_pairs().iter().map(|[a, b]| x[*a as usize].distance(x[*b as usize])).fold(0.0, f32::max)
    }
}

//! A sewn pattern as cloth: the XPBD simulator (`crate::cloth`) with the panels at their
//! placed positions, the stitched vertex pairs as seam constraints whose rest length closes
//! from the initial gap to zero (`SimParams::seam_close_time`), gravity off while the seams
//! close, and optionally a moving body mesh to collide with.

use std::path::Path;

use anyhow::{Context, bail};
use glam::Vec3;

use super::Sewn;
use crate::cloth::{BodyMesh, Cloth, ClothState, FRAME_DT, SimParams};

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

/// A drape at one frame: what the `Garment` node's `save_state` writes and `start_state` starts
/// from. `key` names what it belongs to ([`Drape::key`]); a state only fits a drape of the same key.
#[derive(Clone, Debug, PartialEq)]
pub struct DrapeState {
    pub key: u64,
    /// Frames the cloth had simulated, and its time (s): gravity and the seams' closing go on
    /// from there.
    pub frame: u64,
    pub time: f64,
    pub positions: Vec<Vec3>,
    pub velocities: Vec<Vec3>,
    /// `(vertex, triangle, side)` of the self-contacts of the last frame.
    pub sides: Vec<(u32, u32, f32)>,
    /// `(body vertex, cloth triangle, side)` of the body's contacts of the last frame.
    pub body_sides: Vec<(u32, u32, f32)>,
}

/// The file's first bytes and version.
const STATE_MAGIC: &[u8; 8] = b"WSDRAPE\0";
const STATE_VERSION: u32 = 1;

/// The file's header, little-endian, then positions and velocities as f32 triples, then the
/// self-contacts and the body's contacts as (u32 vertex, u32 triangle, f32 side).
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct StateHeader {
    magic: [u8; 8],
    version: u32,
    vertices: u32,
    key: u64,
    frame: u64,
    time: f64,
    sides: u32,
    body_sides: u32,
}

impl DrapeState {
    pub fn to_bytes(&self) -> Vec<u8> {
        let header = StateHeader {
            magic: *STATE_MAGIC,
            version: STATE_VERSION,
            vertices: self.positions.len() as u32,
            key: self.key,
            frame: self.frame,
            time: self.time,
            sides: self.sides.len() as u32,
            body_sides: self.body_sides.len() as u32,
        };
        let mut out = bytemuck::bytes_of(&header).to_vec();
        for v in self.positions.iter().chain(&self.velocities) {
            for c in v.to_array() {
                out.extend_from_slice(&c.to_le_bytes());
            }
        }
        for &(vertex, triangle, side) in self.sides.iter().chain(&self.body_sides) {
            out.extend_from_slice(&vertex.to_le_bytes());
            out.extend_from_slice(&triangle.to_le_bytes());
            out.extend_from_slice(&side.to_le_bytes());
        }
        out
    }

    pub fn from_bytes(bytes: &[u8]) -> anyhow::Result<DrapeState> {
        let head = std::mem::size_of::<StateHeader>();
        if bytes.len() < head {
            bail!("{} bytes: too short for a drape state ({head}-byte header)", bytes.len());
        }
        let header: StateHeader = bytemuck::pod_read_unaligned(&bytes[..head]);
        if &header.magic != STATE_MAGIC {
            bail!("not a werkstatt drape state (it does not start with \"WSDRAPE\")");
        }
        if header.version != STATE_VERSION {
            bail!("drape state version {}, this werkstatt reads version {STATE_VERSION}", header.version);
        }
        let (n, sides, body_sides) = (header.vertices as usize, header.sides as usize, header.body_sides as usize);
        let want = head + n * 2 * 12 + (sides + body_sides) * 12;
        if bytes.len() != want {
            bail!(
                "{} bytes where {n} vertices and {} contacts take {want}: the file is cut short or has more in it",
                bytes.len(),
                sides + body_sides
            );
        }
        let word = |at: usize| [bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]];
        let vectors = head + n * 24;
        let floats: Vec<f32> = (head..vectors).step_by(4).map(|at| f32::from_le_bytes(word(at))).collect();
        let vecs: Vec<Vec3> = floats.chunks_exact(3).map(Vec3::from_slice).collect();
        let mut contacts: Vec<(u32, u32, f32)> = (vectors..want)
            .step_by(12)
            .map(|at| {
                (u32::from_le_bytes(word(at)), u32::from_le_bytes(word(at + 4)), f32::from_le_bytes(word(at + 8)))
            })
            .collect();
        let body_sides = contacts.split_off(sides);
        if vecs.iter().any(|v| !v.is_finite())
            || !header.time.is_finite()
            || contacts.iter().chain(&body_sides).any(|s| !s.2.is_finite())
        {
            bail!("the state holds non-finite numbers");
        }
        let (positions, velocities) = vecs.split_at(n);
        Ok(DrapeState {
            key: header.key,
            frame: header.frame,
            time: header.time,
            positions: positions.to_vec(),
            velocities: velocities.to_vec(),
            sides: contacts,
            body_sides,
        })
    }

    pub fn read(path: &Path) -> anyhow::Result<DrapeState> {
        let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
        DrapeState::from_bytes(&bytes).with_context(|| format!("{}", path.display()))
    }

    pub fn write(&self, path: &Path) -> anyhow::Result<()> {
        crate::io::atomic::write_atomic(path, &self.to_bytes()).with_context(|| format!("writing {}", path.display()))
    }
}

impl Drape {
    /// What a saved state must match to start this drape: the sewn mesh (pattern, edge length,
    /// placement and sleeves all move its vertices), the simulation settings and the body's
    /// vertex count. Stable across runs and platforms.
    pub fn key(sewn: &Sewn, params: &DrapeParams, body_vertices: Option<usize>) -> u64 {
        let mut bytes: Vec<u8> = Vec::new();
        for p in &sewn.positions {
            bytes.extend(p.to_array().iter().flat_map(|c| c.to_le_bytes()));
        }
        for t in sewn.mesh.triangles() {
            bytes.extend(t.iter().flat_map(|i| i.to_le_bytes()));
        }
        bytes.extend(format!("{params:?} {body_vertices:?}").bytes());
        crate::core::hash::fnv1a(&bytes)
    }

    /// This drape's state now, under `key`.
    pub fn state(&self, key: u64) -> DrapeState {
        DrapeState {
            key,
            frame: self.cloth.frame(),
            time: self.cloth.time(),
            positions: self.cloth.positions().to_vec(),
            velocities: self.cloth.velocities().to_vec(),
            sides: self.cloth.self_contact_sides().to_vec(),
            body_sides: self.cloth.body_contact_sides().to_vec(),
        }
    }

    /// Continues from `state` (of the same key): its positions and velocities, gravity on once
    /// its frame is past the sewing frames.
    pub fn restore(&mut self, state: &DrapeState) -> anyhow::Result<()> {
        let saved = ClothState {
            positions: &state.positions,
            velocities: &state.velocities,
            time: state.time,
            frame: state.frame,
            sides: &state.sides,
            body_sides: &state.body_sides,
        };
        self.cloth.restore(saved).map_err(|e| anyhow::anyhow!("the drape state does not fit this garment: {e}"))?;
        if state.frame >= self.sewing_frames {
            self.cloth.set_gravity(self.gravity);
        }
        Ok(())
    }
}

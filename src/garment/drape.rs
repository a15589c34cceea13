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
            sim: SimParams {
                seam_close_time: 0.4,
                iterations: 2,
                struts: true,
                strain_limit: Some(0.03),
                ..SimParams::default()
            },
            sewing_frames: 30,
        }
    }
}

impl DrapeParams {
    /// The `Garment` node's default substeps per 1/60 s frame for each 1/cm of edge length. 30
    /// holds the 1 cm shirt's strain under 5 % through the 10 s walk, but gives 60 at 0.5 cm,
    /// where the shirt then settled with 51 cloth-cloth crossings against none with 40
    /// (docs/garments.md), so the default stays 20.
    pub const SUBSTEPS_PER_CM: f64 = 20.0;

    /// Simulator substeps per 1/60 s frame for a garment of `edge_cm` edges: `per_cm` for each
    /// 1/cm of resolution (with 20: 20 at 1 cm, 40 at 0.5 cm), never fewer than 20. A fixed
    /// number of Gauss-Seidel sweeps carries a load across fewer edges the finer the mesh, so
    /// the same substeps make a finer garment stretchier: without struts, the shirt's
    /// 99th-percentile edge strain was 11 % at 1 cm with 20 substeps (6.8 % with 30, 5.1 % with
    /// 40; with struts 5.5 % with 20), and at 0.5 cm with 20 it stretched 38 % and slid off the
    /// shoulders (docs/garments.md).
    pub fn substeps_for(edge_cm: f64, per_cm: f64) -> u32 {
        let n = per_cm / edge_cm.max(1e-3);
        (n.round().min(1000.0) as u32).clamp(20, 1000)
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
        cloth.start_outside_body();
        cloth.ease_strained_edges();
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
    pub cloth: ClothState,
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
        let c = &self.cloth;
        let header = StateHeader {
            magic: *STATE_MAGIC,
            version: STATE_VERSION,
            vertices: c.positions.len() as u32,
            key: self.key,
            frame: c.frame,
            time: c.time,
            sides: c.sides.len() as u32,
            body_sides: c.body_sides.len() as u32,
        };
        let mut out = bytemuck::bytes_of(&header).to_vec();
        for v in c.positions.iter().chain(&c.velocities) {
            for x in v.to_array() {
                out.extend_from_slice(&x.to_le_bytes());
            }
        }
        for &(vertex, triangle, side) in c.sides.iter().chain(&c.body_sides) {
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
        let (n, sides) = (header.vertices as usize, header.sides as usize);
        let contacts = sides + header.body_sides as usize;
        let want = head + n * 24 + contacts * 12;
        if bytes.len() != want {
            bail!(
                "{} bytes where {n} vertices and {contacts} contacts take {want}: the file is cut short or has more in it",
                bytes.len()
            );
        }
        let word = |at: usize| [bytes[at], bytes[at + 1], bytes[at + 2], bytes[at + 3]];
        let float = |at: usize| f32::from_le_bytes(word(at));
        let vector = |at: usize| Vec3::new(float(at), float(at + 4), float(at + 8));
        let contact = |at: usize| (u32::from_le_bytes(word(at)), u32::from_le_bytes(word(at + 4)), float(at + 8));
        let velocities_at = head + n * 12;
        let contacts_at = velocities_at + n * 12;
        let cloth = ClothState {
            positions: (head..velocities_at).step_by(12).map(vector).collect(),
            velocities: (velocities_at..contacts_at).step_by(12).map(vector).collect(),
            time: header.time,
            frame: header.frame,
            sides: (contacts_at..contacts_at + sides * 12).step_by(12).map(contact).collect(),
            body_sides: (contacts_at + sides * 12..want).step_by(12).map(contact).collect(),
        };
        if cloth.positions.iter().chain(&cloth.velocities).any(|v| !v.is_finite())
            || !cloth.time.is_finite()
            || cloth.sides.iter().chain(&cloth.body_sides).any(|s| !s.2.is_finite())
        {
            bail!("the state holds non-finite numbers");
        }
        Ok(DrapeState { key: header.key, cloth })
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
        DrapeState { key, cloth: self.cloth.state() }
    }

    /// Continues from `state` (of the same key); [`Drape::step`] turns gravity on from its frame.
    pub fn restore(&mut self, state: &DrapeState) -> anyhow::Result<()> {
        self.cloth.restore(&state.cloth).map_err(|e| anyhow::anyhow!("the drape state does not fit this garment: {e}"))
    }
}

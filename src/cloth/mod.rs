//! Deterministic cloth simulation for garment rendering.
//!
//! Garments are built from flat sewing-pattern pieces ([`pattern`]), which
//! are triangulated and packed into one UV atlas, so a vertex's UV is its
//! pattern position. [`Cloth`] simulates them with XPBD ([`sim`]) against
//! analytic and mesh colliders ([`collider`]); [`presets`] builds ready
//! scenes. A renderer calls [`Cloth::step_frame`] and [`Cloth::surface`]
//! once per frame.
//!
//! The work runs on all cores, but in an order fixed by the input alone (the
//! constraint sweep's parts, the contacts found in parallel and applied in
//! order): the same inputs give bit-identical positions on the same build and
//! platform, for any thread count.
//!
//! ```
//! use werkstatt::cloth::{FRAME_DT, FlagParams, Preset};
//!
//! let mut cloth = Preset::Flag(FlagParams { triangles: 500, ..Default::default() }).build();
//! for _ in 0..3 {
//!     cloth.step_frame(FRAME_DT);
//!     let frame = cloth.surface(); // upload positions, normals, uvs, indices
//!     assert_eq!(frame.indices.len(), 3 * cloth.triangle_count());
//! }
//! ```

pub mod body_collision;
pub mod bvh;
pub mod collider;
pub mod intersections;
pub mod pattern;
pub mod presets;
pub mod self_collision;
pub mod sim;
mod triangulate;

pub use body_collision::BodyMesh;
pub use collider::{Collider, Contact, TriMeshCollider};
pub use pattern::{EdgeRef, PatternError, PatternMesh, Piece, PieceMesh, Seam};
pub use presets::{FlagParams, Preset, SkirtParams, TableclothParams};
pub use sim::{CM, Cloth, ClothState, SimParams, StepTimings, Wind};

/// Frame length used by [`simulate_to_frame`] (60 frames per second).
pub const FRAME_DT: f32 = 1.0 / 60.0;

/// One frame of cloth geometry, ready for upload.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct SurfaceFrame {
    pub positions: Vec<[f32; 3]>,
    /// Area-weighted vertex normals.
    pub normals: Vec<[f32; 3]>,
    /// Packed pattern coordinates in [0,1]².
    pub uvs: Vec<[f32; 2]>,
    /// Triangles, CCW when seen from the normal side.
    pub indices: Vec<u32>,
    pub piece_ids: Vec<u32>,
}

/// Builds `preset` and simulates `frame` frames of [`FRAME_DT`] from its
/// initial state (frame 0 is the initial state). Always re-simulates, so the
/// result depends only on the arguments.
pub fn simulate_to_frame(preset: &Preset, frame: u32) -> SurfaceFrame {
    let mut cloth = preset.build();
    for _ in 0..frame {
        cloth.step_frame(FRAME_DT);
    }
    cloth.surface()
}

//! The bundled avatar as a collision body along a motion, outside the node graph: what the
//! drape benchmark and the garment tests step a garment against. The `Avatar` node does the
//! same per frame with its parameters (units, skinning, clothes).

use std::path::Path;

use glam::{DVec3, Vec3};

use super::bvh::Bvh;
use super::retarget::{JointMap, Retarget};
use super::rig::{Pose, Skeleton, Skinning, Weights, skin};
use super::{Body, collision_mesh};
use crate::cloth::BodyMesh;

/// MakeHuman's base mesh rigged with its default skeleton and weights, walking by a BVH.
pub struct WalkingAvatar {
    pub body: Body,
    pub skeleton: Skeleton,
    weights: Weights,
    bvh: Bvh,
    retarget: Retarget,
    pub skinning: Skinning,
    /// Radians each upper arm turns away from the body on top of the walk ([`Pose::spread_arms`]).
    pub arm_spread: f64,
    /// The body's lowest visible point at rest ([`Body::floor`]), found once: placing a pose
    /// looks it up for every vertex.
    floor: f32,
}

impl WalkingAvatar {
    /// Loads `makehuman-base.obj`, `default.mhskel`, `default_weights.mhw`, the motion `walk1.bvh`
    /// and its joint map `makehuman-old-rig.ron` from `dir` (the project's assets/avatar).
    pub fn load(dir: &Path) -> anyhow::Result<WalkingAvatar> {
        let read = |name: &str| {
            std::fs::read_to_string(dir.join(name)).map_err(|e| anyhow::anyhow!("{}: {e}", dir.join(name).display()))
        };
        let body = Body::load(&dir.join("makehuman-base.obj"))?;
        let skeleton = Skeleton::from_mhskel(&read("default.mhskel")?, "default.mhskel", &body.obj.positions)?;
        let weights = Weights::from_mhw(
            &read("default_weights.mhw")?,
            "default_weights.mhw",
            &skeleton,
            body.obj.positions.len(),
        )?;
        let bvh = Bvh::load(&dir.join("walk1.bvh"))?;
        let (map, text) = JointMap::load(&dir.join("makehuman-old-rig.ron"))?;
        let retarget = Retarget::new(&map, "makehuman-old-rig.ron", &text, &bvh, "walk1.bvh", &skeleton)?;
        let floor = body.floor();
        Ok(WalkingAvatar { body, skeleton, weights, bvh, retarget, skinning: Skinning::Linear, arm_spread: 0.0, floor })
    }

    /// Base-mesh units (decimetres, feet at the mesh's floor) to metres with the feet on y = 0,
    /// as the `Avatar` node's default `units` places the body.
    pub fn place(&self, p: Vec3) -> Vec3 {
        (p - Vec3::Y * self.floor) * 0.1
    }

    /// The collision body's vertices (metres) in `pose`.
    pub fn collision_vertices(&self, pose: &Pose) -> Vec<Vec3> {
        let posed = skin(&self.body.obj.positions, &self.weights, &self.skeleton.skinning(pose), self.skinning);
        let mesh = collision_mesh(&self.body, &posed, |p| self.place(p)).expect("the base mesh's visible faces build");
        mesh.positions
    }

    /// The collision body at rest.
    pub fn rest_body(&self) -> BodyMesh {
        let positions = self.collision_vertices(&Pose::rest(&self.skeleton));
        let tris = self.body.collision_indices.chunks_exact(3).map(|t| [t[0], t[1], t[2]]).collect();
        BodyMesh::new(positions, tris)
    }

    /// The walk's pose `seconds` in (looping).
    pub fn walk_pose(&self, seconds: f64) -> Pose {
        let mut pose = self.retarget.pose(&self.bvh, &self.skeleton, seconds / self.bvh.frame_time, true, 1.0);
        pose.spread_arms(&self.skeleton, self.arm_spread);
        pose
    }

    /// The bones' heads at rest, in base-mesh units (see [`WalkingAvatar::place`]).
    pub fn rest_heads(&self) -> Vec<DVec3> {
        self.skeleton.globals(&Pose::rest(&self.skeleton)).into_iter().map(|(_, h)| h).collect()
    }
}

//! MakeHuman's skeleton (`.mhskel`) and skinning weights (`.mhw`), and skinning: linear blend
//! (LBS) and dual quaternions (DQS).
//!
//! Bones carry no rest orientation: like a BVH joint, a bone's frame is parallel to the world's
//! at rest, so a pose is one local rotation per bone (about its head, in its parent's frame) and
//! the rest pose is the identity everywhere. Skinning runs in f64, so the rest pose reproduces
//! the f32 mesh exactly.

use std::collections::BTreeMap;

use anyhow::{Context as _, bail};
use glam::{DMat3, DQuat, DVec3, Vec3};

#[derive(Clone, Debug)]
pub struct Bone {
    pub name: String,
    /// Parents come before their children in `Skeleton::bones`.
    pub parent: Option<usize>,
    /// Rest positions of the bone's head (its pivot) and tail, in mesh units.
    pub head: DVec3,
    pub tail: DVec3,
}

#[derive(Clone, Debug, Default)]
pub struct Skeleton {
    pub bones: Vec<Bone>,
}

/// A pose: a local rotation per bone (in its parent's frame; identity = rest) and a
/// displacement of the root bones' heads.
#[derive(Clone, Debug, PartialEq)]
pub struct Pose {
    pub rotations: Vec<DQuat>,
    pub root_offset: DVec3,
}

impl Pose {
    pub fn rest(skeleton: &Skeleton) -> Pose {
        Pose { rotations: vec![DQuat::IDENTITY; skeleton.bones.len()], root_offset: DVec3::ZERO }
    }

    /// Turns each upper arm (`upperarm01.L`/`.R`, with everything below it) `radians` away from
    /// the body about the chest's forward axis, after the motion's own rotation: walks recorded
    /// on slimmer bodies swing MakeHuman's arms through its torso at the armpits, and a few
    /// degrees outward keep arm and torso apart. Bones missing from the skeleton are skipped.
    pub fn spread_arms(&mut self, skeleton: &Skeleton, radians: f64) {
        for name in ["upperarm01.L", "upperarm01.R"] {
            let Some(b) = skeleton.index(name) else { continue };
            // Local rotations are deltas from the rest pose in mesh axes (facing +Z, left arm
            // at +X): a turn about +Z in the parent's frame, applied after the motion's.
            let side = skeleton.bones[b].head.x.signum();
            self.rotations[b] = (DQuat::from_rotation_z(side * radians) * self.rotations[b]).normalize();
        }
    }
}

/// A rigid transform x -> q x + t.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Rigid {
    pub q: DQuat,
    pub t: DVec3,
}

impl Rigid {
    pub fn apply(&self, x: DVec3) -> DVec3 {
        self.q * x + self.t
    }
}

impl Skeleton {
    pub fn index(&self, name: &str) -> Option<usize> {
        self.bones.iter().position(|b| b.name == name)
    }

    /// Builds a skeleton from bones given in any order (name, parent name, head, tail): sorts
    /// parents first (by name among siblings) and checks that every parent exists.
    pub fn from_unordered(mut list: Vec<(String, Option<String>, DVec3, DVec3)>) -> anyhow::Result<Skeleton> {
        list.sort_by(|a, b| a.0.cmp(&b.0));
        let mut bones: Vec<Bone> = Vec::new();
        let mut placed = vec![false; list.len()];
        loop {
            let before = bones.len();
            for (i, (name, parent, head, tail)) in list.iter().enumerate() {
                if placed[i] {
                    continue;
                }
                let parent_index = match parent {
                    None => None,
                    Some(p) => match bones.iter().position(|b| b.name == *p) {
                        Some(k) => Some(k),
                        None => continue,
                    },
                };
                bones.push(Bone { name: name.clone(), parent: parent_index, head: *head, tail: *tail });
                placed[i] = true;
            }
            if bones.len() == list.len() {
                return Ok(Skeleton { bones });
            }
            if bones.len() == before {
                let (name, parent, ..) = list.iter().zip(&placed).find(|(_, p)| !**p).expect("one is left").0;
                bail!("bone {name:?} has parent {:?}, which is not a bone (or the parents form a cycle)", parent);
            }
        }
    }

    /// MakeHuman's `.mhskel` (JSON): each bone names its head and tail joints, each joint a
    /// list of vertices of the base mesh whose mean is its position. `file` names it in errors.
    pub fn from_mhskel(text: &str, file: &str, positions: &[Vec3]) -> anyhow::Result<Skeleton> {
        let json: serde_json::Value =
            serde_json::from_str(text).with_context(|| format!("{file} is not valid JSON"))?;
        let bones =
            json.get("bones").and_then(|b| b.as_object()).with_context(|| format!("{file} has no \"bones\""))?;
        let joints =
            json.get("joints").and_then(|b| b.as_object()).with_context(|| format!("{file} has no \"joints\""))?;
        let joint = |bone: &str, name: Option<&str>| -> anyhow::Result<DVec3> {
            let name = name.with_context(|| format!("{file}: bone {bone:?} lacks a head or tail joint"))?;
            let verts = joints
                .get(name)
                .and_then(|v| v.as_array())
                .with_context(|| format!("{file}: joint {name:?} (of bone {bone:?}) is not in \"joints\""))?;
            let mut sum = DVec3::ZERO;
            for v in verts {
                let i = v.as_u64().with_context(|| format!("{file}: joint {name:?} lists a non-index"))? as usize;
                let p = positions.get(i).with_context(|| {
                    format!("{file}: joint {name:?} uses vertex {i}, but the mesh has {} vertices", positions.len())
                })?;
                sum += p.as_dvec3();
            }
            if verts.is_empty() {
                bail!("{file}: joint {name:?} has no vertices");
            }
            Ok(sum / verts.len() as f64)
        };
        let mut list = Vec::new();
        for (name, b) in bones {
            let head = joint(name, b.get("head").and_then(|h| h.as_str()))?;
            let tail = joint(name, b.get("tail").and_then(|h| h.as_str()))?;
            let parent = b.get("parent").and_then(|p| p.as_str()).map(str::to_string);
            list.push((name.clone(), parent, head, tail));
        }
        Skeleton::from_unordered(list).with_context(|| format!("in {file}"))
    }

    /// Global rotation and head position of every bone in `pose`.
    pub fn globals(&self, pose: &Pose) -> Vec<(DQuat, DVec3)> {
        let mut out: Vec<(DQuat, DVec3)> = Vec::with_capacity(self.bones.len());
        for (i, b) in self.bones.iter().enumerate() {
            let local = pose.rotations[i];
            let g = match b.parent {
                None => (local, b.head + pose.root_offset),
                Some(p) => {
                    let (pq, ph) = out[p];
                    ((pq * local).normalize(), ph + pq * (b.head - self.bones[p].head))
                }
            };
            out.push(g);
        }
        out
    }

    /// The skinning transform of every bone: rest position -> posed position.
    pub fn skinning(&self, pose: &Pose) -> Vec<Rigid> {
        self.globals(pose).into_iter().zip(&self.bones).map(|((q, h), b)| Rigid { q, t: h - q * b.head }).collect()
    }
}

/// Skinning weights: per vertex, (bone, weight) pairs summing to 1.
#[derive(Clone, Debug, Default)]
pub struct Weights {
    pub vertices: Vec<Vec<(u32, f64)>>,
    /// Vertices that had no weight at all (bound to the first root bone).
    pub unweighted: usize,
    /// Vertices whose weights were rescaled by more than 1% to sum to 1.
    pub renormalized: usize,
}

impl Weights {
    /// MakeHuman's `.mhw` (JSON: `weights`: bone -> [[vertex, weight], ...]) for a mesh of
    /// `vertex_count` vertices. Weights are normalized per vertex (MakeHuman's files do not sum
    /// to 1 exactly); a vertex without any is bound to the root.
    pub fn from_mhw(text: &str, file: &str, skeleton: &Skeleton, vertex_count: usize) -> anyhow::Result<Weights> {
        let json: serde_json::Value =
            serde_json::from_str(text).with_context(|| format!("{file} is not valid JSON"))?;
        let table =
            json.get("weights").and_then(|w| w.as_object()).with_context(|| format!("{file} has no \"weights\""))?;
        let mut raw: BTreeMap<String, Vec<(usize, f64)>> = BTreeMap::new();
        for (bone, list) in table {
            let list = list.as_array().with_context(|| format!("{file}: weights of {bone:?} are not a list"))?;
            let mut pairs = Vec::with_capacity(list.len());
            for pair in list {
                let (v, w) = pair
                    .as_array()
                    .filter(|a| a.len() == 2)
                    .and_then(|a| Some((a[0].as_u64()? as usize, a[1].as_f64()?)))
                    .with_context(|| format!("{file}: bone {bone:?} has an entry that is not [vertex, weight]"))?;
                pairs.push((v, w));
            }
            raw.insert(bone.clone(), pairs);
        }
        Weights::from_table(&raw, file, skeleton, vertex_count)
    }

    pub fn from_table(
        raw: &BTreeMap<String, Vec<(usize, f64)>>,
        file: &str,
        skeleton: &Skeleton,
        vertex_count: usize,
    ) -> anyhow::Result<Weights> {
        let mut vertices: Vec<Vec<(u32, f64)>> = vec![Vec::new(); vertex_count];
        for (bone, pairs) in raw {
            let b = skeleton
                .index(bone)
                .with_context(|| format!("{file}: weights for bone {bone:?}, which the skeleton does not have"))?;
            for &(v, w) in pairs {
                if v >= vertex_count {
                    bail!("{file}: bone {bone:?} weighs vertex {v}, but the mesh has {vertex_count} vertices");
                }
                if !(w.is_finite() && w >= 0.0) {
                    bail!("{file}: bone {bone:?} gives vertex {v} the weight {w}");
                }
                if w > 0.0 {
                    vertices[v].push((b as u32, w));
                }
            }
        }
        let root = skeleton.bones.iter().position(|b| b.parent.is_none()).context("the skeleton has no root")? as u32;
        let (mut unweighted, mut renormalized) = (0, 0);
        for list in &mut vertices {
            list.sort_by_key(|(b, _)| *b);
            let sum: f64 = list.iter().map(|(_, w)| w).sum();
            if sum <= 0.0 {
                *list = vec![(root, 1.0)];
                unweighted += 1;
            } else {
                if (sum - 1.0).abs() > 0.01 {
                    renormalized += 1;
                }
                list.iter_mut().for_each(|(_, w)| *w /= sum);
            }
        }
        Ok(Weights { vertices, unweighted, renormalized })
    }
}

/// How bone transforms are blended per vertex.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Skinning {
    /// Linear blend skinning: the weighted mean of the bones' matrices.
    Linear,
    /// Dual-quaternion skinning (Kavan et al. 2008): the normalized weighted sum of the
    /// bones' unit dual quaternions, a rigid transform per vertex.
    DualQuaternion,
}

/// The posed positions of `rest` (mesh units) under `bones` (from [`Skeleton::skinning`]).
pub fn skin(rest: &[Vec3], weights: &Weights, bones: &[Rigid], method: Skinning) -> Vec<Vec3> {
    match method {
        Skinning::Linear => {
            let mats: Vec<(DMat3, DVec3)> = bones.iter().map(|r| (DMat3::from_quat(r.q), r.t)).collect();
            rest.iter()
                .zip(&weights.vertices)
                .map(|(p, list)| {
                    let x = p.as_dvec3();
                    let mut out = DVec3::ZERO;
                    for &(b, w) in list {
                        let (m, t) = mats[b as usize];
                        out += w * (m * x + t);
                    }
                    out.as_vec3()
                })
                .collect()
        }
        Skinning::DualQuaternion => {
            let dqs: Vec<DualQuat> = bones.iter().map(|r| DualQuat::from_rigid(*r)).collect();
            rest.iter()
                .zip(&weights.vertices)
                .map(|(p, list)| {
                    let x = p.as_dvec3();
                    // Blend in the hemisphere of the heaviest bone (antipodal quaternions are the
                    // same rotation but would cancel).
                    let pivot = list.iter().max_by(|a, b| a.1.total_cmp(&b.1)).map(|(b, _)| dqs[*b as usize].real);
                    let pivot = pivot.unwrap_or(DQuat::IDENTITY);
                    let mut sum = DualQuat {
                        real: DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0),
                        dual: DQuat::from_xyzw(0.0, 0.0, 0.0, 0.0),
                    };
                    for &(b, w) in list {
                        let d = dqs[b as usize];
                        let w = if d.real.dot(pivot) < 0.0 { -w } else { w };
                        sum.real += d.real * w;
                        sum.dual += d.dual * w;
                    }
                    sum.to_rigid().apply(x).as_vec3()
                })
                .collect()
        }
    }
}

/// A unit dual quaternion real + ε dual, with dual = ½ t real.
#[derive(Clone, Copy, Debug)]
struct DualQuat {
    real: DQuat,
    dual: DQuat,
}

impl DualQuat {
    fn from_rigid(r: Rigid) -> DualQuat {
        let t = DQuat::from_xyzw(r.t.x, r.t.y, r.t.z, 0.0);
        DualQuat { real: r.q, dual: (t * r.q) * 0.5 }
    }

    /// Normalizes and converts back (t = 2 dual real*).
    fn to_rigid(self) -> Rigid {
        let n = self.real.length();
        if n < 1e-12 {
            return Rigid { q: DQuat::IDENTITY, t: DVec3::ZERO };
        }
        let (real, dual) = (self.real / n, self.dual / n);
        let t = (dual * 2.0) * real.conjugate();
        // The dual part's component along the real one is not a translation; removing it is
        // the normalization of the dual quaternion.
        Rigid { q: real, t: DVec3::new(t.x, t.y, t.z) }
    }
}

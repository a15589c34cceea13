//! Retargeting a BVH motion onto another skeleton through a joint map.
//!
//! A joint map (RON, [`JointMap`]) names, for bones of the destination skeleton, the source
//! joint whose motion they follow, and how the source file's axes and units relate to the
//! mesh's. Rotations are transferred relative to each rig's rest pose: both rigs have rest
//! frames parallel to the world (BVH's convention, and [`super::rig`]'s), so a mapped bone
//! takes its source joint's global rotation, times a fixed rest correction that turns the
//! destination bone's rest direction onto the source's (so a rig resting in a T-pose drives one
//! resting in an A-pose correctly). Unmapped bones keep their rest orientation relative to
//! their parent. The source root's position channels move the body, relative to the first
//! frame and scaled by the ratio of hip heights.

use std::collections::BTreeMap;

use anyhow::{Context as _, bail};
use glam::{DMat3, DQuat, DVec3};
use serde::{Deserialize, Serialize};

use super::bvh::Bvh;
use super::rig::{Pose, Skeleton};

fn makehuman_axes() -> (String, String, String) {
    ("x".into(), "z".into(), "-y".into())
}

fn one() -> f64 {
    1.0
}

/// How a source rig drives a destination skeleton (a `.ron` file; see docs/avatar.md).
#[derive(Clone, Debug, Deserialize, Serialize, PartialEq)]
#[serde(deny_unknown_fields)]
pub struct JointMap {
    /// The mesh's x, y and z axes as signed source axes: `("x", "z", "-y")` (the default) for
    /// MakeHuman's Z-up BVH files on its Y-up mesh, `("x", "y", "z")` for Y-up files (CMU).
    #[serde(default = "makehuman_axes")]
    pub axes: (String, String, String),
    /// Mesh units per source unit (MakeHuman's are the same: decimetres).
    #[serde(default = "one")]
    pub scale: f64,
    /// The source joint whose position channels move the body; default the file's root.
    #[serde(default)]
    pub root: Option<String>,
    /// Destination bone -> source joint. A source joint may drive several bones.
    pub bones: BTreeMap<String, String>,
    /// Mapped bones whose rest direction is not corrected towards the source's.
    #[serde(default)]
    pub keep_rest: Vec<String>,
}

impl JointMap {
    /// Every joint of `bvh` that is also a bone of `skeleton`, by name, in MakeHuman's axes.
    pub fn same_names(bvh: &Bvh, skeleton: &Skeleton) -> JointMap {
        let bones = bvh
            .joints
            .iter()
            .filter(|j| skeleton.index(&j.name).is_some())
            .map(|j| (j.name.clone(), j.name.clone()))
            .collect();
        JointMap { axes: makehuman_axes(), scale: 1.0, root: None, bones, keep_rest: Vec::new() }
    }

    /// Parses a joint map; errors name `file` and the line.
    pub fn parse(text: &str, file: &str) -> anyhow::Result<JointMap> {
        ron::from_str(text).map_err(|e| anyhow::anyhow!("{file}:{e}"))
    }

    pub fn load(path: &std::path::Path) -> anyhow::Result<(JointMap, String)> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        Ok((JointMap::parse(&text, &path.display().to_string())?, text))
    }

    /// The rotation taking source vectors to mesh vectors.
    pub fn axes_rotation(&self) -> anyhow::Result<DQuat> {
        let axis = |s: &str| -> anyhow::Result<DVec3> {
            Ok(match s.trim() {
                "x" | "+x" => DVec3::X,
                "y" | "+y" => DVec3::Y,
                "z" | "+z" => DVec3::Z,
                "-x" => -DVec3::X,
                "-y" => -DVec3::Y,
                "-z" => -DVec3::Z,
                other => bail!("axes: {other:?} is not one of x, y, z, -x, -y, -z"),
            })
        };
        // Row i of the matrix is the source axis that becomes mesh axis i.
        let rows = [axis(&self.axes.0)?, axis(&self.axes.1)?, axis(&self.axes.2)?];
        let m = DMat3::from_cols(rows[0], rows[1], rows[2]).transpose();
        if (m.determinant() - 1.0).abs() > 1e-9 {
            bail!("axes {:?} are not a rotation (each axis once, and no mirroring)", self.axes);
        }
        Ok(DQuat::from_mat3(&m))
    }
}

/// The line of `text` where `"name"` first appears (for errors), 0 if nowhere.
fn line_of(text: &str, name: &str) -> usize {
    let quoted = format!("\"{name}\"");
    text.lines().position(|l| l.contains(&quoted)).map_or(0, |i| i + 1)
}

/// A joint map resolved against one source file and one destination skeleton.
#[derive(Clone, Debug)]
pub struct Retarget {
    axes: DQuat,
    /// Per destination bone: the source joint and the rest correction.
    pub map: Vec<Option<(usize, DQuat)>>,
    root: usize,
    /// Destination hip height / source hip height (root motion scale).
    pub root_scale: f64,
    /// Source rest joint positions in mesh axes and units.
    pub source_rest: Vec<DVec3>,
}

impl Retarget {
    /// Resolves `map` (text `map_text`, from `map_file`) for `bvh` (from `bvh_file`) onto `dst`:
    /// a bone or joint the map names that does not exist is an error naming the map's line.
    pub fn new(
        map: &JointMap,
        map_file: &str,
        map_text: &str,
        bvh: &Bvh,
        bvh_file: &str,
        dst: &Skeleton,
    ) -> anyhow::Result<Retarget> {
        let axes =
            map.axes_rotation().map_err(|e| anyhow::anyhow!("{map_file}:{}: {e}", line_of(map_text, "axes").max(1)))?;
        let here = |name: &str| format!("{map_file}:{}", line_of(map_text, name));
        let mut table = vec![None; dst.bones.len()];
        for (bone, joint) in &map.bones {
            let b = dst
                .index(bone)
                .with_context(|| format!("{}: bone {bone:?} is not a bone of the destination skeleton", here(bone)))?;
            let j = bvh.index(joint).with_context(|| {
                format!("{}: joint {joint:?} (mapped to bone {bone:?}) is not a joint of {bvh_file}", here(joint))
            })?;
            table[b] = Some(j);
        }
        for bone in &map.keep_rest {
            if dst.index(bone).is_none() {
                bail!("{}: keep_rest names {bone:?}, which is not a bone of the destination skeleton", here(bone));
            }
        }
        if table.iter().all(Option::is_none) {
            bail!("{map_file}: the map connects no bone of the skeleton to a joint of {bvh_file}");
        }
        let root = match &map.root {
            Some(r) => {
                bvh.index(r).with_context(|| format!("{}: root joint {r:?} is not a joint of {bvh_file}", here(r)))?
            }
            None => 0,
        };
        let source_rest: Vec<DVec3> = bvh.rest_positions().into_iter().map(|p| axes * p * map.scale).collect();
        // Rest corrections: bone b mapped to joint j, whose first mapped descendant d is mapped
        // to joint k: turn b's rest direction (head b -> head d) onto j -> k.
        let children = |b: usize| (0..dst.bones.len()).filter(move |&c| dst.bones[c].parent == Some(b));
        let mut resolved = vec![None; dst.bones.len()];
        for b in 0..dst.bones.len() {
            let Some(j) = table[b] else { continue };
            let mut found = Vec::new();
            let mut stack: Vec<usize> = children(b).collect();
            while let Some(c) = stack.pop() {
                if table[c].is_some() {
                    found.push(c);
                } else {
                    stack.extend(children(c));
                }
            }
            // Without one mapped descendant (a hand, a fingertip, the spine's top) the bone
            // keeps the correction of its nearest mapped ancestor, so it stays in line with it.
            let mut inherited = DQuat::IDENTITY;
            let mut a = dst.bones[b].parent;
            while let Some(p) = a {
                if let Some((_, c)) = resolved[p] {
                    inherited = c;
                    break;
                }
                a = dst.bones[p].parent;
            }
            let mut correction = inherited;
            if let [d] = found[..] {
                let k = table[d].expect("found mapped");
                let to = (source_rest[k] - source_rest[j]).normalize_or_zero();
                let from = (dst.bones[d].head - dst.bones[b].head).normalize_or_zero();
                if to != DVec3::ZERO && from != DVec3::ZERO {
                    correction = DQuat::from_rotation_arc(from, to);
                }
            }
            if map.keep_rest.contains(&dst.bones[b].name) {
                correction = DQuat::IDENTITY;
            }
            resolved[b] = Some((j, correction));
        }
        let lowest = source_rest.iter().map(|p| p.y).fold(f64::INFINITY, f64::min);
        let source_height = source_rest[root].y - lowest;
        let dst_lowest = dst.bones.iter().flat_map(|b| [b.head.y, b.tail.y]).fold(f64::INFINITY, f64::min);
        let dst_root = dst.bones.iter().position(|b| b.parent.is_none()).context("the skeleton has no root")?;
        let dst_height = dst.bones[dst_root].head.y - dst_lowest;
        let root_scale = if source_height > 1e-9 && dst_height > 1e-9 { dst_height / source_height } else { 1.0 };
        Ok(Retarget { axes, map: resolved, root, root_scale, source_rest })
    }

    /// Number of destination bones driven by a source joint.
    pub fn mapped(&self) -> usize {
        self.map.iter().filter(|m| m.is_some()).count()
    }

    /// Frame position `u` (in frames) as two frames and a blend: wrapped when `looping`,
    /// else clamped.
    pub fn frames_at(bvh: &Bvh, u: f64, looping: bool) -> (usize, usize, f64) {
        let n = bvh.frames.len();
        if n == 1 {
            return (0, 0, 0.0);
        }
        if looping {
            let u = u.rem_euclid(n as f64);
            let f0 = (u.floor() as usize).min(n - 1);
            (f0, (f0 + 1) % n, u - f0 as f64)
        } else {
            let u = u.clamp(0.0, (n - 1) as f64);
            let f0 = (u.floor() as usize).min(n - 2);
            (f0, f0 + 1, u - f0 as f64)
        }
    }

    /// Global rotations of the source joints (mesh axes) and the root displacement (mesh
    /// units, before `root_scale`) at frame position `u`.
    pub fn source_globals(&self, bvh: &Bvh, u: f64, looping: bool) -> (Vec<DQuat>, DVec3) {
        let (f0, f1, a) = Retarget::frames_at(bvh, u, looping);
        let mut g: Vec<DQuat> = Vec::with_capacity(bvh.joints.len());
        for (j, joint) in bvh.joints.iter().enumerate() {
            let local = bvh.rotation(f0, j).slerp(bvh.rotation(f1, j), a);
            let local = self.axes * local * self.axes.conjugate();
            g.push(match joint.parent {
                Some(p) => (g[p] * local).normalize(),
                None => local.normalize(),
            });
        }
        let t = |f: usize| bvh.translation(f, self.root);
        let moved = t(f0).lerp(t(f1), a) - t(0);
        (g, self.axes * moved)
    }

    /// The destination pose at frame position `u` of `bvh` (the file this was resolved for).
    pub fn pose(&self, bvh: &Bvh, dst: &Skeleton, u: f64, looping: bool, scale: f64) -> Pose {
        let (source, moved) = self.source_globals(bvh, u, looping);
        let mut global: Vec<DQuat> = Vec::with_capacity(dst.bones.len());
        let mut rotations = Vec::with_capacity(dst.bones.len());
        for (b, bone) in dst.bones.iter().enumerate() {
            let parent = bone.parent.map_or(DQuat::IDENTITY, |p| global[p]);
            let g = match self.map[b] {
                Some((j, correction)) => (source[j] * correction).normalize(),
                None => parent,
            };
            rotations.push((parent.conjugate() * g).normalize());
            global.push(g);
        }
        Pose { rotations, root_offset: moved * scale * self.root_scale }
    }
}

/// A skeleton made of a BVH file's own rest pose (bones at its joints, tails at the first
/// child or end site), in mesh axes: the destination for retargeting a motion onto its own rig.
pub fn skeleton_of(bvh: &Bvh, map: &JointMap) -> anyhow::Result<Skeleton> {
    let axes = map.axes_rotation()?;
    let rest = bvh.rest_positions();
    let mut list = Vec::new();
    for (j, joint) in bvh.joints.iter().enumerate() {
        let child = bvh.joints.iter().position(|c| c.parent == Some(j));
        let tail = match (child, joint.end) {
            (Some(c), _) => rest[c],
            (None, Some(e)) => rest[j] + e,
            (None, None) => rest[j],
        };
        let parent = joint.parent.map(|p| bvh.joints[p].name.clone());
        list.push((joint.name.clone(), parent, axes * rest[j] * map.scale, axes * tail * map.scale));
    }
    Skeleton::from_unordered(list)
}

//! `Avatar`: MakeHuman's base body, skinned by its default skeleton, walking a BVH motion
//! retargeted through a joint map, optionally wearing a `.mhclo` proxy garment
//! (`crate::avatar`; docs/avatar.md).

use std::path::Path;
use std::sync::Arc;

use glam::Vec3;

use crate::avatar::bvh::Bvh;
use crate::avatar::mhclo::Proxy;
use crate::avatar::obj::{Obj, SplitMesh};
use crate::avatar::retarget::{JointMap, Retarget};
use crate::avatar::rig::{Pose, Skeleton, Skinning, Weights, skin};
use crate::avatar::{self, Body};
use crate::core::node::prelude::*;

pub static AVATAR: NodeSpec = NodeSpec {
    kind: "Avatar",
    category: Category::Geometry,
    doc: "MakeHuman's base body (helper geometry hidden), skinned by its default skeleton and weights (linear blend or dual quaternions) and posed every frame from a BVH motion, retargeted onto the skeleton through a joint map; optionally wearing a .mhclo proxy garment fitted to the posed body. In metres, feet on y = 0, facing +Z. Paths are relative to the graph's folder; the defaults are the bundled assets/avatar files.",
    inputs: &[],
    outputs: &[
        PortSpec::output(
            "surface",
            PortType::Surface,
            "The posed body (UVs are MakeHuman's texture coordinates, v down).",
        ),
        PortSpec::output(
            "collision",
            PortType::Mesh,
            "The posed body as a welded triangle mesh for cloth collisions: the same vertices and triangles every frame.",
        ),
        PortSpec::output(
            "clothes",
            PortType::Surface,
            "The .mhclo garment fitted to the posed body (the body itself when no clothes are set).",
        ),
        PortSpec::output("frame", PortType::Scalar, "The motion's frame position this frame (fractional; 0 at rest)."),
        PortSpec::output(
            "joints",
            PortType::Joints,
            "The skeleton's joints at rest, placed like the body (for the Garment node's sleeve fit).",
        ),
    ],
    params: &[
        ParamSpec::new(
            "mesh",
            ParamKind::Path { default: "../assets/avatar/makehuman-base.obj", extensions: &["obj"] },
            "The base mesh with its helper groups (helper-*, joint-*: hidden, but joints and proxies refer to them).",
        ),
        ParamSpec::new(
            "skeleton",
            ParamKind::Path { default: "../assets/avatar/default.mhskel", extensions: &["mhskel"] },
            "MakeHuman skeleton (.mhskel): bones by head and tail joints of the mesh.",
        ),
        ParamSpec::new(
            "weights",
            ParamKind::Path { default: "../assets/avatar/default_weights.mhw", extensions: &["mhw"] },
            "Skinning weights (.mhw) of the skeleton's bones for the mesh; normalized per vertex.",
        ),
        ParamSpec::new(
            "motion",
            ParamKind::Path { default: "", extensions: &["bvh"] },
            "A BVH motion; empty: the rest pose.",
        ),
        ParamSpec::new(
            "joint_map",
            ParamKind::Path { default: "", extensions: &["ron"] },
            "How the motion's joints drive the skeleton's bones (docs/avatar.md); empty: joints drive the bones of the same name, in MakeHuman's axes.",
        ),
        ParamSpec::new(
            "skinning",
            ParamKind::Choice { default: "lbs", options: SkinningKind::OPTIONS },
            "lbs: linear blend skinning; dqs: dual-quaternion skinning (keeps volume in twists and bends).",
        ),
        ParamSpec::new(
            "speed",
            ParamKind::Float { default: 1.0, min: 0.0, max: 100.0 },
            "Playback speed (1: the file's frame time).",
        ),
        ParamSpec::new("loop", ParamKind::Bool { default: true }, "Loop the motion (else hold its last frame)."),
        ParamSpec::new(
            "arm_spread",
            ParamKind::Float { default: 0.0, min: -45.0, max: 90.0 },
            "Degrees each upper arm turns away from the body on top of the motion (about the chest's forward axis). Walks recorded on slimmer bodies swing MakeHuman's arms through its torso at the armpits, which pinches a garment's underarm into the body; about 30 keeps arm and torso apart through the bundled walk (docs/garments.md).",
        ),
        ParamSpec::new(
            "start",
            ParamKind::Float { default: 0.0, min: -1e6, max: 1e6 },
            "Motion time (seconds) at frame 0 (once the rest and blend times are over).",
        ),
        ParamSpec::new(
            "rest",
            ParamKind::Float { default: 0.0, min: 0.0, max: 600.0 },
            "Seconds the body holds its rest pose before the motion (a garment is sewn and settles on it); 0: the motion from frame 0.",
        ),
        ParamSpec::new(
            "blend",
            ParamKind::Float { default: 0.5, min: 0.0, max: 60.0 },
            "After a rest time: seconds over which the body moves from the rest pose to the motion's first pose (vertex by vertex), before the motion plays.",
        ),
        ParamSpec::new(
            "units",
            ParamKind::Float { default: 0.1, min: 1e-6, max: 1e6 },
            "Metres per mesh unit (MakeHuman's are decimetres).",
        ),
        ParamSpec::new(
            "clothes",
            ParamKind::Path { default: "", extensions: &["mhclo"] },
            "A MakeHuman proxy garment (.mhclo, its .obj beside it); empty: none.",
        ),
        ParamSpec::new(
            "hide_covered",
            ParamKind::Bool { default: false },
            "Leave out of the surface the body triangles the garment's delete_verts cover (the collision mesh keeps them).",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(AvatarNode::default()),
};

crate::choice!(
    enum SkinningKind {
        Lbs = "lbs",
        Dqs = "dqs",
    }
);

/// Loaded text (skeleton and weights are resolved against the mesh they belong to).
fn load_text(path: &Path) -> anyhow::Result<String> {
    std::fs::read_to_string(path).map_err(|e| anyhow::anyhow!("cannot read {}: {e}", path.display()))
}

/// A garment's OBJ, split by UV.
fn load_garment(path: &Path) -> anyhow::Result<(Obj, SplitMesh)> {
    let obj = Obj::load(path)?;
    let split = SplitMesh::new(&obj, |_| true);
    Ok((obj, split))
}

type Key = Vec<usize>;

fn key<T>(arcs: &[&Arc<T>]) -> Key {
    arcs.iter().map(|a| Arc::as_ptr(a) as *const u8 as usize).collect()
}

#[derive(Default)]
struct AvatarNode {
    rig: Option<(Key, Arc<(Skeleton, Weights)>)>,
    retarget: Option<(Key, Arc<Retarget>)>,
    /// The rest joints, placed, and the rig and metres per unit they were placed for.
    joints: Option<((Key, u32), Arc<avatar::Joints>)>,
}

impl Node for AvatarNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let file = |cx: &EvalCx<'_>, name: &str| -> Result<std::path::PathBuf, NodeError> {
            if cx.str(name).is_empty() {
                return Err(NodeError::msg(format!("parameter \"{name}\" is empty: name a file")));
            }
            Ok(cx.path(name))
        };
        let (mesh_path, skel_path, weights_path) = (file(cx, "mesh")?, file(cx, "skeleton")?, file(cx, "weights")?);
        let body = cx.load(&mesh_path, Body::load)?;
        let skel_text = cx.load(&skel_path, load_text)?;
        let weights_text = cx.load(&weights_path, load_text)?;
        let rig_key =
            vec![Arc::as_ptr(&body) as usize, Arc::as_ptr(&skel_text) as usize, Arc::as_ptr(&weights_text) as usize];
        if self.rig.as_ref().is_none_or(|(k, _)| *k != rig_key) {
            let n = body.obj.positions.len();
            let skeleton = Skeleton::from_mhskel(&skel_text, &skel_path.display().to_string(), &body.obj.positions)
                .map_err(|e| NodeError::msg(format!("{e:#}")))?;
            let weights = Weights::from_mhw(&weights_text, &weights_path.display().to_string(), &skeleton, n)
                .map_err(|e| NodeError::msg(format!("{e:#}")))?;
            self.rig = Some((rig_key.clone(), Arc::new((skeleton, weights))));
        }
        let rig = self.rig.as_ref().expect("set above").1.clone();
        let (skeleton, weights) = (&rig.0, &rig.1);
        if weights.unweighted > 0 {
            cx.warn(format!("{} vertices have no skinning weight; they follow the root", weights.unweighted));
        }

        // The pose.
        let mut frame = 0.0;
        // 1: the motion's pose; below 1, blended with the rest pose by this weight.
        let mut towards_motion = 1.0;
        let pose = if cx.str("motion").is_empty() {
            Pose::rest(skeleton)
        } else {
            let motion_path = cx.path("motion");
            let bvh = cx.load(&motion_path, Bvh::load)?;
            let mut retarget_key = rig_key.clone();
            retarget_key.push(Arc::as_ptr(&bvh) as usize);
            let map = if cx.str("joint_map").is_empty() {
                None
            } else {
                let map_path = cx.path("joint_map");
                let map = cx.load(&map_path, JointMap::load)?;
                retarget_key.extend(key(&[&map]));
                Some((map, map_path))
            };
            if self.retarget.as_ref().is_none_or(|(k, _)| *k != retarget_key) {
                let motion_name = motion_path.display().to_string();
                let r = match &map {
                    Some((m, p)) => Retarget::new(&m.0, &p.display().to_string(), &m.1, &bvh, &motion_name, skeleton),
                    None => {
                        let m = JointMap::same_names(&bvh, skeleton);
                        Retarget::new(&m, "(joints by name)", "", &bvh, &motion_name, skeleton)
                    }
                }
                .map_err(|e| NodeError::msg(format!("{e:#}")))?;
                self.retarget = Some((retarget_key, Arc::new(r)));
            }
            let retarget = self.retarget.as_ref().expect("set above").1.clone();
            let (motion_time, weight) = rest_then_motion(cx.time().seconds(), cx.f64("rest"), cx.f64("blend"));
            towards_motion = weight;
            let seconds = cx.f64("start") + motion_time * cx.f64("speed");
            frame = seconds / bvh.frame_time;
            let mut pose = retarget.pose(&bvh, skeleton, frame, cx.bool("loop"), 1.0);
            pose.spread_arms(skeleton, cx.f64("arm_spread").to_radians());
            pose
        };
        let method = match cx.choice::<SkinningKind>("skinning") {
            SkinningKind::Lbs => Skinning::Linear,
            SkinningKind::Dqs => Skinning::DualQuaternion,
        };
        // The rest pose is the base mesh itself (the rest pose reproduces it exactly): while the
        // body rests there is nothing to skin.
        let posed = if towards_motion > 0.0 {
            let mut posed = skin(&body.obj.positions, weights, &skeleton.skinning(&pose), method);
            if towards_motion < 1.0 {
                for (p, r) in posed.iter_mut().zip(&body.obj.positions) {
                    *p = r.lerp(*p, towards_motion as f32);
                }
            }
            posed
        } else {
            body.obj.positions.clone()
        };
        let (floor, units) = (body.floor(), cx.f32("units"));
        let place = move |p: Vec3| (p - Vec3::Y * floor) * units;

        // The garment.
        let mut hidden = None;
        let clothes = if cx.str("clothes").is_empty() {
            None
        } else {
            let clo_path = cx.path("clothes");
            let proxy = cx.load(&clo_path, Proxy::load)?;
            let name = clo_path.display().to_string();
            proxy.check(body.obj.positions.len(), &name).map_err(|e| NodeError::msg(format!("{e:#}")))?;
            let obj_path = proxy.obj_file.clone().ok_or_else(|| NodeError::msg(format!("{name} names no obj_file")))?;
            let garment = cx.load(&obj_path, load_garment)?;
            if garment.0.positions.len() != proxy.bindings.len() {
                return Err(NodeError::msg(format!(
                    "{} has {} vertices but {name} binds {}",
                    obj_path.display(),
                    garment.0.positions.len(),
                    proxy.bindings.len()
                )));
            }
            if cx.bool("hide_covered") {
                let mut h = vec![false; body.obj.positions.len()];
                for v in &proxy.delete_verts {
                    if let Some(x) = h.get_mut(*v as usize) {
                        *x = true;
                    }
                }
                hidden = Some(h);
            }
            let fitted = proxy.fit(&body.obj.positions, &posed);
            let mesh = avatar::split_surface(&garment.1, &fitted, place, None)
                .map_err(|e| NodeError::msg(format!("{}: {e:#}", obj_path.display())))?;
            cx.count("garment_triangles", mesh.triangle_count());
            Some(Arc::new(mesh))
        };

        let surface = avatar::split_surface(&body.surface, &posed, place, hidden.as_deref())
            .map_err(|e| NodeError::msg(format!("the posed body: {e:#}")))?;
        let collision = avatar::collision_mesh(&body, &posed, place)
            .map_err(|e| NodeError::msg(format!("the collision body: {e:#}")))?;
        let surface = Arc::new(surface);
        cx.count("triangles", surface.triangle_count());
        cx.set("clothes", clothes.unwrap_or_else(|| surface.clone()));
        cx.set("surface", surface);
        cx.set("collision", Arc::new(collision));
        cx.set("frame", frame);
        // The rest joints change with the rig and units only, not per frame.
        let joints_key = (rig_key, units.to_bits());
        if self.joints.as_ref().is_none_or(|(k, _)| *k != joints_key) {
            let joints = avatar::Joints {
                names: skeleton.bones.iter().map(|b| b.name.clone()).collect(),
                rest: skeleton.bones.iter().map(|b| place(b.head.as_vec3())).collect(),
            };
            self.joints = Some((joints_key, Arc::new(joints)));
        }
        cx.set("joints", self.joints.as_ref().expect("set above").1.clone());
        Ok(())
    }
}

/// The motion's time (seconds from its start) and the weight of its pose against the rest pose
/// at graph time `t`: the rest pose for `rest` seconds, then a blend over `blend` seconds into
/// the motion's first pose, then the motion. Without a rest time the motion plays from 0.
fn rest_then_motion(t: f64, rest: f64, blend: f64) -> (f64, f64) {
    if rest <= 0.0 {
        return (t, 1.0);
    }
    let blended = if blend > 0.0 { ((t - rest) / blend).clamp(0.0, 1.0) } else { f64::from(t >= rest) };
    ((t - rest - blend.max(0.0)).max(0.0), blended)
}

#[cfg(test)]
mod tests {
    use super::rest_then_motion;

    #[test]
    fn the_body_rests_blends_then_moves() {
        assert_eq!(rest_then_motion(0.7, 0.0, 0.5), (0.7, 1.0));
        assert_eq!(rest_then_motion(0.5, 1.0, 0.5), (0.0, 0.0));
        assert_eq!(rest_then_motion(1.25, 1.0, 0.5), (0.0, 0.5));
        assert_eq!(rest_then_motion(2.0, 1.0, 0.5), (0.5, 1.0));
        assert_eq!(rest_then_motion(0.9, 1.0, 0.0), (0.0, 0.0));
        assert_eq!(rest_then_motion(1.0, 1.0, 0.0), (0.0, 1.0));
    }
}

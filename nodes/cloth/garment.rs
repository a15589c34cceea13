//! The `Garment` node: a sewing pattern from a file (`crate::garment`), sewn and draped by the
//! cloth simulator on an optional moving body.

use std::path::Path;
use std::sync::Arc;

use glam::DVec3;

use crate::avatar::Joints;
use crate::cloth::BodyMesh;
use crate::core::node::prelude::*;
use crate::garment::drape::{Drape, DrapeParams, DrapeState};
use crate::garment::sleeves::{ArmAxis, fit_sleeves};
use crate::garment::{Fit, Pattern, Sewn, freesewing, garmentcode};
use crate::mesh::Mesh;
use crate::warp::Placement;

pub static GARMENT: NodeSpec = NodeSpec {
    kind: "Garment",
    category: Category::Simulation,
    doc: "A garment sewn from a sewing pattern: GarmentCode v2 JSON, or a FreeSewing SVG through a RON sidecar that names its seams and places its parts (docs/garments.md). Panels are triangulated at the target edge length with equal vertex counts on stitched edges, placed in 3D, sewn by seam constraints that close over the first frames with gravity off, then draped (XPBD, 60 steps per second) against the body input, which moves every frame. UVs are the packed panel coordinates; piece ids follow the file's panel order; stitches are the Surface's seams.",
    inputs: &[
        PortSpec::optional(
            "body",
            PortType::Mesh,
            "The body to collide with (Avatar's collision output): the same vertices and triangles every frame.",
        ),
        PortSpec::optional(
            "joints",
            PortType::Joints,
            "The body's joints at rest (Avatar's joints output): sleeve panels are slid along their arms to the armholes, and one-piece sleeves (sewn to themselves) are wrapped round the whole arm, shoulder to wrist, turned back at the wrist where longer; without it they stay where the pattern places them.",
        ),
    ],
    outputs: &[
        PortSpec::output("surface", PortType::Surface, "The garment at the current time."),
        PortSpec::output("seam_gap", PortType::Scalar, "The largest distance between two sewn vertices (metres)."),
        PortSpec::output("max_strain", PortType::Scalar, "The largest edge strain this frame."),
        PortSpec::output(
            "buttons",
            PortType::Instances,
            "The pattern's button marks as placements (FreeSewing `#button` snippets; none for GarmentCode).",
        ),
    ],
    params: &[
        ParamSpec::new(
            "pattern",
            ParamKind::Path { default: "", extensions: &["json", "ron"] },
            "A GarmentCode specification (.json) or a FreeSewing sidecar (.ron, naming its SVG).",
        ),
        ParamSpec::new(
            "edge_length",
            ParamKind::Float { default: 1.0, min: 0.2, max: 20.0 },
            "Target triangle edge length (cm).",
        ),
        ParamSpec::new(
            "substeps_per_cm",
            ParamKind::Float { default: DrapeParams::SUBSTEPS_PER_CM, min: 1.0, max: 500.0 },
            "Simulator substeps per 1/60 s frame for each 1/cm of edge length, at least 20 a frame (the default gives 20 at 1 cm, 40 at 0.5 cm): finer cloth needs more to hold its stretch. More holds it closer at more cost: through a 10 s walk the 1 cm shirt's 99th-percentile edge strain reaches 10.3 % with 20 a frame, 4.7 % with 30 (1.3 times the time; set 30 here for the 5 % gate at 1 cm), 3.3 % with 40.",
        ),
        ParamSpec::new(
            "scale",
            ParamKind::Float { default: Fit::ON_MAKEHUMAN.scale.x, min: 0.01, max: 100.0 },
            "Scales the pattern's placement (not its panels) about the origin; the default fits GarmentCode's 172 cm body to MakeHuman's 166.6 cm.",
        ),
        ParamSpec::new(
            "offset",
            ParamKind::Vec3 { default: Fit::ON_MAKEHUMAN.offset.to_array() },
            "Moves the placement (cm, after scaling); the default centres GarmentCode's panels on MakeHuman's chest.",
        ),
        ParamSpec::new(
            "sewing_frames",
            ParamKind::Int { default: 30, min: 0, max: 100_000 },
            "Frames (of 1/60 s) with gravity off at the start while the seams close.",
        ),
        ParamSpec::new(
            "warmup",
            ParamKind::Float { default: 0.0, min: 0.0, max: 600.0 },
            "Seconds simulated before frame 0, against the body as it is at the first evaluated frame.",
        ),
        ParamSpec::new("self_collision", ParamKind::Bool { default: false }, "Cloth-cloth contacts (slower)."),
        ParamSpec::new(
            "untangle",
            ParamKind::Bool { default: true },
            "With self-collision: once the seams have closed, pull back cloth found through the cloth.",
        ),
        ParamSpec::new(
            "struts",
            ParamKind::Bool { default: true },
            "Keep vertices of a panel 2, 5 and 12 edges apart no farther apart than on the pattern, so the garment's weight crosses a panel in a few solver sweeps, and, once the seams are welded, the vertices an edge in from either side of a seam no farther apart than the way between them through it: the shirt's 99th-percentile edge strain at 1 cm and 20 substeps falls from 11 % to about 5 % at rest (6.6-8.0 % in the worst frame of two seconds of walking), for a few per cent more time a frame.",
        ),
        ParamSpec::new(
            "start_state",
            ParamKind::Path { default: "", extensions: &["drape"] },
            "A drape saved by `save_state` (relative to the graph's folder): the simulation starts from it at frame 0, seams closed, instead of from the flat panels. It must have been saved for the same garment (pattern, edge length, placement, sleeves), simulation settings and body vertex count; otherwise a warning says so and the garment is sewn from the start. Where the body stands at frame 0 is up to the graph: start the motion where the saving graph's was.",
        ),
        ParamSpec::new(
            "save_state",
            ParamKind::Text { default: "" },
            "Where to write the drape (relative to the graph's folder) when the simulation reaches `save_at`: a warm start for `start_state`. Render every frame up to it at 60 fps, so that the body moves between the simulator's frames (`werkstatt render GRAPH --frames 0..N --fps 60 --set garment.save_state=FILE --set garment.save_at=T`, N = 60 T). Empty: nothing is written.",
        ),
        ParamSpec::new(
            "save_at",
            ParamKind::Float { default: 0.0, min: 0.0, max: 3600.0 },
            "Graph time (s) at which `save_state` is written, rounded to the simulation's 1/60 s frames.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(GarmentNode::default()),
};

/// Reads either format by extension.
fn load_pattern(path: &Path) -> anyhow::Result<Pattern> {
    let is_ron = path.extension().is_some_and(|e| e.eq_ignore_ascii_case("ron"));
    Ok(if is_ron { freesewing::load(path)? } else { garmentcode::load(path)? })
}

#[derive(Default)]
struct GarmentNode {
    sim: Option<Simulation>,
    /// The sewn pattern, what it was sewn from, and how many sleeves were fitted.
    sewn: Option<(String, Arc<Sewn>, usize)>,
}

/// The drape being simulated.
struct Simulation {
    drape: Drape,
    /// What it was built from (rebuilt when that changes).
    built_from: String,
    /// Simulator frames since graph time 0.
    step: u64,
    /// Its [`Drape::key`], under which it saves and against which a start state is checked.
    state_key: u64,
    /// Why `start_state` was not used (warned every frame).
    start_refused: Option<String>,
}

impl Node for GarmentNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        if cx.str("pattern").is_empty() {
            return Err(NodeError::msg("parameter \"pattern\" is empty: name a .json or .ron pattern"));
        }
        let pattern = cx.load(&cx.path("pattern"), load_pattern)?;
        let o = cx.vec3("offset");
        let fit = Fit { scale: DVec3::splat(cx.f64("scale")), offset: DVec3::new(o.x as f64, o.y as f64, o.z as f64) };
        let edge = cx.f64("edge_length");
        let joints: Option<Arc<Joints>> = cx.optional("joints");
        let arms = match &joints {
            Some(j) => ArmAxis::of_joints(j).map_err(|e| NodeError::msg(format!("input \"joints\": {e:#}")))?.to_vec(),
            None => Vec::new(),
        };
        let sew_key = format!("{:p} {edge} {fit:?} {arms:?}", Arc::as_ptr(&pattern));
        if self.sewn.as_ref().is_none_or(|(k, ..)| *k != sew_key) {
            let mut sewn = pattern.sew(edge, fit).map_err(|e| NodeError::msg(e.to_string()))?;
            let fitted = fit_sleeves(&mut sewn, &arms).len();
            self.sewn = Some((sew_key.clone(), Arc::new(sewn), fitted));
        }
        let (_, sewn, fitted) = self.sewn.as_ref().expect("set above");
        let sewn = sewn.clone();
        cx.count("sleeves_fitted", *fitted);
        for w in &sewn.warnings {
            cx.warn(w.clone());
        }

        let body: Option<Arc<Mesh>> = cx.optional("body");
        let body_n = body.as_ref().map(|b| b.positions.len());
        let params = DrapeParams {
            sim: crate::cloth::SimParams {
                self_collision: cx.bool("self_collision"),
                untangle: cx.bool("untangle"),
                struts: cx.bool("struts"),
                substeps: DrapeParams::substeps_for(edge, cx.f64("substeps_per_cm")),
                ..DrapeParams::default().sim
            },
            sewing_frames: cx.int("sewing_frames") as u64,
        };
        let start: Option<Arc<DrapeState>> = match cx.str("start_state").trim() {
            "" => None,
            _ => Some(cx.load(&cx.path("start_state"), DrapeState::read)?),
        };
        let save = (!cx.str("save_state").trim().is_empty()).then(|| cx.path("save_state"));
        if save.is_some() && start.is_some() && save == Some(cx.path("start_state")) {
            // The write would reload the start and sew again, over and over.
            return Err(NodeError::msg(
                "parameters \"save_state\" and \"start_state\" name the same file: save to another one",
            ));
        }
        let key = format!("{sew_key} {body_n:?} {params:?} {:?}", start.as_ref().map(Arc::as_ptr));
        let time = cx.time();
        let target = ((cx.f64("warmup") + time.seconds()) * 60.0).round().max(0.0) as u64;
        let rebuild = self.sim.as_ref().is_none_or(|s| s.built_from != key || s.step > target);
        if rebuild {
            let body_mesh = body.as_deref().map(BodyMesh::from_mesh);
            let mut drape = Drape::new(&sewn, &params, body_mesh);
            let state_key = Drape::key(&sewn, &params, body_n);
            let mut start_refused = None;
            if let Some(start) = &start {
                if start.key == state_key {
                    drape.restore(start).map_err(|e| NodeError::msg(format!("parameter \"start_state\": {e:#}")))?;
                } else {
                    start_refused = Some(format!(
                        "start_state {}: saved for another garment, body or simulation settings ({} vertices, key {:016x}; \
                         this garment has {} vertices, key {state_key:016x}): sewing from the flat panels instead",
                        cx.str("start_state"),
                        start.cloth.positions.len(),
                        start.key,
                        sewn.positions.len()
                    ));
                }
            }
            self.sim = Some(Simulation { drape, built_from: key, step: 0, state_key, start_refused });
        }
        let sim = self.sim.as_mut().expect("built above");
        if let Some(why) = &sim.start_refused {
            cx.warn(why.clone());
        }
        let save_step = (cx.f64("save_at") * 60.0).round().max(0.0) as u64;
        let write = |sim: &Simulation| -> Result<(), NodeError> {
            match &save {
                Some(path) if sim.step == save_step => sim
                    .drape
                    .state(sim.state_key)
                    .write(path)
                    .map_err(|e| NodeError::msg(format!("parameter \"save_state\": {e:#}"))),
                _ => Ok(()),
            }
        };
        if rebuild {
            write(sim)?;
        }
        while sim.step < target {
            sim.drape.step(body.as_ref().map(|b| b.positions.as_slice()));
            sim.step += 1;
            write(sim)?;
        }
        let (drape, step) = (&sim.drape, sim.step);
        let cloth = &drape.cloth;
        if cloth.positions().iter().any(|p| !p.is_finite()) {
            return Err(NodeError::msg(format!("the simulation diverged (non-finite positions) at step {step}")));
        }
        let mesh = super::node::surface_mesh(cloth)
            .map_err(|e| NodeError::msg(format!("the garment at step {step}: {e:#}")))?;
        cx.count("triangles", mesh.triangle_count());
        if let (_, Some(self_stats)) = cloth.collision_stats() {
            // Self-contact pairs this frame, and the vertices that met more triangles than the
            // cap (a heap, a burst of speed) and kept the nearest.
            cx.count("self_pairs", self_stats.pairs);
            cx.count("self_pairs_capped_vertices", self_stats.capped);
            cx.count("self_crossings_found", self_stats.crossings);
            cx.count("self_pairs_forced_back", self_stats.forced);
        }
        cx.count("panels", sewn.piece_names.len());
        cx.count("stitches", pattern.stitches.len());
        cx.set("seam_gap", drape.max_seam_gap() as f64);
        cx.set("max_strain", cloth.max_strain() as f64);
        cx.set("surface", Arc::new(mesh));
        let buttons: Vec<Placement> = sewn
            .buttons
            .iter()
            .map(|&(piece, uv)| Placement { piece, u: uv.x, v: uv.y, angle: 0.0, scale: 1.0 })
            .collect();
        cx.count("buttons", buttons.len());
        cx.set("buttons", Arc::new(buttons));
        Ok(())
    }
}

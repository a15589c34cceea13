//! The `ClothSim` node: the built-in simulator as the pipeline's input stage.

use std::sync::{Arc, LazyLock, Mutex};

use glam::{Mat4, Quat, Vec2, Vec3};

use crate::cloth::{Cloth, Collider, FRAME_DT, FlagParams, Preset, SkirtParams, TableclothParams};
use crate::core::node::prelude::*;
use crate::mesh::Mesh;
use crate::nodes::mesh::geometry;
use crate::render::scene::{DrawItem, Material};

pub static CLOTH_SIM: NodeSpec = NodeSpec {
    kind: "ClothSim",
    category: Category::Simulation,
    doc: "Built-in deterministic cloth (XPBD, 60 steps per second of animation) from 2D pattern pieces sewn together: a tablecloth over a torus, a flag in the wind, or a four-panel skirt on a capsule body. UVs are the packed pattern coordinates.",
    inputs: &[],
    outputs: &[
        PortSpec::output("surface", PortType::Surface, "The cloth at the current time."),
        PortSpec::output("colliders", PortType::Scene, "The collision bodies, to draw them."),
        PortSpec::output("max_strain", PortType::Scalar, "The largest edge strain (stretch) this frame."),
        PortSpec::output(
            "bounds_min",
            PortType::Vector,
            "Lowest corner of the cloth's bounding box this frame (metres).",
        ),
        PortSpec::output(
            "bounds_max",
            PortType::Vector,
            "Highest corner of the cloth's bounding box this frame (metres).",
        ),
    ],
    params: &[
        ParamSpec::new(
            "preset",
            ParamKind::Choice { default: "tablecloth", options: PresetKind::OPTIONS },
            "The scene; docs/presets.md (`werkstatt nodes --presets`) gives each preset's bounds and each pattern piece's UV rectangle.",
        ),
        ParamSpec::new("triangles", ParamKind::Int { default: 4000, min: 100, max: 200_000 }, "Target triangle count."),
        ParamSpec::new(
            "seed",
            ParamKind::Int { default: 1, min: 0, max: i64::MAX },
            "Seed of the preset's randomness (wind gusts, initial jitter).",
        ),
        ParamSpec::new(
            "warmup",
            ParamKind::Float { default: 0.0, min: 0.0, max: 600.0 },
            "Seconds simulated before frame 0 (to start from a settled drape).",
        ),
        ParamSpec::new(
            "wind_speed",
            ParamKind::Float { default: 6.0, min: 0.0, max: 100.0 },
            "Mean wind speed in m/s (flag).",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(ClothSimNode::default()),
};

#[derive(Default)]
struct ClothSimNode {
    /// The running simulation, the preset it was built from, and its step count.
    state: Option<(Cloth, String, u64)>,
    colliders: Option<(String, Arc<Vec<DrawItem>>)>,
}

crate::choice!(
    enum PresetKind {
        Tablecloth = "tablecloth",
        Flag = "flag",
        Skirt = "skirt",
    }
);

impl Node for ClothSimNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let (triangles, seed) = (cx.int("triangles") as usize, cx.int("seed") as u64);
        let preset = preset_of(cx.choice::<PresetKind>("preset"), triangles, seed, cx.f32("wind_speed"));
        let key = format!("{preset:?}");
        let time = cx.time();
        let target = ((cx.f64("warmup") + time.seconds()) / FRAME_DT as f64).round().max(0.0) as u64;
        // Deterministic by construction: going back in time, or changing the preset, replays from the start.
        let rebuild = match &self.state {
            Some((_, k, step)) => *k != key || *step > target,
            None => true,
        };
        if rebuild {
            self.state = Some(match warm_state(&key, target) {
                Some((cloth, step)) => (cloth, key.clone(), step),
                None => (preset.build(), key.clone(), 0),
            });
        }
        let (cloth, _, step) = self.state.as_mut().expect("built above");
        // A long warm-up reports progress; a cancel keeps the steps made (the state stays whole).
        let first = *step;
        while *step < target {
            cx.progress((*step - first) as usize, (target - first) as usize)?;
            cloth.step_frame(FRAME_DT);
            *step += 1;
        }
        cx.count("steps_simulated", (*step - first) as usize);
        if *step - first >= WARM_KEEP_STEPS {
            keep_warm_state(&key, *step, cloth);
        }
        let mesh = surface_mesh(cloth)
            .map_err(|e| NodeError::msg(format!("the simulation produced an invalid frame at step {step}: {e:#}")))?;
        let strain = cloth.max_strain() as f64;
        if self.colliders.as_ref().is_none_or(|(k, _)| *k != key) {
            self.colliders = Some((key, Arc::new(collider_items(cloth.colliders(), cx.node_id)?)));
        }
        let (lo, hi) = mesh.bounds();
        cx.count("triangles", mesh.triangle_count());
        cx.set("bounds_min", lo);
        cx.set("bounds_max", hi);
        cx.set("surface", Arc::new(mesh));
        cx.set("colliders", self.colliders.as_ref().expect("set above").1.clone());
        cx.set("max_strain", strain);
        Ok(())
    }
}

/// States after a warm-up, shared by every ClothSim of the process: a graph rendered again
/// (a second render, the editor reopening it, a test's variant of a figure) starts from the
/// settled drape instead of simulating its `warmup` seconds again. Stepping is deterministic,
/// so the frames are the same bytes either way. A few presets' worth (each a few MB at most).
static WARM_STATES: LazyLock<Mutex<Vec<(String, u64, Cloth)>>> = LazyLock::new(Default::default);
const WARM_STATES_KEPT: usize = 8;
/// Runs shorter than this (a frame of playback) are not kept.
const WARM_KEEP_STEPS: u64 = 30;

/// The latest kept state of `key` at or before step `target`.
fn warm_state(key: &str, target: u64) -> Option<(Cloth, u64)> {
    let states = WARM_STATES.lock().unwrap_or_else(|e| e.into_inner());
    let (_, step, cloth) = states.iter().filter(|(k, s, _)| k == key && *s <= target).max_by_key(|(_, s, _)| *s)?;
    Some((cloth.clone(), *step))
}

fn keep_warm_state(key: &str, step: u64, cloth: &Cloth) {
    let mut states = WARM_STATES.lock().unwrap_or_else(|e| e.into_inner());
    if states.iter().any(|(k, s, _)| k == key && *s == step) {
        return;
    }
    if states.len() >= WARM_STATES_KEPT {
        states.remove(0);
    }
    states.push((key.to_string(), step, cloth.clone()));
}

fn preset_of(kind: PresetKind, triangles: usize, seed: u64, wind_speed: f32) -> Preset {
    match kind {
        PresetKind::Flag => Preset::Flag(FlagParams { triangles, seed, wind_speed }),
        PresetKind::Skirt => Preset::Skirt(SkirtParams { triangles, seed, ..Default::default() }),
        PresetKind::Tablecloth => Preset::Tablecloth(TableclothParams { triangles, seed, ..Default::default() }),
    }
}

/// The cloth's current state as a Surface mesh (pieces and seams from its pattern).
pub(super) fn surface_mesh(cloth: &Cloth) -> anyhow::Result<Mesh> {
    let frame = cloth.surface();
    let v3 = |a: &[[f32; 3]]| a.iter().map(|p| Vec3::from_array(*p)).collect::<Vec<_>>();
    let mut mesh = Mesh::from_parts(
        v3(&frame.positions),
        Some(v3(&frame.normals)),
        frame.uvs.iter().map(|t| Vec2::from_array(*t)).collect(),
        frame.indices,
        frame.piece_ids,
    )?;
    mesh.seams = cloth.pattern().seam_pairs().to_vec();
    Ok(mesh)
}

/// docs/presets.md: where each preset is at frame 0 with the node's default parameters, and
/// the UV rectangle of each pattern piece (which simulation never changes), so placements and
/// cameras can be set up from the docs alone.
pub fn presets_markdown() -> anyhow::Result<String> {
    use std::fmt::Write as _;
    let default_of = |name: &str| match CLOTH_SIM.param(name).map(|(_, p)| &p.kind) {
        Some(ParamKind::Int { default, .. }) => *default as f64,
        Some(ParamKind::Float { default, .. }) => *default,
        _ => 0.0,
    };
    let (triangles, seed, wind) =
        (default_of("triangles") as usize, default_of("seed") as u64, default_of("wind_speed"));
    let mut out = String::from(
        "# ClothSim presets\n\nGenerated by `werkstatt nodes --presets` from the presets themselves; do not edit by hand \
         (a test fails when this file is out of date). Bounds are at frame 0 with the node's default parameters \
         (`warmup` 0, so the rest pose; the cloth moves from there, `bounds_min`/`bounds_max` give them per frame). \
         UV rectangles never change; v points down. A placement outside every piece is dropped with a warning.\n",
    );
    for (i, name) in PresetKind::OPTIONS.iter().enumerate() {
        let kind = PresetKind::from_index(i).expect("an index of OPTIONS");
        let mesh = surface_mesh(&preset_of(kind, triangles, seed, wind as f32).build())?;
        let (lo, hi) = mesh.bounds();
        let v = |p: Vec3| format!("({:.2}, {:.2}, {:.2})", p.x, p.y, p.z);
        let _ = write!(
            out,
            "\n## `{name}`\n\nBounds (metres): {} to {}, centre {}.\n\n| piece | u | v |\n|---:|---|---|\n",
            v(lo),
            v(hi),
            v((lo + hi) * 0.5)
        );
        for (piece, a, b) in mesh.piece_uv_rects() {
            let _ = writeln!(out, "| {piece} | {:.3} - {:.3} | {:.3} - {:.3} |", a.x, b.x, a.y, b.y);
        }
    }
    Ok(out)
}

/// Drawable stand-ins for the colliders (a capsule as a cylinder with two spheres).
fn collider_items(colliders: &[Collider], node_id: &str) -> anyhow::Result<Vec<DrawItem>> {
    let material = Arc::new(Material { base_color: Vec3::new(0.55, 0.55, 0.6), glossiness: 0.3, ..Default::default() });
    let name: Arc<str> = format!("{node_id}_collider").into();
    let item = |mesh: Mesh, model: Mat4| DrawItem::plain(Arc::new(mesh), material.clone(), model).named(name.clone());
    let mut items = Vec::new();
    for c in colliders {
        match c {
            Collider::Sphere { center, radius } => {
                items.push(item(geometry::sphere(*radius, 48, 24)?, Mat4::from_translation(*center)));
            }
            Collider::Capsule { a, b, radius } => {
                let axis = *b - *a;
                let rotation = Quat::from_rotation_arc(Vec3::Y, axis.normalize_or(Vec3::Y));
                let model = Mat4::from_rotation_translation(rotation, (*a + *b) * 0.5);
                items.push(item(geometry::cylinder(*radius, axis.length().max(1e-6), 32, 1)?, model));
                for end in [a, b] {
                    items.push(item(geometry::sphere(*radius, 32, 16)?, Mat4::from_translation(*end)));
                }
            }
            Collider::Box { center, half_extents, rotation } => {
                let model = Mat4::from_scale_rotation_translation(*half_extents * 2.0, *rotation, *center);
                items.push(item(geometry::cube(1.0)?, model));
            }
            Collider::Torus { center, axis, major_radius, minor_radius } => {
                let rotation = Quat::from_rotation_arc(Vec3::Y, axis.normalize_or(Vec3::Y));
                let model = Mat4::from_rotation_translation(rotation, *center);
                items.push(item(geometry::torus(*major_radius, *minor_radius, 96, 32)?, model));
            }
            Collider::Mesh(m) => {
                let indices = m.triangles().iter().flatten().copied().collect();
                items.push(item(Mesh::build(m.positions().to_vec(), None, None, indices)?, Mat4::IDENTITY));
            }
        }
    }
    Ok(items)
}

//! `werkstatt bench editor`: how fast the editor's viewport answers on a graph, measured through
//! the evaluation the window drives ([`Live`]), headless: the first frame, the first loop of
//! the timeline (simulated and rendered frame by frame), its replay from the kept pictures, and
//! turning the view (at half size while it turns, at the full size at rest).

use std::path::Path;
use std::sync::Arc;
use std::time::{Duration, Instant};

use anyhow::{Context, bail};

use super::bench::{MarkdownRow, median, ms_since};
use crate::app::editor::live::{CameraOverride, Live, NodeState, camera_for};
use crate::core::graph::Graph;
use crate::gpu::GpuContext;

/// The longest any one step may take before the bench gives up.
const STEP_DEADLINE: Duration = Duration::from_secs(300);

/// The mouse drag (points) of each turn of the view: 8 degrees of yaw.
const ORBIT_DRAG_POINTS: f32 = 20.0;

/// One phase of `werkstatt bench editor`.
#[derive(Debug, serde::Serialize)]
pub struct EditorRow {
    pub phase: &'static str,
    /// The size of the pictures the viewport showed.
    pub width: u32,
    pub height: u32,
    pub samples: usize,
    /// Evaluations the phase took: none where the viewport showed kept pictures.
    pub evaluations: u64,
    pub median_ms: f64,
    pub max_ms: f64,
    /// Pictures a second at the median.
    pub fps: f64,
}

/// What one phase measured: each step's milliseconds, the evaluations they took, and the size
/// of the pictures shown.
struct Measured {
    ms: Vec<f64>,
    evaluations: u64,
    size: (u32, u32),
}

impl EditorRow {
    fn new(phase: &'static str, Measured { ms, evaluations, size: (width, height) }: Measured) -> Self {
        let (samples, max_ms) = (ms.len(), ms.iter().copied().fold(0.0, f64::max));
        let median_ms = median(ms);
        EditorRow { phase, width, height, samples, evaluations, median_ms, max_ms, fps: 1e3 / median_ms }
    }
}

impl MarkdownRow for EditorRow {
    const HEADER: &'static str =
        "| phase | size | samples | evaluations | median ms | max ms | fps |\n|---|---|---:|---:|---:|---:|---:|";
    fn markdown(&self) -> String {
        format!(
            "| {} | {}x{} | {} | {} | {:.1} | {:.1} | {:.1} |",
            self.phase, self.width, self.height, self.samples, self.evaluations, self.median_ms, self.max_ms, self.fps
        )
    }
}

/// Measures the editor's viewport on the graph at `path` at `size`: the timeline's frames
/// `0..frames` (at least 2) and `orbit_steps` turns of the view (at least 1) each way.
pub fn editor(
    gpu: &Arc<GpuContext>,
    path: &Path,
    size: (u32, u32),
    frames: i64,
    orbit_steps: usize,
) -> anyhow::Result<Vec<EditorRow>> {
    if frames < 2 || orbit_steps == 0 {
        bail!("--frames must be at least 2 and --orbit-steps at least 1");
    }
    let graph = Graph::load(path)?;
    let camera_node = camera_for(&graph, None)
        .with_context(|| format!("{}: no orbit camera (OrbitCamera) for the viewport to turn", path.display()))?;
    let mut camera = CameraOverride::from_graph(&graph, &camera_node)
        .with_context(|| format!("{}: camera \"{camera_node}\" lacks yaw, pitch or distance", path.display()))?;
    let base_dir = path.parent().map_or_else(|| Path::new(".").to_path_buf(), Path::to_path_buf);
    let mut live = Live::new(base_dir, false);
    live.set_size(size.0, size.1);
    live.frame = 0;
    live.sync(&graph, 1, None);

    let start = Instant::now();
    settle(&mut live, gpu, &graph, "the first frame")?;
    let first = Measured { ms: vec![ms_since(start)], evaluations: live.finished, size };

    // The timeline's first loop: every frame evaluated (a simulation steps through each).
    live.playing = true;
    let first_loop = play(&mut live, gpu, &graph, 1..frames)?;
    // The loop again: the pictures kept from the first (none where a node reads another program).
    let replay = play(&mut live, gpu, &graph, 0..frames)?;
    live.playing = false;
    live.frame = 0;
    settle(&mut live, gpu, &graph, "frame 0 again")?;

    let mut orbit = |live: &mut Live, navigating: bool| -> anyhow::Result<Measured> {
        live.navigating = navigating;
        let mut ms = Vec::new();
        let mut evaluations = 0;
        // One turn more than measured: the first at a new size also makes its textures.
        for step in 0..=orbit_steps {
            camera.orbit(ORBIT_DRAG_POINTS, 0.0);
            live.camera = Some(camera.clone());
            live.sync(&graph, 1, None);
            let (t, before) = (Instant::now(), live.finished);
            settle(live, gpu, &graph, "a turn of the view")?;
            if step > 0 {
                ms.push(ms_since(t));
                evaluations += live.finished - before;
            }
        }
        Ok(Measured { ms, evaluations, size: shown_size(live).unwrap_or_default() })
    };
    let turning = orbit(&mut live, true)?;
    let resting = orbit(&mut live, false)?;

    Ok(vec![
        EditorRow::new("first frame (everything runs)", first),
        EditorRow::new("first loop (each frame evaluated)", first_loop),
        EditorRow::new("replay (kept pictures)", replay),
        EditorRow::new("turning the view (half size)", turning),
        EditorRow::new("turned view at rest (full size)", resting),
    ])
}

/// Shows the timeline's `frames` one after the other as playback does: each frame's time and
/// the evaluations they took.
fn play(
    live: &mut Live,
    gpu: &Arc<GpuContext>,
    graph: &Graph,
    frames: std::ops::Range<i64>,
) -> anyhow::Result<Measured> {
    let (mut ms, before) = (Vec::new(), live.finished);
    for f in frames {
        live.frame = f;
        let t = Instant::now();
        show(live, gpu, graph, f)?;
        ms.push(ms_since(t));
    }
    let size = shown_size(live).unwrap_or_default();
    Ok(Measured { ms, evaluations: live.finished - before, size })
}

/// The size of the viewport's picture.
fn shown_size(live: &Live) -> Option<(u32, u32)> {
    let [w, h] = live.display()?.pixels.as_ref()?.size;
    Some((w as u32, h as u32))
}

/// Pumps until the evaluation is done, then fails on a node that failed.
fn settle(live: &mut Live, gpu: &Arc<GpuContext>, graph: &Graph, what: &str) -> anyhow::Result<()> {
    if !live.wait_idle(Some(gpu), STEP_DEADLINE) {
        bail!("{what} was not evaluated within {} s", STEP_DEADLINE.as_secs());
    }
    failed_node(live, graph)
}

/// Pumps until the viewport shows frame `f` and nothing is evaluating.
fn show(live: &mut Live, gpu: &Arc<GpuContext>, graph: &Graph, f: i64) -> anyhow::Result<()> {
    let deadline = Instant::now() + STEP_DEADLINE;
    loop {
        live.pump(Some(gpu));
        if live.shown_frame() == Some(f) && live.busy().is_none() {
            return failed_node(live, graph);
        }
        if Instant::now() >= deadline {
            bail!("frame {f} was not shown within {} s", STEP_DEADLINE.as_secs());
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

fn failed_node(live: &Live, graph: &Graph) -> anyhow::Result<()> {
    for id in graph.nodes.keys() {
        if let NodeState::Failed(why) = live.state(id) {
            bail!("node \"{id}\" failed: {why}");
        }
    }
    Ok(())
}

//! Live evaluation inside the editor: the document is turned into a graph that can run
//! (nodes with problems, or with changes past the cost limits, are left out and their
//! problems shown on them), and a worker thread evaluates it, so the window never waits for
//! the graph. The evaluator is updated after each edit so only what changed re-runs; a newer
//! edit cancels a running evaluation at the next node boundary (long nodes check inside their
//! loops); the UI shows the last finished evaluation, and the progress of the running one.
//! Shader files reload when `WERKSTATT_SHADER_DIR` is set. No drawing here.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, Sender, channel};
use std::time::{Duration, Instant, SystemTime};

use super::cost::{self, Estimate};
use crate::core::eval::{Cancelled, Evaluator, FrameSettings, FrameSummary, FrameTime, NodeStatus};
use crate::core::graph::{Graph, Place, PortRef, ProblemKind};
use crate::core::node::Capabilities;
use crate::core::param::ParamValue;
use crate::core::port::Value;
use crate::core::progress::Progress;
use crate::core::resources::Resources;
use crate::core::spec;
use crate::gpu::{FullscreenPass, GpuContext, GpuImage, TextureDesc};

/// What a node shows on the canvas.
#[derive(Clone, Debug, PartialEq)]
pub enum NodeState {
    /// Not needed by any output (or not evaluated yet).
    Idle,
    Ok,
    /// Waiting for a file to load.
    Pending(String),
    Failed(String),
    /// An input has no value because its source failed or waits.
    Blocked(String),
}

impl NodeState {
    pub fn message(&self) -> Option<&str> {
        match self {
            NodeState::Idle | NodeState::Ok => None,
            NodeState::Pending(m) | NodeState::Failed(m) | NodeState::Blocked(m) => Some(m),
        }
    }
}

/// Why a node of the document was left out of the graph that runs.
#[derive(Clone, Debug, PartialEq)]
pub struct StaticError {
    pub message: String,
    /// The node itself is fine, but an input it needs comes from a node that is left out.
    pub blocked: bool,
}

/// The part of `graph` that can run, and the reason for each node left out: nodes with
/// problems (unknown kind, bad parameter, unconnected required input, ...) are removed
/// together with what depends on them, and bad links are dropped.
pub fn runnable(graph: &Graph) -> (Graph, BTreeMap<String, StaticError>) {
    let mut g = graph.clone();
    let mut errors: BTreeMap<String, StaticError> = BTreeMap::new();
    for _ in 0..graph.nodes.len() + graph.links.len() + 2 {
        let problems = g.validate();
        if problems.is_empty() {
            break;
        }
        let mut drop_nodes = BTreeSet::new();
        let mut drop_links = BTreeSet::new();
        for p in problems {
            match (&p.place, &p.kind) {
                (Place::Link(i), _) => {
                    drop_links.insert(*i);
                    if let Some(l) = g.links.get(*i) {
                        errors
                            .entry(l.to.node.clone())
                            .or_insert(StaticError { message: p.message.clone(), blocked: false });
                    }
                }
                (_, ProblemKind::MissingInput) => {
                    let (Some(node), Some(port)) = (p.node.clone(), p.port.clone()) else { continue };
                    // Linked in the document, so its source was left out: this node is blocked.
                    let source = graph.links.iter().find(|l| l.to.node == node && l.to.port == port);
                    let e = match source {
                        Some(l) => StaticError {
                            message: format!("input \"{port}\" waits for \"{}\", which cannot run", l.from.node),
                            blocked: true,
                        },
                        None => StaticError { message: p.message.clone(), blocked: false },
                    };
                    errors.entry(node.clone()).or_insert(e);
                    drop_nodes.insert(node);
                }
                _ => {
                    if let Some(node) = p.node.clone() {
                        errors
                            .entry(node.clone())
                            .or_insert(StaticError { message: p.message.clone(), blocked: false });
                        drop_nodes.insert(node);
                    }
                }
            }
        }
        if drop_nodes.is_empty() && drop_links.is_empty() {
            break;
        }
        let mut i = 0;
        g.links.retain(|_| {
            i += 1;
            !drop_links.contains(&(i - 1))
        });
        crate::app::editor::document::remove_nodes(&mut g, &drop_nodes);
    }
    (g, errors)
}

/// The viewport's orbit controls, applied over the graph's OrbitCamera parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct CameraOverride {
    pub node: String,
    pub yaw: f64,
    pub pitch: f64,
    pub distance: f64,
}

impl CameraOverride {
    /// Starts from the camera's current parameters.
    pub fn from_graph(graph: &Graph, node: &str) -> Option<CameraOverride> {
        let f = |name: &str| graph.param(node, name).and_then(|v| v.as_f64());
        Some(CameraOverride { node: node.into(), yaw: f("yaw")?, pitch: f("pitch")?, distance: f("distance")? })
    }

    /// Turns by a mouse drag in points.
    pub fn orbit(&mut self, dx: f32, dy: f32) {
        self.yaw = (self.yaw - dx as f64 * 0.4).rem_euclid(360.0);
        self.pitch = (self.pitch + dy as f64 * 0.4).clamp(-89.0, 89.0);
    }

    /// Zooms by wheel steps (positive = closer).
    pub fn zoom(&mut self, steps: f32) {
        self.distance = (self.distance * (-steps as f64 * 0.1).exp()).clamp(1e-3, 1e5);
    }

    fn apply(&self, g: &mut Graph) {
        if is_orbit_camera(g, &self.node) {
            for (name, v) in [("yaw", self.yaw), ("pitch", self.pitch), ("distance", self.distance)] {
                let _ = crate::app::editor::document::set_param(g, &self.node, name, ParamValue::Float(v));
            }
        }
    }
}

/// Whether node `id` is a camera the viewport orbits ([`Capabilities::ORBIT_CAMERA`]).
fn is_orbit_camera(graph: &Graph, id: &str) -> bool {
    graph.nodes.get(id).and_then(|n| spec::find(&n.kind)).is_some_and(|s| s.has(Capabilities::ORBIT_CAMERA))
}

/// The orbit camera ([`Capabilities::ORBIT_CAMERA`]) that feeds `node` (the viewed one), else
/// the first in the graph.
pub fn camera_for(graph: &Graph, node: Option<&str>) -> Option<String> {
    let is_cam = |id: &str| is_orbit_camera(graph, id);
    if let Some(start) = node {
        let mut stack = vec![start.to_string()];
        let mut seen = BTreeSet::new();
        while let Some(n) = stack.pop() {
            if is_cam(&n) {
                return Some(n);
            }
            if seen.insert(n.clone()) {
                stack.extend(graph.links.iter().filter(|l| l.to.node == n).map(|l| l.from.node.clone()));
            }
        }
    }
    graph.nodes.keys().find(|id| is_cam(id)).cloned()
}

/// The port the viewport shows: the inspected port, else the first preview node's image
/// ([`Capabilities::PREVIEW`]),
/// else the first output node with a texture output, else the first output node's value
/// (a Watch), shown as text.
pub fn viewed_port(graph: &Graph, inspected: Option<&PortRef>) -> Option<PortRef> {
    if let Some(p) = inspected {
        return Some(p.clone());
    }
    let texture_out =
        |kind: &str| spec::find(kind).and_then(|s| s.outputs.iter().find(|p| p.ty.viewable())).map(|p| p.name);
    let pick = |want_preview: bool| {
        graph.nodes.iter().find_map(|(id, n)| {
            let s = spec::find(&n.kind)?;
            let ok = if want_preview { s.has(Capabilities::PREVIEW) } else { s.is_output() };
            if !ok {
                return None;
            }
            texture_out(&n.kind).map(|port| PortRef { node: id.clone(), port: port.into() })
        })
    };
    pick(true).or_else(|| pick(false)).or_else(|| {
        graph.nodes.iter().find_map(|(id, n)| {
            let s = spec::find(&n.kind).filter(|s| s.is_output())?;
            s.outputs.first().map(|p| PortRef { node: id.clone(), port: p.name.into() })
        })
    })
}

struct ShaderWatch {
    dir: PathBuf,
    stamps: BTreeMap<PathBuf, (SystemTime, u64)>,
    last_poll: Instant,
}

impl ShaderWatch {
    fn new(dir: PathBuf) -> Self {
        let mut w = ShaderWatch { dir, stamps: BTreeMap::new(), last_poll: Instant::now() };
        w.stamps = w.scan();
        w
    }

    fn scan(&self) -> BTreeMap<PathBuf, (SystemTime, u64)> {
        // The shaders' folder and the family folders in it (render/, warp/, ...).
        let folders = std::fs::read_dir(&self.dir).into_iter().flatten().flatten().map(|e| e.path());
        std::iter::once(self.dir.clone())
            .chain(folders.filter(|p| p.is_dir()))
            .flat_map(|d| std::fs::read_dir(d).into_iter().flatten().flatten())
            .filter(|e| e.path().extension().is_some_and(|x| x == "wgsl"))
            .filter_map(|e| {
                let m = e.metadata().ok()?;
                Some((e.path(), (m.modified().ok()?, m.len())))
            })
            .collect()
    }

    /// Whether a shader file changed since the last poll (checked twice a second).
    fn changed(&mut self) -> bool {
        if self.last_poll.elapsed() < Duration::from_millis(500) {
            return false;
        }
        self.last_poll = Instant::now();
        let now = self.scan();
        let changed = now != self.stamps;
        self.stamps = now;
        changed
    }
}

/// The viewport's display conversion: a full-screen pass over shaders/render/display.wgsl,
/// run by the worker after each evaluation (so the UI thread records no GPU work).
struct Converter {
    pass: FullscreenPass,
}

/// The format egui samples.
const DISPLAY_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

impl Converter {
    fn new() -> Converter {
        Converter { pass: FullscreenPass::new("display.wgsl") }
    }

    /// The display mode for a source format, or why it cannot be shown.
    fn mode(image: &GpuImage) -> Result<u32, String> {
        use wgpu::TextureFormat as F;
        if !image.texture.usage().contains(wgpu::TextureUsages::TEXTURE_BINDING) {
            return Err("this texture cannot be sampled, so it cannot be shown".into());
        }
        match image.format {
            F::Rgba8Unorm | F::Bgra8Unorm => Ok(1),
            F::R32Float | F::R16Float => Ok(2),
            f if matches!(f.sample_type(None, None), Some(wgpu::TextureSampleType::Float { .. })) => Ok(0),
            f => Err(format!("textures of format {f:?} cannot be shown")),
        }
    }

    /// `src` converted to gamma-encoded Rgba8Unorm in a pooled texture, submitted.
    fn convert(&mut self, gpu: &GpuContext, src: &GpuImage) -> Result<GpuImage, String> {
        let mode = Converter::mode(src)?;
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        let dst = gpu.acquire("viewport", TextureDesc::d2(src.width, src.height, DISPLAY_FORMAT, usage));
        gpu.checked("viewport display", || {
            let r = self.pass.run(gpu, bytemuck::cast_slice(&[mode, 0u32, 0, 0]), &[src], &dst);
            gpu.flush();
            r
        })
        .and_then(|r| r)
        .map_err(|e| format!("{e:#}"))?;
        Ok(dst)
    }
}

/// The viewport's picture from the last finished evaluation.
pub struct Display {
    /// The port it shows.
    pub port: PortRef,
    /// The picture, converted for display on the engine's device; `None` with `error` when it
    /// cannot be shown.
    pub image: Option<GpuImage>,
    /// The same picture on the CPU (gamma-encoded RGBA8, rows top down), for the window,
    /// whose device is not the engine's.
    pub pixels: Option<egui::ColorImage>,
    pub error: Option<String>,
    /// Counts finished evaluations, so the viewport registers each new picture once.
    pub stamp: u64,
}

impl Display {
    /// The picture without its GPU image: what playback keeps and shows again.
    fn cpu_copy(&self) -> Display {
        let (port, pixels, error) = (self.port.clone(), self.pixels.clone(), self.error.clone());
        Display { port, image: None, pixels, error, stamp: self.stamp }
    }
}

/// What the UI shows of one node, from the last finished evaluation.
#[derive(Clone, Debug)]
struct NodeShot {
    state: NodeState,
    warnings: Vec<String>,
    /// The CPU time of its latest run (kept across evaluations it skipped), and whether it ran
    /// in the last one.
    cpu: Option<Duration>,
    ran: bool,
    runs: u64,
}

/// A port's value as the UI sees it: a summary always; the value itself where it is plain data
/// or the viewed port. GPU values of other ports are not held, so that the evaluator's pools
/// reuse their textures while the next evaluation runs.
struct PortShot {
    summary: String,
    value: Option<Value>,
}

/// A finished evaluation, as the worker hands it to the UI.
#[derive(Default)]
struct Snapshot {
    nodes: HashMap<String, NodeShot>,
    outputs: HashMap<PortRef, PortShot>,
    inputs: HashMap<PortRef, PortShot>,
    summary: FrameSummary,
    eval: Duration,
    shader_error: Option<String>,
    display: Option<Display>,
}

/// What the worker is asked to evaluate. Requests that pile up while it is busy are merged.
struct Request {
    generation: u64,
    /// The runnable graph and extra roots, when they changed since the last request.
    graph: Option<(Arc<Graph>, Vec<String>)>,
    time: FrameTime,
    settings: FrameSettings,
    viewed: Option<PortRef>,
    /// Forget the evaluator (a new document or folder) / every cache (a new size).
    reset: bool,
    invalidate: bool,
    reload_shaders: bool,
    /// An edit: afterwards give back pooled memory nothing uses any more.
    edit: bool,
    progress: Progress,
}

impl Request {
    /// `self` followed by `next`: the newest state, with what the older asked for kept.
    fn merge(self, next: Request) -> Request {
        Request {
            graph: next.graph.or(self.graph),
            reset: self.reset || next.reset,
            invalidate: self.invalidate || next.invalidate,
            reload_shaders: self.reload_shaders || next.reload_shaders,
            edit: self.edit || next.edit,
            ..next
        }
    }
}

/// The worker's answer to a request.
struct Finished {
    generation: u64,
    /// `None` when cancelled: the UI keeps showing the evaluation before.
    snapshot: Option<Snapshot>,
    cancelled: Option<Cancelled>,
    engine_error: Option<String>,
}

/// Calls the UI back when an evaluation finished (egui's `request_repaint`).
pub type Waker = Arc<dyn Fn() + Send + Sync>;

struct Worker {
    requests: Option<Sender<Request>>,
    finished: Receiver<Finished>,
    exited: Receiver<()>,
}

impl Drop for Worker {
    fn drop(&mut self) {
        // Closing the channel ends the worker after its evaluation (cancelled by `Live`'s drop);
        // wait a little so it does not outlive the window by much.
        self.requests = None;
        let _ = self.exited.recv_timeout(Duration::from_secs(2));
    }
}

/// The evaluation that runs now.
struct InFlight {
    generation: u64,
    progress: Progress,
    started: Instant,
    /// When it was cancelled, to measure how long the worker took to stop.
    cancelled_at: Option<Instant>,
    /// What it evaluates (see `Live::wanted`).
    wanted: Wanted,
}

/// What an evaluation is of: the runnable graph's version, the time, the size, the viewed port.
#[derive(Clone, Debug, PartialEq)]
struct Wanted {
    graph: u64,
    time: (i64, u64),
    size: (u32, u32),
    viewed: Option<PortRef>,
}

/// How long a value held by a pointer gesture (a slider drag) must stay unchanged before it is
/// evaluated; releasing the pointer evaluates at once.
pub const SETTLE: Duration = Duration::from_millis(250);

/// The progress of the running evaluation, for the viewport and the canvas.
#[derive(Clone, Debug)]
pub struct Busy {
    pub node: Option<Arc<str>>,
    pub fraction: f32,
    pub elapsed: Duration,
    /// Cancelled, waiting for the worker to stop.
    pub cancelling: bool,
}

/// The evaluation behind the editor's canvas and viewport.
pub struct Live {
    pub resources: Arc<Resources>,
    pub settings: FrameSettings,
    pub frame: i64,
    pub fps: f64,
    pub playing: bool,
    /// Inclusive range of the frame slider.
    pub frame_range: (i64, i64),
    play_clock: f64,
    pub camera: Option<CameraOverride>,
    static_errors: BTreeMap<String, StaticError>,
    /// Cost estimates of the document's nodes (see [`cost`]), and the refused ones.
    pub estimates: BTreeMap<String, Estimate>,
    pub refused: BTreeMap<String, String>,
    runnable: Arc<Graph>,
    extra_roots: Vec<String>,
    /// The port the viewport shows (see [`viewed_port`]).
    viewed: Option<PortRef>,
    synced: Option<(u64, Option<PortRef>, Option<CameraOverride>)>,
    /// Bumped whenever `runnable` or `extra_roots` change; `sent_graph` is the one the worker has.
    graph_version: u64,
    sent_graph: u64,
    /// When the graph last changed while a pointer gesture held it.
    held_since: Option<Instant>,
    /// Whether a pointer gesture (a drag) is going on: set by the window every frame.
    pub gesture: bool,
    /// Whether the view is being turned or zoomed: set by the viewport every frame. Meanwhile
    /// frames are evaluated at half the width and height ([`NAVIGATION_SCALE`]), and at the full
    /// size once it stops.
    pub navigating: bool,
    reset_pending: bool,
    invalidate_pending: bool,
    reload_pending: bool,
    edit_pending: bool,
    worker: Option<Worker>,
    waker: Option<Waker>,
    in_flight: Option<InFlight>,
    next_generation: u64,
    /// What the last request asked for, and when it was sent.
    sent: Option<(Wanted, Instant)>,
    /// A cancel by the user: nothing is evaluated again until something changes.
    user_cancelled: Option<Wanted>,
    snapshot: Snapshot,
    /// Finished evaluations so far.
    pub finished: u64,
    pub last_summary: FrameSummary,
    /// Wall time of the last finished evaluation.
    pub last_eval: Duration,
    /// How long the last cancel took to stop the worker.
    pub last_cancel: Option<(Cancelled, Duration)>,
    /// Whether the next frame may differ without any input (playing, evaluating, files loading).
    pub animating: bool,
    shaders: Option<ShaderWatch>,
    /// The compile error of the last shader reload, while the old pipelines are kept.
    pub shader_error: Option<String>,
    /// An error building the evaluator (should not happen: the graph is made runnable first).
    pub engine_error: Option<String>,
    /// Pictures of the frames played so far, shown again on the next loop without evaluating.
    played: PlayCache,
    /// The kept picture shown now (see `played`), until the next evaluation finishes.
    cached_shown: Option<Display>,
    /// Whether played frames may be kept: no node takes values from another program.
    cacheable: bool,
    /// The frame whose picture the viewport shows (evaluated or from `played`).
    shown_frame: Option<i64>,
}

/// Pictures of played frames for one graph version, size, view and frame rate: playback shows
/// them again instead of evaluating, so a loop plays at its frame rate once it has been
/// evaluated. Only the CPU pixels are kept, up to [`PLAY_CACHE_BYTES`].
#[derive(Default)]
struct PlayCache {
    key: Option<PlayKey>,
    frames: BTreeMap<i64, Display>,
    bytes: usize,
}

/// What kept pictures are of: the graph version, size, viewed port and frame rate of [`Wanted`].
type PlayKey = (u64, (u32, u32), Option<PortRef>, u64);

/// The most bytes of kept playback pictures: 139 frames at 800x600, and every frame of the
/// editor's default 240 at its default 480x360.
pub const PLAY_CACHE_BYTES: usize = 256 << 20;

impl PlayCache {
    fn key_of(w: &Wanted) -> PlayKey {
        (w.graph, w.size, w.viewed.clone(), w.time.1)
    }

    fn get(&self, w: &Wanted) -> Option<&Display> {
        if self.key.as_ref() != Some(&Self::key_of(w)) {
            return None;
        }
        self.frames.get(&w.time.0)
    }

    fn clear(&mut self) {
        *self = PlayCache::default();
    }

    /// Keeps the picture of frame `w`, forgetting pictures of another graph, size or view.
    fn keep(&mut self, w: &Wanted, display: &Display) {
        let Some(pixels) = &display.pixels else { return };
        let key = Self::key_of(w);
        if self.key.as_ref() != Some(&key) {
            self.clear();
            self.key = Some(key);
        }
        let bytes = pixels.pixels.len() * 4;
        if self.bytes + bytes > PLAY_CACHE_BYTES || self.frames.contains_key(&w.time.0) {
            return;
        }
        self.bytes += bytes;
        self.frames.insert(w.time.0, display.cpu_copy());
    }
}

/// How much smaller frames are while the view moves (see [`Live::navigating`]): only the nodes
/// that read the frame size re-run for it (the G-buffer and what it feeds), so each step of an
/// orbit costs about a quarter of the screen-space passes.
pub const NAVIGATION_SCALE: u32 = 2;

/// The play range the editor starts with; a turntable camera turns once over it.
const DEFAULT_FRAME_RANGE: (i64, i64) = (0, 239);

/// Re-evaluates this often while nothing changed, to pick up loaded or reloaded files.
const POLL: Duration = Duration::from_millis(500);

impl Live {
    pub fn new(base_dir: PathBuf, watch_files: bool) -> Self {
        Live {
            resources: Arc::new(Resources::new(watch_files)),
            settings: FrameSettings { width: 480, height: 360, base_dir, frames: Some(DEFAULT_FRAME_RANGE) },
            frame: 0,
            fps: 30.0,
            playing: false,
            frame_range: DEFAULT_FRAME_RANGE,
            play_clock: 0.0,
            camera: None,
            static_errors: BTreeMap::new(),
            estimates: BTreeMap::new(),
            refused: BTreeMap::new(),
            runnable: Arc::new(Graph::new()),
            extra_roots: Vec::new(),
            viewed: None,
            synced: None,
            graph_version: 0,
            sent_graph: u64::MAX,
            held_since: None,
            gesture: false,
            navigating: false,
            reset_pending: false,
            invalidate_pending: false,
            reload_pending: false,
            edit_pending: false,
            worker: None,
            waker: None,
            in_flight: None,
            next_generation: 1,
            sent: None,
            user_cancelled: None,
            snapshot: Snapshot::default(),
            finished: 0,
            last_summary: FrameSummary::default(),
            last_eval: Duration::ZERO,
            last_cancel: None,
            animating: false,
            shaders: crate::gpu::shaders::shader_dir().map(ShaderWatch::new),
            shader_error: None,
            engine_error: None,
            played: PlayCache::default(),
            cached_shown: None,
            cacheable: true,
            shown_frame: None,
        }
    }

    /// Called (from the worker thread) whenever an evaluation finished.
    pub fn set_waker(&mut self, waker: Waker) {
        self.waker = Some(waker);
    }

    /// Brings the graph to evaluate up to date with the document; cheap when nothing changed.
    /// A change past the cost limits ([`cost`]) leaves its node out, with the reason on it.
    pub fn sync(&mut self, graph: &Graph, revision: u64, inspected: Option<&PortRef>) {
        self.sync_with(graph, revision, inspected, None);
    }

    /// [`Live::sync`] with the adapter's limits to check costs against.
    pub fn sync_with(
        &mut self,
        graph: &Graph,
        revision: u64,
        inspected: Option<&PortRef>,
        limits: Option<&cost::Limits>,
    ) {
        let key = (revision, inspected.cloned(), self.camera.clone());
        if self.synced.as_ref() == Some(&key) {
            return;
        }
        let graph_changed = self.synced.as_ref().is_none_or(|s| s.0 != revision);
        let (mut run, mut errors) = runnable(graph);
        let limits = limits.cloned().unwrap_or_else(|| cost::Limits::from_env(None));
        self.estimates = cost::estimate(&run, &limits);
        self.refused = cost::refusals(&self.estimates, &limits);
        if !self.refused.is_empty() {
            // Left out like a node with a problem: what depends on it waits.
            let mut without = run.clone();
            let refused: BTreeSet<String> = self.refused.keys().cloned().collect();
            crate::app::editor::document::remove_nodes(&mut without, &refused);
            let (r, mut e) = runnable(&without);
            for (id, why) in &self.refused {
                e.insert(id.clone(), StaticError { message: why.clone(), blocked: false });
            }
            for l in run.links.iter().filter(|l| self.refused.contains_key(&l.from.node)) {
                // Its input is unconnected now because of the refusal: it waits, it is not wrong.
                e.insert(
                    l.to.node.clone(),
                    StaticError {
                        message: format!("input \"{}\" waits for \"{}\", which was refused", l.to.port, l.from.node),
                        blocked: true,
                    },
                );
            }
            errors.extend(e);
            run = r;
        }
        if let Some(cam) = &self.camera {
            cam.apply(&mut run);
        }
        let extra_roots: Vec<String> =
            inspected.filter(|p| run.nodes.contains_key(&p.node)).map(|p| vec![p.node.clone()]).unwrap_or_default();
        self.static_errors = errors;
        self.viewed = viewed_port(graph, inspected);
        if *self.runnable != run || self.extra_roots != extra_roots {
            self.cacheable =
                !run.nodes.values().any(|n| spec::find(&n.kind).is_some_and(|s| s.has(Capabilities::EXTERNAL_SOURCE)));
            self.runnable = Arc::new(run);
            self.extra_roots = extra_roots;
            self.graph_version += 1;
            if graph_changed {
                self.edit_pending = true;
                self.held_since = Some(Instant::now());
            }
        }
        self.synced = Some(key);
    }

    /// Forgets the evaluator and its caches (a new document, a new folder).
    pub fn reset(&mut self) {
        self.reset_pending = true;
        self.synced = None;
        self.sent = None;
    }

    pub fn set_size(&mut self, width: u32, height: u32) {
        if (width, height) != (self.settings.width, self.settings.height) {
            self.settings.width = width.clamp(16, 4096);
            self.settings.height = height.clamp(16, 4096);
            self.invalidate_pending = true;
        }
    }

    pub fn time(&self) -> FrameTime {
        FrameTime { frame: self.frame, fps: self.fps }
    }

    /// Advances the frame while playing, by `dt` seconds of wall time. Every frame is shown:
    /// playback waits for the worker on a frame it has not evaluated yet, so a simulation sees
    /// each frame, and plays the frames kept from an earlier loop at the frame rate. With a node
    /// fed by another program (nothing is kept) a frame the worker had no time for is skipped
    /// instead: it renders the newest when it is free.
    pub fn advance(&mut self, dt: f64) {
        if !self.playing {
            self.play_clock = 0.0;
            return;
        }
        self.play_clock += dt.clamp(0.0, 0.5);
        let step = 1.0 / self.fps;
        while self.play_clock >= step {
            // The frame on screen, or kept to be shown at once.
            let shown = self.shown_frame == Some(self.frame) || self.played.get(&self.wanted()).is_some();
            if self.cacheable && !shown {
                self.play_clock = 0.0;
                break;
            }
            self.play_clock -= step;
            self.frame = if self.frame >= self.frame_range.1 { self.frame_range.0 } else { self.frame + 1 };
        }
    }

    /// Re-reads the shader files and evaluates: only the nodes whose pipelines used a changed
    /// file re-run (with rebuilt pipelines), the rest keep their results and state. A shader
    /// that fails to compile keeps the last good pipeline; its error is on the nodes that use
    /// it and in `shader_error` once the evaluation finished.
    pub fn reload_shaders(&mut self) {
        self.reload_pending = true;
        self.sent = None;
    }

    fn wanted(&self) -> Wanted {
        let (w, h) = (self.settings.width, self.settings.height);
        Wanted {
            graph: self.graph_version,
            time: (self.frame, self.fps.to_bits()),
            size: if self.navigating {
                ((w / NAVIGATION_SCALE).max(16), (h / NAVIGATION_SCALE).max(16))
            } else {
                (w, h)
            },
            viewed: self.viewed.clone(),
        }
    }

    /// Takes finished evaluations from the worker and sends it the next request when one is
    /// due; never waits. Returns whether a new evaluation finished. Call it every UI frame.
    pub fn pump(&mut self, gpu: Option<&Arc<GpuContext>>) -> bool {
        let mut got = self.receive();
        if let (Some(_), Some(w)) = (gpu, &mut self.shaders)
            && w.changed()
        {
            self.reload_pending = true;
            self.sent = None;
        }
        let wanted = self.wanted();
        // Kept pictures of another graph, size or view are not shown again: free them now.
        if !self.cacheable
            || self.played.key.as_ref().is_some_and(|k| *k != PlayCache::key_of(&wanted))
            || self.reset_pending
            || self.invalidate_pending
            || self.reload_pending
            || self.resources.in_flight() > 0
        {
            self.played.clear();
        }
        let kept = if self.playing { self.played.get(&wanted) } else { None };
        let from_cache = kept.is_some();
        if let Some(kept) = kept
            && self.shown_frame != Some(wanted.time.0)
        {
            self.cached_shown = Some(kept.cpu_copy());
            self.shown_frame = Some(wanted.time.0);
            got = true;
        }
        let graph_new = wanted.graph != self.sent_graph;
        // A gesture holds a changing value until it rests or is let go.
        let held = graph_new && self.gesture && self.held_since.is_some_and(|t| t.elapsed() < SETTLE);
        if let Some(f) = &mut self.in_flight {
            // A newer edit supersedes the running evaluation (a new time or view waits for it).
            if graph_new && !held && f.cancelled_at.is_none() {
                f.progress.cancel();
                f.cancelled_at = Some(Instant::now());
            }
        } else if !held && !from_cache && self.user_cancelled.as_ref() != Some(&wanted) {
            self.user_cancelled = None;
            let due = match &self.sent {
                None => true,
                Some((w, at)) => {
                    *w != wanted
                        || self.reset_pending
                        || self.invalidate_pending
                        || self.reload_pending
                        || self.last_summary.pending > 0
                        || self.resources.in_flight() > 0
                        || at.elapsed() >= POLL
                }
            };
            if due {
                self.send(gpu, wanted);
            }
        }
        self.animating = self.playing
            || self.in_flight.is_some()
            || held
            || self.last_summary.pending > 0
            || self.resources.in_flight() > 0;
        got
    }

    fn send(&mut self, gpu: Option<&Arc<GpuContext>>, wanted: Wanted) {
        if self.worker.is_none() {
            self.worker = Some(spawn_worker(gpu.cloned(), self.resources.clone(), self.waker.clone()));
        }
        let generation = self.next_generation;
        self.next_generation += 1;
        let progress = Progress::new();
        let graph_new = wanted.graph != self.sent_graph;
        let request = Request {
            generation,
            graph: graph_new.then(|| (self.runnable.clone(), self.extra_roots.clone())),
            time: self.time(),
            settings: FrameSettings { width: wanted.size.0, height: wanted.size.1, ..self.settings.clone() },
            viewed: wanted.viewed.clone(),
            reset: std::mem::take(&mut self.reset_pending),
            invalidate: std::mem::take(&mut self.invalidate_pending),
            reload_shaders: std::mem::take(&mut self.reload_pending),
            edit: std::mem::take(&mut self.edit_pending),
            progress: progress.clone(),
        };
        let sent = self.worker.as_ref().and_then(|w| w.requests.as_ref()).is_some_and(|tx| tx.send(request).is_ok());
        if sent {
            self.sent_graph = wanted.graph;
            self.in_flight = Some(InFlight {
                generation,
                progress,
                started: Instant::now(),
                cancelled_at: None,
                wanted: wanted.clone(),
            });
            self.sent = Some((wanted, Instant::now()));
        } else {
            self.engine_error = Some("the evaluation thread stopped; reopen the graph".into());
            self.worker = None;
        }
    }

    fn receive(&mut self) -> bool {
        let Some(worker) = &self.worker else { return false };
        let mut got = false;
        while let Ok(done) = worker.finished.try_recv() {
            let mut of = None;
            if let Some(f) = self.in_flight.take_if(|f| f.generation == done.generation) {
                of = Some(f.wanted.clone());
                if let (Some(c), Some(at)) = (&done.cancelled, f.cancelled_at) {
                    self.last_cancel = Some((c.clone(), at.elapsed()));
                }
                if done.cancelled.is_some() {
                    // Its state was not reached: ask again, unless the user cancelled it.
                    self.sent = None;
                }
            }
            self.engine_error = done.engine_error;
            if let Some(snapshot) = done.snapshot {
                if let (Some(w), Some(d)) = (&of, &snapshot.display)
                    && self.cacheable
                    && snapshot.summary.pending == 0
                    && self.resources.in_flight() == 0
                {
                    self.played.keep(w, d);
                }
                self.shown_frame = of.map(|w| w.time.0);
                self.cached_shown = None;
                self.finished += 1;
                self.last_summary = snapshot.summary;
                self.last_eval = snapshot.eval;
                self.shader_error = snapshot.shader_error.clone();
                self.snapshot = snapshot;
                got = true;
            }
        }
        got
    }

    /// Cancels the running evaluation (Esc, the viewport's button) and pauses playback; nothing
    /// is evaluated again until something changes. Returns whether one was running.
    pub fn cancel(&mut self) -> bool {
        self.playing = false;
        let Some(f) = &mut self.in_flight else { return false };
        f.progress.cancel();
        f.cancelled_at.get_or_insert_with(Instant::now);
        self.user_cancelled = Some(f.wanted.clone());
        true
    }

    /// The running evaluation's progress.
    pub fn busy(&self) -> Option<Busy> {
        self.in_flight.as_ref().map(|f| Busy {
            node: f.progress.node(),
            fraction: f.progress.fraction(),
            elapsed: f.started.elapsed(),
            cancelling: f.cancelled_at.is_some(),
        })
    }

    /// Whether the shown evaluation was cancelled by the user and is not redone.
    pub fn cancelled_by_user(&self) -> bool {
        self.user_cancelled.is_some() && self.in_flight.is_none()
    }

    /// Evaluates again what the user cancelled.
    pub fn resume(&mut self) {
        self.user_cancelled = None;
        self.sent = None;
    }

    /// Whether nothing runs and nothing is waiting to be evaluated.
    pub fn idle(&self) -> bool {
        self.in_flight.is_none()
            && self.sent.as_ref().is_some_and(|(w, _)| *w == self.wanted())
            && !(self.reset_pending || self.invalidate_pending || self.reload_pending)
    }

    /// Pumps until idle with no file loading (tests, command-line use); false at the deadline.
    pub fn wait_idle(&mut self, gpu: Option<&Arc<GpuContext>>, timeout: Duration) -> bool {
        let deadline = Instant::now() + timeout;
        loop {
            self.pump(gpu);
            if self.idle() && self.last_summary.pending == 0 && self.resources.in_flight() == 0 {
                return true;
            }
            if Instant::now() >= deadline {
                return false;
            }
            std::thread::sleep(Duration::from_millis(2));
        }
    }

    /// What node `id` shows: its problem in the document, else its last evaluation.
    pub fn state(&self, id: &str) -> NodeState {
        if let Some(e) = self.static_errors.get(id) {
            return if e.blocked {
                NodeState::Blocked(e.message.clone())
            } else {
                NodeState::Failed(e.message.clone())
            };
        }
        self.snapshot.nodes.get(id).map_or(NodeState::Idle, |n| n.state.clone())
    }

    /// Warnings of the node's last run.
    pub fn warnings(&self, id: &str) -> Vec<String> {
        self.snapshot.nodes.get(id).map(|n| n.warnings.clone()).unwrap_or_default()
    }

    /// The CPU time of the node's latest run and whether it ran in the last frame.
    pub fn timing(&self, id: &str) -> Option<(Duration, bool)> {
        let n = self.snapshot.nodes.get(id)?;
        n.cpu.map(|d| (d, n.ran))
    }

    /// How many times the node has run.
    pub fn runs(&self, id: &str) -> u64 {
        self.snapshot.nodes.get(id).map_or(0, |n| n.runs)
    }

    /// A port's value in the last finished evaluation: plain values (numbers, vectors,
    /// cameras) and the viewed port; see [`Live::summary`] for the others.
    pub fn output(&self, port: &PortRef) -> Option<&Value> {
        self.snapshot.outputs.get(port)?.value.as_ref()
    }

    pub fn input(&self, port: &PortRef) -> Option<&Value> {
        self.snapshot.inputs.get(port)?.value.as_ref()
    }

    /// A one-line description of an output's (or input's) value in the last finished evaluation.
    pub fn summary(&self, port: &PortRef, input: bool) -> Option<&str> {
        let map = if input { &self.snapshot.inputs } else { &self.snapshot.outputs };
        map.get(port).map(|p| p.summary.as_str())
    }

    /// The viewport's picture: of the last finished evaluation, or of the frame played now
    /// when an earlier loop kept it.
    pub fn display(&self) -> Option<&Display> {
        self.cached_shown.as_ref().or(self.snapshot.display.as_ref())
    }

    /// The frame whose picture the viewport shows.
    pub fn shown_frame(&self) -> Option<i64> {
        self.shown_frame
    }

    /// How many played frames are kept, and their bytes.
    pub fn kept_frames(&self) -> (usize, usize) {
        (self.played.frames.len(), self.played.bytes)
    }
}

impl Drop for Live {
    fn drop(&mut self) {
        if let Some(f) = &self.in_flight {
            f.progress.cancel();
        }
    }
}

fn spawn_worker(gpu: Option<Arc<GpuContext>>, resources: Arc<Resources>, waker: Option<Waker>) -> Worker {
    let (req_tx, req_rx) = channel::<Request>();
    let (done_tx, done_rx) = channel::<Finished>();
    let (exit_tx, exit_rx) = channel::<()>();
    let spawned = std::thread::Builder::new().name("werkstatt-eval".into()).spawn(move || {
        let mut state = WorkerState { ev: None, converter: None, last_cpu: HashMap::new(), stamp: 0 };
        while let Ok(mut request) = req_rx.recv() {
            // Only the newest request matters; what older ones asked for is merged into it.
            while let Ok(next) = req_rx.try_recv() {
                request = request.merge(next);
            }
            let done = state.evaluate(request, gpu.as_deref(), &resources);
            if done_tx.send(done).is_err() {
                break;
            }
            if let Some(w) = &waker {
                w();
            }
        }
        let _ = exit_tx.send(());
    });
    if let Err(e) = spawned {
        // Without a thread there is no evaluation; say so instead of freezing.
        let (tx, rx) = channel();
        let _ = tx.send(Finished {
            generation: 0,
            snapshot: None,
            cancelled: None,
            engine_error: Some(format!("cannot start the evaluation thread: {e}")),
        });
        let (_etx, erx) = channel();
        return Worker { requests: None, finished: rx, exited: erx };
    }
    Worker { requests: Some(req_tx), finished: done_rx, exited: exit_rx }
}

/// What lives on the worker thread.
struct WorkerState {
    ev: Option<Evaluator>,
    converter: Option<Converter>,
    last_cpu: HashMap<String, Duration>,
    stamp: u64,
}

impl WorkerState {
    fn evaluate(&mut self, r: Request, gpu: Option<&GpuContext>, resources: &Resources) -> Finished {
        let mut engine_error = None;
        if r.reset {
            self.ev = None;
            self.last_cpu.clear();
        }
        if let Some((graph, roots)) = &r.graph {
            let result = match &mut self.ev {
                Some(ev) => ev.update(graph, roots),
                None => Evaluator::new(graph, roots).map(|ev| {
                    self.ev = Some(ev);
                }),
            };
            if let Err(e) = result {
                // `update` leaves the evaluator as it was; start over from the runnable graph.
                engine_error = Some(e.to_string());
                self.ev = Evaluator::new(graph, &[]).ok();
            }
        }
        let Some(ev) = &mut self.ev else {
            return Finished {
                generation: r.generation,
                snapshot: Some(Snapshot::default()),
                cancelled: None,
                engine_error,
            };
        };
        if r.invalidate {
            ev.invalidate_all();
        }
        if r.reload_shaders
            && let Some(gpu) = gpu
        {
            gpu.reload_shaders();
        }
        let start = Instant::now();
        let result = ev.evaluate_cancellable(r.time, gpu, resources, &r.settings, &r.progress);
        let eval = start.elapsed();
        let cancelled = result.is_err();
        let finished = match result {
            Err((_, cancelled)) => {
                Finished { generation: r.generation, snapshot: None, cancelled: Some(cancelled), engine_error }
            }
            Ok(summary) => {
                for rep in ev.reports() {
                    if rep.ran {
                        self.last_cpu.insert(rep.id.to_string(), rep.cpu);
                    }
                }
                self.stamp += 1;
                let display = r.viewed.as_ref().map(|port| {
                    let image = ev.output(&port.node, &port.port).and_then(|v| v.as_texture());
                    let converted = match (image, gpu) {
                        (Some(img), Some(gpu)) => {
                            Some(self.converter.get_or_insert_with(Converter::new).convert(gpu, img))
                        }
                        (Some(_), None) => Some(Err("no GPU display: the window has no wgpu renderer".into())),
                        (None, _) => None,
                    };
                    let copied = match (converted, gpu) {
                        (Some(Ok(i)), Some(gpu)) => Some(to_cpu(gpu, &i).map(|p| (i, p))),
                        (Some(Err(e)), _) => Some(Err(e)),
                        _ => None,
                    };
                    let (image, pixels, error) = match copied {
                        Some(Ok((i, p))) => (Some(i), Some(p), None),
                        Some(Err(e)) => (None, None, Some(e)),
                        None => (None, None, None),
                    };
                    Display { port: port.clone(), image, pixels, error, stamp: self.stamp }
                });
                let snapshot = snapshot(ev, &self.last_cpu, r.viewed.as_ref(), summary, eval, display);
                Finished { generation: r.generation, snapshot: Some(snapshot), cancelled: None, engine_error }
            }
        };
        // After an edit (which may have failed) or a cancel, pooled memory nothing holds any more
        // goes back (the textures of a lowered light count, a half-built set); a steady
        // animation keeps its pools.
        if (r.edit || cancelled)
            && let Some(gpu) = gpu
        {
            gpu.release_unused();
        }
        finished
    }
}

/// A display picture (Rgba8Unorm, gamma-encoded) read back for the window.
fn to_cpu(gpu: &GpuContext, image: &GpuImage) -> Result<egui::ColorImage, String> {
    let px = crate::gpu::read_back(gpu, image).map_err(|e| format!("{e:#}"))?;
    let bytes: Vec<u8> = px.rgba.iter().map(|v| (v.clamp(0.0, 1.0) * 255.0).round() as u8).collect();
    Ok(egui::ColorImage::from_rgba_unmultiplied([px.width as usize, px.height as usize], &bytes))
}

/// Whether a value is plain data the UI may keep (no GPU memory, small).
fn plain(v: &Value) -> bool {
    matches!(v, Value::Scalar(_) | Value::Vector(_) | Value::Color(_) | Value::Camera(_))
}

fn snapshot(
    ev: &Evaluator,
    last_cpu: &HashMap<String, Duration>,
    viewed: Option<&PortRef>,
    summary: FrameSummary,
    eval: Duration,
    display: Option<Display>,
) -> Snapshot {
    let mut s = Snapshot { summary, eval, display, ..Default::default() };
    let shot = |port: &PortRef, v: &Value| PortShot {
        summary: v.summary(),
        value: (plain(v) || Some(port) == viewed).then(|| v.clone()),
    };
    let mut shader_errors = Vec::new();
    for id in ev.node_ids() {
        let Some(r) = ev.report(id) else { continue };
        let state = if *r.status == NodeStatus::Ok && !r.shader_errors.is_empty() {
            let errors: Vec<String> = r.shader_errors.iter().map(|e| e.to_string()).collect();
            NodeState::Failed(format!("shader reload failed, last good pipeline kept: {}", errors.join("; ")))
        } else {
            match r.status {
                NodeStatus::NotRun => NodeState::Idle,
                NodeStatus::Ok => NodeState::Ok,
                NodeStatus::Pending(p) => NodeState::Pending(format!("loading {}", p.display())),
                NodeStatus::Failed(m) => NodeState::Failed(m.clone()),
                NodeStatus::Blocked(m) => NodeState::Blocked(m.clone()),
            }
        };
        shader_errors.extend(r.shader_errors.iter().map(|e| format!("{id}: {e}")));
        let node =
            NodeShot { state, warnings: r.warnings.to_vec(), cpu: last_cpu.get(id).copied(), ran: r.ran, runs: r.runs };
        s.nodes.insert(id.clone(), node);
        let Some(spec) = spec::find(r.kind) else { continue };
        for p in spec.outputs {
            let port = PortRef { node: id.clone(), port: p.name.into() };
            if let Some(v) = ev.output(id, p.name) {
                let shot = shot(&port, v);
                s.outputs.insert(port, shot);
            }
        }
        for p in spec.inputs {
            let port = PortRef { node: id.clone(), port: p.name.into() };
            if let Some(v) = ev.input(id, p.name) {
                let shot = PortShot { summary: v.summary(), value: plain(v).then(|| v.clone()) };
                s.inputs.insert(port, shot);
            }
        }
    }
    s.shader_error = (!shader_errors.is_empty()).then(|| shader_errors.join("\n"));
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::editor::document;

    fn p(s: &str) -> PortRef {
        PortRef::parse(s).unwrap()
    }

    #[test]
    fn runnable_leaves_out_broken_nodes_and_blocks_their_consumers() {
        let mut g = Graph::new();
        let n = document::add_node(&mut g, "Number", [0.0, 0.0]).unwrap();
        let w = document::add_node(&mut g, "Watch", [0.0, 0.0]).unwrap();
        document::connect(&mut g, &p(&format!("{n}.value")), &p(&format!("{w}.value"))).unwrap();
        let t = document::add_node(&mut g, "Tonemap", [0.0, 0.0]).unwrap();
        let pv = document::add_node(&mut g, "Preview", [0.0, 0.0]).unwrap();
        document::connect(&mut g, &p(&format!("{t}.image")), &p(&format!("{pv}.image"))).unwrap();
        let (run, errors) = runnable(&g);
        assert!(run.validate().is_empty());
        assert!(run.nodes.contains_key(&n) && run.nodes.contains_key(&w));
        assert!(!run.nodes.contains_key(&t) && !run.nodes.contains_key(&pv));
        assert!(!errors[&t].blocked, "tonemap misses its image input");
        assert!(errors[&t].message.contains("not connected"), "{}", errors[&t].message);
        assert!(errors[&pv].blocked, "preview waits for tonemap: {}", errors[&pv].message);
    }

    #[test]
    fn live_evaluates_without_gpu_and_reports_states() {
        let mut g = Graph::new();
        let m = document::add_node(&mut g, "Math", [0.0, 0.0]).unwrap();
        let w = document::add_node(&mut g, "Watch", [0.0, 0.0]).unwrap();
        document::connect(&mut g, &p(&format!("{m}.result")), &p(&format!("{w}.value"))).unwrap();
        document::set_param(&mut g, &m, "op", ParamValue::Str("divide".into())).unwrap();
        let mut live = Live::new(PathBuf::from("."), false);
        live.sync(&g, 1, None);
        assert!(live.wait_idle(None, Duration::from_secs(60)), "the evaluation finished");
        assert!(matches!(live.state(&m), NodeState::Failed(ref e) if e.contains("division by zero")));
        assert!(matches!(live.state(&w), NodeState::Blocked(_)));
        document::set_param(&mut g, &m, "b", ParamValue::Float(2.0)).unwrap();
        document::set_param(&mut g, &m, "a", ParamValue::Float(3.0)).unwrap();
        live.sync(&g, 2, None);
        assert!(live.wait_idle(None, Duration::from_secs(60)), "the evaluation finished");
        assert_eq!(live.state(&m), NodeState::Ok);
        assert_eq!(live.output(&p(&format!("{m}.result"))).map(|v| v.summary()), Some("1.5".to_string()));
        let runs = live.runs(&m);
        live.sync(&g, 2, None);
        assert!(live.wait_idle(None, Duration::from_secs(60)), "the evaluation finished");
        assert_eq!(live.runs(&m), runs, "nothing changed, nothing re-ran");
    }

    #[test]
    fn the_viewport_prefers_preview_then_outputs() {
        let g =
            Graph::load(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/graphs/still_life.ron"))).unwrap();
        assert_eq!(viewed_port(&g, None), Some(p("image.image")));
        assert_eq!(viewed_port(&crate::app::chain_graph(3), None), Some(p("watch.value")), "else a Watch value");
        assert_eq!(viewed_port(&Graph::new(), None), None);
        assert_eq!(camera_for(&g, Some("image")), Some("camera".into()));
        let mut cam = CameraOverride::from_graph(&g, "camera").unwrap();
        assert_eq!((cam.yaw, cam.pitch, cam.distance), (35.0, 25.0, 4.0));
        cam.orbit(10.0, 1000.0);
        assert_eq!(cam.pitch, 89.0);
        cam.zoom(1.0);
        assert!(cam.distance < 4.0);
    }
}

//! Live evaluation inside the editor: the document is turned into a graph that can run
//! (nodes with problems are left out and their problems shown on them), the evaluator is
//! updated after each edit so only what changed re-runs, and shader files reload when
//! `WERKSTATT_SHADER_DIR` is set. No drawing here.

use std::collections::{BTreeMap, BTreeSet, HashMap};
use std::path::PathBuf;
use std::time::{Duration, Instant, SystemTime};

use crate::core::eval::{Evaluator, FrameSettings, FrameSummary, FrameTime, NodeStatus};
use crate::core::graph::{Graph, Place, PortRef, ProblemKind};
use crate::core::node::Capabilities;
use crate::core::param::ParamValue;
use crate::core::port::Value;
use crate::core::resources::Resources;
use crate::core::spec;
use crate::gpu::GpuContext;

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

/// The evaluation behind the editor's canvas and viewport.
pub struct Live {
    evaluator: Option<Evaluator>,
    pub resources: Resources,
    pub settings: FrameSettings,
    pub frame: i64,
    pub fps: f64,
    pub playing: bool,
    /// Inclusive range of the frame slider.
    pub frame_range: (i64, i64),
    play_clock: f64,
    pub camera: Option<CameraOverride>,
    static_errors: BTreeMap<String, StaticError>,
    runnable: Graph,
    extra_roots: Vec<String>,
    synced: Option<(u64, Option<PortRef>, Option<CameraOverride>)>,
    /// The CPU time of each node's latest run.
    last_cpu: HashMap<String, Duration>,
    pub last_summary: FrameSummary,
    /// Wall time of the last `evaluate`.
    pub last_eval: Duration,
    /// Whether the next frame may differ without any input (playing, or files loading).
    pub animating: bool,
    shaders: Option<ShaderWatch>,
    /// The compile error of the last shader reload, while the old pipelines are kept.
    pub shader_error: Option<String>,
    /// An error building the evaluator (should not happen: the graph is made runnable first).
    pub engine_error: Option<String>,
}

/// The play range the editor starts with; a turntable camera turns once over it.
const DEFAULT_FRAME_RANGE: (i64, i64) = (0, 239);

impl Live {
    pub fn new(base_dir: PathBuf, watch_files: bool) -> Self {
        Live {
            evaluator: None,
            resources: Resources::new(watch_files),
            settings: FrameSettings { width: 480, height: 360, base_dir, frames: Some(DEFAULT_FRAME_RANGE) },
            frame: 0,
            fps: 30.0,
            playing: false,
            frame_range: DEFAULT_FRAME_RANGE,
            play_clock: 0.0,
            camera: None,
            static_errors: BTreeMap::new(),
            runnable: Graph::new(),
            extra_roots: Vec::new(),
            synced: None,
            last_cpu: HashMap::new(),
            last_summary: FrameSummary::default(),
            last_eval: Duration::ZERO,
            animating: false,
            shaders: crate::gpu::shaders::shader_dir().map(ShaderWatch::new),
            shader_error: None,
            engine_error: None,
        }
    }

    /// Brings the evaluator up to date with the document; cheap when nothing changed.
    pub fn sync(&mut self, graph: &Graph, revision: u64, inspected: Option<&PortRef>) {
        let key = (revision, inspected.cloned(), self.camera.clone());
        if self.synced.as_ref() == Some(&key) {
            return;
        }
        let (mut run, errors) = runnable(graph);
        if let Some(cam) = &self.camera {
            cam.apply(&mut run);
        }
        self.extra_roots =
            inspected.filter(|p| run.nodes.contains_key(&p.node)).map(|p| vec![p.node.clone()]).unwrap_or_default();
        self.static_errors = errors;
        let result = match &mut self.evaluator {
            Some(ev) => ev.update(&run, &self.extra_roots),
            None => Evaluator::new(&run, &self.extra_roots).map(|ev| {
                self.evaluator = Some(ev);
            }),
        };
        match result {
            Ok(()) => self.engine_error = None,
            Err(e) => {
                // `update` leaves the evaluator as it was; start over from the runnable graph.
                self.engine_error = Some(e.to_string());
                self.evaluator = Evaluator::new(&run, &[]).ok();
            }
        }
        self.runnable = run;
        self.synced = Some(key);
    }

    /// Forgets the evaluator and its caches (a new document, a new frame size).
    pub fn reset(&mut self) {
        self.evaluator = None;
        self.synced = None;
        self.last_cpu.clear();
    }

    pub fn set_size(&mut self, width: u32, height: u32) {
        if (width, height) != (self.settings.width, self.settings.height) {
            self.settings.width = width.clamp(16, 4096);
            self.settings.height = height.clamp(16, 4096);
            if let Some(ev) = &mut self.evaluator {
                ev.invalidate_all();
            }
        }
    }

    pub fn time(&self) -> FrameTime {
        FrameTime { frame: self.frame, fps: self.fps }
    }

    /// Advances the frame while playing, by `dt` seconds of wall time.
    pub fn advance(&mut self, dt: f64) {
        if !self.playing {
            self.play_clock = 0.0;
            return;
        }
        self.play_clock += dt.clamp(0.0, 0.5);
        let step = 1.0 / self.fps;
        while self.play_clock >= step {
            self.play_clock -= step;
            self.frame = if self.frame >= self.frame_range.1 { self.frame_range.0 } else { self.frame + 1 };
        }
    }

    /// Evaluates one frame (only what changed runs).
    pub fn evaluate(&mut self, gpu: Option<&GpuContext>) -> FrameSummary {
        if let (Some(gpu), Some(w)) = (gpu, &mut self.shaders)
            && w.changed()
        {
            gpu.reload_shaders();
        }
        self.run(gpu)
    }

    fn run(&mut self, gpu: Option<&GpuContext>) -> FrameSummary {
        let Some(ev) = &mut self.evaluator else { return FrameSummary::default() };
        let start = Instant::now();
        let summary = ev.evaluate(FrameTime { frame: self.frame, fps: self.fps }, gpu, &self.resources, &self.settings);
        self.last_eval = start.elapsed();
        for r in ev.reports() {
            if r.ran {
                self.last_cpu.insert(r.id.to_string(), r.cpu);
            }
        }
        let errors: Vec<String> =
            ev.reports().flat_map(|r| r.shader_errors.iter().map(move |e| format!("{}: {e}", r.id))).collect();
        self.shader_error = (!errors.is_empty()).then(|| errors.join("\n"));
        self.animating = self.playing || summary.pending > 0 || self.resources.in_flight() > 0;
        self.last_summary = summary;
        summary
    }

    /// Re-reads the shader files and evaluates: only the nodes whose pipelines used a changed
    /// file re-run (with rebuilt pipelines), the rest keep their results and state. A shader
    /// that fails to compile keeps the last good pipeline; its error is on the nodes that use
    /// it and in `shader_error`.
    pub fn reload_shaders(&mut self, gpu: &GpuContext) {
        gpu.reload_shaders();
        self.run(Some(gpu));
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
        let Some(r) = self.evaluator.as_ref().and_then(|ev| ev.report(id)) else { return NodeState::Idle };
        if *r.status == NodeStatus::Ok && !r.shader_errors.is_empty() {
            let errors: Vec<String> = r.shader_errors.iter().map(|e| e.to_string()).collect();
            return NodeState::Failed(format!("shader reload failed, last good pipeline kept: {}", errors.join("; ")));
        }
        match r.status {
            NodeStatus::NotRun => NodeState::Idle,
            NodeStatus::Ok => NodeState::Ok,
            NodeStatus::Pending(p) => NodeState::Pending(format!("loading {}", p.display())),
            NodeStatus::Failed(m) => NodeState::Failed(m.clone()),
            NodeStatus::Blocked(m) => NodeState::Blocked(m.clone()),
        }
    }

    /// Warnings of the node's last run.
    pub fn warnings(&self, id: &str) -> Vec<String> {
        self.evaluator.as_ref().and_then(|ev| ev.report(id)).map(|r| r.warnings.to_vec()).unwrap_or_default()
    }

    /// The CPU time of the node's latest run and whether it ran in the last frame.
    pub fn timing(&self, id: &str) -> Option<(Duration, bool)> {
        let ran = self.evaluator.as_ref().and_then(|ev| ev.report(id)).is_some_and(|r| r.ran);
        self.last_cpu.get(id).map(|d| (*d, ran))
    }

    /// How many times the node has run.
    pub fn runs(&self, id: &str) -> u64 {
        self.evaluator.as_ref().and_then(|ev| ev.report(id)).map_or(0, |r| r.runs)
    }

    pub fn output(&self, port: &PortRef) -> Option<&Value> {
        self.evaluator.as_ref()?.output(&port.node, &port.port)
    }

    pub fn input(&self, port: &PortRef) -> Option<&Value> {
        self.evaluator.as_ref()?.input(&port.node, &port.port)
    }
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
        live.evaluate(None);
        assert!(matches!(live.state(&m), NodeState::Failed(ref e) if e.contains("division by zero")));
        assert!(matches!(live.state(&w), NodeState::Blocked(_)));
        document::set_param(&mut g, &m, "b", ParamValue::Float(2.0)).unwrap();
        document::set_param(&mut g, &m, "a", ParamValue::Float(3.0)).unwrap();
        live.sync(&g, 2, None);
        live.evaluate(None);
        assert_eq!(live.state(&m), NodeState::Ok);
        assert_eq!(live.output(&p(&format!("{m}.result"))).map(|v| v.summary()), Some("1.5".to_string()));
        let runs = live.runs(&m);
        live.sync(&g, 2, None);
        live.evaluate(None);
        assert_eq!(live.runs(&m), runs, "nothing changed, nothing re-ran");
    }

    #[test]
    fn the_viewport_prefers_preview_then_outputs() {
        let g = Graph::load(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/graphs/default.ron"))).unwrap();
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

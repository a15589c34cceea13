//! The node author's API: a node kind's spec (ports, parameters), the [`Node`] trait, and the
//! context [`EvalCx`] a node runs in, with typed access to its inputs, parameters and outputs.
//! The host side (planning, caching, running) is [`crate::core::eval`].

use std::any::type_name;
use std::cell::RefCell;
use std::fmt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use crate::core::param::{Choice, ParamKind, ParamSpec, ParamValue};
use crate::core::port::{FromValue, IntoValue, PortType, Value};
use crate::core::resources::{LoadError, Resources, SlotRef};
pub use crate::core::signal::ChangeSignal;
use crate::gpu::{GpuContext, GpuImage};
use crate::io::geometry::GeometryFormat;
use crate::io::image::ImageFormat;
use crate::mesh::Mesh;

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Category {
    Input,
    Geometry,
    Simulation,
    Attachment,
    Scene,
    Lighting,
    Render,
    Output,
}

impl Category {
    pub const ALL: [Category; 8] = [
        Category::Input,
        Category::Geometry,
        Category::Simulation,
        Category::Attachment,
        Category::Scene,
        Category::Lighting,
        Category::Render,
        Category::Output,
    ];
}

impl fmt::Display for Category {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self, f)
    }
}

#[derive(Clone, Copy, Debug)]
pub struct PortSpec {
    pub name: &'static str,
    pub ty: PortType,
    pub required: bool,
    pub doc: &'static str,
}

impl PortSpec {
    pub const fn required(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        PortSpec { name, ty, required: true, doc }
    }
    pub const fn optional(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        PortSpec { name, ty, required: false, doc }
    }
    pub const fn output(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        PortSpec { name, ty, required: false, doc }
    }
}

/// Everything the framework knows about a node kind.
pub struct NodeSpec {
    pub kind: &'static str,
    pub category: Category,
    pub doc: &'static str,
    pub inputs: &'static [PortSpec],
    pub outputs: &'static [PortSpec],
    pub params: &'static [ParamSpec],
    /// What the engine may do with the node beyond evaluating it (an output root, the
    /// viewport's preview, an orbit camera the viewport drives, a source that waits for another
    /// program). Engine code asks for a capability, never for a kind by name. Most nodes have
    /// none: `capabilities: Capabilities::NONE`.
    pub capabilities: Capabilities,
    pub create: fn() -> Box<dyn Node>,
}

/// What the engine may do with a node beyond evaluating it: a set of flags, combined with
/// [`Capabilities::with`] in a `const` (`Capabilities::OUTPUT.with(Capabilities::PREVIEW)`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Capabilities {
    flags: u8,
    /// For [`Capabilities::EXTERNAL_SOURCE`]: what to do instead in a batch render.
    batch_help: Option<&'static str>,
}

impl Capabilities {
    /// A plain node.
    pub const NONE: Capabilities = Capabilities::flag(0);
    /// A root that evaluation pulls from; `render` writes what it emits.
    pub const OUTPUT: Capabilities = Capabilities::flag(1);
    /// The image the editor's viewport shows before any other output.
    pub const PREVIEW: Capabilities = Capabilities::flag(2);
    /// A camera with `yaw`, `pitch` and `distance` parameters that dragging in the viewport
    /// turns and zooms.
    pub const ORBIT_CAMERA: Capabilities = Capabilities::flag(4);
    /// Its values come from another program (a simulator), so a batch render may wait for them
    /// forever; see [`Capabilities::external_source`] to say what to do instead.
    pub const EXTERNAL_SOURCE: Capabilities = Capabilities::flag(8);

    const fn flag(flags: u8) -> Self {
        Capabilities { flags, batch_help: None }
    }

    /// [`Capabilities::EXTERNAL_SOURCE`] with the help a batch render prints when it waits for
    /// the node.
    pub const fn external_source(batch_help: &'static str) -> Self {
        Capabilities { flags: Capabilities::EXTERNAL_SOURCE.flags, batch_help: Some(batch_help) }
    }

    /// The union of both sets (the help text of either).
    pub const fn with(self, other: Capabilities) -> Self {
        Capabilities {
            flags: self.flags | other.flags,
            batch_help: match self.batch_help {
                Some(h) => Some(h),
                None => other.batch_help,
            },
        }
    }

    /// Whether every flag of `other` is set.
    pub const fn contains(self, other: Capabilities) -> bool {
        self.flags & other.flags == other.flags
    }

    /// For an external source: what a batch render should do instead of waiting for it.
    pub const fn batch_help(self) -> Option<&'static str> {
        self.batch_help
    }
}

impl NodeSpec {
    /// Whether the node has every capability of `c`.
    pub const fn has(&self, c: Capabilities) -> bool {
        self.capabilities.contains(c)
    }
    /// Output nodes are the roots evaluation pulls from; `render` writes their products.
    pub const fn is_output(&self) -> bool {
        self.has(Capabilities::OUTPUT)
    }
    pub fn input(&self, name: &str) -> Option<(usize, &PortSpec)> {
        self.inputs.iter().enumerate().find(|(_, p)| p.name == name)
    }
    pub fn output(&self, name: &str) -> Option<(usize, &PortSpec)> {
        self.outputs.iter().enumerate().find(|(_, p)| p.name == name)
    }
    pub fn param(&self, name: &str) -> Option<(usize, &ParamSpec)> {
        self.params.iter().enumerate().find(|(_, p)| p.name == name)
    }
}

impl fmt::Debug for NodeSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("NodeSpec").field("kind", &self.kind).finish_non_exhaustive()
    }
}

/// A node's behaviour. Instances live as long as their node in the graph, so a node may
/// keep GPU pipelines or simulation state between frames.
pub trait Node: Send {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError>;
}

#[derive(Debug)]
pub enum NodeError {
    /// A resource it needs is still loading; not an error in interactive mode.
    Pending(PathBuf),
    Failed(String),
    /// The evaluation was cancelled while the node ran (see [`EvalCx::progress`]): nothing it
    /// made is kept, and it runs again next time.
    Cancelled,
}

impl NodeError {
    pub fn msg(m: impl Into<String>) -> Self {
        NodeError::Failed(m.into())
    }
}

impl From<anyhow::Error> for NodeError {
    fn from(e: anyhow::Error) -> Self {
        NodeError::Failed(format!("{e:#}"))
    }
}

#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameTime {
    pub frame: i64,
    pub fps: f64,
}

impl FrameTime {
    pub fn seconds(&self) -> f64 {
        self.frame as f64 / self.fps
    }
}

/// What every node of a frame shares.
#[derive(Clone, Debug)]
pub struct FrameSettings {
    pub width: u32,
    pub height: u32,
    /// Folder that relative resource paths are resolved against (the graph file's folder).
    pub base_dir: PathBuf,
    /// The inclusive frame range being rendered or played, when there is one (a turntable
    /// turns once over it).
    pub frames: Option<(i64, i64)>,
}

impl Default for FrameSettings {
    fn default() -> Self {
        FrameSettings { width: 320, height: 240, base_dir: PathBuf::from("."), frames: None }
    }
}

impl From<LoadError> for NodeError {
    fn from(e: LoadError) -> Self {
        match e {
            LoadError::Pending(p) => NodeError::Pending(p),
            LoadError::Failed(m) => NodeError::Failed(m),
        }
    }
}

/// What an output node hands the batch runner (`werkstatt render`) to write or report for
/// the frame. The runner names files `<node id>_<frame>.<ext>`, writes them atomically and
/// counts them; the editor ignores products.
#[derive(Clone)]
pub enum Product {
    Image {
        image: Arc<GpuImage>,
        format: ImageFormat,
    },
    Geometry {
        mesh: Arc<Mesh>,
        /// The materials of its triangles (written by formats that have materials).
        parts: Arc<[crate::io::geometry::GeometryPart]>,
        format: GeometryFormat,
    },
    /// A number for `stats.json` (`values`).
    Value(f64),
}

/// The prefix of a status that reports a programming error in a node (an undeclared port or
/// parameter name, a value of the wrong type): never the user's fault. A test runs every
/// registered node and fails on any.
pub const INTERNAL_ERROR: &str = "internal error";

/// What a node sees while it runs. Ports and parameters are read by name and checked against
/// the node's spec: a name the spec does not declare, or a read of the wrong type, is recorded
/// as an internal error on the node (never a panic) and the accessor returns a neutral value.
pub struct EvalCx<'a> {
    pub node_id: &'a str,
    pub spec: &'static NodeSpec,
    pub(crate) params: &'a [ParamValue],
    pub(crate) inputs: &'a [Option<Value>],
    pub(crate) outputs: &'a mut [Option<Value>],
    pub(crate) time: FrameTime,
    pub(crate) used_time: bool,
    pub(crate) gpu: Option<&'a GpuContext>,
    pub(crate) resources: &'a Resources,
    pub(crate) touched: &'a mut Vec<(SlotRef, u64)>,
    pub(crate) signals: &'a mut Vec<(ChangeSignal, u64)>,
    pub(crate) warnings: &'a mut Vec<String>,
    pub(crate) counts: &'a mut Vec<(&'static str, u64)>,
    pub(crate) linked: &'a [bool],
    pub(crate) products: &'a mut Vec<Product>,
    /// Programming errors found while the node ran (see [`INTERNAL_ERROR`]).
    pub(crate) misuse: RefCell<Vec<String>>,
    /// Read through [`EvalCx::frame_size`], [`EvalCx::frame_range`] and [`EvalCx::path`], so
    /// that only nodes that read the frame size re-run when it changes.
    pub(crate) settings: &'a FrameSettings,
    pub(crate) used_size: bool,
    pub(crate) progress: &'a crate::core::progress::Progress,
}

impl<'a> EvalCx<'a> {
    /// Reports how far a long node is (`done` of `total` steps) and answers a cancel: call it
    /// inside long loops and return its error (`cx.progress(i, n)?`), which ends the node
    /// without outputs. Cheap enough for every iteration.
    pub fn progress(&self, done: usize, total: usize) -> Result<(), NodeError> {
        self.progress.set_fraction(if total == 0 { 1.0 } else { done as f32 / total as f32 });
        if self.progress.cancelled() { Err(NodeError::Cancelled) } else { Ok(()) }
    }

    fn misuse(&self, what: String) {
        self.misuse.borrow_mut().push(format!("{INTERNAL_ERROR}: node kind {} {what}", self.spec.kind));
    }

    fn param(&self, name: &str) -> Option<(&ParamSpec, &ParamValue)> {
        match self.spec.param(name) {
            Some((i, p)) => Some((p, &self.params[i])),
            None => {
                self.misuse(format!("reads undeclared parameter \"{name}\""));
                None
            }
        }
    }

    /// A parameter of the given kinds; anything else is a misuse.
    fn param_of(&self, name: &str, accept: fn(&ParamKind) -> bool, what: &str) -> Option<&ParamValue> {
        let (spec, value) = self.param(name)?;
        if accept(&spec.kind) {
            Some(value)
        } else {
            self.misuse(format!("reads {} parameter \"{name}\" as {what}", spec.kind.type_name()));
            None
        }
    }

    /// A float or integer parameter.
    pub fn f64(&self, name: &str) -> f64 {
        self.param_of(name, |k| matches!(k, ParamKind::Float { .. } | ParamKind::Int { .. }), "a number")
            .and_then(ParamValue::as_f64)
            .unwrap_or_default()
    }
    pub fn f32(&self, name: &str) -> f32 {
        self.f64(name) as f32
    }
    pub fn int(&self, name: &str) -> i64 {
        match self.param_of(name, |k| matches!(k, ParamKind::Int { .. }), "an integer") {
            Some(ParamValue::Int(i)) => *i,
            _ => 0,
        }
    }
    pub fn bool(&self, name: &str) -> bool {
        matches!(self.param_of(name, |k| matches!(k, ParamKind::Bool { .. }), "a bool"), Some(ParamValue::Bool(true)))
    }
    /// A vector or colour parameter.
    pub fn vec3(&self, name: &str) -> glam::Vec3 {
        match self.param_of(
            name,
            |k| matches!(k, ParamKind::Vec3 { .. } | ParamKind::Scale { .. } | ParamKind::Color { .. }),
            "a vector",
        ) {
            Some(ParamValue::Vec(v)) if v.len() == 3 => glam::Vec3::new(v[0] as f32, v[1] as f32, v[2] as f32),
            _ => glam::Vec3::ZERO,
        }
    }
    /// A text or path parameter as written (choices are read with [`EvalCx::choice`]).
    pub fn str(&self, name: &str) -> &str {
        match self.param_of(name, |k| matches!(k, ParamKind::Text { .. } | ParamKind::Path { .. }), "text") {
            Some(ParamValue::Str(s)) => s,
            _ => "",
        }
    }
    /// A path parameter resolved against the graph's folder.
    pub fn path(&self, name: &str) -> PathBuf {
        let p = Path::new(self.str(name));
        if p.is_absolute() { p.to_path_buf() } else { self.settings.base_dir.join(p) }
    }
    /// A choice parameter as its enum. The spec must declare it with `options: T::OPTIONS`;
    /// validation has made sure the stored option is one of them.
    pub fn choice<T: Choice>(&self, name: &str) -> T {
        let fallback = || T::from_index(0).expect("a choice enum has at least one variant");
        let Some((spec, value)) = self.param(name) else { return fallback() };
        let ParamKind::Choice { options, .. } = spec.kind else {
            self.misuse(format!("reads {} parameter \"{name}\" as a choice", spec.kind.type_name()));
            return fallback();
        };
        if options != T::OPTIONS {
            self.misuse(format!(
                "reads choice \"{name}\" as {}, whose options differ from the spec's",
                type_name::<T>()
            ));
            return fallback();
        }
        let index = match value {
            ParamValue::Str(s) => options.iter().position(|o| o == s),
            _ => None,
        };
        match index.and_then(T::from_index) {
            Some(choice) => choice,
            None => {
                self.misuse(format!("holds an unvalidated value for choice \"{name}\""));
                fallback()
            }
        }
    }

    fn input_slot(&self, name: &str) -> Option<(&PortSpec, Option<&Value>)> {
        match self.spec.input(name) {
            Some((i, p)) => Some((p, self.inputs[i].as_ref())),
            None => {
                self.misuse(format!("reads undeclared input \"{name}\""));
                None
            }
        }
    }

    fn typed<T: FromValue>(&self, name: &str, value: &Value) -> Option<T> {
        let t = T::from_value(value);
        if t.is_none() {
            self.misuse(format!("reads input \"{name}\" ({}) as {}", value.type_name(), T::NAME));
        }
        t
    }

    /// A required input as its Rust type; an input with no value is an error naming the port.
    pub fn input<T: FromValue>(&self, name: &str) -> Result<T, NodeError> {
        let (_, value) =
            self.input_slot(name).ok_or_else(|| NodeError::msg(format!("{INTERNAL_ERROR}: no input \"{name}\"")))?;
        let value = value.ok_or_else(|| NodeError::msg(format!("input \"{name}\" has no value")))?;
        self.typed(name, value)
            .ok_or_else(|| NodeError::msg(format!("{INTERNAL_ERROR}: input \"{name}\" has the wrong type")))
    }

    /// An optional input: `None` when unconnected.
    pub fn optional<T: FromValue>(&self, name: &str) -> Option<T> {
        let (_, value) = self.input_slot(name)?;
        self.typed(name, value?)
    }

    /// An input's value as it is, for nodes that pass values through.
    pub fn value(&self, name: &str) -> Option<&Value> {
        self.input_slot(name)?.1
    }

    /// Sets an output; the value must fit the port's declared type.
    pub fn set(&mut self, name: &str, value: impl IntoValue) {
        let Some((i, port)) = self.spec.output(name) else {
            self.misuse(format!("writes undeclared output \"{name}\""));
            return;
        };
        match value.into_value(port.ty) {
            Some(v) => self.outputs[i] = Some(v),
            None => self.misuse(format!("writes a value of another type to {} output \"{name}\"", port.ty)),
        }
    }

    /// The frame time. Reading it makes the node re-run whenever the time changes.
    pub fn time(&mut self) -> FrameTime {
        self.used_time = true;
        self.time
    }

    /// The frame's width and height in pixels. Reading it makes the node re-run whenever the
    /// size changes (nodes that take the size from an input image re-run through that input).
    pub fn frame_size(&mut self) -> (u32, u32) {
        self.used_size = true;
        (self.settings.width, self.settings.height)
    }

    /// The host's frame range, if it has one (a render's `--frames`, the editor's slider).
    pub fn frame_range(&self) -> Option<(i64, i64)> {
        self.settings.frames
    }

    pub fn gpu(&self) -> Result<&'a GpuContext, NodeError> {
        self.gpu.ok_or_else(|| NodeError::msg("this node needs a GPU, but evaluation runs without one"))
    }

    pub fn warn(&mut self, message: impl Into<String>) {
        self.warnings.push(message.into());
    }

    /// Whether a link leaves output `name`: for a check that only matters to consumers of
    /// that output (MeshFile's surface needs UVs, its mesh does not). The node re-runs
    /// when this changes.
    pub fn output_linked(&self, name: &str) -> bool {
        match self.spec.output(name) {
            Some((i, _)) => self.linked.get(i).copied().unwrap_or(false),
            None => {
                self.misuse(format!("asks about undeclared output \"{name}\""));
                false
            }
        }
    }

    /// Reports a count for `stats.json` and the editor (placements, instances, triangles):
    /// what a user checks first when a result looks sparse.
    pub fn count(&mut self, name: &'static str, n: usize) {
        self.counts.push((name, n as u64));
    }

    /// Hands the batch runner something to write this frame (output nodes only).
    pub fn emit(&mut self, product: Product) {
        if !self.spec.is_output() {
            self.misuse("emits a product but is not an output node".into());
        }
        self.products.push(product);
    }

    /// Loads a file through the lazy resource system. While it loads this returns
    /// `NodeError::Pending`; the node re-runs when the resource is ready or reloaded.
    pub fn load<T: Send + Sync + 'static>(
        &mut self,
        path: &Path,
        loader: fn(&Path) -> anyhow::Result<T>,
    ) -> Result<Arc<T>, NodeError> {
        let (slot, version, state) = self.resources.request_observed(path, loader);
        self.touched.push((slot, version));
        Ok(state?)
    }

    /// Starts loading a file that a later run will `load`, without making this run depend on
    /// it (it does not re-run when the load completes).
    pub fn prefetch<T: Send + Sync + 'static>(&self, path: &Path, loader: fn(&Path) -> anyhow::Result<T>) {
        let _ = self.resources.request(path, loader);
    }

    /// Lets the resource system forget a file loaded as `T` that this node no longer needs
    /// (frees its memory). Returns false, and keeps it, while another node or a loader still
    /// uses it; call again later.
    pub fn release<T: 'static>(&self, path: &Path) -> bool {
        self.resources.release::<T>(path)
    }

    /// Makes this run depend on an external change signal: the node re-runs when the signal
    /// is bumped. Returns the version seen; the fingerprint records that version, so a bump
    /// that races with this run still triggers the next one.
    pub fn watch(&mut self, signal: &ChangeSignal) -> u64 {
        let v = signal.version();
        self.signals.push((signal.clone(), v));
        v
    }
}

/// What a node file needs: `use crate::core::node::prelude::*;`.
pub mod prelude {
    pub use super::{Capabilities, Category, EvalCx, Node, NodeError, NodeSpec, PortSpec, Product};
    pub use crate::core::param::{Choice, ParamKind, ParamSpec};
    pub use crate::core::port::{PortType, Value};
}

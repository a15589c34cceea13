//! Per-frame evaluation: a graph compiles to a plan (the nodes that feed an output, in
//! topological order); each frame every planned node is skipped when its fingerprint
//! (parameters, input versions, touched resources, and the time if it read it) is unchanged.

use std::cell::RefCell;
use std::collections::HashMap;
use std::path::PathBuf;
use std::time::{Duration, Instant};

use crate::core::graph::{Graph, GraphError};
use crate::core::node::{EvalCx, INTERNAL_ERROR, Node, NodeError, NodeSpec, Product};
use crate::core::param::ParamValue;
use crate::core::port::Value;
use crate::core::progress::Progress;
use crate::core::resources::{Resources, SlotRef};
use crate::core::spec;
use crate::gpu::{GpuContext, ShaderError};

/// The frame settings and time a host passes to [`Evaluator::evaluate`].
pub use crate::core::node::{ChangeSignal, FrameSettings, FrameTime};

#[derive(Clone, Debug, PartialEq)]
pub enum NodeStatus {
    NotRun,
    Ok,
    Pending(PathBuf),
    Failed(String),
    /// An input's source has no value (it failed or is pending).
    Blocked(String),
}

struct NodeState {
    instance: Box<dyn Node>,
    fingerprint: Option<u64>,
    version: u64,
    status: NodeStatus,
    outputs: Vec<Option<Value>>,
    uses_time: bool,
    /// Its last run read the frame size ([`EvalCx::frame_size`]): a new size re-runs it.
    uses_size: bool,
    /// Resources and external signals the last run depended on, with the versions it saw.
    touched: Vec<(SlotRef, u64)>,
    signals: Vec<(ChangeSignal, u64)>,
    warnings: Vec<String>,
    /// Counts its last run reported (`EvalCx::count`).
    counts: Vec<(&'static str, u64)>,
    /// Shaders of its last run that failed to compile (it ran on the last good pipelines, or failed).
    shader_errors: Vec<ShaderError>,
    /// What the last successful run emitted for the batch runner.
    products: Vec<Product>,
    last_cpu: Duration,
    ran_last_frame: bool,
    runs: u64,
}

/// The compiled graph with per-node caches.
pub struct Evaluator {
    ids: Vec<String>,
    index: HashMap<String, usize>,
    specs: Vec<&'static NodeSpec>,
    params: Vec<Vec<ParamValue>>,
    param_hash: Vec<u64>,
    /// Per node, per input port: the source node and its output index.
    sources: Vec<Vec<Option<(usize, usize)>>>,
    /// Per node, per output port: whether a link leaves it (`EvalCx::output_linked`).
    linked: Vec<Vec<bool>>,
    /// Nodes that feed a root, sources first.
    order: Vec<usize>,
    /// Per node: the nodes its outputs feed, and whether it is in `order`.
    consumers: Vec<Vec<usize>>,
    planned: Vec<bool>,
    /// Per node: whether its outputs were released this frame (see `release_outputs`).
    released: Vec<bool>,
    roots: Vec<usize>,
    state: Vec<NodeState>,
    scratch_inputs: Vec<Option<Value>>,
    next_version: u64,
    /// Hash of the frame settings of the last evaluation but the size: a new folder or frame
    /// range re-runs everything.
    settings_hash: u64,
    /// Hash of the frame size of the last evaluation: a new size re-runs the nodes that read it.
    size_hash: u64,
}

/// Counts of one frame's evaluation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameSummary {
    pub ran: usize,
    pub skipped: usize,
    pub pending: usize,
    pub failed: usize,
}

/// An evaluation stopped by its [`Progress`] token, before or inside node `node`. Nodes that
/// finished before keep their results; the rest re-run next time. Nothing half-made is kept.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Cancelled {
    pub node: String,
}

impl std::fmt::Display for Cancelled {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "evaluation cancelled at node \"{}\"", self.node)
    }
}

impl std::error::Error for Cancelled {}

/// One node's record for the last frame.
#[derive(Clone, Debug)]
pub struct NodeReport<'a> {
    pub id: &'a str,
    pub kind: &'static str,
    pub ran: bool,
    pub cpu: Duration,
    pub status: &'a NodeStatus,
    pub warnings: &'a [String],
    pub counts: &'a [(&'static str, u64)],
    /// Shader files that failed to compile when it last ran: with status `Ok` it rendered
    /// with the last good pipeline.
    pub shader_errors: &'a [ShaderError],
    pub runs: u64,
}

#[inline]
fn mix(h: u64, x: u64) -> u64 {
    (h.rotate_left(5) ^ x).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95)
}

impl Evaluator {
    /// Compiles a validated graph. `extra_roots` are nodes to evaluate besides the output
    /// nodes (for `--dump node.port`).
    pub fn new(graph: &Graph, extra_roots: &[String]) -> Result<Evaluator, GraphError> {
        let mut ev = Evaluator {
            ids: Vec::new(),
            index: HashMap::new(),
            specs: Vec::new(),
            params: Vec::new(),
            param_hash: Vec::new(),
            sources: Vec::new(),
            linked: Vec::new(),
            order: Vec::new(),
            consumers: Vec::new(),
            planned: Vec::new(),
            released: Vec::new(),
            roots: Vec::new(),
            state: Vec::new(),
            scratch_inputs: Vec::new(),
            next_version: 1,
            settings_hash: 0,
            size_hash: 0,
        };
        ev.rebuild(graph, extra_roots, HashMap::new())?;
        Ok(ev)
    }

    /// Recompiles after an edit, keeping the caches (and node instances) of nodes whose
    /// kind is unchanged: only what the edit touched re-runs.
    /// On an error the evaluator is left as it was.
    pub fn update(&mut self, graph: &Graph, extra_roots: &[String]) -> Result<(), GraphError> {
        // Check everything `rebuild` could fail on first, so a bad edit leaves the evaluator
        // (and its caches) as it was.
        if let Some(p) = graph.validate().into_iter().next() {
            return Err(p.into());
        }
        if let Some(id) = extra_roots.iter().find(|id| !graph.nodes.contains_key(*id)) {
            return Err(GraphError::NoSuchNode(id.clone()));
        }
        let mut old = HashMap::new();
        let ids = std::mem::take(&mut self.ids);
        for (id, (state, spec)) in
            ids.into_iter().zip(std::mem::take(&mut self.state).into_iter().zip(self.specs.drain(..)))
        {
            old.insert(id, (spec.kind, state));
        }
        self.rebuild(graph, extra_roots, old)
    }

    fn rebuild(
        &mut self,
        graph: &Graph,
        extra_roots: &[String],
        mut old: HashMap<String, (&'static str, NodeState)>,
    ) -> Result<(), GraphError> {
        if let Some(p) = graph.validate().into_iter().next() {
            return Err(p.into());
        }
        self.ids.clear();
        self.index.clear();
        self.specs.clear();
        self.params.clear();
        self.param_hash.clear();
        self.sources.clear();
        self.state.clear();
        for (i, (id, doc)) in graph.nodes.iter().enumerate() {
            let spec = spec::find(&doc.kind).expect("validate() checked every kind");
            let params: Vec<ParamValue> = spec
                .params
                .iter()
                .map(|p| {
                    doc.params.get(p.name).and_then(|v| p.kind.check(v).ok()).unwrap_or_else(|| p.kind.default_value())
                })
                .collect();
            let mut h = std::collections::hash_map::DefaultHasher::new();
            for p in &params {
                p.hash_into(&mut h);
            }
            let state = match old.remove(id) {
                Some((kind, state)) if kind == spec.kind => state,
                _ => NodeState {
                    instance: (spec.create)(),
                    fingerprint: None,
                    version: 0,
                    status: NodeStatus::NotRun,
                    outputs: vec![None; spec.outputs.len()],
                    uses_time: false,
                    uses_size: false,
                    touched: Vec::new(),
                    signals: Vec::new(),
                    warnings: Vec::new(),
                    counts: Vec::new(),
                    shader_errors: Vec::new(),
                    products: Vec::new(),
                    last_cpu: Duration::ZERO,
                    ran_last_frame: false,
                    runs: 0,
                },
            };
            self.ids.push(id.clone());
            self.index.insert(id.clone(), i);
            self.specs.push(spec);
            self.params.push(params);
            self.param_hash.push(std::hash::Hasher::finish(&h));
            self.sources.push(vec![None; spec.inputs.len()]);
            self.state.push(state);
        }
        for link in &graph.links {
            let (Some(&from), Some(&to)) = (self.index.get(&link.from.node), self.index.get(&link.to.node)) else {
                continue;
            };
            let (out, _) = self.specs[from].output(&link.from.port).expect("validate() checked every port");
            let (inp, _) = self.specs[to].input(&link.to.port).expect("validate() checked every port");
            self.sources[to][inp] = Some((from, out));
        }
        self.linked = self.specs.iter().map(|s| vec![false; s.outputs.len()]).collect();
        for (from, out) in self.sources.iter().flatten().flatten() {
            self.linked[*from][*out] = true;
        }
        // A node that behaves differently by what is linked re-runs when that changes.
        for (h, linked) in self.param_hash.iter_mut().zip(&self.linked) {
            *h = mix(*h, linked.iter().fold(0u64, |m, &l| (m << 1) | u64::from(l)));
        }
        self.roots = (0..self.ids.len()).filter(|&i| self.specs[i].is_output()).collect();
        for id in extra_roots {
            let &i = self.index.get(id).ok_or_else(|| GraphError::NoSuchNode(id.clone()))?;
            if !self.roots.contains(&i) {
                self.roots.push(i);
            }
        }
        // Post-order DFS from the roots over input links gives sources before consumers.
        self.order.clear();
        let mut visited = vec![false; self.ids.len()];
        for &root in &self.roots.clone() {
            let mut stack = vec![(root, 0usize)];
            while let Some((n, next)) = stack.pop() {
                if next == 0 {
                    if visited[n] {
                        continue;
                    }
                    visited[n] = true;
                }
                if let Some(src) = self.sources[n].get(next) {
                    stack.push((n, next + 1));
                    if let Some((s, _)) = src
                        && !visited[*s]
                    {
                        stack.push((*s, 0));
                    }
                } else {
                    self.order.push(n);
                }
            }
        }
        self.consumers = vec![Vec::new(); self.ids.len()];
        for (to, srcs) in self.sources.iter().enumerate() {
            for (from, _) in srcs.iter().flatten() {
                if !self.consumers[*from].contains(&to) {
                    self.consumers[*from].push(to);
                }
            }
        }
        self.planned = vec![false; self.ids.len()];
        for &n in &self.order {
            self.planned[n] = true;
        }
        self.released = vec![false; self.ids.len()];
        Ok(())
    }

    /// Drops the outputs of `n`, which is about to run, and of the planned nodes downstream of
    /// it: each of them re-runs later in this frame (its input changes) or is blocked, so their
    /// values are stale. Pooled textures they held can then serve the runs in between, and a
    /// steady animation needs one set of textures instead of one per frame in flight.
    fn release_outputs(&mut self, n: usize) {
        let mut stack = vec![n];
        while let Some(i) = stack.pop() {
            if std::mem::replace(&mut self.released[i], true) {
                continue;
            }
            self.state[i].outputs.iter_mut().for_each(|o| *o = None);
            self.state[i].products.clear();
            stack.extend(self.consumers[i].iter().copied().filter(|&c| self.planned[c]));
        }
    }

    /// Evaluates one frame. Nodes whose fingerprint is unchanged are skipped.
    pub fn evaluate(
        &mut self,
        time: FrameTime,
        gpu: Option<&GpuContext>,
        resources: &Resources,
        settings: &FrameSettings,
    ) -> FrameSummary {
        // Nobody else holds this token, so nothing can cancel.
        match self.evaluate_cancellable(time, gpu, resources, settings, &Progress::new()) {
            Ok(summary) | Err((summary, _)) => summary,
        }
    }

    /// [`Evaluator::evaluate`] that `progress` can cancel: checked before every node, and by
    /// long nodes inside their loops (`EvalCx::progress`). A cancelled frame returns what ran
    /// so far and where it stopped; the queued GPU work of the nodes that finished is still
    /// submitted, the cancelled node's is dropped.
    pub fn evaluate_cancellable(
        &mut self,
        time: FrameTime,
        gpu: Option<&GpuContext>,
        resources: &Resources,
        settings: &FrameSettings,
        progress: &Progress,
    ) -> Result<FrameSummary, (FrameSummary, Cancelled)> {
        let mut cancelled = None;
        let mut summary = FrameSummary::default();
        fn hash_of(value: impl std::hash::Hash) -> u64 {
            let mut h = std::collections::hash_map::DefaultHasher::new();
            value.hash(&mut h);
            std::hash::Hasher::finish(&h)
        }
        self.settings_hash = hash_of((&settings.base_dir, settings.frames, gpu.is_some()));
        self.size_hash = hash_of((settings.width, settings.height));
        self.released.iter_mut().for_each(|r| *r = false);
        for oi in 0..self.order.len() {
            let n = self.order[oi];
            let blocked = self.sources[n]
                .iter()
                .flatten()
                .find(|(s, _)| self.state[*s].status != NodeStatus::Ok)
                .map(|(s, _)| self.ids[*s].as_str());
            let h = self.recompute(n, time, false);
            let state = &self.state[n];
            if let Some(upstream) = blocked {
                let msg = format!("waiting for input from \"{upstream}\"");
                let state = &mut self.state[n];
                state.ran_last_frame = false;
                state.last_cpu = Duration::ZERO;
                state.fingerprint = None;
                if state.status != NodeStatus::Blocked(msg.clone()) {
                    state.status = NodeStatus::Blocked(msg);
                    state.outputs.iter_mut().for_each(|o| *o = None);
                    state.products.clear();
                }
                summary.skipped += 1;
                continue;
            }
            if state.fingerprint == Some(h) {
                let state = &mut self.state[n];
                state.ran_last_frame = false;
                state.last_cpu = Duration::ZERO;
                summary.skipped += 1;
                match state.status {
                    NodeStatus::Pending(_) => summary.pending += 1,
                    NodeStatus::Failed(_) => summary.failed += 1,
                    _ => {}
                }
                continue;
            }
            if progress.cancelled() {
                cancelled = Some(oi);
                break;
            }
            progress.start_node(&self.ids[n]);
            self.release_outputs(n);
            if !self.run_node(n, time, gpu, resources, settings, progress) {
                cancelled = Some(oi);
                break;
            }
            // Hash again: the run may have started or stopped reading the time, or touched resources.
            // Versions as the run saw them: a load or signal that changed during the run re-runs it.
            self.state[n].fingerprint = Some(self.recompute(n, time, true));
            summary.ran += 1;
            match self.state[n].status {
                NodeStatus::Pending(_) => summary.pending += 1,
                NodeStatus::Failed(_) => summary.failed += 1,
                _ => {}
            }
        }
        // One submit for the whole frame's GPU work.
        if let Some(gpu) = gpu {
            gpu.flush();
        }
        let Some(at) = cancelled else { return Ok(summary) };
        // The nodes from the cancelled one on whose outputs were let go run again next time.
        for &n in &self.order[at..] {
            if self.released[n] {
                self.state[n].fingerprint = None;
            }
        }
        Err((summary, Cancelled { node: self.ids[self.order[at]].clone() }))
    }

    /// The fingerprint of node `n` from its current sources, time use, resources and signals;
    /// `as_seen`: with the resource and signal versions its last run observed, not the current ones.
    fn recompute(&self, n: usize, time: FrameTime, as_seen: bool) -> u64 {
        let mut h = mix(self.param_hash[n], self.settings_hash);
        for src in &self.sources[n] {
            h = match src {
                // The output index too: re-pointing a link to another port of the same node is a change.
                Some((s, o)) => mix(mix(h, self.state[*s].version), *o as u64),
                None => mix(h, u64::MAX),
            };
        }
        let state = &self.state[n];
        if state.uses_time {
            h = mix(h, time.frame as u64);
            h = mix(h, time.fps.to_bits());
        }
        if state.uses_size {
            h = mix(h, self.size_hash);
        }
        for (slot, seen) in &state.touched {
            h = mix(h, if as_seen { *seen } else { slot.version() });
        }
        for (signal, seen) in &state.signals {
            h = mix(h, if as_seen { *seen } else { signal.version() });
        }
        h
    }

    fn run_node(
        &mut self,
        n: usize,
        time: FrameTime,
        gpu: Option<&GpuContext>,
        resources: &Resources,
        settings: &FrameSettings,
        progress: &Progress,
    ) -> bool {
        let mut inputs = std::mem::take(&mut self.scratch_inputs);
        inputs.clear();
        inputs.extend(self.sources[n].iter().map(|src| src.and_then(|(s, o)| self.state[s].outputs[o].clone())));
        let spec = self.specs[n];
        let state = &mut self.state[n];
        let mut outputs = vec![None; spec.outputs.len()];
        state.touched.clear();
        state.signals.clear();
        state.warnings.clear();
        state.counts.clear();
        let mut products = Vec::new();
        // The node's GPU work runs in its own validation error scope.
        let scope = gpu.map(|g| g.begin_node(&self.ids[n]));
        let start = Instant::now();
        let (result, used_time, used_size, misuse) = {
            let mut cx = EvalCx {
                node_id: &self.ids[n],
                spec,
                params: &self.params[n],
                inputs: &inputs,
                outputs: &mut outputs,
                time,
                used_time: false,
                gpu,
                resources,
                touched: &mut state.touched,
                signals: &mut state.signals,
                warnings: &mut state.warnings,
                counts: &mut state.counts,
                linked: &self.linked[n],
                products: &mut products,
                misuse: RefCell::new(Vec::new()),
                settings,
                used_size: false,
                progress,
            };
            let r = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| state.instance.eval(&mut cx)));
            let r = r.unwrap_or_else(|panic| {
                let what = panic
                    .downcast_ref::<String>()
                    .cloned()
                    .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                    .unwrap_or_default();
                Err(NodeError::msg(format!("{INTERNAL_ERROR} (panic) in {}: {what}", spec.kind)))
            });
            (r, cx.used_time, cx.used_size, cx.misuse.into_inner())
        };
        if matches!(result, Err(NodeError::Cancelled)) {
            // Nothing of the run is kept: its commands are dropped, it counts as not run, and a
            // fresh instance replaces it, so caches it filled part-way (uniform rings, bind
            // groups holding half a PEM set) are let go too.
            if let Some(scope) = scope {
                scope.discard();
            }
            state.instance = (spec.create)();
            state.fingerprint = None;
            state.status = NodeStatus::NotRun;
            state.ran_last_frame = false;
            state.products.clear();
            inputs.clear();
            self.scratch_inputs = inputs;
            return false;
        }
        let result = Self::check_contract(spec, result, &outputs, misuse);
        state.last_cpu = start.elapsed();
        let mut result = result;
        state.shader_errors.clear();
        if let Some(done) = scope.map(|s| s.end()) {
            // A changed shader file it used re-runs it, like a reloaded resource.
            state.signals.extend(done.shaders);
            state.shader_errors = done.shader_errors;
            if let Some(e) = done.error {
                let e = format!("GPU validation error: {e}");
                result = match result {
                    Ok(()) => Err(NodeError::Failed(e)),
                    Err(NodeError::Failed(m)) => Err(NodeError::Failed(format!("{m}; {e}"))),
                    Err(other) => Err(other),
                };
            }
        }
        state.ran_last_frame = true;
        state.runs += 1;
        state.uses_time = used_time;
        state.uses_size = used_size;
        match result {
            Ok(()) => {
                state.status = NodeStatus::Ok;
                state.outputs = outputs;
                state.products = products;
                state.version = self.next_version;
                self.next_version += 1;
            }
            Err(NodeError::Pending(p)) => {
                state.products.clear();
                state.status = NodeStatus::Pending(p);
                state.outputs.iter_mut().for_each(|o| *o = None);
            }
            Err(NodeError::Failed(m)) => {
                state.products.clear();
                state.status = NodeStatus::Failed(m);
                state.outputs.iter_mut().for_each(|o| *o = None);
            }
            // Returned above; kept apart from failures should that ever change.
            Err(NodeError::Cancelled) => {
                state.products.clear();
                state.status = NodeStatus::NotRun;
                state.outputs.iter_mut().for_each(|o| *o = None);
            }
        }
        inputs.clear();
        self.scratch_inputs = inputs;
        true
    }

    /// Turns a node's programming errors (see [`INTERNAL_ERROR`]) into its result. In debug
    /// builds also checks that a successful run set every output with a value of its declared
    /// type (`EvalCx::set` checks types; this catches a port the node forgot).
    fn check_contract(
        spec: &NodeSpec,
        result: Result<(), NodeError>,
        outputs: &[Option<Value>],
        mut misuse: Vec<String>,
    ) -> Result<(), NodeError> {
        if cfg!(debug_assertions) && result.is_ok() {
            for (port, value) in spec.outputs.iter().zip(outputs) {
                match value {
                    None => misuse
                        .push(format!("{INTERNAL_ERROR}: node kind {} left output \"{}\" unset", spec.kind, port.name)),
                    Some(v) if v.port_type() != port.ty => misuse.push(format!(
                        "{INTERNAL_ERROR}: node kind {} wrote a {} to {} output \"{}\"",
                        spec.kind,
                        v.type_name(),
                        port.ty,
                        port.name
                    )),
                    Some(_) => {}
                }
            }
        }
        // A programming error outranks whatever the node returned.
        if misuse.is_empty() { result } else { Err(NodeError::Failed(misuse.join("; "))) }
    }

    /// Forgets every cache, e.g. after the frame size changed.
    pub fn invalidate_all(&mut self) {
        for s in &mut self.state {
            s.fingerprint = None;
        }
    }

    pub fn node_ids(&self) -> &[String] {
        &self.ids
    }

    /// The nodes evaluation runs, in order.
    pub fn planned(&self) -> impl Iterator<Item = &str> {
        self.order.iter().map(|&i| self.ids[i].as_str())
    }

    pub fn roots(&self) -> impl Iterator<Item = &str> {
        self.roots.iter().map(|&i| self.ids[i].as_str())
    }

    pub fn report(&self, id: &str) -> Option<NodeReport<'_>> {
        let &i = self.index.get(id)?;
        Some(self.report_at(i))
    }

    fn report_at(&self, i: usize) -> NodeReport<'_> {
        let s = &self.state[i];
        NodeReport {
            id: &self.ids[i],
            kind: self.specs[i].kind,
            ran: s.ran_last_frame,
            cpu: s.last_cpu,
            status: &s.status,
            warnings: &s.warnings,
            counts: &s.counts,
            shader_errors: &s.shader_errors,
            runs: s.runs,
        }
    }

    /// Reports of the planned nodes, in evaluation order.
    pub fn reports(&self) -> impl Iterator<Item = NodeReport<'_>> {
        self.order.iter().map(|&i| self.report_at(i))
    }

    /// What output node `id` emitted for the batch runner in its last successful run (a node
    /// skipped this frame still stands by it: its inputs are unchanged).
    pub fn products(&self, id: &str) -> &[Product] {
        self.index.get(id).map_or(&[], |&i| &self.state[i].products)
    }

    pub fn output(&self, id: &str, port: &str) -> Option<&Value> {
        let &i = self.index.get(id)?;
        let (o, _) = self.specs[i].output(port)?;
        self.state[i].outputs[o].as_ref()
    }

    /// The value feeding input `port` of node `id`.
    pub fn input(&self, id: &str, port: &str) -> Option<&Value> {
        let &i = self.index.get(id)?;
        let (p, _) = self.specs[i].input(port)?;
        let (s, o) = self.sources[i][p]?;
        self.state[s].outputs[o].as_ref()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A node whose code is wrong: every built-in kind is expected never to panic, so the
    /// registry has none of these; the test swaps it in for one node of a graph.
    struct Panicking;

    impl Node for Panicking {
        fn eval(&mut self, _: &mut EvalCx<'_>) -> Result<(), NodeError> {
            panic!("index 7 out of range")
        }
    }

    #[test]
    fn a_node_that_panics_fails_with_the_message_and_blocks_its_consumers_only() {
        let text = r#"(version: 1, nodes: {
            "x": (kind: "Number", params: {"value": 2.0}),
            "broken": (kind: "Math", params: {"op": "add"}),
            "out": (kind: "Watch"),
            "ok": (kind: "Math", params: {"op": "multiply", "b": 3.0}),
            "out_ok": (kind: "Watch"),
        }, links: [("x.value", "broken.a"), ("broken.result", "out.value"),
                   ("x.value", "ok.a"), ("ok.result", "out_ok.value")])"#;
        let graph = Graph::load_str(text, "test.ron".as_ref()).unwrap();
        let mut ev = Evaluator::new(&graph, &[]).unwrap();
        let broken = ev.ids.iter().position(|id| id == "broken").unwrap();
        ev.state[broken].instance = Box::new(Panicking);
        let resources = Resources::new(false);
        let summary = ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, None, &resources, &FrameSettings::default());
        assert_eq!(summary.failed, 1, "only the panicking node fails");
        let status = &ev.report("broken").unwrap().status;
        assert!(
            matches!(status, NodeStatus::Failed(m) if m.contains("panic") && m.contains("Math") && m.contains("index 7 out of range")),
            "the panic becomes the node's error, naming its kind and message: {status:?}"
        );
        assert!(matches!(&ev.report("out").unwrap().status, NodeStatus::Blocked(m) if m.contains("\"broken\"")));
        assert!(
            matches!(ev.output("out_ok", "value"), Some(Value::Scalar(v)) if *v == 6.0),
            "other branches still run"
        );
        // A panicked node is a failed one: not retried while nothing changes.
        ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, None, &resources, &FrameSettings::default());
        assert_eq!(ev.report("broken").unwrap().runs, 1);
    }
}

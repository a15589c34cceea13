//! The headless batch runner behind `werkstatt render`: evaluates frames, waits for every
//! resource (so output is deterministic), writes the output nodes' images and `stats.json`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context as _, bail};
use serde::Serialize;

use crate::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
use crate::core::graph::{Graph, PortRef};
use crate::core::node::Product;
use crate::core::param::Choice as _;
use crate::core::port::Value;
use crate::core::resources::Resources;
use crate::gpu::{self, GpuContext};
use crate::io::geometry::GeometryFormat;
use crate::io::image::ImageFormat;

#[derive(Clone)]
pub struct RenderOptions {
    pub graph_path: PathBuf,
    /// Inclusive frame range.
    pub frames: (i64, i64),
    pub fps: f64,
    pub width: u32,
    pub height: u32,
    pub out_dir: PathBuf,
    /// `node.param=value` overrides.
    pub sets: Vec<String>,
    /// `node.port` texture outputs to write besides the output nodes.
    pub dumps: Vec<String>,
    /// Supersampling: passes render at `ssaa` x the size and written images are box-filtered
    /// down to it (1: off).
    pub ssaa: u32,
    /// The format of `dumps`; `None`: PNG for 8-bit textures, EXR for float ones.
    pub dump_format: Option<ImageFormat>,
    pub progress: bool,
    /// The command line that asked for the run, recorded in `stats.json` (empty from code).
    pub command: Vec<String>,
    /// How long one frame may wait for pending nodes (loads, external sources) before it fails.
    pub pending_timeout: std::time::Duration,
}

#[derive(Serialize, Debug)]
pub struct NodeTiming {
    pub cpu_ms: f64,
    /// Time of the node's GPU passes, where the adapter has timestamp queries.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub gpu_ms: Option<f64>,
    pub ran: bool,
    /// What the node counted in its last run (placements, instances, triangles).
    #[serde(skip_serializing_if = "BTreeMap::is_empty")]
    pub counts: BTreeMap<&'static str, u64>,
}

/// Where a frame's time went, in the order it is spent; the parts sum to the frame's
/// `total_ms`.
#[derive(Serialize, Debug, Default, Clone, Copy)]
pub struct FramePhases {
    /// Evaluating the graph: the nodes' CPU work (each node's `cpu_ms` is part of it),
    /// recording and submitting GPU commands, the evaluator's bookkeeping.
    pub evaluate_ms: f64,
    /// Waiting for background loads (files, caches) to arrive.
    pub loads_ms: f64,
    /// Waiting for the GPU to finish the frame and reading its timestamps back (where the
    /// adapter has none, that wait falls into `readback_ms`).
    pub gpu_wait_ms: f64,
    /// Reading output images back from the GPU, box-filtering supersampled ones.
    pub readback_ms: f64,
    /// Encoding and writing the output files.
    pub write_ms: f64,
    /// Everything else: warnings, statistics, the progress bar.
    pub other_ms: f64,
}

#[derive(Serialize, Debug)]
pub struct FrameStats {
    pub frame: i64,
    /// From the frame's start until the GPU finished it (evaluate + loads + gpu_wait).
    pub wall_ms: f64,
    /// The whole frame, its files written.
    pub total_ms: f64,
    pub phases: FramePhases,
    pub nodes: BTreeMap<String, NodeTiming>,
    /// GPU textures and buffers created during the frame (evaluation and writing outputs);
    /// a steady animation creates none after its first frame.
    pub gpu_created: gpu::Created,
}

#[derive(Serialize, Debug)]
pub struct Stats {
    /// The command line of the run, so that stats.json alone says how to repeat it.
    pub command: Vec<String>,
    pub version: &'static str,
    /// The commit the binary was built from, when it was built in a git checkout.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub git_commit: Option<&'static str>,
    pub graph: String,
    /// FNV-1a 64 of the graph's canonical text (after --set), hex; absent when it did not load.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub graph_hash: Option<String>,
    /// The `--set` overrides, as given.
    pub sets: Vec<String>,
    /// The inclusive frame range asked for.
    pub frame_range: [i64; 2],
    pub fps: f64,
    pub adapter: String,
    pub width: u32,
    pub height: u32,
    /// Supersampling factor per axis (1: none).
    pub ssaa: u32,
    pub frames: Vec<FrameStats>,
    /// Values reported by Watch nodes, one per frame.
    pub values: BTreeMap<String, Vec<f64>>,
    /// Files written, relative to the output folder.
    pub files: Vec<String>,
    /// Warnings about the run as a whole (first frame's node warnings included).
    pub warnings: Vec<String>,
    /// Why the run failed; absent when it succeeded.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
}

impl Stats {
    /// The record of a run before anything rendered: what was asked for.
    pub fn new(opts: &RenderOptions) -> Stats {
        Stats {
            command: opts.command.clone(),
            version: env!("CARGO_PKG_VERSION"),
            git_commit: option_env!("WERKSTATT_GIT_COMMIT"),
            graph: opts.graph_path.display().to_string(),
            graph_hash: None,
            sets: opts.sets.clone(),
            frame_range: [opts.frames.0, opts.frames.1],
            fps: opts.fps,
            adapter: String::new(),
            width: opts.width,
            height: opts.height,
            ssaa: opts.ssaa,
            frames: Vec::new(),
            values: BTreeMap::new(),
            files: Vec::new(),
            warnings: Vec::new(),
            error: None,
        }
    }
}

/// Writes a stats.json that records a run which failed before rendering (the graph did not
/// load, no GPU), so CI finds the reason where it looks for results. Best effort: the
/// original error is what the caller reports.
pub fn record_failure(opts: &RenderOptions, error: &anyhow::Error) {
    let mut stats = Stats::new(opts);
    stats.error = Some(format!("{error:#}"));
    if std::fs::create_dir_all(&opts.out_dir).is_ok() {
        let _ = write_stats(&opts.out_dir, &stats);
    }
}

/// How long batch rendering waits for one frame's pending nodes before failing, by default.
pub const PENDING_LIMIT: std::time::Duration = std::time::Duration::from_secs(120);

/// Loads the graph and applies `--set` overrides, re-validating afterwards; files the graph
/// names must exist (see [`check_files`]).
pub fn load_with_overrides(path: &Path, sets: &[String]) -> anyhow::Result<Graph> {
    let mut graph = Graph::load(path).map_err(|e| anyhow::anyhow!("{e}"))?;
    for s in sets {
        graph.set_from_cli(s)?;
    }
    check_files(&graph, path)?;
    Ok(graph)
}

/// Loads the graph (with `--set` overrides) and renders the frames; returns the statistics
/// (also written to `stats.json`, with an `error` when the run fails).
pub fn render(opts: &RenderOptions, gpu: &GpuContext) -> anyhow::Result<Stats> {
    let graph = load_with_overrides(&opts.graph_path, &opts.sets).inspect_err(|e| record_failure(opts, e))?;
    render_graph(opts, &graph, gpu)
}

/// The variants of a sweep, each with its options (its own folder under `opts.out_dir`, named
/// by its assignments) and its graph with the overrides applied. Every variant is loaded and
/// validated here, so a bad value fails before anything renders.
pub fn plan_sweep(opts: &RenderOptions) -> anyhow::Result<Vec<(Vec<String>, RenderOptions, Graph)>> {
    let sweep = crate::app::sweep::Sweep::parse(&opts.sets)?;
    sweep
        .variants()
        .into_iter()
        .map(|variant| {
            let mut o = opts.clone();
            o.sets = sweep.fixed.iter().chain(&variant).cloned().collect();
            if !sweep.axes.is_empty() {
                o.out_dir = opts.out_dir.join(crate::app::sweep::variant_name(&variant));
            }
            let graph = load_with_overrides(&o.graph_path, &o.sets)
                .map_err(|e| if variant.is_empty() { e } else { e.context(format!("variant {}", variant.join(" "))) })
                .inspect_err(|e| record_failure(&o, e))?;
            Ok((variant, o, graph))
        })
        .collect()
}

/// Fails, naming every missing file with its line and column and a did-you-mean, when a path
/// parameter names a file that does not exist: before the GPU starts rather than seconds in.
pub fn check_files(graph: &Graph, graph_path: &Path) -> anyhow::Result<()> {
    let missing = graph.missing_files(graph_path.parent().unwrap_or(Path::new("")));
    if missing.is_empty() {
        return Ok(());
    }
    let source = std::fs::read_to_string(graph_path).unwrap_or_default();
    let lines: Vec<String> = missing
        .iter()
        .map(|w| {
            let (line, col) = w.line_col(&source);
            format!("{}:{line}:{col}: {w}", graph_path.display())
        })
        .collect();
    bail!("{}", lines.join("\n"))
}

/// Writes the contact sheets of a rendered sweep into `out`: for every PNG a variant wrote,
/// `contact_sheet.png` (or `contact_sheet_<file>.png` when each variant wrote several), the
/// variants in rows of the last axis's values, each labelled with its assignments. Returns
/// the files written.
pub fn write_contact_sheets(
    out: &Path,
    runs: &[(Vec<String>, RenderOptions, Stats)],
    columns: usize,
) -> anyhow::Result<Vec<PathBuf>> {
    use crate::app::contact_sheet::{Cell, montage};
    let Some((_, _, first)) = runs.first() else { return Ok(Vec::new()) };
    let pngs: Vec<&String> = first.files.iter().filter(|f| f.ends_with(".png")).collect();
    let mut written = Vec::new();
    for png in &pngs {
        let mut cells = Vec::new();
        for (variant, o, _) in runs {
            let path = o.out_dir.join(png);
            let image = image::open(&path).with_context(|| format!("cannot read {}", path.display()))?.to_rgba8();
            let mut label = variant.clone();
            if pngs.len() > 1 {
                label.push((*png).clone());
            }
            cells.push(Cell { image, label });
        }
        let name = if pngs.len() == 1 {
            "contact_sheet.png".to_string()
        } else {
            format!("contact_sheet_{}.png", png.trim_end_matches(".png"))
        };
        let mut bytes = std::io::Cursor::new(Vec::new());
        montage(&cells, columns).write_to(&mut bytes, image::ImageFormat::Png)?;
        let path = out.join(name);
        crate::io::atomic::write_atomic(&path, bytes.get_ref())
            .with_context(|| format!("cannot write {}", path.display()))?;
        written.push(path);
    }
    Ok(written)
}

/// Renders the frames of a loaded graph (`opts.sets` already applied). On failure stats.json
/// keeps the frames that rendered and says why the run stopped.
pub fn render_graph(opts: &RenderOptions, graph: &Graph, gpu: &GpuContext) -> anyhow::Result<Stats> {
    let mut stats = Stats::new(opts);
    stats.graph_hash = Some(format!("{:016x}", crate::core::hash::fnv1a(graph.to_ron().as_bytes())));
    stats.adapter = gpu.adapter_name();
    match render_frames(opts, graph, gpu, &mut stats) {
        Ok(()) => {
            write_stats(&opts.out_dir, &stats)?;
            Ok(stats)
        }
        Err(e) => {
            stats.error = Some(format!("{e:#}"));
            if std::fs::create_dir_all(&opts.out_dir).is_ok() {
                let _ = write_stats(&opts.out_dir, &stats);
            }
            Err(e)
        }
    }
}

/// Frames of an output node with a fixed `frame` parameter (ExportGeometry's `frame: 24`)
/// that the range never reaches: the node would write nothing, which must not pass silently.
fn fixed_frame_warnings(graph: &Graph, (first, last): (i64, i64)) -> Vec<String> {
    let mut out = Vec::new();
    for (id, node) in &graph.nodes {
        let Some(spec) = crate::core::spec::find(&node.kind).filter(|s| s.is_output()) else { continue };
        let Some((_, p)) = spec.param("frame") else { continue };
        let frame = node.params.get("frame").and_then(crate::core::param::ParamValue::as_f64).unwrap_or(match p.kind {
            crate::core::param::ParamKind::Int { default, .. } => default as f64,
            _ => -1.0,
        }) as i64;
        if frame >= 0 && !(first..=last).contains(&frame) {
            out.push(format!(
                "node \"{id}\" ({}) writes only frame {frame}, outside the rendered frames {first}..{last}: it writes nothing",
                spec.kind
            ));
        }
    }
    out
}

fn render_frames(opts: &RenderOptions, graph: &Graph, gpu: &GpuContext, stats: &mut Stats) -> anyhow::Result<()> {
    let dumps: Vec<PortRef> = opts.dumps.iter().map(|d| parse_dump(graph, d)).collect::<anyhow::Result<_>>()?;
    let extra_roots: Vec<String> = dumps.iter().map(|d| d.node.clone()).collect();
    let mut evaluator = Evaluator::new(graph, &extra_roots)?;
    if evaluator.roots().next().is_none() {
        bail!(
            "{}: the graph has no output node (ImageWrite, Preview or Watch), so there is nothing to render",
            opts.graph_path.display()
        );
    }
    std::fs::create_dir_all(&opts.out_dir).with_context(|| format!("cannot create {}", opts.out_dir.display()))?;
    let resources = Resources::new(false);
    let settings = FrameSettings {
        width: opts.width * opts.ssaa.max(1),
        height: opts.height * opts.ssaa.max(1),
        frames: Some(opts.frames),
        base_dir: opts.graph_path.parent().map(Path::to_path_buf).unwrap_or_default(),
    };
    let (first, last) = opts.frames;
    for w in fixed_frame_warnings(graph, opts.frames) {
        eprintln!("warning: {w}");
        stats.warnings.push(w);
    }
    let bar = opts.progress.then(|| {
        let bar = indicatif::ProgressBar::new(last.saturating_sub(first).saturating_add(1) as u64);
        bar.set_style(
            indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} frames {elapsed} (eta {eta})")
                .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
        );
        bar
    });
    // USD exports of each node: one cache file for the frame range, written after the last frame.
    let mut caches: BTreeMap<String, Vec<(i64, Arc<crate::mesh::Mesh>)>> = BTreeMap::new();
    for frame in first..=last {
        let time = FrameTime { frame, fps: opts.fps };
        let start = Instant::now();
        let created_before = gpu.created();
        let mut nodes = BTreeMap::new();
        let loads =
            settle(&mut evaluator, time, gpu, &resources, &settings, start, opts.pending_timeout, |evaluator| {
                for r in evaluator.reports() {
                    let t = nodes.entry(r.id.to_string()).or_insert(NodeTiming {
                        cpu_ms: 0.0,
                        gpu_ms: None,
                        ran: false,
                        counts: BTreeMap::new(),
                    });
                    t.cpu_ms += r.cpu.as_secs_f64() * 1e3;
                    t.ran |= r.ran;
                    t.counts = r.counts.iter().copied().collect();
                }
            })?;
        let settled = start.elapsed();
        for (node, ms) in gpu.collect_timings() {
            if let Some(t) = nodes.get_mut(&*node) {
                *t.gpu_ms.get_or_insert(0.0) += ms;
            }
        }
        let wall = start.elapsed();
        let wall_ms = ms(wall);
        let mut phases = FramePhases {
            evaluate_ms: ms(settled.saturating_sub(loads)),
            loads_ms: ms(loads),
            gpu_wait_ms: ms(wall - settled),
            ..FramePhases::default()
        };
        let failures = failures(&evaluator);
        if !failures.is_empty() {
            if let Some(b) = &bar {
                b.abandon();
            }
            // Keep the statistics of the frames that worked: CI wants them most when a frame fails.
            let gpu_created = gpu.created().since(created_before);
            let total_ms = phases.close(start);
            stats.frames.push(FrameStats { frame, wall_ms, total_ms, phases, nodes, gpu_created });
            bail!("frame {frame}: {}", failures.join("\n  "));
        }
        for r in evaluator.reports() {
            for w in r.warnings {
                if frame == first {
                    let w = format!("node \"{}\" ({}): {w}", r.id, r.kind);
                    eprintln!("warning: {w}");
                    stats.warnings.push(w);
                }
            }
        }
        let roots: Vec<String> = evaluator.roots().map(str::to_string).collect();
        for id in &roots {
            for product in evaluator.products(id) {
                let name = |ext: &str| format!("{id}_{frame:04}.{ext}");
                match product {
                    Product::Image { image, format } => {
                        let name = name(format.name());
                        let px = timed(&mut phases.readback_ms, || resolve(gpu, image, opts))?;
                        timed(&mut phases.write_ms, || {
                            crate::io::image::write_image(&opts.out_dir.join(&name), &px, *format)
                        })?;
                        stats.files.push(name);
                    }
                    Product::Geometry { mesh, format: GeometryFormat::Usda, .. } => {
                        caches.entry(id.clone()).or_default().push((frame, mesh.clone()));
                    }
                    Product::Geometry { mesh, parts, format } => {
                        let name = name(format.name());
                        timed(&mut phases.write_ms, || {
                            crate::io::geometry::write_geometry(&opts.out_dir.join(&name), mesh, parts, *format)
                        })?;
                        stats.files.push(name);
                    }
                    Product::Value(v) => stats.values.entry(id.clone()).or_default().push(*v),
                }
            }
        }
        for d in &dumps {
            let value = evaluator.output(&d.node, &d.port);
            let Some(img) = value.and_then(Value::as_texture) else {
                bail!("--dump {d}: the port holds no texture this frame");
            };
            let format = opts.dump_format.unwrap_or(match img.format {
                wgpu::TextureFormat::Rgba8UnormSrgb | wgpu::TextureFormat::Rgba8Unorm => ImageFormat::Png,
                _ => ImageFormat::Exr,
            });
            let name = format!("{}.{}_{frame:04}.{}", d.node, d.port, format.name());
            let mut px = timed(&mut phases.readback_ms, || resolve(gpu, img, opts))?;
            timed(&mut phases.write_ms, || {
                if format == ImageFormat::Png {
                    crate::io::image::tonemap_for_png(&mut px);
                }
                crate::io::image::write_image(&opts.out_dir.join(&name), &px, format)
            })?;
            stats.files.push(name);
        }
        let gpu_created = gpu.created().since(created_before);
        let total_ms = phases.close(start);
        stats.frames.push(FrameStats { frame, wall_ms, total_ms, phases, nodes, gpu_created });
        if let Some(b) = &bar {
            b.inc(1);
        }
    }
    if let Some(b) = &bar {
        b.finish_and_clear();
    }
    for (id, frames) in caches {
        let name = format!("{id}.usda");
        let frames: Vec<(i64, &crate::mesh::Mesh)> = frames.iter().map(|(f, m)| (*f, &**m)).collect();
        crate::io::usda::write_usda(&opts.out_dir.join(&name), opts.fps, &frames)?;
        stats.files.push(name);
    }
    Ok(())
}

fn ms(d: std::time::Duration) -> f64 {
    d.as_secs_f64() * 1e3
}

/// Runs `f`, adding its duration to `acc` (milliseconds).
fn timed<T>(acc: &mut f64, f: impl FnOnce() -> T) -> T {
    let start = Instant::now();
    let out = f();
    *acc += ms(start.elapsed());
    out
}

impl FramePhases {
    /// The frame's total time since `start`; what the measured phases leave becomes
    /// `other_ms`.
    fn close(&mut self, start: Instant) -> f64 {
        let total = ms(start.elapsed());
        let measured = self.evaluate_ms + self.loads_ms + self.gpu_wait_ms + self.readback_ms + self.write_ms;
        self.other_ms = (total - measured).max(0.0);
        total
    }
}

/// Evaluates one frame the way batch rendering does: evaluate, wait for the resources, repeat
/// until nothing is pending, so the result is deterministic. `after_pass` sees the evaluator
/// after every pass (the runner sums node timings there). Returns the time spent waiting for
/// resources. Fails when nothing will arrive (a live link without a sender) or after `timeout`
/// from `start`.
#[allow(clippy::too_many_arguments)]
pub fn settle(
    evaluator: &mut Evaluator,
    time: FrameTime,
    gpu: &GpuContext,
    resources: &Resources,
    settings: &FrameSettings,
    start: Instant,
    timeout: std::time::Duration,
    mut after_pass: impl FnMut(&Evaluator),
) -> anyhow::Result<std::time::Duration> {
    let frame = time.frame;
    let mut waited = std::time::Duration::ZERO;
    loop {
        let summary = evaluator.evaluate(time, Some(gpu), resources, settings);
        after_pass(evaluator);
        if summary.pending == 0 {
            return Ok(waited);
        }
        if resources.in_flight() == 0 && summary.ran == 0 {
            bail!("frame {frame}: {}", nothing_will_arrive(evaluator));
        }
        // A node waiting on an external source (a live link with no sender) never settles.
        if start.elapsed() > timeout {
            bail!(
                "frame {frame}: still pending after {:.1} s (--pending-timeout): {}",
                timeout.as_secs_f64(),
                failures(evaluator).join("; ")
            );
        }
        // Bounded too: a loader that never returns fails the frame above instead of hanging.
        let wait = Instant::now();
        resources.wait_idle_timeout(timeout.saturating_sub(start.elapsed()));
        if resources.in_flight() == 0 {
            std::thread::sleep(std::time::Duration::from_millis(1));
        }
        waited += wait.elapsed();
    }
}

/// Reads an image back at the output size: a supersampled frame-sized image is box-filtered
/// down; other sizes (a matrix texture, a shadow atlas) do not scale with the frame and are
/// written as they are.
fn resolve(gpu: &GpuContext, image: &gpu::GpuImage, opts: &RenderOptions) -> anyhow::Result<gpu::Pixels> {
    let px = gpu::read_back(gpu, image)?;
    let n = opts.ssaa.max(1);
    Ok(if n > 1 && (px.width, px.height) == (opts.width * n, opts.height * n) {
        crate::io::image::downsample_box(&px, n)
    } else {
        px
    })
}

fn write_stats(dir: &Path, stats: &Stats) -> anyhow::Result<()> {
    let json = serde_json::to_string_pretty(stats)?;
    crate::io::atomic::write_atomic(&dir.join("stats.json"), json.as_bytes())
        .with_context(|| format!("cannot write {}/stats.json", dir.display()))
}

fn parse_dump(graph: &Graph, text: &str) -> anyhow::Result<PortRef> {
    let r = PortRef::parse(text).with_context(|| format!("--dump \"{text}\": expected node.port"))?;
    let node = graph.nodes.get(&r.node).with_context(|| format!("--dump {text}: there is no node \"{}\"", r.node))?;
    let spec = crate::core::spec::find(&node.kind).context("unknown kind")?;
    let Some((_, port)) = spec.output(&r.port) else {
        bail!(
            "--dump {text}: {} has no output \"{}\"; its outputs are: {}",
            spec.kind,
            r.port,
            spec.outputs.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
        );
    };
    if !port.ty.viewable() {
        bail!("--dump {text}: the port is a {}, not a texture", port.ty);
    }
    Ok(r)
}

/// Why a batch render cannot settle: the pending nodes wait for something that no file load
/// will bring (a `LiveLink` waits for a simulator to connect), with what to do instead.
fn nothing_will_arrive(ev: &Evaluator) -> String {
    let waiting = failures(ev);
    // A pending external source (a LiveLink waiting for a simulator) says what to do instead.
    let help = ev
        .reports()
        .filter(|r| matches!(r.status, NodeStatus::Pending(_)))
        .filter_map(|r| crate::core::spec::find(r.kind)?.capabilities.batch_help())
        .next();
    let mut msg = format!("nothing will arrive in a batch render: {}", waiting.join("; "));
    if let Some(help) = help {
        msg.push_str(&format!("\n  help: {help}"));
    }
    msg
}

/// Messages for every failed node, naming node and kind.
pub fn failures(ev: &Evaluator) -> Vec<String> {
    ev.reports()
        .filter_map(|r| match r.status {
            NodeStatus::Failed(m) => Some(format!("node \"{}\" ({}) failed: {m}", r.id, r.kind)),
            NodeStatus::Pending(p) => {
                Some(format!("node \"{}\" ({}) is still waiting for {}", r.id, r.kind, p.display()))
            }
            _ => None,
        })
        .collect()
}

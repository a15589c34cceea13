//! `werkstatt test`: renders saved graphs and compares every output (images, EXR, exported
//! geometry, `Watch` values) with stored references, under tolerances from a small RON
//! manifest beside the references; sweeps of parameter values, shards for cluster schedulers,
//! and the reports (results.json, JUnit XML, HTML; see [`report`]).
//!
//! The unit of work is a *case*: one graph with one set of parameter values (a sweep's
//! variant) over its frames, or over a part of them with `frames_per_case`. Cases are named
//! (`tablecloth`, `default@median_cut.count=4`, `tablecloth@frames=0-11`), sorted by name, and
//! shard `I/N` runs the cases whose position in that order is I modulo N. Each case renders into `<out>/<case>/`, and its references live in
//! `<references>/<case>/`: the files it wrote and `reference.ron` (the file list, the `Watch`
//! values and the render time at the last `--bless`).

use std::collections::{BTreeMap, BTreeSet};
use std::path::{Path, PathBuf};
use std::time::Instant;

use anyhow::{Context as _, bail};
use serde::{Deserialize, Serialize};

use crate::app::compare::{self, ImageTolerance};
use crate::app::render::{self, RenderOptions};
use crate::app::sweep::{Sweep, parse_axis, product, sanitize};
use crate::gpu::GpuContext;

pub mod report;

/// The file name of a manifest; a folder of references may hold one.
pub const MANIFEST: &str = "manifest.ron";
/// The file in each case's reference folder that lists its outputs, values and timing.
pub const REFERENCE: &str = "reference.ron";
/// The run's machine-readable results, which `werkstatt report merge` reads.
pub const RESULTS: &str = "results.json";

/// The tolerances of a case (or of one of its outputs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Tolerances {
    /// 8-bit images (PNG): threshold in levels.
    pub image: ImageTolerance,
    /// Float images (EXR): threshold in absolute value.
    pub exr: ImageTolerance,
    /// Numbers in text outputs (OBJ geometry): absolute difference.
    pub text: f64,
    /// `Watch` values: absolute difference.
    pub value: f64,
    /// Flag (not fail) a case whose render takes more than this factor times its reference time.
    pub slowdown: f64,
}

impl Default for Tolerances {
    fn default() -> Self {
        Tolerances {
            image: ImageTolerance::default(),
            exr: ImageTolerance { threshold: 0.01, ..ImageTolerance::default() },
            text: 1e-4,
            value: 1e-6,
            slowdown: 2.0,
        }
    }
}

/// What the manifest says about the cases of one graph (keyed by the graph's file stem).
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct CaseConfig {
    /// `node.param=value` overrides applied to every variant.
    pub sets: Vec<String>,
    /// Sweep axes, `node.param=a,b,c` each: one case per combination.
    pub sweep: Vec<String>,
    pub size: Option<(u32, u32)>,
    /// Inclusive frame range.
    pub frames: Option<(i64, i64)>,
    /// Split the frames into cases of this many frames each (see [`Manifest::frames_per_case`]).
    pub frames_per_case: Option<u32>,
    /// Replaces the manifest's tolerances for this graph (fields not written: built-in defaults).
    pub tolerance: Option<Tolerances>,
    /// Tolerances of single outputs, by file name (`image_0000.png`).
    pub outputs: BTreeMap<String, Tolerances>,
    /// The render must fail with a message containing this text (a graph that cannot render
    /// in batch, such as a `LiveLink` without a sender); there are no references then.
    pub expect_error: Option<String>,
}

/// `manifest.ron`: which graphs, at what size and frames, with which tolerances.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Manifest {
    /// Graph files and folders (every `.ron` directly inside), relative to the manifest.
    pub graphs: Vec<String>,
    pub size: (u32, u32),
    pub frames: (i64, i64),
    /// Split each graph's frames into cases of this many frames (`tablecloth@frames=0-11`,
    /// ...), so that shards share out long animations too. Each such case renders its frames
    /// on its own: nodes that depend on earlier frames replay them (ClothSim simulates from
    /// the start), so the outputs are those of one run over all frames, at more cost.
    /// 0: one case for all frames.
    pub frames_per_case: u32,
    pub fps: f64,
    pub tolerance: Tolerances,
    /// Per graph, by file stem.
    pub cases: BTreeMap<String, CaseConfig>,
}

impl Default for Manifest {
    fn default() -> Self {
        Manifest {
            graphs: Vec::new(),
            size: (160, 120),
            frames: (0, 0),
            frames_per_case: 0,
            fps: 30.0,
            tolerance: Tolerances::default(),
            cases: BTreeMap::new(),
        }
    }
}

impl Manifest {
    pub fn load(path: &Path) -> anyhow::Result<Manifest> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        parse_ron(&text, path)
    }
}

/// Parses RON text read from `path`; an error names the file, line and column.
fn parse_ron<T: serde::de::DeserializeOwned>(text: &str, path: &Path) -> anyhow::Result<T> {
    ron::from_str(text)
        .map_err(|e| anyhow::anyhow!("{}:{}:{}: {}", path.display(), e.span.start.line, e.span.start.col, e.code))
}

/// What `werkstatt test` was asked to do.
#[derive(Clone, Debug)]
pub struct TestOptions {
    /// Graph files, folders of graphs, or one manifest (a file named `manifest.ron` or
    /// `*.manifest.ron`).
    pub inputs: Vec<PathBuf>,
    /// The references' folder for graphs given directly (a manifest's references sit beside
    /// it); a `manifest.ron` there gives the sizes and tolerances.
    pub references: PathBuf,
    pub out_dir: PathBuf,
    /// Accept the current outputs as the new references.
    pub bless: bool,
    /// `node.param=value` (an override) or `node.param=a,b,c` (a sweep axis), for every graph.
    pub sets: Vec<String>,
    /// A RON list of sweep axes, `["node.param=a,b", ...]`.
    pub sweep_file: Option<PathBuf>,
    /// This run's shard (index, count).
    pub shard: (usize, usize),
    /// Fail a case that is slower than its reference by more than its `slowdown` tolerance
    /// (by default such a case is only flagged).
    pub fail_on_slowdown: bool,
}

impl TestOptions {
    pub fn new(inputs: Vec<PathBuf>, out_dir: PathBuf) -> TestOptions {
        TestOptions {
            inputs,
            references: PathBuf::from("tests/references"),
            out_dir,
            bless: false,
            sets: Vec::new(),
            sweep_file: None,
            shard: (0, 1),
            fail_on_slowdown: false,
        }
    }
}

/// One graph with one set of parameter values.
#[derive(Clone, Debug)]
pub struct Case {
    pub name: String,
    pub graph: PathBuf,
    /// The overrides of this case: the fixed ones, then the variant's.
    pub sets: Vec<String>,
    /// The variant's assignments (empty without a sweep).
    pub variant: Vec<String>,
    pub size: (u32, u32),
    pub frames: (i64, i64),
    pub fps: f64,
    pub tolerance: Tolerances,
    pub outputs: BTreeMap<String, Tolerances>,
    pub expect_error: Option<String>,
    /// `<references>/<name>`.
    pub reference_dir: PathBuf,
}

/// The full, sorted list of cases of a run (before sharding).
pub fn plan(opts: &TestOptions) -> anyhow::Result<Vec<Case>> {
    let is_manifest = |p: &Path| p.is_file() && p.file_name().is_some_and(|n| n.to_string_lossy().ends_with(MANIFEST));
    let (manifest, base, graphs) = match opts.inputs.as_slice() {
        [one] if is_manifest(one) => {
            let m = Manifest::load(one)?;
            let base = one.parent().map(Path::to_path_buf).unwrap_or_default();
            if m.graphs.is_empty() {
                bail!("{}: the manifest lists no graphs (graphs: [\"../graphs\", ...])", one.display());
            }
            let graphs = m.graphs.iter().map(|g| clean(&base.join(g))).collect::<Vec<_>>();
            (m, base, graphs)
        }
        inputs => {
            if let Some(m) = inputs.iter().find(|p| is_manifest(p)) {
                bail!("{}: a manifest is given alone, not together with graphs or other manifests", m.display());
            }
            if inputs.is_empty() {
                bail!("no graphs to test: give graph files, folders or a manifest.ron");
            }
            let path = opts.references.join(MANIFEST);
            let m = if path.exists() { Manifest::load(&path)? } else { Manifest::default() };
            (m, opts.references.clone(), inputs.to_vec())
        }
    };
    let mut files = Vec::new();
    for g in &graphs {
        if g.is_dir() {
            let mut inside: Vec<PathBuf> = std::fs::read_dir(g)
                .with_context(|| format!("cannot read the folder {}", g.display()))?
                .filter_map(|e| e.ok().map(|e| e.path()))
                .filter(|p| {
                    p.extension().is_some_and(|e| e == "ron") && !p.to_string_lossy().ends_with(".autosave.ron")
                })
                .collect();
            inside.sort();
            files.extend(inside);
        } else if g.is_file() {
            files.push(g.clone());
        } else {
            bail!("{}: no such graph or folder", g.display());
        }
    }
    let Sweep { fixed: fixed_cli, axes: mut axes_cli } = Sweep::parse(&opts.sets)?;
    if let Some(path) = &opts.sweep_file {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let list: Vec<String> =
            parse_ron(&text, path).context("a sweep file is a RON list of \"node.param=a,b,c\" strings")?;
        for s in &list {
            axes_cli.push(parse_axis(s).with_context(|| format!("in {}", path.display()))?);
        }
    }
    let known: BTreeSet<String> = files.iter().map(|f| stem(f)).collect();
    if let Some(unknown) = manifest.cases.keys().find(|k| !known.contains(*k))
        && opts.inputs.len() == 1
        && is_manifest(&opts.inputs[0])
    {
        bail!(
            "{}: cases: \"{unknown}\" is not the stem of any graph listed (graphs: {})",
            opts.inputs[0].display(),
            known.iter().cloned().collect::<Vec<_>>().join(", ")
        );
    }
    let mut cases: Vec<Case> = Vec::new();
    for file in files {
        let stem = stem(&file);
        let config = manifest.cases.get(&stem).cloned().unwrap_or_default();
        let mut axes = config.sweep.iter().map(|s| parse_axis(s)).collect::<anyhow::Result<Vec<_>>>()?;
        axes.extend(axes_cli.iter().cloned());
        let mut fixed = config.sets.clone();
        fixed.extend(fixed_cli.iter().cloned());
        let (first, last) = config.frames.unwrap_or(manifest.frames);
        let per_case = config.frames_per_case.unwrap_or(manifest.frames_per_case) as i64;
        let chunks: Vec<(i64, i64)> = if per_case > 0 && last - first + 1 > per_case {
            (first..=last).step_by(per_case as usize).map(|a| (a, (a + per_case - 1).min(last))).collect()
        } else {
            vec![(first, last)]
        };
        for variant in product(&axes) {
            for &(a, b) in &chunks {
                let mut suffix = variant.clone();
                if chunks.len() > 1 {
                    suffix.push(format!("frames={a}-{b}"));
                }
                let name =
                    if suffix.is_empty() { stem.clone() } else { sanitize(&format!("{stem}@{}", suffix.join("+"))) };
                if let Some(other) = cases.iter().find(|c| c.name == name) {
                    bail!(
                        "two cases are named \"{name}\": {} and {}; graphs tested together need distinct file names",
                        other.graph.display(),
                        file.display()
                    );
                }
                cases.push(Case {
                    reference_dir: base.join(&name),
                    name,
                    graph: file.clone(),
                    sets: fixed.iter().cloned().chain(variant.iter().cloned()).collect(),
                    variant: variant.clone(),
                    size: config.size.unwrap_or(manifest.size),
                    frames: (a, b),
                    fps: manifest.fps,
                    tolerance: config.tolerance.clone().unwrap_or_else(|| manifest.tolerance.clone()),
                    outputs: config.outputs.clone(),
                    expect_error: config.expect_error.clone(),
                });
            }
        }
    }
    cases.sort_by(|a, b| a.name.cmp(&b.name));
    Ok(cases)
}

/// `a/b/../c` as `a/c` (without touching the file system), so reports name graphs plainly.
fn clean(path: &Path) -> PathBuf {
    use std::path::Component;
    let mut out = PathBuf::new();
    for c in path.components() {
        match c {
            Component::ParentDir if matches!(out.components().next_back(), Some(Component::Normal(_))) => {
                out.pop();
            }
            Component::CurDir => {}
            c => out.push(c),
        }
    }
    out
}

fn stem(path: &Path) -> String {
    path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default()
}

/// The shard of this run: `--shard I/N`, else Slurm's array variables
/// (`SLURM_ARRAY_TASK_ID` - `SLURM_ARRAY_TASK_MIN`, `SLURM_ARRAY_TASK_COUNT`), else a
/// Kubernetes indexed Job's `JOB_COMPLETION_INDEX` with `WERKSTATT_SHARD_COUNT` (the Job's
/// `completions`), else the whole run (0/1). `env` reads a variable.
pub fn shard_from(flag: Option<&str>, env: impl Fn(&str) -> Option<String>) -> anyhow::Result<(usize, usize)> {
    let check = |i: usize, n: usize, from: &str| -> anyhow::Result<(usize, usize)> {
        if n == 0 || i >= n {
            bail!("{from}: shard {i} of {n} does not exist (shards are numbered 0..N-1, N >= 1)");
        }
        Ok((i, n))
    };
    let number = |name: &str, text: &str| -> anyhow::Result<usize> {
        text.trim().parse().with_context(|| format!("{name}=\"{text}\" is not a whole number"))
    };
    if let Some(flag) = flag {
        let (i, n) = flag.split_once('/').with_context(|| format!("--shard \"{flag}\": expected I/N, e.g. 0/4"))?;
        return check(number("--shard", i)?, number("--shard", n)?, &format!("--shard {flag}"));
    }
    if let (Some(id), Some(count)) = (env("SLURM_ARRAY_TASK_ID"), env("SLURM_ARRAY_TASK_COUNT")) {
        let min = env("SLURM_ARRAY_TASK_MIN").map(|m| number("SLURM_ARRAY_TASK_MIN", &m)).transpose()?.unwrap_or(0);
        let id = number("SLURM_ARRAY_TASK_ID", &id)?;
        let i = id.checked_sub(min).context("SLURM_ARRAY_TASK_ID is below SLURM_ARRAY_TASK_MIN")?;
        return check(i, number("SLURM_ARRAY_TASK_COUNT", &count)?, "Slurm array (--array=0-N with contiguous ids)");
    }
    if let Some(index) = env("JOB_COMPLETION_INDEX") {
        let count = env("WERKSTATT_SHARD_COUNT").context(
            "JOB_COMPLETION_INDEX is set (a Kubernetes indexed Job) but WERKSTATT_SHARD_COUNT is not: set it to the Job's completions",
        )?;
        return check(
            number("JOB_COMPLETION_INDEX", &index)?,
            number("WERKSTATT_SHARD_COUNT", &count)?,
            "Kubernetes indexed Job",
        );
    }
    Ok((0, 1))
}

/// A case's result.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Status {
    Passed,
    /// An output differs from its reference beyond the tolerance.
    Failed,
    /// The case could not be compared: the render failed, or a reference is missing.
    Error,
    /// `--bless` wrote the references.
    Blessed,
}

/// One output of a case, compared.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutputResult {
    /// The file name (`image_0000.png`), or `watch:<node>` for values.
    pub name: String,
    pub passed: bool,
    /// Metrics, or why it failed.
    pub detail: String,
    /// Views for the report, relative to the run's folder: reference, current, diff (PNG).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub images: Option<[String; 3]>,
    /// The factor the diff view's levels were multiplied by (it is scaled to its maximum).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub diff_scale: Option<f64>,
}

#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CaseResult {
    pub name: String,
    pub graph: String,
    pub variant: Vec<String>,
    /// Every `--set` override the case rendered with (the manifest's, then the variant's).
    #[serde(default)]
    pub sets: Vec<String>,
    /// Whether the graph file's bytes differ from those at the last `--bless`; None when the
    /// reference does not record them (blessed before the hash was kept) or was not read.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph_changed: Option<bool>,
    pub status: Status,
    /// Why the case failed or errored (one line per problem).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub message: Option<String>,
    pub outputs: Vec<OutputResult>,
    /// Render time (the frames' wall time) and comparison time, ms.
    pub render_ms: f64,
    pub compare_ms: f64,
    /// The render time recorded at the last `--bless`.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub reference_ms: Option<f64>,
    /// Slower than `slowdown` x the reference time: flagged, not failed.
    pub slow: bool,
}

/// The results of one run (or of merged shards): what `results.json` holds.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TestRun {
    /// Every case of the unsharded run, in order, so that a merge can tell a missing shard.
    pub plan: Vec<String>,
    /// (index, count); merged results are (0, 1) like an unsharded run.
    pub shard: (usize, usize),
    pub cases: Vec<CaseResult>,
}

impl TestRun {
    pub fn count(&self, status: Status) -> usize {
        self.cases.iter().filter(|c| c.status == status).count()
    }

    /// Whether any case failed or errored.
    pub fn regressed(&self) -> bool {
        self.cases.iter().any(|c| matches!(c.status, Status::Failed | Status::Error))
    }

    /// A one-line summary.
    pub fn summary(&self) -> String {
        let (render, compare) = self.cases.iter().fold((0.0, 0.0), |(r, c), x| (r + x.render_ms, c + x.compare_ms));
        format!(
            "{} case(s): {} passed, {} failed, {} errors, {} blessed, {} slow; render {:.0} ms, compare {:.0} ms",
            self.cases.len(),
            self.count(Status::Passed),
            self.count(Status::Failed),
            self.count(Status::Error),
            self.count(Status::Blessed),
            self.cases.iter().filter(|c| c.slow).count(),
            render,
            compare
        )
    }
}

/// What `reference.ron` records about a case at `--bless`.
#[derive(Clone, Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Reference {
    pub files: Vec<String>,
    pub values: BTreeMap<String, Vec<f64>>,
    /// The frames' wall time when blessed, ms (compared, never failing).
    pub render_ms: f64,
    /// FNV-1a of the graph file's bytes when blessed (hex), so that a report can say the
    /// graph changed since (files the graph loads are not included).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub graph_hash: Option<String>,
}

/// The hash `reference.ron` records of a graph file, or None when it cannot be read.
fn graph_hash(graph: &Path) -> Option<String> {
    std::fs::read(graph).ok().map(|bytes| format!("{:016x}", crate::core::hash::fnv1a(&bytes)))
}

/// Runs this shard's cases, writes `results.json`, `junit.xml` and `report.html` into
/// `opts.out_dir`, and returns the results (check [`TestRun::regressed`]). `progress` hears
/// each case as it finishes.
pub fn run(opts: &TestOptions, gpu: &GpuContext, mut progress: impl FnMut(&CaseResult)) -> anyhow::Result<TestRun> {
    let cases = plan(opts)?;
    let (index, count) = opts.shard;
    std::fs::create_dir_all(&opts.out_dir).with_context(|| format!("cannot create {}", opts.out_dir.display()))?;
    let mut results = Vec::new();
    for case in cases.iter().skip(index).step_by(count.max(1)) {
        let r = run_case(case, opts, gpu)?;
        progress(&r);
        results.push(r);
    }
    let run = TestRun { plan: cases.iter().map(|c| c.name.clone()).collect(), shard: opts.shard, cases: results };
    report::write_all(&opts.out_dir, &run)?;
    Ok(run)
}

fn run_case(case: &Case, opts: &TestOptions, gpu: &GpuContext) -> anyhow::Result<CaseResult> {
    let out = opts.out_dir.join(&case.name);
    if out.exists() {
        std::fs::remove_dir_all(&out).with_context(|| format!("cannot clear {}", out.display()))?;
    }
    let ropts = RenderOptions {
        graph_path: case.graph.clone(),
        frames: case.frames,
        fps: case.fps,
        width: case.size.0,
        height: case.size.1,
        out_dir: out.clone(),
        sets: case.sets.clone(),
        dumps: Vec::new(),
        ssaa: 1,
        dump_format: None,
        progress: false,
        command: Vec::new(),
        pending_timeout: crate::app::render::PENDING_LIMIT,
    };
    let rendered = render::render(&ropts, gpu);
    let mut result = CaseResult {
        name: case.name.clone(),
        graph: case.graph.display().to_string(),
        variant: case.variant.clone(),
        sets: case.sets.clone(),
        graph_changed: None,
        status: Status::Passed,
        message: None,
        outputs: Vec::new(),
        render_ms: 0.0,
        compare_ms: 0.0,
        reference_ms: None,
        slow: false,
    };
    let stats = match (rendered, &case.expect_error) {
        (Err(e), Some(expected)) => {
            let msg = format!("{e:#}");
            if !msg.contains(expected.as_str()) {
                result.status = Status::Failed;
                result.message = Some(format!("failed with \"{msg}\", expected a message containing \"{expected}\""));
            }
            return Ok(result);
        }
        (Ok(_), Some(expected)) => {
            result.status = Status::Failed;
            result.message = Some(format!("rendered, but the manifest expects it to fail with \"{expected}\""));
            return Ok(result);
        }
        (Err(e), None) => {
            result.status = Status::Error;
            result.message = Some(format!("the render failed: {e:#}"));
            return Ok(result);
        }
        (Ok(stats), None) => stats,
    };
    result.render_ms = stats.frames.iter().map(|f| f.wall_ms).sum();
    let start = Instant::now();
    if opts.bless {
        bless(case, &out, &stats, result.render_ms)?;
        result.status = Status::Blessed;
        result.compare_ms = start.elapsed().as_secs_f64() * 1e3;
        return Ok(result);
    }
    let reference_file = case.reference_dir.join(REFERENCE);
    let reference: Reference = match std::fs::read_to_string(&reference_file) {
        Ok(text) => parse_ron(&text, &reference_file)?,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => {
            result.status = Status::Error;
            result.message = Some(format!(
                "no reference for case \"{}\": {} does not exist; if the outputs in {} are right, accept them with `werkstatt test --bless` (same arguments)",
                case.name,
                reference_file.display(),
                out.display()
            ));
            return Ok(result);
        }
        Err(e) => return Err(e).with_context(|| format!("cannot read {}", reference_file.display())),
    };
    result.reference_ms = Some(reference.render_ms);
    result.graph_changed = reference.graph_hash.map(|h| graph_hash(&case.graph) != Some(h));
    result.slow = result.render_ms > reference.render_ms * case.tolerance.slowdown;
    if result.slow && opts.fail_on_slowdown {
        result.outputs.push(fail(
            "time",
            format!(
                "{:.1} ms, more than {} x the reference's {:.1} ms (--fail-on-slowdown)",
                result.render_ms, case.tolerance.slowdown, reference.render_ms
            ),
        ));
    }
    let current: BTreeSet<&String> = stats.files.iter().collect();
    let expected: BTreeSet<&String> = reference.files.iter().collect();
    for name in current.union(&expected) {
        let tol = case.outputs.get(name.as_str()).unwrap_or(&case.tolerance);
        let r = match (current.contains(name), expected.contains(name)) {
            (true, false) => fail(name, "a new output without a reference (bless to accept it)".into()),
            (false, _) => fail(name, "missing: the reference has it, this run did not write it".into()),
            (true, true) => compare_file(name, &case.reference_dir, &out, &case.name, tol)?,
        };
        result.outputs.push(r);
    }
    let keys: BTreeSet<&String> = stats.values.keys().chain(reference.values.keys()).collect();
    for key in keys {
        let name = format!("watch:{key}");
        let (cur, refv) = (stats.values.get(key), reference.values.get(key));
        let tol = case.outputs.get(&name).unwrap_or(&case.tolerance).value;
        result.outputs.push(
            match compare::compare_values(refv.map_or(&[][..], Vec::as_slice), cur.map_or(&[][..], Vec::as_slice), tol)
            {
                Ok(()) => OutputResult {
                    name,
                    passed: true,
                    detail: format!("{:?}", cur.unwrap_or(&Vec::new())),
                    images: None,
                    diff_scale: None,
                },
                Err(why) => fail(&name, why),
            },
        );
    }
    let failures: Vec<String> =
        result.outputs.iter().filter(|o| !o.passed).map(|o| format!("{}: {}", o.name, o.detail)).collect();
    if !failures.is_empty() {
        result.status = Status::Failed;
        result.message = Some(failures.join("\n"));
    }
    result.compare_ms = start.elapsed().as_secs_f64() * 1e3;
    Ok(result)
}

fn fail(name: &str, detail: String) -> OutputResult {
    OutputResult { name: name.to_string(), passed: false, detail, images: None, diff_scale: None }
}

/// Compares one output file with its reference; a failing image gets its reference, current
/// and diff views (PNG) written beside the output for the report.
fn compare_file(
    name: &str,
    reference_dir: &Path,
    out: &Path,
    case: &str,
    tol: &Tolerances,
) -> anyhow::Result<OutputResult> {
    let (ref_path, cur_path) = (reference_dir.join(name), out.join(name));
    let ext = Path::new(name).extension().map(|e| e.to_string_lossy().to_lowercase()).unwrap_or_default();
    let open = |p: &Path| image::open(p).with_context(|| format!("cannot read the image {}", p.display()));
    let base = Path::new(name).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let view = |suffix: &str| format!("{base}.{suffix}.png");
    match ext.as_str() {
        "png" | "exr" => {
            let (reference, current) = (open(&ref_path)?, open(&cur_path)?);
            if (reference.width(), reference.height()) != (current.width(), current.height()) {
                return Ok(fail(
                    name,
                    format!(
                        "{}x{}, the reference is {}x{}",
                        current.width(),
                        current.height(),
                        reference.width(),
                        reference.height()
                    ),
                ));
            }
            let (diff, t) = if ext == "png" {
                (compare::compare_rgba8(&reference.to_rgba8(), &current.to_rgba8(), tol.image.threshold), &tol.image)
            } else {
                (compare::compare_rgba32f(&reference.to_rgba32f(), &current.to_rgba32f(), tol.exr.threshold), &tol.exr)
            };
            let Some(why) = diff.verdict(t) else {
                return Ok(OutputResult {
                    name: name.into(),
                    passed: true,
                    detail: diff.summary(),
                    images: None,
                    diff_scale: None,
                });
            };
            let write = |file: &str, img: &image::RgbaImage| -> anyhow::Result<()> {
                let mut bytes = std::io::Cursor::new(Vec::new());
                img.write_to(&mut bytes, image::ImageFormat::Png)?;
                crate::io::atomic::write_atomic(&out.join(file), bytes.get_ref())
                    .with_context(|| format!("cannot write {}", out.join(file).display()))
            };
            let display = |img: &image::DynamicImage| -> image::RgbaImage {
                if ext == "png" {
                    return img.to_rgba8();
                }
                let f = img.to_rgba32f();
                let mut px =
                    crate::gpu::Pixels { width: f.width(), height: f.height(), rgba: f.into_raw(), is_ldr: false };
                crate::io::image::tonemap_for_png(&mut px);
                image::RgbaImage::from_raw(px.width, px.height, crate::io::image::to_rgba8(&px)).expect("sized")
            };
            write(&view("reference"), &display(&reference))?;
            write(&view("diff"), &diff.diff)?;
            let current_view = if ext == "png" {
                name.to_string()
            } else {
                write(&view("current"), &display(&current))?;
                view("current")
            };
            let rel = |f: &str| format!("{case}/{f}");
            Ok(OutputResult {
                name: name.into(),
                passed: false,
                detail: format!("{why}; diff image {} (levels x{:.1})", rel(&view("diff")), diff.diff_scale),
                images: Some([rel(&view("reference")), rel(&current_view), rel(&view("diff"))]),
                diff_scale: Some(diff.diff_scale),
            })
        }
        _ => {
            let read = |p: &Path| std::fs::read(p).with_context(|| format!("cannot read {}", p.display()));
            let (reference, current) = (read(&ref_path)?, read(&cur_path)?);
            let verdict = match (std::str::from_utf8(&reference), std::str::from_utf8(&current)) {
                (Ok(r), Ok(c)) => compare::compare_text(r, c, tol.text),
                _ if reference == current => Ok(()),
                _ => Err(format!("the bytes differ ({} bytes, the reference {})", current.len(), reference.len())),
            };
            Ok(match verdict {
                Ok(()) => OutputResult {
                    name: name.into(),
                    passed: true,
                    detail: "same".into(),
                    images: None,
                    diff_scale: None,
                },
                Err(why) => fail(name, why),
            })
        }
    }
}

/// Makes the current outputs the case's references: copies the files, removes references the
/// run no longer writes, and records the file list, values and render time.
fn bless(case: &Case, out: &Path, stats: &render::Stats, render_ms: f64) -> anyhow::Result<()> {
    let dir = &case.reference_dir;
    std::fs::create_dir_all(dir).with_context(|| format!("cannot create {}", dir.display()))?;
    for f in &stats.files {
        let bytes = std::fs::read(out.join(f)).with_context(|| format!("cannot read {}", out.join(f).display()))?;
        crate::io::atomic::write_atomic(&dir.join(f), &bytes)
            .with_context(|| format!("cannot write {}", dir.join(f).display()))?;
    }
    for entry in std::fs::read_dir(dir)? {
        let name = entry?.file_name().to_string_lossy().into_owned();
        if name != REFERENCE && !stats.files.contains(&name) {
            std::fs::remove_file(dir.join(&name))
                .with_context(|| format!("cannot remove {}", dir.join(&name).display()))?;
        }
    }
    let reference = Reference {
        files: stats.files.clone(),
        values: stats.values.clone(),
        render_ms: (render_ms * 10.0).round() / 10.0,
        graph_hash: graph_hash(&case.graph),
    };
    let text = ron::ser::to_string_pretty(&reference, ron::ser::PrettyConfig::default())? + "\n";
    crate::io::atomic::write_atomic(&dir.join(REFERENCE), text.as_bytes())
        .with_context(|| format!("cannot write {}", dir.join(REFERENCE).display()))
}

/// `werkstatt report merge`: combines the shards' folders into `out`: the cases' folders are
/// copied, and the results, JUnit XML and HTML report written as one unsharded run would.
/// Fails when a shard is missing or two shards ran one case.
pub fn merge(shards: &[PathBuf], out: &Path) -> anyhow::Result<TestRun> {
    let mut plan: Option<Vec<String>> = None;
    let mut cases: BTreeMap<String, (CaseResult, PathBuf)> = BTreeMap::new();
    for dir in shards {
        let path = dir.join(RESULTS);
        let text = std::fs::read_to_string(&path).with_context(|| {
            format!("cannot read {}: is {} the output folder of a `werkstatt test` run?", path.display(), dir.display())
        })?;
        let run: TestRun =
            serde_json::from_str(&text).with_context(|| format!("{}: not a results file", path.display()))?;
        match &plan {
            Some(p) if *p != run.plan => bail!("{}: a run of other cases than {}", path.display(), shards[0].display()),
            _ => plan = Some(run.plan.clone()),
        }
        for c in run.cases {
            if let Some((_, other)) = cases.get(&c.name) {
                bail!("case \"{}\" is in both {} and {}", c.name, other.display(), dir.display());
            }
            cases.insert(c.name.clone(), (c, dir.clone()));
        }
    }
    let plan = plan.context("report merge needs at least one shard folder")?;
    let missing: Vec<&String> = plan.iter().filter(|n| !cases.contains_key(*n)).collect();
    if !missing.is_empty() {
        bail!(
            "{} of {} case(s) are in none of the shards (a shard is missing or failed early): {}",
            missing.len(),
            plan.len(),
            missing.iter().map(|s| s.as_str()).collect::<Vec<_>>().join(", ")
        );
    }
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    let mut merged = Vec::new();
    for name in &plan {
        let (case, dir) = cases.remove(name).expect("checked above");
        copy_dir(&dir.join(name), &out.join(name))?;
        merged.push(case);
    }
    let run = TestRun { plan, shard: (0, 1), cases: merged };
    report::write_all(out, &run)?;
    Ok(run)
}

fn copy_dir(from: &Path, to: &Path) -> anyhow::Result<()> {
    if !from.exists() {
        return Ok(());
    }
    std::fs::create_dir_all(to).with_context(|| format!("cannot create {}", to.display()))?;
    for entry in std::fs::read_dir(from)? {
        let entry = entry?;
        let bytes = std::fs::read(entry.path()).with_context(|| format!("cannot read {}", entry.path().display()))?;
        let target = to.join(entry.file_name());
        crate::io::atomic::write_atomic(&target, &bytes)
            .with_context(|| format!("cannot write {}", target.display()))?;
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_comes_from_the_flag_slurm_or_kubernetes() {
        let none = |_: &str| None;
        assert_eq!(shard_from(None, none).unwrap(), (0, 1));
        assert_eq!(shard_from(Some("1/3"), none).unwrap(), (1, 3));
        assert!(shard_from(Some("3/3"), none).is_err());
        assert!(shard_from(Some("1"), none).is_err());
        let slurm = |k: &str| match k {
            "SLURM_ARRAY_TASK_ID" => Some("5".into()),
            "SLURM_ARRAY_TASK_MIN" => Some("4".into()),
            "SLURM_ARRAY_TASK_COUNT" => Some("2".into()),
            _ => None,
        };
        assert_eq!(shard_from(None, slurm).unwrap(), (1, 2));
        assert_eq!(shard_from(Some("0/2"), slurm).unwrap(), (0, 2), "the flag wins");
        let k8s = |k: &str| match k {
            "JOB_COMPLETION_INDEX" => Some("2".into()),
            "WERKSTATT_SHARD_COUNT" => Some("4".into()),
            _ => None,
        };
        assert_eq!(shard_from(None, k8s).unwrap(), (2, 4));
        let k8s_no_count = |k: &str| (k == "JOB_COMPLETION_INDEX").then(|| "2".to_string());
        assert!(format!("{:#}", shard_from(None, k8s_no_count).unwrap_err()).contains("WERKSTATT_SHARD_COUNT"));
    }
}

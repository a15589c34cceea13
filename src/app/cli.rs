//! The command line: render, test, report, edit, check, fmt, nodes, info, bench, btf.

use std::io::IsTerminal as _;
use std::path::PathBuf;
use std::process::ExitCode;

use clap::{Parser, Subcommand};

use crate::app::bench::{
    AttachRow, CuboidRow, ExportRow, IblRow, MarkdownRow as _, ShadowRow, SsaoRow, Table1Row, TessellationRow,
    WarpCostRow,
};
use crate::core::graph::Graph;
use crate::gpu::{Backend, GpuContext};

#[derive(Parser)]
#[command(
    name = "werkstatt",
    version,
    about = "A real-time garment renderer as a node graph: render, edit, check and format .ron graphs"
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Render a graph headless: one image per output node per frame, plus stats.json.
    Render {
        /// The graph file (.ron).
        graph: PathBuf,
        /// Frames to render: N, or A..B (inclusive).
        #[arg(long, default_value = "0")]
        frames: String,
        /// Frames per second of the animation time.
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        /// Image size WxH.
        #[arg(long, default_value = "640x480")]
        size: String,
        /// Output folder.
        #[arg(long, default_value = "out")]
        out: PathBuf,
        /// Anti-aliasing by supersampling: render every pass at N x the size (N^2 the pixels)
        /// and box-filter the written images down to it.
        #[arg(long, default_value_t = 1, value_parser = clap::value_parser!(u32).range(1..=8))]
        ssaa: u32,
        /// Override a parameter: node.param=value (repeatable). Several values sweep:
        /// node.param=a,b,c or a range a..b:n renders every combination into its own folder
        /// under --out, named by its values.
        #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
        sets: Vec<String>,
        /// With a sweep: also write contact_sheet.png into --out, every variant's image
        /// labelled with its parameter values.
        #[arg(long)]
        contact_sheet: bool,
        /// Also write a texture output: node.port (repeatable), e.g. gbuffer.normal.
        #[arg(long = "dump", value_name = "NODE.PORT")]
        dumps: Vec<String>,
        /// File format of --dump: png (8-bit; float textures tone mapped with x/(1+x), then sRGB)
        /// or exr (values as they are). Default: png for 8-bit textures, exr for float ones.
        #[arg(long, value_parser = ["png", "exr"])]
        dump_format: Option<String>,
        /// Seconds one frame may wait for loads and external sources before the render fails.
        #[arg(long, default_value_t = crate::app::render::PENDING_LIMIT.as_secs_f64())]
        pending_timeout: f64,
        /// GPU backend (or WERKSTATT_BACKEND).
        #[arg(long, value_enum)]
        backend: Option<Backend>,
    },
    /// Open the node editor on a graph (created on save if it does not exist yet).
    #[cfg(all(feature = "editor", not(test)))]
    Edit {
        /// The graph file (.ron); without it the editor starts with a new graph.
        graph: Option<PathBuf>,
        /// GPU backend (or WERKSTATT_BACKEND).
        #[arg(long, value_enum)]
        backend: Option<Backend>,
    },
    /// Validate graphs without a GPU; reports every problem with file, line and node.
    Check {
        #[arg(required = true)]
        graphs: Vec<PathBuf>,
        /// human: one line per problem with a hint; json: one JSON object per problem on
        /// stdout (file, line, column, node, port, message, help), for CI annotations.
        #[arg(long, value_parser = ["human", "json"], default_value = "human")]
        message_format: String,
    },
    /// Render graphs and compare every output with stored references (image regression).
    Test {
        /// Graph files, folders of graphs, or one manifest (manifest.ron or *.manifest.ron).
        #[arg(required = true)]
        inputs: Vec<PathBuf>,
        /// The references of graphs given directly, one folder per case; a manifest.ron there
        /// sets sizes and tolerances. A manifest's references sit beside it.
        #[arg(long, default_value = "tests/references")]
        references: PathBuf,
        /// Output folder: a folder per case, results.json, junit.xml, report.html.
        #[arg(long, default_value = "test-out")]
        out: PathBuf,
        /// Accept the current outputs as the references.
        #[arg(long)]
        bless: bool,
        /// node.param=value overrides, or node.param=a,b,c to sweep (repeatable: every
        /// combination is a case; vectors in brackets: [0,0,1],[1,0,0]).
        #[arg(long = "set", value_name = "NODE.PARAM=A,B,...")]
        sets: Vec<String>,
        /// A RON list of sweep axes: ["node.param=a,b", ...].
        #[arg(long)]
        sweep: Option<PathBuf>,
        /// Run shard I of N (0-based). Default: from SLURM_ARRAY_TASK_ID/SLURM_ARRAY_TASK_COUNT,
        /// or JOB_COMPLETION_INDEX/WERKSTATT_SHARD_COUNT, else everything.
        #[arg(long, value_name = "I/N")]
        shard: Option<String>,
        /// Fail cases slower than their reference time by more than the manifest's `slowdown`
        /// factor (without it they are only flagged).
        #[arg(long)]
        fail_on_slowdown: bool,
        /// GPU backend (or WERKSTATT_BACKEND).
        #[arg(long, value_enum)]
        backend: Option<Backend>,
    },
    /// Work with the results of `werkstatt test`.
    Report {
        #[command(subcommand)]
        what: ReportWhat,
    },
    /// Rewrite graphs in canonical form, or with --check list those that are not.
    Fmt {
        #[arg(long)]
        check: bool,
        #[arg(required = true)]
        graphs: Vec<PathBuf>,
    },
    /// List node kinds, or describe one in full (ports, parameters with defaults and ranges).
    Nodes {
        /// One node kind to describe, e.g. Material.
        kind: Option<String>,
        /// Print as JSON (all kinds, or KIND), for tools.
        #[arg(long, conflicts_with = "markdown")]
        json: bool,
        /// Print the Markdown node reference (the text of docs/nodes.md) to stdout, or to --out.
        #[arg(long, conflicts_with = "kind")]
        markdown: bool,
        /// Print the ClothSim presets' bounds and pattern pieces' UV rectangles (docs/presets.md).
        #[arg(long, conflicts_with_all = ["kind", "json", "markdown"])]
        presets: bool,
        /// Write the output to this file instead of stdout.
        #[arg(long)]
        out: Option<PathBuf>,
    },
    /// Print the GPU adapters wgpu finds.
    Info {
        #[arg(long, value_enum)]
        backend: Option<Backend>,
    },
    /// Measure the framework itself.
    Bench {
        #[command(subcommand)]
        what: BenchWhat,
    },
    /// The comparison against a path tracer (docs/fidelity.md): export a graph's view for
    /// Blender Cycles (tools/fidelity/cycles.py), then measure the two images.
    Fidelity {
        #[command(subcommand)]
        what: FidelityWhat,
    },
    /// Bidirectional texture functions (docs/btf.md).
    Btf {
        #[command(subcommand)]
        what: BtfWhat,
    },
}

#[derive(Subcommand)]
enum BtfWhat {
    /// Compress a BTF file per view slot (PCA, eq. 1) and print its sizes and errors.
    Compress {
        /// A BTF file (docs/btf.md, "File format").
        file: PathBuf,
        /// Components kept per view slot.
        #[arg(short, long, default_value_t = 16)]
        components: usize,
        /// Decompose the light images as they are (eq. 1 literally) instead of around their mean.
        #[arg(long)]
        no_centre: bool,
        /// Plot the eigenvalues of the view slots (0, 0), (45, 300) and (75, 45) (those the BTF
        /// has) as an SVG: the paper's Fig. 7.
        #[arg(long, value_name = "SVG")]
        eigenvalues_svg: Option<PathBuf>,
        /// Write the compressed BTF (8-bit images, docs/btf.md "Compressed file"), which the Btf
        /// node reads without compressing again.
        #[arg(long, value_name = "BTFC")]
        out: Option<PathBuf>,
    },
    /// Write the analytic Lambertian BTF (rho / pi cos theta_i, a checkerboard albedo): an input
    /// to try the tools on.
    Lambertian {
        /// Where the BTF file goes.
        #[arg(long)]
        out: PathBuf,
        /// Texels per side.
        #[arg(long, default_value_t = 32)]
        size: usize,
        /// All 81 directions of the paper's sampling instead of the 19 of the test tier.
        #[arg(long)]
        full: bool,
    },
    /// Bake a BTF from woven yarn geometry with a CPU ray tracer (docs/btf.md, "Baking"). Bakes
    /// are cached by a hash of their parameters.
    Bake {
        #[arg(long, value_enum, default_value = "plain")]
        weave: WeaveArg,
        /// test: 32x32 texels, 19 directions; default: 128x128, 81; paper: 256x256, 81.
        #[arg(long, value_enum, default_value = "default")]
        tier: TierArg,
        /// Where the BTF file goes.
        #[arg(long)]
        out: PathBuf,
        /// The warp yarns' albedo, linear "r,g,b" in [0, 1].
        #[arg(long, value_name = "R,G,B")]
        warp: Option<String>,
        /// The weft yarns' albedo, linear "r,g,b" in [0, 1].
        #[arg(long, value_name = "R,G,B")]
        weft: Option<String>,
        /// n: n x n samples per texel (default 2).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=8))]
        supersample: Option<u32>,
        /// Texels per side instead of the tier's (its directions stay).
        #[arg(long, value_parser = clap::value_parser!(u32).range(1..=4096))]
        size: Option<u32>,
        /// Tracing threads (0: one per core); the result does not depend on them.
        #[arg(long, default_value_t = 0)]
        threads: usize,
        /// The cache folder (default: .werkstatt-cache next to --out).
        #[arg(long)]
        cache_dir: Option<PathBuf>,
        /// Bake even if the cache has this bake, and do not cache it.
        #[arg(long)]
        no_cache: bool,
    },
    /// Read a measured BTF from a folder of per-direction images (Bonn database names, or a
    /// manifest.json) into a BTF file (docs/btf.md, "Measured BTFs").
    Import {
        folder: PathBuf,
        /// Where the BTF file goes.
        #[arg(long)]
        out: PathBuf,
        /// The images are sRGB-encoded (default: linear).
        #[arg(long)]
        srgb: bool,
        /// Multiplies every value.
        #[arg(long, default_value_t = 1.0)]
        scale: f32,
        /// Resample onto this sampling (default: keep H2 or the test tier's, else H2).
        #[arg(long, value_enum)]
        sampling: Option<SamplingArg>,
    },
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum WeaveArg {
    Plain,
    Twill,
    Satin,
    /// A flat Lambertian plane (the analytic check).
    Flat,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum TierArg {
    Test,
    Default,
    Paper,
}

#[derive(Clone, Copy, clap::ValueEnum)]
enum SamplingArg {
    /// The paper's 81 directions.
    H2,
    /// The test tier's 19.
    Tests,
}

/// "a,b,c" as three numbers, for `flag` that takes them as `names` ("r,g,b").
fn parse_three<T: std::str::FromStr + Copy>(flag: &str, names: &str, text: &str) -> anyhow::Result<[T; 3]> {
    let parts: Vec<&str> = text.split(',').map(str::trim).collect();
    let numbers: Vec<T> = parts.iter().filter_map(|p| p.parse().ok()).collect();
    anyhow::ensure!(parts.len() == 3 && numbers.len() == 3, "{flag} takes three numbers \"{names}\", not {text:?}");
    Ok([numbers[0], numbers[1], numbers[2]])
}

#[derive(Subcommand)]
enum FidelityWhat {
    /// Evaluate one frame of a graph and write, into --out: scene.glb (the G-buffer's scene as
    /// drawn, a material per item), scene.json (camera, probe, materials, regions, check
    /// points), texture_<i>.png, werkstatt.exr (the linear image entering Tonemap), ids.exr (item
    /// per pixel and its world position) and albedo.exr.
    Export {
        /// The graph file (.ron).
        graph: PathBuf,
        /// Override a parameter: node.param=value (repeatable; one value each).
        #[arg(long = "set", value_name = "NODE.PARAM=VALUE")]
        sets: Vec<String>,
        /// Disconnect an input: node.port (repeatable), e.g. light.shadows for IBL without
        /// the shadow atlas.
        #[arg(long = "unlink", value_name = "NODE.PORT")]
        unlinks: Vec<String>,
        #[arg(long, default_value_t = 0)]
        frame: i64,
        #[arg(long, default_value_t = 30.0)]
        fps: f64,
        #[arg(long, default_value = "320x240")]
        size: String,
        #[arg(long)]
        out: PathBuf,
        #[arg(long, value_enum)]
        backend: Option<Backend>,
    },
    /// Measure DIR/werkstatt.exr against the path tracer's DIR/cycles.exr: relative MAE overall
    /// and per item, floor-region ratios, open floor at the screen's edges (Markdown tables;
    /// also DIR/metrics.json).
    Compare {
        dir: PathBuf,
        /// The path tracer's image, a file in DIR.
        #[arg(long, default_value = "cycles.exr")]
        cycles: String,
    },
}

#[derive(Subcommand)]
enum ReportWhat {
    /// Combine the output folders of the shards of one `werkstatt test` run into one.
    Merge {
        /// The shards' output folders.
        #[arg(required = true)]
        shards: Vec<PathBuf>,
        /// Where the merged run goes (the same files an unsharded run writes).
        #[arg(long)]
        out: PathBuf,
    },
}

/// What every GPU bench takes: the frame size, the adapter, and where to write the rows.
#[derive(clap::Args)]
struct GpuBench {
    #[arg(long, default_value = "640x480")]
    size: String,
    /// Also write the rows as JSON.
    #[arg(long)]
    json: Option<PathBuf>,
    #[arg(long, value_enum)]
    backend: Option<Backend>,
}

impl GpuBench {
    /// The headless adapter and the parsed size.
    fn open(&self) -> anyhow::Result<(GpuContext, (u32, u32))> {
        let size = parse_size(&self.size)?;
        Ok((GpuContext::headless(pick_backend(self.backend)?)?, size))
    }

    /// Writes `rows` to `--json` when given.
    fn write_json(&self, rows: &impl serde::Serialize) -> anyhow::Result<()> {
        if let Some(path) = &self.json {
            crate::io::atomic::write_atomic(path, serde_json::to_string_pretty(rows)?.as_bytes())?;
        }
        Ok(())
    }
}

#[derive(Subcommand)]
enum BenchWhat {
    /// Every GPU bench (attachments, table1, cuboids, pem-memory, ibl, shadows, ssao,
    /// tessellation, woven, btf) in this order within a time budget: each bench's rows as JSON, all.json
    /// (what ran, how long, each status) and summary.md (our tables beside the seeds' figures)
    /// into DIR. Exit code 1 when a bench failed.
    All {
        /// The folder for the results.
        #[arg(long, value_name = "DIR")]
        json: PathBuf,
        /// How much each bench measures: small on lavapipe, the papers' counts on a GPU.
        #[arg(long, value_enum, default_value = "auto")]
        preset: crate::app::bench_all::Preset,
        /// Seconds after which no further bench starts [default: 480 for full, 600 for small].
        #[arg(long)]
        budget_s: Option<u64>,
        /// Only these benches, comma-separated.
        #[arg(long, value_delimiter = ',')]
        only: Vec<String>,
        #[arg(long, value_enum)]
        backend: Option<Backend>,
    },
    /// Evaluator overhead per idle frame (nothing changed) for a graph of cheap nodes.
    Graph {
        #[arg(long, default_value_t = 200)]
        nodes: usize,
        #[arg(long, default_value_t = 20000)]
        frames: usize,
    },
    /// The editor's viewport on a graph, through the evaluation the window drives (headless):
    /// the first frame, the timeline's first loop (each frame evaluated, simulations stepped),
    /// its replay from the kept pictures, and turning the view (half size while it turns, full
    /// size at rest). Milliseconds and pictures a second.
    #[cfg(feature = "editor")]
    Editor {
        #[arg(long, default_value = "graphs/default.ron")]
        graph: PathBuf,
        /// The viewport's size.
        #[arg(long, default_value = "800x600")]
        size: String,
        /// The timeline's frames 0..N.
        #[arg(long, default_value_t = 24)]
        frames: i64,
        /// Turns of the view measured each way.
        #[arg(long, default_value_t = 12)]
        orbit_steps: usize,
        /// Also write the rows as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
        #[arg(long, value_enum)]
        backend: Option<Backend>,
    },
    /// Cloth simulation time per frame against triangle count (tablecloth over a torus).
    Cloth {
        #[arg(long, default_value = "2000,5000,10000,20000,50000", value_delimiter = ',')]
        triangles: Vec<usize>,
        #[arg(long, default_value_t = 30)]
        warmup: usize,
        #[arg(long, default_value_t = 60)]
        frames: usize,
    },
    /// Draping with body and self collision: by default the GarmentCode shirt sewn at each
    /// `--edges` length on the MakeHuman avatar, settled at rest and then walking; with
    /// `--capsules`, a skirt of `--triangles` on a body of capsules swinging its legs. Reports
    /// ms per 1/60 s frame split into collision detection, constraints, self-collision and
    /// body collision, settling time, crossings and clearance.
    Drape {
        /// The old benchmark: a skirt on a capsule body.
        #[arg(long)]
        capsules: bool,
        /// Target edge lengths (cm) of the sewn garment.
        #[arg(long, default_value = "1,0.5", value_delimiter = ',')]
        edges: Vec<f64>,
        /// The GarmentCode pattern (default: the bundled shirt).
        #[arg(long, default_value = "assets/patterns/garmentcode/shirt_mean_specification.json")]
        pattern: PathBuf,
        /// The avatar's files (base mesh, skeleton, weights, walk and joint map).
        #[arg(long, default_value = "assets/avatar")]
        avatar: PathBuf,
        /// Solver substeps per 1/60 s frame of the garment (default: as the `Garment` node
        /// takes them, 20 per 1/cm of edge length, at least 20), and constraint sweeps per
        /// substep.
        #[arg(long)]
        substeps: Option<u32>,
        #[arg(long, default_value_t = 2)]
        iterations: u32,
        #[arg(long, default_value_t = 20000)]
        triangles: usize,
        /// Most frames to wait for the garment to settle on the standing body.
        #[arg(long, default_value_t = 120)]
        settle: usize,
        /// Timed frames of walking.
        #[arg(long, default_value_t = 60)]
        frames: usize,
        /// Leg swing amplitude (degrees).
        #[arg(long, default_value_t = 20.0)]
        swing: f32,
        /// Count crossings every N walking frames (0: never).
        #[arg(long, default_value_t = 10)]
        check_every: usize,
        /// Leave cloth found through the cloth where it is (the `Garment` node's `untangle` off).
        #[arg(long)]
        no_untangle: bool,
        /// Without the struts that hold a panel's vertices within their pattern distance (the
        /// `Garment` node's `struts` off).
        #[arg(long)]
        no_struts: bool,
        /// The avatar's arms spread out from its sides (degrees), as the graphs have them: at 0
        /// MakeHuman's arms pass through its torso in the walk, with the cloth between.
        #[arg(long, default_value_t = 30.0)]
        arm_spread: f64,
        /// Moves the pattern's placement (cm: x,y,z), as the `Garment` node's `offset` (its
        /// default when left out). graphs/garment_dress.ron sets 0,4,3: lower, the pencil
        /// dress's strap seams close through the shoulders and it falls. Given more than once,
        /// each placement runs in turn and a line per edge length after the table gives the
        /// mean and range of the figures over them: the worst frame's strain and crossings
        /// change by a point or more between placements millimetres apart, so compare changes
        /// over several.
        #[arg(long, allow_hyphen_values = true, action = clap::ArgAction::Append)]
        offset: Vec<String>,
        /// Write the start, settled and last cloth and every body pose as OBJ here (the
        /// Blender peer, peers/blender_drape.py, reads them).
        #[arg(long)]
        obj_dir: Option<PathBuf>,
        /// Also write the report as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
    },
    /// Image-based lighting (graphs/fig3_13_glossiness.ron) against the number of median-cut
    /// regions: PEM rebuild time, frame time (G-buffer + shading), PEM memory. Region count
    /// 0 is one lookup into the filtered full map.
    Ibl {
        #[arg(long, default_value = "0,1,4,16,64,256", value_delimiter = ',')]
        regions: Vec<usize>,
        /// Timed frames per count (median reported).
        #[arg(long, default_value_t = 5)]
        frames: usize,
        #[command(flatten)]
        out: GpuBench,
    },
    /// Adaptive tessellation (Fig. 5.11): for each mode and level, generated triangles, the
    /// compute pass's time and triangles per second, and the frame time (tessellation + G-buffer)
    /// on a 1024-triangle sphere; vertex levels all at the level ("equal") or random in
    /// [1, level] ("random").
    Tessellation {
        /// Levels, comma-separated.
        #[arg(long, default_value = "1,2,3,4,6,8,12,16", value_delimiter = ',')]
        levels: Vec<u32>,
        /// Timed frames per row (median reported).
        #[arg(long, default_value_t = 5)]
        frames: usize,
        #[command(flatten)]
        out: GpuBench,
    },
    /// Woven cloth (Zhang et al. 2012, IDSS, Table 1): a flat tablecloth of 4x4 to 32x32
    /// patches tessellated in compute and drawn into the G-buffer at uniform L = 7, uniform
    /// L = 9 and adaptive L, beside the paper's figures (NVIDIA 8400M).
    Woven {
        /// Table 1's rows to run (0-5).
        #[arg(long, value_delimiter = ',', default_value = "0,1,2,3,4,5")]
        rows: Vec<usize>,
        /// Timed frames per row (median reported).
        #[arg(long, default_value_t = 5)]
        frames: usize,
        /// Modes that would draw more triangles are skipped.
        #[arg(long, default_value_t = 40_000_000)]
        max_triangles: u64,
        #[command(flatten)]
        out: GpuBench,
    },
    /// BTF cloth (Sattler et al. 2003, Table 2), on the CPU: per-vertex visibility
    /// preprocessing, the environment (HEM) update and its eigen-weightset rotation on folded
    /// panels of about 900 and 6400 vertices; the BTF tiers' bake, compression and sizes.
    Btf {
        /// The lavapipe preset: a 16² hemicube and only the 900-vertex panel's eigen-weightsets.
        #[arg(long)]
        small: bool,
        /// Also write the rows as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
        /// Frame rates (PLS and HEM) at these sizes on the GPU, median of `--frames` frames;
        /// none: skipped.
        #[arg(long, value_delimiter = ',', default_value = "640x480,1280x960")]
        frame_sizes: Vec<String>,
        #[arg(long, default_value_t = 3)]
        frames: usize,
    },
    /// Local occlusion (Ssao) on the spheres-on-a-plane scene of graphs/fig5_25_occlusion.ron:
    /// ms per frame of the Ssao passes for each mode at full and half resolution.
    Ssao {
        /// Depth taps per pixel.
        #[arg(long, default_value_t = 16)]
        samples: u32,
        /// Timed frames per row (median reported).
        #[arg(long, default_value_t = 10)]
        frames: usize,
        #[command(flatten)]
        out: GpuBench,
    },
    /// Global occlusion (graphs/fig5_24_shadows.ron without its unshadowed pass): frame time
    /// (G-buffer, shadow atlas, shadowed IBL, SSAO, hybrid, tone mapping; a sphere moves every
    /// frame so the atlas is redrawn) against the number of lights and the atlas tile size,
    /// and the atlas memory.
    Shadows {
        /// Light counts, comma-separated.
        #[arg(long, default_value = "16,64,128,256,512", value_delimiter = ',')]
        lights: Vec<usize>,
        /// Tile sizes (texels, guard band included), comma-separated.
        #[arg(long, default_value = "64,128,256,512", value_delimiter = ',')]
        tiles: Vec<u32>,
        /// Timed frames per row (median reported).
        #[arg(long, default_value_t = 3)]
        frames: usize,
        #[command(flatten)]
        out: GpuBench,
    },
    /// The deferred-warping paper's Fig. 10: a 928-triangle button attached N times (point,
    /// area, curve) against plain instancing and a CPU warp path; million triangles per second.
    Attachments {
        /// Instance counts, comma-separated.
        #[arg(long, default_value = "1000,2000,4000,8000,16000,32000,65000", value_delimiter = ',')]
        counts: Vec<usize>,
        /// Timed frames per measurement (median reported).
        #[arg(long, default_value_t = 3)]
        frames: usize,
        /// Skip the CPU warp path.
        #[arg(long)]
        no_cpu: bool,
        #[command(flatten)]
        out: GpuBench,
    },
    /// The paper's Table 1: the Fig. 1 graphs scaled to the paper's triangle counts (25M fur,
    /// 10M embroidery, 6M buttons and seams, 48M knit, 650k stickers), triangles and ms per
    /// frame (matrix texture + G-buffer) beside the paper's GTX 580 times.
    Table1 {
        /// Timed frames per figure (median reported).
        #[arg(long, default_value_t = 3)]
        frames: usize,
        /// Fraction of the paper's triangle counts (1 = the paper's; smaller for a quick look).
        #[arg(long, default_value_t = 1.0)]
        scale: f64,
        /// Only these figures (graph name prefixes, e.g. fig1c), comma-separated.
        #[arg(long, value_delimiter = ',')]
        only: Vec<String>,
        #[command(flatten)]
        out: GpuBench,
    },
    /// The export path of Fig. 10's data: N point-attached 928-triangle buttons on the
    /// tablecloth sequence; producing the warped geometry in memory (GPU, and the threaded CPU
    /// twin) apart from writing it as binary PLY.
    Export {
        /// Button counts, comma-separated.
        #[arg(long, default_value = "1000,10000,65000", value_delimiter = ',')]
        counts: Vec<usize>,
        /// Timed runs per measurement (median reported).
        #[arg(long, default_value_t = 3)]
        frames: usize,
        /// Folder the PLY files are written to (and removed from); a RAM disk measures the copy.
        #[arg(long, default_value = "out")]
        dir: PathBuf,
        #[command(flatten)]
        out: GpuBench,
    },
    /// The dissertation's cuboid table (section 5.1.1): frames per second with linear and with
    /// trilinear transforms (CPU composition + G-buffer per frame) for spheres on an animated
    /// object and helices of small objects, and their ratio.
    Cuboids {
        /// Spheres on the animated object: count x triangles per sphere.
        #[arg(long, default_value = "185x2000")]
        spheres: String,
        /// Helices: count x triangles per object, comma-separated.
        #[arg(long, default_value = "4617x36,2566x256", value_delimiter = ',')]
        helices: Vec<String>,
        /// Timed frames per block: each round runs each path in two blocks (A B B A), each
        /// after one untimed frame; the medians of each path's frames are reported.
        #[arg(long, default_value_t = 5)]
        frames: usize,
        /// Rounds of blocks A B B A; the ratio is the median of the rounds' ratios (with 5
        /// rounds a row moved by up to 8 points between runs on a 2-core machine, with 15 by 3-6).
        #[arg(long, default_value_t = 15)]
        rounds: usize,
        #[command(flatten)]
        out: GpuBench,
    },
    /// The dissertation's Figs. 5.19/5.20 on the CPU: for each PEM filter kernel and Phong
    /// exponent, the volume-matched mip level and the lobe's shape error; also the default
    /// kernel's calibration table and the PEM memory table.
    PemLobes {
        /// Cube map face size (a power of two).
        #[arg(long, default_value_t = 128)]
        size: usize,
        /// Also write the plot (shape error against s) as SVG.
        #[arg(long)]
        svg: Option<PathBuf>,
        /// Also write the rows as JSON.
        #[arg(long)]
        json: Option<PathBuf>,
    },
}

pub fn main() -> ExitCode {
    let cli = Cli::parse();
    match run(cli.command) {
        Ok(code) => code,
        Err(e) => {
            eprintln!("error: {e:#}");
            ExitCode::FAILURE
        }
    }
}

/// `werkstatt check`: validates each graph; with `json`, one JSON object per problem on
/// stdout (file, line, column, node, port, message, help; warnings with "level": "warning").
fn check(graphs: &[PathBuf], json: bool) -> ExitCode {
    let mut failed = 0;
    let print_json = |file: &std::path::Path, line: usize, col: usize, level: &str, problem: serde_json::Value| {
        let mut v =
            serde_json::json!({ "file": file.display().to_string(), "line": line, "column": col, "level": level });
        if let (Some(o), serde_json::Value::Object(p)) = (v.as_object_mut(), problem) {
            o.extend(p);
        }
        println!("{v}");
    };
    for path in graphs {
        match Graph::load(path) {
            Ok(g) => {
                let base = path.parent().unwrap_or(std::path::Path::new(""));
                let source = std::fs::read_to_string(path).unwrap_or_default();
                let missing = g.missing_files(base);
                if missing.is_empty() && !json {
                    println!("ok: {} ({} nodes, {} links)", path.display(), g.nodes.len(), g.links.len());
                }
                failed += usize::from(!missing.is_empty());
                let warnings = g.warnings();
                let levels = missing.iter().map(|w| ("error", w)).chain(warnings.iter().map(|w| ("warning", w)));
                for (level, w) in levels {
                    let (line, col) = w.line_col(&source);
                    if json {
                        let problem =
                            serde_json::json!({ "node": w.node, "port": null, "message": w.message, "help": w.help });
                        print_json(path, line, col, level, problem);
                    } else {
                        eprintln!("{}:{line}:{col}: {level}: {w}", path.display());
                    }
                }
            }
            Err(e) => {
                failed += 1;
                if !json {
                    eprintln!("{e}");
                    continue;
                }
                for d in &e.diagnostics {
                    let p = &d.problem;
                    let problem =
                        serde_json::json!({ "node": p.node, "port": p.port, "message": p.message, "help": p.help });
                    print_json(&d.file, d.line, d.col, "error", problem);
                }
            }
        }
    }
    if failed > 0 {
        eprintln!("{failed} of {} graph(s) have errors", graphs.len());
        return ExitCode::FAILURE;
    }
    ExitCode::SUCCESS
}

fn pick_backend(flag: Option<Backend>) -> anyhow::Result<Backend> {
    match flag {
        Some(b) => Ok(b),
        None => Backend::from_env().map_err(anyhow::Error::msg),
    }
}

fn parse_frames(text: &str) -> anyhow::Result<(i64, i64)> {
    let bad = || anyhow::anyhow!("--frames \"{text}\": expected N or A..B with A <= B");
    let (a, b) = match text.split_once("..") {
        Some((a, b)) => (a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?),
        None => {
            let n: i64 = text.trim().parse().map_err(|_| bad())?;
            (n, n)
        }
    };
    if a > b || b.checked_sub(a).is_none_or(|n| n >= 10_000_000) {
        return Err(bad());
    }
    Ok((a, b))
}

fn parse_size(text: &str) -> anyhow::Result<(u32, u32)> {
    let bad = || anyhow::anyhow!("--size \"{text}\": expected WxH, e.g. 640x480, each 1..=8192");
    let (w, h) = text.split_once(['x', 'X']).ok_or_else(bad)?;
    let (w, h): (u32, u32) = (w.trim().parse().map_err(|_| bad())?, h.trim().parse().map_err(|_| bad())?);
    if !(1..=8192).contains(&w) || !(1..=8192).contains(&h) {
        return Err(bad());
    }
    Ok((w, h))
}

fn run(command: Command) -> anyhow::Result<ExitCode> {
    match command {
        Command::Render {
            graph,
            frames,
            fps,
            size,
            out,
            ssaa,
            sets,
            contact_sheet,
            dumps,
            dump_format,
            pending_timeout,
            backend,
        } => {
            use crate::core::param::Choice as _;
            let dump_format = dump_format.map(|name| {
                let i =
                    crate::io::image::ImageFormat::OPTIONS.iter().position(|o| *o == name).expect("clap checked it");
                crate::io::image::ImageFormat::from_index(i).expect("an index of OPTIONS")
            });
            let frames = parse_frames(&frames)?;
            let (width, height) = parse_size(&size)?;
            if width.max(height) * ssaa > 8192 {
                anyhow::bail!(
                    "--size {size} with --ssaa {ssaa} renders {}x{}, over the limit of 8192",
                    width * ssaa,
                    height * ssaa
                );
            }
            if !(fps > 0.0 && fps.is_finite()) {
                anyhow::bail!("--fps must be a positive number");
            }
            let pending_timeout = std::time::Duration::try_from_secs_f64(pending_timeout)
                .map_err(|_| anyhow::anyhow!("--pending-timeout must be a number of seconds, not {pending_timeout}"))?;
            let progress = std::io::stderr().is_terminal() && std::env::var_os("CI").is_none();
            let opts = crate::app::render::RenderOptions {
                graph_path: graph,
                frames,
                fps,
                width,
                height,
                out_dir: out.clone(),
                sets,
                dumps,
                dump_format,
                ssaa,
                progress,
                command: std::env::args().collect(),
                pending_timeout,
            };
            // Validate every variant before touching the GPU, so a bad graph fails fast and
            // clearly.
            let variants = crate::app::render::plan_sweep(&opts)?;
            let sweep = crate::app::sweep::Sweep::parse(&opts.sets)?;
            if contact_sheet && sweep.axes.is_empty() {
                anyhow::bail!("--contact-sheet needs a sweep: a --set with two or more values (a,b,c or a..b:n)");
            }
            let gpu = GpuContext::headless(pick_backend(backend)?).inspect_err(|e| {
                for (_, o, _) in &variants {
                    crate::app::render::record_failure(o, e);
                }
            })?;
            let mut runs = Vec::new();
            for (variant, o, loaded) in variants {
                let stats = crate::app::render::render_graph(&o, &loaded, &gpu)?;
                eprintln!(
                    "rendered {} frame(s) on {}: {} file(s) and stats.json in {}",
                    stats.frames.len(),
                    stats.adapter,
                    stats.files.len(),
                    o.out_dir.display()
                );
                runs.push((variant, o, stats));
            }
            if contact_sheet {
                let columns = sweep.axes.last().map_or(1, |(_, values)| values.len());
                for path in crate::app::render::write_contact_sheets(&out, &runs, columns)? {
                    eprintln!("contact sheet: {}", path.display());
                }
            }
            Ok(ExitCode::SUCCESS)
        }
        #[cfg(all(feature = "editor", not(test)))]
        Command::Edit { graph, backend } => {
            crate::app::editor::run(graph, pick_backend(backend)?)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Check { graphs, message_format } => Ok(check(&graphs, message_format == "json")),
        Command::Test { inputs, references, out, bless, sets, sweep, shard, fail_on_slowdown, backend } => {
            let shard = crate::app::regress::shard_from(shard.as_deref(), |k| std::env::var(k).ok())?;
            let opts = crate::app::regress::TestOptions {
                inputs,
                references,
                out_dir: out.clone(),
                bless,
                sets,
                sweep_file: sweep,
                shard,
                fail_on_slowdown,
            };
            // Plan first, so a bad manifest or --set fails before the GPU starts.
            crate::app::regress::plan(&opts)?;
            let gpu = GpuContext::headless(pick_backend(backend)?)?;
            let run = crate::app::regress::run(&opts, &gpu, |c| {
                let first = c.message.as_deref().and_then(|m| m.lines().next()).unwrap_or("");
                let slow = if c.slow { " (slower than its reference)" } else { "" };
                eprintln!("{:?}: {} {:.0} ms{slow} {first}", c.status, c.name, c.render_ms);
            })?;
            eprintln!("{}\nreports: {}/junit.xml, {}/report.html", run.summary(), out.display(), out.display());
            Ok(if run.regressed() { ExitCode::FAILURE } else { ExitCode::SUCCESS })
        }
        Command::Report { what: ReportWhat::Merge { shards, out } } => {
            let run = crate::app::regress::merge(&shards, &out)?;
            eprintln!("{}\nreports: {}/junit.xml, {}/report.html", run.summary(), out.display(), out.display());
            Ok(if run.regressed() { ExitCode::FAILURE } else { ExitCode::SUCCESS })
        }
        Command::Fmt { check, graphs } => {
            let mut bad = 0;
            for path in &graphs {
                let g = match Graph::load(path) {
                    Ok(g) => g,
                    Err(e) => {
                        bad += 1;
                        eprintln!("{e}");
                        continue;
                    }
                };
                let text = std::fs::read_to_string(path)?;
                let canonical = g.to_ron();
                if text != canonical {
                    if check {
                        bad += 1;
                        println!("not canonical: {}", path.display());
                    } else {
                        g.save(path)?;
                        println!("formatted: {}", path.display());
                    }
                }
            }
            Ok(if bad > 0 { ExitCode::FAILURE } else { ExitCode::SUCCESS })
        }
        Command::Nodes { kind, json, markdown, presets, out } => {
            let spec = kind.as_deref().map(crate::app::docs::find).transpose().map_err(anyhow::Error::msg)?;
            let text = match (spec, json) {
                (Some(s), true) => serde_json::to_string_pretty(&crate::app::docs::node_json(s))? + "\n",
                (None, true) => serde_json::to_string_pretty(&crate::app::docs::json())? + "\n",
                (Some(s), false) => crate::app::docs::describe(s),
                (None, false) if markdown => crate::app::docs::markdown(),
                (None, false) if presets => crate::nodes::cloth::node::presets_markdown()?,
                (None, false) => crate::app::docs::listing(),
            };
            match out {
                Some(path) => crate::io::atomic::write_atomic(&path, text.as_bytes())?,
                None => print!("{text}"),
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Fidelity { what: FidelityWhat::Export { graph, sets, unlinks, frame, fps, size, out, backend } } => {
            let (width, height) = parse_size(&size)?;
            let gpu = GpuContext::headless(pick_backend(backend)?)?;
            let opts =
                crate::app::fidelity::ExportOptions { graph_path: graph, sets, unlinks, frame, fps, width, height };
            let cap = crate::app::fidelity::export(&opts, &gpu, &out)?;
            let names: Vec<&str> = cap.scene.items.iter().map(|i| i.name.as_str()).collect();
            println!("wrote {} ({} items: {})", out.display(), names.len(), names.join(", "));
            Ok(ExitCode::SUCCESS)
        }
        Command::Fidelity { what: FidelityWhat::Compare { dir, cycles } } => {
            let m = crate::app::fidelity::compare_dir(&dir, &cycles)?;
            print!("{}", m.table());
            crate::io::atomic::write_atomic(&dir.join("metrics.json"), serde_json::to_string_pretty(&m)?.as_bytes())?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Info { backend } => {
            let backend = pick_backend(backend)?;
            let adapters = crate::gpu::list_adapters(backend);
            if adapters.is_empty() {
                eprintln!("no GPU adapter found for backend {backend:?}\n  help: {}", crate::gpu::NO_ADAPTER_HELP);
                return Ok(ExitCode::FAILURE);
            }
            for a in adapters {
                println!("{a}");
            }
            // What the nodes render into on the adapter `render` would pick.
            if let Ok(gpu) = GpuContext::headless(backend) {
                let f = gpu.formats();
                println!(
                    "formats on {}: linear depth {:?}, HDR {:?}, half matrix {:?}, depth {:?}, float32 renderable: {}, float32 filterable: {}",
                    gpu.adapter_name(),
                    f.linear_depth,
                    f.hdr,
                    f.matrix_f16,
                    f.depth,
                    f.float32_renderable,
                    f.float32_filterable
                );
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Btf { what: BtfWhat::Compress { file, components, no_centre, eigenvalues_svg, out } } => {
            use crate::btf::pca::{Centring, compress};
            anyhow::ensure!(components > 0, "--components must be at least 1");
            let start = std::time::Instant::now();
            let btf = crate::btf::container::load(&file)?;
            let loaded = start.elapsed();
            let centring = if no_centre { Centring::None } else { Centring::Mean };
            let packed = compress(&btf, components, centring);
            let compressed = start.elapsed() - loaded;
            let r = packed.report(&btf);
            let n = btf.sampling.len();
            let mib = |b: usize| b as f64 / (1 << 20) as f64;
            println!(
                "{}: {}x{} texels, {n} views x {n} lights, c = {components}, {centring:?} centring",
                file.display(),
                btf.width,
                btf.height
            );
            println!("load {:.2} s, compress {:.2} s", loaded.as_secs_f64(), compressed.as_secs_f64());
            println!(
                "size (f16): {:.2} MiB raw -> {:.2} MiB compressed, ratio {:.1}",
                mib(r.raw_bytes),
                mib(r.compressed_bytes),
                r.raw_bytes as f64 / r.compressed_bytes.max(1) as f64
            );
            println!("relative Frobenius error {:.3e}", r.relative_error);
            println!(
                "8-bit RGB error length (exposure {:.3}: p99.5 -> 255): mean {:.3}, p99 {:.3}, max {:.3}",
                r.exposure, r.error8_mean, r.error8_p99, r.error8_max
            );
            let captured = |s: &crate::btf::pca::SlotPca| {
                let total: f64 = s.eigenvalues.iter().sum();
                if total > 0.0 { s.eigenvalues.iter().take(components).sum::<f64>() / total } else { 1.0 }
            };
            let worst = packed.slots.iter().map(captured).fold(1.0, f64::min);
            println!("captured eigenvalue energy: worst slot {worst:.6}");
            // The file's 8-bit images against 8-bit raw images (the paper's 1230 MB -> 260 MB).
            let q = packed.quantised().report(&btf);
            let file_bytes = crate::btf::pca_file::data_bytes(&packed);
            println!(
                "8-bit images (the compressed file): {:.2} MiB raw -> {:.2} MiB, ratio {:.1}; relative Frobenius error {:.3e}; 8-bit RGB error length mean {:.3}, p99 {:.3}, max {:.3}",
                mib(r.raw_bytes / 2),
                mib(file_bytes),
                (r.raw_bytes / 2) as f64 / file_bytes.max(1) as f64,
                q.relative_error,
                q.error8_mean,
                q.error8_p99,
                q.error8_max
            );
            if let Some(path) = out {
                crate::btf::pca_file::save(&packed, &btf.sampling, btf.width, btf.height, &path)?;
                println!("wrote {}", path.display());
            }
            if let Some(path) = eigenvalues_svg {
                use crate::btf::directions::Dir;
                let curves: Vec<(String, Vec<f64>)> = [(0.0, 0.0), (45.0, 300.0), (75.0, 45.0)]
                    .into_iter()
                    .filter_map(|(theta, phi)| {
                        let j = btf.direction_index(Dir { theta, phi })?;
                        Some((format!("view ({theta}, {phi})"), packed.slots[j].eigenvalues.clone()))
                    })
                    .collect();
                let name = file.file_name().map_or(String::new(), |n| n.to_string_lossy().replace(['<', '&'], "_"));
                let title = format!("Eigenvalues per view slot (Fig. 7): {name}");
                crate::io::atomic::write_atomic(&path, crate::btf::pca::eigenvalue_svg(&curves, &title).as_bytes())?;
                println!("wrote {}", path.display());
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Btf { what: BtfWhat::Lambertian { out, size, full } } => {
            use crate::btf::directions::Sampling;
            anyhow::ensure!((1..=1024).contains(&size), "--size must be 1..1024, not {size}");
            let sampling = if full { Sampling::h2() } else { Sampling::h2_tests() };
            let check = |x: usize, y: usize| {
                if (x * 8 / size + y * 8 / size).is_multiple_of(2) { [0.8, 0.3, 0.2] } else { [0.2, 0.3, 0.7] }
            };
            crate::btf::container::save(&crate::btf::Btf::lambertian(sampling, size, size, check), &out)?;
            println!("wrote {}", out.display());
            Ok(ExitCode::SUCCESS)
        }
        Command::Btf {
            what: BtfWhat::Bake { weave, tier, out, warp, weft, supersample, size, threads, cache_dir, no_cache },
        } => {
            use crate::btf::bake::{BakeParams, Baker, Pattern, Tier};
            let pattern = match weave {
                WeaveArg::Plain => Pattern::Plain,
                WeaveArg::Twill => Pattern::Twill,
                WeaveArg::Satin => Pattern::Satin,
                WeaveArg::Flat => Pattern::Flat,
            };
            let tier = match tier {
                TierArg::Test => Tier::Test,
                TierArg::Default => Tier::Default,
                TierArg::Paper => Tier::Paper,
            };
            let mut params = BakeParams::tier(pattern, tier);
            if let Some(w) = warp {
                params.warp_colour = parse_three("--warp", "r,g,b", &w)?;
            }
            if let Some(w) = weft {
                params.weft_colour = parse_three("--weft", "r,g,b", &w)?;
            }
            if let Some(n) = supersample {
                params.supersample = n as usize;
            }
            if let Some(n) = size {
                params.size = n as usize;
            }
            let start = std::time::Instant::now();
            let key = params.cache_key();
            let cache_dir =
                cache_dir.unwrap_or_else(|| out.parent().unwrap_or(std::path::Path::new("")).join(".werkstatt-cache"));
            let cached = cache_dir.join(format!("bake-{key:016x}.btf"));
            let copy = |from: &std::path::Path| {
                std::fs::copy(from, &out)
                    .map(|_| ())
                    .map_err(|e| anyhow::anyhow!("copying {} to {}: {e}", from.display(), out.display()))
            };
            if !no_cache && cached.is_file() {
                copy(&cached)?;
                println!("wrote {} from the cache {} (key {key:016x})", out.display(), cached.display());
                return Ok(ExitCode::SUCCESS);
            }
            let baker = Baker::new(&params, threads)?;
            let built = start.elapsed();
            let target = if no_cache { out.clone() } else { cached.clone() };
            if !no_cache {
                std::fs::create_dir_all(&cache_dir)
                    .map_err(|e| anyhow::anyhow!("creating the cache folder {}: {e}", cache_dir.display()))?;
            }
            // Written beside its place and renamed when whole, so an interrupted bake leaves no
            // file that looks finished.
            let part = target.with_extension("btf.part");
            let mut writer = crate::btf::container::Writer::create(&part, params.size, params.size, &params.sampling)?;
            let show = std::io::stderr().is_terminal() && std::env::var_os("CI").is_none();
            let bar = indicatif::ProgressBar::new(baker.views() as u64);
            if show {
                bar.set_style(
                    indicatif::ProgressStyle::with_template("{bar:40} {pos}/{len} views {elapsed} (eta {eta})")
                        .unwrap_or_else(|_| indicatif::ProgressStyle::default_bar()),
                );
            } else {
                bar.set_draw_target(indicatif::ProgressDrawTarget::hidden());
            }
            for view in 0..baker.views() {
                writer.write_view(&baker.view(view))?;
                bar.inc(1);
            }
            bar.finish_and_clear();
            writer.finish()?;
            std::fs::rename(&part, &target)
                .map_err(|e| anyhow::anyhow!("renaming {} to {}: {e}", part.display(), target.display()))?;
            if !no_cache {
                copy(&cached)?;
            }
            let n = params.sampling.len();
            println!(
                "baked {:?} {}x{} texels, {n} views x {n} lights, {}x{} samples per texel: geometry {:.2} s, \
                 tracing {:.1} s",
                pattern,
                params.size,
                params.size,
                params.supersample,
                params.supersample,
                built.as_secs_f64(),
                (start.elapsed() - built).as_secs_f64()
            );
            if no_cache {
                println!("wrote {}", out.display());
            } else {
                println!("wrote {} (cached as {})", out.display(), cached.display());
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Btf { what: BtfWhat::Import { folder, out, srgb, scale, sampling } } => {
            use crate::btf::directions::Sampling;
            let sampling = sampling.map(|s| match s {
                SamplingArg::H2 => Sampling::h2(),
                SamplingArg::Tests => Sampling::h2_tests(),
            });
            let options = crate::btf::measured::ImportOptions { srgb, scale, sampling };
            let start = std::time::Instant::now();
            let btf = crate::btf::measured::import_folder(&folder, &options)?;
            crate::btf::container::save(&btf, &out)?;
            let n = btf.sampling.len();
            println!(
                "{}: {}x{} texels, {n} views x {n} lights, {:.2} s; wrote {}",
                folder.display(),
                btf.width,
                btf.height,
                start.elapsed().as_secs_f64(),
                out.display()
            );
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::All { json, preset, budget_s, only, backend } } => {
            let gpu = GpuContext::headless(pick_backend(backend)?)?;
            let preset = preset.resolve(&gpu);
            let budget = budget_s.map_or(preset.default_budget(), std::time::Duration::from_secs);
            println!("adapter: {}, preset {preset:?}, budget {} s", gpu.adapter_name(), budget.as_secs());
            let report = crate::app::bench_all::run_all(&gpu, preset, budget, &only, &json, |m| eprintln!("{m}"))?;
            println!(
                "{} bench(es) in {:.1} s, {} failed: {}",
                report.benches.len(),
                report.seconds,
                report.failed(),
                json.join("summary.md").display()
            );
            Ok(if report.failed() == 0 { ExitCode::SUCCESS } else { ExitCode::FAILURE })
        }
        Command::Bench { what: BenchWhat::Attachments { counts, frames, no_cpu, out } } => {
            let (gpu, size) = out.open()?;
            println!("adapter: {}, {}x{}, median of {frames} frame(s)", gpu.adapter_name(), size.0, size.1);
            println!("{}", AttachRow::HEADER);
            let rows =
                crate::app::bench::attachments(&gpu, &counts, frames, size, !no_cpu, |r| println!("{}", r.markdown()))?;
            out.write_json(&rows)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Export { counts, frames, dir, out } } => {
            let (gpu, _) = out.open()?;
            println!("adapter: {}, median of {frames} run(s), PLY into {}", gpu.adapter_name(), dir.display());
            println!("{}", ExportRow::HEADER);
            let rows = crate::app::bench::export(&gpu, &counts, frames, &dir, |r| println!("{}", r.markdown()))?;
            out.write_json(&rows)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Table1 { frames, scale, only, out } } => {
            let (gpu, size) = out.open()?;
            println!("adapter: {}, {}x{}, median of {frames} frame(s)", gpu.adapter_name(), size.0, size.1);
            println!("{}", Table1Row::HEADER);
            let rows = crate::app::bench::table1(&gpu, frames, size, scale, &only, |r| println!("{}", r.markdown()))?;
            out.write_json(&rows)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Ibl { regions, frames, out } } => {
            let (gpu, size) = out.open()?;
            println!("adapter: {}, {}x{}, median of {frames} frame(s)", gpu.adapter_name(), size.0, size.1);
            println!("{}", IblRow::HEADER);
            let rows = crate::app::bench::ibl(&gpu, &regions, frames, size, |r| println!("{}", r.markdown()))?;
            out.write_json(&rows)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Tessellation { levels, frames, out } } => {
            let (gpu, size) = out.open()?;
            println!("adapter: {}, {}x{}, median of {frames} frame(s)", gpu.adapter_name(), size.0, size.1);
            println!("{}", TessellationRow::HEADER);
            let rows = crate::app::bench::tessellation(&gpu, &levels, frames, size, |r| println!("{}", r.markdown()))?;
            let pairs = 4 * frames.max(1);
            println!(
                "\nwarping's cost, random levels, median of {pairs} interleaved pairs (compute alone; whole frames with the G-buffer draw):\n{}",
                WarpCostRow::HEADER
            );
            let costs = crate::app::bench::tessellation_warp_cost(&gpu, &levels, pairs, size, |r| {
                println!("{}", r.markdown())
            })?;
            out.write_json(&serde_json::json!({ "rows": rows, "warp_cost": costs }))?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Woven { rows, frames, max_triangles, out } } => {
            use crate::app::bench_woven::WovenRow;
            let (gpu, size) = out.open()?;
            println!("adapter: {}, {}x{}, median of {frames} frame(s)", gpu.adapter_name(), size.0, size.1);
            println!("{}", WovenRow::HEADER);
            let rows = crate::app::bench_woven::woven(&gpu, &rows, frames, size, max_triangles, |r| {
                println!("{}", r.markdown())
            })?;
            out.write_json(&rows)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Btf { small, json, frame_sizes, frames } } => {
            use crate::app::bench_btf::{FrameRow, HemRow, TierRow};
            let sizes: Vec<(u32, u32)> =
                frame_sizes.iter().filter(|s| !s.is_empty()).map(|s| parse_size(s)).collect::<anyhow::Result<_>>()?;
            let mut frame_rows = Vec::new();
            if !sizes.is_empty() {
                let gpu = GpuContext::headless(pick_backend(None)?)?;
                println!("adapter: {}, median of {frames} frame(s)\n{}", gpu.adapter_name(), FrameRow::HEADER);
                frame_rows = crate::app::bench_btf::frames(&gpu, &sizes, frames, |r| println!("{}", r.markdown()))?;
                println!();
            }
            println!("{}", HemRow::HEADER);
            let hem = crate::app::bench_btf::hem(small, |r| println!("{}", r.markdown()))?;
            println!("\n{}", TierRow::HEADER);
            let tiers = crate::app::bench_btf::tiers(|r| println!("{}", r.markdown()))?;
            if let Some(path) = json {
                let rows = serde_json::json!({ "frames": frame_rows, "hem": hem, "tiers": tiers });
                crate::io::atomic::write_atomic(&path, serde_json::to_string_pretty(&rows)?.as_bytes())?;
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Ssao { samples, frames, out } } => {
            let (gpu, size) = out.open()?;
            println!(
                "adapter: {}, {}x{}, {samples} samples, median of {frames} frame(s)",
                gpu.adapter_name(),
                size.0,
                size.1
            );
            println!("{}", SsaoRow::HEADER);
            let rows = crate::app::bench::ssao(&gpu, samples, frames, size, |r| println!("{}", r.markdown()))?;
            out.write_json(&rows)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Cuboids { spheres, helices, frames, rounds, out } } => {
            let (gpu, size) = out.open()?;
            let pair = |s: &str| -> anyhow::Result<(usize, usize)> {
                let bad = || anyhow::anyhow!("expected COUNTxTRIANGLES such as 185x2000, not {s:?}");
                let (a, b) = s.split_once('x').ok_or_else(bad)?;
                let (a, b): (usize, usize) =
                    (a.trim().parse().map_err(|_| bad())?, b.trim().parse().map_err(|_| bad())?);
                if a == 0 || b == 0 {
                    return Err(bad());
                }
                Ok((a, b))
            };
            let spheres = pair(&spheres)?;
            let helices = helices.iter().map(|h| pair(h)).collect::<anyhow::Result<Vec<_>>>()?;
            println!(
                "adapter: {}, {}x{}, {rounds} round(s) of blocks A B B A of {frames} frame(s)",
                gpu.adapter_name(),
                size.0,
                size.1
            );
            println!("{}", CuboidRow::HEADER);
            let rows = crate::app::bench::cuboids(&gpu, spheres, &helices, frames, rounds, size, |r| {
                println!("{}", r.markdown())
            })?;
            out.write_json(&rows)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Shadows { lights, tiles, frames, out } } => {
            let (gpu, size) = out.open()?;
            println!("adapter: {}, {}x{}, median of {frames} frame(s)", gpu.adapter_name(), size.0, size.1);
            println!("{}", ShadowRow::HEADER);
            let rows =
                crate::app::bench::shadows(&gpu, &lights, &tiles, frames, size, |r| println!("{}", r.markdown()))?;
            out.write_json(&rows)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench {
            what:
                BenchWhat::Drape {
                    capsules: false,
                    edges,
                    pattern,
                    avatar,
                    substeps,
                    iterations,
                    settle,
                    frames,
                    check_every,
                    no_untangle,
                    no_struts,
                    arm_spread,
                    offset,
                    obj_dir,
                    json,
                    ..
                },
        } => {
            let offsets_cm = if offset.is_empty() {
                vec![crate::garment::Fit::ON_MAKEHUMAN.offset]
            } else {
                let parse = |text: &String| parse_three::<f64>("--offset", "x,y,z", text).map(glam::DVec3::from);
                offset.iter().map(parse).collect::<anyhow::Result<Vec<_>>>()?
            };
            let placed = offsets_cm.iter().map(|o| format!("{o}")).collect::<Vec<_>>().join(", ");
            println!(
                "{} placed at offset {placed} cm on the walking MakeHuman avatar (arms spread {arm_spread} degrees), self-collision on, {} substeps per 1/60 s frame, {iterations} sweeps each, {frames} timed frames of walking{}",
                pattern.display(),
                substeps.map_or("the Garment node's".to_string(), |n| n.to_string()),
                [(no_untangle, ", untangling off"), (no_struts, ", struts off")]
                    .iter()
                    .filter_map(|&(off, what)| off.then_some(what))
                    .collect::<String>()
            );
            let mut rows = Vec::new();
            for &offset_cm in &offsets_cm {
                let setup = crate::app::bench::DrapeSetup {
                    substeps,
                    iterations,
                    untangle: !no_untangle,
                    struts: !no_struts,
                    arm_spread,
                    offset_cm,
                };
                // Each placement's OBJs in a folder of their own when there are several.
                let placement = match offsets_cm.len() {
                    1 => String::new(),
                    _ => format!("offset_{},{},{}", offset_cm.x, offset_cm.y, offset_cm.z),
                };
                for &edge in &edges {
                    let dir = obj_dir.as_ref().map(|d| d.join(&placement).join(format!("edge_{edge}cm")));
                    let r = crate::app::bench::drape_garment(
                        &avatar,
                        &pattern,
                        edge,
                        &setup,
                        settle,
                        frames,
                        check_every,
                        dir.as_deref(),
                    )?;
                    rows.push(r);
                }
            }
            print!("{}", crate::app::bench::markdown_table(&rows));
            if offsets_cm.len() > 1 {
                print!("{}", crate::app::bench::placement_summary(&rows));
            }
            if let Some(path) = json {
                crate::io::atomic::write_atomic(&path, serde_json::to_string_pretty(&rows)?.as_bytes())?;
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench {
            what: BenchWhat::Drape { triangles, settle, frames, swing, check_every, obj_dir, json, .. },
        } => {
            let r = crate::app::bench::drape(triangles, settle, frames, swing, check_every, obj_dir.as_deref())?;
            println!(
                "skirt on a walking capsule body: {} particles, {} triangles, body {} triangles, self-collision on",
                r.particles, r.triangles, r.body_triangles
            );
            println!("settled after {} frames ({:.0} ms)", r.settled_after_frames, r.settle_ms);
            println!(
                "| ms/frame | detection | constraints | self-collision | body collision |\n|---:|---:|---:|---:|---:|"
            );
            println!(
                "| {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |",
                r.frame_ms, r.detection_ms, r.constraints_ms, r.self_collision_ms, r.body_collision_ms
            );
            println!(
                "walking: max body crossings {}, max self crossings {}, min clearance {:.2} mm, max speed {:.2} m/s",
                r.max_body_crossings, r.max_self_crossings, r.min_clearance_mm, r.max_speed
            );
            if let Some(path) = json {
                crate::io::atomic::write_atomic(&path, serde_json::to_string_pretty(&r)?.as_bytes())?;
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Cloth { triangles, warmup, frames } } => {
            println!("tablecloth over torus, frame = 1/60 s, {warmup} warm-up + {frames} timed frames");
            println!(
                "| triangles | mean ms/frame | median | worst | CPU ms/frame | max strain |\n|---:|---:|---:|---:|---:|---:|"
            );
            for r in crate::app::bench::cloth(&triangles, warmup, frames) {
                let cpu = r.cpu_ms.map_or("n/a".to_string(), |c| format!("{c:.2}"));
                println!(
                    "| {} | {:.2} | {:.2} | {:.2} | {cpu} | {:.3} |",
                    r.triangles, r.mean_ms, r.median_ms, r.worst_ms, r.max_strain
                );
            }
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::PemLobes { size, svg, json } } => {
            let rows = crate::app::bench::pem_lobes(size)?;
            println!("Lobe shape error at equal volume, face size {size}:\n");
            print!("{}", crate::app::bench::pem_lobes_markdown(&rows));
            println!("\nCalibration, default kernel, face size {size}:\n");
            print!("{}", crate::app::bench::pem_calibration_markdown(size));
            println!("\nPEM memory (MiB):\n");
            print!("{}", crate::app::bench::pem_memory_markdown());
            if let Some(path) = svg {
                let title = format!("PEM lobe shape error at equal volume, {size}^2 faces");
                crate::io::atomic::write_atomic(&path, crate::app::bench::pem_lobes_svg(&rows, &title).as_bytes())?;
            }
            if let Some(path) = json {
                crate::io::atomic::write_atomic(&path, serde_json::to_string_pretty(&rows)?.as_bytes())?;
            }
            Ok(ExitCode::SUCCESS)
        }
        #[cfg(feature = "editor")]
        Command::Bench { what: BenchWhat::Editor { graph, size, frames, orbit_steps, json, backend } } => {
            // GpuBench's parts, with the editor's own default size.
            let out = GpuBench { size, json, backend };
            let (gpu, size) = out.open()?;
            let gpu = std::sync::Arc::new(gpu);
            let rows = crate::app::bench_editor::editor(&gpu, &graph, size, frames, orbit_steps)?;
            println!("{} in the editor's viewport, on {}:\n", graph.display(), gpu.info.name);
            print!("{}", crate::app::bench::markdown_table(&rows));
            out.write_json(&rows)?;
            Ok(ExitCode::SUCCESS)
        }
        Command::Bench { what: BenchWhat::Graph { nodes, frames } } => {
            let r = crate::app::bench::idle_overhead(nodes, frames)?;
            println!(
                "evaluator overhead, {} nodes, nothing changed: {:.2} us/frame (median of {} batches of {} frames); first frame (all run): {:.1} us",
                nodes, r.median_us, r.batches, r.frames_per_batch, r.first_frame_us
            );
            Ok(ExitCode::SUCCESS)
        }
    }
}

#[cfg(test)]
mod tests {
    use super::{BenchWhat, Cli, Command, parse_three};
    use clap::Parser;

    #[test]
    fn bench_drape_takes_several_placements() {
        let cli =
            Cli::try_parse_from(["werkstatt", "bench", "drape", "--offset", "0,0,3", "--offset", "-0.2,0,3"]).unwrap();
        let Command::Bench { what: BenchWhat::Drape { offset, .. } } = cli.command else { panic!("not bench drape") };
        assert_eq!(offset, ["0,0,3", "-0.2,0,3"]);
    }

    #[test]
    fn three_numbers_parse_and_anything_else_names_the_flag() {
        assert_eq!(parse_three::<f32>("--offset", "x,y,z", "0,4,3").unwrap(), [0.0, 4.0, 3.0]);
        assert_eq!(parse_three::<f32>("--offset", "x,y,z", "-1.5, 2,3").unwrap(), [-1.5, 2.0, 3.0]);
        for bad in ["1,2", "1,2,3,4", "a,2,3", ""] {
            let err = parse_three::<f32>("--offset", "x,y,z", bad).unwrap_err().to_string();
            assert!(err.contains("--offset takes three numbers \"x,y,z\""), "{bad:?}: {err}");
        }
    }
}

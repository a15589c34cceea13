//! `werkstatt bench all`: every GPU bench in a fixed order within a time budget, so that one
//! short run on a borrowed GPU fills every row. Writes each bench's rows as JSON, `all.json`
//! with what ran and for how long, and `summary.md`: our tables beside the seeds' figures.

use std::path::Path;
use std::time::{Duration, Instant};

use serde::Serialize;

use crate::app::bench::{self, MarkdownRow, markdown_table};
use crate::gpu::GpuContext;

/// How much each bench measures: `Small` fits a software rasterizer in a few minutes, `Full`
/// is each bench's own default (the papers' counts) within minutes on a datacenter GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, clap::ValueEnum)]
#[serde(rename_all = "lowercase")]
pub enum Preset {
    /// Small on a CPU adapter (lavapipe, llvmpipe), full on a GPU.
    Auto,
    Small,
    Full,
}

impl Preset {
    /// `Auto` decided by the adapter.
    pub fn resolve(self, gpu: &GpuContext) -> Preset {
        match self {
            Preset::Auto if gpu.info.device_type == wgpu::DeviceType::Cpu => Preset::Small,
            Preset::Auto => Preset::Full,
            p => p,
        }
    }

    /// The whole run's default budget: the 8 minutes on a GPU; lavapipe gets more for
    /// its smaller preset.
    pub fn default_budget(self) -> Duration {
        Duration::from_secs(if self == Preset::Full { 480 } else { 600 })
    }
}

/// One bench of the run, in the order they run.
struct Step {
    name: &'static str,
    /// What it reproduces, for the summary.
    figure: &'static str,
    /// The seeds' figures or the aims to read our rows against (markdown).
    reference: &'static str,
    run: fn(&GpuContext, Preset) -> anyhow::Result<Measured>,
}

/// What a bench produced: its parameters, rows (JSON) and tables (markdown).
struct Measured {
    params: serde_json::Value,
    rows: serde_json::Value,
    markdown: String,
}

impl Measured {
    fn new<R: MarkdownRow + Serialize>(params: serde_json::Value, rows: &[R]) -> anyhow::Result<Measured> {
        Ok(Measured { params, rows: serde_json::to_value(rows)?, markdown: markdown_table(rows) })
    }
}

const VGA: (u32, u32) = (640, 480);
const HD: (u32, u32) = (1920, 1080);

/// The benches `bench all` runs, in order, the fabric papers' tables (the IDSS Table 1,
/// Sattler et al.'s Table 2) last.
const STEPS: [Step; 10] = [
    Step {
        name: "attachments",
        figure: "Deferred warping, Fig. 10: a 928-triangle button attached N times (point, area, curve)",
        reference: "Paper (GTX 580): up to 65 000 buttons, 60.1 MTriangles at the maximum; the times are in the plot only.",
        run: |gpu, p| {
            let (counts, frames, cpu): (&[usize], usize, bool) = match p {
                Preset::Full => (&[1000, 2000, 4000, 8000, 16000, 32000, 65000], 3, true),
                _ => (&[1000, 4000], 1, false),
            };
            let rows = bench::attachments(gpu, counts, frames, VGA, cpu, |_| {})?;
            Measured::new(
                serde_json::json!({ "counts": counts, "frames": frames, "size": VGA, "cpu_path": cpu }),
                &rows,
            )
        },
    },
    Step {
        name: "table1",
        figure: "Deferred warping, Table 1: the Fig. 1 graphs at the paper's triangle counts",
        reference: "The paper's counts and GTX 580 times are in the rows.",
        run: |gpu, p| {
            let (scale, frames) = if p == Preset::Full { (1.0, 3) } else { (0.01, 1) };
            let rows = bench::table1(gpu, frames, VGA, scale, &[], |_| {})?;
            Measured::new(serde_json::json!({ "scale": scale, "frames": frames, "size": VGA }), &rows)
        },
    },
    Step {
        name: "cuboids",
        figure: "Dissertation section 5.1.1: linear against trilinear (cuboid) transforms",
        reference: "Dissertation (GeForce 8800, Core 2 Quad 6600, screen size not given):\n\n\
| scene | objects | triangles | FPS linear | FPS trilinear | ratio |\n|---|---:|---:|---:|---:|---:|\n\
| spheres | 185 | 1.5M | 19.5 | 14.9 | 76% |\n| helix | 4617 | 164k | 16.5 | 13.3 | 80% |\n\
| helix | 2566 | 656k | 10.8 | 8.4 | 77% |",
        run: |gpu, p| {
            let (frames, rounds) = if p == Preset::Full { (5, 15) } else { (2, 1) };
            let helices = [(4617, 36), (2566, 256)];
            let rows = bench::cuboids(gpu, (185, 2000), &helices, frames, rounds, VGA, |_| {})?;
            Measured::new(
                serde_json::json!({ "spheres": [185, 2000], "helices": helices, "frames": frames, "rounds": rounds, "size": VGA }),
                &rows,
            )
        },
    },
    Step {
        name: "pem-memory",
        figure: "Dissertation Table 5.1: PEM memory against the number of lights",
        reference: "Table 5.1 allows x2 for the mip chains; a real chain adds 1/3 (both columns are in the table).",
        run: |_, _| {
            Ok(Measured {
                params: serde_json::json!({}),
                rows: serde_json::Value::Null,
                markdown: bench::pem_memory_markdown(),
            })
        },
    },
    Step {
        name: "ibl",
        figure: "Image-based lighting with PEMs (graphs/fig3_13_glossiness.ron) against the number of regions",
        reference: "Aim on lavapipe: 16 PEMs at 640x480 in 100 ms or less per frame. The dissertation gives no frame times for Fig. 5.22.",
        run: |gpu, p| {
            let (regions, frames): (&[usize], usize) =
                if p == Preset::Full { (&[0, 1, 4, 16, 64, 256], 5) } else { (&[0, 1, 16], 2) };
            let rows = bench::ibl(gpu, regions, frames, VGA, |_| {})?;
            Measured::new(serde_json::json!({ "regions": regions, "frames": frames, "size": VGA }), &rows)
        },
    },
    Step {
        name: "shadows",
        figure: "Shadow atlas and hybrid occlusion (graphs/fig5_24_shadows.ron) against lights and tile size",
        reference: "Aims at 1920x1080 on a GPU: 128 lights within 16.7 ms, 512 within 33 ms. The dissertation measured 15 fps at 128 and 6 fps at 512 lights (Fig. 5.24; hardware and sizes not given).",
        run: |gpu, p| {
            let (lights, tiles, frames, size): (&[usize], &[u32], usize, _) = match p {
                Preset::Full => (&[16, 128, 512], &[128, 256], 3, HD),
                _ => (&[16], &[128], 1, VGA),
            };
            let rows = bench::shadows(gpu, lights, tiles, frames, size, |_| {})?;
            Measured::new(
                serde_json::json!({ "lights": lights, "tiles": tiles, "frames": frames, "size": size }),
                &rows,
            )
        },
    },
    Step {
        name: "ssao",
        figure: "Screen-space ambient occlusion (graphs/fig5_25_occlusion.ron), 16 samples",
        reference: "Aim at 1920x1080 on a GPU: under 1 ms.",
        run: |gpu, p| {
            let (frames, size) = if p == Preset::Full { (10, HD) } else { (3, VGA) };
            let rows = bench::ssao(gpu, 16, frames, size, |_| {})?;
            Measured::new(serde_json::json!({ "samples": 16, "frames": frames, "size": size }), &rows)
        },
    },
    Step {
        name: "tessellation",
        figure: "Adaptive tessellation, Fig. 5.11: triangles and time against the level; the cost of warping",
        reference: "Fig. 5.11's values are in the plot only; the text says warping costs about 9% of the frame rate.",
        run: |gpu, p| {
            let (levels, frames): (&[u32], usize) =
                if p == Preset::Full { (&[1, 2, 3, 4, 6, 8, 12, 16], 5) } else { (&[1, 4, 8], 2) };
            let rows = bench::tessellation(gpu, levels, frames, VGA, |_| {})?;
            let costs = bench::tessellation_warp_cost(gpu, levels, 4 * frames, VGA, |_| {})?;
            Ok(Measured {
                params: serde_json::json!({ "levels": levels, "frames": frames, "size": VGA }),
                rows: serde_json::json!({ "rows": rows, "warp_cost": costs }),
                markdown: format!(
                    "{}\nThe cost of warping (random levels):\n\n{}",
                    markdown_table(&rows),
                    markdown_table(&costs)
                ),
            })
        },
    },
    Step {
        name: "woven",
        figure: "Woven cloth (Zhang et al. 2012, IDSS), Table 1: 4x4 to 32x32 patches at uniform L = 7, L = 9 and adaptive L",
        reference: "Paper (NVIDIA 8400M): adaptive rows at 20-27 FPS (37-49 ms) with 142k-229k triangles; L = 7 from 29 FPS (4x4) down to 1 FPS (32x32), L = 9 at 8 FPS and below. Aim: every adaptive row at 25 FPS or more.",
        run: |gpu, p| {
            let (ids, frames, max): (&[usize], usize, u64) = match p {
                Preset::Full => (&[0, 1, 2, 3, 4, 5], 5, 40_000_000),
                _ => (&[0, 2, 3, 4, 5], 2, 1_500_000),
            };
            let rows = crate::app::bench_woven::woven(gpu, ids, frames, VGA, max, |_| {})?;
            Measured::new(
                serde_json::json!({ "rows": ids, "frames": frames, "max_triangles": max, "size": VGA }),
                &rows,
            )
        },
    },
    Step {
        name: "btf",
        figure: "BTF cloth (Sattler et al. 2003), Table 2 on the CPU: visibility preprocessing, HEM update and eigen-weightset rotation; the BTF tiers' storage",
        reference: "Paper (Athlon 1.5 GHz, Radeon 9700, hemicube 64², c = 16, 1280x960): 9.3 / 9.5 fps (PLS / HEM) for the 900-vertex shirt, 2.1 / 2.1 for the 5222-vertex trousers, 1.3 / 1.1 for the 9208-vertex shirt; HEM update 3.8k ms and VPT 8.0k ms for the 900-vertex shirt, 23.2k / 205.5k ms for the 5222-vertex trousers, 38.5k ms update for the 9208-vertex shirt; about 2 fps with the decomposition instead of 3700 ms per change. Aim: a HEM update at least 30x faster than 3.7 s (under 123 ms) for 900 vertices. Storage: 1230 MB of 8-bit images -> 260 MB per sample.",
        run: |gpu, p| {
            let small = p != Preset::Full;
            // lavapipe: one size, one timed frame (a 1280x960 HEM frame takes seconds there).
            let (sizes, count) = if small { (vec![(640, 480)], 1) } else { (vec![(640, 480), (1280, 960)], 5) };
            let frames = crate::app::bench_btf::frames(gpu, &sizes, count, |_| {})?;
            let hem = crate::app::bench_btf::hem(small, |_| {})?;
            let tiers = crate::app::bench_btf::tiers(|_| {})?;
            Ok(Measured {
                params: serde_json::json!({ "small": small }),
                rows: serde_json::json!({ "frames": frames, "hem": hem, "tiers": tiers }),
                markdown: format!(
                    "Frame rates:\n\n{}\n{}\nTiers:\n\n{}",
                    markdown_table(&frames),
                    markdown_table(&hem),
                    markdown_table(&tiers)
                ),
            })
        },
    },
];

/// The names `--only` takes, in run order.
pub fn bench_names() -> Vec<&'static str> {
    STEPS.iter().map(|s| s.name).collect()
}

/// One bench's record in `all.json`.
#[derive(Debug, Serialize)]
pub struct BenchRecord {
    pub name: &'static str,
    pub figure: &'static str,
    /// "ok", "failed: ..." or "skipped: ...".
    pub status: String,
    pub seconds: f64,
    pub params: serde_json::Value,
    pub rows: serde_json::Value,
}

/// `all.json`.
#[derive(Debug, Serialize)]
pub struct AllReport {
    pub adapter: String,
    pub preset: Preset,
    pub budget_s: f64,
    pub seconds: f64,
    pub benches: Vec<BenchRecord>,
}

impl AllReport {
    pub fn failed(&self) -> usize {
        self.benches.iter().filter(|b| b.status.starts_with("failed")).count()
    }
}

/// Runs the benches named in `only` (all when empty) in their fixed order on `gpu`, skipping
/// those that would start after `budget` has passed, and writes every file into `dir`.
/// `progress` hears each bench as it starts and ends. A bench that fails is recorded and the
/// run goes on.
pub fn run_all(
    gpu: &GpuContext,
    preset: Preset,
    budget: Duration,
    only: &[String],
    dir: &Path,
    mut progress: impl FnMut(&str),
) -> anyhow::Result<AllReport> {
    for name in only {
        anyhow::ensure!(
            STEPS.iter().any(|s| s.name == name),
            "--only {name:?}: no such bench; the benches are {}",
            bench_names().join(", ")
        );
    }
    std::fs::create_dir_all(dir).map_err(|e| anyhow::anyhow!("cannot create {}: {e}", dir.display()))?;
    let preset = preset.resolve(gpu);
    let start = Instant::now();
    let mut report = AllReport {
        adapter: gpu.adapter_name(),
        preset,
        budget_s: budget.as_secs_f64(),
        seconds: 0.0,
        benches: Vec::new(),
    };
    let mut summary = format!(
        "# werkstatt bench all\n\nAdapter: {}. Preset: {preset:?}. Budget: {:.0} s.\n",
        report.adapter,
        budget.as_secs_f64()
    );
    for step in STEPS.iter().filter(|s| only.is_empty() || only.iter().any(|o| o == s.name)) {
        let t0 = Instant::now();
        let (status, measured) = if start.elapsed() >= budget {
            (format!("skipped: the budget of {:.0} s was spent", budget.as_secs_f64()), None)
        } else {
            progress(&format!("{}: running ({})", step.name, step.figure));
            match (step.run)(gpu, preset) {
                Ok(m) => ("ok".to_string(), Some(m)),
                Err(e) => (format!("failed: {e:#}"), None),
            }
        };
        let seconds = t0.elapsed().as_secs_f64();
        progress(&format!("{}: {status} ({seconds:.1} s)", step.name));
        summary.push_str(&format!("\n## {}: {}\n\n", step.name, step.figure));
        let (params, rows) = match measured {
            Some(m) => {
                summary.push_str(&format!("{}\n{}\n", m.markdown, step.reference));
                if !m.rows.is_null() {
                    let path = dir.join(format!("{}.json", step.name));
                    crate::io::atomic::write_atomic(&path, serde_json::to_string_pretty(&m.rows)?.as_bytes())?;
                }
                (m.params, m.rows)
            }
            None => {
                summary.push_str(&format!("Not measured: {status}.\n\n{}\n", step.reference));
                (serde_json::Value::Null, serde_json::Value::Null)
            }
        };
        report.benches.push(BenchRecord { name: step.name, figure: step.figure, status, seconds, params, rows });
    }
    report.seconds = start.elapsed().as_secs_f64();
    summary.push_str(&format!("\nTotal: {:.1} s.\n", report.seconds));
    crate::io::atomic::write_atomic(&dir.join("all.json"), serde_json::to_string_pretty(&report)?.as_bytes())?;
    crate::io::atomic::write_atomic(&dir.join("summary.md"), summary.as_bytes())?;
    Ok(report)
}

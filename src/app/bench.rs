//! Benchmarks of the framework itself (`werkstatt bench ...`).

use std::time::Instant;

use crate::core::eval::{Evaluator, FrameSettings, FrameTime};
use crate::core::graph::{Graph, Link, NodeDoc, PortRef};
use crate::core::param::ParamValue;
use crate::core::resources::Resources;

/// A chain of `n` Math nodes (each adds 1 to its predecessor) ending in a Watch node.
pub fn chain_graph(n: usize) -> Graph {
    let mut g = Graph::new();
    for i in 0..n {
        let mut params = std::collections::BTreeMap::new();
        params.insert("b".to_string(), ParamValue::Float(1.0));
        g.nodes.insert(format!("m{i:04}"), NodeDoc { kind: "Math".into(), pos: [i as f32 * 10.0, 0.0], params });
        if i > 0 {
            g.links.push(Link {
                from: PortRef { node: format!("m{:04}", i - 1), port: "result".into() },
                to: PortRef { node: format!("m{i:04}"), port: "a".into() },
            });
        }
    }
    g.nodes.insert("watch".into(), NodeDoc { kind: "Watch".into(), pos: [0.0, 100.0], params: Default::default() });
    g.links.push(Link {
        from: PortRef { node: format!("m{:04}", n.saturating_sub(1)), port: "result".into() },
        to: PortRef { node: "watch".into(), port: "value".into() },
    });
    g
}

pub struct IdleOverhead {
    pub median_us: f64,
    pub first_frame_us: f64,
    pub batches: usize,
    pub frames_per_batch: usize,
}

pub fn idle_overhead(nodes: usize, frames: usize) -> anyhow::Result<IdleOverhead> {
    let graph = chain_graph(nodes.max(1));
    let mut ev = Evaluator::new(&graph, &[])?;
    let resources = Resources::new(false);
    let settings = FrameSettings::default();
    let t = Instant::now();
    ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, None, &resources, &settings);
    let first_frame_us = t.elapsed().as_secs_f64() * 1e6;
    let batches = 21;
    let per = (frames / batches).max(1);
    let mut samples = Vec::with_capacity(batches);
    for b in 0..batches {
        let t = Instant::now();
        for f in 0..per {
            // The time changes every frame; no node reads it, so nothing re-runs.
            let s = ev.evaluate(FrameTime { frame: (b * per + f + 1) as i64, fps: 30.0 }, None, &resources, &settings);
            debug_assert_eq!(s.ran, 0);
        }
        samples.push(t.elapsed().as_secs_f64() * 1e6 / per as f64);
    }
    samples.sort_by(f64::total_cmp);
    Ok(IdleOverhead { median_us: samples[batches / 2], first_frame_us, batches, frames_per_batch: per })
}

/// One untimed run of `work` (pipelines, uploads), then the median of `frames` timed ones, ms.
pub(crate) fn median_ms(frames: usize, work: &mut dyn FnMut() -> anyhow::Result<()>) -> anyhow::Result<f64> {
    work()?;
    let mut samples = Vec::new();
    for _ in 0..frames.max(1) {
        let t = Instant::now();
        work()?;
        samples.push(t.elapsed().as_secs_f64() * 1e3);
    }
    Ok(median(samples))
}

/// Milliseconds since `t`.
pub(super) fn ms_since(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// The median of samples (the mean of the middle two of an even count); `v` is not empty.
pub(super) fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let mid = v.len() / 2;
    if v.len().is_multiple_of(2) { (v[mid - 1] + v[mid]) / 2.0 } else { v[mid] }
}

/// One row of `werkstatt bench attachments`.
#[derive(Debug, serde::Serialize)]
pub struct AttachRow {
    pub path: &'static str,
    pub instances: usize,
    pub triangles: usize,
    pub ms_per_frame: f64,
    pub mtri_per_s: f64,
}

/// The paper's Fig. 10 experiment: a 928-triangle button attached `counts` times to a
/// surface with point, area and curve attachments, against plain instancing of the same
/// geometry and a CPU path that warps with threads and uploads every frame.
pub fn attachments(
    gpu: &crate::gpu::GpuContext,
    counts: &[usize],
    frames: usize,
    size: (u32, u32),
    cpu_path: bool,
    mut report: impl FnMut(&AttachRow),
) -> anyhow::Result<Vec<AttachRow>> {
    use std::sync::Arc;

    use glam::{Affine2, Mat4, Vec2, Vec3};

    use crate::nodes::mesh::geometry;
    use crate::nodes::warp::attach::point_instance;
    use crate::nodes::warp::matrix_texture::MatrixTextureNode;
    use crate::render::draw::{SceneDrawer, render_gbuffer};
    use crate::render::scene::{Camera, DrawItem, Material};
    use crate::warp::gpu::read_matrix;
    use crate::warp::{AttachedDraw, InstanceData, Placement, WarpMode, WarpSettings, warp_layout_cpu};

    let surface = geometry::plane(1.0, 64, 64)?;
    let matrix =
        Arc::new(MatrixTextureNode::default().render(gpu, &surface, 512, wgpu::TextureFormat::Rgba32Float, 0, None)?);
    let texels = read_matrix(gpu, &matrix)?;
    let button = Arc::new(geometry::disc(0.5, 0.2, 232)?);
    assert_eq!(button.triangle_count(), 928);
    let camera = Camera {
        eye: Vec3::new(0.0, 1.4, 0.9),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_degrees: 40.0,
        near: 0.05,
        far: 10.0,
    };
    let material = Arc::new(Material::default());
    let mut drawer = SceneDrawer::default();
    let median_ms = |work: &mut dyn FnMut() -> anyhow::Result<()>| median_ms(frames, work);
    let mut rows = Vec::new();
    let mut push = |path: &'static str, instances: usize, triangles: usize, ms: f64| {
        let row = AttachRow { path, instances, triangles, ms_per_frame: ms, mtri_per_s: triangles as f64 / ms / 1e3 };
        report(&row);
        rows.push(row);
    };
    for &count in counts {
        let side = (count as f64).sqrt().ceil() as usize;
        let cell = 1.0 / side as f32;
        let places: Vec<Placement> = (0..count)
            .map(|i| Placement {
                piece: 0,
                u: (i % side) as f32 * cell + cell / 2.0,
                v: (i / side) as f32 * cell + cell / 2.0,
                angle: 0.0,
                scale: 1.0,
            })
            .collect();
        let point: Vec<InstanceData> = places.iter().map(|p| point_instance(p, cell * 0.8, 1.0, 0.0, 0.0)).collect();
        // Plain instancing: the same instances placed without a surface (xz = uv - 0.5).
        let plain: Vec<InstanceData> = places
            .iter()
            .map(|p| point_instance(&Placement { u: p.u - 0.5, v: p.v - 0.5, ..*p }, cell * 0.8, 1.0, 0.0, 0.0))
            .collect();
        let area: Vec<InstanceData> = places
            .iter()
            .map(|p| {
                let m = Affine2::from_translation(Vec2::new(p.u, p.v)) * Affine2::from_scale(Vec2::splat(cell * 0.8));
                InstanceData::identity().with_tex(m).with_tan(Mat4::from_scale(Vec3::new(1.0, cell * 0.8, 1.0)))
            })
            .collect();
        // Curves: one straight cubic per row, `side` repetitions along each.
        let curve: Vec<InstanceData> = places
            .iter()
            .enumerate()
            .map(|(i, p)| {
                let (k, row_v) = (i % side, p.v);
                let seg = [
                    Vec2::new(0.0, row_v),
                    Vec2::new(1.0 / 3.0, row_v),
                    Vec2::new(2.0 / 3.0, row_v),
                    Vec2::new(1.0, row_v),
                ];
                InstanceData::identity().with_tan(Mat4::from_scale(Vec3::splat(cell * 0.8))).with_curve(
                    &seg,
                    k as f32 / side as f32,
                    (k + 1) as f32 / side as f32,
                    -0.5,
                    0.5,
                )
            })
            .collect();
        let tris = count * button.triangle_count();
        let cases: [(&'static str, WarpMode, &Vec<InstanceData>); 4] = [
            ("plain instancing", WarpMode::Unattached, &plain),
            ("point", WarpMode::Point, &point),
            ("area", WarpMode::Area, &area),
            ("curve", WarpMode::CurveAligned, &curve),
        ];
        for (name, mode, instances) in cases {
            let draw = AttachedDraw::new(
                matrix.clone(),
                WarpSettings { mode, gravity: 0.0, min_weight: 0.5 },
                instances.clone(),
            );
            let item = DrawItem { detail: true, ..DrawItem::plain(button.clone(), material.clone(), Mat4::IDENTITY) }
                .with_kind(draw);
            let ms = median_ms(&mut || {
                render_gbuffer(gpu, &mut drawer, std::slice::from_ref(&item), camera, size.0, size.1)?;
                gpu.submit_checked()?;
                gpu.wait_idle();
                Ok(())
            })?;
            push(name, count, tris, ms);
        }
        if cpu_path {
            let settings = WarpSettings { mode: WarpMode::Point, gravity: 0.0, min_weight: 0.5 };
            let nv = button.positions.len();
            let indices: Vec<u32> =
                (0..count as u32).flat_map(|i| button.indices.iter().map(move |&k| k + i * nv as u32)).collect();
            let uvs: Vec<Vec2> = (0..count).flat_map(|_| button.uvs.iter().copied()).collect();
            let ms = median_ms(&mut || {
                let warped = warp_layout_cpu(&texels, &settings, &button, &point);
                let normals = warped.normals;
                let mesh = crate::mesh::Mesh::from_raw(
                    warped.positions,
                    normals.clone(),
                    uvs.clone(),
                    normals.clone(),
                    normals,
                    indices.clone(),
                );
                let item =
                    DrawItem { detail: true, ..DrawItem::plain(Arc::new(mesh), material.clone(), Mat4::IDENTITY) };
                render_gbuffer(gpu, &mut drawer, std::slice::from_ref(&item), camera, size.0, size.1)?;
                gpu.submit_checked()?;
                gpu.wait_idle();
                Ok(())
            })?;
            push("cpu warp + upload", count, tris, ms);
        }
    }
    Ok(rows)
}

/// One row of `werkstatt bench cloth`.
#[derive(Debug, serde::Serialize)]
pub struct ClothRow {
    pub target_triangles: usize,
    pub triangles: usize,
    pub mean_ms: f64,
    pub median_ms: f64,
    pub worst_ms: f64,
    /// On-CPU time of the simulating thread (Linux), unaffected by a busy machine's waits.
    pub cpu_ms: Option<f64>,
    pub max_strain: f32,
}

/// Simulation time per frame (1/60 s) against triangle count for the tablecloth preset,
/// after `warmup` frames so the cloth is in contact with the torus.
pub fn cloth(sizes: &[usize], warmup: usize, frames: usize) -> Vec<ClothRow> {
    use crate::cloth::{FRAME_DT, Preset, TableclothParams};
    let cpu_ns = || -> Option<u64> {
        std::fs::read_to_string("/proc/thread-self/schedstat").ok()?.split_whitespace().next()?.parse().ok()
    };
    sizes
        .iter()
        .map(|&target| {
            let mut cloth = Preset::Tablecloth(TableclothParams { triangles: target, ..Default::default() }).build();
            for _ in 0..warmup {
                cloth.step_frame(FRAME_DT);
            }
            let cpu_start = cpu_ns();
            let mut times: Vec<f64> = (0..frames.max(1))
                .map(|_| {
                    let t = Instant::now();
                    cloth.step_frame(FRAME_DT);
                    ms_since(t)
                })
                .collect();
            let cpu_ms = match (cpu_start, cpu_ns()) {
                (Some(a), Some(b)) => Some((b - a) as f64 / 1e6 / times.len() as f64),
                _ => None,
            };
            let mean_ms = times.iter().sum::<f64>() / times.len() as f64;
            times.sort_by(f64::total_cmp);
            ClothRow {
                target_triangles: target,
                triangles: cloth.triangle_count(),
                mean_ms,
                median_ms: times[times.len() / 2],
                worst_ms: times[times.len() - 1],
                cpu_ms,
                max_strain: cloth.max_strain(),
            }
        })
        .collect()
}

/// Evaluates `frame` until nothing is pending (the light probe loads first), waiting for the
/// GPU after each pass; a failed node or a load taking over 600 s is an error naming `what`.
pub(crate) fn settle_frame(
    ev: &mut Evaluator,
    gpu: &crate::gpu::GpuContext,
    resources: &Resources,
    settings: &FrameSettings,
    frame: i64,
    what: &str,
) -> anyhow::Result<()> {
    use crate::core::eval::NodeStatus;
    let deadline = Instant::now() + std::time::Duration::from_secs(600);
    loop {
        let s = ev.evaluate(FrameTime { frame, fps: 30.0 }, Some(gpu), resources, settings);
        gpu.wait_idle();
        if s.failed > 0 {
            let why: Vec<String> = ev
                .reports()
                .filter(|r| !matches!(r.status, NodeStatus::Ok))
                .map(|r| format!("{}: {:?}", r.id, r.status))
                .collect();
            anyhow::bail!("{what} failed: {}", why.join("; "));
        }
        if s.pending == 0 {
            return Ok(());
        }
        anyhow::ensure!(Instant::now() < deadline, "{what}: files did not load within 600 s");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
}

/// One row of `werkstatt bench ibl`.
#[derive(Debug, serde::Serialize)]
pub struct IblRow {
    /// Median-cut regions (PEMs); 0 for the single lookup into the filtered full map.
    pub regions: usize,
    /// Median cut + PEM filtering + one shaded frame, after changing the region count.
    pub rebuild_ms: f64,
    /// One frame with a moving camera: G-buffer + IBL shading (median).
    pub frame_ms: f64,
    /// GPU memory of the PEMs (MiB), mip chains included.
    pub pem_mib: f64,
}

/// IBL cost against the number of regions: graphs/fig3_13_glossiness.ron (six spheres under
/// the forest probe) with the camera orbiting so every frame re-renders and re-shades.
pub fn ibl(
    gpu: &crate::gpu::GpuContext,
    regions: &[usize],
    frames: usize,
    size: (u32, u32),
    mut report: impl FnMut(&IblRow),
) -> anyhow::Result<Vec<IblRow>> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs");
    let mut graph = Graph::load(&dir.join("fig3_13_glossiness.ron")).map_err(|e| anyhow::anyhow!("{e}"))?;
    let set = |graph: &mut Graph, node: &str, param: &str, value: ParamValue| -> anyhow::Result<()> {
        graph
            .nodes
            .get_mut(node)
            .ok_or_else(|| anyhow::anyhow!("fig3_13_glossiness.ron has no node {node}"))?
            .params
            .insert(param.into(), value);
        Ok(())
    };
    set(&mut graph, "camera", "orbit_speed", ParamValue::Float(30.0))?;
    let resources = Resources::new(false);
    let settings = FrameSettings { width: size.0, height: size.1, base_dir: dir, frames: None };
    let mut ev = Evaluator::new(&graph, &[])?;
    let mut frame = 0i64;
    let mut step = |ev: &mut Evaluator| -> anyhow::Result<()> {
        settle_frame(ev, gpu, &resources, &settings, frame, "the IBL graph")?;
        frame += 1;
        Ok(())
    };
    step(&mut ev)?;
    let mut rows = Vec::new();
    for &n in regions {
        let (mode, count) = if n == 0 { ("full", 1) } else { ("pems", n) };
        set(&mut graph, "median_cut", "count", ParamValue::Int(count as i64))?;
        set(&mut graph, "ibl", "mode", ParamValue::Str(mode.into()))?;
        ev.update(&graph, &[])?;
        let t = Instant::now();
        step(&mut ev)?;
        let rebuild_ms = t.elapsed().as_secs_f64() * 1e3;
        let mut samples = Vec::new();
        for _ in 0..frames.max(1) {
            let t = Instant::now();
            step(&mut ev)?;
            samples.push(t.elapsed().as_secs_f64() * 1e3);
        }
        samples.sort_by(f64::total_cmp);
        let pem_mib = match ev.output("pems", "memory_mb") {
            Some(crate::core::port::Value::Scalar(mb)) if n > 0 => *mb,
            _ => 0.0,
        };
        let row = IblRow { regions: n, rebuild_ms, frame_ms: samples[samples.len() / 2], pem_mib };
        report(&row);
        rows.push(row);
    }
    Ok(rows)
}

/// One row of `werkstatt bench pem-lobes`: a kernel's lobe error at one Phong exponent.
#[derive(Debug, serde::Serialize)]
pub struct PemLobeRow {
    pub kernel: &'static str,
    pub size: usize,
    pub s: f32,
    #[serde(flatten)]
    pub error: crate::ibl::pem::LobeError,
}

/// The dissertation's Figs. 5.19/5.20 on the CPU: every kernel at every exponent of
/// [`BENCH_EXPONENTS`](crate::ibl::pem::BENCH_EXPONENTS), face size `size`.
pub fn pem_lobes(size: usize) -> anyhow::Result<Vec<PemLobeRow>> {
    use crate::core::param::Choice as _;
    use crate::ibl::pem::{BENCH_EXPONENTS, Kernel, lobe_error};
    if !size.is_power_of_two() || !(4..=1024).contains(&size) {
        anyhow::bail!("--size {size}: the face size must be a power of two in 4..=1024");
    }
    // One thread per kernel (the impulse chains and calibrations are independent).
    let rows = std::thread::scope(|s| {
        let handles: Vec<_> = Kernel::ALL
            .iter()
            .map(|&k| {
                s.spawn(move || {
                    BENCH_EXPONENTS
                        .iter()
                        .map(|&e| PemLobeRow { kernel: k.name(), size, s: e, error: lobe_error(k, size, e) })
                        .collect::<Vec<_>>()
                })
            })
            .collect();
        handles.into_iter().flat_map(|h| h.join().expect("lobe error thread")).collect()
    });
    Ok(rows)
}

/// The shape errors as a Markdown table: one row per exponent, one column per kernel (%),
/// plus the default kernel's calibrated level and volume error.
pub fn pem_lobes_markdown(rows: &[PemLobeRow]) -> String {
    use crate::core::param::Choice as _;
    use crate::ibl::pem::{BENCH_EXPONENTS, Kernel};
    let mut out = String::from("| s |");
    for k in Kernel::ALL {
        out += &format!(" {} |", k.name());
    }
    let default = Kernel::default().name();
    out += &format!(" level ({default}) | volume error ({default}) |\n|---:|");
    out += &"---:|".repeat(Kernel::ALL.len() + 2);
    out += "\n";
    for &s in &BENCH_EXPONENTS {
        out += &format!("| {s} |");
        for k in Kernel::ALL {
            let r = rows.iter().find(|r| r.s == s && r.kernel == k.name());
            out += &r.map_or(" |".to_string(), |r| format!(" {:.1}% |", 100.0 * r.error.shape_error));
        }
        let d = rows.iter().find(|r| r.s == s && r.kernel == default);
        out += &d
            .map_or(" | |".to_string(), |r| format!(" {:.3} | {:+.2}% |", r.error.level, 100.0 * r.error.volume_error));
        out += "\n";
    }
    out
}

/// The shape error (%) against s on a log axis, one polyline per kernel, as SVG text (colours
/// as in the dissertation's Fig. 5.20: none dotted violet, gaussian black, box red, cosine
/// green, sqrt_cosine blue).
pub fn pem_lobes_svg(rows: &[PemLobeRow], title: &str) -> String {
    use crate::core::param::Choice as _;
    use crate::ibl::pem::Kernel;
    let chart =
        crate::io::svg::Chart { width: 760.0, height: 440.0, left: 70.0, right: 170.0, top: 40.0, bottom: 50.0 };
    let (w, h, left, right, top, bottom) =
        (chart.width, chart.height, chart.left, chart.right, chart.top, chart.bottom);
    let max_err = rows.iter().map(|r| 100.0 * r.error.shape_error as f64).fold(10.0f64, f64::max);
    let y_max = ((max_err / 10.0).ceil() * 10.0).min(200.0);
    let x = |s: f64| left + (s.log10() / 3.0) * (w - left - right);
    let y = |e: f64| top + (1.0 - (e / y_max).min(1.0)) * (h - top - bottom);
    let mut svg = chart.open(title);
    for s in [1.0f64, 10.0, 100.0, 1000.0] {
        svg += &format!(
            "<line x1=\"{0:.1}\" y1=\"{top}\" x2=\"{0:.1}\" y2=\"{1:.1}\" stroke=\"#ccc\"/><text x=\"{0:.1}\" y=\"{2:.1}\" text-anchor=\"middle\">{s}</text>\n",
            x(s),
            h - bottom,
            h - bottom + 16.0
        );
    }
    let step = if y_max > 50.0 { 20.0 } else { 10.0 };
    let mut e = 0.0;
    while e <= y_max + 1e-3 {
        svg += &format!(
            "<line x1=\"{left}\" y1=\"{0:.1}\" x2=\"{1:.1}\" y2=\"{0:.1}\" stroke=\"#ccc\"/><text x=\"{2:.1}\" y=\"{3:.1}\" text-anchor=\"end\">{e}%</text>\n",
            y(e),
            w - right,
            left - 6.0,
            y(e) + 4.0
        );
        e += step;
    }
    svg += &chart.axis_titles("Phong exponent s (log)", "shape error at equal volume");
    for (i, k) in Kernel::ALL.iter().enumerate() {
        let (colour, dash) = match k {
            Kernel::None => ("#8a2be2", "3 3"),
            Kernel::Box => ("#d62728", ""),
            Kernel::Gaussian => ("#000000", ""),
            Kernel::Cosine => ("#2ca02c", ""),
            Kernel::SqrtCosine => ("#1f4fd6", ""),
            Kernel::Phong => ("#ff7f0e", ""),
        };
        let points = rows
            .iter()
            .filter(|r| r.kernel == k.name())
            .map(|r| (x(r.s as f64), y(100.0 * r.error.shape_error as f64)));
        svg += &chart.series(i, k.name(), colour, dash, points);
    }
    svg + "</svg>\n"
}

/// The default kernel's calibration table at face size `size` as Markdown (s -> level).
pub fn pem_calibration_markdown(size: usize) -> String {
    use crate::core::param::Choice as _;
    use crate::ibl::pem::{Kernel, TABLE, calibration, table_exponent};
    let c = calibration(Kernel::default(), size);
    let mut out = format!("| i | s | g = 1 - 1/s | level ({}, {size}^2) |\n|---:|---:|---:|---:|\n", c.kernel.name());
    for i in 0..TABLE {
        let s = table_exponent(i);
        out += &format!("| {i} | {s:.2} | {:.4} | {:.4} |\n", 1.0 - 1.0 / s, c.levels[i]);
    }
    out
}

/// PEM memory (MiB) with a real mip chain (x4/3) beside the dissertation's Table 5.1 (x2).
pub fn pem_memory_markdown() -> String {
    let mib = |b: u64| b as f64 / (1024.0 * 1024.0);
    let mut out = String::from(
        "| N | 128^2, x4/3 (ours) | 128^2, x2 (Table 5.1) | 256^2, x4/3 (ours) | 256^2, x2 (Table 5.1) |\n|---:|---:|---:|---:|---:|\n",
    );
    for n in [1u64, 12, 32, 64, 128, 256] {
        let row: Vec<String> = [128u64, 256]
            .iter()
            .flat_map(|&res| {
                let ours = crate::ibl::pem::pem_memory_bytes(n, res);
                [format!("{:.2}", mib(ours)), format!("{}", mib(n * 6 * res * res * 8 * 2))]
            })
            .collect();
        out += &format!("| {n} | {} |\n", row.join(" | "));
    }
    out
}

/// One row of `werkstatt bench ssao`.
#[derive(Debug, serde::Serialize)]
pub struct SsaoRow {
    pub mode: &'static str,
    pub half_resolution: bool,
    pub samples: u32,
    /// The Ssao passes alone (estimate, 4x4 filter, upsampling), median ms per frame.
    pub ms_per_frame: f64,
}

/// The spheres-on-a-plane scene of graphs/fig5_25_occlusion.ron (five spheres of radius
/// 0.15-0.3 on a 4 x 4 plane, camera 35 degrees down): its world draw items and camera.
pub fn occlusion_scene() -> anyhow::Result<(Vec<crate::render::scene::DrawItem>, crate::render::scene::Camera)> {
    use std::sync::Arc;

    use glam::{Mat4, Vec3};

    use crate::nodes::mesh::geometry;
    use crate::render::scene::{Camera, DrawItem, Material};

    let material = Arc::new(Material::default());
    let item = |mesh: &Arc<crate::mesh::Mesh>, model: Mat4| DrawItem::plain(mesh.clone(), material.clone(), model);
    let floor = Arc::new(geometry::plane(4.0, 1, 1)?);
    let ball = Arc::new(geometry::sphere(1.0, 64, 32)?);
    let mut items = vec![item(&floor, Mat4::IDENTITY)];
    for (x, z, r) in [(-0.9, 0.3, 0.3), (-0.35, -0.25, 0.2), (0.15, 0.15, 0.25), (0.62, -0.2, 0.15), (0.7, 0.45, 0.22)]
    {
        items.push(item(
            &ball,
            Mat4::from_scale_rotation_translation(Vec3::splat(r), Default::default(), Vec3::new(x, r, z)),
        ));
    }
    let (yaw, pitch) = (20f32.to_radians(), 35f32.to_radians());
    let target = Vec3::new(0.0, 0.1, 0.05);
    let eye = target + Vec3::new(yaw.sin() * pitch.cos(), pitch.sin(), yaw.cos() * pitch.cos()) * 3.2;
    Ok((items, Camera { eye, target, up: Vec3::Y, fov_y_degrees: 40.0, near: 0.05, far: 100.0 }))
}

/// SSAO cost per frame on the spheres scene: each mode at full and half resolution, the
/// G-buffer drawn once, then the median of `frames` runs of the Ssao passes (each waited for).
pub fn ssao(
    gpu: &crate::gpu::GpuContext,
    samples: u32,
    frames: usize,
    size: (u32, u32),
    mut report: impl FnMut(&SsaoRow),
) -> anyhow::Result<Vec<SsaoRow>> {
    use crate::occlusion::ssao::{SsaoMode, SsaoRunner, SsaoSettings};
    use crate::render::draw::{SceneDrawer, render_gbuffer};

    let (items, camera) = occlusion_scene()?;
    let mut drawer = SceneDrawer::default();
    let g = render_gbuffer(gpu, &mut drawer, &items, camera, size.0, size.1)?;
    gpu.submit_checked()?;
    gpu.wait_idle();
    let mut runner = SsaoRunner::default();
    let mut rows = Vec::new();
    for (mode, name) in [(SsaoMode::Sphere, "sphere"), (SsaoMode::Horizon, "horizon")] {
        for half_resolution in [false, true] {
            let settings = SsaoSettings { mode, radius: 0.3, samples, half_resolution, blur: true, strength: 1.0 };
            let mut once = || -> anyhow::Result<f64> {
                let t = Instant::now();
                let out = runner.occlusion(gpu, &g, &settings)?;
                gpu.submit_checked()?;
                gpu.wait_idle();
                drop(out);
                Ok(t.elapsed().as_secs_f64() * 1e3)
            };
            once()?;
            let mut samples_ms = (0..frames.max(1)).map(|_| once()).collect::<anyhow::Result<Vec<f64>>>()?;
            samples_ms.sort_by(f64::total_cmp);
            let row = SsaoRow { mode: name, half_resolution, samples, ms_per_frame: samples_ms[samples_ms.len() / 2] };
            report(&row);
            rows.push(row);
        }
    }
    Ok(rows)
}

/// One row of `werkstatt bench tessellation`.
#[derive(Debug, serde::Serialize)]
pub struct TessellationRow {
    /// "equal": every vertex at `level`; "random": vertex levels uniform in [1, level].
    pub levels: &'static str,
    pub mode: &'static str,
    pub level: u32,
    /// Triangles generated (counted by the CPU reference's `counts`).
    pub triangles: u64,
    /// Median time of the compute passes alone (recorded, submitted, waited for).
    pub compute_ms: f64,
    pub mtri_per_s: f64,
    /// Median time of tessellation + G-buffer draw of the result at the bench size.
    pub frame_ms: f64,
}

/// Fig. 5.11 on this machine: a 1024-triangle sphere tessellated in every mode at each level.
pub fn tessellation(
    gpu: &crate::gpu::GpuContext,
    levels: &[u32],
    frames: usize,
    size: (u32, u32),
    mut report: impl FnMut(&TessellationRow),
) -> anyhow::Result<Vec<TessellationRow>> {
    use crate::core::param::Choice;
    use crate::tessellation::{Lod, Metric, Mode, Settings, ViewLod, counts, triangle_edge_levels};

    let mesh = tessellation_bench_mesh(1)?.0;
    let camera = tessellation_bench_camera();
    let view = crate::render::scene::View::new(&camera, size.0, size.1);
    let mut timer = TessTimer::new(size);
    let mut rows = Vec::new();
    for (kind, random) in [("equal", false), ("random", true)] {
        for &level in levels {
            let level = level.clamp(1, 64);
            let vertex_levels =
                if random { tessellation_bench_mesh(level)?.1 } else { vec![level as f32; mesh.positions.len()] };
            for mode in [Mode::Uniform, Mode::Dyadic, Mode::Pattern, Mode::PatternWarp] {
                let s = Settings { mode, max_level: level, pn: true };
                let triangles: u64 = mesh
                    .indices
                    .chunks_exact(3)
                    .map(|t| {
                        let n = triangle_edge_levels(&vertex_levels, [t[0], t[1], t[2]], &s);
                        u64::from(counts(n, mode == Mode::Dyadic).1)
                    })
                    .sum();
                let lod = ViewLod {
                    view_proj: view.view_proj,
                    eye: camera.eye,
                    width: size.0 as f32,
                    height: size.1 as f32,
                    lod: Lod { near: 1.0, far: 10.0, max_level: level as f32, silhouette: 0.0 },
                    metric: Metric::Distance,
                    max_edge_px: 16.0,
                };
                let mut once = |draw: bool| timer.time(gpu, &mesh, &vertex_levels, &lod, &s, draw);
                let median = |once: &mut dyn FnMut(bool) -> anyhow::Result<f64>, draw: bool| -> anyhow::Result<f64> {
                    once(draw)?;
                    let mut v = (0..frames.max(1)).map(|_| once(draw)).collect::<anyhow::Result<Vec<f64>>>()?;
                    v.sort_by(f64::total_cmp);
                    Ok(v[v.len() / 2])
                };
                let compute_ms = median(&mut once, false)?;
                let frame_ms = median(&mut once, true)?;
                let row = TessellationRow {
                    levels: kind,
                    mode: mode.name(),
                    level,
                    triangles,
                    compute_ms,
                    mtri_per_s: triangles as f64 / compute_ms / 1e3,
                    frame_ms,
                };
                report(&row);
                rows.push(row);
            }
        }
    }
    Ok(rows)
}

/// Warping's cost in `werkstatt bench tessellation`: the pattern without and with warping,
/// measured in interleaved pairs (alternating which runs first) so that load changes on a
/// shared machine hit both alike; the compute passes alone, and the frame (compute and the
/// G-buffer draw of the result), whose rate the dissertation's 9% refers to.
#[derive(Debug, serde::Serialize)]
pub struct WarpCostRow {
    pub level: u32,
    pub pairs: usize,
    /// Medians over the pairs (ms), compute alone.
    pub pattern_ms: f64,
    pub pattern_warp_ms: f64,
    /// The median over pairs of pattern_warp / pattern, minus 1 (0.05 = 5% slower), compute alone.
    pub cost: f64,
    /// Medians over the pairs (ms) of whole frames.
    pub frame_pattern_ms: f64,
    pub frame_pattern_warp_ms: f64,
    /// The loss of frame rate: 1 - the median over pairs of pattern / pattern_warp frame time.
    pub frame_rate_loss: f64,
}

/// Times `run(false, k)` (A) against `run(true, k)` (B) in `pairs` interleaved pairs, each
/// going first in half of them, so that a change of the machine's load during the run falls on
/// both alike (one untimed call of each first). Returns the medians of A's and B's times and
/// the median of the pairs' ratios B / A.
fn interleaved_pairs(
    pairs: usize,
    mut run: impl FnMut(bool, usize) -> anyhow::Result<f64>,
) -> anyhow::Result<(f64, f64, f64)> {
    run(false, 0)?;
    run(true, 0)?;
    let (mut a, mut b, mut ratio) = (Vec::new(), Vec::new(), Vec::new());
    for k in 1..=pairs.max(1) {
        let (ta, tb) = if k % 2 == 0 {
            let ta = run(false, k)?;
            (ta, run(true, k)?)
        } else {
            let tb = run(true, k)?;
            (run(false, k)?, tb)
        };
        a.push(ta);
        b.push(tb);
        ratio.push(tb / ta);
    }
    Ok((median(a), median(b), median(ratio)))
}

/// Like [`interleaved_pairs`], but each path runs `frames` frames in a row, in `rounds` rounds
/// of blocks A B B A (drift cancels within a round): what a scene that keeps one kind of
/// transform does every frame. A path whose cost depends on what the frame before left behind
/// (buffers, caches, descriptor state) shows it here, where alternating frames would hide it.
/// Each block starts with one untimed frame. Returns the medians of each path's frames, and
/// the median over rounds of each round's ratio b / a (of its frames' medians): a round takes
/// seconds, so a change of the machine's speed between rounds does not enter a ratio.
fn abba_blocks(
    frames: usize,
    rounds: usize,
    mut run: impl FnMut(bool, usize) -> anyhow::Result<f64>,
) -> anyhow::Result<(f64, f64, f64)> {
    let (mut a, mut b, mut ratios) = (Vec::new(), Vec::new(), Vec::new());
    let mut frame = 0;
    for _ in 0..rounds.max(1) {
        let (mut round_a, mut round_b) = (Vec::new(), Vec::new());
        for second in [false, true, true, false] {
            run(second, frame)?;
            for _ in 0..frames.max(1) {
                frame += 1;
                let t = run(second, frame)?;
                if second { round_b.push(t) } else { round_a.push(t) }
            }
        }
        ratios.push(median(round_b.clone()) / median(round_a.clone()));
        a.extend(round_a);
        b.extend(round_b);
    }
    Ok((median(a), median(b), median(ratios)))
}

/// Times one tessellation of the bench mesh (recorded, submitted, waited for), optionally with
/// the G-buffer draw of the result at `size` from the bench camera: what both tessellation
/// tables time.
struct TessTimer {
    tess: crate::tessellation::GpuTessellator,
    drawer: crate::render::draw::SceneDrawer,
    size: (u32, u32),
}

impl TessTimer {
    fn new(size: (u32, u32)) -> Self {
        TessTimer { tess: Default::default(), drawer: Default::default(), size }
    }

    /// Milliseconds of one run.
    fn time(
        &mut self,
        gpu: &crate::gpu::GpuContext,
        mesh: &std::sync::Arc<crate::mesh::Mesh>,
        levels: &[f32],
        lod: &crate::tessellation::ViewLod,
        settings: &crate::tessellation::Settings,
        draw: bool,
    ) -> anyhow::Result<f64> {
        let t = Instant::now();
        let out = self.tess.run(gpu, mesh, Some(levels), lod, settings)?;
        let item = crate::render::scene::DrawItem::plain(mesh.clone(), Default::default(), glam::Mat4::IDENTITY)
            .with_kind(out);
        let (w, h) = self.size;
        let camera = tessellation_bench_camera();
        let g = draw
            .then(|| crate::render::draw::render_gbuffer(gpu, &mut self.drawer, &[item], camera, w, h))
            .transpose()?;
        gpu.submit_checked()?;
        gpu.wait_idle();
        drop(g);
        Ok(t.elapsed().as_secs_f64() * 1e3)
    }
}

/// The tessellation bench's view of its sphere.
fn tessellation_bench_camera() -> crate::render::scene::Camera {
    crate::render::scene::Camera {
        eye: glam::Vec3::new(0.0, 0.5, 3.0),
        target: glam::Vec3::ZERO,
        up: glam::Vec3::Y,
        fov_y_degrees: 40.0,
        near: 0.05,
        far: 100.0,
    }
}

/// The 1024-triangle sphere of the tessellation bench and its random vertex levels in [1, level].
fn tessellation_bench_mesh(level: u32) -> anyhow::Result<(std::sync::Arc<crate::mesh::Mesh>, Vec<f32>)> {
    let mesh = std::sync::Arc::new(crate::nodes::mesh::geometry::sphere(1.0, 32, 16)?);
    let mut rng = crate::core::rng::SplitMix64::new(5);
    let levels = (0..mesh.positions.len()).map(|_| 1.0 + (level as f32 - 1.0) * rng.next_f32()).collect();
    Ok((mesh, levels))
}

/// Warping's cost (Fig. 5.11's red against green line) at each level, random vertex levels:
/// the compute passes alone, and whole frames (the G-buffer draw of the result at `size` with
/// the camera of [`tessellation`]).
pub fn tessellation_warp_cost(
    gpu: &crate::gpu::GpuContext,
    levels: &[u32],
    pairs: usize,
    size: (u32, u32),
    mut report: impl FnMut(&WarpCostRow),
) -> anyhow::Result<Vec<WarpCostRow>> {
    use crate::tessellation::{Lod, Metric, Mode, Settings, ViewLod};
    let mut timer = TessTimer::new(size);
    let mut rows = Vec::new();
    for &level in levels {
        let level = level.clamp(1, 64);
        let (mesh, vertex_levels) = tessellation_bench_mesh(level)?;
        let lod = ViewLod {
            view_proj: glam::Mat4::IDENTITY,
            eye: glam::Vec3::ZERO,
            width: 1.0,
            height: 1.0,
            lod: Lod { near: 1.0, far: 10.0, max_level: level as f32, silhouette: 0.0 },
            metric: Metric::Distance,
            max_edge_px: 16.0,
        };
        let mut once = |mode: Mode, draw: bool| {
            timer.time(gpu, &mesh, &vertex_levels, &lod, &Settings { mode, max_level: level, pn: true }, draw)
        };
        let mode = |warp: bool| if warp { Mode::PatternWarp } else { Mode::Pattern };
        let (pattern_ms, pattern_warp_ms, ratio) = interleaved_pairs(pairs, |warp, _| once(mode(warp), false))?;
        let (frame_pattern_ms, frame_pattern_warp_ms, frame_ratio) =
            interleaved_pairs(pairs, |warp, _| once(mode(warp), true))?;
        let row = WarpCostRow {
            level,
            pairs: pairs.max(1),
            pattern_ms,
            pattern_warp_ms,
            cost: ratio - 1.0,
            frame_pattern_ms,
            frame_pattern_warp_ms,
            frame_rate_loss: 1.0 - 1.0 / frame_ratio,
        };
        report(&row);
        rows.push(row);
    }
    Ok(rows)
}

/// One row of `werkstatt bench shadows`.
#[derive(Debug, serde::Serialize)]
pub struct ShadowRow {
    pub lights: usize,
    pub tile: u32,
    pub atlas_width: u32,
    pub atlas_height: u32,
    /// Atlas memory (MiB): its texels x 4 bytes (Rg16Float).
    pub atlas_mib: f64,
    /// The dissertation's Table 5.1 rule for VSMs: N x res^2 x 4 bytes (MiB).
    pub table_mib: f64,
    /// Median frame time (ms); None where skipped.
    pub ms_per_frame: Option<f64>,
    pub note: String,
}

/// Frame time against light count and atlas tile size on graphs/fig5_24_shadows.ron (its
/// unshadowed IblShading removed): each timed frame moves a sphere a little, so the G-buffer,
/// the shadow atlas, the shadowed IBL, SSAO and the combination all run; the PEMs (which do
/// not depend on the scene) are rebuilt, untimed, when the light count changes. Atlases
/// wider than the device's texture limit are skipped.
pub fn shadows(
    gpu: &crate::gpu::GpuContext,
    lights: &[usize],
    tiles: &[u32],
    frames: usize,
    size: (u32, u32),
    mut report: impl FnMut(&ShadowRow),
) -> anyhow::Result<Vec<ShadowRow>> {
    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs");
    let mut graph = Graph::load(&dir.join("fig5_24_shadows.ron")).map_err(|e| anyhow::anyhow!("{e}"))?;
    graph.nodes.remove("unshadowed");
    graph.links.retain(|l| l.from.node != "unshadowed" && l.to.node != "unshadowed");
    let set = |graph: &mut Graph, node: &str, param: &str, value: ParamValue| -> anyhow::Result<()> {
        graph
            .nodes
            .get_mut(node)
            .ok_or_else(|| anyhow::anyhow!("fig5_24_shadows.ron has no node {node}"))?
            .params
            .insert(param.into(), value);
        Ok(())
    };
    let resources = Resources::new(false);
    let settings = FrameSettings { width: size.0, height: size.1, base_dir: dir, frames: None };
    let mut ev = Evaluator::new(&graph, &[])?;
    let mut frame = 0i64;
    let mut step = |ev: &mut Evaluator, graph: &mut Graph| -> anyhow::Result<()> {
        // Move a sphere by a hair: the scene changes, so everything downstream of it re-runs.
        let y = 0.3 + 1e-4 * (frame % 2) as f64;
        set(graph, "sphere_0", "translate", ParamValue::Vec(vec![-0.9, y, 0.3]))?;
        ev.update(graph, &[])?;
        settle_frame(ev, gpu, &resources, &settings, frame, "the shadow graph")?;
        frame += 1;
        Ok(())
    };
    let max_dim = gpu.limits.max_texture_dimension_2d;
    let mut rows = Vec::new();
    for &n in lights {
        for &tile in tiles {
            let (columns, rows_) = crate::nodes::ibl::shadow_atlas::grid(n);
            let (w, h) = (columns * tile, rows_ * tile);
            let mib = |b: u64| b as f64 / (1u64 << 20) as f64;
            let mut row = ShadowRow {
                lights: n,
                tile,
                atlas_width: w,
                atlas_height: h,
                atlas_mib: mib(w as u64 * h as u64 * 4),
                table_mib: mib(n as u64 * tile as u64 * tile as u64 * 4),
                ms_per_frame: None,
                note: String::new(),
            };
            if w > max_dim.min(8192) || h > max_dim.min(8192) {
                row.note = format!("atlas wider than {} texels", max_dim.min(8192));
                report(&row);
                rows.push(row);
                continue;
            }
            set(&mut graph, "median_cut", "count", ParamValue::Int(n as i64))?;
            set(&mut graph, "shadow_atlas", "tile_size", ParamValue::Int(tile as i64))?;
            step(&mut ev, &mut graph)?;
            let mut samples = Vec::new();
            for _ in 0..frames.max(1) {
                let t = Instant::now();
                step(&mut ev, &mut graph)?;
                samples.push(t.elapsed().as_secs_f64() * 1e3);
            }
            samples.sort_by(f64::total_cmp);
            row.ms_per_frame = Some(samples[samples.len() / 2]);
            if let Some(crate::core::port::Value::Scalar(m)) = ev.output("shadow_atlas", "memory_mb") {
                row.atlas_mib = *m;
            }
            report(&row);
            rows.push(row);
        }
    }
    Ok(rows)
}

/// One row of `werkstatt bench cuboids` (the dissertation's table in section 5.1.1).
#[derive(Debug, serde::Serialize)]
pub struct CuboidRow {
    pub scene: &'static str,
    pub objects: usize,
    pub triangles: usize,
    /// The draw calls of the last frame, a linear one (objects that share a mesh draw
    /// instanced; the trilinear frames of these scenes draw as many).
    pub draws: usize,
    /// Frames per second with linear (affine, fast path) and trilinear transforms: each
    /// frame composes the transforms on the CPU, draws the G-buffer and waits for it.
    pub fps_linear: f64,
    pub fps_trilinear: f64,
    /// The trilinear frame rate over the linear one: the median over rounds of blocks
    /// A B B A of each round's ratio of median frame times.
    pub ratio: f64,
}

/// The dissertation's cuboid measurements (section 5.1.1) on this machine: `spheres` spheres
/// of about `sphere_triangles` triangles each on an animated object (one transform for all,
/// composed per frame: an animated rotation, or an animated bend grid), and helices of small
/// objects, each with its own transform composed on the CPU every frame (an affine frame along
/// the helix, or a cuboid sampled from the helix's curve, so each one is trilinear).
pub fn cuboids(
    gpu: &crate::gpu::GpuContext,
    spheres: (usize, usize),
    helices: &[(usize, usize)],
    frames: usize,
    rounds: usize,
    size: (u32, u32),
    mut report: impl FnMut(&CuboidRow),
) -> anyhow::Result<Vec<CuboidRow>> {
    use crate::cuboid::{CuboidGrid, NormalMethod, Transform, bend, compose};
    use crate::render::draw::{SceneDrawer, render_gbuffer};
    use crate::render::scene::{Camera, DrawItem, Material};
    use glam::{DMat4, DVec3, Mat4, Vec3};
    use std::sync::Arc;

    /// A UV sphere of about `triangles` triangles.
    fn ball(triangles: usize) -> anyhow::Result<Arc<crate::mesh::Mesh>> {
        let v = ((triangles as f64 / 4.0).sqrt().round() as u32).max(2);
        Ok(Arc::new(crate::nodes::mesh::geometry::sphere(1.0, 2 * v, v)?))
    }
    let material = Arc::new(Material::default());
    let camera = Camera {
        eye: Vec3::new(0.0, 3.0, 9.0),
        target: Vec3::ZERO,
        up: Vec3::Y,
        fov_y_degrees: 45.0,
        near: 0.1,
        far: 50.0,
    };
    let mut drawer = SceneDrawer::default();
    // Frames per second of each path (median frame times) and their ratio (trilinear / linear
    // rate), from blocks of frames of one path each. Each frame composes, draws and waits.
    let mut compare = |make: &dyn Fn(bool, usize) -> Vec<DrawItem>| -> anyhow::Result<(f64, f64, f64, usize)> {
        let (linear, trilinear, ratio) = abba_blocks(frames, rounds, |trilinear, i| {
            let t = Instant::now();
            let items = make(!trilinear, i);
            let g = render_gbuffer(gpu, &mut drawer, &items, camera, size.0, size.1)?;
            gpu.submit_checked()?;
            gpu.wait_idle();
            drop(g);
            Ok(t.elapsed().as_secs_f64())
        })?;
        Ok((1.0 / linear, 1.0 / trilinear, 1.0 / ratio, drawer.draw_count()))
    };
    let mut rows = Vec::new();
    let mut push = |row: CuboidRow| {
        report(&row);
        rows.push(row);
    };

    // Spheres on an animated object: a 6 x 6 (x 6, cut to the count) block in a box.
    let (count, tris) = spheres;
    let mesh = ball(tris)?;
    let (lo, hi) = (DVec3::new(-3.0, -1.0, -1.0), DVec3::new(3.0, 1.0, 1.0));
    let placed: Vec<DrawItem> = (0..count)
        .map(|i| {
            let (x, y, z) = (i % 8, (i / 8) % 4, i / 32);
            let p = Vec3::new(-2.8 + 0.8 * x as f32, -0.8 + 0.5 * y as f32, -0.8 + 0.3 * (z % 6) as f32);
            DrawItem::plain(
                mesh.clone(),
                material.clone(),
                Mat4::from_scale_rotation_translation(Vec3::splat(0.18), Default::default(), p),
            )
        })
        .collect();
    // A bend grid of 8 cells holds each sphere inside one cell (each then draws as its cell's
    // single cuboid); one of 24 cells, narrower than a sphere, makes every sphere cross cells
    // (the vertex stage looks up each vertex's cell).
    for (scene, cells) in [("spheres", 8), ("spheres across cells", 24)] {
        let animate = |linear: bool, i: usize| -> Vec<DrawItem> {
            let angle = 40.0 + 10.0 * (i as f64 * 0.3).sin();
            let t = if linear {
                Transform::Affine(DMat4::from_rotation_z(angle.to_radians() * 0.2))
            } else {
                let f = bend(lo, hi, angle);
                Transform::from_grid(
                    CuboidGrid::from_fn(lo, hi, [cells, 1, 1], NormalMethod::TangentSpace, |u| f(lo + u * (hi - lo)))
                        .expect("a valid box"),
                )
            };
            placed
                .iter()
                .map(|item| {
                    let (model, cuboid) = compose(item.model, None, &t);
                    DrawItem { model, cuboid, ..item.clone() }
                })
                .collect()
        };
        let triangles = count * mesh.indices.len() / 3;
        let (fps_linear, fps_trilinear, ratio, draws) = compare(&animate)?;
        push(CuboidRow { scene, objects: count, triangles, draws, fps_linear, fps_trilinear, ratio });
    }

    // Helices: object k sits at parameter s_k; its transform is the helix's frame there
    // (linear) or the cuboid whose corners follow the helix over the object's extent.
    for &(count, tris) in helices {
        let mesh = ball(tris)?;
        let base = DrawItem::plain(mesh.clone(), material.clone(), Mat4::IDENTITY);
        let turns = 6.0;
        let helix = |s: f64, phase: f64| {
            let a = s * turns * std::f64::consts::TAU + phase;
            DVec3::new(2.5 * a.cos(), -2.5 + 5.0 * s, 2.5 * a.sin())
        };
        let r = 0.7 * 5.0 / count as f64 * turns.max(1.0);
        let make = |linear: bool, i: usize| -> Vec<DrawItem> {
            let phase = 0.05 * i as f64;
            (0..count)
                .map(|k| {
                    let s = (k as f64 + 0.5) / count as f64;
                    let ds = 1.0 / count as f64;
                    // The object's box -1..1 spans the helix from s - ds/2 to s + ds/2 (x), and
                    // r across it (y radial, z along the tangent's normal).
                    let frame_at = |u: f64| {
                        let c = helix(s + (u - 0.5) * ds, phase);
                        let radial = DVec3::new(c.x, 0.0, c.z).normalize();
                        (c, radial)
                    };
                    let corner = |u: DVec3| {
                        let (c, radial) = frame_at(u.x);
                        c + radial * (u.y - 0.5) * 2.0 * r + DVec3::Y * (u.z - 0.5) * 2.0 * r
                    };
                    let grid =
                        CuboidGrid::from_fn(-DVec3::ONE, DVec3::ONE, [1, 1, 1], NormalMethod::TangentSpace, corner)
                            .expect("a valid box");
                    let t = if linear {
                        // The parallelepiped of the cuboid's right half: the helix's frame at s.
                        let c = grid.cell(0, 0, 0).coefficients();
                        let unit = DMat4::from_translation(DVec3::splat(0.5)) * DMat4::from_scale(DVec3::splat(0.5));
                        Transform::Affine(c.affine_part() * unit)
                    } else {
                        Transform::from_grid(grid)
                    };
                    let (model, cuboid) = compose(Mat4::IDENTITY, None, &t);
                    DrawItem { model, cuboid, ..base.clone() }
                })
                .collect()
        };
        let triangles = count * mesh.indices.len() / 3;
        let (fps_linear, fps_trilinear, ratio, draws) = compare(&make)?;
        push(CuboidRow { scene: "helix", objects: count, triangles, draws, fps_linear, fps_trilinear, ratio });
    }
    Ok(rows)
}

/// One figure of the paper's Table 1 (Fig. 1 a-e at the paper's triangle counts).
pub struct Table1Figure {
    pub graph: &'static str,
    pub types: &'static str,
    pub paper_triangles: usize,
    pub paper_ms: &'static str,
    /// The parameters scaled to reach the count: (node, parameter, exponent). Each is scaled
    /// by (target / reached)^(1 / exponent): a count 1, a spacing -1, a tile size -2; knobs of
    /// separate parts (buttons and seams) each with their own exponent, two knobs of one
    /// product (a grid's segments along u and v) 2 each.
    pub knobs: &'static [(&'static str, &'static str, f64)],
}

/// Table 1 of the paper: the Fig. 1 graphs and how each reaches the paper's triangle count.
pub const TABLE1: [Table1Figure; 5] = [
    Table1Figure {
        graph: "fig1a_fur",
        types: "points",
        paper_triangles: 25_000_000,
        paper_ms: "~37",
        knobs: &[("scatter", "count", 1.0)],
    },
    Table1Figure {
        graph: "fig1b_embroidery",
        types: "curves",
        paper_triangles: 10_000_000,
        paper_ms: "~20",
        knobs: &[("stitches", "spacing", -1.0)],
    },
    Table1Figure {
        graph: "fig1c_buttons_seam",
        types: "curves and points",
        paper_triangles: 6_000_000,
        paper_ms: "~13",
        knobs: &[("seam", "spacing", -1.0), ("button_row", "spacing", -1.0)],
    },
    Table1Figure {
        graph: "fig1d_knitwear",
        types: "area",
        paper_triangles: 48_000_000,
        paper_ms: "~56",
        knobs: &[("knit", "tile_size", -2.0)],
    },
    Table1Figure {
        graph: "fig1e_stickers",
        types: "area",
        paper_triangles: 650_000,
        paper_ms: "< 6",
        knobs: &[("tile", "segments_u", 2.0), ("tile", "segments_v", 2.0)],
    },
];

/// One row of `werkstatt bench table1`.
#[derive(Debug, serde::Serialize)]
pub struct Table1Row {
    pub figure: &'static str,
    pub types: &'static str,
    pub paper_triangles: usize,
    pub paper_ms: &'static str,
    /// Attached triangles reached (the attachment nodes' counts).
    pub triangles: u64,
    /// The parameters as set: "node.param=value".
    pub settings: Vec<String>,
    /// Median per frame: the matrix texture pass.
    pub matrix_ms: f64,
    /// Median per frame: the G-buffer pass over the whole scene (attachments warped in it).
    pub gbuffer_ms: f64,
    pub ms_per_frame: f64,
}

/// The attached triangles of an evaluated graph: the sum of its attachment nodes' counts.
fn attached_triangles(ev: &Evaluator, graph: &Graph) -> u64 {
    graph
        .nodes
        .iter()
        .filter(|(_, n)| n.kind.ends_with("Attachment"))
        .filter_map(|(id, _)| ev.report(id))
        .flat_map(|r| r.counts.iter().filter(|c| c.0 == "triangles").map(|c| c.1))
        .sum()
}

/// The paper's Table 1: each Fig. 1 graph (those named in `only`, or all) with its knobs scaled (up to six evaluations) until
/// its attachments have the paper's triangle count (within 5%, or `scale` times it), then the
/// median over `frames` of the matrix texture pass and the G-buffer pass of its scene.
pub fn table1(
    gpu: &crate::gpu::GpuContext,
    frames: usize,
    size: (u32, u32),
    scale: f64,
    only: &[String],
    mut report: impl FnMut(&Table1Row),
) -> anyhow::Result<Vec<Table1Row>> {
    use crate::core::port::Value;
    use crate::nodes::warp::matrix_texture::MatrixTextureNode;
    use crate::render::draw::{SceneDrawer, render_gbuffer};

    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("graphs");
    let resources = Resources::new(false);
    let settings = FrameSettings { width: size.0, height: size.1, base_dir: dir.clone(), frames: None };
    let mut rows = Vec::new();
    for fig in TABLE1.iter().filter(|f| only.is_empty() || only.iter().any(|o| f.graph.starts_with(o.as_str()))) {
        let what = format!("{}.ron", fig.graph);
        let mut graph = Graph::load(&dir.join(&what)).map_err(|e| anyhow::anyhow!("{e}"))?;
        let mut ev = Evaluator::new(&graph, &[])?;
        settle_frame(&mut ev, gpu, &resources, &settings, 0, &what)?;
        let target = fig.paper_triangles as f64 * scale;
        for _ in 0..6 {
            let have = attached_triangles(&ev, &graph) as f64;
            anyhow::ensure!(have > 0.0, "{what}: no attached triangles");
            if (have / target - 1.0).abs() < 0.05 {
                break;
            }
            for &(node, param, exponent) in fig.knobs {
                // Within the parameter's range: a knob at its limit leaves the rest to the others.
                let kind = graph.nodes.get(node).map(|n| n.kind.clone()).unwrap_or_default();
                let range = crate::core::spec::find(&kind).and_then(|s| s.param(param)).map(|(_, p)| p.kind);
                let p = graph
                    .nodes
                    .get_mut(node)
                    .ok_or_else(|| anyhow::anyhow!("{what} has no node {node}"))?
                    .params
                    .get_mut(param)
                    .ok_or_else(|| anyhow::anyhow!("{what}: {node} does not set {param}"))?;
                let f = (target / have).powf(1.0 / exponent);
                *p = match (&*p, range) {
                    (ParamValue::Int(v), Some(crate::core::param::ParamKind::Int { min, max, .. })) => {
                        ParamValue::Int((((*v as f64) * f).round() as i64).clamp(min, max))
                    }
                    (ParamValue::Float(v), Some(crate::core::param::ParamKind::Float { min, max, .. })) => {
                        ParamValue::Float((*v * f).clamp(min, max))
                    }
                    (ParamValue::Int(v), _) => ParamValue::Int(((*v as f64) * f).round().max(1.0) as i64),
                    (ParamValue::Float(v), _) => ParamValue::Float(*v * f),
                    (other, _) => anyhow::bail!("{what}: {node}.{param} is {other:?}, not a number"),
                };
            }
            ev.update(&graph, &[])?;
            settle_frame(&mut ev, gpu, &resources, &settings, 0, &what)?;
        }
        let triangles = attached_triangles(&ev, &graph);
        let knob_settings = fig
            .knobs
            .iter()
            .map(|&(node, param, _)| match &graph.nodes[node].params[param] {
                ParamValue::Int(v) => format!("{node}.{param}={v}"),
                ParamValue::Float(v) => format!("{node}.{param}={v:.5}"),
                other => format!("{node}.{param}={other:?}"),
            })
            .collect();
        // The scene the G-buffer pass draws, its camera and the surface of the matrix texture.
        let link_into = |to: &str, port: &str| {
            graph.links.iter().find(|l| l.to.node == to && l.to.port == port).map(|l| l.from.clone())
        };
        let scene = link_into("gbuffer", "scene")
            .and_then(|f| match ev.output(&f.node, &f.port) {
                Some(Value::Scene(s)) => Some(s.clone()),
                _ => None,
            })
            .ok_or_else(|| anyhow::anyhow!("{what}: no scene into gbuffer"))?;
        let camera = link_into("gbuffer", "camera")
            .and_then(|f| match ev.output(&f.node, &f.port) {
                Some(Value::Camera(c)) => Some(*c),
                _ => None,
            })
            .ok_or_else(|| anyhow::anyhow!("{what}: no camera into gbuffer"))?;
        let surface = link_into("matrix", "surface")
            .and_then(|f| match ev.output(&f.node, &f.port) {
                Some(Value::Surface(s)) => Some(s.clone()),
                _ => None,
            })
            .ok_or_else(|| anyhow::anyhow!("{what}: no surface into matrix"))?;
        let resolution = match graph.nodes["matrix"].params.get("resolution") {
            Some(ParamValue::Int(r)) => *r as u32,
            _ => 512,
        };
        let mut matrix_node = MatrixTextureNode::default();
        let mut drawer = SceneDrawer::default();
        let matrix_ms = median_ms(frames, &mut || {
            matrix_node.render(gpu, &surface, resolution, wgpu::TextureFormat::Rgba32Float, 0, None)?;
            gpu.submit_checked()?;
            gpu.wait_idle();
            Ok(())
        })?;
        let gbuffer_ms = median_ms(frames, &mut || {
            render_gbuffer(gpu, &mut drawer, &scene, camera, size.0, size.1)?;
            gpu.submit_checked()?;
            gpu.wait_idle();
            Ok(())
        })?;
        let row = Table1Row {
            figure: fig.graph,
            types: fig.types,
            paper_triangles: fig.paper_triangles,
            paper_ms: fig.paper_ms,
            triangles,
            settings: knob_settings,
            matrix_ms,
            gbuffer_ms,
            ms_per_frame: matrix_ms + gbuffer_ms,
        };
        report(&row);
        rows.push(row);
    }
    Ok(rows)
}

/// One row of `werkstatt bench export`.
#[derive(Debug, serde::Serialize)]
pub struct ExportRow {
    pub buttons: usize,
    pub triangles: usize,
    /// GPU path: the compute warp and read-back into the output layout.
    pub gpu_warp_ms: f64,
    /// GPU path: warp, then the mesh assembled (outliers dropped): the geometry in memory.
    pub gpu_produce_ms: f64,
    /// CPU path: the matrix texture read back and the threaded twin's warp.
    pub cpu_warp_ms: f64,
    /// CPU path: warp, then the same assembly.
    pub cpu_produce_ms: f64,
    /// The path `ExportGeometry`'s `warp: auto` takes on this adapter ("gpu" or "cpu").
    pub auto: &'static str,
    /// Writing binary PLY to `out`.
    pub write_ms: f64,
    pub megabytes: f64,
}

/// The export path of Fig. 10's data: `counts` point-attached 928-triangle buttons on a grid
/// over the tablecloth sequence (tests/data/sequence), produced as one mesh (GPU and CPU twin)
/// and written as binary PLY into `out`, each timed apart (median of `frames`). The graph's
/// ExportGeometry (at a frame never reached) only pulls the scene.
pub fn export(
    gpu: &crate::gpu::GpuContext,
    counts: &[usize],
    frames: usize,
    out: &std::path::Path,
    mut report: impl FnMut(&ExportRow),
) -> anyhow::Result<Vec<ExportRow>> {
    use crate::core::port::Value;
    use crate::warp::gpu::{GpuWarper, WarpDevice, assemble};

    let dir = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data");
    let resources = Resources::new(false);
    let settings = FrameSettings { width: 64, height: 64, base_dir: dir, frames: None };
    std::fs::create_dir_all(out)?;
    let mut rows = Vec::new();
    for &count in counts {
        let side = (count as f64).sqrt().round().max(1.0) as usize;
        let cols = count.div_ceil(side);
        let text = format!(
            r#"(version: 1, nodes: {{
                "cloth": (kind: "MeshSequence", params: {{"path": "sequence"}}),
                "matrix": (kind: "MatrixTexture", params: {{"resolution": 512}}),
                "grid": (kind: "GridPlacement", params: {{"columns": {cols}, "rows": {side}}}),
                "button": (kind: "Primitive", params: {{"shape": "disc", "radius": 0.5, "height": 0.2, "segments_u": 232}}),
                "buttons": (kind: "PointAttachment", params: {{"scale": {scale}}}),
                "out": (kind: "ExportGeometry", params: {{"frame": 1000000}}),
            }}, links: [("cloth.surface", "matrix.surface"), ("cloth.surface", "grid.surface"),
                ("matrix.matrix", "buttons.matrix"), ("button.mesh", "buttons.mesh"),
                ("grid.placements", "buttons.placements"), ("buttons.scene", "out.scene")])"#,
            scale = 0.8 / cols as f32,
        );
        let graph = Graph::load_str(&text, "export.ron".as_ref()).map_err(|e| anyhow::anyhow!("{e}"))?;
        let mut ev = Evaluator::new(&graph, &[])?;
        settle_frame(&mut ev, gpu, &resources, &settings, 0, "the export scene")?;
        let Some(Value::Scene(items)) = ev.output("buttons", "scene") else {
            anyhow::bail!("the export scene has no attachments");
        };
        let item = &items[0];
        let draw = item
            .kind_as::<crate::warp::AttachedDraw>()
            .ok_or_else(|| anyhow::anyhow!("the export scene's item is not an attachment"))?;
        let mut warper = GpuWarper::default();
        let mut time = |device: WarpDevice| -> anyhow::Result<(f64, f64, crate::mesh::Mesh)> {
            let warp_ms = median_ms(frames, &mut || warper.warp_layout_on(gpu, &item.mesh, draw, device).map(drop))?;
            let mut mesh = None;
            let produce_ms = median_ms(frames, &mut || {
                mesh = Some(assemble(&item.mesh, warper.warp_layout_on(gpu, &item.mesh, draw, device)?)?);
                Ok(())
            })?;
            Ok((warp_ms, produce_ms, mesh.expect("assembled above")))
        };
        let (gpu_warp_ms, gpu_produce_ms, mesh) = time(WarpDevice::Gpu)?;
        let (cpu_warp_ms, cpu_produce_ms, cpu_mesh) = time(WarpDevice::Cpu)?;
        anyhow::ensure!(
            mesh.indices == cpu_mesh.indices,
            "the GPU and the CPU twin keep different triangles ({} and {})",
            mesh.triangle_count(),
            cpu_mesh.triangle_count()
        );
        let worst = mesh.positions.iter().zip(&cpu_mesh.positions).map(|(a, b)| a.distance(*b)).fold(0.0, f32::max);
        anyhow::ensure!(worst < 1e-4, "the GPU and the CPU twin place a vertex {worst} apart");
        let path = out.join(format!("export_{count}.ply"));
        let write_ms = median_ms(frames, &mut || crate::io::geometry::write_ply(&path, &mesh))?;
        let megabytes = std::fs::metadata(&path).map(|m| m.len() as f64 / 1e6).unwrap_or(0.0);
        let _ = std::fs::remove_file(&path);
        let row = ExportRow {
            buttons: draw.instances.len(),
            triangles: mesh.triangle_count(),
            gpu_warp_ms,
            gpu_produce_ms,
            cpu_warp_ms,
            cpu_produce_ms,
            auto: crate::core::param::Choice::name(WarpDevice::Auto.resolve(gpu)),
            write_ms,
            megabytes,
        };
        report(&row);
        rows.push(row);
    }
    Ok(rows)
}

#[cfg(test)]
mod tests {
    use super::{DrapeReport, GarmentDrapeReport, median, placement_summary};

    #[test]
    fn the_placement_summary_gives_each_edge_lengths_mean_and_range() {
        let row = |edge_cm: f64, frame_ms: f64, crossings: usize, strain: f32| GarmentDrapeReport {
            edge_cm,
            drape: DrapeReport {
                frame_ms,
                max_self_crossings: crossings,
                min_clearance_mm: 2.4,
                max_p99_strain_percent: strain,
                ..Default::default()
            },
            ..Default::default()
        };
        let rows = [row(1.0, 100.0, 3, 7.0), row(0.5, 900.0, 0, 3.0), row(1.0, 140.0, 22, 8.0)];
        let lines: Vec<String> = placement_summary(&rows).lines().map(str::to_string).collect();
        assert_eq!(lines.len(), 2, "{lines:?}");
        assert!(lines[0].starts_with("0.5 cm over 1 placements"), "{}", lines[0]);
        assert!(lines[1].starts_with("1 cm over 2 placements"), "{}", lines[1]);
        for part in
            ["ms/frame 120.0 (100.0-140.0)", "self crossings walk max 12.5 (3.0-22.0)", "p99 strain % 7.5 (7.0-8.0)"]
        {
            assert!(lines[1].contains(part), "{part} in {}", lines[1]);
        }
    }

    #[test]
    fn the_median_of_an_even_count_is_the_mean_of_the_middle_two() {
        assert_eq!(median(vec![3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(vec![4.0, 1.0, 3.0, 2.0]), 2.5);
        assert_eq!(median(vec![7.0]), 7.0);
    }
}

/// `werkstatt bench drape`: a skirt of `triangles` triangles (about half as
/// many particles) with self-collision on a body mesh (the skirt preset's
/// capsules as triangle meshes); the body stands still while the skirt
/// settles, then walks (legs swing ±`swing_deg` at 1 Hz, the torso sways).
#[derive(Debug, Default, serde::Serialize)]
pub struct DrapeReport {
    pub particles: usize,
    pub triangles: usize,
    pub body_triangles: usize,
    /// Frames until at most 1.5 % of the particles move more than 0.3 mm in
    /// a frame (GarmentCode's criterion), or `settle_frames` when never.
    pub settled_after_frames: usize,
    pub settle_ms: f64,
    /// Mean over the walking frames (ms per 1/60 s frame).
    pub frame_ms: f64,
    pub detection_ms: f64,
    pub constraints_ms: f64,
    pub self_collision_ms: f64,
    pub body_collision_ms: f64,
    /// Worst over the walking frames (checked every `check_every` frames).
    pub max_body_crossings: usize,
    pub max_self_crossings: usize,
    /// Checked walking frames with any cloth edge through a cloth triangle.
    pub self_crossing_frames: usize,
    pub min_clearance_mm: f32,
    /// Worst 99th-percentile edge strain (%) over the checked frames.
    pub max_p99_strain_percent: f32,
    pub max_speed: f32,
}

/// The walking body of `werkstatt bench drape` at time `t` (seconds):
/// capsules `(a, b, radius)` of the skirt preset's body, legs swinging.
pub fn drape_body_pose(t: f32, swing_deg: f32) -> Vec<(glam::Vec3, glam::Vec3, f32)> {
    use crate::cloth::Collider;
    let phase = std::f32::consts::TAU * t;
    let swing = swing_deg.to_radians() * phase.sin();
    let sway = glam::Quat::from_rotation_y(0.1 * phase.sin());
    crate::cloth::presets::capsule_body()
        .iter()
        .enumerate()
        .map(|(k, c)| {
            let Collider::Capsule { a, b, radius } = c else { unreachable!("the body is capsules") };
            let (a, b) = match k {
                // Legs: rotate about the hip joint (their top end) about x.
                3 | 4 => {
                    let q = glam::Quat::from_rotation_x(if k == 3 { swing } else { -swing });
                    (*a, *a + q * (*b - *a))
                }
                _ => (*a, *b),
            };
            (sway * a, sway * b, *radius)
        })
        .collect()
}

/// The body mesh of [`drape_body_pose`]: all capsules in one mesh.
pub fn drape_body_mesh(t: f32, swing_deg: f32) -> (Vec<glam::Vec3>, Vec<[u32; 3]>) {
    let mut pos = Vec::new();
    let mut tris = Vec::new();
    for (a, b, r) in drape_body_pose(t, swing_deg) {
        let rings = ((a.distance(b) / 0.015).ceil() as u32).max(2);
        let (p, t) = crate::cloth::body_collision::capsule_mesh(a, b, r, rings, 40);
        let base = pos.len() as u32;
        pos.extend(p);
        tris.extend(t.iter().map(|t| t.map(|i| i + base)));
    }
    (pos, tris)
}

pub fn drape(
    triangles: usize,
    settle_frames: usize,
    walk_frames: usize,
    swing_deg: f32,
    check_every: usize,
    obj_dir: Option<&std::path::Path>,
) -> anyhow::Result<DrapeReport> {
    use crate::cloth::{BodyMesh, FRAME_DT, Preset, SkirtParams};
    let mut cloth = Preset::Skirt(SkirtParams { triangles, seed: 1, panels: 4 }).build();
    cloth.colliders_mut().clear();
    cloth.set_self_collision(true);
    let (pos, tris) = drape_body_mesh(0.0, swing_deg);
    let mut r = DrapeReport {
        particles: cloth.vertex_count(),
        triangles: cloth.triangle_count(),
        body_triangles: tris.len(),
        min_clearance_mm: f32::INFINITY,
        ..Default::default()
    };
    cloth.set_body(Some(BodyMesh::new(pos.clone(), tris.clone())));
    let cloth_tris = cloth.pattern().triangles().to_vec();
    if let Some(dir) = obj_dir {
        std::fs::create_dir_all(dir)?;
        write_obj(dir, "cloth_start.obj", cloth.positions(), &cloth_tris, &[])?;
        write_obj(dir, "body_0000.obj", &pos, &tris, &[])?;
    }
    let t0 = Instant::now();
    r.settled_after_frames = settle(&mut cloth, settle_frames, 10, |c| c.step_frame(FRAME_DT), |c| c.positions());
    r.settle_ms = t0.elapsed().as_secs_f64() * 1e3;
    if let Some(dir) = obj_dir {
        write_obj(dir, "cloth_settled.obj", cloth.positions(), &cloth_tris, &[])?;
    }
    for f in 0..walk_frames {
        let t = (f + 1) as f32 * FRAME_DT;
        let (pose, _) = drape_body_mesh(t, swing_deg);
        if let Some(dir) = obj_dir {
            write_obj(dir, &format!("body_{:04}.obj", f + 1), &pose, &tris, &[])?;
        }
        cloth.body_mut().expect("set above").move_to(&pose);
        let t0 = Instant::now();
        cloth.step_frame(FRAME_DT);
        let check = check_every > 0 && ((f + 1) % check_every == 0 || f + 1 == walk_frames);
        r.record_frame(&cloth, t0.elapsed().as_secs_f64() * 1e3, check);
    }
    if let Some(dir) = obj_dir {
        write_obj(dir, "cloth_walked.obj", cloth.positions(), &cloth_tris, &[])?;
    }
    r.finish(walk_frames);
    Ok(r)
}

impl DrapeReport {
    /// Adds a timed frame of `cloth`; `check` also counts crossings and clearance.
    fn record_frame(&mut self, cloth: &crate::cloth::Cloth, ms: f64, check: bool) {
        let s = cloth.timings();
        self.frame_ms += ms;
        self.detection_ms += s.detection_ms;
        self.constraints_ms += s.constraints_ms;
        self.self_collision_ms += s.self_collision_ms;
        self.body_collision_ms += s.body_collision_ms;
        self.max_speed = self.max_speed.max(cloth.max_speed());
        if check {
            self.max_body_crossings = self.max_body_crossings.max(cloth.body_crossings());
            let crossings = cloth.self_crossings();
            self.max_self_crossings = self.max_self_crossings.max(crossings);
            self.self_crossing_frames += usize::from(crossings > 0);
            if let Some(c) = cloth.body_clearance(0.05) {
                self.min_clearance_mm = self.min_clearance_mm.min(c * 1e3);
            }
            self.max_p99_strain_percent = self.max_p99_strain_percent.max(100.0 * cloth.strain_percentile(0.99));
        }
    }

    /// Turns the sums of [`DrapeReport::record_frame`] into means over `frames`.
    fn finish(&mut self, frames: usize) {
        let n = frames.max(1) as f64;
        for v in [
            &mut self.frame_ms,
            &mut self.detection_ms,
            &mut self.constraints_ms,
            &mut self.self_collision_ms,
            &mut self.body_collision_ms,
        ] {
            *v /= n;
        }
    }
}

/// Steps `state` until at most 1.5 % of the particles move more than 0.3 mm in a frame
/// (GarmentCode's criterion), not before `min_frames`; the frames taken, or `max_frames`.
fn settle<S>(
    state: &mut S,
    max_frames: usize,
    min_frames: usize,
    step: impl Fn(&mut S),
    positions: impl Fn(&S) -> &[glam::Vec3],
) -> usize {
    for f in 0..max_frames {
        let before = positions(state).to_vec();
        step(state);
        let moving = before.iter().zip(positions(state)).filter(|(a, b)| a.distance(**b) > 3e-4).count();
        if f >= min_frames && moving as f64 <= 0.015 * before.len() as f64 {
            return f + 1;
        }
    }
    max_frames
}

/// A bench row as one line of a markdown table: the `werkstatt bench` commands print these, and
/// `werkstatt bench all` writes them into its summary, so both show the same columns.
pub trait MarkdownRow {
    /// The header line and the alignment line.
    const HEADER: &'static str;
    fn markdown(&self) -> String;
}

/// `rows` as a markdown table.
pub fn markdown_table<R: MarkdownRow>(rows: &[R]) -> String {
    let mut s = format!("{}\n", R::HEADER);
    for r in rows {
        s.push_str(&r.markdown());
        s.push('\n');
    }
    s
}

impl MarkdownRow for AttachRow {
    const HEADER: &'static str = "| path | instances | triangles | ms/frame | MTri/s |\n|---|---:|---:|---:|---:|";
    fn markdown(&self) -> String {
        format!(
            "| {} | {} | {} | {:.2} | {:.2} |",
            self.path, self.instances, self.triangles, self.ms_per_frame, self.mtri_per_s
        )
    }
}

impl MarkdownRow for ExportRow {
    const HEADER: &'static str = "| buttons | triangles | GPU warp + read-back ms | GPU produce ms | CPU warp ms | CPU produce ms | auto | PLY write ms | MB |\n|---:|---:|---:|---:|---:|---:|---|---:|---:|";
    fn markdown(&self) -> String {
        format!(
            "| {} | {} | {:.1} | {:.1} | {:.1} | {:.1} | {} | {:.1} | {:.1} |",
            self.buttons,
            self.triangles,
            self.gpu_warp_ms,
            self.gpu_produce_ms,
            self.cpu_warp_ms,
            self.cpu_produce_ms,
            self.auto,
            self.write_ms,
            self.megabytes
        )
    }
}

impl MarkdownRow for Table1Row {
    const HEADER: &'static str = "| figure | types | paper triangles | paper ms (GTX 580) | triangles | matrix ms | G-buffer ms | ms/frame | settings |\n|---|---|---:|---:|---:|---:|---:|---:|---|";
    fn markdown(&self) -> String {
        format!(
            "| {} | {} | {} | {} | {} | {:.2} | {:.2} | {:.2} | {} |",
            self.figure,
            self.types,
            self.paper_triangles,
            self.paper_ms,
            self.triangles,
            self.matrix_ms,
            self.gbuffer_ms,
            self.ms_per_frame,
            self.settings.join(" ")
        )
    }
}

impl MarkdownRow for IblRow {
    const HEADER: &'static str =
        "| regions | rebuild ms (cut + PEMs + frame) | ms/frame (G-buffer + IBL) | PEM MiB |\n|---:|---:|---:|---:|";
    fn markdown(&self) -> String {
        let n = if self.regions == 0 { "full map".to_string() } else { self.regions.to_string() };
        format!("| {n} | {:.1} | {:.2} | {:.1} |", self.rebuild_ms, self.frame_ms, self.pem_mib)
    }
}

impl MarkdownRow for TessellationRow {
    const HEADER: &'static str = "| levels | mode | level | triangles | compute ms | Mtri/s (compute) | frame ms |\n|---|---|---:|---:|---:|---:|---:|";
    fn markdown(&self) -> String {
        format!(
            "| {} | {} | {} | {} | {:.2} | {:.1} | {:.2} |",
            self.levels, self.mode, self.level, self.triangles, self.compute_ms, self.mtri_per_s, self.frame_ms
        )
    }
}

impl MarkdownRow for WarpCostRow {
    const HEADER: &'static str = "| level | pattern ms | pattern_warp ms | compute cost | frame ms | frame ms (warp) | frame-rate loss |\n|---:|---:|---:|---:|---:|---:|---:|";
    fn markdown(&self) -> String {
        format!(
            "| {} | {:.2} | {:.2} | {:+.1}% | {:.2} | {:.2} | {:+.1}% |",
            self.level,
            self.pattern_ms,
            self.pattern_warp_ms,
            100.0 * self.cost,
            self.frame_pattern_ms,
            self.frame_pattern_warp_ms,
            100.0 * self.frame_rate_loss
        )
    }
}

impl MarkdownRow for SsaoRow {
    const HEADER: &'static str = "| mode | resolution | ms/frame (Ssao passes) |\n|---|---|---:|";
    fn markdown(&self) -> String {
        let res = if self.half_resolution { "half" } else { "full" };
        format!("| {} | {res} | {:.2} |", self.mode, self.ms_per_frame)
    }
}

impl MarkdownRow for CuboidRow {
    const HEADER: &'static str = "| scene | objects | triangles | draws | FPS linear | FPS trilinear | ratio |\n|---|---:|---:|---:|---:|---:|---:|";
    fn markdown(&self) -> String {
        format!(
            "| {} | {} | {} | {} | {:.1} | {:.1} | {:.0}% |",
            self.scene,
            self.objects,
            self.triangles,
            self.draws,
            self.fps_linear,
            self.fps_trilinear,
            100.0 * self.ratio
        )
    }
}

impl MarkdownRow for ShadowRow {
    const HEADER: &'static str = "| lights | tile | atlas | atlas MiB | N x tile^2 x 4 B (Table 5.1) MiB | ms/frame |\n|---:|---:|---:|---:|---:|---:|";
    fn markdown(&self) -> String {
        let ms = self.ms_per_frame.map_or_else(|| format!("skipped ({})", self.note), |ms| format!("{ms:.1}"));
        format!(
            "| {} | {} | {}x{} | {:.1} | {:.1} | {ms} |",
            self.lights, self.tile, self.atlas_width, self.atlas_height, self.atlas_mib, self.table_mib
        )
    }
}

/// `werkstatt bench drape` on a sewn garment: a GarmentCode pattern sewn at `edge_cm`,
/// fitted to MakeHuman (the `Garment` node's default scale and offset, sleeves slid up the
/// arms), draped with self-collision (`substeps` per frame, `iterations` sweeps each) on the
/// avatar at rest until settled, then walked: half a
/// second from the rest pose to the walk's first frame, then `walk_frames` timed frames.
#[derive(Debug, Default, serde::Serialize)]
pub struct GarmentDrapeReport {
    pub edge_cm: f64,
    /// The placement's offset (cm).
    pub offset_cm: [f64; 3],
    pub substeps: u32,
    /// Settling and the timed walk, as for the skirt.
    #[serde(flatten)]
    pub drape: DrapeReport,
    /// At the end of the settling.
    pub settled_body_crossings: usize,
    pub settled_self_crossings: usize,
    /// Worst over the walk's checked frames.
    pub max_seam_gap_mm: f32,
}

/// Writes `positions` (and triangles, and `lines` as OBJ line elements) as OBJ into `dir`.
fn write_obj(
    dir: &std::path::Path,
    name: &str,
    positions: &[glam::Vec3],
    tris: &[[u32; 3]],
    lines: &[[u32; 2]],
) -> anyhow::Result<()> {
    use std::fmt::Write as _;
    let mut s = String::new();
    for v in positions {
        writeln!(s, "v {} {} {}", v.x, v.y, v.z)?;
    }
    for f in tris {
        writeln!(s, "f {} {} {}", f[0] + 1, f[1] + 1, f[2] + 1)?;
    }
    for l in lines {
        writeln!(s, "l {} {}", l[0] + 1, l[1] + 1)?;
    }
    Ok(crate::io::atomic::write_atomic(&dir.join(name), s.as_bytes())?)
}

/// How `werkstatt bench drape` simulates the garment (its command line's options).
pub struct DrapeSetup {
    /// Substeps per 1/60 s frame (`None`: as the `Garment` node takes them for the edge length).
    pub substeps: Option<u32>,
    pub iterations: u32,
    pub untangle: bool,
    pub struts: bool,
    /// The avatar's arms spread from its sides (degrees).
    pub arm_spread: f64,
    /// The placement's offset (cm), as the `Garment` node's `offset`.
    pub offset_cm: glam::DVec3,
}

#[allow(clippy::too_many_arguments)] // the command line's options
pub fn drape_garment(
    avatar_dir: &std::path::Path,
    pattern: &std::path::Path,
    edge_cm: f64,
    setup: &DrapeSetup,
    settle_frames: usize,
    walk_frames: usize,
    check_every: usize,
    obj_dir: Option<&std::path::Path>,
) -> anyhow::Result<GarmentDrapeReport> {
    use crate::avatar::walk::WalkingAvatar;
    use crate::cloth::FRAME_DT;
    use crate::garment::drape::{Drape, DrapeParams};
    use crate::garment::{Fit, garmentcode, sleeves::fit_sleeves};
    let substeps = setup.substeps.unwrap_or_else(|| DrapeParams::substeps_for(edge_cm, DrapeParams::SUBSTEPS_PER_CM));
    let mut avatar = WalkingAvatar::load(avatar_dir)?;
    avatar.arm_spread = setup.arm_spread.to_radians();
    let fit = Fit { offset: setup.offset_cm, ..Fit::ON_MAKEHUMAN };
    let mut sewn = garmentcode::load(pattern)?.sew(edge_cm, fit)?;
    fit_sleeves(&mut sewn, &crate::garment::sleeves::ArmAxis::of_avatar(&avatar)?);
    let body = avatar.rest_body();
    let rest = body.positions().to_vec();
    let body_tris = body.triangles().to_vec();
    let params = DrapeParams {
        sim: crate::cloth::SimParams {
            self_collision: true,
            untangle: setup.untangle,
            struts: setup.struts,
            substeps,
            iterations: setup.iterations,
            ..DrapeParams::default().sim
        },
        ..DrapeParams::default()
    };
    let mut drape = Drape::new(&sewn, &params, Some(body));
    let mut r = GarmentDrapeReport {
        edge_cm,
        offset_cm: setup.offset_cm.to_array(),
        substeps,
        drape: DrapeReport {
            particles: drape.cloth.vertex_count(),
            triangles: drape.cloth.triangle_count(),
            body_triangles: body_tris.len(),
            min_clearance_mm: f32::INFINITY,
            ..Default::default()
        },
        ..Default::default()
    };
    if let Some(dir) = obj_dir {
        std::fs::create_dir_all(dir)?;
        let tris = sewn.mesh.triangles();
        write_obj(dir, "garment_rest.obj", &sewn.positions, tris, drape.cloth.seam_pairs())?;
        write_obj(dir, "body_rest.obj", &rest, &body_tris, &[])?;
    }

    let t0 = Instant::now();
    let sewing = params.sewing_frames as usize;
    r.drape.settled_after_frames = settle(&mut drape, settle_frames, sewing, |d| d.step(None), |d| d.cloth.positions());
    r.drape.settle_ms = t0.elapsed().as_secs_f64() * 1e3;
    r.settled_body_crossings = drape.cloth.body_crossings();
    r.settled_self_crossings = drape.cloth.self_crossings();
    if let Some(dir) = obj_dir {
        write_obj(dir, "garment_settled.obj", drape.cloth.positions(), sewn.mesh.triangles(), &[])?;
    }

    // The body's poses: a blend from rest to the walk's first frame, then the walk.
    let blend = 30;
    let first = avatar.collision_vertices(&avatar.walk_pose(0.0));
    let poses: Vec<Vec<glam::Vec3>> = (0..blend + walk_frames)
        .map(|f| {
            if f < blend {
                let s = (f + 1) as f32 / blend as f32;
                rest.iter().zip(&first).map(|(a, b)| a.lerp(*b, s)).collect()
            } else {
                avatar.collision_vertices(&avatar.walk_pose((f - blend) as f64 * FRAME_DT as f64))
            }
        })
        .collect();
    if let Some(dir) = obj_dir {
        // Little-endian f32 triples, one block of body vertices per frame, for the peer.
        let bytes: Vec<u8> = poses.iter().flatten().flat_map(|v| v.to_array()).flat_map(f32::to_le_bytes).collect();
        crate::io::atomic::write_atomic(&dir.join("body_frames.f32"), &bytes)?;
    }
    for (f, pose) in poses.iter().enumerate() {
        let t0 = Instant::now();
        drape.step(Some(pose));
        if f < blend {
            continue;
        }
        let k = f - blend + 1;
        let check = check_every > 0 && (k % check_every == 0 || k == walk_frames);
        r.drape.record_frame(&drape.cloth, t0.elapsed().as_secs_f64() * 1e3, check);
        if check {
            r.max_seam_gap_mm = r.max_seam_gap_mm.max(drape.max_seam_gap() * 1e3);
        }
    }
    if let Some(dir) = obj_dir {
        write_obj(dir, "garment_walked.obj", drape.cloth.positions(), sewn.mesh.triangles(), &[])?;
    }
    r.drape.finish(walk_frames);
    Ok(r)
}

/// A line per edge length over the placements `rows` ran at: each figure's mean and range
/// (`werkstatt bench drape` with `--offset` more than once).
pub fn placement_summary(rows: &[GarmentDrapeReport]) -> String {
    let mut edges: Vec<f64> = rows.iter().map(|r| r.edge_cm).collect();
    edges.sort_by(f64::total_cmp);
    edges.dedup();
    let mut s = String::new();
    for edge in edges {
        let at: Vec<&GarmentDrapeReport> = rows.iter().filter(|r| r.edge_cm == edge).collect();
        let spread = |figure: &dyn Fn(&GarmentDrapeReport) -> f64, digits: usize| {
            let values: Vec<f64> = at.iter().map(|r| figure(r)).collect();
            let mean = values.iter().sum::<f64>() / values.len() as f64;
            let (lo, hi) =
                values.iter().fold((f64::INFINITY, f64::NEG_INFINITY), |(lo, hi), &v| (lo.min(v), hi.max(v)));
            format!("{mean:.digits$} ({lo:.digits$}-{hi:.digits$})")
        };
        s.push_str(&format!(
            "{edge} cm over {} placements, mean (range): ms/frame {}, self crossings walk max {}, walk frames with any {}, min clearance mm {}, p99 strain % {}\n",
            at.len(),
            spread(&|r| r.drape.frame_ms, 1),
            spread(&|r| r.drape.max_self_crossings as f64, 1),
            spread(&|r| r.drape.self_crossing_frames as f64, 1),
            spread(&|r| f64::from(r.drape.min_clearance_mm), 2),
            spread(&|r| f64::from(r.drape.max_p99_strain_percent), 1),
        ));
    }
    s
}

impl MarkdownRow for GarmentDrapeReport {
    const HEADER: &'static str = "| edge cm | offset cm | substeps | particles | settled (frames, ms) | ms/frame | detection | constraints | self | body | body crossings (settled / walk max) | self crossings (settled / walk max / walk frames with any) | min clearance mm | max gap mm | p99 strain % |\n|---:|---|---:|---:|---|---:|---:|---:|---:|---:|---|---|---:|---:|---:|";
    fn markdown(&self) -> String {
        let d = &self.drape;
        let [x, y, z] = self.offset_cm;
        format!(
            "| {} | {x},{y},{z} | {} | {} | {}, {:.0} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} | {} / {} | {} / {} / {} | {:.2} | {:.2} | {:.1} |",
            self.edge_cm,
            self.substeps,
            d.particles,
            d.settled_after_frames,
            d.settle_ms,
            d.frame_ms,
            d.detection_ms,
            d.constraints_ms,
            d.self_collision_ms,
            d.body_collision_ms,
            self.settled_body_crossings,
            d.max_body_crossings,
            self.settled_self_crossings,
            d.max_self_crossings,
            d.self_crossing_frames,
            d.min_clearance_mm,
            self.max_seam_gap_mm,
            d.max_p99_strain_percent
        )
    }
}

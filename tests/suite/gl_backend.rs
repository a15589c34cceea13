//! The second software backend: every graph in graphs/ renders on OpenGL ES through EGL
//! (Mesa's llvmpipe), with the formats the context picks for what that driver can render
//! (llvmpipe's GLES renders no 32-bit float targets), and the still life (graphs/still_life.ron) stays close to
//! its golden image there.
//!
//! Skipped, with a message, only where no EGL driver is installed at all
//! (`apt-get install libegl1 libegl-mesa0 libgles2`).

use std::net::TcpStream;
use std::time::{Duration, Instant};

use crate::common::*;
use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
use werkstatt::core::graph::Graph;
use werkstatt::core::param::ParamValue;
use werkstatt::core::resources::Resources;
use werkstatt::gpu::{Backend, GpuContext, Pixels, read_back};
use werkstatt::nodes::mesh::live_link::{encode_frame, encode_topology};

/// The GL context, or `None` (checks skipped) where the machine has no EGL library.
fn gl() -> Option<GpuContext> {
    match GpuContext::headless(Backend::Gl) {
        Ok(gpu) => {
            assert_eq!(gpu.info.backend, wgpu::Backend::Gl);
            crate::common::skip_driver_teardown_at_exit();
            Some(gpu)
        }
        Err(e) => {
            let egl = [
                "/usr/lib/x86_64-linux-gnu/libEGL.so.1",
                "/usr/lib/aarch64-linux-gnu/libEGL.so.1",
                "/usr/lib/libEGL.so.1",
            ]
            .iter()
            .any(|p| std::path::Path::new(p).exists());
            assert!(!egl, "EGL is installed, but no GL adapter opened: {e:#}");
            eprintln!("skipping: no EGL driver on this machine (apt-get install libegl1 libegl-mesa0 libgles2): {e:#}");
            None
        }
    }
}

/// A check on the GL context, by name.
type GlCheck = (&'static str, fn(&GpuContext));

/// Every GL check below, in one test on one context. llvmpipe's GL crashed (SIGSEGV inside
/// swrast_dri.so during a queue submit) with a second GL context working on another test thread;
/// as separate tests behind a lock, the checks kept a second test thread waiting for 24 s of the
/// suite's 103. Each check runs to its end whatever the others do; the failures are listed by
/// name (their messages are above them in the output).
#[test]
fn every_check_on_gl() {
    let Some(gpu) = gl() else { return };
    let checks: [GlCheck; 7] = [
        (
            "gl_formats_are_renderable_where_lavapipe_uses_r32float",
            gl_formats_are_renderable_where_lavapipe_uses_r32float,
        ),
        ("every_graph_renders_on_gl", every_graph_renders_on_gl),
        ("a_direct_light_graph_matches_vulkan_on_gl", a_direct_light_graph_matches_vulkan_on_gl),
        (
            "the_still_life_with_image_based_lighting_matches_vulkan_on_gl",
            the_still_life_with_image_based_lighting_matches_vulkan_on_gl,
        ),
        ("a_white_furnace_with_pems_stays_white_on_gl", a_white_furnace_with_pems_stays_white_on_gl),
        (
            "screen_space_reflections_of_a_uniform_probe_keep_the_image_on_gl",
            screen_space_reflections_of_a_uniform_probe_keep_the_image_on_gl,
        ),
        ("the_live_link_graph_renders_on_gl", render_livelink),
    ];
    let failed: Vec<&str> = checks
        .iter()
        .filter(|(name, check)| {
            let start = Instant::now();
            let passed = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| check(&gpu))).is_ok();
            eprintln!("{name}: {} in {:.1} s", if passed { "passed" } else { "FAILED" }, start.elapsed().as_secs_f64());
            !passed
        })
        .map(|(name, _)| *name)
        .collect();
    assert!(failed.is_empty(), "{} of {} GL checks failed: {failed:?}", failed.len(), checks.len());
}

fn render_on(
    gpu: &GpuContext,
    graph: &str,
    out: &std::path::Path,
    frames: (i64, i64),
    dumps: &[&str],
    sets: &[String],
) -> anyhow::Result<()> {
    let sets: Vec<&str> = sets.iter().map(String::as_str).collect();
    render_graph_on(gpu, &root().join("graphs").join(graph), out, frames, (96, 72), &sets, dumps).map(|_| ())
}

fn gl_formats_are_renderable_where_lavapipe_uses_r32float(gpu: &GpuContext) {
    let f = gpu.formats();
    // Whatever llvmpipe offers, every role has a format the device renders and samples.
    for format in [f.linear_depth, f.hdr, f.matrix_f16, f.ldr] {
        let desc = werkstatt::gpu::TextureDesc::target(4, 4, format);
        let img = gpu.acquire("probe", desc);
        gpu.checked("probe", || {
            gpu.record(|enc| {
                enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                    label: None,
                    color_attachments: &[img.clear_attachment()],
                    depth_stencil_attachment: None,
                    timestamp_writes: None,
                    occlusion_query_set: None,
                    multiview_mask: None,
                });
            });
            gpu.flush();
        })
        .unwrap_or_else(|e| panic!("{format:?}: {e:#}"));
    }
}

/// Every graph of the graphs/ folder renders on GL, none black (livelink.ron in its own check).
fn every_graph_renders_on_gl(gpu: &GpuContext) {
    let mut graphs: Vec<String> = std::fs::read_dir(root().join("graphs"))
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.ends_with(".ron") && !n.contains(".autosave"))
        .collect();
    graphs.sort();
    assert!(graphs.len() >= 10, "{graphs:?}");
    // The regression manifest's overrides keep each graph small (fewer lights, smaller maps):
    // what this checks is that every node kind runs on GL, not the full-size figures.
    let manifest = werkstatt::app::regress::Manifest::load(&root().join("tests/references/manifest.ron")).unwrap();
    for name in graphs.iter().filter(|n| *n != "livelink.ron") {
        let out = out_dir(&format!("gl-{name}"));
        let stem = name.trim_end_matches(".ron");
        let sets = manifest.cases.get(stem).map(|c| c.sets.clone()).unwrap_or_default();
        render_on(gpu, name, &out, (0, 0), &[], &sets).unwrap_or_else(|e| panic!("{name} on GL: {e:#}"));
        let images: Vec<_> = std::fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|x| x == "png"))
            .collect();
        for p in &images {
            let img = read_png(p);
            let lum: f64 = img.pixels().map(|p| (p[0] as f64 + p[1] as f64 + p[2] as f64) / 3.0).sum::<f64>()
                / img.pixels().len() as f64;
            assert!(lum > 5.0, "{name}: {} is black on GL", p.display());
        }
    }
}

/// livelink.ron waits for a simulator: send it one frame over loopback, then render.
fn render_livelink(gpu: &GpuContext) {
    let mut graph = Graph::load(&root().join("graphs/livelink.ron")).unwrap();
    graph.nodes.get_mut("simulator").unwrap().params.insert("address".into(), ParamValue::Str("127.0.0.1:0".into()));
    let mut ev = Evaluator::new(&graph, &[]).unwrap();
    let res = Resources::new(false);
    let settings = FrameSettings { width: 160, height: 120, base_dir: root().join("graphs"), frames: None };
    let deadline = Instant::now() + Duration::from_secs(30);
    let mut sender: Option<TcpStream> = None;
    let mut frame = 0;
    loop {
        frame += 1;
        ev.evaluate(FrameTime { frame, fps: 30.0 }, Some(gpu), &res, &settings);
        if ev.report("preview").unwrap().status == &NodeStatus::Ok {
            break;
        }
        if sender.is_none()
            && let NodeStatus::Pending(p) = ev.report("simulator").unwrap().status
            && let Some(addr) = p.display().to_string().rsplit("tcp://").next().and_then(|a| a.parse().ok())
            && let Ok(mut s) = TcpStream::connect_timeout(&addr, Duration::from_secs(5))
        {
            use std::io::Write;
            let n = 8;
            let uvs: Vec<glam::Vec2> =
                (0..n * n).map(|i| glam::Vec2::new((i % n) as f32, (i / n) as f32) / (n - 1) as f32).collect();
            let mut indices = Vec::new();
            for j in 0..n - 1 {
                for i in 0..n - 1 {
                    let a = (j * n + i) as u32;
                    indices.extend_from_slice(&[a, a + n as u32, a + 1, a + 1, a + n as u32, a + n as u32 + 1]);
                }
            }
            let positions: Vec<glam::Vec3> =
                uvs.iter().map(|uv| glam::Vec3::new(uv.x - 0.5, 0.0, uv.y - 0.5)).collect();
            s.write_all(&encode_topology(&indices, &uvs, None)).unwrap();
            s.write_all(&encode_frame(1, indices.len() as u32, &positions, None)).unwrap();
            sender = Some(s);
        }
        assert!(Instant::now() < deadline, "livelink.ron on GL: {:?}", ev.report("simulator").unwrap().status);
        std::thread::sleep(Duration::from_millis(10));
    }
    let px = read_back(gpu, ev.output("preview", "image").unwrap().as_texture().unwrap()).unwrap();
    assert!(px.rgba.chunks_exact(4).any(|p| p[0] + p[1] + p[2] > 0.1), "livelink.ron is black on GL");
}

/// The same image as on lavapipe, within a GL tolerance: llvmpipe's GL rasterizes and
/// interpolates a little differently (edges, the sphere's silhouette), and where it cannot
/// render 32-bit floats the linear depth is stored as 16-bit floats.
fn matches_vulkan_on_gl(gl_gpu: &GpuContext, graph: &str, output: &str) {
    let (gl_out, vk_out) = (out_dir(&format!("gl-match-{graph}")), out_dir(&format!("vk-match-{graph}")));
    render_on(gl_gpu, graph, &gl_out, (0, 0), &[], &[]).unwrap();
    render_on(gpu(), graph, &vk_out, (0, 0), &[], &[]).unwrap();
    let file = format!("{output}_0000.png");
    let (a, b) = (read_png(&gl_out.join(&file)), read_png(&vk_out.join(&file)));
    assert_eq!(a.dimensions(), b.dimensions());
    let differing = a.pixels().zip(b.pixels()).filter(|(p, q)| (0..3).any(|c| p[c].abs_diff(q[c]) > 8)).count();
    let lum: f64 = a.pixels().map(|p| p[0] as f64 + p[1] as f64 + p[2] as f64).sum::<f64>() / a.pixels().len() as f64;
    assert!(lum > 15.0, "{graph}: the GL image is black");
    assert!(
        differing as f64 / a.pixels().len() as f64 <= 0.02,
        "{graph}: {differing} pixels differ by more than 8 levels between GL and Vulkan"
    );
}

fn a_direct_light_graph_matches_vulkan_on_gl(gpu: &GpuContext) {
    matches_vulkan_on_gl(gpu, "spot.ron", "preview");
}

/// Image-based lighting (cube faces kept as 2D arrays, which wgpu's GL backend would turn into
/// cube maps at 6 layers) and the VSM shadow atlas (depth read as float) on GL.
fn the_still_life_with_image_based_lighting_matches_vulkan_on_gl(gpu: &GpuContext) {
    matches_vulkan_on_gl(gpu, "still_life.ron", "image");
}

/// A white furnace on GL: glossy spheres of every glossiness in a white environment read 1 in
/// every pixel. Guards the silhouettes, where neighbouring pixels read different mip levels:
/// wgpu's GL backend checks each texel read against `textureSize(tex, level)`, which llvmpipe
/// answers with the first pixel's level of those it shades together, and such pixels read black
/// (33 here) before the lookups took their levels from a counted loop (shaders/ibl/cube.wgsl
/// `cube_trilinear_counted`).
fn a_white_furnace_with_pems_stays_white_on_gl(gpu: &GpuContext) {
    let out = out_dir("gl-furnace");
    let probe = out.join("white.hdr");
    write_probe(&probe, 16, 8, |_, _| glam::Vec3::ONE);
    let gloss = [0.0, 0.25, 0.5, 0.75, 0.9, 1.0];
    let text = sphere_row_graph(&probe, 16, 11, &gloss, 1.0, r#""mode": "pems""#, r#""kernel": "box""#);
    // One 48-pixel square per sphere, as in the Vulkan furnace (tests/suite/ibl.rs).
    let img = render_dumps_on_gl(gpu, &out, &text, (6 * 48, 48), &["ibl.image"]).remove(0);
    // Half-float targets on GL round 1 to within 1e-3.
    let wrong: Vec<usize> = img
        .rgba
        .chunks_exact(4)
        .enumerate()
        .filter(|(_, p)| p[..3].iter().any(|c| (c - 1.0).abs() > 1e-2))
        .map(|(i, _)| i)
        .collect();
    assert!(
        wrong.is_empty(),
        "{} of {} pixels are not white, first {:?}",
        wrong.len(),
        img.rgba.len() / 4,
        &wrong[..wrong.len().min(8)]
    );
}

/// Renders frame 0 of the graph `text` at `size` on `gpu` and reads back the textures of `dumps`.
fn render_dumps_on_gl(
    gpu: &GpuContext,
    out: &std::path::Path,
    text: &str,
    size: (u32, u32),
    dumps: &[&str],
) -> Vec<Pixels> {
    let graph = out.join("graph.ron");
    std::fs::write(&graph, text).unwrap();
    render_graph_on(gpu, &graph, out, (0, 0), size, &[], dumps).unwrap();
    dumps.iter().map(|d| read_exr(&out.join(format!("{d}_0000.exr")))).collect()
}

/// Screen-space reflections on GL: a glossy sphere alone under a uniform probe, so every ray
/// leaves for the environment, which answers with the probe's radiance; the image stays what
/// IblShading lit, as on Vulkan (tests/suite/ssr.rs). The environment lookups read a level per
/// ray, which read zeros on GL before they took it from a counted loop.
fn screen_space_reflections_of_a_uniform_probe_keep_the_image_on_gl(gpu: &GpuContext) {
    let out = out_dir("gl-ssr");
    let probe = out.join("probe.hdr");
    write_probe(&probe, 32, 16, |_, _| glam::Vec3::splat(0.5));
    let text = format!(
        r#"(version: 2, nodes: {{
        "sphere": (kind: "Primitive", params: {{ "shape": "sphere", "radius": 0.3 }}),
        "glossy": (kind: "Material", params: {{ "base_color": [0.8, 0.8, 0.8], "glossiness": 0.95 }}),
        "ball": (kind: "Draw", params: {{ "translate": [0.0, 0.5, 0.0] }}),
        "camera": (kind: "OrbitCamera", params: {{ "distance": 3.0, "pitch": 10.0, "yaw": 0.0, "target": [0.0, 0.4, 0.0] }}),
        "gbuffer": (kind: "GBufferPass"),
        "environment": (kind: "EnvironmentMap", params: {{ "path": {probe:?}, "size": 32 }}),
        "cut": (kind: "MedianCut", params: {{ "count": 1 }}),
        "pems": (kind: "Pems"),
        "light": (kind: "IblShading", params: {{ "mode": "full" }}),
        "ssr": (kind: "ScreenSpaceReflections"),
    }}, links: [
        ("sphere.mesh", "ball.mesh"), ("glossy.material", "ball.material"),
        ("ball.scene", "gbuffer.scene"), ("camera.camera", "gbuffer.camera"),
        ("environment.environment", "cut.environment"), ("environment.environment", "pems.environment"),
        ("cut.lights", "pems.lights"), ("pems.pems", "light.pems"), ("gbuffer.gbuffer", "light.gbuffer"),
        ("gbuffer.gbuffer", "ssr.gbuffer"), ("light.image", "ssr.image"), ("environment.environment", "ssr.environment"),
    ])"#,
        probe = probe.display().to_string(),
    );
    let images = render_dumps_on_gl(gpu, &out, &text, (160, 120), &["light.image", "ssr.image"]);
    let (lit, reflected) = (&images[0], &images[1]);
    let worst = lit
        .rgba
        .chunks_exact(4)
        .zip(reflected.rgba.chunks_exact(4))
        .map(|(a, b)| (0..3).map(|c| (b[c] - a[c]).abs() / a[c].max(1e-3)).fold(0.0, f32::max))
        .fold(0.0, f32::max);
    // 1% on Vulkan; GL's half-float targets add their rounding.
    assert!(worst < 0.02, "an open scene under a uniform probe changed by {:.3}% on GL", 100.0 * worst);
}

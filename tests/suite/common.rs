//! Shared test helpers: one GPU context per test binary, rendering into temp folders,
//! and the golden-image comparison.

#![allow(dead_code)]

use std::path::{Path, PathBuf};

use werkstatt::app::compare::ImageTolerance;
use werkstatt::app::render::{RenderOptions, Stats, render};
use werkstatt::gpu::{Backend, GpuContext, Pixels};

/// One GPU context per running test: a context serves one evaluator at a time (validation
/// errors and pass timings are collected per device), and tests run in parallel threads.
/// libtest starts a thread per test; each takes a context from a shared pool and gives it back
/// when the thread ends, so the binary opens about as many devices as it runs tests at once.
/// A device per test thread had left hundreds of devices alive and opened them concurrently.
pub fn gpu() -> &'static GpuContext {
    static IDLE: std::sync::Mutex<Vec<&'static GpuContext>> = std::sync::Mutex::new(Vec::new());
    struct Lease(&'static GpuContext);
    impl Drop for Lease {
        fn drop(&mut self) {
            // Errors a failed test left outside node scopes must not fail the next test.
            let _ = self.0.take_errors();
            IDLE.lock().unwrap_or_else(|e| e.into_inner()).push(self.0);
        }
    }
    thread_local! {
        static GPU: Lease = Lease({
            let idle = IDLE.lock().unwrap_or_else(|e| e.into_inner()).pop();
            idle.unwrap_or_else(|| {
                let gpu = GpuContext::headless(Backend::from_env().unwrap())
                    .unwrap_or_else(|e| panic!("GPU tests need a software adapter (apt-get install mesa-vulkan-drivers): {e:#}"));
                skip_driver_teardown_at_exit();
                Box::leak(Box::new(gpu))
            })
        });
    }
    GPU.with(|g| g.0)
}

/// Ends the test process with its exit status as soon as `exit` starts, before the C
/// library's teardown. This binary leaves hundreds of GPU devices (Vulkan, GL, the editor's)
/// alive at exit, and Mesa's exit handlers then tear the drivers down under their still
/// running threads: the process crashed with SIGSEGV after every test had passed, in about
/// one run of two. Exit handlers run in reverse order of registration, so this is registered
/// again after each device is made (after the driver registered its own). A single
/// `werkstatt` process drops its one device before exiting and does not need this.
pub fn skip_driver_teardown_at_exit() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        unsafe extern "C" {
            fn on_exit(function: extern "C" fn(i32, *mut std::ffi::c_void), arg: *mut std::ffi::c_void) -> i32;
            fn _exit(status: i32) -> !;
        }
        extern "C" fn leave(status: i32, _: *mut std::ffi::c_void) {
            use std::io::Write;
            let _ = std::io::stdout().flush();
            let _ = std::io::stderr().flush();
            // SAFETY: _exit ends the process at once; nothing runs after it.
            unsafe { _exit(status) }
        }
        // SAFETY: registers a plain function with no captured state.
        unsafe { on_exit(leave, std::ptr::null_mut()) };
    }
}

/// How long a test waits for resource loads before it fails (generous: a loaded 2-core
/// machine, debug build; a hang fails here with a message instead of stalling the suite).
pub const LOAD_WAIT: std::time::Duration = std::time::Duration::from_secs(60);

/// `Resources::wait_idle` with a deadline and a clear failure.
pub fn wait_idle(res: &werkstatt::core::resources::Resources) {
    assert!(res.wait_idle_timeout(LOAD_WAIT), "{} resource loads still in flight after {LOAD_WAIT:?}", res.in_flight());
}

pub fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

pub fn out_dir(name: &str) -> PathBuf {
    let dir = root().join("target/test-out").join(name);
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    dir
}

pub fn render_graph(
    graph: &Path,
    out: &Path,
    frames: (i64, i64),
    size: (u32, u32),
    sets: &[&str],
    dumps: &[&str],
) -> anyhow::Result<Stats> {
    render_graph_on(gpu(), graph, out, frames, size, sets, dumps)
}

/// [`render_graph`] on the device `gpu` (another backend).
pub fn render_graph_on(
    gpu: &GpuContext,
    graph: &Path,
    out: &Path,
    frames: (i64, i64),
    size: (u32, u32),
    sets: &[&str],
    dumps: &[&str],
) -> anyhow::Result<Stats> {
    let opts = RenderOptions {
        graph_path: graph.to_path_buf(),
        frames,
        fps: 30.0,
        width: size.0,
        height: size.1,
        out_dir: out.to_path_buf(),
        sets: sets.iter().map(|s| s.to_string()).collect(),
        dumps: dumps.iter().map(|s| s.to_string()).collect(),
        dump_format: None,
        ssaa: 1,
        progress: false,
        command: Vec::new(),
        pending_timeout: werkstatt::app::render::PENDING_LIMIT,
    };
    render(&opts, gpu)
}

pub fn read_exr(path: &Path) -> Pixels {
    let img = image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_rgba32f();
    Pixels { width: img.width(), height: img.height(), rgba: img.into_raw(), is_ldr: false }
}

pub fn read_png(path: &Path) -> image::RgbaImage {
    image::open(path).unwrap_or_else(|e| panic!("{}: {e}", path.display())).to_rgba8()
}

/// How float colour channels map to 8-bit for a golden image. Alpha is stored as it is,
/// clamped to [0, 1]: the G-buffer keeps glossiness in the colour's alpha and the detail flag
/// in the normal's, and the goldens guard them too.
#[derive(Clone, Copy)]
pub enum Encoding {
    /// Values already in [0, 1] (colours): stored as they are.
    Unit,
    /// Signed unit vectors (normals): x * 0.5 + 0.5.
    Signed,
    /// Distances: x / range.
    Range(f32),
}

pub fn encode(px: &Pixels, enc: Encoding) -> image::RgbaImage {
    let bytes = px
        .rgba
        .iter()
        .enumerate()
        .map(|(i, &v)| {
            let v = if i % 4 == 3 {
                v
            } else {
                match enc {
                    Encoding::Unit => v,
                    Encoding::Signed => v * 0.5 + 0.5,
                    Encoding::Range(r) => v / r,
                }
            };
            (v.clamp(0.0, 1.0) * 255.0).round() as u8
        })
        .collect();
    image::RgbaImage::from_raw(px.width, px.height, bytes).unwrap()
}

/// The goldens were rendered by lavapipe (Mesa's Vulkan software rasterizer) of the Mesa that
/// Debian ships. Another Mesa may round differently at triangle edges and in transcendental
/// functions: a few levels on a few pixels, which this tolerance absorbs (up to 0.5% of the
/// pixels off by more than 3 levels, 40 dB overall). A wrong shading model, a missing object
/// or a wrong G-buffer channel moves far more. After a Mesa upgrade that exceeds it, look at
/// the diff image before re-blessing.
pub const STRICT: ImageTolerance =
    ImageTolerance { threshold: 3.0, max_failing: 0.005, min_psnr: 40.0, min_ssim: ImageTolerance::MIN_SSIM };

/// Compares `actual` with `tests/golden/NAME.png` (`werkstatt::app::compare`, as `werkstatt test`
/// does). With `WERKSTATT_BLESS=1` the reference is (re)written instead. On failure a diff
/// image (differences x8) is written beside the output.
pub fn assert_golden(name: &str, actual: &image::RgbaImage, tol: ImageTolerance) {
    let golden = root().join("tests/golden").join(format!("{name}.png"));
    // Only an explicit 1 re-blesses: `WERKSTATT_BLESS=0` or an empty value compares.
    if std::env::var("WERKSTATT_BLESS").as_deref() == Ok("1") {
        actual.save(&golden).unwrap();
        eprintln!("blessed {}", golden.display());
        return;
    }
    assert!(
        golden.exists(),
        "no reference image {}: run the tests with WERKSTATT_BLESS=1 to create it",
        golden.display()
    );
    let expected = read_png(&golden);
    assert_eq!(expected.dimensions(), actual.dimensions(), "{name}: size differs from the reference");
    let diff = werkstatt::app::compare::compare_rgba8(&expected, actual, tol.threshold);
    if let Some(why) = diff.verdict(&tol) {
        let dir = root().join("target/golden-diff");
        std::fs::create_dir_all(&dir).unwrap();
        actual.save(dir.join(format!("{name}.actual.png"))).unwrap();
        diff.diff.save(dir.join(format!("{name}.diff.png"))).unwrap();
        panic!(
            "{name}: {why}; see {}/{name}.diff.png; if the change is intended, re-bless with WERKSTATT_BLESS=1",
            dir.display()
        );
    }
}

/// Evaluates frame 0 of `graph` on the test GPU until nothing is pending (deadline 300 s) and
/// checks that every node ran fine (NotRun: a node no output pulls from).
pub fn run_graph(graph: &werkstatt::core::graph::Graph, width: u32, height: u32) -> werkstatt::core::eval::Evaluator {
    let ev = evaluate_graph(graph, width, height);
    for id in graph.nodes.keys() {
        if let Some(r) = ev.report(id) {
            use werkstatt::core::eval::NodeStatus;
            assert!(matches!(r.status, NodeStatus::Ok | NodeStatus::NotRun), "node {id}: {:?}", r.status);
        }
    }
    ev
}

/// Evaluates frame 0 of `graph` until no node is pending; nodes may fail (see their reports).
pub fn evaluate_graph(
    graph: &werkstatt::core::graph::Graph,
    width: u32,
    height: u32,
) -> werkstatt::core::eval::Evaluator {
    use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime};
    let mut ev = Evaluator::new(graph, &[]).unwrap();
    let res = werkstatt::core::resources::Resources::new(false);
    let settings = FrameSettings { width, height, base_dir: root(), frames: None };
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(300);
    loop {
        let summary = ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, Some(gpu()), &res, &settings);
        if summary.pending == 0 {
            break;
        }
        assert!(std::time::Instant::now() < deadline, "the graph did not finish within 300 s");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    ev
}

/// Channel 0 of the texture on `node.port`, row-major.
pub fn channel0(ev: &werkstatt::core::eval::Evaluator, node: &str, port: &str) -> Vec<f32> {
    let value = ev.output(node, port).and_then(werkstatt::core::port::Value::as_texture).expect("a texture");
    werkstatt::gpu::read_back(gpu(), value).unwrap().rgba.chunks_exact(4).map(|c| c[0]).collect()
}

/// Per pixel of the G-buffer of node "gbuffer", the world position: None where nothing was
/// drawn, or within `margin_percent` of the image size from a border.
pub fn world_positions(ev: &werkstatt::core::eval::Evaluator, margin_percent: u32) -> Vec<Option<glam::Vec3>> {
    let g = match ev.output("gbuffer", "gbuffer") {
        Some(werkstatt::core::port::Value::GBuffer(g)) => g.clone(),
        _ => panic!("no G-buffer"),
    };
    let depth = werkstatt::gpu::read_back(gpu(), &g.depth).unwrap();
    let channels = depth.rgba.len() / (depth.width * depth.height) as usize;
    let (w, h) = (g.width(), g.height());
    let (mx, my) = (w * margin_percent / 100, h * margin_percent / 100);
    (0..w * h)
        .map(|i| {
            let (x, y) = (i % w, i / w);
            let d = depth.rgba[i as usize * channels];
            let border = x < mx || x >= w - mx || y < my || y >= h - my;
            (d > 0.0 && !border).then(|| werkstatt::occlusion::reference::world_position(&g.view, x, y, d))
        })
        .collect()
}

/// A camera at `eye` looking at the origin, y up, near plane 0.1.
pub fn camera_toward_origin(eye: glam::Vec3, fov_y_degrees: f32, far: f32) -> werkstatt::render::scene::Camera {
    werkstatt::render::scene::Camera { eye, target: glam::Vec3::ZERO, up: glam::Vec3::Y, fov_y_degrees, near: 0.1, far }
}

/// Writes an equirectangular .hdr of `width` x `height` whose pixel (x, y) is `f(x, y)`
/// (row 0 is straight up).
pub fn write_probe(path: &std::path::Path, width: usize, height: usize, f: impl Fn(usize, usize) -> glam::Vec3) {
    let pixels: Vec<image::Rgb<f32>> = (0..height)
        .flat_map(|y| (0..width).map(move |x| (x, y)))
        .map(|(x, y)| image::Rgb(f(x, y).to_array()))
        .collect();
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    image::codecs::hdr::HdrEncoder::new(file).encode(&pixels, width, height).unwrap();
}

/// Damaged copies of a file for the readers' corruption loops, the same on every run: the
/// truncations at `cuts`, then 400 copies with one byte inverted (even k) or replaced (odd k)
/// at the place `pick(k, random)` chooses, from a fixed xorshift sequence.
pub fn damaged_copies(
    original: &[u8],
    cuts: impl IntoIterator<Item = usize>,
    pick: impl Fn(usize, u64) -> usize,
) -> Vec<Vec<u8>> {
    let mut cases: Vec<Vec<u8>> = cuts.into_iter().map(|cut| original[..cut].to_vec()).collect();
    let mut state = 0x9E37_79B9_7F4A_7C15u64;
    let mut next = || {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        state
    };
    for k in 0..400 {
        let mut bytes = original.to_vec();
        let at = pick(k, next());
        bytes[at] = if k % 2 == 0 { !bytes[at] } else { next() as u8 };
        cases.push(bytes);
    }
    cases
}

/// Cuts and places for container files, whose structure (headers, tables, metadata) sits at the
/// start and the end: the first 64 lengths and 60 spread over the file; the first 256 bytes, the
/// last 4096, or anywhere.
pub fn damaged_container(original: &[u8]) -> Vec<Vec<u8>> {
    let n = original.len();
    let cuts = (0..64).chain((0..60).map(|k| k * n / 60)).chain([n - 1]);
    damaged_copies(original, cuts, |k, r| match k % 3 {
        0 => r as usize % 256.min(n),
        1 => n - 1 - r as usize % 4096.min(n),
        _ => r as usize % n,
    })
}

/// The text of a graph: a row of spheres (one per glossiness, albedo `albedo`) lit by `probe` through the whole
/// IBL chain; `ibl` adds IblShading parameters, `pems` Pems parameters.
pub fn sphere_row_graph(
    probe: &Path,
    size: u32,
    count: usize,
    gloss: &[f32],
    albedo: f32,
    ibl: &str,
    pems: &str,
) -> String {
    let mut nodes = format!(
        r#""sphere": (kind: "Primitive", params: {{ "shape": "sphere", "radius": 0.45 }}),
        "camera": (kind: "OrbitCamera", params: {{ "distance": {dist}, "yaw": 0.0, "pitch": 0.0, "fov": 30.0 }}),
        "gbuffer": (kind: "GBufferPass"),
        "env": (kind: "EnvironmentMap", params: {{ "path": {probe:?}, "size": {size} }}),
        "cut": (kind: "MedianCut", params: {{ "count": {count} }}),
        "pems": (kind: "Pems", params: {{ {pems} }}),
        "ibl": (kind: "IblShading", params: {{ {ibl} }}),
        "out": (kind: "Preview"),
        "#,
        dist = 2.1,
        probe = probe.display().to_string(),
    );
    let mut links = String::from(
        r#"("camera.camera", "gbuffer.camera"), ("env.environment", "cut.environment"),
        ("env.environment", "pems.environment"), ("cut.lights", "pems.lights"), ("pems.pems", "ibl.pems"),
        ("gbuffer.gbuffer", "ibl.gbuffer"), ("ibl.image", "out.image"),"#,
    );
    let merges = gloss.len().div_ceil(4);
    for (i, g) in gloss.iter().enumerate() {
        let x = (i as f32 - (gloss.len() as f32 - 1.0) / 2.0) * 1.0;
        nodes += &format!(
            r#""m{i}": (kind: "Material", params: {{ "base_color": [{albedo}, {albedo}, {albedo}], "glossiness": {g} }}),
            "d{i}": (kind: "Draw", params: {{ "translate": [{x}, 0.0, 0.0] }}),"#
        );
        links += &format!(
            r#"("sphere.mesh", "d{i}.mesh"), ("m{i}.material", "d{i}.material"), ("d{i}.scene", "row{}.{}"),"#,
            i / 4,
            ["a", "b", "c", "d"][i % 4]
        );
    }
    for m in 0..merges {
        nodes += &format!(r#""row{m}": (kind: "Merge"),"#);
        links += &format!(r#"("row{m}.scene", "all.{}"),"#, ["a", "b", "c", "d"][m]);
    }
    nodes += r#""all": (kind: "Merge"),"#;
    links += r#"("all.scene", "gbuffer.scene"),"#;
    format!("(version: 1, nodes: {{ {nodes} }}, links: [ {links} ])")
}

//! Shader hot reload in the editor's live evaluation (`WERKSTATT_SHADER_DIR`): a saved shader
//! is picked up; one that does not compile keeps the last good pipeline and reports the error.
//! The variable is read by the whole process and the other tests run on threads of this one, so
//! the test runs in a process of its own: the test binary again, filtered to this test, with the
//! variable set in the child's environment.

use std::path::PathBuf;
use std::sync::Arc;
use std::time::Duration;

use werkstatt::app::editor::live::{Live, NodeState};
use werkstatt::core::graph::{Graph, PortRef};
use werkstatt::core::param::ParamValue;
use werkstatt::gpu::{Backend, GpuContext, read_back};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn settle(live: &mut Live, gpu: &Arc<GpuContext>) {
    assert!(live.wait_idle(Some(gpu), Duration::from_secs(120)), "evaluation did not settle in 120 s");
}

/// A device, graphs/`name` and the editor's live evaluation of it at `size`, settled.
fn live_on(name: &str, size: (u32, u32)) -> (Arc<GpuContext>, Graph, Live) {
    let gpu = Arc::new(GpuContext::headless(Backend::from_env().unwrap()).expect("a software adapter (lavapipe)"));
    let graph = Graph::load(&root().join("graphs").join(name)).unwrap();
    let mut live = Live::new(root().join("graphs"), false);
    live.set_size(size.0, size.1);
    live.sync(&graph, 1, None);
    settle(&mut live, &gpu);
    (gpu, graph, live)
}

/// The centre pixel of the graph's output image.
fn centre(live: &Live, gpu: &GpuContext) -> [f32; 4] {
    let value = live.output(&PortRef::parse("image.image").unwrap()).expect("the image was rendered");
    let px = read_back(gpu, value.as_texture().unwrap()).unwrap();
    let i = ((px.height / 2 * px.width + px.width / 2) * 4) as usize;
    [px.rgba[i], px.rgba[i + 1], px.rgba[i + 2], px.rgba[i + 3]]
}

/// The whole output image.
fn image(live: &Live, gpu: &GpuContext) -> Vec<f32> {
    let value = live.output(&PortRef::parse("image.image").unwrap()).expect("the image was rendered");
    read_back(gpu, value.as_texture().unwrap()).unwrap().rgba
}

/// Set in the environment of the child process that runs the test body.
const CHILD: &str = "WERKSTATT_TEST_SHADER_RELOAD_CHILD";

#[test]
fn shaders_reload_and_a_broken_one_keeps_the_last_good_pipeline() {
    let dir = root().join("target/test-out/editor-shaders");
    if std::env::var_os(CHILD).is_none() {
        // The test's name in the harness: its module path without the crate's name.
        let name = "shaders_reload_and_a_broken_one_keeps_the_last_good_pipeline";
        let test = module_path!().split_once("::").map_or(name.to_string(), |(_, m)| format!("{m}::{name}"));
        let out = std::process::Command::new(std::env::current_exe().unwrap())
            .args(["--exact", &test, "--test-threads=1", "--nocapture"])
            .env(CHILD, "1")
            .env("WERKSTATT_SHADER_DIR", &dir)
            .output()
            .unwrap();
        let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(
            out.status.success() && stdout.contains("test result: ok. 1 passed"),
            "the test in its own process ({}) failed:\n{stdout}\n{stderr}",
            out.status
        );
        return;
    }
    assert_eq!(werkstatt::gpu::shaders::shader_dir(), Some(dir.clone()), "the parent sets WERKSTATT_SHADER_DIR");
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    for path in werkstatt::gpu::shaders::paths() {
        std::fs::create_dir_all(dir.join(path).parent().unwrap()).unwrap();
        std::fs::copy(root().join("shaders").join(path), dir.join(path)).unwrap();
    }
    let (gpu, mut graph, mut live) = live_on("still_life.ron", (64, 48));
    assert_eq!(live.state("tonemap"), NodeState::Ok);
    let original = std::fs::read_to_string(dir.join("render/tonemap.wgsl")).unwrap();
    let exposure = |graph: &mut Graph, live: &mut Live, value: f64, generation: u64| {
        werkstatt::app::editor::document::set_param(graph, "tonemap", "exposure", ParamValue::Float(value)).unwrap();
        live.sync(graph, generation, None);
        settle(live, &gpu);
    };
    // References rendered with the original shader: exposure 0.5, and 0.25 left showing.
    let default_exposure = image(&live, &gpu);
    exposure(&mut graph, &mut live, 0.5, 2);
    let half = image(&live, &gpu);
    exposure(&mut graph, &mut live, 0.25, 3);
    let quarter = image(&live, &gpu);
    assert!(half != default_exposure && half != quarter, "the exposure changes the picture");
    let gbuffer_runs = live.runs("gbuffer");

    // A broken shader: the error is reported, the last good pipeline keeps rendering.
    std::fs::write(dir.join("render/tonemap.wgsl"), original.replace("fn aces(", "fn aces( this is not wgsl")).unwrap();
    live.reload_shaders();
    settle(&mut live, &gpu);
    let err = live.shader_error.clone().expect("the compile error is kept");
    assert!(err.contains("tonemap.wgsl"), "{err}");
    assert!(matches!(live.state("tonemap"), NodeState::Failed(ref m) if m.contains("last good pipeline kept")));
    assert_eq!(live.runs("gbuffer"), gbuffer_runs, "a tonemap.wgsl edit re-runs only what uses it");
    let runs = live.runs("tonemap");
    exposure(&mut graph, &mut live, 0.5, 4);
    assert_eq!(live.runs("tonemap"), runs + 1, "the old node re-ran with its pipeline");
    // It renders exactly what the original shader rendered at this exposure.
    assert!(image(&live, &gpu) == half, "the last good pipeline must render as the original shader did");

    // A fixed shader that paints everything red, picked up by the file poll.
    let red = original.replace(
        "let c = textureLoad(hdr, vec2<i32>(frag.xy), 0).rgb * params.exposure;",
        "let c = vec3<f32>(4.0, 0.0, 0.0) + 0.0 * textureLoad(hdr, vec2<i32>(frag.xy), 0).rgb * params.exposure;",
    );
    assert_ne!(red, original, "the test edits a line that exists");
    std::thread::sleep(Duration::from_millis(20));
    std::fs::write(dir.join("render/tonemap.wgsl"), red).unwrap();
    std::thread::sleep(Duration::from_millis(600));
    settle(&mut live, &gpu);
    assert_eq!(live.shader_error, None);
    assert_eq!(live.state("tonemap"), NodeState::Ok);
    let px = centre(&live, &gpu);
    assert!(px[0] > 0.5 && px[1] < 0.1 && px[2] < 0.1, "the new shader runs: {px:?}");
}

/// While the view moves (`Live::navigating`) frames are half as wide and high, and only what
/// reads the frame size re-runs for it (the G-buffer, and the shadow atlas, which fits its
/// tiles to the view): the cloth, the light probe, the median cut and the PEMs keep their
/// results, and the full size comes back when the view rests.
#[test]
fn a_moving_view_renders_at_half_size_and_reruns_only_what_reads_the_size() {
    let (gpu, _, mut live) = live_on("still_life.ron", (64, 48));
    let size = |live: &Live| live.display().and_then(|d| d.pixels.as_ref()).map(|p| p.size);
    assert_eq!(size(&live), Some([64, 48]));
    let upstream = ["cloth", "pems", "median_cut", "environment"];
    let runs = |live: &Live| upstream.map(|id| live.runs(id));
    let before = runs(&live);
    let gbuffer = live.runs("gbuffer");
    live.navigating = true;
    settle(&mut live, &gpu);
    assert_eq!(size(&live), Some([32, 24]), "half size while the view moves");
    live.navigating = false;
    settle(&mut live, &gpu);
    assert_eq!(size(&live), Some([64, 48]), "the full size when it rests");
    assert_eq!(live.runs("gbuffer"), gbuffer + 2, "the G-buffer ran at each size");
    assert_eq!(runs(&live), before, "{upstream:?} re-ran for a new size");
}

//! The engine's GPU side (src/gpu/): pooled textures and persistent buffers (a steady orbit
//! creates nothing after its first frame, counted in stats.json), the pipeline cache (a shader
//! edit re-runs only the nodes that used it, simulation state survives, a broken shader keeps
//! the last good pipeline and reports a typed error), and error scopes per node (a validation
//! error lands on the node that caused it).

use std::path::{Path, PathBuf};
use std::time::Duration;

use crate::common::*;
use werkstatt::app::render::{RenderOptions, render};
use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
use werkstatt::core::graph::Graph;
use werkstatt::core::resources::Resources;
use werkstatt::gpu::{Backend, GpuContext, read_back};

fn fresh_gpu() -> GpuContext {
    GpuContext::headless(Backend::from_env().unwrap())
        .expect("a software adapter (apt-get install mesa-vulkan-drivers)")
}

fn settings(width: u32, height: u32) -> FrameSettings {
    FrameSettings { width, height, base_dir: root().join("graphs"), frames: None }
}

/// Evaluates `frame` until nothing is pending.
fn settle(ev: &mut Evaluator, gpu: &GpuContext, res: &Resources, frame: i64, s: &FrameSettings) {
    for _ in 0..2000 {
        let summary = ev.evaluate(FrameTime { frame, fps: 30.0 }, Some(gpu), res, s);
        if summary.pending == 0 {
            return;
        }
        crate::common::wait_idle(res);
        std::thread::sleep(Duration::from_millis(2));
    }
    panic!("frame {frame} did not settle");
}

/// The nodes that ran in the last evaluation, sorted.
fn ran(ev: &Evaluator) -> Vec<String> {
    let mut v: Vec<String> = ev.reports().filter(|r| r.ran).map(|r| r.id.to_string()).collect();
    v.sort();
    v
}

/// A copy of shaders/ that a test may edit, read by `gpu` instead of the embedded sources.
fn shader_copy(gpu: &GpuContext, name: &str) -> PathBuf {
    let dir = out_dir(name).join("shaders");
    std::fs::create_dir_all(&dir).unwrap();
    for s in werkstatt::gpu::shaders::paths() {
        std::fs::create_dir_all(dir.join(s).parent().unwrap()).unwrap();
        std::fs::copy(root().join("shaders").join(s), dir.join(s)).unwrap();
    }
    gpu.set_shader_dir(Some(dir.clone()));
    dir
}

fn edit(path: &Path, from: &str, to: &str) {
    let text = std::fs::read_to_string(path).unwrap();
    assert!(text.contains(from), "{} has no line {from:?}", path.display());
    std::fs::write(path, text.replacen(from, to, 1)).unwrap();
}

fn centre(gpu: &GpuContext, ev: &Evaluator, node: &str) -> [f32; 4] {
    let value = ev.output(node, "image").expect("the image was rendered");
    let px = read_back(gpu, value.as_texture().unwrap()).unwrap();
    let i = ((px.height / 2 * px.width + px.width / 2) * 4) as usize;
    [px.rgba[i], px.rgba[i + 1], px.rgba[i + 2], px.rgba[i + 3]]
}

#[test]
fn a_steady_orbit_creates_no_gpu_textures_or_buffers_after_the_first_frame() {
    let gpu = fresh_gpu();
    let out = out_dir("gpu-created");
    let opts = RenderOptions {
        graph_path: root().join("graphs/still_life.ron"),
        frames: (0, 23),
        fps: 30.0,
        width: 96,
        height: 72,
        out_dir: out.clone(),
        // Fewer lights: 24 frames of many-light shading are most of this test on lavapipe,
        // and the resources it counts do not depend on the light count.
        sets: vec!["median_cut.count=4".into()],
        dumps: Vec::new(),
        dump_format: None,
        ssaa: 1,
        progress: false,
        command: Vec::new(),
        pending_timeout: werkstatt::app::render::PENDING_LIMIT,
    };
    render(&opts, &gpu).unwrap();
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stats.json")).unwrap()).unwrap();
    let frames = json["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 24);
    let created = |f: &serde_json::Value, what: &str| f["gpu_created"][what].as_u64().unwrap();
    assert!(created(&frames[0], "textures") >= 5, "the first frame makes the targets: {}", frames[0]["gpu_created"]);
    assert!(created(&frames[0], "buffers") >= 1, "the first frame makes the uniform buffers");
    for f in &frames[1..] {
        // The camera orbits: the G-buffer and everything after it re-render every frame.
        assert!(f["nodes"]["gbuffer"]["ran"].as_bool().unwrap(), "frame {} did not re-render", f["frame"]);
        assert_eq!(
            (created(f, "textures"), created(f, "buffers")),
            (0, 0),
            "frame {} created GPU resources: {}",
            f["frame"],
            f["gpu_created"]
        );
    }
}

/// A simulated cloth is a new mesh every frame: its buffers come back from the pool once a
/// submit has passed, and reusing them changes nothing in the picture.
#[test]
fn an_animated_cloth_reuses_its_buffers_without_changing_the_picture() {
    let gpu = fresh_gpu();
    let graph = root().join("graphs/tablecloth.ron");
    let run = |out: &Path, frames: (i64, i64)| {
        let opts = RenderOptions {
            graph_path: graph.clone(),
            frames,
            fps: 30.0,
            width: 96,
            height: 72,
            out_dir: out.to_path_buf(),
            sets: Vec::new(),
            dumps: Vec::new(),
            dump_format: None,
            ssaa: 1,
            progress: false,
            command: Vec::new(),
            pending_timeout: werkstatt::app::render::PENDING_LIMIT,
        };
        render(&opts, &gpu).unwrap()
    };
    let (seq, alone) = (out_dir("gpu-cloth-sequence"), out_dir("gpu-cloth-alone"));
    let stats = run(&seq, (0, 5));
    for f in &stats.frames[2..] {
        assert_eq!((f.gpu_created.textures, f.gpu_created.buffers), (0, 0), "frame {}", f.frame);
    }
    run(&alone, (5, 5));
    assert!(
        std::fs::read(seq.join("image_0005.png")).unwrap() == std::fs::read(alone.join("image_0005.png")).unwrap(),
        "frame 5 after 5 frames of reuse differs from frame 5 rendered alone"
    );
}

#[test]
fn a_shader_edit_reruns_only_the_nodes_that_use_it_and_keeps_the_cloth_state() {
    let gpu = fresh_gpu();
    let dir = shader_copy(&gpu, "gpu-shader-edit");
    let graph = Graph::load(&root().join("graphs/tablecloth.ron")).unwrap();
    let mut ev = Evaluator::new(&graph, &[]).unwrap();
    let res = Resources::new(false);
    let s = settings(64, 48);
    for frame in 0..4 {
        settle(&mut ev, &gpu, &res, frame, &s);
    }
    assert_eq!(ev.report("cloth").unwrap().status, &NodeStatus::Ok);
    let cloth_runs = ev.report("cloth").unwrap().runs;
    let before = centre(&gpu, &ev, "image");

    // Nothing changed: nothing re-runs, not even with a reload.
    assert!(gpu.reload_shaders().is_empty());
    settle(&mut ev, &gpu, &res, 3, &s);
    assert_eq!(ran(&ev), Vec::<String>::new());

    // fullscreen.wgsl is included by the lighting and tone-mapping shaders only.
    edit(
        &dir.join("common/fullscreen.wgsl"),
        "return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0);",
        "return vec4<f32>(uv * 2.0 - 1.0, 0.0, 1.0) ;",
    );
    assert_eq!(gpu.reload_shaders(), ["fullscreen.wgsl"]);
    settle(&mut ev, &gpu, &res, 3, &s);
    assert_eq!(ran(&ev), ["image", "light", "tonemap"], "only users of the file and what follows them re-run");
    assert_eq!(ev.report("cloth").unwrap().runs, cloth_runs, "the simulation did not re-run");
    assert_eq!(centre(&gpu, &ev, "image"), before);

    // A real change to the tone mapper: only it and the output re-run, and it shows.
    edit(
        &dir.join("render/tonemap.wgsl"),
        "let c = textureLoad(hdr, vec2<i32>(frag.xy), 0).rgb * params.exposure;",
        "let c = vec3<f32>(4.0, 0.0, 0.0) + 0.0 * textureLoad(hdr, vec2<i32>(frag.xy), 0).rgb * params.exposure;",
    );
    assert_eq!(gpu.reload_shaders(), ["tonemap.wgsl"]);
    settle(&mut ev, &gpu, &res, 3, &s);
    assert_eq!(ran(&ev), ["image", "tonemap"]);
    let red = centre(&gpu, &ev, "image");
    assert!(red[0] > 0.9 && red[1] < 0.1 && red[2] < 0.1, "the edited shader runs: {red:?}");

    // The simulation continues from where it was: one more run for one more frame.
    settle(&mut ev, &gpu, &res, 4, &s);
    assert_eq!(ev.report("cloth").unwrap().runs, cloth_runs + 1, "the cloth steps on, it does not replay");
    assert!(ran(&ev).contains(&"gbuffer".to_string()));
}

#[test]
fn a_broken_shader_keeps_the_last_good_pipeline_and_reports_a_typed_error() {
    let gpu = fresh_gpu();
    let dir = shader_copy(&gpu, "gpu-shader-broken");
    let graph = Graph::load(&root().join("graphs/still_life.ron")).unwrap();
    let mut ev = Evaluator::new(&graph, &[]).unwrap();
    let res = Resources::new(false);
    let s = settings(64, 48);
    settle(&mut ev, &gpu, &res, 0, &s);
    let good = centre(&gpu, &ev, "image");

    edit(&dir.join("render/tonemap.wgsl"), "fn aces(", "fn aces( this is not wgsl");
    assert_eq!(gpu.reload_shaders(), ["tonemap.wgsl"]);
    settle(&mut ev, &gpu, &res, 0, &s);
    let r = ev.report("tonemap").unwrap();
    assert_eq!(r.status, &NodeStatus::Ok, "it ran on the last good pipeline");
    assert_eq!(r.shader_errors.len(), 1, "{:?}", r.shader_errors);
    assert_eq!(r.shader_errors[0].file, "tonemap.wgsl");
    assert!(r.shader_errors[0].to_string().contains("shaders/render/tonemap.wgsl"), "{}", r.shader_errors[0]);
    assert_eq!(centre(&gpu, &ev, "image"), good, "the old pipeline renders as before");
    assert!(ev.report("light").unwrap().shader_errors.is_empty(), "the error is on the node that uses the shader");

    // The error stays on the node while it is skipped, and the next frame still renders.
    settle(&mut ev, &gpu, &res, 1, &s);
    assert_eq!(ev.report("tonemap").unwrap().shader_errors.len(), 1);
    assert_eq!(ev.report("image").unwrap().status, &NodeStatus::Ok);

    // A graph that never had a good pipeline fails on that node, with the same typed error.
    let mut fresh = Evaluator::new(&graph, &[]).unwrap();
    gpu.clear_shader_cache();
    settle(&mut fresh, &gpu, &res, 0, &s);
    let r = fresh.report("tonemap").unwrap();
    assert!(matches!(r.status, NodeStatus::Failed(m) if m.contains("tonemap.wgsl")), "{:?}", r.status);
    assert_eq!(r.shader_errors[0].file, "tonemap.wgsl");
    assert_eq!(fresh.report("light").unwrap().status, &NodeStatus::Ok);

    // Fixed: the node recovers.
    edit(&dir.join("render/tonemap.wgsl"), "fn aces( this is not wgsl", "fn aces(");
    assert_eq!(gpu.reload_shaders(), ["tonemap.wgsl"]);
    settle(&mut ev, &gpu, &res, 1, &s);
    assert!(ev.report("tonemap").unwrap().shader_errors.is_empty());
}

#[test]
fn a_validation_error_lands_on_the_node_that_caused_it() {
    let gpu = fresh_gpu();
    let graph = Graph::load(&root().join("graphs/still_life.ron")).unwrap();
    let mut ev = Evaluator::new(&graph, &[]).unwrap();
    let res = Resources::new(false);
    // A zero-sized frame: the G-buffer pass is the first to make textures of the frame size.
    settle(&mut ev, &gpu, &res, 0, &settings(0, 48));
    let status = |ev: &Evaluator, id: &str| ev.report(id).unwrap().status.clone();
    assert!(
        matches!(status(&ev, "gbuffer"), NodeStatus::Failed(ref m) if m.contains("GPU validation error")),
        "{:?}",
        status(&ev, "gbuffer")
    );
    assert_eq!(status(&ev, "camera"), NodeStatus::Ok);
    assert_eq!(status(&ev, "scene"), NodeStatus::Ok);
    assert!(matches!(status(&ev, "light"), NodeStatus::Blocked(_)), "{:?}", status(&ev, "light"));
    assert!(gpu.take_errors().is_empty(), "nothing escaped the node's scope");

    // At a real size the same evaluator renders: the failed commands were never submitted.
    settle(&mut ev, &gpu, &res, 0, &settings(64, 48));
    for id in ["gbuffer", "light", "tonemap", "image"] {
        assert_eq!(status(&ev, id), NodeStatus::Ok, "{id}");
    }
    assert!(centre(&gpu, &ev, "image")[3] > 0.0);
    assert!(gpu.take_errors().is_empty());
}

#[test]
fn node_scopes_keep_errors_apart() {
    let gpu = fresh_gpu();
    let small = gpu.create_buffer("small", 16, wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST);
    let other = gpu.create_buffer("other", 16, wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST);
    let bad = gpu.begin_node("bad");
    // 64 bytes out of a 16-byte buffer.
    gpu.record(|enc| enc.copy_buffer_to_buffer(&small, 0, &other, 0, 64));
    let bad = bad.end();
    let good = gpu.begin_node("good");
    gpu.record(|enc| enc.clear_buffer(&small, 0, None));
    let good = good.end();
    assert!(bad.error.as_deref().is_some_and(|e| e.contains("Validation")), "{:?}", bad.error);
    assert_eq!(good.error, None);
    gpu.submit_checked().expect("the bad commands were dropped, the good ones submit");
}

/// The toolkit's texture kinds through the pass helpers: a cube map with mips and a 2D array
/// rendered face by face and level by level (full-screen passes into layer/mip views), a
/// depth texture, then read in one compute pass that binds a cube, an array, a depth texture,
/// a filtering and a comparison sampler and a storage buffer, read back generically.
#[test]
fn passes_bind_cube_array_and_depth_textures_with_samplers() {
    let gpu = fresh_gpu();
    let dir = shader_copy(&gpu, "gpu-texture-kinds");
    std::fs::write(
        dir.join("fill.wgsl"),
        "// #include \"fullscreen.wgsl\"\n\
         struct P { value: vec4<f32> };\n\
         @group(0) @binding(0) var<uniform> p: P;\n\
         @fragment fn fs_main() -> @location(0) vec4<f32> { return p.value; }\n",
    )
    .unwrap();
    std::fs::write(
        dir.join("probe.wgsl"),
        "@group(0) @binding(0) var cube: texture_cube<f32>;\n\
         @group(0) @binding(1) var samp: sampler;\n\
         @group(0) @binding(2) var<storage, read_write> out: array<vec4<f32>>;\n\
         @group(0) @binding(3) var layers: texture_2d_array<f32>;\n\
         @group(0) @binding(4) var depth: texture_depth_2d;\n\
         @group(0) @binding(5) var cmp: sampler_comparison;\n\
         @compute @workgroup_size(1) fn main() {\n\
           out[0] = textureSampleLevel(cube, samp, vec3<f32>(1.0, 0.0, 0.0), 0.0);\n\
           out[1] = textureSampleLevel(cube, samp, vec3<f32>(-1.0, 0.0, 0.0), 0.0);\n\
           out[2] = textureSampleLevel(cube, samp, vec3<f32>(0.0, 1.0, 0.0), 0.0);\n\
           out[3] = textureSampleLevel(cube, samp, vec3<f32>(0.0, -1.0, 0.0), 0.0);\n\
           out[4] = textureSampleLevel(cube, samp, vec3<f32>(0.0, 0.0, 1.0), 0.0);\n\
           out[5] = textureSampleLevel(cube, samp, vec3<f32>(0.0, 0.0, -1.0), 0.0);\n\
           out[6] = textureSampleLevel(cube, samp, vec3<f32>(0.0, 0.0, -1.0), 1.0);\n\
           out[7] = textureLoad(layers, vec2<i32>(1, 1), 2, 0);\n\
           out[8] = vec4<f32>(textureSampleCompareLevel(depth, cmp, vec2<f32>(0.5, 0.5), 0.1));\n\
           out[9] = vec4<f32>(textureSampleCompareLevel(depth, cmp, vec2<f32>(0.5, 0.5), 0.5));\n\
         }\n",
    )
    .unwrap();
    use werkstatt::gpu::{Bind, ComputePass, FullscreenPass, SamplerKind, TextureDesc};
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
    let hdr = gpu.formats().hdr;
    let cube = gpu.acquire("cube", TextureDesc::cube(8, hdr, usage).with_full_mips());
    assert_eq!((cube.desc.layers, cube.desc.mips), (6, 4));
    let layers = gpu.acquire("layers", TextureDesc::array(4, 4, 3, hdr, usage));
    let depth = gpu.acquire("depth", TextureDesc::target(4, 4, wgpu::TextureFormat::Depth32Float));
    let mut fill = FullscreenPass::new("fill.wgsl");
    for face in 0..6 {
        for mip in 0..2 {
            let value = [face as f32, mip as f32, 0.0, 1.0];
            fill.draw(&gpu, &[Bind::Uniform(bytemuck::cast_slice(&value))], &[&cube.layer_view(face, mip)], &[hdr])
                .unwrap();
        }
    }
    for layer in 0..3 {
        let value = [10.0 + layer as f32, 0.0, 0.0, 1.0];
        fill.draw(&gpu, &[Bind::Uniform(bytemuck::cast_slice(&value))], &[&layers.layer_view(layer, 0)], &[hdr])
            .unwrap();
    }
    gpu.record(|enc| {
        enc.begin_render_pass(&wgpu::RenderPassDescriptor {
            label: Some("depth clear"),
            color_attachments: &[],
            depth_stencil_attachment: Some(wgpu::RenderPassDepthStencilAttachment {
                view: &depth.view,
                depth_ops: Some(wgpu::Operations { load: wgpu::LoadOp::Clear(0.25), store: wgpu::StoreOp::Store }),
                stencil_ops: None,
            }),
            timestamp_writes: None,
            occlusion_query_set: None,
            multiview_mask: None,
        });
    });
    let out = gpu.create_buffer("probe out", 16 * 10, wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC);
    let mut probe = ComputePass::new("probe.wgsl", "main");
    let binds = [
        Bind::Texture(&cube),
        Bind::Sampler(SamplerKind::LinearClamp),
        Bind::StorageRw(&out),
        Bind::Texture(&layers),
        Bind::Texture(&depth),
        Bind::Sampler(SamplerKind::Comparison),
    ];
    probe.dispatch(&gpu, &[&binds], [1, 1, 1]).unwrap();
    let px: Vec<[f32; 4]> = werkstatt::gpu::read_buffer(&gpu, &out).unwrap();
    for (face, texel) in px[..6].iter().enumerate() {
        assert_eq!(texel[..2], [face as f32, 0.0], "cube face {face} at mip 0: {texel:?}");
    }
    assert_eq!(px[6][..2], [5.0, 1.0], "face -z at mip 1: {:?}", px[6]);
    assert_eq!(px[7][0], 12.0, "array layer 2: {:?}", px[7]);
    assert_eq!((px[8][0], px[9][0]), (1.0, 0.0), "comparison against depth 0.25");
    assert!(gpu.take_errors().is_empty(), "{:?}", gpu.take_errors());
    // A layer of the array reads back on its own too.
    let layer = werkstatt::gpu::readback::read_back_layer(&gpu, &layers, 1, 0).unwrap();
    assert_eq!(layer.rgba[0], 11.0);
}

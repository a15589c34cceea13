//! Headless tests of the node editor: the real `EditorApp` in an egui_kittest harness,
//! rendering with wgpu on the software adapter (lavapipe), driven by pointer and keyboard
//! events like a user.

use std::path::{Path, PathBuf};
use std::time::Instant;

use egui::accesskit::Role;
use egui::{Modifiers, Pos2, Vec2};
use egui_kittest::Harness;
use egui_kittest::kittest::Queryable;
use werkstatt::app::editor::{EditorApp, Options};
use werkstatt::core::graph::{Graph, PortRef};

fn root() -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
}

fn temp_dir(name: &str) -> PathBuf {
    let d = root().join("target/test-out/editor").join(name);
    let _ = std::fs::remove_dir_all(&d);
    std::fs::create_dir_all(&d).unwrap();
    d
}

fn options() -> Options {
    Options { file_dialogs: false, autosave: false, watch_files: false }
}

/// The software adapter the other GPU tests use (Vulkan, or GL with WERKSTATT_BACKEND=gl),
/// opened as the editor opens its window's device.
fn wgpu_setup() -> egui_wgpu::WgpuSetup {
    let mut setup = egui_wgpu::WgpuSetupCreateNew::without_display_handle();
    setup.instance_descriptor.backends = match werkstatt::gpu::Backend::from_env() {
        Ok(werkstatt::gpu::Backend::Gl) => wgpu::Backends::GL,
        _ => wgpu::Backends::VULKAN,
    };
    setup.device_descriptor = std::sync::Arc::new(werkstatt::gpu::GpuContext::device_descriptor);
    egui_wgpu::WgpuSetup::CreateNew(setup)
}

/// The editor on `graph`, in a 2000x1100 window with a wgpu renderer: the still life (graphs/still_life.ron) fits
/// at the smallest framing zoom (titles readable), so every node is on screen.
fn editor(graph: &Path) -> Harness<'static, EditorApp> {
    editor_with(graph, Vec2::new(2000.0, 1100.0), 1.0, options())
}

fn editor_with(graph: &Path, size: Vec2, pixels_per_point: f32, options: Options) -> Harness<'static, EditorApp> {
    let graph = graph.to_path_buf();
    let mut h = Harness::builder()
        .with_size(size)
        .with_pixels_per_point(pixels_per_point)
        .with_max_steps(200)
        .wgpu_setup(wgpu_setup())
        .build_eframe(move |cc| EditorApp::new(cc, Some(graph), options));
    crate::common::skip_driver_teardown_at_exit();
    settle(&mut h);
    h
}

/// Runs frames until the canvas has laid out and the evaluation has settled.
/// Steps the UI at least six frames and until the evaluation worker is idle with nothing left
/// to evaluate and no file loading (the still life's light probe loads on a thread), with a
/// 120 s deadline.
fn settle(h: &mut Harness<'_, EditorApp>) {
    for _ in 0..6 {
        h.step();
    }
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    loop {
        let live = &h.state().live;
        if live.idle() && live.last_summary.pending == 0 && live.resources.in_flight() == 0 {
            break;
        }
        assert!(std::time::Instant::now() < deadline, "the editor's evaluation did not settle in 120 s");
        std::thread::sleep(std::time::Duration::from_millis(5));
        h.step();
    }
    // The finished evaluation is drawn.
    h.step();
}

fn p(s: &str) -> PortRef {
    PortRef::parse(s).unwrap()
}

fn pin(h: &Harness<'_, EditorApp>, port: &str, input: bool) -> Pos2 {
    let app = h.state();
    app.canvas.pin_screen_pos(&p(port), &app.state.graph, input).unwrap_or_else(|| panic!("pin {port} was not drawn"))
}

/// Drags the pointer from `a` to `b` in small steps, like a hand would.
fn drag(h: &mut Harness<'_, EditorApp>, a: Pos2, b: Pos2) {
    h.hover_at(a);
    h.step();
    h.drag_at(a);
    h.step();
    for i in 1..=6 {
        h.hover_at(a + (b - a) * (i as f32 / 6.0));
        h.step();
    }
    // Release without taking the pointer away (menus opened by the drop need it).
    h.event(egui::Event::PointerButton {
        pos: b,
        button: egui::PointerButton::Primary,
        pressed: false,
        modifiers: Modifiers::NONE,
    });
    h.step();
    h.step();
}

fn click_at(h: &mut Harness<'_, EditorApp>, pos: Pos2) {
    h.hover_at(pos);
    h.step();
    h.drag_at(pos);
    h.step();
    h.drop_at(pos);
    h.step();
    h.step();
}

/// graphs/still_life.ron copied into `dir`, its light probe path made absolute (it is relative
/// to graphs/), with 8 median-cut lights instead of 22 and the cheaper sqrt_cosine PEM kernel
/// instead of phong: the editor's tests evaluate it often, and building its PEMs is most of its
/// first frame on lavapipe.
fn copy_default(dir: &Path) -> PathBuf {
    let path = dir.join("still_life.ron");
    let text = std::fs::read_to_string(root().join("graphs/still_life.ron")).unwrap();
    let assets = root().join("assets").display().to_string();
    assert!(text.contains("\"../assets/"), "still_life.ron no longer names ../assets/");
    let lights = "\"count\": 22,";
    assert!(text.contains(lights), "still_life.ron no longer has 22 median-cut lights");
    let pems = "kind: \"Pems\",\n            pos: (720.0, 560.0),\n            params: {},";
    assert!(text.contains(pems), "still_life.ron's Pems node moved or has parameters");
    // In canonical form: a test saves the graph and compares the text.
    let cheap = pems.replace("params: {},", "params: {\n                \"kernel\": \"sqrt_cosine\",\n            },");
    let text =
        text.replace("\"../assets/", &format!("\"{assets}/")).replace(lights, "\"count\": 8,").replace(pems, &cheap);
    std::fs::write(&path, text).unwrap();
    path
}

#[test]
fn add_connect_edit_undo_redo_and_save() {
    let dir = temp_dir("session");
    let path = copy_default(&dir);
    let original = std::fs::read_to_string(&path).unwrap();
    let mut h = editor(&path);
    assert!(!h.state().state.is_dirty());
    assert!(h.state().gpu().is_some(), "the engine opened a device on the window's adapter");

    // Add a Preview node from the Add menu, through its search field.
    h.get_by_role_and_label(Role::Button, "Add").click();
    h.step();
    h.step();
    h.get_by_role(Role::TextInput).type_text("Preview");
    h.step();
    h.step();
    h.get_by_role_and_label(Role::Button, "Preview").click();
    settle(&mut h);
    let pos = {
        let g = &h.state().state.graph;
        assert!(g.nodes.contains_key("preview"), "nodes: {:?}", g.nodes.keys().collect::<Vec<_>>());
        assert_eq!(g.nodes["preview"].kind, "Preview");
        g.nodes["preview"].pos
    };
    assert!(h.state().state.is_dirty());
    assert!(h.state().state.title().starts_with("* "), "unsaved changes are marked in the title");

    // Connect tonemap.image to preview.image by dragging a wire between the pins.
    let from = pin(&h, "tonemap.image", false);
    let to = pin(&h, "preview.image", true);
    if std::env::var_os("EDITOR_DEBUG").is_some() {
        eprintln!("from {from:?} to {to:?} preview {:?}", h.state().canvas.node_screen_rect("preview"));
        h.render().unwrap().save(dir.join("debug.png")).unwrap();
    }
    drag(&mut h, from, to);
    settle(&mut h);
    let linked = h.state().state.graph.links.iter().any(|l| l.from == p("tonemap.image") && l.to == p("preview.image"));
    assert!(linked, "links: {:?}", h.state().state.graph.links);
    // The viewport now shows the preview, rendered live.
    assert!(h.query_by_label("showing preview.image").is_some());
    assert!(h.state().live.output(&p("preview.image")).is_some(), "the preview was evaluated");

    // Change a parameter in the inspector: select the tonemap node, pick another operator.
    let header = h.state().canvas.node_screen_rect("tonemap").expect("tonemap is on screen");
    click_at(&mut h, header.left_top() + Vec2::new(30.0, 12.0));
    assert_eq!(h.state().state.selection.iter().collect::<Vec<_>>(), vec!["tonemap"]);
    h.get_by_value("aces").click();
    h.step();
    h.step();
    let runs = |h: &Harness<'_, EditorApp>, id: &str| h.state().live.runs(id);
    let (gbuffer_runs, tonemap_runs) = (runs(&h, "gbuffer"), runs(&h, "tonemap"));
    h.get_by_label("reinhard").click();
    settle(&mut h);
    assert_eq!(runs(&h, "gbuffer"), gbuffer_runs, "nodes upstream of the change are not re-run");
    assert_eq!(runs(&h, "tonemap"), tonemap_runs + 1, "the changed node re-ran once");
    let op = |h: &Harness<'_, EditorApp>| h.state().state.graph.nodes["tonemap"].params.get("operator").cloned();
    assert_eq!(op(&h), Some(werkstatt::core::param::ParamValue::Str("reinhard".into())));

    // Undo the parameter, then redo it (keyboard and buttons).
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    settle(&mut h);
    assert_eq!(op(&h), None, "undo restores the default operator");
    assert!(h.state().state.graph.links.iter().any(|l| l.to == p("preview.image")), "only one step was undone");
    h.get_by_role_and_label(Role::Button, "Redo").click();
    settle(&mut h);
    assert_eq!(op(&h), Some(werkstatt::core::param::ParamValue::Str("reinhard".into())));

    // Save with Ctrl+S and compare with the expected canonical file.
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::S);
    settle(&mut h);
    assert!(!h.state().state.is_dirty());
    let saved = std::fs::read_to_string(&path).unwrap();
    let preview = format!(
        "        \"preview\": (\n            kind: \"Preview\",\n            pos: ({:?}, {:?}),\n            params: {{}},\n        ),\n",
        pos[0] as f64, pos[1] as f64
    );
    let expected = original
        .replace(
            "        \"scene\": (",
            &format!("{preview}        \"scene\": ("),
        )
        .replace(
            "        \"tonemap\": (\n            kind: \"Tonemap\",\n            pos: (1440.0, 200.0),\n            params: {},",
            "        \"tonemap\": (\n            kind: \"Tonemap\",\n            pos: (1440.0, 200.0),\n            params: {\n                \"operator\": \"reinhard\",\n            },",
        )
        .replace(
            "        (\"tonemap.image\", \"image.image\"),\n",
            "        (\"tonemap.image\", \"image.image\"),\n        (\"tonemap.image\", \"preview.image\"),\n",
        );
    assert_eq!(saved, expected);
    // The saved file is a valid graph in canonical form.
    let reloaded = Graph::load(&path).unwrap();
    assert_eq!(reloaded.to_ron(), saved);
}

#[test]
fn an_incompatible_link_is_refused_with_a_message() {
    let dir = temp_dir("refused");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    let links = h.state().state.graph.links.clone();
    let from = pin(&h, "camera.camera", false);
    let to = pin(&h, "tonemap.image", true);
    drag(&mut h, from, to);
    settle(&mut h);
    assert_eq!(h.state().state.graph.links, links, "nothing changed");
    assert!(!h.state().state.is_dirty());
    let msg =
        "cannot connect camera.camera (Camera) to tonemap.image (Texture): a Texture input does not accept Camera";
    assert_eq!(h.state().state.last_message().map(|m| m.text.as_str()), Some(msg));
    assert!(h.query_by_label(msg).is_some(), "the message is shown in the status bar");
}

#[test]
fn a_failing_node_shows_its_error_on_the_node() {
    let dir = temp_dir("failing");
    let path = dir.join("failing.ron");
    std::fs::write(
        &path,
        r#"(
    version: 1,
    nodes: {
        "divide": (kind: "Math", pos: (0.0, 0.0), params: {"op": "divide", "a": 1.0}),
        "watch": (kind: "Watch", pos: (300.0, 0.0), params: {}),
        "tonemap": (kind: "Tonemap", pos: (0.0, 300.0), params: {}),
        "mystery": (kind: "Mystery", pos: (300.0, 300.0), params: {"x": 1}),
        "far": (kind: "Number", pos: (inf, NaN), params: {}),
    },
    links: [("divide.result", "watch.value")],
)
"#,
    )
    .unwrap();
    let mut h = editor(&path);
    settle(&mut h);
    // A node that fails while running, and one that cannot run (unconnected required input).
    assert!(h.query_by_label("error: division by zero (input b is 0)").is_some());
    assert!(h.query_by_label_contains("required input \"image\" (Texture) is not connected").is_some());
    assert!(h.query_by_label_contains("waiting for input from \"divide\"").is_some());
    // A kind this build does not know still opens, shown with its problem, and is kept.
    assert!(h.query_by_label_contains("unknown node kind \"Mystery\"").is_some());
    assert_eq!(h.state().state.graph.nodes["mystery"].params.len(), 1);
    // Positions that are not numbers are drawn at the origin, and are not an edit.
    assert!(!h.state().state.is_dirty());
    // Fixing the parameter clears the error.
    let header = h.state().canvas.node_screen_rect("divide").unwrap();
    click_at(&mut h, header.left_top() + Vec2::new(30.0, 12.0));
    h.state_mut().state.set_param("divide", "b", werkstatt::core::param::ParamValue::Float(4.0)).unwrap();
    settle(&mut h);
    assert!(h.query_by_label("error: division by zero (input b is 0)").is_none());
    assert_eq!(h.state().live.output(&p("divide.result")).map(|v| v.summary()), Some("0.25".into()));
}

/// Editing a 200-node chain: idle frames re-run nothing, a parameter change every frame
/// re-runs the chain every frame, a node drag moves the node. Prints the UI frame times (a
/// figure, not asserted: a debug build on a loaded machine says nothing about speed).
#[test]
fn a_200_node_graph_stays_responsive() {
    let dir = temp_dir("big");
    let path = dir.join("chain.ron");
    // The benchmark chain, laid out as a user would: rows of 20 nodes.
    let mut chain = werkstatt::app::chain_graph(200);
    for (i, node) in chain.nodes.values_mut().enumerate() {
        node.pos = [(i % 20) as f32 * 180.0, (i / 20) as f32 * 110.0];
    }
    chain.save(&path).unwrap();
    let mut h = editor(&path);
    let measure =
        |h: &mut Harness<'_, EditorApp>, what: &str, f: &mut dyn FnMut(&mut Harness<'_, EditorApp>, usize)| {
            let mut times = Vec::new();
            for i in 0..30 {
                f(h, i);
                let t = Instant::now();
                h.step();
                times.push(t.elapsed().as_secs_f64() * 1e3);
            }
            times.sort_by(f64::total_cmp);
            let (median, p95) = (times[times.len() / 2], times[(times.len() * 95) / 100]);
            eprintln!("200-node graph, {what}: median {median:.1} ms, p95 {p95:.1} ms per UI frame (harness step)");
        };
    let last_runs = |h: &Harness<'_, EditorApp>| (h.state().live.runs("m0000"), h.state().live.runs("m0199"));
    let before = last_runs(&h);
    assert!(before.1 > 0, "the chain ran");
    measure(&mut h, "idle", &mut |_, _| {});
    assert_eq!(last_runs(&h), before, "idle frames must re-run nothing");
    measure(&mut h, "changing a parameter every frame", &mut |h, i| {
        h.state_mut().state.set_param("m0000", "b", werkstatt::core::param::ParamValue::Float(i as f64)).unwrap();
    });
    settle(&mut h);
    // Changes that come faster than the worker evaluates are merged: at most one run per change.
    let runs = last_runs(&h);
    assert!(runs.0 > before.0 && runs.0 <= before.0 + 30, "{before:?} -> {runs:?}");
    assert_eq!(runs.0, runs.1, "each evaluation re-ran the whole chain");
    let pos_before = h.state().state.graph.nodes["m0100"].pos;
    let start = h.state().canvas.node_screen_rect("m0100").map(|r| r.left_top() + Vec2::new(20.0, 10.0));
    let start = start.expect("node m0100 is on screen");
    h.hover_at(start);
    h.step();
    h.drag_at(start);
    measure(&mut h, "dragging a node", &mut |h, i| h.hover_at(start + Vec2::new(i as f32 * 3.0, 0.0)));
    h.drop_at(start + Vec2::new(90.0, 0.0));
    h.step();
    let pos_after = h.state().state.graph.nodes["m0100"].pos;
    assert!(pos_after[0] > pos_before[0] + 10.0 && pos_after[1] == pos_before[1], "{pos_before:?} -> {pos_after:?}");
    let (m, p95, _) = h.state().frame_times.stats().unwrap();
    eprintln!("200-node graph, inside EditorApp::ui (evaluation and layout): median {m:.1} ms, p95 {p95:.1} ms");
    // The last value is 1 + 199 more additions of 1, plus the b the loop set on the first node.
    settle(&mut h);
    assert_eq!(h.state().live.output(&p("m0199.result")).map(|v| v.summary()), Some("228".into()));
}

/// The viewport shows the rendered graph; dragging on it orbits the camera without touching
/// the document, and clicking a texture output shows that texture.
#[test]
fn the_viewport_shows_the_rendered_graph_and_orbits() {
    let dir = temp_dir("viewport");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    assert!(h.query_by_label("showing image.image").is_some());
    let image = h.render().expect("the harness renders with wgpu");
    assert!(viewport_colours(&image) > 20, "the viewport shows a picture");
    assert_viewport_shows(&h, "image.image");

    // Orbit: drag on the picture.
    let runs = h.state().live.runs("camera");
    let centre = viewport_centre(&h);
    drag(&mut h, centre, centre + Vec2::new(80.0, -20.0));
    settle(&mut h);
    let cam = h.state().live.camera.clone().expect("the drag overrides the camera");
    assert_eq!(cam.node, "camera");
    // From yaw 35, pitch 25 (graphs/still_life.ron), 0.4 degrees per point: 80 points right
    // turn the yaw to 35 - 32 = 3, 20 points up the pitch to 25 - 8 = 17; no zoom.
    let close = |a: f64, b: f64| (a - b).abs() < 1e-3;
    assert!(
        close(cam.yaw, 3.0) && close(cam.pitch, 17.0) && close(cam.distance, 4.0),
        "orbit by (80, -20) points: yaw {}, pitch {}, distance {}",
        cam.yaw,
        cam.pitch,
        cam.distance
    );
    assert!(h.state().live.runs("camera") > runs, "the camera re-ran with the new view");
    assert!(!h.state().state.is_dirty(), "orbiting does not edit the graph");
    h.get_by_role_and_label(Role::Button, "apply to graph").click();
    settle(&mut h);
    let param = |name: &str| h.state().state.graph.param("camera", name).and_then(|v| v.as_f64()).unwrap();
    let applied = (param("yaw"), param("pitch"), param("distance"));
    assert_eq!(applied, (cam.yaw, cam.pitch, cam.distance), "the applied view");
    assert!(h.state().state.is_dirty());

    // Inspect an intermediate texture: click the G-buffer output of the gbuffer node.
    let port = port_label(&h, "gbuffer.gbuffer", false);
    click_at(&mut h, port);
    settle(&mut h);
    assert_eq!(h.state().state.inspected, Some(p("gbuffer.gbuffer")));
    assert!(h.query_by_label("showing gbuffer.gbuffer").is_some());
    let image = h.render().unwrap();
    assert!(viewport_colours(&image) > 8, "the G-buffer colour is shown");
    assert_viewport_shows(&h, "gbuffer.gbuffer");
    h.get_by_role_and_label(Role::Button, "back to preview").click();
    settle(&mut h);
    assert_eq!(h.state().state.inspected, None);
}

/// Hovering a port shows its type and current value.
#[test]
fn hovering_a_port_shows_its_value() {
    let dir = temp_dir("hover");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    let port = port_label(&h, "camera.camera", false);
    h.hover_at(port);
    // Tooltips wait for the pointer to rest.
    for _ in 0..60 {
        h.step();
    }
    assert!(h.query_by_label_contains("value: camera at").is_some(), "the camera output's summary is shown");
}

/// Renders the editor on the still life as in docs/editor.png; with
/// `WERKSTATT_EDITOR_SCREENSHOT=path` the picture is written there.
#[test]
fn screenshot() {
    let dir = temp_dir("screenshot");
    let path = copy_default(&dir);
    let mut h = editor_with(&path, Vec2::new(1360.0, 820.0), 1.5, options());
    h.get_by_label("⏱ Timings").click();
    settle(&mut h);
    // The timings made the nodes wider: frame them again.
    h.hover_at(Pos2::new(400.0, 400.0));
    h.key_press(egui::Key::F);
    settle(&mut h);
    let light = header_point(&h, "light");
    click_at(&mut h, light);
    h.hover_at(Pos2::new(5.0, 700.0));
    settle(&mut h);
    let image = h.render().expect("the harness renders with wgpu");
    assert_eq!(image.dimensions(), (2040, 1230));
    assert!(viewport_colours(&image) > 20);
    if let Some(out) = std::env::var_os("WERKSTATT_EDITOR_SCREENSHOT") {
        image.save(&out).unwrap();
    }
}

/// The viewport's display texture is the viewed port's picture, sRGB-encoded as the batch
/// renderer's PNGs are: every pixel within one level of the CPU encoding of its read-back.
fn assert_viewport_shows(h: &Harness<'_, EditorApp>, port: &str) {
    let app = h.state();
    let gpu = app.gpu().expect("a GPU");
    let source = app.live.output(&p(port)).and_then(|v| v.as_texture()).expect("the port holds a texture");
    let display = app.viewport_display().expect("the viewport converted a picture");
    assert_eq!((display.width, display.height), (source.width, source.height));
    let shown = werkstatt::gpu::read_back(gpu, display).unwrap();
    let linear = werkstatt::gpu::read_back(gpu, source).unwrap();
    let encoded = source.format.is_srgb() || source.format == wgpu::TextureFormat::Rgba8Unorm;
    let mut worst = 0.0f32;
    for (i, (s, l)) in shown.rgba.chunks(4).zip(linear.rgba.chunks(4)).enumerate() {
        for c in 0..3 {
            let want = if encoded { l[c] } else { werkstatt::color::linear_to_srgb(l[c].clamp(0.0, 1.0)) };
            let diff = (s[c] - want).abs() * 255.0;
            assert!(diff <= 1.0, "{port}: pixel {i} channel {c} shows {} for {}", s[c] * 255.0, want * 255.0);
            worst = worst.max(diff);
        }
    }
    eprintln!("viewport vs sRGB read-back of {port}: worst {worst:.2} levels");
}

/// How many distinct colours the top of the side panel (the viewport) holds.
fn viewport_colours(image: &image::RgbaImage) -> usize {
    let (w, hgt) = image.dimensions();
    let mut colours = std::collections::BTreeSet::new();
    for y in (hgt / 10..hgt / 2).step_by(7) {
        for x in (w * 3 / 4..w - 10).step_by(7) {
            let p = image.get_pixel(x, y).0;
            colours.insert((p[0] / 16, p[1] / 16, p[2] / 16));
        }
    }
    colours.len()
}

/// The screen centre of a port's label: of the widgets named like the port, the one
/// nearest to the port's pin (widgets inside nodes report graph-space rectangles).
fn port_label(h: &Harness<'_, EditorApp>, port: &str, input: bool) -> Pos2 {
    let pin = pin(h, port, input);
    let name = port.split_once('.').unwrap().1;
    let canvas = &h.state().canvas;
    h.get_all_by_label(name)
        .map(|n| canvas.to_screen(n.rect()).center())
        .min_by(|a, b| a.distance(pin).total_cmp(&b.distance(pin)))
        .unwrap()
}

fn viewport_centre(h: &Harness<'_, EditorApp>) -> Pos2 {
    let r = h.get_by_label_contains("showing ").rect();
    Pos2::new(r.left() + 200.0, r.bottom() + 150.0)
}

fn header_point(h: &Harness<'_, EditorApp>, id: &str) -> Pos2 {
    let r = h.state().canvas.node_screen_rect(id).unwrap_or_else(|| panic!("node {id} is not drawn"));
    r.left_top() + Vec2::new(r.width() * 0.5, 8.0)
}

#[test]
fn select_move_copy_paste_duplicate_delete_and_undo() {
    let dir = temp_dir("clipboard");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    let before = h.state().state.graph.clone();

    // Drag the camera node by its header: one undo step, position rounded.
    let at = header_point(&h, "camera");
    drag(&mut h, at, at + Vec2::new(60.0, 40.0));
    settle(&mut h);
    let moved = h.state().state.graph.nodes["camera"].pos;
    assert_ne!(moved, before.nodes["camera"].pos, "the node moved");
    assert!(moved.iter().all(|c| c.fract() == 0.0), "positions are whole units: {moved:?}");
    assert_eq!(h.state().state.history.undo_label(), Some("move camera"));
    assert_eq!(h.state().state.selection.iter().collect::<Vec<_>>(), vec!["camera"]);

    // Copy and paste keep the parameters; duplicate keeps them too; new ids are readable.
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::C);
    settle(&mut h);
    h.hover_at(h.state().canvas.node_screen_rect("camera").unwrap().center() + Vec2::new(0.0, 150.0));
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::V);
    settle(&mut h);
    let g = &h.state().state.graph;
    assert!(g.nodes.contains_key("camera_2"), "{:?}", g.nodes.keys().collect::<Vec<_>>());
    assert_eq!(g.nodes["camera_2"].params, g.nodes["camera"].params);
    assert_eq!(h.state().state.selection.iter().collect::<Vec<_>>(), vec!["camera_2"]);
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::D);
    settle(&mut h);
    assert_eq!(h.state().state.graph.nodes["camera_3"].params, h.state().state.graph.nodes["camera"].params);

    // Shift-click adds to the selection; Delete removes the selected nodes and their links.
    let tonemap = header_point(&h, "tonemap");
    click_at(&mut h, tonemap);
    let image = header_point(&h, "image");
    h.hover_at(image);
    h.step();
    h.event_modifiers(
        egui::Event::PointerButton {
            pos: image,
            button: egui::PointerButton::Primary,
            pressed: true,
            modifiers: Modifiers::SHIFT,
        },
        Modifiers::SHIFT,
    );
    h.event_modifiers(
        egui::Event::PointerButton {
            pos: image,
            button: egui::PointerButton::Primary,
            pressed: false,
            modifiers: Modifiers::SHIFT,
        },
        Modifiers::SHIFT,
    );
    settle(&mut h);
    let sel: Vec<String> = h.state().state.selection.iter().cloned().collect();
    assert_eq!(sel, vec!["image".to_string(), "tonemap".to_string()], "shift-click adds to the selection");
    h.key_press(egui::Key::Delete);
    settle(&mut h);
    let g = &h.state().state.graph;
    for id in &sel {
        assert!(!g.nodes.contains_key(id), "{id} was deleted");
        assert!(g.links.iter().all(|l| &l.from.node != id && &l.to.node != id));
    }

    // Undo everything, back to the file as it was opened.
    while h.state().state.history.can_undo() {
        h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
        h.step();
        h.step();
    }
    settle(&mut h);
    assert_eq!(h.state().state.graph, before);
    assert!(!h.state().state.is_dirty());
}

#[test]
fn a_wire_dropped_on_empty_space_offers_compatible_nodes() {
    let dir = temp_dir("dropped");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    let from = pin(&h, "tonemap.image", false);
    let empty = from + Vec2::new(20.0, 260.0);
    drag(&mut h, from, empty);
    settle(&mut h);
    assert!(h.query_by_label_contains("Add node for tonemap.image (Texture)").is_some(), "the menu is open");
    // Only nodes with a Texture input are offered.
    if std::env::var_os("EDITOR_DEBUG").is_some() {
        h.render().unwrap().save(dir.join("debug.png")).unwrap();
        for n in h.query_all_by_label_contains("put") {
            eprintln!("{n:?}");
        }
    }
    assert!(h.query_by_role_and_label(Role::Button, "Output ⏵").is_some());
    assert!(h.query_by_role_and_label(Role::Button, "Render ⏵").is_some());
    assert!(h.query_by_role_and_label(Role::Button, "Input ⏵").is_none(), "no Input-category node takes a Texture");
    h.get_by_role(Role::TextInput).type_text("prev");
    h.step();
    h.step();
    h.get_by_role_and_label(Role::Button, "Preview").click();
    settle(&mut h);
    let g = &h.state().state.graph;
    assert!(g.links.iter().any(|l| l.from == p("tonemap.image") && l.to == p("preview.image")), "{:?}", g.links);
}

#[test]
fn a_node_dropped_on_a_wire_is_inserted() {
    let dir = temp_dir("insert");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    // A free Tonemap below the hybrid -> tonemap wire, then dragged onto it.
    let below = {
        let app = h.state();
        let r = app.canvas.node_screen_rect("hybrid").unwrap();
        app.canvas.graph_pos(Some(r.left_bottom() + Vec2::new(0.0, 200.0)))
    };
    h.state_mut().state.add_node("Tonemap", below).unwrap();
    settle(&mut h);
    let a = pin(&h, "hybrid.combined", false);
    let b = pin(&h, "tonemap.image", true);
    let rect = h.state().canvas.node_screen_rect("tonemap_2").unwrap();
    let grab = rect.left_top() + Vec2::new(rect.width() * 0.5, 8.0);
    let target = a + (b - a) * 0.5;
    let end = grab + (target - rect.center());
    h.hover_at(grab);
    h.step();
    h.drag_at(grab);
    h.step();
    for i in 1..=6 {
        h.hover_at(grab + (end - grab) * (i as f32 / 6.0));
        h.step();
    }
    // Snarl moves a node after drawing it: one more frame shows where it is, and the wire
    // it would go into is marked.
    h.step();
    assert!(h.state().canvas.shows_insert_hint());
    if std::env::var_os("EDITOR_DEBUG").is_some() {
        h.render().unwrap().save(dir.join("dragging.png")).unwrap();
    }
    h.event(egui::Event::PointerButton {
        pos: end,
        button: egui::PointerButton::Primary,
        pressed: false,
        modifiers: Modifiers::NONE,
    });
    settle(&mut h);
    let g = &h.state().state.graph;
    assert!(g.links.iter().any(|l| l.from == p("hybrid.combined") && l.to == p("tonemap_2.image")), "{:?}", g.links);
    assert!(g.links.iter().any(|l| l.from == p("tonemap_2.image") && l.to == p("tonemap.image")));
    assert!(!g.links.iter().any(|l| l.from == p("hybrid.combined") && l.to == p("tonemap.image")));
}

#[test]
fn autosave_recovery_unsaved_close_and_reload_from_disk() {
    let dir = temp_dir("recovery");
    let path = copy_default(&dir);
    // A session that ended without saving left an autosave with one more node.
    let mut crashed = Graph::load(&path).unwrap();
    werkstatt::app::editor::document::add_node(&mut crashed, "Number", [0.0, 960.0]).unwrap();
    std::fs::write(dir.join("still_life.autosave.ron"), crashed.to_ron()).unwrap();

    let opts = Options { watch_files: true, ..options() };
    let mut h = editor_with(&path, Vec2::new(2000.0, 1100.0), 1.0, opts);
    assert!(h.query_by_label("Recover unsaved changes?").is_some(), "the autosave is offered");
    h.get_by_role_and_label(Role::Button, "Recover").click();
    settle(&mut h);
    assert_eq!(h.state().state.graph, crashed);
    assert!(h.state().state.is_dirty(), "recovered changes are unsaved");
    assert!(h.state().state.title().starts_with("* still_life.ron"));

    // Closing the window with unsaved changes asks first.
    h.input_mut().viewports.entry(egui::ViewportId::ROOT).or_default().events.push(egui::ViewportEvent::Close);
    h.step();
    h.step();
    assert!(h.query_by_label("Unsaved changes").is_some());
    h.get_by_role_and_label(Role::Button, "Cancel").click();
    settle(&mut h);
    assert!(h.query_by_label("Unsaved changes").is_none());

    // Another program rewrites the file: the editor offers to reload it (one undo step).
    let mut other = Graph::load(&path).unwrap();
    werkstatt::app::editor::document::set_param(
        &mut other,
        "tonemap",
        "exposure",
        werkstatt::core::param::ParamValue::Float(1.5),
    )
    .unwrap();
    other.save(&path).unwrap();
    std::thread::sleep(std::time::Duration::from_millis(1100));
    settle(&mut h);
    assert!(h.query_by_label("still_life.ron changed on disk.").is_some());
    h.get_by_role_and_label(Role::Button, "Reload").click();
    settle(&mut h);
    assert_eq!(h.state().state.graph, other);
    assert!(!h.state().state.is_dirty());
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    settle(&mut h);
    assert_eq!(h.state().state.graph, crashed, "the reload can be undone");
}

#[test]
fn a_slider_drag_is_one_undo_step_and_only_dependents_rerun() {
    let dir = temp_dir("slider");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    let tonemap = header_point(&h, "tonemap");
    click_at(&mut h, tonemap);
    let steps = h.state().state.history.len();
    let runs = |h: &Harness<'_, EditorApp>, id: &str| h.state().live.runs(id);
    let (light, tm) = (runs(&h, "light"), runs(&h, "tonemap"));
    // The inspector's exposure slider is the lowest slider (the frame slider is above it).
    let slider = h.get_all_by_role(Role::Slider).map(|n| n.rect()).max_by(|a, b| a.top().total_cmp(&b.top())).unwrap();
    let a = slider.center();
    let t = Instant::now();
    drag(&mut h, a, a + Vec2::new(slider.width() * 0.3, 0.0));
    let dragged = t.elapsed();
    settle(&mut h);
    let exposure = h.state().state.graph.param("tonemap", "exposure").and_then(|v| v.as_f64()).unwrap();
    assert!(exposure > 1.0, "the drag raised the exposure: {exposure}");
    assert_eq!(h.state().state.history.len(), steps + 1, "the whole drag is one undo step");
    assert_eq!(runs(&h, "light"), light, "upstream nodes did not re-run");
    assert!(runs(&h, "tonemap") > tm, "the tone mapper re-ran");
    // A value held by the drag is evaluated when it rests (250 ms) or is let go: a drag that
    // never rested that long evaluates its final value only, not the ones on the way.
    if dragged < werkstatt::app::editor::live::SETTLE {
        assert_eq!(runs(&h, "tonemap"), tm + 1, "only the released value was evaluated");
    } else {
        eprintln!("the drag took {dragged:?} (a loaded machine): intermediate values may have rested");
    }
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    settle(&mut h);
    assert_eq!(h.state().state.graph.nodes["tonemap"].params.get("exposure"), None);
}

#[test]
fn a_new_graph_is_saved_through_save_as() {
    let dir = temp_dir("new");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    // File > New asks nothing while there are no changes.
    h.get_by_role_and_label(Role::Button, "File").click();
    h.step();
    h.step();
    h.get_by(|n| n.role() == Role::Button && n.label().is_some_and(|l| l.starts_with("New"))).click();
    settle(&mut h);
    assert!(h.state().state.graph.nodes.is_empty());
    assert_eq!(h.state().state.title(), "untitled - werkstatt");
    h.state_mut().state.add_node("Number", [0.0, 0.0]).unwrap();
    settle(&mut h);
    // Ctrl+S on a graph without a file asks for one.
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::S);
    settle(&mut h);
    assert!(h.query_by_label("Save graph as").is_some());
    let target = dir.join("fresh");
    h.get_by_role(Role::TextInput).type_text(&target.display().to_string());
    h.step();
    h.get_by_role_and_label(Role::Button, "Save").click();
    settle(&mut h);
    let saved = dir.join("fresh.ron");
    assert_eq!(h.state().state.path.as_deref(), Some(saved.as_path()));
    assert!(!h.state().state.is_dirty());
    assert_eq!(std::fs::read_to_string(&saved).unwrap(), h.state().state.graph.to_ron());
    assert_eq!(h.state().state.title(), "fresh.ron - werkstatt");
}

/// File > Open's "Browse…" opens a file dialog drawn by egui in the graph's folder; picking
/// a file there opens it.
#[test]
fn a_graph_is_opened_through_the_file_dialog() {
    let dir = temp_dir("browse");
    let path = copy_default(&dir);
    let other = dir.join("other.ron");
    std::fs::write(&other, "(version: 2, nodes: {\"n\": (kind: \"Number\")}, links: [])").unwrap();
    std::fs::write(dir.join("notes.txt"), "not a graph").unwrap();
    let mut h = editor_with(&path, Vec2::new(1600.0, 1000.0), 1.0, Options { file_dialogs: true, ..options() });
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::O);
    settle(&mut h);
    h.get_by_role_and_label(Role::Button, "Browse…").click();
    settle(&mut h);
    let label =
        |h: &Harness<'_, EditorApp>, name: &str| h.query_by(|n| n.label().is_some_and(|l| l.ends_with(name))).is_some();
    assert!(label(&h, "other.ron") && label(&h, "still_life.ron"), "the dialog lists the graph's folder");
    assert!(!label(&h, "notes.txt"), "the dialog shows graphs only");
    h.get_by(|n| n.label().is_some_and(|l| l.ends_with("other.ron"))).click();
    settle(&mut h);
    h.get_by(|n| n.role() == Role::Button && n.label().is_some_and(|l| l.ends_with("Open"))).click();
    settle(&mut h);
    assert_eq!(h.state().state.path.as_deref(), Some(other.as_path()));
    assert!(h.state().state.graph.nodes.contains_key("n"));
}

// ---- a slow graph: evaluation off the UI thread, progress, cancel, costs, memory ----

/// The CPU time of the calling thread: what a UI frame costs itself, whatever else the
/// (shared, loaded) machine runs meanwhile.
fn thread_cpu() -> std::time::Duration {
    let mut ts = libc::timespec { tv_sec: 0, tv_nsec: 0 };
    // SAFETY: clock_gettime writes the timespec it is given.
    unsafe { libc::clock_gettime(libc::CLOCK_THREAD_CPUTIME_ID, &mut ts) };
    std::time::Duration::new(ts.tv_sec as u64, ts.tv_nsec as u32)
}

/// One UI frame, timed: (wall ms, CPU ms of the UI thread).
fn timed_step(h: &mut Harness<'_, EditorApp>) -> (f64, f64) {
    let (t, c) = (Instant::now(), thread_cpu());
    h.step();
    (t.elapsed().as_secs_f64() * 1e3, (thread_cpu() - c).as_secs_f64() * 1e3)
}

/// (median, p95, max) of frame times in ms.
fn stats(v: &[f64]) -> (f64, f64, f64) {
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
    (at(0.5), at(0.95), v[v.len() - 1])
}

/// The still life (8 lights) with a `Delay` node between the tone mapper and the output.
fn copy_default_with_delay(dir: &Path) -> PathBuf {
    let path = copy_default(dir);
    let text = std::fs::read_to_string(&path).unwrap();
    let link = "(\"tonemap.image\", \"image.image\")";
    assert!(text.contains(link), "still_life.ron no longer links tonemap to image");
    let text = text.replace(link, "(\"tonemap.image\", \"delay.image\"), (\"delay.image\", \"image.image\")").replacen(
        "nodes: {",
        "nodes: {\n        \"delay\": (kind: \"Delay\", pos: (1440.0, 420.0), params: {}),",
        1,
    );
    std::fs::write(&path, text).unwrap();
    path
}

/// Steps the UI until `done` holds, with a deadline; returns the frames' (wall, CPU) times.
fn step_until(
    h: &mut Harness<'_, EditorApp>,
    what: &str,
    timeout: std::time::Duration,
    done: impl Fn(&EditorApp) -> bool,
) -> Vec<(f64, f64)> {
    let deadline = Instant::now() + timeout;
    let mut times = Vec::new();
    while !done(h.state()) {
        assert!(Instant::now() < deadline, "{what}: not within {timeout:?}");
        times.push(timed_step(h));
        std::thread::sleep(std::time::Duration::from_millis(2));
    }
    times
}

fn set_param(h: &mut Harness<'_, EditorApp>, node: &str, name: &str, v: werkstatt::core::param::ParamValue) {
    h.state_mut().state.set_param(node, name, v).unwrap();
}

/// Runs the calling test alone in a child process (the test binary again, filtered to it):
/// its timings and the process's memory are then its own. Returns true in the child.
fn in_own_process(name: &str) -> bool {
    const CHILD: &str = "WERKSTATT_TEST_EDITOR_CHILD";
    if std::env::var_os(CHILD).is_some() {
        return true;
    }
    let test = module_path!().split_once("::").map_or(name.to_string(), |(_, m)| format!("{m}::{name}"));
    let out = std::process::Command::new(std::env::current_exe().unwrap())
        .args(["--exact", &test, "--test-threads=1", "--nocapture", "--include-ignored"])
        .env(CHILD, "1")
        .output()
        .unwrap();
    let (stdout, stderr) = (String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(
        out.status.success() && stdout.contains("test result: ok. 1 passed"),
        "the test in its own process ({}) failed:\n{stdout}\n{stderr}",
        out.status
    );
    // Its figures, for the log.
    for line in stderr.lines().filter(|l| l.starts_with("figure:")) {
        eprintln!("{line}");
    }
    false
}

/// The resident memory of this process in MiB.
fn rss_mib() -> f64 {
    let statm = std::fs::read_to_string("/proc/self/statm").unwrap();
    let pages: f64 = statm.split_whitespace().nth(1).unwrap().parse().unwrap();
    pages * 4096.0 / (1u64 << 20) as f64
}

#[test]
fn a_slow_node_keeps_the_ui_responsive_and_cancels() {
    use werkstatt::core::param::ParamValue;
    if !in_own_process("a_slow_node_keeps_the_ui_responsive_and_cancels") {
        return;
    }
    let dir = temp_dir("slow");
    let path = copy_default_with_delay(&dir);
    let mut h = editor(&path);
    let stamp = |app: &EditorApp| app.live.display().map(|d| d.stamp);
    let before = stamp(h.state()).expect("the first frame is shown");
    let shown = h.state().viewport_display().map(|d| d.texture.clone()).expect("a picture");
    let delay_runs = h.state().live.runs("delay");

    // A change that makes the delay take 5 s: the window keeps answering, the old frame stays.
    set_param(&mut h, "delay", "seconds", ParamValue::Float(5.0));
    step_until(&mut h, "the delay starts", std::time::Duration::from_secs(60), |app| {
        app.live.busy().is_some_and(|b| b.node.as_deref() == Some("delay"))
    });
    let mut frames = Vec::new();
    let t = Instant::now();
    while t.elapsed() < std::time::Duration::from_millis(1500) {
        frames.push(timed_step(&mut h));
        // A window paints at most at its display's rate.
        std::thread::sleep(std::time::Duration::from_millis(8));
    }
    let busy = h.state().live.busy().expect("still evaluating");
    assert!(busy.fraction > 0.1 && busy.fraction < 0.9, "the delay reports its progress: {}", busy.fraction);
    assert_eq!(stamp(h.state()), Some(before), "the viewport keeps the last finished frame");
    assert_eq!(h.state().viewport_display().map(|d| d.texture.clone()), Some(shown.clone()));
    assert!(h.query_by_label_contains("rendering… ").is_some(), "the viewport says it is rendering");
    let wall: Vec<f64> = frames.iter().map(|f| f.0).collect();
    let cpu: Vec<f64> = frames.iter().map(|f| f.1).collect();
    let (wm, wp, wx) = stats(&wall);
    let (cm, cp, _) = stats(&cpu);
    eprintln!(
        "figure: UI frames during a 5 s evaluation ({} frames): wall median {wm:.1} ms, p95 {wp:.1} ms, max {wx:.1} ms; \
         UI thread CPU median {cm:.1} ms, p95 {cp:.1} ms",
        frames.len()
    );
    // What the UI thread spends on a frame (immune to a loaded machine), and no frame waits for
    // the evaluation (it would take seconds). Wall times only against that: on a loaded CI
    // machine the p95 was 44-49 ms, so a 33 ms wall bound failed without a UI fault.
    assert!(cp < 33.0, "UI frames cost p95 {cp:.1} ms of the UI thread during a slow evaluation");
    assert!(wp < 500.0, "UI frames took p95 {wp:.1} ms during a 5 s evaluation: they wait for it");
    assert!(wx < 1000.0, "a UI frame took {wx:.0} ms: it waited for the evaluation");
    assert!(frames.len() >= 15, "only {} UI frames in 1.5 s", frames.len());

    // Esc cancels: control (an idle worker) is back within 1 s, the old frame still shows.
    let t = Instant::now();
    h.key_press(egui::Key::Escape);
    step_until(&mut h, "the cancel", std::time::Duration::from_secs(10), |app| app.live.busy().is_none());
    let back = t.elapsed();
    let (cancelled, latency) = h.state().live.last_cancel.clone().expect("the cancel was measured");
    eprintln!(
        "figure: Esc to an idle worker {:.0} ms (worker stopped {:.0} ms after the cancel)",
        back.as_secs_f64() * 1e3,
        latency.as_secs_f64() * 1e3
    );
    assert_eq!(cancelled.node, "delay");
    assert!(back < std::time::Duration::from_secs(1), "the cancel took {back:?}");
    assert_eq!(stamp(h.state()), Some(before), "a cancelled evaluation shows nothing half-made");
    assert_eq!(h.state().live.runs("delay"), delay_runs, "a cancelled run does not count");
    assert!(h.state().live.cancelled_by_user());
    for _ in 0..10 {
        h.step();
    }
    assert!(h.state().live.busy().is_none(), "a cancelled evaluation is not started again by itself");
    assert!(h.query_by_label_contains("cancelled: showing the last finished frame").is_some());

    // A quick value renders a new frame.
    set_param(&mut h, "delay", "seconds", ParamValue::Float(0.0));
    settle(&mut h);
    assert!(stamp(h.state()) > Some(before), "a new frame was shown");
    assert_eq!(h.state().live.runs("delay"), delay_runs + 1);
}

#[test]
fn a_newer_edit_supersedes_a_running_evaluation() {
    use werkstatt::core::param::ParamValue;
    let dir = temp_dir("supersede");
    let path = copy_default_with_delay(&dir);
    let mut h = editor(&path);
    let (delay_runs, tonemap_runs) = (h.state().live.runs("delay"), h.state().live.runs("tonemap"));
    set_param(&mut h, "delay", "seconds", ParamValue::Float(60.0));
    step_until(&mut h, "the delay starts", std::time::Duration::from_secs(60), |app| {
        app.live.busy().is_some_and(|b| b.node.as_deref() == Some("delay"))
    });
    // The newer edit cancels the minute-long run at once and is evaluated instead.
    let t = Instant::now();
    set_param(&mut h, "delay", "seconds", ParamValue::Float(0.0));
    settle(&mut h);
    assert!(t.elapsed() < std::time::Duration::from_secs(30), "the newer edit waited for the older one");
    let (cancelled, latency) = h.state().live.last_cancel.clone().expect("the older evaluation was cancelled");
    assert_eq!(cancelled.node, "delay");
    eprintln!("superseded after {:.0} ms", latency.as_secs_f64() * 1e3);
    assert_eq!(h.state().live.runs("delay"), delay_runs + 1, "only the newer value ran to the end");
    assert_eq!(h.state().live.runs("tonemap"), tonemap_runs, "upstream of the change nothing re-ran");
    assert_eq!(h.state().live.state("delay"), werkstatt::app::editor::live::NodeState::Ok);
}

#[test]
fn a_change_past_the_limits_is_refused_before_any_work() {
    use werkstatt::core::param::ParamValue;
    let dir = temp_dir("refused-cost");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    let gpu_created = h.state().gpu().unwrap().created();
    let pems_runs = h.state().live.runs("pems");
    let before = rss_mib();
    set_param(&mut h, "median_cut", "count", ParamValue::Int(2200));
    // The window answers at once: the refusal is decided before the worker gets the graph.
    let t = Instant::now();
    h.step();
    let first = t.elapsed();
    let mut peak = rss_mib();
    for _ in 0..50 {
        h.step();
        peak = peak.max(rss_mib());
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    settle(&mut h);
    eprintln!(
        "figure: the frame after the change to 2200 lights took {:.1} ms; resident memory {before:.1} MiB before, \
         {peak:.1} MiB peak, {:.1} MiB after (the whole test process)",
        first.as_secs_f64() * 1e3,
        rss_mib()
    );
    let state = |h: &Harness<'_, EditorApp>, id: &str| h.state().live.state(id);
    let werkstatt::app::editor::live::NodeState::Failed(why) = state(&h, "pems") else {
        panic!("pems is refused: {:?}", state(&h, "pems"))
    };
    assert!(why.contains("refused before any work") && why.contains("2200 PEMs"), "{why}");
    assert!(why.contains("budget"), "{why}");
    assert!(
        matches!(state(&h, "shadow_atlas"), werkstatt::app::editor::live::NodeState::Failed(m) if m.contains("at most 1024 lights"))
    );
    assert!(matches!(state(&h, "light"), werkstatt::app::editor::live::NodeState::Blocked(_)));
    assert!(h.state().live.runs("pems") <= pems_runs, "no PEM was built");
    let created = h.state().gpu().unwrap().created().since(gpu_created);
    assert!(created.textures < 50, "{} textures were created for a refused change", created.textures);
    let said = h.state().state.last_message().map(|m| m.text.clone()).unwrap_or_default();
    assert!(said.contains(": refused before any work"), "the status bar says so: {said}");
    assert!(h.query_by_label(&said).is_some(), "the message is shown");
    // The inspector shows the estimate of the selected node.
    let pems = header_point(&h, "pems");
    click_at(&mut h, pems);
    assert!(h.query_by_label_contains("estimated memory: 2200 PEMs (median_cut.count)").is_some());
    // Back down, it runs again.
    set_param(&mut h, "median_cut", "count", ParamValue::Int(8));
    settle(&mut h);
    assert_eq!(state(&h, "pems"), werkstatt::app::editor::live::NodeState::Ok);
    assert_eq!(state(&h, "light"), werkstatt::app::editor::live::NodeState::Ok);
}

/// A PEM build of 600 lights cancelled a quarter in: (resident MiB before, at the peak, after;
/// pooled textures held and in use after; PEMs runs before and after; textures the build made).
fn cancelled_build(name: &str) -> (f64, f64, f64, (usize, usize), (u64, u64), u64) {
    use werkstatt::core::param::ParamValue;
    let dir = temp_dir(name);
    let path = copy_default(&dir);
    let mut h = editor(&path);
    for _ in 0..20 {
        h.step();
    }
    let before = rss_mib();
    let runs_before = h.state().live.runs("pems");
    let created_before = h.state().gpu().unwrap().created();
    // 600 PEMs fit the budget (about 600 MiB): the build starts; cancel it a quarter in.
    set_param(&mut h, "median_cut", "count", ParamValue::Int(600));
    let mut peak = before;
    let deadline = Instant::now() + std::time::Duration::from_secs(300);
    while !h.state().live.busy().is_some_and(|b| b.node.as_deref() == Some("pems") && b.fraction >= 0.25) {
        assert!(Instant::now() < deadline, "the PEM build did not get a quarter in within 300 s");
        h.step();
        peak = peak.max(rss_mib());
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    h.key_press(egui::Key::Escape);
    step_until(&mut h, "the cancel", std::time::Duration::from_secs(10), |app| app.live.busy().is_none());
    peak = peak.max(rss_mib());
    for _ in 0..10 {
        h.step();
        std::thread::sleep(std::time::Duration::from_millis(100));
    }
    let after = rss_mib();
    // SAFETY: reads the allocator's statistics.
    let m = unsafe { libc::mallinfo2() };
    eprintln!(
        "figure: memory before {before:.1} MiB, during the build {peak:.1} MiB, after the cancel {after:.1} MiB \
         (C heap after: {} MiB in use, {} MiB free, {} MiB in large mappings)",
        m.uordblks >> 20,
        m.fordblks >> 20,
        m.hblkhd >> 20
    );
    let pool = h.state().gpu().unwrap().pool_counts();
    let made = h.state().gpu().unwrap().created().since(created_before).textures;
    (before, peak, after, pool, (runs_before, h.state().live.runs("pems")), made)
}

/// After a PEM build cancelled part-way, nothing of it is kept: the pool holds no texture
/// nobody uses, the node did not count a run, and the half-made set is gone.
#[test]
fn a_cancelled_build_keeps_nothing_of_it() {
    if !in_own_process("a_cancelled_build_keeps_nothing_of_it") {
        return;
    }
    let (_, _, _, (held, in_use), (runs_before, runs_after), made) = cancelled_build("memory");
    // Resident memory cannot show it: the PEM builds are compute dispatches recorded faster than
    // lavapipe runs them, so a quarter in little has executed yet.
    assert!(made >= 100, "the build made {made} textures before the cancel: the test measures something");
    assert_eq!(held, in_use, "the pool gave back every texture nobody uses");
    assert_eq!(runs_after, runs_before, "a cancelled run does not count");
}

/// The issue's bound on the process's memory after a cancelled build. Not met yet: the C heap
/// keeps about 90 MiB more in use per cancelled 150-PEM build (inside wgpu or lavapipe, not in
/// werkstatt's pools or nodes, which are empty; see docs/editor.md).
#[test]
#[ignore = "not met: about 90 MiB of the C heap stays in use after a cancelled 150-PEM build (docs/editor.md)"]
fn memory_after_a_cancelled_build_is_within_10_percent() {
    if !in_own_process("memory_after_a_cancelled_build_is_within_10_percent") {
        return;
    }
    let (before, _, after, _, _, _) = cancelled_build("memory-10");
    assert!(after < before * 1.1, "after the cancel {after:.1} MiB, before {before:.1} MiB");
}

#[test]
fn playback_keeps_the_ui_frames_short() {
    if !in_own_process("playback_keeps_the_ui_frames_short") {
        return;
    }
    let dir = temp_dir("playback");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    let finished = h.state().live.finished;
    h.get_by_label("▶ play").click();
    h.step();
    // At least 3 s (a few hundred UI frames) and 3 rendered frames (a loaded machine renders
    // slower), within 300 s.
    let mut frames = Vec::new();
    let t = Instant::now();
    while t.elapsed() < std::time::Duration::from_secs(3) || h.state().live.finished < finished + 3 {
        assert!(t.elapsed() < std::time::Duration::from_secs(300), "playback rendered too few frames in 300 s");
        frames.push(timed_step(&mut h));
        // A window paints at most at its display's rate.
        std::thread::sleep(std::time::Duration::from_millis(8));
    }
    let secs = t.elapsed().as_secs_f64();
    let shown = h.state().live.finished - finished;
    let (wm, wp, wx) = stats(&frames.iter().map(|f| f.0).collect::<Vec<_>>());
    let (cm, cp, _) = stats(&frames.iter().map(|f| f.1).collect::<Vec<_>>());
    eprintln!(
        "figure: playback of still_life.ron (8 lights), {} UI frames and {shown} rendered frames in {secs:.1} s: UI wall median {wm:.1} ms, \
         p95 {wp:.1} ms, max {wx:.1} ms; UI thread CPU median {cm:.1} ms, p95 {cp:.1} ms",
        frames.len()
    );
    // The UI thread's own cost, and the wall time: a UI that waits for the GPU costs little CPU
    // but long frames (the commit before this work: p95 2.2 s of wall time, 6.8 ms of CPU). The
    // wall time is held against the rendered frames' (a loaded machine slows both), not a fixed
    // 33 ms, which a loaded CI machine broke without a UI fault.
    let render_frame_ms = secs * 1e3 / shown as f64;
    assert!(cp < 33.0, "UI frames cost p95 {cp:.1} ms of the UI thread while playing");
    assert!(
        wp < render_frame_ms / 2.0,
        "UI frames took p95 {wp:.1} ms while playing, against {render_frame_ms:.0} ms per rendered frame: they wait for the renders"
    );
    h.get_by_label("⏸ pause").click();
    settle(&mut h);
}

/// Playback shows every frame, waiting for the worker on one it has not evaluated (so a
/// simulation sees each frame), and plays a loop it has shown once again from the kept
/// pictures: nothing is evaluated on the second loop, and each frame shows its first picture.
#[test]
fn a_played_loop_plays_again_from_the_kept_pictures() {
    let dir = temp_dir("play-loop");
    let path = copy_default(&dir);
    let mut h = editor(&path);
    h.state_mut().live.frame_range = (0, 2);
    h.get_by_label("▶ play").click();
    // Each new picture: (frame, stamp, evaluations finished so far).
    let mut shown: Vec<(i64, u64, u64)> = Vec::new();
    let t = Instant::now();
    while shown.len() < 7 {
        assert!(t.elapsed() < std::time::Duration::from_secs(300), "two loops of 3 frames took over 300 s: {shown:?}");
        h.step();
        std::thread::sleep(std::time::Duration::from_millis(8));
        let live = &h.state().live;
        let (Some(frame), Some(stamp)) = (live.shown_frame(), live.display().map(|d| d.stamp)) else { continue };
        match shown.last_mut() {
            Some(last) if last.1 == stamp => {}
            // The same frame evaluated again (re-evaluations pick up loaded files).
            Some(last) if last.0 == frame => *last = (frame, stamp, live.finished),
            _ => shown.push((frame, stamp, live.finished)),
        }
    }
    h.get_by_label("⏸ pause").click();
    let frames: Vec<i64> = shown.iter().map(|s| s.0).collect();
    // The first is the picture shown when play was pressed.
    assert_eq!(frames, [0, 1, 2, 0, 1, 2, 0], "every frame in order: {shown:?}");
    // Frames 1 and 2 are evaluated on the first loop; from then on the kept pictures show.
    assert!(shown[2..].iter().all(|s| s.2 == shown[2].2), "the second loop evaluated: {shown:?}");
    assert_eq!((shown[4].1, shown[5].1), (shown[1].1, shown[2].1), "the second loop shows the first's pictures");
    assert_eq!(shown[3].1, shown[6].1);
    assert_eq!(h.state().live.kept_frames().0, 3);
}

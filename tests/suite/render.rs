//! Rendering through the batch runner on the software adapter: non-blank, depth-correct,
//! deterministic, and matching the golden images.

use crate::common::*;

fn default_graph() -> std::path::PathBuf {
    root().join("graphs/still_life.ron")
}

#[test]
fn default_graph_renders_a_lit_non_blank_image() {
    let out = out_dir("default");
    let stats = render_graph(&default_graph(), &out, (0, 1), (160, 120), &[], &[]).unwrap();
    assert_eq!(stats.files, ["image_0000.png", "image_0001.png"]);
    let img = read_png(&out.join("image_0000.png"));
    let lum: Vec<f64> = img.pixels().map(|p| (p[0] as f64 + p[1] as f64 + p[2] as f64) / 3.0).collect();
    let mean = lum.iter().sum::<f64>() / lum.len() as f64;
    let var = lum.iter().map(|l| (l - mean).powi(2)).sum::<f64>() / lum.len() as f64;
    assert!(mean > 30.0 && var.sqrt() > 20.0, "image looks blank: mean {mean}, std {}", var.sqrt());
    // The orbiting camera moves between frames.
    assert_ne!(read_png(&out.join("image_0001.png")).into_raw(), img.into_raw());
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("stats.json")).unwrap()).unwrap();
    assert_eq!(json["frames"].as_array().unwrap().len(), 2);
    assert!(json["frames"][0]["nodes"]["gbuffer"]["ran"].as_bool().unwrap());
    assert!(json["adapter"].as_str().unwrap().len() > 3);
}

#[test]
fn same_graph_same_bytes() {
    let a = out_dir("determinism-a");
    let b = out_dir("determinism-b");
    render_graph(&default_graph(), &a, (3, 3), (128, 96), &[], &["gbuffer.normal"]).unwrap();
    render_graph(&default_graph(), &b, (3, 3), (128, 96), &[], &["gbuffer.normal"]).unwrap();
    for f in ["image_0003.png", "gbuffer.normal_0003.exr"] {
        assert!(std::fs::read(a.join(f)).unwrap() == std::fs::read(b.join(f)).unwrap(), "{f} differs between two runs");
    }
}

/// A sphere of radius 0.5 seen from distance 3 along +Z: the G-buffer's centre pixel has
/// linear depth 2.5 and normal +Z; the corner is empty (depth 0).
#[test]
fn gbuffer_depth_and_normal_are_exact_at_the_centre() {
    let out = out_dir("gbuffer-numbers");
    let sets = [
        "camera.orbit_speed=0",
        "camera.yaw=0",
        "camera.pitch=0",
        "camera.distance=3",
        "camera.target=0,0,0",
        "draw_torus.translate=0,50,0",
        "draw_floor.translate=0,-50,0",
        "draw_ball.translate=0,0,0",
        "ball.radius=0.5",
        "ball.segments_u=256",
        "ball.segments_v=128",
    ];
    render_graph(&default_graph(), &out, (0, 0), (161, 121), &sets, &["gbuffer.depth", "gbuffer.normal"]).unwrap();
    let depth = read_exr(&out.join("gbuffer.depth_0000.exr"));
    let normal = read_exr(&out.join("gbuffer.normal_0000.exr"));
    let centre = ((60 * 161 + 80) * 4) as usize;
    assert!((depth.rgba[centre] - 2.5).abs() < 2e-3, "centre depth {}", depth.rgba[centre]);
    let n = &normal.rgba[centre..centre + 3];
    assert!(n[0].abs() < 0.02 && n[1].abs() < 0.02 && (n[2] - 1.0).abs() < 1e-3, "centre normal {n:?}");
    assert_eq!(depth.rgba[0], 0.0, "the corner sees nothing");
}

#[test]
fn golden_final_image_and_gbuffer_channels() {
    let out = out_dir("golden");
    render_graph(
        &default_graph(),
        &out,
        (0, 0),
        (160, 120),
        &[],
        &["gbuffer.color", "gbuffer.normal", "gbuffer.depth"],
    )
    .unwrap();
    assert_golden("default_image", &read_png(&out.join("image_0000.png")), STRICT);
    assert_golden(
        "default_gbuffer_color",
        &encode(&read_exr(&out.join("gbuffer.color_0000.exr")), Encoding::Unit),
        STRICT,
    );
    assert_golden(
        "default_gbuffer_normal",
        &encode(&read_exr(&out.join("gbuffer.normal_0000.exr")), Encoding::Signed),
        STRICT,
    );
    assert_golden(
        "default_gbuffer_depth",
        &encode(&read_exr(&out.join("gbuffer.depth_0000.exr")), Encoding::Range(8.0)),
        STRICT,
    );
}

#[test]
fn failing_node_fails_the_render_with_its_name() {
    let out = out_dir("failing");
    let err = render_graph(&default_graph(), &out, (0, 0), (32, 24), &["camera.near=200"], &[]).unwrap_err();
    let msg = format!("{err:#}");
    assert!(msg.contains("node \"camera\" (OrbitCamera) failed") && msg.contains("near"), "{msg}");
}

#[test]
fn dump_of_a_non_texture_port_is_refused() {
    let out = out_dir("bad-dump");
    let err = render_graph(&default_graph(), &out, (0, 0), (32, 24), &[], &["camera.camera"]).unwrap_err();
    assert!(format!("{err:#}").contains("not a texture"), "{err:#}");
    let err = render_graph(&default_graph(), &out, (0, 0), (32, 24), &[], &["gbuffer.nope"]).unwrap_err();
    assert!(format!("{err:#}").contains("its outputs are: gbuffer, color, normal, depth"), "{err:#}");
}

/// A glossiness parameter map (Fig. 5.23) varies glossiness within one material: the
/// G-buffer's gloss channel holds both the map's 0 level (gloss_min) and its 1 level.
#[test]
fn gloss_map_sets_two_gloss_levels_in_the_gbuffer() {
    let out = out_dir("gloss-map");
    let sets = [
        "cloth.gloss_map=stripes",
        "cloth.gloss_min=0.1",
        "cloth.glossiness=0.9",
        "cloth.uv_scale=2",
        "cloth.texture=none",
    ];
    render_graph(&default_graph(), &out, (0, 0), (160, 120), &sets, &["gbuffer.color"]).unwrap();
    let color = read_exr(&out.join("gbuffer.color_0000.exr"));
    let near = |g: f32| color.rgba.chunks_exact(4).filter(|p| p[0] > 0.5 && (p[3] - g).abs() < 0.01).count();
    // The torus (red channel > 0.5) shows both levels, each on a good share of its pixels.
    let (low, high) = (near(0.1), near(0.9));
    assert!(low > 200 && high > 200, "gloss levels: {low} pixels at 0.1, {high} at 0.9");
}

/// `ImageWrite` with `format: exr` writes the same pixels as the PNG, as floats: every
/// channel of the EXR rounds to the PNG's byte (the tone-mapped image is display-encoded, so
/// neither file re-encodes it).
#[test]
fn image_write_exr_holds_the_pngs_pixels_as_floats() {
    let (png_dir, exr_dir) = (out_dir("image-write-png"), out_dir("image-write-exr"));
    render_graph(&default_graph(), &png_dir, (0, 0), (64, 48), &[], &[]).unwrap();
    let stats = render_graph(&default_graph(), &exr_dir, (0, 0), (64, 48), &["image.format=exr"], &[]).unwrap();
    assert_eq!(stats.files, ["image_0000.exr"]);
    let png = read_png(&png_dir.join("image_0000.png"));
    let exr = read_exr(&exr_dir.join("image_0000.exr"));
    assert_eq!((exr.width, exr.height), png.dimensions());
    assert_eq!(exr.rgba.len(), png.as_raw().len());
    let differing = exr.rgba.iter().zip(png.as_raw()).filter(|(f, b)| (*f * 255.0).round() as u8 != **b).count();
    assert_eq!(differing, 0, "{differing} channels of the EXR do not match the PNG");
}

/// A ClothSim warm-up is simulated once per process: rendering the graph again starts from
/// the kept state (no steps) and gives the same bytes as the first, simulated, render.
#[test]
fn a_cloth_warm_up_is_simulated_once_and_then_reused_exactly() {
    let graph = root().join("graphs/placements.ron");
    // A seed no other test uses: the first render simulates.
    let sets = ["cloth.seed=424242", "cloth.triangles=400", "cloth.warmup=1"];
    let (a, b) = (out_dir("warm-state-a"), out_dir("warm-state-b"));
    let first = render_graph(&graph, &a, (0, 0), (48, 48), &sets, &[]).unwrap();
    let again = render_graph(&graph, &b, (0, 0), (48, 48), &sets, &[]).unwrap();
    let steps = |s: &werkstatt::app::render::Stats| {
        serde_json::to_value(s).unwrap()["frames"][0]["nodes"]["cloth"]["counts"]["steps_simulated"].as_u64()
    };
    assert_eq!(steps(&first), Some(60), "one second of warm-up at 60 steps per second");
    assert_eq!(steps(&again), Some(0), "the second render starts from the kept state");
    assert!(!first.files.is_empty() && first.files == again.files);
    for f in &first.files {
        assert!(std::fs::read(a.join(f)).unwrap() == std::fs::read(b.join(f)).unwrap(), "{f} differs");
    }
}

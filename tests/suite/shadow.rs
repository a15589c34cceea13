//! Global occlusion (issue 11): the shadow atlas (variance shadow maps of the median-cut
//! lights), the visibility term of `IblShading` (eq. 3.43) and `HybridOcclusion`.
//!
//! - Without a shadow atlas IblShading's output is bit for bit what it was before the
//!   visibility term existed (an EXR rendered by the previous build, tests/data/ibl_unshadowed).
//! - An unoccluded plane has VIS = 1; a planar occluder over a planar receiver blocks lights
//!   from above under its middle and nothing far outside.
//! - Atlas tiles do not overlap, and the per-tile blur never reads another tile.
//! - HybridOcclusion with the local part off returns the global part bit for bit.
//! - On spheres on a plane under a white environment (g = 0, albedo 1, so shadowed /
//!   unshadowed IBL is the cosine-weighted visibility) the hybrid is closer to the ray-traced
//!   reference than either part.

use std::path::Path;
use std::sync::Arc;
use std::time::Instant;

use glam::{Mat4, Vec3};

use crate::common::*;
use werkstatt::eval::Evaluator;
use werkstatt::gpu::{GpuImage, read_back};
use werkstatt::graph::Graph;
use werkstatt::ibl::gpu::Lights;
use werkstatt::ibl::median_cut::RegionLight;
use werkstatt::nodes::reference_occlusion::world_position;
use werkstatt::nodes::shadow_atlas::{AtlasBuilder, AtlasSettings, VsmParams};
use werkstatt::port::Value;
use werkstatt::scene::{DrawItem, GBuffer, Material};

/// Writes an equirectangular .hdr whose pixel (x, y) is `f(x, y)` (row 0 is straight up).
fn write_probe(path: &Path, width: usize, height: usize, f: impl Fn(usize, usize) -> f32) {
    let pixels: Vec<image::Rgb<f32>> =
        (0..height).flat_map(|y| (0..width).map(move |x| (x, y))).map(|(x, y)| image::Rgb([f(x, y); 3])).collect();
    let file = std::io::BufWriter::new(std::fs::File::create(path).unwrap());
    image::codecs::hdr::HdrEncoder::new(file).encode(&pixels, width, height).unwrap();
}

/// A white environment (`cap_degrees` = 180) or a white cap of that many degrees around
/// the zenith, black elsewhere.
fn probe(dir: &Path, cap_degrees: f32) -> std::path::PathBuf {
    let path = dir.join(format!("probe_{cap_degrees}.hdr"));
    let (w, h) = (64, 32);
    write_probe(&path, w, h, |_, y| if (y as f32 + 0.5) / h as f32 * 180.0 <= cap_degrees { 1.0 } else { 0.0 });
    path
}

/// The IBL chain with and without shadows over `scene` (RON nodes whose Merge "all" is the
/// scene; draws get the white g = 0 material "m"), plus Ssao, HybridOcclusion and, with
/// `reference`, ReferenceOcclusion.
struct Setup<'a> {
    scene: &'a str,
    links: &'a str,
    camera: &'a str,
    probe: &'a Path,
    lights: usize,
    atlas: &'a str,
    hybrid: &'a str,
    reference: Option<&'a str>,
}

fn graph(s: &Setup<'_>) -> Graph {
    let mut nodes = format!(
        r#"{scene}
        "m": (kind: "Material", params: {{ "base_color": [1.0, 1.0, 1.0], "glossiness": 0.0 }}),
        "camera": (kind: "OrbitCamera", params: {{ {camera} }}),
        "gbuffer": (kind: "GBufferPass"),
        "env": (kind: "EnvironmentMap", params: {{ "path": {probe:?}, "size": 16 }}),
        "cut": (kind: "MedianCut", params: {{ "count": {lights} }}),
        "pems": (kind: "Pems"),
        "atlas": (kind: "ShadowAtlas", params: {{ {atlas} }}),
        "ibl": (kind: "IblShading", params: {{ "background": "color" }}),
        "ibl_plain": (kind: "IblShading", params: {{ "background": "color" }}),
        "ssao": (kind: "Ssao", params: {{ "radius": 0.3 }}),
        "hybrid": (kind: "HybridOcclusion", params: {{ {hybrid} }}),
        "out_combined": (kind: "Preview"), "out_global": (kind: "Preview"), "out_local": (kind: "Preview"),
        "#,
        scene = s.scene,
        camera = s.camera,
        probe = s.probe.display().to_string(),
        lights = s.lights,
        atlas = s.atlas,
        hybrid = s.hybrid,
    );
    let mut links = format!(
        r#"{}
        ("all.scene", "gbuffer.scene"), ("all.scene", "atlas.scene"), ("camera.camera", "gbuffer.camera"),
        ("env.environment", "cut.environment"), ("env.environment", "pems.environment"), ("cut.lights", "pems.lights"),
        ("cut.lights", "atlas.lights"), ("pems.pems", "ibl.pems"), ("pems.pems", "ibl_plain.pems"),
        ("gbuffer.gbuffer", "ibl.gbuffer"), ("gbuffer.gbuffer", "ibl_plain.gbuffer"), ("atlas.shadows", "ibl.shadows"),
        ("gbuffer.gbuffer", "ssao.gbuffer"), ("ibl.image", "hybrid.global"), ("ssao.occlusion", "hybrid.local"),
        ("ibl_plain.image", "hybrid.unshadowed"), ("hybrid.combined", "out_combined.image"),
        ("hybrid.global", "out_global.image"), ("hybrid.local_only", "out_local.image"),"#,
        s.links
    );
    if let Some(r) = s.reference {
        nodes +=
            &format!(r#""reference": (kind: "ReferenceOcclusion", params: {{ {r} }}), "out_ref": (kind: "Preview"),"#);
        links += r#"("all.scene", "reference.scene"), ("gbuffer.gbuffer", "reference.gbuffer"), ("reference.occlusion", "out_ref.image"),"#;
    }
    let text = format!("(version: 1, nodes: {{ {nodes} }}, links: [ {links} ])");
    Graph::load_str(&text, "shadow-test.ron".as_ref()).unwrap_or_else(|e| panic!("{e}\n{text}"))
}

fn rgba(ev: &Evaluator, node: &str, port: &str) -> Vec<f32> {
    read_back(gpu(), ev.output(node, port).and_then(Value::as_texture).expect("a texture")).unwrap().rgba
}

/// Per pixel, the world position (None where nothing was drawn).
fn positions(ev: &Evaluator) -> Vec<Option<Vec3>> {
    let g: Arc<GBuffer> = match ev.output("gbuffer", "gbuffer") {
        Some(Value::GBuffer(g)) => g.clone(),
        _ => panic!("no G-buffer"),
    };
    let depth = read_back(gpu(), &g.depth).unwrap();
    let channels = depth.rgba.len() / (depth.width * depth.height) as usize;
    let (w, h) = (g.width(), g.height());
    (0..w * h)
        .map(|i| {
            let d = depth.rgba[i as usize * channels];
            (d > 0.0).then(|| world_position(&g.view, i % w, i / w, d))
        })
        .collect()
}

/// Shadowed / unshadowed IBL per pixel (the visibility, with albedo 1 and g = 0).
fn visibility(ev: &Evaluator) -> Vec<f32> {
    let (lit, plain) = (channel0(ev, "ibl", "image"), channel0(ev, "ibl_plain", "image"));
    lit.iter().zip(&plain).map(|(a, b)| if *b > 1e-4 { a / b } else { 1.0 }).collect()
}

fn stats(values: &[f32], pos: &[Option<Vec3>], pick: impl Fn(Vec3) -> bool) -> (f32, f32, f32, usize) {
    let picked: Vec<f32> = values.iter().zip(pos).filter(|(_, p)| p.is_some_and(&pick)).map(|(v, _)| *v).collect();
    assert!(!picked.is_empty(), "no pixel picked");
    let mean = picked.iter().sum::<f32>() / picked.len() as f32;
    let min = picked.iter().copied().fold(f32::INFINITY, f32::min);
    let max = picked.iter().copied().fold(f32::NEG_INFINITY, f32::max);
    (mean, min, max, picked.len())
}

const FLOOR: &str = r#""floor": (kind: "Primitive", params: { "shape": "plane", "size": 4.0, "segments_u": 1, "segments_v": 1 }),
    "floor_draw": (kind: "Draw"), "all": (kind: "Merge"),"#;
const FLOOR_LINKS: &str =
    r#"("floor.mesh", "floor_draw.mesh"), ("m.material", "floor_draw.material"), ("floor_draw.scene", "all.a"),"#;

#[test]
fn without_shadows_ibl_shading_is_bit_for_bit_what_it_was() {
    // old.exr: this graph rendered at 64 x 48 without an atlas (re-rendered when cube maps
    // became six-layer arrays; VIS_i = 1 multiplies exactly, so it is the pre-visibility output).
    let dir = root().join("tests/data/ibl_unshadowed");
    let out = out_dir("shadow_unshadowed");
    render_graph(&dir.join("graph.ron"), &out, (0, 0), (64, 48), &[], &[]).unwrap();
    let (old, new) = (read_exr(&dir.join("old.exr")), read_exr(&out.join("out_0000.exr")));
    assert_eq!((old.width, old.height), (new.width, new.height));
    let differing = old.rgba.iter().zip(&new.rgba).filter(|(a, b)| a.to_bits() != b.to_bits()).count();
    assert_eq!(differing, 0, "{differing} channel values changed without a shadow atlas");
}

#[test]
fn an_unoccluded_plane_has_visibility_one() {
    let out = out_dir("shadow_plane");
    let probe = probe(&out, 180.0);
    let s = Setup {
        scene: FLOOR,
        links: FLOOR_LINKS,
        camera: r#""distance": 3.0, "pitch": 40.0, "yaw": 20.0"#,
        probe: &probe,
        lights: 16,
        atlas: "",
        hybrid: "",
        reference: None,
    };
    let ev = run_graph(&graph(&s), 96, 72);
    let pos = positions(&ev);
    let (lit, plain) = (channel0(&ev, "ibl", "image"), channel0(&ev, "ibl_plain", "image"));
    let mut worst = 0.0f32;
    for ((a, b), p) in lit.iter().zip(&plain).zip(&pos) {
        if p.is_some() {
            worst = worst.max((a - b).abs() / b.max(1e-3));
        }
    }
    eprintln!("unoccluded plane: worst relative difference shadowed/unshadowed {worst:.2e}");
    // Half precision (2^-11 relative) on the accumulated sum of 16 lights.
    assert!(worst <= 2e-3, "an open plane is shadowed: relative difference {worst}");
}

#[test]
fn a_planar_occluder_blocks_lights_from_above_under_its_middle_only() {
    let out = out_dir("shadow_occluder");
    // Light within 30 degrees of the zenith; the occluder (2 x 2 at height 0.5) covers up to
    // 63 degrees from the zenith seen from under its middle.
    let probe = probe(&out, 30.0);
    let scene = r#""floor": (kind: "Primitive", params: { "shape": "plane", "size": 8.0, "segments_u": 1, "segments_v": 1 }),
        "floor_draw": (kind: "Draw"),
        "board": (kind: "Primitive", params: { "shape": "plane", "size": 2.0, "segments_u": 1, "segments_v": 1 }),
        "board_draw": (kind: "Draw", params: { "translate": [0.0, 0.5, 0.0] }),
        "all": (kind: "Merge"),"#;
    let links = r#"("floor.mesh", "floor_draw.mesh"), ("m.material", "floor_draw.material"), ("floor_draw.scene", "all.a"),
        ("board.mesh", "board_draw.mesh"), ("m.material", "board_draw.material"), ("board_draw.scene", "all.b"),"#;
    let s = Setup {
        scene,
        links,
        camera: r#""distance": 5.0, "pitch": 6.0, "yaw": 30.0, "fov": 35.0"#,
        probe: &probe,
        lights: 8,
        atlas: "",
        hybrid: "",
        reference: None,
    };
    let ev = run_graph(&graph(&s), 160, 120);
    let pos = positions(&ev);
    let vis = visibility(&ev);
    let on_floor = |p: Vec3| p.y.abs() < 1e-3;
    let (under, under_min, under_max, n_under) =
        stats(&vis, &pos, |p| on_floor(p) && p.x.abs() < 0.3 && p.z.abs() < 0.3);
    let (outside, outside_min, _, n_out) =
        stats(&vis, &pos, |p| on_floor(p) && p.x.abs().max(p.z.abs()) > 1.8 && p.x.abs().max(p.z.abs()) < 3.0);
    eprintln!(
        "under the middle: mean {under:.4} (min {under_min:.4}, max {under_max:.4}, {n_under} px); far outside: mean {outside:.4} \
         (min {outside_min:.4}, {n_out} px)"
    );
    assert!(n_under > 20 && n_out > 200);
    assert!(under_max < 0.05, "light from above leaks under the occluder's middle: up to {under_max}");
    assert!(
        outside > 0.98 && outside_min > 0.9,
        "the floor far outside is shadowed: mean {outside}, min {outside_min}"
    );
}

fn white_items(meshes: &[(Arc<werkstatt::mesh::Mesh>, Mat4)]) -> Vec<DrawItem> {
    let material = Arc::new(Material::default());
    meshes
        .iter()
        .map(|(m, model)| DrawItem {
            mesh: m.clone(),
            material: material.clone(),
            model: *model,
            detail: false,
            attached: None,
            cuboid: None,
        })
        .collect()
}

fn light(direction: Vec3) -> RegionLight {
    RegionLight { direction, color: Vec3::ONE, solid_angle: 0.1, energy: 1.0, texels: 1 }
}

#[test]
fn atlas_tiles_do_not_overlap_and_no_blur_reads_another_tile() {
    let gpu = gpu();
    let mut builder = AtlasBuilder::default();
    // A synthetic grid of 5 tiles of 16 texels, 3 columns: tile 0 far (1, 1), tiles 1..5
    // dark (0, 0) but for a bright texel column at their left edge (next to tile 0 or 3).
    let (t, columns) = (16u32, 3u32);
    let (w, h) = (columns * t, 2 * t);
    let mut texels = vec![[0.0f32; 4]; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let j = (y / t) * columns + x / t;
            let v = if j == 0 || j >= 5 {
                1.0
            } else if x % t == 0 {
                0.5
            } else {
                0.0
            };
            texels[(y * w + x) as usize] = [v, v * v, 0.0, 0.0];
        }
    }
    let src = GpuImage::upload(gpu, "tiles", w, h, wgpu::TextureFormat::Rgba32Float, 16, bytemuck::cast_slice(&texels));
    let sigmas = [5.0f32; 5];
    let out = read_back(gpu, &builder.blur(gpu, &src, t, columns, &sigmas).unwrap()).unwrap();
    for y in 0..h {
        for x in 0..w {
            let j = (y / t) * columns + x / t;
            let i = (y * w + x) as usize * 4;
            let (m1, m2) = (out.rgba[i], out.rgba[i + 1]);
            match j {
                // Far tiles (and the empty slot) stay exactly far.
                0 | 5 => assert!(m1 == 1.0 && m2 == 1.0, "tile {j} texel ({x}, {y}): ({m1}, {m2})"),
                // Dark tiles only ever see their own bright column, so they stay below 0.5 and
                // their right halves (> 3 sigma from it) stay exactly dark.
                _ => {
                    assert!(m1 <= 0.5, "tile {j} texel ({x}, {y}) read another tile: {m1}");
                    if x % t >= 16 {
                        assert_eq!(m1, 0.0);
                    }
                }
            }
        }
    }
    // A real atlas: a floor lit from above and exactly edge-on, one light per tile.
    let floor = Arc::new(werkstatt::nodes::geometry::plane(4.0, 1, 1).unwrap());
    let items = white_items(&[(floor, Mat4::IDENTITY)]);
    let lights = Lights {
        lights: vec![light(Vec3::Y), light(Vec3::X), light(Vec3::new(0.0, 1.0, 1.0).normalize()), light(Vec3::Z)],
        regions: None,
        preview: None,
    };
    let settings = AtlasSettings { tile_size: 32, guard: None, coarse_only: true, blur_scale: 1.0 };
    let params =
        VsmParams { min_variance: 1e-5, bleed_reduction: 0.3, jitter: 0.0, normal_offset: 1.0, depth_bias: 0.002 };
    let atlas = builder.build(gpu, &items, &lights, &settings, params).unwrap();
    assert_eq!((atlas.atlas.width, atlas.atlas.height), (64, 64));
    for (a, la) in atlas.lights.iter().enumerate() {
        let [ax, ay, aw, ah] = la.rect;
        assert!(ax + aw <= 64 && ay + ah <= 64);
        for lb in &atlas.lights[a + 1..] {
            let [bx, by, bw, bh] = lb.rect;
            assert!(ax + aw <= bx || bx + bw <= ax || ay + ah <= by || by + bh <= ay, "tiles overlap");
        }
    }
    let px = read_back(gpu, &atlas.atlas).unwrap();
    let tile_values = |k: usize| -> Vec<(f32, f32)> {
        let [x0, y0, tw, th] = atlas.lights[k].rect;
        (y0..y0 + th)
            .flat_map(|y| (x0..x0 + tw).map(move |x| (x, y)))
            .map(|(x, y)| {
                let i = (y * px.width + x) as usize * 4;
                (px.rgba[i], px.rgba[i + 1])
            })
            .collect()
    };
    for k in [1, 3] {
        assert!(tile_values(k).iter().all(|&(m1, m2)| m1 == 1.0 && m2 == 1.0), "edge-on tile {k} is not all far");
    }
    for k in [0, 2] {
        let dark = tile_values(k).iter().filter(|(m1, _)| *m1 < 0.9).count();
        assert!(dark > 100, "tile {k} shows no floor ({dark} texels)");
    }
    // The floor seen from straight above lies at mid depth (0.5).
    let (m1, _) = tile_values(0)[(16 * 32 + 16) as usize];
    assert!((m1 - 0.5).abs() < 2e-3, "mid depth {m1}");
}

#[test]
fn hybrid_with_the_local_part_off_is_the_global_part_bit_for_bit() {
    let out = out_dir("shadow_hybrid");
    let probe = probe(&out, 180.0);
    let scene = r#""floor": (kind: "Primitive", params: { "shape": "plane", "size": 4.0, "segments_u": 1, "segments_v": 1 }),
        "floor_draw": (kind: "Draw"),
        "ball": (kind: "Primitive", params: { "shape": "sphere", "radius": 0.4, "segments_u": 32, "segments_v": 16 }),
        "ball_draw": (kind: "Draw", params: { "translate": [0.0, 0.4, 0.0] }),
        "all": (kind: "Merge"),"#;
    let links = r#"("floor.mesh", "floor_draw.mesh"), ("m.material", "floor_draw.material"), ("floor_draw.scene", "all.a"),
        ("ball.mesh", "ball_draw.mesh"), ("m.material", "ball_draw.material"), ("ball_draw.scene", "all.b"),"#;
    let mut s = Setup {
        scene,
        links,
        camera: r#""distance": 3.0, "pitch": 30.0"#,
        probe: &probe,
        lights: 16,
        atlas: "",
        hybrid: r#""local": false"#,
        reference: None,
    };
    let ev = run_graph(&graph(&s), 96, 72);
    let global = rgba(&ev, "ibl", "image");
    let combined = rgba(&ev, "hybrid", "combined");
    assert!(global.iter().zip(&combined).all(|(a, b)| a.to_bits() == b.to_bits()), "local off changed the image");
    assert!(global.iter().zip(rgba(&ev, "hybrid", "global").iter()).all(|(a, b)| a.to_bits() == b.to_bits()));
    // With the local part on: global x local, never brighter than global.
    s.hybrid = "";
    let ev = run_graph(&graph(&s), 96, 72);
    let (global, local, combined) =
        (rgba(&ev, "ibl", "image"), rgba(&ev, "ssao", "occlusion"), rgba(&ev, "hybrid", "combined"));
    let plain = rgba(&ev, "ibl_plain", "image");
    let local_only = rgba(&ev, "hybrid", "local_only");
    for i in (0..global.len()).filter(|i| i % 4 < 3) {
        let want = global[i] * local[i];
        assert!((combined[i] - want).abs() <= 1e-3 * want.max(1.0), "texel {i}: {} vs {want}", combined[i]);
        assert!(combined[i] <= global[i] * (1.0 + 1e-3));
        let want = plain[i] * local[i];
        assert!((local_only[i] - want).abs() <= 1e-3 * want.max(1.0));
    }
    assert!(combined.iter().zip(&global).any(|(c, g)| c < &(g * 0.9)), "the local part occludes nothing");
}

/// The spheres of graphs/fig5_25_occlusion.ron on a 4 x 4 plane.
const SPHERES: &str = r#""floor": (kind: "Primitive", params: { "shape": "plane", "size": 4.0, "segments_u": 1, "segments_v": 1 }),
    "floor_draw": (kind: "Draw"),
    "ball": (kind: "Primitive", params: { "shape": "sphere", "radius": 1.0, "segments_u": 48, "segments_v": 24 }),
    "s0": (kind: "Draw", params: { "scale": [0.3, 0.3, 0.3], "translate": [-0.9, 0.3, 0.3] }),
    "s1": (kind: "Draw", params: { "scale": [0.2, 0.2, 0.2], "translate": [-0.35, 0.2, -0.25] }),
    "s2": (kind: "Draw", params: { "scale": [0.25, 0.25, 0.25], "translate": [0.15, 0.25, 0.15] }),
    "s3": (kind: "Draw", params: { "scale": [0.15, 0.15, 0.15], "translate": [0.62, 0.15, -0.2] }),
    "s4": (kind: "Draw", params: { "scale": [0.22, 0.22, 0.22], "translate": [0.7, 0.22, 0.45] }),
    "sa": (kind: "Merge"), "sb": (kind: "Merge"), "all": (kind: "Merge"),"#;
const SPHERE_LINKS: &str = r#"("floor.mesh", "floor_draw.mesh"), ("m.material", "floor_draw.material"),
    ("ball.mesh", "s0.mesh"), ("ball.mesh", "s1.mesh"), ("ball.mesh", "s2.mesh"), ("ball.mesh", "s3.mesh"), ("ball.mesh", "s4.mesh"),
    ("m.material", "s0.material"), ("m.material", "s1.material"), ("m.material", "s2.material"), ("m.material", "s3.material"),
    ("m.material", "s4.material"), ("s0.scene", "sa.a"), ("s1.scene", "sa.b"), ("s2.scene", "sa.c"), ("s3.scene", "sa.d"),
    ("s4.scene", "sb.a"), ("floor_draw.scene", "sb.b"), ("sa.scene", "all.a"), ("sb.scene", "all.b"),"#;

/// MSEs against the ray-traced reference on the spheres scene with `lights` lights: (global,
/// local, hybrid). `SHADOW_ATLAS` (RON parameters, e.g. `"blur_scale": 0.25`) overrides the
/// atlas's defaults, for exploring.
fn spheres_errors(probe: &Path, lights: usize, size: (u32, u32)) -> (f64, f64, f64) {
    let atlas = std::env::var("SHADOW_ATLAS").unwrap_or_default();
    let s = Setup {
        scene: SPHERES,
        links: SPHERE_LINKS,
        camera: r#""distance": 3.2, "pitch": 35.0, "yaw": 20.0, "fov": 40.0, "target": [0.0, 0.1, 0.05]"#,
        probe,
        lights,
        atlas: &atlas,
        hybrid: "",
        reference: Some(r#""samples": 128, "max_distance": 10.0"#),
    };
    let t = Instant::now();
    let ev = run_graph(&graph(&s), size.0, size.1);
    let pos = positions(&ev);
    let global = visibility(&ev);
    let local = channel0(&ev, "ssao", "occlusion");
    let reference = channel0(&ev, "reference", "occlusion");
    let mse = |f: &dyn Fn(usize) -> f32| -> f64 {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for (i, p) in pos.iter().enumerate() {
            if p.is_some() {
                sum += ((f(i) - reference[i]) as f64).powi(2);
                n += 1;
            }
        }
        sum / n as f64
    };
    let errors = (mse(&|i| global[i]), mse(&|i| local[i]), mse(&|i| global[i] * local[i]));
    let bias = |f: &dyn Fn(usize) -> f32| -> f64 {
        let (mut sum, mut n) = (0.0f64, 0usize);
        for (i, p) in pos.iter().enumerate() {
            if p.is_some() {
                sum += (f(i) - reference[i]) as f64;
                n += 1;
            }
        }
        sum / n as f64
    };
    eprintln!(
        "mean signed error: global {:.4}, local {:.4}, hybrid {:.4}",
        bias(&|i| global[i]),
        bias(&|i| local[i]),
        bias(&|i| global[i] * local[i])
    );
    eprintln!(
        "{lights} lights: MSE against the reference: global {:.5}, local (SSAO) {:.5}, hybrid {:.5} ({:.1} s)",
        errors.0,
        errors.1,
        errors.2,
        t.elapsed().as_secs_f64()
    );
    errors
}

#[test]
fn hybrid_occlusion_is_closer_to_the_ray_traced_reference_than_either_part() {
    let out = out_dir("shadow_spheres");
    let probe = probe(&out, 180.0);
    let size = (160, 120);
    let (global, local, hybrid) = spheres_errors(&probe, 128, size);
    eprintln!(
        "hybrid MSE is {:.0}% below global's and {:.0}% below SSAO's",
        100.0 * (1.0 - hybrid / global),
        100.0 * (1.0 - hybrid / local)
    );
    assert!(hybrid < global && hybrid < local, "hybrid {hybrid} is not below global {global} and local {local}");
    // More lights, smaller regions, narrower blurs: the global part alone gets closer.
    let (global_many, _, hybrid_many) = spheres_errors(&probe, 512, size);
    assert!(global_many < global, "global-only at 512 lights {global_many} is not below 128 lights {global}");
    // The dissertation's claim (hybrid at 128 lights no worse than global-only at 512) does
    // not hold here: every sphere is in the atlas, so the global part already has the contact
    // shadows and SSAO counts them twice. Printed for the record, not asserted.
    eprintln!(
        "hybrid at 128 lights {hybrid:.5} against global-only at 512 {global_many:.5} (hybrid at 512: {hybrid_many:.5})"
    );
}

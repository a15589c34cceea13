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
use werkstatt::core::eval::Evaluator;
use werkstatt::core::graph::Graph;
use werkstatt::core::port::Value;
use werkstatt::gpu::{GpuImage, read_back};
use werkstatt::ibl::gpu::Lights;
use werkstatt::ibl::median_cut::RegionLight;
use werkstatt::nodes::ibl::shadow_atlas::{AtlasBuilder, AtlasSettings, TileSizes, VsmParams};
use werkstatt::render::scene::{DrawItem, Material};

/// A grey probe whose pixel (x, y) is `f(x, y)` (row 0 is straight up).
fn write_probe(path: &Path, width: usize, height: usize, f: impl Fn(usize, usize) -> f32) {
    crate::common::write_probe(path, width, height, |x, y| glam::Vec3::splat(f(x, y)));
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
    // became six-layer arrays and when the PEMs got diffuse ends; VIS_i = 1 multiplies exactly,
    // so it is the pre-visibility output).
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
    let pos = world_positions(&ev, 0);
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
    let pos = world_positions(&ev, 0);
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

/// A 2 x 2 board attached 0.5 above the middle of a floor (a PointAttachment on the floor's
/// matrix texture), under light from within 30 degrees of the zenith: by default the
/// attachment casts (its 2 triangles are within the budget) and the floor under it is dark;
/// with coarse_only it does not cast; over detail_triangle_budget it does not either, and the
/// atlas warns with the count.
#[test]
fn attachments_cast_by_default_unless_coarse_only_or_over_the_budget() {
    let out = out_dir("shadow_attachment");
    let probe = probe(&out, 30.0);
    let scene = r#""floor": (kind: "Primitive", params: { "shape": "plane", "size": 8.0, "segments_u": 1, "segments_v": 1 }),
        "floor_draw": (kind: "Draw"),
        "matrix": (kind: "MatrixTexture", params: { "resolution": 64 }),
        "spot": (kind: "GridPlacement", params: { "columns": 1, "rows": 1 }),
        "board": (kind: "Primitive", params: { "shape": "plane", "size": 1.0, "segments_u": 1, "segments_v": 1 }),
        "board_attached": (kind: "PointAttachment", params: { "scale": 2.0, "lift": 0.5 }),
        "all": (kind: "Merge"),"#;
    let links = r#"("floor.mesh", "floor_draw.mesh"), ("m.material", "floor_draw.material"), ("floor_draw.scene", "all.a"),
        ("floor.mesh", "matrix.surface"), ("floor.mesh", "spot.surface"), ("matrix.matrix", "board_attached.matrix"),
        ("board.mesh", "board_attached.mesh"), ("spot.placements", "board_attached.placements"),
        ("m.material", "board_attached.material"), ("board_attached.scene", "all.b"),"#;
    let under = |atlas: &str| {
        let s = Setup {
            scene,
            links,
            camera: r#""distance": 5.0, "pitch": 6.0, "yaw": 30.0, "fov": 35.0"#,
            probe: &probe,
            lights: 8,
            atlas,
            hybrid: "",
            reference: None,
        };
        let ev = run_graph(&graph(&s), 160, 120);
        let pos = world_positions(&ev, 0);
        let (mean, _, max, n) =
            stats(&visibility(&ev), &pos, |p| p.y.abs() < 1e-3 && p.x.abs() < 0.3 && p.z.abs() < 0.3);
        assert!(n > 20, "only {n} floor pixels under the board");
        (mean, max, ev.report("atlas").unwrap().warnings.to_vec())
    };
    let (cast, cast_max, warnings) = under("");
    let (coarse, _, coarse_warnings) = under(r#""coarse_only": true"#);
    let (over, _, over_warnings) = under(r#""detail_triangle_budget": 1"#);
    eprintln!(
        "floor under an attachment: visibility {cast:.4} (default), {coarse:.4} (coarse_only), {over:.4} (over the budget)"
    );
    assert!(cast_max < 0.1, "the attachment casts no shadow by default: visibility up to {cast_max} under it");
    assert!(warnings.is_empty() && coarse_warnings.is_empty(), "{warnings:?} {coarse_warnings:?}");
    assert!(coarse > 0.95, "coarse_only still draws the attachment: visibility {coarse}");
    assert!(over > 0.95, "over the budget the attachment still casts: visibility {over}");
    assert!(
        over_warnings.iter().any(|w| w.contains("2 triangles") && w.contains("detail_triangle_budget (1)")),
        "{over_warnings:?}"
    );
}

/// The standard normal CDF (Abramowitz and Stegun 7.1.26, error under 1.5e-7).
fn normal_cdf(x: f32) -> f32 {
    let z = (x.abs() / std::f32::consts::SQRT_2) as f64;
    let t = 1.0 / (1.0 + 0.3275911 * z);
    let poly = t * (0.254829592 + t * (-0.284496736 + t * (1.421413741 + t * (-1.453152027 + t * 1.061405429))));
    let erf = 1.0 - poly * (-z * z).exp();
    (0.5 * (1.0 + x.signum() as f64 * erf)) as f32
}

/// The floor under the edge of a half-plane occluder (x < 0, height 0.5), lit by one light
/// straight down (a cap symmetric about the zenith: one median-cut region whose centroid is
/// the zenith) with pure Chebyshev (no bleed reduction, bias or normal offset) and `jitter`:
/// per floor pixel within 3 sigma of the edge, (x, VIS), and the tile's sigma in world units
/// and in texels.
fn half_plane_penumbra(jitter: f32) -> (Vec<(f32, f32)>, f32, f32) {
    let out = out_dir(&format!("shadow_lit_fraction_{jitter}"));
    let probe = probe(&out, 20.0);
    let scene = r#""floor": (kind: "Primitive", params: { "shape": "plane", "size": 4.0, "segments_u": 1, "segments_v": 1 }),
        "floor_draw": (kind: "Draw"),
        "board": (kind: "Primitive", params: { "shape": "plane", "size": 2.0, "segments_u": 1, "segments_v": 1 }),
        "board_draw": (kind: "Draw", params: { "translate": [-1.0, 0.5, 0.0] }),
        "all": (kind: "Merge"),"#;
    let links = r#"("floor.mesh", "floor_draw.mesh"), ("m.material", "floor_draw.material"), ("floor_draw.scene", "all.a"),
        ("board.mesh", "board_draw.mesh"), ("m.material", "board_draw.material"), ("board_draw.scene", "all.b"),"#;
    let atlas = format!(r#""bleed_reduction": 0.0, "depth_bias": 0.0, "normal_offset": 0.0, "jitter": {jitter:?}"#);
    let s = Setup {
        scene,
        links,
        // Low, from +x: the floor under the board's edge is in view.
        camera: r#""distance": 3.0, "pitch": 4.0, "yaw": 90.0, "fov": 40.0, "target": [0.0, 0.0, 0.0]"#,
        probe: &probe,
        lights: 1,
        atlas: &atlas,
        hybrid: "",
        reference: None,
    };
    let ev = run_graph(&graph(&s), 160, 120);
    let atlas = match ev.output("atlas", "shadows") {
        Some(Value::ShadowAtlas(a)) => a.clone(),
        _ => panic!("no shadow atlas"),
    };
    let light = &atlas.lights[0];
    assert!(light.direction.angle_between(Vec3::Y) < 1e-3, "the light is not straight up: {}", light.direction);
    let sigma = light.sigma * atlas.texel_world;
    assert!(sigma > 0.05, "the blur is too narrow to measure a penumbra: sigma {sigma}");
    let (pos, vis) = (world_positions(&ev, 0), visibility(&ev));
    let picked: Vec<(f32, f32)> = pos
        .iter()
        .zip(&vis)
        .filter_map(|(p, v)| p.map(|p| (p, *v)))
        .filter(|(p, _)| p.y.abs() < 1e-3 && p.z.abs() < 0.4 && p.x.abs() < 3.0 * sigma)
        .map(|(p, v)| (p.x, v))
        .collect();
    let side = |lit: bool| picked.iter().filter(|(x, _)| x.abs() > 0.3 * sigma && (*x > 0.0) == lit).count();
    assert!(
        picked.len() > 200 && side(false) > 20 && side(true) > 20,
        "too few penumbra pixels: {} ({} in shadow, {} lit)",
        picked.len(),
        side(false),
        side(true)
    );
    (picked, sigma, light.sigma)
}

/// The largest |VIS - Phi(x / sigma)| over `pixels`.
fn worst_against_phi(pixels: &[(f32, f32)], sigma: f32) -> f32 {
    pixels.iter().map(|(x, v)| (v - normal_cdf(x / sigma)).abs()).fold(0.0, f32::max)
}

#[test]
fn after_the_blur_a_planar_occluder_gives_the_lit_fraction_of_the_area_light() {
    // With two depths under the kernel, the blurred moments give p_max = 1 - a exactly, a the
    // occluded fraction of the kernel: along x the lit fraction is the Gaussian CDF
    // Phi(x / sigma) of the tile's blur.
    let (pixels, sigma, sigma_texels) = half_plane_penumbra(0.0);
    let worst = worst_against_phi(&pixels, sigma);
    eprintln!("sigma {sigma:.4} (world), {sigma_texels} texels; {} pixels; worst |VIS - Phi| {worst:.4}", pixels.len());
    // Rasterizing the edge at texel centres shifts it by up to half a texel: Phi's slope times
    // that (about 0.04 at this sigma of 5 texels), plus half-float moments. (Uncentred
    // moments, before shaders/ibl/vsm.wgsl centred them, gave 0.05 here.)
    let tol = 0.4 * 0.5 / sigma_texels + 0.005;
    assert!(worst <= tol, "VIS departs from the lit fraction by {worst} (tolerance {tol})");
}

#[test]
fn the_jittered_lookup_is_deterministic_and_moves_each_pixel_at_most_its_radius() {
    // Fig. 4.13: each pixel's lookup moves by up to `jitter` texels per axis, so its VIS is the
    // lit fraction at a point at most that far away (Phi's slope times the distance), and the
    // 4x4 pattern is a fixed function of the pixel: the same image twice.
    let jitter = 1.5;
    let (plain, sigma, sigma_texels) = half_plane_penumbra(0.0);
    let (jittered, _, _) = half_plane_penumbra(jitter);
    assert_eq!(jittered, half_plane_penumbra(jitter).0, "the jittered lookup is not deterministic");
    assert_eq!(plain.len(), jittered.len());
    let worst = worst_against_phi(&jittered, sigma);
    let tol = 0.4 * (0.5 + jitter * std::f32::consts::SQRT_2) / sigma_texels + 0.005;
    eprintln!("jitter {jitter}: worst |VIS - Phi| {worst:.4} (tolerance {tol:.4})");
    assert!(worst <= tol, "a jittered lookup lands farther than its radius: {worst} (tolerance {tol})");
    let moved = plain.iter().zip(&jittered).filter(|(a, b)| (a.1 - b.1).abs() > 0.01).count();
    assert!(moved > plain.len() / 4, "the jitter moves only {moved} of {} penumbra pixels", plain.len());
}

fn white_items(meshes: &[(Arc<werkstatt::mesh::Mesh>, Mat4)]) -> Vec<DrawItem> {
    let material = Arc::new(Material::default());
    meshes.iter().map(|(m, model)| DrawItem::plain(m.clone(), material.clone(), *model)).collect()
}

fn light(direction: Vec3) -> RegionLight {
    RegionLight { direction, color: Vec3::ONE, solid_angle: 0.1, energy: 1.0, texels: 1 }
}

#[test]
fn atlas_tiles_do_not_overlap_and_no_blur_reads_another_tile() {
    let gpu = gpu();
    let mut builder = AtlasBuilder::default();
    // A synthetic grid of 5 tiles of 16 texels, 3 columns: tile 0 far (centred depth 0.5:
    // (0.5, 0.25)), tiles 1..5 dark (0, 0) but for a bright (0.25) texel column at their left
    // edge (next to tile 0 or 3).
    let (t, columns) = (16u32, 3u32);
    let (w, h) = (columns * t, 2 * t);
    let mut texels = vec![[0.0f32; 4]; (w * h) as usize];
    for y in 0..h {
        for x in 0..w {
            let j = (y / t) * columns + x / t;
            let v = if j == 0 || j >= 5 {
                0.5
            } else if x % t == 0 {
                0.25
            } else {
                0.0
            };
            texels[(y * w + x) as usize] = [v, v * v, 0.0, 0.0];
        }
    }
    let src = GpuImage::upload(gpu, "tiles", w, h, wgpu::TextureFormat::Rgba32Float, 16, bytemuck::cast_slice(&texels));
    let tiles: Vec<([u32; 4], f32)> = (0..5).map(|j| ([(j % columns) * t, (j / columns) * t, t, t], 5.0)).collect();
    let out = read_back(gpu, &builder.blur(gpu, &src, &tiles).unwrap()).unwrap();
    for y in 0..h {
        for x in 0..w {
            let j = (y / t) * columns + x / t;
            let i = (y * w + x) as usize * 4;
            let (m1, m2) = (out.rgba[i], out.rgba[i + 1]);
            match j {
                // Far tiles (and the empty slot) stay exactly far.
                0 | 5 => assert!(m1 == 0.5 && m2 == 0.25, "tile {j} texel ({x}, {y}): ({m1}, {m2})"),
                // Dark tiles only ever see their own bright column, so they stay below 0.25 and
                // their right halves (> 3 sigma from it) stay exactly dark.
                _ => {
                    assert!(m1 <= 0.25, "tile {j} texel ({x}, {y}) read another tile: {m1}");
                    if x % t >= 16 {
                        assert_eq!(m1, 0.0);
                    }
                }
            }
        }
    }
    // A real atlas: a floor lit from above and exactly edge-on, one light per tile.
    let floor = Arc::new(werkstatt::nodes::mesh::geometry::plane(4.0, 1, 1).unwrap());
    let items = white_items(&[(floor, Mat4::IDENTITY)]);
    let lights = Lights {
        lights: vec![light(Vec3::Y), light(Vec3::X), light(Vec3::new(0.0, 1.0, 1.0).normalize()), light(Vec3::Z)],
        regions: None,
        preview: None,
    };
    let settings = AtlasSettings {
        tile_size: 32,
        guard: None,
        coarse_only: true,
        blur_scale: 1.0,
        sizes: TileSizes::Uniform,
        fit_view: None,
    };
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
        assert!(tile_values(k).iter().all(|&(m1, m2)| m1 == 0.5 && m2 == 0.25), "edge-on tile {k} is not all far");
    }
    for k in [0, 2] {
        let dark = tile_values(k).iter().filter(|(m1, _)| *m1 < 0.4).count();
        assert!(dark > 100, "tile {k} shows no floor ({dark} texels)");
    }
    // The floor seen from straight above lies at mid depth (0.5: centred, 0).
    let (m1, _) = tile_values(0)[(16 * 32 + 16) as usize];
    assert!(m1.abs() < 2e-3, "mid depth {m1}");
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

/// MSEs against the ray-traced reference on the spheres scene with `lights` lights and the
/// atlas parameters `atlas` (RON): (global, local, hybrid), and the reference. `reference`
/// reuses one traced before (the scene and camera do not change with the lights).
/// `SHADOW_ATLAS` replaces `atlas`, for exploring.
fn spheres_errors(
    probe: &Path,
    lights: usize,
    size: (u32, u32),
    atlas: &str,
    reference: Option<Vec<f32>>,
) -> ((f64, f64, f64), Vec<f32>) {
    let atlas = std::env::var("SHADOW_ATLAS").unwrap_or(atlas.to_string());
    let s = Setup {
        scene: SPHERES,
        links: SPHERE_LINKS,
        camera: r#""distance": 3.2, "pitch": 35.0, "yaw": 20.0, "fov": 40.0, "target": [0.0, 0.1, 0.05]"#,
        probe,
        lights,
        atlas: &atlas,
        hybrid: "",
        reference: reference.is_none().then_some(r#""samples": 128, "max_distance": 10.0"#),
    };
    let t = Instant::now();
    let ev = run_graph(&graph(&s), size.0, size.1);
    let pos = world_positions(&ev, 0);
    let global = visibility(&ev);
    let local = channel0(&ev, "ssao", "occlusion");
    let reference = reference.unwrap_or_else(|| channel0(&ev, "reference", "occlusion"));
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
    (errors, reference)
}

#[test]
fn hybrid_occlusion_is_closer_to_the_ray_traced_reference_than_either_part() {
    // The dissertation's regime: deliberately low-resolution shadow maps (32^2 tiles), whose
    // blur loses the contact shadows that the local pass restores. (With 128^2 tiles the
    // global part alone resolves the contacts and the local part over-occludes them: hybrid
    // 0.0050 against global 0.0046; docs/occlusion.md.)
    let out = out_dir("shadow_spheres");
    let probe = probe(&out, 180.0);
    let size = (160, 120);
    let low_res = r#""tile_size": 32"#;
    let ((global, local, hybrid), _) = spheres_errors(&probe, 128, size, low_res, None);
    eprintln!(
        "hybrid MSE is {:.0}% below global's and {:.0}% below SSAO's",
        100.0 * (1.0 - hybrid / global),
        100.0 * (1.0 - hybrid / local)
    );
    assert!(hybrid <= 0.7 * global, "hybrid {hybrid} is not 30% below global {global}");
    assert!(hybrid <= 0.7 * local, "hybrid {hybrid} is not 30% below SSAO {local}");
    // The dissertation's second claim (hybrid at 128 lights no worse than global-only at 512)
    // needs a 512-light run, half a minute on lavapipe: measured in docs/occlusion.md (hybrid
    // 0.0120 at 128 against global 0.0107 at 512: close, not met), not repeated in every CI run.
}

/// Figs. 5.24, 5.26 and 5.27 at a small size and with fewer lights than the graphs (128, 64
/// and 512: a minute on lavapipe), every output of each: the whole chain (atlas, jittered
/// lookup, bleeding reduction, SSAO, hybrid) is guarded picture by picture. (Fig. 5.25's
/// graph is measured against its ray-traced reference in ssao.rs.)
#[test]
fn occlusion_figure_graphs_match_their_goldens() {
    let out = out_dir("occlusion-figures");
    let figures: [(&str, &str, &[&str]); 3] = [
        ("fig5_24_shadows", "524", &["combined_image", "global_image", "local_image"]),
        ("fig5_26_bleeding", "526", &["leaky_image", "global_image", "combined_image"]),
        ("fig5_27_garment_occlusion", "527", &["none_image", "local_image", "global_image", "image"]),
    ];
    for (graph, short, outputs) in figures {
        let dir = out.join(short);
        render_graph(
            &root().join(format!("graphs/{graph}.ron")),
            &dir,
            (0, 0),
            (64, 48),
            &["median_cut.count=16"],
            &[],
        )
        .unwrap();
        for name in outputs.iter() {
            assert_golden(&format!("fig{short}_{name}"), &read_png(&dir.join(format!("{name}_0000.png"))), STRICT);
        }
    }
}

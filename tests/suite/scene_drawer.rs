//! The scene drawer's depth-only target: one draw fills several tiles of one depth texture,
//! each with its own view, plain meshes and warped attachments alike, and matches the depth
//! the G-buffer target writes for the same view, texel for texel, without spilling into the
//! neighbouring tile.

use crate::common;

use std::path::PathBuf;
use std::sync::Arc;

use glam::Vec3;
use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime};
use werkstatt::core::graph::Graph;
use werkstatt::core::port::Value;
use werkstatt::core::resources::Resources;
use werkstatt::gpu::read_back;
use werkstatt::render::draw::{SceneDrawer, Tile};
use werkstatt::render::scene::{Camera, DrawItem, View};

/// The scene and camera feeding `gbuffer` in the stickers figure: a flag (plain mesh) with two
/// decals (area attachments, warped through the matrix texture).
fn stickers_scene() -> (Arc<Vec<DrawItem>>, Camera) {
    let path = common::root().join("graphs/fig1e_stickers.ron");
    let graph = Graph::load(&path).unwrap();
    let mut ev = Evaluator::new(&graph, &["gbuffer".to_string()]).unwrap();
    let resources = Resources::new(false);
    let settings =
        FrameSettings { width: 32, height: 32, base_dir: path.parent().map(PathBuf::from).unwrap(), frames: None };
    ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, Some(common::gpu()), &resources, &settings);
    let Some(Value::Scene(scene)) = ev.input("gbuffer", "scene").cloned() else { panic!("no scene") };
    let Some(Value::Camera(camera)) = ev.input("gbuffer", "camera").cloned() else { panic!("no camera") };
    assert!(scene.iter().any(|i| !i.kind.places_mesh()) && scene.iter().any(|i| i.kind.places_mesh()));
    (scene, camera)
}

#[test]
fn depth_tiles_match_the_gbuffer_depth_of_each_view() {
    let gpu = common::gpu();
    let (scene, camera) = stickers_scene();
    let moved = Camera { eye: camera.target + (camera.eye - camera.target).rotate_towards(Vec3::Y, 0.4), ..camera };
    let (tw, th) = (40u32, 48u32);
    // Two tiles side by side and an empty strip on the right that no tile covers.
    let (width, height) = (2 * tw + 8, th);
    let mut drawer = SceneDrawer::default();
    let views = [View::new(&camera, tw, th), View::new(&moved, tw, th)];
    let tiles: Vec<Tile> = views
        .iter()
        .enumerate()
        .map(|(i, v)| Tile { view_proj: v.view_proj, rect: [i as u32 * tw, 0, tw, th] })
        .collect();
    let atlas = drawer.depth_tiles(gpu, &scene, &tiles, width, height).unwrap();
    let references: Vec<_> =
        [camera, moved].iter().zip(&views).map(|(c, v)| drawer.gbuffer(gpu, &scene, *c, *v).unwrap()).collect();
    gpu.submit_checked().unwrap();
    let atlas = read_back(gpu, &atlas).unwrap();
    let texel = |x: u32, y: u32| atlas.rgba[4 * (y * width + x) as usize];
    for (t, reference) in references.iter().enumerate() {
        let reference = read_back(gpu, &reference.depth_buffer).unwrap();
        let mut covered = 0;
        for y in 0..th {
            for x in 0..tw {
                let expected = reference.rgba[4 * (y * tw + x) as usize];
                let got = texel(t as u32 * tw + x, y);
                assert!((got - expected).abs() < 1e-5, "tile {t} texel ({x}, {y}): {got} against {expected}");
                covered += usize::from(expected < 1.0);
            }
        }
        assert!(covered > (tw * th / 10) as usize, "tile {t}: only {covered} texels show the scene");
    }
    for y in 0..th {
        for x in 2 * tw..width {
            assert_eq!(texel(x, y), 1.0, "texel ({x}, {y}) outside every tile was written");
        }
    }
}

#[test]
fn depth_tiles_refuse_bad_layouts() {
    let gpu = common::gpu();
    let (scene, camera) = stickers_scene();
    let view = View::new(&camera, 16, 16);
    let mut drawer = SceneDrawer::default();
    let outside = [Tile { view_proj: view.view_proj, rect: [8, 0, 16, 16] }];
    let error = |tiles: &[Tile], drawer: &mut SceneDrawer| match drawer.depth_tiles(gpu, &scene, tiles, 16, 16) {
        Ok(_) => panic!("{tiles:?} accepted"),
        Err(e) => e.to_string(),
    };
    let e = error(&outside, &mut drawer);
    assert!(e.contains("outside"), "{e}");
    let e = error(&[], &mut drawer);
    assert!(e.contains("1 to 64 tiles"), "{e}");
}

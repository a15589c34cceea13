//! USD caches in MeshSequence (src/io/usd.rs, usdc.rs, usda.rs): Blender's binary and text
//! exports of the cloth simulation of tests/data/alembic read back against Blender's OBJ
//! export of it, several Mesh prims as pieces, changing topology, playback through the node,
//! bounded memory, and damaged files.

use std::path::{Path, PathBuf};

use werkstatt::core::eval::NodeStatus;
use werkstatt::core::resources::Resources;
use werkstatt::mesh::Mesh;
use werkstatt::nodes::mesh::mesh_sequence::{index_path, load_cache_frame, load_index};

use crate::alembic::{cache_frames, differences, obj_frame, plays_a_changing_topology};
use crate::common;
use crate::mesh_sequence::{sequence_graph, settle, surface, temp_dir};

fn data() -> PathBuf {
    common::root().join("tests/data/usd")
}

/// Blender's default .usdc (Z up, the cloth's placement as Xform ops above the mesh,
/// face-varying UVs and normals): frames 1-8 at 24 fps, each equal to the OBJ frame.
#[test]
fn the_binary_cloth_cache_equals_the_obj_sequence_vertex_by_vertex() {
    let index = load_index(&index_path(&data().join("cloth.usdc"), "Cloth")).unwrap();
    assert_eq!(index.fps, Some(24.0));
    assert!(index.cache, "frames load one at a time");
    let frames = cache_frames(&data().join("cloth.usdc"), "Cloth");
    assert_eq!(frames.iter().map(|(n, _)| *n).collect::<Vec<_>>(), (1..=8).collect::<Vec<_>>());
    for (n, usd) in &frames {
        assert_eq!((usd.positions.len(), usd.triangle_count()), (289, 512));
        let [dp, duv, dn] = differences(usd, &obj_frame(*n));
        // The OBJ holds six decimals for positions and UVs, four for normals.
        assert!(dp < 2e-6 && duv < 2e-6 && dn < 2e-4, "frame {n}: positions {dp}, UVs {duv}, normals {dn}");
    }
    let low = |m: &Mesh| m.positions.iter().map(|p| p.y).fold(f32::MAX, f32::min);
    assert!(low(&frames[7].1) < low(&frames[0].1) - 0.1, "the cloth falls");
}

/// The text export, turned to Y up by a rotation on the root prim, without normals: the same
/// positions and UVs; normals made from the faces point the OBJ's way.
#[test]
fn the_text_cloth_cache_equals_the_obj_sequence() {
    let index = load_index(&index_path(&data().join("cloth.usda"), "")).unwrap();
    assert_eq!(index.fps, Some(24.0));
    assert!(index.cache, "frames load one at a time, as a binary cache's do");
    for (n, usd) in cache_frames(&data().join("cloth.usda"), "") {
        let obj = obj_frame(n);
        let [dp, duv, _] = differences(&usd, &obj);
        assert!(dp < 2e-6 && duv < 2e-6, "frame {n}: positions {dp}, UVs {duv}");
        let agree = usd.normals.iter().zip(&obj.normals).filter(|(a, b)| a.dot(**b) > 0.9).count();
        assert!(agree > 280, "frame {n}: {agree} of 289 normals agree");
    }
}

/// Every Mesh prim is a piece (path order: the cloth, then the sphere); the sphere is constant
/// and its faces turn outward.
#[test]
fn the_mesh_prims_of_a_file_are_pieces() {
    let all = cache_frames(&data().join("cloth.usdc"), "");
    let cloth = &cache_frames(&data().join("cloth.usdc"), "/root/Cloth/Grid")[0].1;
    let sphere = &cache_frames(&data().join("cloth.usdc"), "Collider")[0].1;
    let mesh = &all[0].1;
    assert_eq!(mesh.positions.len(), cloth.positions.len() + sphere.positions.len());
    let pieces: std::collections::BTreeSet<u32> = mesh.piece_ids.iter().copied().collect();
    assert_eq!(pieces.into_iter().collect::<Vec<_>>(), vec![0, 1]);
    assert_eq!(mesh.piece_ids[0], 0);
    assert!(mesh.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4));
    let centre = sphere.positions.iter().copied().sum::<glam::Vec3>() / sphere.positions.len() as f32;
    assert!(sphere.positions.iter().zip(&sphere.normals).all(|(p, n)| (*p - centre).dot(*n) > 0.0));
    let t = &sphere.indices;
    let (a, b, c) = (sphere.positions[t[0] as usize], sphere.positions[t[1] as usize], sphere.positions[t[2] as usize]);
    assert!((b - a).cross(c - a).dot(a - centre) > 0.0, "the sphere's triangles wind clockwise seen from outside");
    let sphere_of =
        |m: &Mesh| m.positions.iter().zip(&m.piece_ids).filter(|(_, p)| **p == 1).map(|(v, _)| *v).collect::<Vec<_>>();
    assert_eq!(sphere_of(mesh), sphere_of(&all.last().unwrap().1), "the sphere stays");
}

#[test]
fn a_changing_topology_plays_frame_by_frame() {
    plays_a_changing_topology(&data().join("build.usdc"));
}

/// Through the node at 30 fps: render frame f shows cache frame 1 + 0.8 f, held or blended;
/// a long loop holds a few frames only.
#[test]
fn the_node_plays_a_binary_cache_with_bounded_memory() {
    let usdc = data().join("cloth.usdc");
    let res = Resources::new(false);
    let mut held = sequence_graph(&usdc, r#""object": "Cloth", "interpolate": false"#);
    for (f, frame) in [(0, 1), (2, 2), (5, 5), (20, 8)] {
        assert_eq!(settle(&mut held, &res, f), NodeStatus::Ok);
        assert!(
            differences(&surface(&held), &obj_frame(frame))[0] < 2e-6,
            "render frame {f} holds cache frame {frame}"
        );
    }
    let res = Resources::new(false);
    let mut looped = sequence_graph(&usdc, r#""object": "Cloth", "mode": "loop""#);
    let mut most = 0;
    for f in 0..30 {
        assert_eq!(settle(&mut looped, &res, f), NodeStatus::Ok);
        most = most.max(res.resident());
    }
    assert!(most <= 5, "{most} resources held while playing 8 frames in a loop");
}

#[test]
fn unknown_meshes_and_files_without_uvs_are_errors_naming_the_file() {
    let e = format!("{:#}", load_index(&index_path(&data().join("cloth.usdc"), "Shirt")).unwrap_err());
    assert!(e.contains("cloth.usdc") && e.contains("no mesh named \"Shirt\"") && e.contains("/root/Cloth/Grid"), "{e}");
    let dir = temp_dir("usd-no-uv");
    let file = dir.join("plain.usda");
    std::fs::write(
        &file,
        "#usda 1.0\ndef Mesh \"m\" {\n    int[] faceVertexCounts = [3]\n    int[] faceVertexIndices = [0, 1, 2]\n    point3f[] points = [(0, 0, 0), (1, 0, 0), (0, 1, 0)]\n}\n",
    )
    .unwrap();
    let e = format!("{:#}", load_index(&index_path(&file, "")).unwrap_err());
    assert!(e.contains("plain.usda") && e.contains("no UVs"), "{e}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// Truncations at many lengths and bytes overwritten at many places (more where the structure
/// sits: a crate file's header and its tables at the end): each load is an error naming the
/// file, or a result, never a panic.
fn damaged_files_are_errors_naming_the_file(name: &str) {
    let original = std::fs::read(data().join(name)).unwrap();
    let dir = temp_dir(&format!("usd-fuzz-{name}"));
    let path = dir.join(format!("damaged.{}", Path::new(name).extension().unwrap().to_str().unwrap()));
    let cases = common::damaged_container(&original);
    let (mut failed, mut read) = (0, 0);
    for (case, bytes) in cases.iter().enumerate() {
        std::fs::write(&path, bytes).unwrap();
        let outcome = load_index(&index_path(&path, "")).and_then(|index| {
            for (_, label) in index.frames.iter().take(2).chain(index.frames.last()) {
                load_cache_frame(label)?;
            }
            Ok(())
        });
        match outcome {
            Ok(()) => read += 1,
            Err(e) => {
                let e = format!("{e:#}");
                assert!(
                    e.contains(path.file_name().unwrap().to_str().unwrap()),
                    "case {case}: the error does not name the file: {e}"
                );
                failed += 1;
            }
        }
    }
    assert!(failed > 100 && read > 0, "{failed} errors, {read} read");
    std::fs::remove_dir_all(dir).unwrap();
}

#[test]
fn damaged_binary_caches_are_errors_naming_the_file() {
    damaged_files_are_errors_naming_the_file("cloth.usdc");
}

#[test]
fn damaged_text_caches_are_errors_naming_the_file() {
    damaged_files_are_errors_naming_the_file("cloth.usda");
}

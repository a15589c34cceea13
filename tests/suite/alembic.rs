//! Alembic caches in MeshSequence (src/io/alembic.rs): a Blender cloth cache read back against
//! Blender's OBJ export of the same simulation, time sampling to frames, changing topology,
//! several objects, bounded memory, and damaged files.

use std::path::{Path, PathBuf};

use werkstatt::core::eval::NodeStatus;
use werkstatt::core::resources::Resources;
use werkstatt::mesh::Mesh;
use werkstatt::nodes::mesh::mesh_sequence::{blend, index_path, load_cache_frame, load_frame, load_index};

use crate::common;
use crate::mesh_sequence::{sequence_graph, settle, surface, temp_dir};

fn data() -> PathBuf {
    common::root().join("tests/data/alembic")
}

/// The frames of `object` in a cache `file` (Alembic or USD): (frame number, mesh), through the
/// sequence index.
pub fn cache_frames(file: &Path, object: &str) -> Vec<(i64, Mesh)> {
    let index = load_index(&index_path(file, object)).unwrap_or_else(|e| panic!("{e:#}"));
    index
        .frames
        .iter()
        .map(|(n, label)| (*n, (*load_cache_frame(label).unwrap_or_else(|e| panic!("{e:#}")).mesh).clone()))
        .collect()
}

/// Blender's OBJ export of the fixtures' cloth simulation, frame `n`.
pub fn obj_frame(n: i64) -> Mesh {
    let path = data().join(format!("cloth_obj/cloth{n:04}.obj"));
    (*load_frame(&path).unwrap_or_else(|e| panic!("{e:#}")).mesh).clone()
}

/// The largest difference between two meshes' positions, UVs and normals; their triangles
/// must be the same.
pub fn differences(a: &Mesh, b: &Mesh) -> [f32; 3] {
    assert_eq!(a.positions.len(), b.positions.len(), "vertex counts");
    assert_eq!(a.indices, b.indices, "triangles");
    let most = |d: Vec<f32>| d.into_iter().fold(0.0f32, f32::max);
    [
        most(a.positions.iter().zip(&b.positions).map(|(p, q)| p.distance(*q)).collect()),
        most(a.uvs.iter().zip(&b.uvs).map(|(p, q)| p.distance(*q)).collect()),
        most(a.normals.iter().zip(&b.normals).map(|(p, q)| p.distance(*q)).collect()),
    ]
}

#[test]
fn the_cloth_cache_equals_the_obj_sequence_vertex_by_vertex() {
    let index = load_index(&index_path(&data().join("cloth.abc"), "Cloth")).unwrap();
    // Blender wrote frames 1..8 at 24 fps: samples at 1/24 s, 2/24 s, ...
    assert_eq!(index.fps, Some(24.0));
    let frames = cache_frames(&data().join("cloth.abc"), "Cloth");
    assert_eq!(frames.iter().map(|(n, _)| *n).collect::<Vec<_>>(), (1..=8).collect::<Vec<_>>());
    for (n, abc) in &frames {
        let obj = obj_frame(*n);
        // 17 x 17 vertices, 256 quads: no seams on a grid.
        assert_eq!(abc.positions.len(), 289);
        assert_eq!(abc.triangle_count(), 512);
        let [dp, duv, dn] = differences(abc, &obj);
        // The OBJ holds six decimals for positions and UVs, four for normals.
        assert!(dp < 2e-6 && duv < 2e-6 && dn < 2e-4, "frame {n}: positions {dp}, UVs {duv}, normals {dn}");
    }
    // The cloth falls: the last frame is lower, and differs from the first.
    let low = |m: &Mesh| m.positions.iter().map(|p| p.y).fold(f32::MAX, f32::min);
    assert!(low(&frames[7].1) < low(&frames[0].1) - 0.1);
}

#[test]
fn the_meshes_of_a_file_are_pieces_with_uvs_and_normals() {
    let all = cache_frames(&data().join("cloth.abc"), "");
    let (cloth, sphere) = (
        &cache_frames(&data().join("cloth.abc"), "/Cloth/Grid")[0].1,
        &cache_frames(&data().join("cloth.abc"), "Collider")[0].1,
    );
    let mesh = &all[0].1;
    assert_eq!(mesh.positions.len(), cloth.positions.len() + sphere.positions.len());
    // Two pieces in file order (the collider first), each with its UVs and normals.
    let pieces: std::collections::BTreeSet<u32> = mesh.piece_ids.iter().copied().collect();
    assert_eq!(pieces.into_iter().collect::<Vec<_>>(), vec![0, 1]);
    assert_eq!(mesh.uvs.len(), mesh.positions.len());
    assert!(mesh.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-4));
    assert!(mesh.uvs.iter().all(|uv| (0.0..=1.0).contains(&uv.x) && (0.0..=1.0).contains(&uv.y)));
    // The sphere is constant; its normals point outward (faces turned counter-clockwise).
    let centre = sphere.positions.iter().copied().sum::<glam::Vec3>() / sphere.positions.len() as f32;
    assert!(sphere.positions.iter().zip(&sphere.normals).all(|(p, n)| (*p - centre).dot(*n) > 0.0));
    let t = &sphere.indices;
    let (a, b, c) = (sphere.positions[t[0] as usize], sphere.positions[t[1] as usize], sphere.positions[t[2] as usize]);
    assert!((b - a).cross(c - a).dot(a - centre) > 0.0, "the sphere's triangles wind clockwise seen from outside");
    let last = &all.last().unwrap().1;
    let sphere_vertices =
        |m: &Mesh| m.positions.iter().zip(&m.piece_ids).filter(|(_, p)| **p == 0).map(|(v, _)| *v).collect::<Vec<_>>();
    assert_eq!(sphere_vertices(mesh), sphere_vertices(last));
}

#[test]
fn frames_between_samples_hold_or_interpolate() {
    let abc = data().join("cloth.abc");
    let res = Resources::new(false);
    let obj = |n| obj_frame(n);
    // The render runs at 30 fps, the cache at 24: render frame f shows cache frame 1 + f * 0.8.
    let mut held = sequence_graph(&abc, r#""object": "Cloth", "interpolate": false"#);
    let mut blended = sequence_graph(&abc, r#""object": "Cloth""#);
    for (f, before, after, w) in [(0, 1, 2, 0.0), (2, 2, 3, 0.6), (5, 5, 6, 0.0), (7, 6, 7, 0.6), (20, 8, 8, 0.0)] {
        assert_eq!(settle(&mut held, &res, f), NodeStatus::Ok);
        assert_eq!(settle(&mut blended, &res, f), NodeStatus::Ok);
        assert!(differences(&surface(&held), &obj(before))[0] < 2e-6, "render frame {f} holds cache frame {before}");
        let expected = blend(&obj(before), &obj(after), w as f32);
        assert!(differences(&surface(&blended), &expected)[0] < 2e-6, "render frame {f} blends {before} and {after}");
    }
}

#[test]
fn a_changing_topology_plays_frame_by_frame() {
    plays_a_changing_topology(&data().join("build.abc"));
}

/// Blender's Build modifier adding the grid's 16 faces over frames 1..5, cached as `file`:
/// the frames grow, and between two frames of different topology the earlier one shows, not a
/// blend or an error.
pub fn plays_a_changing_topology(file: &Path) {
    let frames = cache_frames(file, "");
    let triangles: Vec<usize> = frames.iter().map(|(_, m)| m.triangle_count()).collect();
    assert_eq!(frames.len(), 5);
    assert!(triangles.windows(2).all(|w| w[0] < w[1]), "{triangles:?}");
    assert_eq!(*triangles.last().unwrap(), 32);
    let res = Resources::new(false);
    let mut ev = sequence_graph(file, "");
    for f in 0..8 {
        assert_eq!(settle(&mut ev, &res, f), NodeStatus::Ok);
        let at = ((f as f64 * 0.8).floor() as usize).min(4);
        assert_eq!(surface(&ev).triangle_count(), triangles[at], "render frame {f}");
    }
}

#[test]
fn memory_stays_bounded_while_playing_a_cache() {
    let res = Resources::new(false);
    let mut ev = sequence_graph(&data().join("cloth.abc"), r#""object": "Cloth", "mode": "loop""#);
    let mut most = 0;
    for f in 0..30 {
        assert_eq!(settle(&mut ev, &res, f), NodeStatus::Ok);
        most = most.max(res.resident());
    }
    // The index, the two frames around the time, the prefetched next one, one still loading.
    assert!(most <= 5, "{most} resources held while playing 8 frames in a loop");
}

#[test]
fn unknown_objects_and_other_files_are_errors_naming_the_file() {
    let abc = data().join("cloth.abc");
    let e = format!("{:#}", load_index(&index_path(&abc, "Shirt")).unwrap_err());
    assert!(e.contains("cloth.abc") && e.contains("no mesh named \"Shirt\"") && e.contains("/Cloth/Grid"), "{e}");
    let e = format!(
        "{:#}",
        load_index(&index_path(&data().join("cloth_obj/cloth0001.obj").with_extension("abc"), "")).unwrap_err()
    );
    assert!(e.contains("cloth0001.abc"), "{e}");
    let dir = temp_dir("abc-not-ogawa");
    let fake = dir.join("hdf5.abc");
    std::fs::write(&fake, b"\x89HDF\r\n\x1a\n and more bytes than sixteen").unwrap();
    let e = format!("{:#}", load_index(&index_path(&fake, "")).unwrap_err());
    assert!(e.contains("hdf5.abc") && e.contains("Ogawa"), "{e}");
    std::fs::remove_dir_all(dir).unwrap();
}

/// Truncations at many lengths and bytes overwritten at many places: each load is an error
/// naming the file or a mesh, never a crash (nor one caught inside the reader).
#[test]
fn damaged_caches_are_errors_naming_the_file() {
    let original = std::fs::read(data().join("cloth.abc")).unwrap();
    let dir = temp_dir("abc-fuzz");
    let path = dir.join("damaged.abc");
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
                assert!(e.contains("damaged.abc"), "case {case}: the error does not name the file: {e}");
                assert!(!e.contains("the Alembic reader failed"), "case {case}: the reader crashed: {e}");
                failed += 1;
            }
        }
    }
    assert!(failed > 100 && read > 0, "{failed} errors, {read} read");
    std::fs::remove_dir_all(dir).unwrap();
}

/// Plays a whole sequence (every frame once, not interpolated) through MeshSequence: the load
/// time and peak memory in docs/formats.md. A measurement, not a test:
/// `WERKSTATT_SEQUENCE_BENCH=/tmp/big.abc WERKSTATT_SEQUENCE_OBJECT=Cloth /usr/bin/time -v target/debug/deps/suite-* --ignored --exact alembic::play_a_whole_sequence --nocapture`
#[test]
#[ignore = "a measurement; set WERKSTATT_SEQUENCE_BENCH to a cache or OBJ sequence"]
fn play_a_whole_sequence() {
    let Ok(path) = std::env::var("WERKSTATT_SEQUENCE_BENCH") else { return };
    // An .abc cache's mesh (WERKSTATT_SEQUENCE_OBJECT; default: all of them).
    let object = std::env::var("WERKSTATT_SEQUENCE_OBJECT").unwrap_or_default();
    let start = std::time::Instant::now();
    let res = Resources::new(false);
    let mut ev = sequence_graph(Path::new(&path), &format!(r#""interpolate": false, "object": {object:?}"#));
    let frames = load_index(&index_path(Path::new(&path), &object)).unwrap().frames.len();
    // settle renders at 30 fps; the caches here run at 24: every render frame 0.8 cache frames on.
    let mut vertices = 0;
    for f in 0..=(frames as i64 * 5 / 4) {
        assert_eq!(settle(&mut ev, &res, f), NodeStatus::Ok);
        vertices = vertices.max(surface(&ev).positions.len());
    }
    println!("{path}: {frames} frames of {vertices} vertices in {:.2} s", start.elapsed().as_secs_f64());
}

static PART_LOADS: std::sync::atomic::AtomicUsize = std::sync::atomic::AtomicUsize::new(0);

/// A frame of a cache is a resource `file|part`: it reloads when its file changes, and a
/// missing file is named as such (not the label).
#[test]
fn file_parts_reload_with_their_file_and_name_it_when_missing() {
    use werkstatt::core::resources::{part_path, split_part};
    let dir = temp_dir("abc-parts");
    let file = dir.join("cache.abc");
    std::fs::write(&file, b"x").unwrap();
    let part = part_path(&file, "frame=3,object=%2FCloth");
    assert_eq!(split_part(&part), (file.as_path(), Some("frame=3,object=%2FCloth")));
    let load = |p: &Path| -> anyhow::Result<usize> {
        PART_LOADS.fetch_add(1, std::sync::atomic::Ordering::SeqCst);
        std::fs::read(split_part(p).0)?;
        Ok(1)
    };
    let res = Resources::new(false);
    let _ = res.request(&part, load);
    common::wait_idle(&res);
    res.reload(&file);
    common::wait_idle(&res);
    assert_eq!(PART_LOADS.load(std::sync::atomic::Ordering::SeqCst), 2, "the part reloads with its file");
    std::fs::remove_file(&file).unwrap();
    res.reload(&file);
    common::wait_idle(&res);
    let e = res.request(&part, load).1.unwrap_err().to_string();
    assert_eq!(e, format!("no such file: {}", file.display()));
    // Through MeshSequence.
    let mut ev = sequence_graph(&file, "");
    match settle(&mut ev, &res, 0) {
        NodeStatus::Failed(m) => assert!(m.contains(&format!("no such file: {}", file.display())), "{m}"),
        other => panic!("{other:?}"),
    }
    std::fs::remove_dir_all(dir).unwrap();
}

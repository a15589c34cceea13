//! Draco-compressed glTF (KHR_draco_mesh_compression) through MeshFile's loader
//! (src/mesh.rs, decoded by draco-oxide-decoder): a Blender export against its uncompressed
//! twin, a real-world file of the npm package @pmndrs/assets, and damaged files.

use std::path::PathBuf;

use werkstatt::mesh::{Mesh, load_mesh_file};

use crate::common;
use crate::mesh_sequence::temp_dir;

fn data() -> PathBuf {
    common::root().join("tests/data/draco")
}

fn load(name: &str) -> Mesh {
    load_mesh_file(&data().join(name)).unwrap_or_else(|e| panic!("{e:#}"))
}

/// The same two meshes, compressed and not: the same triangles and pieces, and every vertex
/// of the decoded file is a vertex of the plain one (the decoder may split points; counts differ) to within the quantization (14 bits of the
/// 2 m wide scene for positions, 12 bits for UVs).
#[test]
fn a_draco_file_decodes_to_its_uncompressed_twin() {
    let (draco, plain) = (load("uvs_draco.glb"), load("uvs_plain.glb"));
    assert_eq!(draco.triangle_count(), plain.triangle_count());
    assert_eq!(draco.triangle_count(), (672 + 96) / 3);
    let pieces = |m: &Mesh| m.piece_ids.iter().copied().collect::<std::collections::BTreeSet<u32>>().len();
    assert_eq!((pieces(&draco), pieces(&plain)), (2, 2));
    let (dp, duv) = (2.0 / 16384.0, 1.0 / 4096.0);
    for (p, uv) in draco.positions.iter().zip(&draco.uvs) {
        let near = plain.positions.iter().zip(&plain.uvs).any(|(q, w)| p.distance(*q) <= dp && uv.distance(*w) <= duv);
        assert!(near, "decoded vertex {p} (uv {uv}) is not a vertex of the plain file");
    }
    // Each decoded triangle is a plain triangle, wound the same way (corners in some rotation).
    let corners = |m: &Mesh, t: &[u32]| t.iter().map(|&i| m.positions[i as usize]).collect::<Vec<_>>();
    for t in draco.indices.chunks_exact(3) {
        let a = corners(&draco, t);
        let same = plain.indices.chunks_exact(3).any(|u| {
            let b = corners(&plain, u);
            (0..3).any(|r| (0..3).all(|k| a[k].distance(b[(k + r) % 3]) <= dp))
        });
        assert!(same, "decoded triangle {a:?} is not a triangle of the plain file");
    }
}

/// A GLB of @pmndrs/assets (all three are Draco-compressed and were refused before).
#[test]
fn the_pmndrs_bunny_loads() {
    let bunny = load("bunny.glb");
    assert_eq!(bunny.triangle_count(), 16944 / 3);
    // Draco may split a point where the mesh is not manifold: at least the file's 2826.
    assert!(bunny.positions.len() >= 2826);
    assert!(bunny.normals.iter().all(|n| (n.length() - 1.0).abs() < 1e-3));
}

/// Truncations and overwritten bytes, more of them in the compressed data: each load is an
/// error naming the file, or a mesh, never a panic.
#[test]
fn damaged_draco_files_are_errors_naming_the_file() {
    let original = std::fs::read(data().join("uvs_draco.glb")).unwrap();
    let dir = temp_dir("draco-fuzz");
    let path = dir.join("damaged.glb");
    let n = original.len();
    // The JSON sits at the start, the Draco streams after it.
    let cases = common::damaged_copies(&original, (0..60).map(|k| k * n / 60), |k, r| {
        if k % 4 == 0 { r as usize % n } else { n / 3 + r as usize % (n - n / 3) }
    });
    let (mut failed, mut read) = (0, 0);
    for (case, bytes) in cases.iter().enumerate() {
        std::fs::write(&path, bytes).unwrap();
        match load_mesh_file(&path) {
            Ok(_) => read += 1,
            Err(e) => {
                let e = format!("{e:#}");
                assert!(e.contains("damaged.glb"), "case {case}: the error does not name the file: {e}");
                failed += 1;
            }
        }
    }
    eprintln!("damaged Draco files: {failed} refused, {read} read");
    assert!(failed >= 60, "{failed} errors, {read} read");
    std::fs::remove_dir_all(dir).unwrap();
}

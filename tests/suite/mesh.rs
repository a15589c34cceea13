//! Mesh building, repair and loading: broken input gives a clear error or a repair note,
//! never a panic; tangents follow the UV parametrization exactly.

use glam::{Vec2, Vec3};
use werkstatt::mesh::{Mesh, load_mesh_file};
use werkstatt::nodes::mesh::geometry;

fn quad() -> (Vec<Vec3>, Vec<Vec2>, Vec<u32>) {
    (
        vec![Vec3::ZERO, Vec3::X, Vec3::new(1.0, 1.0, 0.0), Vec3::Y],
        vec![Vec2::ZERO, Vec2::X, Vec2::ONE, Vec2::Y],
        vec![0, 1, 2, 0, 2, 3],
    )
}

#[test]
fn nan_positions_and_degenerate_triangles_are_dropped_with_a_note() {
    let (mut p, uv, mut idx) = quad();
    p.push(Vec3::new(f32::NAN, 0.0, 0.0));
    idx.extend_from_slice(&[0, 1, 4, 0, 0, 1, 0, 1, 1]);
    let mut uv2 = uv.clone();
    uv2.push(Vec2::ZERO);
    let m = Mesh::build(p, Some(uv2), None, idx).unwrap();
    assert_eq!(m.triangle_count(), 2);
    let notes = m.repairs.join("; ");
    assert!(notes.contains("NaN") && notes.contains("degenerate"), "{notes}");
    assert!(m.positions.iter().all(|p| p.is_finite()));
}

#[test]
fn unusable_meshes_are_errors() {
    let (p, uv, _) = quad();
    let e = Mesh::build(p.clone(), Some(uv.clone()), None, vec![0, 1, 9]).unwrap_err();
    assert!(e.to_string().contains("index 9 is out of range"), "{e}");
    let e = Mesh::build(p.clone(), Some(uv.clone()), None, vec![0, 1]).unwrap_err();
    assert!(e.to_string().contains("multiple of 3"), "{e}");
    let e = Mesh::build(vec![Vec3::NAN; 3], None, None, vec![0, 1, 2]).unwrap_err();
    assert!(e.to_string().contains("NaN"), "{e}");
    let e = Mesh::build(p, Some(uv), None, vec![0, 0, 1]).unwrap_err();
    assert!(e.to_string().contains("no triangle is left"), "{e}");
    assert!(Mesh::build(vec![], None, None, vec![]).is_err());
}

#[test]
fn missing_normals_and_uvs_are_computed() {
    let (p, _, idx) = quad();
    let m = Mesh::build(p, None, None, idx).unwrap();
    assert!(m.normals.iter().all(|n| (*n - Vec3::Z).length() < 1e-6));
    assert!(m.repairs.iter().any(|r| r.contains("no UVs")));
    assert_eq!(m.uvs.len(), 4);
}

#[test]
fn plane_tangents_are_the_uv_axes() {
    let m = geometry::plane(2.0, 4, 4).unwrap();
    for i in 0..m.positions.len() {
        assert!((m.tangents_u[i] - Vec3::X).length() < 1e-5);
        assert!((m.tangents_v[i] - Vec3::Z).length() < 1e-5);
        assert!((m.normals[i] - Vec3::Y).length() < 1e-6);
    }
}

#[test]
fn cylinder_tangents_match_the_analytic_derivatives() {
    let m = geometry::cylinder(0.5, 1.0, 64, 8).unwrap();
    for i in 0..m.positions.len() {
        let a = m.uvs[i].x * std::f32::consts::TAU;
        // dP/du ∝ (cos a, 0, -sin a); dP/dv ∝ -Y.
        let du = Vec3::new(a.cos(), 0.0, -a.sin());
        // Averaging neighbouring faces' gradients costs about half a segment of angle.
        assert!(m.tangents_u[i].dot(du) > 0.998, "vertex {i}: {:?} vs {du:?}", m.tangents_u[i]);
        assert!((m.tangents_v[i] + Vec3::Y).length() < 1e-4);
        assert!((m.normals[i] - Vec3::new(a.sin(), 0.0, a.cos())).length() < 1e-5);
    }
}

/// The triangles of `m` with vertices welded by position (within 1e-5): seams of the UV
/// layout and per-face corners become one vertex. Triangles that collapse (at a pole) are left
/// out.
fn welded_triangles(m: &Mesh) -> Vec<[usize; 3]> {
    let mut first: Vec<usize> = Vec::with_capacity(m.positions.len());
    for (i, p) in m.positions.iter().enumerate() {
        let same = (0..i).find(|&j| (m.positions[j] - *p).length() < 1e-5).map_or(i, |j| first[j]);
        first.push(same);
    }
    m.indices
        .chunks_exact(3)
        .map(|t| [first[t[0] as usize], first[t[1] as usize], first[t[2] as usize]])
        .filter(|t| t[0] != t[1] && t[1] != t[2] && t[0] != t[2])
        .collect()
}

/// How often each directed edge occurs.
fn directed_edges(tris: &[[usize; 3]]) -> std::collections::HashMap<(usize, usize), usize> {
    let mut edges = std::collections::HashMap::new();
    for t in tris {
        for k in 0..3 {
            *edges.entry((t[k], t[(k + 1) % 3])).or_insert(0) += 1;
        }
    }
    edges
}

#[test]
fn every_primitive_is_a_valid_closed_or_open_mesh() {
    use std::f32::consts::PI;
    // (name, mesh, closed, analytic volume, relative tolerance of the faceted volume)
    let cases = [
        ("plane", geometry::plane(1.0, 3, 5), false, 0.0, 0.0),
        ("cylinder", geometry::cylinder(0.5, 1.0, 16, 4), false, 0.0, 0.0),
        ("sphere", geometry::sphere(0.5, 16, 8), true, 4.0 / 3.0 * PI * 0.125, 0.08),
        ("torus", geometry::torus(1.0, 0.25, 24, 12), true, 2.0 * PI * PI * 1.0 * 0.0625, 0.08),
        ("disc", geometry::disc(0.5, 0.1, 24), true, PI * 0.25 * 0.1, 0.03),
        ("cube", geometry::cube(1.0), true, 1.0, 1e-5),
    ];
    for (name, m, closed, volume, tolerance) in cases {
        let m = m.unwrap();
        assert!(m.triangle_count() > 0);
        let n = m.positions.len();
        assert_eq!((m.normals.len(), m.uvs.len(), m.tangents_u.len(), m.tangents_v.len()), (n, n, n, n));
        for i in 0..n {
            assert!((m.normals[i].length() - 1.0).abs() < 1e-4);
            assert!(m.normals[i].dot(m.tangents_u[i]).abs() < 1e-4);
        }
        // Consistently wound: no directed edge occurs twice (two faces disagreeing on it).
        let tris = welded_triangles(&m);
        let edges = directed_edges(&tris);
        assert!(edges.values().all(|&c| c == 1), "{name}: a directed edge is shared by two faces");
        // The winding agrees with the vertex normals (front faces are the normals' side).
        for t in m.indices.chunks_exact(3) {
            let [a, b, c] = [t[0], t[1], t[2]].map(|i| m.positions[i as usize]);
            let face = (b - a).cross(c - a);
            // Collapsed triangles at a pole have no direction of their own.
            if face.length() < 1e-6 {
                continue;
            }
            for &i in t {
                assert!(
                    face.normalize().dot(m.normals[i as usize]) > 0.0,
                    "{name}: face {t:?} at {a}, {b}, {c} winds against the normal {} of vertex {i}",
                    m.normals[i as usize]
                );
            }
        }
        if closed {
            // Closed: every edge has exactly two faces, one on each side (its reverse occurs).
            let open: Vec<_> = edges.keys().filter(|(a, b)| !edges.contains_key(&(*b, *a))).collect();
            assert!(open.is_empty(), "{name}: {} edges have one face, e.g. {:?}", open.len(), open.first());
            // Outward: the signed volume (divergence theorem) is positive and near the solid's.
            let signed: f32 =
                tris.iter().map(|t| m.positions[t[0]].dot(m.positions[t[1]].cross(m.positions[t[2]])) / 6.0).sum();
            assert!(
                signed > 0.0 && (signed - volume).abs() <= tolerance * volume,
                "{name}: signed volume {signed}, the solid's {volume}"
            );
        } else {
            let boundary = edges.keys().filter(|(a, b)| !edges.contains_key(&(*b, *a))).count();
            assert!(boundary > 0, "{name} is an open surface");
        }
    }
}

/// A binary glTF with one quad under a translated node, in `primitives` primitives (copies).
fn write_glb(path: &std::path::Path, primitives: usize) {
    let prims = vec![r#"{"attributes":{"POSITION":0,"TEXCOORD_0":1},"indices":2}"#; primitives].join(",");
    let positions: [[f32; 3]; 4] = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [0.0, 1.0, 0.0]];
    let uvs: [[f32; 2]; 4] = [[0.0, 0.0], [1.0, 0.0], [1.0, 1.0], [0.0, 1.0]];
    let indices: [u16; 6] = [0, 1, 2, 0, 2, 3];
    let mut bin: Vec<u8> = Vec::new();
    bin.extend(positions.iter().flatten().flat_map(|f| f.to_le_bytes()));
    bin.extend(uvs.iter().flatten().flat_map(|f| f.to_le_bytes()));
    bin.extend(indices.iter().flat_map(|i| i.to_le_bytes()));
    while !bin.len().is_multiple_of(4) {
        bin.push(0);
    }
    let json = format!(
        r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],
        "nodes":[{{"mesh":0,"translation":[0,0,5]}}],
        "meshes":[{{"primitives":[{prims}]}}],
        "buffers":[{{"byteLength":{}}}],
        "bufferViews":[{{"buffer":0,"byteOffset":0,"byteLength":48}},{{"buffer":0,"byteOffset":48,"byteLength":32}},{{"buffer":0,"byteOffset":80,"byteLength":12}}],
        "accessors":[{{"bufferView":0,"componentType":5126,"count":4,"type":"VEC3","min":[0,0,0],"max":[1,1,0]}},
                     {{"bufferView":1,"componentType":5126,"count":4,"type":"VEC2"}},
                     {{"bufferView":2,"componentType":5123,"count":6,"type":"SCALAR"}}]}}"#,
        bin.len()
    );
    let mut json = json.into_bytes();
    while !json.len().is_multiple_of(4) {
        json.push(b' ');
    }
    let total = 12 + 8 + json.len() + 8 + bin.len();
    let mut glb = Vec::new();
    glb.extend(b"glTF");
    glb.extend(2u32.to_le_bytes());
    glb.extend((total as u32).to_le_bytes());
    glb.extend((json.len() as u32).to_le_bytes());
    glb.extend(b"JSON");
    glb.extend(&json);
    glb.extend((bin.len() as u32).to_le_bytes());
    glb.extend(b"BIN\0");
    glb.extend(&bin);
    std::fs::write(path, glb).unwrap();
}

#[test]
fn gltf_and_obj_files_load_and_bad_ones_name_the_file() {
    let dir = std::env::temp_dir().join(format!("werkstatt-mesh-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let glb = dir.join("quad.glb");
    write_glb(&glb, 1);
    let m = load_mesh_file(&glb).unwrap();
    assert_eq!(m.triangle_count(), 2);
    assert!(m.piece_ids.is_empty(), "one primitive is one piece, no list");
    // Each primitive is a pattern piece (MeshFile's surface output).
    let two = dir.join("two.glb");
    write_glb(&two, 2);
    assert_eq!(load_mesh_file(&two).unwrap().piece_ids, [0, 0, 0, 0, 1, 1, 1, 1]);
    assert!(m.positions.iter().all(|p| (p.z - 5.0).abs() < 1e-6), "node translation applied");
    assert!((m.normals[0] - Vec3::Z).length() < 1e-6);

    let bad = dir.join("broken.glb");
    std::fs::write(&bad, b"glTF garbage").unwrap();
    assert!(format!("{:#}", load_mesh_file(&bad).unwrap_err()).contains("broken.glb"));
    let obj = dir.join("broken.obj");
    std::fs::write(&obj, "v 0 0 0\nv 1 0\nf 1 2 3\n").unwrap();
    assert!(format!("{:#}", load_mesh_file(&obj).unwrap_err()).contains("broken.obj"));
    let other = dir.join("mesh.stl");
    std::fs::write(&other, b"solid").unwrap();
    assert!(load_mesh_file(&other).unwrap_err().to_string().contains("unsupported mesh format"));
    std::fs::remove_dir_all(dir).unwrap();
}

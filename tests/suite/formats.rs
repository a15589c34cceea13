//! File formats out: ExportGeometry's binary glTF holds the geometry its OBJ of the same frame
//! holds (read back by the `gltf` crate, compared with the OBJ text parsed here), one
//! primitive per scene item, with that item's material.

use std::path::Path;

use crate::common::{out_dir, render_graph};

/// A cloth drawn in one material and 20 buttons attached to it in another, exported at frame 0
/// as OBJ and as GLB by two nodes.
const GRAPH: &str = r#"(version: 1, nodes: {
    "cloth": (kind: "ClothSim", params: {"triangles": 400}),
    "fabric": (kind: "Material", params: {"base_color": [0.9, 0.2, 0.1], "glossiness": 0.25}),
    "draw": (kind: "Draw", params: {}),
    "matrix": (kind: "MatrixTexture", params: {"resolution": 128}),
    "grid": (kind: "GridPlacement", params: {"columns": 5, "rows": 4}),
    "button": (kind: "Primitive", params: {"shape": "disc", "radius": 0.5, "height": 0.2, "segments_u": 16}),
    "horn": (kind: "Material", params: {"base_color": [0.1, 0.3, 0.9], "glossiness": 0.75}),
    "buttons": (kind: "PointAttachment", params: {"scale": 0.1}),
    "scene": (kind: "Merge", params: {}),
    "obj": (kind: "ExportGeometry", params: {"format": "obj"}),
    "glb": (kind: "ExportGeometry", params: {"format": "glb"}),
}, links: [("cloth.surface", "draw.mesh"), ("fabric.material", "draw.material"),
    ("cloth.surface", "matrix.surface"), ("cloth.surface", "grid.surface"),
    ("matrix.matrix", "buttons.matrix"), ("button.mesh", "buttons.mesh"), ("horn.material", "buttons.material"),
    ("grid.placements", "buttons.placements"), ("draw.scene", "scene.a"), ("buttons.scene", "scene.b"),
    ("scene.scene", "obj.scene"), ("scene.scene", "glb.scene")])"#;

/// Vertices and 0-based triangles of an OBJ as ExportGeometry writes it (`f a/a/a ...`).
fn read_obj(path: &Path) -> (Vec<[f32; 3]>, Vec<u32>) {
    let text = std::fs::read_to_string(path).unwrap();
    let (mut v, mut f) = (Vec::new(), Vec::new());
    for line in text.lines() {
        let mut words = line.split_whitespace();
        match words.next() {
            Some("v") => {
                let p: Vec<f32> = words.map(|w| w.parse().unwrap()).collect();
                v.push([p[0], p[1], p[2]]);
            }
            Some("f") => f.extend(words.map(|w| w.split('/').next().unwrap().parse::<u32>().unwrap() - 1)),
            _ => {}
        }
    }
    (v, f)
}

#[test]
fn glb_export_holds_the_obj_geometry_with_a_material_per_item() {
    let dir = out_dir("formats-glb");
    let graph = dir.join("export.ron");
    std::fs::write(&graph, GRAPH).unwrap();
    let started = std::time::Instant::now();
    let stats = render_graph(&graph, &dir, (0, 0), (16, 16), &[], &[]).unwrap();
    let mut files = stats.files.clone();
    files.sort();
    assert_eq!(files, ["glb_0000.glb", "obj_0000.obj"]);
    let (obj_positions, obj_indices) = read_obj(&dir.join("obj_0000.obj"));

    let glb = dir.join("glb_0000.glb");
    let (doc, buffers, _) = gltf::import(&glb).unwrap_or_else(|e| panic!("{}: {e}", glb.display()));
    let meshes: Vec<_> = doc.meshes().collect();
    assert_eq!(meshes.len(), 1);
    let (mut indices, mut colors, mut positions) = (Vec::new(), Vec::new(), Vec::new());
    for prim in meshes[0].primitives() {
        assert_eq!(prim.mode(), gltf::mesh::Mode::Triangles);
        let reader = prim.reader(|b| Some(&buffers[b.index()]));
        // The primitives share one vertex array.
        positions = reader.read_positions().expect("positions").collect();
        assert_eq!(reader.read_normals().expect("normals").len(), positions.len());
        assert_eq!(reader.read_tex_coords(0).expect("uvs").into_f32().len(), positions.len());
        let prim_indices: Vec<u32> = reader.read_indices().expect("indices").into_u32().collect();
        let m = prim.material().pbr_metallic_roughness();
        colors.push((m.base_color_factor(), m.roughness_factor(), m.metallic_factor(), prim_indices.len() / 3));
        indices.extend(prim_indices);
    }
    // Every vertex and triangle of the OBJ, bit for bit (OBJ prints the shortest f32 that reads
    // back the same).
    assert_eq!(positions.len(), obj_positions.len());
    assert!(positions == obj_positions, "the .glb's positions differ from the .obj's");
    assert_eq!(indices, obj_indices);
    // The cloth (400 triangles or so) in the fabric, then the 20 buttons in horn.
    assert_eq!(colors.len(), 2, "{colors:?}");
    assert_eq!((colors[0].0, colors[0].1, colors[0].2), ([0.9, 0.2, 0.1, 1.0], 0.75, 0.0));
    assert_eq!((colors[1].0, colors[1].1, colors[1].2), ([0.1, 0.3, 0.9, 1.0], 0.25, 0.0));
    assert!(colors[0].3 > 300 && colors[1].3 >= 18 * 64, "triangles per part: {colors:?}");
    // Bounds are required on POSITION and must hold every vertex.
    let bounds = doc.meshes().next().unwrap().primitives().next().unwrap().bounding_box();
    for p in &positions {
        assert!((0..3).all(|k| bounds.min[k] <= p[k] && p[k] <= bounds.max[k]), "{p:?} outside {bounds:?}");
    }
    eprintln!(
        "glb export: {} vertices, {} triangles, {} bytes (obj {} bytes), {:.0} ms for both",
        positions.len(),
        indices.len() / 3,
        std::fs::metadata(&glb).unwrap().len(),
        std::fs::metadata(dir.join("obj_0000.obj")).unwrap().len(),
        started.elapsed().as_secs_f64() * 1e3
    );
}

/// A cloth in motion exported over frames 0-3 as OBJ per frame and as one USD cache: the cache
/// has a time code per frame at the graph's rate and, at each, every vertex and triangle of
/// that frame's OBJ.
#[test]
fn usda_cache_holds_each_frame_of_the_obj_sequence() {
    let dir = out_dir("formats-usda");
    let graph = dir.join("cache.ron");
    std::fs::write(
        &graph,
        r#"(version: 1, nodes: {
            "cloth": (kind: "ClothSim", params: {"triangles": 200, "warmup": 0.0}),
            "draw": (kind: "Draw", params: {}),
            "obj": (kind: "ExportGeometry", params: {"format": "obj"}),
            "usd": (kind: "ExportGeometry", params: {"format": "usda"}),
        }, links: [("cloth.surface", "draw.mesh"), ("draw.scene", "obj.scene"), ("draw.scene", "usd.scene")])"#,
    )
    .unwrap();
    let stats = render_graph(&graph, &dir, (0, 3), (16, 16), &[], &[]).unwrap();
    assert!(stats.files.contains(&"usd.usda".to_string()), "{:?}", stats.files);
    let path = dir.join("usd.usda");
    let stage = werkstatt::io::usda::read_usda(&path).unwrap();
    assert_eq!((stage.time_codes_per_second, stage.start, stage.end), (30.0, 0.0, 3.0));
    assert_eq!(stage.meshes.len(), 1);
    let samples = &stage.meshes[0].samples;
    assert_eq!(samples.iter().map(|s| s.0).collect::<Vec<_>>(), [0.0, 1.0, 2.0, 3.0], "one sample per frame");
    for (t, s) in samples {
        let (positions, indices) = read_obj(&dir.join(format!("obj_{:04}.obj", *t as i64)));
        let ours: Vec<[f32; 3]> = s.positions.iter().map(|p| p.to_array()).collect();
        assert!(ours == positions, "frame {t}: the cache's points differ from the OBJ's");
        assert_eq!(s.indices, indices, "frame {t}");
        assert_eq!(s.normals.len(), ours.len());
    }
    assert_ne!(samples[0].1.positions, samples[3].1.positions, "the cloth moves");
    eprintln!("usda cache: 4 frames, {} bytes", std::fs::metadata(&path).unwrap().len());

    // Played back by MeshSequence at the cache's own rate (the node's fps is ignored) and
    // exported again: each frame is the original frame's OBJ, vertex for vertex.
    let play = dir.join("play");
    std::fs::create_dir_all(&play).unwrap();
    let replay = play.join("replay.ron");
    std::fs::write(
        &replay,
        r#"(version: 1, nodes: {
            "seq": (kind: "MeshSequence", params: {"path": "../usd.usda", "fps": 7.0}),
            "draw": (kind: "Draw", params: {}),
            "obj": (kind: "ExportGeometry", params: {"format": "obj"}),
        }, links: [("seq.surface", "draw.mesh"), ("draw.scene", "obj.scene")])"#,
    )
    .unwrap();
    render_graph(&replay, &play, (0, 3), (16, 16), &[], &[]).unwrap();
    for f in 0..=3 {
        let name = format!("obj_{f:04}.obj");
        let (original, replayed) = (read_obj(&dir.join(&name)), read_obj(&play.join(&name)));
        assert!(original == replayed, "frame {f}: MeshSequence plays other geometry than the cache holds");
    }
}

/// Every way of cutting or damaging a file: `read` returns an error naming the file (or, for a
/// damage that leaves a valid file, a result), and never panics.
fn corruption_loop(good: &Path, read: impl Fn(&Path) -> anyhow::Result<()>) {
    let bytes = std::fs::read(good).unwrap();
    let bad = good.with_file_name(format!("damaged.{}", good.extension().unwrap().to_str().unwrap()));
    let mut rng = 0x9e37_79b9_7f4a_7c15u64;
    let mut next = move || {
        rng ^= rng << 13;
        rng ^= rng >> 7;
        rng ^= rng << 17;
        rng
    };
    let mut failures = 0;
    for case in 0..120 {
        let mut b = bytes.clone();
        if case < 60 {
            b.truncate((next() % bytes.len() as u64) as usize);
        } else {
            for _ in 0..1 + case % 4 {
                let i = (next() % b.len() as u64) as usize;
                b[i] = next() as u8;
            }
        }
        std::fs::write(&bad, &b).unwrap();
        let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| read(&bad)));
        match result {
            Err(_) => panic!("case {case}: reading {} panicked", bad.display()),
            Ok(Err(e)) => {
                failures += 1;
                let e = format!("{e:#}");
                assert!(e.contains("damaged."), "case {case}: the error does not name the file: {e}");
            }
            // A cut that only took trailing white space leaves the file whole.
            Ok(Ok(())) => assert!(
                case >= 60 || b.trim_ascii_end() == bytes.trim_ascii_end(),
                "case {case}: a file cut at {} of {} bytes read without an error",
                b.len(),
                bytes.len()
            ),
        }
    }
    assert!(failures >= 60, "only {failures} of 120 damaged files were refused");
}

#[test]
fn damaged_usda_and_glb_files_fail_with_the_file_named() {
    let dir = out_dir("formats-damaged");
    let graph = dir.join("small.ron");
    std::fs::write(
        &graph,
        r#"(version: 1, nodes: {
            "plane": (kind: "Primitive", params: {"shape": "plane", "segments_u": 3, "segments_v": 3}),
            "draw": (kind: "Draw", params: {}),
            "glb": (kind: "ExportGeometry", params: {"format": "glb"}),
            "usd": (kind: "ExportGeometry", params: {"format": "usda"}),
        }, links: [("plane.mesh", "draw.mesh"), ("draw.scene", "glb.scene"), ("draw.scene", "usd.scene")])"#,
    )
    .unwrap();
    render_graph(&graph, &dir, (0, 0), (8, 8), &[], &[]).unwrap();
    // The project's own readers take the good files.
    let mesh = werkstatt::mesh::load_mesh_file(&dir.join("glb_0000.glb")).unwrap();
    assert_eq!(mesh.triangle_count(), 18);
    let stage = werkstatt::io::usda::read_usda(&dir.join("usd.usda")).unwrap();
    assert_eq!(stage.meshes[0].samples[0].1.indices.len(), 3 * 18);
    corruption_loop(&dir.join("glb_0000.glb"), |p| werkstatt::mesh::load_mesh_file(p).map(|_| ()));
    corruption_loop(&dir.join("usd.usda"), |p| werkstatt::io::usda::read_usda(p).map(|_| ()));
}

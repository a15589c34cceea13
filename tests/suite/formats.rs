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

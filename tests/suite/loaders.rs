//! File loaders' error paths and exact conversions: SvgCurves (SVG to cubic segments) and
//! MeshFile (OBJ, glTF). Every error names the file.

use glam::Vec2;
use werkstatt::mesh::load_mesh_file;
use werkstatt::nodes::warp::curves::load_svg;

use crate::common::out_dir;

fn error_of<T>(r: anyhow::Result<T>) -> String {
    match r {
        Ok(_) => panic!("expected an error"),
        Err(e) => format!("{e:#}"),
    }
}

#[test]
fn svg_errors_name_the_problem_and_the_file() {
    let dir = out_dir("loaders-svg-errors");
    let missing = dir.join("missing.svg");
    let e = error_of(load_svg(&missing));
    assert!(e.contains("cannot read") && e.contains("missing.svg"), "{e}");
    let invalid = dir.join("invalid.svg");
    std::fs::write(&invalid, "<svg this is not xml").unwrap();
    let e = error_of(load_svg(&invalid));
    assert!(e.contains("invalid SVG"), "{e}");
    let empty = dir.join("empty.svg");
    std::fs::write(&empty, r#"<svg xmlns="http://www.w3.org/2000/svg" width="10" height="10"><rect/></svg>"#).unwrap();
    let e = error_of(load_svg(&empty));
    assert!(e.contains("no paths"), "{e}");
}

fn cubic(s: &[Vec2; 4], t: f32) -> Vec2 {
    let u = 1.0 - t;
    s[0] * u * u * u + s[1] * 3.0 * u * u * t + s[2] * 3.0 * u * t * t + s[3] * t * t * t
}

#[test]
fn svg_coordinates_are_normalized_by_the_document_width_and_quadratics_are_exact() {
    let dir = out_dir("loaders-svg");
    let path = dir.join("curves.svg");
    std::fs::write(
        &path,
        r#"<svg xmlns="http://www.w3.org/2000/svg" width="200" height="100" viewBox="0 0 200 100">
            <path d="M 0 0 L 200 100" fill="none" stroke="black"/>
            <path d="M 20 80 Q 100 0 180 80" fill="none" stroke="black"/>
        </svg>"#,
    )
    .unwrap();
    let curves = load_svg(&path).unwrap();
    assert_eq!(curves.paths.len(), 2);
    // The line: from (0, 0) to (200, 100) / 200, its control points on the line at thirds.
    let line = &curves.paths[0];
    assert_eq!(line.len(), 1);
    let close = |a: Vec2, b: Vec2| (a - b).length() < 1e-5;
    assert!(close(line[0][0], Vec2::ZERO) && close(line[0][3], Vec2::new(1.0, 0.5)), "{line:?}");
    assert!(close(line[0][1], Vec2::new(1.0, 0.5) / 3.0) && close(line[0][2], Vec2::new(1.0, 0.5) * 2.0 / 3.0));
    // The quadratic, elevated to a cubic: the same curve at every parameter.
    let quad = &curves.paths[1];
    assert_eq!(quad.len(), 1);
    let (p0, c, p1) = (Vec2::new(20.0, 80.0) / 200.0, Vec2::new(100.0, 0.0) / 200.0, Vec2::new(180.0, 80.0) / 200.0);
    for k in 0..=10 {
        let t = k as f32 / 10.0;
        let expected = p0 * (1.0 - t) * (1.0 - t) + c * 2.0 * (1.0 - t) * t + p1 * t * t;
        assert!(close(cubic(&quad[0], t), expected), "t = {t}: {:?} vs {expected:?}", cubic(&quad[0], t));
    }
}

#[test]
fn mesh_file_errors_name_the_file() {
    let dir = out_dir("loaders-mesh-errors");
    let write = |name: &str, text: &str| {
        let p = dir.join(name);
        std::fs::write(&p, text).unwrap();
        p
    };
    let zeros = "data:application/octet-stream;base64,AAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAAA";
    let cases = [
        (write("no_scene.gltf", r#"{"asset":{"version":"2.0"}}"#), "no scene"),
        (
            write(
                "lines.gltf",
                &format!(
                    r#"{{"asset":{{"version":"2.0"}},"scene":0,"scenes":[{{"nodes":[0]}}],"nodes":[{{"mesh":0}}],
                    "meshes":[{{"primitives":[{{"attributes":{{"POSITION":0}},"mode":1}}]}}],
                    "buffers":[{{"byteLength":36,"uri":"{zeros}"}}],"bufferViews":[{{"buffer":0,"byteLength":36}}],
                    "accessors":[{{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[0,0,0]}}]}}"#
                ),
            ),
            "no triangle geometry",
        ),
        (
            write(
                "external.gltf",
                r#"{"asset":{"version":"2.0"},"scene":0,"scenes":[{"nodes":[0]}],"nodes":[{"mesh":0}],
                "meshes":[{"primitives":[{"attributes":{"POSITION":0}}]}],
                "buffers":[{"byteLength":36,"uri":"missing.bin"}],"bufferViews":[{"buffer":0,"byteLength":36}],
                "accessors":[{"bufferView":0,"componentType":5126,"count":3,"type":"VEC3","min":[0,0,0],"max":[0,0,0]}]}"#,
            ),
            "cannot parse glTF file",
        ),
        (write("empty.obj", "# only a comment\no nothing\n"), "no geometry"),
    ];
    for (path, needle) in cases {
        let e = error_of(load_mesh_file(&path));
        let name = path.file_name().unwrap().to_string_lossy().into_owned();
        assert!(e.contains(&name) && e.contains(needle), "{name}: expected \"{needle}\" in: {e}");
    }
}

#[test]
fn a_relative_mesh_path_is_resolved_against_the_graph_folder() {
    use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
    let dir = out_dir("loaders-relative");
    std::fs::create_dir_all(dir.join("meshes")).unwrap();
    std::fs::write(dir.join("meshes/tri.obj"), "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n").unwrap();
    let g = werkstatt::core::graph::Graph::load_str(
        r#"(version: 1, nodes: {"mesh": (kind: "MeshFile", params: {"path": "meshes/tri.obj", "normalize": false})}, links: [])"#,
        "test.ron".as_ref(),
    )
    .unwrap();
    let mut ev = Evaluator::new(&g, &["mesh".to_string()]).unwrap();
    let res = werkstatt::core::resources::Resources::new(false);
    let settings = FrameSettings { base_dir: dir.clone(), ..FrameSettings::default() };
    for _ in 0..3 {
        ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, None, &res, &settings);
        crate::common::wait_idle(&res);
    }
    assert_eq!(ev.report("mesh").unwrap().status, &NodeStatus::Ok);
    match ev.output("mesh", "mesh") {
        Some(werkstatt::core::port::Value::Mesh(m)) => assert_eq!(m.positions[1], glam::Vec3::X),
        _ => panic!("no mesh"),
    }
    // Its bounds, in the file's units: what lines meshes up without reading the file.
    for (port, expected) in [("bounds_min", glam::Vec3::ZERO), ("bounds_max", glam::Vec3::new(1.0, 1.0, 0.0))] {
        match ev.output("mesh", port) {
            Some(werkstatt::core::port::Value::Vector(v)) => assert_eq!(*v, expected, "{port}"),
            _ => panic!("{port}: no vector"),
        }
    }
}

/// Meshes of one source normalized together keep lining up: a garment normalized by its body's
/// file gets the body's centre and scale, not its own.
#[test]
fn meshes_normalized_by_one_file_share_its_scale() {
    use werkstatt::core::port::Value;
    let dir = out_dir("normalize_by");
    // A "body" 2 units tall from y = 0, and a "garment" on its upper half.
    std::fs::write(dir.join("body.obj"), "v -0.5 0 0\nv 0.5 0 0\nv 0 2 0\nf 1 2 3\n").unwrap();
    std::fs::write(dir.join("garment.obj"), "v -0.5 1 0.1\nv 0.5 1 0.1\nv 0 1.5 0.1\nf 1 2 3\n").unwrap();
    let run = |garment_params: &str| {
        let text = format!(
            r#"(version: 2, nodes: {{
                "body": (kind: "MeshFile", params: {{"path": "{d}/body.obj", "normalize": true}}),
                "garment": (kind: "MeshFile", params: {{"path": "{d}/garment.obj", "normalize": true, {garment_params}}}),
                "merge": (kind: "Merge"),
                "a": (kind: "Draw"), "b": (kind: "Draw"), "export": (kind: "ExportGeometry"),
            }}, links: [("body.mesh", "a.mesh"), ("garment.mesh", "b.mesh"), ("a.scene", "merge.a"), ("b.scene", "merge.b"),
                ("merge.scene", "export.scene")])"#,
            d = dir.display()
        );
        let g = werkstatt::core::graph::Graph::load_str(&text, "test.ron".as_ref()).unwrap();
        let ev = crate::common::run_graph(&g, 8, 8);
        match ev.output("garment", "mesh") {
            Some(Value::Mesh(m)) => m.positions.clone(),
            _ => panic!("no garment mesh"),
        }
    };
    // Alone, the garment is stretched to unit height about its own centre.
    let own = run("");
    assert!((own[2].y - 0.5).abs() < 1e-6 && (own[0].y + 0.5).abs() < 1e-6, "{own:?}");
    // By the body's file: centre (0, 1, 0), scale 1/2, so y 1 -> 0 and 1.5 -> 0.25.
    let shared = run(&format!(r#""normalize_by": "{}/body.obj""#, dir.display()));
    for (p, file) in shared.iter().zip([[-0.5f32, 1.0, 0.1], [0.5, 1.0, 0.1], [0.0, 1.5, 0.1]]) {
        let expected = (glam::Vec3::from(file) - glam::Vec3::new(0.0, 1.0, 0.0)) * 0.5;
        assert!((*p - expected).length() < 1e-6, "{p:?} vs {expected:?}");
    }
}

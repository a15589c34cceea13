//! Every kind of graph error, each from a file that triggers it: the message must name the
//! file, the line (and column), and the node and port where there is one.

use std::path::PathBuf;

use werkstatt::core::eval::Evaluator;
use werkstatt::core::graph::{Diagnostic, Graph, GraphError, ProblemKind};

fn errors(name: &str) -> Vec<Diagnostic> {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("tests/data/bad").join(name);
    match Graph::load(&path) {
        Ok(_) => panic!("{name} loaded without errors"),
        Err(e) => {
            for d in &e.diagnostics {
                let text = d.to_string();
                assert!(text.contains(name), "message does not name the file: {text}");
                assert!(text.contains(&format!(":{}:{}:", d.line, d.col)), "message lacks line:col: {text}");
            }
            e.diagnostics
        }
    }
}

fn only(name: &str, kind: ProblemKind) -> Diagnostic {
    let mut all = errors(name);
    assert_eq!(all.len(), 1, "{name}: expected one error, got: {all:#?}");
    let d = all.remove(0);
    assert_eq!(d.problem.kind, kind, "{name}: {d}");
    d
}

#[test]
fn malformed_file_reports_ron_position() {
    let d = only("syntax.ron", ProblemKind::Syntax);
    assert_eq!(d.line, 5, "{d}");
    let d = only("not_text.ron", ProblemKind::Io);
    assert!(d.to_string().contains("UTF-8"), "{d}");
}

#[test]
fn unknown_field_is_a_syntax_error_with_position() {
    let d = only("unknown_field.ron", ProblemKind::Syntax);
    assert_eq!(d.line, 4, "{d}");
    assert!(d.to_string().contains("parms"), "{d}");
}

#[test]
fn newer_version_is_refused() {
    let d = only("version_too_new.ron", ProblemKind::VersionTooNew);
    assert_eq!(d.line, 2);
    assert!(d.to_string().contains("99"), "{d}");
}

#[test]
fn an_older_version_without_a_migration_is_not_called_too_new() {
    let d = only("version_zero.ron", ProblemKind::VersionUnsupported);
    assert_eq!(d.line, 2);
    let text = d.to_string();
    assert!(text.contains("no migration from version 0") && !text.contains("newer"), "{text}");
}

#[test]
fn unknown_kind_names_node_and_suggests() {
    let d = only("unknown_kind.ron", ProblemKind::UnknownKind);
    assert_eq!((d.line, d.problem.node.as_deref()), (5, Some("cam")));
    let text = d.to_string();
    assert!(text.contains("OrbitCamra") && text.contains("did you mean \"OrbitCamera\""), "{text}");
}

#[test]
fn unknown_param_names_its_line() {
    let d = only("unknown_param.ron", ProblemKind::UnknownParam);
    assert_eq!((d.line, d.problem.node.as_deref()), (9, Some("cam")));
    assert!(d.to_string().contains("did you mean \"distance\""), "{d}");
}

#[test]
fn wrong_param_type() {
    let d = only("param_type.ron", ProblemKind::ParamType);
    assert_eq!(d.line, 8);
    assert!(d.to_string().contains("\"fov\": expected float, found string \"wide\""), "{d}");
}

#[test]
fn param_out_of_range() {
    let d = only("param_range.ron", ProblemKind::ParamRange);
    assert_eq!(d.line, 8);
    assert!(d.to_string().contains("120 is out of range [-89, 89]"), "{d}");
}

/// A zero scale component is an error of the graph, found by `check` with the value named,
/// not only when the node runs; a tiny one is not (millimetres to metres).
#[test]
fn a_degenerate_scale_is_a_range_error_naming_its_value() {
    let d = only("degenerate_scale.ron", ProblemKind::ParamRange);
    assert_eq!(d.line, 13, "{d}");
    assert_eq!(d.problem.node.as_deref(), Some("draw"));
    assert!(
        d.to_string().contains(
            "parameter \"scale\": the transform is degenerate: scale [0.0001, 0.0001, 0] has a component that is 0"
        ),
        "{d}"
    );
}

#[test]
fn link_between_different_types() {
    let d = only("link_type.ron", ProblemKind::LinkTypeMismatch);
    assert_eq!(d.line, 10, "{d}");
    assert_eq!((d.problem.node.as_deref(), d.problem.port.as_deref()), (Some("draw"), Some("material")));
    assert!(d.to_string().contains("cam.camera (Camera) to draw.material (Material)"), "{d}");
}

#[test]
fn unknown_port_suggests_the_right_one() {
    let all = errors("unknown_port.ron");
    let d = all.iter().find(|d| d.problem.kind == ProblemKind::UnknownPort).expect("an unknown-port error");
    assert_eq!(d.line, 9);
    assert_eq!(d.problem.port.as_deref(), Some("meshes"));
    assert!(d.to_string().contains("did you mean \"mesh\""), "{d}");
}

#[test]
fn link_to_missing_node() {
    let all = errors("unknown_node.ron");
    let d = all.iter().find(|d| d.problem.kind == ProblemKind::UnknownNode).expect("an unknown-node error");
    assert_eq!(d.line, 7);
    assert!(d.to_string().contains("\"ghost\""), "{d}");
}

#[test]
fn a_misspelt_node_in_a_link_gets_a_suggestion() {
    let all = errors("misspelt_node.ron");
    let d = all.iter().find(|d| d.problem.kind == ProblemKind::UnknownNode).expect("an unknown-node error");
    assert_eq!(d.line, 10);
    assert!(d.to_string().contains("did you mean \"floor_material\"?"), "{d}");
}

#[test]
fn missing_required_input() {
    let d = only("missing_input.ron", ProblemKind::MissingInput);
    assert_eq!(d.line, 5);
    assert_eq!((d.problem.node.as_deref(), d.problem.port.as_deref()), (Some("draw"), Some("mesh")));
}

#[test]
fn duplicate_node_id() {
    let d = only("duplicate_id.ron", ProblemKind::DuplicateId);
    assert!(d.to_string().contains("\"n\" is used twice"), "{d}");
    assert_eq!(d.line, 4);
}

#[test]
fn cycle_names_its_nodes() {
    let d = only("cycle.ron", ProblemKind::Cycle);
    let text = d.to_string();
    assert!(text.contains("a -> b -> c -> a"), "{text}");
}

#[test]
fn malformed_link() {
    let d = only("bad_link.ron", ProblemKind::BadLinkSyntax);
    assert_eq!(d.line, 7);
}

#[test]
fn input_fed_twice() {
    let d = only("linked_twice.ron", ProblemKind::InputLinkedTwice);
    assert_eq!(d.line, 10);
    assert_eq!(d.problem.port.as_deref(), Some("a"));
}

#[test]
fn all_errors_of_a_file_are_reported() {
    let all = errors("many_errors.ron");
    let kinds: Vec<_> = all.iter().map(|d| (d.problem.kind.clone(), d.line)).collect();
    assert!(kinds.contains(&(ProblemKind::UnknownKind, 4)), "{kinds:?}");
    assert!(kinds.contains(&(ProblemKind::ParamRange, 5)), "{kinds:?}");
    assert!(kinds.contains(&(ProblemKind::MissingInput, 6)), "{kinds:?}");
}

#[test]
fn missing_file_is_an_error_naming_it() {
    let err = Graph::load(std::path::Path::new("tests/data/bad/does-not-exist.ron")).unwrap_err();
    assert_eq!(err.diagnostics[0].problem.kind, ProblemKind::Io);
    assert!(err.to_string().contains("does-not-exist.ron"));
}

#[test]
fn cli_set_errors_name_node_and_param() {
    let mut g =
        Graph::load(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/graphs/still_life.ron"))).unwrap();
    let err = g.set_from_cli("camera.distanse=3").unwrap_err();
    assert!(matches!(&err, GraphError::SetUnknownParam { node, param, .. } if node == "camera" && param == "distanse"));
    let e = err.to_string();
    assert!(e.contains("\"camera\"") && e.contains("distanse") && e.contains("distance"), "{e}");
    let err = g.set_from_cli("camera.distance=far").unwrap_err();
    assert!(matches!(&err, GraphError::SetValue { node, .. } if node == "camera"));
    let e = err.to_string();
    assert!(e.contains("camera.distance") && e.contains("not a number"), "{e}");
    let e = g.set_from_cli("camera.pitch=100").unwrap_err().to_string();
    assert!(e.contains("out of range"), "{e}");
    let err = g.set_from_cli("nobody.x=1").unwrap_err();
    assert_eq!(err.node(), Some("nobody"));
    let e = err.to_string();
    assert!(e.contains("no node \"nobody\""), "{e}");
    assert!(matches!(g.set_from_cli("camera"), Err(GraphError::SetSyntax { .. })));
    g.set_from_cli("camera.distance=5").unwrap();
    assert_eq!(g.param("camera", "distance"), Some(werkstatt::core::param::ParamValue::Float(5.0)));
}

/// Loading and evaluation share one error type: a file's problems keep their file, line, node
/// and port; an in-memory graph's problem names its node and port; a missing root its id.
#[test]
fn graph_errors_are_typed_and_name_file_line_node_and_port() {
    let text = "(version: 1, nodes: {\n  \"t\": (kind: \"Tonemap\"),\n}, links: [])";
    let err: GraphError = Graph::load_str(text, std::path::Path::new("typed.ron")).unwrap_err().into();
    let GraphError::Load(load) = &err else { panic!("expected GraphError::Load, got {err:?}") };
    let d = &load.diagnostics[0];
    assert_eq!((d.file.to_str(), d.line, d.problem.node.as_deref()), (Some("typed.ron"), 2, Some("t")));
    assert_eq!(err.node(), Some("t"));
    assert!(err.to_string().starts_with("typed.ron:2:"), "{err}");

    let (graph, _) = Graph::load_lenient(text, std::path::Path::new("typed.ron")).unwrap();
    let err = Evaluator::new(&graph, &[]).err().expect("an unconnected required input");
    let GraphError::Invalid(problem) = &err else { panic!("expected GraphError::Invalid, got {err:?}") };
    assert_eq!((problem.kind.clone(), problem.port.as_deref()), (ProblemKind::MissingInput, Some("image")));
    assert!(err.to_string().contains("node \"t\", port \"image\""), "{err}");

    let ok =
        Graph::load_str("(version: 1, nodes: {\"n\": (kind: \"Number\")}, links: [])", std::path::Path::new("x.ron"))
            .unwrap();
    let err = Evaluator::new(&ok, &["nope".to_string()]).err().expect("an unknown root");
    assert!(matches!(&err, GraphError::NoSuchNode(id) if id == "nope"));
    assert_eq!(err.node(), Some("nope"));
}

#[test]
fn link_errors_after_a_malformed_link_point_at_their_own_row() {
    let text = r#"(
    version: 1,
    nodes: {
        "cam": (kind: "OrbitCamera"),
        "shape": (kind: "Primitive"),
        "draw": (kind: "Draw"),
    },
    links: [
        ("nonsense", "draw.mesh"),
        ("shape.mesh", "draw.mesh"),
        ("cam.camera", "draw.material"),
    ],
)"#;
    let err = Graph::load_str(text, "rows.ron".as_ref()).unwrap_err();
    let mismatch = err.diagnostics.iter().find(|d| d.problem.kind == ProblemKind::LinkTypeMismatch).unwrap();
    assert_eq!(mismatch.line, 11, "{mismatch}");
    let bad = err.diagnostics.iter().find(|d| d.problem.kind == ProblemKind::BadLinkSyntax).unwrap();
    assert_eq!(bad.line, 9, "{bad}");
}

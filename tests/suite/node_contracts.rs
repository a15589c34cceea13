//! Every registered node honours its spec: run with all inputs connected, with default
//! parameters and with each option of each choice parameter, no node reads or writes a port
//! or parameter its spec does not declare, reads one as the wrong type, or leaves an output
//! unset (the evaluator reports those as internal errors; see `werkstatt::core::node::INTERNAL_ERROR`).

use crate::common;

use std::collections::BTreeMap;
use std::path::PathBuf;

use werkstatt::core::eval::{Evaluator, FrameSettings, FrameTime, NodeStatus};
use werkstatt::core::graph::{Graph, Link, NodeDoc, PortRef};
use werkstatt::core::node::{INTERNAL_ERROR, NodeSpec};
use werkstatt::core::param::{ParamKind, ParamValue};
use werkstatt::core::port::PortType;
use werkstatt::core::resources::Resources;

type Params = Vec<(&'static str, ParamValue)>;

/// A producer for each input type: (kind, output port, parameters).
fn producer(ty: PortType) -> Option<(&'static str, &'static str, Params)> {
    let small = vec![("segments_u", ParamValue::Int(8)), ("segments_v", ParamValue::Int(4))];
    Some(match ty {
        PortType::Scalar => ("Number", "value", vec![("value", ParamValue::Float(0.5))]),
        PortType::Mesh | PortType::Surface => ("Primitive", "mesh", small),
        PortType::Scene => ("Draw", "scene", vec![]),
        PortType::Material => ("Material", "material", vec![]),
        PortType::Camera => ("OrbitCamera", "camera", vec![]),
        PortType::Texture => ("GBufferPass", "color", vec![]),
        PortType::GBuffer => ("GBufferPass", "gbuffer", vec![]),
        PortType::Instances => ("GridPlacement", "placements", vec![]),
        PortType::MatrixTexture => ("MatrixTexture", "matrix", vec![("resolution", ParamValue::Int(64))]),
        PortType::Curves => ("SvgCurves", "curves", vec![]),
        PortType::Environment => ("EnvironmentMap", "environment", vec![]),
        PortType::Lights => ("MedianCut", "lights", vec![]),
        PortType::Pems => ("Pems", "pems", vec![]),
        PortType::ShadowAtlas => ("ShadowAtlas", "shadows", vec![("tile_size", ParamValue::Int(32))]),
        PortType::CuboidTransform => ("Cuboid", "transform", vec![]),
        PortType::Btf => ("Btf", "btf", vec![]),
        PortType::Joints => ("Avatar", "joints", vec![]),
        PortType::Vector | PortType::Color => return None,
    })
}

/// Inputs that need a particular producer rather than any of their type.
fn input_producer(kind: &str, input: &str) -> Option<(&'static str, &'static str, Params)> {
    match (kind, input) {
        // The refined mesh of the surface: Tessellate of an equal Primitive (both producers
        // make the same small sphere).
        ("MatrixTexture", "refined") => Some(("Tessellate", "scene", vec![])),
        _ => None,
    }
}

/// Parameters that make a node do real work in the test (files that exist, small sizes).
fn fixture_params(kind: &str) -> Params {
    let data = |p: &str| ParamValue::Str(common::root().join(p).display().to_string());
    match kind {
        "MeshFile" => vec![("path", data("assets/meshes/spot.obj"))],
        "Avatar" => vec![
            ("mesh", data("assets/avatar/makehuman-base.obj")),
            ("skeleton", data("assets/avatar/default.mhskel")),
            ("weights", data("assets/avatar/default_weights.mhw")),
            ("motion", data("assets/avatar/walk1.bvh")),
            ("joint_map", data("assets/avatar/makehuman-old-rig.ron")),
            ("clothes", data("assets/avatar/male_worksuit01.mhclo")),
        ],
        "SvgCurves" => vec![("path", data("assets/patterns/embroidery.svg"))],
        "PlacementFile" => vec![("path", data("assets/placements/buttons.csv"))],
        // Points off the producer's surface, so their nearest points are searched for.
        "SurfacePoints" => {
            vec![("points", ParamValue::Str("0 0 2; 1 0 0".into())), ("max_distance", ParamValue::Float(10.0))]
        }
        "MeshSequence" => vec![("path", data("tests/data/sequence"))],
        "ClothSim" => vec![("triangles", ParamValue::Int(200))],
        "Garment" => vec![
            ("pattern", data("assets/patterns/garmentcode/shirt_mean_specification.json")),
            ("edge_length", ParamValue::Float(6.0)),
        ],
        // btf_id 1: BtfShading's default material_id, so its HEM finds an item in the scene.
        "Material" => vec![
            ("texture_path", data("docs/default.png")),
            ("gloss_map_path", data("docs/default.png")),
            ("btf_id", ParamValue::Int(1)),
        ],
        "MatrixTexture" => vec![("resolution", ParamValue::Int(64))],
        "EnvironmentMap" => vec![("path", data("assets/hdri/forest.hdr")), ("size", ParamValue::Int(8))],
        "MedianCut" => vec![("count", ParamValue::Int(5))],
        "Btf" => vec![("path", data("assets/btf/checker8.btf")), ("resolution", ParamValue::Int(4))],
        "Primitive" => vec![("segments_u", ParamValue::Int(8)), ("segments_v", ParamValue::Int(4))],
        _ => vec![],
    }
}

struct Builder {
    graph: Graph,
    next: usize,
}

impl Builder {
    /// Adds a node of `kind` with every input connected to a producer; returns its id.
    fn add(&mut self, kind: &str, params: Params) -> String {
        let spec = werkstatt::core::spec::find(kind).unwrap_or_else(|| panic!("no kind {kind}"));
        let id = format!("n{}_{}", self.next, kind.to_lowercase());
        self.next += 1;
        let mut doc_params: BTreeMap<String, ParamValue> =
            fixture_params(kind).into_iter().map(|(k, v)| (k.to_string(), v)).collect();
        doc_params.extend(params.into_iter().map(|(k, v)| (k.to_string(), v)));
        self.graph.nodes.insert(id.clone(), NodeDoc { kind: kind.into(), params: doc_params, pos: [0.0, 0.0] });
        for input in spec.inputs {
            let (pkind, port, pparams) = input_producer(kind, input.name)
                .or_else(|| producer(input.ty))
                .unwrap_or_else(|| panic!("no producer for {} (input {} of {kind})", input.ty, input.name));
            let src = self.add(pkind, pparams);
            self.graph.links.push(Link {
                from: PortRef { node: src, port: port.into() },
                to: PortRef { node: id.clone(), port: input.name.into() },
            });
        }
        id
    }
}

fn run(spec: &NodeSpec, params: Params) -> Result<(), String> {
    let mut b = Builder { graph: Graph::new(), next: 0 };
    let id = b.add(spec.kind, params);
    if let Some(p) = b.graph.validate().first() {
        return Err(format!("fixture graph is invalid: {}", p.message));
    }
    let mut ev = Evaluator::new(&b.graph, std::slice::from_ref(&id)).map_err(|e| e.to_string())?;
    let resources = Resources::new(false);
    let settings = FrameSettings { width: 32, height: 24, base_dir: PathBuf::from("."), frames: None };
    // Twice, so nodes with state see a second frame; loads are waited for in between.
    for frame in 0..2 {
        // Stops when nothing is pending, or when no load was in flight across a whole
        // evaluation (a load that finished right after the evaluation that asked for it is
        // picked up by the next one; LiveLink stays pending for good).
        let deadline = std::time::Instant::now() + std::time::Duration::from_secs(60);
        let mut idle_evaluations = 0;
        loop {
            let summary = ev.evaluate(FrameTime { frame, fps: 30.0 }, Some(common::gpu()), &resources, &settings);
            idle_evaluations = if resources.in_flight() == 0 { idle_evaluations + 1 } else { 0 };
            if summary.pending == 0 || idle_evaluations == 2 || std::time::Instant::now() > deadline {
                break;
            }
            common::wait_idle(&resources);
        }
    }
    let target = ev.report(&id).expect("the node under test");
    // LiveLink waits for a simulator to connect; every other node must do its work.
    if !spec.has(werkstatt::core::node::Capabilities::EXTERNAL_SOURCE) && target.status != &NodeStatus::Ok {
        return Err(format!("did not run to completion: {:?}", target.status));
    }
    for r in ev.reports() {
        let message = match r.status {
            NodeStatus::Failed(m) | NodeStatus::Blocked(m) => m.as_str(),
            _ => continue,
        };
        if message.contains(INTERNAL_ERROR) {
            return Err(format!("node \"{}\" ({}): {message}", r.id, r.kind));
        }
    }
    Ok(())
}

#[test]
fn every_node_reads_and_writes_only_what_its_spec_declares() {
    let mut problems = Vec::new();
    for spec in werkstatt::core::spec::all() {
        if let Err(e) = run(spec, vec![]) {
            problems.push(format!("{} (defaults): {e}", spec.kind));
        }
        for param in spec.params {
            if let ParamKind::Choice { options, default } = param.kind {
                for option in options.iter().filter(|o| **o != default) {
                    if let Err(e) = run(spec, vec![(param.name, ParamValue::Str(option.to_string()))]) {
                        problems.push(format!("{} ({} = {option}): {e}", spec.kind, param.name));
                    }
                }
            }
        }
    }
    assert!(problems.is_empty(), "{}", problems.join("\n"));
}

#[test]
fn every_input_type_has_a_producer_in_this_test() {
    for spec in werkstatt::core::spec::all() {
        for input in spec.inputs {
            assert!(producer(input.ty).is_some(), "add a producer of {} for {}.{}", input.ty, spec.kind, input.name);
        }
    }
}

/// Engine code asks a spec for capabilities instead of comparing kind names; a capability
/// promises what the engine then relies on.
#[test]
fn capabilities_keep_their_promises() {
    use werkstatt::core::node::Capabilities;
    let find = |kind| werkstatt::core::spec::find(kind).expect(kind);
    assert!(find("Preview").has(Capabilities::PREVIEW) && find("Preview").is_output());
    assert!(find("OrbitCamera").has(Capabilities::ORBIT_CAMERA) && !find("OrbitCamera").is_output());
    assert!(find("LiveLink").has(Capabilities::EXTERNAL_SOURCE));
    assert!(!find("Math").has(Capabilities::OUTPUT) && find("Math").capabilities == Capabilities::NONE);
    let both = Capabilities::OUTPUT.with(Capabilities::PREVIEW);
    assert!(both.contains(Capabilities::OUTPUT) && both.contains(Capabilities::PREVIEW));
    assert!(!both.contains(Capabilities::ORBIT_CAMERA) && both.contains(Capabilities::NONE));
    for spec in werkstatt::core::spec::all() {
        // The viewport previews an image: a preview node has a texture output.
        if spec.has(Capabilities::PREVIEW) {
            assert!(spec.outputs.iter().any(|p| p.ty.viewable()), "{} previews no texture", spec.kind);
        }
        // The viewport's drag writes these three parameters.
        if spec.has(Capabilities::ORBIT_CAMERA) {
            for name in ["yaw", "pitch", "distance"] {
                let p = spec.param(name).map(|(_, p)| &p.kind);
                assert!(matches!(p, Some(ParamKind::Float { .. })), "{} lacks float parameter {name}", spec.kind);
            }
        }
        // A batch render that waits for an external source says what to do instead.
        if spec.has(Capabilities::EXTERNAL_SOURCE) {
            assert!(spec.capabilities.batch_help().is_some_and(|h| !h.is_empty()), "{}", spec.kind);
        }
    }
}

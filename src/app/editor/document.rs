//! The editor's document operations on a [`Graph`]: add, remove, connect, set parameters,
//! move, copy and paste. Plain functions on the document model, with no UI, so that they
//! are tested without a window. Every operation either succeeds or leaves the graph as it
//! was and says why in an [`EditError`].

use std::collections::{BTreeMap, BTreeSet};
use std::fmt;
use std::path::{Path, PathBuf};

use crate::core::graph::{Graph, Link, NodeDoc, PortRef};
use crate::core::node::NodeSpec;
use crate::core::param::ParamValue;
use crate::core::port::PortType;
use crate::core::spec;

/// Why an edit was refused. The message is shown to the user as it is.
#[derive(Clone, Debug, PartialEq)]
pub enum EditError {
    UnknownKind(String),
    NoSuchNode(String),
    NoSuchPort { port: PortRef, input: bool },
    IncompatibleTypes { from: PortRef, from_ty: PortType, to: PortRef, to_ty: PortType },
    SelfLink(String),
    Cycle { from: PortRef, to: PortRef },
    BadParam(String),
    CannotInsert(String),
    Clipboard(String),
}

impl fmt::Display for EditError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            EditError::UnknownKind(k) => write!(f, "there is no node kind \"{k}\""),
            EditError::NoSuchNode(n) => write!(f, "there is no node \"{n}\""),
            EditError::NoSuchPort { port, input } => {
                write!(f, "node \"{}\" has no {} \"{}\"", port.node, if *input { "input" } else { "output" }, port.port)
            }
            EditError::IncompatibleTypes { from, from_ty, to, to_ty } => write!(
                f,
                "cannot connect {from} ({from_ty}) to {to} ({to_ty}): a {to_ty} input does not accept {from_ty}"
            ),
            EditError::SelfLink(n) => write!(f, "cannot connect node \"{n}\" to itself"),
            EditError::Cycle { from, to } => {
                write!(f, "cannot connect {from} to {to}: the link would form a cycle")
            }
            EditError::BadParam(m) | EditError::CannotInsert(m) | EditError::Clipboard(m) => f.write_str(m),
        }
    }
}

impl std::error::Error for EditError {}

/// The readable base of new node ids: `GBufferPass` becomes `gbuffer_pass`.
pub fn id_stem(kind: &str) -> String {
    let mut out = String::new();
    let mut prev_lower = false;
    for c in kind.chars() {
        if c.is_ascii_uppercase() && prev_lower {
            out.push('_');
        }
        prev_lower = c.is_ascii_lowercase() || c.is_ascii_digit();
        if c.is_ascii_alphanumeric() || c == '_' || c == '-' {
            out.push(c.to_ascii_lowercase());
        }
    }
    if out.is_empty() { "node".into() } else { out }
}

/// A new id for a node named after `stem`: `stem` itself if free, else `stem_2`, `stem_3`, ...
/// A stem that already ends in `_N` counts on from there (`tonemap_2` gives `tonemap_3`).
pub fn unique_id(graph: &Graph, stem: &str) -> String {
    unique_id_in(stem, |id| graph.nodes.contains_key(id))
}

fn unique_id_in(stem: &str, taken: impl Fn(&str) -> bool) -> String {
    let stem = if crate::core::graph::valid_id(stem) { stem.to_string() } else { id_stem(stem) };
    if !taken(&stem) {
        return stem;
    }
    let (base, first) = match stem.rsplit_once('_') {
        Some((b, n)) if !b.is_empty() && n.parse::<u64>().is_ok() => (b.to_string(), n.parse::<u64>().unwrap_or(1) + 1),
        _ => (stem.clone(), 2),
    };
    (first..).map(|n| format!("{base}_{n}")).find(|id| !taken(id)).unwrap_or(stem)
}

fn spec_of(graph: &Graph, id: &str) -> Result<&'static NodeSpec, EditError> {
    let node = graph.nodes.get(id).ok_or_else(|| EditError::NoSuchNode(id.into()))?;
    spec::find(&node.kind).ok_or_else(|| EditError::UnknownKind(node.kind.clone()))
}

/// The type of an output (`input == false`) or input port.
pub fn port_type(graph: &Graph, port: &PortRef, input: bool) -> Result<PortType, EditError> {
    let spec = spec_of(graph, &port.node)?;
    let found = if input { spec.input(&port.port) } else { spec.output(&port.port) };
    found.map(|(_, p)| p.ty).ok_or_else(|| EditError::NoSuchPort { port: port.clone(), input })
}

/// Adds a node of `kind` at `pos` with default parameters; returns its new id.
pub fn add_node(graph: &mut Graph, kind: &str, pos: [f32; 2]) -> Result<String, EditError> {
    let spec = spec::find(kind).ok_or_else(|| EditError::UnknownKind(kind.into()))?;
    let id = unique_id(graph, &id_stem(spec.kind));
    graph.nodes.insert(id.clone(), NodeDoc { kind: spec.kind.into(), pos, params: BTreeMap::new() });
    Ok(id)
}

/// Removes nodes and every link that touches them; returns how many nodes were removed.
pub fn remove_nodes<'a>(graph: &mut Graph, ids: impl IntoIterator<Item = &'a String>) -> usize {
    let ids: BTreeSet<&String> = ids.into_iter().collect();
    let before = graph.nodes.len();
    graph.nodes.retain(|id, _| !ids.contains(id));
    graph.links.retain(|l| !ids.contains(&l.from.node) && !ids.contains(&l.to.node));
    before - graph.nodes.len()
}

/// Whether `to` can reach `from` along links (so that a link from -> to would close a cycle).
fn reaches(graph: &Graph, start: &str, goal: &str) -> bool {
    let mut stack = vec![start];
    let mut seen = BTreeSet::new();
    while let Some(n) = stack.pop() {
        if n == goal {
            return true;
        }
        if seen.insert(n) {
            stack.extend(graph.links.iter().filter(|l| l.from.node == n).map(|l| l.to.node.as_str()));
        }
    }
    false
}

/// Checks a link without making it.
pub fn check_link(graph: &Graph, from: &PortRef, to: &PortRef) -> Result<(), EditError> {
    let from_ty = port_type(graph, from, false)?;
    let to_ty = port_type(graph, to, true)?;
    if from.node == to.node {
        return Err(EditError::SelfLink(from.node.clone()));
    }
    if !to_ty.accepts(from_ty) {
        return Err(EditError::IncompatibleTypes { from: from.clone(), from_ty, to: to.clone(), to_ty });
    }
    if reaches(graph, &to.node, &from.node) {
        return Err(EditError::Cycle { from: from.clone(), to: to.clone() });
    }
    Ok(())
}

/// Links output `from` to input `to`, type-checked. An input takes one link, so a link
/// already feeding `to` is replaced; it is returned.
pub fn connect(graph: &mut Graph, from: &PortRef, to: &PortRef) -> Result<Option<Link>, EditError> {
    check_link(graph, from, to)?;
    let old = disconnect_input(graph, to);
    graph.links.push(Link { from: from.clone(), to: to.clone() });
    Ok(old)
}

/// Removes the link feeding input `to`, if any.
pub fn disconnect_input(graph: &mut Graph, to: &PortRef) -> Option<Link> {
    let i = graph.links.iter().position(|l| &l.to == to)?;
    Some(graph.links.remove(i))
}

/// Removes every link leaving output `from`; returns how many.
pub fn disconnect_output(graph: &mut Graph, from: &PortRef) -> usize {
    let before = graph.links.len();
    graph.links.retain(|l| &l.from != from);
    before - graph.links.len()
}

/// Sets a parameter, checked against the node's spec (type and range); the value is stored
/// in canonical form (an integer given for a float parameter becomes a float).
pub fn set_param(graph: &mut Graph, id: &str, name: &str, value: ParamValue) -> Result<(), EditError> {
    let spec = spec_of(graph, id)?;
    let (_, ps) = spec
        .param(name)
        .ok_or_else(|| EditError::BadParam(format!("{} (node \"{id}\") has no parameter \"{name}\"", spec.kind)))?;
    let value = ps.kind.check(&value).map_err(|m| EditError::BadParam(format!("{id}.{name}: {m}")))?;
    if let Some(node) = graph.nodes.get_mut(id) {
        node.params.insert(name.into(), value);
    }
    Ok(())
}

/// Forgets a parameter's value so that it takes its default again.
pub fn reset_param(graph: &mut Graph, id: &str, name: &str) -> Result<(), EditError> {
    let node = graph.nodes.get_mut(id).ok_or_else(|| EditError::NoSuchNode(id.into()))?;
    node.params.remove(name);
    Ok(())
}

/// Moves nodes; positions are rounded to whole units so that files stay readable.
pub fn move_nodes(graph: &mut Graph, moves: &[(String, [f32; 2])]) {
    for (id, pos) in moves {
        if let Some(node) = graph.nodes.get_mut(id)
            && pos.iter().all(|c| c.is_finite())
        {
            node.pos = [pos[0].round(), pos[1].round()];
        }
    }
}

/// Puts node `id` into `link`: `link.from -> id.input` and `id.output -> link.to`, using the
/// node's first input and output whose types fit.
pub fn insert_on_link(graph: &mut Graph, id: &str, link: &Link) -> Result<(), EditError> {
    let spec = spec_of(graph, id)?;
    if !graph.links.contains(link) {
        return Err(EditError::CannotInsert(format!("there is no link {} -> {}", link.from, link.to)));
    }
    if link.from.node == id || link.to.node == id {
        return Err(EditError::CannotInsert(format!("node \"{id}\" is already on that link")));
    }
    let from_ty = port_type(graph, &link.from, false)?;
    let to_ty = port_type(graph, &link.to, true)?;
    let input = spec.inputs.iter().find(|p| p.ty.accepts(from_ty));
    let output = spec.outputs.iter().find(|p| to_ty.accepts(p.ty));
    let (Some(input), Some(output)) = (input, output) else {
        return Err(EditError::CannotInsert(format!(
            "{} has no {from_ty} input and {to_ty}-compatible output to put on {} -> {}",
            spec.kind, link.from, link.to
        )));
    };
    let mut g = graph.clone();
    g.links.retain(|l| l != link);
    let mid_in = PortRef { node: id.into(), port: input.name.into() };
    let mid_out = PortRef { node: id.into(), port: output.name.into() };
    connect(&mut g, &link.from, &mid_in)?;
    connect(&mut g, &mid_out, &link.to)?;
    *graph = g;
    Ok(())
}

/// Nodes and the links among them, as copied to the clipboard. As text it is a graph file.
#[derive(Clone, Debug, PartialEq, Default)]
pub struct Fragment {
    pub nodes: BTreeMap<String, NodeDoc>,
    pub links: Vec<Link>,
}

impl Fragment {
    /// The nodes `ids` of `graph` and the links between them.
    pub fn copy<'a>(graph: &Graph, ids: impl IntoIterator<Item = &'a String>) -> Fragment {
        let nodes: BTreeMap<String, NodeDoc> =
            ids.into_iter().filter_map(|id| Some((id.clone(), graph.nodes.get(id)?.clone()))).collect();
        let links = graph
            .links
            .iter()
            .filter(|l| nodes.contains_key(&l.from.node) && nodes.contains_key(&l.to.node))
            .cloned()
            .collect();
        Fragment { nodes, links }
    }

    pub fn is_empty(&self) -> bool {
        self.nodes.is_empty()
    }

    /// The canonical graph text of the fragment (what goes to the system clipboard).
    pub fn to_text(&self) -> String {
        Graph { version: crate::core::graph::CURRENT_VERSION, nodes: self.nodes.clone(), links: self.links.clone() }
            .to_ron()
    }

    /// Reads a fragment from graph text; unknown kinds are refused, missing inputs are fine.
    pub fn from_text(text: &str) -> Result<Fragment, EditError> {
        let (g, _) = Graph::load_lenient(text, Path::new("clipboard"))
            .map_err(|e| EditError::Clipboard(format!("the clipboard does not hold nodes: {e}")))?;
        if g.nodes.is_empty() {
            return Err(EditError::Clipboard("the clipboard holds no nodes".into()));
        }
        if let Some(n) = g.nodes.values().find(|n| spec::find(&n.kind).is_none()) {
            return Err(EditError::UnknownKind(n.kind.clone()));
        }
        Ok(Fragment { nodes: g.nodes, links: g.links })
    }

    /// The top-left corner of the fragment's nodes.
    pub fn origin(&self) -> [f32; 2] {
        let mut o = [f32::INFINITY; 2];
        for n in self.nodes.values() {
            o = [o[0].min(n.pos[0]), o[1].min(n.pos[1])];
        }
        if o[0].is_finite() { o } else { [0.0, 0.0] }
    }
}

/// Inserts a fragment with fresh ids, its top-left corner at `at`; keeps parameters and the
/// links inside it. Returns the new ids, in the fragment's order.
pub fn paste(graph: &mut Graph, fragment: &Fragment, at: [f32; 2]) -> Result<Vec<String>, EditError> {
    paste_mapped(graph, fragment, at).map(|(ids, _)| ids)
}

fn paste_mapped(
    graph: &mut Graph,
    fragment: &Fragment,
    at: [f32; 2],
) -> Result<(Vec<String>, BTreeMap<String, String>), EditError> {
    let origin = fragment.origin();
    let mut g = graph.clone();
    let mut rename = BTreeMap::new();
    let mut ids = Vec::new();
    for (old, node) in &fragment.nodes {
        if spec::find(&node.kind).is_none() {
            return Err(EditError::UnknownKind(node.kind.clone()));
        }
        let id = unique_id(&g, old);
        let pos = [(node.pos[0] - origin[0] + at[0]).round(), (node.pos[1] - origin[1] + at[1]).round()];
        g.nodes.insert(id.clone(), NodeDoc { pos, ..node.clone() });
        rename.insert(old.clone(), id.clone());
        ids.push(id);
    }
    for l in &fragment.links {
        let (Some(f), Some(t)) = (rename.get(&l.from.node), rename.get(&l.to.node)) else { continue };
        let from = PortRef { node: f.clone(), port: l.from.port.clone() };
        let to = PortRef { node: t.clone(), port: l.to.port.clone() };
        // A link that no longer fits (ports renamed since it was copied) is left out.
        let _ = connect(&mut g, &from, &to);
    }
    *graph = g;
    Ok((ids, rename))
}

/// Copies nodes next to themselves, keeping their parameters, the links among them, and
/// the links that feed them from outside (so a duplicated pass sees the same inputs).
pub fn duplicate(graph: &mut Graph, ids: &[String], offset: [f32; 2]) -> Result<Vec<String>, EditError> {
    let fragment = Fragment::copy(graph, ids);
    if fragment.is_empty() {
        return Ok(Vec::new());
    }
    let o = fragment.origin();
    let mut g = graph.clone();
    let (new_ids, rename) = paste_mapped(&mut g, &fragment, [o[0] + offset[0], o[1] + offset[1]])?;
    let incoming: Vec<Link> = graph
        .links
        .iter()
        .filter(|l| fragment.nodes.contains_key(&l.to.node) && !fragment.nodes.contains_key(&l.from.node))
        .cloned()
        .collect();
    for l in incoming {
        if let Some(t) = rename.get(&l.to.node) {
            let _ = connect(&mut g, &l.from, &PortRef { node: t.clone(), port: l.to.port.clone() });
        }
    }
    *graph = g;
    Ok(new_ids)
}

/// Node kinds that can take a wire dropped from an output of type `ty` (`from_output`),
/// or feed an input of type `ty`, with the port to connect.
pub fn compatible_kinds(ty: PortType, from_output: bool) -> Vec<(&'static NodeSpec, &'static str)> {
    spec::all()
        .iter()
        .filter_map(|s| {
            let port = if from_output {
                s.inputs.iter().find(|p| p.ty.accepts(ty))
            } else {
                s.outputs.iter().find(|p| ty.accepts(p.ty))
            };
            port.map(|p| (*s, p.name))
        })
        .collect()
}

/// Where an autosave of `path` goes: `<dir>/<name>.autosave.ron` (git-ignored), or
/// `untitled.autosave.ron` in the working folder for a graph never saved.
pub fn autosave_path(path: Option<&Path>) -> PathBuf {
    match path {
        Some(p) => {
            let stem = p.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_else(|| "graph".into());
            p.with_file_name(format!("{stem}.autosave.ron"))
        }
        None => PathBuf::from("untitled.autosave.ron"),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn p(s: &str) -> PortRef {
        PortRef::parse(s).unwrap()
    }

    fn demo() -> Graph {
        let mut g = Graph::new();
        let a = add_node(&mut g, "Number", [0.0, 0.0]).unwrap();
        let b = add_node(&mut g, "Math", [200.0, 0.0]).unwrap();
        let w = add_node(&mut g, "Watch", [400.0, 0.0]).unwrap();
        connect(&mut g, &p(&format!("{a}.value")), &p(&format!("{b}.a"))).unwrap();
        connect(&mut g, &p(&format!("{b}.result")), &p(&format!("{w}.value"))).unwrap();
        g
    }

    #[test]
    fn ids_are_readable_and_unique() {
        assert_eq!(id_stem("GBufferPass"), "gbuffer_pass");
        assert_eq!(id_stem("OrbitCamera"), "orbit_camera");
        assert_eq!(id_stem("Tonemap"), "tonemap");
        let mut g = Graph::new();
        assert_eq!(add_node(&mut g, "Tonemap", [0.0, 0.0]).unwrap(), "tonemap");
        assert_eq!(add_node(&mut g, "Tonemap", [0.0, 0.0]).unwrap(), "tonemap_2");
        assert_eq!(add_node(&mut g, "Tonemap", [0.0, 0.0]).unwrap(), "tonemap_3");
        assert_eq!(unique_id(&g, "tonemap_2"), "tonemap_4");
        assert!(matches!(add_node(&mut g, "NoSuchKind", [0.0, 0.0]), Err(EditError::UnknownKind(_))));
    }

    #[test]
    fn connect_checks_types_and_replaces_the_old_link() {
        let mut g = demo();
        assert!(g.validate().is_empty(), "{:?}", g.validate());
        let cam = add_node(&mut g, "OrbitCamera", [0.0, 200.0]).unwrap();
        let before = g.clone();
        let err = connect(&mut g, &p(&format!("{cam}.camera")), &p("math.b")).unwrap_err();
        assert!(matches!(err, EditError::IncompatibleTypes { .. }));
        assert_eq!(
            err.to_string(),
            "cannot connect orbit_camera.camera (Camera) to math.b (Scalar): a Scalar input does not accept Camera"
        );
        assert_eq!(g, before, "a refused link changes nothing");
        let n2 = add_node(&mut g, "Number", [0.0, 100.0]).unwrap();
        let old = connect(&mut g, &p(&format!("{n2}.value")), &p("math.a")).unwrap();
        assert_eq!(old, Some(Link { from: p("number.value"), to: p("math.a") }));
        assert_eq!(g.links.iter().filter(|l| l.to == p("math.a")).count(), 1);
        assert!(matches!(connect(&mut g, &p("math.result"), &p("math.a")), Err(EditError::SelfLink(_))));
        assert!(matches!(connect(&mut g, &p("math.valu"), &p("watch.value")), Err(EditError::NoSuchPort { .. })));
        // Surface is a Mesh: the one implicit conversion.
        assert!(PortType::Mesh.accepts(PortType::Surface));
    }

    #[test]
    fn cycles_are_refused() {
        let mut g = Graph::new();
        let a = add_node(&mut g, "Math", [0.0, 0.0]).unwrap();
        let b = add_node(&mut g, "Math", [0.0, 0.0]).unwrap();
        connect(&mut g, &p(&format!("{a}.result")), &p(&format!("{b}.a"))).unwrap();
        let err = connect(&mut g, &p(&format!("{b}.result")), &p(&format!("{a}.a"))).unwrap_err();
        assert!(matches!(err, EditError::Cycle { .. }), "{err}");
        assert!(g.find_cycle().is_none());
    }

    #[test]
    fn remove_takes_the_links_along() {
        let mut g = demo();
        assert_eq!(remove_nodes(&mut g, &["math".to_string()]), 1);
        assert!(g.links.is_empty());
        assert_eq!(g.nodes.len(), 2);
    }

    #[test]
    fn params_are_checked_and_canonical() {
        let mut g = demo();
        set_param(&mut g, "math", "b", ParamValue::Int(2)).unwrap();
        assert_eq!(g.nodes["math"].params["b"], ParamValue::Float(2.0));
        set_param(&mut g, "math", "op", ParamValue::Str("multiply".into())).unwrap();
        assert!(set_param(&mut g, "math", "op", ParamValue::Str("modulo".into())).is_err());
        assert!(set_param(&mut g, "math", "nope", ParamValue::Int(1)).is_err());
        let mut t = Graph::new();
        add_node(&mut t, "Tonemap", [0.0, 0.0]).unwrap();
        let e = set_param(&mut t, "tonemap", "exposure", ParamValue::Float(99.0)).unwrap_err();
        assert!(e.to_string().contains("out of range"), "{e}");
        reset_param(&mut g, "math", "b").unwrap();
        assert!(!g.nodes["math"].params.contains_key("b"));
    }

    #[test]
    fn copy_paste_keeps_params_and_inner_links() {
        let mut g = demo();
        set_param(&mut g, "math", "op", ParamValue::Str("multiply".into())).unwrap();
        let frag = Fragment::copy(&g, &["number".to_string(), "math".to_string()]);
        assert_eq!(frag.links.len(), 1);
        let text = frag.to_text();
        let back = Fragment::from_text(&text).unwrap();
        assert_eq!(back, frag);
        let ids = paste(&mut g, &back, [0.0, 300.0]).unwrap();
        assert_eq!(ids, vec!["math_2".to_string(), "number_2".to_string()]);
        assert_eq!(g.nodes["math_2"].params["op"], ParamValue::Str("multiply".into()));
        assert_eq!(g.nodes["number_2"].pos, [0.0, 300.0]);
        assert_eq!(g.nodes["math_2"].pos, [200.0, 300.0]);
        assert!(g.links.contains(&Link { from: p("number_2.value"), to: p("math_2.a") }));
        assert!(Fragment::from_text("not a graph").is_err());
    }

    #[test]
    fn duplicate_keeps_incoming_links() {
        let mut g = demo();
        let ids = duplicate(&mut g, &["math".to_string()], [0.0, 100.0]).unwrap();
        assert_eq!(ids, vec!["math_2".to_string()]);
        assert!(g.links.contains(&Link { from: p("number.value"), to: p("math_2.a") }));
        assert_eq!(g.nodes["math_2"].pos, [200.0, 100.0]);
        // The output of the copy is free: watch still reads the original.
        assert!(g.links.contains(&Link { from: p("math.result"), to: p("watch.value") }));
    }

    #[test]
    fn insert_on_link_rewires_through_the_node() {
        let mut g = demo();
        let m = add_node(&mut g, "Math", [300.0, 100.0]).unwrap();
        let link = Link { from: p("math.result"), to: p("watch.value") };
        insert_on_link(&mut g, &m, &link).unwrap();
        assert!(!g.links.contains(&link));
        assert!(g.links.contains(&Link { from: p("math.result"), to: p(&format!("{m}.a")) }));
        assert!(g.links.contains(&Link { from: p(&format!("{m}.result")), to: p("watch.value") }));
        let cam = add_node(&mut g, "OrbitCamera", [0.0, 0.0]).unwrap();
        let before = g.clone();
        let link = Link { from: p("number.value"), to: p("math.a") };
        assert!(insert_on_link(&mut g, &cam, &link).is_err());
        assert_eq!(g, before);
    }

    #[test]
    fn compatible_kinds_filters_the_palette() {
        let from_texture = compatible_kinds(PortType::Texture, true);
        assert!(from_texture.iter().any(|(s, port)| s.kind == "Tonemap" && *port == "image"));
        assert!(!from_texture.iter().any(|(s, _)| s.kind == "Number"));
        let into_camera = compatible_kinds(PortType::Camera, false);
        assert!(into_camera.iter().all(|(s, _)| s.outputs.iter().any(|p| p.ty == PortType::Camera)));
    }

    #[test]
    fn autosave_sits_next_to_the_graph() {
        assert_eq!(autosave_path(Some(Path::new("graphs/default.ron"))), PathBuf::from("graphs/default.autosave.ron"));
        assert_eq!(autosave_path(None), PathBuf::from("untitled.autosave.ron"));
    }
}

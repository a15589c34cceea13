//! The document checked against the node registry, and what `check` warns about.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

use super::model::{Graph, Link, PortRef, valid_id};
use super::problem::{Place, Problem, ProblemKind, Warning};
use crate::core::node::Capabilities;
use crate::core::param::{ParamKind, ParamValue};
use crate::core::spec;

impl Graph {
    /// Checks the document against the node registry: kinds, parameters, ports, link
    /// types, required inputs and cycles.
    pub fn validate(&self) -> Vec<Problem> {
        let mut problems = Vec::new();
        for (id, node) in &self.nodes {
            if !valid_id(id) {
                problems.push(
                    Problem::new(
                        ProblemKind::InvalidId,
                        Place::Node(id.clone()),
                        format!("node id \"{id}\" is not valid"),
                    )
                    .help("use letters, digits, '_' and '-' only"),
                );
            }
            let Some(spec) = spec::find(&node.kind) else {
                let mut p = Problem::new(
                    ProblemKind::UnknownKind,
                    Place::Node(id.clone()),
                    format!("unknown node kind \"{}\"", node.kind),
                );
                p.help = Some(match spec::closest(&node.kind, spec::all().iter().map(|s| s.kind)) {
                    Some(k) => format!("did you mean \"{k}\"? (`werkstatt nodes` lists all kinds)"),
                    None => "`werkstatt nodes` lists all kinds".into(),
                });
                problems.push(p);
                continue;
            };
            for (name, value) in &node.params {
                let place = Place::Param(id.clone(), name.clone());
                match spec.param(name) {
                    None => {
                        let mut p = Problem::new(
                            ProblemKind::UnknownParam,
                            place,
                            format!("{} has no parameter \"{name}\"", spec.kind),
                        );
                        p.help = Some(match spec::closest(name, spec.params.iter().map(|p| p.name)) {
                            Some(n) => format!("did you mean \"{n}\"?"),
                            None => format!(
                                "its parameters are: {}",
                                spec.params.iter().map(|p| p.name).collect::<Vec<_>>().join(", ")
                            ),
                        });
                        problems.push(p);
                    }
                    Some((_, ps)) => {
                        if let Err(msg) = ps.kind.check(value) {
                            let kind = if msg.starts_with("expected") {
                                ProblemKind::ParamType
                            } else {
                                ProblemKind::ParamRange
                            };
                            problems.push(Problem::new(kind, place, format!("parameter \"{name}\": {msg}")));
                        }
                    }
                }
            }
        }

        let mut fed: BTreeMap<(&str, &str), usize> = BTreeMap::new();
        for (i, link) in self.links.iter().enumerate() {
            let place = Place::Link(i);
            let from_ty = self.port_type(&link.from, false, &place, &mut problems);
            let to_ty = self.port_type(&link.to, true, &place, &mut problems);
            if let (Some(a), Some(b)) = (from_ty, to_ty)
                && !b.accepts(a)
            {
                let mut problem = Problem::new(
                    ProblemKind::LinkTypeMismatch,
                    place.clone(),
                    format!("cannot link {} ({a}) to {} ({b})", link.from, link.to),
                )
                .port(&link.to.node, &link.to.port);
                if let Some(help) = self.compatible_port(link, a, b) {
                    problem = problem.help(help);
                }
                problems.push(problem);
            }
            if let Some(first) = fed.insert((&link.to.node, &link.to.port), i) {
                problems.push(
                    Problem::new(
                        ProblemKind::InputLinkedTwice,
                        place,
                        format!(
                            "input {} is fed by two links (from {} and {})",
                            link.to, self.links[first].from, link.from
                        ),
                    )
                    .port(&link.to.node, &link.to.port)
                    .help("an input takes one link; remove one of them"),
                );
            }
        }
        for (id, node) in &self.nodes {
            let Some(spec) = spec::find(&node.kind) else { continue };
            for input in spec.inputs.iter().filter(|p| p.required) {
                if !fed.contains_key(&(id.as_str(), input.name)) {
                    problems.push(
                        Problem::new(
                            ProblemKind::MissingInput,
                            Place::Node(id.clone()),
                            format!("required input \"{}\" ({}) is not connected", input.name, input.ty),
                        )
                        .port(id, input.name),
                    );
                }
            }
        }
        if let Some(cycle) = self.find_cycle() {
            let first = cycle[0].clone();
            problems.push(
                Problem::new(
                    ProblemKind::Cycle,
                    Place::Node(first),
                    format!("the links form a cycle: {} -> {}", cycle.join(" -> "), cycle[0]),
                )
                .help("a node's output cannot feed back into its own inputs"),
            );
        }
        problems
    }

    fn port_type(
        &self,
        port: &PortRef,
        input: bool,
        place: &Place,
        problems: &mut Vec<Problem>,
    ) -> Option<crate::core::port::PortType> {
        let Some(node) = self.nodes.get(&port.node) else {
            let mut problem = Problem::new(
                ProblemKind::UnknownNode,
                place.clone(),
                format!("link names node \"{}\", which does not exist", port.node),
            );
            if let Some(n) = spec::closest(&port.node, self.nodes.keys().map(String::as_str)) {
                problem = problem.help(format!("did you mean \"{n}\"?"));
            }
            problems.push(problem);
            return None;
        };
        let spec = spec::find(&node.kind)?;
        let ports = if input { spec.inputs } else { spec.outputs };
        match ports.iter().find(|p| p.name == port.port) {
            Some(p) => Some(p.ty),
            None => {
                let which = if input { "input" } else { "output" };
                let names: Vec<&str> = ports.iter().map(|p| p.name).collect();
                let help = match spec::closest(&port.port, names.iter().copied()) {
                    Some(n) => format!("did you mean \"{n}\"?"),
                    None if names.is_empty() => format!("{} has no {which}s", spec.kind),
                    None => format!("its {which}s are: {}", names.join(", ")),
                };
                problems.push(
                    Problem::new(
                        ProblemKind::UnknownPort,
                        place.clone(),
                        format!("{} has no {which} \"{}\"", spec.kind, port.port),
                    )
                    .port(&port.node, &port.port)
                    .help(help),
                );
                None
            }
        }
    }

    /// For a link of mismatched types, the port that would fit: an input of the target node
    /// that takes the source's type, else an output of the source node the target takes.
    fn compatible_port(
        &self,
        link: &Link,
        from: crate::core::port::PortType,
        to: crate::core::port::PortType,
    ) -> Option<String> {
        let spec_of = |id: &str| self.nodes.get(id).and_then(|n| spec::find(&n.kind));
        let inputs: Vec<String> = spec_of(&link.to.node)?
            .inputs
            .iter()
            .filter(|p| p.ty.accepts(from))
            .map(|p| format!("{}.{}", link.to.node, p.name))
            .collect();
        let outputs: Vec<String> = spec_of(&link.from.node)?
            .outputs
            .iter()
            .filter(|p| to.accepts(p.ty))
            .map(|p| format!("{}.{}", link.from.node, p.name))
            .collect();
        let (fits, what) = if inputs.is_empty() { (outputs, format!("a {to}")) } else { (inputs, format!("a {from}")) };
        match fits.as_slice() {
            [] => None,
            [one] => Some(format!("did you mean {one}? (it takes {what})")),
            many => Some(format!("ports that fit {what}: {}", many.join(", "))),
        }
    }

    /// Files that path parameters name and that do not exist, resolved against `base_dir`
    /// (the graph's folder, as rendering does): `check` and `render` fail on them before any
    /// work. A sequence pattern (frame_%04d.obj, frame_####.obj, frame_*.obj) needs its
    /// folder. The help suggests the closest name in that folder.
    pub fn missing_files(&self, base_dir: &Path) -> Vec<Warning> {
        let mut out = Vec::new();
        for (id, node) in &self.nodes {
            let Some(spec) = spec::find(&node.kind) else { continue };
            for p in spec.params.iter().filter(|p| matches!(p.kind, ParamKind::Path { .. })) {
                let Some(ParamValue::Str(text)) = node.params.get(p.name) else { continue };
                if text.is_empty() {
                    continue;
                }
                let path = base_dir.join(text);
                let is_pattern = crate::core::resources::is_file_pattern(text);
                let must_exist = if is_pattern { path.parent().unwrap_or(base_dir) } else { &path };
                if !must_exist.exists() {
                    out.push(Warning {
                        place: Place::Param(id.clone(), p.name.to_string()),
                        node: id.clone(),
                        kind: spec.kind,
                        message: format!("parameter \"{}\": no such file: {}", p.name, must_exist.display()),
                        help: closest_file(must_exist, text),
                    });
                }
            }
        }
        out
    }

    /// What `check` warns about but does not fail on: nodes that cannot finish a batch render.
    pub fn warnings(&self) -> Vec<Warning> {
        let mut out = Vec::new();
        for (id, node) in &self.nodes {
            let Some(spec) = spec::find(&node.kind) else { continue };
            if spec.has(Capabilities::EXTERNAL_SOURCE) {
                out.push(Warning {
                    place: Place::Node(id.clone()),
                    node: id.clone(),
                    kind: spec.kind,
                    message: "waits for a simulator to connect: `werkstatt render` fails unless one sends frames"
                        .into(),
                    help: spec.capabilities.batch_help().map(Into::into),
                });
            }
        }
        out
    }

    /// A cycle through the links, as the node ids along it, if there is one.
    pub fn find_cycle(&self) -> Option<Vec<String>> {
        let mut succ: BTreeMap<&str, BTreeSet<&str>> = BTreeMap::new();
        // A link to or from a node that does not exist is an error of its own, not part of a cycle.
        for l in
            self.links.iter().filter(|l| self.nodes.contains_key(&l.from.node) && self.nodes.contains_key(&l.to.node))
        {
            succ.entry(&l.from.node).or_default().insert(&l.to.node);
        }
        // Iterative DFS with colours; the grey stack is the current path.
        let mut colour: BTreeMap<&str, u8> = BTreeMap::new();
        for start in self.nodes.keys() {
            if colour.contains_key(start.as_str()) {
                continue;
            }
            let mut stack: Vec<(&str, Vec<&str>)> =
                vec![(start, succ.get(start.as_str()).map(|s| s.iter().copied().collect()).unwrap_or_default())];
            colour.insert(start, 1);
            while let Some((node, next)) = stack.last_mut() {
                let node = *node;
                match next.pop() {
                    Some(n) => match colour.get(n) {
                        Some(1) => {
                            let pos = stack.iter().position(|(s, _)| *s == n).unwrap_or(0);
                            return Some(stack[pos..].iter().map(|(s, _)| s.to_string()).collect());
                        }
                        Some(_) => {}
                        None => {
                            colour.insert(n, 1);
                            stack.push((n, succ.get(n).map(|s| s.iter().copied().collect()).unwrap_or_default()));
                        }
                    },
                    None => {
                        colour.insert(node, 2);
                        stack.pop();
                    }
                }
            }
        }
        None
    }
}

/// "did you mean ...?" for a missing file: the closest name in the nearest folder that exists,
/// written as the parameter would be (`written` with its last part replaced).
fn closest_file(missing: &Path, written: &str) -> Option<String> {
    let mut missing = missing.to_path_buf();
    let mut written = written.trim_end_matches('/').to_string();
    // Walk up to the first folder that exists; the name below it is what was misspelt.
    loop {
        let (Some(parent), Some(name)) = (missing.parent(), missing.file_name()) else { return None };
        if parent.as_os_str().is_empty() || parent.is_dir() {
            let folder = if parent.as_os_str().is_empty() { Path::new(".") } else { parent };
            let mut names: Vec<String> = std::fs::read_dir(folder)
                .ok()?
                .filter_map(|e| e.ok().map(|e| e.file_name().to_string_lossy().into_owned()))
                .collect();
            // Sorted, so that of two equally close names the same one is suggested every time.
            names.sort();
            let best = spec::closest(&name.to_string_lossy(), names.iter().map(String::as_str))?;
            let prefix = written.rfind('/').map_or("", |i| &written[..=i]);
            return Some(format!("did you mean \"{prefix}{best}\"?"));
        }
        missing = parent.to_path_buf();
        written = written.rfind('/').map_or(String::new(), |i| written[..i].to_string());
    }
}

//! Graph documents: the `.ron` file model, its canonical writer, migrations and validation.
//!
//! A graph file looks like this (the canonical form `werkstatt fmt` writes):
//!
//! ```ron
//! (
//!     version: 1,
//!     nodes: {
//!         "camera": (
//!             kind: "OrbitCamera",
//!             pos: (40.0, 120.0),
//!             params: {
//!                 "distance": 3.0,
//!             },
//!         ),
//!     },
//!     links: [
//!         ("camera.camera", "gbuffer.camera"),
//!     ],
//! )
//! ```

use std::collections::{BTreeMap, BTreeSet};
use std::fmt::{self, Write as _};
use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};

use crate::core::param::{ParamKind, ParamValue};
use crate::core::spec;

/// The file format version this build writes.
pub const CURRENT_VERSION: u32 = 1;

#[derive(Clone, Debug, PartialEq)]
pub struct Graph {
    pub version: u32,
    pub nodes: BTreeMap<String, NodeDoc>,
    pub links: Vec<Link>,
}

#[derive(Clone, Debug, PartialEq)]
pub struct NodeDoc {
    pub kind: String,
    /// Position on the editor canvas.
    pub pos: [f32; 2],
    /// The parameters the file sets; the others take their spec's default.
    pub params: BTreeMap<String, ParamValue>,
}

#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct PortRef {
    pub node: String,
    pub port: String,
}

impl PortRef {
    pub fn parse(text: &str) -> Option<PortRef> {
        let (node, port) = text.split_once('.')?;
        (valid_id(node) && !port.is_empty()).then(|| PortRef { node: node.into(), port: port.into() })
    }
}

impl fmt::Display for PortRef {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}.{}", self.node, self.port)
    }
}

#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub struct Link {
    pub from: PortRef,
    pub to: PortRef,
}

/// Node ids are used in `node.port` references and file names, so keep them plain.
pub fn valid_id(id: &str) -> bool {
    !id.is_empty() && id.chars().all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '-')
}

// ---------------------------------------------------------------------------
// Problems and their places
// ---------------------------------------------------------------------------

/// What is wrong, independent of where it is written.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum ProblemKind {
    Syntax,
    Io,
    VersionTooNew,
    /// An older format version that no migration upgrades.
    VersionUnsupported,
    DuplicateId,
    InvalidId,
    UnknownKind,
    UnknownParam,
    ParamType,
    ParamRange,
    BadLinkSyntax,
    UnknownNode,
    UnknownPort,
    LinkTypeMismatch,
    InputLinkedTwice,
    MissingInput,
    Cycle,
}

/// Where a problem sits in the document, used to find its line and column.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Place {
    File,
    Node(String),
    Param(String, String),
    Link(usize),
}

#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Problem {
    pub kind: ProblemKind,
    pub place: Place,
    /// The node and port the problem is about, when there is one.
    pub node: Option<String>,
    pub port: Option<String>,
    pub message: String,
    pub help: Option<String>,
}

impl Problem {
    fn new(kind: ProblemKind, place: Place, message: impl Into<String>) -> Self {
        let node = match &place {
            Place::Node(n) | Place::Param(n, _) => Some(n.clone()),
            _ => None,
        };
        Problem { kind, place, node, port: None, message: message.into(), help: None }
    }
    fn port(mut self, node: &str, port: &str) -> Self {
        self.node = Some(node.into());
        self.port = Some(port.into());
        self
    }
    fn help(mut self, help: impl Into<String>) -> Self {
        self.help = Some(help.into());
        self
    }
}

/// A problem with its file position, ready to print.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Diagnostic {
    pub file: PathBuf,
    pub line: usize,
    pub col: usize,
    pub problem: Problem,
}

impl fmt::Display for Diagnostic {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}:{}: error", self.file.display(), self.line, self.col)?;
        match (&self.problem.node, &self.problem.port) {
            (Some(n), Some(p)) => write!(f, " in node \"{n}\", port \"{p}\"")?,
            (Some(n), None) => write!(f, " in node \"{n}\"")?,
            _ => {}
        }
        write!(f, ": {}", self.problem.message)?;
        if let Some(help) = &self.problem.help {
            write!(f, "\n  help: {help}")?;
        }
        Ok(())
    }
}

/// Something `check` warns about without failing (see [`Graph::warnings`]).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Warning {
    pub place: Place,
    pub node: String,
    pub kind: &'static str,
    pub message: String,
    pub help: Option<String>,
}

impl Warning {
    /// Line and column of the warning's place in `source`, the graph's text.
    pub fn line_col(&self, source: &str) -> (usize, usize) {
        SourceMap::new(source).locate(&self.place)
    }
}

impl fmt::Display for Warning {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "node \"{}\" ({}): {}", self.node, self.kind, self.message)?;
        if let Some(help) = &self.help {
            write!(f, "; {help}")?;
        }
        Ok(())
    }
}

/// All problems of one file.
#[derive(Debug)]
pub struct LoadError {
    pub diagnostics: Vec<Diagnostic>,
}

impl fmt::Display for LoadError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        for (i, d) in self.diagnostics.iter().enumerate() {
            if i > 0 {
                writeln!(f)?;
            }
            write!(f, "{d}")?;
        }
        Ok(())
    }
}

impl std::error::Error for LoadError {}

// ---------------------------------------------------------------------------
// Parsing
// ---------------------------------------------------------------------------

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawGraph {
    version: u32,
    #[serde(default)]
    nodes: RawEntries<RawNode>,
    #[serde(default)]
    links: Vec<(String, String)>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct RawNode {
    kind: String,
    #[serde(default)]
    pos: (f32, f32),
    #[serde(default)]
    params: RawEntries<ParamValue>,
}

/// Only the version, read first so that a newer file is refused before its contents are.
#[derive(Deserialize)]
struct VersionProbe {
    version: u32,
}

/// A map read in file order with duplicates kept, so that a repeated id is an error
/// instead of the last one silently winning.
struct RawEntries<T>(Vec<(String, T)>);

impl<T> Default for RawEntries<T> {
    fn default() -> Self {
        RawEntries(Vec::new())
    }
}

impl<'de, T: Deserialize<'de>> Deserialize<'de> for RawEntries<T> {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V<T>(std::marker::PhantomData<T>);
        impl<'de, T: Deserialize<'de>> Visitor<'de> for V<T> {
            type Value = RawEntries<T>;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a map of \"name\": value entries")
            }
            fn visit_map<A: MapAccess<'de>>(self, mut map: A) -> Result<Self::Value, A::Error> {
                let mut entries = Vec::new();
                while let Some((k, v)) = map.next_entry::<String, T>()? {
                    entries.push((k, v));
                }
                Ok(RawEntries(entries))
            }
        }
        d.deserialize_map(V(std::marker::PhantomData))
    }
}

impl<'de> Deserialize<'de> for ParamValue {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        struct V;
        impl<'de> Visitor<'de> for V {
            type Value = ParamValue;
            fn expecting(&self, f: &mut fmt::Formatter) -> fmt::Result {
                f.write_str("a number, bool, string or list of numbers")
            }
            fn visit_bool<E>(self, v: bool) -> Result<ParamValue, E> {
                Ok(ParamValue::Bool(v))
            }
            fn visit_i64<E>(self, v: i64) -> Result<ParamValue, E> {
                Ok(ParamValue::Int(v))
            }
            fn visit_u64<E: de::Error>(self, v: u64) -> Result<ParamValue, E> {
                i64::try_from(v).map(ParamValue::Int).map_err(|_| E::custom("integer too large"))
            }
            fn visit_f64<E>(self, v: f64) -> Result<ParamValue, E> {
                Ok(ParamValue::Float(v))
            }
            fn visit_str<E>(self, v: &str) -> Result<ParamValue, E> {
                Ok(ParamValue::Str(v.to_string()))
            }
            fn visit_string<E>(self, v: String) -> Result<ParamValue, E> {
                Ok(ParamValue::Str(v))
            }
            fn visit_seq<A: SeqAccess<'de>>(self, mut seq: A) -> Result<ParamValue, A::Error> {
                let mut out = Vec::new();
                while let Some(x) = seq.next_element::<f64>()? {
                    out.push(x);
                }
                Ok(ParamValue::Vec(out))
            }
        }
        d.deserialize_any(V)
    }
}

/// A step that upgrades a document from `from` to `from + 1`.
pub struct Migration {
    pub from: u32,
    pub note: &'static str,
    pub apply: fn(&mut Graph),
}

/// Every format change adds an entry here; old files then keep opening.
pub const MIGRATIONS: &[Migration] = &[];

/// Upgrades `graph` to `target` with `table`, returning the notes of the applied steps.
pub fn migrate(graph: &mut Graph, target: u32, table: &[Migration]) -> Result<Vec<&'static str>, String> {
    let mut notes = Vec::new();
    while graph.version < target {
        let step = table
            .iter()
            .find(|m| m.from == graph.version)
            .ok_or_else(|| format!("no migration from version {} (this build reads {target})", graph.version))?;
        (step.apply)(graph);
        notes.push(step.note);
        graph.version += 1;
    }
    Ok(notes)
}

impl Graph {
    pub fn new() -> Self {
        Graph { version: CURRENT_VERSION, nodes: BTreeMap::new(), links: Vec::new() }
    }

    /// Reads and validates a graph file. All problems found are reported together.
    pub fn load(path: &Path) -> Result<Graph, LoadError> {
        let error = |line, col, message: String| LoadError {
            diagnostics: vec![Diagnostic {
                file: path.to_path_buf(),
                line,
                col,
                problem: Problem::new(ProblemKind::Io, Place::File, format!("cannot read the file: {message}")),
            }],
        };
        let bytes = std::fs::read(path).map_err(|e| error(0, 0, e.to_string()))?;
        // Text that is not UTF-8 is reported at its first bad byte.
        let source = String::from_utf8(bytes).map_err(|e| {
            let valid = std::str::from_utf8(&e.as_bytes()[..e.utf8_error().valid_up_to()]).unwrap_or_default();
            let (line, col) = SourceMap::new(valid).line_col(valid.len());
            error(line, col, "stream did not contain valid UTF-8".into())
        })?;
        Graph::load_str(&source, path)
    }

    /// Parses and validates `source`; `path` is used in messages only.
    pub fn load_str(source: &str, path: &Path) -> Result<Graph, LoadError> {
        let (graph, diagnostics) = Graph::load_lenient(source, path)?;
        if diagnostics.is_empty() { Ok(graph) } else { Err(LoadError { diagnostics }) }
    }

    /// Parses `source` like [`Graph::load_str`], but returns the graph together with its
    /// problems instead of refusing it, so that the editor can open a graph with, say, an
    /// unconnected input and let the user fix it. Only text that is not a graph (syntax errors,
    /// a newer format version) is an error.
    pub fn load_lenient(source: &str, path: &Path) -> Result<(Graph, Vec<Diagnostic>), LoadError> {
        let (graph, mut problems, link_rows) = Graph::parse_unvalidated(source)
            .map_err(|d| LoadError { diagnostics: vec![Diagnostic { file: path.to_path_buf(), ..d }] })?;
        // validate() numbers the well-formed links; point back at their rows in the file.
        problems.extend(graph.validate().into_iter().map(|mut p| {
            if let Place::Link(i) = p.place {
                p.place = Place::Link(link_rows.get(i).copied().unwrap_or(i));
            }
            p
        }));
        let map = SourceMap::new(source);
        let diagnostics = problems
            .into_iter()
            .map(|problem| {
                let (line, col) = map.locate(&problem.place);
                Diagnostic { file: path.to_path_buf(), line, col, problem }
            })
            .collect();
        Ok((graph, diagnostics))
    }

    /// Parses without validating the nodes against the registry; returns the problems
    /// (duplicates, bad link syntax) that the document model cannot hold.
    /// Also returns, for each kept link, its index among the file's links.
    #[allow(clippy::result_large_err)] // built once per load, on the error path only
    fn parse_unvalidated(source: &str) -> Result<(Graph, Vec<Problem>, Vec<usize>), Diagnostic> {
        let syntax = |e: ron::error::SpannedError| Diagnostic {
            file: PathBuf::new(),
            line: e.span.start.line,
            col: e.span.start.col,
            problem: Problem::new(ProblemKind::Syntax, Place::File, e.code.to_string()),
        };
        let probe: VersionProbe = ron::from_str(source).map_err(syntax)?;
        if probe.version > CURRENT_VERSION {
            let line = source.lines().position(|l| l.contains("version")).map_or(1, |i| i + 1);
            return Err(Diagnostic {
                file: PathBuf::new(),
                line,
                col: 1,
                problem: Problem::new(
                    ProblemKind::VersionTooNew,
                    Place::File,
                    format!("the file has format version {}, newer than this build's {CURRENT_VERSION}", probe.version),
                )
                .help("update werkstatt to open it"),
            });
        }
        let raw: RawGraph = ron::from_str(source).map_err(syntax)?;
        let mut problems = Vec::new();
        let mut nodes = BTreeMap::new();
        for (id, node) in raw.nodes.0 {
            let mut params = BTreeMap::new();
            for (name, value) in node.params.0 {
                if params.insert(name.clone(), value).is_some() {
                    problems.push(Problem::new(
                        ProblemKind::DuplicateId,
                        Place::Param(id.clone(), name.clone()),
                        format!("parameter \"{name}\" is set twice"),
                    ));
                }
            }
            let doc = NodeDoc { kind: node.kind, pos: [node.pos.0, node.pos.1], params };
            if nodes.insert(id.clone(), doc).is_some() {
                problems.push(
                    Problem::new(
                        ProblemKind::DuplicateId,
                        Place::Node(id.clone()),
                        format!("node id \"{id}\" is used twice"),
                    )
                    .help("give each node its own id"),
                );
            }
        }
        let mut links = Vec::new();
        let mut link_rows = Vec::new();
        for (i, (from, to)) in raw.links.into_iter().enumerate() {
            match (PortRef::parse(&from), PortRef::parse(&to)) {
                (Some(from), Some(to)) => {
                    links.push(Link { from, to });
                    link_rows.push(i);
                }
                _ => problems.push(
                    Problem::new(
                        ProblemKind::BadLinkSyntax,
                        Place::Link(i),
                        format!("link (\"{from}\", \"{to}\") is malformed"),
                    )
                    .help("links are written (\"node.output\", \"node.input\")"),
                ),
            }
        }
        let mut graph = Graph { version: raw.version, nodes, links };
        // An older version without a migration is not "too new": it cannot be upgraded.
        migrate(&mut graph, CURRENT_VERSION, MIGRATIONS).map_err(|message| Diagnostic {
            file: PathBuf::new(),
            line: source.lines().position(|l| l.contains("version")).map_or(1, |i| i + 1),
            col: 1,
            problem: Problem::new(ProblemKind::VersionUnsupported, Place::File, message),
        })?;
        Ok((graph, problems, link_rows))
    }

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
            problems.push(Problem::new(
                ProblemKind::UnknownNode,
                place.clone(),
                format!("link names node \"{}\", which does not exist", port.node),
            ));
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

    /// What `check` warns about but does not fail on: files a path parameter names that do
    /// not exist (yet: a simulator may write them later), and nodes that cannot finish a batch
    /// render. Paths are resolved against `base_dir`, the graph's folder, as rendering does.
    pub fn warnings(&self, base_dir: &Path) -> Vec<Warning> {
        let mut out = Vec::new();
        for (id, node) in &self.nodes {
            let Some(spec) = spec::find(&node.kind) else { continue };
            for p in spec.params.iter().filter(|p| matches!(p.kind, ParamKind::Path { .. })) {
                let Some(ParamValue::Str(text)) = node.params.get(p.name) else { continue };
                if text.is_empty() {
                    continue;
                }
                let path = base_dir.join(text);
                // A sequence pattern (frame_%04d.obj, frame_####.obj, frame_*.obj) names its folder.
                let is_pattern = crate::core::resources::is_file_pattern(text);
                let must_exist = if is_pattern { path.parent().unwrap_or(base_dir) } else { &path };
                if !must_exist.exists() {
                    out.push(Warning {
                        place: Place::Param(id.clone(), p.name.to_string()),
                        node: id.clone(),
                        kind: spec.kind,
                        message: format!("parameter \"{}\": no such file: {}", p.name, must_exist.display()),
                        help: None,
                    });
                }
            }
            if spec.kind == crate::nodes::mesh::live_link::LIVE_LINK.kind {
                out.push(Warning {
                    place: Place::Node(id.clone()),
                    node: id.clone(),
                    kind: spec.kind,
                    message: "waits for a simulator to connect: `werkstatt render` fails unless one sends frames"
                        .into(),
                    help: Some(crate::nodes::mesh::live_link::RECORD_HELP.into()),
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

    /// The canonical text: sorted ids, parameters and links, four-space indents,
    /// floats in their shortest exact form. `load` then `to_ron` gives back the same bytes.
    pub fn to_ron(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "(\n    version: {},\n    nodes: {{", self.version);
        for (id, node) in &self.nodes {
            let _ = writeln!(out, "        {}: (", quote(id));
            let _ = writeln!(out, "            kind: {},", quote(&node.kind));
            // Positions are f32: print them as f32 so 0.1 stays 0.1.
            let _ = writeln!(out, "            pos: ({:?}, {:?}),", node.pos[0], node.pos[1]);
            if node.params.is_empty() {
                out.push_str("            params: {},\n");
            } else {
                out.push_str("            params: {\n");
                for (name, value) in &node.params {
                    let _ = writeln!(out, "                {}: {},", quote(name), value_ron(value));
                }
                out.push_str("            },\n");
            }
            out.push_str("        ),\n");
        }
        out.push_str("    },\n");
        let mut links = self.links.clone();
        links.sort();
        if links.is_empty() {
            out.push_str("    links: [],\n");
        } else {
            out.push_str("    links: [\n");
            for l in &links {
                let _ = writeln!(out, "        ({}, {}),", quote(&l.from.to_string()), quote(&l.to.to_string()));
            }
            out.push_str("    ],\n");
        }
        out.push_str(")\n");
        out
    }

    /// Writes the canonical text atomically: a temporary file in the same folder, then a rename,
    /// so a crash mid-save never leaves a half-written graph.
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        crate::io::atomic::write_atomic(path, self.to_ron().as_bytes())
    }

    /// The value of a parameter: the file's, or the spec's default.
    pub fn param(&self, node: &str, name: &str) -> Option<ParamValue> {
        let doc = self.nodes.get(node)?;
        if let Some(v) = doc.params.get(name) {
            return Some(v.clone());
        }
        spec::find(&doc.kind)?.param(name).map(|(_, p)| p.kind.default_value())
    }

    /// Applies `node.param=value` from the command line, checked against the spec.
    pub fn set_from_cli(&mut self, assignment: &str) -> Result<(), String> {
        let (target, value) =
            assignment.split_once('=').ok_or_else(|| format!("--set \"{assignment}\": expected node.param=value"))?;
        let (id, name) =
            target.split_once('.').ok_or_else(|| format!("--set \"{assignment}\": expected node.param=value"))?;
        let hint = |wanted: &str, names: Vec<&str>| match spec::closest(wanted, names.iter().copied()) {
            Some(n) => format!("did you mean \"{n}\"?"),
            None => format!("the choices are: {}", names.join(", ")),
        };
        let ids: Vec<&str> = self.nodes.keys().map(String::as_str).collect();
        let Some(node) = self.nodes.get(id) else {
            return Err(format!("--set {target}: there is no node \"{id}\"; {}", hint(id, ids)));
        };
        let spec =
            spec::find(&node.kind).ok_or_else(|| format!("--set: node \"{id}\" has unknown kind {}", node.kind))?;
        let (_, ps) = spec.param(name).ok_or_else(|| {
            format!(
                "--set {target}: {} (node \"{id}\") has no parameter \"{name}\"; {}",
                spec.kind,
                hint(name, spec.params.iter().map(|p| p.name).collect())
            )
        })?;
        let node = self.nodes.get_mut(id).expect("found above");
        let parsed = ps.kind.parse_cli(value).map_err(|e| format!("--set {id}.{name}: {e}"))?;
        node.params.insert(name.to_string(), parsed);
        Ok(())
    }
}

impl Default for Graph {
    fn default() -> Self {
        Graph::new()
    }
}

fn quote(s: &str) -> String {
    // Rust's debug escapes (\", \\, \n, \u{..}) are valid RON string escapes.
    format!("{s:?}")
}

fn float(v: f64) -> String {
    // `{:?}` is the shortest text that parses back to the same bits, and always has a '.' or 'e'.
    format!("{v:?}")
}

fn value_ron(v: &ParamValue) -> String {
    match v {
        ParamValue::Bool(b) => b.to_string(),
        ParamValue::Int(i) => i.to_string(),
        ParamValue::Float(f) => float(*f),
        ParamValue::Str(s) => quote(s),
        ParamValue::Vec(v) => format!("[{}]", v.iter().map(|x| float(*x)).collect::<Vec<_>>().join(", ")),
    }
}

/// Finds where ids, parameters and links are written, for error positions. RON values carry
/// no spans, so this scans the text once, skipping comments, for the string keys (decoded, with
/// their nesting depth: node ids sit directly in the `nodes` map, parameter names two levels
/// deeper) and the entries of the `links` list.
struct SourceMap<'a> {
    source: &'a str,
    /// Every string literal followed by `:`, as (offset, depth, value).
    keys: Vec<(usize, usize, String)>,
    /// Where each entry of the top-level `links` list starts.
    links: Vec<usize>,
}

/// The depth of node ids: inside the graph's `(` and the `nodes` map's `{`.
const NODE_DEPTH: usize = 2;
/// The depth of parameter names: inside the node's `(` and its `params` map's `{`.
const PARAM_DEPTH: usize = 4;

impl<'a> SourceMap<'a> {
    fn new(source: &'a str) -> Self {
        let b = source.as_bytes();
        let ident = |c: u8| c.is_ascii_alphanumeric() || c == b'_';
        let (mut keys, mut links) = (Vec::new(), Vec::new());
        let (mut i, mut depth) = (0, 0usize);
        // After the top-level `links` key: waiting for its list, then inside it.
        let (mut links_key, mut in_links) = (false, false);
        while i < b.len() {
            let c = b[i];
            // (Identifiers are skipped whole, so an `r` inside one does not start a raw string.)
            if let Some(end) = string_end(b, i) {
                if b.get(skip_trivia(b, end)) == Some(&b':')
                    && let Ok(value) = ron::from_str::<String>(&source[i..end])
                {
                    keys.push((i, depth, value));
                }
                i = end;
                continue;
            }
            match c {
                b'/' if matches!(b.get(i + 1), Some(b'/' | b'*')) => {
                    i = skip_trivia(b, i);
                    continue;
                }
                b'(' | b'[' | b'{' => {
                    if c == b'(' && in_links && depth == 2 {
                        links.push(i);
                    }
                    if c == b'[' && links_key && depth == 1 {
                        (links_key, in_links) = (false, true);
                    }
                    depth += 1;
                }
                b')' | b']' | b'}' => {
                    depth = depth.saturating_sub(1);
                    if depth == 1 {
                        in_links = false;
                    }
                }
                _ if ident(c) => {
                    let start = i;
                    while i < b.len() && ident(b[i]) {
                        i += 1;
                    }
                    if depth == 1 && &b[start..i] == b"links" {
                        links_key = true;
                    }
                    continue;
                }
                _ => {}
            }
            i += 1;
        }
        SourceMap { source, keys, links }
    }

    fn locate(&self, place: &Place) -> (usize, usize) {
        let offset = match place {
            Place::File => Some(0),
            Place::Node(id) => self.node_offsets(id).next(),
            // A repeated id keeps its last entry, so look in every entry written with that id.
            Place::Param(id, name) => self.node_offsets(id).find_map(|start| {
                let end =
                    self.keys.iter().find(|k| k.0 > start && k.1 == NODE_DEPTH).map_or(self.source.len(), |k| k.0);
                self.keys
                    .iter()
                    .find(|k| (start..end).contains(&k.0) && k.1 == PARAM_DEPTH && k.2 == *name)
                    .map(|k| k.0)
            }),
            Place::Link(i) => self.links.get(*i).copied(),
        };
        self.line_col(offset.unwrap_or(0))
    }

    /// Where each entry of the node `id` starts (more than one if the id is repeated).
    fn node_offsets(&self, id: &str) -> impl Iterator<Item = usize> {
        self.keys.iter().filter(move |k| k.1 == NODE_DEPTH && k.2 == id).map(|k| k.0)
    }

    fn line_col(&self, offset: usize) -> (usize, usize) {
        let before = &self.source[..offset.min(self.source.len())];
        let line = before.matches('\n').count() + 1;
        let col = before.rfind('\n').map_or(before.chars().count(), |nl| before[nl + 1..].chars().count()) + 1;
        (line, col)
    }
}

/// The end of the string literal (`"..."` or `r#"..."#`) that starts at `i`, if one does.
fn string_end(b: &[u8], i: usize) -> Option<usize> {
    match b[i] {
        b'"' => {
            let mut j = i + 1;
            while j < b.len() && b[j] != b'"' {
                j += if b[j] == b'\\' { 2 } else { 1 };
            }
            Some((j + 1).min(b.len()))
        }
        b'r' => {
            let hashes = b[i + 1..].iter().take_while(|&&c| c == b'#').count();
            if b.get(i + 1 + hashes) != Some(&b'"') {
                return None;
            }
            let close: Vec<u8> = std::iter::once(b'"').chain(std::iter::repeat_n(b'#', hashes)).collect();
            let body = i + 2 + hashes;
            let end = b[body..].windows(close.len()).position(|w| w == close.as_slice());
            Some(end.map_or(b.len(), |e| body + e + close.len()))
        }
        _ => None,
    }
}

/// The offset of the first byte at or after `i` that is not white space or in a comment.
fn skip_trivia(b: &[u8], mut i: usize) -> usize {
    loop {
        match (b.get(i), b.get(i + 1)) {
            (Some(c), _) if c.is_ascii_whitespace() => i += 1,
            (Some(b'/'), Some(b'/')) => i = b[i..].iter().position(|&c| c == b'\n').map_or(b.len(), |n| i + n),
            (Some(b'/'), Some(b'*')) => {
                // Block comments nest.
                let mut depth = 0;
                while i < b.len() {
                    if b[i..].starts_with(b"/*") {
                        (depth, i) = (depth + 1, i + 2);
                    } else if b[i..].starts_with(b"*/") {
                        (depth, i) = (depth - 1, i + 2);
                        if depth == 0 {
                            break;
                        }
                    } else {
                        i += 1;
                    }
                }
            }
            _ => return i,
        }
    }
}

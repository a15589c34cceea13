//! Text to document: RON through serde, maps read in file order with duplicates kept, then
//! validation; every problem located in the text.

use std::collections::BTreeMap;
use std::fmt;
use std::path::{Path, PathBuf};

use serde::Deserialize;
use serde::de::{self, Deserializer, MapAccess, SeqAccess, Visitor};

use super::migrate::{MIGRATIONS, migrate};
use super::model::{CURRENT_VERSION, Graph, Link, NodeDoc, PortRef};
use super::problem::{Diagnostic, LoadError, Place, Problem, ProblemKind};
use super::source::SourceMap;
use crate::core::param::ParamValue;

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

impl Graph {
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
        migrate(&mut graph, CURRENT_VERSION, MIGRATIONS).map_err(|e| Diagnostic {
            file: PathBuf::new(),
            line: source.lines().position(|l| l.contains("version")).map_or(1, |i| i + 1),
            col: 1,
            problem: Problem::new(ProblemKind::VersionUnsupported, Place::File, e.to_string()),
        })?;
        Ok((graph, problems, link_rows))
    }
}

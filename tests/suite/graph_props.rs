//! Property tests of the graph loader and validator: mutated versions of every graph in graphs/
//! and graphs generated from the node registry, valid and invalid. Loading never panics, every
//! error names its place (file:line:col pointing at the node id, parameter or link it is about,
//! and the node and port where there is one), and a graph that loads writes canonical text that
//! loads back to the same text.
//!
//! The runs are deterministic (a fixed seed, no failure files); `PROPTEST_CASES` and
//! `PROPTEST_RNG_SEED` override the case count and the seed for a longer local search.

use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use proptest::prelude::*;
use proptest::test_runner::{Config, RngSeed};
use werkstatt::core::graph::{Graph, Link, NodeDoc, Place, PortRef, Problem, ProblemKind};
use werkstatt::core::node::NodeSpec;
use werkstatt::core::param::{ParamKind, ParamValue};
use werkstatt::core::spec;

use crate::common;

const SEED: u64 = 0x5eed_9a0f_0a0f;

fn config(cases: u32) -> Config {
    // Config::default() reads the PROPTEST_* variables; without them the run is fixed.
    let env = Config::default();
    Config {
        cases: if std::env::var_os("PROPTEST_CASES").is_some() { env.cases } else { cases },
        rng_seed: if std::env::var_os("PROPTEST_RNG_SEED").is_some() { env.rng_seed } else { RngSeed::Fixed(SEED) },
        failure_persistence: None,
        ..env
    }
}

/// The graphs in graphs/, as (file name, text).
fn real_graphs() -> &'static [(String, String)] {
    static GRAPHS: OnceLock<Vec<(String, String)>> = OnceLock::new();
    GRAPHS.get_or_init(|| {
        let mut files: Vec<PathBuf> = std::fs::read_dir(common::root().join("graphs"))
            .unwrap()
            .map(|e| e.unwrap().path())
            .filter(|p| p.extension().is_some_and(|e| e == "ron"))
            .collect();
        files.sort();
        assert!(files.len() >= 10, "graphs/ holds the example graphs");
        files
            .into_iter()
            .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read_to_string(&p).unwrap()))
            .collect()
    })
}

/// Every name the registry knows (kinds, ports, parameters, choices), to swap into files.
fn registry_names() -> &'static [&'static str] {
    static NAMES: OnceLock<Vec<&'static str>> = OnceLock::new();
    NAMES.get_or_init(|| {
        let mut names = Vec::new();
        for s in spec::all() {
            names.push(s.kind);
            names.extend(s.inputs.iter().chain(s.outputs).map(|p| p.name));
            for p in s.params {
                names.push(p.name);
                if let ParamKind::Choice { options, .. } = p.kind {
                    names.extend(options.iter().copied());
                }
            }
        }
        names.sort();
        names.dedup();
        names
    })
}

// ---------------------------------------------------------------------------
// The property
// ---------------------------------------------------------------------------

/// The text from a 1-based line and column (columns count characters) to the end.
fn text_at(source: &str, line: usize, col: usize) -> Option<&str> {
    let mut start = 0;
    for _ in 1..line.checked_sub(1)? + 1 {
        start += source[start..].find('\n')? + 1;
    }
    let l = source[start..].split('\n').next()?;
    let at = l.char_indices().map(|(i, _)| i).chain([l.len()]).nth(col.checked_sub(1)?)?;
    Some(&source[start + at..])
}

/// The value `text` starts with (a string literal, a link's tuple), read by RON.
fn value_at<T: serde::de::DeserializeOwned>(text: &str) -> Option<T> {
    T::deserialize(&mut ron::Deserializer::from_str(text).ok()?).ok()
}

/// The file's links, as written.
fn links_of(source: &str) -> Vec<(String, String)> {
    #[derive(serde::Deserialize)]
    struct Links {
        #[serde(default)]
        links: Vec<(String, String)>,
    }
    ron::from_str::<Links>(source).map(|l| l.links).unwrap_or_default()
}

/// Loads `bytes` as the file `path` and checks what comes back.
fn check_load(path: &Path, bytes: &[u8]) -> Result<(), TestCaseError> {
    let (source, result) = match std::str::from_utf8(bytes) {
        Ok(source) => (source, Graph::load_str(source, path)),
        // Not text: through the file, as `werkstatt check` reads it.
        Err(e) => {
            std::fs::write(path, bytes).unwrap();
            let prefix = std::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap();
            (prefix, Graph::load(path))
        }
    };
    match result {
        Ok(graph) => {
            // Canonical text is a fixed point: it loads, and writes the same text again.
            let text = graph.to_ron();
            let again = Graph::load_str(&text, path);
            prop_assert!(
                again.is_ok(),
                "the canonical text of a loaded graph does not load: {}\n{text}",
                again.unwrap_err()
            );
            prop_assert_eq!(again.unwrap().to_ron(), text);
        }
        Err(err) => {
            prop_assert!(!err.diagnostics.is_empty(), "an error without diagnostics");
            for d in &err.diagnostics {
                let shown = d.to_string();
                prop_assert_eq!(&d.file, path, "{}", shown);
                prop_assert!(
                    shown.starts_with(&format!("{}:{}:{}: error", path.display(), d.line, d.col)),
                    "no file:line:col: {}",
                    shown
                );
                let at = text_at(source, d.line, d.col);
                prop_assert!(at.is_some(), "{}:{} is outside the text: {}", d.line, d.col, shown);
                check_problem(&d.problem, &shown)?;
                let at = at.unwrap();
                match &d.problem.place {
                    Place::Node(id) => {
                        prop_assert!(value_at::<String>(at).as_ref() == Some(id), "not at node {id:?}: {shown}")
                    }
                    Place::Param(_, name) => {
                        prop_assert!(
                            value_at::<String>(at).as_ref() == Some(name),
                            "not at parameter {name:?}: {shown}"
                        )
                    }
                    Place::Link(i) => {
                        let link = links_of(source).get(*i).cloned();
                        prop_assert!(link.is_some(), "the file has no link {i}: {shown}");
                        prop_assert_eq!(value_at::<(String, String)>(at), link, "not at link {}: {}", i, shown);
                    }
                    Place::File => {
                        prop_assert!(
                            matches!(
                                d.problem.kind,
                                ProblemKind::Syntax
                                    | ProblemKind::Io
                                    | ProblemKind::VersionTooNew
                                    | ProblemKind::VersionUnsupported
                            ),
                            "a problem of the whole file: {}",
                            shown
                        );
                        // Text that is not UTF-8: at its first bad byte, where the text read ends.
                        if d.problem.kind == ProblemKind::Io {
                            prop_assert!(at.is_empty(), "not at the first byte that is not UTF-8: {}", shown);
                        }
                    }
                }
            }
        }
    }
    Ok(())
}

/// A problem names the node (and port) it is about, in its fields and in its message.
fn check_problem(p: &Problem, shown: &str) -> Result<(), TestCaseError> {
    if let Place::Node(id) | Place::Param(id, _) = &p.place {
        prop_assert_eq!(p.node.as_ref(), Some(id), "{}", shown);
    }
    if matches!(
        p.kind,
        ProblemKind::UnknownPort
            | ProblemKind::LinkTypeMismatch
            | ProblemKind::InputLinkedTwice
            | ProblemKind::MissingInput
    ) {
        prop_assert!(p.node.is_some() && p.port.is_some(), "no node and port: {}", shown);
    }
    if let Some(n) = &p.node {
        prop_assert!(shown.contains(&format!("in node \"{n}\"")), "the message does not name node {n:?}: {shown}");
    }
    if let Some(port) = &p.port {
        prop_assert!(shown.contains(&format!("port \"{port}\"")), "the message does not name port {port:?}: {shown}");
    }
    Ok(())
}

// ---------------------------------------------------------------------------
// (a) Mutated graph files
// ---------------------------------------------------------------------------

#[derive(Clone, Debug)]
enum Mutation {
    /// Flips one bit of one byte (the result may not be UTF-8).
    FlipBit {
        at: usize,
        bit: u8,
    },
    Truncate {
        at: usize,
    },
    DeleteLine {
        line: usize,
    },
    DuplicateLine {
        line: usize,
    },
    /// Swaps two whitespace-separated words.
    SwapWords {
        a: usize,
        b: usize,
    },
    /// Replaces the n-th number literal.
    ReplaceNumber {
        which: usize,
        with: String,
    },
    /// Replaces the contents of the n-th string literal (ids, kinds, links, names, values).
    ReplaceString {
        which: usize,
        with: String,
    },
    Insert {
        at: usize,
        text: String,
    },
}

fn number_text() -> impl Strategy<Value = String> {
    prop_oneof![
        prop::sample::select(vec![
            "NaN",
            "-NaN",
            "inf",
            "-inf",
            "1e308",
            "1e309",
            "-1e400",
            "3.5e38",
            "1e-320",
            "9223372036854775807",
            "9223372036854775808",
            "-9223372036854775809",
            "18446744073709551616",
            "0",
            "-0.0",
            "1",
            "-1",
            "1_000",
            "0x10",
            "1.",
            ".5",
            "+2",
            "1e",
            "true",
            "\"3\"",
            "[1.0, 2.0]",
        ])
        .prop_map(String::from),
        any::<f64>().prop_map(|v| format!("{v:?}")),
        any::<i64>().prop_map(|v| v.to_string()),
        (-1000.0..1000.0f64).prop_map(|v| format!("{v:?}")),
    ]
}

fn string_text() -> impl Strategy<Value = String> {
    prop_oneof![
        4 => prop::sample::select(registry_names()).prop_map(String::from),
        1 => prop::sample::select(vec![
            "", "Nope", "a.b", "x.", ".y", "ghost.out", "camera.camera", "with space", "é", r"\u{1F600}", r"\n",
            r"\\", r"\", r"\q", "{", "\"", "links:", "nodes",
        ])
        .prop_map(String::from),
        1 => "[a-z_.]{0,10}",
    ]
}

fn snippet() -> impl Strategy<Value = String> {
    prop::sample::select(vec![
        "\"x\": 1.0,",
        "(",
        ")",
        "[",
        "]",
        "{",
        "}",
        ",",
        ":",
        "// a comment\n",
        "/* ",
        "\"",
        "\\",
        "kind: \"Math\",",
        "params: {},",
        "pos: (1.0, 2.0),",
        "\"n\": (kind: \"Number\"),",
        "(\"a.b\", \"c.d\"),",
        "(\"camera.camera\", \"gbuffer.camera\"),",
        "r#\"raw\"#",
        "\0",
        "é",
        "\u{feff}",
        "version: 2,",
        "\n",
    ])
    .prop_map(String::from)
}

fn mutation() -> impl Strategy<Value = Mutation> {
    let at = any::<usize>();
    prop_oneof![
        1 => (at, 0..8u8).prop_map(|(at, bit)| Mutation::FlipBit { at, bit }),
        1 => at.prop_map(|at| Mutation::Truncate { at }),
        1 => at.prop_map(|line| Mutation::DeleteLine { line }),
        1 => at.prop_map(|line| Mutation::DuplicateLine { line }),
        1 => (at, at).prop_map(|(a, b)| Mutation::SwapWords { a, b }),
        2 => (at, number_text()).prop_map(|(which, with)| Mutation::ReplaceNumber { which, with }),
        2 => (at, string_text()).prop_map(|(which, with)| Mutation::ReplaceString { which, with }),
        1 => (at, snippet()).prop_map(|(at, text)| Mutation::Insert { at, text }),
    ]
}

type Spans = Vec<(usize, usize)>;

/// Byte ranges of the literals in `text`: (strings, numbers). Strings include their quotes.
fn literals(text: &[u8]) -> (Spans, Spans) {
    let (mut strings, mut numbers) = (Vec::new(), Vec::new());
    let mut i = 0;
    while i < text.len() {
        let c = text[i];
        if c == b'"' {
            let start = i;
            i += 1;
            while i < text.len() && text[i] != b'"' {
                i += if text[i] == b'\\' { 2 } else { 1 };
            }
            strings.push((start, (i + 1).min(text.len())));
        } else if (c.is_ascii_digit() || c == b'-')
            && (i == 0 || !(text[i - 1].is_ascii_alphanumeric() || text[i - 1] == b'_'))
        {
            let start = i;
            i += 1;
            while i < text.len() && (text[i].is_ascii_alphanumeric() || matches!(text[i], b'.' | b'_' | b'+' | b'-')) {
                i += 1;
            }
            if text[start..i].iter().any(u8::is_ascii_digit) {
                numbers.push((start, i));
            }
            continue;
        }
        i += 1;
    }
    (strings, numbers)
}

fn splice(text: &mut Vec<u8>, (start, end): (usize, usize), with: &[u8]) {
    text.splice(start..end, with.iter().copied());
}

/// Byte ranges of the lines (with their newline) or of the words of `text`.
fn spans(text: &[u8], words: bool) -> Vec<(usize, usize)> {
    let mut out = Vec::new();
    let mut start = None;
    for (i, &c) in text.iter().enumerate() {
        let sep = if words { c.is_ascii_whitespace() } else { c == b'\n' };
        match (start, sep) {
            (None, false) => start = Some(i),
            (Some(s), true) => {
                out.push((s, if words { i } else { i + 1 }));
                start = None;
            }
            _ => {}
        }
    }
    if let Some(s) = start {
        out.push((s, text.len()));
    }
    out
}

fn apply(text: &mut Vec<u8>, m: &Mutation) {
    let pick = |spans: &[(usize, usize)], n: usize| (!spans.is_empty()).then(|| spans[n % spans.len()]);
    let len = text.len();
    match m {
        Mutation::FlipBit { at, bit } if len > 0 => text[at % len] ^= 1 << bit,
        Mutation::Truncate { at } => text.truncate(at % (len + 1)),
        Mutation::DeleteLine { line } => {
            if let Some(span) = pick(&spans(text, false), *line) {
                splice(text, span, b"");
            }
        }
        Mutation::DuplicateLine { line } => {
            if let Some((s, e)) = pick(&spans(text, false), *line) {
                let copy = text[s..e].to_vec();
                splice(text, (e, e), &copy);
            }
        }
        Mutation::SwapWords { a, b } => {
            let words = spans(text, true);
            if let (Some(x), Some(y)) = (pick(&words, *a), pick(&words, *b)) {
                let (x, y) = if x.0 <= y.0 { (x, y) } else { (y, x) };
                if x != y {
                    let (wx, wy) = (text[x.0..x.1].to_vec(), text[y.0..y.1].to_vec());
                    splice(text, y, &wx);
                    splice(text, x, &wy);
                }
            }
        }
        Mutation::ReplaceNumber { which, with } => {
            if let Some(span) = pick(&literals(text).1, *which) {
                splice(text, span, with.as_bytes());
            }
        }
        Mutation::ReplaceString { which, with } => {
            if let Some(span) = pick(&literals(text).0, *which) {
                splice(text, span, format!("\"{with}\"").as_bytes());
            }
        }
        Mutation::Insert { at, text: snippet } => {
            let at = at % (len + 1);
            splice(text, (at, at), snippet.as_bytes());
        }
        Mutation::FlipBit { .. } => {}
    }
}

fn out_dir() -> &'static Path {
    static DIR: OnceLock<PathBuf> = OnceLock::new();
    DIR.get_or_init(|| common::out_dir("graph-props"))
}

proptest! {
    #![proptest_config(config(2048))]

    #[test]
    fn mutated_graph_files_load_or_fail_with_located_errors(
        file in 0..64usize,
        mutations in prop::collection::vec(mutation(), 1..4),
    ) {
        let (name, text) = &real_graphs()[file % real_graphs().len()];
        let mut bytes = text.clone().into_bytes();
        for m in &mutations {
            apply(&mut bytes, m);
        }
        check_load(&out_dir().join(name), &bytes)?;
    }
}

// ---------------------------------------------------------------------------
// (b) Graphs generated from the registry
// ---------------------------------------------------------------------------

/// A parameter value, resolved against the parameter's kind when the graph is written.
#[derive(Clone, Debug)]
enum GenValue {
    /// The spec's default.
    Default,
    /// A valid value, from a number in [0, 1).
    Valid(f64),
    Float(f64),
    Int(i64),
    Bool(bool),
    Str(String),
    List(Vec<f64>),
    /// Any text, not necessarily a value.
    Raw(String),
}

#[derive(Clone, Debug)]
enum GenName {
    /// The n-th name the node's spec has (parameter, input or output).
    Known(usize),
    Other(String),
}

#[derive(Clone, Debug)]
struct GenNode {
    id: usize,
    /// An index into the registry, or an unknown kind.
    kind: Result<usize, String>,
    pos: Option<(f32, f32)>,
    params: Vec<(GenName, GenValue)>,
}

#[derive(Clone, Debug)]
enum GenLink {
    Ports { from: usize, out: GenName, to: usize, input: GenName },
    Malformed(String, String),
}

#[derive(Clone, Debug)]
struct GenGraph {
    version: u32,
    nodes: Vec<GenNode>,
    links: Vec<GenLink>,
    one_line: bool,
}

/// Node ids: the first `VALID_IDS` valid, then invalid ones; drawn from a small pool so ids repeat.
const IDS: &[&str] = &[
    "cam",
    "shape",
    "draw",
    "n_1",
    "out",
    "m-2",
    "x",
    "y",
    "Z9",
    "long_node_name",
    "n2",
    "_",
    "",
    "a.b",
    "with space",
    "é",
    "q\"uote",
    "back\\slash",
];
const VALID_IDS: usize = 12;

fn gen_name() -> impl Strategy<Value = GenName> {
    prop_oneof![
        4 => (0..16usize).prop_map(GenName::Known),
        1 => prop_oneof![string_text(), "[a-z]{1,8}"].prop_map(GenName::Other),
    ]
}

fn gen_value() -> impl Strategy<Value = GenValue> {
    prop_oneof![
        2 => Just(GenValue::Default),
        6 => (0.0..1.0f64).prop_map(GenValue::Valid),
        1 => prop_oneof![any::<f64>(), Just(f64::NAN), Just(f64::INFINITY), Just(1e308), Just(-1e308)].prop_map(GenValue::Float),
        1 => prop_oneof![any::<i64>(), Just(i64::MAX), Just(i64::MIN), -3..3i64].prop_map(GenValue::Int),
        1 => any::<bool>().prop_map(GenValue::Bool),
        1 => string_text().prop_map(GenValue::Str),
        1 => prop::collection::vec(prop_oneof![-2.0..2.0f64, Just(f64::NAN), Just(-1.0)], 0..5).prop_map(GenValue::List),
        1 => prop_oneof![number_text(), snippet()].prop_map(GenValue::Raw),
    ]
}

fn gen_graph() -> impl Strategy<Value = GenGraph> {
    let kinds = spec::all().len();
    let node = (
        0..IDS.len(),
        prop_oneof![9 => (0..kinds).prop_map(Ok), 1 => prop_oneof![string_text(), "[A-Z][a-z]{2,8}"].prop_map(Err)],
        prop::option::weighted(0.8, (any::<f32>(), -1000.0..1000.0f32)),
        prop::collection::vec((gen_name(), gen_value()), 0..5),
    )
        .prop_map(|(id, kind, pos, params)| GenNode { id, kind, pos, params });
    let link = prop_oneof![
        9 => (0..8usize, gen_name(), 0..8usize, gen_name()).prop_map(|(from, out, to, input)| GenLink::Ports { from, out, to, input }),
        1 => (string_text(), string_text()).prop_map(|(a, b)| GenLink::Malformed(a, b)),
    ];
    (
        prop_oneof![9 => Just(1u32), 1 => 0..4u32],
        prop::collection::vec(node, 0..8),
        prop::collection::vec(link, 0..12),
        any::<bool>(),
    )
        .prop_map(|(version, nodes, links, one_line)| GenGraph { version, nodes, links, one_line })
}

fn kind_of(node: &GenNode) -> Option<&'static NodeSpec> {
    node.kind.as_ref().ok().map(|&k| spec::all()[k])
}

fn value_text(kind: Option<&ParamKind>, v: &GenValue) -> String {
    let valid = |t: f64| -> String {
        match kind {
            None => format!("{t:?}"),
            Some(&ParamKind::Float { min, max, default }) => {
                let v = if (max - min).is_finite() { min + t * (max - min) } else { default + t };
                format!("{v:?}")
            }
            Some(&ParamKind::Int { min, max, .. }) => (min as i128 + ((max as i128 - min as i128) as f64 * t) as i128)
                .clamp(min as i128, max as i128)
                .to_string(),
            Some(ParamKind::Bool { .. }) => (t < 0.5).to_string(),
            Some(ParamKind::Vec3 { .. }) => format!("[{t:?}, {:?}, -1.0]", t * 2.0),
            Some(ParamKind::Scale { .. }) => format!("[{:?}, {:?}, -1.0]", 1.0 + t, t * 2.0 + 0.5),
            Some(ParamKind::Color { .. }) => format!("[{t:?}, {t:?}, 1.0]"),
            Some(ParamKind::Text { .. }) => format!("{:?}", format!("text {t}")),
            Some(ParamKind::Path { .. }) => "\"no/such/file.obj\"".into(),
            Some(ParamKind::Choice { options, .. }) => format!("{:?}", options[(t * options.len() as f64) as usize]),
        }
    };
    let float = |v: f64| format!("{v:?}");
    match v {
        GenValue::Default => match kind.map(ParamKind::default_value) {
            Some(ParamValue::Bool(b)) => b.to_string(),
            Some(ParamValue::Int(i)) => i.to_string(),
            Some(ParamValue::Float(f)) => float(f),
            Some(ParamValue::Str(s)) => format!("{s:?}"),
            Some(ParamValue::Vec(v)) => format!("[{}]", v.iter().map(|x| float(*x)).collect::<Vec<_>>().join(", ")),
            None => "0".into(),
        },
        GenValue::Valid(t) => valid(*t),
        GenValue::Float(f) => float(*f),
        GenValue::Int(i) => i.to_string(),
        GenValue::Bool(b) => b.to_string(),
        GenValue::Str(s) => format!("{s:?}"),
        GenValue::List(v) => format!("[{}]", v.iter().map(|x| float(*x)).collect::<Vec<_>>().join(", ")),
        GenValue::Raw(s) => s.clone(),
    }
}

fn port_name(spec: Option<&NodeSpec>, name: &GenName, input: bool) -> String {
    match (spec, name) {
        (Some(s), GenName::Known(i)) => {
            let ports = if input { s.inputs } else { s.outputs };
            if ports.is_empty() { "none".into() } else { ports[i % ports.len()].name.into() }
        }
        (None, GenName::Known(i)) => format!("port{i}"),
        (_, GenName::Other(n)) => n.clone(),
    }
}

impl GenGraph {
    fn text(&self) -> String {
        let (nl, ind) = if self.one_line { (" ", "") } else { ("\n", "    ") };
        let mut s = format!("({nl}{ind}version: {},{nl}{ind}nodes: {{{nl}", self.version);
        for node in &self.nodes {
            let spec = kind_of(node);
            let kind = spec.map_or_else(|| node.kind.clone().unwrap_err(), |s| s.kind.to_string());
            s += &format!("{ind}{ind}{:?}: ({nl}{ind}{ind}{ind}kind: {kind:?},{nl}", IDS[node.id]);
            if let Some((x, y)) = node.pos {
                s += &format!("{ind}{ind}{ind}pos: ({x:?}, {y:?}),{nl}");
            }
            s += &format!("{ind}{ind}{ind}params: {{{nl}");
            for (name, value) in &node.params {
                let (name, kind) = match (spec, name) {
                    (Some(sp), GenName::Known(i)) if !sp.params.is_empty() => {
                        let p = &sp.params[i % sp.params.len()];
                        (p.name.to_string(), Some(&p.kind))
                    }
                    (_, GenName::Known(i)) => (format!("p{i}"), None),
                    (_, GenName::Other(n)) => (n.clone(), None),
                };
                s += &format!("{ind}{ind}{ind}{ind}{name:?}: {},{nl}", value_text(kind, value));
            }
            s += &format!("{ind}{ind}{ind}}},{nl}{ind}{ind}),{nl}");
        }
        s += &format!("{ind}}},{nl}{ind}links: [{nl}");
        for link in &self.links {
            let (a, b) = match link {
                GenLink::Ports { from, out, to, input } => {
                    let node = |i: usize| self.nodes.get(i % self.nodes.len().max(1));
                    let (f, t) = (node(*from), node(*to));
                    let id = |n: Option<&GenNode>| n.map_or("ghost", |n| IDS[n.id]);
                    (
                        format!("{}.{}", id(f), port_name(f.and_then(kind_of), out, false)),
                        format!("{}.{}", id(t), port_name(t.and_then(kind_of), input, true)),
                    )
                }
                GenLink::Malformed(a, b) => (a.clone(), b.clone()),
            };
            s += &format!("{ind}{ind}({a:?}, {b:?}),{nl}");
        }
        s += &format!("{ind}],{nl})\n");
        s
    }

    /// The document model of the graph as it is meant (first of repeated ids, well-formed
    /// links only), for calling `validate` directly.
    fn doc(&self) -> Graph {
        let mut g = Graph::new();
        for node in &self.nodes {
            let kind = kind_of(node).map_or_else(|| node.kind.clone().unwrap_err(), |s| s.kind.to_string());
            let params = node
                .params
                .iter()
                .filter_map(|(name, value)| {
                    let (name, v) = match (kind_of(node), name) {
                        (Some(sp), GenName::Known(i)) if !sp.params.is_empty() => {
                            let p = &sp.params[i % sp.params.len()];
                            (p.name.to_string(), Some(p.kind.default_value()))
                        }
                        (_, GenName::Other(n)) => (n.clone(), None),
                        _ => return None,
                    };
                    let v = match value {
                        GenValue::Float(f) => ParamValue::Float(*f),
                        GenValue::Int(i) => ParamValue::Int(*i),
                        GenValue::Bool(b) => ParamValue::Bool(*b),
                        GenValue::Str(s) => ParamValue::Str(s.clone()),
                        GenValue::List(l) => ParamValue::Vec(l.clone()),
                        _ => v.unwrap_or(ParamValue::Int(0)),
                    };
                    Some((name, v))
                })
                .collect();
            let pos = node.pos.map_or([0.0; 2], |(x, y)| [x, y]);
            g.nodes.entry(IDS[node.id].to_string()).or_insert(NodeDoc { kind, pos, params });
        }
        for link in &self.links {
            if let GenLink::Ports { from, out, to, input } = link
                && !self.nodes.is_empty()
            {
                let (f, t) = (&self.nodes[from % self.nodes.len()], &self.nodes[to % self.nodes.len()]);
                let from = PortRef { node: IDS[f.id].into(), port: port_name(kind_of(f), out, false) };
                let to = PortRef { node: IDS[t.id].into(), port: port_name(kind_of(t), input, true) };
                g.links.push(Link { from, to });
            }
        }
        g
    }
}

/// Graphs that validate: known kinds, unique valid ids, parameters in range, and each input
/// linked (required ones always) from an earlier node's output of a type it accepts.
fn valid_graph() -> impl Strategy<Value = GenGraph> {
    let node = (
        0..spec::all().len(),
        prop::option::of((any::<f32>(), any::<f32>())),
        prop::collection::vec((0..16usize, 0.0..1.0f64), 0..4),
        prop::collection::vec(any::<usize>(), 1..6),
    );
    (prop::collection::vec(node, 1..32), any::<bool>()).prop_map(|(nodes, one_line)| {
        let mut g = GenGraph { version: 1, nodes: Vec::new(), links: Vec::new(), one_line };
        for (kind, pos, params, choices) in nodes {
            let spec = spec::all()[kind];
            let to = g.nodes.len();
            let (mut links, mut unfed) = (Vec::new(), false);
            for (k, input) in spec.inputs.iter().enumerate() {
                let outputs: Vec<(usize, usize)> = (0..to)
                    .flat_map(|j| {
                        let from = kind_of(&g.nodes[j]).unwrap().outputs;
                        (0..from.len()).filter(move |&o| input.ty.accepts(from[o].ty)).map(move |o| (j, o))
                    })
                    .collect();
                let choice = choices[k % choices.len()];
                if !outputs.is_empty() && (input.required || choice % 3 != 0) {
                    let (from, out) = outputs[choice % outputs.len()];
                    links.push(GenLink::Ports { from, out: GenName::Known(out), to, input: GenName::Known(k) });
                } else {
                    unfed |= input.required;
                }
            }
            if unfed || to == VALID_IDS {
                continue;
            }
            let mut params: Vec<(GenName, GenValue)> = params
                .into_iter()
                .filter(|_| !spec.params.is_empty())
                .map(|(p, t)| (GenName::Known(p % spec.params.len()), GenValue::Valid(t)))
                .collect();
            params.sort_by_key(|(n, _)| match n {
                GenName::Known(i) => *i,
                GenName::Other(_) => usize::MAX,
            });
            params.dedup_by_key(|(n, _)| match n {
                GenName::Known(i) => *i,
                GenName::Other(_) => usize::MAX,
            });
            g.nodes.push(GenNode { id: to, kind: Ok(kind), pos, params });
            g.links.extend(links);
        }
        g
    })
}

proptest! {
    #![proptest_config(config(512))]

    #[test]
    fn generated_graphs_load_or_fail_with_located_errors(graph in gen_graph()) {
        check_load(&out_dir().join("generated.ron"), graph.text().as_bytes())?;
    }

    #[test]
    fn generated_valid_graphs_load_and_round_trip(graph in valid_graph()) {
        let (path, text) = (out_dir().join("valid.ron"), graph.text());
        let loaded = Graph::load_str(&text, &path);
        prop_assert!(loaded.is_ok(), "{}\n{}", loaded.unwrap_err(), text);
        check_load(&path, text.as_bytes())?;
    }

    #[test]
    fn validate_names_existing_nodes_links_and_ports(graph in gen_graph()) {
        let doc = graph.doc();
        for p in doc.validate() {
            let shown = format!("{:?}: {}", p.kind, p.message);
            match &p.place {
                Place::Node(id) | Place::Param(id, _) => {
                    prop_assert!(doc.nodes.contains_key(id), "no node {id:?}: {shown}");
                    prop_assert_eq!(p.node.as_ref(), Some(id), "{}", shown);
                }
                Place::Link(i) => prop_assert!(*i < doc.links.len(), "no link {i}: {shown}"),
                Place::File => prop_assert!(false, "validate reports a problem of the whole file: {shown}"),
            }
            if let Place::Param(id, name) = &p.place {
                prop_assert!(doc.nodes[id].params.contains_key(name), "node {id:?} sets no {name:?}: {shown}");
            }
            if let (Some(n), Some(port)) = (&p.node, &p.port) {
                let linked = doc.links.iter().any(|l| (&l.from.node, &l.from.port) == (n, port) || (&l.to.node, &l.to.port) == (n, port));
                let spec_port = doc.nodes.get(n).and_then(|d| spec::find(&d.kind)).is_some_and(|s| s.input(port).is_some());
                prop_assert!(linked || spec_port, "port {n}.{port} is neither linked nor in the spec: {shown}");
            }
        }
    }
}

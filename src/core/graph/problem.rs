//! Problems of a document, where they sit, and the errors that carry them.

use std::fmt;
use std::path::PathBuf;

use super::source::SourceMap;

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
    pub(super) fn new(kind: ProblemKind, place: Place, message: impl Into<String>) -> Self {
        let node = match &place {
            Place::Node(n) | Place::Param(n, _) => Some(n.clone()),
            _ => None,
        };
        Problem { kind, place, node, port: None, message: message.into(), help: None }
    }
    pub(super) fn port(mut self, node: &str, port: &str) -> Self {
        self.node = Some(node.into());
        self.port = Some(port.into());
        self
    }
    pub(super) fn help(mut self, help: impl Into<String>) -> Self {
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

impl fmt::Display for Problem {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match (&self.node, &self.port) {
            (Some(n), Some(p)) => write!(f, "node \"{n}\", port \"{p}\": ")?,
            (Some(n), None) => write!(f, "node \"{n}\": ")?,
            _ => {}
        }
        f.write_str(&self.message)?;
        if let Some(help) = &self.help {
            write!(f, "; {help}")?;
        }
        Ok(())
    }
}

/// Why a graph could not be loaded, changed or compiled for evaluation: the one error type of
/// the graph layer (the loader, migrations, `--set`, [`crate::core::eval::Evaluator`]). Each
/// variant names what it is about: the file, line and column (through its diagnostics), the
/// node, the parameter or port.
#[derive(Debug, thiserror::Error)]
pub enum GraphError {
    /// The problems of a file, each with its file, line, column, node and port.
    #[error(transparent)]
    Load(#[from] LoadError),
    /// A graph in memory (no file) that does not validate; the problem names node and port.
    #[error("{0}")]
    Invalid(Box<Problem>),
    /// A node id that the graph does not have (an extra root, `--dump node.port`).
    #[error("there is no node \"{0}\"")]
    NoSuchNode(String),
    /// A format version that no migration upgrades.
    #[error("no migration from version {from} (this build reads {target})")]
    NoMigration { from: u32, target: u32 },
    /// `--set` text that is not `node.param=value`.
    #[error("--set \"{assignment}\": expected node.param=value")]
    SetSyntax { assignment: String },
    /// `--set` names a node the graph does not have.
    #[error("--set {node}.{param}: there is no node \"{node}\"; {help}")]
    SetUnknownNode { node: String, param: String, help: String },
    /// `--set` names a parameter the node's kind does not have.
    #[error("--set {node}.{param}: {kind} (node \"{node}\") has no parameter \"{param}\"; {help}")]
    SetUnknownParam { node: String, kind: String, param: String, help: String },
    /// `--set` gives a value the parameter does not accept.
    #[error("--set {node}.{param}: {reason}")]
    SetValue { node: String, param: String, reason: String },
}

impl GraphError {
    /// The node the error is about, if there is one (the first diagnostic's, for a file).
    pub fn node(&self) -> Option<&str> {
        match self {
            GraphError::Load(e) => e.diagnostics.first()?.problem.node.as_deref(),
            GraphError::Invalid(p) => p.node.as_deref(),
            GraphError::NoSuchNode(node)
            | GraphError::SetUnknownNode { node, .. }
            | GraphError::SetUnknownParam { node, .. }
            | GraphError::SetValue { node, .. } => Some(node),
            GraphError::NoMigration { .. } | GraphError::SetSyntax { .. } => None,
        }
    }
}

impl From<Problem> for GraphError {
    fn from(p: Problem) -> Self {
        GraphError::Invalid(Box::new(p))
    }
}

//! The document model: nodes keyed by stable ids, links between their ports.

use std::collections::BTreeMap;
use std::fmt;

use crate::core::param::ParamValue;
use crate::core::spec;

/// The file format version this build writes.
pub const CURRENT_VERSION: u32 = 2;

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

impl Graph {
    pub fn new() -> Self {
        Graph { version: CURRENT_VERSION, nodes: BTreeMap::new(), links: Vec::new() }
    }
    /// The value of a parameter: the file's, or the spec's default.
    pub fn param(&self, node: &str, name: &str) -> Option<ParamValue> {
        let doc = self.nodes.get(node)?;
        if let Some(v) = doc.params.get(name) {
            return Some(v.clone());
        }
        spec::find(&doc.kind)?.param(name).map(|(_, p)| p.kind.default_value())
    }
}

impl Default for Graph {
    fn default() -> Self {
        Graph::new()
    }
}

//! Older format versions, upgraded step by step.

use super::model::Graph;
use super::problem::GraphError;

/// A step that upgrades a document from `from` to `from + 1`.
pub struct Migration {
    pub from: u32,
    pub note: &'static str,
    pub apply: fn(&mut Graph),
}

/// Every format change adds an entry here; old files then keep opening.
pub const MIGRATIONS: &[Migration] = &[Migration {
    from: 1,
    note: "MeshFile keeps the file's units by default; nodes that relied on the old default get normalize: true",
    apply: normalize_explicitly,
}];

/// Version 2 changed `MeshFile.normalize`'s default from true to false (a body and a garment
/// from one tool were scaled to unit height each, so they no longer lined up). Files written
/// before keep what they rendered.
fn normalize_explicitly(graph: &mut Graph) {
    for node in graph.nodes.values_mut().filter(|n| n.kind == "MeshFile") {
        node.params.entry("normalize".into()).or_insert(crate::core::param::ParamValue::Bool(true));
    }
}

/// Upgrades `graph` to `target` with `table`, returning the notes of the applied steps.
pub fn migrate(graph: &mut Graph, target: u32, table: &[Migration]) -> Result<Vec<&'static str>, GraphError> {
    let mut notes = Vec::new();
    while graph.version < target {
        let step = table
            .iter()
            .find(|m| m.from == graph.version)
            .ok_or(GraphError::NoMigration { from: graph.version, target })?;
        (step.apply)(graph);
        notes.push(step.note);
        graph.version += 1;
    }
    Ok(notes)
}

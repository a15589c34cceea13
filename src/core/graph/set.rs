//! `--set node.param=value` from the command line.

use super::model::Graph;
use super::problem::GraphError;
use crate::core::spec;

impl Graph {
    /// Applies `node.param=value` from the command line, checked against the spec.
    pub fn set_from_cli(&mut self, assignment: &str) -> Result<(), GraphError> {
        let syntax = || GraphError::SetSyntax { assignment: assignment.into() };
        let (target, value) = assignment.split_once('=').ok_or_else(syntax)?;
        let (id, name) = target.split_once('.').ok_or_else(syntax)?;
        let hint = |wanted: &str, names: Vec<&str>| match spec::closest(wanted, names.iter().copied()) {
            Some(n) => format!("did you mean \"{n}\"?"),
            None => format!("the choices are: {}", names.join(", ")),
        };
        let ids: Vec<&str> = self.nodes.keys().map(String::as_str).collect();
        let Some(node) = self.nodes.get(id) else {
            return Err(GraphError::SetUnknownNode { node: id.into(), param: name.into(), help: hint(id, ids) });
        };
        let unknown_param = |kind: &str, help: String| GraphError::SetUnknownParam {
            node: id.into(),
            kind: kind.into(),
            param: name.into(),
            help,
        };
        let spec = spec::find(&node.kind).ok_or_else(|| unknown_param(&node.kind, "the kind is unknown".into()))?;
        let (_, ps) = spec
            .param(name)
            .ok_or_else(|| unknown_param(spec.kind, hint(name, spec.params.iter().map(|p| p.name).collect())))?;
        let node = self.nodes.get_mut(id).expect("found above");
        let parsed = ps.kind.parse_cli(value).map_err(|reason| GraphError::SetValue {
            node: id.into(),
            param: name.into(),
            reason,
        })?;
        node.params.insert(name.to_string(), parsed);
        Ok(())
    }
}

//! Undo and redo: a snapshot of the whole [`Graph`] before each edit. Graphs are small
//! (a 200-node graph is some tens of kilobytes), so snapshots are simpler and safer than
//! inverse operations. Edits that carry the same coalescing key one after another (the
//! frames of one slider drag) become one step until the gesture is sealed.

use crate::core::graph::Graph;

struct Step {
    before: Graph,
    label: String,
}

pub struct History {
    undo: Vec<Step>,
    redo: Vec<Step>,
    /// The coalescing key of the open gesture, if the last step may still grow.
    open: Option<String>,
    limit: usize,
}

impl Default for History {
    fn default() -> Self {
        History::new(500)
    }
}

impl History {
    /// A history that keeps at most `limit` undo steps.
    pub fn new(limit: usize) -> Self {
        History { undo: Vec::new(), redo: Vec::new(), open: None, limit: limit.max(1) }
    }

    /// Records an edit that changed the graph from `before`. With a `coalesce` key equal to
    /// the open gesture's, the edit joins the last step instead of making a new one.
    pub fn record(&mut self, before: Graph, label: &str, coalesce: Option<&str>) {
        self.redo.clear();
        if coalesce.is_some() && coalesce == self.open.as_deref() && !self.undo.is_empty() {
            return;
        }
        self.undo.push(Step { before, label: label.to_string() });
        if self.undo.len() > self.limit {
            self.undo.remove(0);
        }
        self.open = coalesce.map(str::to_string);
    }

    /// Ends the open gesture: the next edit makes a new step even with the same key.
    pub fn seal(&mut self) {
        self.open = None;
    }

    /// Restores the graph before the last step; returns the step's label.
    pub fn undo(&mut self, current: &mut Graph) -> Option<String> {
        let step = self.undo.pop()?;
        let after = std::mem::replace(current, step.before);
        self.redo.push(Step { before: after, label: step.label.clone() });
        self.open = None;
        Some(step.label)
    }

    /// Re-applies the last undone step; returns its label.
    pub fn redo(&mut self, current: &mut Graph) -> Option<String> {
        let step = self.redo.pop()?;
        let before = std::mem::replace(current, step.before);
        self.undo.push(Step { before, label: step.label.clone() });
        self.open = None;
        Some(step.label)
    }

    pub fn can_undo(&self) -> bool {
        !self.undo.is_empty()
    }

    pub fn can_redo(&self) -> bool {
        !self.redo.is_empty()
    }

    pub fn undo_label(&self) -> Option<&str> {
        self.undo.last().map(|s| s.label.as_str())
    }

    pub fn redo_label(&self) -> Option<&str> {
        self.redo.last().map(|s| s.label.as_str())
    }

    pub fn len(&self) -> usize {
        self.undo.len()
    }

    pub fn is_empty(&self) -> bool {
        self.undo.is_empty()
    }

    pub fn clear(&mut self) {
        self.undo.clear();
        self.redo.clear();
        self.open = None;
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::editor::document::{add_node, set_param};
    use crate::core::param::ParamValue;

    #[test]
    fn undo_redo_round_trip() {
        let mut h = History::default();
        let mut g = Graph::new();
        let before = g.clone();
        add_node(&mut g, "Number", [0.0, 0.0]).unwrap();
        h.record(before, "add number", None);
        let before = g.clone();
        set_param(&mut g, "number", "value", ParamValue::Float(3.0)).unwrap();
        h.record(before, "set number.value", None);
        let end = g.clone();

        assert_eq!(h.undo(&mut g).as_deref(), Some("set number.value"));
        assert!(!g.nodes["number"].params.contains_key("value"));
        assert_eq!(h.undo(&mut g).as_deref(), Some("add number"));
        assert!(g.nodes.is_empty());
        assert!(h.undo(&mut g).is_none());
        h.redo(&mut g);
        h.redo(&mut g);
        assert_eq!(g, end);
        assert!(h.redo(&mut g).is_none());
    }

    #[test]
    fn slider_drags_coalesce_until_sealed() {
        let mut h = History::default();
        let mut g = Graph::new();
        add_node(&mut g, "Number", [0.0, 0.0]).unwrap();
        let start = g.clone();
        for v in 1..=10 {
            let before = g.clone();
            set_param(&mut g, "number", "value", ParamValue::Float(v as f64)).unwrap();
            h.record(before, "set number.value", Some("number.value"));
        }
        assert_eq!(h.len(), 1, "one drag is one step");
        h.seal();
        let before = g.clone();
        set_param(&mut g, "number", "value", ParamValue::Float(20.0)).unwrap();
        h.record(before, "set number.value", Some("number.value"));
        assert_eq!(h.len(), 2);
        h.undo(&mut g);
        h.undo(&mut g);
        assert_eq!(g, start);
    }

    #[test]
    fn a_new_edit_drops_the_redo_steps_and_the_limit_holds() {
        let mut h = History::new(3);
        let mut g = Graph::new();
        for _ in 0..5 {
            let before = g.clone();
            add_node(&mut g, "Number", [0.0, 0.0]).unwrap();
            h.record(before, "add", None);
        }
        assert_eq!(h.len(), 3);
        // Only the last three steps are kept: undoing them leaves the first two nodes.
        for _ in 0..3 {
            assert_eq!(h.undo(&mut g).as_deref(), Some("add"));
        }
        assert_eq!(g.nodes.keys().map(String::as_str).collect::<Vec<_>>(), ["number", "number_2"]);
        assert!(h.undo(&mut g).is_none(), "the oldest steps were dropped");
        h.redo(&mut g);
        h.redo(&mut g);
        let four = g.clone();
        assert_eq!(four.nodes.len(), 4);
        assert!(h.can_redo());
        let before = g.clone();
        add_node(&mut g, "Math", [0.0, 0.0]).unwrap();
        h.record(before, "add math", None);
        assert!(!h.can_redo());
        assert_eq!(h.undo(&mut g).as_deref(), Some("add math"));
        assert_eq!(g, four);
    }
}

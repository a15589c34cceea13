//! The editor's state without any drawing: the document, its file, selection, clipboard,
//! undo history and messages. The UI turns clicks into calls on [`EditorState`]; tests
//! call the same methods directly.

use std::collections::BTreeSet;
use std::path::{Path, PathBuf};
use std::time::Instant;

use super::document::{self, EditError, Fragment};
use super::history::History;
use crate::core::graph::{Diagnostic, Graph, Link, PortRef};
use crate::core::param::ParamValue;

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Level {
    Info,
    Error,
}

#[derive(Clone, Debug)]
pub struct Message {
    pub level: Level,
    pub text: String,
    pub at: Instant,
}

pub struct EditorState {
    pub graph: Graph,
    /// The file the graph is saved to; `None` for a new graph.
    pub path: Option<PathBuf>,
    /// The graph as it was last loaded or saved, for the unsaved-changes mark.
    saved: Graph,
    pub history: History,
    pub selection: BTreeSet<String>,
    pub clipboard: Option<Fragment>,
    pub messages: Vec<Message>,
    /// Bumped on every change of `graph`, so views know when to resync.
    pub revision: u64,
    /// The texture port shown in the viewport instead of the preview, if any.
    pub inspected: Option<PortRef>,
}

impl Default for EditorState {
    fn default() -> Self {
        EditorState::new(Graph::new(), None)
    }
}

impl EditorState {
    pub fn new(graph: Graph, path: Option<PathBuf>) -> Self {
        EditorState {
            saved: graph.clone(),
            graph,
            path,
            history: History::default(),
            selection: BTreeSet::new(),
            clipboard: None,
            messages: Vec::new(),
            revision: 1,
            inspected: None,
        }
    }

    /// Opens a graph file. A file with problems (an unconnected input, an unknown kind) still
    /// opens, and the problems are returned to show; one that is not a graph is an error.
    pub fn open(path: &Path) -> Result<(EditorState, Vec<Diagnostic>), String> {
        let source = std::fs::read_to_string(path).map_err(|e| format!("cannot read {}: {e}", path.display()))?;
        let (graph, problems) = Graph::load_lenient(&source, path).map_err(|e| e.to_string())?;
        Ok((EditorState::new(graph, Some(path.to_path_buf())), problems))
    }

    pub fn is_dirty(&self) -> bool {
        !same_graph(&self.graph, &self.saved)
    }

    /// The graph as last saved or loaded.
    pub fn saved_graph(&self) -> &Graph {
        &self.saved
    }

    /// Declares the current graph saved (after writing it) or the file's content (`saved`).
    pub fn mark_saved(&mut self, saved: Option<Graph>) {
        self.saved = saved.unwrap_or_else(|| self.graph.clone());
    }

    pub fn file_name(&self) -> String {
        match &self.path {
            Some(p) => {
                p.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| p.display().to_string())
            }
            None => "untitled".into(),
        }
    }

    /// The window title: file name, a mark for unsaved changes, and the program.
    pub fn title(&self) -> String {
        format!("{}{} - werkstatt", if self.is_dirty() { "* " } else { "" }, self.file_name())
    }

    pub fn info(&mut self, text: impl Into<String>) {
        self.push_message(Level::Info, text.into());
    }

    pub fn error(&mut self, text: impl Into<String>) {
        self.push_message(Level::Error, text.into());
    }

    fn push_message(&mut self, level: Level, text: String) {
        self.messages.push(Message { level, text, at: Instant::now() });
        if self.messages.len() > 100 {
            self.messages.remove(0);
        }
    }

    /// The last message, if any.
    pub fn last_message(&self) -> Option<&Message> {
        self.messages.last()
    }

    /// Applies an edit to the graph. On success it becomes an undo step (joined to the last
    /// one when `coalesce` matches the open gesture); on failure the graph is left as it was
    /// and the reason is shown.
    pub fn edit<T>(
        &mut self,
        label: &str,
        coalesce: Option<&str>,
        f: impl FnOnce(&mut Graph) -> Result<T, EditError>,
    ) -> Result<T, EditError> {
        let before = self.graph.clone();
        match f(&mut self.graph) {
            Ok(v) => {
                if !same_graph(&self.graph, &before) {
                    self.history.record(before, label, coalesce);
                    self.changed();
                }
                Ok(v)
            }
            Err(e) => {
                self.graph = before;
                self.error(e.to_string());
                Err(e)
            }
        }
    }

    /// Replaces the whole graph (reload from disk, recovery) as one undoable step.
    pub fn replace_graph(&mut self, graph: Graph, label: &str) {
        let _ = self.edit(label, None, |g| {
            *g = graph;
            Ok(())
        });
    }

    fn changed(&mut self) {
        self.revision += 1;
        let graph = &self.graph;
        self.selection.retain(|id| graph.nodes.contains_key(id));
        if let Some(p) = &self.inspected
            && !graph.nodes.contains_key(&p.node)
        {
            self.inspected = None;
        }
    }

    pub fn undo(&mut self) -> bool {
        match self.history.undo(&mut self.graph) {
            Some(label) => {
                self.changed();
                self.info(format!("undid: {label}"));
                true
            }
            None => false,
        }
    }

    pub fn redo(&mut self) -> bool {
        match self.history.redo(&mut self.graph) {
            Some(label) => {
                self.changed();
                self.info(format!("redid: {label}"));
                true
            }
            None => false,
        }
    }

    /// Ends a gesture (slider drag, text typing), so the next edit is a new undo step.
    pub fn seal(&mut self) {
        self.history.seal();
    }

    // -- the operations the UI offers -----------------------------------------------------

    /// Adds a node and selects it.
    pub fn add_node(&mut self, kind: &str, pos: [f32; 2]) -> Result<String, EditError> {
        let id = self.edit(&format!("add {kind}"), None, |g| document::add_node(g, kind, pos))?;
        self.selection = BTreeSet::from([id.clone()]);
        Ok(id)
    }

    /// Adds a node and connects it to `port` in one step (a wire dropped on empty space):
    /// `port` is an output (`from_output`) feeding the new node's `new_port`, or an input
    /// the new node's output `new_port` feeds.
    pub fn add_node_connected(
        &mut self,
        kind: &str,
        pos: [f32; 2],
        port: &PortRef,
        from_output: bool,
        new_port: &str,
    ) -> Result<String, EditError> {
        let id = self.edit(&format!("add {kind}"), None, |g| {
            let id = document::add_node(g, kind, pos)?;
            let new = PortRef { node: id.clone(), port: new_port.into() };
            if from_output {
                document::connect(g, port, &new)?;
            } else {
                document::connect(g, &new, port)?;
            }
            Ok(id)
        })?;
        self.selection = BTreeSet::from([id.clone()]);
        Ok(id)
    }

    pub fn connect(&mut self, from: &PortRef, to: &PortRef) -> Result<(), EditError> {
        self.edit(&format!("connect {from} -> {to}"), None, |g| document::connect(g, from, to)).map(|_| ())
    }

    pub fn disconnect_input(&mut self, to: &PortRef) {
        let _ = self.edit(&format!("disconnect {to}"), None, |g| Ok(document::disconnect_input(g, to)));
    }

    pub fn disconnect_output(&mut self, from: &PortRef) {
        let _ = self.edit(&format!("disconnect {from}"), None, |g| Ok(document::disconnect_output(g, from)));
    }

    pub fn remove_link(&mut self, link: &Link) {
        let _ = self.edit(&format!("disconnect {} -> {}", link.from, link.to), None, |g| {
            g.links.retain(|l| l != link);
            Ok(())
        });
    }

    /// Sets a parameter; repeated sets of the same parameter within one gesture are one step.
    pub fn set_param(&mut self, id: &str, name: &str, value: ParamValue) -> Result<(), EditError> {
        let key = format!("param {id}.{name}");
        self.edit(&format!("set {id}.{name}"), Some(&key), |g| document::set_param(g, id, name, value))
    }

    pub fn reset_param(&mut self, id: &str, name: &str) {
        let _ = self.edit(&format!("reset {id}.{name}"), None, |g| document::reset_param(g, id, name));
    }

    pub fn move_nodes(&mut self, moves: &[(String, [f32; 2])]) {
        let label = match moves {
            [(id, _)] => format!("move {id}"),
            _ => format!("move {} nodes", moves.len()),
        };
        let _ = self.edit(&label, None, |g| {
            document::move_nodes(g, moves);
            Ok(())
        });
    }

    pub fn insert_on_link(&mut self, id: &str, link: &Link) -> Result<(), EditError> {
        self.edit(&format!("insert {id}"), None, |g| document::insert_on_link(g, id, link))
    }

    /// Deletes the selected nodes and their links.
    pub fn delete_selected(&mut self) -> usize {
        let ids: Vec<String> = self.selection.iter().cloned().collect();
        if ids.is_empty() {
            return 0;
        }
        let label = if ids.len() == 1 { format!("delete {}", ids[0]) } else { format!("delete {} nodes", ids.len()) };
        let n = self.edit(&label, None, |g| Ok(document::remove_nodes(g, &ids))).unwrap_or(0);
        self.selection.clear();
        n
    }

    /// Copies the selected nodes; returns the fragment's text for the system clipboard.
    pub fn copy_selected(&mut self) -> Option<String> {
        if self.selection.is_empty() {
            return None;
        }
        let fragment = Fragment::copy(&self.graph, &self.selection);
        let text = fragment.to_text();
        self.info(format!("copied {} node(s)", fragment.nodes.len()));
        self.clipboard = Some(fragment);
        Some(text)
    }

    pub fn cut_selected(&mut self) -> Option<String> {
        let text = self.copy_selected()?;
        self.delete_selected();
        Some(text)
    }

    /// Pastes `text` if it holds nodes, else the editor's own clipboard, at `at`; the
    /// pasted nodes become the selection.
    pub fn paste(&mut self, text: Option<&str>, at: [f32; 2]) -> Result<Vec<String>, EditError> {
        let fragment = match text.map(Fragment::from_text) {
            Some(Ok(f)) => f,
            _ => match &self.clipboard {
                Some(f) => f.clone(),
                None => {
                    let e = EditError::Clipboard("nothing to paste: copy nodes first".into());
                    self.error(e.to_string());
                    return Err(e);
                }
            },
        };
        let ids =
            self.edit(&format!("paste {} node(s)", fragment.nodes.len()), None, |g| document::paste(g, &fragment, at))?;
        self.selection = ids.iter().cloned().collect();
        Ok(ids)
    }

    pub fn duplicate_selected(&mut self) -> Result<Vec<String>, EditError> {
        let ids: Vec<String> = self.selection.iter().cloned().collect();
        if ids.is_empty() {
            return Ok(Vec::new());
        }
        let new = self
            .edit(&format!("duplicate {} node(s)", ids.len()), None, |g| document::duplicate(g, &ids, [40.0, 40.0]))?;
        self.selection = new.iter().cloned().collect();
        Ok(new)
    }

    pub fn select_only(&mut self, id: &str) {
        self.selection = BTreeSet::from([id.to_string()]);
    }

    /// Writes the graph (canonical, atomic) to `path`, which becomes the document's file.
    pub fn save_as(&mut self, path: &Path) -> Result<(), String> {
        self.graph.save(path).map_err(|e| format!("cannot save {}: {e}", path.display()))?;
        let old_autosave = document::autosave_path(self.path.as_deref());
        let _ = std::fs::remove_file(&old_autosave);
        let _ = std::fs::remove_file(document::autosave_path(Some(path)));
        self.path = Some(path.to_path_buf());
        self.mark_saved(None);
        self.info(format!("saved {}", path.display()));
        Ok(())
    }

    /// Saves to the document's file; `Err` without a file (use [`EditorState::save_as`]).
    pub fn save(&mut self) -> Result<(), String> {
        let path = self.path.clone().ok_or_else(|| "the graph has no file yet: use Save As".to_string())?;
        self.save_as(&path)
    }
}

/// Whether two graphs are the same document. Equal graphs compare fast; graphs holding a
/// NaN (a file may) are never `==`, so those compare by their canonical text.
fn same_graph(a: &Graph, b: &Graph) -> bool {
    a == b || a.to_ron() == b.to_ron()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn edits_undo_and_mark_dirty() {
        let mut s = EditorState::default();
        assert!(!s.is_dirty());
        let id = s.add_node("Number", [0.0, 0.0]).unwrap();
        assert!(s.is_dirty());
        assert_eq!(s.title(), "* untitled - werkstatt");
        s.set_param(&id, "value", ParamValue::Float(1.0)).unwrap();
        s.set_param(&id, "value", ParamValue::Float(2.0)).unwrap();
        s.seal();
        s.set_param(&id, "value", ParamValue::Float(3.0)).unwrap();
        assert_eq!(s.history.len(), 3);
        s.undo();
        assert_eq!(s.graph.nodes[&id].params["value"], ParamValue::Float(2.0));
        s.undo();
        s.undo();
        assert!(!s.is_dirty());
        assert!(s.selection.is_empty(), "undoing the add drops the node from the selection");
    }

    #[test]
    fn undo_and_redo_across_a_save_track_dirtiness_and_the_inspected_node() {
        let dir = std::env::temp_dir().join(format!("werkstatt-undo-save-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("g.ron");
        let mut s = EditorState::default();
        let a = s.add_node("Number", [0.0, 0.0]).unwrap();
        s.set_param(&a, "value", ParamValue::Float(4.0)).unwrap();
        s.save_as(&path).unwrap();
        assert!(!s.is_dirty());
        // Undo after a save: the graph differs from the file again.
        assert!(s.undo());
        assert!(s.is_dirty(), "undo after save leaves the document clean");
        assert_eq!(s.graph.nodes[&a].params.get("value"), None, "undo did not restore the default");
        // Redo back to the saved state: clean again, and the title says so.
        assert!(s.redo());
        assert!(!s.is_dirty(), "redo to the saved graph leaves it dirty");
        assert_eq!(s.title(), "g.ron - werkstatt");
        assert!(!s.redo(), "nothing left to redo");
        // Undoing the step that added the inspected node stops inspecting it.
        let b = s.add_node("Number", [100.0, 0.0]).unwrap();
        s.inspected = Some(PortRef { node: b.clone(), port: "value".into() });
        assert!(s.undo());
        assert!(!s.graph.nodes.contains_key(&b));
        assert_eq!(s.inspected, None, "the inspector still shows a node that undo removed");
        // A reload from disk is one undoable step, and undoing it brings the edit back.
        s.set_param(&a, "value", ParamValue::Float(9.0)).unwrap();
        let on_disk = Graph::load(&path).unwrap();
        s.replace_graph(on_disk, "reload from disk");
        assert_eq!(s.graph.nodes[&a].params["value"], ParamValue::Float(4.0));
        assert!(s.undo());
        assert_eq!(s.graph.nodes[&a].params["value"], ParamValue::Float(9.0));
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn refused_edits_leave_a_message_and_no_step() {
        let mut s = EditorState::default();
        let cam = s.add_node("OrbitCamera", [0.0, 0.0]).unwrap();
        let tm = s.add_node("Tonemap", [200.0, 0.0]).unwrap();
        let steps = s.history.len();
        let e = s
            .connect(&PortRef { node: cam, port: "camera".into() }, &PortRef { node: tm, port: "image".into() })
            .unwrap_err();
        assert!(matches!(e, EditError::IncompatibleTypes { .. }));
        assert_eq!(s.history.len(), steps);
        let m = s.last_message().unwrap();
        assert_eq!(m.level, Level::Error);
        assert!(m.text.contains("cannot connect"), "{}", m.text);
    }

    #[test]
    fn copy_paste_delete_through_the_state() {
        let mut s = EditorState::default();
        let a = s.add_node("Number", [10.0, 10.0]).unwrap();
        s.set_param(&a, "value", ParamValue::Float(7.0)).unwrap();
        let text = s.copy_selected().unwrap();
        let ids = s.paste(None, [100.0, 100.0]).unwrap();
        assert_eq!(ids, vec!["number_2".to_string()]);
        assert_eq!(s.graph.nodes["number_2"].params["value"], ParamValue::Float(7.0));
        let ids = s.paste(Some(&text), [300.0, 100.0]).unwrap();
        assert_eq!(ids, vec!["number_3".to_string()]);
        assert_eq!(s.selection.len(), 1);
        assert_eq!(s.delete_selected(), 1);
        assert!(!s.graph.nodes.contains_key("number_3"));
        s.select_only("number");
        let dup = s.duplicate_selected().unwrap();
        assert_eq!(dup, vec!["number_3".to_string()]);
        assert_eq!(s.graph.nodes["number_3"].pos, [50.0, 50.0]);
    }

    #[test]
    fn save_writes_canonical_text_and_clears_dirty() {
        let dir = std::env::temp_dir().join(format!("werkstatt-state-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let path = dir.join("g.ron");
        let mut s = EditorState::default();
        s.add_node("Number", [0.0, 0.0]).unwrap();
        assert!(s.save().is_err());
        s.save_as(&path).unwrap();
        assert!(!s.is_dirty());
        let text = std::fs::read_to_string(&path).unwrap();
        assert_eq!(text, s.graph.to_ron());
        let (reopened, problems) = EditorState::open(&path).unwrap();
        assert!(problems.is_empty());
        assert_eq!(reopened.graph, s.graph);
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

//! The editor's file side: autosave (every few seconds while there are unsaved changes,
//! to `<graph>.autosave.ron` next to the graph), recovery of an autosave on the next open,
//! and noticing that the graph file was changed on disk by someone else.

use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use super::document::autosave_path;
use super::state::EditorState;
use crate::core::graph::Graph;

/// An autosave newer than the file, found when the file is opened.
#[derive(Clone, Debug)]
pub struct Recovery {
    pub path: PathBuf,
    pub graph: Graph,
    pub modified: Option<SystemTime>,
}

/// The autosave for `path` (or for an untitled graph), if there is one whose graph differs
/// from `current` (what was just opened).
pub fn find_recovery(path: Option<&Path>, current: &Graph) -> Option<Recovery> {
    let auto = autosave_path(path);
    let text = std::fs::read_to_string(&auto).ok()?;
    let (graph, _) = Graph::load_lenient(&text, &auto).ok()?;
    if &graph == current {
        let _ = std::fs::remove_file(&auto);
        return None;
    }
    let modified = std::fs::metadata(&auto).and_then(|m| m.modified()).ok();
    Some(Recovery { path: auto, graph, modified })
}

fn stamp(path: &Path) -> Option<(SystemTime, u64)> {
    let m = std::fs::metadata(path).ok()?;
    Some((m.modified().ok()?, m.len()))
}

pub struct FileWatch {
    pub autosave_every: Duration,
    last_autosave: Instant,
    /// What the autosave file holds now.
    autosaved: Option<Graph>,
    watched: Option<PathBuf>,
    disk_stamp: Option<(SystemTime, u64)>,
    last_check: Instant,
    /// A graph file changed on disk that differs from the document, waiting for an answer.
    pub changed_on_disk: Option<Graph>,
}

impl Default for FileWatch {
    fn default() -> Self {
        FileWatch::new(Duration::from_secs(5))
    }
}

impl FileWatch {
    pub fn new(autosave_every: Duration) -> Self {
        FileWatch {
            autosave_every,
            last_autosave: Instant::now(),
            autosaved: None,
            watched: None,
            disk_stamp: None,
            last_check: Instant::now(),
            changed_on_disk: None,
        }
    }

    /// Remembers the file's current state (after open or save), so only later changes count.
    pub fn track(&mut self, path: Option<&Path>) {
        self.watched = path.map(Path::to_path_buf);
        self.disk_stamp = path.and_then(stamp);
        self.changed_on_disk = None;
    }

    /// Writes the autosave when it is due: unsaved changes that the autosave does not hold
    /// yet, and `autosave_every` passed since the last one. Returns the file written.
    pub fn autosave(&mut self, state: &EditorState, force: bool) -> Option<Result<PathBuf, String>> {
        if !state.is_dirty() || self.autosaved.as_ref() == Some(&state.graph) {
            return None;
        }
        if !force && self.last_autosave.elapsed() < self.autosave_every {
            return None;
        }
        self.last_autosave = Instant::now();
        let path = autosave_path(state.path.as_deref());
        let result = crate::io::atomic::write_atomic(&path, state.graph.to_ron().as_bytes())
            .map(|_| path.clone())
            .map_err(|e| format!("cannot write the autosave {}: {e}", path.display()));
        if result.is_ok() {
            self.autosaved = Some(state.graph.clone());
        }
        Some(result)
    }

    /// Deletes the autosave (after a save, or when changes are discarded).
    pub fn discard_autosave(&mut self, path: Option<&Path>) {
        let _ = std::fs::remove_file(autosave_path(path));
        self.autosaved = None;
    }

    /// Checks (at most once a second, or now with `force`) whether the graph file changed on
    /// disk; a change whose content differs from the document as last loaded or saved is
    /// kept in `changed_on_disk` for the user to reload or ignore.
    pub fn poll_disk(&mut self, state: &EditorState, force: bool) -> bool {
        if !force && self.last_check.elapsed() < Duration::from_secs(1) {
            return false;
        }
        self.last_check = Instant::now();
        let Some(path) = self.watched.clone() else { return false };
        let now = stamp(&path);
        if now == self.disk_stamp || now.is_none() {
            return false;
        }
        self.disk_stamp = now;
        let Ok(text) = std::fs::read_to_string(&path) else { return false };
        let Ok((graph, _)) = Graph::load_lenient(&text, &path) else { return false };
        if &graph == state.saved_graph() || graph == state.graph {
            return false;
        }
        self.changed_on_disk = Some(graph);
        true
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::editor::document;

    fn temp_dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("werkstatt-files-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn autosave_then_recover() {
        let dir = temp_dir("autosave");
        let path = dir.join("g.ron");
        let mut s = EditorState::default();
        s.save_as(&path).unwrap();
        let mut fw = FileWatch::new(Duration::from_secs(3600));
        assert!(fw.autosave(&s, false).is_none(), "nothing unsaved");
        s.add_node("Number", [0.0, 0.0]).unwrap();
        assert!(fw.autosave(&s, false).is_none(), "not due yet");
        let written = fw.autosave(&s, true).unwrap().unwrap();
        assert_eq!(written, dir.join("g.autosave.ron"));
        assert!(fw.autosave(&s, true).is_none(), "already holds this graph");

        // Next session: the file is older than the autosave.
        let (opened, _) = EditorState::open(&path).unwrap();
        let rec = find_recovery(Some(&path), &opened.graph).unwrap();
        assert_eq!(rec.graph, s.graph);
        // Saving removes the autosave.
        s.save().unwrap();
        assert!(!written.exists());
        assert!(find_recovery(Some(&path), &s.graph).is_none());
        std::fs::remove_dir_all(&dir).unwrap();
    }

    #[test]
    fn a_file_changed_on_disk_is_noticed() {
        let dir = temp_dir("disk");
        let path = dir.join("g.ron");
        let mut s = EditorState::default();
        s.save_as(&path).unwrap();
        let mut fw = FileWatch::default();
        fw.track(Some(&path));
        assert!(!fw.poll_disk(&s, true));
        let mut other = s.graph.clone();
        document::add_node(&mut other, "Number", [0.0, 0.0]).unwrap();
        // A different length guarantees a new stamp even on coarse file-system clocks.
        other.save(&path).unwrap();
        assert!(fw.poll_disk(&s, true));
        assert_eq!(fw.changed_on_disk.as_ref(), Some(&other));
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

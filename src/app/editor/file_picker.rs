//! File dialogs drawn by egui itself (egui-file-dialog): the same on every desktop and in
//! tests, with no desktop portal to talk to.

use std::path::{Path, PathBuf};

use egui_file_dialog::{DialogState, FileDialog};

use super::app::Then;

/// What the picked file is for.
#[derive(Clone, Debug)]
pub enum Purpose {
    /// Open a graph, or save the graph there and then do `then`.
    Graph { save: bool, then: Option<Then> },
    /// A file parameter, stored relative to `base` (the graph's folder).
    Param { node: String, param: String, base: PathBuf },
}

/// An open file dialog and what its answer is for.
pub struct FilePicker {
    dialog: FileDialog,
    purpose: Purpose,
}

/// What a dialog said this frame.
pub enum Answer {
    Open,
    Cancelled,
    Picked(PathBuf, Purpose),
}

impl FilePicker {
    /// A dialog titled `title` for files with one of `extensions` (any file when empty), starting
    /// in the folder of `near` (or `near` itself when it is a folder), proposing `file_name`
    /// when saving.
    pub fn new(
        title: &str,
        extensions: &[&'static str],
        near: &Path,
        file_name: Option<&str>,
        purpose: Purpose,
    ) -> Self {
        let mut dialog = FileDialog::new().title(title).as_modal(true);
        if !extensions.is_empty() {
            let label = extensions.iter().map(|e| format!("*.{e}")).collect::<Vec<_>>().join(", ");
            dialog = dialog.add_file_filter_extensions(&label, extensions.to_vec()).default_file_filter(&label);
        }
        let dir = if near.is_dir() { Some(near) } else { near.parent() };
        if let Some(dir) = dir.filter(|d| !d.as_os_str().is_empty()).and_then(|d| std::path::absolute(d).ok()) {
            dialog = dialog.initial_directory(dir);
        }
        if let Some(name) = file_name {
            dialog = dialog.default_file_name(name);
        }
        match &purpose {
            Purpose::Graph { save: true, .. } => dialog.save_file(),
            _ => dialog.pick_file(),
        }
        FilePicker { dialog, purpose }
    }

    /// Draws the dialog; once answered, says with what.
    pub fn show(&mut self, ctx: &egui::Context) -> Answer {
        self.dialog.update(ctx);
        match self.dialog.state() {
            DialogState::Open => Answer::Open,
            DialogState::Picked(p) => Answer::Picked(p.clone(), self.purpose.clone()),
            DialogState::Closed | DialogState::Cancelled | DialogState::PickedMultiple(_) => Answer::Cancelled,
        }
    }
}

//! The editor window: menus, canvas, viewport, inspector, status bar and dialogs, glued
//! to the plain-Rust [`EditorState`] and [`Live`] evaluation.

use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant};

use egui::{Color32, Key, KeyboardShortcut, Modifiers, RichText};

use super::canvas::{Action, Canvas, ERROR_COLOR, node_menu};
use super::cost;
use super::file_picker::{Answer, FilePicker, Purpose};
use super::files::{FileWatch, Recovery, find_recovery};
use super::inspector::Inspector;
use super::live::Live;
use super::state::{EditorState, Level};
use super::viewport::Viewport;
use crate::gpu::{Backend, GpuContext};

/// How the editor talks to the world; tests switch the system parts off.
#[derive(Clone, Debug)]
pub struct Options {
    /// File dialogs behind "Browse…" and the inspector's file buttons; without, a path field
    /// is asked for instead.
    pub file_dialogs: bool,
    /// Write `<graph>.autosave.ron` while there are unsaved changes.
    pub autosave: bool,
    /// Reload resources edited on disk, and notice a changed graph file.
    pub watch_files: bool,
}

impl Default for Options {
    fn default() -> Self {
        Options { file_dialogs: true, autosave: true, watch_files: true }
    }
}

/// What to do once unsaved changes are dealt with.
#[derive(Clone, Debug)]
pub enum Then {
    New,
    Open(Option<PathBuf>),
    Quit,
}

#[derive(Clone, Debug)]
enum Dialog {
    Unsaved(Then),
    Recover(Recovery),
    Path { save: bool, text: String, then: Option<Then> },
}

/// UI frame times, for the status bar and benchmarks.
#[derive(Default)]
pub struct FrameTimes {
    samples: VecDeque<Duration>,
}

impl FrameTimes {
    pub fn push(&mut self, d: Duration) {
        self.samples.push_back(d);
        if self.samples.len() > 240 {
            self.samples.pop_front();
        }
    }

    /// Median, 95th percentile and maximum of the recent frames, in milliseconds.
    pub fn stats(&self) -> Option<(f64, f64, f64)> {
        if self.samples.is_empty() {
            return None;
        }
        let mut v: Vec<f64> = self.samples.iter().map(|d| d.as_secs_f64() * 1e3).collect();
        v.sort_by(f64::total_cmp);
        let at = |q: f64| v[((v.len() - 1) as f64 * q).round() as usize];
        Some((at(0.5), at(0.95), v[v.len() - 1]))
    }

    pub fn clear(&mut self) {
        self.samples.clear();
    }
}

pub struct EditorApp {
    pub state: EditorState,
    pub live: Live,
    pub canvas: Canvas,
    viewport: Viewport,
    inspector: Inspector,
    pub files: FileWatch,
    gpu: Option<Arc<GpuContext>>,
    /// What cost estimates are checked against: the device's limits and the memory budget.
    limits: Option<cost::Limits>,
    /// Calls for a repaint when the evaluation worker finishes.
    waker: super::live::Waker,
    /// The refusals already reported in the status bar.
    reported_refusals: std::collections::BTreeMap<String, String>,
    dialog: Option<Dialog>,
    /// The file dialog, while one is open.
    picker: Option<FilePicker>,
    options: Options,
    /// Time spent in each UI frame (layout, evaluation, canvas), newest last.
    pub frame_times: FrameTimes,
    /// Whole frames as eframe measures them (UI, tessellation, painting), in a window.
    pub window_frames: FrameTimes,
    title: String,
    quitting: bool,
    last_frame: Option<Instant>,
}

impl EditorApp {
    /// Creates the editor, opening `path`. The engine opens a device of its own on the
    /// window's adapter: the window paints on its device while the engine's worker submits.
    pub fn new(cc: &eframe::CreationContext<'_>, path: Option<PathBuf>, options: Options) -> Self {
        let mut engine_error = None;
        let gpu = cc.wgpu_render_state.as_ref().and_then(|rs| match GpuContext::from_adapter(&rs.adapter) {
            Ok(g) => Some(Arc::new(g)),
            Err(e) => {
                engine_error = Some(format!("{e:#}"));
                None
            }
        });
        let egui_ctx = cc.egui_ctx.clone();
        let waker: super::live::Waker = Arc::new(move || egui_ctx.request_repaint());
        let limits = gpu.as_deref().map(cost::Limits::for_gpu);
        let mut app = EditorApp {
            state: EditorState::default(),
            live: new_live(PathBuf::from("."), options.watch_files, &waker),
            limits,
            waker,
            reported_refusals: Default::default(),
            canvas: Canvas::new(),
            viewport: Viewport::new(),
            inspector: Inspector { file_dialogs: options.file_dialogs, picker: None },
            files: FileWatch::default(),
            gpu,
            dialog: None,
            picker: None,
            options,
            frame_times: FrameTimes::default(),
            window_frames: FrameTimes::default(),
            title: String::new(),
            quitting: false,
            last_frame: None,
        };
        match path {
            Some(p) if p.exists() => app.open(&p),
            Some(p) => {
                // A new graph that will be saved there.
                app.state.path = Some(p.clone());
                app.live = new_live(base_dir(Some(&p)), app.options.watch_files, &app.waker);
                app.state.info(format!("{} does not exist yet; it is created on save", p.display()));
            }
            None => {
                if let Some(rec) = find_recovery(None, &app.state.graph) {
                    app.dialog = Some(Dialog::Recover(rec));
                }
            }
        }
        if let Some(gpu) = &app.gpu {
            app.state.info(format!("rendering on {}", gpu.adapter_name()));
        }
        if let Some(e) = engine_error {
            app.state.error(format!("cannot open a device for the engine: {e}"));
        }
        app
    }

    /// The GPU the nodes render with (a device of its own on the window's adapter).
    pub fn gpu(&self) -> Option<&GpuContext> {
        self.gpu.as_deref()
    }

    /// The viewport's picture as egui samples it (gamma-encoded Rgba8Unorm).
    pub fn viewport_display(&self) -> Option<&crate::gpu::GpuImage> {
        self.viewport.display()
    }

    /// Opens a graph file (unsaved changes must have been dealt with).
    pub fn open(&mut self, path: &Path) {
        match EditorState::open(path) {
            Ok((state, problems)) => {
                let mut state = state;
                for p in &problems {
                    state.error(p.to_string());
                }
                state.info(format!("opened {}", path.display()));
                let rec = find_recovery(Some(path), &state.graph);
                self.state = state;
                self.live = new_live(base_dir(Some(path)), self.options.watch_files, &self.waker);
                self.canvas.reset();
                self.files.track(Some(path));
                if let Some(rec) = rec {
                    self.dialog = Some(Dialog::Recover(rec));
                }
            }
            Err(e) => self.state.error(e),
        }
    }

    fn new_graph(&mut self) {
        self.state = EditorState::default();
        self.live = new_live(PathBuf::from("."), self.options.watch_files, &self.waker);
        self.canvas.reset();
        self.files.track(None);
    }

    /// Runs `then` now, or asks first when there are unsaved changes.
    fn request(&mut self, then: Then, ctx: &egui::Context) {
        if self.state.is_dirty() {
            self.dialog = Some(Dialog::Unsaved(then));
        } else {
            self.proceed(then, ctx);
        }
    }

    fn proceed(&mut self, then: Then, ctx: &egui::Context) {
        match then {
            Then::New => self.new_graph(),
            Then::Open(Some(p)) => self.open(&p),
            Then::Open(None) => {
                // A path field always works; "Browse…" adds the system dialog where there is one.
                let text = self.state.path.as_deref().map(|p| base_dir(Some(p)).join("").display().to_string());
                self.dialog = Some(Dialog::Path { save: false, text: text.unwrap_or_default(), then: None });
            }
            Then::Quit => {
                self.quitting = true;
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
        }
    }

    /// Saves to the graph's file, or asks for one, then does `then`. Returns whether it saved.
    fn save(&mut self, then: Option<Then>, ctx: &egui::Context) -> bool {
        match self.state.path.clone() {
            Some(p) => self.save_to(&p, then, ctx),
            None => {
                self.save_as(then, ctx);
                false
            }
        }
    }

    fn save_to(&mut self, path: &Path, then: Option<Then>, ctx: &egui::Context) -> bool {
        let old = self.state.path.clone();
        match self.state.save_as(path) {
            Ok(()) => {
                self.files.discard_autosave(old.as_deref());
                self.files.discard_autosave(Some(path));
                self.files.track(Some(path));
                if base_dir(old.as_deref()) != base_dir(Some(path)) {
                    // Relative file parameters now mean other files: evaluate afresh.
                    self.live.settings.base_dir = base_dir(Some(path));
                    self.live.reset();
                }
                if let Some(t) = then {
                    self.proceed(t, ctx);
                }
                true
            }
            Err(e) => {
                self.state.error(e);
                false
            }
        }
    }

    fn save_as(&mut self, then: Option<Then>, _ctx: &egui::Context) {
        let text = self.state.path.as_ref().map(|p| p.display().to_string()).unwrap_or_default();
        self.dialog = Some(Dialog::Path { save: true, text, then });
    }

    /// Opens the file dialog for the path prompt (the prompt closes; the dialog's answer
    /// opens or saves).
    fn browse(&mut self, save: bool, current: &str, then: Option<Then>) {
        let title = if save { "Save graph as" } else { "Open graph" };
        let name = save.then(|| self.state.file_name());
        let purpose = Purpose::Graph { save, then };
        self.picker = Some(FilePicker::new(title, &["ron"], Path::new(current), name.as_deref(), purpose));
    }

    /// Draws the open file dialog and acts on its answer.
    fn file_picker(&mut self, ctx: &egui::Context) {
        let Some(picker) = &mut self.picker else { return };
        match picker.show(ctx) {
            Answer::Open => {}
            Answer::Cancelled => self.picker = None,
            Answer::Picked(path, purpose) => {
                self.picker = None;
                match purpose {
                    Purpose::Graph { save: true, then } => {
                        self.save_to(&graph_file(path), then, ctx);
                    }
                    Purpose::Graph { save: false, .. } => self.open(&path),
                    Purpose::Param { node, param, base } => {
                        let value = crate::core::param::ParamValue::Str(super::inspector::relative_to(&path, &base));
                        if let Err(e) = self.state.set_param(&node, &param, value) {
                            self.state.error(e.to_string());
                        }
                    }
                }
            }
        }
    }

    fn apply(&mut self, actions: Vec<Action>, ctx: &egui::Context) {
        for a in actions {
            match a {
                Action::Connect(f, t) => {
                    let _ = self.state.connect(&f, &t);
                }
                Action::RemoveLink(l) => self.state.remove_link(&l),
                Action::DisconnectInput(p) => self.state.disconnect_input(&p),
                Action::DisconnectOutput(p) => self.state.disconnect_output(&p),
                Action::Add { kind, pos } => {
                    let _ = self.state.add_node(kind, pos);
                }
                Action::AddConnected { kind, pos, port, from_output, new_port } => {
                    let _ = self.state.add_node_connected(kind, pos, &port, from_output, new_port);
                }
                Action::Inspect(p) => self.state.inspected = p,
                Action::SelectOnly(id) => self.state.select_only(&id),
                Action::SetSelection(s) => self.state.selection = s,
                Action::Move(m) => self.state.move_nodes(&m),
                Action::InsertOnLink(id, link) => {
                    if self.state.insert_on_link(&id, &link).is_ok() {
                        self.state.info(format!("inserted {id} into {} -> {}", link.from, link.to));
                    }
                }
                Action::Delete => {
                    self.state.delete_selected();
                }
                Action::Duplicate => {
                    let _ = self.state.duplicate_selected();
                }
                Action::Copy => {
                    if let Some(text) = self.state.copy_selected() {
                        ctx.copy_text(text);
                    }
                }
            }
            ctx.request_repaint();
        }
    }

    fn shortcuts(&mut self, ctx: &egui::Context) {
        // Text fields keep their own keys (undo in a text field, copy of text).
        if ctx.egui_wants_keyboard_input() || self.dialog.is_some() {
            return;
        }
        let cmd = Modifiers::COMMAND;
        let shortcut = |m: Modifiers, k: Key| ctx.input_mut(|i| i.consume_shortcut(&KeyboardShortcut::new(m, k)));
        if shortcut(cmd | Modifiers::SHIFT, Key::Z) || shortcut(cmd, Key::Y) {
            self.state.redo();
        }
        if shortcut(cmd, Key::Z) {
            self.state.undo();
        }
        if shortcut(cmd | Modifiers::SHIFT, Key::S) {
            self.save_as(None, ctx);
        }
        if shortcut(cmd, Key::S) {
            self.save(None, ctx);
        }
        if shortcut(cmd, Key::O) {
            self.request(Then::Open(None), ctx);
        }
        if shortcut(cmd, Key::N) {
            self.request(Then::New, ctx);
        }
        if shortcut(cmd, Key::D) {
            let _ = self.state.duplicate_selected();
        }
        if shortcut(cmd, Key::A) {
            self.state.selection = self.state.graph.nodes.keys().cloned().collect();
        }
        if shortcut(Modifiers::NONE, Key::F) {
            self.canvas.request_fit();
        }
        if self.live.busy().is_some() && shortcut(Modifiers::NONE, Key::Escape) {
            self.live.cancel();
            self.state.info("evaluation cancelled: the viewport shows the last finished frame");
        }
        if shortcut(Modifiers::NONE, Key::Delete) || shortcut(Modifiers::NONE, Key::Backspace) {
            self.state.delete_selected();
        }
        let at = self.canvas.graph_pos(ctx.pointer_latest_pos());
        // Copy, cut and paste come as events from the window (and as keys in tests).
        let events = ctx.input(|i| i.events.clone());
        for e in events {
            match e {
                egui::Event::Copy => self.copy(ctx),
                egui::Event::Cut => {
                    if let Some(text) = self.state.cut_selected() {
                        ctx.copy_text(text);
                    }
                }
                egui::Event::Paste(text) => {
                    let _ = self.state.paste(Some(&text), at);
                }
                egui::Event::Key { key: Key::C, pressed: true, modifiers, .. } if modifiers.command => self.copy(ctx),
                egui::Event::Key { key: Key::X, pressed: true, modifiers, .. } if modifiers.command => {
                    if let Some(text) = self.state.cut_selected() {
                        ctx.copy_text(text);
                    }
                }
                egui::Event::Key { key: Key::V, pressed: true, modifiers, .. } if modifiers.command => {
                    let _ = self.state.paste(None, at);
                }
                _ => {}
            }
        }
    }

    fn copy(&mut self, ctx: &egui::Context) {
        if let Some(text) = self.state.copy_selected() {
            ctx.copy_text(text);
        }
    }

    fn menu_bar(&mut self, ui: &mut egui::Ui) {
        let ctx = ui.ctx().clone();
        let keys = |m: Modifiers, k: Key| ctx.format_shortcut(&KeyboardShortcut::new(m, k));
        let item = |text: &str, m: Modifiers, k: Key| egui::Button::new(text.to_string()).shortcut_text(keys(m, k));
        let cmd = Modifiers::COMMAND;
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| {
                if ui.add(item("New", cmd, Key::N)).clicked() {
                    self.request(Then::New, &ctx);
                    ui.close();
                }
                if ui.add(item("Open…", cmd, Key::O)).clicked() {
                    self.request(Then::Open(None), &ctx);
                    ui.close();
                }
                if ui.add(item("Save", cmd, Key::S)).clicked() {
                    self.save(None, &ctx);
                    ui.close();
                }
                if ui.add(item("Save As…", cmd | Modifiers::SHIFT, Key::S)).clicked() {
                    self.save_as(None, &ctx);
                    ui.close();
                }
                ui.separator();
                if ui.button("Quit").clicked() {
                    self.request(Then::Quit, &ctx);
                    ui.close();
                }
            });
            ui.menu_button("Edit", |ui| {
                let undo =
                    self.state.history.undo_label().map(|l| format!("Undo: {l}")).unwrap_or("Undo: nothing".into());
                if ui
                    .add_enabled(
                        self.state.history.can_undo(),
                        egui::Button::new(undo).shortcut_text(keys(cmd, Key::Z)),
                    )
                    .clicked()
                {
                    self.state.undo();
                }
                let redo =
                    self.state.history.redo_label().map(|l| format!("Redo: {l}")).unwrap_or("Redo: nothing".into());
                if ui
                    .add_enabled(
                        self.state.history.can_redo(),
                        egui::Button::new(redo).shortcut_text(keys(cmd | Modifiers::SHIFT, Key::Z)),
                    )
                    .clicked()
                {
                    self.state.redo();
                }
                ui.separator();
                let any = !self.state.selection.is_empty();
                if ui.add_enabled(any, item("Copy", cmd, Key::C)).clicked() {
                    self.copy(&ctx);
                    ui.close();
                }
                if ui.add_enabled(self.state.clipboard.is_some(), item("Paste", cmd, Key::V)).clicked() {
                    let at = self.canvas.free_spot(self.canvas.graph_pos(None));
                    let _ = self.state.paste(None, at);
                    ui.close();
                }
                if ui.add_enabled(any, item("Duplicate", cmd, Key::D)).clicked() {
                    let _ = self.state.duplicate_selected();
                    ui.close();
                }
                if ui.add_enabled(any, item("Delete", Modifiers::NONE, Key::Delete)).clicked() {
                    self.state.delete_selected();
                    ui.close();
                }
            });
            ui.menu_button("Add", |ui| {
                if let Some((spec, _)) = node_menu(ui, &mut self.canvas.search, None) {
                    let pos = self.canvas.free_spot(self.canvas.graph_pos(None));
                    let _ = self.state.add_node(spec.kind, pos);
                    self.canvas.search.clear();
                    ui.close();
                }
            });
            ui.menu_button("View", |ui| {
                ui.checkbox(&mut self.canvas.show_timings, "Node timings");
                if ui.button("Frame all nodes (F)").clicked() {
                    self.canvas.request_fit();
                    ui.close();
                }
                if ui.button("Reset viewport camera").clicked() {
                    self.live.camera = None;
                    ui.close();
                }
            });
            ui.separator();
            if ui
                .add_enabled(self.state.history.can_undo(), egui::Button::new("Undo"))
                .on_hover_text(self.state.history.undo_label().unwrap_or("nothing to undo"))
                .clicked()
            {
                self.state.undo();
            }
            if ui
                .add_enabled(self.state.history.can_redo(), egui::Button::new("Redo"))
                .on_hover_text(self.state.history.redo_label().unwrap_or("nothing to redo"))
                .clicked()
            {
                self.state.redo();
            }
            ui.toggle_value(&mut self.canvas.show_timings, "⏱ Timings");
        });
    }

    /// Says in the status bar when a change was refused by its cost (once per refusal).
    fn report_refusals(&mut self) {
        if self.live.refused != self.reported_refusals {
            for (id, why) in &self.live.refused {
                if self.reported_refusals.get(id) != Some(why) {
                    self.state.error(format!("{id}: {why}"));
                }
            }
            self.reported_refusals = self.live.refused.clone();
        }
    }

    fn status_bar(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            if let Some((median, p95, _)) = self.window_frames.stats() {
                ui.label(RichText::new(format!("frame {median:.1} ms (p95 {p95:.1})")).small().monospace())
                    .on_hover_text("whole frames: UI, tessellation and painting, median of the last 240");
            }
            if let Some((median, p95, _)) = self.frame_times.stats() {
                ui.label(RichText::new(format!("ui {median:.1} ms (p95 {p95:.1})")).small().monospace())
                    .on_hover_text("inside the editor's update: evaluation, canvas, panels");
            }
            let s = self.live.last_summary;
            ui.label(
                RichText::new(format!(
                    "eval {:.2} ms, {} ran, {} cached{}",
                    self.live.last_eval.as_secs_f64() * 1e3,
                    s.ran,
                    s.skipped,
                    if s.failed > 0 { format!(", {} failed", s.failed) } else { String::new() }
                ))
                .small()
                .monospace(),
            );
            if let Some(b) = self.live.busy() {
                let node = b.node.as_deref().unwrap_or("");
                ui.label(
                    RichText::new(format!(
                        "rendering {node} {:.0}%, {:.1} s",
                        b.fraction * 100.0,
                        b.elapsed.as_secs_f64()
                    ))
                    .small()
                    .monospace(),
                )
                .on_hover_text("the evaluation runs on its own thread; Esc cancels it");
            }
            ui.separator();
            if let Some(m) = self.state.last_message() {
                let color = if m.level == Level::Error { ERROR_COLOR } else { ui.visuals().text_color() };
                ui.add(egui::Label::new(RichText::new(&m.text).color(color)).truncate());
            }
        });
    }

    fn dialogs(&mut self, ctx: &egui::Context) {
        // Taken out while shown: a button may open the next dialog (recovery after open).
        let Some(mut dialog) = self.dialog.take() else { return };
        let mut close = false;
        let mut browse = None;
        let modal = egui::Modal::new(egui::Id::new("werkstatt-dialog")).show(ctx, |ui| {
            ui.set_max_width(420.0);
            match &mut dialog {
                Dialog::Unsaved(then) => {
                    ui.heading("Unsaved changes");
                    ui.label(format!("{} has unsaved changes. Save them first?", self.state.file_name()));
                    ui.horizontal(|ui| {
                        if ui.button("Save").clicked() {
                            close = true;
                            self.save(Some(then.clone()), ctx);
                        }
                        if ui.button("Don't save").clicked() {
                            close = true;
                            self.files.discard_autosave(self.state.path.as_deref());
                            self.state.mark_saved(None);
                            self.proceed(then.clone(), ctx);
                        }
                        if ui.button("Cancel").clicked() {
                            close = true;
                        }
                    });
                }
                Dialog::Recover(rec) => {
                    ui.heading("Recover unsaved changes?");
                    let age = rec
                        .modified
                        .and_then(|m| m.elapsed().ok())
                        .map(|d| format!(" (from {} s ago)", d.as_secs()))
                        .unwrap_or_default();
                    ui.label(format!(
                        "{} holds changes{age} that were never saved, probably from a session that ended unexpectedly.",
                        rec.path.display()
                    ));
                    ui.horizontal(|ui| {
                        if ui.button("Recover").clicked() {
                            close = true;
                            self.state.replace_graph(rec.graph.clone(), "recover autosave");
                            self.state.info(format!("recovered {}", rec.path.display()));
                        }
                        if ui.button("Discard").clicked() {
                            close = true;
                            let _ = std::fs::remove_file(&rec.path);
                        }
                    });
                }
                Dialog::Path { save, text, then } => {
                    let save = *save;
                    ui.heading(if save { "Save graph as" } else { "Open graph" });
                    let r =
                        ui.add(egui::TextEdit::singleline(text).hint_text("path/to/graph.ron").desired_width(380.0));
                    if !r.has_focus() && ui.ctx().memory(|m| m.focused().is_none()) {
                        r.request_focus();
                    }
                    let enter = r.lost_focus() && ui.input(|i| i.key_pressed(Key::Enter));
                    ui.horizontal(|ui| {
                        let go = ui.button(if save { "Save" } else { "Open" }).clicked() || enter;
                        if self.options.file_dialogs && ui.button("Browse…").clicked() {
                            close = true;
                            browse = Some((save, text.clone(), then.clone()));
                        }
                        if go && !text.trim().is_empty() {
                            close = true;
                            let p = PathBuf::from(text.trim());
                            if save {
                                self.save_to(&graph_file(p), then.clone(), ctx);
                            } else {
                                self.open(&p);
                            }
                        }
                        if ui.button("Cancel").clicked() {
                            close = true;
                        }
                    });
                }
            }
        });
        if modal.should_close() {
            close = true;
        }
        if !close && self.dialog.is_none() {
            self.dialog = Some(dialog);
        }
        if let Some((save, text, then)) = browse {
            self.browse(save, &text, then);
        }
    }

    fn disk_banner(&mut self, ui: &mut egui::Ui) {
        let Some(g) = self.files.changed_on_disk.clone() else { return };
        ui.horizontal(|ui| {
            ui.colored_label(Color32::from_rgb(240, 190, 80), format!("{} changed on disk.", self.state.file_name()));
            if ui.button("Reload").clicked() {
                self.state.replace_graph(g.clone(), "reload from disk");
                self.state.mark_saved(Some(g.clone()));
                self.files.changed_on_disk = None;
            }
            if ui.button("Ignore").clicked() {
                self.files.changed_on_disk = None;
            }
        });
    }
}

/// Where a graph saved as `path` goes: `.ron` is added when the name has no extension.
fn graph_file(mut path: PathBuf) -> PathBuf {
    if path.extension().is_none() {
        path.set_extension("ron");
    }
    path
}

/// A live evaluation that asks the window for a repaint when its worker finishes.
fn new_live(base: PathBuf, watch_files: bool, waker: &super::live::Waker) -> Live {
    let mut live = Live::new(base, watch_files);
    live.set_waker(waker.clone());
    live
}

fn base_dir(path: Option<&Path>) -> PathBuf {
    path.and_then(Path::parent)
        .filter(|p| !p.as_os_str().is_empty())
        .map(Path::to_path_buf)
        .unwrap_or_else(|| PathBuf::from("."))
}

impl eframe::App for EditorApp {
    fn ui(&mut self, ui: &mut egui::Ui, frame: &mut eframe::Frame) {
        let start = Instant::now();
        if let Some(cpu) = frame.info().cpu_usage {
            self.window_frames.push(Duration::from_secs_f32(cpu.max(0.0)));
        }
        let ctx = ui.ctx().clone();
        let dt = self.last_frame.map_or(0.0, |t| t.elapsed().as_secs_f64());
        self.last_frame = Some(start);
        self.live.advance(dt);

        if ctx.input(|i| i.viewport().close_requested()) && self.state.is_dirty() && !self.quitting {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.dialog = Some(Dialog::Unsaved(Then::Quit));
        }
        self.shortcuts(&ctx);

        self.live.sync_with(
            &self.state.graph,
            self.state.revision,
            self.state.inspected.as_ref(),
            self.limits.as_ref(),
        );
        self.report_refusals();
        // A drag holds its value until it rests or is let go (see `live::SETTLE`).
        self.live.gesture = ctx.input(|i| i.pointer.any_down());
        self.live.pump(self.gpu.as_ref());
        self.canvas.sync(&self.state.graph, self.state.revision);
        let synced = (self.state.revision, self.state.inspected.clone(), self.live.camera.clone());

        egui::Panel::top("menu").show(ui, |ui| {
            self.menu_bar(ui);
            self.disk_banner(ui);
            if let Some(e) = &self.live.shader_error {
                ui.colored_label(ERROR_COLOR, format!("shader reload failed, last good pipelines kept:\n{e}"));
            }
        });
        egui::Panel::bottom("status").show(ui, |ui| self.status_bar(ui));
        egui::Panel::right("side").resizable(true).default_size(420.0).min_size(280.0).show(ui, |ui| {
            let h = (ui.available_height() * 0.5).max(200.0);
            ui.allocate_ui(egui::vec2(ui.available_width(), h), |ui| {
                self.viewport.show(ui, &mut self.state, &mut self.live);
            });
            ui.separator();
            egui::ScrollArea::vertical().show(ui, |ui| self.inspector.show(ui, &mut self.state, &self.live));
        });
        let actions = egui::CentralPanel::default()
            .frame(egui::Frame::NONE)
            .show(ui, |ui| {
                self.canvas.show(
                    ui,
                    &self.state.graph,
                    &self.live,
                    &self.state.selection,
                    self.state.inspected.as_ref(),
                )
            })
            .inner;
        self.apply(actions, &ctx);
        self.dialogs(&ctx);
        if let Some(picker) = self.inspector.picker.take() {
            self.picker = Some(picker);
        }
        self.file_picker(&ctx);

        if self.options.autosave
            && let Some(Err(e)) = self.files.autosave(&self.state, false)
        {
            self.state.error(e);
        }
        if self.options.watch_files {
            self.files.poll_disk(&self.state, false);
        }
        // A gesture (slider drag, typing) ends when nothing is held and nothing has focus.
        if !ctx.input(|i| i.pointer.any_down()) && ctx.memory(|m| m.focused().is_none()) {
            self.state.seal();
        }
        let title = self.state.title();
        if title != self.title {
            ctx.send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
            self.title = title;
        }
        // An edit made this frame is evaluated in the next one: ask for it now.
        let changed = synced != (self.state.revision, self.state.inspected.clone(), self.live.camera.clone());
        if self.live.playing || changed {
            ctx.request_repaint();
        } else if self.live.animating {
            // The worker wakes the window when it finishes; until then, show its progress.
            ctx.request_repaint_after(Duration::from_millis(30));
        } else {
            // Poll files (autosave, disk changes, shader edits) now and then.
            ctx.request_repaint_after(Duration::from_millis(500));
        }
        self.frame_times.push(start.elapsed());
    }
}

/// Opens the editor window on `graph` (or a new graph) and runs until it is closed.
pub fn run(graph: Option<PathBuf>, backend: Backend) -> anyhow::Result<()> {
    let mut setup = egui_wgpu::WgpuSetupCreateNew::without_display_handle();
    setup.instance_descriptor.backends = match backend {
        Backend::Auto => wgpu::Backends::VULKAN | wgpu::Backends::GL,
        Backend::Vulkan => wgpu::Backends::VULKAN,
        Backend::Gl => wgpu::Backends::GL,
    };
    // The engine opens its own device on this adapter (see `EditorApp::new`); the window asks
    // for the same features and limits.
    setup.device_descriptor = Arc::new(GpuContext::device_descriptor);
    let mut native = eframe::NativeOptions {
        viewport: egui::ViewportBuilder::default().with_title("werkstatt").with_inner_size([1440.0, 900.0]),
        renderer: eframe::Renderer::Wgpu,
        ..Default::default()
    };
    native.wgpu_options.wgpu_setup = egui_wgpu::WgpuSetup::CreateNew(setup);
    eframe::run_native(
        "werkstatt",
        native,
        Box::new(move |cc| Ok(Box::new(EditorApp::new(cc, graph, Options::default())))),
    )
    .map_err(|e| {
        anyhow::anyhow!(
            "cannot open the editor window: {e}\n  help: `werkstatt edit` needs a display (X11 or Wayland; \
             on a machine without one, run it under Xvfb); {}",
            crate::gpu::NO_ADAPTER_HELP
        )
    })
}

//! The inspector: the selected node's parameters, with widgets made from its spec (sliders
//! and drag values within the spec's range, colour pickers, xyz fields, check boxes, combo
//! boxes, text and file fields), each with the parameter's doc as tooltip. Changes go
//! through [`EditorState::set_param`], so they are undoable and a slider drag is one step;
//! the evaluator then re-runs only the nodes that depend on the change.

use std::path::Path;

use egui::{RichText, Ui};

use super::canvas::{ERROR_COLOR, PENDING_COLOR, port_color};
use super::file_picker::{FilePicker, Purpose};
use super::live::{Live, NodeState};
use super::state::EditorState;
use crate::core::param::{ParamKind, ParamSpec, ParamValue};
use crate::core::spec;

pub struct Inspector {
    /// Whether file buttons open a file dialog (off in tests).
    pub file_dialogs: bool,
    /// A file dialog a file button asked for, for the window to show.
    pub picker: Option<FilePicker>,
}

impl Default for Inspector {
    fn default() -> Self {
        Inspector { file_dialogs: true, picker: None }
    }
}

impl Inspector {
    pub fn show(&mut self, ui: &mut Ui, state: &mut EditorState, live: &Live) {
        let selected: Vec<String> = state.selection.iter().cloned().collect();
        let id = match selected.as_slice() {
            [] => {
                ui.weak("Select a node to edit its parameters.");
                return;
            }
            [id] => id.clone(),
            many => {
                ui.label(format!("{} nodes selected", many.len()));
                return;
            }
        };
        let Some(node) = state.graph.nodes.get(&id) else { return };
        let kind = node.kind.clone();
        ui.horizontal(|ui| {
            ui.heading(&id);
            ui.label(RichText::new(&kind).weak());
        });
        let Some(spec) = spec::find(&kind) else {
            ui.colored_label(ERROR_COLOR, format!("unknown node kind \"{kind}\""));
            return;
        };
        ui.add(egui::Label::new(RichText::new(spec.doc).small()).wrap());
        match live.state(&id) {
            NodeState::Failed(m) => {
                ui.colored_label(ERROR_COLOR, format!("error: {m}"));
            }
            NodeState::Pending(m) | NodeState::Blocked(m) => {
                ui.colored_label(PENDING_COLOR, m);
            }
            _ => {}
        }
        // What its parameters will allocate, estimated before it runs (see `cost`).
        if let Some(e) = live.estimates.get(&id) {
            let refused = live.refused.contains_key(&id);
            let text = RichText::new(format!("estimated memory: {}", e.detail)).small();
            ui.add(egui::Label::new(if refused { text.color(ERROR_COLOR) } else { text }).wrap());
        }
        if let Some((t, _)) = live.timing(&id) {
            ui.label(
                RichText::new(format!("last run {:.2} ms, {} runs", t.as_secs_f64() * 1e3, live.runs(&id))).small(),
            );
        }
        ui.separator();
        if spec.params.is_empty() {
            ui.weak("no parameters");
        }
        egui::Grid::new(("params", &id)).num_columns(3).spacing([8.0, 6.0]).striped(true).show(ui, |ui| {
            for ps in spec.params {
                let explicit = state.graph.nodes.get(&id).is_some_and(|n| n.params.contains_key(ps.name));
                let name = if explicit { RichText::new(ps.name).strong() } else { RichText::new(ps.name) };
                ui.label(name).on_hover_text(format!("{}\n{}", ps.doc, describe(&ps.kind)));
                let current = state.graph.param(&id, ps.name).unwrap_or_else(|| ps.kind.default_value());
                ui.horizontal(|ui| {
                    if let Some(v) = self.widget(ui, ps, &current, &id, state) {
                        let _ = state.set_param(&id, ps.name, v);
                    }
                });
                if explicit {
                    if ui.small_button("⟲").on_hover_text("reset to the default").clicked() {
                        state.reset_param(&id, ps.name);
                    }
                } else {
                    ui.label("");
                }
                ui.end_row();
            }
        });
        ui.separator();
        ui.label(RichText::new("Ports").strong());
        for (input, ports) in [(true, spec.inputs), (false, spec.outputs)] {
            for p in ports {
                ui.horizontal(|ui| {
                    ui.colored_label(port_color(p.ty), if input { "▶" } else { "◀" });
                    ui.label(format!("{} ({})", p.name, p.ty)).on_hover_text(p.doc);
                    let port = crate::core::graph::PortRef { node: id.clone(), port: p.name.into() };
                    if let Some(v) = live.summary(&port, input) {
                        ui.label(RichText::new(v).small().weak());
                    }
                });
            }
        }
    }

    /// One parameter's widget; returns a new value when the user changed it.
    fn widget(
        &mut self,
        ui: &mut Ui,
        ps: &ParamSpec,
        current: &ParamValue,
        id: &str,
        state: &EditorState,
    ) -> Option<ParamValue> {
        let tip = ps.doc;
        match ps.kind {
            ParamKind::Float { min, max, .. } => {
                let mut v = current.as_f64().unwrap_or_default();
                let r = if max - min <= 1e4 {
                    ui.add(egui::Slider::new(&mut v, min..=max).clamping(egui::SliderClamping::Always))
                } else {
                    let speed = (v.abs() * 0.01).max(0.01);
                    ui.add(egui::DragValue::new(&mut v).range(min..=max).speed(speed))
                };
                r.on_hover_text(tip).changed().then_some(ParamValue::Float(v))
            }
            ParamKind::Int { min, max, .. } => {
                let mut v = match current {
                    ParamValue::Int(i) => *i,
                    other => other.as_f64().unwrap_or_default() as i64,
                };
                let r = if max - min <= 4096 {
                    ui.add(egui::Slider::new(&mut v, min..=max).clamping(egui::SliderClamping::Always))
                } else {
                    ui.add(egui::DragValue::new(&mut v).range(min..=max))
                };
                r.on_hover_text(tip).changed().then_some(ParamValue::Int(v))
            }
            ParamKind::Bool { .. } => {
                let mut v = matches!(current, ParamValue::Bool(true));
                ui.checkbox(&mut v, "").on_hover_text(tip).changed().then_some(ParamValue::Bool(v))
            }
            ParamKind::Vec3 { .. } | ParamKind::Scale { .. } => {
                let mut v = vec3(current);
                let mut changed = false;
                for (i, axis) in ["x", "y", "z"].iter().enumerate() {
                    let r = ui.add(egui::DragValue::new(&mut v[i]).speed(0.01).prefix(format!("{axis} ")));
                    changed |= r.on_hover_text(tip).changed();
                }
                changed.then(|| ParamValue::Vec(v.to_vec()))
            }
            ParamKind::Color { .. } => {
                let v = vec3(current);
                let mut rgb = [v[0] as f32, v[1] as f32, v[2] as f32];
                let mut changed = egui::color_picker::color_edit_button_rgb(ui, &mut rgb).on_hover_text(tip).changed();
                let mut out = [rgb[0] as f64, rgb[1] as f64, rgb[2] as f64];
                if changed {
                    // The picker works in [0, 1]; keep HDR channels the user did not touch.
                    for c in 0..3 {
                        if (rgb[c] - v[c] as f32).abs() < 1e-6 {
                            out[c] = v[c];
                        }
                    }
                }
                for (i, ch) in ["r", "g", "b"].iter().enumerate() {
                    let r = ui.add(
                        egui::DragValue::new(&mut out[i])
                            .speed(0.005)
                            .range(0.0..=1e4)
                            .prefix(format!("{ch} "))
                            .max_decimals(3),
                    );
                    changed |= r.on_hover_text(tip).changed();
                }
                changed.then(|| ParamValue::Vec(out.to_vec()))
            }
            ParamKind::Text { .. } => {
                let mut s = str_of(current);
                ui.add(egui::TextEdit::singleline(&mut s).desired_width(160.0))
                    .on_hover_text(tip)
                    .changed()
                    .then_some(ParamValue::Str(s))
            }
            ParamKind::Path { extensions, .. } => {
                let mut s = str_of(current);
                let changed =
                    ui.add(egui::TextEdit::singleline(&mut s).desired_width(130.0)).on_hover_text(tip).changed();
                if self.file_dialogs && ui.small_button("…").on_hover_text("choose a file").clicked() {
                    let base = state.path.as_deref().and_then(Path::parent).map(Path::to_path_buf).unwrap_or_default();
                    let near = if s.is_empty() { base.clone() } else { base.join(&s) };
                    let purpose = Purpose::Param { node: id.to_string(), param: ps.name.to_string(), base };
                    let title = format!("{id}.{}", ps.name);
                    self.picker = Some(FilePicker::new(&title, extensions, &near, None, purpose));
                }
                changed.then_some(ParamValue::Str(s))
            }
            ParamKind::Choice { options, .. } => {
                let cur = str_of(current);
                let mut picked = None;
                egui::ComboBox::from_id_salt(("choice", id, ps.name))
                    .selected_text(&cur)
                    .show_ui(ui, |ui| {
                        for o in options {
                            if ui.selectable_label(cur == *o, *o).clicked() && cur != *o {
                                picked = Some(ParamValue::Str(o.to_string()));
                            }
                        }
                    })
                    .response
                    .on_hover_text(tip);
                picked
            }
        }
    }
}

fn vec3(v: &ParamValue) -> [f64; 3] {
    match v {
        ParamValue::Vec(v) if v.len() == 3 => [v[0], v[1], v[2]],
        _ => [0.0; 3],
    }
}

fn str_of(v: &ParamValue) -> String {
    match v {
        ParamValue::Str(s) => s.clone(),
        _ => String::new(),
    }
}

/// `file` relative to `base` when it lies inside it (graphs keep portable relative paths).
pub(super) fn relative_to(file: &Path, base: &Path) -> String {
    let abs_base = std::path::absolute(base).unwrap_or_else(|_| base.to_path_buf());
    match file.strip_prefix(&abs_base) {
        Ok(rel) => rel.to_string_lossy().into_owned(),
        Err(_) => file.to_string_lossy().into_owned(),
    }
}

fn describe(kind: &ParamKind) -> String {
    match kind {
        ParamKind::Float { default, min, max } => format!("float in [{min}, {max}], default {default}"),
        ParamKind::Int { default, min, max } => format!("integer in [{min}, {max}], default {default}"),
        ParamKind::Bool { default } => format!("bool, default {default}"),
        ParamKind::Vec3 { default } => format!("vector, default {default:?}"),
        ParamKind::Scale { default } => format!("scale per axis, no component 0, default {default:?}"),
        ParamKind::Color { default } => format!("linear RGB colour, default {default:?}"),
        ParamKind::Text { default } => format!("text, default \"{default}\""),
        ParamKind::Path { extensions, .. } => format!("file ({}), relative to the graph", extensions.join(", ")),
        ParamKind::Choice { default, options } => format!("one of {}, default {default}", options.join(", ")),
    }
}

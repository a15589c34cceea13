//! The viewport: the viewed texture (the graph's Preview, its first output, or any
//! inspected texture port) shown live. The evaluation worker converts it for display on the
//! engine's GPU (any float format to gamma-encoded Rgba8Unorm, which is what egui samples) and
//! copies that to the CPU; the viewport hands the pixels to egui. The engine has a device of
//! its own: on a software rasterizer a submit holds wgpu's queue for as long as the GPU work
//! runs, and on a shared queue the window could not paint meanwhile. While an evaluation runs,
//! the last finished picture stays, with its progress over it and a button to cancel.

use egui::{Color32, RichText, Sense, Ui, Vec2};

use super::live::{CameraOverride, Live, camera_for, viewed_port};
use super::state::EditorState;
use crate::gpu::GpuImage;

/// Render sizes offered in the viewport's toolbar.
pub const SIZES: &[(u32, u32)] = &[(320, 240), (480, 360), (640, 480), (960, 720), (1280, 960)];

pub struct Viewport {
    /// The picture shown, on the engine's device (for tests that read it back).
    display: Option<GpuImage>,
    texture: Option<egui::TextureHandle>,
    /// The stamp of the picture shown, to hand each new one to egui once.
    last_stamp: Option<u64>,
    pub message: Option<String>,
}

impl Default for Viewport {
    fn default() -> Self {
        Viewport::new()
    }
}

impl Viewport {
    pub fn new() -> Self {
        Viewport { display: None, texture: None, last_stamp: None, message: None }
    }

    /// The picture shown: the viewed port converted for display (None before the first).
    pub fn display(&self) -> Option<&GpuImage> {
        self.display.as_ref()
    }

    /// Hands a newly finished picture to egui (the previous one is let go).
    fn update_texture(&mut self, ctx: &egui::Context, display: &super::live::Display) {
        if self.last_stamp == Some(display.stamp) && self.texture.is_some() {
            return;
        }
        let Some(pixels) = display.pixels.clone() else { return };
        match &mut self.texture {
            Some(t) => t.set(pixels, egui::TextureOptions::LINEAR),
            None => self.texture = Some(ctx.load_texture("viewport", pixels, egui::TextureOptions::LINEAR)),
        }
        self.display = display.image.as_ref().map(GpuImage::share);
        self.last_stamp = Some(display.stamp);
    }

    /// Over the picture: the running evaluation's progress and a cancel button, or that the
    /// user cancelled. Short evaluations (a playing animation's frames) show nothing.
    fn progress(&mut self, ui: &mut Ui, live: &mut Live, rect: egui::Rect) {
        let bar =
            egui::Rect::from_min_size(rect.left_top() + Vec2::new(6.0, 6.0), Vec2::new(rect.width() - 12.0, 24.0));
        if let Some(busy) = live.busy().filter(|b| b.elapsed.as_millis() >= 150 || b.cancelling) {
            let text = match (&busy.node, busy.cancelling) {
                (_, true) => "cancelling…".to_string(),
                (Some(n), false) => format!("rendering… {:.0}% ({n})", busy.fraction * 100.0),
                (None, false) => "rendering…".to_string(),
            };
            ui.scope_builder(egui::UiBuilder::new().max_rect(bar), |ui| {
                egui::Frame::new().fill(Color32::from_black_alpha(170)).inner_margin(3.0).corner_radius(3.0).show(
                    ui,
                    |ui| {
                        ui.horizontal(|ui| {
                            ui.label(RichText::new(text).color(Color32::WHITE));
                            if !busy.cancelling
                                && ui.small_button("cancel").on_hover_text("stop the evaluation (Esc)").clicked()
                            {
                                live.cancel();
                            }
                        });
                    },
                );
            });
        } else if live.cancelled_by_user() {
            ui.scope_builder(egui::UiBuilder::new().max_rect(bar), |ui| {
                egui::Frame::new().fill(Color32::from_black_alpha(170)).inner_margin(3.0).corner_radius(3.0).show(
                    ui,
                    |ui| {
                        ui.horizontal(|ui| {
                            ui.label(RichText::new("cancelled: showing the last finished frame").color(Color32::WHITE));
                            if ui.small_button("render").clicked() {
                                live.resume();
                            }
                        });
                    },
                );
            });
        }
    }

    /// Draws the viewport: toolbar (what is shown, size, frame, play), image, orbit controls.
    pub fn show(&mut self, ui: &mut Ui, state: &mut EditorState, live: &mut Live) {
        let viewed = viewed_port(&state.graph, state.inspected.as_ref());
        ui.horizontal(|ui| {
            match &viewed {
                Some(p) => {
                    ui.label(RichText::new(format!("showing {p}")).strong());
                    if let Some(v) = live.summary(p, false) {
                        ui.label(RichText::new(v).small().weak());
                    }
                }
                None => {
                    ui.label("nothing to show: add a Preview node");
                }
            };
            if state.inspected.is_some() && ui.small_button("back to preview").clicked() {
                state.inspected = None;
            }
        });
        ui.horizontal(|ui| {
            let label = format!("{}x{}", live.settings.width, live.settings.height);
            egui::ComboBox::from_id_salt("render size").selected_text(label).width(90.0).show_ui(ui, |ui| {
                for &(w, h) in SIZES {
                    if ui
                        .selectable_label((w, h) == (live.settings.width, live.settings.height), format!("{w}x{h}"))
                        .clicked()
                    {
                        live.set_size(w, h);
                    }
                }
            });
            let play = if live.playing { "⏸ pause" } else { "▶ play" };
            if ui.button(play).clicked() {
                live.playing = !live.playing;
            }
            let (a, b) = live.frame_range;
            ui.add(egui::Slider::new(&mut live.frame, a..=b).text("frame"));
        });

        let Some(port) = viewed else { return };
        // The last finished picture of this port, while the next one is made.
        let display = live.display().filter(|d| d.port == port);
        let shown = match display.filter(|d| d.pixels.is_some()) {
            Some(d) => {
                self.update_texture(ui.ctx(), d);
                self.texture.as_ref().map(|t| (t.id(), t.size_vec2()))
            }
            None => {
                self.message = Some(match (live.state(&port.node), display.and_then(|d| d.error.clone())) {
                    (_, Some(e)) => e,
                    (super::live::NodeState::Failed(m), _) => format!("{}: {m}", port.node),
                    (super::live::NodeState::Pending(m), _) => format!("{}: {m}", port.node),
                    (super::live::NodeState::Blocked(m), _) => format!("{}: {m}", port.node),
                    _ => match live.summary(&port, false) {
                        Some(v) => format!("{port} = {v}"),
                        None if live.busy().is_some() => "rendering…".into(),
                        None => format!("{port} has no value yet"),
                    },
                });
                None
            }
        };
        let has_value = live.summary(&port, false).is_some();
        let avail = ui.available_size();
        let response = match shown {
            Some((id, size)) => {
                self.message = None;
                let scale = (avail.x / size.x).min(avail.y / size.y).max(0.05);
                let img = egui::Image::from_texture(egui::load::SizedTexture::new(id, size))
                    .fit_to_exact_size(size * scale)
                    .sense(Sense::click_and_drag());
                ui.add(img)
            }
            None => {
                let (rect, response) =
                    ui.allocate_exact_size(avail.max(Vec2::new(50.0, 50.0)), Sense::click_and_drag());
                ui.painter().rect_filled(rect, 4.0, Color32::from_gray(25));
                if let Some(m) = &self.message {
                    // A value (a Watch node's number) is news, anything else a problem.
                    let color = if has_value { ui.visuals().strong_text_color() } else { super::canvas::ERROR_COLOR };
                    ui.painter().text(
                        rect.center(),
                        egui::Align2::CENTER_CENTER,
                        m,
                        egui::FontId::proportional(13.0),
                        color,
                    );
                }
                response
            }
        };
        self.progress(ui, live, response.rect);
        // Orbit controls: drag turns, wheel zooms, double-click resets to the graph's camera.
        let camera = live
            .camera
            .as_ref()
            .map(|c| c.node.clone())
            .filter(|n| state.graph.nodes.contains_key(n))
            .or_else(|| camera_for(&state.graph, Some(&port.node)));
        live.navigating = false;
        let Some(camera) = camera else { return };
        let drag = response.drag_delta();
        let wheel = if response.hovered() { ui.input(|i| i.smooth_scroll_delta.y) } else { 0.0 };
        live.navigating = response.dragged() || wheel != 0.0;
        if drag != Vec2::ZERO || wheel != 0.0 {
            let mut cam = live
                .camera
                .clone()
                .filter(|c| c.node == camera)
                .or_else(|| CameraOverride::from_graph(&state.graph, &camera));
            if let Some(c) = &mut cam {
                c.orbit(drag.x, drag.y);
                c.zoom(wheel / 50.0);
            }
            live.camera = cam;
        }
        if response.double_clicked() {
            live.camera = None;
        }
        if let Some(cam) = live.camera.clone() {
            ui.horizontal(|ui| {
                ui.label(
                    RichText::new(format!(
                        "view of {}: yaw {:.0}, pitch {:.0}, distance {:.2}",
                        cam.node, cam.yaw, cam.pitch, cam.distance
                    ))
                    .small(),
                );
                if ui.small_button("reset").on_hover_text("back to the graph's camera parameters").clicked() {
                    live.camera = None;
                }
                if ui.small_button("apply to graph").on_hover_text("write this view into the camera node").clicked() {
                    let _ = state.edit(&format!("set view of {}", cam.node), None, |g| {
                        use crate::core::param::ParamValue;
                        for (name, v) in [("yaw", cam.yaw), ("pitch", cam.pitch), ("distance", cam.distance)] {
                            super::document::set_param(g, &cam.node, name, ParamValue::Float(v))?;
                        }
                        Ok(())
                    });
                    live.camera = None;
                }
            });
        }
    }
}

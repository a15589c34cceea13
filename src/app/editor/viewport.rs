//! The viewport: the viewed texture (the graph's Preview, its first output, or any
//! inspected texture port) shown live through egui-wgpu. The engine renders on the window's
//! own device, so the texture is only converted for display on the GPU (any float format to
//! gamma-encoded Rgba8Unorm, which is what egui samples) and registered with egui's
//! renderer; nothing is copied to the CPU.

use std::sync::Arc;

use egui::{Color32, RichText, Sense, Ui, Vec2};

use super::live::{CameraOverride, Live, camera_for, viewed_port};
use super::state::EditorState;
use crate::gpu::{FullscreenPass, GpuContext, GpuImage};

const DISPLAY_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba8Unorm;

/// The display conversion: a full-screen pass over shaders/render/display.wgsl.
struct Converter {
    pass: FullscreenPass,
}

impl Converter {
    fn new() -> Converter {
        Converter { pass: FullscreenPass::new("display.wgsl") }
    }

    /// The display mode for a source format, or why it cannot be shown.
    fn mode(image: &GpuImage) -> Result<u32, String> {
        use wgpu::TextureFormat as F;
        if !image.texture.usage().contains(wgpu::TextureUsages::TEXTURE_BINDING) {
            return Err("this texture cannot be sampled, so it cannot be shown".into());
        }
        match image.format {
            F::Rgba8Unorm | F::Bgra8Unorm => Ok(1),
            F::R32Float | F::R16Float => Ok(2),
            f if matches!(f.sample_type(None, None), Some(wgpu::TextureSampleType::Float { .. })) => Ok(0),
            f => Err(format!("textures of format {f:?} cannot be shown")),
        }
    }

    /// Converts and submits, so egui's renderer samples the result.
    fn run(&mut self, gpu: &GpuContext, src: &GpuImage, dst: &GpuImage, mode: u32) -> anyhow::Result<()> {
        gpu.checked("viewport display", || {
            let r = self.pass.run(gpu, bytemuck::cast_slice(&[mode, 0u32, 0, 0]), &[src], dst);
            gpu.flush();
            r
        })?
    }
}

/// Render sizes offered in the viewport's toolbar.
pub const SIZES: &[(u32, u32)] = &[(320, 240), (480, 360), (640, 480), (960, 720), (1280, 960)];

pub struct Viewport {
    converter: Option<Converter>,
    display: Option<GpuImage>,
    texture_id: Option<egui::TextureId>,
    /// The source last converted: its address and the evaluation count, to skip repeats.
    last_source: Option<(usize, u64)>,
    pub message: Option<String>,
}

impl Default for Viewport {
    fn default() -> Self {
        Viewport::new()
    }
}

impl Viewport {
    pub fn new() -> Self {
        Viewport { converter: None, display: None, texture_id: None, last_source: None, message: None }
    }

    /// The texture egui shows: the viewed port converted for display (None before the first).
    pub fn display(&self) -> Option<&GpuImage> {
        self.display.as_ref()
    }

    /// Converts the viewed texture for display (when it changed) and registers it with egui.
    fn update_texture(
        &mut self,
        gpu: &GpuContext,
        render_state: &egui_wgpu::RenderState,
        src: &GpuImage,
        stamp: u64,
    ) -> Result<(), String> {
        let key = (src as *const GpuImage as usize, stamp);
        if self.last_source == Some(key) && self.texture_id.is_some() {
            return Ok(());
        }
        let mode = Converter::mode(src)?;
        let converter = self.converter.get_or_insert_with(Converter::new);
        let resized = self.display.as_ref().is_none_or(|d| (d.width, d.height) != (src.width, src.height));
        if resized {
            let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
            self.display = Some(GpuImage::new(gpu, "viewport", src.width, src.height, DISPLAY_FORMAT, usage));
        }
        let Some(display) = &self.display else { return Ok(()) };
        converter.run(gpu, src, display, mode).map_err(|e| format!("{e:#}"))?;
        let mut renderer = render_state.renderer.write();
        match self.texture_id {
            Some(id) if resized => {
                renderer.update_egui_texture_from_wgpu_texture(&gpu.device, &display.view, wgpu::FilterMode::Linear, id)
            }
            Some(_) => {}
            None => {
                self.texture_id =
                    Some(renderer.register_native_texture(&gpu.device, &display.view, wgpu::FilterMode::Linear));
            }
        }
        self.last_source = Some(key);
        Ok(())
    }

    /// Draws the viewport: toolbar (what is shown, size, frame, play), image, orbit controls.
    pub fn show(
        &mut self,
        ui: &mut Ui,
        state: &mut EditorState,
        live: &mut Live,
        gpu: Option<&Arc<GpuContext>>,
        render_state: Option<&egui_wgpu::RenderState>,
        eval_count: u64,
    ) {
        let viewed = viewed_port(&state.graph, state.inspected.as_ref());
        ui.horizontal(|ui| {
            match &viewed {
                Some(p) => {
                    ui.label(RichText::new(format!("showing {p}")).strong());
                    if let Some(v) = live.output(p) {
                        ui.label(RichText::new(v.summary()).small().weak());
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
        let value = live.output(&port);
        let image = value.and_then(|v| v.as_texture());
        let shown = match (image, gpu, render_state) {
            (Some(img), Some(gpu), Some(rs)) => match self.update_texture(gpu, rs, img, eval_count) {
                Ok(()) => {
                    self.texture_id.zip(self.display.as_ref().map(|d| Vec2::new(d.width as f32, d.height as f32)))
                }
                Err(e) => {
                    self.message = Some(e);
                    None
                }
            },
            (Some(_), _, _) => {
                self.message = Some("no GPU display: the window has no wgpu renderer".into());
                None
            }
            (None, _, _) => {
                self.message = Some(match live.state(&port.node) {
                    super::live::NodeState::Failed(m) => format!("{}: {m}", port.node),
                    super::live::NodeState::Pending(m) => format!("{}: {m}", port.node),
                    super::live::NodeState::Blocked(m) => format!("{}: {m}", port.node),
                    _ => match value {
                        Some(v) => format!("{port} = {} ({})", v.summary(), v.type_name()),
                        None => format!("{port} has no value yet"),
                    },
                });
                None
            }
        };
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
                    let color =
                        if value.is_some() { ui.visuals().strong_text_color() } else { super::canvas::ERROR_COLOR };
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
        // Orbit controls: drag turns, wheel zooms, double-click resets to the graph's camera.
        let camera = live
            .camera
            .as_ref()
            .map(|c| c.node.clone())
            .filter(|n| state.graph.nodes.contains_key(n))
            .or_else(|| camera_for(&state.graph, Some(&port.node)));
        let Some(camera) = camera else { return };
        let drag = response.drag_delta();
        let wheel = if response.hovered() { ui.input(|i| i.smooth_scroll_delta.y) } else { 0.0 };
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

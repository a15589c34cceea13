//! The node editor behind `werkstatt edit [GRAPH]`: an egui window with the graph canvas
//! (egui-snarl), a live viewport, an inspector, files with autosave, and undo.
//!
//! The logic lives in plain Rust types that tests drive without a window:
//! [`document`] (operations on a [`Graph`](crate::core::graph::Graph)), [`history`] (undo),
//! [`state::EditorState`] (document, file, selection, clipboard, messages) and
//! [`live::Live`] (evaluation, on a worker thread) and [`cost`] (estimates before evaluation).
//! [`app::EditorApp`] draws them and turns input into calls.

pub mod app;
pub mod canvas;
pub mod cost;
pub mod document;
pub mod file_picker;
pub mod files;
pub mod history;
pub mod inspector;
pub mod live;
pub mod state;
pub mod viewport;

use std::path::PathBuf;
use std::sync::Arc;

pub use app::{EditorApp, Options};
pub use state::EditorState;

use crate::gpu::{Backend, GpuContext};

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

//! The node editor behind `werkstatt edit [GRAPH]`: an egui window with the graph canvas
//! (egui-snarl), a live viewport, an inspector, files with autosave, and undo.
//!
//! The logic lives in plain Rust types that tests drive without a window:
//! [`document`] (operations on a [`Graph`](crate::core::graph::Graph)), [`history`] (undo),
//! [`state::EditorState`] (document, file, selection, clipboard, messages) and
//! [`live::Live`] (evaluation, on a worker thread) and [`cost`] (estimates before evaluation).
//! [`app::EditorApp`] draws them and turns input into calls.

// The window's modules are drawn by the suite (headless, egui_kittest); the library's unit
// tests cover the plain-Rust ones, so its test build skips the window (a shorter CI build).
#[cfg(not(test))]
pub mod app;
#[cfg(not(test))]
pub mod canvas;
pub mod cost;
pub mod document;
#[cfg(not(test))]
pub mod file_picker;
pub mod files;
pub mod history;
#[cfg(not(test))]
pub mod inspector;
pub mod live;
pub mod state;
#[cfg(not(test))]
pub mod viewport;

#[cfg(not(test))]
pub use app::{EditorApp, Options, run};
pub use state::EditorState;

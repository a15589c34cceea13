//! Rendering: the scene that flows between render nodes and the scene drawer with its item
//! kinds.

pub mod draw;
pub mod scene;

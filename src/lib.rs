//! werkstatt: a real-time garment renderer as a node graph.
//!
//! A graph (`.ron`, see [`graph`]) names nodes from the registry ([`spec`], [`nodes`]);
//! [`eval::Evaluator`] runs the nodes that feed an output, skipping those whose inputs,
//! parameters, resources and time are unchanged. [`render`] is the headless batch runner.

pub mod atomic;
pub mod bench;
pub mod cli;
pub mod color;
pub mod compare;
pub mod cuboid;
pub mod docs;
pub mod draw;
#[cfg(feature = "editor")]
pub mod editor;
pub mod eval;
pub mod geometry_io;
pub mod gpu;
pub mod graph;
pub mod hash;
pub mod ibl;
pub mod image_io;
#[cfg(test)]
mod layering;
pub mod mesh;
pub mod node;
pub mod param;
pub mod port;
pub mod regress;
pub mod render;
pub mod resources;
pub mod rng;
pub mod scene;
pub mod shaders;
pub mod signal;
pub mod spec;
pub mod tessellation;
pub mod warp;

#[path = "../nodes/mod.rs"]
pub mod nodes;

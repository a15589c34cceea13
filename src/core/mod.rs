//! The engine's core: the graph model, node API, ports, parameters, resources and evaluation.

pub mod eval;
pub mod graph;
pub mod hash;
pub mod node;
pub mod parallel;
pub mod param;
pub mod port;
pub mod progress;
pub mod resources;
pub mod rng;
pub mod signal;
pub mod spec;

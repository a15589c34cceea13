//! werkstatt: a real-time garment renderer as a node graph.
//!
//! The crate is layered, and no module imports one that imports it back (`src/layering.rs`
//! checks it):
//!
//! - [`core`]: the graph model ([`core::graph`]), nodes, ports, parameters, resources and the
//!   evaluator ([`core::eval::Evaluator`] runs the nodes that feed an output, skipping those whose
//!   inputs, parameters, resources and time are unchanged);
//! - [`gpu`]: the wgpu toolkit (pooled textures and buffers, passes, the pipeline cache, shaders);
//! - [`mesh`] and [`color`]: the geometry and colour encodings every layer shares;
//! - [`render`]: the scene that flows between render nodes, and the scene drawer with its item
//!   kinds ([`render::draw`]);
//! - one module per technique: [`cloth`] (the cloth simulator), [`garment`] (sewing patterns
//!   from GarmentCode and FreeSewing files, sewn into cloth), [`warp`] (deferred warping),
//!   [`cuboid`] (the cuboid scene graph), [`tessellation`], [`ibl`] (image-based lighting,
//!   shadows), [`occlusion`] (SSAO and its ray-traced reference), [`avatar`] (a skinned, posed,
//!   dressed MakeHuman body);
//! - [`io`]: writing images and geometry;
//! - [`nodes`]: the node library, one folder per family as above (`nodes/render/`,
//!   `nodes/warp/`, ...), and its registry;
//! - [`app`]: the command line, the batch renderer, image regression, the editor, the benches.

pub mod app;
pub mod avatar;
pub mod btf;
pub mod cloth;
pub mod color;
pub mod core;
pub mod cuboid;
pub mod garment;
pub mod gpu;
pub mod ibl;
pub mod io;
#[cfg(test)]
mod layering;
pub mod mesh;
pub mod occlusion;
pub mod render;
pub mod tessellation;
pub mod warp;
pub mod woven;

#[path = "../nodes/mod.rs"]
pub mod nodes;

/// `docs/adding-a-node.md`: its snippets are doctests, so the guide compiles against the code.
#[doc = include_str!("../docs/adding-a-node.md")]
#[cfg(doctest)]
pub struct AddingANodeDoctests;

//! Graph documents: the `.ron` file model, its canonical writer, migrations and validation.
//!
//! A graph file looks like this (the canonical form `werkstatt fmt` writes):
//!
//! ```ron
//! (
//!     version: 1,
//!     nodes: {
//!         "camera": (
//!             kind: "OrbitCamera",
//!             pos: (40.0, 120.0),
//!             params: {
//!                 "distance": 3.0,
//!             },
//!         ),
//!     },
//!     links: [
//!         ("camera.camera", "gbuffer.camera"),
//!     ],
//! )
//! ```
//!
//! One file per responsibility: [`model`] (the document), [`parse`] (text to document, with
//! positions of problems), [`validate`] (against the node registry), [`migrate`] (older format
//! versions), [`write`] (the canonical text, atomic saves), [`set`] (`--set node.param=value`),
//! [`problem`] (problems, diagnostics and the typed errors), [`source`] (where ids, parameters
//! and links are written in the text).

pub mod migrate;
pub mod model;
pub mod parse;
pub mod problem;
pub mod set;
mod source;
pub mod validate;
pub mod write;

pub use migrate::{MIGRATIONS, Migration, migrate};
pub use model::{CURRENT_VERSION, Graph, Link, NodeDoc, PortRef, valid_id};
pub use problem::{Diagnostic, GraphError, LoadError, Place, Problem, ProblemKind, Warning};

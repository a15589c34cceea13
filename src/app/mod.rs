//! The applications on top of the library: the command line, the batch renderer, image
//! regression, the node editor and the benches.

pub mod bench;
pub mod cli;
pub mod compare;
pub mod docs;
#[cfg(feature = "editor")]
pub mod editor;
pub mod regress;
pub mod render;

//! The applications on top of the library: the command line, the batch renderer, image
//! regression, the node editor and the benches (`werkstatt bench`, private to the command line:
//! not part of the library's surface).

mod bench;
mod bench_all;
mod bench_btf;
#[cfg(feature = "editor")]
mod bench_editor;
mod bench_woven;
pub mod cli;
pub mod compare;
pub mod contact_sheet;
pub mod docs;
#[cfg(feature = "editor")]
pub mod editor;
pub mod fidelity;
pub mod regress;
pub mod render;
pub mod sweep;

// The idle-overhead bench's graph, which the tests also use.
pub use bench::chain_graph;

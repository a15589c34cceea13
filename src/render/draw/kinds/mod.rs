//! The kinds of drawable, one file each (see [`super::kind::ItemKind`]). A new kind is a new
//! file here and its `pub mod` line below.

pub mod attached;
pub mod mesh;
pub mod pn_pixels;
pub mod tessellated;
pub mod woven;

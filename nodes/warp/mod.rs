//! Deferred-warping nodes (src/warp/): the matrix texture, placements, curves and attachments.

pub mod attach;
pub mod curves;
pub mod landmarks;
pub mod matrix_texture;
pub mod placements;

//! Comparison nodes: the difference of two images.

pub mod image_difference;

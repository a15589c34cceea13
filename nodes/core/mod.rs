//! Basic nodes: numbers, maths, time, watching values, writing and previewing images.

pub mod basic;
pub mod delay;
pub mod output;

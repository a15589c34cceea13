//! Woven fabric geometry at three scales: IDSS (Zhang, Baciu, Zheng, Liang, Li and Hu,
//! "IDSS: A Novel Representation for Woven Fabrics", TVCG 2012). The CPU evaluation is the reference twin of the compute
//! shader `shaders/tessellation/woven.wgsl`:
//!
//! - [`weave`]: weave patterns η (plain, twill, satin, custom);
//! - [`panel`]: the ternary interpolatory subdivision of Hassan et al. (μ = 4/45) and its
//!   bicubic Bézier woven patches (eqs. 6-10);
//! - [`yarn`]: yarn path, yarn and fibre frames, shells and their composition (eqs. 11-15, 5/19);
//! - [`lod`]: the level from distance (eq. 16) and geomorphing (eqs. 17, 18, 20, corrected);
//! - [`tess`]: tessellation of a grid of patches with crack snapping (eq. 21);
//! - [`gpu`]: the same tessellation in compute shaders, drawn with indirect arguments;
//! - [`resample`]: a Surface resampled per pattern piece into a regular control grid.
//!
//! docs/woven.md lists the equations, the corrections and what is weak.

pub mod gpu;
pub mod lod;
pub mod panel;
pub mod resample;
pub mod tess;
pub mod weave;
pub mod yarn;

#[cfg(test)]
mod tests;

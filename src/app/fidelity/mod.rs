//! The comparison against a path tracer (issue 34, docs/fidelity.md): `werkstatt fidelity
//! export` evaluates a graph and writes its scene (geometry as the G-buffer draws it, camera,
//! light probe, materials), werkstatt's linear HDR image of the view and which item covers each
//! pixel; `tools/fidelity/cycles.py` renders the same scene in Blender Cycles; `werkstatt
//! fidelity compare` measures the two images against each other (relative MAE overall and per
//! item, floor-region ratios, open floor at the screen's edges). The metrics are plain Rust, so
//! a test checks them against a committed Cycles image without Blender.

pub mod capture;
pub mod metrics;
pub mod raster;
pub mod scene;

pub use capture::{Capture, ExportOptions, capture, export};
pub use metrics::{Metrics, compare_dir, measure};
pub use raster::PixelIds;
pub use scene::SceneInfo;

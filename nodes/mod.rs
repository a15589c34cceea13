//! The node library: one file per node family. `ALL` is the registry.

pub mod basic;
pub mod camera;
pub mod direct_light;
pub mod gbuffer;
pub mod geometry;
pub mod live_link;
pub mod mesh_sequence;
pub mod output;
pub mod passes;
pub mod scene;
pub mod tonemap;

use crate::spec::NodeSpec;

/// Every node kind, in the order `werkstatt nodes` and the docs list them.
pub static ALL: &[&NodeSpec] = &[
    &basic::NUMBER,
    &basic::MATH,
    &basic::TIME,
    &geometry::PRIMITIVE,
    &geometry::MESH_FILE,
    &mesh_sequence::MESH_SEQUENCE,
    &live_link::LIVE_LINK,
    &scene::MATERIAL,
    &scene::DRAW,
    &scene::MERGE,
    &camera::ORBIT_CAMERA,
    &gbuffer::GBUFFER_PASS,
    &direct_light::DIRECT_LIGHT,
    &tonemap::TONEMAP,
    &output::IMAGE_WRITE,
    &output::PREVIEW,
    &basic::WATCH,
];

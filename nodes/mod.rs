//! The node library: one file per node family. `ALL` is the registry.

pub mod attach;
pub mod avatar;
pub mod basic;
pub mod camera;
pub mod cloth;
pub mod cuboid;
pub mod cuboid_grid;
pub mod curves;
pub mod direct_light;
pub mod environment_map;
pub mod export;
pub mod gbuffer;
pub mod geometry;
pub mod hybrid_occlusion;
pub mod ibl_shading;
pub mod image_difference;
pub mod live_link;
pub mod matrix_texture;
pub mod median_cut;
pub mod mesh_sequence;
pub mod output;
pub mod pems;
pub mod placements;
pub mod reference_occlusion;
pub mod scene;
pub mod shadow_atlas;
pub mod ssao;
pub mod tessellate;
pub mod tonemap;

use crate::core::node::prelude::*;

/// Every node kind, in the order `werkstatt nodes` and the docs list them.
pub static ALL: &[&NodeSpec] = &[
    &basic::NUMBER,
    &basic::MATH,
    &basic::TIME,
    &geometry::PRIMITIVE,
    &geometry::MESH_FILE,
    &geometry::TRANSFORM_MESH,
    &avatar::AVATAR,
    &tessellate::TESSELLATE,
    &cloth::node::CLOTH_SIM,
    &mesh_sequence::MESH_SEQUENCE,
    &live_link::LIVE_LINK,
    &scene::MATERIAL,
    &scene::DRAW,
    &scene::MERGE,
    &cuboid::CUBOID,
    &cuboid_grid::CUBOID_GRID,
    &cuboid::DEFORM,
    &cuboid::DEFORM_SURFACE,
    &camera::ORBIT_CAMERA,
    &matrix_texture::MATRIX_TEXTURE,
    &placements::SCATTER,
    &placements::GRID_PLACEMENT,
    &placements::CURVE_PLACEMENT,
    &placements::PLACEMENT_FILE,
    &curves::SVG_CURVES,
    &attach::POINT_ATTACHMENT,
    &attach::AREA_ATTACHMENT,
    &attach::CURVE_ATTACHMENT,
    &gbuffer::GBUFFER_PASS,
    &direct_light::DIRECT_LIGHT,
    &environment_map::ENVIRONMENT_MAP,
    &median_cut::MEDIAN_CUT,
    &pems::PEMS,
    &shadow_atlas::SHADOW_ATLAS,
    &ibl_shading::IBL_SHADING,
    &ssao::SSAO,
    &hybrid_occlusion::HYBRID_OCCLUSION,
    &reference_occlusion::REFERENCE_OCCLUSION,
    &tonemap::TONEMAP,
    &image_difference::IMAGE_DIFFERENCE,
    &output::IMAGE_WRITE,
    &output::PREVIEW,
    &export::EXPORT_GEOMETRY,
    &basic::WATCH,
];

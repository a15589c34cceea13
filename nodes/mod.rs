//! The node library, one folder per family, as `src/` is grouped: `core` (numbers, maths, time,
//! watching, writing and previewing images), `mesh` (primitives, mesh files, sequences, the live
//! link), `cloth`, `render` (materials and draws, camera, G-buffer, direct light, tone mapping,
//! export), one folder per technique (`warp`, `cuboid`, `tessellation`, `ibl`, `occlusion`, `woven`, `btf`) and
//! `compare`. The nodes are glue: the algorithms they run live in `src/` (`src/warp/`, ...).
//! `ALL` is the registry.

/// Cloth nodes: the simulator (`src/cloth/`) as a node. (Declared here, not in a
/// `nodes/cloth/mod.rs`: that path was the simulator's before it moved to `src/cloth/`.)
pub mod cloth {
    pub mod garment;
    pub mod node;
    pub mod settle_surface;
}
pub mod btf;
pub mod compare;
pub mod core;
pub mod cuboid;
pub mod ibl;
pub mod mesh;
pub mod occlusion;
pub mod render;
pub mod tessellation;
pub mod warp;
pub mod woven;

use crate::core::node::prelude::*;

/// Every node kind, in the order `werkstatt nodes` and the docs list them.
pub static ALL: &[&NodeSpec] = &[
    &core::basic::NUMBER,
    &core::basic::MATH,
    &core::basic::TIME,
    &mesh::geometry::PRIMITIVE,
    &mesh::geometry::MESH_FILE,
    &mesh::geometry::TRANSFORM_MESH,
    &mesh::avatar::AVATAR,
    &tessellation::tessellate::TESSELLATE,
    &woven::woven_cloth::WOVEN_CLOTH,
    &cloth::node::CLOTH_SIM,
    &cloth::garment::GARMENT,
    &cloth::settle_surface::SETTLE_SURFACE,
    &mesh::mesh_sequence::MESH_SEQUENCE,
    &mesh::live_link::LIVE_LINK,
    &render::scene::MATERIAL,
    &render::scene::DRAW,
    &render::scene::MERGE,
    &cuboid::cuboid::CUBOID,
    &cuboid::cuboid_grid::CUBOID_GRID,
    &cuboid::cuboid::DEFORM,
    &cuboid::cuboid::DEFORM_SURFACE,
    &render::camera::ORBIT_CAMERA,
    &warp::matrix_texture::MATRIX_TEXTURE,
    &warp::placements::SCATTER,
    &warp::placements::GRID_PLACEMENT,
    &warp::placements::CURVE_PLACEMENT,
    &warp::placements::PLACEMENT_FILE,
    &warp::placements::SURFACE_POINTS,
    &warp::landmarks::PATTERN_LANDMARKS,
    &warp::landmarks::POLYLINE,
    &warp::curves::SVG_CURVES,
    &warp::attach::POINT_ATTACHMENT,
    &warp::attach::AREA_ATTACHMENT,
    &warp::attach::CURVE_ATTACHMENT,
    &render::gbuffer::GBUFFER_PASS,
    &render::direct_light::DIRECT_LIGHT,
    &ibl::environment_map::ENVIRONMENT_MAP,
    &ibl::median_cut::MEDIAN_CUT,
    &ibl::sun_light::SUN_LIGHT,
    &ibl::pems::PEMS,
    &ibl::shadow_atlas::SHADOW_ATLAS,
    &ibl::ibl_shading::IBL_SHADING,
    &btf::btf_resource::BTF,
    &btf::btf_shading::BTF_SHADING,
    &btf::btf_slot::BTF_SLOT,
    &occlusion::ssao::SSAO,
    &occlusion::hybrid_occlusion::HYBRID_OCCLUSION,
    &occlusion::bounce::BOUNCE,
    &occlusion::ssr::SCREEN_SPACE_REFLECTIONS,
    &occlusion::reference_occlusion::REFERENCE_OCCLUSION,
    &render::tonemap::TONEMAP,
    &core::delay::DELAY,
    &compare::image_difference::IMAGE_DIFFERENCE,
    &core::output::IMAGE_WRITE,
    &core::output::PREVIEW,
    &render::export::EXPORT_GEOMETRY,
    &core::basic::WATCH,
];

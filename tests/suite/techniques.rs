//! The integration tests of the node families' techniques (cloth and garments, warping,
//! image-based lighting, shadows, occlusion, tessellation, the fabric models), as the second
//! test binary beside tests/suite/main.rs: the two build in parallel. The same rules hold:
//! tests run on parallel threads of one process, must not change process-wide state, and
//! write only into folders named after themselves (see `common::out_dir`).

mod common;

mod avatar;
mod bounce;
mod btf;
mod btf_render;
mod cloth;
mod cloth_collision;
mod cuboid;
mod fidelity;
mod figures;
mod garment;
mod ibl;
mod scene_drawer;
mod shadow;
mod ssao;
mod ssr;
mod tessellation;
mod warping;
mod woven;

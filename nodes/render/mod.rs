//! Render nodes: materials and draws (the scene), the camera, the G-buffer pass, direct light, tone mapping, geometry export.

pub mod camera;
pub mod direct_light;
pub mod export;
pub mod gbuffer;
pub mod scene;
pub mod tonemap;

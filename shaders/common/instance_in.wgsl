// The per-instance vertex layout of attached items (src/warp/mod.rs `InstanceData`), shared by
// every pass that draws attachments.

struct InstanceIn {
    @location(5) m_tex0: vec4<f32>,
    @location(6) m_tex1: vec4<f32>,
    @location(7) m_tan0: vec4<f32>,
    @location(8) m_tan1: vec4<f32>,
    @location(9) m_tan2: vec4<f32>,
    @location(10) m_tan3: vec4<f32>,
    @location(11) curve01: vec4<f32>,
    @location(12) curve23: vec4<f32>,
    @location(13) range: vec4<f32>,
};

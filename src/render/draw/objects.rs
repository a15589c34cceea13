//! Group 1 of every scene pass: the objects (one per item: its material, and for kinds that ask
//! for it the model matrix) in one storage buffer per pass, the base and gloss maps.

use glam::Mat4;

use crate::gpu::pass::{Bindings, dynamic_storage_entry, texture_entry};
use crate::gpu::{Bind, GpuContext, SamplerKind};
use crate::render::scene::{DrawItem, Image8};

use super::compose::ComposedItem;

/// shaders/common/object.wgsl `Object`: one entry of the storage buffer of all objects of a pass.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub struct GpuObject {
    /// For kinds whose fragment stage transforms vertices (per-pixel PN depth); zero otherwise.
    model: [[f32; 4]; 4],
    normal_matrix: [[f32; 4]; 4],
    /// Linear base colour and glossiness.
    base_color: [f32; 4],
    uv_scale: f32,
    /// 1 where a base map is bound.
    has_texture: f32,
    /// 1 for detail geometry (the G-buffer's normal alpha).
    detail: f32,
    /// 1 where a gloss map is bound.
    has_gloss_map: f32,
    /// Glossiness where the gloss map is 0.
    gloss_min: f32,
    /// The material's BtfShading id (the G-buffer's surface target).
    btf_id: f32,
    pad: [f32; 2],
    unused: [[f32; 4]; 5],
}

/// An object's size in the storage buffer of all objects: a multiple of every storage offset
/// alignment an adapter may ask (at most 256), so a draw's range can start at any item.
pub const OBJECT_SIZE: u64 = std::mem::size_of::<GpuObject>() as u64;
const _: () = assert!(OBJECT_SIZE == 256);
const _: () = assert!(std::mem::offset_of!(GpuObject, gloss_min) == 160);
const _: () = assert!(std::mem::offset_of!(GpuObject, btf_id) == 164);

pub const OBJECT_VISIBILITY: wgpu::ShaderStages = wgpu::ShaderStages::VERTEX_FRAGMENT;

impl GpuObject {
    /// `t.model` is the item's own matrix, or the composed one where the linear fast path
    /// folded an affine grid into it.
    pub fn new(item: &DrawItem, t: &ComposedItem) -> GpuObject {
        let (model, m) = (t.model, &item.material);
        let with_model = item.kind.object_model();
        let flag = |b: bool| f32::from(u8::from(b));
        GpuObject {
            model: if with_model { model } else { Mat4::ZERO }.to_cols_array_2d(),
            normal_matrix: if with_model { model.inverse().transpose() } else { Mat4::ZERO }.to_cols_array_2d(),
            base_color: [m.base_color.x, m.base_color.y, m.base_color.z, m.glossiness],
            uv_scale: m.uv_scale,
            has_texture: flag(m.texture.is_some()),
            detail: flag(item.detail),
            has_gloss_map: flag(m.gloss_map.is_some()),
            gloss_min: m.gloss_min,
            btf_id: f32::from(m.btf_id),
            pad: [0.0; 2],
            unused: [[0.0; 4]; 5],
        }
    }
}

/// The layout of group 1 (the objects of a draw, base map, sampler, gloss map) and, for items
/// under a non-linear grid, binding 4: the pass's cell texture. One group per draw on both
/// paths: a third group rebound for every trilinear draw cost lavapipe a few percent.
pub fn object_layout(gpu: &GpuContext, white: &Image8, with_cells: bool) -> wgpu::BindGroupLayout {
    let white = white.gpu(gpu);
    let shape =
        [Bind::Uniform(&[]), Bind::Texture(white), Bind::Sampler(SamplerKind::LinearRepeat), Bind::Texture(white)];
    let mut entries = Bindings::new(OBJECT_VISIBILITY).layout_entries(&shape);
    entries[0] = dynamic_storage_entry(0, OBJECT_VISIBILITY, OBJECT_SIZE);
    if with_cells {
        entries.push(texture_entry(4, wgpu::ShaderStages::VERTEX, false));
    }
    gpu.bind_group_layout(&entries)
}

//! A per-view PCA of a BTF on the GPU, as `BtfShading` reads it (shaders/btf/btf_shading.wgsl;
//! docs/btf.md, "Rendering").
//!
//! - **Images**: one `Rgba16Float` 2D array (rgb used, filterable, repeating), `c + 1` layers per
//!   view slot: the slot's mean image, then its eigentextures B_0..B_{c-1} (zero where a
//!   low-rank slot kept fewer). 81 views x 17 layers = 1377 layers, within lavapipe's 2048.
//! - **Coefficients**: one storage buffer of f32, `c + 1` per (view, light) pair: 1 (the mean's
//!   weight, so eq. 4's k = 0 term is blended like the others), then p_0..p_{c-1}.
//! - **Rings**: the sampling's rings (theta, count, first direction) for the shader's copy of
//!   [`Sampling::weights`](super::directions::Sampling::weights).

use std::sync::Arc;

use anyhow::ensure;

use super::Btf;
use super::directions::Sampling;
use super::pca::{Centring, Compressed};
use crate::gpu::{GpuContext, GpuImage, TextureDesc};

/// The most rings a sampling may have on the GPU (`rings` in shaders/btf/btf_shading.wgsl).
pub const MAX_RINGS: usize = 16;
/// The most components per slot the shader blends (`MAX_LAYERS` - 1 in btf_shading.wgsl).
pub const MAX_COMPONENTS: usize = 32;

/// A compressed BTF uploaded for rendering.
pub struct GpuBtf {
    pub images: GpuImage,
    pub coeffs: wgpu::Buffer,
    pub sampling: Sampling,
    /// c: the eigentextures per slot (layers per slot are c + 1).
    pub components: usize,
    pub width: usize,
    pub height: usize,
    /// GPU memory of the images and coefficients.
    pub bytes: u64,
    /// The coefficients on the CPU, for the per-vertex weight sets of environment light (HEM).
    pub table: super::hem::WeightTable,
    /// The uncompressed BTF it was made from (shared, not copied), for the figures that compare
    /// against it (`BtfSlot`).
    pub source: Arc<Btf>,
}

impl GpuBtf {
    /// Texture layers per view slot.
    pub fn layers_per_slot(&self) -> usize {
        self.components + 1
    }

    /// `rings` of shaders/btf/btf_shading.wgsl: theta (degrees), count, first direction, 0.
    pub fn rings_uniform(&self) -> [[f32; 4]; MAX_RINGS] {
        let mut rings = [[0.0; 4]; MAX_RINGS];
        let mut start = 0;
        for (u, r) in rings.iter_mut().zip(&self.sampling.rings) {
            *u = [r.theta as f32, r.count as f32, start as f32, 0.0];
            start += r.count;
        }
        rings
    }
}

/// Uploads `pca`, the per-view PCA (centred on the mean) of `btf`, with `components`
/// eigentextures per slot. Fails, saying which limit, where the device cannot hold it.
pub fn upload(gpu: &GpuContext, pca: &Compressed, btf: &Arc<Btf>, components: usize) -> anyhow::Result<GpuBtf> {
    let (sampling, width, height) = (&btf.sampling, btf.width, btf.height);
    let n = sampling.len();
    ensure!(pca.centring == Centring::Mean, "the GPU BTF expects a PCA centred on the mean");
    ensure!(pca.slots.len() == n, "{} PCA slots for {n} directions", pca.slots.len());
    ensure!(sampling.rings.len() <= MAX_RINGS, "{} rings (the shader holds {MAX_RINGS})", sampling.rings.len());
    ensure!(components <= MAX_COMPONENTS, "{components} components (the shader blends at most {MAX_COMPONENTS})");
    let per_slot = components + 1;
    let layers = n * per_slot;
    let limits = &gpu.limits;
    ensure!(
        layers <= limits.max_texture_array_layers as usize,
        "{n} views x {per_slot} images (mean + components) = {layers} texture layers; {} allows {} \
         (at most {} components for {n} views)",
        gpu.adapter_name(),
        limits.max_texture_array_layers,
        (limits.max_texture_array_layers as usize / n.max(1)).saturating_sub(1)
    );
    let max_side = limits.max_texture_dimension_2d as usize;
    ensure!(width <= max_side && height <= max_side, "{width}x{height} images exceed the device's {max_side}");
    let texels = width * height;
    // f16 bits (the half crate is built without bytemuck).
    let mut rgba = vec![0u16; layers * texels * 4];
    for (j, slot) in pca.slots.iter().enumerate() {
        ensure!(slot.dim == texels * 3, "slot {j} holds images of {} values, not {}", slot.dim, texels * 3);
        let kept = slot.components().min(components);
        let images = std::iter::once(slot.mean.as_slice()).chain((0..kept).map(|k| slot.eigentexture(k)));
        for (s, image) in images.enumerate() {
            let layer = &mut rgba[(j * per_slot + s) * texels * 4..][..texels * 4];
            for (out, rgb) in layer.chunks_exact_mut(4).zip(image.chunks_exact(3)) {
                for (o, &x) in out.iter_mut().zip(rgb) {
                    *o = half::f16::from_f32(x).to_bits();
                }
            }
        }
    }
    let mut coeffs = vec![0.0f32; n * n * per_slot];
    for (j, slot) in pca.slots.iter().enumerate() {
        let (kept, stored) = (slot.components().min(components), slot.components());
        for i in 0..n {
            let row = &mut coeffs[(j * n + i) * per_slot..][..per_slot];
            row[0] = 1.0;
            row[1..=kept].copy_from_slice(&slot.coeffs[i * stored..][..kept]);
        }
    }
    let coeff_bytes = (coeffs.len() * 4) as u64;
    ensure!(
        coeff_bytes <= limits.max_storage_buffer_binding_size,
        "{coeff_bytes} bytes of coefficients exceed the device's storage binding limit"
    );
    let desc = TextureDesc::array(
        width as u32,
        height as u32,
        layers as u32,
        wgpu::TextureFormat::Rgba16Float,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    );
    let images = GpuImage::create(gpu, "btf images", desc);
    gpu.queue.write_texture(
        wgpu::TexelCopyTextureInfo {
            texture: &images.texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        bytemuck::cast_slice(&rgba),
        wgpu::TexelCopyBufferLayout {
            offset: 0,
            bytes_per_row: Some(8 * width as u32),
            rows_per_image: Some(height as u32),
        },
        desc.extent(),
    );
    let coeffs_buffer =
        gpu.create_buffer_init("btf coefficients", bytemuck::cast_slice(&coeffs), wgpu::BufferUsages::STORAGE);
    Ok(GpuBtf {
        images,
        coeffs: coeffs_buffer,
        sampling: sampling.clone(),
        components,
        width,
        height,
        bytes: (rgba.len() * 2) as u64 + coeff_bytes,
        table: super::hem::WeightTable::new(pca, sampling)?,
        source: btf.clone(),
    })
}

/// The smooth shadow boundary's 1D texture (eq. 6): `size` texels, black below the middle and
/// white above, box-blurred over `blur` texels (soft boundaries), as the value at each texel
/// centre.
pub fn shadow_ramp(size: usize, blur: f32) -> Vec<f32> {
    let half = blur.max(0.0) / 2.0;
    (0..size)
        .map(|k| {
            // Distance of the texel centre from the step, in texels.
            let x = k as f32 + 0.5 - size as f32 / 2.0;
            if half <= 0.0 { if x > 0.0 { 1.0 } else { 0.0 } } else { ((x + half) / (2.0 * half)).clamp(0.0, 1.0) }
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_shadow_ramp_steps_at_the_middle_and_blurs_symmetrically() {
        let hard = shadow_ramp(1024, 0.0);
        assert_eq!((hard[511], hard[512]), (0.0, 1.0));
        let soft = shadow_ramp(1024, 64.0);
        assert_eq!((soft[479], soft[544]), (0.0, 1.0));
        assert!((soft[511] + soft[512] - 1.0).abs() < 1e-6 && soft[500] > 0.0 && soft[500] < 0.5);
    }
}

//! A per-view PCA of a BTF on the GPU, as `BtfShading` reads it (shaders/btf/btf_shading.wgsl;
//! docs/btf.md, "Rendering").
//!
//! - **Images**: one 2D array (rgb used, filterable, repeating), `c + 1` layers per view slot: the
//!   slot's mean image, then its eigentextures B_0..B_{c-1} (zero where a low-rank slot kept
//!   fewer). 81 views x 17 layers = 1377 layers, within lavapipe's 2048. `Rgba16Float`, or
//!   `Rgba8Unorm` ([`Storage::Unorm8`], half the memory) with per layer and channel an offset and
//!   a scale (value = offset + scale x texel; `affine`, identity for f16): filtering commutes
//!   with that map, so trilinear lookups stay exact.
//! - **Coefficients**: one storage buffer of f32, `c + 1` per (view, light) pair: 1 (the mean's
//!   weight, so eq. 4's k = 0 term is blended like the others), then p_0..p_{c-1}.
//! - **Rings**: the sampling's rings (theta, count, first direction) for the shader's copy of
//!   [`Sampling::weights`](super::directions::Sampling::weights).

use std::sync::Arc;

use anyhow::ensure;

use super::Btf;
use super::directions::Sampling;
use super::pca::{Centring, Compressed};
use super::pca_file::{channel_range, to_byte};
use crate::gpu::{GpuContext, GpuImage, TextureDesc};

/// The most rings a sampling may have on the GPU (`rings` in shaders/btf/btf_shading.wgsl).
pub const MAX_RINGS: usize = 16;
/// The most components per slot the shader blends (`MAX_LAYERS` - 1 in btf_shading.wgsl).
pub const MAX_COMPONENTS: usize = 32;

/// How the images are stored on the GPU.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Storage {
    Half,
    /// 8 bits per channel over each layer's own range per channel, as the `.btfc` file stores them.
    Unorm8,
}

/// A compressed BTF uploaded for rendering.
pub struct GpuBtf {
    pub images: GpuImage,
    /// Per layer two vec4s: the offset and the scale (rgb) that map a texel to its value.
    pub affine: wgpu::Buffer,
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
    /// against it (`BtfSlot`); `None` when it was read compressed.
    pub source: Option<Arc<Btf>>,
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

/// Uploads `pca`, the per-view PCA (centred on the mean) of a `width x height` BTF on
/// `sampling` (`source`, where it is in memory), with `components` eigentextures per slot.
/// Fails, saying which limit, where the device cannot hold it.
pub fn upload(
    gpu: &GpuContext,
    pca: &Compressed,
    sampling: &Sampling,
    (width, height): (usize, usize),
    source: Option<Arc<Btf>>,
    components: usize,
    storage: Storage,
) -> anyhow::Result<GpuBtf> {
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
    // Level 0 of every layer, RGBA f32; then the mip chain.
    let mut rgba = vec![0.0f32; layers * texels * 4];
    for (j, slot) in pca.slots.iter().enumerate() {
        ensure!(slot.dim == texels * 3, "slot {j} holds images of {} values, not {}", slot.dim, texels * 3);
        let kept = slot.components().min(components);
        let images = std::iter::once(slot.mean.as_slice()).chain((0..kept).map(|k| slot.eigentexture(k)));
        for (s, image) in images.enumerate() {
            let layer = &mut rgba[(j * per_slot + s) * texels * 4..][..texels * 4];
            for (out, rgb) in layer.chunks_exact_mut(4).zip(image.chunks_exact(3)) {
                out[..3].copy_from_slice(rgb);
            }
        }
    }
    let levels = mip_chain(rgba, width, height, layers);
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
    // Per layer and channel the value range (level 0 holds every level's extremes: mips average).
    let mut affine = vec![[0.0f32, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0]; layers];
    if storage == Storage::Unorm8 {
        let level0 = &levels[0].2;
        for (l, a) in affine.iter_mut().enumerate() {
            for c in 0..3 {
                (a[c], a[4 + c]) = channel_range(&level0[l * texels * 4..][..texels * 4], 4, c);
            }
        }
    }
    let format = match storage {
        Storage::Half => wgpu::TextureFormat::Rgba16Float,
        Storage::Unorm8 => wgpu::TextureFormat::Rgba8Unorm,
    };
    let desc = TextureDesc::array(
        width as u32,
        height as u32,
        layers as u32,
        format,
        wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
    )
    .with_mips(levels.len() as u32);
    let images = GpuImage::create(gpu, "btf images", desc);
    let mut image_bytes = 0;
    for (m, (w, h, level)) in levels.iter().enumerate() {
        let bytes: Vec<u8> = match storage {
            // f16 bits (the half crate is built without bytemuck).
            Storage::Half => level.iter().flat_map(|&x| half::f16::from_f32(x).to_le_bytes()).collect(),
            Storage::Unorm8 => level
                .chunks_exact(w * h * 4)
                .zip(&affine)
                .flat_map(|(layer, a)| {
                    layer.iter().enumerate().map(move |(t, &x)| match t % 4 {
                        3 => 0,
                        c => to_byte(x, (a[c], a[4 + c])),
                    })
                })
                .collect(),
        };
        image_bytes += bytes.len() as u64;
        gpu.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &images.texture,
                mip_level: m as u32,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            &bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some((bytes.len() / (h * layers)) as u32),
                rows_per_image: Some(*h as u32),
            },
            wgpu::Extent3d { width: *w as u32, height: *h as u32, depth_or_array_layers: layers as u32 },
        );
    }
    let affine_buffer =
        gpu.create_buffer_init("btf layer ranges", bytemuck::cast_slice(&affine), wgpu::BufferUsages::STORAGE);
    let coeffs_buffer =
        gpu.create_buffer_init("btf coefficients", bytemuck::cast_slice(&coeffs), wgpu::BufferUsages::STORAGE);
    Ok(GpuBtf {
        images,
        affine: affine_buffer,
        coeffs: coeffs_buffer,
        sampling: sampling.clone(),
        components,
        width,
        height,
        bytes: image_bytes + coeff_bytes + (layers * 32) as u64,
        table: super::hem::WeightTable::new(pca, sampling, components)?,
        source,
    })
}

/// The mip chain of `layers` RGBA f32 images of `width` x `height` (layer-major), down to 1x1
/// by 2x2 box averages while both sides are even: (width, height, texels) per level, level 0
/// first. Each level's average equals level 0's, so a minified weave shows its mean colour
/// instead of aliasing, and since a pixel's image is linear in the mean and eigentextures,
/// filtering them equals filtering the reconstructed images. A side that turns odd ends the chain.
pub fn mip_chain(level0: Vec<f32>, width: usize, height: usize, layers: usize) -> Vec<(usize, usize, Vec<f32>)> {
    let mut levels = vec![(width, height, level0)];
    loop {
        let (w, h, prev) = levels.last().expect("level 0");
        let (w, h) = (*w, *h);
        if w < 2 && h < 2 || w % 2 == 1 && w > 1 || h % 2 == 1 && h > 1 {
            break;
        }
        let (nw, nh) = ((w / 2).max(1), (h / 2).max(1));
        let (sx, sy) = (w / nw, h / nh);
        let mut next = vec![0.0f32; layers * nw * nh * 4];
        for l in 0..layers {
            for y in 0..nh {
                for x in 0..nw {
                    for c in 0..4 {
                        let mut sum = 0.0f32;
                        for dy in 0..sy {
                            for dx in 0..sx {
                                sum += prev[((l * h + y * sy + dy) * w + x * sx + dx) * 4 + c];
                            }
                        }
                        next[((l * nh + y) * nw + x) * 4 + c] = sum / (sx * sy) as f32;
                    }
                }
            }
        }
        levels.push((nw, nh, next));
    }
    levels
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
    fn the_mip_chain_averages_2x2_blocks_down_to_one_texel() {
        // Two layers of 4 x 2 texels: stripes of period 2 along x.
        let level0: Vec<f32> =
            (0..2 * 4 * 2).flat_map(|t| [if t % 2 == 0 { 1.0 } else { 0.0 }, t as f32, 0.5, 1.0]).collect();
        let chain = mip_chain(level0.clone(), 4, 2, 2);
        let sizes: Vec<(usize, usize)> = chain.iter().map(|(w, h, _)| (*w, *h)).collect();
        assert_eq!(sizes, [(4, 2), (2, 1), (1, 1)]);
        // Level 1: the stripes average to 0.5; every level keeps each layer's mean.
        assert!(chain[1].2.chunks_exact(4).all(|p| p[0] == 0.5 && p[2] == 0.5));
        for (w, h, level) in &chain {
            for l in 0..2 {
                let mean = |data: &[f32], n: usize| {
                    data[l * n * 4..][..n * 4].iter().skip(1).step_by(4).sum::<f32>() / n as f32
                };
                assert!((mean(level, w * h) - mean(&level0, 8)).abs() < 1e-5, "level {w}x{h}, layer {l}");
            }
        }
        // An odd side stops the chain.
        assert_eq!(mip_chain(vec![0.0; 3 * 2 * 4], 3, 2, 1).len(), 1);
    }

    #[test]
    fn the_shadow_ramp_steps_at_the_middle_and_blurs_symmetrically() {
        let hard = shadow_ramp(1024, 0.0);
        assert_eq!((hard[511], hard[512]), (0.0, 1.0));
        let soft = shadow_ramp(1024, 64.0);
        assert_eq!((soft[479], soft[544]), (0.0, 1.0));
        assert!((soft[511] + soft[512] - 1.0).abs() < 1e-6 && soft[500] > 0.0 && soft[500] < 0.5);
    }
}

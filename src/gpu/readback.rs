//! Copies from the GPU to the CPU: one buffer read-back, one texture read-back. Both submit
//! the queued work first and reuse their mappable staging buffers.

use anyhow::{Context as _, anyhow, bail};

use super::{GpuContext, GpuImage, lock};

/// A mappable staging buffer of at least `size` bytes, reused across read-backs.
fn staging(gpu: &GpuContext, size: u64) -> wgpu::Buffer {
    let mut pool = lock(&gpu.staging);
    let best = pool.iter().enumerate().filter(|(_, b)| b.size() >= size).min_by_key(|(_, b)| b.size()).map(|(i, _)| i);
    match best {
        Some(i) => pool.swap_remove(i),
        None => {
            // Round up so sizes that grow a little do not make a new buffer each time.
            let size = size.max(256).next_power_of_two();
            gpu.create_buffer("read back", size, wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ)
        }
    }
}

fn give_back(gpu: &GpuContext, buffer: wgpu::Buffer) {
    let mut pool = lock(&gpu.staging);
    pool.push(buffer);
    // A few sizes at most; drop the smallest beyond that.
    if pool.len() > 8 {
        pool.sort_by_key(|b| std::cmp::Reverse(b.size()));
        pool.truncate(8);
    }
}

/// Submits the queued work, maps the first `size` bytes of `buffer` (MAP_READ) and copies them out.
pub(crate) fn map_read(gpu: &GpuContext, buffer: &wgpu::Buffer, size: u64) -> anyhow::Result<Vec<u8>> {
    map_with(gpu, buffer, size, <[u8]>::to_vec)
}

/// The first `size` bytes of `src` (COPY_SRC), after the queued work, handed to `f` while
/// mapped: `f` copies them where they belong, the only copy on the CPU.
pub fn read_buffer_with<R>(
    gpu: &GpuContext,
    src: &wgpu::Buffer,
    size: u64,
    f: impl FnOnce(&[u8]) -> R,
) -> anyhow::Result<R> {
    let buffer = staging(gpu, size);
    gpu.record(|enc| enc.copy_buffer_to_buffer(src, 0, &buffer, 0, size));
    let r = map_with(gpu, &buffer, size, f);
    give_back(gpu, buffer);
    r
}

fn map_with<R>(gpu: &GpuContext, buffer: &wgpu::Buffer, size: u64, f: impl FnOnce(&[u8]) -> R) -> anyhow::Result<R> {
    gpu.flush();
    let slice = buffer.slice(..size);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    let _ = gpu.device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None });
    rx.recv().context("read-back was cancelled")?.context("cannot map the read-back buffer")?;
    let data = f(&slice.get_mapped_range().map_err(|e| anyhow!("cannot read the mapped buffer: {e}"))?);
    buffer.unmap();
    Ok(data)
}

/// Copies `src` (COPY_SRC) to the CPU as plain-old-data values, after the queued work.
pub fn read_buffer<T: bytemuck::Pod>(gpu: &GpuContext, src: &wgpu::Buffer) -> anyhow::Result<Vec<T>> {
    read_buffer_range(gpu, src, src.size())
}

/// The first `size` bytes of `src` as plain-old-data values (`size` a multiple of 4).
pub fn read_buffer_range<T: bytemuck::Pod>(gpu: &GpuContext, src: &wgpu::Buffer, size: u64) -> anyhow::Result<Vec<T>> {
    let buffer = staging(gpu, size);
    gpu.record(|enc| enc.copy_buffer_to_buffer(src, 0, &buffer, 0, size));
    let data = map_read(gpu, &buffer, size);
    give_back(gpu, buffer);
    Ok(bytemuck::pod_collect_to_vec(&data?))
}

/// Pixels read back from the GPU, as f32 RGBA (linear or as stored), row-major, top row first.
pub struct Pixels {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<f32>,
    /// Whether the texture stored sRGB-encoded values (8-bit formats) or linear/HDR ones.
    pub is_ldr: bool,
}

/// Copies mip 0 of layer 0 of a texture to the CPU. Supports the formats the renderer produces.
pub fn read_back(gpu: &GpuContext, image: &GpuImage) -> anyhow::Result<Pixels> {
    read_back_layer(gpu, image, 0, 0)
}

/// Copies one layer at one mip level of a texture to the CPU.
pub fn read_back_layer(gpu: &GpuContext, image: &GpuImage, layer: u32, mip: u32) -> anyhow::Result<Pixels> {
    use wgpu::TextureFormat as F;
    if image.format.is_depth_stencil_format() && image.desc.layers == 1 && mip == 0 && layer == 0 {
        return read_back_depth(gpu, image);
    }
    let (bytes_per_texel, channels) = match image.format {
        F::Rgba8Unorm | F::Rgba8UnormSrgb | F::Bgra8Unorm | F::Bgra8UnormSrgb => (4, 4),
        F::Rgba16Float => (8, 4),
        F::R16Float => (2, 1),
        F::Rg16Float => (4, 2),
        F::Rgba32Float => (16, 4),
        F::R32Float | F::Depth32Float => (4, 1),
        F::Rg32Float => (8, 2),
        // The integers' bits as f32 (`f32::to_bits` gives them back): the G-buffer's surface.
        F::Rgba32Uint => (16, 4),
        other => bail!("cannot read back a texture of format {other:?}"),
    };
    if layer >= image.desc.layers || mip >= image.desc.mips {
        bail!(
            "layer {layer}, mip {mip} is outside the texture ({} layers, {} mips)",
            image.desc.layers,
            image.desc.mips
        );
    }
    let (width, height) = image.mip_size(mip);
    let unpadded = width * bytes_per_texel;
    let padded = unpadded.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let size = (padded * height) as u64;
    let buffer = staging(gpu, size);
    gpu.record(|enc| {
        enc.copy_texture_to_buffer(
            wgpu::TexelCopyTextureInfo {
                texture: &image.texture,
                mip_level: mip,
                origin: wgpu::Origin3d { x: 0, y: 0, z: layer },
                aspect: image.desc.copy_aspect(),
            },
            wgpu::TexelCopyBufferInfo {
                buffer: &buffer,
                layout: wgpu::TexelCopyBufferLayout {
                    offset: 0,
                    bytes_per_row: Some(padded),
                    rows_per_image: Some(height),
                },
            },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        )
    });
    let data = map_read(gpu, &buffer, size);
    give_back(gpu, buffer);
    let data = data?;
    let mut rgba = Vec::with_capacity((width * height * 4) as usize);
    for row in 0..height {
        let line = &data[(row * padded) as usize..(row * padded + unpadded) as usize];
        for texel in line.chunks_exact(bytes_per_texel as usize) {
            let mut px = [0.0f32, 0.0, 0.0, 1.0];
            match image.format {
                F::Rgba8Unorm | F::Rgba8UnormSrgb => {
                    for c in 0..4 {
                        px[c] = texel[c] as f32 / 255.0;
                    }
                }
                F::Bgra8Unorm | F::Bgra8UnormSrgb => {
                    px = [
                        texel[2] as f32 / 255.0,
                        texel[1] as f32 / 255.0,
                        texel[0] as f32 / 255.0,
                        texel[3] as f32 / 255.0,
                    ];
                }
                F::Rgba16Float | F::R16Float | F::Rg16Float => {
                    for c in 0..channels {
                        px[c] = half::f16::from_le_bytes([texel[2 * c], texel[2 * c + 1]]).to_f32();
                    }
                }
                _ => {
                    for c in 0..channels {
                        px[c] = f32::from_le_bytes(texel[4 * c..4 * c + 4].try_into().unwrap_or_default());
                    }
                }
            }
            if channels == 1 {
                px = [px[0], px[0], px[0], 1.0];
            }
            rgba.extend_from_slice(&px);
        }
    }
    let is_ldr = matches!(image.format, F::Rgba8Unorm | F::Rgba8UnormSrgb | F::Bgra8Unorm | F::Bgra8UnormSrgb);
    Ok(Pixels { width, height, rgba, is_ldr })
}

/// A 2D depth texture through a compute copy into a buffer (shaders/common/depth_readback.wgsl):
/// OpenGL ES cannot copy depth to a buffer (wgpu's GL backend then reads zeros), and one path
/// for every backend keeps the values comparable.
fn read_back_depth(gpu: &GpuContext, image: &GpuImage) -> anyhow::Result<Pixels> {
    let (width, height) = (image.width, image.height);
    let out = gpu.create_buffer(
        "depth read-back",
        u64::from(width) * u64::from(height) * 4,
        wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
    );
    let mut pass = super::ComputePass::new("depth_readback.wgsl", "main");
    let float = wgpu::TextureSampleType::Float { filterable: false };
    let binds = [super::Bind::View(&image.view, wgpu::TextureViewDimension::D2, float), super::Bind::StorageRw(&out)];
    pass.dispatch(gpu, &[&binds], [width.div_ceil(8), height.div_ceil(8), 1])?;
    let depth: Vec<f32> = read_buffer(gpu, &out)?;
    let rgba = depth.iter().flat_map(|&d| [d, d, d, 1.0]).collect();
    Ok(Pixels { width, height, rgba, is_ldr: false })
}

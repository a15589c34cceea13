//! Graph-owned transient textures: handed out by description, taken back when the last
//! user drops its handle (the pool then holds the only reference).
//!
//! Reusing a texture that commands not yet submitted still read is safe: commands run in
//! recording order and wgpu orders the accesses. Writing a pooled texture with
//! `queue.write_texture` is not (it runs before the whole next submit), so pooled textures
//! are written by passes only.

use std::sync::{Arc, Mutex};

use super::texture::{GpuImage, Shared, TextureDesc};
use super::{GpuContext, lock};

/// A pooled texture unused for this many submits is released (e.g. after a resize).
const KEEP_UNUSED_EPOCHS: u64 = 256;

struct Entry {
    image: GpuImage,
    last_used: u64,
}

#[derive(Default)]
pub(crate) struct TexturePool {
    entries: Mutex<Vec<Entry>>,
}

impl TexturePool {
    pub(crate) fn acquire(&self, gpu: &GpuContext, label: &str, desc: TextureDesc) -> GpuImage {
        let desc = TextureDesc { usage: desc.usage | wgpu::TextureUsages::COPY_SRC, ..desc };
        let epoch = gpu.epoch();
        let mut entries = lock(&self.entries);
        if let Some(e) = entries.iter_mut().find(|e| e.image.desc == desc && Arc::strong_count(&e.image.shared) == 1) {
            e.last_used = epoch;
            return e.image.share();
        }
        let texture = gpu.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: desc.extent(),
            mip_level_count: desc.mips,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: desc.format,
            usage: desc.usage,
            view_formats: &[],
        });
        let image = GpuImage::from_texture(texture, desc, Arc::new(Shared::default()));
        let handle = image.share();
        entries.push(Entry { image, last_used: epoch });
        handle
    }

    /// Releases textures nobody has used for a while.
    pub(crate) fn trim(&self, epoch: u64) {
        let mut entries = lock(&self.entries);
        for e in entries.iter_mut() {
            if Arc::strong_count(&e.image.shared) > 1 {
                e.last_used = epoch;
            }
        }
        entries.retain(|e| epoch.saturating_sub(e.last_used) < KEEP_UNUSED_EPOCHS);
    }

    /// (textures held by the pool, of which in use).
    pub(crate) fn counts(&self) -> (usize, usize) {
        let entries = lock(&self.entries);
        (entries.len(), entries.iter().filter(|e| Arc::strong_count(&e.image.shared) > 1).count())
    }
}

impl GpuContext {
    /// (textures the pool holds, of which handed out).
    pub fn pool_counts(&self) -> (usize, usize) {
        self.pool.counts()
    }
}

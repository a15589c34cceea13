//! Graph-owned transient textures: handed out by description, taken back when the last
//! user drops its handle (the pool then holds the only reference).
//!
//! Reusing a texture that commands not yet submitted still read is safe: commands run in
//! recording order and wgpu orders the accesses. Writing a pooled texture with
//! `queue.write_texture` is not (it runs before the whole next submit), so pooled textures
//! are written by passes only.

use std::sync::{Arc, Mutex};

use super::texture::{GpuImage, TextureDesc};
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
        let image = GpuImage::create(gpu, label, desc);
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

    /// Releases every texture nobody holds now; returns how many.
    pub(crate) fn release_unused(&self) -> usize {
        let mut entries = lock(&self.entries);
        let before = entries.len();
        entries.retain(|e| Arc::strong_count(&e.image.shared) > 1);
        before - entries.len()
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

/// A buffer from the [`BufferPool`]: derefs to the `wgpu::Buffer`; goes back to the pool when
/// the last clone is dropped.
#[derive(Clone)]
pub struct PooledBuffer {
    buffer: wgpu::Buffer,
    _lease: Arc<()>,
}

impl std::ops::Deref for PooledBuffer {
    type Target = wgpu::Buffer;
    fn deref(&self) -> &wgpu::Buffer {
        &self.buffer
    }
}

struct BufferEntry {
    buffer: wgpu::Buffer,
    lease: Arc<()>,
    /// Nobody held it at the last submit, so no command waiting to be submitted reads it and
    /// `queue.write_buffer` (which lands before the next submit's commands) cannot be seen
    /// by an earlier user.
    free_at_submit: bool,
    last_used: u64,
}

/// Buffers of exact sizes that change contents every frame (a simulated mesh, attachment
/// instances), reused once a submit has passed since their last user let go.
#[derive(Default)]
pub(crate) struct BufferPool {
    entries: Mutex<Vec<BufferEntry>>,
}

impl BufferPool {
    fn acquire(
        &self,
        gpu: &GpuContext,
        label: &str,
        size: u64,
        usage: wgpu::BufferUsages,
        contents: Option<&[u8]>,
    ) -> PooledBuffer {
        let usage = usage | wgpu::BufferUsages::COPY_DST;
        let size = size.max(4).next_multiple_of(wgpu::COPY_BUFFER_ALIGNMENT);
        let epoch = gpu.epoch();
        let mut entries = lock(&self.entries);
        let reusable = entries.iter_mut().find(|e| {
            e.free_at_submit && Arc::strong_count(&e.lease) == 1 && e.buffer.size() == size && e.buffer.usage() == usage
        });
        let (buffer, lease) = match reusable {
            Some(e) => {
                e.free_at_submit = false;
                e.last_used = epoch;
                if let Some(bytes) = contents {
                    write_padded(gpu, &e.buffer, bytes);
                }
                (e.buffer.clone(), e.lease.clone())
            }
            None => {
                let buffer = match contents {
                    Some(bytes) => {
                        let mut padded = bytes.to_vec();
                        padded.resize(size as usize, 0);
                        gpu.create_buffer_init(label, &padded, usage)
                    }
                    None => gpu.create_buffer(label, size, usage),
                };
                let lease = Arc::new(());
                entries.push(BufferEntry {
                    buffer: buffer.clone(),
                    lease: lease.clone(),
                    free_at_submit: false,
                    last_used: epoch,
                });
                (buffer, lease)
            }
        };
        PooledBuffer { buffer, _lease: lease }
    }

    /// Releases every buffer nobody holds now; returns how many.
    fn release_unused(&self) -> usize {
        let mut entries = lock(&self.entries);
        let before = entries.len();
        entries.retain(|e| Arc::strong_count(&e.lease) > 1);
        before - entries.len()
    }

    /// Called after each submit: marks the buffers nobody holds; releases long-unused ones.
    fn after_submit(&self, epoch: u64) {
        let mut entries = lock(&self.entries);
        for e in entries.iter_mut() {
            if Arc::strong_count(&e.lease) == 1 {
                e.free_at_submit = true;
            } else {
                e.free_at_submit = false;
                e.last_used = epoch;
            }
        }
        entries.retain(|e| epoch.saturating_sub(e.last_used) < KEEP_UNUSED_EPOCHS);
    }
}

fn write_padded(gpu: &GpuContext, buffer: &wgpu::Buffer, bytes: &[u8]) {
    let aligned = bytes.len() - bytes.len() % wgpu::COPY_BUFFER_ALIGNMENT as usize;
    if aligned > 0 {
        gpu.queue.write_buffer(buffer, 0, &bytes[..aligned]);
    }
    if aligned < bytes.len() {
        let mut tail = bytes[aligned..].to_vec();
        tail.resize(wgpu::COPY_BUFFER_ALIGNMENT as usize, 0);
        gpu.queue.write_buffer(buffer, aligned as u64, &tail);
    }
}

impl GpuContext {
    /// A pooled buffer holding `contents` (COPY_DST is added to `usage`): a buffer of the same
    /// size and usage that nobody has held since the last submit, rewritten, else a new one.
    /// For data that is re-uploaded every frame with the same size.
    pub fn upload_pooled(&self, label: &str, contents: &[u8], usage: wgpu::BufferUsages) -> PooledBuffer {
        self.buffer_pool.acquire(self, label, contents.len() as u64, usage, Some(contents))
    }

    /// A pooled buffer of `size` bytes for the GPU to fill (contents undefined).
    pub fn scratch_pooled(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> PooledBuffer {
        self.buffer_pool.acquire(self, label, size, usage, None)
    }

    /// Gives back what nothing uses any more: pooled textures and buffers nobody holds (after a
    /// cancelled or failed evaluation, or a parameter that went down, they would otherwise wait
    /// 256 submits, for ever when nothing is evaluated), then lets wgpu destroy them and the C
    /// heap return freed memory to the system. Returns the textures and buffers released.
    pub fn release_unused(&self) -> (usize, usize) {
        let released = (self.pool.release_unused(), self.buffer_pool.release_unused());
        // Destruction waits for the GPU to be done with them.
        let _ = self
            .device
            .poll(wgpu::PollType::Wait { submission_index: None, timeout: Some(std::time::Duration::from_secs(5)) });
        #[cfg(all(target_os = "linux", target_env = "gnu"))]
        // SAFETY: malloc_trim only returns free heap memory to the system; it is thread-safe.
        unsafe {
            libc::malloc_trim(0);
        }
        released
    }

    pub(crate) fn pools_after_submit(&self, epoch: u64) {
        self.pool.trim(epoch);
        self.buffer_pool.after_submit(epoch);
    }
}

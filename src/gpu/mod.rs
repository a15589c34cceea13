//! The GPU toolkit: one wgpu device and queue (headless for batch rendering, or the editor
//! window's), and what every pass shares.
//!
//! - [`texture`]: texture descriptions (layers, mips, cube and array views, depth formats),
//!   [`GpuImage`], cached samplers (filtering, clamp/repeat, comparison).
//! - [`pool`]: graph-owned transient textures, handed out by description and taken back when
//!   the last user drops them.
//! - [`pass`]: bind-group layout helpers, [`FullscreenPass`] and [`ComputePass`] (any texture
//!   kind, samplers, storage buffers; persistent uniform buffers; cached bind groups).
//! - [`pipelines`]: render and compute pipelines cached apart from node state, keyed by shader
//!   and variant; shader reload rebuilds only what used a changed file and keeps the last
//!   good pipeline on error ([`ShaderError`]).
//! - [`readback`]: one buffer read-back and one texture read-back.
//!
//! Work is recorded into one command encoder per node ([`GpuContext::record`]), finished inside
//! that node's validation error scope ([`GpuContext::begin_node`]) and queued; everything queued
//! is submitted once ([`GpuContext::flush`]): at the end of `Evaluator::evaluate`, or before a
//! read-back. Every texture and buffer is created through [`GpuContext::create_texture`] or
//! [`GpuContext::create_buffer`], so [`GpuContext::created`] counts them honestly.

pub mod pass;
pub mod pipelines;
pub mod pool;
pub mod readback;
pub mod shaders;
pub mod texture;

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, MutexGuard, OnceLock};

use anyhow::{Context as _, bail};

pub use pass::{Bind, BufferRing, ComputePass, FullscreenPass};
pub use pipelines::RenderPipelineDesc;
pub use pipelines::ShaderError;
pub use pool::PooledBuffer;
pub use readback::{Pixels, read_back, read_buffer};
pub use texture::{GpuImage, SamplerKind, TextureDesc, TextureKind};

use crate::core::signal::ChangeSignal;

/// Which wgpu backend to use.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum, Default)]
pub enum Backend {
    /// Vulkan if an adapter exists there, else OpenGL (EGL).
    #[default]
    Auto,
    Vulkan,
    Gl,
}

impl Backend {
    /// `WERKSTATT_BACKEND=vulkan|gl|auto` picks the backend when no flag does.
    pub fn from_env() -> Result<Backend, String> {
        match std::env::var("WERKSTATT_BACKEND").ok().as_deref().map(str::to_ascii_lowercase).as_deref() {
            None | Some("") | Some("auto") => Ok(Backend::Auto),
            Some("vulkan") => Ok(Backend::Vulkan),
            Some("gl") => Ok(Backend::Gl),
            Some(other) => Err(format!("WERKSTATT_BACKEND=\"{other}\" is not one of auto, vulkan, gl")),
        }
    }

    fn backends(self) -> wgpu::Backends {
        match self {
            Backend::Auto => wgpu::Backends::VULKAN | wgpu::Backends::GL,
            Backend::Vulkan => wgpu::Backends::VULKAN,
            Backend::Gl => wgpu::Backends::GL,
        }
    }
}

pub const NO_ADAPTER_HELP: &str = "werkstatt renders with wgpu and needs a Vulkan or OpenGL driver; \
without a GPU, install Mesa's software rasterizers: `apt-get install mesa-vulkan-drivers` (Vulkan, lavapipe) \
and/or `apt-get install libegl1 libegl-mesa0 libgles2` (OpenGL ES through EGL, llvmpipe; then --backend gl)";

/// Texture formats chosen at context creation from what this device can render, sample and
/// filter: the nodes ask for a role, not a format, so llvmpipe's GL (no renderable R32Float)
/// and lavapipe's Vulkan run the same graphs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Formats {
    /// The G-buffer's linear view depth: R32Float where renderable, else the first renderable
    /// of Rg32Float, Rgba32Float, R16Float, Rgba16Float. Read channel 0.
    pub linear_depth: wgpu::TextureFormat,
    /// Linear HDR colour (G-buffer colour and normal, lighting): Rgba16Float, else Rgba32Float.
    pub hdr: wgpu::TextureFormat,
    /// Whether Rgba32Float can be a render target. Where not (llvmpipe's GL), full-precision
    /// matrix textures are rendered as bits into Rgba32Uint and copied (see `copy_bits`).
    pub float32_renderable: bool,
    /// Half-precision matrix textures: Rgba16Float.
    pub matrix_f16: wgpu::TextureFormat,
    /// The hardware depth buffer: Depth32Float, else Depth24Plus.
    pub depth: wgpu::TextureFormat,
    /// Two-channel moments (variance shadow maps): Rg16Float, else the first renderable of
    /// Rgba16Float, Rgba32Float (llvmpipe's GL cannot render Rg16Float).
    pub moments: wgpu::TextureFormat,
    /// Display-ready 8-bit colour: Rgba8UnormSrgb.
    pub ldr: wgpu::TextureFormat,
    /// Whether 32-bit float textures can be sampled with a filtering sampler.
    pub float32_filterable: bool,
}

impl Formats {
    /// Picks formats from `features(format)`, which is `None` where the device cannot use it.
    pub fn choose(features: impl Fn(wgpu::TextureFormat) -> Option<wgpu::TextureFormatFeatures>) -> Formats {
        use wgpu::TextureFormat as F;
        let target = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        let renders = |f: F| features(f).is_some_and(|x| x.allowed_usages.contains(target));
        let first = |candidates: &[F]| candidates.iter().copied().find(|&f| renders(f)).unwrap_or(candidates[0]);
        Formats {
            linear_depth: first(&[F::R32Float, F::Rg32Float, F::Rgba32Float, F::R16Float, F::Rgba16Float]),
            hdr: first(&[F::Rgba16Float, F::Rgba32Float]),
            float32_renderable: renders(F::Rgba32Float),
            matrix_f16: first(&[F::Rgba16Float, F::Rgba32Float]),
            depth: first(&[F::Depth32Float, F::Depth24Plus]),
            moments: first(&[F::Rg16Float, F::Rgba16Float, F::Rgba32Float]),
            ldr: F::Rgba8UnormSrgb,
            float32_filterable: features(F::Rgba32Float)
                .is_some_and(|x| x.flags.contains(wgpu::TextureFormatFeatureFlags::FILTERABLE)),
        }
    }

    /// The formats wgpu validates against on `device` opened from `adapter`: the adapter's own
    /// where the device is downlevel or asked for adapter-specific format features, else
    /// WebGPU's guarantees (what wgpu-core's `describe_format_features` does).
    pub fn for_device(adapter: &wgpu::Adapter, device_features: wgpu::Features) -> Formats {
        let adapter_specific = device_features.contains(wgpu::Features::TEXTURE_ADAPTER_SPECIFIC_FORMAT_FEATURES)
            || !adapter
                .get_downlevel_capabilities()
                .flags
                .contains(wgpu::DownlevelFlags::WEBGPU_TEXTURE_FORMAT_SUPPORT);
        Formats::choose(|f| {
            if !device_features.contains(f.required_features()) {
                return None;
            }
            Some(if adapter_specific {
                adapter.get_texture_format_features(f)
            } else {
                f.guaranteed_format_features(device_features)
            })
        })
    }
}

impl Default for Formats {
    /// What a WebGPU-conformant device (lavapipe's Vulkan) offers.
    fn default() -> Self {
        Formats::choose(|f| Some(f.guaranteed_format_features(wgpu::Features::empty())))
    }
}

/// GPU textures and buffers created since the context was opened.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub struct Created {
    pub textures: u64,
    pub buffers: u64,
}

impl Created {
    /// What was created between `earlier` and `self`.
    pub fn since(self, earlier: Created) -> Created {
        Created { textures: self.textures - earlier.textures, buffers: self.buffers - earlier.buffers }
    }
}

/// What a node did on the GPU, collected while it ran (see [`GpuContext::begin_node`]).
#[derive(Default)]
pub struct NodeGpu {
    /// The first validation error its GPU work raised (its commands were not submitted).
    pub error: Option<String>,
    /// Every shader file its pipelines were built from (includes too), with the version seen:
    /// a change to one of them re-runs the node.
    pub shaders: Vec<(ChangeSignal, u64)>,
    /// Shaders that failed to compile; with `error` unset it ran on the last good pipeline.
    pub shader_errors: Vec<ShaderError>,
}

/// The node the context works for, and what it used.
#[derive(Default)]
struct Current {
    node: Option<Arc<str>>,
    shaders: Vec<(ChangeSignal, u64)>,
    shader_errors: Vec<ShaderError>,
}

/// The device and queue. A context serves one evaluator at a time: wgpu error scopes are
/// per thread, command encoding and pass timings per context.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub features: wgpu::Features,
    pub limits: wgpu::Limits,
    formats: Formats,
    errors: Arc<Mutex<Vec<String>>>,
    timer: Option<GpuTimer>,
    textures_created: AtomicU64,
    buffers_created: AtomicU64,
    /// Bumped by every submit: buffers written with `queue.write_buffer` in an earlier epoch
    /// are no longer read by commands waiting to be submitted (see [`BufferRing`]).
    epoch: AtomicU64,
    encoder: Mutex<Option<wgpu::CommandEncoder>>,
    queued: Mutex<Vec<wgpu::CommandBuffer>>,
    current: Mutex<Current>,
    pub(crate) pool: pool::TexturePool,
    pub(crate) buffer_pool: pool::BufferPool,
    pub(crate) pipelines: pipelines::PipelineCache,
    samplers: Mutex<HashMap<SamplerKind, wgpu::Sampler>>,
    /// Mappable buffers for read-backs, reused.
    staging: Mutex<Vec<wgpu::Buffer>>,
}

/// GPU time per node from timestamp queries: passes ask for timestamp writes, which are
/// attributed to the node the evaluator is running.
struct GpuTimer {
    /// Query sets made as a frame needs them (a PEM set of 512 lights records about 40 000
    /// passes; one set holds at most wgpu's 4096 queries), kept for later frames.
    sets: [OnceLock<TimerSet>; MAX_TIMER_SETS],
    period_ns: f32,
    /// (pass number, node id), in allocation order: pass n uses queries 2 (n % PASSES_PER_SET)
    /// and the next of set n / PASSES_PER_SET.
    passes: Mutex<Vec<(u32, Arc<str>)>>,
}

/// One query set and its resolve and read-back buffers.
struct TimerSet {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
}

/// Passes per query set: wgpu allows 4096 queries per set, two per pass.
const PASSES_PER_SET: u32 = 2048;
/// Passes timed per frame at most (later ones run untimed).
const MAX_TIMER_SETS: usize = 64;
const MAX_TIMED_PASSES: u32 = PASSES_PER_SET * MAX_TIMER_SETS as u32;

fn lock<T>(m: &Mutex<T>) -> MutexGuard<'_, T> {
    m.lock().unwrap_or_else(|p| p.into_inner())
}

fn instance(backend: Backend) -> wgpu::Instance {
    let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
    desc.backends = backend.backends();
    wgpu::Instance::new(desc)
}

/// Human-readable lines describing every adapter wgpu finds.
pub fn list_adapters(backend: Backend) -> Vec<String> {
    let inst = instance(backend);
    pollster::block_on(inst.enumerate_adapters(backend.backends()))
        .into_iter()
        .map(|a| {
            let i = a.get_info();
            format!("{} ({:?}, {:?}, driver: {} {})", i.name, i.backend, i.device_type, i.driver, i.driver_info)
        })
        .collect()
}

/// Asks glibc to keep freed memory for reuse instead of returning it to the system at once.
/// Lavapipe allocates and frees per draw and instance; with glibc's defaults the heap's top
/// was trimmed and grown again all the time, and page faults took up to 40% of a frame of
/// many instanced objects (`werkstatt bench cuboids`: 7.4 s of system time in an 18 s run,
/// 0.3 s with these settings; frames up to 1.7x faster). Once per process; a no-op elsewhere.
fn keep_freed_memory() {
    #[cfg(all(target_os = "linux", target_env = "gnu"))]
    {
        static ONCE: std::sync::Once = std::sync::Once::new();
        ONCE.call_once(|| {
            // Freed memory above 256 MiB at the heap's top goes back; blocks under 32 MiB come
            // from the heap, not from fresh mappings. A failed call leaves the defaults.
            // SAFETY: mallopt only sets allocator parameters; it is thread-safe.
            unsafe {
                libc::mallopt(libc::M_TRIM_THRESHOLD, 256 << 20);
                libc::mallopt(libc::M_MMAP_THRESHOLD, 32 << 20);
            }
        });
    }
}

impl GpuContext {
    /// Opens a device without a window. Fails with installation advice where no adapter exists.
    pub fn headless(backend: Backend) -> anyhow::Result<GpuContext> {
        // One device opened at a time per process: drivers crashed when threads created
        // instances, adapters and devices concurrently (wgpu issues #10010 and #10234; the
        // parallel test harness did so, and a CI run died with SIGSEGV).
        static OPENING: Mutex<()> = Mutex::new(());
        let _one_at_a_time = lock(&OPENING);
        // Try Vulkan before GL: probing EGL prints noise and lavapipe is the better rasterizer.
        let order: &[Backend] = match backend {
            Backend::Auto => &[Backend::Vulkan, Backend::Gl],
            one => std::slice::from_ref(match one {
                Backend::Vulkan => &Backend::Vulkan,
                _ => &Backend::Gl,
            }),
        };
        let mut reasons = Vec::new();
        for &b in order {
            let inst = instance(b);
            match pollster::block_on(inst.request_adapter(&wgpu::RequestAdapterOptions {
                power_preference: wgpu::PowerPreference::HighPerformance,
                ..Default::default()
            })) {
                Ok(adapter) => return GpuContext::from_adapter(&adapter),
                Err(e) => reasons.push(format!("{b:?}: {e}")),
            }
        }
        bail!("no GPU adapter found ({})\n  help: {NO_ADAPTER_HELP}", reasons.join("; "))
    }

    /// What werkstatt asks of a device: the adapter's limits and the optional features it
    /// can use (timestamps, filterable 32-bit floats). The editor passes this to eframe so
    /// that the window's device is one the nodes can render with.
    pub fn device_descriptor(adapter: &wgpu::Adapter) -> wgpu::DeviceDescriptor<'static> {
        let wanted = wgpu::Features::TIMESTAMP_QUERY
            | wgpu::Features::TIMESTAMP_QUERY_INSIDE_ENCODERS
            | wgpu::Features::FLOAT32_FILTERABLE;
        wgpu::DeviceDescriptor {
            label: Some("werkstatt"),
            required_features: adapter.features() & wanted,
            required_limits: adapter.limits(),
            ..Default::default()
        }
    }

    pub fn from_adapter(adapter: &wgpu::Adapter) -> anyhow::Result<GpuContext> {
        let info = adapter.get_info();
        let (device, queue) = pollster::block_on(adapter.request_device(&GpuContext::device_descriptor(adapter)))
            .with_context(|| format!("cannot open a device on adapter {}", info.name))?;
        Ok(GpuContext::from_device(device, queue, adapter))
    }

    /// Wraps a device opened elsewhere from `adapter`, e.g. the editor window's (eframe's
    /// render state), so the nodes render into textures the window can show without copies.
    /// Its features and limits are whatever that device was opened with.
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue, adapter: &wgpu::Adapter) -> GpuContext {
        keep_freed_memory();
        let info = adapter.get_info();
        let features = device.features();
        let limits = device.limits();
        let formats = Formats::for_device(adapter, features);
        let errors: Arc<Mutex<Vec<String>>> = Arc::default();
        let sink = errors.clone();
        // The default handler panics; a bad shader or pass must become a node error instead.
        // Errors outside any scope (a node's) land here.
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            lock(&sink).push(e.to_string());
        }));
        let mut gpu = GpuContext {
            device,
            queue,
            info,
            features,
            limits,
            formats,
            errors,
            timer: None,
            textures_created: AtomicU64::new(0),
            buffers_created: AtomicU64::new(0),
            epoch: AtomicU64::new(1),
            encoder: Mutex::default(),
            queued: Mutex::default(),
            current: Mutex::default(),
            pool: pool::TexturePool::default(),
            buffer_pool: pool::BufferPool::default(),
            pipelines: pipelines::PipelineCache::new(crate::gpu::shaders::shader_dir()),
            samplers: Mutex::default(),
            staging: Mutex::default(),
        };
        if features.contains(wgpu::Features::TIMESTAMP_QUERY) {
            gpu.timer = Some(GpuTimer {
                sets: std::array::from_fn(|_| OnceLock::new()),
                period_ns: gpu.queue.get_timestamp_period(),
                passes: Mutex::default(),
            });
        }
        gpu
    }

    pub fn adapter_name(&self) -> String {
        format!("{} ({:?})", self.info.name, self.info.backend)
    }

    /// The formats this device renders each role in.
    pub fn formats(&self) -> &Formats {
        &self.formats
    }

    /// Whether cube maps stored as six-layer arrays (`cube_target`) can be sampled through cube
    /// views with filtering: not on wgpu's GL backend, where such arrays carry a spare layer
    /// (see [`GpuImage::create`]), nor where the HDR format cannot be filtered.
    pub fn cube_sampling(&self) -> bool {
        let hdr_filterable = self.formats.hdr != wgpu::TextureFormat::Rgba32Float || self.formats.float32_filterable;
        self.info.backend != wgpu::Backend::Gl && hdr_filterable
    }

    /// Whether shaders must read texels at a level that differs between neighbouring pixels
    /// through a loop counting up the levels (shaders/ibl/cube.wgsl `cube_trilinear_counted`,
    /// `load_counted`; their `COUNTED_LEVELS` overrides): on wgpu's GL backend, whose bounds
    /// check asks for one level's size per group of pixels on llvmpipe.
    pub fn counted_levels(&self) -> bool {
        self.info.backend == wgpu::Backend::Gl
    }

    // ---- creation (counted) ----

    /// Creates a texture. Every texture is made here, so [`GpuContext::created`] is honest.
    pub fn create_texture(&self, desc: &wgpu::TextureDescriptor<'_>) -> wgpu::Texture {
        self.textures_created.fetch_add(1, Ordering::Relaxed);
        self.device.create_texture(desc)
    }

    /// Creates an uninitialised buffer (counted).
    pub fn create_buffer(&self, label: &str, size: u64, usage: wgpu::BufferUsages) -> wgpu::Buffer {
        self.buffers_created.fetch_add(1, Ordering::Relaxed);
        self.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage,
            mapped_at_creation: false,
        })
    }

    /// Creates a buffer holding `contents` (counted).
    pub fn create_buffer_init(&self, label: &str, contents: &[u8], usage: wgpu::BufferUsages) -> wgpu::Buffer {
        use wgpu::util::DeviceExt;
        self.buffers_created.fetch_add(1, Ordering::Relaxed);
        self.device.create_buffer_init(&wgpu::util::BufferInitDescriptor { label: Some(label), contents, usage })
    }

    /// Textures and buffers created so far.
    pub fn created(&self) -> Created {
        Created {
            textures: self.textures_created.load(Ordering::Relaxed),
            buffers: self.buffers_created.load(Ordering::Relaxed),
        }
    }

    /// A pooled texture of `desc`: one no longer used by anyone, else a new one. It returns to
    /// the pool when its last [`GpuImage`] handle is dropped. Its contents are undefined; write
    /// it with GPU commands (a cleared render pass, a compute pass), not `queue.write_texture`.
    pub fn acquire(&self, label: &str, desc: TextureDesc) -> GpuImage {
        self.pool.acquire(self, label, desc)
    }

    /// A cached sampler.
    pub fn sampler(&self, kind: SamplerKind) -> wgpu::Sampler {
        lock(&self.samplers).entry(kind).or_insert_with(|| kind.create(&self.device)).clone()
    }

    /// A bind group layout with these entries; equal entries give the same layout, so
    /// pipelines and bind groups made by different passes fit each other.
    pub fn bind_group_layout(&self, entries: &[wgpu::BindGroupLayoutEntry]) -> wgpu::BindGroupLayout {
        self.pipelines.layout(&self.device, entries)
    }

    // ---- recording and submission ----

    /// The submission epoch: it changes whenever queued work is submitted.
    pub fn epoch(&self) -> u64 {
        self.epoch.load(Ordering::Acquire)
    }

    /// Records GPU commands into the current node's command encoder (made on first use).
    /// `f` must not call `record` itself.
    pub fn record<R>(&self, f: impl FnOnce(&mut wgpu::CommandEncoder) -> R) -> R {
        let mut enc = lock(&self.encoder);
        let enc = enc.get_or_insert_with(|| {
            self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("werkstatt") })
        });
        f(enc)
    }

    /// Finishes the open encoder and queues its commands; `false` if there was none.
    fn finish_encoder(&self) -> Option<wgpu::CommandBuffer> {
        lock(&self.encoder).take().map(|e| e.finish())
    }

    /// Submits everything recorded and queued so far, in one `queue.submit`. The evaluator
    /// calls it once per frame; read-backs call it before copying.
    pub fn flush(&self) {
        let mut buffers = std::mem::take(&mut *lock(&self.queued));
        buffers.extend(self.finish_encoder());
        // Submitting nothing still flushes `queue.write_buffer`/`write_texture` calls.
        self.queue.submit(buffers);
        let epoch = self.epoch.fetch_add(1, Ordering::AcqRel) + 1;
        self.pools_after_submit(epoch);
    }

    /// wgpu validation errors raised outside any node's scope since the last call.
    pub fn take_errors(&self) -> Vec<String> {
        std::mem::take(&mut *lock(&self.errors))
    }

    /// Submits the queued work; fails with the validation errors raised outside node scopes
    /// (for callers outside the evaluator: benchmarks, tests).
    pub fn submit_checked(&self) -> anyhow::Result<()> {
        self.flush();
        let errors = self.take_errors();
        if !errors.is_empty() {
            bail!("GPU error: {}", errors.join("; "));
        }
        Ok(())
    }

    /// Runs `f` and turns any wgpu validation error it raises into an `Err`.
    pub fn checked<T>(&self, what: &str, f: impl FnOnce() -> T) -> anyhow::Result<T> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let value = f();
        if let Some(e) = pollster::block_on(scope.pop()) {
            bail!("{what}: {e}");
        }
        Ok(value)
    }

    /// Starts a node's GPU work: a validation error scope (this thread's) and a record of the
    /// shaders it uses. [`NodeScope::end`] finishes its commands inside the scope and queues
    /// them, or drops them if anything the node did on the GPU was invalid.
    pub fn begin_node(&self, node: &str) -> NodeScope<'_> {
        // Work recorded outside any node goes ahead of this node's, outside its scope.
        if let Some(cb) = self.finish_encoder() {
            lock(&self.queued).push(cb);
        }
        *lock(&self.current) = Current { node: Some(Arc::from(node)), ..Default::default() };
        let timed_before = self.timer.as_ref().map_or(0, |t| lock(&t.passes).len());
        NodeScope { gpu: self, scope: Some(self.device.push_error_scope(wgpu::ErrorFilter::Validation)), timed_before }
    }

    /// Records that the running node used these shader files (for re-running it on reload).
    pub(crate) fn note_shaders(&self, files: &[(ChangeSignal, u64)], error: Option<&ShaderError>) {
        let mut cur = lock(&self.current);
        if cur.node.is_none() {
            return;
        }
        cur.shaders.extend(files.iter().cloned());
        if let Some(e) = error
            && !cur.shader_errors.contains(e)
        {
            cur.shader_errors.push(e.clone());
        }
    }

    // ---- shaders ----

    /// Where shader sources are read from: `WERKSTATT_SHADER_DIR` when the context was made,
    /// else the copies embedded in the binary; tests point contexts at their own folders.
    pub fn set_shader_dir(&self, dir: Option<PathBuf>) {
        self.pipelines.set_dir(dir);
    }

    /// Re-reads the shader files used so far and returns those whose text changed. The
    /// pipelines built from them are rebuilt when next asked for, and the nodes that used
    /// them re-run on the next evaluation (their fingerprint holds the files' versions); the
    /// other nodes, and their state (a cloth simulation), are untouched.
    pub fn reload_shaders(&self) -> Vec<String> {
        self.pipelines.reload()
    }

    /// Forgets every cached shader and pipeline, so all are rebuilt from source.
    pub fn clear_shader_cache(&self) {
        self.pipelines.clear();
    }

    /// A render pipeline from the cache (see [`pipelines`]).
    pub fn render_pipeline(&self, desc: &RenderPipelineDesc<'_>) -> Result<wgpu::RenderPipeline, ShaderError> {
        pipelines::render_pipeline(self, desc)
    }

    /// A compute pipeline from the cache: `shader`'s `entry`, with these bind groups.
    pub fn compute_pipeline(
        &self,
        shader: &str,
        entry: &str,
        groups: &[Option<&wgpu::BindGroupLayout>],
        constants: &[(&str, u32)],
    ) -> Result<wgpu::ComputePipeline, ShaderError> {
        pipelines::compute_pipeline(self, shader, entry, groups, constants)
    }

    // ---- timing ----

    /// Whether passes are timed on the GPU (the adapter has timestamp queries).
    pub fn has_gpu_timing(&self) -> bool {
        self.timer.is_some()
    }

    /// A query pair for the running node's next pass, or `None` where timing is unsupported,
    /// no node runs, or the query budget is spent.
    fn next_timed_pass(&self) -> Option<(&wgpu::QuerySet, u32)> {
        let t = self.timer.as_ref()?;
        let node = lock(&self.current).node.clone()?;
        let mut passes = lock(&t.passes);
        let pass = passes.len() as u32;
        if pass >= MAX_TIMED_PASSES {
            return None;
        }
        passes.push((pass, node));
        let set = t.sets[(pass / PASSES_PER_SET) as usize].get_or_init(|| self.timer_set());
        Some((&set.queries, 2 * (pass % PASSES_PER_SET)))
    }

    fn timer_set(&self) -> TimerSet {
        let size = 2 * PASSES_PER_SET as u64 * 8;
        TimerSet {
            queries: self.device.create_query_set(&wgpu::QuerySetDescriptor {
                label: Some("node timings"),
                ty: wgpu::QueryType::Timestamp,
                count: 2 * PASSES_PER_SET,
            }),
            resolve: self.create_buffer(
                "timestamp resolve",
                size,
                wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            ),
            read: self.create_buffer(
                "timestamp read",
                size,
                wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
            ),
        }
    }

    /// Timestamp writes for a render pass (see `next_timed_pass`).
    pub fn pass_timestamps(&self) -> Option<wgpu::RenderPassTimestampWrites<'_>> {
        let (query_set, index) = self.next_timed_pass()?;
        Some(wgpu::RenderPassTimestampWrites {
            query_set,
            beginning_of_pass_write_index: Some(index),
            end_of_pass_write_index: Some(index + 1),
        })
    }

    /// Timestamp writes for a compute pass (see `next_timed_pass`).
    pub fn compute_timestamps(&self) -> Option<wgpu::ComputePassTimestampWrites<'_>> {
        let (query_set, index) = self.next_timed_pass()?;
        Some(wgpu::ComputePassTimestampWrites {
            query_set,
            beginning_of_pass_write_index: Some(index),
            end_of_pass_write_index: Some(index + 1),
        })
    }

    /// GPU milliseconds per node for the passes timed since the last call.
    pub fn collect_timings(&self) -> HashMap<Arc<str>, f64> {
        let mut out = HashMap::new();
        let Some(t) = &self.timer else { return out };
        let passes = std::mem::take(&mut *lock(&t.passes));
        if passes.is_empty() {
            return out;
        }
        // Passes are 0..n: a node whose commands were dropped gave its queries back.
        let mut stamps: Vec<u64> = Vec::with_capacity(2 * passes.len());
        for (k, first) in (0..passes.len() as u32).step_by(PASSES_PER_SET as usize).enumerate() {
            let Some(set) = t.sets[k].get() else { return out };
            let count = 2 * (passes.len() as u32 - first).min(PASSES_PER_SET);
            self.record(|enc| {
                enc.resolve_query_set(&set.queries, 0..count, &set.resolve, 0);
                enc.copy_buffer_to_buffer(&set.resolve, 0, &set.read, 0, count as u64 * 8);
            });
            let Ok(data) = readback::map_read(self, &set.read, count as u64 * 8) else { return out };
            stamps.extend_from_slice(bytemuck::cast_slice(&data));
        }
        for (pass, node) in &passes {
            let (a, b) = (stamps[2 * *pass as usize], stamps[2 * *pass as usize + 1]);
            let ms = b.saturating_sub(a) as f64 * t.period_ns as f64 * 1e-6;
            *out.entry(node.clone()).or_insert(0.0) += ms;
        }
        out
    }

    /// Submits queued work and waits until the GPU has finished it.
    pub fn wait_idle(&self) {
        self.flush();
        let _ = self.device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None });
    }
}

/// A node's GPU work in progress: see [`GpuContext::begin_node`].
pub struct NodeScope<'a> {
    gpu: &'a GpuContext,
    scope: Option<wgpu::ErrorScopeGuard>,
    timed_before: usize,
}

impl NodeScope<'_> {
    /// Finishes the node's commands inside its error scope; queues them if it raised no
    /// validation error, else drops them. Returns what the node did.
    pub fn end(self) -> NodeGpu {
        self.finish(true)
    }

    /// Ends the scope of a node that was cancelled: its commands are dropped unsubmitted, so
    /// what it recorded (and the textures only those commands held) is let go.
    pub fn discard(self) -> NodeGpu {
        self.finish(false)
    }

    fn finish(mut self, keep: bool) -> NodeGpu {
        let gpu = self.gpu;
        let commands = gpu.finish_encoder();
        let error = self.scope.take().and_then(|s| pollster::block_on(s.pop())).map(|e| e.to_string());
        match (&error, commands) {
            (None, Some(cb)) if keep => lock(&gpu.queued).push(cb),
            (Some(_), _) | (None, Some(_)) => {
                // Its timed passes never run: forget their queries.
                if let Some(t) = &gpu.timer {
                    lock(&t.passes).truncate(self.timed_before);
                }
            }
            (None, None) => {}
        }
        let cur = std::mem::take(&mut *lock(&gpu.current));
        NodeGpu { error, shaders: cur.shaders, shader_errors: cur.shader_errors }
    }
}

impl Drop for NodeScope<'_> {
    fn drop(&mut self) {
        if self.scope.is_some() {
            *lock(&self.gpu.current) = Current::default();
        }
    }
}

//! The GPU context: one wgpu device and queue, headless (batch) or shared with the editor,
//! plus textures, shader loading and read-back.

use std::collections::HashMap;
use std::path::PathBuf;
use std::sync::{Arc, Mutex};

use anyhow::{Context as _, anyhow, bail};

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
without a GPU, install Mesa's software rasterizer: `apt-get install mesa-vulkan-drivers` (Vulkan, lavapipe) \
or `libegl-mesa0` (OpenGL through EGL, then --backend gl)";

/// The device and queue. A context serves one evaluator at a time: wgpu validation errors
/// and pass timings are collected per device, not per caller.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub info: wgpu::AdapterInfo,
    pub features: wgpu::Features,
    pub limits: wgpu::Limits,
    shaders: Mutex<HashMap<&'static str, Arc<wgpu::ShaderModule>>>,
    errors: Arc<Mutex<Vec<String>>>,
    timer: Option<GpuTimer>,
}

/// GPU time per node from timestamp queries: passes ask for timestamp writes, which are
/// attributed to the node the evaluator is running.
struct GpuTimer {
    queries: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    read: wgpu::Buffer,
    period_ns: f32,
    /// (first query index of a pass, node id), in allocation order.
    passes: Mutex<Vec<(u32, Arc<str>)>>,
    current_node: Mutex<Option<Arc<str>>>,
}

const MAX_TIMED_PASSES: u32 = 512;

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

impl GpuContext {
    /// Opens a device without a window. Fails with installation advice where no adapter exists.
    pub fn headless(backend: Backend) -> anyhow::Result<GpuContext> {
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
        Ok(GpuContext::from_device(device, queue, info))
    }

    /// Wraps a device opened elsewhere, e.g. the editor window's (eframe's render state), so
    /// the nodes render into textures the window can show without copies. Its features and
    /// limits are whatever that device was opened with.
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue, info: wgpu::AdapterInfo) -> GpuContext {
        let features = device.features();
        let limits = device.limits();
        let errors: Arc<Mutex<Vec<String>>> = Arc::default();
        let sink = errors.clone();
        // The default handler panics; a bad shader or pass must become a node error instead.
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| {
            sink.lock().unwrap_or_else(|p| p.into_inner()).push(e.to_string());
        }));
        let timer = features.contains(wgpu::Features::TIMESTAMP_QUERY).then(|| {
            let size = 2 * MAX_TIMED_PASSES as u64 * 8;
            GpuTimer {
                queries: device.create_query_set(&wgpu::QuerySetDescriptor {
                    label: Some("node timings"),
                    ty: wgpu::QueryType::Timestamp,
                    count: 2 * MAX_TIMED_PASSES,
                }),
                resolve: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timestamp resolve"),
                    size,
                    usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
                    mapped_at_creation: false,
                }),
                read: device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("timestamp read"),
                    size,
                    usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
                    mapped_at_creation: false,
                }),
                period_ns: queue.get_timestamp_period(),
                passes: Mutex::default(),
                current_node: Mutex::default(),
            }
        });
        GpuContext { device, queue, info, features, limits, shaders: Mutex::default(), errors, timer }
    }

    pub fn adapter_name(&self) -> String {
        format!("{} ({:?})", self.info.name, self.info.backend)
    }

    /// wgpu validation errors raised since the last call.
    pub fn take_errors(&self) -> Vec<String> {
        std::mem::take(&mut *self.errors.lock().unwrap_or_else(|p| p.into_inner()))
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

    /// A shader module from `shaders/NAME`. Sources are embedded in the binary; with
    /// `WERKSTATT_SHADER_DIR` set they are read from that folder instead (live editing).
    /// A shader that fails to compile is an error naming the file.
    pub fn shader(&self, name: &'static str) -> anyhow::Result<Arc<wgpu::ShaderModule>> {
        if let Some(m) = self.shaders.lock().unwrap_or_else(|p| p.into_inner()).get(name) {
            return Ok(m.clone());
        }
        let source = crate::shaders::source(name)?;
        let module = self.checked(&format!("shaders/{name}"), || {
            self.device.create_shader_module(wgpu::ShaderModuleDescriptor {
                label: Some(name),
                source: wgpu::ShaderSource::Wgsl(source.into()),
            })
        })?;
        let module = Arc::new(module);
        self.shaders.lock().unwrap_or_else(|p| p.into_inner()).insert(name, module.clone());
        Ok(module)
    }

    /// Forgets cached shader modules so the next use re-reads them (shader hot reload).
    pub fn clear_shader_cache(&self) {
        self.shaders.lock().unwrap_or_else(|p| p.into_inner()).clear();
    }

    /// Whether passes are timed on the GPU (the adapter has timestamp queries).
    pub fn has_gpu_timing(&self) -> bool {
        self.timer.is_some()
    }

    /// Set by the evaluator around each node's run, so pass timings are attributed to it.
    pub fn set_current_node(&self, node: Option<&str>) {
        if let Some(t) = &self.timer {
            *t.current_node.lock().unwrap_or_else(|p| p.into_inner()) = node.map(Arc::from);
        }
    }

    /// Timestamp writes for a render pass, or `None` where timing is unsupported or the
    /// frame's query budget is spent.
    pub fn pass_timestamps(&self) -> Option<wgpu::RenderPassTimestampWrites<'_>> {
        let t = self.timer.as_ref()?;
        let node = t.current_node.lock().unwrap_or_else(|p| p.into_inner()).clone()?;
        let mut passes = t.passes.lock().unwrap_or_else(|p| p.into_inner());
        let index = 2 * passes.len() as u32;
        if index >= 2 * MAX_TIMED_PASSES {
            return None;
        }
        passes.push((index, node));
        Some(wgpu::RenderPassTimestampWrites {
            query_set: &t.queries,
            beginning_of_pass_write_index: Some(index),
            end_of_pass_write_index: Some(index + 1),
        })
    }

    /// GPU milliseconds per node for the passes timed since the last call.
    pub fn collect_timings(&self) -> HashMap<Arc<str>, f64> {
        let mut out = HashMap::new();
        let Some(t) = &self.timer else { return out };
        let passes = std::mem::take(&mut *t.passes.lock().unwrap_or_else(|p| p.into_inner()));
        if passes.is_empty() {
            return out;
        }
        let count = 2 * passes.len() as u32;
        let mut enc = self.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("timings") });
        enc.resolve_query_set(&t.queries, 0..count, &t.resolve, 0);
        enc.copy_buffer_to_buffer(&t.resolve, 0, &t.read, 0, count as u64 * 8);
        self.queue.submit([enc.finish()]);
        let slice = t.read.slice(..count as u64 * 8);
        let (tx, rx) = std::sync::mpsc::channel();
        slice.map_async(wgpu::MapMode::Read, move |r| {
            let _ = tx.send(r);
        });
        self.wait_idle();
        if !matches!(rx.recv(), Ok(Ok(()))) {
            return out;
        }
        if let Ok(data) = slice.get_mapped_range() {
            let stamps: &[u64] = bytemuck::cast_slice(&data);
            for (index, node) in &passes {
                let (a, b) = (stamps[*index as usize], stamps[*index as usize + 1]);
                let ms = b.saturating_sub(a) as f64 * t.period_ns as f64 * 1e-6;
                *out.entry(node.clone()).or_insert(0.0) += ms;
            }
        }
        t.read.unmap();
        out
    }

    pub fn wait_idle(&self) {
        let _ = self.device.poll(wgpu::PollType::Wait { submission_index: None, timeout: None });
    }
}

/// A 2D texture with its default view.
pub struct GpuImage {
    pub texture: wgpu::Texture,
    pub view: wgpu::TextureView,
    pub format: wgpu::TextureFormat,
    pub width: u32,
    pub height: u32,
}

impl GpuImage {
    pub fn new(
        gpu: &GpuContext,
        label: &str,
        width: u32,
        height: u32,
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> GpuImage {
        let texture = gpu.device.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format,
            usage: usage | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let view = texture.create_view(&wgpu::TextureViewDescriptor::default());
        GpuImage { texture, view, format, width, height }
    }

    /// Another handle to the same texture (wgpu textures are reference counted).
    pub fn share(&self) -> GpuImage {
        GpuImage {
            texture: self.texture.clone(),
            view: self.view.clone(),
            format: self.format,
            width: self.width,
            height: self.height,
        }
    }

    /// A sampled texture filled with `bytes` (tightly packed rows of `bytes_per_texel`).
    pub fn upload(
        gpu: &GpuContext,
        label: &str,
        width: u32,
        height: u32,
        format: wgpu::TextureFormat,
        bytes_per_texel: u32,
        bytes: &[u8],
    ) -> GpuImage {
        let img = GpuImage::new(
            gpu,
            label,
            width,
            height,
            format,
            wgpu::TextureUsages::TEXTURE_BINDING | wgpu::TextureUsages::COPY_DST,
        );
        gpu.queue.write_texture(
            wgpu::TexelCopyTextureInfo {
                texture: &img.texture,
                mip_level: 0,
                origin: wgpu::Origin3d::ZERO,
                aspect: wgpu::TextureAspect::All,
            },
            bytes,
            wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(bytes_per_texel * width),
                rows_per_image: Some(height),
            },
            wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
        );
        img
    }

    /// A colour attachment that clears to transparent black and stores.
    pub fn clear_attachment(&self) -> Option<wgpu::RenderPassColorAttachment<'_>> {
        Some(wgpu::RenderPassColorAttachment {
            view: &self.view,
            depth_slice: None,
            resolve_target: None,
            ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT), store: wgpu::StoreOp::Store },
        })
    }

    /// A render target that can also be sampled and read back.
    pub fn target(gpu: &GpuContext, label: &str, width: u32, height: u32, format: wgpu::TextureFormat) -> GpuImage {
        GpuImage::new(
            gpu,
            label,
            width,
            height,
            format,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        )
    }
}

/// Pixels read back from the GPU, as f32 RGBA (linear or as stored), row-major, top row first.
pub struct Pixels {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<f32>,
    /// Whether the texture stored sRGB-encoded values (8-bit formats) or linear/HDR ones.
    pub is_ldr: bool,
}

/// Copies a texture to the CPU. Supports the formats the renderer produces.
pub fn read_back(gpu: &GpuContext, image: &GpuImage) -> anyhow::Result<Pixels> {
    use wgpu::TextureFormat as F;
    let (bytes_per_texel, channels) = match image.format {
        F::Rgba8Unorm | F::Rgba8UnormSrgb | F::Bgra8Unorm | F::Bgra8UnormSrgb => (4, 4),
        F::Rgba16Float => (8, 4),
        F::Rgba32Float => (16, 4),
        F::R32Float | F::Depth32Float => (4, 1),
        F::Rg32Float => (8, 2),
        other => bail!("cannot read back a texture of format {other:?}"),
    };
    let unpadded = image.width * bytes_per_texel;
    let padded = unpadded.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let buffer = gpu.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size: (padded * image.height) as u64,
        usage: wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::MAP_READ,
        mapped_at_creation: false,
    });
    let mut enc = gpu.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("readback") });
    enc.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo {
            texture: &image.texture,
            mip_level: 0,
            origin: wgpu::Origin3d::ZERO,
            aspect: wgpu::TextureAspect::All,
        },
        wgpu::TexelCopyBufferInfo {
            buffer: &buffer,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded),
                rows_per_image: Some(image.height),
            },
        },
        wgpu::Extent3d { width: image.width, height: image.height, depth_or_array_layers: 1 },
    );
    gpu.queue.submit([enc.finish()]);
    let slice = buffer.slice(..);
    let (tx, rx) = std::sync::mpsc::channel();
    slice.map_async(wgpu::MapMode::Read, move |r| {
        let _ = tx.send(r);
    });
    gpu.wait_idle();
    rx.recv().context("read-back was cancelled")?.context("cannot map the read-back buffer")?;
    let data = slice.get_mapped_range().map_err(|e| anyhow!("cannot read the mapped buffer: {e}"))?;
    let mut rgba = Vec::with_capacity((image.width * image.height * 4) as usize);
    for row in 0..image.height {
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
                F::Rgba16Float => {
                    for c in 0..4 {
                        px[c] = half::f16::from_le_bytes([texel[2 * c], texel[2 * c + 1]]).to_f32();
                    }
                }
                _ => {
                    for c in 0..channels {
                        px[c] = f32::from_le_bytes(texel[4 * c..4 * c + 4].try_into().unwrap_or_default());
                    }
                    if channels == 1 {
                        px = [px[0], px[0], px[0], 1.0];
                    }
                }
            }
            rgba.extend_from_slice(&px);
        }
    }
    drop(data);
    buffer.unmap();
    let is_ldr = matches!(image.format, F::Rgba8Unorm | F::Rgba8UnormSrgb | F::Bgra8Unorm | F::Bgra8UnormSrgb);
    Ok(Pixels { width: image.width, height: image.height, rgba, is_ldr })
}

/// Where shader sources are read from disk when live editing, if anywhere.
pub fn shader_dir() -> Option<PathBuf> {
    std::env::var_os("WERKSTATT_SHADER_DIR").map(PathBuf::from)
}

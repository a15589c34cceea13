//! The pipeline cache, apart from node state: render and compute pipelines keyed by shader
//! file and variant (entry points, bind group layouts, target formats, ...), shared by every
//! node that asks for the same one.
//!
//! Each shader file has a version ([`ChangeSignal`]). A pipeline remembers the files it was
//! built from (its WGSL includes too) and their versions; [`GpuContext::reload_shaders`]
//! bumps the versions of files whose text changed, so only pipelines that used one are
//! rebuilt, when next asked for. A rebuild that fails keeps the last good pipeline and hands
//! the running node a [`ShaderError`]. The running node is told which files it used (see
//! [`GpuContext::begin_node`]), so the evaluator re-runs exactly the nodes that used a
//! changed file.

use std::collections::HashMap;
use std::hash::{Hash, Hasher};
use std::path::PathBuf;
use std::sync::Mutex;

use super::{GpuContext, lock};
use crate::core::signal::ChangeSignal;

/// A shader file that does not compile, or a pipeline that cannot be built from it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ShaderError {
    /// The shader file the pipeline was built from, e.g. `tonemap.wgsl`.
    pub file: String,
    pub message: String,
}

impl std::fmt::Display for ShaderError {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "shaders/{}: {}", crate::gpu::shaders::path(&self.file), self.message)
    }
}

impl std::error::Error for ShaderError {}

/// A render pipeline as the cache builds it. Everything but `shader` is the variant.
#[derive(Clone, Debug, Hash)]
pub struct RenderPipelineDesc<'a> {
    pub shader: &'a str,
    pub vertex_entry: &'a str,
    /// `None`: no fragment stage (depth only, which a software rasterizer tests before any
    /// shading).
    pub fragment_entry: Option<&'a str>,
    /// Bind group layouts by group index (`None`: the group is unused).
    pub groups: &'a [Option<&'a wgpu::BindGroupLayout>],
    pub vertex_buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
    /// Colour targets, written without blending.
    pub targets: &'a [wgpu::TextureFormat],
    /// A depth buffer: its format and test; depth is written.
    pub depth: Option<(wgpu::TextureFormat, wgpu::CompareFunction)>,
    pub cull: Option<wgpu::Face>,
    /// Values of the shader's pipeline-overridable constants (`override`; a bool as 0 or 1):
    /// a variant with a feature compiled out where a branch would cost (lavapipe runs a
    /// branch's body masked rather than jumping over it).
    pub constants: &'a [(&'a str, u32)],
}

impl<'a> RenderPipelineDesc<'a> {
    /// `vs_main` and `fs_main` of `shader` over these vertex buffers, into `targets`.
    pub fn new(
        shader: &'a str,
        groups: &'a [Option<&'a wgpu::BindGroupLayout>],
        vertex_buffers: &'a [Option<wgpu::VertexBufferLayout<'a>>],
        targets: &'a [wgpu::TextureFormat],
    ) -> Self {
        RenderPipelineDesc {
            shader,
            vertex_entry: "vs_main",
            fragment_entry: Some("fs_main"),
            groups,
            vertex_buffers,
            targets,
            depth: None,
            cull: None,
            constants: &[],
        }
    }

    /// A full-screen triangle (`vs_fullscreen` of shaders/common/fullscreen.wgsl) and `fs_main`.
    pub fn fullscreen(
        shader: &'a str,
        groups: &'a [Option<&'a wgpu::BindGroupLayout>],
        targets: &'a [wgpu::TextureFormat],
    ) -> Self {
        RenderPipelineDesc { vertex_entry: "vs_fullscreen", ..RenderPipelineDesc::new(shader, groups, &[], targets) }
    }

    fn variant(&self) -> u64 {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        self.hash(&mut h);
        h.finish()
    }
}

/// File, version: what a module or pipeline was built from.
type Deps = Vec<(String, u64)>;

struct File {
    /// The text, or why it could not be read.
    text: Result<String, String>,
    version: ChangeSignal,
}

struct Entry<P> {
    /// The last pipeline that built, and what from.
    good: Option<(P, Deps)>,
    /// The last failed build, and what from.
    failed: Option<(Deps, ShaderError)>,
}

impl<P> Default for Entry<P> {
    fn default() -> Self {
        Entry { good: None, failed: None }
    }
}

pub(crate) struct PipelineCache {
    dir: Mutex<Option<PathBuf>>,
    files: Mutex<HashMap<String, File>>,
    modules: Mutex<HashMap<String, (wgpu::ShaderModule, Deps)>>,
    render: Mutex<HashMap<(String, u64), Entry<wgpu::RenderPipeline>>>,
    compute: Mutex<HashMap<(String, u64), Entry<wgpu::ComputePipeline>>>,
    layouts: Mutex<HashMap<Vec<wgpu::BindGroupLayoutEntry>, wgpu::BindGroupLayout>>,
}

impl PipelineCache {
    pub(crate) fn new(dir: Option<PathBuf>) -> Self {
        PipelineCache {
            dir: Mutex::new(dir),
            files: Mutex::default(),
            modules: Mutex::default(),
            render: Mutex::default(),
            compute: Mutex::default(),
            layouts: Mutex::default(),
        }
    }

    pub(crate) fn set_dir(&self, dir: Option<PathBuf>) {
        *lock(&self.dir) = dir;
        self.clear();
    }

    /// Forgets all shaders and pipelines; file versions are bumped, so nodes re-run.
    pub(crate) fn clear(&self) {
        for f in lock(&self.files).values() {
            f.version.bump();
        }
        lock(&self.files).clear();
        lock(&self.modules).clear();
        lock(&self.render).clear();
        lock(&self.compute).clear();
    }

    pub(crate) fn layout(
        &self,
        device: &wgpu::Device,
        entries: &[wgpu::BindGroupLayoutEntry],
    ) -> wgpu::BindGroupLayout {
        lock(&self.layouts)
            .entry(entries.to_vec())
            .or_insert_with(|| {
                device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: None, entries })
            })
            .clone()
    }

    fn read(&self, name: &str) -> Result<String, String> {
        let dir = lock(&self.dir).clone();
        crate::gpu::shaders::read(dir.as_deref(), name).map_err(|e| format!("{e:#}"))
    }

    /// The text and version of a file, read on first use.
    fn text(&self, name: &str) -> (Result<String, String>, u64) {
        if let Some(f) = lock(&self.files).get(name) {
            return (f.text.clone(), f.version.version());
        }
        let text = self.read(name);
        let mut files = lock(&self.files);
        let f = files.entry(name.to_string()).or_insert(File { text, version: ChangeSignal::new() });
        (f.text.clone(), f.version.version())
    }

    /// Re-reads every file read so far; bumps and returns those whose text changed.
    pub(crate) fn reload(&self) -> Vec<String> {
        let names: Vec<String> = lock(&self.files).keys().cloned().collect();
        let mut changed = Vec::new();
        for name in names {
            let text = self.read(&name);
            let mut files = lock(&self.files);
            if let Some(f) = files.get_mut(&name)
                && f.text != text
            {
                f.text = text;
                f.version.bump();
                changed.push(name);
            }
        }
        changed.sort();
        changed
    }

    fn fresh(&self, deps: &Deps) -> bool {
        let files = lock(&self.files);
        deps.iter().all(|(name, v)| files.get(name).is_some_and(|f| f.version.version() == *v))
    }

    fn signals(&self, deps: &Deps) -> Vec<(ChangeSignal, u64)> {
        let files = lock(&self.files);
        deps.iter().filter_map(|(name, v)| Some((files.get(name)?.version.clone(), *v))).collect()
    }

    /// The module of `shader` with its includes, compiled once per version of its files.
    fn module(&self, gpu: &GpuContext, shader: &str) -> (Deps, Result<wgpu::ShaderModule, ShaderError>) {
        if let Some((m, deps)) = lock(&self.modules).get(shader)
            && self.fresh(deps)
        {
            return (deps.clone(), Ok(m.clone()));
        }
        let mut deps = Deps::new();
        let expanded = crate::gpu::shaders::expand(shader, &mut |name| {
            let (text, version) = self.text(name);
            deps.push((name.to_string(), version));
            text.map_err(anyhow::Error::msg)
        });
        let error = |message: String| ShaderError { file: shader.to_string(), message };
        let source = match expanded {
            Ok((source, _)) => source,
            Err(e) => return (deps, Err(error(format!("{e:#}")))),
        };
        let scope = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let module = gpu.device.create_shader_module(wgpu::ShaderModuleDescriptor {
            label: Some(shader),
            source: wgpu::ShaderSource::Wgsl(source.into()),
        });
        if let Some(e) = pollster::block_on(scope.pop()) {
            return (deps, Err(error(e.to_string())));
        }
        lock(&self.modules).insert(shader.to_string(), (module.clone(), deps.clone()));
        (deps, Ok(module))
    }
}

/// The cache lookup shared by render and compute pipelines.
fn cached<P: Clone>(
    gpu: &GpuContext,
    map: &Mutex<HashMap<(String, u64), Entry<P>>>,
    shader: &str,
    variant: u64,
    build: impl FnOnce(&wgpu::ShaderModule) -> P,
) -> Result<P, ShaderError> {
    let cache = &gpu.pipelines;
    let key = (shader.to_string(), variant);
    {
        let map = lock(map);
        if let Some(e) = map.get(&key) {
            if let Some((p, deps)) = &e.good
                && cache.fresh(deps)
            {
                gpu.note_shaders(&cache.signals(deps), None);
                return Ok(p.clone());
            }
            if let Some((deps, err)) = &e.failed
                && cache.fresh(deps)
            {
                gpu.note_shaders(&cache.signals(deps), Some(err));
                return e.good.as_ref().map(|(p, _)| p.clone()).ok_or_else(|| err.clone());
            }
        }
    }
    let (deps, module) = cache.module(gpu, shader);
    let built = module.and_then(|module| {
        // Internal errors too: a backend that cannot translate the shader (naga's GLSL for GL)
        // reports an internal error, not a validation one.
        let internal = gpu.device.push_error_scope(wgpu::ErrorFilter::Internal);
        let validation = gpu.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let p = build(&module);
        let validation = pollster::block_on(validation.pop());
        match validation.or(pollster::block_on(internal.pop())) {
            Some(e) => Err(ShaderError { file: shader.to_string(), message: format!("{e:#}") }),
            None => Ok(p),
        }
    });
    let signals = cache.signals(&deps);
    let mut map = lock(map);
    let entry = map.entry(key).or_default();
    match built {
        Ok(p) => {
            gpu.note_shaders(&signals, None);
            *entry = Entry { good: Some((p.clone(), deps)), failed: None };
            Ok(p)
        }
        Err(err) => {
            gpu.note_shaders(&signals, Some(&err));
            entry.failed = Some((deps, err.clone()));
            entry.good.as_ref().map(|(p, _)| p.clone()).ok_or(err)
        }
    }
}

pub(crate) fn render_pipeline(
    gpu: &GpuContext,
    desc: &RenderPipelineDesc<'_>,
) -> Result<wgpu::RenderPipeline, ShaderError> {
    cached(gpu, &gpu.pipelines.render, desc.shader, desc.variant(), |module| {
        let layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(desc.shader),
            bind_group_layouts: desc.groups,
            immediate_size: 0,
        });
        let constants: Vec<(&str, f64)> = desc.constants.iter().map(|&(name, v)| (name, f64::from(v))).collect();
        let options = wgpu::PipelineCompilationOptions { constants: &constants, ..Default::default() };
        let targets: Vec<Option<wgpu::ColorTargetState>> = desc
            .targets
            .iter()
            .map(|&format| Some(wgpu::ColorTargetState { format, blend: None, write_mask: wgpu::ColorWrites::ALL }))
            .collect();
        gpu.device.create_render_pipeline(&wgpu::RenderPipelineDescriptor {
            label: Some(desc.shader),
            layout: Some(&layout),
            vertex: wgpu::VertexState {
                module,
                entry_point: Some(desc.vertex_entry),
                buffers: desc.vertex_buffers,
                compilation_options: options.clone(),
            },
            fragment: desc.fragment_entry.map(|entry| wgpu::FragmentState {
                module,
                entry_point: Some(entry),
                targets: &targets,
                compilation_options: options,
            }),
            primitive: wgpu::PrimitiveState { cull_mode: desc.cull, ..Default::default() },
            depth_stencil: desc.depth.map(|(format, compare)| wgpu::DepthStencilState {
                format,
                depth_write_enabled: Some(true),
                depth_compare: Some(compare),
                stencil: Default::default(),
                bias: Default::default(),
            }),
            multisample: Default::default(),
            multiview_mask: None,
            cache: None,
        })
    })
}

pub(crate) fn compute_pipeline(
    gpu: &GpuContext,
    shader: &str,
    entry: &str,
    groups: &[Option<&wgpu::BindGroupLayout>],
    constants: &[(&str, u32)],
) -> Result<wgpu::ComputePipeline, ShaderError> {
    let variant = {
        let mut h = std::collections::hash_map::DefaultHasher::new();
        (entry, groups, constants).hash(&mut h);
        h.finish()
    };
    cached(gpu, &gpu.pipelines.compute, shader, variant, |module| {
        let overrides: Vec<(&str, f64)> = constants.iter().map(|&(name, v)| (name, f64::from(v))).collect();
        let layout = gpu.device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
            label: Some(shader),
            bind_group_layouts: groups,
            immediate_size: 0,
        });
        gpu.device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
            label: Some(shader),
            layout: Some(&layout),
            module,
            entry_point: Some(entry),
            compilation_options: wgpu::PipelineCompilationOptions { constants: &overrides, ..Default::default() },
            cache: None,
        })
    })
}

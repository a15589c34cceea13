//! Passes: bind-group layout helpers, [`Bindings`] (persistent uniform buffers written with
//! `queue.write_buffer`, bind groups cached while their inputs are unchanged), and the two
//! pass shapes most nodes need: [`FullscreenPass`] and [`ComputePass`].

use std::collections::HashMap;

use super::texture::{SamplerKind, clear_attachment};
use super::{GpuContext, GpuImage, RenderPipelineDesc};

pub fn uniform_entry(binding: u32, visibility: wgpu::ShaderStages) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Uniform,
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// A read-only storage range of `size` bytes at a dynamic offset (`set_bind_group`'s offsets).
pub fn dynamic_storage_entry(binding: u32, visibility: wgpu::ShaderStages, size: u64) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: true,
            min_binding_size: wgpu::BufferSize::new(size),
        },
        count: None,
    }
}

/// A 2D float texture (`texture_2d<f32>`).
pub fn texture_entry(binding: u32, visibility: wgpu::ShaderStages, filterable: bool) -> wgpu::BindGroupLayoutEntry {
    texture_kind_entry(
        binding,
        visibility,
        wgpu::TextureSampleType::Float { filterable },
        wgpu::TextureViewDimension::D2,
    )
}

/// A texture of any sample type and view dimension (arrays, cubes, depth).
pub fn texture_kind_entry(
    binding: u32,
    visibility: wgpu::ShaderStages,
    sample_type: wgpu::TextureSampleType,
    view_dimension: wgpu::TextureViewDimension,
) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Texture { sample_type, view_dimension, multisampled: false },
        count: None,
    }
}

pub fn sampler_entry(binding: u32, visibility: wgpu::ShaderStages, kind: SamplerKind) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry { binding, visibility, ty: wgpu::BindingType::Sampler(kind.binding_type()), count: None }
}

pub fn storage_entry(binding: u32, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    storage_entry_for(binding, wgpu::ShaderStages::COMPUTE, read_only)
}

pub fn storage_entry_for(binding: u32, visibility: wgpu::ShaderStages, read_only: bool) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry {
        binding,
        visibility,
        ty: wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        },
        count: None,
    }
}

/// Resources written with `queue.write_buffer` or `queue.write_texture`, kept across frames.
/// Such a write lands before every command of the next submit, so a resource written twice
/// before one submit would show both readers the second value: each write in one submit
/// epoch takes its own slot, and the slots are reused once the epoch changes. A pass that
/// runs once per frame keeps one slot.
pub struct WriteSlots<T> {
    slots: Vec<T>,
    epoch: u64,
    used: usize,
}

impl<T> Default for WriteSlots<T> {
    fn default() -> Self {
        WriteSlots { slots: Vec::new(), epoch: 0, used: 0 }
    }
}

impl<T> WriteSlots<T> {
    /// This write's slot: the next one of this epoch, made by `make` where there is none yet
    /// or where `fits` refuses the one there (`make` sees the one it replaces).
    pub fn next(&mut self, gpu: &GpuContext, fits: impl Fn(&T) -> bool, make: impl FnOnce(Option<&T>) -> T) -> &T {
        let epoch = gpu.epoch();
        if epoch != self.epoch {
            // The last epoch that wrote used `used` slots: far fewer than are kept means a
            // workload that went down (600 PEMs, then 16), so the rest goes.
            if self.used < self.slots.len() / 2 {
                self.slots.truncate(self.used.max(1));
            }
            self.epoch = epoch;
            self.used = 0;
        }
        let slot = self.used;
        self.used += 1;
        if slot == self.slots.len() {
            let made = make(None);
            self.slots.push(made);
        } else if !fits(&self.slots[slot]) {
            let made = make(Some(&self.slots[slot]));
            self.slots[slot] = made;
        }
        &self.slots[slot]
    }
}

/// Buffers written with `queue.write_buffer`, kept across frames ([`WriteSlots`]).
pub struct BufferRing {
    label: &'static str,
    usage: wgpu::BufferUsages,
    slots: WriteSlots<wgpu::Buffer>,
}

impl BufferRing {
    pub fn new(label: &'static str, usage: wgpu::BufferUsages) -> Self {
        BufferRing { label, usage: usage | wgpu::BufferUsages::COPY_DST, slots: WriteSlots::default() }
    }

    pub fn uniform(label: &'static str) -> Self {
        BufferRing::new(label, wgpu::BufferUsages::UNIFORM)
    }

    /// A buffer holding `bytes` for commands recorded until the next submit.
    pub fn write(&mut self, gpu: &GpuContext, bytes: &[u8]) -> &wgpu::Buffer {
        // Uniform sizes must be multiples of 16; storage arrays of their element size (4 here).
        let size = (bytes.len() as u64).max(16).next_multiple_of(16);
        let (label, usage) = (self.label, self.usage);
        let buffer = self.slots.next(
            gpu,
            |b| b.size() >= size,
            |old| gpu.create_buffer(label, size.max(old.map_or(0, |b| b.size() * 2)), usage),
        );
        if !bytes.is_empty() {
            gpu.queue.write_buffer(buffer, 0, bytes);
        }
        buffer
    }
}

/// One resource of a bind group, bound at the binding number of its position.
#[derive(Clone, Copy)]
pub enum Bind<'a> {
    /// A uniform block, copied into a buffer the pass keeps (see [`BufferRing`]).
    Uniform(&'a [u8]),
    /// A texture's default view: 2D, 2D array or cube, as its description says.
    Texture(&'a GpuImage),
    /// Another view of a texture (one mip, one layer, ...) with its dimension.
    View(&'a wgpu::TextureView, wgpu::TextureViewDimension, wgpu::TextureSampleType),
    Sampler(SamplerKind),
    /// A read-only storage buffer.
    Storage(&'a wgpu::Buffer),
    /// A read-write storage buffer.
    StorageRw(&'a wgpu::Buffer),
    /// A uniform buffer owned elsewhere.
    UniformBuffer(&'a wgpu::Buffer),
    /// A read-only storage range of this many bytes, placed per draw by a dynamic offset (a
    /// draw binds only its own part of a large buffer: lavapipe copies a bound storage range
    /// for every draw).
    DynamicStorage(&'a wgpu::Buffer, u64),
    /// A write-only storage texture view (compute passes): its format and dimension.
    StorageTexture(&'a wgpu::TextureView, wgpu::TextureFormat, wgpu::TextureViewDimension),
}

/// What identifies a bound resource, for the bind group cache.
#[derive(Clone, PartialEq, Eq, Hash)]
enum Key {
    Buffer(wgpu::Buffer),
    Range(wgpu::Buffer, u64),
    View(wgpu::TextureView),
    Sampler(SamplerKind),
}

/// The bind group cache holds at most this many groups (their resources stay alive meanwhile).
const MAX_CACHED_GROUPS: usize = 16;

/// The bindings of one bind group of a pass: the layout entries its resources need, a ring
/// per uniform block, and bind groups cached by the resources bound.
pub struct Bindings {
    visibility: wgpu::ShaderStages,
    rings: Vec<BufferRing>,
    groups: HashMap<Vec<Key>, wgpu::BindGroup>,
}

impl Bindings {
    pub fn new(visibility: wgpu::ShaderStages) -> Self {
        Bindings { visibility, rings: Vec::new(), groups: HashMap::new() }
    }

    /// The layout entries for `binds`: textures are filterable where the group binds a
    /// filtering sampler and the device can filter their format.
    pub fn layout_entries(&self, binds: &[Bind<'_>]) -> Vec<wgpu::BindGroupLayoutEntry> {
        let filtering = binds
            .iter()
            .any(|b| matches!(b, Bind::Sampler(k) if k.binding_type() == wgpu::SamplerBindingType::Filtering));
        binds
            .iter()
            .enumerate()
            .map(|(i, b)| {
                let binding = i as u32;
                match b {
                    Bind::Uniform(_) | Bind::UniformBuffer(_) => uniform_entry(binding, self.visibility),
                    Bind::DynamicStorage(_, size) => dynamic_storage_entry(binding, self.visibility, *size),
                    Bind::Texture(img) => texture_kind_entry(
                        binding,
                        self.visibility,
                        img.desc.sample_type(filtering),
                        img.desc.view_dimension(),
                    ),
                    Bind::View(_, dim, sample_type) => texture_kind_entry(binding, self.visibility, *sample_type, *dim),
                    Bind::Sampler(kind) => sampler_entry(binding, self.visibility, *kind),
                    Bind::Storage(_) => storage_entry_for(binding, self.visibility, true),
                    Bind::StorageRw(_) => storage_entry_for(binding, self.visibility, false),
                    Bind::StorageTexture(_, format, view_dimension) => wgpu::BindGroupLayoutEntry {
                        binding,
                        visibility: self.visibility,
                        ty: wgpu::BindingType::StorageTexture {
                            access: wgpu::StorageTextureAccess::WriteOnly,
                            format: *format,
                            view_dimension: *view_dimension,
                        },
                        count: None,
                    },
                }
            })
            .collect()
    }

    /// The (cached) layout for `binds`.
    pub fn layout(&self, gpu: &GpuContext, binds: &[Bind<'_>]) -> wgpu::BindGroupLayout {
        gpu.bind_group_layout(&self.layout_entries(binds))
    }

    /// A bind group of `binds` for `layout`: uniform blocks written to this pass's buffers,
    /// the group reused while the same resources are bound.
    pub fn bind_group(
        &mut self,
        gpu: &GpuContext,
        layout: &wgpu::BindGroupLayout,
        binds: &[Bind<'_>],
    ) -> wgpu::BindGroup {
        let mut ring = 0;
        let mut key = Vec::with_capacity(binds.len() + 1);
        let mut buffers: Vec<Option<wgpu::Buffer>> = Vec::with_capacity(binds.len());
        for b in binds {
            let buffer = match b {
                Bind::Uniform(bytes) => {
                    if ring == self.rings.len() {
                        self.rings.push(BufferRing::uniform("pass uniforms"));
                    }
                    let buf = self.rings[ring].write(gpu, bytes).clone();
                    ring += 1;
                    Some(buf)
                }
                Bind::Storage(buf) | Bind::StorageRw(buf) | Bind::UniformBuffer(buf) | Bind::DynamicStorage(buf, _) => {
                    Some((*buf).clone())
                }
                _ => None,
            };
            key.push(match (b, &buffer) {
                // The range's size is part of the group: the same buffer with another size is another group.
                (Bind::DynamicStorage(_, size), Some(buf)) => Key::Range(buf.clone(), *size),
                (_, Some(buf)) => Key::Buffer(buf.clone()),
                (Bind::Texture(img), _) => Key::View(img.view.clone()),
                (Bind::View(view, ..), _) | (Bind::StorageTexture(view, ..), _) => Key::View((*view).clone()),
                (Bind::Sampler(kind), _) => Key::Sampler(*kind),
                _ => unreachable!("buffers are handled above"),
            });
            buffers.push(buffer);
        }
        if let Some(g) = self.groups.get(&key) {
            return g.clone();
        }
        let samplers: Vec<Option<wgpu::Sampler>> =
            binds.iter().map(|b| if let Bind::Sampler(k) = b { Some(gpu.sampler(*k)) } else { None }).collect();
        let entries: Vec<wgpu::BindGroupEntry<'_>> = binds
            .iter()
            .enumerate()
            .map(|(i, b)| wgpu::BindGroupEntry {
                binding: i as u32,
                resource: match (b, &buffers[i], &samplers[i]) {
                    (Bind::DynamicStorage(_, size), Some(buf), _) => {
                        wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                            buffer: buf,
                            offset: 0,
                            size: wgpu::BufferSize::new(*size),
                        })
                    }
                    (_, Some(buf), _) => buf.as_entire_binding(),
                    (_, _, Some(s)) => wgpu::BindingResource::Sampler(s),
                    (Bind::Texture(img), ..) => wgpu::BindingResource::TextureView(&img.view),
                    (Bind::View(view, ..), ..) | (Bind::StorageTexture(view, ..), ..) => {
                        wgpu::BindingResource::TextureView(view)
                    }
                    _ => unreachable!("every bind is a buffer, a sampler or a view"),
                },
            })
            .collect();
        let group = gpu.device.create_bind_group(&wgpu::BindGroupDescriptor { label: None, layout, entries: &entries });
        if self.groups.len() >= MAX_CACHED_GROUPS {
            self.groups.clear();
        }
        self.groups.insert(key, group.clone());
        group
    }
}

/// A full-screen pass: bound resources (uniform blocks, textures of any kind, samplers,
/// storage buffers) in group 0, one triangle drawn into one or more targets. Lighting, tone
/// mapping, filters and later screen-space passes are all of this shape.
pub struct FullscreenPass {
    shader: &'static str,
    fragment_entry: &'static str,
    bindings: Bindings,
}

impl FullscreenPass {
    /// `shader` must define `vs_fullscreen` (include shaders/common/fullscreen.wgsl) and `fs_main`.
    /// [`FullscreenPass::run`] binds a uniform block at binding 0 and 2D textures at bindings
    /// 1.. of group 0; [`FullscreenPass::draw`] binds anything. The pipeline for the bound
    /// resources and targets comes from the context's cache on each run.
    pub fn new(shader: &'static str) -> Self {
        FullscreenPass { shader, fragment_entry: "fs_main", bindings: Bindings::new(wgpu::ShaderStages::FRAGMENT) }
    }

    /// Draws with fragment entry point `entry` instead of `fs_main`.
    pub fn with_fragment_entry(self, entry: &'static str) -> Self {
        FullscreenPass { fragment_entry: entry, ..self }
    }

    /// A uniform block and 2D textures into one target.
    pub fn run(
        &mut self,
        gpu: &GpuContext,
        uniform: &[u8],
        textures: &[&GpuImage],
        target: &GpuImage,
    ) -> anyhow::Result<()> {
        self.run_mrt(gpu, uniform, textures, &[target])
    }

    /// Like `run`, writing several targets (multiple render targets).
    pub fn run_mrt(
        &mut self,
        gpu: &GpuContext,
        uniform: &[u8],
        textures: &[&GpuImage],
        targets: &[&GpuImage],
    ) -> anyhow::Result<()> {
        let mut binds = vec![Bind::Uniform(uniform)];
        binds.extend(textures.iter().map(|t| Bind::Texture(t)));
        let views: Vec<&wgpu::TextureView> = targets.iter().map(|t| &t.view).collect();
        let formats: Vec<wgpu::TextureFormat> = targets.iter().map(|t| t.format).collect();
        self.draw(gpu, &binds, &views, &formats)
    }

    /// Binds `binds` at bindings 0.. of group 0 and draws into `targets` (views of `formats`),
    /// cleared first.
    pub fn draw(
        &mut self,
        gpu: &GpuContext,
        binds: &[Bind<'_>],
        targets: &[&wgpu::TextureView],
        formats: &[wgpu::TextureFormat],
    ) -> anyhow::Result<()> {
        self.draw_specialized(gpu, binds, targets, formats, &[])
    }

    /// Like `draw`, with the shader's `override` constants set (one cached pipeline per set of
    /// values). Switches that stay fixed for many frames (counts, modes, whether an input is
    /// bound) belong here rather than in branches on a uniform: lavapipe (Mesa 22) inlines the
    /// uniforms that a branch or loop depends on alone and compiles the shader again on every
    /// draw that binds them, which cost IblShading 20x its drawing time per frame with a cold
    /// shader cache (docs/ibl.md, "Frame time and memory").
    pub fn draw_specialized(
        &mut self,
        gpu: &GpuContext,
        binds: &[Bind<'_>],
        targets: &[&wgpu::TextureView],
        formats: &[wgpu::TextureFormat],
        constants: &[(&str, u32)],
    ) -> anyhow::Result<()> {
        let layout = self.bindings.layout(gpu, binds);
        let pipeline = gpu.render_pipeline(&RenderPipelineDesc {
            fragment_entry: Some(self.fragment_entry),
            constants,
            ..RenderPipelineDesc::fullscreen(self.shader, &[Some(&layout)], formats)
        })?;
        let group = self.bindings.bind_group(gpu, &layout, binds);
        let attachments: Vec<_> = targets.iter().map(|v| Some(clear_attachment(v))).collect();
        gpu.record(|enc| {
            let mut pass = enc.begin_render_pass(&wgpu::RenderPassDescriptor {
                label: Some(self.shader),
                color_attachments: &attachments,
                depth_stencil_attachment: None,
                timestamp_writes: gpu.pass_timestamps(),
                occlusion_query_set: None,
                multiview_mask: None,
            });
            pass.set_pipeline(&pipeline);
            pass.set_bind_group(0, &group, &[]);
            pass.draw(0..3, 0..1);
        });
        Ok(())
    }
}

/// A compute pass over `shader`'s entry point: one [`Bindings`] per bind group (an empty
/// slice leaves a group unused), timed like render passes.
pub struct ComputePass {
    shader: &'static str,
    entry: &'static str,
    groups: Vec<Bindings>,
}

impl ComputePass {
    pub fn new(shader: &'static str, entry: &'static str) -> Self {
        ComputePass { shader, entry, groups: Vec::new() }
    }

    /// The pipeline and bind groups for `groups`, built or taken from the caches.
    fn prepare(
        &mut self,
        gpu: &GpuContext,
        groups: &[&[Bind<'_>]],
        constants: &[(&str, u32)],
    ) -> anyhow::Result<(wgpu::ComputePipeline, Vec<Option<wgpu::BindGroup>>)> {
        while self.groups.len() < groups.len() {
            self.groups.push(Bindings::new(wgpu::ShaderStages::COMPUTE));
        }
        let layouts: Vec<Option<wgpu::BindGroupLayout>> = groups
            .iter()
            .zip(&self.groups)
            .map(|(binds, b)| (!binds.is_empty()).then(|| b.layout(gpu, binds)))
            .collect();
        let refs: Vec<Option<&wgpu::BindGroupLayout>> = layouts.iter().map(Option::as_ref).collect();
        let pipeline = gpu.compute_pipeline(self.shader, self.entry, &refs, constants)?;
        let bind_groups = groups
            .iter()
            .zip(self.groups.iter_mut())
            .zip(&layouts)
            .map(|((binds, b), layout)| layout.as_ref().map(|l| b.bind_group(gpu, l, binds)))
            .collect();
        Ok((pipeline, bind_groups))
    }

    /// Dispatches `workgroups` with `groups` bound.
    pub fn dispatch(&mut self, gpu: &GpuContext, groups: &[&[Bind<'_>]], workgroups: [u32; 3]) -> anyhow::Result<()> {
        self.dispatch_specialized(gpu, groups, workgroups, &[])
    }

    /// Like `dispatch`, with the shader's `override` constants set (see
    /// [`FullscreenPass::draw_specialized`]).
    pub fn dispatch_specialized(
        &mut self,
        gpu: &GpuContext,
        groups: &[&[Bind<'_>]],
        workgroups: [u32; 3],
        constants: &[(&str, u32)],
    ) -> anyhow::Result<()> {
        let (pipeline, bind_groups) = self.prepare(gpu, groups, constants)?;
        gpu.record(|enc| {
            let mut pass = enc.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some(self.shader),
                timestamp_writes: gpu.compute_timestamps(),
            });
            pass.set_pipeline(&pipeline);
            for (i, g) in bind_groups.iter().enumerate() {
                if let Some(g) = g {
                    pass.set_bind_group(i as u32, g, &[]);
                }
            }
            pass.dispatch_workgroups(workgroups[0], workgroups[1], workgroups[2]);
        });
        Ok(())
    }

    /// Workgroups for `n` invocations of `size` threads: x up to 65535, the rest in y
    /// (shaders fold y into the index in steps of 65535 workgroups).
    pub fn groups_for(n: usize, size: usize) -> [u32; 3] {
        let groups = n.div_ceil(size).max(1) as u32;
        [groups.min(65535), groups.div_ceil(65535), 1]
    }
}

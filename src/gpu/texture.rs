//! Texture descriptions, images with their views, and cached samplers.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use super::{GpuContext, lock};

/// The shape of a texture: what its default view is.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum TextureKind {
    /// One 2D image (`layers` is 1).
    D2,
    /// An array of 2D layers (shadow tiles, per-light maps), seen as `texture_2d_array`.
    D2Array,
    /// A cube map (6 layers; a multiple of 6 is a cube array), seen as `texture_cube`.
    Cube,
}

/// Everything that makes two textures interchangeable for the pool.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct TextureDesc {
    pub width: u32,
    pub height: u32,
    /// Array layers (6 per cube).
    pub layers: u32,
    pub mips: u32,
    pub kind: TextureKind,
    pub format: wgpu::TextureFormat,
    pub usage: wgpu::TextureUsages,
}

impl TextureDesc {
    /// A 2D texture with one mip level.
    pub fn d2(width: u32, height: u32, format: wgpu::TextureFormat, usage: wgpu::TextureUsages) -> TextureDesc {
        TextureDesc { width, height, layers: 1, mips: 1, kind: TextureKind::D2, format, usage }
    }

    /// A render target that can also be sampled and read back.
    pub fn target(width: u32, height: u32, format: wgpu::TextureFormat) -> TextureDesc {
        TextureDesc::d2(
            width,
            height,
            format,
            wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING,
        )
    }

    /// An array of `layers` 2D layers.
    pub fn array(
        width: u32,
        height: u32,
        layers: u32,
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> TextureDesc {
        TextureDesc { layers, kind: TextureKind::D2Array, ..TextureDesc::d2(width, height, format, usage) }
    }

    /// A cube map of `size` x `size` faces.
    pub fn cube(size: u32, format: wgpu::TextureFormat, usage: wgpu::TextureUsages) -> TextureDesc {
        TextureDesc { layers: 6, kind: TextureKind::Cube, ..TextureDesc::d2(size, size, format, usage) }
    }

    /// With `mips` mip levels.
    pub fn with_mips(self, mips: u32) -> TextureDesc {
        TextureDesc { mips: mips.max(1), ..self }
    }

    /// With the full mip chain down to 1x1.
    pub fn with_full_mips(self) -> TextureDesc {
        self.with_mips(32 - self.width.max(self.height).max(1).leading_zeros())
    }

    pub fn extent(&self) -> wgpu::Extent3d {
        wgpu::Extent3d { width: self.width, height: self.height, depth_or_array_layers: self.layers }
    }

    /// The dimension of the default view, as bind group layouts name it.
    pub fn view_dimension(&self) -> wgpu::TextureViewDimension {
        match self.kind {
            TextureKind::D2 => wgpu::TextureViewDimension::D2,
            TextureKind::D2Array => wgpu::TextureViewDimension::D2Array,
            TextureKind::Cube if self.layers > 6 => wgpu::TextureViewDimension::CubeArray,
            TextureKind::Cube => wgpu::TextureViewDimension::Cube,
        }
    }

    /// The aspect copies of this format use (depth only for depth formats).
    pub fn copy_aspect(&self) -> wgpu::TextureAspect {
        if self.format.has_depth_aspect() { wgpu::TextureAspect::DepthOnly } else { wgpu::TextureAspect::All }
    }

    /// How shaders sample it: depth formats as depth, others by their sample type
    /// (`filterable` only where asked for and the device can filter the format).
    pub fn sample_type(&self, filterable: bool) -> wgpu::TextureSampleType {
        match self.format.sample_type(Some(self.copy_aspect()), None) {
            Some(wgpu::TextureSampleType::Float { filterable: can }) => {
                wgpu::TextureSampleType::Float { filterable: filterable && can }
            }
            Some(other) => other,
            None => wgpu::TextureSampleType::Float { filterable: false },
        }
    }
}

/// A view of part of an image: a mip range, a layer range, a dimension.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct ViewSel {
    pub dimension: wgpu::TextureViewDimension,
    pub base_mip: u32,
    pub mips: u32,
    pub base_layer: u32,
    pub layers: u32,
}

/// What every handle to one texture shares: its views, and the pool's lease.
#[derive(Default)]
pub(crate) struct Shared {
    views: Mutex<HashMap<ViewSel, wgpu::TextureView>>,
}

/// A texture with its description and default view. Cloning handles with [`GpuImage::share`]
/// is cheap; a pooled texture goes back to the pool when the last handle is dropped.
pub struct GpuImage {
    pub texture: wgpu::Texture,
    /// The default view: the whole texture as `desc.kind` (2D, 2D array, cube).
    pub view: wgpu::TextureView,
    pub format: wgpu::TextureFormat,
    pub width: u32,
    pub height: u32,
    pub desc: TextureDesc,
    pub(crate) shared: Arc<Shared>,
}

impl GpuImage {
    /// Wraps a texture made from `desc`.
    pub(crate) fn from_texture(texture: wgpu::Texture, desc: TextureDesc, shared: Arc<Shared>) -> GpuImage {
        let view = texture
            .create_view(&wgpu::TextureViewDescriptor { dimension: Some(desc.view_dimension()), ..Default::default() });
        GpuImage { texture, view, format: desc.format, width: desc.width, height: desc.height, desc, shared }
    }

    /// A new texture of `desc` (not pooled: for textures that live as long as their owner,
    /// uploads, display targets). Always readable back (COPY_SRC).
    pub fn create(gpu: &GpuContext, label: &str, desc: TextureDesc) -> GpuImage {
        let desc = TextureDesc { usage: desc.usage | wgpu::TextureUsages::COPY_SRC, ..desc };
        let mut size = desc.extent();
        // wgpu's GL backend makes every square texture of 6k layers a cube map
        // (GL_TEXTURE_CUBE_MAP[_ARRAY]), which then reads as zero through 2D-array views: a
        // spare layer keeps a 2D array (cube faces kept for `textureLoad`) a 2D array there.
        if gpu.info.backend == wgpu::Backend::Gl
            && desc.kind == TextureKind::D2Array
            && desc.width == desc.height
            && desc.layers.is_multiple_of(6)
        {
            size.depth_or_array_layers += 1;
        }
        let texture = gpu.create_texture(&wgpu::TextureDescriptor {
            label: Some(label),
            size,
            mip_level_count: desc.mips,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D2,
            format: desc.format,
            usage: desc.usage,
            view_formats: &[],
        });
        GpuImage::from_texture(texture, desc, Arc::default())
    }

    /// A new 2D texture (not pooled).
    pub fn new(
        gpu: &GpuContext,
        label: &str,
        width: u32,
        height: u32,
        format: wgpu::TextureFormat,
        usage: wgpu::TextureUsages,
    ) -> GpuImage {
        GpuImage::create(gpu, label, TextureDesc::d2(width, height, format, usage))
    }

    /// Another handle to the same texture.
    pub fn share(&self) -> GpuImage {
        GpuImage {
            texture: self.texture.clone(),
            view: self.view.clone(),
            format: self.format,
            width: self.width,
            height: self.height,
            desc: self.desc,
            shared: self.shared.clone(),
        }
    }

    /// A sampled texture filled with `bytes` (tightly packed rows of `bytes_per_texel`).
    /// Not pooled: `queue.write_texture` runs before the commands of the next submit, so a
    /// pooled texture still read by queued commands must not be written this way.
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

    /// A pooled render target that can also be sampled and read back (see [`GpuContext::acquire`]).
    pub fn target(gpu: &GpuContext, label: &str, width: u32, height: u32, format: wgpu::TextureFormat) -> GpuImage {
        gpu.acquire(label, TextureDesc::target(width, height, format))
    }

    /// A colour attachment of the default view that clears to transparent black and stores.
    pub fn clear_attachment(&self) -> Option<wgpu::RenderPassColorAttachment<'_>> {
        Some(clear_attachment(&self.view))
    }

    /// A view of mips `base_mip..base_mip + mips` and layers `base_layer..base_layer + layers`
    /// as `dimension`; made once per image and selection.
    pub fn view_of(&self, sel: ViewSel) -> wgpu::TextureView {
        lock(&self.shared.views)
            .entry(sel)
            .or_insert_with(|| {
                self.texture.create_view(&wgpu::TextureViewDescriptor {
                    label: None,
                    format: None,
                    dimension: Some(sel.dimension),
                    usage: None,
                    aspect: wgpu::TextureAspect::All,
                    base_mip_level: sel.base_mip,
                    mip_level_count: Some(sel.mips),
                    base_array_layer: sel.base_layer,
                    array_layer_count: Some(sel.layers),
                })
            })
            .clone()
    }

    /// One layer at one mip level as a 2D view: a render target for a cube face, an array
    /// layer or a mip level.
    pub fn layer_view(&self, layer: u32, mip: u32) -> wgpu::TextureView {
        self.view_of(ViewSel {
            dimension: wgpu::TextureViewDimension::D2,
            base_mip: mip,
            mips: 1,
            base_layer: layer,
            layers: 1,
        })
    }

    /// All layers of one mip level, viewed as the texture's kind (for sampling a level).
    pub fn mip_view(&self, mip: u32) -> wgpu::TextureView {
        self.view_of(ViewSel {
            dimension: self.desc.view_dimension(),
            base_mip: mip,
            mips: 1,
            base_layer: 0,
            layers: self.desc.layers,
        })
    }

    /// The six faces with all their mips as a cube, for filtered sampling
    /// ([`GpuContext::cube_sampling`] says where that works).
    pub fn cube_view(&self) -> wgpu::TextureView {
        self.view_of(ViewSel {
            dimension: wgpu::TextureViewDimension::Cube,
            base_mip: 0,
            mips: self.desc.mips,
            base_layer: 0,
            layers: 6,
        })
    }

    /// All layers as a 2D array (a cube map's faces, for writing from a compute pass).
    pub fn array_view(&self) -> wgpu::TextureView {
        self.view_of(ViewSel {
            dimension: wgpu::TextureViewDimension::D2Array,
            base_mip: 0,
            mips: self.desc.mips,
            base_layer: 0,
            layers: self.desc.layers,
        })
    }

    /// The size of mip level `mip`.
    pub fn mip_size(&self, mip: u32) -> (u32, u32) {
        ((self.width >> mip).max(1), (self.height >> mip).max(1))
    }
}

/// A colour attachment that clears to transparent black and stores.
pub fn clear_attachment(view: &wgpu::TextureView) -> wgpu::RenderPassColorAttachment<'_> {
    wgpu::RenderPassColorAttachment {
        view,
        depth_slice: None,
        resolve_target: None,
        ops: wgpu::Operations { load: wgpu::LoadOp::Clear(wgpu::Color::TRANSPARENT), store: wgpu::StoreOp::Store },
    }
}

/// The samplers passes use, made once per context ([`GpuContext::sampler`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum SamplerKind {
    /// Bilinear (trilinear across mips), clamped at the edges.
    LinearClamp,
    /// Bilinear (trilinear across mips), repeating: tiled material maps.
    LinearRepeat,
    /// Nearest texel, clamped.
    NearestClamp,
    /// Nearest texel, repeating.
    NearestRepeat,
    /// Depth comparison (less-or-equal), bilinear, clamped: shadow map lookups.
    Comparison,
}

impl SamplerKind {
    /// The binding type a layout declares for this sampler.
    pub fn binding_type(self) -> wgpu::SamplerBindingType {
        match self {
            SamplerKind::LinearClamp | SamplerKind::LinearRepeat => wgpu::SamplerBindingType::Filtering,
            SamplerKind::NearestClamp | SamplerKind::NearestRepeat => wgpu::SamplerBindingType::NonFiltering,
            SamplerKind::Comparison => wgpu::SamplerBindingType::Comparison,
        }
    }

    pub(crate) fn create(self, device: &wgpu::Device) -> wgpu::Sampler {
        let (filter, mode) = match self {
            SamplerKind::LinearClamp | SamplerKind::Comparison => {
                (wgpu::FilterMode::Linear, wgpu::AddressMode::ClampToEdge)
            }
            SamplerKind::LinearRepeat => (wgpu::FilterMode::Linear, wgpu::AddressMode::Repeat),
            SamplerKind::NearestClamp => (wgpu::FilterMode::Nearest, wgpu::AddressMode::ClampToEdge),
            SamplerKind::NearestRepeat => (wgpu::FilterMode::Nearest, wgpu::AddressMode::Repeat),
        };
        let mipmap_filter = match filter {
            wgpu::FilterMode::Linear => wgpu::MipmapFilterMode::Linear,
            wgpu::FilterMode::Nearest => wgpu::MipmapFilterMode::Nearest,
        };
        device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("werkstatt sampler"),
            address_mode_u: mode,
            address_mode_v: mode,
            address_mode_w: mode,
            mag_filter: filter,
            min_filter: filter,
            mipmap_filter,
            compare: (self == SamplerKind::Comparison).then_some(wgpu::CompareFunction::LessEqual),
            ..Default::default()
        })
    }
}

/// Copies mip 0 of `src` into `dst` byte for byte through `scratch` (grown as needed): for
/// formats of the same texel size that `copy_texture_to_texture` will not pair, e.g. a float
/// texture rendered as its bits into Rgba32Uint where Rgba32Float is not renderable.
pub fn copy_bits(gpu: &GpuContext, src: &GpuImage, dst: &GpuImage, scratch: &mut Option<wgpu::Buffer>) {
    let texel = src.format.block_copy_size(None).unwrap_or(4);
    debug_assert_eq!(Some(texel), dst.format.block_copy_size(None), "copy_bits needs equal texel sizes");
    let row = (src.width * texel).next_multiple_of(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT);
    let size = row as u64 * src.height as u64;
    if scratch.as_ref().is_none_or(|b| b.size() < size) {
        let usage = wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST;
        *scratch = Some(gpu.create_buffer("bit copy", size, usage));
    }
    let buffer = scratch.as_ref().expect("made above");
    let layout = wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(row), rows_per_image: Some(src.height) };
    let extent = wgpu::Extent3d { width: src.width, height: src.height, depth_or_array_layers: 1 };
    gpu.record(|enc| {
        enc.copy_texture_to_buffer(src.texture.as_image_copy(), wgpu::TexelCopyBufferInfo { buffer, layout }, extent);
        enc.copy_buffer_to_texture(wgpu::TexelCopyBufferInfo { buffer, layout }, dst.texture.as_image_copy(), extent);
    });
}

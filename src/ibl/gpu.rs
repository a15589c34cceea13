//! The GPU side of image-based lighting: the values that flow between the IBL nodes and
//! the passes they share (probe resampling, the PEM mask and mip filter, cube previews).

use std::path::PathBuf;
use std::sync::Arc;

use std::f32::consts::{PI, SQRT_2};

use glam::Vec3;

use super::cube::{CubeImage, face_dir, texel_center};
use super::median_cut::{RegionLight, Regions};
use super::pem::{Calibration, Kernel};
use crate::gpu::{Bind, ComputePass, FullscreenPass, GpuContext, GpuImage, TextureDesc};

/// A light probe as a cube map (`EnvironmentMap`'s output).
pub struct EnvMap {
    /// The radiance, rotated and scaled, with a plain (2x2 box) mip chain: HDR format.
    pub cube: GpuImage,
    /// Level 0 as read back (what the median cut splits and the reference integrates).
    pub texels: Arc<CubeImage>,
    /// An equirectangular view of level 0 for the viewport.
    pub preview: GpuImage,
    pub source: PathBuf,
}

impl EnvMap {
    pub fn size(&self) -> usize {
        self.texels.size
    }
}

/// Directional lights, one per region of the environment map (`MedianCut`'s output), with
/// the regions themselves where they came from a map (the PEMs need them).
pub struct Lights {
    pub lights: Vec<RegionLight>,
    pub regions: Option<Arc<Regions>>,
    /// The regions shown over the map, for inspection (Fig. 3.14).
    pub preview: Option<GpuImage>,
}

/// The filtered partial environment maps of every region (`Pems`' output).
pub struct PemSet {
    pub kernel: Kernel,
    /// One cube map per region, full mip chain, HDR format.
    pub pems: Vec<GpuImage>,
    /// The whole map filtered with the same kernel: what the PEMs sum to.
    pub full: GpuImage,
    /// The diffuse ends ([`super::pem::diffuse_end`]) of the PEMs, one [`diffuse_target`] per
    /// [`PEMS_PER_PASS`] PEMs (PEM k at layers 6 (k mod 8) ..), as IblShading binds them.
    pub diffuse: Vec<GpuImage>,
    /// The full map's diffuse end (six layers).
    pub full_diffuse: GpuImage,
    pub calibration: Arc<Calibration>,
    /// A chosen PEM (or the sum) at a chosen level, as an equirectangular image.
    pub preview: GpuImage,
    /// GPU memory of `pems` (bytes), mip chains included.
    pub bytes: u64,
}

/// A cube map of face size `size` with its full mip chain, stored as a 2D array of six layers
/// (shaders/ibl/cube.wgsl reads it with `textureLoad`: OpenGL cannot view a cube texture as an
/// array, and the CPU twins then match exactly), for rendering or storing into faces and
/// levels. Rgba16Float: WebGPU guarantees it renderable, filterable and storable.
pub fn cube_target(gpu: &GpuContext, label: &str, size: u32) -> anyhow::Result<GpuImage> {
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
        | wgpu::TextureUsages::TEXTURE_BINDING
        | wgpu::TextureUsages::STORAGE_BINDING
        | wgpu::TextureUsages::COPY_DST;
    Ok(GpuImage::create(gpu, label, TextureDesc::array(size, size, 6, CUBE_FORMAT, usage).with_full_mips()))
}

/// PEMs per IblShading pass (its bindings pem0..pem7).
pub const PEMS_PER_PASS: usize = 8;

/// Diffuse ends ([`super::pem::diffuse_end`]) of `cubes` cube maps of face size `size`, one
/// 2D array (cube k's faces at layers 6k..6k+5, one mip).
pub fn diffuse_target(gpu: &GpuContext, label: &str, size: u32, cubes: u32) -> GpuImage {
    let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
        | wgpu::TextureUsages::TEXTURE_BINDING
        | wgpu::TextureUsages::STORAGE_BINDING;
    GpuImage::create(gpu, label, TextureDesc::array(size, size, 6 * cubes, CUBE_FORMAT, usage))
}

/// The format of cube maps and PEMs (shaders/ibl/pem_filter.wgsl stores into it).
const CUBE_FORMAT: wgpu::TextureFormat = wgpu::TextureFormat::Rgba16Float;

/// Writes mip `level` of the six faces at layers `first_layer..first_layer + 6` of `dst` (a
/// cube, or a 2D array of cubes) with one of shaders/ibl/pem_filter.wgsl's or pem_phong.wgsl's
/// passes (`params` and `binds` after it in group 0): one compute dispatch, or on GL one render
/// pass per face.
fn faces_pass<P: FaceParams>(
    gpu: &GpuContext,
    (compute, render): &mut (ComputePass, FullscreenPass),
    params: P,
    binds: &[Bind<'_>],
    (dst, level, first_layer): (&GpuImage, u32, u32),
) -> anyhow::Result<()> {
    let size = dst.width >> level;
    if gpu.info.backend != wgpu::Backend::Gl {
        let mut group0 = vec![Bind::Uniform(bytemuck::bytes_of(&params))];
        group0.extend_from_slice(binds);
        let store = dst.view_of(crate::gpu::texture::ViewSel {
            dimension: wgpu::TextureViewDimension::D2Array,
            base_mip: level,
            mips: 1,
            base_layer: first_layer,
            layers: 6,
        });
        let group1 = [Bind::StorageTexture(&store, CUBE_FORMAT, wgpu::TextureViewDimension::D2Array)];
        return compute.dispatch(gpu, &[&group0, &group1], [size.div_ceil(8), size.div_ceil(8), 6]);
    }
    for face in 0..6 {
        let params = params.with_face(face);
        let mut group0 = vec![Bind::Uniform(bytemuck::bytes_of(&params))];
        group0.extend_from_slice(binds);
        render.draw(gpu, &group0, &[&dst.layer_view(first_layer + face, level)], &[dst.format])?;
    }
    Ok(())
}

/// Uniforms of a pass over a cube's faces: the render path draws one face at a time.
trait FaceParams: bytemuck::Pod {
    fn with_face(self, face: u32) -> Self;
}

impl FaceParams for FilterParams {
    fn with_face(self, face: u32) -> Self {
        FilterParams { face, ..self }
    }
}

impl FaceParams for PhongParams {
    fn with_face(self, face: u32) -> Self {
        PhongParams { face, ..self }
    }
}

/// Mip `level` of the first `layers` layers of a cube map's texture, as a 2D array: its six
/// faces for reading, or every layer for storing (GL binds images by whole levels, and its cube
/// maps carry a spare layer, see `GpuImage::create`).
fn level_layers(cube: &GpuImage, level: u32, layers: u32) -> wgpu::TextureView {
    cube.view_of(crate::gpu::texture::ViewSel {
        dimension: wgpu::TextureViewDimension::D2Array,
        base_mip: level,
        mips: 1,
        base_layer: 0,
        layers,
    })
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct FilterParams {
    face: u32,
    src_size: u32,
    region: u32,
    pad: u32,
    weights: [f32; 28],
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PhongParams {
    face: u32,
    dst_size: u32,
    src_size: u32,
    full_sphere: u32,
    exponent: f32,
    window: i32,
    pad: [f32; 2],
    bounds: FaceBounds,
    /// Axis and cos of the half-angle outside which the level is black ([`Footprint::cone`]).
    cone: [f32; 4],
    /// The same for single lookups into the source level (window 0): taps outside it read
    /// exact zeros, and are skipped.
    tap_cone: [f32; 4],
}

impl PhongParams {
    /// The sum over every source texel inside `bounds` of all six faces, source and
    /// destination of face size `size`, no cone.
    fn whole_sphere(face: u32, size: u32, exponent: f32, bounds: FaceBounds) -> PhongParams {
        PhongParams {
            face,
            dst_size: size,
            src_size: size,
            full_sphere: 1,
            exponent,
            window: 0,
            pad: [0.0; 2],
            bounds,
            cone: NO_CONE,
            tap_cone: NO_CONE,
        }
    }
}

/// Where a cube map's level 0 may be non-zero (a PEM is black outside its region): the Phong
/// prefilter sums only these texels on its whole-sphere levels and returns black, without
/// summing, for destination texels whose window cannot reach them.
#[derive(Clone, Copy, Debug)]
pub struct Footprint {
    /// Per face, (x0, y0, x1, y1) inclusive; empty when x0 > x1.
    pub faces: FaceBounds,
    /// A cone holding every non-zero texel: its axis and half-angle (radians; pi: everything).
    pub axis: Vec3,
    pub angle: f32,
}

pub type FaceBounds = [[u32; 4]; 6];

/// A cone that skips nothing.
const NO_CONE: [f32; 4] = [0.0, 0.0, 1.0, -2.0];

impl Footprint {
    /// Every texel of a face-size `size` map.
    pub fn whole(size: u32) -> Footprint {
        Footprint { faces: [[0, 0, size - 1, size - 1]; 6], axis: Vec3::Z, angle: PI }
    }

    /// The texels of `ids` (a cube's region ids, faces stacked vertically) equal to `region`.
    pub fn of_region(ids: &[u32], size: usize, region: u32) -> Footprint {
        let mut faces = [[u32::MAX, u32::MAX, 0, 0]; 6];
        let mut dirs = Vec::new();
        for (i, _) in ids.iter().enumerate().filter(|(_, id)| **id == region) {
            let (face, y, x) = (i / (size * size), (i / size) % size, i % size);
            let b = &mut faces[face];
            *b = [b[0].min(x as u32), b[1].min(y as u32), b[2].max(x as u32), b[3].max(y as u32)];
            dirs.push(face_dir(face, texel_center(size, x), texel_center(size, y)).normalize());
        }
        let axis = dirs.iter().sum::<Vec3>().normalize_or_zero();
        // Half a texel's diagonal (on the face plane, an upper bound of the angle) beyond the
        // farthest texel centre.
        let farthest = dirs.iter().map(|d| d.dot(axis).clamp(-1.0, 1.0).acos()).fold(0.0f32, f32::max);
        let angle = if axis == Vec3::ZERO { PI } else { (farthest + SQRT_2 / size as f32).min(PI) };
        Footprint { faces, axis, angle }
    }

    /// The cone (axis, cos of the half-angle) outside which a Phong level of a plain-chain
    /// source of face size `src` and window `window` is exactly black: the window's centre
    /// lies within a texel of the destination texel's, its taps reach sqrt(2) window texels
    /// further on the face plane, each bilinear lookup one texel further, and the plain chain's
    /// box filter spreads the footprint by one more (angles on the sphere are at most
    /// distances on a face plane). -2 where the cone covers everything.
    fn cone(&self, src: u32, window: i32) -> [f32; 4] {
        let h = 2.0 / src as f32;
        let angle = self.angle + SQRT_2 * h * (window.max(0) as f32 + 3.0);
        if angle >= PI {
            return NO_CONE;
        }
        [self.axis.x, self.axis.y, self.axis.z, angle.cos()]
    }
}

/// `bounds` at mip `level` of the plain (2x2 box) chain: each level-0 rectangle halved per
/// level, widened by a texel against any rounding in the box filter's lookups.
fn bounds_at_level(bounds: &FaceBounds, level: u32, size: u32) -> FaceBounds {
    let last = (size >> level).max(1) - 1;
    bounds.map(|[x0, y0, x1, y1]| {
        if x0 > x1 {
            return [1, 1, 0, 0];
        }
        let lo = |c: u32| (c >> level).saturating_sub(1);
        let hi = |c: u32| ((c >> level) + 1).min(last);
        [lo(x0), lo(y0), hi(x1), hi(y1)]
    })
}

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct PreviewParams {
    size: [f32; 2],
    level: f32,
    scale: f32,
    face_size: u32,
    top: f32,
    pad: [f32; 2],
}

/// The passes that build cube maps: level 0 uploads, masking, the mip filters, previews.
pub struct CubePasses {
    /// shaders/ibl/pem_filter.wgsl: the filter and the mask, as compute (one dispatch per
    /// level) or, on GL, as a render pass per face.
    filter: (ComputePass, FullscreenPass),
    /// The plain chain's 2x2 box (kernel none).
    boxed: (ComputePass, FullscreenPass),
    mask: (ComputePass, FullscreenPass),
    /// The Phong levels and diffuse ends (compute, or a render pass per face on GL).
    phong: (ComputePass, FullscreenPass),
    /// The padded source of a windowed Phong level (pem_phong.wgsl cs_pad).
    pad: (ComputePass, FullscreenPass),
    phong_norm: FullscreenPass,
    /// fs_phong_norm's output for the whole-sphere levels of one face size, kept: it depends
    /// only on the geometry, and every PEM of a set shares it.
    norms: Option<GpuImage>,
    /// fs_phong_norm's output for the diffuse end of one face size.
    diffuse_norms: Option<GpuImage>,
    preview: FullscreenPass,
}

impl Default for CubePasses {
    fn default() -> Self {
        CubePasses {
            filter: (
                ComputePass::new("pem_filter.wgsl", "cs_filter"),
                FullscreenPass::new("pem_filter.wgsl").with_fragment_entry("fs_filter"),
            ),
            boxed: (
                ComputePass::new("pem_filter.wgsl", "cs_box"),
                FullscreenPass::new("pem_filter.wgsl").with_fragment_entry("fs_box"),
            ),
            mask: (
                ComputePass::new("pem_filter.wgsl", "cs_mask"),
                FullscreenPass::new("pem_filter.wgsl").with_fragment_entry("fs_mask"),
            ),
            phong: (
                ComputePass::new("pem_phong.wgsl", "cs_phong"),
                FullscreenPass::new("pem_phong.wgsl").with_fragment_entry("fs_phong"),
            ),
            pad: (
                ComputePass::new("pem_phong.wgsl", "cs_pad"),
                FullscreenPass::new("pem_phong.wgsl").with_fragment_entry("fs_pad"),
            ),
            phong_norm: FullscreenPass::new("pem_phong.wgsl").with_fragment_entry("fs_phong_norm"),
            norms: None,
            diffuse_norms: None,
            preview: FullscreenPass::new("cube_preview.wgsl"),
        }
    }
}

impl CubePasses {
    /// Writes `texels` (a CPU cube map, e.g. the resampled probe) into level 0 of `cube`.
    pub fn upload_level0(&self, gpu: &GpuContext, texels: &CubeImage, cube: &GpuImage) {
        let size = texels.size as u32;
        let data: Vec<u16> = texels
            .texels
            .iter()
            .flat_map(|t| t.to_array())
            .map(|v| half::f16::from_f32(v.min(65504.0)).to_bits())
            .collect();
        // One layer per write: the GL backend mishandles multi-layer writes.
        let face_bytes = (8 * size * size) as usize;
        for (face, bytes) in bytemuck::cast_slice::<u16, u8>(&data).chunks_exact(face_bytes).enumerate() {
            gpu.queue.write_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: &cube.texture,
                    mip_level: 0,
                    origin: wgpu::Origin3d { x: 0, y: 0, z: face as u32 },
                    aspect: wgpu::TextureAspect::All,
                },
                bytes,
                wgpu::TexelCopyBufferLayout { offset: 0, bytes_per_row: Some(8 * size), rows_per_image: Some(size) },
                wgpu::Extent3d { width: size, height: size, depth_or_array_layers: 1 },
            );
        }
    }

    /// Fills levels 1.. of `cube` from level 0 with `kernel` (shaders/ibl/pem_filter.wgsl,
    /// pem_phong.wgsl); level 0 is black outside `bounds`. With `diffuse` (a
    /// [`diffuse_target`] and a cube index in it), also writes the map's diffuse end there.
    pub fn filter_chain(
        &mut self,
        gpu: &GpuContext,
        cube: &GpuImage,
        kernel: Kernel,
        footprint: &Footprint,
        diffuse: Option<(&GpuImage, u32)>,
    ) -> anyhow::Result<()> {
        let plain =
            if kernel == Kernel::Phong || diffuse.is_some() { Some(self.plain_chain(gpu, cube)?) } else { None };
        match &plain {
            Some(plain) if kernel == Kernel::Phong => self.phong_levels(gpu, cube, plain, footprint)?,
            _ => self.kernel_levels(gpu, cube, kernel)?,
        }
        if let (Some((dst, index)), Some(plain)) = (diffuse, &plain) {
            self.diffuse_end(gpu, plain, footprint, dst, index)?;
        }
        Ok(())
    }

    /// Levels 1.. of `cube` with a 5x5 kernel, each from the one before.
    fn kernel_levels(&mut self, gpu: &GpuContext, cube: &GpuImage, kernel: Kernel) -> anyhow::Result<()> {
        let w = super::pem::weights(kernel);
        let total: f32 = w.iter().flatten().sum();
        let mut weights = [0.0f32; 28];
        for (i, v) in w.iter().flatten().enumerate() {
            weights[i] = v / total;
        }
        for mip in 1..cube.desc.mips {
            let source = level_layers(cube, mip - 1, 6);
            let params = FilterParams { face: 0, src_size: cube.width >> (mip - 1), region: 0, pad: 0, weights };
            let sample_type = cube.desc.sample_type(false);
            let binds = [Bind::View(&source, wgpu::TextureViewDimension::D2Array, sample_type)];
            let pass = if kernel == Kernel::None { &mut self.boxed } else { &mut self.filter };
            faces_pass(gpu, pass, params, &binds, (cube, mip, 0))?;
        }
        Ok(())
    }

    /// A plain (2x2 box) mip chain of `cube`'s level 0, in a pooled cube.
    fn plain_chain(&mut self, gpu: &GpuContext, cube: &GpuImage) -> anyhow::Result<GpuImage> {
        let plain = gpu.acquire("plain mip chain", cube.desc);
        gpu.record(|enc| {
            enc.copy_texture_to_texture(
                cube.texture.as_image_copy(),
                plain.texture.as_image_copy(),
                wgpu::Extent3d { width: cube.width, height: cube.width, depth_or_array_layers: 6 },
            )
        });
        self.kernel_levels(gpu, &plain, Kernel::None)?;
        Ok(plain)
    }

    /// The Phong prefilter (src/ibl/pem.rs phong_level): every level of `cube` integrated from
    /// the plain chain.
    fn phong_levels(
        &mut self,
        gpu: &GpuContext,
        cube: &GpuImage,
        plain: &GpuImage,
        footprint: &Footprint,
    ) -> anyhow::Result<()> {
        let norms = self.phong_norms(gpu, cube)?;
        let size = cube.width as usize;
        let sample_type = plain.desc.sample_type(false);
        for mip in 1..cube.desc.mips {
            let source = super::pem::phong_source(size, mip as usize) as u32;
            let view = level_layers(plain, source, 6);
            let norm_view = level_layers(&norms, mip, 6);
            let (dst, src) = (cube.width >> mip, cube.width >> source);
            let exponent = super::pem::phong_exponent(size, mip as usize);
            let full_sphere = u32::from(dst as usize <= super::pem::PHONG_FULL_SPHERE_SIZE);
            let window = super::pem::phong_window(src as usize, exponent);
            let params = PhongParams {
                face: 0,
                dst_size: dst,
                src_size: src,
                full_sphere,
                exponent,
                window,
                pad: [0.0; 2],
                bounds: bounds_at_level(&footprint.faces, source, cube.width),
                // The whole-sphere sum reaches every texel in front of r: no cone there.
                cone: if full_sphere == 1 { NO_CONE } else { footprint.cone(src, window) },
                tap_cone: if full_sphere == 1 { NO_CONE } else { footprint.cone(src, 0) },
            };
            let norm_bind = Bind::View(&norm_view, wgpu::TextureViewDimension::D2Array, norms.desc.sample_type(false));
            if full_sphere == 1 {
                let binds = [Bind::View(&view, wgpu::TextureViewDimension::D2Array, sample_type), norm_bind];
                faces_pass(gpu, &mut self.phong, params, &binds, (cube, mip, 0))?;
                continue;
            }
            let padded = self.padded_source(gpu, &view, sample_type, params)?;
            let binds = [Bind::Texture(&padded), norm_bind];
            faces_pass(gpu, &mut self.phong, params, &binds, (cube, mip, 0))?;
        }
        Ok(())
    }

    /// The source level `view` of a windowed Phong level padded by the window's half-width
    /// (pem_phong.wgsl cs_pad), in a pooled texture.
    fn padded_source(
        &mut self,
        gpu: &GpuContext,
        view: &wgpu::TextureView,
        sample_type: wgpu::TextureSampleType,
        params: PhongParams,
    ) -> anyhow::Result<GpuImage> {
        let size = params.src_size + 2 * params.window as u32;
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::STORAGE_BINDING;
        let padded = gpu.acquire("padded Phong source", TextureDesc::array(size, size, 6, CUBE_FORMAT, usage));
        let binds = [Bind::View(view, wgpu::TextureViewDimension::D2Array, sample_type)];
        faces_pass(gpu, &mut self.pad, params, &binds, (&padded, 0, 0))?;
        Ok(padded)
    }

    /// The diffuse end (src/ibl/pem.rs diffuse_end): the cosine lobe summed over the whole
    /// sphere of the plain chain's level of the target's face size, into cube `index` of `dst`.
    fn diffuse_end(
        &mut self,
        gpu: &GpuContext,
        plain: &GpuImage,
        footprint: &Footprint,
        dst: &GpuImage,
        index: u32,
    ) -> anyhow::Result<()> {
        let d = dst.width;
        let source = (plain.width / d).ilog2();
        let norms = match self.diffuse_norms.as_ref().filter(|n| n.width == d) {
            Some(n) => n.share(),
            None => {
                let norms = self.norm_target(gpu, "diffuse end normalization", d, 1);
                self.norm_pass(gpu, &norms, 0, d, 1.0, None)?;
                self.diffuse_norms = Some(norms.share());
                norms
            }
        };
        let view = level_layers(plain, source, 6);
        let norm_view = level_layers(&norms, 0, 6);
        let params = PhongParams::whole_sphere(0, d, 1.0, bounds_at_level(&footprint.faces, source, plain.width));
        let binds = [
            Bind::View(&view, wgpu::TextureViewDimension::D2Array, plain.desc.sample_type(false)),
            Bind::View(&norm_view, wgpu::TextureViewDimension::D2Array, norms.desc.sample_type(false)),
        ];
        faces_pass(gpu, &mut self.phong, params, &binds, (dst, 0, 6 * index))?;
        Ok(())
    }

    /// A six-layer texture for Phong normalizations (one float channel, as precise as the
    /// device renders: linear depth's format, R32Float or 16-bit floats on llvmpipe's GL).
    fn norm_target(&self, gpu: &GpuContext, label: &str, size: u32, mips: u32) -> GpuImage {
        let usage = wgpu::TextureUsages::RENDER_ATTACHMENT | wgpu::TextureUsages::TEXTURE_BINDING;
        let desc = TextureDesc::array(size, size, 6, gpu.formats().linear_depth, usage).with_mips(mips);
        GpuImage::create(gpu, label, desc)
    }

    /// fs_phong_norm into mip `mip` (face size `size`) of `norms`: the weights' sum at exponent
    /// `exponent` over the whole sphere of a source of the same face size or, with
    /// `window` = (source face size, half-width), over that window.
    fn norm_pass(
        &mut self,
        gpu: &GpuContext,
        norms: &GpuImage,
        mip: u32,
        size: u32,
        exponent: f32,
        window: Option<(u32, i32)>,
    ) -> anyhow::Result<()> {
        for face in 0..6 {
            let mut params = PhongParams::whole_sphere(face, size, exponent, Footprint::whole(size).faces);
            if let Some((src, window)) = window {
                (params.full_sphere, params.src_size, params.window) = (0, src, window);
            }
            self.phong_norm.draw(
                gpu,
                &[Bind::Uniform(bytemuck::bytes_of(&params))],
                &[&norms.layer_view(face, mip)],
                &[norms.format],
            )?;
        }
        Ok(())
    }

    /// The Phong weights' sum per texel of every level of a face-size `cube.width` chain
    /// (fs_phong_norm), computed once per size.
    fn phong_norms(&mut self, gpu: &GpuContext, cube: &GpuImage) -> anyhow::Result<GpuImage> {
        if let Some(norms) = self.norms.as_ref().filter(|n| n.width == cube.width) {
            return Ok(norms.share());
        }
        let norms = self.norm_target(gpu, "Phong normalization", cube.width, cube.desc.mips);
        let size = cube.width as usize;
        for mip in 1..cube.desc.mips {
            let dst = cube.width >> mip;
            let src = cube.width >> super::pem::phong_source(size, mip as usize);
            let exponent = super::pem::phong_exponent(size, mip as usize);
            let window = (dst as usize > super::pem::PHONG_FULL_SPHERE_SIZE)
                .then(|| (src, super::pem::phong_window(src as usize, exponent)));
            self.norm_pass(gpu, &norms, mip, dst, exponent, window)?;
        }
        self.norms = Some(norms.share());
        Ok(norms)
    }

    /// Level 0 of `dst`: level 0 of `src` where `regions` (faces stacked vertically) holds
    /// `region`, black elsewhere.
    pub fn mask(
        &mut self,
        gpu: &GpuContext,
        src: &GpuImage,
        regions: &GpuImage,
        region: u32,
        dst: &GpuImage,
    ) -> anyhow::Result<()> {
        let source = level_layers(src, 0, 6);
        let params = FilterParams { face: 0, src_size: src.width, region, pad: 0, weights: [0.0; 28] };
        let sample_type = src.desc.sample_type(false);
        let binds = [Bind::View(&source, wgpu::TextureViewDimension::D2Array, sample_type), Bind::Texture(regions)];
        faces_pass(gpu, &mut self.mask, params, &binds, (dst, 0, 0))?;
        Ok(())
    }

    /// An equirectangular image (2 size x size) of `cube` at mip `level`, times `scale`.
    pub fn preview(&mut self, gpu: &GpuContext, cube: &GpuImage, level: f32, scale: f32) -> anyhow::Result<GpuImage> {
        let (w, h) = (2 * cube.width.max(16), cube.width.max(16));
        let out = GpuImage::create(gpu, "cube preview", TextureDesc::target(w, h, gpu.formats().hdr));
        let top = (cube.desc.mips - 1) as f32;
        let params =
            PreviewParams { size: [w as f32, h as f32], level, scale, face_size: cube.width, top, pad: [0.0; 2] };
        self.preview.draw(
            gpu,
            &[Bind::Uniform(bytemuck::bytes_of(&params)), Bind::Texture(cube)],
            &[&out.view],
            &[out.format],
        )?;
        Ok(out)
    }
}

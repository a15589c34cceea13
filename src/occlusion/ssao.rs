//! Local, screen-space ambient occlusion on the G-buffer (the local part of the dissertation's
//! hybrid occlusion, §3.2.2 and §4.2.2; shaders/occlusion/ssao.wgsl), run by the `Ssao` node
//! (nodes/occlusion/ssao.rs) and the benches.

use crate::gpu::{Bind, FullscreenPass, GpuContext, GpuImage};
use crate::render::scene::GBuffer;

crate::choice!(
    /// How the occlusion is estimated.
    pub enum SsaoMode {
        /// The dissertation's depth-only sphere sampling, normalised to 1 on a plane.
        Sphere = "sphere",
        /// Horizon-based, normal-aware, cosine-weighted (after GTAO, Jimenez et al. 2016).
        Horizon = "horizon",
    }
);

/// The depth bias of the sphere test, as a fraction of the radius.
pub const BIAS: f32 = 0.02;
/// The range check of the sphere test, in radii: an occluder more than this far in front of
/// a sample does not count (a foreground object does not darken what lies far behind it).
pub const RANGE: f32 = 2.0;
/// The plane tolerance of the blur and upsampling, as a fraction of the radius.
pub const PLANE_TOLERANCE: f32 = 0.1;

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
pub(crate) struct SsaoUniform {
    pub(crate) proj: [[f32; 4]; 4],
    pub(crate) view: [[f32; 4]; 4],
    pub(crate) size: [f32; 4],
    /// World units.
    pub(crate) radius: f32,
    /// Unused: the sample count is the pipeline's constant `SAMPLES`.
    pub(crate) unused0: f32,
    /// The exponent.
    pub(crate) strength: f32,
    /// 1, or 2 at half resolution.
    pub(crate) scale: f32,
    pub(crate) depth_bias: f32,
    /// How far in front of a sample an occluder may be.
    pub(crate) range: f32,
    /// Of the blur and upsampling.
    pub(crate) plane_tolerance: f32,
    /// Unused: whether the blur follows is the pipeline's constant `BLUR`.
    pub(crate) unused1: f32,
}

pub(crate) struct Passes {
    pub(crate) sphere: FullscreenPass,
    pub(crate) horizon: FullscreenPass,
    pub(crate) blur: FullscreenPass,
    pub(crate) upsample: FullscreenPass,
    pub(crate) apply: FullscreenPass,
}

impl Passes {
    pub(crate) fn new() -> Self {
        let pass = |entry| FullscreenPass::new("ssao.wgsl").with_fragment_entry(entry);
        Passes {
            sphere: pass("fs_sphere"),
            horizon: pass("fs_horizon"),
            blur: pass("fs_blur"),
            upsample: pass("fs_upsample"),
            apply: pass("fs_apply"),
        }
    }
}

/// The settings of one SSAO evaluation (the node's parameters).
#[derive(Clone, Copy, Debug)]
pub struct SsaoSettings {
    pub mode: SsaoMode,
    pub radius: f32,
    pub samples: u32,
    pub half_resolution: bool,
    pub blur: bool,
    pub strength: f32,
}

impl Passes {
    /// The factor for `g` (Rgba16Float, the G-buffer's size).
    pub(crate) fn occlusion(&mut self, gpu: &GpuContext, g: &GBuffer, s: &SsaoSettings) -> anyhow::Result<GpuImage> {
        let scale = if s.half_resolution { 2 } else { 1 };
        let (w, h) = (g.width(), g.height());
        let (aw, ah) = (w.div_ceil(scale), h.div_ceil(scale));
        let format = gpu.formats().hdr;
        let uniform = |tw: u32, th: u32, scale: u32| SsaoUniform {
            proj: g.view.proj.to_cols_array_2d(),
            view: g.view.view.to_cols_array_2d(),
            size: [w as f32, h as f32, tw as f32, th as f32],
            radius: s.radius,
            unused0: 0.0,
            strength: s.strength,
            scale: scale as f32,
            depth_bias: BIAS * s.radius,
            range: RANGE * s.radius,
            plane_tolerance: PLANE_TOLERANCE * s.radius,
            unused1: 0.0,
        };
        let run = |pass: &mut FullscreenPass, u: SsaoUniform, ao: &GpuImage, out: &GpuImage| {
            let binds = [
                Bind::Uniform(bytemuck::bytes_of(&u)),
                Bind::Texture(&g.depth),
                Bind::Texture(&g.normal),
                Bind::Texture(ao),
                Bind::Texture(&g.color),
            ];
            let switches = [("SAMPLES", s.samples), ("BLUR", u32::from(s.blur))];
            pass.draw_specialized(gpu, &binds, &[&out.view], &[out.format], &switches)
        };
        let raw = GpuImage::target(gpu, "ssao raw", aw, ah, format);
        let estimate = match s.mode {
            SsaoMode::Sphere => &mut self.sphere,
            SsaoMode::Horizon => &mut self.horizon,
        };
        // The estimate reads no AO texture: the colour target stands in for the binding.
        run(estimate, uniform(aw, ah, scale), &g.color, &raw)?;
        let filtered = if s.blur {
            let out = GpuImage::target(gpu, "ssao filtered", aw, ah, format);
            run(&mut self.blur, uniform(aw, ah, scale), &raw, &out)?;
            out
        } else {
            raw
        };
        if scale == 1 {
            return Ok(filtered);
        }
        let out = GpuImage::target(gpu, "ssao", w, h, format);
        run(&mut self.upsample, uniform(aw, ah, scale), &filtered, &out)?;
        Ok(out)
    }
}

/// Runs SSAO outside a graph (benches): the factor for `g`.
pub struct SsaoRunner(Passes);

impl Default for SsaoRunner {
    fn default() -> Self {
        SsaoRunner(Passes::new())
    }
}

impl SsaoRunner {
    pub fn occlusion(&mut self, gpu: &GpuContext, g: &GBuffer, settings: &SsaoSettings) -> anyhow::Result<GpuImage> {
        self.0.occlusion(gpu, g, settings)
    }
}

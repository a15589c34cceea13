//! `Ssao`: local, screen-space ambient occlusion on the G-buffer (the local part of the
//! dissertation's hybrid occlusion, §3.2.2 and §4.2.2; shaders/ssao.wgsl).

use std::sync::Arc;

use crate::core::node::prelude::*;
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

pub static SSAO: NodeSpec = NodeSpec {
    kind: "Ssao",
    category: Category::Lighting,
    doc: "Local screen-space ambient occlusion from the G-buffer: the visibility factor v in [0, 1] (1 = unoccluded). \
mode sphere is the dissertation's depth-only SSAO (§4.2.2): `samples` points in a sphere of `radius` (world units) around the pixel's point, \
uniform in radius (so denser toward the centre), each occluded when the G-buffer's depth where it projects is in front of it by more than \
0.02 radius and less than 2 radii; v = clamp(2 (1 - occluded fraction), 0, 1), so an open plane gives 1, a 90-degree concave edge 1/2, a corner 1/4, \
convex surfaces 1 (clamped). mode horizon is normal-aware and cosine-weighted (GTAO): per pixel two slices, samples/4 depth taps per side of each, \
the horizons within the radius, visibility integrated analytically per slice (plane 1, edge 1/2, corner 1/4). Both rotate their kernel per pixel \
with a 4x4 interleaved pattern and then filter each 4x4 tile edge-aware (neighbours within 0.1 radius of the pixel's tangent plane, weighted by (n.n')^4). \
half_resolution computes at half size and upsamples depth- and normal-aware. Deterministic: no time-based noise.",
    inputs: &[
        PortSpec::required(
            "gbuffer",
            PortType::GBuffer,
            "The G-buffer (its linear depth; its normals in horizon mode).",
        ),
        PortSpec::optional("image", PortType::Texture, "An image (of the G-buffer's size) to multiply by the factor."),
    ],
    outputs: &[
        PortSpec::output("occlusion", PortType::Texture, "The visibility factor in rgb (1 = unoccluded), Rgba16Float."),
        PortSpec::output(
            "image",
            PortType::Texture,
            "The image times the factor; the factor itself when no image is connected.",
        ),
    ],
    params: &[
        ParamSpec::new(
            "mode",
            ParamKind::Choice { default: "sphere", options: SsaoMode::OPTIONS },
            "sphere: depth-only sphere sampling (the dissertation); horizon: normal-aware horizon-based (GTAO).",
        ),
        ParamSpec::new(
            "radius",
            ParamKind::Float { default: 0.3, min: 1e-4, max: 1e4 },
            "The neighbourhood's radius in world units.",
        ),
        ParamSpec::new(
            "samples",
            ParamKind::Int { default: 16, min: 4, max: 256 },
            "Depth taps per pixel (a tile of 4x4 pixels uses 16 times as many directions).",
        ),
        ParamSpec::new(
            "half_resolution",
            ParamKind::Bool { default: false },
            "Compute at half size and upsample depth-aware.",
        ),
        ParamSpec::new(
            "blur",
            ParamKind::Bool { default: true },
            "Filter the 4x4 dither pattern away (off shows the raw interleaved estimate).",
        ),
        ParamSpec::new(
            "strength",
            ParamKind::Float { default: 1.0, min: 0.0, max: 8.0 },
            "Exponent applied to the factor (1 leaves it as estimated; 0 turns occlusion off).",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(SsaoNode::default()),
};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct SsaoUniform {
    proj: [[f32; 4]; 4],
    view: [[f32; 4]; 4],
    size: [f32; 4],
    /// World units.
    radius: f32,
    samples: f32,
    /// The exponent.
    strength: f32,
    /// 1, or 2 at half resolution.
    scale: f32,
    depth_bias: f32,
    /// How far in front of a sample an occluder may be.
    range: f32,
    /// Of the blur and upsampling.
    plane_tolerance: f32,
    /// 1 when the blur follows.
    blur: f32,
}

#[derive(Default)]
struct SsaoNode {
    passes: Option<Passes>,
}

struct Passes {
    sphere: FullscreenPass,
    horizon: FullscreenPass,
    blur: FullscreenPass,
    upsample: FullscreenPass,
    apply: FullscreenPass,
}

impl Passes {
    fn new() -> Self {
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
    fn occlusion(&mut self, gpu: &GpuContext, g: &GBuffer, s: &SsaoSettings) -> anyhow::Result<GpuImage> {
        let scale = if s.half_resolution { 2 } else { 1 };
        let (w, h) = (g.width(), g.height());
        let (aw, ah) = (w.div_ceil(scale), h.div_ceil(scale));
        let format = gpu.formats().hdr;
        let uniform = |tw: u32, th: u32, scale: u32| SsaoUniform {
            proj: g.view.proj.to_cols_array_2d(),
            view: g.view.view.to_cols_array_2d(),
            size: [w as f32, h as f32, tw as f32, th as f32],
            radius: s.radius,
            samples: s.samples as f32,
            strength: s.strength,
            scale: scale as f32,
            depth_bias: BIAS * s.radius,
            range: RANGE * s.radius,
            plane_tolerance: PLANE_TOLERANCE * s.radius,
            blur: if s.blur { 1.0 } else { 0.0 },
        };
        let run = |pass: &mut FullscreenPass, u: SsaoUniform, ao: &GpuImage, out: &GpuImage| {
            let binds = [
                Bind::Uniform(bytemuck::bytes_of(&u)),
                Bind::Texture(&g.depth),
                Bind::Texture(&g.normal),
                Bind::Texture(ao),
                Bind::Texture(&g.color),
            ];
            pass.draw(gpu, &binds, &[&out.view], &[out.format])
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

impl Node for SsaoNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let g: Arc<GBuffer> = cx.input("gbuffer")?;
        let image: Option<Arc<GpuImage>> = cx.optional("image");
        if let Some(img) = &image
            && (img.width, img.height) != (g.width(), g.height())
        {
            return Err(NodeError::msg(format!(
                "the image is {}x{} but the G-buffer {}x{}",
                img.width,
                img.height,
                g.width(),
                g.height()
            )));
        }
        let settings = SsaoSettings {
            mode: cx.choice("mode"),
            radius: cx.f32("radius"),
            samples: cx.int("samples").clamp(1, 256) as u32,
            half_resolution: cx.bool("half_resolution"),
            blur: cx.bool("blur"),
            strength: cx.f32("strength"),
        };
        let passes = self.passes.get_or_insert_with(Passes::new);
        let occlusion = Arc::new(passes.occlusion(gpu, &g, &settings)?);
        let product = match image {
            Some(img) => {
                let out = GpuImage::target(gpu, "ssao image", img.width, img.height, gpu.formats().hdr);
                let u = SsaoUniform {
                    proj: g.view.proj.to_cols_array_2d(),
                    view: g.view.view.to_cols_array_2d(),
                    size: [g.width() as f32, g.height() as f32, g.width() as f32, g.height() as f32],
                    radius: settings.radius,
                    samples: settings.samples as f32,
                    strength: settings.strength,
                    scale: 1.0,
                    depth_bias: 0.0,
                    range: 0.0,
                    plane_tolerance: 0.0,
                    blur: 0.0,
                };
                let binds = [
                    Bind::Uniform(bytemuck::bytes_of(&u)),
                    Bind::Texture(&g.depth),
                    Bind::Texture(&g.normal),
                    Bind::Texture(&occlusion),
                    Bind::Texture(&img),
                ];
                passes.apply.draw(gpu, &binds, &[&out.view], &[out.format])?;
                Arc::new(out)
            }
            None => occlusion.clone(),
        };
        cx.set("occlusion", occlusion);
        cx.set("image", product);
        Ok(())
    }
}

//! `IblShading`: the deferred image-based lighting pass of eq. 3.43.

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::gpu::{Bind, FullscreenPass, GpuImage, SamplerKind};
use crate::ibl::gpu::{PEMS_PER_PASS, PemSet, cube_target};
use crate::ibl::pem::TABLE;
use crate::nodes::ibl::shadow_atlas::ShadowAtlas;
use crate::render::scene::GBuffer;

crate::choice!(
    /// What IblShading sums.
    pub enum IblMode {
        /// Eq. 3.43: one lookup per PEM (each to be weighted by its light's visibility).
        Pems = "pems",
        /// One lookup into the filtered full map: eq. 3.43 with every visibility 1.
        Full = "full",
    }
);

crate::choice!(
    /// What shows where nothing was drawn.
    pub enum Background {
        Color = "color",
        Environment = "environment",
    }
);

crate::choice!(
    /// How IblShading reads the cube maps.
    pub enum CubeLookup {
        /// Hardware cube sampling where the backend can (`GpuContext::cube_sampling`), else reference.
        Auto = "auto",
        /// Hardware seamless trilinear filtering (shaders/ibl/ibl_shading_hw.wgsl).
        Hardware = "hardware",
        /// Eight `textureLoad` taps with seams handled in the shader (shaders/ibl/ibl_shading.wgsl):
        /// the twin of the CPU reference, and what GL gets.
        Reference = "reference",
    }
);

pub static IBL_SHADING: NodeSpec = NodeSpec {
    kind: "IblShading",
    category: Category::Lighting,
    doc: "Deferred image-based lighting (eq. 3.43): per pixel, albedo x the sum over regions of VIS_i x PEM_i, each looked up along r' = n(1-g) + r g at the mip level calibrated for glossiness g (s = 1/(1-g), lobe volumes matched); below the chain's handover exponent the lookup is blended, by lobe volume, with the PEM's diffuse end (its cosine-lobe convolution at 16^2: exact Lambertian irradiance, docs/ibl.md). VIS_i = 1 unless a shadow atlas (of the same lights, in the same order) is connected: then, per pixel, the world position from the G-buffer depth, moved along the normal by `normal_offset`, is transformed into light i's tile, the blurred moments (mu, E[d^2]) sampled bilinearly (clamped to the tile, optionally jittered), and VIS_i = 1 for t <= mu, else linstep(bleed_reduction, 1, var / (var + (t - mu)^2)) with var = max(E[d^2] - mu^2, min_variance) and t the receiver's light depth minus depth_bias. Cloth and detail geometry alike; the G-buffer's glossiness (and its parameter maps) drive it.",
    inputs: &[
        PortSpec::required("gbuffer", PortType::GBuffer, "The G-buffer to shade."),
        PortSpec::required("pems", PortType::Pems, "The filtered partial environment maps."),
        PortSpec::optional(
            "shadows",
            PortType::ShadowAtlas,
            "Variance shadow maps of the PEMs' lights (ShadowAtlas): VIS_i by Chebyshev's inequality; unconnected, every VIS_i is 1.",
        ),
    ],
    outputs: &[PortSpec::output("image", PortType::Texture, "Linear HDR radiance.")],
    params: &[
        ParamSpec::new(
            "mode",
            ParamKind::Choice { default: "pems", options: IblMode::OPTIONS },
            "Sum the PEMs (eq. 3.43) or look up the filtered full map once (equal without shadows).",
        ),
        ParamSpec::new(
            "background",
            ParamKind::Choice { default: "environment", options: Background::OPTIONS },
            "What shows where nothing was drawn.",
        ),
        ParamSpec::new(
            "background_color",
            ParamKind::Color { default: [0.05, 0.05, 0.06] },
            "Background colour (background = color).",
        ),
        ParamSpec::new(
            "background_level",
            ParamKind::Float { default: 0.0, min: 0.0, max: 16.0 },
            "Mip level of the environment shown behind the scene (0 sharp; higher blurs it).",
        ),
        ParamSpec::new(
            "cube_lookup",
            ParamKind::Choice { default: "auto", options: CubeLookup::OPTIONS },
            "How the cube maps are read: hardware filtering (fast; auto uses it where the backend can) or the textureLoad reference (the CPU twin's lookups, seams in the shader). Equal within filtering precision.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(IblShadingNode::default()),
};

#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct IblUniform {
    inv_view_proj: [[f32; 4]; 4],
    /// Width, height, unused, 1 on the first pass.
    size: [f32; 4],
    /// The background colour, unused.
    background: [f32; 4],
    background_level: f32,
    top_level: f32,
    unused: f32,
    /// Face size of level 0.
    face_size: f32,
    levels: [f32; 36],
    /// The diffuse end's face size, the handover level and exponent (src/ibl/pem.rs Handover),
    /// unused.
    diffuse: [f32; 4],
}

/// shaders/ibl/ibl_shading.wgsl `Shadow`: the lights of one pass (world to atlas coordinates,
/// their tiles in atlas coordinates inset by half a texel) and the lookup settings.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct ShadowUniform {
    to_atlas: [[[f32; 4]; 4]; PEMS_PER_PASS],
    rect: [[f32; 4]; PEMS_PER_PASS],
    min_variance: f32,
    bleed_reduction: f32,
    /// In texels.
    jitter: f32,
    unused: f32,
    /// Each light's normal offset (world units).
    normal_offset: [f32; PEMS_PER_PASS],
    /// atlas width, height (texels), unused, depth bias.
    bias: [f32; 4],
    eye: [f32; 4],
    forward: [f32; 4],
}

impl ShadowUniform {
    fn new(atlas: Option<&ShadowAtlas>, first: usize, g: &GBuffer) -> ShadowUniform {
        let mut u: ShadowUniform = bytemuck::Zeroable::zeroed();
        let Some(a) = atlas else { return u };
        let (w, h) = (a.atlas.width as f32, a.atlas.height as f32);
        for (k, l) in a.lights.iter().enumerate().skip(first).take(PEMS_PER_PASS) {
            u.to_atlas[k - first] = l.to_atlas.to_cols_array_2d();
            u.rect[k - first] = a.lookup_rect(k);
            u.normal_offset[k - first] = l.normal_offset;
        }
        let p = &a.params;
        (u.min_variance, u.bleed_reduction, u.jitter) = (p.min_variance, p.bleed_reduction, p.jitter);
        u.bias = [w, h, 0.0, p.depth_bias];
        let forward = g.view.inv_view.transform_vector3(glam::Vec3::NEG_Z).normalize();
        u.eye = g.view.eye.extend(1.0).to_array();
        u.forward = forward.extend(0.0).to_array();
        u
    }
}

#[derive(Default)]
struct IblShadingNode {
    /// The pass and whether it samples in hardware (ibl_shading_hw.wgsl).
    pass: Option<(FullscreenPass, bool)>,
    /// Bound in the PEM slots a pass leaves empty.
    empty_cube: Option<GpuImage>,
}

impl Node for IblShadingNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let g: Arc<GBuffer> = cx.input("gbuffer")?;
        let pems: Arc<PemSet> = cx.input("pems")?;
        let mode: IblMode = cx.choice("mode");
        let mut shadows: Option<Arc<ShadowAtlas>> = cx.optional("shadows");
        if let Some(s) = &shadows {
            if mode == IblMode::Full {
                cx.warn("mode full looks up the filtered full map once: the shadow atlas is ignored (use mode pems)");
                shadows = None;
            } else if s.lights.len() != pems.pems.len() {
                return Err(NodeError::msg(format!(
                    "the shadow atlas has {} lights but there are {} PEMs: feed both from the same MedianCut",
                    s.lights.len(),
                    pems.pems.len()
                )));
            }
        }
        let background: Background = cx.choice("background");
        let hardware = match cx.choice::<CubeLookup>("cube_lookup") {
            CubeLookup::Auto => gpu.cube_sampling(),
            CubeLookup::Reference => false,
            CubeLookup::Hardware if gpu.cube_sampling() => true,
            CubeLookup::Hardware => {
                return Err(NodeError::msg(format!(
                    "cube_lookup hardware: {} cannot sample these cube maps through cube views (use auto or reference)",
                    gpu.adapter_name()
                )));
            }
        };
        if self.pass.as_ref().is_none_or(|(_, hw)| *hw != hardware) {
            let shader = if hardware { "ibl_shading_hw.wgsl" } else { "ibl_shading.wgsl" };
            self.pass = Some((FullscreenPass::new(shader), hardware));
        }
        let (pass, _) = self.pass.as_mut().expect("made above");
        if self.empty_cube.is_none() {
            self.empty_cube = Some(cube_target(gpu, "empty cube", 1)?);
        }
        let empty = self.empty_cube.as_ref().expect("made above");

        let mut levels = [0.0f32; 36];
        levels[..TABLE].copy_from_slice(&pems.calibration.levels);
        let top = (pems.full.desc.mips - 1) as f32;
        let handover = pems.calibration.handover();
        let diffuse = handover.map_or([0.0; 4], |h| [pems.full_diffuse.width as f32, h.level, h.exponent, 0.0]);
        let (w, h) = (g.width(), g.height());
        // Each pass's PEMs and their diffuse ends.
        let batches: Vec<(&[GpuImage], &GpuImage)> = match mode {
            IblMode::Full => vec![(&[], &pems.full_diffuse)],
            IblMode::Pems => pems.pems.chunks(PEMS_PER_PASS).zip(&pems.diffuse).collect(),
        };
        let bg = cx.vec3("background_color");
        let mut previous: Option<GpuImage> = None;
        for (i, &(batch, diffuse_ends)) in batches.iter().enumerate() {
            let uniform = IblUniform {
                inv_view_proj: g.view.inv_view_proj.to_cols_array_2d(),
                size: [w as f32, h as f32, 0.0, if i == 0 { 1.0 } else { 0.0 }],
                background: [bg.x, bg.y, bg.z, 0.0],
                background_level: cx.f32("background_level").min(top),
                top_level: top,
                unused: 0.0,
                face_size: pems.full.width as f32,
                levels,
                diffuse,
            };
            let out = GpuImage::target(gpu, "ibl shading", w, h, gpu.formats().hdr);
            let mut binds = vec![
                Bind::Uniform(bytemuck::bytes_of(&uniform)),
                Bind::Texture(&g.color),
                Bind::Texture(&g.normal),
                Bind::Texture(&g.depth),
                Bind::Texture(previous.as_ref().unwrap_or(&g.color)),
            ];
            // Bindings 5..13: the full map, then the pass's PEMs (the empty cube where it has fewer).
            let cubes: Vec<&GpuImage> =
                std::iter::once(&pems.full).chain((0..PEMS_PER_PASS).map(|k| batch.get(k).unwrap_or(empty))).collect();
            let cube_views: Vec<wgpu::TextureView> =
                if hardware { cubes.iter().map(|c| c.cube_view()).collect() } else { Vec::new() };
            binds.extend(cubes.iter().enumerate().map(|(k, c)| match cube_views.get(k) {
                Some(view) => Bind::View(view, wgpu::TextureViewDimension::Cube, c.desc.sample_type(true)),
                None => Bind::Texture(c),
            }));
            let shadow = ShadowUniform::new(shadows.as_deref(), i * PEMS_PER_PASS, &g);
            // Without an atlas the G-buffer's colour stands in for it (never read).
            binds.push(Bind::Texture(shadows.as_ref().map_or(&g.color, |s| &s.atlas)));
            binds.push(Bind::Uniform(bytemuck::bytes_of(&shadow)));
            binds.push(Bind::Sampler(SamplerKind::LinearClamp));
            // The diffuse ends: a cube array for the sampler, or the six-layer-per-PEM array.
            let diffuse_view = hardware.then(|| {
                diffuse_ends.view_of(crate::gpu::texture::ViewSel {
                    dimension: wgpu::TextureViewDimension::CubeArray,
                    base_mip: 0,
                    mips: 1,
                    base_layer: 0,
                    layers: diffuse_ends.desc.layers,
                })
            });
            binds.push(match &diffuse_view {
                Some(view) => {
                    Bind::View(view, wgpu::TextureViewDimension::CubeArray, diffuse_ends.desc.sample_type(true))
                }
                None => Bind::Texture(diffuse_ends),
            });
            let mut switches = vec![
                ("PEMS", batch.len() as u32),
                ("FULL_MAP", u32::from(mode == IblMode::Full)),
                ("BACKGROUND_ENV", u32::from(background == Background::Environment)),
                ("SHADOWS", u32::from(shadows.is_some())),
                ("JITTER", u32::from(shadows.as_ref().is_some_and(|s| s.params.jitter > 0.0))),
                ("DIFFUSE_ENDS", u32::from(handover.is_some())),
            ];
            if !hardware && gpu.counted_levels() {
                switches.push(("COUNTED_LEVELS", 1));
            }
            pass.draw_specialized(gpu, &binds, &[&out.view], &[out.format], &switches)?;
            previous = Some(out);
        }
        cx.set("image", Arc::new(previous.expect("at least one pass")));
        Ok(())
    }
}

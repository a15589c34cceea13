//! `ScreenSpaceReflections`: glossy reflections of what the screen shows, falling back to the
//! environment where a ray leaves the screen or finds nothing (issue 34,
//! shaders/occlusion/ssr.wgsl). IblShading reflects the probe only, so a glossy ball above a
//! lit floor reflects the probe's dark ground; this node swaps in the floor's radiance from
//! the lit image for the part of the lobe that hits it.

use std::sync::Arc;

use super::GatherResolve;
use crate::core::node::prelude::*;
use crate::gpu::{Bind, BufferRing, GpuImage, SamplerKind};
use crate::ibl::gpu::{EnvMap, Lights};
use crate::ibl::shadow::{ShadowAtlas, gpu_lights, vsm_settings};
use crate::render::scene::GBuffer;

pub static SCREEN_SPACE_REFLECTIONS: NodeSpec = NodeSpec {
    kind: "ScreenSpaceReflections",
    category: Category::Lighting,
    doc: "Glossy reflections of the scene in screen space, with the environment where a ray finds nothing (issue 34). IblShading \
reflects only the probe (albedo x sum VIS_i PEM_i along r' = n(1-g) + r g), so a glossy ball above a lit floor shows the probe's dark ground. \
Per pixel of glossiness g above `threshold`, `samples` rays of the GGX lobe as wide as IblShading's Phong lobe cos^s about r' (s = 1/(1-g), \
alpha^2 = 2/(4s + 2), drawn by their visible normals with weights w_k = G2/G1) are marched against \
the G-buffer's depth in 16 steps up to `max_distance` (world units, spaced quadratically) with 4 bisections; a ray that crosses a visible \
surface facing it (by less than `thickness` plus the step's depth) takes that surface's radiance L_k from the lit image. A ray that leaves the \
screen meets the tangent plane of the edge pixel it left through (a floor cut by the screen's edge goes on as a floor) and takes that pixel's \
radiance, with a weight that falls linearly to 0 at `extend` screen heights beyond the screen; hits also fade out over the last fifth of \
`max_distance`. Each ray's weight h_k (1 for on-screen hits) says how much of it hit; the rest escapes, weighed by the environment's radiance \
E_k along it (a texel of its box mip chain at the level of the ray's share of the lobe): out = image x m + albedo x sum w_k h_k L_k / sum w_k, \
m = [sum w_k (1 - h_k) lum(E_k) / sum w_k lum(E_k)] x [GGX lobe's / Phong lobe's environment light], the share of the lobe's environment light \
that still arrives times what the GGX lobe reads of the probe over what IblShading's Phong lobe read (horizon included; 4K environment-only \
directions each). So IblShading's result, shadows and occlusion included, is kept \
for the escaped directions, reshaped to the GGX lobe (unchanged under a uniform probe). The lobe is rotated per pixel with a 4x4 interleaved pattern and the \
result averaged over each 4x4 tile, edge-aware; it fades in over glossiness threshold..threshold + 0.1 (pixels at or below the threshold are \
unchanged). Surfaces hidden from the camera are not reflected (a ray passing behind one goes on); with `ground`, such a ray going down meets a ground plane lit by `lights` through `shadows` (the floor under a glossy object). Deterministic: no time-based noise.",
    inputs: &[
        PortSpec::required("gbuffer", PortType::GBuffer, "The G-buffer (depth, normals, albedo, glossiness in alpha)."),
        PortSpec::required(
            "image",
            PortType::Texture,
            "The lit image (linear radiance, the G-buffer's size): what rays hit, and what the reflections go into.",
        ),
        PortSpec::required(
            "environment",
            PortType::Environment,
            "The environment map IblShading's PEMs come from: weighs the escaped directions.",
        ),
        PortSpec::optional(
            "lights",
            PortType::Lights,
            "With `ground`: the directional lights (MedianCut) that light the hidden ground.",
        ),
        PortSpec::optional(
            "shadows",
            PortType::ShadowAtlas,
            "With `ground`: a ShadowAtlas of `lights` (in their order), their visibility on the hidden ground.",
        ),
    ],
    outputs: &[PortSpec::output("image", PortType::Texture, "The image with screen-space reflections.")],
    params: &[
        ParamSpec::new(
            "samples",
            ParamKind::Int { default: 8, min: 1, max: 64 },
            "Rays per pixel (a 4x4 tile uses 16 times as many directions).",
        ),
        ParamSpec::new(
            "threshold",
            ParamKind::Float { default: 0.3, min: 0.0, max: 1.0 },
            "Glossiness at or below which a pixel is left as it is; reflections fade in over the next 0.1.",
        ),
        ParamSpec::new(
            "max_distance",
            ParamKind::Float { default: 4.0, min: 1e-3, max: 1e4 },
            "How far a ray is marched, world units.",
        ),
        ParamSpec::new(
            "thickness",
            ParamKind::Float { default: 0.3, min: 0.0, max: 1e4 },
            "How far behind the visible surface a ray may cross it and still hit it, world units (plus the step's depth).",
        ),
        ParamSpec::new(
            "ground",
            ParamKind::Bool { default: false },
            "Rays that find nothing on screen and go down meet the plane y = ground_height, lit by `lights` through `shadows`: radiance ground_albedo / pi x sum VIS_i E_i max(0, l_i . y), the floor a glossy object reflects where the camera cannot see it (under the object itself).",
        ),
        ParamSpec::new(
            "ground_height",
            ParamKind::Float { default: 0.0, min: -1e4, max: 1e4 },
            "The ground plane's height (world y).",
        ),
        ParamSpec::new(
            "ground_albedo",
            ParamKind::Color { default: [0.5, 0.5, 0.5] },
            "The ground's albedo (linear RGB), as its material's base colour.",
        ),
        ParamSpec::new(
            "extend",
            ParamKind::Float { default: 4.0, min: 0.0, max: 100.0 },
            "How far beyond the screen the edge pixels' tangent planes reach, in screen heights (0: a ray leaving the screen escapes).",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(SsrNode::default()),
};

/// shaders/occlusion/ssr.wgsl `Ssr`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct SsrUniform {
    proj: [[f32; 4]; 4],
    view: [[f32; 4]; 4],
    size: [f32; 4],
    max_distance: f32,
    thickness: f32,
    samples: f32,
    threshold: f32,
    plane_tolerance: f32,
    /// Pixels.
    extend: f32,
    _pad: [f32; 2],
    /// March steps, bisections, resolve taps.
    loops: [u32; 4],
    /// The ground: rgb its albedo, w its height.
    ground: [f32; 4],
    /// The atlas's min variance, bleed reduction, depth bias (ibl::shadow::vsm_settings).
    vsm: [f32; 4],
}

struct SsrNode {
    passes: Option<GatherResolve>,
    lights: BufferRing,
}

impl Default for SsrNode {
    fn default() -> Self {
        SsrNode { passes: None, lights: BufferRing::new("ssr lights", wgpu::BufferUsages::STORAGE) }
    }
}

impl Node for SsrNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let g: Arc<GBuffer> = cx.input("gbuffer")?;
        let image: Arc<GpuImage> = cx.input("image")?;
        let env: Arc<EnvMap> = cx.input("environment")?;
        let sky: Option<Arc<Lights>> = cx.optional("lights");
        let shadows: Option<Arc<ShadowAtlas>> = cx.optional("shadows");
        let ground = cx.bool("ground");
        super::check_image_size(&image, &g)?;
        let max_distance = cx.f32("max_distance");
        let u = SsrUniform {
            proj: g.view.proj.to_cols_array_2d(),
            view: g.view.view.to_cols_array_2d(),
            size: [g.width() as f32, g.height() as f32, env.cube.width as f32, (env.cube.desc.mips - 1) as f32],
            max_distance,
            thickness: cx.f32("thickness"),
            samples: cx.int("samples").clamp(1, 64) as f32,
            threshold: cx.f32("threshold"),
            // The resolve averages over one surface: points within 5% of the march's reach of
            // the tangent plane.
            plane_tolerance: 0.05 * max_distance,
            extend: cx.f32("extend") * g.height() as f32,
            _pad: [0.0; 2],
            loops: [16, 4, 16, 0],
            ground: cx.vec3("ground_albedo").extend(cx.f32("ground_height")).to_array(),
            vsm: {
                let [a, b, c] = vsm_settings(shadows.as_deref());
                [a, b, c, 0.0]
            },
        };
        let mut lights = match (&sky, ground) {
            (_, false) => Vec::new(),
            (None, true) => {
                return Err(NodeError::msg(
                    "parameter \"ground\" is on but input \"lights\" is not connected: the ground is lit by them",
                ));
            }
            (Some(sky), true) => gpu_lights(&sky.lights, shadows.as_deref(), 0.0, 1.0).map_err(NodeError::msg)?,
        };
        let count = lights.len();
        // A storage binding must not be empty.
        lights.resize(count.max(1), bytemuck::Zeroable::zeroed());
        let light_buffer = self.lights.write(gpu, bytemuck::cast_slice(&lights)).clone();
        let binds = [
            Bind::Texture(&env.cube),
            Bind::Storage(&light_buffer),
            // Unbound: the environment stands in (never read).
            Bind::Texture(shadows.as_ref().map_or(&g.normal, |a| &a.atlas)),
            Bind::Sampler(SamplerKind::LinearClamp),
        ];
        let constants = [("LIGHTS", count as u32), ("COUNTED_LEVELS", u32::from(gpu.counted_levels()))];
        let passes = self.passes.get_or_insert_with(|| GatherResolve::new("ssr.wgsl"));
        let out = passes.run(gpu, "ssr", &g, &image, bytemuck::bytes_of(&u), &binds, &constants)?;
        cx.set("image", Arc::new(out));
        Ok(())
    }
}

//! `BtfShading`: the deferred BTF shading of Sattler et al. 2003 (shaders/btf/btf_shading.wgsl).

use std::sync::Arc;

use crate::btf::gpu::{GpuBtf, shadow_ramp};
use crate::core::node::prelude::*;
use crate::gpu::{Bind, BufferRing, FullscreenPass, GpuImage, SamplerKind};
use crate::ibl::gpu::Lights;
use crate::render::scene::GBuffer;

/// Texels of eq. 6's 1D texture (the paper's 1024).
const RAMP_SIZE: usize = 1024;

pub static BTF_SHADING: NodeSpec = NodeSpec {
    kind: "BtfShading",
    category: Category::Lighting,
    doc: "Deferred BTF shading (Sattler et al. 2003) of the pixels whose material's btf_id equals material_id: view and lights in the tangent frame of the item's UVs (the G-buffer's surface target), the 4 nearest view slots (eq. 5) and per light the 4 nearest light directions (eq. 3) with bilinear ring weights, coefficients blended before one pass over the mean and eigentextures (eqs. 3-4), times exposure (eq. 11). Lights: a directional sun with eq. 6's smooth shadow boundary (alpha and a blurred 1D texture), and the directional lights of a MedianCut (environment light through its median-cut lights, without visibility). The weave tiles `tiling` times per UV unit, turned by `rotation`. Other pixels show `base` (or the background colour).",
    inputs: &[
        PortSpec::required("gbuffer", PortType::GBuffer, "The G-buffer to shade."),
        PortSpec::required("btf", PortType::Btf, "The compressed BTF (Btf)."),
        PortSpec::optional(
            "base",
            PortType::Texture,
            "Linear HDR image for the pixels this node does not shade (DirectLight, IblShading); unconnected: the background colour.",
        ),
        PortSpec::optional(
            "lights",
            PortType::Lights,
            "Directional lights of an environment (MedianCut), each through the BTF; no visibility.",
        ),
    ],
    outputs: &[PortSpec::output("image", PortType::Texture, "Linear HDR radiance.")],
    params: &[
        ParamSpec::new(
            "material_id",
            ParamKind::Int { default: 1, min: 1, max: 65535 },
            "Shades the pixels of materials whose btf_id equals this.",
        ),
        ParamSpec::new(
            "exposure",
            ParamKind::Float { default: 1.0, min: 0.0, max: 1e6 },
            "f of eq. 11: scales the result.",
        ),
        ParamSpec::new(
            "tiling",
            ParamKind::Float { default: 8.0, min: 1e-3, max: 1e5 },
            "Repeats of the BTF tile per UV unit.",
        ),
        ParamSpec::new(
            "rotation",
            ParamKind::Float { default: 0.0, min: -360.0, max: 360.0 },
            "Turns the weave on the surface, degrees from the UV's u axis towards the tile's y axis (up its images, decreasing v).",
        ),
        ParamSpec::new(
            "sun_direction",
            ParamKind::Vec3 { default: [-0.4, -1.0, -0.6] },
            "Direction the sun's light travels.",
        ),
        ParamSpec::new("sun_color", ParamKind::Color { default: [1.0, 0.96, 0.9] }, "Sun colour."),
        ParamSpec::new(
            "sun_intensity",
            ParamKind::Float { default: 3.0, min: 0.0, max: 1e5 },
            "Sun irradiance on a surface facing it (0: no sun).",
        ),
        ParamSpec::new(
            "alpha",
            ParamKind::Float { default: 15.0, min: 0.0, max: 90.0 },
            "Eq. 6's offset in degrees: the sun's boundary sits where the angle between normal and light is 90 - alpha.",
        ),
        ParamSpec::new(
            "shadow_blur",
            ParamKind::Float { default: 64.0, min: 0.0, max: 1024.0 },
            "Blur of eq. 6's 1D texture, in its 1024 texels (0: a hard boundary).",
        ),
        ParamSpec::new(
            "environment_intensity",
            ParamKind::Float { default: 1.0, min: 0.0, max: 1e5 },
            "Scales the lights of the `lights` input.",
        ),
        ParamSpec::new(
            "background",
            ParamKind::Color { default: [0.05, 0.05, 0.06] },
            "Colour of the pixels not shaded here when `base` is unconnected.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(BtfShadingNode::default()),
};

/// shaders/btf/btf_shading.wgsl `Params`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct Params {
    inv_view_proj: [[f32; 4]; 4],
    eye: [f32; 4],
    size: [f32; 4],
    btf: [f32; 4],
    tiling: [f32; 4],
    background: [f32; 4],
    rings: [[f32; 4]; crate::btf::gpu::MAX_RINGS],
}

/// shaders/btf/btf_shading.wgsl `Light`.
#[repr(C)]
#[derive(Clone, Copy, bytemuck::Pod, bytemuck::Zeroable)]
struct GpuLight {
    dir: [f32; 4],
    color: [f32; 4],
}

struct BtfShadingNode {
    pass: FullscreenPass,
    lights: BufferRing,
    /// Eq. 6's texture and the blur it was made with.
    ramp: Option<(f32, GpuImage)>,
}

impl Default for BtfShadingNode {
    fn default() -> Self {
        BtfShadingNode {
            pass: FullscreenPass::new("btf_shading.wgsl"),
            lights: BufferRing::new("btf lights", wgpu::BufferUsages::STORAGE),
            ramp: None,
        }
    }
}

impl Node for BtfShadingNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let g: Arc<GBuffer> = cx.input("gbuffer")?;
        let btf: Arc<GpuBtf> = cx.input("btf")?;
        let base: Option<Arc<GpuImage>> = cx.optional("base");
        let env: Option<Arc<Lights>> = cx.optional("lights");
        let (w, h) = (g.width(), g.height());
        if let Some(b) = &base
            && (b.width, b.height) != (w, h)
        {
            return Err(NodeError::msg(format!(
                "input \"base\" is {}x{}, the G-buffer {w}x{h}: shade the same view",
                b.width, b.height
            )));
        }
        let mut lights = Vec::new();
        let sun = cx.vec3("sun_color") * cx.f32("sun_intensity");
        if sun.max_element() > 0.0 {
            let towards = -cx
                .vec3("sun_direction")
                .try_normalize()
                .ok_or_else(|| NodeError::msg("parameter \"sun_direction\" must not be zero"))?;
            lights.push(GpuLight { dir: towards.extend(1.0).to_array(), color: sun.extend(0.0).to_array() });
        }
        let scale = cx.f32("environment_intensity");
        for l in env.iter().flat_map(|e| &e.lights) {
            lights.push(GpuLight {
                dir: l.direction.extend(0.0).to_array(),
                color: (l.color * scale).extend(0.0).to_array(),
            });
        }
        let count = lights.len();
        // A storage binding must not be empty.
        lights.resize(count.max(1), GpuLight { dir: [0.0; 4], color: [0.0; 4] });
        let blur = cx.f32("shadow_blur");
        if self.ramp.as_ref().is_none_or(|(b, _)| *b != blur) {
            let bits: Vec<u16> =
                shadow_ramp(RAMP_SIZE, blur).iter().map(|&x| half::f16::from_f32(x).to_bits()).collect();
            let image = GpuImage::upload(
                gpu,
                "btf shadow ramp",
                RAMP_SIZE as u32,
                1,
                wgpu::TextureFormat::R16Float,
                2,
                bytemuck::cast_slice(&bits),
            );
            self.ramp = Some((blur, image));
        }
        let (_, ramp) = self.ramp.as_ref().expect("made above");
        let rotation = cx.f32("rotation").to_radians();
        let background = cx.vec3("background");
        let params = Params {
            inv_view_proj: g.view.inv_view_proj.to_cols_array_2d(),
            eye: g.view.eye.extend(1.0).to_array(),
            size: [w as f32, h as f32, count as f32, cx.int("material_id") as f32],
            btf: [
                btf.sampling.len() as f32,
                btf.layers_per_slot() as f32,
                btf.sampling.rings.len() as f32,
                cx.f32("exposure"),
            ],
            tiling: [cx.f32("tiling"), rotation.cos(), rotation.sin(), cx.f32("alpha").to_radians()],
            background: [background.x, background.y, background.z, if base.is_some() { 1.0 } else { 0.0 }],
            rings: btf.rings_uniform(),
        };
        let light_buffer = self.lights.write(gpu, bytemuck::cast_slice(&lights)).clone();
        let out = GpuImage::target(gpu, "btf shading", w, h, gpu.formats().hdr);
        let binds = [
            Bind::Uniform(bytemuck::bytes_of(&params)),
            Bind::Texture(&g.normal),
            Bind::Texture(&g.depth),
            Bind::Texture(&g.surface),
            // Unbound: the normal stands in (never read).
            Bind::Texture(base.as_deref().unwrap_or(&g.normal)),
            Bind::Texture(&btf.images),
            Bind::Sampler(SamplerKind::LinearRepeat),
            Bind::Texture(ramp),
            Bind::Sampler(SamplerKind::LinearClamp),
            Bind::Storage(&btf.coeffs),
            Bind::Storage(&light_buffer),
        ];
        self.pass.draw(gpu, &binds, &[&out.view], &[out.format])?;
        cx.count("lights", count);
        cx.set("image", Arc::new(out));
        Ok(())
    }
}

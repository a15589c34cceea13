//! `Ssao`: local, screen-space ambient occlusion on the G-buffer (the local part of the
//! dissertation's hybrid occlusion, §3.2.2 and §4.2.2; shaders/occlusion/ssao.wgsl).

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::gpu::{Bind, GpuImage};
use crate::occlusion::ssao::{Passes, SsaoMode, SsaoSettings, SsaoUniform};
use crate::render::scene::GBuffer;

pub static SSAO: NodeSpec = NodeSpec {
    kind: "Ssao",
    category: Category::Lighting,
    doc: "Local screen-space ambient occlusion from the G-buffer: the visibility factor v in [0, 1] (1 = unoccluded). \
mode sphere is the dissertation's depth-only SSAO (§4.2.2): `samples` points in a sphere of `radius` (world units) around the pixel's point, \
uniform in radius (so denser toward the centre), each occluded when the G-buffer's depth where it projects is in front of it by more than \
0.02 radius and less than 2 radii (a sample that projects off screen is replaced by its mirror image through the point, with the opposite outcome: \
exact on a plane, so open floor stays 1 up to the screen's borders); v = clamp(2 (1 - occluded fraction), 0, 1), so an open plane gives 1, a 90-degree concave edge 1/2, a corner 1/4, \
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

#[derive(Default)]
struct SsaoNode {
    passes: Option<Passes>,
}

impl Node for SsaoNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let g: Arc<GBuffer> = cx.input("gbuffer")?;
        let image: Option<Arc<GpuImage>> = cx.optional("image");
        if let Some(img) = &image {
            super::check_image_size(img, &g)?;
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
                    unused0: 0.0,
                    strength: settings.strength,
                    scale: 1.0,
                    depth_bias: 0.0,
                    range: 0.0,
                    plane_tolerance: 0.0,
                    unused1: 0.0,
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

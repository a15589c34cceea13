//! Occlusion nodes (src/occlusion/): SSAO, the ray-traced reference, hybrid occlusion, and the
//! screen-space bounce of diffuse light and screen-space reflections.

pub mod bounce;
pub mod hybrid_occlusion;
pub mod reference_occlusion;
pub mod ssao;
pub mod ssr;

use crate::core::node::NodeError;
use crate::gpu::{Bind, FullscreenPass, GpuContext, GpuImage};
use crate::render::scene::GBuffer;

/// The screen-space nodes read an image pixel for pixel with the G-buffer: refuse another size.
pub(crate) fn check_image_size(image: &GpuImage, g: &GBuffer) -> Result<(), NodeError> {
    if (image.width, image.height) == (g.width(), g.height()) {
        return Ok(());
    }
    Err(NodeError::msg(format!(
        "input \"image\" is {}x{} but the G-buffer {}x{}",
        image.width,
        image.height,
        g.width(),
        g.height()
    )))
}

/// The two passes of a screen-space estimate that is dithered per 4x4 tile (Bounce, SSR):
/// `fs_gather` writes the raw estimate from the lit image, `fs_resolve` averages it over each
/// tile, edge-aware, and combines it with the image. Both read the bindings uniform, depth,
/// normal, colour, image, then the gathered estimate (the image itself in the gather, which
/// does not read it), then `extra`.
pub(crate) struct GatherResolve {
    gather: FullscreenPass,
    resolve: FullscreenPass,
}

impl GatherResolve {
    pub(crate) fn new(shader: &'static str) -> GatherResolve {
        GatherResolve {
            gather: FullscreenPass::new(shader).with_fragment_entry("fs_gather"),
            resolve: FullscreenPass::new(shader).with_fragment_entry("fs_resolve"),
        }
    }

    /// Runs both passes at the G-buffer's size, with the shader's `override` constants;
    /// returns the resolved image.
    #[allow(clippy::too_many_arguments)]
    pub(crate) fn run(
        &mut self,
        gpu: &GpuContext,
        label: &'static str,
        g: &GBuffer,
        image: &GpuImage,
        uniform: &[u8],
        extra: &[Bind<'_>],
        constants: &[(&str, u32)],
    ) -> Result<GpuImage, NodeError> {
        let format = gpu.formats().hdr;
        let gathered = GpuImage::target(gpu, label, g.width(), g.height(), format);
        let out = GpuImage::target(gpu, label, g.width(), g.height(), format);
        for (pass, input, target) in [(&mut self.gather, image, &gathered), (&mut self.resolve, &gathered, &out)] {
            let mut binds = vec![
                Bind::Uniform(uniform),
                Bind::Texture(&g.depth),
                Bind::Texture(&g.normal),
                Bind::Texture(&g.color),
                Bind::Texture(image),
                Bind::Texture(input),
            ];
            binds.extend_from_slice(extra);
            pass.draw_specialized(gpu, &binds, &[&target.view], &[format], constants)
                .map_err(|e| NodeError::msg(e.to_string()))?;
        }
        Ok(out)
    }
}

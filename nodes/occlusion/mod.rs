//! Occlusion nodes (src/occlusion/): SSAO, the ray-traced reference, hybrid occlusion, and the
//! screen-space bounce of diffuse light and screen-space reflections.

pub mod bounce;
pub mod hybrid_occlusion;
pub mod reference_occlusion;
pub mod ssao;
pub mod ssr;

use crate::core::node::NodeError;
use crate::gpu::GpuImage;
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

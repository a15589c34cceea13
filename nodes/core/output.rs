//! Output nodes: the roots that evaluation pulls from. `werkstatt render` writes their images.

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::gpu::GpuImage;
use crate::io::image::ImageFormat;

pub static IMAGE_WRITE: NodeSpec = NodeSpec {
    kind: "ImageWrite",
    category: Category::Output,
    doc: "Writes its image each frame as <out>/<node id>_<frame>.png (8-bit) or .exr (float, for HDR intermediates).",
    inputs: &[PortSpec::required("image", PortType::Texture, "The image to write.")],
    outputs: &[PortSpec::output("image", PortType::Texture, "The same image.")],
    params: &[ParamSpec::new(
        "format",
        ParamKind::Choice { default: "png", options: ImageFormat::OPTIONS },
        "File format.",
    )],
    capabilities: Capabilities::OUTPUT,
    create: || Box::new(ImageWriteNode),
};

pub static PREVIEW: NodeSpec = NodeSpec {
    kind: "Preview",
    category: Category::Output,
    doc: "The image the editor's viewport shows; `render` writes it as a PNG too.",
    inputs: &[PortSpec::required("image", PortType::Texture, "The image to show.")],
    outputs: &[PortSpec::output("image", PortType::Texture, "The same image.")],
    params: &[],
    capabilities: Capabilities::OUTPUT.with(Capabilities::PREVIEW),
    create: || Box::new(PreviewNode),
};

struct ImageWriteNode;
impl Node for ImageWriteNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        pass_image(cx, cx.choice("format"))
    }
}

struct PreviewNode;
impl Node for PreviewNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        pass_image(cx, ImageFormat::Png)
    }
}

fn pass_image(cx: &mut EvalCx<'_>, format: ImageFormat) -> Result<(), NodeError> {
    let image: Arc<GpuImage> = cx.input("image")?;
    cx.emit(Product::Image { image: image.clone(), format });
    cx.set("image", image);
    Ok(())
}

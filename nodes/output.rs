//! Output nodes: the roots that evaluation pulls from. `werkstatt render` writes their images.

use crate::eval::{EvalCx, Node, NodeError};
use crate::spec::{Category, NodeSpec, ParamKind, ParamSpec, PortSpec, PortType};
use crate::value::Value;

pub static IMAGE_WRITE: NodeSpec = NodeSpec {
    kind: "ImageWrite",
    category: Category::Output,
    doc: "Writes its image each frame as <out>/<node id>_<frame>.png (8-bit) or .exr (float, for HDR intermediates).",
    inputs: &[PortSpec::required("image", PortType::Texture, "The image to write.")],
    outputs: &[PortSpec::output("image", PortType::Texture, "The same image.")],
    params: &[ParamSpec::new("format", ParamKind::Choice { default: "png", options: &["png", "exr"] }, "File format.")],
    is_output: true,
    create: || Box::new(PassThrough),
};

pub static PREVIEW: NodeSpec = NodeSpec {
    kind: "Preview",
    category: Category::Output,
    doc: "The image the editor's viewport shows; `render` writes it as a PNG too.",
    inputs: &[PortSpec::required("image", PortType::Texture, "The image to show.")],
    outputs: &[PortSpec::output("image", PortType::Texture, "The same image.")],
    params: &[],
    is_output: true,
    create: || Box::new(PassThrough),
};

struct PassThrough;
impl Node for PassThrough {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let image = cx.required("image")?.clone();
        if !matches!(image, Value::Texture(_)) {
            return Err(NodeError::msg("image input is not a texture"));
        }
        cx.set("image", image);
        Ok(())
    }
}

//! `HybridOcclusion`: the dissertation's combination of global and local occlusion (§3.2.2,
//! §4.2.2, Figs. 5.25 and 5.27): the shadowed IBL result (global, directional occlusion from
//! the shadow atlas) modulated once, after all lights, by the local screen-space factor (SSAO).

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::gpu::{FullscreenPass, GpuContext, GpuImage};

pub static HYBRID_OCCLUSION: NodeSpec = NodeSpec {
    kind: "HybridOcclusion",
    category: Category::Lighting,
    doc: "Combines global and local occlusion as the dissertation does (§3.2.2): combined = global x local, the global (shadowed IBL) \
image modulated once, after all lights, by the local factor (Ssao's occlusion output). The parts do not exchange information, so \
occlusion both see is counted twice (over-occlusion, §6.2.2). Also outputs each part alone for side-by-side figures (Figs. 5.25, 5.27).",
    inputs: &[
        PortSpec::required("global", PortType::Texture, "The globally occluded image: IblShading with a shadow atlas."),
        PortSpec::required("local", PortType::Texture, "The local occlusion factor (Ssao occlusion, 1 = unoccluded)."),
        PortSpec::optional("unshadowed", PortType::Texture, "IblShading without shadows, for local_only."),
    ],
    outputs: &[
        PortSpec::output("combined", PortType::Texture, "global x local (global itself when `local` is off)."),
        PortSpec::output("global", PortType::Texture, "The global part alone (the input, passed through)."),
        PortSpec::output(
            "local_only",
            PortType::Texture,
            "unshadowed x local where unshadowed is connected, else the local factor itself.",
        ),
    ],
    params: &[ParamSpec::new(
        "local",
        ParamKind::Bool { default: true },
        "Apply the local factor (off: combined is global, bit for bit).",
    )],
    capabilities: Capabilities::NONE,
    create: || Box::new(HybridOcclusionNode::default()),
};

#[derive(Default)]
struct HybridOcclusionNode {
    pass: Option<FullscreenPass>,
}

/// `image` x `factor` (rgb), a new HDR texture of the image's size.
pub fn modulate(
    gpu: &GpuContext,
    pass: &mut FullscreenPass,
    image: &GpuImage,
    factor: &GpuImage,
) -> anyhow::Result<GpuImage> {
    let out = GpuImage::target(gpu, "hybrid occlusion", image.width, image.height, gpu.formats().hdr);
    pass.run(gpu, &[0u8; 16], &[image, factor], &out)?;
    Ok(out)
}

impl Node for HybridOcclusionNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let global: Arc<GpuImage> = cx.input("global")?;
        let local: Arc<GpuImage> = cx.input("local")?;
        let unshadowed: Option<Arc<GpuImage>> = cx.optional("unshadowed");
        for (name, img) in [("local", Some(&local)), ("unshadowed", unshadowed.as_ref())] {
            if let Some(img) = img
                && (img.width, img.height) != (global.width, global.height)
            {
                return Err(NodeError::msg(format!(
                    "{name} is {}x{} but global {}x{}",
                    img.width, img.height, global.width, global.height
                )));
            }
        }
        let pass = self.pass.get_or_insert_with(|| FullscreenPass::new("hybrid_occlusion.wgsl"));
        let err = |e: anyhow::Error| NodeError::msg(e.to_string());
        let combined = if cx.bool("local") {
            Arc::new(modulate(gpu, pass, &global, &local).map_err(err)?)
        } else {
            global.clone()
        };
        let local_only = match &unshadowed {
            Some(u) => Arc::new(modulate(gpu, pass, u, &local).map_err(err)?),
            None => local.clone(),
        };
        cx.set("combined", combined);
        cx.set("global", global);
        cx.set("local_only", local_only);
        Ok(())
    }
}

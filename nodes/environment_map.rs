//! `EnvironmentMap`: an equirectangular light probe (.hdr, .exr) as a cube map on the GPU.

use std::sync::Arc;

use crate::ibl::cube::EquirectImage;
use crate::ibl::gpu::{CubePasses, EnvMap, cube_target, read_cube_level0};
use crate::ibl::pem::Kernel;
use crate::node::prelude::*;

pub static ENVIRONMENT_MAP: NodeSpec = NodeSpec {
    kind: "EnvironmentMap",
    category: Category::Lighting,
    doc: "Loads an equirectangular light probe (Radiance .hdr or OpenEXR .exr, on a worker thread) and resamples it on the GPU into a cube map with a full mip chain; rotation about +Y and an intensity scale. The map's centre column looks down -Z.",
    inputs: &[],
    outputs: &[
        PortSpec::output(
            "environment",
            PortType::Environment,
            "The cube map (HDR, 2x2-box mip chain) and its level 0 on the CPU.",
        ),
        PortSpec::output(
            "preview",
            PortType::Texture,
            "Level 0 as an equirectangular image (2 size x size), for the viewport.",
        ),
    ],
    params: &[
        ParamSpec::new(
            "path",
            ParamKind::Path { default: "", extensions: &["hdr", "exr"] },
            "The probe, relative to the graph's folder (DWAA/DWAB-compressed EXR is not readable; use .hdr).",
        ),
        ParamSpec::new(
            "size",
            ParamKind::Int { default: 128, min: 4, max: 2048 },
            "Cube face size in texels, a power of two.",
        ),
        ParamSpec::new(
            "rotation",
            ParamKind::Float { default: 0.0, min: -360.0, max: 360.0 },
            "Rotation of the probe about +Y, degrees.",
        ),
        ParamSpec::new("intensity", ParamKind::Float { default: 1.0, min: 0.0, max: 1e6 }, "Radiance scale."),
    ],
    is_output: false,
    create: || Box::new(EnvironmentMapNode::default()),
};

#[derive(Default)]
struct EnvironmentMapNode {
    passes: CubePasses,
}

impl Node for EnvironmentMapNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        if cx.str("path").is_empty() {
            return Err(NodeError::msg("parameter \"path\" is empty: name an .hdr or .exr light probe"));
        }
        let size = cx.int("size");
        if !(size as u64).is_power_of_two() {
            return Err(NodeError::msg(format!("size {size} is not a power of two (the mip chain halves it to 1)")));
        }
        let path = cx.path("path");
        let probe = cx.load(&path, EquirectImage::load)?;
        let cube = cube_target(gpu, "environment map", size as u32);
        self.passes.resample_probe(gpu, &probe, &cube, cx.f32("rotation"), cx.f32("intensity"))?;
        self.passes.filter_chain(gpu, &cube, Kernel::None)?;
        let texels = read_cube_level0(gpu, &cube)?;
        let preview = self.passes.preview(gpu, &cube, 0.0, 1.0)?;
        cx.set("preview", Arc::new(preview.share()));
        cx.set("environment", Arc::new(EnvMap { cube, texels: Arc::new(texels), preview, source: path }));
        Ok(())
    }
}

//! `EnvironmentMap`: an equirectangular light probe (.hdr, .exr) as a cube map on the GPU.

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::ibl::cube::{CubeImage, EquirectImage, cube_from_equirect};
use crate::ibl::gpu::{CubePasses, EnvMap, Footprint, cube_target};
use crate::ibl::pem::Kernel;

pub static ENVIRONMENT_MAP: NodeSpec = NodeSpec {
    kind: "EnvironmentMap",
    category: Category::Lighting,
    doc: "Loads an equirectangular light probe (Radiance .hdr or OpenEXR .exr, on a worker thread), resamples it into a cube map (4x4 bilinear lookups per texel) and builds its full mip chain on the GPU; rotation about +Y and an intensity scale. The map's centre column looks down -Z.",
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
    capabilities: Capabilities::NONE,
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
        // Resampled on the CPU (src/ibl/cube.rs): exact, the same bytes on every backend, and the
        // median cut needs the texels here anyway; the mip chain is filtered on the GPU.
        let texels = cube_from_equirect(&probe, size as usize, cx.f32("rotation"), cx.f32("intensity"));
        // What the GPU stores (half floats), so the median cut and the references see it too.
        let texels = CubeImage { size: texels.size, texels: texels.texels.iter().map(|t| round_half(*t)).collect() };
        let cube = cube_target(gpu, "environment map", size as u32)?;
        self.passes.upload_level0(gpu, &texels, &cube);
        self.passes.filter_chain(gpu, &cube, Kernel::None, &Footprint::whole(cube.width), None)?;
        let preview = self.passes.preview(gpu, &cube, 0.0, 1.0)?;
        cx.set("preview", Arc::new(preview.share()));
        cx.set("environment", Arc::new(EnvMap { cube, texels: Arc::new(texels), preview, source: path }));
        Ok(())
    }
}

/// `v` rounded to half precision per channel (clamped to the half range).
fn round_half(v: glam::Vec4) -> glam::Vec4 {
    glam::Vec4::from_array(v.to_array().map(|c| half::f16::from_f32(c.min(65504.0)).to_f32()))
}

//! `Pems`: one filtered partial environment map per median-cut region.

use std::sync::Arc;

use crate::core::node::prelude::*;
use crate::gpu::GpuImage;
use crate::ibl::gpu::{CubePasses, EnvMap, Footprint, Lights, PEMS_PER_PASS, PemSet, cube_target, diffuse_target};
use crate::ibl::pem::DIFFUSE_SIZE;
use crate::ibl::pem::{Kernel, calibration};

pub static PEMS: NodeSpec = NodeSpec {
    kind: "Pems",
    category: Category::Lighting,
    doc: "Partial environment maps (dissertation 3.2.1): per region, the cube map with the texels outside the region black, filtered into a mip chain with a 5x5 kernel at every level, so a mip level stands for a glossiness (calibrated by lobe volume, docs/ibl.md). Also filters the whole map the same way (what the PEMs sum to).",
    inputs: &[
        PortSpec::required("environment", PortType::Environment, "The cube map."),
        PortSpec::required("lights", PortType::Lights, "The regions (from MedianCut)."),
    ],
    outputs: &[
        PortSpec::output("pems", PortType::Pems, "The filtered PEMs, the filtered full map and the calibration."),
        PortSpec::output("preview", PortType::Texture, "One PEM (or the sum) at one level, equirectangular."),
        PortSpec::output(
            "memory_mb",
            PortType::Scalar,
            "GPU memory of the PEMs in MiB: N x 6 x size^2 x texel bytes x 4/3, plus their diffuse ends (N x 6 x 16^2 x texel bytes).",
        ),
    ],
    params: &[
        ParamSpec::new(
            "kernel",
            ParamKind::Choice { default: "phong", options: Kernel::OPTIONS },
            "How the mip levels are filtered: a 5x5 kernel at every level (none, box, gaussian, cosine, sqrt_cosine: the dissertation chose sqrt_cosine), or phong: each level the map convolved with a Phong lobe (lowest lobe error, docs/ibl.md).",
        ),
        ParamSpec::new(
            "preview_region",
            ParamKind::Int { default: -1, min: -1, max: 4095 },
            "The PEM the preview shows; -1 shows the filtered full map (the sum of all PEMs).",
        ),
        ParamSpec::new(
            "preview_level",
            ParamKind::Float { default: 0.0, min: 0.0, max: 16.0 },
            "The mip level the preview shows.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(PemsNode::default()),
};

#[derive(Default)]
struct PemsNode {
    passes: CubePasses,
}

impl Node for PemsNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let env: Arc<EnvMap> = cx.input("environment")?;
        let lights: Arc<Lights> = cx.input("lights")?;
        let Some(regions) = lights.regions.as_ref() else {
            return Err(NodeError::msg("the lights carry no regions: feed lights from a MedianCut of this map"));
        };
        if regions.size != env.size() {
            return Err(NodeError::msg(format!(
                "the regions were cut on a {0}x{0} cube, the environment is {1}x{1}: use the same EnvironmentMap for both",
                regions.size,
                env.size()
            )));
        }
        let kernel: Kernel = cx.choice("kernel");
        let size = env.cube.width;
        let ids = GpuImage::upload(
            gpu,
            "median cut region ids",
            size,
            6 * size,
            wgpu::TextureFormat::R32Uint,
            4,
            bytemuck::cast_slice(&regions.ids),
        );
        let full = cube_target(gpu, "filtered environment", size)?;
        gpu.record(|enc| {
            enc.copy_texture_to_texture(
                env.cube.texture.as_image_copy(),
                full.texture.as_image_copy(),
                wgpu::Extent3d { width: size, height: size, depth_or_array_layers: 6 },
            )
        });
        let d = size.min(DIFFUSE_SIZE as u32);
        let full_diffuse = diffuse_target(gpu, "diffuse end of the full map", d, 1);
        self.passes.filter_chain(gpu, &full, kernel, &Footprint::whole(size), Some((&full_diffuse, 0)))?;
        let count = regions.lights.len();
        let diffuse: Vec<GpuImage> = (0..count.div_ceil(PEMS_PER_PASS))
            .map(|b| {
                diffuse_target(gpu, "diffuse ends of PEMs", d, (count - b * PEMS_PER_PASS).min(PEMS_PER_PASS) as u32)
            })
            .collect();
        let mut pems = Vec::with_capacity(count);
        for region in 0..count {
            // Hundreds of regions take minutes on a software rasterizer: report and answer a cancel.
            cx.progress(region, regions.lights.len())?;
            let pem = cube_target(gpu, "PEM", size)?;
            self.passes.mask(gpu, &env.cube, &ids, region as u32, &pem)?;
            let footprint = Footprint::of_region(&regions.ids, size as usize, region as u32);
            let slot = (&diffuse[region / PEMS_PER_PASS], (region % PEMS_PER_PASS) as u32);
            self.passes.filter_chain(gpu, &pem, kernel, &footprint, Some(slot))?;
            pems.push(pem);
        }
        let bytes = pem_bytes(&full) * pems.len() as u64 + diffuse.iter().map(array_bytes).sum::<u64>();
        let shown = match usize::try_from(cx.int("preview_region")) {
            Ok(i) => pems.get(i).ok_or_else(|| {
                NodeError::msg(format!("preview_region {i} does not exist: there are {} regions", pems.len()))
            })?,
            Err(_) => &full,
        };
        let preview = self.passes.preview(gpu, shown, cx.f32("preview_level"), 1.0)?;
        cx.set("preview", Arc::new(preview.share()));
        cx.set("memory_mb", bytes as f64 / (1u64 << 20) as f64);
        let calibration = calibration(kernel, size as usize);
        cx.set("pems", Arc::new(PemSet { kernel, pems, full, diffuse, full_diffuse, calibration, preview, bytes }));
        Ok(())
    }
}

/// Bytes of a one-mip texture array's layers (GL's spare layer, see `GpuImage::create`, is
/// not the PEMs').
fn array_bytes(t: &GpuImage) -> u64 {
    let texel = t.format.block_copy_size(None).unwrap_or(8) as u64;
    (t.width as u64).pow(2) * t.desc.layers as u64 * texel
}

/// Bytes of one cube map with its whole mip chain.
fn pem_bytes(cube: &GpuImage) -> u64 {
    let texel = cube.format.block_copy_size(None).unwrap_or(8) as u64;
    (0..cube.desc.mips).map(|m| (cube.width as u64 >> m).max(1).pow(2) * 6 * texel).sum()
}

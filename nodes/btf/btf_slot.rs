//! `BtfSlot`: one view slot of a BTF against its PCA, for the paper's Figs. 6 and 7 (the
//! original image, its reconstruction from c components, the 8-bit error heatmap, and the
//! slot's eigenvalues in stats.json).

use std::sync::Arc;

use crate::btf::directions::Dir;
use crate::btf::gpu::GpuBtf;
use crate::btf::pca::{Centring, compress_slot};
use crate::btf::{error8, exposure8};
use crate::core::node::prelude::*;
use crate::gpu::GpuImage;

pub static BTF_SLOT: NodeSpec = NodeSpec {
    kind: "BtfSlot",
    category: Category::Output,
    doc: "One image of a BTF against its per-view PCA (Sattler et al. 2003, Figs. 6 and 7): the original image of a measured (view, light) pair, its reconstruction from the view slot's mean and `components` eigentextures (eq. 1, centred), and a heatmap of the length of the 8-bit RGB error vector (green 0, red 255 or more). Reports the error's mean, 99th percentile and maximum, and writes the slot's eigenvalues (all, descending) to stats.json under \"values\".",
    inputs: &[PortSpec::required("btf", PortType::Btf, "The BTF (Btf); its uncompressed images are used.")],
    outputs: &[
        PortSpec::output(
            "original",
            PortType::Texture,
            "The original image times exposure / 255 (linear, f16; 1 is 8-bit 255).",
        ),
        PortSpec::output("reconstruction", PortType::Texture, "The reconstruction, scaled like `original`."),
        PortSpec::output(
            "error",
            PortType::Texture,
            "The 8-bit RGB error length per texel: green 0 to red 255 (sRGB).",
        ),
        PortSpec::output("error_mean", PortType::Scalar, "The mean 8-bit RGB error length."),
        PortSpec::output("error_p99", PortType::Scalar, "Its 99th percentile."),
        PortSpec::output("error_max", PortType::Scalar, "Its maximum."),
    ],
    params: &[
        ParamSpec::new(
            "view_theta",
            ParamKind::Float { default: 0.0, min: 0.0, max: 90.0 },
            "The view slot: a measured direction's theta (degrees from the normal).",
        ),
        ParamSpec::new(
            "view_phi",
            ParamKind::Float { default: 0.0, min: 0.0, max: 360.0 },
            "The view slot's phi (degrees from the warp towards the bitangent).",
        ),
        ParamSpec::new(
            "light_theta",
            ParamKind::Float { default: 30.0, min: 0.0, max: 90.0 },
            "The light: a measured direction's theta.",
        ),
        ParamSpec::new("light_phi", ParamKind::Float { default: 60.0, min: 0.0, max: 360.0 }, "The light's phi."),
        ParamSpec::new(
            "components",
            ParamKind::Int { default: 16, min: 0, max: 4096 },
            "c: eigentextures in the reconstruction (0: the mean alone); at most the lights per view.",
        ),
        ParamSpec::new(
            "exposure",
            ParamKind::Float { default: 0.0, min: 0.0, max: 1e9 },
            "8-bit value per unit of the BTF; 0: the BTF's 99.5th percentile maps to 255 (as `werkstatt btf compress`).",
        ),
    ],
    capabilities: Capabilities::OUTPUT,
    create: || Box::new(BtfSlotNode),
};

struct BtfSlotNode;

/// An RGB image as a sampled texture that can be read back (ImageWrite), `format` Rgba16Float
/// (values as f16 bits) or Rgba8UnormSrgb (bytes).
fn image(
    gpu: &crate::gpu::GpuContext,
    label: &str,
    w: usize,
    h: usize,
    format: wgpu::TextureFormat,
    bytes: &[u8],
) -> GpuImage {
    let texel = (bytes.len() / (w * h)) as u32;
    GpuImage::upload(gpu, label, w as u32, h as u32, format, texel, bytes)
}

/// RGB values times `scale` as Rgba16Float bits (alpha 1).
fn rgba16(rgb: &[f32], scale: f64) -> Vec<u16> {
    rgb.chunks_exact(3)
        .flat_map(|p| [p[0], p[1], p[2]].map(|x| (f64::from(x) * scale) as f32).into_iter().chain([1.0]))
        .map(|x| half::f16::from_f32(x).to_bits())
        .collect()
}

/// The paper's error colours: green at 0, red at 255 and above, linear in between (sRGB bytes).
pub fn heatmap(errors: &[f64]) -> Vec<u8> {
    errors
        .iter()
        .flat_map(|&e| {
            let t = (e / 255.0).clamp(0.0, 1.0);
            [(255.0 * t).round() as u8, (255.0 * (1.0 - t)).round() as u8, 0, 255]
        })
        .collect()
}

/// Mean, 99th percentile and maximum.
fn summary(errors: &[f64]) -> (f64, f64, f64) {
    let mut sorted = errors.to_vec();
    sorted.sort_by(f64::total_cmp);
    let mean = sorted.iter().sum::<f64>() / sorted.len().max(1) as f64;
    let p99 = sorted.get((sorted.len() as f64 * 0.99) as usize).or(sorted.last()).copied().unwrap_or(0.0);
    (mean, p99, sorted.last().copied().unwrap_or(0.0))
}

impl Node for BtfSlotNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let gpu_btf: Arc<GpuBtf> = cx.input("btf")?;
        let Some(btf) = &gpu_btf.source else {
            return Err(NodeError::msg(
                "input \"btf\" was read compressed (.btfc): BtfSlot compares against the BTF's images, so its Btf must read the .btf file",
            ));
        };
        let find = |which: &str| {
            let d = Dir { theta: cx.f64(&format!("{which}_theta")), phi: cx.f64(&format!("{which}_phi")) };
            btf.direction_index(d).ok_or_else(|| {
                let rings: Vec<String> =
                    btf.sampling.rings.iter().map(|r| format!("{} deg x {}", r.theta, r.count)).collect();
                NodeError::msg(format!(
                    "parameters \"{which}_theta\" and \"{which}_phi\" ({}, {}) are not a measured direction of the BTF (rings: {}; phi in steps of 360 / count from 0)",
                    d.theta,
                    d.phi,
                    rings.join(", ")
                ))
            })
        };
        let (view, light) = (find("view")?, find("light")?);
        let n = btf.sampling.len();
        let c = cx.int("components") as usize;
        if c > n {
            return Err(NodeError::msg(format!(
                "parameter \"components\" is {c}, but the BTF has {n} light directions per view: a view's PCA has at most {n} components"
            )));
        }
        let exposure = match cx.f64("exposure") {
            0.0 => exposure8(&btf.data),
            e => e,
        };
        let dim = btf.image_len();
        let pca = compress_slot(btf.slot(view), dim, c, Centring::Mean);
        let original = &btf.slot(view)[light * dim..][..dim];
        let rebuilt = pca.reconstruct(light);
        let errors = error8(original, &rebuilt, exposure);
        let (mean, p99, max) = summary(&errors);
        let (w, h) = (btf.width, btf.height);
        let hdr = wgpu::TextureFormat::Rgba16Float;
        let scale = exposure / 255.0;
        let images = [
            ("original", image(gpu, "btf slot original", w, h, hdr, bytemuck::cast_slice(&rgba16(original, scale)))),
            (
                "reconstruction",
                image(gpu, "btf slot reconstruction", w, h, hdr, bytemuck::cast_slice(&rgba16(&rebuilt, scale))),
            ),
            ("error", image(gpu, "btf slot error", w, h, wgpu::TextureFormat::Rgba8UnormSrgb, &heatmap(&errors))),
        ];
        for (name, img) in images {
            cx.set(name, Arc::new(img));
        }
        cx.set("error_mean", mean);
        cx.set("error_p99", p99);
        cx.set("error_max", max);
        for &lambda in &pca.eigenvalues {
            cx.emit(Product::Value(lambda));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_heatmap_runs_from_green_to_red_and_saturates() {
        assert_eq!(
            heatmap(&[0.0, 127.5, 255.0, 400.0]),
            [0, 255, 0, 255, 128, 128, 0, 255, 255, 0, 0, 255, 255, 0, 0, 255]
        );
    }

    #[test]
    fn the_summary_is_mean_p99_and_max() {
        let errors: Vec<f64> = (0..200).map(f64::from).collect();
        assert_eq!(summary(&errors), (99.5, 198.0, 199.0));
    }
}

//! `Btf`: a bidirectional texture function, compressed per view by PCA (eq. 1) and uploaded
//! for `BtfShading` (src/btf/gpu.rs).

use std::sync::Arc;

use crate::btf::Btf;
use crate::btf::directions::Sampling;
use crate::btf::gpu::MAX_COMPONENTS;
use crate::btf::gpu::{Storage, upload};
use crate::btf::pca::{Centring, compress};
use crate::btf::pca_file::PcaFile;
use crate::core::node::prelude::*;

crate::choice!(
    /// Where the BTF comes from.
    pub enum BtfSource {
        /// The project's container file (src/btf/container.rs).
        File = "file",
        /// The analytic Lambertian BTF rho / pi cos(theta_i), optionally striped.
        Lambert = "lambert",
        /// A diagnostic BTF: every (view, light) image one flat colour, distinct per pair, so a
        /// render shows which images the interpolation blends and how much.
        Directions = "directions",
        /// Baked from woven yarn geometry (src/btf/bake.rs) while the node runs: small tiles only.
        Bake = "bake",
    }
);

crate::choice!(
    /// The weave of a baked BTF.
    pub enum BtfWeave {
        Plain = "plain",
        Twill = "twill",
        Satin = "satin",
    }
);

/// The largest tile the node bakes itself (32^2 with 81 directions: 11 s with one ray per texel
/// on two shared cores, four times that with 2x2); larger ones are baked once by
/// `werkstatt btf bake` and read with source = file.
const MAX_BAKE_SIZE: usize = 32;

crate::choice!(
    /// The directions of an analytic BTF.
    pub enum BtfSampling {
        /// Table 1's second sampling, 81 directions up to theta = 75 deg.
        H2 = "h2",
        /// Its rings up to 30 deg, 19 directions (the test tier).
        H2Tests = "h2_tests",
    }
);

pub static BTF: NodeSpec = NodeSpec {
    kind: "Btf",
    category: Category::Scene,
    doc: "A bidirectional texture function (Sattler et al. 2003): for every view and light direction an image of the fabric. Read from a BTF file (on a worker thread; a compressed .btfc skips the PCA) or made analytically (a Lambertian rho/pi cos theta_i, optionally striped; or a diagnostic BTF of flat colours), compressed per view slot by PCA centred on the mean (eq. 1, `components` eigentextures) and uploaded: a 2D texture array of (c + 1) layers per view (mean, eigentextures; f16, or 8-bit with each layer's range: `storage`) and a buffer of coefficients. For BtfShading.",
    inputs: &[],
    outputs: &[PortSpec::output("btf", PortType::Btf, "The compressed BTF on the GPU.")],
    params: &[
        ParamSpec::new(
            "source",
            ParamKind::Choice { default: "lambert", options: BtfSource::OPTIONS },
            "file: the BTF file at `path`; lambert: rho/pi cos theta_i with `albedo` (stripes of `stripe_albedo`); directions: flat colours per (view, light) pair, for checking the interpolation; bake: a `weave` baked from yarn geometry at `resolution` (at most 32) and `sampling`, in `warp_color` and `weft_color`.",
        ),
        ParamSpec::new(
            "path",
            ParamKind::Path { default: "", extensions: &["btf", "btfc"] },
            "The BTF file for source = file, relative to the graph's folder: images (.btf: werkstatt btf bake / lambertian / import), compressed here, or already compressed (.btfc: werkstatt btf compress --out; 8-bit images, loads without the PCA's minutes).",
        ),
        ParamSpec::new(
            "storage",
            ParamKind::Choice { default: "f16", options: BtfStorage::OPTIONS },
            "How the mean and eigentextures sit in GPU memory: f16 (RGBA half floats), or 8bit (RGBA8 with each layer's range per channel, as the .btfc file stores them: half the memory, e.g. 482 instead of 963 MiB for the 256² tier with c = 16).",
        ),
        ParamSpec::new(
            "components",
            ParamKind::Int { default: 16, min: 1, max: MAX_COMPONENTS as i64 },
            "Eigentextures kept per view slot (c, eq. 1), besides the mean; at most the lights per view. A slot of lower rank keeps fewer.",
        ),
        ParamSpec::new(
            "sampling",
            ParamKind::Choice { default: "h2", options: BtfSampling::OPTIONS },
            "Directions of an analytic BTF: h2 (81, up to 75 deg) or h2_tests (19, up to 30 deg).",
        ),
        ParamSpec::new(
            "resolution",
            ParamKind::Int { default: 16, min: 1, max: 1024 },
            "Image size of an analytic BTF (texels per side of the tile).",
        ),
        ParamSpec::new("albedo", ParamKind::Color { default: [0.8, 0.8, 0.8] }, "Lambert: rho, linear RGB."),
        ParamSpec::new(
            "stripes",
            ParamKind::Int { default: 0, min: 0, max: 512 },
            "Lambert: pairs of stripes along the tile's u (x) axis, the second of each pair in `stripe_albedo`; 0: uniform.",
        ),
        ParamSpec::new("stripe_albedo", ParamKind::Color { default: [0.2, 0.2, 0.6] }, "Lambert: the stripes' rho."),
        ParamSpec::new(
            "weave",
            ParamKind::Choice { default: "plain", options: BtfWeave::OPTIONS },
            "Bake: plain, 2/1 twill or 5-satin (one repeat per tile).",
        ),
        ParamSpec::new("supersample", ParamKind::Int { default: 2, min: 1, max: 4 }, "Bake: n x n rays per texel."),
        ParamSpec::new(
            "warp_color",
            ParamKind::Color { default: crate::btf::bake::WARP_COLOUR },
            "Bake: the warps' albedo, linear RGB (as WovenCloth's warp_color, to shade its panel).",
        ),
        ParamSpec::new(
            "weft_color",
            ParamKind::Color { default: crate::btf::bake::WEFT_COLOUR },
            "Bake: the wefts' albedo, linear RGB.",
        ),
        ParamSpec::new(
            "frontal",
            ParamKind::Bool { default: false },
            "Replace the BTF by the plain texture of its frontal view (the paper's comparison in Figs. 2 and 13): every image the frontal view and light's, times cos theta_i; no parallax, self-shadowing or highlights.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(BtfNode),
};

struct BtfNode;

impl Node for BtfNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let gpu = cx.gpu()?;
        let loaded = match cx.choice::<BtfSource>("source") {
            BtfSource::File => {
                if cx.str("path").is_empty() {
                    return Err(NodeError::msg(
                        "source = \"file\" but parameter \"path\" is empty: name a .btf or .btfc file",
                    ));
                }
                let path = cx.path("path");
                cx.load(&path, load_btf_file).map_err(|e| match e {
                    NodeError::Failed(m) => NodeError::msg(format!("parameter \"path\": {m}")),
                    other => other,
                })?
            }
            source => {
                let sampling = match cx.choice::<BtfSampling>("sampling") {
                    BtfSampling::H2 => Sampling::h2(),
                    BtfSampling::H2Tests => Sampling::h2_tests(),
                };
                let size = cx.int("resolution") as usize;
                Arc::new(LoadedBtf::Images(Arc::new(match source {
                    BtfSource::Directions => directions_btf(sampling, size),
                    BtfSource::Bake => bake(cx, sampling, size)?,
                    _ => {
                        let (a, b, stripes) = (cx.vec3("albedo"), cx.vec3("stripe_albedo"), cx.int("stripes") as usize);
                        Btf::lambertian(sampling, size, size, |x, _| {
                            let striped = stripes > 0 && !(x * 2 * stripes / size).is_multiple_of(2);
                            if striped { b.to_array() } else { a.to_array() }
                        })
                    }
                })))
            }
        };
        let frontal = |e: anyhow::Error| NodeError::msg(format!("parameter \"frontal\": {e:#}"));
        let components = cx.int("components") as usize;
        let lights = match &*loaded {
            LoadedBtf::Images(btf) => btf.sampling.len(),
            LoadedBtf::Compressed(file) => file.sampling.len(),
        };
        if components > lights {
            return Err(NodeError::msg(format!(
                "parameter \"components\" is {components}, but the BTF has {lights} light directions per view: a view's PCA has at most {lights} components"
            )));
        }
        let storage = match cx.choice::<BtfStorage>("storage") {
            BtfStorage::Half => Storage::Half,
            BtfStorage::Unorm8 => Storage::Unorm8,
        };
        let gpu_btf = match &*loaded {
            LoadedBtf::Images(btf) if cx.bool("frontal") => {
                // Kept as BtfSlot's source; its PCA in closed form (rank one).
                let frontal_btf = Arc::new(btf.frontal().map_err(frontal)?);
                let pca = crate::btf::pca::lambertian(&btf.sampling, &btf.data[..btf.image_len()]);
                upload(gpu, &pca, &btf.sampling, (btf.width, btf.height), Some(frontal_btf), components, storage)
            }
            LoadedBtf::Images(btf) => {
                let pca = compress(btf, components, Centring::Mean);
                upload(gpu, &pca, &btf.sampling, (btf.width, btf.height), Some(btf.clone()), components, storage)
            }
            LoadedBtf::Compressed(file) if cx.bool("frontal") => {
                // The frontal image decoded, lit by cos(theta_i) alone: a rank-one PCA.
                crate::btf::check_frontal(&file.sampling).map_err(frontal)?;
                let slot = file.compressed.slots.first().ok_or_else(|| NodeError::msg("the compressed BTF has no view slot"))?;
                let pca = crate::btf::pca::lambertian(&file.sampling, &slot.reconstruct(0));
                upload(gpu, &pca, &file.sampling, (file.width, file.height), None, components, storage)
            }
            LoadedBtf::Compressed(file) => {
                if file.compressed.centring != Centring::Mean {
                    return Err(NodeError::msg(
                        "parameter \"path\": the compressed BTF is not centred on its mean (compressed with --no-centre); BtfShading draws centred ones: compress it again without --no-centre",
                    ));
                }
                upload(gpu, &file.compressed, &file.sampling, (file.width, file.height), None, components, storage)
            }
        }
        .map_err(|e| NodeError::msg(format!("uploading the BTF: {e:#}")))?;
        cx.count("btf_bytes", gpu_btf.bytes as usize);
        cx.set("btf", Arc::new(gpu_btf));
        Ok(())
    }
}

crate::choice!(
    enum BtfStorage {
        Half = "f16",
        Unorm8 = "8bit",
    }
);

/// A BTF file as read: its images, or their PCA (`.btfc`).
enum LoadedBtf {
    Images(Arc<Btf>),
    Compressed(Arc<PcaFile>),
}

/// Reads either kind of BTF file, told apart by the format in its header.
fn load_btf_file(path: &std::path::Path) -> anyhow::Result<LoadedBtf> {
    let mut head = [0u8; 64];
    let read = std::io::Read::read(
        &mut std::fs::File::open(path).map_err(|e| anyhow::anyhow!("cannot open {}: {e}", path.display()))?,
        &mut head,
    )?;
    Ok(if crate::btf::pca_file::is_compressed(&head[..read]) {
        LoadedBtf::Compressed(Arc::new(crate::btf::pca_file::load(path)?))
    } else {
        LoadedBtf::Images(Arc::new(crate::btf::container::load(path)?))
    })
}

/// Bakes the `weave` at `size` texels on `sampling` with all cores (the bytes do not depend
/// on the thread count).
fn bake(cx: &EvalCx<'_>, sampling: Sampling, size: usize) -> Result<Btf, NodeError> {
    use crate::btf::bake::{BakeParams, Pattern, Tier};
    if size > MAX_BAKE_SIZE {
        return Err(NodeError::msg(format!(
            "parameter \"resolution\" is {size}: the node bakes tiles of at most {MAX_BAKE_SIZE} texels; bake larger ones once with `werkstatt btf bake` and read them with source = \"file\""
        )));
    }
    let pattern = match cx.choice::<BtfWeave>("weave") {
        BtfWeave::Plain => Pattern::Plain,
        BtfWeave::Twill => Pattern::Twill,
        BtfWeave::Satin => Pattern::Satin,
    };
    let params = BakeParams {
        size,
        sampling,
        supersample: cx.int("supersample") as usize,
        warp_colour: cx.vec3("warp_color").to_array(),
        weft_colour: cx.vec3("weft_color").to_array(),
        ..BakeParams::tier(pattern, Tier::Test)
    };
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    crate::btf::bake::bake(&params, threads).map_err(|e| NodeError::msg(format!("baking the BTF: {e:#}")))
}

/// The diagnostic BTF: image (view j, light i) is one flat colour from a hash of (j, i), each
/// channel in [0.1, 0.9].
pub fn directions_btf(sampling: Sampling, size: usize) -> Btf {
    let n = sampling.len();
    let mut data = Vec::with_capacity(n * n * size * size * 3);
    for j in 0..n {
        for i in 0..n {
            let colour = directions_colour(j, i);
            for _ in 0..size * size {
                data.extend_from_slice(&colour);
            }
        }
    }
    Btf { width: size, height: size, sampling, data }
}

/// The flat colour of image (view `j`, light `i`) of [`directions_btf`].
pub fn directions_colour(j: usize, i: usize) -> [f32; 3] {
    let mut h = (j as u64).wrapping_mul(0x9e37_79b9_7f4a_7c15) ^ (i as u64).wrapping_mul(0xc2b2_ae3d_27d4_eb4f);
    std::array::from_fn(|_| {
        h ^= h >> 29;
        h = h.wrapping_mul(0xbf58_476d_1ce4_e5b9);
        h ^= h >> 32;
        0.1 + 0.8 * (h >> 40) as f32 / (1u64 << 24) as f32
    })
}

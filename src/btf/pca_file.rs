//! The compressed BTF file (`.btfc`): per view slot its PCA (eq. 1) stored as the paper stores
//! it, 8 bits per channel for the mean and eigentextures, so that the 256² tier of 81 x 81
//! directions with c = 16 takes 258.7 MiB (the paper: 1230 MB -> 260 MB). Loading it skips the
//! decomposition, which takes minutes for the larger tiers.
//!
//! One line of JSON (the header), then per view slot, in the sampling's order, little-endian:
//! - its n eigenvalues (f64), all of them, descending;
//! - its coefficients p_ik (f32), n rows (lights) of `kept[j]` components;
//! - per stored image (the mean unless `centring` is "none", then the kept eigentextures) and
//!   channel an offset and a step (f32 each): the value of byte q is `offset + step * q`;
//! - the stored images' bytes, `height x width x 3` each, rows top to bottom.
//!
//! Each image channel is quantised over its own range (min to max in 255 steps), so a value is
//! off by at most half a step. Loading checks the format, version, sizes, directions, lengths
//! and finiteness and names the file and slot in its errors.

use std::path::Path;

use anyhow::{Context, bail, ensure};
use serde::{Deserialize, Serialize};

use super::container::{check_header, header_line, sampling_from_rings};
use super::directions::Sampling;
use super::pca::{Centring, Compressed, SlotPca};

/// The `format` field of every header.
pub const FORMAT: &str = "werkstatt-btf-pca";
/// The version this build writes and reads.
pub const VERSION: u32 = 1;

#[derive(Serialize, Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct Header {
    format: String,
    version: u32,
    width: u32,
    height: u32,
    channels: u32,
    /// The c the file was compressed with (a low-rank slot keeps fewer: `kept`).
    components: usize,
    /// "mean" or "none".
    centring: String,
    /// "u8-affine": see the module's documentation.
    images: String,
    rings: Vec<(f64, usize)>,
    /// Components kept per view slot.
    kept: Vec<usize>,
}

/// A compressed BTF with its geometry, as read from a file.
#[derive(Debug)]
pub struct PcaFile {
    pub width: usize,
    pub height: usize,
    pub sampling: Sampling,
    pub compressed: Compressed,
}

/// One image quantised to 8 bits per channel: per channel (offset, step), and the bytes.
struct Quantised {
    ranges: [(f32, f32); 3],
    bytes: Vec<u8>,
}

/// The range of channel `c` of `values` interleaved in `channels`: (its minimum, max - min);
/// (0, 0) when empty. With [`to_byte`] the 8-bit quantisation of the file and of the GPU's
/// 8-bit layers (src/btf/gpu.rs).
pub(crate) fn channel_range(values: &[f32], channels: usize, c: usize) -> (f32, f32) {
    let (lo, hi) =
        values.iter().skip(c).step_by(channels).fold((f32::MAX, f32::MIN), |(lo, hi), &x| (lo.min(x), hi.max(x)));
    if lo <= hi { (lo, hi - lo) } else { (0.0, 0.0) }
}

/// `x` as the byte nearest to it over the range (offset, span) in 255 steps.
pub(crate) fn to_byte(x: f32, (offset, span): (f32, f32)) -> u8 {
    if span > 0.0 { ((x - offset) / span * 255.0).round().clamp(0.0, 255.0) as u8 } else { 0 }
}

fn quantise(image: &[f32]) -> Quantised {
    let spans = [0, 1, 2].map(|c| channel_range(image, 3, c));
    let bytes = image.iter().enumerate().map(|(t, &x)| to_byte(x, spans[t % 3])).collect();
    Quantised { ranges: spans.map(|(offset, span)| (offset, span / 255.0)), bytes }
}

fn dequantise(ranges: &[(f32, f32); 3], bytes: &[u8]) -> Vec<f32> {
    bytes.iter().enumerate().map(|(t, &q)| ranges[t % 3].0 + ranges[t % 3].1 * q as f32).collect()
}

/// The images a slot stores: its mean (unless uncentred), then its kept eigentextures.
fn stored_images(slot: &SlotPca) -> impl Iterator<Item = &[f32]> {
    (!slot.mean.is_empty())
        .then_some(slot.mean.as_slice())
        .into_iter()
        .chain((0..slot.components()).map(|k| slot.eigentexture(k)))
}

impl Compressed {
    /// The same PCA with its images as a compressed file holds them (8 bits per channel):
    /// what [`save`] then [`load`] give back, for measuring the quantisation's error.
    pub fn quantised(&self) -> Compressed {
        let slots = self
            .slots
            .iter()
            .map(|slot| {
                let mut images = stored_images(slot).map(|image| {
                    let q = quantise(image);
                    dequantise(&q.ranges, &q.bytes)
                });
                let mean = if slot.mean.is_empty() { Vec::new() } else { images.next().expect("the mean") };
                SlotPca { mean, basis: images.flatten().collect(), ..slot.clone() }
            })
            .collect();
        Compressed { slots, ..self.clone() }
    }
}

/// The exact size in bytes of the file [`save`] writes for `pca`, without its header line.
pub fn data_bytes(pca: &Compressed) -> usize {
    let n = pca.slots.len();
    pca.slots.iter().map(|s| slot_bytes(n, s.components(), s.dim, !s.mean.is_empty())).sum()
}

/// The bytes of one view slot in the file: n eigenvalues, n x `kept` coefficients, and per
/// stored image (the mean where `centred`, the kept eigentextures) its ranges and `dim` bytes.
pub fn slot_bytes(n: usize, kept: usize, dim: usize, centred: bool) -> usize {
    8 * n + 4 * n * kept + (kept + usize::from(centred)) * (24 + dim)
}

/// Writes `pca`, the per-view PCA of a `width x height` BTF on `sampling`, to `path`.
pub fn save(pca: &Compressed, sampling: &Sampling, width: usize, height: usize, path: &Path) -> anyhow::Result<()> {
    let n = sampling.len();
    ensure!(pca.slots.len() == n, "{} slots for the sampling's {n} views", pca.slots.len());
    let header = Header {
        format: FORMAT.into(),
        version: VERSION,
        width: width as u32,
        height: height as u32,
        channels: 3,
        components: pca.components,
        centring: match pca.centring {
            Centring::Mean => "mean",
            Centring::None => "none",
        }
        .into(),
        images: "u8-affine".into(),
        rings: sampling.rings.iter().map(|r| (r.theta, r.count)).collect(),
        kept: pca.slots.iter().map(SlotPca::components).collect(),
    };
    let mut out = serde_json::to_vec(&header)?;
    out.push(b'\n');
    out.reserve(data_bytes(pca));
    for (j, slot) in pca.slots.iter().enumerate() {
        ensure!(
            slot.dim == width * height * 3,
            "slot {j} holds images of {} values, not {}",
            slot.dim,
            width * height * 3
        );
        ensure!(slot.eigenvalues.len() == n, "slot {j} has {} eigenvalues, not {n}", slot.eigenvalues.len());
        out.extend(slot.eigenvalues.iter().flat_map(|x| x.to_le_bytes()));
        out.extend(slot.coeffs.iter().flat_map(|x| x.to_le_bytes()));
        let quantised: Vec<Quantised> = stored_images(slot).map(quantise).collect();
        out.extend(
            quantised.iter().flat_map(|q| q.ranges).flat_map(|(o, s)| [o.to_le_bytes(), s.to_le_bytes()]).flatten(),
        );
        out.extend(quantised.iter().flat_map(|q| &q.bytes));
    }
    crate::io::atomic::write_atomic(path, &out)
        .with_context(|| format!("writing the compressed BTF {}", path.display()))
}

/// Whether `bytes` start like a compressed BTF file (its format name in the header line), so
/// that one `path` parameter can take either kind of file.
pub fn is_compressed(bytes: &[u8]) -> bool {
    let head = &bytes[..bytes.len().min(64)];
    head.windows(FORMAT.len() + 2).any(|w| w == format!("\"{FORMAT}\"").as_bytes())
}

/// Reads a compressed BTF written by [`save`].
pub fn load(path: &Path) -> anyhow::Result<PcaFile> {
    let bytes = std::fs::read(path).with_context(|| format!("reading the compressed BTF {}", path.display()))?;
    parse(&bytes).with_context(|| format!("{} is not a usable compressed BTF file", path.display()))
}

/// A little-endian reader that names what it ran out reading.
struct Reader<'a> {
    data: &'a [u8],
    at: usize,
}

impl Reader<'_> {
    fn take(&mut self, len: usize, what: &dyn Fn() -> String) -> anyhow::Result<&[u8]> {
        ensure!(
            self.data.len() - self.at >= len,
            "truncated: {} needs {len} bytes, {} are left",
            what(),
            self.data.len() - self.at
        );
        self.at += len;
        Ok(&self.data[self.at - len..self.at])
    }
}

fn parse(bytes: &[u8]) -> anyhow::Result<PcaFile> {
    let (line, data) = header_line(bytes)?;
    let header: Header = serde_json::from_slice(line).context("the header is not valid")?;
    check_header((&header.format, FORMAT), (header.version, VERSION), header.channels, (header.width, header.height))?;
    ensure!(header.images == "u8-affine", "images {:?} (only \"u8-affine\" is read)", header.images);
    let centring = match header.centring.as_str() {
        "mean" => Centring::Mean,
        "none" => Centring::None,
        other => bail!("centring {other:?} (\"mean\" or \"none\")"),
    };
    let sampling = sampling_from_rings(&header.rings)?;
    let n = sampling.len();
    ensure!(header.kept.len() == n, "{} slots in \"kept\" for the rings' {n} views", header.kept.len());
    let dim = header.width as usize * header.height as usize * 3;
    let mut reader = Reader { data, at: 0 };
    let mut slots = Vec::with_capacity(n);
    for (j, &kept) in header.kept.iter().enumerate() {
        let dir = sampling.directions()[j];
        let slot_name = || format!("view slot {j} (theta {}, phi {})", dir.theta, dir.phi);
        ensure!(kept <= n, "{} keeps {kept} components of {n}", slot_name());
        let floats = |r: &mut Reader, count: usize, size: usize, what: &str| -> anyhow::Result<Vec<f64>> {
            let raw = r.take(count * size, &|| format!("{} {what}", slot_name()))?;
            let values: Vec<f64> = if size == 8 {
                raw.chunks_exact(8).map(|b| f64::from_le_bytes(b.try_into().expect("8 bytes"))).collect()
            } else {
                raw.chunks_exact(4).map(|b| f32::from_le_bytes(b.try_into().expect("4 bytes")) as f64).collect()
            };
            if let Some(k) = values.iter().position(|x| !x.is_finite()) {
                bail!("{} {what}: value {k} is {}", slot_name(), values[k]);
            }
            Ok(values)
        };
        let eigenvalues = floats(&mut reader, n, 8, "eigenvalues")?;
        let coeffs = floats(&mut reader, n * kept, 4, "coefficients")?;
        let images = kept + usize::from(centring == Centring::Mean);
        let ranges = floats(&mut reader, images * 6, 4, "ranges")?;
        let raw = reader.take(images * dim, &|| format!("{} images", slot_name()))?;
        let mut decoded = raw.chunks_exact(dim).enumerate().map(|(i, bytes)| {
            let r = &ranges[i * 6..][..6];
            dequantise(&[(r[0] as f32, r[1] as f32), (r[2] as f32, r[3] as f32), (r[4] as f32, r[5] as f32)], bytes)
        });
        let mean = if centring == Centring::Mean { decoded.next().expect("the mean") } else { Vec::new() };
        slots.push(SlotPca {
            dim,
            mean,
            basis: decoded.flatten().collect(),
            coeffs: coeffs.into_iter().map(|x| x as f32).collect(),
            eigenvalues,
        });
    }
    ensure!(reader.at == data.len(), "{} bytes after the last view slot", data.len() - reader.at);
    Ok(PcaFile {
        width: header.width as usize,
        height: header.height as usize,
        sampling,
        compressed: Compressed { components: header.components, centring, slots },
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::btf::Btf;
    use crate::btf::pca::compress;

    fn sample() -> (Btf, Compressed) {
        // Pseudo-random images: every slot keeps all 4 components.
        let sampling = Sampling::h2_tests();
        let (w, h) = (5, 3);
        let len = sampling.len() * sampling.len() * w * h * 3;
        let data = (0..len).map(|i| ((i as u64 * 2654435761) % 1000) as f32 / 500.0).collect();
        let btf = Btf { width: w, height: h, sampling, data };
        let pca = compress(&btf, 4, Centring::Mean);
        (btf, pca)
    }

    fn dir() -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("werkstatt-btf-pca-file-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_saved_pca_loads_back_within_half_a_quantisation_step() {
        let (btf, pca) = sample();
        let path = dir().join("roundtrip.btfc");
        save(&pca, &btf.sampling, btf.width, btf.height, &path).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        assert!(is_compressed(&bytes));
        let header_len = bytes.iter().position(|&b| b == b'\n').unwrap() + 1;
        assert_eq!(bytes.len() - header_len, data_bytes(&pca));
        let back = load(&path).unwrap();
        assert_eq!((back.width, back.height, &back.sampling), (btf.width, btf.height, &btf.sampling));
        assert_eq!(back.compressed, pca.quantised(), "load gives what `quantised` predicts");
        for (a, b) in back.compressed.slots.iter().zip(&pca.slots) {
            assert_eq!((&a.coeffs, &a.eigenvalues), (&b.coeffs, &b.eigenvalues));
            for (qa, qb) in stored_images(a).zip(stored_images(b)) {
                for c in 0..3 {
                    let channel = |i: &[f32]| i.iter().skip(c).step_by(3).copied().collect::<Vec<f32>>();
                    let (x, y) = (channel(qa), channel(qb));
                    let range = y.iter().fold(f32::MIN, |m, &v| m.max(v)) - y.iter().fold(f32::MAX, |m, &v| m.min(v));
                    let worst = x.iter().zip(&y).map(|(p, q)| (p - q).abs()).fold(0.0f32, f32::max);
                    assert!(worst <= range / 510.0 * 1.001 + 1e-7, "error {worst} over half a step of {range} / 255");
                }
            }
        }
        // An 8-bit BTF (the paper's 1230 MB) against its 8-bit PCA: the 256² tier of 81 x 81
        // directions at c = 16 fits the paper's 260 MB.
        let slot = slot_bytes(81, 16, 256 * 256 * 3, true);
        assert!(((81 * slot) as f64 / (1 << 20) as f64) < 260.0);
        let images = dir().join("roundtrip.btf");
        crate::btf::container::save(&btf, &images).unwrap();
        assert!(!is_compressed(&std::fs::read(images).unwrap()));
    }

    #[test]
    fn damaged_compressed_files_give_errors_that_name_the_file_and_slot() {
        let (btf, pca) = sample();
        let d = dir();
        let good = d.join("good.btfc");
        save(&pca, &btf.sampling, btf.width, btf.height, &good).unwrap();
        let bytes = std::fs::read(&good).unwrap();
        let end = bytes.iter().position(|&b| b == b'\n').unwrap();
        let header = std::str::from_utf8(&bytes[..end]).unwrap().to_string();
        let with_header = |h: String| [h.as_bytes(), &bytes[end..]].concat();
        let mut nan = bytes.clone();
        nan[end + 1..end + 9].copy_from_slice(&f64::NAN.to_le_bytes());
        let cases: Vec<(&str, Vec<u8>, &str)> = vec![
            ("truncated.btfc", bytes[..bytes.len() - 5].to_vec(), "truncated: view slot 18"),
            ("trailing.btfc", [bytes.as_slice(), &[1]].concat(), "1 bytes after the last view slot"),
            ("empty.btfc", Vec::new(), "no header"),
            ("version.btfc", with_header(header.replace("\"version\":1", "\"version\":2")), "version 2"),
            ("centring.btfc", with_header(header.replace("\"mean\"", "\"median\"")), "centring \"median\""),
            ("kept.btfc", with_header(header.replace("\"kept\":[", "\"kept\":[1,")), "20 slots in \"kept\""),
            ("nan.btfc", nan, "view slot 0 (theta 0, phi 0) eigenvalues: value 0 is NaN"),
        ];
        for (name, b, want) in cases {
            let path = d.join(name);
            std::fs::write(&path, &b).unwrap();
            let msg = format!("{:#}", load(&path).expect_err("a damaged file must not load"));
            assert!(msg.contains(name) && msg.contains(want), "{name}: {msg:?} should name the file and say {want:?}");
        }
    }
}

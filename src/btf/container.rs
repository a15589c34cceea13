//! The project's BTF file: one line of JSON (the header), then the images as raw little-endian
//! f16 blocks, one block per (view, light) pair, view-major in the header's order, each block
//! `height x width x channels` values, rows top to bottom, texels left to right.
//!
//! Loading checks everything a damaged or foreign file can get wrong and names the file in the
//! error: the format name and version, the header's fields, directions missing from (or
//! repeated in) the named sampling, the data length (truncated or trailing bytes) and NaN or
//! infinite values.

use std::path::Path;

use anyhow::{Context, bail, ensure};
use serde::{Deserialize, Serialize};

use super::Btf;
use super::directions::{Dir, Sampling};

/// The `format` field of every header.
pub const FORMAT: &str = "werkstatt-btf";
/// The version this build writes and reads.
pub const VERSION: u32 = 1;
/// The longest header line read before giving up (a foreign binary file has no newline early).
const MAX_HEADER: usize = 1 << 20;

#[derive(Serialize, Deserialize, Debug)]
#[serde(deny_unknown_fields)]
struct Header {
    format: String,
    version: u32,
    width: u32,
    height: u32,
    channels: u32,
    encoding: String,
    /// The rings of the sampling that views and lights both use: `[theta_deg, count]`.
    rings: Vec<(f64, usize)>,
    /// The view and light directions, `[theta_deg, phi_deg]`, in block order.
    views: Vec<(f64, f64)>,
    lights: Vec<(f64, f64)>,
}

/// Writes `btf` to `path`.
pub fn save(btf: &Btf, path: &Path) -> anyhow::Result<()> {
    let mut w = Writer::create(path, btf.width, btf.height, &btf.sampling)?;
    for view in 0..btf.sampling.len() {
        w.write_view(btf.slot(view))?;
    }
    w.finish()
}

/// A BTF file written one view slot at a time, so that a bake need not hold every image.
pub struct Writer {
    file: std::io::BufWriter<std::fs::File>,
    path: std::path::PathBuf,
    /// Values per view slot (all its light images).
    slot_len: usize,
    views_left: usize,
}

impl Writer {
    /// Creates `path` and writes the header of a `width x height` BTF on `sampling`.
    pub fn create(path: &Path, width: usize, height: usize, sampling: &Sampling) -> anyhow::Result<Writer> {
        let header = Header {
            format: FORMAT.into(),
            version: VERSION,
            width: width as u32,
            height: height as u32,
            channels: 3,
            encoding: "f16-le".into(),
            rings: sampling.rings.iter().map(|r| (r.theta, r.count)).collect(),
            views: sampling.directions().iter().map(|d| (d.theta, d.phi)).collect(),
            lights: sampling.directions().iter().map(|d| (d.theta, d.phi)).collect(),
        };
        let context = || format!("writing the BTF {}", path.display());
        let mut file = std::io::BufWriter::new(std::fs::File::create(path).with_context(context)?);
        let mut line = serde_json::to_vec(&header)?;
        line.push(b'\n');
        std::io::Write::write_all(&mut file, &line).with_context(context)?;
        let n = sampling.len();
        Ok(Writer { file, path: path.to_path_buf(), slot_len: n * width * height * 3, views_left: n })
    }

    /// Appends the next view slot: its light images in the sampling's order.
    pub fn write_view(&mut self, slot: &[f32]) -> anyhow::Result<()> {
        ensure!(self.views_left > 0, "{}: every view slot is already written", self.path.display());
        ensure!(
            slot.len() == self.slot_len,
            "{}: a view slot has {} values, not {}",
            self.path.display(),
            slot.len(),
            self.slot_len
        );
        let bytes: Vec<u8> = slot.iter().flat_map(|&x| half::f16::from_f32(x).to_le_bytes()).collect();
        std::io::Write::write_all(&mut self.file, &bytes)
            .with_context(|| format!("writing the BTF {}", self.path.display()))?;
        self.views_left -= 1;
        Ok(())
    }

    /// Flushes the file; every view slot must have been written.
    pub fn finish(mut self) -> anyhow::Result<()> {
        ensure!(self.views_left == 0, "{}: {} view slots were not written", self.path.display(), self.views_left);
        std::io::Write::flush(&mut self.file).with_context(|| format!("writing the BTF {}", self.path.display()))
    }
}

/// Reads a BTF written by [`save`].
pub fn load(path: &Path) -> anyhow::Result<Btf> {
    let bytes = std::fs::read(path).with_context(|| format!("reading the BTF {}", path.display()))?;
    parse(&bytes).with_context(|| format!("{} is not a usable BTF file", path.display()))
}

/// Splits a file into its header line (without the newline) and the data after it.
pub(super) fn header_line(bytes: &[u8]) -> anyhow::Result<(&[u8], &[u8])> {
    let Some(end) = bytes.iter().take(MAX_HEADER).position(|&b| b == b'\n') else {
        bail!("no header line (a JSON object ending in a newline) in its first {MAX_HEADER} bytes");
    };
    Ok((&bytes[..end], &bytes[end + 1..]))
}

/// The checks every BTF header shares: its format and version are `(found, expected)`, RGB,
/// and a size in 1..8192.
pub(super) fn check_header(
    (format, want_format): (&str, &str),
    (version, want_version): (u32, u32),
    channels: u32,
    (width, height): (u32, u32),
) -> anyhow::Result<()> {
    ensure!(format == want_format, "the header's format is {format:?}, not {want_format:?}");
    ensure!(version == want_version, "version {version} (this build reads version {want_version})");
    ensure!(channels == 3, "{channels} channels (RGB, 3, expected)");
    ensure!(
        width > 0 && height > 0 && width <= 8192 && height <= 8192,
        "image size {width}x{height} is out of range (1..8192)"
    );
    Ok(())
}

/// The sampling of a header's `[theta, count]` rings, checked.
pub(super) fn sampling_from_rings(rings: &[(f64, usize)]) -> anyhow::Result<Sampling> {
    let sampling =
        Sampling { rings: rings.iter().map(|&(theta, count)| super::directions::Ring { theta, count }).collect() };
    sampling.check().map_err(anyhow::Error::msg).context("the header's rings")?;
    ensure!(sampling.len() <= 1024, "{} directions per ring set (at most 1024)", sampling.len());
    Ok(sampling)
}

fn parse(bytes: &[u8]) -> anyhow::Result<Btf> {
    let (line, raw) = header_line(bytes)?;
    let header: Header = serde_json::from_slice(line).context("the header is not valid")?;
    check_header((&header.format, FORMAT), (header.version, VERSION), header.channels, (header.width, header.height))?;
    ensure!(header.encoding == "f16-le", "encoding {:?} (only \"f16-le\" is read)", header.encoding);
    let sampling = sampling_from_rings(&header.rings)?;
    for (what, list) in [("views", &header.views), ("lights", &header.lights)] {
        check_directions(&sampling, list).with_context(|| format!("the header's {what}"))?;
    }
    let n = sampling.len();
    let (w, h) = (header.width as usize, header.height as usize);
    let values = n * n * w * h * 3;
    let data_bytes = raw.len();
    ensure!(
        data_bytes >= values * 2,
        "truncated: {n}x{n} images of {w}x{h} RGB need {} bytes of f16 data, the file has {data_bytes}",
        values * 2
    );
    ensure!(data_bytes == values * 2, "{} bytes after the {} bytes of f16 data", data_bytes - values * 2, values * 2);
    // Blocks are stored in the header's order; the Btf holds them in the sampling's order.
    let dirs = sampling.directions();
    let index = |list: &[(f64, f64)], d: Dir| list.iter().position(|&(t, p)| same(d, t, p)).expect("checked above");
    let view_of: Vec<usize> = dirs.iter().map(|&d| index(&header.views, d)).collect();
    let light_of: Vec<usize> = dirs.iter().map(|&d| index(&header.lights, d)).collect();
    let block = w * h * 3;
    let mut data = Vec::with_capacity(values);
    for (vj, &v) in view_of.iter().enumerate() {
        for (li, &l) in light_of.iter().enumerate() {
            let start = (v * n + l) * block;
            for t in 0..block {
                let o = 2 * (start + t);
                let x = half::f16::from_le_bytes([raw[o], raw[o + 1]]).to_f32();
                if !x.is_finite() {
                    let (d, e) = (dirs[vj], dirs[li]);
                    bail!(
                        "value {x} at view ({}, {}) light ({}, {}), texel {} channel {}",
                        d.theta,
                        d.phi,
                        e.theta,
                        e.phi,
                        t / 3,
                        t % 3
                    );
                }
                data.push(x);
            }
        }
    }
    Ok(Btf { width: w, height: h, sampling, data })
}

fn same(d: Dir, theta: f64, phi: f64) -> bool {
    // At the pole phi is meaningless.
    (d.theta - theta).abs() < 1e-6 && (d.theta == 0.0 || (d.phi - phi.rem_euclid(360.0)).abs() < 1e-6)
}

/// Every direction of the sampling appears exactly once, and nothing else does.
fn check_directions(sampling: &Sampling, list: &[(f64, f64)]) -> anyhow::Result<()> {
    ensure!(list.iter().all(|&(t, p)| t.is_finite() && p.is_finite()), "a direction is NaN or infinite");
    for d in sampling.directions() {
        match list.iter().filter(|&&(t, p)| same(d, t, p)).count() {
            0 => bail!("direction (theta {}, phi {}) of the sampling is missing", d.theta, d.phi),
            1 => {}
            k => bail!("direction (theta {}, phi {}) appears {k} times", d.theta, d.phi),
        }
    }
    ensure!(list.len() == sampling.len(), "{} directions listed, the sampling has {}", list.len(), sampling.len());
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn sample() -> Btf {
        Btf::lambertian(Sampling::h2_tests(), 4, 3, |x, y| [0.2 + 0.1 * x as f32, 0.5, 0.1 * y as f32 + 0.3])
    }

    fn dir() -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("werkstatt-btf-container-{}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    fn error(path: &Path) -> String {
        format!("{:#}", load(path).expect_err("a damaged file must not load"))
    }

    #[test]
    fn a_saved_btf_loads_back_to_f16_precision() {
        let btf = sample();
        let path = dir().join("roundtrip.btf");
        save(&btf, &path).unwrap();
        let back = load(&path).unwrap();
        assert_eq!((back.width, back.height, &back.sampling), (btf.width, btf.height, &btf.sampling));
        let err =
            back.data.iter().zip(&btf.data).map(|(a, b)| (a - b).abs() / b.abs().max(1e-3)).fold(0.0f32, f32::max);
        assert!(err < 1e-3, "f16 round trip relative error {err}");
    }

    #[test]
    fn damaged_files_give_errors_that_name_the_file() {
        let d = dir();
        let good = d.join("good.btf");
        save(&sample(), &good).unwrap();
        let bytes = std::fs::read(&good).unwrap();
        let end = bytes.iter().position(|&b| b == b'\n').unwrap();
        let header = std::str::from_utf8(&bytes[..end]).unwrap().to_string();
        let write = |name: &str, b: &[u8]| {
            let p = d.join(name);
            std::fs::write(&p, b).unwrap();
            p
        };
        let with_header = |h: String| [h.as_bytes(), &bytes[end..]].concat();
        let cases: Vec<(&str, Vec<u8>, &str)> = vec![
            ("truncated.btf", bytes[..bytes.len() - 7].to_vec(), "truncated"),
            ("trailing.btf", [bytes.as_slice(), &[0, 0]].concat(), "bytes after"),
            ("empty.btf", Vec::new(), "no header"),
            ("garbage.btf", vec![0xff; 64], "no header"),
            ("notjson.btf", b"{\"format\": 3\n".to_vec(), "header is not valid"),
            ("format.btf", with_header(header.replace(FORMAT, "other")), "format is \"other\""),
            ("version.btf", with_header(header.replace("\"version\":1", "\"version\":9")), "version 9"),
            (
                "missing.btf",
                with_header(header.replacen("[30.0,30.0]", "[30.0,31.0]", 1)),
                "(theta 30, phi 30) of the sampling is missing",
            ),
            ("rings.btf", with_header(header.replace("[15.0,6]", "[15.0,1]")), "rings"),
            (
                "nan.btf",
                [&bytes[..end + 1], &[0x00, 0x7e], &bytes[end + 3..]].concat(),
                "value NaN at view (0, 0) light (0, 0), texel 0 channel 0",
            ),
        ];
        for (name, b, want) in cases {
            let path = write(name, &b);
            let msg = error(&path);
            assert!(msg.contains(name) && msg.contains(want), "{name}: {msg:?} should name the file and say {want:?}");
        }
        assert!(error(&d.join("absent.btf")).contains("absent.btf"));
    }
}

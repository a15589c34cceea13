//! Measured BTFs from folders of per-direction images (docs/btf.md, "Measured BTFs").
//!
//! **Bonn layout.** The Bonn BTF database (UBO2003, the samples of Sattler et al.) ships one
//! folder per view, `tv030_pv030/`, holding one image per light, named
//! `00008 tl000 pl000 tv030 pv030.jpg`: a running number, then the light's theta and phi and
//! the view's theta and phi in whole degrees. Here every image below the folder (two levels
//! deep) whose name carries `tl`, `pl`, `tv` and `pv` numbers (separated by spaces or
//! underscores, in any order) is read; `tv`/`pv` missing from the file name are taken from its
//! folder's name. Other files are ignored.
//!
//! **Manifest.** Instead, `manifest.json` in the folder lists the images and their directions:
//! `{"images": [{"file": "a.png", "view": [theta, phi], "light": [theta, phi]}, ...]}`.
//!
//! **Sampling.** The directions found must form a ring sampling (Table 1): rings of constant
//! theta with directions evenly spaced in phi from 0, the same set for views and lights, and an
//! image for every pair. That sampling is kept when it is H2 (81 directions) or the test tier's
//! 19; any other (the paper's H1, say) is resampled onto H2 with the 4 x 4 weights of
//! [`Sampling::weights`] (exact where the directions agree). Values are read as linear (8-bit
//! images as value / 255) unless `srgb` is set, then scaled by `scale`.

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail, ensure};
use serde::Deserialize;

use super::Btf;
use super::directions::{Dir, Ring, Sampling};

/// How to read the images.
#[derive(Clone, Debug, PartialEq)]
pub struct ImportOptions {
    /// The images are sRGB-encoded (decoded to linear on reading).
    pub srgb: bool,
    /// Multiplies every value (to radiance under unit irradiance).
    pub scale: f32,
    /// The sampling to resample onto; none: as described in the module documentation.
    pub sampling: Option<Sampling>,
}

impl Default for ImportOptions {
    fn default() -> ImportOptions {
        ImportOptions { srgb: false, scale: 1.0, sampling: None }
    }
}

/// One image and its directions.
#[derive(Clone, Debug)]
struct Entry {
    file: PathBuf,
    view: Dir,
    light: Dir,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct Manifest {
    images: Vec<ManifestImage>,
}

#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct ManifestImage {
    file: PathBuf,
    view: (f64, f64),
    light: (f64, f64),
}

/// Image files that may be BTF images.
const EXTENSIONS: [&str; 5] = ["png", "jpg", "jpeg", "exr", "hdr"];

/// The Bonn name of the image of `view` and `light` (number `index`).
pub fn bonn_name(index: usize, view: Dir, light: Dir, extension: &str) -> String {
    let deg = |x: f64| x.round() as i64;
    format!(
        "tv{:03}_pv{:03}/{index:05} tl{:03} pl{:03} tv{:03} pv{:03}.{extension}",
        deg(view.theta),
        deg(view.phi),
        deg(light.theta),
        deg(light.phi),
        deg(view.theta),
        deg(view.phi)
    )
}

/// The angles named in `text` (`tl030`, `pl060`, ...), by key; an error when a key repeats.
fn angles_in(text: &str) -> Result<BTreeMap<&'static str, f64>, String> {
    let mut found = BTreeMap::new();
    for token in text.split(|c: char| c.is_whitespace() || c == '_') {
        for key in ["tl", "pl", "tv", "pv"] {
            let Some(number) = token.strip_prefix(key) else { continue };
            let Ok(value) = number.parse::<f64>() else { continue };
            if !value.is_finite() {
                continue;
            }
            if found.insert(key, value).is_some() {
                return Err(format!("names {key} twice"));
            }
        }
    }
    Ok(found)
}

/// The directions of a Bonn-named image at `path`: `None` when the name carries no angles.
fn bonn_entry(path: &Path) -> anyhow::Result<Option<Entry>> {
    let stem = path.file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
    let mut angles = angles_in(&stem).map_err(|e| anyhow::anyhow!("the image name {} {e}", path.display()))?;
    if angles.is_empty() {
        return Ok(None);
    }
    if !angles.contains_key("tv") || !angles.contains_key("pv") {
        let folder = path.parent().and_then(|p| p.file_name()).map(|s| s.to_string_lossy().into_owned());
        if let Ok(outer) = angles_in(&folder.unwrap_or_default()) {
            for key in ["tv", "pv"] {
                if let Some(&v) = outer.get(key) {
                    angles.entry(key).or_insert(v);
                }
            }
        }
    }
    let missing: Vec<&str> = ["tl", "pl", "tv", "pv"].into_iter().filter(|k| !angles.contains_key(k)).collect();
    ensure!(
        missing.is_empty(),
        "the image name {} has no {} angle (Bonn names look like \"00008 tl000 pl000 tv030 pv030.jpg\")",
        path.display(),
        missing.join(", ")
    );
    Ok(Some(Entry {
        file: path.to_path_buf(),
        view: Dir { theta: angles["tv"], phi: angles["pv"] },
        light: Dir { theta: angles["tl"], phi: angles["pl"] },
    }))
}

/// The images of `dir`: from its manifest, or by their Bonn names.
fn entries(dir: &Path) -> anyhow::Result<Vec<Entry>> {
    let manifest = dir.join("manifest.json");
    if manifest.exists() {
        let text = std::fs::read_to_string(&manifest).with_context(|| format!("reading {}", manifest.display()))?;
        let m: Manifest =
            serde_json::from_str(&text).with_context(|| format!("{} is not valid", manifest.display()))?;
        return Ok(m
            .images
            .into_iter()
            .map(|i| Entry {
                file: dir.join(i.file),
                view: Dir { theta: i.view.0, phi: i.view.1 },
                light: Dir { theta: i.light.0, phi: i.light.1 },
            })
            .collect());
    }
    let mut files = Vec::new();
    let mut folders = vec![(dir.to_path_buf(), 0)];
    while let Some((folder, depth)) = folders.pop() {
        let list = std::fs::read_dir(&folder).with_context(|| format!("reading the folder {}", folder.display()))?;
        for item in list {
            let path = item.with_context(|| format!("reading the folder {}", folder.display()))?.path();
            if path.is_dir() {
                if depth < 2 {
                    folders.push((path, depth + 1));
                }
            } else if path
                .extension()
                .is_some_and(|e| EXTENSIONS.iter().any(|x| e.to_string_lossy().eq_ignore_ascii_case(x)))
            {
                files.push(path);
            }
        }
    }
    files.sort();
    let mut found = Vec::new();
    for f in files {
        found.extend(bonn_entry(&f)?);
    }
    ensure!(
        !found.is_empty(),
        "{} has no manifest.json and no images named like \"00008 tl000 pl000 tv030 pv030.png\"",
        dir.display()
    );
    Ok(found)
}

/// Directions closer than this (degrees) are the same.
const SAME: f64 = 0.01;

/// The pole has no phi.
fn canonical(d: Dir) -> Dir {
    if d.theta.abs() < SAME {
        Dir { theta: 0.0, phi: 0.0 }
    } else {
        Dir { theta: d.theta, phi: d.phi.rem_euclid(360.0) }
    }
}

/// The ring sampling that the directions of `entries` form.
fn sampling_of(entries: &[Entry]) -> anyhow::Result<Sampling> {
    let mut rings: Vec<(f64, Vec<f64>)> = Vec::new();
    for e in entries {
        for d in [e.view, e.light] {
            ensure!(
                d.theta.is_finite() && d.phi.is_finite() && (0.0..90.0).contains(&d.theta),
                "{}: the direction (theta {}, phi {}) is outside the hemisphere",
                e.file.display(),
                d.theta,
                d.phi
            );
            let d = canonical(d);
            let ring = match rings.iter().position(|(t, _)| (t - d.theta).abs() < SAME) {
                Some(i) => i,
                None => {
                    rings.push((d.theta, Vec::new()));
                    rings.len() - 1
                }
            };
            let phis = &mut rings[ring].1;
            if !phis.iter().any(|p| (p - d.phi).abs() < SAME) {
                phis.push(d.phi);
            }
        }
    }
    rings.sort_by(|a, b| a.0.total_cmp(&b.0));
    let mut out = Vec::new();
    for (theta, mut phis) in rings {
        phis.sort_by(f64::total_cmp);
        let n = phis.len();
        for (k, p) in phis.iter().enumerate() {
            let want = k as f64 * 360.0 / n as f64;
            ensure!(
                (p - want).abs() < 0.5,
                "the {n} directions at theta {theta} deg are not evenly spaced from phi 0 (phi {p}, expected {want}): \
                 not a ring sampling"
            );
        }
        out.push(Ring { theta, count: n });
    }
    let sampling = Sampling { rings: out };
    sampling.check().map_err(anyhow::Error::msg).context("the directions of the images")?;
    Ok(sampling)
}

/// The index of `d` among `dirs` (same within [`SAME`]).
fn index_of(dirs: &[Dir], d: Dir) -> Option<usize> {
    let d = canonical(d);
    dirs.iter().position(|&e| (e.theta - d.theta).abs() < SAME && (e.theta == 0.0 || (e.phi - d.phi).abs() < 0.5))
}

/// Reads one image as linear RGB.
fn read_image(path: &Path, options: &ImportOptions) -> anyhow::Result<(usize, usize, Vec<f32>)> {
    let image = image::open(path).with_context(|| format!("cannot read the image {}", path.display()))?;
    let rgb = image.to_rgb32f();
    let (w, h) = (rgb.width() as usize, rgb.height() as usize);
    let decode = |x: f32| {
        let linear =
            if options.srgb { if x <= 0.04045 { x / 12.92 } else { ((x + 0.055) / 1.055).powf(2.4) } } else { x };
        linear * options.scale
    };
    let data: Vec<f32> = rgb.into_raw().into_iter().map(decode).collect();
    if let Some(bad) = data.iter().position(|x| !x.is_finite()) {
        bail!("the image {} has a NaN or infinite value at texel {}", path.display(), bad / 3);
    }
    Ok((w, h, data))
}

/// Reads the measured BTF in the folder `dir` (module documentation).
pub fn import_folder(dir: &Path, options: &ImportOptions) -> anyhow::Result<Btf> {
    ensure!(options.scale.is_finite() && options.scale > 0.0, "the scale must be positive, not {}", options.scale);
    ensure!(dir.is_dir(), "{} is not a folder", dir.display());
    let entries = entries(dir)?;
    let source = sampling_of(&entries)?;
    let dirs = source.directions();
    let n = dirs.len();
    // Every (view, light) pair has exactly one image.
    let mut table: Vec<Option<PathBuf>> = vec![None; n * n];
    for e in &entries {
        let (Some(v), Some(l)) = (index_of(&dirs, e.view), index_of(&dirs, e.light)) else {
            bail!("{}: its directions are not on the sampling of the folder", e.file.display());
        };
        if let Some(other) = &table[v * n + l] {
            bail!(
                "{} and {} are both view (theta {}, phi {}) light (theta {}, phi {})",
                other.display(),
                e.file.display(),
                dirs[v].theta,
                dirs[v].phi,
                dirs[l].theta,
                dirs[l].phi
            );
        }
        table[v * n + l] = Some(e.file.clone());
    }
    let missing: Vec<(usize, usize)> = (0..n * n).filter(|&k| table[k].is_none()).map(|k| (k / n, k % n)).collect();
    if let Some(&(v, l)) = missing.first() {
        bail!(
            "{}: {} of the {} view/light pairs of its {n} directions have no image, the first view (theta {}, \
             phi {}) light (theta {}, phi {}), e.g. {}",
            dir.display(),
            missing.len(),
            n * n,
            dirs[v].theta,
            dirs[v].phi,
            dirs[l].theta,
            dirs[l].phi,
            bonn_name(v * n + l, dirs[v], dirs[l], "png")
        );
    }
    let target = match &options.sampling {
        Some(s) => s.clone(),
        None if source == Sampling::h2() || source == Sampling::h2_tests() => source.clone(),
        None => Sampling::h2(),
    };
    target.check().map_err(anyhow::Error::msg)?;
    // Source views are read when a target view first needs them and dropped after the last.
    let target_dirs = target.directions();
    // Views and lights share the sampling, so one set of weights serves both.
    let weights: Vec<[(usize, f64); 4]> = target_dirs.iter().map(|&d| source.weights(d)).collect();
    let last_use = |sv: usize| weights.iter().rposition(|w| w.iter().any(|&(i, x)| i == sv && x > 0.0));
    let mut loaded: BTreeMap<usize, Vec<Vec<f32>>> = BTreeMap::new();
    let mut size: Option<(usize, usize, PathBuf)> = None;
    let mut data = Vec::new();
    for (tv, vw) in weights.iter().enumerate() {
        for &(sv, w) in vw {
            if w == 0.0 || loaded.contains_key(&sv) {
                continue;
            }
            let mut images = Vec::with_capacity(n);
            for sl in 0..n {
                let file = table[sv * n + sl].as_ref().expect("checked above");
                let (width, height, pixels) = read_image(file, options)?;
                if let Some((w0, h0, first)) = &size {
                    ensure!(
                        (width, height) == (*w0, *h0),
                        "the image {} is {width}x{height}, but {} is {w0}x{h0}",
                        file.display(),
                        first.display()
                    );
                } else {
                    size = Some((width, height, file.clone()));
                }
                images.push(pixels);
            }
            loaded.insert(sv, images);
        }
        let len = size.as_ref().map_or(0, |(w, h, _)| w * h * 3);
        for lw in &weights {
            let mut out = vec![0.0f64; len];
            for &(sv, wv) in vw {
                for &(sl, wl) in lw {
                    let w = wv * wl;
                    if w == 0.0 {
                        continue;
                    }
                    for (o, &x) in out.iter_mut().zip(&loaded[&sv][sl]) {
                        *o += w * x as f64;
                    }
                }
            }
            data.extend(out.into_iter().map(|x| x as f32));
        }
        loaded.retain(|&sv, _| last_use(sv).is_some_and(|last| last > tv));
    }
    let (width, height, _) = size.expect("a sampling has at least one direction");
    Ok(Btf { width, height, sampling: target, data })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn temp(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("werkstatt-btf-measured-{}-{name}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    /// Writes `btf` as 8-bit PNGs in the Bonn layout (values in [0, 1]).
    fn write_bonn(btf: &Btf, dir: &Path) {
        let dirs = btf.sampling.directions();
        let n = dirs.len();
        for (v, &view) in dirs.iter().enumerate() {
            for (l, &light) in dirs.iter().enumerate() {
                let path = dir.join(bonn_name(v * n + l, view, light, "png"));
                std::fs::create_dir_all(path.parent().unwrap()).unwrap();
                let image = &btf.data[(v * n + l) * btf.image_len()..][..btf.image_len()];
                let bytes: Vec<u8> = image.iter().map(|x| (x * 255.0).round().clamp(0.0, 255.0) as u8).collect();
                image::RgbImage::from_raw(btf.width as u32, btf.height as u32, bytes).unwrap().save(&path).unwrap();
            }
        }
    }

    /// A BTF whose every image differs: the view and light indices in red and green.
    fn synthetic(sampling: Sampling) -> Btf {
        let n = sampling.len();
        let (w, h) = (3, 2);
        let mut data = Vec::new();
        for v in 0..n {
            for l in 0..n {
                for t in 0..w * h {
                    data.extend([v as f32 / n as f32, l as f32 / n as f32, t as f32 / 8.0]);
                }
            }
        }
        Btf { width: w, height: h, sampling, data }
    }

    #[test]
    fn a_bonn_folder_reads_back_in_the_samplings_order() {
        let btf = synthetic(Sampling::h2_tests());
        let dir = temp("roundtrip");
        write_bonn(&btf, &dir);
        let back = import_folder(&dir, &ImportOptions::default()).unwrap();
        assert_eq!((back.width, back.height, &back.sampling), (3, 2, &btf.sampling));
        let err = back.data.iter().zip(&btf.data).map(|(a, b)| (a - b).abs()).fold(0.0f32, f32::max);
        assert!(err <= 0.5 / 255.0 + 1e-6, "8-bit round trip error {err}");
        // Resampled onto H2's first rings: the same directions, the same images.
        let options = ImportOptions { scale: 2.0, ..ImportOptions::default() };
        let scaled = import_folder(&dir, &options).unwrap();
        assert!(scaled.data.iter().zip(&back.data).all(|(a, b)| (a - 2.0 * b).abs() < 1e-6));
    }

    #[test]
    fn another_sampling_is_resampled_onto_h2() {
        // Rings at 0 / 20 / 40 / 80 deg: Lambertian images, blended linearly in theta.
        let source = Sampling {
            rings: vec![
                Ring { theta: 0.0, count: 1 },
                Ring { theta: 20.0, count: 6 },
                Ring { theta: 40.0, count: 8 },
                Ring { theta: 80.0, count: 12 },
            ],
        };
        let btf = Btf::lambertian(source, 2, 2, |_, _| [0.9, 0.5, 0.2]);
        let dir = temp("resample");
        write_bonn(&btf, &dir);
        let back = import_folder(&dir, &ImportOptions::default()).unwrap();
        assert_eq!(back.sampling, Sampling::h2());
        let n = back.sampling.len();
        for (l, light) in back.sampling.directions().iter().enumerate() {
            let exact = 0.9 / std::f32::consts::PI * light.theta.to_radians().cos() as f32;
            let got = back.data[l * back.image_len()];
            // Linear in theta between rings 20 or 40 deg apart, plus 8-bit rounding.
            assert!((got - exact).abs() < 0.04, "light {light:?}: {got} against {exact}");
            // Every view the same (the source's views are all Lambertian).
            assert!((got - back.data[((n - 1) * n + l) * back.image_len()]).abs() < 1e-6);
        }
    }

    #[test]
    fn broken_folders_are_named() {
        let btf = synthetic(Sampling::h2_tests());
        let error = |dir: &Path| format!("{:#}", import_folder(dir, &ImportOptions::default()).unwrap_err());
        let dirs = btf.sampling.directions();
        let name = |v: usize, l: usize| bonn_name(v * 19 + l, dirs[v], dirs[l], "png");

        let dir = temp("missing");
        write_bonn(&btf, &dir);
        std::fs::remove_file(dir.join(name(3, 5))).unwrap();
        let e = error(&dir);
        assert!(e.contains("1 of the 361") && e.contains("view (theta 15, phi 120) light (theta 15, phi 240)"), "{e}");

        let dir = temp("unreadable");
        write_bonn(&btf, &dir);
        std::fs::write(dir.join(name(2, 7)), b"not a png").unwrap();
        let e = error(&dir);
        assert!(e.contains("cannot read the image") && e.contains(&name(2, 7)), "{e}");

        let dir = temp("size");
        write_bonn(&btf, &dir);
        image::RgbImage::new(4, 4).save(dir.join(name(0, 9))).unwrap();
        let e = error(&dir);
        assert!(e.contains(&name(0, 9)) && e.contains("is 4x4") && e.contains("is 3x2"), "{e}");

        let dir = temp("empty");
        assert!(error(&dir).contains("no images named like"));
        let dir = temp("halfnamed");
        image::RgbImage::new(1, 1).save(dir.join("00000 tl000 pl000.png")).unwrap();
        let e = error(&dir);
        assert!(e.contains("00000 tl000 pl000.png") && e.contains("no tv, pv angle"), "{e}");
        let dir = temp("uneven");
        for (tl, pl) in [(0, 0), (30, 0), (30, 100), (30, 240)] {
            let file = dir.join(format!("tl{tl:03} pl{pl:03} tv000 pv000.png"));
            image::RgbImage::new(1, 1).save(file).unwrap();
        }
        assert!(error(&dir).contains("not evenly spaced"));
        let dir = temp("manifest");
        std::fs::write(dir.join("manifest.json"), "{\"images\": [{\"file\": \"a.png\"}]}").unwrap();
        let e = error(&dir);
        assert!(e.contains("manifest.json is not valid"), "{e}");
    }
}

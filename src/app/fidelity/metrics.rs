//! werkstatt's image against the path tracer's, on the pixels the ids say are geometry.

use std::fmt::Write as _;
use std::path::Path;

use anyhow::{Context as _, bail};
use glam::Vec3;
use serde::Serialize;

use super::raster::PixelIds;
use super::scene::{FAR_BIT, SceneInfo};
use crate::color::luminance;
use crate::gpu::Pixels;

#[derive(Serialize, Clone, Debug)]
pub struct ItemError {
    pub name: String,
    pub pixels: usize,
    /// sum |w - c| / sum c over the item's pixels and the R, G, B channels.
    pub rel_mae: f64,
    /// Mean luminance of each image over the item's pixels.
    pub mean_werkstatt: f64,
    pub mean_cycles: f64,
    /// The item's brightest pixel (luminance) in each image, and their distance in pixels: a
    /// mirror ball's sun highlight.
    pub brightest_werkstatt: [u32; 2],
    pub brightest_cycles: [u32; 2],
    pub brightest_distance: f64,
    /// The item's rows on screen cut into five bands of equal height, top to bottom: in each,
    /// mean luminance werkstatt over Cycles (1 where the band has no pixel): where on the item
    /// light is missing (an underside the floor lights, a top the sky lights).
    pub fifths: [f64; 5],
}

#[derive(Serialize, Clone, Debug)]
pub struct RegionRatio {
    pub name: String,
    pub pixels: usize,
    /// Mean floor shading (luminance of radiance over luminance of albedo) in the region over
    /// the far floor's mean, in each image.
    pub cycles: f64,
    pub werkstatt: f64,
}

#[derive(Serialize, Clone, Debug)]
pub struct Metrics {
    /// Geometry pixels (the ids hit an item).
    pub pixels: usize,
    /// sum |w - c| / sum c over geometry pixels and the R, G, B channels.
    pub rel_mae: f64,
    /// The same over the pixels where nothing was hit: the probe seen directly (werkstatt
    /// shows its cube map's level 0, so this checks the probe's orientation, not its detail).
    pub background_rel_mae: f64,
    pub items: Vec<ItemError>,
    pub regions: Vec<RegionRatio>,
    /// The far floor: its pixels and mean shading in each image, and the analytic open-floor
    /// value of the probe (scene.json `open_floor_level`).
    pub far_floor_pixels: usize,
    pub far_floor_cycles: f64,
    pub far_floor_werkstatt: f64,
    pub open_floor_analytic: Option<f32>,
    /// Far-floor pixels within a tenth of the width of the left or right edge, and the fraction
    /// of them whose shading is below 0.95 of the far floor's median, in each image.
    pub edge_pixels: usize,
    pub edge_dark_cycles: f64,
    pub edge_dark_werkstatt: f64,
    /// The fraction of the same pixels where werkstatt's shading, over its far floor's mean, is
    /// below 0.95 of Cycles' over Cycles' far floor's mean (pixel by pixel: what werkstatt
    /// darkens that the path tracer does not).
    pub edge_below_cycles: f64,
    /// The fraction of pixels where the ids disagree with werkstatt's G-buffer and with
    /// Cycles' own ids render (cycles_ids.exr), where known.
    pub ids_gbuffer_mismatch: Option<f32>,
    pub ids_cycles_mismatch: Option<f32>,
}

fn rgb(px: &Pixels, i: usize) -> Vec3 {
    Vec3::new(px.rgba[4 * i], px.rgba[4 * i + 1], px.rgba[4 * i + 2])
}

fn median(mut v: Vec<f64>) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    v.sort_by(f64::total_cmp);
    v[v.len() / 2]
}

/// Per item: error, reference sum, pixels, luminance sums (werkstatt, path tracer), brightest
/// pixel (luminance, index) in each.
type Sums = (f64, f64, usize, f64, f64, (f32, usize), (f32, usize));

/// The metrics of werkstatt's image `w` against the path tracer's `c`.
pub fn measure(scene: &SceneInfo, ids: &PixelIds, w: &Pixels, c: &Pixels) -> anyhow::Result<Metrics> {
    let (width, height) = (ids.width, ids.height);
    for (name, p) in [("werkstatt", w), ("cycles", c)] {
        if (p.width, p.height) != (width, height) {
            bail!("the {name} image is {}x{}, the ids {width}x{height}", p.width, p.height);
        }
    }
    let n = (width * height) as usize;
    let mut items: Vec<Sums> = vec![(0.0, 0.0, 0, 0.0, 0.0, (f32::MIN, 0), (f32::MIN, 0)); scene.items.len()];
    let (mut err, mut sum, mut pixels) = (0.0f64, 0.0f64, 0usize);
    let (mut bg_err, mut bg_sum) = (0.0f64, 0.0f64);
    for i in 0..n {
        let Ok(k) = usize::try_from(ids.id[i]) else {
            bg_err += (rgb(w, i) - rgb(c, i)).abs().element_sum() as f64;
            bg_sum += rgb(c, i).element_sum() as f64;
            continue;
        };
        let (a, b) = (rgb(w, i), rgb(c, i));
        let e = (a - b).abs().element_sum() as f64;
        let s = b.element_sum() as f64;
        err += e;
        sum += s;
        pixels += 1;
        if let Some(it) = items.get_mut(k) {
            it.0 += e;
            it.1 += s;
            it.2 += 1;
            it.3 += luminance(a) as f64;
            it.4 += luminance(b) as f64;
            if luminance(a) > it.5.0 {
                it.5 = (luminance(a), i);
            }
            if luminance(b) > it.6.0 {
                it.6 = (luminance(b), i);
            }
        }
    }
    let at = |i: usize| [i as u32 % width, i as u32 / width];
    let fifths = |k: usize| {
        let mine: Vec<usize> = (0..n).filter(|&i| ids.id[i] == k as i32).collect();
        let row = |i: usize| i / width as usize;
        // Pixel indices grow row by row: the first and last are the top and bottom rows.
        let (top, bottom) = (mine.first().map_or(0, |&i| row(i)), mine.last().map_or(0, |&i| row(i)));
        let mut bands = [(0.0f64, 0.0f64); 5];
        for &i in &mine {
            let band = (5 * (row(i) - top) / (bottom - top + 1)).min(4);
            bands[band].0 += luminance(rgb(w, i)) as f64;
            bands[band].1 += luminance(rgb(c, i)) as f64;
        }
        bands.map(|(lw, lc)| if lc > 0.0 { lw / lc } else { 1.0 })
    };
    let items = scene
        .items
        .iter()
        .zip(items)
        .enumerate()
        .map(|(k, (info, (e, s, p, lw, lc, bw, bc)))| {
            let (pw, pc) = (at(bw.1), at(bc.1));
            ItemError {
                fifths: fifths(k),
                name: info.name.clone(),
                pixels: p,
                rel_mae: e / s.max(1e-12),
                mean_werkstatt: lw / p.max(1) as f64,
                mean_cycles: lc / p.max(1) as f64,
                brightest_werkstatt: pw,
                brightest_cycles: pc,
                brightest_distance: ((pw[0] as f64 - pc[0] as f64).powi(2) + (pw[1] as f64 - pc[1] as f64).powi(2))
                    .sqrt(),
            }
        })
        .collect();

    // Floor shading: radiance over albedo (luminance), so the checker does not count.
    let floor = scene.floor_item.map(|f| f as i32);
    let shading = |px: &Pixels, i: usize| luminance(rgb(px, i)) as f64 / (luminance(ids.albedo[i]) as f64).max(1e-6);
    let is_floor = |i: usize| Some(ids.id[i]) == floor;
    let mask = |i: usize| ids.regions.get(i).copied().unwrap_or(0);
    let far: Vec<usize> = (0..n).filter(|&i| is_floor(i) && mask(i) & (1 << FAR_BIT) != 0).collect();
    let mean = |px: &Pixels, set: &[usize]| set.iter().map(|&i| shading(px, i)).sum::<f64>() / set.len().max(1) as f64;
    let (far_c, far_w) = (mean(c, &far), mean(w, &far));
    let regions = scene
        .regions
        .iter()
        .enumerate()
        .map(|(k, r)| {
            let set: Vec<usize> = (0..n).filter(|&i| mask(i) & (1 << k) != 0).collect();
            RegionRatio {
                name: r.name.clone(),
                pixels: set.len(),
                cycles: mean(c, &set) / far_c,
                werkstatt: mean(w, &set) / far_w,
            }
        })
        .collect();
    let band = width / 10;
    let edge: Vec<usize> =
        far.iter().copied().filter(|&i| (i as u32 % width) < band || (i as u32 % width) >= width - band).collect();
    let dark = |px: &Pixels| {
        let level = median(far.iter().map(|&i| shading(px, i)).collect());
        edge.iter().filter(|&&i| shading(px, i) < 0.95 * level).count() as f64 / edge.len().max(1) as f64
    };
    Ok(Metrics {
        pixels,
        rel_mae: err / sum.max(1e-12),
        background_rel_mae: bg_err / bg_sum.max(1e-12),
        items,
        regions,
        far_floor_pixels: far.len(),
        far_floor_cycles: far_c,
        far_floor_werkstatt: far_w,
        open_floor_analytic: scene.open_floor_level,
        edge_pixels: edge.len(),
        edge_dark_cycles: dark(c),
        edge_dark_werkstatt: dark(w),
        edge_below_cycles: edge.iter().filter(|&&i| shading(w, i) / far_w < 0.95 * shading(c, i) / far_c).count()
            as f64
            / edge.len().max(1) as f64,
        ids_gbuffer_mismatch: scene.ids_gbuffer_mismatch,
        ids_cycles_mismatch: None,
    })
}

impl Metrics {
    /// The metrics as Markdown tables.
    pub fn table(&self) -> String {
        let mut s = String::new();
        let _ = writeln!(
            s,
            "relative MAE (sum |w - c| / sum c, RGB, {} geometry pixels): {:.1}%\n",
            self.pixels,
            100.0 * self.rel_mae
        );
        let _ = writeln!(
            s,
            "| item | pixels | relative MAE | mean Cycles | mean werkstatt | brightest pixel Cycles / werkstatt (distance) |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|");
        let _ = writeln!(s, "| background (probe) | - | {:.1}% | | | |", 100.0 * self.background_rel_mae);
        for it in &self.items {
            let _ = writeln!(
                s,
                "| {} | {} | {:.1}% | {:.4} | {:.4} | {:?} / {:?} ({:.1} px) |",
                it.name,
                it.pixels,
                100.0 * it.rel_mae,
                it.mean_cycles,
                it.mean_werkstatt,
                it.brightest_cycles,
                it.brightest_werkstatt,
                it.brightest_distance
            );
        }
        let _ = writeln!(
            s,
            "\n| item: werkstatt / Cycles luminance, fifths of its height top to bottom | 1 | 2 | 3 | 4 | 5 |"
        );
        let _ = writeln!(s, "|---|---|---|---|---|---|");
        for it in &self.items {
            let f = it.fifths;
            let _ =
                writeln!(s, "| {} | {:.2} | {:.2} | {:.2} | {:.2} | {:.2} |", it.name, f[0], f[1], f[2], f[3], f[4]);
        }
        let _ = writeln!(s, "\n| region (floor shading / far floor's) | pixels | Cycles | werkstatt |");
        let _ = writeln!(s, "|---|---|---|---|");
        for r in &self.regions {
            let _ = writeln!(s, "| {} | {} | {:.3} | {:.3} |", r.name, r.pixels, r.cycles, r.werkstatt);
        }
        let analytic = self.open_floor_analytic.map_or("-".to_string(), |v| format!("{v:.4}"));
        let _ = writeln!(
            s,
            "| far floor (radiance / albedo; analytic open floor {analytic}) | {} | {:.4} | {:.4} |",
            self.far_floor_pixels, self.far_floor_cycles, self.far_floor_werkstatt
        );
        let _ = writeln!(
            s,
            "| open floor at the left/right edges below 0.95 | {} | {:.1}% | {:.1}% |",
            self.edge_pixels,
            100.0 * self.edge_dark_cycles,
            100.0 * self.edge_dark_werkstatt
        );
        let _ = writeln!(
            s,
            "| open floor at the edges below 0.95 of Cycles, pixel by pixel (each over its far floor) | {} | | {:.1}% |",
            self.edge_pixels,
            100.0 * self.edge_below_cycles
        );
        let pct = |v: Option<f32>| v.map_or("-".to_string(), |v| format!("{:.2}%", 100.0 * v));
        let _ = writeln!(
            s,
            "\nids disagree with werkstatt's G-buffer on {} of the pixels, with Cycles' ids on {}",
            pct(self.ids_gbuffer_mismatch),
            pct(self.ids_cycles_mismatch)
        );
        s
    }
}

/// Reads an EXR (any channel type the decoder reads) as RGBA f32.
pub fn read_exr(path: &Path) -> anyhow::Result<Pixels> {
    let img = image::open(path).with_context(|| format!("cannot read {}", path.display()))?.to_rgba32f();
    Ok(Pixels { width: img.width(), height: img.height(), rgba: img.into_raw(), is_ldr: false })
}

/// The ids and albedo `werkstatt fidelity export` wrote.
pub fn read_ids(dir: &Path) -> anyhow::Result<PixelIds> {
    let ids = read_exr(&dir.join("ids.exr"))?;
    let albedo = read_exr(&dir.join("albedo.exr"))?;
    let regions = read_exr(&dir.join("regions.exr"))?;
    let n = (ids.width * ids.height) as usize;
    Ok(PixelIds {
        width: ids.width,
        height: ids.height,
        id: (0..n).map(|i| ids.rgba[4 * i].round() as i32).collect(),
        position: (0..n).map(|i| Vec3::new(ids.rgba[4 * i + 1], ids.rgba[4 * i + 2], ids.rgba[4 * i + 3])).collect(),
        albedo: (0..n).map(|i| rgb(&albedo, i)).collect(),
        regions: (0..n).map(|i| regions.rgba[4 * i] as u32).collect(),
    })
}

/// `werkstatt fidelity compare DIR`: werkstatt.exr against `cycles` (a file in DIR); also
/// writes DIR/compare.png: werkstatt, the path tracer and |w - c| x 4 side by side (x / (1 + x)).
pub fn compare_dir(dir: &Path, cycles: &str) -> anyhow::Result<Metrics> {
    let scene = SceneInfo::load(&dir.join("scene.json"))?;
    let ids = read_ids(dir)?;
    let w = read_exr(&dir.join("werkstatt.exr"))?;
    let c = read_exr(&dir.join(cycles))?;
    let mut m = measure(&scene, &ids, &w, &c)?;
    let cycles_ids = dir.join("cycles_ids.exr");
    if cycles_ids.exists() {
        let ci = read_exr(&cycles_ids)?;
        if ci.rgba.len() == 4 * ids.id.len() {
            let bad = ids.id.iter().enumerate().filter(|&(i, &id)| (ci.rgba[4 * i].round() as i32 - 1) != id).count();
            m.ids_cycles_mismatch = Some(bad as f32 / ids.id.len().max(1) as f32);
        }
    }
    let (width, height) = (w.width, w.height);
    let mut sheet = Pixels { width: 3 * width, height, rgba: vec![0.0; (12 * width * height) as usize], is_ldr: false };
    for y in 0..height as usize {
        for x in 0..width as usize {
            let i = y * width as usize + x;
            let (a, b) = (rgb(&w, i), rgb(&c, i));
            for (panel, v) in [a, b, (a - b).abs() * 4.0].into_iter().enumerate() {
                let o = 4 * (y * 3 * width as usize + panel * width as usize + x);
                sheet.rgba[o..o + 4].copy_from_slice(&[v.x, v.y, v.z, 1.0]);
            }
        }
    }
    crate::io::image::tonemap_for_png(&mut sheet);
    crate::io::image::write_png(&dir.join("compare.png"), &sheet)?;
    Ok(m)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::app::fidelity::scene::{CameraInfo, ItemInfo, Region};

    fn item(index: usize, name: &str) -> ItemInfo {
        ItemInfo {
            index,
            name: name.into(),
            base_color: [0.5; 3],
            glossiness: 0.0,
            texture: None,
            uv_scale: 1.0,
            triangles: [0, 0],
            bounds_min: [0.0; 3],
            bounds_max: [0.0; 3],
        }
    }

    fn scene_of(
        width: u32,
        height: u32,
        items: Vec<ItemInfo>,
        floor_item: Option<usize>,
        regions: Vec<Region>,
    ) -> SceneInfo {
        SceneInfo {
            conventions: String::new(),
            graph: String::new(),
            sets: Vec::new(),
            unlinks: Vec::new(),
            frame: 0,
            fps: 30.0,
            width,
            height,
            camera: CameraInfo {
                eye: [0.0; 3],
                target: [0.0, 0.0, -1.0],
                up: [0.0, 1.0, 0.0],
                fov_y_degrees: 40.0,
                near: 0.1,
                far: 10.0,
            },
            environment: None,
            sun: None,
            floor_item,
            floor_y: floor_item.map(|_| 0.0),
            open_floor_level: None,
            items,
            regions,
            far_margin: 1.5,
            ids_gbuffer_mismatch: None,
            check_points: Vec::new(),
        }
    }

    #[test]
    fn relative_errors_and_region_ratios_follow_their_definitions() {
        // Four pixels: two floor pixels (one far, one under the ball), one ball pixel, one
        // background pixel.
        let regions = vec![Region { name: "under ball".into(), item: 1, kind: "under".into() }];
        let scene = scene_of(4, 1, vec![item(0, "floor"), item(1, "ball")], Some(0), regions);
        let ids = PixelIds {
            width: 4,
            height: 1,
            id: vec![0, 0, 1, -1],
            position: vec![Vec3::ZERO; 4],
            albedo: vec![Vec3::splat(0.5); 4],
            regions: vec![1 << FAR_BIT, 1, 0, 0],
        };
        let px = |v: [f32; 4]| Pixels {
            width: 4,
            height: 1,
            rgba: v.iter().flat_map(|&x| [x, x, x, 1.0]).collect(),
            is_ldr: false,
        };
        let c = px([1.0, 0.5, 2.0, 3.0]);
        let w = px([1.0, 0.8, 1.0, 3.0]);
        let m = measure(&scene, &ids, &w, &c).unwrap();
        // |0| + |0.3| + |1| over 1 + 0.5 + 2 (per channel, three channels alike).
        assert!((m.rel_mae - 1.3 / 3.5).abs() < 1e-6);
        assert!((m.items[1].rel_mae - 0.5).abs() < 1e-6);
        assert_eq!(m.far_floor_pixels, 1);
        let under = &m.regions[0];
        assert!((under.cycles - 0.5).abs() < 1e-6 && (under.werkstatt - 0.8).abs() < 1e-6);
        assert_eq!(m.background_rel_mae, 0.0);
        // One row: the ball's one pixel is its top fifth (1 / 2); bands without pixels are 1.
        assert_eq!(m.items[1].fifths, [0.5, 1.0, 1.0, 1.0, 1.0]);
    }

    #[test]
    fn fifths_cut_an_item_into_bands_of_rows_top_to_bottom() {
        // A one-column item ten rows high: werkstatt's row r is (r + 1) / 10 of Cycles'.
        let ids = PixelIds {
            width: 1,
            height: 10,
            id: vec![0; 10],
            position: vec![Vec3::ZERO; 10],
            albedo: vec![Vec3::splat(0.5); 10],
            regions: vec![0; 10],
        };
        let px = |f: &dyn Fn(usize) -> f32| Pixels {
            width: 1,
            height: 10,
            rgba: (0..10).flat_map(|r| [f(r), f(r), f(r), 1.0]).collect(),
            is_ldr: false,
        };
        let c = px(&|_| 1.0);
        let w = px(&|r| (r + 1) as f32 / 10.0);
        let scene = scene_of(1, 10, vec![item(0, "ball")], None, Vec::new());
        let m = measure(&scene, &ids, &w, &c).unwrap();
        let want = [0.15, 0.35, 0.55, 0.75, 0.95];
        for (got, want) in m.items[0].fifths.iter().zip(want) {
            assert!((got - want).abs() < 1e-6, "{:?}", m.items[0].fifths);
        }
    }
}

//! `scene.json`: what a path tracer needs besides the geometry (camera, probe, materials), and
//! the world-space regions the metrics average over.

use glam::Vec3;
use serde::{Deserialize, Serialize};

/// The conventions a reader of `scene.json` must follow, written into the file itself.
pub const CONVENTIONS: &str = "World space is werkstatt's: right-handed, Y up, metres; scene.glb is the same space (glTF's). \
The camera is glam's look_at_rh(eye, target, up) with a vertical field of view (perspective_rh, the aspect width/height), \
pixel (x, y) is sampled at its centre, x to the right, y down from the top row. \
The probe is an equirectangular image looked up along world direction d (after turning d by -rotation_deg about +Y) at \
u = 0.5 + atan2(d.x, -d.z) / 2pi, v = acos(d.y) / pi, rows from +Y (v = 0) down; radiance times intensity. \
Material colours are linear RGB; an item with a texture multiplies base_color by the texture (sRGB-encoded PNG, \
bilinear, repeating) at (u, v) * uv_scale, v as glTF stores it (down from the image's top row).";

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct CameraInfo {
    pub eye: [f32; 3],
    pub target: [f32; 3],
    pub up: [f32; 3],
    pub fov_y_degrees: f32,
    pub near: f32,
    pub far: f32,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct EnvironmentInfo {
    /// Absolute path of the equirectangular probe.
    pub path: String,
    /// Degrees about +Y (EnvironmentMap's `rotation`).
    pub rotation_deg: f32,
    pub intensity: f32,
}

/// The brightest median-cut light: the region with the highest mean radiance (energy per solid
/// angle; the regions have equal energy, so the smallest one), the sun of an outdoor probe.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SunInfo {
    /// Unit direction towards the light.
    pub direction: [f32; 3],
    pub solid_angle: f32,
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct ItemInfo {
    /// The item's index in the G-buffer's scene; also its part (glTF material `part_<index>`).
    pub index: usize,
    /// The mesh node feeding the item's Draw (or the node that made it).
    pub name: String,
    /// Linear RGB.
    pub base_color: [f32; 3],
    /// 0 rough ... 1 mirror (werkstatt's lobe; docs/fidelity.md gives the path tracer's mapping).
    pub glossiness: f32,
    /// `texture_<index>.png` beside scene.json, when the material has a base-colour texture.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub texture: Option<String>,
    pub uv_scale: f32,
    /// Triangles of scene.glb's mesh (first, one past the last).
    pub triangles: [usize; 2],
    pub bounds_min: [f32; 3],
    pub bounds_max: [f32; 3],
}

/// A part of the floor (see [`region_masks`]): the floor under an item (its footprint seen from
/// straight above) or its cast shadow (its footprint seen along the sun's direction, less every
/// item's footprint).
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct Region {
    pub name: String,
    pub item: usize,
    /// "under" or "shadow".
    pub kind: String,
}

/// A world point and where werkstatt's camera projects it (pixels, x right, y down, pixel
/// centres at .5): the path tracer's camera is checked against these.
#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct CheckPoint {
    pub world: [f32; 3],
    pub pixel: [f32; 2],
}

#[derive(Serialize, Deserialize, Clone, Debug, PartialEq)]
pub struct SceneInfo {
    pub conventions: String,
    /// The graph as given on the command line.
    pub graph: String,
    pub sets: Vec<String>,
    /// Links removed (`node.port` inputs left unconnected).
    pub unlinks: Vec<String>,
    pub frame: i64,
    pub fps: f64,
    pub width: u32,
    pub height: u32,
    pub camera: CameraInfo,
    pub environment: Option<EnvironmentInfo>,
    pub sun: Option<SunInfo>,
    /// The item that is the floor (the flattest item, facing up) and its height.
    pub floor_item: Option<usize>,
    pub floor_y: Option<f32>,
    /// Radiance over albedo of an unoccluded Lambertian floor under the probe, luminance:
    /// (1/pi) x the integral of L cos over the upper hemisphere, from the probe file.
    pub open_floor_level: Option<f32>,
    pub items: Vec<ItemInfo>,
    /// `under <item>` and `shadow of <item>` per item other than the floor (bit i of a
    /// pixel's region mask); the far floor (bit [`FAR_BIT`]) is the floor in none of them and
    /// farther than `far_margin` x its larger horizontal half-extent from every other item's
    /// centre, horizontally.
    pub regions: Vec<Region>,
    pub far_margin: f32,
    /// The fraction of pixels where the ids and werkstatt's G-buffer disagree (hit or not, or
    /// depth off by more than 1%): triangle edges the rasterizer and the rays decide apart.
    #[serde(default)]
    pub ids_gbuffer_mismatch: Option<f32>,
    pub check_points: Vec<CheckPoint>,
}

impl SceneInfo {
    pub fn load(path: &std::path::Path) -> anyhow::Result<SceneInfo> {
        use anyhow::Context as _;
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        serde_json::from_str(&text).with_context(|| format!("{}: not a fidelity scene.json", path.display()))
    }
}

/// The floor: the item whose bounds are flattest (height over the larger horizontal extent
/// below 1%), the largest such.
pub fn find_floor(items: &[ItemInfo]) -> Option<usize> {
    items
        .iter()
        .filter(|i| {
            let (lo, hi) = (Vec3::from(i.bounds_min), Vec3::from(i.bounds_max));
            let e = hi - lo;
            e.y <= 0.01 * e.x.max(e.z) && e.x.max(e.z) > 0.0
        })
        .max_by(|a, b| {
            let area = |i: &ItemInfo| (i.bounds_max[0] - i.bounds_min[0]) * (i.bounds_max[2] - i.bounds_min[2]);
            area(a).total_cmp(&area(b))
        })
        .map(|i| i.index)
}

/// The regions of the metrics: per item but the floor, `under <name>` and, when the sun is at
/// least 5 degrees high, `shadow of <name>`.
pub fn regions(items: &[ItemInfo], floor: usize, sun: Option<&SunInfo>) -> Vec<Region> {
    let mut out = Vec::new();
    let sun_up = sun.is_some_and(|s| Vec3::from(s.direction).normalize().y > 5f32.to_radians().sin());
    for item in items.iter().filter(|i| i.index != floor) {
        out.push(Region { name: format!("under {}", item.name), item: item.index, kind: "under".into() });
        if sun_up {
            out.push(Region { name: format!("shadow of {}", item.name), item: item.index, kind: "shadow".into() });
        }
    }
    out.truncate(FAR_BIT as usize);
    out
}

/// The bit of the far floor in a pixel's region mask (masks are stored as f32, exact to 2^24).
pub const FAR_BIT: u32 = 23;

/// Cells of the footprint grid along the floor's larger side.
const CELLS: usize = 1024;

/// Each pixel's regions as a bit mask (bit i: `scene.regions[i]`, bit [`FAR_BIT`]: the far
/// floor), from the exported geometry: every item's triangles are projected onto the floor
/// plane, straight down (its footprint) and along the sun's direction (its shadow), and
/// rasterized into a grid of 1024 cells along the floor's larger side; a floor pixel belongs to
/// the footprints of the cell its visible point falls in. A shadow leaves out every item's
/// footprint (contact darkening is `under`).
pub fn region_masks(scene: &SceneInfo, mesh: &crate::mesh::Mesh, ids: &super::raster::PixelIds) -> Vec<u32> {
    const N: usize = CELLS;
    let n = ids.id.len();
    let mut masks = vec![0u32; n];
    let (Some(floor), Some(floor_y)) = (scene.floor_item, scene.floor_y) else { return masks };
    let fl = &scene.items[floor];
    let (x0, z0) = (fl.bounds_min[0], fl.bounds_min[2]);
    let side = (fl.bounds_max[0] - x0).max(fl.bounds_max[2] - z0).max(1e-6);
    let cell = side / N as f32;
    let to_cell = |p: Vec3| ((p.x - x0) / cell, (p.z - z0) / cell);
    let sun = scene.sun.as_ref().map(|s| Vec3::from(s.direction).normalize());
    let raster = |item: &ItemInfo, project: &dyn Fn(Vec3) -> Vec3| {
        let mut grid = vec![false; N * N];
        for t in item.triangles[0]..item.triangles[1] {
            let v: Vec<(f32, f32)> =
                mesh.indices[3 * t..3 * t + 3].iter().map(|&i| to_cell(project(mesh.positions[i as usize]))).collect();
            let lx = v.iter().map(|p| p.0).fold(f32::MAX, f32::min);
            let hx = v.iter().map(|p| p.0).fold(f32::MIN, f32::max);
            let lz = v.iter().map(|p| p.1).fold(f32::MAX, f32::min);
            let hz = v.iter().map(|p| p.1).fold(f32::MIN, f32::max);
            if hx < 0.0 || hz < 0.0 || lx >= N as f32 || lz >= N as f32 {
                continue;
            }
            let edge =
                |a: (f32, f32), b: (f32, f32), p: (f32, f32)| (b.0 - a.0) * (p.1 - a.1) - (b.1 - a.1) * (p.0 - a.0);
            let area = edge(v[0], v[1], v[2]);
            for cz in (lz.max(0.0) as usize)..=(hz.min(N as f32 - 1.0) as usize) {
                for cx in (lx.max(0.0) as usize)..=(hx.min(N as f32 - 1.0) as usize) {
                    let p = (cx as f32 + 0.5, cz as f32 + 0.5);
                    let (e0, e1, e2) = (edge(v[1], v[2], p), edge(v[2], v[0], p), edge(v[0], v[1], p));
                    let inside = if area >= 0.0 {
                        e0 >= 0.0 && e1 >= 0.0 && e2 >= 0.0
                    } else {
                        e0 <= 0.0 && e1 <= 0.0 && e2 <= 0.0
                    };
                    grid[cz * N + cx] |= inside;
                }
            }
        }
        grid
    };
    let grids: Vec<Vec<bool>> = scene
        .regions
        .iter()
        .map(|r| {
            let item = &scene.items[r.item];
            match (r.kind.as_str(), sun) {
                ("shadow", Some(l)) => raster(item, &|p: Vec3| p - l * ((p.y - floor_y).max(0.0) / l.y)),
                _ => raster(item, &|p: Vec3| p),
            }
        })
        .collect();
    let others: Vec<(Vec3, f32)> = scene
        .items
        .iter()
        .filter(|i| i.index != floor)
        .map(|i| {
            let (lo, hi) = (Vec3::from(i.bounds_min), Vec3::from(i.bounds_max));
            ((lo + hi) * 0.5, 0.5 * (hi.x - lo.x).max(hi.z - lo.z))
        })
        .collect();
    for (i, mask) in masks.iter_mut().enumerate() {
        if ids.id[i] != floor as i32 {
            continue;
        }
        let p = ids.position[i];
        let (cx, cz) = to_cell(p);
        if cx < 0.0 || cz < 0.0 || cx >= N as f32 || cz >= N as f32 {
            continue;
        }
        let c = cz as usize * N + cx as usize;
        let under_any = scene.regions.iter().zip(&grids).any(|(r, g)| r.kind == "under" && g[c]);
        for (k, (r, g)) in scene.regions.iter().zip(&grids).enumerate() {
            if g[c] && (r.kind == "under" || !under_any) {
                *mask |= 1 << k;
            }
        }
        let far = others
            .iter()
            .all(|(centre, h)| Vec3::new(p.x - centre.x, 0.0, p.z - centre.z).length() > scene.far_margin * h);
        if *mask == 0 && far {
            *mask |= 1 << FAR_BIT;
        }
    }
    masks
}

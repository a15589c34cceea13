//! Evaluating a graph for the comparison: its G-buffer's scene and camera, the image that enters
//! its Tonemap node, the probe and the brightest median-cut light; and writing them for a path
//! tracer (`werkstatt fidelity export`).

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::Instant;

use anyhow::{Context as _, bail};
use glam::Vec3;

use super::raster::{Albedo, PixelIds, cast, project};
use super::scene::{
    CONVENTIONS, CameraInfo, CheckPoint, EnvironmentInfo, ItemInfo, SceneInfo, SunInfo, find_floor, region_masks,
    regions,
};
use crate::core::eval::{Evaluator, FrameSettings, FrameTime};
use crate::core::graph::{Graph, PortRef};
use crate::core::param::ParamValue;
use crate::core::port::Value;
use crate::core::resources::Resources;
use crate::gpu::{GpuContext, Pixels};
use crate::io::geometry::GeometryPart;
use crate::mesh::Mesh;
use crate::render::draw::kind::{ExportCx, ExportDevice};
use crate::render::scene::{Camera, View};

#[derive(Clone, Debug)]
pub struct ExportOptions {
    pub graph_path: PathBuf,
    /// `node.param=value` overrides (one value each).
    pub sets: Vec<String>,
    /// Inputs to disconnect, `node.port` (e.g. `light.shadows`: IBL without the atlas).
    pub unlinks: Vec<String>,
    pub frame: i64,
    pub fps: f64,
    pub width: u32,
    pub height: u32,
}

/// A graph's view, evaluated.
pub struct Capture {
    pub scene: SceneInfo,
    /// The linear HDR image that enters the Tonemap node.
    pub image: Pixels,
    pub ids: PixelIds,
    /// The G-buffer's scene as one mesh (as drawn) and each item's triangles.
    pub mesh: Mesh,
    pub parts: Vec<GeometryPart>,
    /// Each item's base-colour texture: (width, height, sRGB RGBA8).
    pub textures: Vec<Option<(u32, u32, Vec<u8>)>>,
}

fn only_node<'a>(graph: &'a Graph, kind: &str) -> anyhow::Result<Option<&'a str>> {
    let ids: Vec<&str> = graph.nodes.iter().filter(|(_, n)| n.kind == kind).map(|(id, _)| id.as_str()).collect();
    match ids.as_slice() {
        [] => Ok(None),
        [one] => Ok(Some(one)),
        many => bail!("the graph has {} {kind} nodes ({}); the comparison needs one", many.len(), many.join(", ")),
    }
}

fn source(graph: &Graph, node: &str, port: &str) -> Option<PortRef> {
    graph.links.iter().find(|l| l.to.node == node && l.to.port == port).map(|l| l.from.clone())
}

/// Names of the items a scene output makes, in order: a Merge's inputs in turn, a Draw named by
/// the node that feeds its mesh; None where the graph does not say (then items are `item<i>`).
fn item_names(graph: &Graph, from: &PortRef) -> Option<Vec<String>> {
    let node = graph.nodes.get(&from.node)?;
    match node.kind.as_str() {
        "Merge" => {
            let mut out = Vec::new();
            for port in ["a", "b", "c", "d"] {
                if let Some(src) = source(graph, &from.node, port) {
                    out.extend(item_names(graph, &src)?);
                }
            }
            Some(out)
        }
        "Draw" => Some(vec![source(graph, &from.node, "mesh").map_or(from.node.clone(), |m| m.node)]),
        _ => None,
    }
}

fn param_f32(graph: &Graph, node: &str, name: &str) -> f32 {
    graph.param(node, name).and_then(|v| v.as_f64()).unwrap_or(0.0) as f32
}

/// Evaluates frame `opts.frame` of the graph (with its overrides and unlinked inputs) as batch
/// rendering does, and gathers what the comparison needs.
pub fn capture(opts: &ExportOptions, gpu: &GpuContext) -> anyhow::Result<Capture> {
    let mut graph = crate::app::render::load_with_overrides(&opts.graph_path, &opts.sets)?;
    for u in &opts.unlinks {
        let to = PortRef::parse(u).with_context(|| format!("--unlink \"{u}\": expected node.port"))?;
        let before = graph.links.len();
        graph.links.retain(|l| l.to != to);
        if graph.links.len() == before {
            bail!("--unlink {u}: nothing is linked to that input");
        }
    }
    let gbuffer = only_node(&graph, "GBufferPass")?.context("the graph has no GBufferPass")?.to_string();
    let tonemap = only_node(&graph, "Tonemap")?
        .context("the graph has no Tonemap node: the comparison takes the linear image that enters it")?
        .to_string();
    let environment = only_node(&graph, "EnvironmentMap")?.map(str::to_string);
    let median_cut = only_node(&graph, "MedianCut")?.map(str::to_string);
    let mut roots = vec![gbuffer.clone(), tonemap.clone()];
    roots.extend(median_cut.clone());
    let mut evaluator = Evaluator::new(&graph, &roots)?;
    let resources = Resources::new(false);
    let settings = FrameSettings {
        width: opts.width,
        height: opts.height,
        frames: Some((opts.frame, opts.frame)),
        base_dir: opts.graph_path.parent().map(Path::to_path_buf).unwrap_or_default(),
    };
    let time = FrameTime { frame: opts.frame, fps: opts.fps };
    let start = Instant::now();
    crate::app::render::settle(
        &mut evaluator,
        time,
        gpu,
        &resources,
        &settings,
        start,
        crate::app::render::PENDING_LIMIT,
        |_| {},
    )?;
    let failures = crate::app::render::failures(&evaluator);
    if !failures.is_empty() {
        bail!("frame {}: {}", opts.frame, failures.join("\n  "));
    }
    let Some(Value::Camera(camera)) = evaluator.input(&gbuffer, "camera").cloned() else {
        bail!("node \"{gbuffer}\" has no camera this frame");
    };
    let Some(Value::Scene(items)) = evaluator.input(&gbuffer, "scene").cloned() else {
        bail!("node \"{gbuffer}\" has no scene this frame");
    };
    let image = match evaluator.input(&tonemap, "image").and_then(Value::as_texture) {
        Some(t) => crate::gpu::read_back(gpu, t)?,
        None => bail!("node \"{tonemap}\" has no input image this frame"),
    };
    if (image.width, image.height) != (opts.width, opts.height) {
        bail!("the image entering \"{tonemap}\" is {}x{}, not the frame size", image.width, image.height);
    }
    let sun = median_cut.as_ref().and_then(|id| match evaluator.output(id, "lights") {
        Some(Value::Lights(lights)) => lights
            .lights
            .iter()
            .filter(|l| l.solid_angle > 0.0)
            .max_by(|a, b| {
                (crate::color::luminance(a.color) / a.solid_angle)
                    .total_cmp(&(crate::color::luminance(b.color) / b.solid_angle))
            })
            .map(|l| SunInfo { direction: l.direction.to_array(), solid_angle: l.solid_angle }),
        _ => None,
    });

    // The geometry as drawn, one part per item.
    let mut warper = crate::warp::gpu::GpuWarper::default();
    let mut export = ExportCx { gpu, device: ExportDevice::Cpu, warper: &mut warper, placements: false };
    let (mesh, parts) = crate::render::draw::export::flatten_parts(&mut export, &items)?;
    if parts.len() != items.len() {
        bail!(
            "{} of the scene's {} items have no triangles; the comparison needs every item drawn",
            items.len() - parts.len(),
            items.len()
        );
    }
    let names = source(&graph, &gbuffer, "scene")
        .and_then(|s| item_names(&graph, &s))
        .filter(|n| n.len() == items.len())
        .unwrap_or_else(|| (0..items.len()).map(|i| format!("item{i}")).collect());
    let textures: Vec<Option<(u32, u32, Vec<u8>)>> =
        items.iter().map(|i| i.material.texture.as_ref().map(|t| (t.width, t.height, srgb_rgba(t)))).collect();
    let mut infos = Vec::new();
    for (k, (item, part)) in items.iter().zip(&parts).enumerate() {
        let (mut lo, mut hi) = (Vec3::splat(f32::MAX), Vec3::splat(f32::MIN));
        for t in part.triangles.clone() {
            for &v in &mesh.indices[3 * t..3 * t + 3] {
                lo = lo.min(mesh.positions[v as usize]);
                hi = hi.max(mesh.positions[v as usize]);
            }
        }
        infos.push(ItemInfo {
            index: k,
            name: names[k].clone(),
            base_color: item.material.base_color.to_array(),
            glossiness: item.material.glossiness,
            texture: textures[k].as_ref().map(|_| format!("texture_{k}.png")),
            uv_scale: item.material.uv_scale,
            triangles: [part.triangles.start, part.triangles.end],
            bounds_min: lo.to_array(),
            bounds_max: hi.to_array(),
        });
    }
    let albedo: Vec<Albedo<'_>> = items
        .iter()
        .zip(&textures)
        .map(|(item, tex)| Albedo {
            base_color: item.material.base_color,
            texture: tex.as_ref().map(|(w, h, rgba)| (*w, *h, rgba.as_slice(), true)),
            uv_scale: item.material.uv_scale,
        })
        .collect();
    let item_of = |t: usize| parts.iter().position(|p| p.triangles.contains(&t)).unwrap_or(0);
    let ids = cast(&camera, opts.width, opts.height, &mesh, &item_of, &albedo);

    let env_info = match &environment {
        Some(id) => {
            let Some(ParamValue::Str(path)) = graph.param(id, "path") else { bail!("node \"{id}\" has no path") };
            let path = settings.base_dir.join(path);
            let path = path.canonicalize().with_context(|| format!("probe {}", path.display()))?;
            Some(EnvironmentInfo {
                path: path.display().to_string(),
                rotation_deg: param_f32(&graph, id, "rotation"),
                intensity: param_f32(&graph, id, "intensity"),
            })
        }
        None => None,
    };
    let open_floor_level = match &env_info {
        Some(e) => Some(open_floor(Path::new(&e.path))? * e.intensity),
        None => None,
    };
    let floor_item = find_floor(&infos);
    let floor_y = floor_item.map(|f| infos[f].bounds_max[1]);
    let regions = floor_item.map_or_else(Vec::new, |f| regions(&infos, f, sun.as_ref()));
    let view = View::new(&camera, opts.width, opts.height);
    let check_points = infos
        .iter()
        .flat_map(|i| {
            (0..8).map(move |c| {
                Vec3::new(
                    if c & 1 == 0 { i.bounds_min[0] } else { i.bounds_max[0] },
                    if c & 2 == 0 { i.bounds_min[1] } else { i.bounds_max[1] },
                    if c & 4 == 0 { i.bounds_min[2] } else { i.bounds_max[2] },
                )
            })
        })
        .filter_map(|p| project(&view, p).map(|px| CheckPoint { world: p.to_array(), pixel: px.to_array() }))
        .collect();
    let scene = SceneInfo {
        conventions: CONVENTIONS.to_string(),
        graph: opts.graph_path.display().to_string(),
        sets: opts.sets.clone(),
        unlinks: opts.unlinks.clone(),
        frame: opts.frame,
        fps: opts.fps,
        width: opts.width,
        height: opts.height,
        camera: camera_info(&camera),
        environment: env_info,
        sun,
        floor_item,
        floor_y,
        open_floor_level,
        items: infos,
        regions,
        far_margin: 1.5,
        ids_gbuffer_mismatch: None,
        check_points,
    };
    let mut ids = ids;
    ids.regions = region_masks(&scene, &mesh, &ids);
    let mut scene = scene;
    if let Some(Value::GBuffer(g)) = evaluator.output(&gbuffer, "gbuffer") {
        scene.ids_gbuffer_mismatch = Some(mismatch(&crate::gpu::read_back(gpu, &g.depth)?, &ids, &view));
    }
    Ok(Capture { scene, image, ids, mesh, parts, textures })
}

/// The fraction of pixels where the ray-cast ids and the G-buffer disagree: one hit something
/// and the other nothing, or their view depths differ by more than 1%.
fn mismatch(depth: &Pixels, ids: &PixelIds, view: &View) -> f32 {
    let forward = -view.inv_view.z_axis.truncate().normalize();
    let n = ids.id.len();
    if depth.rgba.len() != 4 * n {
        return 1.0;
    }
    let bad = (0..n)
        .filter(|&i| {
            let gpu = depth.rgba[4 * i];
            match ids.id[i] >= 0 {
                false => gpu > 0.0,
                true => {
                    let ray = (ids.position[i] - view.eye).dot(forward);
                    gpu <= 0.0 || (gpu - ray).abs() > 0.01 * ray
                }
            }
        })
        .count();
    bad as f32 / n.max(1) as f32
}

fn camera_info(c: &Camera) -> CameraInfo {
    CameraInfo {
        eye: c.eye.to_array(),
        target: c.target.to_array(),
        up: c.up.to_array(),
        fov_y_degrees: c.fov_y_degrees,
        near: c.near,
        far: c.far,
    }
}

/// A material texture's texels as sRGB-encoded RGBA8 (data maps are stored as they are).
fn srgb_rgba(t: &Arc<crate::render::scene::Image8>) -> Vec<u8> {
    if t.srgb {
        return t.rgba.clone();
    }
    t.rgba
        .iter()
        .enumerate()
        .map(
            |(i, &c)| {
                if i % 4 == 3 { c } else { (255.0 * crate::color::linear_to_srgb(c as f32 / 255.0)).round() as u8 }
            },
        )
        .collect()
}

/// Radiance over albedo of an unoccluded Lambertian floor (normal +Y) under the probe file, as
/// luminance: (1/pi) sum over the map's texels of L cos(theta) dOmega for the upper hemisphere.
/// A rotation about +Y does not change it.
pub fn open_floor(path: &Path) -> anyhow::Result<f32> {
    let eq = crate::ibl::cube::EquirectImage::load(path)?;
    let (w, h) = (eq.width, eq.height);
    let mut sum = 0.0f64;
    for y in 0..h {
        let theta0 = std::f64::consts::PI * y as f64 / h as f64;
        let theta1 = std::f64::consts::PI * (y + 1) as f64 / h as f64;
        // Integral of cos(theta) sin(theta) over the row, times the row's azimuth step.
        let (c0, c1) = (theta0.cos().max(0.0), theta1.cos().max(0.0));
        let weight = 0.5 * (c0 * c0 - c1 * c1) * std::f64::consts::TAU / w as f64;
        if weight <= 0.0 {
            continue;
        }
        for x in 0..w {
            sum += weight * crate::color::luminance(eq.rgb[y * w + x]) as f64;
        }
    }
    Ok((sum / std::f64::consts::PI) as f32)
}

/// Writes `werkstatt fidelity export`'s folder: scene.glb, scene.json, texture_<i>.png,
/// werkstatt.exr (linear HDR entering Tonemap), ids.exr (R: item index or -1, G B A: world
/// position of the visible point), albedo.exr (the albedo the ids saw, RGB) and regions.exr (R:
/// each pixel's region mask, `scene::region_masks`).
pub fn export(opts: &ExportOptions, gpu: &GpuContext, out: &Path) -> anyhow::Result<Capture> {
    let cap = capture(opts, gpu)?;
    std::fs::create_dir_all(out).with_context(|| format!("cannot create {}", out.display()))?;
    crate::io::geometry::write_glb(&out.join("scene.glb"), &cap.mesh, &cap.parts)?;
    for (k, t) in cap.textures.iter().enumerate() {
        if let Some((w, h, rgba)) = t {
            let img = image::RgbaImage::from_raw(*w, *h, rgba.clone()).context("texture size")?;
            let mut bytes = std::io::Cursor::new(Vec::new());
            img.write_to(&mut bytes, image::ImageFormat::Png)?;
            crate::io::atomic::write_atomic(&out.join(format!("texture_{k}.png")), bytes.get_ref())?;
        }
    }
    let json = serde_json::to_string_pretty(&cap.scene)?;
    crate::io::atomic::write_atomic(&out.join("scene.json"), json.as_bytes())?;
    crate::io::image::write_exr(&out.join("werkstatt.exr"), &cap.image)?;
    let (w, h) = (cap.ids.width, cap.ids.height);
    let ids = Pixels {
        width: w,
        height: h,
        rgba: (0..(w * h) as usize)
            .flat_map(|i| {
                let p = cap.ids.position[i];
                [cap.ids.id[i] as f32, p.x, p.y, p.z]
            })
            .collect(),
        is_ldr: false,
    };
    crate::io::image::write_exr(&out.join("ids.exr"), &ids)?;
    let albedo = Pixels {
        width: w,
        height: h,
        rgba: cap.ids.albedo.iter().flat_map(|a| [a.x, a.y, a.z, 1.0]).collect(),
        is_ldr: false,
    };
    crate::io::image::write_exr(&out.join("albedo.exr"), &albedo)?;
    let regions = Pixels {
        width: w,
        height: h,
        rgba: cap.ids.regions.iter().flat_map(|&m| [m as f32, 0.0, 0.0, 1.0]).collect(),
        is_ldr: false,
    };
    crate::io::image::write_exr(&out.join("regions.exr"), &regions)?;
    Ok(cap)
}

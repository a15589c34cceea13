//! `WovenCloth`: woven fabric as panel, yarns or fibres (Zhang et al. 2012, IDSS; src/woven/).
//! The surface is resampled per pattern piece into a regular control grid, each patch gets its
//! level of detail, and the CPU evaluates the geomorphed, crack-free tessellation every run.

use std::sync::Arc;

use glam::{Mat4, Vec2, Vec3};

use crate::core::node::prelude::*;
use crate::mesh::Mesh;
use crate::render::draw::kinds::woven::{LAYER_NAMES, WovenGpu, WovenLayer};
use crate::render::scene::{Camera, DrawItem, Material, View};
use crate::woven::gpu::{GpuWoven, culled_patches, patch_levels};
use crate::woven::lod::{MAX_LEVEL, Morph};
use crate::woven::panel::Panel;
use crate::woven::resample::resample;
use crate::woven::tess::{Layer, Woven};
use crate::woven::weave::Weave;
use crate::woven::yarn::YarnParams;

crate::choice!(
    /// Where the patches are tessellated.
    pub enum Evaluate {
        Gpu = "gpu",
        Cpu = "cpu",
    }
);

crate::choice!(
    /// The weave pattern η.
    pub enum WeaveKind {
        Plain = "plain",
        Twill = "twill",
        Satin = "satin",
        Custom = "custom",
    }
);

pub static WOVEN_CLOTH: NodeSpec = NodeSpec {
    kind: "WovenCloth",
    category: Category::Geometry,
    doc: "Woven fabric at three scales (Zhang et al. 2012, IDSS): the surface resampled per pattern piece into a regular control grid of woven patches (16x16 nodes each by default), drawn as a smooth panel (L 0-4), swept yarns (5-9) or twisted fibres (10-14), geomorphed between levels and crack-free between patches. Evaluated in compute shaders and drawn with indirect arguments (or on the CPU, the reference twin); patches outside the camera's view are culled. Outputs up to three items per pattern piece (panel, weft, warp).",
    inputs: &[
        PortSpec::required("surface", PortType::Mesh, "The cloth: a Surface (per pattern piece) or a mesh with UVs."),
        PortSpec::optional("camera", PortType::Camera, "The view the adaptive levels are chosen for (eq. 16)."),
    ],
    outputs: &[
        PortSpec::output("scene", PortType::Scene, "The panel, weft and warp items (those with triangles)."),
        PortSpec::output(
            "wireframe",
            PortType::Mesh,
            "The drawn triangles' edges as thin ribbons (for figures; empty unless linked).",
        ),
    ],
    params: &[
        ParamSpec::new(
            "weave",
            ParamKind::Choice { default: "plain", options: WeaveKind::OPTIONS },
            "plain, twill (twill_over/twill_under), satin (satin_n) or custom (pattern).",
        ),
        ParamSpec::new(
            "twill_over",
            ParamKind::Int { default: 2, min: 1, max: 16 },
            "Twill: warps the weft floats over.",
        ),
        ParamSpec::new(
            "twill_under",
            ParamKind::Int { default: 1, min: 1, max: 16 },
            "Twill: warps the weft passes under.",
        ),
        ParamSpec::new(
            "satin_n",
            ParamKind::Int { default: 5, min: 3, max: 32 },
            "Satin: harnesses (5, 7, 8, ...: a regular satin needs a step coprime with n).",
        ),
        ParamSpec::new(
            "pattern",
            ParamKind::Text { default: "10/01" },
            "Custom weave: rows (wefts) of 0/1 separated by '/', 1 = weft over.",
        ),
        ParamSpec::new(
            "nodes",
            ParamKind::Int { default: 16, min: 1, max: 64 },
            "Interlaced nodes per patch side (the paper's 16).",
        ),
        ParamSpec::new(
            "spacing",
            ParamKind::Float { default: 0.01, min: 0.0, max: 10.0 },
            "S: distance between neighbouring yarns, in scene units; a patch is nodes x spacing.",
        ),
        ParamSpec::new(
            "crimp",
            ParamKind::Float { default: 0.004, min: 0.0, max: 10.0 },
            "H: the yarns' offset from the panel at a crossing.",
        ),
        ParamSpec::new("radius", ParamKind::Float { default: 0.004, min: 0.0, max: 10.0 }, "K: the yarn radius."),
        ParamSpec::new("weft_color", ParamKind::Color { default: [0.75, 0.2, 0.15] }, "Linear RGB of the wefts."),
        ParamSpec::new("warp_color", ParamKind::Color { default: [0.85, 0.8, 0.7] }, "Linear RGB of the warps."),
        ParamSpec::new(
            "glossiness",
            ParamKind::Float { default: 0.3, min: 0.0, max: 1.0 },
            "Glossiness of all three items.",
        ),
        ParamSpec::new(
            "panel_btf_id",
            ParamKind::Int { default: 0, min: 0, max: 65535 },
            "The panel layer's btf_id (levels 0-4, one quad per patch): a BtfShading node whose material_id equals it shades the far patches with a BTF (a Btf baked from the same weave, tiled once per weave repeat); 0: the panel is shaded as geometry in the warp and weft colours mixed by cover. The yarn and fibre layers are always geometry.",
        ),
        ParamSpec::new(
            "fibres",
            ParamKind::Int { default: 6, min: 1, max: 32 },
            "Fibres per yarn, on one ring (radius from packing).",
        ),
        ParamSpec::new(
            "migration",
            ParamKind::Float { default: 0.3, min: 0.0, max: 1.0 },
            "Radial fibre migration: r(u) between (1 - migration) r0 and r0.",
        ),
        ParamSpec::new(
            "twist",
            ParamKind::Float { default: 0.5, min: -8.0, max: 8.0 },
            "Fibre turns around the yarn per node spacing.",
        ),
        ParamSpec::new(
            "level",
            ParamKind::Float { default: -1.0, min: -1.0, max: 1e6 },
            "A fixed level of detail L in [0, 14] for every patch; negative: adaptive from the camera (eq. 16).",
        ),
        ParamSpec::new(
            "wire_width",
            ParamKind::Float { default: 0.001, min: 1e-6, max: 1.0 },
            "Width of the wireframe output's ribbons, in scene units.",
        ),
        ParamSpec::new(
            "max_triangles",
            ParamKind::Int { default: 4_000_000, min: 1, max: 1 << 30 },
            "A budget: the node fails, naming the levels, rather than evaluate more triangles than this.",
        ),
        ParamSpec::new(
            "evaluate",
            ParamKind::Choice { default: "gpu", options: Evaluate::OPTIONS },
            "gpu: compute shaders, drawn with indirect arguments, patches outside the view culled; cpu: the reference evaluation, drawn as plain meshes.",
        ),
        ParamSpec::new(
            "lod_c",
            ParamKind::Float { default: 0.02, min: 0.0, max: 1e6 },
            "C of eq. 16, L = c / (C |p_c - p_e|): smaller C, finer levels.",
        ),
        ParamSpec::new(
            "snap",
            ParamKind::Bool { default: true },
            "Crack snapping at shared patch borders (eq. 21); off only to show the cracks it closes (Fig. 9).",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(WovenClothNode::default()),
};

#[derive(Default)]
struct WovenClothNode {
    gpu: GpuWoven,
}

fn port_err(port: &str, e: impl std::fmt::Display) -> NodeError {
    NodeError::msg(format!("WovenCloth, port \"{port}\": {e}"))
}

impl Node for WovenClothNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let mesh: Arc<Mesh> = cx.input("surface")?;
        let weave = match cx.choice::<WeaveKind>("weave") {
            WeaveKind::Plain => Weave::plain(),
            WeaveKind::Twill => Weave::twill(cx.int("twill_over") as usize, cx.int("twill_under") as usize)
                .map_err(|e| port_err("twill_over", e))?,
            WeaveKind::Satin => Weave::satin(cx.int("satin_n") as usize).map_err(|e| port_err("satin_n", e))?,
            WeaveKind::Custom => Weave::parse(cx.str("pattern")).map_err(|e| port_err("pattern", e))?,
        };
        let yarn = YarnParams {
            nodes: cx.int("nodes") as usize,
            spacing: cx.f64("spacing"),
            crimp: cx.f64("crimp"),
            radius: cx.f64("radius"),
            fibres: cx.int("fibres") as usize,
            migration: cx.f64("migration"),
            twist: cx.f64("twist"),
        };
        if yarn.spacing <= 0.0 {
            return Err(port_err("spacing", format!("must be positive (got {})", yarn.spacing)));
        }
        if yarn.radius <= 0.0 {
            return Err(port_err("radius", format!("must be positive (got {})", yarn.radius)));
        }
        yarn.validate().map_err(|e| port_err("spacing", e))?;
        let fixed = cx.f64("level");
        if fixed > MAX_LEVEL {
            return Err(port_err("level", format!("{fixed} is above the finest level {MAX_LEVEL} (fibre scale)")));
        }
        let coef = cx.f64("lod_c");
        let snap = cx.bool("snap");
        let camera: Option<Camera> = cx.optional("camera");
        let eye = if fixed < 0.0 {
            if coef <= 0.0 {
                return Err(port_err("lod_c", format!("must be positive for adaptive levels (got {coef})")));
            }
            let camera = camera.as_ref().ok_or_else(|| {
                port_err("camera", "adaptive levels (level < 0) need a camera; link one or set a fixed level")
            })?;
            Some(camera.eye.as_dvec3())
        } else {
            None
        };
        let on_gpu = cx.choice::<Evaluate>("evaluate") == Evaluate::Gpu;
        // Only a camera makes the frame size matter (and re-run this node when it changes).
        let view_proj = camera.map(|c| {
            let (w, h) = cx.frame_size();
            View::new(&c, w, h).view_proj.as_dmat4()
        });
        let patch = yarn.nodes as f64 * yarn.spacing;
        let grids = resample(&mesh, patch).map_err(|e| port_err("surface", e))?;
        let budget = cx.int("max_triangles") as usize;
        let wire_linked = cx.output_linked("wireframe");
        let (weft, warp) = (cx.vec3("weft_color"), cx.vec3("warp_color"));
        let cover = weave.weft_cover() as f32;
        let gloss = cx.f32("glossiness");
        // The panel layer carries the BTF id: far patches switch from geometry to the BTF at
        // the panel scale (L < 4), where the yarns have not yet risen from the panel.
        let panel_btf = u16::try_from(cx.int("panel_btf_id")).unwrap_or(0);
        let materials =
            [(weft * cover + warp * (1.0 - cover), panel_btf), (weft, 0), (warp, 0)].map(|(color, btf_id)| {
                Arc::new(Material { base_color: color, glossiness: gloss, btf_id, ..Default::default() })
            });
        let names = LAYER_NAMES;
        let mut planned = 0;
        let mut layers: [Layer; 3] = Default::default();
        let mut scales = [0; 3];
        let mut culled_total = 0;
        let mut gpu_items = Vec::new();
        for (gi, pg) in grids.iter().enumerate() {
            let panel = Arc::new(Panel { flip: pg.flipped, ..Panel::new(&pg.grid) });
            let levels =
                patch_levels(&panel, &pg.inside, eye.is_none().then_some(fixed), coef, eye.unwrap_or_default());
            let woven = Woven { panel: &panel, weave: &weave, yarn: &yarn, morph: Morph::Continuous, snap };
            // Only the GPU path culls: the CPU evaluation stays the whole reference.
            let culled = culled_patches(&woven, view_proj.as_ref().filter(|_| on_gpu));
            planned += levels
                .iter()
                .zip(&culled)
                .filter_map(|(l, &c)| l.filter(|_| !c))
                .map(|l| woven.patch_triangles(l))
                .sum::<usize>();
            if planned > budget {
                let port = if eye.is_some() { "lod_c" } else { "level" };
                let top = levels.iter().flatten().fold(0.0f64, |a, &b| a.max(b));
                return Err(port_err(
                    port,
                    format!(
                        "the levels (up to {top:.2}) would make over {planned} triangles, more than max_triangles ({budget}): lower the level (raise lod_c) or raise the spacing"
                    ),
                ));
            }
            if on_gpu {
                let frame = self.gpu.run(cx.gpu()?, &woven, &levels, &culled)?;
                scales.iter_mut().zip(frame.scales).for_each(|(a, b)| *a += b);
                culled_total += frame.culled;
                let coarse = Arc::new(coarse_panel(&panel, &pg.inside));
                for (k, layer) in frame.layers.into_iter().enumerate() {
                    let Some(layer) = layer else { continue };
                    let (panel, weave, yarn, levels, culled) =
                        (panel.clone(), weave.clone(), yarn.clone(), levels.clone(), culled.clone());
                    let cpu_reference = Box::new(move || {
                        let woven = Woven { panel: &panel, weave: &weave, yarn: &yarn, morph: Morph::Continuous, snap };
                        let t = woven.tessellate_culled(&levels, &culled)?;
                        Ok(to_mesh([t.panel, t.weft, t.warp].into_iter().nth(k).unwrap_or_default()))
                    });
                    let name = if grids.len() == 1 { names[k].to_string() } else { format!("{}_{gi}", names[k]) };
                    let item = DrawItem::plain(coarse.clone(), materials[k].clone(), Mat4::IDENTITY)
                        .with_kind(WovenLayer {
                            layer: names[k],
                            scales: [0; 3],
                            culled: 0,
                            gpu: Some(Arc::new(WovenGpu { layer, cpu_reference })),
                        })
                        .named(format!("{}_{name}", cx.node_id));
                    gpu_items.push(item);
                }
            }
            if !on_gpu || wire_linked {
                let t = woven.tessellate_culled(&levels, &culled)?;
                if !on_gpu {
                    scales.iter_mut().zip(t.scales).for_each(|(a, b)| *a += b);
                }
                for (acc, l) in layers.iter_mut().zip([t.panel, t.weft, t.warp]) {
                    append(acc, l);
                }
            }
        }
        let cpu_meshes: Vec<Mesh> = layers.into_iter().map(to_mesh).collect();
        let mut items = Vec::new();
        if on_gpu {
            for mut item in gpu_items {
                if let Some(k) = item.kind_as::<WovenLayer>().cloned() {
                    item = item.with_kind(WovenLayer { scales, culled: culled_total, ..k });
                }
                items.push(item);
            }
        } else {
            for (k, m) in cpu_meshes.iter().enumerate() {
                if m.indices.is_empty() {
                    continue;
                }
                let item = DrawItem::plain(Arc::new(m.clone()), materials[k].clone(), Mat4::IDENTITY)
                    .with_kind(WovenLayer { layer: names[k], scales, culled: 0, gpu: None })
                    .named(format!("{}_{}", cx.node_id, names[k]));
                items.push(item);
            }
        }
        cx.count("patches_panel", scales[0]);
        cx.count("patches_yarn", scales[1]);
        cx.count("patches_fibre", scales[2]);
        cx.count("patches_culled", culled_total);
        cx.count("triangles", items.iter().map(|i| i.kind.drawn_triangles(i)).sum());
        let wire = if wire_linked && cpu_meshes.iter().any(|m| !m.indices.is_empty()) {
            let (mut vertices, mut indices) = (Vec::new(), Vec::new());
            for m in &cpu_meshes {
                let base = vertices.len() as u32;
                vertices.extend(m.positions.iter().zip(&m.normals).map(|(p, n)| crate::mesh::Vertex {
                    position: p.to_array(),
                    normal: n.to_array(),
                    tangent_u: [0.0; 3],
                    uv: [0.0; 2],
                    tangent_v: [0.0; 3],
                }));
                indices.extend(m.indices.iter().map(|i| i + base));
            }
            crate::tessellation::wireframe(&vertices, &indices, cx.f32("wire_width"))?
        } else {
            Mesh::default()
        };
        cx.set("wireframe", Arc::new(wire));
        cx.set("scene", Arc::new(items));
        Ok(())
    }
}

/// The panel at level 0, one quad per patch (the bounds and CPU shape of GPU-drawn items).
fn coarse_panel(panel: &Panel, inside: &[bool]) -> Mesh {
    let (mut positions, mut normals, mut uvs, mut indices) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (pu, pv) = (panel.patches_u, panel.patches_v);
    for (k, _) in inside.iter().enumerate().filter(|(_, i)| **i) {
        let (pi, pj) = (k % pu, k / pu);
        let base = positions.len() as u32;
        for (s, t) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            positions.push(panel.position(pi, pj, s, t).as_vec3());
            normals.push(panel.frame(pi, pj, s, t).n.as_vec3());
            uvs.push(Vec2::new((pi as f32 + s as f32) / pu as f32, (pj as f32 + t as f32) / pv as f32));
        }
        indices.extend_from_slice(&[base, base + 1, base + 3, base, base + 3, base + 2]);
    }
    Mesh::from_raw(positions, normals, uvs, Vec::new(), Vec::new(), indices)
}

fn append(acc: &mut Layer, l: Layer) {
    let base = acc.positions.len() as u32;
    acc.positions.extend(l.positions);
    acc.normals.extend(l.normals);
    acc.uvs.extend(l.uvs);
    acc.outer.extend(l.outer);
    acc.indices.extend(l.indices.into_iter().map(|i| i + base));
}

/// The drawn mesh of a layer (single precision, as the GPU draws it).
pub fn to_mesh(l: Layer) -> Mesh {
    Mesh::from_raw(
        l.positions.iter().map(|p| p.as_vec3()).collect(),
        l.normals.iter().map(|n| n.as_vec3().try_normalize().unwrap_or(Vec3::Y)).collect(),
        l.uvs.iter().map(|u| Vec2::new(u[0] as f32, u[1] as f32)).collect(),
        Vec::new(),
        Vec::new(),
        l.indices,
    )
}

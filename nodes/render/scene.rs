//! Materials and drawable items: what a G-buffer pass draws.

use std::sync::Arc;

use glam::Vec3;

use crate::core::node::prelude::*;
use crate::mesh::Mesh;
use crate::render::scene::{DrawItem, Image8, Material};

pub static MATERIAL: NodeSpec = NodeSpec {
    kind: "Material",
    category: Category::Scene,
    doc: "Base colour and glossiness, optionally modulated by a texture (a procedural checker or an image file).",
    inputs: &[],
    outputs: &[PortSpec::output("material", PortType::Material, "The material.")],
    params: &[
        ParamSpec::new("base_color", ParamKind::Color { default: [0.8, 0.8, 0.8] }, "Linear RGB base colour."),
        ParamSpec::new("glossiness", ParamKind::Float { default: 0.2, min: 0.0, max: 1.0 }, "0 rough, 1 mirror-like."),
        ParamSpec::new("texture", ParamKind::Choice { default: "none", options: BaseMap::OPTIONS }, "Base-colour map."),
        ParamSpec::new(
            "texture_path",
            ParamKind::Path { default: "", extensions: &["png", "jpg", "jpeg"] },
            "Image for texture = file.",
        ),
        ParamSpec::new("checker_color", ParamKind::Color { default: [0.2, 0.2, 0.2] }, "Second colour of the checker."),
        ParamSpec::new(
            "uv_scale",
            ParamKind::Float { default: 8.0, min: 1e-3, max: 1e4 },
            "Texture repeats per UV unit.",
        ),
        ParamSpec::new(
            "gloss_map",
            ParamKind::Choice { default: "none", options: GlossMap::OPTIONS },
            "Glossiness parameter map (Fig. 5.23): satin stripes, or an image whose red channel blends gloss_min..glossiness.",
        ),
        ParamSpec::new(
            "gloss_map_path",
            ParamKind::Path { default: "", extensions: &["png", "jpg", "jpeg"] },
            "Image for gloss_map = file (read as data, not colour).",
        ),
        ParamSpec::new(
            "gloss_min",
            ParamKind::Float { default: 0.0, min: 0.0, max: 1.0 },
            "Glossiness where the map is 0.",
        ),
        ParamSpec::new(
            "btf_id",
            ParamKind::Int { default: 0, min: 0, max: 65535 },
            "Marks the material for the BtfShading node whose material_id equals it (written to the G-buffer's surface target); 0: none.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(MaterialNode),
};

crate::choice!(
    enum BaseMap {
        None = "none",
        Checker = "checker",
        File = "file",
    }
);

crate::choice!(
    enum GlossMap {
        None = "none",
        Stripes = "stripes",
        File = "file",
    }
);

struct MaterialNode;
impl Node for MaterialNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let texture = match cx.choice::<BaseMap>("texture") {
            BaseMap::Checker => Some(Arc::new(checker(cx.vec3("checker_color")))),
            BaseMap::File => {
                if cx.str("texture_path").is_empty() {
                    return Err(NodeError::msg("texture = \"file\" but parameter \"texture_path\" is empty"));
                }
                let path = cx.path("texture_path");
                Some(cx.load(&path, load_image)?)
            }
            BaseMap::None => None,
        };
        let gloss_map = match cx.choice::<GlossMap>("gloss_map") {
            GlossMap::Stripes => Some(Arc::new(stripes())),
            GlossMap::File => {
                if cx.str("gloss_map_path").is_empty() {
                    return Err(NodeError::msg("gloss_map = \"file\" but parameter \"gloss_map_path\" is empty"));
                }
                let path = cx.path("gloss_map_path");
                let img = cx.load(&path, load_image)?;
                Some(Arc::new(Image8::new_linear(img.width, img.height, img.rgba.clone())))
            }
            GlossMap::None => None,
        };
        cx.set(
            "material",
            Value::Material(Arc::new(Material {
                base_color: cx.vec3("base_color"),
                glossiness: cx.f32("glossiness"),
                texture,
                uv_scale: cx.f32("uv_scale"),
                gloss_map,
                gloss_min: cx.f32("gloss_min"),
                btf_id: cx.int("btf_id") as u16,
            })),
        );
        Ok(())
    }
}

/// An 8x8 checker of white and `dark` (linear), stored sRGB-encoded.
fn checker(dark: Vec3) -> Image8 {
    let n = 64u32;
    let encode = |c: f32| (255.0 * crate::color::linear_to_srgb(c.clamp(0.0, 1.0))).round() as u8;
    let dark = [encode(dark.x), encode(dark.y), encode(dark.z), 255];
    let mut rgba = Vec::with_capacity((n * n * 4) as usize);
    for y in 0..n {
        for x in 0..n {
            let odd = ((x / 8) + (y / 8)) % 2 == 1;
            rgba.extend_from_slice(if odd { &dark } else { &[255, 255, 255, 255] });
        }
    }
    Image8::new(n, n, rgba)
}

/// Satin stripes: 8 glossy (1) and 8 matte (0) bands along u, a data map.
fn stripes() -> Image8 {
    let n = 64u32;
    let mut rgba = Vec::with_capacity((n * n * 4) as usize);
    for _y in 0..n {
        for x in 0..n {
            let v = if (x / 4) % 2 == 0 { 255 } else { 0 };
            rgba.extend_from_slice(&[v, v, v, 255]);
        }
    }
    Image8::new_linear(n, n, rgba)
}

fn load_image(path: &std::path::Path) -> anyhow::Result<Image8> {
    let img = image::open(path).map_err(|e| anyhow::anyhow!("cannot read image: {e}"))?.to_rgba8();
    Ok(Image8::new(img.width(), img.height(), img.into_raw()))
}

pub static DRAW: NodeSpec = NodeSpec {
    kind: "Draw",
    category: Category::Scene,
    doc: "Places a mesh with a material and a transform (scale, then rotate XYZ in degrees, then translate).",
    inputs: &[
        PortSpec::required("mesh", PortType::Mesh, "What to draw."),
        PortSpec::optional("material", PortType::Material, "Its material (default: light grey)."),
    ],
    outputs: &[PortSpec::output("scene", PortType::Scene, "One draw item.")],
    params: &[
        crate::nodes::mesh::geometry::TRANSLATE,
        crate::nodes::mesh::geometry::ROTATE,
        crate::nodes::mesh::geometry::SCALE,
        ParamSpec::new(
            "detail",
            ParamKind::Bool { default: false },
            "Mark as detail geometry: the G-buffer normal's alpha is 1 (no pass reads the flag yet).",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(DrawNode),
};

struct DrawNode;
impl Node for DrawNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let mesh: Arc<Mesh> = cx.input("mesh")?;
        let material = cx.optional("material").unwrap_or_else(|| Arc::new(Material::default()));
        let model = crate::nodes::mesh::geometry::model_matrix(cx)?;
        cx.count("triangles", mesh.triangle_count());
        let item = DrawItem { detail: cx.bool("detail"), ..DrawItem::plain(mesh, material, model) }.named(cx.node_id);
        cx.set("scene", Arc::new(vec![item]));
        Ok(())
    }
}

pub static MERGE: NodeSpec = NodeSpec {
    kind: "Merge",
    category: Category::Scene,
    doc: "Combines up to four scenes into one.",
    inputs: &[
        PortSpec::optional("a", PortType::Scene, "Scene a."),
        PortSpec::optional("b", PortType::Scene, "Scene b."),
        PortSpec::optional("c", PortType::Scene, "Scene c."),
        PortSpec::optional("d", PortType::Scene, "Scene d."),
    ],
    outputs: &[PortSpec::output("scene", PortType::Scene, "All items, in input order.")],
    params: &[ParamSpec::new(
        "check_units",
        ParamKind::Bool { default: true },
        "Warn when the inputs' largest meshes (200 triangles or more, not attachments) differ in size by more than 10x: a body and a garment in different units. Off for scenes that mean it (a small collider under a large cloth).",
    )],
    capabilities: Capabilities::NONE,
    create: || Box::new(MergeNode),
};

struct MergeNode;
impl Node for MergeNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let mut items = Vec::new();
        // The largest mesh of each input, for the units check below.
        let mut sizes = Vec::new();
        for port in ["a", "b", "c", "d"] {
            if let Some(s) = cx.optional::<Arc<Vec<DrawItem>>>(port) {
                items.extend(s.iter().cloned());
                if let Some(size) = s.iter().filter_map(mesh_size).reduce(f32::max) {
                    sizes.push((port, size));
                }
            }
        }
        if let Some(warning) = units_mismatch(&sizes).filter(|_| cx.bool("check_units")) {
            cx.warn(warning);
        }
        cx.set("scene", Arc::new(items));
        Ok(())
    }
}

/// The world-space diagonal of an item's mesh, for items that are whole objects: coarse meshes
/// of at least 200 triangles (not attachments, floors or markers).
fn mesh_size(item: &DrawItem) -> Option<f32> {
    if item.detail || item.mesh.triangle_count() < 200 {
        return None;
    }
    let (lo, hi) = item.mesh.bounds();
    let corners = (0..8).map(|i| {
        let pick = |bit: usize, axis: usize| if i >> bit & 1 == 1 { hi[axis] } else { lo[axis] };
        item.model.transform_point3(glam::Vec3::new(pick(0, 0), pick(1, 1), pick(2, 2)))
    });
    let (wlo, whi) =
        corners.fold((glam::Vec3::splat(f32::MAX), glam::Vec3::splat(f32::MIN)), |(a, b), p| (a.min(p), b.max(p)));
    Some((whi - wlo).length()).filter(|d| d.is_finite() && *d > 0.0)
}

/// A warning when the inputs' largest meshes differ in size by more than 10x: a body and a
/// garment from files in different units, or one normalized and the other not.
fn units_mismatch(sizes: &[(&str, f32)]) -> Option<String> {
    let small = sizes.iter().min_by(|a, b| a.1.total_cmp(&b.1))?;
    let large = sizes.iter().max_by(|a, b| a.1.total_cmp(&b.1))?;
    (large.1 > 10.0 * small.1).then(|| {
        format!(
            "the meshes of input \"{}\" ({:.3} across) and input \"{}\" ({:.3} across) differ in size by {:.0}x: \
             files in different units, or one MeshFile normalized and the other not? (MeshFile keeps the file's units \
             unless normalize is on)",
            small.0,
            small.1,
            large.0,
            large.1,
            large.1 / small.1
        )
    })
}

#[cfg(test)]
mod tests {
    #[test]
    fn inputs_ten_times_apart_in_size_are_named() {
        assert_eq!(super::units_mismatch(&[("a", 1.8), ("b", 1.2)]), None);
        let w = super::units_mismatch(&[("a", 1.8), ("b", 0.17)]).unwrap();
        assert!(w.contains("input \"b\" (0.170 across)") && w.contains("input \"a\" (1.800 across)"), "{w}");
        assert!(w.contains("11x"), "{w}");
        assert_eq!(super::units_mismatch(&[("a", 1.0)]), None);
    }
}

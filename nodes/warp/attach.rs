//! Deferred warping, pass 2: point, area and curve attachments (paper sections 3.3-3.6).
//! Each node turns placements into per-instance transforms (M_tex, M_tan, curve pieces);
//! the G-buffer pass warps the detail mesh through the matrix texture in its vertex shader.

use std::sync::Arc;

use glam::{Affine2, Mat4, Quat, Vec2, Vec3};

use crate::core::node::prelude::*;
use crate::mesh::Mesh;
use crate::render::scene::{DrawItem, Material};
use crate::warp::{ArcTable, AttachedDraw, Curves, InstanceData, MatrixTexture, Placement, WarpMode, WarpSettings};

const MATRIX: PortSpec = PortSpec::required("matrix", PortType::MatrixTexture, "The surface's matrix texture.");
const DETAIL: PortSpec =
    PortSpec::required("mesh", PortType::Mesh, "The detail geometry, in tangent space (y = normal).");
const MATERIAL: PortSpec = PortSpec::optional("material", PortType::Material, "Its material.");
const SCENE: PortSpec = PortSpec::output("scene", PortType::Scene, "The attached geometry, drawn as detail.");
const GRAVITY: ParamSpec = ParamSpec::new(
    "gravity",
    ParamKind::Float { default: 0.0, min: 0.0, max: 1e4 },
    "Fur post-process c of eqs. 11-12: bends vertices down by c * height^2, keeping their distance to the surface.",
);
const MIN_WEIGHT: ParamSpec = ParamSpec::new(
    "min_weight",
    ParamKind::Float { default: 0.5, min: 0.0, max: 1.0 },
    "Outlier test: a vertex whose bilinear lookup has less weight on covered texels is discarded.",
);

crate::choice!(
    enum AreaMode {
        Tile = "tile",
        Decal = "decal",
    }
);

struct Common {
    matrix: Arc<MatrixTexture>,
    mesh: Arc<Mesh>,
    material: Arc<Material>,
}

fn common(cx: &EvalCx<'_>) -> Result<Common, NodeError> {
    let material = cx.optional("material").unwrap_or_else(|| Arc::new(Material::default()));
    Ok(Common { matrix: cx.input("matrix")?, mesh: cx.input("mesh")?, material })
}

fn emit(cx: &mut EvalCx<'_>, c: Common, mode: WarpMode, instances: Vec<InstanceData>) {
    let settings = WarpSettings { mode, gravity: cx.f32("gravity"), min_weight: cx.f32("min_weight") };
    cx.count("instances", instances.len());
    cx.count("triangles", instances.len() * c.mesh.triangle_count());
    let attached = AttachedDraw::new(c.matrix, settings, instances);
    let item = DrawItem { detail: true, ..DrawItem::plain(c.mesh, c.material, Mat4::IDENTITY) }
        .with_kind(attached)
        .named(cx.node_id);
    cx.set("scene", Arc::new(vec![item]));
}

/// M_tan of a point placement: lift along the normal, turn about it, scale (normal axis extra).
pub fn point_tangent_matrix(angle_deg: f32, scale: f32, normal_scale: f32, lift: f32) -> Mat4 {
    Mat4::from_translation(Vec3::new(0.0, lift, 0.0))
        // Positive angles turn the u axis towards +v, as in M_tex (decals) and placement files.
        * Mat4::from_quat(Quat::from_rotation_y(-angle_deg.to_radians()))
        * Mat4::from_scale(Vec3::new(scale, scale * normal_scale, scale))
}

/// The instance of one point placement: f_uv = (0, 0) moved to (u, v) by M_tex (eq. 4).
pub fn point_instance(p: &Placement, scale: f32, normal_scale: f32, lift: f32, extra_angle: f32) -> InstanceData {
    InstanceData::identity().with_tex(Affine2::from_translation(Vec2::new(p.u, p.v))).with_tan(point_tangent_matrix(
        p.angle + extra_angle,
        p.scale * scale,
        normal_scale,
        lift,
    ))
}

/// M_tex of an area attachment: maps the detail mesh's xz bounds (`lo`, `hi`) onto a UV
/// square of side `size` centred at `origin`, turned by `angle_deg` (positive from +u towards
/// +v). `uniform` (decals): scaled uniformly (eq. 6), the longer side `size`, so a 2:1 logo
/// stays 2:1; else (tiles) stretched to fill the square cell.
pub fn area_tex(lo: Vec3, hi: Vec3, uniform: bool, origin: Vec2, size: f32, angle_deg: f32) -> Affine2 {
    let extent = Vec2::new(hi.x - lo.x, hi.z - lo.z);
    let fit = if uniform { Vec2::splat(extent.max_element()) } else { extent };
    let to_unit = Affine2::from_translation(Vec2::splat(0.5) - extent / fit * 0.5)
        * Affine2::from_scale(Vec2::ONE / fit)
        * Affine2::from_translation(-Vec2::new(lo.x, lo.z));
    Affine2::from_translation(origin)
        * Affine2::from_angle(angle_deg.to_radians())
        * Affine2::from_scale(Vec2::splat(size))
        * Affine2::from_translation(Vec2::splat(-0.5))
        * to_unit
}

pub static POINT_ATTACHMENT: NodeSpec = NodeSpec {
    kind: "PointAttachment",
    category: Category::Attachment,
    doc: "Attaches the detail mesh at each placement (eqs. 4-5): one surface frame per instance, so buttons keep their shape however the UVs shear.",
    inputs: &[MATRIX, DETAIL, PortSpec::required("placements", PortType::Instances, "Where to attach."), MATERIAL],
    outputs: &[SCENE],
    params: &[
        ParamSpec::new(
            "scale",
            ParamKind::Float { default: 0.02, min: 0.0, max: 1e4 },
            "World size of the detail mesh (times each placement's scale).",
        ),
        ParamSpec::new(
            "normal_scale",
            ParamKind::Float { default: 1.0, min: 0.0, max: 1e4 },
            "Extra scale along the normal (M_tan).",
        ),
        ParamSpec::new(
            "lift",
            ParamKind::Float { default: 0.0, min: -1e3, max: 1e3 },
            "Offset along the normal (M_tan).",
        ),
        ParamSpec::new(
            "spin",
            ParamKind::Float { default: 0.0, min: -36000.0, max: 36000.0 },
            "Rotation about the normal in degrees per second (a time-dependent M_tan).",
        ),
        GRAVITY,
        MIN_WEIGHT,
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(PointAttachmentNode),
};

struct PointAttachmentNode;
impl Node for PointAttachmentNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let c = common(cx)?;
        let places: Arc<Vec<Placement>> = cx.input("placements")?;
        let spin = cx.f32("spin");
        let extra = if spin != 0.0 { spin * cx.time().seconds() as f32 } else { 0.0 };
        let (scale, ns, lift) = (cx.f32("scale"), cx.f32("normal_scale"), cx.f32("lift"));
        let instances = places.iter().map(|p| point_instance(p, scale, ns, lift, extra)).collect();
        emit(cx, c, WarpMode::Point, instances);
        Ok(())
    }
}

pub static AREA_ATTACHMENT: NodeSpec = NodeSpec {
    kind: "AreaAttachment",
    category: Category::Attachment,
    doc: "Attaches the detail mesh over an area (eqs. 6-7): f_uv = (x, z), f_map = (0, y, 0). `tile` repeats it over the whole UV square to replace the surface (knitwear); `decal` places one copy (a sticker), optionally spinning over time.",
    inputs: &[MATRIX, DETAIL, MATERIAL],
    outputs: &[SCENE],
    params: &[
        ParamSpec::new(
            "mode",
            ParamKind::Choice { default: "tile", options: AreaMode::OPTIONS },
            "Tile the UV square, or one decal.",
        ),
        ParamSpec::new(
            "tile_size",
            ParamKind::Float { default: 0.05, min: 1e-4, max: 1.0 },
            "UV size of one tile (tile mode).",
        ),
        ParamSpec::new(
            "height",
            ParamKind::Float { default: 1.0, min: 0.0, max: 1e4 },
            "Scale of the mesh's y (height over the surface) (M_tan).",
        ),
        ParamSpec::new(
            "lift",
            ParamKind::Float { default: 0.0, min: -1e3, max: 1e3 },
            "Offset along the normal after scaling (M_tan), e.g. to keep a flat sticker off the cloth.",
        ),
        ParamSpec::new("center", ParamKind::Vec3 { default: [0.5, 0.5, 0.0] }, "Decal centre in UV (x = u, y = v)."),
        ParamSpec::new(
            "size",
            ParamKind::Float { default: 0.2, min: 1e-5, max: 10.0 },
            "Decal size in UV units: its longer side (the mesh keeps its aspect ratio, eq. 6).",
        ),
        ParamSpec::new(
            "angle",
            ParamKind::Float { default: 0.0, min: -3600.0, max: 3600.0 },
            "Decal rotation in UV space, degrees.",
        ),
        ParamSpec::new(
            "spin",
            ParamKind::Float { default: 0.0, min: -36000.0, max: 36000.0 },
            "Decal rotation speed in degrees per second: the time-dependent mapping of Fig. 8.",
        ),
        GRAVITY,
        MIN_WEIGHT,
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(AreaAttachmentNode),
};

struct AreaAttachmentNode;
impl Node for AreaAttachmentNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let c = common(cx)?;
        let (lo, hi) = c.mesh.bounds();
        let extent = Vec2::new(hi.x - lo.x, hi.z - lo.z);
        if extent.x <= 0.0 || extent.y <= 0.0 {
            return Err(NodeError::msg(
                "the detail mesh is flat in x or z; area attachments project it on the xz-plane (eq. 6)",
            ));
        }
        let m_tan = Mat4::from_translation(Vec3::new(0.0, cx.f32("lift"), 0.0))
            * Mat4::from_scale(Vec3::new(1.0, cx.f32("height"), 1.0));
        let decal = cx.choice::<AreaMode>("mode") == AreaMode::Decal;
        let tile = |origin: Vec2, size: f32, angle_deg: f32| {
            InstanceData::identity().with_tex(area_tex(lo, hi, decal, origin, size, angle_deg)).with_tan(m_tan)
        };
        let instances = if decal {
            let spin = cx.f32("spin");
            let angle = cx.f32("angle") + if spin != 0.0 { spin * cx.time().seconds() as f32 } else { 0.0 };
            vec![tile(cx.vec3("center").truncate(), cx.f32("size"), angle)]
        } else {
            let size = cx.f32("tile_size");
            let n = (1.0 / size).ceil() as usize;
            if n * n > 4_000_000 {
                return Err(NodeError::msg(format!(
                    "tile_size {size} gives {} tiles, over the limit of 4 million",
                    n * n
                )));
            }
            let mut v = Vec::with_capacity(n * n);
            for j in 0..n {
                for i in 0..n {
                    v.push(tile(Vec2::new((i as f32 + 0.5) * size, (j as f32 + 0.5) * size), size, 0.0));
                }
            }
            v
        };
        emit(cx, c, WarpMode::Area, instances);
        Ok(())
    }
}

pub static CURVE_ATTACHMENT: NodeSpec = NodeSpec {
    kind: "CurveAttachment",
    category: Category::Attachment,
    doc: "Repeats the detail mesh along curves (eqs. 8-10): its z extent maps to one repetition of arc length, x is the offset across the curve, y the height. `aligned` turns it with the curve normal (eq. 10).",
    inputs: &[MATRIX, DETAIL, PortSpec::required("curves", PortType::Curves, "Curves in UV space."), MATERIAL],
    outputs: &[SCENE],
    params: &[
        ParamSpec::new(
            "spacing",
            ParamKind::Float { default: 0.02, min: 1e-5, max: 1.0 },
            "UV arc length of one repetition; each Bezier segment gets round(length / spacing) copies.",
        ),
        ParamSpec::new(
            "scale",
            ParamKind::Float { default: 0.01, min: 0.0, max: 1e4 },
            "World size of the mesh's x and y (M_tan).",
        ),
        ParamSpec::new(
            "aligned",
            ParamKind::Bool { default: true },
            "Align to the curve normal (eq. 10) instead of the u axis (eq. 9).",
        ),
        GRAVITY,
        MIN_WEIGHT,
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(CurveAttachmentNode),
};

struct CurveAttachmentNode;
impl Node for CurveAttachmentNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let c = common(cx)?;
        let curves: Arc<Curves> = cx.input("curves")?;
        let (lo, hi) = c.mesh.bounds();
        if hi.z - lo.z <= 0.0 {
            return Err(NodeError::msg(
                "the detail mesh has no extent in z, which curve attachments map along the curve (eq. 8)",
            ));
        }
        let spacing = cx.f32("spacing");
        let m_tan = Mat4::from_scale(Vec3::splat(cx.f32("scale")));
        let mut instances = Vec::new();
        for path in &curves.paths {
            for seg in path {
                let table = ArcTable::new(std::slice::from_ref(seg), 64);
                let n = ((table.length() / spacing).round() as usize).max(1);
                if instances.len() + n > 4_000_000 {
                    return Err(NodeError::msg("more than 4 million curve repetitions: increase spacing"));
                }
                for i in 0..n {
                    let (_, t0) = table.at(table.length() * i as f32 / n as f32);
                    let (_, t1) = table.at(table.length() * (i + 1) as f32 / n as f32);
                    instances.push(InstanceData::identity().with_tan(m_tan).with_curve(seg, t0, t1, lo.z, hi.z));
                }
            }
        }
        let mode = if cx.bool("aligned") { WarpMode::CurveAligned } else { WarpMode::Curve };
        emit(cx, c, mode, instances);
        Ok(())
    }
}

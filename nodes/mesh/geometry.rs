//! Geometry sources: parametric primitives with a UV parametrization, and mesh files.

use std::f32::consts::{PI, TAU};
use std::sync::Arc;

use glam::{Vec2, Vec3};

use crate::core::node::prelude::*;
use crate::mesh::{self, Mesh};

pub static PRIMITIVE: NodeSpec = NodeSpec {
    kind: "Primitive",
    category: Category::Geometry,
    doc: "A parametric shape with analytic normals and a UV parametrization (u around, v along).",
    inputs: &[],
    outputs: &[PortSpec::output("mesh", PortType::Surface, "The shape; its UVs are its parametrization.")],
    params: &[
        ParamSpec::new(
            "shape",
            ParamKind::Choice { default: "sphere", options: Shape::OPTIONS },
            "plane: size x size in XZ; triangle: equilateral of edge size in XZ; icosahedron: radius (Fig. 5.13); cylinder: radius, height along Y (open); sphere: radius; torus: radius, minor_radius; disc: a button of radius and height; box: size cube.",
        ),
        ParamSpec::new("size", ParamKind::Float { default: 1.0, min: 1e-4, max: 1e4 }, "Edge length of plane and box."),
        ParamSpec::new(
            "radius",
            ParamKind::Float { default: 0.5, min: 1e-4, max: 1e4 },
            "Radius (major radius for the torus).",
        ),
        ParamSpec::new(
            "minor_radius",
            ParamKind::Float { default: 0.15, min: 1e-4, max: 1e4 },
            "Tube radius of the torus.",
        ),
        ParamSpec::new(
            "height",
            ParamKind::Float { default: 1.0, min: 1e-4, max: 1e4 },
            "Height of cylinder and disc.",
        ),
        ParamSpec::new(
            "segments_u",
            ParamKind::Int { default: 48, min: 1, max: 4096 },
            "Subdivisions along u (around).",
        ),
        ParamSpec::new("segments_v", ParamKind::Int { default: 24, min: 1, max: 4096 }, "Subdivisions along v."),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(PrimitiveNode),
};

crate::choice!(
    enum Shape {
        Plane = "plane",
        Cylinder = "cylinder",
        Sphere = "sphere",
        Torus = "torus",
        Disc = "disc",
        Box = "box",
        Icosahedron = "icosahedron",
        Triangle = "triangle",
    }
);

struct PrimitiveNode;
impl Node for PrimitiveNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let (su, sv) = (cx.int("segments_u") as u32, cx.int("segments_v") as u32);
        let mesh = match cx.choice::<Shape>("shape") {
            Shape::Plane => plane(cx.f32("size"), su, sv),
            Shape::Cylinder => cylinder(cx.f32("radius"), cx.f32("height"), su.max(3), sv),
            Shape::Torus => torus(cx.f32("radius"), cx.f32("minor_radius"), su.max(3), sv.max(3)),
            Shape::Disc => disc(cx.f32("radius"), cx.f32("height"), su.max(3)),
            Shape::Box => cube(cx.f32("size")),
            Shape::Sphere => sphere(cx.f32("radius"), su.max(3), sv.max(2)),
            Shape::Icosahedron => icosahedron(cx.f32("radius")),
            Shape::Triangle => triangle(cx.f32("size")),
        }?;
        cx.set("mesh", Arc::new(mesh));
        Ok(())
    }
}

/// A (su+1) x (sv+1) vertex grid over (u, v) in [0,1]^2, mapped by `f` to (position, normal).
fn grid(su: u32, sv: u32, f: impl Fn(f32, f32) -> (Vec3, Vec3)) -> anyhow::Result<Mesh> {
    let (mut p, mut n, mut uv, mut idx) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for j in 0..=sv {
        for i in 0..=su {
            let (u, v) = (i as f32 / su as f32, j as f32 / sv as f32);
            let (pos, nor) = f(u, v);
            p.push(pos);
            n.push(nor);
            uv.push(Vec2::new(u, v));
        }
    }
    let row = su + 1;
    for j in 0..sv {
        for i in 0..su {
            let a = j * row + i;
            idx.extend_from_slice(&[a, a + row, a + 1, a + 1, a + row, a + row + 1]);
        }
    }
    Mesh::build(p, Some(uv), Some(n), idx)
}

/// The regular icosahedron of circumradius `r` (12 vertices, 20 faces), normals pointing out,
/// UVs by longitude and latitude.
pub fn icosahedron(r: f32) -> anyhow::Result<Mesh> {
    let g = (1.0 + 5f32.sqrt()) / 2.0;
    let raw = [
        [-1.0, g, 0.0],
        [1.0, g, 0.0],
        [-1.0, -g, 0.0],
        [1.0, -g, 0.0],
        [0.0, -1.0, g],
        [0.0, 1.0, g],
        [0.0, -1.0, -g],
        [0.0, 1.0, -g],
        [g, 0.0, -1.0],
        [g, 0.0, 1.0],
        [-g, 0.0, -1.0],
        [-g, 0.0, 1.0],
    ];
    let n: Vec<Vec3> = raw.iter().map(|p| Vec3::from_array(*p).normalize()).collect();
    let p: Vec<Vec3> = n.iter().map(|n| *n * r).collect();
    let uv = n.iter().map(|n| Vec2::new(0.5 + n.x.atan2(n.z) / TAU, n.y.clamp(-1.0, 1.0).acos() / PI)).collect();
    let mut idx: Vec<u32> = vec![
        0, 11, 5, 0, 5, 1, 0, 1, 7, 0, 7, 10, 0, 10, 11, 1, 5, 9, 5, 11, 4, 11, 10, 2, 10, 7, 6, 7, 1, 8, 3, 9, 4, 3,
        4, 2, 3, 2, 6, 3, 6, 8, 3, 8, 9, 4, 9, 5, 2, 4, 11, 6, 2, 10, 8, 6, 7, 9, 8, 1,
    ];
    // Wind every face like the other primitives: (b - a) x (c - a) along the outward normal.
    for t in idx.chunks_exact_mut(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| p[i as usize]);
        if (b - a).cross(c - a).dot(a + b + c) < 0.0 {
            t.swap(1, 2);
        }
    }
    Mesh::build(p, Some(uv), Some(n), idx)
}

/// One equilateral triangle of edge `size` in the XZ plane, normal +Y (Figs. 3.7-3.11).
pub fn triangle(size: f32) -> anyhow::Result<Mesh> {
    let h = size * 3f32.sqrt() / 2.0;
    let p = vec![
        Vec3::new(-size / 2.0, 0.0, -h / 3.0),
        Vec3::new(0.0, 0.0, 2.0 * h / 3.0),
        Vec3::new(size / 2.0, 0.0, -h / 3.0),
    ];
    let uv = vec![Vec2::new(0.0, 0.0), Vec2::new(0.5, 1.0), Vec2::new(1.0, 0.0)];
    Mesh::build(p, Some(uv), Some(vec![Vec3::Y; 3]), vec![0, 1, 2])
}

/// In the XZ plane, normal +Y; u along +X, v along +Z.
pub fn plane(size: f32, su: u32, sv: u32) -> anyhow::Result<Mesh> {
    grid(su, sv, |u, v| (Vec3::new((u - 0.5) * size, 0.0, (v - 0.5) * size), Vec3::Y))
}

/// Open cylinder around +Y: P(u, v) = (r sin 2πu, h (0.5 - v), r cos 2πu).
pub fn cylinder(r: f32, h: f32, su: u32, sv: u32) -> anyhow::Result<Mesh> {
    grid(su, sv, |u, v| {
        let a = u * TAU;
        let n = Vec3::new(a.sin(), 0.0, a.cos());
        (n * r + Vec3::Y * h * (0.5 - v), n)
    })
}

/// P(u, v) = r (sin θ sin φ, cos θ, sin θ cos φ) with φ = 2πu, θ = πv.
pub fn sphere(r: f32, su: u32, sv: u32) -> anyhow::Result<Mesh> {
    grid(su, sv, |u, v| {
        let (phi, theta) = (u * TAU, v * PI);
        let n = Vec3::new(theta.sin() * phi.sin(), theta.cos(), theta.sin() * phi.cos());
        (n * r, n)
    })
}

/// Torus around +Y, major radius `big`, tube radius `small`.
pub fn torus(big: f32, small: f32, su: u32, sv: u32) -> anyhow::Result<Mesh> {
    let mut m = grid(su, sv, |u, v| {
        let (phi, theta) = (u * TAU, v * TAU);
        let ring = Vec3::new(phi.sin(), 0.0, phi.cos());
        let n = ring * theta.cos() + Vec3::Y * theta.sin();
        (ring * big + n * small, n)
    })?;
    // v runs up the outside of the tube, so the grid's triangles would face inwards, against
    // the normals: turn them around (positions, UVs and tangents stay as they are).
    for t in m.indices.chunks_exact_mut(3) {
        t.swap(1, 2);
    }
    Ok(m)
}

/// A closed cuboid; each face its own UV square.
pub fn cube(size: f32) -> anyhow::Result<Mesh> {
    let h = size * 0.5;
    let (mut p, mut n, mut uv, mut idx) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for axis in [Vec3::X, Vec3::Y, Vec3::Z, -Vec3::X, -Vec3::Y, -Vec3::Z] {
        let t = if axis.y.abs() > 0.5 { Vec3::X } else { Vec3::Y.cross(axis) };
        let b = axis.cross(t);
        let base = p.len() as u32;
        for (su, sv) in [(0.0, 0.0), (1.0, 0.0), (0.0, 1.0), (1.0, 1.0)] {
            p.push((axis + t * (su * 2.0 - 1.0) + b * (sv * 2.0 - 1.0)) * h);
            n.push(axis);
            uv.push(Vec2::new(su, sv));
        }
        idx.extend_from_slice(&[base, base + 1, base + 2, base + 2, base + 1, base + 3]);
    }
    Mesh::build(p, Some(uv), Some(n), idx)
}

/// A button: a short closed cylinder around +Y with flat caps (UVs: planar on the caps).
pub fn disc(r: f32, h: f32, segments: u32) -> anyhow::Result<Mesh> {
    let side = cylinder(r, h, segments, 1)?;
    let (mut p, mut n, mut uv, mut idx) = (side.positions, side.normals, side.uvs, side.indices);
    for (y, up) in [(h * 0.5, 1.0f32), (-h * 0.5, -1.0)] {
        let centre = p.len() as u32;
        p.push(Vec3::new(0.0, y, 0.0));
        n.push(Vec3::Y * up);
        uv.push(Vec2::splat(0.5));
        for i in 0..=segments {
            let a = i as f32 / segments as f32 * TAU;
            p.push(Vec3::new(a.sin() * r, y, a.cos() * r));
            n.push(Vec3::Y * up);
            uv.push(Vec2::new(0.5 + 0.5 * a.sin(), 0.5 + 0.5 * a.cos()));
        }
        for i in 0..segments {
            let (a, b) = (centre + 1 + i, centre + 2 + i);
            if up > 0.0 {
                idx.extend_from_slice(&[centre, a, b]);
            } else {
                idx.extend_from_slice(&[centre, b, a]);
            }
        }
    }
    Mesh::build(p, Some(uv), Some(n), idx)
}

pub static MESH_FILE: NodeSpec = NodeSpec {
    kind: "MeshFile",
    category: Category::Geometry,
    doc: "Loads a mesh from an OBJ or glTF file (on a worker thread); missing normals and tangents are computed, broken triangles repaired with a warning. A UV-mapped garment from any tool is also a Surface that takes attachments: one pattern piece per OBJ object or group, or per glTF primitive.",
    inputs: &[],
    outputs: &[
        PortSpec::output("mesh", PortType::Mesh, "The loaded mesh."),
        PortSpec::output(
            "surface",
            PortType::Surface,
            "The same mesh as a Surface (UVs are the pattern coordinates, v down); linking it requires UVs in the file.",
        ),
        PortSpec::output(
            "bounds_min",
            PortType::Vector,
            "Lowest corner of the mesh's bounding box, in the output's units (the file's, or normalized): to line meshes up, or place by height.",
        ),
        PortSpec::output(
            "bounds_max",
            PortType::Vector,
            "Highest corner of the mesh's bounding box, in the output's units.",
        ),
    ],
    params: &[
        ParamSpec::new(
            "path",
            ParamKind::Path { default: "", extensions: &["obj", "gltf", "glb"] },
            "The file, relative to the graph's folder.",
        ),
        ParamSpec::new(
            "normalize",
            ParamKind::Bool { default: false },
            "Centre the mesh and scale it to unit height. Off: the file's units, so meshes from one tool (a body and its garment) line up.",
        ),
        ParamSpec::new(
            "normalize_by",
            ParamKind::Path { default: "", extensions: &["obj", "gltf", "glb"] },
            "With normalize: the file whose bounds give the centre and scale (empty: this file). Give the meshes of one source the same one (a garment normalized by its body's file), so they stay lined up.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(MeshFileNode),
};

struct MeshFileNode;
impl Node for MeshFileNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        if cx.str("path").is_empty() {
            return Err(NodeError::msg("parameter \"path\" is empty: name an .obj file"));
        }
        let path = cx.path("path");
        let loaded = cx.load(&path, mesh::load_mesh_file)?;
        for r in &loaded.repairs {
            cx.warn(format!("{}: {r}", path.display()));
        }
        let mesh = if cx.bool("normalize") {
            // One scale for the meshes of one source: the bounds of the file they name.
            let (lo, hi) = if cx.str("normalize_by").is_empty() {
                loaded.bounds()
            } else {
                cx.load(&cx.path("normalize_by"), mesh::load_mesh_file)?.bounds()
            };
            let scale = 1.0 / (hi.y - lo.y).max(1e-6);
            let centre = (lo + hi) * 0.5;
            let mut m = (*loaded).clone();
            m.positions.iter_mut().for_each(|p| *p = (*p - centre) * scale);
            Arc::new(m)
        } else {
            loaded
        };
        if cx.output_linked("surface") && mesh.uvs_generated() {
            return Err(NodeError::msg(format!(
                "{} has no UVs, so it cannot be a surface (attachments are placed by UV); UV-map it in the modelling tool, or link \"mesh\" instead",
                path.display()
            )));
        }
        cx.count("triangles", mesh.triangle_count());
        let (lo, hi) = mesh.bounds();
        cx.set("bounds_min", lo);
        cx.set("bounds_max", hi);
        cx.set("surface", mesh.clone());
        cx.set("mesh", mesh);
        Ok(())
    }
}

pub static TRANSFORM_MESH: NodeSpec = NodeSpec {
    kind: "TransformMesh",
    category: Category::Geometry,
    doc: "Scales, rotates (XYZ, degrees) and translates a mesh's vertices, e.g. to stand a detail mesh up or put its base at y = 0 before attaching it.",
    inputs: &[PortSpec::required("mesh", PortType::Mesh, "The mesh.")],
    outputs: &[PortSpec::output("mesh", PortType::Mesh, "The transformed mesh.")],
    params: &[TRANSLATE, ROTATE, SCALE],
    capabilities: Capabilities::NONE,
    create: || Box::new(TransformMeshNode),
};

/// The transform parameters of `TransformMesh`, `Draw` and `MatrixTexture` (read by `model_matrix`).
pub const TRANSLATE: ParamSpec =
    ParamSpec::new("translate", ParamKind::Vec3 { default: [0.0, 0.0, 0.0] }, "Translation (applied last).");
pub const ROTATE: ParamSpec =
    ParamSpec::new("rotate", ParamKind::Vec3 { default: [0.0, 0.0, 0.0] }, "Rotation about X, Y, Z in degrees.");
pub const SCALE: ParamSpec =
    ParamSpec::new("scale", ParamKind::Scale { default: [1.0, 1.0, 1.0] }, "Scale per axis (applied first).");

/// The model matrix of the `translate`, `rotate`, `scale` parameters (see [`trs_matrix`]).
pub fn model_matrix(cx: &EvalCx<'_>) -> Result<glam::Mat4, NodeError> {
    trs_matrix(cx.vec3("translate"), cx.vec3("rotate"), cx.vec3("scale"))
}

/// Scale, then rotate about X, Y, Z in degrees, then translate. A scale component that is 0 or
/// not finite is an error that names the scale; a tiny one is not (millimetres to metres).
pub fn trs_matrix(translate: glam::Vec3, rotate: glam::Vec3, scale: glam::Vec3) -> Result<glam::Mat4, NodeError> {
    if let Some(why) = crate::core::param::degenerate_scale(scale.as_dvec3().to_array()) {
        return Err(NodeError::msg(why));
    }
    let r = rotate;
    let rotation = glam::Quat::from_euler(glam::EulerRot::XYZ, r.x.to_radians(), r.y.to_radians(), r.z.to_radians());
    Ok(glam::Mat4::from_scale_rotation_translation(scale, rotation, translate))
}

/// `mesh` with positions moved by `m`, normals by its inverse transpose and tangents by its
/// linear part.
pub fn transform_mesh(mesh: &Mesh, m: glam::Mat4) -> Mesh {
    let normal_matrix = glam::Mat3::from_mat4(m).inverse().transpose();
    let linear = glam::Mat3::from_mat4(m);
    let mut out = mesh.clone();
    out.positions.iter_mut().for_each(|p| *p = m.transform_point3(*p));
    out.normals.iter_mut().for_each(|n| *n = (normal_matrix * *n).normalize_or_zero());
    out.tangents_u.iter_mut().for_each(|t| *t = (linear * *t).normalize_or_zero());
    out.tangents_v.iter_mut().for_each(|t| *t = (linear * *t).normalize_or_zero());
    out
}

struct TransformMeshNode;
impl Node for TransformMeshNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let mesh: Arc<Mesh> = cx.input("mesh")?;
        let out = transform_mesh(&mesh, model_matrix(cx)?);
        cx.set("mesh", Arc::new(out));
        Ok(())
    }
}

#[cfg(test)]
mod transform_tests {
    use glam::Vec3;

    #[test]
    fn a_tiny_scale_is_a_transform_and_a_zero_one_names_its_value() {
        let tiny = super::trs_matrix(Vec3::ZERO, Vec3::ZERO, Vec3::splat(1e-4)).unwrap();
        assert!((tiny.transform_point3(Vec3::X) - Vec3::new(1e-4, 0.0, 0.0)).length() < 1e-9);
        let err = super::trs_matrix(Vec3::ZERO, Vec3::ZERO, Vec3::new(1.0, 0.0, 2.0)).unwrap_err();
        assert!(matches!(&err, super::NodeError::Failed(m) if m.contains("scale [1, 0, 2]")), "{err:?}");
        assert!(super::trs_matrix(Vec3::ZERO, Vec3::ZERO, Vec3::new(1.0, f32::NAN, 1.0)).is_err());
    }
}

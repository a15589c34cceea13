//! Export equals render: the geometry of a scene as its items' kinds draw it, placed as their
//! vertex stages place it (model matrix, then a non-linear grid by eq. 3.4).

use glam::{DVec3, Mat3, Vec3};

use crate::cuboid::{CuboidGrid, fast_path};
use crate::io::geometry::GeometryPart;
use crate::mesh::{Mesh, has_area};
use crate::render::scene::DrawItem;

use super::kind::{ExportCx, Exported};

/// One mesh of everything the scene draws; triangles without area (collapsed by the transform,
/// or touching an outlier vertex of an attachment) are left out.
pub fn flatten(cx: &mut ExportCx<'_>, items: &[DrawItem]) -> anyhow::Result<Mesh> {
    flatten_parts(cx, items).map(|(mesh, _)| mesh)
}

/// [`flatten`], with the triangles of each item that has any as a part carrying its material
/// (for formats with materials: glTF).
pub fn flatten_parts(cx: &mut ExportCx<'_>, items: &[DrawItem]) -> anyhow::Result<(Mesh, Vec<GeometryPart>)> {
    let mut parts = Vec::with_capacity(items.len());
    let mut materials = Vec::with_capacity(items.len());
    let mut triangles = 0;
    for (i, item) in items.iter().enumerate() {
        let exported =
            item.kind.export(cx, item).map_err(|e| e.context(format!("exporting item {i} ({})", item.kind.name())))?;
        parts.push(match exported {
            Exported::World(mesh) => mesh,
            Exported::Local(mesh) => {
                let (model, grid) = fast_path(item.model, item.cuboid.clone());
                place(&mesh, model, grid.as_deref())
            }
        });
        let count = parts.last().map_or(0, Mesh::triangle_count);
        if count > 0 {
            let m = &item.material;
            let range = triangles..triangles + count;
            materials.push(GeometryPart { triangles: range, base_color: m.base_color, glossiness: m.glossiness });
        }
        triangles += count;
    }
    if parts.iter().all(|p| p.indices.is_empty()) {
        anyhow::bail!("nothing to export: the scene has no visible triangles");
    }
    if parts.len() == 1 {
        return Ok((parts.pop().expect("one part"), materials));
    }
    let (mut positions, mut normals, mut uvs, mut indices) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for p in parts {
        let base = positions.len() as u32;
        positions.extend_from_slice(&p.positions);
        normals.extend_from_slice(&p.normals);
        uvs.extend_from_slice(&p.uvs);
        indices.extend(p.indices.iter().map(|i| i + base));
    }
    Ok((Mesh::from_raw(positions, normals, uvs, Vec::new(), Vec::new(), indices), materials))
}

/// `mesh` placed as the vertex stages place it: `model`, then `grid` (eq. 3.4, in f64, and
/// normals by the grid's normal method), keeping only triangles with an area.
pub fn place(mesh: &Mesh, model: glam::Mat4, grid: Option<&CuboidGrid>) -> Mesh {
    let normal_matrix = Mat3::from_mat4(model).inverse().transpose();
    let (positions, normals): (Vec<Vec3>, Vec<Vec3>) = mesh
        .positions
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let n = mesh.normals.get(i).map_or(Vec3::ZERO, |n| normal_matrix * *n);
            let q = model.as_dmat4().transform_point3(p.as_dvec3());
            match grid {
                None => (q.as_vec3(), n.normalize_or_zero()),
                Some(g) => (g.eval(q).as_vec3(), g.normal(q, n.as_dvec3()).normalize_or(DVec3::ZERO).as_vec3()),
            }
        })
        .unzip();
    let indices = mesh
        .indices
        .chunks_exact(3)
        .map(|t| [t[0], t[1], t[2]])
        .filter(|&t| has_area(&positions, t))
        .flatten()
        .collect();
    let normals = if mesh.normals.is_empty() { Vec::new() } else { normals };
    Mesh::from_raw(positions, normals, mesh.uvs.clone(), Vec::new(), Vec::new(), indices)
}

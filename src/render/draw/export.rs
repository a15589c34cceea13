//! Export equals render: the geometry of a scene as its items' kinds draw it, placed as their
//! vertex stages place it (model matrix, then a non-linear grid by eq. 3.4).

use glam::{DVec3, Mat3, Vec3};

use crate::cuboid::{CuboidGrid, fast_path};
use std::sync::Arc;

use crate::io::geometry::{GeometryPart, Instancing, Span};
use crate::mesh::{Mesh, has_area};
use crate::render::scene::DrawItem;

use super::kind::{ExportCx, Exported};

/// One mesh of everything the scene draws; triangles without area (collapsed by the transform,
/// or touching an outlier vertex of an attachment) are left out.
pub fn flatten(cx: &mut ExportCx<'_>, items: &[DrawItem]) -> anyhow::Result<Mesh> {
    flatten_parts(cx, items).map(|(mesh, _)| mesh)
}

/// [`flatten`], with a part per item that has triangles: its name, vertex and triangle
/// ranges, attachment instances and material (for formats that keep items apart).
pub fn flatten_parts(cx: &mut ExportCx<'_>, items: &[DrawItem]) -> anyhow::Result<(Mesh, Vec<GeometryPart>)> {
    let names = item_names(items);
    let mut meshes = Vec::with_capacity(items.len());
    let mut parts = Vec::with_capacity(items.len());
    let (mut vertices, mut triangles) = (0, 0);
    for ((i, item), name) in items.iter().enumerate().zip(names) {
        let exported =
            item.kind.export(cx, item).map_err(|e| e.context(format!("exporting item {i} ({})", item.kind.name())))?;
        let (mesh, per_instance) = match exported {
            Exported::Instances { mesh, per_instance, placements } => {
                let instancing = placements.map(|placements| Instancing { mesh: item.mesh.clone(), placements });
                (mesh, Some((per_instance, instancing)))
            }
            Exported::Local(mesh) => {
                let (model, grid) = fast_path(item.model, item.cuboid.clone());
                (place(&mesh, model, grid.as_deref()), None)
            }
        };
        let count = mesh.triangle_count();
        if count > 0 {
            let attached = per_instance.is_some();
            let (instances, instancing) = match per_instance {
                Some((n, instancing)) => (instance_spans(&mesh, n, vertices, triangles), instancing.map(Arc::new)),
                None => (Vec::new(), None),
            };
            // A placed mesh keeps its item's vertices, so the item's pattern pieces still apply.
            let piece_of = &item.mesh.piece_ids;
            let pieces = if !attached && piece_of.len() == mesh.positions.len() {
                mesh.indices.chunks_exact(3).map(|t| piece_of[t[0] as usize]).collect()
            } else {
                Vec::new()
            };
            let m = &item.material;
            parts.push(GeometryPart {
                name,
                vertices: vertices..vertices + mesh.positions.len(),
                triangles: triangles..triangles + count,
                instances,
                pieces,
                instancing,
                base_color: m.base_color,
                glossiness: m.glossiness,
            });
        }
        vertices += mesh.positions.len();
        triangles += count;
        meshes.push(mesh);
    }
    if triangles == 0 {
        anyhow::bail!("nothing to export: the scene has no visible triangles");
    }
    if meshes.len() == 1 {
        return Ok((meshes.pop().expect("one mesh"), parts));
    }
    let (mut positions, mut normals, mut uvs, mut indices) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for p in meshes {
        let base = positions.len() as u32;
        positions.extend_from_slice(&p.positions);
        normals.extend_from_slice(&p.normals);
        uvs.extend_from_slice(&p.uvs);
        indices.extend(p.indices.iter().map(|i| i + base));
    }
    Ok((Mesh::from_raw(positions, normals, uvs, Vec::new(), Vec::new(), indices), parts))
}

/// Each item's object name: the node that made it, else its kind, made a file-safe word;
/// items sharing a name are numbered (`collider_0`, `collider_1`).
fn item_names(items: &[DrawItem]) -> Vec<String> {
    let base: Vec<String> = items
        .iter()
        .map(|item| {
            let name = item.name.as_deref().unwrap_or(item.kind.name());
            name.chars().map(|c| if c.is_alphanumeric() || "-_.".contains(c) { c } else { '_' }).collect()
        })
        .collect();
    let mut total = std::collections::HashMap::<&str, usize>::new();
    base.iter().for_each(|b| *total.entry(b.as_str()).or_default() += 1);
    let mut seen = std::collections::HashMap::<&str, usize>::new();
    base.iter()
        .map(|b| {
            let n = seen.entry(b.as_str()).or_default();
            *n += 1;
            if total[b.as_str()] > 1 { format!("{b}_{}", *n - 1) } else { b.clone() }
        })
        .collect()
}

/// The vertex and triangle ranges (offset by the export's `vertices` and `triangles` before
/// this item) of each instance of an instance-major `mesh` with `per_instance` vertices each;
/// an instance whose triangles were all dropped (outliers) has an empty triangle range.
fn instance_spans(mesh: &Mesh, per_instance: usize, vertices: usize, triangles: usize) -> Vec<Span> {
    let count = mesh.positions.len() / per_instance.max(1);
    let mut spans = Vec::with_capacity(count);
    let mut t = 0;
    for k in 0..count {
        let start = t;
        while t < mesh.triangle_count() && (mesh.indices[3 * t] as usize) < (k + 1) * per_instance {
            t += 1;
        }
        let v = vertices + k * per_instance;
        spans.push(Span { vertices: v..v + per_instance, triangles: triangles + start..triangles + t });
    }
    spans
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

//! Writing geometry files: OBJ (text) and binary glTF (.glb, with a material per item), each
//! with an object per scene item and per attachment instance, and PLY (binary little-endian,
//! one mesh), atomically.

use std::io::Write as _;
use std::path::Path;

use anyhow::Context as _;

use glam::{Quat, Vec3};

use crate::mesh::Mesh;

crate::choice!(
    /// The geometry file formats `render` writes; the option names are the file extensions.
    pub enum GeometryFormat {
        Obj = "obj",
        Ply = "ply",
        Glb = "glb",
        /// A cache of the rendered frame range in one file (`crate::io::usda`).
        Usda = "usda",
    }
);

/// One scene item in an export: its object name, where its vertices and triangles lie in the
/// exported mesh, its attachment instances and its material. OBJ and glTF write an object per
/// item drawn once and per attachment instance ([`objects`]); PLY and USDA ignore parts.
#[derive(Clone, Debug, PartialEq)]
pub struct GeometryPart {
    /// The item's name: the node that made it, else its kind (unique within the export).
    pub name: String,
    /// Vertex indices into the exported mesh.
    pub vertices: std::ops::Range<usize>,
    /// Triangle indices (not index-buffer offsets) into the exported mesh.
    pub triangles: std::ops::Range<usize>,
    /// The instances of an attachment, in instance order, each within `vertices` and
    /// `triangles`; empty for an item drawn once.
    pub instances: Vec<Span>,
    /// The pattern piece of each of the item's triangles (a Surface's); empty otherwise.
    pub pieces: Vec<u32>,
    /// An attachment whose instances are rigid copies of its detail mesh, where the export
    /// asked for instancing: .glb writes the mesh once and the placements with
    /// `EXT_mesh_gpu_instancing`; other formats realize every instance.
    pub instancing: Option<std::sync::Arc<Instancing>>,
    /// Linear RGB.
    pub base_color: glam::Vec3,
    /// 0 = rough, 1 = mirror-like (the renderer's glossiness).
    pub glossiness: f32,
}

/// The vertices and triangles of one attachment instance in an exported mesh.
#[derive(Clone, Debug, PartialEq)]
pub struct Span {
    pub vertices: std::ops::Range<usize>,
    pub triangles: std::ops::Range<usize>,
}

/// An attachment's detail mesh and each instance's affine map of it, in instance order (an
/// instance without triangles has any matrix).
pub struct Instancing {
    pub mesh: std::sync::Arc<Mesh>,
    pub placements: Vec<glam::Mat4>,
}

impl PartialEq for Instancing {
    fn eq(&self, other: &Self) -> bool {
        std::sync::Arc::ptr_eq(&self.mesh, &other.mesh) && self.placements == other.placements
    }
}

impl std::fmt::Debug for Instancing {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Instancing({} vertices, {} placements)", self.mesh.positions.len(), self.placements.len())
    }
}

impl GeometryPart {
    /// All of `mesh` as one item named `name` in a default grey, with the mesh's pattern pieces.
    pub fn whole(mesh: &Mesh, name: &str) -> GeometryPart {
        let pieces = if mesh.piece_ids.len() == mesh.positions.len() {
            mesh.indices.chunks_exact(3).map(|t| mesh.piece_ids[t[0] as usize]).collect()
        } else {
            Vec::new()
        };
        GeometryPart {
            name: name.to_string(),
            vertices: 0..mesh.positions.len(),
            triangles: 0..mesh.triangle_count(),
            instances: Vec::new(),
            pieces,
            instancing: None,
            base_color: glam::Vec3::splat(0.8),
            glossiness: 0.2,
        }
    }
}

/// One object of an export: an item drawn once, or one instance of an attachment (named
/// `<item>_<instance index>`). Objects without triangles are left out (an instance whose
/// vertices were all outliers keeps its index gap).
#[derive(Clone, Debug, PartialEq)]
pub struct GeometryObject<'a> {
    pub name: std::borrow::Cow<'a, str>,
    /// Index of the part (item) it belongs to.
    pub part: usize,
    pub vertices: std::ops::Range<usize>,
    pub triangles: std::ops::Range<usize>,
    /// The pattern piece of each triangle, or empty.
    pub pieces: &'a [u32],
}

/// The objects of `parts` in order, and what an export header counts of them.
pub fn objects(parts: &[GeometryPart]) -> (Vec<GeometryObject<'_>>, ObjectCounts) {
    let mut objects = Vec::new();
    let mut counts = ObjectCounts::default();
    for (k, part) in parts.iter().enumerate() {
        let before = objects.len();
        if part.instances.is_empty() {
            if !part.triangles.is_empty() {
                objects.push(GeometryObject {
                    name: part.name.as_str().into(),
                    part: k,
                    vertices: part.vertices.clone(),
                    triangles: part.triangles.clone(),
                    pieces: &part.pieces,
                });
            }
        } else {
            for (i, s) in part.instances.iter().enumerate().filter(|(_, s)| !s.triangles.is_empty()) {
                objects.push(GeometryObject {
                    name: format!("{}_{i}", part.name).into(),
                    part: k,
                    vertices: s.vertices.clone(),
                    triangles: s.triangles.clone(),
                    pieces: &[],
                });
            }
            counts.instances += objects.len() - before;
        }
        counts.items += usize::from(objects.len() > before);
    }
    counts.objects = objects.len();
    (objects, counts)
}

/// What an export holds: scene items with triangles, attachment instances with triangles, and
/// objects (items drawn once plus instances).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct ObjectCounts {
    pub items: usize,
    pub instances: usize,
    pub objects: usize,
}

/// Checks that `objects` cover the mesh's triangles in order and their vertex ranges are in
/// the mesh and hold their triangles' vertices (the writers rely on both).
fn check_objects(path: &Path, mesh: &Mesh, objects: &[GeometryObject<'_>]) -> anyhow::Result<()> {
    let triangles = mesh.triangle_count();
    let contiguous = objects.windows(2).all(|w| w[0].triangles.end == w[1].triangles.start);
    if !contiguous
        || objects.first().map_or(0, |o| o.triangles.start) != 0
        || objects.last().map_or(0, |o| o.triangles.end) != triangles
    {
        anyhow::bail!("cannot write {}: the objects do not cover the {triangles} triangles", path.display());
    }
    for o in objects {
        let inside = o.vertices.end <= mesh.positions.len()
            && mesh.indices[3 * o.triangles.start..3 * o.triangles.end]
                .iter()
                .all(|&i| o.vertices.contains(&(i as usize)));
        if !inside {
            anyhow::bail!("cannot write {}: object {} uses vertices outside its range", path.display(), o.name);
        }
    }
    Ok(())
}

/// Writes `mesh` to `path` in `format`; `parts` give the materials of its triangles.
pub fn write_geometry(path: &Path, mesh: &Mesh, parts: &[GeometryPart], format: GeometryFormat) -> anyhow::Result<()> {
    match format {
        GeometryFormat::Obj => write_obj(path, mesh, parts),
        GeometryFormat::Ply => write_ply(path, mesh),
        GeometryFormat::Glb => write_glb(path, mesh, parts),
        // One frame on its own; the batch runner collects a range into one cache instead.
        GeometryFormat::Usda => crate::io::usda::write_usda(path, 24.0, &[(0, mesh)]),
    }
}

/// An instance's translation, rotation and scale.
type Trs = (Vec3, Quat, Vec3);

/// The translation, rotation and scale of each instance of `part` with triangles, where
/// `instancing` reproduces every such instance's exported vertices (to 1e-5 of their size):
/// the same vertex and triangle counts as the detail mesh, and a placement that is a
/// rotation and per-axis scale (a mirror is a negative scale). None: write it realized.
fn instance_trs(mesh: &Mesh, part: &GeometryPart, instancing: &Instancing) -> Option<Vec<Trs>> {
    let detail = &instancing.mesh;
    let (nv, nt) = (detail.positions.len(), detail.triangle_count());
    if instancing.placements.len() != part.instances.len() || detail.normals.len() != nv || detail.uvs.len() != nv {
        return None;
    }
    let kept = part.instances.iter().zip(&instancing.placements).filter(|(s, _)| !s.triangles.is_empty());
    kept.map(|(span, placement)| {
        if span.vertices.len() != nv || span.triangles.len() != nt {
            return None;
        }
        let (scale, rotation, translation) = placement.to_scale_rotation_translation();
        let trs = glam::Mat4::from_scale_rotation_translation(scale, rotation, translation);
        let realized = &mesh.positions[span.vertices.clone()];
        let size = realized.iter().fold(0.0f32, |m, p| m.max((*p - translation).length()));
        let exact = detail.positions.iter().zip(realized).all(|(p, q)| {
            let d = trs.transform_point3(*p).distance(*q);
            d.is_finite() && d <= 1e-5 * size.max(1e-3)
        });
        exact.then_some((translation, rotation, scale))
    })
    .collect()
}

/// Writes binary glTF 2.0: one buffer (positions, then normals and UVs where every vertex has
/// one, then u32 indices, each object's counted from its first vertex), a mesh and a node per
/// object (an item drawn once, or an attachment instance as a child of a node named after its
/// item; see [`objects`]) whose accessors view its range of the shared arrays, and a
/// metallic-roughness material per item (base colour, metallic 0, roughness 1 - glossiness,
/// double-sided: cloth is seen from both sides). An attachment with [`Instancing`] whose
/// placements reproduce its instances ([`instance_trs`]) is instead one node named after it,
/// holding the detail mesh once and the instances' translations, rotations and scales
/// (`EXT_mesh_gpu_instancing`, listed in `extensionsUsed`). `asset.extras` counts items,
/// instances and objects, and the instances written so as `instanced`. Positions are world
/// space, Y up, as rendered. Parts whose objects do not cover the triangles exactly are an
/// error (one default-grey item is used when `parts` is empty).
pub fn write_glb(path: &Path, mesh: &Mesh, parts: &[GeometryPart]) -> anyhow::Result<()> {
    use serde_json::json;
    let n = mesh.positions.len();
    let fallback = [GeometryPart::whole(mesh, "werkstatt")];
    let parts = if parts.is_empty() { &fallback[..] } else { parts };
    if mesh.indices.iter().any(|&i| i as usize >= n) {
        anyhow::bail!("cannot write {}: an index is past the {n} vertices", path.display());
    }
    let (objects, counts) = objects(parts);
    check_objects(path, mesh, &objects)?;
    let with_normals = n > 0 && mesh.normals.len() == n;
    let with_uvs = n > 0 && mesh.uvs.len() == n;
    let instanced: Vec<Option<(&Mesh, Vec<Trs>)>> = parts
        .iter()
        .map(|part| {
            let instancing = part.instancing.as_deref()?;
            instance_trs(mesh, part, instancing).map(|trs| (&*instancing.mesh, trs))
        })
        .collect();
    // What the buffer holds, in order: each realized object's range of the mesh, or an
    // instanced attachment's detail mesh once (at its first object).
    let mut segments: Vec<(&Mesh, std::ops::Range<usize>, std::ops::Range<usize>, u32)> = Vec::new();
    for (k, o) in objects.iter().enumerate() {
        match &instanced[o.part] {
            Some(_) if k > 0 && objects[k - 1].part == o.part => {}
            Some((detail, _)) => segments.push((detail, 0..detail.positions.len(), 0..detail.triangle_count(), 0)),
            None => segments.push((mesh, o.vertices.clone(), o.triangles.clone(), o.vertices.start as u32)),
        }
    }
    let written = segments.iter().map(|s| s.1.len()).sum::<usize>();
    let written_triangles = segments.iter().map(|s| s.2.len()).sum::<usize>();
    let trs_floats: usize = instanced.iter().flatten().map(|(_, trs)| 10 * trs.len()).sum();
    // One view per array; each object's accessors start at its first vertex.
    let mut views = vec![json!({"buffer": 0, "byteOffset": 0, "byteLength": 12 * written, "target": 34962})];
    let mut offset = 12 * written;
    let mut array_view = |width: usize| {
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": 4 * width * written, "target": 34962}));
        offset += 4 * width * written;
        views.len() - 1
    };
    let normal_view = with_normals.then(|| array_view(3));
    let uv_view = with_uvs.then(|| array_view(2));
    let index_view = views.len();
    views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": 12 * written_triangles, "target": 34963}));
    offset += 12 * written_triangles;
    // Instance translations, rotations and scales: not vertex data, so no target.
    let trs_view = views.len();
    if trs_floats > 0 {
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": 4 * trs_floats}));
    }
    let total = offset + 4 * trs_floats;
    // Materials are named by item index: tools/fidelity/cycles.py finds its items by them.
    let materials: Vec<_> = parts
        .iter()
        .enumerate()
        .map(|(k, part)| {
            let c = part.base_color;
            json!({
                "name": format!("part_{k}"),
                "pbrMetallicRoughness": {"baseColorFactor": [c.x, c.y, c.z, 1.0], "metallicFactor": 0.0,
                    "roughnessFactor": (1.0 - part.glossiness).clamp(0.0, 1.0)},
                "doubleSided": true,
            })
        })
        .collect();
    let (mut accessors, mut meshes, mut nodes, mut roots) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    let (mut item_node, mut segment, mut v0, mut t0, mut trs0, mut instances_written) = (None, 0, 0, 0, 0, 0);
    for (k, o) in objects.iter().enumerate() {
        let instanced = &instanced[o.part];
        if instanced.is_some() && k > 0 && objects[k - 1].part == o.part {
            // A later instance of an attachment written once.
            continue;
        }
        let (source, vertices, tris, _) = segments[segment].clone();
        segment += 1;
        let count = vertices.len();
        let (lo, hi) = source.positions[vertices.clone()]
            .iter()
            .fold((Vec3::splat(f32::MAX), Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
        let attribute = |accessors: &mut Vec<serde_json::Value>, view: usize, width: usize, kind: &str| {
            accessors.push(json!({"bufferView": view, "byteOffset": 4 * width * v0, "componentType": 5126,
                "count": count, "type": kind}));
            accessors.len() - 1
        };
        let mut attributes = serde_json::Map::new();
        let position = attribute(&mut accessors, 0, 3, "VEC3");
        // glTF requires the bounds of POSITION.
        accessors[position]["min"] = json!(lo.to_array());
        accessors[position]["max"] = json!(hi.to_array());
        attributes.insert("POSITION".into(), position.into());
        if let Some(view) = normal_view {
            attributes.insert("NORMAL".into(), attribute(&mut accessors, view, 3, "VEC3").into());
        }
        if let Some(view) = uv_view {
            attributes.insert("TEXCOORD_0".into(), attribute(&mut accessors, view, 2, "VEC2").into());
        }
        accessors.push(json!({"bufferView": index_view, "byteOffset": 12 * t0,
            "componentType": 5125, "count": 3 * tris.len(), "type": "SCALAR"}));
        v0 += count;
        t0 += tris.len();
        let primitive =
            json!({"attributes": attributes, "indices": accessors.len() - 1, "material": o.part, "mode": 4});
        if let Some((_, trs)) = instanced {
            // One node for all instances: translations, then rotations, then scales.
            let name = &parts[o.part].name;
            meshes.push(json!({"name": name, "primitives": [primitive]}));
            let mut trs_accessor = |width: usize, kind: &str| {
                accessors.push(json!({"bufferView": trs_view, "byteOffset": 4 * trs0, "componentType": 5126,
                    "count": trs.len(), "type": kind}));
                trs0 += width * trs.len();
                accessors.len() - 1
            };
            let attributes = json!({"TRANSLATION": trs_accessor(3, "VEC3"), "ROTATION": trs_accessor(4, "VEC4"),
                "SCALE": trs_accessor(3, "VEC3")});
            nodes.push(json!({"name": name, "mesh": meshes.len() - 1,
                "extensions": {"EXT_mesh_gpu_instancing": {"attributes": attributes}}}));
            roots.push(nodes.len() - 1);
            instances_written += trs.len();
            continue;
        }
        meshes.push(json!({"name": o.name, "primitives": [primitive]}));
        let node = json!({"name": o.name, "mesh": meshes.len() - 1});
        if parts[o.part].instances.is_empty() {
            nodes.push(node);
            roots.push(nodes.len() - 1);
            continue;
        }
        // An attachment's instances are children of one node named after the attachment.
        let parent = match item_node {
            Some((part, parent)) if part == o.part => parent,
            _ => {
                nodes.push(json!({"name": parts[o.part].name, "children": []}));
                roots.push(nodes.len() - 1);
                item_node = Some((o.part, nodes.len() - 1));
                nodes.len() - 1
            }
        };
        nodes.push(node);
        let child = nodes.len() - 1;
        nodes[parent]["children"].as_array_mut().expect("an item node has children").push(child.into());
    }
    let mut doc = json!({
        "asset": {"version": "2.0", "generator": "werkstatt",
            "extras": {"items": counts.items, "attachment_instances": counts.instances, "objects": counts.objects}},
        "scene": 0,
        "scenes": [{"nodes": roots}],
        "nodes": nodes,
        "meshes": meshes,
        "materials": materials,
        "buffers": [{"byteLength": total}],
        "bufferViews": views,
        "accessors": accessors,
    });
    if instances_written > 0 {
        doc["asset"]["extras"]["instanced"] = instances_written.into();
        doc["extensionsUsed"] = json!(["EXT_mesh_gpu_instancing"]);
    }
    let mut json = serde_json::to_vec(&doc)?;
    // Chunks are 4-byte aligned: JSON padded with spaces; the binary chunk is whole floats.
    json.resize(json.len().next_multiple_of(4), b' ');
    let length = 12 + 8 + json.len() + 8 + total;
    let length = u32::try_from(length)
        .map_err(|_| anyhow::anyhow!("cannot write {}: {length} bytes is past glTF's 4 GiB", path.display()))?;
    crate::io::atomic::write_atomic_with(path, |out| {
        out.write_all(b"glTF")?;
        out.write_all(&2u32.to_le_bytes())?;
        out.write_all(&length.to_le_bytes())?;
        out.write_all(&(json.len() as u32).to_le_bytes())?;
        out.write_all(b"JSON")?;
        out.write_all(&json)?;
        out.write_all(&(total as u32).to_le_bytes())?;
        out.write_all(b"BIN\0")?;
        let floats = |out: &mut std::io::BufWriter<std::fs::File>, v: &[f32]| -> std::io::Result<()> {
            v.iter().try_for_each(|f| out.write_all(&f.to_le_bytes()))
        };
        for (source, vertices, _, _) in &segments {
            floats(out, bytemuck::cast_slice(&source.positions[vertices.clone()]))?;
        }
        if with_normals {
            for (source, vertices, _, _) in &segments {
                floats(out, bytemuck::cast_slice(&source.normals[vertices.clone()]))?;
            }
        }
        if with_uvs {
            // The mesh's v runs down from the top of the image, as glTF's does.
            for (source, vertices, _, _) in &segments {
                floats(out, bytemuck::cast_slice(&source.uvs[vertices.clone()]))?;
            }
        }
        segments.iter().try_for_each(|(source, _, tris, base)| {
            let indices = &source.indices[3 * tris.start..3 * tris.end];
            indices.iter().try_for_each(|i| out.write_all(&(i - base).to_le_bytes()))
        })?;
        for (_, trs) in instanced.iter().flatten() {
            trs.iter().try_for_each(|(t, _, _)| floats(out, &t.to_array()))?;
            trs.iter().try_for_each(|(_, r, _)| floats(out, &r.to_array()))?;
            trs.iter().try_for_each(|(_, _, s)| floats(out, &s.to_array()))?;
        }
        Ok(())
    })
    .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes OBJ. With `parts` (an export): a header comment counting items, attachment
/// instances and objects, then per object ([`objects`]) `o <name>`, its vertices (positions,
/// UVs with v up, normals) and its triangles, those of a Surface's pattern pieces under
/// `g piece_<id>` when it has several. Without parts (a recorded frame): every vertex, then
/// the triangles, a Surface's pattern pieces as objects `piece_0`, `piece_1`, ... (each id up
/// to the largest, even when empty, so MeshSequence reads the same ids back).
pub fn write_obj(path: &Path, mesh: &Mesh, parts: &[GeometryPart]) -> anyhow::Result<()> {
    let mut out = std::io::BufWriter::new(Vec::new());
    let n = mesh.positions.len();
    let (with_uvs, with_normals) = (mesh.uvs.len() == n, mesh.normals.len() == n);
    let vertex = |out: &mut std::io::BufWriter<Vec<u8>>, i: usize| -> std::io::Result<()> {
        let p = mesh.positions[i];
        writeln!(out, "v {} {} {}", p.x, p.y, p.z)
    };
    let extras = |out: &mut std::io::BufWriter<Vec<u8>>, range: std::ops::Range<usize>| -> std::io::Result<()> {
        if with_uvs {
            // OBJ's v points up.
            mesh.uvs[range.clone()].iter().try_for_each(|t| writeln!(out, "vt {} {}", t.x, 1.0 - t.y))?;
        }
        if with_normals {
            mesh.normals[range].iter().try_for_each(|n| writeln!(out, "vn {} {} {}", n.x, n.y, n.z))?;
        }
        Ok(())
    };
    // `shift` turns a mesh index into the file's (1-based, counting only written vertices).
    let face = |out: &mut std::io::BufWriter<Vec<u8>>, t: &[u32], shift: i64| {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| i as i64 + shift);
        match (with_uvs, with_normals) {
            (true, true) => writeln!(out, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}"),
            (true, false) => writeln!(out, "f {a}/{a} {b}/{b} {c}/{c}"),
            (false, true) => writeln!(out, "f {a}//{a} {b}//{b} {c}//{c}"),
            (false, false) => writeln!(out, "f {a} {b} {c}"),
        }
    };
    let triangles = |range: std::ops::Range<usize>| mesh.indices[3 * range.start..3 * range.end].chunks_exact(3);
    if parts.is_empty() {
        writeln!(out, "# werkstatt export: {n} vertices, {} triangles", mesh.triangle_count())?;
        (0..n).try_for_each(|i| vertex(&mut out, i))?;
        extras(&mut out, 0..n)?;
        if mesh.piece_ids.is_empty() {
            for t in triangles(0..mesh.triangle_count()) {
                face(&mut out, t, 1)?;
            }
        } else {
            // One OBJ object per pattern piece (MeshSequence reads each object as a piece).
            let pieces = mesh.piece_ids.iter().copied().max().unwrap_or(0);
            for piece in 0..=pieces {
                writeln!(out, "o piece_{piece}")?;
                for t in triangles(0..mesh.triangle_count()).filter(|t| mesh.piece_ids[t[0] as usize] == piece) {
                    face(&mut out, t, 1)?;
                }
            }
        }
    } else {
        let (objects, counts) = objects(parts);
        check_objects(path, mesh, &objects)?;
        let written: usize = objects.iter().map(|o| o.vertices.len()).sum();
        let total: usize = objects.iter().map(|o| o.triangles.len()).sum();
        writeln!(
            out,
            "# werkstatt export: {written} vertices, {total} triangles; {} items, {} attachment instances, {} objects",
            counts.items, counts.instances, counts.objects
        )?;
        let mut before = 0;
        for o in &objects {
            writeln!(out, "o {}", o.name)?;
            o.vertices.clone().try_for_each(|i| vertex(&mut out, i))?;
            extras(&mut out, o.vertices.clone())?;
            let shift = (before + 1) as i64 - o.vertices.start as i64;
            let mut ids: Vec<u32> = o.pieces.to_vec();
            ids.sort_unstable();
            ids.dedup();
            if ids.len() < 2 {
                for t in triangles(o.triangles.clone()) {
                    face(&mut out, t, shift)?;
                }
            } else {
                for id in ids {
                    writeln!(out, "g piece_{id}")?;
                    let of_piece = o.pieces.iter().map(|&p| p == id);
                    for (t, _) in triangles(o.triangles.clone()).zip(of_piece).filter(|(_, mine)| *mine) {
                        face(&mut out, t, shift)?;
                    }
                }
            }
            before += o.vertices.len();
        }
    }
    let bytes = out.into_inner().map_err(|e| anyhow::anyhow!("{e}"))?;
    crate::io::atomic::write_atomic(path, &bytes).with_context(|| format!("cannot write {}", path.display()))
}

pub fn write_ply(path: &Path, mesh: &Mesh) -> anyhow::Result<()> {
    let header = format!(
        "ply\nformat binary_little_endian 1.0\ncomment werkstatt export\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float s\nproperty float t\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangle_count()
    );
    // The file's bytes are streamed in blocks (a 10k-button export is 420 MB, never a second
    // copy of the mesh in memory), each built on another thread while the previous one is
    // written.
    let vertex = |i: usize| {
        let (p, n, uv) = (mesh.positions[i], mesh.normals[i], mesh.uvs[i]);
        [p.x, p.y, p.z, n.x, n.y, n.z, uv.x, 1.0 - uv.y].map(f32::to_le_bytes)
    };
    let face = |t: &[u32]| {
        let mut face = [3u8; 13];
        for (k, i) in t.iter().enumerate() {
            face[1 + 4 * k..5 + 4 * k].copy_from_slice(&i.to_le_bytes());
        }
        face
    };
    const PER_BLOCK: usize = 1 << 16;
    crate::io::atomic::write_atomic_with(path, |out| {
        out.write_all(header.as_bytes())?;
        write_pipelined(out, mesh.positions.len(), PER_BLOCK, |range, block| {
            range.for_each(|i| block.extend_from_slice(vertex(i).as_flattened()));
        })?;
        write_pipelined(out, mesh.triangle_count(), PER_BLOCK, |range, block| {
            range.for_each(|t| block.extend_from_slice(&face(&mesh.indices[3 * t..3 * t + 3])));
        })
    })
    .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes `items` records in blocks of `per_block`: `fill` appends a range's records to a
/// block on a second thread while `out` takes the block before, so building the bytes and the
/// kernel's copy overlap. Three blocks are reused throughout.
fn write_pipelined(
    out: &mut impl std::io::Write,
    items: usize,
    per_block: usize,
    fill: impl Fn(std::ops::Range<usize>, &mut Vec<u8>) + Send,
) -> std::io::Result<()> {
    let per_block = per_block.max(1);
    let (full_tx, full_rx) = std::sync::mpsc::sync_channel::<Vec<u8>>(2);
    let (empty_tx, empty_rx) = std::sync::mpsc::channel::<Vec<u8>>();
    for _ in 0..3 {
        let _ = empty_tx.send(Vec::new());
    }
    std::thread::scope(|scope| {
        scope.spawn(move || {
            for start in (0..items).step_by(per_block) {
                // Both channels close when the writer stops (done or failed).
                let Ok(mut block) = empty_rx.recv() else { return };
                block.clear();
                fill(start..(start + per_block).min(items), &mut block);
                if full_tx.send(block).is_err() {
                    return;
                }
            }
        });
        // Owns the writer's channel ends, so an error drops them and the builder stops.
        (move || {
            for block in full_rx {
                out.write_all(&block)?;
                let _ = empty_tx.send(block);
            }
            Ok(())
        })()
    })
}

#[cfg(test)]
mod tests {
    use glam::{Vec2, Vec3};

    /// Blocks arrive in order and whole, and a failing writer stops the builder (no hang).
    #[test]
    fn pipelined_blocks_keep_their_order_and_stop_on_a_write_error() {
        let fill = |range: std::ops::Range<usize>, block: &mut Vec<u8>| block.extend(range.map(|i| i as u8));
        let mut out = Vec::new();
        super::write_pipelined(&mut out, 100, 7, fill).unwrap();
        assert_eq!(out, (0..100u8).collect::<Vec<_>>());
        struct Full;
        impl std::io::Write for Full {
            fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
                Err(std::io::Error::other("disk full"))
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        assert!(super::write_pipelined(&mut Full, 1000, 7, fill).is_err());
    }

    /// OBJ with parts: an object per item drawn once (a Surface's pieces as groups) and per
    /// attachment instance with triangles; an instance without any leaves its vertices out and
    /// a gap in the numbering, and later faces still point at their own vertices.
    #[test]
    fn obj_objects_are_items_and_instances_with_pieces_as_groups() {
        use super::{GeometryPart, Span};
        let tri = |x: f32| [Vec3::new(x, 0.0, 0.0), Vec3::new(x + 1.0, 0.0, 0.0), Vec3::new(x, 1.0, 0.0)];
        let positions: Vec<Vec3> = (0..5).flat_map(|k| tri(k as f32)).collect();
        // Cloth: vertices 0..6, a triangle of piece 1 then one of piece 0; three instances of a
        // triangle at 6..15, the middle one dropped.
        let indices = vec![0, 1, 2, 3, 4, 5, 6, 7, 8, 12, 13, 14];
        let mesh = crate::mesh::Mesh::from_raw(
            positions,
            vec![Vec3::Z; 15],
            vec![Vec2::ZERO; 15],
            Vec::new(),
            Vec::new(),
            indices,
        );
        let part = |name: &str, vertices, triangles, instances, pieces| GeometryPart {
            name: name.into(),
            vertices,
            triangles,
            instances,
            pieces,
            instancing: None,
            base_color: Vec3::ONE,
            glossiness: 0.0,
        };
        let spans = vec![
            Span { vertices: 6..9, triangles: 2..3 },
            Span { vertices: 9..12, triangles: 3..3 },
            Span { vertices: 12..15, triangles: 3..4 },
        ];
        let parts = [part("cloth", 0..6, 0..2, Vec::new(), vec![1, 0]), part("b", 6..15, 2..4, spans, Vec::new())];
        let path = std::env::temp_dir().join(format!("werkstatt-objects-{}.obj", std::process::id()));
        super::write_obj(&path, &mesh, &parts).unwrap();
        let text = std::fs::read_to_string(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        let lines: Vec<&str> = text.lines().filter(|l| !l.starts_with("v")).collect();
        assert_eq!(
            lines,
            [
                "# werkstatt export: 12 vertices, 4 triangles; 2 items, 2 attachment instances, 3 objects",
                "o cloth",
                "g piece_0",
                "f 4/4/4 5/5/5 6/6/6",
                "g piece_1",
                "f 1/1/1 2/2/2 3/3/3",
                "o b_0",
                "f 7/7/7 8/8/8 9/9/9",
                "o b_2",
                "f 10/10/10 11/11/11 12/12/12",
            ]
        );
        assert_eq!(text.lines().filter(|l| l.starts_with("v ")).count(), 12);
    }

    /// Binary PLY: the header's counts, 32 bytes per vertex (position, normal, s, t = 1 - v),
    /// 13 per face (count 3, three indices), little-endian.
    #[test]
    fn ply_records_are_little_endian_and_complete() {
        let mesh = crate::mesh::Mesh::from_raw(
            vec![Vec3::new(1.0, 2.0, 3.0), Vec3::X, Vec3::Y],
            vec![Vec3::Z; 3],
            vec![Vec2::new(0.25, 0.75), Vec2::ZERO, Vec2::ONE],
            Vec::new(),
            Vec::new(),
            vec![0, 1, 2],
        );
        let path = std::env::temp_dir().join(format!("werkstatt-ply-{}.ply", std::process::id()));
        super::write_ply(&path, &mesh).unwrap();
        let bytes = std::fs::read(&path).unwrap();
        let _ = std::fs::remove_file(&path);
        let end = b"end_header\n";
        let body = bytes.windows(end.len()).position(|w| w == end).unwrap() + end.len();
        let header = std::str::from_utf8(&bytes[..body]).unwrap();
        assert!(header.contains("element vertex 3\n") && header.contains("element face 1\n"), "{header}");
        assert_eq!(bytes.len() - body, 3 * 32 + 13);
        let f = |k: usize| f32::from_le_bytes(bytes[body + 4 * k..body + 4 * k + 4].try_into().unwrap());
        assert_eq!((0..8).map(f).collect::<Vec<_>>(), [1.0, 2.0, 3.0, 0.0, 0.0, 1.0, 0.25, 0.25]);
        let face = &bytes[body + 96..];
        assert_eq!(face[0], 3);
        let index = |k: usize| u32::from_le_bytes(face[1 + 4 * k..5 + 4 * k].try_into().unwrap());
        assert_eq!([index(0), index(1), index(2)], [0, 1, 2]);
    }
}

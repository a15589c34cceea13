//! Writing geometry files: OBJ (text), PLY (binary little-endian) and binary glTF (.glb, with a
//! material per part), atomically.

use std::io::Write as _;
use std::path::Path;

use anyhow::Context as _;

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

/// A run of an export's triangles drawn with one material: the material of the scene item they
/// came from. glTF writes one primitive with its own material per part; OBJ and PLY ignore them.
#[derive(Clone, Debug, PartialEq)]
pub struct GeometryPart {
    /// Triangle indices (not index-buffer offsets) into the exported mesh.
    pub triangles: std::ops::Range<usize>,
    /// Linear RGB.
    pub base_color: glam::Vec3,
    /// 0 = rough, 1 = mirror-like (the renderer's glossiness).
    pub glossiness: f32,
}

/// Writes `mesh` to `path` in `format`; `parts` give the materials of its triangles.
pub fn write_geometry(path: &Path, mesh: &Mesh, parts: &[GeometryPart], format: GeometryFormat) -> anyhow::Result<()> {
    match format {
        GeometryFormat::Obj => write_obj(path, mesh),
        GeometryFormat::Ply => write_ply(path, mesh),
        GeometryFormat::Glb => write_glb(path, mesh, parts),
        // One frame on its own; the batch runner collects a range into one cache instead.
        GeometryFormat::Usda => crate::io::usda::write_usda(path, 24.0, &[(0, mesh)]),
    }
}

/// Writes binary glTF 2.0: one buffer (positions, then normals and UVs where every vertex has
/// one, then u32 indices), one mesh with a primitive per part sharing the vertex accessors, and
/// a metallic-roughness material per part (base colour, metallic 0, roughness 1 - glossiness,
/// double-sided: cloth is seen from both sides). Positions are world space, Y up, as rendered.
/// Parts that do not cover the triangles exactly are an error (one default-grey part is used
/// when `parts` is empty).
pub fn write_glb(path: &Path, mesh: &Mesh, parts: &[GeometryPart]) -> anyhow::Result<()> {
    use serde_json::json;
    let (n, triangles) = (mesh.positions.len(), mesh.triangle_count());
    let fallback = [GeometryPart { triangles: 0..triangles, base_color: glam::Vec3::splat(0.8), glossiness: 0.2 }];
    let parts = if parts.is_empty() { &fallback[..] } else { parts };
    let contiguous = parts.windows(2).all(|w| w[0].triangles.end == w[1].triangles.start);
    if !contiguous || parts[0].triangles.start != 0 || parts[parts.len() - 1].triangles.end != triangles {
        anyhow::bail!("cannot write {}: the material parts do not cover the {triangles} triangles", path.display());
    }
    if mesh.indices.iter().any(|&i| i as usize >= n) {
        anyhow::bail!("cannot write {}: an index is past the {n} vertices", path.display());
    }
    let with_normals = n > 0 && mesh.normals.len() == n;
    let with_uvs = n > 0 && mesh.uvs.len() == n;
    let (lo, hi) = mesh
        .positions
        .iter()
        .fold((glam::Vec3::splat(f32::MAX), glam::Vec3::splat(f32::MIN)), |(lo, hi), p| (lo.min(*p), hi.max(*p)));
    let mut views = Vec::new();
    let mut accessors = Vec::new();
    let mut offset = 0usize;
    let mut vertex_attribute = |views: &mut Vec<_>, accessors: &mut Vec<_>, width: usize, kind: &str| {
        views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": 4 * width * n, "target": 34962}));
        let mut a = json!({"bufferView": views.len() - 1, "componentType": 5126, "count": n, "type": kind});
        if kind == "VEC3" && accessors.is_empty() {
            // glTF requires the bounds of POSITION.
            a["min"] = json!(lo.to_array());
            a["max"] = json!(hi.to_array());
        }
        accessors.push(a);
        offset += 4 * width * n;
        accessors.len() - 1
    };
    let mut attributes = serde_json::Map::new();
    attributes.insert("POSITION".into(), vertex_attribute(&mut views, &mut accessors, 3, "VEC3").into());
    if with_normals {
        attributes.insert("NORMAL".into(), vertex_attribute(&mut views, &mut accessors, 3, "VEC3").into());
    }
    if with_uvs {
        attributes.insert("TEXCOORD_0".into(), vertex_attribute(&mut views, &mut accessors, 2, "VEC2").into());
    }
    let index_view = views.len();
    views.push(json!({"buffer": 0, "byteOffset": offset, "byteLength": 12 * triangles, "target": 34963}));
    let total = offset + 12 * triangles;
    let mut primitives = Vec::new();
    let mut materials = Vec::new();
    for (k, part) in parts.iter().enumerate() {
        let c = part.base_color;
        materials.push(json!({
            "name": format!("part_{k}"),
            "pbrMetallicRoughness": {"baseColorFactor": [c.x, c.y, c.z, 1.0], "metallicFactor": 0.0,
                "roughnessFactor": (1.0 - part.glossiness).clamp(0.0, 1.0)},
            "doubleSided": true,
        }));
        if part.triangles.is_empty() {
            continue;
        }
        accessors.push(json!({"bufferView": index_view, "byteOffset": 12 * part.triangles.start,
            "componentType": 5125, "count": 3 * part.triangles.len(), "type": "SCALAR"}));
        primitives.push(json!({"attributes": attributes, "indices": accessors.len() - 1, "material": k, "mode": 4}));
    }
    let doc = json!({
        "asset": {"version": "2.0", "generator": "werkstatt"},
        "scene": 0,
        "scenes": [{"nodes": [0]}],
        "nodes": [{"name": "werkstatt", "mesh": 0}],
        "meshes": [{"name": "werkstatt", "primitives": primitives}],
        "materials": materials,
        "buffers": [{"byteLength": total}],
        "bufferViews": views,
        "accessors": accessors,
    });
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
        floats(out, bytemuck::cast_slice(&mesh.positions))?;
        if with_normals {
            floats(out, bytemuck::cast_slice(&mesh.normals))?;
        }
        if with_uvs {
            // The mesh's v runs down from the top of the image, as glTF's does.
            floats(out, bytemuck::cast_slice(&mesh.uvs))?;
        }
        mesh.indices[..3 * triangles].iter().try_for_each(|i| out.write_all(&i.to_le_bytes()))
    })
    .with_context(|| format!("cannot write {}", path.display()))
}

/// Writes OBJ: positions, UVs (v up), normals and triangles; a Surface's pattern pieces as
/// objects `piece_0`, `piece_1`, ... (the faces of each piece in their order).
pub fn write_obj(path: &Path, mesh: &Mesh) -> anyhow::Result<()> {
    let mut out = std::io::BufWriter::new(Vec::new());
    writeln!(out, "# werkstatt export: {} vertices, {} triangles", mesh.positions.len(), mesh.triangle_count())?;
    for p in &mesh.positions {
        writeln!(out, "v {} {} {}", p.x, p.y, p.z)?;
    }
    for t in &mesh.uvs {
        // OBJ's v points up.
        writeln!(out, "vt {} {}", t.x, 1.0 - t.y)?;
    }
    for n in &mesh.normals {
        writeln!(out, "vn {} {} {}", n.x, n.y, n.z)?;
    }
    let face = |out: &mut std::io::BufWriter<Vec<u8>>, t: &[u32]| {
        let [a, b, c] = [t[0] + 1, t[1] + 1, t[2] + 1];
        writeln!(out, "f {a}/{a}/{a} {b}/{b}/{b} {c}/{c}/{c}")
    };
    if mesh.piece_ids.is_empty() {
        for t in mesh.indices.chunks_exact(3) {
            face(&mut out, t)?;
        }
    } else {
        // One OBJ object per pattern piece (MeshSequence reads each object as a piece), every
        // id up to the largest written even when empty, so the ids read back the same.
        let pieces = mesh.piece_ids.iter().copied().max().unwrap_or(0);
        for piece in 0..=pieces {
            writeln!(out, "o piece_{piece}")?;
            for t in mesh.indices.chunks_exact(3).filter(|t| mesh.piece_ids[t[0] as usize] == piece) {
                face(&mut out, t)?;
            }
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

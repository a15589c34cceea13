//! Writing geometry files: OBJ (text) and PLY (binary little-endian), atomically.

use std::io::Write as _;
use std::path::Path;

use anyhow::Context as _;

use crate::mesh::Mesh;

crate::choice!(
    /// The geometry file formats `render` writes; the option names are the file extensions.
    pub enum GeometryFormat {
        Obj = "obj",
        Ply = "ply",
    }
);

/// Writes `mesh` to `path` in `format`.
pub fn write_geometry(path: &Path, mesh: &Mesh, format: GeometryFormat) -> anyhow::Result<()> {
    match format {
        GeometryFormat::Obj => write_obj(path, mesh),
        GeometryFormat::Ply => write_ply(path, mesh),
    }
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
    crate::atomic::write_atomic(path, &bytes).with_context(|| format!("cannot write {}", path.display()))
}

pub fn write_ply(path: &Path, mesh: &Mesh) -> anyhow::Result<()> {
    let mut out = Vec::new();
    write!(
        out,
        "ply\nformat binary_little_endian 1.0\ncomment werkstatt export\nelement vertex {}\nproperty float x\nproperty float y\nproperty float z\nproperty float nx\nproperty float ny\nproperty float nz\nproperty float s\nproperty float t\nelement face {}\nproperty list uchar uint vertex_indices\nend_header\n",
        mesh.positions.len(),
        mesh.triangle_count()
    )?;
    for i in 0..mesh.positions.len() {
        for f in mesh.positions[i]
            .to_array()
            .into_iter()
            .chain(mesh.normals[i].to_array())
            .chain([mesh.uvs[i].x, 1.0 - mesh.uvs[i].y])
        {
            out.extend_from_slice(&f.to_le_bytes());
        }
    }
    for t in mesh.indices.chunks_exact(3) {
        out.push(3);
        for i in t {
            out.extend_from_slice(&i.to_le_bytes());
        }
    }
    crate::atomic::write_atomic(path, &out).with_context(|| format!("cannot write {}", path.display()))
}

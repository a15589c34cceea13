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

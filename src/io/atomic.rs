//! Atomic file writes: a reader sees the old file or the new one, never half of one, and a
//! write that fails (a full disk) leaves the old file and no temporary behind.

use std::io::Write;
use std::path::Path;

pub fn write_atomic(path: &Path, bytes: &[u8]) -> std::io::Result<()> {
    write_atomic_with(path, |f| f.write_all(bytes))
}

/// `write_atomic` for data written in pieces (a large export streamed through a buffer, never
/// whole in memory).
pub fn write_atomic_with(
    path: &Path,
    write: impl FnOnce(&mut std::io::BufWriter<std::fs::File>) -> std::io::Result<()>,
) -> std::io::Result<()> {
    let dir = path.parent().filter(|p| !p.as_os_str().is_empty()).unwrap_or(Path::new("."));
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let tmp = Temporary(dir.join(format!(".{name}.{}.tmp", std::process::id())));
    let mut f = std::io::BufWriter::with_capacity(1 << 20, std::fs::File::create(&tmp.0)?);
    write(&mut f)?;
    let f = f.into_inner().map_err(std::io::IntoInnerError::into_error)?;
    f.sync_all()?;
    std::fs::rename(&tmp.0, path)
}

/// A temporary file removed when dropped: after a failed write, or a panic while writing; a
/// renamed one is gone already and the removal fails harmlessly.
struct Temporary(std::path::PathBuf);

impl Drop for Temporary {
    fn drop(&mut self) {
        let _ = std::fs::remove_file(&self.0);
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn a_failed_write_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("werkstatt-atomic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        // Renaming onto a non-empty directory fails after the temporary was written.
        let target = dir.join("occupied");
        std::fs::create_dir_all(target.join("inside")).unwrap();
        assert!(super::write_atomic(&target, b"data").is_err());
        let left: Vec<_> = std::fs::read_dir(&dir).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left, ["occupied"], "only the directory remains");
        super::write_atomic(&dir.join("file"), b"data").unwrap();
        assert_eq!(std::fs::read(dir.join("file")).unwrap(), b"data");
        std::fs::remove_dir_all(&dir).unwrap();
    }

    /// A writer that panics half-way (a bug in a streamed export) leaves no temporary either.
    #[test]
    fn a_panic_while_writing_leaves_no_temporary() {
        let dir = std::env::temp_dir().join(format!("werkstatt-atomic-panic-{}", std::process::id()));
        std::fs::create_dir_all(&dir).unwrap();
        let target = dir.join("export.ply");
        let result = std::panic::catch_unwind(|| {
            super::write_atomic_with(&target, |f| {
                std::io::Write::write_all(f, b"half")?;
                panic!("a bug while writing")
            })
        });
        assert!(result.is_err());
        assert_eq!(std::fs::read_dir(&dir).unwrap().count(), 0, "the temporary is removed");
        std::fs::remove_dir_all(&dir).unwrap();
    }
}

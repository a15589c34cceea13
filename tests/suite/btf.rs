//! `werkstatt btf`: writing a BTF file and compressing it from the command line.

use std::process::Command;

fn werkstatt(args: &[&str]) -> (i32, String, String) {
    let out = Command::new(env!("CARGO_BIN_EXE_werkstatt")).args(args).output().unwrap();
    (
        out.status.code().unwrap_or(-1),
        String::from_utf8_lossy(&out.stdout).into_owned(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn btf_compress_prints_sizes_and_errors() {
    let dir = std::env::temp_dir().join(format!("werkstatt-btf-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).unwrap();
    let file = dir.join("lambert.btf");
    let path = file.to_str().unwrap();
    let (code, _, err) = werkstatt(&["btf", "lambertian", "--out", path, "--size", "16"]);
    assert_eq!(code, 0, "{err}");
    let (code, out, err) = werkstatt(&["btf", "compress", path, "-c", "4"]);
    assert_eq!(code, 0, "{err}");
    // 19 x 19 images of 16x16 RGB as f16: 554,496 bytes. The file's slots have low rank (3
    // light angles, 2 albedos), so at most 4 components reconstruct them exactly.
    assert!(out.contains("19 views x 19 lights, c = 4, Mean centring") && out.contains("0.53 MiB raw"), "{out}");
    assert!(out.contains("relative Frobenius error 0.000e0"), "{out}");
    assert!(out.contains("8-bit RGB error length"), "{out}");
    // A damaged file is an error that names it, not a panic.
    std::fs::write(&file, b"{}\n").unwrap();
    let (code, _, err) = werkstatt(&["btf", "compress", path]);
    assert_eq!(code, 1, "{err}");
    assert!(err.contains("lambert.btf") && !err.contains("panicked"), "{err}");
}

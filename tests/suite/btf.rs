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

#[test]
fn btf_bake_writes_a_cached_btf_and_import_reads_a_bonn_folder() {
    let dir = std::env::temp_dir().join(format!("werkstatt-btf-bake-cli-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).unwrap();
    let out = dir.join("twill.btf");
    let path = out.to_str().unwrap();
    let bake = ["btf", "bake", "--weave", "twill", "--tier", "test", "--warp", "0.5,0.5,0.1", "--out", path];
    let (code, first, err) = werkstatt(&bake);
    assert_eq!(code, 0, "{err}");
    assert!(first.contains("baked Twill 32x32 texels, 19 views x 19 lights") && first.contains("cached as"), "{first}");
    let bytes = std::fs::read(&out).unwrap();
    // The second bake with the same parameters comes from the cache, byte for byte.
    std::fs::remove_file(&out).unwrap();
    let (code, second, err) = werkstatt(&bake);
    assert_eq!(code, 0, "{err}");
    assert!(second.contains("from the cache"), "{second}");
    assert!(std::fs::read(&out).unwrap() == bytes, "the cached bake differs");
    let (code, out_text, err) = werkstatt(&["btf", "compress", path, "-c", "8"]);
    assert_eq!(code, 0, "{err}");
    assert!(out_text.contains("19 views x 19 lights, c = 8"), "{out_text}");
    let (code, _, err) = werkstatt(&["btf", "bake", "--warp", "1,2", "--out", path]);
    assert_eq!(code, 1);
    assert!(err.contains("--warp takes three numbers"), "{err}");

    // One frontal image, spread over the test tier's 19 x 19 directions.
    let bonn = dir.join("bonn");
    std::fs::create_dir_all(bonn.join("tv000_pv000")).unwrap();
    let image = bonn.join("tv000_pv000/00000 tl000 pl000 tv000 pv000.png");
    image::RgbImage::from_pixel(4, 4, image::Rgb([255, 128, 0])).save(&image).unwrap();
    let imported = dir.join("bonn.btf");
    let args = ["btf", "import", bonn.to_str().unwrap(), "--sampling", "tests", "--out", imported.to_str().unwrap()];
    let (code, text, err) = werkstatt(&args);
    assert_eq!(code, 0, "{err}");
    assert!(text.contains("4x4 texels, 19 views x 19 lights"), "{text}");
    std::fs::write(&image, b"broken").unwrap();
    let (code, _, err) = werkstatt(&args);
    assert_eq!(code, 1);
    assert!(err.contains("cannot read the image") && err.contains("00000 tl000 pl000 tv000 pv000.png"), "{err}");
}

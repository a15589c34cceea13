//! The integration tests, as one test binary: every file of tests/ linked against wgpu (and
//! egui) on its own dominated the build time of `cargo test`, so they are modules of this crate
//! instead. Tests of different modules run on parallel threads of one process: a test must not
//! change process-wide state (the environment, the current folder) and writes only into
//! folders named after itself (see `common::out_dir`).

mod common;

mod alembic;
mod avatar;
mod bounce;
mod btf;
mod btf_render;
mod cli;
mod cloth;
mod cloth_collision;
mod cuboid;
mod draco;
#[cfg(feature = "editor")]
mod editor;
#[cfg(feature = "editor")]
mod editor_shaders;
mod evaluation;
mod export_kinds;
mod fidelity;
mod figures;
mod formats;
mod garment;
mod gl_backend;
mod gpu_engine;
mod graph_errors;
mod graph_props;
mod ibl;
mod live_link;
mod loaders;
mod mesh;
mod mesh_sequence;
mod node_contracts;
mod placing;
mod regression;
mod render;
mod roundtrip;
mod scene_drawer;
mod shader_lint;
mod shadow;
mod ssao;
mod ssr;
mod tessellation;
mod usd;
mod warping;
mod woven;

/// Cargo.toml sets `autotests = false`, so a test file put directly under tests/ would not be
/// built at all, and one in tests/suite/ only when it is declared above.
#[test]
fn every_test_file_is_a_module_of_this_suite() {
    let tests = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests");
    let rust_files = |dir: &std::path::Path| -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.ends_with(".rs"))
            .collect();
        names.sort();
        names
    };
    let stray = rust_files(&tests);
    assert!(
        stray.is_empty(),
        "{stray:?} in tests/ would not be built: move them to tests/suite/ and declare them there"
    );
    let main = std::fs::read_to_string(tests.join("suite/main.rs")).unwrap();
    for name in rust_files(&tests.join("suite")) {
        let module = name.trim_end_matches(".rs");
        assert!(
            name == "main.rs" || main.lines().any(|l| l.trim() == format!("mod {module};")),
            "tests/suite/{name} is not declared in tests/suite/main.rs, so it is not built"
        );
    }
}

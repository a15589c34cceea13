//! The integration tests of the engine, the command line, the editor and the file formats, as
//! one test binary; tests/suite/techniques.rs is the other, with the node families'
//! techniques (the two build in parallel). Every file of tests/ linked against wgpu (and egui)
//! on its own dominated the build time of `cargo test`, so they are modules of these two
//! crates instead. Tests of different modules run on parallel threads of one process: a test must not
//! change process-wide state (the environment, the current folder) and writes only into
//! folders named after itself (see `common::out_dir`).

mod common;

mod alembic;
mod cli;
mod draco;
#[cfg(feature = "editor")]
mod editor;
#[cfg(feature = "editor")]
mod editor_shaders;
mod evaluation;
mod export_kinds;
mod formats;
mod gl_backend;
mod gpu_engine;
mod graph_errors;
mod graph_props;
mod live_link;
mod loaders;
mod mesh;
mod mesh_sequence;
mod node_contracts;
mod placing;
mod regression;
mod render;
mod roundtrip;
mod shader_lint;
mod usd;

/// Cargo.toml sets `autotests = false`, so a test file put directly under tests/ would not be
/// built at all, and one in tests/suite/ only when it is declared above or in techniques.rs.
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
    let roots = ["main.rs", "techniques.rs"];
    let declared: Vec<String> =
        roots.iter().map(|r| std::fs::read_to_string(tests.join("suite").join(r)).unwrap()).collect();
    for name in rust_files(&tests.join("suite")) {
        let module = name.trim_end_matches(".rs");
        let count = declared.iter().filter(|d| d.lines().any(|l| l.trim() == format!("mod {module};"))).count();
        assert!(
            roots.contains(&name.as_str()) || count == 1 || (module == "common" && count == 2),
            "tests/suite/{name} is declared in {count} of tests/suite/main.rs and techniques.rs: it must be in one"
        );
    }
}

//! A test of the module structure: no module of `src/` (or the node library) imports one that
//! imports it back, directly or through others, so each layer can be read and changed alone.
//! Modules of the layer folders (`core`, `io`, `app`) count one by one (`core::graph`), and so
//! do the node library's family folders (`nodes/render/` is `nodes::render`); the `render`
//! folder (the scene and the drawer, whose items carry their kind of draw) and a technique's
//! folder (`cloth`, `warp`, `cuboid`, `tessellation`, `ibl`, `occlusion`) count as one module
//! each. A technique imports no node (`crate::nodes`): the nodes are built on the techniques.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;

/// Folders of `src/` that group modules of one layer, each module counted alone, and the node
/// library (`nodes/`, beside `src/`), each family counted alone.
const LAYERS: [&str; 4] = ["core", "io", "app", "nodes"];

/// The module a source file belongs to (`src/gpu/pool.rs` -> `gpu`, `src/core/graph.rs` ->
/// `core::graph`, `src/render/draw/kinds/mesh.rs` -> `render`, `nodes/warp/attach.rs` ->
/// `nodes::warp`).
fn module_of(root: &Path, file: &Path) -> Option<String> {
    let rel = file.strip_prefix(root).ok()?;
    let mut parts = rel.components().map(|c| c.as_os_str().to_string_lossy().into_owned());
    let top = parts.next()?;
    let name = match top.as_str() {
        "nodes" => top,
        _ => parts.next()?.trim_end_matches(".rs").to_string(),
    };
    if LAYERS.contains(&name.as_str()) {
        let second = parts.next()?;
        let inner = second.trim_end_matches(".rs");
        return (inner != "mod").then(|| format!("{name}::{inner}"));
    }
    (name != "lib" && name != "main").then_some(name)
}

/// The module a path after `crate::` names (`core::graph::Graph` -> `core::graph`).
fn named_module(path: &str) -> String {
    let mut parts = path.split("::");
    let first = parts.next().unwrap_or_default();
    match parts.next() {
        Some(second) if LAYERS.contains(&first) => format!("{first}::{second}"),
        _ => first.to_string(),
    }
}

fn rust_files(dir: &Path, out: &mut Vec<std::path::PathBuf>) {
    for entry in std::fs::read_dir(dir).into_iter().flatten().flatten() {
        let path = entry.path();
        if path.is_dir() {
            rust_files(&path, out);
        } else if path.extension().is_some_and(|e| e == "rs") {
            out.push(path);
        }
    }
}

/// Module -> the modules it names as `crate::name`.
fn imports(root: &Path) -> BTreeMap<String, BTreeSet<String>> {
    let mut files = Vec::new();
    rust_files(&root.join("src"), &mut files);
    rust_files(&root.join("nodes"), &mut files);
    let mut graph: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for file in files {
        let Some(module) = module_of(root, &file) else { continue };
        // Code only: doc links to other modules are not imports.
        let text: String = std::fs::read_to_string(&file)
            .unwrap_or_default()
            .lines()
            .map(|l| l.split("//").next().unwrap_or(""))
            .collect::<Vec<_>>()
            .join("\n");
        let deps = graph.entry(module.clone()).or_default();
        for (i, _) in text.match_indices("crate::") {
            let path: String =
                text[i + 7..].chars().take_while(|c| c.is_ascii_alphanumeric() || *c == '_' || *c == ':').collect();
            // `crate::choice!` and friends are macros, not module imports.
            let is_macro = text[i + 7 + path.len()..].starts_with('!');
            let name = named_module(path.trim_end_matches(':'));
            if !name.is_empty() && name != module && !is_macro {
                deps.insert(name);
            }
        }
    }
    graph
}

/// A cycle through `start`, as a path of module names, if there is one.
fn cycle_from(graph: &BTreeMap<String, BTreeSet<String>>, start: &str) -> Option<Vec<String>> {
    let mut stack = vec![(start.to_string(), vec![start.to_string()])];
    let mut seen = BTreeSet::new();
    while let Some((node, path)) = stack.pop() {
        for next in graph.get(&node).into_iter().flatten() {
            if next == start {
                let mut cycle = path.clone();
                cycle.push(start.to_string());
                return Some(cycle);
            }
            if seen.insert(next.clone()) {
                let mut p = path.clone();
                p.push(next.clone());
                stack.push((next.clone(), p));
            }
        }
    }
    None
}

#[test]
fn no_module_imports_one_that_imports_it_back() {
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let graph = imports(root);
    assert!(graph.len() > 10, "found only {:?}", graph.keys());
    let cycles: Vec<String> = graph.keys().filter_map(|m| cycle_from(&graph, m)).map(|c| c.join(" -> ")).collect();
    assert!(cycles.is_empty(), "import cycles:\n{}", cycles.join("\n"));
}

/// The technique folders of `src/`: algorithms the nodes run, below the node library.
const TECHNIQUES: [&str; 7] = ["btf", "cloth", "warp", "cuboid", "tessellation", "ibl", "occlusion"];

#[test]
fn no_technique_imports_a_node() {
    let graph = imports(Path::new(env!("CARGO_MANIFEST_DIR")));
    for technique in TECHNIQUES {
        let deps = graph.get(technique).unwrap_or_else(|| panic!("no module {technique} in src/"));
        let nodes: Vec<&String> = deps.iter().filter(|d| d.split("::").next() == Some("nodes")).collect();
        assert!(nodes.is_empty(), "{technique} imports {nodes:?}: a technique must not depend on the nodes");
    }
}

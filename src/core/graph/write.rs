//! The canonical writer (`werkstatt fmt`, the editor's save).

use std::fmt::Write as _;
use std::path::Path;

use super::model::Graph;
use crate::core::param::ParamValue;

impl Graph {
    /// The canonical text: sorted ids, parameters and links, four-space indents,
    /// floats in their shortest exact form. `load` then `to_ron` gives back the same bytes.
    pub fn to_ron(&self) -> String {
        let mut out = String::new();
        let _ = writeln!(out, "(\n    version: {},\n    nodes: {{", self.version);
        for (id, node) in &self.nodes {
            let _ = writeln!(out, "        {}: (", quote(id));
            let _ = writeln!(out, "            kind: {},", quote(&node.kind));
            // Positions are f32: print them as f32 so 0.1 stays 0.1.
            let _ = writeln!(out, "            pos: ({:?}, {:?}),", node.pos[0], node.pos[1]);
            if node.params.is_empty() {
                out.push_str("            params: {},\n");
            } else {
                out.push_str("            params: {\n");
                for (name, value) in &node.params {
                    let _ = writeln!(out, "                {}: {},", quote(name), value_ron(value));
                }
                out.push_str("            },\n");
            }
            out.push_str("        ),\n");
        }
        out.push_str("    },\n");
        let mut links = self.links.clone();
        links.sort();
        if links.is_empty() {
            out.push_str("    links: [],\n");
        } else {
            out.push_str("    links: [\n");
            for l in &links {
                let _ = writeln!(out, "        ({}, {}),", quote(&l.from.to_string()), quote(&l.to.to_string()));
            }
            out.push_str("    ],\n");
        }
        out.push_str(")\n");
        out
    }

    /// Writes the canonical text atomically: a temporary file in the same folder, then a rename,
    /// so a crash mid-save never leaves a half-written graph.
    pub fn save(&self, path: &Path) -> std::io::Result<()> {
        crate::io::atomic::write_atomic(path, self.to_ron().as_bytes())
    }
}

fn quote(s: &str) -> String {
    // Rust's debug escapes (\", \\, \n, \u{..}) are valid RON string escapes.
    format!("{s:?}")
}

fn float(v: f64) -> String {
    // `{:?}` is the shortest text that parses back to the same bits, and always has a '.' or 'e'.
    format!("{v:?}")
}

fn value_ron(v: &ParamValue) -> String {
    match v {
        ParamValue::Bool(b) => b.to_string(),
        ParamValue::Int(i) => i.to_string(),
        ParamValue::Float(f) => float(*f),
        ParamValue::Str(s) => quote(s),
        ParamValue::Vec(v) => format!("[{}]", v.iter().map(|x| float(*x)).collect::<Vec<_>>().join(", ")),
    }
}

//! Costs before they hurt: the GPU memory that nodes with large allocations will take,
//! estimated from the graph's parameters alone (nothing is evaluated), shown in the inspector.
//! A node past the adapter's limits, or past the editor's memory budget
//! (`WERKSTATT_EDITOR_BUDGET_MB`, 1024 by default), is refused before any work starts.
//!
//! - `Pems`: N regions (its `lights` from a `MedianCut`'s `count`) plus the filtered full map,
//!   each a cube of 6 faces x size² (the `EnvironmentMap`'s `size`) with its whole mip chain
//!   (x 4/3) in the HDR format, and the region ids (size x 6 size x 4 bytes).
//! - `ShadowAtlas`: N tiles of `tile_size`² on a near-square grid, in the moments format, its
//!   blur target and a depth buffer; at most `MAX_LIGHTS` lights and the adapter's 2D size.

use std::collections::BTreeMap;

use crate::core::graph::Graph;
use crate::gpu::GpuContext;
use crate::nodes::ibl::shadow_atlas::{MAX_LIGHTS, grid};

/// What a node is estimated to allocate.
#[derive(Clone, Debug, PartialEq)]
pub struct Estimate {
    pub bytes: u64,
    /// How the figure comes about, for the inspector.
    pub detail: String,
    /// A limit of the adapter or of the node itself that the parameters break.
    pub over_limit: Option<String>,
}

/// What the estimates are checked against.
#[derive(Clone, Debug, PartialEq)]
pub struct Limits {
    pub max_texture_2d: u32,
    /// Bytes per texel of the HDR format (cube maps): 8 for Rgba16Float, 16 for Rgba32Float.
    pub hdr_texel: u64,
    /// Bytes per texel of the shadow moments format.
    pub moments_texel: u64,
    pub budget: u64,
}

/// The memory budget when `WERKSTATT_EDITOR_BUDGET_MB` is not set.
pub const DEFAULT_BUDGET_MB: u64 = 1024;

impl Limits {
    /// WebGPU's default limits and formats, with the budget from the environment.
    pub fn from_env(max_texture_2d: Option<u32>) -> Limits {
        Limits {
            max_texture_2d: max_texture_2d.unwrap_or(wgpu::Limits::default().max_texture_dimension_2d),
            hdr_texel: 8,
            moments_texel: 4,
            budget: budget_from_env(),
        }
    }

    /// The device's limits and formats.
    pub fn for_gpu(gpu: &GpuContext) -> Limits {
        let texel = |f: wgpu::TextureFormat| f.block_copy_size(None).unwrap_or(8) as u64;
        Limits {
            max_texture_2d: gpu.limits.max_texture_dimension_2d,
            hdr_texel: texel(gpu.formats().hdr),
            moments_texel: texel(gpu.formats().moments),
            budget: budget_from_env(),
        }
    }
}

fn budget_from_env() -> u64 {
    let mb = std::env::var("WERKSTATT_EDITOR_BUDGET_MB").ok().and_then(|v| v.trim().parse::<u64>().ok());
    mb.unwrap_or(DEFAULT_BUDGET_MB).saturating_mul(1 << 20)
}

/// Bytes in mebibytes or gibibytes, for messages.
pub fn human(bytes: u64) -> String {
    let mib = bytes as f64 / (1u64 << 20) as f64;
    if mib >= 1024.0 { format!("{:.1} GiB", mib / 1024.0) } else { format!("{mib:.1} MiB") }
}

/// The integer parameter `name` of the node feeding `node`'s input `port`, if that node is of
/// kind `kind`; with the source's id.
fn source_int(graph: &Graph, node: &str, port: &str, kind: &str, name: &str) -> Option<(String, i64)> {
    let link = graph.links.iter().find(|l| l.to.node == node && l.to.port == port)?;
    let src = graph.nodes.get(&link.from.node)?;
    if src.kind != kind {
        return None;
    }
    let v = graph.param(&link.from.node, name)?.as_f64()?;
    Some((link.from.node.clone(), v as i64))
}

/// A cube map of `size`² faces with its whole mip chain.
fn cube_bytes(size: u64, texel: u64) -> u64 {
    let mips = 64 - size.max(1).leading_zeros() as u64;
    (0..mips).map(|m| (size >> m).max(1).pow(2) * 6 * texel).sum()
}

/// Estimates of the nodes of `graph` with large allocations, by node id.
pub fn estimate(graph: &Graph, limits: &Limits) -> BTreeMap<String, Estimate> {
    let mut out = BTreeMap::new();
    for (id, node) in &graph.nodes {
        match node.kind.as_str() {
            "Pems" => {
                let Some((cut, n)) = source_int(graph, id, "lights", "MedianCut", "count") else { continue };
                let Some((env, size)) = source_int(graph, id, "environment", "EnvironmentMap", "size") else {
                    continue;
                };
                let (n, size) = (n.max(1) as u64, size.max(1) as u64);
                let bytes = (n + 1) * cube_bytes(size, limits.hdr_texel) + size * 6 * size * 4;
                let detail = format!(
                    "{n} PEMs ({cut}.count) + the full map, each 6 faces x {size}² ({env}.size) x {} B with mips: {}",
                    limits.hdr_texel,
                    human(bytes)
                );
                out.insert(id.clone(), Estimate { bytes, detail, over_limit: None });
            }
            "ShadowAtlas" => {
                let Some((cut, n)) = source_int(graph, id, "lights", "MedianCut", "count") else { continue };
                let t = graph.param(id, "tile_size").and_then(|v| v.as_f64()).unwrap_or(128.0).max(1.0) as u64;
                let n = n.max(1) as usize;
                let (columns, rows) = grid(n);
                let (w, h) = (columns as u64 * t, rows as u64 * t);
                // Moments, their blur target, and depth (4 bytes).
                let bytes = w * h * (2 * limits.moments_texel + 4);
                let detail = format!("{n} tiles ({cut}.count) of {t}² in a {w}x{h} atlas: {}", human(bytes));
                let over_limit = if n > MAX_LIGHTS {
                    Some(format!("the atlas holds at most {MAX_LIGHTS} lights, {cut}.count asks for {n}"))
                } else if w.max(h) > limits.max_texture_2d as u64 {
                    Some(format!(
                        "a {w}x{h} atlas ({n} tiles of {t}) exceeds the adapter's {} texels",
                        limits.max_texture_2d
                    ))
                } else {
                    None
                };
                out.insert(id.clone(), Estimate { bytes, detail, over_limit });
            }
            _ => {}
        }
    }
    out
}

/// The nodes to refuse, with the reason: past a limit, or past the budget.
pub fn refusals(estimates: &BTreeMap<String, Estimate>, limits: &Limits) -> BTreeMap<String, String> {
    let mut out = BTreeMap::new();
    for (id, e) in estimates {
        let why = match &e.over_limit {
            Some(limit) => Some(limit.clone()),
            None if e.bytes > limits.budget => Some(format!(
                "{} need about {}, past the editor's memory budget of {} (WERKSTATT_EDITOR_BUDGET_MB)",
                e.detail.split(':').next().unwrap_or(&e.detail),
                human(e.bytes),
                human(limits.budget)
            )),
            None => None,
        };
        if let Some(why) = why {
            out.insert(id.clone(), format!("refused before any work: {why}"));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::core::param::ParamValue;

    fn default_graph() -> Graph {
        Graph::load(std::path::Path::new(concat!(env!("CARGO_MANIFEST_DIR"), "/graphs/still_life.ron"))).unwrap()
    }

    fn limits() -> Limits {
        Limits { max_texture_2d: 8192, hdr_texel: 8, moments_texel: 4, budget: DEFAULT_BUDGET_MB << 20 }
    }

    #[test]
    fn the_default_graph_is_estimated_and_2200_lights_refused() {
        let mut g = default_graph();
        let e = estimate(&g, &limits());
        // 23 cubes of 6 x (128² + 64² + ... + 1) texels of 8 bytes, and the 128 x 768 ids.
        let cube = 6 * (128 * 128 + 64 * 64 + 32 * 32 + 16 * 16 + 8 * 8 + 4 * 4 + 2 * 2 + 1) * 8;
        assert_eq!(e["pems"].bytes, 23 * cube + 128 * 768 * 4);
        assert!(e["pems"].detail.contains("22 PEMs (median_cut.count)"), "{}", e["pems"].detail);
        // 22 tiles of 64 (still_life.ron) on a 5 x 5 grid: 320², 12 bytes per texel.
        assert_eq!(e["shadow_atlas"].bytes, 320 * 320 * 12);
        assert!(refusals(&e, &limits()).is_empty(), "the still life fits");

        g.nodes.get_mut("median_cut").unwrap().params.insert("count".into(), ParamValue::Int(2200));
        let e = estimate(&g, &limits());
        assert!(e["pems"].bytes > 2 << 30, "2201 cubes of about 1 MiB: {}", human(e["pems"].bytes));
        let r = refusals(&e, &limits());
        assert!(r["pems"].contains("past the editor's memory budget of 1.0 GiB"), "{}", r["pems"]);
        assert!(r["shadow_atlas"].contains("at most 1024 lights"), "{}", r["shadow_atlas"]);

        // A smaller budget refuses what fits the default one; a small adapter refuses the atlas.
        let small = Limits { budget: 16 << 20, ..limits() };
        assert!(refusals(&estimate(&default_graph(), &small), &small).contains_key("pems"));
        g.nodes.get_mut("median_cut").unwrap().params.insert("count".into(), ParamValue::Int(1000));
        // 1000 tiles of 64 on a 32 x 32 grid: 2048².
        let tiny = Limits { max_texture_2d: 1024, ..limits() };
        let r = refusals(&estimate(&g, &tiny), &tiny);
        assert!(
            r["shadow_atlas"].contains("a 2048x2048 atlas (1000 tiles of 64) exceeds the adapter's 1024 texels"),
            "{}",
            r["shadow_atlas"]
        );
    }
}

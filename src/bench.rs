//! Benchmarks of the framework itself (`werkstatt bench ...`).

use std::time::Instant;

use crate::eval::{Evaluator, FrameSettings, FrameTime};
use crate::graph::{Graph, Link, NodeDoc, PortRef};
use crate::resources::Resources;
use crate::spec::ParamValue;

/// A chain of `n` Math nodes (each adds 1 to its predecessor) ending in a Watch node.
pub fn chain_graph(n: usize) -> Graph {
    let mut g = Graph::new();
    for i in 0..n {
        let mut params = std::collections::BTreeMap::new();
        params.insert("b".to_string(), ParamValue::Float(1.0));
        g.nodes.insert(format!("m{i:04}"), NodeDoc { kind: "Math".into(), pos: [i as f32 * 10.0, 0.0], params });
        if i > 0 {
            g.links.push(Link {
                from: PortRef { node: format!("m{:04}", i - 1), port: "result".into() },
                to: PortRef { node: format!("m{i:04}"), port: "a".into() },
            });
        }
    }
    g.nodes.insert("watch".into(), NodeDoc { kind: "Watch".into(), pos: [0.0, 100.0], params: Default::default() });
    g.links.push(Link {
        from: PortRef { node: format!("m{:04}", n.saturating_sub(1)), port: "result".into() },
        to: PortRef { node: "watch".into(), port: "value".into() },
    });
    g
}

pub struct IdleOverhead {
    pub median_us: f64,
    pub first_frame_us: f64,
    pub batches: usize,
    pub frames_per_batch: usize,
}

pub fn idle_overhead(nodes: usize, frames: usize) -> anyhow::Result<IdleOverhead> {
    let graph = chain_graph(nodes.max(1));
    let mut ev = Evaluator::new(&graph, &[]).map_err(anyhow::Error::msg)?;
    let resources = Resources::new(false);
    let settings = FrameSettings::default();
    let t = Instant::now();
    ev.evaluate(FrameTime { frame: 0, fps: 30.0 }, None, &resources, &settings);
    let first_frame_us = t.elapsed().as_secs_f64() * 1e6;
    let batches = 21;
    let per = (frames / batches).max(1);
    let mut samples = Vec::with_capacity(batches);
    for b in 0..batches {
        let t = Instant::now();
        for f in 0..per {
            // The time changes every frame; no node reads it, so nothing re-runs.
            let s = ev.evaluate(FrameTime { frame: (b * per + f + 1) as i64, fps: 30.0 }, None, &resources, &settings);
            debug_assert_eq!(s.ran, 0);
        }
        samples.push(t.elapsed().as_secs_f64() * 1e6 / per as f64);
    }
    samples.sort_by(f64::total_cmp);
    Ok(IdleOverhead { median_us: samples[batches / 2], first_frame_us, batches, frames_per_batch: per })
}

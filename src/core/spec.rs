//! The registry of node kinds: the one list (`nodes::ALL`) that the loader, the evaluator, the
//! command line, the editor palette and `docs/nodes.md` all read.

use crate::core::node::NodeSpec;

/// The registry: every node kind, in the order of `nodes::ALL`.
pub fn all() -> &'static [&'static NodeSpec] {
    crate::nodes::ALL
}

pub fn find(kind: &str) -> Option<&'static NodeSpec> {
    all().iter().copied().find(|s| s.kind == kind)
}

/// The closest known name to `wanted`, for "did you mean" hints.
pub fn closest<'a>(wanted: &str, candidates: impl IntoIterator<Item = &'a str>) -> Option<&'a str> {
    candidates
        .into_iter()
        .map(|c| (edit_distance(&wanted.to_lowercase(), &c.to_lowercase()), c))
        .filter(|(d, c)| *d <= (c.len().max(wanted.len()) / 3).max(2))
        .min_by_key(|(d, _)| *d)
        .map(|(_, c)| c)
}

fn edit_distance(a: &str, b: &str) -> usize {
    let b: Vec<char> = b.chars().collect();
    let mut row: Vec<usize> = (0..=b.len()).collect();
    for (i, ca) in a.chars().enumerate() {
        let mut prev = row[0];
        row[0] = i + 1;
        for (j, cb) in b.iter().enumerate() {
            let cur = row[j + 1];
            row[j + 1] = (prev + usize::from(ca != *cb)).min(row[j] + 1).min(cur + 1);
            prev = cur;
        }
    }
    row[b.len()]
}

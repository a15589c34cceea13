//! Change signals: version counters that data arriving from outside the graph bumps.

use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};

/// A version counter that something outside the graph (a network listener, a simulator
/// thread) bumps when it has new data for a node. A node that calls `EvalCx::watch` re-runs
/// when the counter changes, the way it re-runs when a file it loaded reloads; it need not
/// read the time (and re-run every frame) to notice. Cheap to clone (shared).
#[derive(Clone, Debug, Default)]
pub struct ChangeSignal(Arc<AtomicU64>);

impl ChangeSignal {
    pub fn new() -> Self {
        Self::default()
    }
    /// Marks a change: nodes watching this signal re-run on the next evaluated frame.
    pub fn bump(&self) {
        self.0.fetch_add(1, Ordering::AcqRel);
    }
    pub fn version(&self) -> u64 {
        self.0.load(Ordering::Acquire)
    }
}

//! Progress and cancellation of one evaluation, shared between the thread that evaluates and
//! the one that shows it (the editor's UI). Cloning shares the same token.
//!
//! The evaluator checks [`Progress::cancelled`] at every node boundary; long nodes report a
//! fraction through `EvalCx::progress`, which also answers a cancel inside their loops.

use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{Arc, Mutex};

#[derive(Default)]
struct Inner {
    cancelled: AtomicBool,
    /// The running node's fraction done, as `f32` bits.
    fraction: AtomicU32,
    node: Mutex<Option<Arc<str>>>,
}

/// A cancel flag, the node that runs and how far it is.
#[derive(Clone, Default)]
pub struct Progress(Arc<Inner>);

impl std::fmt::Debug for Progress {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Progress")
            .field("cancelled", &self.cancelled())
            .field("node", &self.node())
            .field("fraction", &self.fraction())
            .finish()
    }
}

impl Progress {
    pub fn new() -> Progress {
        Progress::default()
    }

    /// Asks the evaluation to stop at the next node boundary or progress report.
    pub fn cancel(&self) {
        self.0.cancelled.store(true, Ordering::Release);
    }

    pub fn cancelled(&self) -> bool {
        self.0.cancelled.load(Ordering::Acquire)
    }

    /// The evaluator starts node `id` (fraction 0).
    pub fn start_node(&self, id: &str) {
        *self.0.node.lock().unwrap_or_else(|p| p.into_inner()) = Some(Arc::from(id));
        self.set_fraction(0.0);
    }

    /// The running node's fraction done, clamped to 0..=1.
    pub fn set_fraction(&self, f: f32) {
        let f = if f.is_finite() { f.clamp(0.0, 1.0) } else { 0.0 };
        self.0.fraction.store(f.to_bits(), Ordering::Relaxed);
    }

    pub fn fraction(&self) -> f32 {
        f32::from_bits(self.0.fraction.load(Ordering::Relaxed))
    }

    /// The node that runs (or ran last).
    pub fn node(&self) -> Option<Arc<str>> {
        self.0.node.lock().unwrap_or_else(|p| p.into_inner()).clone()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clones_share_the_cancel_and_the_fraction() {
        let p = Progress::new();
        let seen = p.clone();
        assert!(!seen.cancelled());
        p.start_node("pems");
        p.set_fraction(0.25);
        assert_eq!((seen.node().as_deref(), seen.fraction()), (Some("pems"), 0.25));
        p.set_fraction(f32::NAN);
        assert_eq!(seen.fraction(), 0.0, "a fraction that is not a number reads as none done");
        p.set_fraction(7.0);
        assert_eq!(seen.fraction(), 1.0);
        p.cancel();
        assert!(seen.cancelled());
    }
}

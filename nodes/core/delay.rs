//! `Delay`: a deliberately slow node. It passes its image through after a wait, reporting
//! progress and answering a cancel, so a slow evaluation can be tried (and tested) on any
//! graph without a minute-long PEM build.

use std::sync::Arc;
use std::time::{Duration, Instant};

use crate::core::node::prelude::*;
use crate::gpu::GpuImage;

pub static DELAY: NodeSpec = NodeSpec {
    kind: "Delay",
    category: Category::Render,
    doc: "Passes the image through after waiting `seconds` of wall time, reporting progress and stopping when the evaluation is cancelled: a stand-in for a slow node (try the editor's progress, cancel and supersede on any graph).",
    inputs: &[PortSpec::required("image", PortType::Texture, "The image to pass through.")],
    outputs: &[PortSpec::output("image", PortType::Texture, "The same image.")],
    params: &[ParamSpec::new(
        "seconds",
        ParamKind::Float { default: 0.0, min: 0.0, max: 600.0 },
        "How long each run waits.",
    )],
    capabilities: Capabilities::NONE,
    create: || Box::new(DelayNode),
};

struct DelayNode;

/// How often the wait checks for a cancel.
const TICK: Duration = Duration::from_millis(5);

impl Node for DelayNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let image: Arc<GpuImage> = cx.input("image")?;
        let wait = Duration::from_secs_f64(cx.f64("seconds").clamp(0.0, 600.0));
        let start = Instant::now();
        // Progress in thousandths of the wait.
        while start.elapsed() < wait {
            cx.progress((start.elapsed().as_secs_f64() / wait.as_secs_f64() * 1000.0) as usize, 1000)?;
            std::thread::sleep(TICK.min(wait.saturating_sub(start.elapsed())));
        }
        cx.set("image", image);
        Ok(())
    }
}

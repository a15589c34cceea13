//! Scalars: constants, arithmetic, the frame time, and `Watch`, which reports a number
//! in `stats.json` so CI can check values, not just pictures.

use crate::core::node::prelude::*;

pub static NUMBER: NodeSpec = NodeSpec {
    kind: "Number",
    category: Category::Input,
    doc: "A constant scalar.",
    inputs: &[],
    outputs: &[PortSpec::output("value", PortType::Scalar, "The constant.")],
    params: &[ParamSpec::new("value", ParamKind::Float { default: 0.0, min: -1e12, max: 1e12 }, "The value.")],
    capabilities: Capabilities::NONE,
    create: || Box::new(NumberNode),
};

struct NumberNode;
impl Node for NumberNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let v = cx.f64("value");
        cx.set("value", v);
        Ok(())
    }
}

pub static MATH: NodeSpec = NodeSpec {
    kind: "Math",
    category: Category::Input,
    doc: "Combines two scalars; an unconnected input takes its parameter's value.",
    inputs: &[
        PortSpec::optional("a", PortType::Scalar, "First operand (else parameter a)."),
        PortSpec::optional("b", PortType::Scalar, "Second operand (else parameter b)."),
    ],
    outputs: &[PortSpec::output("result", PortType::Scalar, "op(a, b).")],
    params: &[
        ParamSpec::new(
            "op",
            ParamKind::Choice { default: "add", options: MathOp::OPTIONS },
            "The operation (sin uses a only: sin(a) * b).",
        ),
        ParamSpec::new(
            "a",
            ParamKind::Float { default: 0.0, min: -1e12, max: 1e12 },
            "a when the input is unconnected.",
        ),
        ParamSpec::new(
            "b",
            ParamKind::Float { default: 0.0, min: -1e12, max: 1e12 },
            "b when the input is unconnected.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(MathNode),
};

crate::choice!(
    enum MathOp {
        Add = "add",
        Subtract = "subtract",
        Multiply = "multiply",
        Divide = "divide",
        Min = "min",
        Max = "max",
        Power = "power",
        Sin = "sin",
    }
);

struct MathNode;
impl Node for MathNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let operand = |cx: &EvalCx<'_>, name: &str| cx.optional::<f64>(name).unwrap_or_else(|| cx.f64(name));
        let (a, b) = (operand(cx, "a"), operand(cx, "b"));
        let op: MathOp = cx.choice("op");
        let r = match op {
            MathOp::Add => a + b,
            MathOp::Subtract => a - b,
            MathOp::Multiply => a * b,
            MathOp::Divide if b == 0.0 => return Err(NodeError::msg("division by zero (input b is 0)")),
            MathOp::Divide => a / b,
            MathOp::Min => a.min(b),
            MathOp::Max => a.max(b),
            MathOp::Power => a.powf(b),
            MathOp::Sin => a.sin() * b,
        };
        if !r.is_finite() {
            return Err(NodeError::msg(format!("the result of {} on {a} and {b} is not finite", op.name())));
        }
        cx.set("result", r);
        Ok(())
    }
}

pub static TIME: NodeSpec = NodeSpec {
    kind: "Time",
    category: Category::Input,
    doc: "The current frame and time in seconds; nodes fed by it re-run every frame.",
    inputs: &[],
    outputs: &[
        PortSpec::output("seconds", PortType::Scalar, "frame / fps."),
        PortSpec::output("frame", PortType::Scalar, "The frame number."),
    ],
    params: &[],
    capabilities: Capabilities::NONE,
    create: || Box::new(TimeNode),
};

struct TimeNode;
impl Node for TimeNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let t = cx.time();
        cx.set("seconds", t.seconds());
        cx.set("frame", t.frame as f64);
        Ok(())
    }
}

pub static WATCH: NodeSpec = NodeSpec {
    kind: "Watch",
    category: Category::Output,
    doc: "Reports a scalar every frame (in stats.json under \"values\"), optionally failing the render when it leaves a range.",
    inputs: &[PortSpec::required("value", PortType::Scalar, "The value to report.")],
    outputs: &[PortSpec::output("value", PortType::Scalar, "The same value.")],
    params: &[
        ParamSpec::new("min", ParamKind::Float { default: -1e12, min: -1e12, max: 1e12 }, "Lowest accepted value."),
        ParamSpec::new("max", ParamKind::Float { default: 1e12, min: -1e12, max: 1e12 }, "Highest accepted value."),
    ],
    capabilities: Capabilities::OUTPUT,
    create: || Box::new(WatchNode),
};

struct WatchNode;
impl Node for WatchNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let v: f64 = cx.input("value")?;
        let (lo, hi) = (cx.f64("min"), cx.f64("max"));
        if v < lo || v > hi {
            return Err(NodeError::msg(format!("value {v} is outside the accepted range [{lo}, {hi}]")));
        }
        cx.emit(Product::Value(v));
        cx.set("value", v);
        Ok(())
    }
}

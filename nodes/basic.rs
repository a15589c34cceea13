//! Scalars: constants, arithmetic, the frame time, and `Watch`, which reports a number
//! in `stats.json` so CI can check values, not just pictures.

use crate::eval::{EvalCx, Node, NodeError};
use crate::spec::{Category, NodeSpec, ParamKind, ParamSpec, PortSpec, PortType};
use crate::value::Value;

pub static NUMBER: NodeSpec = NodeSpec {
    kind: "Number",
    category: Category::Input,
    doc: "A constant scalar.",
    inputs: &[],
    outputs: &[PortSpec::output("value", PortType::Scalar, "The constant.")],
    params: &[ParamSpec::new("value", ParamKind::Float { default: 0.0, min: -1e12, max: 1e12 }, "The value.")],
    is_output: false,
    create: || Box::new(NumberNode),
};

struct NumberNode;
impl Node for NumberNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let v = cx.f64("value");
        cx.set("value", Value::Scalar(v));
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
            ParamKind::Choice {
                default: "add",
                options: &["add", "subtract", "multiply", "divide", "min", "max", "power", "sin"],
            },
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
    is_output: false,
    create: || Box::new(MathNode),
};

struct MathNode;
impl Node for MathNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let operand = |cx: &EvalCx<'_>, name: &str| match cx.input(name) {
            Some(Value::Scalar(v)) => *v,
            _ => cx.f64(name),
        };
        let (a, b) = (operand(cx, "a"), operand(cx, "b"));
        let r = match cx.str("op") {
            "add" => a + b,
            "subtract" => a - b,
            "multiply" => a * b,
            "divide" if b == 0.0 => return Err(NodeError::msg("division by zero (input b is 0)")),
            "divide" => a / b,
            "min" => a.min(b),
            "max" => a.max(b),
            "power" => a.powf(b),
            _ => a.sin() * b,
        };
        if !r.is_finite() {
            return Err(NodeError::msg(format!("the result of {} on {a} and {b} is not finite", cx.str("op"))));
        }
        cx.set("result", Value::Scalar(r));
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
    is_output: false,
    create: || Box::new(TimeNode),
};

struct TimeNode;
impl Node for TimeNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let t = cx.time();
        cx.set("seconds", Value::Scalar(t.seconds()));
        cx.set("frame", Value::Scalar(t.frame as f64));
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
    is_output: true,
    create: || Box::new(WatchNode),
};

struct WatchNode;
impl Node for WatchNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        let Value::Scalar(v) = cx.required("value")? else { return Err(NodeError::msg("value is not a scalar")) };
        let v = *v;
        let (lo, hi) = (cx.f64("min"), cx.f64("max"));
        if v < lo || v > hi {
            return Err(NodeError::msg(format!("value {v} is outside the accepted range [{lo}, {hi}]")));
        }
        cx.set("value", Value::Scalar(v));
        Ok(())
    }
}

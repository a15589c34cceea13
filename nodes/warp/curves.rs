//! Curves in UV space from SVG files, for curve attachments (seams, embroidery).

use std::path::Path;
use std::sync::Arc;

use anyhow::Context as _;
use glam::Vec2;

use crate::core::node::prelude::*;
use crate::warp::Curves;

pub static SVG_CURVES: NodeSpec = NodeSpec {
    kind: "SvgCurves",
    category: Category::Attachment,
    doc: "Every path of an SVG file (with its transforms) as cubic Bezier curves in UV space: the document's width maps to 1 UV unit (aspect kept), then scale and offset apply. Lines and quadratics become exact cubics; zero-length segments are dropped.",
    inputs: &[],
    outputs: &[PortSpec::output("curves", PortType::Curves, "The curves.")],
    params: &[
        ParamSpec::new("path", ParamKind::Path { default: "", extensions: &["svg"] }, "The SVG file."),
        ParamSpec::new("scale", ParamKind::Float { default: 1.0, min: 1e-6, max: 1e6 }, "UV units per document width."),
        ParamSpec::new("offset", ParamKind::Vec3 { default: [0.0, 0.0, 0.0] }, "UV offset (x = u, y = v; z unused)."),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::new(SvgCurvesNode),
};

struct SvgCurvesNode;
impl Node for SvgCurvesNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        if cx.str("path").is_empty() {
            return Err(NodeError::msg("parameter \"path\" is empty: name an .svg file"));
        }
        let path = cx.path("path");
        let doc = cx.load(&path, load_svg)?;
        let (scale, offset) = (cx.f32("scale"), cx.vec3("offset").truncate());
        let paths = doc.paths.iter().map(|p| p.iter().map(|seg| seg.map(|q| q * scale + offset)).collect()).collect();
        cx.set("curves", Arc::new(Curves { paths }));
        Ok(())
    }
}

/// Reads every path of an SVG into cubic segments, normalized by the document width
/// (so the aspect ratio is kept).
pub fn load_svg(path: &Path) -> anyhow::Result<Curves> {
    let data = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let tree =
        usvg::Tree::from_data(&data, &usvg::Options::default()).map_err(|e| anyhow::anyhow!("invalid SVG: {e}"))?;
    let width = tree.size().width().max(1e-6);
    let mut curves = Curves::default();
    collect(tree.root(), width, &mut curves);
    if curves.paths.is_empty() {
        anyhow::bail!("the SVG contains no paths");
    }
    Ok(curves)
}

fn collect(group: &usvg::Group, width: f32, out: &mut Curves) {
    use usvg::tiny_skia_path::PathSegment;
    for node in group.children() {
        match node {
            usvg::Node::Group(g) => collect(g, width, out),
            usvg::Node::Path(p) => {
                let tf = p.abs_transform();
                let map = |pt: usvg::tiny_skia_path::Point| {
                    let mut q = [pt];
                    tf.map_points(&mut q);
                    Vec2::new(q[0].x, q[0].y) / width
                };
                let mut current: Vec<[Vec2; 4]> = Vec::new();
                let (mut start, mut last) = (Vec2::ZERO, Vec2::ZERO);
                for seg in p.data().segments() {
                    match seg {
                        PathSegment::MoveTo(a) => {
                            current.retain(|seg| seg.iter().any(|p| p.distance(seg[0]) > 1e-9));
                            if !current.is_empty() {
                                out.paths.push(std::mem::take(&mut current));
                            }
                            start = map(a);
                            last = start;
                        }
                        PathSegment::LineTo(a) => {
                            let b = map(a);
                            current.push([last, last.lerp(b, 1.0 / 3.0), last.lerp(b, 2.0 / 3.0), b]);
                            last = b;
                        }
                        PathSegment::QuadTo(c, a) => {
                            let (c, b) = (map(c), map(a));
                            current.push([last, last + (c - last) * (2.0 / 3.0), b + (c - b) * (2.0 / 3.0), b]);
                            last = b;
                        }
                        PathSegment::CubicTo(c1, c2, a) => {
                            let b = map(a);
                            current.push([last, map(c1), map(c2), b]);
                            last = b;
                        }
                        PathSegment::Close => {
                            if last.distance(start) > 1e-9 {
                                current.push([last, last.lerp(start, 1.0 / 3.0), last.lerp(start, 2.0 / 3.0), start]);
                            }
                            last = start;
                        }
                    }
                }
                current.retain(|seg| seg.iter().any(|p| p.distance(seg[0]) > 1e-9));
                if !current.is_empty() {
                    out.paths.push(current);
                }
            }
            _ => {}
        }
    }
}

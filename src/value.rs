//! Values carried along links. Heavy data is shared (`Arc`), so caching a node's outputs
//! and handing them to several consumers costs nothing.

use std::sync::Arc;

use glam::Vec3;

use crate::gpu::GpuImage;
use crate::mesh::Mesh;
use crate::scene::{Camera, DrawItem, GBuffer, Material};
use crate::spec::PortType;
use crate::warp::{Curves, MatrixTexture, Placement};

#[derive(Clone)]
pub enum Value {
    Scalar(f64),
    Vector(Vec3),
    Color(Vec3),
    /// Mesh and Surface ports.
    Mesh(Arc<Mesh>),
    Scene(Arc<Vec<DrawItem>>),
    Material(Arc<Material>),
    Camera(Camera),
    Texture(Arc<GpuImage>),
    GBuffer(Arc<GBuffer>),
    MatrixTexture(Arc<MatrixTexture>),
    Instances(Arc<Vec<Placement>>),
    Curves(Arc<Curves>),
}

impl Value {
    pub fn type_name(&self) -> &'static str {
        match self {
            Value::Scalar(_) => "Scalar",
            Value::Vector(_) => "Vector",
            Value::Color(_) => "Color",
            Value::Mesh(_) => "Mesh",
            Value::Scene(_) => "Scene",
            Value::Material(_) => "Material",
            Value::Camera(_) => "Camera",
            Value::Texture(_) => "Texture",
            Value::GBuffer(_) => "GBuffer",
            Value::MatrixTexture(_) => "MatrixTexture",
            Value::Instances(_) => "Instances",
            Value::Curves(_) => "Curves",
        }
    }

    pub fn matches(&self, ty: PortType) -> bool {
        matches!(
            (self, ty),
            (Value::Scalar(_), PortType::Scalar)
                | (Value::Vector(_), PortType::Vector)
                | (Value::Color(_), PortType::Color)
                | (Value::Mesh(_), PortType::Mesh | PortType::Surface)
                | (Value::Scene(_), PortType::Scene)
                | (Value::Material(_), PortType::Material)
                | (Value::Camera(_), PortType::Camera)
                | (Value::Texture(_), PortType::Texture)
                | (Value::GBuffer(_), PortType::GBuffer)
                | (Value::MatrixTexture(_), PortType::MatrixTexture)
                | (Value::Instances(_), PortType::Instances)
                | (Value::Curves(_), PortType::Curves)
        )
    }

    /// A one-line description for tooltips and logs.
    pub fn summary(&self) -> String {
        match self {
            Value::Scalar(v) => format!("{v}"),
            Value::Vector(v) | Value::Color(v) => format!("[{}, {}, {}]", v.x, v.y, v.z),
            Value::Mesh(m) => format!("{m:?}"),
            Value::Scene(s) => format!("{} draw items", s.len()),
            Value::Material(m) => format!("material {:?}", m.base_color.to_array()),
            Value::Camera(c) => format!("camera at {:?}", c.eye.to_array()),
            Value::Texture(t) => format!("{}x{} {:?}", t.width, t.height, t.format),
            Value::GBuffer(g) => format!("G-buffer {}x{}", g.width(), g.height()),
            Value::MatrixTexture(m) => format!("matrix texture {0}x{0}", m.resolution),
            Value::Instances(p) => format!("{} placements", p.len()),
            Value::Curves(c) => format!("{} paths, {} Bezier segments", c.paths.len(), c.segment_count()),
        }
    }

    /// The texture this value can be viewed as (for `--dump` and the editor's inspector).
    pub fn as_texture(&self) -> Option<&GpuImage> {
        match self {
            Value::Texture(t) => Some(t),
            Value::GBuffer(g) => Some(&g.color),
            Value::MatrixTexture(m) => Some(&m.col_n),
            _ => None,
        }
    }
}

//! Port types and the values that flow along links. `port_types!` below is the one table
//! that defines each type: its name, the Rust type its values carry, its colour in the editor
//! and whether it can be viewed as a texture. Adding a port type is one row there, plus
//! [`FromValue`]/[`IntoValue`] impls when its Rust type is new.
//!
//! Heavy data is shared (`Arc`), so caching a node's outputs and handing them to several
//! consumers costs nothing.

use std::fmt;
use std::sync::Arc;

use glam::Vec3;

use crate::avatar::Joints;
use crate::btf::gpu::GpuBtf;
use crate::cuboid::Transform as CuboidTransform;
use crate::gpu::GpuImage;
use crate::ibl::gpu::{EnvMap, Lights, PemSet};
use crate::ibl::shadow::ShadowAtlas;
use crate::mesh::Mesh;
use crate::render::scene::{Camera, DrawItem, GBuffer, Material};
use crate::warp::{Curves, MatrixTexture, Placement};

/// What the editor and `--dump` can show of a value: nothing, or one of its textures.
type ViewFn<T> = fn(&T) -> Option<&GpuImage>;

macro_rules! port_types {
    ($($(#[doc = $doc:literal])+ $ty:ident($rust:ty) { color: [$r:literal, $g:literal, $b:literal], view: $view:expr });+ $(;)?) => {
        /// The closed set of types that flow along links.
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
        pub enum PortType {
            $($(#[doc = $doc])+ $ty),+
        }

        /// A value on a link: one variant per port type.
        #[derive(Clone)]
        pub enum Value {
            $($(#[doc = $doc])+ $ty($rust)),+
        }

        impl PortType {
            /// Every port type, in declaration order.
            pub const ALL: &'static [PortType] = &[$(PortType::$ty),+];

            pub fn name(self) -> &'static str {
                match self { $(PortType::$ty => stringify!($ty)),+ }
            }

            /// The pin colour in the node editor (sRGB).
            pub fn color(self) -> [u8; 3] {
                match self { $(PortType::$ty => [$r, $g, $b]),+ }
            }

            /// Whether values of this type can be shown as a texture (editor viewport, `--dump`).
            pub fn viewable(self) -> bool {
                match self { $(PortType::$ty => { let view: Option<ViewFn<$rust>> = $view; view.is_some() }),+ }
            }
        }

        impl Value {
            pub fn port_type(&self) -> PortType {
                match self { $(Value::$ty(_) => PortType::$ty),+ }
            }

            /// The texture this value can be viewed as (for `--dump` and the editor's inspector).
            pub fn as_texture(&self) -> Option<&GpuImage> {
                match self {
                    $(Value::$ty(v) => { let view: Option<ViewFn<$rust>> = $view; view.and_then(|f| f(v)) }),+
                }
            }
        }
    };
}

port_types! {
    /// A number.
    Scalar(f64) { color: [160, 160, 160], view: None };
    /// A 3D vector.
    Vector(Vec3) { color: [110, 110, 220], view: None };
    /// A linear RGB colour.
    Color(Vec3) { color: [220, 200, 60], view: None };
    /// A triangle mesh (positions, normals, tangents, UVs, indices).
    Mesh(Arc<Mesh>) { color: [0, 190, 170], view: None };
    /// A mesh whose UVs are the garment's packed pattern coordinates (goes wherever a Mesh goes).
    Surface(Arc<Mesh>) { color: [60, 220, 120], view: None };
    /// Drawable items (meshes with materials and transforms) for a pass that draws the scene.
    Scene(Arc<Vec<DrawItem>>) { color: [230, 130, 40], view: None };
    /// Surface appearance: base colour, glossiness, texture and parameter maps.
    Material(Arc<Material>) { color: [210, 90, 160], view: None };
    /// A view of the scene.
    Camera(Camera) { color: [120, 180, 255], view: None };
    /// A 2D GPU texture (any format).
    Texture(Arc<GpuImage>) { color: [240, 90, 90], view: Some(|t| Some(&**t)) };
    /// The deferred renderer's targets; viewed as its colour target.
    GBuffer(Arc<GBuffer>) { color: [190, 70, 230], view: Some(|g| Some(&g.color)) };
    /// Detail placements on a surface (UV point, rotation, scale).
    Instances(Arc<Vec<Placement>>) { color: [150, 220, 60], view: None };
    /// Per-texel surface frames rendered in UV space (deferred warping, eq. 3); viewed as its normal column.
    MatrixTexture(Arc<MatrixTexture>) { color: [255, 140, 140], view: Some(|m| Some(&m.col_n)) };
    /// 2D Bezier curves (from SVG) for curve attachments.
    Curves(Arc<Curves>) { color: [100, 200, 230], view: None };
    /// A light probe as a cube map with mips; viewed as its equirectangular preview.
    Environment(Arc<EnvMap>) { color: [255, 200, 120], view: Some(|e| Some(&e.preview)) };
    /// Directional lights, one per median-cut region; viewed as the regions.
    Lights(Arc<Lights>) { color: [250, 240, 170], view: Some(|l| l.preview.as_ref()) };
    /// Filtered partial environment maps, one per region; viewed as the chosen preview.
    Pems(Arc<PemSet>) { color: [240, 160, 50], view: Some(|p| Some(&p.preview)) };
    /// Variance shadow maps of many lights in one atlas, with each light's matrices; viewed as the atlas.
    ShadowAtlas(Arc<ShadowAtlas>) { color: [120, 120, 200], view: Some(|s| Some(&s.atlas)) };
    /// A cuboid (trilinear) transform or grid of them over a bounding box; affine where linear.
    CuboidTransform(Arc<CuboidTransform>) { color: [200, 120, 255], view: None };
    /// A bidirectional texture function compressed per view (PCA) on the GPU.
    Btf(Arc<GpuBtf>) { color: [170, 110, 60], view: None };
    /// A skeleton's joints at rest, by bone name (the avatar's, for fitting sleeves).
    Joints(Arc<Joints>) { color: [235, 225, 200], view: None };
}

impl PortType {
    /// Whether a value of type `from` may feed an input of this type.
    /// A Surface is a Mesh with a pattern parametrization, so it can go wherever a Mesh goes.
    pub fn accepts(self, from: PortType) -> bool {
        self == from || (self == PortType::Mesh && from == PortType::Surface)
    }
}

impl fmt::Display for PortType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

impl Value {
    pub fn type_name(&self) -> &'static str {
        self.port_type().name()
    }

    /// A one-line description for tooltips and logs.
    pub fn summary(&self) -> String {
        match self {
            Value::Scalar(v) => format!("{v}"),
            Value::Vector(v) | Value::Color(v) => format!("[{}, {}, {}]", v.x, v.y, v.z),
            Value::Mesh(m) | Value::Surface(m) => format!("{m:?}"),
            Value::Scene(s) => format!("{} draw items", s.len()),
            Value::Material(m) => format!("material {:?}", m.base_color.to_array()),
            Value::Camera(c) => format!("camera at {:?}", c.eye.to_array()),
            Value::Texture(t) => format!("{}x{} {:?}", t.width, t.height, t.format),
            Value::GBuffer(g) => format!("G-buffer {}x{}", g.width(), g.height()),
            Value::MatrixTexture(m) => format!("matrix texture {0}x{0}", m.resolution),
            Value::Instances(p) => format!("{} placements", p.len()),
            Value::Curves(c) => format!("{} paths, {} Bezier segments", c.paths.len(), c.segment_count()),
            Value::Environment(e) => format!("environment {0}x{0} from {1}", e.size(), e.source.display()),
            Value::Lights(l) => format!("{} lights", l.lights.len()),
            Value::Pems(p) => format!("{} PEMs, {:.1} MiB", p.pems.len(), p.bytes as f64 / (1u64 << 20) as f64),
            Value::ShadowAtlas(s) => format!(
                "{} shadow tiles of {}, {}x{}, {:.1} MiB",
                s.lights.len(),
                s.tile_size,
                s.atlas.width,
                s.atlas.height,
                s.bytes as f64 / (1u64 << 20) as f64
            ),
            Value::Btf(b) => format!(
                "BTF {}x{}, {} directions, c = {}, {:.1} MiB",
                b.width,
                b.height,
                b.sampling.len(),
                b.components,
                b.bytes as f64 / (1u64 << 20) as f64
            ),
            Value::Joints(j) => format!("{} joints", j.names.len()),
            Value::CuboidTransform(t) => match &**t {
                CuboidTransform::Affine(_) => "affine cuboid (linear fast path)".into(),
                CuboidTransform::Grid(g) => format!("{g:?}"),
            },
        }
    }
}

/// A Rust type a node reads from an input port (`cx.input::<T>("name")`).
pub trait FromValue: Sized {
    /// The Rust type's name, for error messages.
    const NAME: &'static str;
    fn from_value(value: &Value) -> Option<Self>;
}

/// A Rust type a node writes to an output port; the port's declared type picks the variant
/// where one Rust type serves several port types (`Arc<Mesh>` for Mesh and Surface).
pub trait IntoValue {
    fn into_value(self, ty: PortType) -> Option<Value>;
}

impl IntoValue for Value {
    fn into_value(self, ty: PortType) -> Option<Value> {
        (self.port_type() == ty).then_some(self)
    }
}

/// `FromValue`/`IntoValue` for a Rust type carried by the listed variants.
macro_rules! typed {
    ($rust:ty: $($variant:ident),+) => {
        impl FromValue for $rust {
            const NAME: &'static str = stringify!($rust);
            fn from_value(value: &Value) -> Option<Self> {
                match value {
                    $(Value::$variant(v) => Some(v.clone()),)+
                    #[allow(unreachable_patterns)]
                    _ => None,
                }
            }
        }
        impl IntoValue for $rust {
            fn into_value(self, ty: PortType) -> Option<Value> {
                match ty {
                    $(PortType::$variant => Some(Value::$variant(self)),)+
                    #[allow(unreachable_patterns)]
                    _ => None,
                }
            }
        }
    };
}

typed!(f64: Scalar);
typed!(Vec3: Vector, Color);
typed!(Arc<Mesh>: Mesh, Surface);
typed!(Arc<Vec<DrawItem>>: Scene);
typed!(Arc<Material>: Material);
typed!(Camera: Camera);
typed!(Arc<GpuImage>: Texture);
typed!(Arc<GBuffer>: GBuffer);
typed!(Arc<Vec<Placement>>: Instances);
typed!(Arc<MatrixTexture>: MatrixTexture);
typed!(Arc<Curves>: Curves);
typed!(Arc<Joints>: Joints);
typed!(Arc<EnvMap>: Environment);
typed!(Arc<Lights>: Lights);
typed!(Arc<PemSet>: Pems);
typed!(Arc<ShadowAtlas>: ShadowAtlas);
typed!(Arc<CuboidTransform>: CuboidTransform);
typed!(Arc<GpuBtf>: Btf);

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_port_type_has_a_distinct_name_and_colour() {
        let names: std::collections::HashSet<_> = PortType::ALL.iter().map(|t| t.name()).collect();
        let colors: std::collections::HashSet<_> = PortType::ALL.iter().map(|t| t.color()).collect();
        assert_eq!(names.len(), PortType::ALL.len());
        assert_eq!(colors.len(), PortType::ALL.len());
    }

    #[test]
    fn viewable_types_are_those_with_textures() {
        let viewable: Vec<_> = PortType::ALL.iter().filter(|t| t.viewable()).map(|t| t.name()).collect();
        assert_eq!(viewable, ["Texture", "GBuffer", "MatrixTexture", "Environment", "Lights", "Pems", "ShadowAtlas"]);
    }

    #[test]
    fn typed_values_round_trip_through_their_port_types() {
        let v = Vec3::new(1.0, 2.0, 3.0).into_value(PortType::Color).unwrap();
        assert_eq!(v.port_type(), PortType::Color);
        assert_eq!(Vec3::from_value(&v), Some(Vec3::new(1.0, 2.0, 3.0)));
        assert!(2.0f64.into_value(PortType::Vector).is_none());
        assert!(f64::from_value(&v).is_none());
        assert!(PortType::Mesh.accepts(PortType::Surface) && !PortType::Surface.accepts(PortType::Mesh));
    }
}

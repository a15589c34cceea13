//! Node specifications: the one description of a node kind that the loader, the
//! evaluator, the command line, the editor palette and `docs/nodes.md` all read.

use std::fmt;

use crate::eval::Node;

/// The closed set of types that flow along links.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum PortType {
    Scalar,
    Vector,
    Color,
    /// A triangle mesh (positions, normals, tangents, UVs, indices).
    Mesh,
    /// A mesh whose UVs are the garment's packed pattern coordinates.
    Surface,
    /// Drawable items (meshes with materials and transforms) for a G-buffer pass.
    Scene,
    Material,
    Camera,
    /// A 2D GPU texture (any format).
    Texture,
    GBuffer,
    Lights,
    Instances,
    MatrixTexture,
    CubeMap,
    Pems,
    ShadowAtlas,
    Curves,
    CuboidTransform,
}

impl PortType {
    /// Whether a value of type `from` may feed an input of this type.
    /// A Surface is a Mesh with a pattern parametrization, so it can go wherever a Mesh goes.
    pub fn accepts(self, from: PortType) -> bool {
        self == from || (self == PortType::Mesh && from == PortType::Surface)
    }

    pub fn name(self) -> &'static str {
        match self {
            PortType::Scalar => "Scalar",
            PortType::Vector => "Vector",
            PortType::Color => "Color",
            PortType::Mesh => "Mesh",
            PortType::Surface => "Surface",
            PortType::Scene => "Scene",
            PortType::Material => "Material",
            PortType::Camera => "Camera",
            PortType::Texture => "Texture",
            PortType::GBuffer => "GBuffer",
            PortType::Lights => "Lights",
            PortType::Instances => "Instances",
            PortType::MatrixTexture => "MatrixTexture",
            PortType::CubeMap => "CubeMap",
            PortType::Pems => "Pems",
            PortType::ShadowAtlas => "ShadowAtlas",
            PortType::Curves => "Curves",
            PortType::CuboidTransform => "CuboidTransform",
        }
    }
}

impl fmt::Display for PortType {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(self.name())
    }
}

#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Category {
    Input,
    Geometry,
    Simulation,
    Attachment,
    Scene,
    Lighting,
    Render,
    Output,
}

impl Category {
    pub const ALL: [Category; 8] = [
        Category::Input,
        Category::Geometry,
        Category::Simulation,
        Category::Attachment,
        Category::Scene,
        Category::Lighting,
        Category::Render,
        Category::Output,
    ];
}

impl fmt::Display for Category {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        fmt::Debug::fmt(self, f)
    }
}

#[derive(Clone, Copy, Debug)]
pub struct PortSpec {
    pub name: &'static str,
    pub ty: PortType,
    pub required: bool,
    pub doc: &'static str,
}

impl PortSpec {
    pub const fn required(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        PortSpec { name, ty, required: true, doc }
    }
    pub const fn optional(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        PortSpec { name, ty, required: false, doc }
    }
    pub const fn output(name: &'static str, ty: PortType, doc: &'static str) -> Self {
        PortSpec { name, ty, required: false, doc }
    }
}

/// The type, default and valid range of a parameter.
#[derive(Clone, Copy, Debug)]
pub enum ParamKind {
    Float {
        default: f64,
        min: f64,
        max: f64,
    },
    Int {
        default: i64,
        min: i64,
        max: i64,
    },
    Bool {
        default: bool,
    },
    Vec3 {
        default: [f64; 3],
    },
    /// Linear RGB, each channel in [0, inf) (HDR colours are allowed).
    Color {
        default: [f64; 3],
    },
    Text {
        default: &'static str,
    },
    /// A file, relative to the graph file's folder.
    Path {
        default: &'static str,
        extensions: &'static [&'static str],
    },
    Choice {
        default: &'static str,
        options: &'static [&'static str],
    },
}

impl ParamKind {
    pub fn type_name(&self) -> &'static str {
        match self {
            ParamKind::Float { .. } => "float",
            ParamKind::Int { .. } => "integer",
            ParamKind::Bool { .. } => "bool",
            ParamKind::Vec3 { .. } => "vector [x, y, z]",
            ParamKind::Color { .. } => "colour [r, g, b]",
            ParamKind::Text { .. } => "string",
            ParamKind::Path { .. } => "path string",
            ParamKind::Choice { .. } => "choice string",
        }
    }

    pub fn default_value(&self) -> ParamValue {
        match *self {
            ParamKind::Float { default, .. } => ParamValue::Float(default),
            ParamKind::Int { default, .. } => ParamValue::Int(default),
            ParamKind::Bool { default } => ParamValue::Bool(default),
            ParamKind::Vec3 { default } | ParamKind::Color { default } => ParamValue::Vec(default.to_vec()),
            ParamKind::Text { default } | ParamKind::Path { default, .. } | ParamKind::Choice { default, .. } => {
                ParamValue::Str(default.to_string())
            }
        }
    }

    /// Checks a value against this kind, converting where the meaning is unambiguous
    /// (an integer literal for a float parameter). Returns the value in canonical form.
    pub fn check(&self, value: &ParamValue) -> Result<ParamValue, String> {
        let wrong = || format!("expected {}, found {}", self.type_name(), value.describe());
        match (self, value) {
            (ParamKind::Float { min, max, .. }, ParamValue::Float(_) | ParamValue::Int(_)) => {
                let v = value.as_f64().unwrap_or(f64::NAN);
                if !v.is_finite() {
                    return Err(format!("{v} is not a finite number"));
                }
                if v < *min || v > *max {
                    return Err(format!("{v} is out of range [{min}, {max}]"));
                }
                Ok(ParamValue::Float(v))
            }
            (ParamKind::Int { min, max, .. }, ParamValue::Int(v)) => {
                if v < min || v > max {
                    return Err(format!("{v} is out of range [{min}, {max}]"));
                }
                Ok(value.clone())
            }
            (ParamKind::Bool { .. }, ParamValue::Bool(_)) => Ok(value.clone()),
            (ParamKind::Vec3 { .. } | ParamKind::Color { .. }, ParamValue::Vec(v)) => {
                if v.len() != 3 {
                    return Err(format!("expected 3 components, found {}", v.len()));
                }
                if v.iter().any(|c| !c.is_finite()) {
                    return Err("components must be finite numbers".into());
                }
                if matches!(self, ParamKind::Color { .. }) && v.iter().any(|c| *c < 0.0) {
                    return Err("colour channels must not be negative".into());
                }
                Ok(value.clone())
            }
            (ParamKind::Text { .. } | ParamKind::Path { .. }, ParamValue::Str(_)) => Ok(value.clone()),
            (ParamKind::Choice { options, .. }, ParamValue::Str(s)) => {
                if options.contains(&s.as_str()) {
                    Ok(value.clone())
                } else {
                    Err(format!("\"{s}\" is not one of: {}", options.join(", ")))
                }
            }
            _ => Err(wrong()),
        }
    }

    /// Parses a command-line value (`--set node.param=value`) for this kind.
    pub fn parse_cli(&self, text: &str) -> Result<ParamValue, String> {
        let text = text.trim();
        let value = match self {
            ParamKind::Float { .. } => {
                ParamValue::Float(text.parse().map_err(|_| format!("\"{text}\" is not a number"))?)
            }
            ParamKind::Int { .. } => {
                ParamValue::Int(text.parse().map_err(|_| format!("\"{text}\" is not an integer"))?)
            }
            ParamKind::Bool { .. } => {
                ParamValue::Bool(text.parse().map_err(|_| format!("\"{text}\" is not true or false"))?)
            }
            ParamKind::Vec3 { .. } | ParamKind::Color { .. } => {
                let parts: Result<Vec<f64>, _> = text
                    .trim_matches(|c| c == '[' || c == ']' || c == '(' || c == ')')
                    .split(',')
                    .map(|p| p.trim().parse::<f64>())
                    .collect();
                ParamValue::Vec(parts.map_err(|_| format!("\"{text}\" is not a list of numbers like 1,0.5,0"))?)
            }
            ParamKind::Text { .. } | ParamKind::Path { .. } | ParamKind::Choice { .. } => {
                ParamValue::Str(text.to_string())
            }
        };
        self.check(&value)
    }
}

#[derive(Clone, Copy, Debug)]
pub struct ParamSpec {
    pub name: &'static str,
    pub kind: ParamKind,
    pub doc: &'static str,
}

impl ParamSpec {
    pub const fn new(name: &'static str, kind: ParamKind, doc: &'static str) -> Self {
        ParamSpec { name, kind, doc }
    }
}

/// A parameter value as stored in a graph file.
#[derive(Clone, Debug, PartialEq)]
pub enum ParamValue {
    Bool(bool),
    Int(i64),
    Float(f64),
    Str(String),
    Vec(Vec<f64>),
}

impl ParamValue {
    pub fn as_f64(&self) -> Option<f64> {
        match *self {
            ParamValue::Float(v) => Some(v),
            ParamValue::Int(v) => Some(v as f64),
            _ => None,
        }
    }

    pub fn describe(&self) -> String {
        match self {
            ParamValue::Bool(b) => format!("bool {b}"),
            ParamValue::Int(i) => format!("integer {i}"),
            ParamValue::Float(f) => format!("float {f}"),
            ParamValue::Str(s) => format!("string \"{s}\""),
            ParamValue::Vec(v) => format!("list of {} numbers", v.len()),
        }
    }

    /// Feeds the value into a hasher; floats by their bits so that -0.0 and 0.0 differ
    /// exactly when the file differs.
    pub fn hash_into(&self, h: &mut impl std::hash::Hasher) {
        use std::hash::Hash;
        match self {
            ParamValue::Bool(b) => (0u8, b).hash(h),
            ParamValue::Int(i) => (1u8, i).hash(h),
            ParamValue::Float(f) => (2u8, f.to_bits()).hash(h),
            ParamValue::Str(s) => (3u8, s).hash(h),
            ParamValue::Vec(v) => {
                4u8.hash(h);
                for c in v {
                    c.to_bits().hash(h);
                }
            }
        }
    }
}

/// Everything the framework knows about a node kind.
pub struct NodeSpec {
    pub kind: &'static str,
    pub category: Category,
    pub doc: &'static str,
    pub inputs: &'static [PortSpec],
    pub outputs: &'static [PortSpec],
    pub params: &'static [ParamSpec],
    /// Output nodes are the roots evaluation pulls from; `render` writes their images.
    pub is_output: bool,
    pub create: fn() -> Box<dyn Node>,
}

impl NodeSpec {
    pub fn input(&self, name: &str) -> Option<(usize, &PortSpec)> {
        self.inputs.iter().enumerate().find(|(_, p)| p.name == name)
    }
    pub fn output(&self, name: &str) -> Option<(usize, &PortSpec)> {
        self.outputs.iter().enumerate().find(|(_, p)| p.name == name)
    }
    pub fn param(&self, name: &str) -> Option<(usize, &ParamSpec)> {
        self.params.iter().enumerate().find(|(_, p)| p.name == name)
    }
}

impl fmt::Debug for NodeSpec {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("NodeSpec").field("kind", &self.kind).finish_non_exhaustive()
    }
}

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

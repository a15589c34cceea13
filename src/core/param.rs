//! Node parameters: their kinds (type, default, range), the values a graph file stores, and
//! choice parameters as Rust enums, so a node never compares option strings.

use std::fmt;

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
    /// A per-axis scale: a vector whose components are finite and not 0 (a transform with a zero
    /// scale is degenerate; a tiny one is not: millimetres to metres).
    Scale {
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
            ParamKind::Scale { .. } => "scale [x, y, z]",
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
            ParamKind::Vec3 { default } | ParamKind::Scale { default } | ParamKind::Color { default } => {
                ParamValue::Vec(default.to_vec())
            }
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
            (ParamKind::Vec3 { .. } | ParamKind::Scale { .. } | ParamKind::Color { .. }, ParamValue::Vec(v)) => {
                if v.len() != 3 {
                    return Err(format!("expected 3 components, found {}", v.len()));
                }
                if v.iter().any(|c| !c.is_finite()) {
                    return Err("components must be finite numbers".into());
                }
                if matches!(self, ParamKind::Color { .. }) && v.iter().any(|c| *c < 0.0) {
                    return Err("colour channels must not be negative".into());
                }
                if let (ParamKind::Scale { .. }, Some(why)) = (self, degenerate_scale([v[0], v[1], v[2]])) {
                    return Err(why);
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
            ParamKind::Vec3 { .. } | ParamKind::Scale { .. } | ParamKind::Color { .. } => {
                // In `--set`, unbracketed commas make a sweep, so a vector written 0,7.7,0 arrives
                // here one number at a time.
                if !text.contains(',') && text.trim().parse::<f64>().is_ok() {
                    return Err(format!(
                        "\"{text}\" is one number, not three: write a vector in brackets, [x,y,z] (in --set, a,b,c without brackets is a sweep of three values)"
                    ));
                }
                let parts: Result<Vec<f64>, _> = text
                    .trim_matches(|c| c == '[' || c == ']' || c == '(' || c == ')')
                    .split(',')
                    .map(|p| p.trim().parse::<f64>())
                    .collect();
                ParamValue::Vec(parts.map_err(|_| format!("\"{text}\" is not a list of numbers like [1,0.5,0]"))?)
            }
            ParamKind::Text { .. } | ParamKind::Path { .. } | ParamKind::Choice { .. } => {
                ParamValue::Str(text.to_string())
            }
        };
        self.check(&value)
    }
}

/// Why a per-axis scale makes a transform degenerate (a component that is 0 or not finite),
/// naming the scale; None where it is fine (a tiny one is: millimetres to metres). Checked for
/// every [`ParamKind::Scale`] value, and by the transform code alike.
pub fn degenerate_scale(scale: [f64; 3]) -> Option<String> {
    let [x, y, z] = scale;
    scale
        .iter()
        .any(|c| *c == 0.0 || !c.is_finite())
        .then(|| format!("the transform is degenerate: scale [{x}, {y}, {z}] has a component that is 0 or not finite"))
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

/// A choice parameter as a Rust enum. Declare it with [`choice!`](crate::choice); its option
/// strings are the spec's `ParamKind::Choice { options: T::OPTIONS, .. }`, so the names in the
/// graph file and the enum cannot drift apart.
pub trait Choice: Copy + fmt::Debug + 'static {
    const OPTIONS: &'static [&'static str];
    /// The variant at `OPTIONS[index]`; `None` past the end.
    fn from_index(index: usize) -> Option<Self>;
    fn name(self) -> &'static str;
}

/// Declares a choice enum: `choice!(pub enum Shape { Plane = "plane", Sphere = "sphere" });`
#[macro_export]
macro_rules! choice {
    ($(#[$meta:meta])* $vis:vis enum $name:ident { $($(#[$vmeta:meta])* $variant:ident = $text:literal),+ $(,)? }) => {
        $(#[$meta])*
        #[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
        $vis enum $name { $($(#[$vmeta])* $variant),+ }

        impl $crate::core::param::Choice for $name {
            const OPTIONS: &'static [&'static str] = &[$($text),+];
            fn from_index(index: usize) -> Option<Self> {
                const ALL: &[$name] = &[$($name::$variant),+];
                ALL.get(index).copied()
            }
            fn name(self) -> &'static str {
                match self { $($name::$variant => $text),+ }
            }
        }
    };
}

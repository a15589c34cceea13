//! USD mesh caches in, text (.usda) or binary (.usdc, .usd), read without a USD library: a
//! layer's prims and their attributes ([`Layer`], from [`crate::io::usda`] or
//! [`crate::io::usdc`]), and a Mesh prim at a time assembled from them ([`UsdFile::sample`]).
//!
//! One layer, no composition: references, payloads, sublayers, variants and instancing are
//! not followed. What is read: `def`/`over` prims at any depth; a Mesh's `points`,
//! `faceVertexCounts`, `faceVertexIndices`, `orientation`, normals (`primvars:normals`, else
//! `normals`) and UVs (`primvars:st`, else the first `texCoord2*[]` primvar), each per vertex,
//! per face corner or per face, plain or indexed (`:indices`); the transform ops
//! (`xformOpOrder`) of the mesh and every prim above it; the stage's `upAxis`,
//! `metersPerUnit`, `timeCodesPerSecond` and `startTimeCode`. An attribute's value at a time
//! is its time sample at or before it (the first sample before the first), else its default.
//! Output is Y up, metres, counter-clockwise faces.

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex};

use anyhow::{Context as _, bail};
use glam::{DMat4, DQuat, DVec3, Vec2};

use super::usda::{LazySpan, Val, val_value};
use super::usdc::Crate;
use super::{NONE, PolySample};

/// A decoded attribute value: numbers (scalars, vectors, matrices and their arrays, flattened;
/// quaternions as w, x, y, z) or tokens and strings.
#[derive(Debug, Clone, PartialEq)]
pub enum Value {
    Numbers(Vec<f64>),
    Tokens(Vec<String>),
}

/// A layer's prims, each value left as `H` until it is needed (parsed text, or where the value
/// lies in a binary file).
#[derive(Debug)]
pub struct Layer<H> {
    pub time_codes_per_second: f64,
    pub start: f64,
    pub end: f64,
    pub up_axis: String,
    pub meters_per_unit: f64,
    pub prims: Vec<Prim<H>>,
}

impl<H> Default for Layer<H> {
    fn default() -> Self {
        Layer {
            time_codes_per_second: 24.0,
            start: 0.0,
            end: 0.0,
            up_axis: "Y".into(),
            meters_per_unit: 1.0,
            prims: Vec::new(),
        }
    }
}

/// A prim: its path (`/root/Cloth/Grid`), type (`Mesh`, `Xform`, empty) and attributes.
#[derive(Debug)]
pub struct Prim<H> {
    pub path: String,
    pub type_name: String,
    pub attrs: HashMap<String, Attr<H>>,
}

/// An attribute: its type (`point3f[]`), `interpolation` metadata, default and time samples.
#[derive(Debug)]
pub struct Attr<H> {
    pub type_name: String,
    pub interpolation: Option<String>,
    pub default: Option<H>,
    pub samples: Vec<(f64, H)>,
}

impl<H> Default for Attr<H> {
    fn default() -> Self {
        Attr { type_name: String::new(), interpolation: None, default: None, samples: Vec::new() }
    }
}

impl<H> Attr<H> {
    /// The value held at time `t`: the sample at or before it, else the first, else the default.
    fn at(&self, t: f64) -> Option<&H> {
        let held = self.samples.iter().rev().find(|s| s.0 <= t).or(self.samples.first());
        held.map(|s| &s.1).or(self.default.as_ref())
    }
}

impl<H> Layer<H> {
    /// Puts the prims in path order (so text and binary files list meshes alike) and checks
    /// what the whole file shares, after parsing.
    pub fn finish(&mut self) -> anyhow::Result<()> {
        self.prims.sort_by(|a, b| a.path.cmp(&b.path));
        if !(self.time_codes_per_second.is_finite() && self.time_codes_per_second > 0.0) {
            bail!("timeCodesPerSecond {} is not a positive number", self.time_codes_per_second);
        }
        if !(self.meters_per_unit.is_finite() && self.meters_per_unit > 0.0) {
            bail!("metersPerUnit {} is not a positive number", self.meters_per_unit);
        }
        if !matches!(self.up_axis.as_str(), "Y" | "Z") {
            bail!("upAxis \"{}\" is neither Y nor Z", self.up_axis);
        }
        Ok(())
    }
}

/// An open USD file: a text layer parsed whole, or a binary one whose values are read when
/// asked for.
pub enum UsdFile {
    /// Long numeric arrays are [`Val::Lazy`]: read from the file when asked for.
    Text {
        path: PathBuf,
        layer: Arc<Layer<Val>>,
        lazy: Arc<Vec<LazySpan>>,
    },
    Binary {
        path: PathBuf,
        layer: Layer<u64>,
        file: Box<Crate>,
    },
}

/// Whether a path names a USD file by its extension.
pub fn is_usd(path: &Path) -> bool {
    path.extension()
        .and_then(|e| e.to_str())
        .is_some_and(|e| ["usd", "usda", "usdc"].contains(&e.to_ascii_lowercase().as_str()))
}

impl UsdFile {
    /// Opens a .usda, .usdc or .usd file (text or binary by its first bytes). Errors name the
    /// file.
    pub fn open(path: &Path) -> anyhow::Result<UsdFile> {
        let mut head = [0u8; 8];
        let n = {
            use std::io::Read;
            let mut f = std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
            f.read(&mut head).with_context(|| format!("cannot read {}", path.display()))?
        };
        let file = if head[..n].starts_with(b"PXR-USDC") {
            let (file, layer) = Crate::open(path)?;
            UsdFile::Binary { path: path.to_path_buf(), layer, file: Box::new(file) }
        } else {
            let (layer, lazy) = text_layer(path)?;
            UsdFile::Text { path: path.to_path_buf(), layer, lazy }
        };
        if file.mesh_names().is_empty() {
            bail!("{}: the stage holds no Mesh prim", path.display());
        }
        Ok(file)
    }

    pub fn path(&self) -> &Path {
        match self {
            UsdFile::Text { path, .. } | UsdFile::Binary { path, .. } => path,
        }
    }

    pub fn time_codes_per_second(&self) -> f64 {
        match self {
            UsdFile::Text { layer, .. } => layer.time_codes_per_second,
            UsdFile::Binary { layer, .. } => layer.time_codes_per_second,
        }
    }

    /// The paths of the Mesh prims, in path order.
    pub fn mesh_names(&self) -> Vec<String> {
        fn names<H>(layer: &Layer<H>) -> Vec<String> {
            layer.prims.iter().filter(|p| p.type_name == "Mesh").map(|p| p.path.clone()).collect()
        }
        match self {
            UsdFile::Text { layer, .. } => names(layer),
            UsdFile::Binary { layer, .. } => names(layer),
        }
    }

    /// The time codes at which Mesh `m` (an index into [`UsdFile::mesh_names`]) changes: its
    /// points' samples, its topology's and those of transforms above it that change. Sorted,
    /// distinct; the start time code when nothing is sampled.
    pub fn sample_times(&self, m: usize) -> anyhow::Result<Vec<f64>> {
        let times = match self {
            UsdFile::Text { layer, .. } => sample_times(layer, m),
            UsdFile::Binary { layer, .. } => sample_times(layer, m),
        };
        times.with_context(|| format!("{}: Mesh {}", self.path().display(), self.mesh_names()[m]))
    }

    /// Mesh `m` at time code `t`, in world space, Y up, metres. Errors name the file and prim.
    pub fn sample(&mut self, m: usize, t: f64) -> anyhow::Result<PolySample> {
        let name = self.mesh_names()[m].clone();
        let sample = match self {
            UsdFile::Text { path, layer, lazy } => {
                let mut decode = |v: &Val| match v {
                    Val::Lazy(k) => {
                        let span = *lazy.get(*k).with_context(|| format!("no array {k} in the file"))?;
                        val_value(&super::usda::read_lazy(path, span)?)
                    }
                    v => val_value(v),
                };
                sample_mesh(layer, &mut decode, m, t)
            }
            UsdFile::Binary { layer, file, .. } => sample_mesh(layer, &mut |rep: &u64| file.value(*rep), m, t),
        };
        sample.with_context(|| format!("{}: Mesh {name} at time {t}", self.path().display()))
    }
}

/// A text layer and its lazy arrays' spans.
type TextLayer = (Arc<Layer<Val>>, Arc<Vec<LazySpan>>);

/// The text layer of `path`: read once and kept while the file keeps its size and time (a
/// cache's frames load one at a time, each opening the file), so each frame reads only its
/// arrays.
fn text_layer(path: &Path) -> anyhow::Result<TextLayer> {
    /// A file as last seen: its path, modification time and size.
    type Seen = (PathBuf, std::time::SystemTime, u64);
    static LAST: Mutex<Option<(Seen, TextLayer)>> = Mutex::new(None);
    let meta = std::fs::metadata(path).with_context(|| format!("cannot read {}", path.display()))?;
    let key = (path.to_path_buf(), meta.modified().ok().unwrap_or(std::time::UNIX_EPOCH), meta.len());
    if let Some((k, layer)) = &*LAST.lock().unwrap_or_else(|e| e.into_inner())
        && *k == key
    {
        return Ok(layer.clone());
    }
    let (layer, lazy) = super::usda::read_usda_layer(path)?;
    let layer = (Arc::new(layer), Arc::new(lazy));
    *LAST.lock().unwrap_or_else(|e| e.into_inner()) = Some((key, layer.clone()));
    Ok(layer)
}

fn mesh_prim<H>(layer: &Layer<H>, m: usize) -> &Prim<H> {
    layer.prims.iter().filter(|p| p.type_name == "Mesh").nth(m).expect("a mesh index from mesh_names")
}

/// The prims from the root down to `prim` (itself included) in the layer.
fn chain<'a, H>(layer: &'a Layer<H>, prim: &Prim<H>) -> Vec<&'a Prim<H>> {
    let mut out: Vec<&Prim<H>> =
        layer.prims.iter().filter(|p| prim.path == p.path || prim.path.starts_with(&format!("{}/", p.path))).collect();
    out.sort_by_key(|p| p.path.len());
    out
}

fn sample_times<H>(layer: &Layer<H>, m: usize) -> anyhow::Result<Vec<f64>> {
    let prim = mesh_prim(layer, m);
    let mut times = Vec::new();
    for name in ["points", "faceVertexCounts", "faceVertexIndices"] {
        times.extend(prim.attrs.get(name).iter().flat_map(|a| a.samples.iter().map(|s| s.0)));
    }
    // Transforms count where they change (a constant one may have one sample anywhere).
    for p in chain(layer, prim) {
        for (name, a) in &p.attrs {
            if name.starts_with("xformOp:") && a.samples.len() > 1 {
                times.extend(a.samples.iter().map(|s| s.0));
            }
        }
    }
    if times.iter().any(|t| !t.is_finite()) {
        bail!("a time code is not a finite number");
    }
    times.sort_by(f64::total_cmp);
    times.dedup();
    if times.is_empty() {
        times.push(layer.start);
    }
    Ok(times)
}

type Decode<'a, H> = dyn FnMut(&H) -> anyhow::Result<Value> + 'a;

/// Attribute `name` of `prim` at `t`, decoded; None where the prim has no such value.
fn get<H>(prim: &Prim<H>, name: &str, t: f64, decode: &mut Decode<'_, H>) -> anyhow::Result<Option<Value>> {
    match prim.attrs.get(name).and_then(|a| a.at(t)) {
        Some(h) => decode(h).with_context(|| format!("attribute {name}")).map(Some),
        None => Ok(None),
    }
}

fn numbers(v: Value, name: &str, width: usize) -> anyhow::Result<Vec<f64>> {
    match v {
        Value::Numbers(n) if n.len() % width == 0 => Ok(n),
        Value::Numbers(n) => bail!("{name} holds {} numbers, not groups of {width}", n.len()),
        Value::Tokens(_) => bail!("{name} holds text, not numbers"),
    }
}

fn vec3s(v: Value, name: &str) -> anyhow::Result<Vec<DVec3>> {
    Ok(numbers(v, name, 3)?.chunks_exact(3).map(|c| DVec3::new(c[0], c[1], c[2])).collect())
}

fn indices(v: Value, name: &str) -> anyhow::Result<Vec<u32>> {
    numbers(v, name, 1)?
        .into_iter()
        .map(|x| (x.fract() == 0.0 && x >= 0.0 && x < NONE as f64).then_some(x as u32))
        .collect::<Option<_>>()
        .with_context(|| format!("{name} holds a value that is not a count or index"))
}

fn token(v: Option<Value>) -> Option<String> {
    match v {
        Some(Value::Tokens(t)) => t.into_iter().next(),
        _ => None,
    }
}

fn sample_mesh<H>(layer: &Layer<H>, decode: &mut Decode<'_, H>, m: usize, t: f64) -> anyhow::Result<PolySample> {
    let prim = mesh_prim(layer, m);
    let required = |v: Option<Value>, name: &str| v.with_context(|| format!("the mesh has no {name}"));
    let points = vec3s(required(get(prim, "points", t, decode)?, "points")?, "points")?;
    let counts = indices(required(get(prim, "faceVertexCounts", t, decode)?, "faceVertexCounts")?, "faceVertexCounts")?;
    let corners =
        indices(required(get(prim, "faceVertexIndices", t, decode)?, "faceVertexIndices")?, "faceVertexIndices")?;
    let total: u64 = counts.iter().map(|&c| c as u64).sum();
    if total != corners.len() as u64 {
        bail!("faceVertexCounts add up to {total} corners but there are {} faceVertexIndices", corners.len());
    }
    if let Some(bad) = corners.iter().find(|&&i| i as usize >= points.len()) {
        bail!("face vertex index {bad} is past the {} points", points.len());
    }
    let topology = Topology { counts: &counts, corners: &corners, points: points.len() };

    let uv_name = if prim.attrs.contains_key("primvars:st") {
        Some("primvars:st".to_string())
    } else {
        let mut names: Vec<&String> = prim
            .attrs
            .iter()
            .filter(|(n, a)| {
                n.starts_with("primvars:") && !n.ends_with(":indices") && a.type_name.starts_with("texCoord2")
            })
            .map(|(n, _)| n)
            .collect();
        names.sort();
        names.first().map(|n| n.to_string())
    };
    let uvs = match &uv_name {
        Some(name) => primvar(prim, name, t, decode, &topology, 2, true)?,
        None => None,
    };
    let has_uvs = uvs.is_some();
    let (uvs, uv_corner) = uvs.unwrap_or_default();
    let normal_name = if prim.attrs.contains_key("primvars:normals") { "primvars:normals" } else { "normals" };
    let (normals, normal_corner) = primvar(prim, normal_name, t, decode, &topology, 3, false)?.unwrap_or_default();

    let mut world = DMat4::IDENTITY;
    for p in chain(layer, prim) {
        let (local, reset) = local_transform(p, t, decode).with_context(|| format!("the transform of {}", p.path))?;
        world = if reset { local } else { world * local };
    }
    // To Y up, metres: Z up turns as Blender's exporters turn it, (x, y, z) to (x, z, -y).
    let mut stage = DMat4::from_scale(DVec3::splat(layer.meters_per_unit));
    if layer.up_axis == "Z" {
        stage =
            DMat4::from_cols_array(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0, -1.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
                * stage;
    }
    let world = stage * world;
    let normal_matrix = world.inverse().transpose();
    if !world.is_finite() || !normal_matrix.is_finite() {
        bail!("the transform is not invertible");
    }
    let positions = points.iter().map(|p| world.transform_point3(*p).as_vec3()).collect();
    let normals = normals
        .chunks_exact(3)
        .map(|n| normal_matrix.transform_vector3(DVec3::new(n[0], n[1], n[2])).normalize_or_zero().as_vec3())
        .collect();
    let uvs = uvs.chunks_exact(2).map(|c| Vec2::new(c[0] as f32, c[1] as f32)).collect();
    // A mirroring transform or a left-handed mesh turns the faces: keep them counter-clockwise.
    let left = token(get(prim, "orientation", t, decode)?).is_some_and(|o| o == "leftHanded");
    let reverse = left != (world.determinant() < 0.0);
    let mut out = Vec::with_capacity(corners.len());
    let mut start = 0usize;
    for &c in &counts {
        let face = start..start + c as usize;
        let at = |k: usize, per_corner: &[u32]| per_corner.get(k).copied().unwrap_or(NONE);
        let corner = |k: usize| [corners[k], at(k, &uv_corner), at(k, &normal_corner)];
        if reverse {
            out.extend(face.rev().map(corner));
        } else {
            out.extend(face.map(corner));
        }
        start += c as usize;
    }
    Ok(PolySample { positions, face_counts: counts, corners: out, uvs, has_uvs, normals })
}

struct Topology<'a> {
    counts: &'a [u32],
    corners: &'a [u32],
    points: usize,
}

/// A primvar's values (flat, `width` numbers each) and each face corner's value index, by its
/// interpolation (vertex and varying: per point; faceVarying: per corner; uniform: per face;
/// constant: one) and its `:indices`; `merge_equal` (2 numbers each): equal face-varying values
/// share an index. None where the mesh has no such primvar.
fn primvar<H>(
    prim: &Prim<H>,
    name: &str,
    t: f64,
    decode: &mut Decode<'_, H>,
    topo: &Topology<'_>,
    width: usize,
    merge_equal: bool,
) -> anyhow::Result<Option<(Vec<f64>, Vec<u32>)>> {
    let Some(v) = get(prim, name, t, decode)? else { return Ok(None) };
    let values = numbers(v, name, width)?;
    let count = values.len() / width;
    let index_name = format!("{name}:indices");
    let ix = get(prim, &index_name, t, decode)?.map(|v| indices(v, &index_name)).transpose()?;
    if let Some(bad) = ix.iter().flatten().find(|&&i| i as usize >= count) {
        bail!("{index_name} holds {bad}, past the {count} values of {name}");
    }
    let entries = ix.as_ref().map_or(count, Vec::len);
    let interpolation = prim.attrs.get(name).and_then(|a| a.interpolation.as_deref()).unwrap_or("vertex");
    let entry_of_corner: Vec<u32> = match interpolation {
        "vertex" | "varying" if entries == topo.points => topo.corners.to_vec(),
        "faceVarying" if entries == topo.corners.len() => (0..entries as u32).collect(),
        "uniform" if entries == topo.counts.len() => {
            topo.counts.iter().enumerate().flat_map(|(f, &c)| std::iter::repeat_n(f as u32, c as usize)).collect()
        }
        "constant" if entries == 1 => vec![0; topo.corners.len()],
        _ => bail!(
            "{name} is {interpolation} with {entries} entries, but the mesh has {} points, {} faces and {} face corners",
            topo.points,
            topo.counts.len(),
            topo.corners.len()
        ),
    };
    let per_corner = match ix {
        Some(ix) => entry_of_corner.iter().map(|&e| ix[e as usize]).collect(),
        // Un-indexed face-varying UVs (Blender's) repeat a value at every corner that shares
        // it: equal values get one index, so a UV seam, not every corner, splits a vertex (as
        // OBJ's shared `vt` and Alembic's indexed UVs do). Normals need not: they are averaged
        // per point.
        None if interpolation == "faceVarying" && merge_equal => {
            let mut first: HashMap<[u64; 2], u32> = HashMap::with_capacity(count);
            let key = |e: u32| std::array::from_fn(|k| values[e as usize * width + k].to_bits());
            entry_of_corner.iter().map(|&e| *first.entry(key(e)).or_insert(e)).collect()
        }
        None => entry_of_corner,
    };
    Ok(Some((values, per_corner)))
}

/// A prim's own transform from its `xformOpOrder` at `t` (the first op outermost), and whether
/// it resets the transforms above it (`!resetXformStack!`).
fn local_transform<H>(prim: &Prim<H>, t: f64, decode: &mut Decode<'_, H>) -> anyhow::Result<(DMat4, bool)> {
    let Some(order) = get(prim, "xformOpOrder", t, decode)? else { return Ok((DMat4::IDENTITY, false)) };
    let Value::Tokens(order) = order else { bail!("xformOpOrder is not a list of names") };
    let (mut m, mut reset) = (DMat4::IDENTITY, false);
    for op in &order {
        if op == "!resetXformStack!" {
            (m, reset) = (DMat4::IDENTITY, true);
            continue;
        }
        let (invert, name) = match op.strip_prefix("!invert!") {
            Some(n) => (true, n),
            None => (false, op.as_str()),
        };
        let kind = name.strip_prefix("xformOp:").and_then(|k| k.split(':').next()).unwrap_or("");
        let v =
            get(prim, name, t, decode)?.with_context(|| format!("xformOpOrder names {name}, which has no value"))?;
        let width = match kind {
            "transform" => 16,
            "orient" => 4,
            "rotateX" | "rotateY" | "rotateZ" => 1,
            _ => 3,
        };
        let v = numbers(v, name, width)?;
        if v.len() != width {
            bail!("{name} holds {} numbers, not {width}", v.len());
        }
        let v3 = || DVec3::new(v[0], v[1], v[2]);
        let axis = |c: char, degrees: f64| {
            let r = degrees.to_radians();
            match c {
                'X' => DMat4::from_rotation_x(r),
                'Y' => DMat4::from_rotation_y(r),
                _ => DMat4::from_rotation_z(r),
            }
        };
        let op_matrix = match kind {
            "translate" => DMat4::from_translation(v3()),
            "scale" => DMat4::from_scale(v3()),
            "rotateX" | "rotateY" | "rotateZ" => axis(kind.chars().last().unwrap_or('Z'), v[0]),
            "orient" => DMat4::from_quat(DQuat::from_xyzw(v[1], v[2], v[3], v[0]).normalize()),
            // Row-major with the translation in the last row (row vectors): as columns, the same.
            "transform" => DMat4::from_cols_slice(&v),
            k if k.len() == 9 && k.starts_with("rotate") => {
                // rotateXYZ turns about X first: the value's components are the X, Y, Z angles.
                let angle = |c: char| v[(c as u8 - b'X') as usize];
                let axes: Vec<char> = k[6..].chars().collect();
                if !axes.iter().all(|c| matches!(c, 'X' | 'Y' | 'Z')) {
                    bail!("unknown transform op {name}");
                }
                axes.iter().fold(DMat4::IDENTITY, |acc, &c| axis(c, angle(c)) * acc)
            }
            _ => bail!("unknown transform op {name}"),
        };
        m *= if invert { op_matrix.inverse() } else { op_matrix };
    }
    Ok((m, reset))
}

/// The frame numbers of time codes: the codes themselves where all are whole numbers (USD
/// time codes count frames), else multiples of the smallest gap. Returns the frame rate (the
/// time codes per second over the gap) and each code's frame.
pub fn frames_of(time_codes_per_second: f64, times: &[f64]) -> anyhow::Result<(f64, Vec<i64>)> {
    let whole = times.iter().all(|t| t.fract() == 0.0);
    let gap = if whole { 1.0 } else { times.windows(2).map(|w| w[1] - w[0]).fold(f64::INFINITY, f64::min) };
    let gap = if gap.is_finite() && gap > 0.0 { gap } else { 1.0 };
    let mut frames = Vec::with_capacity(times.len());
    for t in times {
        let n = (t / gap).round();
        if n.abs() > 1e15 {
            bail!("the time code {t} is too far from 0");
        }
        frames.push(n as i64);
    }
    Ok((time_codes_per_second / gap, frames))
}

//! Alembic (.abc, Ogawa) polygon-mesh caches, read with `ogawa-rs` 0.4: the object tree, time
//! samplings and the raw property data come from the crate; samples, transforms and mesh
//! assembly are read here.
//!
//! Every read opens the file anew and reads only what it needs (the structure, then one sample
//! of each property), so a long cache costs memory for one frame, not for all. ogawa-rs is
//! not `Send` (it holds `Rc`s), so an [`AbcArchive`] lives inside one loader call.
//!
//! Work-arounds for ogawa-rs 0.4, whose animated array properties read wrong samples:
//! - A header that says "every sample differs" leaves `first_changed_index` at 0; the
//!   Alembic library treats it as 1 ([`stored_index`]).
//! - An array property's samples are (data, dimensions) pairs, so sample `i` is group child
//!   `2i`, not `i` ([`read_sample`]).
//!
//! Robustness: ogawa-rs allocates buffers from sizes in the file and indexes without checks,
//! so before handing it the file, [`check_structure`] walks every group and checks that each
//! group and each chunk it will read lies inside the file; sample data is read and
//! bounds-checked here; a crash inside the crate is caught and reported with the file name.
//!
//! Conventions: Alembic is Y up, metres, with clockwise front faces, so each face's corners
//! are reversed here (Blender reverses them on export: its face `[0, 1, 22, 21]` is written
//! `[21, 22, 1, 0]`). Blender converts its Z-up scene to Y up on export ((x, y, z) becomes
//! (x, z, -y)), as its OBJ exporter does with forward -Z, up Y: the two agree as they are.

use std::collections::HashSet;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use glam::{DMat4, DVec3, Vec2, Vec3};

use super::{NONE, PolySample};
use ogawa_rs::{
    Archive, ArchiveReader, DataType, GroupChunk, ObjectReader, PodType, PropertyHeader, PropertyReader, TimeSampling,
};

/// An open archive and its polygon meshes (with the transforms above each).
pub struct AbcArchive {
    path: PathBuf,
    reader: FileBlocks,
    archive: Archive,
    pub meshes: Vec<AbcMesh>,
}

/// A PolyMesh object: its full name (`/Cloth/Grid`), its `.geom` properties and the Xforms
/// from the root down to it.
pub struct AbcMesh {
    pub name: String,
    /// A compound (ogawa-rs does not export the compound reader's type).
    geom: PropertyReader,
    xforms: Vec<Xform>,
}

/// An Xform's `.ops` and `.vals` (none: identity).
struct Xform {
    ops: Option<Property>,
    vals: Option<Property>,
}

/// An array or scalar property: its header and the group holding its samples.
struct Property {
    header: PropertyHeader,
    group: GroupChunk,
    array: bool,
}

/// The most objects (and the deepest nesting) a file may have; a corrupt file could claim a
/// loop of objects.
const MAX_OBJECTS: usize = 1 << 20;
const MAX_DEPTH: usize = 256;
/// The most samples a property may claim: the frames are listed from them.
const MAX_SAMPLES: u32 = 1_000_000;

impl AbcArchive {
    /// Opens `path` and lists its polygon meshes. Errors name the file.
    pub fn open(path: &Path) -> anyhow::Result<AbcArchive> {
        contain(|| Self::open_inner(path)).with_context(|| format!("cannot read the Alembic file {}", path.display()))
    }

    fn open_inner(path: &Path) -> anyhow::Result<AbcArchive> {
        let mut reader = FileBlocks::open(path)?;
        check_structure(&mut reader)?;
        // ogawa-rs reads the header from where the reader stands.
        reader.seek(SeekFrom::Start(0))?;
        let archive = Archive::new(&mut reader).map_err(ogawa)?;
        let root_group = root_group(&mut reader)?;
        let root_object = group_child(&mut reader, root_group, 2)?;
        check_object_group(&mut reader, root_object.context("the file has no root object")?)?;
        let root = archive.load_root_object(&mut reader).map_err(ogawa)?;
        let mut meshes = Vec::new();
        let mut path_groups = vec![root.group.position];
        collect_meshes(&archive, &mut reader, &root, &mut Vec::new(), &mut path_groups, &mut meshes, &mut 0)?;
        Ok(AbcArchive { path: path.to_path_buf(), reader, archive, meshes })
    }

    /// The times (seconds) at which mesh `m` changes: the samples of its positions, and of its
    /// topology and the transforms above it where those change. Sorted, distinct.
    pub fn sample_times(&mut self, m: usize) -> anyhow::Result<Vec<f64>> {
        let AbcArchive { path, reader, archive, meshes } = self;
        let mesh = &meshes[m];
        contain(|| {
            let mut props = Vec::new();
            for name in ["P", ".faceIndices", ".faceCounts"] {
                props.push(property(&mesh.geom, name, reader, archive)?.with_context(|| format!("no {name}"))?);
            }
            let mut times = Vec::new();
            let xforms = mesh.xforms.iter().filter_map(|x| x.vals.as_ref());
            for (k, p) in props.iter().chain(xforms).enumerate() {
                let n = p.header.next_sample_index;
                // A constant property's one sample may sit at time 0, before the animation.
                if k > 0 && (n < 2 || stored_index(&p.header, n - 1)? == 0) {
                    continue;
                }
                if n > MAX_SAMPLES {
                    bail!("property {} claims {n} samples", p.header.name);
                }
                let ts = time_sampling(&p.header)?;
                times.extend((0..n.max(1)).map(|k| sample_time(ts, k)));
            }
            if times.iter().any(|t| !t.is_finite()) {
                bail!("a sample time is not a finite number");
            }
            times.sort_by(f64::total_cmp);
            times.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
            Ok(times)
        })
        .with_context(|| format!("cannot read {} from the Alembic file {}", mesh.name, path.display()))
    }

    /// The frame rate of mesh `m`'s positions when they are sampled uniformly.
    pub fn uniform_rate(&mut self, m: usize) -> Option<f64> {
        let AbcArchive { reader, archive, meshes, .. } = self;
        let p = contain(|| property(&meshes[m].geom, "P", reader, archive)).ok()??;
        let ts = p.header.time_sampling.as_ref()?;
        (ts.sampling_type.num_samples_per_cycle == 1 && ts.sampling_type.time_per_cycle > 0.0)
            .then(|| 1.0 / ts.sampling_type.time_per_cycle)
    }

    /// Mesh `m` at time `t` (seconds): each property's sample at or before `t`.
    pub fn sample(&mut self, m: usize, t: f64) -> anyhow::Result<PolySample> {
        let name = self.meshes[m].name.clone();
        let AbcArchive { path, reader, archive, meshes } = self;
        contain(|| sample_mesh(reader, archive, &meshes[m], t))
            .with_context(|| format!("cannot read {name} at {t} s from the Alembic file {}", path.display()))
    }
}

fn sample_mesh(r: &mut FileBlocks, a: &Archive, mesh: &AbcMesh, t: f64) -> anyhow::Result<PolySample> {
    let mut required = |name: &str| -> anyhow::Result<Values> {
        let p = property(&mesh.geom, name, r, a)?.with_context(|| format!("the mesh has no {name}"))?;
        read_at(r, &p, t)
    };
    let positions = vec3s(&required("P")?, "P")?;
    let counts = required(".faceCounts")?.into_u32s(".faceCounts")?;
    let indices = required(".faceIndices")?.into_u32s(".faceIndices")?;
    let total: u64 = counts.iter().map(|&c| c as u64).sum();
    if total != indices.len() as u64 {
        bail!("the face counts add up to {total} corners but there are {} face indices", indices.len());
    }
    if let Some(bad) = indices.iter().find(|&&i| i as usize >= positions.len()) {
        bail!("face index {bad} is out of range ({} positions)", positions.len());
    }
    let uvs = geom_param(r, a, &mesh.geom, "uv", t, positions.len(), &indices, |v| {
        Ok(v.floats("uv", 2)?.chunks_exact(2).map(|c| Vec2::new(c[0] as f32, c[1] as f32)).collect())
    })?;
    let has_uvs = uvs.is_some();
    let (uvs, uv_corner) = uvs.unwrap_or_default();
    let normals = geom_param(r, a, &mesh.geom, "N", t, positions.len(), &indices, |v| vec3s(&v, "N"))?;
    let (normals, normal_corner) = normals.unwrap_or_default();

    let mut world = DMat4::IDENTITY;
    for xform in &mesh.xforms {
        let (Some(ops), Some(vals)) = (&xform.ops, &xform.vals) else { continue };
        let ops = ops_of(read_at(r, ops, t)?)?;
        world *= xform_matrix(&ops, &read_at(r, vals, t)?.floats(".vals", 1)?)?;
    }
    let (point_matrix, normal_matrix) = (world.as_mat4(), world.inverse().transpose().as_mat4());
    let positions = positions.iter().map(|p| point_matrix.transform_point3(*p)).collect();
    let normals = normals.iter().map(|n| normal_matrix.transform_vector3(*n).normalize_or_zero()).collect();
    // Reverse each face's corners: clockwise (Alembic) to counter-clockwise.
    let mut corners = Vec::with_capacity(indices.len());
    let mut start = 0usize;
    for &c in &counts {
        for k in (start..start + c as usize).rev() {
            let at = |per_corner: &[u32]| per_corner.get(k).copied().unwrap_or(NONE);
            corners.push([indices[k], at(&uv_corner), at(&normal_corner)]);
        }
        start += c as usize;
    }
    Ok(PolySample { positions, face_counts: counts, corners, uvs, has_uvs, normals })
}

/// A geometry parameter (`uv`, `N`): an array (per corner or per vertex) or a compound of
/// `.vals` and `.indices`. Returns the values and each corner's value index, if present.
#[allow(clippy::too_many_arguments)]
fn geom_param<T>(
    r: &mut FileBlocks,
    a: &Archive,
    geom: &PropertyReader,
    name: &str,
    t: f64,
    vertex_count: usize,
    face_indices: &[u32],
    convert: impl Fn(Values) -> anyhow::Result<Vec<T>>,
) -> anyhow::Result<Option<(Vec<T>, Vec<u32>)>> {
    let Some(param) = sub_property(geom, name, r, a)? else { return Ok(None) };
    let (values, indices) = match param {
        c @ PropertyReader::Compound(_) => {
            let vals = property(&c, ".vals", r, a)?.with_context(|| format!("{name} has no .vals"))?;
            let values = convert(read_at(r, &vals, t)?)?;
            let indices = match property(&c, ".indices", r, a)? {
                Some(p) => Some(read_at(r, &p, t)?.into_u32s(&format!("{name}/.indices"))?),
                None => None,
            };
            (values, indices)
        }
        PropertyReader::Array(p) => {
            let p = Property { header: p.header, group: p.group, array: true };
            (convert(read_at(r, &p, t)?)?, None)
        }
        PropertyReader::Scalar(_) => bail!("{name} is a scalar, not an array"),
    };
    let corners = face_indices.len();
    let count = indices.as_ref().map_or(values.len(), Vec::len);
    if let Some(bad) = indices.iter().flatten().find(|&&i| i as usize >= values.len()) {
        bail!("{name} index {bad} is out of range ({} values)", values.len());
    }
    let per_corner = match indices {
        // Face-varying (one per corner) or per vertex (through the face indices).
        Some(ix) if count == corners => ix,
        Some(ix) if count == vertex_count => face_indices.iter().map(|&v| ix[v as usize]).collect(),
        None if count == corners => (0..corners as u32).collect(),
        None if count == vertex_count => face_indices.to_vec(),
        _ => {
            bail!("{name} has {count} entries, neither one per corner ({corners}) nor one per vertex ({vertex_count})")
        }
    };
    Ok(Some((values, per_corner)))
}

/// The property `name` of a compound (none if `compound` is not one).
fn sub_property(
    compound: &PropertyReader,
    name: &str,
    r: &mut FileBlocks,
    a: &Archive,
) -> anyhow::Result<Option<PropertyReader>> {
    let PropertyReader::Compound(compound) = compound else { return Ok(None) };
    let Some(i) = compound.find_sub_property_index(name) else { return Ok(None) };
    // load_sub_property indexes the group's children by the header's position unchecked.
    if i >= compound.group.children.len() {
        bail!("property {name} has no data");
    }
    Ok(Some(compound.load_sub_property(i, r, a).map_err(ogawa)?))
}

/// The property `name` of a compound, if it is an array or a scalar.
fn property(
    compound: &PropertyReader,
    name: &str,
    r: &mut FileBlocks,
    a: &Archive,
) -> anyhow::Result<Option<Property>> {
    Ok(match sub_property(compound, name, r, a)? {
        Some(PropertyReader::Array(p)) => Some(Property { header: p.header, group: p.group, array: true }),
        Some(PropertyReader::Scalar(p)) => Some(Property { header: p.header, group: p.group, array: false }),
        _ => None,
    })
}

/// A property's sample at or before time `t`.
fn read_at(r: &mut FileBlocks, p: &Property, t: f64) -> anyhow::Result<Values> {
    let k = sample_at(time_sampling(&p.header)?, p.header.next_sample_index, t);
    read_sample(r, p, k).with_context(|| format!("property {}", p.header.name))
}

/// Runs `f`, turning a crash inside ogawa-rs into an error (the caller names the file).
fn contain<T>(f: impl FnOnce() -> anyhow::Result<T>) -> anyhow::Result<T> {
    std::panic::catch_unwind(std::panic::AssertUnwindSafe(f))
        .unwrap_or_else(|_| bail!("the Alembic reader failed on the file's structure (corrupt or unsupported)"))
}

fn ogawa(e: ogawa_rs::OgawaError) -> anyhow::Error {
    anyhow::Error::new(e).context("not a readable Alembic (Ogawa) file")
}

/// Walks the Ogawa objects from `object` down, collecting PolyMesh objects.
#[allow(clippy::too_many_arguments)]
fn collect_meshes(
    archive: &Archive,
    reader: &mut FileBlocks,
    object: &ObjectReader,
    xforms: &mut Vec<Xform>,
    path_groups: &mut Vec<u64>,
    meshes: &mut Vec<AbcMesh>,
    visited: &mut usize,
) -> anyhow::Result<()> {
    if path_groups.len() > MAX_DEPTH {
        bail!("objects are nested more than {MAX_DEPTH} deep");
    }
    for i in 0..object.children.len() {
        *visited += 1;
        if *visited > MAX_OBJECTS {
            bail!("more than {MAX_OBJECTS} objects");
        }
        // load_child reads group child i + 1 unchecked.
        let Some(&position) = object.group.children.get(i + 1) else {
            bail!("object {} lists more children than it holds", object.header.full_name);
        };
        if path_groups.contains(&position) {
            bail!("object {} contains itself", object.children[i].full_name);
        }
        check_object_group(reader, position)?;
        let child = object.load_child(i, reader, &archive.indexed_meta_data, &archive.time_samplings).map_err(ogawa)?;
        // The schema is named by the object or (Blender's Xforms) by its first property.
        let first_property = child.properties().and_then(|p| p.property_headers.first());
        let schema = [Some(&child.header.meta_data), first_property.map(|h| &h.meta_data)]
            .into_iter()
            .flatten()
            .find_map(|m| m.tokens.get("schema"))
            .map(String::as_str);
        let mut geom = || -> anyhow::Result<Option<PropertyReader>> {
            let Some(props) = child.properties() else { return Ok(None) };
            if props.sub_property_count() == 0 || props.group.children.is_empty() {
                return Ok(None);
            }
            Ok(match props.load_sub_property(0, reader, archive).map_err(ogawa)? {
                c @ PropertyReader::Compound(_) => Some(c),
                _ => None,
            })
        };
        let pushed = match schema {
            Some("AbcGeom_PolyMesh_v1") => {
                let geom =
                    geom()?.with_context(|| format!("the mesh {} has no .geom properties", child.header.full_name))?;
                let xforms = xforms.iter().map(Xform::clone_ref).collect();
                meshes.push(AbcMesh { name: child.header.full_name.clone(), geom, xforms });
                false
            }
            Some("AbcGeom_Xform_v3") => {
                let xform = match geom()? {
                    Some(g) => Xform {
                        ops: property(&g, ".ops", reader, archive)?,
                        vals: property(&g, ".vals", reader, archive)?,
                    },
                    None => Xform { ops: None, vals: None },
                };
                xforms.push(xform);
                true
            }
            _ => false,
        };
        path_groups.push(position);
        let result = collect_meshes(archive, reader, &child, xforms, path_groups, meshes, visited);
        path_groups.pop();
        if pushed {
            xforms.pop();
        }
        result?;
    }
    Ok(())
}

impl Xform {
    fn clone_ref(&self) -> Xform {
        let c = |p: &Option<Property>| {
            p.as_ref().map(|p| Property { header: p.header.clone(), group: p.group.clone(), array: p.array })
        };
        Xform { ops: c(&self.ops), vals: c(&self.vals) }
    }
}

/// The matrix of an Xform sample: its operations, outermost first (Alembic `XformSample`),
/// each reading its values in order: scale (3), translate (3), rotate (axis 3, degrees),
/// matrix (16, row-major with the translation last, as Imath), rotate X, Y, Z (degrees).
fn xform_matrix(ops: &[u8], vals: &[f64]) -> anyhow::Result<DMat4> {
    let mut m = DMat4::IDENTITY;
    let mut at = 0usize;
    for &op in ops {
        let n = match op >> 4 {
            0 | 1 => 3,
            2 => 4,
            3 => 16,
            4..=6 => 1,
            other => bail!("unknown transform operation {other}"),
        };
        let v = vals.get(at..at + n).context("the transform has fewer values than its operations need")?;
        at += n;
        m *= match op >> 4 {
            0 => DMat4::from_scale(DVec3::new(v[0], v[1], v[2])),
            1 => DMat4::from_translation(DVec3::new(v[0], v[1], v[2])),
            2 => DMat4::from_axis_angle(
                DVec3::new(v[0], v[1], v[2]).try_normalize().context("a rotation axis is zero")?,
                v[3].to_radians(),
            ),
            3 => DMat4::from_cols_array(v.try_into().expect("16 values")),
            4 => DMat4::from_rotation_x(v[0].to_radians()),
            5 => DMat4::from_rotation_y(v[0].to_radians()),
            _ => DMat4::from_rotation_z(v[0].to_radians()),
        };
    }
    if !m.is_finite() {
        bail!("the transform is not finite");
    }
    Ok(m)
}

fn ops_of(v: Values) -> anyhow::Result<Vec<u8>> {
    match v.pod {
        PodType::U8 => Ok(v.bytes),
        other => bail!(".ops holds {other:?}, not bytes"),
    }
}

/// A data type's element type, which ogawa-rs keeps private but names in its Debug output.
fn pod_type(data_type: &DataType) -> PodType {
    use PodType::*;
    let text = format!("{data_type:?}");
    [Boolean, U8, I8, U16, I16, U32, I32, U64, I64, F16, F32, F64, String, WString]
        .into_iter()
        .find(|p| text.contains(&format!("pod_type: {p:?},")))
        .unwrap_or(Unknown)
}

/// Raw sample data and its element type.
struct Values {
    pod: PodType,
    bytes: Vec<u8>,
}

impl Values {
    /// The values as numbers, whose count must be a multiple of `group`.
    fn floats(&self, name: &str, group: usize) -> anyhow::Result<Vec<f64>> {
        let v: Vec<f64> = match self.pod {
            PodType::F32 => {
                self.bytes.chunks_exact(4).map(|c| f32::from_le_bytes(c.try_into().unwrap()) as f64).collect()
            }
            PodType::F64 => self.bytes.chunks_exact(8).map(|c| f64::from_le_bytes(c.try_into().unwrap())).collect(),
            PodType::F16 => {
                self.bytes.chunks_exact(2).map(|c| half::f16::from_le_bytes(c.try_into().unwrap()).to_f64()).collect()
            }
            other => bail!("{name} holds {other:?}, not floating-point numbers"),
        };
        if !v.len().is_multiple_of(group) {
            bail!("{name} has {} numbers, not a multiple of {group}", v.len());
        }
        Ok(v)
    }

    fn into_u32s(self, name: &str) -> anyhow::Result<Vec<u32>> {
        let v: Vec<i64> = match self.pod {
            PodType::I32 => {
                self.bytes.chunks_exact(4).map(|c| i32::from_le_bytes(c.try_into().unwrap()) as i64).collect()
            }
            PodType::U32 => {
                self.bytes.chunks_exact(4).map(|c| u32::from_le_bytes(c.try_into().unwrap()) as i64).collect()
            }
            other => bail!("{name} holds {other:?}, not integers"),
        };
        v.into_iter()
            .map(|i| u32::try_from(i).ok().filter(|&i| i != NONE).with_context(|| format!("{name} holds {i}")))
            .collect()
    }
}

fn vec3s(v: &Values, name: &str) -> anyhow::Result<Vec<Vec3>> {
    let f = v.floats(name, 3)?;
    if f.iter().any(|x| !x.is_finite()) {
        bail!("{name} holds a number that is not finite");
    }
    Ok(f.chunks_exact(3).map(|c| Vec3::new(c[0] as f32, c[1] as f32, c[2] as f32)).collect())
}

fn time_sampling(header: &PropertyHeader) -> anyhow::Result<&TimeSampling> {
    let ts =
        header.time_sampling.as_deref().with_context(|| format!("property {} has no time sampling", header.name))?;
    if ts.samples.is_empty() || !ts.samples.iter().all(|t| t.is_finite()) {
        bail!("property {}: its time sampling has no valid start times", header.name);
    }
    let cyclic = ts.sampling_type.num_samples_per_cycle != u32::MAX;
    if cyclic && !(ts.sampling_type.time_per_cycle.is_finite() && ts.sampling_type.time_per_cycle > 0.0) {
        bail!("property {}: its time sampling has no valid cycle", header.name);
    }
    Ok(ts)
}

/// The time of sample `k`: uniform and cyclic samplings repeat their start times every
/// cycle; acyclic ones list every time (the last one holds after the list).
fn sample_time(ts: &TimeSampling, k: u32) -> f64 {
    let m = ts.samples.len() as u64;
    if ts.sampling_type.num_samples_per_cycle == u32::MAX {
        return ts.samples[(k as usize).min(ts.samples.len() - 1)];
    }
    let k = k as u64;
    ts.samples[(k % m) as usize] + (k / m) as f64 * ts.sampling_type.time_per_cycle
}

/// The last of `n` samples at or before time `t` (the first if all are later).
fn sample_at(ts: &TimeSampling, n: u32, t: f64) -> u32 {
    if n <= 1 {
        return 0;
    }
    let eps = 1e-9;
    // Sample times increase with k; find the last k with time(k) <= t by bisection.
    let (mut lo, mut hi) = (0u32, n - 1);
    if sample_time(ts, 0) > t + eps {
        return 0;
    }
    while lo < hi {
        let mid = lo + (hi - lo).div_ceil(2);
        if sample_time(ts, mid) <= t + eps {
            lo = mid;
        } else {
            hi = mid - 1;
        }
    }
    lo
}

/// Which stored sample holds sample `k` of a property that changed between samples
/// `first_changed_index` and `last_changed_index` (the Alembic library's rule), correcting
/// ogawa-rs's `first_changed_index` of 0 for "every sample differs".
fn stored_index(h: &PropertyHeader, k: u32) -> anyhow::Result<u64> {
    let (n, mut first, last) = (h.next_sample_index, h.first_changed_index, h.last_changed_index);
    if n > 1 && first == 0 && last == n - 1 {
        first = 1;
    }
    if first > last || (n > 0 && last >= n) {
        bail!("its sample range ({first}..{last} of {n}) is inconsistent");
    }
    Ok(if k < first || (first == 0 && last == 0) {
        0
    } else if k >= last {
        (last - first + 1) as u64
    } else {
        (k - first + 1) as u64
    })
}

/// Reads sample `k` of a property: for arrays group child 2i (data; 2i + 1 holds dimensions),
/// for scalars child i. The data starts with a 16-byte hash.
fn read_sample(reader: &mut FileBlocks, p: &Property, k: u32) -> anyhow::Result<Values> {
    let i = stored_index(&p.header, k)?;
    let child = if p.array { 2 * i } else { i };
    let entry = *usize::try_from(child)
        .ok()
        .and_then(|c| p.group.children.get(c))
        .with_context(|| format!("sample {k} is missing ({} entries)", p.group.children.len()))?;
    if entry & (1 << 63) == 0 {
        bail!("sample {k} is not data");
    }
    let position = entry & !(1 << 63);
    let size = if position == 0 { 0 } else { reader.u64_at(position)? };
    let element = match pod_type(&p.header.data_type) {
        PodType::U8 | PodType::I8 => 1,
        PodType::U16 | PodType::I16 | PodType::F16 => 2,
        PodType::U32 | PodType::I32 | PodType::F32 => 4,
        PodType::U64 | PodType::I64 | PodType::F64 => 8,
        other => bail!("its data type {other:?} is not read"),
    };
    if size == 0 {
        return Ok(Values { pod: pod_type(&p.header.data_type), bytes: Vec::new() });
    }
    let end = position.checked_add(8).and_then(|s| s.checked_add(size));
    if size < 16 || end.is_none_or(|e| e > reader.len) || !(size - 16).is_multiple_of(element) {
        bail!("sample {k} has a damaged size ({size} bytes at byte {position} of {})", reader.len);
    }
    let mut bytes = vec![0u8; (size - 16) as usize];
    reader.seek(SeekFrom::Start(position + 8 + 16))?;
    reader.read_exact(&mut bytes)?;
    Ok(Values { pod: pod_type(&p.header.data_type), bytes })
}

/// Checks the Ogawa structure before ogawa-rs reads it: the header, and every group reachable
/// from the root, whose children must lie inside the file; the data chunks ogawa-rs reads
/// whole (the root's and each group's last child, which holds its headers) must end inside
/// the file. Each group is visited once, so a group that contains itself ends the walk.
fn check_structure(r: &mut FileBlocks) -> anyhow::Result<()> {
    let mut header = [0u8; 16];
    if r.len < 16 {
        bail!("the file is {} bytes, too short for an Alembic file", r.len);
    }
    r.seek(SeekFrom::Start(0))?;
    r.read_exact(&mut header)?;
    if &header[..5] != b"Ogawa" {
        bail!("not an Alembic file in the Ogawa format (HDF5 Alembic files are not read)");
    }
    let root = u64::from_le_bytes(header[8..16].try_into().expect("8 bytes"));
    check_groups(r, root)?;
    check_time_samplings(r, root)
}

/// Checks the time samplings (the root's child 4; ogawa-rs allocates each one's list of start
/// times from a count in the file): every list must fit in the chunk.
fn check_time_samplings(r: &mut FileBlocks, root: u64) -> anyhow::Result<()> {
    if r.u64_at(root)? <= 5 {
        return Ok(()); // ogawa-rs rejects the file itself
    }
    let entry = r.u64_at(root + 8 + 4 * 8)?;
    let address = entry & !(1 << 63);
    if entry & (1 << 63) == 0 || address == 0 {
        return Ok(());
    }
    let size = r.u64_at(address)?;
    let mut at = 0u64;
    while at < size {
        // max sample (u32), time per cycle (f64), sample count (u32), that many f64 times.
        if at + 16 > size {
            bail!("the time samplings are cut short");
        }
        let count = u32::from_le_bytes(r.bytes_at(address + 8 + at + 12)?) as u64;
        at += 16 + 8 * count;
        if at > size {
            bail!("a time sampling claims {count} times, more than its data holds");
        }
    }
    Ok(())
}

/// The root group's position (from the file header).
fn root_group(r: &mut FileBlocks) -> anyhow::Result<u64> {
    r.u64_at(8)
}

/// Group child `k` of the group at `group` if it is a (non-empty) group.
fn group_child(r: &mut FileBlocks, group: u64, k: u64) -> anyhow::Result<Option<u64>> {
    if k >= r.u64_at(group)? {
        return Ok(None);
    }
    let c = r.u64_at(group + 8 + 8 * k)?;
    Ok((c & (1 << 63) == 0 && c != 0).then_some(c))
}

/// The bytes of the group's last child if it is data (the headers of an object or compound).
fn last_data(r: &mut FileBlocks, group: u64) -> anyhow::Result<Vec<u8>> {
    let count = r.u64_at(group)?;
    if count == 0 {
        return Ok(Vec::new());
    }
    let c = r.u64_at(group + 8 + 8 * (count - 1))?;
    let address = c & !(1 << 63);
    if c & (1 << 63) == 0 || address == 0 {
        return Ok(Vec::new());
    }
    let size = r.u64_at(address)?;
    // check_structure made sure it ends inside the file.
    let mut bytes = vec![0u8; size as usize];
    r.seek(SeekFrom::Start(address + 8))?;
    r.read_exact(&mut bytes)?;
    Ok(bytes)
}

/// Checks what ogawa-rs parses when it opens an object (and where it would crash instead of
/// failing): the names of its children (unique), and its property headers, nested compounds
/// included (counts and sizes inside their data; a sample count of 0 with changing samples).
fn check_object_group(r: &mut FileBlocks, group: u64) -> anyhow::Result<()> {
    let headers = last_data(r, group)?;
    if headers.len() > 32 {
        let mut names = HashSet::new();
        let mut b = Bytes { data: &headers[..headers.len() - 32], at: 0 };
        while b.at < b.data.len() {
            let size = b.uint(4)?;
            let name = b.take(size)?.to_vec();
            if b.uint(1)? == 0xff {
                let size = b.uint(4)?;
                b.take(size)?;
            }
            if !names.insert(name) {
                bail!("an object has two children of one name");
            }
        }
    }
    match group_child(r, group, 0)? {
        Some(properties) => check_compound_group(r, properties, 0),
        None => Ok(()),
    }
}

fn check_compound_group(r: &mut FileBlocks, group: u64, depth: usize) -> anyhow::Result<()> {
    if depth > MAX_DEPTH {
        bail!("properties are nested more than {MAX_DEPTH} deep");
    }
    let headers = last_data(r, group)?;
    let mut b = Bytes { data: &headers, at: 0 };
    let mut k = 0;
    while b.at < b.data.len() {
        let info = b.uint(4)? as u32;
        let width = match (info >> 2) & 3 {
            0 => 1,
            1 => 2,
            2 => 4,
            _ => bail!("a property header has an unknown size hint"),
        };
        let compound = info & 3 == 0;
        if !compound {
            let samples = b.uint(width)?;
            if info & 0x200 != 0 {
                b.uint(width)?;
                b.uint(width)?;
            } else if info & 0x800 == 0 && samples == 0 {
                bail!("a property claims changing samples but has none");
            }
            if info & 0x100 != 0 {
                b.uint(width)?;
            }
        }
        let name = b.uint(width)?;
        b.take(name)?;
        if (info >> 20) & 0xff == 0xff {
            let size = b.uint(width)?;
            if b.at < b.data.len() {
                b.take(size)?;
            }
        }
        if compound && let Some(child) = group_child(r, group, k)? {
            check_compound_group(r, child, depth + 1)?;
        }
        k += 1;
    }
    Ok(())
}

/// A cursor over header bytes that fails instead of reading past the end.
struct Bytes<'a> {
    data: &'a [u8],
    at: usize,
}

impl Bytes<'_> {
    fn take(&mut self, n: u64) -> anyhow::Result<&[u8]> {
        let end = usize::try_from(n).ok().and_then(|n| self.at.checked_add(n)).filter(|&e| e <= self.data.len());
        let end = end.context("a header runs past the end of its data")?;
        let bytes = &self.data[self.at..end];
        self.at = end;
        Ok(bytes)
    }

    /// A little-endian unsigned integer of `width` bytes.
    fn uint(&mut self, width: u64) -> anyhow::Result<u64> {
        Ok(self.take(width)?.iter().rev().fold(0u64, |v, &b| v << 8 | b as u64))
    }
}

/// See [`check_structure`].
fn check_groups(r: &mut FileBlocks, root: u64) -> anyhow::Result<()> {
    let mut stack = vec![(root, true)];
    let mut seen = HashSet::new();
    while let Some((group, is_root)) = stack.pop() {
        if group == 0 || !seen.insert(group) {
            continue;
        }
        let count = r.u64_at(group)?;
        let room = (r.len - group - 8) / 8;
        if count > room {
            bail!("a group at byte {group} claims {count} children, more than the file holds");
        }
        let mut children = vec![0u8; count as usize * 8];
        r.seek(SeekFrom::Start(group + 8))?;
        r.read_exact(&mut children)?;
        for (k, c) in children.chunks_exact(8).enumerate() {
            let c = u64::from_le_bytes(c.try_into().expect("8 bytes"));
            let address = c & !(1 << 63);
            if c & (1 << 63) == 0 {
                if address >= r.len {
                    bail!("a group at byte {group} points past the end of the file");
                }
                stack.push((address, false));
            } else if address != 0 && (is_root || k as u64 == count - 1) {
                let size = r.u64_at(address)?;
                if address.checked_add(8).and_then(|s| s.checked_add(size)).is_none_or(|e| e > r.len) {
                    bail!("data at byte {address} claims {size} bytes, past the end of the file ({} bytes)", r.len);
                }
            }
        }
    }
    Ok(())
}

/// A file read through a small block buffer: the structure is many small reads at scattered
/// places, the samples few large ones.
struct FileBlocks {
    file: File,
    len: u64,
    pos: u64,
    block: Vec<u8>,
    block_start: u64,
}

const BLOCK: usize = 4096;

impl FileBlocks {
    fn open(path: &Path) -> anyhow::Result<FileBlocks> {
        let file = File::open(path).with_context(|| format!("cannot open {}", path.display()))?;
        let len = file.metadata()?.len();
        Ok(FileBlocks { file, len, pos: 0, block: Vec::new(), block_start: 0 })
    }

    fn u64_at(&mut self, position: u64) -> anyhow::Result<u64> {
        Ok(u64::from_le_bytes(self.bytes_at(position)?))
    }

    fn bytes_at<const N: usize>(&mut self, position: u64) -> anyhow::Result<[u8; N]> {
        if position.checked_add(N as u64).is_none_or(|e| e > self.len) {
            bail!("byte {position} is past the end of the file ({} bytes)", self.len);
        }
        let mut b = [0u8; N];
        self.seek(SeekFrom::Start(position))?;
        self.read_exact(&mut b)?;
        Ok(b)
    }
}

impl Read for FileBlocks {
    fn read(&mut self, buf: &mut [u8]) -> std::io::Result<usize> {
        let in_block = self.pos >= self.block_start && self.pos < self.block_start + self.block.len() as u64;
        if !in_block {
            if buf.len() >= BLOCK {
                self.file.seek(SeekFrom::Start(self.pos))?;
                let n = self.file.read(buf)?;
                self.pos += n as u64;
                return Ok(n);
            }
            self.file.seek(SeekFrom::Start(self.pos))?;
            self.block.resize(BLOCK, 0);
            let mut filled = 0;
            while filled < BLOCK {
                match self.file.read(&mut self.block[filled..])? {
                    0 => break,
                    n => filled += n,
                }
            }
            self.block.truncate(filled);
            self.block_start = self.pos;
            if filled == 0 {
                return Ok(0);
            }
        }
        let offset = (self.pos - self.block_start) as usize;
        let n = buf.len().min(self.block.len() - offset);
        buf[..n].copy_from_slice(&self.block[offset..offset + n]);
        self.pos += n as u64;
        Ok(n)
    }
}

impl Seek for FileBlocks {
    fn seek(&mut self, to: SeekFrom) -> std::io::Result<u64> {
        let target = match to {
            SeekFrom::Start(p) => Some(p),
            SeekFrom::End(d) => self.len.checked_add_signed(d),
            SeekFrom::Current(d) => self.pos.checked_add_signed(d),
        };
        self.pos =
            target.ok_or_else(|| std::io::Error::new(std::io::ErrorKind::InvalidInput, "seek before the start"))?;
        Ok(self.pos)
    }
}

impl ArchiveReader for FileBlocks {
    fn size(&self) -> u64 {
        self.len
    }
}

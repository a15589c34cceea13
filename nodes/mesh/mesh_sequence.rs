//! Simulator input from files: an OBJ frame sequence (`frame_0001.obj`, ...) that another
//! simulator exported, a USD mesh cache (.usda, .usdc, .usd) or an Alembic cache (.abc), played
//! back against the frame time with linear interpolation.
//!
//! Every frame file loads through the lazy resource system on a worker thread; the node
//! holds the (at most two) files the current time needs, prefetches the next one and lets
//! the resource system forget the others, so memory stays bounded however long the
//! sequence is. All frames must share one topology (vertices, triangles, UVs, pieces); a
//! frame that does not is an error naming its file. The frames of an Alembic or binary USD
//! cache load one at a time like OBJ files (each a resource `cache.abc|frame=...`), reading
//! only that time's samples. A USD text cache (.usda) holds every frame in one text, so it is
//! parsed whole, once, and all its frames are held. A cache's topology may change from frame
//! to frame (frames of different topology are not blended).

use std::collections::HashMap;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use anyhow::{Context as _, bail};
use glam::{Vec2, Vec3};

use crate::core::hash::fnv1a;
use crate::core::node::prelude::*;
use crate::core::resources::{part_path, split_part};
use crate::io::alembic::AbcArchive;
use crate::io::usd::{self, UsdFile};
use crate::io::{NONE, PolySample};
use crate::mesh::{self, Mesh};

pub static MESH_SEQUENCE: NodeSpec = NodeSpec {
    kind: "MeshSequence",
    category: Category::Simulation,
    doc: "Plays an OBJ frame sequence (frame_0001.obj, ...), a USD mesh cache (.usda, .usdc or .usd; its time codes as frame numbers at its timeCodesPerSecond) or an Alembic cache (.abc, Ogawa; its sample times as frames) exported by a cloth simulator, with UVs as pattern coordinates and one pattern piece per OBJ object, USD Mesh prim or Alembic mesh; positions and normals are interpolated between frames. Frames load on worker threads; only the frames around the current time are held in memory.",
    inputs: &[],
    outputs: &[PortSpec::output(
        "surface",
        PortType::Surface,
        "The garment at the current time; UVs are the pattern coordinates (v down), piece ids from the OBJ objects.",
    )],
    params: &[
        ParamSpec::new(
            "path",
            ParamKind::Path { default: "", extensions: &["obj", "usda", "usdc", "usd", "abc"] },
            "A folder holding one sequence, a file pattern: frame_%04d.obj, frame_####.obj or frame_*.obj (the number in each file name is its frame), a USD cache (.usda, .usdc, .usd) of Mesh prims with UVs (primvars:st), or an Alembic .abc cache of polygon meshes with UVs; relative to the graph's folder.",
        ),
        ParamSpec::new(
            "object",
            ParamKind::Text { default: "" },
            "Alembic and USD caches: the mesh to play, by full path (/Cloth/Grid) or the name of it or of an object or prim above it (Cloth); empty: every polygon mesh in the file, each a pattern piece.",
        ),
        ParamSpec::new(
            "fps",
            ParamKind::Float { default: 24.0, min: 1e-3, max: 1e4 },
            "Frames per second of the sequence's numbering: file frame n is shown (n - start_frame) / fps seconds after time 0. A USD cache uses its own timeCodesPerSecond instead, an .abc cache its sample spacing.",
        ),
        ParamSpec::new(
            "start_frame",
            ParamKind::Int { default: -1, min: -1, max: 1_000_000_000 },
            "The sequence frame shown at time 0 (in mode hold: always); -1: the first file's number.",
        ),
        ParamSpec::new(
            "mode",
            ParamKind::Choice { default: "clamp", options: Mode::OPTIONS },
            "Outside the files' range: clamp shows the first or last file; loop repeats the sequence (blending the last file into the first over one file spacing); hold shows start_frame as a still and does not follow the time.",
        ),
        ParamSpec::new(
            "interpolate",
            ParamKind::Bool { default: true },
            "Blend positions (and normals, renormalized; tangents recomputed) linearly between the two files around the time; off: show the file at or before it.",
        ),
    ],
    capabilities: Capabilities::NONE,
    create: || Box::<MeshSequenceNode>::default(),
};

/// The frame files of one sequence, sorted by frame number.
#[derive(Debug)]
pub struct SequenceIndex {
    /// Frame numbers and files (for a cache: labels `cache.abc|frame=...`, see
    /// [`load_cache_frame`]).
    pub frames: Vec<(i64, PathBuf)>,
    /// A USD cache's frame rate (timeCodesPerSecond) or an .abc cache's sample rate, which
    /// replaces the node's `fps`.
    pub fps: Option<f64>,
    /// The frames come from one cache file (Alembic, USD), loaded with [`load_cache_frame`],
    /// and may differ in topology.
    pub cache: bool,
}

/// One loaded frame: the complete surface and its topology signature.
pub struct SeqFrame {
    pub mesh: Arc<Mesh>,
    pub topology: Topology,
}

/// What must stay the same across the frames of a sequence.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Topology {
    pub vertices: usize,
    pub triangles: usize,
    pub index_hash: u64,
    pub uv_hash: u64,
    pub piece_hash: u64,
}

impl Topology {
    fn of(mesh: &Mesh) -> Topology {
        Topology {
            vertices: mesh.positions.len(),
            triangles: mesh.triangle_count(),
            index_hash: fnv1a(bytemuck::cast_slice(&mesh.indices)),
            uv_hash: fnv1a(bytemuck::cast_slice(&mesh.uvs)),
            piece_hash: fnv1a(bytemuck::cast_slice(&mesh.piece_ids)),
        }
    }

    /// Why `self` (of `file`) differs from `reference`, or None.
    fn difference(&self, reference: &Topology) -> Option<String> {
        if self.vertices != reference.vertices {
            Some(format!("{} vertices instead of {}", self.vertices, reference.vertices))
        } else if self.triangles != reference.triangles {
            Some(format!("{} triangles instead of {}", self.triangles, reference.triangles))
        } else if self.index_hash != reference.index_hash {
            Some("the same counts but other triangles (the faces connect other vertices)".into())
        } else if self.uv_hash != reference.uv_hash {
            Some("the same triangles but other UVs".into())
        } else if self.piece_hash != reference.piece_hash {
            Some("the same triangles and UVs but other pattern pieces (OBJ objects)".into())
        } else {
            None
        }
    }
}

crate::choice!(
    /// How time maps to frames outside (and, for hold, inside) the files' range.
    pub enum Mode {
        Clamp = "clamp",
        Loop = "loop",
        Hold = "hold",
    }
);

/// The two files to blend at sequence frame `s` (fractional) and the weight of the second:
/// indices into `numbers` (sorted, distinct frame numbers of the files). Gaps in the
/// numbering are interpolated across. In loop mode the sequence repeats with period
/// `last - first + spacing`, where spacing is the gap between the last two files.
pub fn bracket(numbers: &[i64], s: f64, mode: Mode) -> (usize, usize, f64) {
    let n = numbers.len();
    assert!(n > 0, "a sequence has at least one file");
    let (first, last) = (numbers[0] as f64, numbers[n - 1] as f64);
    let s = if mode == Mode::Loop && n > 1 {
        let spacing = (numbers[n - 1] - numbers[n - 2]) as f64;
        let s = first + (s - first).rem_euclid(last - first + spacing);
        if s >= last {
            return (n - 1, 0, ((s - last) / spacing).clamp(0.0, 1.0));
        }
        s
    } else {
        s
    };
    if s <= first {
        return (0, 0, 0.0);
    }
    if s >= last {
        return (n - 1, n - 1, 0.0);
    }
    let i = numbers.partition_point(|&x| x as f64 <= s) - 1;
    let (a, b) = (numbers[i] as f64, numbers[i + 1] as f64);
    (i, i + 1, (s - a) / (b - a))
}

/// Positions and normals blended linearly (normals renormalized), tangents recomputed;
/// topology, UVs and pieces from `a` (equal in `b`).
pub fn blend(a: &Mesh, b: &Mesh, w: f32) -> Mesh {
    let mut m = a.clone();
    m.positions = a.positions.iter().zip(&b.positions).map(|(p, q)| p.lerp(*q, w)).collect();
    m.normals = a
        .normals
        .iter()
        .zip(&b.normals)
        .map(|(p, q)| p.lerp(*q, w).try_normalize().unwrap_or(if w < 0.5 { *p } else { *q }))
        .collect();
    let (tu, tv) = mesh::uv_tangents(&m.positions, &m.normals, &m.uvs, &m.indices);
    m.tangents_u = tu;
    m.tangents_v = tv;
    m
}

#[derive(Default)]
struct MeshSequenceNode {
    /// The sequence's first file and its topology, which every frame is checked against.
    reference: Option<(PathBuf, Topology)>,
    /// Frame files this node requested and has not released yet.
    held: Vec<PathBuf>,
    /// The last output, reused while its frames and weight stay.
    last: Option<LastOutput>,
}

/// An output surface and the two frames and weight it was made from.
type LastOutput = (Arc<SeqFrame>, Arc<SeqFrame>, f64, Arc<Mesh>);

impl Node for MeshSequenceNode {
    fn eval(&mut self, cx: &mut EvalCx<'_>) -> Result<(), NodeError> {
        if cx.str("path").is_empty() {
            return Err(NodeError::msg(
                "parameter \"path\" is empty: name a folder of OBJ frames or a pattern like frames/frame_%04d.obj",
            ));
        }
        let index = cx.load(&index_path(&cx.path("path"), cx.str("object")), load_index)?;
        let numbers: Vec<i64> = index.frames.iter().map(|(n, _)| *n).collect();
        let mode: Mode = cx.choice("mode");
        let start = match cx.int("start_frame") {
            -1 => numbers[0],
            s => s,
        };
        let s = if mode == Mode::Hold {
            start as f64
        } else {
            let t = cx.time();
            start as f64 + t.frame as f64 * index.fps.unwrap_or_else(|| cx.f64("fps")) / t.fps
        };
        let (mut a, mut b, mut w) = bracket(&numbers, s, mode);
        if !cx.bool("interpolate") || w < 1e-6 {
            (b, w) = (a, 0.0);
        } else if w > 1.0 - 1e-6 {
            (a, w) = (b, 0.0);
        }
        let first = index.frames[0].1.clone();
        if self.reference.as_ref().is_some_and(|(p, _)| *p != first) {
            self.reference = None;
            self.last = None;
        }
        // The file after the pair, to have it ready when the time gets there.
        let next = match mode {
            Mode::Hold => None,
            _ if b + 1 < numbers.len() => Some(b + 1),
            Mode::Loop => Some(0),
            Mode::Clamp => None,
        }
        .map(|i| index.frames[i].1.clone());
        let (pa, pb) = (index.frames[a].1.clone(), index.frames[b].1.clone());
        let (fa, mut fb) = match index.cache {
            true => self.load_pair(cx, None, [pa.as_path(), pb.as_path()], next, load_cache_frame)?,
            false => self.load_pair(cx, Some(&first), [pa.as_path(), pb.as_path()], next, load_frame)?,
        };
        if index.cache {
            // A cache whose topology changes shows each frame as it is, without blending.
            if fa.topology != fb.topology {
                (fb, w) = (fa.clone(), 0.0);
            }
        } else if let Some((ref_path, ref_topology)) = &self.reference {
            for (frame, path) in [(&fa, &pa), (&fb, &pb)] {
                if let Some(why) = frame.topology.difference(ref_topology) {
                    return Err(NodeError::msg(format!(
                        "{}: the topology differs from {}, the first file of the sequence: {why}. Every frame of a sequence needs the same vertices, triangles and UVs",
                        path.display(),
                        ref_path.display()
                    )));
                }
            }
        }
        let mesh = match &self.last {
            Some((la, lb, lw, m)) if Arc::ptr_eq(la, &fa) && Arc::ptr_eq(lb, &fb) && *lw == w => m.clone(),
            _ if w == 0.0 => fa.mesh.clone(),
            _ => Arc::new(blend(&fa.mesh, &fb.mesh, w as f32)),
        };
        self.last = Some((fa, fb, w, mesh.clone()));
        cx.set("surface", mesh);
        Ok(())
    }
}

impl MeshSequenceNode {
    /// Loads frames `pa` and `pb` with `loader` (and `first`, the reference topology, once)
    /// through the lazy resources, prefetches `next` and releases the frames no longer needed.
    fn load_pair(
        &mut self,
        cx: &mut EvalCx<'_>,
        first: Option<&Path>,
        [pa, pb]: [&Path; 2],
        next: Option<PathBuf>,
        loader: fn(&Path) -> anyhow::Result<SeqFrame>,
    ) -> Result<(Arc<SeqFrame>, Arc<SeqFrame>), NodeError> {
        let first = first.filter(|_| self.reference.is_none());
        let mut wanted = vec![pa.to_path_buf(), pb.to_path_buf()];
        wanted.extend(first.map(Path::to_path_buf));
        wanted.extend(next.clone());
        // Let go of what this time does not need before loading (bounded memory while scrubbing).
        self.held.retain(|p| wanted.contains(p) || !cx.release::<SeqFrame>(p));
        for p in &wanted {
            if !self.held.contains(p) {
                self.held.push(p.clone());
            }
        }
        if let Some(p) = &next {
            cx.prefetch(p, loader);
        }
        // Request all before waiting on any, so they load in parallel.
        let reference = first.map(|f| (f, cx.load(f, loader)));
        let (fa, fb) = (cx.load(pa, loader), cx.load(pb, loader));
        if let Some((f, r)) = reference {
            self.reference = Some((f.to_path_buf(), r?.topology.clone()));
        }
        Ok((fa?, fb?))
    }
}

/// Lists the frame files of a sequence: `path` is a folder (all its OBJ files whose names
/// end in a number, which must share one prefix) or a pattern whose file name holds
/// `%d`, `%0Nd`, a run of `#` or one `*` where the frame number goes.
pub fn load_index(path: &Path) -> anyhow::Result<SequenceIndex> {
    if let (file, Some(part)) = split_part(path) {
        let object = unescape(part.strip_prefix("object=").unwrap_or(part));
        return if usd::is_usd(file) { load_usd_index(file, &object) } else { load_abc_index(file, &object) };
    }
    let (dir, prefix, suffix) = if path.is_dir() {
        (path.to_path_buf(), None, None)
    } else {
        let name = path.file_name().and_then(|n| n.to_str()).context("the path has no file name")?;
        let (prefix, suffix) = split_pattern(name).with_context(|| {
            format!(
                "{} is neither a folder nor a pattern (use frame_%04d.obj, frame_####.obj or frame_*.obj)",
                path.display()
            )
        })?;
        (path.parent().map(Path::to_path_buf).unwrap_or_default(), Some(prefix), Some(suffix))
    };
    let entries = std::fs::read_dir(&dir).with_context(|| format!("cannot list the folder {}", dir.display()))?;
    let mut frames = Vec::new();
    let mut prefixes: Vec<String> = Vec::new();
    for entry in entries {
        let entry = entry?;
        let Some(name) = entry.file_name().to_str().map(str::to_string) else { continue };
        let number = match (&prefix, &suffix) {
            (Some(p), Some(s)) => name
                .strip_prefix(p.as_str())
                .and_then(|r| r.strip_suffix(s.as_str()))
                .filter(|d| !d.is_empty() && d.bytes().all(|b| b.is_ascii_digit())),
            _ => {
                let Some(stem) = name.strip_suffix(".obj").or_else(|| name.strip_suffix(".OBJ")) else { continue };
                let digits = stem.len() - stem.bytes().rev().take_while(u8::is_ascii_digit).count();
                if digits == stem.len() {
                    continue;
                }
                if !prefixes.iter().any(|p| p == &stem[..digits]) {
                    prefixes.push(stem[..digits].to_string());
                }
                Some(&stem[digits..])
            }
        };
        let Some(number) = number else { continue };
        let n: i64 = number.parse().with_context(|| format!("frame number {number} in {name} is too large"))?;
        frames.push((n, dir.join(&name)));
    }
    if prefixes.len() > 1 {
        prefixes.sort();
        bail!(
            "the folder {} holds more than one sequence ({}): name one with a pattern like {}%04d.obj",
            dir.display(),
            prefixes.iter().map(|p| format!("{p}####.obj")).collect::<Vec<_>>().join(", "),
            prefixes[0]
        );
    }
    if frames.is_empty() {
        bail!("no frame files found for {} (expected names like frame_0001.obj)", path.display());
    }
    frames.sort();
    if let Some(w) = frames.windows(2).find(|w| w[0].0 == w[1].0) {
        bail!("{} and {} have the same frame number {}", w[0].1.display(), w[1].1.display(), w[0].0);
    }
    Ok(SequenceIndex { frames, fps: None, cache: false })
}

/// A USD cache as a sequence: the time codes at which the chosen Mesh prims change, as frames
/// (see [`usd::frames_of`]).
fn load_usd_index(file: &Path, object: &str) -> anyhow::Result<SequenceIndex> {
    let mut stage = UsdFile::open(file)?;
    let meshes = select_meshes(&stage.mesh_names(), file, object)?;
    let mut times = Vec::new();
    for &m in &meshes {
        times.extend(stage.sample_times(m)?);
    }
    times.sort_by(f64::total_cmp);
    times.dedup();
    let (fps, numbers) =
        usd::frames_of(stage.time_codes_per_second(), &times).with_context(|| file.display().to_string())?;
    if let Some(w) = numbers.windows(2).find(|w| w[0] == w[1]) {
        bail!(
            "{}: two time codes fall on frame {}; their spacing is too uneven to number as frames",
            file.display(),
            w[0]
        );
    }
    // One frame read now, so a file that cannot be played (no UVs, say) fails here.
    if let Some(&first) = times.first() {
        usd_frame(&mut stage, &meshes, first)?;
    }
    let frames: Vec<(i64, PathBuf)> = numbers
        .iter()
        .zip(&times)
        .map(|(n, t)| (*n, part_path(file, &format!("frame={n},t={t},object={}", escape(object)))))
        .collect();
    Ok(SequenceIndex { frames, fps: Some(fps), cache: true })
}

/// The chosen Mesh prims of a USD file at time code `t`, each a pattern piece.
fn usd_frame(stage: &mut UsdFile, meshes: &[usize], t: f64) -> anyhow::Result<SeqFrame> {
    let names = stage.mesh_names();
    let mut samples = Vec::new();
    for &m in meshes {
        samples.push((names[m].clone(), stage.sample(m, t)?));
    }
    frame_of_samples(stage.path(), samples, &format!("time code {t}"))
}

/// Loads one frame of a cache file, named by a label of its index
/// (`file|frame=N,t=T,object=...`): an Alembic cache's meshes at T seconds, a USD cache's at
/// time code T.
pub fn load_cache_frame(label: &Path) -> anyhow::Result<SeqFrame> {
    let (file, Some(part)) = split_part(label) else { bail!("{} names no frame of a cache", label.display()) };
    let field = |key: &str| part.split(',').find_map(|f| f.strip_prefix(key));
    let t: f64 = field("t=").and_then(|t| t.parse().ok()).context("the frame label has no time")?;
    let object = unescape(field("object=").unwrap_or(""));
    if !usd::is_usd(file) {
        return abc_frame(file, t, &object);
    }
    let mut stage = UsdFile::open(file)?;
    let meshes = select_meshes(&stage.mesh_names(), file, &object)?;
    usd_frame(&mut stage, &meshes, t)
}

/// The resource that lists a sequence's frames: the path itself, or for an Alembic cache
/// the file and the `object` parameter.
pub fn index_path(path: &Path, object: &str) -> PathBuf {
    if path.extension().is_some_and(|e| e.eq_ignore_ascii_case("abc")) || usd::is_usd(path) {
        part_path(path, &format!("object={}", escape(object)))
    } else {
        path.to_path_buf()
    }
}

/// An Alembic cache as a sequence: the sample times of the chosen meshes, as frames at the
/// positions' uniform rate (or, for other samplings, the smallest spacing between samples).
fn load_abc_index(file: &Path, object: &str) -> anyhow::Result<SequenceIndex> {
    let mut archive = AbcArchive::open(file)?;
    let names: Vec<String> = archive.meshes.iter().map(|m| m.name.clone()).collect();
    let meshes = select_meshes(&names, file, object)?;
    let mut times = Vec::new();
    for &m in &meshes {
        times.extend(archive.sample_times(m)?);
    }
    times.sort_by(f64::total_cmp);
    times.dedup_by(|a, b| (*a - *b).abs() < 1e-9);
    let rates: Vec<Option<f64>> = meshes.iter().map(|&m| archive.uniform_rate(m)).collect();
    let on_grid = |rate: f64| times.iter().all(|t| (t * rate - (t * rate).round()).abs() < 1e-3);
    let fps = match rates[0] {
        Some(r) if rates.iter().all(|&q| q == Some(r)) && on_grid(r) => Some(r),
        _ => times.windows(2).map(|w| w[1] - w[0]).min_by(f64::total_cmp).map(|gap| 1.0 / gap),
    };
    let mut frames = Vec::new();
    for &t in &times {
        let n = fps.map_or(0.0, |fps| (t * fps).round());
        if n.abs() > 1e15 {
            bail!("{}: the sample time {t} s is too far from 0", file.display());
        }
        let part = format!("frame={n},t={t},object={}", escape(object));
        frames.push((n as i64, part_path(file, &part)));
    }
    Ok(SequenceIndex { frames, fps, cache: true })
}

/// The meshes `object` names (see the `object` parameter) among a file's `names`, in file
/// order.
fn select_meshes(names: &[String], file: &Path, object: &str) -> anyhow::Result<Vec<usize>> {
    if names.is_empty() {
        bail!("{}: holds no polygon mesh", file.display());
    }
    let chosen: Vec<usize> = (0..names.len())
        .filter(|&m| object.is_empty() || names[m] == object || names[m].split('/').any(|part| part == object))
        .collect();
    if chosen.is_empty() {
        bail!("{}: no mesh named \"{object}\" (its meshes: {})", file.display(), names.join(", "));
    }
    Ok(chosen)
}

/// One frame of an Alembic cache: every chosen mesh at `t` seconds, each a pattern piece.
fn abc_frame(file: &Path, t: f64, object: &str) -> anyhow::Result<SeqFrame> {
    let mut archive = AbcArchive::open(file)?;
    let names: Vec<String> = archive.meshes.iter().map(|m| m.name.clone()).collect();
    let mut samples = Vec::new();
    for m in select_meshes(&names, file, object)? {
        samples.push((names[m].clone(), archive.sample(m, t)?));
    }
    frame_of_samples(file, samples, &format!("{t} s"))
}

/// A frame of a cache from its meshes (name, sample), each a pattern piece; `at` says when,
/// for errors.
fn frame_of_samples(file: &Path, mut samples: Vec<(String, PolySample)>, at: &str) -> anyhow::Result<SeqFrame> {
    let cannot = || format!("cannot use {} at {at} as a sequence frame", file.display());
    // One mesh with its UVs (and normals) per vertex keeps its vertices as they are, in the
    // file's order: a cache written by ExportGeometry plays back vertex for vertex.
    if let [(_, s)] = samples.as_mut_slice() {
        let per_vertex = |k: usize, len: usize| s.corners.iter().all(|c| c[k] == c[0]) && len == s.positions.len();
        let no_normals = s.corners.iter().all(|c| c[2] == NONE);
        if s.has_uvs && per_vertex(1, s.uvs.len()) && (no_normals || per_vertex(2, s.normals.len())) {
            let mut indices = Vec::new();
            let mut start = 0;
            for &count in &s.face_counts {
                let face = &s.corners[start..start + count as usize];
                start += count as usize;
                indices
                    .extend((1..face.len().saturating_sub(1)).flat_map(|k| [face[0][0], face[k][0], face[k + 1][0]]));
            }
            let uvs = s.uvs.iter().map(|uv| Vec2::new(uv.x, 1.0 - uv.y)).collect();
            let normals = (!no_normals).then(|| std::mem::take(&mut s.normals));
            let mesh = Mesh::from_parts(std::mem::take(&mut s.positions), normals, uvs, indices, Vec::new())
                .with_context(cannot)?;
            return Ok(SeqFrame { topology: Topology::of(&mesh), mesh: Arc::new(mesh) });
        }
    }
    let (mut v, mut vt, mut vn) = (Vec::new(), Vec::new(), Vec::new());
    let (mut corners, mut tri_piece) = (Vec::new(), Vec::new());
    let pieces = samples.len();
    for (piece, (name, sample)) in samples.into_iter().enumerate() {
        if !sample.has_uvs {
            bail!("{}: the mesh {name} has no UVs, which a Surface needs as pattern coordinates", file.display());
        }
        let offset = |i: u32, base: usize| if i == NONE { NONE } else { i + base as u32 };
        let mut start = 0;
        for &count in &sample.face_counts {
            let face = &sample.corners[start..start + count as usize];
            start += count as usize;
            for k in 1..face.len().saturating_sub(1) {
                for c in [face[0], face[k], face[k + 1]] {
                    corners.push([offset(c[0], v.len()), offset(c[1], vt.len()), offset(c[2], vn.len())]);
                }
                tri_piece.push(piece as u32);
            }
        }
        v.extend(sample.positions);
        // Caches store v up; the Surface's runs down.
        vt.extend(sample.uvs.iter().map(|uv| Vec2::new(uv.x, 1.0 - uv.y)));
        vn.extend(sample.normals);
    }
    let mesh = mesh_from_corners(&v, &vt, &vn, &corners, &tri_piece, pieces).with_context(cannot)?;
    Ok(SeqFrame { topology: Topology::of(&mesh), mesh: Arc::new(mesh) })
}

/// An object name made safe for a resource label: bytes other than letters, digits and
/// `_.-:` as `%XX`.
fn escape(name: &str) -> String {
    let mut out = String::new();
    for b in name.bytes() {
        if b.is_ascii_alphanumeric() || b"_.-:".contains(&b) {
            out.push(b as char);
        } else {
            out.push_str(&format!("%{b:02X}"));
        }
    }
    out
}

fn unescape(text: &str) -> String {
    let mut bytes = Vec::new();
    let mut rest = text.as_bytes();
    while let Some((&b, tail)) = rest.split_first() {
        let hex = tail.get(..2).and_then(|h| std::str::from_utf8(h).ok()).and_then(|h| u8::from_str_radix(h, 16).ok());
        match (b, hex) {
            (b'%', Some(h)) => {
                bytes.push(h);
                rest = &tail[2..];
            }
            _ => {
                bytes.push(b);
                rest = tail;
            }
        }
    }
    String::from_utf8_lossy(&bytes).into_owned()
}

/// The text before and after the frame-number placeholder of a file-name pattern.
fn split_pattern(name: &str) -> Option<(String, String)> {
    if let Some(i) = name.find('%') {
        let rest = &name[i + 1..];
        let d = rest.find('d')?;
        if !rest[..d].bytes().all(|b| b.is_ascii_digit()) {
            return None;
        }
        return Some((name[..i].to_string(), rest[d + 1..].to_string()));
    }
    if let Some(i) = name.find('#') {
        let end = i + name[i..].bytes().take_while(|&b| b == b'#').count();
        return Some((name[..i].to_string(), name[end..].to_string()));
    }
    let i = name.find('*')?;
    Some((name[..i].to_string(), name[i + 1..].to_string()))
}

/// Loads one frame file (see [`parse_obj`]).
pub fn load_frame(path: &Path) -> anyhow::Result<SeqFrame> {
    let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mesh = parse_obj(&text).with_context(|| format!("cannot use {} as a sequence frame", path.display()))?;
    Ok(SeqFrame { topology: Topology::of(&mesh), mesh: Arc::new(mesh) })
}

/// Parses an OBJ frame into a Surface ([`mesh_from_corners`]) whose topology depends only on
/// the faces' position and texture-coordinate indices, not on the normal indices (which
/// exporters renumber from frame to frame). Polygons are fans; each `o` object is a piece.
pub fn parse_obj(text: &str) -> anyhow::Result<Mesh> {
    let (mut v, mut vt, mut vn) = (Vec::<Vec3>::new(), Vec::<Vec2>::new(), Vec::<Vec3>::new());
    // Triangle corners as (v, vt, vn) with 0-based indices, and each triangle's piece.
    let mut corners: Vec<[u32; 3]> = Vec::new();
    let mut tri_piece: Vec<u32> = Vec::new();
    let mut pieces: Vec<String> = Vec::new();
    let mut piece: Option<u32> = None;
    for (lineno, line) in text.lines().enumerate() {
        let at = || format!("line {}", lineno + 1);
        let mut words = line.split_whitespace();
        let Some(tag) = words.next() else { continue };
        let mut floats = |n: usize| -> anyhow::Result<Vec<f32>> {
            let f: Vec<f32> = words
                .by_ref()
                .take(n)
                .map(|w| w.parse::<f32>().with_context(|| format!("{}: \"{w}\" is not a number", at())))
                .collect::<anyhow::Result<_>>()?;
            if f.len() < n {
                bail!("{}: expected {n} numbers after \"{tag}\"", at());
            }
            Ok(f)
        };
        match tag {
            "v" => {
                let f = floats(3)?;
                v.push(Vec3::new(f[0], f[1], f[2]));
            }
            // OBJ's v axis points up; textures here have v down (as in mesh::load_obj).
            "vt" => {
                let f = floats(2)?;
                vt.push(Vec2::new(f[0], 1.0 - f[1]));
            }
            "vn" => {
                let f = floats(3)?;
                vn.push(Vec3::new(f[0], f[1], f[2]));
            }
            "o" => {
                let name = line.trim_start()[1..].trim().to_string();
                let i = pieces.iter().position(|p| *p == name).unwrap_or_else(|| {
                    pieces.push(name);
                    pieces.len() - 1
                });
                piece = Some(i as u32);
            }
            "f" => {
                let p = *piece.get_or_insert_with(|| {
                    pieces.push(String::new());
                    pieces.len() as u32 - 1
                });
                let face: Vec<[u32; 3]> = words
                    .map(|w| parse_corner(w, v.len(), vt.len(), vn.len()).with_context(at))
                    .collect::<anyhow::Result<_>>()?;
                if face.iter().any(|c| c[1] == NONE) {
                    bail!("{}: a face has no texture coordinates (vt); a sequence frame needs the pattern's UVs", at());
                }
                for k in 1..face.len().saturating_sub(1) {
                    corners.extend_from_slice(&[face[0], face[k], face[k + 1]]);
                    tri_piece.push(p);
                }
            }
            _ => {}
        }
    }
    mesh_from_corners(&v, &vt, &vn, &corners, &tri_piece, pieces.len())
}

/// A frame's Surface from triangle corners (indices into positions `v`, UVs `vt` (v down) and
/// normals `vn`; normal NONE where there are none) and each triangle's piece: one vertex per
/// distinct (position, UV) pair in order of first use, so a position on a UV seam becomes two
/// vertices the same way in every frame. Normals are the given ones averaged per position (so
/// seams do not show), or area-weighted face normals where a corner has none.
fn mesh_from_corners(
    v: &[Vec3],
    vt: &[Vec2],
    vn: &[Vec3],
    corners: &[[u32; 3]],
    tri_piece: &[u32],
    piece_count: usize,
) -> anyhow::Result<Mesh> {
    if corners.is_empty() {
        bail!("no faces");
    }
    let mut ids: HashMap<(u32, u32), u32> = HashMap::new();
    let (mut pos_of, mut uvs, mut piece_ids, mut indices) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
    for (c, corner) in corners.iter().enumerate() {
        let id = *ids.entry((corner[0], corner[1])).or_insert_with(|| {
            pos_of.push(corner[0]);
            uvs.push(vt[corner[1] as usize]);
            piece_ids.push(tri_piece[c / 3]);
            pos_of.len() as u32 - 1
        });
        indices.push(id);
    }
    let positions: Vec<Vec3> = pos_of.iter().map(|&i| v[i as usize]).collect();
    let mut per_position = vec![Vec3::ZERO; v.len()];
    if corners.iter().all(|c| c[2] != NONE) {
        for c in corners {
            per_position[c[0] as usize] += vn[c[2] as usize].normalize_or_zero();
        }
    } else {
        for t in corners.chunks_exact(3) {
            let [a, b, c] = [t[0][0] as usize, t[1][0] as usize, t[2][0] as usize];
            let n = (v[b] - v[a]).cross(v[c] - v[a]);
            for i in [a, b, c] {
                per_position[i] += n;
            }
        }
    }
    let normals = pos_of.iter().map(|&i| per_position[i as usize].try_normalize().unwrap_or(Vec3::Y)).collect();
    if piece_count < 2 {
        piece_ids.clear();
    }
    Mesh::from_parts(positions, Some(normals), uvs, indices, piece_ids)
}

/// `v`, `v/vt`, `v//vn` or `v/vt/vn`; 1-based or negative (relative) indices, made 0-based.
fn parse_corner(word: &str, nv: usize, nvt: usize, nvn: usize) -> anyhow::Result<[u32; 3]> {
    let mut parts = word.split('/');
    let mut index = |count: usize, what: &str, required: bool| -> anyhow::Result<u32> {
        let text = parts.next().unwrap_or("");
        if text.is_empty() {
            if required {
                bail!("face corner \"{word}\" has no {what} index");
            }
            return Ok(NONE);
        }
        let i: i64 = text.parse().with_context(|| format!("face corner \"{word}\": \"{text}\" is not an index"))?;
        let resolved = if i > 0 { i - 1 } else { count as i64 + i };
        if i == 0 || resolved < 0 || resolved >= count as i64 {
            bail!("face corner \"{word}\": {what} index {i} is out of range (there are {count} so far)");
        }
        Ok(resolved as u32)
    };
    Ok([index(nv, "position", true)?, index(nvt, "texture coordinate", false)?, index(nvn, "normal", false)?])
}

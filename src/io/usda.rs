//! USD ASCII (.usda), written by hand and read back: a mesh cache of a frame range (no USD
//! library builds with our toolchain at a cost CI affords, and the text form is simple).
//!
//! Written: a stage with `timeCodesPerSecond` = the frame rate, `startTimeCode`/`endTimeCode`
//! = the first and last frame (one time code per frame), Y up, metres; an Xform `/werkstatt`
//! holding a Mesh `mesh` with `points`, `normals` (per vertex), `primvars:st` (per vertex, v
//! up), `faceVertexCounts` and `faceVertexIndices`. Each is written once as its first frame's
//! value and, where frames differ, also as `timeSamples` keyed by frame.
//!
//! Read: the subset this writes and what similar writers (Blender, Houdini) put in a mesh
//! cache: `def` prims nested in any depth, attribute defaults and time samples (held between
//! samples), polygons fan-triangulated; normals and UVs are kept where they are per vertex.

use anyhow::{Context as _, bail};
use glam::{Vec2, Vec3};
use std::fmt::Write as _;
use std::path::Path;

use crate::mesh::Mesh;

/// Writes `frames` (frame number, mesh; in increasing frame order) as one animated mesh.
pub fn write_usda(path: &Path, fps: f64, frames: &[(i64, &Mesh)]) -> anyhow::Result<()> {
    let text = usda_text(fps, frames).with_context(|| format!("cannot write {}", path.display()))?;
    crate::io::atomic::write_atomic(path, text.as_bytes()).with_context(|| format!("cannot write {}", path.display()))
}

fn usda_text(fps: f64, frames: &[(i64, &Mesh)]) -> anyhow::Result<String> {
    let (Some((first, _)), Some((last, _))) = (frames.first(), frames.last()) else { bail!("no frames to write") };
    if !(fps.is_finite() && fps > 0.0) {
        bail!("frame rate {fps} is not a positive number");
    }
    for (frame, mesh) in frames {
        if mesh.positions.iter().chain(&mesh.normals).any(|p| !p.is_finite()) {
            bail!("frame {frame}: a position or normal is not finite");
        }
    }
    let mut s = String::new();
    let _ = write!(
        s,
        "#usda 1.0\n(\n    defaultPrim = \"werkstatt\"\n    doc = \"werkstatt mesh cache\"\n    metersPerUnit = 1\n    upAxis = \"Y\"\n    timeCodesPerSecond = {fps}\n    framesPerSecond = {fps}\n    startTimeCode = {first}\n    endTimeCode = {last}\n)\n\ndef Xform \"werkstatt\"\n{{\n    def Mesh \"mesh\"\n    {{\n        uniform token subdivisionScheme = \"none\"\n"
    );
    let counts = |m: &Mesh, s: &mut String| list(s, m.indices.chunks_exact(3), |s, _| s.write_char('3'));
    let indices = |m: &Mesh, s: &mut String| list(s, &m.indices[..3 * m.triangle_count()], |s, i| write!(s, "{i}"));
    let vec3 = |s: &mut String, p: &Vec3| write!(s, "({}, {}, {})", p.x, p.y, p.z);
    attribute(&mut s, "int[] faceVertexCounts", "", frames, counts);
    attribute(&mut s, "int[] faceVertexIndices", "", frames, indices);
    attribute(&mut s, "point3f[] points", "", frames, |m, s| list(s, &m.positions, vec3));
    if frames.iter().all(|(_, m)| m.normals.len() == m.positions.len()) {
        attribute(&mut s, "normal3f[] normals", "", frames, |m, s| list(s, &m.normals, vec3));
    }
    if frames.iter().all(|(_, m)| m.uvs.len() == m.positions.len()) {
        // USD's st has v up (as OBJ's); the mesh's v runs down.
        let st = |m: &Mesh, s: &mut String| list(s, &m.uvs, |s, t| write!(s, "({}, {})", t.x, 1.0 - t.y));
        attribute(
            &mut s,
            "texCoord2f[] primvars:st",
            " (\n            interpolation = \"vertex\"\n        )",
            frames,
            st,
        );
    }
    s.push_str("    }\n}\n");
    Ok(s)
}

/// `[a, b, ...]` of `items`, each written by `item`.
fn list<T>(
    s: &mut String,
    items: impl IntoIterator<Item = T>,
    mut item: impl FnMut(&mut String, T) -> std::fmt::Result,
) {
    s.push('[');
    for (k, t) in items.into_iter().enumerate() {
        if k > 0 {
            s.push_str(", ");
        }
        let _ = item(s, t);
    }
    s.push(']');
}

/// One attribute: the first frame's value as its default (with `meta`), and time samples of
/// every frame when the values differ.
fn attribute(s: &mut String, decl: &str, meta: &str, frames: &[(i64, &Mesh)], value: impl Fn(&Mesh, &mut String)) {
    let text = |m: &Mesh| {
        let mut v = String::new();
        value(m, &mut v);
        v
    };
    let first = text(frames[0].1);
    let _ = writeln!(s, "        {decl} = {first}{meta}");
    // Meshes are shared between frames when nothing changed; compare the text only otherwise.
    let same = |m: &Mesh| std::ptr::eq(m, frames[0].1) || text(m) == first;
    if frames.iter().all(|(_, m)| same(m)) {
        return;
    }
    let _ = writeln!(s, "        {decl}.timeSamples = {{");
    for (frame, m) in frames {
        let _ = writeln!(s, "            {frame}: {},", text(m));
    }
    s.push_str("        }\n");
}

/// A stage read from a .usda file: its time codes and every Mesh prim.
#[derive(Debug)]
pub struct UsdaStage {
    pub time_codes_per_second: f64,
    pub start: f64,
    pub end: f64,
    pub meshes: Vec<UsdaMesh>,
}

/// One Mesh prim: its path and its geometry at each time it has samples (one at `start` when
/// nothing is animated).
#[derive(Debug)]
pub struct UsdaMesh {
    pub path: String,
    pub samples: Vec<(f64, MeshSample)>,
}

/// A mesh at one time: triangles (polygons fan-triangulated), normals and UVs (v down, as the
/// renderer's) where the file has them per vertex, else empty.
#[derive(Debug, Clone, PartialEq)]
pub struct MeshSample {
    pub positions: Vec<Vec3>,
    pub normals: Vec<Vec3>,
    pub uvs: Vec<Vec2>,
    pub indices: Vec<u32>,
}

/// Reads a .usda file; every error names the file (and the line where the text is wrong).
pub fn read_usda(path: &Path) -> anyhow::Result<UsdaStage> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    let text = std::str::from_utf8(&bytes).map_err(|e| anyhow::anyhow!("{}: not UTF-8 text ({e})", path.display()))?;
    parse_usda(text).map_err(|e| anyhow::anyhow!("{}: {e:#}", path.display()))
}

/// Parses USD ASCII text (see [`read_usda`]).
pub fn parse_usda(text: &str) -> anyhow::Result<UsdaStage> {
    if !text.starts_with("#usda ") {
        bail!("not USD ASCII: the file does not start with \"#usda\"");
    }
    let mut p = Parser { toks: tokenize(text)?, at: 0 };
    let mut stage = UsdaStage { time_codes_per_second: 24.0, start: 0.0, end: 0.0, meshes: Vec::new() };
    if p.peek_punct('(') {
        for (key, value) in p.metadata()? {
            let number = || value.number().with_context(|| format!("{key} is not a number"));
            match key.as_str() {
                "timeCodesPerSecond" => stage.time_codes_per_second = number()?,
                "startTimeCode" => stage.start = number()?,
                "endTimeCode" => stage.end = number()?,
                _ => {}
            }
        }
    }
    while p.at < p.toks.len() {
        p.prim("", &mut stage)?;
    }
    if stage.meshes.is_empty() {
        bail!("the stage holds no Mesh prim");
    }
    if !(stage.time_codes_per_second.is_finite() && stage.time_codes_per_second > 0.0) {
        bail!("timeCodesPerSecond {} is not a positive number", stage.time_codes_per_second);
    }
    Ok(stage)
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Word(String),
    Num(f64),
    Str(String),
    Punct(char),
}

#[derive(Debug, Clone)]
enum Val {
    Num(f64),
    /// A word or string (tokens, asset paths): not needed for meshes.
    Other,
    List(Vec<Val>),
    Dict(Vec<(f64, Val)>),
}

impl Val {
    fn number(&self) -> Option<f64> {
        if let Val::Num(n) = self { Some(*n) } else { None }
    }

    fn numbers(&self) -> Option<Vec<f64>> {
        let Val::List(items) = self else { return None };
        items.iter().map(Val::number).collect()
    }

    /// `[(x, y), ...]` as tuples of `N` numbers.
    fn tuples<const N: usize>(&self) -> Option<Vec<[f32; N]>> {
        let Val::List(items) = self else { return None };
        let tuple = |v: &Val| {
            let n = v.numbers()?;
            let mut out = [0.0; N];
            (n.len() == N).then(|| {
                out.iter_mut().zip(n).for_each(|(o, x)| *o = x as f32);
                out
            })
        };
        items.iter().map(tuple).collect()
    }
}

/// Tokens with the line each starts on.
fn tokenize(text: &str) -> anyhow::Result<Vec<(Tok, usize)>> {
    let mut toks = Vec::new();
    let b = text.as_bytes();
    let (mut i, mut line) = (0, 1);
    while i < b.len() {
        let c = b[i];
        match c {
            b'\n' => {
                line += 1;
                i += 1;
            }
            _ if c.is_ascii_whitespace() => i += 1,
            b'#' => {
                while i < b.len() && b[i] != b'\n' {
                    i += 1;
                }
            }
            b'"' | b'\'' => {
                // Triple-quoted strings may span lines; escapes are kept as written.
                let triple = b[i..].starts_with(&[c, c, c]);
                let quote = if triple { 3 } else { 1 };
                let start = i + quote;
                let mut j = start;
                loop {
                    if j >= b.len() {
                        bail!("line {line}: a string is not closed");
                    }
                    if b[j] == b'\\' {
                        j += 2;
                        continue;
                    }
                    if b[j..].starts_with(&b[i..i + quote]) {
                        break;
                    }
                    j += 1;
                }
                let s = text.get(start..j.min(b.len())).context("a string is cut inside a character")?;
                toks.push((Tok::Str(s.to_string()), line));
                line += s.matches('\n').count();
                i = j + quote;
            }
            b'<' => {
                let end = b[i..]
                    .iter()
                    .position(|&x| x == b'>')
                    .with_context(|| format!("line {line}: a path is not closed"))?;
                toks.push((Tok::Str(text[i + 1..i + end].to_string()), line));
                i += end + 1;
            }
            b'0'..=b'9' | b'-' | b'+' | b'.' => {
                let start = i;
                i += 1;
                while i < b.len() && matches!(b[i], b'0'..=b'9' | b'.' | b'e' | b'E' | b'-' | b'+') {
                    i += 1;
                }
                let word = &text[start..i];
                let n = word.parse::<f64>().map_err(|_| anyhow::anyhow!("line {line}: \"{word}\" is not a number"))?;
                toks.push((Tok::Num(n), line));
            }
            _ if c.is_ascii_alphabetic() || c == b'_' => {
                let start = i;
                while i < b.len() && (b[i].is_ascii_alphanumeric() || matches!(b[i], b'_' | b':' | b'.')) {
                    i += 1;
                }
                // "inf" and "nan" are numbers in USD text.
                match &text[start..i] {
                    "inf" => toks.push((Tok::Num(f64::INFINITY), line)),
                    "nan" => toks.push((Tok::Num(f64::NAN), line)),
                    w => toks.push((Tok::Word(w.to_string()), line)),
                }
            }
            b'(' | b')' | b'[' | b']' | b'{' | b'}' | b'=' | b',' | b':' | b';' => {
                toks.push((Tok::Punct(c as char), line));
                i += 1;
            }
            _ => bail!("line {line}: unexpected character {:?}", text[i..].chars().next().unwrap_or('?')),
        }
    }
    Ok(toks)
}

struct Parser {
    toks: Vec<(Tok, usize)>,
    at: usize,
}

/// An attribute of a prim: its default value and its time samples.
#[derive(Default)]
struct Attr {
    default: Option<Val>,
    samples: Vec<(f64, Val)>,
}

impl Parser {
    fn line(&self) -> usize {
        self.toks.get(self.at).or(self.toks.last()).map_or(1, |t| t.1)
    }

    fn next(&mut self) -> anyhow::Result<Tok> {
        let t = self.toks.get(self.at).map(|t| t.0.clone());
        self.at += 1;
        t.with_context(|| format!("line {}: the file ends early", self.line()))
    }

    fn peek_punct(&self, c: char) -> bool {
        matches!(self.toks.get(self.at), Some((Tok::Punct(p), _)) if *p == c)
    }

    fn expect(&mut self, c: char) -> anyhow::Result<()> {
        let line = self.line();
        match self.next()? {
            Tok::Punct(p) if p == c => Ok(()),
            t => bail!("line {line}: expected '{c}', found {t:?}"),
        }
    }

    fn value(&mut self) -> anyhow::Result<Val> {
        let line = self.line();
        Ok(match self.next()? {
            Tok::Num(n) => Val::Num(n),
            Tok::Str(_) | Tok::Word(_) => Val::Other,
            Tok::Punct(open @ ('[' | '(')) => {
                let close = if open == '[' { ']' } else { ')' };
                let mut items = Vec::new();
                while !self.peek_punct(close) {
                    items.push(self.value()?);
                    if !self.peek_punct(close) {
                        self.expect(',')?;
                    }
                }
                self.expect(close)?;
                Val::List(items)
            }
            Tok::Punct('{') => {
                let mut entries = Vec::new();
                while !self.peek_punct('}') {
                    let line = self.line();
                    let Tok::Num(key) = self.next()? else { bail!("line {line}: a time sample's key is not a number") };
                    self.expect(':')?;
                    entries.push((key, self.value()?));
                    if !self.peek_punct('}') {
                        self.expect(',')?;
                    }
                }
                self.expect('}')?;
                Val::Dict(entries)
            }
            t => bail!("line {line}: expected a value, found {t:?}"),
        })
    }

    /// `( key = value ... )`, skipping doc strings; nested dictionaries are skipped whole.
    fn metadata(&mut self) -> anyhow::Result<Vec<(String, Val)>> {
        self.expect('(')?;
        let mut out = Vec::new();
        loop {
            let line = self.line();
            match self.next()? {
                Tok::Punct(')') => return Ok(out),
                Tok::Str(_) | Tok::Punct(';') => {}
                Tok::Word(w) => {
                    // `key = value`, or typed/listop forms (`prepend apiSchemas = [...]`):
                    // the last word before '=' is the key.
                    let mut key = w;
                    while let Some((Tok::Word(_), _)) = self.toks.get(self.at) {
                        key = match self.next()? {
                            Tok::Word(w) => w,
                            _ => unreachable!("peeked a word"),
                        };
                    }
                    self.expect('=')?;
                    if self.peek_punct('{') {
                        self.skip_braces()?;
                    } else {
                        out.push((key, self.value()?));
                    }
                }
                t => bail!("line {line}: unexpected {t:?} in metadata"),
            }
        }
    }

    fn skip_braces(&mut self) -> anyhow::Result<()> {
        self.expect('{')?;
        let mut depth = 1;
        while depth > 0 {
            match self.next()? {
                Tok::Punct('{') => depth += 1,
                Tok::Punct('}') => depth -= 1,
                _ => {}
            }
        }
        Ok(())
    }

    /// `def|over|class [Type] "name" [(metadata)] { ... }`; Mesh prims go into `stage`.
    fn prim(&mut self, parent: &str, stage: &mut UsdaStage) -> anyhow::Result<()> {
        let line = self.line();
        match self.next()? {
            Tok::Word(w) if matches!(w.as_str(), "def" | "over" | "class") => {}
            t => bail!("line {line}: expected a prim (def ...), found {t:?}"),
        }
        let type_name = match self.next()? {
            Tok::Word(w) => {
                let line = self.line();
                let Tok::Str(_) = self.next()? else { bail!("line {line}: a prim without a name") };
                self.at -= 1;
                w
            }
            Tok::Str(_) => {
                self.at -= 1;
                String::new()
            }
            t => bail!("line {line}: expected a prim type or name, found {t:?}"),
        };
        let Tok::Str(name) = self.next()? else { bail!("line {line}: a prim without a name") };
        let path = format!("{parent}/{name}");
        if self.peek_punct('(') {
            self.metadata()?;
        }
        self.expect('{')?;
        let mut attrs: std::collections::HashMap<String, Attr> = std::collections::HashMap::new();
        while !self.peek_punct('}') {
            if matches!(self.toks.get(self.at), Some((Tok::Word(w), _)) if matches!(w.as_str(), "def" | "over" | "class"))
            {
                self.prim(&path, stage)?;
                continue;
            }
            self.property(&mut attrs)?;
        }
        self.expect('}')?;
        if type_name == "Mesh" {
            let samples = mesh_samples(&attrs, stage.start).with_context(|| format!("Mesh {path} (line {line})"))?;
            stage.meshes.push(UsdaMesh { path, samples });
        }
        Ok(())
    }

    /// `[uniform|custom|varying] type[[]] name[.timeSamples] [= value] [(metadata)]`, or
    /// `rel name [= <path>]`, or a variant set (an error: not supported).
    fn property(&mut self, attrs: &mut std::collections::HashMap<String, Attr>) -> anyhow::Result<()> {
        let line = self.line();
        let mut words = Vec::new();
        while let Some((Tok::Word(_), _)) = self.toks.get(self.at) {
            let Tok::Word(w) = self.next()? else { unreachable!("peeked a word") };
            words.push(w);
            if self.peek_punct('[') {
                self.expect('[')?;
                self.expect(']')?;
            }
        }
        let Some(name) = words.pop() else { bail!("line {line}: expected a property, found {:?}", self.next()?) };
        if words.is_empty() {
            bail!("line {line}: property {name} has no type");
        }
        let value = if self.peek_punct('=') {
            self.expect('=')?;
            Some(self.value()?)
        } else {
            None
        };
        if self.peek_punct('(') {
            self.metadata()?;
        }
        if let Some(base) = name.strip_suffix(".timeSamples") {
            let Some(Val::Dict(samples)) = value else { bail!("line {line}: {name} is not a dictionary of samples") };
            attrs.entry(base.to_string()).or_default().samples = samples;
        } else if let Some(value) = value {
            attrs.entry(name).or_default().default = Some(value);
        }
        Ok(())
    }
}

/// The mesh at every time any of its attributes has a sample; each attribute's value at a time
/// is its sample there, else the one before (held), else the first, else its default.
fn mesh_samples(attrs: &std::collections::HashMap<String, Attr>, start: f64) -> anyhow::Result<Vec<(f64, MeshSample)>> {
    let names = ["points", "faceVertexCounts", "faceVertexIndices", "normals", "primvars:st"];
    let mut times: Vec<f64> =
        names.iter().filter_map(|n| attrs.get(*n)).flat_map(|a| a.samples.iter().map(|s| s.0)).collect();
    times.sort_by(f64::total_cmp);
    times.dedup();
    if times.is_empty() {
        times.push(start);
    }
    let at = |name: &str, t: f64| -> Option<&Val> {
        let a = attrs.get(name)?;
        let held = a.samples.iter().rev().find(|s| s.0 <= t).or(a.samples.first()).map(|s| &s.1);
        held.or(a.default.as_ref())
    };
    let mut out = Vec::with_capacity(times.len());
    for t in times {
        let positions: Vec<Vec3> = at("points", t)
            .with_context(|| format!("time {t}: no points"))?
            .tuples::<3>()
            .with_context(|| format!("time {t}: points are not a list of 3 numbers each"))?
            .into_iter()
            .map(Vec3::from)
            .collect();
        let ints = |name: &str| -> anyhow::Result<Vec<i64>> {
            let v = at(name, t).with_context(|| format!("time {t}: no {name}"))?;
            let n = v.numbers().with_context(|| format!("time {t}: {name} is not a list of numbers"))?;
            n.into_iter()
                .map(|x| (x.fract() == 0.0 && x >= 0.0 && x < u32::MAX as f64).then_some(x as i64))
                .collect::<Option<_>>()
                .with_context(|| format!("time {t}: {name} holds a value that is not a count or index"))
        };
        let (counts, corners) = (ints("faceVertexCounts")?, ints("faceVertexIndices")?);
        if counts.iter().sum::<i64>() != corners.len() as i64 {
            bail!(
                "time {t}: faceVertexCounts add up to {}, not the {} faceVertexIndices",
                counts.iter().sum::<i64>(),
                corners.len()
            );
        }
        if let Some(i) = corners.iter().find(|&&i| i as usize >= positions.len()) {
            bail!("time {t}: index {i} is past the {} points", positions.len());
        }
        let mut indices = Vec::new();
        let mut k = 0;
        for &n in &counts {
            let face = &corners[k..k + n as usize];
            for j in 1..face.len().saturating_sub(1) {
                indices.extend([face[0], face[j], face[j + 1]].map(|i| i as u32));
            }
            k += n as usize;
        }
        // Per-vertex normals and UVs only; face-varying ones are left to the mesh builder.
        let per_vertex = |v: Option<Vec<[f32; 3]>>| v.filter(|v| v.len() == positions.len()).unwrap_or_default();
        let normals = per_vertex(at("normals", t).and_then(Val::tuples::<3>)).into_iter().map(Vec3::from).collect();
        let uvs = at("primvars:st", t)
            .and_then(Val::tuples::<2>)
            .filter(|v| v.len() == positions.len())
            .unwrap_or_default()
            .into_iter()
            .map(|[s, t]| Vec2::new(s, 1.0 - t))
            .collect();
        out.push((t, MeshSample { positions, normals, uvs, indices }));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn mesh(dx: f32) -> Mesh {
        Mesh::from_raw(
            vec![Vec3::new(dx, 0.0, 0.0), Vec3::X, Vec3::new(0.5, 1.0, -0.25)],
            vec![Vec3::Z; 3],
            vec![Vec2::new(0.0, 0.0), Vec2::new(1.0, 0.0), Vec2::new(0.5, 0.75)],
            Vec::new(),
            Vec::new(),
            vec![0, 1, 2],
        )
    }

    /// Written and read back: the time codes, a sample per frame where points move, the
    /// topology written once, UVs' v flipped there and back.
    #[test]
    fn a_cache_reads_back_frame_by_frame() {
        let (still, moved) = (mesh(0.0), mesh(-0.125));
        let frames = vec![(3, &still), (4, &still), (5, &moved)];
        let text = usda_text(30.0, &frames).unwrap();
        assert_eq!(text.matches("faceVertexIndices").count(), 1, "constant topology once:\n{text}");
        assert!(text.contains("texCoord2f[] primvars:st = [(0, 1), (1, 1), (0.5, 0.25)]"), "{text}");
        let stage = parse_usda(&text).unwrap();
        assert_eq!((stage.time_codes_per_second, stage.start, stage.end), (30.0, 3.0, 5.0));
        assert_eq!(stage.meshes.len(), 1);
        assert_eq!(stage.meshes[0].path, "/werkstatt/mesh");
        let samples = &stage.meshes[0].samples;
        assert_eq!(samples.iter().map(|s| s.0).collect::<Vec<_>>(), [3.0, 4.0, 5.0]);
        for ((_, m), (_, s)) in frames.iter().zip(samples) {
            assert_eq!((&s.positions, &s.normals, &s.uvs, &s.indices), (&m.positions, &m.normals, &m.uvs, &m.indices));
        }
    }

    /// Quads are fan-triangulated, held samples fill the times in between.
    #[test]
    fn polygons_triangulate_and_samples_hold() {
        let text = "#usda 1.0\n(\n    \"a doc string\"\n    timeCodesPerSecond = 24\n)\ndef \"root\" (\n    kind = \"component\"\n)\n{\n    def Mesh \"quad\" {\n        int[] faceVertexCounts = [4]\n        int[] faceVertexIndices = [0, 1, 2, 3]\n        point3f[] points.timeSamples = {\n            1: [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)],\n            3: [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)],\n        }\n        float3[] extent = [(0, 0, 0), (1, 1, 1)]\n        rel material:binding = </Looks/a>\n    }\n}\n";
        let stage = parse_usda(text).unwrap();
        let s = &stage.meshes[0].samples;
        assert_eq!(stage.meshes[0].path, "/root/quad");
        assert_eq!(s.len(), 2);
        assert_eq!(s[0].1.indices, [0, 1, 2, 0, 2, 3]);
        assert_eq!(s[1].1.positions[2], Vec3::ONE);
    }
}

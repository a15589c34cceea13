//! USD ASCII (.usda), written by hand and read back: a mesh cache of a frame range (no USD
//! library builds with our toolchain at a cost CI affords, and the text form is simple).
//!
//! Written: a stage with `timeCodesPerSecond` = the frame rate, `startTimeCode`/`endTimeCode`
//! = the first and last frame (one time code per frame), Y up, metres; an Xform `/werkstatt`
//! holding a Mesh `mesh` with `points`, `normals` (per vertex), `primvars:st` (per vertex, v
//! up), `faceVertexCounts` and `faceVertexIndices`. Each is written once as its first frame's
//! value and, where frames differ, also as `timeSamples` keyed by frame.
//!
//! Read: the prims of a layer at any depth with their attributes' defaults, time samples and
//! `interpolation` ([`read_usda_layer`]); [`crate::io::usd`] assembles meshes from them. The
//! text is read in one pass without a token list, and number arrays are kept flat, so a cache
//! costs about 8 bytes per number it holds.

use anyhow::{Context as _, bail};
use glam::Vec3;
use std::fmt::Write as _;
use std::path::Path;

use super::usd::{Attr, Layer, Prim, Value};
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

/// Reads a .usda file's layer; every error names the file (and the line where the text is
/// wrong). Numeric arrays longer than [`LAZY_BYTES`] are not parsed: the layer holds
/// [`Val::Lazy`] for each, an index into the returned spans ([`read_lazy`] parses one), so
/// the layer of a long cache stays small.
pub fn read_usda_layer(path: &Path) -> anyhow::Result<(Layer<Val>, Vec<LazySpan>)> {
    let file = std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let (skeleton, spans) = skim(std::io::BufReader::with_capacity(1 << 20, file))
        .map_err(|e| anyhow::anyhow!("{}: {e:#}", path.display()))?;
    let text = String::from_utf8(skeleton).map_err(|e| anyhow::anyhow!("{}: not UTF-8 text ({e})", path.display()))?;
    let layer = parse_usda(&text).map_err(|e| anyhow::anyhow!("{}: {e:#}", path.display()))?;
    Ok((layer, spans))
}

/// Numeric arrays at least this long (in bytes of text) are read when a value is asked for.
pub const LAZY_BYTES: u64 = 4096;

/// Where a numeric array left unparsed lies in a .usda file: its byte range and first line.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct LazySpan {
    pub offset: u64,
    pub len: u64,
    pub line: usize,
}

/// The array at `span` of the .usda file at `path`, parsed.
pub fn read_lazy(path: &Path, span: LazySpan) -> anyhow::Result<Val> {
    use std::io::{Read as _, Seek as _};
    let mut file = std::fs::File::open(path).with_context(|| format!("cannot read {}", path.display()))?;
    let mut bytes = Vec::new();
    file.seek(std::io::SeekFrom::Start(span.offset))?;
    file.take(span.len).read_to_end(&mut bytes)?;
    anyhow::ensure!(bytes.len() as u64 == span.len, "line {}: the file ends inside an array (it changed?)", span.line);
    let text = std::str::from_utf8(&bytes).map_err(|e| anyhow::anyhow!("line {}: not UTF-8 text ({e})", span.line))?;
    let mut p = Parser { lex: Lexer { text, i: 0, line: span.line }, peeked: None };
    let value = p.value()?;
    match p.peek()? {
        None if matches!(value, Val::Numbers(_)) => Ok(value),
        _ => bail!("line {}: the array is not plain numbers", span.line),
    }
}

/// The marker that stands for a lazy array in the skimmed text: `\x01<index>\x01`.
const LAZY_MARK: u8 = 1;

/// Copies USD text from `input` line by line, replacing each numeric array (only numbers,
/// tuples, commas and blanks between its brackets) of at least [`LAZY_BYTES`] with a marker
/// and its span, and keeping its line breaks so later lines keep their numbers. Strings and
/// comments are copied as they are. Memory: the skeleton, and the longest line.
fn skim(mut input: impl std::io::BufRead) -> anyhow::Result<(Vec<u8>, Vec<LazySpan>)> {
    enum State {
        Text,
        /// Inside a string closed by `quote` repeated `count` times.
        Quoted {
            quote: u8,
            count: usize,
        },
        /// Inside an array that may be lazy: where it starts, its line, the nesting depth,
        /// and its bytes while it is short enough to be copied if it turns out not to be.
        Array {
            offset: u64,
            line: usize,
            depth: usize,
            bytes: Vec<u8>,
            breaks: usize,
        },
    }
    let numeric = |c: u8| c.is_ascii_digit() || b".eE+-,()[] \t\r\ninfa".contains(&c);
    let (mut out, mut spans, mut state) = (Vec::new(), Vec::new(), State::Text);
    let (mut offset, mut line_number, mut line) = (0u64, 1usize, Vec::new());
    loop {
        line.clear();
        if input.read_until(b'\n', &mut line)? == 0 {
            break;
        }
        let mut i = 0;
        while i < line.len() {
            let c = line[i];
            match &mut state {
                State::Text => match c {
                    b'#' => {
                        out.extend_from_slice(&line[i..]);
                        i = line.len();
                        continue;
                    }
                    b'"' | b'\'' | b'@' => {
                        let count = if line[i..].starts_with(&[c, c, c]) { 3 } else { 1 };
                        out.extend_from_slice(&line[i..i + count]);
                        i += count;
                        state = State::Quoted { quote: c, count };
                        continue;
                    }
                    b'[' => {
                        state = State::Array {
                            offset: offset + i as u64,
                            line: line_number,
                            depth: 1,
                            bytes: vec![c],
                            breaks: 0,
                        };
                    }
                    LAZY_MARK => bail!("line {line_number}: unexpected character '\\x01'"),
                    _ => out.push(c),
                },
                State::Quoted { quote, count } => {
                    if c == b'\\' && *quote != b'@' {
                        out.extend_from_slice(&line[i..(i + 2).min(line.len())]);
                        i += 2;
                        continue;
                    }
                    if line[i..].iter().take(*count).filter(|&&q| q == *quote).count() == *count {
                        out.extend_from_slice(&line[i..i + *count]);
                        i += *count;
                        state = State::Text;
                        continue;
                    }
                    out.push(c);
                }
                State::Array { offset: start, line: first, depth, bytes, breaks } => {
                    if !numeric(c) {
                        // Not a plain numeric array: copied, and this byte read as text.
                        out.append(bytes);
                        state = State::Text;
                        continue;
                    }
                    bytes.push(c);
                    *breaks += usize::from(c == b'\n');
                    match c {
                        b'[' => *depth += 1,
                        b']' => *depth -= 1,
                        _ => {}
                    }
                    if *depth == 0 {
                        let len = offset + i as u64 + 1 - *start;
                        if len >= LAZY_BYTES {
                            out.push(LAZY_MARK);
                            out.extend_from_slice(spans.len().to_string().as_bytes());
                            out.push(LAZY_MARK);
                            out.extend(std::iter::repeat_n(b'\n', *breaks));
                            spans.push(LazySpan { offset: *start, len, line: *first });
                        } else {
                            out.append(bytes);
                        }
                        state = State::Text;
                    }
                }
            }
            i += 1;
        }
        offset += line.len() as u64;
        line_number += 1;
    }
    if let State::Array { bytes, .. } = &mut state {
        // An array the file ends in: the parser says where.
        out.append(bytes);
    }
    Ok((out, spans))
}

/// Parses USD ASCII text (see [`read_usda_layer`]).
pub fn parse_usda(text: &str) -> anyhow::Result<Layer<Val>> {
    if !text.starts_with("#usda ") {
        bail!("not USD ASCII: the file does not start with \"#usda\"");
    }
    let mut p = Parser { lex: Lexer { text, i: 0, line: 1 }, peeked: None };
    p.lex.skip_line();
    let mut layer = Layer::default();
    if p.peek_punct('(')? {
        for (key, value) in p.metadata()? {
            let number = || match &value {
                Val::Numbers(n) if n.len() == 1 => Ok(n[0]),
                _ => Err(anyhow::anyhow!("{key} is not a number")),
            };
            match key.as_str() {
                "timeCodesPerSecond" => layer.time_codes_per_second = number()?,
                "startTimeCode" => layer.start = number()?,
                "endTimeCode" => layer.end = number()?,
                "metersPerUnit" => layer.meters_per_unit = number()?,
                "upAxis" => {
                    let Val::Text(axis) = &value else { bail!("upAxis is not a token") };
                    layer.up_axis = axis.clone();
                }
                _ => {}
            }
        }
    }
    while p.peek()?.is_some() {
        p.prim("", &mut layer)?;
    }
    layer.finish()?;
    Ok(layer)
}

/// A parsed value: numbers (scalars, tuples and arrays of them, flattened), a word or string,
/// a list of other values, or time samples.
#[derive(Debug, Clone)]
pub enum Val {
    Numbers(Vec<f64>),
    Text(String),
    List(Vec<Val>),
    Samples(Vec<(f64, Val)>),
    /// A numeric array left in the file: an index into the spans of [`read_usda_layer`].
    Lazy(usize),
}

/// A parsed value as a [`Value`]: numbers, or a token or list of tokens.
pub fn val_value(v: &Val) -> anyhow::Result<Value> {
    match v {
        Val::Numbers(n) => Ok(Value::Numbers(n.clone())),
        Val::Text(t) => Ok(Value::Tokens(vec![t.clone()])),
        Val::List(items) => items
            .iter()
            .map(|i| if let Val::Text(t) = i { Some(t.clone()) } else { None })
            .collect::<Option<_>>()
            .map(Value::Tokens)
            .context("a list of mixed values"),
        Val::Samples(_) => bail!("time samples where a value belongs"),
        Val::Lazy(_) => bail!("an array not read from the file"),
    }
}

#[derive(Debug, Clone, PartialEq)]
enum Tok {
    Word(String),
    Num(f64),
    Str(String),
    Punct(char),
    /// A lazy array's marker.
    Lazy(usize),
}

/// Tokens one at a time, with the line each starts on.
struct Lexer<'a> {
    text: &'a str,
    i: usize,
    line: usize,
}

impl Lexer<'_> {
    fn skip_line(&mut self) {
        let b = self.text.as_bytes();
        while self.i < b.len() && b[self.i] != b'\n' {
            self.i += 1;
        }
    }

    /// The next token and its line, or None at the end.
    fn token(&mut self) -> anyhow::Result<Option<(Tok, usize)>> {
        let (text, b) = (self.text, self.text.as_bytes());
        loop {
            let Some(&c) = b.get(self.i) else { return Ok(None) };
            let line = self.line;
            match c {
                b'\n' => {
                    self.line += 1;
                    self.i += 1;
                }
                _ if c.is_ascii_whitespace() => self.i += 1,
                b'#' => self.skip_line(),
                b'"' | b'\'' | b'@' => {
                    // Triple-quoted strings (and @@@ asset paths) may span lines; escapes are
                    // kept as written.
                    let i = self.i;
                    let quote = if b[i..].starts_with(&[c, c, c]) { 3 } else { 1 };
                    let start = i + quote;
                    let mut j = start;
                    loop {
                        if j >= b.len() {
                            bail!("line {line}: a string is not closed");
                        }
                        if b[j] == b'\\' && c != b'@' {
                            j += 2;
                            continue;
                        }
                        if b[j..].starts_with(&b[i..i + quote]) {
                            break;
                        }
                        j += 1;
                    }
                    let s = text.get(start..j).context("a string is cut inside a character")?;
                    self.line += s.matches('\n').count();
                    self.i = j + quote;
                    return Ok(Some((Tok::Str(s.to_string()), line)));
                }
                b'<' => {
                    let end = b[self.i..]
                        .iter()
                        .position(|&x| x == b'>')
                        .with_context(|| format!("line {line}: a path is not closed"))?;
                    let s = text.get(self.i + 1..self.i + end).context("a path is cut inside a character")?;
                    self.i += end + 1;
                    return Ok(Some((Tok::Str(s.to_string()), line)));
                }
                b'0'..=b'9' | b'-' | b'+' | b'.' => {
                    let start = self.i;
                    self.i += 1;
                    while self.i < b.len() && matches!(b[self.i], b'0'..=b'9' | b'.' | b'e' | b'E' | b'-' | b'+') {
                        self.i += 1;
                    }
                    let word = &text[start..self.i];
                    // "-inf" and "-nan" are numbers in USD text.
                    let word = match (word, b.get(self.i..self.i + 3)) {
                        ("-", Some(b"inf" | b"nan")) => {
                            self.i += 3;
                            &text[start..self.i]
                        }
                        _ => word,
                    };
                    let n =
                        word.parse::<f64>().map_err(|_| anyhow::anyhow!("line {line}: \"{word}\" is not a number"))?;
                    return Ok(Some((Tok::Num(n), line)));
                }
                _ if c.is_ascii_alphabetic() || c == b'_' => {
                    let start = self.i;
                    while self.i < b.len()
                        && (b[self.i].is_ascii_alphanumeric() || matches!(b[self.i], b'_' | b':' | b'.'))
                    {
                        self.i += 1;
                    }
                    return Ok(Some(match &text[start..self.i] {
                        "inf" => (Tok::Num(f64::INFINITY), line),
                        "nan" => (Tok::Num(f64::NAN), line),
                        w => (Tok::Word(w.to_string()), line),
                    }));
                }
                LAZY_MARK => {
                    let end = b[self.i + 1..].iter().position(|&x| x == LAZY_MARK).map(|e| self.i + 1 + e);
                    let index = end.and_then(|end| text[self.i + 1..end].parse().ok());
                    let (Some(end), Some(index)) = (end, index) else { bail!("line {line}: unexpected character") };
                    self.i = end + 1;
                    return Ok(Some((Tok::Lazy(index), line)));
                }
                b'(' | b')' | b'[' | b']' | b'{' | b'}' | b'=' | b',' | b':' | b';' => {
                    self.i += 1;
                    return Ok(Some((Tok::Punct(c as char), line)));
                }
                _ => bail!("line {line}: unexpected character {:?}", text[self.i..].chars().next().unwrap_or('?')),
            }
        }
    }
}

struct Parser<'a> {
    lex: Lexer<'a>,
    peeked: Option<(Tok, usize)>,
}

impl Parser<'_> {
    fn line(&self) -> usize {
        self.peeked.as_ref().map_or(self.lex.line, |p| p.1)
    }

    fn peek(&mut self) -> anyhow::Result<Option<&Tok>> {
        if self.peeked.is_none() {
            self.peeked = self.lex.token()?;
        }
        Ok(self.peeked.as_ref().map(|p| &p.0))
    }

    fn next(&mut self) -> anyhow::Result<Tok> {
        self.peek()?;
        let line = self.line();
        self.peeked.take().map(|p| p.0).with_context(|| format!("line {line}: the file ends early"))
    }

    fn peek_punct(&mut self, c: char) -> anyhow::Result<bool> {
        Ok(matches!(self.peek()?, Some(Tok::Punct(p)) if *p == c))
    }

    fn peek_word(&mut self) -> anyhow::Result<bool> {
        Ok(matches!(self.peek()?, Some(Tok::Word(_))))
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
            Tok::Num(n) => Val::Numbers(vec![n]),
            Tok::Lazy(index) => Val::Lazy(index),
            Tok::Str(s) | Tok::Word(s) => Val::Text(s),
            Tok::Punct(open @ ('[' | '(')) => {
                let close = if open == '[' { ']' } else { ')' };
                // Numbers and tuples of numbers go straight into one flat list.
                let (mut flat, mut items) = (Vec::new(), Vec::new());
                while !self.peek_punct(close)? {
                    match self.value()? {
                        Val::Numbers(n) if items.is_empty() => flat.extend(n),
                        v => {
                            if !flat.is_empty() {
                                items.push(Val::Numbers(std::mem::take(&mut flat)));
                            }
                            items.push(v);
                        }
                    }
                    if !self.peek_punct(close)? {
                        self.expect(',')?;
                    }
                }
                self.expect(close)?;
                if items.is_empty() { Val::Numbers(flat) } else { Val::List(items) }
            }
            Tok::Punct('{') => {
                // Time samples (`time: value, ...`); a dictionary value is skipped.
                if !matches!(self.peek()?, Some(Tok::Num(_) | Tok::Punct('}'))) {
                    self.skip_braces()?;
                    return Ok(Val::List(Vec::new()));
                }
                let mut entries = Vec::new();
                while !self.peek_punct('}')? {
                    let line = self.line();
                    let Tok::Num(key) = self.next()? else { bail!("line {line}: a time sample's key is not a number") };
                    self.expect(':')?;
                    entries.push((key, self.value()?));
                    if !self.peek_punct('}')? {
                        self.expect(',')?;
                    }
                }
                self.expect('}')?;
                Val::Samples(entries)
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
                    while self.peek_word()? {
                        if let Tok::Word(w) = self.next()? {
                            key = w;
                        }
                    }
                    self.expect('=')?;
                    if self.peek_punct('{')? {
                        self.expect('{')?;
                        self.skip_braces()?;
                    } else {
                        out.push((key, self.value()?));
                    }
                }
                t => bail!("line {line}: unexpected {t:?} in metadata"),
            }
        }
    }

    /// Skips to the '}' that closes a '{' already read.
    fn skip_braces(&mut self) -> anyhow::Result<()> {
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

    /// `def|over|class [Type] "name" [(metadata)] { ... }`, pushed into `layer` with every
    /// prim inside it.
    fn prim(&mut self, parent: &str, layer: &mut Layer<Val>) -> anyhow::Result<()> {
        let line = self.line();
        match self.next()? {
            Tok::Word(w) if matches!(w.as_str(), "def" | "over" | "class") => {}
            t => bail!("line {line}: expected a prim (def ...), found {t:?}"),
        }
        let mut type_name = String::new();
        let name = loop {
            match self.next()? {
                Tok::Word(w) if type_name.is_empty() => type_name = w,
                Tok::Str(name) => break name,
                t => bail!("line {line}: expected a prim type and name, found {t:?}"),
            }
        };
        let path = format!("{parent}/{name}");
        if self.peek_punct('(')? {
            self.metadata()?;
        }
        self.expect('{')?;
        let index = layer.prims.len();
        layer.prims.push(Prim { path: path.clone(), type_name, attrs: Default::default() });
        loop {
            let nested = match self.peek()? {
                Some(Tok::Punct('}')) => break,
                Some(Tok::Word(w)) => matches!(w.as_str(), "def" | "over" | "class"),
                _ => false,
            };
            if nested {
                self.prim(&path, layer)?;
            } else {
                self.property(&mut layer.prims[index].attrs)?;
            }
        }
        self.expect('}')
    }

    /// `[uniform|custom|varying] type[[]] name[.timeSamples] [= value] [(metadata)]`, or
    /// `rel name [= <path>]`, or a variant set (an error: not supported).
    fn property(&mut self, attrs: &mut std::collections::HashMap<String, Attr<Val>>) -> anyhow::Result<()> {
        let line = self.line();
        let mut words = Vec::new();
        while self.peek_word()? {
            let Tok::Word(mut w) = self.next()? else { unreachable!("peeked a word") };
            if self.peek_punct('[')? {
                self.expect('[')?;
                self.expect(']')?;
                w.push_str("[]");
            }
            words.push(w);
        }
        let Some(name) = words.pop() else { bail!("line {line}: expected a property, found {:?}", self.next()?) };
        let Some(type_name) = words.pop() else { bail!("line {line}: property {name} has no type") };
        let value = if self.peek_punct('=')? {
            self.expect('=')?;
            Some(self.value()?)
        } else {
            None
        };
        let interpolation = if self.peek_punct('(')? {
            self.metadata()?.into_iter().find_map(|(k, v)| match v {
                Val::Text(t) if k == "interpolation" => Some(t),
                _ => None,
            })
        } else {
            None
        };
        let (base, samples) = match name.strip_suffix(".timeSamples") {
            Some(base) => (base.to_string(), true),
            None => (name, false),
        };
        let attr = attrs.entry(base.clone()).or_default();
        attr.type_name = type_name;
        if interpolation.is_some() {
            attr.interpolation = interpolation;
        }
        match value {
            Some(Val::Samples(s)) if samples => attr.samples = s,
            Some(_) if samples => bail!("line {line}: {base}.timeSamples is not a dictionary of samples"),
            Some(v) => attr.default = Some(v),
            None => {}
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::io::usd::UsdFile;
    use glam::Vec2;

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

    fn open(text: &str) -> UsdFile {
        let layer = parse_usda(text).unwrap_or_else(|e| panic!("{e:#}"));
        UsdFile::Text { path: "test.usda".into(), layer: layer.into(), lazy: Default::default() }
    }

    /// Written and read back: the time codes, a sample per frame where points move, the
    /// topology written once, UVs per vertex (v up in the file).
    #[test]
    fn a_cache_reads_back_frame_by_frame() {
        let (still, moved) = (mesh(0.0), mesh(-0.125));
        let frames = vec![(3, &still), (4, &still), (5, &moved)];
        let text = usda_text(30.0, &frames).unwrap();
        assert_eq!(text.matches("faceVertexIndices").count(), 1, "constant topology once:\n{text}");
        assert!(text.contains("texCoord2f[] primvars:st = [(0, 1), (1, 1), (0.5, 0.25)]"), "{text}");
        let mut file = open(&text);
        let UsdFile::Text { layer, .. } = &file else { unreachable!() };
        assert_eq!((layer.time_codes_per_second, layer.start, layer.end), (30.0, 3.0, 5.0));
        assert_eq!(file.mesh_names(), ["/werkstatt/mesh"]);
        assert_eq!(file.sample_times(0).unwrap(), [3.0, 4.0, 5.0]);
        for (frame, m) in &frames {
            let s = file.sample(0, *frame as f64).unwrap();
            assert_eq!(s.positions, m.positions);
            assert_eq!(s.face_counts, [3]);
            // Per-vertex UVs and normals: each corner's index is its vertex's.
            assert_eq!(s.corners, [[0, 0, 0], [1, 1, 1], [2, 2, 2]]);
            assert_eq!(s.normals, m.normals);
            assert_eq!(s.uvs, [Vec2::new(0.0, 1.0), Vec2::new(1.0, 1.0), Vec2::new(0.5, 0.25)]);
        }
    }

    /// Quads stay quads, held samples fill the times in between, transforms above the mesh and
    /// a Z-up stage turn the points (Z up becomes Y up), face-varying UVs index by corner.
    #[test]
    fn samples_hold_and_transforms_apply() {
        let text = "#usda 1.0\n(\n    \"a doc string\"\n    timeCodesPerSecond = 24\n    upAxis = \"Z\"\n)\ndef Xform \"root\" (\n    kind = \"component\"\n    customData = { dictionary Blender = { bool generated = 1 } }\n)\n{\n    double3 xformOp:translate = (0, 0, 2)\n    uniform token[] xformOpOrder = [\"xformOp:translate\"]\n    def Mesh \"quad\" {\n        int[] faceVertexCounts = [4]\n        int[] faceVertexIndices = [0, 1, 2, 3]\n        point3f[] points.timeSamples = {\n            1: [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0)],\n            3: [(0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)],\n        }\n        texCoord2f[] primvars:st = [(0, 0), (1, 0), (1, 1), (0, 1)] (\n            interpolation = \"faceVarying\"\n        )\n        int[] primvars:st:indices = [3, 2, 1, 0]\n        float3[] extent = [(0, 0, 0), (1, 1, 1)]\n        rel material:binding = </Looks/a>\n        custom string userProperties:blender:object_name = \"quad\"\n    }\n}\n";
        let mut file = open(text);
        assert_eq!(file.mesh_names(), ["/root/quad"]);
        assert_eq!(file.sample_times(0).unwrap(), [1.0, 3.0]);
        let s = file.sample(0, 2.0).unwrap();
        assert_eq!(s.face_counts, [4]);
        // Held: time 2 shows the sample at 1; z (up) = 2 becomes y = 2.
        assert_eq!(s.positions[2], Vec3::new(1.0, 2.0, -1.0));
        assert_eq!(s.corners.iter().map(|c| c[1]).collect::<Vec<_>>(), [3, 2, 1, 0]);
        assert_eq!(file.sample(0, 3.0).unwrap().positions[2], Vec3::new(1.0, 3.0, -1.0));
    }

    /// A file's long numeric arrays stay in the file until a frame asks for them, and come
    /// back as the text parsed whole gives them; lines after them keep their numbers, and a
    /// damaged array is an error naming its line when its frame is read.
    #[test]
    fn long_arrays_are_read_when_their_frame_is() {
        let grid = |dx: f32| {
            let positions: Vec<Vec3> =
                (0..400).map(|i| Vec3::new((i % 20) as f32 * 0.1 + dx, (i / 20) as f32 * 0.1, 0.0)).collect();
            let indices = (0..19 * 19).flat_map(|q| [q + q / 19, q + q / 19 + 1, q + q / 19 + 20]).collect();
            Mesh::from_raw(positions, vec![Vec3::Z; 400], vec![Vec2::ZERO; 400], Vec::new(), Vec::new(), indices)
        };
        let (a, b) = (grid(0.0), grid(0.5));
        let text = usda_text(24.0, &[(1, &a), (2, &b)]).unwrap();
        let path = std::env::temp_dir().join(format!("werkstatt-lazy-{}.usda", std::process::id()));
        std::fs::write(&path, &text).unwrap();
        let mut lazy = UsdFile::open(&path).unwrap();
        let UsdFile::Text { layer, lazy: spans, .. } = &lazy else { unreachable!() };
        let points = &layer.prims.iter().find(|p| p.type_name == "Mesh").unwrap().attrs["points"];
        assert!(points.samples.iter().all(|s| matches!(s.1, Val::Lazy(_))), "{:?}", points.samples.len());
        assert!(spans.len() >= 5, "points, normals and indices: {spans:?}");
        let mut whole = open(&text);
        for t in [1.0, 2.0] {
            let (l, w) = (lazy.sample(0, t).unwrap(), whole.sample(0, t).unwrap());
            assert_eq!((l.positions, l.normals, l.corners), (w.positions, w.normals, w.corners));
        }
        // An error after the arrays names its own line.
        let broken = text.clone() + "def Mesh \"late\" { int[] x = [1, }\n";
        std::fs::write(&path, &broken).unwrap();
        let e = format!("{:#}", UsdFile::open(&path).map(|_| ()).unwrap_err());
        assert!(e.contains(&format!("line {}", text.lines().count() + 1)), "{e}");
        // A damaged number inside a lazy array: found when its frame is read.
        let at = text.rfind("(0.5").unwrap();
        let mut damaged = text.clone().into_bytes();
        damaged[at + 3] = b'.';
        std::fs::write(&path, &damaged).unwrap();
        let mut file = UsdFile::open(&path).unwrap();
        let e = format!("{:#}", file.sample(0, 2.0).unwrap_err());
        let _ = std::fs::remove_file(&path);
        assert!(e.contains("werkstatt-lazy") && e.contains("line"), "{e}");
    }

    /// Errors name the line.
    #[test]
    fn bad_text_names_the_line() {
        let e = format!(
            "{:#}",
            parse_usda("#usda 1.0\ndef Mesh \"m\" {\n    int[] faceVertexCounts = [4, ]]\n}\n").unwrap_err()
        );
        assert!(e.contains("line 3"), "{e}");
    }
}

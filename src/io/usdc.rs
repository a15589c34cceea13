//! Binary USD ("crate" files: .usdc, and .usd files that start with `PXR-USDC`), read without
//! a USD library, far enough for mesh caches: the structure (tokens, strings, fields, field
//! sets, paths, specs) when the file opens, and each value only when it is asked for, so a
//! frame of a long cache reads that frame's arrays and nothing else.
//!
//! The layout follows Pixar's `crateFile.cpp` (file versions 0.4.0 and later: everything
//! written since 2017): a bootstrap header with the table of contents' offset; sections whose
//! integer arrays are delta-coded (`integerCoding.cpp`) and LZ4-compressed in TfFastCompression
//! chunks; 64-bit value representations (type, array, inlined and compressed bits, and an
//! offset or an inlined value). Every offset, count and index read from the file is checked
//! against the file and the tables before it is used, so a damaged file is an error, never a
//! crash or a huge allocation.

use std::collections::HashMap;
use std::fs::File;
use std::io::{Read, Seek, SeekFrom};
use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail, ensure};

use super::usd::{Attr, Layer, Prim, Value};

/// An open crate file: its tables, and the file to read values from.
pub struct Crate {
    path: PathBuf,
    file: File,
    len: u64,
    version: (u8, u8, u8),
    tokens: Vec<String>,
    strings: Vec<u32>,
    /// (token index of the name, value representation).
    fields: Vec<(u32, u64)>,
    /// Field indices, each set ended by `u32::MAX`.
    fieldsets: Vec<u32>,
    paths: Vec<String>,
    /// (path index, field set index, spec type).
    specs: Vec<[u32; 3]>,
}

// SdfSpecType values.
const SPEC_ATTRIBUTE: u32 = 1;
const SPEC_PRIM: u32 = 6;
const SPEC_PSEUDO_ROOT: u32 = 7;

// Crate value types (crateDataTypes.h).
const T_INT: u64 = 3;
const T_UINT: u64 = 4;
const T_INT64: u64 = 5;
const T_UINT64: u64 = 6;
const T_HALF: u64 = 7;
const T_FLOAT: u64 = 8;
const T_DOUBLE: u64 = 9;
const T_STRING: u64 = 10;
const T_TOKEN: u64 = 11;
const T_MATRIX2D: u64 = 13;
const T_MATRIX4D: u64 = 15;
const T_QUATD: u64 = 16;
const T_QUATH: u64 = 18;
const T_VEC2D: u64 = 19;
const T_VEC4I: u64 = 30;
const T_TOKEN_VECTOR: u64 = 41;
const T_TIME_SAMPLES: u64 = 46;
const T_DOUBLE_VECTOR: u64 = 48;

/// Sections and tables larger than this are taken for damage.
const MAX_ITEMS: u64 = 1 << 32;

impl Crate {
    /// Opens `path` and lists its prims with their attributes (values not read yet). Errors
    /// name the file.
    pub fn open(path: &Path) -> anyhow::Result<(Crate, Layer<u64>)> {
        Self::open_inner(path).with_context(|| format!("cannot read the binary USD file {}", path.display()))
    }

    fn open_inner(path: &Path) -> anyhow::Result<(Crate, Layer<u64>)> {
        let file = File::open(path)?;
        let len = file.metadata()?.len();
        let mut c = Crate {
            path: path.to_path_buf(),
            file,
            len,
            version: (0, 0, 0),
            tokens: Vec::new(),
            strings: Vec::new(),
            fields: Vec::new(),
            fieldsets: Vec::new(),
            paths: Vec::new(),
            specs: Vec::new(),
        };
        let head = c.bytes(0, 24).context("the file is shorter than its header")?;
        ensure!(&head[..8] == b"PXR-USDC", "not a binary USD file (no PXR-USDC header)");
        c.version = (head[8], head[9], head[10]);
        ensure!(
            c.version.0 == 0 && c.version.1 >= 4,
            "file version {}.{}.{} is not read (0.4.0 and later are)",
            c.version.0,
            c.version.1,
            c.version.2
        );
        let mut pos = le_u64(&head[16..24]);
        let count = c.u64(&mut pos).context("the table of contents")?;
        ensure!(count < 64, "the table of contents claims {count} sections");
        let mut sections = HashMap::new();
        for _ in 0..count {
            let b = c.bytes(pos, 32).context("the table of contents")?;
            pos += 32;
            let name = String::from_utf8_lossy(b[..16].split(|&x| x == 0).next().unwrap_or(&[])).into_owned();
            sections.insert(name, le_u64(&b[16..24]));
        }
        let section = |name: &str| sections.get(name).copied().with_context(|| format!("no {name} section"));
        c.read_tokens(section("TOKENS")?).context("the TOKENS section")?;
        if let Ok(start) = section("STRINGS") {
            let mut pos = start;
            let n = c.count(&mut pos, 4).context("the STRINGS section")?;
            c.strings = c.bytes(pos, n * 4)?.chunks_exact(4).map(le_u32).collect();
        }
        c.read_fields(section("FIELDS")?).context("the FIELDS section")?;
        let mut pos = section("FIELDSETS")?;
        let n = c.count(&mut pos, 0).context("the FIELDSETS section")?;
        c.fieldsets =
            c.ints(&mut pos, n, false).context("the FIELDSETS section")?.into_iter().map(|i| i as u32).collect();
        c.read_paths(section("PATHS")?).context("the PATHS section")?;
        c.read_specs(section("SPECS")?).context("the SPECS section")?;
        let mut layer = c.layer()?;
        layer.finish()?;
        Ok((c, layer))
    }

    /// `n` bytes at `pos`, checked against the file's length.
    fn bytes(&mut self, pos: u64, n: u64) -> anyhow::Result<Vec<u8>> {
        ensure!(
            pos <= self.len && n <= self.len - pos,
            "{n} bytes at offset {pos} run past the end of the file ({} bytes)",
            self.len
        );
        self.file.seek(SeekFrom::Start(pos))?;
        let mut b = vec![0; n as usize];
        self.file.read_exact(&mut b)?;
        Ok(b)
    }

    fn u64(&mut self, pos: &mut u64) -> anyhow::Result<u64> {
        let b = self.bytes(*pos, 8)?;
        *pos += 8;
        Ok(le_u64(&b))
    }

    /// A count of items of `size` bytes each (0: compressed) that must fit in the file.
    fn count(&mut self, pos: &mut u64, size: u64) -> anyhow::Result<u64> {
        let n = self.u64(pos)?;
        ensure!(n <= MAX_ITEMS && n.saturating_mul(size) <= self.len, "a count of {n} does not fit in the file");
        Ok(n)
    }

    /// A TfFastCompression block at `pos`: its compressed size, then the chunks; at most `max`
    /// bytes out.
    fn compressed(&mut self, pos: &mut u64, max: u64) -> anyhow::Result<Vec<u8>> {
        let size = self.u64(pos)?;
        let input = self.bytes(*pos, size)?;
        *pos += size;
        fast_decompress(&input, max)
    }

    /// `n` delta-coded integers at `pos` (32- or 64-bit).
    fn ints(&mut self, pos: &mut u64, n: u64, wide: bool) -> anyhow::Result<Vec<i64>> {
        if n == 0 {
            return Ok(Vec::new());
        }
        let w = if wide { 8 } else { 4 };
        let max = w + (n * 2).div_ceil(8) + w * n;
        let buf = self.compressed(pos, max)?;
        decode_ints(&buf, n as usize, wide)
    }

    fn read_tokens(&mut self, mut pos: u64) -> anyhow::Result<()> {
        let n = self.count(&mut pos, 0)?;
        let size = self.count(&mut pos, 0)?;
        let buf = self.compressed(&mut pos, size)?;
        ensure!(buf.len() as u64 == size, "{} bytes of tokens instead of {size}", buf.len());
        if n == 0 {
            return Ok(());
        }
        let text = buf.strip_suffix(&[0]).context("the tokens do not end in a 0 byte")?;
        self.tokens = text.split(|&b| b == 0).map(|t| String::from_utf8_lossy(t).into_owned()).collect();
        ensure!(self.tokens.len() as u64 == n, "{} tokens instead of {n}", self.tokens.len());
        Ok(())
    }

    fn read_fields(&mut self, mut pos: u64) -> anyhow::Result<()> {
        let n = self.count(&mut pos, 0)?;
        let names = self.ints(&mut pos, n, false)?;
        let reps = self.compressed(&mut pos, n * 8)?;
        ensure!(reps.len() as u64 == n * 8, "{} bytes of field values instead of {}", reps.len(), n * 8);
        for (name, rep) in names.into_iter().zip(reps.chunks_exact(8)) {
            let name = u32::try_from(name).ok().filter(|&i| (i as usize) < self.tokens.len());
            self.fields.push((name.context("a field's name is not a token")?, le_u64(rep)));
        }
        Ok(())
    }

    fn read_paths(&mut self, mut pos: u64) -> anyhow::Result<()> {
        let n = self.count(&mut pos, 0)?;
        let encoded = self.count(&mut pos, 0)?;
        ensure!(encoded <= n && n <= self.len, "{encoded} encoded paths for {n} paths");
        let path_index = self.ints(&mut pos, encoded, false)?;
        let element = self.ints(&mut pos, encoded, false)?;
        let jumps = self.ints(&mut pos, encoded, false)?;
        self.paths = vec![String::new(); n as usize];
        if encoded == 0 {
            return Ok(());
        }
        // crateFile.cpp `_BuildDecompressedPathsImpl`: entries in depth-first order; a jump
        // says whether an entry has a child (the next entry) and where its next sibling is.
        let mut pending = vec![(0usize, None::<String>)];
        let mut visited = 0usize;
        while let Some((mut i, mut parent)) = pending.pop() {
            loop {
                visited += 1;
                ensure!(visited <= encoded as usize && i < encoded as usize, "the path tree does not hold together");
                let slot = usize::try_from(path_index[i]).ok().filter(|&s| s < self.paths.len());
                let slot = slot.context("a path index is out of range")?;
                let path = match &parent {
                    None => "/".to_string(),
                    Some(parent) => {
                        let token = element[i].unsigned_abs() as usize;
                        let name = self.tokens.get(token).context("a path element is not a token")?;
                        if element[i] < 0 {
                            format!("{parent}.{name}")
                        } else if parent == "/" {
                            format!("/{name}")
                        } else {
                            format!("{parent}/{name}")
                        }
                    }
                };
                self.paths[slot] = path.clone();
                let (has_child, has_sibling) = (jumps[i] > 0 || jumps[i] == -1, jumps[i] >= 0);
                if has_child {
                    if has_sibling {
                        pending.push((i + jumps[i] as usize, parent.clone()));
                    }
                    parent = Some(path);
                }
                if !has_child && !has_sibling {
                    break;
                }
                i += 1;
            }
        }
        Ok(())
    }

    fn read_specs(&mut self, mut pos: u64) -> anyhow::Result<()> {
        let n = self.count(&mut pos, 0)?;
        let paths = self.ints(&mut pos, n, false)?;
        let sets = self.ints(&mut pos, n, false)?;
        let types = self.ints(&mut pos, n, false)?;
        for ((p, s), t) in paths.into_iter().zip(sets).zip(types) {
            let p =
                u32::try_from(p).ok().filter(|&p| (p as usize) < self.paths.len()).context("a spec's path index")?;
            let s =
                u32::try_from(s).ok().filter(|&s| (s as usize) < self.fieldsets.len()).context("a spec's fields")?;
            self.specs.push([p, s, t as u32]);
        }
        Ok(())
    }

    /// The fields of spec `s`: (name, value representation).
    fn spec_fields(&self, set: u32) -> anyhow::Result<Vec<(&str, u64)>> {
        let mut out = Vec::new();
        for &f in self.fieldsets[set as usize..].iter().take_while(|&&f| f != u32::MAX) {
            let &(name, rep) = self.fields.get(f as usize).context("a field index is out of range")?;
            out.push((self.tokens[name as usize].as_str(), rep));
        }
        Ok(out)
    }

    /// The prims and their attributes; stage metadata from the pseudo-root.
    fn layer(&mut self) -> anyhow::Result<Layer<u64>> {
        let mut layer = Layer::default();
        let mut prims: HashMap<String, usize> = HashMap::new();
        let mut attrs = Vec::new();
        for k in 0..self.specs.len() {
            let [p, set, kind] = self.specs[k];
            let path = self.paths[p as usize].clone();
            let fields: Vec<(String, u64)> =
                self.spec_fields(set)?.into_iter().map(|(n, r)| (n.to_string(), r)).collect();
            match kind {
                SPEC_PSEUDO_ROOT => {
                    for (name, rep) in fields {
                        let number = |c: &mut Crate| -> anyhow::Result<f64> {
                            match c.value(rep)? {
                                Value::Numbers(n) if n.len() == 1 => Ok(n[0]),
                                _ => bail!("{name} is not a number"),
                            }
                        };
                        match name.as_str() {
                            "timeCodesPerSecond" => layer.time_codes_per_second = number(self)?,
                            "startTimeCode" => layer.start = number(self)?,
                            "endTimeCode" => layer.end = number(self)?,
                            "metersPerUnit" => layer.meters_per_unit = number(self)?,
                            "upAxis" => layer.up_axis = self.token_value(rep).context("upAxis")?,
                            _ => {}
                        }
                    }
                }
                SPEC_PRIM => {
                    let type_name = match fields.iter().find(|f| f.0 == "typeName") {
                        Some(&(_, rep)) => self.token_value(rep).with_context(|| format!("the type of {path}"))?,
                        None => String::new(),
                    };
                    prims.insert(path.clone(), layer.prims.len());
                    layer.prims.push(Prim { path, type_name, attrs: HashMap::new() });
                }
                SPEC_ATTRIBUTE => attrs.push((path, fields)),
                _ => {}
            }
        }
        for (path, fields) in attrs {
            let Some((prim, name)) = split_property(&path) else { continue };
            let Some(&p) = prims.get(prim) else { continue };
            let mut attr = Attr::default();
            for (field, rep) in fields {
                match field.as_str() {
                    "default" => attr.default = Some(rep),
                    "timeSamples" => {
                        attr.samples = self.time_samples(rep).with_context(|| format!("the time samples of {path}"))?
                    }
                    "interpolation" => attr.interpolation = Some(self.token_value(rep)?),
                    "typeName" => attr.type_name = self.token_value(rep)?,
                    _ => {}
                }
            }
            layer.prims[p].attrs.insert(name.to_string(), attr);
        }
        Ok(layer)
    }

    fn token_value(&mut self, rep: u64) -> anyhow::Result<String> {
        match self.value(rep)? {
            Value::Tokens(t) if t.len() == 1 => Ok(t.into_iter().next().unwrap_or_default()),
            _ => bail!("not a token"),
        }
    }

    /// A time-sampled value: each time and its value's representation (values are read later).
    fn time_samples(&mut self, rep: u64) -> anyhow::Result<Vec<(f64, u64)>> {
        ensure!(ty(rep) == T_TIME_SAMPLES && !inlined(rep), "not time samples");
        // Two relative offsets: to the times' representation, then to the values'.
        let mut pos = payload(rep);
        let jump = |c: &mut Crate, pos: &mut u64| -> anyhow::Result<()> {
            let at = *pos;
            let offset = c.u64(pos)? as i64;
            *pos = at.checked_add_signed(offset).filter(|&p| p <= c.len).context("an offset leaves the file")?;
            Ok(())
        };
        jump(self, &mut pos)?;
        let times_rep = self.u64(&mut pos)?;
        let Value::Numbers(times) = self.value(times_rep)? else { bail!("the sample times are not numbers") };
        jump(self, &mut pos)?;
        let n = self.count(&mut pos, 8)?;
        ensure!(n == times.len() as u64, "{} sample times but {n} values", times.len());
        let reps = self.bytes(pos, n * 8)?;
        Ok(times.into_iter().zip(reps.chunks_exact(8).map(le_u64)).collect())
    }

    /// An array's element count at its offset (empty at offset 0); `pos` moves past it.
    fn array_len(&mut self, rep: u64, pos: &mut u64) -> anyhow::Result<u64> {
        *pos = payload(rep);
        if *pos == 0 {
            return Ok(0);
        }
        if self.version < (0, 5, 0) {
            *pos += 4;
        }
        let n = if self.version < (0, 7, 0) {
            let b = self.bytes(*pos, 4)?;
            *pos += 4;
            le_u32(&b) as u64
        } else {
            self.u64(pos)?
        };
        ensure!(n <= MAX_ITEMS, "an array claims {n} elements");
        Ok(n)
    }

    /// Reads the value a field or time sample holds. Errors name the file.
    pub fn value(&mut self, rep: u64) -> anyhow::Result<Value> {
        self.value_inner(rep).with_context(|| format!("cannot read a value of {}", self.path.display()))
    }

    fn value_inner(&mut self, rep: u64) -> anyhow::Result<Value> {
        let (t, array) = (ty(rep), rep >> 63 != 0);
        let compressed = rep & (1 << 61) != 0;
        let low = payload(rep) as u32;
        Ok(match t {
            T_TOKEN if !array => Value::Tokens(vec![self.token(low)?]),
            T_TOKEN | T_TOKEN_VECTOR => {
                let mut pos = payload(rep);
                let n = if t == T_TOKEN { self.array_len(rep, &mut pos)? } else { self.count(&mut pos, 4)? };
                let b = self.bytes(pos, n * 4)?;
                Value::Tokens(b.chunks_exact(4).map(|i| self.token(le_u32(i))).collect::<anyhow::Result<_>>()?)
            }
            T_STRING if !array => {
                let token = *self.strings.get(low as usize).context("a string index is out of range")?;
                Value::Tokens(vec![self.token(token)?])
            }
            T_INT..=T_UINT64 if array => {
                let mut pos = 0;
                let n = self.array_len(rep, &mut pos)?;
                let wide = t >= T_INT64;
                if compressed && self.version >= (0, 5, 0) && n >= 4 {
                    let ints = self.ints(&mut pos, n, wide)?;
                    ensure!(ints.len() as u64 == n, "{} integers instead of {n}", ints.len());
                    Value::Numbers(
                        ints.into_iter().map(|i| if t == T_UINT64 { i as u64 as f64 } else { i as f64 }).collect(),
                    )
                } else {
                    let size = if wide { 8 } else { 4 };
                    let b = self.bytes(pos, n * size)?;
                    Value::Numbers(b.chunks_exact(size as usize).map(|c| scalar(t, c)).collect())
                }
            }
            T_INT | T_UINT | T_FLOAT | T_HALF if inlined(rep) => Value::Numbers(vec![scalar(t, &low.to_le_bytes())]),
            T_DOUBLE if inlined(rep) => Value::Numbers(vec![f32::from_bits(low) as f64]),
            T_INT64 | T_UINT64 | T_DOUBLE if !array => Value::Numbers(vec![scalar(t, &self.bytes(payload(rep), 8)?)]),
            T_HALF | T_FLOAT | T_DOUBLE | T_DOUBLE_VECTOR => {
                let mut pos = payload(rep);
                // A std::vector<double> (time sample times) has a plain 64-bit count.
                let n = if t == T_DOUBLE_VECTOR { self.count(&mut pos, 8)? } else { self.array_len(rep, &mut pos)? };
                let t = if t == T_DOUBLE_VECTOR { T_DOUBLE } else { t };
                let size = element_size(t);
                if compressed && self.version >= (0, 6, 0) && n >= 4 {
                    let code = self.bytes(pos, 1)?[0];
                    pos += 1;
                    match code {
                        b'i' => Value::Numbers(self.ints(&mut pos, n, false)?.into_iter().map(|i| i as f64).collect()),
                        b't' => {
                            let b = self.bytes(pos, 4)?;
                            pos += 4;
                            let lut_len = le_u32(&b) as u64;
                            let lut: Vec<f64> = self
                                .bytes(pos, lut_len * size)?
                                .chunks_exact(size as usize)
                                .map(|c| scalar(t, c))
                                .collect();
                            pos += lut_len * size;
                            let ix = self.ints(&mut pos, n, false)?;
                            let at = |i: i64| usize::try_from(i).ok().and_then(|i| lut.get(i).copied());
                            Value::Numbers(
                                ix.into_iter()
                                    .map(at)
                                    .collect::<Option<_>>()
                                    .context("a table index is out of range")?,
                            )
                        }
                        _ => bail!("unknown float array coding {code}"),
                    }
                } else {
                    let b = self.bytes(pos, n * size)?;
                    Value::Numbers(b.chunks_exact(size as usize).map(|c| scalar(t, c)).collect())
                }
            }
            T_MATRIX2D..=T_VEC4I => {
                let (width, element) = shape(t);
                let size = element_size(element);
                let numbers = if array {
                    let mut pos = 0;
                    let n = self.array_len(rep, &mut pos)?;
                    let b = self.bytes(pos, n.saturating_mul(width * size))?;
                    b.chunks_exact(size as usize).map(|c| scalar(element, c)).collect()
                } else if inlined(rep) {
                    // Small integral values inline as signed bytes: a vector's components, or
                    // a matrix's diagonal.
                    let b = low.to_le_bytes().map(|x| x as i8 as f64);
                    if t <= T_MATRIX4D {
                        let side = (width as f64).sqrt() as usize;
                        (0..width as usize).map(|k| if k % (side + 1) == 0 { b[k / (side + 1)] } else { 0.0 }).collect()
                    } else {
                        b[..width as usize].to_vec()
                    }
                } else {
                    let b = self.bytes(payload(rep), width * size)?;
                    b.chunks_exact(size as usize).map(|c| scalar(element, c)).collect::<Vec<f64>>()
                };
                if (T_QUATD..=T_QUATH).contains(&t) {
                    // Stored as x, y, z, w; quaternions read as w, x, y, z (as USD text writes them).
                    Value::Numbers(numbers.chunks_exact(4).flat_map(|q| [q[3], q[0], q[1], q[2]]).collect())
                } else {
                    Value::Numbers(numbers)
                }
            }
            _ => bail!("values of crate type {t}{} are not read", if array { " (array)" } else { "" }),
        })
    }

    fn token(&self, i: u32) -> anyhow::Result<String> {
        self.tokens.get(i as usize).cloned().context("a token index is out of range")
    }
}

fn ty(rep: u64) -> u64 {
    (rep >> 48) & 0xff
}

fn inlined(rep: u64) -> bool {
    rep & (1 << 62) != 0
}

fn payload(rep: u64) -> u64 {
    rep & ((1 << 48) - 1)
}

fn le_u64(b: &[u8]) -> u64 {
    u64::from_le_bytes(std::array::from_fn(|i| b[i]))
}

fn le_u32(b: &[u8]) -> u32 {
    u32::from_le_bytes(std::array::from_fn(|i| b[i]))
}

/// Bytes per element of a scalar type.
fn element_size(t: u64) -> u64 {
    match t {
        T_HALF => 2,
        T_INT | T_UINT | T_FLOAT => 4,
        _ => 8,
    }
}

/// Components and their scalar type of a matrix, quaternion or vector type.
fn shape(t: u64) -> (u64, u64) {
    match t {
        13 => (4, T_DOUBLE),
        14 => (9, T_DOUBLE),
        15 => (16, T_DOUBLE),
        16 => (4, T_DOUBLE),
        17 => (4, T_FLOAT),
        18 => (4, T_HALF),
        _ => {
            // Vec2d, Vec2f, Vec2h, Vec2i, Vec3d, ...: four scalar types per size.
            let k = t - T_VEC2D;
            (2 + k / 4, [T_DOUBLE, T_FLOAT, T_HALF, T_INT][(k % 4) as usize])
        }
    }
}

/// One little-endian scalar of type `t` as a number.
fn scalar(t: u64, b: &[u8]) -> f64 {
    match t {
        T_INT => le_u32(b) as i32 as f64,
        T_UINT => le_u32(b) as f64,
        T_INT64 => le_u64(b) as i64 as f64,
        T_UINT64 => le_u64(b) as f64,
        T_HALF => half::f16::from_bits(u16::from_le_bytes([b[0], b[1]])).to_f64(),
        T_FLOAT => f32::from_bits(le_u32(b)) as f64,
        _ => f64::from_bits(le_u64(b)),
    }
}

/// The property part of a property path: `/a/b.points` is (`/a/b`, `points`).
fn split_property(path: &str) -> Option<(&str, &str)> {
    let slash = path.rfind('/')?;
    let dot = slash + path[slash..].find('.')?;
    Some((&path[..dot], &path[dot + 1..]))
}

/// TfFastCompression: a chunk count byte; 0 is one LZ4 block, else each chunk is its size
/// (i32) and an LZ4 block. At most `max` bytes out.
fn fast_decompress(input: &[u8], max: u64) -> anyhow::Result<Vec<u8>> {
    let (&chunks, mut rest) = input.split_first().context("an empty compressed block")?;
    let mut out = Vec::new();
    if chunks == 0 {
        lz4_block(rest, &mut out, max)?;
        return Ok(out);
    }
    for _ in 0..chunks {
        ensure!(rest.len() >= 4, "a compressed chunk is cut short");
        let size = le_u32(rest) as i32;
        let size = usize::try_from(size).ok().filter(|&s| s <= rest.len() - 4).context("a compressed chunk's size")?;
        lz4_block(&rest[4..4 + size], &mut out, max)?;
        rest = &rest[4 + size..];
    }
    Ok(out)
}

/// Appends an LZ4 block's output to `out`, refusing to grow it past `max` bytes.
fn lz4_block(src: &[u8], out: &mut Vec<u8>, max: u64) -> anyhow::Result<()> {
    let start = out.len();
    let mut i = 0;
    let length = |i: &mut usize, mut n: usize| -> anyhow::Result<usize> {
        if n == 15 {
            loop {
                let b = *src.get(*i).context("an LZ4 length is cut short")?;
                *i += 1;
                n += b as usize;
                if b != 255 {
                    break;
                }
            }
        }
        Ok(n)
    };
    loop {
        let token = *src.get(i).context("an LZ4 block is cut short")?;
        i += 1;
        let literals = length(&mut i, (token >> 4) as usize)?;
        let end = i.checked_add(literals).filter(|&e| e <= src.len()).context("LZ4 literals run past the block")?;
        ensure!(
            (out.len() - start + literals) as u64 <= max,
            "the data decompresses to more than the {max} bytes expected"
        );
        out.extend_from_slice(&src[i..end]);
        i = end;
        if i == src.len() {
            return Ok(());
        }
        let b = src.get(i..i + 2).context("an LZ4 match is cut short")?;
        let offset = u16::from_le_bytes([b[0], b[1]]) as usize;
        i += 2;
        ensure!(offset != 0 && offset <= out.len() - start, "an LZ4 match points before the data");
        let matched = length(&mut i, (token & 15) as usize)? + 4;
        ensure!(
            (out.len() - start + matched) as u64 <= max,
            "the data decompresses to more than the {max} bytes expected"
        );
        let from = out.len() - offset;
        for k in 0..matched {
            out.push(out[from + k]);
        }
    }
}

/// Usd_IntegerCompression's decoding: a common delta, 2-bit codes (common, small, medium,
/// large) four to a byte, then the other deltas at their widths; each value is the running sum.
fn decode_ints(data: &[u8], n: usize, wide: bool) -> anyhow::Result<Vec<i64>> {
    let w = if wide { 8 } else { 4 };
    let code_bytes = (n * 2).div_ceil(8);
    ensure!(data.len() >= w + code_bytes, "coded integers are cut short");
    let signed = |b: &[u8]| -> i64 {
        match b.len() {
            1 => b[0] as i8 as i64,
            2 => i16::from_le_bytes([b[0], b[1]]) as i64,
            4 => le_u32(b) as i32 as i64,
            _ => le_u64(b) as i64,
        }
    };
    let common = signed(&data[..w]);
    let codes = &data[w..w + code_bytes];
    let mut at = w + code_bytes;
    let (mut value, mut out) = (0i64, Vec::with_capacity(n));
    for k in 0..n {
        let size = match ((codes[k / 4] >> (2 * (k % 4))) & 3, wide) {
            (0, _) => 0,
            (1, false) => 1,
            (1, true) | (2, false) => 2,
            (2, true) | (3, false) => 4,
            _ => 8,
        };
        let delta = if size == 0 {
            common
        } else {
            let b = data.get(at..at + size).context("coded integers are cut short")?;
            at += size;
            signed(b)
        };
        value = value.wrapping_add(delta);
        out.push(value);
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A literal run, then a match that overlaps its own output (run-length style).
    #[test]
    fn lz4_blocks_decode_and_refuse_damage() {
        let block = [0x32, b'a', b'b', b'c', 2, 0, 0x10, b'!'];
        let mut out = Vec::new();
        lz4_block(&block, &mut out, 100).unwrap();
        assert_eq!(out, b"abcbcbcbc!");
        assert!(lz4_block(&block, &mut Vec::new(), 5).is_err(), "more than the expected size");
        assert!(lz4_block(&block[..5], &mut Vec::new(), 100).is_err(), "cut short");
        assert!(lz4_block(&[0x02, 9, 0], &mut Vec::new(), 100).is_err(), "a match before the data");
    }

    /// Common deltas, small and large ones, and a running sum.
    #[test]
    fn coded_integers_are_running_sums_of_deltas() {
        // common 1; codes: common, small (-3), large (1000), common.
        let mut data = 1i32.to_le_bytes().to_vec();
        data.push(0b00_11_01_00);
        data.push(-3i8 as u8);
        data.extend(1000i32.to_le_bytes());
        assert_eq!(decode_ints(&data, 4, false).unwrap(), [1, -2, 998, 999]);
        assert!(decode_ints(&data[..6], 4, false).is_err());
    }

    #[test]
    fn property_paths_split_at_the_last_prims_dot() {
        assert_eq!(split_property("/root/Grid.primvars:st"), Some(("/root/Grid", "primvars:st")));
        assert_eq!(split_property("/root/Grid"), None);
    }
}

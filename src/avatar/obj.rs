//! A small OBJ reader that keeps what MakeHuman's files mean and `tobj` would lose: the file's
//! own vertex numbering (weights, joints and `.mhclo` proxies refer to it), the group of every
//! face (helper geometry is marked by groups) and polygons as written.

use std::path::Path;

use anyhow::{Context as _, bail};
use glam::{Vec2, Vec3};

/// One polygon: vertex and texture-coordinate indices (0-based), and its group.
#[derive(Clone, Debug)]
pub struct Face {
    pub v: Vec<u32>,
    pub vt: Vec<u32>,
    pub group: u32,
}

/// An OBJ file in its own numbering.
#[derive(Clone, Debug, Default)]
pub struct Obj {
    pub positions: Vec<Vec3>,
    /// Texture coordinates as written (v up).
    pub uvs: Vec<Vec2>,
    pub faces: Vec<Face>,
    /// Group names; `Face::group` indexes this (index 0 is the unnamed group).
    pub groups: Vec<String>,
}

/// Whether a group of the MakeHuman base mesh is helper geometry: the proxy garments
/// (`helper-tights`, `helper-skirt`, ...) and the joint cubes (`joint-*`) that MakeHuman uses
/// to fit clothes and place joints, never drawn.
pub fn is_helper_group(name: &str) -> bool {
    name.starts_with("helper-") || name.starts_with("joint-")
}

impl Obj {
    pub fn load(path: &Path) -> anyhow::Result<Obj> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        Obj::parse(&text).with_context(|| format!("in {}", path.display()))
    }

    pub fn parse(text: &str) -> anyhow::Result<Obj> {
        let mut obj = Obj { groups: vec![String::new()], ..Default::default() };
        let mut group = 0u32;
        for (i, line) in text.lines().enumerate() {
            let line_no = i + 1;
            let mut words = line.split_whitespace();
            let Some(key) = words.next() else { continue };
            let floats = |words: std::str::SplitWhitespace<'_>, n: usize| -> anyhow::Result<Vec<f32>> {
                let v: Vec<f32> = words
                    .take(n)
                    .map(|w| w.parse::<f32>())
                    .collect::<Result<_, _>>()
                    .with_context(|| format!("line {line_no}: a number is malformed"))?;
                if v.len() < n {
                    bail!("line {line_no}: expected {n} numbers after {key:?}");
                }
                Ok(v)
            };
            match key {
                "v" => {
                    let v = floats(words, 3)?;
                    obj.positions.push(Vec3::new(v[0], v[1], v[2]));
                }
                "vt" => {
                    let v = floats(words, 2)?;
                    obj.uvs.push(Vec2::new(v[0], v[1]));
                }
                "g" | "o" => {
                    let name = words.collect::<Vec<_>>().join(" ");
                    group = match obj.groups.iter().position(|g| *g == name) {
                        Some(i) => i as u32,
                        None => {
                            obj.groups.push(name);
                            obj.groups.len() as u32 - 1
                        }
                    };
                }
                "f" => {
                    let mut face = Face { v: Vec::new(), vt: Vec::new(), group };
                    for w in words {
                        let mut parts = w.split('/');
                        let index = |s: Option<&str>, count: usize| -> anyhow::Result<Option<u32>> {
                            let Some(s) = s.filter(|s| !s.is_empty()) else { return Ok(None) };
                            let i: i64 = s.parse().with_context(|| format!("line {line_no}: bad index {s:?}"))?;
                            let i = if i < 0 { count as i64 + i } else { i - 1 };
                            if i < 0 || i as usize >= count {
                                bail!("line {line_no}: index {s} is out of range ({count} defined so far)");
                            }
                            Ok(Some(i as u32))
                        };
                        let v = index(parts.next(), obj.positions.len())?
                            .with_context(|| format!("line {line_no}: a face corner has no vertex"))?;
                        face.v.push(v);
                        if let Some(t) = index(parts.next(), obj.uvs.len())? {
                            face.vt.push(t);
                        }
                    }
                    if face.v.len() < 3 {
                        bail!("line {line_no}: a face needs at least 3 corners");
                    }
                    if !face.vt.is_empty() && face.vt.len() != face.v.len() {
                        bail!("line {line_no}: some corners of the face have texture coordinates, some not");
                    }
                    obj.faces.push(face);
                }
                _ => {}
            }
        }
        if obj.positions.is_empty() {
            bail!("no vertices");
        }
        Ok(obj)
    }
}

/// The drawable part of an OBJ as a triangle mesh whose vertices are split where texture
/// coordinates differ (a Surface needs one UV per vertex), remembering for each mesh vertex
/// which file vertex it is; and the same triangles in the file's own numbering (welded).
#[derive(Clone, Debug, Default)]
pub struct SplitMesh {
    /// File vertex of each mesh vertex.
    pub source: Vec<u32>,
    /// UV of each mesh vertex, v down.
    pub uvs: Vec<Vec2>,
    /// Triangles in mesh numbering.
    pub indices: Vec<u32>,
    /// The same triangles in file numbering.
    pub welded: Vec<u32>,
}

impl SplitMesh {
    /// The faces `keep` accepts, fan-triangulated; faces without texture coordinates get UV (0, 0).
    pub fn new(obj: &Obj, keep: impl Fn(&Face) -> bool) -> SplitMesh {
        let mut out = SplitMesh::default();
        let mut seen = std::collections::HashMap::<(u32, u32), u32>::new();
        for face in obj.faces.iter().filter(|f| keep(f)) {
            let corners: Vec<u32> = (0..face.v.len())
                .map(|c| {
                    let vt = face.vt.get(c).copied().unwrap_or(u32::MAX);
                    *seen.entry((face.v[c], vt)).or_insert_with(|| {
                        out.source.push(face.v[c]);
                        let uv = obj.uvs.get(vt as usize).copied().unwrap_or(Vec2::ZERO);
                        out.uvs.push(Vec2::new(uv.x, 1.0 - uv.y));
                        out.source.len() as u32 - 1
                    })
                })
                .collect();
            for k in 1..corners.len() - 1 {
                out.indices.extend_from_slice(&[corners[0], corners[k], corners[k + 1]]);
                out.welded.extend_from_slice(&[face.v[0], face.v[k], face.v[k + 1]]);
            }
        }
        out
    }
}

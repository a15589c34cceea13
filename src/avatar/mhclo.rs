//! MakeHuman `.mhclo` proxies: a garment mesh whose every vertex is bound to the base mesh,
//! either to one vertex or to three with weights and an offset.
//!
//! On the base mesh B the fit is p = Σ w_i B[v_i] + S d, with S = diag(|B[v1]_a - B[v2]_a| /
//! d_a) per axis a from the `x_scale`/`y_scale`/`z_scale` lines. On a posed body P the offset
//! turns with the reference triangle: p = Σ w_i P[v_i] + R S d, where R is the rotation taking
//! the rest triangle (B[v_1], B[v_2], B[v_3]) to the posed one, and S is measured on the rest
//! body (a pose bends the body, it does not change its proportions). At rest R is the identity
//! and the fit is the formula exactly.

use std::path::{Path, PathBuf};

use anyhow::{Context as _, bail};
use glam::{DMat3, DVec3, Vec3};

#[derive(Clone, Debug, PartialEq)]
pub enum Binding {
    /// The clothes vertex is this body vertex.
    Exact(u32),
    Weighted {
        v: [u32; 3],
        w: [f32; 3],
        d: Vec3,
    },
}

#[derive(Clone, Debug)]
pub struct Proxy {
    pub name: String,
    /// The garment's OBJ, resolved against the `.mhclo`'s folder.
    pub obj_file: Option<PathBuf>,
    /// Per axis x, y, z: two body vertices and the distance they had when the proxy was made.
    pub scale: [Option<(u32, u32, f32)>; 3],
    pub bindings: Vec<Binding>,
    /// Body vertices the garment hides.
    pub delete_verts: Vec<u32>,
}

impl Proxy {
    pub fn load(path: &Path) -> anyhow::Result<Proxy> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        let mut p = Proxy::parse(&text, &path.display().to_string())?;
        if let Some(obj) = &p.obj_file {
            p.obj_file = Some(path.parent().unwrap_or(Path::new(".")).join(obj));
        }
        Ok(p)
    }

    /// Parses a `.mhclo` (the format of mpfb2's docs/fileformats/mhclo.md); errors name `file` and the line.
    pub fn parse(text: &str, file: &str) -> anyhow::Result<Proxy> {
        #[derive(PartialEq)]
        enum Section {
            Header,
            Verts,
            Delete,
        }
        let mut p = Proxy {
            name: String::new(),
            obj_file: None,
            scale: [None; 3],
            bindings: Vec::new(),
            delete_verts: Vec::new(),
        };
        let mut section = Section::Header;
        for (i, line) in text.lines().enumerate() {
            let n = i + 1;
            let words: Vec<&str> = line.split_whitespace().collect();
            let Some(&first) = words.first() else {
                section = Section::Header;
                continue;
            };
            if first.starts_with('#') || first == "material" || first.starts_with("vertexboneweights") {
                continue;
            }
            let numeric = first.parse::<f64>().is_ok();
            match section {
                Section::Verts if numeric => {
                    let int = |k: usize| -> anyhow::Result<u32> {
                        words[k].parse().with_context(|| format!("{file}:{n}: {:?} is not a vertex index", words[k]))
                    };
                    let float = |k: usize| -> anyhow::Result<f32> {
                        words[k].parse().with_context(|| format!("{file}:{n}: {:?} is not a number", words[k]))
                    };
                    match words.len() {
                        1 => p.bindings.push(Binding::Exact(int(0)?)),
                        9.. => p.bindings.push(Binding::Weighted {
                            v: [int(0)?, int(1)?, int(2)?],
                            w: [float(3)?, float(4)?, float(5)?],
                            d: Vec3::new(float(6)?, float(7)?, float(8)?),
                        }),
                        k => bail!(
                            "{file}:{n}: a vertex line has {k} fields (1, or 3 vertices, 3 weights and an offset)"
                        ),
                    }
                    continue;
                }
                Section::Delete if numeric => {
                    let mut k = 0;
                    while k < words.len() {
                        let a: u32 = words[k]
                            .parse()
                            .with_context(|| format!("{file}:{n}: {:?} is not a vertex index", words[k]))?;
                        if words.get(k + 1) == Some(&"-") {
                            let b: u32 = words
                                .get(k + 2)
                                .and_then(|w| w.parse().ok())
                                .with_context(|| format!("{file}:{n}: a range after {a} - has no end"))?;
                            p.delete_verts.extend(a..=b);
                            k += 3;
                        } else {
                            p.delete_verts.push(a);
                            k += 1;
                        }
                    }
                    continue;
                }
                Section::Verts | Section::Delete => {
                    // A non-numeric line ends the section and is discarded (the format's rule).
                    section = Section::Header;
                    continue;
                }
                Section::Header => {}
            }
            match first {
                "name" => p.name = words.get(1).unwrap_or(&"").to_string(),
                "obj_file" => p.obj_file = words.get(1).map(PathBuf::from),
                "x_scale" | "y_scale" | "z_scale" => {
                    let axis = (first.as_bytes()[0] - b'x') as usize;
                    let parse = || -> Option<(u32, u32, f32)> {
                        Some((words.get(1)?.parse().ok()?, words.get(2)?.parse().ok()?, words.get(3)?.parse().ok()?))
                    };
                    let s = parse()
                        .with_context(|| format!("{file}:{n}: expected {first} <vertex> <vertex> <distance>"))?;
                    if s.2 <= 0.0 {
                        bail!("{file}:{n}: {first} distance {} is not positive", s.2);
                    }
                    p.scale[axis] = Some(s);
                }
                "verts" if words.len() > 1 => section = Section::Verts,
                "delete_verts" => section = Section::Delete,
                _ => {}
            }
        }
        if p.bindings.is_empty() {
            bail!("{file}: no vertex bindings (a \"verts 0\" section)");
        }
        Ok(p)
    }

    /// The largest body vertex index the proxy refers to.
    pub fn max_vertex(&self) -> u32 {
        let scale = self.scale.iter().flatten().flat_map(|s| [s.0, s.1]);
        let binds = self.bindings.iter().flat_map(|b| match b {
            Binding::Exact(v) => vec![*v],
            Binding::Weighted { v, .. } => v.to_vec(),
        });
        scale.chain(binds).chain(self.delete_verts.iter().copied()).max().unwrap_or(0)
    }

    /// S per axis on body `rest` (1 where a scale line is missing).
    pub fn scale_on(&self, rest: &[Vec3]) -> Vec3 {
        let mut s = Vec3::ONE;
        for (a, line) in self.scale.iter().enumerate() {
            if let Some((v1, v2, d)) = line {
                s[a] = (rest[*v1 as usize][a] - rest[*v2 as usize][a]).abs() / d;
            }
        }
        s
    }

    /// Checks that the proxy fits a body of `n` vertices.
    pub fn check(&self, n: usize, file: &str) -> anyhow::Result<()> {
        let m = self.max_vertex() as usize;
        if m >= n {
            bail!(
                "{file} refers to body vertex {m}, but the body has {n} vertices (use the full base mesh with its helpers)"
            );
        }
        Ok(())
    }

    /// The formula on the rest body: p = Σ w_i B[v_i] + S d.
    pub fn fit_rest(&self, rest: &[Vec3]) -> Vec<Vec3> {
        self.fit(rest, rest)
    }

    /// The proxy on `posed` (the body `rest` after skinning, same numbering).
    pub fn fit(&self, rest: &[Vec3], posed: &[Vec3]) -> Vec<Vec3> {
        let s = self.scale_on(rest).as_dvec3();
        self.bindings
            .iter()
            .map(|b| match b {
                Binding::Exact(v) => posed[*v as usize],
                Binding::Weighted { v, w, d } => {
                    let r = v.map(|i| rest[i as usize]);
                    let q = v.map(|i| posed[i as usize]);
                    let mut p = DVec3::ZERO;
                    for k in 0..3 {
                        p += w[k] as f64 * q[k].as_dvec3();
                    }
                    let offset = s * d.as_dvec3();
                    let offset = if r == q { offset } else { triangle_rotation(r, q) * offset };
                    (p + offset).as_vec3()
                }
            })
            .collect()
    }
}

/// An orthonormal frame of a triangle (edge a->b, normal, their cross), if it has an area.
fn frame(t: [Vec3; 3]) -> Option<DMat3> {
    let [a, b, c] = t.map(|p| p.as_dvec3());
    let e1 = (b - a).try_normalize()?;
    let n = e1.cross(c - a).try_normalize()?;
    Some(DMat3::from_cols(e1, n, e1.cross(n)))
}

/// The rotation taking triangle `from` to triangle `to` (identity for a degenerate one).
pub fn triangle_rotation(from: [Vec3; 3], to: [Vec3; 3]) -> DMat3 {
    match (frame(from), frame(to)) {
        (Some(f), Some(t)) => t * f.transpose(),
        _ => DMat3::IDENTITY,
    }
}

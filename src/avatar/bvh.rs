//! BVH motion files: a joint hierarchy (offsets, channels) and frames of channel values.
//!
//! A joint's rotation channels compose in the order they are listed (`Zrotation Xrotation
//! Yrotation` is Rz Rx Ry), in degrees, about axes parallel to the file's world axes at rest;
//! a joint's world transform is its parent's, then a translation by its offset (plus its
//! position channels, if any), then its rotation.

use anyhow::{Context as _, bail};
use glam::{DQuat, DVec3};

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Channel {
    Xposition,
    Yposition,
    Zposition,
    Xrotation,
    Yrotation,
    Zrotation,
}

#[derive(Clone, Debug)]
pub struct Joint {
    pub name: String,
    pub parent: Option<usize>,
    pub offset: DVec3,
    pub channels: Vec<Channel>,
    /// Index of this joint's first channel in a frame.
    pub first_channel: usize,
    /// The end site's offset, if the joint has one.
    pub end: Option<DVec3>,
}

#[derive(Clone, Debug)]
pub struct Bvh {
    /// Parents before children, in file order.
    pub joints: Vec<Joint>,
    pub frame_time: f64,
    /// Channel values, one row per frame.
    pub frames: Vec<Vec<f64>>,
}

struct Tokens<'a> {
    words: Vec<(usize, &'a str)>,
    at: usize,
    file: &'a str,
}

impl<'a> Tokens<'a> {
    fn line(&self) -> usize {
        self.words.get(self.at).or(self.words.last()).map_or(1, |w| w.0)
    }
    fn next(&mut self, what: &str) -> anyhow::Result<&'a str> {
        let w = self
            .words
            .get(self.at)
            .with_context(|| format!("{}: the file ends where {what} was expected", self.file))?;
        self.at += 1;
        Ok(w.1)
    }
    fn expect(&mut self, word: &str) -> anyhow::Result<()> {
        let line = self.line();
        let got = self.next(&format!("{word:?}"))?;
        if !got.eq_ignore_ascii_case(word) {
            bail!("{}:{line}: expected {word:?}, found {got:?}", self.file);
        }
        Ok(())
    }
    fn number(&mut self, what: &str) -> anyhow::Result<f64> {
        let line = self.line();
        let w = self.next(what)?;
        w.parse::<f64>()
            .ok()
            .filter(|v| v.is_finite())
            .with_context(|| format!("{}:{line}: {what}: {w:?} is not a number", self.file))
    }
}

impl Bvh {
    pub fn load(path: &std::path::Path) -> anyhow::Result<Bvh> {
        let text = std::fs::read_to_string(path).with_context(|| format!("cannot read {}", path.display()))?;
        Bvh::parse(&text, &path.display().to_string())
    }

    /// Parses BVH text; errors name `file` and the line.
    pub fn parse(text: &str, file: &str) -> anyhow::Result<Bvh> {
        let words: Vec<(usize, &str)> =
            text.lines().enumerate().flat_map(|(i, l)| l.split_whitespace().map(move |w| (i + 1, w))).collect();
        let mut t = Tokens { words, at: 0, file };
        t.expect("HIERARCHY")?;
        let mut joints: Vec<Joint> = Vec::new();
        let mut stack: Vec<usize> = Vec::new();
        let mut channels = 0usize;
        let line = t.line();
        let root = t.next("ROOT")?;
        if !root.eq_ignore_ascii_case("ROOT") {
            bail!("{file}:{line}: expected ROOT, found {root:?}");
        }
        loop {
            // After a ROOT or JOINT keyword: name { OFFSET x y z CHANNELS n ... children }
            let line = t.line();
            let name = t.next("a joint name")?.to_string();
            if joints.iter().any(|j| j.name == name) {
                bail!("{file}:{line}: joint {name:?} is defined twice");
            }
            t.expect("{")?;
            t.expect("OFFSET")?;
            let offset = DVec3::new(t.number("OFFSET x")?, t.number("OFFSET y")?, t.number("OFFSET z")?);
            t.expect("CHANNELS")?;
            let line = t.line();
            let n = t.number("the channel count")?;
            if !(0.0..=6.0).contains(&n) || n.fract() != 0.0 {
                bail!("{file}:{line}: joint {name:?} has {n} channels (0 to 6 allowed)");
            }
            let mut list = Vec::new();
            for _ in 0..n as usize {
                let line = t.line();
                let c = t.next("a channel name")?;
                list.push(match c.to_ascii_lowercase().as_str() {
                    "xposition" => Channel::Xposition,
                    "yposition" => Channel::Yposition,
                    "zposition" => Channel::Zposition,
                    "xrotation" => Channel::Xrotation,
                    "yrotation" => Channel::Yrotation,
                    "zrotation" => Channel::Zrotation,
                    _ => bail!("{file}:{line}: joint {name:?}: unknown channel {c:?}"),
                });
            }
            joints.push(Joint {
                name,
                parent: stack.last().copied(),
                offset,
                channels: list,
                first_channel: channels,
                end: None,
            });
            channels += n as usize;
            stack.push(joints.len() - 1);
            // Children, end sites and closing braces until the next joint or the end of the hierarchy.
            loop {
                let line = t.line();
                let w = t.next("JOINT, End Site or }")?;
                if w.eq_ignore_ascii_case("JOINT") {
                    break;
                } else if w.eq_ignore_ascii_case("End") {
                    t.expect("Site")?;
                    t.expect("{")?;
                    t.expect("OFFSET")?;
                    let end = DVec3::new(t.number("OFFSET x")?, t.number("OFFSET y")?, t.number("OFFSET z")?);
                    t.expect("}")?;
                    let j = *stack.last().with_context(|| format!("{file}:{line}: End Site outside a joint"))?;
                    joints[j].end = Some(end);
                } else if w == "}" {
                    stack.pop().with_context(|| format!("{file}:{line}: unmatched }}"))?;
                    if stack.is_empty() {
                        break;
                    }
                } else {
                    bail!("{file}:{line}: expected JOINT, End Site or }}, found {w:?}");
                }
            }
            if stack.is_empty() {
                break;
            }
        }
        t.expect("MOTION")?;
        t.expect("Frames:")?;
        let line = t.line();
        let count = t.number("the frame count")?;
        if count < 1.0 || count.fract() != 0.0 {
            bail!("{file}:{line}: the frame count {count} is not a positive integer");
        }
        t.expect("Frame")?;
        t.expect("Time:")?;
        let line = t.line();
        let frame_time = t.number("the frame time")?;
        if frame_time <= 0.0 {
            bail!("{file}:{line}: the frame time {frame_time} is not positive");
        }
        let mut frames = Vec::with_capacity(count as usize);
        for f in 0..count as usize {
            let first = t.line();
            let mut row = Vec::with_capacity(channels);
            for _ in 0..channels {
                let line = t.line();
                if t.at < t.words.len() && line != first {
                    bail!(
                        "{file}:{line}: frame {f} (line {first}) has {} values, the hierarchy {channels} channels",
                        row.len()
                    );
                }
                row.push(t.number(&format!("frame {f}"))?);
            }
            frames.push(row);
            if t.at < t.words.len() && t.line() == first {
                bail!("{file}:{first}: frame {f} has more than the hierarchy's {channels} values");
            }
        }
        if t.at < t.words.len() {
            bail!("{file}:{}: more frames than the {count} announced", t.line());
        }
        Ok(Bvh { joints, frame_time, frames })
    }

    pub fn index(&self, name: &str) -> Option<usize> {
        self.joints.iter().position(|j| j.name == name)
    }

    /// Joint `j`'s rotation in frame `f` (file axes).
    pub fn rotation(&self, f: usize, j: usize) -> DQuat {
        let joint = &self.joints[j];
        let row = &self.frames[f];
        let mut q = DQuat::IDENTITY;
        for (k, c) in joint.channels.iter().enumerate() {
            let a = row[joint.first_channel + k].to_radians();
            q *= match c {
                Channel::Xrotation => DQuat::from_rotation_x(a),
                Channel::Yrotation => DQuat::from_rotation_y(a),
                Channel::Zrotation => DQuat::from_rotation_z(a),
                _ => DQuat::IDENTITY,
            };
        }
        q
    }

    /// Joint `j`'s position channels in frame `f` (zero where it has none).
    pub fn translation(&self, f: usize, j: usize) -> DVec3 {
        let joint = &self.joints[j];
        let row = &self.frames[f];
        let mut p = DVec3::ZERO;
        for (k, c) in joint.channels.iter().enumerate() {
            let v = row[joint.first_channel + k];
            match c {
                Channel::Xposition => p.x = v,
                Channel::Yposition => p.y = v,
                Channel::Zposition => p.z = v,
                _ => {}
            }
        }
        p
    }

    /// Rest positions of the joints (offsets accumulated, the root's included), file axes and units.
    pub fn rest_positions(&self) -> Vec<DVec3> {
        let mut out: Vec<DVec3> = Vec::with_capacity(self.joints.len());
        for j in &self.joints {
            let p = j.parent.map_or(DVec3::ZERO, |p| out[p]) + j.offset;
            out.push(p);
        }
        out
    }
}

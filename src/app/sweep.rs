//! Parameter sweeps, shared by `werkstatt render` and `werkstatt test`: `--set node.param=a,b,c`
//! (or a range `a..b:n`) is an axis, every combination of the axes is a variant, and a variant
//! has a name that is a folder name on every system.

use std::collections::BTreeSet;

use anyhow::{Context as _, bail};

/// The `--set` arguments of a run: plain overrides and the axes to sweep.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Sweep {
    /// `node.param=value` overrides with one value, for every variant.
    pub fixed: Vec<String>,
    /// Targets with two or more values, in the order given.
    pub axes: Vec<(String, Vec<String>)>,
}

impl Sweep {
    /// Splits `--set` arguments into overrides and axes.
    pub fn parse(sets: &[String]) -> anyhow::Result<Sweep> {
        let mut sweep = Sweep::default();
        for s in sets {
            let (target, mut values) = parse_axis(s)?;
            if values.len() == 1 {
                sweep.fixed.push(assignment(&target, &values.remove(0)));
            } else {
                sweep.axes.push((target, values));
            }
        }
        Ok(sweep)
    }

    /// Every variant's assignments (see [`product`]); one empty variant without axes.
    pub fn variants(&self) -> Vec<Vec<String>> {
        product(&self.axes)
    }
}

/// A case or variant name usable as a folder name on every system.
pub fn sanitize(name: &str) -> String {
    name.chars().map(|c| if c.is_ascii_alphanumeric() || "._=+,@-".contains(c) { c } else { '_' }).collect()
}

/// The folder name of a variant: its assignments joined by `+`.
pub fn variant_name(variant: &[String]) -> String {
    sanitize(&variant.join("+"))
}

fn assignment(target: &str, value: &str) -> String {
    format!("{target}={value}")
}

/// `node.param=a,b,c` into the target and its values. Commas inside brackets do not split,
/// so vectors are written `[0,0,1],[1,0,0]` (brackets dropped). A value `a..b:n` is n numbers
/// from a to b, both included, evenly spaced.
pub fn parse_axis(text: &str) -> anyhow::Result<(String, Vec<String>)> {
    let (target, values) = text.split_once('=').filter(|(t, _)| t.contains('.')).with_context(|| {
        format!("--set \"{text}\": expected node.param=value, node.param=a,b,c or node.param=a..b:n")
    })?;
    let mut out = Vec::new();
    let (mut depth, mut current) = (0i32, String::new());
    for c in values.chars() {
        match c {
            '[' => depth += 1,
            ']' => depth -= 1,
            ',' if depth == 0 => {
                out.push(std::mem::take(&mut current).trim().to_string());
                continue;
            }
            _ => {}
        }
        current.push(c);
    }
    out.push(current.trim().to_string());
    let mut values = Vec::new();
    for v in out {
        let v = v.trim_start_matches('[').trim_end_matches(']').to_string();
        match range(&v).with_context(|| format!("--set \"{text}\""))? {
            Some(numbers) => values.extend(numbers),
            None => values.push(v),
        }
    }
    if depth != 0 || values.iter().any(String::is_empty) {
        bail!("--set \"{text}\": a value is empty or a bracket is not closed");
    }
    let unique: BTreeSet<&String> = values.iter().collect();
    if unique.len() != values.len() {
        let numbers = values.iter().all(|v| v.parse::<f64>().is_ok());
        let hint = if numbers { " (a vector is written in brackets: node.param=[x,y,z])" } else { "" };
        bail!("--set \"{text}\": a value is repeated, so two variants would have one name{hint}");
    }
    Ok((target.trim().to_string(), values))
}

/// `a..b:n` as its n values (None for any other text).
fn range(text: &str) -> anyhow::Result<Option<Vec<String>>> {
    let Some((span, count)) = text.split_once(':') else { return Ok(None) };
    let Some((a, b)) = span.split_once("..") else { return Ok(None) };
    let number = |t: &str| t.trim().parse::<f64>().ok().filter(|x| x.is_finite());
    let (Some(a), Some(b)) = (number(a), number(b)) else {
        bail!("the range \"{text}\" needs two finite numbers: a..b:n");
    };
    let n: usize = count
        .trim()
        .parse()
        .ok()
        .filter(|n| (2..=1000).contains(n))
        .with_context(|| format!("the range \"{text}\" needs a count n from 2 to 1000 after the colon"))?;
    // Twelve significant digits: 0.1..0.9:5 gives 0.3, not 0.30000000000000004.
    let tidy = |x: f64| format!("{}", format!("{x:.12e}").parse::<f64>().unwrap_or(x));
    Ok(Some((0..n).map(|i| tidy(a + (b - a) * i as f64 / (n - 1) as f64)).collect()))
}

/// Every combination of the axes' values, the first axis slowest; one empty variant for no axes.
pub fn product(axes: &[(String, Vec<String>)]) -> Vec<Vec<String>> {
    let mut out = vec![Vec::new()];
    for (target, values) in axes {
        out = out
            .into_iter()
            .flat_map(|prefix: Vec<String>| {
                values.iter().map(move |v| {
                    let mut p = prefix.clone();
                    p.push(assignment(target, v));
                    p
                })
            })
            .collect();
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sweep_axes_multiply_in_order_and_keep_vectors_whole() {
        let a = parse_axis("camera.target=[0,0,0],[1,2,3]").unwrap();
        assert_eq!(a, ("camera.target".to_string(), vec!["0,0,0".to_string(), "1,2,3".to_string()]));
        let b = parse_axis("light.count=4,8").unwrap();
        let p = product(&[b, a]);
        assert_eq!(
            p,
            [
                ["light.count=4", "camera.target=0,0,0"],
                ["light.count=4", "camera.target=1,2,3"],
                ["light.count=8", "camera.target=0,0,0"],
                ["light.count=8", "camera.target=1,2,3"],
            ]
        );
        assert!(parse_axis("x.y=1,,2").is_err());
        assert!(parse_axis("x.y=1,1").is_err());
        assert!(parse_axis("xy=1").is_err());
    }

    #[test]
    fn ranges_expand_evenly_with_both_ends() {
        let (_, v) = parse_axis("fabric.glossiness=0.1..0.9:5").unwrap();
        assert_eq!(v, ["0.1", "0.3", "0.5", "0.7", "0.9"]);
        let (_, v) = parse_axis("light.count=1..4:4,16").unwrap();
        assert_eq!(v, ["1", "2", "3", "4", "16"]);
        assert!(format!("{:#}", parse_axis("x.y=0..1:1").unwrap_err()).contains("count"));
        assert!(format!("{:#}", parse_axis("x.y=a..1:3").unwrap_err()).contains("two finite numbers"));
        // A time of day is not a range.
        assert_eq!(parse_axis("x.y=12:30").unwrap().1, ["12:30"]);
    }

    #[test]
    fn sets_split_into_overrides_and_axes() {
        let s = Sweep::parse(&["a.b=1".into(), "c.d=2,3".into()]).unwrap();
        assert_eq!(s.fixed, ["a.b=1"]);
        assert_eq!(s.variants(), [["c.d=2"], ["c.d=3"]]);
        assert_eq!(variant_name(&s.variants()[1]), "c.d=3");
        assert_eq!(Sweep::parse(&[]).unwrap().variants(), [Vec::<String>::new()]);
    }

    /// A vector written without brackets is a sweep of its components: where that cannot be
    /// meant (a repeated number), the error says how to write a vector, and a vector parameter
    /// given one number says so too.
    #[test]
    fn a_vector_without_brackets_gets_an_error_naming_the_brackets() {
        let repeated = parse_axis("draw.translate=0,7.7,0").unwrap_err().to_string();
        assert!(repeated.contains("[x,y,z]"), "{repeated}");
        assert!(!parse_axis("node.mode=a,a").unwrap_err().to_string().contains("[x,y,z]"));
        let vec3 = crate::core::param::ParamKind::Vec3 { default: [0.0; 3] };
        let one = vec3.parse_cli("7.7").unwrap_err();
        assert!(one.contains("in brackets, [x,y,z]"), "{one}");
        assert!(vec3.parse_cli("[0,7.7,0]").is_ok());
    }
}

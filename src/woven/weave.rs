//! Weave patterns η (Zhang et al. 2012, section 4.2.1): which yarn lies on top at each crossing.
//! `eta(i, j)` is +1 where weft `j` passes over warp `i` (the weft is displaced by +η, the
//! warp by -η, eq. 11), -1 where it passes under. Patterns repeat in both directions.

use anyhow::{bail, ensure};

/// A repeating weave: `width` warps by `height` wefts of ±1.
#[derive(Clone, Debug, PartialEq)]
pub struct Weave {
    width: usize,
    height: usize,
    /// Row-major by weft: `cells[j * width + i]`.
    cells: Vec<i8>,
}

impl Weave {
    /// Plain weave: over one, under one, shifted by one each weft (η = (-1)^(i+j)).
    pub fn plain() -> Weave {
        Weave::from_fn(2, 2, |i, j| (i + j) % 2 == 0)
    }

    /// Twill `over`/`under`: the weft floats over `over` warps and under `under`, the
    /// pattern moving one warp per weft (the diagonal wale).
    pub fn twill(over: usize, under: usize) -> anyhow::Result<Weave> {
        ensure!(over >= 1 && under >= 1, "a twill needs at least one warp over and one under (got {over}/{under})");
        let n = over + under;
        Ok(Weave::from_fn(n, n, |i, j| (i + n - j % n) % n < over))
    }

    /// Regular satin of `n` harnesses: one crossing over per weft, moved by a counter `s`
    /// (the smallest in 2..n-1 coprime with n), so no two floats touch.
    pub fn satin(n: usize) -> anyhow::Result<Weave> {
        let step = (2..n.saturating_sub(1)).find(|&s| gcd(s, n) == 1);
        let Some(s) = step else {
            bail!(
                "there is no regular satin of {n} harnesses (it needs a step in 2..{n}-2 coprime with {n}; try 5, 7 or 8)"
            )
        };
        Ok(Weave::from_fn(n, n, |i, j| i == (j * s) % n))
    }

    /// A custom pattern: rows (wefts) of `0`/`1` separated by `/`, `;` or newlines; `1` puts
    /// the weft over. Every row must have the same length.
    pub fn parse(text: &str) -> anyhow::Result<Weave> {
        let rows: Vec<&str> = text.split(['/', ';', '\n']).map(|r| r.trim()).filter(|r| !r.is_empty()).collect();
        ensure!(!rows.is_empty(), "the weave pattern is empty (give rows of 0 and 1, e.g. \"10/01\")");
        let width = rows[0].chars().filter(|c| !c.is_whitespace()).count();
        let mut cells = Vec::with_capacity(width * rows.len());
        for (j, row) in rows.iter().enumerate() {
            let start = cells.len();
            for c in row.chars().filter(|c| !c.is_whitespace()) {
                match c {
                    '1' => cells.push(1),
                    '0' => cells.push(-1),
                    other => bail!(
                        "the weave pattern's row {} has {other:?}: only 0 (under) and 1 (over) are allowed",
                        j + 1
                    ),
                }
            }
            let n = cells.len() - start;
            ensure!(n == width, "the weave pattern's row {} has {n} entries but row 1 has {width}", j + 1);
        }
        ensure!(width > 0, "the weave pattern is empty (give rows of 0 and 1, e.g. \"10/01\")");
        Ok(Weave { width, height: rows.len(), cells })
    }

    fn from_fn(width: usize, height: usize, over: impl Fn(usize, usize) -> bool) -> Weave {
        let cells =
            (0..height).flat_map(|j| (0..width).map(move |i| (i, j))).map(|(i, j)| if over(i, j) { 1 } else { -1 });
        Weave { width, height, cells: cells.collect() }
    }

    pub fn width(&self) -> usize {
        self.width
    }

    pub fn height(&self) -> usize {
        self.height
    }

    /// η at warp `i`, weft `j` (any integers: the pattern repeats).
    pub fn eta(&self, i: i64, j: i64) -> f64 {
        let (w, h) = (self.width as i64, self.height as i64);
        f64::from(self.cells[(j.rem_euclid(h) * w + i.rem_euclid(w)) as usize])
    }

    /// The fraction of crossings where the weft is on top (to shade the panel scale).
    pub fn weft_cover(&self) -> f64 {
        self.cells.iter().filter(|&&c| c > 0).count() as f64 / self.cells.len() as f64
    }
}

fn gcd(a: usize, b: usize) -> usize {
    if b == 0 { a } else { gcd(b, a % b) }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plain_alternates_in_both_directions() {
        let w = Weave::plain();
        for i in -3..5 {
            for j in -3..5 {
                assert_eq!(w.eta(i, j), if (i + j).rem_euclid(2) == 0 { 1.0 } else { -1.0 });
            }
        }
        assert_eq!(w.weft_cover(), 0.5);
    }

    #[test]
    fn twill_floats_and_shifts_by_one() {
        let w = Weave::twill(2, 1).unwrap();
        assert_eq!((w.width(), w.height()), (3, 3));
        for j in 0..3i64 {
            let over: Vec<i64> = (0..3).filter(|&i| w.eta(i, j) > 0.0).collect();
            assert_eq!(over.len(), 2, "weft {j}");
            // The next weft's pattern is this one moved by one warp.
            for i in 0..3 {
                assert_eq!(w.eta(i, j), w.eta(i + 1, j + 1));
            }
        }
        assert!(Weave::twill(0, 2).is_err());
    }

    #[test]
    fn satin_has_one_float_per_weft_and_warp_without_neighbours() {
        let w = Weave::satin(5).unwrap();
        for j in 0..5i64 {
            let over: Vec<i64> = (0..5).filter(|&i| w.eta(i, j) > 0.0).collect();
            assert_eq!(over.len(), 1);
            let col: Vec<i64> = (0..5).filter(|&k| w.eta(j, k) > 0.0).collect();
            assert_eq!(col.len(), 1);
            // Satin: the next weft's crossing is not adjacent (no twill line).
            let next = (0..5).find(|&i| w.eta(i, j + 1) > 0.0).unwrap();
            assert!((next - over[0]).rem_euclid(5) > 1 && (next - over[0]).rem_euclid(5) < 4);
        }
        let e = Weave::satin(6).unwrap_err().to_string();
        assert!(e.contains("no regular satin of 6"), "{e}");
    }

    #[test]
    fn custom_patterns_are_validated() {
        let w = Weave::parse("110/011; 101").unwrap();
        assert_eq!((w.width(), w.height()), (3, 3));
        assert_eq!(w.eta(0, 0), 1.0);
        assert_eq!(w.eta(2, 0), -1.0);
        assert_eq!(w.eta(1, 2), -1.0);
        assert!(Weave::parse("").unwrap_err().to_string().contains("empty"));
        assert!(Weave::parse(" / ;").unwrap_err().to_string().contains("empty"));
        let e = Weave::parse("10/02").unwrap_err().to_string();
        assert!(e.contains("row 2") && e.contains("'2'"), "{e}");
        assert!(Weave::parse("10/011").unwrap_err().to_string().contains("row 2 has 3 entries"));
    }
}

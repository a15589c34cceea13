//! The measured directions of a BTF and the weights that blend the 4 nearest of them.
//!
//! Directions are given in the cloth's tangent frame: `theta` from the normal (z), `phi` from the
//! tangent (x, the warp direction) towards the bitangent (y), both in degrees.
//!
//! **Sampling.** Sattler et al. measure on rings of constant `theta`, `count` directions evenly
//! spaced in `phi` from 0 (Table 1). Their second sampling H2 has rings at 0/15/30/45/60/75 deg
//! with 1/6/12/18/20/24 directions, 81 in all; the test tier keeps its rings up to 30 deg, 19
//! directions.
//!
//! **Weights (eqs. 3 and 5).** The paper calls its light weights tau "bilinear" and gives no
//! formula; the view weights omega and the visibility-map weights h are the same kind. Here one
//! function serves all three: `theta` is bracketed between two adjacent rings (`t` linear in
//! `theta`), and on each of the two rings `phi` between its two neighbouring directions (`s`
//! linear in `phi`, wrapping from the last direction to the first). The 4 weights are
//! `(1-t)(1-s_a), (1-t)s_a, t(1-s_b), t s_b`. The one-direction pole ring takes `1-t` alone.
//! Beyond the outermost ring `theta` is clamped to it (grazing views and lights use the
//! outermost ring). The weights are >= 0, sum to 1, equal a unit vector at a measured
//! direction, and are continuous in `theta` and `phi` (across rings, at the `phi` wrap, and at
//! the pole, where `phi` is undefined).

use glam::DVec3;

/// One ring of a sampling: `count` directions at polar angle `theta` degrees, `phi = k * 360 /
/// count`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Ring {
    pub theta: f64,
    pub count: usize,
}

/// A direction in the tangent frame, in degrees.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Dir {
    pub theta: f64,
    pub phi: f64,
}

impl Dir {
    /// The unit vector (x along the tangent, z along the normal).
    pub fn to_vec(self) -> DVec3 {
        let (t, p) = (self.theta.to_radians(), self.phi.to_radians());
        DVec3::new(t.sin() * p.cos(), t.sin() * p.sin(), t.cos())
    }

    /// The direction of a vector (need not be normalised; `phi` in [0, 360)).
    pub fn from_vec(v: DVec3) -> Dir {
        let v = v.normalize_or(DVec3::Z);
        let theta = v.z.clamp(-1.0, 1.0).acos().to_degrees();
        let phi = v.y.atan2(v.x).to_degrees().rem_euclid(360.0);
        Dir { theta, phi }
    }
}

/// A ring sampling of the hemisphere (Table 1).
#[derive(Clone, Debug, PartialEq)]
pub struct Sampling {
    pub rings: Vec<Ring>,
}

/// The rings of H2, Table 1's second sampling.
const H2: [Ring; 6] = [
    Ring { theta: 0.0, count: 1 },
    Ring { theta: 15.0, count: 6 },
    Ring { theta: 30.0, count: 12 },
    Ring { theta: 45.0, count: 18 },
    Ring { theta: 60.0, count: 20 },
    Ring { theta: 75.0, count: 24 },
];

impl Sampling {
    /// H2, the paper's 81 directions.
    pub fn h2() -> Sampling {
        Sampling { rings: H2.to_vec() }
    }

    /// The test tier: H2's rings up to 30 deg, 19 directions.
    pub fn h2_tests() -> Sampling {
        Sampling { rings: H2[..3].to_vec() }
    }

    /// The number of directions.
    pub fn len(&self) -> usize {
        self.rings.iter().map(|r| r.count).sum()
    }

    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The directions, ring by ring from the pole, `phi` ascending within a ring.
    pub fn directions(&self) -> Vec<Dir> {
        self.rings
            .iter()
            .flat_map(|r| (0..r.count).map(move |k| Dir { theta: r.theta, phi: k as f64 * 360.0 / r.count as f64 }))
            .collect()
    }

    /// A sampling is usable when its rings ascend strictly in `theta` within [0, 90], each has at
    /// least one direction, and only a ring at the pole has exactly one.
    pub fn check(&self) -> Result<(), String> {
        if self.rings.is_empty() {
            return Err("the sampling has no rings".into());
        }
        for (i, r) in self.rings.iter().enumerate() {
            if !(0.0..=90.0).contains(&r.theta) || r.count == 0 {
                return Err(format!("ring {i} (theta {} deg, {} directions) is out of range", r.theta, r.count));
            }
            if r.count == 1 && r.theta != 0.0 {
                return Err(format!("ring {i} at theta {} deg has one direction; only the pole may", r.theta));
            }
            if i > 0 && r.theta <= self.rings[i - 1].theta {
                return Err(format!("ring {i} (theta {} deg) does not ascend", r.theta));
            }
        }
        Ok(())
    }

    /// The index of the first direction of each ring.
    fn ring_starts(&self) -> Vec<usize> {
        self.rings
            .iter()
            .scan(0, |start, r| {
                let s = *start;
                *start += r.count;
                Some(s)
            })
            .collect()
    }

    /// The 4 directions (indices into [`Sampling::directions`]) around `d` and their weights, as
    /// the module documentation describes. Entries may repeat an index with weight 0 (at the pole
    /// or with a single ring).
    pub fn weights(&self, d: Dir) -> [(usize, f64); 4] {
        let starts = self.ring_starts();
        let rings = &self.rings;
        let last = rings.len() - 1;
        let theta = d.theta.clamp(rings[0].theta, rings[last].theta);
        // The bracketing rings a <= theta <= b (b = a + 1 unless there is one ring).
        let b = rings.iter().position(|r| r.theta >= theta).unwrap_or(last).max(1).min(last);
        let a = b.saturating_sub(1);
        let t =
            if a == b { 0.0 } else { ((theta - rings[a].theta) / (rings[b].theta - rings[a].theta)).clamp(0.0, 1.0) };
        let on_ring = |i: usize| -> [(usize, f64); 2] {
            let n = rings[i].count;
            if n == 1 {
                return [(starts[i], 1.0), (starts[i], 0.0)];
            }
            let x = d.phi.rem_euclid(360.0) * n as f64 / 360.0;
            let k0 = (x.floor() as usize).min(n - 1);
            let s = (x - k0 as f64).clamp(0.0, 1.0);
            [(starts[i] + k0, 1.0 - s), (starts[i] + (k0 + 1) % n, s)]
        };
        let [a0, a1] = on_ring(a);
        let [b0, b1] = on_ring(b);
        [(a0.0, (1.0 - t) * a0.1), (a1.0, (1.0 - t) * a1.1), (b0.0, t * b0.1), (b1.0, t * b1.1)]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dense(s: &Sampling, d: Dir) -> Vec<f64> {
        let mut w = vec![0.0; s.len()];
        for (i, x) in s.weights(d) {
            w[i] += x;
        }
        w
    }

    #[test]
    fn h2_has_the_papers_81_directions_and_the_test_tier_19() {
        let h2 = Sampling::h2();
        assert_eq!(h2.len(), 81);
        assert_eq!(Sampling::h2_tests().len(), 19);
        h2.check().unwrap();
        let dirs = h2.directions();
        // The directions of the paper's Figs. 5 and 7 lie on H2.
        for (theta, phi) in [(60.0, 342.0), (45.0, 300.0), (75.0, 45.0), (0.0, 0.0)] {
            assert!(
                dirs.iter().any(|d| d.theta == theta && (d.phi - phi).abs() < 1e-9),
                "({theta}, {phi}) is not in H2"
            );
        }
    }

    #[test]
    fn weights_are_a_unit_vector_at_measured_directions() {
        for s in [Sampling::h2(), Sampling::h2_tests()] {
            for (i, d) in s.directions().into_iter().enumerate() {
                let w = dense(&s, d);
                assert!((w[i] - 1.0).abs() < 1e-12, "direction {i} {d:?}: {w:?}");
                assert!((dirs_dir_roundtrip(d)).abs() < 1e-9);
            }
        }
    }

    fn dirs_dir_roundtrip(d: Dir) -> f64 {
        let e = Dir::from_vec(d.to_vec());
        if d.theta == 0.0 { e.theta } else { (e.theta - d.theta).abs() + (e.phi - d.phi).abs() }
    }

    /// 0.1 deg sweeps in theta (at several phi, through the pole) and in phi (on and between
    /// rings, across the wrap): weights >= 0, sum 1, and no jump between neighbouring steps.
    #[test]
    fn weights_are_nonnegative_sum_to_one_and_continuous() {
        for s in [Sampling::h2(), Sampling::h2_tests()] {
            // A 0.1 deg step moves t or s by at most 0.1 / 15 (the smallest ring and phi gaps).
            let max_step = 2.0 * 0.1 / 15.0 + 1e-9;
            let check_path = |path: &mut dyn Iterator<Item = Dir>| {
                let mut prev: Option<Vec<f64>> = None;
                for d in path {
                    let w = dense(&s, d);
                    assert!(w.iter().all(|&x| x >= 0.0), "{d:?}: negative weight");
                    assert!(
                        (w.iter().sum::<f64>() - 1.0).abs() < 1e-12,
                        "{d:?}: weights sum to {}",
                        w.iter().sum::<f64>()
                    );
                    if let Some(p) = &prev {
                        let jump = w.iter().zip(p).map(|(a, b)| (a - b).abs()).fold(0.0, f64::max);
                        assert!(jump <= max_step, "{d:?}: weights jump by {jump}");
                    }
                    prev = Some(w);
                }
            };
            for phi in [0.0, 7.0, 100.0, 359.95] {
                // From theta 89.9 over the pole to the opposite side: phi + 180 on the way back.
                let down = (0..=899).rev().map(move |k| Dir { theta: k as f64 * 0.1, phi });
                let up = (1..=899).map(move |k| Dir { theta: k as f64 * 0.1, phi: phi + 180.0 });
                check_path(&mut down.chain(up));
            }
            for theta in [0.0, 10.0, 15.0, 22.5, 30.0, 52.0, 75.0, 80.0] {
                // Two full turns, so the wrap 360 -> 0 is crossed.
                check_path(&mut (0..=7200).map(move |k| Dir { theta, phi: k as f64 * 0.1 }));
            }
        }
    }
}

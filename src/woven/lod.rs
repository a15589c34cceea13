//! Level of detail (Zhang et al. 2012, section 5): the per-patch factor L (eq. 16), the
//! geomorphing factors (eqs. 17, 18, 20) and the grids each level draws.
//!
//! L in [0, 4) is the panel scale, [4, 9] the yarn scale, (9, 14] the fibre scale. The paper's
//! eq. 20 sets α = L - ⌊L⌋, so a level reaches its coarser neighbour's shape just before it is
//! replaced by the finer one (a pop), and it zeroes β_y above 5 and β_f above 10. Here (the fix
//! of the notes' B4.6) α = 1 - (L - ⌊L⌋), so the grid of level n first shows level n-1's shape
//! and has become itself when level n+1 takes over showing level n's shape; β_y and β_f stay 1
//! once reached. Across [9, 10) the yarn's own morph continues while β_f rises, so that at
//! L = 9 the fibres coincide with the yarn of level 8.

/// The highest level: the finest fibre grid.
pub const MAX_LEVEL: f64 = 14.0;

/// Eq. 16: L = c / (C |p_c - p_e|), clamped to [0, MAX_LEVEL]. `c`: the patch size, `coef`: C.
pub fn level_from_distance(c: f64, coef: f64, distance: f64) -> f64 {
    if distance <= 0.0 {
        return MAX_LEVEL;
    }
    (c / (coef * distance)).clamp(0.0, MAX_LEVEL)
}

/// The geomorphing rule: the corrected one, or eq. 20 as printed (kept to show that it pops).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Morph {
    Continuous,
    Literal,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Scale {
    Panel,
    Yarn,
    Fibre,
}

/// What a patch at level L draws and how far each term is morphed.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LodState {
    pub scale: Scale,
    /// The level whose grid is drawn (0..=3 panel: 2^n quads a side; 5..=14 tubes).
    pub grid: u32,
    /// Eq. 17's α: the weight of the coarser grid (level `grid - 1`) in each vertex.
    pub alpha: f64,
    pub beta_y: f64,
    pub beta_f: f64,
    /// While the yarns rise (L in [4, 5)) the panel term morphs from the 8x8 panel grid, where
    /// the panel scale left it, to the exact surface.
    pub alpha_panel: f64,
}

impl LodState {
    pub fn at(level: f64, morph: Morph) -> LodState {
        let l = level.clamp(0.0, MAX_LEVEL);
        let frac = l - l.floor();
        let n = l.floor() as u32;
        match morph {
            Morph::Continuous => {
                if l < 4.0 {
                    let alpha = if n == 0 { 0.0 } else { 1.0 - frac };
                    return LodState {
                        scale: Scale::Panel,
                        grid: n,
                        alpha,
                        beta_y: 0.0,
                        beta_f: 0.0,
                        alpha_panel: 0.0,
                    };
                }
                let grid = n.clamp(5, 14);
                let alpha = if l < 6.0 { 0.0 } else { 1.0 - frac };
                let beta_y = (l - 4.0).min(1.0);
                let beta_f = (l - 9.0).clamp(0.0, 1.0);
                let alpha_panel = if l < 5.0 { 1.0 - beta_y } else { 0.0 };
                let scale = if beta_f > 0.0 { Scale::Fibre } else { Scale::Yarn };
                LodState { scale, grid, alpha, beta_y, beta_f, alpha_panel }
            }
            Morph::Literal => {
                let (scale, grid) = if l < 4.0 {
                    (Scale::Panel, n)
                } else if l <= 9.0 {
                    (Scale::Yarn, n.clamp(5, 9))
                } else {
                    (Scale::Fibre, n.clamp(10, 14))
                };
                let only = |lo: f64, hi: f64| if l >= lo && l < hi { frac } else { 0.0 };
                let alpha = match scale {
                    Scale::Panel if n > 0 => frac,
                    Scale::Yarn if l >= 6.0 => only(5.0, 9.0),
                    Scale::Fibre => only(10.0, 14.0),
                    _ => 0.0,
                };
                LodState { scale, grid, alpha, beta_y: only(4.0, 5.0), beta_f: only(9.0, 10.0), alpha_panel: 0.0 }
            }
        }
    }

    /// Quads per patch side of the panel grid.
    pub fn panel_res(&self) -> usize {
        1 << self.grid.min(4)
    }

    /// Segments per node along a yarn and around it for tube level `grid` (>= 5): the total
    /// doubles per level, alternately around and along, from 1 x 2 at level 5 (the paper's
    /// "two quads for the weft thread and two quads for the warp").
    pub fn tube_res(grid: u32) -> (usize, usize) {
        let k = grid.max(5) - 4;
        (1 << (k / 2), 1 << k.div_ceil(2))
    }
}

/// The yarn parameters of a tube grid's rings along one patch, relative to the patch's first
/// node: the patch borders at -1/2 and N - 1/2, and `along` points per node from there. With
/// one point per node the nodes themselves are the points (so the crimp shows), plus the borders.
pub fn along_points(along: usize, nodes: usize) -> Vec<f64> {
    if along == 1 {
        let mut p = vec![-0.5];
        p.extend((0..nodes).map(|k| k as f64));
        p.push(nodes as f64 - 0.5);
        return p;
    }
    (0..=nodes * along).map(|k| -0.5 + k as f64 / along as f64).collect()
}

/// The interval of `points` (sorted) holding `x` and the weight of its upper end.
pub fn bracket(points: &[f64], x: f64) -> (usize, f64) {
    let i = points.partition_point(|&p| p <= x).clamp(1, points.len() - 1) - 1;
    let w = ((x - points[i]) / (points[i + 1] - points[i])).clamp(0.0, 1.0);
    (i, w)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn level_halves_when_the_distance_doubles() {
        let l1 = level_from_distance(1.0, 0.05, 2.0);
        let l2 = level_from_distance(1.0, 0.05, 4.0);
        assert!((l1 - 10.0).abs() < 1e-12 && (l2 - 5.0).abs() < 1e-12, "{l1} {l2}");
        assert_eq!(level_from_distance(1.0, 0.05, 1e-9), MAX_LEVEL);
    }

    #[test]
    fn states_follow_the_scales() {
        let s = LodState::at(2.25, Morph::Continuous);
        assert_eq!((s.scale, s.grid, s.alpha), (Scale::Panel, 2, 0.75));
        let s = LodState::at(4.5, Morph::Continuous);
        assert_eq!((s.scale, s.grid, s.beta_y, s.alpha_panel), (Scale::Yarn, 5, 0.5, 0.5));
        let s = LodState::at(9.25, Morph::Continuous);
        assert_eq!((s.scale, s.grid, s.beta_y, s.beta_f, s.alpha), (Scale::Fibre, 9, 1.0, 0.25, 0.75));
        let s = LodState::at(12.0, Morph::Continuous);
        assert_eq!((s.scale, s.grid, s.beta_f, s.alpha), (Scale::Fibre, 12, 1.0, 1.0));
        // The printed eq. 20 drops the crimp above L = 5.
        assert_eq!(LodState::at(7.5, Morph::Literal).beta_y, 0.0);
    }

    #[test]
    fn tube_grids_double_per_level() {
        let counts: Vec<usize> = (5..=14).map(LodState::tube_res).map(|(a, r)| a * r).collect();
        assert_eq!(counts, vec![2, 4, 8, 16, 32, 64, 128, 256, 512, 1024]);
        assert_eq!(LodState::tube_res(5), (1, 2));
        assert_eq!(along_points(1, 3), vec![-0.5, 0.0, 1.0, 2.0, 2.5]);
        assert_eq!(along_points(2, 2), vec![-0.5, 0.0, 0.5, 1.0, 1.5]);
        assert_eq!(bracket(&[0.0, 1.0, 3.0], 2.0), (1, 0.5));
        assert_eq!(bracket(&[0.0, 1.0, 3.0], 3.0), (1, 1.0));
    }
}

//! Checks of the woven geometry against its equations and analytic cases (the notes' B5).

use std::collections::HashMap;
use std::f64::consts::TAU;

use glam::DVec3;

use super::lod::{LodState, Morph, Scale, along_points, bracket};
use super::panel::{BezierPatch, ControlGrid, Frame, MU, Panel, bezier_mask, refine, ternary_weights};
use super::tess::{Layer, Woven, YarnRef};
use super::weave::Weave;
use super::yarn::{Dir, YarnParams, compose, fibre, height, yarn_frame, yarn_offset};
use crate::core::rng::SplitMix64;

fn rng_vec(r: &mut SplitMix64) -> DVec3 {
    DVec3::new(r.next_signed() as f64, r.next_signed() as f64, r.next_signed() as f64)
}

/// A curved n x n control grid over [0, n-1]^2 (patch size 1), heights from a fixed seed.
fn curved_grid(n: usize, amp: f64, seed: u64) -> ControlGrid {
    let mut r = SplitMix64::new(seed);
    let pts = (0..n * n).map(|k| DVec3::new((k % n) as f64, amp * r.next_signed() as f64, (k / n) as f64)).collect();
    ControlGrid::new(n, n, pts).unwrap()
}

fn params() -> YarnParams {
    // Patch size 1, 16 nodes: S = 1/16; yarns just touching at crossings (H = K).
    YarnParams { nodes: 16, spacing: 1.0 / 16.0, crimp: 0.02, radius: 0.02, fibres: 6, migration: 0.3, twist: 0.5 }
}

#[test]
fn ternary_rule_interpolates_and_reproduces_quadratics_not_cubics() {
    let w = ternary_weights(MU);
    let exact = [-19.0, 207.0, 93.0, -11.0].map(|x: f64| x / 270.0);
    for k in 0..4 {
        assert!((w[k] - exact[k]).abs() < 1e-15, "{w:?}");
    }
    let line =
        |f: &dyn Fn(f64) -> f64| -> Vec<DVec3> { (0..8).map(|i| DVec3::new(i as f64, f(i as f64), 0.0)).collect() };
    let quad = |x: f64| 0.5 * x * x - 2.0 * x + 1.0;
    let cubic = |x: f64| x * x * x;
    for (f, mu, reproduced) in [
        (&quad as &dyn Fn(f64) -> f64, MU, true),
        (&|x: f64| 3.0 * x - 1.0, MU, true),
        (&cubic, MU, false),
        // Lagrange cubic interpolation, outside the C2 range: the only μ with cubic precision.
        (&cubic, 1.0 / 27.0, true),
    ] {
        let p = line(f);
        let r = refine(&p, mu);
        assert_eq!(r.len(), 3 * p.len() - 2);
        let mut worst: f64 = 0.0;
        // Interior points (away from the linear ghosts at the ends).
        for (k, q) in r.iter().enumerate().skip(3).take(r.len() - 6) {
            let x = k as f64 / 3.0;
            assert!((q.x - x).abs() < 1e-12, "linear precision in x at {k}");
            worst = worst.max((q.y - f(x)).abs());
            if k % 3 == 0 {
                assert_eq!(*q, p[k / 3], "old vertices are kept");
            }
        }
        assert_eq!(worst < 1e-9, reproduced, "μ = {mu}: error {worst}");
    }
}

#[test]
fn bezier_masks_have_the_closed_form() {
    let m = bezier_mask(MU);
    let q1 = [-3.0 / 20.0, 19.0 / 20.0, 13.0 / 60.0, -1.0 / 60.0];
    for k in 0..4 {
        assert!((m[0][k] - [0.0, 1.0, 0.0, 0.0][k]).abs() < 1e-14, "{:?}", m[0]);
        assert!((m[1][k] - q1[k]).abs() < 1e-14, "{:?}", m[1]);
        assert!((m[2][k] - q1[3 - k]).abs() < 1e-14, "{:?}", m[2]);
        assert!((m[3][k] - [0.0, 0.0, 1.0, 0.0][k]).abs() < 1e-14, "{:?}", m[3]);
    }
}

#[test]
fn patch_interpolates_its_refinement_points_and_corners() {
    let mut r = SplitMix64::new(7);
    let a = ternary_weights(MU);
    let rows = [[0.0, 1.0, 0.0, 0.0], a, [a[3], a[2], a[1], a[0]], [0.0, 0.0, 1.0, 0.0]];
    for _ in 0..20 {
        let mut h = [[DVec3::ZERO; 4]; 4];
        h.iter_mut().flatten().for_each(|p| *p = rng_vec(&mut r));
        let patch = BezierPatch::from_controls(&h, &bezier_mask(MU));
        for i in 0..4 {
            for j in 0..4 {
                // M_R R: the subdivision's point at (i/3, j/3) (tensor product of the 1D rule).
                let mut target = DVec3::ZERO;
                for k in 0..4 {
                    for l in 0..4 {
                        target += rows[i][k] * rows[j][l] * h[k][l];
                    }
                }
                let got = patch.position(i as f64 / 3.0, j as f64 / 3.0);
                assert!(got.distance(target) < 1e-6, "({i},{j}): {got} vs {target}");
            }
        }
        assert!(patch.position(0.0, 0.0).distance(h[1][1]) < 1e-12);
        assert!(patch.position(1.0, 1.0).distance(h[2][2]) < 1e-12);
        assert!(patch.position(1.0, 0.0).distance(h[2][1]) < 1e-12);
    }
}

#[test]
fn a_plane_stays_planar_and_a_quadratic_is_exact_at_refinement_points() {
    let mut r = SplitMix64::new(11);
    let (e1, e2) = (DVec3::new(1.0, 0.3, 0.1), DVec3::new(-0.2, 0.4, 1.0));
    let normal = e1.cross(e2).normalize();
    let n = 5;
    let pts = (0..n * n)
        .map(|k| {
            let (i, j) = ((k % n) as f64, (k / n) as f64);
            (i + 0.3 * r.next_signed() as f64) * e1
                + (j + 0.3 * r.next_signed() as f64) * e2
                + DVec3::new(1.0, 2.0, 3.0)
        })
        .collect();
    let grid = ControlGrid::new(n, n, pts).unwrap();
    let panel = Panel::new(&grid);
    let origin = DVec3::new(1.0, 2.0, 3.0);
    for pj in 0..n - 1 {
        for pi in 0..n - 1 {
            for _ in 0..10 {
                let (s, t) = (r.next_f32() as f64, r.next_f32() as f64);
                let off = (panel.position(pi, pj, s, t) - origin).dot(normal);
                assert!(off.abs() < 1e-9, "off the plane by {off}");
                let f = panel.frame(pi, pj, s, t);
                assert!(f.n.cross(normal).length() < 1e-9);
            }
        }
    }
    // z = f(x, y) quadratic on a regular grid: refinement points lie on it exactly (the rule
    // reproduces quadratics), so the patch hits f there.
    let f = |x: f64, y: f64| 0.3 * x * x - 0.2 * x * y + 0.1 * y * y + x - 2.0;
    let pts =
        (0..n * n).map(|k| DVec3::new((k % n) as f64, (k / n) as f64, f((k % n) as f64, (k / n) as f64))).collect();
    let panel = Panel::new(&ControlGrid::new(n, n, pts).unwrap());
    for i in 0..4 {
        for j in 0..4 {
            let p = panel.position(1, 2, i as f64 / 3.0, j as f64 / 3.0);
            assert!((p.z - f(p.x, p.y)).abs() < 1e-9, "{p}");
        }
    }
}

#[test]
fn yarn_and_fibre_geometry_match_the_analytic_forms() {
    let weave = Weave::twill(2, 1).unwrap();
    let p = params();
    for n in -4..8i64 {
        for line in 0..3 {
            let (h, dh) = height(&weave, Dir::Weft, line, n as f64);
            assert_eq!((h, dh), (weave.eta(n, line), 0.0));
            let (h, _) = height(&weave, Dir::Warp, line, n as f64);
            assert_eq!(h, -weave.eta(line, n));
        }
    }
    // dh/du against a central difference, and a frame that is orthonormal everywhere.
    let mut r = SplitMix64::new(3);
    for _ in 0..200 {
        let u = 10.0 * r.next_f32() as f64;
        for dir in [Dir::Weft, Dir::Warp] {
            let (_, dh) = height(&weave, dir, 1, u);
            let e = 1e-6;
            if (u - u.round()).abs() > 2.0 * e {
                let fd = (height(&weave, dir, 1, u + e).0 - height(&weave, dir, 1, u - e).0) / (2.0 * e);
                assert!((fd - dh).abs() < 1e-5, "{u}: {fd} vs {dh}");
            }
            let f = yarn_frame(dir, p.spacing, p.crimp, dh);
            assert!(f.orthonormality_error() < 1e-12);
            // The tangent follows the path (S along the axis, H h' up).
            let axis = if dir == Dir::Weft { DVec3::X } else { DVec3::Z };
            let t = p.spacing * axis + p.crimp * dh * DVec3::Y;
            assert!(f.t.cross(t).length() < 1e-12);
            let fp = fibre(&p, 2, u, p.spacing, 1.0);
            assert!(fp.frame.orthonormality_error() < 1e-12);
            // |l_f| = r(u), phase φ + ω u.
            assert!((fp.offset.length() - fp.r).abs() < 1e-12);
            let phase = fp.offset.y.atan2(fp.offset.z);
            let want = TAU * 2.0 / 6.0 + p.omega() * u;
            assert!((phase - want).rem_euclid(TAU).min((want - phase).rem_euclid(TAU)) < 1e-9);
            let r0 = p.ring_radius();
            assert!(fp.r <= r0 + 1e-15 && fp.r >= (1.0 - p.migration) * r0 - 1e-15);
        }
    }
    // Packing: six fibres of radius K/3 on a ring at 2K/3.
    assert!((p.fibre_radius() - p.radius / 3.0).abs() < 1e-15);
    assert!((p.ring_radius() - 2.0 * p.radius / 3.0).abs() < 1e-15);
}

#[test]
fn composition_on_a_flat_panel_matches_the_closed_form() {
    // A flat 3x3-patch panel in the xz plane: l_p = (u, 0, v), M_p = (x, -y, z).
    let pts = (0..16).map(|k| DVec3::new((k % 4) as f64, 0.0, (k / 4) as f64)).collect();
    let panel = Panel::new(&ControlGrid::new(4, 4, pts).unwrap());
    let weave = Weave::plain();
    let p = params();
    let woven = Woven { panel: &panel, weave: &weave, yarn: &p, morph: Morph::Continuous, snap: true };
    let st = LodState::at(8.0, Morph::Continuous);
    assert_eq!((st.beta_y, st.alpha), (1.0, 1.0));
    let mut r = SplitMix64::new(5);
    for _ in 0..100 {
        let index = (r.next_u64() % 16) as usize;
        let u = -0.5 + 16.0 * r.next_f32() as f64;
        let theta = TAU * r.next_f32() as f64;
        let y = YarnRef { dir: Dir::Weft, pi: 1, pj: 2, index };
        let (got, normal) = woven.tube_point(y, None, u, theta, &st, false);
        // Weft line 2*16 + index at v = 2 + (index + 1/2)/16, x = 1 + (u + 1/2)/16.
        let line = (32 + index) as i64;
        let ug = 16.0 + u;
        let (h, dh) = height(&weave, Dir::Weft, line, ug);
        let (s, hh) = (p.spacing, p.crimp);
        let axis = DVec3::new(1.0 + (u + 0.5) / 16.0, -hh * h, 2.0 + (index as f64 + 0.5) / 16.0);
        // World n_y = (-H h' x + S n_p) / |.|, with n_p = -y; b_y = z.
        let ny = (-hh * dh * DVec3::X + s * DVec3::NEG_Y) / s.hypot(hh * dh);
        let want = axis + p.radius * (theta.sin() * ny + theta.cos() * DVec3::Z);
        assert!(got.distance(want) < 1e-12, "{got} vs {want}");
        assert!((normal.length() - 1.0).abs() < 1e-12);
        // The shell is K from the axis, perpendicular to the yarn's tangent.
        let tangent = s * DVec3::X - hh * dh * DVec3::Y;
        assert!(((got - axis).length() - p.radius).abs() < 1e-12);
        assert!((got - axis).dot(tangent).abs() < 1e-12);
    }
    // A fibre at β_f = 1 sits r(u) from the yarn axis.
    let st = LodState::at(10.0, Morph::Continuous);
    let y = YarnRef { dir: Dir::Warp, pi: 0, pj: 1, index: 3 };
    for k in 0..20 {
        let u = -0.5 + k as f64 * 0.8;
        let (ax, _) = compose_axis(&woven, y, u, &st);
        let (fa, _) = woven.tube_point(y, Some(4), u, 0.0, &st, false);
        let (fb, _) = woven.tube_point(y, Some(4), u, TAU / 2.0, &st, false);
        let centre = 0.5 * (fa + fb);
        let ug = 16.0 + u;
        let (_, dh) = height(&weave, Dir::Warp, 3, ug);
        let fp = fibre(&p, 4, ug, p.spacing.hypot(p.crimp * dh), 1.0);
        assert!((centre.distance(ax) - fp.r).abs() < 1e-12, "{} vs {}", centre.distance(ax), fp.r);
        assert!(((fa - centre).length() - p.fibre_radius()).abs() < 1e-12);
    }
}

/// The yarn axis (no shell) at a tube point.
fn compose_axis(w: &Woven<'_>, y: YarnRef, u: f64, st: &LodState) -> (DVec3, DVec3) {
    let (a, _) = w.tube_point(y, None, u, 0.0, st, false);
    let (b, _) = w.tube_point(y, None, u, TAU / 2.0, st, false);
    (0.5 * (a + b), DVec3::ZERO)
}

#[test]
fn frames_are_orthonormal() {
    let panel = Panel::new(&curved_grid(5, 0.3, 9));
    let mut r = SplitMix64::new(1);
    for _ in 0..500 {
        let (pi, pj) = ((r.next_u64() % 4) as usize, (r.next_u64() % 4) as usize);
        let f = panel.frame(pi, pj, r.next_f32() as f64, r.next_f32() as f64);
        assert!(f.orthonormality_error() < 1e-5);
        let c = f.compose(&yarn_frame(Dir::Warp, 0.1, 0.05, r.next_signed() as f64 * 3.0));
        assert!(c.orthonormality_error() < 1e-5);
    }
    let _ = (compose as fn(_, _, _, _, _, _, _, _) -> _, yarn_offset, Frame::IDENTITY);
}

/// The drawn surface at a fixed parameter: the bilinear interpolation, over the grid a level
/// draws, of its morphed vertices (what the triangles show up to their diagonal).
fn panel_surface(w: &Woven<'_>, s: f64, t: f64, l: f64, morph: Morph) -> DVec3 {
    let st = LodState::at(l, morph);
    let g = st.panel_res() as f64;
    let (a0, b0) = ((s * g).floor().min(g - 1.0), (t * g).floor().min(g - 1.0));
    let (ws, wt) = (s * g - a0, t * g - b0);
    let v = |a: f64, b: f64| w.panel_vertex(1, 1, a / g, b / g, &st).0;
    (1.0 - wt) * ((1.0 - ws) * v(a0, b0) + ws * v(a0 + 1.0, b0))
        + wt * ((1.0 - ws) * v(a0, b0 + 1.0) + ws * v(a0 + 1.0, b0 + 1.0))
}

fn tube_surface(w: &Woven<'_>, y: YarnRef, u: f64, theta: f64, l: f64, morph: Morph) -> DVec3 {
    let st = LodState::at(l, morph);
    let (sa, sr) = LodState::tube_res(st.grid);
    let pts = along_points(sa, w.yarn.nodes);
    let (i, wu) = bracket(&pts, u);
    let x = theta * sr as f64 / TAU;
    let k0 = x.floor();
    let wt = x - k0;
    let f = (st.scale == Scale::Fibre).then_some(0);
    let v = |a: f64, k: f64| w.tube_vertex(y, f, a, k * TAU / sr as f64, &st).0;
    (1.0 - wt) * ((1.0 - wu) * v(pts[i], k0) + wu * v(pts[i + 1], k0))
        + wt * ((1.0 - wu) * v(pts[i], k0 + 1.0) + wu * v(pts[i + 1], k0 + 1.0))
}

/// The largest |p(L + d) - p(L)| over L in [from, to) in steps d.
fn max_step(f: &dyn Fn(f64) -> DVec3, from: f64, to: f64, d: f64) -> (f64, f64) {
    let mut prev = f(from);
    let mut worst = (0.0, from);
    let steps = ((to - from) / d).round() as usize;
    for k in 1..=steps {
        let l = from + k as f64 * d;
        let p = f(l);
        let jump = p.distance(prev);
        if jump > worst.0 {
            worst = (jump, l);
        }
        prev = p;
    }
    worst
}

#[test]
fn geomorphing_does_not_pop_across_levels_and_scales() {
    let panel = Panel::new(&curved_grid(4, 0.4, 21));
    let weave = Weave::plain();
    let p = params();
    let d = 1e-3;
    // Lipschitz bound: the patch size (1) per unit L; a pop is a step of ~d * 10 or more.
    let k = 1.0;
    for morph in [Morph::Continuous, Morph::Literal] {
        let w = Woven { panel: &panel, weave: &weave, yarn: &p, morph, snap: true };
        let mut worst: f64 = 0.0;
        for (s, t) in [(0.3125, 0.5625), (0.71875, 0.15625), (0.5, 0.5)] {
            let (j, at) = max_step(&|l| panel_surface(&w, s, t, l, morph), 0.0, 3.999, d);
            if morph == Morph::Continuous {
                assert!(j <= k * d, "panel pops by {j} at L = {at} at ({s}, {t})");
            }
            worst = worst.max(j);
        }
        let y = YarnRef { dir: Dir::Weft, pi: 1, pj: 1, index: 5 };
        for (u, theta) in [(3.28125, 1.0 / 32.0 * TAU), (7.0 + 3.0 / 32.0, 0.3 * TAU), (10.5, 0.55 * TAU)] {
            let (j, at) = max_step(&|l| tube_surface(&w, y, u, theta, l, morph), 4.0, 14.0, d);
            if morph == Morph::Continuous {
                assert!(j <= k * d, "yarn/fibre pops by {j} at L = {at} at (u {u}, θ {theta})");
            }
            worst = worst.max(j);
        }
        if morph == Morph::Literal {
            assert!(worst > 10.0 * k * d, "the printed eq. 20 should pop; largest step {worst}");
        }
    }
    // Across L = 4 the ribbons' centre lines start on the panel as drawn just below 4.
    let w = Woven { panel: &panel, weave: &weave, yarn: &p, morph: Morph::Continuous, snap: true };
    for index in [0, 7, 15] {
        for u in [-0.5, 0.0, 3.0, 9.0, 15.5] {
            let y = YarnRef { dir: Dir::Warp, pi: 1, pj: 1, index };
            let st = LodState::at(4.0, Morph::Continuous);
            let a = w.tube_vertex(y, None, u, 0.0, &st).0;
            let b = w.tube_vertex(y, None, u, TAU / 2.0, &st).0;
            let (s, t) = ((index as f64 + 0.5) / 16.0, (u + 0.5) / 16.0);
            let below = panel_surface(&w, s, t, 4.0 - 1e-12, Morph::Continuous);
            assert!((0.5 * (a + b)).distance(below) < 1e-9, "{index} {u}");
        }
    }
}

/// Welds the layers (positions equal to 1e-9) and returns the edges used by one triangle only
/// whose ends are not both on the outer boundary.
fn inner_open_edges(layers: &[&Layer]) -> usize {
    let mut ids: HashMap<[i64; 3], usize> = HashMap::new();
    let mut outer: Vec<bool> = Vec::new();
    let mut tris = Vec::new();
    for layer in layers {
        let map: Vec<usize> = layer
            .positions
            .iter()
            .zip(&layer.outer)
            .map(|(p, &o)| {
                let key = (*p * 1e9).round().as_i64vec3().to_array();
                let n = ids.len();
                let id = *ids.entry(key).or_insert(n);
                if id == outer.len() {
                    outer.push(o);
                } else {
                    outer[id] |= o;
                }
                id
            })
            .collect();
        tris.extend(
            layer.indices.chunks_exact(3).map(|t| [map[t[0] as usize], map[t[1] as usize], map[t[2] as usize]]),
        );
    }
    let mut edges: HashMap<(usize, usize), usize> = HashMap::new();
    for t in tris {
        if t[0] == t[1] || t[1] == t[2] || t[0] == t[2] {
            continue;
        }
        for (a, b) in [(t[0], t[1]), (t[1], t[2]), (t[2], t[0])] {
            *edges.entry((a.min(b), a.max(b))).or_default() += 1;
        }
    }
    edges.iter().filter(|&(&(a, b), &n)| n == 1 && !(outer[a] && outer[b])).count()
}

/// On a curved 4x4 patch grid with random levels in `range` (`trials` draws from `seed`),
/// the edges that only one triangle uses lie on the outer boundary after welding.
fn assert_no_inner_cracks(weave: &Weave, p: &YarnParams, range: (f64, f64), seed: u64, trials: usize) {
    let panel = Panel::new(&curved_grid(5, 0.3, 33));
    let w = Woven { panel: &panel, weave, yarn: p, morph: Morph::Continuous, snap: true };
    let mut r = SplitMix64::new(seed);
    let (lo, hi) = range;
    for _ in 0..trials {
        let levels: Vec<Option<f64>> = (0..16).map(|_| Some(lo + (hi - lo) * r.next_f32() as f64)).collect();
        let t = w.tessellate(&levels).unwrap();
        let open = inner_open_edges(&[&t.panel, &t.weft, &t.warp]);
        assert_eq!(open, 0, "levels {levels:?}");
    }
}

// The yarn and fibre scales (levels 4 to 11.5) are three tests, one draw each, so that they
// run on parallel threads: together they are the longest unit test.
#[test]
fn no_cracks_between_yarn_and_fibre_patches_of_random_levels_1() {
    assert_no_inner_cracks(&Weave::twill(2, 1).unwrap(), &YarnParams { fibres: 3, ..params() }, (4.0, 11.5), 991, 1);
}

#[test]
fn no_cracks_between_yarn_and_fibre_patches_of_random_levels_2() {
    assert_no_inner_cracks(&Weave::twill(2, 1).unwrap(), &YarnParams { fibres: 3, ..params() }, (4.0, 11.5), 992, 1);
}

#[test]
fn no_cracks_between_yarn_and_fibre_patches_of_random_levels_3() {
    assert_no_inner_cracks(&Weave::twill(2, 1).unwrap(), &YarnParams { fibres: 3, ..params() }, (4.0, 11.5), 993, 1);
}

#[test]
fn no_cracks_between_patches_of_random_levels() {
    let weave = Weave::twill(2, 1).unwrap();
    let p = YarnParams { fibres: 3, ..params() };
    assert_no_inner_cracks(&weave, &p, (0.0, 4.0), 99, 3);
    // Panel next to yarns: every yarn end on that edge lands on a vertex of the panel's edge.
    let levels = vec![Some(2.5), Some(6.5), Some(3.7), Some(4.2)];
    let small = Panel::new(&curved_grid(3, 0.3, 34));
    let w = Woven { panel: &small, weave: &weave, yarn: &p, morph: Morph::Continuous, snap: true };
    let t = w.tessellate(&levels).unwrap();
    assert_eq!(t.scales, [2, 2, 0]);
    let key = |p: &DVec3| (*p * 1e9).round().as_i64vec3().to_array();
    let panel_vertices: std::collections::HashSet<_> = t.panel.positions.iter().map(key).collect();
    // Yarn ends on the shared edges of patch (1,0) (L 6.5) with (0,0) (L 2.5) collapse onto panel vertices.
    let ends: Vec<&DVec3> = t.weft.positions.iter().filter(|q| (q.x - 1.0).abs() < 1e-12 && q.z < 1.0).collect();
    assert!(!ends.is_empty());
    for q in ends {
        assert!(panel_vertices.contains(&key(q)), "yarn end {q} hangs off the panel");
    }
}

#[test]
fn triangle_counts_follow_the_papers_pattern() {
    let pts = (0..9).map(|k| DVec3::new((k % 3) as f64, 0.0, (k / 3) as f64)).collect();
    let panel = Panel::new(&ControlGrid::new(3, 3, pts).unwrap());
    let weave = Weave::plain();
    let p = params();
    let w = Woven { panel: &panel, weave: &weave, yarn: &p, morph: Morph::Continuous, snap: true };
    for (l, per_patch) in [(7.0, 8192), (9.0, 32768), (7.5, 8192), (3.0, 2 * 8 * 8)] {
        let t = w.tessellate(&[Some(l); 4]).unwrap();
        assert_eq!(t.triangles(), 4 * per_patch, "L = {l}");
        assert_eq!(w.patch_triangles(l), per_patch);
    }
    assert!(w.tessellate(&[Some(14.5); 4]).unwrap_err().to_string().contains("outside"));
}

/// The notes' B5.1 figures: how far the Bézier patch is from the subdivision surface (three
/// refinement steps) and how much the normal turns across a patch edge (the patches are C0).
#[test]
fn patch_deviation_from_the_subdivision_surface_is_small() {
    let n = 7;
    let h = |x: f64, y: f64| 0.4 * (0.9 * x).sin() * (0.7 * y).cos();
    let pts: Vec<DVec3> =
        (0..n * n).map(|k| ((k % n) as f64, (k / n) as f64)).map(|(x, y)| DVec3::new(x, h(x, y), y)).collect();
    // Three tensor-product refinement steps: rows, then columns.
    let (mut rows, mut m) = (pts.chunks(n).map(|r| r.to_vec()).collect::<Vec<_>>(), n);
    for _ in 0..3 {
        let refined_rows: Vec<Vec<DVec3>> = rows.iter().map(|r| refine(r, MU)).collect();
        let w = refined_rows[0].len();
        let cols: Vec<Vec<DVec3>> =
            (0..w).map(|i| refine(&refined_rows.iter().map(|r| r[i]).collect::<Vec<_>>(), MU)).collect();
        m = cols[0].len();
        rows = (0..m).map(|j| cols.iter().map(|c| c[j]).collect()).collect();
    }
    assert_eq!(m, 27 * (n - 1) + 1);
    let panel = Panel::new(&ControlGrid::new(n, n, pts).unwrap());
    let (mut worst, mut sum, mut count) = (0.0f64, 0.0, 0.0);
    // Interior patches only: the refinement's own boundary ghosts differ from the grid's.
    for (pi, pj) in [(2, 2), (3, 2), (2, 3), (3, 3)] {
        for b in 0..=27 {
            for a in 0..=27 {
                let want = rows[27 * pj + b][27 * pi + a];
                let d = panel.position(pi, pj, a as f64 / 27.0, b as f64 / 27.0).distance(want);
                worst = worst.max(d);
                sum += d * d;
                count += 1.0;
            }
        }
    }
    let rms = (sum / count).sqrt();
    // The normal jump across the edge between patches (2,2) and (3,2), unshared frames.
    let mut jump: f64 = 0.0;
    for k in 0..=20 {
        let t = k as f64 / 20.0;
        let (l, r) = (panel.patch(2, 2).derivatives(1.0, t), panel.patch(3, 2).derivatives(0.0, t));
        let (nl, nr) = (l.0.cross(l.1).normalize(), r.0.cross(r.1).normalize());
        jump = jump.max(nl.dot(nr).clamp(-1.0, 1.0).acos().to_degrees());
    }
    eprintln!("patch vs 3 refinement steps: max {worst:.2e}, rms {rms:.2e} (patch size 1); normal jump {jump:.3} deg");
    // Refinement points of level 1 are hit exactly; the rest stays within a small fraction.
    assert!(worst < 2.5e-3 && rms < 1e-3 && jump < 0.5, "max {worst}, rms {rms}, jump {jump}");
}

/// The share of a layer's triangles (degenerate ones left out) whose front, by their winding,
/// faces the way their vertex normals do.
fn wound_along_normals(layer: &Layer) -> f64 {
    let (mut along, mut total) = (0usize, 0usize);
    for t in layer.indices.chunks_exact(3) {
        let [a, b, c] = [t[0], t[1], t[2]].map(|i| i as usize);
        let p = &layer.positions;
        let face = (p[b] - p[a]).cross(p[c] - p[a]);
        let normal = layer.normals[a] + layer.normals[b] + layer.normals[c];
        if face.length() < 1e-12 {
            continue;
        }
        total += 1;
        along += usize::from(face.dot(normal) > 0.0);
    }
    along as f64 / total.max(1) as f64
}

/// The G-buffer lights a triangle's back with its normal flipped (two-sided cloth), so a
/// triangle wound against its normal is shaded as if lit from behind. The panel layer is wound
/// along its normals, flipped or not; the weft's and the warp's tubes but for a few sheared
/// triangles (5% of the weft's, 5-13% of the warp's: docs/woven.md).
#[test]
fn triangles_are_wound_along_their_normals() {
    let weave = Weave::twill(2, 1).unwrap();
    let p = YarnParams { fibres: 3, ..params() };
    for flip in [false, true] {
        let panel = Panel { flip, ..Panel::new(&curved_grid(5, 0.3, 33)) };
        let w = Woven { panel: &panel, weave: &weave, yarn: &p, morph: Morph::Continuous, snap: true };
        let levels: Vec<Option<f64>> = (0..16).map(|k| Some([2.0, 5.0, 7.0, 9.5][k % 4])).collect();
        let t = w.tessellate(&levels).unwrap();
        assert!(t.panel.triangles() > 0 && t.weft.triangles() > 0);
        assert_eq!(wound_along_normals(&t.panel), 1.0, "panel, flip {flip}");
        let weft = wound_along_normals(&t.weft);
        assert!(weft > 0.9, "weft {weft}, flip {flip}");
        let warp = wound_along_normals(&t.warp);
        assert!(warp > 0.85, "warp {warp}, flip {flip}");
    }
}

//! Edge curves flattened to polylines, arc-length resampling and the outline crossing test.

use glam::DVec2;

/// Points per flattened Bézier or arc: fine enough that resampling at 0.5 cm along a 50 cm
/// curve is off the true curve by well under a millimetre (the chord error of 64 pieces of a
/// curve bending at most a quarter turn is below 1e-4 of its length).
pub const CURVE_POINTS: usize = 64;

pub fn polyline_length(p: &[DVec2]) -> f64 {
    p.windows(2).map(|w| w[0].distance(w[1])).sum()
}

/// A quadratic Bézier `a, c, b` as `CURVE_POINTS + 1` points.
pub fn quadratic(a: DVec2, c: DVec2, b: DVec2) -> Vec<DVec2> {
    (0..=CURVE_POINTS)
        .map(|i| {
            let t = i as f64 / CURVE_POINTS as f64;
            let s = 1.0 - t;
            a * (s * s) + c * (2.0 * s * t) + b * (t * t)
        })
        .collect()
}

/// A cubic Bézier `a, c1, c2, b` as `CURVE_POINTS + 1` points.
pub fn cubic(a: DVec2, c1: DVec2, c2: DVec2, b: DVec2) -> Vec<DVec2> {
    (0..=CURVE_POINTS)
        .map(|i| {
            let t = i as f64 / CURVE_POINTS as f64;
            let s = 1.0 - t;
            a * (s * s * s) + c1 * (3.0 * s * s * t) + c2 * (3.0 * s * t * t) + b * (t * t * t)
        })
        .collect()
}

/// A circular arc from `a` to `b` of radius `r` with the SVG flags (`large_arc`, `sweep`: the
/// angle increases from `a` to `b`, counter-clockwise with y up), by the SVG specification's
/// endpoint-to-centre conversion (SVG 1.1, appendix F.6.5, with no axis rotation). A radius
/// too small to reach is scaled up (F.6.6), as SVG renderers do. `None` for coincident ends or
/// a radius that is not positive and finite.
pub fn arc(a: DVec2, b: DVec2, r: f64, large_arc: bool, sweep: bool) -> Option<Vec<DVec2>> {
    if !(r.is_finite() && r > 0.0) || a.distance(b) < 1e-12 {
        return None;
    }
    let half = (a - b) * 0.5;
    let mid = (a + b) * 0.5;
    let d2 = half.length_squared();
    let r = r.max(d2.sqrt());
    let coef = ((r * r - d2) / d2).max(0.0).sqrt();
    let sign = if large_arc != sweep { 1.0 } else { -1.0 };
    let c_rel = DVec2::new(half.y, -half.x) * (sign * coef);
    let center = c_rel + mid;
    let u = (half - c_rel) / r;
    let v = (-half - c_rel) / r;
    let theta1 = u.y.atan2(u.x);
    let mut delta = u.perp_dot(v).atan2(u.dot(v));
    if !sweep && delta > 0.0 {
        delta -= std::f64::consts::TAU;
    } else if sweep && delta < 0.0 {
        delta += std::f64::consts::TAU;
    }
    let mut pts: Vec<DVec2> = (0..=CURVE_POINTS)
        .map(|i| {
            let t = theta1 + delta * i as f64 / CURVE_POINTS as f64;
            center + DVec2::new(t.cos(), t.sin()) * r
        })
        .collect();
    // Exact ends: the next edge starts where this one ends.
    pts[0] = a;
    pts[CURVE_POINTS] = b;
    Some(pts)
}

/// `n + 1` points at equal arc-length steps along the polyline `p`, first and last exact.
pub fn resample(p: &[DVec2], n: usize) -> Vec<DVec2> {
    let n = n.max(1);
    let total = polyline_length(p);
    let mut out = Vec::with_capacity(n + 1);
    out.push(p[0]);
    let (mut seg, mut walked) = (0usize, 0.0f64);
    for k in 1..n {
        let target = total * k as f64 / n as f64;
        while seg + 1 < p.len() - 1 && walked + p[seg].distance(p[seg + 1]) < target {
            walked += p[seg].distance(p[seg + 1]);
            seg += 1;
        }
        let len = p[seg].distance(p[seg + 1]);
        let t = if len > 0.0 { ((target - walked) / len).clamp(0.0, 1.0) } else { 0.0 };
        out.push(p[seg].lerp(p[seg + 1], t));
    }
    out.push(*p.last().expect("a polyline has points"));
    out
}

fn orient(a: DVec2, b: DVec2, c: DVec2) -> f64 {
    (b - a).perp_dot(c - a)
}

/// True when closed segments `ab` and `cd` share a point.
fn segments_touch(a: DVec2, b: DVec2, c: DVec2, d: DVec2) -> bool {
    let (o1, o2, o3, o4) = (orient(a, b, c), orient(a, b, d), orient(c, d, a), orient(c, d, b));
    if o1 * o2 < 0.0 && o3 * o4 < 0.0 {
        return true;
    }
    let within = |p: DVec2, q: DVec2, r: DVec2| {
        r.x >= p.x.min(q.x) && r.x <= p.x.max(q.x) && r.y >= p.y.min(q.y) && r.y <= p.y.max(q.y)
    };
    (o1 == 0.0 && within(a, b, c))
        || (o2 == 0.0 && within(a, b, d))
        || (o3 == 0.0 && within(c, d, a))
        || (o4 == 0.0 && within(c, d, b))
}

/// The first pair of outline segments that touch other than at their shared corner, as the
/// edges (`owner` of each segment) they belong to; `None` for a simple closed polyline.
/// Segments are sorted by their lower x so only overlapping x ranges are compared.
pub fn first_crossing(pts: &[DVec2], owner: &[usize]) -> Option<(usize, usize)> {
    let m = pts.len();
    let seg = |i: usize| (pts[i], pts[(i + 1) % m]);
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&i, &j| {
        let (a, b) = (seg(i), seg(j));
        a.0.x.min(a.1.x).total_cmp(&b.0.x.min(b.1.x)).then(i.cmp(&j))
    });
    let mut found: Option<(usize, usize)> = None;
    for (k, &i) in order.iter().enumerate() {
        let (a, b) = seg(i);
        let hi = a.x.max(b.x);
        for &j in &order[k + 1..] {
            let (c, d) = seg(j);
            if c.x.min(d.x) > hi {
                break;
            }
            let (lo, hi2) = (i.min(j), i.max(j));
            let adjacent = hi2 == lo + 1 || (lo == 0 && hi2 == m - 1);
            let touch = if adjacent {
                // Neighbours share a corner; they overlap only when the outline folds back.
                let (shared, p, q) =
                    if hi2 == lo + 1 { (pts[hi2], pts[lo], pts[(hi2 + 1) % m]) } else { (pts[0], pts[1], pts[m - 1]) };
                let (u, w) = (p - shared, q - shared);
                u.perp_dot(w).abs() <= 1e-12 * u.length() * w.length() && u.dot(w) > 0.0
            } else {
                segments_touch(a, b, c, d)
            };
            if touch {
                let pair = (owner[lo].min(owner[hi2]), owner[lo].max(owner[hi2]));
                found = Some(found.map_or(pair, |f| f.min(pair)));
            }
        }
    }
    found
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn quarter_arc_matches_the_circle() {
        // From (1, 0) to (0, 1) counter-clockwise (sweep) with radius 1: the centre is the origin.
        let p = arc(DVec2::X, DVec2::Y, 1.0, false, true).unwrap();
        assert!(p.iter().all(|q| (q.length() - 1.0).abs() < 1e-12));
        assert!(p[CURVE_POINTS / 2].distance(DVec2::splat(0.5f64.sqrt())) < 1e-12);
        // Clockwise (no sweep), small arc: the centre is (1, 1), the arc bulges towards the origin.
        let q = arc(DVec2::X, DVec2::Y, 1.0, false, false).unwrap();
        assert!(q.iter().all(|r| (r.distance(DVec2::ONE) - 1.0).abs() < 1e-12));
        assert!(q[CURVE_POINTS / 2].length() < 0.5);
        // Large arc, counter-clockwise: three quarters of the circle around (1, 1).
        let l = arc(DVec2::X, DVec2::Y, 1.0, true, true).unwrap();
        // 64 chords of 4.2 degrees fall short of the arc by (dθ)²/24 of its length: 1.1e-3.
        let len = polyline_length(&l);
        assert!((len - 1.5 * std::f64::consts::PI).abs() < 1.2e-3, "{len}");
        // A radius too small is scaled up to half the chord: a half circle.
        let h = arc(DVec2::ZERO, DVec2::new(2.0, 0.0), 0.1, false, true).unwrap();
        assert!((polyline_length(&h) - std::f64::consts::PI).abs() < 1e-3);
        assert!(arc(DVec2::ZERO, DVec2::ZERO, 1.0, false, true).is_none());
    }

    #[test]
    fn resampling_is_uniform_in_arc_length() {
        let p = [DVec2::ZERO, DVec2::new(3.0, 0.0), DVec2::new(3.0, 1.0)];
        let r = resample(&p, 4);
        assert_eq!(r.len(), 5);
        for w in r.windows(2) {
            assert!((w[0].distance(w[1]) - 1.0).abs() < 1e-12 || w[0].x == 3.0 || w[1].x == 3.0);
        }
        assert_eq!(r[3], DVec2::new(3.0, 0.0));
        assert_eq!(r[4], DVec2::new(3.0, 1.0));
    }

    #[test]
    fn crossing_names_the_edges() {
        // A bow tie: edge 0 (0,0)-(2,2)... as four one-segment edges; 0 and 2 cross.
        let pts = [DVec2::ZERO, DVec2::new(2.0, 2.0), DVec2::new(2.0, 0.0), DVec2::new(0.0, 2.0)];
        assert_eq!(first_crossing(&pts, &[0, 1, 2, 3]), Some((0, 2)));
        let square = [DVec2::ZERO, DVec2::X, DVec2::ONE, DVec2::Y];
        assert_eq!(first_crossing(&square, &[0, 1, 2, 3]), None);
        // Folding back onto the previous segment.
        let fold = [DVec2::ZERO, DVec2::new(2.0, 0.0), DVec2::new(1.0, 0.0), DVec2::new(1.0, 1.0)];
        assert!(first_crossing(&fold, &[0, 1, 2, 3]).is_some());
    }
}

//! The Monte-Carlo reference of eq. 3.42: the embedded glossiness lobe integrated against the
//! original (unfiltered) map, so the filtered-PEM approximation's error can be measured.

use glam::Vec3;

use super::cube::CubeImage;

/// The i-th of `n` Hammersley points in [0, 1)^2: ((i + 0.5)/n, radical inverse of i in base 2).
pub fn hammersley(i: u32, n: u32) -> (f32, f32) {
    ((i as f32 + 0.5) / n as f32, (i.reverse_bits() as f64 / 4294967296.0) as f32)
}

/// An orthonormal basis (t, b) perpendicular to unit `n` (Duff et al. 2017).
fn basis(n: Vec3) -> (Vec3, Vec3) {
    let sign = 1.0f32.copysign(n.z);
    let a = -1.0 / (sign + n.z);
    let b = n.x * n.y * a;
    (Vec3::new(1.0 + sign * n.x * n.x * a, sign * b, -sign * n.x), Vec3::new(b, sign + n.y * n.y * a, -n.y))
}

/// integral env(w) max(0, r'.w)^s dw / (2 pi/(s+1)) with r' normalized: the Phong lobe of
/// exponent `s` about `r_prime`, normalized to unit weight, against `cube` (level 0, looked up
/// with [`CubeImage::sample`]). Importance sampling of the normalized lobe (pdf (s+1)/(2 pi)
/// cos^s theta: cos theta = u^(1/(s+1)), phi = 2 pi v) with `samples` Hammersley points, so the
/// estimate is the plain mean of the lookups and is deterministic.
pub fn embedded_lobe(cube: &CubeImage, r_prime: Vec3, s: f32, samples: usize) -> Vec3 {
    let axis = r_prime.normalize();
    let (t, b) = basis(axis);
    let n = samples.max(1) as u32;
    let mut sum = glam::DVec3::ZERO;
    for i in 0..n {
        let (u, v) = hammersley(i, n);
        let cos = u.powf(1.0 / (s + 1.0));
        let sin = (1.0 - cos * cos).max(0.0).sqrt();
        let phi = std::f32::consts::TAU * v;
        let w = t * (sin * phi.cos()) + b * (sin * phi.sin()) + axis * cos;
        sum += cube.sample(w).truncate().as_dvec3();
    }
    (sum / n as f64).as_vec3()
}

/// The same integral by quadrature over every texel of `cube` (each weighted by the lobe and
/// its exact solid angle, normalized by the weights' sum): noise-free, so it measures small
/// errors that Monte-Carlo noise around a bright sun would hide; costs 6 size^2 per call.
pub fn embedded_lobe_quadrature(cube: &CubeImage, r_prime: Vec3, s: f32) -> Vec3 {
    let axis = r_prime.normalize();
    let size = cube.size;
    let (mut sum, mut total) = (glam::DVec3::ZERO, 0.0f64);
    for (i, t) in cube.texels.iter().enumerate() {
        let (face, x, y) = (i / (size * size), i % size, (i / size) % size);
        let c = axis.dot(super::cube::texel_dir(size, face, x, y));
        if c > 0.0 {
            let w = c.powf(s) as f64 * super::cube::texel_solid_angle(size, x, y) as f64;
            sum += t.truncate().as_dvec3() * w;
            total += w;
        }
    }
    (sum / total.max(1e-300)).as_vec3()
}

/// The reference shading of eqs. 3.39-3.42 for unit normal `n`, unit direction to the eye
/// `v_to_eye` and glossiness `g`: r = reflect(-v, n), r' = n(1-g) + r g, s = 1/(1-g), the
/// [`embedded_lobe`] along r' with `samples` samples (0: [`embedded_lobe_quadrature`]).
/// g >= 1 is the mirror: `cube.sample(r)`.
pub fn shade(cube: &CubeImage, n: Vec3, v_to_eye: Vec3, g: f32, samples: usize) -> Vec3 {
    let r = 2.0 * n.dot(v_to_eye) * n - v_to_eye;
    if g >= 1.0 {
        return cube.sample(r).truncate();
    }
    let g = g.max(0.0);
    let r_prime = n * (1.0 - g) + r * g;
    let s = 1.0 / (1.0 - g);
    if samples == 0 { embedded_lobe_quadrature(cube, r_prime, s) } else { embedded_lobe(cube, r_prime, s, samples) }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::ibl::cube::texel_dir;
    use glam::Vec4;

    /// A map of max(0, d.y).
    fn sky(size: usize) -> CubeImage {
        CubeImage::from_fn(size, |f, x, y| Vec4::splat(texel_dir(size, f, x, y).y.max(0.0)))
    }

    /// integral max(0, y.w) max(0, r.w) dw / pi for the angle gamma between r and +Y:
    /// (2/3)((pi - gamma) cos gamma + sin gamma) / pi (the clamped-cosine product integral;
    /// 2 pi/3 at gamma = 0 = the hemisphere integral of cos^2, 2/3 at gamma = pi/2).
    fn analytic(gamma: f32) -> f32 {
        let pi = std::f32::consts::PI;
        (2.0 / 3.0) * ((pi - gamma) * gamma.cos() + gamma.sin()) / pi
    }

    #[test]
    fn monte_carlo_converges_to_the_quadrature() {
        let map = CubeImage::from_fn(16, |f, x, y| {
            let d = texel_dir(16, f, x, y);
            Vec4::splat(1.0 + 0.5 * d.x + 4.0 * d.z.max(0.0).powi(3))
        });
        for s in [1.0, 4.0, 20.0] {
            let axis = Vec3::new(0.2, 0.3, 0.9);
            let exact = embedded_lobe_quadrature(&map, axis, s);
            let err = |n| (embedded_lobe(&map, axis, s, n) - exact).abs().max_element() / exact.max_element();
            assert!(err(256) < 0.05, "s {s}: {} off with 256 samples", err(256));
            assert!(err(16384) < 0.005, "s {s}: {} off with 16384 samples", err(16384));
        }
    }

    #[test]
    fn white_furnace() {
        let white = CubeImage::from_fn(8, |_, _, _| Vec4::ONE);
        for s in [1.0, 2.0, 10.0, 100.0, 1000.0] {
            let c = embedded_lobe(&white, Vec3::new(0.3, -0.2, 0.9), s, 256);
            assert!((c - Vec3::ONE).abs().max_element() < 1e-5, "s {s}: {c}");
        }
        for g in [0.0, 0.5, 0.9, 1.0] {
            let c = shade(&white, Vec3::Y, Vec3::new(0.0, 1.0, 1.0).normalize(), g, 64);
            assert!((c - Vec3::ONE).abs().max_element() < 1e-5, "g {g}: {c}");
        }
    }

    #[test]
    fn a_cosine_sky_matches_its_analytic_integral() {
        let map = sky(64);
        for gamma_deg in [0.0f32, 30.0, 60.0, 90.0, 135.0] {
            let gamma = gamma_deg.to_radians();
            let r = Vec3::new(gamma.sin(), gamma.cos(), 0.0);
            let got = embedded_lobe(&map, r, 1.0, 16384).x;
            let want = analytic(gamma);
            assert!((got - want).abs() < 3e-3, "gamma {gamma_deg}: {got} vs {want}");
        }
        // g = 0: the lobe about the normal (s = 1), whatever the eye.
        let n = Vec3::new(0.5, 0.5, 0.0).normalize();
        let c = shade(&map, n, Vec3::Z, 0.0, 16384).x;
        assert!((c - analytic(std::f32::consts::FRAC_PI_4)).abs() < 3e-3, "{c}");
    }

    #[test]
    fn the_estimate_converges_with_the_sample_count() {
        let map = sky(64);
        let gamma = 1.1f32;
        let r = Vec3::new(gamma.sin(), gamma.cos(), 0.0);
        let want = analytic(gamma);
        let err = |n| (embedded_lobe(&map, r, 1.0, n).x - want).abs();
        let (e16, e256, e16384) = (err(16), err(256), err(16384));
        assert!(e16384 < e256 && e256 < e16 && e16384 < 3e-3, "{e16} {e256} {e16384}");
    }

    #[test]
    fn the_mirror_looks_up_along_r() {
        let map = sky(16);
        let n = Vec3::new(0.2, 1.0, 0.1).normalize();
        let v = Vec3::new(0.5, 0.3, 1.0).normalize();
        let r = 2.0 * n.dot(v) * n - v;
        assert_eq!(shade(&map, n, v, 1.0, 8), map.sample(r).truncate());
    }
}

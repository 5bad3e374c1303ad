//! Reference for Sun et al.'s surface term (physics.md §9): the airlight L_a of §6 arriving
//! from every direction of the hemisphere, weighted by the Lambertian BRDF ρ/π and cosθ_i,
//! integrated numerically in two dimensions. Directions are parametrised around the light
//! (γ from the direction to the light, φ the azimuth), where L_a depends on γ alone and
//! sinγ·dγ removes its 1/γ peak; the clamped cosine is integrated over φ numerically, split
//! where it reaches zero. Nothing here uses the G function or its table.

use super::quad;
use super::sun::sun_la;
use std::f64::consts::{FRAC_PI_2, PI};

/// ∫_0^{2π} max(cosθ_s cosγ + sinθ_s sinγ cosφ, 0) dφ by quadrature.
fn azimuth_quadrature(theta_s: f64, gamma: f64) -> f64 {
    let (a, b) = (theta_s.cos() * gamma.cos(), theta_s.sin() * gamma.sin());
    let mut points = vec![0.0, PI];
    if b.abs() > a.abs() {
        points.push((-a / b).acos());
    }
    let points = quad::breakpoints(points, 0.0, PI);
    2.0 * quad::integrate(|phi| (a + b * phi.cos()).max(0.0), &points, 1e-12, 1e-300, 1000).0
}

/// Radiance scattered by homogeneous fog β onto a diffuse surface of albedo 1 at distance `d`
/// from an isotropic point light of intensity 1, `theta_s` the angle between the normal and
/// the direction to the light (0..π), ignoring occlusion by other surfaces.
pub fn surface_glow_quadrature(beta: f64, d: f64, theta_s: f64) -> f64 {
    if beta <= 0.0 {
        return 0.0;
    }
    let k1 = (FRAC_PI_2 - theta_s).abs();
    let t = beta * d;
    let mut points = vec![k1, PI - k1];
    points.extend([1e-6, 1e-4, 1e-2].iter().map(|k| k / t.max(1e-3)));
    points.extend(crate::sun_table::KNEES.iter().map(|k| (k / t.max(1e-300)).min(PI)));
    let points = quad::breakpoints(points, 0.0, PI);
    let integrand = |g: f64| sun_la(g, d, f64::INFINITY, beta, 1.0) * g.sin() * azimuth_quadrature(theta_s, g) / PI;
    quad::integrate(integrand, &points, 1e-9, 1e-300, 4_000).0
}

/// ∫_0^{2π} max(cosθ_r cosγ + sinθ_r sinγ cosφ, 0)^n dφ by adaptive quadrature.
fn lobe_azimuth_quadrature(theta_r: f64, gamma: f64, n: f64) -> f64 {
    let (a, b) = (theta_r.cos() * gamma.cos(), theta_r.sin() * gamma.sin());
    let mut points = vec![0.0, PI];
    if b.abs() > a.abs() {
        points.push((-a / b).acos());
    }
    if b.abs() > 0.0 && n > 0.0 {
        let sigma = ((a + b.abs()).abs() / (n * b.abs())).sqrt();
        points.extend([0.25, 1.0, 4.0, 16.0].iter().map(|k| k * sigma));
    }
    let points = quad::breakpoints(points, 0.0, PI);
    let lobe = |phi: f64| {
        let c = a + b * phi.cos();
        if c <= 0.0 {
            0.0
        } else if n == 0.0 {
            1.0
        } else {
            c.powf(n)
        }
    };
    2.0 * quad::integrate(lobe, &points, 1e-12, 1e-300, 2000).0
}

/// Radiance scattered by homogeneous fog β onto a Phong-specular surface (specular
/// coefficient 1, exponent n: BRDF·cosθ_i = (n + 1)/(2π)·max(cos α, 0)^n, α the angle to the
/// mirror direction of the view) at distance `d` from an isotropic point light of intensity
/// 1, `theta_r` the angle between the mirror direction and the direction to the light. As in
/// Sun et al., the lobe is integrated over the whole sphere of incoming airlight.
pub fn specular_glow_quadrature(beta: f64, d: f64, theta_r: f64, n: f64) -> f64 {
    if beta <= 0.0 {
        return 0.0;
    }
    let t = beta * d;
    let w = 1.0 / (n + 1.0).sqrt();
    let mut points = vec![(FRAC_PI_2 - theta_r).abs(), theta_r + FRAC_PI_2];
    points.extend([-8.0, -4.0, -2.0, -1.0, 0.0, 1.0, 2.0, 4.0, 8.0].iter().map(|k| theta_r + k * w));
    points.extend([1e-6, 1e-4, 1e-2].iter().map(|k| k / t.max(1e-3)));
    points.extend(crate::sun_table::KNEES.iter().map(|k| (k / t.max(1e-300)).min(PI)));
    let points = quad::breakpoints(points, 0.0, PI);
    let norm = (n + 1.0) / (2.0 * PI);
    let integrand =
        |g: f64| sun_la(g, d, f64::INFINITY, beta, 1.0) * g.sin() * lobe_azimuth_quadrature(theta_r, g, n) * norm;
    quad::integrate(integrand, &points, 1e-9, 1e-300, 4_000).0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Lcg;
    use crate::surface_table::{g_exact, glow_lookup, glow_radiance, glow_table, GLOW_NT, GLOW_NTHETA, GLOW_T_MAX};

    /// Random (β, D, θ_s): optical distances from 1e-3 to 30, every light direction.
    fn cases(n: usize) -> Vec<(f64, f64, f64)> {
        let mut s = Lcg(7);
        (0..n)
            .map(|_| {
                let beta = 10f64.powf(-2.0 + 2.0 * s.f64());
                let t = 10f64.powf(-3.0 + 4.5 * s.f64());
                (beta, t / beta, PI * s.f64())
            })
            .collect()
    }

    #[test]
    fn g_function_matches_hemisphere_quadrature() {
        let mut worst: f64 = 0.0;
        for (beta, d, theta) in cases(60) {
            let want = surface_glow_quadrature(beta, d, theta);
            let got = glow_radiance(beta, d, theta, g_exact);
            assert!(want.is_finite() && want >= 0.0);
            let rel = (got - want).abs() / want.max(1e-300);
            worst = worst.max(rel);
            assert!(rel < 2e-5, "β {beta} D {d} θ {theta}: {got} vs {want}");
        }
        println!("exact G vs hemisphere quadrature: max relative error {worst:.2e}");
    }

    /// The table's error against the hemisphere quadrature, bounded by bilinear
    /// interpolation's error (Δx²/8)|G_xx| + (Δy²/8)|G_yy| with the second derivatives
    /// estimated from the table's own second differences over the neighbouring nodes (×2 for
    /// their variation inside a cell), plus f32 rounding.
    #[test]
    fn glow_table_error_within_bilinear_bound() {
        let table = glow_table();
        let at = |i: usize, j: usize| table[j * GLOW_NT + i] as f64;
        let d2x = |i: usize, j: usize| {
            let i = i.clamp(1, GLOW_NT - 2);
            (at(i - 1, j) - 2.0 * at(i, j) + at(i + 1, j)).abs()
        };
        let d2y = |i: usize, j: usize| {
            let j = j.clamp(1, GLOW_NTHETA - 2);
            (at(i, j - 1) - 2.0 * at(i, j) + at(i, j + 1)).abs()
        };
        let (mut sum, mut max, mut n, mut max_scale) = (0.0f64, 0.0f64, 0usize, 0.0f64);
        for (beta, d, theta) in cases(400) {
            let t = beta * d;
            let want = surface_glow_quadrature(beta, d, theta);
            let got = glow_radiance(beta, d, theta, |t, th| glow_lookup(table, t, th));
            let fx = (t.min(GLOW_T_MAX) / GLOW_T_MAX).sqrt().sqrt() * (GLOW_NT - 1) as f64;
            let fy = theta / PI * (GLOW_NTHETA - 1) as f64;
            let (i, j) = ((fx as usize).min(GLOW_NT - 2), (fy as usize).min(GLOW_NTHETA - 2));
            let mut curv = 0.0f64;
            for (a, b) in [(i, j), (i + 1, j), (i, j + 1), (i + 1, j + 1)] {
                for (a, b) in [(a.saturating_sub(1), b), (a, b.saturating_sub(1)), (a, b), (a + 1, b), (a, b + 1)] {
                    let (a, b) = (a.min(GLOW_NT - 1), b.min(GLOW_NTHETA - 1));
                    curv = curv.max(d2x(a, b) + d2y(a, b));
                }
            }
            let g_want = want / glow_radiance(beta, d, theta, |_, _| 1.0);
            let g_bound = 2.0 * curv / 8.0 + 1e-6 * g_want.abs() + 1e-7;
            let g_got = glow_lookup(table, t, theta);
            assert!(
                (g_got - g_want).abs() <= g_bound,
                "T {t} θ {theta}: G table {g_got} vs quadrature {g_want}, bound {g_bound}"
            );
            // Relative to the light's glow at this distance facing it (θ_s = 0), the scale a
            // viewer sees.
            let scale = glow_radiance(beta, d, 0.0, g_exact);
            let rel = (got - want).abs() / scale;
            max_scale = max_scale.max(rel);
            if want > 1e-3 * scale {
                let r = (got - want).abs() / want;
                sum += r;
                max = max.max(r);
                n += 1;
            }
        }
        println!(
            "glow table {GLOW_NT}x{GLOW_NTHETA} vs hemisphere quadrature: relative mean {:.2e} max {max:.2e} \
             (over {n} samples with term > 1e-3 of the facing value); max error / facing value {max_scale:.2e}",
            sum / n as f64
        );
        assert!(max_scale < 0.01, "{max_scale}");
    }

    /// Random (β, D, θ_r, n): optical distances from 1e-3 to 30, every mirror angle, exponents
    /// from 0 to the table's maximum (uniform in ln(1 + n)), with the ends included.
    fn spec_cases(n: usize) -> Vec<(f64, f64, f64, f64)> {
        use crate::surface_table::SPEC_N_MAX;
        let mut s = Lcg(11);
        let mut out: Vec<(f64, f64, f64, f64)> = cases(n)
            .into_iter()
            .map(|(beta, d, theta)| (beta, d, theta, (1.0 + SPEC_N_MAX).powf(s.f64()) - 1.0))
            .collect();
        for (k, c) in out.iter_mut().enumerate().take(8) {
            c.3 = if k % 2 == 0 { 0.0 } else { SPEC_N_MAX };
            if k < 4 {
                c.2 = [0.0, 1e-4, PI - 1e-4, PI][k];
            }
        }
        out
    }

    #[test]
    fn specular_s_function_matches_sphere_quadrature() {
        use crate::surface_table::{s_exact, spec_radiance};
        let mut worst: f64 = 0.0;
        for (beta, d, theta, n) in spec_cases(40) {
            let want = specular_glow_quadrature(beta, d, theta, n);
            let got = spec_radiance(beta, d, theta, n, s_exact);
            assert!(want.is_finite() && want >= 0.0 && got.is_finite());
            let scale = spec_radiance(beta, d, 0.0, n, s_exact);
            let rel = (got - want).abs() / want.max(1e-9 * scale).max(1e-300);
            worst = worst.max(rel);
            assert!(rel < 1e-4, "β {beta} D {d} θ_r {theta} n {n}: {got} vs {want}");
        }
        println!("exact S_n vs sphere quadrature: max relative error {worst:.2e}");
    }

    /// The specular table against the sphere quadrature, on random (β, D, θ_r, n) including
    /// the exponent's ends and grazing mirror angles. The error is measured relative to the
    /// term's value with the light at the mirror direction (θ_r = 0), the scale of the glow a
    /// viewer sees in the highlight; the bound is twice the measured figure rounded up.
    #[test]
    fn specular_table_error_against_quadrature() {
        use crate::surface_table::{s_exact, spec_lookup, spec_radiance, spec_table};
        let t0 = std::time::Instant::now();
        let table = spec_table();
        let built = t0.elapsed();
        let (mut sum, mut max, mut n_rel, mut max_scale) = (0.0f64, 0.0f64, 0usize, 0.0f64);
        for (beta, d, theta, n) in spec_cases(150) {
            let want = specular_glow_quadrature(beta, d, theta, n);
            let got = spec_radiance(beta, d, theta, n, |t, th, n| spec_lookup(table, t, th, n));
            assert!(got.is_finite() && got >= 0.0, "β {beta} D {d} θ_r {theta} n {n}: {got}");
            let scale = spec_radiance(beta, d, 0.0, n, s_exact);
            let rel = (got - want).abs() / scale;
            max_scale = max_scale.max(rel);
            if want > 1e-2 * scale {
                let r = (got - want).abs() / want;
                sum += r;
                max = max.max(r);
                n_rel += 1;
            }
        }
        println!(
            "specular table {}x{}x{} (built in {:.2} s) vs sphere quadrature: relative mean {:.2e} max {max:.2e} \
             (over {n_rel} samples with term > 1e-2 of the mirror value); max error / mirror value {max_scale:.2e}",
            crate::surface_table::SPEC_NT,
            crate::surface_table::SPEC_NTHETA,
            crate::surface_table::SPEC_NN,
            built.as_secs_f64(),
            sum / n_rel as f64
        );
        assert!(max_scale < 0.02, "{max_scale}");
    }

    #[test]
    fn specular_at_exponent_one_is_the_diffuse_g_over_pi() {
        use crate::surface_table::s_exact;
        for (t, theta) in [(0.0, 0.3), (0.01, 1.0), (1.0, 2.0), (5.0, 0.1), (30.0, 3.0)] {
            let (s, g) = (s_exact(t, theta, 1.0), g_exact(t, theta) / PI);
            assert!((s - g).abs() <= 1e-7 * g.max(1e-30), "T {t} θ {theta}: {s} vs {g}");
        }
    }
}

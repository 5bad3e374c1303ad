//! Sun et al. 2005's surface term for a diffuse surface (their §4, the "G0" function): the
//! light that homogeneous fog scatters onto a surface point from an isotropic point light,
//! and the 2D table the GPU reads (appended to the F table in `shaders/march.wgsl`'s
//! `sun_table`, read by `shaders/surface_glow.wgsl`).
//!
//! With T = β·D the optical distance from the surface point to the light and θ_s the angle
//! between the normal and the direction to the light, integrating the airlight L_a(γ, D, ∞)
//! (physics.md §6) over the hemisphere with a Lambertian BRDF ρ/π gives
//!
//! ```text
//! L_p,a = (ρ/π) · β I e^{−T} / (2π D) · G(T, θ_s)
//! G(T, θ_s) = ∫_0^π C(θ_s, γ) B(T, γ) dγ
//! B(T, γ) = ∫_{γ/2}^{π/2} exp(−T (cosγ + sinγ tanξ − 1)) dξ
//! ```
//!
//! γ is the angle between an incoming direction and the direction to the light; the sinγ of
//! the solid angle cancels the 1/sinγ of the airlight's A0, and C(θ_s, γ) is the clamped
//! cosine max(cosθ_i, 0) integrated over the azimuth around the light's direction, in closed
//! form. G is the paper's G0 scaled by e^{T}; the exponent in B is ≤ 0, so G is bounded and
//! nothing overflows. The table holds G on x = (T / T_MAX)^{1/4}, y = θ_s / π: near T = 0, G
//! varies like T·ln T, which the fourth root makes smooth enough for bilinear interpolation.

use crate::quad;
use std::f64::consts::{FRAC_PI_2, PI};

/// Largest tabulated optical distance; beyond it G is extended by its 1/T decay (the term
/// carries e^{−T} < 1e-27 there).
pub const GLOW_T_MAX: f64 = 64.0;

/// Table size, nodes on both ends of each axis (T along the first index).
pub const GLOW_NT: usize = 64;
pub const GLOW_NTHETA: usize = 64;

/// C(θ_s, γ) = ∫_0^{2π} max(cosθ_s cosγ + sinθ_s sinγ cosφ, 0) dφ.
pub fn clamped_cosine(theta_s: f64, gamma: f64) -> f64 {
    let a = theta_s.cos() * gamma.cos();
    let b = (theta_s.sin() * gamma.sin()).abs();
    if b <= a.abs() {
        return if a > 0.0 { 2.0 * PI * a } else { 0.0 };
    }
    let c = (-a / b).clamp(-1.0, 1.0);
    let phi0 = c.acos();
    2.0 * (a * phi0 + b * (1.0 - c * c).sqrt())
}

/// B(T, γ), the airlight from the direction at angle γ to the light, scaled by
/// 2π D sinγ e^{T} / (β² I).
pub fn b_exact(t: f64, gamma: f64) -> f64 {
    let lo = 0.5 * gamma;
    if lo >= FRAC_PI_2 {
        return 0.0;
    }
    if t <= 0.0 {
        return FRAC_PI_2 - lo;
    }
    let (s, c) = gamma.sin_cos();
    let t0 = lo.tan();
    // The exponent grows like T sinγ (tanξ − tan(γ/2)): split where it passes 2^k.
    let knees = crate::sun_table::KNEES.iter().map(|k| (t0 + k / (t * s).max(1e-300)).atan()).collect();
    let points = quad::breakpoints(knees, lo, FRAC_PI_2);
    quad::integrate(|xi| (-t * (c + s * xi.tan() - 1.0).max(0.0)).exp(), &points, 1e-12, 0.0, 4_000).0
}

/// G(T, θ_s) to about 1e-10 relative.
pub fn g_exact(t: f64, theta_s: f64) -> f64 {
    let theta_s = theta_s.clamp(0.0, PI);
    let k1 = (FRAC_PI_2 - theta_s).abs();
    let mut points = vec![k1, PI - k1];
    if t > 0.0 {
        points.extend(crate::sun_table::KNEES.iter().map(|k| (k / t).min(PI)));
    }
    let points = quad::breakpoints(points, 0.0, PI);
    quad::integrate(|g| clamped_cosine(theta_s, g) * b_exact(t, g), &points, 1e-10, 1e-300, 4_000).0
}

/// The G table the GPU reads: entry (i, j) at `data[j * GLOW_NT + i]`, T_i = T_MAX (i/(NT−1))⁴,
/// θ_j = π j/(NΘ−1). Built once per process.
pub fn glow_table() -> &'static [f32] {
    static TABLE: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| {
        let mut data = vec![0.0f32; GLOW_NT * GLOW_NTHETA];
        let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
        let rows_per = GLOW_NTHETA.div_ceil(threads);
        std::thread::scope(|s| {
            for (c, rows) in data.chunks_mut(rows_per * GLOW_NT).enumerate() {
                s.spawn(move || {
                    for (n, v) in rows.iter_mut().enumerate() {
                        let (i, j) = (n % GLOW_NT, c * rows_per + n / GLOW_NT);
                        let x = i as f64 / (GLOW_NT - 1) as f64;
                        let theta = PI * j as f64 / (GLOW_NTHETA - 1) as f64;
                        *v = g_exact(GLOW_T_MAX * (x * x) * (x * x), theta) as f32;
                    }
                });
            }
        });
        data
    })
}

/// G from the table, bilinear: the f64 transliteration of `glow_g` in
/// shaders/surface_glow.wgsl.
pub fn glow_lookup(table: &[f32], t: f64, theta_s: f64) -> f64 {
    let tc = t.clamp(0.0, GLOW_T_MAX);
    let fx = (tc / GLOW_T_MAX).sqrt().sqrt() * (GLOW_NT - 1) as f64;
    let fy = (theta_s / PI).clamp(0.0, 1.0) * (GLOW_NTHETA - 1) as f64;
    let i = (fx as usize).min(GLOW_NT - 2);
    let j = (fy as usize).min(GLOW_NTHETA - 2);
    let (tx, ty) = (fx - i as f64, fy - j as f64);
    let at = |i: usize, j: usize| table[j * GLOW_NT + i] as f64;
    let bottom = at(i, j) * (1.0 - tx) + at(i + 1, j) * tx;
    let top = at(i, j + 1) * (1.0 - tx) + at(i + 1, j + 1) * tx;
    let g = bottom * (1.0 - ty) + top * ty;
    if t > GLOW_T_MAX {
        g * GLOW_T_MAX / t
    } else {
        g
    }
}

/// The surface term per unit albedo ρ and intensity I: e^{−βD} β G(βD, θ_s) / (2π² D), with
/// G from `g` (the table or the exact function). 0 without fog.
pub fn glow_radiance(beta: f64, d: f64, theta_s: f64, g: impl Fn(f64, f64) -> f64) -> f64 {
    if beta <= 0.0 {
        return 0.0;
    }
    let d = d.max(1e-12);
    let t = beta * d;
    (-t).exp() * beta * g(t, theta_s) / (2.0 * PI * PI * d)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn clamped_cosine_limits() {
        // Light at the zenith: C = 2π cosγ on the upper half.
        assert!((clamped_cosine(0.0, 0.3) - 2.0 * PI * 0.3f64.cos()).abs() < 1e-12);
        assert_eq!(clamped_cosine(0.0, 2.0), 0.0);
        // Integrated over γ with sinγ: ∫ max(cosθ_i, 0) dω = π for every θ_s.
        for theta in [0.0, 0.7, FRAC_PI_2, 2.5, PI] {
            let points = quad::breakpoints(vec![(FRAC_PI_2 - theta).abs(), PI - (FRAC_PI_2 - theta).abs()], 0.0, PI);
            let total = quad::integrate(|g| clamped_cosine(theta, g) * g.sin(), &points, 1e-12, 0.0, 1000).0;
            assert!((total - PI).abs() < 1e-9, "θ {theta}: {total}");
        }
    }

    #[test]
    fn g_at_zero_thickness_is_closed_form_free_of_nan() {
        for theta in [0.0, 1.0, FRAC_PI_2, 3.0, PI] {
            for t in [0.0, 1e-9, 1e-3, 1.0, 30.0, 64.0, 1e4] {
                let g = g_exact(t, theta);
                assert!(g.is_finite() && g >= 0.0, "G({t}, {theta}) = {g}");
            }
        }
        // Lights below the horizon still light the surface through the fog.
        assert!(g_exact(1.0, 2.5) > 0.0);
    }
}

//! Sun et al. 2005's surface term (their §4, the G functions): the light that homogeneous fog
//! scatters onto a surface point from an isotropic point light, for a diffuse surface and for
//! a Phong-specular one, and the tables the GPU reads (appended to the F table in
//! `shaders/march.wgsl`'s `sun_table`, read by `shaders/surface_glow.wgsl`).
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
//!
//! **Specular.** With the Phong BRDF written as BRDF·cosθ_i = k_s (n + 1)/(2π) max(cos α, 0)^n,
//! α the angle between the incoming direction and the view's mirror direction (k_s is then the
//! reflectance of a uniformly bright sky), the same integral with the lobe in place of the
//! clamped cosine gives
//!
//! ```text
//! L_p,a = k_s · β I e^{−T} / (2π D) · S_n(T, θ_r)
//! S_n(T, θ_r) = (n + 1)/(2π) ∫_0^π C_n(θ_r, γ) B(T, γ) dγ
//! C_n(θ_r, γ) = ∫_0^{2π} max(cosθ_r cosγ + sinθ_r sinγ cosφ, 0)^n dφ
//! ```
//!
//! θ_r the angle between the mirror direction and the direction to the light. S_1 = G/π: the
//! diffuse case is the lobe n = 1 around the normal. As in the paper the lobe is integrated over
//! the whole sphere: airlight from below the surface's horizon, which a lobe reaches when the
//! view grazes the surface, is counted. So S depends on T, θ_r and n alone, and the table has
//! a third axis, n from 0 to [`SPEC_N_MAX`] uniform in ln(1 + n), linear between nodes. S peaks like 1/w_n (w_n = 1/sqrt(n + 1), the lobe's width) at
//! θ_r = 0 and falls like 1/θ_r beyond the lobe, so each exponent node stores
//! S·sqrt(θ_r² + w_n²) on an angle axis that is linear within w_n and logarithmic beyond.

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
    b_with_tolerance(t, gamma, 1e-12)
}

fn b_with_tolerance(t: f64, gamma: f64, tol: f64) -> f64 {
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
    quad::integrate(|xi| (-t * (c + s * xi.tan() - 1.0).max(0.0)).exp(), &points, tol, 0.0, 4_000).0
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
/// θ_j = π j/(NΘ−1). Embedded from [`GLOW_TABLE_FILE`]: [`compute_glow_table`] takes seconds
/// of quadrature, which every start of the program would pay.
pub fn glow_table() -> &'static [f32] {
    static TABLE: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| decode_table(include_bytes!("../assets/tables/glow_g.f32"), GLOW_NT * GLOW_NTHETA))
}

/// Where the embedded G table lives in the source tree.
pub const GLOW_TABLE_FILE: &str = "assets/tables/glow_g.f32";
/// Where the embedded specular table lives in the source tree.
pub const SPEC_TABLE_FILE: &str = "assets/tables/spec_s.f32";

/// An embedded table: little-endian f32 values, `len` of them (the build's own file, so a
/// wrong length is a defect of the tree, caught by the tests).
fn decode_table(bytes: &[u8], len: usize) -> Vec<f32> {
    assert_eq!(bytes.len(), 4 * len, "an embedded surface table has the wrong size: regenerate it with FOGSMITH_WRITE_TABLES=1 cargo test --release --lib embedded_tables");
    bytes.chunks_exact(4).map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]])).collect()
}

/// A table as the bytes of its file in `assets/tables/`.
pub fn tables_file_bytes(table: &[f32]) -> Vec<u8> {
    table.iter().flat_map(|v| v.to_le_bytes()).collect()
}

/// The G table by hemisphere quadrature, the source of [`glow_table`].
pub fn compute_glow_table() -> Vec<f32> {
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

/// Largest Phong exponent the specular table covers (projects are refused above it).
pub const SPEC_N_MAX: f64 = 1000.0;

/// Specular table size: optical distance (as [`GLOW_NT`]), angle to the mirror direction,
/// Phong exponent. Entry (i, j, k) at `data[(k * SPEC_NTHETA + j) * SPEC_NT + i]`.
pub const SPEC_NT: usize = 48;
pub const SPEC_NTHETA: usize = 48;
pub const SPEC_NN: usize = 16;

/// The angular scale of a Phong lobe cos^n: where the table's angle axis turns from linear to
/// logarithmic, and the width that keeps the stored values bounded.
pub fn lobe_width(n: f64) -> f64 {
    1.0 / (n + 1.0).sqrt()
}

/// The exponent of the table's k-th node: uniform in ln(1 + n) from 0 to [`SPEC_N_MAX`].
pub fn spec_node_exponent(k: usize) -> f64 {
    (1.0 + SPEC_N_MAX).powf(k as f64 / (SPEC_NN - 1) as f64) - 1.0
}

/// The 8-point Gauss–Legendre rule on [−1, 1]: (node, weight), positive half.
const GL8: [(f64, f64); 4] = [
    (0.183_434_642_495_65, 0.362_683_783_378_362),
    (0.525_532_409_916_329, 0.313_706_645_877_887_3),
    (0.796_666_477_413_626_7, 0.222_381_034_453_374_5),
    (0.960_289_856_497_536_3, 0.101_228_536_290_376_3),
];

/// ∫ f over the consecutive intervals between the sorted `points`, 8-point Gauss–Legendre on each.
fn gl8_panels(f: impl Fn(f64) -> f64, points: &[f64]) -> f64 {
    points
        .windows(2)
        .map(|w| {
            let (m, h) = (0.5 * (w[0] + w[1]), 0.5 * (w[1] - w[0]));
            h * GL8.iter().map(|(x, wt)| wt * (f(m - h * x) + f(m + h * x))).sum::<f64>()
        })
        .sum()
}

/// C_n(θ_r, γ) = ∫_0^{2π} max(cosθ_r cosγ + sinθ_r sinγ cosφ, 0)^n dφ: the Phong lobe around
/// the mirror direction integrated over the azimuth around the light's direction. Panels at
/// multiples of the lobe's width in φ and towards the end of its support; about 1e-9 relative.
pub fn lobe_azimuth(theta_r: f64, gamma: f64, n: f64) -> f64 {
    let a = theta_r.cos() * gamma.cos();
    let b = (theta_r.sin() * gamma.sin()).abs();
    if a + b <= 0.0 {
        return 0.0;
    }
    let phi0 = if a >= b { PI } else { (-a / b).clamp(-1.0, 1.0).acos() };
    if n == 0.0 {
        return 2.0 * phi0;
    }
    if b <= 1e-14 * (a + b) {
        return 2.0 * PI * a.max(0.0).powf(n);
    }
    let sigma = ((a + b) / (n * b)).sqrt();
    let mut points: Vec<f64> = (-1..=4).map(|k| sigma * 2f64.powi(k)).collect();
    points.extend((1..=4).map(|k| phi0 * (1.0 - 0.25f64.powi(k))));
    let points = quad::breakpoints(points, 0.0, phi0);
    2.0 * gl8_panels(|phi| (a + b * phi.cos()).max(0.0).powf(n), &points)
}

/// S_n(T, θ_r) = (n + 1)/(2π) ∫_0^π C_n(θ_r, γ) B(T, γ) dγ, the specular counterpart of G
/// (S_1(T, θ) = G(T, θ)/π), by adaptive quadrature: about 1e-8 relative.
pub fn s_exact(t: f64, theta_r: f64, n: f64) -> f64 {
    let theta_r = theta_r.clamp(0.0, PI);
    let w = lobe_width(n);
    let mut points = vec![(FRAC_PI_2 - theta_r).abs(), theta_r + FRAC_PI_2];
    points.extend([-8.0, -4.0, -2.0, -1.0, 0.0, 1.0, 2.0, 4.0, 8.0].iter().map(|k| theta_r + k * w));
    if t > 0.0 {
        points.extend(crate::sun_table::KNEES.iter().map(|k| (k / t).min(PI)));
    }
    let points = quad::breakpoints(points, 0.0, PI);
    let g = quad::integrate(|g| lobe_azimuth(theta_r, g, n) * b_exact(t, g), &points, 1e-9, 1e-300, 4_000).0;
    (n + 1.0) / (2.0 * PI) * g
}

/// The γ nodes and weights the table's γ integral uses: 8-point Gauss–Legendre on `panels`
/// equal panels over [0, π], the first split geometrically down to 2^−8 of its width (B
/// changes on the scale 1/T near γ = 0).
fn table_gamma_rule(panels: usize) -> Vec<(f64, f64)> {
    let h = PI / panels as f64;
    let mut points: Vec<f64> = (0..=panels).map(|i| h * i as f64).collect();
    points.extend((1..=8).map(|k| h * 0.5f64.powi(k)));
    let points = quad::breakpoints(points, 0.0, PI);
    let mut rule = Vec::new();
    for w in points.windows(2) {
        let (m, hh) = (0.5 * (w[0] + w[1]), 0.5 * (w[1] - w[0]));
        for (x, wt) in GL8 {
            rule.push((m - hh * x, hh * wt));
            rule.push((m + hh * x, hh * wt));
        }
    }
    rule
}

/// Exponents from which the table's γ integral uses the fine rule: the lobe is then narrower
/// than a few coarse panels.
const FINE_RULE_FROM: f64 = 30.0;

/// The table's angle node j for a lobe of width `w`: θ_j = w·sinh(y_j·asinh(π/w)), y_j = j/(NΘ−1):
/// linear within the lobe, logarithmic beyond, where the glow falls like 1/θ.
fn spec_theta(j: usize, w: f64) -> f64 {
    let y = j as f64 / (SPEC_NTHETA - 1) as f64;
    (w * (y * (PI / w).asinh()).sinh()).min(PI)
}

/// The specular table the GPU reads: H = S_n(T, θ_r)·sqrt(θ_r² + w_n²) (bounded: S peaks like
/// 1/w_n at θ_r = 0 and falls like 1/θ_r), at T_i = T_MAX (i/(NT−1))⁴, θ_j as [`spec_theta`],
/// n_k as [`spec_node_exponent`]. Embedded from [`SPEC_TABLE_FILE`], as [`glow_table`] is.
pub fn spec_table() -> &'static [f32] {
    static TABLE: std::sync::OnceLock<Vec<f32>> = std::sync::OnceLock::new();
    TABLE.get_or_init(|| decode_table(include_bytes!("../assets/tables/spec_s.f32"), SPEC_NT * SPEC_NTHETA * SPEC_NN))
}

/// The specular table by quadrature, the source of [`spec_table`]. The γ integral uses one
/// fixed Gauss–Legendre rule, so B is computed once per T.
pub fn compute_spec_table() -> Vec<f32> {
    let (fine, coarse) = (table_gamma_rule(256), table_gamma_rule(64));
    let rule: Vec<(f64, f64)> = fine.iter().chain(&coarse).copied().collect();
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let ts: Vec<f64> = (0..SPEC_NT)
        .map(|i| {
            let x = i as f64 / (SPEC_NT - 1) as f64;
            GLOW_T_MAX * (x * x) * (x * x)
        })
        .collect();
    // B(T_i, γ_q)·weight_q, T fastest per γ node.
    let mut bw = vec![0.0f64; rule.len() * SPEC_NT];
    let per = rule.len().div_ceil(threads);
    std::thread::scope(|s| {
        for (c, chunk) in bw.chunks_mut(per * SPEC_NT).enumerate() {
            let (rule, ts) = (&rule, &ts);
            s.spawn(move || {
                for (n, v) in chunk.iter_mut().enumerate() {
                    let (q, i) = (c * per + n / SPEC_NT, n % SPEC_NT);
                    *v = b_with_tolerance(ts[i], rule[q].0, 1e-10) * rule[q].1;
                }
            });
        }
    });
    let mut data = vec![0.0f32; SPEC_NT * SPEC_NTHETA * SPEC_NN];
    let rows = SPEC_NTHETA * SPEC_NN;
    let rows_per = rows.div_ceil(threads);
    std::thread::scope(|s| {
        for (c, block) in data.chunks_mut(rows_per * SPEC_NT).enumerate() {
            let (rule, bw, fine) = (&rule, &bw, &fine);
            s.spawn(move || {
                for (r, row) in block.chunks_mut(SPEC_NT).enumerate() {
                    let row_index = c * rows_per + r;
                    let (j, k) = (row_index % SPEC_NTHETA, row_index / SPEC_NTHETA);
                    let n = spec_node_exponent(k);
                    let w = lobe_width(n);
                    let theta = spec_theta(j, w);
                    let mut g = vec![0.0f64; SPEC_NT];
                    // Beyond δ from the mirror direction the lobe is below 1e-12 of its peak.
                    let delta = if n > 0.0 { (1e-12f64.powf(1.0 / n)).acos() + 1e-3 } else { PI };
                    let range = if n >= FINE_RULE_FROM { 0..fine.len() } else { fine.len()..rule.len() };
                    for q in range {
                        let gamma = rule[q].0;
                        if (gamma - theta).abs() > delta {
                            continue;
                        }
                        let cn = lobe_azimuth(theta, gamma, n);
                        if cn != 0.0 {
                            for (i, gi) in g.iter_mut().enumerate() {
                                *gi += cn * bw[q * SPEC_NT + i];
                            }
                        }
                    }
                    let scale = (n + 1.0) / (2.0 * PI) * (theta * theta + w * w).sqrt();
                    for (v, gi) in row.iter_mut().zip(&g) {
                        *v = (gi * scale) as f32;
                    }
                }
            });
        }
    });
    data
}

/// S_n from the table: bilinear in (T, θ_r) at the two exponent nodes around n (each with its
/// own angle axis), linear in ln(1 + n) between them, divided by sqrt(θ_r² + w_n²). The f64
/// transliteration of `spec_s` in shaders/surface_glow.wgsl.
pub fn spec_lookup(table: &[f32], t: f64, theta_r: f64, n: f64) -> f64 {
    let tc = t.clamp(0.0, GLOW_T_MAX);
    let theta = theta_r.clamp(0.0, PI);
    let nc = n.clamp(0.0, SPEC_N_MAX);
    let fx = (tc / GLOW_T_MAX).sqrt().sqrt() * (SPEC_NT - 1) as f64;
    let i = (fx as usize).min(SPEC_NT - 2);
    let tx = fx - i as f64;
    let fz = (1.0 + nc).ln() / (1.0 + SPEC_N_MAX).ln() * (SPEC_NN - 1) as f64;
    let k = (fz as usize).min(SPEC_NN - 2);
    let tz = fz - k as f64;
    let at_node = |k: usize| {
        let w = lobe_width(spec_node_exponent(k));
        let fy = ((theta / w).asinh() / (PI / w).asinh()).clamp(0.0, 1.0) * (SPEC_NTHETA - 1) as f64;
        let j = (fy as usize).min(SPEC_NTHETA - 2);
        let ty = fy - j as f64;
        let at = |i: usize, j: usize| table[(k * SPEC_NTHETA + j) * SPEC_NT + i] as f64;
        let bottom = at(i, j) * (1.0 - tx) + at(i + 1, j) * tx;
        let top = at(i, j + 1) * (1.0 - tx) + at(i + 1, j + 1) * tx;
        bottom * (1.0 - ty) + top * ty
    };
    let h = at_node(k) * (1.0 - tz) + at_node(k + 1) * tz;
    let w = lobe_width(nc);
    let s = h / (theta * theta + w * w).sqrt();
    if t > GLOW_T_MAX {
        s * GLOW_T_MAX / t
    } else {
        s
    }
}

/// The specular surface term per unit specular coefficient and intensity:
/// e^{−βD} β S_n(βD, θ_r) / (2π D), θ_r the angle between the mirror direction of the view
/// and the direction to the light, S from `s` (the table or the exact function). 0 without fog.
pub fn spec_radiance(beta: f64, d: f64, theta_r: f64, n: f64, s: impl Fn(f64, f64, f64) -> f64) -> f64 {
    if beta <= 0.0 {
        return 0.0;
    }
    let d = d.max(1e-12);
    let t = beta * d;
    (-t).exp() * beta * s(t, theta_r, n) / (2.0 * PI * d)
}

/// The Phong lobe's direct reflection per unit specular coefficient: (n + 1)/(2π)·cos^n α for
/// cos α > 0 (cos^0 = 1 there), else 0.
pub fn phong_lobe(cos_alpha: f64, n: f64) -> f64 {
    if cos_alpha <= 0.0 {
        return 0.0;
    }
    (n + 1.0) / (2.0 * PI) * if n == 0.0 { 1.0 } else { cos_alpha.powf(n) }
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

    /// The embedded tables are what the quadrature gives today (to f32 rounding, whatever the
    /// platform's libm): a change to the quadrature or a table's layout fails here until the
    /// files are regenerated with `FOGSMITH_WRITE_TABLES=1 cargo test --release --lib
    /// embedded_tables`.
    #[test]
    fn embedded_tables_match_the_quadrature() {
        let root = std::path::Path::new(env!("CARGO_MANIFEST_DIR"));
        for (name, file, embedded, computed) in [
            ("G", GLOW_TABLE_FILE, glow_table(), compute_glow_table()),
            ("specular", SPEC_TABLE_FILE, spec_table(), compute_spec_table()),
        ] {
            if std::env::var_os("FOGSMITH_WRITE_TABLES").is_some() {
                std::fs::write(root.join(file), tables_file_bytes(&computed)).unwrap();
                continue;
            }
            assert_eq!(embedded.len(), computed.len(), "{name} table ({file}): size");
            let peak = computed.iter().fold(0.0f32, |m, v| m.max(v.abs()));
            for (n, (a, b)) in embedded.iter().zip(&computed).enumerate() {
                assert!(
                    b.is_finite() && (a - b).abs() <= 1e-6 * peak,
                    "{name} table ({file}) entry {n}: embedded {a}, quadrature {b}"
                );
            }
        }
    }
}

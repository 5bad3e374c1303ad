//! Globally adaptive Gauss–Kronrod (7/15-point) quadrature, the reference's tool for
//! integrals without a closed form (the Sun special function, the adaptive radiance
//! integral, brute-force checks in tests).

const XGK: [f64; 8] = [
    0.991_455_371_120_812_6,
    0.949_107_912_342_758_5,
    0.864_864_423_359_769_1,
    0.741_531_185_599_394_4,
    0.586_087_235_467_691_1,
    0.405_845_151_377_397_2,
    0.207_784_955_007_898_5,
    0.0,
];
const WGK: [f64; 8] = [
    0.022_935_322_010_529_22,
    0.063_092_092_629_978_55,
    0.104_790_010_322_250_18,
    0.140_653_259_715_525_92,
    0.169_004_726_639_267_9,
    0.190_350_578_064_785_4,
    0.204_432_940_075_298_9,
    0.209_482_141_084_727_83,
];
/// Gauss weights for the Kronrod nodes with odd index (1, 3, 5, 7).
const WG: [f64; 4] =
    [0.129_484_966_168_869_7, 0.279_705_391_489_276_7, 0.381_830_050_505_118_9, 0.417_959_183_673_469_4];

/// One 15-point Kronrod estimate and its difference to the embedded 7-point Gauss rule.
fn gk15(f: &mut impl FnMut(f64) -> f64, a: f64, b: f64) -> (f64, f64) {
    let c = 0.5 * (a + b);
    let h = 0.5 * (b - a);
    let fc = f(c);
    let mut k = fc * WGK[7];
    let mut g = fc * WG[3];
    for j in 0..7 {
        let x = h * XGK[j];
        let s = f(c - x) + f(c + x);
        k += WGK[j] * s;
        if j % 2 == 1 {
            g += WG[j / 2] * s;
        }
    }
    (k * h, ((k - g) * h).abs())
}

/// ∫ f over the consecutive intervals between the sorted `points` (at least two), refining
/// the interval with the largest error estimate until the total error is below
/// `max(abs_tol, rel_tol·|result|)` or `max_intervals` is reached. Returns (value, error).
pub fn integrate(
    mut f: impl FnMut(f64) -> f64,
    points: &[f64],
    rel_tol: f64,
    abs_tol: f64,
    max_intervals: usize,
) -> (f64, f64) {
    let mut parts: Vec<(f64, f64, f64, f64)> = points
        .windows(2)
        .filter(|w| w[1] > w[0])
        .map(|w| {
            let (v, e) = gk15(&mut f, w[0], w[1]);
            (w[0], w[1], v, e)
        })
        .collect();
    loop {
        let total: f64 = parts.iter().map(|p| p.2).sum();
        let err: f64 = parts.iter().map(|p| p.3).sum();
        if parts.is_empty() || err <= abs_tol.max(rel_tol * total.abs()) || parts.len() >= max_intervals {
            return (total, err);
        }
        let (worst, _) =
            parts.iter().enumerate().fold((0, -1.0), |best, (i, p)| if p.3 > best.1 { (i, p.3) } else { best });
        let (a, b, _, _) = parts[worst];
        let m = 0.5 * (a + b);
        if m <= a || m >= b {
            // The interval cannot be split further in f64; accept it as it is.
            parts[worst].3 = 0.0;
            continue;
        }
        let (v1, e1) = gk15(&mut f, a, m);
        let (v2, e2) = gk15(&mut f, m, b);
        parts[worst] = (a, m, v1, e1);
        parts.push((m, b, v2, e2));
    }
}

/// Sorts `points`, removes duplicates and keeps only those within [lo, hi] (both included).
pub fn breakpoints(mut points: Vec<f64>, lo: f64, hi: f64) -> Vec<f64> {
    points.retain(|p| p.is_finite() && *p > lo && *p < hi);
    points.push(lo);
    points.push(hi);
    points.sort_by(f64::total_cmp);
    points.dedup();
    points
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn kronrod_rule_is_exact_for_polynomials_up_to_degree_22() {
        for deg in [0, 1, 5, 13, 22] {
            let (v, _) = gk15(&mut |x: f64| x.powi(deg), 0.0, 1.0);
            assert!((v - 1.0 / (deg as f64 + 1.0)).abs() < 1e-14, "degree {deg}: {v}");
        }
    }

    #[test]
    fn adaptive_handles_a_sharp_peak() {
        let eps = 1e-3_f64;
        let (v, _) = integrate(|x| eps / (x * x + eps * eps), &[-1.0, 1.0], 1e-12, 0.0, 1000);
        let exact = 2.0 * (1.0 / eps).atan();
        assert!((v - exact).abs() < 1e-10 * exact, "{v} vs {exact}");
    }
}

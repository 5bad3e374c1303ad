//! Exact optical depths for suns and exponential height fog (physics.md §9).
//!
//! - [`height_fog_depth`]: the base fog β₀·exp(−k(y − y₀)) integrated along a straight line in
//!   closed form, to a finite length or to infinity.
//! - [`sun_optical_depth`]: from a point towards a directional light: the gaussians clipped to
//!   the grid box (erf integrals, §3) plus the height fog all the way to infinity.

use super::{clip_to_box, Medium64};
use crate::scene::{GridSpec, Medium, Project, MAX_HEIGHT_EXPONENT};
use glam::DVec3;

/// ∫ β(y(t)) dt along `o + t·d` (unit `d`) for t in [0, len] (`len` may be infinite), with
/// β(y) = β₀·exp(−k(y − y₀)) and the exponent clamped at [`MAX_HEIGHT_EXPONENT`] as
/// [`Medium::base_at`] does at the start point. Infinite when the path never thins out (k = 0
/// or not rising, over an infinite length); never NaN.
pub fn height_fog_depth(medium: &Medium, o: DVec3, d: DVec3, len: f64) -> f64 {
    height_fog_depth_raw(medium.base_extinction as f64, medium.height_falloff as f64, medium.height_origin as f64, o, d, len)
}

/// [`height_fog_depth`] with β₀, k and y₀ given.
pub fn height_fog_depth_raw(beta: f64, k: f64, y0: f64, o: DVec3, d: DVec3, len: f64) -> f64 {
    if beta <= 0.0 || len <= 0.0 {
        return 0.0;
    }
    let c = k * d.y;
    let a = (-k * (o.y - y0)).min(MAX_HEIGHT_EXPONENT);
    // ∫_0^L e^{−c t} dt, in log space.
    let log_f = if len.is_infinite() {
        if c <= 0.0 {
            return f64::INFINITY;
        }
        -c.ln()
    } else {
        let x = c * len;
        if x.abs() < 1e-8 {
            len.ln() + (1.0 - 0.5 * x).ln()
        } else if x > 0.0 {
            (-(-x).exp_m1() / c).ln()
        } else {
            -x + (-x.exp_m1() / -c).ln()
        }
    };
    let log_t = beta.ln() + a + log_f;
    if log_t > 700.0 {
        f64::INFINITY
    } else {
        log_t.exp()
    }
}

/// Optical depth from `x` towards a sun whose light travels along `direction`: the project's
/// gaussians over the part of the path inside the grid box plus the base (height) fog along
/// the whole path to infinity.
pub fn sun_optical_depth(project: &Project, gaussians: &Medium64, x: DVec3, direction: DVec3) -> f64 {
    let towards = -direction.normalize();
    let fog = height_fog_depth(&project.medium, x, towards, f64::INFINITY);
    if fog.is_infinite() {
        return fog;
    }
    let grid = &project.grid;
    let inside = match clip_to_box(grid.min.as_dvec3(), grid.max.as_dvec3(), x, towards, f64::INFINITY) {
        Some((t0, t1)) if t1.is_finite() => gaussians.optical_depth(x + towards * t0, x + towards * t1),
        _ => 0.0,
    };
    fog + inside
}

/// The gaussians of `project` without base fog (the base fog is integrated separately).
pub fn gaussians_only(project: &Project) -> Medium64 {
    Medium64::new(0.0, Medium64::from_project(project).gaussians().to_vec())
}

/// [`sun_optical_depth`] of light `light` (a directional light) at the centres of `cells`.
pub fn sun_optical_depth_cells(project: &Project, light: usize, cells: &[[u32; 3]]) -> Vec<f64> {
    sun_optical_depth_cells_with(project, &gaussians_only(project), light, cells)
}

/// [`sun_optical_depth_cells`] with the medium inside the box given (without base fog, such
/// as [`Medium64::without_base`] of a medium with a base volume).
pub fn sun_optical_depth_cells_with(project: &Project, gaussians: &Medium64, light: usize, cells: &[[u32; 3]]) -> Vec<f64> {
    let crate::scene::LightKind::Directional { direction } = project.lights[light].kind else {
        panic!("light {light} is not directional");
    };
    let grid: &GridSpec = &project.grid;
    let mut out = vec![0.0; cells.len()];
    super::par_fill(&mut out, 64, |n| {
        let [i, j, k] = cells[n];
        sun_optical_depth(project, gaussians, super::cell_center64(grid, i, j, k), direction.as_dvec3())
    });
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn medium(beta: f32, k: f32, y0: f32) -> Medium {
        Medium { base_extinction: beta, height_falloff: k, height_origin: y0, ..Medium::default() }
    }

    /// Composite Gauss–Legendre of β along the line, for comparison.
    fn quadrature(m: &Medium, o: DVec3, d: DVec3, len: f64) -> f64 {
        let n = 20_000;
        let h = len / n as f64;
        const X: f64 = 0.577_350_269_189_625_8;
        (0..n)
            .map(|i| {
                let mid = (i as f64 + 0.5) * h;
                [mid - 0.5 * h * X, mid + 0.5 * h * X].iter().map(|&t| m.base_at((o + d * t).y)).sum::<f64>() * 0.5 * h
            })
            .sum()
    }

    #[test]
    fn closed_form_matches_quadrature() {
        let mut s = 0x2545_f491_4f6c_dd1du64;
        let mut r = || {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            (s >> 11) as f64 / (1u64 << 53) as f64
        };
        let mut worst = 0.0f64;
        for _ in 0..200 {
            let m = medium((0.01 + r()) as f32, (r() * 3.0) as f32, (r() * 4.0 - 2.0) as f32);
            let o = DVec3::new(r() * 4.0 - 2.0, r() * 6.0 - 3.0, r() * 4.0 - 2.0);
            let d = DVec3::new(r() - 0.5, r() - 0.5, r() - 0.5).normalize();
            let len = r() * 5.0;
            let want = quadrature(&m, o, d, len);
            let got = height_fog_depth(&m, o, d, len);
            worst = worst.max((got - want).abs() / want.max(1e-300));
        }
        println!("height fog closed form vs quadrature: max relative error {worst:.2e}");
        assert!(worst < 1e-9, "{worst:e}");
    }

    #[test]
    fn extreme_height_fog_is_finite_or_opaque_never_nan() {
        for k in [0.0f32, 1e-6, 1.0, 1e3, 1e6] {
            for y in [-1e9f64, -1e3, -1.0, 0.0, 1.0, 1e3, 1e9] {
                for dy in [-1.0f64, -0.3, 0.0, 1e-9, 0.3, 1.0] {
                    let d = DVec3::new((1.0 - dy * dy).sqrt(), dy, 0.0);
                    for len in [0.0, 1e-6, 1.0, 1e9, f64::INFINITY] {
                        let t = height_fog_depth(&medium(1e12, k, 0.0), DVec3::new(0.0, y, 0.0), d, len);
                        assert!(!t.is_nan() && t >= 0.0, "k {k} y {y} dy {dy} len {len}: {t}");
                    }
                }
            }
        }
        // Thin layer, looking up from far below: finite and equal to β₀e^{k y₀}·e^{−k y}/(k d_y).
        let m = medium(0.5, 1e3, 0.0);
        let t = height_fog_depth(&m, DVec3::new(0.0, 0.01, 0.0), DVec3::Y, f64::INFINITY);
        let want = 0.5 * (-10.0f64).exp() / 1e3;
        assert!((t - want).abs() <= 1e-12 * want, "{t} vs {want}");
    }
}

//! Exact optical depths for suns and exponential height fog (physics.md §9).
//!
//! - [`height_fog_depth`]: the base fog β₀·exp(−k(y − y₀)) integrated along a straight line in
//!   closed form, to a finite length or to infinity.
//! - [`sun_optical_depth`]: from a point towards a directional light: the gaussians clipped to
//!   the grid box (erf integrals, §3) plus the height fog all the way to infinity.
//!
//! ## Why the renderer has no table of optical depth against height and zenith angle
//!
//! Tan et al. tabulate the optical depth towards the sun against height and zenith angle
//! because their atmosphere is spherical: along a ray the height is not linear in the
//! distance, and the integral (a Chapman function) has no closed form. Fogsmith's height fog
//! is planar, β(y) = β₀·exp(−k(y − y₀)): along any straight line y is linear in the distance,
//! so the integral is elementary, exact for a finite segment and to infinity, for every height
//! and zenith angle (physics.md §9). Outside the grid there is only this base fog, and every
//! optical depth the renderer takes there is along a straight line: camera-ray steps, the
//! path from a point or spot light to where it meets the grid box (the propagation schemes'
//! seeds, and the march's light paths outside the box), and a sun's path beyond the box. All
//! of them use the closed form (`base_fog_depth` in `shaders/common.wgsl`, in log space so that
//! nothing overflows), so a table could only add interpolation error. What Sun et al.'s closed
//! form stops covering in height fog is not an optical depth but the in-scattering integral
//! along the camera ray (their F function assumes a constant β): the march integrates it step
//! by step, each step's light-path optical depth from the closed form. The tests below state
//! the closed form's error against quadrature in f64 and in the shader's f32 arithmetic, and
//! `tests/lights.rs` states the pipeline's optical depth towards point lights outside the box
//! against quadrature.

use super::{clip_to_box, Medium64};
use crate::scene::{GridSpec, Medium, Project, MAX_HEIGHT_EXPONENT};
use glam::DVec3;

/// ∫ β(y(t)) dt along `o + t·d` (unit `d`) for t in [0, len] (`len` may be infinite), with
/// β(y) = β₀·exp(−k(y − y₀)) and the exponent clamped at [`MAX_HEIGHT_EXPONENT`] as
/// [`Medium::base_at`] does at the start point. Infinite when the path never thins out (k = 0
/// or not rising, over an infinite length); never NaN.
pub fn height_fog_depth(medium: &Medium, o: DVec3, d: DVec3, len: f64) -> f64 {
    height_fog_depth_raw(
        medium.base_extinction as f64,
        medium.height_falloff as f64,
        medium.height_origin as f64,
        o,
        d,
        len,
    )
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
    Medium64::from_project(project).without_base()
}

/// [`sun_optical_depth`] of light `light` (a directional light) at the centres of `cells`.
pub fn sun_optical_depth_cells(project: &Project, light: usize, cells: &[[u32; 3]]) -> Vec<f64> {
    sun_optical_depth_cells_with(project, &gaussians_only(project), light, cells)
}

/// [`sun_optical_depth_cells`] with the medium inside the box given (without base fog, such
/// as [`Medium64::without_base`] of a medium with a base volume).
pub fn sun_optical_depth_cells_with(
    project: &Project,
    gaussians: &Medium64,
    light: usize,
    cells: &[[u32; 3]],
) -> Vec<f64> {
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
        let mut s = crate::rng::XorShift(0x2545_f491_4f6c_dd1d);
        let mut r = || s.f64();
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

    /// An f32 transliteration of `base_fog_depth` in shaders/common.wgsl.
    fn base_fog_depth32(beta: f32, k: f32, y0: f32, o_y: f32, d_y: f32, len: f32) -> f32 {
        const OPAQUE: f32 = 1e30;
        if beta <= 0.0 {
            return 0.0;
        }
        if k == 0.0 && len >= 0.0 {
            return (beta * len).min(OPAQUE);
        }
        let c = k * d_y;
        let a = (-k * (o_y - y0)).min(MAX_HEIGHT_EXPONENT as f32);
        let log_f = if len < 0.0 {
            if c <= 0.0 {
                return OPAQUE;
            }
            -c.ln()
        } else {
            let x = c * len;
            if x.abs() < 0.1 {
                len.max(1e-30).ln() + (1.0 - x * (0.5 - x * (1.0 / 6.0 - x * (1.0 / 24.0 - x / 120.0)))).ln()
            } else if x > 0.0 {
                ((1.0 - (-x).exp()) / c).ln()
            } else {
                -x + ((1.0 - x.exp()) / -c).ln()
            }
        };
        let log_t = beta.ln() + a + log_f;
        if log_t > 69.0 {
            OPAQUE
        } else {
            log_t.exp()
        }
    }

    /// The closed form as the shaders evaluate it (f32) against adaptive quadrature of β(y)
    /// along the line, over heights from far below y₀ to far above, every zenith angle, finite
    /// segments and paths to infinity: what a table of optical depth against height and zenith
    /// angle would have held. Depths beyond 100 (transmittance below f32's range) need only be
    /// opaque. The bound is 50 f32 ulps (the logarithm of a term of size ~10 loses about 10
    /// ulps to the exponential).
    #[test]
    fn shader_closed_form_matches_quadrature_over_height_and_zenith() {
        let mut s = crate::rng::XorShift(0x0014_7a11);
        let mut r = || s.f64();
        let (mut worst_finite, mut worst_infinite, mut n) = (0.0f64, 0.0f64, 0);
        for _ in 0..2000 {
            let (beta, k, y0) = ((0.01 + r()) as f32, (0.05 + r() * 4.0) as f32, (r() * 4.0 - 2.0) as f32);
            let m = medium(beta, k, y0);
            // Heights within ±8/k of y₀: from 3000× to 1/3000 of β₀.
            let y = (y0 as f64 + (r() * 16.0 - 8.0) / k as f64) as f32;
            let zenith = r() * std::f64::consts::PI;
            let d = DVec3::new(zenith.sin(), zenith.cos(), 0.0);
            let infinite = r() < 0.3;
            if infinite && d.y <= 0.0 {
                continue;
            }
            let len = if infinite { f64::INFINITY } else { 10f64.powf(r() * 4.0 - 2.0) };
            let want = if infinite {
                // Substituting t = s/(1 − s) maps [0, ∞) onto [0, 1).
                let f = |u: f64| m.base_at(y as f64 + d.y * u / (1.0 - u)) / ((1.0 - u) * (1.0 - u));
                crate::quad::integrate(
                    f,
                    &crate::quad::breakpoints((1..12).map(|i| 1.0 - 0.5f64.powi(i)).collect(), 0.0, 1.0),
                    1e-12,
                    0.0,
                    10_000,
                )
                .0
            } else {
                let f = |t: f64| m.base_at(y as f64 + d.y * t);
                crate::quad::integrate(f, &[0.0, len], 1e-12, 0.0, 10_000).0
            };
            let got = base_fog_depth32(beta, k, y0, y, d.y as f32, if infinite { -1.0 } else { len as f32 }) as f64;
            if want > 100.0 {
                // Opaque in f32 (e^{−100} < the smallest f32); the exponent's clamp far below y₀
                // differs between the closed form and β(y) beyond that.
                assert!(got > 100.0, "y {y} zenith {zenith} len {len}: {got} vs {want}");
                continue;
            }
            let rel = (got - want).abs() / want;
            if infinite {
                worst_infinite = worst_infinite.max(rel);
            } else {
                worst_finite = worst_finite.max(rel);
            }
            n += 1;
        }
        println!(
            "height fog optical depth, shader's f32 closed form vs quadrature over {n} (height, zenith, length): \
             max relative error {worst_finite:.2e} for segments, {worst_infinite:.2e} to infinity"
        );
        let bound = 50.0 * f32::EPSILON as f64;
        assert!(worst_finite < bound && worst_infinite < bound, "{worst_finite:e} {worst_infinite:e}");
    }
}

//! Error metrics of physics.md §8: GPU results against the exact f64 reference.
//!
//! Shared by `fogsmith verify`, the benchmarks, the stress matrix and the tests, so every
//! figure Fogsmith reports is computed the same way.

use crate::gpu::Image;
use crate::reference::{
    clipped_optical_depth_cells_with, grid_light_depth_cells, optical_depth_cells, GridMedium64, Medium64,
};
use crate::scene::{GridSpec, Project, Volume};
use serde::Serialize;

/// Every cell when the grid has at most `max` of them, else `max` cells drawn with a fixed
/// seed (so runs are comparable), always including the eight corners.
pub fn sample_cells(grid: &GridSpec, max: usize) -> Vec<[u32; 3]> {
    let r = grid.resolution;
    let n = grid.cell_count() as usize;
    let cell = |idx: usize| grid.cell_of(idx);
    if n <= max {
        return (0..n).map(cell).collect();
    }
    let mut out: Vec<[u32; 3]> =
        (0..8u32).map(|c| [(c & 1) * (r.x - 1), ((c >> 1) & 1) * (r.y - 1), ((c >> 2) & 1) * (r.z - 1)]).collect();
    let mut rng = crate::rng::Lcg(0x9E37_79B9_7F4A_7C15);
    while out.len() < max {
        out.push(cell((rng.next_u64() >> 11) as usize % n));
    }
    out
}

/// Transmittance error of one light's OPV.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct OpvError {
    pub light: usize,
    pub transmittance_max_abs_error: f64,
    pub transmittance_mean_abs_error: f64,
    /// Largest |T − T_exact| / T_exact where T_exact > 0.01.
    pub depth_max_rel_error: f64,
    pub cells: usize,
    /// Whether the compared depths held a NaN or −∞ (counted as error 1).
    pub nan_or_inf: bool,
}

pub fn opv_error(project: &Project, light: usize, opv: &Volume, cells: &[[u32; 3]]) -> OpvError {
    opv_error_against(light, opv, cells, &optical_depth_cells(project, light, cells))
}

/// [`opv_error`] with the exact optical depths at `cells` already computed.
pub fn opv_error_against(light: usize, opv: &Volume, cells: &[[u32; 3]], exact: &[f64]) -> OpvError {
    let got: Vec<f64> = cells.iter().map(|c| opv.get(c[0], c[1], c[2]) as f64).collect();
    depth_error(light, &got, exact)
}

/// Transmittance error of optical depths `got` against `exact`, value by value.
pub fn depth_error(light: usize, got: &[f64], exact: &[f64]) -> OpvError {
    let (mut max, mut sum, mut rel, mut bad) = (0.0f64, 0.0f64, 0.0f64, false);
    for (&t, t_exact) in got.iter().zip(exact) {
        // T = +∞ is an opaque path (transmittance 0), as the reference gives for a sun
        // seen through endless homogeneous fog.
        let e = if !t.is_nan() && t != f64::NEG_INFINITY {
            ((-t).exp() - (-t_exact).exp()).abs()
        } else {
            bad = true;
            1.0
        };
        max = max.max(e);
        sum += e;
        if *t_exact > 0.01 && t.is_finite() {
            rel = rel.max((t - t_exact).abs() / t_exact);
        }
    }
    OpvError {
        light,
        transmittance_max_abs_error: max,
        transmittance_mean_abs_error: sum / got.len().max(1) as f64,
        depth_max_rel_error: rel,
        cells: got.len(),
        nan_or_inf: bad,
    }
}

/// One light's OPV error, split by cause.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct OpvErrors {
    pub light: usize,
    /// The OPV against the line integral through the grid's own trilinear medium: what the
    /// propagation scheme gets wrong.
    pub scheme: OpvError,
    /// The grid's medium against the analytic gaussians clipped to the box: what the grid's
    /// resolution (and injection) gets wrong, whatever the scheme.
    pub resolution: OpvError,
    /// The OPV against the analytic gaussians clipped to the box: both together.
    pub total: OpvError,
}

/// [`OpvErrors`] of `light` at `cells`; `ev` is the extinction volume the OPV was propagated
/// through.
pub fn opv_errors(project: &Project, light: usize, ev: &Volume, opv: &Volume, cells: &[[u32; 3]]) -> OpvErrors {
    opv_errors_with(project, &Medium64::from_project(project), light, ev, opv, cells)
}

/// [`opv_errors`] with the exact medium given: the project's, with its base volume.
pub fn opv_errors_with(
    project: &Project,
    exact: &Medium64,
    light: usize,
    ev: &Volume,
    opv: &Volume,
    cells: &[[u32; 3]],
) -> OpvErrors {
    let medium = GridMedium64::for_project(project, ev);
    let grid_depth = grid_light_depth_cells(project, &medium, light, cells);
    let clipped = clipped_optical_depth_cells_with(project, exact, light, cells);
    let got: Vec<f64> = cells.iter().map(|c| opv.get(c[0], c[1], c[2]) as f64).collect();
    OpvErrors {
        light,
        scheme: depth_error(light, &got, &grid_depth),
        resolution: depth_error(light, &grid_depth, &clipped),
        total: depth_error(light, &got, &clipped),
    }
}

/// Cells below this σ_t (1/m) are left out of the EV's relative error: there the particles'
/// cut-off (each drops below ~1e-6 /m) dominates, and such fog is invisible anyway.
pub const EV_REL_THRESHOLD: f64 = 1e-3;

/// The EV against the analytic σ_t: largest relative error where σ_t ≥ [`EV_REL_THRESHOLD`]
/// and largest absolute error everywhere (both infinite if the EV holds a NaN or infinity).
pub fn ev_error(project: &Project, ev: &Volume, cells: &[[u32; 3]]) -> (f64, f64) {
    ev_error_with(&Medium64::from_project(project), project, ev, cells)
}

/// [`ev_error`] against `medium`: the project's, with its base volume.
pub fn ev_error_with(medium: &Medium64, project: &Project, ev: &Volume, cells: &[[u32; 3]]) -> (f64, f64) {
    let (mut rel, mut abs) = (0.0f64, 0.0f64);
    for c in cells {
        let got = ev.get(c[0], c[1], c[2]) as f64;
        if !got.is_finite() {
            return (f64::INFINITY, f64::INFINITY);
        }
        let want = medium.extinction(crate::reference::cell_center64(&project.grid, c[0], c[1], c[2]));
        abs = abs.max((got - want).abs());
        if want >= EV_REL_THRESHOLD {
            rel = rel.max((got - want).abs() / want);
        }
    }
    (rel, abs)
}

/// Relative RMSE (RMS error over the mean reference radiance, all channels) and largest
/// absolute error of a GPU image against a reference of the same size.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ImageError {
    pub rel_rmse: f64,
    pub max_abs_error: f64,
    pub nan_or_inf: bool,
}

pub fn image_error(image: &Image, reference: &[[f64; 3]]) -> ImageError {
    let (mut sq, mut mean, mut max, mut bad) = (0.0f64, 0.0f64, 0.0f64, false);
    for (p, r) in image.rgba.iter().zip(reference) {
        for c in 0..3 {
            let v = p[c] as f64;
            if !v.is_finite() {
                bad = true;
                continue;
            }
            let d = v - r[c];
            sq += d * d;
            mean += r[c];
            max = max.max(d.abs());
        }
    }
    let n = (reference.len() * 3).max(1) as f64;
    let mean = mean / n;
    let rel_rmse = if mean > 0.0 { (sq / n).sqrt() / mean } else { (sq / n).sqrt() };
    ImageError { rel_rmse, max_abs_error: max, nan_or_inf: bad }
}

/// How far an image is from another of the same size (adaptive sampling against the
/// per-pixel march): RMS error over the mean radiance, and the 99.9th percentile and the
/// largest of each pixel's largest channel error, over the reference's largest channel value.
#[derive(Clone, Copy, Debug, Serialize)]
pub struct ImageDifference {
    pub rel_rmse: f64,
    pub p999_of_max: f64,
    pub max_of_max: f64,
    pub nan_or_inf: bool,
}

pub fn image_difference(image: &Image, reference: &Image) -> ImageDifference {
    let (mut sq, mut sum, mut peak, mut bad) = (0.0f64, 0.0f64, 0.0f64, false);
    let mut errors: Vec<f64> = Vec::with_capacity(reference.rgba.len());
    for (p, r) in image.rgba.iter().zip(&reference.rgba) {
        let mut worst = 0.0f64;
        for c in 0..3 {
            let (v, r) = (p[c] as f64, r[c] as f64);
            if !v.is_finite() {
                bad = true;
                worst = f64::INFINITY;
                continue;
            }
            sq += (v - r) * (v - r);
            sum += r;
            peak = peak.max(r);
            worst = worst.max((v - r).abs());
        }
        errors.push(worst);
    }
    let n = (reference.rgba.len() * 3).max(1) as f64;
    let mean = sum / n;
    let rmse = (sq / n).sqrt();
    errors.sort_by(f64::total_cmp);
    let p999 = errors.get(((errors.len() as f64 * 0.999) as usize).min(errors.len().saturating_sub(1))).copied();
    let of_peak = |e: f64| if peak > 0.0 { e / peak } else { e };
    ImageDifference {
        rel_rmse: if mean > 0.0 { rmse / mean } else { rmse },
        p999_of_max: of_peak(p999.unwrap_or(0.0)),
        max_of_max: of_peak(errors.last().copied().unwrap_or(0.0)),
        nan_or_inf: bad,
    }
}

//! Emission–absorption rendering of baked grids (physics.md §10), in f64: what an engine that
//! reads the baked density and emission draws, with no lights. σ_t and the emission j are
//! trilinear between cell centres and held constant from the outermost centres to the box
//! faces (the march's clamping); nothing lies outside the box. Each step of a fine uniform
//! march is integrated exactly for constant σ_t and j: L += T·j/σ_t·(1 − e^{−σ_t Δ}),
//! T ·= e^{−σ_t Δ}. Rays stop at the first surface, which the bake does not hold.

use super::{camera_ray64, clip_to_box, par_fill};
use crate::scene::{GridSpec, Project, Volume, Volume3};
use glam::DVec3;

/// Baked extinction and emission on one grid, interleaved per cell as [σ_t, r, g, b].
pub struct BakedGrid64 {
    min: DVec3,
    max: DVec3,
    cell: DVec3,
    dims: [usize; 3],
    values: Vec<[f64; 4]>,
}

impl BakedGrid64 {
    /// # Panics
    /// If the volumes are not on the same grid.
    pub fn new(ev: &Volume, emission: &Volume3) -> Self {
        assert_eq!(ev.grid, emission.grid, "the EV and the emission must share a grid");
        let grid: GridSpec = ev.grid;
        let (min, max) = (grid.min.as_dvec3(), grid.max.as_dvec3());
        let r = grid.resolution;
        let values = ev
            .data
            .iter()
            .zip(&emission.data)
            .map(|(&s, e)| [s as f64, e[0] as f64, e[1] as f64, e[2] as f64])
            .collect();
        Self { min, max, cell: (max - min) / r.as_dvec3(), dims: [r.x as usize, r.y as usize, r.z as usize], values }
    }

    /// [σ_t, j_r, j_g, j_b] at `x` inside the box.
    pub fn at(&self, x: DVec3) -> [f64; 4] {
        let (i0, i1, f) = super::grid::trilinear_cells(x, self.min, self.cell, self.dims);
        let mut out = [0.0; 4];
        for n in 0..8 {
            let pick = |a: usize| if n >> a & 1 == 1 { (i1[a], f[a]) } else { (i0[a], 1.0 - f[a]) };
            let ((i, wx), (j, wy), (k, wz)) = (pick(0), pick(1), pick(2));
            let w = wx * wy * wz;
            if w == 0.0 {
                continue;
            }
            let v = &self.values[i + self.dims[0] * (j + self.dims[1] * k)];
            for c in 0..4 {
                out[c] += w * v[c];
            }
        }
        out
    }

    /// Radiance along `origin + t·dir` (|dir| = 1) for t in [0, t_max], in steps of about `step`.
    pub fn radiance(&self, origin: DVec3, dir: DVec3, t_max: f64, step: f64) -> DVec3 {
        let Some((t0, t1)) = clip_to_box(self.min, self.max, origin, dir, t_max) else { return DVec3::ZERO };
        let n = ((t1 - t0) / step).ceil().max(1.0) as usize;
        let dt = (t1 - t0) / n as f64;
        let mut radiance = DVec3::ZERO;
        let mut transmittance = 1.0;
        for k in 0..n {
            let [sigma, r, g, b] = self.at(origin + dir * (t0 + (k as f64 + 0.5) * dt));
            let tau = sigma * dt;
            let j = DVec3::new(r, g, b);
            // ∫_0^Δ j·e^{−σ s} ds, by its series where σΔ is tiny.
            let weight = if tau < 1e-6 { dt * (1.0 - 0.5 * tau) } else { -(-tau).exp_m1() / sigma };
            radiance += transmittance * weight * j;
            transmittance *= (-tau).exp();
            if transmittance < 1e-12 {
                break;
            }
        }
        radiance
    }
}

/// Linear RGB radiance of every pixel (row-major, row 0 at the top) of the emission–absorption
/// render of `ev` and `emission` from the project's camera, in steps of 1/16 of the smallest
/// cell edge.
pub fn render_emission(project: &Project, ev: &Volume, emission: &Volume3, width: u32, height: u32) -> Vec<[f64; 3]> {
    let baked = BakedGrid64::new(ev, emission);
    let step = baked.cell.min_element() / 16.0;
    let origin = project.camera.position.as_dvec3();
    let mut out = vec![[0.0; 3]; width as usize * height as usize];
    par_fill(&mut out, width as usize, |n| {
        let (px, py) = ((n % width as usize) as u32, (n / width as usize) as u32);
        let dir = camera_ray64(&project.camera, px, py, width, height);
        let t_max = project.surfaces.first_hit(origin, dir).map_or(f64::INFINITY, |h| h.t);
        baked.radiance(origin, dir, t_max, step).to_array()
    });
    out
}

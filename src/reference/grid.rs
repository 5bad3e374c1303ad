//! The medium a grid represents, in f64: σ_t trilinear between cell centres, held constant
//! from the outermost centres out to the box faces, and only the base fog outside the box
//! (with the project's height falloff, integrated in closed form).
//! This is what the GPU's propagation schemes integrate, so the exact line integral through
//! it isolates a scheme's own error from the grid's resolution error.

use super::{cell_center64, Medium64};
use crate::scene::{GridSpec, Project, Volume};
use glam::DVec3;

/// Sample points and weights of 2-point Gauss–Legendre on [0, 1]: exact for cubics, and the
/// trilinear medium is a cubic along a ray between two crossings of cell-centre planes.
const GAUSS: [(f64, f64); 2] = [(0.211_324_865_405_187_1, 0.5), (0.788_675_134_594_812_9, 0.5)];

#[derive(Clone, Debug, PartialEq)]
pub struct GridMedium64 {
    min: DVec3,
    max: DVec3,
    cell: DVec3,
    dims: [usize; 3],
    values: Vec<f64>,
    base: f64,
    /// Height fog falloff k and origin y₀ of the fog outside the box (k = 0: homogeneous).
    height: (f64, f64),
}

impl GridMedium64 {
    /// `values`: σ_t at the cell centres, x fastest (they include the base fog, as the EV
    /// does); `base`: the fog outside the box.
    ///
    /// # Panics
    /// If `values` does not hold one value per cell.
    pub fn new(grid: &GridSpec, values: Vec<f64>, base: f64) -> Self {
        assert_eq!(values.len() as u64, grid.cell_count(), "one value per cell");
        let (min, max) = (grid.min.as_dvec3(), grid.max.as_dvec3());
        let r = grid.resolution;
        Self {
            min,
            max,
            cell: (max - min) / r.as_dvec3(),
            dims: [r.x as usize, r.y as usize, r.z as usize],
            values,
            base,
            height: (0.0, 0.0),
        }
    }

    /// The medium a project's EV represents: its values inside the box, and the project's
    /// base fog, with its height falloff, outside it.
    pub fn for_project(project: &Project, ev: &Volume) -> Self {
        let m = &project.medium;
        Self::from_volume(&project.grid, ev, m.base_extinction.max(0.0) as f64)
            .with_height_fog(m.height_falloff as f64, m.height_origin as f64)
    }

    /// The fog outside the box becomes base·exp(−k·(y − y₀)).
    pub fn with_height_fog(mut self, falloff: f64, origin: f64) -> Self {
        self.height = (falloff, origin);
        self
    }

    /// Extinction of the fog outside the box at height `y`.
    fn outside_at(&self, y: f64) -> f64 {
        if self.height.0 == 0.0 {
            return self.base;
        }
        self.base * (-self.height.0 * (y - self.height.1)).min(crate::scene::MAX_HEIGHT_EXPONENT).exp()
    }

    /// Optical depth of the fog outside the box along `o + t·d`, t in [0, len] (len may be
    /// infinite).
    fn outside_depth(&self, o: DVec3, d: DVec3, len: f64) -> f64 {
        if self.base <= 0.0 || len <= 0.0 {
            return 0.0;
        }
        if self.height.0 == 0.0 {
            return self.base * len;
        }
        super::lights::height_fog_depth_raw(self.base, self.height.0, self.height.1, o, d, len)
    }

    /// The medium of a volume read back from the GPU (the EV).
    pub fn from_volume(grid: &GridSpec, ev: &Volume, base: f64) -> Self {
        Self::new(grid, ev.data.iter().map(|&v| v as f64).collect(), base)
    }

    /// The analytic medium sampled at the cell centres: what an exact injection would hold.
    pub fn sampled(grid: &GridSpec, medium: &Medium64) -> Self {
        let mut values = vec![0.0; grid.cell_count() as usize];
        super::par_fill(&mut values, grid.resolution.x.max(1) as usize, |idx| {
            let [i, j, k] = grid.cell_of(idx);
            medium.extinction(cell_center64(grid, i, j, k))
        });
        let (k, y0) = medium.height_fog();
        Self::new(grid, values, medium.base()).with_height_fog(k, y0)
    }

    fn value(&self, i: usize, j: usize, k: usize) -> f64 {
        self.values[i + self.dims[0] * (j + self.dims[1] * k)]
    }

    /// σ_t at `x`.
    pub fn extinction(&self, x: DVec3) -> f64 {
        if (0..3).any(|a| x[a] < self.min[a] || x[a] > self.max[a]) {
            return self.outside_at(x.y);
        }
        let (i0, i1, f) = trilinear_cells(x, self.min, self.cell, self.dims);
        let lerp = |a: f64, b: f64, t: f64| a + (b - a) * t;
        let v = |i: usize, j: usize, k: usize| self.value(i, j, k);
        lerp(
            lerp(
                lerp(v(i0[0], i0[1], i0[2]), v(i1[0], i0[1], i0[2]), f[0]),
                lerp(v(i0[0], i1[1], i0[2]), v(i1[0], i1[1], i0[2]), f[0]),
                f[1],
            ),
            lerp(
                lerp(v(i0[0], i0[1], i1[2]), v(i1[0], i0[1], i1[2]), f[0]),
                lerp(v(i0[0], i1[1], i1[2]), v(i1[0], i1[1], i1[2]), f[0]),
                f[1],
            ),
            f[2],
        )
    }

    /// Exact ∫σ_t along the segment from `a` to `b`: the part in the box piecewise by
    /// Gauss–Legendre between crossings of cell-centre planes, the rest as base fog.
    pub fn optical_depth(&self, a: DVec3, b: DVec3) -> f64 {
        let len = (b - a).length();
        if len == 0.0 {
            return 0.0;
        }
        self.ray_depth(a, (b - a) / len, len)
    }

    /// Optical depth along `a + t·dir` (unit `dir`), t in [0, len]; `len` may be infinite
    /// (the path to a sun).
    pub fn ray_depth(&self, a: DVec3, dir: DVec3, len: f64) -> f64 {
        let Some((t0, t1)) = clip_to_box(self.min, self.max, a, dir, len) else {
            return self.outside_depth(a, dir, len);
        };
        let mut cuts = vec![t0, t1];
        for ax in 0..3 {
            if dir[ax] == 0.0 {
                continue;
            }
            // Cell-centre planes: min + (k + 0.5)·cell.
            let u0 = (a[ax] + dir[ax] * t0 - self.min[ax]) / self.cell[ax] - 0.5;
            let u1 = (a[ax] + dir[ax] * t1 - self.min[ax]) / self.cell[ax] - 0.5;
            let (lo, hi) = (u0.min(u1).ceil().max(0.0), u0.max(u1).floor().min((self.dims[ax] - 1) as f64));
            let mut k = lo;
            while k <= hi {
                let t = (self.min[ax] + (k + 0.5) * self.cell[ax] - a[ax]) / dir[ax];
                if t > t0 && t < t1 {
                    cuts.push(t);
                }
                k += 1.0;
            }
        }
        cuts.sort_by(f64::total_cmp);
        let mut sum = 0.0;
        for w in cuts.windows(2) {
            let h = w[1] - w[0];
            if h <= 0.0 {
                continue;
            }
            sum += h * GAUSS.iter().map(|&(x, wt)| wt * self.extinction(a + dir * (w[0] + h * x))).sum::<f64>();
        }
        let after = if len.is_finite() { len - t1 } else { f64::INFINITY };
        sum + self.outside_depth(a, dir, t0) + self.outside_depth(a + dir * t1, dir, after)
    }
}

/// The parameter interval [t0, t1] ⊂ [0, len] of `a + t·dir` inside the box, if any.
pub fn clip_to_box(min: DVec3, max: DVec3, a: DVec3, dir: DVec3, len: f64) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (0.0f64, len);
    for ax in 0..3 {
        if dir[ax] == 0.0 {
            if a[ax] < min[ax] || a[ax] > max[ax] {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((min[ax] - a[ax]) / dir[ax], (max[ax] - a[ax]) / dir[ax]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t0 < t1).then_some((t0, t1))
}

/// Optical depth of the analytic medium clipped to the grid box: the gaussians and base fog
/// over the part of the segment inside the box, base fog elsewhere. The best any grid of
/// this box can hold, so the gap to [`GridMedium64::optical_depth`] is the resolution error.
pub fn clipped_optical_depth(grid: &GridSpec, medium: &Medium64, a: DVec3, b: DVec3) -> f64 {
    let len = (b - a).length();
    if len == 0.0 {
        return 0.0;
    }
    let dir = (b - a) / len;
    match clip_to_box(grid.min.as_dvec3(), grid.max.as_dvec3(), a, dir, len) {
        Some((t0, t1)) => {
            medium.optical_depth(a + dir * t0, a + dir * t1)
                + medium.base_depth(a, dir, t0)
                + medium.base_depth(a + dir * t1, dir, len - t1)
        }
        None => medium.base_depth(a, dir, len),
    }
}

/// The trilinear neighbourhood of `x` in a grid of `dims` cells from `min`, values at cell
/// centres, clamped to the outermost centres as the GPU's lookups are: the lower and upper
/// cell index per axis and the fraction between them.
pub(crate) fn trilinear_cells(
    x: DVec3,
    min: DVec3,
    cell: DVec3,
    dims: [usize; 3],
) -> ([usize; 3], [usize; 3], [f64; 3]) {
    let mut i0 = [0usize; 3];
    let mut i1 = [0usize; 3];
    let mut f = [0.0f64; 3];
    for a in 0..3 {
        let hi = (dims[a] - 1) as f64;
        let u = ((x[a] - min[a]) / cell[a] - 0.5).clamp(0.0, hi);
        let fl = u.floor();
        i0[a] = fl as usize;
        i1[a] = (i0[a] + 1).min(dims[a] - 1);
        f[a] = u - fl;
    }
    (i0, i1, f)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::Gaussian64;
    use crate::rng::Lcg;
    use glam::{UVec3, Vec3};

    /// Against fine midpoint quadrature of `extinction` itself, for segments inside, through
    /// and outside the box.
    #[test]
    fn grid_line_integral_matches_fine_quadrature() {
        let grid =
            GridSpec { min: Vec3::new(-1.0, 0.0, 0.5), max: Vec3::new(1.0, 0.5, 2.0), resolution: UVec3::new(7, 3, 5) };
        let mut s = Lcg(3);
        let values: Vec<f64> = (0..grid.cell_count()).map(|_| s.f64() * 4.0).collect();
        let m = GridMedium64::new(&grid, values, 0.3);
        for _ in 0..40 {
            let p = |s: &mut Lcg| DVec3::new(s.f64() * 4.0 - 2.0, s.f64() * 1.5 - 0.5, s.f64() * 3.0);
            let (a, b) = (p(&mut s), p(&mut s));
            let n = 200_000;
            let h = (b - a).length() / n as f64;
            let fine: f64 = (0..n).map(|i| m.extinction(a + (b - a) * ((i as f64 + 0.5) / n as f64))).sum::<f64>() * h;
            let exact = m.optical_depth(a, b);
            assert!((exact - fine).abs() < 1e-5 * fine.max(1.0), "{a} {b}: {exact} vs {fine}");
        }
    }

    #[test]
    fn clipped_depth_keeps_only_base_fog_outside_the_box() {
        let grid = GridSpec { min: Vec3::ZERO, max: Vec3::ONE, resolution: UVec3::splat(4) };
        let g = Gaussian64 { center: DVec3::new(1.5, 0.5, 0.5), radius: 0.3, density: 5.0 };
        let medium = Medium64::new(0.1, vec![g]);
        let (a, b) = (DVec3::new(0.5, 0.5, 0.5), DVec3::new(3.0, 0.5, 0.5));
        let want = Medium64::new(0.1, vec![g]).optical_depth(a, DVec3::new(1.0, 0.5, 0.5)) + 0.1 * 2.0;
        assert!((clipped_optical_depth(&grid, &medium, a, b) - want).abs() < 1e-12);
        let outside = clipped_optical_depth(&grid, &medium, DVec3::new(2.0, 2.0, 2.0), DVec3::new(3.0, 2.0, 2.0));
        assert!((outside - 0.1).abs() < 1e-12);
    }
}

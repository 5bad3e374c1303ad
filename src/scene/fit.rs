//! Particles that reach outside the grid box, and fitting the box to them.
//!
//! The medium is baked only inside the grid box, so a particle whose fog reaches past the box
//! is cut off there with a hard edge. The rule: a visible particle **crosses the box** when
//! its support, the ball where its extinction exceeds [`SUPPORT_FRACTION`] of its peak
//! (radius r·√ln(1/f), about 2.15 r), is not inside the box. The fraction is relative, so the
//! rule does not depend on the particle's density: at 1 % of the peak the cut is faint on its
//! own, but the integral beyond it is under 0.2 % of the particle's total extinction.
//!
//! A face of the box hidden behind an opaque surface does not count: the ground seals the
//! bottom face when it lies at or above it (all fog below the face is underground), and a
//! surface box seals a face when it covers the whole face from outside (a wall flush with
//! it). Fog cut there is never seen.
//!
//! [`Project::fit_grid_to_particles`] gives the box that just holds every visible particle's
//! support, keeping either the cell size or the resolution.

use super::{GridSpec, Particle, Project};
use glam::{UVec3, Vec3};

/// Fraction of a particle's peak extinction that bounds its support.
pub const SUPPORT_FRACTION: f32 = 0.01;

/// What "Fit grid to particles" keeps.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum FitKeep {
    /// The cell size stays; the resolution follows the new box.
    #[default]
    CellSize,
    /// The resolution stays; the cells stretch or shrink with the box.
    Resolution,
}

/// Largest grid "Fit grid to particles" proposes while keeping the cell size: 2²⁷ cells
/// (512 MiB per volume).
pub const MAX_FIT_CELLS: u64 = 1 << 27;

impl Particle {
    /// Radius of the support: where the extinction is [`SUPPORT_FRACTION`] of the peak.
    pub fn support_radius(&self) -> f32 {
        self.radius * (1.0 / SUPPORT_FRACTION).ln().sqrt()
    }
}

impl GridSpec {
    /// Whether the ball at `center` of radius `r` lies inside the box.
    pub fn holds_ball(&self, center: Vec3, r: f32) -> bool {
        (center - r).cmpge(self.min).all() && (center + r).cmple(self.max).all()
    }
}

impl Project {
    /// Which faces of the grid box a surface hides, as `[axis][0: min face, 1: max face]`.
    pub fn sealed_grid_faces(&self) -> [[bool; 2]; 3] {
        let g = &self.grid;
        let eps = 1e-4 * g.size().max_element();
        let mut sealed = [[false; 2]; 3];
        if let Some(ground) = &self.surfaces.ground {
            sealed[1][0] = ground.height >= g.min.y - eps;
        }
        for b in &self.surfaces.boxes {
            for (a, sealed_a) in sealed.iter_mut().enumerate() {
                let (u, v) = ((a + 1) % 3, (a + 2) % 3);
                let covers = |c: usize| b.min[c] <= g.min[c] + eps && b.max[c] >= g.max[c] - eps;
                if !(covers(u) && covers(v)) {
                    continue;
                }
                if b.min[a] < g.min[a] && b.max[a] >= g.min[a] - eps {
                    sealed_a[0] = true;
                }
                if b.max[a] > g.max[a] && b.min[a] <= g.max[a] + eps {
                    sealed_a[1] = true;
                }
            }
        }
        sealed
    }

    /// Indices of the visible particles whose support crosses an open face of the grid box
    /// (see the module).
    pub fn particles_crossing_grid(&self) -> Vec<usize> {
        self.particles_crossing_grid_from(0)
    }

    /// [`Self::particles_crossing_grid`] among the particles from index `start` on.
    pub fn particles_crossing_grid_from(&self, start: usize) -> Vec<usize> {
        let sealed = self.sealed_grid_faces();
        let g = &self.grid;
        self.particles
            .iter()
            .enumerate()
            .skip(start)
            .filter(|(_, p)| {
                let r = p.support_radius();
                !p.hidden
                    && p.density > 0.0
                    && (0..3).any(|a| {
                        (!sealed[a][0] && p.center[a] - r < g.min[a]) || (!sealed[a][1] && p.center[a] + r > g.max[a])
                    })
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// The grid box that just holds every visible particle's support, keeping the cell size
    /// (resolution rounded up, the box grown to whole cells on its open sides) or the
    /// resolution. A sealed face (see [`Self::sealed_grid_faces`]) never moves outwards.
    /// An error says why there is nothing sensible to fit.
    pub fn fit_grid_to_particles(&self, keep: FitKeep) -> Result<GridSpec, String> {
        // Moving faces can uncover a face a wall sealed: refit with only the faces that stay
        // sealed around the result (at most six rounds, one per face given up).
        let mut sealed = self.sealed_grid_faces();
        loop {
            let grid = self.fit_with(keep, sealed)?;
            let mut fitted = self.clone();
            fitted.grid = grid;
            let now = fitted.sealed_grid_faces();
            let kept = std::array::from_fn(|a| [sealed[a][0] && now[a][0], sealed[a][1] && now[a][1]]);
            if kept == sealed {
                return Ok(grid);
            }
            sealed = kept;
        }
    }

    fn fit_with(&self, keep: FitKeep, sealed: [[bool; 2]; 3]) -> Result<GridSpec, String> {
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        for p in self.particles.iter().filter(|p| !p.hidden && p.density > 0.0) {
            let r = p.support_radius();
            lo = lo.min(p.center - r);
            hi = hi.max(p.center + r);
        }
        if !lo.is_finite() || !hi.is_finite() {
            return Err("there are no visible particles to fit the grid to".into());
        }
        // A hair of slack, so rounding never puts a support's edge just outside the new box.
        let pad = Vec3::splat((hi - lo).max_element() * 1e-5 + 1e-6);
        let (mut lo, mut hi) = (lo - pad, hi + pad);
        let g = self.grid;
        for a in 0..3 {
            if sealed[a][0] {
                lo[a] = lo[a].max(g.min[a]);
            }
            if sealed[a][1] {
                hi[a] = hi[a].min(g.max[a]);
            }
            if hi[a] <= lo[a] {
                return Err(
                    "the visible particles lie outside the sealed faces of the grid box; move them in first".into()
                );
            }
        }
        match keep {
            FitKeep::Resolution => Ok(GridSpec { min: lo, max: hi, resolution: g.resolution }),
            FitKeep::CellSize => {
                let cell = g.cell_size();
                let n = ((hi - lo) / cell).ceil().max(Vec3::ONE);
                let resolution = UVec3::new(n.x as u32, n.y as u32, n.z as u32);
                let cells = resolution.x as u64 * resolution.y as u64 * resolution.z as u64;
                if !n.is_finite() || n.max_element() > 1.0e6 || cells > MAX_FIT_CELLS {
                    return Err(format!(
                        "keeping the cell size would need {}×{}×{} cells (more than {MAX_FIT_CELLS}); keep the resolution instead, or make the particles smaller",
                        n.x, n.y, n.z
                    ));
                }
                // The whole cells' extra length goes to the open sides.
                let extra = resolution.as_vec3() * cell - (hi - lo);
                let (mut min, mut max) = (lo, hi);
                for a in 0..3 {
                    let to_min = match sealed[a] {
                        [true, false] => 0.0,
                        [false, true] => 1.0,
                        _ => 0.5,
                    };
                    min[a] -= extra[a] * to_min;
                    max[a] += extra[a] * (1.0 - to_min);
                }
                Ok(GridSpec { min, max, resolution })
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_support_bounds_the_particle_at_the_stated_fraction() {
        let p = Particle::new(Vec3::ZERO, 0.5, 3.0);
        let r = p.support_radius();
        let at = p.density * (-(r * r) / (p.radius * p.radius)).exp();
        assert!((at / p.density - SUPPORT_FRACTION).abs() < 1e-6, "{at}");
    }

    #[test]
    fn crossing_and_fitting_on_random_scenes() {
        let mut s = crate::rng::XorShift(0x9e3779b97f4a7c15);
        for _ in 0..200 {
            let mut p = Project::default();
            let n = 1 + (s.f32() * 20.0) as usize;
            for _ in 0..n {
                let c = Vec3::new(s.f32(), s.f32(), s.f32()) * 8.0 - 4.0;
                p.particles.push(Particle::new(c, 0.05 + s.f32(), 0.1 + s.f32() * 5.0));
            }
            // Brute force: a particle crosses iff a point of its support ball lies outside.
            for (i, q) in p.particles.iter().enumerate() {
                let r = q.support_radius();
                let outside = (0..3).any(|a| q.center[a] - r < p.grid.min[a] || q.center[a] + r > p.grid.max[a]);
                assert_eq!(p.particles_crossing_grid().contains(&i), outside);
            }
            for keep in [FitKeep::CellSize, FitKeep::Resolution] {
                let cell = p.grid.cell_size();
                let g = p.fit_grid_to_particles(keep).unwrap();
                let mut fitted = p.clone();
                fitted.grid = g;
                assert!(fitted.particles_crossing_grid().is_empty(), "{keep:?}: every particle fits");
                match keep {
                    FitKeep::Resolution => assert_eq!(g.resolution, p.grid.resolution),
                    FitKeep::CellSize => {
                        assert!(
                            (g.cell_size() - cell).abs().max_element() < 1e-4 * cell.max_element(),
                            "{:?} vs {cell:?}",
                            g.cell_size()
                        );
                        // No whole cell to spare on any axis.
                        let lo =
                            p.particles.iter().map(|q| q.center - q.support_radius()).fold(Vec3::INFINITY, Vec3::min);
                        let hi = p
                            .particles
                            .iter()
                            .map(|q| q.center + q.support_radius())
                            .fold(Vec3::NEG_INFINITY, Vec3::max);
                        assert!((g.size() - (hi - lo)).cmplt(cell + 1e-3).all(), "{:?} vs {:?}", g.size(), hi - lo);
                    }
                }
            }
        }
        assert!(Project::default()
            .fit_grid_to_particles(FitKeep::CellSize)
            .unwrap_err()
            .contains("no visible particles"));
    }

    #[test]
    fn faces_behind_surfaces_do_not_count() {
        use crate::scene::{Ground, SurfaceBox};
        // Default grid: (-2, 0, -2) .. (2, 4, 2). One particle through the floor, one through -x.
        let mut p = Project {
            particles: vec![
                Particle::new(Vec3::new(0.0, 0.1, 0.0), 0.3, 1.0),
                Particle::new(Vec3::new(-1.9, 2.0, 0.0), 0.3, 1.0),
            ],
            ..Project::default()
        };
        assert_eq!(p.particles_crossing_grid(), [0, 1]);
        p.surfaces.ground = Some(Ground { height: 0.0, albedo: Vec3::splat(0.5), ..Ground::default() });
        assert_eq!(p.particles_crossing_grid(), [1], "the ground hides the floor face");
        let wall = SurfaceBox {
            min: Vec3::new(-2.1, -0.1, -2.1),
            max: Vec3::new(-2.0, 4.1, 2.1),
            albedo: Vec3::splat(0.5),
            ..SurfaceBox::default()
        };
        p.surfaces.boxes.push(SurfaceBox { max: Vec3::new(-2.0, 4.1, 1.0), ..wall });
        assert_eq!(p.particles_crossing_grid(), [1], "a wall that covers part of the face does not seal it");
        p.surfaces.boxes.push(wall);
        assert!(p.particles_crossing_grid().is_empty(), "a flush wall over the whole face seals it");
        let g = p.fit_grid_to_particles(FitKeep::CellSize).unwrap();
        assert_eq!((g.min.x, g.min.y), (-2.0, 0.0), "sealed faces do not move outwards: {g:?}");
    }
}

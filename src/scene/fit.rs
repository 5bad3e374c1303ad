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
//! it). Fog cut there is never seen. A particle's cut at an open face does not count either
//! where a wall flush with that face covers the face at the point nearest the particle's
//! centre, where the cut fog is densest: the gaussian's tail past the wall's edge is what
//! may show. Fitting moves a face out only as far as the cuts that count there need, so it
//! never pushes the box through a floor or wall for fog the floor or wall hides.
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
        self.particles
            .iter()
            .enumerate()
            .skip(start)
            .filter(|(_, p)| {
                !p.hidden && p.density > 0.0 && (0..3).any(|a| (0..2).any(|side| self.cut_at(p, a, side, &sealed)))
            })
            .map(|(i, _)| i)
            .collect()
    }

    /// Whether particle `p`'s support crosses face `side` (0: min, 1: max) of axis `a` where
    /// no surface hides the cut: the face is open, and no surface box flush with it covers
    /// the point of the face nearest the particle's centre, where the cut fog is densest.
    fn cut_at(&self, p: &Particle, a: usize, side: usize, sealed: &[[bool; 2]; 3]) -> bool {
        let g = &self.grid;
        let r = p.support_radius();
        let crosses = if side == 0 { p.center[a] - r < g.min[a] } else { p.center[a] + r > g.max[a] };
        if !crosses || sealed[a][side] {
            return false;
        }
        let eps = 1e-4 * g.size().max_element();
        let plane = if side == 0 { g.min[a] } else { g.max[a] };
        let (u, v) = ((a + 1) % 3, (a + 2) % 3);
        // The cut's densest point: the point of the face nearest the particle's centre.
        let (cu, cv) = (p.center[u].clamp(g.min[u], g.max[u]), p.center[v].clamp(g.min[v], g.max[v]));
        !self.surfaces.boxes.iter().any(|b| {
            let flush = if side == 0 {
                b.min[a] < plane && b.max[a] >= plane - eps
            } else {
                b.max[a] > plane && b.min[a] <= plane + eps
            };
            flush && b.min[u] <= cu + eps && b.max[u] >= cu - eps && b.min[v] <= cv + eps && b.max[v] >= cv - eps
        })
    }

    /// The grid box that just holds every visible particle's support where it shows, keeping
    /// the cell size (resolution rounded up, the box grown to whole cells on its open sides)
    /// or the resolution. A face moves outwards only as far as the particles whose cut there
    /// counts (see the module) need; a sealed face (see [`Self::sealed_grid_faces`]) never
    /// does. An error says why there is nothing sensible to fit.
    ///
    /// The cuts are judged on the box as it is: a face that grows can widen the footprint of
    /// a cut at a neighbouring face past a wall's edge, so a few particles may count as cut
    /// on the fitted box (the caller says so); fitting again would then move that face too.
    pub fn fit_grid_to_particles(&self, keep: FitKeep) -> Result<GridSpec, String> {
        let sealed = self.sealed_grid_faces();
        let g = self.grid;
        let visible: Vec<&Particle> = self.particles.iter().filter(|p| !p.hidden && p.density > 0.0).collect();
        if visible.is_empty() {
            return Err("there are no visible particles to fit the grid to".into());
        }
        // Per face: the box just holding every support, but no further out than the face
        // itself where no cut counts there, and as far as the counted cuts need.
        let mut lo = Vec3::splat(f32::INFINITY);
        let mut hi = Vec3::splat(f32::NEG_INFINITY);
        let mut lo_cut = Vec3::splat(f32::INFINITY);
        let mut hi_cut = Vec3::splat(f32::NEG_INFINITY);
        for p in &visible {
            let r = p.support_radius();
            lo = lo.min(p.center - r);
            hi = hi.max(p.center + r);
            for a in 0..3 {
                if self.cut_at(p, a, 0, &sealed) {
                    lo_cut[a] = lo_cut[a].min(p.center[a] - r);
                }
                if self.cut_at(p, a, 1, &sealed) {
                    hi_cut[a] = hi_cut[a].max(p.center[a] + r);
                }
            }
        }
        if !lo.is_finite() || !hi.is_finite() {
            return Err("the visible particles' extent is not finite; fix their positions and radii first".into());
        }
        let lo = lo.max(g.min).min(lo_cut);
        let hi = hi.min(g.max).max(hi_cut);
        // A hair of slack, so rounding never puts a support's edge just outside the new box.
        let pad = Vec3::splat((hi - lo).max_element() * 1e-5 + 1e-6);
        // Faces that stay where they are get no slack.
        let lo = Vec3::from_array(std::array::from_fn(|a| if lo[a] >= g.min[a] { lo[a] } else { lo[a] - pad[a] }));
        let hi = Vec3::from_array(std::array::from_fn(|a| if hi[a] <= g.max[a] { hi[a] } else { hi[a] + pad[a] }));
        for a in 0..3 {
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
                    // A face held where it was (particles cut there behind a surface) stays
                    // put; the other side takes the rest.
                    let pinned = [lo[a] == g.min[a], hi[a] == g.max[a]];
                    let to_min = match pinned {
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
        p.surfaces.boxes.push(SurfaceBox { max: Vec3::new(-2.0, 4.1, -0.5), ..wall });
        assert_eq!(p.particles_crossing_grid(), [1], "a wall beside the particle's cut does not hide it");
        p.surfaces.boxes.push(SurfaceBox { max: Vec3::new(-2.0, 4.1, 0.1), ..wall });
        assert!(p.particles_crossing_grid().is_empty(), "a wall over the cut's densest point hides it");
        p.surfaces.boxes.pop();
        p.surfaces.boxes.push(wall);
        assert!(p.particles_crossing_grid().is_empty(), "a flush wall over the whole face seals it");
        let g = p.fit_grid_to_particles(FitKeep::CellSize).unwrap();
        assert_eq!((g.min.x, g.min.y), (-2.0, 0.0), "sealed faces do not move outwards: {g:?}");
    }

    /// The cornell demo: fitting keeps the box on the floor, between the walls and under the
    /// ceiling, and after it no particle's fog is cut where it shows.
    #[test]
    fn fitting_the_cornell_demo_keeps_the_box_inside_the_room() {
        let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("projects/cornell.ron");
        let p = crate::scene::load_project(&path).unwrap();
        for keep in [FitKeep::CellSize, FitKeep::Resolution] {
            let g = p.fit_grid_to_particles(keep).unwrap();
            assert!(g.min.cmpge(p.grid.min).all(), "{keep:?}: not through the floor or walls: {g:?}");
            assert!(g.max.x <= p.grid.max.x && g.max.y <= p.grid.max.y, "{keep:?}: nor the ceiling: {g:?}");
            assert!(g.max.z > p.grid.max.z, "{keep:?}: it grows out of the open front: {g:?}");
            let mut fitted = p.clone();
            fitted.grid = g;
            assert_eq!(fitted.particles_crossing_grid(), Vec::<usize>::new(), "{keep:?}: {g:?}");
        }
    }
}

//! Exact CPU reference, in f64, for measuring the GPU pipeline's error.
//!
//! Nothing here is meant for users' images: it is slow on purpose, trading speed for
//! formulas that are exact or converge to a tight tolerance, so that benchmarks,
//! `verify` and the editor's error views have ground truth to compare against.
//!
//! - [`Medium64`]: the analytic medium of `physics.md` §2 and its exact optical depth (§3).
//! - [`GridMedium64`]: the medium a grid represents (trilinear between cell centres, base fog
//!   outside the box), for separating a propagation scheme's error from the grid's. It also
//!   models a project's imported base volume inside [`Medium64`], as the injection adds it.
//! - [`optical_depth_volume`], [`optical_depth_cells`]: exact optical-depth volumes (OPVs).
//! - [`render_reference`], [`radiance_along_ray`], [`in_scatter_adaptive`]: single scattering
//!   (§4) with exact transmittance, the surfaces shadowing the fog and each other.
//! - [`render_emission`]: emission–absorption renders of baked density and emission (§10).
//! - [`sun`]: Sun et al.'s closed form for homogeneous fog (§6) and its lookup tables.
//! - [`surface_glow`]: Sun et al.'s surface term by hemisphere quadrature (§9).
//! - [`lights`]: directional lights' optical depths and the height fog's closed form (§9).
//! - [`noise`]: the medium's fractal noise on the particles, by the GPU's own hash.

mod emission;
mod grid;
pub mod lights;
pub mod noise;
pub use crate::quad;
mod render;
pub mod sun;
pub mod surface_glow;

pub use emission::{render_emission, BakedGrid64};
pub use grid::{clip_to_box, clipped_optical_depth, GridMedium64};
pub use render::{
    camera_ray64, default_step, in_scatter_adaptive, radiance_along_ray, render_reference, render_reference_with,
    shadowed, RefRenderOptions,
};

use crate::scene::{GridSpec, Project, Volume};
use glam::DVec3;
use std::sync::{Arc, Mutex};

/// A particle is skipped on a segment where its whole line integral, c·r·√π·exp(−d²/r²) with
/// d its distance to the segment, is below this: an absolute optical depth that changes any
/// transmittance by less than 1e-20 relative.
pub const NEGLIGIBLE_DEPTH: f64 = 1e-20;

const SQRT_PI: f64 = 1.772_453_850_905_516;

/// One gaussian of the medium: σ_t(x) = density · exp(−|x − center|² / radius²).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Gaussian64 {
    pub center: DVec3,
    pub radius: f64,
    pub density: f64,
}

/// The medium of a project in f64: base fog plus gaussians, plus the imported base volume
/// when one is given.
#[derive(Clone, Debug, PartialEq)]
pub struct Medium64 {
    base: f64,
    /// Height fog falloff k and origin y₀: the base fog is base·exp(−k(y − y₀)) (physics.md §9).
    height: (f64, f64),
    gaussians: Vec<Gaussian64>,
    /// Per gaussian, the d²/r² beyond which it adds less than [`NEGLIGIBLE_DEPTH`].
    cull: Vec<f64>,
    /// Per gaussian, whether `noise` modulates it (all false without noise).
    noisy: Vec<bool>,
    noise: Option<noise::Noise64>,
    /// The base volume as the injection adds it: its values at the cell centres, trilinear
    /// between them, constant out to the box faces and nothing outside the box.
    layer: Option<Arc<GridMedium64>>,
}

impl Medium64 {
    pub fn new(base: f64, gaussians: Vec<Gaussian64>) -> Self {
        let cull = gaussians.iter().map(|g| (g.density * g.radius * SQRT_PI / NEGLIGIBLE_DEPTH).ln()).collect();
        let noisy = vec![false; gaussians.len()];
        Self { base, height: (0.0, 0.0), gaussians, cull, noisy, noise: None, layer: None }
    }

    /// [`from_project`](Self::from_project) plus the project's base volume `layer` as
    /// [`crate::export::load_base_layer`] returns it (already scaled, on the project's grid).
    ///
    /// # Panics
    /// If `layer` is not on `project.grid`.
    pub fn for_project(project: &Project, layer: Option<&Volume>) -> Self {
        let m = Self::from_project(project);
        match layer {
            Some(v) => m.with_layer(&project.grid, v),
            None => m,
        }
    }

    /// This medium plus `layer`, σ_t at the centres of `grid`'s cells (see [`Medium64::layer`]).
    ///
    /// # Panics
    /// If `layer` is not on `grid`.
    pub fn with_layer(mut self, grid: &GridSpec, layer: &Volume) -> Self {
        assert_eq!(layer.grid, *grid, "the base volume must be resampled into the project's grid");
        self.layer = Some(Arc::new(GridMedium64::from_volume(grid, layer, 0.0)));
        self
    }

    /// The same medium without its base (height) fog: the gaussians (with their noise) and the
    /// base volume, which a sun's optical depth integrates inside the box only.
    pub fn without_base(&self) -> Self {
        Self { base: 0.0, height: (0.0, 0.0), ..self.clone() }
    }

    /// Whether a base volume is part of this medium.
    pub fn has_layer(&self) -> bool {
        self.layer.is_some()
    }

    /// Visible particles with positive radius and density; hidden ones contribute nothing.
    /// The medium's noise (with the octaves the grid keeps) modulates the particles that
    /// take it.
    pub fn from_project(project: &Project) -> Self {
        let kept: Vec<&crate::scene::Particle> =
            project.visible_particles().filter(|p| p.radius > 0.0 && p.density > 0.0).collect();
        let gaussians = kept
            .iter()
            .map(|p| Gaussian64 { center: p.center.as_dvec3(), radius: p.radius as f64, density: p.density as f64 })
            .collect();
        let mut m = Self::new(project.medium.base_extinction.max(0.0) as f64, gaussians);
        m.height = (project.medium.height_falloff as f64, project.medium.height_origin as f64);
        m.noise = project.medium.noise.filter(|n| n.amplitude > 0.0).map(|n| noise::Noise64::new(&n, &project.grid));
        if m.noise.is_some() {
            m.noisy = kept.iter().map(|p| p.noise).collect();
        }
        m
    }

    /// The noise modulating some of the gaussians, if any.
    pub fn noise(&self) -> Option<&noise::Noise64> {
        self.noise.as_ref()
    }

    /// Base-fog extinction at height `y` (the height fog's exponent clamped as on the GPU).
    pub fn base_at(&self, y: f64) -> f64 {
        if self.height.0 == 0.0 {
            return self.base;
        }
        self.base * (-self.height.0 * (y - self.height.1)).min(crate::scene::MAX_HEIGHT_EXPONENT).exp()
    }

    /// The base fog's optical depth along `o + t·d` (unit `d`), t in [0, len], in closed form.
    pub fn base_depth(&self, o: DVec3, d: DVec3, len: f64) -> f64 {
        if self.base <= 0.0 || len <= 0.0 {
            return 0.0;
        }
        if self.height.0 == 0.0 {
            return self.base * len;
        }
        lights::height_fog_depth_raw(self.base, self.height.0, self.height.1, o, d, len)
    }

    /// The height fog's falloff k and origin y₀ (k = 0: homogeneous base fog).
    pub fn height_fog(&self) -> (f64, f64) {
        self.height
    }

    /// Homogeneous base extinction, 1/m.
    pub fn base(&self) -> f64 {
        self.base
    }

    pub fn gaussians(&self) -> &[Gaussian64] {
        &self.gaussians
    }

    /// σ_t at `x`.
    pub fn extinction(&self, x: DVec3) -> f64 {
        let (mut plain, mut noisy) = (0.0, 0.0);
        for (g, &n) in self.gaussians.iter().zip(&self.noisy) {
            let v = g.density * (-(x - g.center).length_squared() / (g.radius * g.radius)).exp();
            if n {
                noisy += v;
            } else {
                plain += v;
            }
        }
        let noisy = match &self.noise {
            Some(n) if noisy > 0.0 => noisy * n.modulation(x),
            _ => noisy,
        };
        self.base_at(x.y) + self.layer.as_ref().map_or(0.0, |l| l.extinction(x)) + plain + noisy
    }

    /// Exact optical depth ∫ σ_t along the segment from `a` to `b` (physics.md §3); both ends
    /// must be finite.
    pub fn optical_depth(&self, a: DVec3, b: DVec3) -> f64 {
        let len = (b - a).length();
        if len == 0.0 {
            return 0.0;
        }
        let dir = (b - a) / len;
        self.base_depth(a, dir, len)
            + self
                .gaussians
                .iter()
                .zip(&self.cull)
                .zip(&self.noisy)
                .filter(|(_, &n)| !n)
                .map(|((g, &cull), _)| g.segment_depth(cull, a, dir, len))
                .sum::<f64>()
            + self.noisy_depth(a, dir, len)
            + self.layer.as_ref().map_or(0.0, |l| l.optical_depth(a, b))
    }

    /// ∫ of the noisy gaussians times the noise's modulation along `a + t·dir`, t in
    /// [0, len]: no closed form, so adaptive Gauss–Kronrod split where each gaussian matters
    /// and at the crossings of the finest octave's lattice planes (where the noise's second
    /// derivative jumps), to relative tolerance 1e-10.
    fn noisy_depth(&self, a: DVec3, dir: DVec3, len: f64) -> f64 {
        let Some(noise) = &self.noise else { return 0.0 };
        let mut active = Vec::new();
        let mut points = Vec::new();
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for ((g, &cull), _) in self.gaussians.iter().zip(&self.cull).zip(&self.noisy).filter(|(_, &n)| n) {
            let ob = g.center - a;
            let t_star = dir.dot(ob);
            let q = (ob - dir * t_star).length_squared() / (g.radius * g.radius);
            if q > cull {
                continue;
            }
            let w = g.radius * (cull - q).sqrt();
            let (t0, t1) = ((t_star - w).max(0.0), (t_star + w).min(len));
            if t0 >= t1 {
                continue;
            }
            active.push(*g);
            lo = lo.min(t0);
            hi = hi.max(t1);
            points.extend([t0, t1]);
            points.extend((-4..=4).map(|k| t_star + k as f64 * 0.5 * g.radius));
        }
        if active.is_empty() {
            return 0.0;
        }
        let spacing = noise.finest_spacing();
        let crossings: f64 = (0..3).map(|ax| (dir[ax] * (hi - lo)).abs() / spacing).sum();
        if crossings < 20_000.0 {
            for ax in 0..3 {
                if dir[ax] == 0.0 {
                    continue;
                }
                // The lattice planes drift with the noise's offset.
                let a_ax = a[ax] - noise.offset[ax] as f64;
                let (u0, u1) = ((a_ax + dir[ax] * lo) / spacing, (a_ax + dir[ax] * hi) / spacing);
                let mut k = u0.min(u1).ceil();
                while k <= u0.max(u1) {
                    points.push((k * spacing - a_ax) / dir[ax]);
                    k += 1.0;
                }
            }
        }
        let points = quad::breakpoints(points, lo, hi);
        let f = |t: f64| {
            let x = a + dir * t;
            let sum: f64 = active
                .iter()
                .map(|g| g.density * (-(x - g.center).length_squared() / (g.radius * g.radius)).exp())
                .sum();
            if sum > 0.0 {
                sum * noise.modulation(x)
            } else {
                0.0
            }
        };
        quad::integrate(f, &points, 1e-10, 1e-14, points.len() * 4 + 2_000).0
    }

    /// The gaussians that can contribute anywhere along the line `origin + t·dir` (unit `dir`).
    pub fn along_line(&self, origin: DVec3, dir: DVec3) -> Self {
        let mut kept = Self {
            base: self.base,
            height: self.height,
            gaussians: Vec::new(),
            cull: Vec::new(),
            noisy: Vec::new(),
            noise: self.noise,
            layer: self.layer.clone(),
        };
        for ((g, &cull), &noisy) in self.gaussians.iter().zip(&self.cull).zip(&self.noisy) {
            let ob = g.center - origin;
            let perp = ob - dir * dir.dot(ob);
            if perp.length_squared() / (g.radius * g.radius) <= cull {
                kept.gaussians.push(*g);
                kept.cull.push(cull);
                kept.noisy.push(noisy);
            }
        }
        kept
    }
}

impl Gaussian64 {
    /// ∫_0^len of this gaussian along `origin + t·dir`, unit `dir`.
    /// `cull`: the d²/r² beyond which the whole integral is negligible (see [`Medium64`]).
    fn segment_depth(&self, cull: f64, origin: DVec3, dir: DVec3, len: f64) -> f64 {
        let r = self.radius;
        let ob = self.center - origin;
        let t_star = dir.dot(ob);
        let q = (ob - dir * t_star).length_squared() / (r * r);
        let nearest = t_star.clamp(0.0, len);
        if q > cull || (ob - dir * nearest).length_squared() / (r * r) > cull {
            return 0.0;
        }
        let z0 = -t_star / r;
        let z1 = (len - t_star) / r;
        if len < 1e-2 * r {
            // A short segment: the erf difference would cancel; 4-point Gauss–Legendre is
            // exact to rounding for an interval this narrow.
            const X: [f64; 2] = [0.339_981_043_584_856_3, 0.861_136_311_594_052_6];
            const W: [f64; 2] = [0.652_145_154_862_546_1, 0.347_854_845_137_453_9];
            let (c, h) = ((0.5 * len - t_star) / r, 0.5 * len / r);
            let sum: f64 = (0..2)
                .map(|i| W[i] * ((-q - (c - h * X[i]).powi(2)).exp() + (-q - (c + h * X[i]).powi(2)).exp()))
                .sum();
            return self.density * r * h * sum;
        }
        self.density * (-q).exp() * r * (0.5 * SQRT_PI) * erf_diff(z0, z1)
    }
}

/// erf(z1) − erf(z0) for z0 ≤ z1, through erfc where both arguments have the same sign so
/// that tails far from the centre do not cancel.
fn erf_diff(z0: f64, z1: f64) -> f64 {
    if z0 >= 0.0 {
        libm::erfc(z0) - libm::erfc(z1)
    } else if z1 <= 0.0 {
        libm::erfc(-z1) - libm::erfc(-z0)
    } else {
        libm::erf(z1) - libm::erf(z0)
    }
}

/// Centre of cell (i, j, k) in f64.
pub fn cell_center64(grid: &GridSpec, i: u32, j: u32, k: u32) -> DVec3 {
    let min = grid.min.as_dvec3();
    let cell = (grid.max.as_dvec3() - min) / grid.resolution.as_dvec3();
    min + (DVec3::new(i as f64, j as f64, k as f64) + 0.5) * cell
}

/// Exact optical depth T(cell centre, light) for every cell of `project.grid`, x fastest.
/// `light` indexes `project.lights`, hidden or not; hidden particles are left out.
///
/// # Panics
/// If `light` is not an index into `project.lights`.
pub fn optical_depth_volume(project: &Project, light: usize) -> Vec<f64> {
    let grid = project.grid;
    let r = grid.resolution;
    let cells = r.x as usize * r.y as usize * r.z as usize;
    let medium = Medium64::from_project(project);
    let source = project.lights[light].position.as_dvec3();
    let mut out = vec![0.0; cells];
    par_fill(&mut out, r.x.max(1) as usize, |idx| {
        let [i, j, k] = grid.cell_of(idx);
        medium.optical_depth(cell_center64(&grid, i, j, k), source)
    });
    out
}

/// Exact optical depth towards `light` at the centres of the given cells, in their order.
///
/// # Panics
/// If `light` is not an index into `project.lights`.
pub fn optical_depth_cells(project: &Project, light: usize, cells: &[[u32; 3]]) -> Vec<f64> {
    if matches!(project.lights[light].kind, crate::scene::LightKind::Directional { .. }) {
        return lights::sun_optical_depth_cells(project, light, cells);
    }
    let medium = Medium64::from_project(project);
    let source = project.lights[light].position.as_dvec3();
    let mut out = vec![0.0; cells.len()];
    par_fill(&mut out, 64, |n| {
        let [i, j, k] = cells[n];
        medium.optical_depth(cell_center64(&project.grid, i, j, k), source)
    });
    out
}

/// Exact optical depth towards `source` through the grid's own medium, at the centres of
/// `cells`, in their order.
pub fn grid_optical_depth_cells(grid: &GridSpec, medium: &GridMedium64, source: DVec3, cells: &[[u32; 3]]) -> Vec<f64> {
    let mut out = vec![0.0; cells.len()];
    par_fill(&mut out, 64, |n| {
        let [i, j, k] = cells[n];
        medium.optical_depth(cell_center64(grid, i, j, k), source)
    });
    out
}

/// Exact optical depth towards light `light` of `project` through the grid's own medium,
/// at the centres of `cells`: to the light's position for point and spot lights, along the
/// reversed light direction to infinity for directional ones.
///
/// # Panics
/// If `light` is not an index into `project.lights`.
pub fn grid_light_depth_cells(project: &Project, medium: &GridMedium64, light: usize, cells: &[[u32; 3]]) -> Vec<f64> {
    let l = &project.lights[light];
    match l.kind {
        crate::scene::LightKind::Directional { direction } => {
            let towards = -direction.as_dvec3().normalize_or_zero();
            let mut out = vec![0.0; cells.len()];
            par_fill(&mut out, 64, |n| {
                let [i, j, k] = cells[n];
                medium.ray_depth(cell_center64(&project.grid, i, j, k), towards, f64::INFINITY)
            });
            out
        }
        _ => grid_optical_depth_cells(&project.grid, medium, l.position.as_dvec3(), cells),
    }
}

/// Exact optical depth towards `light` through the analytic medium clipped to the grid box
/// (base fog outside it), at the centres of `cells`, in their order.
///
/// # Panics
/// If `light` is not an index into `project.lights`.
pub fn clipped_optical_depth_cells(project: &Project, light: usize, cells: &[[u32; 3]]) -> Vec<f64> {
    clipped_optical_depth_cells_with(project, &Medium64::from_project(project), light, cells)
}

/// [`clipped_optical_depth_cells`] through `medium` (the project's, with its base volume).
///
/// # Panics
/// If `light` is not an index into `project.lights`.
pub fn clipped_optical_depth_cells_with(
    project: &Project,
    medium: &Medium64,
    light: usize,
    cells: &[[u32; 3]],
) -> Vec<f64> {
    if matches!(project.lights[light].kind, crate::scene::LightKind::Directional { .. }) {
        return lights::sun_optical_depth_cells_with(project, &medium.without_base(), light, cells);
    }
    let source = project.lights[light].position.as_dvec3();
    let mut out = vec![0.0; cells.len()];
    par_fill(&mut out, 64, |n| {
        let [i, j, k] = cells[n];
        let x = cell_center64(&project.grid, i, j, k);
        clipped_optical_depth(&project.grid, &medium.along_line(x, (source - x).normalize_or_zero()), x, source)
    });
    out
}

/// Fills `out[n] = f(n)` on all available cores, handing out chunks of `chunk` items.
pub(crate) fn par_fill<T: Send>(out: &mut [T], chunk: usize, f: impl Fn(usize) -> T + Sync) {
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get());
    let chunk = chunk.max(1);
    let chunks = out.len().div_ceil(chunk);
    let work = Mutex::new(out.chunks_mut(chunk).enumerate());
    std::thread::scope(|s| {
        for _ in 0..threads.min(chunks) {
            s.spawn(|| loop {
                let next = work.lock().map(|mut it| it.next()).ok().flatten();
                let Some((c, items)) = next else { break };
                for (n, item) in items.iter_mut().enumerate() {
                    *item = f(c * chunk + n);
                }
            });
        }
    });
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Lcg;
    use crate::scene::{Light, Particle};
    use glam::{UVec3, Vec3};

    fn brute_force(m: &Medium64, a: DVec3, b: DVec3) -> f64 {
        let len = (b - a).length();
        let dir = (b - a) / len;
        let mut pts = Vec::new();
        for g in &m.gaussians {
            let t = dir.dot(g.center - a);
            pts.extend((-6..=6).map(|k| t + k as f64 * g.radius));
        }
        let pts = quad::breakpoints(pts, 0.0, len);
        quad::integrate(|t| m.extinction(a + dir * t), &pts, 1e-13, 0.0, 20_000).0
    }

    #[test]
    fn optical_depth_matches_brute_force_quadrature() {
        let mut s = Lcg(7);
        for _ in 0..20 {
            let p = |s: &mut Lcg| DVec3::new(s.f64(), s.f64(), s.f64()) * 4.0 - 2.0;
            let gaussians = (0..3)
                .map(|_| Gaussian64 { center: p(&mut s), radius: 0.1 + s.f64(), density: 0.1 + 5.0 * s.f64() })
                .collect();
            let m = Medium64::new(0.05, gaussians);
            let (a, b) = (p(&mut s), p(&mut s));
            let exact = m.optical_depth(a, b);
            let brute = brute_force(&m, a, b);
            assert!((exact - brute).abs() <= 1e-9 * brute, "{exact} vs {brute}");
        }
    }

    /// The base volume adds its cell values at the cell centres, trilinear between them and
    /// nothing outside the box, to σ_t and to every optical depth (against fine quadrature).
    #[test]
    fn a_base_volume_adds_as_injected() {
        let grid = GridSpec {
            min: Vec3::new(-1.0, 0.0, -0.5),
            max: Vec3::new(1.0, 1.0, 0.5),
            resolution: UVec3::new(5, 4, 3),
        };
        let mut s = Lcg(11);
        let layer = crate::scene::Volume::new(grid, (0..grid.cell_count()).map(|_| s.f64() as f32 * 3.0).collect());
        let g = Gaussian64 { center: DVec3::new(0.2, 0.5, 0.0), radius: 0.3, density: 2.0 };
        let m = Medium64::new(0.1, vec![g]).with_layer(&grid, &layer);
        let plain = Medium64::new(0.1, vec![g]);
        for idx in [0usize, 7, 59] {
            let [i, j, k] = grid.cell_of(idx);
            let x = cell_center64(&grid, i, j, k);
            assert!((m.extinction(x) - plain.extinction(x) - layer.data[idx] as f64).abs() < 1e-12);
        }
        assert_eq!(
            m.extinction(DVec3::new(1.5, 0.5, 0.0)),
            plain.extinction(DVec3::new(1.5, 0.5, 0.0)),
            "nothing outside the box"
        );
        for _ in 0..10 {
            let p = |s: &mut Lcg| DVec3::new(s.f64() * 3.0 - 1.5, s.f64() * 1.6 - 0.3, s.f64() * 1.6 - 0.8);
            let (a, b) = (p(&mut s), p(&mut s));
            let n = 100_000;
            let fine = (0..n).map(|i| m.extinction(a + (b - a) * ((i as f64 + 0.5) / n as f64))).sum::<f64>()
                * (b - a).length()
                / n as f64;
            let exact = m.optical_depth(a, b);
            // Midpoint quadrature errs by up to a step times the jump at the box faces.
            assert!((exact - fine).abs() < 1e-4 * fine.max(1.0), "{exact} vs {fine}");
            assert!(
                exact > plain.optical_depth(a, b)
                    || clip_to_box(grid.min.as_dvec3(), grid.max.as_dvec3(), a, (b - a).normalize(), (b - a).length())
                        .is_none()
            );
        }
        let outside = DVec3::new(1.5, 0.5, 2.0);
        assert!(m.without_base().extinction(outside) < 1e-20, "without base fog nothing is left outside the box");
    }

    #[test]
    fn optical_depth_of_extreme_particles_is_finite_and_accurate() {
        let a = DVec3::new(-3.0, 0.2, 0.1);
        for radius in [1e-3, 1e-2, 1.0, 1e3] {
            for density in [1e-6, 1.0, 1e4] {
                for offset in [0.0, 0.5 * radius, 3.0 * radius, 40.0 * radius] {
                    let g = Gaussian64 { center: DVec3::new(0.3, 0.2 + offset, 0.1), radius, density };
                    let m = Medium64::new(0.0, vec![g]);
                    for b in [
                        a,
                        a + DVec3::X * 1e-9,
                        DVec3::new(0.3, 0.2, 0.1),
                        DVec3::new(5.0, 0.2, 0.1),
                        DVec3::new(3.0, 0.5, 0.1),
                    ] {
                        let t = m.optical_depth(a, b);
                        assert!(t.is_finite() && t >= 0.0, "r {radius} c {density} off {offset}: {t}");
                        let brute = if a == b { 0.0 } else { brute_force(&m, a, b) };
                        assert!(
                            (t - brute).abs() <= 1e-9 * brute + NEGLIGIBLE_DEPTH,
                            "r {radius} c {density} off {offset} b {b}: {t} vs {brute}"
                        );
                    }
                }
            }
        }
    }

    #[test]
    fn full_line_through_a_gaussian_integrates_to_its_mass() {
        let g = Gaussian64 { center: DVec3::ZERO, radius: 0.7, density: 3.0 };
        let m = Medium64::new(0.0, vec![g]);
        let t = m.optical_depth(DVec3::new(-50.0, 0.0, 0.0), DVec3::new(50.0, 0.0, 0.0));
        let exact = 3.0 * 0.7 * std::f64::consts::PI.sqrt();
        assert!((t - exact).abs() < 1e-13 * exact);
        assert_eq!(m.optical_depth(DVec3::ONE, DVec3::ONE), 0.0);
    }

    #[test]
    fn volume_and_cells_agree_and_skip_hidden_particles() {
        let mut project = Project::default();
        project.grid.resolution = UVec3::new(5, 4, 3);
        project.medium.base_extinction = 0.1;
        project.particles.push(Particle::new(Vec3::new(0.0, 2.0, 0.0), 0.8, 2.0));
        let mut hidden = Particle::new(Vec3::new(0.5, 1.0, 0.0), 0.8, 100.0);
        hidden.hidden = true;
        project.particles.push(hidden);
        project.lights.push(Light::new(Vec3::new(1.0, 3.5, -1.0), 1.0, Vec3::ONE));
        let volume = optical_depth_volume(&project, 0);
        assert_eq!(volume.len(), 60);
        let cells = [[0, 0, 0], [4, 3, 2], [2, 1, 1]];
        let sampled = optical_depth_cells(&project, 0, &cells);
        let medium = Medium64::from_project(&project);
        assert_eq!(medium.gaussians.len(), 1);
        for (n, [i, j, k]) in cells.iter().copied().enumerate() {
            assert_eq!(sampled[n], volume[project.grid.index(i, j, k)]);
            let x = cell_center64(&project.grid, i, j, k);
            assert_eq!(sampled[n], medium.optical_depth(x, DVec3::new(1.0, 3.5, -1.0)));
        }
    }
}

#[cfg(test)]
mod timings {
    use super::*;
    use std::time::Instant;

    /// `cargo test --release --lib demo_project_timings -- --ignored --nocapture`: the
    /// reference's costs on the demos, and its fixed-step march against the adaptive
    /// integral at a few pixels.
    #[test]
    #[ignore = "prints the reference's costs on the demos (minutes on two cores); run by hand"]
    fn demo_project_timings() {
        for name in ["cloud", "cornell", "street", "room"] {
            let path = std::path::PathBuf::from(env!("CARGO_MANIFEST_DIR")).join(format!("projects/{name}.ron"));
            let project = match crate::scene::load_project(&path) {
                Ok(p) => p,
                Err(e) => panic!("{e}"),
            };
            let t = Instant::now();
            let opv = optical_depth_volume(&project, 0);
            let opv_s = t.elapsed().as_secs_f64();
            let t = Instant::now();
            let image = render_reference(&project, 32, 18, &RefRenderOptions::default());
            let render_s = t.elapsed().as_secs_f64();
            let max_t = opv.iter().copied().fold(0.0, f64::max);
            let medium = Medium64::from_project(&project);
            let origin = project.camera.position.as_dvec3();
            let mut worst = 0.0_f64;
            for (px, py) in [(16, 9), (5, 4), (25, 12), (10, 15)] {
                let dir = camera_ray64(&project.camera, px, py, 32, 18);
                let march =
                    radiance_along_ray(&medium, &project, origin, dir, f64::INFINITY, &RefRenderOptions::default());
                let exact = in_scatter_adaptive(&medium, &project, origin, dir, f64::INFINITY, 1e-9);
                worst = worst.max(((march[0] - exact[0]) / exact[0]).abs());
            }
            println!("{name}: default step {:.2e} m, march vs adaptive max rel {worst:.2e}", default_step(&project));
            let mean_l = image.iter().map(|p| p[0]).sum::<f64>() / image.len() as f64;
            assert!(max_t.is_finite() && mean_l.is_finite() && mean_l >= 0.0, "{name}: T {max_t}, mean R {mean_l}");
            assert!(worst.is_finite(), "{name}: the march against the adaptive integral gave {worst}");
            println!(
                "{name}: OPV {} cells in {opv_s:.2} s (max T {max_t:.2}); reference 32x18 in {render_s:.2} s (mean R {mean_l:.3e}); {} threads",
                opv.len(),
                std::thread::available_parallelism().map_or(1, |n| n.get())
            );
        }
    }
}

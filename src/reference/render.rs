//! Reference single scattering (physics.md §4 with §8's rule): exact transmittance towards
//! the lights and along the view ray, steps far finer than the preview's.
//!
//! Semantics shared with the GPU ray march: σ_s = albedo·σ_t; isotropic phase 1/(4π) when the
//! anisotropy g is 0, else Henyey–Greenstein with cosθ = ⟨(x − S)/|x − S|, −ω⟩; light radiance
//! I·color/|S − x|² · exp(−T(x, S)), or none where a surface blocks the path from x to the light
//! (by [`shadowed`]'s rules, as for surfaces); hidden lights are ignored. Without base fog only the
//! ray's overlap with the grid box is integrated (particles are assumed inside it); with base
//! fog the ray runs from the camera to `t_max` (possibly infinite), the parts outside the box
//! carrying base fog only.

use super::{par_fill, quad, Medium64};
use crate::scene::{Camera, Light, Project};
use glam::DVec3;
use std::f64::consts::PI;

/// A hard cap on march steps per ray, far above what any sane scene needs.
const MAX_STEPS: usize = 100_000_000;

/// How finely [`radiance_along_ray`] and [`render_reference`] integrate.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct RefRenderOptions {
    /// Step inside the grid box in metres; `None`: [`default_step`].
    pub step: Option<f64>,
    /// Upper bound on a step as a fraction of the distance to the nearest light and, outside
    /// the box, of the base fog's mean free path. Default 0.01.
    pub rel_step: f64,
    /// The march stops once what remains is provably below this fraction of the radiance
    /// gathered so far. Default 1e-9.
    pub tolerance: f64,
}

impl Default for RefRenderOptions {
    fn default() -> Self {
        Self { step: None, rel_step: 0.01, tolerance: 1e-9 }
    }
}

/// The smallest cell edge / 16, or 1/16 of the preview's step where that is finer
/// (physics.md §8: at least 16× finer than the preview).
pub fn default_step(project: &Project) -> f64 {
    let grid = &project.grid;
    let cell = (grid.size().as_dvec3() / grid.resolution.as_dvec3()).min_element();
    let preview = cell * project.render.step_factor as f64;
    cell.min(if preview > 0.0 { preview } else { cell }) / 16.0
}

struct Light64 {
    position: DVec3,
    rgb: DVec3,
    light: Light,
    /// A directional light's unit direction of travel.
    sun: Option<DVec3>,
    /// For a sun: the medium's gaussians without base fog (its height fog is integrated apart).
    gaussians: Option<Medium64>,
}

impl Light64 {
    /// The spot's cone factor at `x` (1 for a point light).
    fn cone(&self, x: DVec3) -> f64 {
        self.light.cone_factor(x)
    }
}

/// Light arriving at `x` from `l` per unit of its intensity: (direction of travel, cone/d² for
/// point and spot lights or 1 for a sun, transmittance from the light).
fn arriving(medium: &Medium64, project: &Project, l: &Light64, x: DVec3) -> Option<(DVec3, f64, f64)> {
    if let Some(direction) = l.sun {
        let gaussians = l.gaussians.as_ref().unwrap_or(medium);
        let depth = super::lights::sun_optical_depth(project, gaussians, x, direction);
        return Some((direction, 1.0, (-depth).exp()));
    }
    let to_x = x - l.position;
    let d2 = to_x.length_squared();
    let cone = l.cone(x);
    if d2 == 0.0 || cone == 0.0 {
        return None;
    }
    Some((to_x / d2.sqrt(), cone / d2, (-medium.optical_depth(x, l.position)).exp()))
}

/// [`arriving`] at a fog sample `x`, or None where a surface blocks the path to the light.
fn arriving_fog(medium: &Medium64, project: &Project, l: &Light64, x: DVec3) -> Option<(DVec3, f64, f64)> {
    if !project.surfaces.is_empty() {
        let (towards, reach) = match l.sun {
            Some(direction) => (-direction, f64::INFINITY),
            None => {
                let v = l.position - x;
                let d = v.length();
                (v / d, d)
            }
        };
        if reach > 0.0 && shadowed(project, x, DVec3::ZERO, towards, reach) {
            return None;
        }
    }
    arriving(medium, project, l, x)
}

fn lights64(project: &Project, medium: &Medium64) -> Vec<Light64> {
    project
        .visible_lights()
        .map(|l| Light64 {
            position: l.position.as_dvec3(),
            rgb: l.radiance_rgb().as_dvec3(),
            light: l.clone(),
            sun: match l.kind {
                crate::scene::LightKind::Directional { direction } => Some(direction.as_dvec3().normalize()),
                _ => None,
            },
            gaussians: matches!(l.kind, crate::scene::LightKind::Directional { .. }).then(|| medium.without_base()),
        })
        .filter(|l| l.rgb.max_element() > 0.0)
        .collect()
}

#[derive(Clone, Copy)]
struct Phase {
    g: f64,
}

impl Phase {
    fn eval(self, cos_theta: f64) -> f64 {
        let g = self.g;
        if g == 0.0 {
            return 1.0 / (4.0 * PI);
        }
        (1.0 - g * g) / (4.0 * PI * (1.0 + g * g - 2.0 * g * cos_theta).powf(1.5))
    }
    fn max(self) -> f64 {
        self.eval(self.g.signum())
    }
}

/// The part of the ray that is integrated, and its overlap with the grid box.
struct Domain {
    t0: f64,
    t1: f64,
    in_box: Option<(f64, f64)>,
}

fn ray_box(origin: DVec3, dir: DVec3, min: DVec3, max: DVec3) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for a in 0..3 {
        if dir[a] == 0.0 {
            if origin[a] < min[a] || origin[a] > max[a] {
                return None;
            }
            continue;
        }
        let (ta, tb) = ((min[a] - origin[a]) / dir[a], (max[a] - origin[a]) / dir[a]);
        t0 = t0.max(ta.min(tb));
        t1 = t1.min(ta.max(tb));
    }
    (t0 <= t1).then_some((t0, t1))
}

fn domain(project: &Project, base: f64, origin: DVec3, dir: DVec3, t_max: f64) -> Option<Domain> {
    let grid = &project.grid;
    let in_box = ray_box(origin, dir, grid.min.as_dvec3(), grid.max.as_dvec3())
        .map(|(a, b)| (a.max(0.0), b.min(t_max)))
        .filter(|(a, b)| a < b);
    if base > 0.0 {
        (t_max > 0.0).then_some(Domain { t0: 0.0, t1: t_max, in_box })
    } else {
        in_box.map(|(a, b)| Domain { t0: a, t1: b, in_box })
    }
}

/// Radiance arriving from all lights at `x` (past the surfaces), scattered towards −`dir`, per
/// unit σ_s.
fn in_scattered(medium: &Medium64, project: &Project, lights: &[Light64], phase: Phase, x: DVec3, dir: DVec3) -> DVec3 {
    lights
        .iter()
        .filter_map(|l| {
            let (travel, geometry, tr) = arriving_fog(medium, project, l, x)?;
            Some(l.rgb * (geometry * phase.eval(travel.dot(-dir)) * tr))
        })
        .sum()
}

/// Nearest distance from `light` to the ray `origin + s·dir` over s ≥ t.
fn nearest_ahead(origin: DVec3, dir: DVec3, t: f64, light: DVec3) -> f64 {
    let s = dir.dot(light - origin).max(t);
    (origin + dir * s - light).length()
}

/// Single-scattered radiance along `origin + t·dir` for t up to `t_max`, marching with the
/// exact segment optical depth and midpoint in-scattering (see the module doc for the
/// semantics). Each segment contributes Tv·albedo·L_in(midpoint)·(1 − exp(−τ_segment)),
/// the exact integral for constant in-scattered radiance whatever the density.
pub fn radiance_along_ray(
    medium: &Medium64,
    project: &Project,
    origin: DVec3,
    dir: DVec3,
    t_max: f64,
    opts: &RefRenderOptions,
) -> [f64; 3] {
    let dir = dir.normalize();
    let lights = lights64(project, medium);
    let Some(dom) = domain(project, medium.base(), origin, dir, t_max) else { return [0.0; 3] };
    if lights.is_empty() || !dir.is_finite() {
        return [0.0; 3];
    }
    let view = medium.along_line(origin, dir);
    let albedo = project.medium.albedo.clamp(0.0, 1.0) as f64;
    let phase = Phase { g: project.medium.anisotropy as f64 };
    let step = opts.step.filter(|s| *s > 0.0).unwrap_or_else(|| default_step(project));
    let min_step = step * 1e-4;
    let (b0, b1) = dom.in_box.unwrap_or((f64::INFINITY, f64::INFINITY));
    let bound_scale = albedo * phase.max();
    let (mut t, mut tau, mut radiance) = (dom.t0, 0.0_f64, DVec3::ZERO);
    for _ in 0..MAX_STEPS {
        if t >= dom.t1 {
            break;
        }
        let x = origin + dir * t;
        let inside = t >= b0 && t < b1;
        // Outside the box a step spans about rel_step of base fog optical depth (at most a
        // million steps' worth of the grid's own step, where height fog has all but vanished).
        let mut h =
            if inside || medium.base() <= 0.0 { step } else { (opts.rel_step / medium.base_at(x.y)).min(1e6 * step) };
        let near =
            lights.iter().filter(|l| l.sun.is_none()).map(|l| (x - l.position).length()).fold(f64::INFINITY, f64::min);
        h = h.min((opts.rel_step * near).max(min_step));
        if t < b0 {
            h = h.min(b0 - t);
        } else if inside {
            h = h.min(b1 - t);
        }
        let t_next = (t + h).min(dom.t1);
        if t_next <= t {
            break;
        }
        let seg = view.optical_depth(x, origin + dir * t_next);
        let weight = (-tau).exp() * albedo * -(-seg).exp_m1();
        if weight > 0.0 {
            radiance +=
                weight * in_scattered(medium, project, &lights, phase, origin + dir * (0.5 * (t + t_next)), dir);
        }
        tau += seg;
        t = t_next;
        let tv = (-tau).exp();
        // What a light can still add is bounded by the opacity of the fog left ahead, once
        // the grid box is behind (∫σ e^{−τ} ≤ 1 − e^{−τ_rest}); a sun has no falloff.
        let fog_ahead = if t >= b1 || b0.is_infinite() {
            -(-medium.base_depth(origin + dir * t, dir, f64::INFINITY)).exp_m1()
        } else {
            1.0
        };
        let rest: f64 = lights
            .iter()
            .map(|l| match l.sun {
                // In homogeneous base fog no sunlight gets through at all.
                Some(_) if project.medium.height_falloff == 0.0 && medium.base() > 0.0 => 0.0,
                Some(_) => l.rgb.element_sum() * fog_ahead,
                // ∫σ e^{−τ} over what is left is at most the opacity of the fog ahead, too:
                // height fog thinning out ends the march, as it does for a sun.
                None => l.rgb.element_sum() / nearest_ahead(origin, dir, t, l.position).powi(2) * fog_ahead,
            })
            .sum();
        if tv == 0.0 || tv * bound_scale * rest <= opts.tolerance * radiance.element_sum() {
            break;
        }
    }
    radiance.to_array()
}

/// The same integral as [`radiance_along_ray`] by globally adaptive Gauss–Kronrod
/// quadrature of the full integrand σ_s·p·I/d²·exp(−T(O, x) − T(x, S)) (0 where a surface
/// blocks the light), both optical depths exact, to relative tolerance `rel_tol`. The domain is split at each light's and each
/// nearby particle's closest approach and at the box faces; an infinite tail is mapped onto
/// a finite interval. Far slower than marching; used to validate it (and the Sun test).
pub fn in_scatter_adaptive(
    medium: &Medium64,
    project: &Project,
    origin: DVec3,
    dir: DVec3,
    t_max: f64,
    rel_tol: f64,
) -> [f64; 3] {
    let dir = dir.normalize();
    let lights = lights64(project, medium);
    let Some(dom) = domain(project, medium.base(), origin, dir, t_max) else { return [0.0; 3] };
    if !dir.is_finite() {
        return [0.0; 3];
    }
    let view = medium.along_line(origin, dir);
    let albedo = project.medium.albedo.clamp(0.0, 1.0) as f64;
    let phase = Phase { g: project.medium.anisotropy as f64 };
    let mut split = Vec::new();
    if let Some((a, b)) = dom.in_box {
        split.extend([a, b]);
    }
    for g in view.gaussians() {
        let t = dir.dot(g.center - origin);
        split.extend([-2.0, -1.0, 0.0, 1.0, 2.0].map(|k| t + k * g.radius));
    }
    let mut radiance = DVec3::ZERO;
    for light in &lights {
        let integrand = |t: f64| {
            let x = origin + dir * t;
            let Some((travel, geometry, tr)) = arriving_fog(medium, project, light, x) else { return 0.0 };
            geometry
                * albedo
                * medium.extinction(x)
                * phase.eval(travel.dot(-dir))
                * tr
                * (-view.optical_depth(origin, x)).exp()
        };
        let mut points = split.clone();
        if light.sun.is_none() {
            points.push(dir.dot(light.position - origin));
        }
        let finite_end = if dom.t1.is_finite() {
            dom.t1
        } else {
            points.iter().copied().filter(|p| p.is_finite()).fold(dom.t0, f64::max) + 1.0 / medium.base()
        };
        let points = quad::breakpoints(points, dom.t0, finite_end);
        let (mut value, _) = quad::integrate(integrand, &points, rel_tol, 0.0, 5_000);
        if !dom.t1.is_finite() {
            let scale = 1.0 / medium.base();
            let tail = |s: f64| {
                let t = finite_end + scale * s / (1.0 - s);
                integrand(t) * scale / ((1.0 - s) * (1.0 - s))
            };
            value += quad::integrate(tail, &[0.0, 1.0], rel_tol, rel_tol * value.abs(), 5_000).0;
        }
        radiance += light.rgb * value;
    }
    radiance.to_array()
}

/// Unit direction through the centre of pixel (px, py), as `Camera::ray_dir` in f64.
pub fn camera_ray64(camera: &Camera, px: u32, py: u32, width: u32, height: u32) -> DVec3 {
    let position = camera.position.as_dvec3();
    let forward = (camera.target.as_dvec3() - position).normalize();
    let right = forward.cross(camera.up.as_dvec3()).normalize();
    let up = right.cross(forward);
    let tan_half = ((camera.fov_y_deg as f64).to_radians() * 0.5).tan();
    let aspect = width as f64 / height as f64;
    let sx = ((px as f64 + 0.5) / width as f64 * 2.0 - 1.0) * tan_half * aspect;
    let sy = (1.0 - (py as f64 + 0.5) / height as f64 * 2.0) * tan_half;
    (forward + right * sx + up * sy).normalize()
}

/// Linear RGB radiance of every pixel, row-major with row 0 at the top, from the project's
/// camera, rows shared among all cores. A ray stops at the first surface (the rules of
/// [`Surfaces::first_hit`](crate::scene::Surfaces::first_hit)), which adds its Lambertian
/// radiance lit through the fog, attenuated by the exact view transmittance.
pub fn render_reference(project: &Project, width: u32, height: u32, opts: &RefRenderOptions) -> Vec<[f64; 3]> {
    render_reference_with(project, &Medium64::from_project(project), width, height, opts)
}

/// [`render_reference`] through `medium` (the project's, with its base volume).
pub fn render_reference_with(
    project: &Project,
    medium: &Medium64,
    width: u32,
    height: u32,
    opts: &RefRenderOptions,
) -> Vec<[f64; 3]> {
    let lights = lights64(project, medium);
    let origin = project.camera.position.as_dvec3();
    let mut out = vec![[0.0; 3]; width as usize * height as usize];
    par_fill(&mut out, width as usize, |n| {
        let (px, py) = ((n % width as usize) as u32, (n / width as usize) as u32);
        let dir = camera_ray64(&project.camera, px, py, width, height);
        let hit = project.surfaces.first_hit(origin, dir);
        let t_max = hit.map_or(f64::INFINITY, |h| h.t);
        let mut l = DVec3::from(radiance_along_ray(medium, project, origin, dir, t_max, opts));
        if let Some(h) = hit {
            let x = origin + dir * h.t;
            l += (-medium.optical_depth(origin, x)).exp() * surface_radiance(medium, project, &lights, x, dir, &h);
        }
        l.to_array()
    });
    out
}

/// Radiance leaving a surface point towards the camera (view direction `dir`), Lambertian plus
/// Phong specular, lit by every light through the fog, by the rules of the GPU march's
/// `shade_surface`: direct light unless another surface blocks the straight path to the light
/// ([`shadowed`]), plus, in homogeneous base fog, Sun et al.'s surface term for point and spot
/// lights from the exact G and S functions ([`crate::surface_table::g_exact`] and
/// [`crate::surface_table::s_exact`], themselves checked against quadrature over the
/// directions in [`super::surface_glow`]), times the medium's albedo, the spot's cone factor
/// at x and the transmittance of the medium's optical depth beyond the base fog's on the
/// direct path.
fn surface_radiance(
    medium: &Medium64,
    project: &Project,
    lights: &[Light64],
    x: DVec3,
    dir: DVec3,
    hit: &crate::scene::SurfaceHit,
) -> DVec3 {
    let (normal, albedo, ks, n) = (hit.normal, hit.albedo, hit.specular, hit.phong_exponent);
    let mirror = dir - 2.0 * dir.dot(normal) * normal;
    let beta = project.medium.base_extinction as f64;
    let glow = beta > 0.0 && project.medium.height_falloff == 0.0;
    lights
        .iter()
        .map(|l| {
            let mut out = DVec3::ZERO;
            if glow && l.sun.is_none() {
                let to_light = l.position - x;
                let d = to_light.length();
                let cone = l.cone(x);
                if cone > 0.0 && d > 0.0 {
                    let theta = normal.dot(to_light / d).clamp(-1.0, 1.0).acos();
                    let extra = (-(medium.optical_depth(x, l.position) - beta * d).max(0.0)).exp();
                    let g = crate::surface_table::glow_radiance(beta, d, theta, crate::surface_table::g_exact);
                    let mut rho = albedo * g;
                    if ks > 0.0 {
                        let theta_r = mirror.dot(to_light / d).clamp(-1.0, 1.0).acos();
                        rho += DVec3::splat(
                            ks * crate::surface_table::spec_radiance(
                                beta,
                                d,
                                theta_r,
                                n,
                                crate::surface_table::s_exact,
                            ),
                        );
                    }
                    out += rho * l.rgb * (project.medium.albedo as f64 * cone * extra);
                }
            }
            if let Some((travel, geometry, tr)) = arriving(medium, project, l, x) {
                let cos = normal.dot(-travel);
                let reach = if l.sun.is_some() { f64::INFINITY } else { (l.position - x).length() };
                if cos > 0.0 && !shadowed(project, x, normal, -travel, reach) {
                    let brdf =
                        albedo / PI * cos + DVec3::splat(ks * crate::surface_table::phong_lobe(mirror.dot(-travel), n));
                    out += brdf * l.rgb * (geometry * tr);
                }
            }
            out
        })
        .sum()
}

/// Whether a surface of `project` blocks the path from `x` (on a surface with normal `n`)
/// along unit `u` before distance `t_max`: a box the path enters (or starts in), or the ground
/// crossed from above. The start is lifted off its surface by a hair along `n`, and a light
/// within 0.1 % of the distance of a face, on its outer side, is not blocked by that face.
pub fn shadowed(project: &Project, x: DVec3, n: DVec3, u: DVec3, t_max: f64) -> bool {
    let eps = 1e-9 * (1.0 + x.abs().max_element());
    let o = x + n * eps;
    let reach = t_max * (1.0 - 1e-3);
    if let Some(g) = &project.surfaces.ground {
        let h = g.height as f64;
        if u.y < 0.0 && o.y > h && (h - o.y) / u.y < reach {
            return true;
        }
    }
    project.surfaces.boxes.iter().any(|b| {
        ray_box(o, u, b.min.as_dvec3(), b.max.as_dvec3()).is_some_and(|(t_in, t_out)| t_out > 0.0 && t_in < reach)
    })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::reference::sun::REFERENCE_VALUES;
    use crate::scene::{Light, Particle};
    use glam::{UVec3, Vec3};

    /// Homogeneous fog β, no particles, one white light of intensity 1 at distance D_sv and
    /// angle γ from the ray origin + t·x̂; the box covers only the ray's first metre.
    fn sun_scene(gamma: f64, d_sv: f64, beta: f64) -> (Project, DVec3) {
        let mut project = Project::default();
        project.grid.min = Vec3::splat(-1.0);
        project.grid.max = Vec3::splat(1.0);
        project.grid.resolution = UVec3::splat(32);
        project.medium.base_extinction = beta as f32;
        let light = DVec3::new(gamma.cos(), gamma.sin(), 0.0) * d_sv;
        project.lights.push(Light::new(light.as_vec3(), 1.0, Vec3::ONE));
        (project, light)
    }

    #[test]
    fn marching_and_adaptive_reproduce_sun_reference_values() {
        for (gamma, d_sv, d_vp, beta, want) in REFERENCE_VALUES {
            let (mut project, light) = sun_scene(gamma, d_sv, beta);
            // The project stores f32: compare against the closed form for exactly the stored
            // β and light distance, with the ray turned so that γ is exact.
            let stored = project.lights[0].position.as_dvec3();
            let rot_gamma = stored.y.atan2(stored.x);
            let d = stored.length();
            assert!((rot_gamma - gamma).abs() < 1e-6 && (d - d_sv).abs() < 1e-5 * d_sv, "{light}");
            project.lights[0].position = stored.as_vec3();
            let dir = DVec3::new((rot_gamma - gamma).cos(), (rot_gamma - gamma).sin(), 0.0);
            let exact = crate::reference::sun::sun_la(gamma, d, d_vp, project.medium.base_extinction as f64, 1.0);
            assert!(((exact - want) / want).abs() < 1e-6);
            let medium = Medium64::from_project(&project);
            let march = radiance_along_ray(&medium, &project, DVec3::ZERO, dir, d_vp, &RefRenderOptions::default());
            let adaptive = in_scatter_adaptive(&medium, &project, DVec3::ZERO, dir, d_vp, 1e-10);
            for c in 0..3 {
                assert!(((march[c] - exact) / exact).abs() < 1e-3, "march γ {gamma}: {} vs {exact}", march[c]);
                assert!(((adaptive[c] - exact) / exact).abs() < 1e-9, "adaptive γ {gamma}: {} vs {exact}", adaptive[c]);
            }
            println!(
                "γ {gamma}: march rel err {:.2e}, adaptive rel err {:.2e}",
                march[0] / exact - 1.0,
                adaptive[0] / exact - 1.0
            );
        }
    }

    fn tiny_project() -> Project {
        let mut project = Project::default();
        project.grid.resolution = UVec3::splat(16);
        project.medium.anisotropy = 0.4;
        project.medium.albedo = 0.9;
        project.particles.push(Particle::new(Vec3::new(0.0, 1.5, 0.0), 0.6, 3.0));
        project.particles.push(Particle::new(Vec3::new(0.8, 2.2, 0.3), 0.3, 8.0));
        project.lights.push(Light::new(Vec3::new(1.5, 3.5, 1.0), 20.0, Vec3::new(1.0, 0.8, 0.6)));
        let mut hidden = Light::new(Vec3::new(0.0, 1.5, 0.0), 1e6, Vec3::ONE);
        hidden.hidden = true;
        project.lights.push(hidden);
        project
    }

    #[test]
    fn marching_matches_adaptive_through_particles() {
        let project = tiny_project();
        let medium = Medium64::from_project(&project);
        let origin = project.camera.position.as_dvec3();
        for target in [DVec3::new(0.0, 1.5, 0.0), DVec3::new(0.7, 2.1, 0.2), DVec3::new(-0.5, 0.5, 0.0)] {
            let dir = (target - origin).normalize();
            let march = radiance_along_ray(&medium, &project, origin, dir, f64::INFINITY, &RefRenderOptions::default());
            let adaptive = in_scatter_adaptive(&medium, &project, origin, dir, f64::INFINITY, 1e-9);
            for c in 0..3 {
                assert!(((march[c] - adaptive[c]) / adaptive[c]).abs() < 1e-3, "{target}: {march:?} vs {adaptive:?}");
            }
            println!("{target}: march vs adaptive rel {:.2e}", march[0] / adaptive[0] - 1.0);
        }
    }

    #[test]
    fn render_smoke() {
        let mut project = tiny_project();
        project.medium.base_extinction = 0.02;
        let image = render_reference(&project, 8, 6, &RefRenderOptions { step: Some(0.02), ..Default::default() });
        assert_eq!(image.len(), 48);
        assert!(image.iter().flatten().all(|v| v.is_finite() && *v >= 0.0));
        // Base fog lights every pixel; the particle glows brighter than the corners; red
        // dominates as the light's colour says.
        assert!(image.iter().all(|p| p[0] > 0.0 && p[0] >= p[1] && p[1] >= p[2]));
        let centre = image[3 * 8 + 4][0];
        assert!(centre > 2.0 * image[0][0], "centre {centre} corner {}", image[0][0]);
        assert!(centre < 100.0);
    }
}

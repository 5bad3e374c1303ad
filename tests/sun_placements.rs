//! Optical depth towards suns on randomized scenes, per class of sun direction: the refined
//! directional sweep and `exact` against the line integral through the grid's own trilinear
//! medium (the scheme error), `analytic` against the gaussians clipped to the box and the
//! height fog in closed form. Particles of 1–10 cells radius; cubic, non-cubic and thin grids;
//! half the scenes in exponential height fog. `cargo test --release --test sun_placements --
//! --nocapture --test-threads=1` prints each scheme's table, with the plain sweep's for
//! comparison; SUN_SEED=n draws other scenes.

mod common;

use common::scenes::transmittance_errors;
use common::{pipeline, Lcg};
use fogsmith::gpu::FrameRequest;
use fogsmith::measure::{opv_error_against, opv_errors, sample_cells};
use fogsmith::reference::clipped_optical_depth_cells;
use fogsmith::scene::{Camera, GridSpec, Light, LightKind, Medium, Particle, Project, Scheme};
use glam::{UVec3, Vec3};

/// The refined directional sweep's and `exact`'s largest transmittance error against the
/// grid's medium: the goal the point lights' sweep meets.
const SCHEME_BOUND: f64 = 2e-3;

/// `analytic` against the clipped gaussians: f32 rounding and the erf approximation only.
const ANALYTIC_BOUND: f64 = 2e-5;

const CLASSES: [&str; 6] =
    ["along an axis", "diagonal", "grazing a face", "straight down", "nearly horizontal", "random"];

/// One direction towards the sun per class, in `CLASSES` order. In height fog the sun is kept
/// above the horizon (a path that never rises out of the fog is opaque), except along a
/// horizontal axis.
fn towards_by_class(rng: &mut Lcg, fog: bool) -> Vec<Vec3> {
    let up = |v: Vec3| if fog { Vec3::new(v.x, v.y.abs(), v.z) } else { v };
    let axis = {
        let mut v = Vec3::ZERO;
        v[rng.pick(3)] = rng.sign();
        up(v)
    };
    let diagonal = up(Vec3::new(rng.sign(), rng.sign(), rng.sign()).normalize());
    // Within 1° of parallel to a face: a direction in the face's plane tilted out of it.
    let grazing = {
        let f = rng.pick(3);
        let (b, c) = ((f + 1) % 3, (f + 2) % 3);
        let phi = rng.range(0.0, std::f32::consts::TAU);
        let tilt = rng.range(0.05, 1.0).to_radians() * if fog && f == 1 { 1.0 } else { rng.sign() };
        let mut v = Vec3::ZERO;
        v[b] = phi.cos() * tilt.cos();
        v[c] = phi.sin() * tilt.cos();
        v[f] = tilt.sin();
        let v = up(v);
        // In fog a direction in a vertical face's plane must still rise.
        if fog && f != 1 && v.y < 0.05 {
            Vec3::new(v.x, 0.3, v.z).normalize()
        } else {
            v
        }
    };
    let down = Vec3::Y;
    let horizontal = {
        let (h, phi) = (rng.range(1.0, 5.0).to_radians(), rng.range(0.0, std::f32::consts::TAU));
        Vec3::new(h.cos() * phi.cos(), h.sin(), h.cos() * phi.sin())
    };
    let random = up(Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize());
    vec![axis, diagonal, grazing, down, horizontal, random]
}

fn scene(rng: &mut Lcg, resolution: UVec3, fog: bool) -> (Project, usize) {
    let mut p = Project::default();
    let cell = 0.05;
    let size = resolution.as_vec3() * cell;
    let offset = Vec3::new(0.3, -0.1, 0.2);
    p.grid = GridSpec { min: -0.5 * size + offset, max: 0.5 * size + offset, resolution };
    p.medium = Medium { albedo: 0.8, ..Medium::default() };
    if fog {
        p.medium.base_extinction = rng.range(0.05, 0.5);
        p.medium.height_falloff = rng.range(0.5, 3.0);
        p.medium.height_origin = p.grid.min.y;
    }
    let n = 6 + rng.pick(10);
    for _ in 0..n {
        let r = cell * rng.range(1.0, 10.0);
        let centre =
            p.grid.min - Vec3::splat(r) + (size + Vec3::splat(2.0 * r)) * Vec3::new(rng.f32(), rng.f32(), rng.f32());
        // Peak optical depth through the particle between 0.1 and 2.
        let density = rng.range(0.1, 2.0) / (r * 1.772_453_9);
        p.particles.push(Particle::new(centre, r, density));
    }
    p.lights = towards_by_class(rng, fog)
        .into_iter()
        .map(|towards| Light {
            kind: LightKind::Directional { direction: -towards },
            ..Light::new(Vec3::ZERO, 1.0, Vec3::ONE)
        })
        .collect();
    p.camera = Camera { position: Vec3::new(0.0, 0.0, 5.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 45.0 };
    p.render.width = 8;
    p.render.height = 8;
    (p, n)
}

/// What a run measures: the OPV against the grid's medium, or against the clipped gaussians.
#[derive(Clone, Copy, PartialEq)]
enum Against {
    Grid,
    Gaussians,
}

/// The worst transmittance error per class of sun direction of `scheme` (the sweep with
/// `refine` or not) on the scenes of `seed`.
fn worst_by_class(scheme: Scheme, refine: bool, against: Against, seed: u64) -> Vec<f64> {
    let mut gpu = pipeline();
    let grids = [UVec3::splat(32), UVec3::new(40, 24, 16), UVec3::new(48, 5, 40), UVec3::new(12, 48, 10)];
    let mut worst = vec![0.0f64; CLASSES.len()];
    let mut rng = Lcg(seed);
    for &res in &grids {
        for fog in [false, true] {
            let (mut p, particles) = scene(&mut rng, res, fog);
            p.propagation.scheme = scheme;
            p.propagation.sweep_refine = refine;
            gpu.update(&p, &FrameRequest::for_project(&p)).unwrap();
            let ev = gpu.read_ev().unwrap();
            let cells = sample_cells(&p.grid, 6000);
            for (l, light) in p.lights.iter().enumerate() {
                let opv = gpu.read_opv(l).unwrap();
                let e = match against {
                    Against::Grid => opv_errors(&p, l, &ev, &opv, &cells).scheme,
                    Against::Gaussians => {
                        opv_error_against(l, &opv, &cells, &clipped_optical_depth_cells(&p, l, &cells))
                    }
                };
                assert!(!e.nan_or_inf, "{scheme} {res} sun {l}: NaN or infinity");
                if std::env::var("SUN_DIAG").is_ok() && against == Against::Grid {
                    diagnose(&p, l, &ev, &opv, &cells);
                }
                let LightKind::Directional { direction } = light.kind else { unreachable!() };
                println!(
                    "{scheme} refine {refine:5} {:>3}×{:>3}×{:>3} {particles:2} particles fog {fog:5} {:18} towards {:>6.3?}: {:.2e}",
                    res.x,
                    res.y,
                    res.z,
                    CLASSES[l],
                    (-direction).to_array(),
                    e.transmittance_max_abs_error
                );
                worst[l] = worst[l].max(e.transmittance_max_abs_error);
            }
        }
    }
    println!("{scheme} refine {refine}, seed {seed}: worst transmittance error per class of sun direction");
    for (class, w) in CLASSES.iter().zip(&worst) {
        println!("  {class:18} {w:.2e}");
    }
    worst
}

/// The worst cell of sun `l`: the reference and computed optical depth.
fn diagnose(p: &Project, l: usize, ev: &fogsmith::scene::Volume, opv: &fogsmith::scene::Volume, cells: &[[u32; 3]]) {
    use fogsmith::reference::{grid_light_depth_cells, GridMedium64};
    let medium = GridMedium64::for_project(p, ev);
    let exact = grid_light_depth_cells(p, &medium, l, cells);
    let got = |c: &[u32; 3]| opv.get(c[0], c[1], c[2]) as f64;
    let (errors, worst) = transmittance_errors(opv, cells, &exact);
    let bad = errors.iter().filter(|&&e| e > SCHEME_BOUND).count();
    let Some(n) = worst else { return };
    let c = cells[n];
    println!(
        "    worst cell {c:?} error {:.2e} reference {:.5} got {:.5}; {bad} cells beyond the bound",
        errors[n],
        exact[n],
        got(&c)
    );
}

fn seeds() -> Vec<u64> {
    std::env::var("SUN_SEED").map_or(vec![0x5EED_0036, 11], |s| vec![s.parse().expect("SUN_SEED is a number")])
}

fn check(scheme: Scheme, refine: bool, against: Against, bound: f64) {
    for seed in seeds() {
        let worst = worst_by_class(scheme, refine, against, seed);
        for (class, w) in CLASSES.iter().zip(&worst) {
            assert!(*w <= bound, "seed {seed}, {scheme} refine {refine}, sun {class}: error {w:.3e} > {bound:e}");
        }
    }
}

#[test]
fn refined_directional_sweep_is_accurate_for_every_sun_direction() {
    check(Scheme::Sweep, true, Against::Grid, SCHEME_BOUND);
}

/// The error control is what brings the sweep within the bound: without it the same scenes
/// measure well above it.
#[test]
fn the_plain_directional_sweep_is_less_accurate() {
    let seed = seeds()[0];
    let plain = worst_by_class(Scheme::Sweep, false, Against::Grid, seed);
    let refined = worst_by_class(Scheme::Sweep, true, Against::Grid, seed);
    let (p, r) = (plain.iter().cloned().fold(0.0, f64::max), refined.iter().cloned().fold(0.0, f64::max));
    assert!(r < 0.5 * p, "seed {seed}: refined {r:.3e} against plain {p:.3e}");
}

#[test]
fn exact_scheme_matches_the_grid_medium_for_every_sun_direction() {
    check(Scheme::Exact, false, Against::Grid, SCHEME_BOUND);
}

#[test]
fn analytic_scheme_is_exact_against_the_gaussians_for_every_sun_direction() {
    check(Scheme::Analytic, false, Against::Gaussians, ANALYTIC_BOUND);
}

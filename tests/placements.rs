//! Optical depth for every class of light placement, on randomized scenes: the GPU's OPV
//! against the line integral through the grid's own trilinear medium (the scheme error),
//! and that medium against the analytic gaussians clipped to the box (the resolution error).
//! `cargo test --release --test placements -- --nocapture --test-threads=1` prints the table
//! per class, for particles of 1–10 and of 6–10 cells radius; SWEEP_STRIDES=4,8,16 measures
//! other strides (the bounds are for stride 8), PLACEMENT_SEED=n draws other scenes, and
//! PLACEMENT_DIAG=1 prints each light's worst cell with the reference and computed optical
//! depth along its path.

mod common;

use common::scenes::transmittance_errors;
use common::{pipeline, Lcg};
use fogsmith::gpu::FrameRequest;
use fogsmith::measure::{opv_errors, sample_cells};
use fogsmith::scene::{Camera, GridSpec, Light, Medium, Particle, Project, Scheme, DEFAULT_SWEEP_TOLERANCE};
use glam::{UVec3, Vec3};

/// The `sweep` scheme's largest transmittance error against the grid's own medium, at stride
/// 8 with `sweep_refine` at its default tolerance (5e-4 per interpolation), for every
/// placement class and particles of 1 to 10 cells radius (peak optical depth up to 2). Each
/// interpolation's estimated error stays within the tolerance (shaders/propagate_sweep.wgsl),
/// and a ray takes a few of them, so the bound is a small multiple of it: the goal of 2e-3
/// the scheme is built for. The worst class on the scenes of six seeds measured 1.4e-3.
const SWEEP_SCHEME_BOUNDS: [f64; 8] = [2e-3; 8];

/// The same for particles of 6 to 10 cells radius, whose shadows the interpolation resolves:
/// the worst class measured 1.03e-3 (beyond a face, seed 7).
const SWEEP_SCHEME_BOUNDS_RESOLVED: [f64; 8] = [1.5e-3; 8];

/// A tolerance of 1e-4 against the default one, on the same scenes: the worst error over the
/// classes must fall by at least this factor (below about 5e-4 the error falls more slowly
/// than the tolerance, so the gain asked for is well short of the tolerances' ratio of 5).
const TIGHT_TOLERANCE: f32 = 1e-4;
const TIGHT_TOLERANCE_GAIN: f64 = 0.8;

/// Without `sweep_refine` (faster), per placement class in
/// `CLASSES` order: the numerical diffusion of the interpolations, which cannot resolve the
/// shadow of a particle of 1–2 cells radius, least of all along the long paths of lights
/// outside the elongated grids. Each bound is the class's worst case on these scenes with a
/// margin of 20–50 %.
const PLAIN_SWEEP_SCHEME_BOUNDS: [f64; 8] = [1.5e-2, 1e-2, 2e-2, 6e-3, 4.5e-2, 3e-2, 6e-3, 4e-2];

/// The same for particles of 6 to 10 cells radius, whose shadows the interpolation resolves:
/// every class stays below 2e-3 on the first seed's scenes. Other seeds' scenes measured up
/// to 8.2e-3 (beyond an edge, seed 3) and 3.3e-3 (beyond a face, seed 7): along the long paths
/// of lights outside the box the interpolation errors add up even for resolved particles,
/// which is why `sweep_refine` is on by default.
const PLAIN_SWEEP_SCHEME_BOUNDS_RESOLVED: [f64; 8] = [1.2e-3, 1e-3, 1e-3, 5e-4, 2e-3, 1.5e-3, 5e-4, 1.5e-3];

const CLASSES: [&str; 8] = [
    "inside",
    "on a face",
    "on an edge",
    "on a corner",
    "beyond a face",
    "beyond an edge",
    "beyond a corner",
    "far away",
];

/// One light per placement class, in `CLASSES` order.
fn lights_by_class(rng: &mut Lcg, grid: &GridSpec, blob: Vec3) -> Vec<Vec3> {
    let (lo, hi) = (grid.min, grid.max);
    let size = grid.size();
    let c = (lo + hi) * 0.5;
    let within = |rng: &mut Lcg| lo + size * Vec3::new(rng.f32(), rng.f32(), rng.f32());
    // A point with `outside` axes (distinct, random) beyond a face, the others in the box.
    let beyond = |rng: &mut Lcg, outside: usize| {
        let mut p = within(rng);
        let first = rng.pick(3);
        for k in 0..outside {
            let a = (first + k) % 3;
            p[a] = c[a] + rng.sign() * size[a] * rng.range(0.55, 1.5);
        }
        p
    };
    // A point on `fixed` axes' faces.
    let on = |rng: &mut Lcg, fixed: usize| {
        let mut p = within(rng);
        let first = rng.pick(3);
        for k in 0..fixed {
            let a = (first + k) % 3;
            p[a] = if rng.f32() < 0.5 { lo[a] } else { hi[a] };
        }
        p
    };
    let dir = Vec3::new(rng.range(-1.0, 1.0), rng.range(-1.0, 1.0), rng.range(-1.0, 1.0)).normalize();
    let far = c + dir * size.length() * 10f32.powf(rng.range(2.0, 6.0));
    vec![blob, on(rng, 1), on(rng, 2), on(rng, 3), beyond(rng, 1), beyond(rng, 2), beyond(rng, 3), far]
}

fn scene(rng: &mut Lcg, resolution: UVec3, base: f32, min_radius: f32) -> (Project, usize) {
    let mut p = Project::default();
    let cell = 0.05;
    let size = resolution.as_vec3() * cell;
    p.grid = GridSpec {
        min: -0.5 * size + Vec3::new(0.3, -0.1, 0.2),
        max: 0.5 * size + Vec3::new(0.3, -0.1, 0.2),
        resolution,
    };
    p.medium = Medium { base_extinction: base, albedo: 0.8, anisotropy: 0.0, ..Medium::default() };
    let n = 6 + rng.pick(10);
    for _ in 0..n {
        let r = cell * rng.range(min_radius, 10.0);
        // Centres anywhere in the box and up to a radius beyond it, so tails cross faces.
        let centre =
            p.grid.min - Vec3::splat(r) + (size + Vec3::splat(2.0 * r)) * Vec3::new(rng.f32(), rng.f32(), rng.f32());
        // Peak optical depth through the particle between 0.1 and 2.
        let density = rng.range(0.1, 2.0) / (r * 1.772_453_9);
        p.particles.push(Particle::new(centre, r, density));
    }
    // The inside light sits in the densest particle whose centre is in the box.
    let blob = p
        .particles
        .iter()
        .filter(|q| (0..3).all(|a| q.center[a] > p.grid.min[a] && q.center[a] < p.grid.max[a]))
        .max_by(|a, b| (a.density * a.radius).total_cmp(&(b.density * b.radius)))
        .map_or((p.grid.min + p.grid.max) * 0.5, |q| q.center);
    // Bright enough that no light is culled as negligible, however far.
    p.lights = lights_by_class(rng, &p.grid, blob).into_iter().map(|pos| Light::new(pos, 1e15, Vec3::ONE)).collect();
    p.camera = Camera { position: Vec3::new(0.0, 0.0, 5.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 45.0 };
    p.render.width = 8;
    p.render.height = 8;
    (p, n)
}

/// The scenes' seed: PLACEMENT_SEED, else the one the bounds were measured on.
const SEED: u64 = 0x5EED_0012;

/// The grids of the sweep's scenes: a cube, boxes of mixed aspect and a long thin one.
const GRIDS: [UVec3; 4] = [UVec3::splat(32), UVec3::new(40, 24, 16), UVec3::new(128, 16, 16), UVec3::new(12, 48, 10)];

/// Flat grids, as ground fog and street mist use: one layer deep, and three.
const THIN_GRIDS: [UVec3; 3] = [UVec3::new(64, 64, 1), UVec3::new(48, 3, 40), UVec3::new(96, 2, 96)];

fn worst_by_class(scheme: Scheme, stride: u32, refine: Option<f32>, min_radius: f32, seed: u64) -> Vec<(f64, f64)> {
    worst_by_class_on(&GRIDS, scheme, stride, refine, min_radius, seed)
}

fn worst_by_class_on(
    grids: &[UVec3],
    scheme: Scheme,
    stride: u32,
    refine: Option<f32>,
    min_radius: f32,
    seed: u64,
) -> Vec<(f64, f64)> {
    let mut gpu = pipeline();
    let mut worst = vec![(0.0f64, 0.0f64); CLASSES.len()];
    let mut rng = Lcg(seed);
    for (g, &res) in grids.iter().enumerate() {
        for seed in 0..2 {
            // Half the scenes without base fog, so that far lights still see the medium.
            let base = if (g + seed) % 2 == 0 { 0.0 } else { rng.range(0.02, 0.3) };
            let (mut p, particles) = scene(&mut rng, res, base, min_radius);
            p.propagation.scheme = scheme;
            p.propagation.sweep_stride = stride;
            p.propagation.sweep_refine = refine.is_some();
            p.propagation.sweep_tolerance = refine.unwrap_or(p.propagation.sweep_tolerance);
            gpu.update(&p, &FrameRequest::for_project(&p)).unwrap();
            let ev = gpu.read_ev().unwrap();
            let cells = sample_cells(&p.grid, 6000);
            for (l, light) in p.lights.iter().enumerate() {
                assert_eq!(gpu.read_opv(l).unwrap().data.len() as u64, p.grid.cell_count());
                let e = opv_errors(&p, l, &ev, &gpu.read_opv(l).unwrap(), &cells);
                assert!(!e.scheme.nan_or_inf, "{scheme} {res} light {l}: NaN or infinity");
                let (s, r) = (e.scheme.transmittance_max_abs_error, e.resolution.transmittance_max_abs_error);
                println!(
                    "{scheme}{stride} {:>3}×{:>3}×{:>3} {particles:2} particles base {base:.3}  {:16} {:>11.3e}: scheme {s:.2e} resolution {r:.2e}",
                    res.x,
                    res.y,
                    res.z,
                    CLASSES[l],
                    light.position.length()
                );
                if std::env::var("PLACEMENT_DIAG").is_ok() {
                    diagnose(&p, l, &ev, &gpu.read_opv(l).unwrap(), &cells);
                }
                worst[l].0 = worst[l].0.max(s);
                worst[l].1 = worst[l].1.max(r);
            }
        }
    }
    println!("{scheme} stride {stride} refine {refine:?}, particle radii {min_radius}–10 cells: worst transmittance error per placement class");
    for (class, (s, r)) in CLASSES.iter().zip(&worst) {
        println!("  {class:16} scheme {s:.2e}  resolution {r:.2e}");
    }
    worst
}

/// The worst cell of light `l` and the cells along its path towards the light (every 4
/// cells along the dominant axis): reference and computed optical depth, and where the ray
/// leaves the box.
fn diagnose(p: &Project, l: usize, ev: &fogsmith::scene::Volume, opv: &fogsmith::scene::Volume, cells: &[[u32; 3]]) {
    use fogsmith::reference::{grid_optical_depth_cells, GridMedium64};
    let medium = GridMedium64::from_volume(&p.grid, ev, p.medium.base_extinction.max(0.0) as f64);
    let s = p.lights[l].position.as_dvec3();
    let exact = grid_optical_depth_cells(&p.grid, &medium, s, cells);
    let (errors, worst) = transmittance_errors(opv, cells, &exact);
    let n = worst.unwrap();
    let c = cells[n];
    let cell = p.grid.cell_size().as_dvec3();
    let x = p.grid.cell_center(c[0], c[1], c[2]).as_dvec3();
    let su = (s - p.grid.min.as_dvec3()) / cell - 0.5;
    let v = (s - x) / cell;
    let len = (s - x).length();
    let dir = (s - x) / len;
    let (lo, hi) = (p.grid.min.as_dvec3(), p.grid.max.as_dvec3());
    let (t0, t1) = fogsmith::reference::clip_to_box(lo, hi, x, dir, len).unwrap_or((0.0, 0.0));
    let e = x + dir * t1;
    let eu = (e - lo) / cell - 0.5;
    println!("    worst cell {c:?} err {:.2e} light(cells) {:.1?} path(cells) {:.1?} in-box {:.2} cells t0 {t0:.2} exit(cells) {:.2?}", errors[n], su.to_array(), v.to_array(), t1 / cell.min_element(), eu.to_array());
    let a = (0..3).max_by(|&i, &j| v[i].abs().total_cmp(&v[j].abs())).unwrap();
    let res = p.grid.resolution;
    let mut along = Vec::new();
    let mut k = 0.0;
    while k <= v[a].abs() {
        let q = x + dir * (k / v[a].abs()) * len;
        let qu = ((q - lo) / cell - 0.5).round();
        if (0..3).any(|i| qu[i] < 0.0 || qu[i] >= res[i] as f64) {
            break;
        }
        along.push([qu.x as u32, qu.y as u32, qu.z as u32]);
        k += 4.0;
    }
    let ex = grid_optical_depth_cells(&p.grid, &medium, s, &along);
    for (q, t) in along.iter().zip(&ex) {
        println!("      {q:?} ref {t:.5} got {:.5}", opv.get(q[0], q[1], q[2]));
    }
}

/// Asserts `bounds` on the scenes of each of `seeds` (or of PLACEMENT_SEED alone).
fn check_sweep(min_radius: f32, refine: Option<f32>, bounds: [f64; 8], seeds: &[u64]) {
    let strides: Vec<u32> =
        std::env::var("SWEEP_STRIDES").map_or(vec![8], |s| s.split(',').map(|v| v.parse().unwrap()).collect());
    let seeds = std::env::var("PLACEMENT_SEED")
        .map_or(seeds.to_vec(), |s| vec![s.parse().expect("PLACEMENT_SEED is a number")]);
    for &seed in &seeds {
        for &stride in &strides {
            let worst = worst_by_class(Scheme::Sweep, stride, refine, min_radius, seed);
            for ((class, (s, _)), bound) in CLASSES.iter().zip(&worst).zip(bounds) {
                assert!(*s <= bound, "seed {seed}, sweep stride {stride} refine {refine:?}, radii {min_radius}–10 cells, light {class}: scheme error {s:.3e} > {bound:e}");
            }
        }
    }
}

/// The refined sweep on [`THIN_GRIDS`]: every class within 5e-3. The worst measured is
/// 4.14e-3 (light inside, 64×64×1, seed 7), at the outermost cell of a ray along the layer;
/// the cells four and more inwards are within 2e-5. Above the 2e-3 of thicker grids.
const THIN_SWEEP_SCHEME_BOUNDS: [f64; 8] = [5e-3; 8];

#[test]
fn refined_sweep_is_accurate_on_thin_grids() {
    let seeds = std::env::var("PLACEMENT_SEED")
        .map_or(vec![SEED, 7, 99], |s| vec![s.parse().expect("PLACEMENT_SEED is a number")]);
    for seed in seeds {
        let worst = worst_by_class_on(&THIN_GRIDS, Scheme::Sweep, 8, Some(DEFAULT_SWEEP_TOLERANCE), 1.0, seed);
        for ((class, (s, _)), bound) in CLASSES.iter().zip(&worst).zip(THIN_SWEEP_SCHEME_BOUNDS) {
            assert!(*s <= bound, "seed {seed}, thin grids, light {class}: scheme error {s:.3e} > {bound:e}");
        }
    }
}

#[test]
fn refined_sweep_is_accurate_for_every_light_placement() {
    check_sweep(1.0, Some(DEFAULT_SWEEP_TOLERANCE), SWEEP_SCHEME_BOUNDS, &[SEED, 7, 99]);
}

/// The tolerance controls the error: the same scenes, at the default tolerance and a tighter
/// one, must show a measurable gain, not merely both stay within a bound.
#[test]
fn a_tighter_tolerance_tightens_the_error() {
    let seed = std::env::var("PLACEMENT_SEED").map_or(SEED, |s| s.parse().expect("PLACEMENT_SEED is a number"));
    let worst = |tolerance: f32| {
        worst_by_class(Scheme::Sweep, 8, Some(tolerance), 1.0, seed).iter().map(|&(s, _)| s).fold(0.0, f64::max)
    };
    let (default, tight) = (worst(DEFAULT_SWEEP_TOLERANCE), worst(TIGHT_TOLERANCE));
    println!("seed {seed}: worst scheme error {default:.2e} at tolerance {DEFAULT_SWEEP_TOLERANCE:e}, {tight:.2e} at {TIGHT_TOLERANCE:e}");
    assert!(
        tight <= TIGHT_TOLERANCE_GAIN * default,
        "seed {seed}: tolerance {TIGHT_TOLERANCE:e} gives {tight:.3e}, not below {TIGHT_TOLERANCE_GAIN} × {default:.3e} (tolerance {DEFAULT_SWEEP_TOLERANCE:e})"
    );
}

#[test]
fn refined_sweep_is_accurate_for_resolved_particles() {
    check_sweep(6.0, Some(DEFAULT_SWEEP_TOLERANCE), SWEEP_SCHEME_BOUNDS_RESOLVED, &[SEED, 7]);
}

/// The plain sweep's bounds are its measured worst on the first seed's scenes plus a margin.
#[test]
fn plain_sweep_is_bounded_for_every_light_placement() {
    check_sweep(1.0, None, PLAIN_SWEEP_SCHEME_BOUNDS, &[SEED]);
}

#[test]
fn plain_sweep_matches_an_inside_light_everywhere_for_resolved_particles() {
    check_sweep(6.0, None, PLAIN_SWEEP_SCHEME_BOUNDS_RESOLVED, &[SEED]);
}

/// The `analytic` scheme's largest transmittance error against the analytic gaussians and
/// fog clipped to the box, per placement class. Nothing is interpolated or sampled, so what
/// remains is f32 rounding, the erf approximation (1.5e-7 per evaluation, two per particle
/// and brick) and the tails beyond the particles' cut-off: the worst class measured 5.0e-6
/// over eight seeds (inside, seed 3). Computing a particle's closest distance as |d|² − t_c² instead, which
/// cancels in f32, measured 5.8e-5.
const ANALYTIC_BOUND: f64 = 2e-5;

/// Worst transmittance error of the `analytic` scheme against the clipped analytic medium
/// per placement class, on the scenes of `worst_by_class`, half of those with base fog given
/// a height falloff.
fn analytic_worst_by_class(min_radius: f32, seed: u64) -> Vec<f64> {
    use fogsmith::measure::opv_error_against;
    use fogsmith::reference::clipped_optical_depth_cells;
    let mut gpu = pipeline();
    // The thin grids last, so that the earlier grids' scenes stay those the bounds were
    // measured on.
    let grids: Vec<UVec3> = GRIDS.iter().chain(&THIN_GRIDS).copied().collect();
    let mut worst = vec![0.0f64; CLASSES.len()];
    let mut rng = Lcg(seed);
    for (g, &res) in grids.iter().enumerate() {
        for seed in 0..2 {
            let base = if (g + seed) % 2 == 0 { 0.0 } else { rng.range(0.02, 0.3) };
            let (mut p, particles) = scene(&mut rng, res, base, min_radius);
            if seed == 1 {
                p.medium.height_falloff = rng.range(0.5, 3.0);
                p.medium.height_origin = p.grid.min.y;
            }
            p.propagation.scheme = Scheme::Analytic;
            gpu.update(&p, &FrameRequest::for_project(&p)).unwrap();
            let cells = sample_cells(&p.grid, 6000);
            for l in 0..p.lights.len() {
                let reference = clipped_optical_depth_cells(&p, l, &cells);
                let e = opv_error_against(l, &gpu.read_opv(l).unwrap(), &cells, &reference);
                assert!(!e.nan_or_inf, "analytic {res} light {l}: NaN or infinity");
                println!(
                    "analytic {:>3}×{:>3}×{:>3} {particles:2} particles base {base:.3} falloff {:.2}  {:16}: {:.2e}",
                    res.x, res.y, res.z, p.medium.height_falloff, CLASSES[l], e.transmittance_max_abs_error
                );
                worst[l] = worst[l].max(e.transmittance_max_abs_error);
            }
        }
    }
    worst
}

#[test]
fn analytic_scheme_is_exact_against_the_gaussians_for_every_light_placement() {
    let seeds =
        std::env::var("PLACEMENT_SEED").map_or(vec![SEED, 7], |s| vec![s.parse().expect("PLACEMENT_SEED is a number")]);
    for seed in seeds {
        let worst = analytic_worst_by_class(1.0, seed);
        println!(
            "analytic, particle radii 1–10 cells, seed {seed}: worst transmittance error against the clipped gaussians"
        );
        for (class, w) in CLASSES.iter().zip(&worst) {
            println!("  {class:16} {w:.2e}");
            assert!(*w <= ANALYTIC_BOUND, "seed {seed}, analytic, light {class}: error {w:.3e} > {ANALYTIC_BOUND:e}");
        }
    }
}

//! The numerical stress matrix behind `fogsmith stress` and `tests/stress.rs`.
//!
//! Each [`StressCase`] is a small project at an extreme of the inputs (densities, particle
//! radii and counts, light placement and kind, camera placement, base and height fog, grid
//! size, propagation scheme).
//! [`run_case`] bakes it on the real adapter and checks what must hold whatever the input:
//! EV, OPV, image and light bake (both phase modes) free of NaN and infinity, optical depth T ≥ 0 (so the transmittance
//! exp(−T) lies in [0, 1]), image alpha within [0, 1], OPV non-decreasing away from the light
//! along the axes through its cell in homogeneous fog, and, where the grid resolves the
//! medium, the OPV transmittance within a stated bound of the exact reference
//! ([`crate::measure`]). Cases past the adapter's limits must be refused with a
//! [`GpuError::Limit`] before anything is allocated, and values past the project's own
//! bounds ([`MAX_COORDINATE`], [`MAX_EXTINCTION`]) by validation.
//!
//! Memory for particles is bounded by the adapter: the particle buffer (32 bytes each) and
//! the CPU-built particle–bin lists (4 bytes per particle per injection bin, 2³ to 8³ cells,
//! its cut-off sphere reaches, counted before anything is allocated) must each fit one
//! storage binding, so a million small particles bake while a thousand grid-filling ones on
//! 256³ are refused.

use crate::gpu::{BakePhase, FogPipeline, FrameRequest, GpuError};
use crate::measure::{ev_error, opv_error, sample_cells};
use crate::rng::{scrambled, Lcg};
use crate::scene::{
    Camera, GridSpec, Light, LightKind, Medium, Particle, Project, Scheme, StepPolicy, Volume, MAX_COORDINATE,
    MAX_EXTINCTION, MAX_INTENSITY,
};
use glam::{UVec3, Vec3};
use serde::Serialize;
use std::time::Instant;

/// What a case expects from the pipeline.
#[derive(Clone, Debug, PartialEq)]
pub enum Expect {
    /// A finished bake; `bound` is the largest OPV transmittance error allowed against the
    /// exact reference, None where the grid does not resolve the medium (reported only).
    Bake { bound: Option<f64>, monotone: bool },
    /// Refusal with a limit or validation error whose message contains this text.
    Refused(&'static str),
}

#[derive(Clone, Debug)]
pub struct StressCase {
    pub name: String,
    pub project: Project,
    pub scheme: Scheme,
    pub expect: Expect,
    /// Most cells compared with the exact reference.
    pub reference_cells: usize,
}

/// One row of the stress table.
#[derive(Clone, Debug, Serialize)]
pub struct StressResult {
    pub case: String,
    pub scheme: String,
    /// Largest |exp(−T) − exp(−T_exact)| over the sampled cells and all lights; None when
    /// the case was refused.
    pub max_error: Option<f64>,
    pub bound: Option<f64>,
    /// Largest relative error of the EV against the analytic σ_t where σ_t ≥
    /// [`crate::measure::EV_REL_THRESHOLD`] (cut-off radii included).
    pub ev_rel_error: Option<f64>,
    pub nan_or_inf: bool,
    pub time_ms: f64,
    pub passed: bool,
    /// What failed, or for refused cases the refusal message.
    pub detail: String,
}

const DEFAULT_RES: u32 = 32;

/// A unit-ish box [-1, 1]³ seen from outside, no fog, no lights.
fn base(res: u32) -> Project {
    let mut p = Project {
        grid: GridSpec { min: Vec3::splat(-1.0), max: Vec3::splat(1.0), resolution: UVec3::splat(res) },
        medium: Medium { base_extinction: 0.0, albedo: 0.8, anisotropy: 0.3, ..Medium::default() },
        camera: Camera { position: Vec3::new(0.3, 0.4, 3.5), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 45.0 },
        ..Project::default()
    };
    p.render.width = 24;
    p.render.height = 17;
    p
}

fn light(pos: Vec3) -> Light {
    Light::new(pos, 4.0, Vec3::new(1.0, 0.9, 0.8))
}

/// A sun of irradiance 3 W/m² travelling along `direction`.
fn sun(direction: Vec3) -> Light {
    let mut l = Light::new(Vec3::ZERO, 3.0, Vec3::new(1.0, 0.95, 0.9));
    l.kind = LightKind::Directional { direction };
    l
}

/// Where a case puts its light, from the project.
type Placement = Box<dyn Fn(&Project) -> Vec3>;

/// Centre of cell (i, j, k) of a project's grid.
fn center(p: &Project, c: [u32; 3]) -> Vec3 {
    p.grid.cell_center(c[0], c[1], c[2])
}

fn bake(name: String, project: Project, scheme: Scheme, bound: Option<f64>, monotone: bool) -> StressCase {
    StressCase { name, project, scheme, expect: Expect::Bake { bound, monotone }, reference_cells: 400 }
}

/// Transmittance error allowed where the grid resolves the medium: cells of optical
/// thickness ≤ 1 and particles ≥ 2 cells across. Measured worst case 0.03 (trilinear EV
/// and OPV interpolation between cell centres near a dense particle), with headroom.
pub const RESOLVED_BOUND: f64 = 0.05;
/// Homogeneous fog: T = β·distance is reproduced by every scheme up to f32 rounding and the
/// `exact` scheme's Simpson error.
pub const HOMOGENEOUS_BOUND: f64 = 1e-4;

/// The matrix. `quick` keeps every case small; the full matrix adds a million particles, a
/// grid at the adapter's largest OPV and every scheme on more cases. `max_3d` and
/// `max_binding` are the adapter's limits and `opv_capacity` the lights whose optical-depth
/// volumes a pipeline can hold on a 64³ grid, used to build cases just past them.
pub fn matrix(quick: bool, max_3d: u32, max_binding: u64, opv_capacity: u64) -> Vec<StressCase> {
    let mut cases = Vec::new();
    let all = [Scheme::Sweep, Scheme::Giroud, Scheme::Exact, Scheme::Analytic];
    let cell = 2.0 / DEFAULT_RES as f32;

    // Homogeneous fog from none to very large, light inside the grid off the cell centres.
    for beta in [0.0f32, 1e-6, 1e-2, 1.0, 1e2, 1e4, MAX_EXTINCTION] {
        let schemes: &[Scheme] = if quick && !(beta == 1.0 || beta == MAX_EXTINCTION) { &all[..1] } else { &all };
        for &s in schemes {
            let mut p = base(DEFAULT_RES);
            p.medium.base_extinction = beta;
            p.lights.push(light(Vec3::new(0.21, -0.33, 0.47)));
            let bound = if beta * cell <= 1.0 { Some(HOMOGENEOUS_BOUND) } else { None };
            cases.push(bake(format!("base fog {beta:e}/m"), p, s, bound, true));
        }
    }

    // Light placement in homogeneous fog.
    let placements: Vec<(&str, Placement)> = vec![
        ("light on a cell centre", Box::new(|p| center(p, [13, 20, 7]))),
        ("light on a grid face", Box::new(|p| Vec3::new(p.grid.max.x, 0.1, -0.2))),
        ("light on a grid corner", Box::new(|p| p.grid.min)),
        ("light on an inner cell corner", Box::new(|_| Vec3::ZERO)),
        ("light just outside", Box::new(|p| p.grid.max + Vec3::splat(1e-3))),
        ("light 1e3 m outside", Box::new(|_| Vec3::new(1e3, 20.0, -7.0))),
        ("light 1e7 m outside", Box::new(|_| Vec3::new(-1e7, 3e6, 1e5))),
        ("light 1e9 m outside", Box::new(|_| Vec3::new(MAX_COORDINATE, -MAX_COORDINATE, 1e8))),
        ("light at the camera", Box::new(|p| p.camera.position)),
    ];
    for (name, at) in &placements {
        // Far lights run every scheme even in the quick matrix: the exact scheme's cost used
        // to grow with the distance to the light (minutes per bake at 1e3 m).
        let far = name.contains("m outside");
        let schemes: &[Scheme] = if quick && !far { &all[..1] } else { &all };
        for &s in schemes {
            let mut p = base(DEFAULT_RES);
            let at = at(&p);
            // Far away, thin fog keeps the transmittance to the light measurable.
            p.medium.base_extinction = if far { 1.0 / at.length() } else { 0.7 };
            p.lights.push(light(at));
            cases.push(bake(name.to_string(), p, s, Some(HOMOGENEOUS_BOUND), true));
        }
    }
    for (name, field, mut p) in
        [("light at 1e30 m", "lights[0].position", base(8)), ("base fog 1e30/m", "medium.base_extinction", base(8))]
    {
        p.lights.push(light(Vec3::new(1e30, -1e30, 1e29)));
        if field.starts_with("medium") {
            p.lights[0].position = Vec3::ZERO;
            p.medium.base_extinction = 1e30;
        }
        cases.push(StressCase {
            name: name.into(),
            project: p,
            scheme: Scheme::Sweep,
            expect: Expect::Refused(field),
            reference_cells: 0,
        });
    }
    for (name, lo, hi) in [("grid 1e-6 m across", -5e-7f32, 5e-7f32), ("grid 4e8 m across", -2e8, 2e8)] {
        let mut p = base(16);
        p.grid.min = Vec3::splat(lo);
        p.grid.max = Vec3::splat(hi);
        p.medium.base_extinction = 0.5 / hi;
        p.camera.position = Vec3::new(0.3, 0.4, 3.5) * hi;
        p.lights.push(light(Vec3::new(0.21, -0.33, 0.47) * hi));
        p.lights[0].intensity = (4.0 * hi * hi).min(MAX_INTENSITY);
        cases.push(bake(name.into(), p, Scheme::Sweep, Some(HOMOGENEOUS_BOUND), true));
    }
    {
        // A very bright light on a cell centre, seen straight on from inside the fog.
        let mut p = base(DEFAULT_RES);
        p.medium.base_extinction = 0.3;
        p.camera = Camera {
            position: Vec3::new(-0.5, 0.1, 0.2),
            target: center(&p, [20, 17, 15]),
            up: Vec3::Y,
            fov_y_deg: 30.0,
        };
        p.render.width = 25;
        p.render.height = 17;
        p.lights.push(Light::new(p.camera.target, 1e12, Vec3::ONE));
        cases.push(bake(
            "1e12 W/sr light on a cell centre, seen straight on".into(),
            p.clone(),
            Scheme::Sweep,
            Some(HOMOGENEOUS_BOUND),
            true,
        ));
        p.lights[0].intensity = MAX_INTENSITY;
        cases.push(bake(
            "1e15 W/sr light on a cell centre, seen straight on".into(),
            p.clone(),
            Scheme::Sweep,
            Some(HOMOGENEOUS_BOUND),
            true,
        ));
        p.lights[0].intensity = 3e38;
        p.lights[0].color = Vec3::splat(10.0);
        cases.push(StressCase {
            name: "3e38 W/sr light, colour 10".into(),
            project: p.clone(),
            scheme: Scheme::Sweep,
            expect: Expect::Refused("lights[0].intensity"),
            reference_cells: 0,
        });
        // The same brightest light seen straight on in a grid 20 µm across, with the
        // finest step allowed: the largest inverse-square factor the march can meet.
        let scale = 1e-5f32;
        p.grid.min *= scale;
        p.grid.max *= scale;
        p.grid.resolution = UVec3::splat(64);
        p.medium.base_extinction = 0.3 / scale;
        p.medium.albedo = 0.0;
        p.render.step_factor = 0.01;
        p.camera.position *= scale;
        p.lights[0] = Light::new(center(&p, [40, 33, 30]), MAX_INTENSITY, Vec3::ONE);
        p.camera.target = p.lights[0].position;
        cases.push(bake(
            "1e15 W/sr light in a 2e-5 m grid, albedo 0, seen straight on".into(),
            p.clone(),
            Scheme::Sweep,
            Some(HOMOGENEOUS_BOUND),
            true,
        ));
        p.medium.albedo = 1.0;
        cases.push(bake(
            "1e15 W/sr light in a 2e-5 m grid, seen straight on".into(),
            p,
            Scheme::Sweep,
            Some(HOMOGENEOUS_BOUND),
            true,
        ));
    }
    {
        // Camera inside the fog looking straight at a light: the middle pixel's ray passes
        // through it (γ → 0 in Sun's formula; the in-scattered radiance there is unbounded
        // in exact arithmetic and must stay finite).
        let mut p = base(DEFAULT_RES);
        p.medium.base_extinction = 0.5;
        p.camera = Camera {
            position: Vec3::new(-0.6, -0.2, 0.3),
            target: Vec3::new(0.4, 0.3, -0.1),
            up: Vec3::Y,
            fov_y_deg: 50.0,
        };
        p.render.width = 25;
        p.render.height = 17;
        p.lights.push(light(p.camera.target));
        cases.push(bake(
            "camera in fog looking at a light".into(),
            p.clone(),
            Scheme::Sweep,
            Some(HOMOGENEOUS_BOUND),
            true,
        ));
        p.lights[0].position = p.camera.position;
        cases.push(bake("camera in fog at a light".into(), p, Scheme::Sweep, Some(HOMOGENEOUS_BOUND), true));
    }

    // Light kinds and height fog (physics.md §9).
    {
        let blob = |p: &mut Project| {
            let c = center(p, [14, 17, 15]);
            p.particles.push(Particle::new(c, 4.0 * cell, 0.5 / cell));
        };
        // Suns: along an axis (parallel to four faces), diagonal, grazing a face, and from
        // below; no base fog (a sun in homogeneous fog sees infinite optical depth).
        for (name, dir) in [
            ("sun along -y, parallel to the side faces", Vec3::new(0.0, -1.0, 0.0)),
            ("sun along +x, parallel to four faces", Vec3::new(1.0, 0.0, 0.0)),
            ("sun diagonal", Vec3::new(1.0, -1.0, 1.0)),
            ("sun grazing the top face", Vec3::new(1.0, -1e-4, 0.3)),
            ("sun from below", Vec3::new(0.2, 1.0, -0.1)),
        ] {
            let schemes: &[Scheme] = if quick { &all[..1] } else { &all };
            for &s in schemes {
                let mut p = base(DEFAULT_RES);
                blob(&mut p);
                p.lights.push(sun(dir));
                cases.push(bake(name.into(), p, s, Some(RESOLVED_BOUND), false));
            }
        }
        // Height fog: ordinary, a thin layer (k large), and k·(y − y₀) past the clamp.
        for (name, beta, k, y0, bound) in [
            ("height fog k 2/m", 0.4f32, 2.0f32, -0.3f32, Some(RESOLVED_BOUND)),
            ("height fog in a layer a cell thick (k 30/m)", 0.4, 30.0, -0.2, None),
            ("height fog k 1e4/m, overflowing below y0", 1e-3, 1e4, 0.9, None),
            ("height fog k 1e6/m far above y0", 50.0, 1e6, -1e3, Some(RESOLVED_BOUND)),
        ] {
            let mut p = base(DEFAULT_RES);
            p.medium.base_extinction = beta;
            p.medium.height_falloff = k;
            p.medium.height_origin = y0;
            blob(&mut p);
            p.lights.push(light(Vec3::new(0.21, -0.33, 0.47)));
            p.lights.push(light(Vec3::new(2.5, 1.5, -0.3)));
            p.lights.push(sun(Vec3::new(0.3, -1.0, 0.2)));
            let mut spot = light(Vec3::new(-0.4, 0.8, 0.1));
            spot.kind = LightKind::Spot { direction: Vec3::new(0.2, -1.0, 0.0), angle_deg: 25.0, blend: 0.3 };
            p.lights.push(spot);
            cases.push(bake(name.into(), p, Scheme::Sweep, bound, false));
        }
        // Spots: one whose cone misses the grid entirely, and one on a face pointing in.
        let mut p = base(DEFAULT_RES);
        p.medium.base_extinction = 0.7;
        let mut away = light(Vec3::new(0.0, 0.0, 1.5));
        away.kind = LightKind::Spot { direction: Vec3::Z, angle_deg: 30.0, blend: 0.2 };
        p.lights.push(away);
        cases.push(bake("spot pointing away from the grid".into(), p, Scheme::Sweep, Some(HOMOGENEOUS_BOUND), true));
        let mut p = base(DEFAULT_RES);
        p.medium.base_extinction = 0.7;
        let mut on_face = light(Vec3::new(p.grid.max.x, 0.1, -0.2));
        on_face.kind = LightKind::Spot { direction: -Vec3::X, angle_deg: 90.0, blend: 1.0 };
        p.lights.push(on_face);
        cases.push(bake(
            "spot on a face, 90° cone, full blend".into(),
            p,
            Scheme::Sweep,
            Some(HOMOGENEOUS_BOUND),
            true,
        ));
    }

    // One particle: density × radius (in cells), light in its densest cell.
    for density in [1e-6f32, 1.0, 1e4] {
        for radius_cells in [1e-3f32, 0.1, 1.0, 4.0, 1e3] {
            let mut p = base(DEFAULT_RES);
            p.medium.base_extinction = 0.05;
            let c = center(&p, [16, 16, 16]) + Vec3::splat(0.2 * cell);
            p.particles.push(Particle::new(c, radius_cells * cell, density));
            p.lights.push(light(c + Vec3::new(0.1, 0.05, -0.1) * cell));
            // Inside the grid: particles are clipped to it (outside only the base fog exists),
            // while the reference integrates whole gaussians.
            p.lights.push(light(Vec3::new(0.8, 0.7, 0.6)));
            let resolved = radius_cells >= 2.0 && density * cell <= 1.0;
            let bound = if resolved { Some(RESOLVED_BOUND) } else { None };
            cases.push(bake(
                format!("particle c {density:e}/m r {radius_cells:e} cells"),
                p,
                Scheme::Sweep,
                bound,
                false,
            ));
        }
    }

    // Particle counts.
    let counts: &[usize] = &[1, 1000, 100_000, 1_000_000];
    for &n in counts {
        let mut p = base(DEFAULT_RES);
        let mut rng = Lcg(17);
        let radius = if n >= 100_000 { 0.3 * cell } else { 2.0 * cell };
        let density = 20.0 / (n as f32).cbrt();
        p.particles = (0..n)
            .map(|_| Particle::new(Vec3::new(rng.f32(), rng.f32(), rng.f32()) * 1.8 - 0.9, radius, density))
            .collect();
        p.lights.push(light(Vec3::new(0.3, 0.2, -0.1)));
        let bound = if radius >= 2.0 * cell { Some(RESOLVED_BOUND) } else { None };
        let mut case = bake(format!("{n} particles"), p, Scheme::Sweep, bound, false);
        case.reference_cells = if n >= 100_000 { 24 } else { 200 };
        cases.push(case);
    }
    // Grid shapes.
    let mut shapes = vec![UVec3::ONE, UVec3::new(1, 1, 64), UVec3::new(2, 3, 5), UVec3::new(max_3d, 1, 1)];
    if !quick {
        let per_light = max_binding / 4;
        let edge = ((per_light as f64).cbrt().floor() as u32).min(max_3d).min(256);
        shapes.push(UVec3::splat(edge));
    }
    for r in shapes {
        let schemes: &[Scheme] = if r.element_product() <= 4096 { &all } else { &all[..1] };
        for &s in schemes {
            let mut p = base(DEFAULT_RES);
            p.grid.resolution = r;
            p.medium.base_extinction = 0.9;
            p.lights.push(light(Vec3::new(0.13, -0.41, 0.29)));
            let mut case = bake(format!("grid {}×{}×{}", r.x, r.y, r.z), p, s, Some(HOMOGENEOUS_BOUND), true);
            case.reference_cells = 200;
            cases.push(case);
        }
    }
    {
        let mut p = base(DEFAULT_RES);
        p.grid.resolution = UVec3::new(max_3d.saturating_add(1), 1, 1);
        p.lights.push(light(Vec3::ZERO));
        cases.push(StressCase {
            name: format!("grid {}×1×1 (past the device)", max_3d.saturating_add(1)),
            project: p,
            scheme: Scheme::Sweep,
            expect: Expect::Refused("grid"),
            reference_cells: 0,
        });
        let mut p = base(64);
        let lights = (opv_capacity + 1) as usize;
        p.lights = (0..lights).map(|i| light(Vec3::new(-0.9 + 1.8 * (i as f32 / lights as f32), 0.5, 0.5))).collect();
        cases.push(StressCase {
            name: format!("{lights} lights on 64³ (past the device)"),
            project: p,
            scheme: Scheme::Sweep,
            // Refused by the texture bindings or by memory, whichever binds first.
            expect: Expect::Refused("lights"),
            reference_cells: 0,
        });
    }
    cases
}

/// A random small scene with every magnitude drawn log-uniformly up to the project's bounds
/// (scene size 1e-6 to 1e8 m, extinction up to [`MAX_EXTINCTION`], lights up to
/// [`MAX_COORDINATE`] away, point, spot and directional lights, height fog, any scheme and
/// step policy): only the properties that hold for
/// every input are checked, not the error against the reference.
pub fn random_case(seed: u64) -> StressCase {
    let mut rng = Lcg(scrambled(seed));
    let mut u = move || rng.f32();
    let log = |lo: f32, hi: f32, u: f32| 10f32.powf(lo + (hi - lo) * u);
    loop {
        let size = log(-6.0, 8.0, u());
        let res = UVec3::new(1 + (u() * 12.0) as u32, 1 + (u() * 12.0) as u32, 1 + (u() * 12.0) as u32);
        let mut p = base(8);
        let min = Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5) * size;
        p.grid = GridSpec { min, max: min + Vec3::new(0.2 + u(), 0.2 + u(), 0.2 + u()) * size, resolution: res };
        let mid = (p.grid.min + p.grid.max) * 0.5;
        let point = |spread: f32, u1: f32, u2: f32, u3: f32, u4: f32| {
            mid + (Vec3::new(u1, u2, u3) - 0.5) * size * log(-3.0, spread, u4)
        };
        p.medium.base_extinction =
            if u() < 0.2 { 0.0 } else { log(-6.0, 12.0, u()) / size.max(1e-6) }.min(MAX_EXTINCTION);
        p.medium.anisotropy = (u() - 0.5) * 1.98;
        p.medium.albedo = u();
        for _ in 0..(u() * 5.0) as usize {
            let c = point(1.0, u(), u(), u(), u());
            let r = size * log(-4.0, 2.0, u());
            let d = (log(-6.0, 12.0, u()) / size.max(1e-6)).min(MAX_EXTINCTION);
            p.particles.push(Particle::new(c, r.min(MAX_COORDINATE), d));
        }
        for _ in 0..1 + (u() * 3.0) as usize {
            let at = point(3.0, u(), u(), u(), u());
            let mut l = Light::new(
                at.clamp(Vec3::splat(-MAX_COORDINATE), Vec3::splat(MAX_COORDINATE)),
                log(-3.0, 15.0, u()),
                Vec3::new(u(), u(), u()),
            );
            let (kind, dir) = (u(), Vec3::new(u() - 0.5, u() - 0.5, u() - 0.5));
            let dir = if u() < 0.3 { Vec3::AXES[(u() * 3.0) as usize % 3] * dir.signum() } else { dir };
            if kind < 0.25 {
                l.kind = LightKind::Directional { direction: dir };
            } else if kind < 0.5 {
                l.kind = LightKind::Spot { direction: dir, angle_deg: 0.1 + 89.9 * u(), blend: u() };
            }
            p.lights.push(l);
        }
        if u() < 0.3 {
            p.medium.height_falloff = log(-3.0, 6.0, u()) / size.max(1e-6);
            p.medium.height_origin = point(2.0, u(), u(), u(), u()).y;
        }
        p.camera.position =
            point(2.0, u(), u(), u(), u()).clamp(Vec3::splat(-MAX_COORDINATE), Vec3::splat(MAX_COORDINATE));
        p.camera.target = if u() < 0.3 { p.lights[0].position } else { mid };
        p.camera.fov_y_deg = 1.0 + 170.0 * u();
        p.render.width = 1 + (u() * 20.0) as u32;
        p.render.height = 1 + (u() * 20.0) as u32;
        p.render.step_policy =
            [StepPolicy::Fixed, StepPolicy::TwoLevel, StepPolicy::Adaptive][(u() * 3.0) as usize % 3];
        p.render.skip_empty = u() < 0.5;
        let scheme = [Scheme::Sweep, Scheme::Giroud, Scheme::Exact][(u() * 3.0) as usize % 3];
        if p.validate(crate::scene::MAX_RESOLUTION_DEFAULT).is_ok() {
            return StressCase {
                name: format!("random scene {seed}"),
                project: p,
                scheme,
                expect: Expect::Bake { bound: None, monotone: false },
                reference_cells: 8,
            };
        }
    }
}

/// Bakes one case and checks it; never panics, whatever the pipeline returns.
pub fn run_case(gpu: &mut FogPipeline, case: &StressCase) -> StressResult {
    let started = Instant::now();
    let request = FrameRequest { scheme: case.scheme, force: true, ..FrameRequest::for_project(&case.project) };
    let outcome = gpu.update(&case.project, &request);
    let mut result = StressResult {
        case: case.name.clone(),
        scheme: case.scheme.to_string(),
        max_error: None,
        bound: None,
        ev_rel_error: None,
        nan_or_inf: false,
        time_ms: 0.0,
        passed: false,
        detail: String::new(),
    };
    match (&case.expect, outcome) {
        (Expect::Refused(what), Err(e)) => {
            let msg = e.to_string();
            let limit_error = matches!(e, GpuError::Limit { .. } | GpuError::Invalid(_));
            result.passed = limit_error && msg.contains(what);
            result.detail =
                if result.passed { format!("refused: {msg}") } else { format!("refused with the wrong error: {msg}") };
        }
        (Expect::Refused(_), Ok(_)) => result.detail = "accepted a scene past the adapter's limits".into(),
        (Expect::Bake { .. }, Err(e)) => result.detail = format!("bake failed: {e}"),
        (Expect::Bake { bound, monotone }, Ok(_)) => {
            result.bound = *bound;
            let mut failures = Vec::new();
            if let Err(e) = check_bake(gpu, case, *monotone, &mut result, &mut failures) {
                failures.push(format!("readback failed: {e}"));
            }
            if let (Some(b), Some(e)) = (bound, result.max_error) {
                if e > *b {
                    failures.push(format!("transmittance error {e:.3e} > bound {b:.1e}"));
                }
            }
            result.passed = failures.is_empty();
            result.detail = failures.join("; ");
        }
    }
    result.time_ms = started.elapsed().as_secs_f64() * 1e3;
    result
}

fn check_bake(
    gpu: &mut FogPipeline,
    case: &StressCase,
    monotone: bool,
    result: &mut StressResult,
    failures: &mut Vec<String>,
) -> Result<(), GpuError> {
    let p = &case.project;
    let ev = gpu.read_ev()?;
    if let Some(v) = ev.data.iter().find(|v| !v.is_finite() || **v < 0.0) {
        result.nan_or_inf |= !v.is_finite();
        failures.push(format!("EV holds {v}"));
    }
    let cells = sample_cells(&p.grid, case.reference_cells.max(8));
    if !p.particles.is_empty() {
        result.ev_rel_error = Some(ev_error(p, &ev, &cells).0);
    }
    let mut worst = 0.0f64;
    for (l, light) in p.lights.iter().enumerate() {
        if !crate::gpu::light_has_opv(p, light) {
            continue;
        }
        let opv = gpu.read_opv(l)?;
        if let Some(v) = opv.data.iter().find(|v| !v.is_finite() || **v < 0.0) {
            result.nan_or_inf |= !v.is_finite();
            failures.push(format!("OPV of light {l} holds T = {v}"));
        }
        if monotone && !matches!(light.kind, LightKind::Directional { .. }) {
            if let Some(problem) = monotone_violation(p, &opv, light.position) {
                failures.push(format!("light {l}: {problem}"));
            }
        }
        let e = opv_error(p, l, &opv, &cells);
        result.nan_or_inf |= e.nan_or_inf;
        worst = worst.max(e.transmittance_max_abs_error);
    }
    if !p.lights.is_empty() {
        result.max_error = Some(worst);
    }
    if p.lights.iter().any(|l| !l.hidden) {
        let request = FrameRequest { scheme: case.scheme, ..FrameRequest::for_project(p) };
        for phase in [BakePhase::Isotropic, BakePhase::Camera] {
            // The bake refuses non-finite values itself, with a message saying so.
            match gpu.bake_emission(p, &request, phase) {
                Ok(emission) => {
                    if let Some(v) = emission.data.iter().flatten().find(|v| **v < 0.0) {
                        failures.push(format!("the {} light bake holds {v}", phase.name()));
                    }
                }
                Err(e) => {
                    result.nan_or_inf |= e.to_string().contains("not finite");
                    failures.push(format!("the {} light bake failed: {e}", phase.name()));
                }
            }
        }
    }
    let image = gpu.read_image()?;
    for px in &image.rgba {
        if px.iter().any(|v| !v.is_finite()) {
            result.nan_or_inf = true;
            failures.push(format!("image holds {px:?}"));
            break;
        }
        if px[..3].iter().any(|v| *v < 0.0) || !(0.0..=1.0).contains(&px[3]) {
            failures.push(format!("image pixel {px:?} has negative radiance or alpha outside [0, 1]"));
            break;
        }
    }
    Ok(())
}

/// Along the three axis lines through the light's cell (clamped into the grid), T must not
/// decrease while the distance to the light grows. In homogeneous fog T = β·distance; f32
/// rounding is allowed 1e-5 relative.
fn monotone_violation(p: &Project, opv: &Volume, light: Vec3) -> Option<String> {
    let g = &p.grid;
    let r = g.resolution;
    let lc = ((light - g.min) / g.cell_size()).floor();
    let lc = [0, 1, 2].map(|a| lc[a].clamp(0.0, (r[a] - 1) as f32) as u32);
    for axis in 0..3 {
        let mut line: Vec<(f32, f32, [u32; 3])> = (0..r[axis])
            .map(|n| {
                let mut c = lc;
                c[axis] = n;
                (center(p, c).distance(light), opv.get(c[0], c[1], c[2]), c)
            })
            .collect();
        line.sort_by(|a, b| a.0.total_cmp(&b.0));
        for w in line.windows(2) {
            let (near, far) = (w[0], w[1]);
            if far.0 > near.0 && far.1 < near.1 - 1e-5 * near.1.abs() {
                return Some(format!(
                    "T decreases away from the light: {} at cell {:?} then {} at cell {:?}",
                    near.1, near.2, far.1, far.2
                ));
            }
        }
    }
    None
}

/// Runs every case in order, calling `progress` after each.
pub fn run_matrix(
    gpu: &mut FogPipeline,
    cases: &[StressCase],
    mut progress: impl FnMut(&StressResult),
) -> Vec<StressResult> {
    cases
        .iter()
        .map(|c| {
            let r = run_case(gpu, c);
            progress(&r);
            r
        })
        .collect()
}

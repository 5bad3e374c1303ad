//! A reduced stress matrix on the real adapter: extreme inputs give finite, in-range, monotone
//! results within the stated error bounds, and scenes past the adapter's limits are refused
//! before allocation with the limit named.

mod common;

use common::{pipeline, small_scene};
use fogsmith::gpu::{FrameRequest, GpuError};
use fogsmith::scene::{Particle, Scheme};
use fogsmith::stress::{matrix, run_case, Expect, StressCase};
use glam::{UVec3, Vec3};

/// The quick matrix without its slowest rows (a million particles, the longest grid).
fn reduced(cases: Vec<StressCase>, max_3d: u32) -> Vec<StressCase> {
    cases
        .into_iter()
        .filter(|c| c.project.particles.len() < 1_000_000 || matches!(c.expect, Expect::Refused(_)))
        .filter(|c| c.project.grid.resolution.x < max_3d)
        .collect()
}

#[test]
fn reduced_stress_matrix_holds() {
    let mut gpu = pipeline();
    let limits = gpu.context().limits.clone();
    let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    let cases = reduced(
        matrix(true, limits.max_texture_dimension_3d, binding, opv_capacity(&limits)),
        limits.max_texture_dimension_3d,
    );
    assert!(cases.len() >= 40, "{} cases", cases.len());
    let mut failures = Vec::new();
    for case in &cases {
        let r = run_case(&mut gpu, case);
        println!(
            "{:<44} {:<7} err {:?} bound {:?} nan {} {:.0} ms {}",
            r.case, r.scheme, r.max_error, r.bound, r.nan_or_inf, r.time_ms, r.detail
        );
        assert!(!r.nan_or_inf || !r.passed, "{}: a NaN must fail the case", r.case);
        if !r.passed {
            failures.push(format!("{} ({}): {}", r.case, r.scheme, r.detail));
        }
    }
    assert!(failures.is_empty(), "failed cases:\n{}", failures.join("\n"));
}

fn opv_capacity(limits: &wgpu::Limits) -> u64 {
    fogsmith::gpu::OpvLayout::for_limits(limits).capacity_lights(UVec3::splat(64))
}

/// A grid edge, OPV total, particle count or image past the adapter is refused by
/// `check_limits` (and so by `update`) with the limit and a suggestion in the message.
#[test]
fn limits_are_refused_before_allocation_with_the_limit_named() {
    let gpu = pipeline();
    let limits = gpu.context().limits.clone();
    let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    let limit_message = |p: &fogsmith::scene::Project, w: u32, h: u32| match gpu.check_limits(p, w, h) {
        Err(e @ GpuError::Limit { .. }) => e.to_string(),
        other => panic!("expected a limit error, got {other:?}"),
    };

    let mut p = small_scene(8, &[Vec3::ONE]);
    p.grid.resolution = UVec3::new(limits.max_texture_dimension_3d + 1, 2, 2);
    let msg = limit_message(&p, 16, 16);
    assert!(
        msg.contains(&limits.max_texture_dimension_3d.to_string()) && msg.contains("lower grid.resolution"),
        "{msg}"
    );

    // OPVs span several textures: refused only past all of them together, or past memory.
    let mut p = small_scene(64, &[]);
    let memory = gpu.context().memory_bytes().unwrap_or(u64::MAX);
    let by_memory = (0..=opv_capacity(&limits))
        .rev()
        .find(|&n| gpu.memory_needed(&p.grid, n as usize, p.particles.len(), 16, 16) <= memory)
        .unwrap();
    let most = by_memory.min(opv_capacity(&limits));
    p.lights =
        (0..=most).map(|i| fogsmith::scene::Light::new(Vec3::new(i as f32 * 1e-5, 0.0, 0.0), 1.0, Vec3::ONE)).collect();
    let msg = limit_message(&p, 16, 16);
    if most == by_memory {
        assert!(msg.contains("GPU memory") && msg.contains("fewer lights"), "{msg}");
    } else {
        let capacity = opv_capacity(&limits) * 64 * 64 * 64 * 4;
        assert!(
            msg.contains("optical-depth") && msg.contains(&capacity.to_string()) && msg.contains("at most"),
            "{msg}"
        );
    }
    p.lights.truncate(most as usize);
    assert!(gpu.check_limits(&p, 16, 16).is_ok(), "the most lights that fit are accepted");

    let mut p = small_scene(8, &[Vec3::ONE]);
    let n = binding / 32 + 1;
    p.particles = vec![Particle::new(Vec3::new(50.0, 0.0, 0.0), 0.1, 1.0); n as usize];
    let msg = limit_message(&p, 16, 16);
    assert!(msg.contains("particles") && msg.contains("use at most"), "{msg}");

    let p = small_scene(8, &[Vec3::ONE]);
    let msg = limit_message(&p, limits.max_texture_dimension_2d + 1, 8);
    assert!(msg.contains("image") && msg.contains("smaller image"), "{msg}");
}

/// Giroud's gather dispatches ⌈nz/4⌉ workgroups per light along z; past the adapter's
/// dispatch limit it is refused with a pointer to the sweep scheme, which has no such limit.
#[test]
fn giroud_dispatch_limit_is_refused_and_sweep_still_runs() {
    let mut gpu = pipeline();
    let max = gpu.context().limits.max_compute_workgroups_per_dimension;
    let mut p = small_scene(4, &[]);
    p.grid.resolution = UVec3::new(1, 1, 4);
    p.lights = (0..=max)
        .map(|i| fogsmith::scene::Light::new(Vec3::new(0.0, 0.0, -0.9 + 1e-5 * i as f32), 0.0, Vec3::ONE))
        .collect();
    p.lights[0].intensity = 1.0;
    p.render.width = 8;
    p.render.height = 8;
    let err = gpu.update(&p, &FrameRequest { scheme: Scheme::Giroud, ..FrameRequest::for_project(&p) }).unwrap_err();
    assert!(matches!(err, GpuError::Limit { .. }) && err.to_string().contains("sweep scheme"), "{err}");
    gpu.update(&p, &FrameRequest { scheme: Scheme::Sweep, ..FrameRequest::for_project(&p) }).unwrap();
}

/// A grid of more 8³ bricks than one dispatch may have workgroups is injected in several
/// dispatches: every brick, the last included, gets the base fog.
#[test]
fn grids_with_more_bricks_than_one_dispatch_are_fully_injected() {
    let mut gpu = pipeline();
    let limits = gpu.context().limits.clone();
    let max_groups = limits.max_compute_workgroups_per_dimension as u64;
    let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    // Shallow in y and z so that x alone makes the bricks, within the OPV budget.
    let (ny, nz) = (64u32, 128u32);
    let nx = ((max_groups + 1).div_ceil((ny / 8 * nz / 8) as u64) * 8) as u32;
    assert!(nx <= limits.max_texture_dimension_3d, "this adapter's limits need another shape: {limits:?}");
    assert!(nx as u64 * (ny * nz) as u64 * 4 <= binding, "this adapter's limits need another shape");
    let mut p = small_scene(8, &[]);
    p.particles.clear();
    p.medium.base_extinction = 0.25;
    p.grid.resolution = UVec3::new(nx, ny, nz);
    p.render.width = 8;
    p.render.height = 8;
    let report = gpu.update(&p, &FrameRequest::for_project(&p)).unwrap();
    assert!(report.counters.dispatches >= 3, "inject split over at least two dispatches, plus occupancy");
    let ev = gpu.read_ev().unwrap();
    let wrong = ev.data.iter().filter(|v| **v != 0.25).count();
    assert_eq!(wrong, 0, "{wrong} cells missed by injection");
}

/// A light millions of cells outside the grid still gets a plan that solves every cell
/// exactly once, in a few dispatches (its cell index used to overflow i32).
#[test]
fn sweep_plan_of_a_far_light_covers_the_grid_once() {
    let p = small_scene(32, &[]);
    for light in [Vec3::new(1e9, -1e9, 1e8), Vec3::new(-1e9, 0.1, 0.2), Vec3::new(0.3, 1e9, -1e9)] {
        let plan = fogsmith::gpu::sweep_steps(&p.grid, &[(0, light)], 8);
        let frame = fogsmith::gpu::ShellFrame::new(&p.grid, light, 8);
        // Batches of stride − 3 = 5 shells over the grid's 32 levels.
        assert!(!plan.steps.is_empty() && plan.steps.len() <= 33 / 5 + 1, "{light}: {} dispatches", plan.steps.len());
        for k in 0..32 {
            for j in 0..32 {
                for i in 0..32 {
                    let (batch, face) = frame.claim([i, j, k]);
                    let c = [i, j, k];
                    let holders = plan
                        .boxes
                        .iter()
                        .filter(|b| b.batch == batch && b.face == face)
                        .filter(|b| (0..3).all(|a| c[a] >= b.lo[a] && c[a] < b.lo[a] + b.size[a] as i32))
                        .count();
                    assert_eq!(holders, 1, "{light}: cell {c:?}");
                }
            }
        }
    }
}

/// Positions and extinctions past the project's bounds are refused by validation with the
/// field named, before they can overflow f32 on the GPU (a light at 1e30 m gave NaN frames).
#[test]
fn out_of_range_positions_and_extinction_are_invalid() {
    let mut gpu = pipeline();
    let mut p = small_scene(8, &[Vec3::new(1e30, 0.0, 0.0)]);
    let err = gpu.update(&p, &FrameRequest::for_project(&p)).unwrap_err().to_string();
    assert!(err.contains("lights[0].position") && err.contains("1e9"), "{err}");
    p.lights[0].position = Vec3::ONE;
    p.medium.base_extinction = 1e30;
    let err = gpu.update(&p, &FrameRequest::for_project(&p)).unwrap_err().to_string();
    assert!(err.contains("medium.base_extinction") && err.contains("1e12"), "{err}");
    // A light bright enough to overflow the radiance near it (it gave infinite pixels).
    p.medium.base_extinction = 0.1;
    p.lights[0].intensity = 3e38;
    let err = gpu.update(&p, &FrameRequest::for_project(&p)).unwrap_err().to_string();
    assert!(err.contains("lights[0].intensity") && err.contains("1e15"), "{err}");
}

/// Random small scenes at every magnitude the project allows: finite, in-range results.
#[test]
fn random_extreme_scenes_stay_finite_and_in_range() {
    let mut gpu = pipeline();
    let mut failures = Vec::new();
    for seed in 0..40 {
        let case = fogsmith::stress::random_case(seed);
        let r = run_case(&mut gpu, &case);
        println!("seed {seed}: {} {:.0} ms {}", r.scheme, r.time_ms, r.detail);
        if !r.passed {
            failures.push(format!("seed {seed}: {}\n{:?}", r.detail, case.project));
        }
    }
    assert!(failures.is_empty(), "{}", failures.join("\n\n"));
}

/// A base layer too large for the adapter is not uploaded (wgpu would panic) and the bake is
/// refused with the limit named; a zero-sized frame is an error, not a GPU validation failure.
#[test]
fn oversized_base_layer_and_empty_frames_are_errors() {
    let mut gpu = pipeline();
    let limits = gpu.context().limits.clone();
    let binding = limits.max_storage_buffer_binding_size.min(limits.max_buffer_size);
    let mut p = small_scene(8, &[Vec3::ONE]);
    let nz = (binding / 4 / (256 * 256) + 1) as u32;
    p.grid.resolution = UVec3::new(256, 256, nz);
    gpu.set_base_layer(Some(fogsmith::scene::Volume::new(p.grid, vec![0.5; p.grid.cell_count() as usize])));
    let err = gpu.update(&p, &FrameRequest::for_project(&p)).unwrap_err();
    assert!(matches!(err, GpuError::Limit { .. }) && err.to_string().contains("lower grid.resolution"), "{err}");
    gpu.set_base_layer(None);
    let p = small_scene(8, &[Vec3::ONE]);
    let err = gpu.update(&p, &FrameRequest { width: 0, ..FrameRequest::for_project(&p) }).unwrap_err().to_string();
    assert!(err.contains("width") && err.contains("got 0"), "{err}");
}

/// `fogsmith stress --json` prints these results: the documented keys are present.
#[test]
fn stress_results_serialise_with_the_documented_keys() {
    let mut gpu = pipeline();
    let limits = gpu.context().limits.clone();
    let case =
        matrix(true, limits.max_texture_dimension_3d, limits.max_storage_buffer_binding_size, opv_capacity(&limits))
            .remove(0);
    let v = serde_json::to_value(vec![run_case(&mut gpu, &case)]).unwrap();
    let row = &v[0];
    for key in ["case", "max_error", "nan_or_inf", "time_ms", "passed", "bound", "scheme"] {
        assert!(row.get(key).is_some(), "{key} missing from {row}");
    }
    assert!(row["nan_or_inf"].is_boolean() && row["time_ms"].is_number() && row["case"].is_string());
}

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
    let binding = (limits.max_storage_buffer_binding_size as u64).min(limits.max_buffer_size);
    let cases = reduced(matrix(true, limits.max_texture_dimension_3d, binding), limits.max_texture_dimension_3d);
    assert!(cases.len() >= 40, "{} cases", cases.len());
    let mut failures = Vec::new();
    for case in &cases {
        let r = run_case(&mut gpu, case);
        println!("{:<44} {:<7} err {:?} bound {:?} nan {} {:.0} ms {}", r.case, r.scheme, r.max_error, r.bound, r.nan_or_inf, r.time_ms, r.detail);
        assert!(!r.nan_or_inf || !r.passed, "{}: a NaN must fail the case", r.case);
        if !r.passed {
            failures.push(format!("{} ({}): {}", r.case, r.scheme, r.detail));
        }
    }
    assert!(failures.is_empty(), "failed cases:\n{}", failures.join("\n"));
}

/// A grid edge, OPV, particle list or light count past the adapter is refused by
/// `check_limits` (and so by `update`) with the limit and a suggestion in the message.
#[test]
fn limits_are_refused_before_allocation_with_the_limit_named() {
    let gpu = pipeline();
    let limits = gpu.context().limits.clone();
    let binding = (limits.max_storage_buffer_binding_size as u64).min(limits.max_buffer_size);
    let limit_message = |p: &fogsmith::scene::Project, w: u32, h: u32| match gpu.check_limits(p, w, h) {
        Err(e @ GpuError::Limit { .. }) => e.to_string(),
        other => panic!("expected a limit error, got {other:?}"),
    };

    let mut p = small_scene(8, &[Vec3::ONE]);
    p.grid.resolution = UVec3::new(limits.max_texture_dimension_3d + 1, 2, 2);
    let msg = limit_message(&p, 16, 16);
    assert!(msg.contains(&limits.max_texture_dimension_3d.to_string()) && msg.contains("lower grid.resolution"), "{msg}");

    let mut p = small_scene(64, &[]);
    let lights = binding / (64 * 64 * 64 * 4) + 1;
    p.lights = (0..lights).map(|i| fogsmith::scene::Light::new(Vec3::new(i as f32 * 1e-3, 0.0, 0.0), 1.0, Vec3::ONE)).collect();
    let msg = limit_message(&p, 16, 16);
    assert!(msg.contains("optical-depth") && msg.contains(&binding.to_string()) && msg.contains("at most"), "{msg}");

    let mut p = small_scene(256, &[Vec3::ONE]);
    let n = binding / 4 / 32768 + 1;
    p.particles = vec![Particle::new(Vec3::ZERO, 100.0, 1.0); n as usize];
    let msg = limit_message(&p, 16, 16);
    assert!(msg.contains("particle–brick") && msg.contains("fewer or smaller particles"), "{msg}");

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
    p.lights = (0..=max).map(|i| fogsmith::scene::Light::new(Vec3::new(0.0, 0.0, -0.9 + 1e-5 * i as f32), 0.0, Vec3::ONE)).collect();
    p.lights[0].intensity = 1.0;
    p.render.width = 8;
    p.render.height = 8;
    let err = gpu.update(&p, &FrameRequest { scheme: Scheme::Giroud, ..FrameRequest::for_project(&p) }).unwrap_err();
    assert!(matches!(err, GpuError::Limit { .. }) && err.to_string().contains("sweep scheme"), "{err}");
    gpu.update(&p, &FrameRequest { scheme: Scheme::Sweep, ..FrameRequest::for_project(&p) }).unwrap();
}

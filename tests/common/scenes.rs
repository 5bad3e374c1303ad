//! The scenes the tests render: small hand-made ones, the project's seeded generators that
//! randomize them, the real pipeline, and one render of a scene on both the pipeline and the
//! exact reference.

use fogsmith::gpu::{FogPipeline, FrameReport, FrameRequest, GpuContext, Image};
use fogsmith::measure::image_error;
use fogsmith::reference::{render_reference, RefRenderOptions};
use fogsmith::scene::{Camera, GridSpec, Light, Medium, Particle, Project, Volume};
use glam::{UVec3, Vec3};

/// The linear congruential generator, for the tests whose scenes were drawn from it.
pub use fogsmith::rng::Lcg;
/// The generator of the randomized scenes (xorshift): `Rng(seed)`.
pub use fogsmith::rng::XorShift as Rng;

/// The real pipeline on whatever adapter wgpu finds (lavapipe on CI). A missing adapter
/// fails the test loudly: GPU tests are never skipped.
pub fn pipeline() -> FogPipeline {
    fogsmith::cli::ensure_runtime_dir();
    match GpuContext::new_headless() {
        Ok(ctx) => FogPipeline::new(ctx),
        Err(e) => panic!("GPU tests need an adapter and none is available: {e}"),
    }
}

/// A small cloud of gaussians in a unit-ish box with one or more lights.
pub fn small_scene(res: u32, lights: &[Vec3]) -> Project {
    let mut p = Project {
        grid: GridSpec {
            min: Vec3::new(-1.0, -1.0, -1.0),
            max: Vec3::new(1.0, 1.0, 1.0),
            resolution: UVec3::splat(res),
        },
        medium: Medium { base_extinction: 0.05, albedo: 0.8, anisotropy: 0.0, ..Medium::default() },
        particles: vec![
            Particle::new(Vec3::new(0.0, 0.0, 0.0), 0.35, 4.0),
            Particle::new(Vec3::new(0.4, -0.2, 0.1), 0.25, 6.0),
            Particle::new(Vec3::new(-0.45, 0.3, -0.2), 0.3, 3.0),
            Particle::new(Vec3::new(0.1, 0.5, 0.4), 0.2, 8.0),
        ],
        lights: lights.iter().map(|&pos| Light::new(pos, 5.0, Vec3::new(1.0, 0.9, 0.8))).collect(),
        ..Project::default()
    };
    p.camera = Camera { position: Vec3::new(0.3, 0.4, 3.5), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 45.0 };
    p.render.width = 48;
    p.render.height = 36;
    p
}

/// A grid filled with base fog only.
pub fn homogeneous_scene(res: u32, beta: f32, light: Vec3) -> Project {
    let mut p = small_scene(res, &[light]);
    p.particles.clear();
    p.medium.base_extinction = beta;
    p
}

/// `project` rendered on a fresh pipeline and by the reference at its output size: the GPU
/// image, the reference's linear RGB and the pipeline's report. A GPU image holding NaN or
/// infinity fails the test.
pub fn render_both(project: &Project) -> (Image, Vec<[f64; 3]>, FrameReport) {
    let mut gpu = pipeline();
    let (w, h) = (project.render.width, project.render.height);
    let report = gpu.update(project, &FrameRequest::for_project(project)).unwrap();
    let image = gpu.read_image().unwrap();
    let reference = render_reference(project, w, h, &RefRenderOptions::default());
    let err = image_error(&image, &reference);
    assert!(!err.nan_or_inf, "the GPU image holds NaN or infinity");
    (image, reference, report)
}

/// Per cell of `cells`, the transmittance error |exp(−τ) − exp(−τ_exact)| of a light's optical
/// depths `opv` against the exact ones, and the worst cell's index (the last of equals); what
/// the placement tests print when asked to diagnose.
pub fn transmittance_errors(opv: &Volume, cells: &[[u32; 3]], exact: &[f64]) -> (Vec<f64>, Option<usize>) {
    let errors: Vec<f64> = cells
        .iter()
        .zip(exact)
        .map(|(c, t)| ((-(opv.get(c[0], c[1], c[2]) as f64)).exp() - (-t).exp()).abs())
        .collect();
    let worst = (0..errors.len()).max_by(|&a, &b| errors[a].total_cmp(&errors[b]));
    (errors, worst)
}

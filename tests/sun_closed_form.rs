//! Sun et al.'s closed form on the GPU: base fog outside the grid, lit by a light whose light
//! paths miss the grid, against the exact airlight of the reference.

mod common;

use common::pipeline;
use fogsmith::gpu::FrameRequest;
use fogsmith::reference::sun::sun_la;
use fogsmith::scene::{Camera, GridSpec, Light, Project};
use glam::{UVec3, Vec3};

#[test]
fn gpu_base_fog_matches_sun_closed_form() {
    let mut gpu = pipeline();
    for (beta, light, fov) in [
        (0.1f32, Vec3::new(1.5, 0.4, -5.0), 60.0f32),
        (0.5, Vec3::new(-0.3, 0.2, -1.0), 90.0),
        (0.04, Vec3::new(0.0, 0.0, -3.0), 20.0),
    ] {
        // A grid far behind the camera: every ray and every light path misses it.
        let mut p = Project {
            grid: GridSpec { min: Vec3::splat(100.0), max: Vec3::splat(101.0), resolution: UVec3::splat(4) },
            ..Project::default()
        };
        p.medium.base_extinction = beta;
        p.lights = vec![Light::new(light, 3.0, Vec3::new(1.0, 0.5, 0.25))];
        p.camera = Camera { position: Vec3::ZERO, target: Vec3::new(0.0, 0.0, -1.0), up: Vec3::Y, fov_y_deg: fov };
        let (w, h) = (24, 16);
        let report = gpu.update(&p, &FrameRequest { width: w, height: h, ..FrameRequest::for_project(&p) }).unwrap();
        assert_eq!(report.counters.samples_marched, 0, "the closed form needs no samples");
        let image = gpu.read_image().unwrap();
        let mut worst = 0.0f64;
        for py in 0..h {
            for px in 0..w {
                let dir = p.camera.ray_dir(px, py, w, h).as_dvec3();
                let to_light = light.as_dvec3();
                let gamma = dir.dot(to_light / to_light.length()).clamp(-1.0, 1.0).acos();
                let want = 3.0 * sun_la(gamma, to_light.length(), f64::INFINITY, beta as f64, 1.0);
                let got = image.rgba[(py * w + px) as usize];
                assert!(got.iter().all(|c| c.is_finite()));
                worst = worst.max((got[0] as f64 - want).abs() / want);
                assert!((got[1] as f64 - 0.5 * want).abs() <= 3e-3 * want, "green channel at ({px}, {py})");
            }
        }
        println!("β = {beta}: max relative error vs Sun's exact airlight {worst:.2e}");
        // The remapped 64×64 table is within 1e-3 of the exact F over the sweep (f32 on the GPU).
        assert!(worst < 3e-3, "β = {beta}: {worst:e}");
    }
}

//! Adaptive image-space sampling against the per-pixel march, on randomized scenes: every
//! class of light placement (inside the fog, outside it, behind the camera, on the screen's
//! edge), the sun grazing and straight behind the viewer, surfaces with sharp silhouettes in
//! front of bright fog, thin grids, small and large particles.

mod common;

use common::{pipeline, Rng};
use fogsmith::gpu::{FrameRequest, Image, ImageSampling};
use fogsmith::measure::{image_difference, ImageDifference};
use fogsmith::scene::{Camera, GridSpec, Ground, Light, LightKind, Particle, Project, SurfaceBox};
use glam::{UVec3, Vec3};

/// The targets of adaptive sampling against the per-pixel march.
const MAX_REL_RMSE: f64 = 0.005;
const MAX_P999_OF_MAX: f64 = 0.02;

fn render(p: &Project, sampling: ImageSampling) -> (Image, u64) {
    let mut gpu = pipeline();
    gpu.set_image_sampling(sampling);
    let report = gpu.update(p, &FrameRequest::for_project(p)).unwrap();
    (gpu.read_image().unwrap(), report.counters.rays_marched)
}

/// Where a ray through pixel centre (x, y) of `p`'s image is at distance `t` from the camera.
fn through_pixel(p: &Project, x: f32, y: f32, t: f32) -> Vec3 {
    let cam = &p.camera;
    let (right, up, forward) = cam.basis();
    let tan_half = (cam.fov_y_deg.to_radians() * 0.5).tan();
    let (w, h) = (p.render.width as f32, p.render.height as f32);
    let sx = (x + 0.5) / w * 2.0 - 1.0;
    let sy = 1.0 - (y + 0.5) / h * 2.0;
    let dir = (forward + right * sx * tan_half * (w / h) + up * sy * tan_half).normalize();
    cam.position + dir * t
}

/// A random scene of case `case`: the light placement cycles through the classes the module
/// doc lists; grids, particles, media and surfaces are drawn at random.
fn scene(rng: &mut Rng, case: u32) -> (Project, &'static str) {
    let thin = case % 4 == 3;
    let resolution = if thin {
        [UVec3::new(48, 3, 40), UVec3::new(40, 40, 2), UVec3::new(2, 36, 40)][(case / 4) as usize % 3]
    } else {
        UVec3::splat(24 + rng.pick(3) as u32 * 8)
    };
    let half = if thin { resolution.as_vec3() / resolution.max_element() as f32 * 1.2 } else { Vec3::splat(1.0) };
    let mut p = Project {
        grid: GridSpec { min: -half.max(Vec3::splat(0.05)), max: half.max(Vec3::splat(0.05)), resolution },
        ..Project::default()
    };
    p.medium.base_extinction = if rng.f32() < 0.4 { 0.06 } else { 0.0 };
    p.medium.albedo = 0.6 + 0.4 * rng.f32();
    p.medium.anisotropy = -0.3 + 1.1 * rng.f32();
    for _ in 0..3 + rng.pick(6) {
        let radius = if rng.f32() < 0.5 { 0.04 + 0.1 * rng.f32() } else { 0.25 + 0.35 * rng.f32() };
        let centre = rng.vec3(-0.8, 0.8) * half;
        p.particles.push(Particle::new(centre, radius, 1.0 + 8.0 * rng.f32()));
    }
    // Above the ground, which hides everything from a camera below it.
    let d = rng.direction();
    let eye = Vec3::new(d.x, d.y.abs() * 0.8 + 0.1, d.z).normalize() * (3.2 + rng.f32());
    p.camera = Camera { position: eye, target: rng.vec3(-0.2, 0.2), up: Vec3::Y, fov_y_deg: 40.0 + 20.0 * rng.f32() };
    p.render.width = 160;
    p.render.height = 96;
    let (_, _, forward) = p.camera.basis();
    let (light, what) = match case % 7 {
        0 => (Light::new(rng.vec3(-0.6, 0.6) * half, 3.0, Vec3::ONE), "a point light inside the fog"),
        1 => (Light::new(rng.direction() * 2.2, 6.0, Vec3::ONE), "a point light outside the grid"),
        2 => (Light::new(eye - forward * 0.8 + rng.vec3(-0.3, 0.3), 6.0, Vec3::ONE), "a point light behind the camera"),
        3 => {
            let (w, h) = (p.render.width as f32, p.render.height as f32);
            let (x, y) = if rng.f32() < 0.5 { (0.0, h * rng.f32()) } else { (w * rng.f32(), h - 1.0) };
            (Light::new(through_pixel(&p, x, y, 2.5 + rng.f32()), 5.0, Vec3::ONE), "a point light on the screen's edge")
        }
        4 => {
            let mut l = Light::new(Vec3::ZERO, 3.0, Vec3::ONE);
            let side = forward.cross(Vec3::Y).normalize_or(Vec3::X);
            l.kind = LightKind::Directional { direction: (side + Vec3::new(0.0, -0.08, 0.0)).normalize() };
            (l, "the sun at a grazing angle")
        }
        5 => {
            let mut l = Light::new(Vec3::ZERO, 3.0, Vec3::ONE);
            l.kind = LightKind::Directional { direction: forward };
            (l, "the sun straight behind the viewer")
        }
        _ => {
            let at = rng.direction() * 2.0;
            let mut l = Light::new(at, 8.0, Vec3::ONE);
            l.kind = LightKind::Spot { direction: -at, angle_deg: 25.0 + 20.0 * rng.f32(), blend: 0.2 };
            (l, "a spot light outside the grid")
        }
    };
    if matches!(light.kind, LightKind::Directional { .. }) {
        // Homogeneous base fog without end hides every sun.
        p.medium.base_extinction = 0.0;
    }
    p.lights.push(light);
    if case.is_multiple_of(3) || case % 7 == 4 {
        // A box between the camera and the fog: a sharp silhouette in front of bright fog.
        let c = eye * (0.45 + 0.1 * rng.f32());
        let size = 0.15 + 0.2 * rng.f32();
        p.surfaces.boxes.push(SurfaceBox { min: c - size, max: c + size, ..SurfaceBox::default() });
        p.surfaces.ground = Some(Ground { height: p.grid.min.y - 0.3, ..Ground::default() });
    }
    (p, what)
}

fn check(case: u32, what: &str, d: &ImageDifference, rays: u64, pixels: u64) {
    println!(
        "case {case:2} ({what}): rel-RMSE {:.3} %, p99.9 {:.3} % of max, {:.3} rays/px",
        d.rel_rmse * 100.0,
        d.p999_of_max * 100.0,
        rays as f64 / pixels as f64
    );
    assert!(!d.nan_or_inf, "case {case} ({what}): NaN or infinity in the adaptive image");
    assert!(d.rel_rmse <= MAX_REL_RMSE, "case {case} ({what}): rel-RMSE {} over {MAX_REL_RMSE}", d.rel_rmse);
    assert!(d.p999_of_max <= MAX_P999_OF_MAX, "case {case} ({what}): p99.9 {} of max", d.p999_of_max);
}

/// On randomized scenes of every placement class, the adaptive image is within the targets of
/// the per-pixel one, holds no NaN, and marches fewer rays than there are pixels (else the
/// comparison would prove nothing).
#[test]
fn adaptive_sampling_matches_the_per_pixel_march_on_random_scenes() {
    let mut rng = Rng(0x1a9e_5a37);
    let mut worst = 0.0f64;
    for case in 0..14 {
        let (p, what) = scene(&mut rng, case);
        let (per_pixel, all) = render(&p, ImageSampling::PerPixel);
        let (adaptive, rays) = render(&p, ImageSampling::default());
        let pixels = (p.render.width * p.render.height) as u64;
        assert_eq!(all, pixels, "case {case}: the per-pixel march marches every pixel once");
        let peak = per_pixel.rgba.iter().map(|c| c[0].max(c[1]).max(c[2])).fold(0.0f32, f32::max);
        assert!(peak > 0.0, "case {case} ({what}): the scene is dark");
        let d = image_difference(&adaptive, &per_pixel);
        if let Ok(dir) = std::env::var("FOGSMITH_SAMPLING_DUMP") {
            fogsmith::scene::save_project(&std::path::Path::new(&dir).join(format!("case{case}.ron")), &p).unwrap();
        }
        check(case, what, &d, rays, pixels);
        assert!(rays < pixels, "case {case} ({what}): {rays} rays for {pixels} pixels");
        worst = worst.max(d.rel_rmse);
    }
    println!("worst rel-RMSE {:.3} %", worst * 100.0);
}

/// Every pixel gets a value from this march: after an image of another scene in the same
/// target, no pixel keeps the old one (a hole would show the previous scene).
#[test]
fn no_pixel_keeps_a_previous_image() {
    let mut rng = Rng(0x5eed_0b1e);
    let (bright, _) = scene(&mut rng, 0);
    let (mut other, what) = scene(&mut rng, 1);
    other.render.width = bright.render.width;
    other.render.height = bright.render.height;
    let mut gpu = pipeline();
    gpu.update(&bright, &FrameRequest::for_project(&bright)).unwrap();
    gpu.update(&other, &FrameRequest::for_project(&other)).unwrap();
    let reused = gpu.read_image().unwrap();
    let (per_pixel, _) = render(&other, ImageSampling::PerPixel);
    let d = image_difference(&reused, &per_pixel);
    check(1, what, &d, 0, 1);
}

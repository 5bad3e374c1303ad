//! Surfaces lit through the fog on the real pipeline: boxes shadowing the ground for every
//! light kind, and the fog's glow on surfaces (Sun et al.'s surface term), against exact
//! values and the CPU reference.

mod common;

use common::{pipeline, Lcg};
use fogsmith::gpu::FrameRequest;
use fogsmith::measure::image_error;
use fogsmith::reference::{camera_ray64, render_reference, shadowed, RefRenderOptions};
use fogsmith::scene::{Camera, GridSpec, Ground, Light, LightKind, Medium, Project, SurfaceBox};
use glam::{DVec3, UVec3, Vec3};
use std::f64::consts::PI;

fn gpu_image(p: &Project) -> Vec<[f32; 4]> {
    let mut gpu = pipeline();
    // Pixel by pixel against exact values: one ray per pixel, so that no pixel's fog is an
    // interpolation (tests/image_sampling.rs checks that).
    gpu.set_image_sampling(fogsmith::gpu::ImageSampling::PerPixel);
    gpu.update(p, &FrameRequest::for_project(p)).unwrap();
    let image = gpu.read_image().unwrap().rgba;
    assert!(image.iter().flatten().all(|v| v.is_finite()), "the GPU image holds NaN or infinity");
    image
}

/// The ground y = 0 seen from above through homogeneous fog β (no particles), one light
/// above it, and (with `block`) a block hovering between the light and the ground, above the
/// camera's view: the block changes nothing in the image but its shadow.
fn shadow_scene(kind: LightKind, beta: f32, block: bool) -> Project {
    let mut p = Project {
        grid: GridSpec { min: Vec3::splat(-1.0), max: Vec3::splat(1.0), resolution: UVec3::splat(16) },
        medium: Medium { base_extinction: beta, albedo: 1.0, anisotropy: 0.0, ..Medium::default() },
        ..Project::default()
    };
    p.particles.clear();
    let mut light = Light::new(Vec3::new(0.1, 3.0, -0.1), 6.0, Vec3::new(1.0, 0.9, 0.8));
    light.kind = kind;
    p.lights = vec![light];
    p.surfaces.ground = Some(Ground { height: 0.0, albedo: Vec3::splat(0.5), ..Ground::default() });
    if block {
        p.surfaces.boxes.push(SurfaceBox {
            min: Vec3::new(-0.3, 2.0, -0.3),
            max: Vec3::new(0.3, 2.2, 0.3),
            albedo: Vec3::splat(0.5),
            ..SurfaceBox::default()
        });
    }
    p.camera = Camera { position: Vec3::new(0.0, 1.2, 2.5), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 40.0 };
    p.render.width = 48;
    p.render.height = 36;
    p
}

/// The direct light the block removes at ground point x, as seen by the camera: exact for
/// homogeneous fog (ρ/π · I·cone·cosθ/d² · e^{−βd}, or ρ/π · E·cosθ for a sun) times the
/// view transmittance.
fn expected_direct(p: &Project, x: DVec3, channel: usize) -> f64 {
    let beta = p.medium.base_extinction as f64;
    let l = &p.lights[0];
    let rgb = l.radiance_rgb().as_dvec3()[channel];
    let rho = p.surfaces.ground.unwrap().albedo.as_dvec3()[channel] / PI;
    let view = (-beta * (x - p.camera.position.as_dvec3()).length()).exp();
    match l.kind {
        LightKind::Directional { direction } => rho * rgb * (-direction.as_dvec3().normalize().y) * view,
        _ => {
            let to = l.position.as_dvec3() - x;
            let d = to.length();
            rho * rgb * l.cone_factor(x) * (to.y / d) / (d * d) * (-beta * d).exp() * view
        }
    }
}

/// For each light kind: ground pixels whose whole neighbourhood is in the block's shadow
/// (by the CPU ray–box test) lose exactly the direct light (GPU with block vs GPU without,
/// relative error below 1e-3: the optical depth is exact in homogeneous fog, f32 leaves
/// ~1e-6), pixels well outside the shadow lose nothing, and the image with the block matches
/// the reference render. The first two compare scenes whose fog scatters nothing (albedo 0),
/// so that the block's shadow in the fog in front of the ground leaves those pixels alone;
/// the reference comparison includes it.
#[test]
fn block_shadows_ground_for_every_light_kind() {
    let kinds = [
        (LightKind::Point, 0.1),
        (LightKind::Spot { direction: Vec3::new(0.05, -1.0, 0.0), angle_deg: 55.0, blend: 0.3 }, 0.1),
        // Homogeneous fog without end extinguishes a sun: its case has no base fog.
        (LightKind::Directional { direction: Vec3::new(0.25, -1.0, 0.15) }, 0.0),
    ];
    for (kind, beta) in kinds {
        let with = shadow_scene(kind, beta, true);
        let absorbing = |block| {
            let mut p = shadow_scene(kind, beta, block);
            p.medium.albedo = 0.0;
            p
        };
        let (w, h) = (with.render.width, with.render.height);
        let (img_with, img_without) = (gpu_image(&absorbing(true)), gpu_image(&absorbing(false)));
        let light = &with.lights[0];
        let origin = with.camera.position.as_dvec3();
        let (mut in_shadow, mut lit, mut worst_shadow, mut worst_lit) = (0, 0, 0.0f64, 0.0f64);
        for py in 0..h {
            for px in 0..w {
                let dir = camera_ray64(&with.camera, px, py, w, h);
                let Some(hit) = with.surfaces.first_hit(origin, dir) else { continue };
                let x = origin + dir * hit.t;
                let blocked = |x: DVec3| match light.kind {
                    LightKind::Directional { direction } => {
                        shadowed(&with, x, hit.normal, -direction.as_dvec3().normalize(), f64::INFINITY)
                    }
                    _ => {
                        let to = light.position.as_dvec3() - x;
                        shadowed(&with, x, hit.normal, to.normalize(), to.length())
                    }
                };
                let around = [DVec3::ZERO, DVec3::X * 0.05, -DVec3::X * 0.05, DVec3::Z * 0.05, -DVec3::Z * 0.05];
                let states: Vec<bool> = around.iter().map(|o| blocked(x + *o)).collect();
                let i = (py * w + px) as usize;
                for c in 0..3 {
                    let diff = img_without[i][c] as f64 - img_with[i][c] as f64;
                    if states.iter().all(|s| *s) {
                        let want = expected_direct(&with, x, c);
                        assert!(want > 0.0);
                        let rel = (diff - want).abs() / want;
                        worst_shadow = worst_shadow.max(rel);
                        assert!(rel < 1e-3, "{kind:?} pixel ({px}, {py}): darker by {diff}, expected {want}");
                        in_shadow += 1;
                    } else if states.iter().all(|s| !*s) {
                        let rel = diff.abs() / (img_with[i][c] as f64).max(1e-12);
                        worst_lit = worst_lit.max(rel);
                        assert!(rel < 1e-5, "{kind:?} pixel ({px}, {py}) outside the shadow changed by {diff}");
                        lit += 1;
                    }
                }
            }
        }
        let reference = render_reference(&with, w, h, &RefRenderOptions::default());
        let image = fogsmith::gpu::Image { width: w, height: h, rgba: gpu_image(&with) };
        let err = image_error(&image, &reference);
        println!(
            "{kind:?}: {} shadowed and {} lit pixel channels; shadow depth rel error max {worst_shadow:.2e}, \
             lit change max {worst_lit:.2e}; image vs reference relative RMSE {:.4}",
            in_shadow, lit, err.rel_rmse
        );
        assert!(in_shadow > 60 && lit > 60, "the shadow must cross the picture");
        assert!(!err.nan_or_inf && err.rel_rmse < 0.02, "{kind:?}: {}", err.rel_rmse);
    }
}

/// Lights on a box's face and inside a box, for point and spot lights: no NaN, and the image
/// matches the reference (inside a box, the surfaces outside receive no direct light).
#[test]
fn lights_on_and_inside_boxes_stay_finite() {
    for position in [Vec3::new(0.0, 2.0, 0.0), Vec3::new(0.0, 2.1, 0.0), Vec3::new(0.3, 2.1, 0.0)] {
        for kind in
            [LightKind::Point, LightKind::Spot { direction: Vec3::new(0.0, -1.0, 0.0), angle_deg: 50.0, blend: 0.2 }]
        {
            let mut p = shadow_scene(kind, 0.1, true);
            p.lights[0].position = position;
            let img = gpu_image(&p);
            let reference = render_reference(&p, p.render.width, p.render.height, &RefRenderOptions::default());
            let image = fogsmith::gpu::Image { width: p.render.width, height: p.render.height, rgba: img };
            let err = image_error(&image, &reference);
            println!("light at {position} {kind:?}: relative RMSE {:.4}", err.rel_rmse);
            assert!(!err.nan_or_inf && err.rel_rmse < 0.03, "{position} {kind:?}: {}", err.rel_rmse);
        }
    }
}

/// A street lamp low over the road in thick fog, next to a block: the road and the block's
/// faces turned away from the lamp are lit by the fog's glow. Against the reference (which
/// evaluates the surface term exactly), pixels lit by the glow alone match within the table's
/// error (about 1 % at most, see the lib test glow_table_error_within_bilinear_bound) plus
/// the march's, which includes the block's shadow in the fog in front of those faces: the
/// march takes each step as lit or shadowed at its middle, so a shadow's edge costs up to half
/// a step's in-scattering there.
#[test]
fn fog_glow_on_surfaces_matches_reference() {
    let mut p = shadow_scene(LightKind::Point, 0.35, false);
    p.lights[0].position = Vec3::new(0.0, 0.6, 0.0);
    p.surfaces.boxes.push(SurfaceBox {
        min: Vec3::new(0.4, 0.0, -0.6),
        max: Vec3::new(0.9, 0.7, 0.2),
        albedo: Vec3::splat(0.7),
        ..SurfaceBox::default()
    });
    p.camera =
        Camera { position: Vec3::new(2.2, 1.0, 2.0), target: Vec3::new(0.3, 0.2, 0.0), up: Vec3::Y, fov_y_deg: 45.0 };
    let (w, h) = (p.render.width, p.render.height);
    let img = gpu_image(&p);
    let reference = render_reference(&p, w, h, &RefRenderOptions::default());
    let origin = p.camera.position.as_dvec3();
    let (mut glow_only, mut worst) = (0, 0.0f64);
    for py in 0..h {
        for px in 0..w {
            let dir = camera_ray64(&p.camera, px, py, w, h);
            let Some(hit) = p.surfaces.first_hit(origin, dir) else { continue };
            let x = origin + dir * hit.t;
            let to = p.lights[0].position.as_dvec3() - x;
            if hit.normal.dot(to) < 0.0 {
                let i = (py * w + px) as usize;
                for c in 0..3 {
                    assert!(reference[i][c] > 0.0);
                    let rel = (img[i][c] as f64 - reference[i][c]).abs() / reference[i][c];
                    worst = worst.max(rel);
                }
                glow_only += 1;
            }
        }
    }
    let image = fogsmith::gpu::Image { width: w, height: h, rgba: img };
    let err = image_error(&image, &reference);
    println!("street lamp: {glow_only} pixels on faces turned away, max relative error {worst:.4}; image relative RMSE {:.4}", err.rel_rmse);
    assert!(glow_only > 20, "{glow_only}");
    assert!(worst < 0.05, "{worst}");
    assert!(err.rel_rmse < 0.02, "{}", err.rel_rmse);
}

/// Uniform in [lo, hi), drawn in f64.
fn range(rng: &mut Lcg, lo: f64, hi: f64) -> f32 {
    (lo + (hi - lo) * rng.f64()) as f32
}

/// A Phong exponent, uniform in ln(1 + n) over [0, 1000].
fn exponent(rng: &mut Lcg) -> f32 {
    (1001f64.powf(rng.f64()) - 1.0) as f32
}

/// Phong-specular surfaces in homogeneous fog on random scenes: ground and a box with random
/// specular coefficients and exponents (0 and 1000, the ends, included), a point or spot
/// light, cameras from high to grazing. What the specular part adds to each pixel (the image
/// with it minus the image without, on the GPU and in the reference, which evaluates Sun et
/// al.'s S function exactly and the direct highlight in f64) must agree within the specular
/// table's bound, 2 % of the term's value with the light at the mirror direction (the lib test
/// specular_table_error_against_quadrature asserts it against quadrature over the sphere),
/// plus 2e-3 of the value for f32 rounding (cos^n amplifies the cosine's rounding n-fold).
/// Pixels next to an edge, a shadow's boundary, or a jump of the lobe (n = 0) are left out:
/// there f32 and f64 may see different surfaces.
#[test]
fn specular_surfaces_match_reference_on_random_scenes() {
    let mut rng = Lcg(0x5bec_0014);
    let (mut compared, mut worst, mut worst_rel) = (0usize, 0.0f64, 0.0f64);
    for case in 0..6 {
        let beta = range(&mut rng, 0.05, 0.6);
        let kind = if case % 2 == 0 {
            LightKind::Point
        } else {
            LightKind::Spot {
                direction: Vec3::new(range(&mut rng, -0.3, 0.3), -1.0, range(&mut rng, -0.3, 0.3)),
                angle_deg: 60.0,
                blend: 0.4,
            }
        };
        let mut p = shadow_scene(kind, beta, false);
        p.lights[0].position =
            Vec3::new(range(&mut rng, -1.0, 1.0), range(&mut rng, 0.2, 1.5), range(&mut rng, -1.0, 1.0));
        let (n_ground, n_box) = match case {
            0 => (0.0, 1000.0),
            1 => (1000.0, 0.0),
            _ => (exponent(&mut rng), exponent(&mut rng)),
        };
        let ground = p.surfaces.ground.as_mut().unwrap();
        ground.specular = range(&mut rng, 0.3, 1.0);
        ground.phong_exponent = n_ground;
        let a = Vec3::new(range(&mut rng, -1.2, 0.4), 0.0, range(&mut rng, -1.2, 0.0));
        p.surfaces.boxes.push(SurfaceBox {
            min: a,
            max: a + Vec3::new(range(&mut rng, 0.3, 0.8), range(&mut rng, 0.2, 0.9), range(&mut rng, 0.3, 0.8)),
            albedo: Vec3::splat(0.4),
            specular: range(&mut rng, 0.3, 1.0),
            phong_exponent: n_box,
        });
        // From high above to grazing the ground (the last cases).
        let height = if case >= 4 { range(&mut rng, 0.02, 0.08) } else { range(&mut rng, 0.5, 2.5) };
        let azimuth = range(&mut rng, 0.0, std::f64::consts::TAU);
        p.camera = Camera {
            position: Vec3::new(3.0 * azimuth.cos(), height, 3.0 * azimuth.sin()),
            target: Vec3::new(0.0, if case >= 4 { height * 0.5 } else { 0.0 }, 0.0),
            up: Vec3::Y,
            fov_y_deg: 50.0,
        };
        p.render.width = 40;
        p.render.height = 30;
        let mut matte = p.clone();
        matte.surfaces.ground.as_mut().unwrap().specular = 0.0;
        matte.surfaces.boxes[0].specular = 0.0;
        let (w, h) = (p.render.width, p.render.height);
        let opts = RefRenderOptions::default();
        let (gpu_spec, gpu_matte) = (gpu_image(&p), gpu_image(&matte));
        let (ref_spec, ref_matte) = (render_reference(&p, w, h, &opts), render_reference(&matte, w, h, &opts));
        let origin = p.camera.position.as_dvec3();
        let light = &p.lights[0];
        let s = light.position.as_dvec3();
        let key = |px: u32, py: u32| {
            let dir = camera_ray64(&p.camera, px, py, w, h);
            p.surfaces.first_hit(origin, dir).map(|hit| {
                let x = origin + dir * hit.t;
                let to = s - x;
                let lit = !shadowed(&p, x, hit.normal, to.normalize(), to.length());
                (hit.normal.to_array().map(|v| v as i8), (hit.specular * 1e6) as i64, lit)
            })
        };
        let (mut case_n, mut case_worst) = (0, 0.0f64);
        for py in 1..h - 1 {
            for px in 1..w - 1 {
                let here = key(px, py);
                let Some(_) = here else { continue };
                if [(px - 1, py), (px + 1, py), (px, py - 1), (px, py + 1)].iter().any(|(x, y)| key(*x, *y) != here) {
                    continue;
                }
                let dir = camera_ray64(&p.camera, px, py, w, h);
                let hit = p.surfaces.first_hit(origin, dir).unwrap();
                let x = origin + dir * hit.t;
                let to = s - x;
                let d = to.length();
                let mirror = dir - 2.0 * dir.dot(hit.normal) * hit.normal;
                let cos_i = hit.normal.dot(to / d);
                if cos_i.abs() < 0.02 || (hit.phong_exponent < 1.0 && mirror.dot(to / d).abs() < 0.02) {
                    continue;
                }
                let view = (-(beta as f64) * hit.t).exp();
                let mirror_value = fogsmith::surface_table::spec_radiance(
                    beta as f64,
                    d,
                    0.0,
                    hit.phong_exponent,
                    fogsmith::surface_table::s_exact,
                );
                let i = (py * w + px) as usize;
                for c in 0..3 {
                    let scale =
                        view * hit.specular * light.radiance_rgb().as_dvec3()[c] * light.cone_factor(x) * mirror_value;
                    let got = gpu_spec[i][c] as f64 - gpu_matte[i][c] as f64;
                    let want = ref_spec[i][c] - ref_matte[i][c];
                    let err = (got - want).abs();
                    let bound = 0.02 * scale + 2e-3 * want.abs() + 1e-6 * ref_spec[i][c];
                    assert!(
                        err <= bound,
                        "case {case} pixel ({px}, {py}) n {}: specular part {got} vs {want}, error {err:.3e} > bound {bound:.3e}",
                        hit.phong_exponent
                    );
                    case_worst = case_worst.max(err / bound);
                    if want > 0.05 * scale {
                        worst_rel = worst_rel.max(err / want);
                    }
                    case_n += 1;
                }
            }
        }
        println!("case {case}: β {beta:.3}, exponents {n_ground:.1} / {n_box:.1}, {case_n} pixel channels, max error / bound {case_worst:.3}");
        assert!(case_n > 300, "case {case}: only {case_n} pixel channels compared");
        compared += case_n;
        worst = worst.max(case_worst);
    }
    println!("specular surfaces: {compared} pixel channels, max error / bound {worst:.3}, max relative error {worst_rel:.2e} (term > 5 % of the mirror value)");
}

/// A surface's specular coefficient and exponent: refused when negative, NaN or out of range,
/// with the field named; absent in an older project, they default to a matte surface.
#[test]
fn specular_fields_default_and_are_validated() {
    let p = Project {
        surfaces: ron::from_str("(ground: Some((height: 0.0)), boxes: [(min: (0, 0, 0), max: (1, 1, 1))])").unwrap(),
        ..Project::default()
    };
    assert_eq!(p.surfaces.ground.unwrap().specular, 0.0);
    assert_eq!(p.surfaces.boxes[0].specular, 0.0);
    p.validate(1024).unwrap();
    assert!(!ron::to_string(&p).unwrap().contains("specular"), "a matte surface saves as before");
    for (specular, exponent, field) in [
        (-0.1, 32.0, "surfaces.ground.specular"),
        (f32::NAN, 32.0, "surfaces.ground.specular"),
        (1.5, 32.0, "surfaces.ground.specular"),
        (0.5, -1.0, "surfaces.ground.phong_exponent"),
        (0.5, f32::NAN, "surfaces.ground.phong_exponent"),
        (0.5, 1e4, "surfaces.ground.phong_exponent"),
    ] {
        let mut q = p.clone();
        let g = q.surfaces.ground.as_mut().unwrap();
        g.specular = specular;
        g.phong_exponent = exponent;
        let e = q.validate(1024).unwrap_err();
        assert_eq!(e.field, field, "{e}");
        let mut q = p.clone();
        q.surfaces.boxes[0].specular = specular;
        q.surfaces.boxes[0].phong_exponent = exponent;
        let e = q.validate(1024).unwrap_err();
        assert_eq!(e.field, field.replace("ground", "boxes[0]"), "{e}");
    }
}

/// Specular surfaces never give NaN: lights on the ground and on a box's face, cameras
/// grazing the ground and looking straight down (the light at the mirror direction), for the
/// exponent's ends, in thin and thick fog and without fog.
#[test]
fn specular_surfaces_never_give_nan() {
    let mut gpu = pipeline();
    for beta in [0.0f32, 0.3, 5.0] {
        for exponent in [0.0f32, 1e-3, 1.0, 1000.0] {
            for (light, camera) in [
                (Vec3::new(0.0, 0.0, 0.0), Vec3::new(2.0, 1e-4, 0.0)),
                (Vec3::new(0.3, 2.0, 0.0), Vec3::new(-0.3, 2.0, 0.0)),
                (Vec3::new(0.0, 1.0, 0.0), Vec3::new(0.0, 1.0, 1e-3)),
            ] {
                let mut p = shadow_scene(LightKind::Point, beta, true);
                p.lights[0].position = light;
                p.camera.position = camera;
                p.camera.target = Vec3::new(0.0, 0.0, 0.01);
                let g = p.surfaces.ground.as_mut().unwrap();
                g.specular = 1.0;
                g.phong_exponent = exponent;
                p.surfaces.boxes[0].specular = 0.5;
                p.surfaces.boxes[0].phong_exponent = exponent;
                p.render.width = 24;
                p.render.height = 18;
                gpu.update(&p, &FrameRequest::for_project(&p)).unwrap();
                let image = gpu.read_image().unwrap();
                assert!(
                    image.rgba.iter().flatten().all(|v| v.is_finite() && *v >= 0.0),
                    "β {beta} n {exponent} light {light} camera {camera}: NaN, infinity or negative"
                );
            }
        }
    }
}

/// Camera rays parallel to the faces of the grid box and of a surface box, starting on their
/// planes (odd image sizes put the centre row and column exactly along the axes): the slab
/// tests must not meet 0·∞, so the image holds no NaN and is not black.
#[test]
fn rays_along_box_faces_give_no_nan() {
    let mut gpu = pipeline();
    for beta in [0.0f32, 0.4] {
        let mut p = shadow_scene(LightKind::Point, beta, false);
        p.surfaces.boxes.push(SurfaceBox {
            min: Vec3::new(-1.0, 0.5, 0.0),
            max: Vec3::new(-0.5, 1.0, 0.5),
            albedo: Vec3::splat(0.5),
            ..SurfaceBox::default()
        });
        p.camera = Camera {
            position: Vec3::new(-1.0, 0.5, -3.0),
            target: Vec3::new(-1.0, 0.5, 0.0),
            up: Vec3::Y,
            fov_y_deg: 40.0,
        };
        p.render.width = 25;
        p.render.height = 19;
        gpu.update(&p, &FrameRequest::for_project(&p)).unwrap();
        let image = gpu.read_image().unwrap();
        assert!(image.rgba.iter().flatten().all(|v| v.is_finite() && *v >= 0.0), "β {beta}: NaN, infinity or negative");
        assert!(image.rgba.iter().any(|v| v[0] > 0.0), "β {beta}: the image is black");
    }
}

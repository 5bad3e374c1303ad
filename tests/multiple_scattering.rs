//! Multiple scattering (src/gpu/scattering.rs) on the real pipeline: what it must never do
//! (add light without albedo, NaN, create energy), what it must do (add light, converge as
//! orders and resolution grow), and that files without the setting render as before. The
//! comparison with a path tracer's all orders is in tests/mitsuba_reference.rs.

mod common;

use common::scenes::pipeline;
use common::Rng;
use fogsmith::gpu::{FogPipeline, FrameRequest, Image};
use fogsmith::scene::{
    Camera, GridSpec, Ground, Light, LightKind, Medium, MultipleScattering, Particle, Project, Surfaces,
};
use glam::{UVec3, Vec3};

/// A blob of optical depth about `depth` through its centre in a 2 m box at `res`³, lit by a
/// point light outside it, seen from the front.
fn blob(res: u32, depth: f32, albedo: f32, g: f32) -> Project {
    let radius = 0.35;
    // A gaussian of peak σ and standard deviation r has optical depth σ·r·√(2π) through its centre.
    let density = depth / (radius * (2.0 * std::f32::consts::PI).sqrt());
    let mut p = Project {
        grid: GridSpec { min: Vec3::splat(-1.0), max: Vec3::splat(1.0), resolution: UVec3::splat(res) },
        medium: Medium { albedo, anisotropy: g, ..Medium::default() },
        particles: vec![Particle::new(Vec3::ZERO, radius, density)],
        lights: vec![Light::new(Vec3::new(1.6, 0.9, 0.7), 6.0, Vec3::new(1.0, 0.9, 0.8))],
        ..Project::default()
    };
    p.camera = Camera { position: Vec3::new(0.4, 0.5, 4.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 40.0 };
    p.render.width = 48;
    p.render.height = 32;
    p
}

fn with_ms(mut p: Project, ms: MultipleScattering) -> Project {
    p.medium.multiple_scattering = Some(ms);
    p
}

fn render(pipeline: &mut FogPipeline, p: &Project) -> Image {
    pipeline.update(p, &FrameRequest { force: true, ..FrameRequest::for_project(p) }).expect("update");
    let image = pipeline.read_image().expect("read image");
    assert!(
        image.rgba.iter().all(|p| p[..3].iter().all(|v| v.is_finite() && *v >= 0.0)),
        "a pixel is negative or not finite"
    );
    image
}

fn mean(image: &Image) -> f64 {
    image.rgba.iter().map(|p| (p[0] + p[1] + p[2]) as f64 / 3.0).sum::<f64>() / image.rgba.len() as f64
}

/// Without albedo, or at strength 0, the setting adds nothing: the image is bit for bit the
/// single-scattering one (a lit ground behind the fog keeps it from being black).
#[test]
fn no_albedo_or_no_strength_adds_nothing() {
    let mut pipeline = pipeline();
    for (albedo, strength) in [(0.0, 1.0), (0.9, 0.0)] {
        let mut p = blob(24, 3.0, albedo, 0.3);
        p.surfaces = Surfaces { ground: Some(Ground { height: -0.9, ..Ground::default() }), ..Surfaces::default() };
        let single = render(&mut pipeline, &p);
        let multiple = render(&mut pipeline, &with_ms(p, MultipleScattering { strength, ..Default::default() }));
        assert_eq!(single.rgba, multiple.rgba, "albedo {albedo}, strength {strength}: the image changed");
        assert!(mean(&single) > 0.0, "the ground is not lit: the test shows nothing");
    }
}

/// Every order's power is finite and non-negative, each order scatters no more power than the
/// one before (with albedo 1 nothing is absorbed, so more would be light created), and the
/// image is finite, at the extremes of optical depth, albedo and anisotropy, for every light
/// kind.
#[test]
fn orders_lose_power_and_stay_finite_at_the_extremes() {
    let mut pipeline = pipeline();
    let orders = 12;
    let mut created = Vec::new();
    for depth in [0.0, 0.01, 5.0, 100.0] {
        for albedo in [0.3, 1.0] {
            for g in [-0.95, 0.0, 0.95] {
                for kind in 0..3 {
                    let mut p = blob(20, depth, albedo, g);
                    let at = p.lights[0].position;
                    match kind {
                        1 => p.lights[0].kind = LightKind::Directional { direction: -at.normalize() },
                        2 => {
                            p.lights[0].kind =
                                LightKind::Spot { direction: -at.normalize(), angle_deg: 20.0, blend: 0.1 }
                        }
                        _ => p.lights[0].position = Vec3::new(0.1, 0.0, 0.05),
                    }
                    let p = with_ms(p, MultipleScattering { orders, ..Default::default() });
                    let single = mean(&render(
                        &mut pipeline,
                        &with_ms(p.clone(), MultipleScattering { strength: 0.0, ..Default::default() }),
                    ));
                    let image = render(&mut pipeline, &p);
                    let what = format!("depth {depth}, albedo {albedo}, g {g}, light kind {kind}");
                    let powers = pipeline.scatter_powers(orders).expect("powers");
                    assert!(powers.iter().all(|w| w.is_finite() && *w >= 0.0), "{what}: powers {powers:?}");
                    let worst = (1..powers.len()).map(|k| powers[k] / powers[k - 1].max(1e-30)).fold(0.0f32, f32::max);
                    if worst > 1.0001 {
                        created.push(format!(
                            "{what}: an order scatters {worst} times the power of the one before: {powers:?}"
                        ));
                    }
                    if depth == 0.0 {
                        assert!(powers.iter().all(|w| *w == 0.0), "{what}: light scattered in empty space");
                    }
                    assert!(mean(&image) >= single * 0.99999, "{what}: multiple scattering darkened the image");
                }
            }
        }
    }
    assert!(created.is_empty(), "light created: {created:#?}");
}

/// Bright fog gains light: at albedo 1 and optical depth 5 the added orders are a large part of
/// the image (the path tracer's all orders give about twice single scattering there), and they
/// are fewer in absorbing fog.
#[test]
fn bright_fog_gains_more_than_dark_fog() {
    let mut pipeline = pipeline();
    let gain = |pipeline: &mut FogPipeline, albedo: f32| {
        let p = blob(32, 5.0, albedo, 0.2);
        let single = mean(&render(pipeline, &p));
        let multiple = mean(&render(pipeline, &with_ms(p, MultipleScattering::default())));
        multiple / single
    };
    let bright = gain(&mut pipeline, 1.0);
    let dark = gain(&mut pipeline, 0.5);
    println!("all orders / single scattering: albedo 1 {bright:.3}, albedo 0.5 {dark:.3}");
    assert!(bright > 1.3, "albedo 1 gains only {bright}");
    assert!(dark > 1.0 && dark < bright, "albedo 0.5 gains {dark}, albedo 1 {bright}");
}

/// The solution converges: more orders change the image less and less (the tail stands for
/// the rest), and a finer coarse grid changes it little, on randomized scenes.
#[test]
fn converges_in_orders_and_resolution() {
    let mut pipeline = pipeline();
    let mut rng = Rng(0x0dd_5ca7);
    for n in 0..3 {
        let depth = rng.range(2.0, 15.0);
        let mut p = blob(48, depth, rng.range(0.7, 1.0), rng.range(-0.3, 0.8));
        p.particles[0].center = rng.vec3(-0.2, 0.2);
        p.lights[0].position = rng.direction() * 1.7;
        let image = |pipeline: &mut FogPipeline, orders: u32, resolution: u32| {
            let ms = MultipleScattering { orders, resolution, ..Default::default() };
            mean(&render(pipeline, &with_ms(p.clone(), ms)))
        };
        let single = mean(&render(&mut pipeline, &p));
        let [o4, o8, o32] = [4, 8, 32].map(|o| image(&mut pipeline, o, 24));
        let [r12, r24, r48] = [12, 24, 48].map(|r| image(&mut pipeline, 8, r));
        let added = |v: f64| v - single;
        println!(
            "scene {n} (depth {depth:.1}): added light by orders 4/8/32 {:.4e} {:.4e} {:.4e}; by resolution 12/24/48 {:.4e} {:.4e} {:.4e}",
            added(o4),
            added(o8),
            added(o32),
            added(r12),
            added(r24),
            added(r48)
        );
        let rel = |a: f64, b: f64| (a - b).abs() / b.abs().max(1e-30);
        assert!(rel(added(o8), added(o32)) < 0.05, "scene {n}: 8 orders are {} off 32", rel(added(o8), added(o32)));
        assert!(
            rel(added(o8), added(o32)) <= rel(added(o4), added(o32)) + 1e-3,
            "scene {n}: 8 orders are further from 32 than 4 are"
        );
        assert!(
            rel(added(r24), added(r48)) < 0.1,
            "scene {n}: resolution 24 is {} off 48",
            rel(added(r24), added(r48))
        );
    }
}

/// A file without the setting renders single scattering; `medium.multiple_scattering` round-trips
/// through RON with its defaults filled in, and bad values are refused by name.
#[test]
fn the_setting_loads_saves_and_validates() {
    let p = blob(16, 2.0, 0.9, 0.0);
    let text = ron::ser::to_string_pretty(&p, Default::default()).unwrap();
    assert!(!text.contains("multiple_scattering"), "an unset field is written");
    let on = with_ms(p.clone(), MultipleScattering { orders: 5, ..Default::default() });
    let text = ron::ser::to_string_pretty(&on, Default::default()).unwrap();
    let back = fogsmith::scene::parse_project(&text, std::path::Path::new("ms.ron")).unwrap();
    assert_eq!(back.medium.multiple_scattering, on.medium.multiple_scattering);
    let partial = text.replace("orders: 5,", "");
    let back = fogsmith::scene::parse_project(&partial, std::path::Path::new("ms.ron")).unwrap();
    assert_eq!(back.medium.multiple_scattering, Some(MultipleScattering::default()));
    for (field, ms) in [
        ("orders", MultipleScattering { orders: 0, ..Default::default() }),
        ("strength", MultipleScattering { strength: f32::NAN, ..Default::default() }),
        ("resolution", MultipleScattering { resolution: 1000, ..Default::default() }),
    ] {
        let bad = with_ms(p.clone(), ms);
        let e = bad.validate(512).expect_err(field).to_string();
        assert!(e.contains(&format!("medium.multiple_scattering.{field}")), "{field}: {e}");
    }
    assert!(Project::new_empty().medium.multiple_scattering.is_some(), "new projects are single scattering");
}

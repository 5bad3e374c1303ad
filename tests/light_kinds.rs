//! The project model of light kinds, height fog and noise: defaults that keep older files
//! loading unchanged, RON round trips, the cone factor, and clear errors on bad values.

mod common;

use fogsmith::scene::io::to_ron_string;
use fogsmith::scene::{cone_factor, parse_project, Light, LightKind, Noise, Project};
use glam::{DVec3, Vec3};
use std::path::Path;

fn parse(text: &str) -> Result<Project, String> {
    parse_project(text, Path::new("test.ron")).map_err(|e| e.to_string())
}

#[test]
fn files_without_the_new_fields_load_as_before() {
    let p = parse("Project(version: 1, medium: (base_extinction: 0.1), lights: [(position: (0, 1, 0), intensity: 3)])")
        .unwrap();
    assert_eq!(p.lights[0].kind, LightKind::Point);
    assert_eq!(p.medium.height_falloff, 0.0);
    assert_eq!(p.medium.height_origin, 0.0);
    assert_eq!(p.medium.noise, None);
    // Nothing new is written for a project that does not use it.
    let text = to_ron_string(&p).unwrap();
    for word in ["kind", "height_falloff", "height_origin", "noise"] {
        assert!(!text.contains(word), "{word} written for a default project:\n{text}");
    }
    for demo in ["cloud", "cornell", "street", "room"] {
        let path = common::root().join("projects").join(format!("{demo}.ron"));
        fogsmith::scene::load_project(&path).unwrap_or_else(|e| panic!("{demo}: {e}"));
    }
}

#[test]
fn new_fields_round_trip_in_the_documented_syntax() {
    let text = "Project(version: 1,
        medium: (base_extinction: 0.1, height_falloff: 0.5, height_origin: -1),
        lights: [
            (position: (0, 3, 0), intensity: 30, kind: Spot(direction: (0, -1, 0), angle_deg: 25, blend: 0.2)),
            (position: (0, 0, 0), intensity: 2, kind: Directional(direction: (1, -1, 0))),
            (position: (1, 1, 1), intensity: 1, kind: Point),
        ])";
    let p = parse(text).unwrap();
    assert_eq!(p.lights[0].kind, LightKind::Spot { direction: Vec3::new(0.0, -1.0, 0.0), angle_deg: 25.0, blend: 0.2 });
    assert_eq!(p.lights[1].kind, LightKind::Directional { direction: Vec3::new(1.0, -1.0, 0.0) });
    assert_eq!(p.lights[2].kind, LightKind::Point);
    // Noise parses in the documented syntax and round-trips; a particle's noise flag is
    // written only when it is off.
    let q = parse("Project(version: 1, medium: (noise: Some((0.8, 1.5, 4, 7))), particles: [(center: (0, 0, 0), radius: 1, density: 1), (center: (0, 0, 0), radius: 1, density: 1, noise: false)])").unwrap();
    assert_eq!(q.medium.noise, Some(Noise::new(0.8, 1.5, 4, 7)));
    assert!(q.particles[0].noise && !q.particles[1].noise);
    let text = to_ron_string(&q).unwrap();
    assert_eq!(text.matches("noise").count(), 2, "{text}");
    assert_eq!(parse(&text).unwrap(), q);
    let n: Noise = ron::from_str("(0.8, 1.5, 4, 7)").unwrap();
    assert_eq!(n, Noise::new(0.8, 1.5, 4, 7));
    assert_eq!(p.medium.height_falloff, 0.5);
    let again = parse(&to_ron_string(&p).unwrap()).unwrap();
    assert_eq!(again, p);
}

/// physics.md §9: 1 within A(1 − B), 0 beyond A, t²(3 − 2t) between.
#[test]
fn cone_factor_follows_its_definition() {
    let axis = DVec3::new(0.0, 0.0, 2.0);
    let at = |deg: f64| DVec3::new(deg.to_radians().sin(), 0.0, deg.to_radians().cos()) * 3.0;
    let (a, b) = (30.0, 0.4);
    assert_eq!(cone_factor(axis, a, b, at(0.0)), 1.0);
    assert_eq!(cone_factor(axis, a, b, at(a * (1.0 - b) - 1e-6)), 1.0);
    assert_eq!(cone_factor(axis, a, b, at(a + 1e-6)), 0.0);
    assert_eq!(cone_factor(axis, a, b, at(120.0)), 0.0);
    for deg in [18.5, 21.0, 24.0, 27.0, 29.5] {
        let t = (a - deg) / (a * b);
        let want = t * t * (3.0 - 2.0 * t);
        assert!((cone_factor(axis, a, b, at(deg)) - want).abs() < 1e-9, "{deg}°");
    }
    // A hard edge.
    assert_eq!(cone_factor(axis, a, 0.0, at(29.9)), 1.0);
    assert_eq!(cone_factor(axis, a, 0.0, at(30.1)), 0.0);
    assert_eq!(cone_factor(axis, 90.0, 0.0, at(89.0)), 1.0);
}

#[test]
fn spots_know_whether_they_reach_a_box() {
    let (min, max) = (Vec3::splat(-1.0), Vec3::splat(1.0));
    let mut l = Light::new(Vec3::new(0.0, 3.0, 0.0), 1.0, Vec3::ONE);
    l.kind = LightKind::Spot { direction: Vec3::Y, angle_deg: 30.0, blend: 0.0 };
    assert!(!l.reaches_box(min, max), "aimed away");
    l.kind = LightKind::Spot { direction: -Vec3::Y, angle_deg: 5.0, blend: 0.0 };
    assert!(l.reaches_box(min, max), "aimed at it");
    l.kind = LightKind::Spot { direction: Vec3::X, angle_deg: 20.0, blend: 0.5 };
    assert!(!l.reaches_box(min, max), "aimed past it");
    l.kind = LightKind::Spot { direction: Vec3::X, angle_deg: 90.0, blend: 0.5 };
    assert!(l.reaches_box(min, max), "a half-space cone");
    l.position = Vec3::ZERO;
    l.kind = LightKind::Spot { direction: Vec3::X, angle_deg: 1.0, blend: 0.0 };
    assert!(l.reaches_box(min, max), "inside the box");
    l.kind = LightKind::Point;
    l.position = Vec3::splat(100.0);
    assert!(l.reaches_box(min, max));
    // Never a false "misses" for random spots: sample each cone and check no sample lands in the box.
    let mut rng = common::Rng(0x1234_5678);
    let mut next = || rng.f64();
    for _ in 0..300 {
        let pos = Vec3::new(next() as f32 * 8.0 - 4.0, next() as f32 * 8.0 - 4.0, next() as f32 * 8.0 - 4.0);
        let dir = Vec3::new(next() as f32 - 0.5, next() as f32 - 0.5, next() as f32 - 0.5);
        let angle = 1.0 + 89.0 * next() as f32;
        let mut l = Light::new(pos, 1.0, Vec3::ONE);
        l.kind = LightKind::Spot { direction: dir, angle_deg: angle, blend: 0.0 };
        if l.reaches_box(min, max) {
            continue;
        }
        for _ in 0..400 {
            let x = DVec3::new(next() * 2.0 - 1.0, next() * 2.0 - 1.0, next() * 2.0 - 1.0);
            assert_eq!(l.cone_factor(x), 0.0, "{pos} {dir} {angle}: said to miss but lights {x}");
        }
    }
}

#[test]
fn bad_values_get_clear_errors() {
    let cases = [
        ("kind: Spot(direction: (0, 0, 0), angle_deg: 20, blend: 0.1)", "lights[0].kind.direction", "non-zero"),
        ("kind: Directional(direction: (0, 0, 0))", "lights[0].kind.direction", "non-zero"),
        ("kind: Spot(direction: (0, -1, 0), angle_deg: 0, blend: 0.1)", "lights[0].kind.angle_deg", "(0, 90]"),
        ("kind: Spot(direction: (0, -1, 0), angle_deg: 95, blend: 0.1)", "lights[0].kind.angle_deg", "(0, 90]"),
        ("kind: Spot(direction: (0, -1, 0), angle_deg: 30, blend: 1.5)", "lights[0].kind.blend", "[0, 1]"),
        ("kind: Spot(direction: (0, -1, 0), angle_deg: 30, blend: -0.1)", "lights[0].kind.blend", "[0, 1]"),
    ];
    for (kind, field, hint) in cases {
        let text = format!("Project(version: 1, lights: [(position: (0, 1, 0), intensity: 3, {kind})])");
        let e = parse(&text).unwrap_err();
        assert!(e.contains(field) && e.contains(hint), "{kind}: {e}");
    }
    let media = [
        ("height_falloff: -0.5", "medium.height_falloff", "≥ 0"),
        ("height_falloff: 1e9", "medium.height_falloff", "at most"),
        ("height_origin: 1e12", "medium.height_origin", "within"),
        ("noise: Some((-1, 1, 3, 0))", "medium.noise.amplitude", "within"),
        ("noise: Some((0.5, 0, 3, 0))", "medium.noise.frequency", "within"),
        ("noise: Some((0.5, 1, 0, 0))", "medium.noise.octaves", "1..="),
        ("noise: Some((0.5, 1, 40, 0))", "medium.noise.octaves", "1..="),
    ];
    for (field_text, field, hint) in media {
        let e = parse(&format!("Project(version: 1, medium: ({field_text}))")).unwrap_err();
        assert!(e.contains(field) && e.contains(hint), "{field_text}: {e}");
    }
    let e = parse("Project(version: 1, lights: [(position: (0, 1, 0), intensity: 3, kind: Cone)])").unwrap_err();
    assert!(e.contains("Cone") || e.contains("variant"), "{e}");
}

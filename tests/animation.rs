//! Time in a project: interpolation against hand-computed values, holding outside the keys,
//! `Project::at_frame`, the key-editing API, deleting animated objects, and every
//! validation error of the animation with the track and key it names.

mod common;

use fogsmith::scene::{
    parse_project, Animation, Channel, Interp, Key, KeyValue, LightKind, Noise, Object, Particle, Project, Prop, Track,
};
use glam::Vec3;
use std::path::Path;

fn float(track: &Track, frame: i32) -> f32 {
    match track.sample(frame) {
        Some(KeyValue::Float(v)) => v,
        other => panic!("{other:?}"),
    }
}

fn keys(on: Channel, keys: &[(i32, KeyValue, Interp)]) -> Track {
    Track { on, keys: keys.iter().map(|&(frame, value, interp)| Key { frame, value, interp }).collect() }
}

const RADIUS: Channel = Channel(Object::Particle(0), Prop::Radius);

#[test]
fn linear_hold_and_smooth_against_hand_computed_values() {
    use KeyValue::Float as F;
    // Keys 10 → 20 (linear), 20 → 30 (smooth), 30 → 40 (hold).
    let t = keys(
        RADIUS,
        &[
            (10, F(1.0), Interp::Linear),
            (20, F(3.0), Interp::Smooth),
            (30, F(1.0), Interp::Hold),
            (40, F(5.0), Interp::Linear),
        ],
    );
    // At the keys: the keys' values.
    for (f, v) in [(10, 1.0), (20, 3.0), (30, 1.0), (40, 5.0)] {
        assert_eq!(float(&t, f), v, "frame {f}");
    }
    // Linear: 1 + 2·u.
    assert_eq!(float(&t, 15), 2.0);
    assert!((float(&t, 12) - 1.4).abs() < 1e-6);
    // Smooth: 3 − 2·(3u² − 2u³); u = 0.25: 0.15625 → 2.6875; u = 0.5: 2.0.
    assert!((float(&t, 22) - (3.0 - 2.0 * (3.0 * 0.04 - 2.0 * 0.008))).abs() < 1e-6, "{}", float(&t, 22));
    assert_eq!(float(&t, 25), 2.0);
    assert!((float(&t, 27) - (3.0 - 2.0 * (3.0 * 0.49 - 2.0 * 0.343))).abs() < 1e-6);
    // Hold: the key's value until the next key.
    assert_eq!(float(&t, 31), 1.0);
    assert_eq!(float(&t, 39), 1.0);
    // Outside the keys the value holds.
    assert_eq!(float(&t, -100), 1.0);
    assert_eq!(float(&t, 9), 1.0);
    assert_eq!(float(&t, 41), 5.0);
    assert_eq!(float(&t, 10_000), 5.0);
}

/// Smooth's slope at its keys is zero (the one-frame differences next to a key are second
/// order in the step), where linear's is not; between, it is steeper than linear.
#[test]
fn smooth_has_zero_slope_at_the_keys() {
    use KeyValue::Float as F;
    let smooth = keys(RADIUS, &[(0, F(0.0), Interp::Smooth), (1000, F(1000.0), Interp::Linear)]);
    let linear = keys(RADIUS, &[(0, F(0.0), Interp::Linear), (1000, F(1000.0), Interp::Linear)]);
    // u = 0.001: 3u² − 2u³ ≈ 3e-6, so the value moved by ≈ 0.003 (linear: 1).
    let step_after = float(&smooth, 1) - float(&smooth, 0);
    let step_before = float(&smooth, 1000) - float(&smooth, 999);
    assert!(step_after.abs() < 0.004 && step_before.abs() < 0.004, "{step_after} {step_before}");
    assert_eq!(float(&linear, 1) - float(&linear, 0), 1.0);
    // Mid-way the slope is 1.5 × linear's.
    assert!((float(&smooth, 501) - float(&smooth, 500) - 1.5).abs() < 0.01);
    // Never outside the keys' values.
    assert!((0..=1000).all(|f| (0.0..=1000.0).contains(&float(&smooth, f))));
}

#[test]
fn vectors_bools_and_directions() {
    let center = Channel(Object::Particle(0), Prop::Center);
    let t = keys(
        center,
        &[
            (0, KeyValue::Vec3(Vec3::new(0.0, 2.0, -4.0)), Interp::Linear),
            (4, KeyValue::Vec3(Vec3::new(4.0, 2.0, 4.0)), Interp::Linear),
        ],
    );
    assert_eq!(t.sample(1), Some(KeyValue::Vec3(Vec3::new(1.0, 2.0, -2.0))));
    let hidden = keys(
        Channel(Object::Particle(0), Prop::Hidden),
        &[(0, KeyValue::Bool(false), Interp::Smooth), (10, KeyValue::Bool(true), Interp::Linear)],
    );
    assert_eq!(hidden.sample(9), Some(KeyValue::Bool(false)), "booleans step at the next key");
    assert_eq!(hidden.sample(10), Some(KeyValue::Bool(true)));
    // Directions are re-normalised; through zero the earlier key's direction stays.
    let dir = Channel(Object::Light(0), Prop::SunDirection);
    let t =
        keys(dir, &[(0, KeyValue::Vec3(Vec3::X), Interp::Linear), (2, KeyValue::Vec3(Vec3::Y * 3.0), Interp::Linear)]);
    let KeyValue::Vec3(v) = t.sample(1).unwrap() else { panic!() };
    assert!((v - Vec3::new(0.5, 1.5, 0.0).normalize()).length() < 1e-6, "{v}");
    let t = keys(dir, &[(0, KeyValue::Vec3(Vec3::X), Interp::Linear), (2, KeyValue::Vec3(-Vec3::X), Interp::Linear)]);
    assert_eq!(t.sample(1), Some(KeyValue::Vec3(Vec3::X)));
}

fn animated() -> Project {
    let mut p = Project {
        particles: vec![Particle::new(Vec3::new(0.0, 1.0, 0.0), 0.5, 2.0), Particle::new(Vec3::ONE, 0.3, 1.0)],
        lights: vec![fogsmith::scene::Light::new(Vec3::new(1.0, 2.0, 0.0), 5.0, Vec3::ONE)],
        ..Project::default()
    };
    p.ensure_unique_ids();
    p.lights[0].kind = LightKind::Spot { direction: -Vec3::Y, angle_deg: 30.0, blend: 0.2 };
    p.medium.noise = Some(Noise { velocity: Vec3::new(0.5, 0.0, -2.0), ..Noise::new(1.0, 2.0, 3, 4) });
    p
}

#[test]
fn at_frame_applies_every_track_and_drifts_the_noise() {
    let mut p = animated();
    assert_eq!(p.at_frame(7), p, "a project without animation is its own still");
    p.animation = Some(Animation { fps: 24.0, start: 1, end: 48 });
    let c = |o, v| Channel(o, v);
    p.set_key(c(Object::Particle(1), Prop::Density), 1, KeyValue::Float(1.0), Interp::Linear).unwrap();
    p.set_key(c(Object::Particle(1), Prop::Density), 11, KeyValue::Float(3.0), Interp::Linear).unwrap();
    p.set_key(c(Object::Light(0), Prop::AngleDeg), 1, KeyValue::Float(20.0), Interp::Linear).unwrap();
    p.set_key(c(Object::Light(0), Prop::AngleDeg), 21, KeyValue::Float(40.0), Interp::Linear).unwrap();
    p.set_key(c(Object::Camera, Prop::Target), 5, KeyValue::Vec3(Vec3::ZERO), Interp::Hold).unwrap();
    p.set_key(c(Object::Medium, Prop::NoiseAmplitude), 1, KeyValue::Float(0.5), Interp::Hold).unwrap();
    p.validate(4096).unwrap();
    let still = p.at_frame(6);
    assert_eq!(still.animation, None);
    assert!(still.tracks.is_empty(), "the pipeline sees a plain still");
    assert_eq!(still.particles[1].density, 2.0);
    assert_eq!(still.particles[0], p.particles[0], "unkeyed values are untouched");
    assert_eq!(still.lights[0].kind, LightKind::Spot { direction: -Vec3::Y, angle_deg: 25.0, blend: 0.2 });
    assert_eq!(still.camera.target, Vec3::ZERO);
    let noise = still.medium.noise.unwrap();
    assert_eq!(noise.amplitude, 0.5);
    assert_eq!(noise.offset, Vec3::new(0.5, 0.0, -2.0) * (6.0f64 / 24.0) as f32);
    assert_eq!(noise.offset, Vec3::new(0.125, 0.0, -0.5));
    assert_eq!(still.at_frame(30), still, "a still of a still is itself");
    let a = p.animation.unwrap();
    assert_eq!(a.time(36), 1.5);
    assert_eq!(a.frames(), 1..=48);
}

#[test]
fn editing_keys() {
    let mut p = animated();
    let density = Channel(Object::Particle(0), Prop::Density);
    assert_eq!(p.animatable(Object::Particle(0)).len(), 4);
    assert_eq!(
        p.animatable(Object::Light(0)).iter().map(|c| c.1).collect::<Vec<_>>(),
        [Prop::Position, Prop::Intensity, Prop::Color, Prop::SpotDirection, Prop::AngleDeg, Prop::Blend]
    );
    assert!(p.animatable(Object::Particle(9)).is_empty());
    assert_eq!(p.value_of(density), Some(KeyValue::Float(2.0)));
    assert_eq!(p.value_of(Channel(Object::Light(0), Prop::SunDirection)), None, "a spot has no sun direction");
    assert!(!p.is_animated(density));

    p.set_key(density, 10, KeyValue::Float(1.0), Interp::Smooth).unwrap();
    assert_eq!(p.animation, Some(Animation::default()), "the first key makes the still an animation");
    p.set_key(density, 5, KeyValue::Float(2.0), Interp::Linear).unwrap();
    p.set_key(density, 10, KeyValue::Float(4.0), Interp::Hold).unwrap();
    let t = p.track(density).unwrap();
    assert_eq!(
        t.keys.iter().map(|k| (k.frame, k.value)).collect::<Vec<_>>(),
        [(5, KeyValue::Float(2.0)), (10, KeyValue::Float(4.0))]
    );
    assert_eq!(t.keys[1].interp, Interp::Hold, "a key on the same frame is replaced");
    assert!(p.set_key(density, 1, KeyValue::Bool(true), Interp::Linear).unwrap_err().0.contains("Float"));
    assert!(p.set_key(Channel(Object::Particle(9), Prop::Radius), 1, KeyValue::Float(1.0), Interp::Linear).is_err());
    p.set_key(Channel(Object::Particle(0), Prop::Center), 7, KeyValue::Vec3(Vec3::ONE), Interp::Linear).unwrap();
    assert_eq!(p.key_frames(Object::Particle(0)), [5, 7, 10]);
    assert!(p.has_key(density, 5) && !p.has_key(density, 7));

    let err = p.move_key(density, 5, 10).unwrap_err();
    assert!(err.0.contains("frame 10"), "{err}");
    assert!(p.move_key(density, 6, 8).is_err(), "no key at 6");
    p.move_key(density, 5, 12).unwrap();
    assert_eq!(p.track(density).unwrap().keys.iter().map(|k| k.frame).collect::<Vec<_>>(), [10, 12]);
    assert!(p.remove_key(density, 10));
    assert!(!p.remove_key(density, 10));
    assert!(p.remove_key(density, 12));
    assert!(!p.is_animated(density) && p.track(density).is_none(), "the last key takes the track");
    p.validate(4096).unwrap();
}

#[test]
fn deleting_an_object_drops_its_tracks() {
    let mut p = animated();
    let (pid, lid) = (p.particles[1].id, p.lights[0].id);
    p.set_key(Channel(Object::Particle(pid), Prop::Radius), 1, KeyValue::Float(1.0), Interp::Linear).unwrap();
    p.set_key(Channel(Object::Particle(p.particles[0].id), Prop::Radius), 1, KeyValue::Float(1.0), Interp::Linear)
        .unwrap();
    p.set_key(Channel(Object::Light(lid), Prop::Intensity), 1, KeyValue::Float(1.0), Interp::Linear).unwrap();
    // A spot turned into a point light loses its cone's tracks, not the others.
    p.set_key(Channel(Object::Light(lid), Prop::AngleDeg), 1, KeyValue::Float(10.0), Interp::Linear).unwrap();
    p.lights[0].kind = LightKind::Point;
    p.drop_inapplicable_tracks();
    assert_eq!(p.tracks.len(), 3);
    assert!(!p.is_animated(Channel(Object::Light(lid), Prop::AngleDeg)));
    p.remove_particles(&[1].into());
    p.remove_lights(&[0].into());
    assert_eq!(p.particles.len(), 1);
    assert!(p.lights.is_empty());
    assert_eq!(p.tracks.len(), 1);
    assert_eq!(p.tracks[0].on.0, Object::Particle(p.particles[0].id));
    p.validate(4096).unwrap();
}

const BASE: &str = r#"Project(
    version: 3,
    medium: (base_extinction: 0.1),
    particles: [(id: 2, center: (0.0, 1.5, 0.0), radius: 0.6, density: 3.0)],
    lights: [(id: 3, position: (1.2, 2.5, 0.4), intensity: 20.0)],
    animation: Some((fps: 24.0, start: 1, end: 120)),
    tracks: [TRACKS],
)"#;

fn invalid(animation: &str, tracks: &str) -> String {
    let text = BASE.replace("animation: Some((fps: 24.0, start: 1, end: 120))", animation).replace("TRACKS", tracks);
    parse_project(&text, Path::new("a.ron")).unwrap_err().to_string()
}

#[test]
fn the_documented_example_loads() {
    let tracks = "(on: (Light(3), Position), keys: [(frame: 1, value: Vec3((0.0, 1.0, 0.0)), interp: Smooth), (frame: 48, value: Vec3((2.0, 1.5, 0.0)))]),
        (on: (Particle(2), Density), keys: [(frame: 1, value: Float(2.0), interp: Hold), (frame: 60, value: Float(0.5))]),
        (on: (Particle(2), Hidden), keys: [(frame: 90, value: Bool(true))]),
        (on: (Camera, FovYDeg), keys: [(frame: 1, value: Float(40.0)), (frame: 120, value: Float(25.0))])";
    let p = parse_project(&BASE.replace("TRACKS", tracks), Path::new("a.ron")).unwrap();
    assert_eq!(p.tracks.len(), 4);
    assert_eq!(p.tracks[3].keys[0].interp, Interp::Linear, "interp defaults to Linear");
    let still = p.at_frame(100);
    assert!(still.particles[0].hidden);
    assert_eq!(still.lights[0].position, Vec3::new(2.0, 1.5, 0.0));
    // Saved and loaded again, the animation is the same, key for key.
    let dir = common::temp_dir();
    let path = dir.path().join("animated.ron");
    fogsmith::scene::io::save_project(&path, &p).unwrap();
    let again = fogsmith::scene::io::load_project(&path).unwrap();
    assert_eq!(again.animation, p.animation);
    assert_eq!(again.tracks, p.tracks);
    assert_eq!(again.at_frame(100).lights[0].position, still.lights[0].position);
}

#[test]
fn every_animation_error_names_the_track_key_and_fix() {
    let key = |v: &str| format!("(frame: 1, value: {v})");
    let cases: Vec<(String, String, &[&str])> = vec![
        ("animation: Some((fps: 0.0, start: 1, end: 9))".into(), String::new(), &["animation.fps", "> 0"]),
        ("animation: Some((fps: NaN, start: 1, end: 9))".into(), String::new(), &["animation.fps", "finite"]),
        (
            "animation: Some((fps: 24.0, start: 10, end: 9))".into(),
            String::new(),
            &["animation.end", "before the first", "end ≥ start"],
        ),
        (
            "animation: None".into(),
            format!("(on: (Camera, FovYDeg), keys: [{}])", key("Float(30.0)")),
            &["tracks", "add `animation"],
        ),
        (
            String::new(),
            format!("(on: (Particle(7), Radius), keys: [{}])", key("Float(1.0)")),
            &["tracks[0].on", "track 0 (Particle #7 Radius)", "no particle with id 7"],
        ),
        (
            String::new(),
            format!("(on: (Light(4), Intensity), keys: [{}])", key("Float(1.0)")),
            &["tracks[0].on", "no light with id 4"],
        ),
        (
            String::new(),
            format!("(on: (Light(3), AngleDeg), keys: [{}])", key("Float(10.0)")),
            &["tracks[0].on", "a point light has no AngleDeg", "Intensity"],
        ),
        (
            String::new(),
            format!("(on: (Particle(2), Position), keys: [{}])", key("Vec3((0,0,0))")),
            &["tracks[0].on", "a particle has no Position", "Center"],
        ),
        (
            String::new(),
            format!("(on: (Medium, NoiseAmplitude), keys: [{}])", key("Float(1.0)")),
            &["tracks[0].on", "no noise"],
        ),
        (
            String::new(),
            "(on: (Camera, FovYDeg), keys: [])".into(),
            &["tracks[0].keys", "track 0 (Camera FovYDeg) has no keys", "remove the track"],
        ),
        (
            String::new(),
            format!(
                "(on: (Camera, FovYDeg), keys: [{}]), (on: (Camera, FovYDeg), keys: [{}])",
                key("Float(30.0)"),
                key("Float(20.0)")
            ),
            &["tracks[1].on", "track 1 (Camera FovYDeg)", "track 0 already animates", "merge"],
        ),
        (
            String::new(),
            format!(
                "(on: (Camera, FovYDeg), keys: [{}, (frame: 5, value: Float(2.0)), {}])",
                key("Float(30.0)"),
                key("Float(20.0)")
            ),
            &["tracks[0].keys[2].frame", "key 2 (frame 1)", "key 0 is on the same frame", "one key per frame"],
        ),
        (
            String::new(),
            "(on: (Camera, FovYDeg), keys: [(frame: 5, value: Float(2.0)), (frame: 3, value: Float(2.0))])".into(),
            &["tracks[0].keys[1].frame", "frame order"],
        ),
        (
            String::new(),
            format!("(on: (Particle(2), Radius), keys: [{}])", key("Vec3((1,1,1))")),
            &["tracks[0].keys[0].value", "key 0 (frame 1)", "Radius takes a Float value, e.g. Float(1.0)"],
        ),
        (
            String::new(),
            format!("(on: (Particle(2), Hidden), keys: [{}])", key("Float(1.0)")),
            &["tracks[0].keys[0].value", "Bool(true)"],
        ),
        (
            String::new(),
            format!("(on: (Particle(2), Radius), keys: [{}])", key("Float(0.0)")),
            &["tracks[0].keys[0].value", "track 0 (Particle #2 Radius), key 0 (frame 1)", "(0, 1e9] m"],
        ),
        (
            String::new(),
            format!("(on: (Particle(2), Density), keys: [{}])", key("Float(inf)")),
            &["tracks[0].keys[0].value", "finite"],
        ),
        (
            String::new(),
            format!("(on: (Particle(2), Center), keys: [{}])", key("Vec3((0, NaN, 0))")),
            &["tracks[0].keys[0].value", "finite"],
        ),
        (
            String::new(),
            format!("(on: (Light(3), Intensity), keys: [{}])", key("Float(-1.0)")),
            &["tracks[0].keys[0].value", "≥ 0"],
        ),
        (
            String::new(),
            format!("(on: (Camera, FovYDeg), keys: [{}])", key("Float(180.0)")),
            &["tracks[0].keys[0].value", "(0, 180) degrees"],
        ),
        (
            String::new(),
            format!("(on: (Light(3), Color), keys: [{}])", key("Vec3((1, -1, 1))")),
            &["tracks[0].keys[0].value", "≥ 0"],
        ),
    ];
    for (animation, tracks, want) in cases {
        let animation =
            if animation.is_empty() { "animation: Some((fps: 24.0, start: 1, end: 120))" } else { &animation };
        let e = invalid(animation, &tracks);
        for w in want {
            assert!(e.contains(w), "{animation} {tracks}: {e:?} lacks {w:?}");
        }
    }
    // A spot light's angle and a sun's direction check their ranges.
    let spot = BASE
        .replace("intensity: 20.0)", "intensity: 20.0, kind: Spot(direction: (0, -1, 0), angle_deg: 30, blend: 0.1))");
    let text = spot.replace("TRACKS", "(on: (Light(3), AngleDeg), keys: [(frame: 1, value: Float(95.0))])");
    let e = parse_project(&text, Path::new("a.ron")).unwrap_err().to_string();
    assert!(e.contains("tracks[0].keys[0].value") && e.contains("(0, 90] degrees"), "{e}");
    let text = spot.replace("TRACKS", "(on: (Light(3), SpotDirection), keys: [(frame: 1, value: Vec3((0, 0, 0)))])");
    let e = parse_project(&text, Path::new("a.ron")).unwrap_err().to_string();
    assert!(e.contains("non-zero direction"), "{e}");
    // The error points at the key's line.
    let text = BASE.replace("TRACKS", "(on: (Camera, FovYDeg), keys: [\n (frame: 1, value: Float(0.0))])");
    let e = parse_project(&text, Path::new("a.ron")).unwrap_err().to_string();
    assert!(e.starts_with("a.ron:8:13:"), "{e}");
}

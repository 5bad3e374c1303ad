//! Project files: the documented example loads, every demo loads, errors carry file, line,
//! column and field, and saving is atomic and round-trips exactly.

mod common;

use fogsmith::scene::io::to_ron_string;
use fogsmith::scene::{load_project, parse_project, save_project, Project, ProjectError, Scheme};
use std::path::Path;

const EXAMPLE: &str = r#"Project(
    version: 1,
    grid: (min: (-2.0, 0.0, -2.0), max: (2.0, 4.0, 2.0), resolution: (64, 64, 64)),
    medium: (base_extinction: 0.0, albedo: 1.0, anisotropy: 0.0),
    particles: [
        (center: (0.0, 1.5, 0.0), radius: 0.6, density: 3.0),
    ],
    lights: [
        (position: (1.2, 2.5, 0.4), intensity: 20.0, color: (1.0, 0.95, 0.9)),
    ],
    camera: (position: (0.0, 2.0, 7.0), target: (0.0, 1.5, 0.0), up: (0.0, 1.0, 0.0), fov_y_deg: 40.0),
    render: (width: 640, height: 360),
)"#;

fn parse(text: &str) -> Result<Project, ProjectError> {
    parse_project(text, Path::new("scene.ron"))
}

#[test]
fn documented_example_loads_with_defaults() {
    let p = parse(EXAMPLE).unwrap();
    assert_eq!(p.particles.len(), 1);
    assert_eq!(p.lights[0].intensity, 20.0);
    assert_eq!(p.render.step_factor, 0.5, "omitted fields take their documented defaults");
    assert_eq!(p.propagation.scheme, Scheme::Sweep);
}

#[test]
fn every_demo_project_loads() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("projects");
    let mut n = 0;
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "ron") {
            let p = load_project(&path).unwrap_or_else(|e| panic!("{e}"));
            assert!(!p.lights.is_empty(), "{}", path.display());
            n += 1;
        }
    }
    assert!(n >= 3, "at least three demo projects ship, found {n}");
}

#[test]
fn syntax_errors_name_file_line_and_column() {
    let broken = EXAMPLE.replace("radius: 0.6,", "radius: 0.6");
    match parse(&broken) {
        Err(ProjectError::Syntax { path, line, col, message }) => {
            assert_eq!(path, Path::new("scene.ron"));
            assert_eq!(line, 6, "{message}");
            assert!(col > 1);
        }
        other => panic!("expected a syntax error, got {other:?}"),
    }
}

#[test]
fn invalid_values_name_the_field_and_its_position() {
    let cases = [
        ("radius: 0.6", "radius: -0.6", "particles[0].radius", 6),
        ("density: 3.0", "density: NaN", "particles[0].density", 6),
        ("intensity: 20.0", "intensity: -1.0", "lights[0].intensity", 9),
        ("resolution: (64, 64, 64)", "resolution: (64, 0, 64)", "grid.resolution.y", 3),
        ("resolution: (64, 64, 64)", "resolution: (64, 100000, 64)", "grid.resolution.y", 3),
        ("max: (2.0, 4.0, 2.0)", "max: (2.0, -4.0, 2.0)", "grid.max.y", 3),
        ("albedo: 1.0", "albedo: 1.5", "medium.albedo", 4),
        ("fov_y_deg: 40.0", "fov_y_deg: 0.0", "camera.fov_y_deg", 11),
        (
            "render: (width: 640, height: 360),",
            "render: (width: 640, height: 360),\n    propagation: (sweep_tolerance: 0.0),",
            "propagation.sweep_tolerance",
            13,
        ),
        (
            "render: (width: 640, height: 360),",
            "render: (width: 640, height: 360),\n    propagation: (sweep_stride: 2),",
            "propagation.sweep_stride",
            13,
        ),
    ];
    for (from, to, field, want_line) in cases {
        let text = EXAMPLE.replace(from, to);
        match parse(&text) {
            Err(ProjectError::Invalid { line, error, .. }) => {
                assert_eq!(error.field, field, "{to}");
                assert_eq!(line, want_line, "{to}: {error}");
            }
            other => panic!("{to}: expected a validation error, got {other:?}"),
        }
        let message = parse(&text).unwrap_err().to_string();
        assert!(message.starts_with(&format!("scene.ron:{want_line}:")), "{message}");
        assert!(message.contains(field), "{message}");
    }
}

#[test]
fn missing_file_is_a_clear_error() {
    let err = load_project(Path::new("/nonexistent/fog.ron")).unwrap_err();
    assert!(err.to_string().contains("/nonexistent/fog.ron"), "{err}");
}

#[test]
fn save_then_load_is_identical_and_keeps_a_backup() {
    let dir = common::temp_dir();
    let path = dir.path().join("fog.ron");
    let mut p = parse(EXAMPLE).unwrap();
    p.particles[0].name = Some("wisp".into());
    p.lights[0].hidden = true;
    save_project(&path, &p).unwrap();
    let back = load_project(&path).unwrap();
    assert_eq!(back, p);
    assert_eq!(to_ron_string(&back).unwrap(), std::fs::read_to_string(&path).unwrap());

    p.medium.base_extinction = 0.25;
    save_project(&path, &p).unwrap();
    assert_eq!(load_project(&path).unwrap(), p);
    let backup = load_project(&dir.path().join("fog.ron.bak")).unwrap();
    assert_eq!(backup.medium.base_extinction, 0.0, "the previous version is kept as .bak");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path())
        .unwrap()
        .filter_map(|e| e.ok())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".tmp"))
        .collect();
    assert!(leftovers.is_empty(), "no temporary files are left behind");
}

#[test]
fn saving_to_an_unwritable_place_fails_cleanly() {
    let p = parse(EXAMPLE).unwrap();
    let err = save_project(Path::new("/nonexistent-dir/fog.ron"), &p).unwrap_err();
    assert!(err.to_string().contains("/nonexistent-dir/fog.ron"), "{err}");
}

/// A version-1 file (no ids) migrates: ids are the list positions, the counters follow them,
/// and the project saves as the current version with its ids.
#[test]
fn version_1_files_get_ids_in_list_order() {
    let text = EXAMPLE.replace(
        "(center: (0.0, 1.5, 0.0), radius: 0.6, density: 3.0),",
        "(center: (0.0, 1.5, 0.0), radius: 0.6, density: 3.0),\n        (center: (0.5, 1.5, 0.0), radius: 0.4, density: 1.0),\n        (center: (-0.5, 1.5, 0.0), radius: 0.3, density: 2.0),",
    );
    assert!(text.contains("version: 1"));
    let mut p = parse(&text).unwrap();
    assert_eq!(p.version, fogsmith::scene::PROJECT_VERSION);
    assert_eq!(p.particles.iter().map(|q| q.id).collect::<Vec<_>>(), [0, 1, 2]);
    assert_eq!(p.lights[0].id, 0);
    assert_eq!(p.particle_label(2), "Particle #2");
    p.particles.remove(1);
    assert_eq!(p.particle_label(1), "Particle #2", "an erase does not rename the others");
    assert_eq!(p.new_particle_id(), 3);
    assert_eq!(p.new_light_id(), 1);

    let dir = common::temp_dir();
    let path = dir.path().join("v3.ron");
    save_project(&path, &p).unwrap();
    let saved = std::fs::read_to_string(&path).unwrap();
    assert!(saved.contains("version: 3") && saved.contains("id: 2"), "{saved}");
    let back = load_project(&path).unwrap();
    assert_eq!(back, p);
}

#[test]
fn duplicate_ids_and_unknown_versions_are_clear_errors() {
    let text = EXAMPLE.replace("version: 1", "version: 2").replace(
        "(center: (0.0, 1.5, 0.0), radius: 0.6, density: 3.0),",
        "(id: 4, center: (0.0, 1.5, 0.0), radius: 0.6, density: 3.0),\n        (id: 4, center: (0.5, 1.5, 0.0), radius: 0.4, density: 1.0),",
    );
    let err = parse(&text).unwrap_err().to_string();
    assert!(err.contains("scene.ron:7:") && err.contains("particles[1].id") && err.contains("own id"), "{err}");
    let err = parse(&EXAMPLE.replace("version: 1", "version: 9")).unwrap_err().to_string();
    assert!(err.contains("version 9") && err.contains("newer Fogsmith"), "{err}");
}

/// A project built in code (every id 0) is numbered when saved, so the file loads again.
#[test]
fn code_built_projects_save_with_distinct_ids() {
    let p = Project {
        particles: (0..3)
            .map(|i| fogsmith::scene::Particle::new(glam::Vec3::new(i as f32 * 0.3, 1.0, 0.0), 0.2, 1.0))
            .collect(),
        ..Project::default()
    };
    let dir = common::temp_dir();
    let path = dir.path().join("code.ron");
    save_project(&path, &p).unwrap();
    let back = load_project(&path).unwrap();
    assert_eq!(back.particles.iter().map(|q| q.id).collect::<Vec<_>>(), [0, 1, 2]);
}

/// What the outside-the-box rule says on the demos (printed; see the README), and that fitting
/// the grid leaves no particle crossing it.
#[test]
fn demos_particles_crossing_the_grid() {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("projects");
    for entry in std::fs::read_dir(&dir).unwrap() {
        let path = entry.unwrap().path();
        let p = load_project(&path).unwrap();
        let crossing = p.particles_crossing_grid();
        println!("{}: {} of {} particles cross the grid box", path.display(), crossing.len(), p.particles.len());
        for keep in [fogsmith::scene::FitKeep::CellSize, fogsmith::scene::FitKeep::Resolution] {
            let g = p.fit_grid_to_particles(keep).unwrap();
            println!("  fit {keep:?}: {:?} .. {:?} {:?}", g.min, g.max, g.resolution);
            let fitted = Project { grid: g, ..p.clone() };
            assert!(
                fitted.particles_crossing_grid().is_empty(),
                "{}: after fitting ({keep:?}) no particle crosses",
                path.display()
            );
            if keep == fogsmith::scene::FitKeep::Resolution {
                assert_eq!(g.resolution, p.grid.resolution);
            }
        }
    }
}

/// A file without a version (hand-written, minimal) reads as version 1: no ids needed.
#[test]
fn files_without_a_version_need_no_ids() {
    let text = "Project(particles: [(center: (0, 1, 0), radius: 0.5, density: 1), (center: (0.5, 1, 0), radius: 0.5, density: 1)])";
    let p = parse(text).unwrap();
    assert_eq!(p.version, fogsmith::scene::PROJECT_VERSION);
    assert_eq!(p.particles.iter().map(|q| q.id).collect::<Vec<_>>(), [0, 1]);
}

/// A version-2 file (ids, no animation) loads as the same still, whatever it holds; saved,
/// it is version 3 and otherwise the same text, with no animation fields written.
#[test]
fn version_2_files_load_unchanged_as_stills() {
    let v2 = EXAMPLE
        .replace("version: 1", "version: 2")
        .replace("(center: (0.0, 1.5, 0.0)", "(id: 5, center: (0.0, 1.5, 0.0)")
        .replace("(position: (1.2", "(id: 7, position: (1.2")
        .replace(
            "medium: (base_extinction: 0.0, albedo: 1.0, anisotropy: 0.0)",
            "medium: (base_extinction: 0.1, albedo: 1.0, anisotropy: 0.0, noise: Some((0.8, 1.5, 4, 7)))",
        );
    let p = parse(&v2).unwrap();
    assert_eq!(p.version, fogsmith::scene::PROJECT_VERSION);
    assert_eq!((p.particles[0].id, p.lights[0].id), (5, 7));
    assert_eq!(p.medium.noise, Some(fogsmith::scene::Noise::new(0.8, 1.5, 4, 7)));
    assert_eq!(p.animation, None);
    assert!(p.tracks.is_empty());
    assert_eq!(p.at_frame(10), p, "a still is its own frame");
    let text = to_ron_string(&p).unwrap();
    assert!(text.contains("version: 3"), "{text}");
    assert!(!text.contains("animation") && !text.contains("tracks") && !text.contains("velocity"), "{text}");
    assert!(text.contains("noise: Some((0.8, 1.5, 4, 7))"), "the noise keeps its 4-tuple form: {text}");
    let back = parse(&text).unwrap();
    assert_eq!(back, p);
    assert_eq!(to_ron_string(&back).unwrap(), text, "a still round-trips unchanged");
}

/// Wind and animation fields round-trip; the noise reads its 4-, 5- and 6-tuple forms.
#[test]
fn animated_projects_and_wind_round_trip() {
    let text = EXAMPLE.replace("version: 1", "version: 3").replace(
        "medium: (base_extinction: 0.0, albedo: 1.0, anisotropy: 0.0)",
        "medium: (base_extinction: 0.1, noise: Some((0.8, 1.5, 4, 7, (1.0, 0.0, -0.5)))),
    animation: Some((fps: 24.0, start: 1, end: 120)),
    tracks: [
        (on: (Light(0), Position), keys: [
            (frame: 1, value: Vec3((0.0, 1.0, 0.0)), interp: Smooth),
            (frame: 48, value: Vec3((2.0, 1.5, 0.0))),
        ]),
        (on: (Particle(0), Hidden), keys: [(frame: 90, value: Bool(true))]),
        (on: (Camera, FovYDeg), keys: [(frame: 1, value: Float(40.0), interp: Hold), (frame: 120, value: Float(25.0))]),
    ]",
    );
    let p = parse(&text).unwrap();
    let noise = p.medium.noise.unwrap();
    assert_eq!(noise.velocity, glam::Vec3::new(1.0, 0.0, -0.5));
    assert_eq!(p.tracks.len(), 3);
    let saved = to_ron_string(&p).unwrap();
    assert_eq!(parse(&saved).unwrap(), p);
    let still = p.at_frame(48);
    assert_eq!(still.medium.noise.unwrap().offset, glam::Vec3::new(2.0, 0.0, -1.0));
    let saved = to_ron_string(&still).unwrap();
    assert!(saved.contains("(1.0, 0.0, -0.5), (2.0, 0.0, -1.0)"), "a still keeps its drift: {saved}");
    assert_eq!(parse(&saved).unwrap(), still);
}

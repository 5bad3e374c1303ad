//! An animated stage in Blender 4.5 (`bpy` from the project's test venv, ./setup.sh): a small
//! fog scene whose particles, lights and camera move over frames 1-4 is exported with
//! `--frames 1-4 --preset blender --usd`, imported by Fogsmith's Blender add-on alone, and
//! checked: the scene plays at the project's frame rate, the volume is a
//! VDB sequence starting at frame 1 with one frame per file, the lights and the camera move as
//! keyed, and Cycles renders frames 1 and 4 within 5 % in mean of `fogsmith render --frames`
//! of the same frames.

mod common;
use common::{root, run_ok, venv_python};

use fogsmith::scene::animation::{Animation, Channel, Interp, Key, KeyValue, Object, Prop, Track};
use fogsmith::scene::{Camera, GridSpec, Light, Medium, Particle, Project};
use glam::{UVec3, Vec3};
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

const W: usize = 48;
const H: usize = 36;

fn ramp(on: Channel, a: Vec3, b: Vec3) -> Track {
    let key = |frame, v| Key { frame, value: KeyValue::Vec3(v), interp: Interp::Linear };
    Track { on, keys: vec![key(1, a), key(4, b)] }
}

fn scene() -> Project {
    let mut p = Project {
        grid: GridSpec { min: Vec3::splat(-1.2), max: Vec3::splat(1.2), resolution: UVec3::splat(24) },
        medium: Medium { base_extinction: 0.0, albedo: 0.9, anisotropy: 0.2, ..Medium::default() },
        particles: vec![
            Particle::new(Vec3::new(-0.2, 0.0, 0.1), 0.3, 3.0),
            Particle::new(Vec3::new(0.3, 0.2, -0.1), 0.25, 4.0),
            Particle::new(Vec3::new(0.0, -0.3, 0.2), 0.2, 2.0),
        ],
        lights: vec![
            Light::new(Vec3::new(1.8, 1.2, 0.8), 20.0, Vec3::new(1.0, 0.9, 0.7)),
            Light::new(Vec3::new(-1.8, 0.5, -1.0), 10.0, Vec3::new(0.5, 0.7, 1.0)),
        ],
        ..Default::default()
    };
    p.camera = Camera { position: Vec3::new(0.5, 0.8, 4.0), target: Vec3::ZERO, up: Vec3::Y, fov_y_deg: 40.0 };
    p.ensure_unique_ids();
    p.animation = Some(Animation { fps: 12.0, start: 1, end: 4 });
    let (l0, q0) = (p.lights[0].id, p.particles[0].id);
    p.tracks = vec![
        ramp(Channel(Object::Light(l0), Prop::Position), p.lights[0].position, Vec3::new(1.0, 1.6, 1.6)),
        ramp(Channel(Object::Camera, Prop::Position), p.camera.position, Vec3::new(-1.2, 0.6, 3.8)),
        ramp(Channel(Object::Particle(q0), Prop::Center), p.particles[0].center, Vec3::new(-0.5, 0.2, 0.0)),
    ];
    p
}

fn exr_mean(path: &Path) -> f64 {
    use exr::prelude::*;
    let image = read_all_flat_layers_from_file(path).unwrap();
    let layer = &image.layer_data[0];
    assert_eq!((layer.size.0, layer.size.1), (W, H));
    let mut sum = 0.0;
    for c in &layer.channel_data.list {
        if ["R", "G", "B"].contains(&c.name.to_string().as_str()) {
            sum += c.sample_data.values_as_f32().map(|v| v as f64).sum::<f64>();
        }
    }
    sum / (W * H * 3) as f64
}

/// Blender's position in its Z-up world of a Fogsmith (Y-up) position.
fn blender(p: Vec3) -> [f64; 3] {
    [p.x as f64, -p.z as f64, p.y as f64]
}

fn close(a: &Value, b: [f64; 3], what: &str) {
    let a: Vec<f64> = a.as_array().unwrap().iter().map(|v| v.as_f64().unwrap()).collect();
    assert!((0..3).all(|i| (a[i] - b[i]).abs() < 1e-4), "{what}: Blender {a:?}, keyed {b:?}");
}

#[test]
fn blender_imports_the_animated_stage_and_cycles_matches_each_frame() {
    let py = venv_python("bpy");
    fogsmith::cli::ensure_runtime_dir();
    let bin = env!("CARGO_BIN_EXE_fogsmith");
    let tmp = common::temp_dir();
    let dir = tmp.path();
    let project = scene();
    let ron = dir.join("anim.ron");
    fogsmith::scene::io::save_project(&ron, &project).unwrap();
    let usd = dir.join("anim.usda");
    let (w, h) = (W.to_string(), H.to_string());
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let common = ["--frames", "1-4", "--width", &w, "--height", &h];
    run_ok(
        Command::new(bin).args(["export", &s(&ron), "--preset", "blender", "--usd", &s(&usd)]).args(common),
        "export",
    );
    let exr = dir.join("fog.####.exr");
    run_ok(Command::new(bin).args(["render", &s(&ron), "-o", &s(&exr), "--scheme", "exact"]).args(common), "render");

    let prefix = dir.join("cycles_");
    let stdout = run_ok(
        Command::new(&py).arg(root().join("tests/blender_sequence.py")).args([
            s(&usd),
            s(&prefix),
            w.clone(),
            h.clone(),
            "128".into(),
            "1".into(),
            "4".into(),
        ]),
        "Blender",
    );
    let line = stdout.lines().rev().find(|l| l.starts_with('{')).expect("a JSON line from blender_sequence.py");
    let b: Value = serde_json::from_str(line).unwrap();
    eprintln!("{b}");
    assert_eq!(b["is_sequence"], true, "the volume is not a sequence: {b}");
    assert_eq!(b["frame_start"], 1, "{b}");
    assert_eq!(b["frame_duration"], 4, "{b}");
    assert_eq!(b["scene_frames"], serde_json::json!([1, 4]), "{b}");
    let fps = b["fps"].as_f64().unwrap();
    assert!((fps - 12.0).abs() < 1e-6, "the scene plays at {fps} frames/s, the project at 12: {b}");
    for f in [1, 4] {
        let shown = PathBuf::from(b["shown"][f.to_string()].as_str().unwrap());
        let want = dir.join(format!("anim.{f:04}.vdb"));
        assert_eq!(shown.canonicalize().unwrap(), want.canonicalize().unwrap(), "frame {f}: {b}");
    }
    for f in 1..=4 {
        let still = project.at_frame(f);
        let k = (f - 1) as usize;
        close(&b["camera"][k], blender(still.camera.position), &format!("camera at frame {f}"));
        let lights = b["lights"].as_object().unwrap();
        for (i, l) in still.lights.iter().enumerate() {
            let name = format!("Light_{i}");
            let got = lights.get(&name).unwrap_or_else(|| panic!("no light {name}: {b}"));
            close(&got[k], blender(l.position), &format!("{name} at frame {f}"));
        }
    }
    for f in [1, 4] {
        let fog = exr_mean(&dir.join(format!("fog.{f:04}.exr")));
        let cycles = b["renders"][f.to_string()].as_f64().unwrap();
        let ratio = cycles / fog;
        eprintln!("frame {f}: mean Fogsmith {fog:.5}, Cycles {cycles:.5}, ratio {ratio:.4}");
        assert!(fog > 1e-4, "frame {f}: Fogsmith's image is black");
        assert!((ratio - 1.0).abs() <= 0.05, "frame {f}: Cycles/Fogsmith mean radiance {ratio:.4}, allowed 1 ± 0.05");
    }
}

#[test]
fn the_blender_addon_imports_a_vdb_sequence_alone_with_its_material_and_frame_rate() {
    let py = venv_python("bpy");
    fogsmith::cli::ensure_runtime_dir();
    let bin = env!("CARGO_BIN_EXE_fogsmith");
    let tmp = common::temp_dir();
    let dir = tmp.path();
    let project = scene();
    let ron = dir.join("anim.ron");
    fogsmith::scene::io::save_project(&ron, &project).unwrap();
    let s = |p: &Path| p.to_str().unwrap().to_string();
    let vdbs = dir.join("cache/fog.####.vdb");
    run_ok(
        Command::new(bin).args(["export", &s(&ron), "--preset", "blender", "--frames", "1-4", "--vdb", &s(&vdbs)]),
        "export",
    );
    let first = dir.join("cache/fog.0001.vdb");
    let stdout = run_ok(
        Command::new(&py).arg(root().join("tests/blender_import.py")).arg(s(&first)),
        "Blender import through the add-on",
    );
    let line = stdout.lines().rev().find(|l| l.starts_with('{')).expect("a JSON line from blender_import.py");
    let b: Value = serde_json::from_str(line).unwrap();
    eprintln!("{b}");
    let fps = b["fps"].as_f64().unwrap();
    assert!((fps - 12.0).abs() < 1e-6, "the scene plays at {fps} frames/s, the files at 12: {b}");
    let vols = b["volumes"].as_array().unwrap();
    assert_eq!(vols.len(), 1, "{b}");
    let v = &vols[0];
    assert_eq!(v["is_sequence"], true, "{b}");
    assert_eq!(
        (v["frame_start"].as_i64(), v["frame_duration"].as_i64(), v["frame_offset"].as_i64()),
        (Some(1), Some(4), Some(0))
    );
    assert_eq!(v["material"], "Fogsmith Fog", "{b}");
    let albedo = project.medium.albedo as f64;
    for c in v["color"].as_array().unwrap() {
        assert!((c.as_f64().unwrap() - albedo).abs() < 1e-6, "colour {c}, albedo {albedo}: {b}");
    }
    let g = v["anisotropy"].as_f64().unwrap();
    assert!((g - project.medium.anisotropy as f64).abs() < 1e-6, "anisotropy {g}: {b}");
    // Half a voxel back along each axis: the grid's cells are 0.1 m in every direction.
    let half = 0.5 * project.grid.cell_size().x as f64;
    for c in v["location"].as_array().unwrap() {
        let c = c.as_f64().unwrap();
        assert!((c.abs() - half).abs() < 1e-5, "the volume is at {c} on an axis, not half a voxel ({half}) back: {b}");
    }
}

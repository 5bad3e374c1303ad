//! Frame sequences end to end: `--frames` and output patterns on `render` and `export`, the
//! reuse between frames of one pipeline, determinism against cold bakes, Ctrl+C between
//! frames, the animated USD stage and VDB metadata read by usd-core and OpenVDB, and every
//! error a bad frame list or output path gets.

mod common;
use common::{root, venv_python};

use fogsmith::scene::animation::{Animation, Channel, Interp, KeyValue, Object, Prop, Track};
use fogsmith::scene::{io::save_project, Project};
use glam::Vec3;
use serde_json::Value;
use std::path::{Path, PathBuf};
use std::process::Command;

fn fogsmith() -> Command {
    Command::new(env!("CARGO_BIN_EXE_fogsmith"))
}

/// Grid cells per axis: 4³ bricks of injection, so a moved particle touches only some.
const RES: u32 = 32;

fn key(frame: i32, value: KeyValue) -> fogsmith::scene::animation::Key {
    fogsmith::scene::animation::Key { frame, value, interp: Interp::Linear }
}

fn track(on: Channel, keys: &[(i32, KeyValue)]) -> Track {
    Track { on, keys: keys.iter().map(|&(f, v)| key(f, v)).collect() }
}

/// A small scene of two lights, animated over frames 1-`end`: frame 2 moves light 0 only,
/// frame 3 moves the camera only, frame 4 moves a particle only, and from frame 4 on
/// nothing changes, except that with `drift` light 1 moves from frame 2 to the end and the
/// camera from frame 3 to the end.
fn animated(end: i32, drift: bool) -> Project {
    let mut p = common::small_scene(RES, &[Vec3::new(1.6, 1.2, 0.5), Vec3::new(-1.5, 0.8, -0.9)]);
    p.render.width = 32;
    p.render.height = 24;
    // A small puff in a corner, the particle that moves.
    p.particles.push(fogsmith::scene::Particle::new(Vec3::new(0.7, 0.7, 0.7), 0.08, 3.0));
    p.ensure_unique_ids();
    p.animation = Some(Animation { fps: 24.0, start: 1, end });
    let (l0, l1, q0) = (p.lights[0].id, p.lights[1].id, p.particles[4].id);
    let v = KeyValue::Vec3;
    let light0 = p.lights[0].position;
    let cam = p.camera.position;
    let centre = p.particles[4].center;
    p.tracks = vec![
        track(Channel(Object::Light(l0), Prop::Position), &[(1, v(light0)), (2, v(light0 + Vec3::new(0.0, 0.3, 0.0)))]),
        track(
            Channel(Object::Camera, Prop::Position),
            &[(2, v(cam)), (3, v(cam + Vec3::new(0.4, 0.0, 0.0))), (end.max(4), v(cam + Vec3::new(0.4, 0.0, 0.0)))],
        ),
        track(
            Channel(Object::Particle(q0), Prop::Center),
            &[(3, v(centre)), (4, v(centre + Vec3::new(0.06, 0.03, 0.0)))],
        ),
    ];
    if drift {
        let light1 = p.lights[1].position;
        p.tracks.push(track(
            Channel(Object::Light(l1), Prop::Position),
            &[(2, v(light1)), (end, v(light1 + Vec3::new(0.0, 0.0, 0.6)))],
        ));
        p.tracks[1].keys.last_mut().unwrap().value = v(cam + Vec3::new(0.9, 0.2, 0.0));
    }
    p
}

fn save(dir: &Path, name: &str, project: &Project) -> PathBuf {
    let path = dir.join(name);
    save_project(&path, project).unwrap();
    path
}

fn run(args: &[&str]) -> std::process::Output {
    fogsmith().args(args).output().unwrap()
}

fn json_of(out: &std::process::Output) -> Value {
    assert!(out.status.success(), "failed: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout)
        .unwrap_or_else(|e| panic!("stdout is not JSON ({e}): {}", String::from_utf8_lossy(&out.stdout)))
}

fn stderr_of(out: &std::process::Output) -> String {
    assert!(!out.status.success(), "succeeded where it should fail: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

fn s(p: &Path) -> &str {
    p.to_str().unwrap()
}

fn u64_of(v: &Value, counter: &str) -> u64 {
    v["counters"][counter].as_u64().unwrap_or_else(|| panic!("no counter {counter}: {v}"))
}

/// One pipeline bakes the frames in order and reruns only what each frame changed: a
/// light that moved alone is propagated alone and injects nothing, a camera that moved
/// alone reruns only the march, a particle that moved reinjects, and a frame equal to the
/// previous one runs nothing.
#[test]
fn each_frame_reruns_only_what_it_changed() {
    let dir = common::temp_dir();
    let project = save(dir.path(), "anim.ron", &animated(5, false));
    let pattern = dir.path().join("f.####.png");
    let v = json_of(&run(&["render", s(&project), "--frames", "1-5", "-o", s(&pattern), "--json"]));
    let frames = v["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 5, "{v}");
    for (k, f) in frames.iter().enumerate() {
        assert_eq!(f["frame"], k as i64 + 1, "{v}");
        let path = dir.path().join(format!("f.{:04}.png", k + 1));
        assert_eq!(f["output"], s(&path), "{v}");
        assert!(image::open(&path).is_ok(), "{} is not a readable PNG", path.display());
    }
    let first = &frames[0];
    assert!(u64_of(first, "cells_injected") > 0 && u64_of(first, "lights_propagated") == 2, "{first}");
    // Frame 2: light 0 moved.
    let f2 = &frames[1];
    assert_eq!(u64_of(f2, "cells_injected"), 0, "a moved light injects nothing: {f2}");
    assert_eq!(u64_of(f2, "lights_propagated"), 1, "only the moved light propagates: {f2}");
    assert!(u64_of(f2, "samples_marched") > 0, "{f2}");
    // Frame 3: the camera moved.
    let f3 = &frames[2];
    assert_eq!(u64_of(f3, "cells_injected"), 0, "{f3}");
    assert_eq!(u64_of(f3, "lights_propagated"), 0, "a moved camera propagates nothing: {f3}");
    assert_eq!(u64_of(f3, "cells_propagated"), 0, "{f3}");
    assert!(u64_of(f3, "samples_marched") > 0, "a moved camera marches again: {f3}");
    // Frame 4: a particle moved: injection (of the bricks it touches) and both lights.
    let f4 = &frames[3];
    assert!(u64_of(f4, "cells_injected") > 0, "{f4}");
    assert!(u64_of(f4, "cells_injected") < u64_of(first, "cells_injected"), "only the touched bricks: {f4}");
    assert_eq!(u64_of(f4, "lights_propagated"), 2, "{f4}");
    // Frame 5 equals frame 4.
    let f5 = &frames[4];
    for c in ["cells_injected", "cells_propagated", "samples_marched"] {
        assert_eq!(u64_of(f5, c), 0, "frame 5 is frame 4 again, {c}: {f5}");
    }
}

/// Every channel of every layer of an EXR file as (layer, channel, f32 bits). The bytes of
/// two files with equal pixels may differ: blocks compressed in parallel are written in the
/// order they finish.
fn exr_bits(path: &Path) -> Vec<(String, String, Vec<u32>)> {
    let image = exr::prelude::read_all_flat_layers_from_file(path).unwrap();
    let mut out = Vec::new();
    for layer in &image.layer_data {
        let name = layer.attributes.layer_name.as_ref().map(|n| n.to_string()).unwrap_or_default();
        for c in &layer.channel_data.list {
            let bits = c.sample_data.values_as_f32().map(f32::to_bits).collect();
            out.push((name.clone(), c.name.to_string(), bits));
        }
    }
    out
}

/// Frames 3-4 baked alone are bit-identical to frames 3-4 of the run 1-5 that reused the
/// earlier frames' work: images, EXR grids and VDB grids.
#[test]
fn a_range_alone_matches_the_same_frames_of_a_longer_run() {
    let dir = common::temp_dir();
    let project = save(dir.path(), "anim.ron", &animated(5, true));
    let bake = |frames: &str, sub: &str| {
        let out = dir.path().join(sub);
        std::fs::create_dir(&out).unwrap();
        let v = json_of(&run(&[
            "export",
            s(&project),
            "--frames",
            frames,
            "--exr-render",
            s(&out.join("r.####.exr")),
            "--exr-slices",
            s(&out.join("s.%04d.exr")),
            "--vdb",
            s(&out.join("v.$F4.vdb")),
            "--json",
        ]));
        (out, v)
    };
    let (long, v_long) = bake("1-5", "long");
    let (short, _) = bake("3-4", "short");
    // The long run reused work at frames 3 and 4 (else the comparison proves nothing).
    let frames = v_long["frames"].as_array().unwrap();
    assert_eq!(frames.len(), 5);
    assert_eq!(u64_of(&frames[2], "cells_injected"), 0, "{v_long}");
    assert!(u64_of(&frames[3], "cells_injected") < u64_of(&frames[0], "cells_injected"), "{v_long}");
    for f in [3, 4] {
        for name in [format!("r.{f:04}.exr"), format!("s.{f:04}.exr")] {
            let (a, b) = (exr_bits(&long.join(&name)), exr_bits(&short.join(&name)));
            assert!(!a.is_empty() && a == b, "{name} differs between --frames 1-5 and --frames 3-4");
        }
        let name = format!("v.{f:04}.vdb");
        for grid in ["density", "optical_depth_0", "optical_depth_1"] {
            let read = |d: &Path| fogsmith::export::vdb_read::read_vdb_grid(&d.join(&name), Some(grid)).unwrap();
            let (a, b) = (read(&long), read(&short));
            let n = RES as i32;
            let bits = |g: &fogsmith::export::vdb_read::VdbFloatGrid| {
                let cells = (0..n * n * n).map(|c| [c % n, (c / n) % n, c / (n * n)]);
                cells.map(|p| g.value_at(p).to_bits()).collect::<Vec<_>>()
            };
            assert!(bits(&a) == bits(&b), "{name} {grid} differs between --frames 1-5 and --frames 3-4");
        }
    }
    // Frames 1, 2 and 5 only in the long run.
    assert!(long.join("r.0005.exr").exists() && !short.join("r.0005.exr").exists());
}

/// Ctrl+C during a sequence: status 130, every frame written before it is complete, and no
/// partial or temporary file is left.
#[test]
fn ctrl_c_leaves_complete_frames_and_no_temporary_file() {
    let dir = common::temp_dir();
    let mut p = animated(400, true);
    p.render.width = 64;
    p.render.height = 48;
    let project = save(dir.path(), "anim.ron", &p);
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    let mut child = fogsmith()
        .args(["render", s(&project), "--frames", "1-400", "-o", s(&out.join("f.####.png"))])
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let started = std::time::Instant::now();
    while !out.join("f.0001.png").exists() {
        assert!(started.elapsed().as_secs() < 120, "no frame written in 2 minutes");
        assert!(child.try_wait().unwrap().is_none(), "the render ended before its first frame was seen");
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let status = Command::new("kill").args(["-INT", &child.id().to_string()]).status().unwrap();
    assert!(status.success());
    let output = child.wait_with_output().unwrap();
    let err = String::from_utf8_lossy(&output.stderr);
    assert_eq!(output.status.code(), Some(130), "{err}");
    assert!(err.contains("cancelled by Ctrl+C"), "{err}");
    let names: Vec<String> =
        std::fs::read_dir(&out).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(!names.is_empty() && names.len() < 400, "{names:?}");
    for name in &names {
        assert!(name.starts_with("f.") && name.ends_with(".png") && !name.starts_with('.'), "left behind: {name}");
        let img = image::open(out.join(name)).unwrap_or_else(|e| panic!("{name} is not a complete PNG: {e}"));
        assert_eq!((img.width(), img.height()), (64, 48), "{name}");
    }
    // The frames written are the first ones, without a gap.
    let mut numbers: Vec<usize> = names.iter().map(|n| n[2..6].parse().unwrap()).collect();
    numbers.sort();
    assert_eq!(numbers, (1..=names.len()).collect::<Vec<_>>());
}

/// Every refusal of a frame list or an output path, with its message.
#[test]
fn bad_frames_and_paths_are_refused_with_the_fix() {
    let dir = common::temp_dir();
    let project = save(dir.path(), "anim.ron", &animated(5, false));
    let still = root().join("projects/cornell.ron");
    let png = dir.path().join("f.####.png");
    let render = |project: &Path, frames: &str, out: &Path| {
        stderr_of(&run(&["render", s(project), "--frames", frames, "-o", s(out), "--quiet"]))
    };
    let cases: [(String, &[&str]); 9] = [
        (render(&project, "1-x", &png), &["--frames \"1-x\"", "\"1-x\" is not a frame or a range", "1-120x4"]),
        (render(&project, "", &png), &["--frames is empty"]),
        (render(&project, "4-2", &png), &["the range \"4-2\" ends before it starts; write 2-4"]),
        (render(&project, "1-4x0", &png), &["step of \"1-4x0\" must be at least 1"]),
        (render(&project, "3-9", &png), &["4 frames (6 … 9) are outside the project's animation range 1-5"]),
        (render(&project, "0", &png), &["frame 0 is outside the project's animation range 1-5"]),
        (
            render(&still, "1-3", &png),
            &["cornell.ron has no animation", "animation: Some((fps: 24.0, start: 1, end: 120))"],
        ),
        (
            render(&project, "1-3", &dir.path().join("f.png")),
            &["f.png: --frames 1-3 is 3 frames, and this path has no frame number", "f.####.png"],
        ),
        (
            render(&project, "1-2", &dir.path().join("f.####.jpg")),
            &["f.####.jpg: unsupported output format; use a .png", ".exr"],
        ),
    ];
    for (err, expected) in &cases {
        for e in *expected {
            assert!(err.contains(e), "expected {e:?} in: {err}");
        }
    }
    let export = |args: &[&str]| {
        let mut all = vec!["export", s(&project), "--frames", "1-3", "--quiet"];
        all.extend_from_slice(args);
        stderr_of(&run(&all))
    };
    let vdb = dir.path().join("fog.vdb");
    let err = export(&["--vdb", s(&vdb)]);
    assert!(err.contains("--vdb") && err.contains("has no frame number") && err.contains("fog.####.vdb"), "{err}");
    let err = export(&["--exr-atlas", s(&dir.path().join("a.exr"))]);
    assert!(err.contains("--exr-atlas") && err.contains("a.####.exr"), "{err}");
    let err = export(&["--usd", s(&dir.path().join("s.####.usda"))]);
    assert!(err.contains("one stage holds every frame"), "{err}");
    let err = stderr_of(&run(&["verify", s(&project), "--frame", "9", "--quiet"]));
    assert!(err.contains("--frame 9: frame 9 is outside the project's animation range 1-5"), "{err}");
    let bench_out = common::temp_dir();
    let bench = |scene: &str, frame: &str| {
        let args = ["bench", "--suite", "opv", "--scene", scene, "--frame", frame, "--quiet", "--out"];
        stderr_of(&fogsmith().args(args).arg(bench_out.path()).output().unwrap())
    };
    let err = bench("cornell", "3");
    assert!(err.contains("--frame 3: no animated demo among --scene cornell; name one of street-wind"), "{err}");
    let err = bench("street-wind", "49");
    assert!(err.contains("--frame 49: outside the demo street-wind's animation range 1-48"), "{err}");
    // Nothing was written by any refused command.
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, vec![std::ffi::OsString::from("anim.ron")]);

    // A rate of 0 or below and a range that ends before it starts are refused on load.
    for (animation, expected) in [
        ("(fps: 0.0, start: 1, end: 5)", "animation.fps"),
        ("(fps: -24.0, start: 1, end: 5)", "animation.fps"),
        ("(fps: 24.0, start: 6, end: 5)", "animation.end"),
    ] {
        let mut text = std::fs::read_to_string(&project).unwrap();
        let at = text.find("animation: Some(").unwrap();
        let end = at + text[at..].find("),").unwrap() + 1;
        text.replace_range(at..end, &format!("animation: Some({animation})"));
        let bad = dir.path().join("bad.ron");
        std::fs::write(&bad, text).unwrap();
        let err = render(&bad, "1-2", &png);
        assert!(err.contains(expected), "{animation}: expected {expected} in: {err}");
    }
}

/// The animated stage: time codes and rate in its metadata, one VDB per frame in every
/// field's filePath samples, and the moving light and camera sampled per frame, as USD
/// (usd-core) reads it; every VDB as OpenVDB reads it: frame and fps in the metadata, one
/// transform, the values the pipeline baked for that frame.
#[test]
fn animated_usd_stage_and_vdb_sequence_in_usd_and_openvdb() {
    let dir = common::temp_dir();
    let anim = animated(4, true);
    let project = save(dir.path(), "anim.ron", &anim);
    let stage = dir.path().join("shot.usda");
    let v =
        json_of(&run(&["export", s(&project), "--frames", "2-4", "--preset", "blender", "--usd", s(&stage), "--json"]));
    assert_eq!(v["usd"]["frames"], 3, "{v}");
    let vdbs: Vec<PathBuf> = (2..=4).map(|f| dir.path().join(format!("shot.{f:04}.vdb"))).collect();
    for p in &vdbs {
        assert!(p.exists(), "{} missing: {v}", p.display());
    }
    let py = venv_python("pxr");
    let out = Command::new(&py).arg(root().join("tests/usd_sequence_check.py")).arg(&stage).output().unwrap();
    assert!(out.status.success(), "usd_sequence_check.py: {}", String::from_utf8_lossy(&out.stderr));
    let u: Value = serde_json::from_slice(&out.stdout).unwrap();
    assert_eq!(u["start"], 2.0, "{u}");
    assert_eq!(u["end"], 4.0, "{u}");
    assert_eq!(u["tcps"], 24.0, "{u}");
    assert_eq!(u["fps"], 24.0, "{u}");
    assert_eq!(u["errors"], serde_json::json!([]), "{u}");
    let fields = u["fields"].as_object().unwrap();
    assert_eq!(fields.len(), 3, "density and one optical depth per light: {u}");
    for (name, samples) in fields {
        let samples = samples.as_array().unwrap();
        assert_eq!(samples.len(), 3, "{name}: {u}");
        for (s, path) in samples.iter().zip(&vdbs) {
            let resolved = PathBuf::from(s[1].as_str().unwrap());
            assert_eq!(resolved.canonicalize().unwrap(), path.canonicalize().unwrap(), "{name}: {u}");
        }
        assert_eq!(samples.iter().map(|s| s[0].as_f64().unwrap()).collect::<Vec<_>>(), [2.0, 3.0, 4.0]);
    }
    // Light 1 drifts along world z (Blender: −y) over frames 4..; light 0 stands still.
    let lights = &u["lights"];
    assert_eq!(lights["Light_0"]["samples"], 0, "{u}");
    let l1 = lights["Light_1"]["positions"].as_array().unwrap();
    assert_eq!(l1.len(), 3, "{u}");
    let at = |f: i32| {
        let p = anim.at_frame(f).lights[1].position;
        [p.x as f64, -p.z as f64, p.y as f64]
    };
    for (k, f) in (2..=4).enumerate() {
        let got: Vec<f64> = l1[k].as_array().unwrap().iter().map(|c| c.as_f64().unwrap()).collect();
        for a in 0..3 {
            assert!((got[a] - at(f)[a]).abs() < 1e-5, "frame {f}: {got:?} vs {:?}", at(f));
        }
    }
    let cams = u["camera"].as_array().unwrap();
    assert_eq!(cams.len(), 3, "{u}");
    for (k, f) in (2..=4).enumerate() {
        let p = anim.at_frame(f).camera.position;
        let want = [p.x as f64, -p.z as f64, p.y as f64];
        let got: Vec<f64> = cams[k].as_array().unwrap().iter().map(|c| c.as_f64().unwrap()).collect();
        for a in 0..3 {
            assert!((got[a] - want[a]).abs() < 1e-5, "camera at frame {f}: {got:?} vs {want:?}");
        }
    }

    // OpenVDB: each file's metadata, transform and the density the pipeline bakes for it.
    let ok = Command::new("/usr/bin/python3").args(["-c", "import pyopenvdb"]).output().map(|o| o.status.success());
    assert!(ok.unwrap_or(false), "/usr/bin/python3 cannot import pyopenvdb: run ./setup.sh");
    let r = anim.grid.resolution;
    let mut gpu = common::pipeline();
    let mut first_world = None;
    for (f, path) in (2..=4).zip(&vdbs) {
        let out = Command::new("/usr/bin/python3")
            .arg(root().join("tests/vdb_check.py"))
            .arg(path)
            .args([r.x.to_string(), r.y.to_string(), r.z.to_string()])
            .output()
            .unwrap();
        assert!(
            out.status.success(),
            "OpenVDB cannot read {}: {}",
            path.display(),
            String::from_utf8_lossy(&out.stderr)
        );
        let c: Value = serde_json::from_slice(&out.stdout).unwrap();
        assert_eq!(c["file_metadata"]["frame"], f.to_string(), "{}", c["file_metadata"]);
        assert_eq!(c["file_metadata"]["fps"], "24.0", "{}", c["file_metadata"]);
        let density = c["grids"].as_array().unwrap().iter().find(|g| g["name"] == "density").unwrap();
        assert_eq!(density["meta"]["frame"], f, "{}", density["meta"]);
        let world = density["world"].clone();
        assert_eq!(*first_world.get_or_insert_with(|| world.clone()), world, "frame {f}: the transform moved");
        let still = anim.at_frame(f);
        let request = fogsmith::gpu::FrameRequest::for_project(&still);
        gpu.update(&still, &request).unwrap();
        let ev = gpu.read_ev().unwrap();
        let got: Vec<u32> = density["values"].as_array().unwrap().iter().map(|b| b.as_u64().unwrap() as u32).collect();
        let want: Vec<u32> = ev.data.iter().map(|v| v.to_bits()).collect();
        assert!(got == want, "frame {f}: OpenVDB's density differs from the baked extinction");
    }
}

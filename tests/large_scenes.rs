//! Large scenes on the user's path: a loaded project is validated once and the per-frame
//! paths validate nothing; particle sidecars round-trip bit for bit and a damaged one is an
//! error naming it with nothing lost; undo and redo across a large scene restore every
//! state exactly, holding only what each step changed. The GPU tests fail without an
//! adapter; they never skip.

mod common;

use egui::{PointerButton, Vec2};
use egui_kittest::Harness;
use fogsmith::editor::app::{PreviewScale, Quality, StartProject};
use fogsmith::editor::session::{Session, NEW_STEP};
use fogsmith::editor::tools::Tool;
use fogsmith::editor::{EditorApp, EditorOptions};
use fogsmith::gpu::FrameRequest;
use fogsmith::scene::sidecar::SIDECAR_MIN_PARTICLES;
use fogsmith::scene::{load_project, save_project, validations_on_this_thread, Light, Particle, Project};
use glam::{UVec3, Vec3};
use std::collections::BTreeSet;
use std::path::{Path, PathBuf};

/// `n` small particles in a 4 m box, with unique ids, a few named, hidden or noise-free,
/// and coordinates that RON text could not carry bit for bit (−0, subnormals).
fn scene(n: usize) -> Project {
    let mut p = Project::default();
    p.grid.resolution = UVec3::splat(32);
    let mut rng = common::Rng(7);
    p.particles = (0..n)
        .map(|i| {
            let mut q = Particle::new(
                rng.vec3(-2.0, 2.0) + Vec3::new(0.0, 2.0, 0.0),
                rng.range(0.02, 0.06),
                rng.range(0.5, 3.5),
            );
            q.name = (i % 997 == 0).then(|| format!("dab {i} ☁"));
            q.hidden = i % 13 == 0;
            q.noise = i % 7 != 0;
            q
        })
        .collect();
    p.particles[1].center = Vec3::new(-0.0, f32::from_bits(1), 1.0 + f32::EPSILON);
    p.lights = vec![Light::new(Vec3::new(1.5, 3.0, 0.5), 5.0, Vec3::ONE)];
    p.ensure_unique_ids();
    p
}

fn sidecars(dir: &Path) -> Vec<PathBuf> {
    let mut v: Vec<PathBuf> = std::fs::read_dir(dir)
        .unwrap()
        .flatten()
        .map(|e| e.path())
        .filter(|p| p.extension().is_some_and(|e| e == "particles"))
        .collect();
    v.sort();
    v
}

fn same_bits(a: &[Particle], b: &[Particle]) {
    assert_eq!(a.len(), b.len());
    for (i, (x, y)) in a.iter().zip(b).enumerate() {
        let bits = |p: &Particle| (p.center.to_array().map(f32::to_bits), p.radius.to_bits(), p.density.to_bits());
        assert_eq!(bits(x), bits(y), "particle {i}");
        assert_eq!((x.id, &x.name, x.hidden, x.noise), (y.id, &y.name, y.hidden, y.noise), "particle {i}");
    }
}

#[test]
fn a_loaded_project_is_validated_exactly_once() {
    let dir = common::temp_dir();
    for n in [10, SIDECAR_MIN_PARTICLES + 5] {
        let path = dir.path().join(format!("p{n}.ron"));
        save_project(&path, &scene(n)).unwrap();
        let before = validations_on_this_thread();
        let p = load_project(&path).unwrap();
        assert_eq!(validations_on_this_thread() - before, 1, "{n} particles");
        assert_eq!(p.particles.len(), n);
    }
}

#[test]
fn the_pipeline_validates_nothing_per_frame_but_still_refuses_bad_settings() {
    let mut gpu = common::pipeline();
    let mut p = scene(2000);
    p.render.width = 32;
    p.render.height = 18;
    let request = FrameRequest::for_project(&p);
    let before = validations_on_this_thread();
    for _ in 0..5 {
        gpu.advance(&p, &request, Some(std::time::Duration::from_millis(5))).unwrap();
    }
    gpu.update_with(&p, &request, std::time::Duration::from_millis(5), &mut |_| true).unwrap();
    gpu.update(&p, &request).unwrap();
    assert_eq!(validations_on_this_thread(), before, "no full validation on the per-frame paths");
    let mut bad = p.clone();
    bad.camera.fov_y_deg = 200.0;
    let err = gpu.update(&bad, &request).unwrap_err().to_string();
    assert!(err.contains("camera.fov_y_deg"), "{err}");
}

#[test]
fn the_sidecar_round_trips_bit_for_bit_and_old_files_stay_until_replaced() {
    let dir = common::temp_dir();
    let path = dir.path().join("big.ron");
    let p = scene(SIDECAR_MIN_PARTICLES * 2);
    save_project(&path, &p).unwrap();
    let text = std::fs::read_to_string(&path).unwrap();
    assert!(text.contains("version: 4") && text.contains("particle_file:"), "{}", &text[..text.len().min(600)]);
    assert!(text.len() < 10_000, "the RON holds no particles: {} bytes", text.len());
    assert_eq!(sidecars(dir.path()).len(), 1);
    let loaded = load_project(&path).unwrap();
    same_bits(&loaded.particles, &p.particles);
    assert_eq!(loaded, p, "every other field too");
    // Saving the loaded project writes the same bytes.
    let first = std::fs::read(&sidecars(dir.path())[0]).unwrap();
    save_project(&path, &loaded).unwrap();
    assert_eq!(sidecars(dir.path()).len(), 1);
    assert_eq!(std::fs::read(&sidecars(dir.path())[0]).unwrap(), first);

    // A changed project: the .bak keeps the previous particles; a third save drops them.
    let mut q = loaded.clone();
    q.particles[3].radius *= 2.0;
    save_project(&path, &q).unwrap();
    assert_eq!(sidecars(dir.path()).len(), 2, "the .bak's sidecar stays");
    let bak = dir.path().join("big.ron.bak");
    same_bits(&load_project(&bak).unwrap().particles, &p.particles);
    same_bits(&load_project(&path).unwrap().particles, &q.particles);
    let mut r = q.clone();
    r.particles.truncate(SIDECAR_MIN_PARTICLES / 2);
    save_project(&path, &r).unwrap();
    assert_eq!(sidecars(dir.path()).len(), 1, "only the .bak's sidecar is left: the small project is inline");
    same_bits(&load_project(&bak).unwrap().particles, &q.particles);
    same_bits(&load_project(&path).unwrap().particles, &r.particles);
}

#[test]
fn a_damaged_sidecar_is_an_error_naming_it_and_nothing_is_lost() {
    let dir = common::temp_dir();
    let path = dir.path().join("big.ron");
    let p = scene(SIDECAR_MIN_PARTICLES);
    save_project(&path, &p).unwrap();
    let side = sidecars(dir.path()).remove(0);
    let name = side.file_name().unwrap().to_string_lossy().into_owned();
    let good = std::fs::read(&side).unwrap();
    let ron = std::fs::read(&path).unwrap();
    let mut flipped = good.clone();
    flipped[good.len() / 2] ^= 0x10;
    for (what, bytes) in [("truncated", good[..good.len() - 9].to_vec()), ("damaged", flipped)] {
        std::fs::write(&side, &bytes).unwrap();
        let err = load_project(&path).unwrap_err().to_string();
        assert!(err.contains(&name) && err.contains(what), "{what}: {err}");
        assert_eq!(std::fs::read(&side).unwrap(), bytes, "loading leaves the file as it was");
        assert_eq!(std::fs::read(&path).unwrap(), ron);
    }
    std::fs::remove_file(&side).unwrap();
    let err = load_project(&path).unwrap_err().to_string();
    assert!(err.contains(&name) && err.contains("cannot read"), "{err}");
    // An invalid particle in a sidecar names the sidecar and the particle.
    let mut bad = p.clone();
    bad.particles[42].radius = -1.0;
    save_project(&path, &bad).unwrap();
    let err = load_project(&path).unwrap_err().to_string();
    assert!(err.contains(".particles") && err.contains("particles[42].radius"), "{err}");
}

#[test]
fn undo_and_redo_across_a_large_scene_restore_every_state_and_hold_only_the_edits() {
    let n = 100_000;
    let mut s = Session::new(scene(n), None, "large.ron");
    let mut states = vec![s.project().clone()];
    // 100 dabs: a few particles each, as a paint stroke's dabs.
    let mut rng = common::Rng(3);
    for _ in 0..100 {
        let tag = s.new_tag();
        s.add_particles(tag, (0..4).map(|_| Particle::new(rng.vec3(-1.0, 1.0) + Vec3::Y * 2.0, 0.04, 2.0)));
        s.end_edit();
        states.push(s.project().clone());
    }
    let held = s.history_particles();
    assert!(held <= 100 * 4, "100 dab steps hold {held} particles, not copies of the scene");
    // Scale a scattered few, move a selection, erase, delete, and an inspector edit.
    let targets: BTreeSet<usize> = (0..n).step_by(9973).collect();
    s.scale_particles(NEW_STEP, &targets, 1.5, false);
    s.end_edit();
    states.push(s.project().clone());
    s.selection.particles = (5000..5010).chain([77_777]).collect();
    s.translate_selection(NEW_STEP, Vec3::X * 0.1);
    s.end_edit();
    states.push(s.project().clone());
    let erased = s.erase_along_ray(NEW_STEP, Vec3::new(0.0, 2.0, 8.0), Vec3::NEG_Z, 0.05);
    assert!(erased > 0);
    s.end_edit();
    states.push(s.project().clone());
    s.selection.particles = [10, 20_000, 99_000].into();
    s.delete_selection();
    s.end_edit();
    states.push(s.project().clone());
    s.edit(NEW_STEP).particles[123].density = 9.0;
    states.push(s.project().clone());
    // Until its edit ends, the last step holds every particle (the edit may change any).
    assert!(s.history_particles() >= n);
    s.end_edit();
    assert!(s.history_particles() < n / 10, "{} particles held", s.history_particles());

    let steps = states.len() - 1;
    for k in (0..steps).rev() {
        assert!(s.undo());
        assert!(s.project() == &states[k], "undo to state {k}");
    }
    assert!(!s.undo());
    for (k, state) in states.iter().enumerate().skip(1) {
        assert!(s.redo());
        assert!(s.project() == state, "redo to state {k}");
    }
    assert!(s.history_particles() < n / 10, "{} particles held after the round trip", s.history_particles());
}

#[test]
fn editor_frames_and_strokes_validate_nothing() {
    fogsmith::cli::ensure_runtime_dir();
    let project = scene(20_000);
    let start = StartProject { project, path: None, name: "large.ron".into(), error: None };
    let mut h = Harness::builder()
        .with_size(Vec2::new(1280.0, 800.0))
        .wgpu_setup(fogsmith::editor::wgpu_setup())
        .build_eframe(|cc| {
            let mut app = EditorApp::new(cc, start, EditorOptions::default());
            app.set_quality(Quality::Balanced);
            app.set_preview_scale(PreviewScale::Quarter);
            app
        });
    h.run_steps(3);
    assert_eq!(h.state().gpu_error(), None, "the preview must render");
    let before = validations_on_this_thread();
    h.state_mut().set_tool(Tool::Paint);
    let rect = h.state().viewport_rect().expect("the viewport is shown");
    let c = rect.center();
    h.hover_at(c);
    h.event(egui::Event::PointerButton {
        pos: c,
        button: PointerButton::Primary,
        pressed: true,
        modifiers: Default::default(),
    });
    for i in 0..10 {
        h.hover_at(c + Vec2::new(i as f32 * 6.0, 0.0));
        h.step();
    }
    h.event(egui::Event::PointerButton {
        pos: c,
        button: PointerButton::Primary,
        pressed: false,
        modifiers: Default::default(),
    });
    h.run_steps(10);
    assert!(h.state().session().project().particles.len() > 20_000, "the stroke painted");
    assert_eq!(validations_on_this_thread(), before, "frames and a stroke ran no full validation");
}

/// In a large scene clicks go through the particle bins: each click on a particle selects
/// what the full scan picks there, the nearest particle under the pointer.
#[test]
fn clicks_in_a_large_scene_select_what_the_scan_picks() {
    use fogsmith::editor::tools::{pick, Hit};
    use fogsmith::editor::view::ViewProjection;
    fogsmith::cli::ensure_runtime_dir();
    let project = scene(20_000);
    let start = StartProject { project, path: None, name: "large.ron".into(), error: None };
    let mut h = Harness::builder()
        .with_size(Vec2::new(1280.0, 800.0))
        .wgpu_setup(fogsmith::editor::wgpu_setup())
        .build_eframe(|cc| {
            let mut app = EditorApp::new(cc, start, EditorOptions::default());
            app.set_quality(Quality::Balanced);
            app.set_preview_scale(PreviewScale::Quarter);
            app
        });
    h.run_steps(3);
    h.state_mut().set_tool(Tool::Select);
    let rect = h.state().viewport_rect().expect("the viewport is shown");
    let project = h.state().session().project().clone();
    let view = ViewProjection::new(&project.camera, rect);
    let mut picked = 0;
    for i in (0..20_000).step_by(1999) {
        let Some((pos, _)) = view.project(project.particles[i].center).filter(|(s, _)| rect.shrink(8.0).contains(*s))
        else {
            continue;
        };
        let expected = match pick(&project, &view, pos) {
            Some(Hit::Particle(j)) => BTreeSet::from([j]),
            _ => BTreeSet::new(),
        };
        h.state_mut().session_mut().selection.clear();
        h.step();
        h.hover_at(pos);
        for pressed in [true, false] {
            h.event(egui::Event::PointerButton {
                pos,
                button: PointerButton::Primary,
                pressed,
                modifiers: Default::default(),
            });
            h.step();
        }
        assert_eq!(h.state().session().selection.particles, expected, "click on particle {i} at {pos:?}");
        picked += !expected.is_empty() as usize;
    }
    assert!(picked >= 5, "only {picked} clicks picked a particle");
}

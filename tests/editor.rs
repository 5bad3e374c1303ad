//! Drives the editor headlessly with egui_kittest on a real wgpu device (lavapipe on
//! machines without a GPU): painting, scaling, slices, undo, files, and a snapshot of the
//! default layout. Without an adapter these tests fail; they never skip.

use egui::{Event, Modifiers, PointerButton, Pos2, Vec2};
use egui_kittest::kittest::Queryable;
use egui_kittest::SnapshotOptions;
use fogsmith::editor::app::{Action, ExportChoices, PreviewScale, Quality, StartProject};
use fogsmith::editor::slices::Axis;
use fogsmith::editor::tools::Tool;
use fogsmith::editor::view::ViewProjection;
use fogsmith::editor::EditorOptions;
use fogsmith::scene::{load_project, Volume};
use std::path::PathBuf;

mod common;
use common::editor::{
    build, compare_with_fresh_bake_of, converge, demo, harness, harness_scaled, harness_with, has_label,
    progressive_harness, read_ev, wait_idle,
};
use fogsmith::editor::driver::EditorDriver;

fn max_diff(a: &Volume, b: &Volume) -> f32 {
    a.data.iter().zip(&b.data).map(|(x, y)| (x - y).abs()).fold(0.0, f32::max)
}

#[test]
fn painting_a_stroke_adds_fog_and_undo_restores_it() {
    let mut h = harness(demo());
    let rect = h.state().viewport_rect().expect("the viewport is shown");
    let before = h.state().session().project().particles.len();
    let ev_before = read_ev(&h);
    h.state_mut().set_tool(Tool::Paint);
    h.state_mut().brush_mut().spacing = 0.3;
    let c = rect.center();
    h.drag(c - Vec2::new(60.0, 0.0), c + Vec2::new(60.0, 20.0), 12);
    let after = h.state().session().project().particles.len();
    assert!(after > before + 3, "the stroke deposited particles: {before} → {after}");
    assert!(h.state().session().is_dirty());
    assert!(h.state().title().contains('●'), "title marks unsaved changes: {}", h.state().title());
    let ev_after = read_ev(&h);
    assert!(max_diff(&ev_before, &ev_after) > 0.1, "the extinction volume changed");

    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(2);
    assert_eq!(h.state().session().project().particles.len(), before, "one undo removes the whole stroke");
    assert!(!h.state().session().is_dirty() || h.state().session().path().is_none());
    assert!(max_diff(&ev_before, &read_ev(&h)) < 1e-6, "the EV is back to what it was");

    h.key_press_modifiers(Modifiers::COMMAND | Modifiers::SHIFT, egui::Key::Z);
    h.run_steps(2);
    assert_eq!(h.state().session().project().particles.len(), after, "redo brings the stroke back");
}

#[test]
fn clicking_selects_and_the_wheel_scales_the_selection() {
    let mut h = harness(demo());
    let rect = h.state().viewport_rect().expect("the viewport is shown");
    let project = h.state().session().project().clone();
    let view = ViewProjection::new(&project.camera, rect);
    // The high wisp (index 24) stands alone in front of the camera.
    let (pos, _) = view.project(project.particles[24].center).expect("in view");
    h.state_mut().set_tool(Tool::Select);
    h.event(Event::PointerMoved(pos));
    h.step();
    h.press(pos, PointerButton::Primary, true);
    h.press(pos, PointerButton::Primary, false);
    h.step();
    let sel = &h.state().session().selection;
    assert_eq!(sel.particles.iter().copied().collect::<Vec<_>>(), vec![24], "the click picked the wisp");

    h.state_mut().set_tool(Tool::Scale);
    let r0 = project.particles[24].radius;
    for _ in 0..3 {
        h.event(Event::MouseWheel {
            unit: egui::MouseWheelUnit::Point,
            delta: Vec2::new(0.0, 60.0),
            phase: egui::TouchPhase::Move,
            modifiers: Modifiers::NONE,
        });
        h.step();
    }
    let p = &h.state().session().project().particles;
    assert!(p[24].radius > r0 * 1.2, "radius grew: {r0} → {}", p[24].radius);
    assert_eq!(p[0].radius, project.particles[0].radius, "unselected particles keep their size");
    assert_eq!(p[24].density, project.particles[24].density);
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.step();
    assert_eq!(h.state().session().project().particles[24].radius, r0, "the wheel gesture is one undo step");
}

#[test]
fn the_slice_axis_and_field_follow_the_controls() {
    let mut h = harness(demo());
    h.run_steps(2);
    let s = h.state().current_slice().expect("the Slices panel shows a slice");
    assert_eq!(s.axis, Axis::Z);
    h.get_by_label("X").click();
    h.run_steps(3);
    let s = h.state().current_slice().expect("slice after changing axis");
    assert_eq!(s.axis, Axis::X);
    let project = h.state().session().project().clone();
    assert_eq!((s.width, s.height), (project.grid.resolution.z as usize, project.grid.resolution.y as usize));
    let ev = read_ev(&h);
    let (x, y) = (s.width / 2, s.height / 2);
    let [i, j, k] = s.cell(x, y);
    assert_eq!(s.get(x, y), ev.get(i, j, k), "the slice shows the EV values");

    h.state_mut().slice_settings_mut().field = fogsmith::editor::slices::Field::Transmittance;
    h.run_steps(3);
    let s = h.state().current_slice().expect("transmittance slice");
    assert!(s.values.iter().all(|v| (0.0..=1.0).contains(v)), "exp(−T) lies in [0, 1]");

    h.state_mut().slice_settings_mut().field = fogsmith::editor::slices::Field::Error;
    for _ in 0..3000 {
        h.step();
        if h.state().busy() == 0 && h.state().current_slice().is_some_and(|s| s.values.iter().any(|v| *v > 0.0)) {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    let s = h.state().current_slice().expect("error slice from the CPU reference");
    let worst = s.values.iter().copied().fold(0.0f32, f32::max);
    assert!(s.values.iter().all(|v| v.is_finite() && *v >= 0.0), "|T − T_exact| is a finite magnitude");
    assert!(worst > 0.0 && worst < 2.0, "the pipeline's optical depth is close to the exact one (worst {worst})");
}

#[test]
fn save_and_reopen_round_trip() {
    let dir = common::temp_dir();
    let path: PathBuf = dir.path().join("scene.ron");
    let mut h = harness(demo());
    let rect = h.state().viewport_rect().expect("viewport");
    h.state_mut().set_tool(Tool::Paint);
    h.drag(rect.center(), rect.center() + Vec2::new(40.0, -30.0), 6);
    h.state_mut().save_as(path.clone());
    wait_idle(&mut h);
    assert!(!h.state().session().is_dirty(), "saved: {:?}", h.state().messages());
    assert!(h.state().title().starts_with("scene.ron"), "{}", h.state().title());
    let saved = h.state().session().project().clone();
    assert_eq!(load_project(&path).expect("the saved file loads"), saved);

    h.state_mut().request(Action::New);
    h.step();
    assert!(h.state().session().project().particles.is_empty());
    h.state_mut().request(Action::Open(path.clone()));
    wait_idle(&mut h);
    assert_eq!(h.state().session().project(), &saved);
    assert_eq!(h.state().session().path(), Some(path.as_path()));

    let vdb = dir.path().join("scene.vdb");
    h.state_mut().export(ExportChoices::default(), vdb.clone());
    wait_idle(&mut h);
    let names: Vec<String> = fogsmith::export::vdb_read::list_vdb_grids(&vdb)
        .expect("the exported VDB reads back")
        .into_iter()
        .map(|g| g.name)
        .collect();
    assert_eq!(names, ["density", "optical_depth_0", "optical_depth_1"]);
}

#[test]
fn unsaved_changes_ask_before_they_are_discarded_and_errors_are_shown() {
    let mut h = harness(demo());
    h.state_mut().session_mut().select_all();
    h.key_press(egui::Key::Delete);
    h.step();
    assert!(h.state().session().project().particles.is_empty());
    h.state_mut().request(Action::New);
    h.run_steps(2);
    h.get_by_label("Unsaved changes");
    h.get_by_label("Cancel").click();
    h.run_steps(2);
    assert!(h.state().session().is_dirty(), "cancel keeps the edits");

    h.state_mut().request(Action::New);
    h.run_steps(2);
    h.get_by_label("Discard").click();
    h.run_steps(2);
    h.state_mut().request(Action::Open(PathBuf::from("/nonexistent/nowhere.ron")));
    wait_idle(&mut h);
    let messages = h.state().messages();
    assert!(messages.iter().any(|(error, text)| *error && text.contains("nowhere.ron")), "{messages:?}");
}

#[test]
fn default_layout_snapshot() {
    let mut h = harness_scaled(demo(), EditorOptions::default(), PreviewScale::Full);
    h.run_steps(4);
    // The preview comes from a software rasteriser or a GPU; small differences are allowed.
    let options = SnapshotOptions::new().threshold(6.0).max_failed_pixels(4000);
    h.snapshot_options("editor_layout", &options);
}

/// The Inspector's "multiple scattering" box turns medium.multiple_scattering off and on as one
/// undo step each, and the preview then renders without and with it (less light without).
#[test]
fn the_multiple_scattering_box_edits_the_project_and_undoes() {
    let mut h = harness(demo());
    let on = |h: &EditorDriver| h.state().session().project().medium.multiple_scattering.is_some();
    assert!(on(&h), "the demo has multiple scattering on");
    converge(&mut h);
    let mean = |h: &EditorDriver| {
        let image = h.state().pipeline().unwrap().read_image().unwrap();
        image.rgba.iter().map(|p| (p[0] + p[1] + p[2]) as f64).sum::<f64>()
    };
    let with = mean(&h);
    h.get_by_label("multiple scattering").click();
    h.run_steps(2);
    assert!(!on(&h), "the box turned multiple scattering off");
    converge(&mut h);
    assert!(mean(&h) < with, "the preview did not lose the multiply scattered light");
    assert_eq!(h.state().gpu_error(), None);
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(2);
    assert!(on(&h), "undo turns it on again");
}

/// The Inspector's "refine thin shadows" box sets propagation.sweep_refine as one undo step,
/// and its tolerance field shows only while it is on.
#[test]
fn the_sweep_refine_box_edits_the_project_and_undoes() {
    let mut h = harness(demo());
    assert!(h.state().session().project().propagation.sweep_refine);
    assert!(h.query_by_label_contains("tolerance").is_some(), "the tolerance shows while refine is on");
    h.get_by_label("refine thin shadows").click();
    h.run_steps(2);
    assert!(!h.state().session().project().propagation.sweep_refine, "the box turned sweep_refine off");
    assert!(h.query_by_label_contains("tolerance").is_none(), "the tolerance hides while refine is off");
    assert_eq!(h.state().gpu_error(), None);
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(2);
    assert!(h.state().session().project().propagation.sweep_refine, "undo turns it on again");
}

/// The toolbar's resolution control sets the preview's pixels per screen pixel.
#[test]
fn the_preview_resolution_follows_its_control() {
    let mut h = harness(demo());
    let rect = h.state().viewport_rect().expect("the viewport is shown");
    let quarter = h.state().preview_size();
    assert_eq!(quarter[0], (rect.width() * 0.25).round() as u32, "¼ res: {quarter:?} for {rect:?}");
    h.get_by_label("preview res").click();
    h.run_steps(2);
    h.get_by_label("½").click();
    h.run_steps(3);
    let half = h.state().preview_size();
    assert_eq!(half, [(rect.width() * 0.5).round() as u32, (rect.height() * 0.5).round() as u32]);
    assert_eq!(h.state().gpu_error(), None);
    let image = h.state().pipeline().unwrap().read_image().unwrap();
    assert_eq!((image.width, image.height), (half[0], half[1]), "the preview renders at the chosen resolution");
}

/// Picks `choice` in the viewport's preview menu and lets the preview render.
fn choose_preview(h: &mut EditorDriver, choice: &str) {
    h.get_by_label("preview").click();
    h.run_steps(2);
    h.get_by_label(choice).click();
    h.run_steps(3);
    assert_eq!(h.state().gpu_error(), None, "{choice}");
}

/// "as baked" in the preview menu shows the bake as an engine draws it (no lights), which is
/// not the lit preview; the camera mode differs from the isotropic one where g ≠ 0; going back
/// to the lit preview shows its image again, bit for bit.
#[test]
fn the_as_baked_preview_switches_on_and_back_to_the_lit_one() {
    let mut h = harness(demo());
    assert!(h.state().session().project().medium.anisotropy != 0.0, "the demo must have g ≠ 0");
    let shown = |h: &EditorDriver| h.state().shown_preview().expect("a preview").expect("readback");
    let lit = shown(&h);
    choose_preview(&mut h, "as baked (isotropic)");
    let iso = shown(&h);
    assert_eq!((iso.width, iso.height), (lit.width, lit.height));
    let differ = |a: &fogsmith::gpu::Image, b: &fogsmith::gpu::Image| {
        a.rgba
            .iter()
            .zip(&b.rgba)
            .filter(|(p, q)| (0..3).any(|c| (p[c] - q[c]).abs() > 1e-3 * q[c].abs().max(1e-3)))
            .count()
    };
    assert!(iso.rgba.iter().any(|p| p[0] > 0.0), "the bake's render is black");
    assert!(differ(&iso, &lit) > lit.rgba.len() / 10, "the as-baked image must not be the lit one");
    choose_preview(&mut h, "as baked (camera)");
    let camera = shown(&h);
    assert!(differ(&camera, &iso) > lit.rgba.len() / 10, "for g ≠ 0 the camera bake differs from the isotropic one");
    choose_preview(&mut h, "wait for full");
    let back = shown(&h);
    assert!(back.rgba == lit.rgba, "the lit preview must come back bit for bit");
}

#[test]
fn unsaved_work_leaves_a_recovery_file_that_the_next_start_offers() {
    let dir = common::temp_dir();
    let options = EditorOptions { recovery: true, state_dir: Some(dir.path().to_owned()), ..EditorOptions::default() };
    let mut h = harness_with(demo(), options.clone());
    h.state_mut().session_mut().select_all();
    h.key_press(egui::Key::Delete);
    h.step();
    let mut files = Vec::new();
    for _ in 0..400 {
        h.step();
        files = std::fs::read_dir(dir.path()).expect("state dir").filter_map(Result::ok).map(|e| e.path()).collect();
        if !files.is_empty() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    assert_eq!(files.len(), 1, "one recovery file while there are unsaved changes");
    drop(h);

    let mut h = harness_with(demo(), options);
    h.get_by_label("Recover unsaved work");
    h.get_by_label("Restore").click();
    h.run_steps(2);
    wait_idle(&mut h);
    assert!(h.state().session().project().particles.is_empty(), "the recovered work replaced the demo");
    assert!(h.state().session().is_dirty(), "recovered work is unsaved");
}

/// A project whose particles live in a sidecar opens off the UI thread with the steps of its
/// load reported as the terminal's progress bar names them, and so does restoring a large
/// recovery file; the editor keeps drawing frames meanwhile.
#[test]
fn a_large_project_opens_and_restores_with_the_steps_of_its_load() {
    use fogsmith::scene::{save_project, Particle, Project};
    let dir = common::temp_dir();
    let particles = (0..12_000)
        .map(|i| {
            let t = i as f32 / 12_000.0;
            Particle::new(glam::Vec3::new(t * 3.0 - 1.5, 1.0 + (t * 40.0).sin() * 0.5, (t * 23.0).cos()), 0.05, 1.5)
        })
        .collect();
    let mut project = Project { particles, ..Project::default() };
    project.ensure_unique_ids();
    let path = dir.path().join("large.ron");
    save_project(&path, &project).expect("the large project saves");
    let text = std::fs::read_to_string(&path).expect("the RON");
    assert!(text.contains("particle_file"), "the particles are in a sidecar");
    let expected = load_project(&path).expect("it loads");
    let steps = ["reading", "parsing", "reading particles", "validating"];

    let state_dir = dir.path().join("state");
    let options = EditorOptions { recovery: true, state_dir: Some(state_dir.clone()), ..EditorOptions::default() };
    let mut h = harness_with(demo(), options.clone());
    let generation = h.state().session().generation();
    h.state_mut().request(Action::Open(path.clone()));
    // The job's result is taken in at a frame's start, so until then it is still listed,
    // however fast the thread: the request returned without loading.
    assert!(h.state().busy() > 0, "the load runs in the background");
    assert_eq!(h.state().session().generation(), generation, "the old project stays until the new one is in");
    wait_idle(&mut h);
    assert_eq!(h.state().session().project(), &expected, "{:?}", h.state().messages());
    assert_eq!(h.state().session().path(), Some(path.as_path()));
    assert_eq!(h.state().load_steps(), steps);

    // Unsaved work on it leaves a recovery file with a sidecar; the next start lists it
    // without reading the particles and restores it with the same steps but parsing, which
    // the listing did.
    h.state_mut().session_mut().add_particles(0, [Particle::new(glam::Vec3::ONE, 0.2, 1.0)]);
    let edited = h.state().session().project().clone();
    for _ in 0..400 {
        h.step();
        let found = fogsmith::scene::recovery::find_recoveries(&state_dir);
        if found.first().and_then(|f| f.as_ref().ok()).is_some_and(|(_, r)| r.project == edited) {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(10));
    }
    drop(h);
    let mut h = harness_with(demo(), options);
    h.get_by_label("Recover unsaved work");
    h.get_by_label_contains("12001 particles");
    h.get_by_label("Restore").click();
    h.run_steps(2);
    wait_idle(&mut h);
    assert_eq!(h.state().session().project(), &edited, "{:?}", h.state().messages());
    assert!(h.state().session().is_dirty(), "restored work is unsaved");
    assert_eq!(h.state().load_steps(), ["reading", "reading particles", "validating"]);
}

/// Recovery keeps every stroke: with no frame after the stroke's release (an idle editor) and
/// no clean exit (a crash), the recovery file holds the project as it was at the release, and
/// the next start restores exactly that.
#[test]
fn an_idle_crash_after_a_stroke_recovers_the_project_at_release() {
    let dir = common::temp_dir();
    let options = EditorOptions { recovery: true, state_dir: Some(dir.path().to_owned()), ..EditorOptions::default() };
    let mut h = harness_with(demo(), options.clone());
    let rect = h.state().viewport_rect().expect("the viewport is shown");
    h.state_mut().set_tool(Tool::Paint);
    h.state_mut().brush_mut().spacing = 0.3;
    let c = rect.center();
    let before = h.state().session().project().particles.len();
    h.drag(c - Vec2::new(60.0, 0.0), c + Vec2::new(60.0, 20.0), 12);
    let at_release = h.state().session().project().clone();
    assert!(at_release.particles.len() > before + 3, "the stroke deposited particles");
    // Idle: no input and no frame from here on. The file is written off the UI thread.
    let mut on_disk = None;
    for _ in 0..400 {
        let found = fogsmith::scene::recovery::find_recoveries(dir.path());
        on_disk = found.into_iter().next().and_then(Result::ok).map(|(_, r)| r.project);
        if on_disk.as_ref() == Some(&at_release) {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(25));
    }
    let on_disk = on_disk.expect("a recovery file for the unsaved stroke");
    assert_eq!(
        on_disk.particles.len(),
        at_release.particles.len(),
        "the recovery file holds the whole stroke, not the state at an earlier dab"
    );
    assert_eq!(on_disk, at_release);
    // The crash: the editor never exits cleanly.
    std::mem::forget(h);

    let mut h = harness_with(demo(), options);
    h.get_by_label("Recover unsaved work");
    h.get_by_label("Restore").click();
    h.run_steps(2);
    wait_idle(&mut h);
    assert_eq!(h.state().session().project(), &at_release, "the restored project is the one at the release");
}

/// The frame-budgeted preview: a dragged light's glow is on show in the frame of each move,
/// and once the preview converges it equals a from-scratch bake of the
/// same scene, bit for bit.
#[test]
fn a_dragged_light_shows_every_frame_and_the_preview_converges_to_the_fresh_bake() {
    let mut h = progressive_harness();
    converge(&mut h);
    assert_eq!(h.state().gpu_error(), None);
    let rect = h.state().viewport_rect().expect("the viewport is shown");
    let project = h.state().session().project().clone();
    let view = ViewProjection::new(&project.camera, rect);
    let (light, _) = project
        .lights
        .iter()
        .filter_map(|l| view.project(l.position))
        .find(|(p, _)| rect.shrink(20.0).contains(*p))
        .expect("a light in view");
    h.state_mut().set_tool(Tool::Select);
    h.event(Event::PointerMoved(light));
    h.step();
    h.press(light, PointerButton::Primary, true);
    // Small steps, as a pointer moves between frames: the drag starts on the light.
    for k in 1..=6 {
        h.event(Event::PointerMoved(light + Vec2::new(4.0 * k as f32, -2.0 * k as f32)));
        h.step();
        let status = h.state().preview_status().expect("a preview");
        assert_eq!(
            status.shown_generation,
            Some(h.state().session().generation()),
            "move {k}: the frame of the move shows the moved light"
        );
    }
    let moved = h.state().session().project().lights.clone();
    assert_ne!(moved, project.lights, "the drag moved a light");
    h.press(light + Vec2::new(24.0, -12.0), PointerButton::Primary, false);
    converge(&mut h);

    let status = h.state().preview_status().unwrap();
    assert!(!status.shadows_stale);
    let shown = h.state().pipeline().unwrap().read_image().unwrap();
    assert_eq!([shown.width, shown.height], status.shown_size);
    let (differing, diff, peak) = compare_with_fresh_bake(&h);
    eprintln!("converged vs fresh: max difference {diff:e} of peak {peak:e}, {differing} values differ");
    assert!(differing == 0, "the converged preview equals a fresh bake: max difference {diff:e} of peak {peak:e}, {differing} values differ");
}

/// An edit that changes nothing the preview shows (a particle renamed) is on show in the frame
/// of the edit, with the image it already had: no input waits for an image that will not come.
#[test]
fn an_edit_that_changes_nothing_on_show_is_shown_at_once() {
    let mut h = progressive_harness();
    // Single scattering: the density edit's frame has missed its image under load, with the
    // demo's multiple scattering on (README, "Multiple scattering"); this keeps the case that
    // passed before it existed.
    h.state_mut().session_mut().edit(fogsmith::editor::session::NEW_STEP).medium.multiple_scattering = None;
    h.step_until_converged(5000);
    let before = h.state().preview_status().expect("a preview");
    assert!(before.converged, "the preview converged");
    h.state_mut().session_mut().edit(fogsmith::editor::session::NEW_STEP).particles[0].name = Some("renamed".into());
    h.step();
    let after = h.state().preview_status().unwrap();
    assert_eq!(after.shown_generation, Some(h.state().session().generation()), "the rename is on show");
    assert_eq!(after.renders, before.renders, "with no new image");
    // A change the image shows is on show only with its own image.
    h.state_mut().session_mut().edit(fogsmith::editor::session::NEW_STEP).particles[0].density *= 3.0;
    h.step();
    let painted = h.state().preview_status().unwrap();
    assert_eq!(painted.shown_generation, Some(h.state().session().generation()));
    assert!(painted.renders > after.renders, "the denser particle got a new image");
}

/// The preview image against a fresh bake of the session's project at the same size: how
/// many values differ in their bits, the largest difference and the fresh bake's peak.
fn compare_with_fresh_bake(h: &EditorDriver) -> (usize, f32, f32) {
    compare_with_fresh_bake_of(h, &h.state().session().project().clone())
}

fn differs_from_fresh_bake(h: &EditorDriver) -> usize {
    compare_with_fresh_bake(h).0
}

/// The Inspector's kind selector turns a point light into a sun and a spot: each is one undo
/// step, the light takes that kind (a spot aimed at the grid's centre), and the preview
/// renders it as that kind, equal to a fresh bake of the changed project.
#[test]
fn a_light_kind_changed_in_the_inspector_renders_as_that_kind() {
    use fogsmith::scene::LightKind;
    let mut h = harness(demo());
    h.state_mut().session_mut().selection.lights.insert(0);
    h.run_steps(3);
    let point_image = h.state().pipeline().unwrap().read_image().unwrap();
    let undo = h.state().session().undo_len();
    h.get_by_label("sun").click();
    h.run_steps(3);
    let light = h.state().session().project().lights[0].clone();
    assert!(matches!(light.kind, LightKind::Directional { .. }), "the light is a sun: {light:?}");
    assert_eq!(h.state().session().undo_len(), undo + 1, "one undo step");
    h.get_by_label("irradiance");
    assert_eq!(h.state().gpu_error(), None);
    let sun_image = h.state().pipeline().unwrap().read_image().unwrap();
    assert_ne!(sun_image.rgba, point_image.rgba, "the sun lights the fog differently");
    assert_eq!(differs_from_fresh_bake(&h), 0, "the preview renders the sun as a fresh bake does");

    h.get_by_label("spot").click();
    h.run_steps(3);
    let p = h.state().session().project().clone();
    let LightKind::Spot { direction, angle_deg, .. } = p.lights[0].kind else { panic!("a spot: {:?}", p.lights[0]) };
    let centre = (p.grid.min + p.grid.max) * 0.5;
    assert!(direction.dot((centre - p.lights[0].position).normalize()) > 0.999, "aimed at the centre");
    assert!(angle_deg > 0.0 && angle_deg <= 90.0);
    h.get_by_label("angle");
    h.get_by_label("blend");
    assert_eq!(differs_from_fresh_bake(&h), 0, "the preview renders the spot as a fresh bake does");

    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(3);
    assert!(matches!(h.state().session().project().lights[0].kind, LightKind::Point), "two undos: a point again");
    assert_eq!(differs_from_fresh_bake(&h), 0);
}

/// The artist's steps of the report: point → spot → sun → point in the Inspector. The light
/// ends where it started, with the power it started with, and the preview is lit as before.
#[test]
fn a_kind_round_trip_in_the_inspector_keeps_the_lights_position_and_power() {
    use fogsmith::scene::LightKind;
    let mut h = harness(demo());
    h.state_mut().session_mut().selection.lights.insert(0);
    h.run_steps(3);
    let start = h.state().session().project().lights[0].clone();
    assert!(matches!(start.kind, LightKind::Point), "the demo's light 0 is a point light: {start:?}");
    for kind in ["spot", "sun", "point"] {
        h.get_by_label(kind).click();
        h.run_steps(3);
        let l = &h.state().session().project().lights[0];
        assert!(
            (l.position - start.position).length() < 1e-4,
            "after {kind}: at {} (was {})",
            l.position,
            start.position
        );
    }
    let end = h.state().session().project().lights[0].clone();
    assert!(matches!(end.kind, LightKind::Point), "a point light again: {end:?}");
    assert!(
        (end.intensity - start.intensity).abs() <= 1e-4 * start.intensity,
        "power {} W/sr, was {} W/sr",
        end.intensity,
        start.intensity
    );
    assert_eq!(differs_from_fresh_bake(&h), 0, "the preview renders the restored light as a fresh bake does");
}

fn street_wind() -> StartProject {
    let path = PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("projects/street-wind.ron");
    StartProject::resolve(Some(path)).expect("the bundled street-wind demo loads")
}

fn outside_box(p: &fogsmith::scene::Project, from: usize) -> Vec<glam::Vec3> {
    let g = p.grid;
    p.particles[from..].iter().map(|q| q.center).filter(|c| c.cmplt(g.min).any() || c.cmpgt(g.max).any()).collect()
}

/// The report's steps on street-wind: B, then strokes across the upper middle of the
/// viewport and across its middle. Every painted particle lies inside the grid box, the
/// middle stroke paints fog, and while the brush looks past the box the viewport says so.
#[test]
fn painting_keeps_particles_inside_the_grid_and_says_when_it_cannot() {
    let mut h = harness(street_wind());
    let rect = h.state().viewport_rect().expect("viewport");
    h.shortcut(Modifiers::NONE, egui::Key::B);
    assert_eq!(h.state().tool(), Tool::Paint);
    let before = h.state().session().project().particles.len();
    let mut told = false;
    for y in [0.12, 0.3, 0.5] {
        let (a, b) = (rect.lerp_inside(Vec2::new(0.2, y)), rect.lerp_inside(Vec2::new(0.8, y)));
        h.move_to(a);
        h.press(a, PointerButton::Primary, true);
        for k in 1..=10 {
            h.move_to(a + (b - a) * (k as f32 / 10.0));
            told |= h.state().viewport_notice().is_some();
        }
        h.press(b, PointerButton::Primary, false);
        h.run_steps(2);
        assert_eq!(h.state().viewport_notice(), None, "the notice goes with the stroke");
    }
    let p = h.state().session().project();
    assert!(p.particles.len() > before + 10, "the strokes painted: {before} → {}", p.particles.len());
    assert_eq!(outside_box(p, before), Vec::<glam::Vec3>::new(), "no painted particle outside the grid box");
    // The top of street-wind's view looks over the box: part of the first stroke could not paint.
    let g = p.grid;
    let view = ViewProjection::new(&p.camera, rect);
    let misses = (0..=10).any(|k| {
        let at = rect.lerp_inside(Vec2::new(0.2 + 0.06 * k as f32, 0.12));
        fogsmith::editor::tools::into_grid_along_ray(&g, view.position, view.ray(at), view.position).is_none()
    });
    assert_eq!(told, misses, "the viewport says so exactly when the brush looked past the box");
}

/// Particles poking out of the box bring the warning over the viewport, which neither moves
/// nor shrinks: a press aimed at a handle lands where it was aimed.
#[test]
fn the_grid_warning_moves_no_viewport_pixel() {
    let mut start = demo();
    let crossing = start.project.particles_crossing_grid();
    let mut k = 0;
    start.project.particles.retain(|_| {
        k += 1;
        !crossing.contains(&(k - 1))
    });
    assert!(start.project.particles_crossing_grid().is_empty());
    let mut h = harness(start);
    h.run_steps(2);
    assert!(!has_label(&h, "Fit grid to particles"), "no warning while every particle is inside");
    let rect = h.state().viewport_rect().expect("viewport");
    let g = h.state().session().project().grid;
    let c = (g.min + g.max) * 0.5;
    h.state_mut()
        .session_mut()
        .add_particles(0, [fogsmith::scene::Particle::new(glam::Vec3::new(c.x, c.y, g.max.z + 0.5), 0.3, 2.0)]);
    h.run_steps(3);
    h.get_by_label("Fit grid to particles");
    assert_eq!(h.state().viewport_rect(), Some(rect), "the viewport stays where it was");
}

/// In "wait for full" mode, B and a stroke at once (the artist's hand is faster than a full
/// frame, so they arrive in one frame's input) paint the stroke as one undo step.
#[test]
fn a_stroke_right_after_pressing_b_lands() {
    let mut h = harness(demo());
    h.state_mut().set_tool(Tool::Select);
    h.run_steps(2);
    let rect = h.state().viewport_rect().expect("viewport");
    let (a, b) = (rect.center() - Vec2::new(60.0, 0.0), rect.center() + Vec2::new(60.0, 10.0));
    // Each event in a frame of its own; the key in one frame and the stroke in the next; all
    // of it in one frame.
    for (batched, key_apart) in [(false, true), (true, true), (true, false)] {
        h.state_mut().set_tool(Tool::Select);
        h.move_to(a);
        let before = h.state().session().project().particles.len();
        let undo = h.state().session().undo_len();
        h.key_press(egui::Key::B);
        if key_apart {
            h.step();
        }
        h.event(Event::PointerButton {
            pos: a,
            button: PointerButton::Primary,
            pressed: true,
            modifiers: Modifiers::NONE,
        });
        if !batched {
            h.step();
        }
        for k in 1..=8 {
            h.event(Event::PointerMoved(a + (b - a) * (k as f32 / 8.0)));
            if !batched {
                h.step();
            }
        }
        h.event(Event::PointerButton {
            pos: b,
            button: PointerButton::Primary,
            pressed: false,
            modifiers: Modifiers::NONE,
        });
        h.run_steps(3);
        assert_eq!(h.state().tool(), Tool::Paint);
        let after = h.state().session().project().particles.len();
        assert!(after > before + 3, "batched {batched}: the stroke painted: {before} → {after}");
        assert_eq!(h.state().session().undo_len(), undo + 1, "batched {batched}: one undo step");
    }
}

fn screen_of(h: &EditorDriver, p: glam::Vec3) -> Pos2 {
    let rect = h.state().viewport_rect().expect("viewport");
    ViewProjection::new(&h.state().session().project().camera, rect).project(p).expect("in view").0
}

/// The mouse keeps moving in the frame where the button is released: the stroke ends at the
/// release, as one undo step.
#[test]
fn a_stroke_stops_where_the_button_is_released() {
    let mut h = harness(demo());
    let rect = h.state().viewport_rect().expect("viewport");
    h.state_mut().set_tool(Tool::Paint);
    *h.state_mut().brush_mut() =
        fogsmith::editor::tools::Brush { radius: 0.1, density: 2.0, spacing: 0.3, jitter: 0.0, ..Default::default() };
    let before = h.state().session().project().particles.len();
    let undo_before = h.state().session().undo_len();
    let (a, b) = (rect.center() - Vec2::new(60.0, 0.0), rect.center() + Vec2::new(20.0, 0.0));
    let far = rect.right_bottom() - Vec2::new(4.0, 4.0);
    h.event(Event::PointerMoved(a));
    h.step();
    h.press(a, PointerButton::Primary, true);
    for k in 1..=6 {
        h.event(Event::PointerMoved(a + (b - a) * (k as f32 / 6.0)));
        h.step();
    }
    // One frame holds the release and the moves after it, as when frames are slow.
    h.input_mut().events.push(Event::PointerButton {
        pos: b,
        button: PointerButton::Primary,
        pressed: false,
        modifiers: Modifiers::NONE,
    });
    h.input_mut().events.push(Event::PointerMoved(far - Vec2::new(100.0, 0.0)));
    h.input_mut().events.push(Event::PointerMoved(far));
    h.step();
    for k in 1..=4 {
        h.event(Event::PointerMoved(far - Vec2::new(10.0 * k as f32, 0.0)));
        h.step();
    }
    let particles = h.state().session().project().particles.clone();
    assert!(particles.len() > before + 5, "the stroke painted: {before} → {}", particles.len());
    for p in &particles[before..] {
        let s = screen_of(&h, p.center);
        assert!(
            s.x >= a.x - 1.0 && s.x <= b.x + 1.0 && (s.y - a.y).abs() < 1.0,
            "a dab at {s:?} lies off the stroke {a:?} → {b:?}"
        );
    }
    assert_eq!(h.state().session().undo_len(), undo_before + 1, "the stroke is one undo step");
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.step();
    assert_eq!(h.state().session().project().particles.len(), before, "one undo removes the whole stroke");
}

fn wheel(modifiers: Modifiers) -> Event {
    Event::MouseWheel {
        unit: egui::MouseWheelUnit::Point,
        delta: Vec2::new(0.0, 50.0),
        phase: egui::TouchPhase::Move,
        modifiers,
    }
}

/// Alt is read per wheel event: an Alt+wheel that starts and ends within one frame changes
/// the density only, and a plain wheel event in the same frame changes the radius only.
#[test]
fn alt_wheel_changes_density_only() {
    let mut h = harness(demo());
    let project = h.state().session().project().clone();
    let pos = screen_of(&h, project.particles[24].center);
    h.state_mut().session_mut().selection.particles = [24].into();
    h.state_mut().set_tool(Tool::Scale);
    h.event(Event::PointerMoved(pos));
    h.step();
    // A quick Alt+wheel: the key goes down and up within the frame, around the wheel events.
    h.input_mut().events.push(wheel(Modifiers::ALT));
    h.input_mut().events.push(wheel(Modifiers::ALT));
    h.step();
    let f = (100.0f32 * 0.002).exp();
    let p = &h.state().session().project().particles[24];
    assert_eq!(p.radius, project.particles[24].radius, "Alt+wheel leaves the radius alone");
    assert!(
        (p.density / project.particles[24].density - f).abs() < 1e-4,
        "density × {f}: {} → {}",
        project.particles[24].density,
        p.density
    );
    let d = p.density;
    h.input_mut().events.push(wheel(Modifiers::ALT));
    h.input_mut().events.push(wheel(Modifiers::NONE));
    h.step();
    let p = &h.state().session().project().particles[24];
    let g = (50.0f32 * 0.002).exp();
    assert!((p.radius / project.particles[24].radius - g).abs() < 1e-4, "the plain wheel event scaled the radius");
    assert!((p.density / d - g).abs() < 1e-4, "the Alt+wheel event scaled the density");
}

/// Dragging a light with the Light tool moves it, however fast the drag starts; dragging
/// on empty space adds a light and places it, as one undo step.
#[test]
fn the_light_tool_drags_lights() {
    let mut h = harness(demo());
    h.state_mut().set_tool(Tool::Light);
    // The toolbar shows the Light tool's options from the next frame.
    h.run_steps(2);
    let n = h.state().session().project().lights.len();
    let from = screen_of(&h, h.state().session().project().lights[0].position);
    let to = from + Vec2::new(45.0, 30.0);
    h.event(Event::PointerMoved(from));
    h.step();
    h.press(from, PointerButton::Primary, true);
    h.event(Event::PointerMoved(to));
    h.step();
    h.step();
    h.press(to, PointerButton::Primary, false);
    h.step();
    let lights = &h.state().session().project().lights;
    assert_eq!(lights.len(), n, "dragging a light adds none");
    let s = screen_of(&h, lights[0].position);
    assert!(s.distance(to) < 1.0, "the light follows the pointer: at {s:?}, pointer at {to:?}");
    assert_eq!(h.state().session().selection.lights.iter().copied().collect::<Vec<_>>(), vec![0]);

    let rect = h.state().viewport_rect().expect("viewport");
    let (a, b) = (rect.center() + Vec2::new(-80.0, 60.0), rect.center() + Vec2::new(-20.0, 80.0));
    let undo = h.state().session().undo_len();
    h.drag(a, b, 4);
    let lights = &h.state().session().project().lights;
    assert_eq!(lights.len(), n + 1, "a drag on empty space adds one light");
    assert!(screen_of(&h, lights[n].position).distance(b) < 1.0, "placed where the drag ended");
    assert_eq!(h.state().session().undo_len(), undo + 1, "adding and placing is one undo step");

    // With "sun" chosen in the toolbar a click on empty space adds a sun, shining from where
    // the click was towards the grid's centre, and dragging its icon re-aims it. (Nothing
    // selected, so the only "sun" is the toolbar's, not the Inspector's.)
    h.state_mut().session_mut().selection.clear();
    h.run_steps(2);
    h.get_by_label("sun").click();
    h.run_steps(2);
    let c = rect.center() + Vec2::new(-60.0, -40.0);
    h.press(c, PointerButton::Primary, true);
    h.press(c, PointerButton::Primary, false);
    h.run_steps(2);
    let p = h.state().session().project().clone();
    assert_eq!(p.lights.len(), n + 2, "the click added a light");
    let fogsmith::scene::LightKind::Directional { direction } = p.lights[n + 1].kind else {
        panic!("the new light is a sun: {:?}", p.lights[n + 1])
    };
    let anchor = p.light_anchor(&p.lights[n + 1]);
    let centre = (p.grid.min + p.grid.max) * 0.5;
    assert!((anchor - (centre - direction.normalize() * p.sun_distance())).length() < 1e-4);
    let from = screen_of(&h, anchor);
    h.drag(from, from + Vec2::new(50.0, 30.0), 4);
    let fogsmith::scene::LightKind::Directional { direction: turned } =
        h.state().session().project().lights[n + 1].kind
    else {
        panic!("still a sun")
    };
    assert!(turned.angle_between(direction) > 1e-3, "dragging the sun re-aims it: {direction} → {turned}");
    assert_eq!(h.state().session().project().lights.len(), n + 2, "dragging the sun adds no light");
}

/// A selected spot shows an aim handle at the tip of its axis; dragging it points the spot
/// at the pointer (one undo step), and a press beside the handle does not aim.
#[test]
fn dragging_a_spots_aim_handle_points_it() {
    use fogsmith::scene::LightKind;
    let mut h = harness(StartProject::resolve(Some(PathBuf::from("projects/room.ron"))).expect("room"));
    let spot = h.state().session().project().lights.iter().position(|l| matches!(l.kind, LightKind::Spot { .. }));
    let i = spot.expect("room.ron has a spot");
    h.state_mut().session_mut().selection.lights.insert(i);
    h.run_steps(2);
    let before = h.state().session().project().clone();
    let tip = before.spot_tip(&before.lights[i]).expect("a spot has a tip");
    let from = screen_of(&h, tip);
    let to = from + Vec2::new(40.0, -25.0);
    let undo = h.state().session().undo_len();
    h.drag(from, to, 4);
    let p = h.state().session().project().clone();
    let LightKind::Spot { direction, .. } = p.lights[i].kind else { panic!("still a spot: {:?}", p.lights[i]) };
    let LightKind::Spot { direction: old, .. } = before.lights[i].kind else { unreachable!() };
    assert!(direction.angle_between(old) > 0.05, "the drag turned the spot: {old} → {direction}");
    assert_eq!(p.lights[i].position, before.lights[i].position, "aiming does not move the spot");
    let new_tip = p.spot_tip(&p.lights[i]).expect("tip");
    let on_screen = screen_of(&h, new_tip);
    // The axis passes under the pointer (the tip itself sits at a fixed distance along it).
    let (a, b) = (screen_of(&h, p.lights[i].position), on_screen);
    let (u, w) = (b - a, to - a);
    let off_axis = (u.x * w.y - u.y * w.x).abs() / u.length();
    assert!(off_axis < 1.5, "the axis points at the pointer: {off_axis} px off");
    assert_eq!(h.state().session().undo_len(), undo + 1, "one undo step");
    h.state_mut().session_mut().undo();
    assert_eq!(h.state().session().project().lights[i], before.lights[i], "undo restores the aim");

    // A press well beside the handle, on empty space, does not aim the spot.
    let aside = from + Vec2::new(0.0, 60.0);
    h.drag(aside, aside + Vec2::new(30.0, 0.0), 3);
    assert_eq!(h.state().session().project().lights[i].kind, before.lights[i].kind);
}

/// The EV slice shows the volume after an erase, without touching the slice controls.
#[test]
fn the_ev_slice_follows_an_erase() {
    let mut h = harness(demo());
    h.run_steps(2);
    let project = h.state().session().project().clone();
    let k = ((project.particles[24].center.z - project.grid.min.z) / project.grid.cell_size().z) as u32;
    h.state_mut().slice_settings_mut().index = k;
    h.run_steps(2);
    let before = h.state().current_slice().expect("slice").clone();
    h.state_mut().set_tool(Tool::Erase);
    h.state_mut().brush_mut().radius = 0.2;
    let c = screen_of(&h, project.particles[24].center);
    h.drag(c - Vec2::new(10.0, 0.0), c + Vec2::new(10.0, 0.0), 4);
    h.run_steps(3);
    assert!(h.state().session().project().particles.len() < project.particles.len(), "the erase removed particles");
    let ev = read_ev(&h);
    let s = h.state().current_slice().expect("slice after the erase");
    assert_eq!(s.index, k);
    let expected = fogsmith::editor::slices::extract(&ev, Axis::Z, k);
    assert_ne!(before.values, expected.values, "the erase changed this slice");
    assert_eq!(s.values, expected.values, "the slice shows the EV after the erase");
}

#[test]
fn reset_layout_escape_and_the_viewport_tab() {
    use egui_dock::TabViewer;
    let mut h = harness(demo());
    h.state_mut().set_tab_open(fogsmith::editor::Tab::Slices, false);
    h.run_steps(2);
    assert!(h.state().dock.find_tab(&fogsmith::editor::Tab::Slices).is_none());
    h.get_by_label("View").click();
    h.run_steps(2);
    h.get_by_label("Reset layout").click();
    h.run_steps(2);
    assert!(
        h.state().dock.find_tab(&fogsmith::editor::Tab::Slices).is_some(),
        "one click on Reset layout restores the panels"
    );

    h.get_by_label("preview").click();
    h.run_steps(2);
    assert!(h.query_by_label("wait for full").is_some(), "the quality drop-down opened");
    h.key_press(egui::Key::Escape);
    h.run_steps(2);
    assert!(h.query_by_label("wait for full").is_none(), "Escape closes the drop-down");

    // Escape closes the Shortcuts window before it touches the selection.
    h.state_mut().session_mut().select_all();
    h.key_press(egui::Key::F1);
    h.run_steps(2);
    assert!(h.query_by_label("Cancel / deselect").is_some(), "F1 opened the Shortcuts window");
    h.key_press(egui::Key::Escape);
    h.run_steps(2);
    assert!(h.query_by_label("Cancel / deselect").is_none(), "Escape closes the Shortcuts window");
    assert!(!h.state().session().selection.is_empty(), "that Escape keeps the selection");
    h.key_press(egui::Key::Escape);
    h.run_steps(2);
    assert!(h.state().session().selection.is_empty(), "the next Escape clears it");

    assert!(
        !h.state_mut().state.is_closeable(&fogsmith::editor::Tab::Viewport),
        "the Viewport tab has no close button"
    );
    assert!(h.state_mut().state.is_closeable(&fogsmith::editor::Tab::Slices));
}

/// With no desktop portal and no zenity, Save As and Export open Fogsmith's own file
/// dialog, say so, and save and export through it.
#[test]
fn without_a_portal_save_as_and_export_use_the_built_in_dialog() {
    use fogsmith::editor::files::FileDialogs;
    let dir = common::temp_dir();
    let path = dir.path().join("room.ron");
    fogsmith::scene::save_project(&path, &fogsmith::editor::demo_project().expect("demo")).expect("save");
    let dialogs = FileDialogs::detect_with(|_| None);
    assert!(matches!(dialogs, FileDialogs::BuiltIn { .. }), "no portal, no zenity: {dialogs:?}");
    let options = EditorOptions {
        file_dialogs: Some(dialogs),
        state_dir: Some(dir.path().join("state")),
        ..EditorOptions::default()
    };
    let mut h = harness_with(StartProject::resolve(Some(path.clone())).expect("start"), options);

    h.key_press_modifiers(Modifiers::COMMAND | Modifiers::SHIFT, egui::Key::S);
    h.run_steps(3);
    assert!(h.state().built_in_dialog_open(), "Ctrl+Shift+S opened the built-in dialog");
    let messages = h.state().messages();
    assert!(messages.iter().any(|(_, t)| t.contains("Fogsmith's file dialog")), "the window says why: {messages:?}");
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::A);
    h.event(Event::Text("copy.ron".into()));
    h.step();
    h.key_press(egui::Key::Enter);
    h.run_steps(2);
    wait_idle(&mut h);
    let copy = dir.path().join("copy.ron");
    assert!(!h.state().built_in_dialog_open());
    assert_eq!(load_project(&copy).expect("saved through the dialog"), *h.state().session().project());
    assert!(h.state().title().starts_with("copy.ron"), "{}", h.state().title());

    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::E);
    h.run_steps(2);
    h.get_by_label("Export to…").click();
    h.run_steps(3);
    assert!(h.state().built_in_dialog_open(), "export opens the built-in dialog");
    h.key_press(egui::Key::Enter);
    h.run_steps(2);
    wait_idle(&mut h);
    let vdb = dir.path().join("copy.vdb");
    let grids = fogsmith::export::vdb_read::list_vdb_grids(&vdb).expect("exported through the dialog");
    assert_eq!(grids.len(), 3, "density and one optical depth per light");
}

/// Circles and unfilled closed paths: the selection's outlines and the faint polygons of the rest.
fn circles(h: &EditorDriver) -> usize {
    h.output()
        .shapes
        .iter()
        .filter(|c| match &c.shape {
            egui::Shape::Circle(_) => true,
            egui::Shape::Path(p) => p.closed && p.fill == egui::Color32::TRANSPARENT,
            _ => false,
        })
        .count()
}

/// View → Particle outlines off leaves only the selection outlined.
#[test]
fn particle_outlines_can_be_limited_to_the_selection() {
    let mut h = harness(demo());
    let n = h.state().session().project().particles.len();
    h.state_mut().session_mut().selection.particles = [3].into();
    h.run_steps(2);
    let all = circles(&h);
    assert!(all >= n, "every particle is outlined: {all} circles for {n} particles");
    h.state_mut().set_outline_all(false);
    h.run_steps(2);
    let some = circles(&h);
    assert_eq!(all - some, n - 1, "the unselected particles' outlines went ({all} → {some} circles)");
}

/// With the frame-budgeted preview an export asked for mid-bake waits for the bake; the status
/// bar says so with a Cancel button, and cancelling leaves no file and says so. Asked again, it
/// completes once the bake has and names the file.
#[test]
fn an_export_waits_for_the_bake_and_can_be_cancelled() {
    // At full preview resolution: a quarter's bake can complete within the first frames.
    let mut h = build(demo(), EditorOptions::default(), Quality::Balanced, PreviewScale::Full);
    h.step();
    assert!(!h.state().preview_status().unwrap().converged, "the first frame starts the bake");
    let dir = common::temp_dir();
    let path = dir.path().join("fog.vdb");
    h.state_mut().export(ExportChoices::default(), path.clone());
    h.step();
    h.get_by_label("Cancel").click();
    h.step();
    assert!(h.state().messages().iter().any(|(_, m)| m.contains("Export cancelled")), "{:?}", h.state().messages());
    h.step_until(3000, |app| app.preview_status().unwrap().converged && app.busy() == 0);
    h.run_steps(3);
    assert!(!path.exists(), "a cancelled export writes nothing");

    h.state_mut().export(ExportChoices::default(), path.clone());
    wait_idle(&mut h);
    h.run_steps(2);
    assert!(path.exists(), "the export completes: {:?}", h.state().messages());
    assert!(
        h.state().messages().iter().any(|(_, m)| m.contains("Exported") && m.contains("fog.vdb")),
        "{:?}",
        h.state().messages()
    );
    let names: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(names.len(), 1, "no temporary file remains: {names:?}");
}

/// Ids are stable: after deleting other particles and a light, the Inspector, Outliner and
/// the Slices light list still name every object by the id it had.
#[test]
fn names_follow_stable_ids_after_deletions() {
    let mut h = harness(demo());
    let project = h.state().session().project().clone();
    assert!(project.particles.len() > 24 && project.lights.len() >= 2, "the demo has the wisp and two lights");
    let wisp_id = project.particles[24].id;
    let last_light_id = project.lights.last().unwrap().id;
    {
        let s = h.state_mut().session_mut();
        s.selection.particles = (0..5).collect();
        s.selection.lights = [0].into();
        assert_eq!(s.delete_selection(), 6);
        s.selection.particles = [19].into();
    }
    h.run_steps(3);
    assert_eq!(h.state().session().project().particles[19].id, wisp_id);
    let shown = h.query_all_by_label(&format!("Particle #{wisp_id}")).count();
    assert!(shown >= 2, "the Inspector and the Outliner name the wisp by its id ({shown} labels)");
    assert_eq!(h.query_all_by_label("Particle #0").count(), 0, "the deleted particle #0's name is not reused");
    assert_eq!(h.query_all_by_label("Particle #5").count(), 1, "the first row is the particle that was #5");
    // Lights keep their ids too.
    let lights = &h.state().session().project().lights;
    assert_eq!(lights.last().unwrap().id, last_light_id);
    assert!(lights.iter().all(|l| l.id != project.lights[0].id), "the deleted light's id is gone");

    // The undo history names the deleted objects by id.
    let label = h.state().session().undo_label().expect("an undo step");
    assert_eq!(label, format!("Delete Particles #0, #1, #2 and 2 more and Light #{}", project.lights[0].id));
    h.get_by_label("Edit").click();
    h.run_steps(2);
    h.get_by_label_contains(&format!("Undo {label}"));
    h.key_press(egui::Key::Escape);
    h.run_steps(2);

    // New objects take fresh ids, never one of a deleted object.
    let before_max = project.particles.iter().map(|p| p.id).max().unwrap();
    let n = h
        .state_mut()
        .session_mut()
        .add_particles(0, [fogsmith::scene::Particle::new(glam::Vec3::new(0.0, 1.0, 0.0), 0.2, 1.0)]);
    let added = h.state().session().project().particles[n - 1].id;
    assert!(added > before_max, "new particle id {added} is above every id used before ({before_max})");
}

/// File → Import VDB…: the grid picker imports a grid, the editor's pipeline loads it through
/// the project, and the EV (and its slice) shows base + particles; undo takes it out again.
#[test]
fn an_imported_vdb_shows_in_the_ev_and_its_slice() {
    use fogsmith::export::vdb::{write_vdb, VdbGrid, VdbOptions};
    let mut h = harness(demo());
    h.run_steps(2);
    let grid = h.state().session().project().grid;
    let without = read_ev(&h);
    let layer: Vec<f32> = (0..grid.cell_count()).map(|i| ((i % 5) as f32) * 0.1).collect();
    let dir = common::temp_dir();
    let vdb = dir.path().join("base.vdb");
    let volume = Volume::new(grid, layer.clone());
    write_vdb(
        &vdb,
        &[VdbGrid::from_volume("smoke", &volume), VdbGrid::from_volume("density", &volume)],
        &VdbOptions::default(),
    )
    .unwrap();

    h.state_mut().import_vdb(vdb.clone());
    h.run_steps(2);
    h.get_by_label("Import VDB");
    h.get_by_label("Import").click();
    h.run_steps(4);
    let base = h.state().session().project().base_volume.clone().expect("the import set the base volume");
    assert_eq!(base.grid, "density");
    assert_eq!(base.path, vdb, "a VDB outside the project's folder keeps its absolute path");
    let with = read_ev(&h);
    for i in (0..layer.len()).step_by(97) {
        let want = without.data[i] + layer[i];
        assert!((with.data[i] - want).abs() <= 1e-4 * want.max(1.0), "cell {i}: EV {} vs {want}", with.data[i]);
    }
    let s = h.state().current_slice().expect("the Slices panel shows the EV").clone();
    let expected = fogsmith::editor::slices::extract(&with, s.axis, s.index);
    assert_eq!(s.values, expected.values, "the EV slice shows the imported density");

    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(4);
    assert!(h.state().session().project().base_volume.is_none());
    assert!(max_diff(&without, &read_ev(&h)) < 1e-6, "undo takes the base volume out of the EV");

    // A base volume that cannot load is reported, not silently dropped.
    h.state_mut().session_mut().edit(0).base_volume =
        Some(fogsmith::scene::BaseVolume { path: dir.path().join("gone.vdb"), grid: "density".into(), scale: 1.0 });
    h.run_steps(3);
    assert!(
        h.state().messages().iter().any(|(error, m)| *error && m.contains("gone.vdb")),
        "{:?}",
        h.state().messages()
    );
    h.state_mut().session_mut().edit(0).base_volume = None;

    // Under the analytic scheme the dialog says, before the import, that the scheme cannot use
    // the volume; importing switches to sweep in the same undo step, and the preview renders.
    h.state_mut().session_mut().edit(0).propagation.scheme = fogsmith::scene::Scheme::Analytic;
    h.run_steps(3);
    let undo = h.state().session().undo_len();
    h.state_mut().import_vdb(vdb.clone());
    h.run_steps(2);
    h.get_by_label_contains("cannot use an imported volume");
    h.get_by_label("Switch to sweep and import").click();
    h.run_steps(4);
    let project = h.state().session().project();
    assert!(project.base_volume.is_some(), "the import set the base volume");
    assert_eq!(project.propagation.scheme, fogsmith::scene::Scheme::Sweep);
    assert_eq!(h.state().session().undo_len(), undo + 1, "volume and scheme are one undo step");
    assert_eq!(h.state().gpu_error(), None, "the preview renders the imported volume");
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(2);
    let project = h.state().session().project();
    assert!(project.base_volume.is_none() && project.propagation.scheme == fogsmith::scene::Scheme::Analytic);
}

/// Particles reaching outside the grid box: the viewport warns with their count, and "Fit grid
/// to particles" (keeping the resolution here) is one undo step after which none crosses.
#[test]
fn particles_outside_the_grid_are_named_and_the_grid_fits_them() {
    let mut h = harness(demo());
    let g = h.state().session().project().grid;
    let already = h.state().session().project().particles_crossing_grid().len();
    // Two particles whose support (≈2.15 r) pokes out of the open front (+z) face, one well
    // inside. (The demo's walls seal its other faces.)
    let inside = (g.min + g.max) * 0.5;
    h.state_mut().session_mut().add_particles(
        0,
        [
            fogsmith::scene::Particle::new(glam::Vec3::new(inside.x, inside.y, g.max.z - 0.2), 0.3, 2.0),
            fogsmith::scene::Particle::new(glam::Vec3::new(inside.x, inside.y, g.max.z + 0.5), 0.3, 2.0),
            fogsmith::scene::Particle::new(inside, 0.1, 2.0),
        ],
    );
    h.run_steps(2);
    let n = already + 2;
    assert_eq!(h.state().session().project().particles_crossing_grid().len(), n);
    h.get_by_label_contains(&format!("{n} particles reach outside the grid box"));

    h.get_by_label("keep resolution").click();
    h.run_steps(1);
    h.get_by_label("Fit grid to particles").click();
    h.run_steps(3);
    let fitted = h.state().session().project().grid;
    assert_eq!(fitted.resolution, g.resolution, "the resolution is kept");
    assert!(fitted.max.z > g.max.z + 0.5, "the box grew to hold the particle outside: {fitted:?}");
    assert!(
        fitted.min.cmpge(g.min).all() && fitted.max.x <= g.max.x && fitted.max.y <= g.max.y,
        "not through the floor, walls or ceiling: {fitted:?} from {g:?}"
    );
    assert!(h.state().session().project().particles_crossing_grid().is_empty());
    assert!(h.query_by_label_contains("reach outside the grid box").is_none(), "the warning is gone");
    assert_eq!(h.state().gpu_error(), None, "the preview renders the fitted grid");

    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(2);
    assert_eq!(h.state().session().project().grid, g, "one undo restores the grid");
}

/// One command table: every shortcut dispatches its command (through the dispatcher the
/// editor uses), appears on the Help → Shortcuts sheet, and no two commands share one.
#[test]
fn every_command_shortcut_dispatches_and_is_on_the_help_sheet() {
    use fogsmith::editor::commands::{format_shortcut, help_sheet, Command};
    let sheet = help_sheet();
    let mut seen: Vec<(egui::KeyboardShortcut, Command)> = Vec::new();
    for c in Command::ALL {
        for s in c.shortcuts() {
            if let Some((_, other)) = seen.iter().find(|(t, _)| *t == s) {
                panic!("{c:?} and {other:?} share {}", format_shortcut(&s));
            }
            seen.push((s, c));
            let ctx = egui::Context::default();
            let event = Event::Key {
                key: s.logical_key,
                physical_key: None,
                pressed: true,
                repeat: false,
                modifiers: s.modifiers,
            };
            let input = egui::RawInput { events: vec![event], ..Default::default() };
            let mut got = Vec::new();
            let _ = ctx.run_ui(input, |ui| got = Command::pressed(ui.ctx(), false, true));
            assert_eq!(got, vec![c], "{} dispatches {c:?}", format_shortcut(&s));
            assert!(
                sheet
                    .iter()
                    .any(|(keys, what)| *what == c.sheet_text() && keys.split(" / ").any(|k| k == format_shortcut(&s))),
                "{c:?} ({}) is on the help sheet",
                format_shortcut(&s)
            );
        }
    }
    assert!(seen.len() > 25, "the table holds the editor's shortcuts");

    // Through the real editor: the slice steps one cell with ] and PageDown, the toolbar
    // shows the tool shortcuts from the table, and the help sheet lists the commands.
    let mut h = harness(demo());
    let k0 = h.state_mut().slice_settings_mut().index;
    h.key_press(egui::Key::CloseBracket);
    h.run_steps(2);
    assert_eq!(h.state().last_command(), Some(Command::SliceNext));
    assert_eq!(h.state_mut().slice_settings_mut().index, k0 + 1, "] steps the slice one cell");
    h.key_press(egui::Key::PageDown);
    h.run_steps(2);
    assert_eq!(h.state_mut().slice_settings_mut().index, k0, "PageDown steps it back");
    h.get_by_label("Paint (B)");
    h.key_press(egui::Key::F1);
    h.run_steps(2);
    h.get_by_label("Ctrl+Shift+Z / Ctrl+Y");
    h.get_by_label("Next slice");
}

/// With a light selected, every field of the Inspector lies inside the window: the
/// position's three fields wrap instead of running past the panel's right edge.
#[test]
fn the_inspectors_vector_fields_stay_inside_the_window() {
    let mut h = harness(demo());
    h.state_mut().session_mut().selection.lights.insert(0);
    h.run_steps(3);
    let width = 1280.0;
    let fields: Vec<_> = h.get_all_by_role(egui::accesskit::Role::SpinButton).map(|n| n.rect()).collect();
    assert!(fields.len() >= 6, "the Inspector shows the light's fields: {}", fields.len());
    for r in &fields {
        assert!(r.max.x <= width - 4.0, "a field runs past the right edge: {r:?}");
    }
}

/// F1's sheet on a short window: it fits the window and scrolls to its last line, and the
/// Scale tool and scaling the selection read differently.
#[test]
fn the_shortcuts_sheet_scrolls_within_a_short_window() {
    use fogsmith::editor::commands::help_sheet;
    let setup = fogsmith::editor::driver::DriverSetup { size: Vec2::new(1000.0, 480.0), ..Default::default() };
    let mut h = EditorDriver::new(demo(), setup);
    h.run_steps(2);
    h.key_press(egui::Key::F1);
    h.run_steps(3);
    let sheet = help_sheet();
    let (_, last) = sheet.last().unwrap();
    h.get_by_label("Scale tool");
    h.get_by_label("Scale the selection");
    let first = h.get_by_label(&sheet[0].1).rect();
    let bottom = 480.0;
    assert!(h.get_by_label(last).rect().min.y > bottom, "the sheet is longer than the window");
    let over = Pos2::new(((first.min.x + first.max.x) * 0.5) as f32, (first.max.y + 20.0) as f32);
    h.event(Event::PointerMoved(over));
    for _ in 0..40 {
        h.event(Event::MouseWheel {
            unit: egui::MouseWheelUnit::Point,
            delta: Vec2::new(0.0, -200.0),
            phase: egui::TouchPhase::Move,
            modifiers: Modifiers::NONE,
        });
        h.step();
    }
    h.run_steps(3);
    let end = h.get_by_label(last).rect();
    assert!(end.max.y <= bottom && end.min.y >= 0.0, "its last line scrolled into the window: {end:?}");
}

/// The slice plane shows in the viewport as a translucent quad in its axis colour, and the
/// slice image names its world axes with their ranges in metres and the plane's position.
#[test]
fn the_slice_plane_shows_in_the_viewport_and_the_slice_names_its_axes() {
    use fogsmith::editor::slices::{slice_plane_corners, Axis};
    let mut h = harness(demo());
    h.state_mut().slice_settings_mut().axis = Axis::Z;
    h.state_mut().slice_settings_mut().index = 32;
    h.state_mut().set_show_slice_plane(false);
    h.run_steps(3);
    let grid = h.state().session().project().grid;
    let corners = slice_plane_corners(&grid, Axis::Z, 32);
    let centre = corners.iter().copied().sum::<glam::Vec3>() / 4.0;
    assert!((centre.z - (grid.min.z + 32.5 * grid.cell_size().z)).abs() < 1e-6, "the plane is at the cell centre");
    let at = screen_of(&h, centre);
    let pixel = |img: &image::RgbaImage| {
        let p = img.get_pixel(at.x as u32, at.y as u32).0;
        [p[0] as i32, p[1] as i32, p[2] as i32]
    };
    let without = pixel(&h.render().expect("render"));
    h.state_mut().set_show_slice_plane(true);
    h.run_steps(2);
    let with = pixel(&h.render().expect("render"));
    let c = Axis::Z.colour();
    let towards = |i: usize, target: u8| (target as i32 - without[i]).signum() * (with[i] - without[i]);
    assert!(with != without, "the quad tints the viewport: {without:?} → {with:?}");
    assert!(
        towards(2, c.b()) > 0 && towards(0, c.r()) >= 0,
        "tinted towards the z colour {c:?}: {without:?} → {with:?}"
    );

    h.get_by_label("x -1.00 … 1.00 m");
    h.get_by_label("y 0.00 … 2.00 m");
    h.get_by_label("z = 0.016 m");
    h.key_press(egui::Key::CloseBracket);
    h.run_steps(3);
    h.get_by_label("z = 0.047 m");
}

/// Paint at fog depth: a click over a dense puff paints where the optical depth from the
/// camera through the pipeline's EV reaches 0.5 (in front of the puff's centre), the brush preview
/// sits there before the click, a ray through no fog falls back to the working plane, and
/// the working plane stays a choice.
#[test]
fn paint_lands_at_the_fog_depth_under_the_cursor() {
    use fogsmith::editor::tools::{fog_depth_point, working_plane_point, PaintDepth, FOG_DEPTH_TAU};
    let mut h = harness(demo());
    // A dense puff between the camera and the working plane (through the grid centre).
    let g = h.state().session().project().grid;
    let puff = fogsmith::scene::Particle::new(glam::Vec3::new(0.1, 1.0, g.max.z - 0.4), 0.12, 20.0);
    h.state_mut().session_mut().add_particles(0, [puff]);
    h.run_steps(3);
    let rect = h.state().viewport_rect().expect("viewport");
    let project = h.state().session().project().clone();
    let vp = ViewProjection::new(&project.camera, rect);
    let wisp = project.particles.last().unwrap().clone();
    let pos = screen_of(&h, wisp.center);
    h.state_mut().set_tool(Tool::Paint);
    *h.state_mut().brush_mut() = fogsmith::editor::tools::Brush {
        radius: 0.05,
        density: 1.0,
        spacing: 0.5,
        jitter: 0.0,
        depth: PaintDepth::Fog,
        noise: true,
    };
    let ev = read_ev(&h);
    let expected = fog_depth_point(&ev, vp.position, vp.ray(pos), FOG_DEPTH_TAU)
        .expect("the ray through the puff reaches τ = 0.5");
    let cam = project.camera.position;
    let (d_hit, d_wisp) = ((expected - cam).length(), (wisp.center - cam).length());
    assert!(
        d_hit < d_wisp && d_hit > d_wisp - 2.2 * wisp.radius,
        "the fog begins in front of the puff's centre: {d_hit} vs {d_wisp}"
    );

    h.event(Event::PointerMoved(pos));
    h.run_steps(2);
    let preview = h.state().brush_point().expect("the brush preview has a depth");
    assert!((preview - expected).length() < 1e-3, "the preview sits at the fog: {preview:?} vs {expected:?}");
    let n = project.particles.len();
    h.press(pos, PointerButton::Primary, true);
    h.press(pos, PointerButton::Primary, false);
    h.run_steps(2);
    let painted = h.state().session().project().particles[n].center;
    assert!((painted - expected).length() < 1e-3, "painted at the fog depth: {painted:?} vs {expected:?}");
    let plane = working_plane_point(&project, &vp, pos).unwrap();
    assert!((plane - expected).length() > 0.05, "the fog depth differs from the working plane here");

    // A ray through the box that meets too little fog falls back to the working plane (moved
    // along the ray into the box where the plane lies outside it).
    let ev = read_ev(&h);
    let thin = (0..40)
        .flat_map(|i| (0..24).map(move |j| rect.lerp_inside(Vec2::new(i as f32 / 39.0, j as f32 / 23.0))))
        .find(|&q| {
            fogsmith::editor::tools::into_grid_along_ray(&g, vp.position, vp.ray(q), vp.position).is_some()
                && fog_depth_point(&ev, vp.position, vp.ray(q), FOG_DEPTH_TAU).is_none()
        })
        .expect("a pixel whose ray crosses the box through thin fog");
    let n = h.state().session().project().particles.len();
    h.click(thin, PointerButton::Primary);
    h.step();
    let fallback = h.state().session().project().particles[n].center;
    let plane_point = working_plane_point(&project, &vp, thin).unwrap();
    let want = fogsmith::editor::tools::into_grid_along_ray(&g, vp.position, vp.ray(thin), plane_point).unwrap();
    assert!((fallback - want).length() < 1e-3, "thin fog: the working plane ({fallback:?} vs {want:?})");
    // A ray that misses the box paints nothing.
    let corner = rect.min + Vec2::new(6.0, 6.0);
    assert!(fogsmith::editor::tools::into_grid_along_ray(&g, vp.position, vp.ray(corner), vp.position).is_none());
    let n = h.state().session().project().particles.len();
    h.click(corner, PointerButton::Primary);
    h.step();
    assert_eq!(h.state().session().project().particles.len(), n, "nothing painted outside the grid box");

    // The working plane as the artist's choice.
    h.state_mut().brush_mut().depth = PaintDepth::Plane;
    let rect_now = h.state().viewport_rect().unwrap();
    let cam_now = h.state().session().project().camera;
    assert_eq!((rect_now, cam_now), (rect, project.camera), "the view did not move");
    let n = h.state().session().project().particles.len();
    h.event(Event::PointerMoved(pos));
    h.step();
    h.press(pos, PointerButton::Primary, true);
    h.press(pos, PointerButton::Primary, false);
    h.run_steps(2);
    let added: Vec<_> = h.state().session().project().particles[n..].iter().map(|p| p.center).collect();
    assert_eq!(added.len(), 1, "one click, one dab: {added:?}");
    let on_plane = added[0];
    let centre = (project.grid.min + project.grid.max) * 0.5;
    let depth = |p: glam::Vec3| (p - vp.position).dot(vp.forward);
    assert!(
        (depth(on_plane) - depth(centre)).abs() < 1e-4,
        "on the working plane: {on_plane:?} (plane through {centre:?})"
    );
    assert!((depth(on_plane) - depth(painted)).abs() > 0.05, "not at the fog depth");
}

/// The Inspector's noise: the checkbox turns it on (the EV changes), dragging its amplitude
/// changes the EV live, and undo restores first the amplitude, then the noise-free EV.
#[test]
fn inspector_noise_amplitude_changes_the_ev_and_undo_restores_it() {
    let mut h = harness(demo());
    let plain = read_ev(&h);
    assert_eq!(h.state().session().project().medium.noise, None, "the demo starts without noise");
    h.get_by_label("noise detail").click();
    h.run_steps(3);
    let noise = h.state().session().project().medium.noise.expect("the checkbox turns noise on");
    let noisy = read_ev(&h);
    assert!(max_diff(&plain, &noisy) > 1e-3, "noise changes the EV");

    let label = h.get_by_label("amplitude").rect();
    let field = h
        .get_all_by_role(egui::accesskit::Role::SpinButton)
        .map(|n| n.rect())
        .find(|r| (r.center().y - label.center().y).abs() < 6.0 && r.left() > label.right())
        .expect("an amplitude field beside its label");
    h.drag(field.center(), field.center() + Vec2::new(60.0, 0.0), 6);
    h.run_steps(3);
    let edited = h.state().session().project().medium.noise.expect("still on").amplitude;
    assert!(edited > noise.amplitude + 0.1, "the drag raised the amplitude: {} → {edited}", noise.amplitude);
    let stronger = read_ev(&h);
    assert!(max_diff(&noisy, &stronger) > 1e-3, "the live preview's EV follows the amplitude");

    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(3);
    assert_eq!(h.state().session().project().medium.noise, Some(noise), "one undo restores the amplitude");
    assert!(max_diff(&noisy, &read_ev(&h)) < 1e-6, "and the EV");
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(3);
    assert_eq!(h.state().session().project().medium.noise, None, "a second undo turns the noise off");
    assert!(max_diff(&plain, &read_ev(&h)) < 1e-6, "the EV is back to the noise-free one");
}

/// Particle 24 selected with the Select tool, seen from the front (along −z) from 6 m (so
/// the gizmo's arrows reach past its outline):
/// its centre, its screen position and the points per metre at its depth.
fn gizmo_on_24(h: &mut EditorDriver) -> (glam::Vec3, Pos2, f32) {
    let p = h.state().session().project().particles[24].center;
    let camera = fogsmith::scene::Camera {
        position: p + glam::Vec3::new(0.0, 0.0, 6.0),
        target: p,
        up: glam::Vec3::Y,
        ..h.state().session().project().camera
    };
    h.state_mut().session_mut().set_camera(camera);
    h.state_mut().session_mut().selection.particles = [24].into();
    h.state_mut().set_tool(Tool::Select);
    h.run_steps(2);
    let vp = ViewProjection::new(&camera, h.state().viewport_rect().expect("viewport"));
    let (s, z) = vp.project(p).expect("in view");
    (p, s, vp.points_per_metre(z))
}

fn centres(h: &EditorDriver) -> Vec<glam::Vec3> {
    h.state().session().project().particles.iter().map(|p| p.center).collect()
}

/// Whether a gizmo handle is drawn lit (under the pointer).
fn lit(h: &EditorDriver) -> bool {
    h.output().shapes.iter().any(
        |s| matches!(&s.shape, egui::Shape::LineSegment { stroke, .. } if stroke.color == fogsmith::editor::gizmo::LIT),
    )
}

fn texts(h: &EditorDriver) -> Vec<String> {
    h.output()
        .shapes
        .iter()
        .filter_map(|c| match &c.shape {
            egui::Shape::Text(t) => Some(t.galley.text().to_string()),
            _ => None,
        })
        .collect()
}

/// Dragging the gizmo's x arrow moves the selection along x only, by the pointer's travel
/// along the arrow, with the preview and the drag values following; the whole drag is one
/// undo step. Hovering lights the arrow up.
#[test]
fn the_gizmo_x_arrow_moves_the_selection_along_x_as_one_undo_step() {
    let mut h = harness(demo());
    let (p0, c, ppm) = gizmo_on_24(&mut h);
    let before = centres(&h);
    let undo = h.state().session().undo_len();
    let ev_before = read_ev(&h);
    h.event(Event::PointerMoved(c + Vec2::new(-60.0, 40.0)));
    h.run_steps(2);
    assert!(!lit(&h), "no handle is lit away from the gizmo");
    let grab = c + Vec2::new(60.0, 0.0);
    h.event(Event::PointerMoved(grab));
    h.run_steps(2);
    assert!(lit(&h), "the x arrow lights up under the pointer");
    h.press(grab, PointerButton::Primary, true);
    // The pointer wanders off the axis on the way; only its travel along x counts.
    for off in [Vec2::new(20.0, 15.0), Vec2::new(50.0, -25.0)] {
        h.event(Event::PointerMoved(grab + off));
        h.step();
    }
    let mid = h.state().session().project().particles[24].center;
    assert!(
        mid.x > p0.x && mid.y == p0.y && mid.z == p0.z,
        "mid-drag the particle has moved along x only: {p0} → {mid}"
    );
    let shown = texts(&h);
    let values =
        shown.iter().find(|t| t.starts_with("Δx ")).unwrap_or_else(|| panic!("the drag values show: {shown:?}"));
    let dx: f32 = values["Δx ".len()..].split(' ').next().and_then(|v| v.parse().ok()).expect("Δx is a number");
    assert!((dx - (mid.x - p0.x)).abs() < 1e-3, "Δx reads {dx} m, moved {} m: {values}", mid.x - p0.x);
    assert!(values.contains("Δy +0.000 m") && values.contains("Δz +0.000 m"), "{values}");
    assert!(max_diff(&ev_before, &read_ev(&h)) > 1e-3, "the preview's EV follows the drag");
    h.event(Event::PointerMoved(grab + Vec2::new(80.0, 0.0)));
    h.step();
    h.press(grab + Vec2::new(80.0, 0.0), PointerButton::Primary, false);
    h.step();
    let after = centres(&h);
    let d = after[24] - p0;
    let expected = 80.0 / ppm;
    assert!((d.x - expected).abs() < 1e-3 * expected, "moved {} m along x, expected {expected} m", d.x);
    assert!(d.y == 0.0 && d.z == 0.0, "y and z untouched: {d}");
    for (i, (a, b)) in before.iter().zip(&after).enumerate() {
        assert!(i == 24 || a == b, "particle {i} is not selected and stays put");
    }
    assert_eq!(h.state().session().undo_len(), undo + 1, "the drag is one undo step");
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(2);
    assert_eq!(h.state().session().project().particles[24].center, p0, "one undo puts it back");
}

/// Escape or a right click during a gizmo drag puts the selection back and leaves no undo
/// step; Ctrl snaps the drag to the grid cell; a drag on empty space moves nothing.
#[test]
fn gizmo_drags_cancel_snap_and_empty_space_moves_nothing() {
    let mut h = harness(demo());
    let (p0, c, _) = gizmo_on_24(&mut h);
    let undo = h.state().session().undo_len();
    let grab = c + Vec2::new(60.0, 0.0);

    for cancel in ["escape", "right click"] {
        h.event(Event::PointerMoved(grab));
        h.step();
        h.press(grab, PointerButton::Primary, true);
        h.event(Event::PointerMoved(grab + Vec2::new(70.0, 0.0)));
        h.step();
        assert!(
            h.state().session().project().particles[24].center.x > p0.x + 0.05,
            "{cancel}: the drag moves the particle first"
        );
        if cancel == "escape" {
            h.key_press(egui::Key::Escape);
        } else {
            h.press(grab + Vec2::new(70.0, 0.0), PointerButton::Secondary, true);
        }
        h.step();
        h.event(Event::PointerMoved(grab + Vec2::new(90.0, 10.0)));
        h.step();
        if cancel != "escape" {
            h.press(grab + Vec2::new(90.0, 10.0), PointerButton::Secondary, false);
        }
        h.press(grab + Vec2::new(90.0, 10.0), PointerButton::Primary, false);
        h.run_steps(2);
        assert_eq!(h.state().session().project().particles[24].center, p0, "{cancel} puts the particle back");
        assert_eq!(h.state().session().undo_len(), undo, "{cancel}: a cancelled drag leaves no undo step");
        assert!(!h.state().session().can_redo(), "{cancel}: nor a redo step");
        assert_eq!(
            h.state().session().selection.particles.iter().copied().collect::<Vec<_>>(),
            vec![24],
            "{cancel} keeps the selection"
        );
    }

    // Ctrl held: the particle's centre lands on a grid cell's centre along x.
    let grid = h.state().session().project().grid;
    let cell = grid.cell_size().x;
    h.event(Event::PointerMoved(grab));
    h.step();
    h.press(grab, PointerButton::Primary, true);
    h.event(Event::ModifiersChanged(Modifiers::CTRL));
    h.event(Event::PointerMoved(grab + Vec2::new(47.0, 3.0)));
    h.step();
    let shown = texts(&h);
    assert!(shown.iter().any(|t| t.contains("snapped")), "the drag values say they are snapped: {shown:?}");
    h.event(Event::PointerButton {
        pos: grab + Vec2::new(47.0, 3.0),
        button: PointerButton::Primary,
        pressed: false,
        modifiers: Modifiers::CTRL,
    });
    h.step();
    h.event(Event::ModifiersChanged(Modifiers::NONE));
    h.step();
    let moved = h.state().session().project().particles[24].center;
    let d = moved - p0;
    let cells = (moved.x - grid.min.x) / cell - 0.5;
    assert!(
        d.x > 0.0 && (cells - cells.round()).abs() < 1e-3 && d.y == 0.0 && d.z == 0.0,
        "x snapped to a centre of the {cell} m cells: {p0} → {moved}"
    );
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(2);
    assert_eq!(h.state().session().project().particles[24].center, p0);

    // View → Move gizmo off: no arrow lights up and a drag there moves nothing.
    let before = centres(&h);
    let undo = h.state().session().undo_len();
    h.state_mut().set_show_gizmo(false);
    h.event(Event::PointerMoved(grab));
    h.run_steps(2);
    assert!(!lit(&h), "the hidden gizmo is not drawn");
    h.drag(grab, grab + Vec2::new(80.0, 0.0), 4);
    assert_eq!(centres(&h), before, "with the gizmo hidden its arrows do not move anything");
    h.state_mut().set_show_gizmo(true);
    h.state_mut().session_mut().selection.particles = [24].into();
    h.run_steps(2);

    // A drag that starts away from the gizmo (and from every particle) moves nothing.
    h.drag(c + Vec2::new(-120.0, -100.0), c + Vec2::new(-60.0, -140.0), 4);
    assert_eq!(centres(&h), before, "a drag on empty space moves nothing");
    assert_eq!(h.state().session().undo_len(), undo);
}

/// The Inspector's scheme list offers `analytic` only where it can represent the medium:
/// with noise on, the entry is disabled, its tooltip names the noise and a click leaves the
/// scheme alone; without noise a click selects it as one undo step and the preview bakes
/// with it.
#[test]
fn the_analytic_scheme_is_offered_only_where_it_can_represent_the_medium() {
    use egui_kittest::kittest::NodeT;
    use fogsmith::scene::Scheme;
    let mut h = harness(demo());
    let scheme = |h: &EditorDriver| h.state().session().project().propagation.scheme;
    assert_eq!(scheme(&h), Scheme::Sweep);
    h.get_by_label("noise detail").click();
    h.run_steps(3);
    assert!(h.state().session().project().medium.noise.is_some(), "the checkbox turns noise on");
    h.get_by_label("scheme").click();
    h.run_steps(2);
    let entry = h.get_by_label("analytic");
    assert!(entry.accesskit_node().is_disabled(), "with noise the analytic entry is disabled");
    entry.hover();
    h.run_steps(3);
    assert!(h.query_by_label_contains("cannot represent the medium's noise").is_some(), "its tooltip says why");
    h.get_by_label("analytic").click();
    h.run_steps(2);
    assert_eq!(scheme(&h), Scheme::Sweep, "a click on the disabled entry changes nothing");
    h.key_press(egui::Key::Escape);
    h.run_steps(2);

    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(3);
    assert_eq!(h.state().session().project().medium.noise, None, "undo turns the noise off");
    wait_idle(&mut h);
    let sweep = h.state().pipeline().unwrap().read_opv(0).expect("OPV readback");
    h.get_by_label("scheme").click();
    h.run_steps(2);
    let entry = h.get_by_label("analytic");
    assert!(!entry.accesskit_node().is_disabled(), "without noise the analytic entry is enabled");
    entry.click();
    h.run_steps(2);
    assert_eq!(scheme(&h), Scheme::Analytic, "a click selects it");
    wait_idle(&mut h);
    assert_eq!(h.state().gpu_error(), None);
    let analytic = h.state().pipeline().unwrap().read_opv(0).expect("OPV readback");
    let diff = sweep.data.iter().zip(&analytic.data).map(|(a, b)| (a - b).abs()).fold(0.0, f32::max);
    assert!(
        diff > 1e-5 && analytic.data.iter().all(|t| t.is_finite() && *t >= 0.0),
        "the preview bakes with the analytic scheme: {diff:e}"
    );
    h.key_press_modifiers(Modifiers::COMMAND, egui::Key::Z);
    h.run_steps(3);
    assert_eq!(scheme(&h), Scheme::Sweep, "undo restores the sweep");
}

/// A frame whose first pass egui discards (the Inspector's grid for a newly selected light
/// sizing itself) runs the UI twice; the pipeline still advances once in it, so the frame
/// keeps to one budget of work.
#[test]
fn a_frame_of_two_passes_advances_the_preview_once() {
    let mut h = build(demo(), EditorOptions::default(), Quality::Balanced, PreviewScale::Full);
    h.step();
    let status = |h: &EditorDriver| h.state().preview_status().unwrap();
    assert!(!status(&h).converged, "the preview is refining");
    let mut two_passes = false;
    for light in 0..h.state().session().project().lights.len() {
        h.state_mut().session_mut().selection.lights.clear();
        h.state_mut().session_mut().selection.lights.insert(light);
        let (calls, passes) = (status(&h).calls, h.ctx.cumulative_pass_nr());
        h.step();
        let passes = h.ctx.cumulative_pass_nr() - passes;
        assert!(!status(&h).converged, "still refining after light {light}'s frame");
        assert_eq!(status(&h).calls - calls, 1, "light {light}: one call into the pipeline in {passes} passes");
        two_passes |= passes > 1;
    }
    assert!(two_passes, "no frame ran two passes: the test shows nothing");
}

/// Preview → March every pixel marches the preview again with one ray per pixel, and off,
/// adaptively again: each converged image is the one `render` makes with that sampling.
#[test]
fn the_preview_menu_switches_the_image_sampling() {
    use fogsmith::gpu::ImageSampling;
    let mut h = build(demo(), EditorOptions::default(), Quality::Full, PreviewScale::Quarter);
    converge(&mut h);
    let image = |h: &EditorDriver| h.state().pipeline().unwrap().read_image().unwrap();
    let adaptive = image(&h);
    assert_eq!(h.state().pipeline().unwrap().image_sampling(), ImageSampling::default());
    for (on, sampling) in [(true, ImageSampling::PerPixel), (false, ImageSampling::default())] {
        h.get_by_label("Preview").click();
        h.run_steps(2);
        h.get_by_label("March every pixel").click();
        h.run_steps(2);
        converge(&mut h);
        let pipeline = h.state().pipeline().unwrap();
        assert_eq!(pipeline.image_sampling(), sampling, "after the click (on: {on})");
        let shown = image(&h);
        let mut fresh = fogsmith::gpu::FogPipeline::new(pipeline.context().clone());
        fresh.set_image_sampling(sampling);
        let project = h.state().session().project().clone();
        let request = fogsmith::gpu::FrameRequest {
            width: shown.width,
            height: shown.height,
            ..fogsmith::gpu::FrameRequest::for_project(&project)
        };
        fresh.update(&project, &request).unwrap();
        assert!(shown.rgba == fresh.read_image().unwrap().rgba, "on: {on}: the preview is render's image bit for bit");
        if on {
            assert!(shown.rgba != adaptive.rgba, "the per-pixel image was marched again");
        } else {
            assert!(shown.rgba == adaptive.rgba, "adaptive again gives the first image");
        }
    }
}

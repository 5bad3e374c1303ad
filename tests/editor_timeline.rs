//! The Timeline and keying, driven through the real editor with egui_kittest on a real
//! wgpu device (lavapipe on machines without a GPU): Animate, K, the Inspector's diamonds,
//! auto-key, scrubbing (the preview equals a fresh bake of `at_frame` bit for bit), playing
//! in real time and frame by frame, dragging, deleting and re-shaping keys, motion paths, and
//! every timeline command in the menus. Without an adapter these tests fail; they never skip.

use egui::{Event, Modifiers, PointerButton, Pos2, Vec2};
use egui_kittest::kittest::Queryable;
use fogsmith::editor::app::{PreviewScale, Quality};
use fogsmith::editor::commands::Command;
use fogsmith::editor::timeline::{PlayMode, MOTION_PATH};
use fogsmith::editor::tools::Tool;
use fogsmith::editor::view::ViewProjection;
use fogsmith::editor::EditorOptions;
use fogsmith::scene::animation::{Animation, Channel, Interp, KeyValue, Object, Prop};
use fogsmith::scene::Project;

mod common;
use common::editor::{has_label, start};
use fogsmith::editor::driver::EditorDriver;

fn demo() -> Project {
    common::editor::demo().project
}

/// The demo animated over frames 1–48 at 24 fps: light #0 rises 0.6 m from frame 1 to 24.
fn animated() -> Project {
    let mut p = demo();
    p.animation = Some(Animation { fps: 24.0, start: 1, end: 48 });
    let c = light_position(&p);
    let at = p.lights[0].position;
    p.set_key(c, 1, KeyValue::Vec3(at), Interp::Linear).unwrap();
    p.set_key(c, 24, KeyValue::Vec3(at + glam::Vec3::new(0.4, -0.6, 0.3)), Interp::Linear).unwrap();
    p
}

/// [`animated`] on a grid of 128³ cells: the moved light's propagation takes many frames'
/// budgets on any adapter this suite runs on, so a jump shows stale shadows for a while.
fn heavy_animated() -> Project {
    let mut p = animated();
    p.grid.resolution = glam::UVec3::splat(128);
    p
}

fn light_position(p: &Project) -> Channel {
    Channel(Object::Light(p.lights[0].id), Prop::Position)
}

/// The editor on `project` at a quarter of the preview's resolution, every frame converged.
fn harness(project: Project) -> EditorDriver {
    common::editor::harness(start(project))
}

fn build(project: Project, quality: Quality) -> EditorDriver {
    common::editor::build(start(project), EditorOptions::default(), quality, PreviewScale::Quarter)
}

fn frame(h: &EditorDriver) -> i32 {
    h.state().session().frame()
}

fn undo(h: &mut EditorDriver) {
    h.shortcut(Modifiers::COMMAND, egui::Key::Z);
}

/// Where frame `f`'s marker sits on the scrub bar.
fn marker(h: &EditorDriver, f: i32) -> Pos2 {
    let bar = h.state().scrub_bar().expect("the Timeline shows its scrub bar");
    Pos2::new(bar.x_of(f), bar.marker_y())
}

/// The preview image against a fresh bake of `p`: how many values differ in their bits.
fn differs_from_fresh_bake_of(h: &EditorDriver, p: &Project) -> usize {
    common::editor::compare_with_fresh_bake_of(h, p).0
}

/// Widgets whose label holds `text` (a menu item's label also holds its shortcut).
fn count_labels(h: &EditorDriver, text: &str) -> usize {
    h.query_all_by_label_contains(text).count()
}

/// Animate (the Timeline's button) gives a still its frame range; K keys every animatable
/// value of the selection at the current frame; each is one undo step with its label.
#[test]
fn animate_and_k_key_the_selection_and_undo_takes_them_back() {
    let mut h = harness(demo());
    assert_eq!(h.state().session().project().animation, None);
    assert!(has_label(&h, "This project is a still"));
    h.get_by_label("Animate").click();
    h.run_steps(2);
    assert_eq!(h.state().session().project().animation, Some(Animation::default()));
    assert_eq!(h.state().session().undo_label().as_deref(), Some("Animate (frames 1–120 at 24 fps)"));
    assert!(h.state().scrub_bar().is_some(), "the Timeline now shows the frame range");

    h.key_press(egui::Key::ArrowRight);
    h.key_press(egui::Key::ArrowRight);
    h.run_steps(2);
    assert_eq!(frame(&h), 3, "Right steps a frame");
    h.state_mut().session_mut().selection.particles.insert(24);
    h.state_mut().session_mut().selection.lights.insert(1);
    h.step();
    h.key_press(egui::Key::K);
    h.run_steps(2);
    let p = h.state().session().project().clone();
    let objects = [Object::Particle(p.particles[24].id), Object::Light(p.lights[1].id)];
    for o in objects {
        for c in p.animatable(o) {
            assert!(p.has_key(c, 3), "{c} keyed at frame 3");
            assert_eq!(p.track(c).unwrap().keys[0].value, p.value_of(c).unwrap());
        }
    }
    assert_eq!(p.tracks.len(), 4 + 3, "a particle's four values and a point light's three");
    let label = h.state().session().undo_label().unwrap();
    assert_eq!(label, format!("Key Particle #{}, Light #{} at frame 3", p.particles[24].id, p.lights[1].id));
    assert!(p.at_frame(3) == p.at_frame(90), "one key per value holds everywhere");

    undo(&mut h);
    assert!(h.state().session().project().tracks.is_empty(), "one undo takes every key back");
    undo(&mut h);
    assert_eq!(h.state().session().project().animation, None, "and the next the frame range");
}

/// Scrubbing shows exactly `at_frame` of the frame under the pointer, and the preview
/// converges to a fresh bake of that still, bit for bit; frames differ from each other.
#[test]
fn scrubbing_shows_at_frame_and_converges_to_its_fresh_bake() {
    let mut h = harness(animated());
    assert_eq!(frame(&h), 1);
    let first = h.state().pipeline().unwrap().read_image().unwrap();
    let bar = h.state().scrub_bar().expect("the Timeline shows its scrub bar");
    h.click(Pos2::new(bar.x_of(12), bar.rect.top() + 8.0), PointerButton::Primary);
    h.run_steps(2);
    assert_eq!(frame(&h), 12, "the click showed the frame under it");
    let still = animated().at_frame(12);
    assert!(h.state().session().frame_still() == still, "the preview's project is at_frame(12) of the file's");
    let status = h.state().preview_status().unwrap();
    assert!(status.converged);
    assert_eq!((status.shown_frame, status.shadows_frame), (Some(12), Some(12)));
    assert_eq!(differs_from_fresh_bake_of(&h, &still), 0, "the converged preview equals a fresh bake of at_frame(12)");
    let now = h.state().pipeline().unwrap().read_image().unwrap();
    assert_ne!(now.rgba, first.rgba, "the moved light shows");
    assert!(!h.state().session().is_dirty(), "scrubbing is not an edit");

    // Dragging along the bar scrubs through frames.
    h.drag(Pos2::new(bar.x_of(12), bar.rect.top() + 8.0), Pos2::new(bar.x_of(30), bar.rect.top() + 8.0), 6);
    assert_eq!(frame(&h), 30);
    assert_eq!(differs_from_fresh_bake_of(&h, &animated().at_frame(30)), 0);
}

/// With the frame-budgeted preview, a jump to another frame shows that frame's fog at once;
/// while its shadows are still an earlier frame's, the Timeline says so, naming both frames,
/// until the preview converges on the new frame.
#[test]
fn a_frame_shown_with_an_earlier_frames_shadows_says_so() {
    let mut h = build(heavy_animated(), Quality::Balanced);
    h.step_until_converged(5000);
    let bar = h.state().scrub_bar().expect("the Timeline shows its scrub bar");
    h.click(Pos2::new(bar.x_of(24), bar.rect.top() + 8.0), PointerButton::Primary);
    let mut mixed = 0;
    for _ in 0..5000 {
        let status = h.state().preview_status().unwrap();
        assert_eq!(status.shown_frame, Some(24), "the frame's fog shows in the frame of the click");
        let shadows = status.shadows_frame.expect("shadows of a frame");
        assert_eq!(status.shadows_stale, shadows != 24, "stale shadows are an earlier frame's");
        let note = format!("Preview: frame 24 with shadows from frame {shadows}");
        assert_eq!(has_label(&h, &note), shadows != 24, "the Timeline says so exactly when they differ");
        mixed += usize::from(shadows != 24);
        if status.converged {
            break;
        }
        h.step();
    }
    let status = h.state().preview_status().unwrap();
    assert!(status.converged);
    assert_eq!(status.shadows_frame, Some(24));
    println!("{mixed} frames showed frame 24 with an earlier frame's shadows");
    assert!(mixed > 0, "the jump never showed stale shadows, so the note was not tested");
}

/// Space plays: in real time the frame follows the clock (kittest's steps are 0.25 s, six
/// frames at 24 fps, so five are dropped per step); every frame shows each frame converged
/// in turn. The preview follows; Space pauses.
#[test]
fn playing_advances_frames_in_real_time_or_every_frame() {
    let mut h = harness(animated());
    h.state_mut().set_looping(false);
    let before = h.state().pipeline().unwrap().read_image().unwrap();
    // A key press is two steps (press, release): play starts on the first, 0.25 s on.
    h.key_press(egui::Key::Space);
    let mut seen = Vec::new();
    for _ in 0..4 {
        h.step();
        seen.push(frame(&h));
    }
    assert!(h.state().playing());
    assert_eq!(seen, vec![7, 13, 19, 25], "the frame due at each step");
    assert_eq!(h.state().playback_rate(), (Some(4.0), 20), "4 frames shown per second, 5 dropped per step");
    assert!(has_label(&h, "Playing 4.0 frames/s of 24, 20 dropped"));
    let after = h.state().pipeline().unwrap().read_image().unwrap();
    assert_ne!(before.rgba, after.rgba, "the preview changed with the frames");
    assert_eq!(h.state().preview_status().unwrap().shown_frame, Some(25));
    h.run_steps(6);
    assert_eq!(frame(&h), 48, "without looping playback stops at the last frame");
    assert!(!h.state().playing());

    h.key_press(egui::Key::Home);
    h.step();
    assert_eq!(frame(&h), 1, "Home shows the first frame");
    h.state_mut().set_play_mode(PlayMode::EveryFrame);
    h.key_press(egui::Key::Space);
    h.step();
    let f0 = frame(&h);
    assert!(f0 > 1, "playing");
    for f in f0 + 1..=f0 + 4 {
        h.step();
        assert_eq!(frame(&h), f, "one frame per converged preview");
        let status = h.state().preview_status().unwrap();
        assert_eq!((status.shown_frame, status.shadows_frame), (Some(f), Some(f)), "frame {f}, its own shadows");
        assert!(status.converged);
    }
    h.key_press(egui::Key::Space);
    h.step();
    assert!(!h.state().playing(), "Space pauses");
    let paused = frame(&h);
    h.run_steps(3);
    assert_eq!(frame(&h), paused);
    h.key_press_modifiers(Modifiers::SHIFT, egui::Key::ArrowRight);
    h.step();
    assert_eq!(frame(&h), 48, "Shift+Right shows the last frame");
    h.key_press(egui::Key::ArrowLeft);
    h.step();
    assert_eq!(frame(&h), 47);
}

/// Moving an animated light without auto-key on a frame without a key changes it on this
/// frame only, with a warning, until the frame changes; with auto-key the move keys it, one
/// undo step. The Inspector's diamond keys and unkeys the one value.
#[test]
fn auto_key_off_warns_and_auto_key_on_keys_the_move() {
    let mut h = harness(animated());
    h.state_mut().session_mut().selection.lights.insert(0);
    h.state_mut().set_tool(Tool::Select);
    for _ in 0..11 {
        h.key_press(egui::Key::ArrowRight);
    }
    h.run_steps(2);
    assert_eq!(frame(&h), 12);
    let keyed = h.state().session().project().clone();
    let c = light_position(&keyed);
    let drag_light = |h: &mut EditorDriver| {
        let rect = h.state().viewport_rect().expect("the viewport is shown");
        let p = h.state().session().project().clone();
        let view = ViewProjection::new(&p.camera, rect);
        let (at, _) = view.project(p.lights[0].position).expect("the light is in view");
        h.drag(at, at + Vec2::new(30.0, -10.0), 5);
        h.run_steps(2);
    };
    drag_light(&mut h);
    let s = h.state().session();
    let moved = s.project().lights[0].position;
    assert_ne!(moved, keyed.at_frame(12).lights[0].position, "the light moved");
    assert!(!s.project().has_key(c, 12), "no key without auto-key");
    assert_eq!(s.frame_still().lights[0].position, moved, "the preview shows the move");
    assert_eq!(s.project().at_frame(12), keyed.at_frame(12), "the animation is unchanged");
    assert!(has_label(&h, "Not keyed: Light #0 Position changed at frame 12 only"));
    h.key_press(egui::Key::ArrowRight);
    h.run_steps(2);
    assert!(!has_label(&h, "Not keyed"), "the warning goes with the frame");
    assert!(h.state().messages().iter().any(|(_, m)| m.contains("Unkeyed changes dropped: Light #0 Position")));
    h.key_press(egui::Key::ArrowLeft);
    h.run_steps(2);
    assert_eq!(h.state().session().project().lights[0].position, keyed.at_frame(12).lights[0].position);

    h.get_by_label("Auto-key").click();
    h.run_steps(2);
    assert!(h.state().session().auto_key);
    let steps = h.state().session().undo_len();
    drag_light(&mut h);
    let s = h.state().session();
    assert!(s.project().has_key(c, 12), "auto-key keyed the move at frame 12");
    assert_eq!(s.project().at_frame(12).lights[0].position, s.project().lights[0].position);
    assert_eq!(s.undo_len(), steps + 1, "the drag is one undo step");
    assert_eq!(s.undo_label().as_deref(), Some("Key Light #0 Position at frame 12"));
    undo(&mut h);
    assert!(!h.state().session().project().has_key(c, 12));
    assert_eq!(h.state().session().project().lights[0].position, keyed.at_frame(12).lights[0].position);

    // The diamond beside the Inspector's position: a click keys the value here, another unkeys it.
    h.get_by_label("Key position").click();
    h.run_steps(2);
    assert!(h.state().session().project().has_key(c, 12));
    assert_eq!(h.state().session().project().track(c).unwrap().keys.len(), 3);
    h.get_by_label("Key position").click();
    h.run_steps(2);
    assert!(!h.state().session().project().has_key(c, 12));
    h.get_by_label("Key intensity").click();
    h.run_steps(2);
    let id = keyed.lights[0].id;
    assert!(h.state().session().project().has_key(Channel(Object::Light(id), Prop::Intensity), 12));
}

/// The report's steps: light #0's intensity keyed at frame 31, an unkeyed change of it at
/// frame 10. The "Not keyed" notice appears, and no row of the Inspector moves: the next
/// click on a diamond lands on the diamond that was under the pointer.
#[test]
fn the_unkeyed_notice_moves_no_inspector_row() {
    let mut h = harness(animated());
    h.state_mut().session_mut().selection.lights.insert(0);
    h.state_mut().session_mut().set_frame(31);
    h.run_steps(2);
    h.get_by_label("Key intensity").click();
    h.run_steps(2);
    let id = h.state().session().project().lights[0].id;
    let intensity = Channel(Object::Light(id), Prop::Intensity);
    assert!(h.state().session().project().has_key(intensity, 31));
    h.state_mut().session_mut().set_frame(10);
    h.run_steps(2);
    let rows = |h: &EditorDriver| [h.get_by_label("Key intensity").rect(), h.get_by_label("Key position").rect()];
    let before = rows(&h);
    let tag = h.state_mut().session_mut().new_tag();
    h.state_mut().session_mut().edit_light(tag, 0, |l| l.intensity += 1.0);
    h.state_mut().session_mut().end_edit();
    h.run_steps(3);
    assert!(has_label(&h, "Not keyed: Light #0 Intensity changed at frame 10 only"), "the notice shows");
    assert_eq!(rows(&h), before, "the Inspector's rows stay where they were");
    h.get_by_label("Key intensity").click();
    h.run_steps(2);
    let p = h.state().session().project();
    assert!(p.has_key(intensity, 10), "the click keyed the intensity");
    assert!(!p.has_key(light_position(p), 10), "and not the position");
}

/// The selection's keys show as markers: dragging one moves its keys (one undo step), a
/// click selects it and Delete deletes its keys (not the selection), and its menu sets the
/// interpolation.
#[test]
fn key_markers_drag_delete_and_set_interpolation() {
    let mut h = harness(animated());
    h.state_mut().session_mut().selection.lights.insert(0);
    h.run_steps(2);
    let p = h.state().session().project().clone();
    let object = Object::Light(p.lights[0].id);
    let c = light_position(&p);
    let (m24, m30) = (marker(&h, 24), marker(&h, 30));
    h.drag(m24, m30, 6);
    assert_eq!(h.state().session().project().key_frames(object), vec![1, 30], "the key moved to frame 30");
    assert_eq!(
        h.state().session().undo_label().as_deref(),
        Some("Move key of Light #0 Position from frame 24 to 30"),
        "one undo step"
    );
    assert_eq!(h.state().selected_key(), Some(30));
    undo(&mut h);
    assert_eq!(h.state().session().project().key_frames(object), vec![1, 24]);

    let m24 = marker(&h, 24);
    h.click(m24, PointerButton::Primary);
    assert_eq!(h.state().selected_key(), Some(24));
    assert_eq!(frame(&h), 1, "selecting a marker does not scrub");
    h.key_press(egui::Key::Delete);
    h.run_steps(2);
    let q = h.state().session().project();
    assert_eq!(q.key_frames(object), vec![1], "Delete deleted the marker's key");
    assert_eq!(q.lights.len(), p.lights.len(), "and not the selected light");
    assert_eq!(h.state().session().undo_label().as_deref(), Some("Delete key of Light #0 Position at frame 24"));
    undo(&mut h);

    let m1 = marker(&h, 1);
    h.click(m1, PointerButton::Secondary);
    h.get_by_label("Smooth").click();
    h.run_steps(2);
    let q = h.state().session().project();
    assert_eq!(q.track(c).unwrap().keys[0].interp, Interp::Smooth);
    assert_eq!(
        h.state().session().undo_label().as_deref(),
        Some("Smooth interpolation on Light #0 Position at frame 1")
    );
}

/// A selected animated light shows its motion path, with a dot at each key.
#[test]
fn a_selected_animated_light_shows_its_motion_path() {
    let mut h = harness(animated());
    let has_path = |h: &EditorDriver| {
        h.output().shapes.iter().any(
            |s| matches!(&s.shape, egui::Shape::Path(p) if matches!(p.stroke.color, egui::epaint::ColorMode::Solid(c) if c == MOTION_PATH)),
        )
    };
    let dots = |h: &EditorDriver| {
        h.output().shapes.iter().filter(|s| matches!(&s.shape, egui::Shape::Circle(c) if c.fill == MOTION_PATH)).count()
    };
    assert!(!has_path(&h), "no path without a selection");
    h.state_mut().session_mut().selection.lights.insert(0);
    h.run_steps(2);
    assert!(has_path(&h));
    assert_eq!(dots(&h), 2, "a dot at each of the two keys");
    h.state_mut().session_mut().selection.lights.clear();
    h.state_mut().session_mut().selection.lights.insert(1);
    h.run_steps(2);
    assert!(!has_path(&h), "the other light is not animated");
}

/// Every timeline command is in the Animation menu; the Timeline is a panel under View;
/// the new shortcuts are on the help sheet.
#[test]
fn every_timeline_command_is_in_the_menus_and_on_the_help_sheet() {
    let mut h = harness(demo());
    h.get_by_label("Animation").click();
    h.run_steps(2);
    assert_eq!(h.query_all_by_label(Command::Animate.text()).count(), 2, "in the menu and the Timeline");
    h.key_press(egui::Key::Escape);
    h.run_steps(2);
    h.get_by_label(Command::Animate.text()).click();
    h.run_steps(2);
    assert!(h.state().session().project().animation.is_some());
    let commands = [
        Command::PlayPause,
        Command::PreviousFrame,
        Command::NextFrame,
        Command::FirstFrame,
        Command::LastFrame,
        Command::InsertKey,
        Command::DeleteKeys,
        Command::AutoKey,
        Command::LoopPlayback,
        Command::PlayEveryFrame,
    ];
    let before: Vec<usize> = commands.iter().map(|c| count_labels(&h, c.text())).collect();
    h.get_by_label("Animation").click();
    h.run_steps(2);
    for (c, n) in commands.iter().zip(before) {
        assert_eq!(count_labels(&h, c.text()), n + 1, "{c:?} is in the Animation menu");
    }
    h.get_by_label_contains(Command::PlayEveryFrame.text()).click();
    h.run_steps(2);
    assert_eq!(h.state().last_command(), Some(Command::PlayEveryFrame), "the menu's check box runs the command");
    h.key_press(egui::Key::Escape);
    h.run_steps(2);
    h.get_by_label("View").click();
    h.run_steps(2);
    h.get_by_label(Command::PanelTimeline.text());
    let sheet = fogsmith::editor::commands::help_sheet();
    for (c, keys) in [(Command::PlayPause, "Space"), (Command::InsertKey, "K"), (Command::FirstFrame, "Home")] {
        assert!(c.shortcut_text().starts_with(keys));
        assert!(sheet.iter().any(|(k, w)| *k == c.shortcut_text() && w == c.text()), "{c:?} on the help sheet");
    }
}

/// The Inspector keys the camera and the medium like the selection: a diamond click keys
/// the field of view and the base extinction at this frame, an edit off their keys is an
/// unkeyed edit until its diamond is clicked, and undo takes each key back. Orbiting the
/// view never keys an animated camera, even with auto-key on.
#[test]
fn the_inspector_keys_the_camera_and_the_medium_and_orbiting_never_keys() {
    let mut h = harness(animated());
    for _ in 0..11 {
        h.key_press(egui::Key::ArrowRight);
    }
    h.run_steps(2);
    assert_eq!(frame(&h), 12);
    let fov = Channel(Object::Camera, Prop::FovYDeg);
    let fog = Channel(Object::Medium, Prop::BaseExtinction);
    let before = h.state().session().project().clone();
    for (c, label) in [(fov, "Key field of view"), (fog, "Key base extinction")] {
        h.get_by_label(label).click();
        h.run_steps(2);
        let p = h.state().session().project();
        assert!(p.has_key(c, 12), "{label} keys {c} at frame 12");
        assert_eq!(p.track(c).unwrap().keys[0].value, before.value_of(c).unwrap());
        assert_eq!(h.state().session().undo_label(), Some(format!("Key {c} at frame 12")));
    }

    // Off its key, an edit is unkeyed until the diamond keys it.
    for _ in 0..18 {
        h.key_press(egui::Key::ArrowRight);
    }
    h.run_steps(2);
    assert_eq!(frame(&h), 30);
    h.state_mut().session_mut().edit(0).camera.fov_y_deg = 55.0;
    h.state_mut().session_mut().edit(0).medium.base_extinction = 0.25;
    h.run_steps(2);
    assert!(has_label(&h, "Not keyed: Camera FovYDeg, Medium BaseExtinction changed at frame 30 only"));
    assert_eq!(h.state().session().frame_still().camera.fov_y_deg, 55.0, "the preview shows the edit");
    h.get_by_label("Key field of view").click();
    h.get_by_label("Key base extinction").click();
    h.run_steps(2);
    assert!(!has_label(&h, "Not keyed"));
    let p = h.state().session().project().clone();
    assert_eq!(p.at_frame(30).camera.fov_y_deg, 55.0);
    assert_eq!(p.at_frame(30).medium.base_extinction, 0.25);
    assert_eq!(p.at_frame(12).camera.fov_y_deg, before.camera.fov_y_deg);
    assert_eq!(p.at_frame(12).medium.base_extinction, before.medium.base_extinction);

    undo(&mut h);
    let s = h.state().session();
    assert!(!s.project().has_key(fog, 30), "undo takes the last key back");
    assert!(s.project().has_key(fov, 30));
    assert_eq!(s.project().medium.base_extinction, before.medium.base_extinction, "posed from its keys again");
    undo(&mut h);
    let s = h.state().session();
    assert!(!s.project().has_key(fov, 30));
    assert_eq!(s.project().camera.fov_y_deg, before.camera.fov_y_deg);
    for _ in 0..4 {
        undo(&mut h); // the two edits, then the two keys at frame 12
    }
    assert!(h.state().session().project().track(fov).is_none() && h.state().session().project().track(fog).is_none());

    // An animated camera position: orbiting with auto-key on is an unkeyed edit, not a key.
    let position = Channel(Object::Camera, Prop::Position);
    h.get_by_label("Key camera position").click();
    h.run_steps(2);
    assert!(h.state().session().project().has_key(position, 30));
    h.get_by_label("Auto-key").click();
    h.run_steps(2);
    assert!(h.state().session().auto_key);
    let keyed = h.state().session().project().clone();
    let rect = h.state().viewport_rect().expect("the viewport is shown");
    let from = rect.center();
    h.event(Event::PointerMoved(from));
    h.step();
    h.press(from, PointerButton::Secondary, true);
    for k in 1..=5 {
        h.event(Event::PointerMoved(from + Vec2::new(12.0 * k as f32, 4.0 * k as f32)));
        h.step();
    }
    h.press(from + Vec2::new(60.0, 20.0), PointerButton::Secondary, false);
    h.run_steps(2);
    let s = h.state().session();
    assert_ne!(s.project().camera.position, keyed.camera.position, "the view orbited");
    assert_eq!(s.project().tracks, keyed.tracks, "orbiting keyed nothing");
    assert!(s.unkeyed().contains_key(&position), "the orbit is an unkeyed edit");
    assert!(has_label(&h, "Not keyed: Camera Position"));
}

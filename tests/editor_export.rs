//! File → Export… driven through the real window with egui_kittest on a real wgpu device
//! (lavapipe without a GPU): formats and options picked by clicking, the destination through
//! Fogsmith's own file dialog, the files read back with the project's readers and compared
//! with the pipeline's read-back; refused combinations; choices remembered per project.

use egui::{Key, Modifiers};
use egui_kittest::kittest::{NodeT, Queryable};
use fogsmith::editor::app::{ExportFormat, ImageFormat, PreviewScale, StartProject};
use fogsmith::editor::files::FileDialogs;
use fogsmith::editor::EditorOptions;
use fogsmith::export::frame::{Frame, Handedness, Preset, Units, UpAxis};
use fogsmith::export::ktx::{r8_texel, Ktx2Format};
use fogsmith::export::vdb_read::{list_vdb_grids, read_vdb_grid};
use fogsmith::scene::{save_project, Project};
use std::path::{Path, PathBuf};

mod common;
use common::editor::{has_label, read_ev};
use fogsmith::editor::driver::EditorDriver;

/// The demo saved as `name` in `dir`, changed by `edit`.
fn project_file(dir: &Path, name: &str, edit: impl FnOnce(&mut Project)) -> PathBuf {
    let mut project = fogsmith::editor::demo_project().expect("the demo parses");
    edit(&mut project);
    let path = dir.join(name);
    save_project(&path, &project).expect("save the project");
    path
}

/// The editor on `project` with Fogsmith's own file dialog and `state_dir` for its choices.
fn editor(project: &Path, state_dir: &Path) -> EditorDriver {
    let options = EditorOptions {
        file_dialogs: Some(FileDialogs::detect_with(|_| None)),
        state_dir: Some(state_dir.to_path_buf()),
        ..EditorOptions::default()
    };
    let start = StartProject::resolve(Some(project.to_path_buf())).expect("start");
    assert_eq!(start.error, None);
    common::editor::harness_scaled(start, options, PreviewScale::Quarter)
}

fn open_with_ctrl_e(h: &mut EditorDriver) {
    h.shortcut(Modifiers::COMMAND, Key::E);
    assert!(h.state().export_window().is_some(), "Ctrl+E opens the Export window");
}

#[track_caller]
fn click(h: &mut EditorDriver, label: &str) {
    h.get_by_label(label).click();
    h.run_steps(2);
}

/// Export to… then Enter in the file dialog (its proposed name in the project's folder), and
/// the background job to its end; returns the message that says what was written.
fn export_through_the_dialog(h: &mut EditorDriver) -> String {
    click(h, "Export to…");
    assert!(h.state().export_window().is_none(), "the window gives way to the file dialog");
    assert!(h.state().built_in_dialog_open(), "Export to… asks where to write");
    h.key_press(Key::Enter);
    h.run_steps(2);
    for _ in 0..20_000 {
        let messages = h.state().messages();
        if let Some((_, m)) = messages.iter().find(|(_, m)| m.starts_with("Exported")) {
            assert!(!h.state().built_in_dialog_open());
            return m.clone();
        }
        if let Some((_, m)) = messages.iter().find(|(e, _)| *e) {
            panic!("the export failed: {m}");
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
        h.step();
    }
    panic!("the export did not finish: {:?}", h.state().messages());
}

fn meta_string(grid: &fogsmith::export::vdb_read::VdbFloatGrid, name: &str) -> String {
    let m = grid.metadata.iter().find(|m| m.0 == name).unwrap_or_else(|| panic!("{} has no {name}", grid.name));
    String::from_utf8_lossy(&m.2).into_owned()
}

/// VDB with the Houdini preset (picked after Blender, so the preset must reset the axes),
/// transmittance added and no compression: the grids the CLI writes for these options, in
/// Houdini's frame (Y-up, metres, right-handed: index → world lands on the project's cell
/// centres), holding exactly the pipeline's read-back values.
#[test]
fn vdb_with_the_houdini_preset_holds_the_pipeline_volumes_in_houdinis_frame() {
    let dir = common::temp_dir();
    let project = project_file(dir.path(), "room.ron", |_| {});
    let mut h = editor(&project, &dir.path().join("state"));
    click(&mut h, "File");
    click(&mut h, "Export… Ctrl+E");
    let choices = h.state().export_window().expect("File → Export… opens the window");
    assert_eq!(choices.format, ExportFormat::Vdb);
    click(&mut h, "Blender");
    let blender = h.state().export_window().unwrap();
    assert_eq!((blender.preset, blender.settings.frame), (Some(Preset::Blender), Frame::preset(Preset::Blender)));
    click(&mut h, "Houdini");
    click(&mut h, "transmittance per light");
    click(&mut h, "none");
    let choices = h.state().export_window().unwrap();
    assert_eq!(choices.preset, Some(Preset::Houdini));
    let houdini = Frame { up: UpAxis::Y, units: Units::M, handedness: Handedness::Right };
    assert_eq!(choices.settings.frame, houdini);
    let summary = export_through_the_dialog(&mut h);
    assert!(summary.contains("room.vdb") && summary.contains("5 grids"), "{summary}");

    let vdb = dir.path().join("room.vdb");
    let names: Vec<String> = list_vdb_grids(&vdb).expect("the VDB reads back").into_iter().map(|g| g.name).collect();
    assert_eq!(names, ["density", "optical_depth_0", "transmittance_0", "optical_depth_1", "transmittance_1"]);
    let ev = read_ev(&h);
    let opv = h.state().pipeline().unwrap().read_opv(1).expect("OPV readback");
    let r = ev.grid.resolution;
    for (name, want) in
        [("density", ev.data.clone()), ("transmittance_1", opv.data.iter().map(|t| (-t).exp()).collect())]
    {
        let grid = read_vdb_grid(&vdb, Some(name)).expect("grid");
        assert_eq!(grid.frame, houdini, "{name}");
        assert_eq!(
            (meta_string(&grid, "up_axis"), meta_string(&grid, "handedness")),
            ("Y".into(), "right".into()),
            "{name}"
        );
        assert!(!grid.half, "{name}: full floats");
        for (i, j, k) in [(0, 0, 0), (r.x - 1, r.y - 1, r.z - 1), (r.x / 2, 3, r.z - 2)] {
            let centre = ev.grid.cell_center(i, j, k);
            let w = grid.transform.index_to_world([i as f64, j as f64, k as f64]);
            for a in 0..3 {
                assert!((w[a] - centre[a] as f64).abs() < 1e-5, "{name} ({i}, {j}, {k}) → {w:?}, want {centre}");
            }
        }
        for k in 0..r.z {
            for j in 0..r.y {
                for i in 0..r.x {
                    let v = want[ev.grid.index(i, j, k)];
                    let back = grid.value_at([i as i32, j as i32, k as i32]);
                    assert_eq!(back.to_bits(), v.to_bits(), "{name} at ({i}, {j}, {k})");
                }
            }
        }
    }
}

/// The rendered image is written at the project's output size, not the viewport's, and as
/// `fogsmith render` would write it; the EXR variant holds half floats when asked.
#[test]
fn the_rendered_image_has_the_projects_output_size() {
    let dir = common::temp_dir();
    let project = project_file(dir.path(), "shot.ron", |p| {
        p.render.width = 96;
        p.render.height = 54;
    });
    let mut h = editor(&project, &dir.path().join("state"));
    assert_ne!(h.state().preview_size(), [96, 54], "the preview renders at another size");
    open_with_ctrl_e(&mut h);
    click(&mut h, "Rendered image (.png / .exr)");
    h.get_by_label_contains("96×54 px");
    assert!(h.query_by_label("Y-up").is_none(), "axes do not apply to an image");
    let summary = export_through_the_dialog(&mut h);
    assert!(summary.contains("96×54"), "{summary}");
    let png = image::open(dir.path().join("shot.png")).expect("a PNG").to_rgb8();
    assert_eq!(png.dimensions(), (96, 54));

    // The same image as `fogsmith render` writes it, from a pipeline of its own.
    let p = fogsmith::scene::load_project(&project).unwrap();
    let mut pipeline = fogsmith::gpu::FogPipeline::new(fogsmith::gpu::GpuContext::new_headless().expect("adapter"));
    pipeline.update(&p, &fogsmith::gpu::FrameRequest::for_project(&p)).expect("render");
    let reference = dir.path().join("reference.png");
    fogsmith::export::image::write_image(&reference, &pipeline.read_image().unwrap(), p.render.exposure).unwrap();
    let reference = image::open(&reference).unwrap().to_rgb8();
    let diffs: Vec<i32> =
        png.as_raw().iter().zip(reference.as_raw()).map(|(a, b)| (*a as i32 - *b as i32).abs()).collect();
    let lit = png.as_raw().iter().filter(|v| **v > 8).count();
    assert!(lit > png.as_raw().len() / 20, "the image shows the fog ({lit} lit channels)");
    assert!(
        diffs.iter().all(|d| *d <= 3),
        "the PNG matches `fogsmith render` (largest difference {:?})",
        diffs.iter().max()
    );

    open_with_ctrl_e(&mut h);
    assert_eq!(h.state().export_window().unwrap().format, ExportFormat::Image, "the last format is proposed");
    click(&mut h, "EXR");
    click(&mut h, "half floats");
    let choices = h.state().export_window().unwrap();
    assert_eq!((choices.image, choices.settings.exr_half), (ImageFormat::Exr, true));
    export_through_the_dialog(&mut h);
    let meta = exr::meta::MetaData::read_from_file(dir.path().join("shot.exr"), false).expect("an EXR");
    let header = &meta.headers[0];
    assert_eq!((header.layer_size.width(), header.layer_size.height()), (96, 54));
    assert!(header.channels.list.iter().all(|c| c.sample_type == exr::meta::attribute::SampleType::F16));
}

/// USD with a left-handed frame cannot be written: the window says what to change and its
/// Export to… button stays disabled; once right-handed it writes the stage and its VDB.
#[test]
fn usd_with_a_left_handed_frame_is_refused_until_it_is_right_handed() {
    let dir = common::temp_dir();
    let project = project_file(dir.path(), "hall.ron", |_| {});
    let mut h = editor(&project, &dir.path().join("state"));
    open_with_ctrl_e(&mut h);
    click(&mut h, "USD stage (.usda + .vdb)");
    click(&mut h, "Unreal");
    let message = h.get_by_label_contains("USD stages are right-handed");
    let node = message.accesskit_node();
    let text = node.label().or_else(|| node.value()).unwrap_or_default();
    assert!(text.contains("Z-up, cm, left-handed") && text.contains("choose right-handed"), "{text}");
    assert!(h.get_by_label("Export to…").accesskit_node().is_disabled(), "Export to… is disabled");
    click(&mut h, "Export to…");
    assert!(!h.state().built_in_dialog_open(), "nothing is asked or written");
    assert!(h.state().export_window().is_some());

    click(&mut h, "density grid");
    h.get_by_label_contains("tick “density grid”");
    click(&mut h, "density grid");
    click(&mut h, "right-handed");
    assert!(h.query_by_label_contains("USD stages are right-handed").is_none(), "the message goes");
    let choices = h.state().export_window().unwrap();
    assert_eq!(choices.preset, None, "no preset is Z-up, cm, right-handed");
    assert_eq!(choices.settings.frame, Frame { up: UpAxis::Z, units: Units::Cm, handedness: Handedness::Right });
    export_through_the_dialog(&mut h);
    let usda = std::fs::read_to_string(dir.path().join("hall.usda")).expect("the stage");
    assert!(usda.contains("def Volume") && usda.contains("@./hall.vdb@"), "{usda}");
    assert!(usda.contains("upAxis = \"Z\"") && usda.contains("metersPerUnit = 0.01"), "{usda}");
    let grid = read_vdb_grid(&dir.path().join("hall.vdb"), Some("density")).expect("the VDB beside it");
    assert_eq!(grid.frame, choices.settings.frame);
}

/// The window reopens on the choices last exported for the project, in this editor and the
/// next one; another project starts from the defaults; a damaged file is ignored with a note.
/// The KTX2 export on the way is read back texel by texel against the pipeline's EV.
#[test]
fn reopening_the_window_shows_the_last_choices_for_the_project() {
    let dir = common::temp_dir();
    let state = dir.path().join("state");
    let a = project_file(dir.path(), "a.ron", |_| {});
    let b = project_file(dir.path(), "b.ron", |_| {});
    let mut h = editor(&a, &state);
    open_with_ctrl_e(&mut h);
    click(&mut h, "KTX2 texture (.ktx2 + .fogvolume.ron)");
    assert!(h.query_by_label("Houdini").is_none(), "presets do not apply to KTX2");
    click(&mut h, "r8");
    export_through_the_dialog(&mut h);
    let ev = read_ev(&h);
    let ktx = ktx2::Reader::new(std::fs::read(dir.path().join("a.ktx2")).unwrap()).expect("a KTX2 file");
    let header = ktx.header();
    assert_eq!(header.format, Some(ktx2::Format::R8_UNORM));
    let r = ev.grid.resolution;
    assert_eq!((header.pixel_width, header.pixel_height, header.pixel_depth), (r.x, r.y, r.z));
    let scale = ev.data.iter().fold(0.0f32, |m, v| m.max(*v));
    let data = ktx.levels().next().unwrap().data;
    for (n, v) in ev.data.iter().enumerate() {
        assert_eq!(data[n], r8_texel(*v, scale), "texel {n}");
    }
    let snippet = std::fs::read_to_string(dir.path().join("a.fogvolume.ron")).expect("the snippet");
    assert!(snippet.contains("s.is_srgb = false).load(\"a.ktx2\"))"), "{snippet}");

    open_with_ctrl_e(&mut h);
    let again = h.state().export_window().unwrap();
    assert_eq!((again.format, again.settings.ktx2_format), (ExportFormat::Ktx2, Ktx2Format::R8));
    let r8 = h.get_by_label("r8").accesskit_node().toggled();
    assert_eq!(r8, Some(egui::accesskit::Toggled::True), "the window shows r8 chosen");
    h.key_press(Key::Escape);
    h.run_steps(2);
    assert!(h.state().export_window().is_none(), "Escape closes the window");
    drop(h);

    let mut h = editor(&a, &state);
    open_with_ctrl_e(&mut h);
    let next = h.state().export_window().unwrap();
    assert_eq!((next.format, next.settings.ktx2_format), (ExportFormat::Ktx2, Ktx2Format::R8), "kept between runs");
    drop(h);

    let mut h = editor(&b, &state);
    open_with_ctrl_e(&mut h);
    assert_eq!(h.state().export_window().unwrap().format, ExportFormat::Vdb, "another project starts afresh");
    drop(h);

    let file = state.join("export-choices.ron");
    assert!(std::fs::read_to_string(&file).unwrap().contains("a.ron"));
    std::fs::write(&file, "ExportMemory(projects: [(\"a.ron\", (format: Mp4").unwrap();
    let mut h = editor(&a, &state);
    open_with_ctrl_e(&mut h);
    assert_eq!(h.state().export_window().unwrap().format, ExportFormat::Vdb, "a damaged file is ignored");
    let messages = h.state().messages();
    let notes: Vec<_> = messages.iter().filter(|(_, m)| m.contains("export-choices.ron")).collect();
    assert_eq!(notes.len(), 1, "{messages:?}");
    assert!(!notes[0].0 && !notes[0].1.contains('\n') && notes[0].1.contains("Ignored"), "{notes:?}");
}

/// Cancel in the status bar stops the image's render at the next work item: nothing is
/// written, and the message says so.
#[test]
fn an_image_export_is_cancelled_while_it_renders() {
    let dir = common::temp_dir();
    // Long enough to be mid-render when Cancel is clicked, even on a fast GPU: 8 Mpixels
    // with fine ray-march steps.
    let project = project_file(dir.path(), "big.ron", |p| {
        p.render.width = 3840;
        p.render.height = 2160;
        p.render.step_factor = 0.02;
    });
    let mut h = editor(&project, &dir.path().join("state"));
    open_with_ctrl_e(&mut h);
    click(&mut h, "Rendered image (.png / .exr)");
    click(&mut h, "Export to…");
    h.key_press(Key::Enter);
    h.run_steps(2);
    assert_eq!(h.state().busy(), 1, "the render runs: {:?}", h.state().messages());
    click(&mut h, "Cancel");
    for _ in 0..20_000 {
        if h.state().busy() == 0 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
        h.step();
    }
    h.run_steps(2);
    let messages = h.state().messages();
    assert!(
        messages.iter().any(|(e, m)| !e && m.contains("Export cancelled") && m.contains("big.png")),
        "{messages:?}"
    );
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left.len(), 2, "the project and the state folder only: {left:?}");
}

/// "Bake lighting for engines" with the camera phase adds the vec3s `emission` grid to the
/// VDB, as `fogsmith export --bake-light --bake-phase camera` does.
#[test]
fn baking_the_lighting_adds_the_emission_grid() {
    let dir = common::temp_dir();
    let project = project_file(dir.path(), "lit.ron", |_| {});
    let mut h = editor(&project, &dir.path().join("state"));
    open_with_ctrl_e(&mut h);
    click(&mut h, "Bake lighting for engines");
    click(&mut h, "towards the camera");
    let choices = h.state().export_window().unwrap();
    assert_eq!(choices.settings.bake_light, Some(fogsmith::gpu::BakePhase::Camera));
    let summary = export_through_the_dialog(&mut h);
    assert!(summary.contains("lit.vdb"), "{summary}");
    let grids = list_vdb_grids(&dir.path().join("lit.vdb")).expect("the VDB reads back");
    let emission = grids.iter().find(|g| g.name == "emission").unwrap_or_else(|| panic!("no emission grid: {grids:?}"));
    assert_eq!(emission.tree_type, "Tree_vec3s_5_4_3");
    assert!(!emission.importable, "a vector grid is not offered as a density");
}

/// NanoVDB through the window: the format's own extension, the grid options but not the
/// VDB's half floats and compression, and a file NanoVDB validates.
#[test]
fn nanovdb_is_one_of_the_formats() {
    let dir = common::temp_dir();
    let project = project_file(dir.path(), "nano.ron", |_| {});
    let mut h = editor(&project, &dir.path().join("state"));
    open_with_ctrl_e(&mut h);
    click(&mut h, "NanoVDB (.nvdb)");
    assert_eq!(h.state().export_window().unwrap().format, ExportFormat::Nvdb);
    assert!(h.query_by_label("half floats").is_none() && h.query_by_label("zip").is_none());
    click(&mut h, "transmittance per light");
    let summary = export_through_the_dialog(&mut h);
    assert!(summary.contains("nano.nvdb") && summary.contains("5 grids"), "{summary}");
    let out = std::process::Command::new("nanovdb_validate")
        .arg("-v")
        .arg(dir.path().join("nano.nvdb"))
        .output()
        .expect("nanovdb_validate runs: ./setup.sh installs libnanovdb-tools");
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success() && text.matches(": passed").count() == 5 && !text.contains("failed"), "{text}");
}

/// An animated project exports a range of frames: "Frames" proposes `NAME.####.vdb`, and the
/// three frames baked in the background equal, value for value in every grid, those of
/// `fogsmith export --frames` on the same project.
#[test]
fn a_vdb_sequence_equals_the_command_lines_value_for_value() {
    use fogsmith::scene::animation::{Animation, Channel, Interp, KeyValue, Object, Prop};
    let dir = common::temp_dir();
    let project = project_file(dir.path(), "anim.ron", |p| {
        p.animation = Some(Animation { fps: 24.0, start: 1, end: 3 });
        let c = Channel(Object::Light(p.lights[0].id), Prop::Position);
        let at = p.lights[0].position;
        p.set_key(c, 1, KeyValue::Vec3(at), Interp::Linear).unwrap();
        p.set_key(c, 3, KeyValue::Vec3(at + glam::Vec3::new(0.5, -0.4, 0.2)), Interp::Linear).unwrap();
        let fog = Channel(Object::Medium, Prop::BaseExtinction);
        p.set_key(fog, 1, KeyValue::Float(0.02), Interp::Linear).unwrap();
        p.set_key(fog, 3, KeyValue::Float(0.1), Interp::Linear).unwrap();
    });
    let mut h = editor(&project, &dir.path().join("state"));
    open_with_ctrl_e(&mut h);
    let this = h.get_by_label("This frame (1)").accesskit_node().toggled();
    assert_eq!(this, Some(egui::accesskit::Toggled::True), "the frame on show by default");
    click(&mut h, "Frames");
    assert!(has_label(&h, "Writes anim.####.vdb"), "the window names the frame pattern");
    let summary = export_through_the_dialog(&mut h);
    assert!(summary.contains("3 frames"), "{summary}");

    let cli = dir.path().join("cli.####.vdb");
    let out = std::process::Command::new(env!("CARGO_BIN_EXE_fogsmith"))
        .args(["export", project.to_str().unwrap(), "--frames", "1-3", "--vdb", cli.to_str().unwrap(), "--quiet"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r = fogsmith::scene::load_project(&project).unwrap().grid.resolution;
    let mut differ_between_frames = false;
    for f in 1..=3 {
        let ours = dir.path().join(format!("anim.{f:04}.vdb"));
        let theirs = dir.path().join(format!("cli.{f:04}.vdb"));
        let names = |p: &Path| -> Vec<String> { list_vdb_grids(p).unwrap().into_iter().map(|g| g.name).collect() };
        assert_eq!(names(&ours), names(&theirs), "frame {f}: the same grids");
        assert!(names(&ours).contains(&"optical_depth_0".to_string()));
        for name in names(&ours) {
            let (a, b) = (read_vdb_grid(&ours, Some(&name)).unwrap(), read_vdb_grid(&theirs, Some(&name)).unwrap());
            let first = (f > 1).then(|| read_vdb_grid(&dir.path().join("anim.0001.vdb"), Some(&name)).unwrap());
            for k in 0..r.z as i32 {
                for j in 0..r.y as i32 {
                    for i in 0..r.x as i32 {
                        let v = a.value_at([i, j, k]);
                        assert_eq!(v.to_bits(), b.value_at([i, j, k]).to_bits(), "frame {f} {name} at ({i}, {j}, {k})");
                        differ_between_frames |= first.as_ref().is_some_and(|g| g.value_at([i, j, k]) != v);
                    }
                }
            }
        }
    }
    assert!(differ_between_frames, "each frame holds its own values");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left.len(), 2 + 3 + 3, "the project, the state folder and six VDBs, no temporary: {left:?}");
}

/// Cancel during a sequence stops the frame under way: every frame written before it is
/// complete, and nothing else is left (no temporary, no partial frame).
#[test]
fn a_cancelled_sequence_keeps_its_completed_frames_and_nothing_else() {
    use fogsmith::scene::animation::{Animation, Channel, Interp, KeyValue, Object, Prop};
    let dir = common::temp_dir();
    // Each frame's march at this size takes long enough to be under way when Cancel comes.
    let project = project_file(dir.path(), "slow.ron", |p| {
        p.render.width = 640;
        p.render.height = 360;
        p.render.step_factor = 0.05;
        p.animation = Some(Animation { fps: 24.0, start: 1, end: 3 });
        let fog = Channel(Object::Medium, Prop::BaseExtinction);
        p.set_key(fog, 1, KeyValue::Float(0.02), Interp::Linear).unwrap();
        p.set_key(fog, 3, KeyValue::Float(0.1), Interp::Linear).unwrap();
    });
    let mut h = editor(&project, &dir.path().join("state"));
    open_with_ctrl_e(&mut h);
    click(&mut h, "Frames");
    click(&mut h, "Export to…");
    h.key_press(Key::Enter);
    h.run_steps(2);
    let first = dir.path().join("slow.0001.vdb");
    for _ in 0..200_000 {
        if first.exists() {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
        h.step();
    }
    assert!(first.exists(), "frame 1 is written: {:?}", h.state().messages());
    click(&mut h, "Cancel");
    for _ in 0..200_000 {
        if h.state().busy() == 0 {
            break;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
        h.step();
    }
    h.run_steps(2);
    let messages = h.state().messages();
    let message = messages.iter().find(|(_, m)| m.contains("cancelled after")).map(|(_, m)| m.clone());
    let message = message.unwrap_or_else(|| panic!("no cancel message: {messages:?}"));
    let mut left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    left.sort();
    let frames: Vec<&String> = left.iter().filter(|n| n.ends_with(".vdb")).collect();
    assert!(!frames.is_empty() && frames.len() < 3, "{left:?}");
    assert!(message.contains(&format!("after {} of 3 frames", frames.len())), "{message}");
    for (k, name) in frames.iter().enumerate() {
        assert_eq!(**name, format!("slow.{:04}.vdb", k + 1), "{left:?}");
        let grids = list_vdb_grids(&dir.path().join(name)).expect("a completed frame reads back");
        assert!(grids.iter().any(|g| g.name == "density"), "{name}");
    }
    assert_eq!(left.len(), 2 + frames.len(), "the project, the state folder and the completed frames only: {left:?}");
}

/// After an export into another folder, the next Export, Save As and Open start there (each
/// kind then keeps its own folder); an export into a folder that does not exist is refused at
/// once, before any bake, with the folder named.
#[test]
fn dialogs_remember_their_folder_and_a_missing_folder_is_refused_at_once() {
    use fogsmith::editor::files::DialogKind;
    let dir = common::temp_dir();
    let project = project_file(dir.path(), "fog.ron", |_| {});
    let mut h = editor(&project, &dir.path().join("state"));
    let home = std::fs::canonicalize(dir.path()).unwrap();
    for kind in [DialogKind::Export, DialogKind::SaveAs, DialogKind::Open] {
        assert_eq!(h.state().dialog_start(kind), Some(home.clone()), "{kind:?} starts in the project's folder");
    }
    let out = dir.path().join("renders");
    std::fs::create_dir(&out).unwrap();
    let choices = fogsmith::editor::app::ExportChoices { format: ExportFormat::Vdb, ..Default::default() };
    h.state_mut().export(choices, out.join("fog.vdb"));
    common::editor::wait_idle(&mut h);
    assert!(out.join("fog.vdb").is_file(), "the export was written: {:?}", h.state().messages());
    let out = std::fs::canonicalize(&out).unwrap();
    for kind in [DialogKind::Export, DialogKind::SaveAs, DialogKind::Open] {
        assert_eq!(h.state().dialog_start(kind), Some(out.clone()), "{kind:?} starts where the export went");
    }
    h.state_mut().save_as(dir.path().join("fog.ron"));
    common::editor::wait_idle(&mut h);
    assert_eq!(h.state().dialog_start(DialogKind::SaveAs), Some(home.clone()), "Save As keeps its own folder");
    assert_eq!(h.state().dialog_start(DialogKind::Export), Some(out), "and Export its own");

    let missing = dir.path().join("rendrs").join("fog.vdb");
    let before = h.state().messages().len();
    h.state_mut().export(choices, missing.clone());
    assert_eq!(h.state().busy(), 0, "nothing is baked or written");
    let messages = h.state().messages();
    let new: Vec<_> = messages[before..].iter().filter(|(error, _)| *error).collect();
    assert!(
        new.iter().any(|(_, m)| m.contains("rendrs") && m.contains("does not exist")),
        "the error names the missing folder at once: {messages:?}"
    );
    assert!(!missing.parent().unwrap().exists(), "no folder was made");
}

/// Errors do not pile up over the panels: the same error again counts up on its toast, at
/// most three toasts show at once with the rest folded into one line, and "Dismiss all"
/// closes every one.
#[test]
fn error_toasts_fold_instead_of_piling_up() {
    let dir = common::temp_dir();
    let project = project_file(dir.path(), "fog.ron", |_| {});
    let mut h = editor(&project, &dir.path().join("state"));
    let choices = fogsmith::editor::app::ExportChoices { format: ExportFormat::Vdb, ..Default::default() };
    for k in 0..6 {
        h.state_mut().export(choices, dir.path().join(format!("missing-{k}")).join("fog.vdb"));
    }
    for _ in 0..3 {
        h.state_mut().export(choices, dir.path().join("missing-5").join("fog.vdb"));
    }
    h.run_steps(2);
    let errors = h.state().messages().into_iter().filter(|(error, _)| *error).count();
    assert_eq!(errors, 6, "one message per distinct error");
    assert!(has_label(&h, "(×4)"), "the repeated error counts up");
    assert_eq!(h.get_all_by_label("✕").count(), 3, "three toasts on screen");
    h.get_by_label("3 earlier messages");
    h.get_by_label("Dismiss all").click();
    h.run_steps(2);
    assert!(h.state().messages().is_empty(), "Dismiss all closed them: {:?}", h.state().messages());
    assert_eq!(h.query_all_by_label("✕").count(), 0);
}

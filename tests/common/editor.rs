//! The editor the tests drive: [`EditorDriver`] opened on a project the way each test needs
//! it, and what the tests read back from it (volumes, labels, the preview against a fresh
//! bake). Without an adapter these fail; they never skip.

use egui_kittest::kittest::Queryable;
use fogsmith::editor::app::{PreviewScale, Quality, StartProject};
use fogsmith::editor::driver::{DriverSetup, EditorDriver};
use fogsmith::editor::EditorOptions;
use fogsmith::scene::{Project, Volume};

/// The bundled demo, as a bare `fogsmith` opens it.
pub fn demo() -> StartProject {
    StartProject::resolve(None).expect("the bundled demo parses")
}

/// `project`, unsaved, as the editor starts on it.
pub fn start(project: Project) -> StartProject {
    StartProject { project, path: None, name: "test.ron".into(), error: None }
}

pub fn harness(start: StartProject) -> EditorDriver {
    harness_with(start, EditorOptions::default())
}

/// The editor at a quarter of the preview's resolution: the march's cost is per pixel, and
/// what these tests check does not depend on it (the layout snapshot uses full resolution).
pub fn harness_with(start: StartProject, options: EditorOptions) -> EditorDriver {
    harness_scaled(start, options, PreviewScale::Quarter)
}

/// The editor with every frame converged after its first three, which must render.
pub fn harness_scaled(start: StartProject, options: EditorOptions, scale: PreviewScale) -> EditorDriver {
    let mut h = build(start, options, Quality::Full, scale);
    h.run_steps(3);
    assert_eq!(h.state().gpu_error(), None, "the preview must render");
    h
}

/// The editor as it starts for a user: the frame-budgeted preview, nothing rendered yet.
pub fn progressive_harness() -> EditorDriver {
    build(demo(), EditorOptions::default(), Quality::Balanced, PreviewScale::Quarter)
}

/// A 1280×800 editor window on the pipeline's adapter, before its first frame.
pub fn build(start: StartProject, options: EditorOptions, quality: Quality, scale: PreviewScale) -> EditorDriver {
    let setup = DriverSetup { quality, preview_scale: Some(scale), options, ..DriverSetup::default() };
    EditorDriver::new(start, setup)
}

/// Steps until the preview converges; fails the test after 5000 steps.
#[track_caller]
pub fn converge(h: &mut EditorDriver) {
    assert!(h.step_until_converged(5000), "the preview did not converge");
}

/// Steps until the background jobs are done, and once more; fails the test after 2000 steps.
pub fn wait_idle(h: &mut EditorDriver) {
    for _ in 0..2000 {
        if h.state().busy() == 0 {
            h.step();
            return;
        }
        std::thread::sleep(std::time::Duration::from_millis(5));
        h.step();
    }
    panic!("background jobs did not finish");
}

/// The pipeline's extinction volume.
pub fn read_ev(h: &EditorDriver) -> Volume {
    h.state()
        .pipeline()
        .expect("the editor shares egui-wgpu's device with the pipeline")
        .read_ev()
        .expect("EV readback")
}

/// Whether a widget's label holds `text`.
pub fn has_label(h: &EditorDriver, text: &str) -> bool {
    h.query_all_by_label_contains(text).next().is_some()
}

/// The preview image against a fresh bake of `p` at the same size: how many values differ
/// in their bits, the largest difference and the fresh bake's peak.
pub fn compare_with_fresh_bake_of(h: &EditorDriver, p: &Project) -> (usize, f32, f32) {
    let shown = h.state().pipeline().unwrap().read_image().unwrap();
    let mut fresh = fogsmith::gpu::FogPipeline::new(fogsmith::gpu::GpuContext::new_headless().expect("an adapter"));
    let request = fogsmith::gpu::FrameRequest {
        width: shown.width,
        height: shown.height,
        ..fogsmith::gpu::FrameRequest::for_project(p)
    };
    fresh.update(p, &request).unwrap();
    let want = fresh.read_image().unwrap();
    let pairs = || shown.rgba.iter().flatten().zip(want.rgba.iter().flatten());
    let (diff, peak) = pairs().fold((0f32, 0f32), |(d, m), (a, b)| (d.max((a - b).abs()), m.max(b.abs())));
    (pairs().filter(|(a, b)| a.to_bits() != b.to_bits()).count(), diff, peak)
}

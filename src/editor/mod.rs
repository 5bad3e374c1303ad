//! The editor: an eframe/egui_dock window to paint gaussian fog, place lights and watch the
//! pipeline's live preview beside slices of its volumes.
//!
//! - [`session`]: the project under edit and its named edit commands, composed of the
//!   selection (`selection`), the undo/redo `history` and the animated pose (`pose`),
//!   with the file it came from (no UI).
//! - [`tools`], [`gizmo`], [`view`], [`slices`]: the geometry and data behind tools, picking,
//!   the viewport and the slice views (no UI either).
//! - [`commands`]: every command in one table (text, tooltip, shortcuts), behind the menus,
//!   the key dispatch and the help sheet.
//! - [`app`]: the eframe application: the dock and the state it shows, persisted between runs.
//! - `state`: what the panels share (the session, view state, jobs, recovery, the preview);
//!   what acts on it is split by concern: `preview` (the pipeline driver), `jobs`
//!   (background work and exports), `export_choices` (what an export writes) and `export`
//!   (its window; `export_memory` keeps the choices per project), `playback` (the frame
//!   clock), `file_actions`, `recovery`, `dispatch` (commands and keys), `menus`, `shell`
//!   (status bar, messages), `scripted` (`--screenshot`, `--measure-fps`).
//! - `viewport` (input and gestures), `overlays` (what it draws over the preview),
//!   `slice_panel`, `panels` and [`timeline`] draw the dockable tabs, from the state alone.
//! - [`driver`]: the editor headless with a real pipeline and scripted input, for the tests
//!   and the interaction bench.
//!
//! The editor never calls wgpu itself: it shares egui-wgpu's device with the
//! [`FogPipeline`](crate::gpu::FogPipeline) and hands the pipeline's display view to egui-wgpu.

pub mod app;
pub mod commands;
mod dispatch;
pub mod driver;
mod export;
mod export_choices;
mod export_memory;
mod file_actions;
pub mod files;
pub mod gizmo;
mod history;
mod import;
mod jobs;
mod layout;
mod menus;
mod overlays;
mod panels;
pub mod pick_index;
mod playback;
mod pose;
mod preview;
mod recovery;
mod scripted;
mod selection;
pub mod session;
mod shell;
mod slice_panel;
pub mod slices;
mod state;
pub mod timeline;
pub mod tools;
pub mod view;
mod viewport;

pub use app::EditorApp;
pub use layout::Tab;

use crate::scene::Project;
use eframe::egui_wgpu;
use std::path::PathBuf;
use std::sync::Arc;

/// The demo project opened by a bare `fogsmith`.
pub const DEMO_PROJECT: &str = include_str!("../../projects/cornell.ron");
pub const DEMO_NAME: &str = "cornell.ron (demo)";

/// Why the editor could not start.
#[derive(Debug, thiserror::Error)]
pub enum EditorError {
    #[error(
        "no display: the editor needs a window (neither DISPLAY nor WAYLAND_DISPLAY is set). \
         For headless use, render with `fogsmith render PROJECT.ron -o image.png`"
    )]
    NoDisplay,
    #[error("could not open the editor window: {0}. For headless use, render with `fogsmith render PROJECT.ron -o image.png`")]
    Window(String),
    #[error("the demo project does not parse: {0}")]
    Demo(String),
}

/// Start-up options, mostly for scripted runs.
#[derive(Clone, Debug, Default)]
pub struct EditorOptions {
    /// Save a PNG of the window once the first preview frame is on screen, then exit.
    pub screenshot: Option<PathBuf>,
    /// Redraw continuously for this many seconds (half still, half orbiting), print the
    /// frame rates, then exit.
    pub measure_fps: Option<f32>,
    /// Write crash recovery files while there are unsaved changes, and offer to restore
    /// those left by an earlier run (see [`crate::scene::recovery`]).
    pub recovery: bool,
    /// Where recovery files and the Export window's choices go; `None` means
    /// [`crate::scene::recovery::state_dir`].
    pub state_dir: Option<PathBuf>,
    /// Paint this many particles as one stroke once the editor has opened.
    pub scripted_stroke: Option<usize>,
    /// Which file dialogs to use; `None` decides from the environment
    /// ([`files::FileDialogs::detect`]).
    pub file_dialogs: Option<files::FileDialogs>,
}

/// The project a bare `fogsmith` opens.
pub fn demo_project() -> Result<Project, EditorError> {
    crate::scene::parse_project(DEMO_PROJECT, std::path::Path::new(DEMO_NAME))
        .map_err(|e| EditorError::Demo(e.to_string()))
}

/// How the editor asks egui-wgpu for its device: the adapter the pipeline would pick
/// (Vulkan before GL, which gives wrong 3D storage texture results on llvmpipe), with the
/// adapter's full limits and timestamp queries when available, so the pipeline can run on
/// the same device. `FOGSMITH_BACKEND=vulkan|gl|metal|dx12` restricts the backend.
pub fn wgpu_setup() -> egui_wgpu::WgpuSetup {
    use egui_wgpu::wgpu;
    let mut setup = egui_wgpu::WgpuSetupCreateNew::without_display_handle();
    setup.instance_descriptor.backends = match std::env::var("FOGSMITH_BACKEND").ok().as_deref() {
        Some("vulkan") => wgpu::Backends::VULKAN,
        Some("gl") => wgpu::Backends::GL,
        Some("metal") => wgpu::Backends::METAL,
        Some("dx12") => wgpu::Backends::DX12,
        _ => wgpu::Backends::PRIMARY | wgpu::Backends::GL,
    };
    setup.native_adapter_selector =
        Some(Arc::new(|adapters: &[wgpu::Adapter], surface: Option<&wgpu::Surface<'_>>| {
            adapters
                .iter()
                .filter(|a| a.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS))
                .filter(|a| surface.is_none_or(|s| !s.get_capabilities(a).formats.is_empty()))
                .max_by_key(|a| crate::gpu::adapter_rank(&a.get_info()))
                .cloned()
                .ok_or_else(|| crate::gpu::GpuError::NoAdapter.to_string())
        }));
    setup.device_descriptor = Arc::new(|adapter: &wgpu::Adapter| wgpu::DeviceDescriptor {
        label: Some("fogsmith editor"),
        required_features: adapter.features() & crate::gpu::OPTIONAL_FEATURES,
        required_limits: adapter.limits(),
        ..Default::default()
    });
    egui_wgpu::WgpuSetup::CreateNew(setup)
}

/// Opens the editor window on `project_path`, or on the demo project when `None`.
/// Returns when the window closes.
pub fn run(project_path: Option<PathBuf>, options: EditorOptions) -> Result<(), EditorError> {
    #[cfg(all(unix, not(target_os = "macos")))]
    if std::env::var_os("DISPLAY").is_none() && std::env::var_os("WAYLAND_DISPLAY").is_none() {
        return Err(EditorError::NoDisplay);
    }
    let start = app::StartProject::resolve(project_path)?;
    let native = eframe::NativeOptions {
        renderer: eframe::Renderer::Wgpu,
        wgpu_options: egui_wgpu::WgpuConfiguration { wgpu_setup: wgpu_setup(), ..Default::default() },
        viewport: egui::ViewportBuilder::default()
            .with_title("Fogsmith")
            .with_app_id("fogsmith")
            .with_inner_size([1400.0, 880.0])
            .with_min_inner_size([640.0, 400.0])
            .with_drag_and_drop(true),
        ..Default::default()
    };
    let result = std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
        eframe::run_native(
            "fogsmith",
            native,
            Box::new(move |cc| Ok(Box::new(EditorApp::new(cc, start, options)) as Box<dyn eframe::App>)),
        )
    }));
    match result {
        Ok(Ok(())) => Ok(()),
        Ok(Err(e)) => Err(EditorError::Window(e.to_string())),
        Err(panic) => {
            let message = panic
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| panic.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "the windowing system failed".into());
            Err(EditorError::Window(message))
        }
    }
}

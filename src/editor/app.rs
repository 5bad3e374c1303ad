//! The eframe application: dock layout, menus, shortcuts, files (open/save in background
//! threads, recent files, drag-and-drop, unsaved-changes confirmation), messages, and the
//! bridge to the pipeline (one shared device, the preview handed to egui-wgpu as a texture).

use super::commands::Command;
use super::files::{DialogSpec, FileDialogs};
use super::session::Session;
use super::slices::{Slice, SliceSettings};
use super::tools::{Brush, Stroke, Tool};
use super::{EditorError, EditorOptions};
use crate::gpu::{FogPipeline, FrameReport, FrameRequest, GpuContext, Progress};
use crate::scene::{load_project, save_project, Project};
use eframe::egui_wgpu::{self, wgpu};
use egui::{Context, Id, Key};
use egui_dock::{DockArea, DockState, NodeIndex};
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::{mpsc, Arc};
use std::time::{Duration, Instant};

/// The dockable panels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Tab {
    Viewport,
    Slices,
    Outliner,
    Inspector,
    Stats,
}

impl Tab {
    pub const ALL: [Tab; 5] = [Tab::Viewport, Tab::Slices, Tab::Outliner, Tab::Inspector, Tab::Stats];
    pub fn title(self) -> &'static str {
        match self {
            Tab::Viewport => "Viewport",
            Tab::Slices => "Slices",
            Tab::Outliner => "Outliner",
            Tab::Inspector => "Inspector",
            Tab::Stats => "Stats",
        }
    }
}

/// The default arrangement: outliner left, viewport centre with slices below, inspector and
/// stats right.
pub fn default_layout() -> DockState<Tab> {
    let mut dock = DockState::new(vec![Tab::Viewport]);
    let tree = dock.main_surface_mut();
    let [center, _right] = tree.split_right(NodeIndex::root(), 0.76, vec![Tab::Inspector, Tab::Stats]);
    let [center, _left] = tree.split_left(center, 0.2, vec![Tab::Outliner]);
    tree.split_below(center, 0.64, vec![Tab::Slices]);
    dock
}

/// The project the editor starts on.
pub struct StartProject {
    pub project: Project,
    pub path: Option<PathBuf>,
    pub name: String,
    pub error: Option<String>,
}

impl StartProject {
    /// The file at `path`, or the demo; a file that fails to load opens an empty project and
    /// the error is shown in the window.
    pub fn resolve(path: Option<PathBuf>) -> Result<Self, EditorError> {
        match path {
            None => {
                Ok(Self { project: super::demo_project()?, path: None, name: super::DEMO_NAME.into(), error: None })
            }
            Some(path) => match load_project(&path) {
                Ok(project) => Ok(Self { project, path: Some(path), name: String::new(), error: None }),
                Err(e) => Ok(Self {
                    project: Project::default(),
                    path: None,
                    name: "untitled.ron".into(),
                    error: Some(e.to_string()),
                }),
            },
        }
    }
}

/// What is remembered between runs.
#[derive(Default, Serialize, Deserialize)]
#[serde(default)]
struct Persisted {
    dock: Option<DockState<Tab>>,
    recent: Vec<PathBuf>,
    tool: Tool,
    brush: Brush,
    slices: SliceSettings,
    quality: Quality,
    preview_scale: PreviewScale,
    outline_all: Option<bool>,
    show_gizmo: Option<bool>,
}

const STORAGE_KEY: &str = "fogsmith-editor";
/// Seconds between recovery files while there are unsaved changes: `FOGSMITH_AUTOSAVE_SECS`,
/// default 5.
fn recovery_interval_s() -> f64 {
    static SECS: std::sync::OnceLock<f64> = std::sync::OnceLock::new();
    *SECS.get_or_init(|| {
        std::env::var("FOGSMITH_AUTOSAVE_SECS")
            .ok()
            .and_then(|v| v.parse::<f64>().ok())
            .filter(|s| s.is_finite() && *s >= 0.0)
            .unwrap_or(5.0)
    })
}
/// GPU time the preview may take per frame. The rest of a frame (egui's layout and
/// painting) stays well within 100 ms on a software adapter, so the window keeps following
/// the pointer while the pipeline refines the preview over the following frames.
pub const FRAME_BUDGET_MS: f64 = 30.0;

/// How the preview trades responsiveness for finished frames.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Quality {
    /// Frame-budgeted: every frame shows the edit at once (reduced resolution, optical
    /// depths possibly stale), and the full image catches up over the next frames.
    #[default]
    Balanced,
    /// Every frame waits for the converged full-resolution image (the window freezes while
    /// it renders; for screenshots and comparisons).
    Full,
}

/// Preview pixels per screen pixel: a coarser preview renders in a fraction of the time
/// (the march's cost is per pixel), for slow adapters and large windows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum PreviewScale {
    #[default]
    Full,
    Half,
    Quarter,
}

impl PreviewScale {
    pub const ALL: [PreviewScale; 3] = [PreviewScale::Full, PreviewScale::Half, PreviewScale::Quarter];
    pub fn factor(self) -> f32 {
        match self {
            PreviewScale::Full => 1.0,
            PreviewScale::Half => 0.5,
            PreviewScale::Quarter => 0.25,
        }
    }
    pub fn label(self) -> &'static str {
        match self {
            PreviewScale::Full => "full",
            PreviewScale::Half => "½",
            PreviewScale::Quarter => "¼",
        }
    }
}

const MAX_RECENT: usize = 10;

/// An action that would discard unsaved changes.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    New,
    OpenDialog,
    Open(PathBuf),
    Revert,
    Quit,
}

enum JobResult {
    Picked { purpose: Pick, spec: Box<DialogSpec>, path: Option<PathBuf>, seconds: f64 },
    Exported { path: PathBuf, result: Result<String, String> },
    Loaded { path: PathBuf, result: Result<Box<Project>, String> },
    Saved { path: PathBuf, generation: u64, result: Result<(), String> },
    Exact { key: ExactKey, result: Result<Vec<f64>, String> },
}

/// What a file dialog was opened for.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Export {
    /// OpenVDB: density plus optical depth per light.
    Vdb,
    /// Multi-channel OpenEXR with every z slice of density and optical depth per light.
    ExrSlices,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Pick {
    Open,
    SaveAs,
    Export(Export),
    ImportVdb,
}

/// Identifies the exact optical depths computed for one slice of one project state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct ExactKey {
    pub epoch: u64,
    pub generation: u64,
    pub light: usize,
    pub axis: super::slices::Axis,
    pub index: u32,
}

/// A dismissable message.
pub(crate) struct Toast {
    pub text: String,
    pub error: bool,
    pub born: f64,
}

/// The pipeline on egui-wgpu's device and the texture its frames are shown through.
pub(crate) struct GpuView {
    render_state: egui_wgpu::RenderState,
    pub pipeline: FogPipeline,
    pub texture: Option<(egui::TextureId, [u32; 2])>,
    /// Inputs of the last converged preview: nothing to do until they change.
    converged: Option<(u64, u64, [u32; 2])>,
    /// The last progress in which a stage ran.
    pub report: FrameReport,
    pub progress: Progress,
    pub error: Option<String>,
    /// Images shown so far.
    pub renders: u64,
    /// Wall time of the last pipeline call, all items and waits included.
    pub update_ms: f64,
    /// Frame at which the pipeline last ran, so that it runs once per frame.
    last_frame: u64,
    /// Epoch and session generation of the image on show.
    shown: Option<(u64, u64)>,
}

impl GpuView {
    fn new(render_state: &egui_wgpu::RenderState) -> Self {
        let info = render_state.adapter.get_info();
        let ctx = GpuContext::from_device(render_state.device.clone(), render_state.queue.clone(), info);
        Self {
            render_state: render_state.clone(),
            pipeline: FogPipeline::new(ctx),
            texture: None,
            converged: None,
            report: FrameReport::default(),
            progress: Progress::default(),
            error: None,
            renders: 0,
            update_ms: 0.0,
            last_frame: u64::MAX,
            shown: None,
        }
    }

    /// Whether the preview still has work to do for the current inputs.
    pub fn refining(&self) -> bool {
        self.converged.is_none() && self.error.is_none()
    }

    /// Advances the pipeline towards the session's scene at `size` pixels within `budget`
    /// (None: to convergence); returns whether a new image is on show.
    fn render(&mut self, session: &Session, epoch: u64, size: [u32; 2], budget: Option<Duration>) -> bool {
        let key = (epoch, session.generation(), size);
        if self.converged == Some(key) {
            return false;
        }
        self.converged = None;
        let project = session.project();
        let request =
            FrameRequest { width: size[0], height: size[1], scheme: project.propagation.scheme, force: false };
        let started = Instant::now();
        let result = self.pipeline.advance(project, &request, budget);
        self.update_ms = started.elapsed().as_secs_f64() * 1e3;
        let progress = match result {
            Ok(p) => p,
            Err(e) => {
                self.error = Some(e.to_string());
                self.converged = Some(key);
                return false;
            }
        };
        self.error = None;
        if progress.report.counters.dispatches > 0 {
            self.report = progress.report;
        }
        self.progress = progress;
        if progress.converged() {
            self.converged = Some(key);
        }
        if !progress.new_image {
            return false;
        }
        self.renders += 1;
        self.shown = Some((epoch, session.generation()));
        if let Some((view, shown)) = self.pipeline.display_view() {
            let mut renderer = self.render_state.renderer.write();
            let device = &self.render_state.device;
            match self.texture {
                None => {
                    let id = renderer.register_native_texture(device, view, wgpu::FilterMode::Linear);
                    self.texture = Some((id, shown));
                }
                Some((id, _)) => {
                    // Quick and full images live in different textures.
                    renderer.update_egui_texture_from_wgpu_texture(device, view, wgpu::FilterMode::Linear, id);
                    self.texture = Some((id, shown));
                }
            }
        }
        true
    }
}

/// An export written in a background thread: its progress and a request to stop it.
pub(crate) struct ExportJob {
    path: PathBuf,
    /// Fraction written, as f32 bits.
    fraction: Arc<AtomicU32>,
    cancel: Arc<AtomicBool>,
}

/// The result of an export cancelled from the status bar.
const EXPORT_CANCELLED: &str = "cancelled";

/// What the preview shows, for scripted drivers of the editor (tests, `bench`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PreviewStatus {
    /// Session generation of the scene the image on show was rendered from.
    pub shown_generation: Option<u64>,
    /// Full resolution with fresh optical depths, nothing left to do.
    pub converged: bool,
    /// The image on show reads optical depths that lag the scene.
    pub shadows_stale: bool,
    pub shown_size: [u32; 2],
    /// Images shown so far.
    pub renders: u64,
}

/// Frame times of the last couple of seconds.
#[derive(Default)]
pub(crate) struct FrameClock {
    times: VecDeque<Instant>,
}

impl FrameClock {
    fn tick(&mut self) {
        let now = Instant::now();
        self.times.push_back(now);
        while self.times.len() > 2 && now.duration_since(self.times[0]).as_secs_f32() > 2.0 {
            self.times.pop_front();
        }
    }
    /// Frames per second over the recent window, if the editor has been redrawing.
    pub fn fps(&self) -> Option<f32> {
        let (first, last) = (self.times.front()?, self.times.back()?);
        let span = last.duration_since(*first).as_secs_f32();
        (self.times.len() > 2 && span > 0.0).then(|| (self.times.len() - 1) as f32 / span)
    }
}

/// A pointer gesture in progress in the viewport or a slice.
pub(crate) enum Gesture {
    Orbit,
    Pan,
    Box {
        start: egui::Pos2,
    },
    /// `start`: where the drag began; `applied`: the displacement already applied.
    Move {
        tag: u64,
        depth: f32,
        start: egui::Pos2,
        applied: glam::Vec3,
    },
    MoveLight {
        tag: u64,
        light: usize,
        depth: f32,
        start: egui::Pos2,
        applied: glam::Vec3,
    },
    Paint(Stroke),
    SlicePaint(Stroke),
    Erase {
        tag: u64,
    },
    ScaleDrag {
        tag: u64,
        targets: std::collections::BTreeSet<usize>,
        last_x: f32,
    },
    /// A drag on a move-gizmo handle: `center` where the gizmo stood and `grab` the point the
    /// handle was grabbed at, both when the drag began; `applied`: the displacement applied;
    /// `snap`: whether it was snapped to the grid cell (Ctrl held).
    Gizmo {
        tag: u64,
        handle: super::gizmo::Handle,
        center: glam::Vec3,
        grab: glam::Vec3,
        applied: glam::Vec3,
        snap: bool,
    },
    /// A cancelled drag: the rest of it, until the buttons go up, does nothing (no orbit).
    Cancelled,
}

/// G / S: the selection follows the pointer until a click confirms or Esc cancels.
pub(crate) struct Modal {
    pub scale: bool,
    pub tag: u64,
    pub start: egui::Pos2,
    pub applied: glam::Vec3,
    pub applied_factor: f32,
}

/// Everything the panels share, apart from the dock layout, in four parts: the document
/// (the session with its undo history), the view state, the background jobs and crash
/// recovery; plus the preview on the GPU and the shell around them (messages, dialogs).
pub struct EditorState {
    /// The document: the project, selection and snapshot undo history.
    pub(crate) session: Session,
    /// Bumped when the whole project is replaced, so caches keyed on generations reset.
    pub(crate) epoch: u64,
    pub(crate) view: ViewState,
    pub(crate) jobs: Jobs,
    recovery: RecoveryState,
    pub(crate) gpu: Option<GpuView>,
    pub(crate) gpu_missing: Option<String>,
    pub(crate) toasts: Vec<Toast>,
    pub(crate) recent: Vec<PathBuf>,
    pub(crate) confirm: Option<Action>,
    after_save: Option<Action>,
    options: EditorOptions,
    frames: u64,
    screenshot_requested: bool,
    measure_start: Option<Instant>,
    measure_frames: [u32; 2],
    title: String,
    quit_confirmed: bool,
    ctx: Context,
    /// The system's file dialogs, or the built-in one and why.
    file_dialogs: FileDialogs,
    /// The built-in file dialog while it is open, and what it was opened for.
    built_in_dialog: Option<(Pick, egui_file_dialog::FileDialog)>,
    built_in_explained: bool,
    /// What the pipeline's base layer was loaded from: base volume, grid and project file.
    base_loaded: Option<(Option<crate::scene::BaseVolume>, crate::scene::GridSpec, Option<PathBuf>)>,
    /// File → Import VDB… while its window is open.
    import: Option<super::import::ImportVdb>,
    /// The command run last, for scripted drivers.
    last_command: Option<Command>,
}

/// How the artist looks at the document: tools, brush, slices, gestures, the viewport.
/// Not part of undo; the tool, brush and slice settings persist between runs.
pub(crate) struct ViewState {
    pub tool: Tool,
    pub brush: Brush,
    pub slices: SliceSettings,
    pub show_shortcuts: bool,
    pub gesture: Option<Gesture>,
    pub modal: Option<Modal>,
    pub scale_wheel: Option<(u64, f64)>,
    pub viewport_rect: Option<egui::Rect>,
    pub preview_size: [u32; 2],
    pub interacting: bool,
    pub quality: Quality,
    pub preview_scale: PreviewScale,
    /// Scripted camera motion counts as interaction (`--measure-fps`).
    pub force_interacting: bool,
    pub clock: FrameClock,
    pub continuous: bool,
    pub slice: SliceCache,
    pub rename: Option<(super::tools::Hit, String)>,
    pub outliner_anchor: Option<super::tools::Hit>,
    /// Outline every particle in the viewport; otherwise only the selection.
    pub outline_all: bool,
    /// What "Fit grid to particles" keeps.
    pub fit_keep: crate::scene::FitKeep,
    /// Draw the Slices panel's plane in the viewport.
    pub show_slice_plane: bool,
    /// Show the move gizmo at the selection's centre (Select tool).
    pub show_gizmo: bool,
    /// Where a Paint stroke would start under the pointer.
    pub brush_point: Option<glam::Vec3>,
    /// The pipeline's EV read back for painting at the fog's depth, with the epoch and
    /// content generation it was read at.
    pub fog_ev: Option<(u64, u64, crate::scene::Volume)>,
}

/// Work running in background threads and what waits for it.
pub(crate) struct Jobs {
    tx: mpsc::Sender<JobResult>,
    rx: mpsc::Receiver<JobResult>,
    /// What each running job is doing, for the status bar.
    pub busy: Vec<String>,
    /// An export waiting for the bake to complete.
    pending_export: Option<(Export, PathBuf)>,
    /// The export being written in the background.
    export_job: Option<ExportJob>,
}

/// Crash recovery: where recovery files go and what an earlier run left.
#[derive(Default)]
pub(crate) struct RecoveryState {
    /// Where recovery files go, when enabled.
    dir: Option<PathBuf>,
    written: Option<(u64, u64, f64)>,
    /// Work left by an earlier run that did not exit cleanly, offered at start.
    pub found: Vec<(PathBuf, crate::scene::recovery::Recovery)>,
}

/// The slice currently shown and what it was made from.
#[derive(Default)]
pub(crate) struct SliceCache {
    pub key: Option<(u64, u64, SliceSettings)>,
    pub slice: Option<Slice>,
    pub texture: Option<egui::TextureHandle>,
    pub error: Option<String>,
    pub exact: Option<(ExactKey, Result<Vec<f64>, String>)>,
    pub exact_pending: Option<ExactKey>,
    pub hover: Option<String>,
}

/// The editor application.
pub struct EditorApp {
    pub dock: DockState<Tab>,
    pub state: EditorState,
}

impl EditorApp {
    pub fn new(cc: &eframe::CreationContext<'_>, start: StartProject, options: EditorOptions) -> Self {
        let persisted: Persisted = cc.storage.and_then(|s| eframe::get_value(s, STORAGE_KEY)).unwrap_or_default();
        let (gpu, gpu_missing) = match &cc.wgpu_render_state {
            Some(rs) => (Some(GpuView::new(rs)), None),
            None => (None, Some("no wgpu renderer: the preview needs eframe's wgpu backend".to_string())),
        };
        let (jobs_tx, jobs_rx) = mpsc::channel();
        let file_dialogs = options.file_dialogs.clone().unwrap_or_else(FileDialogs::detect);
        let dock = persisted.dock.filter(|d| d.iter_all_tabs().next().is_some()).unwrap_or_else(default_layout);
        let mut state = EditorState {
            session: Session::new(start.project, start.path, &start.name),
            epoch: 1,
            view: ViewState {
                tool: persisted.tool,
                brush: persisted.brush,
                slices: persisted.slices,
                show_shortcuts: false,
                gesture: None,
                modal: None,
                scale_wheel: None,
                viewport_rect: None,
                preview_size: [640, 400],
                interacting: false,
                quality: if options.screenshot.is_some() { Quality::Full } else { persisted.quality },
                preview_scale: persisted.preview_scale,
                force_interacting: false,
                clock: FrameClock::default(),
                continuous: options.measure_fps.is_some(),
                slice: SliceCache::default(),
                rename: None,
                outliner_anchor: None,
                outline_all: persisted.outline_all.unwrap_or(true),
                fit_keep: crate::scene::FitKeep::default(),
                show_slice_plane: true,
                show_gizmo: persisted.show_gizmo.unwrap_or(true),
                brush_point: None,
                fog_ev: None,
            },
            jobs: Jobs { tx: jobs_tx, rx: jobs_rx, busy: Vec::new(), pending_export: None, export_job: None },
            recovery: RecoveryState::default(),
            gpu,
            gpu_missing,
            toasts: Vec::new(),
            recent: persisted.recent,
            confirm: None,
            after_save: None,
            options,
            frames: 0,
            screenshot_requested: false,
            measure_start: None,
            measure_frames: [0, 0],
            title: String::new(),
            quit_confirmed: false,
            ctx: cc.egui_ctx.clone(),
            file_dialogs,
            built_in_dialog: None,
            built_in_explained: false,
            base_loaded: None,
            import: None,
            last_command: None,
        };
        if state.options.recovery {
            let dir = crate::scene::recovery::state_dir();
            for found in crate::scene::recovery::find_recoveries(&dir) {
                match found {
                    Ok(r) => state.recovery.found.push(r),
                    Err(e) => state.error(format!("A recovery file could not be read: {e}")),
                }
            }
            state.recovery.dir = Some(dir);
        }
        if let Some(e) = start.error {
            state.error(e);
        }
        if let Some(n) = state.options.scripted_stroke {
            let g = state.session.project().grid;
            let (centre, span) = ((g.min + g.max) * 0.5, (g.max - g.min) * 0.3);
            let tag = state.session.new_tag();
            state.session.add_particles(
                tag,
                (0..n).map(|i| {
                    let f = if n > 1 { i as f32 / (n - 1) as f32 - 0.5 } else { 0.0 };
                    crate::scene::Particle::new(centre + span * f, span.min_element() * 0.2, 2.0)
                }),
            );
            state.session.end_edit();
        }
        if let Some(p) = state.session.path().map(Path::to_owned) {
            state.push_recent(p);
        }
        Self { dock, state }
    }

    pub fn session(&self) -> &Session {
        &self.state.session
    }
    pub fn session_mut(&mut self) -> &mut Session {
        &mut self.state.session
    }
    pub fn pipeline(&self) -> Option<&FogPipeline> {
        self.state.gpu.as_ref().map(|g| &g.pipeline)
    }
    /// The preview's screen rectangle in the last frame.
    pub fn viewport_rect(&self) -> Option<egui::Rect> {
        self.state.view.viewport_rect
    }
    pub fn tool(&self) -> Tool {
        self.state.view.tool
    }
    pub fn set_tool(&mut self, tool: Tool) {
        self.state.view.tool = tool;
    }
    /// Full-resolution previews make frames independent of the adapter's speed (tests).
    pub fn set_quality(&mut self, quality: Quality) {
        self.state.view.quality = quality;
    }
    pub fn set_preview_scale(&mut self, scale: PreviewScale) {
        self.state.view.preview_scale = scale;
    }
    /// Pixels of the preview image (the viewport's, times the preview scale).
    pub fn preview_size(&self) -> [u32; 2] {
        self.state.view.preview_size
    }
    pub fn brush_mut(&mut self) -> &mut Brush {
        &mut self.state.view.brush
    }
    pub fn slice_settings_mut(&mut self) -> &mut SliceSettings {
        &mut self.state.view.slices
    }
    /// The slice shown in the Slices panel, if it has been drawn.
    pub fn current_slice(&self) -> Option<&Slice> {
        self.state.view.slice.slice.as_ref()
    }
    /// Messages currently shown (errors and notices).
    pub fn messages(&self) -> Vec<(bool, String)> {
        self.state.toasts.iter().map(|t| (t.error, t.text.clone())).collect()
    }
    /// Where the preview stands: what it shows and what is left to refine.
    pub fn preview_status(&self) -> Option<PreviewStatus> {
        let gpu = self.state.gpu.as_ref()?;
        Some(PreviewStatus {
            shown_generation: gpu.shown.filter(|&(e, _)| e == self.state.epoch).map(|(_, g)| g),
            converged: !gpu.refining(),
            shadows_stale: gpu.progress.shadows_stale,
            shown_size: gpu.progress.shown_size,
            renders: gpu.renders,
        })
    }

    pub fn gpu_error(&self) -> Option<String> {
        self.state.gpu.as_ref().and_then(|g| g.error.clone()).or_else(|| self.state.gpu_missing.clone())
    }
    /// Background jobs (saving, loading, dialogs) still running.
    pub fn busy(&self) -> usize {
        self.state.jobs.busy.len()
    }
    /// Runs or (with unsaved changes) asks before running `action`.
    pub fn request(&mut self, action: Action) {
        self.state.request(action);
    }
    /// Saves to `path` in the background.
    pub fn save_as(&mut self, path: PathBuf) {
        self.state.save_to(path);
    }
    /// Exports the baked volumes to `path` in the background.
    pub fn export(&mut self, kind: Export, path: PathBuf) {
        self.state.export_to(kind, path);
    }
    /// Asks where to export, as File → Export does.
    pub fn export_dialog(&mut self, kind: Export) {
        self.state.export_dialog(kind);
    }
    /// View → Particle outlines: every particle, or only the selection.
    pub fn set_outline_all(&mut self, all: bool) {
        self.state.view.outline_all = all;
    }
    /// Where a Paint stroke would start under the pointer (the brush preview's depth).
    pub fn brush_point(&self) -> Option<glam::Vec3> {
        self.state.view.brush_point
    }
    /// View → Slice plane.
    pub fn set_show_slice_plane(&mut self, show: bool) {
        self.state.view.show_slice_plane = show;
    }
    /// View → Move gizmo.
    pub fn set_show_gizmo(&mut self, show: bool) {
        self.state.view.show_gizmo = show;
    }
    /// The command run last, from a menu or a shortcut.
    pub fn last_command(&self) -> Option<Command> {
        self.state.last_command
    }
    /// File → Import VDB…, as the menu does.
    pub fn import_vdb_dialog(&mut self) {
        self.state.import_vdb_dialog();
    }
    /// Opens the Import VDB window on `path`, as after choosing it in the file dialog.
    pub fn import_vdb(&mut self, path: PathBuf) {
        self.state.import_vdb(path);
    }
    /// Whether Fogsmith's own file dialog is open.
    pub fn built_in_dialog_open(&self) -> bool {
        self.state.built_in_dialog.is_some()
    }
    pub fn title(&self) -> &str {
        &self.state.title
    }

    fn menu_bar(&mut self, ui: &mut egui::Ui) {
        egui::MenuBar::new().ui(ui, |ui| {
            ui.menu_button("File", |ui| self.state.file_menu(ui));
            ui.menu_button("Edit", |ui| self.state.edit_menu(ui));
            ui.menu_button("View", |ui| self.view_menu(ui));
            ui.menu_button("Help", |ui| {
                if Command::Shortcuts.menu_button(ui, true) {
                    self.state.view.show_shortcuts = true;
                }
            });
        });
    }

    fn view_menu(&mut self, ui: &mut egui::Ui) {
        ui.label("Panels");
        for tab in Tab::ALL {
            let mut open = self.dock.find_tab(&tab).is_some();
            if ui.checkbox(&mut open, tab.title()).on_hover_text("Show or hide this panel").changed() {
                self.set_tab_open(tab, open);
            }
        }
        if ui.button("Reset layout").on_hover_text("Back to the default arrangement of panels").clicked() {
            self.dock = default_layout();
        }
        ui.separator();
        ui.checkbox(&mut self.state.view.outline_all, "Particle outlines")
            .on_hover_text("Outline every particle in the viewport; when off, only the selection is outlined");
        ui.checkbox(&mut self.state.view.show_slice_plane, "Slice plane")
            .on_hover_text("Show the Slices panel's plane in the viewport, in its axis colour");
        ui.checkbox(&mut self.state.view.show_gizmo, "Move gizmo").on_hover_text(
            "With the Select tool, arrows and squares at the selection's centre: drag one to move along that axis or in that plane (Ctrl snaps to the grid cell; Esc or right click cancels)",
        );
        ui.separator();
        ui.label("Camera");
        self.state.camera_menu(ui);
    }

    /// Opens (in the focused area) or closes a panel.
    pub fn set_tab_open(&mut self, tab: Tab, open: bool) {
        match (self.dock.find_tab(&tab), open) {
            (Some(path), false) => {
                self.dock.remove_tab(path);
            }
            (None, true) => {
                if self.dock.iter_all_tabs().next().is_none() {
                    self.dock = DockState::new(vec![tab]);
                } else {
                    self.dock.push_to_first_leaf(tab);
                }
            }
            _ => {}
        }
    }

    /// Makes `tab` the visible tab of its area.
    pub fn focus_tab(&mut self, tab: Tab) {
        if let Some(path) = self.dock.find_tab(&tab) {
            let _ = self.dock.set_active_tab(path);
        } else {
            self.set_tab_open(tab, true);
        }
    }
}

impl eframe::App for EditorApp {
    fn ui(&mut self, ui: &mut egui::Ui, _frame: &mut eframe::Frame) {
        let ctx = ui.ctx().clone();
        self.state.begin_frame(&ctx);
        egui::Panel::top("menu").show(ui, |ui| self.menu_bar(ui));
        egui::Panel::bottom("status").show(ui, |ui| self.state.status_bar(ui));
        let style = egui_dock::Style::from_egui(ui.style().as_ref());
        egui::CentralPanel::default().frame(egui::Frame::NONE).show(ui, |ui| {
            DockArea::new(&mut self.dock).style(style).show_inside(ui, &mut self.state);
        });
        self.state.end_frame(&ctx);
    }

    fn on_exit(&mut self) {
        self.state.drop_recovery();
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        let persisted = Persisted {
            dock: Some(self.dock.clone()),
            recent: self.state.recent.clone(),
            tool: self.state.view.tool,
            brush: self.state.view.brush,
            slices: self.state.view.slices,
            quality: self.state.view.quality,
            preview_scale: self.state.view.preview_scale,
            outline_all: Some(self.state.view.outline_all),
            show_gizmo: Some(self.state.view.show_gizmo),
        };
        eframe::set_value(storage, STORAGE_KEY, &persisted);
    }
}

impl egui_dock::TabViewer for EditorState {
    type Tab = Tab;

    fn title(&mut self, tab: &mut Tab) -> egui::WidgetText {
        tab.title().into()
    }

    fn id(&mut self, tab: &mut Tab) -> Id {
        Id::new(("fogsmith-tab", tab.title()))
    }

    fn ui(&mut self, ui: &mut egui::Ui, tab: &mut Tab) {
        match tab {
            Tab::Viewport => super::viewport::show(self, ui),
            Tab::Slices => super::panels::slices(self, ui),
            Tab::Outliner => super::panels::outliner(self, ui),
            Tab::Inspector => super::panels::inspector(self, ui),
            Tab::Stats => super::panels::stats(self, ui),
        }
    }

    /// The Viewport has no close button on its tab, where a click meant to focus it would
    /// land; View → Panels still hides it.
    fn is_closeable(&self, tab: &Tab) -> bool {
        *tab != Tab::Viewport
    }

    fn scroll_bars(&self, tab: &Tab) -> [bool; 2] {
        match tab {
            Tab::Inspector | Tab::Stats => [false, true],
            _ => [false, false],
        }
    }
}

impl EditorState {
    pub(crate) fn error(&mut self, text: impl Into<String>) {
        let born = self.ctx.input(|i| i.time);
        self.toasts.push(Toast { text: text.into(), error: true, born });
    }

    pub(crate) fn info(&mut self, text: impl Into<String>) {
        let born = self.ctx.input(|i| i.time);
        self.toasts.push(Toast { text: text.into(), error: false, born });
    }

    fn push_recent(&mut self, path: PathBuf) {
        let path = std::fs::canonicalize(&path).unwrap_or(path);
        self.recent.retain(|p| p != &path);
        self.recent.insert(0, path);
        self.recent.truncate(MAX_RECENT);
    }

    /// Advances the preview once per frame within the frame budget (or to convergence in
    /// [`Quality::Full`]); while work remains, asks for another frame.
    pub(crate) fn render_preview(&mut self) {
        let Some(gpu) = &mut self.gpu else { return };
        if gpu.last_frame == self.frames {
            return;
        }
        gpu.last_frame = self.frames;
        let budget = match self.view.quality {
            Quality::Balanced => Some(Duration::from_secs_f64(FRAME_BUDGET_MS * 1e-3)),
            Quality::Full => None,
        };
        // The base volume, loaded through the project like every other path.
        let project = self.session.project();
        let key = (project.base_volume.clone(), project.grid, self.session.path().map(Path::to_owned));
        if self.base_loaded.as_ref() != Some(&key) {
            let loaded = crate::export::load_base_layer(project, self.session.path());
            let failed = loaded.as_ref().err().map(|e| format!("The base volume is left out of the fog: {e}"));
            gpu.pipeline.set_base_layer(loaded.ok().flatten());
            gpu.converged = None;
            self.base_loaded = Some(key);
            if let Some(message) = failed {
                self.error(message);
            }
        }
        let Some(gpu) = &mut self.gpu else { return };
        let before = gpu.error.clone();
        gpu.render(&self.session, self.epoch, self.view.preview_size, budget);
        if gpu.refining() {
            self.ctx.request_repaint();
        }
        if gpu.error.is_some() && gpu.error != before {
            let message = gpu.error.clone().unwrap_or_default();
            self.error(format!("Preview failed: {message}"));
        }
    }

    fn replace_project(&mut self, project: Project, path: Option<PathBuf>, name: &str) {
        self.drop_recovery();
        self.session.replace(project, path, name);
        self.epoch += 1;
        self.view.gesture = None;
        self.view.modal = None;
        self.view.rename = None;
        self.view.slice = SliceCache::default();
    }

    fn spawn(&mut self, label: &str, job: impl FnOnce() -> JobResult + Send + 'static) {
        self.jobs.busy.push(label.to_owned());
        let tx = self.jobs.tx.clone();
        let ctx = self.ctx.clone();
        std::thread::spawn(move || {
            let _ = tx.send(job());
            ctx.request_repaint();
        });
    }

    pub(crate) fn request(&mut self, action: Action) {
        let discards = !matches!(action, Action::Quit) || !self.quit_confirmed;
        if self.session.is_dirty() && discards {
            self.confirm = Some(action);
        } else {
            self.perform(action);
        }
    }

    fn perform(&mut self, action: Action) {
        match action {
            Action::New => self.replace_project(Project::default(), None, "untitled.ron"),
            Action::OpenDialog => {
                let spec = DialogSpec {
                    title: "Open project",
                    filter: "Fogsmith project",
                    extension: "ron",
                    file_name: None,
                    directory: self.dialog_directory(),
                };
                self.choose_file(Pick::Open, spec);
            }
            Action::Open(path) => {
                let p = path.clone();
                self.spawn(&format!("Opening {}", path.display()), move || JobResult::Loaded {
                    result: load_project(&p).map(Box::new).map_err(|e| e.to_string()),
                    path: p,
                });
            }
            Action::Revert => match self.session.path().map(Path::to_owned) {
                Some(path) => self.perform(Action::Open(path)),
                None => self.info("Nothing to revert to: the project has never been saved"),
            },
            Action::Quit => {
                self.quit_confirmed = true;
                self.ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
        }
    }

    pub(crate) fn save(&mut self) {
        match self.session.path().map(Path::to_owned) {
            Some(path) => self.save_to(path),
            None => self.save_as_dialog(),
        }
    }

    fn save_as_dialog(&mut self) {
        let name = self.session.name().split(' ').next().unwrap_or("untitled.ron").to_owned();
        let spec = DialogSpec {
            title: "Save project as",
            filter: "Fogsmith project",
            extension: "ron",
            file_name: Some(name),
            directory: self.dialog_directory(),
        };
        self.choose_file(Pick::SaveAs, spec);
    }

    /// The project's folder, where dialogs start.
    fn dialog_directory(&self) -> Option<PathBuf> {
        self.session.path().and_then(Path::parent).filter(|d| !d.as_os_str().is_empty()).map(Path::to_owned)
    }

    /// Asks for a file with the system's dialog, or the built-in one where that cannot open.
    fn choose_file(&mut self, purpose: Pick, spec: DialogSpec) {
        if self.built_in_dialog.is_some() {
            self.info("A file dialog is already open");
            return;
        }
        match &self.file_dialogs {
            FileDialogs::System => {
                let label = if spec.is_save() { "Choosing where to save" } else { "Choosing a file" };
                self.spawn(label, move || {
                    let started = Instant::now();
                    let path = spec.run_system();
                    JobResult::Picked { purpose, path, seconds: started.elapsed().as_secs_f64(), spec: Box::new(spec) }
                });
            }
            FileDialogs::BuiltIn { reason } => {
                if !self.built_in_explained {
                    self.built_in_explained = true;
                    let text = format!("Using Fogsmith's file dialog: {reason}");
                    self.info(text);
                }
                self.open_built_in(purpose, &spec);
            }
        }
    }

    fn open_built_in(&mut self, purpose: Pick, spec: &DialogSpec) {
        self.built_in_dialog = Some((purpose, spec.built_in()));
    }

    /// Shows the built-in dialog and acts on its choice.
    fn built_in_dialog(&mut self, ctx: &Context) {
        let Some((purpose, dialog)) = &mut self.built_in_dialog else { return };
        let purpose = *purpose;
        dialog.update(ctx);
        let picked = dialog.take_picked();
        let open = matches!(dialog.state(), egui_file_dialog::DialogState::Open);
        if let Some(path) = picked {
            self.built_in_dialog = None;
            self.picked(purpose, path);
        } else if !open {
            self.built_in_dialog = None;
            self.after_save = None;
        }
    }

    /// File → Import VDB…: asks for the file (as Open does), then shows the grid picker.
    pub(crate) fn import_vdb_dialog(&mut self) {
        let spec = DialogSpec {
            title: "Import VDB",
            filter: "OpenVDB",
            extension: "vdb",
            file_name: None,
            directory: self.dialog_directory(),
        };
        self.choose_file(Pick::ImportVdb, spec);
    }

    /// Opens the import window on `path` directly (a dropped file, scripted use).
    pub(crate) fn import_vdb(&mut self, path: PathBuf) {
        self.picked(Pick::ImportVdb, path);
    }

    fn import_window(&mut self, ctx: &Context) {
        let Some(import) = &mut self.import else { return };
        match import.ui(ctx) {
            Some(true) => {
                let base = import.base_volume(self.session.path());
                self.import = None;
                let text = format!("Base volume: grid {:?} of {}, × {}", base.grid, base.path.display(), base.scale);
                self.session.edit(super::session::NEW_STEP).base_volume = Some(base);
                self.info(text);
            }
            Some(false) => self.import = None,
            None => {}
        }
    }

    fn picked(&mut self, purpose: Pick, path: PathBuf) {
        match purpose {
            Pick::Open => self.perform(Action::Open(path)),
            Pick::SaveAs => self.save_to(path),
            Pick::Export(kind) => self.export_to(kind, path),
            Pick::ImportVdb => match super::import::ImportVdb::open(path) {
                Ok(import) => self.import = Some(import),
                Err(e) => self.error(format!("Cannot import: {e}")),
            },
        }
    }

    pub(crate) fn save_to(&mut self, path: PathBuf) {
        let path = if path.extension().is_none() { path.with_extension("ron") } else { path };
        let project = self.session.project().clone();
        let generation = self.session.generation();
        let p = path.clone();
        self.spawn(&format!("Saving {}", path.display()), move || JobResult::Saved {
            result: save_project(&p, &project).map_err(|e| e.to_string()),
            path: p,
            generation,
        });
    }

    pub(crate) fn export_dialog(&mut self, kind: Export) {
        let (filter, ext) = match kind {
            Export::Vdb => ("OpenVDB", "vdb"),
            Export::ExrSlices => ("OpenEXR", "exr"),
        };
        let stem =
            Path::new(self.session.name()).file_stem().map(|s| s.to_string_lossy().into_owned()).unwrap_or_default();
        let name = format!("{}.{ext}", stem.split(' ').next().unwrap_or("fog"));
        let spec = DialogSpec {
            title: "Export",
            filter,
            extension: ext,
            file_name: Some(name),
            directory: self.dialog_directory(),
        };
        self.choose_file(Pick::Export(kind), spec);
    }

    /// Reads the baked volumes back (brief) and writes them in a background thread.
    pub(crate) fn export_to(&mut self, kind: Export, path: PathBuf) {
        let Some(gpu) = &self.gpu else {
            self.error("Nothing to export: the pipeline is not running");
            return;
        };
        if gpu.refining() {
            // The volumes are still being baked: export once they are complete.
            if self.jobs.pending_export.is_none() {
                self.info(format!("Exporting {} once the bake completes…", path.display()));
            }
            self.jobs.pending_export = Some((kind, path));
            self.ctx.request_repaint();
            return;
        }
        let project = self.session.project();
        let volumes = gpu.pipeline.read_ev().and_then(|ev| {
            let opvs = (0..project.lights.len()).map(|i| gpu.pipeline.read_opv(i)).collect::<Result<Vec<_>, _>>()?;
            Ok((ev, opvs))
        });
        let (ev, opvs) = match volumes {
            Ok(v) => v,
            Err(e) => {
                self.error(format!("Export failed: {e}"));
                return;
            }
        };
        let infos = crate::export::light_infos(project);
        let p = path.clone();
        let job = ExportJob {
            path: path.clone(),
            fraction: Arc::new(AtomicU32::new(0)),
            cancel: Arc::new(AtomicBool::new(false)),
        };
        let (fraction, cancel) = (job.fraction.clone(), job.cancel.clone());
        self.jobs.export_job = Some(job);
        self.spawn(&format!("Exporting {}", path.display()), move || {
            // Written beside the target and moved onto it only if not cancelled meanwhile.
            let mut staged = crate::export::Staged::default();
            let set = |f: f32| fraction.store(f.to_bits(), Ordering::Relaxed);
            let result = match kind {
                Export::Vdb => {
                    use crate::export::vdb::{grids_from_volumes, write_vdb_with_progress, GridSelection, VdbOptions};
                    let lights: Vec<_> = opvs.iter().zip(&infos).map(|(v, l)| (v, *l)).collect();
                    let grids = grids_from_volumes(&ev, &lights, GridSelection::default());
                    staged
                        .write(&p, |temp| {
                            write_vdb_with_progress(temp, &grids, &VdbOptions::default(), &mut |f| set(f))
                        })
                        .map(|stats| format!("{} grids, {} bytes", stats.grids.len(), stats.bytes))
                }
                Export::ExrSlices => {
                    let names: Vec<String> = (0..opvs.len()).map(|i| format!("optical_depth_{i}")).collect();
                    let mut channels: Vec<(&str, &crate::scene::Volume)> = vec![("density", &ev)];
                    channels.extend(names.iter().map(String::as_str).zip(opvs.iter()));
                    staged
                        .write(&p, |temp| crate::export::exr::write_slices_exr(temp, &channels))
                        .map(|_| format!("{} volumes", channels.len()))
                }
            };
            let result = match result {
                Ok(_) if cancel.load(Ordering::Relaxed) => Err(EXPORT_CANCELLED.to_string()),
                Ok(summary) => staged.commit().map(|_| summary).map_err(|e| e.to_string()),
                Err(e) => Err(e),
            };
            set(1.0);
            JobResult::Exported { path: p, result }
        });
    }

    fn finish_job(&mut self, result: JobResult) {
        self.jobs.busy.pop();
        match result {
            JobResult::Picked { purpose, spec, path: None, seconds } if seconds < super::files::NO_DIALOG_SECONDS => {
                let reason = "the system file dialog did not open (no desktop portal or zenity answered)".to_string();
                self.info(format!("{}; using Fogsmith's file dialog", capitalized(&reason)));
                self.file_dialogs = FileDialogs::BuiltIn { reason };
                self.built_in_explained = true;
                self.open_built_in(purpose, &spec);
            }
            JobResult::Picked { path: None, .. } => self.after_save = None,
            JobResult::Picked { purpose, path: Some(path), .. } => self.picked(purpose, path),
            JobResult::Exported { path, result } if self.jobs.export_job.as_ref().is_some_and(|j| j.path == path) => {
                self.jobs.export_job = None;
                match result {
                    Ok(summary) => self.info(format!("Exported {}: {summary}", path.display())),
                    Err(e) if e == EXPORT_CANCELLED => {
                        self.info(format!("Export cancelled; {} is unchanged", path.display()))
                    }
                    Err(e) => self.error(format!("Export to {} failed: {e}", path.display())),
                }
            }
            JobResult::Exported { path, result: Ok(summary) } => {
                self.info(format!("Exported {}: {summary}", path.display()))
            }
            JobResult::Exported { path, result: Err(e) } => {
                self.error(format!("Export to {} failed: {e}", path.display()))
            }
            JobResult::Loaded { path, result: Ok(project) } => {
                self.replace_project(*project, Some(path.clone()), "");
                self.info(format!("Opened {}", path.display()));
                self.push_recent(path);
            }
            JobResult::Loaded { path, result: Err(e) } => {
                self.recent.retain(|p| p != &path);
                self.error(format!("Could not open the project: {e}"));
            }
            JobResult::Saved { path, generation, result: Ok(()) } => {
                self.drop_recovery();
                self.session.mark_saved(path.clone(), generation);
                self.info(format!("Saved {}", path.display()));
                self.push_recent(path);
                if let Some(action) = self.after_save.take() {
                    self.perform(action);
                }
            }
            JobResult::Saved { result: Err(e), .. } => {
                self.after_save = None;
                self.error(format!("Could not save: {e}"));
            }
            JobResult::Exact { key, result } => {
                if self.view.slice.exact_pending == Some(key) {
                    self.view.slice.exact_pending = None;
                }
                self.view.slice.exact = Some((key, result));
                self.view.slice.key = None;
            }
        }
    }

    /// Starts computing the exact optical depth on a slice's cells, unless it is under way.
    pub(crate) fn request_exact(&mut self, key: ExactKey, cells: Vec<[u32; 3]>) {
        if self.view.slice.exact_pending == Some(key) {
            return;
        }
        self.view.slice.exact_pending = Some(key);
        let project = self.session.project().clone();
        let path = self.session.path().map(Path::to_owned);
        self.spawn("Computing the exact optical depth", move || JobResult::Exact {
            key,
            result: crate::export::load_base_layer(&project, path.as_deref())
                .map_err(|e| format!("The base volume cannot be loaded for the exact reference: {e}"))
                .and_then(|layer| super::slices::exact_optical_depth(&project, layer.as_ref(), key.light, &cells)),
        });
    }

    /// Removes this session's recovery file: its work was saved or deliberately dropped.
    fn drop_recovery(&mut self) {
        if let (Some(dir), Some(_)) = (&self.recovery.dir, self.recovery.written.take()) {
            let path = crate::scene::recovery::recovery_path(dir, self.session.path());
            if let Err(e) = crate::scene::recovery::remove_recovery(&path) {
                self.error(e.to_string());
            }
        }
    }

    /// Every few seconds while there are unsaved changes, writes a recovery file in the
    /// background.
    fn write_recovery(&mut self, now: f64) {
        let Some(dir) = self.recovery.dir.clone() else { return };
        if !self.session.is_dirty() {
            return;
        }
        let key = (self.epoch, self.session.content_generation());
        if let Some((epoch, generation, at)) = self.recovery.written {
            if (epoch, generation) == key || now - at < recovery_interval_s() {
                return;
            }
        }
        self.recovery.written = Some((key.0, key.1, now));
        let project = self.session.project().clone();
        let original = self.session.path().map(Path::to_owned);
        let tx = self.jobs.tx.clone();
        std::thread::spawn(move || {
            if let Err(e) = crate::scene::recovery::write_recovery(&dir, original.as_deref(), &project) {
                let _ = tx.send(JobResult::Exported {
                    path: dir,
                    result: Err(format!("could not write the recovery file: {e}")),
                });
            }
        });
    }

    fn recovery_dialog(&mut self, ctx: &Context) {
        if self.recovery.found.is_empty() {
            return;
        }
        let mut action = None;
        egui::Window::new("Recover unsaved work").collapsible(false).resizable(false).show(ctx, |ui| {
            ui.label("Fogsmith did not exit cleanly last time. This work was not saved:");
            for (i, (_, rec)) in self.recovery.found.iter().enumerate() {
                ui.horizontal(|ui| {
                    let name =
                        rec.original.as_ref().map_or("untitled project".to_string(), |p| p.display().to_string());
                    ui.label(format!(
                        "{name} ({} particles, {} lights)",
                        rec.project.particles.len(),
                        rec.project.lights.len()
                    ));
                    if ui
                        .button("Restore")
                        .on_hover_text("Open this work (unsaved) in place of the current project")
                        .clicked()
                    {
                        action = Some((i, true));
                    }
                    if ui.button("Discard").on_hover_text("Delete the recovery file").clicked() {
                        action = Some((i, false));
                    }
                });
            }
        });
        if let Some((i, restore)) = action {
            let (file, rec) = self.recovery.found.remove(i);
            if restore {
                self.replace_project(rec.project, rec.original, "recovered.ron");
                self.session.mark_unsaved();
            }
            if let Err(e) = crate::scene::recovery::remove_recovery(&file) {
                self.error(e.to_string());
            }
        }
    }

    fn begin_frame(&mut self, ctx: &Context) {
        self.view.clock.tick();
        self.frames += 1;
        while let Ok(result) = self.jobs.rx.try_recv() {
            self.finish_job(result);
        }
        let dropped: Vec<PathBuf> = ctx.input(|i| {
            i.raw.dropped_files.iter().map(|f| f.path().to_path_buf()).filter(|p| !p.as_os_str().is_empty()).collect()
        });
        if let Some(path) = dropped.into_iter().next() {
            let ext = path.extension().and_then(|e| e.to_str()).unwrap_or("").to_ascii_lowercase();
            if ext == "ron" {
                self.request(Action::Open(path));
            } else if ext == "vdb" {
                self.import_vdb(path);
            } else {
                self.error(format!("{}: not a Fogsmith project or VDB; drop a .ron or .vdb file", path.display()));
            }
        }
        if ctx.input(|i| i.viewport().close_requested()) && self.session.is_dirty() && !self.quit_confirmed {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.confirm = Some(Action::Quit);
        }
        self.shortcuts(ctx);
    }

    fn end_frame(&mut self, ctx: &Context) {
        // After every panel has seen the release, so a gesture's last step joins its undo step.
        if ctx.input(|i| i.pointer.any_released()) {
            self.session.end_edit();
            ctx.request_repaint();
        }
        self.write_recovery(ctx.input(|i| i.time));
        self.recovery_dialog(ctx);
        self.confirm_dialog(ctx);
        self.built_in_dialog(ctx);
        self.import_window(ctx);
        self.shortcuts_window(ctx);
        self.show_toasts(ctx);
        let title = format!("{}{} — Fogsmith", self.session.name(), if self.session.is_dirty() { " ●" } else { "" });
        if title != self.title {
            ctx.send_viewport_cmd(egui::ViewportCommand::Title(title.clone()));
            self.title = title;
        }
        if self.view.continuous || !self.jobs.busy.is_empty() {
            ctx.request_repaint();
        }
        // After every panel has applied this frame's input, so the preview shows it in the
        // frame being painted.
        self.render_preview();
        if self.gpu.as_ref().is_some_and(|g| !g.refining()) {
            if let Some((kind, path)) = self.jobs.pending_export.take() {
                self.export_to(kind, path);
            }
        }
        self.scripted(ctx);
    }

    /// `--screenshot` and `--measure-fps` runs.
    fn scripted(&mut self, ctx: &Context) {
        if let Some(path) = self.options.screenshot.clone() {
            let ready = self.gpu.as_ref().is_none_or(|g| g.renders > 0 || g.error.is_some());
            if ready && self.frames > 5 && !self.screenshot_requested {
                self.screenshot_requested = true;
                ctx.send_viewport_cmd(egui::ViewportCommand::Screenshot(egui::UserData::default()));
            }
            let shot = ctx.input(|i| {
                i.raw.events.iter().find_map(|e| match e {
                    egui::Event::Screenshot { image, .. } => Some(image.clone()),
                    _ => None,
                })
            });
            if let Some(image) = shot {
                let bytes: Vec<u8> = image.pixels.iter().flat_map(|c| c.to_array()).collect();
                let [w, h] = image.size;
                let result = image::RgbaImage::from_raw(w as u32, h as u32, bytes)
                    .ok_or_else(|| "screenshot has the wrong size".to_string())
                    .and_then(|img| img.save(&path).map_err(|e| e.to_string()));
                match result {
                    Ok(()) => eprintln!("fogsmith: screenshot saved to {}", path.display()),
                    Err(e) => eprintln!("fogsmith: could not save the screenshot {}: {e}", path.display()),
                }
                self.quit_confirmed = true;
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            ctx.request_repaint();
        }
        if let Some(seconds) = self.options.measure_fps {
            let ready = self.gpu.as_ref().is_none_or(|g| g.renders > 0);
            if !ready || self.frames < 10 {
                return;
            }
            let start = *self.measure_start.get_or_insert_with(Instant::now);
            let t = start.elapsed().as_secs_f32();
            if t < seconds * 0.5 {
                self.measure_frames[0] += 1;
            } else if t < seconds {
                self.measure_frames[1] += 1;
                let camera = super::view::orbit(&self.session.project().camera, 0.02, 0.0);
                self.session.set_camera(camera);
                self.view.force_interacting = true;
                self.view.interacting = true;
            } else {
                self.view.force_interacting = false;
                self.view.interacting = false;
                let half = seconds * 0.5;
                let p = self.session.project();
                println!(
                    "fps: still {:.1}, orbiting {:.1} ({} particles, {} lights, grid {:?}, preview {}x{})",
                    self.measure_frames[0] as f32 / half,
                    self.measure_frames[1] as f32 / half,
                    p.particles.len(),
                    p.lights.len(),
                    p.grid.resolution.to_array(),
                    self.view.preview_size[0],
                    self.view.preview_size[1]
                );
                if let Some(g) = &self.gpu {
                    let t = g.report.timings_ms;
                    println!(
                        "last update: {:.1} ms wall; inject {:.1} ms, propagate {:.1} ms, march {:.1} ms at {:?}; {}",
                        g.update_ms,
                        t.inject,
                        t.propagate,
                        t.march,
                        g.texture.map(|t| t.1),
                        g.pipeline.context().adapter_summary()
                    );
                }
                self.options.measure_fps = None;
                self.quit_confirmed = true;
                ctx.send_viewport_cmd(egui::ViewportCommand::Close);
            }
            ctx.request_repaint();
        }
    }

    fn shortcuts(&mut self, ctx: &Context) {
        let typing = ctx.egui_wants_keyboard_input();
        let pointer = ctx.input(|i| i.pointer.hover_pos());
        let in_viewport = pointer.zip(self.view.viewport_rect).is_some_and(|(p, r)| r.contains(p));
        for command in Command::pressed(ctx, typing, in_viewport) {
            self.run(command);
        }
        if typing || ctx.input(|i| i.modifiers.command) {
            return;
        }
        let step = 0.08;
        let orbit = ctx.input(|i| {
            let mut d = glam::Vec2::ZERO;
            if i.key_down(Key::ArrowLeft) {
                d.x -= step;
            }
            if i.key_down(Key::ArrowRight) {
                d.x += step;
            }
            if i.key_down(Key::ArrowUp) {
                d.y += step;
            }
            if i.key_down(Key::ArrowDown) {
                d.y -= step;
            }
            d
        });
        if orbit != glam::Vec2::ZERO {
            let c = super::view::orbit(&self.session.project().camera, orbit.x, orbit.y);
            self.session.set_camera(c);
        }
    }

    /// The pipeline's extinction volume, read back once per content change (for painting at
    /// the fog's depth); None without a pipeline or when the read fails.
    pub(crate) fn fog_ev(&mut self) -> Option<&crate::scene::Volume> {
        let key = (self.epoch, self.session.content_generation());
        let fresh = self.view.fog_ev.as_ref().is_some_and(|(e, g, _)| (*e, *g) == key);
        if !fresh {
            let gpu = self.gpu.as_ref()?;
            let grid = self.session.project().grid;
            let stale_usable = self.view.fog_ev.as_ref().is_some_and(|(e, _, ev)| *e == key.0 && ev.grid == grid);
            // While the bake catches up with an edit, the last complete read is close enough.
            if !(gpu.refining() && stale_usable) {
                let ev = gpu.pipeline.read_ev().ok()?;
                if ev.grid != grid {
                    return None;
                }
                let generation = if gpu.refining() { 0 } else { key.1 };
                self.view.fog_ev = Some((key.0, generation, ev));
            }
        }
        self.view.fog_ev.as_ref().map(|(_, _, ev)| ev)
    }

    /// Runs `command`, from a menu or a shortcut.
    pub(crate) fn run(&mut self, command: Command) {
        use super::view::AxisView;
        self.last_command = Some(command);
        let zoom = |s: &mut Self, f: f32| {
            let c = super::view::zoom(&s.session.project().camera, f);
            s.session.set_camera(c);
        };
        match command {
            Command::New => self.request(Action::New),
            Command::Open => self.request(Action::OpenDialog),
            Command::Save => self.save(),
            Command::SaveAs => self.save_as_dialog(),
            Command::ImportVdb => self.import_vdb_dialog(),
            Command::ExportVdb => self.export_dialog(Export::Vdb),
            Command::ExportExr => self.export_dialog(Export::ExrSlices),
            Command::Revert => self.request(Action::Revert),
            Command::Quit => self.request(Action::Quit),
            Command::Undo => self.undo(),
            Command::Redo => self.redo(),
            Command::SelectAll => self.session.select_all(),
            Command::Duplicate => self.duplicate(),
            Command::Delete => self.delete(),
            Command::Escape => {
                if self.view.modal.is_some() {
                    self.cancel_modal();
                } else if matches!(self.view.gesture, Some(Gesture::Gizmo { .. })) {
                    self.cancel_gizmo();
                } else {
                    self.session.selection.clear();
                }
            }
            Command::Grab | Command::ScaleSelection => {
                let scale = command == Command::ScaleSelection;
                let start = self.ctx.input(|i| i.pointer.hover_pos());
                let applicable = if scale {
                    !self.session.selection.particles.is_empty()
                } else {
                    !self.session.selection.is_empty()
                };
                if let (Some(start), true, true) = (start, applicable, self.view.modal.is_none()) {
                    self.start_modal(scale, start);
                }
            }
            Command::FitGrid => super::viewport::fit_grid(self),
            Command::ToolSelect => self.view.tool = Tool::Select,
            Command::ToolPaint => self.view.tool = Tool::Paint,
            Command::ToolScale => self.view.tool = Tool::Scale,
            Command::ToolErase => self.view.tool = Tool::Erase,
            Command::ToolLight => self.view.tool = Tool::Light,
            Command::FrameSelection => self.frame_selection(),
            Command::ViewFront => self.axis_view(AxisView::Front),
            Command::ViewRight => self.axis_view(AxisView::Right),
            Command::ViewTop => self.axis_view(AxisView::Top),
            Command::ZoomIn => zoom(self, 0.85),
            Command::ZoomOut => zoom(self, 1.0 / 0.85),
            Command::SliceNext | Command::SlicePrevious => {
                let max =
                    self.session.project().grid.resolution.to_array()[self.view.slices.axis.index()].saturating_sub(1);
                let i = self.view.slices.index.min(max);
                self.view.slices.index =
                    if command == Command::SliceNext { (i + 1).min(max) } else { i.saturating_sub(1) };
            }
            Command::Shortcuts => self.view.show_shortcuts = !self.view.show_shortcuts,
        }
    }

    fn start_modal(&mut self, scale: bool, start: egui::Pos2) {
        let tag = self.session.new_tag();
        self.view.modal = Some(Modal { scale, tag, start, applied: glam::Vec3::ZERO, applied_factor: 1.0 });
    }

    pub(crate) fn cancel_modal(&mut self) {
        if let Some(m) = self.view.modal.take() {
            if m.applied != glam::Vec3::ZERO || m.applied_factor != 1.0 {
                self.session.undo();
            }
        }
    }

    /// Ends a move-gizmo drag, putting the selection back where the drag began.
    pub(crate) fn cancel_gizmo(&mut self) {
        if let Some(Gesture::Gizmo { tag, .. }) = self.view.gesture {
            self.session.cancel_edit(tag);
            self.view.gesture = Some(Gesture::Cancelled);
        }
    }

    pub(crate) fn undo(&mut self) {
        self.view.modal = None;
        if !self.session.undo() {
            self.info("Nothing to undo");
        }
    }

    pub(crate) fn redo(&mut self) {
        self.view.modal = None;
        if !self.session.redo() {
            self.info("Nothing to redo");
        }
    }

    pub(crate) fn delete(&mut self) {
        self.session.delete_selection();
    }

    pub(crate) fn duplicate(&mut self) {
        let offset = self.session.project().grid.cell_size().max_element() * 2.0;
        self.session.duplicate_selection(glam::Vec3::new(offset, 0.0, offset));
    }

    pub(crate) fn frame_selection(&mut self) {
        let p = self.session.project();
        let (center, radius) = match self.session.selection_center() {
            Some(c) => {
                let r = self
                    .session
                    .selection
                    .particles
                    .iter()
                    .filter_map(|&i| p.particles.get(i))
                    .map(|q| (q.center - c).length() + q.radius * 2.0)
                    .chain(
                        self.session
                            .selection
                            .lights
                            .iter()
                            .filter_map(|&i| p.lights.get(i))
                            .map(|l| (l.position - c).length() + 0.1),
                    )
                    .fold(0.1f32, f32::max);
                (c, r)
            }
            None => ((p.grid.min + p.grid.max) * 0.5, p.grid.size().length() * 0.5),
        };
        let c = super::view::frame(&p.camera, center, radius);
        self.session.set_camera(c);
    }

    pub(crate) fn axis_view(&mut self, v: super::view::AxisView) {
        let p = self.session.project();
        let c = super::view::axis_view(&p.camera, &p.grid, v);
        self.session.set_camera(c);
    }

    fn camera_menu(&mut self, ui: &mut egui::Ui) {
        use super::view::AxisView;
        let views = [
            (Some(Command::ViewFront), "Front", AxisView::Front),
            (None, "Back", AxisView::Back),
            (Some(Command::ViewRight), "Right", AxisView::Right),
            (None, "Left", AxisView::Left),
            (Some(Command::ViewTop), "Top", AxisView::Top),
        ];
        for (command, label, v) in views {
            match command {
                Some(c) => {
                    if c.menu_button(ui, true) {
                        self.run(c);
                    }
                }
                None => {
                    if ui.button(label).clicked() {
                        self.axis_view(v);
                    }
                }
            }
        }
        for c in [Command::FrameSelection, Command::ZoomIn, Command::ZoomOut] {
            if c.menu_button(ui, true) {
                self.run(c);
            }
        }
    }

    fn file_menu(&mut self, ui: &mut egui::Ui) {
        for c in [Command::New, Command::Open] {
            if c.menu_button(ui, true) {
                self.run(c);
            }
        }
        ui.menu_button("Open Recent", |ui| {
            if self.recent.is_empty() {
                ui.label("No recent projects");
            }
            for path in self.recent.clone() {
                if ui.button(path.display().to_string()).clicked() {
                    self.request(Action::Open(path));
                }
            }
        });
        ui.separator();
        for c in [Command::Save, Command::SaveAs] {
            if c.menu_button(ui, true) {
                self.run(c);
            }
        }
        ui.menu_button("Export", |ui| {
            for c in [Command::ExportVdb, Command::ExportExr] {
                if c.menu_button(ui, true) {
                    self.run(c);
                }
            }
        });
        ui.separator();
        if Command::ImportVdb.menu_button(ui, true) {
            self.run(Command::ImportVdb);
        }
        if self.session.project().base_volume.is_some()
            && ui.button("Remove base volume").on_hover_text("Drop the imported VDB grid from the fog").clicked()
        {
            self.session.edit(super::session::NEW_STEP).base_volume = None;
        }
        let can_revert = self.session.path().is_some();
        if Command::Revert.menu_button(ui, can_revert) {
            self.run(Command::Revert);
        }
        ui.separator();
        if Command::Quit.menu_button(ui, true) {
            self.run(Command::Quit);
        }
    }

    fn edit_menu(&mut self, ui: &mut egui::Ui) {
        let undo = self.session.undo_label().map_or("Undo".to_string(), |l| format!("Undo {l}"));
        if Command::Undo.menu_button_text(ui, self.session.can_undo(), &undo) {
            self.run(Command::Undo);
        }
        let redo = self.session.redo_label().map_or("Redo".to_string(), |l| format!("Redo {l}"));
        if Command::Redo.menu_button_text(ui, self.session.can_redo(), &redo) {
            self.run(Command::Redo);
        }
        ui.separator();
        let has_selection = !self.session.selection.is_empty();
        for (c, enabled) in
            [(Command::SelectAll, true), (Command::Duplicate, has_selection), (Command::Delete, has_selection)]
        {
            if c.menu_button(ui, enabled) {
                self.run(c);
            }
        }
        ui.separator();
        let has_particles = !self.session.project().particles.is_empty();
        if Command::FitGrid.menu_button(ui, has_particles) {
            self.run(Command::FitGrid);
        }
    }

    fn status_bar(&mut self, ui: &mut egui::Ui) {
        ui.horizontal(|ui| {
            if let Some(job) = self.jobs.busy.last() {
                ui.spinner();
                ui.label(job.as_str());
                ui.separator();
            }
            if let Some(job) = &self.jobs.export_job {
                let f = f32::from_bits(job.fraction.load(Ordering::Relaxed));
                let name = job.path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
                ui.add(
                    egui::ProgressBar::new(f).desired_width(160.0).show_percentage().text(format!("exporting {name}")),
                );
                if job.cancel.load(Ordering::Relaxed) {
                    ui.label("cancelling…");
                } else if ui
                    .button("Cancel")
                    .on_hover_text(format!("Stop the export; {} stays as it was", job.path.display()))
                    .clicked()
                {
                    job.cancel.store(true, Ordering::Relaxed);
                }
                ui.separator();
                ui.ctx().request_repaint_after(std::time::Duration::from_millis(100));
            }
            if let Some((_, path)) = &self.jobs.pending_export {
                let path = path.clone();
                ui.label(format!(
                    "{} waits for the bake",
                    path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
                ));
                if ui.button("Cancel").on_hover_text("Do not export").clicked() {
                    self.jobs.pending_export = None;
                    self.info(format!("Export cancelled; {} is unchanged", path.display()));
                }
                ui.separator();
            }
            if let Some(gpu) = self.gpu.as_ref().filter(|g| g.refining()) {
                let p = gpu.progress;
                let stage = p.stage.name();
                ui.add(
                    egui::ProgressBar::new(p.stage_fraction as f32)
                        .desired_width(120.0)
                        .text(format!("preview: {stage}")),
                )
                .on_hover_text("The preview refines over the next frames: optical depths, then full resolution");
                ui.separator();
            }
            let p = self.session.project();
            ui.label(format!(
                "{} particles · {} lights · {} selected · tool: {}",
                p.particles.len(),
                p.lights.len(),
                self.session.selection.len(),
                self.view.tool.label()
            ));
            if self.view.modal.is_some() {
                ui.separator();
                ui.label("Move the mouse; click or Enter to confirm, Esc or right-click to cancel");
            }
        });
    }

    fn confirm_dialog(&mut self, ctx: &Context) {
        let Some(action) = self.confirm.clone() else { return };
        let what = match &action {
            Action::New => "starting a new project",
            Action::OpenDialog | Action::Open(_) => "opening another project",
            Action::Revert => "reverting",
            Action::Quit => "quitting",
        };
        let mut choice = None;
        egui::Modal::new(Id::new("confirm-discard")).show(ctx, |ui| {
            ui.heading("Unsaved changes");
            ui.label(format!("{} has unsaved changes. Save them before {what}?", self.session.name()));
            ui.horizontal(|ui| {
                if ui.button("Save").clicked() {
                    choice = Some(0);
                }
                if ui.button("Discard").clicked() {
                    choice = Some(1);
                }
                if ui.button("Cancel").clicked() {
                    choice = Some(2);
                }
            });
        });
        match choice {
            Some(0) => {
                self.confirm = None;
                self.after_save = Some(action);
                self.save();
            }
            Some(1) => {
                self.confirm = None;
                if action == Action::Quit {
                    self.quit_confirmed = true;
                }
                self.perform(action);
            }
            Some(_) => self.confirm = None,
            None => {}
        }
    }

    fn shortcuts_window(&mut self, ctx: &Context) {
        let mut open = self.view.show_shortcuts;
        egui::Window::new("Shortcuts").open(&mut open).resizable(false).show(ctx, |ui| {
            egui::Grid::new("shortcuts").striped(true).show(ui, |ui| {
                for (k, v) in super::commands::help_sheet() {
                    ui.label(k);
                    ui.label(v);
                    ui.end_row();
                }
            });
        });
        self.view.show_shortcuts = open;
    }

    fn show_toasts(&mut self, ctx: &Context) {
        let now = ctx.input(|i| i.time);
        self.toasts.retain(|t| t.error || now - t.born < 4.0);
        if self.toasts.iter().any(|t| !t.error) {
            ctx.request_repaint_after(std::time::Duration::from_millis(250));
        }
        let mut dismiss = None;
        egui::Area::new(Id::new("toasts"))
            .order(egui::Order::Foreground)
            .anchor(egui::Align2::RIGHT_BOTTOM, [-12.0, -36.0])
            .show(ctx, |ui| {
                for (i, t) in self.toasts.iter().enumerate() {
                    egui::Frame::popup(ui.style()).show(ui, |ui| {
                        ui.set_max_width(420.0);
                        ui.horizontal(|ui| {
                            let text = egui::RichText::new(&t.text);
                            ui.label(if t.error { text.color(ui.visuals().error_fg_color) } else { text });
                            if ui.small_button("✕").on_hover_text("Dismiss").clicked() {
                                dismiss = Some(i);
                            }
                        });
                    });
                }
            });
        if let Some(i) = dismiss {
            self.toasts.remove(i);
        }
    }
}

fn capitalized(s: &str) -> String {
    let mut c = s.chars();
    c.next().map(|f| f.to_uppercase().chain(c).collect()).unwrap_or_default()
}

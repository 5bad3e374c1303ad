//! The editor's state, apart from the dock layout: the document (the session with its undo
//! history), the view, the background jobs, crash recovery, the preview on the GPU and the
//! shell around them. The data lives here; what acts on it lives in the sibling modules
//! (`preview`, `jobs`, `file_actions`, `recovery`, `dispatch`, `menus`, `shell`, `scripted`),
//! each an `impl EditorState` that imports this module and not the app.

use super::commands::Command;
use super::export_choices::ExportChoices;
use super::export_memory::ExportUi;
use super::files::{DialogSpec, FileDialogs};
use super::session::{Session, Version};
use super::slices::{Slice, SliceSettings};
use super::tools::{Brush, Stroke, Tool};
use super::EditorOptions;
use crate::gpu::{FogPipeline, FrameReport, Progress};
use crate::scene::Project;
use eframe::egui_wgpu;
use egui::Context;
use serde::{Deserialize, Serialize};
use std::collections::VecDeque;
use std::path::PathBuf;
use std::sync::atomic::{AtomicBool, AtomicU32};
use std::sync::{mpsc, Arc};
use std::time::Instant;

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
    /// What an engine shows of the light bake with this phase mode: the emission–absorption
    /// render of the baked density and emission, with no lights (waits like `Full`).
    AsBaked(crate::gpu::BakePhase),
}

impl Quality {
    /// The bake's phase mode in the "as baked" preview; None for the lit preview.
    pub fn as_baked(self) -> Option<crate::gpu::BakePhase> {
        match self {
            Quality::AsBaked(phase) => Some(phase),
            Quality::Balanced | Quality::Full => None,
        }
    }
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

/// An action that would discard unsaved changes.
#[derive(Clone, Debug, PartialEq)]
pub enum Action {
    New,
    OpenDialog,
    Open(PathBuf),
    Revert,
    Quit,
}

/// What a background job hands back to the frame loop.
pub(super) enum JobResult {
    Picked {
        purpose: Pick,
        spec: Box<DialogSpec>,
        path: Option<PathBuf>,
        seconds: f64,
    },
    Exported {
        path: PathBuf,
        result: Result<String, String>,
    },
    Loaded {
        path: PathBuf,
        result: Result<Box<Project>, String>,
    },
    /// A recovery file's work, restored: `file` is the recovery file, `original` the project
    /// file the work belongs to.
    Restored {
        file: PathBuf,
        original: Option<PathBuf>,
        result: Result<Box<Project>, String>,
    },
    Saved {
        path: PathBuf,
        generation: u64,
        result: Result<(), String>,
    },
    Exact {
        key: ExactKey,
        result: Result<Vec<f64>, String>,
    },
}

/// What a file dialog was opened for.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Pick {
    Open,
    SaveAs,
    Export(ExportChoices),
    ImportVdb,
}

/// Identifies the exact optical depths computed for one slice of one project state.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct ExactKey {
    /// The project's content at the time.
    pub version: Version,
    pub light: usize,
    pub axis: super::slices::Axis,
    pub index: u32,
}

/// A dismissable message.
pub(crate) struct Toast {
    pub text: String,
    pub error: bool,
    pub born: f64,
    /// How many times the same message came (shown as "×N" instead of a pile of copies).
    pub count: u32,
}

/// Toasts on screen at once: the newest; the rest fold into one line with "Dismiss all".
pub(crate) const TOASTS_SHOWN: usize = 3;

/// The pipeline on egui-wgpu's device and the texture its frames are shown through.
pub(crate) struct GpuView {
    pub(super) render_state: egui_wgpu::RenderState,
    pub pipeline: FogPipeline,
    pub texture: Option<(egui::TextureId, [u32; 2])>,
    /// Inputs of the last converged preview: nothing to do until they change.
    pub(super) converged: Option<PreviewKey>,
    /// The last progress in which a stage ran.
    pub report: FrameReport,
    pub progress: Progress,
    pub error: Option<String>,
    /// Images shown so far.
    pub renders: u64,
    /// Calls into the pipeline so far.
    pub calls: u64,
    /// Wall time of the last pipeline call, all items and waits included.
    pub update_ms: f64,
    /// Wall time of this frame's pipeline call, ms: 0 when the frame made none (converged).
    pub frame_update_ms: f64,
    /// The last frame's budget for the pipeline, ms (None: to convergence), and whether it
    /// was an idle frame's larger one.
    pub budget_ms: Option<(f64, bool)>,
    /// Wall time of the last whole frame and the part of it not spent in the pipeline, ms.
    pub frame_ms: Option<(f64, f64)>,
    /// Frame at which the pipeline last ran, so that it runs once per frame.
    pub(super) last_frame: u64,
    /// The project state the image on show was rendered from.
    pub(super) shown: Option<Version>,
    /// The phase mode of the "as baked" image on show; None while the lit preview shows.
    pub(super) as_baked: Option<crate::gpu::BakePhase>,
    /// Animation: the frame the baked optical depths belong to, and the frames of the image
    /// on show (its fog's, its shadows').
    pub(super) frames: ShownFrames,
}

/// Which animation frames the preview's image and optical depths come from: while playback
/// outruns propagation, an image shows one frame's fog with an earlier frame's shadows.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct ShownFrames {
    /// The frame whose optical depths the pipeline holds (propagation finished for it).
    pub baked_shadows: Option<i32>,
    /// The frame of the fog on show.
    pub fog: Option<i32>,
    /// The frame of the shadows on show.
    pub shadows: Option<i32>,
}

/// What a converged preview was rendered from: nothing to do until it changes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct PreviewKey {
    pub version: Version,
    pub size: [u32; 2],
}

/// An export written in a background thread: its progress and a request to stop it.
pub(crate) struct ExportJob {
    pub(super) path: PathBuf,
    /// Fraction written, as f32 bits.
    pub(super) fraction: Arc<AtomicU32>,
    pub(super) cancel: Arc<AtomicBool>,
    /// Which frame of a sequence is being written ("frame 12, 3 of 10"); empty otherwise.
    pub(super) frame: Arc<std::sync::Mutex<String>>,
}

/// Frame times of the last couple of seconds.
#[derive(Default)]
pub(crate) struct FrameClock {
    pub(super) times: VecDeque<Instant>,
}

impl FrameClock {
    fn tick(&mut self) {
        let now = Instant::now();
        self.times.push_back(now);
        while self.times.len() > 2 && now.duration_since(self.times[0]).as_secs_f32() > 2.0 {
            self.times.pop_front();
        }
    }
    /// Wall time between the last two frames' starts, ms.
    pub fn last_frame_ms(&self) -> Option<f64> {
        let n = self.times.len();
        (n >= 2).then(|| self.times[n - 1].duration_since(self.times[n - 2]).as_secs_f64() * 1e3)
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
    /// A drag on a selected spot's aim handle: the tip of its axis, `tip` when the drag
    /// began, follows the pointer at the tip's `depth`, and the axis points at it.
    AimSpot {
        tag: u64,
        light: usize,
        depth: f32,
        start: egui::Pos2,
        tip: glam::Vec3,
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
    pub(super) recovery: RecoveryState,
    pub(crate) gpu: Option<GpuView>,
    pub(crate) gpu_missing: Option<String>,
    pub(crate) toasts: Vec<Toast>,
    pub(crate) recent: Vec<PathBuf>,
    /// Where each kind of file dialog last chose, per project.
    pub(crate) folders: super::files::DialogFolders,
    pub(crate) confirm: Option<Action>,
    pub(super) after_save: Option<Action>,
    pub(super) options: EditorOptions,
    pub(super) frames: u64,
    /// When the last input event (pointer, keys, wheel) arrived.
    pub(super) last_input: std::time::Instant,
    pub(super) scripted: Scripted,
    pub(super) title: String,
    pub(super) quit_confirmed: bool,
    pub(super) ctx: Context,
    /// The system's file dialogs, or the built-in one and why.
    pub(super) file_dialogs: FileDialogs,
    /// The built-in file dialog while it is open, and what it was opened for.
    pub(super) built_in_dialog: Option<(Pick, egui_file_dialog::FileDialog)>,
    pub(super) built_in_explained: bool,
    /// What the pipeline's base layer was loaded from.
    pub(super) base_loaded: Option<BaseKey>,
    /// File → Import VDB… while its window is open.
    pub(super) import: Option<super::import::ImportVdb>,
    /// File → Export…: its window and the choices remembered per project.
    pub(super) export: ExportUi,
    /// The command run last, for scripted drivers.
    pub(super) last_command: Option<Command>,
    /// Layout commands (View → Panels, Reset layout) for the app to apply to the dock.
    pub(super) dock_commands: Vec<Command>,
    /// The Timeline: playback and the selected key marker.
    pub(crate) timeline: super::playback::TimelineState,
    /// The still of the frame on show, for the preview, and the state it was made from.
    pub(super) still: Option<(Version, Project)>,
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
    /// The preview marches every pixel instead of sampling the image adaptively.
    pub per_pixel_march: bool,
    /// What "Fit grid to particles" keeps.
    pub fit_keep: crate::scene::FitKeep,
    /// Draw the Slices panel's plane in the viewport.
    pub show_slice_plane: bool,
    /// The kind of light the Light tool adds.
    pub new_light: crate::scene::LightKindChoice,
    /// Show the move gizmo at the selection's centre (Select tool).
    pub show_gizmo: bool,
    /// Where a Paint stroke would start under the pointer.
    pub brush_point: Option<glam::Vec3>,
    /// The pipeline's EV read back for painting at the fog's depth.
    pub fog_ev: Option<FogEv>,
    /// Particle bins for picking and box selection, and the content they were built from.
    pub pick_index: Option<(Version, std::sync::Arc<super::pick_index::ParticleIndex>)>,
}

/// `--screenshot` and `--measure-fps` progress.
#[derive(Default)]
pub(crate) struct Scripted {
    pub screenshot_requested: bool,
    pub measure_start: Option<Instant>,
    /// Frames drawn while still and while orbiting.
    pub measure_frames: [u32; 2],
}

/// Work running in background threads and what waits for it.
pub(crate) struct Jobs {
    pub(super) tx: mpsc::Sender<JobResult>,
    pub(super) rx: mpsc::Receiver<JobResult>,
    /// What each running job is doing, for the status bar.
    pub busy: Vec<String>,
    /// An export waiting for the bake to complete.
    pub(super) pending_export: Option<(ExportChoices, PathBuf)>,
    /// The export being written in the background.
    pub(super) export_job: Option<ExportJob>,
    /// The project being opened or restored in the background.
    pub(super) load: Option<LoadJob>,
    /// The steps of the last load that finished.
    pub(super) last_load_steps: Vec<String>,
}

impl Jobs {
    pub(super) fn new() -> Self {
        let (tx, rx) = mpsc::channel();
        Self {
            tx,
            rx,
            busy: Vec::new(),
            pending_export: None,
            export_job: None,
            load: None,
            last_load_steps: Vec::new(),
        }
    }
}

/// A project read in the background (File → Open, a recent file, a dropped file, a restored
/// recovery file): the steps of its load as `load_project_with` reports them, for the status
/// bar.
pub(crate) struct LoadJob {
    /// The file's name, for the status bar.
    pub(super) name: String,
    pub(super) started: Instant,
    /// Each step so far and the fraction of the load done before it.
    pub(super) steps: Arc<std::sync::Mutex<Vec<(String, f64)>>>,
}

/// Crash recovery: where recovery files go and what an earlier run left.
#[derive(Default)]
pub(crate) struct RecoveryState {
    /// Where recovery files go, when enabled.
    pub(super) dir: Option<PathBuf>,
    /// Writes and removes the files off the UI thread; present when recovery is enabled.
    pub(super) writer: Option<crate::scene::recovery::RecoveryWriter>,
    pub(super) written: Option<RecoveryWritten>,
    /// Work left by an earlier run that did not exit cleanly, offered at start.
    pub found: Vec<(PathBuf, crate::scene::recovery::Recovery)>,
}

/// The pipeline's extinction volume as read back, and the content it was read for
/// (generation 0 while the bake was still catching up with an edit).
pub(crate) struct FogEv {
    pub version: Version,
    pub ev: crate::scene::Volume,
}

/// What a shown slice was made from: the project, the pipeline's baked volumes and the
/// Slices panel's settings.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct SliceKey {
    pub epoch: u64,
    /// [`FogPipeline::volumes_generation`]: the volumes change when a bake completes,
    /// frames after the edit.
    pub volumes: u64,
    pub settings: SliceSettings,
}

/// What the pipeline's base layer is loaded from: it reloads when any of these change.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct BaseKey {
    pub base_volume: Option<crate::scene::BaseVolume>,
    pub grid: crate::scene::GridSpec,
    /// The project file, which relative base volume paths start from.
    pub project_path: Option<PathBuf>,
}

/// The last recovery file written: where, which content, and when.
#[derive(Clone, Debug)]
pub(crate) struct RecoveryWritten {
    pub path: PathBuf,
    pub version: Version,
    /// egui time, seconds.
    pub at: f64,
}

/// The slice currently shown and what it was made from.
#[derive(Default)]
pub(crate) struct SliceCache {
    pub key: Option<SliceKey>,
    pub slice: Option<Slice>,
    pub texture: Option<egui::TextureHandle>,
    pub error: Option<String>,
    pub exact: Option<(ExactKey, Result<Vec<f64>, String>)>,
    pub exact_pending: Option<ExactKey>,
    pub hover: Option<String>,
}

impl EditorState {
    /// The project as it stands: keys caches of whatever depends on it.
    pub(crate) fn version(&self) -> Version {
        Version { epoch: self.epoch, generation: self.session.generation() }
    }

    /// Particle bins for picking and box selection in large scenes (None in small ones, where
    /// the scan is as quick), built once per content generation.
    pub(crate) fn particle_index(&mut self) -> Option<std::sync::Arc<super::pick_index::ParticleIndex>> {
        let particles = &self.session.project().particles;
        if particles.len() < super::pick_index::INDEX_FROM {
            return None;
        }
        let version = self.content_version();
        match &self.view.pick_index {
            Some((v, index)) if *v == version && index.fits(particles) => Some(index.clone()),
            _ => {
                let index = std::sync::Arc::new(super::pick_index::ParticleIndex::build(particles));
                self.view.pick_index = Some((version, index.clone()));
                Some(index)
            }
        }
    }

    /// [`Self::version`] by content only (camera moves leave it alone).
    pub(crate) fn content_version(&self) -> Version {
        Version { epoch: self.epoch, generation: self.session.content_generation() }
    }

    /// What the viewport says over its image about the gesture under way, if anything.
    pub(crate) fn viewport_notice(&self) -> Option<&'static str> {
        match &self.view.gesture {
            Some(Gesture::Paint(stroke)) if stroke.outside => Some(
                "The brush is outside the grid box: Paint lays fog only inside it (move or resize the grid in the Inspector to paint here)",
            ),
            _ => None,
        }
    }

    pub(crate) fn error(&mut self, text: impl Into<String>) {
        self.toast(text.into(), true);
    }

    pub(crate) fn info(&mut self, text: impl Into<String>) {
        self.toast(text.into(), false);
    }

    /// A message as the newest toast; the same message again counts up instead of piling up.
    fn toast(&mut self, text: String, error: bool) {
        let born = self.ctx.input(|i| i.time);
        let count = match self.toasts.iter().position(|t| t.text == text && t.error == error) {
            Some(i) => self.toasts.remove(i).count + 1,
            None => 1,
        };
        self.toasts.push(Toast { text, error, born, count });
    }

    pub(super) fn replace_project(&mut self, project: Project, path: Option<PathBuf>, name: &str) {
        self.drop_recovery();
        self.session.replace(project, path, name);
        self.epoch += 1;
        self.view.gesture = None;
        self.view.modal = None;
        self.view.rename = None;
        self.view.slice = SliceCache::default();
        self.timeline.playing = None;
        self.timeline.selected_key = None;
        self.timeline.drag = None;
        self.still = None;
    }

    pub(super) fn begin_frame(&mut self, ctx: &Context) {
        // A frame whose first pass is discarded (a new grid or window sizing itself) runs the UI
        // again: that is still one frame, whose pipeline work the first pass did.
        if ctx.current_pass_index() == 0 {
            self.view.clock.tick();
            self.frames += 1;
        }
        while let Ok(result) = self.jobs.rx.try_recv() {
            self.finish_job(result);
        }
        self.open_dropped(ctx);
        if ctx.input(|i| i.viewport().close_requested()) && self.session.is_dirty() && !self.quit_confirmed {
            ctx.send_viewport_cmd(egui::ViewportCommand::CancelClose);
            self.confirm = Some(Action::Quit);
        }
        self.shortcuts(ctx);
        self.tick_playback();
    }

    pub(super) fn end_frame(&mut self, ctx: &Context) {
        // This frame's edits of animated values become keys (or unkeyed edits).
        self.session.sync_keys();
        // After every panel has seen the release, so a gesture's last step joins its undo step.
        if ctx.input(|i| i.pointer.any_released()) {
            self.session.end_edit();
            ctx.request_repaint();
        }
        self.write_recovery(ctx);
        self.recovery_dialog(ctx);
        self.confirm_dialog(ctx);
        self.built_in_dialog(ctx);
        self.import_window(ctx);
        self.export_window(ctx);
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
            if let Some((choices, path)) = self.jobs.pending_export.take() {
                self.export_to(choices, path);
            }
        }
        self.run_scripted(ctx);
    }
}

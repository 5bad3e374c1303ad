//! The eframe application: the dock and the state it shows, persisted between runs; the
//! frame's order (menus, status bar, dock, then dialogs and the preview).

use super::commands::Command;
use super::files::FileDialogs;
use super::layout::{self, default_layout, Tab};
use super::session::Session;
use super::slices::{Slice, SliceSettings};
use super::state::{FrameClock, GpuView, Jobs, RecoveryState, Scripted, SliceCache, ViewState};
use super::tools::{Brush, Tool};
use super::{EditorError, EditorOptions};
use crate::gpu::FogPipeline;
use crate::scene::{load_project, Project};
use egui::Id;
use egui_dock::{DockArea, DockState};
use serde::{Deserialize, Serialize};
use std::path::{Path, PathBuf};

pub use super::export_choices::{ExportChoices, ExportFormat, ImageFormat};
pub use super::preview::{PreviewStatus, FRAME_BUDGET_MS};
pub use super::state::{Action, EditorState, PreviewScale, Quality};

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
    folders: super::files::DialogFolders,
    tool: Tool,
    brush: Brush,
    slices: SliceSettings,
    quality: Quality,
    preview_scale: PreviewScale,
    outline_all: Option<bool>,
    show_gizmo: Option<bool>,
    /// The layout has been given the Timeline once (layouts remembered from before it
    /// existed get it under the viewport).
    timeline_added: bool,
    looping: Option<bool>,
    play_mode: super::playback::PlayMode,
}

const STORAGE_KEY: &str = "fogsmith-editor";

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
        let file_dialogs = options.file_dialogs.clone().unwrap_or_else(FileDialogs::detect);
        let state_dir = options.state_dir.clone().unwrap_or_else(crate::scene::recovery::state_dir);
        let mut dock = persisted.dock.filter(|d| d.iter_all_tabs().next().is_some()).unwrap_or_else(default_layout);
        if !persisted.timeline_added && dock.find_tab(&Tab::Timeline).is_none() {
            layout::add_timeline(&mut dock);
        }
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
                per_pixel_march: false,
                fit_keep: crate::scene::FitKeep::default(),
                show_slice_plane: false,
                new_light: crate::scene::LightKindChoice::Point,
                show_gizmo: persisted.show_gizmo.unwrap_or(true),
                brush_point: None,
                fog_ev: None,
                pick_index: None,
            },
            jobs: Jobs::new(),
            recovery: RecoveryState::default(),
            gpu,
            gpu_missing,
            toasts: Vec::new(),
            recent: persisted.recent,
            folders: persisted.folders,
            confirm: None,
            after_save: None,
            options,
            frames: 0,
            last_input: std::time::Instant::now(),
            scripted: Scripted::default(),
            title: String::new(),
            quit_confirmed: false,
            ctx: cc.egui_ctx.clone(),
            file_dialogs,
            built_in_dialog: None,
            built_in_explained: false,
            base_loaded: None,
            import: None,
            export: super::export_memory::ExportUi::new(state_dir),
            last_command: None,
            dock_commands: Vec::new(),
            timeline: super::playback::TimelineState {
                looping: persisted.looping.unwrap_or(true),
                mode: persisted.play_mode,
                ..super::playback::TimelineState::new()
            },
            still: None,
        };
        if state.options.recovery {
            state.find_recoveries();
        }
        if let Some(e) = start.error {
            state.error(e);
        }
        if let Some(n) = state.options.scripted_stroke {
            state.scripted_stroke(n);
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
    /// What the viewport says over its image about the gesture under way (e.g. a brush
    /// outside the grid box).
    pub fn viewport_notice(&self) -> Option<&'static str> {
        self.state.viewport_notice()
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
    /// Preview → March every pixel.
    pub fn set_per_pixel_march(&mut self, on: bool) {
        self.state.view.per_pixel_march = on;
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
    /// The preview image on show as linear HDR radiance (lit, or "as baked").
    pub fn shown_preview(&self) -> Option<Result<crate::gpu::Image, crate::gpu::GpuError>> {
        self.state.gpu.as_ref().map(|g| g.shown_image())
    }
    /// Where the preview stands: what it shows and what is left to refine.
    pub fn preview_status(&self) -> Option<PreviewStatus> {
        self.state.preview_status()
    }

    /// Wall time of the last frame's pipeline call (its budgeted work and the quick image),
    /// ms; 0 when that frame made none.
    pub fn pipeline_ms(&self) -> Option<f64> {
        self.state.gpu.as_ref().map(|g| g.frame_update_ms)
    }

    pub fn gpu_error(&self) -> Option<String> {
        self.state.gpu.as_ref().and_then(|g| g.error.clone()).or_else(|| self.state.gpu_missing.clone())
    }
    /// Background jobs (saving, loading, dialogs) still running.
    pub fn busy(&self) -> usize {
        self.state.jobs.busy.len()
    }
    /// The steps of the project load in progress (File → Open, a recent or dropped file, a
    /// restored recovery file), or of the last one once it has finished, as the status bar
    /// names them.
    pub fn load_steps(&self) -> Vec<String> {
        match &self.state.jobs.load {
            Some(load) => {
                load.steps.lock().map(|s| s.iter().map(|(step, _)| step.clone()).collect()).unwrap_or_default()
            }
            None => self.state.jobs.last_load_steps.clone(),
        }
    }

    /// Runs or (with unsaved changes) asks before running `action`.
    pub fn request(&mut self, action: Action) {
        self.state.request(action);
    }
    /// Saves to `path` in the background, as after choosing it in the Save As dialog.
    pub fn save_as(&mut self, path: PathBuf) {
        self.state.picked(super::state::Pick::SaveAs, path);
    }
    /// Exports to `path` in the background, as the Export window does with `choices` once
    /// `path` is chosen in its dialog.
    pub fn export(&mut self, choices: ExportChoices, path: PathBuf) {
        self.state.picked(super::state::Pick::Export(choices), path);
    }
    /// The folder a file dialog of `kind` would start in now.
    pub fn dialog_start(&self, kind: super::files::DialogKind) -> Option<PathBuf> {
        self.state.dialog_directory(kind)
    }
    /// The Export window's choices while it is open.
    pub fn export_window(&self) -> Option<ExportChoices> {
        self.state.export.window
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
    /// Where the Timeline's scrub bar was drawn last, to point at frames and key markers.
    pub fn scrub_bar(&self) -> Option<super::playback::ScrubBar> {
        self.state.timeline.bar
    }
    /// Whether playback is running.
    pub fn playing(&self) -> bool {
        self.state.timeline.playing.is_some()
    }
    pub fn set_play_mode(&mut self, mode: super::playback::PlayMode) {
        self.state.timeline.mode = mode;
    }
    pub fn set_looping(&mut self, looping: bool) {
        self.state.timeline.looping = looping;
    }
    /// The frame of the selected key marker, if one is selected.
    pub fn selected_key(&self) -> Option<i32> {
        self.state.timeline.selected_key.as_ref().map(|(f, _)| *f)
    }
    /// Playback's rate: frames shown per second over the last two seconds, and the frames
    /// real-time playback dropped since it started.
    pub fn playback_rate(&self) -> (Option<f64>, u64) {
        (self.state.timeline.meter.fps(), self.state.timeline.dropped)
    }
    /// Runs `command`, as its menu item or shortcut would.
    pub fn run(&mut self, command: Command) {
        self.state.run(command);
    }

    /// Opens (in the focused area) or closes a panel.
    pub fn set_tab_open(&mut self, tab: Tab, open: bool) {
        layout::set_open(&mut self.dock, tab, open);
    }

    /// Applies the layout commands run since the last call (View → Panels, Reset layout).
    fn apply_dock_commands(&mut self) {
        for command in std::mem::take(&mut self.state.dock_commands) {
            match command.panel() {
                Some(tab) => {
                    let open = self.dock.find_tab(&tab).is_some();
                    self.set_tab_open(tab, !open);
                }
                None => self.dock = default_layout(),
            }
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
        egui::Panel::top("menu").show(ui, |ui| self.state.menu_bar(ui, &self.dock));
        self.apply_dock_commands();
        egui::Panel::bottom("status").show(ui, |ui| self.state.status_bar(ui));
        let mut style = egui_dock::Style::from_egui(ui.style().as_ref());
        // Lets a panel be as short as the Timeline (egui_dock's default keeps 175 points).
        style.separator.extra = layout::MIN_PANEL;
        egui::CentralPanel::default().frame(egui::Frame::NONE).show(ui, |ui| {
            DockArea::new(&mut self.dock).style(style).show_inside(ui, &mut self.state);
        });
        self.state.end_frame(&ctx);
    }

    fn on_exit(&mut self) {
        self.state.drop_recovery();
        self.state.finish_recovery();
    }

    fn save(&mut self, storage: &mut dyn eframe::Storage) {
        let persisted = Persisted {
            dock: Some(self.dock.clone()),
            recent: self.state.recent.clone(),
            folders: self.state.folders.clone(),
            tool: self.state.view.tool,
            brush: self.state.view.brush,
            slices: self.state.view.slices,
            quality: self.state.view.quality,
            preview_scale: self.state.view.preview_scale,
            outline_all: Some(self.state.view.outline_all),
            show_gizmo: Some(self.state.view.show_gizmo),
            timeline_added: true,
            looping: Some(self.state.timeline.looping),
            play_mode: self.state.timeline.mode,
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
            Tab::Slices => super::slice_panel::show(self, ui),
            Tab::Outliner => super::panels::outliner(self, ui),
            Tab::Inspector => super::panels::inspector(self, ui),
            Tab::Stats => super::panels::stats(self, ui),
            Tab::Timeline => super::timeline::show(self, ui),
        }
    }

    /// The Viewport has no close button on its tab, where a click meant to focus it would
    /// land; View → Panels still hides it.
    fn is_closeable(&self, tab: &Tab) -> bool {
        *tab != Tab::Viewport
    }

    fn scroll_bars(&self, tab: &Tab) -> [bool; 2] {
        match tab {
            // The Inspector scrolls its rows itself, above its notice strip.
            Tab::Stats | Tab::Timeline => [false, true],
            _ => [false, false],
        }
    }
}

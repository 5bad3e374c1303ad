//! The preview driver: advances the pipeline on egui-wgpu's device once per frame within a
//! time budget and hands its image to egui-wgpu as a texture; also reads the extinction
//! volume back for painting at the fog's depth.

use super::session::Version;
use super::state::{BaseKey, EditorState, FogEv, GpuView, PreviewKey, Quality, ShownFrames};
use crate::gpu::{BakePhase, FogPipeline, FrameReport, FrameRequest, GpuContext, Progress};
use crate::scene::Project;
use eframe::egui_wgpu::{self, wgpu};
use std::path::Path;
use std::time::{Duration, Instant};

/// GPU time the preview may take per frame. The rest of a frame (egui's layout and
/// painting) stays well within 100 ms on a software adapter, so the window keeps following
/// the pointer while the pipeline refines the preview over the following frames.
pub const FRAME_BUDGET_MS: f64 = 30.0;

/// While no input arrives, the pipeline may take this many times the rest of the last
/// frame's cost (egui, the quick march, present), so that most of the wall time goes to the
/// work and convergence approaches the work's own time...
pub const IDLE_WORK_SHARE: f64 = 6.0;
/// ...but no more than this, so that input arriving during an idle frame waits at most
/// about this plus the rest of the frame. The march's bands fit the time left (parts of a
/// row of workgroups where a whole row would not), so idle frames keep to it.
pub const IDLE_BUDGET_MAX_MS: f64 = 200.0;

/// How long without input before a frame counts as idle: longer than the gaps between the
/// steps of a wheel turn (a drag holds its gesture and is never idle).
pub const IDLE_AFTER: Duration = Duration::from_millis(250);

/// The pipeline's budget for a frame: [`FRAME_BUDGET_MS`] during input, and while idle
/// [`IDLE_WORK_SHARE`] times the rest of the last frame, between the two bounds.
pub fn frame_budget_ms(idle: bool, last_frame_ms: Option<f64>, last_update_ms: f64) -> f64 {
    match (idle, last_frame_ms) {
        (true, Some(frame)) => {
            let rest = (frame - last_update_ms).max(0.0);
            (IDLE_WORK_SHARE * rest).clamp(FRAME_BUDGET_MS, IDLE_BUDGET_MAX_MS)
        }
        _ => FRAME_BUDGET_MS,
    }
}

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
    /// Calls into the pipeline so far: at most one per frame.
    pub calls: u64,
    /// In an animation: the frame of the fog on show, and of its shadows (an earlier one
    /// while propagation catches up with playback or a scrub).
    pub shown_frame: Option<i32>,
    pub shadows_frame: Option<i32>,
}

impl GpuView {
    pub(super) fn new(render_state: &egui_wgpu::RenderState) -> Self {
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
            calls: 0,
            update_ms: 0.0,
            frame_update_ms: 0.0,
            budget_ms: None,
            frame_ms: None,
            last_frame: u64::MAX,
            shown: None,
            as_baked: None,
            frames: ShownFrames::default(),
        }
    }

    /// Whether the preview still has work to do for the current inputs.
    pub fn refining(&self) -> bool {
        self.converged.is_none() && self.error.is_none()
    }

    /// Advances the pipeline towards `project` (the still of animation frame `frame`, if
    /// any) at `size` pixels within `budget` (None: to convergence), with quick images
    /// while it refines when `previews`, or renders its bake as an engine shows it
    /// (`as_baked`, to convergence); returns whether a new image is on show.
    fn render(
        &mut self,
        project: &Project,
        frame: Option<i32>,
        version: Version,
        size: [u32; 2],
        (budget, previews): (Option<Duration>, bool),
        as_baked: Option<BakePhase>,
    ) -> bool {
        let key = PreviewKey { version, size };
        if self.converged == Some(key) && self.as_baked == as_baked {
            return false;
        }
        self.converged = None;
        self.calls += 1;
        let request =
            FrameRequest { width: size[0], height: size[1], scheme: project.propagation.scheme, force: false };
        if let Some(phase) = as_baked {
            return self.render_as_baked(project, &request, key, phase);
        }
        let switched_back = self.as_baked.take().is_some();
        let started = Instant::now();
        let result = match previews {
            true => self.pipeline.advance(project, &request, budget),
            false => self.pipeline.advance_full_only(project, &request, budget),
        };
        self.update_ms = started.elapsed().as_secs_f64() * 1e3;
        self.frame_update_ms = self.update_ms;
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
        self.frames = shown_frames(self.frames, frame, &progress);
        self.progress = progress;
        if progress.converged() {
            self.converged = Some(key);
        }
        // Back from "as baked": the lit image the pipeline holds shows again.
        if !progress.new_image && !switched_back {
            // An edit that changes nothing on show (a dab outside the grid) is on show at once.
            if progress.shows_scene {
                self.shown = Some(version);
            }
            return false;
        }
        self.renders += 1;
        self.shown = Some(version);
        if let Some((view, shown)) = self.pipeline.display_view() {
            show_texture(&self.render_state, &mut self.texture, view, shown);
        }
        true
    }

    /// Bakes `project` and shows its emission–absorption render.
    fn render_as_baked(
        &mut self,
        project: &Project,
        request: &FrameRequest,
        key: PreviewKey,
        phase: BakePhase,
    ) -> bool {
        let started = Instant::now();
        let result = self.pipeline.render_as_baked(project, request, phase);
        self.update_ms = started.elapsed().as_secs_f64() * 1e3;
        self.frame_update_ms = self.update_ms;
        self.converged = Some(key);
        self.as_baked = Some(phase);
        if let Err(e) = result {
            self.error = Some(e.to_string());
            return false;
        }
        self.error = None;
        self.renders += 1;
        self.shown = Some(key.version);
        if let Some((view, shown)) = self.pipeline.as_baked_view() {
            show_texture(&self.render_state, &mut self.texture, view, shown);
        }
        true
    }

    /// The image on show as linear HDR radiance: the lit preview's, or the "as baked" one.
    pub(crate) fn shown_image(&self) -> Result<crate::gpu::Image, crate::gpu::GpuError> {
        match self.as_baked {
            Some(_) => self.pipeline.read_as_baked(),
            None => self.pipeline.read_image(),
        }
    }
}

/// Points the preview's egui texture at `view` (quick, full and "as baked" images live in
/// different textures).
fn show_texture(
    render_state: &egui_wgpu::RenderState,
    texture: &mut Option<(egui::TextureId, [u32; 2])>,
    view: &wgpu::TextureView,
    shown: [u32; 2],
) {
    let mut renderer = render_state.renderer.write();
    let device = &render_state.device;
    match *texture {
        None => {
            let id = renderer.register_native_texture(device, view, wgpu::FilterMode::Linear);
            *texture = Some((id, shown));
        }
        Some((id, _)) => {
            renderer.update_egui_texture_from_wgpu_texture(device, view, wgpu::FilterMode::Linear, id);
            *texture = Some((id, shown));
        }
    }
}

/// The frames on show after a pipeline call for animation frame `frame` (None: a still)
/// that made `progress`. Once a call ends past propagation, the optical depths are that
/// frame's; a new image's shadows are its frame's unless they are stale, and then those
/// baked before the call (a quick image is marched before propagation runs).
pub(crate) fn shown_frames(before: ShownFrames, frame: Option<i32>, progress: &crate::gpu::Progress) -> ShownFrames {
    use crate::gpu::Stage;
    let Some(frame) = frame else { return ShownFrames::default() };
    let mut now = before;
    if matches!(progress.stage, Stage::Scatter | Stage::March | Stage::Done) {
        now.baked_shadows = Some(frame);
    }
    if progress.new_image {
        now.fog = Some(frame);
        now.shadows = if progress.shadows_stale { before.baked_shadows } else { Some(frame) };
    }
    now
}

impl EditorState {
    /// Advances the preview once per frame within the frame budget (or to convergence in
    /// [`Quality::Full`]); while work remains, asks for another frame.
    pub(crate) fn render_preview(&mut self) {
        let Some(gpu) = &mut self.gpu else { return };
        if gpu.last_frame == self.frames {
            return;
        }
        gpu.last_frame = self.frames;
        let last_frame = self.view.clock.last_frame_ms();
        gpu.frame_ms = last_frame.map(|f| (f, (f - gpu.frame_update_ms).max(0.0)));
        let last_update_ms = std::mem::take(&mut gpu.frame_update_ms);
        // Idle: no gesture, no button held, and no event (pointer moves, keys, wheel) for a while.
        if self.ctx.input(|i| !i.events.is_empty() || i.pointer.any_down()) {
            self.last_input = Instant::now();
        }
        let idle = self.view.gesture.is_none() && self.last_input.elapsed() >= IDLE_AFTER;
        let budget = match self.view.quality {
            Quality::Balanced => {
                let ms = frame_budget_ms(idle, last_frame, last_update_ms);
                gpu.budget_ms = Some((ms, idle && ms > FRAME_BUDGET_MS));
                Some(Duration::from_secs_f64(ms * 1e-3))
            }
            Quality::Full | Quality::AsBaked(_) => {
                gpu.budget_ms = None;
                None
            }
        };
        // The base volume, loaded through the project like every other path.
        let project = self.session.project();
        let key = BaseKey {
            base_volume: project.base_volume.clone(),
            grid: project.grid,
            project_path: self.session.path().map(Path::to_owned),
        };
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
        let version = self.version();
        let animated = self.session.project().animation.is_some();
        if animated && self.still.as_ref().is_none_or(|(v, _)| *v != version) {
            self.still = Some((version, self.session.frame_still()));
        }
        let (project, frame) = match &self.still {
            Some((_, still)) if animated => (still, Some(self.session.frame())),
            _ => (self.session.project(), None),
        };
        // Playing every frame shows each frame converged: a quick image would be marched
        // only to be replaced.
        let previews = !self.playing_every_frame();
        let Some(gpu) = &mut self.gpu else { return };
        let sampling = if self.view.per_pixel_march {
            crate::gpu::ImageSampling::PerPixel
        } else {
            crate::gpu::ImageSampling::default()
        };
        if gpu.pipeline.image_sampling() != sampling {
            gpu.pipeline.set_image_sampling(sampling);
            gpu.converged = None;
        }
        let before = gpu.error.clone();
        gpu.render(project, frame, version, self.view.preview_size, (budget, previews), self.view.quality.as_baked());
        if gpu.refining() {
            self.ctx.request_repaint();
        }
        if gpu.error.is_some() && gpu.error != before {
            let message = gpu.error.clone().unwrap_or_default();
            self.error(format!("Preview failed: {message}"));
        }
    }

    /// The pipeline's extinction volume, read back once per content change (for painting at
    /// the fog's depth); None without a pipeline or when the read fails.
    pub(crate) fn fog_ev(&mut self) -> Option<&crate::scene::Volume> {
        let key = self.content_version();
        let fresh = self.view.fog_ev.as_ref().is_some_and(|f| f.version == key);
        if !fresh {
            let gpu = self.gpu.as_ref()?;
            let grid = self.session.project().grid;
            let stale_usable =
                self.view.fog_ev.as_ref().is_some_and(|f| f.version.epoch == key.epoch && f.ev.grid == grid);
            // While the bake catches up with an edit, the last complete read is close enough.
            if !(gpu.refining() && stale_usable) {
                let ev = gpu.pipeline.read_ev().ok()?;
                if ev.grid != grid {
                    return None;
                }
                let generation = if gpu.refining() { 0 } else { key.generation };
                self.view.fog_ev = Some(FogEv { version: Version { generation, ..key }, ev });
            }
        }
        self.view.fog_ev.as_ref().map(|f| &f.ev)
    }

    /// Where the preview stands: what it shows and what is left to refine.
    pub(super) fn preview_status(&self) -> Option<PreviewStatus> {
        let gpu = self.gpu.as_ref()?;
        Some(PreviewStatus {
            shown_generation: gpu.shown.filter(|v| v.epoch == self.epoch).map(|v| v.generation),
            converged: !gpu.refining(),
            shadows_stale: gpu.progress.shadows_stale,
            shown_size: gpu.progress.shown_size,
            renders: gpu.renders,
            calls: gpu.calls,
            shown_frame: gpu.frames.fog,
            shadows_frame: gpu.frames.shadows,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_budget_grows_only_while_idle_and_stays_within_its_bounds() {
        assert_eq!(frame_budget_ms(false, Some(200.0), 30.0), FRAME_BUDGET_MS, "input keeps the frame budget");
        assert_eq!(frame_budget_ms(true, None, 0.0), FRAME_BUDGET_MS, "no frame measured yet");
        assert_eq!(frame_budget_ms(true, Some(35.0), 20.0), 90.0, "six times the 15 ms rest of the frame");
        assert_eq!(frame_budget_ms(true, Some(35.0), 30.0), FRAME_BUDGET_MS, "never below the frame budget");
        assert_eq!(frame_budget_ms(true, Some(500.0), 30.0), IDLE_BUDGET_MAX_MS, "never above the cap");
        assert_eq!(frame_budget_ms(true, Some(10.0), 30.0), FRAME_BUDGET_MS, "a rest below zero counts as none");
    }

    #[test]
    fn the_frames_on_show_follow_propagation_and_new_images() {
        use crate::gpu::{Progress, Stage};
        let call = |stage: Stage, new_image: bool, shadows_stale: bool| Progress {
            stage,
            new_image,
            shadows_stale,
            ..Progress::default()
        };
        let s = shown_frames(ShownFrames::default(), Some(1), &call(Stage::Done, true, false));
        assert_eq!(s, ShownFrames { baked_shadows: Some(1), fog: Some(1), shadows: Some(1) });
        // Frame 5: a quick image with frame 1's optical depths while propagation runs.
        let s = shown_frames(s, Some(5), &call(Stage::Propagate { lights: 1 }, true, true));
        assert_eq!(s, ShownFrames { baked_shadows: Some(1), fog: Some(5), shadows: Some(1) });
        // Frame 9: a quick image first, then frame 9's propagation finishes in the same call.
        let s = shown_frames(s, Some(9), &call(Stage::March, true, true));
        assert_eq!(s, ShownFrames { baked_shadows: Some(9), fog: Some(9), shadows: Some(1) });
        // No new image: what is on show stays.
        let s = shown_frames(s, Some(9), &call(Stage::March, false, true));
        assert_eq!(s.fog, Some(9));
        let s = shown_frames(s, Some(9), &call(Stage::Done, true, false));
        assert_eq!((s.fog, s.shadows), (Some(9), Some(9)));
        assert_eq!(shown_frames(s, None, &call(Stage::Done, true, false)), ShownFrames::default(), "a still");
    }
}

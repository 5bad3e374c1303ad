//! `bench --suite interaction`: the editor as an artist meets it. Drives the real editor
//! (egui_kittest on the real pipeline and device, every frame painted) with scripted input on
//! every demo and a scene of 10⁵ small particles, `large` (or those `--scene` names), timed
//! by the wall clock:
//! - 2 s without input, once the preview has converged (idle frames);
//! - a 40-dab paint stroke over 2 s;
//! - a 1 s drag of a light (Select tool);
//! - 5 wheel steps of the Scale tool on a selection;
//! - an erase stroke over 1 s;
//! - playback: the first light with a position keyed to travel across 24 frames, played in
//!   the Timeline's "every frame" mode (each frame shown converged before the next).
//!
//! For each it records every frame's wall time (p50, p95, p99, max), the time from each input
//! to the end of the first frame whose preview shows it, and the time from the end of the
//! interaction to the converged image (full resolution, fresh optical depths), and where the
//! frames' time went: the pipeline's call (budgeted work and the quick image) against the
//! rest (egui's layout and painting), during the interaction and while converging. For
//! playback it records the frames played per second of wall time, beside the rate at which
//! the same frames' work alone (injection, propagation and march at the preview's size, on a
//! pipeline of its own) completes: the rate "every frame" playback can reach.

use super::context::{small_particle_scene, LARGE_SCENE};
use super::BenchError;
use crate::editor::app::{Quality, StartProject};
use crate::editor::driver::{DriverSetup, EditorDriver};
use crate::editor::tools::Tool;
use crate::editor::view::ViewProjection;
use crate::editor::EditorOptions;
use egui::{Event, Modifiers, PointerButton, Pos2, Vec2};
use serde_json::{json, Value};
use std::time::{Duration, Instant};

/// Longest wait for the preview to converge after an interaction (four times this on the
/// large scene, whose march steps finely through the whole box).
const CONVERGE_LIMIT: Duration = Duration::from_secs(60);

/// The editor under the script, and what its frames recorded.
struct Recorder {
    h: EditorDriver,
    /// Wall time of every frame of the current interaction, in ms.
    frames: Vec<f64>,
    /// Per input: when it was queued and the session generation it produced.
    inputs: Vec<(Instant, u64)>,
    /// Per frame: when it ended and the generation on show.
    shown: Vec<(Instant, Option<u64>)>,
    /// Per frame: the pipeline call's wall time, ms (its share of the frame's).
    pipeline: Vec<f64>,
    /// The same two for the frames after the interaction, until convergence.
    settle_frames: Vec<f64>,
    settle_pipeline: Vec<f64>,
    scene: String,
    converge_limit: Duration,
    /// The session's generation when the current interaction began.
    begun_at: u64,
}

impl Recorder {
    /// One frame, painted, with `event` (if any) as its input.
    fn frame(&mut self, event: Option<Event>) -> Result<(), BenchError> {
        let queued = Instant::now();
        let is_input = event.is_some();
        self.h
            .painted_frame(event)
            .map_err(|message| BenchError::Editor(format!("painting a frame failed: {message}")))?;
        let end = Instant::now();
        self.frames.push((end - queued).as_secs_f64() * 1e3);
        self.pipeline.push(self.h.state().pipeline_ms().unwrap_or(0.0));
        let status = self
            .h
            .state()
            .preview_status()
            .ok_or_else(|| BenchError::Editor("the editor has no GPU preview".into()))?;
        let generation = self.h.state().session().generation();
        // An input counts once it changes the project (a hover before a press does not).
        let last = self.inputs.last().map_or(self.begun_at, |&(_, g)| g);
        if is_input && generation != last {
            self.inputs.push((queued, generation));
        }
        self.shown.push((end, status.shown_generation));
        if let Some(e) = self.h.state().gpu_error() {
            return Err(BenchError::Editor(format!("the preview failed: {e}")));
        }
        Ok(())
    }

    /// Frames until the preview converges; returns the time it took. Their frame and
    /// pipeline times go to `settle_frames` and `settle_pipeline`.
    fn settle(&mut self) -> Result<f64, BenchError> {
        let (frames, pipeline) = (self.frames.len(), self.pipeline.len());
        let start = Instant::now();
        while !self.h.converged() {
            if start.elapsed() > self.converge_limit {
                return Err(BenchError::Editor(format!(
                    "the preview did not converge within {} s",
                    self.converge_limit.as_secs()
                )));
            }
            self.frame(None)?;
        }
        self.settle_frames = self.frames.split_off(frames);
        self.settle_pipeline = self.pipeline.split_off(pipeline);
        Ok(start.elapsed().as_secs_f64() * 1e3)
    }

    fn begin(&mut self) {
        self.begun_at = self.h.state().session().generation();
        self.frames.clear();
        self.inputs.clear();
        self.shown.clear();
        self.pipeline.clear();
    }

    /// Runs frames for `duration`, feeding the pointer along `path(t)` (t in [0, 1]) at the
    /// wall-clock rate of `steps` inputs over the duration; the newest due input goes into
    /// each frame, as a real pointer's moves coalesce between frames.
    fn pointer_path(&mut self, duration: Duration, steps: usize, path: impl Fn(f32) -> Pos2) -> Result<(), BenchError> {
        let start = Instant::now();
        let mut sent = 0;
        while sent < steps {
            let due = ((start.elapsed().as_secs_f64() / duration.as_secs_f64()) * steps as f64).floor() as usize;
            let due = due.min(steps);
            if due > sent {
                sent = due;
                self.frame(Some(Event::PointerMoved(path(sent as f32 / steps as f32))))?;
            } else {
                self.frame(None)?;
            }
        }
        Ok(())
    }

    fn press(&mut self, pos: Pos2, pressed: bool) -> Result<(), BenchError> {
        self.frame(Some(EditorDriver::button_event(pos, PointerButton::Primary, pressed)))
    }

    /// The figures of the interaction just run, after waiting for convergence.
    fn record(&mut self, name: &str, quality: Quality, log: &mut dyn FnMut(&str)) -> Result<Value, BenchError> {
        if name != "idle" && self.inputs.is_empty() {
            return Err(BenchError::Editor(format!(
                "{}: the {name} case changed nothing in the project (its input missed its target), so it has no figures",
                self.scene
            )));
        }
        let frames = self.frames.clone();
        let pipeline = self.pipeline.clone();
        let converge_ms = self.settle()?;
        let during = Breakdown::of(&frames, &pipeline);
        let converging = Breakdown::of(&self.settle_frames, &self.settle_pipeline);
        let mut latencies = Vec::new();
        for (i, &(t, _)) in self.inputs.iter().enumerate() {
            let later: Vec<u64> = self.inputs[i..].iter().map(|&(_, g)| g).collect();
            if let Some(&(end, _)) =
                self.shown.iter().find(|&&(end, g)| end >= t && g.is_some_and(|g| later.contains(&g)))
            {
                latencies.push((end - t).as_secs_f64() * 1e3);
            }
        }
        let unseen = self.inputs.len() - latencies.len();
        let f = percentiles(&frames);
        let l = percentiles(&latencies);
        let record = json!({
            "suite": "interaction",
            "scene": self.scene,
            "case": name,
            "quality": format!("{quality:?}"),
            "frames": frames.len(),
            "frame_ms": {"p50": f[0], "p95": f[1], "p99": f[2], "max": f[3]},
            "inputs": self.inputs.len(),
            "inputs_never_shown": unseen,
            "input_to_preview_ms": {"p50": l[0], "p95": l[1], "p99": l[2], "max": l[3]},
            "end_to_converged_ms": converge_ms,
            "breakdown_during": during.json(),
            "breakdown_converging": converging.json(),
            "frame_times_ms": frames,
        });
        log(&format!(
            "interaction {:<8} {name:<12} {:?}: {} frames, frame ms p50 {:.0} p95 {:.0} p99 {:.0} max {:.0}; input→preview ms p50 {:.0} max {:.0} ({} inputs, {} never shown); end→converged {:.0} ms",
            self.scene, quality, frames.len(), f[0], f[1], f[2], f[3], l[0], l[3], self.inputs.len(), unseen, converge_ms
        ));
        log(&format!(
            "    frame time during: {}; while converging ({} frames): {}",
            during.text(),
            self.settle_frames.len(),
            converging.text()
        ));
        Ok(record)
    }
}

/// Where a run of frames' wall time went: the pipeline's call against the rest.
struct Breakdown {
    frames: usize,
    total_ms: f64,
    pipeline_ms: f64,
}

impl Breakdown {
    fn of(frames: &[f64], pipeline: &[f64]) -> Self {
        Self { frames: frames.len(), total_ms: frames.iter().sum(), pipeline_ms: pipeline.iter().sum() }
    }
    fn rest_ms(&self) -> f64 {
        (self.total_ms - self.pipeline_ms).max(0.0)
    }
    fn json(&self) -> Value {
        let n = self.frames.max(1) as f64;
        json!({
            "frames": self.frames,
            "mean_frame_ms": self.total_ms / n,
            "mean_pipeline_ms": self.pipeline_ms / n,
            "mean_rest_ms": self.rest_ms() / n,
        })
    }
    fn text(&self) -> String {
        if self.frames == 0 {
            return "no frames".into();
        }
        let n = self.frames as f64;
        format!(
            "mean {:.0} ms = pipeline {:.0} ms ({:.0} %) + UI and painting {:.0} ms",
            self.total_ms / n,
            self.pipeline_ms / n,
            100.0 * self.pipeline_ms / self.total_ms.max(1e-9),
            self.rest_ms() / n
        )
    }
}

/// p50, p95, p99 and max (NaN for no samples).
fn percentiles(v: &[f64]) -> [f64; 4] {
    if v.is_empty() {
        return [f64::NAN; 4];
    }
    let mut s = v.to_vec();
    s.sort_by(f64::total_cmp);
    let at = |q: f64| s[((q * (s.len() - 1) as f64).round() as usize).min(s.len() - 1)];
    [at(0.5), at(0.95), at(0.99), s[s.len() - 1]]
}

/// Runs the script on demo `scene` (or [`LARGE_SCENE`]) with the preview in `quality`.
pub fn run(
    scene: &str,
    quality: Quality,
    sampling: crate::gpu::ImageSampling,
    log: &mut dyn FnMut(&str),
) -> Result<Vec<Value>, BenchError> {
    let large = scene == LARGE_SCENE;
    let project = if large { small_particle_scene(100_000, 2, 64) } else { crate::demos::demo(scene)? };
    let start = StartProject { project, path: None, name: format!("{scene}.ron"), error: None };
    let setup = DriverSetup {
        // The window size whose viewport is about 840×455 points in the default layout.
        size: Vec2::new(1384.0, 869.0),
        quality,
        preview_scale: large.then_some(crate::editor::app::PreviewScale::Quarter),
        options: EditorOptions::default(),
    };
    let mut h = EditorDriver::new(start, setup);
    h.state_mut().set_per_pixel_march(sampling == crate::gpu::ImageSampling::PerPixel);
    let mut d = Recorder {
        h,
        frames: Vec::new(),
        inputs: Vec::new(),
        shown: Vec::new(),
        pipeline: Vec::new(),
        settle_frames: Vec::new(),
        settle_pipeline: Vec::new(),
        scene: scene.to_owned(),
        converge_limit: if large { CONVERGE_LIMIT * 4 } else { CONVERGE_LIMIT },
        begun_at: 0,
    };
    // The Timeline is driven by its commands here; closed, it leaves the viewport the size of
    // the earlier records.
    d.h.state_mut().set_tab_open(crate::editor::Tab::Timeline, false);
    d.frame(None)?;
    d.settle()?;
    let rect = d.h.viewport_rect().ok_or_else(|| BenchError::Editor("the viewport is not shown".into()))?;
    log(&format!(
        "interaction: {scene}, viewport {:.0}×{:.0} points, adapter {}",
        rect.width(),
        rect.height(),
        d.h.state().pipeline().map(|p| p.context().adapter_summary()).unwrap_or_default()
    ));
    let mut records = Vec::new();
    // A stroke across the upper middle of the viewport, `t` in [0, 1]. Each case reads the
    // layout again: a warning row above the viewport (particles outside the grid after the
    // paint stroke) moves it down.
    let across = |rect: egui::Rect, t: f32| {
        rect.center() + Vec2::new((t - 0.5) * rect.width() * 0.5, (t - 0.5) * rect.height() * 0.15)
    };
    let viewport =
        |d: &Recorder| d.h.viewport_rect().ok_or_else(|| BenchError::Editor("the viewport is not shown".into()));

    // Idle: frames with nothing to do but show the converged image.
    d.begin();
    let idle = Instant::now();
    while idle.elapsed() < Duration::from_secs(2) {
        d.frame(None)?;
    }
    records.push(d.record("idle", quality, log)?);

    // A paint stroke: 40 dabs over 2 s.
    d.h.state_mut().set_tool(Tool::Paint);
    d.begin();
    d.frame(Some(Event::PointerMoved(across(rect, 0.0))))?;
    d.press(across(rect, 0.0), true)?;
    d.pointer_path(Duration::from_secs(2), 40, |t| across(rect, t))?;
    d.press(across(rect, 1.0), false)?;
    records.push(d.record("paint", quality, log)?);

    // Drag the light nearest the view's centre for 1 s.
    let rect = viewport(&d)?;
    let centre = rect.center();
    let project = d.h.state().session().project().clone();
    let view = ViewProjection::new(&project.camera, rect);
    let light = project
        .lights
        .iter()
        .filter_map(|l| view.project(project.light_anchor(l)).map(|(p, _)| p))
        .filter(|p| rect.shrink(20.0).contains(*p))
        .min_by(|a, b| a.distance(centre).total_cmp(&b.distance(centre)));
    match light {
        Some(light) => {
            d.h.state_mut().set_tool(Tool::Select);
            d.begin();
            d.frame(Some(Event::PointerMoved(light)))?;
            d.press(light, true)?;
            let drag = |t: f32| light + Vec2::new(t * rect.width() * 0.15, -t * rect.height() * 0.1);
            d.pointer_path(Duration::from_secs(1), 30, drag)?;
            d.press(drag(1.0), false)?;
            records.push(d.record("light_drag", quality, log)?);
        }
        None => log(&format!("interaction {scene:<8} light_drag: skipped, no light of the scene is in view")),
    }

    // Five wheel steps of Scale on a selection of particles.
    {
        let state = d.h.state_mut();
        let n = state.session().project().particles.len();
        state.session_mut().selection.clear();
        state.session_mut().selection.particles.extend(0..n.min(12));
        state.set_tool(Tool::Scale);
    }
    d.begin();
    d.frame(Some(Event::PointerMoved(viewport(&d)?.center())))?;
    for _ in 0..5 {
        let t = Instant::now();
        d.frame(Some(EditorDriver::wheel_event(40.0, Modifiers::NONE)))?;
        while t.elapsed() < Duration::from_millis(100) {
            d.frame(None)?;
        }
    }
    records.push(d.record("scale_wheel", quality, log)?);

    // An erase stroke across the painted one, over 1 s.
    d.h.state_mut().set_tool(Tool::Erase);
    let rect = viewport(&d)?;
    d.begin();
    d.frame(Some(Event::PointerMoved(across(rect, 0.0))))?;
    d.press(across(rect, 0.0), true)?;
    d.pointer_path(Duration::from_secs(1), 20, |t| across(rect, t))?;
    d.press(across(rect, 1.0), false)?;
    records.push(d.record("erase", quality, log)?);

    match playback(&mut d, quality, log)? {
        Some(record) => records.push(record),
        None => log(&format!("interaction {scene:<8} playback: skipped, the scene has no light with a position")),
    }
    Ok(records)
}

/// Frames of the playback interaction.
const PLAYBACK_FRAMES: i32 = 24;

/// Keys the first light with a position to travel across [`PLAYBACK_FRAMES`] frames and plays
/// them in "every frame" mode: the achieved frames per second of wall time, each frame
/// converged. None when the scene has no such light.
fn playback(d: &mut Recorder, quality: Quality, log: &mut dyn FnMut(&str)) -> Result<Option<Value>, BenchError> {
    use crate::editor::commands::Command;
    use crate::editor::timeline::PlayMode;
    use crate::scene::animation::{Animation, Channel, Interp, KeyValue, Object, Prop};
    let project = d.h.state().session().project().clone();
    let Some(light) = project.lights.iter().find(|l| !matches!(l.kind, crate::scene::LightKind::Directional { .. }))
    else {
        return Ok(None);
    };
    let channel = Channel(Object::Light(light.id), Prop::Position);
    let travel = project.grid.size() * glam::Vec3::new(0.3, -0.1, 0.2);
    {
        let app = d.h.state_mut();
        app.set_looping(false);
        app.set_play_mode(PlayMode::EveryFrame);
        let edit = app.session_mut().edit(crate::editor::session::NEW_STEP);
        edit.animation = Some(Animation { fps: 24.0, start: 1, end: PLAYBACK_FRAMES });
        let keyed = edit.set_key(channel, 1, KeyValue::Vec3(light.position), Interp::Linear).and_then(|_| {
            edit.set_key(channel, PLAYBACK_FRAMES, KeyValue::Vec3(light.position + travel), Interp::Linear)
        });
        keyed.map_err(|e| BenchError::Editor(format!("keying the playback's light: {e}")))?;
        app.run(Command::FirstFrame);
    }
    d.frame(None)?;
    d.settle()?;
    d.begin();
    let start = Instant::now();
    d.h.state_mut().run(Command::PlayPause);
    while d.h.state().playing() {
        if start.elapsed() > CONVERGE_LIMIT * PLAYBACK_FRAMES as u32 {
            return Err(BenchError::Editor("playback did not reach its last frame".into()));
        }
        d.frame(None)?;
    }
    let seconds = start.elapsed().as_secs_f64();
    let played = d.h.state().session().frame() - 1;
    if played != PLAYBACK_FRAMES - 1 {
        return Err(BenchError::Editor(format!("playback stopped at frame {} of {PLAYBACK_FRAMES}", played + 1)));
    }
    let fps = played as f64 / seconds;
    let f = percentiles(&d.frames);
    let breakdown = Breakdown::of(&d.frames, &d.pipeline);
    let work = playback_work(d)?;
    let work_fps = played as f64 / work.seconds;
    log(&format!(
        "interaction {:<8} playback     {:?}: {played} frames played converged in {seconds:.2} s = {fps:.2} frames/s ({} editor frames, frame ms p50 {:.0} max {:.0}); the same frames' work alone at {}×{} px: {work_fps:.2} frames/s ({:.2} s; stages inject {:.0} + propagate {:.0} + march {:.0} ms); {}",
        d.scene,
        quality,
        d.frames.len(),
        f[0],
        f[3],
        work.size[0],
        work.size[1],
        work.seconds,
        work.stage_ms[0],
        work.stage_ms[1],
        work.stage_ms[2],
        breakdown.text()
    ));
    Ok(Some(json!({
        "suite": "interaction",
        "scene": d.scene,
        "case": "playback",
        "quality": format!("{quality:?}"),
        "mode": "every frame",
        "frames_played": played,
        "seconds": seconds,
        "fps": fps,
        "frames": d.frames.len(),
        "frame_ms": {"p50": f[0], "p95": f[1], "p99": f[2], "max": f[3]},
        "breakdown_during": breakdown.json(),
        "work_alone": {
            "fps": work_fps,
            "seconds": work.seconds,
            "size": work.size,
            "stage_ms": {"inject": work.stage_ms[0], "propagate": work.stage_ms[1], "march": work.stage_ms[2]},
        },
    })))
}

/// The work of the frames playback showed, alone: wall time and stage times.
struct PlaybackWork {
    seconds: f64,
    size: [u32; 2],
    /// Inject, propagate and march, summed over the frames.
    stage_ms: [f64; 3],
}

/// Bakes the frames playback showed (2 to [`PLAYBACK_FRAMES`], after frame 1) in order to
/// convergence on a pipeline of their own at the preview's size, as playback's preview
/// does but with no editor around it: the rate playback's "every frame" mode can reach.
fn playback_work(d: &Recorder) -> Result<PlaybackWork, BenchError> {
    let app = d.h.state();
    let pipeline = app.pipeline().ok_or_else(|| BenchError::Editor("the editor has no pipeline".into()))?;
    let size = app.preview_size();
    let project = app.session().project().clone();
    let mut fresh = crate::gpu::FogPipeline::new(pipeline.context().clone());
    fresh.set_image_sampling(pipeline.image_sampling());
    let layer = crate::export::load_base_layer(&project, app.session().path())
        .map_err(|e| BenchError::Editor(format!("the base volume: {e}")))?;
    fresh.set_base_layer(layer);
    let request =
        crate::gpu::FrameRequest { width: size[0], height: size[1], ..crate::gpu::FrameRequest::for_project(&project) };
    let failed = |e: crate::gpu::GpuError| BenchError::Editor(format!("baking the playback's frames alone: {e}"));
    fresh.update(&project.at_frame(1), &request).map_err(failed)?;
    let start = Instant::now();
    let mut stage_ms = [0.0; 3];
    for frame in 2..=PLAYBACK_FRAMES {
        let t = fresh.update(&project.at_frame(frame), &request).map_err(failed)?.timings_ms;
        stage_ms = [stage_ms[0] + t.inject, stage_ms[1] + t.propagate, stage_ms[2] + t.march];
    }
    Ok(PlaybackWork { seconds: start.elapsed().as_secs_f64(), size, stage_ms })
}

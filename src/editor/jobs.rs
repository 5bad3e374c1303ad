//! Work in background threads: spawning a job, acting on its result when it comes back,
//! and the exports (grids read back from the pipeline or an image rendered at the output
//! size, written beside the target, moved onto it unless cancelled) and exact optical depths
//! for the slice views.

use super::export_choices::ExportChoices;
use super::files::FileDialogs;
use super::state::{EditorState, ExactKey, ExportJob, JobResult};
use crate::export::plan::{write_plan, ExportInputs, ExportPlan, ExportRunError, Written};
use crate::export::usd::{asset_path, write_usd_sequence, StageFrame, UsdOptions};
use crate::gpu::{FogPipeline, FrameRequest, GpuContext, GpuError, Image, Stage};
use crate::scene::Project;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU32, Ordering};
use std::sync::Arc;

/// The result of an export cancelled from the status bar.
const EXPORT_CANCELLED: &str = "cancelled";

impl EditorState {
    /// Runs `job` in a background thread, labelled in the status bar until its result is
    /// handled at the start of a frame.
    pub(super) fn spawn(&mut self, label: &str, job: impl FnOnce() -> JobResult + Send + 'static) {
        self.jobs.busy.push(label.to_owned());
        let tx = self.jobs.tx.clone();
        let ctx = self.ctx.clone();
        std::thread::spawn(move || {
            let _ = tx.send(job());
            ctx.request_repaint();
        });
    }

    /// Exports to `path` with `choices` in a background thread. The grids are read back from
    /// the preview's pipeline once its bake is complete (the export waits for it); the
    /// rendered image comes from a pipeline of its own at the project's output size.
    pub(crate) fn export_to(&mut self, choices: ExportChoices, path: PathBuf) {
        let path = match choices.destination(path) {
            Ok(p) => p,
            Err(e) => return self.error(format!("Cannot export: {e}")),
        };
        if let Some(problem) = choices.problems(self.session.project(), &path).into_iter().next() {
            return self.error(format!("Cannot export to {}: {problem}", path.display()));
        }
        if let Some(problem) = super::files::output_folder_problem(&path) {
            return self.error(format!("Cannot export to {}: {problem}", path.display()));
        }
        let plan = choices.plan(&path);
        let Some(gpu) = &self.gpu else {
            let why = self.gpu_missing.clone().unwrap_or_else(|| "the pipeline is not running".into());
            return self.error(format!("Cannot export to {}: {why}", path.display()));
        };
        if let Some((first, last)) = choices.sequence(self.session.project()) {
            let ctx = gpu.pipeline.context().clone();
            return self.export_sequence(ctx, plan, path, (first..=last).collect());
        }
        if let Some(e) = gpu.error.as_ref().filter(|_| plan.needs_volumes()) {
            let text =
                format!("Cannot export to {}: the preview's bake failed, so there are no volumes: {e}", path.display());
            return self.error(text);
        }
        if plan.needs_volumes() && gpu.refining() {
            // The volumes are still being baked: export once they are complete.
            if self.jobs.pending_export.is_none() {
                self.info(format!("Exporting {} once the bake completes…", path.display()));
            }
            self.jobs.pending_export = Some((choices, path));
            self.ctx.request_repaint();
            return;
        }
        let project = self.session.frame_still();
        let time = self
            .session
            .project()
            .animation
            .map(|a| crate::export::sequence::FrameTime { frame: self.session.frame(), fps: a.fps });
        // The bake reads the preview's converged volumes: its request is the preview's, so
        // nothing is recomputed.
        let baked = plan.settings.bake_light.zip(self.gpu.as_mut()).map(|(phase, g)| {
            let size = g.converged.map_or([project.render.width, project.render.height], |k| k.size);
            let request =
                FrameRequest { width: size[0], height: size[1], scheme: project.propagation.scheme, force: false };
            g.pipeline.bake_emission(&project, &request, phase)
        });
        let emission = match baked.transpose() {
            Ok(e) => e,
            Err(e) => return self.error(format!("Export to {} failed baking the lighting: {e}", path.display())),
        };
        if emission.is_some() && project.medium.albedo == 0.0 {
            self.info("The medium's albedo is 0: the fog scatters no light, so the baked lighting is 0");
        }
        let Some(gpu) = &self.gpu else { return };
        let volumes = if plan.needs_volumes() {
            let read = gpu.pipeline.read_ev().and_then(|ev| {
                let opvs =
                    (0..project.lights.len()).map(|i| gpu.pipeline.read_opv(i)).collect::<Result<Vec<_>, _>>()?;
                Ok((ev, opvs))
            });
            match read {
                Ok(v) => Some(v),
                Err(e) => {
                    return self.error(format!("Export to {} failed reading the volumes back: {e}", path.display()))
                }
            }
        } else {
            None
        };
        let render =
            plan.needs_image().then(|| (gpu.pipeline.context().clone(), self.session.path().map(Path::to_owned)));
        let job = ExportJob {
            path: path.clone(),
            fraction: Arc::new(AtomicU32::new(0)),
            cancel: Arc::new(AtomicBool::new(false)),
            frame: Arc::default(),
        };
        let (fraction, cancel) = (job.fraction.clone(), job.cancel.clone());
        self.jobs.export_job = Some(job);
        self.spawn(&format!("Exporting {}", path.display()), move || {
            let set = |f: f32| fraction.store(f.to_bits(), Ordering::Relaxed);
            let cancelled = || cancel.load(Ordering::Relaxed);
            // Rendering takes this share of the bar, writing the rest.
            let rendering = if render.is_some() { 0.9 } else { 0.0 };
            let image = match render {
                Some((ctx, project_path)) => {
                    match render_output(ctx, &project, project_path.as_deref(), &mut |f| set(f * rendering), &cancelled)
                    {
                        Ok(image) => Some(image),
                        Err(e) => return JobResult::Exported { path, result: Err(e) },
                    }
                }
                None => None,
            };
            let inputs = ExportInputs {
                project: &project,
                volumes: volumes.as_ref().map(|(ev, opvs)| (ev, opvs.as_slice())),
                image: image.as_ref(),
                emission: emission.as_ref(),
                render_size: [project.render.width, project.render.height],
                time,
            };
            // Written beside the target and moved onto it only if not cancelled meanwhile.
            let mut staged = crate::export::Staged::default();
            let result = write_plan(
                &plan,
                &inputs,
                &mut staged,
                &mut |p| set(rendering + (1.0 - rendering) * p.overall),
                &cancelled,
            );
            let result = match result {
                Ok(_) if cancelled() => Err(EXPORT_CANCELLED.to_string()),
                Ok(written) => staged.commit().map(|_| summary(&written)).map_err(|e| e.to_string()),
                Err(ExportRunError::Cancelled) => Err(EXPORT_CANCELLED.to_string()),
                Err(ExportRunError::Failed(e)) => Err(e),
            };
            set(1.0);
            JobResult::Exported { path, result }
        });
    }

    /// Exports `frames` of the animated project in a background thread, each frame's
    /// `at_frame` baked to convergence on a pipeline of its own (the preview keeps its own)
    /// and written to the files of `plan` with the frame's number in place of the pattern,
    /// as `fogsmith export --frames` does; a USD stage is written last, with a time sample
    /// per frame. Each frame's files replace their targets once all of them are written, so
    /// cancelling leaves every completed frame complete and nothing of the frame under way.
    fn export_sequence(&mut self, ctx: GpuContext, plan: ExportPlan, path: PathBuf, frames: Vec<i32>) {
        let project = self.session.project().clone();
        let project_path = self.session.path().map(Path::to_owned);
        let plans = super::export_choices::sequence_plans(&plan, &frames);
        let job = ExportJob {
            path: path.clone(),
            fraction: Arc::new(AtomicU32::new(0)),
            cancel: Arc::new(AtomicBool::new(false)),
            frame: Arc::default(),
        };
        let (fraction, cancel, note) = (job.fraction.clone(), job.cancel.clone(), job.frame.clone());
        self.jobs.export_job = Some(job);
        self.spawn(&format!("Exporting {}", path.display()), move || {
            let set = |f: f32| fraction.store(f.to_bits(), Ordering::Relaxed);
            let cancelled = || cancel.load(Ordering::Relaxed);
            let mut done = 0;
            let result = bake_sequence(
                ctx,
                &project,
                project_path.as_deref(),
                (&plan, &plans, &frames),
                &mut |k, f| {
                    done = k;
                    if let Ok(mut n) = note.lock() {
                        *n = format!("frame {} ({} of {})", frames[k], k + 1, frames.len());
                    }
                    set((k as f32 + f) / frames.len() as f32);
                },
                &cancelled,
            );
            set(1.0);
            let result = match result {
                Err(e) if e == EXPORT_CANCELLED => Err(format!(
                    "{EXPORT_CANCELLED} after {done} of {} frames; the files of those frames are complete",
                    frames.len()
                )),
                other => other,
            };
            JobResult::Exported { path, result }
        });
    }

    pub(super) fn finish_job(&mut self, result: JobResult) {
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
                    Err(e) if e.starts_with(EXPORT_CANCELLED) => self.info(format!("Export {e}")),
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
                self.finish_load();
                self.replace_project(*project, Some(path.clone()), "");
                self.info(format!("Opened {}", path.display()));
                self.push_recent(path);
            }
            JobResult::Loaded { path, result: Err(e) } => {
                self.finish_load();
                self.recent.retain(|p| p != &path);
                self.error(format!("Could not open the project: {e}"));
            }
            JobResult::Restored { file, original, result: Ok(project) } => {
                self.finish_load();
                self.replace_project(*project, original, "recovered.ron");
                self.session.mark_unsaved();
                if let Err(e) = crate::scene::recovery::remove_recovery(&file) {
                    self.error(e.to_string());
                }
            }
            JobResult::Restored { file, result: Err(e), .. } => {
                self.finish_load();
                self.error(format!("Could not restore the unsaved work: {e}; {} is kept", file.display()));
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
        let project = self.session.frame_still();
        let path = self.session.path().map(Path::to_owned);
        self.spawn("Computing the exact optical depth", move || JobResult::Exact {
            key,
            result: crate::export::load_base_layer(&project, path.as_deref())
                .map_err(|e| format!("The base volume cannot be loaded for the exact reference: {e}"))
                .and_then(|layer| super::slices::exact_optical_depth(&project, layer.as_ref(), key.light, &cells)),
        });
    }
}

/// Renders `project` to convergence at its output size on a pipeline of its own (the preview's
/// renders at the viewport's size), as `fogsmith render` does; `progress` hears the fraction
/// done and `cancelled` stops it at the next work item.
fn render_output(
    ctx: GpuContext,
    project: &Project,
    project_path: Option<&Path>,
    progress: &mut dyn FnMut(f32),
    cancelled: &dyn Fn() -> bool,
) -> Result<Image, String> {
    let request = FrameRequest::for_project(project);
    let mut pipeline = FogPipeline::new(ctx);
    pipeline.check_limits(project, request.width, request.height).map_err(|e| format!("Cannot render: {e}"))?;
    let layer = crate::export::load_base_layer(project, project_path)
        .map_err(|e| format!("The base volume cannot be loaded for the render: {e}"))?;
    pipeline.set_base_layer(layer);
    let result = pipeline.update_with(project, &request, std::time::Duration::from_millis(50), &mut |p| {
        let (start, share) = match p.stage {
            Stage::Inject => (0.0, 0.15),
            Stage::Propagate { .. } => (0.15, 0.45),
            Stage::Scatter => (0.6, 0.1),
            Stage::March => (0.7, 0.3),
            Stage::Done => (1.0, 0.0),
        };
        progress(start + share * p.stage_fraction as f32);
        !cancelled()
    });
    match result {
        Err(GpuError::Cancelled) => Err(EXPORT_CANCELLED.to_string()),
        Err(e) => Err(format!("The render failed: {e}")),
        Ok(_) => pipeline.read_image().map_err(|e| format!("The render could not be read back: {e}")),
    }
}

/// Bakes and writes each frame of a sequence (see `export_sequence`): `plans` are the
/// frames' plans, `plan` the whole export's (its stage); `progress` hears the frame's index
/// and the fraction of it done. Returns what was written, or why not.
fn bake_sequence(
    ctx: GpuContext,
    project: &Project,
    project_path: Option<&Path>,
    (plan, plans, frames): (&ExportPlan, &[ExportPlan], &[i32]),
    progress: &mut dyn FnMut(usize, f32),
    cancelled: &dyn Fn() -> bool,
) -> Result<String, String> {
    let request = FrameRequest::for_project(project);
    let mut pipeline = FogPipeline::new(ctx);
    let layer = crate::export::load_base_layer(project, project_path)
        .map_err(|e| format!("The base volume cannot be loaded for the bake: {e}"))?;
    pipeline.set_base_layer(layer);
    let fps = project.animation.map_or(24.0, |a| a.fps);
    let mut stage_frames = Vec::new();
    let mut fields = Vec::new();
    let mut last = None;
    for (k, (&frame, frame_plan)) in frames.iter().zip(plans).enumerate() {
        progress(k, 0.0);
        let still = project.at_frame(frame);
        pipeline
            .check_limits(&still, request.width, request.height)
            .map_err(|e| format!("Cannot bake frame {frame}: {e}"))?;
        let baked = pipeline.update_with(&still, &request, std::time::Duration::from_millis(50), &mut |p| {
            let share = match p.stage {
                Stage::Inject => 0.1 * p.stage_fraction as f32,
                Stage::Propagate { .. } => 0.1 + 0.5 * p.stage_fraction as f32,
                Stage::Scatter => 0.6 + 0.1 * p.stage_fraction as f32,
                Stage::March => 0.7 + 0.1 * p.stage_fraction as f32,
                Stage::Done => 0.8,
            };
            progress(k, share);
            !cancelled()
        });
        match baked {
            Err(GpuError::Cancelled) => return Err(EXPORT_CANCELLED.to_string()),
            Err(e) => return Err(format!("Baking frame {frame} failed: {e}")),
            Ok(_) => {}
        }
        let read = |e: GpuError| format!("Frame {frame}'s volumes could not be read back: {e}");
        let ev = pipeline.read_ev().map_err(read)?;
        let opvs =
            (0..still.lights.len()).map(|i| pipeline.read_opv(i)).collect::<Result<Vec<_>, _>>().map_err(read)?;
        let image = frame_plan.needs_image().then(|| pipeline.read_image()).transpose().map_err(read)?;
        let emission = plan
            .settings
            .bake_light
            .map(|phase| pipeline.bake_emission(&still, &request, phase))
            .transpose()
            .map_err(|e| format!("Baking frame {frame}'s lighting failed: {e}"))?;
        let inputs = ExportInputs {
            project: &still,
            volumes: Some((&ev, &opvs)),
            image: image.as_ref(),
            emission: emission.as_ref(),
            render_size: [request.width, request.height],
            time: Some(crate::export::sequence::FrameTime { frame, fps }),
        };
        let mut staged = crate::export::Staged::default();
        let written = match write_plan(
            frame_plan,
            &inputs,
            &mut staged,
            &mut |p| progress(k, 0.8 + 0.2 * p.overall),
            cancelled,
        ) {
            Ok(_) if cancelled() => return Err(EXPORT_CANCELLED.to_string()),
            Ok(w) => w,
            Err(ExportRunError::Cancelled) => return Err(EXPORT_CANCELLED.to_string()),
            Err(ExportRunError::Failed(e)) => return Err(e),
        };
        staged.commit().map_err(|e| format!("Frame {frame}: {e}"))?;
        if let Some((vdb, _, _)) = &written.vdb {
            stage_frames.push((frame, vdb.clone(), still));
        }
        fields = written.vdb_fields.clone();
        last = Some(written);
    }
    let mut text = format!("{} frames", frames.len());
    if let Some(w) = &last {
        text.push_str(&format!(" ({} each)", summary(w)));
    }
    if let Some(usd) = &plan.usd {
        let opts = UsdOptions {
            vdb_asset: String::new(),
            fields,
            frame: plan.settings.frame,
            width: request.width,
            height: request.height,
        };
        let stage: Vec<StageFrame> = stage_frames
            .iter()
            .map(|(frame, vdb, still)| StageFrame { frame: *frame, project: still, vdb_asset: asset_path(usd, vdb) })
            .collect();
        let mut staged = crate::export::Staged::default();
        staged.write(usd, |p| write_usd_sequence(p, &stage, fps, &opts)).map_err(|e| e.to_string())?;
        staged.commit().map_err(|e| e.to_string())?;
        text.push_str(&format!(
            "; a stage with a time sample per frame of {}",
            stage.first().map_or(String::new(), |f| f.vdb_asset.clone())
        ));
    }
    Ok(text)
}

/// What an export wrote, for the message that says it is done.
fn summary(w: &Written) -> String {
    let mut parts = Vec::new();
    for (_, stats, _) in w.vdb.iter().chain(&w.nvdb) {
        parts.push(format!("{} grids, {} bytes", stats.grids.len(), stats.bytes));
    }
    if let Some(usd) = &w.usd {
        parts.push(format!("a stage with the volume from {} and {} lights", usd.vdb_asset, usd.lights));
    }
    if let Some((_, info, snippet)) = &w.ktx2 {
        parts.push(format!(
            "{} bytes, texel × {} = extinction 1/m, and {}",
            info.bytes,
            info.scale,
            snippet.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default()
        ));
    }
    for (_, [width, height]) in w.png_render.iter().chain(&w.exr_render) {
        parts.push(format!("{width}×{height} pixels"));
    }
    if let Some((_, quantities)) = &w.exr_slices {
        parts.push(format!("{quantities} volumes"));
    }
    if let Some((_, layout)) = &w.exr_atlas {
        parts.push(layout.to_string());
    }
    parts.join("; ")
}

fn capitalized(s: &str) -> String {
    let mut c = s.chars();
    c.next().map(|f| f.to_uppercase().chain(c).collect()).unwrap_or_default()
}

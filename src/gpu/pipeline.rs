//! [`FogPipeline`]: the scheduler. It decides which work a change of the project requires and
//! runs it on the [`Stages`] as a queue of small work items within a time budget.
//!
//! [`advance`](FogPipeline::advance) runs items until its budget is spent: dirty bricks of the
//! injection, batches of propagation dispatches, bands of rows of the march. With a bounded
//! budget, a changed scene is first shown by a quick, lower-resolution march that reads the
//! optical depths the GPU has (possibly stale); propagation and the full-resolution march then
//! catch up over the following calls, and the full image replaces the quick one only once it
//! is complete. [`update`](FogPipeline::update) runs the same items to completion.
//!
//! Each call translates the project once ([`FrameInputs`]), compares the stages' keys with
//! what the GPU holds ([`Baked`]) and runs the stages in order. The stage objects and the
//! scene's GPU resources live in `stages`, the bake in `baking`, limit checks in `limits`, the
//! budget arithmetic in `budget` and the measurement switches in `tuning`.

use super::baking::BakePhase;
use super::binning;
use super::budget::{ms, Clock, Rate, QUICK_OF_FULL, QUICK_SHARE};
use super::error::ErrorScope;
use super::frame_inputs::{FrameInputs, FrameRequest, Settings};
use super::image_sampling::ImageSampling;
use super::inject::{InjectJob, Injector};
use super::inject_options::{HostCounts, InjectOptions};
use super::keys::{Baked, BakedEv, ImageKey, Level, OpvKey, Region, ScatterKey};
use super::limits::Capacity;
use super::march::{MarchJob, BAND_ROWS};
use super::opv_store::OpvLayout;
use super::outputs::Image;
use super::propagate::PropagationJob;
use super::report::{Counters, FrameReport, Progress, Stage};
use super::scattering::ScatterJob;
use super::slice::{Plane, SliceSource};
use super::stages::{Reallocated, Stages};
use super::timer::{self, StageTimer};
use super::tuning::{InjectPath, Tuning};
use super::{GpuContext, GpuError};
use crate::scene::{GridSpec, Project, Scheme, Volume, Volume3};
use std::time::{Duration, Instant};

/// Work in progress, dropped whenever its inputs change.
#[derive(Default)]
struct Jobs {
    inject: Option<(InjectJob, Region)>,
    propagate: Option<(PropagationJob, Vec<(usize, OpvKey)>)>,
    march: Option<(MarchJob, ImageKey)>,
    scatter: Option<(ScatterJob, ScatterKey)>,
}

/// A stage a call left unfinished when its budget ran out, and the fraction of it done.
type Unfinished = Option<(Stage, f64)>;

/// The GPU fog pipeline: injection → propagation → ray march, plus readback.
pub struct FogPipeline {
    ctx: GpuContext,
    stages: Stages,
    timer: Option<StageTimer>,
    tuning: Tuning,
    baked: Baked,
    jobs: Jobs,
    rates: [Rate; 3],
    last_report: FrameReport,
    /// Bin edge of the last injection's particle lists (see `binning`).
    bin_size: u32,
    volumes_generation: u64,
    image_sampling: ImageSampling,
}

impl FogPipeline {
    pub fn new(ctx: GpuContext) -> Self {
        let layout = OpvLayout::for_limits(&ctx.limits);
        Self::with_opv_layout(ctx, layout)
    }

    /// A pipeline whose optical-depth arrays are stored as `opv_layout` says; [`new`](Self::new)
    /// packs as many lights into a texture as the device allows. Fewer let tests cross
    /// texture boundaries.
    pub fn with_opv_layout(ctx: GpuContext, opv_layout: OpvLayout) -> Self {
        let tuning = Tuning::default();
        let stages = Stages::new(&ctx, opv_layout, tuning.sweep_cells(ctx.adapter_info.device_type));
        let timer = StageTimer::new(&ctx);
        Self {
            ctx,
            stages,
            timer,
            tuning,
            baked: Baked::default(),
            jobs: Jobs::default(),
            // Pessimistic starting costs (software adapters); corrected after the first items.
            rates: [Rate::new(1e-4), Rate::new(1e-3), Rate::new(3e-3)],
            last_report: FrameReport::default(),
            bin_size: binning::BRICK,
            volumes_generation: 0,
            image_sampling: ImageSampling::default(),
        }
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    /// A counter bumped whenever the extinction volume or an optical-depth volume on the GPU
    /// changes, for views that read them back.
    pub fn volumes_generation(&self) -> u64 {
        self.volumes_generation
    }

    /// The report of the last [`update`](Self::update) or [`advance`](Self::advance).
    pub fn last_report(&self) -> FrameReport {
        self.last_report
    }

    /// Refuses, before allocating anything, a scene larger than the adapter allows: grid edge
    /// (3D texture), OPVs (texture bindings, see `opv_store`), particles and lights (one
    /// storage binding each), the image (2D texture and its readback buffer), and the GPU
    /// memory all of it needs together where the device's memory is known.
    pub fn check_limits(&self, project: &Project, width: u32, height: u32) -> Result<(), GpuError> {
        self.capacity().check_limits(project, width, height)
    }

    /// Peak GPU memory, in bytes, of the resources a scene of this size needs: EV, brick
    /// maxima, the OPV array, its scratch twin and the march's lookup array, injection lists
    /// of one chunk and the
    /// particles, both image targets and the image readback.
    pub fn memory_needed(&self, grid: &GridSpec, lights: usize, particles: usize, width: u32, height: u32) -> u64 {
        self.capacity().memory_needed(grid, lights, particles, width, height)
    }

    /// The largest grid, of the same proportions as `grid`, whose scene passes
    /// [`check_limits`](Self::check_limits); None when even a 1-cell edge does not.
    pub fn largest_fitting_grid(
        &self,
        grid: &GridSpec,
        lights: usize,
        particles: usize,
        width: u32,
        height: u32,
    ) -> Option<glam::UVec3> {
        self.capacity().largest_fitting_grid(grid, lights, particles, width, height)
    }

    /// [`check_limits`](Self::check_limits) for a scene described by its sizes alone.
    pub fn check_sizes(
        &self,
        grid: &GridSpec,
        light_count: usize,
        particle_count: usize,
        width: u32,
        height: u32,
    ) -> Result<(), GpuError> {
        self.capacity().check_sizes(grid, light_count, particle_count, width, height)
    }

    fn capacity(&self) -> Capacity<'_> {
        Capacity {
            ctx: &self.ctx,
            opv_layout: self.stages.opv_layout(),
            chunk_bytes: self.inject_chunk_bytes(),
            base_layer: self.stages.base_layer(),
        }
    }

    /// Brings the GPU state up to date with `project` and renders the frame at full
    /// resolution, running every work item the changes since the last call require.
    pub fn update(&mut self, project: &Project, request: &FrameRequest) -> Result<FrameReport, GpuError> {
        let progress = self.advance(project, request, None)?;
        debug_assert!(progress.converged());
        Ok(progress.report)
    }

    /// Like [`update`](Self::update), in slices of at most `slice` between which
    /// `on_progress` sees how far the work is and may stop it (return false): the update then
    /// ends with [`GpuError::Cancelled`] at the next work item.
    pub fn update_with(
        &mut self,
        project: &Project,
        request: &FrameRequest,
        slice: Duration,
        on_progress: &mut dyn FnMut(&Progress) -> bool,
    ) -> Result<FrameReport, GpuError> {
        let mut total: Option<FrameReport> = None;
        let mut request = *request;
        loop {
            let progress = self.run(project, &request, Clock::slice(slice), false)?;
            // Forced once, then continued.
            request.force = false;
            match &mut total {
                None => total = Some(progress.report),
                Some(t) => *t += progress.report,
            }
            if progress.converged() {
                // A quick preview may have been shown on the way; the result is the full frame.
                let report = total.unwrap_or_default();
                self.last_report = report;
                return Ok(report);
            }
            if !on_progress(&progress) {
                return Err(GpuError::Cancelled);
            }
        }
    }

    /// Runs work items for `project` until `budget` is spent (None: until converged) and
    /// says what is on show and what is left. Call it again, with the same or a newer
    /// project, to continue: work whose inputs changed is dropped and replanned. At least
    /// one item runs per call, and one item is never planned larger than the budget left
    /// (down to a single brick chunk, dispatch or band of rows).
    pub fn advance(
        &mut self,
        project: &Project,
        request: &FrameRequest,
        budget: Option<Duration>,
    ) -> Result<Progress, GpuError> {
        self.run(project, request, Clock::start(budget), true)
    }

    /// [`advance`](Self::advance) without quick previews: the image on show changes only
    /// when the full-resolution image is complete (for showing each frame of an animation
    /// converged, where a quick image would be marched only to be replaced).
    pub fn advance_full_only(
        &mut self,
        project: &Project,
        request: &FrameRequest,
        budget: Option<Duration>,
    ) -> Result<Progress, GpuError> {
        self.run(project, request, Clock::start(budget), false)
    }

    /// [`advance`](Self::advance), with or without quick previews.
    fn run(
        &mut self,
        project: &Project,
        request: &FrameRequest,
        clock: Clock,
        previews: bool,
    ) -> Result<Progress, GpuError> {
        self.capacity().check_request(project, request)?;
        let mut inputs = FrameInputs::new(project, request, &self.settings(project));
        let scope = ErrorScope::push(&self.ctx.device);
        let result = self.run_items(project, &mut inputs, clock, previews);
        scope.pop("update")?;
        let mut progress = result?;
        progress.report.gpu_timestamps = self.timer.is_some();
        self.last_report = progress.report;
        Ok(progress)
    }

    /// The pipeline's settings that enter [`FrameInputs`].
    fn settings(&self, project: &Project) -> Settings {
        Settings {
            layer_on_grid: self.stages.base_layer().is_some_and(|v| v.grid == project.grid),
            layer_generation: self.stages.layer_generation(),
            brute_force: self.tuning.brute_force_injection,
            bin_size: self.bin_size,
        }
    }

    /// Runs the stages in order until one is left unfinished, and says what is on show.
    fn run_items(
        &mut self,
        project: &Project,
        inputs: &mut FrameInputs,
        clock: Clock,
        previews: bool,
    ) -> Result<Progress, GpuError> {
        let mut progress = Progress::default();
        if inputs.request.force {
            self.baked = Baked::default();
            self.jobs = Jobs::default();
        }
        self.ensure_grid(project.grid, inputs.light_count());
        self.stages.upload_scene(&self.ctx.queue, inputs);
        if let Some((stage, fraction)) = self.run_stages(project, inputs, clock, previews, &mut progress)? {
            progress.stage = stage;
            progress.stage_fraction = fraction;
        }
        Ok(self.finish(progress, inputs))
    }

    /// Injection, a quick preview when the full image cannot be ready within this call,
    /// propagation, and the full-resolution march.
    fn run_stages(
        &mut self,
        project: &Project,
        inputs: &mut FrameInputs,
        clock: Clock,
        previews: bool,
        progress: &mut Progress,
    ) -> Result<Unfinished, GpuError> {
        if let Some(unfinished) = self.inject_stage(project, inputs, clock, progress)? {
            return Ok(Some(unfinished));
        }
        // Propagation targets: lights whose OPV lags their position or the EV.
        let targets = self.opv_targets(inputs, &mut progress.report.counters);
        if self.jobs.propagate.as_ref().is_some_and(|(_, keys)| *keys != targets) {
            self.jobs.propagate = None;
        }
        if previews && clock.bounded() {
            self.preview_stage(inputs, clock, !targets.is_empty(), progress)?;
        }
        if let Some(unfinished) = self.propagate_stage(project, inputs, targets, clock, progress)? {
            return Ok(Some(unfinished));
        }
        if let Some(unfinished) = self.scatter_stage(inputs, clock, progress)? {
            return Ok(Some(unfinished));
        }
        self.march_stage(inputs, clock, progress)
    }

    /// What a march now would read: the EV, OPVs and multiple-scattering solve on the GPU.
    fn image_key(&self, inputs: &FrameInputs) -> ImageKey {
        let mut key = inputs.image_key(self.baked.ev_generation, &self.baked.opvs);
        if inputs.multiple_scattering.is_some() {
            key.scatter = self.baked.scatter.as_ref().map_or(0, |(_, generation)| *generation);
        }
        key
    }

    /// The multiple-scattering solve, once the OPVs it reads are up to date, when its inputs
    /// changed: a step (the first scattering, one order, the moments) per item. The march reads
    /// the last finished solve until the new one is done.
    fn scatter_stage(
        &mut self,
        inputs: &FrameInputs,
        clock: Clock,
        progress: &mut Progress,
    ) -> Result<Unfinished, GpuError> {
        let (Some(settings), Some(key)) =
            (inputs.multiple_scattering, inputs.scatter_key(self.baked.ev_generation, &self.baked.opvs))
        else {
            self.jobs.scatter = None;
            return Ok(None);
        };
        if self.baked.scatter.as_ref().is_some_and(|(k, _)| *k == key) {
            return Ok(None);
        }
        if self.jobs.scatter.as_ref().is_some_and(|(_, k)| *k != key) {
            self.jobs.scatter = None;
        }
        if self.jobs.scatter.is_none() {
            let job = self.stages.begin_scatter(&self.ctx, inputs, settings)?;
            self.stages.note_memory();
            self.jobs.scatter = Some((job, key));
        }
        while let Some((job, _)) = self.jobs.scatter.as_mut() {
            let t = Instant::now();
            self.stages.scatter_step(&self.ctx, job)?;
            progress.report.timings_ms.scatter += ms(t);
            progress.report.counters.dispatches += 3;
            if let Some((_, key)) = self.jobs.scatter.take_if(|(job, _)| job.done()) {
                self.baked.scatter_generation += 1;
                self.baked.scatter = Some((key, self.baked.scatter_generation));
            } else if let Some((job, _)) = self.jobs.scatter.as_ref().filter(|_| clock.spent()) {
                return Ok(Some((Stage::Scatter, job.fraction())));
            }
        }
        Ok(None)
    }

    /// Injection, by chunks of dirty bricks: every preview frame shows the current extinction
    /// volume. Planning (finding dirty bricks, ordering and counting particles) is the
    /// stage's host work.
    fn inject_stage(
        &mut self,
        project: &Project,
        inputs: &mut FrameInputs,
        clock: Clock,
        progress: &mut Progress,
    ) -> Result<Unfinished, GpuError> {
        let planning = Instant::now();
        self.plan_inject(project, inputs);
        progress.report.timings_ms.inject += ms(planning);
        while self.jobs.inject.is_some() {
            let t = Instant::now();
            let units = self.inject_item(clock.left_ms(t), &mut progress.report.counters)?;
            progress.report.timings_ms.inject += self.item_ms(timer::INJECT, t, units)?;
            if let Some((_, region)) = self.jobs.inject.take_if(|(job, _)| job.done()) {
                self.baked.record_injection(region);
                self.volumes_generation += 1;
            } else if let Some((job, _)) = self.jobs.inject.as_ref().filter(|_| clock.spent()) {
                return Ok(Some((Stage::Inject, job.fraction())));
            }
        }
        Ok(None)
    }

    /// A quick look at the change, with the optical depths the GPU has, when lights are to
    /// be propagated or the full march does not fit the time left. Its resolution never
    /// steps down while the scene stays the same (only optical depths progressing), and
    /// steps up, to at least twice the pixels, when a call has the time for it, until the
    /// full image is half marched. It costs at most [`QUICK_OF_FULL`] of the full march left.
    fn preview_stage(
        &mut self,
        inputs: &FrameInputs,
        clock: Clock,
        propagating: bool,
        progress: &mut Progress,
    ) -> Result<(), GpuError> {
        let key = self.image_key(inputs);
        let (width, height) = (inputs.request.width, inputs.request.height);
        let shown_quick = match &self.baked.shown {
            Some((k, Level::Quick)) if k.same_scene(&key) => {
                self.stages.target(Level::Quick).map(|t| (t.width, t.height))
            }
            _ => None,
        };
        let t = Instant::now();
        let rate = &self.rates[timer::MARCH as usize];
        let full_ms = rate.ms_for(width as u64 * height as u64);
        // The share of this scene's full march still to do.
        let full_left = match &self.jobs.march {
            Some((job, k)) if *k == key => 1.0 - job.fraction(),
            _ => 1.0,
        };
        let budget = clock.left_ms(t).map(|ms| (ms * QUICK_SHARE).min(QUICK_OF_FULL * full_left * full_ms));
        let (w, h) = rate.quick_size(width, height, budget);
        let march = if self.baked.shown.as_ref().is_some_and(|(k, _)| *k == key) {
            // A step up, but not once the full image is more than half marched: it is close
            // to replacing the quick one.
            let nearly_full = full_left < 0.5;
            shown_quick.is_some_and(|(w0, h0)| !nearly_full && w as u64 * h as u64 >= 2 * (w0 as u64 * h0 as u64))
        } else {
            let fits = clock.left_ms(t).is_some_and(|ms| full_ms <= ms);
            propagating || !fits
        };
        if march {
            let (w, h) = shown_quick.map_or((w, h), |(fw, fh)| (w.max(fw), h.max(fh)));
            self.quick_march(w, h, key, &mut progress.report.counters)?;
            progress.report.timings_ms.march += ms(t);
            progress.new_image = true;
        }
        Ok(())
    }

    /// Propagation of the `targets`' optical depths, in batches of dispatches.
    fn propagate_stage(
        &mut self,
        project: &Project,
        inputs: &FrameInputs,
        targets: Vec<(usize, OpvKey)>,
        clock: Clock,
        progress: &mut Progress,
    ) -> Result<Unfinished, GpuError> {
        if targets.is_empty() {
            return Ok(None);
        }
        if self.jobs.propagate.is_none() {
            let analytic = inputs.request.scheme == Scheme::Analytic;
            let lists = if analytic { Some(self.capacity().analytic_lists(project)?) } else { None };
            self.plan_propagation(project, inputs, targets, lists.as_ref());
            self.stages.note_memory();
        }
        while self.jobs.propagate.is_some() {
            let t = Instant::now();
            let units = self.propagate_item(clock.left_ms(t), &mut progress.report.counters);
            progress.report.timings_ms.propagate += self.item_ms(timer::PROPAGATE, t, units)?;
            if let Some((_, keys)) = self.jobs.propagate.take_if(|(job, _)| job.done()) {
                self.stages.propagated(keys.iter().map(|&(i, _)| i));
                for (i, k) in keys {
                    self.baked.opvs[i] = Some(k);
                }
                self.volumes_generation += 1;
            } else if let Some((job, _)) = self.jobs.propagate.as_ref().filter(|_| clock.spent()) {
                return Ok(Some((Stage::Propagate { lights: job.lights.len() as u32 }, job.fraction())));
            }
        }
        Ok(None)
    }

    /// The full-resolution march, in bands of rows, shown once complete.
    fn march_stage(
        &mut self,
        inputs: &FrameInputs,
        clock: Clock,
        progress: &mut Progress,
    ) -> Result<Unfinished, GpuError> {
        let key = self.image_key(inputs);
        if self.baked.shown.as_ref().is_some_and(|(k, level)| *level == Level::Full && *k == key) {
            return Ok(None);
        }
        if self.jobs.march.as_ref().is_some_and(|(_, k)| *k != key) {
            self.jobs.march = None;
        }
        if self.jobs.march.is_none() {
            let (width, height) = (inputs.request.width, inputs.request.height);
            self.stages.ensure_target(&self.ctx, Level::Full, width, height);
            let job = self.stages.begin_march(&self.ctx, Level::Full, &key, &self.tuning, self.image_sampling)?;
            self.jobs.march = Some((job, key));
        }
        while self.jobs.march.is_some() {
            let t = Instant::now();
            let units = self.march_item(clock.left_ms(t), clock.whole_rows, &mut progress.report.counters)?;
            progress.report.timings_ms.march += self.item_ms(timer::MARCH, t, units)?;
            if let Some((_, key)) = self.jobs.march.take_if(|(job, _)| job.done()) {
                self.stages.read_march_counters(&self.ctx, &mut progress.report.counters)?;
                self.baked.shown = Some((key, Level::Full));
                progress.new_image = true;
            } else if let Some((job, _)) = self.jobs.march.as_ref().filter(|_| clock.spent()) {
                return Ok(Some((Stage::March, job.fraction())));
            }
        }
        Ok(None)
    }

    /// Fills in what is on show.
    fn finish(&self, mut progress: Progress, inputs: &FrameInputs) -> Progress {
        self.stages.note_memory();
        if let Some((key, level)) = &self.baked.shown {
            progress.shown_size = self.stages.target(*level).map_or([0, 0], |t| [t.width, t.height]);
            progress.shows_scene = progress.stage != Stage::Inject && key.same_scene(&self.image_key(inputs));
            // A propagated light whose OPV on show differs from what the scene needs now.
            progress.shadows_stale = (0..inputs.light_count()).any(|i| {
                inputs
                    .opv_key(i, self.baked.ev_generation)
                    .is_some_and(|k| key.opvs.get(i).copied().flatten() != Some(k))
            });
        }
        progress
    }

    /// Wall (or GPU) time of a finished item; feeds the stage's rate.
    fn item_ms(&mut self, stage: u32, started: Instant, units: u64) -> Result<f64, GpuError> {
        let wall = ms(started);
        self.rates[stage as usize].observe(units, wall);
        match &self.timer {
            Some(t) => t.read_ms(&self.ctx, stage),
            None => Ok(wall),
        }
    }

    /// Starts (or extends) the injection of what changed since the EV on the GPU. An edit
    /// costs one walk along the particle lists plus what it touched ([`binning::Change`]):
    /// its dirty bricks and the host path's counts come from the change alone, and the EV's
    /// particles are copied from the first one that differs.
    fn plan_inject(&mut self, project: &Project, inputs: &mut FrameInputs) {
        let key = &inputs.ev;
        let grid = &project.grid;
        let inject = InjectOptions::of(&self.tuning);
        let host = inject.host_possible(&self.ctx);
        let mut bricks: Vec<u32> = match &mut self.baked.ev {
            Some(ev) if ev.key == *key => {
                let (old, new) = (&ev.particles, &project.particles);
                let same = old.iter().zip(new).take_while(|(a, b)| a == b).count();
                if same == old.len() && same == new.len() {
                    return;
                }
                let change = binning::Change::between(&old[same..], &new[same..]);
                let bricks = change.dirty_bricks(grid);
                match &mut ev.host {
                    Some(counts) => counts.update(grid, &change),
                    None if host => ev.host = Some(HostCounts::new(grid, &project.particles)),
                    None => {}
                }
                ev.particles.truncate(same);
                ev.particles.extend_from_slice(&project.particles[same..]);
                bricks
            }
            _ => {
                self.baked.ev = Some(BakedEv {
                    key: key.clone(),
                    particles: project.particles.clone(),
                    host: host.then(|| HostCounts::new(grid, &project.particles)),
                });
                let dims = binning::brick_dims(grid);
                (0..dims.x * dims.y * dims.z).collect()
            }
        };
        if bricks.is_empty() && self.jobs.inject.is_none() {
            // Only names or other fields the EV does not read changed.
            return;
        }
        let mut region = Region::of_bricks(&project.grid, &bricks);
        // Bricks an unfinished injection has not reached yet still need doing; those it did
        // hold its particles, which the new dirty bricks were computed against.
        if let Some((job, pending)) = self.jobs.inject.take() {
            region = region.union(pending);
            bricks.extend_from_slice(&job.bricks[job.next..]);
            bricks.sort_unstable();
            bricks.dedup();
        }
        let counts = self.baked.ev.as_ref().and_then(|ev| ev.host.as_ref());
        let (job, bin_size) = inject.begin(&self.ctx, project, key.noise.is_some(), bricks, counts);
        if let Some(bin_size) = bin_size.filter(|&b| b != self.bin_size) {
            self.bin_size = bin_size;
            inputs.grid.bin_size = bin_size;
            self.stages.upload_scene(&self.ctx.queue, inputs);
        }
        self.jobs.inject = Some((job, region));
    }

    /// Runs one chunk of the injection sized to `left_ms`; returns its cost units.
    fn inject_item(&mut self, left_ms: Option<f64>, counters: &mut Counters) -> Result<u64, GpuError> {
        let (Some(spec), Some((job, _))) = (self.stages.grid_spec(), self.jobs.inject.as_mut()) else { return Ok(0) };
        let rate = self.rates[timer::INJECT as usize];
        let budget_units = rate.units_in(left_ms);
        let mut count = Injector::min_bricks(&self.ctx, job, &spec);
        while job.next + count < job.bricks.len() && Injector::units(job, &spec, count * 2) <= budget_units {
            count *= 2;
        }
        if left_ms.is_none() {
            count = job.bricks.len().max(1);
        }
        let units = Injector::units(job, &spec, count);
        let (ctx, stages) = (&self.ctx, &mut self.stages);
        timer::submit(ctx, self.timer.as_ref(), timer::INJECT, |encoder, stamps| {
            stages.encode_inject(ctx, encoder, job, count, stamps, counters)
        });
        self.ctx.wait()?;
        Ok(units)
    }

    /// Lights whose OPV must be (re)propagated, with the inputs it will have; counts the rest.
    fn opv_targets(&mut self, inputs: &FrameInputs, counters: &mut Counters) -> Vec<(usize, OpvKey)> {
        self.baked.opvs.resize(inputs.light_count(), None);
        let mut targets = Vec::new();
        for i in 0..inputs.light_count() {
            match inputs.opv_key(i, self.baked.ev_generation) {
                None => {
                    counters.lights_skipped += 1;
                    counters.lights_culled += inputs.culled[i] as u32;
                }
                Some(k) if self.baked.opvs[i] == Some(k) => counters.lights_skipped += 1,
                Some(k) => targets.push((i, k)),
            }
        }
        targets
    }

    fn plan_propagation(
        &mut self,
        project: &Project,
        frame: &FrameInputs,
        targets: Vec<(usize, OpvKey)>,
        analytic_lists: Option<&binning::ChunkBins>,
    ) {
        let active: Vec<u32> = targets.iter().map(|&(i, _)| i as u32).collect();
        let changed: Vec<Option<(glam::UVec3, glam::UVec3)>> =
            targets.iter().map(|&(i, k)| self.baked.changed_since(i, k)).collect();
        let job = self.stages.plan_propagation(&self.ctx, &project.particles, frame, &active, &changed, analytic_lists);
        if let Some(job) = job {
            self.jobs.propagate = Some((job, targets));
        }
    }

    /// Runs the next batch of propagation dispatches sized to `left_ms`; returns its cells.
    fn propagate_item(&mut self, left_ms: Option<f64>, counters: &mut Counters) -> u64 {
        let Some((job, targets)) = self.jobs.propagate.as_mut() else { return 0 };
        let count = job.fitting(self.rates[timer::PROPAGATE as usize].units_in(left_ms));
        let units = job.units(count);
        let stages = &mut self.stages;
        timer::submit(&self.ctx, self.timer.as_ref(), timer::PROPAGATE, |encoder, stamps| {
            stages.encode_propagation(encoder, job, count, stamps, counters, targets.iter().map(|&(i, _)| i))
        });
        // A lost device surfaces as an error of the next readback or update.
        let _ = self.ctx.wait();
        units
    }

    /// Marches the next band of the full image sized to `left_ms` (at least a row of
    /// workgroups with `whole_rows`); returns its pixels.
    fn march_item(&mut self, left_ms: Option<f64>, whole_rows: bool, counters: &mut Counters) -> Result<u64, GpuError> {
        let (Some((job, _)), Some(target)) = (self.jobs.march.as_mut(), self.stages.target(Level::Full)) else {
            // Without its target a march cannot go on: drop it.
            self.jobs.march = None;
            return Ok(0);
        };
        let mut pixels = self.rates[timer::MARCH as usize].units_in(left_ms);
        if whole_rows {
            pixels = pixels.max(target.width as u64 * BAND_ROWS as u64);
        }
        let (ctx, stages) = (&self.ctx, &self.stages);
        let covered = timer::submit(ctx, self.timer.as_ref(), timer::MARCH, |encoder, stamps| {
            stages.encode_march(ctx, Level::Full, encoder, job, pixels, stamps)
        });
        self.ctx.wait()?;
        counters.dispatches += 1;
        if let Some(e) = self.jobs.march.as_mut().and_then(|(job, _)| job.take_error()) {
            self.jobs.march = None;
            return Err(e);
        }
        Ok(covered.unwrap_or(0))
    }

    /// Marches the whole image at `w`×`h`, a reduced size (see `preview_stage`), and shows it.
    fn quick_march(&mut self, w: u32, h: u32, key: ImageKey, counters: &mut Counters) -> Result<(), GpuError> {
        self.stages.ensure_target(&self.ctx, Level::Quick, w, h);
        let t = Instant::now();
        let mut job = self.stages.begin_march(&self.ctx, Level::Quick, &key, &self.tuning, self.image_sampling)?;
        let (ctx, stages) = (&self.ctx, &self.stages);
        let mut rays = 0;
        while !job.done() {
            rays += timer::submit(ctx, None, timer::MARCH, |encoder, _| {
                stages.encode_march(ctx, Level::Quick, encoder, &mut job, u64::MAX, None)
            })
            .unwrap_or_else(|| {
                job.abandon();
                0
            });
            self.ctx.wait()?;
            counters.dispatches += 1;
            if let Some(e) = job.take_error() {
                return Err(e);
            }
        }
        self.rates[timer::MARCH as usize].observe(rays.max(1), ms(t));
        self.stages.read_march_counters(&self.ctx, counters)?;
        self.baked.shown = Some((key, Level::Quick));
        Ok(())
    }

    /// Allocates the grid's resources on the stages, and drops the work and records that
    /// the reallocation invalidates.
    fn ensure_grid(&mut self, spec: GridSpec, light_count: usize) {
        match self.stages.ensure_grid(&self.ctx, spec, light_count) {
            Reallocated::Nothing => {}
            Reallocated::Lights { count, stages } => {
                if stages {
                    self.jobs = Jobs::default();
                }
                self.baked.opvs.truncate(count);
                // In-flight work binds the old buffers.
                self.jobs.propagate = None;
                self.jobs.march = None;
            }
            Reallocated::Grid => {
                self.baked = Baked::default();
                self.jobs = Jobs::default();
            }
        }
    }

    /// How the stages run (see [`Tuning`]); the `set_*` methods below change it.
    pub fn tuning(&self) -> &Tuning {
        &self.tuning
    }

    /// Caps the particle–bin lists of one injection chunk at `bytes` (None: one storage
    /// binding, the most a chunk can use). Smaller chunks bound memory more tightly at the
    /// cost of more passes; the EV is the same bit for bit.
    pub fn set_inject_chunk_bytes(&mut self, bytes: Option<u64>) {
        self.tuning.inject_chunk_bytes = bytes;
    }

    /// The particle–bin list bytes one injection chunk may use.
    pub fn inject_chunk_bytes(&self) -> u64 {
        InjectOptions::of(&self.tuning).chunk_bytes(&self.ctx)
    }

    /// How the march chooses its rays (default: adaptive). A change marches the image again.
    pub fn set_image_sampling(&mut self, sampling: ImageSampling) {
        if sampling != self.image_sampling {
            self.image_sampling = sampling;
            self.jobs.march = None;
            self.baked.shown = None;
        }
    }

    pub fn image_sampling(&self) -> ImageSampling {
        self.image_sampling
    }

    /// [`Tuning::general_march`]: the image is the same.
    pub fn set_general_march(&mut self, on: bool) {
        self.tuning.general_march = on;
    }

    /// [`Tuning::exhaustive_fog_shadows`]: the image is the same.
    pub fn set_exhaustive_fog_shadows(&mut self, on: bool) {
        self.tuning.exhaustive_fog_shadows = on;
    }

    /// [`Tuning::brute_force_injection`].
    pub fn set_brute_force_injection(&mut self, on: bool) {
        self.tuning.brute_force_injection = on;
    }

    /// Makes each sweep thread solve `cells` cells (at least one) instead of the adapter's
    /// default (`sweep_cells_per_thread`), so that a CPU adapter can run the one-cell-per-thread
    /// configuration a GPU uses. The optical depths are the same bit for bit; those on the GPU
    /// are propagated again.
    pub fn set_sweep_cells_per_thread(&mut self, cells: u32) {
        let cells = cells.max(1);
        self.tuning.sweep_cells_per_thread = Some(cells);
        if self.stages.set_sweep_cells(&self.ctx, cells) {
            self.jobs = Jobs::default();
            self.baked.opvs.iter_mut().for_each(|k| *k = None);
        }
    }

    /// Where the injection sums the particles (see [`InjectPath`]).
    pub fn set_inject_path(&mut self, path: InjectPath) {
        if path != self.tuning.inject_path {
            self.tuning.inject_path = path;
            self.baked.ev = None;
        }
    }

    /// Whether injecting `project` sums its particles on the host. `Auto` does on a CPU
    /// adapter (unless brute force or a fixed bin edge asks for the gather) when the particles
    /// reach at least [`HOST_MIN_ENTRIES_PER_BRICK`](super::HOST_MIN_ENTRIES_PER_BRICK) bricks
    /// per brick of the grid.
    pub fn inject_on_host(&self, project: &Project) -> bool {
        InjectOptions::of(&self.tuning).on_host(&self.ctx, project)
    }

    /// Bins the injection by this edge across (1, 2, 4 or 8 cells) instead of the one with
    /// the fewest evaluations: tests and benchmarks compare the edges. `None` chooses again.
    pub fn set_inject_bin_edge(&mut self, edge: Option<u32>) -> Result<(), GpuError> {
        if let Some(e) = edge.filter(|e| !binning::BIN_EDGES.contains(e)) {
            return Err(GpuError::Invalid(format!(
                "injection bin edge {e}: must be one of {:?} cells",
                binning::BIN_EDGES
            )));
        }
        self.tuning.inject_bin_edge = edge;
        self.baked.ev = None;
        Ok(())
    }

    /// Sets (or clears) a density layer added to every cell of the EV under the particles,
    /// such as a VDB grid resampled into the project's grid. It must match the grid of the
    /// projects passed to [`update`](Self::update).
    pub fn set_base_layer(&mut self, layer: Option<Volume>) {
        self.stages.set_base_layer(&self.ctx, layer);
    }

    /// The radiance each cell emits, W·m⁻³·sr⁻¹ per channel (physics.md §10), baked from the
    /// EV and OPVs of `project` after bringing them up to date as [`update`](Self::update)
    /// does: the preview's own volumes and light rules, plus the surfaces' shadows.
    pub fn bake_emission(
        &mut self,
        project: &Project,
        request: &FrameRequest,
        phase: BakePhase,
    ) -> Result<Volume3, GpuError> {
        let frame = self.update_for_bake(project, request)?;
        self.stages.bake(&self.ctx, &frame, phase)
    }

    /// The emission–absorption render of the bake of `project` at the request's size (see
    /// [`bake_emission`](Self::bake_emission)): the baked density and emission with no
    /// lights, as an engine shows them. Read it with [`read_as_baked`](Self::read_as_baked)
    /// or show it through [`as_baked_view`](Self::as_baked_view).
    pub fn render_as_baked(
        &mut self,
        project: &Project,
        request: &FrameRequest,
        phase: BakePhase,
    ) -> Result<(), GpuError> {
        let frame = self.update_for_bake(project, request)?;
        self.stages.render_as_baked(&self.ctx, &frame, phase)
    }

    /// Brings the volumes up to date for a bake of `project`, and its frame's inputs.
    fn update_for_bake(&mut self, project: &Project, request: &FrameRequest) -> Result<FrameInputs, GpuError> {
        if !project.lights.iter().any(|l| !l.hidden) {
            return Err(GpuError::Invalid(
                "nothing to bake: the project has no visible light; add a light or unhide one".into(),
            ));
        }
        self.update(project, request)?;
        Ok(FrameInputs::new(project, request, &self.settings(project)))
    }

    /// The last [`render_as_baked`](Self::render_as_baked) image as linear HDR radiance.
    pub fn read_as_baked(&self) -> Result<Image, GpuError> {
        self.stages.baking().read(&self.ctx)
    }

    /// The last "as baked" image, tone-mapped (rgba8unorm), and its size, for the editor.
    pub fn as_baked_view(&self) -> Option<(&wgpu::TextureView, [u32; 2])> {
        self.stages.baking().view()
    }

    /// The extinction volume σ_t at cell centres.
    /// The scattered power of each order of the last multiple-scattering solve (the first
    /// scattering first, then `orders` swept orders), W per channel mean, for tests of the
    /// solver's convergence.
    pub fn scatter_powers(&self, orders: u32) -> Result<Vec<f32>, GpuError> {
        self.stages.scatter_powers(&self.ctx, orders)
    }

    pub fn read_ev(&self) -> Result<Volume, GpuError> {
        self.stages.read_ev(&self.ctx)
    }

    /// Optical depth T towards light `light` at cell centres.
    pub fn read_opv(&self, light: usize) -> Result<Volume, GpuError> {
        self.stages.read_opv(&self.ctx, light)
    }

    /// Plane `index` across grid `axis` (0, 1, 2 for x, y, z) of the EV or of one light's
    /// OPV, gathered on the GPU so that only the plane is read back.
    pub fn read_slice(&mut self, source: SliceSource, axis: usize, index: u32) -> Result<Plane, GpuError> {
        self.stages.read_slice(&self.ctx, source, axis, index)
    }

    /// The level of the image on show.
    fn shown_level(&self) -> Option<Level> {
        self.baked.shown.as_ref().map(|(_, level)| *level)
    }

    /// The image on show as linear HDR radiance (after [`update`](Self::update): the full frame).
    pub fn read_image(&self) -> Result<Image, GpuError> {
        let level =
            self.shown_level().ok_or_else(|| GpuError::Invalid("nothing rendered yet: call update first".into()))?;
        self.stages.read_image(&self.ctx, level)
    }

    /// The tone-mapped image on show (rgba8unorm) and its size, for display by the editor
    /// without a CPU round trip. Its view changes when the preview switches resolution.
    pub fn display_view(&self) -> Option<(&wgpu::TextureView, [u32; 2])> {
        let t = self.stages.target(self.shown_level()?)?;
        Some((&t.ldr_view, [t.width, t.height]))
    }

    /// The most GPU memory [`memory_bytes`](Self::memory_bytes) has reported, sampled after
    /// each injection chunk, when propagation is planned and when a call returns.
    pub fn peak_memory_bytes(&self) -> u64 {
        self.stages.peak_memory_bytes()
    }

    /// Starts a new [`peak_memory_bytes`](Self::peak_memory_bytes) window at the memory held now.
    pub fn reset_peak_memory(&self) {
        self.stages.reset_peak_memory();
    }

    /// Bytes of GPU memory the pipeline's live resources hold.
    pub fn memory_bytes(&self) -> u64 {
        self.stages.memory_bytes()
    }
}

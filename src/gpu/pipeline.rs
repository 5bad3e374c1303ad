//! [`FogPipeline`]: the long-lived object that owns one object per stage ([`Injector`],
//! [`Propagator`], [`Marcher`]) and the scene's GPU resources, decides which work a change
//! requires, and runs it as a queue of small work items within a time budget.
//!
//! [`advance`](FogPipeline::advance) runs items until its budget is spent: dirty bricks of the
//! injection, batches of propagation dispatches, bands of rows of the march. With a bounded
//! budget, a changed scene is first shown by a quick, lower-resolution march that reads the
//! optical depths the GPU has (possibly stale); propagation and the full-resolution march then
//! catch up over the following calls, and the full image replaces the quick one only once it
//! is complete. [`update`](FogPipeline::update) runs the same items to completion.
//!
//! Each call translates the project once ([`FrameInputs`]), compares the stages' keys with
//! what the GPU holds ([`Baked`]) and runs the stages in order. Limit checks live in
//! `limits`, the budget arithmetic in `budget`, the GPU resources in `resources` and the
//! readbacks in `outputs`.

use super::as_baked::{AsBakedInputs, AsBakedRenderer};
use super::bake::{BakeInputs, BakePhase, Baker};
use super::binning;
use super::budget::{ms, Clock, Rate, QUICK_OF_FULL, QUICK_SHARE};
use super::buffers::storage_buffer;
use super::error::ErrorScope;
use super::frame_inputs::{FrameInputs, FrameRequest, Settings};
use super::gpu_types::{GridParams, LightGpu, MarchParams};
use super::inject::{InjectInputs, InjectJob, Injector};
use super::inject_options::{HostCounts, InjectOptions, InjectPath};
use super::keys::{Baked, BakedEv, ImageKey, Level, OpvKey, Region};
use super::limits::Capacity;
use super::march::{ImageTarget, MarchFeatures, MarchInputs, MarchJob, Marcher, BAND_ROWS};
use super::march_lookup::{LookupBuilder, LookupInputs};
use super::opv_store::OpvLayout;
use super::outputs::{self, Image};
use super::propagate::{sweep_cells_per_thread, PropagationInputs, PropagationJob, Propagator};
use super::report::{Counters, FrameReport, Progress, Stage};
use super::resources::GridResources;
use super::slice::{Plane, SliceSource, Slicer};
use super::timer::{self, StageTimer};
use super::{GpuContext, GpuError};
use crate::scene::{GridSpec, Project, Scheme, Volume, Volume3};
use std::time::{Duration, Instant};

/// Work in progress, dropped whenever its inputs change.
#[derive(Default)]
struct Jobs {
    inject: Option<(InjectJob, Region)>,
    propagate: Option<(PropagationJob, Vec<(usize, OpvKey)>)>,
    march: Option<(MarchJob, ImageKey)>,
}

/// A stage a call left unfinished when its budget ran out, and the fraction of it done.
type Unfinished = Option<(Stage, f64)>;

/// One light's lookup volume (`march_lookup`) against its OPV.
#[derive(Clone, Copy, Debug)]
struct LookupState {
    /// The volume may differ from what its OPV, the light and the grid parameters on the GPU
    /// give (set by every write to them, cleared by a rebuild). A lookup also reads the EV, at a
    /// light exactly on a cell centre; any EV change re-propagates every light, which marks it.
    stale: bool,
    /// The volume has been built since the OPV was allocated.
    built: bool,
    /// Propagation has written the OPV since its last propagation that completed: the OPV is
    /// then part old, part new.
    opv_partial: bool,
}

impl LookupState {
    /// A newly allocated OPV's.
    const NEW: Self = Self { stale: true, built: false, opv_partial: false };
}

/// The GPU fog pipeline: injection → propagation → ray march, plus readback.
pub struct FogPipeline {
    ctx: GpuContext,
    injector: Injector,
    propagator: Propagator,
    marcher: Marcher,
    lookup: LookupBuilder,
    /// Per light, the state of its lookup volume and OPV.
    lookups: Vec<LookupState>,
    /// The lights and grid parameters last uploaded, to tell a change from a rewrite.
    uploaded: (Vec<LightGpu>, Option<GridParams>),
    slicer: Slicer,
    /// Built on the first bake: most pipelines never bake.
    baker: Option<Baker>,
    /// Built on the first "as baked" render, with the image it last drew.
    as_baked: Option<AsBakedRenderer>,
    as_baked_image: Option<ImageTarget>,
    timer: Option<StageTimer>,
    grid: Option<GridResources>,
    quick: Option<ImageTarget>,
    full: Option<ImageTarget>,
    baked: Baked,
    jobs: Jobs,
    rates: [Rate; 3],
    last_report: FrameReport,
    /// Imported density added under the particles, and a counter bumped when it changes.
    base_layer: Option<(Volume, wgpu::Buffer)>,
    base_layer_generation: u64,
    inject: InjectOptions,
    opv_layout: OpvLayout,
    /// The OPV textures the stages' shaders were built for: only as many as the current
    /// scene's OPVs fill, since every extra texture adds a branch to each OPV read (the march
    /// reads eight per light per sample).
    stage_layout: OpvLayout,
    /// Cells each sweep thread solves (`sweep_cells_per_thread`, or the test setting).
    sweep_cells: u32,
    /// See [`FogPipeline::peak_memory_bytes`].
    peak_memory: std::sync::atomic::AtomicU64,
    /// Bin edge of the last injection's particle lists (see `binning`).
    bin_size: u32,
    volumes_generation: u64,
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
        let device = &ctx.device;
        let injector = Injector::new(device);
        let stage_layout = OpvLayout { textures: 1, ..opv_layout };
        let sweep_cells = sweep_cells_per_thread(ctx.adapter_info.device_type);
        let propagator = Propagator::new(device, stage_layout, sweep_cells);
        let marcher = Marcher::new(device, stage_layout);
        let lookup = LookupBuilder::new(device, stage_layout);
        let slicer = Slicer::new(device, stage_layout);
        let timer = StageTimer::new(&ctx);
        Self {
            ctx,
            injector,
            propagator,
            marcher,
            lookup,
            lookups: Vec::new(),
            uploaded: (Vec::new(), None),
            slicer,
            baker: None,
            as_baked: None,
            as_baked_image: None,
            timer,
            grid: None,
            quick: None,
            full: None,
            baked: Baked::default(),
            jobs: Jobs::default(),
            // Pessimistic starting costs (software adapters); corrected after the first items.
            rates: [Rate::new(1e-4), Rate::new(1e-3), Rate::new(3e-3)],
            last_report: FrameReport::default(),
            base_layer: None,
            base_layer_generation: 0,
            inject: InjectOptions::default(),
            peak_memory: Default::default(),
            opv_layout,
            stage_layout,
            sweep_cells,
            bin_size: binning::BRICK,
            volumes_generation: 0,
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
            opv_layout: self.opv_layout,
            chunk_bytes: self.inject_chunk_bytes(),
            base_layer: self.base_layer.as_ref().map(|(v, _)| v),
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
            layer_on_grid: self.base_layer.as_ref().is_some_and(|(v, _)| v.grid == project.grid),
            layer_generation: self.base_layer_generation,
            brute_force: self.inject.brute_force,
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
        self.write_scene_uniforms(inputs);
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
        self.march_stage(inputs, clock, progress)
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
        let key = inputs.image_key(self.baked.ev_generation, &self.baked.opvs);
        let (width, height) = (inputs.request.width, inputs.request.height);
        let shown_quick = match &self.baked.shown {
            Some((k, Level::Quick)) if k.same_scene(&key) => self.quick.as_ref().map(|t| (t.width, t.height)),
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
            self.note_memory();
        }
        while self.jobs.propagate.is_some() {
            let t = Instant::now();
            let units = self.propagate_item(clock.left_ms(t), &mut progress.report.counters);
            progress.report.timings_ms.propagate += self.item_ms(timer::PROPAGATE, t, units)?;
            if let Some((_, keys)) = self.jobs.propagate.take_if(|(job, _)| job.done()) {
                for (i, k) in keys {
                    self.baked.opvs[i] = Some(k);
                    if let Some(s) = self.lookups.get_mut(i) {
                        s.opv_partial = false;
                    }
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
        let key = inputs.image_key(self.baked.ev_generation, &self.baked.opvs);
        if self.baked.shown.as_ref().is_some_and(|(k, level)| *level == Level::Full && *k == key) {
            return Ok(None);
        }
        if self.jobs.march.as_ref().is_some_and(|(_, k)| *k != key) {
            self.jobs.march = None;
        }
        if self.jobs.march.is_none() {
            let (width, height) = (inputs.request.width, inputs.request.height);
            let target = match self.full.take() {
                Some(t) if t.width == width && t.height == height => t,
                _ => ImageTarget::new(&self.ctx.device, width, height),
            };
            let job = self.begin_march(&target, &key);
            self.full = Some(target);
            self.jobs.march = Some((job?, key));
        }
        while self.jobs.march.is_some() {
            let t = Instant::now();
            let units = self.march_item(clock.left_ms(t), clock.whole_rows, &mut progress.report.counters)?;
            progress.report.timings_ms.march += self.item_ms(timer::MARCH, t, units)?;
            if let Some((_, key)) = self.jobs.march.take_if(|(job, _)| job.done()) {
                self.marcher.read_counters(&self.ctx, &mut progress.report.counters)?;
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
        self.note_memory();
        if let Some((key, _)) = &self.baked.shown {
            progress.shown_size = self.shown_target().map_or([0, 0], |t| [t.width, t.height]);
            progress.shows_scene = progress.stage != Stage::Inject
                && key.same_scene(&inputs.image_key(self.baked.ev_generation, &self.baked.opvs));
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
        let host = self.inject.host_possible(&self.ctx);
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
        let (job, bin_size) = self.inject.begin(&self.ctx, project, key.noise.is_some(), bricks, counts);
        if let Some(bin_size) = bin_size.filter(|&b| b != self.bin_size) {
            self.bin_size = bin_size;
            inputs.grid.bin_size = bin_size;
            self.write_scene_uniforms(inputs);
        }
        self.jobs.inject = Some((job, region));
    }

    /// Runs one chunk of the injection sized to `left_ms`; returns its cost units.
    fn inject_item(&mut self, left_ms: Option<f64>, counters: &mut Counters) -> Result<u64, GpuError> {
        let (Some(g), Some((job, _))) = (&self.grid, self.jobs.inject.as_mut()) else { return Ok(0) };
        let rate = self.rates[timer::INJECT as usize];
        let budget_units = rate.units_in(left_ms);
        let mut count = Injector::min_bricks(&self.ctx, job, &g.spec);
        while job.next + count < job.bricks.len() && Injector::units(job, &g.spec, count * 2) <= budget_units {
            count *= 2;
        }
        if left_ms.is_none() {
            count = job.bricks.len().max(1);
        }
        let units = Injector::units(job, &g.spec, count);
        let layer = match &self.base_layer {
            Some((v, buf)) if v.grid == g.spec => Some(buf),
            _ => None,
        };
        let inputs =
            InjectInputs { grid: &g.spec, grid_buf: &g.grid_buf, ev_view: &g.ev_view, brick_max: &g.brick_max, layer };
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        let stamps = self.timer.as_ref().map(|t| t.writes(timer::INJECT));
        self.injector.encode_next(&self.ctx, &mut encoder, job, &inputs, count, stamps, counters);
        self.note_memory();
        if let Some(t) = &self.timer {
            t.resolve(&mut encoder, timer::INJECT);
        }
        self.ctx.queue.submit([encoder.finish()]);
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
        let Some(g) = &self.grid else { return };
        let inputs = PropagationInputs {
            grid: &g.spec,
            grid_buf: &g.grid_buf,
            ev_view: &g.ev_view,
            lights_buf: &g.lights_buf,
            opv: &g.opv,
            brick_max: &g.brick_max,
            positions: &frame.positions,
            directions: &frame.directions,
            sweep_stride: frame.sweep_stride,
            sweep_refine: frame.sweep_refine,
            particles: &project.particles,
            analytic_lists,
        };
        let active: Vec<u32> = targets.iter().map(|&(i, _)| i as u32).collect();
        let changed: Vec<Option<(glam::UVec3, glam::UVec3)>> =
            targets.iter().map(|&(i, k)| self.baked.changed_since(i, k)).collect();
        let job = self.propagator.plan(&self.ctx.device, &inputs, frame.request.scheme, &active, &changed);
        self.jobs.propagate = Some((job, targets));
    }

    /// Runs the next batch of propagation dispatches sized to `left_ms`; returns its cells.
    fn propagate_item(&mut self, left_ms: Option<f64>, counters: &mut Counters) -> u64 {
        let Some((job, _)) = self.jobs.propagate.as_mut() else { return 0 };
        let count = job.fitting(self.rates[timer::PROPAGATE as usize].units_in(left_ms));
        let units = job.units(count);
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        let stamps = self.timer.as_ref().map(|t| t.writes(timer::PROPAGATE));
        self.propagator.encode_next(&mut encoder, job, count, stamps, counters);
        if let Some(t) = &self.timer {
            t.resolve(&mut encoder, timer::PROPAGATE);
        }
        self.ctx.queue.submit([encoder.finish()]);
        if let Some((_, targets)) = &self.jobs.propagate {
            for &(i, _) in targets {
                if let Some(s) = self.lookups.get_mut(i) {
                    s.stale = true;
                    s.opv_partial = true;
                }
            }
        }
        // A lost device surfaces as an error of the next readback or update.
        let _ = self.ctx.wait();
        units
    }

    /// Rebuilds the lookup volumes of the lights whose OPV, light or grid parameters changed
    /// since their last build, except, once built, those whose OPV propagation has partly
    /// rewritten: a quick image marched meanwhile reads the optical depths of the last complete
    /// propagation rather than a half-written OPV (and skips the rebuild), and the full march,
    /// which waits for propagation to complete, rebuilds them.
    fn refresh_lookup(&mut self) {
        let Some(g) = self.grid.as_ref() else { return };
        self.lookups.resize(g.light_count, LookupState::NEW);
        let rebuild: Vec<bool> = self.lookups.iter().map(|s| s.stale && !(s.built && s.opv_partial)).collect();
        if !rebuild.contains(&true) {
            return;
        }
        let inputs = LookupInputs {
            spec: g.spec,
            stale: &rebuild,
            grid_buf: &g.grid_buf,
            ev_view: &g.ev_view,
            lights_buf: &g.lights_buf,
            opv: &g.opv[0],
            lookup: &g.lookup,
        };
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        self.lookup.encode(&self.ctx, &mut encoder, &inputs);
        self.ctx.queue.submit([encoder.finish()]);
        for (s, rebuilt) in self.lookups.iter_mut().zip(rebuild) {
            if rebuilt {
                s.stale = false;
                s.built = true;
            }
        }
    }

    fn begin_march(&mut self, target: &ImageTarget, key: &ImageKey) -> Result<MarchJob, GpuError> {
        self.refresh_lookup();
        let g = self.grid.as_ref().ok_or_else(nothing_baked)?;
        let inputs = MarchInputs {
            grid_buf: &g.grid_buf,
            ev_view: &g.ev_view,
            lights_buf: &g.lights_buf,
            lookup: &g.lookup,
            brick_max: &g.brick_max,
            surfaces: &key.surfaces,
            features: MarchFeatures::of(&key.lights, &key.surfaces, &key.grid),
            params: MarchParams { size: [target.width, target.height], ..key.params },
        };
        Ok(self.marcher.begin(&self.ctx, target, &inputs))
    }

    /// Marches the next band of the full image sized to `left_ms` (at least a row of
    /// workgroups with `whole_rows`); returns its pixels.
    fn march_item(&mut self, left_ms: Option<f64>, whole_rows: bool, counters: &mut Counters) -> Result<u64, GpuError> {
        let (Some((job, _)), Some(target)) = (self.jobs.march.as_mut(), self.full.as_ref()) else {
            // Without its target a march cannot go on: drop it.
            self.jobs.march = None;
            return Ok(0);
        };
        let mut pixels = self.rates[timer::MARCH as usize].units_in(left_ms);
        if whole_rows {
            pixels = pixels.max(target.width as u64 * BAND_ROWS as u64);
        }
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        let stamps = self.timer.as_ref().map(|t| t.writes(timer::MARCH));
        let covered = self.marcher.encode_band(&self.ctx, target, &mut encoder, job, pixels, stamps);
        if let Some(t) = &self.timer {
            t.resolve(&mut encoder, timer::MARCH);
        }
        self.ctx.queue.submit([encoder.finish()]);
        self.ctx.wait()?;
        counters.dispatches += 1;
        Ok(covered)
    }

    /// Marches the whole image at `w`×`h`, a reduced size (see `preview_stage`), and shows it.
    fn quick_march(&mut self, w: u32, h: u32, key: ImageKey, counters: &mut Counters) -> Result<(), GpuError> {
        let target = match self.quick.take() {
            Some(t) if t.width == w && t.height == h => t,
            _ => ImageTarget::new(&self.ctx.device, w, h),
        };
        let t = Instant::now();
        let mut job = self.begin_march(&target, &key)?;
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        self.marcher.encode_band(&self.ctx, &target, &mut encoder, &mut job, u64::MAX, None);
        self.ctx.queue.submit([encoder.finish()]);
        self.ctx.wait()?;
        self.rates[timer::MARCH as usize].observe(w as u64 * h as u64, ms(t));
        counters.dispatches += 1;
        self.marcher.read_counters(&self.ctx, counters)?;
        self.quick = Some(target);
        self.baked.shown = Some((key, Level::Quick));
        Ok(())
    }

    fn ensure_grid(&mut self, spec: GridSpec, light_count: usize) {
        if let Some(g) = &self.grid {
            if g.spec == spec && g.light_count == light_count {
                return;
            }
            if g.spec == spec {
                self.resize_lights(light_count);
                return;
            }
        }
        let layout = self.stages_for(&spec, light_count);
        self.grid = Some(GridResources::new(&self.ctx.device, spec, light_count, layout));
        self.lookups = vec![LookupState::NEW; light_count];
        self.baked = Baked::default();
        self.jobs = Jobs::default();
    }

    /// The OPV storage for `light_count` lights on `spec`: the fewest textures that hold them
    /// (at most the device's). Rebuilds the stages that read OPVs when that number changes.
    fn stages_for(&mut self, spec: &GridSpec, light_count: usize) -> OpvLayout {
        let needed =
            self.opv_layout.textures_for(spec.resolution, light_count as u64).clamp(1, self.opv_layout.textures as u64)
                as u32;
        let rows = self.opv_layout.needs_rows(spec.resolution, light_count as u64);
        if needed != self.stage_layout.textures || rows != self.stage_layout.rows {
            self.stage_layout = OpvLayout { textures: needed, rows, ..self.opv_layout };
            let device = &self.ctx.device;
            self.propagator = Propagator::new(device, self.stage_layout, self.sweep_cells);
            let (general, exhaustive) = (self.marcher.general, self.marcher.exhaustive_fog_shadows);
            self.marcher = Marcher::new(device, self.stage_layout);
            self.marcher.general = general;
            self.marcher.exhaustive_fog_shadows = exhaustive;
            self.lookup = LookupBuilder::new(device, self.stage_layout);
            self.slicer = Slicer::new(device, self.stage_layout);
            self.baker = None;
            self.as_baked = None;
            self.jobs = Jobs::default();
        }
        self.stage_layout
    }

    /// Reallocates the per-light buffers for a new light count on the same grid, keeping the
    /// OPVs of the lights that remain (by index), so adding a light propagates only that one.
    fn resize_lights(&mut self, light_count: usize) {
        let Some(spec) = self.grid.as_ref().map(|g| g.spec) else { return };
        let layout = self.stages_for(&spec, light_count);
        let Some(g) = &mut self.grid else { return };
        g.resize_lights(&self.ctx, layout, light_count);
        self.lookups = vec![LookupState::NEW; light_count];
        self.baked.opvs.truncate(light_count);
        // In-flight work binds the old buffers.
        self.jobs.propagate = None;
        self.jobs.march = None;
    }

    /// Uploads the lights (culled and hidden ones dark) and the grid parameters every stage reads.
    fn write_scene_uniforms(&mut self, inputs: &FrameInputs) {
        if let Some(g) = &self.grid {
            g.write_uniforms(&self.ctx.queue, &inputs.lights, &inputs.grid);
            let (lights, grid) = &mut self.uploaded;
            self.lookups.resize(inputs.lights.len(), LookupState::NEW);
            let same_grid = grid.is_some_and(|g| bytemuck::bytes_of(&g) == bytemuck::bytes_of(&inputs.grid));
            for (i, l) in inputs.lights.iter().enumerate() {
                if !same_grid || lights.get(i).is_none_or(|old| bytemuck::bytes_of(old) != bytemuck::bytes_of(l)) {
                    self.lookups[i].stale = true;
                }
            }
            *lights = inputs.lights.clone();
            *grid = Some(inputs.grid);
        }
    }

    /// Caps the particle–bin lists of one injection chunk at `bytes` (None: one storage
    /// binding, the most a chunk can use). Smaller chunks bound memory more tightly at the
    /// cost of more passes; the EV is the same bit for bit.
    pub fn set_inject_chunk_bytes(&mut self, bytes: Option<u64>) {
        self.inject.chunk_limit = bytes;
    }

    /// The particle–bin list bytes one injection chunk may use.
    pub fn inject_chunk_bytes(&self) -> u64 {
        self.inject.chunk_bytes(&self.ctx)
    }

    /// Makes every march use the march built for every light kind and medium
    /// (`MarchFeatures::ALL`) instead of the one built for its scene, for measuring what
    /// that saves. The image is the same. Off by default; applies to marches begun after it.
    pub fn set_general_march(&mut self, on: bool) {
        self.marcher.general = on;
    }

    /// Makes base fog outside the grid test every surface for every light, instead of only
    /// those that can hide a point or spot light from the segment marched. The image is the
    /// same. Off by default; applies to marches begun after it.
    pub fn set_exhaustive_fog_shadows(&mut self, on: bool) {
        self.marcher.exhaustive_fog_shadows = on;
    }

    /// Makes every cell evaluate every particle instead of only those binned into its brick:
    /// the brute-force injection, for measuring what binning saves. Off by default.
    pub fn set_brute_force_injection(&mut self, on: bool) {
        self.inject.brute_force = on;
    }

    /// Makes each sweep thread solve `cells` cells (at least one) instead of the adapter's
    /// default (`sweep_cells_per_thread`), so that a CPU adapter can run the one-cell-per-thread
    /// configuration a GPU uses. The optical depths are the same bit for bit; those on the GPU
    /// are propagated again.
    pub fn set_sweep_cells_per_thread(&mut self, cells: u32) {
        let cells = cells.max(1);
        if cells != self.sweep_cells {
            self.sweep_cells = cells;
            self.propagator = Propagator::new(&self.ctx.device, self.stage_layout, cells);
            self.jobs = Jobs::default();
            self.baked.opvs.iter_mut().for_each(|k| *k = None);
        }
    }

    /// Where the injection sums the particles (see [`InjectPath`]).
    pub fn set_inject_path(&mut self, path: InjectPath) {
        if path != self.inject.path {
            self.inject.path = path;
            self.baked.ev = None;
        }
    }

    /// Whether injecting `project` sums its particles on the host. `Auto` does on a CPU
    /// adapter (unless brute force or a fixed bin edge asks for the gather) when the particles
    /// reach at least [`HOST_MIN_ENTRIES_PER_BRICK`](super::HOST_MIN_ENTRIES_PER_BRICK) bricks
    /// per brick of the grid.
    pub fn inject_on_host(&self, project: &Project) -> bool {
        self.inject.on_host(&self.ctx, project)
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
        self.inject.bin_edge = edge;
        self.baked.ev = None;
        Ok(())
    }

    /// Sets (or clears) a density layer added to every cell of the EV under the particles,
    /// such as a VDB grid resampled into the project's grid. It must match the grid of the
    /// projects passed to [`update`](Self::update).
    pub fn set_base_layer(&mut self, layer: Option<Volume>) {
        let binding = self.ctx.max_binding_bytes();
        self.base_layer = layer.map(|v| {
            // A layer too large to bind is not uploaded (wgpu would panic); `check_limits`
            // refuses its grid with the limit named.
            let bytes: &[u8] = bytemuck::cast_slice(&v.data);
            let buf =
                storage_buffer(&self.ctx.device, "base layer", if bytes.len() as u64 > binding { &[] } else { bytes });
            (v, buf)
        });
        self.base_layer_generation += 1;
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
        if !project.lights.iter().any(|l| !l.hidden) {
            return Err(GpuError::Invalid(
                "nothing to bake: the project has no visible light; add a light or unhide one".into(),
            ));
        }
        self.update(project, request)?;
        let frame = FrameInputs::new(project, request, &self.settings(project));
        self.refresh_lookup();
        let baker = self.baker.get_or_insert_with(|| Baker::new(&self.ctx.device, self.stage_layout));
        let g = self.grid.as_ref().ok_or_else(nothing_baked)?;
        let inputs = BakeInputs {
            spec: g.spec,
            grid_buf: &g.grid_buf,
            ev_view: &g.ev_view,
            lights_buf: &g.lights_buf,
            lookup: &g.lookup,
            surfaces: &frame.surfaces,
            params: frame.march,
        };
        let scope = ErrorScope::push(&self.ctx.device);
        let result = baker.bake(&self.ctx, &inputs, phase);
        scope.pop("bake")?;
        let emission = result?;
        let bad = emission.data.iter().flatten().filter(|v| !v.is_finite()).count();
        if bad > 0 {
            return Err(GpuError::Invalid(format!(
                "the baked emission has {bad} values that are not finite numbers; check the lights' intensities \
                 and the medium for values beyond f32's range"
            )));
        }
        Ok(emission)
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
        let emission = self.bake_emission(project, request, phase)?;
        let frame = FrameInputs::new(project, request, &self.settings(project));
        let renderer = self.as_baked.get_or_insert_with(|| AsBakedRenderer::new(&self.ctx.device, self.stage_layout));
        let target = match self.as_baked_image.take() {
            Some(t) if t.width == request.width && t.height == request.height => t,
            _ => ImageTarget::new(&self.ctx.device, request.width, request.height),
        };
        let g = self.grid.as_ref().ok_or_else(nothing_baked)?;
        let inputs = AsBakedInputs {
            grid_buf: &g.grid_buf,
            ev_view: &g.ev_view,
            emission: &emission,
            surfaces: &frame.surfaces,
            params: frame.march,
        };
        let scope = ErrorScope::push(&self.ctx.device);
        let result = renderer.render(&self.ctx, &inputs, &target);
        scope.pop("as baked render")?;
        result?;
        self.as_baked_image = Some(target);
        Ok(())
    }

    /// The last [`render_as_baked`](Self::render_as_baked) image as linear HDR radiance.
    pub fn read_as_baked(&self) -> Result<Image, GpuError> {
        let target = self
            .as_baked_image
            .as_ref()
            .ok_or_else(|| GpuError::Invalid("nothing rendered as baked yet: call render_as_baked first".into()))?;
        outputs::read_image(&self.ctx, target)
    }

    /// The last "as baked" image, tone-mapped (rgba8unorm), and its size, for the editor.
    pub fn as_baked_view(&self) -> Option<(&wgpu::TextureView, [u32; 2])> {
        self.as_baked_image.as_ref().map(|t| (&t.ldr_view, [t.width, t.height]))
    }

    fn grid(&self) -> Result<&GridResources, GpuError> {
        self.grid.as_ref().ok_or_else(nothing_baked)
    }

    /// The extinction volume σ_t at cell centres.
    pub fn read_ev(&self) -> Result<Volume, GpuError> {
        outputs::read_ev(&self.ctx, self.grid()?)
    }

    /// Optical depth T towards light `light` at cell centres.
    pub fn read_opv(&self, light: usize) -> Result<Volume, GpuError> {
        outputs::read_opv(&self.ctx, self.grid()?, light)
    }

    /// Plane `index` across grid `axis` (0, 1, 2 for x, y, z) of the EV or of one light's
    /// OPV, gathered on the GPU so that only the plane is read back.
    pub fn read_slice(&mut self, source: SliceSource, axis: usize, index: u32) -> Result<Plane, GpuError> {
        let g = self.grid.as_ref().ok_or_else(nothing_baked)?;
        outputs::read_slice(&self.ctx, &mut self.slicer, g, source, axis, index)
    }

    fn shown_target(&self) -> Option<&ImageTarget> {
        match self.baked.shown.as_ref()?.1 {
            Level::Quick => self.quick.as_ref(),
            Level::Full => self.full.as_ref(),
        }
    }

    /// The image on show as linear HDR radiance (after [`update`](Self::update): the full frame).
    pub fn read_image(&self) -> Result<Image, GpuError> {
        let img =
            self.shown_target().ok_or_else(|| GpuError::Invalid("nothing rendered yet: call update first".into()))?;
        outputs::read_image(&self.ctx, img)
    }

    /// The tone-mapped image on show (rgba8unorm) and its size, for display by the editor
    /// without a CPU round trip. Its view changes when the preview switches resolution.
    pub fn display_view(&self) -> Option<(&wgpu::TextureView, [u32; 2])> {
        self.shown_target().map(|t| (&t.ldr_view, [t.width, t.height]))
    }

    /// The most GPU memory [`memory_bytes`](Self::memory_bytes) has reported, sampled after
    /// each injection chunk, when propagation is planned and when a call returns.
    pub fn peak_memory_bytes(&self) -> u64 {
        self.peak_memory.load(std::sync::atomic::Ordering::Relaxed).max(self.memory_bytes())
    }

    /// Starts a new [`peak_memory_bytes`](Self::peak_memory_bytes) window at the memory held now.
    pub fn reset_peak_memory(&self) {
        self.peak_memory.store(self.memory_bytes(), std::sync::atomic::Ordering::Relaxed);
    }

    fn note_memory(&self) {
        self.peak_memory.fetch_max(self.memory_bytes(), std::sync::atomic::Ordering::Relaxed);
    }

    /// Bytes of GPU memory the pipeline's live resources hold.
    pub fn memory_bytes(&self) -> u64 {
        let layer = self.base_layer.as_ref().map_or(0, |(_, b)| b.size());
        self.grid.as_ref().map_or(0, GridResources::bytes)
            + self.quick.as_ref().map_or(0, ImageTarget::bytes)
            + self.full.as_ref().map_or(0, ImageTarget::bytes)
            + self.as_baked_image.as_ref().map_or(0, ImageTarget::bytes)
            + self.injector.bytes()
            + self.marcher.bytes()
            + self.slicer.bytes()
            + layer
    }
}

fn nothing_baked() -> GpuError {
    GpuError::Invalid("nothing baked yet: call update first".into())
}

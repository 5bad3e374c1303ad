//! [`Stages`]: what the scheduler runs work on. One long-lived object per stage ([`Injector`],
//! [`Propagator`], [`Marcher`], the march's [`LookupBuilder`], the [`Slicer`] and the
//! [`Baking`]), each owning its pipelines, layouts and WGSL, and the scene's GPU resources
//! (grid, per-light volumes, image targets, base layer) they read and write.
//!
//! The stages' shaders are built for an OPV layout: only as many textures as the current
//! scene's OPVs fill, since every extra texture adds a branch to each OPV read (the march reads
//! eight per light per sample). When the grid or the light count asks for another layout, the
//! stages that read OPVs are rebuilt here, and [`Reallocated`] tells the scheduler what work
//! and records that drops. The device belongs to the [`GpuContext`], passed to each call.

use super::baking::{BakePhase, Baking};
use super::buffers::storage_buffer;
use super::frame_inputs::FrameInputs;
use super::gpu_types::{GridParams, LightGpu, MarchParams};
use super::image_sampling::ImageSampling;
use super::inject::{InjectInputs, InjectJob, Injector};
use super::keys::{ImageKey, Level};
use super::march::{ImageTarget, MarchFeatures, MarchInputs, MarchJob, Marcher};
use super::march_lookup::{LookupBuilder, LookupInputs};
use super::opv_store::OpvLayout;
use super::outputs::{self, Image};
use super::propagate::{PropagationInputs, PropagationJob, Propagator};
use super::report::Counters;
use super::resources::GridResources;
use super::scattering::{ScatterJob, Scatterer};
use super::slice::{Plane, SliceSource, Slicer};
use super::tuning::Tuning;
use super::{GpuContext, GpuError};
use crate::scene::{GridSpec, Particle, Volume, Volume3};
use std::sync::atomic::{AtomicU64, Ordering};

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

/// What [`Stages::ensure_grid`] reallocated, and so what the scheduler's work and records lose.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Reallocated {
    Nothing,
    /// The per-light volumes, for `count` lights on the same grid (the OPVs of the lights that
    /// remain kept by index); `stages`: the stages were rebuilt for another OPV layout.
    Lights {
        count: usize,
        stages: bool,
    },
    /// Everything, for a new grid.
    Grid,
}

/// The stage objects and the scene's GPU resources.
pub(super) struct Stages {
    injector: Injector,
    propagator: Propagator,
    marcher: Marcher,
    lookup: LookupBuilder,
    /// Per light, the state of its lookup volume and OPV.
    lookups: Vec<LookupState>,
    /// The lights and grid parameters last uploaded, to tell a change from a rewrite.
    uploaded: (Vec<LightGpu>, Option<GridParams>),
    slicer: Slicer,
    baking: Baking,
    scatterer: Scatterer,
    grid: Option<GridResources>,
    quick: Option<ImageTarget>,
    full: Option<ImageTarget>,
    /// Imported density added under the particles, and a counter bumped when it changes.
    base_layer: Option<(Volume, wgpu::Buffer)>,
    base_layer_generation: u64,
    /// The most OPV storage the device allows.
    opv_layout: OpvLayout,
    /// The OPV textures the stages' shaders were built for.
    layout: OpvLayout,
    /// Cells each sweep thread of the propagator solves.
    sweep_cells: u32,
    /// See [`Stages::peak_memory_bytes`].
    peak_memory: AtomicU64,
}

impl Stages {
    pub fn new(ctx: &GpuContext, opv_layout: OpvLayout, sweep_cells: u32) -> Self {
        let device = &ctx.device;
        let layout = OpvLayout { textures: 1, ..opv_layout };
        Self {
            injector: Injector::new(device),
            propagator: Propagator::new(device, layout, sweep_cells),
            marcher: Marcher::new(device, layout),
            lookup: LookupBuilder::new(device, layout),
            lookups: Vec::new(),
            uploaded: (Vec::new(), None),
            slicer: Slicer::new(device, layout),
            baking: Baking::default(),
            scatterer: Scatterer::new(device),
            grid: None,
            quick: None,
            full: None,
            base_layer: None,
            base_layer_generation: 0,
            opv_layout,
            layout,
            sweep_cells,
            peak_memory: Default::default(),
        }
    }

    /// How the device allows OPVs to be stored.
    pub fn opv_layout(&self) -> OpvLayout {
        self.opv_layout
    }

    pub fn grid_spec(&self) -> Option<GridSpec> {
        self.grid.as_ref().map(|g| g.spec)
    }

    /// The base layer, if one is set.
    pub fn base_layer(&self) -> Option<&Volume> {
        self.base_layer.as_ref().map(|(v, _)| v)
    }

    /// A counter bumped whenever the base layer is set or cleared.
    pub fn layer_generation(&self) -> u64 {
        self.base_layer_generation
    }

    /// Uploads (or clears) the base layer.
    pub fn set_base_layer(&mut self, ctx: &GpuContext, layer: Option<Volume>) {
        let binding = ctx.max_binding_bytes();
        self.base_layer = layer.map(|v| {
            // A layer too large to bind is not uploaded (wgpu would panic); `check_limits`
            // refuses its grid with the limit named.
            let bytes: &[u8] = bytemuck::cast_slice(&v.data);
            let buf = storage_buffer(&ctx.device, "base layer", if bytes.len() as u64 > binding { &[] } else { bytes });
            (v, buf)
        });
        self.base_layer_generation += 1;
    }

    /// Rebuilds the propagator for `cells` cells per sweep thread; whether they changed.
    pub fn set_sweep_cells(&mut self, ctx: &GpuContext, cells: u32) -> bool {
        if cells == self.sweep_cells {
            return false;
        }
        self.sweep_cells = cells;
        self.propagator = Propagator::new(&ctx.device, self.layout, cells);
        true
    }

    /// Allocates the grid's resources for `light_count` lights, unless they are allocated.
    pub fn ensure_grid(&mut self, ctx: &GpuContext, spec: GridSpec, light_count: usize) -> Reallocated {
        if let Some(g) = &self.grid {
            if g.spec == spec && g.light_count == light_count {
                return Reallocated::Nothing;
            }
            if g.spec == spec {
                // Adding a light propagates only that one.
                let (layout, stages) = self.stages_for(ctx, &spec, light_count);
                if let Some(g) = &mut self.grid {
                    g.resize_lights(ctx, layout, light_count);
                }
                self.lookups = vec![LookupState::NEW; light_count];
                return Reallocated::Lights { count: light_count, stages };
            }
        }
        let (layout, _) = self.stages_for(ctx, &spec, light_count);
        self.grid = Some(GridResources::new(&ctx.device, spec, light_count, layout));
        self.lookups = vec![LookupState::NEW; light_count];
        Reallocated::Grid
    }

    /// The OPV storage for `light_count` lights on `spec`: the fewest textures that hold them
    /// (at most the device's), and whether the stages that read OPVs were rebuilt for it.
    fn stages_for(&mut self, ctx: &GpuContext, spec: &GridSpec, light_count: usize) -> (OpvLayout, bool) {
        let needed =
            self.opv_layout.textures_for(spec.resolution, light_count as u64).clamp(1, self.opv_layout.textures as u64)
                as u32;
        let rows = self.opv_layout.needs_rows(spec.resolution, light_count as u64);
        if needed == self.layout.textures && rows == self.layout.rows {
            return (self.layout, false);
        }
        self.layout = OpvLayout { textures: needed, rows, ..self.opv_layout };
        let device = &ctx.device;
        self.propagator = Propagator::new(device, self.layout, self.sweep_cells);
        self.marcher = Marcher::new(device, self.layout);
        self.lookup = LookupBuilder::new(device, self.layout);
        self.slicer = Slicer::new(device, self.layout);
        self.baking.rebuild();
        self.scatterer.rebuild();
        (self.layout, true)
    }

    /// Uploads the lights (culled and hidden ones dark) and the grid parameters every stage reads.
    pub fn upload_scene(&mut self, queue: &wgpu::Queue, inputs: &FrameInputs) {
        let Some(g) = &self.grid else { return };
        g.write_uniforms(queue, &inputs.lights, &inputs.grid);
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

    /// Encodes the next `count` bricks of `job` into the EV.
    pub fn encode_inject(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        job: &mut InjectJob,
        count: usize,
        stamps: Option<wgpu::ComputePassTimestampWrites>,
        counters: &mut Counters,
    ) {
        let Some(g) = &self.grid else { return };
        let layer = match &self.base_layer {
            Some((v, buf)) if v.grid == g.spec => Some(buf),
            _ => None,
        };
        let inputs =
            InjectInputs { grid: &g.spec, grid_buf: &g.grid_buf, ev_view: &g.ev_view, brick_max: &g.brick_max, layer };
        self.injector.encode_next(ctx, encoder, job, &inputs, count, stamps, counters);
        self.note_memory();
    }

    /// The propagation of the `active` lights' OPVs for `frame`, each over the cells
    /// `changed` says (None: all of them); None without a grid.
    pub fn plan_propagation(
        &self,
        ctx: &GpuContext,
        particles: &[Particle],
        frame: &FrameInputs,
        active: &[u32],
        changed: &[Option<(glam::UVec3, glam::UVec3)>],
        analytic_lists: Option<&super::binning::ChunkBins>,
    ) -> Option<PropagationJob> {
        let g = self.grid.as_ref()?;
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
            particles,
            analytic_lists,
        };
        Some(self.propagator.plan(&ctx.device, &inputs, frame.request.scheme, active, changed))
    }

    /// Encodes the next `count` dispatches of `job`, which writes the OPVs of `lights`.
    pub fn encode_propagation(
        &mut self,
        encoder: &mut wgpu::CommandEncoder,
        job: &mut PropagationJob,
        count: usize,
        stamps: Option<wgpu::ComputePassTimestampWrites>,
        counters: &mut Counters,
        lights: impl Iterator<Item = usize>,
    ) {
        self.propagator.encode_next(encoder, job, count, stamps, counters);
        for i in lights {
            if let Some(s) = self.lookups.get_mut(i) {
                s.stale = true;
                s.opv_partial = true;
            }
        }
    }

    /// The propagation of `lights`' OPVs completed.
    pub fn propagated(&mut self, lights: impl Iterator<Item = usize>) {
        for i in lights {
            if let Some(s) = self.lookups.get_mut(i) {
                s.opv_partial = false;
            }
        }
    }

    /// Rebuilds the lookup volumes of the lights whose OPV, light or grid parameters changed
    /// since their last build, except, once built, those whose OPV propagation has partly
    /// rewritten: a quick image marched meanwhile reads the optical depths of the last complete
    /// propagation rather than a half-written OPV (and skips the rebuild), and the full march,
    /// which waits for propagation to complete, rebuilds them.
    fn refresh_lookup(&mut self, ctx: &GpuContext) {
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
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        self.lookup.encode(ctx, &mut encoder, &inputs);
        ctx.queue.submit([encoder.finish()]);
        for (s, rebuilt) in self.lookups.iter_mut().zip(rebuild) {
            if rebuilt {
                s.stale = false;
                s.built = true;
            }
        }
    }

    /// The image target of `level`, if allocated.
    pub fn target(&self, level: Level) -> Option<&ImageTarget> {
        match level {
            Level::Quick => self.quick.as_ref(),
            Level::Full => self.full.as_ref(),
        }
    }

    /// Allocates the image target of `level` at `width`×`height`, unless it has that size.
    pub fn ensure_target(&mut self, ctx: &GpuContext, level: Level, width: u32, height: u32) {
        let slot = match level {
            Level::Quick => &mut self.quick,
            Level::Full => &mut self.full,
        };
        if !slot.as_ref().is_some_and(|t| t.width == width && t.height == height) {
            *slot = Some(ImageTarget::new(&ctx.device, width, height));
        }
    }

    /// Starts the march of `key` into the target of `level`, after bringing the lookup volumes
    /// up to date.
    pub fn begin_march(
        &mut self,
        ctx: &GpuContext,
        level: Level,
        key: &ImageKey,
        tuning: &Tuning,
        sampling: ImageSampling,
    ) -> Result<MarchJob, GpuError> {
        self.refresh_lookup(ctx);
        let target = match level {
            Level::Quick => self.quick.as_mut(),
            Level::Full => self.full.as_mut(),
        };
        let (Some(g), Some(target)) = (self.grid.as_ref(), target) else { return Err(nothing_baked()) };
        let inputs = MarchInputs {
            grid_buf: &g.grid_buf,
            ev_view: &g.ev_view,
            lights_buf: &g.lights_buf,
            lookup: &g.lookup,
            brick_max: &g.brick_max,
            surfaces: &key.surfaces,
            features: MarchFeatures::of(&key.lights, &key.surfaces, &key.grid, &key.params),
            general: tuning.general_march,
            exhaustive_fog_shadows: tuning.exhaustive_fog_shadows,
            params: MarchParams { size: [target.width, target.height], ..key.params },
            lights: &key.lights,
            scatter: self.scatterer.moments(),
            sampling,
        };
        Ok(self.marcher.begin(ctx, target, &inputs))
    }

    /// Encodes the next band of about `pixels` pixels of `job` into the target of `level`;
    /// returns the pixels it covers, None without the target.
    pub fn encode_march(
        &self,
        ctx: &GpuContext,
        level: Level,
        encoder: &mut wgpu::CommandEncoder,
        job: &mut MarchJob,
        pixels: u64,
        stamps: Option<wgpu::ComputePassTimestampWrites>,
    ) -> Option<u64> {
        let target = self.target(level)?;
        Some(self.marcher.encode_band(ctx, target, encoder, job, pixels, stamps))
    }

    /// Adds the last march's counters to `counters`.
    pub fn read_march_counters(&self, ctx: &GpuContext, counters: &mut Counters) -> Result<(), GpuError> {
        self.marcher.read_counters(ctx, counters)
    }

    /// The emission of the scene on the GPU, with `frame`'s surfaces and camera (see
    /// [`Baking::bake`]).
    pub fn bake(&mut self, ctx: &GpuContext, frame: &FrameInputs, phase: BakePhase) -> Result<Volume3, GpuError> {
        self.refresh_lookup(ctx);
        let g = self.grid.as_ref().ok_or_else(nothing_baked)?;
        self.baking.bake(ctx, self.layout, g, frame, phase, self.scatterer.moments())
    }

    /// [`bake`](Self::bake) and its "as baked" render at the request's size.
    pub fn render_as_baked(&mut self, ctx: &GpuContext, frame: &FrameInputs, phase: BakePhase) -> Result<(), GpuError> {
        self.refresh_lookup(ctx);
        let g = self.grid.as_ref().ok_or_else(nothing_baked)?;
        self.baking.bake_and_render(ctx, self.layout, g, frame, phase, self.scatterer.moments())
    }

    /// Starts a multiple-scattering solve for `frame` with `settings` (see [`Scatterer::begin`]).
    pub fn begin_scatter(
        &mut self,
        ctx: &GpuContext,
        frame: &FrameInputs,
        settings: crate::scene::MultipleScattering,
    ) -> Result<ScatterJob, GpuError> {
        self.refresh_lookup(ctx);
        let g = self.grid.as_ref().ok_or_else(nothing_baked)?;
        self.scatterer.begin(ctx, self.layout, g, frame, settings)
    }

    /// Runs the next step of a solve.
    pub fn scatter_step(&self, ctx: &GpuContext, job: &mut ScatterJob) -> Result<(), GpuError> {
        self.scatterer.step(ctx, job)
    }

    /// The scattered power per order of the last multiple-scattering solve.
    pub fn scatter_powers(&self, ctx: &GpuContext, orders: u32) -> Result<Vec<f32>, GpuError> {
        self.scatterer.read_powers(ctx, orders)
    }

    pub fn baking(&self) -> &Baking {
        &self.baking
    }

    fn grid(&self) -> Result<&GridResources, GpuError> {
        self.grid.as_ref().ok_or_else(nothing_baked)
    }

    pub fn read_ev(&self, ctx: &GpuContext) -> Result<Volume, GpuError> {
        outputs::read_ev(ctx, self.grid()?)
    }

    pub fn read_opv(&self, ctx: &GpuContext, light: usize) -> Result<Volume, GpuError> {
        outputs::read_opv(ctx, self.grid()?, light)
    }

    pub fn read_slice(
        &mut self,
        ctx: &GpuContext,
        source: SliceSource,
        axis: usize,
        index: u32,
    ) -> Result<Plane, GpuError> {
        let g = self.grid.as_ref().ok_or_else(nothing_baked)?;
        outputs::read_slice(ctx, &mut self.slicer, g, source, axis, index)
    }

    /// The image on show at `level`, as linear HDR radiance.
    pub fn read_image(&self, ctx: &GpuContext, level: Level) -> Result<Image, GpuError> {
        let img =
            self.target(level).ok_or_else(|| GpuError::Invalid("nothing rendered yet: call update first".into()))?;
        outputs::read_image(ctx, img)
    }

    /// The most GPU memory [`memory_bytes`](Self::memory_bytes) has reported, sampled after
    /// each injection chunk, when propagation is planned and when a call returns.
    pub fn peak_memory_bytes(&self) -> u64 {
        self.peak_memory.load(Ordering::Relaxed).max(self.memory_bytes())
    }

    /// Starts a new [`peak_memory_bytes`](Self::peak_memory_bytes) window at the memory held now.
    pub fn reset_peak_memory(&self) {
        self.peak_memory.store(self.memory_bytes(), Ordering::Relaxed);
    }

    pub fn note_memory(&self) {
        self.peak_memory.fetch_max(self.memory_bytes(), Ordering::Relaxed);
    }

    /// Bytes of GPU memory the live resources hold.
    pub fn memory_bytes(&self) -> u64 {
        let layer = self.base_layer.as_ref().map_or(0, |(_, b)| b.size());
        self.grid.as_ref().map_or(0, GridResources::bytes)
            + self.quick.as_ref().map_or(0, ImageTarget::bytes)
            + self.full.as_ref().map_or(0, ImageTarget::bytes)
            + self.baking.bytes()
            + self.scatterer.bytes()
            + self.injector.bytes()
            + self.marcher.bytes()
            + self.slicer.bytes()
            + layer
    }
}

fn nothing_baked() -> GpuError {
    GpuError::Invalid("nothing baked yet: call update first".into())
}

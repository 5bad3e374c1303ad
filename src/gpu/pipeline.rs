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

use super::binning;
use super::gpu_types::{GridParams, LightGpu, MarchParams, ParticleGpu, SurfaceGpu};
use super::inject::{InjectInputs, InjectJob, Injector};
use super::layout::{
    LIGHT_DIRECTIONAL, LIGHT_POINT, LIGHT_SPOT, POLICY_ADAPTIVE, POLICY_FIXED, POLICY_TWO_LEVEL, SURFACE_BOX,
    SURFACE_GROUND,
};
use super::march::{ImageTarget, MarchInputs, MarchJob, Marcher, BAND_ROWS};
use super::opv_store::{OpvLayout, OpvVolumes, MAX_TEXTURE_BYTES};
use super::propagate::{sweep_cells_per_thread, PropagationInputs, PropagationJob, Propagator};
use super::readback::read_texture;
use super::slice::{Plane, SliceInputs, SliceParams, SliceSource, Slicer};
use super::timer::{self, StageTimer};
use super::{GpuContext, GpuError};
use crate::scene::{GridSpec, Light, Particle, Project, Scheme, StepPolicy, Volume};
use std::time::{Duration, Instant};

/// What to render this frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameRequest {
    pub width: u32,
    pub height: u32,
    pub scheme: Scheme,
    /// Recompute every stage even if nothing changed.
    pub force: bool,
}

impl FrameRequest {
    /// The project's own render size and propagation scheme.
    pub fn for_project(project: &Project) -> Self {
        Self {
            width: project.render.width,
            height: project.render.height,
            scheme: project.propagation.scheme,
            force: false,
        }
    }
}

/// Particle–brick overlaps per brick of the grid from which `InjectPath::Auto` sums on the
/// host. Below it the host's fixed cost per brick (its sums written, uploaded and read) exceeds
/// the gather's list walk: on llvmpipe at about 8 the two paths take the same time
/// (`fogsmith bench --suite scale` measures both on its largest particle cases).
pub const HOST_MIN_ENTRIES_PER_BRICK: u64 = 8;

/// Where injection sums the particles' gaussians into each cell.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum InjectPath {
    /// The host on a software adapter (which runs on the same cores, where native loops over
    /// each particle's cells beat the shader's list walk many times over) for scenes dense
    /// in particles ([`HOST_MIN_ENTRIES_PER_BRICK`]), the adapter otherwise. Brute-force
    /// injection and a fixed bin edge measure the adapter's path, so they select it.
    #[default]
    Auto,
    /// `host_sums`: the host scatters each particle over its cells; the adapter adds the
    /// base fog, layer and noise.
    Host,
    /// `shaders/inject.wgsl`: each cell evaluates the particles binned around it.
    Adapter,
}

/// Time per stage in milliseconds: GPU timestamps on hardware adapters that have them (see
/// [`FrameReport::gpu_timestamps`]), else wall time of the stage's host work, submits and
/// drained queue.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimings {
    pub inject: f64,
    pub propagate: f64,
    pub march: f64,
}

/// What a call did. Tests read these to prove that work was skipped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Counters {
    pub dispatches: u32,
    pub cells_injected: u64,
    /// Particle–cell pairs injection evaluated (list lengths × cells of the bins it read).
    pub particle_evaluations: u64,
    /// Memory chunks whose particle–bin lists injection built and uploaded.
    pub inject_chunks: u32,
    pub cells_propagated: u64,
    pub lights_propagated: u32,
    /// Lights whose OPV was up to date, or that are hidden, dark or culled.
    pub lights_skipped: u32,
    /// Lights skipped because their contribution is provably negligible
    /// (see [`light_is_negligible`]).
    pub lights_culled: u32,
    /// Jacobi iterations (`giroud`) or dispatches (`sweep`, batches of shells of all lights).
    pub propagation_iterations: u32,
    pub samples_marched: u64,
    /// Empty 8³ bricks camera rays jumped over.
    pub bricks_skipped: u64,
    /// Rays stopped early because their transmittance fell below the cutoff.
    pub rays_terminated: u64,
}

#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct FrameReport {
    pub timings_ms: StageTimings,
    /// Whether `timings_ms` comes from GPU timestamp queries.
    pub gpu_timestamps: bool,
    pub counters: Counters,
}

/// The stage a pipeline is working on.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub enum Stage {
    Inject,
    /// Propagating `lights` lights' optical depths.
    Propagate {
        lights: u32,
    },
    /// The full-resolution march.
    March,
    /// Nothing left: the shown image is full resolution with fresh optical depths.
    #[default]
    Done,
}

impl Stage {
    /// What the pipeline is doing, in words (progress bars and the status bar).
    pub fn name(self) -> String {
        match self {
            Stage::Inject => "inject".into(),
            Stage::Propagate { lights } => format!("propagate {lights} light{}", if lights == 1 { "" } else { "s" }),
            Stage::March => "march".into(),
            Stage::Done => "done".into(),
        }
    }
}

/// What [`FogPipeline::advance`] left behind.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct Progress {
    /// What this call ran.
    pub report: FrameReport,
    /// A new image is on show since the previous call.
    pub new_image: bool,
    /// Size of the image on show (smaller than requested while the preview is refining).
    pub shown_size: [u32; 2],
    /// The image on show reads optical depths that lag the scene (moved lights, edited fog).
    pub shadows_stale: bool,
    /// The stage still to run, [`Stage::Done`] once converged.
    pub stage: Stage,
    /// Fraction of that stage done, in [0, 1].
    pub stage_fraction: f64,
}

impl Progress {
    pub fn converged(&self) -> bool {
        self.stage == Stage::Done
    }
}

/// Linear HDR radiance read back from the GPU: RGB plus alpha = 1 − transmittance.
#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<[f32; 4]>,
}

struct GridResources {
    spec: GridSpec,
    light_count: usize,
    grid_buf: wgpu::Buffer,
    ev: wgpu::Texture,
    ev_view: wgpu::TextureView,
    lights_buf: wgpu::Buffer,
    /// The OPVs and the schemes' scratch array of the same size (see `opv_store`).
    opv: [OpvVolumes; 2],
    /// Largest σ_t seen by samples in each 8³ brick, then each brick's detail (see
    /// `shaders/occupancy.wgsl`).
    brick_max: wgpu::Buffer,
}

impl GridResources {
    fn bytes(&self) -> u64 {
        self.spec.cell_count() * 4
            + self.grid_buf.size()
            + self.lights_buf.size()
            + self.opv.iter().map(OpvVolumes::bytes).sum::<u64>()
            + self.brick_max.size()
    }
}

/// What the extinction volume was injected from.
#[derive(Clone, Debug, PartialEq)]
struct EvKey {
    grid: GridSpec,
    base_extinction: f32,
    /// Height fog falloff and origin.
    height: [f32; 2],
    layer_generation: u64,
    brute_force: bool,
    /// The medium's noise, when it modulates anything (see [`noise_of`]).
    noise: Option<crate::scene::Noise>,
}

/// What a light's optical-depth volume was propagated from.
#[derive(Clone, Copy, Debug, PartialEq)]
struct OpvKey {
    position: glam::Vec3,
    ev_generation: u64,
    scheme: Scheme,
    stride: u32,
    /// The sweep's tolerance, with `sweep_refine`.
    refine: Option<f32>,
    /// A directional light, whose `position` holds its unit direction.
    sun: bool,
}

/// Everything a march reads: two marches with equal keys give identical images.
#[derive(Clone, Debug, PartialEq)]
struct ImageKey {
    params: MarchParams,
    grid: GridParams,
    lights: Vec<LightGpu>,
    surfaces: Vec<SurfaceGpu>,
    ev_generation: u64,
    opvs: Vec<Option<OpvKey>>,
}

#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Level {
    Quick,
    Full,
}

/// What the GPU holds, to decide what a new project state invalidates.
#[derive(Default)]
struct Baked {
    ev: Option<(EvKey, Vec<Particle>)>,
    ev_generation: u64,
    /// Per light: the inputs of the OPV on the GPU (None: never propagated).
    opvs: Vec<Option<OpvKey>>,
    /// The image on show.
    shown: Option<(ImageKey, Level)>,
    /// The cells each recent injection changed, by the EV generation it produced.
    ev_changes: Vec<(u64, Region)>,
}

/// Cells an injection changed: a box (inclusive cell bounds) or the whole grid.
#[derive(Clone, Copy, Debug, PartialEq)]
enum Region {
    Cells(glam::UVec3, glam::UVec3),
    All,
}

impl Region {
    fn union(self, other: Region) -> Region {
        match (self, other) {
            (Region::Cells(a0, a1), Region::Cells(b0, b1)) => Region::Cells(a0.min(b0), a1.max(b1)),
            _ => Region::All,
        }
    }

    /// The cells of `bricks`, or All when they are every brick.
    fn of_bricks(grid: &GridSpec, bricks: &[u32]) -> Region {
        let dims = binning::brick_dims(grid);
        if bricks.len() as u32 >= dims.x * dims.y * dims.z {
            return Region::All;
        }
        let mut region: Option<Region> = None;
        for &b in bricks {
            let at = glam::UVec3::new(b % dims.x, (b / dims.x) % dims.y, b / (dims.x * dims.y)) * binning::BRICK;
            let cells = Region::Cells(at, (at + binning::BRICK - 1).min(grid.resolution - 1));
            region = Some(region.map_or(cells, |r| r.union(cells)));
        }
        region.unwrap_or(Region::All)
    }
}

/// Injections remembered for partial re-propagation.
const EV_HISTORY: usize = 64;

/// Work in progress, dropped whenever its inputs change.
#[derive(Default)]
struct Jobs {
    inject: Option<(InjectJob, Region)>,
    propagate: Option<(PropagationJob, Vec<(usize, OpvKey)>)>,
    march: Option<(MarchJob, ImageKey)>,
}

/// Measured cost of one unit of a stage's work (a cell, a particle evaluation, a pixel),
/// smoothed, to size the next work item to the time left.
#[derive(Clone, Copy, Debug)]
struct Rate {
    ms_per_unit: f64,
}

impl Rate {
    fn new(ms_per_unit: f64) -> Self {
        Self { ms_per_unit }
    }
    fn observe(&mut self, units: u64, ms: f64) {
        // Small items are dominated by fixed submit costs; they would make the rate optimistic.
        if units > 0 && ms > 0.5 {
            let r = ms / units as f64;
            self.ms_per_unit = if self.ms_per_unit > 0.0 { 0.5 * (self.ms_per_unit + r) } else { r };
        }
    }
    /// Units that fit in `ms` (a bounded budget), else everything.
    fn units_in(&self, ms: Option<f64>) -> u64 {
        match ms {
            Some(ms) => (ms.max(0.0) / self.ms_per_unit.max(1e-12)) as u64,
            None => u64::MAX,
        }
    }
    fn ms_for(&self, units: u64) -> f64 {
        units as f64 * self.ms_per_unit
    }
}

/// The GPU fog pipeline: injection → propagation → ray march, plus readback.
pub struct FogPipeline {
    ctx: GpuContext,
    injector: Injector,
    propagator: Propagator,
    marcher: Marcher,
    slicer: Slicer,
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
    brute_force_injection: bool,
    inject_bin_edge: Option<u32>,
    inject_path: InjectPath,
    /// See [`FogPipeline::set_inject_chunk_bytes`].
    inject_chunk_limit: Option<u64>,
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

pub(super) fn storage_buffer(device: &wgpu::Device, label: &str, bytes: &[u8]) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    // Bindings must not be empty.
    let padded;
    let contents = if bytes.is_empty() {
        padded = [0u8; 256];
        &padded[..]
    } else {
        bytes
    };
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
    })
}

/// Share of a bounded budget the quick preview march may take.
const QUICK_SHARE: f64 = 0.4;

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
        let slicer = Slicer::new(device, stage_layout);
        let timer = StageTimer::new(&ctx);
        Self {
            ctx,
            injector,
            propagator,
            marcher,
            slicer,
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
            brute_force_injection: false,
            inject_bin_edge: None,
            inject_path: InjectPath::Auto,
            inject_chunk_limit: None,
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
        self.check_sizes(&project.grid, project.lights.len(), project.particles.len(), width, height)?;
        // The base layer is read through one storage binding (set_base_layer uploads nothing
        // larger): refused here rather than injected as empty.
        if let Some((v, _)) = &self.base_layer {
            let binding = self.ctx.max_binding_bytes();
            let bytes = v.data.len() as u64 * 4;
            if v.grid == project.grid && bytes > binding {
                let r = project.grid.resolution;
                return Err(GpuError::Limit {
                    what: format!("the base layer on a {}×{}×{} grid", r.x, r.y, r.z),
                    needed: bytes,
                    limit: binding,
                    adapter: self.ctx.adapter_info.name.clone(),
                    suggestion: "lower grid.resolution".into(),
                });
            }
        }
        Ok(())
    }

    /// Peak GPU memory, in bytes, of the resources a scene of this size needs: EV, brick
    /// maxima, the OPV array and its scratch twin, injection lists of one chunk and the
    /// particles, both image targets and the image readback.
    pub fn memory_needed(&self, grid: &GridSpec, lights: usize, particles: usize, width: u32, height: u32) -> u64 {
        let cells = grid.cell_count();
        let bricks = binning::brick_dims(grid).as_u64vec3().element_product();
        let bins = (grid.resolution / 2 + 1).as_u64vec3().element_product();
        let particle_bytes = particles as u64 * std::mem::size_of::<ParticleGpu>() as u64;
        // A chunk's lists: at most the chunk limit, and at most every particle in every bin.
        let lists = if particles == 0 {
            0
        } else {
            self.inject_chunk_bytes().min(particles as u64 * bins * 4) + bins * 4 + particle_bytes
        };
        let pixels = width as u64 * height as u64;
        cells * 4 + bricks * 8 + 2 * cells * lights.max(1) as u64 * 4 + lists + pixels * (16 + 4) * 2 + pixels * 16
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
        let edge = grid.resolution.max_element().max(1);
        let scaled = |k: u32| {
            let r = (grid.resolution.as_dvec3() * k as f64 / edge as f64).round().as_uvec3().max(glam::UVec3::ONE);
            GridSpec { resolution: r, ..*grid }
        };
        let fits = |k: u32| self.check_sizes(&scaled(k), lights, particles, width, height).is_ok();
        let (mut lo, mut hi) = (0u32, self.ctx.limits.max_texture_dimension_3d.max(edge));
        if !fits(1) {
            return None;
        }
        lo = lo.max(1);
        while hi - lo > 1 {
            let mid = lo + (hi - lo) / 2;
            if fits(mid) {
                lo = mid;
            } else {
                hi = mid;
            }
        }
        if fits(hi) {
            lo = hi;
        }
        Some(scaled(lo).resolution)
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
        let limits = &self.ctx.limits;
        let adapter = self.ctx.adapter_info.name.clone();
        let edge = grid.resolution.max_element();
        if edge > limits.max_texture_dimension_3d {
            return Err(GpuError::Limit {
                what: format!("a {}³-edge grid", edge),
                needed: edge as u64,
                limit: limits.max_texture_dimension_3d as u64,
                adapter,
                suggestion: "lower grid.resolution".into(),
            });
        }
        let r = grid.resolution;
        // The EV and each light's OPV are one 3D texture each (or share one).
        let volume = grid.cell_count() * 4;
        if volume > MAX_TEXTURE_BYTES {
            return Err(GpuError::Limit {
                what: format!("one volume of a {}×{}×{} grid ({})", r.x, r.y, r.z, human_bytes(volume)),
                needed: volume,
                limit: MAX_TEXTURE_BYTES,
                adapter: adapter.clone(),
                suggestion: "a 3D texture holds at most this much; lower grid.resolution".into(),
            });
        }
        let needed = self.memory_needed(grid, light_count, particle_count, width, height);
        if let Some(memory) = self.ctx.memory_bytes() {
            if needed > memory {
                return Err(GpuError::Limit {
                    what: format!(
                        "a {}×{}×{} grid with {light_count} lights, {particle_count} particles and a {width}×{height} image ({} of GPU memory)",
                        r.x,
                        r.y,
                        r.z,
                        human_bytes(needed)
                    ),
                    needed,
                    limit: memory,
                    adapter: adapter.clone(),
                    suggestion: format!("the device has {}; lower grid.resolution or use fewer lights", human_bytes(memory)),
                });
            }
        }
        let per_light = grid.cell_count() * 4;
        let capacity = self.opv_layout.capacity_lights(grid.resolution);
        if light_count as u64 > capacity {
            return Err(GpuError::Limit {
                what: format!("the optical-depth volumes of {light_count} lights on a {}×{}×{} grid", r.x, r.y, r.z),
                needed: per_light * light_count as u64,
                limit: per_light * capacity,
                adapter: adapter.clone(),
                suggestion: format!(
                    "the adapter gives a shader {} textures of {} lights each at this resolution; use at most {capacity} lights or lower grid.resolution",
                    self.opv_layout.textures,
                    self.opv_layout.per_texture(grid.resolution),
                ),
            });
        }
        let binding = self.ctx.max_binding_bytes();
        let particle_bytes = particle_count as u64 * std::mem::size_of::<ParticleGpu>() as u64;
        if particle_bytes > binding {
            return Err(GpuError::Limit {
                what: format!("{particle_count} particles"),
                needed: particle_bytes,
                limit: binding,
                adapter,
                suggestion: format!(
                    "use at most {} particles, e.g. by merging small ones or importing dense regions as a VDB base volume",
                    binding / std::mem::size_of::<ParticleGpu>() as u64
                ),
            });
        }
        let light_bytes = light_count as u64 * std::mem::size_of::<LightGpu>() as u64;
        if light_bytes > binding {
            return Err(GpuError::Limit {
                what: format!("{light_count} lights"),
                needed: light_bytes,
                limit: binding,
                adapter,
                suggestion: "use fewer lights".into(),
            });
        }
        let edge2d = width.max(height);
        if edge2d > limits.max_texture_dimension_2d {
            return Err(GpuError::Limit {
                what: format!("a {width}×{height} image"),
                needed: edge2d as u64,
                limit: limits.max_texture_dimension_2d as u64,
                adapter,
                suggestion: "render a smaller image".into(),
            });
        }
        let readback = width as u64 * height as u64 * 16;
        if readback > limits.max_buffer_size {
            return Err(GpuError::Limit {
                what: format!("reading back a {width}×{height} RGBA32F image"),
                needed: readback,
                limit: limits.max_buffer_size,
                adapter,
                suggestion: "render a smaller image".into(),
            });
        }
        Ok(())
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
            let progress = self.run(project, &request, Some(slice), false)?;
            // Forced once, then continued.
            request.force = false;
            let r = progress.report;
            match &mut total {
                None => total = Some(r),
                Some(t) => {
                    // Lights skipped and culled are judged by the first slice; the rest adds up.
                    t.timings_ms.inject += r.timings_ms.inject;
                    t.timings_ms.propagate += r.timings_ms.propagate;
                    t.timings_ms.march += r.timings_ms.march;
                    let (c, d) = (&mut t.counters, r.counters);
                    c.dispatches += d.dispatches;
                    c.cells_injected += d.cells_injected;
                    c.particle_evaluations += d.particle_evaluations;
                    c.inject_chunks += d.inject_chunks;
                    c.cells_propagated += d.cells_propagated;
                    c.lights_propagated += d.lights_propagated;
                    c.propagation_iterations = c.propagation_iterations.max(d.propagation_iterations);
                    c.samples_marched += d.samples_marched;
                    c.bricks_skipped += d.bricks_skipped;
                    c.rays_terminated += d.rays_terminated;
                }
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
        self.run(project, request, budget, true)
    }

    /// [`advance`](Self::advance), with or without quick previews.
    fn run(
        &mut self,
        project: &Project,
        request: &FrameRequest,
        budget: Option<Duration>,
        previews: bool,
    ) -> Result<Progress, GpuError> {
        let started = Instant::now();
        self.check_request(project, request)?;
        let scope = ErrorScope::push(&self.ctx.device);
        let result = self.run_items(project, request, budget.map(|b| started + b), previews);
        scope.pop("update")?;
        let mut progress = result?;
        progress.report.gpu_timestamps = self.timer.is_some();
        self.last_report = progress.report;
        Ok(progress)
    }

    /// Refuses an invalid project or request, or one the adapter cannot hold.
    fn check_request(&self, project: &Project, request: &FrameRequest) -> Result<(), GpuError> {
        project.validate(self.ctx.max_grid_edge()).map_err(|e| GpuError::Invalid(e.to_string()))?;
        for (name, v) in [("width", request.width), ("height", request.height)] {
            if v == 0 || v > 16384 {
                return Err(GpuError::Invalid(format!("the frame {name} must be within 1..=16384 pixels, got {v}")));
            }
        }
        self.check_limits(project, request.width, request.height)?;
        if request.scheme == Scheme::Giroud {
            // One dispatch covers every propagated light: z = ⌈nz/WORKGROUP_3D⌉ workgroups per light.
            let z =
                project.grid.resolution.z.div_ceil(super::layout::WORKGROUP_3D) as u64 * project.lights.len() as u64;
            let limit = self.ctx.limits.max_compute_workgroups_per_dimension as u64;
            if z > limit {
                return Err(GpuError::Limit {
                    what: format!(
                        "the giroud scheme with {} lights on a grid {} cells deep",
                        project.lights.len(),
                        project.grid.resolution.z
                    ),
                    needed: z,
                    limit,
                    adapter: self.ctx.adapter_info.name.clone(),
                    suggestion: "use the sweep scheme, fewer lights or a lower grid.resolution.z".into(),
                });
            }
        }
        if let Some((v, _)) = &self.base_layer {
            if v.grid != project.grid {
                return Err(GpuError::Invalid(
                    "the base layer was resampled for another grid; load it again for this grid".into(),
                ));
            }
        }
        // The analytic scheme integrates particles and fog in closed form: it refuses what
        // only the grid holds.
        if request.scheme == Scheme::Analytic {
            if let Some(what) =
                analytic_unsupported(project).or(self.base_layer.as_ref().map(|_| "an imported base volume"))
            {
                return Err(GpuError::Invalid(format!(
                    "the analytic scheme integrates particles and fog in closed form and cannot represent {what}, which only the \
                     grid holds; choose the sweep or exact scheme (propagation.scheme), or remove {what}"
                )));
            }
        }
        Ok(())
    }

    /// The `analytic` scheme's particle lists, one per brick, built when a propagation is
    /// planned (counting them visits every particle); refuses lists longer than a storage
    /// binding.
    fn analytic_lists(&self, project: &Project) -> Result<binning::ChunkBins, GpuError> {
        let counts = binning::BinCounts::new(&project.grid, &project.particles, binning::BRICK, false);
        let bytes = counts.entries() * 4;
        let limit = self.ctx.max_binding_bytes();
        if bytes > limit {
            return Err(GpuError::Limit {
                what: "the analytic scheme's particle lists".into(),
                needed: bytes,
                limit,
                adapter: self.ctx.adapter_info.name.clone(),
                suggestion: "use the sweep scheme, or fewer or smaller particles".into(),
            });
        }
        let bricks: Vec<u32> = (0..binning::brick_dims(&project.grid).element_product()).collect();
        Ok(counts.fill(&project.grid, &project.particles, &bricks))
    }

    fn run_items(
        &mut self,
        project: &Project,
        request: &FrameRequest,
        deadline: Option<Instant>,
        previews: bool,
    ) -> Result<Progress, GpuError> {
        let left = |now: Instant| deadline.map(|d| d.saturating_duration_since(now).as_secs_f64() * 1e3);
        let mut progress = Progress::default();
        if request.force {
            self.baked = Baked::default();
            self.jobs = Jobs::default();
        }
        self.ensure_grid(project);
        self.write_scene_uniforms(project);

        // 1. Injection: every preview frame shows the current extinction volume. Planning
        // (finding dirty bricks, ordering and counting particles) is the stage's host work.
        let planning = Instant::now();
        self.plan_inject(project);
        progress.report.timings_ms.inject += planning.elapsed().as_secs_f64() * 1e3;
        while self.jobs.inject.is_some() {
            let t = Instant::now();
            let units = self.inject_item(project, left(t), &mut progress.report.counters)?;
            progress.report.timings_ms.inject += self.item_ms(timer::INJECT, t, units)?;
            if self.jobs.inject.as_ref().is_some_and(|(job, _)| job.done()) {
                let (_, region) = self.jobs.inject.take().expect("a finished injection");
                self.baked.ev_generation += 1;
                self.baked.ev_changes.push((self.baked.ev_generation, region));
                if self.baked.ev_changes.len() > EV_HISTORY {
                    self.baked.ev_changes.remove(0);
                }
                self.volumes_generation += 1;
            } else if left(Instant::now()).is_some_and(|ms| ms <= 0.0) {
                progress.stage = Stage::Inject;
                progress.stage_fraction = self.jobs.inject.as_ref().map_or(0.0, |(job, _)| job.fraction());
                return Ok(self.finish(progress, project, request));
            }
        }

        // 2. Propagation targets: lights whose OPV lags their position or the EV.
        let targets = self.opv_targets(project, request.scheme, &mut progress.report.counters);
        if self.jobs.propagate.as_ref().is_some_and(|(_, keys)| *keys != targets) {
            self.jobs.propagate = None;
        }

        // 3. A quick look at the change, with the optical depths the GPU has, when the full
        //    image cannot be ready within this call.
        let key = self.image_key(project, request.width, request.height);
        let shown_current = self.baked.shown.as_ref().is_some_and(|(k, _)| *k == key);
        if !shown_current && deadline.is_some() && previews {
            let full_ms = self.rates[timer::MARCH as usize].ms_for(request.width as u64 * request.height as u64);
            let fits = left(Instant::now()).is_some_and(|ms| full_ms <= ms);
            if !targets.is_empty() || !fits {
                let t = Instant::now();
                let budget = left(t).map(|ms| ms * QUICK_SHARE);
                self.quick_march(request, key.clone(), budget, &mut progress.report.counters)?;
                progress.report.timings_ms.march += ms(t);
                progress.new_image = true;
            }
        }

        // 4. Propagation, in batches of dispatches.
        if !targets.is_empty() {
            if self.jobs.propagate.is_none() {
                let lists = if request.scheme == Scheme::Analytic { Some(self.analytic_lists(project)?) } else { None };
                self.plan_propagation(project, request.scheme, targets, lists.as_ref());
                self.note_memory();
            }
            loop {
                let t = Instant::now();
                let units = self.propagate_item(left(t), &mut progress.report.counters);
                progress.report.timings_ms.propagate += self.item_ms(timer::PROPAGATE, t, units)?;
                let (job, keys) = self.jobs.propagate.as_ref().expect("a planned job");
                if job.done() {
                    for &(i, k) in keys {
                        self.baked.opvs[i] = Some(k);
                    }
                    self.jobs.propagate = None;
                    self.volumes_generation += 1;
                    break;
                }
                if left(Instant::now()).is_some_and(|ms| ms <= 0.0) {
                    progress.stage = Stage::Propagate { lights: job.lights.len() as u32 };
                    progress.stage_fraction = job.fraction();
                    return Ok(self.finish(progress, project, request));
                }
            }
        }

        // 5. The full-resolution march, in bands of rows, shown once complete.
        let key = self.image_key(project, request.width, request.height);
        if self.baked.shown.as_ref() == Some(&(key.clone(), Level::Full)) {
            return Ok(self.finish(progress, project, request));
        }
        if self.jobs.march.as_ref().is_some_and(|(_, k)| *k != key) {
            self.jobs.march = None;
        }
        if self.jobs.march.is_none() {
            let target = match self.full.take() {
                Some(t) if t.width == request.width && t.height == request.height => t,
                _ => ImageTarget::new(&self.ctx.device, request.width, request.height),
            };
            let job = self.begin_march(&target, key.clone());
            self.full = Some(target);
            self.jobs.march = Some((job, key.clone()));
        }
        loop {
            let t = Instant::now();
            let rows = {
                let (job, _) = self.jobs.march.as_mut().expect("a started march");
                let per_row = request.width as u64;
                let rows = (self.rates[timer::MARCH as usize].units_in(left(t)) / per_row.max(1))
                    .clamp(BAND_ROWS as u64, u32::MAX as u64) as u32;
                let target = self.full.as_ref().expect("the full target");
                let before = job.next_row;
                let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
                let stamps = self.timer.as_ref().map(|t| t.writes(timer::MARCH));
                self.marcher.encode_band(&self.ctx, target, &mut encoder, job, rows, stamps);
                if let Some(t) = &self.timer {
                    t.resolve(&mut encoder, timer::MARCH);
                }
                self.ctx.queue.submit([encoder.finish()]);
                self.ctx.wait()?;
                progress.report.counters.dispatches += 1;
                (job.next_row - before) as u64 * per_row
            };
            progress.report.timings_ms.march += self.item_ms(timer::MARCH, t, rows)?;
            let (job, _) = self.jobs.march.as_ref().expect("a started march");
            if job.done() {
                let (_, key) = self.jobs.march.take().expect("a started march");
                self.marcher.read_counters(&self.ctx, &mut progress.report.counters)?;
                self.baked.shown = Some((key, Level::Full));
                progress.new_image = true;
                return Ok(self.finish(progress, project, request));
            }
            if left(Instant::now()).is_some_and(|ms| ms <= 0.0) {
                progress.stage = Stage::March;
                progress.stage_fraction = job.fraction();
                return Ok(self.finish(progress, project, request));
            }
        }
    }

    /// Fills in what is on show.
    fn finish(&self, mut progress: Progress, project: &Project, request: &FrameRequest) -> Progress {
        self.note_memory();
        if let Some((key, _)) = &self.baked.shown {
            progress.shown_size = self.shown_target().map_or([0, 0], |t| [t.width, t.height]);
            // A propagated light whose OPV on show differs from what the scene needs now.
            progress.shadows_stale = project.lights.iter().enumerate().any(|(i, l)| {
                self.opv_key(project, l, request.scheme).is_some_and(|k| key.opvs.get(i).copied().flatten() != Some(k))
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

    /// Starts (or extends) the injection of what changed since the EV on the GPU.
    fn plan_inject(&mut self, project: &Project) {
        let key = EvKey {
            grid: project.grid,
            base_extinction: project.medium.base_extinction,
            height: [project.medium.height_falloff, project.medium.height_origin],
            layer_generation: self.base_layer_generation,
            brute_force: self.brute_force_injection,
            noise: noise_of(project),
        };
        let mut bricks: Vec<u32> = match &self.baked.ev {
            Some((k, particles)) if *k == key => {
                if *particles == project.particles {
                    return;
                }
                binning::dirty_bricks(&project.grid, particles, &project.particles)
            }
            _ => {
                let dims = binning::brick_dims(&project.grid);
                (0..dims.x * dims.y * dims.z).collect()
            }
        };
        if bricks.is_empty() && self.jobs.inject.is_none() {
            // Only names or other fields the EV does not read changed.
            self.baked.ev = Some((key, project.particles.clone()));
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
        let max_items = self.inject_chunk_bytes() / 4;
        let particles: Vec<ParticleGpu> =
            project.particles.iter().map(|p| particle_gpu(p, key.noise.is_some())).collect();
        // The host path's per-brick counts are also what decides it, and its cost estimate.
        let brick_counts = self
            .host_possible()
            .then(|| binning::BinCounts::new(&project.grid, &project.particles, binning::BRICK, false))
            .filter(|counts| self.host_pays(&project.grid, counts));
        let job = if let Some(counts) = brick_counts {
            // The host lists nothing.
            let ordered = super::host_sums::order(&project.grid, particles, |p| p.cutoff2.sqrt());
            Injector::begin(&project.grid, Vec::new(), Vec::new(), counts, bricks, max_items, Some(ordered))
        } else {
            let counts = binning::choose_bins(
                &project.grid,
                &project.particles,
                max_items,
                self.brute_force_injection,
                self.inject_bin_edge,
            );
            if counts.bin_size != self.bin_size {
                self.bin_size = counts.bin_size;
                self.write_scene_uniforms(project);
            }
            Injector::begin(&project.grid, project.particles.clone(), particles, counts, bricks, max_items, None)
        };
        self.jobs.inject = Some((job, region));
        self.baked.ev = Some((key, project.particles.clone()));
    }

    /// Runs one chunk of the injection sized to `left_ms`; returns its cost units.
    fn inject_item(
        &mut self,
        project: &Project,
        left_ms: Option<f64>,
        counters: &mut crate::gpu::Counters,
    ) -> Result<u64, GpuError> {
        let (Some(g), Some((job, _))) = (&self.grid, self.jobs.inject.as_mut()) else { return Ok(0) };
        let rate = self.rates[timer::INJECT as usize];
        let budget_units = rate.units_in(left_ms);
        let mut count = Injector::chunk_align(&self.ctx, job);
        while job.next + count < job.bricks.len() && Injector::units(job, &project.grid, count * 2) <= budget_units {
            count *= 2;
        }
        if left_ms.is_none() {
            count = job.bricks.len().max(1);
        }
        let units = Injector::units(job, &project.grid, count);
        let layer = match &self.base_layer {
            Some((v, buf)) if v.grid == project.grid => Some(buf),
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

    /// The OPV inputs light `l` needs, or None when it is not propagated at all (hidden,
    /// dark or culled).
    fn opv_key(&self, project: &Project, l: &Light, scheme: Scheme) -> Option<OpvKey> {
        if !light_has_opv(project, l) {
            return None;
        }
        // A sun's volume depends on its direction only, whatever the scheme.
        if let Some(direction) = sun_direction(l) {
            return Some(OpvKey {
                position: direction,
                ev_generation: self.baked.ev_generation,
                scheme: Scheme::Sweep,
                stride: 0,
                refine: None,
                sun: true,
            });
        }
        let (stride, refine) = match scheme {
            Scheme::Sweep => (project.propagation.sweep_stride, project.propagation.refine_tolerance()),
            _ => (0, None),
        };
        Some(OpvKey {
            position: l.position,
            ev_generation: self.baked.ev_generation,
            scheme,
            stride,
            refine,
            sun: false,
        })
    }

    /// Lights whose OPV must be (re)propagated, with the inputs it will have; counts the rest.
    fn opv_targets(
        &mut self,
        project: &Project,
        scheme: Scheme,
        counters: &mut crate::gpu::Counters,
    ) -> Vec<(usize, OpvKey)> {
        self.baked.opvs.resize(project.lights.len(), None);
        let mut targets = Vec::new();
        for (i, light) in project.lights.iter().enumerate() {
            match self.opv_key(project, light, scheme) {
                None => {
                    counters.lights_skipped += 1;
                    counters.lights_culled += (light_is_negligible(project, light)
                        || !light.reaches_box(project.grid.min, project.grid.max))
                        as u32;
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
        scheme: Scheme,
        targets: Vec<(usize, OpvKey)>,
        analytic_lists: Option<&binning::ChunkBins>,
    ) {
        let Some(g) = &self.grid else { return };
        let positions: Vec<glam::Vec3> = project.lights.iter().map(|l| l.position).collect();
        let directions: Vec<Option<glam::Vec3>> = project.lights.iter().map(sun_direction).collect();
        let inputs = PropagationInputs {
            grid: &g.spec,
            grid_buf: &g.grid_buf,
            ev_view: &g.ev_view,
            lights_buf: &g.lights_buf,
            opv: &g.opv,
            brick_max: &g.brick_max,
            positions: &positions,
            directions: &directions,
            sweep_stride: project.propagation.sweep_stride,
            sweep_refine: project.propagation.refine_tolerance(),
            particles: &project.particles,
            analytic_lists,
        };
        let active: Vec<u32> = targets.iter().map(|&(i, _)| i as u32).collect();
        let changed: Vec<Option<(glam::UVec3, glam::UVec3)>> =
            targets.iter().map(|&(i, k)| self.changed_since(i, k)).collect();
        let job = self.propagator.plan(&self.ctx.device, &inputs, scheme, &active, &changed);
        self.jobs.propagate = Some((job, targets));
    }

    /// The cells whose extinction changed since light `i`'s OPV was propagated, when only the
    /// extinction changed (same position, scheme and stride) and the history covers it; None
    /// when the whole OPV must be recomputed.
    fn changed_since(&self, i: usize, target: OpvKey) -> Option<(glam::UVec3, glam::UVec3)> {
        let baked = self.baked.opvs.get(i).copied().flatten()?;
        if (OpvKey { ev_generation: target.ev_generation, ..baked }) != target {
            return None;
        }
        let first = self.baked.ev_changes.first()?.0;
        if baked.ev_generation + 1 < first {
            return None;
        }
        let mut region: Option<Region> = None;
        for &(generation, r) in &self.baked.ev_changes {
            if generation > baked.ev_generation && generation <= target.ev_generation {
                region = Some(region.map_or(r, |u| u.union(r)));
            }
        }
        match region? {
            Region::Cells(lo, hi) => Some((lo, hi)),
            Region::All => None,
        }
    }

    /// Runs the next batch of propagation dispatches sized to `left_ms`; returns its cells.
    fn propagate_item(&mut self, left_ms: Option<f64>, counters: &mut crate::gpu::Counters) -> u64 {
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
        // A lost device surfaces as an error of the next readback or update.
        let _ = self.ctx.wait();
        units
    }

    fn image_key(&self, project: &Project, width: u32, height: u32) -> ImageKey {
        let surfaces = surfaces_gpu(project);
        ImageKey {
            params: march_params(project, width, height, surfaces.len() as u32),
            grid: self.grid_params(project),
            lights: project.lights.iter().map(|l| light_gpu(l, light_is_negligible(project, l))).collect(),
            surfaces,
            ev_generation: self.baked.ev_generation,
            opvs: self.baked.opvs.clone(),
        }
    }

    fn begin_march(&mut self, target: &ImageTarget, key: ImageKey) -> MarchJob {
        let g = self.grid.as_ref().expect("ensure_grid ran");
        let inputs = MarchInputs {
            grid_buf: &g.grid_buf,
            ev_view: &g.ev_view,
            lights_buf: &g.lights_buf,
            opv: &g.opv[0],
            brick_max: &g.brick_max,
            surfaces: &key.surfaces,
            params: MarchParams { size: [target.width, target.height], ..key.params },
        };
        self.marcher.begin(&self.ctx, target, &inputs)
    }

    /// Marches the whole image at the largest size whose cost fits `budget_ms` (at most
    /// half the requested size per axis) and shows it.
    fn quick_march(
        &mut self,
        request: &FrameRequest,
        key: ImageKey,
        budget_ms: Option<f64>,
        counters: &mut crate::gpu::Counters,
    ) -> Result<(), GpuError> {
        let rate = self.rates[timer::MARCH as usize];
        let pixels = (request.width as f64 * request.height as f64).max(1.0);
        let affordable = rate.units_in(budget_ms) as f64;
        // Sixteenths of the full size, so small changes in the measured rate keep the target.
        let s = ((affordable / pixels).sqrt() * 16.0).floor().clamp(1.0, 8.0) / 16.0;
        let w = ((request.width as f64 * s) as u32).max(16).min(request.width);
        let h = ((request.height as f64 * s) as u32).max(16).min(request.height);
        let target = match self.quick.take() {
            Some(t) if t.width == w && t.height == h => t,
            _ => ImageTarget::new(&self.ctx.device, w, h),
        };
        let t = Instant::now();
        let mut job = self.begin_march(&target, key.clone());
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        self.marcher.encode_band(&self.ctx, &target, &mut encoder, &mut job, h, None);
        self.ctx.queue.submit([encoder.finish()]);
        self.ctx.wait()?;
        self.rates[timer::MARCH as usize].observe(w as u64 * h as u64, ms(t));
        counters.dispatches += 1;
        self.marcher.read_counters(&self.ctx, counters)?;
        self.quick = Some(target);
        self.baked.shown = Some((key, Level::Quick));
        Ok(())
    }

    fn ensure_grid(&mut self, project: &Project) {
        let spec = project.grid;
        let light_count = project.lights.len();
        if let Some(g) = &self.grid {
            if g.spec == spec && g.light_count == light_count {
                return;
            }
            if g.spec == spec {
                self.resize_lights(light_count);
                return;
            }
        }
        let device = &self.ctx.device;
        let r = spec.resolution;
        let (ev, ev_view) = super::opv_store::volume_texture(
            device,
            "extinction volume",
            wgpu::Extent3d { width: r.x, height: r.y, depth_or_array_layers: r.z },
        );
        let grid_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("grid params"),
            size: std::mem::size_of::<GridParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bricks = spec.resolution.map(|n| n.div_ceil(binning::BRICK));
        let brick_max = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("brick max extinction and detail"),
            size: (bricks.x * bricks.y * bricks.z) as u64 * 8,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let layout = self.stages_for(&spec, light_count);
        let device = &self.ctx.device;
        let (lights_buf, opv) = light_buffers(device, layout, &spec, light_count);
        self.grid = Some(GridResources { spec, light_count, grid_buf, ev, ev_view, lights_buf, opv, brick_max });
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
            self.marcher = Marcher::new(device, self.stage_layout);
            self.slicer = Slicer::new(device, self.stage_layout);
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
        let device = &self.ctx.device;
        let (lights_buf, opv) = light_buffers(device, layout, &g.spec, light_count);
        let kept = g.light_count.min(light_count) as u64;
        if kept > 0 {
            let mut encoder = device.create_command_encoder(&Default::default());
            // Both: the sweep keeps each cell's mean in-box extinction in the second one.
            g.opv[0].copy_to(&mut encoder, 0, &opv[0], 0, kept);
            g.opv[1].copy_to(&mut encoder, 0, &opv[1], 0, kept);
            self.ctx.queue.submit([encoder.finish()]);
        }
        g.lights_buf = lights_buf;
        g.opv = opv;
        g.light_count = light_count;
        self.baked.opvs.truncate(light_count);
        // In-flight work binds the old buffers.
        self.jobs.propagate = None;
        self.jobs.march = None;
    }

    fn grid_params(&self, project: &Project) -> GridParams {
        let spec = project.grid;
        GridParams {
            min: spec.min.to_array(),
            base_extinction: project.medium.base_extinction,
            max: spec.max.to_array(),
            light_count: project.lights.len() as u32,
            cell: spec.cell_size().to_array(),
            has_base_layer: self.base_layer.as_ref().is_some_and(|(v, _)| v.grid == spec) as u32,
            dims: spec.resolution.to_array(),
            bin_size: self.bin_size,
            height_falloff: project.medium.height_falloff,
            height_origin: project.medium.height_origin,
            _pad_h: [0; 2],
            noise_amplitude: noise_of(project).map_or(0.0, |n| n.amplitude),
            noise_frequency: noise_of(project).map_or(0.0, |n| n.frequency),
            noise_octaves: noise_of(project).map_or(0, |n| n.effective_octaves(&spec)),
            noise_seed: noise_of(project).map_or(0, |n| n.seed),
        }
    }

    /// Uploads the lights (culled and hidden ones dark) and the grid parameters every stage reads.
    fn write_scene_uniforms(&mut self, project: &Project) {
        let Some(g) = &self.grid else { return };
        let lights: Vec<LightGpu> =
            project.lights.iter().map(|l| light_gpu(l, light_is_negligible(project, l))).collect();
        if !lights.is_empty() {
            self.ctx.queue.write_buffer(&g.lights_buf, 0, bytemuck::cast_slice(&lights));
        }
        let params = self.grid_params(project);
        self.ctx.queue.write_buffer(&g.grid_buf, 0, bytemuck::bytes_of(&params));
    }

    /// Caps the particle–bin lists of one injection chunk at `bytes` (None: one storage
    /// binding, the most a chunk can use). Smaller chunks bound memory more tightly at the
    /// cost of more passes; the EV is the same bit for bit.
    pub fn set_inject_chunk_bytes(&mut self, bytes: Option<u64>) {
        self.inject_chunk_limit = bytes;
    }

    /// The particle–bin list bytes one injection chunk may use.
    pub fn inject_chunk_bytes(&self) -> u64 {
        let binding = self.ctx.max_binding_bytes();
        self.inject_chunk_limit.map_or(binding, |b| b.clamp(4, binding))
    }

    /// Makes every cell evaluate every particle instead of only those binned into its brick:
    /// the brute-force injection, for measuring what binning saves. Off by default.
    pub fn set_brute_force_injection(&mut self, on: bool) {
        self.brute_force_injection = on;
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
        if path != self.inject_path {
            self.inject_path = path;
            self.baked.ev = None;
        }
    }

    /// Whether injecting `project` sums its particles on the host. `Auto` does on a CPU
    /// adapter (unless brute force or a fixed bin edge asks for the gather) when the
    /// particles reach at least [`HOST_MIN_ENTRIES_PER_BRICK`] bricks per brick of the grid.
    pub fn inject_on_host(&self, project: &Project) -> bool {
        self.host_possible()
            && self.host_pays(
                &project.grid,
                &binning::BinCounts::new(&project.grid, &project.particles, binning::BRICK, false),
            )
    }

    /// Whether the injection may take the host path, for scenes dense enough under `Auto`.
    fn host_possible(&self) -> bool {
        match self.inject_path {
            InjectPath::Host => true,
            InjectPath::Adapter => false,
            InjectPath::Auto => {
                self.ctx.adapter_info.device_type == wgpu::DeviceType::Cpu
                    && !self.brute_force_injection
                    && self.inject_bin_edge.is_none()
            }
        }
    }

    /// Given [`host_possible`](Self::host_possible) and the scene's per-brick particle counts,
    /// whether it takes the host path.
    fn host_pays(&self, grid: &GridSpec, brick_counts: &binning::BinCounts) -> bool {
        self.inject_path == InjectPath::Host
            || brick_counts.entries()
                >= HOST_MIN_ENTRIES_PER_BRICK * binning::brick_dims(grid).as_u64vec3().element_product()
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
        self.inject_bin_edge = edge;
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

    /// The extinction volume σ_t at cell centres.
    pub fn read_ev(&self) -> Result<Volume, GpuError> {
        let g = self.grid.as_ref().ok_or_else(|| GpuError::Invalid("nothing baked yet: call update first".into()))?;
        let data = read_texture(&self.ctx, &g.ev, g.spec.resolution.to_array(), 4)?;
        Ok(Volume::new(g.spec, data))
    }

    /// Optical depth T towards light `light` at cell centres.
    pub fn read_opv(&self, light: usize) -> Result<Volume, GpuError> {
        let g = self.grid.as_ref().ok_or_else(|| GpuError::Invalid("nothing baked yet: call update first".into()))?;
        if light >= g.light_count {
            return Err(GpuError::Invalid(format!("light {light} does not exist (the scene has {})", g.light_count)));
        }
        let data = g.opv[0].read(&self.ctx, light as u64)?;
        Ok(Volume::new(g.spec, data))
    }

    /// Plane `index` across grid `axis` (0, 1, 2 for x, y, z) of the EV or of one light's
    /// OPV, gathered on the GPU so that only the plane is read back.
    pub fn read_slice(&mut self, source: SliceSource, axis: usize, index: u32) -> Result<Plane, GpuError> {
        let g = self.grid.as_ref().ok_or_else(|| GpuError::Invalid("nothing baked yet: call update first".into()))?;
        let dims = g.spec.resolution.to_array();
        if axis > 2 || index >= dims[axis.min(2)] {
            return Err(GpuError::Invalid(format!("slice {index} across axis {axis} is outside the {dims:?} grid")));
        }
        let (light, source) = match source {
            SliceSource::Extinction => (0, 0),
            SliceSource::OpticalDepth { light } if light < g.light_count => (light as u32, 1),
            SliceSource::OpticalDepth { light } => {
                return Err(GpuError::Invalid(format!(
                    "light {light} does not exist (the scene has {})",
                    g.light_count
                )))
            }
        };
        let inputs = SliceInputs { grid_buf: &g.grid_buf, ev_view: &g.ev_view, opv: &g.opv[0] };
        self.slicer.read(&self.ctx, &inputs, dims, SliceParams { axis: axis as u32, index, light, source })
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
        let rgba = read_texture(&self.ctx, &img.hdr, [img.width, img.height, 1], 16)?;
        Ok(Image { width: img.width, height: img.height, rgba })
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
            + self.injector.bytes()
            + self.marcher.bytes()
            + self.slicer.bytes()
            + layer
    }
}

/// `bytes` in MiB or GiB, for messages.
pub fn human_bytes(bytes: u64) -> String {
    let mib = bytes as f64 / (1u64 << 20) as f64;
    if mib < 1.0 {
        format!("{:.1} KiB", bytes as f64 / 1024.0)
    } else if mib >= 1024.0 {
        format!("{:.2} GiB", mib / 1024.0)
    } else {
        format!("{mib:.1} MiB")
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

/// The unit direction of travel of a directional light; None for other kinds.
fn sun_direction(l: &Light) -> Option<glam::Vec3> {
    match l.kind {
        crate::scene::LightKind::Directional { direction } => Some(direction.normalize_or_zero()),
        _ => None,
    }
}

fn light_gpu(l: &Light, culled: bool) -> LightGpu {
    use crate::scene::LightKind;
    let rgb = if l.hidden || culled { glam::Vec3::ZERO } else { l.radiance_rgb() };
    let (kind, direction, angle, blend) = match l.kind {
        LightKind::Point => (LIGHT_POINT, glam::Vec3::ZERO, 0.0, 0.0),
        LightKind::Spot { direction, angle_deg, blend } => {
            (LIGHT_SPOT, direction.normalize_or_zero(), angle_deg.to_radians(), blend)
        }
        LightKind::Directional { direction } => (LIGHT_DIRECTIONAL, direction.normalize_or_zero(), 0.0, 0.0),
    };
    LightGpu {
        position: l.position.to_array(),
        kind,
        rgb: rgb.to_array(),
        angle,
        direction: direction.to_array(),
        blend,
    }
}

/// The lights buffer and the two OPV buffers (result and scratch) for `light_count` lights.
fn light_buffers(
    device: &wgpu::Device,
    layout: OpvLayout,
    spec: &GridSpec,
    light_count: usize,
) -> (wgpu::Buffer, [OpvVolumes; 2]) {
    let lights = light_count.max(1) as u64;
    let opv = ["optical depth A", "optical depth B"]
        .map(|label| OpvVolumes::new(device, layout, spec.resolution, lights, label));
    let lights_buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("lights"),
        size: (light_count.max(1) * std::mem::size_of::<LightGpu>()) as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    (lights_buf, opv)
}

/// Whether light `l` gets an optical-depth volume: it is shown, has intensity, can reach
/// the grid box (a spot's cone, a point light's reach) and is not negligible. The others add
/// nothing to the image, so their volumes are never read (their contents are unspecified).
pub fn light_has_opv(project: &Project, l: &Light) -> bool {
    !(l.hidden
        || l.intensity <= 0.0
        || light_is_negligible(project, l)
        || !l.reaches_box(project.grid.min, project.grid.max))
}

/// Radiance below which a light's whole contribution is dropped: the tone-mapped display
/// changes by less than exposure × this, far below one 8-bit step.
pub const CULL_RADIANCE: f32 = 1e-6;

/// Whether light `l` provably adds less than [`CULL_RADIANCE`] / exposure to every pixel.
/// Only possible without base fog and surfaces: then light is scattered only inside the grid,
/// and a pixel receives at most I·albedo·max(phase) / d² (d: the light's distance to the grid
/// box), since ∫σ_t·exp(−τ) along a ray is below 1.
pub fn light_is_negligible(project: &Project, l: &Light) -> bool {
    if !l.reaches_box(project.grid.min, project.grid.max)
        && project.medium.base_extinction <= 0.0
        && project.surfaces.is_empty()
    {
        return true;
    }
    if matches!(l.kind, crate::scene::LightKind::Directional { .. })
        || project.medium.base_extinction > 0.0
        || !project.surfaces.is_empty()
        || project.base_volume.is_some()
    {
        return false;
    }
    let g = project.grid;
    let d2 = (l.position - l.position.clamp(g.min, g.max)).length_squared();
    let gm = project.medium.anisotropy.abs();
    let max_phase = (1.0 + gm) / (4.0 * std::f32::consts::PI * (1.0 - gm).powi(2));
    let bound = l.radiance_rgb().max_element() * project.medium.albedo * max_phase / d2;
    bound * project.render.exposure.max(1e-6) < CULL_RADIANCE
}

/// What in `project` the `analytic` scheme cannot represent, which only the grid holds: the
/// medium's noise on a visible particle, or an imported base volume.
pub fn analytic_unsupported(project: &Project) -> Option<&'static str> {
    if noise_of(project).is_some() && project.particles.iter().any(|p| p.noise && !p.hidden && p.density > 0.0) {
        Some("the medium's noise")
    } else if project.base_volume.is_some() {
        Some("an imported base volume")
    } else {
        None
    }
}

/// The medium's noise when it changes the EV (amplitude above 0), else None.
fn noise_of(project: &Project) -> Option<crate::scene::Noise> {
    project.medium.noise.filter(|n| n.amplitude > 0.0)
}

/// A particle in the injection's layout: its density counts as noisy when the medium has
/// noise and the particle takes it.
fn particle_gpu(p: &Particle, noise: bool) -> ParticleGpu {
    let r = binning::cutoff_radius(p);
    let density = if p.hidden { 0.0 } else { p.density };
    ParticleGpu {
        center: p.center.to_array(),
        inv_r2: 1.0 / (p.radius * p.radius),
        density: if noise && p.noise { [0.0, density] } else { [density, 0.0] },
        cutoff2: r * r,
        _pad: 0.0,
    }
}

/// The project's surfaces in the layout of `shaders/march.wgsl`.
fn surfaces_gpu(project: &Project) -> Vec<SurfaceGpu> {
    let mut out: Vec<SurfaceGpu> = project
        .surfaces
        .boxes
        .iter()
        .map(|b| SurfaceGpu {
            min: b.min.to_array(),
            kind: SURFACE_BOX,
            max: b.max.to_array(),
            specular: b.specular,
            albedo: b.albedo.to_array(),
            phong_exponent: b.phong_exponent,
        })
        .collect();
    if let Some(g) = &project.surfaces.ground {
        out.push(SurfaceGpu {
            min: [0.0, g.height, 0.0],
            kind: SURFACE_GROUND,
            max: [0.0; 3],
            specular: g.specular,
            albedo: g.albedo.to_array(),
            phong_exponent: g.phong_exponent,
        });
    }
    out
}

/// Camera basis scaled to the image plane, step policy and far distance for the march.
fn march_params(project: &Project, width: u32, height: u32, surface_count: u32) -> MarchParams {
    let cam = &project.camera;
    let r = &project.render;
    let (right, up, forward) = cam.basis();
    let tan_half = (cam.fov_y_deg.to_radians() * 0.5).tan();
    let aspect = width as f32 / height as f32;
    let step = r.step_factor * project.grid.cell_size().min_element();
    let base = project.medium.base_extinction;
    // Beyond the grid only base fog remains; follow it until its transmittance is 1e-8.
    // Height fog thins upwards, so no density bounds the distance: the cap alone applies.
    let far_distance = if base > 0.0 {
        let reach = if project.medium.height_falloff > 0.0 { f32::INFINITY } else { 18.42 / base };
        reach.min(20.0 * project.grid.size().length())
    } else {
        0.0
    };
    MarchParams {
        origin: cam.position.to_array(),
        step,
        right: (right * tan_half * aspect).to_array(),
        albedo: project.medium.albedo,
        up: (up * tan_half).to_array(),
        anisotropy: project.medium.anisotropy,
        forward: forward.to_array(),
        exposure: r.exposure,
        size: [width, height],
        tr_cutoff: r.transmittance_cutoff,
        far_distance,
        policy: match r.step_policy {
            StepPolicy::Fixed => POLICY_FIXED,
            StepPolicy::TwoLevel => POLICY_TWO_LEVEL,
            StepPolicy::Adaptive => POLICY_ADAPTIVE,
        },
        near_steps: r.near_steps,
        far_steps: r.far_steps,
        skip_empty: r.skip_empty as u32,
        tau_target: r.tau_target,
        near_fraction: r.near_fraction,
        min_step: 0.25 * step,
        max_step: 4.0 * step,
        surface_count,
        row_offset: 0,
        sun_count: project
            .lights
            .iter()
            .filter(|l| matches!(l.kind, crate::scene::LightKind::Directional { .. }))
            .count() as u32,
        _pad: 0,
    }
}

/// Catches wgpu validation errors of one update as a typed error instead of a panic.
struct ErrorScope(wgpu::ErrorScopeGuard);

impl ErrorScope {
    fn push(device: &wgpu::Device) -> Self {
        Self(device.push_error_scope(wgpu::ErrorFilter::Validation))
    }
    fn pop(self, stage: &'static str) -> Result<(), GpuError> {
        match pollster::block_on(self.0.pop()) {
            Some(e) => Err(GpuError::Validation { stage, message: e.to_string() }),
            None => Ok(()),
        }
    }
}

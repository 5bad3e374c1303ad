//! [`FogPipeline`]: the long-lived object that owns the compute pipelines and the scene's GPU
//! resources, decides which stages a change requires, runs them and reads results back.

use super::binning::{self, bin_particles};
use super::gpu_types::{GridParams, LightGpu, MarchParams, ParticleGpu, SurfaceGpu};
use super::layout::{bind_group, bind_group_layout, compute_pipeline, Slot};
use super::readback::{read_buffer, read_texture};
use super::propagate::{PropagationInputs, Propagator};
use super::timer::{self, StageTimer};
use super::{GpuContext, GpuError};
use crate::reference::sun::GPU_TABLE_SIZE;
use crate::scene::{GridSpec, Light, Particle, Project, Scheme, StepPolicy, Volume};
use std::time::Instant;

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

/// Time per stage in milliseconds: GPU timestamps on hardware adapters that have them (see
/// [`FrameReport::gpu_timestamps`]), else wall time of the stage's host work, submit and a
/// drained queue.
#[derive(Clone, Copy, Debug, Default, PartialEq, serde::Serialize)]
pub struct StageTimings {
    pub inject: f64,
    pub propagate: f64,
    pub march: f64,
}

/// What the last update did. Tests read these to prove that work was skipped.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize)]
pub struct Counters {
    pub dispatches: u32,
    pub cells_injected: u64,
    /// Particle–cell pairs injection evaluated (list lengths × cells of the bins it read).
    pub particle_evaluations: u64,
    pub cells_propagated: u64,
    pub lights_propagated: u32,
    /// Lights whose OPV was up to date, or that are hidden, dark or culled.
    pub lights_skipped: u32,
    /// Lights skipped because their contribution is provably negligible
    /// (see [`light_is_negligible`]).
    pub lights_culled: u32,
    /// Jacobi iterations (`giroud`) or wavefronts (`sweep`) per light.
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
    opv: [wgpu::Buffer; 2],
    /// Largest σ_t seen by samples in each 8³ brick (see `shaders/occupancy.wgsl`).
    brick_max: wgpu::Buffer,
}

struct ImageResources {
    width: u32,
    height: u32,
    hdr: wgpu::Texture,
    ldr_view: wgpu::TextureView,
    params_buf: wgpu::Buffer,
}

/// What the GPU currently holds, to decide what a new project state invalidates.
#[derive(Default)]
struct Baked {
    /// Grid, base extinction, base layer generation and particles of the EV on the GPU.
    ev_inputs: Option<(GridSpec, f32, u64, Vec<Particle>)>,
    /// Per light: position baked into its OPV and the EV generation it used.
    opv_inputs: Vec<Option<(glam::Vec3, u64, Scheme, u32)>>,
    ev_generation: u64,
    image_inputs: Option<String>,
}

/// The GPU fog pipeline: injection → propagation → ray march, plus readback.
pub struct FogPipeline {
    ctx: GpuContext,
    inject_layout: wgpu::BindGroupLayout,
    inject: wgpu::ComputePipeline,
    occupancy_layout: wgpu::BindGroupLayout,
    occupancy: wgpu::ComputePipeline,
    propagator: Propagator,
    march_layout: wgpu::BindGroupLayout,
    march: wgpu::ComputePipeline,
    counters_buf: wgpu::Buffer,
    /// Sun et al.'s F table (remapped layout) for the closed-form base fog.
    sun_table: wgpu::Buffer,
    timer: Option<StageTimer>,
    grid: Option<GridResources>,
    image: Option<ImageResources>,
    baked: Baked,
    last_report: FrameReport,
    /// Imported density added under the particles, and a counter bumped when it changes.
    base_layer: Option<(Volume, wgpu::Buffer)>,
    base_layer_generation: u64,
    brute_force_injection: bool,
    /// Bin edge of the last injection's particle lists (see `binning`).
    bin_size: u32,
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

impl FogPipeline {
    pub fn new(ctx: GpuContext) -> Self {
        let device = &ctx.device;
        let inject_layout = bind_group_layout(
            device,
            "inject",
            &[
                Slot::Uniform,
                Slot::StorageRead,
                Slot::StorageRead,
                Slot::StorageRead,
                Slot::StorageTexture3d(wgpu::TextureFormat::R32Float),
                Slot::StorageRead,
                Slot::StorageRead,
            ],
        );
        let inject = compute_pipeline(device, "inject", &[include_str!("../../shaders/inject.wgsl")], &inject_layout);
        let occupancy_layout =
            bind_group_layout(device, "occupancy", &[Slot::Uniform, Slot::Texture3d, Slot::StorageWrite]);
        let occupancy =
            compute_pipeline(device, "occupancy", &[include_str!("../../shaders/occupancy.wgsl")], &occupancy_layout);
        let propagator = Propagator::new(device);
        let march_layout = bind_group_layout(
            device,
            "march",
            &[
                Slot::Uniform,
                Slot::Uniform,
                Slot::Texture3d,
                Slot::StorageRead,
                Slot::StorageRead,
                Slot::StorageTexture2d(wgpu::TextureFormat::Rgba32Float),
                Slot::StorageTexture2d(wgpu::TextureFormat::Rgba8Unorm),
                Slot::StorageWrite,
                Slot::StorageRead,
                Slot::StorageRead,
                Slot::StorageRead,
            ],
        );
        let march = compute_pipeline(
            device,
            "march",
            &[include_str!("../../shaders/sun.wgsl"), include_str!("../../shaders/march.wgsl")],
            &march_layout,
        );
        let sun = crate::reference::sun::FTable::remapped(GPU_TABLE_SIZE, GPU_TABLE_SIZE);
        let sun_table = storage_buffer(device, "sun F table", bytemuck::cast_slice(&sun.data));
        let counters_buf = storage_buffer(device, "counters", &[0u8; 16]);
        let timer = StageTimer::new(&ctx);
        Self {
            ctx,
            inject_layout,
            inject,
            occupancy_layout,
            occupancy,
            propagator,
            march_layout,
            march,
            counters_buf,
            sun_table,
            timer,
            grid: None,
            image: None,
            baked: Baked::default(),
            last_report: FrameReport::default(),
            base_layer: None,
            base_layer_generation: 0,
            brute_force_injection: false,
            bin_size: binning::BRICK,
        }
    }

    pub fn context(&self) -> &GpuContext {
        &self.ctx
    }

    pub fn last_report(&self) -> FrameReport {
        self.last_report
    }

    /// Refuses, before allocating anything, a scene larger than the adapter allows: grid edge
    /// (3D texture), OPVs, particles, particle–bin lists and lights (one storage binding
    /// each) and the image (2D texture and its readback buffer).
    pub fn check_limits(&self, project: &Project, width: u32, height: u32) -> Result<(), GpuError> {
        let limits = &self.ctx.limits;
        let adapter = self.ctx.adapter_info.name.clone();
        let edge = project.grid.resolution.max_element();
        if edge > limits.max_texture_dimension_3d {
            return Err(GpuError::Limit {
                what: format!("a {}³-edge grid", edge),
                needed: edge as u64,
                limit: limits.max_texture_dimension_3d as u64,
                adapter,
                suggestion: "lower grid.resolution".into(),
            });
        }
        let opv_bytes = project.grid.cell_count() * project.lights.len().max(1) as u64 * 4;
        let opv_limit = (limits.max_storage_buffer_binding_size as u64).min(limits.max_buffer_size);
        if opv_bytes > opv_limit {
            let per_light = project.grid.cell_count() * 4;
            return Err(GpuError::Limit {
                what: format!(
                    "the optical-depth volumes of {} lights on a {}×{}×{} grid",
                    project.lights.len(),
                    project.grid.resolution.x,
                    project.grid.resolution.y,
                    project.grid.resolution.z
                ),
                needed: opv_bytes,
                limit: opv_limit,
                adapter,
                suggestion: format!(
                    "use at most {} lights at this resolution or lower grid.resolution",
                    opv_limit / per_light
                ),
            });
        }
        let binding = (limits.max_storage_buffer_binding_size as u64).min(limits.max_buffer_size);
        let particle_bytes = project.particles.len() as u64 * std::mem::size_of::<ParticleGpu>() as u64;
        if particle_bytes > binding {
            return Err(GpuError::Limit {
                what: format!("{} particles", project.particles.len()),
                needed: particle_bytes,
                limit: binding,
                adapter,
                suggestion: format!(
                    "use at most {} particles, e.g. by merging small ones or importing dense regions as a VDB base volume",
                    binding / std::mem::size_of::<ParticleGpu>() as u64
                ),
            });
        }
        // Each particle is listed once per bin its cut-off sphere overlaps; the count is only
        // summed when its bound (every particle in every bin) could exceed the binding.
        if binning::overlap_bound(&project.grid, project.particles.len()) * 4 > binding {
            let overlaps = if self.brute_force_injection {
                let visible = project.particles.iter().filter(|p| !p.hidden && p.density > 0.0).count() as u64;
                visible * binning::brick_dims(&project.grid).as_u64vec3().element_product()
            } else {
                binning::overlap_count(&project.grid, &project.particles)
            };
            if overlaps * 4 > binding {
                return Err(GpuError::Limit {
                    what: format!("the particle–bin lists of {} particles", project.particles.len()),
                    needed: overlaps * 4,
                    limit: binding,
                    adapter,
                    suggestion: "use fewer or smaller particles (each is listed in every injection bin it reaches), or lower grid.resolution".into(),
                });
            }
        }
        let light_bytes = project.lights.len() as u64 * std::mem::size_of::<LightGpu>() as u64;
        if light_bytes > binding {
            return Err(GpuError::Limit {
                what: format!("{} lights", project.lights.len()),
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

    /// Brings the GPU state up to date with `project`, running only the stages the changes
    /// since the last call require, and renders the frame.
    pub fn update(&mut self, project: &Project, request: &FrameRequest) -> Result<FrameReport, GpuError> {
        project
            .validate(self.ctx.max_grid_edge())
            .map_err(|e| GpuError::Invalid(e.to_string()))?;
        for (name, v) in [("width", request.width), ("height", request.height)] {
            if v == 0 || v > 16384 {
                return Err(GpuError::Invalid(format!("the frame {name} must be within 1..=16384 pixels, got {v}")));
            }
        }
        self.check_limits(project, request.width, request.height)?;
        if request.scheme == Scheme::Giroud {
            // One dispatch covers every propagated light: z = ⌈nz/4⌉ workgroups per light.
            let z = project.grid.resolution.z.div_ceil(4) as u64 * project.lights.len() as u64;
            let limit = self.ctx.limits.max_compute_workgroups_per_dimension as u64;
            if z > limit {
                return Err(GpuError::Limit {
                    what: format!("the giroud scheme with {} lights on a grid {} cells deep", project.lights.len(), project.grid.resolution.z),
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
        let scope = ErrorScope::push(&self.ctx.device);
        let mut report = FrameReport::default();
        if request.force {
            self.baked = Baked::default();
        }
        self.ensure_grid(project);
        self.write_scene_uniforms(project);

        let bricks = self.bricks_to_inject(project);
        if !bricks.is_empty() {
            let t = Instant::now();
            self.run_inject(project, &bricks, &mut report.counters)?;
            report.timings_ms.inject = self.stage_ms(timer::INJECT, t)?;
            self.baked.ev_generation += 1;
        }
        self.baked.ev_inputs =
            Some((project.grid, project.medium.base_extinction, self.base_layer_generation, project.particles.clone()));

        let t = Instant::now();
        self.run_propagation(project, request.scheme, &mut report.counters)?;
        if report.counters.lights_propagated > 0 {
            report.timings_ms.propagate = self.stage_ms(timer::PROPAGATE, t)?;
        }

        let image_key = format!(
            "{:?}{:?}{:?}{:?}{:?}{}x{}{}",
            project.camera,
            project.surfaces,
            project.render,
            project.medium,
            project.lights,
            request.width,
            request.height,
            self.baked.ev_generation
        );
        if self.baked.image_inputs.as_deref() != Some(image_key.as_str()) || report.counters.lights_propagated > 0 {
            let t = Instant::now();
            self.run_march(project, request, &mut report.counters)?;
            report.timings_ms.march = self.stage_ms(timer::MARCH, t)?;
            self.baked.image_inputs = Some(image_key);
        }
        scope.pop("update")?;
        report.gpu_timestamps = self.timer.is_some();
        self.last_report = report;
        Ok(report)
    }

    /// GPU time of a completed stage, or wall time since `started` without timestamps.
    fn stage_ms(&self, stage: u32, started: Instant) -> Result<f64, GpuError> {
        match &self.timer {
            Some(t) => t.read_ms(&self.ctx, stage),
            None => Ok(ms(started)),
        }
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
        let ev = device.create_texture(&wgpu::TextureDescriptor {
            label: Some("extinction volume"),
            size: wgpu::Extent3d { width: r.x, height: r.y, depth_or_array_layers: r.z },
            mip_level_count: 1,
            sample_count: 1,
            dimension: wgpu::TextureDimension::D3,
            format: wgpu::TextureFormat::R32Float,
            usage: wgpu::TextureUsages::STORAGE_BINDING
                | wgpu::TextureUsages::TEXTURE_BINDING
                | wgpu::TextureUsages::COPY_SRC,
            view_formats: &[],
        });
        let ev_view = ev.create_view(&Default::default());
        let grid_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("grid params"),
            size: std::mem::size_of::<GridParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bricks = spec.resolution.map(|n| n.div_ceil(binning::BRICK));
        let brick_max = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("brick max extinction"),
            size: (bricks.x * bricks.y * bricks.z) as u64 * 4,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let (lights_buf, opv) = light_buffers(device, &spec, light_count);
        self.grid = Some(GridResources { spec, light_count, grid_buf, ev, ev_view, lights_buf, opv, brick_max });
        self.baked = Baked::default();
    }

    /// Reallocates the per-light buffers for a new light count on the same grid, keeping the
    /// OPVs of the lights that remain (by index), so adding a light propagates only that one.
    fn resize_lights(&mut self, light_count: usize) {
        let Some(g) = &mut self.grid else { return };
        let device = &self.ctx.device;
        let (lights_buf, opv) = light_buffers(device, &g.spec, light_count);
        let kept = g.spec.cell_count() * 4 * g.light_count.min(light_count) as u64;
        if kept > 0 {
            let mut encoder = device.create_command_encoder(&Default::default());
            encoder.copy_buffer_to_buffer(&g.opv[0], 0, &opv[0], 0, kept);
            self.ctx.queue.submit([encoder.finish()]);
        }
        g.lights_buf = lights_buf;
        g.opv = opv;
        g.light_count = light_count;
        self.baked.opv_inputs.truncate(light_count);
    }

    /// Uploads the lights (culled and hidden ones dark) and the grid parameters every stage reads.
    fn write_scene_uniforms(&mut self, project: &Project) {
        let Some(g) = &self.grid else { return };
        let lights: Vec<LightGpu> =
            project.lights.iter().map(|l| light_gpu(l, light_is_negligible(project, l))).collect();
        if !lights.is_empty() {
            self.ctx.queue.write_buffer(&g.lights_buf, 0, bytemuck::cast_slice(&lights));
        }
        let spec = project.grid;
        let params = GridParams {
            min: spec.min.to_array(),
            base_extinction: project.medium.base_extinction,
            max: spec.max.to_array(),
            light_count: project.lights.len() as u32,
            cell: spec.cell_size().to_array(),
            has_base_layer: self.base_layer.as_ref().is_some_and(|(v, _)| v.grid == spec) as u32,
            dims: spec.resolution.to_array(),
            bin_size: self.bin_size,
        };
        self.ctx.queue.write_buffer(&g.grid_buf, 0, bytemuck::bytes_of(&params));
    }

    /// Makes every cell evaluate every particle instead of only those binned into its brick:
    /// the brute-force injection, for measuring what binning saves. Off by default.
    pub fn set_brute_force_injection(&mut self, on: bool) {
        if on != self.brute_force_injection {
            self.brute_force_injection = on;
            self.baked.ev_inputs = None;
        }
    }

    /// Sets (or clears) a density layer added to every cell of the EV under the particles,
    /// such as a VDB grid resampled into the project's grid. It must match the grid of the
    /// projects passed to [`update`](Self::update).
    pub fn set_base_layer(&mut self, layer: Option<Volume>) {
        let limits = &self.ctx.limits;
        let binding = (limits.max_storage_buffer_binding_size as u64).min(limits.max_buffer_size);
        self.base_layer = layer.map(|v| {
            // A layer too large to bind is not uploaded (wgpu would panic): it is as large as
            // one light's OPV, so `update` refuses its grid with the limit named.
            let bytes: &[u8] = bytemuck::cast_slice(&v.data);
            let buf = storage_buffer(&self.ctx.device, "base layer", if bytes.len() as u64 > binding { &[] } else { bytes });
            (v, buf)
        });
        self.base_layer_generation += 1;
    }

    /// Every brick after a change of grid, base fog or base layer, else only those whose
    /// particles changed.
    fn bricks_to_inject(&self, project: &Project) -> Vec<u32> {
        let dims = binning::brick_dims(&project.grid);
        let all = || (0..dims.x * dims.y * dims.z).collect();
        match &self.baked.ev_inputs {
            Some((grid, base, layer, particles))
                if *grid == project.grid
                    && *base == project.medium.base_extinction
                    && *layer == self.base_layer_generation =>
            {
                if *particles == project.particles {
                    Vec::new()
                } else {
                    binning::dirty_bricks(grid, particles, &project.particles)
                }
            }
            _ => all(),
        }
    }

    fn run_inject(&mut self, project: &Project, bricks: &[u32], counters: &mut Counters) -> Result<(), GpuError> {
        let bins = if self.brute_force_injection {
            binning::bin_all(&project.grid, &project.particles)
        } else {
            bin_particles(&project.grid, &project.particles)
        };
        if bins.bin_size != self.bin_size {
            self.bin_size = bins.bin_size;
            self.write_scene_uniforms(project);
        }
        let Some(g) = &self.grid else { return Ok(()) };
        let device = &self.ctx.device;
        let particles: Vec<ParticleGpu> = project.particles.iter().map(particle_gpu).collect();
        let particles_buf = storage_buffer(device, "particles", bytemuck::cast_slice(&particles));
        let offsets_buf = storage_buffer(device, "brick offsets", bytemuck::cast_slice(&bins.offsets));
        let items_buf = storage_buffer(device, "brick items", bytemuck::cast_slice(&bins.items));
        let bricks_buf = storage_buffer(device, "dirty bricks", bytemuck::cast_slice(bricks));
        let no_layer;
        let layer_buf = match &self.base_layer {
            Some((v, buf)) if v.grid == project.grid => buf,
            _ => {
                no_layer = storage_buffer(device, "no base layer", &[]);
                &no_layer
            }
        };
        // One workgroup pair per brick, at most max_compute_workgroups_per_dimension per
        // dispatch: larger grids take several dispatches over aligned slices of the list.
        let align = (self.ctx.limits.min_storage_buffer_offset_alignment as usize / 4).max(1);
        let chunk = (self.ctx.limits.max_compute_workgroups_per_dimension as usize / align).max(1) * align;
        let groups: Vec<(wgpu::BindGroup, u32)> = bricks
            .chunks(chunk)
            .enumerate()
            .map(|(n, part)| {
                let slice = wgpu::BufferBinding {
                    buffer: &bricks_buf,
                    offset: (n * chunk * 4) as u64,
                    size: wgpu::BufferSize::new(part.len() as u64 * 4),
                };
                let bg = bind_group(
                    device,
                    "inject",
                    &self.inject_layout,
                    &[
                        g.grid_buf.as_entire_binding(),
                        particles_buf.as_entire_binding(),
                        offsets_buf.as_entire_binding(),
                        items_buf.as_entire_binding(),
                        wgpu::BindingResource::TextureView(&g.ev_view),
                        wgpu::BindingResource::Buffer(slice),
                        layer_buf.as_entire_binding(),
                    ],
                );
                (bg, part.len() as u32)
            })
            .collect();
        let r = project.grid.resolution;
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("inject"),
                timestamp_writes: self.timer.as_ref().map(|t| t.writes(timer::INJECT)),
            });
            pass.set_pipeline(&self.inject);
            for (bg, count) in &groups {
                pass.set_bind_group(0, bg, &[]);
                pass.dispatch_workgroups(*count, 2, 1);
            }
            let occ = bind_group(
                device,
                "occupancy",
                &self.occupancy_layout,
                &[
                    g.grid_buf.as_entire_binding(),
                    wgpu::BindingResource::TextureView(&g.ev_view),
                    g.brick_max.as_entire_binding(),
                ],
            );
            let b = r.map(|n| n.div_ceil(binning::BRICK));
            pass.set_pipeline(&self.occupancy);
            pass.set_bind_group(0, &occ, &[]);
            pass.dispatch_workgroups(b.x.div_ceil(4), b.y.div_ceil(4), b.z.div_ceil(4));
        }
        if let Some(t) = &self.timer {
            t.resolve(&mut encoder, timer::INJECT);
        }
        self.ctx.queue.submit([encoder.finish()]);
        self.ctx.wait()?;
        counters.dispatches += 1 + groups.len() as u32;
        let cells_per_brick = (binning::BRICK as u64).pow(3);
        counters.cells_injected += (bricks.len() as u64 * cells_per_brick).min(project.grid.cell_count());
        counters.particle_evaluations += bins.evaluations(&project.grid, bricks);
        Ok(())
    }

    fn run_propagation(&mut self, project: &Project, scheme: Scheme, counters: &mut Counters) -> Result<(), GpuError> {
        let Some(g) = &self.grid else { return Ok(()) };
        let generation = self.baked.ev_generation;
        self.baked.opv_inputs.resize(project.lights.len(), None);
        let mut active = Vec::new();
        for (i, light) in project.lights.iter().enumerate() {
            let key = (light.position, generation, scheme, project.propagation.sweep_stride);
            if light_is_negligible(project, light) {
                counters.lights_skipped += 1;
                counters.lights_culled += 1;
            } else if light.hidden || light.intensity <= 0.0 || self.baked.opv_inputs[i] == Some(key) {
                counters.lights_skipped += 1;
            } else {
                active.push(i as u32);
                self.baked.opv_inputs[i] = Some(key);
            }
        }
        if active.is_empty() {
            return Ok(());
        }
        let positions: Vec<glam::Vec3> = project.lights.iter().map(|l| l.position).collect();
        let inputs = PropagationInputs {
            grid: &g.spec,
            grid_buf: &g.grid_buf,
            ev_view: &g.ev_view,
            lights_buf: &g.lights_buf,
            opv: &g.opv,
            positions: &positions,
            sweep_stride: project.propagation.sweep_stride,
        };
        let mut encoder = self.ctx.device.create_command_encoder(&Default::default());
        let timestamps = self.timer.as_ref().map(|t| t.writes(timer::PROPAGATE));
        self.propagator.encode(&self.ctx.device, &mut encoder, &inputs, scheme, &active, timestamps, counters);
        if let Some(t) = &self.timer {
            t.resolve(&mut encoder, timer::PROPAGATE);
        }
        self.ctx.queue.submit([encoder.finish()]);
        self.ctx.wait()
    }

    fn ensure_image(&mut self, width: u32, height: u32) {
        if let Some(img) = &self.image {
            if img.width == width && img.height == height {
                return;
            }
        }
        let device = &self.ctx.device;
        let make = |label: &str, format: wgpu::TextureFormat, extra: wgpu::TextureUsages| {
            device.create_texture(&wgpu::TextureDescriptor {
                label: Some(label),
                size: wgpu::Extent3d { width, height, depth_or_array_layers: 1 },
                mip_level_count: 1,
                sample_count: 1,
                dimension: wgpu::TextureDimension::D2,
                format,
                usage: wgpu::TextureUsages::STORAGE_BINDING | wgpu::TextureUsages::TEXTURE_BINDING | extra,
                view_formats: &[],
            })
        };
        let hdr = make("radiance (linear)", wgpu::TextureFormat::Rgba32Float, wgpu::TextureUsages::COPY_SRC);
        let ldr = make("radiance (tone-mapped)", wgpu::TextureFormat::Rgba8Unorm, wgpu::TextureUsages::COPY_SRC);
        let ldr_view = ldr.create_view(&Default::default());
        let params_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("march params"),
            size: std::mem::size_of::<MarchParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        self.image = Some(ImageResources { width, height, hdr, ldr_view, params_buf });
    }

    fn run_march(&mut self, project: &Project, request: &FrameRequest, counters: &mut Counters) -> Result<(), GpuError> {
        self.ensure_image(request.width, request.height);
        let (Some(g), Some(img)) = (&self.grid, &self.image) else { return Ok(()) };
        let device = &self.ctx.device;
        let surfaces = surfaces_gpu(project);
        let surfaces_buf = storage_buffer(device, "surfaces", bytemuck::cast_slice(&surfaces));
        let params = march_params(project, request.width, request.height, surfaces.len() as u32);
        self.ctx.queue.write_buffer(&img.params_buf, 0, bytemuck::bytes_of(&params));
        self.ctx.queue.write_buffer(&self.counters_buf, 0, &[0u8; 16]);
        let counters_binding = self.counters_buf.as_entire_binding();
        let hdr_view = img.hdr.create_view(&Default::default());
        let bg = bind_group(
            device,
            "march",
            &self.march_layout,
            &[
                g.grid_buf.as_entire_binding(),
                img.params_buf.as_entire_binding(),
                wgpu::BindingResource::TextureView(&g.ev_view),
                g.lights_buf.as_entire_binding(),
                g.opv[0].as_entire_binding(),
                wgpu::BindingResource::TextureView(&hdr_view),
                wgpu::BindingResource::TextureView(&img.ldr_view),
                counters_binding,
                g.brick_max.as_entire_binding(),
                surfaces_buf.as_entire_binding(),
                self.sun_table.as_entire_binding(),
            ],
        );
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("march"),
                timestamp_writes: self.timer.as_ref().map(|t| t.writes(timer::MARCH)),
            });
            pass.set_pipeline(&self.march);
            pass.set_bind_group(0, &bg, &[]);
            pass.dispatch_workgroups(request.width.div_ceil(8), request.height.div_ceil(8), 1);
        }
        if let Some(t) = &self.timer {
            t.resolve(&mut encoder, timer::MARCH);
        }
        self.ctx.queue.submit([encoder.finish()]);
        self.ctx.wait()?;
        let c: Vec<u32> = read_buffer(&self.ctx, &self.counters_buf, 0, 4)?;
        counters.samples_marched += c[0] as u64;
        counters.bricks_skipped += c[1] as u64;
        counters.rays_terminated += c[2] as u64;
        counters.dispatches += 1;
        Ok(())
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
        let n = g.spec.cell_count();
        let data = read_buffer(&self.ctx, &g.opv[0], light as u64 * n * 4, n as usize)?;
        Ok(Volume::new(g.spec, data))
    }

    /// The last rendered frame as linear HDR radiance.
    pub fn read_image(&self) -> Result<Image, GpuError> {
        let img = self.image.as_ref().ok_or_else(|| GpuError::Invalid("nothing rendered yet: call update first".into()))?;
        let rgba = read_texture(&self.ctx, &img.hdr, [img.width, img.height, 1], 16)?;
        Ok(Image { width: img.width, height: img.height, rgba })
    }

    /// The tone-mapped frame (rgba8unorm), for display by the editor without a CPU round trip.
    pub fn display_view(&self) -> Option<&wgpu::TextureView> {
        self.image.as_ref().map(|i| &i.ldr_view)
    }

    /// Size in bytes of the GPU resources the pipeline holds for the current scene.
    pub fn memory_bytes(&self) -> u64 {
        let grid = self.grid.as_ref().map_or(0, |g| g.spec.cell_count() * 4 * (1 + 2 * g.light_count.max(1) as u64));
        let image = self.image.as_ref().map_or(0, |i| i.width as u64 * i.height as u64 * 20);
        grid + image
    }
}

fn ms(t: Instant) -> f64 {
    t.elapsed().as_secs_f64() * 1e3
}

fn light_gpu(l: &Light, culled: bool) -> LightGpu {
    let rgb = if l.hidden || culled { glam::Vec3::ZERO } else { l.radiance_rgb() };
    LightGpu { position: l.position.to_array(), _pad0: 0.0, rgb: rgb.to_array(), _pad1: 0.0 }
}

/// The lights buffer and the two OPV buffers (result and scratch) for `light_count` lights.
fn light_buffers(device: &wgpu::Device, spec: &GridSpec, light_count: usize) -> (wgpu::Buffer, [wgpu::Buffer; 2]) {
    let opv_size = spec.cell_count() * light_count.max(1) as u64 * 4;
    let opv = ["optical depth A", "optical depth B"].map(|label| {
        device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size: opv_size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        })
    });
    let lights_buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("lights"),
        size: (light_count.max(1) * std::mem::size_of::<LightGpu>()) as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    (lights_buf, opv)
}

/// Radiance below which a light's whole contribution is dropped: the tone-mapped display
/// changes by less than exposure × this, far below one 8-bit step.
pub const CULL_RADIANCE: f32 = 1e-6;

/// Whether light `l` provably adds less than [`CULL_RADIANCE`] / exposure to every pixel.
/// Only possible without base fog and surfaces: then light is scattered only inside the grid,
/// and a pixel receives at most I·albedo·max(phase) / d² (d: the light's distance to the grid
/// box), since ∫σ_t·exp(−τ) along a ray is below 1.
pub fn light_is_negligible(project: &Project, l: &Light) -> bool {
    if project.medium.base_extinction > 0.0 || !project.surfaces.is_empty() || project.base_volume.is_some() {
        return false;
    }
    let g = project.grid;
    let d2 = (l.position - l.position.clamp(g.min, g.max)).length_squared();
    let gm = project.medium.anisotropy.abs();
    let max_phase = (1.0 + gm) / (4.0 * std::f32::consts::PI * (1.0 - gm).powi(2));
    let bound = l.radiance_rgb().max_element() * project.medium.albedo * max_phase / d2;
    bound * project.render.exposure.max(1e-6) < CULL_RADIANCE
}

fn particle_gpu(p: &Particle) -> ParticleGpu {
    let r = binning::cutoff_radius(p);
    ParticleGpu {
        center: p.center.to_array(),
        inv_r2: 1.0 / (p.radius * p.radius),
        density: if p.hidden { 0.0 } else { p.density },
        cutoff2: r * r,
        _pad: [0.0; 2],
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
            kind: 0,
            max: b.max.to_array(),
            _pad0: 0.0,
            albedo: b.albedo.to_array(),
            _pad1: 0.0,
        })
        .collect();
    if let Some(g) = &project.surfaces.ground {
        out.push(SurfaceGpu {
            min: [0.0, g.height, 0.0],
            kind: 1,
            max: [0.0; 3],
            _pad0: 0.0,
            albedo: g.albedo.to_array(),
            _pad1: 0.0,
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
    let far_distance = if base > 0.0 { (18.42 / base).min(20.0 * project.grid.size().length()) } else { 0.0 };
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
            StepPolicy::Fixed => 0,
            StepPolicy::TwoLevel => 1,
            StepPolicy::Adaptive => 2,
        },
        near_steps: r.near_steps,
        far_steps: r.far_steps,
        skip_empty: r.skip_empty as u32,
        tau_target: r.tau_target,
        near_fraction: r.near_fraction,
        min_step: 0.25 * step,
        max_step: 4.0 * step,
        surface_count,
        _pad: [0; 3],
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

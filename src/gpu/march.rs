//! The ray-march stage: single scattering along camera rays (`shaders/march.wgsl`) into an
//! [`ImageTarget`], in bands so that the work can be spread over several submits and frames:
//! whole rows of workgroups, or, where the time left holds less than one such row, part of one
//! (on a software adapter one row of workgroups of a large image costs more than a frame).
//!
//! [`Marcher`] is long-lived: it owns the pipelines, their layout, Sun et al.'s F table and the
//! counters; the per-march inputs (grid, EV, lights, OPVs, occupancy) are passed explicitly.
//! The march is compiled once per [`MarchFeatures`] a scene needs, when first needed.

use super::gpu_types::{GridParams, LightGpu, MarchParams, SurfaceGpu};
use super::image_sampling::{ImageSampler, ImageSampling, SamplingBuffers, LATTICE, LEVELS};
use super::layout::{
    bind_group_layout_with, bind_group_with, compute_pipeline_with, entry, Slot, LIGHT_DIRECTIONAL, LIGHT_SPOT,
    WORKGROUP_2D,
};

use super::opv_store::{OpvLayout, OpvVolumes, EXTRA_BINDING};
use super::readback::read_buffer;
use super::{Counters, GpuContext, GpuError};
use crate::sun_table::{FTable, GPU_TABLE_SIZE};

/// Rows of one march workgroup: bands are multiples of it.
pub const BAND_ROWS: u32 = WORKGROUP_2D;

/// Linear and tone-mapped radiance of one image size.
pub struct ImageTarget {
    pub width: u32,
    pub height: u32,
    pub hdr: wgpu::Texture,
    pub(super) hdr_view: wgpu::TextureView,
    pub ldr_view: wgpu::TextureView,
    params_buf: wgpu::Buffer,
    /// Adaptive sampling's buffers, made by the first adaptive march into this target.
    sampling: Option<SamplingBuffers>,
}

impl ImageTarget {
    pub fn new(device: &wgpu::Device, width: u32, height: u32) -> Self {
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
        let params_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("march params"),
            size: std::mem::size_of::<MarchParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        Self {
            width,
            height,
            hdr_view: hdr.create_view(&Default::default()),
            ldr_view: ldr.create_view(&Default::default()),
            hdr,
            params_buf,
            sampling: None,
        }
    }

    /// Bytes of GPU memory the target holds.
    pub fn bytes(&self) -> u64 {
        self.width as u64 * self.height as u64 * 20
            + self.params_buf.size()
            + self.sampling.as_ref().map_or(0, |s| s.bytes())
    }

    /// Makes the buffers of adaptive sampling, unless there are some.
    pub fn ensure_sampling(&mut self, device: &wgpu::Device, sampler: &ImageSampler) {
        if self.sampling.is_none() {
            self.sampling = Some(SamplingBuffers::new(device, sampler, self.width, self.height));
        }
    }
}

/// What one march reads besides its image target.
pub struct MarchInputs<'a> {
    pub grid_buf: &'a wgpu::Buffer,
    pub ev_view: &'a wgpu::TextureView,
    pub lights_buf: &'a wgpu::Buffer,
    /// The lookup volumes (`march_lookup`), bound where the march reads optical depths.
    pub lookup: &'a OpvVolumes,
    pub brick_max: &'a wgpu::Buffer,
    pub surfaces: &'a [SurfaceGpu],
    /// What the scene needs of the march: at most what `lights`, `surfaces` and the grid hold.
    pub features: MarchFeatures,
    /// Whether the march uses [`MarchFeatures::ALL`] whatever `features` says
    /// (`Tuning::general_march`).
    pub general: bool,
    /// Whether base fog tests every surface (`Tuning::exhaustive_fog_shadows`).
    pub exhaustive_fog_shadows: bool,
    pub params: MarchParams,
    /// The lights, whose epipoles adaptive sampling refines to single pixels.
    pub lights: &'a [LightGpu],
    /// The multiple-scattering moments (`scattering`), read where `params.scatter_factor` > 0.
    pub scatter: &'a wgpu::Buffer,
    pub sampling: ImageSampling,
}

/// The parts of the march a scene uses (the `override` constants of `shaders/march.wgsl`). All
/// of the march is inlined into one loop, and on software adapters the code for a light kind
/// or medium a scene lacks still slows every sample, so each combination in use gets its own
/// pipeline; any scene renders the same with all of them on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct MarchFeatures {
    pub spot_lights: bool,
    pub sun_lights: bool,
    /// Base fog outside the grid.
    pub base_fog: bool,
    /// Base fog that thins with height (`shaders/common.wgsl`'s `height_fog`).
    pub height_fog: bool,
    /// Surfaces, which shadow the fog.
    pub surfaces: bool,
    /// In base fog outside the grid, point and spot lights test only the surfaces that can hide
    /// them from the segment marched; off, every surface (the same image, for tests).
    pub cull_fog_surfaces: bool,
    /// Multiple scattering inside the grid.
    pub multiple_scattering: bool,
}

impl MarchFeatures {
    /// Everything: the march any scene can use.
    pub const ALL: Self = Self {
        spot_lights: true,
        sun_lights: true,
        base_fog: true,
        height_fog: true,
        surfaces: true,
        cull_fog_surfaces: true,
        multiple_scattering: true,
    };

    /// What a scene of these lights, surfaces and grid uses.
    pub fn of(lights: &[LightGpu], surfaces: &[SurfaceGpu], grid: &GridParams, params: &MarchParams) -> Self {
        Self {
            spot_lights: lights.iter().any(|l| l.kind == LIGHT_SPOT),
            sun_lights: lights.iter().any(|l| l.kind == LIGHT_DIRECTIONAL),
            base_fog: grid.base_extinction > 0.0,
            height_fog: grid.height_falloff != 0.0,
            surfaces: !surfaces.is_empty(),
            cull_fog_surfaces: true,
            multiple_scattering: params.scatter_factor > 0,
        }
    }

    fn constants(&self) -> [(&'static str, f64); 7] {
        let on = |b: bool| if b { 1.0 } else { 0.0 };
        [
            ("spot_lights", on(self.spot_lights)),
            ("sun_lights", on(self.sun_lights)),
            ("base_fog", on(self.base_fog)),
            ("height_fog", on(self.height_fog)),
            ("fog_shadows", on(self.surfaces)),
            ("fog_culling", on(self.cull_fog_surfaces)),
            ("multiple_scattering", on(self.multiple_scattering)),
        ]
    }
}

/// A march in progress: per pixel, the rows above `next_row` are done, and in the band of
/// [`BAND_ROWS`] rows from there, the columns left of `next_col`; with adaptive sampling, as
/// its [`AdaptiveJob`] says.
pub struct MarchJob {
    bind_group: wgpu::BindGroup,
    features: MarchFeatures,
    params: MarchParams,
    pub next_row: u32,
    next_col: u32,
    adaptive: Option<AdaptiveJob>,
    /// A readback between refinement levels that failed; the march stops there.
    error: Option<GpuError>,
}

/// The rays [`Self::next`, `Self::count`) of level [`Self::level`] are left to march:
/// level 0 is the first lattice, level l the list that refining the lattice of stride
/// `LATTICE >> (l - 1)` gathered.
struct AdaptiveJob {
    level: u32,
    next: u32,
    count: u32,
    classified: bool,
    finished: bool,
}

impl MarchJob {
    pub fn done(&self) -> bool {
        match &self.adaptive {
            Some(a) => a.finished,
            None => self.next_row >= self.params.size[1],
        }
    }
    pub fn fraction(&self) -> f64 {
        if let Some(a) = &self.adaptive {
            if a.finished {
                return 1.0;
            }
            let within = a.next as f64 / a.count.max(1) as f64;
            return ((a.level as f64 + within) / (LEVELS + 1) as f64).min(1.0);
        }
        let [w, h] = self.params.size;
        let rows = self.next_row as f64 + self.next_col as f64 / w.max(1) as f64 * BAND_ROWS as f64;
        (rows / h.max(1) as f64).min(1.0)
    }
    /// Stops the march where it is (its target is gone).
    pub fn abandon(&mut self) {
        self.next_row = self.params.size[1];
        if let Some(a) = self.adaptive.as_mut() {
            a.finished = true;
        }
    }

    /// The error that stopped the march, if any.
    pub fn take_error(&mut self) -> Option<GpuError> {
        self.error.take()
    }
}

/// The march's entry points (`shaders/march.wgsl`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Entry {
    /// One ray per pixel.
    PerPixel,
    /// Adaptive sampling: geometry classes, rays of a lattice or list, the image.
    Classify,
    List,
    Resolve,
}

impl Entry {
    fn name(self) -> &'static str {
        match self {
            Self::PerPixel => "main",
            Self::Classify => "classify",
            Self::List => "main_list",
            Self::Resolve => "resolve",
        }
    }
}

/// Workgroup of `main_list`.
const LIST_WORKGROUP: u32 = 64;

pub struct Marcher {
    layout: wgpu::BindGroupLayout,
    /// The march per combination of features and entry point used so far.
    pipelines: Vec<(MarchFeatures, Entry, wgpu::ComputePipeline)>,
    sampler: ImageSampler,
    /// Bound as adaptive sampling's buffers by per-pixel marches, which do not read them.
    unused: wgpu::Buffer,
    /// The WGSL they are built from.
    code: String,
    /// Sun et al.'s F table (remapped layout) for the closed-form base fog, then the G table
    /// of their surface term.
    sun_table: wgpu::Buffer,
    counters_buf: wgpu::Buffer,
    surfaces_buf: wgpu::Buffer,
}

impl Marcher {
    pub fn new(device: &wgpu::Device, opv: OpvLayout) -> Self {
        let layout = bind_group_layout_with(
            device,
            "march",
            &[
                Slot::Uniform,
                Slot::Uniform,
                Slot::StorageTexture3dRead(wgpu::TextureFormat::R32Float),
                Slot::StorageRead,
                Slot::Opv { read_only: true },
                Slot::StorageTexture2d(wgpu::TextureFormat::Rgba32Float),
                Slot::StorageTexture2d(wgpu::TextureFormat::Rgba8Unorm),
                Slot::StorageWrite,
                Slot::StorageRead,
                Slot::StorageRead,
                Slot::StorageRead,
            ],
            {
                let mut extra = opv.layout_entries(EXTRA_BINDING, true);
                extra.extend([12, 13].map(|binding| entry(binding, Slot::StorageWrite)));
                extra.push(entry(14, Slot::StorageRead));
                extra
            },
        );
        let code = super::shaders::march(&opv);
        let mut tables = FTable::remapped(GPU_TABLE_SIZE, GPU_TABLE_SIZE).data;
        tables.extend_from_slice(crate::surface_table::glow_table());
        tables.extend_from_slice(crate::surface_table::spec_table());
        let sun_table = super::buffers::storage_buffer(device, "sun F, G and S tables", bytemuck::cast_slice(&tables));
        let counters_buf = super::buffers::storage_buffer(device, "counters", &[0u8; 16]);
        let surfaces_buf = super::buffers::storage_buffer(device, "surfaces", &[]);
        let sampler = ImageSampler::new(device);
        let unused = super::buffers::storage_buffer(device, "unused image samples", &[0u8; 16]);
        Self { layout, pipelines: Vec::new(), sampler, unused, code, sun_table, counters_buf, surfaces_buf }
    }

    /// The pipeline of `entry` for `features`, built on first use.
    fn ensure_pipeline(&mut self, device: &wgpu::Device, features: MarchFeatures, entry: Entry) {
        if !self.pipelines.iter().any(|(f, e, _)| *f == features && *e == entry) {
            let code = self.code.clone();
            let pipeline =
                compute_pipeline_with(device, "march", code, &self.layout, entry.name(), &features.constants());
            self.pipelines.push((features, entry, pipeline));
        }
    }

    fn pipeline(&self, features: MarchFeatures, entry: Entry) -> &wgpu::ComputePipeline {
        self.pipelines
            .iter()
            .find(|(f, e, _)| *f == features && *e == entry)
            .map(|(_, _, p)| p)
            .expect("begin builds the pipelines of every job's features")
    }

    /// Uploads the inputs of a march into `target` and returns the job; its counters start at 0.
    pub fn begin(&mut self, ctx: &GpuContext, target: &mut ImageTarget, inputs: &MarchInputs) -> MarchJob {
        let device = &ctx.device;
        let adaptive = match inputs.sampling {
            ImageSampling::PerPixel => None,
            ImageSampling::Adaptive { tolerance } => {
                target.ensure_sampling(device, &self.sampler);
                let sampling = target.sampling.as_ref().expect("made above");
                let epipoles =
                    super::image_sampling::epipoles(&inputs.params, inputs.lights, target.width, target.height);
                sampling.write_params(&ctx.queue, tolerance, &epipoles);
                let count = super::image_sampling::lattice_rays(sampling.padded);
                Some(AdaptiveJob { level: 0, next: 0, count, classified: false, finished: false })
            }
        };
        let (samples, work) = match &target.sampling {
            Some(s) if adaptive.is_some() => (&s.samples, &s.work),
            _ => (&self.unused, &self.unused),
        };
        let bytes: &[u8] = bytemuck::cast_slice(inputs.surfaces);
        if bytes.len() as u64 > self.surfaces_buf.size() {
            self.surfaces_buf = super::buffers::storage_buffer(device, "surfaces", bytes);
        } else if !bytes.is_empty() {
            ctx.queue.write_buffer(&self.surfaces_buf, 0, bytes);
        }
        ctx.queue.write_buffer(&self.counters_buf, 0, &[0u8; 16]);
        let bind_group = bind_group_with(
            device,
            "march",
            &self.layout,
            &[
                inputs.grid_buf.as_entire_binding(),
                target.params_buf.as_entire_binding(),
                wgpu::BindingResource::TextureView(inputs.ev_view),
                inputs.lights_buf.as_entire_binding(),
                inputs.lookup.first(),
                wgpu::BindingResource::TextureView(&target.hdr_view),
                wgpu::BindingResource::TextureView(&target.ldr_view),
                self.counters_buf.as_entire_binding(),
                inputs.brick_max.as_entire_binding(),
                self.surfaces_buf.as_entire_binding(),
                self.sun_table.as_entire_binding(),
            ],
            {
                let mut extra = inputs.lookup.extra_entries(EXTRA_BINDING);
                extra.push(wgpu::BindGroupEntry { binding: 12, resource: samples.as_entire_binding() });
                extra.push(wgpu::BindGroupEntry { binding: 13, resource: work.as_entire_binding() });
                extra.push(wgpu::BindGroupEntry { binding: 14, resource: inputs.scatter.as_entire_binding() });
                extra
            },
        );
        let features = MarchFeatures {
            cull_fog_surfaces: !inputs.exhaustive_fog_shadows,
            ..if inputs.general { MarchFeatures::ALL } else { inputs.features }
        };
        let entries: &[Entry] =
            if adaptive.is_some() { &[Entry::Classify, Entry::List, Entry::Resolve] } else { &[Entry::PerPixel] };
        for &entry in entries {
            self.ensure_pipeline(device, features, entry);
        }
        let mut params = inputs.params;
        if let Some(s) = target.sampling.as_ref().filter(|_| adaptive.is_some()) {
            [params.padded_width, params.padded_height] = s.padded;
        }
        MarchJob { bind_group, features, params, next_row: 0, next_col: 0, adaptive, error: None }
    }

    /// Encodes the next band of `job`, about `pixels` pixels (at least one workgroup): whole
    /// rows of workgroups where that many fit, else part of one. Returns the pixels it covers.
    /// Each band is its own submit: its offsets live in the target's uniform.
    pub fn encode_band(
        &self,
        ctx: &GpuContext,
        target: &ImageTarget,
        encoder: &mut wgpu::CommandEncoder,
        job: &mut MarchJob,
        pixels: u64,
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
    ) -> u64 {
        if job.adaptive.is_some() {
            return self.encode_adaptive(ctx, target, encoder, job, pixels, timestamps);
        }
        let [width, height] = job.params.size;
        let left = height - job.next_row;
        let row_pixels = width as u64 * BAND_ROWS.min(left) as u64;
        let params = MarchParams { row_offset: job.next_row, col_offset: job.next_col, ..job.params };
        let (groups, covered) = if job.next_col == 0 && pixels >= row_pixels {
            let rows = (pixels / width as u64).min(left as u64) as u32;
            let band = if rows >= left { left } else { rows / BAND_ROWS * BAND_ROWS };
            job.next_row += band;
            ((width.div_ceil(WORKGROUP_2D), band.div_ceil(WORKGROUP_2D)), band as u64 * width as u64)
        } else {
            let rows = BAND_ROWS.min(left);
            let cols = ((pixels / rows as u64).min(width as u64) as u32 / WORKGROUP_2D * WORKGROUP_2D)
                .max(WORKGROUP_2D)
                .min(width - job.next_col);
            job.next_col += cols;
            if job.next_col >= width {
                job.next_col = 0;
                job.next_row += rows;
            }
            ((cols.div_ceil(WORKGROUP_2D), 1), cols as u64 * rows as u64)
        };
        ctx.queue.write_buffer(&target.params_buf, 0, bytemuck::bytes_of(&params));
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("march"),
                timestamp_writes: timestamps,
            });
            pass.set_pipeline(self.pipeline(job.features, Entry::PerPixel));
            pass.set_bind_group(0, &job.bind_group, &[]);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        covered
    }

    /// [`Self::encode_band`] with adaptive sampling: about `pixels` rays of the current level.
    /// A level whose rays are all encoded is refined at the start of the next call (its rays
    /// must have run first), with a submit and a readback of the new list's length; the last
    /// level's band also writes the image.
    fn encode_adaptive(
        &self,
        ctx: &GpuContext,
        target: &ImageTarget,
        encoder: &mut wgpu::CommandEncoder,
        job: &mut MarchJob,
        pixels: u64,
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
    ) -> u64 {
        let (Some(a), Some(buffers)) = (job.adaptive.as_mut(), target.sampling.as_ref()) else { return 0 };
        if a.finished {
            return 0;
        }
        while a.next >= a.count && a.level < LEVELS {
            match self.sampler.refine(ctx, buffers, a.level) {
                Ok(count) => *a = AdaptiveJob { level: a.level + 1, next: 0, count, ..*a },
                Err(e) => {
                    job.error = Some(e);
                    a.finished = true;
                    return 0;
                }
            }
        }
        let end = (a.next as u64 + pixels.max(LIST_WORKGROUP as u64)).min(a.count as u64) as u32;
        let params = MarchParams {
            list_offset: a.next,
            list_end: end,
            lattice_stride: if a.level == 0 { LATTICE } else { 0 },
            ..job.params
        };
        ctx.queue.write_buffer(&target.params_buf, 0, bytemuck::bytes_of(&params));
        let covered = (end - a.next) as u64;
        let resolve = end >= a.count && a.level == LEVELS;
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("march"), timestamp_writes: timestamps });
        pass.set_bind_group(0, &job.bind_group, &[]);
        if !a.classified {
            let [pw, ph] = buffers.padded;
            pass.set_pipeline(self.pipeline(job.features, Entry::Classify));
            pass.dispatch_workgroups(pw.div_ceil(WORKGROUP_2D), ph.div_ceil(WORKGROUP_2D), 1);
            a.classified = true;
        }
        if covered > 0 {
            let groups = (covered as u32).div_ceil(LIST_WORKGROUP);
            let x = groups.min(ctx.limits.max_compute_workgroups_per_dimension);
            pass.set_pipeline(self.pipeline(job.features, Entry::List));
            pass.dispatch_workgroups(x, groups.div_ceil(x), 1);
        }
        a.next = end;
        if resolve {
            let [w, h] = job.params.size;
            pass.set_pipeline(self.pipeline(job.features, Entry::Resolve));
            pass.dispatch_workgroups(w.div_ceil(WORKGROUP_2D), h.div_ceil(WORKGROUP_2D), 1);
            a.finished = true;
        }
        covered
    }

    /// Adds the counters of the finished march to `counters`.
    pub fn read_counters(&self, ctx: &GpuContext, counters: &mut Counters) -> Result<(), GpuError> {
        let c: Vec<u32> = read_buffer(ctx, &self.counters_buf, 0, 4)?;
        counters.samples_marched += c[0] as u64;
        counters.bricks_skipped += c[1] as u64;
        counters.rays_terminated += c[2] as u64;
        counters.rays_marched += c[3] as u64;
        Ok(())
    }

    pub fn bytes(&self) -> u64 {
        self.sun_table.size() + self.counters_buf.size() + self.surfaces_buf.size()
    }
}

//! The ray-march stage: single scattering along camera rays (`shaders/march.wgsl`) into an
//! [`ImageTarget`], in bands so that the work can be spread over several submits and frames:
//! whole rows of workgroups, or, where the time left holds less than one such row, part of one
//! (on a software adapter one row of workgroups of a large image costs more than a frame).
//!
//! [`Marcher`] is long-lived: it owns the pipelines, their layout, Sun et al.'s F table and the
//! counters; the per-march inputs (grid, EV, lights, OPVs, occupancy) are passed explicitly.
//! The march is compiled once per [`MarchFeatures`] a scene needs, when first needed.

use super::gpu_types::{GridParams, LightGpu, MarchParams, SurfaceGpu};
use super::layout::{
    bind_group_layout_with, bind_group_with, compute_pipeline_with, Slot, LIGHT_DIRECTIONAL, LIGHT_SPOT, WORKGROUP_2D,
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
        }
    }

    /// Bytes of GPU memory the target holds.
    pub fn bytes(&self) -> u64 {
        self.width as u64 * self.height as u64 * 20 + self.params_buf.size()
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
    };

    /// What a scene of these lights, surfaces and grid uses.
    pub fn of(lights: &[LightGpu], surfaces: &[SurfaceGpu], grid: &GridParams) -> Self {
        Self {
            spot_lights: lights.iter().any(|l| l.kind == LIGHT_SPOT),
            sun_lights: lights.iter().any(|l| l.kind == LIGHT_DIRECTIONAL),
            base_fog: grid.base_extinction > 0.0,
            height_fog: grid.height_falloff != 0.0,
            surfaces: !surfaces.is_empty(),
            cull_fog_surfaces: true,
        }
    }

    fn constants(&self) -> [(&'static str, f64); 6] {
        let on = |b: bool| if b { 1.0 } else { 0.0 };
        [
            ("spot_lights", on(self.spot_lights)),
            ("sun_lights", on(self.sun_lights)),
            ("base_fog", on(self.base_fog)),
            ("height_fog", on(self.height_fog)),
            ("fog_shadows", on(self.surfaces)),
            ("fog_culling", on(self.cull_fog_surfaces)),
        ]
    }
}

/// A march in progress: the rows above `next_row` are done, and in the band of
/// [`BAND_ROWS`] rows from there, the columns left of `next_col`.
pub struct MarchJob {
    bind_group: wgpu::BindGroup,
    features: MarchFeatures,
    params: MarchParams,
    pub next_row: u32,
    next_col: u32,
}

impl MarchJob {
    pub fn done(&self) -> bool {
        self.next_row >= self.params.size[1]
    }
    pub fn fraction(&self) -> f64 {
        let [w, h] = self.params.size;
        let rows = self.next_row as f64 + self.next_col as f64 / w.max(1) as f64 * BAND_ROWS as f64;
        (rows / h.max(1) as f64).min(1.0)
    }
}

pub struct Marcher {
    layout: wgpu::BindGroupLayout,
    /// The march per combination of features used so far.
    pipelines: Vec<(MarchFeatures, wgpu::ComputePipeline)>,
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
            opv.layout_entries(EXTRA_BINDING, true),
        );
        let code = super::shaders::march(&opv);
        let mut tables = FTable::remapped(GPU_TABLE_SIZE, GPU_TABLE_SIZE).data;
        tables.extend_from_slice(crate::surface_table::glow_table());
        tables.extend_from_slice(crate::surface_table::spec_table());
        let sun_table = super::buffers::storage_buffer(device, "sun F, G and S tables", bytemuck::cast_slice(&tables));
        let counters_buf = super::buffers::storage_buffer(device, "counters", &[0u8; 16]);
        let surfaces_buf = super::buffers::storage_buffer(device, "surfaces", &[]);
        Self { layout, pipelines: Vec::new(), code, sun_table, counters_buf, surfaces_buf }
    }

    /// Uploads the inputs of a march into `target` and returns the job; its counters start at 0.
    pub fn begin(&mut self, ctx: &GpuContext, target: &ImageTarget, inputs: &MarchInputs) -> MarchJob {
        let device = &ctx.device;
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
            inputs.lookup.extra_entries(EXTRA_BINDING),
        );
        let features = MarchFeatures {
            cull_fog_surfaces: !inputs.exhaustive_fog_shadows,
            ..if inputs.general { MarchFeatures::ALL } else { inputs.features }
        };
        if !self.pipelines.iter().any(|(f, _)| *f == features) {
            let code = self.code.clone();
            let pipeline = compute_pipeline_with(device, "march", code, &self.layout, "main", &features.constants());
            self.pipelines.push((features, pipeline));
        }
        MarchJob { bind_group, features, params: inputs.params, next_row: 0, next_col: 0 }
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
            let pipeline = self.pipelines.iter().find(|(f, _)| *f == job.features).map(|(_, p)| p);
            pass.set_pipeline(pipeline.expect("begin builds the pipeline of every job's features"));
            pass.set_bind_group(0, &job.bind_group, &[]);
            pass.dispatch_workgroups(groups.0, groups.1, 1);
        }
        covered
    }

    /// Adds the counters of the finished march to `counters`.
    pub fn read_counters(&self, ctx: &GpuContext, counters: &mut Counters) -> Result<(), GpuError> {
        let c: Vec<u32> = read_buffer(ctx, &self.counters_buf, 0, 4)?;
        counters.samples_marched += c[0] as u64;
        counters.bricks_skipped += c[1] as u64;
        counters.rays_terminated += c[2] as u64;
        Ok(())
    }

    pub fn bytes(&self) -> u64 {
        self.sun_table.size() + self.counters_buf.size() + self.surfaces_buf.size()
    }
}

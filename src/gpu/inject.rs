//! The injection stage: particles (binned on the CPU, see `binning`; the noisy ones modulated
//! by `shaders/noise.wgsl`) and the base fog and layer into the extinction volume
//! (`shaders/inject.wgsl`), then the brick occupancy the march skips empty space with
//! (`shaders/occupancy.wgsl`).
//!
//! The dirty 8³ bricks are cut into memory chunks whose particle–bin lists fit the chunk
//! limit (at most one storage binding); each chunk's lists and particles are built and
//! uploaded when the injection reaches it. Every cell is written once, by the chunk holding
//! its brick, summing its particles in scene order, so the EV is the same bit for bit
//! whatever the chunking. Within a chunk, work is further sliced to fit a frame budget.
//!
//! [`Injector`] is long-lived: it owns both pipelines, their layouts and the particle and
//! bin buffers, which it reuses across updates and grows only when a chunk outgrows them.

use super::binning::{self, BinCounts};
use super::gpu_types::ParticleGpu;
use super::host_sums;
use super::layout::{bind_group, bind_group_layout, compute_pipeline, Slot, WORKGROUP_3D};
use super::shaders;
use super::{Counters, GpuContext};
use crate::scene::GridSpec;
use crate::scene::Particle;

/// What one injection reads besides the particles.
pub struct InjectInputs<'a> {
    pub grid: &'a GridSpec,
    pub grid_buf: &'a wgpu::Buffer,
    pub ev_view: &'a wgpu::TextureView,
    pub brick_max: &'a wgpu::Buffer,
    /// The imported density layer, or None.
    pub layer: Option<&'a wgpu::Buffer>,
}

/// Dirty bricks still to inject; the occupancy pass runs after the last chunk.
pub struct InjectJob {
    pub bricks: Vec<u32>,
    pub next: usize,
    particles: Vec<Particle>,
    gpu_particles: Vec<ParticleGpu>,
    counts: BinCounts,
    /// Particle–cell evaluations of each entry of `bricks`.
    evaluations: Vec<u64>,
    /// End (into `bricks`) of each memory chunk, ascending; the last is `bricks.len()`.
    chunk_ends: Vec<usize>,
    /// The chunk whose lists are on the GPU.
    uploaded: Option<usize>,
    /// Largest list and particle buffers a chunk used, in bytes.
    pub peak_chunk_bytes: u64,
    /// On the host path, the particles in the host's order: the host computes the particle
    /// sums ([`host_sums`]), call by call, instead of the adapter evaluating binned lists.
    ordered: Option<host_sums::Ordered>,
    occupancy_done: bool,
}

impl InjectJob {
    pub fn done(&self) -> bool {
        self.occupancy_done
    }
    fn host(&self) -> bool {
        self.ordered.is_some()
    }
    pub fn fraction(&self) -> f64 {
        self.next as f64 / self.bricks.len().max(1) as f64
    }
}

/// Cells of brick `b` inside the grid.
fn brick_cells(grid: &GridSpec, b: u32) -> u64 {
    let dims = binning::brick_dims(grid);
    let at = glam::UVec3::new(b % dims.x, (b / dims.x) % dims.y, b / (dims.x * dims.y));
    let n = grid.resolution;
    (0..3).map(|a| (n[a] - at[a] * binning::BRICK).min(binning::BRICK) as u64).product()
}

pub struct Injector {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    /// `shaders/inject_sums.wgsl`: the host's particle sums into the EV (same layout).
    sums_pipeline: wgpu::ComputePipeline,
    occupancy_layout: wgpu::BindGroupLayout,
    occupancy: wgpu::ComputePipeline,
    particles: wgpu::Buffer,
    offsets: wgpu::Buffer,
    items: wgpu::Buffer,
    bricks: wgpu::Buffer,
    sums: wgpu::Buffer,
    no_layer: wgpu::Buffer,
}

/// Writes `bytes` into `buf`, replacing it by a larger one when it is too small (1.5×
/// headroom, within one storage binding).
fn upload(ctx: &GpuContext, buf: &mut wgpu::Buffer, label: &str, bytes: &[u8]) {
    if bytes.len() as u64 > buf.size() {
        let binding = ctx.max_binding_bytes();
        let len = (bytes.len() as u64).next_multiple_of(4);
        let size = (len * 3 / 2).next_multiple_of(256).min(binding / 4 * 4).max(len);
        *buf = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some(label),
            size,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
    }
    if !bytes.is_empty() {
        ctx.queue.write_buffer(buf, 0, bytes);
    }
}

impl Injector {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = bind_group_layout(
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
        let pipeline = compute_pipeline(device, "inject", shaders::inject(), &layout);
        let sums_pipeline = compute_pipeline(device, "inject sums", shaders::inject_sums(), &layout);
        let occupancy_layout =
            bind_group_layout(device, "occupancy", &[Slot::Uniform, Slot::Texture3d, Slot::StorageWrite]);
        let occupancy = compute_pipeline(device, "occupancy", shaders::occupancy(), &occupancy_layout);
        let empty = |label| super::buffers::storage_buffer(device, label, &[]);
        Self {
            layout,
            pipeline,
            sums_pipeline,
            occupancy_layout,
            occupancy,
            particles: empty("particles"),
            offsets: empty("bin offsets"),
            items: empty("bin items"),
            bricks: empty("dirty bricks"),
            sums: empty("particle sums"),
            no_layer: empty("no base layer"),
        }
    }

    /// Plans one injection of `bricks`: cuts them into chunks whose lists hold at most
    /// `max_items` entries (a brick with more forms a chunk alone); on the host path (given
    /// `ordered`), whose particle sums (two words per cell) fit `max_items` words. Nothing is
    /// uploaded yet.
    pub fn begin(
        grid: &GridSpec,
        particles: Vec<Particle>,
        gpu_particles: Vec<ParticleGpu>,
        counts: BinCounts,
        bricks: Vec<u32>,
        max_items: u64,
        ordered: Option<host_sums::Ordered>,
    ) -> InjectJob {
        let host = ordered.is_some();
        let (items, evals) = counts.per_brick(grid);
        let mut chunk_ends = Vec::new();
        let mut acc = 0u64;
        for (i, &b) in bricks.iter().enumerate() {
            let n = if host { host_sums::WORDS as u64 } else { items[b as usize] };
            if i > 0 && acc + n > max_items {
                chunk_ends.push(i);
                acc = 0;
            }
            acc += n;
        }
        chunk_ends.push(bricks.len());
        let evaluations = bricks.iter().map(|&b| evals[b as usize]).collect();
        InjectJob {
            bricks,
            next: 0,
            particles,
            gpu_particles,
            counts,
            evaluations,
            chunk_ends,
            uploaded: None,
            peak_chunk_bytes: 0,
            ordered,
            occupancy_done: false,
        }
    }

    /// Builds and uploads the lists of chunk `c`, unless they are on the GPU already.
    fn upload_chunk(&mut self, ctx: &GpuContext, grid: &GridSpec, job: &mut InjectJob, c: usize) {
        if job.uploaded == Some(c) {
            return;
        }
        let start = if c == 0 { 0 } else { job.chunk_ends[c - 1] };
        let bricks = &job.bricks[start..job.chunk_ends[c]];
        let lists = job.counts.fill(grid, &job.particles, bricks);
        let particles: Vec<ParticleGpu> = lists.particles.iter().map(|&i| job.gpu_particles[i as usize]).collect();
        upload(ctx, &mut self.particles, "particles", bytemuck::cast_slice(&particles));
        upload(ctx, &mut self.offsets, "bin offsets", bytemuck::cast_slice(&lists.offsets));
        upload(ctx, &mut self.items, "bin items", bytemuck::cast_slice(&lists.items));
        upload(ctx, &mut self.bricks, "dirty bricks", bytemuck::cast_slice(bricks));
        let bytes = (std::mem::size_of_val(&particles[..]) + lists.items.len() * 4 + lists.offsets.len() * 4) as u64;
        job.peak_chunk_bytes = job.peak_chunk_bytes.max(bytes);
        job.uploaded = Some(c);
    }

    /// Smallest chunk of bricks: a storage binding's offset alignment, in bricks (one brick on
    /// the host path, which uploads each call's bricks from offset 0).
    pub fn chunk_align(ctx: &GpuContext, job: &InjectJob) -> usize {
        if job.host() {
            1
        } else {
            (ctx.limits.min_storage_buffer_offset_alignment as usize / 4).max(1)
        }
    }

    /// Fewest bricks worth one call: the alignment on the adapter; on the host a row of
    /// bricks, since each host call walks the particles within a margin of bricks around its
    /// own (see `host_sums`), which calls of a brick or two would walk again and again.
    pub fn min_bricks(ctx: &GpuContext, job: &InjectJob, grid: &GridSpec) -> usize {
        if job.host() {
            binning::brick_dims(grid).x as usize
        } else {
            Self::chunk_align(ctx, job)
        }
    }

    /// Particle evaluations plus cells of the next `count` bricks: the unit of their cost.
    pub fn units(job: &InjectJob, _grid: &GridSpec, count: usize) -> u64 {
        let end = (job.next + count).min(job.bricks.len());
        job.evaluations[job.next..end].iter().sum::<u64>() + (end - job.next) as u64 * (binning::BRICK as u64).pow(3)
    }

    /// Encodes the next `count` bricks (rounded up to the binding alignment, and never past
    /// the end of the current memory chunk, whose lists it uploads first), or the occupancy
    /// pass once every brick is in. The caller submits before the next call, since a call
    /// may overwrite the lists the previous one read.
    #[allow(clippy::too_many_arguments)] // one caller; each argument is a distinct input or output of the pass
    pub fn encode_next(
        &mut self,
        ctx: &GpuContext,
        encoder: &mut wgpu::CommandEncoder,
        job: &mut InjectJob,
        inputs: &InjectInputs,
        count: usize,
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
        counters: &mut Counters,
    ) {
        let device = &ctx.device;
        let chunk = job.chunk_ends.partition_point(|&e| e <= job.next);
        if job.next < job.bricks.len() && job.uploaded != Some(chunk) {
            if !job.host() {
                self.upload_chunk(ctx, inputs.grid, job, chunk);
            }
            job.uploaded = Some(chunk);
            counters.inject_chunks += 1;
        }
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("inject"), timestamp_writes: timestamps });
        if job.next < job.bricks.len() {
            let start = if chunk == 0 { 0 } else { job.chunk_ends[chunk - 1] };
            let align = Self::chunk_align(ctx, job);
            let max = (ctx.limits.max_compute_workgroups_per_dimension as usize / align).max(1) * align;
            let count = count.max(1).next_multiple_of(align).min(max);
            let end = (job.next + count).min(job.chunk_ends[chunk]);
            let mut offset = ((job.next - start) * 4) as u64;
            if job.host() {
                // The host sums exactly this call's bricks, so a frame budget bounds its work.
                let bricks = &job.bricks[job.next..end];
                // Bricks no particle reaches need no sums: their slot is NONE.
                let (mut slots, mut busy, mut weights) = (Vec::with_capacity(bricks.len()), Vec::new(), Vec::new());
                for (&b, &w) in bricks.iter().zip(&job.evaluations[job.next..end]) {
                    slots.push(if w > 0 { busy.len() as u32 } else { u32::MAX });
                    if w > 0 {
                        busy.push(b);
                        weights.push(w);
                    }
                }
                let ordered = job.ordered.as_ref().expect("the host path's particles");
                let (sums, pairs) = host_sums::particle_sums(inputs.grid, ordered, &busy, &weights);
                upload(ctx, &mut self.sums, "particle sums", bytemuck::cast_slice(&sums));
                upload(ctx, &mut self.offsets, "particle sum slots", bytemuck::cast_slice(&slots));
                upload(ctx, &mut self.bricks, "dirty bricks", bytemuck::cast_slice(bricks));
                job.peak_chunk_bytes = job.peak_chunk_bytes.max(std::mem::size_of_val(&sums[..]) as u64);
                counters.particle_evaluations += pairs;
                offset = 0;
            } else {
                counters.particle_evaluations += job.evaluations[job.next..end].iter().sum::<u64>();
            }
            let slice = wgpu::BufferBinding {
                buffer: &self.bricks,
                offset,
                size: wgpu::BufferSize::new((end - job.next) as u64 * 4),
            };
            let bg = bind_group(
                device,
                "inject",
                &self.layout,
                &[
                    inputs.grid_buf.as_entire_binding(),
                    if job.host() { &self.sums } else { &self.particles }.as_entire_binding(),
                    self.offsets.as_entire_binding(),
                    self.items.as_entire_binding(),
                    wgpu::BindingResource::TextureView(inputs.ev_view),
                    wgpu::BindingResource::Buffer(slice),
                    inputs.layer.unwrap_or(&self.no_layer).as_entire_binding(),
                ],
            );
            pass.set_pipeline(if job.host() { &self.sums_pipeline } else { &self.pipeline });
            pass.set_bind_group(0, &bg, &[]);
            pass.dispatch_workgroups((end - job.next) as u32, 1, 1);
            counters.dispatches += 1;
            counters.cells_injected +=
                job.bricks[job.next..end].iter().map(|&b| brick_cells(inputs.grid, b)).sum::<u64>();
            job.next = end;
        }
        if job.next >= job.bricks.len() {
            let occ = bind_group(
                device,
                "occupancy",
                &self.occupancy_layout,
                &[
                    inputs.grid_buf.as_entire_binding(),
                    wgpu::BindingResource::TextureView(inputs.ev_view),
                    inputs.brick_max.as_entire_binding(),
                ],
            );
            let b = inputs.grid.resolution.map(|n| n.div_ceil(binning::BRICK));
            pass.set_pipeline(&self.occupancy);
            pass.set_bind_group(0, &occ, &[]);
            pass.dispatch_workgroups(
                b.x.div_ceil(WORKGROUP_3D),
                b.y.div_ceil(WORKGROUP_3D),
                b.z.div_ceil(WORKGROUP_3D),
            );
            counters.dispatches += 1;
            job.occupancy_done = true;
        }
    }

    pub fn bytes(&self) -> u64 {
        [&self.particles, &self.offsets, &self.items, &self.bricks, &self.sums, &self.no_layer]
            .iter()
            .map(|b| b.size())
            .sum()
    }
}

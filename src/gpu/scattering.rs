//! [`Scatterer`]: multiple scattering, the light scattered two or more times inside the grid.
//!
//! The method is source iteration of the discrete-ordinates equations on a coarse copy of the
//! grid (at most `resolution`³ cells, see `MultipleScattering::factor`), one scattering order
//! per sweep:
//!
//! 1. The first scattering's source per coarse cell (`shaders/scatter_source.wgsl`): the mean
//!    of σ_s times the unscattered light of every light, from the same OPVs, cone rules and
//!    surface shadows as the light bake, over every fine cell near a point or spot light (the
//!    1/d² peak integrated, not point-sampled) and from 2³ points elsewhere. Its angular shape
//!    is kept as one Henyey–Greenstein lobe about the light's mean direction (exact in the first
//!    moment).
//! 2. Per order, a sweep of the scattered radiance in the 48 directions of the S6
//!    level-symmetric quadrature, upwind layer by layer, each line crossing its cell with the
//!    cell's σ_t and emission so that every cell attenuates exactly what enters it
//!    (`shaders/scatter_sweep.wgsl`), then the order's fluence and flux, summed into the
//!    totals, and the next order's source.
//! 3. The orders not swept as a geometric tail, from the ratio of the last two orders'
//!    scattered powers. It stands for the many orders of thick, bright fog at the cost of a
//!    few sweeps; there the ratios still grow after the last order, so the tail is short by a
//!    few per cent of the added light (README, "Multiple scattering").
//!
//! The march (`ms_inscatter` in `shaders/march.wgsl`) adds σ_s·φ·HG(ω·ê, g·|E|/φ) at every
//! sample in the grid, trilinear from the coarse fluence φ and flux E; the bake adds the same at
//! each cell centre. Single scattering stays exact per pixel: the coarse grid carries only the
//! smooth, multiply scattered part. Base fog outside the grid scatters once only, and surfaces
//! shadow the first scattering but not the later orders.

use super::baking::{entry, program, storage, uniform, Bindings, Program};
use super::frame_inputs::FrameInputs;
use super::gpu_types::{MarchParams, ScatterParams};
use super::layout::{bind_group_layout_with, compute_pipeline_entry, Slot, SWEEP_WORKGROUP, WORKGROUP_3D};
use super::opv_store::{OpvLayout, EXTRA_BINDING};
use super::resources::GridResources;
use super::{GpuContext, GpuError};
use crate::scene::MultipleScattering;

/// Byte stride of the per-order uniforms (dynamic offsets must be 256-aligned).
const PARAMS_SLOT: u64 = 256;

/// The S6 level-symmetric quadrature: 48 unit directions with weights summing to 4π, exact for
/// the moments the lobe closure needs (zeroth, first and second).
pub fn s6_directions() -> Vec<[f32; 4]> {
    const MU: [f64; 3] = [0.266_635_5, 0.681_507_6, 0.926_180_8];
    // Per octant: the permutations of (μ1, μ1, μ3) and of (μ1, μ2, μ2), weights summing to 1.
    let classes = [([0, 0, 2], 0.176_126_3), ([0, 1, 1], 0.157_207_1)];
    let mut points = Vec::new();
    for (class, w) in classes {
        for rot in 0..3 {
            let c = [class[rot % 3], class[(rot + 1) % 3], class[(rot + 2) % 3]];
            points.push(([MU[c[0]], MU[c[1]], MU[c[2]]], w));
        }
    }
    let total: f64 = points.iter().map(|p| p.1).sum();
    let mut out = Vec::with_capacity(48);
    for octant in 0..8 {
        let sign = |axis: u32| if octant & (1 << axis) != 0 { -1.0 } else { 1.0 };
        for (p, w) in &points {
            let v = [p[0] * sign(0), p[1] * sign(1), p[2] * sign(2)];
            let len = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            let weight = w / total * std::f64::consts::FRAC_PI_2;
            out.push([(v[0] / len) as f32, (v[1] / len) as f32, (v[2] / len) as f32, weight as f32]);
        }
    }
    out
}

/// The coarse grid of a fine grid of `dims` cells at `factor` fine cells per coarse edge.
pub fn coarse_dims(dims: glam::UVec3, factor: u32) -> glam::UVec3 {
    dims.map(|n| n.div_ceil(factor.max(1)))
}

fn b(buffer: &wgpu::Buffer, binding: u32) -> wgpu::BindGroupEntry<'_> {
    wgpu::BindGroupEntry { binding, resource: buffer.as_entire_binding() }
}

/// The buffers of one coarse grid size.
struct Buffers {
    count: u32,
    first_source: wgpu::Buffer,
    sigma: wgpu::Buffer,
    source: wgpu::Buffer,
    radiance: wgpu::Buffer,
    chord_mean: wgpu::Buffer,
    order_moments: wgpu::Buffer,
    totals: wgpu::Buffer,
    powers: wgpu::Buffer,
    moments: wgpu::Buffer,
    params: wgpu::Buffer,
}

impl Buffers {
    fn new(device: &wgpu::Device, count: u32) -> Self {
        let make = |label: &str, bytes: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size: bytes.max(16),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            })
        };
        let cells = count as u64;
        Self {
            count,
            first_source: make("multiple scattering: first source", cells * 32),
            sigma: make("multiple scattering: coarse extinction", cells * 4),
            source: make("multiple scattering: source", cells * 32),
            radiance: make("multiple scattering: radiance per direction", cells * 16 * 48),
            chord_mean: make("multiple scattering: chord means per direction", cells * 16 * 48),
            order_moments: make("multiple scattering: order moments", cells * 32),
            totals: make("multiple scattering: totals", cells * 32),
            powers: make("multiple scattering: order powers", 4 * 80),
            moments: make("multiple scattering: moments", cells * 32),
            params: device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("multiple scattering params"),
                size: PARAMS_SLOT * 66,
                usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            }),
        }
    }

    fn bytes(&self) -> u64 {
        [
            &self.first_source,
            &self.sigma,
            &self.source,
            &self.radiance,
            &self.chord_mean,
            &self.order_moments,
            &self.totals,
            &self.powers,
            &self.moments,
            &self.params,
        ]
        .iter()
        .map(|b| b.size())
        .sum()
    }
}

/// A solve in progress: its steps are the first scattering's source, one per order, then the
/// moments (see [`Scatterer::step`]).
pub(super) struct ScatterJob {
    step: u32,
    orders: u32,
    dims: glam::UVec3,
    groups: (u32, u32),
    source_group: wgpu::BindGroup,
    sweep_group: wgpu::BindGroup,
    /// The source pass's uniform, which its bind group holds.
    _params: wgpu::Buffer,
}

impl ScatterJob {
    pub fn done(&self) -> bool {
        self.step > self.orders + 1
    }

    pub fn fraction(&self) -> f64 {
        (self.step as f64 / (self.orders + 2) as f64).min(1.0)
    }
}

/// The sweep module's pipelines over one layout.
struct Sweeps {
    layout: wgpu::BindGroupLayout,
    seed: wgpu::ComputePipeline,
    sweep: wgpu::ComputePipeline,
    gather: wgpu::ComputePipeline,
    power: wgpu::ComputePipeline,
    finish: wgpu::ComputePipeline,
}

impl Sweeps {
    fn new(device: &wgpu::Device) -> Self {
        let mut entries =
            vec![super::layout::entry(1, Slot::UniformDynamic), super::layout::entry(2, Slot::StorageRead)];
        entries.extend((3..=9).map(|b| super::layout::entry(b, Slot::StorageWrite)));
        entries.push(super::layout::entry(10, Slot::StorageRead));
        entries.push(super::layout::entry(11, Slot::StorageWrite));
        let layout = bind_group_layout_with(device, "multiple scattering", &[], entries);
        let code = super::shaders::scatter_sweep();
        let build = |name: &str| compute_pipeline_entry(device, "multiple scattering", code.clone(), &layout, name);
        Self {
            seed: build("seed"),
            sweep: build("sweep"),
            gather: build("gather"),
            power: build("power"),
            finish: build("finish"),
            layout,
        }
    }
}

/// The multiple-scattering stage: its pipelines, the quadrature and the coarse grid's
/// buffers, whose `moments` the march and the bake read.
pub(super) struct Scatterer {
    source: Option<Program>,
    sweeps: Option<Sweeps>,
    directions: wgpu::Buffer,
    buffers: Option<Buffers>,
    /// Bound as the moments while no solve has run (the march then reads none).
    empty: wgpu::Buffer,
}

impl Scatterer {
    pub fn new(device: &wgpu::Device) -> Self {
        let directions = s6_directions();
        Self {
            source: None,
            sweeps: None,
            directions: super::buffers::storage_buffer(device, "S6 directions", bytemuck::cast_slice(&directions)),
            buffers: None,
            empty: super::buffers::storage_buffer(device, "no multiple scattering", &[0u8; 32]),
        }
    }

    /// Drops the source pipeline, built for an OPV layout the scene no longer has.
    pub fn rebuild(&mut self) {
        self.source = None;
    }

    /// What the march and the bake bind as the multiple-scattering moments.
    pub fn moments(&self) -> &wgpu::Buffer {
        self.buffers.as_ref().map_or(&self.empty, |b| &b.moments)
    }

    pub fn bytes(&self) -> u64 {
        self.buffers.as_ref().map_or(0, Buffers::bytes)
    }

    /// Starts the solve of multiple scattering for `frame` on `grid` (EV and lookup volumes up
    /// to date): uploads its parameters and binds its buffers. [`step`](Self::step) runs it; the
    /// moments the march reads change only with its last step.
    pub fn begin(
        &mut self,
        ctx: &GpuContext,
        layout: OpvLayout,
        grid: &GridResources,
        frame: &FrameInputs,
        settings: MultipleScattering,
    ) -> Result<ScatterJob, GpuError> {
        let device = &ctx.device;
        let factor = frame.march.scatter_factor.max(1);
        let dims = coarse_dims(grid.spec.resolution, factor);
        let count = dims.x * dims.y * dims.z;
        let radiance_bytes = count as u64 * 16 * 48;
        if radiance_bytes > ctx.max_binding_bytes() {
            return Err(GpuError::Limit {
                what: "multiple scattering's radiance per direction (and its chord means, as much again)".into(),
                needed: radiance_bytes,
                limit: ctx.max_binding_bytes(),
                adapter: ctx.adapter_summary(),
                suggestion: "lower medium.multiple_scattering.resolution".into(),
            });
        }
        if self.buffers.as_ref().is_none_or(|b| b.count != count) {
            self.buffers = Some(Buffers::new(device, count));
        }
        let source = self.source.get_or_insert_with(|| {
            let mut own = vec![entry(15, storage(false))];
            own.extend(layout.layout_entries(EXTRA_BINDING, true));
            let slots = [Slot::StorageRead, Slot::Opv { read_only: true }];
            program(device, ("scatter source", "scatter_source"), &slots, own, super::shaders::scatter_source(&layout))
        });
        let sweeps = self.sweeps.get_or_insert_with(|| Sweeps::new(device));
        let buffers = self.buffers.as_ref().expect("made above");
        let orders = settings.orders.clamp(1, 64);

        // The source pass reads the bake's cell means with an isotropic phase: 1/(4π) each.
        let bindings = Bindings::new(device, grid, frame);
        let params = MarchParams { anisotropy: 0.0, surface_count: bindings.surface_count, ..bindings.params };
        let params_buf = uniform(device, "scatter source params", &params);
        let mut own = vec![
            wgpu::BindGroupEntry { binding: 3, resource: grid.lights_buf.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 4, resource: grid.lookup.first() },
            wgpu::BindGroupEntry { binding: 15, resource: buffers.first_source.as_entire_binding() },
        ];
        own.extend(grid.lookup.extra_entries(EXTRA_BINDING));
        let source_group = bindings.bind_group(device, "scatter source", source, &params_buf, own);

        let cell = grid.spec.cell_size() * factor as f32;
        let base = ScatterParams {
            dims: dims.to_array(),
            count,
            cell: cell.to_array(),
            albedo: frame.march.albedo,
            min: grid.spec.min.to_array(),
            anisotropy: frame.march.anisotropy,
            order: 0,
            orders,
            strength: settings.strength,
            _pad: 0,
        };
        let mut slots = vec![0u8; (PARAMS_SLOT * (orders as u64 + 1)) as usize];
        for k in 0..=orders {
            let p = ScatterParams { order: k, ..base };
            let at = (k as u64 * PARAMS_SLOT) as usize;
            slots[at..at + std::mem::size_of::<ScatterParams>()].copy_from_slice(bytemuck::bytes_of(&p));
        }
        ctx.queue.write_buffer(&buffers.params, 0, &slots);
        let sweep_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("multiple scattering"),
            layout: &sweeps.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 1,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &buffers.params,
                        offset: 0,
                        size: wgpu::BufferSize::new(std::mem::size_of::<ScatterParams>() as u64),
                    }),
                },
                b(&self.directions, 2),
                b(&buffers.sigma, 3),
                b(&buffers.source, 4),
                b(&buffers.radiance, 5),
                b(&buffers.order_moments, 6),
                b(&buffers.totals, 7),
                b(&buffers.powers, 8),
                b(&buffers.moments, 9),
                b(&buffers.first_source, 10),
                b(&buffers.chord_mean, 11),
            ],
        });

        let groups = count.div_ceil(SWEEP_WORKGROUP);
        let x = groups.min(ctx.limits.max_compute_workgroups_per_dimension);
        Ok(ScatterJob {
            step: 0,
            orders,
            dims,
            groups: (x, groups.div_ceil(x)),
            source_group,
            sweep_group,
            _params: params_buf,
        })
    }

    /// Runs the next step of `job`, and waits for it: the first scattering's source, then one
    /// order per step, then the moments.
    pub fn step(&self, ctx: &GpuContext, job: &mut ScatterJob) -> Result<(), GpuError> {
        let (Some(source), Some(sweeps), Some(buffers)) = (&self.source, &self.sweeps, &self.buffers) else {
            return Err(GpuError::Invalid("multiple scattering stepped before it began".into()));
        };
        let (gx, gy) = job.groups;
        let offset = |k: u32| (k as u64 * PARAMS_SLOT) as u32;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        if job.step == 0 {
            encoder.clear_buffer(&buffers.totals, 0, None);
            encoder.clear_buffer(&buffers.powers, 0, None);
        }
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("multiple scattering"),
                timestamp_writes: None,
            });
            if job.step == 0 {
                let dims = job.dims;
                pass.set_pipeline(&source.pipeline);
                pass.set_bind_group(0, &job.source_group, &[]);
                pass.dispatch_workgroups(
                    dims.x.div_ceil(WORKGROUP_3D),
                    dims.y.div_ceil(WORKGROUP_3D),
                    dims.z.div_ceil(WORKGROUP_3D),
                );
                pass.set_bind_group(0, &job.sweep_group, &[offset(0)]);
                pass.set_pipeline(&sweeps.seed);
                pass.dispatch_workgroups(gx, gy, 1);
                pass.set_pipeline(&sweeps.power);
                pass.dispatch_workgroups(1, 1, 1);
            } else if job.step <= job.orders {
                pass.set_bind_group(0, &job.sweep_group, &[offset(job.step)]);
                pass.set_pipeline(&sweeps.sweep);
                pass.dispatch_workgroups(48, 1, 1);
                pass.set_pipeline(&sweeps.gather);
                pass.dispatch_workgroups(gx, gy, 1);
                pass.set_pipeline(&sweeps.power);
                pass.dispatch_workgroups(1, 1, 1);
            } else {
                pass.set_bind_group(0, &job.sweep_group, &[offset(job.orders)]);
                pass.set_pipeline(&sweeps.finish);
                pass.dispatch_workgroups(gx, gy, 1);
            }
        }
        ctx.queue.submit([encoder.finish()]);
        job.step += 1;
        ctx.wait()
    }

    /// The scattered power of each order of the last solve, the first scattering first.
    pub fn read_powers(&self, ctx: &GpuContext, orders: u32) -> Result<Vec<f32>, GpuError> {
        let buffers = self.buffers.as_ref().ok_or_else(|| GpuError::Invalid("no multiple scattering solved".into()))?;
        super::readback::read_buffer(ctx, &buffers.powers, 0, orders as usize + 1)
    }
}

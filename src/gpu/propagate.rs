//! Opacity propagation: EV → one optical-depth volume (OPV) per light, by one of three
//! schemes (see [`Scheme`]). All OPVs live in one storage buffer, light-major.

use super::gpu_types::{ExactParams, SweepStep};
use super::layout::{bind_group, bind_group_layout, compute_pipeline, Slot, VOLUME_LOOKUP};
use super::Counters;
use crate::scene::{GridSpec, Scheme};
use glam::{IVec3, Vec3};

/// The inputs every scheme reads and the buffers it writes.
pub struct PropagationInputs<'a> {
    pub grid: &'a GridSpec,
    pub grid_buf: &'a wgpu::Buffer,
    pub ev_view: &'a wgpu::TextureView,
    pub lights_buf: &'a wgpu::Buffer,
    /// Result buffer (all lights) and a scratch buffer of the same size.
    pub opv: &'a [wgpu::Buffer; 2],
    /// Light positions, indexed like the OPVs.
    pub positions: &'a [Vec3],
    /// Layers stepped back per interpolation by the `sweep` scheme (≥ 3).
    pub sweep_stride: u32,
}

pub struct Propagator {
    giroud_layout: wgpu::BindGroupLayout,
    giroud: wgpu::ComputePipeline,
    sweep_layout: wgpu::BindGroupLayout,
    sweep: wgpu::ComputePipeline,
    exact: wgpu::ComputePipeline,
    uniform_align: u64,
}

/// Simpson steps per cell edge of the `exact` scheme.
pub const EXACT_STEPS_PER_CELL: u32 = 4;

impl Propagator {
    pub fn new(device: &wgpu::Device) -> Self {
        let giroud_layout = bind_group_layout(
            device,
            "propagate_giroud",
            &[Slot::Uniform, Slot::Texture3d, Slot::StorageRead, Slot::StorageRead, Slot::StorageRead, Slot::StorageWrite],
        );
        let giroud = compute_pipeline(
            device,
            "propagate_giroud",
            &[include_str!("../../shaders/propagate_giroud.wgsl")],
            &giroud_layout,
        );
        // The sweep and exact schemes share one layout: grid, EV, lights, per-dispatch
        // parameters, OPV.
        let sweep_layout = bind_group_layout(
            device,
            "propagate_sweep",
            &[Slot::Uniform, Slot::Texture3d, Slot::StorageRead, Slot::UniformDynamic, Slot::StorageWrite],
        );
        let sweep = compute_pipeline(
            device,
            "propagate_sweep",
            &[VOLUME_LOOKUP, include_str!("../../shaders/propagate_sweep.wgsl")],
            &sweep_layout,
        );
        let exact = compute_pipeline(
            device,
            "propagate_exact",
            &[VOLUME_LOOKUP, include_str!("../../shaders/propagate_exact.wgsl")],
            &sweep_layout,
        );
        let uniform_align = device.limits().min_uniform_buffer_offset_alignment as u64;
        Self { giroud_layout, giroud, sweep_layout, sweep, exact, uniform_align }
    }

    /// Plans the propagation of the `active` lights as a list of dispatches, to be encoded in
    /// order by [`encode_next`](Self::encode_next), in one submit or spread over many.
    pub fn plan(&self, device: &wgpu::Device, inputs: &PropagationInputs, scheme: Scheme, active: &[u32]) -> PropagationJob {
        let cells = inputs.grid.cell_count();
        let (work, groups, units, iterations) = match scheme {
            Scheme::Giroud => {
                let iterations = active
                    .iter()
                    .map(|&l| giroud_iterations(inputs.grid, inputs.positions[l as usize]))
                    .max()
                    .unwrap_or(1);
                // An even count leaves the result in buffer A, where every other light's OPV is.
                let iterations = iterations + iterations % 2;
                let active_buf = super::pipeline::storage_buffer(device, "active lights", bytemuck::cast_slice(active));
                let make = |src: &wgpu::Buffer, dst: &wgpu::Buffer| {
                    bind_group(
                        device,
                        "propagate_giroud",
                        &self.giroud_layout,
                        &[
                            inputs.grid_buf.as_entire_binding(),
                            wgpu::BindingResource::TextureView(inputs.ev_view),
                            inputs.lights_buf.as_entire_binding(),
                            active_buf.as_entire_binding(),
                            src.as_entire_binding(),
                            dst.as_entire_binding(),
                        ],
                    )
                };
                let [a, b] = inputs.opv;
                let work = Work::Giroud { ab: make(a, b), ba: make(b, a), a: a.clone(), b: b.clone(), _active: active_buf };
                let r = inputs.grid.resolution;
                let g = [r.x.div_ceil(4), r.y.div_ceil(4), r.z.div_ceil(4) * active.len() as u32];
                (work, vec![g; iterations as usize], vec![cells * active.len() as u64; iterations as usize], iterations)
            }
            Scheme::Sweep => {
                let steps: Vec<SweepStep> = active
                    .iter()
                    .flat_map(|&l| sweep_steps(inputs.grid, inputs.positions[l as usize], l, inputs.sweep_stride))
                    .collect();
                let groups = steps.iter().map(|s| [s.size[0].div_ceil(8), s.size[1].div_ceil(8), 1]).collect();
                let units = steps.iter().map(|s| s.size[0] as u64 * s.size[1] as u64).collect();
                let iterations = steps.len() as u32 / active.len() as u32;
                (self.per_dispatch(device, inputs, &steps, Which::Sweep), groups, units, iterations)
            }
            Scheme::Exact => {
                let r = inputs.grid.resolution;
                // One dispatch per light and slab of 4 layers, so the work can be spread.
                let params: Vec<ExactParams> = active
                    .iter()
                    .flat_map(|&l| {
                        (0..r.z.div_ceil(4)).map(move |s| ExactParams {
                            light: l,
                            steps_per_cell: EXACT_STEPS_PER_CELL,
                            z_offset: 4 * s,
                            _pad: 0,
                        })
                    })
                    .collect();
                let groups = vec![[r.x.div_ceil(4), r.y.div_ceil(4), 1]; params.len()];
                let units = vec![r.x as u64 * r.y as u64 * 4; params.len()];
                (self.per_dispatch(device, inputs, &params, Which::Exact), groups, units, 1)
            }
        };
        PropagationJob { lights: active.to_vec(), work, groups, units, next: 0, iterations, cells }
    }

    /// Encodes up to `count` further dispatches of `job` into `encoder` and counts them.
    pub fn encode_next(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        job: &mut PropagationJob,
        count: usize,
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
        counters: &mut Counters,
    ) {
        let range = job.next..(job.next + count.max(1)).min(job.groups.len());
        if let (Work::Giroud { a, b, .. }, 0) = (&job.work, job.next) {
            // Lights not being updated must survive in B too, since B feeds back into A.
            encoder.copy_buffer_to_buffer(a, 0, b, 0, None);
        }
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("propagate"), timestamp_writes: timestamps });
            match &job.work {
                Work::Giroud { ab, ba, .. } => {
                    pass.set_pipeline(&self.giroud);
                    for it in range.clone() {
                        pass.set_bind_group(0, if it % 2 == 0 { ab } else { ba }, &[]);
                        let g = job.groups[it];
                        pass.dispatch_workgroups(g[0], g[1], g[2]);
                    }
                }
                Work::PerDispatch { which, bind_group, stride, .. } => {
                    pass.set_pipeline(match which {
                        Which::Sweep => &self.sweep,
                        Which::Exact => &self.exact,
                    });
                    for i in range.clone() {
                        pass.set_bind_group(0, bind_group, &[(i as u64 * stride) as u32]);
                        let g = job.groups[i];
                        pass.dispatch_workgroups(g[0], g[1], g[2]);
                    }
                }
            }
        }
        counters.dispatches += range.len() as u32;
        job.next = range.end;
        if job.done() {
            counters.propagation_iterations = counters.propagation_iterations.max(job.iterations);
            counters.lights_propagated += job.lights.len() as u32;
            let passes = if matches!(job.work, Work::Giroud { .. }) { job.iterations as u64 } else { 1 };
            counters.cells_propagated += job.cells * job.lights.len() as u64 * passes;
        }
    }

    /// Uploads one uniform entry per dispatch and returns the work over it.
    fn per_dispatch<T: bytemuck::Pod>(&self, device: &wgpu::Device, inputs: &PropagationInputs, entries: &[T], which: Which) -> Work {
        use wgpu::util::DeviceExt;
        let stride = (std::mem::size_of::<T>() as u64).div_ceil(self.uniform_align) * self.uniform_align;
        let mut bytes = vec![0u8; stride as usize * entries.len().max(1)];
        for (i, e) in entries.iter().enumerate() {
            let start = i * stride as usize;
            bytes[start..start + std::mem::size_of::<T>()].copy_from_slice(bytemuck::bytes_of(e));
        }
        let buf = device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
            label: Some("propagation steps"),
            contents: &bytes,
            usage: wgpu::BufferUsages::UNIFORM,
        });
        let bind_group = bind_group(
            device,
            "propagate",
            &self.sweep_layout,
            &[
                inputs.grid_buf.as_entire_binding(),
                wgpu::BindingResource::TextureView(inputs.ev_view),
                inputs.lights_buf.as_entire_binding(),
                wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                    buffer: &buf,
                    offset: 0,
                    size: wgpu::BufferSize::new(std::mem::size_of::<T>() as u64),
                }),
                inputs.opv[0].as_entire_binding(),
            ],
        );
        Work::PerDispatch { which, bind_group, stride, _buf: buf }
    }
}

#[derive(Clone, Copy)]
enum Which {
    Sweep,
    Exact,
}

enum Work {
    /// Jacobi iterations ping-ponging between the two OPV buffers.
    Giroud { ab: wgpu::BindGroup, ba: wgpu::BindGroup, a: wgpu::Buffer, b: wgpu::Buffer, _active: wgpu::Buffer },
    /// One dispatch per uniform entry, each seeing its entry through a dynamic offset.
    PerDispatch { which: Which, bind_group: wgpu::BindGroup, stride: u64, _buf: wgpu::Buffer },
}

/// The dispatches that bring the OPVs of some lights up to date, each valid to run once the
/// ones before it have completed, in this or an earlier submit.
pub struct PropagationJob {
    /// The lights this job propagates.
    pub lights: Vec<u32>,
    work: Work,
    groups: Vec<[u32; 3]>,
    /// Cells each dispatch computes: the unit of its cost.
    units: Vec<u64>,
    next: usize,
    iterations: u32,
    cells: u64,
}

impl PropagationJob {
    pub fn done(&self) -> bool {
        self.next >= self.groups.len()
    }
    /// Cells of the next `count` dispatches.
    pub fn units(&self, count: usize) -> u64 {
        self.units[self.next.min(self.units.len())..(self.next + count).min(self.units.len())].iter().sum()
    }
    /// How many of the next dispatches fit in `units` cells (at least one).
    pub fn fitting(&self, units: u64) -> usize {
        let mut sum = 0u64;
        let mut n = 0;
        for &u in &self.units[self.next..] {
            if n > 0 && sum.saturating_add(u) > units {
                break;
            }
            sum = sum.saturating_add(u);
            n += 1;
        }
        n.max(1)
    }
    /// Fraction of the job's cells computed.
    pub fn fraction(&self) -> f64 {
        let total: u64 = self.units.iter().sum();
        if total == 0 {
            return 1.0;
        }
        self.units[..self.next].iter().sum::<u64>() as f64 / total as f64
    }
}

/// The light's cell index (may lie outside the grid). A light far outside is moved, per
/// axis, to 2²⁰ cells beyond the grid: the sweep only compares Manhattan distances between
/// grid cells, which that keeps, and the level arithmetic then stays far inside i32.
fn light_cell(grid: &GridSpec, light: Vec3) -> IVec3 {
    const FAR: f32 = (1 << 20) as f32;
    let c = ((light - grid.min) / grid.cell_size()).floor();
    c.clamp(Vec3::splat(-FAR), grid.resolution.as_vec3() + FAR).as_ivec3()
}

/// The wavefronts of the sweep for one light: for every Manhattan distance ("level") from
/// the light's cell that reaches the grid, the rectangle of (di, dj) offsets to dispatch.
pub fn sweep_steps(grid: &GridSpec, light: Vec3, light_index: u32, stride: u32) -> Vec<SweepStep> {
    let lc = light_cell(grid, light);
    let n = grid.resolution.as_ivec3();
    let (mut lo_level, mut hi_level) = (0, 0);
    for a in 0..3 {
        let (near, far) = if lc[a] < 0 {
            (-lc[a], n[a] - 1 - lc[a])
        } else if lc[a] >= n[a] {
            (lc[a] - (n[a] - 1), lc[a])
        } else {
            (0, lc[a].max(n[a] - 1 - lc[a]))
        };
        lo_level += near;
        hi_level += far;
    }
    let mut steps = Vec::with_capacity((hi_level - lo_level + 1) as usize);
    for level in lo_level..=hi_level {
        let lo_i = (-level).max(-lc.x);
        let hi_i = level.min(n.x - 1 - lc.x);
        let lo_j = (-level).max(-lc.y);
        let hi_j = level.min(n.y - 1 - lc.y);
        if lo_i > hi_i || lo_j > hi_j {
            continue;
        }
        steps.push(SweepStep {
            light_cell: lc.to_array(),
            level,
            lo: [lo_i, lo_j],
            size: [(hi_i - lo_i + 1) as u32, (hi_j - lo_j + 1) as u32],
            light: light_index,
            stride,
            _pad: [0; 2],
        });
    }
    steps
}

/// Jacobi sweeps after which the `giroud` gather has converged exactly: one more than the
/// largest Manhattan distance (in cells) from any cell to the light's slabs.
pub fn giroud_iterations(grid: &GridSpec, light: Vec3) -> u32 {
    let lc = light_cell(grid, light);
    let n = grid.resolution.as_ivec3();
    let mut total = 0;
    for a in 0..3 {
        total += if lc[a] < 0 || lc[a] >= n[a] { n[a] } else { lc[a].max(n[a] - 1 - lc[a]) };
    }
    total as u32 + 1
}

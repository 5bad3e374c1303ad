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

    /// Records the propagation of the `active` lights into `encoder`.
    pub fn encode(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &PropagationInputs,
        scheme: Scheme,
        active: &[u32],
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
        counters: &mut Counters,
    ) {
        if active.is_empty() {
            return;
        }
        match scheme {
            Scheme::Giroud => self.encode_giroud(device, encoder, inputs, active, timestamps, counters),
            Scheme::Sweep => self.encode_sweep(device, encoder, inputs, active, timestamps, counters),
            Scheme::Exact => self.encode_exact(device, encoder, inputs, active, timestamps, counters),
        }
        counters.lights_propagated += active.len() as u32;
    }

    fn encode_giroud(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &PropagationInputs,
        active: &[u32],
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
        counters: &mut Counters,
    ) {
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
        let ab = make(a, b);
        let ba = make(b, a);
        let r = inputs.grid.resolution;
        // Lights not being updated must survive in B too, since B feeds back into A.
        encoder.copy_buffer_to_buffer(a, 0, b, 0, None);
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("propagate giroud"), timestamp_writes: timestamps });
        pass.set_pipeline(&self.giroud);
        for it in 0..iterations {
            pass.set_bind_group(0, if it % 2 == 0 { &ab } else { &ba }, &[]);
            pass.dispatch_workgroups(r.x.div_ceil(4), r.y.div_ceil(4), r.z.div_ceil(4) * active.len() as u32);
        }
        counters.dispatches += iterations;
        counters.propagation_iterations = counters.propagation_iterations.max(iterations);
        counters.cells_propagated += inputs.grid.cell_count() * active.len() as u64 * iterations as u64;
    }

    /// Uploads one uniform entry per dispatch and returns the bind group over it.
    fn per_dispatch_bind_group<T: bytemuck::Pod>(
        &self,
        device: &wgpu::Device,
        inputs: &PropagationInputs,
        entries: &[T],
    ) -> (wgpu::BindGroup, wgpu::Buffer) {
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
        let bg = bind_group(
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
        (bg, buf)
    }

    fn encode_sweep(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &PropagationInputs,
        active: &[u32],
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
        counters: &mut Counters,
    ) {
        let steps: Vec<SweepStep> = active
            .iter()
            .flat_map(|&l| sweep_steps(inputs.grid, inputs.positions[l as usize], l, inputs.sweep_stride))
            .collect();
        let groups: Vec<[u32; 3]> = steps.iter().map(|s| [s.size[0].div_ceil(8), s.size[1].div_ceil(8), 1]).collect();
        self.encode_dispatches(device, encoder, inputs, &self.sweep, "propagate sweep", &steps, &groups, timestamps);
        counters.dispatches += steps.len() as u32;
        counters.propagation_iterations = counters.propagation_iterations.max(steps.len() as u32 / active.len() as u32);
        counters.cells_propagated += inputs.grid.cell_count() * active.len() as u64;
    }

    fn encode_exact(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &PropagationInputs,
        active: &[u32],
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
        counters: &mut Counters,
    ) {
        let params: Vec<ExactParams> = active
            .iter()
            .map(|&l| ExactParams { light: l, steps_per_cell: EXACT_STEPS_PER_CELL, _pad: [0; 2] })
            .collect();
        let r = inputs.grid.resolution;
        let groups = vec![[r.x.div_ceil(4), r.y.div_ceil(4), r.z.div_ceil(4)]; params.len()];
        self.encode_dispatches(device, encoder, inputs, &self.exact, "propagate exact", &params, &groups, timestamps);
        counters.dispatches += params.len() as u32;
        counters.propagation_iterations = counters.propagation_iterations.max(1);
        counters.cells_propagated += inputs.grid.cell_count() * active.len() as u64;
    }

    /// One pass of `pipeline` with one dispatch per entry, each seeing its own entry as the
    /// dynamic-offset uniform.
    #[allow(clippy::too_many_arguments)]
    fn encode_dispatches<T: bytemuck::Pod>(
        &self,
        device: &wgpu::Device,
        encoder: &mut wgpu::CommandEncoder,
        inputs: &PropagationInputs,
        pipeline: &wgpu::ComputePipeline,
        label: &str,
        entries: &[T],
        groups: &[[u32; 3]],
        timestamps: Option<wgpu::ComputePassTimestampWrites>,
    ) {
        let (bg, _buf) = self.per_dispatch_bind_group(device, inputs, entries);
        let stride = (std::mem::size_of::<T>() as u64).div_ceil(self.uniform_align) * self.uniform_align;
        let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some(label), timestamp_writes: timestamps });
        pass.set_pipeline(pipeline);
        for (i, g) in groups.iter().enumerate() {
            pass.set_bind_group(0, &bg, &[(i as u64 * stride) as u32]);
            pass.dispatch_workgroups(g[0], g[1], g[2]);
        }
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

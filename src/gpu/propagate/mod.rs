//! Opacity propagation: EV → one optical-depth volume (OPV) per light, by one of four
//! schemes (see [`Scheme`]). The OPVs live in 3D textures, several lights to a texture
//! (see `opv_store`).
//!
//! [`Propagator`] owns the schemes' pipelines and plans a [`PropagationJob`] of dispatches;
//! the sweep's ordering of cells into batches of Chebyshev shells is in `sweep`, the
//! directional lights' planes in `directional`, the Giroud gather's iteration count in
//! `giroud`.

mod directional;
mod giroud;
mod job;
mod sweep;

pub use giroud::giroud_iterations;
pub use job::PropagationJob;
pub use sweep::{sweep_cells_per_thread, sweep_steps, ShellFrame, SweepPlan};

use super::gpu_types::{AnalyticParticle, ExactParams, PlaneParams, SweepBox};
use super::layout::{
    bind_group_layout_with, bind_group_with, compute_pipeline, Slot, WORKGROUP_2D, WORKGROUP_3D, WORKGROUP_ROW,
};
use super::opv_store::{OpvLayout, OpvVolumes, EXTRA_BINDING, EXTRA_BINDING_2};
use super::shaders;
use super::Counters;
use crate::scene::{GridSpec, Particle, Scheme};
use bytemuck::Zeroable;
use directional::{sun_planes, SUN_STRIDE};
use glam::Vec3;
use sweep::{bricks_around, first_changed_batch, sweep_steps_from, ITEM_CELLS};

/// The inputs every scheme reads and the buffers it writes.
pub struct PropagationInputs<'a> {
    pub grid: &'a GridSpec,
    pub grid_buf: &'a wgpu::Buffer,
    pub ev_view: &'a wgpu::TextureView,
    pub lights_buf: &'a wgpu::Buffer,
    /// Result buffer (all lights) and a scratch buffer of the same size.
    pub opv: &'a [OpvVolumes; 2],
    /// Each brick's largest σ_t, then its detail (`shaders/occupancy.wgsl`).
    pub brick_max: &'a wgpu::Buffer,
    /// Light positions, indexed like the OPVs.
    pub positions: &'a [Vec3],
    /// The unit direction of travel of each directional light (None for point and spot
    /// lights), indexed like the OPVs: the `sweep` and `giroud` schemes sweep those with
    /// `propagate_directional.wgsl`.
    pub directions: &'a [Option<Vec3>],
    /// Layers stepped back per interpolation by the `sweep` scheme (≥ 3).
    pub sweep_stride: u32,
    /// The `sweep` scheme's error control: the tolerance of its interpolations, if on.
    pub sweep_refine: Option<f32>,
    /// The particles, which the `analytic` scheme integrates in closed form.
    pub particles: &'a [Particle],
    /// With the `analytic` scheme, each brick's list of them (the injection's bins of a whole
    /// brick, filled for every brick).
    pub analytic_lists: Option<&'a super::binning::ChunkBins>,
}

pub struct Propagator {
    giroud_layout: wgpu::BindGroupLayout,
    giroud: wgpu::ComputePipeline,
    sweep_layout: wgpu::BindGroupLayout,
    sweep: wgpu::ComputePipeline,
    sweep_sampler: wgpu::Sampler,
    exact_layout: wgpu::BindGroupLayout,
    exact: wgpu::ComputePipeline,
    analytic_layout: wgpu::BindGroupLayout,
    analytic: wgpu::ComputePipeline,
    directional: wgpu::ComputePipeline,
    uniform_align: u64,
    /// Cells each sweep thread solves ([`sweep_cells_per_thread`]).
    cells_per_thread: u32,
}

/// Simpson steps per cell edge of the `exact` scheme.
pub const EXACT_STEPS_PER_CELL: u32 = 4;

impl Propagator {
    /// `cells_per_thread`: see [`sweep_cells_per_thread`].
    pub fn new(device: &wgpu::Device, opv: OpvLayout, cells_per_thread: u32) -> Self {
        let cells_per_thread = cells_per_thread.max(1);
        let two =
            |a: bool, b: bool| [opv.layout_entries(EXTRA_BINDING, a), opv.layout_entries(EXTRA_BINDING_2, b)].concat();
        let giroud_layout = bind_group_layout_with(
            device,
            "propagate_giroud",
            &[
                Slot::Uniform,
                Slot::Texture3d,
                Slot::StorageRead,
                Slot::StorageRead,
                Slot::Opv { read_only: true },
                Slot::Opv { read_only: false },
            ],
            two(true, false),
        );
        let giroud = compute_pipeline(device, "propagate_giroud", shaders::propagate_giroud(&opv), &giroud_layout);
        // The sweep samples σ_t with hardware trilinear filtering where r32float is filterable.
        let filtered = device.features().contains(wgpu::Features::FLOAT32_FILTERABLE);
        let sweep_layout = bind_group_layout_with(
            device,
            "propagate_sweep",
            &[
                Slot::Uniform,
                if filtered { Slot::Texture3dFiltered } else { Slot::Texture3d },
                Slot::StorageRead,
                Slot::UniformDynamic,
                Slot::Opv { read_only: false },
                Slot::Opv { read_only: false },
                Slot::StorageRead,
                Slot::Sampler { filtering: filtered },
                Slot::StorageRead,
            ],
            two(false, false),
        );
        let sweep = compute_pipeline(
            device,
            "propagate_sweep",
            shaders::propagate_sweep(&opv, cells_per_thread, filtered),
            &sweep_layout,
        );
        let sweep_sampler = device.create_sampler(&wgpu::SamplerDescriptor {
            label: Some("propagate_sweep"),
            address_mode_u: wgpu::AddressMode::ClampToEdge,
            address_mode_v: wgpu::AddressMode::ClampToEdge,
            address_mode_w: wgpu::AddressMode::ClampToEdge,
            mag_filter: if filtered { wgpu::FilterMode::Linear } else { wgpu::FilterMode::Nearest },
            min_filter: if filtered { wgpu::FilterMode::Linear } else { wgpu::FilterMode::Nearest },
            ..Default::default()
        });
        // The exact scheme's layout: grid, EV, lights, per-dispatch parameters, OPV.
        let exact_layout = bind_group_layout_with(
            device,
            "propagate_exact",
            &[
                Slot::Uniform,
                Slot::StorageTexture3dRead(wgpu::TextureFormat::R32Float),
                Slot::StorageRead,
                Slot::UniformDynamic,
                Slot::Opv { read_only: false },
            ],
            opv.layout_entries(EXTRA_BINDING, false),
        );
        let exact = compute_pipeline(device, "propagate_exact", shaders::propagate_exact(&opv), &exact_layout);
        // The exact scheme's bindings plus the particles and the bricks' lists of them.
        let analytic_layout = bind_group_layout_with(
            device,
            "propagate_analytic",
            &[
                Slot::Uniform,
                Slot::Texture3d,
                Slot::StorageRead,
                Slot::UniformDynamic,
                Slot::Opv { read_only: false },
                Slot::StorageRead,
                Slot::StorageRead,
                Slot::StorageRead,
            ],
            opv.layout_entries(EXTRA_BINDING, false),
        );
        let analytic =
            compute_pipeline(device, "propagate_analytic", shaders::propagate_analytic(&opv), &analytic_layout);
        // Same bindings as the exact scheme, one plane of one sun per dispatch.
        let directional =
            compute_pipeline(device, "propagate_directional", shaders::propagate_directional(&opv), &exact_layout);
        let uniform_align = device.limits().min_uniform_buffer_offset_alignment as u64;
        Self {
            giroud_layout,
            giroud,
            sweep_layout,
            sweep,
            sweep_sampler,
            exact_layout,
            exact,
            analytic_layout,
            analytic,
            directional,
            uniform_align,
            cells_per_thread,
        }
    }

    /// Plans the propagation of the `active` lights as a list of dispatches, to be encoded in
    /// order by [`encode_next`](Self::encode_next), in one submit or spread over many.
    ///
    /// `changed[k]`, when given, bounds the cells (inclusive) whose extinction changed since
    /// light `active[k]`'s OPV was last propagated from the same position: the sweep then
    /// starts at the first batch of shells those cells can reach, since every cell depends
    /// only on cells closer to the light. The other schemes recompute everything.
    ///
    /// With the `sweep` and `giroud` schemes, directional lights among `active` are swept plane
    /// by plane along their direction (`propagate_directional.wgsl`), after the other lights'
    /// dispatches; `exact` and `analytic` integrate every light kind's paths themselves.
    pub fn plan(
        &self,
        device: &wgpu::Device,
        inputs: &PropagationInputs,
        scheme: Scheme,
        active: &[u32],
        changed: &[Option<(glam::UVec3, glam::UVec3)>],
    ) -> PropagationJob {
        let sun_of = |l: u32| inputs.directions.get(l as usize).copied().flatten();
        let (mut points, mut points_changed, mut suns) = (Vec::new(), Vec::new(), Vec::new());
        // `exact` and `analytic` treat suns like the other lights (their shaders read the kind).
        let swept = matches!(scheme, Scheme::Sweep | Scheme::Giroud);
        for (k, &l) in active.iter().enumerate() {
            match sun_of(l).filter(|_| swept) {
                Some(direction) => suns.push((l, direction)),
                None => {
                    points.push(l);
                    points_changed.push(changed.get(k).copied().flatten());
                }
            }
        }
        let mut job = if points.is_empty() {
            PropagationJob {
                lights: Vec::new(),
                work: Work::Empty,
                groups: Vec::new(),
                whole: Vec::new(),
                units: Vec::new(),
                next: 0,
                iterations: 0,
                cells: 0,
                suns: None,
            }
        } else {
            self.plan_points(device, inputs, scheme, &points, &points_changed)
        };
        if !suns.is_empty() {
            let params: Vec<PlaneParams> = suns
                .iter()
                .flat_map(|&(l, direction)| sun_planes(inputs.grid, l, direction, SUN_STRIDE, inputs.sweep_refine))
                .collect();
            let r = inputs.grid.resolution.to_array();
            let start = job.groups.len();
            for p in &params {
                let (a1, a2) = ((p.axis as usize + 1) % 3, (p.axis as usize + 2) % 3);
                job.groups.push([r[a1].div_ceil(WORKGROUP_2D), r[a2].div_ceil(WORKGROUP_2D), 1]);
                job.units.push(r[a1] as u64 * r[a2] as u64);
            }
            job.cells += inputs.grid.cell_count() * suns.len() as u64;
            job.lights.extend(suns.iter().map(|&(l, _)| l));
            job.iterations = job.iterations.max(1);
            job.suns = Some((start, self.per_dispatch(device, inputs, &params, Which::Directional, &[], None)));
        }
        job
    }

    fn plan_points(
        &self,
        device: &wgpu::Device,
        inputs: &PropagationInputs,
        scheme: Scheme,
        active: &[u32],
        changed: &[Option<(glam::UVec3, glam::UVec3)>],
    ) -> PropagationJob {
        let cells = inputs.grid.cell_count();
        let mut whole = Vec::new();
        let (work, groups, units, iterations) = match scheme {
            Scheme::Giroud => {
                let iterations = active
                    .iter()
                    .map(|&l| giroud_iterations(inputs.grid, inputs.positions[l as usize]))
                    .max()
                    .unwrap_or(1);
                // An even count leaves the result in buffer A, where every other light's OPV is.
                let iterations = iterations + iterations % 2;
                let active_buf = super::buffers::storage_buffer(device, "active lights", bytemuck::cast_slice(active));
                let make = |src: &OpvVolumes, dst: &OpvVolumes| {
                    bind_group_with(
                        device,
                        "propagate_giroud",
                        &self.giroud_layout,
                        &[
                            inputs.grid_buf.as_entire_binding(),
                            wgpu::BindingResource::TextureView(inputs.ev_view),
                            inputs.lights_buf.as_entire_binding(),
                            active_buf.as_entire_binding(),
                            src.first(),
                            dst.first(),
                        ],
                        [src.extra_entries(EXTRA_BINDING), dst.extra_entries(EXTRA_BINDING_2)].concat(),
                    )
                };
                let [a, b] = inputs.opv;
                let work =
                    Work::Giroud { ab: make(a, b), ba: make(b, a), a: a.clone(), b: b.clone(), _active: active_buf };
                let r = inputs.grid.resolution;
                let g = [
                    r.x.div_ceil(WORKGROUP_3D),
                    r.y.div_ceil(WORKGROUP_3D),
                    r.z.div_ceil(WORKGROUP_3D) * active.len() as u32,
                ];
                (work, vec![g; iterations as usize], vec![cells * active.len() as u64; iterations as usize], iterations)
            }
            Scheme::Sweep => {
                let lights: Vec<(u32, Vec3, u32)> = active
                    .iter()
                    .enumerate()
                    .map(|(k, &l)| {
                        let position = inputs.positions[l as usize];
                        let first = changed.get(k).copied().flatten().map_or(0, |cells| {
                            // With refine, a cell's path also reads the detail of the bricks
                            // it crosses, which a change reaches one cell beyond its bricks.
                            let cells =
                                if inputs.sweep_refine.is_some() { bricks_around(inputs.grid, cells) } else { cells };
                            first_changed_batch(inputs.grid, position, inputs.sweep_stride, cells)
                        });
                        (l, position, first)
                    })
                    .collect();
                let k = self.cells_per_thread as u64;
                let mut plan = sweep_steps_from(inputs.grid, &lights, inputs.sweep_stride, k, ITEM_CELLS / k);
                let (refine, tolerance) = inputs.sweep_refine.map_or((0, 0.0), |t| (1, t));
                plan.steps.iter_mut().chain(plan.whole.iter_mut().map(|w| &mut w.1)).for_each(|s| {
                    s.refine = refine;
                    s.tolerance = tolerance;
                });
                let units = plan
                    .steps
                    .iter()
                    .map(|s| {
                        let boxes = &plan.boxes[s.first_box as usize..(s.first_box + s.box_count) as usize];
                        boxes.iter().map(|b| b.size.iter().map(|&n| n as u64).product::<u64>()).sum()
                    })
                    .collect();
                let placeholder = [SweepBox::zeroed()];
                let boxes = super::buffers::storage_buffer(
                    device,
                    "sweep boxes",
                    bytemuck::cast_slice(if plan.boxes.is_empty() { &placeholder[..] } else { &plan.boxes }),
                );
                // The second OPV buffer holds each cell's mean in-box extinction.
                let extra = [
                    inputs.opv[1].first(),
                    boxes.as_entire_binding(),
                    wgpu::BindingResource::Sampler(&self.sweep_sampler),
                    inputs.brick_max.as_entire_binding(),
                ];
                // Entries: the steps, then each split batch as one step.
                let mut entries = plan.steps.clone();
                for (steps, step, groups) in &plan.whole {
                    whole.push((steps.clone(), entries.len(), *groups));
                    entries.push(*step);
                }
                let work = self.per_dispatch(device, inputs, &entries, Which::Sweep, &extra, Some(boxes.clone()));
                // Dispatches when the whole job is encoded at once.
                let iterations =
                    (plan.steps.len() - plan.whole.iter().map(|(r, _, _)| r.len() - 1).sum::<usize>()) as u32;
                (work, plan.groups, units, iterations)
            }
            Scheme::Exact | Scheme::Analytic => {
                let r = inputs.grid.resolution;
                // One dispatch per light and slab of WORKGROUP_3D layers, so the work can be spread.
                let params: Vec<ExactParams> = active
                    .iter()
                    .flat_map(|&l| {
                        (0..r.z.div_ceil(WORKGROUP_3D)).map(move |s| ExactParams {
                            light: l,
                            steps_per_cell: EXACT_STEPS_PER_CELL,
                            z_offset: WORKGROUP_3D * s,
                            _pad: 0,
                        })
                    })
                    .collect();
                // The analytic scheme's workgroups are rows of cells along x.
                let g = if scheme == Scheme::Analytic {
                    [r.x.div_ceil(WORKGROUP_ROW), r.y, WORKGROUP_3D]
                } else {
                    [r.x.div_ceil(WORKGROUP_3D), r.y.div_ceil(WORKGROUP_3D), 1]
                };
                let groups = vec![g; params.len()];
                let units = vec![r.x as u64 * r.y as u64 * WORKGROUP_3D as u64; params.len()];
                let work = if scheme == Scheme::Analytic {
                    let lists = inputs.analytic_lists.expect("FogPipeline builds the analytic lists before it plans");
                    let particles: Vec<AnalyticParticle> =
                        lists.particles.iter().map(|&i| AnalyticParticle::new(&inputs.particles[i as usize])).collect();
                    let storage = |label: &str, bytes: &[u8]| super::buffers::storage_buffer(device, label, bytes);
                    let particles = storage("analytic particles", bytemuck::cast_slice(&particles));
                    let offsets = storage("analytic brick offsets", bytemuck::cast_slice(&lists.offsets));
                    let items = storage("analytic brick items", bytemuck::cast_slice(&lists.items));
                    let extra = [particles.as_entire_binding(), offsets.as_entire_binding(), items.as_entire_binding()];
                    self.per_dispatch(device, inputs, &params, Which::Analytic, &extra, Some(items.clone()))
                } else {
                    self.per_dispatch(device, inputs, &params, Which::Exact, &[], None)
                };
                (work, groups, units, 1)
            }
        };
        // Cells computed: the sweep's boxes (a partial sweep skips some), every cell otherwise.
        let cells = match scheme {
            Scheme::Sweep => units.iter().sum::<u64>(),
            Scheme::Giroud => cells * active.len() as u64 * iterations as u64,
            Scheme::Exact | Scheme::Analytic => cells * active.len() as u64,
        };
        PropagationJob { lights: active.to_vec(), work, groups, whole, units, next: 0, iterations, cells, suns: None }
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
        let sun_start = job.suns.as_ref().map_or(job.groups.len(), |(start, _)| *start);
        let (all, range) = (range.clone(), range.start.min(sun_start)..range.end.min(sun_start));
        if let (Work::Giroud { a, b, .. }, 0) = (&job.work, job.next) {
            // Lights not being updated must survive in B too, since B feeds back into A.
            a.copy_to(encoder, 0, b, 0, a.lights());
        }
        let mut dispatches = 0u32;
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("propagate"),
                timestamp_writes: timestamps,
            });
            match &job.work {
                Work::Giroud { ab, ba, .. } => {
                    dispatches = range.len() as u32;
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
                        Which::Analytic => &self.analytic,
                        Which::Directional => &self.directional,
                    });
                    let mut i = range.start;
                    while i < range.end {
                        // A batch split over several steps, all encoded here: one dispatch.
                        let joined = job.whole.iter().find(|(steps, _, _)| steps.start == i && steps.end <= range.end);
                        let (entry, g, next) = match joined {
                            Some((steps, entry, g)) => (*entry, *g, steps.end),
                            None => (i, job.groups[i], i + 1),
                        };
                        pass.set_bind_group(0, bind_group, &[(entry as u64 * stride) as u32]);
                        pass.dispatch_workgroups(g[0], g[1], g[2]);
                        dispatches += 1;
                        i = next;
                    }
                }
                Work::Empty => {}
            }
            if let Some((start, Work::PerDispatch { bind_group, stride, .. })) = &job.suns {
                let suns = all.start.max(*start)..all.end;
                if !suns.is_empty() {
                    pass.set_pipeline(&self.directional);
                }
                for i in suns {
                    pass.set_bind_group(0, bind_group, &[((i - start) as u64 * stride) as u32]);
                    let g = job.groups[i];
                    pass.dispatch_workgroups(g[0], g[1], g[2]);
                    dispatches += 1;
                }
            }
        }
        let range = all;
        counters.dispatches += dispatches;
        job.next = range.end;
        if job.done() {
            counters.propagation_iterations = counters.propagation_iterations.max(job.iterations);
            counters.lights_propagated += job.lights.len() as u32;
            counters.cells_propagated += job.cells;
        }
    }

    /// Uploads one uniform entry per dispatch and returns the work over it: grid, EV, lights,
    /// the entries (dynamic offset), the OPV, then `extra` (kept alive in `keep`).
    fn per_dispatch<T: bytemuck::Pod>(
        &self,
        device: &wgpu::Device,
        inputs: &PropagationInputs,
        entries: &[T],
        which: Which,
        extra: &[wgpu::BindingResource],
        keep: Option<wgpu::Buffer>,
    ) -> Work {
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
        let mut resources = vec![
            inputs.grid_buf.as_entire_binding(),
            wgpu::BindingResource::TextureView(inputs.ev_view),
            inputs.lights_buf.as_entire_binding(),
            wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                buffer: &buf,
                offset: 0,
                size: wgpu::BufferSize::new(std::mem::size_of::<T>() as u64),
            }),
            inputs.opv[0].first(),
        ];
        resources.extend(extra.iter().cloned());
        let (layout, segments) = match which {
            Which::Sweep => (
                &self.sweep_layout,
                [inputs.opv[0].extra_entries(EXTRA_BINDING), inputs.opv[1].extra_entries(EXTRA_BINDING_2)].concat(),
            ),
            Which::Exact | Which::Directional => (&self.exact_layout, inputs.opv[0].extra_entries(EXTRA_BINDING)),
            Which::Analytic => (&self.analytic_layout, inputs.opv[0].extra_entries(EXTRA_BINDING)),
        };
        let bind_group = bind_group_with(device, "propagate", layout, &resources, segments);
        Work::PerDispatch { which, bind_group, stride, _buf: buf, _keep: keep }
    }
}

#[derive(Clone, Copy)]
enum Which {
    Sweep,
    Exact,
    Analytic,
    Directional,
}

enum Work {
    /// Jacobi iterations ping-ponging between the two OPV buffers.
    Giroud { ab: wgpu::BindGroup, ba: wgpu::BindGroup, a: OpvVolumes, b: OpvVolumes, _active: wgpu::Buffer },
    /// One dispatch per uniform entry, each seeing its entry through a dynamic offset.
    PerDispatch {
        which: Which,
        bind_group: wgpu::BindGroup,
        stride: u64,
        _buf: wgpu::Buffer,
        _keep: Option<wgpu::Buffer>,
    },
    /// Nothing but directional lights to propagate.
    Empty,
}

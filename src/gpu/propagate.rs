//! Opacity propagation: EV → one optical-depth volume (OPV) per light, by one of four
//! schemes (see [`Scheme`]). The OPVs live in 3D textures, several lights to a texture
//! (see `opv_store`).

use super::gpu_types::{AnalyticParticle, ExactParams, PlaneParams, SweepBox, SweepStep};
use super::layout::{bind_group_layout_with, bind_group_with, compute_pipeline, Slot, VOLUME_LOOKUP};
use super::opv_store::{OpvLayout, OpvVolumes, EXTRA_BINDING, EXTRA_BINDING_2};
use super::Counters;
use crate::scene::{GridSpec, Particle, Scheme};
use bytemuck::Zeroable;
use glam::{IVec3, Vec3};

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
    /// lights), indexed like the OPVs: those are swept by `propagate_directional.wgsl`
    /// whatever the scheme.
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

/// The segment integral the sweeps share (shaders/integrate_exact.wgsl).
pub(crate) const INTEGRATE: &str = include_str!("../../shaders/integrate_exact.wgsl");

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
        let src_dst = opv.wgsl("src", 4, EXTRA_BINDING, false) + &opv.wgsl("dst", 5, EXTRA_BINDING_2, true);
        let giroud = compute_pipeline(
            device,
            "propagate_giroud",
            &[&src_dst, include_str!("../../shaders/propagate_giroud.wgsl")],
            &giroud_layout,
        );
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
        let opv_mean = opv.wgsl("opv", 4, EXTRA_BINDING, true) + &opv.wgsl("mean_in", 5, EXTRA_BINDING_2, true);
        let sigma = if filtered {
            include_str!("../../shaders/sweep_sigma_filtered.wgsl")
        } else {
            include_str!("../../shaders/sweep_sigma_loads.wgsl")
        };
        let sweep = compute_pipeline(
            device,
            "propagate_sweep",
            &[
                &sweep_cells_wgsl(cells_per_thread),
                &opv_mean,
                VOLUME_LOOKUP,
                sigma,
                INTEGRATE,
                include_str!("../../shaders/propagate_sweep.wgsl"),
            ],
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
            &[Slot::Uniform, Slot::Texture3d, Slot::StorageRead, Slot::UniformDynamic, Slot::Opv { read_only: false }],
            opv.layout_entries(EXTRA_BINDING, false),
        );
        let opv_rw = opv.wgsl("opv", 4, EXTRA_BINDING, true);
        let exact = compute_pipeline(
            device,
            "propagate_exact",
            &[&opv_rw, VOLUME_LOOKUP, include_str!("../../shaders/propagate_exact.wgsl")],
            &exact_layout,
        );
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
        let analytic = compute_pipeline(
            device,
            "propagate_analytic",
            &[&opv_rw, include_str!("../../shaders/propagate_analytic.wgsl")],
            &analytic_layout,
        );
        // Same bindings as the exact scheme, one plane of one sun per dispatch.
        let directional = compute_pipeline(
            device,
            "propagate_directional",
            &[
                &opv_rw,
                VOLUME_LOOKUP,
                include_str!("../../shaders/sweep_sigma_loads.wgsl"),
                INTEGRATE,
                include_str!("../../shaders/propagate_directional.wgsl"),
            ],
            &exact_layout,
        );
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
    /// Directional lights among `active` are swept plane by plane along their direction
    /// (`propagate_directional.wgsl`), after the other lights' dispatches.
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
        for (k, &l) in active.iter().enumerate() {
            match sun_of(l) {
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
            let params: Vec<PlaneParams> =
                suns.iter().flat_map(|&(l, direction)| sun_planes(inputs.grid, l, direction, SUN_STRIDE)).collect();
            let r = inputs.grid.resolution.to_array();
            let start = job.groups.len();
            for p in &params {
                let (a1, a2) = ((p.axis as usize + 1) % 3, (p.axis as usize + 2) % 3);
                job.groups.push([r[a1].div_ceil(8), r[a2].div_ceil(8), 1]);
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
                let g = [r.x.div_ceil(4), r.y.div_ceil(4), r.z.div_ceil(4) * active.len() as u32];
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
                // The analytic scheme's workgroups are rows of 64 cells along x.
                let g = if scheme == Scheme::Analytic {
                    [r.x.div_ceil(64), r.y, 4]
                } else {
                    [r.x.div_ceil(4), r.y.div_ceil(4), 1]
                };
                let groups = vec![g; params.len()];
                let units = vec![r.x as u64 * r.y as u64 * 4; params.len()];
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

/// Planes a sun's sweep steps back per interpolation: each step integrates the medium exactly
/// over this many planes and interpolates once, so fewer interpolations blur the shadows less.
pub const SUN_STRIDE: u32 = 16;

/// The dispatches of one sun's sweep, upstream plane first. The planes are stacked along the
/// axis the light travels most along; each plane interpolates in the plane `stride` planes
/// upstream (fewer interpolations, less numerical diffusion), the first `stride` planes
/// integrate straight to the box.
fn sun_planes(grid: &GridSpec, light: u32, direction: Vec3, stride: u32) -> Vec<PlaneParams> {
    let towards = -direction;
    let axis = towards.abs().max_position();
    let n = grid.resolution[axis];
    // The sun lies towards +axis when towards[axis] > 0: light enters at the last plane.
    let from_top = towards[axis] > 0.0;
    (0..n)
        .map(|k| {
            let plane = if from_top { n - 1 - k } else { k };
            let previous = if k < stride {
                plane
            } else if from_top {
                plane + stride
            } else {
                plane - stride
            };
            PlaneParams { light, axis: axis as u32, plane, previous }
        })
        .collect()
}

/// The dispatches that bring the OPVs of some lights up to date, each valid to run once the
/// ones before it have completed, in this or an earlier submit.
pub struct PropagationJob {
    /// The lights this job propagates.
    pub lights: Vec<u32>,
    work: Work,
    groups: Vec<[u32; 3]>,
    /// Runs of steps that form one batch, with the entry and workgroups that run them as one.
    whole: Vec<(std::ops::Range<usize>, usize, [u32; 3])>,
    /// Cells each dispatch computes: the unit of its cost.
    units: Vec<u64>,
    next: usize,
    iterations: u32,
    /// Cells the whole job computes.
    cells: u64,
    /// Directional lights' dispatches: those from this index on.
    suns: Option<(usize, Work)>,
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
/// axis, to 2²⁰ cells beyond the grid, which keeps the integer arithmetic far inside i32.
fn light_cell(grid: &GridSpec, light: Vec3) -> IVec3 {
    const FAR: f32 = (1 << 20) as f32;
    let c = ((light - grid.min) / grid.cell_size()).floor();
    c.clamp(Vec3::splat(-FAR), grid.resolution.as_vec3() + FAR).as_ivec3()
}

/// A light farther than this many cells from the grid's centre has its Chebyshev shells
/// measured from the point at this distance on the line to it, so that shell levels stay
/// exact to a small fraction of a cell in f32; the shells then stay within a fraction of a
/// cell of being perpendicular to the light's rays, which keeps the sweep's ordering.
const ANCHOR_CELLS: f64 = (1u64 << 19) as f64;

/// Threads per sweep dispatch before a batch is split over several dispatches.
const MAX_THREADS_PER_DISPATCH: u64 = 1 << 30;

/// Threads per workgroup of `propagate_sweep.wgsl` (its `@workgroup_size`). llvmpipe pays a
/// fixed cost per workgroup, so larger groups amortise it over more cells.
const SWEEP_WORKGROUP: u64 = 256;

/// The cells of one of the scheduler's work items (a batch's cells do not read each other, so
/// any split between its boxes is valid): small enough that one dispatch fits an interactive
/// frame budget on a software adapter, large enough that dispatch overhead stays negligible
/// on a GPU.
pub const ITEM_CELLS: u64 = 1 << 15;

/// The declaration propagate_sweep.wgsl expects before it: its cells per thread.
pub(crate) fn sweep_cells_wgsl(cells_per_thread: u32) -> String {
    format!("const SWEEP_CELLS: u32 = {cells_per_thread}u;\n")
}

/// Cells each sweep thread solves on an adapter of `device_type`. A CPU adapter (llvmpipe)
/// pays a fixed cost per invocation that is comparable with a cell's work, which several
/// cells per thread amortise (`fogsmith bench --suite opv` measures it); a GPU wants one
/// thread per cell.
pub fn sweep_cells_per_thread(device_type: wgpu::DeviceType) -> u32 {
    if device_type == wgpu::DeviceType::Cpu {
        8
    } else {
        1
    }
}

/// How one light's cells are ordered into batches of Chebyshev shells.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShellFrame {
    /// Shell centre in cell-centre coordinates (cell (i, j, k) at (i, j, k)).
    pub anchor: [f32; 3],
    /// Level (Chebyshev distance in cells) where batch 0 starts.
    pub level0: f32,
    /// Levels per batch.
    pub width: f32,
    pub batches: u32,
}

impl ShellFrame {
    pub fn new(grid: &GridSpec, light: Vec3, stride: u32) -> Self {
        let n = grid.resolution.as_dvec3();
        let cell = grid.cell_size().as_dvec3();
        let s = (light.as_dvec3() - grid.min.as_dvec3()) / cell - 0.5;
        let centre = (n - 1.0) * 0.5;
        let off = s - centre;
        let far = off.length();
        let anchor = if far > ANCHOR_CELLS { centre + off * (ANCHOR_CELLS / far) } else { s };
        let anchor = anchor.as_vec3();
        let a = anchor.as_dvec3();
        let (mut near, mut farthest) = (0.0f64, 0.0f64);
        for i in 0..3 {
            let hi = n[i] - 1.0;
            near = near.max((-a[i]).max(a[i] - hi).max(0.0));
            farthest = farthest.max(a[i].abs().max((a[i] - hi).abs()));
        }
        let level0 = near.floor() as f32;
        // Bilinear reads (stride 3) reach 1 cell beyond the crossing laterally, Catmull-Rom
        // reads 2: a cell depends only on cells at least stride − 1 or stride − 2 levels
        // closer, and one level of margin is kept for rounding.
        let width = if stride <= 3 { 1 } else { stride - 3 };
        // One level of slack beyond the farthest cell absorbs f32 rounding of the levels.
        let batches = ((farthest + 1.0 - level0 as f64) / width as f64).floor() as u32 + 1;
        Self { anchor: anchor.to_array(), level0, width: width as f32, batches }
    }

    /// The batch and face that solve cell `c`, computed exactly as the shader does.
    pub fn claim(&self, c: [i32; 3]) -> (u32, u32) {
        let r = [c[0] as f32 - self.anchor[0], c[1] as f32 - self.anchor[1], c[2] as f32 - self.anchor[2]];
        let mut a = 0;
        if r[1].abs() > r[a].abs() {
            a = 1;
        }
        if r[2].abs() > r[a].abs() {
            a = 2;
        }
        let face = 2 * a as u32 + u32::from(r[a] < 0.0);
        let batch = ((r[a].abs() - self.level0) / self.width).floor().max(0.0) as u32;
        (batch, face)
    }

    /// Boxes of cells (lo, size), one per layer of the face's axis, that together hold every
    /// cell of `batch` on `face`: a layer is listed where the shader's own batch arithmetic
    /// (f32, as in [`claim`](Self::claim)) can place it in `batch`, and its box spans exactly
    /// the layer's cells that `claim` gives to the face. Cells of a layer all share the face
    /// axis' offset, so few threads are idle.
    fn face_boxes(&self, grid: &GridSpec, batch: u32, face: u32) -> Vec<([i32; 3], [u32; 3])> {
        let n = grid.resolution.as_ivec3();
        let axis = (face / 2) as usize;
        let negative = face % 2 == 1;
        let lo_level = self.level0 as f64 + batch as f64 * self.width as f64;
        let hi_level = lo_level + self.width as f64;
        let a = self.anchor[axis] as f64;
        let (from, to) = if negative { (a - hi_level, a - lo_level) } else { (a + lo_level, a + hi_level) };
        let first = (from.floor() as i64 - 1).max(0);
        let last = (to.ceil() as i64 + 1).min(n[axis] as i64 - 1);
        let mut out = Vec::new();
        for layer in first..=last {
            let r = layer as f32 - self.anchor[axis];
            if (r < 0.0) != negative {
                continue;
            }
            // The shader divides within a few ulp: a layer next to a batch boundary is listed
            // in both batches, and each cell is still solved once (the shader checks its claim).
            let q = (r.abs() - self.level0) / self.width;
            let eps = 1e-5 * q.abs().max(1.0);
            let (b0, b1) = ((q - eps).floor().max(0.0) as u32, (q + eps).floor().max(0.0) as u32);
            if batch != b0 && batch != b1 {
                continue;
            }
            let reach = r.abs() as f64;
            let (mut lo, mut size) = ([0i32; 3], [1u32; 3]);
            lo[axis] = layer as i32;
            let mut empty = false;
            for i in (0..3).filter(|&i| i != axis) {
                let c = self.anchor[i] as f64;
                // The face's own cells along axis i, as the shader's largest_axis assigns
                // them in f32 (ties go to the lower axis), form an interval around the anchor
                // inside these bounds; the shader runs every listed cell, claimed or not.
                let on_face = |x: i64| {
                    let ri = (x as f32 - self.anchor[i]).abs();
                    if i < axis {
                        ri < r.abs()
                    } else {
                        ri <= r.abs()
                    }
                };
                let mut from = ((c - reach).floor() as i64 - 1).max(0);
                let mut to = ((c + reach).ceil() as i64 + 1).min(n[i] as i64 - 1);
                while from <= to && !on_face(from) {
                    from += 1;
                }
                while to >= from && !on_face(to) {
                    to -= 1;
                }
                if from > to {
                    empty = true;
                    break;
                }
                lo[i] = from as i32;
                size[i] = (to - from + 1) as u32;
            }
            if !empty {
                out.push((lo, size));
            }
        }
        out
    }
}

/// The sweep's dispatches: each step solves its boxes, one batch of shells for each light
/// it covers, and only reads cells that earlier steps solved.
#[derive(Clone, Debug, Default)]
pub struct SweepPlan {
    pub steps: Vec<SweepStep>,
    /// Workgroups of each step.
    pub groups: Vec<[u32; 3]>,
    pub boxes: Vec<SweepBox>,
    /// Batches split over several steps, each as one dispatch: (its steps, the step that
    /// covers them all, its workgroups), used when all those steps are encoded together.
    pub whole: Vec<(std::ops::Range<usize>, SweepStep, [u32; 3])>,
}

/// Plans the sweep of `lights` (OPV index, position) with interpolation stride `stride`:
/// dispatch j solves batch j of every light that has one.
pub fn sweep_steps(grid: &GridSpec, lights: &[(u32, Vec3)], stride: u32) -> SweepPlan {
    let all: Vec<(u32, Vec3, u32)> = lights.iter().map(|&(l, p)| (l, p, 0)).collect();
    sweep_steps_from(grid, &all, stride, 1, MAX_THREADS_PER_DISPATCH)
}

/// [`sweep_steps`] where each light `(index, position, first)` starts at batch `first` (the
/// batches before it are left as they are), with `cells_per_thread` cells per thread and at
/// most `max_threads` threads per dispatch where boxes allow.
pub fn sweep_steps_from(
    grid: &GridSpec,
    lights: &[(u32, Vec3, u32)],
    stride: u32,
    cells_per_thread: u64,
    max_threads: u64,
) -> SweepPlan {
    let frames: Vec<(u32, ShellFrame, u32)> =
        lights.iter().map(|&(l, p, first)| (l, ShellFrame::new(grid, p, stride), first)).collect();
    let batches = frames.iter().map(|(_, f, _)| f.batches).max().unwrap_or(0);
    let mut plan = SweepPlan::default();
    let workgroups = |threads: u64| {
        let groups = threads.div_ceil(SWEEP_WORKGROUP).max(1);
        let x = groups.min(65_535);
        ([x as u32, groups.div_ceil(x) as u32, 1], x as u32 * SWEEP_WORKGROUP as u32)
    };
    // Box `first` fields count threads from the start of the batch; a step starts at `offset`.
    let flush = |plan: &mut SweepPlan, first_box: usize, offset: u64, threads: u64| {
        if plan.boxes.len() == first_box {
            return;
        }
        let (groups, row) = workgroups(threads - offset);
        plan.groups.push(groups);
        plan.steps.push(SweepStep {
            first_box: first_box as u32,
            box_count: (plan.boxes.len() - first_box) as u32,
            row,
            stride,
            offset: offset as u32,
            refine: 0,
            tolerance: 0.0,
            _pad: 0,
        });
    };
    for batch in 0..batches {
        let (batch_box, batch_step) = (plan.boxes.len(), plan.steps.len());
        let (mut first_box, mut offset, mut threads) = (plan.boxes.len(), 0u64, 0u64);
        for &(light, frame, _) in frames.iter().filter(|(_, f, first)| batch < f.batches && batch >= *first) {
            for (face, (lo, size)) in
                (0..6).flat_map(|face| frame.face_boxes(grid, batch, face).into_iter().map(move |b| (face, b)))
            {
                let box_threads = size.iter().map(|&s| s as u64).product::<u64>().div_ceil(cells_per_thread);
                if threads - offset + box_threads > max_threads && threads > offset {
                    flush(&mut plan, first_box, offset, threads);
                    first_box = plan.boxes.len();
                    offset = threads;
                }
                plan.boxes.push(SweepBox {
                    lo,
                    light,
                    size,
                    first: threads as u32,
                    anchor: frame.anchor,
                    level0: frame.level0,
                    width: frame.width,
                    face,
                    batch,
                    _pad: 0,
                });
                threads += box_threads;
            }
        }
        flush(&mut plan, first_box, offset, threads);
        if plan.steps.len() > batch_step + 1 && threads <= MAX_THREADS_PER_DISPATCH {
            let (groups, row) = workgroups(threads);
            let step = SweepStep {
                first_box: batch_box as u32,
                box_count: (plan.boxes.len() - batch_box) as u32,
                row,
                stride,
                offset: 0,
                refine: 0,
                tolerance: 0.0,
                _pad: 0,
            };
            plan.whole.push((batch_step..plan.steps.len(), step, groups));
        }
    }
    plan
}

/// The first batch of shells of a light at `position` that cells `changed` (inclusive cell
/// bounds) can affect. A cell at Chebyshev level L (in cells from the shells' centre) reads
/// the extinction only along its path towards the light, whose levels fall monotonically,
/// through stencils one cell wide, and otherwise only cells of earlier batches: it can change
/// only if L + 1 reaches the nearest changed cell. One batch and two levels of slack absorb
/// rounding. A far light's shells are centred on a nearer point of its line, where that
/// argument does not hold: it starts at 0.
pub fn first_changed_batch(grid: &GridSpec, position: Vec3, stride: u32, changed: (glam::UVec3, glam::UVec3)) -> u32 {
    let frame = ShellFrame::new(grid, position, stride);
    let light = ((position - grid.min) / grid.cell_size() - 0.5).to_array();
    if (0..3).any(|i| (frame.anchor[i] - light[i]).abs() > 1e-3) {
        return 0;
    }
    let (lo, hi) = (changed.0.as_vec3().to_array(), changed.1.as_vec3().to_array());
    let nearest =
        (0..3).map(|i| (lo[i] - frame.anchor[i]).max(frame.anchor[i] - hi[i]).max(0.0)).fold(0.0f32, f32::max);
    let first = ((nearest - 2.0 - frame.level0) / frame.width).floor() - 1.0;
    if first > 0.0 {
        first as u32
    } else {
        0
    }
}

/// Jacobi sweeps after which the `giroud` gather has converged exactly: one more than the
/// largest Manhattan distance (in cells) from any cell to the light's slabs.
/// The cells of the bricks whose detail a change of `cells` (inclusive bounds) can alter: its
/// bricks and those one cell beyond them (`shaders/occupancy.wgsl` reads one cell around).
fn bricks_around(grid: &GridSpec, (lo, hi): (glam::UVec3, glam::UVec3)) -> (glam::UVec3, glam::UVec3) {
    let b = super::binning::BRICK;
    let max = grid.resolution.max(glam::UVec3::ONE) - 1;
    let lo = lo.saturating_sub(glam::UVec3::ONE) / b * b;
    let hi = ((hi + 1) / b * b + (b - 1)).min(max);
    (lo, hi)
}

pub fn giroud_iterations(grid: &GridSpec, light: Vec3) -> u32 {
    let lc = light_cell(grid, light);
    let n = grid.resolution.as_ivec3();
    let mut total = 0;
    for a in 0..3 {
        total += if lc[a] < 0 || lc[a] >= n[a] { n[a] } else { lc[a].max(n[a] - 1 - lc[a]) };
    }
    total as u32 + 1
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::UVec3;

    /// The cells a sweep cell reads (none when it integrates directly), as the shader finds them.
    fn reads(grid: &GridSpec, light: Vec3, stride: u32, c: [i32; 3]) -> Vec<[i32; 3]> {
        let cell = grid.cell_size();
        let x = grid.min + (IVec3::from(c).as_vec3() + 0.5) * cell;
        let v = light - x;
        let len = v.length();
        let dir = v / len;
        let exit = |lo: Vec3, hi: Vec3| {
            let (mut at, mut axis) = (len, 3);
            for i in 0..3 {
                let t = if dir[i] > 0.0 {
                    (hi[i] - x[i]) / dir[i]
                } else if dir[i] < 0.0 {
                    (lo[i] - x[i]) / dir[i]
                } else {
                    len
                };
                if t < at {
                    (at, axis) = (t, i);
                }
            }
            (at.max(0.0), axis)
        };
        let (inside, _) = exit(grid.min, grid.max);
        let (_, exit_axis) = exit(grid.min + 0.5 * cell, grid.max - 0.5 * cell);
        let mag = (v / cell).abs();
        let mut a = 0;
        if mag.y > mag[a] {
            a = 1;
        }
        if mag.z > mag[a] {
            a = 2;
        }
        let s = stride as f32;
        let (mut e, mut layers) = (a, s);
        if exit_axis < 3 && exit_axis != a {
            e = exit_axis;
            layers = (s * mag[e] / mag[a]).ceil().max(1.0);
        }
        let to_plane = len * layers / mag[e];
        let n = grid.resolution.as_ivec3();
        let layer = c[e] + layers as i32 * v[e].signum() as i32;
        if mag[a] < s + 0.5 || inside <= to_plane || layer < 0 || layer >= n[e] {
            return Vec::new();
        }
        let p = x + dir * to_plane;
        let u = (p - grid.min) / cell - 0.5;
        let reach = if stride >= 4 { 1 } else { 0 };
        let mut out = Vec::new();
        let (b, d) = ((e + 1) % 3, (e + 2) % 3);
        let fb = u[b].clamp(0.0, (n[b] - 1) as f32).floor() as i32;
        let fd = u[d].clamp(0.0, (n[d] - 1) as f32).floor() as i32;
        for j in -reach..=1 + reach {
            for i in -reach..=1 + reach {
                let mut r = IVec3::from(c);
                r[e] = layer;
                r[b] = (fb + i).clamp(0, n[b] - 1);
                r[d] = (fd + j).clamp(0, n[d] - 1);
                out.push(r.to_array());
            }
        }
        out
    }

    fn placements(grid: &GridSpec) -> Vec<Vec3> {
        let (lo, hi, c) = (grid.min, grid.max, (grid.min + grid.max) * 0.5);
        let size = grid.size();
        let mut out = vec![
            c,
            lo + size * Vec3::new(0.13, 0.71, 0.37),
            lo,
            hi,
            Vec3::new(lo.x, c.y, hi.z),
            Vec3::new(c.x, hi.y, c.z),
        ];
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let d = Vec3::new(dx as f32, dy as f32, dz as f32);
                    if d != Vec3::ZERO {
                        out.push(c + d * size * 0.8);
                        out.push(c + d * size * 0.5 + Vec3::new(0.01, -0.02, 0.03) * size);
                        out.push(c + d * 1e9 / d.length() + Vec3::new(3.0, -7.0, 1.0));
                    }
                }
            }
        }
        out.push(Vec3::new(1e9, -1e9, 1e8));
        out.push(Vec3::new(0.3, 1e3, -2e2));
        out
    }

    /// Every cell is solved by exactly one box of the plan, after every cell it reads, and a
    /// box lists only cells of its own face (the shader runs every listed cell).
    #[test]
    fn sweep_plan_solves_each_cell_once_after_its_inputs() {
        for (res, stride) in [
            (UVec3::new(12, 12, 12), 3),
            (UVec3::new(20, 9, 5), 8),
            (UVec3::new(40, 6, 6), 16),
            (UVec3::new(17, 17, 17), 5),
        ] {
            let grid = GridSpec { min: Vec3::new(-1.0, 0.0, -0.5), max: Vec3::new(1.5, 1.0, 0.5), resolution: res };
            for light in placements(&grid) {
                let frame = ShellFrame::new(&grid, light, stride);
                let plan = sweep_steps(&grid, &[(0, light)], stride);
                assert!(plan.steps.len() as u32 <= frame.batches, "{light}");
                for b in &plan.boxes {
                    for k in 0..b.size[2] as i32 {
                        for j in 0..b.size[1] as i32 {
                            for i in 0..b.size[0] as i32 {
                                let c = [b.lo[0] + i, b.lo[1] + j, b.lo[2] + k];
                                assert_eq!(
                                    frame.claim(c).1,
                                    b.face,
                                    "{res} {light}: cell {c:?} listed for face {}",
                                    b.face
                                );
                            }
                        }
                    }
                }
                let n = res.as_ivec3();
                for k in 0..n.z {
                    for j in 0..n.y {
                        for i in 0..n.x {
                            let c = [i, j, k];
                            let (batch, face) = frame.claim(c);
                            let holders = plan
                                .boxes
                                .iter()
                                .filter(|b| b.batch == batch && b.face == face)
                                .filter(|b| (0..3).all(|a| c[a] >= b.lo[a] && c[a] < b.lo[a] + b.size[a] as i32))
                                .count();
                            assert_eq!(holders, 1, "{res} {light} cell {c:?} batch {batch} face {face}");
                            for r in reads(&grid, light, stride, c) {
                                let (rb, _) = frame.claim(r);
                                assert!(
                                    rb < batch,
                                    "{res} s{stride} {light}: cell {c:?} (batch {batch}) reads {r:?} (batch {rb})"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// All lights share each dispatch: the count is the batches of the deepest light.
    #[test]
    fn sweep_dispatches_are_batches_of_shells_shared_by_lights() {
        let grid = GridSpec { min: Vec3::ZERO, max: Vec3::ONE, resolution: UVec3::splat(64) };
        let lights = [(0, Vec3::splat(0.5)), (1, Vec3::new(3.0, 0.5, 0.5)), (2, Vec3::new(-1e9, 1e9, 1e9))];
        let plan = sweep_steps(&grid, &lights, 8);
        let deepest = lights.iter().map(|&(_, p)| ShellFrame::new(&grid, p, 8).batches).max().unwrap();
        assert_eq!(plan.steps.len() as u32, deepest);
        // Batches of stride − 3 = 5 levels: 64 levels from outside, 32 from the centre.
        assert!(deepest <= 65 / 5 + 1, "{deepest}");
        let centre = ShellFrame::new(&grid, Vec3::splat(0.5), 8).batches;
        assert!(centre <= 33 / 5 + 1, "{centre}");
    }
}

//! What the adapter can hold: the checks that refuse, before anything is allocated, a scene
//! or request larger than the adapter's limits or memory, with the limit named and a way out,
//! and the memory estimates they rest on.

use super::binning;
use super::frame_inputs::{noise_of, FrameRequest};
use super::gpu_types::{LightGpu, ParticleGpu};
use super::opv_store::{OpvLayout, MAX_TEXTURE_BYTES};
use super::{GpuContext, GpuError};
use crate::scene::{GridSpec, Project, Scheme, Volume};

/// The adapter and the pipeline's settings a scene's size is checked against.
pub(super) struct Capacity<'a> {
    pub ctx: &'a GpuContext,
    pub opv_layout: OpvLayout,
    /// The particle–bin list bytes one injection chunk may use.
    pub chunk_bytes: u64,
    /// The imported base layer, when one is set.
    pub base_layer: Option<&'a Volume>,
}

impl Capacity<'_> {
    /// Refuses, before allocating anything, a scene larger than the adapter allows: grid edge
    /// (3D texture), OPVs (texture bindings, see `opv_store`), particles and lights (one
    /// storage binding each), the image (2D texture and its readback buffer), and the GPU
    /// memory all of it needs together where the device's memory is known.
    pub fn check_limits(&self, project: &Project, width: u32, height: u32) -> Result<(), GpuError> {
        self.check_sizes(&project.grid, project.lights.len(), project.particles.len(), width, height)?;
        // The base layer is read through one storage binding (set_base_layer uploads nothing
        // larger): refused here rather than injected as empty.
        if let Some(v) = self.base_layer {
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
    /// maxima, the OPV array, its scratch twin and the march's lookup array, injection lists of one chunk and the
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
            self.chunk_bytes.min(particles as u64 * bins * 4) + bins * 4 + particle_bytes
        };
        let pixels = width as u64 * height as u64;
        cells * 4 + bricks * 8 + 3 * cells * lights.max(1) as u64 * 4 + lists + pixels * (16 + 4) * 2 + pixels * 16
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

    /// Refuses an invalid request, or a project the adapter cannot hold. The particles and
    /// tracks are trusted: they were validated where they entered (loading, importing,
    /// editing), and checking them here would scan every particle on every call.
    pub fn check_request(&self, project: &Project, request: &FrameRequest) -> Result<(), GpuError> {
        project.validate_settings(self.ctx.max_grid_edge()).map_err(|e| GpuError::Invalid(e.to_string()))?;
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
        if let Some(v) = self.base_layer {
            if v.grid != project.grid {
                return Err(GpuError::Invalid(
                    "the base layer was resampled for another grid; load it again for this grid".into(),
                ));
            }
        }
        // The analytic scheme integrates particles and fog in closed form: it refuses what
        // only the grid holds.
        if request.scheme == Scheme::Analytic {
            if let Some(what) = analytic_unsupported(project).or(self.base_layer.map(|_| "an imported base volume")) {
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
    pub fn analytic_lists(&self, project: &Project) -> Result<binning::ChunkBins, GpuError> {
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

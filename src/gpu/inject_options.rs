//! How the injection runs, as the [`Tuning`] says: where it sums the particles (host or
//! adapter), the bin edge of its particle lists, the size of its memory chunks, and brute
//! force for measurements.

use super::binning::{self, particle_gpu, BinCounts};
use super::gpu_types::ParticleGpu;
use super::host_sums;
use super::inject::{InjectJob, Injector};
use super::tuning::{InjectPath, Tuning};
use super::GpuContext;
use crate::scene::{GridSpec, Project};

/// Particle–brick overlaps per brick of the grid from which `InjectPath::Auto` sums on the
/// host. Below it the host's fixed cost per brick (its sums written, uploaded and read) exceeds
/// the gather's list walk: on llvmpipe at about 8 the two paths take the same time
/// (`fogsmith bench --suite scale` measures both on its largest particle cases).
pub const HOST_MIN_ENTRIES_PER_BRICK: u64 = 8;

/// The smallest box holding the centres of every cell of `bricks` (linear brick indices).
fn cell_centre_box(grid: &GridSpec, bricks: &[u32]) -> (glam::Vec3, glam::Vec3) {
    let dims = binning::brick_dims(grid);
    let (mut lo, mut hi) = (glam::UVec3::MAX, glam::UVec3::ZERO);
    for &b in bricks {
        let at = glam::UVec3::new(b % dims.x, (b / dims.x) % dims.y, b / (dims.x * dims.y));
        lo = lo.min(at * binning::BRICK);
        hi = hi.max(((at + 1) * binning::BRICK).min(grid.resolution) - 1);
    }
    if bricks.is_empty() {
        return (glam::Vec3::INFINITY, glam::Vec3::NEG_INFINITY);
    }
    let centre = |c: glam::UVec3| grid.min + (c.as_vec3() + 0.5) * grid.cell_size();
    (centre(lo), centre(hi))
}

/// What the host path knows of the particles the EV was last planned for: their counts per
/// brick (which decide the path and weigh the bricks) and the longest cut-off reach among
/// them (which bounds the particles a brick can see). Both are kept up to date edit by edit
/// ([`HostCounts::update`]), so that planning a dab costs the dab, not the scene.
#[derive(Clone)]
pub(super) struct HostCounts {
    counts: BinCounts,
    /// No particle's cut-off reaches further, in metres (an upper bound: removing a particle
    /// leaves it as it was).
    reach: f32,
}

impl HostCounts {
    pub fn new(grid: &GridSpec, particles: &[crate::scene::Particle]) -> Self {
        let reach = particles.iter().map(binning::cutoff_radius).fold(0.0f32, f32::max);
        Self { counts: BinCounts::new(grid, particles, binning::BRICK, false), reach }
    }

    /// The counts and reach after `removed` left the particles and `added` joined them.
    pub fn update(&mut self, grid: &GridSpec, change: &binning::Change) {
        self.counts.update(grid, &change.removed, &change.added);
        self.reach = change.added.iter().map(|p| binning::cutoff_radius(p)).fold(self.reach, f32::max);
    }
}

/// The injection's part of the [`Tuning`].
#[derive(Clone, Copy, Debug, Default)]
pub(super) struct InjectOptions {
    pub brute_force: bool,
    pub bin_edge: Option<u32>,
    pub path: InjectPath,
    /// Cap on one chunk's particle–bin list bytes (None: one storage binding).
    pub chunk_limit: Option<u64>,
}

impl InjectOptions {
    pub fn of(tuning: &Tuning) -> Self {
        Self {
            brute_force: tuning.brute_force_injection,
            bin_edge: tuning.inject_bin_edge,
            path: tuning.inject_path,
            chunk_limit: tuning.inject_chunk_bytes,
        }
    }

    /// The particle–bin list bytes one injection chunk may use.
    pub fn chunk_bytes(&self, ctx: &GpuContext) -> u64 {
        let binding = ctx.max_binding_bytes();
        self.chunk_limit.map_or(binding, |b| b.clamp(4, binding))
    }

    /// Whether injecting `project` sums its particles on the host.
    pub fn on_host(&self, ctx: &GpuContext, project: &Project) -> bool {
        self.host_possible(ctx)
            && self.host_pays(&project.grid, &BinCounts::new(&project.grid, &project.particles, binning::BRICK, false))
    }

    /// The injection of `bricks` of `project`, on the path these options choose, with the bin
    /// edge of its particle lists when the adapter sums them. `noise`: the medium's noise
    /// modulates the EV. `host`: the host path's counts of `project`'s particles, given
    /// whenever [`host_possible`](Self::host_possible).
    pub fn begin(
        &self,
        ctx: &GpuContext,
        project: &Project,
        noise: bool,
        bricks: Vec<u32>,
        host: Option<&HostCounts>,
    ) -> (InjectJob, Option<u32>) {
        let grid = &project.grid;
        let max_items = self.chunk_bytes(ctx) / 4;
        let host = host.filter(|h| self.host_possible(ctx) && self.host_pays(grid, &h.counts));
        if let Some(host) = host {
            // The host lists nothing. Only particles that reach the dirty bricks add to them:
            // a dab orders its neighbourhood, not the scene (in the same relative order, so
            // every sum is the same bit for bit). A centre further out than the longest reach
            // (with room for rounding) fails the test below, so it is not converted first.
            let (lo, hi) = cell_centre_box(grid, &bricks);
            let cell = grid.cell_size();
            let slack = (glam::Vec3::splat(host.reach) + cell) * 1.01;
            let (near_lo, near_hi) = (lo - slack, hi + slack);
            let near: Vec<ParticleGpu> = project
                .particles
                .iter()
                .filter(|p| p.center.cmpge(near_lo).all() && p.center.cmple(near_hi).all())
                .map(|p| particle_gpu(p, noise))
                .filter(|p| {
                    let reach = glam::Vec3::splat(p.cutoff2.sqrt() * 1.001) + cell;
                    let c = glam::Vec3::from_array(p.center);
                    (c + reach).cmpge(lo).all() && (c - reach).cmple(hi).all()
                })
                .collect();
            let ordered = host_sums::order(grid, near, |p| p.cutoff2.sqrt());
            let counts = host.counts.clone();
            let job = Injector::begin(grid, Vec::new(), Vec::new(), counts, bricks, max_items, Some(ordered));
            return (job, None);
        }
        let particles: Vec<ParticleGpu> = project.particles.iter().map(|p| particle_gpu(p, noise)).collect();
        let counts = binning::choose_bins(grid, &project.particles, max_items, self.brute_force, self.bin_edge);
        let bin_size = counts.bin_size;
        let job = Injector::begin(grid, project.particles.clone(), particles, counts, bricks, max_items, None);
        (job, Some(bin_size))
    }

    /// Whether the injection may take the host path, for scenes dense enough under `Auto`.
    pub fn host_possible(&self, ctx: &GpuContext) -> bool {
        match self.path {
            InjectPath::Host => true,
            InjectPath::Adapter => false,
            InjectPath::Auto => {
                ctx.adapter_info.device_type == wgpu::DeviceType::Cpu && !self.brute_force && self.bin_edge.is_none()
            }
        }
    }

    /// Given [`host_possible`](Self::host_possible) and the scene's per-brick particle counts,
    /// whether it takes the host path.
    fn host_pays(&self, grid: &GridSpec, brick_counts: &BinCounts) -> bool {
        self.path == InjectPath::Host
            || brick_counts.entries()
                >= HOST_MIN_ENTRIES_PER_BRICK * binning::brick_dims(grid).as_u64vec3().element_product()
    }
}

//! The inputs each stage's result on the GPU was computed from, as typed keys, and what the
//! GPU holds ([`Baked`]): a stage reruns only when its key differs from the baked one.

use super::binning;
use super::gpu_types::{GridParams, LightGpu, MarchParams, SurfaceGpu};
use crate::scene::{GridSpec, Noise, Particle, Scheme};

/// What the extinction volume was injected from.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct EvKey {
    pub grid: GridSpec,
    pub base_extinction: f32,
    /// Height fog falloff and origin.
    pub height: [f32; 2],
    pub layer_generation: u64,
    pub brute_force: bool,
    /// The medium's noise, when it modulates anything (see `frame_inputs::noise_of`).
    pub noise: Option<Noise>,
}

/// What a light's optical-depth volume was propagated from.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) struct OpvKey {
    pub position: glam::Vec3,
    pub ev_generation: u64,
    pub scheme: Scheme,
    pub stride: u32,
    /// The sweep's tolerance, with `sweep_refine`.
    pub refine: Option<f32>,
    /// A directional light, whose `position` holds its unit direction.
    pub sun: bool,
}

/// Everything a march reads: two marches with equal keys give identical images.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct ImageKey {
    pub params: MarchParams,
    pub grid: GridParams,
    pub lights: Vec<LightGpu>,
    pub surfaces: Vec<SurfaceGpu>,
    pub ev_generation: u64,
    pub opvs: Vec<Option<OpvKey>>,
    /// The multiple-scattering solve the march reads ([`Baked::scatter`]'s generation); 0:
    /// none.
    pub scatter: u64,
}

/// What a multiple-scattering solve read: the march's medium and the inputs of the first
/// scattering (EV, OPVs, lights, surfaces), plus the solver's settings.
#[derive(Clone, Debug, PartialEq)]
pub(super) struct ScatterKey {
    pub settings: crate::scene::MultipleScattering,
    pub factor: u32,
    pub albedo: f32,
    pub anisotropy: f32,
    pub grid: GridParams,
    pub lights: Vec<LightGpu>,
    pub surfaces: Vec<SurfaceGpu>,
    pub ev_generation: u64,
    pub opvs: Vec<Option<OpvKey>>,
}

impl ImageKey {
    /// Whether `other` shows the same scene, optical depths aside (a propagation in progress).
    pub fn same_scene(&self, other: &ImageKey) -> bool {
        self.params == other.params
            && self.grid == other.grid
            && self.lights == other.lights
            && self.surfaces == other.surfaces
            && self.ev_generation == other.ev_generation
    }
}

/// Which of the two image targets holds an image.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Level {
    Quick,
    Full,
}

/// Injections remembered for partial re-propagation.
const EV_HISTORY: usize = 64;

/// What the extinction volume holds (or is being injected with): its key and particles, and
/// on the host path their counts, all brought up to date by each edit's span.
pub(super) struct BakedEv {
    pub key: EvKey,
    pub particles: Vec<Particle>,
    pub host: Option<super::inject_options::HostCounts>,
}

/// What the GPU holds, to decide what a new project state invalidates.
#[derive(Default)]
pub(super) struct Baked {
    pub ev: Option<BakedEv>,
    pub ev_generation: u64,
    /// Per light: the inputs of the OPV on the GPU (None: never propagated).
    pub opvs: Vec<Option<OpvKey>>,
    /// The image on show.
    pub shown: Option<(ImageKey, Level)>,
    /// The multiple-scattering solve on the GPU and its generation (counting from 1).
    pub scatter: Option<(ScatterKey, u64)>,
    pub scatter_generation: u64,
    /// The cells each recent injection changed, by the EV generation it produced.
    ev_changes: Vec<(u64, Region)>,
}

impl Baked {
    /// A finished injection that changed `region`: a new EV generation.
    pub fn record_injection(&mut self, region: Region) {
        self.ev_generation += 1;
        self.ev_changes.push((self.ev_generation, region));
        if self.ev_changes.len() > EV_HISTORY {
            self.ev_changes.remove(0);
        }
    }

    /// The cells whose extinction changed since light `i`'s OPV was propagated, when only the
    /// extinction changed (same position, scheme and stride) and the history covers it; None
    /// when the whole OPV must be recomputed.
    pub fn changed_since(&self, i: usize, target: OpvKey) -> Option<(glam::UVec3, glam::UVec3)> {
        let baked = self.opvs.get(i).copied().flatten()?;
        if (OpvKey { ev_generation: target.ev_generation, ..baked }) != target {
            return None;
        }
        let first = self.ev_changes.first()?.0;
        if baked.ev_generation + 1 < first {
            return None;
        }
        let mut region: Option<Region> = None;
        for &(generation, r) in &self.ev_changes {
            if generation > baked.ev_generation && generation <= target.ev_generation {
                region = Some(region.map_or(r, |u| u.union(r)));
            }
        }
        match region? {
            Region::Cells(lo, hi) => Some((lo, hi)),
            Region::All => None,
        }
    }
}

/// Cells an injection changed: a box (inclusive cell bounds) or the whole grid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub(super) enum Region {
    Cells(glam::UVec3, glam::UVec3),
    All,
}

impl Region {
    pub fn union(self, other: Region) -> Region {
        match (self, other) {
            (Region::Cells(a0, a1), Region::Cells(b0, b1)) => Region::Cells(a0.min(b0), a1.max(b1)),
            _ => Region::All,
        }
    }

    /// The cells of `bricks`, or All when they are every brick.
    pub fn of_bricks(grid: &GridSpec, bricks: &[u32]) -> Region {
        let dims = binning::brick_dims(grid);
        if bricks.len() as u32 >= dims.x * dims.y * dims.z {
            return Region::All;
        }
        let mut region: Option<Region> = None;
        for &b in bricks {
            let at = glam::UVec3::new(b % dims.x, (b / dims.x) % dims.y, b / (dims.x * dims.y)) * binning::BRICK;
            let cells = Region::Cells(at, (at + binning::BRICK - 1).min(grid.resolution - 1));
            region = Some(region.map_or(cells, |r| r.union(cells)));
        }
        region.unwrap_or(Region::All)
    }
}

//! Particle bins for picking and box selection in large scenes: clicks and boxes test the
//! bins first, each against a cone or wedge from the camera widened to hold every particle
//! the full scan could accept, and run the scan's own test only on the particles of the bins
//! that pass. The bins depend on the particles alone, so one build serves every view until
//! the particles change (the editor keys it by the content generation). The injection's
//! bricks hold cut-off spheres on the GPU grid, not centres, and only for particles inside
//! it, so picking bins on its own. The bins know particles, not views: the queries through
//! a view are `view`'s.

use crate::scene::Particle;
use glam::Vec3;

/// Scenes with fewer particles are scanned: binning them would cost more than it saves.
pub const INDEX_FROM: usize = 4096;

/// Particles per bin on average: fewer bins cost less per query, fuller bins more per hit.
const PER_BIN: usize = 32;

/// Relative slack on the bin tests, far above f32's rounding in the projection, so that a
/// particle the scan accepts is never in a bin that is skipped.
pub(super) const SLACK: f32 = 1e-3;

pub(super) struct Bin {
    /// Bounding sphere of the centres in the bin.
    pub center: Vec3,
    pub radius: f32,
    /// The largest particle radius in the bin.
    pub max_particle: f32,
    /// Range of `order`.
    start: u32,
    end: u32,
}

/// Particles binned by centre, each class of radii (powers of two) apart, so that a few large
/// particles do not widen every bin's test.
pub struct ParticleIndex {
    bins: Vec<Bin>,
    /// Particle indices grouped by bin.
    order: Vec<u32>,
    /// Particles with a centre or radius that is not finite: always tested.
    loose: Vec<u32>,
    count: usize,
}

/// Spreads the low 21 bits of `v` to every third bit.
fn morton(v: u32) -> u64 {
    let mut x = v as u64 & 0x1f_ffff;
    x = (x | x << 32) & 0x1f_0000_0000_ffff;
    x = (x | x << 16) & 0x1f_0000_ff00_00ff;
    x = (x | x << 8) & 0x100f_00f0_0f00_f00f;
    x = (x | x << 4) & 0x10c3_0c30_c30c_30c3;
    x = (x | x << 2) & 0x1249_2492_4924_9249;
    x
}

/// The radius class of a finite particle.
fn class(radius: f32) -> i32 {
    if radius > 0.0 {
        radius.log2().ceil().clamp(-40.0, 40.0) as i32
    } else {
        -41
    }
}

impl ParticleIndex {
    pub fn build(particles: &[Particle]) -> Self {
        let finite = |p: &Particle| p.center.is_finite() && p.radius.is_finite();
        let loose: Vec<u32> = particles.iter().enumerate().filter(|(_, p)| !finite(p)).map(|(i, _)| i as u32).collect();
        let mut classes: std::collections::BTreeMap<i32, Vec<u32>> = Default::default();
        for (i, p) in particles.iter().enumerate().filter(|(_, p)| finite(p)) {
            classes.entry(class(p.radius)).or_default().push(i as u32);
        }
        let mut index = Self { bins: Vec::new(), order: Vec::new(), loose, count: particles.len() };
        for members in classes.values() {
            index.add_bins(particles, members);
        }
        index
    }

    /// Bins `members` (finite particles): runs of [`PER_BIN`] along the Z-order curve over
    /// their bounding box, which keeps bins small wherever the particles are (a grid over the
    /// box would put a dense cluster into one bin when a few particles lie far out).
    fn add_bins(&mut self, particles: &[Particle], members: &[u32]) {
        let (mut lo, mut hi) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY));
        for &i in members {
            lo = lo.min(particles[i as usize].center);
            hi = hi.max(particles[i as usize].center);
        }
        let scale = Vec3::splat(((1u32 << 21) - 1) as f32) / (hi - lo).max(Vec3::splat(1e-30));
        let mut keyed: Vec<(u64, u32)> = members
            .iter()
            .map(|&i| {
                let q = ((particles[i as usize].center - lo) * scale).as_uvec3().min(glam::UVec3::splat((1 << 21) - 1));
                (morton(q.x) | morton(q.y) << 1 | morton(q.z) << 2, i)
            })
            .collect();
        keyed.sort_unstable();
        let base = self.order.len() as u32;
        for (k, chunk) in keyed.chunks(PER_BIN).enumerate() {
            let (mut a, mut b, mut max_particle) = (Vec3::splat(f32::INFINITY), Vec3::splat(f32::NEG_INFINITY), 0.0f32);
            for &(_, i) in chunk {
                let p = &particles[i as usize];
                a = a.min(p.center);
                b = b.max(p.center);
                max_particle = max_particle.max(p.radius);
            }
            let center = (a + b) * 0.5;
            let radius = chunk.iter().map(|&(_, i)| particles[i as usize].center.distance(center)).fold(0.0, f32::max);
            let start = base + (k * PER_BIN) as u32;
            self.bins.push(Bin { center, radius, max_particle, start, end: start + chunk.len() as u32 });
        }
        self.order.extend(keyed.iter().map(|&(_, i)| i));
    }

    /// Whether the index was built for this many particles (a cheap guard against misuse).
    pub fn fits(&self, particles: &[Particle]) -> bool {
        self.count == particles.len()
    }

    /// The particles of every bin `keep` accepts, then the loose ones, in no particular order.
    pub(super) fn candidates(&self, mut keep: impl FnMut(&Bin) -> bool) -> impl Iterator<Item = usize> + '_ {
        let ranges: Vec<(u32, u32)> = self.bins.iter().filter(|b| keep(b)).map(|b| (b.start, b.end)).collect();
        ranges
            .into_iter()
            .flat_map(|(s, e)| self.order[s as usize..e as usize].iter())
            .chain(self.loose.iter())
            .map(|&i| i as usize)
    }
}

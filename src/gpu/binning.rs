//! CPU binning of particles into cubic bins of cells for injection.
//!
//! A particle is listed in every bin its cut-off sphere (physics.md §2) overlaps, so the
//! injection shader evaluates only particle–cell pairs that can contribute: cost grows with
//! overlaps, not particles × cells. The bin edge (2, 4 or 8 cells) is chosen per scene to
//! minimise the evaluations Σ overlaps × bin volume: small bins for many small particles,
//! large ones for few big ones. The lists are a CSR pair (offsets, items). Work is still
//! dispatched, and edits tracked, in 8³ bricks.

use crate::scene::{GridSpec, Particle};
use glam::{UVec3, Vec3};

pub const BRICK: u32 = 8;

/// Cut-off threshold ε (1/m): a particle is dropped where c·exp(−d²/r²) < ε, with
/// ε = min(1e-6, 1e-4·c) so every particle keeps at least ~3 radii of support.
pub fn cutoff_epsilon(density: f32) -> f32 {
    (1e-4 * density).min(1e-6)
}

/// Cut-off radius of a particle in metres under [`cutoff_epsilon`].
pub fn cutoff_radius(p: &Particle) -> f32 {
    p.cutoff_radius(cutoff_epsilon(p.density))
}

/// Indices of the 8³ bricks a particle's cut-off sphere overlaps, or None if it misses the grid.
pub fn brick_range(grid: &GridSpec, p: &Particle) -> Option<(UVec3, UVec3)> {
    bin_range(grid, p, BRICK)
}

/// Indices of the bins of `bin` cells a particle's cut-off sphere overlaps.
fn bin_range(grid: &GridSpec, p: &Particle, bin: u32) -> Option<(UVec3, UVec3)> {
    if p.hidden || p.density <= 0.0 {
        return None;
    }
    let brick_dims = bin_dims(grid, bin);
    let brick_size = grid.cell_size() * bin as f32;
    let r = cutoff_radius(p);
    let lo = ((p.center - r - grid.min) / brick_size).floor();
    let hi = ((p.center + r - grid.min) / brick_size).floor();
    let max = (brick_dims - 1).as_vec3();
    if hi.cmplt(Vec3::ZERO).any() || lo.cmpgt(max).any() {
        return None;
    }
    Some((lo.clamp(Vec3::ZERO, max).as_uvec3(), hi.clamp(Vec3::ZERO, max).as_uvec3()))
}

pub fn brick_dims(grid: &GridSpec) -> UVec3 {
    bin_dims(grid, BRICK)
}

fn bin_dims(grid: &GridSpec, bin: u32) -> UVec3 {
    (grid.resolution + UVec3::splat(bin - 1)) / bin
}

/// Calls `f` with the linear index of every brick in the inclusive range.
pub fn for_each_brick(dims: UVec3, (lo, hi): (UVec3, UVec3), mut f: impl FnMut(usize)) {
    for z in lo.z..=hi.z {
        for y in lo.y..=hi.y {
            for x in lo.x..=hi.x {
                f((x + dims.x * (y + dims.y * z)) as usize);
            }
        }
    }
}

/// Particle–bin overlaps [`bin_particles`] would list, counted without allocating.
pub fn overlap_count(grid: &GridSpec, particles: &[Particle]) -> u64 {
    let bin = chosen_bin(grid, particles);
    particles
        .iter()
        .filter_map(|p| bin_range(grid, p, bin))
        .map(|(lo, hi)| (hi - lo + UVec3::ONE).as_u64vec3().element_product())
        .sum()
}

/// An upper bound on [`overlap_count`] and on [`bin_all`]'s list: every particle in every
/// bin of the smallest size.
pub fn overlap_bound(grid: &GridSpec, particles: usize) -> u64 {
    particles as u64 * bin_dims(grid, 2).as_u64vec3().element_product()
}

pub struct Bins {
    /// Edge of a bin in cells.
    pub bin_size: u32,
    pub offsets: Vec<u32>,
    pub items: Vec<u32>,
}

impl Bins {
    /// Particle–cell evaluations injection performs in the given 8³ bricks: each cell reads
    /// the whole list of its bin.
    pub fn evaluations(&self, grid: &GridSpec, bricks: &[u32]) -> u64 {
        let bdims = brick_dims(grid);
        let ndims = bin_dims(grid, self.bin_size);
        let per_brick = BRICK / self.bin_size;
        let mut total = 0u64;
        for &b in bricks {
            let b = UVec3::new(b % bdims.x, (b / bdims.x) % bdims.y, b / (bdims.x * bdims.y));
            let lo = b * per_brick;
            let hi = (lo + per_brick).min(ndims) - 1;
            for_each_brick(ndims, (lo, hi), |n| {
                let cells = {
                    let c = UVec3::new(n as u32 % ndims.x, (n as u32 / ndims.x) % ndims.y, n as u32 / (ndims.x * ndims.y));
                    let start = c * self.bin_size;
                    ((start + self.bin_size).min(grid.resolution) - start).as_u64vec3().element_product()
                };
                total += (self.offsets[n + 1] - self.offsets[n]) as u64 * cells;
            });
        }
        total
    }
}

/// Bins visible particles (indices into `particles`), with the bin edge that minimises the
/// particle–cell evaluations.
pub fn bin_particles(grid: &GridSpec, particles: &[Particle]) -> Bins {
    bin_with(grid, particles, chosen_bin(grid, particles))
}

/// The bin edge [`bin_particles`] uses: the one of 2, 4, 8 cells with the fewest evaluations.
pub fn chosen_bin(grid: &GridSpec, particles: &[Particle]) -> u32 {
    let cost = |bin: u32| -> u64 {
        particles
            .iter()
            .filter_map(|p| bin_range(grid, p, bin))
            .map(|(lo, hi)| ((hi - lo + 1).as_u64vec3().element_product()) * (bin as u64).pow(3))
            .sum()
    };
    [2, 4, 8].into_iter().min_by_key(|&b| cost(b)).unwrap_or(BRICK)
}

fn bin_with(grid: &GridSpec, particles: &[Particle], bin: u32) -> Bins {
    let dims = bin_dims(grid, bin);
    let count = (dims.x * dims.y * dims.z) as usize;
    let ranges: Vec<Option<(UVec3, UVec3)>> = particles.iter().map(|p| bin_range(grid, p, bin)).collect();
    let mut offsets = vec![0u32; count + 1];
    for range in ranges.iter().flatten() {
        for_each_brick(dims, *range, |b| offsets[b + 1] += 1);
    }
    for i in 1..offsets.len() {
        offsets[i] += offsets[i - 1];
    }
    let mut cursor = offsets.clone();
    let mut items = vec![0u32; offsets[count] as usize];
    for (pi, range) in ranges.iter().enumerate() {
        if let Some(range) = range {
            for_each_brick(dims, *range, |b| {
                items[cursor[b] as usize] = pi as u32;
                cursor[b] += 1;
            });
        }
    }
    Bins { bin_size: bin, offsets, items }
}

/// Bricks whose EV changes when the particle list goes from `old` to `new`: those overlapped
/// by particles in one list and not the other, counted with multiplicity and compared by
/// value, so reordering or renaming costs nothing.
pub fn dirty_bricks(grid: &GridSpec, old: &[Particle], new: &[Particle]) -> Vec<u32> {
    type Key = ([u32; 3], u32, u32, bool);
    let key = |p: &Particle| -> Key {
        (p.center.to_array().map(f32::to_bits), p.radius.to_bits(), p.density.to_bits(), p.hidden)
    };
    let sorted = |list: &[Particle]| {
        let mut v: Vec<(Key, usize)> = list.iter().enumerate().map(|(i, p)| (key(p), i)).collect();
        v.sort_unstable();
        v
    };
    let (a, b) = (sorted(old), sorted(new));
    let dims = brick_dims(grid);
    let mut dirty = vec![false; (dims.x * dims.y * dims.z) as usize];
    let mut mark = |p: &Particle| {
        if let Some(range) = brick_range(grid, p) {
            for_each_brick(dims, range, |i| dirty[i] = true);
        }
    };
    let (mut i, mut j) = (0, 0);
    while i < a.len() || j < b.len() {
        match (a.get(i), b.get(j)) {
            (Some(x), Some(y)) if x.0 == y.0 => {
                i += 1;
                j += 1;
            }
            (Some(x), Some(y)) if x.0 < y.0 => {
                mark(&old[x.1]);
                i += 1;
            }
            (Some(x), None) => {
                mark(&old[x.1]);
                i += 1;
            }
            (_, Some(y)) => {
                mark(&new[y.1]);
                j += 1;
            }
            (None, None) => break,
        }
    }
    dirty.iter().enumerate().filter(|(_, d)| **d).map(|(i, _)| i as u32).collect()
}

/// Every brick lists every visible particle: the brute-force injection the binning replaces,
/// kept to measure what binning saves.
pub fn bin_all(grid: &GridSpec, particles: &[Particle]) -> Bins {
    let dims = brick_dims(grid);
    let bricks = (dims.x * dims.y * dims.z) as usize;
    let visible: Vec<u32> =
        particles.iter().enumerate().filter(|(_, p)| !p.hidden && p.density > 0.0).map(|(i, _)| i as u32).collect();
    let offsets = (0..=bricks).map(|b| (b * visible.len()) as u32).collect();
    let items = (0..bricks).flat_map(|_| visible.iter().copied()).collect();
    Bins { bin_size: BRICK, offsets, items }
}

//! CPU binning of particles into 8³-cell bricks for injection.
//!
//! A particle is listed in every brick its cut-off sphere (physics.md §2) overlaps, so the
//! injection shader evaluates only particle–cell pairs that can contribute: cost grows with
//! overlaps, not particles × cells. The lists are a CSR pair (offsets, items).

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

/// Indices of the bricks a particle's cut-off sphere overlaps, or None if it misses the grid.
pub fn brick_range(grid: &GridSpec, p: &Particle) -> Option<(UVec3, UVec3)> {
    if p.hidden || p.density <= 0.0 {
        return None;
    }
    let brick_dims = (grid.resolution + UVec3::splat(BRICK - 1)) / BRICK;
    let brick_size = grid.cell_size() * BRICK as f32;
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
    (grid.resolution + UVec3::splat(BRICK - 1)) / BRICK
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

/// Particle–brick overlaps [`bin_particles`] would list, counted without allocating.
pub fn overlap_count(grid: &GridSpec, particles: &[Particle]) -> u64 {
    particles
        .iter()
        .filter_map(|p| brick_range(grid, p))
        .map(|(lo, hi)| (hi - lo + UVec3::ONE).as_u64vec3().element_product())
        .sum()
}

pub struct Bins {
    pub offsets: Vec<u32>,
    pub items: Vec<u32>,
}

/// Bins visible particles (indices into `particles`) into the bricks of `grid`.
pub fn bin_particles(grid: &GridSpec, particles: &[Particle]) -> Bins {
    let dims = brick_dims(grid);
    let brick_count = (dims.x * dims.y * dims.z) as usize;
    let ranges: Vec<Option<(UVec3, UVec3)>> = particles.iter().map(|p| brick_range(grid, p)).collect();
    let mut offsets = vec![0u32; brick_count + 1];
    for range in ranges.iter().flatten() {
        for_each_brick(dims, *range, |b| offsets[b + 1] += 1);
    }
    for i in 1..offsets.len() {
        offsets[i] += offsets[i - 1];
    }
    let mut cursor = offsets.clone();
    let mut items = vec![0u32; offsets[brick_count] as usize];
    for (pi, range) in ranges.iter().enumerate() {
        if let Some(range) = range {
            for_each_brick(dims, *range, |b| {
                items[cursor[b] as usize] = pi as u32;
                cursor[b] += 1;
            });
        }
    }
    Bins { offsets, items }
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

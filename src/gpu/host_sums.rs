//! Particle sums computed on the host, for adapters that are themselves the CPU.
//!
//! On a software adapter (llvmpipe) every loop iteration of a shader invocation costs tens of
//! cycles whatever it does, so the binned gather of `shaders/inject.wgsl` spends its time
//! walking lists, not evaluating gaussians. The same cores running native loops scatter each
//! particle over just the cells inside its cut-off sphere, with the gaussian split into its
//! three axis factors (three short tables of `exp` per particle and brick, one multiply per
//! cell).
//! `shaders/inject_sums.wgsl` then adds the base fog, the layer and the noise on the adapter,
//! exactly as the gather path does.
//!
//! Each cell sums its particles in scene order, and each cell belongs to one thread, so the
//! sums are the same bit for bit however the bricks are split into calls or threads. They
//! differ from the gather path's by rounding only (a product of three exps against one exp
//! per cell): about 1e-6 relative.

use super::binning::{brick_dims, ChunkBins, BRICK};
#[allow(unused_imports)]
use super::binning::BinCounts;
use super::gpu_types::ParticleGpu;
use crate::scene::GridSpec;
use glam::{UVec3, Vec3};

/// Cells of a brick.
pub const CELLS: usize = (BRICK * BRICK * BRICK) as usize;

/// Words of one brick's sums: its plain sums, then its noisy ones (x fastest).
pub const WORDS: usize = 2 * CELLS;

/// The particle sums of `bricks` (linear brick indices, ascending), [`WORDS`] per brick in the
/// order given, from `lists`: the bricks' particle lists ([`BinCounts::fill`] with bins of a
/// brick). Returns the sums and the particle–cell pairs evaluated.
///
/// Work goes brick by brick, so each brick's sums stay in cache while its particles are added
/// (particles in scene order are scattered through space; scattering each over the whole
/// grid was four times slower, in cache misses).
pub fn particle_sums(grid: &GridSpec, particles: &[ParticleGpu], bricks: &[u32], lists: &ChunkBins) -> (Vec<f32>, u64) {
    let mut sums = vec![0.0f32; bricks.len() * WORDS];
    if bricks.is_empty() {
        return (sums, 0);
    }
    let entries = |b: u32| (lists.offsets[b as usize + 1] - lists.offsets[b as usize]) as u64;
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).clamp(1, 16).min(bricks.len());
    // Contiguous runs of bricks with about equal list entries (plus a brick's fixed cost).
    let total: u64 = bricks.iter().map(|&b| entries(b) + 8).sum();
    let mut cuts = vec![0usize];
    let mut acc = 0u64;
    for (i, &b) in bricks.iter().enumerate() {
        acc += entries(b) + 8;
        if cuts.len() < threads && acc * threads as u64 >= total * cuts.len() as u64 && i + 1 < bricks.len() {
            cuts.push(i + 1);
        }
    }
    cuts.push(bricks.len());
    let setup = Setup { dims: brick_dims(grid), res: grid.resolution, min: grid.min, cell: grid.cell_size() };
    let mut pairs = 0u64;
    std::thread::scope(|s| {
        let mut rest = &mut sums[..];
        let mut handles = Vec::new();
        for w in cuts.windows(2) {
            let (out, tail) = rest.split_at_mut((w[1] - w[0]) * WORDS);
            rest = tail;
            let own = &bricks[w[0]..w[1]];
            let setup = &setup;
            handles.push(s.spawn(move || setup.run(particles, own, lists, out)));
        }
        for h in handles {
            pairs += h.join().expect("a particle-sum thread panicked");
        }
    });
    (sums, pairs)
}

struct Setup {
    dims: UVec3,
    res: UVec3,
    min: Vec3,
    cell: Vec3,
}

impl Setup {
    /// Adds every listed particle to the bricks `own`, whose sums are `out`.
    fn run(&self, particles: &[ParticleGpu], own: &[u32], lists: &ChunkBins, out: &mut [f32]) -> u64 {
        let mut n = 0;
        for (&b, out) in own.iter().zip(out.chunks_mut(WORDS)) {
            let list = &lists.items[lists.offsets[b as usize] as usize..lists.offsets[b as usize + 1] as usize];
            for &k in list {
                n += self.add(&particles[lists.particles[k as usize] as usize], b, out);
            }
        }
        n
    }

    /// Adds particle `p`'s gaussian to the cells of brick `b` inside its cut-off sphere;
    /// returns the cells evaluated (whole brick rows: eight per row the sphere reaches).
    fn add(&self, p: &ParticleGpu, b: u32, out: &mut [f32]) -> u64 {
        const B: usize = BRICK as usize;
        if p.density == [0.0, 0.0] || p.cutoff2 <= 0.0 {
            return 0;
        }
        let at = UVec3::new(b % self.dims.x, (b / self.dims.x) % self.dims.y, b / (self.dims.x * self.dims.y)) * BRICK;
        let c = Vec3::from_array(p.center);
        // A hair wider than the cut-off, so that rounding never drops a cell the per-cell
        // test keeps.
        let reach = p.cutoff2.sqrt() * (1.0 + 1e-5) + 1e-6 * self.cell.max_element();
        // Per axis, over the brick's cells: squared distance and gaussian factor, infinite
        // and 0 beyond the sphere's reach (so rows are always eight cells wide, in SIMD).
        let mut range = [(0usize, 0usize); 3];
        let mut d2 = [[f32::INFINITY; B]; 3];
        let mut g = [[0.0f32; B]; 3];
        for a in 0..3 {
            let last = (at[a] + BRICK).min(self.res[a]) - 1;
            // The first and last cell centre within reach, clamped to the brick (ceil and
            // floor by truncation: both arguments are clamped non-negative first).
            let from = ((c[a] - reach - self.min[a]) / self.cell[a] - 0.5).max(at[a] as f32);
            let from = from as u32 + (((from as u32) as f32) < from) as u32;
            let to = ((c[a] + reach - self.min[a]) / self.cell[a] - 0.5).min(last as f32);
            if !(to >= from as f32) {
                return 0;
            }
            range[a] = (from as usize - at[a] as usize, to as usize - at[a] as usize);
            for j in range[a].0..=range[a].1 {
                // The cell centre as the shaders compute it.
                let x = self.min[a] + ((at[a] as usize + j) as f32 + 0.5) * self.cell[a];
                let d = x - c[a];
                d2[a][j] = d * d;
                g[a][j] = (-(d * d) * p.inv_r2).exp();
            }
        }
        // Planar sums: a brick's plain sums, then its noisy ones.
        let mut count = 0u64;
        for (plane, &density) in p.density.iter().enumerate() {
            if density == 0.0 {
                continue;
            }
            let out = &mut out[plane * CELLS..][..CELLS];
            for k in range[2].0..=range[2].1 {
                for j in range[1].0..=range[1].1 {
                    let dyz = d2[1][j] + d2[2][k];
                    if dyz >= p.cutoff2 {
                        continue;
                    }
                    let w = density * g[1][j] * g[2][k];
                    let row: &mut [f32; B] = (&mut out[(k * B + j) * B..][..B]).try_into().expect("a brick row");
                    for i in 0..B {
                        // The shader's order: (dx² + dy²) + dz².
                        let inside = d2[0][i] + d2[1][j] + d2[2][k] < p.cutoff2;
                        row[i] += if inside { w * g[0][i] } else { 0.0 };
                    }
                    count += B as u64;
                }
            }
        }
        count
    }
}

//! Particle sums computed on the host, for adapters that are themselves the CPU.
//!
//! On a software adapter (llvmpipe) every loop iteration of a shader invocation costs tens of
//! cycles whatever it does, so the binned gather of `shaders/inject.wgsl` spends its time
//! walking lists, not evaluating gaussians. The same cores running native loops scatter each
//! particle over just the cells inside its cut-off sphere, with the gaussian split into its
//! three axis factors (one short table of `exp` per axis and particle, one multiply per cell,
//! a brick row of eight cells per SIMD loop). `shaders/inject_sums.wgsl` then adds the base
//! fog, the layer and the noise on the adapter, exactly as the gather path does.
//!
//! The particles come ordered by the brick holding their centre (then scene order), so
//! consecutive particles write the same few bricks while they are in cache; in scene order
//! the misses made the sums several times slower. Each cell sums its particles in that
//! order, and each cell belongs to one thread, so the sums are the same bit for bit however
//! the bricks are split into calls or threads. They differ from the gather path's by
//! rounding only (a product of three exps against one exp per cell): about 1e-6 relative.

use super::binning::{brick_dims, BRICK};
use super::gpu_types::ParticleGpu;
use crate::scene::GridSpec;
use glam::{UVec3, Vec3};

/// Cells of a brick.
pub const CELLS: usize = (BRICK * BRICK * BRICK) as usize;

/// Words of one brick's sums: its plain sums, then its noisy ones (x fastest).
pub const WORDS: usize = 2 * CELLS;

const B: usize = BRICK as usize;
const NONE: u32 = u32::MAX;

/// Particles in the host's order, with what finds those near a brick quickly.
pub struct Ordered {
    pub particles: Vec<ParticleGpu>,
    /// Linear index of the brick holding each particle's centre (clamped to the grid),
    /// ascending.
    pub keys: Vec<u32>,
    /// No particle's sphere reaches further than this many bricks from its key's brick.
    pub margin: u32,
}

/// The particle sums of `bricks` (linear brick indices, ascending), [`WORDS`] per brick in the
/// order given; `weights` (one per brick) balance the threads. Returns the sums and the cells
/// evaluated (whole brick rows: eight per row a sphere reaches).
pub fn particle_sums(grid: &GridSpec, ordered: &Ordered, bricks: &[u32], weights: &[u64]) -> (Vec<f32>, u64) {
    let mut sums = vec![0.0f32; bricks.len() * WORDS];
    if bricks.is_empty() {
        return (sums, 0);
    }
    let dims = brick_dims(grid);
    let mut slot = vec![NONE; dims.as_u64vec3().element_product() as usize];
    for (i, &b) in bricks.iter().enumerate() {
        slot[b as usize] = i as u32;
    }
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get()).clamp(1, 16).min(bricks.len());
    // Contiguous runs of bricks of about equal weight (plus a brick's fixed cost).
    let weight = |i: usize| weights.get(i).copied().unwrap_or(0) + 512;
    let total: u64 = (0..bricks.len()).map(weight).sum();
    let mut cuts = vec![0usize];
    let mut acc = 0u64;
    for i in 0..bricks.len() {
        acc += weight(i);
        if cuts.len() < threads && acc * threads as u64 >= total * cuts.len() as u64 && i + 1 < bricks.len() {
            cuts.push(i + 1);
        }
    }
    cuts.push(bricks.len());
    let setup = Setup { dims, res: grid.resolution, min: grid.min, cell: grid.cell_size(), slot: &slot };
    let mut evaluated = 0u64;
    std::thread::scope(|s| {
        let mut rest = &mut sums[..];
        let mut handles = Vec::new();
        for w in cuts.windows(2) {
            let (out, tail) = rest.split_at_mut((w[1] - w[0]) * WORDS);
            rest = tail;
            let (own, first) = (&bricks[w[0]..w[1]], w[0] as u32);
            let setup = &setup;
            handles.push(s.spawn(move || setup.run(ordered, own, first, out)));
        }
        for h in handles {
            evaluated += h.join().expect("a particle-sum thread panicked");
        }
    });
    (sums, evaluated)
}

struct Setup<'a> {
    dims: UVec3,
    res: UVec3,
    min: Vec3,
    cell: Vec3,
    /// Slot (index into the call's bricks) of every brick of the grid, NONE if not in it.
    slot: &'a [u32],
}

/// Per-thread tables over one particle's cells along each axis: squared distance and
/// gaussian factor. Along x they cover whole brick rows, infinite and 0 outside the sphere's
/// reach, so that every brick row is eight lanes.
#[derive(Default)]
struct Tables {
    d2: [Vec<f32>; 3],
    g: [Vec<f32>; 3],
}

impl Setup<'_> {
    fn brick(&self, b: u32) -> UVec3 {
        UVec3::new(b % self.dims.x, (b / self.dims.x) % self.dims.y, b / (self.dims.x * self.dims.y))
    }

    /// Adds every particle that can reach the bricks `own` (slots from `first`) to them.
    fn run(&self, ordered: &Ordered, own: &[u32], first: u32, out: &mut [f32]) -> u64 {
        let (mut lo, mut hi) = (UVec3::MAX, UVec3::ZERO);
        for &b in own {
            lo = lo.min(self.brick(b));
            hi = hi.max(self.brick(b));
        }
        // Keys are x + y·dx + z·dx·dy: the particles within `margin` bricks of these bricks
        // on every axis are, row by row, runs of consecutive keys, visited in key order.
        let m = ordered.margin;
        let near_lo = lo.saturating_sub(UVec3::splat(m));
        let near_hi = (hi + m).min(self.dims - 1);
        let cells_lo = lo * BRICK;
        let cells_hi = ((hi + 1) * BRICK).min(self.res) - 1;
        let mut tables = Tables::default();
        let mut evaluated = 0;
        let mut at = 0;
        for z in near_lo.z..=near_hi.z {
            for y in near_lo.y..=near_hi.y {
                let row = self.dims.x * (y + self.dims.y * z);
                at += ordered.keys[at..].partition_point(|&k| k < row + near_lo.x);
                let end = at + ordered.keys[at..].partition_point(|&k| k <= row + near_hi.x);
                for p in &ordered.particles[at..end] {
                    evaluated += self.add(p, cells_lo, cells_hi, first, own.len() as u32, &mut tables, out);
                }
                at = end;
            }
        }
        evaluated
    }

    /// Adds particle `p` to the cells within [lo, hi] of the bricks with slots in
    /// [first, first + count); returns the cells evaluated.
    #[allow(clippy::too_many_arguments)] // the innermost loop: bounds, slots and tables as plain values, no struct per particle
    fn add(
        &self,
        p: &ParticleGpu,
        lo: UVec3,
        hi: UVec3,
        first: u32,
        count: u32,
        t: &mut Tables,
        out: &mut [f32],
    ) -> u64 {
        if p.density == [0.0, 0.0] || p.cutoff2 <= 0.0 {
            return 0;
        }
        let c = Vec3::from_array(p.center);
        // A hair wider than the cut-off, so that rounding never drops a cell the per-cell
        // test keeps.
        let reach = p.cutoff2.sqrt() * (1.0 + 1e-5) + 1e-6 * self.cell.max_element();
        let mut range = [(0u32, 0u32); 3];
        for a in 0..3 {
            // The first and last cell centre within reach, clamped to [lo, hi] (ceil and
            // floor by truncation: both arguments are clamped non-negative first).
            let from = ((c[a] - reach - self.min[a]) / self.cell[a] - 0.5).max(lo[a] as f32);
            let from = from as u32 + (((from as u32) as f32) < from) as u32;
            let to = ((c[a] + reach - self.min[a]) / self.cell[a] - 0.5).min(hi[a] as f32);
            if to.partial_cmp(&(from as f32)).is_none_or(|o| o == std::cmp::Ordering::Less) {
                return 0;
            }
            range[a] = (from, to as u32);
        }
        // Along x the tables start at the first cell's brick row.
        let x_base = range[0].0 / BRICK * BRICK;
        for a in 0..3 {
            let (start, end) =
                if a == 0 { (x_base, (range[0].1 / BRICK + 1) * BRICK) } else { (range[a].0, range[a].1 + 1) };
            t.d2[a].clear();
            t.g[a].clear();
            for i in start..end {
                if i < range[a].0 || i > range[a].1 {
                    t.d2[a].push(f32::INFINITY);
                    t.g[a].push(0.0);
                    continue;
                }
                // The cell centre as the shaders compute it.
                let d = self.min[a] + (i as f32 + 0.5) * self.cell[a] - c[a];
                t.d2[a].push(d * d);
                t.g[a].push((-(d * d) * p.inv_r2).exp());
            }
        }
        let mut evaluated = 0u64;
        let last = first + count;
        for (plane, &density) in p.density.iter().enumerate() {
            if density == 0.0 {
                continue;
            }
            for z in range[2].0..=range[2].1 {
                let k = (z - range[2].0) as usize;
                let (dz2, gz) = (t.d2[2][k], t.g[2][k]);
                for y in range[1].0..=range[1].1 {
                    let j = (y - range[1].0) as usize;
                    let dy2 = t.d2[1][j];
                    if dy2 + dz2 >= p.cutoff2 {
                        continue;
                    }
                    let w = density * t.g[1][j] * gz;
                    let within = plane * CELLS + ((z % BRICK) as usize * B + (y % BRICK) as usize) * B;
                    let row_bricks = self.dims.x * (y / BRICK + self.dims.y * (z / BRICK));
                    for bx in range[0].0 / BRICK..=range[0].1 / BRICK {
                        let s = self.slot[(bx + row_bricks) as usize];
                        if s == NONE || s < first || s >= last {
                            continue;
                        }
                        let at = (bx * BRICK - x_base) as usize;
                        // Copies of the row's lanes, so that the loop is one vector.
                        let d2x: [f32; B] = t.d2[0][at..at + B].try_into().expect("a brick row");
                        let gx: [f32; B] = t.g[0][at..at + B].try_into().expect("a brick row");
                        let mut add = [0.0f32; B];
                        for i in 0..B {
                            // The shader's order: (dx² + dy²) + dz².
                            let inside = d2x[i] + dy2 + dz2 < p.cutoff2;
                            add[i] = if inside { w * gx[i] } else { 0.0 };
                        }
                        let row: &mut [f32; B] =
                            (&mut out[(s - first) as usize * WORDS + within..][..B]).try_into().expect("a brick row");
                        for i in 0..B {
                            row[i] += add[i];
                        }
                        evaluated += B as u64;
                    }
                }
            }
        }
        evaluated
    }
}

/// The host's order for `particles` (already in the injection's layout), given each one's
/// cut-off reach in metres: by the brick holding the centre, then scene order.
pub fn order(grid: &GridSpec, particles: Vec<ParticleGpu>, reach: impl Fn(&ParticleGpu) -> f32) -> Ordered {
    let dims = brick_dims(grid);
    let brick_size = grid.cell_size() * BRICK as f32;
    let mut keyed: Vec<u64> = particles
        .iter()
        .enumerate()
        .map(|(i, p)| {
            let c = ((Vec3::from_array(p.center) - grid.min) / brick_size)
                .floor()
                .clamp(Vec3::ZERO, (dims - 1).as_vec3())
                .as_uvec3();
            ((c.x + dims.x * (c.y + dims.y * c.z)) as u64) << 32 | i as u64
        })
        .collect();
    keyed.sort_unstable();
    let margin = particles.iter().map(&reach).fold(0.0f32, f32::max) / brick_size.min_element();
    let margin = if margin.is_finite() { margin.ceil() as u32 + 1 } else { dims.max_element() };
    Ordered {
        particles: keyed.iter().map(|&k| particles[k as u32 as usize]).collect(),
        keys: keyed.iter().map(|&k| (k >> 32) as u32).collect(),
        margin,
    }
}

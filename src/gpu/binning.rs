//! CPU binning of particles into columns of cells for injection.
//!
//! A particle is listed in every bin its cut-off sphere (physics.md §2) overlaps, so the
//! injection shader evaluates only particle–cell pairs that can contribute: cost grows with
//! overlaps, not particles × cells. A bin is b × b cells across and a brick's 8 cells along z:
//! the shader gives each thread one such column of a brick, so one load of a particle serves
//! eight cells (on software adapters the loads, not the gaussians, are most of the cost). The
//! edge b (1, 2, 4 or 8 cells) is chosen per scene to minimise the evaluations Σ overlaps ×
//! bin volume: small bins for many small particles, large ones for few big ones, and no
//! smaller than memory allows. The lists are a CSR pair
//! (offsets, items) built for one chunk of 8³ bricks at a time, so a chunk's lists fit a
//! storage binding whatever the scene. Work is dispatched, and edits tracked, in bricks.

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
    bin_range(grid, p, UVec3::splat(BRICK))
}

/// The bin edges across that the injection can use.
pub const BIN_EDGES: [u32; 4] = [1, 2, 4, 8];

/// Cells of a bin of edge `b` across: b × b × [`BRICK`].
pub fn bin_edge(b: u32) -> UVec3 {
    UVec3::new(b, b, BRICK)
}

/// Indices of the bins of `edge` cells a particle's cut-off sphere overlaps.
fn bin_range(grid: &GridSpec, p: &Particle, edge: UVec3) -> Option<(UVec3, UVec3)> {
    if p.hidden || p.density <= 0.0 {
        return None;
    }
    let brick_dims = bin_dims(grid, edge);
    let brick_size = grid.cell_size() * edge.as_vec3();
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
    bin_dims(grid, UVec3::splat(BRICK))
}

fn bin_dims(grid: &GridSpec, edge: UVec3) -> UVec3 {
    (grid.resolution + edge - 1) / edge
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

/// Particle counts per bin for one bin edge: the histogram the injection cuts its chunks
/// from. The lists themselves are built one chunk of bricks at a time ([`BinCounts::fill`]),
/// so memory is bounded by the chunk, not by the scene.
pub struct BinCounts {
    /// Edge of a bin across (x and y) in cells; along z a bin spans a brick.
    pub bin_size: u32,
    dims: UVec3,
    counts: Vec<u32>,
    /// Every visible particle in every bin (the brute-force injection).
    brute_force: bool,
}

/// One chunk's lists, a CSR pair over all bins of the grid (bins outside the chunk are
/// empty). `items` index `particles`, the chunk's particles by ascending scene index, so each
/// cell sums its particles in scene order whatever the chunking.
pub struct ChunkBins {
    pub offsets: Vec<u32>,
    pub items: Vec<u32>,
    pub particles: Vec<u32>,
}

fn visible(p: &Particle) -> bool {
    !p.hidden && p.density > 0.0
}

impl BinCounts {
    /// Counts the bins of edge `bin`; with `brute_force` every visible particle is listed in
    /// every bin (of edge [`BRICK`]).
    pub fn new(grid: &GridSpec, particles: &[Particle], bin: u32, brute_force: bool) -> Self {
        let bin = if brute_force { BRICK } else { bin };
        let dims = bin_dims(grid, bin_edge(bin));
        let n = dims.as_u64vec3().element_product() as usize;
        let mut counts = vec![0u32; n];
        if brute_force {
            let v = particles.iter().filter(|p| visible(p)).count() as u32;
            counts.iter_mut().for_each(|c| *c = v);
        } else {
            for range in particles.iter().filter_map(|p| bin_range(grid, p, bin_edge(bin))) {
                for_each_brick(dims, range, |b| counts[b] += 1);
            }
        }
        Self { bin_size: bin, dims, counts, brute_force }
    }

    fn range(&self, grid: &GridSpec, p: &Particle) -> Option<(UVec3, UVec3)> {
        if self.brute_force {
            visible(p).then_some((UVec3::ZERO, self.dims - 1))
        } else {
            bin_range(grid, p, bin_edge(self.bin_size))
        }
    }

    fn coords(&self, n: usize) -> UVec3 {
        let n = n as u32;
        UVec3::new(n % self.dims.x, (n / self.dims.x) % self.dims.y, n / (self.dims.x * self.dims.y))
    }

    /// The 8³ brick holding bin `n`.
    fn brick_of(&self, grid: &GridSpec, n: usize) -> usize {
        let b = self.coords(n) * bin_edge(self.bin_size) / BRICK;
        let bd = brick_dims(grid);
        (b.x + bd.x * (b.y + bd.y * b.z)) as usize
    }

    /// List entries over all bins: the particle–bin overlaps.
    pub fn entries(&self) -> u64 {
        self.counts.iter().map(|&c| c as u64).sum()
    }

    /// Per 8³ brick: list entries and particle–cell evaluations (each cell reads its bin's
    /// whole list).
    pub fn per_brick(&self, grid: &GridSpec) -> (Vec<u64>, Vec<u64>) {
        let bricks = brick_dims(grid).as_u64vec3().element_product() as usize;
        let (mut items, mut evals) = (vec![0u64; bricks], vec![0u64; bricks]);
        for (n, &count) in self.counts.iter().enumerate() {
            let b = self.brick_of(grid, n);
            let edge = bin_edge(self.bin_size);
            let start = self.coords(n) * edge;
            let cells = ((start + edge).min(grid.resolution) - start).as_u64vec3().element_product();
            items[b] += count as u64;
            evals[b] += count as u64 * cells;
        }
        (items, evals)
    }

    /// The lists of the bins inside `bricks` (linear 8³-brick indices).
    pub fn fill(&self, grid: &GridSpec, particles: &[Particle], bricks: &[u32]) -> ChunkBins {
        let bd = brick_dims(grid);
        let mut in_chunk = vec![false; bd.as_u64vec3().element_product() as usize];
        let (mut lo, mut hi) = (UVec3::MAX, UVec3::ZERO);
        for &b in bricks {
            in_chunk[b as usize] = true;
            let c = UVec3::new(b % bd.x, (b / bd.x) % bd.y, b / (bd.x * bd.y));
            lo = lo.min(c);
            hi = hi.max(c);
        }
        let mut offsets = vec![0u32; self.counts.len() + 1];
        let mut bin_in = vec![false; self.counts.len()];
        for n in 0..self.counts.len() {
            bin_in[n] = in_chunk[self.brick_of(grid, n)];
            offsets[n + 1] = offsets[n] + if bin_in[n] { self.counts[n] } else { 0 };
        }
        let mut items = vec![0u32; *offsets.last().unwrap_or(&0) as usize];
        let mut chunk_particles = Vec::new();
        if bricks.is_empty() {
            return ChunkBins { offsets, items, particles: chunk_particles };
        }
        // The chunk's bounding box in bins.
        let per = UVec3::splat(BRICK) / bin_edge(self.bin_size);
        let (blo, bhi) = (lo * per, ((hi + 1) * per).min(self.dims) - 1);
        let mut cursor = offsets.clone();
        for (pi, p) in particles.iter().enumerate() {
            let Some((plo, phi)) = self.range(grid, p) else { continue };
            let (plo, phi) = (plo.max(blo), phi.min(bhi));
            if plo.cmpgt(phi).any() {
                continue;
            }
            let mut index = None;
            for_each_brick(self.dims, (plo, phi), |n| {
                if bin_in[n] {
                    let k = *index.get_or_insert_with(|| {
                        chunk_particles.push(pi as u32);
                        chunk_particles.len() as u32 - 1
                    });
                    items[cursor[n] as usize] = k;
                    cursor[n] += 1;
                }
            });
        }
        ChunkBins { offsets, items, particles: chunk_particles }
    }
}

/// The bin edge for `particles` and its counts: of 1, 2, 4 and 8 cells, the one with the fewest
/// particle–cell evaluations whose fullest 8³ brick lists at most `max_brick_items` entries
/// (a brick is the smallest chunk the injection uploads). Larger bins list each particle
/// fewer times, so memory pushes the choice up and evaluations push it down.
///
/// `only` restricts the choice to one edge (tests and benchmarks measure each edge).
pub fn choose_bins(
    grid: &GridSpec,
    particles: &[Particle],
    max_brick_items: u64,
    brute_force: bool,
    only: Option<u32>,
) -> BinCounts {
    if brute_force {
        return BinCounts::new(grid, particles, BRICK, true);
    }
    if let Some(edge) = only {
        return BinCounts::new(grid, particles, edge, false);
    }
    let cost = |bin: u32| -> u64 {
        let edge = bin_edge(bin);
        particles
            .iter()
            .filter_map(|p| bin_range(grid, p, edge))
            .map(|(lo, hi)| ((hi - lo + 1).as_u64vec3().element_product()) * edge.as_u64vec3().element_product())
            .sum()
    };
    let mut order = BIN_EDGES;
    order.sort_by_key(|&b| cost(b));
    let mut counts = None;
    for bin in order {
        let c = BinCounts::new(grid, particles, bin, false);
        let fits = c.per_brick(grid).0.iter().all(|&n| n <= max_brick_items);
        counts = Some(c);
        if fits {
            break;
        }
    }
    counts.expect("BIN_EDGES is not empty")
}

/// Bricks whose EV changes when the particle list goes from `old` to `new`: those overlapped
/// by particles in one list and not the other, counted with multiplicity and compared by
/// value, so reordering or renaming costs nothing.
pub fn dirty_bricks(grid: &GridSpec, old: &[Particle], new: &[Particle]) -> Vec<u32> {
    type Key = ([u32; 3], u32, u32, bool, bool);
    let key = |p: &Particle| -> Key {
        (p.center.to_array().map(f32::to_bits), p.radius.to_bits(), p.density.to_bits(), p.hidden, p.noise)
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

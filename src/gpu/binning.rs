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
//!
//! Below every stage and the project's translation (`frame_inputs`), it reads only the scene
//! and the GPU's data layouts (`gpu_types`), including the particles' own
//! ([`particle_gpu`]).

use super::gpu_types::ParticleGpu;
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

/// A particle in the injection's layout: its density counts as noisy when the medium has
/// noise and the particle takes it.
pub fn particle_gpu(p: &Particle, noise: bool) -> ParticleGpu {
    let r = cutoff_radius(p);
    let density = if p.hidden { 0.0 } else { p.density };
    ParticleGpu {
        center: p.center.to_array(),
        inv_r2: 1.0 / (p.radius * p.radius),
        density: if noise && p.noise { [0.0, density] } else { [density, 0.0] },
        cutoff2: r * r,
        _pad: 0.0,
    }
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
#[derive(Clone)]
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

    /// The counts after `removed` particles left the list they were counted from and `added`
    /// ones joined it: what [`BinCounts::new`] gives for the new list, at the cost of the
    /// change. Counts of brute force are of every visible particle in every bin.
    pub fn update(&mut self, grid: &GridSpec, removed: &[&Particle], added: &[&Particle]) {
        let (dims, edge) = (self.dims, bin_edge(self.bin_size));
        for (list, add) in [(removed, false), (added, true)] {
            for p in list {
                let range = if self.brute_force {
                    visible(p).then_some((UVec3::ZERO, dims - 1))
                } else {
                    bin_range(grid, p, edge)
                };
                if let Some(range) = range {
                    for_each_brick(dims, range, |b| {
                        self.counts[b] = if add { self.counts[b] + 1 } else { self.counts[b] - 1 };
                    });
                }
            }
        }
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

/// The particles that left a list and those that joined it between two states, compared by
/// the values the EV reads (centre, radius, density, hidden, noise) with multiplicity, so that
/// reordering or renaming changes nothing.
pub struct Change<'a> {
    pub removed: Vec<&'a Particle>,
    pub added: Vec<&'a Particle>,
}

impl<'a> Change<'a> {
    /// The change from `old` to `new`. Every edit keeps the particles it does not touch in
    /// order, so one walk along both lists pairs them off (guided by ids, which the editor
    /// hands out ascending) and leaves only what the edit touched to be compared by value:
    /// the cost is the walk plus the edit, not a sort of the scene. Lists in another order
    /// still give the right answer, by sorting more.
    pub fn between(old: &'a [Particle], new: &'a [Particle]) -> Self {
        let (mut removed, mut added) = (Vec::new(), Vec::new());
        let (mut i, mut j) = (0, 0);
        while i < old.len() && j < new.len() {
            let (a, b) = (&old[i], &new[j]);
            if a == b {
                i += 1;
                j += 1;
            } else if a.id == b.id {
                removed.push(a);
                added.push(b);
                i += 1;
                j += 1;
            } else if a.id < b.id {
                removed.push(a);
                i += 1;
            } else {
                added.push(b);
                j += 1;
            }
        }
        removed.extend(&old[i..]);
        added.extend(&new[j..]);
        // What left and came back by value (a rename, a reorder) changes no cell.
        type Key = ([u32; 3], u32, u32, bool, bool);
        let key = |p: &Particle| -> Key {
            (p.center.to_array().map(f32::to_bits), p.radius.to_bits(), p.density.to_bits(), p.hidden, p.noise)
        };
        removed.sort_unstable_by_key(|p| key(p));
        added.sort_unstable_by_key(|p| key(p));
        let (mut left, mut joined) = (Vec::new(), Vec::new());
        let (mut i, mut j) = (0, 0);
        while i < removed.len() || j < added.len() {
            match (removed.get(i).map(|p| key(p)), added.get(j).map(|p| key(p))) {
                (Some(x), Some(y)) if x == y => {
                    i += 1;
                    j += 1;
                }
                (Some(x), Some(y)) if x < y => {
                    left.push(removed[i]);
                    i += 1;
                }
                (Some(_), None) => {
                    left.push(removed[i]);
                    i += 1;
                }
                _ => {
                    joined.push(added[j]);
                    j += 1;
                }
            }
        }
        Self { removed: left, added: joined }
    }

    /// Bricks whose EV changes: those the cut-off spheres of the particles that left or
    /// joined overlap.
    pub fn dirty_bricks(&self, grid: &GridSpec) -> Vec<u32> {
        let dims = brick_dims(grid);
        let mut dirty = vec![false; (dims.x * dims.y * dims.z) as usize];
        for p in self.removed.iter().chain(&self.added) {
            if let Some(range) = brick_range(grid, p) {
                for_each_brick(dims, range, |i| dirty[i] = true);
            }
        }
        dirty.iter().enumerate().filter(|(_, d)| **d).map(|(i, _)| i as u32).collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The bricks by a full multiset comparison: sort both lists by value.
    fn dirty_by_sorting(grid: &GridSpec, old: &[Particle], new: &[Particle]) -> Vec<u32> {
        let key = |p: &Particle| {
            (p.center.to_array().map(f32::to_bits), p.radius.to_bits(), p.density.to_bits(), p.hidden, p.noise)
        };
        let (mut a, mut b): (Vec<&Particle>, Vec<&Particle>) = (old.iter().collect(), new.iter().collect());
        a.sort_by_key(|p| key(p));
        b.sort_by_key(|p| key(p));
        let mut removed = Vec::new();
        let mut added = Vec::new();
        let (mut i, mut j) = (0, 0);
        while i < a.len() || j < b.len() {
            match (a.get(i), b.get(j)) {
                (Some(x), Some(y)) if key(x) == key(y) => (i, j) = (i + 1, j + 1),
                (Some(x), Some(y)) if key(x) < key(y) => (removed.push(*x), i += 1).1,
                (Some(x), None) => (removed.push(*x), i += 1).1,
                (_, Some(y)) => (added.push(*y), j += 1).1,
                (None, None) => break,
            }
        }
        Change { removed, added }.dirty_bricks(grid)
    }

    #[test]
    fn a_change_marks_the_bricks_a_full_comparison_marks() {
        let grid = GridSpec { min: Vec3::ZERO, max: Vec3::splat(4.0), resolution: UVec3::splat(40) };
        let base: Vec<Particle> = (0..300u32)
            .map(|i| {
                let f = |k: u32| ((i * k) % 97) as f32 / 97.0 * 4.0;
                Particle { id: i, ..Particle::new(Vec3::new(f(7), f(13), f(31)), 0.05 + (i % 5) as f32 * 0.02, 1.0) }
            })
            .collect();
        let mut appended = base.clone();
        appended.push(Particle { id: 300, ..Particle::new(Vec3::splat(2.0), 0.1, 3.0) });
        let erased: Vec<Particle> = base.iter().filter(|p| p.id % 37 != 4).cloned().collect();
        let mut scaled = base.clone();
        scaled[10].radius *= 2.0;
        scaled[250].hidden = true;
        let mut renamed = base.clone();
        renamed[5].name = Some("a".into());
        let mut reversed = base.clone();
        reversed.reverse();
        let mut mixed = reversed.clone();
        mixed.remove(17);
        mixed[100].center.y += 0.3;
        mixed.push(Particle { id: 301, ..Particle::new(Vec3::splat(1.0), 0.2, 3.0) });
        let mut shuffled_ids = base.clone();
        for (k, p) in shuffled_ids.iter_mut().enumerate() {
            p.id = (k as u32 * 7919) % 300;
        }
        let mut shuffled_edit = shuffled_ids.clone();
        shuffled_edit[33].density = 5.0;
        shuffled_edit.remove(200);
        for (old, new) in [
            (&base, &appended),
            (&appended, &base),
            (&base, &erased),
            (&base, &scaled),
            (&base, &renamed),
            (&base, &reversed),
            (&reversed, &mixed),
            (&base, &mixed),
            (&shuffled_ids, &shuffled_edit),
            (&base, &Vec::new()),
        ] {
            assert_eq!(Change::between(old, new).dirty_bricks(&grid), dirty_by_sorting(&grid, old, new));
        }
        assert!(Change::between(&base, &renamed).dirty_bricks(&grid).is_empty(), "a rename dirties nothing");
        assert!(Change::between(&base, &reversed).dirty_bricks(&grid).is_empty(), "nor does a reorder");
        let append = Change::between(&base, &appended);
        assert_eq!((append.removed.len(), append.added.len()), (0, 1), "an append is only its particle");
    }
}

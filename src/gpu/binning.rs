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

pub struct Bins {
    pub offsets: Vec<u32>,
    pub items: Vec<u32>,
}

impl Bins {
    pub fn overlaps(&self) -> usize {
        self.items.len()
    }
}

/// Bins visible particles (indices into `particles`) into the bricks of `grid`.
pub fn bin_particles(grid: &GridSpec, particles: &[Particle]) -> Bins {
    let brick_dims = (grid.resolution + UVec3::splat(BRICK - 1)) / BRICK;
    let brick_count = (brick_dims.x * brick_dims.y * brick_dims.z) as usize;
    let brick_size = grid.cell_size() * BRICK as f32;
    let ranges: Vec<Option<(UVec3, UVec3)>> = particles
        .iter()
        .map(|p| {
            if p.hidden || p.density <= 0.0 {
                return None;
            }
            let r = cutoff_radius(p);
            let lo = ((p.center - r - grid.min) / brick_size).floor();
            let hi = ((p.center + r - grid.min) / brick_size).floor();
            let max = (brick_dims - 1).as_vec3();
            if hi.cmplt(Vec3::ZERO).any() || lo.cmpgt(max).any() {
                return None;
            }
            Some((lo.clamp(Vec3::ZERO, max).as_uvec3(), hi.clamp(Vec3::ZERO, max).as_uvec3()))
        })
        .collect();
    let brick_index = |b: UVec3| (b.x + brick_dims.x * (b.y + brick_dims.y * b.z)) as usize;
    let mut counts = vec![0u32; brick_count + 1];
    for (lo, hi) in ranges.iter().flatten() {
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    counts[brick_index(UVec3::new(x, y, z)) + 1] += 1;
                }
            }
        }
    }
    for i in 1..counts.len() {
        counts[i] += counts[i - 1];
    }
    let offsets = counts;
    let mut cursor = offsets.clone();
    let mut items = vec![0u32; offsets[brick_count] as usize];
    for (pi, range) in ranges.iter().enumerate() {
        let Some((lo, hi)) = range else { continue };
        for z in lo.z..=hi.z {
            for y in lo.y..=hi.y {
                for x in lo.x..=hi.x {
                    let b = brick_index(UVec3::new(x, y, z));
                    items[cursor[b] as usize] = pi as u32;
                    cursor[b] += 1;
                }
            }
        }
    }
    Bins { offsets, items }
}

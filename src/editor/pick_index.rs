//! Particle bins for picking and box selection in large scenes: clicks and boxes test the
//! bins first, each against a cone or wedge from the camera widened to hold every particle
//! the full scan could accept, and run the scan's own test only on the particles of the bins
//! that pass. The bins depend on the particles alone, so one build serves every view until
//! the particles change (the editor keys it by the content generation). The injection's
//! bricks hold cut-off spheres on the GPU grid, not centres, and only for particles inside
//! it, so picking bins on its own.

use super::view::ViewProjection;
use crate::scene::Particle;
use egui::{Pos2, Rect};
use glam::Vec3;
use std::collections::BTreeSet;

/// Scenes with fewer particles are scanned: binning them would cost more than it saves.
pub const INDEX_FROM: usize = 4096;

/// Particles per bin on average: fewer bins cost less per query, fuller bins more per hit.
const PER_BIN: usize = 32;

/// Relative slack on the bin tests, far above f32's rounding in the projection, so that a
/// particle the scan accepts is never in a bin that is skipped.
const SLACK: f32 = 1e-3;

struct Bin {
    /// Bounding sphere of the centres in the bin.
    center: Vec3,
    radius: f32,
    /// The largest particle radius in the bin.
    max_particle: f32,
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
    fn candidates(&self, mut keep: impl FnMut(&Bin) -> bool) -> impl Iterator<Item = usize> + '_ {
        let ranges: Vec<(u32, u32)> = self.bins.iter().filter(|b| keep(b)).map(|b| (b.start, b.end)).collect();
        ranges
            .into_iter()
            .flat_map(|(s, e)| self.order[s as usize..e as usize].iter())
            .chain(self.loose.iter())
            .map(|&i| i as usize)
    }

    /// The particle [`tools::pick`](super::tools::pick) picks at `pos` among `particles` (its
    /// view depth and index), or None; exactly the full scan's answer, ties included.
    pub fn pick(&self, particles: &[Particle], view: &ViewProjection, pos: Pos2) -> Option<(f32, usize)> {
        self.pick_counted(particles, view, pos).0
    }

    /// [`pick`](Self::pick), and how many particles it tested (for tests and benchmarks).
    pub fn pick_counted(
        &self,
        particles: &[Particle],
        view: &ViewProjection,
        pos: Pos2,
    ) -> (Option<(f32, usize)>, usize) {
        let degenerate = degenerate(view);
        let dir = view.ray(pos);
        let a = view.points_per_metre(1.0);
        let mut best: Option<(f32, usize)> = None;
        let mut tested = 0;
        let keep = |b: &Bin| {
            if degenerate {
                return true;
            }
            let d = b.center - view.position;
            let slack = SLACK * (d.length() + b.radius);
            let z_far = d.dot(view.forward) + b.radius + slack;
            if z_far <= 1e-4 {
                return false;
            }
            // A hit lies within max(radius, 4 points at its depth) of the ray, sideways at its
            // depth, so at least that close to the ray's line.
            let reach = b.max_particle.max(4.0 * z_far / a);
            let off_line = (d - dir * d.dot(dir)).length();
            off_line - b.radius <= reach * (1.0 + SLACK) + slack
        };
        for i in self.candidates(keep) {
            tested += 1;
            if let Some(z) = pick_depth(&particles[i], view, pos) {
                if best.is_none_or(|(bz, bi)| z < bz || (z == bz && i < bi)) {
                    best = Some((z, i));
                }
            }
        }
        (best, tested)
    }

    /// The visible particles whose centres project inside `rect`: exactly
    /// [`tools::box_select`](super::tools::box_select)'s particles.
    pub fn box_select(&self, particles: &[Particle], view: &ViewProjection, rect: Rect) -> BTreeSet<usize> {
        let degenerate = degenerate(view) || !rect.is_finite();
        // The wedge of the rect's screen bounds: X ≥ x0·Z, X ≤ x1·Z, likewise Y, in camera terms.
        let (kx, ky) = (1.0 / view.points_per_metre(1.0), 1.0 / view.points_per_metre(1.0));
        let centre = view.rect.center();
        let x0 = (rect.min.x - centre.x) * kx;
        let x1 = (rect.max.x - centre.x) * kx;
        let y0 = (centre.y - rect.max.y) * ky;
        let y1 = (centre.y - rect.min.y) * ky;
        let planes = [
            view.right - view.forward * x0,
            view.forward * x1 - view.right,
            view.up - view.forward * y0,
            view.forward * y1 - view.up,
        ];
        let keep = |b: &Bin| {
            if degenerate {
                return true;
            }
            let d = b.center - view.position;
            let slack = SLACK * (d.length() + b.radius);
            if d.dot(view.forward) + b.radius + slack <= 1e-4 {
                return false;
            }
            planes.iter().all(|n| n.dot(d) + b.radius * n.length() >= -slack * n.length())
        };
        self.candidates(keep).filter(|&i| in_box(&particles[i], view, rect)).collect()
    }
}

/// Whether the bin tests' geometry (screen offset = points_per_metre(z) × sideways offset)
/// fails for this view: below a point of width or height, or past the aspect's clamp. The
/// bins then all pass and the query is the scan.
fn degenerate(view: &ViewProjection) -> bool {
    let (w, h) = (view.rect.width(), view.rect.height());
    !(w >= 1.0 && h >= 1.0 && w / h >= 1e-3 && w.is_finite() && h.is_finite())
}

/// The scan's pick test for one particle: its view depth when `pos` falls on its footprint.
pub fn pick_depth(p: &Particle, view: &ViewProjection, pos: Pos2) -> Option<f32> {
    if p.hidden {
        return None;
    }
    let (s, z) = view.project(p.center)?;
    let r = (p.radius * view.points_per_metre(z)).max(4.0);
    (s.distance(pos) <= r).then_some(z)
}

/// The scan's box test for one particle.
pub fn in_box(p: &Particle, view: &ViewProjection, rect: Rect) -> bool {
    !p.hidden && view.project(p.center).is_some_and(|(s, _)| rect.contains(s))
}

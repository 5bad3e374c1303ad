//! The sweep scheme's schedule (`propagate_sweep.wgsl`): each light's cells ordered into
//! batches of Chebyshev shells around it, every cell after the cells it reads, and the
//! batches cut into boxes and dispatches that several lights share.

use crate::gpu::gpu_types::{SweepBox, SweepStep};
use crate::gpu::layout::SWEEP_WORKGROUP;
use crate::scene::GridSpec;
use glam::Vec3;

/// A light farther than this many cells from the grid's centre has its Chebyshev shells
/// measured from the point at this distance on the line to it, so that shell levels stay
/// exact to a small fraction of a cell in f32; the shells then stay within a fraction of a
/// cell of being perpendicular to the light's rays, which keeps the sweep's ordering.
const ANCHOR_CELLS: f64 = (1u64 << 19) as f64;

/// Threads per sweep dispatch before a batch is split over several dispatches.
const MAX_THREADS_PER_DISPATCH: u64 = 1 << 30;

/// The cells of one of the scheduler's work items (a batch's cells do not read each other, so
/// any split between its boxes is valid): small enough that one dispatch fits an interactive
/// frame budget on a software adapter, large enough that dispatch overhead stays negligible
/// on a GPU.
pub const ITEM_CELLS: u64 = 1 << 15;

/// Cells each sweep thread solves on an adapter of `device_type`. A CPU adapter (llvmpipe)
/// pays a fixed cost per invocation that is comparable with a cell's work, which several
/// cells per thread amortise (`fogsmith bench --suite opv` measures it); a GPU wants one
/// thread per cell.
pub fn sweep_cells_per_thread(device_type: wgpu::DeviceType) -> u32 {
    if device_type == wgpu::DeviceType::Cpu {
        8
    } else {
        1
    }
}

/// How one light's cells are ordered into batches of Chebyshev shells.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ShellFrame {
    /// Shell centre in cell-centre coordinates (cell (i, j, k) at (i, j, k)).
    pub anchor: [f32; 3],
    /// Level (Chebyshev distance in cells) where batch 0 starts.
    pub level0: f32,
    /// Levels per batch.
    pub width: f32,
    pub batches: u32,
}

impl ShellFrame {
    pub fn new(grid: &GridSpec, light: Vec3, stride: u32) -> Self {
        let n = grid.resolution.as_dvec3();
        let cell = grid.cell_size().as_dvec3();
        let s = (light.as_dvec3() - grid.min.as_dvec3()) / cell - 0.5;
        let centre = (n - 1.0) * 0.5;
        let off = s - centre;
        let far = off.length();
        let anchor = if far > ANCHOR_CELLS { centre + off * (ANCHOR_CELLS / far) } else { s };
        let anchor = anchor.as_vec3();
        let a = anchor.as_dvec3();
        let (mut near, mut farthest) = (0.0f64, 0.0f64);
        for i in 0..3 {
            let hi = n[i] - 1.0;
            near = near.max((-a[i]).max(a[i] - hi).max(0.0));
            farthest = farthest.max(a[i].abs().max((a[i] - hi).abs()));
        }
        let level0 = near.floor() as f32;
        // Bilinear reads (stride 3) reach 1 cell beyond the crossing laterally, Catmull-Rom
        // reads 2: a cell depends only on cells at least stride − 1 or stride − 2 levels
        // closer, and one level of margin is kept for rounding.
        let width = if stride <= 3 { 1 } else { stride - 3 };
        // One level of slack beyond the farthest cell absorbs f32 rounding of the levels.
        let batches = ((farthest + 1.0 - level0 as f64) / width as f64).floor() as u32 + 1;
        Self { anchor: anchor.to_array(), level0, width: width as f32, batches }
    }

    /// The batch and face that solve cell `c`, computed exactly as the shader does.
    pub fn claim(&self, c: [i32; 3]) -> (u32, u32) {
        let r = [c[0] as f32 - self.anchor[0], c[1] as f32 - self.anchor[1], c[2] as f32 - self.anchor[2]];
        let mut a = 0;
        if r[1].abs() > r[a].abs() {
            a = 1;
        }
        if r[2].abs() > r[a].abs() {
            a = 2;
        }
        let face = 2 * a as u32 + u32::from(r[a] < 0.0);
        let batch = ((r[a].abs() - self.level0) / self.width).floor().max(0.0) as u32;
        (batch, face)
    }

    /// Boxes of cells (lo, size), one per layer of the face's axis, that together hold every
    /// cell of `batch` on `face`: a layer is listed where the shader's own batch arithmetic
    /// (f32, as in [`claim`](Self::claim)) can place it in `batch`, and its box spans exactly
    /// the layer's cells that `claim` gives to the face. Cells of a layer all share the face
    /// axis' offset, so few threads are idle.
    fn face_boxes(&self, grid: &GridSpec, batch: u32, face: u32) -> Vec<([i32; 3], [u32; 3])> {
        let n = grid.resolution.as_ivec3();
        let axis = (face / 2) as usize;
        let negative = face % 2 == 1;
        let lo_level = self.level0 as f64 + batch as f64 * self.width as f64;
        let hi_level = lo_level + self.width as f64;
        let a = self.anchor[axis] as f64;
        let (from, to) = if negative { (a - hi_level, a - lo_level) } else { (a + lo_level, a + hi_level) };
        let first = (from.floor() as i64 - 1).max(0);
        let last = (to.ceil() as i64 + 1).min(n[axis] as i64 - 1);
        let mut out = Vec::new();
        for layer in first..=last {
            let r = layer as f32 - self.anchor[axis];
            if (r < 0.0) != negative {
                continue;
            }
            // The shader divides within a few ulp: a layer next to a batch boundary is listed
            // in both batches, and each cell is still solved once (the shader checks its claim).
            let q = (r.abs() - self.level0) / self.width;
            let eps = 1e-5 * q.abs().max(1.0);
            let (b0, b1) = ((q - eps).floor().max(0.0) as u32, (q + eps).floor().max(0.0) as u32);
            if batch != b0 && batch != b1 {
                continue;
            }
            let reach = r.abs() as f64;
            let (mut lo, mut size) = ([0i32; 3], [1u32; 3]);
            lo[axis] = layer as i32;
            let mut empty = false;
            for i in (0..3).filter(|&i| i != axis) {
                let c = self.anchor[i] as f64;
                // The face's own cells along axis i, as the shader's largest_axis assigns
                // them in f32 (ties go to the lower axis), form an interval around the anchor
                // inside these bounds; the shader runs every listed cell, claimed or not.
                let on_face = |x: i64| {
                    let ri = (x as f32 - self.anchor[i]).abs();
                    if i < axis {
                        ri < r.abs()
                    } else {
                        ri <= r.abs()
                    }
                };
                let mut from = ((c - reach).floor() as i64 - 1).max(0);
                let mut to = ((c + reach).ceil() as i64 + 1).min(n[i] as i64 - 1);
                while from <= to && !on_face(from) {
                    from += 1;
                }
                while to >= from && !on_face(to) {
                    to -= 1;
                }
                if from > to {
                    empty = true;
                    break;
                }
                lo[i] = from as i32;
                size[i] = (to - from + 1) as u32;
            }
            if !empty {
                out.push((lo, size));
            }
        }
        out
    }
}

/// The sweep's dispatches: each step solves its boxes, one batch of shells for each light
/// it covers, and only reads cells that earlier steps solved.
#[derive(Clone, Debug, Default)]
pub struct SweepPlan {
    pub steps: Vec<SweepStep>,
    /// Workgroups of each step.
    pub groups: Vec<[u32; 3]>,
    pub boxes: Vec<SweepBox>,
    /// Batches split over several steps, each as one dispatch: (its steps, the step that
    /// covers them all, its workgroups), used when all those steps are encoded together.
    pub whole: Vec<(std::ops::Range<usize>, SweepStep, [u32; 3])>,
}

/// Plans the sweep of `lights` (OPV index, position) with interpolation stride `stride`:
/// dispatch j solves batch j of every light that has one.
pub fn sweep_steps(grid: &GridSpec, lights: &[(u32, Vec3)], stride: u32) -> SweepPlan {
    let all: Vec<(u32, Vec3, u32)> = lights.iter().map(|&(l, p)| (l, p, 0)).collect();
    sweep_steps_from(grid, &all, stride, 1, MAX_THREADS_PER_DISPATCH)
}

/// [`sweep_steps`] where each light `(index, position, first)` starts at batch `first` (the
/// batches before it are left as they are), with `cells_per_thread` cells per thread and at
/// most `max_threads` threads per dispatch where boxes allow.
pub fn sweep_steps_from(
    grid: &GridSpec,
    lights: &[(u32, Vec3, u32)],
    stride: u32,
    cells_per_thread: u64,
    max_threads: u64,
) -> SweepPlan {
    let frames: Vec<(u32, ShellFrame, u32)> =
        lights.iter().map(|&(l, p, first)| (l, ShellFrame::new(grid, p, stride), first)).collect();
    let batches = frames.iter().map(|(_, f, _)| f.batches).max().unwrap_or(0);
    let mut plan = SweepPlan::default();
    let workgroups = |threads: u64| {
        let groups = threads.div_ceil(SWEEP_WORKGROUP as u64).max(1);
        let x = groups.min(65_535);
        ([x as u32, groups.div_ceil(x) as u32, 1], x as u32 * SWEEP_WORKGROUP)
    };
    // Box `first` fields count threads from the start of the batch; a step starts at `offset`.
    let flush = |plan: &mut SweepPlan, first_box: usize, offset: u64, threads: u64| {
        if plan.boxes.len() == first_box {
            return;
        }
        let (groups, row) = workgroups(threads - offset);
        plan.groups.push(groups);
        plan.steps.push(SweepStep {
            first_box: first_box as u32,
            box_count: (plan.boxes.len() - first_box) as u32,
            row,
            stride,
            offset: offset as u32,
            refine: 0,
            tolerance: 0.0,
            _pad: 0,
        });
    };
    for batch in 0..batches {
        let (batch_box, batch_step) = (plan.boxes.len(), plan.steps.len());
        let (mut first_box, mut offset, mut threads) = (plan.boxes.len(), 0u64, 0u64);
        for &(light, frame, _) in frames.iter().filter(|(_, f, first)| batch < f.batches && batch >= *first) {
            for (face, (lo, size)) in
                (0..6).flat_map(|face| frame.face_boxes(grid, batch, face).into_iter().map(move |b| (face, b)))
            {
                let box_threads = size.iter().map(|&s| s as u64).product::<u64>().div_ceil(cells_per_thread);
                if threads - offset + box_threads > max_threads && threads > offset {
                    flush(&mut plan, first_box, offset, threads);
                    first_box = plan.boxes.len();
                    offset = threads;
                }
                plan.boxes.push(SweepBox {
                    lo,
                    light,
                    size,
                    first: threads as u32,
                    anchor: frame.anchor,
                    level0: frame.level0,
                    width: frame.width,
                    face,
                    batch,
                    _pad: 0,
                });
                threads += box_threads;
            }
        }
        flush(&mut plan, first_box, offset, threads);
        if plan.steps.len() > batch_step + 1 && threads <= MAX_THREADS_PER_DISPATCH {
            let (groups, row) = workgroups(threads);
            let step = SweepStep {
                first_box: batch_box as u32,
                box_count: (plan.boxes.len() - batch_box) as u32,
                row,
                stride,
                offset: 0,
                refine: 0,
                tolerance: 0.0,
                _pad: 0,
            };
            plan.whole.push((batch_step..plan.steps.len(), step, groups));
        }
    }
    plan
}

/// The first batch of shells of a light at `position` that cells `changed` (inclusive cell
/// bounds) can affect. A cell at Chebyshev level L (in cells from the shells' centre) reads
/// the extinction only along its path towards the light, whose levels fall monotonically,
/// through stencils one cell wide, and otherwise only cells of earlier batches: it can change
/// only if L + 1 reaches the nearest changed cell. One batch and two levels of slack absorb
/// rounding. A far light's shells are centred on a nearer point of its line, where that
/// argument does not hold: it starts at 0.
pub fn first_changed_batch(grid: &GridSpec, position: Vec3, stride: u32, changed: (glam::UVec3, glam::UVec3)) -> u32 {
    let frame = ShellFrame::new(grid, position, stride);
    let light = ((position - grid.min) / grid.cell_size() - 0.5).to_array();
    if (0..3).any(|i| (frame.anchor[i] - light[i]).abs() > 1e-3) {
        return 0;
    }
    let (lo, hi) = (changed.0.as_vec3().to_array(), changed.1.as_vec3().to_array());
    let nearest =
        (0..3).map(|i| (lo[i] - frame.anchor[i]).max(frame.anchor[i] - hi[i]).max(0.0)).fold(0.0f32, f32::max);
    let first = ((nearest - 2.0 - frame.level0) / frame.width).floor() - 1.0;
    if first > 0.0 {
        first as u32
    } else {
        0
    }
}

/// The cells of the bricks whose detail a change of `cells` (inclusive bounds) can alter: its
/// bricks and those one cell beyond them (`shaders/occupancy.wgsl` reads one cell around).
pub(super) fn bricks_around(grid: &GridSpec, (lo, hi): (glam::UVec3, glam::UVec3)) -> (glam::UVec3, glam::UVec3) {
    let b = crate::gpu::binning::BRICK;
    let max = grid.resolution.max(glam::UVec3::ONE) - 1;
    let lo = lo.saturating_sub(glam::UVec3::ONE) / b * b;
    let hi = ((hi + 1) / b * b + (b - 1)).min(max);
    (lo, hi)
}

#[cfg(test)]
mod tests {
    use super::*;
    use glam::IVec3;
    use glam::UVec3;

    /// The cells a sweep cell reads (none when it integrates directly), as the shader finds them.
    fn reads(grid: &GridSpec, light: Vec3, stride: u32, c: [i32; 3]) -> Vec<[i32; 3]> {
        let cell = grid.cell_size();
        let x = grid.min + (IVec3::from(c).as_vec3() + 0.5) * cell;
        let v = light - x;
        let len = v.length();
        let dir = v / len;
        let exit = |lo: Vec3, hi: Vec3| {
            let (mut at, mut axis) = (len, 3);
            for i in 0..3 {
                let t = if dir[i] > 0.0 {
                    (hi[i] - x[i]) / dir[i]
                } else if dir[i] < 0.0 {
                    (lo[i] - x[i]) / dir[i]
                } else {
                    len
                };
                if t < at {
                    (at, axis) = (t, i);
                }
            }
            (at.max(0.0), axis)
        };
        let (inside, _) = exit(grid.min, grid.max);
        let (_, exit_axis) = exit(grid.min + 0.5 * cell, grid.max - 0.5 * cell);
        let mag = (v / cell).abs();
        let mut a = 0;
        if mag.y > mag[a] {
            a = 1;
        }
        if mag.z > mag[a] {
            a = 2;
        }
        let s = stride as f32;
        let (mut e, mut layers) = (a, s);
        if exit_axis < 3 && exit_axis != a {
            e = exit_axis;
            layers = (s * mag[e] / mag[a]).ceil().max(1.0);
        }
        let to_plane = len * layers / mag[e];
        let n = grid.resolution.as_ivec3();
        let layer = c[e] + layers as i32 * v[e].signum() as i32;
        if mag[a] < s + 0.5 || inside <= to_plane || layer < 0 || layer >= n[e] {
            return Vec::new();
        }
        let p = x + dir * to_plane;
        let u = (p - grid.min) / cell - 0.5;
        let reach = if stride >= 4 { 1 } else { 0 };
        let mut out = Vec::new();
        let (b, d) = ((e + 1) % 3, (e + 2) % 3);
        let fb = u[b].clamp(0.0, (n[b] - 1) as f32).floor() as i32;
        let fd = u[d].clamp(0.0, (n[d] - 1) as f32).floor() as i32;
        for j in -reach..=1 + reach {
            for i in -reach..=1 + reach {
                let mut r = IVec3::from(c);
                r[e] = layer;
                r[b] = (fb + i).clamp(0, n[b] - 1);
                r[d] = (fd + j).clamp(0, n[d] - 1);
                out.push(r.to_array());
            }
        }
        out
    }

    fn placements(grid: &GridSpec) -> Vec<Vec3> {
        let (lo, hi, c) = (grid.min, grid.max, (grid.min + grid.max) * 0.5);
        let size = grid.size();
        let mut out = vec![
            c,
            lo + size * Vec3::new(0.13, 0.71, 0.37),
            lo,
            hi,
            Vec3::new(lo.x, c.y, hi.z),
            Vec3::new(c.x, hi.y, c.z),
        ];
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let d = Vec3::new(dx as f32, dy as f32, dz as f32);
                    if d != Vec3::ZERO {
                        out.push(c + d * size * 0.8);
                        out.push(c + d * size * 0.5 + Vec3::new(0.01, -0.02, 0.03) * size);
                        out.push(c + d * 1e9 / d.length() + Vec3::new(3.0, -7.0, 1.0));
                    }
                }
            }
        }
        out.push(Vec3::new(1e9, -1e9, 1e8));
        out.push(Vec3::new(0.3, 1e3, -2e2));
        out
    }

    /// Every cell is solved by exactly one box of the plan, after every cell it reads, and a
    /// box lists only cells of its own face (the shader runs every listed cell).
    #[test]
    fn sweep_plan_solves_each_cell_once_after_its_inputs() {
        for (res, stride) in [
            (UVec3::new(12, 12, 12), 3),
            (UVec3::new(20, 9, 5), 8),
            (UVec3::new(40, 6, 6), 16),
            (UVec3::new(17, 17, 17), 5),
            (UVec3::new(24, 24, 1), 8),
            (UVec3::new(20, 2, 18), 5),
        ] {
            let grid = GridSpec { min: Vec3::new(-1.0, 0.0, -0.5), max: Vec3::new(1.5, 1.0, 0.5), resolution: res };
            for light in placements(&grid) {
                let frame = ShellFrame::new(&grid, light, stride);
                let plan = sweep_steps(&grid, &[(0, light)], stride);
                assert!(plan.steps.len() as u32 <= frame.batches, "{light}");
                for b in &plan.boxes {
                    for k in 0..b.size[2] as i32 {
                        for j in 0..b.size[1] as i32 {
                            for i in 0..b.size[0] as i32 {
                                let c = [b.lo[0] + i, b.lo[1] + j, b.lo[2] + k];
                                assert_eq!(
                                    frame.claim(c).1,
                                    b.face,
                                    "{res} {light}: cell {c:?} listed for face {}",
                                    b.face
                                );
                            }
                        }
                    }
                }
                let n = res.as_ivec3();
                for k in 0..n.z {
                    for j in 0..n.y {
                        for i in 0..n.x {
                            let c = [i, j, k];
                            let (batch, face) = frame.claim(c);
                            let holders = plan
                                .boxes
                                .iter()
                                .filter(|b| b.batch == batch && b.face == face)
                                .filter(|b| (0..3).all(|a| c[a] >= b.lo[a] && c[a] < b.lo[a] + b.size[a] as i32))
                                .count();
                            assert_eq!(holders, 1, "{res} {light} cell {c:?} batch {batch} face {face}");
                            for r in reads(&grid, light, stride, c) {
                                let (rb, _) = frame.claim(r);
                                assert!(
                                    rb < batch,
                                    "{res} s{stride} {light}: cell {c:?} (batch {batch}) reads {r:?} (batch {rb})"
                                );
                            }
                        }
                    }
                }
            }
        }
    }

    /// All lights share each dispatch: the count is the batches of the deepest light.
    #[test]
    fn sweep_dispatches_are_batches_of_shells_shared_by_lights() {
        let grid = GridSpec { min: Vec3::ZERO, max: Vec3::ONE, resolution: UVec3::splat(64) };
        let lights = [(0, Vec3::splat(0.5)), (1, Vec3::new(3.0, 0.5, 0.5)), (2, Vec3::new(-1e9, 1e9, 1e9))];
        let plan = sweep_steps(&grid, &lights, 8);
        let deepest = lights.iter().map(|&(_, p)| ShellFrame::new(&grid, p, 8).batches).max().unwrap();
        assert_eq!(plan.steps.len() as u32, deepest);
        // Batches of stride − 3 = 5 levels: 64 levels from outside, 32 from the centre.
        assert!(deepest <= 65 / 5 + 1, "{deepest}");
        let centre = ShellFrame::new(&grid, Vec3::splat(0.5), 8).batches;
        assert!(centre <= 33 / 5 + 1, "{centre}");
    }
}

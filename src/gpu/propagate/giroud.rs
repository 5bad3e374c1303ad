//! The iteration count of Giroud & Biri's gather (`propagate_giroud.wgsl`), which the host
//! computes from the light's cell.

use crate::scene::GridSpec;
use glam::{IVec3, Vec3};

/// The light's cell index (may lie outside the grid). A light far outside is moved, per
/// axis, to 2²⁰ cells beyond the grid, which keeps the integer arithmetic far inside i32.
fn light_cell(grid: &GridSpec, light: Vec3) -> IVec3 {
    const FAR: f32 = (1 << 20) as f32;
    let c = ((light - grid.min) / grid.cell_size()).floor();
    c.clamp(Vec3::splat(-FAR), grid.resolution.as_vec3() + FAR).as_ivec3()
}

/// Jacobi sweeps after which the `giroud` gather has converged exactly: one more than the
/// largest Manhattan distance (in cells) from any cell to the light's slabs.
pub fn giroud_iterations(grid: &GridSpec, light: Vec3) -> u32 {
    let lc = light_cell(grid, light);
    let n = grid.resolution.as_ivec3();
    let mut total = 0;
    for a in 0..3 {
        total += if lc[a] < 0 || lc[a] >= n[a] { n[a] } else { lc[a].max(n[a] - 1 - lc[a]) };
    }
    total as u32 + 1
}

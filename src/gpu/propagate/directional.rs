//! The planes of a sun's sweep (`propagate_directional.wgsl`), which computes its OPV plane by
//! plane along the light's direction: their order and the plane each interpolates from.

use crate::gpu::gpu_types::PlaneParams;
use crate::scene::GridSpec;
use glam::Vec3;

/// Planes a sun's sweep steps back per interpolation: each step integrates the medium exactly
/// over this many planes and interpolates once, so fewer interpolations blur the shadows less.
pub(super) const SUN_STRIDE: u32 = 16;

/// The dispatches of one sun's sweep, upstream plane first. The planes are stacked along the
/// axis the light travels most along; each plane interpolates in the plane `stride` planes
/// upstream (fewer interpolations, less numerical diffusion), the first `stride` planes
/// integrate straight to the box. `refine`: the tolerance of the interpolations' error
/// control, if on.
pub(super) fn sun_planes(
    grid: &GridSpec,
    light: u32,
    direction: Vec3,
    stride: u32,
    refine: Option<f32>,
) -> Vec<PlaneParams> {
    let towards = -direction;
    let axis = towards.abs().max_position();
    let n = grid.resolution[axis];
    // The sun lies towards +axis when towards[axis] > 0: light enters at the last plane.
    let from_top = towards[axis] > 0.0;
    (0..n)
        .map(|k| {
            let plane = if from_top { n - 1 - k } else { k };
            let previous = if k < stride {
                plane
            } else if from_top {
                plane + stride
            } else {
                plane - stride
            };
            PlaneParams {
                light,
                axis: axis as u32,
                plane,
                previous,
                refine: refine.is_some() as u32,
                tolerance: refine.unwrap_or(0.0),
                _pad: [0; 2],
            }
        })
        .collect()
}

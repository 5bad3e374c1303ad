//! Plain-old-data mirrors of the WGSL structs in `shaders/common.wgsl` and friends.

use bytemuck::{Pod, Zeroable};

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct GridParams {
    pub min: [f32; 3],
    pub base_extinction: f32,
    pub max: [f32; 3],
    pub light_count: u32,
    pub cell: [f32; 3],
    pub has_base_layer: u32,
    pub dims: [u32; 3],
    pub bin_size: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct LightGpu {
    pub position: [f32; 3],
    pub _pad0: f32,
    pub rgb: [f32; 3],
    pub _pad1: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct ParticleGpu {
    pub center: [f32; 3],
    pub inv_r2: f32,
    pub density: f32,
    pub cutoff2: f32,
    pub _pad: [f32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct MarchParams {
    pub origin: [f32; 3],
    pub step: f32,
    pub right: [f32; 3],
    pub albedo: f32,
    pub up: [f32; 3],
    pub anisotropy: f32,
    pub forward: [f32; 3],
    pub exposure: f32,
    pub size: [u32; 2],
    pub tr_cutoff: f32,
    pub far_distance: f32,
    pub policy: u32,
    pub near_steps: u32,
    pub far_steps: u32,
    pub skip_empty: u32,
    pub tau_target: f32,
    pub near_fraction: f32,
    pub min_step: f32,
    pub max_step: f32,
    pub surface_count: u32,
    pub _pad: [u32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct SurfaceGpu {
    pub min: [f32; 3],
    pub kind: u32,
    pub max: [f32; 3],
    pub _pad0: f32,
    pub albedo: [f32; 3],
    pub _pad1: f32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct SweepStep {
    /// The dispatch's boxes: `boxes[first_box .. first_box + box_count]`.
    pub first_box: u32,
    pub box_count: u32,
    /// Threads per row of workgroups.
    pub row: u32,
    pub stride: u32,
}

/// One slab of cells a sweep dispatch may solve for one light (see `propagate_sweep.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct SweepBox {
    pub lo: [i32; 3],
    pub light: u32,
    pub size: [u32; 3],
    /// Index, within its dispatch, of the box's first thread.
    pub first: u32,
    /// Where the light's Chebyshev shells are measured from, in cell-centre coordinates.
    pub anchor: [f32; 3],
    pub level0: f32,
    pub width: f32,
    /// 2·axis + 1 on the negative side of the anchor.
    pub face: u32,
    pub batch: u32,
    pub _pad: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct ExactParams {
    pub light: u32,
    pub steps_per_cell: u32,
    pub _pad: [u32; 2],
}

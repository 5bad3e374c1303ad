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
    pub height_falloff: f32,
    pub height_origin: f32,
    pub _pad_h: [u32; 2],
    /// The medium's noise (the octaves kept on the grid; 0: none).
    pub noise_amplitude: f32,
    pub noise_frequency: f32,
    pub noise_octaves: u32,
    pub noise_seed: u32,
    /// The noise's drift (wind): n is evaluated at x − noise_offset.
    pub noise_offset: [f32; 3],
    pub _pad_n: u32,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct LightGpu {
    pub position: [f32; 3],
    /// `LIGHT_POINT`, `LIGHT_SPOT` or `LIGHT_DIRECTIONAL` (src/gpu/layout.rs).
    pub kind: u32,
    pub rgb: [f32; 3],
    /// Spot half-angle in radians.
    pub angle: f32,
    /// Unit spot axis or direction of travel of a directional light.
    pub direction: [f32; 3],
    pub blend: f32,
    /// Bit i set when surface i (< 32) can block a path from the grid box to the light
    /// (`frame_inputs::occluders`).
    pub occluders: u32,
    pub _pad: [u32; 3],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct ParticleGpu {
    pub center: [f32; 3],
    pub inv_r2: f32,
    /// Peak extinction, split by whether the medium's noise modulates the particle:
    /// (plain, noisy); one of them is 0.
    pub density: [f32; 2],
    pub cutoff2: f32,
    pub _pad: f32,
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
    /// First image row of this dispatch (the march runs in bands of rows).
    pub row_offset: u32,
    /// Directional lights among the lights: the march visits them in a loop of their own.
    pub sun_count: u32,
    /// First image column of this dispatch (a band narrower than the image).
    pub col_offset: u32,
    /// Adaptive image sampling (`image_sampling`): the rays [list_offset, list_end) of the
    /// lattice of stride `lattice_stride`, or of the list where that is 0, into the padded
    /// `padded_width`×`padded_height` image.
    pub list_offset: u32,
    pub list_end: u32,
    pub lattice_stride: u32,
    pub padded_width: u32,
    pub padded_height: u32,
    /// Fine cells per coarse cell edge of the multiple-scattering grid the march reads; 0:
    /// single scattering only.
    pub scatter_factor: u32,
    pub _pad: [u32; 2],
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct SurfaceGpu {
    pub min: [f32; 3],
    pub kind: u32,
    pub max: [f32; 3],
    pub specular: f32,
    pub albedo: [f32; 3],
    pub phong_exponent: f32,
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
    /// Index of the step's first thread among its batch's.
    pub offset: u32,
    /// 1: interpolations are error-controlled (`sweep_refine`).
    pub refine: u32,
    /// Their largest accepted error in transmittance (`sweep_tolerance`).
    pub tolerance: f32,
    pub _pad: u32,
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
    /// First z layer of this dispatch's slab.
    pub z_offset: u32,
    pub _pad: u32,
}

/// A particle of the `analytic` propagation (`propagate_analytic.wgsl`, which reads it as two
/// vec4s): its centre and 1/r, then the amplitude ρ·r·√π/2 of its line integrals in x.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct AnalyticParticle {
    pub centre_inv_radius: [f32; 4],
    pub amplitude: [f32; 4],
}

impl AnalyticParticle {
    pub fn new(p: &crate::scene::Particle) -> Self {
        Self {
            centre_inv_radius: p.center.extend(1.0 / p.radius).to_array(),
            amplitude: [p.density * p.radius * (0.5 * std::f32::consts::PI.sqrt()), 0.0, 0.0, 0.0],
        }
    }
}

/// One plane of a sun's sweep (see `propagate_directional.wgsl`).
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct PlaneParams {
    pub light: u32,
    /// The axis the planes are stacked along.
    pub axis: u32,
    pub plane: u32,
    /// The upstream plane; equal to `plane` for the first.
    pub previous: u32,
    /// 1: the interpolations are error-controlled (`propagation.sweep_refine`).
    pub refine: u32,
    /// Their largest accepted error in transmittance.
    pub tolerance: f32,
    pub _pad: [u32; 2],
}

/// Uniform of `shaders/scatter_sweep.wgsl`: the coarse grid, the medium and the order.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct ScatterParams {
    pub dims: [u32; 3],
    pub count: u32,
    pub cell: [f32; 3],
    pub albedo: f32,
    pub min: [f32; 3],
    pub anisotropy: f32,
    /// The order whose source `power` sums (0: the first scattering).
    pub order: u32,
    /// Orders swept.
    pub orders: u32,
    pub strength: f32,
    pub _pad: u32,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gpu::opv_store::OpvLayout;
    use crate::gpu::shaders;
    use wgpu::naga;

    /// Size of WGSL struct `name` in the finished WGSL `code`.
    fn wgsl_size(code: &str, name: &str) -> u32 {
        let module = naga::front::wgsl::parse_str(code).unwrap_or_else(|e| panic!("{name}: {e}"));
        let mut layouter = naga::proc::Layouter::default();
        layouter.update(module.to_ctx()).expect("layout");
        let (handle, _) = module
            .types
            .iter()
            .find(|(_, t)| t.name.as_deref() == Some(name))
            .unwrap_or_else(|| panic!("no struct {name} in the shader"));
        layouter[handle].size
    }

    #[test]
    fn every_gpu_struct_has_the_size_of_its_wgsl_twin() {
        let opv = OpvLayout { textures: 2, max_depth: 2048, lights_per_texture: u32::MAX, rows: true };
        let (inject, march, sweep) = (shaders::inject(), shaders::march(&opv), shaders::propagate_sweep(&opv, 8, true));
        let cases = [
            (shaders::propagate_analytic(&opv), "AnalyticParams", std::mem::size_of::<ExactParams>()),
            (shaders::propagate_directional(&opv), "PlaneParams", std::mem::size_of::<PlaneParams>()),
            (sweep.clone(), "SweepBox", std::mem::size_of::<SweepBox>()),
            (shaders::slice(&opv), "SliceParams", std::mem::size_of::<crate::gpu::slice::SliceParams>()),
            (inject.clone(), "GridParams", std::mem::size_of::<GridParams>()),
            (inject.clone(), "LightGpu", std::mem::size_of::<LightGpu>()),
            (inject, "ParticleGpu", std::mem::size_of::<ParticleGpu>()),
            (march.clone(), "MarchParams", std::mem::size_of::<MarchParams>()),
            (march, "Surface", std::mem::size_of::<SurfaceGpu>()),
            (sweep, "SweepStep", std::mem::size_of::<SweepStep>()),
            (shaders::propagate_exact(&opv), "ExactParams", std::mem::size_of::<ExactParams>()),
            (shaders::scatter_sweep(), "ScatterParams", std::mem::size_of::<ScatterParams>()),
            (shaders::image_refine(), "RefineParams", std::mem::size_of::<crate::gpu::image_sampling::RefineParams>()),
        ];
        for (code, name, rust) in cases {
            assert_eq!(wgsl_size(&code, name) as usize, rust, "{name}: WGSL and Rust sizes differ");
        }
    }
}

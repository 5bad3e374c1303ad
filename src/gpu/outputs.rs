//! What the pipeline hands back: the extinction and optical-depth volumes, planes of them,
//! and the rendered image, read back from the GPU resources that hold them.

use super::march::ImageTarget;
use super::readback::read_texture;
use super::resources::GridResources;
use super::slice::{Plane, SliceInputs, SliceParams, SliceSource, Slicer};
use super::{GpuContext, GpuError};
use crate::scene::Volume;

/// Linear HDR radiance read back from the GPU: RGB plus alpha = 1 − transmittance.
#[derive(Clone, Debug)]
pub struct Image {
    pub width: u32,
    pub height: u32,
    pub rgba: Vec<[f32; 4]>,
}

/// The extinction volume σ_t at cell centres.
pub(super) fn read_ev(ctx: &GpuContext, g: &GridResources) -> Result<Volume, GpuError> {
    let data = read_texture(ctx, &g.ev, g.spec.resolution.to_array(), 4)?;
    Ok(Volume::new(g.spec, data))
}

/// Optical depth T towards light `light` at cell centres.
pub(super) fn read_opv(ctx: &GpuContext, g: &GridResources, light: usize) -> Result<Volume, GpuError> {
    if light >= g.light_count {
        return Err(GpuError::Invalid(format!("light {light} does not exist (the scene has {})", g.light_count)));
    }
    let data = g.opv[0].read(ctx, light as u64)?;
    Ok(Volume::new(g.spec, data))
}

/// Plane `index` across grid `axis` (0, 1, 2 for x, y, z) of the EV or of one light's OPV,
/// gathered on the GPU so that only the plane is read back.
pub(super) fn read_slice(
    ctx: &GpuContext,
    slicer: &mut Slicer,
    g: &GridResources,
    source: SliceSource,
    axis: usize,
    index: u32,
) -> Result<Plane, GpuError> {
    let dims = g.spec.resolution.to_array();
    if axis > 2 || index >= dims[axis.min(2)] {
        return Err(GpuError::Invalid(format!("slice {index} across axis {axis} is outside the {dims:?} grid")));
    }
    let (light, source) = match source {
        SliceSource::Extinction => (0, 0),
        SliceSource::OpticalDepth { light } if light < g.light_count => (light as u32, 1),
        SliceSource::OpticalDepth { light } => {
            return Err(GpuError::Invalid(format!("light {light} does not exist (the scene has {})", g.light_count)))
        }
    };
    let inputs = SliceInputs { grid_buf: &g.grid_buf, ev_view: &g.ev_view, opv: &g.opv[0] };
    slicer.read(ctx, &inputs, dims, SliceParams { axis: axis as u32, index, light, source })
}

/// The linear HDR radiance of `target`.
pub(super) fn read_image(ctx: &GpuContext, target: &ImageTarget) -> Result<Image, GpuError> {
    let rgba = read_texture(ctx, &target.hdr, [target.width, target.height, 1], 16)?;
    Ok(Image { width: target.width, height: target.height, rgba })
}

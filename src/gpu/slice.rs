//! Reading back one plane of a volume (`shaders/slice.wgsl`): what the slice view shows,
//! without copying the whole EV or OPV to the CPU.

use super::layout::{bind_group_layout_with, bind_group_with, compute_pipeline, Slot, WORKGROUP_2D};
use super::opv_store::{OpvLayout, OpvVolumes, EXTRA_BINDING};
use super::readback::read_buffer;
use super::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// Which volume a slice comes from.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum SliceSource {
    Extinction,
    OpticalDepth { light: usize },
}

/// One plane of a volume: `values[u + v·dims[0]]`, where u and v run along the two other grid
/// axes in increasing order (for axis y: x, then z).
#[derive(Clone, Debug, PartialEq)]
pub struct Plane {
    pub axis: usize,
    pub index: u32,
    pub dims: [u32; 2],
    pub values: Vec<f32>,
}

#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable, PartialEq)]
pub struct SliceParams {
    pub axis: u32,
    pub index: u32,
    pub light: u32,
    pub source: u32,
}

/// The bindings a slice reads.
pub struct SliceInputs<'a> {
    pub grid_buf: &'a wgpu::Buffer,
    pub ev_view: &'a wgpu::TextureView,
    pub opv: &'a OpvVolumes,
}

pub struct Slicer {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    params: wgpu::Buffer,
    plane: wgpu::Buffer,
}

impl Slicer {
    pub fn new(device: &wgpu::Device, opv: OpvLayout) -> Self {
        let layout = bind_group_layout_with(
            device,
            "slice",
            &[Slot::Uniform, Slot::Texture3d, Slot::Opv { read_only: true }, Slot::Uniform, Slot::StorageWrite],
            opv.layout_entries(EXTRA_BINDING, true),
        );
        let pipeline = compute_pipeline(device, "slice", super::shaders::slice(&opv), &layout);
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("slice params"),
            size: std::mem::size_of::<SliceParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let plane = super::buffers::storage_buffer(device, "slice plane", &[]);
        Self { layout, pipeline, params, plane }
    }

    /// Gathers plane `index` across `axis` of a `dims` grid and reads it back.
    pub fn read(
        &mut self,
        ctx: &GpuContext,
        inputs: &SliceInputs,
        dims: [u32; 3],
        params: SliceParams,
    ) -> Result<Plane, GpuError> {
        let axis = params.axis as usize;
        let (a, b) = match axis {
            0 => (1, 2),
            1 => (0, 2),
            _ => (0, 1),
        };
        let plane_dims = [dims[a], dims[b]];
        let count = plane_dims[0] as u64 * plane_dims[1] as u64;
        if count * 4 > self.plane.size() {
            self.plane = ctx.device.create_buffer(&wgpu::BufferDescriptor {
                label: Some("slice plane"),
                size: (count * 4).next_multiple_of(256),
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
                mapped_at_creation: false,
            });
        }
        ctx.queue.write_buffer(&self.params, 0, bytemuck::bytes_of(&params));
        let bg = bind_group_with(
            &ctx.device,
            "slice",
            &self.layout,
            &[
                inputs.grid_buf.as_entire_binding(),
                wgpu::BindingResource::TextureView(inputs.ev_view),
                inputs.opv.first(),
                self.params.as_entire_binding(),
                self.plane.as_entire_binding(),
            ],
            inputs.opv.extra_entries(EXTRA_BINDING),
        );
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("slice"), timestamp_writes: None });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bg, &[]);
            pass.dispatch_workgroups(plane_dims[0].div_ceil(WORKGROUP_2D), plane_dims[1].div_ceil(WORKGROUP_2D), 1);
        }
        ctx.queue.submit([encoder.finish()]);
        let values = read_buffer(ctx, &self.plane, 0, count as usize)?;
        Ok(Plane { axis, index: params.index, dims: plane_dims, values })
    }

    pub fn bytes(&self) -> u64 {
        self.params.size() + self.plane.size()
    }
}

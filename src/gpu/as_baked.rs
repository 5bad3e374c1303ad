//! The "as baked" render: the emission–absorption image of a bake (`shaders/as_baked.wgsl`),
//! what an engine that reads the baked density and emission shows, with no lights. The editor
//! shows it beside the lit preview so that what a bake loses (the view's phase in isotropic
//! mode, resolution) is visible before exporting.

use super::gpu_types::{MarchParams, SurfaceGpu};
use super::layout::{compute_pipeline_entry, Slot, WORKGROUP_2D};
use super::march::ImageTarget;
use super::{GpuContext, GpuError};
use crate::scene::Volume3;

/// Steps per smallest cell edge along each ray.
pub const AS_BAKED_STEPS_PER_CELL: f32 = 8.0;

/// What one render reads.
pub struct AsBakedInputs<'a> {
    pub grid_buf: &'a wgpu::Buffer,
    pub ev_view: &'a wgpu::TextureView,
    pub emission: &'a Volume3,
    pub surfaces: &'a [SurfaceGpu],
    /// The march's parameters (camera, exposure); the step is set here.
    pub params: MarchParams,
}

pub struct AsBakedRenderer {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

impl AsBakedRenderer {
    pub fn new(device: &wgpu::Device, opv: super::OpvLayout) -> Self {
        let entry = |binding: u32, ty: wgpu::BindingType| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        };
        let storage_texture = |format| wgpu::BindingType::StorageTexture {
            access: wgpu::StorageTextureAccess::WriteOnly,
            format,
            view_dimension: wgpu::TextureViewDimension::D2,
        };
        let read = wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only: true },
            has_dynamic_offset: false,
            min_binding_size: None,
        };
        // The march's bindings it reads (0–2, 5, 6, 9), plus the emission at 11.
        let extra = vec![
            entry(5, storage_texture(wgpu::TextureFormat::Rgba32Float)),
            entry(6, storage_texture(wgpu::TextureFormat::Rgba8Unorm)),
            entry(9, read),
            entry(11, read),
        ];
        let layout = super::layout::bind_group_layout_with(
            device,
            "as baked",
            &[Slot::Uniform, Slot::Uniform, Slot::StorageTexture3dRead(wgpu::TextureFormat::R32Float)],
            extra,
        );
        let pipeline = compute_pipeline_entry(device, "as baked", super::shaders::as_baked(&opv), &layout, "as_baked");
        Self { layout, pipeline }
    }

    /// Renders the bake into `target`.
    pub fn render(&self, ctx: &GpuContext, inputs: &AsBakedInputs, target: &ImageTarget) -> Result<(), GpuError> {
        let device = &ctx.device;
        let cells: Vec<[f32; 4]> = inputs.emission.data.iter().map(|e| [e[0], e[1], e[2], 0.0]).collect();
        let bytes = std::mem::size_of_val(cells.as_slice()) as u64;
        if bytes > ctx.max_binding_bytes() {
            return Err(GpuError::Limit {
                what: "the baked emission of the \"as baked\" preview".into(),
                needed: bytes,
                limit: ctx.max_binding_bytes(),
                adapter: ctx.adapter_summary(),
                suggestion: "use a coarser grid for the preview".into(),
            });
        }
        let emission = super::buffers::storage_buffer(device, "as baked emission", bytemuck::cast_slice(&cells));
        let surfaces =
            super::buffers::storage_buffer(device, "as baked surfaces", bytemuck::cast_slice(inputs.surfaces));
        let step = inputs.emission.grid.cell_size().min_element() / AS_BAKED_STEPS_PER_CELL;
        let params = MarchParams {
            step,
            size: [target.width, target.height],
            row_offset: 0,
            surface_count: inputs.surfaces.len() as u32,
            ..inputs.params
        };
        let params_buf = {
            use wgpu::util::DeviceExt;
            device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                label: Some("as baked params"),
                contents: bytemuck::bytes_of(&params),
                usage: wgpu::BufferUsages::UNIFORM,
            })
        };
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("as baked"),
            layout: &self.layout,
            entries: &[
                wgpu::BindGroupEntry { binding: 0, resource: inputs.grid_buf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: params_buf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(inputs.ev_view) },
                wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(&target.hdr_view) },
                wgpu::BindGroupEntry { binding: 6, resource: wgpu::BindingResource::TextureView(&target.ldr_view) },
                wgpu::BindGroupEntry { binding: 9, resource: surfaces.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 11, resource: emission.as_entire_binding() },
            ],
        });
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("as baked"), timestamp_writes: None });
            pass.set_pipeline(&self.pipeline);
            pass.set_bind_group(0, &bind_group, &[]);
            pass.dispatch_workgroups(target.width.div_ceil(WORKGROUP_2D), target.height.div_ceil(WORKGROUP_2D), 1);
        }
        ctx.queue.submit([encoder.finish()]);
        ctx.wait()
    }
}

//! The march's lookup volumes (`shaders/march_lookup.wgsl`): per light and cell, the mean
//! extinction along the cell centre's path to the light, which the march interpolates and
//! scales by each sample's own path length. Without them every sample would divide eight
//! optical depths by eight distances (or, for a sun, find eight exit distances and base-fog
//! depths) per light; with them it loads eight values.
//!
//! [`LookupBuilder`] is long-lived (pipeline and layout); the volumes live with the grid's
//! other per-light arrays (`resources`). Before a march or a bake the pipeline rebuilds the
//! volumes of the lights whose OPV, light or grid parameters changed since their last build.

use super::layout::{bind_group_layout_with, bind_group_with, compute_pipeline, Slot, WORKGROUP_3D};
use super::opv_store::{OpvLayout, OpvVolumes, EXTRA_BINDING, EXTRA_BINDING_2};
use super::GpuContext;
use crate::scene::GridSpec;

/// What one build reads and writes.
pub struct LookupInputs<'a> {
    pub spec: GridSpec,
    /// Per light, whether to rebuild its volume.
    pub stale: &'a [bool],
    pub grid_buf: &'a wgpu::Buffer,
    pub ev_view: &'a wgpu::TextureView,
    pub lights_buf: &'a wgpu::Buffer,
    pub opv: &'a OpvVolumes,
    pub lookup: &'a OpvVolumes,
}

pub struct LookupBuilder {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
    /// One flag per light, nonzero where the volume is rebuilt.
    flags: wgpu::Buffer,
}

impl LookupBuilder {
    pub fn new(device: &wgpu::Device, opv: OpvLayout) -> Self {
        let mut extra = opv.layout_entries(EXTRA_BINDING, true);
        extra.extend(opv.layout_entries(EXTRA_BINDING_2, false));
        let layout = bind_group_layout_with(
            device,
            "march lookup",
            &[
                Slot::Uniform,
                Slot::Texture3d,
                Slot::StorageRead,
                Slot::Opv { read_only: true },
                Slot::Opv { read_only: false },
                Slot::StorageRead,
            ],
            extra,
        );
        let pipeline = compute_pipeline(device, "march lookup", super::shaders::march_lookup(&opv), &layout);
        let flags = super::buffers::storage_buffer(device, "march lookup flags", &[0u8; 4]);
        Self { layout, pipeline, flags }
    }

    /// Encodes the rebuild of the stale lights' lookup volumes.
    pub fn encode(&mut self, ctx: &GpuContext, encoder: &mut wgpu::CommandEncoder, inputs: &LookupInputs) {
        if !inputs.stale.contains(&true) {
            return;
        }
        let device = &ctx.device;
        let flags: Vec<u32> = inputs.stale.iter().map(|&s| s as u32).collect();
        let bytes: &[u8] = bytemuck::cast_slice(&flags);
        if bytes.len() as u64 > self.flags.size() {
            self.flags = super::buffers::storage_buffer(device, "march lookup flags", bytes);
        } else {
            ctx.queue.write_buffer(&self.flags, 0, bytes);
        }
        let mut extra = inputs.opv.extra_entries(EXTRA_BINDING);
        extra.extend(inputs.lookup.extra_entries(EXTRA_BINDING_2));
        let bind_group = bind_group_with(
            device,
            "march lookup",
            &self.layout,
            &[
                inputs.grid_buf.as_entire_binding(),
                wgpu::BindingResource::TextureView(inputs.ev_view),
                inputs.lights_buf.as_entire_binding(),
                inputs.opv.first(),
                inputs.lookup.first(),
                self.flags.as_entire_binding(),
            ],
            extra,
        );
        let r = inputs.spec.resolution;
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("march lookup"), timestamp_writes: None });
        pass.set_pipeline(&self.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(r.x.div_ceil(WORKGROUP_3D), r.y.div_ceil(WORKGROUP_3D), r.z.div_ceil(WORKGROUP_3D));
    }
}

//! The march's lookup volumes (`shaders/march_lookup.wgsl`): per light and cell, the mean
//! extinction along the cell centre's path to the light, which the march interpolates and
//! scales by each sample's own path length. Without them every sample would divide eight
//! optical depths by eight distances (or, for a sun, find eight exit distances and base-fog
//! depths) per light; with them it loads eight values.
//!
//! [`LookupBuilder`] is long-lived (pipeline and layout); the volumes live with the grid's
//! other per-light arrays (`resources`). The pipeline rebuilds them before a march or a bake
//! whenever the EV, an OPV, the lights or the grid parameters changed since the last build.

use super::layout::{bind_group_layout_with, bind_group_with, compute_pipeline, Slot, WORKGROUP_3D};
use super::opv_store::{OpvLayout, OpvVolumes, EXTRA_BINDING, EXTRA_BINDING_2};
use crate::scene::GridSpec;

/// What one build reads and writes.
pub struct LookupInputs<'a> {
    pub spec: GridSpec,
    pub light_count: usize,
    pub grid_buf: &'a wgpu::Buffer,
    pub ev_view: &'a wgpu::TextureView,
    pub lights_buf: &'a wgpu::Buffer,
    pub opv: &'a OpvVolumes,
    pub lookup: &'a OpvVolumes,
}

pub struct LookupBuilder {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
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
            ],
            extra,
        );
        let pipeline = compute_pipeline(device, "march lookup", super::shaders::march_lookup(&opv), &layout);
        Self { layout, pipeline }
    }

    /// Encodes the build of every light's lookup volume.
    pub fn encode(&self, device: &wgpu::Device, encoder: &mut wgpu::CommandEncoder, inputs: &LookupInputs) {
        if inputs.light_count == 0 {
            return;
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

//! The bake stage: the single-scattered radiance each cell emits (physics.md §10), for engines
//! that light fog without self-shadowing. It reads the EV and the OPVs the pipeline already
//! holds, through the ray march's own lookups (`shaders/bake.wgsl` is appended to the march's
//! sources), so the bake and the preview share one propagation and one set of light rules.

use super::gpu_types::{MarchParams, SurfaceGpu};
use super::layout::{compute_pipeline_entry, Slot, WORKGROUP_3D};
use super::opv_store::{OpvLayout, OpvVolumes, EXTRA_BINDING};
use super::readback::read_buffer;
use super::{GpuContext, GpuError};
use crate::scene::{GridSpec, Volume3};

/// The phase function the bake applies.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, serde::Serialize, serde::Deserialize)]
pub enum BakePhase {
    /// 1/(4π): exact for g = 0, the direction average otherwise; any camera.
    #[default]
    Isotropic,
    /// Henyey–Greenstein towards the project's camera: exact for that camera, any g.
    Camera,
}

impl BakePhase {
    pub fn name(self) -> &'static str {
        match self {
            BakePhase::Isotropic => "isotropic",
            BakePhase::Camera => "camera",
        }
    }
}

/// What one bake reads.
pub struct BakeInputs<'a> {
    pub spec: GridSpec,
    pub grid_buf: &'a wgpu::Buffer,
    pub ev_view: &'a wgpu::TextureView,
    pub lights_buf: &'a wgpu::Buffer,
    /// The march's lookup volumes (`march_lookup`).
    pub lookup: &'a OpvVolumes,
    pub surfaces: &'a [SurfaceGpu],
    /// The march's parameters: camera, albedo, anisotropy, surface count.
    pub params: MarchParams,
}

pub struct Baker {
    layout: wgpu::BindGroupLayout,
    pipeline: wgpu::ComputePipeline,
}

/// Bytes of one cell's output (RGB and a pad).
const CELL_BYTES: u64 = 16;

impl Baker {
    pub fn new(device: &wgpu::Device, opv: OpvLayout) -> Self {
        let entry = |binding: u32, ty: wgpu::BindingType| wgpu::BindGroupLayoutEntry {
            binding,
            visibility: wgpu::ShaderStages::COMPUTE,
            ty,
            count: None,
        };
        let storage = |read_only| wgpu::BindingType::Buffer {
            ty: wgpu::BufferBindingType::Storage { read_only },
            has_dynamic_offset: false,
            min_binding_size: None,
        };
        // The march's bindings the bake reads (0–4, 9), plus its output at 11.
        let mut extra = vec![entry(9, storage(true)), entry(11, storage(false))];
        extra.extend(opv.layout_entries(EXTRA_BINDING, true));
        let layout = super::layout::bind_group_layout_with(
            device,
            "bake",
            &[
                Slot::Uniform,
                Slot::Uniform,
                Slot::StorageTexture3dRead(wgpu::TextureFormat::R32Float),
                Slot::StorageRead,
                Slot::Opv { read_only: true },
            ],
            extra,
        );
        let pipeline = compute_pipeline_entry(device, "bake", super::shaders::bake(&opv), &layout, "bake");
        Self { layout, pipeline }
    }

    /// Bakes the emission of every cell, in slabs of z layers that fit one storage binding.
    pub fn bake(&self, ctx: &GpuContext, inputs: &BakeInputs, phase: BakePhase) -> Result<Volume3, GpuError> {
        let device = &ctx.device;
        let r = inputs.spec.resolution;
        let layer_bytes = r.x as u64 * r.y as u64 * CELL_BYTES;
        let cap = ctx.max_binding_bytes().min(64 << 20);
        let fitting = (cap / layer_bytes.max(1)).min(u32::MAX as u64) as u32 / WORKGROUP_3D * WORKGROUP_3D;
        let slab = fitting.max(WORKGROUP_3D).min(r.z.max(1));
        if layer_bytes * slab as u64 > ctx.max_binding_bytes() {
            return Err(GpuError::Limit {
                what: "the bake's output for one slab of z layers".into(),
                needed: layer_bytes * slab as u64,
                limit: ctx.max_binding_bytes(),
                adapter: ctx.adapter_summary(),
                suggestion: "use fewer cells along x and y".into(),
            });
        }
        let out = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("baked emission"),
            size: layer_bytes * slab as u64,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let surfaces = super::buffers::storage_buffer(device, "bake surfaces", bytemuck::cast_slice(inputs.surfaces));
        let mut data = Vec::with_capacity(inputs.spec.cell_count() as usize);
        let mut z0 = 0;
        while z0 < r.z {
            let layers = slab.min(r.z - z0);
            let mut params = inputs.params;
            if phase == BakePhase::Isotropic {
                params.anisotropy = 0.0;
            }
            params.row_offset = z0;
            params.size = [r.x, layers];
            params.surface_count = inputs.surfaces.len() as u32;
            let params_buf = {
                use wgpu::util::DeviceExt;
                device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
                    label: Some("bake params"),
                    contents: bytemuck::bytes_of(&params),
                    usage: wgpu::BufferUsages::UNIFORM,
                })
            };
            let mut entries = vec![
                wgpu::BindGroupEntry { binding: 0, resource: inputs.grid_buf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 1, resource: params_buf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(inputs.ev_view) },
                wgpu::BindGroupEntry { binding: 3, resource: inputs.lights_buf.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 4, resource: inputs.lookup.first() },
                wgpu::BindGroupEntry { binding: 9, resource: surfaces.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 11, resource: out.as_entire_binding() },
            ];
            entries.extend(inputs.lookup.extra_entries(EXTRA_BINDING));
            let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
                label: Some("bake"),
                layout: &self.layout,
                entries: &entries,
            });
            let mut encoder = device.create_command_encoder(&Default::default());
            {
                let mut pass = encoder
                    .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("bake"), timestamp_writes: None });
                pass.set_pipeline(&self.pipeline);
                pass.set_bind_group(0, &bind_group, &[]);
                pass.dispatch_workgroups(
                    r.x.div_ceil(WORKGROUP_3D),
                    r.y.div_ceil(WORKGROUP_3D),
                    layers.div_ceil(WORKGROUP_3D),
                );
            }
            ctx.queue.submit([encoder.finish()]);
            let cells = (r.x * r.y * layers) as usize;
            let texels: Vec<[f32; 4]> = read_buffer(ctx, &out, 0, cells)?;
            data.extend(texels.iter().map(|t| [t[0], t[1], t[2]]));
            z0 += layers;
        }
        Ok(Volume3::new(inputs.spec, data))
    }
}

//! The scene's long-lived GPU resources on one grid: the extinction volume, the brick maxima,
//! the grid and light uniforms and the optical-depth volumes, which every stage binds.

use super::binning;
use super::gpu_types::{GridParams, LightGpu};
use super::opv_store::{self, OpvLayout, OpvVolumes};
use super::GpuContext;
use crate::scene::GridSpec;

pub(super) struct GridResources {
    pub spec: GridSpec,
    pub light_count: usize,
    pub grid_buf: wgpu::Buffer,
    pub ev: wgpu::Texture,
    pub ev_view: wgpu::TextureView,
    pub lights_buf: wgpu::Buffer,
    /// The OPVs and the schemes' scratch array of the same size (see `opv_store`).
    pub opv: [OpvVolumes; 2],
    /// The march's lookup volumes, built from the OPVs (see `march_lookup`).
    pub lookup: OpvVolumes,
    /// Largest σ_t seen by samples in each 8³ brick, then each brick's detail (see
    /// `shaders/occupancy.wgsl`).
    pub brick_max: wgpu::Buffer,
}

impl GridResources {
    /// Resources for `light_count` lights on `spec`, their OPVs stored as `layout` says.
    pub fn new(device: &wgpu::Device, spec: GridSpec, light_count: usize, layout: OpvLayout) -> Self {
        let r = spec.resolution;
        let (ev, ev_view) = opv_store::volume_texture(
            device,
            "extinction volume",
            wgpu::Extent3d { width: r.x, height: r.y, depth_or_array_layers: r.z },
        );
        let grid_buf = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("grid params"),
            size: std::mem::size_of::<GridParams>() as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bricks = spec.resolution.map(|n| n.div_ceil(binning::BRICK));
        let brick_max = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("brick max extinction and detail"),
            size: (bricks.x * bricks.y * bricks.z) as u64 * 8,
            usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        let (lights_buf, opv, lookup) = light_buffers(device, layout, &spec, light_count);
        Self { spec, light_count, grid_buf, ev, ev_view, lights_buf, opv, lookup, brick_max }
    }

    /// Reallocates the per-light buffers for `light_count` lights, keeping the OPVs of the
    /// lights that remain (by index). The lookup volumes start empty: they are rebuilt.
    pub fn resize_lights(&mut self, ctx: &GpuContext, layout: OpvLayout, light_count: usize) {
        let device = &ctx.device;
        let (lights_buf, opv, lookup) = light_buffers(device, layout, &self.spec, light_count);
        let kept = self.light_count.min(light_count) as u64;
        if kept > 0 {
            let mut encoder = device.create_command_encoder(&Default::default());
            // Both: the sweep keeps each cell's mean in-box extinction in the second one.
            self.opv[0].copy_to(&mut encoder, 0, &opv[0], 0, kept);
            self.opv[1].copy_to(&mut encoder, 0, &opv[1], 0, kept);
            ctx.queue.submit([encoder.finish()]);
        }
        self.lights_buf = lights_buf;
        self.opv = opv;
        self.lookup = lookup;
        self.light_count = light_count;
    }

    /// Uploads the lights and the grid parameters every stage reads.
    pub fn write_uniforms(&self, queue: &wgpu::Queue, lights: &[LightGpu], grid: &GridParams) {
        if !lights.is_empty() {
            queue.write_buffer(&self.lights_buf, 0, bytemuck::cast_slice(lights));
        }
        queue.write_buffer(&self.grid_buf, 0, bytemuck::bytes_of(grid));
    }

    pub fn bytes(&self) -> u64 {
        self.spec.cell_count() * 4
            + self.grid_buf.size()
            + self.lights_buf.size()
            + self.opv.iter().map(OpvVolumes::bytes).sum::<u64>()
            + self.lookup.bytes()
            + self.brick_max.size()
    }
}

/// The lights buffer, the two OPV arrays (result and scratch) and the march's lookup array
/// for `light_count` lights.
fn light_buffers(
    device: &wgpu::Device,
    layout: OpvLayout,
    spec: &GridSpec,
    light_count: usize,
) -> (wgpu::Buffer, [OpvVolumes; 2], OpvVolumes) {
    let lights = light_count.max(1) as u64;
    let opv = ["optical depth A", "optical depth B"]
        .map(|label| OpvVolumes::new(device, layout, spec.resolution, lights, label));
    let lookup = OpvVolumes::new(device, layout, spec.resolution, lights, "march lookup");
    let lights_buf = device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("lights"),
        size: (light_count.max(1) * std::mem::size_of::<LightGpu>()) as u64,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    });
    (lights_buf, opv, lookup)
}

//! [`Baking`]: the light bake and its "as baked" view, one stage object over one set of
//! bindings.
//!
//! The bake (`shaders/bake.wgsl`) is the single-scattered radiance each cell emits
//! (physics.md §10), for engines that light fog without self-shadowing. It reads the EV and the
//! OPVs the pipeline already holds, through the ray march's own lookups (its WGSL is appended
//! to the march's sources), so the bake and the preview share one propagation and one set of
//! light rules. The "as baked" render (`shaders/as_baked.wgsl`) is the emission–absorption
//! image of a bake, what an engine that reads the baked density and emission shows, with no
//! lights; the editor shows it beside the lit preview so that what a bake loses (the view's
//! phase in isotropic mode, resolution) is visible before exporting.
//!
//! Both read the grid parameters, their own march parameters, the EV and the surfaces at the
//! march's binding numbers (0, 1, 2, 9): [`Bindings`] uploads the surfaces once per bake and
//! builds each bind group from them, the bake's once for all its slabs.

use super::buffers::storage_buffer;
use super::error::ErrorScope;
use super::frame_inputs::FrameInputs;
use super::gpu_types::MarchParams;
use super::layout::{bind_group_layout_with, compute_pipeline_entry, Slot, WORKGROUP_2D, WORKGROUP_3D};
use super::march::ImageTarget;
use super::opv_store::{OpvLayout, EXTRA_BINDING};
use super::outputs::{self, Image};
use super::readback::read_buffer;
use super::resources::GridResources;
use super::{GpuContext, GpuError};
use crate::scene::Volume3;

/// Steps per smallest cell edge along each ray of the "as baked" render.
pub const AS_BAKED_STEPS_PER_CELL: f32 = 8.0;

/// Bytes of one cell's bake output (RGB and a pad).
const CELL_BYTES: u64 = 16;

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

/// One compute pipeline and its bind group layout.
pub(super) struct Program {
    pub layout: wgpu::BindGroupLayout,
    pub pipeline: wgpu::ComputePipeline,
}

/// The bake and the "as baked" view: their pipelines, built on first use (most pipelines
/// never bake), and the image the view last drew.
#[derive(Default)]
pub(super) struct Baking {
    bake: Option<Program>,
    view: Option<Program>,
    image: Option<ImageTarget>,
}

/// What the bake, its view and the multiple-scattering source read from the scene, uploaded
/// once.
pub(super) struct Bindings<'a> {
    pub grid: &'a GridResources,
    surfaces: wgpu::Buffer,
    pub surface_count: u32,
    /// The march's parameters: camera, exposure, albedo, anisotropy.
    pub params: MarchParams,
}

impl<'a> Bindings<'a> {
    pub fn new(device: &wgpu::Device, grid: &'a GridResources, frame: &FrameInputs) -> Self {
        let surfaces = storage_buffer(device, "bake surfaces", bytemuck::cast_slice(frame.surfaces.as_slice()));
        Self { grid, surfaces, surface_count: frame.surfaces.len() as u32, params: frame.march }
    }

    /// A bind group of the bindings both read, with `params` at 1, plus `own`.
    pub fn bind_group(
        &self,
        device: &wgpu::Device,
        label: &str,
        program: &Program,
        params: &wgpu::Buffer,
        own: Vec<wgpu::BindGroupEntry>,
    ) -> wgpu::BindGroup {
        let mut entries = vec![
            wgpu::BindGroupEntry { binding: 0, resource: self.grid.grid_buf.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 1, resource: params.as_entire_binding() },
            wgpu::BindGroupEntry { binding: 2, resource: wgpu::BindingResource::TextureView(&self.grid.ev_view) },
            wgpu::BindGroupEntry { binding: 9, resource: self.surfaces.as_entire_binding() },
        ];
        entries.extend(own);
        device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some(label),
            layout: &program.layout,
            entries: &entries,
        })
    }
}

/// A compute layout entry at `binding`.
pub(super) fn entry(binding: u32, ty: wgpu::BindingType) -> wgpu::BindGroupLayoutEntry {
    wgpu::BindGroupLayoutEntry { binding, visibility: wgpu::ShaderStages::COMPUTE, ty, count: None }
}

pub(super) fn storage(read_only: bool) -> wgpu::BindingType {
    wgpu::BindingType::Buffer {
        ty: wgpu::BufferBindingType::Storage { read_only },
        has_dynamic_offset: false,
        min_binding_size: None,
    }
}

/// The pipeline of `code`'s `entry_point` over the bindings both read (0–2, 9), `slots` after
/// them from 3, and `own`.
pub(super) fn program(
    device: &wgpu::Device,
    (label, entry_point): (&str, &str),
    slots: &[Slot],
    mut own: Vec<wgpu::BindGroupLayoutEntry>,
    code: String,
) -> Program {
    let mut all = vec![Slot::Uniform, Slot::Uniform, Slot::StorageTexture3dRead(wgpu::TextureFormat::R32Float)];
    all.extend_from_slice(slots);
    own.push(entry(9, storage(true)));
    let layout = bind_group_layout_with(device, label, &all, own);
    let pipeline = compute_pipeline_entry(device, label, code, &layout, entry_point);
    Program { layout, pipeline }
}

pub(super) fn uniform(device: &wgpu::Device, label: &str, params: &MarchParams) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents: bytemuck::bytes_of(params),
        usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
    })
}

impl Baking {
    /// Drops the pipelines, built for an OPV layout the scene no longer has.
    pub fn rebuild(&mut self) {
        self.bake = None;
        self.view = None;
    }

    /// The radiance each cell of `grid` emits, W·m⁻³·sr⁻¹ per channel, baked from its EV and
    /// the lookup volumes of its OPVs (up to date) for `frame`'s scene.
    pub fn bake(
        &mut self,
        ctx: &GpuContext,
        layout: OpvLayout,
        grid: &GridResources,
        frame: &FrameInputs,
        phase: BakePhase,
        scatter: &wgpu::Buffer,
    ) -> Result<Volume3, GpuError> {
        let bindings = Bindings::new(&ctx.device, grid, frame);
        self.bake_with(ctx, layout, &bindings, phase, scatter)
    }

    /// [`bake`](Self::bake), then its emission–absorption render at the request's size with
    /// the same bindings, kept for [`read`](Self::read) and [`view`](Self::view).
    pub fn bake_and_render(
        &mut self,
        ctx: &GpuContext,
        layout: OpvLayout,
        grid: &GridResources,
        frame: &FrameInputs,
        phase: BakePhase,
        scatter: &wgpu::Buffer,
    ) -> Result<(), GpuError> {
        let (width, height) = (frame.request.width, frame.request.height);
        let bindings = Bindings::new(&ctx.device, grid, frame);
        let emission = self.bake_with(ctx, layout, &bindings, phase, scatter)?;
        let device = &ctx.device;
        let view = self.view.get_or_insert_with(|| {
            let image = |format| wgpu::BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format,
                view_dimension: wgpu::TextureViewDimension::D2,
            };
            // The march's image bindings (5, 6), plus the emission at 11.
            let own = vec![
                entry(5, image(wgpu::TextureFormat::Rgba32Float)),
                entry(6, image(wgpu::TextureFormat::Rgba8Unorm)),
                entry(11, storage(true)),
            ];
            program(device, ("as baked", "as_baked"), &[], own, super::shaders::as_baked(&layout))
        });
        let target = match self.image.take() {
            Some(t) if t.width == width && t.height == height => t,
            _ => ImageTarget::new(device, width, height),
        };
        let scope = ErrorScope::push(device);
        let result = render(ctx, view, &bindings, &emission, &target);
        scope.pop("as baked render")?;
        result?;
        self.image = Some(target);
        Ok(())
    }

    /// The bake's emission, checked to be finite.
    fn bake_with(
        &mut self,
        ctx: &GpuContext,
        layout: OpvLayout,
        bindings: &Bindings,
        phase: BakePhase,
        scatter: &wgpu::Buffer,
    ) -> Result<Volume3, GpuError> {
        let program = self.bake.get_or_insert_with(|| {
            // The march's lights (3) and lookup volumes (4 and beyond), the output at 11 and the
            // multiple-scattering moments at 14.
            let mut own = vec![entry(11, storage(false)), entry(14, storage(true))];
            own.extend(layout.layout_entries(EXTRA_BINDING, true));
            let slots = [Slot::StorageRead, Slot::Opv { read_only: true }];
            program(&ctx.device, ("bake", "bake"), &slots, own, super::shaders::bake(&layout))
        });
        let scope = ErrorScope::push(&ctx.device);
        let result = bake(ctx, program, bindings, phase, scatter);
        scope.pop("bake")?;
        let emission = result?;
        let bad = emission.data.iter().flatten().filter(|v| !v.is_finite()).count();
        if bad > 0 {
            return Err(GpuError::Invalid(format!(
                "the baked emission has {bad} values that are not finite numbers; check the lights' intensities \
                 and the medium for values beyond f32's range"
            )));
        }
        Ok(emission)
    }

    /// The last "as baked" image as linear HDR radiance.
    pub fn read(&self, ctx: &GpuContext) -> Result<Image, GpuError> {
        let target = self
            .image
            .as_ref()
            .ok_or_else(|| GpuError::Invalid("nothing rendered as baked yet: call render_as_baked first".into()))?;
        outputs::read_image(ctx, target)
    }

    /// The last "as baked" image, tone-mapped (rgba8unorm), and its size.
    pub fn view(&self) -> Option<(&wgpu::TextureView, [u32; 2])> {
        self.image.as_ref().map(|t| (&t.ldr_view, [t.width, t.height]))
    }

    /// Bytes of GPU memory its image holds.
    pub fn bytes(&self) -> u64 {
        self.image.as_ref().map_or(0, ImageTarget::bytes)
    }
}

/// Bakes the emission of every cell, in slabs of z layers that fit one storage binding.
fn bake(
    ctx: &GpuContext,
    program: &Program,
    bindings: &Bindings,
    phase: BakePhase,
    scatter: &wgpu::Buffer,
) -> Result<Volume3, GpuError> {
    let device = &ctx.device;
    let spec = bindings.grid.spec;
    let r = spec.resolution;
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
    let slab_params = |z0: u32| {
        let mut params = bindings.params;
        if phase == BakePhase::Isotropic {
            params.anisotropy = 0.0;
        }
        params.row_offset = z0;
        params.size = [r.x, slab.min(r.z - z0)];
        params.surface_count = bindings.surface_count;
        params
    };
    // Each slab waits for its readback, so one uniform, rewritten before each, serves all.
    let params_buf = uniform(device, "bake params", &slab_params(0));
    let grid = bindings.grid;
    let mut own = vec![
        wgpu::BindGroupEntry { binding: 3, resource: grid.lights_buf.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 4, resource: grid.lookup.first() },
        wgpu::BindGroupEntry { binding: 11, resource: out.as_entire_binding() },
        wgpu::BindGroupEntry { binding: 14, resource: scatter.as_entire_binding() },
    ];
    own.extend(grid.lookup.extra_entries(EXTRA_BINDING));
    let bind_group = bindings.bind_group(device, "bake", program, &params_buf, own);
    let mut data = Vec::with_capacity(spec.cell_count() as usize);
    let mut z0 = 0;
    while z0 < r.z {
        let layers = slab.min(r.z - z0);
        if z0 > 0 {
            ctx.queue.write_buffer(&params_buf, 0, bytemuck::bytes_of(&slab_params(z0)));
        }
        let mut encoder = device.create_command_encoder(&Default::default());
        {
            let mut pass = encoder
                .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("bake"), timestamp_writes: None });
            pass.set_pipeline(&program.pipeline);
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
    Ok(Volume3::new(spec, data))
}

/// Renders `emission` with the EV's density into `target`, as an engine shows a bake.
fn render(
    ctx: &GpuContext,
    program: &Program,
    bindings: &Bindings,
    emission: &Volume3,
    target: &ImageTarget,
) -> Result<(), GpuError> {
    let device = &ctx.device;
    let cells: Vec<[f32; 4]> = emission.data.iter().map(|e| [e[0], e[1], e[2], 0.0]).collect();
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
    let emission_buf = storage_buffer(device, "as baked emission", bytemuck::cast_slice(&cells));
    let step = emission.grid.cell_size().min_element() / AS_BAKED_STEPS_PER_CELL;
    let params = MarchParams {
        step,
        size: [target.width, target.height],
        row_offset: 0,
        surface_count: bindings.surface_count,
        ..bindings.params
    };
    let params_buf = uniform(device, "as baked params", &params);
    let own = vec![
        wgpu::BindGroupEntry { binding: 5, resource: wgpu::BindingResource::TextureView(&target.hdr_view) },
        wgpu::BindGroupEntry { binding: 6, resource: wgpu::BindingResource::TextureView(&target.ldr_view) },
        wgpu::BindGroupEntry { binding: 11, resource: emission_buf.as_entire_binding() },
    ];
    let bind_group = bindings.bind_group(device, "as baked", program, &params_buf, own);
    let mut encoder = device.create_command_encoder(&Default::default());
    {
        let mut pass = encoder
            .begin_compute_pass(&wgpu::ComputePassDescriptor { label: Some("as baked"), timestamp_writes: None });
        pass.set_pipeline(&program.pipeline);
        pass.set_bind_group(0, &bind_group, &[]);
        pass.dispatch_workgroups(target.width.div_ceil(WORKGROUP_2D), target.height.div_ceil(WORKGROUP_2D), 1);
    }
    ctx.queue.submit([encoder.finish()]);
    ctx.wait()
}

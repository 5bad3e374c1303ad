//! Terse construction of explicit bind group layouts and compute pipelines.

use wgpu::{BindGroupLayoutEntry, BindingType, ShaderStages};

/// The kinds of binding the pipeline's shaders use.
#[derive(Clone, Copy)]
pub enum Slot {
    Uniform,
    /// A uniform bound with a dynamic offset, one entry per dispatch.
    UniformDynamic,
    StorageRead,
    StorageWrite,
    /// A 3D f32 texture read with `textureLoad` only (no sampler, so r32float needs no
    /// filtering feature).
    Texture3d,
    /// A 3D f32 texture read through a filtering sampler (r32float needs FLOAT32_FILTERABLE).
    Texture3dFiltered,
    /// A sampler, filtering or not.
    Sampler {
        filtering: bool,
    },
    StorageTexture3d(wgpu::TextureFormat),
    /// A 3D storage texture read with `textureLoad` only (on llvmpipe cheaper than a sampled
    /// texture's loads).
    StorageTexture3dRead(wgpu::TextureFormat),
    StorageTexture2d(wgpu::TextureFormat),
    /// Texture 0 of an array of optical-depth volumes (see `opv_store`).
    Opv {
        read_only: bool,
    },
}

pub fn bind_group_layout(device: &wgpu::Device, label: &str, slots: &[Slot]) -> wgpu::BindGroupLayout {
    bind_group_layout_with(device, label, slots, Vec::new())
}

/// The layout entry of `slot` at `binding`, visible to compute shaders.
pub fn entry(binding: u32, slot: Slot) -> BindGroupLayoutEntry {
    BindGroupLayoutEntry {
        binding,
        visibility: ShaderStages::COMPUTE,
        ty: match slot {
            Slot::Uniform => BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            Slot::UniformDynamic => BindingType::Buffer {
                ty: wgpu::BufferBindingType::Uniform,
                has_dynamic_offset: true,
                min_binding_size: None,
            },
            Slot::StorageRead => BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: true },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            Slot::StorageWrite => BindingType::Buffer {
                ty: wgpu::BufferBindingType::Storage { read_only: false },
                has_dynamic_offset: false,
                min_binding_size: None,
            },
            Slot::Texture3d => BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: false },
                view_dimension: wgpu::TextureViewDimension::D3,
                multisampled: false,
            },
            Slot::Texture3dFiltered => BindingType::Texture {
                sample_type: wgpu::TextureSampleType::Float { filterable: true },
                view_dimension: wgpu::TextureViewDimension::D3,
                multisampled: false,
            },
            Slot::Sampler { filtering } => BindingType::Sampler(if filtering {
                wgpu::SamplerBindingType::Filtering
            } else {
                wgpu::SamplerBindingType::NonFiltering
            }),
            Slot::Opv { read_only } => super::opv_store::OpvLayout::binding_type(read_only),
            Slot::StorageTexture3d(format) => BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format,
                view_dimension: wgpu::TextureViewDimension::D3,
            },
            Slot::StorageTexture3dRead(format) => BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::ReadOnly,
                format,
                view_dimension: wgpu::TextureViewDimension::D3,
            },
            Slot::StorageTexture2d(format) => BindingType::StorageTexture {
                access: wgpu::StorageTextureAccess::WriteOnly,
                format,
                view_dimension: wgpu::TextureViewDimension::D2,
            },
        },
        count: None,
    }
}

/// [`bind_group_layout`] plus `extra` entries at their own binding numbers.
pub fn bind_group_layout_with(
    device: &wgpu::Device,
    label: &str,
    slots: &[Slot],
    extra: Vec<BindGroupLayoutEntry>,
) -> wgpu::BindGroupLayout {
    let mut entries: Vec<BindGroupLayoutEntry> =
        slots.iter().enumerate().map(|(i, &slot)| entry(i as u32, slot)).collect();
    entries.extend(extra);
    device.create_bind_group_layout(&wgpu::BindGroupLayoutDescriptor { label: Some(label), entries: &entries })
}

/// `LightGpu::kind`.
pub const LIGHT_POINT: u32 = 0;
pub const LIGHT_SPOT: u32 = 1;
pub const LIGHT_DIRECTIONAL: u32 = 2;
/// `MarchParams::policy`.
pub const POLICY_FIXED: u32 = 0;
pub const POLICY_TWO_LEVEL: u32 = 1;
pub const POLICY_ADAPTIVE: u32 = 2;
/// `SurfaceGpu::kind`: an axis-aligned box, or the ground plane y = min.y facing +y.
pub const SURFACE_BOX: u32 = 0;
pub const SURFACE_GROUND: u32 = 1;

/// Workgroup edge of the shaders over image pixels or a volume's planes (march, slice, the
/// directional sweep): `WORKGROUP_2D`² threads.
pub const WORKGROUP_2D: u32 = 8;
/// Workgroup edge of the shaders over whole volumes (occupancy, Giroud, exact): `WORKGROUP_3D`³
/// threads; the exact and analytic schemes dispatch slabs of this many layers.
pub const WORKGROUP_3D: u32 = 4;
/// Workgroup of the analytic scheme: a row of cells along x.
pub const WORKGROUP_ROW: u32 = 64;
/// Threads per workgroup of `propagate_sweep.wgsl`. llvmpipe pays a fixed cost per
/// workgroup, so larger groups amortise it over more cells.
pub const SWEEP_WORKGROUP: u32 = 256;

/// Constants the Rust side and the shaders share, written once here for WGSL.
pub fn shared_constants() -> String {
    use crate::sun_table as sun;
    format!(
        "// Generated from the Rust constants (src/gpu/layout.rs).\n\
         const PI: f32 = {:?};\n\
         const LIGHT_POINT: u32 = {}u;\n\
         const LIGHT_SPOT: u32 = {}u;\n\
         const LIGHT_DIRECTIONAL: u32 = {}u;\n\
         const POLICY_FIXED: u32 = {}u;\n\
         const POLICY_TWO_LEVEL: u32 = {}u;\n\
         const POLICY_ADAPTIVE: u32 = {}u;\n\
         const SURFACE_BOX: u32 = {}u;\n\
         const SURFACE_GROUND: u32 = {}u;\n\
         const WORKGROUP_2D: u32 = {}u;\n\
         const WORKGROUP_3D: u32 = {}u;\n\
         const WORKGROUP_ROW: u32 = {}u;\n\
         const SWEEP_WORKGROUP: u32 = {}u;\n\
         const MAX_HEIGHT_EXPONENT: f32 = {:?};\n\
         const BRICK: u32 = {}u;\n\
         const SUN_NU: u32 = {}u;\n\
         const SUN_NV: u32 = {}u;\n\
         const SUN_U_SCALE: f32 = {:?};\n\
         const SUN_K_SCALE: f32 = {:?};\n\
         const SUN_GAMMA_MIN: f32 = {:e};\n\
         const SUN_FAR_SKIP: f32 = {:?};\n\
         const SUN_SHORT_RATIO: f32 = {:?};\n\
         const GLOW_NT: u32 = {}u;\n\
         const GLOW_NTHETA: u32 = {}u;\n\
         const GLOW_T_MAX: f32 = {:?};\n\
         const SPEC_NT: u32 = {}u;\n\
         const SPEC_NTHETA: u32 = {}u;\n\
         const SPEC_NN: u32 = {}u;\n\
         const SPEC_N_MAX: f32 = {:?};\n",
        std::f32::consts::PI,
        LIGHT_POINT,
        LIGHT_SPOT,
        LIGHT_DIRECTIONAL,
        POLICY_FIXED,
        POLICY_TWO_LEVEL,
        POLICY_ADAPTIVE,
        SURFACE_BOX,
        SURFACE_GROUND,
        WORKGROUP_2D,
        WORKGROUP_3D,
        WORKGROUP_ROW,
        SWEEP_WORKGROUP,
        crate::scene::MAX_HEIGHT_EXPONENT as f32,
        super::binning::BRICK,
        sun::GPU_TABLE_SIZE,
        sun::GPU_TABLE_SIZE,
        sun::U_SCALE,
        sun::K_SCALE,
        sun::GAMMA_MIN,
        sun::FAR_SKIP,
        sun::SHORT_RATIO,
        crate::surface_table::GLOW_NT,
        crate::surface_table::GLOW_NTHETA,
        crate::surface_table::GLOW_T_MAX,
        crate::surface_table::SPEC_NT,
        crate::surface_table::SPEC_NTHETA,
        crate::surface_table::SPEC_NN,
        crate::surface_table::SPEC_N_MAX,
    )
}

/// A compute pipeline from finished WGSL (see `shaders`), entry point `main`.
pub fn compute_pipeline(
    device: &wgpu::Device,
    label: &str,
    code: String,
    layout: &wgpu::BindGroupLayout,
) -> wgpu::ComputePipeline {
    compute_pipeline_entry(device, label, code, layout, "main")
}

/// [`compute_pipeline`] with another entry point, for a stage that shares another's sources.
pub fn compute_pipeline_entry(
    device: &wgpu::Device,
    label: &str,
    code: String,
    layout: &wgpu::BindGroupLayout,
    entry: &str,
) -> wgpu::ComputePipeline {
    compute_pipeline_with(device, label, code, layout, entry, &[])
}

/// [`compute_pipeline_entry`] with values for the shader's `override` constants.
pub fn compute_pipeline_with(
    device: &wgpu::Device,
    label: &str,
    code: String,
    layout: &wgpu::BindGroupLayout,
    entry: &str,
    constants: &[(&str, f64)],
) -> wgpu::ComputePipeline {
    let module = device.create_shader_module(wgpu::ShaderModuleDescriptor {
        label: Some(label),
        source: wgpu::ShaderSource::Wgsl(code.into()),
    });
    let pipeline_layout = device.create_pipeline_layout(&wgpu::PipelineLayoutDescriptor {
        label: Some(label),
        bind_group_layouts: &[Some(layout)],
        immediate_size: 0,
    });
    device.create_compute_pipeline(&wgpu::ComputePipelineDescriptor {
        label: Some(label),
        layout: Some(&pipeline_layout),
        module: &module,
        entry_point: Some(entry),
        compilation_options: wgpu::PipelineCompilationOptions { constants, ..Default::default() },
        cache: None,
    })
}

/// A bind group whose entries are the given resources in binding order.
pub fn bind_group(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    resources: &[wgpu::BindingResource<'_>],
) -> wgpu::BindGroup {
    bind_group_with(device, label, layout, resources, Vec::new())
}

/// [`bind_group`] plus `extra` entries at their own binding numbers.
pub fn bind_group_with(
    device: &wgpu::Device,
    label: &str,
    layout: &wgpu::BindGroupLayout,
    resources: &[wgpu::BindingResource<'_>],
    extra: Vec<wgpu::BindGroupEntry<'_>>,
) -> wgpu::BindGroup {
    let mut entries: Vec<wgpu::BindGroupEntry> = resources
        .iter()
        .enumerate()
        .map(|(i, r)| wgpu::BindGroupEntry { binding: i as u32, resource: r.clone() })
        .collect();
    entries.extend(extra);
    device.create_bind_group(&wgpu::BindGroupDescriptor { label: Some(label), layout, entries: &entries })
}

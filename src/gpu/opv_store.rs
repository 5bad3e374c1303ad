//! Optical-depth storage: every light's volume in 3D textures, as many as memory holds.
//!
//! Each light's OPV (and, in the scratch array, the sweep's mean in-box extinction or the
//! Jacobi scheme's destination) is an r32float volume of the grid's size. The volumes of
//! consecutive lights are stacked along z in one 3D texture (then, for thin grids with many
//! lights, in rows along y), as many as the device's 3D edge and [`MAX_TEXTURE_BYTES`] allow;
//! further lights go into further textures, each its own binding. A texture, unlike a storage buffer, is not bounded by the storage-binding size
//! (128 MiB on llvmpipe), so with a handful of texture bindings the lights a scene can have
//! are bounded by the device's memory, which `FogPipeline::check_sizes` checks.
//!
//! Shaders reach the volumes only through the generated helpers `NAME_load(light, cell)` and,
//! for read-write arrays, `NAME_store(light, cell, v)` ([`OpvLayout::wgsl`]). Texture 0 keeps
//! the binding number the stage's array always had; texture `k ≥ 1` is bound at
//! `extra_base + k − 1`. A stage is built for as many textures as the scene fills, since every
//! extra one adds a branch to each read; unused bindings hold a 1-texel placeholder. Lights per
//! texture follow from texture 0's depth, so one pipeline serves every grid.

use glam::UVec3;
use wgpu::{BindGroupEntry, BindGroupLayoutEntry, BindingType, ShaderStages};

/// First binding of the extra textures of a stage's first OPV-like array.
pub const EXTRA_BINDING: u32 = 100;
/// First binding of the extra textures of a stage's second array (the sweep's mean in-box
/// extinction, the Jacobi scheme's destination).
pub const EXTRA_BINDING_2: u32 = 120;
/// Most textures per array.
pub const MAX_TEXTURES: u32 = 16;
/// Most bytes of one texture: llvmpipe addresses a texture with signed 32-bit offsets, and
/// some of its versions refuse textures above 1 GiB.
pub const MAX_TEXTURE_BYTES: u64 = 1 << 30;

/// How OPV arrays are stored on one device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OpvLayout {
    /// Texture bindings per array.
    pub textures: u32,
    /// Deepest texture (the device's 3D edge).
    pub max_depth: u32,
    /// Most lights stacked in one texture (below what depth and size allow only in tests,
    /// which use it to cross texture boundaries on small scenes).
    pub lights_per_texture: u32,
    /// Whether lights are also stacked in rows along y (more lights than fit along z): the
    /// helpers then find a light's place with divisions, which the common case avoids.
    pub rows: bool,
}

impl OpvLayout {
    /// As many textures as the device's storage-texture bindings per stage leave for the
    /// sweep's two arrays and for the march's one beside its two image targets.
    pub fn for_limits(limits: &wgpu::Limits) -> Self {
        let storage = limits.max_storage_textures_per_shader_stage;
        let textures = (storage / 2).min(storage.saturating_sub(2)).clamp(1, MAX_TEXTURES);
        Self { textures, max_depth: limits.max_texture_dimension_3d.max(1), lights_per_texture: u32::MAX, rows: false }
    }

    /// At most `lights` lights per texture: a setting for tests, which makes small scenes span
    /// several textures.
    pub fn with_lights_per_texture(limits: &wgpu::Limits, lights: u32) -> Self {
        Self { lights_per_texture: lights.max(1), ..Self::for_limits(limits) }
    }

    /// Lights one texture holds on a grid of `res` cells (at least one): stacked along z,
    /// then in rows of [`along_z`](Self::along_z) along y, within the 3D edge and
    /// [`MAX_TEXTURE_BYTES`]; a whole number of rows when there is more than one.
    pub fn per_texture(&self, res: UVec3) -> u32 {
        let cell_bytes = res.as_u64vec3().element_product().max(1) * 4;
        let kz = (self.max_depth / res.z.max(1)).max(1) as u64;
        let ky = (self.max_depth / res.y.max(1)).max(1) as u64;
        let by_size = MAX_TEXTURE_BYTES / cell_bytes;
        let n = (kz * ky).min(by_size).min(self.lights_per_texture as u64).clamp(1, u32::MAX as u64);
        (if n > kz { n / kz * kz } else { n }) as u32
    }

    /// Lights stacked along z in one row of a texture.
    pub fn along_z(&self, res: UVec3) -> u32 {
        self.per_texture(res).min((self.max_depth / res.z.max(1)).max(1))
    }

    /// Whether `lights` lights on a grid of `res` cells fill more than one row of a texture.
    pub fn needs_rows(&self, res: UVec3, lights: u64) -> bool {
        lights > self.along_z(res) as u64 && self.per_texture(res) > self.along_z(res)
    }

    /// Textures `lights` lights need on a grid of `res` cells.
    pub fn textures_for(&self, res: UVec3, lights: u64) -> u64 {
        lights.max(1).div_ceil(self.per_texture(res) as u64)
    }

    /// Lights one array can hold on a grid of `res` cells.
    pub fn capacity_lights(&self, res: UVec3) -> u64 {
        self.per_texture(res) as u64 * self.textures as u64
    }

    /// WGSL declaring array `name` (texture 0 at `binding`, the rest from `extra_base`) and its
    /// helpers `name_load(light: u32, c: vec3u) -> f32` and, when `read_write`,
    /// `name_store(light: u32, c: vec3u, v: f32)`. Arrays are storage textures, read-only
    /// where not written (on llvmpipe a sampled texture's `textureLoad` is slower). The
    /// including shader declares `grid: GridParams`.
    pub fn wgsl(&self, name: &str, binding: u32, extra_base: u32, read_write: bool) -> String {
        let ty =
            if read_write { "texture_storage_3d<r32float, read_write>" } else { "texture_storage_3d<r32float, read>" };
        let mut s = format!(
            "// `{name}`: light-major optical-depth volumes in {} textures (src/gpu/opv_store.rs).\n",
            self.textures
        );
        for k in 0..self.textures {
            let b = if k == 0 { binding } else { extra_base + k - 1 };
            s += &format!("@group(0) @binding({b}) var {name}_{k}: {ty};\n");
        }
        let cases = |body: &dyn Fn(u32) -> String| -> String {
            if self.textures == 1 && !self.rows {
                return format!("    let at = vec3u(c.xy, c.z + light * grid.dims.z);\n    {}\n", body(0));
            }
            // Texture 0 is full when there are others; its size gives the lights per row and
            // per texture. Float divisions: integer division is scalarised per lane on SIMD CPUs.
            let mut s = format!(
                "    let d0 = textureDimensions({name}_0);
    let kz = max(u32(f32(d0.z) / f32(grid.dims.z) + 0.5), 1u);
    let per = kz * max(u32(f32(d0.y) / f32(grid.dims.y) + 0.5), 1u);
    let k = u32((f32(light) + 0.5) / f32(per));
    let s = light - k * per;
    let row = u32((f32(s) + 0.5) / f32(kz));
    let at = vec3u(c.x, c.y + row * grid.dims.y, c.z + (s - row * kz) * grid.dims.z);
"
            );
            if self.textures == 1 {
                return s + &format!("    {}\n", body(0));
            }
            s += "    switch k {\n";
            for k in 1..self.textures {
                s += &format!("        case {k}u: {{ {} }}\n", body(k));
            }
            s += &format!("        default: {{ {} }}\n    }}\n", body(0));
            s
        };
        s += &format!(
            "fn {name}_load(light: u32, c: vec3u) -> f32 {{\n{}}}\n",
            cases(&|k| format!("return textureLoad({name}_{k}, at).x;"))
        );
        if read_write {
            s += &format!(
                "fn {name}_store(light: u32, c: vec3u, v: f32) {{\n{}}}\n",
                cases(&|k| format!("textureStore({name}_{k}, at, vec4f(v, 0.0, 0.0, 0.0));"))
            );
        }
        s
    }

    /// The binding type of each texture of an array.
    pub fn binding_type(read_only: bool) -> BindingType {
        BindingType::StorageTexture {
            access: if read_only {
                wgpu::StorageTextureAccess::ReadOnly
            } else {
                wgpu::StorageTextureAccess::ReadWrite
            },
            format: wgpu::TextureFormat::R32Float,
            view_dimension: wgpu::TextureViewDimension::D3,
        }
    }

    /// Layout entries of textures 1.. of an array (texture 0 is in the stage's own list).
    pub fn layout_entries(&self, extra_base: u32, read_only: bool) -> Vec<BindGroupLayoutEntry> {
        (1..self.textures)
            .map(|k| BindGroupLayoutEntry {
                binding: extra_base + k - 1,
                visibility: ShaderStages::COMPUTE,
                ty: Self::binding_type(read_only),
                count: None,
            })
            .collect()
    }
}

/// An r32float 3D texture and its view that shaders write, read and sample, and copies read
/// and write: the EV's and the OPVs' storage.
pub fn volume_texture(device: &wgpu::Device, label: &str, size: wgpu::Extent3d) -> (wgpu::Texture, wgpu::TextureView) {
    let texture = device.create_texture(&wgpu::TextureDescriptor {
        label: Some(label),
        size,
        mip_level_count: 1,
        sample_count: 1,
        dimension: wgpu::TextureDimension::D3,
        format: wgpu::TextureFormat::R32Float,
        usage: wgpu::TextureUsages::STORAGE_BINDING
            | wgpu::TextureUsages::TEXTURE_BINDING
            | wgpu::TextureUsages::COPY_SRC
            | wgpu::TextureUsages::COPY_DST,
        view_formats: &[],
    });
    let view = texture.create_view(&Default::default());
    (texture, view)
}

/// One array of per-light volumes on the GPU.
#[derive(Clone)]
pub struct OpvVolumes {
    /// `layout.textures` textures; those past the data are 1-texel placeholders.
    textures: Vec<(wgpu::Texture, wgpu::TextureView)>,
    res: UVec3,
    per_texture: u32,
    along_z: u32,
    lights: u64,
}

impl OpvVolumes {
    /// An array of `lights` volumes of `res` cells (at least one), zeroed.
    pub fn new(device: &wgpu::Device, layout: OpvLayout, res: UVec3, lights: u64, label: &str) -> Self {
        let lights = lights.max(1);
        let per_texture = layout.per_texture(res);
        let along_z = layout.along_z(res);
        let textures = (0..layout.textures as u64)
            .map(|k| {
                let held = lights.saturating_sub(k * per_texture as u64).min(per_texture as u64) as u32;
                let size = if held == 0 {
                    wgpu::Extent3d { width: 1, height: 1, depth_or_array_layers: 1 }
                } else {
                    let rows = held.div_ceil(along_z);
                    wgpu::Extent3d {
                        width: res.x,
                        height: res.y * rows,
                        depth_or_array_layers: res.z * held.min(along_z),
                    }
                };
                volume_texture(device, label, size)
            })
            .collect();
        Self { textures, res, per_texture, along_z, lights }
    }

    /// Texture 0, for the stage's own binding list.
    pub fn first(&self) -> wgpu::BindingResource<'_> {
        wgpu::BindingResource::TextureView(&self.textures[0].1)
    }

    /// Bind group entries of textures 1.. from `extra_base`.
    pub fn extra_entries(&self, extra_base: u32) -> Vec<BindGroupEntry<'_>> {
        self.textures[1..]
            .iter()
            .enumerate()
            .map(|(k, (_, view))| BindGroupEntry {
                binding: extra_base + k as u32,
                resource: wgpu::BindingResource::TextureView(view),
            })
            .collect()
    }

    /// Lights the array holds.
    pub fn lights(&self) -> u64 {
        self.lights
    }

    pub fn bytes(&self) -> u64 {
        self.textures
            .iter()
            .map(|(t, _)| t.width() as u64 * t.height() as u64 * t.depth_or_array_layers() as u64 * 4)
            .sum()
    }

    /// The texture holding `light` and the copy origin of its volume there.
    fn place(&self, light: u64) -> (&wgpu::Texture, wgpu::Origin3d) {
        let (k, s) = (light / self.per_texture as u64, (light % self.per_texture as u64) as u32);
        let (row, z) = (s / self.along_z, s % self.along_z);
        (&self.textures[k as usize].0, wgpu::Origin3d { x: 0, y: row * self.res.y, z: z * self.res.z })
    }

    fn extent(&self) -> wgpu::Extent3d {
        wgpu::Extent3d { width: self.res.x, height: self.res.y, depth_or_array_layers: self.res.z }
    }

    /// Copies the volumes of lights `start..start + count` of `self` to `dst` (same grid) from
    /// light `dst_start` on.
    pub fn copy_to(
        &self,
        encoder: &mut wgpu::CommandEncoder,
        start: u64,
        dst: &OpvVolumes,
        dst_start: u64,
        count: u64,
    ) {
        for l in 0..count.min(self.lights.saturating_sub(start)).min(dst.lights.saturating_sub(dst_start)) {
            let (src, from) = self.place(start + l);
            let (to_tex, to) = dst.place(dst_start + l);
            encoder.copy_texture_to_texture(
                wgpu::TexelCopyTextureInfo {
                    texture: src,
                    mip_level: 0,
                    origin: from,
                    aspect: wgpu::TextureAspect::All,
                },
                wgpu::TexelCopyTextureInfo {
                    texture: to_tex,
                    mip_level: 0,
                    origin: to,
                    aspect: wgpu::TextureAspect::All,
                },
                self.extent(),
            );
        }
    }

    /// Reads light `light`'s volume back, x fastest.
    pub fn read(&self, ctx: &super::GpuContext, light: u64) -> Result<Vec<f32>, super::GpuError> {
        let (texture, origin) = self.place(light);
        super::readback::read_texture_region(ctx, texture, origin, self.res.to_array(), 4)
    }
}

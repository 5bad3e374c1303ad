//! Adaptive image-space sampling: march a tenth of the rays for the same image.
//!
//! The fog in front of smooth geometry varies slowly across the image, so most pixels can be
//! interpolated from rays a few pixels apart. The march first takes every pixel's geometry
//! class (which face of which surface its ray meets first, and which side of the grid box's
//! silhouette it is on; `shaders/march.wgsl` `classify`), then marches a lattice of rays
//! [`LATTICE`] pixels apart. Each refinement level halves the lattice's stride
//! (`shaders/image_refine.wgsl`): a cell whose corners agree within the tolerance, whose
//! pixels share one class and that holds no light's epipole (the screen position of a point
//! or spot light, or of the sun's direction, where in-scattering peaks) gets its new points
//! interpolated; the new points of every other cell are gathered into a compact list and
//! marched (`main_list`). Gathering keeps the rays of one SIMD group neighbours on screen, so
//! that they take similar paths through the fog; marching them in place at scattered pixels
//! makes neighbouring lanes diverge. After the last level every pixel holds a marched or
//! interpolated value, and `resolve` writes the image.
//!
//! Everything runs on the GPU but the count of each level's list, read back between levels
//! so that the march of a list can be spread over frames in bands like the per-pixel march.
//!
//! [`ImageSampling::PerPixel`] keeps one ray per pixel, for comparison.

use super::layout::{bind_group_layout, compute_pipeline_with, Slot, WORKGROUP_2D};
use super::readback::read_buffer;
use super::{GpuContext, GpuError};
use bytemuck::{Pod, Zeroable};

/// Stride, in pixels, of the first lattice of rays: features narrower than this between
/// four agreeing rays of one geometry class can be missed.
pub const LATTICE: u32 = 8;

/// Default of [`ImageSampling::Adaptive`]'s tolerance: a cell is interpolated where its
/// corners' spread is at most 2 % of their mean radiance plus the image's mean radiance.
pub const DEFAULT_TOLERANCE: f32 = 0.005;

/// Epipoles the refinement keeps refined to single pixels (the first lights' in view).
pub const MAX_EPIPOLES: usize = 8;

/// How the march chooses the rays it marches.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum ImageSampling {
    /// One ray through every pixel's centre.
    PerPixel,
    /// A lattice refined where rays disagree by more than `tolerance` (see the module doc;
    /// default [`DEFAULT_TOLERANCE`]), the rest interpolated.
    Adaptive { tolerance: f32 },
}

impl Default for ImageSampling {
    fn default() -> Self {
        Self::Adaptive { tolerance: DEFAULT_TOLERANCE }
    }
}

impl ImageSampling {
    /// The name the command line and the editor use: `per-pixel` or `adaptive`.
    pub fn name(&self) -> &'static str {
        match self {
            Self::PerPixel => "per-pixel",
            Self::Adaptive { .. } => "adaptive",
        }
    }

    /// Parses [`Self::name`] (the adaptive one at its default tolerance).
    pub fn parse(name: &str) -> Result<Self, String> {
        match name {
            "per-pixel" => Ok(Self::PerPixel),
            "adaptive" => Ok(Self::default()),
            other => Err(format!("unknown image sampling \"{other}\": use per-pixel or adaptive")),
        }
    }
}

/// `RefineParams` of `shaders/image_refine.wgsl`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Pod, Zeroable)]
pub struct RefineParams {
    pub padded: [u32; 2],
    pub stride: u32,
    pub tolerance: f32,
    pub epipole_count: u32,
    pub _pad: [u32; 3],
    pub epipoles: [[f32; 4]; MAX_EPIPOLES],
}

/// Byte distance of the levels' parameters in their uniform buffer (dynamic offsets).
const PARAMS_SLOT: u64 = 256;
/// Refinement levels from [`LATTICE`] down to single pixels.
pub const LEVELS: u32 = LATTICE.trailing_zeros();

/// The image padded right and below to whole cells of the lattice.
pub fn padded_size(width: u32, height: u32) -> [u32; 2] {
    let pad = |n: u32| (n.max(2) - 1).div_ceil(LATTICE) * LATTICE + 1;
    [pad(width), pad(height)]
}

/// Rays of the first lattice over a padded image.
pub fn lattice_rays(padded: [u32; 2]) -> u32 {
    ((padded[0] - 1) / LATTICE + 1) * ((padded[1] - 1) / LATTICE + 1)
}

/// The per-image buffers of adaptive sampling (owned by the image target).
pub struct SamplingBuffers {
    pub padded: [u32; 2],
    /// Radiance and opacity of every padded pixel, marched or interpolated.
    pub samples: wgpu::Buffer,
    /// Geometry classes, the ray list and the cell flags (`shaders/march.wgsl` `work`).
    pub work: wgpu::Buffer,
    /// The list's length and the image's mean radiance.
    stats: wgpu::Buffer,
    params: wgpu::Buffer,
    bind_group: wgpu::BindGroup,
}

impl SamplingBuffers {
    pub fn new(device: &wgpu::Device, sampler: &ImageSampler, width: u32, height: u32) -> Self {
        let padded = padded_size(width, height);
        let pixels = padded[0] as u64 * padded[1] as u64;
        let storage = |label: &str, size: u64| {
            device.create_buffer(&wgpu::BufferDescriptor {
                label: Some(label),
                size,
                usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                mapped_at_creation: false,
            })
        };
        let samples = storage("image samples", pixels * 16);
        let work = storage("image sampling work", (pixels * 2 + pixels / 4 + 64) * 4);
        let stats = storage("image sampling stats", 16);
        let params = device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("image refinement params"),
            size: PARAMS_SLOT * LEVELS as u64,
            usage: wgpu::BufferUsages::UNIFORM | wgpu::BufferUsages::COPY_DST,
            mapped_at_creation: false,
        });
        let bind_group = device.create_bind_group(&wgpu::BindGroupDescriptor {
            label: Some("image refinement"),
            layout: &sampler.layout,
            entries: &[
                wgpu::BindGroupEntry {
                    binding: 0,
                    resource: wgpu::BindingResource::Buffer(wgpu::BufferBinding {
                        buffer: &params,
                        offset: 0,
                        size: wgpu::BufferSize::new(std::mem::size_of::<RefineParams>() as u64),
                    }),
                },
                wgpu::BindGroupEntry { binding: 1, resource: samples.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 2, resource: work.as_entire_binding() },
                wgpu::BindGroupEntry { binding: 3, resource: stats.as_entire_binding() },
            ],
        });
        Self { padded, samples, work, stats, params, bind_group }
    }

    pub fn bytes(&self) -> u64 {
        self.samples.size() + self.work.size() + self.stats.size() + self.params.size()
    }

    /// Writes the parameters of every level.
    pub fn write_params(&self, queue: &wgpu::Queue, tolerance: f32, epipoles: &[[f32; 2]]) {
        for level in 0..LEVELS {
            let mut p = RefineParams {
                padded: self.padded,
                stride: LATTICE >> level,
                tolerance,
                epipole_count: epipoles.len().min(MAX_EPIPOLES) as u32,
                _pad: [0; 3],
                epipoles: [[0.0; 4]; MAX_EPIPOLES],
            };
            for (slot, e) in p.epipoles.iter_mut().zip(epipoles) {
                *slot = [e[0], e[1], 0.0, 0.0];
            }
            queue.write_buffer(&self.params, level as u64 * PARAMS_SLOT, bytemuck::bytes_of(&p));
        }
    }
}

/// The refinement's pipelines (long-lived; the per-image data is in [`SamplingBuffers`]).
pub struct ImageSampler {
    layout: wgpu::BindGroupLayout,
    reference: wgpu::ComputePipeline,
    cells: wgpu::ComputePipeline,
    points: wgpu::ComputePipeline,
}

impl ImageSampler {
    pub fn new(device: &wgpu::Device) -> Self {
        let layout = bind_group_layout(
            device,
            "image refinement",
            &[Slot::UniformDynamic, Slot::StorageWrite, Slot::StorageWrite, Slot::StorageWrite],
        );
        let code = super::shaders::image_refine();
        let build = |entry: &str| compute_pipeline_with(device, "image refinement", code.clone(), &layout, entry, &[]);
        Self { reference: build("reference"), cells: build("cells_pass"), points: build("points_pass"), layout }
    }

    /// Refines the lattice of stride `LATTICE >> level` to half that stride, and returns the
    /// rays it lists to march. Submits and waits: the march of the list needs the count.
    pub fn refine(&self, ctx: &GpuContext, buffers: &SamplingBuffers, level: u32) -> Result<u32, GpuError> {
        let stride = LATTICE >> level;
        let [pw, ph] = buffers.padded;
        let mut encoder = ctx.device.create_command_encoder(&Default::default());
        encoder.clear_buffer(&buffers.stats, 0, Some(4));
        {
            let mut pass = encoder.begin_compute_pass(&wgpu::ComputePassDescriptor {
                label: Some("image refinement"),
                timestamp_writes: None,
            });
            pass.set_bind_group(0, &buffers.bind_group, &[(level as u64 * PARAMS_SLOT) as u32]);
            if level == 0 {
                pass.set_pipeline(&self.reference);
                pass.dispatch_workgroups(1, 1, 1);
            }
            let cells = [(pw - 1) / stride, (ph - 1) / stride];
            pass.set_pipeline(&self.cells);
            pass.dispatch_workgroups(cells[0].div_ceil(WORKGROUP_2D), cells[1].div_ceil(WORKGROUP_2D), 1);
            let half = stride / 2;
            let points = [(pw - 1) / half + 1, (ph - 1) / half + 1];
            pass.set_pipeline(&self.points);
            pass.dispatch_workgroups(points[0].div_ceil(WORKGROUP_2D), points[1].div_ceil(WORKGROUP_2D), 1);
        }
        ctx.queue.submit([encoder.finish()]);
        let count: Vec<u32> = read_buffer(ctx, &buffers.stats, 0, 1)?;
        Ok(count[0])
    }
}

/// Screen positions (pixels, in a `width`×`height` image) of the lights' epipoles that lie
/// in front of the camera and near the image: a point or spot light's position, a sun's
/// direction towards it. The camera is `MarchParams`' origin and its forward, right and up
/// vectors (a ray through pixel centre `(x, y)` runs along
/// forward + right·sx + up·sy, sx = (x + ½)/width·2 − 1, sy = 1 − (y + ½)/height·2).
pub fn epipoles(
    params: &super::gpu_types::MarchParams,
    lights: &[super::gpu_types::LightGpu],
    width: u32,
    height: u32,
) -> Vec<[f32; 2]> {
    use glam::Vec3;
    let (o, f, r, u) =
        (Vec3::from(params.origin), Vec3::from(params.forward), Vec3::from(params.right), Vec3::from(params.up));
    let mut out = Vec::new();
    for l in lights {
        let d = if l.kind == super::layout::LIGHT_DIRECTIONAL {
            -Vec3::from(l.direction)
        } else {
            Vec3::from(l.position) - o
        };
        let a = d.dot(f) / f.length_squared();
        if a.is_nan() || a <= 0.0 || r.length_squared() == 0.0 || u.length_squared() == 0.0 {
            continue;
        }
        let sx = d.dot(r) / (a * r.length_squared());
        let sy = d.dot(u) / (a * u.length_squared());
        let x = (sx + 1.0) * 0.5 * width as f32 - 0.5;
        let y = (1.0 - sy) * 0.5 * height as f32 - 0.5;
        let margin = LATTICE as f32 * 2.0;
        if x.is_finite()
            && y.is_finite()
            && (-margin..width as f32 + margin).contains(&x)
            && (-margin..height as f32 + margin).contains(&y)
        {
            out.push([x, y]);
        }
        if out.len() == MAX_EPIPOLES {
            break;
        }
    }
    out
}

//! Optical-depth storage larger than one storage binding.
//!
//! All lights' OPVs form one light-major array of f32 (light `l`, cell `i` at
//! `l · cells + i`), the index every shader already computes. That array is cut into
//! segments of at most one storage binding, each its own buffer and its own binding, so a
//! scene is limited by the device's memory and by the number of bindings a shader stage may
//! have, not by the size of one binding. Shaders reach the array only through the generated
//! helpers `NAME_load(i)` and `NAME_store(i, v)` ([`OpvLayout::wgsl`]); the storage can
//! change without touching their numerics. Segment 0 keeps the binding number the shader's
//! array always had; segment `k ≥ 1` is bound at `extra_base + k − 1`. The segment count is
//! fixed per device when the pipelines are built; unused segments bind a placeholder.
//!
//! Every segment but the last holds the same number of floats, the length of segment 0,
//! which the helpers read with `arrayLength`. Where a light's volume fits a binding, that
//! length is a whole number of lights, so no light straddles two segments and all lanes
//! working on one light pick the same segment: on SIMD hardware a segment choice that
//! differs between lanes costs every case of the switch.

use wgpu::{BindGroupEntry, BindGroupLayoutEntry, BindingType, ShaderStages};

/// First binding of the extra segments of a stage's first OPV-like array.
pub const EXTRA_BINDING: u32 = 100;
/// First binding of the extra segments of a stage's second array (the sweep's mean in-box
/// extinction, the Jacobi scheme's destination).
pub const EXTRA_BINDING_2: u32 = 120;
/// Most segments per array.
pub const MAX_SEGMENTS: u32 = 16;

/// How OPV arrays are segmented on one device.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct OpvLayout {
    /// Floats per segment.
    pub segment: u32,
    /// Segment bindings per array.
    pub segments: u32,
}

impl OpvLayout {
    /// Segments of one storage binding each; as many as the device's storage-buffer limit
    /// per stage leaves room for two arrays plus the other bindings of the sweep and march.
    pub fn for_limits(limits: &wgpu::Limits) -> Self {
        let binding = (limits.max_storage_buffer_binding_size as u64).min(limits.max_buffer_size);
        let segment = (binding / 4 / 64 * 64).min(1 << 30) as u32;
        let segments = (limits.max_storage_buffers_per_shader_stage.saturating_sub(8) / 2).clamp(1, MAX_SEGMENTS);
        Self { segment, segments }
    }

    /// Segments of `bytes` each (rounded down to whole floats): a setting for tests, which
    /// makes small scenes span several segments.
    pub fn with_segment_bytes(limits: &wgpu::Limits, bytes: u64) -> Self {
        let full = Self::for_limits(limits);
        Self { segment: ((bytes / 4).max(1) as u32).min(full.segment), ..full }
    }

    /// Bytes one array can hold: every segment full, and every index within `u32`.
    pub fn capacity_bytes(&self) -> u64 {
        (self.segment as u64 * self.segments as u64).min(u32::MAX as u64) * 4
    }

    /// Floats per segment for volumes of `cells` cells: whole lights where one fits.
    pub fn segment_for(&self, cells: u64) -> u64 {
        let seg = self.segment as u64;
        if cells == 0 || cells > seg {
            seg
        } else {
            seg / cells * cells
        }
    }

    /// Bytes of the lights' volumes one array can hold on a grid of `cells` cells.
    pub fn capacity_bytes_for(&self, cells: u64) -> u64 {
        (self.segment_for(cells) * self.segments as u64).min(u32::MAX as u64) * 4
    }

    /// WGSL declaring array `name` (segment 0 at `binding`, the rest from `extra_base`) and
    /// its helpers `name_load(i: u32) -> f32` and, when `read_write`, `name_store(i: u32, v: f32)`.
    pub fn wgsl(&self, name: &str, binding: u32, extra_base: u32, read_write: bool) -> String {
        let access = if read_write { "read_write" } else { "read" };
        let mut s = format!("// `{name}`: one light-major f32 array in up to {} segments (src/gpu/opv_store.rs).\n", self.segments);
        for k in 0..self.segments {
            let b = if k == 0 { binding } else { extra_base + k - 1 };
            s += &format!("@group(0) @binding({b}) var<storage, {access}> {name}_{k}: array<f32>;\n");
        }
        let cases = |body: &dyn Fn(u32) -> String| -> String {
            if self.segments == 1 {
                return format!("    {}\n", body(0));
            }
            let mut c = format!("    let n = arrayLength(&{name}_0);\n    let k = i / n;\n    let j = i - k * n;\n    switch k {{\n");
            for k in 1..self.segments {
                c += &format!("        case {k}u: {{ {} }}\n", body(k));
            }
            c += &format!("        default: {{ {} }}\n    }}\n", body(0));
            c
        };
        let at = if self.segments == 1 { "i" } else { "j" };
        s += &format!("fn {name}_load(i: u32) -> f32 {{\n{}}}\n", cases(&|k| format!("return {name}_{k}[{at}];")));
        if read_write {
            s += &format!("fn {name}_store(i: u32, v: f32) {{\n{}}}\n", cases(&|k| format!("{name}_{k}[{at}] = v;")));
        }
        s
    }

    /// Layout entries of segments 1.. of an array (segment 0 is in the stage's own list).
    pub fn layout_entries(&self, extra_base: u32, read_only: bool) -> Vec<BindGroupLayoutEntry> {
        (1..self.segments)
            .map(|k| BindGroupLayoutEntry {
                binding: extra_base + k - 1,
                visibility: ShaderStages::COMPUTE,
                ty: BindingType::Buffer {
                    ty: wgpu::BufferBindingType::Storage { read_only },
                    has_dynamic_offset: false,
                    min_binding_size: None,
                },
                count: None,
            })
            .collect()
    }
}

/// One segmented array on the GPU.
#[derive(Clone)]
pub struct OpvBuffers {
    /// `layout.segments` buffers; those past the data are 4-byte placeholders.
    segments: Vec<wgpu::Buffer>,
    /// Floats per segment (see [`OpvLayout::segment_for`]).
    segment: u64,
    floats: u64,
}

impl OpvBuffers {
    /// An array of `lights` volumes of `cells` floats (at least one float), zeroed.
    pub fn new(device: &wgpu::Device, layout: OpvLayout, cells: u64, lights: u64, label: &str) -> Self {
        let floats = (cells * lights).max(1);
        let segment = layout.segment_for(cells);
        let segments = (0..layout.segments as u64)
            .map(|k| {
                let len = floats.saturating_sub(k * segment).min(segment).max(1);
                device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some(label),
                    size: len * 4,
                    usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            })
            .collect();
        Self { segments, segment, floats }
    }

    /// Segment 0, for the stage's own binding list.
    pub fn first(&self) -> wgpu::BindingResource<'_> {
        self.segments[0].as_entire_binding()
    }

    /// Bind group entries of segments 1.. from `extra_base`.
    pub fn extra_entries(&self, extra_base: u32) -> Vec<BindGroupEntry<'_>> {
        self.segments[1..]
            .iter()
            .enumerate()
            .map(|(k, b)| BindGroupEntry { binding: extra_base + k as u32, resource: b.as_entire_binding() })
            .collect()
    }

    /// Floats the array holds.
    pub fn floats(&self) -> u64 {
        self.floats
    }

    pub fn bytes(&self) -> u64 {
        self.segments.iter().map(|b| b.size()).sum()
    }

    /// The pieces `(segment, offset, floats)` of floats `start..start + count`.
    fn pieces(&self, start: u64, count: u64) -> Vec<(usize, u64, u64)> {
        let seg = self.segment;
        let mut out = Vec::new();
        let (mut at, end) = (start, (start + count).min(self.floats));
        while at < end {
            let k = at / seg;
            let n = (end - at).min(seg - at % seg);
            out.push((k as usize, at % seg, n));
            at += n;
        }
        out
    }

    /// Copies floats `start..start + count` of `self` to `dst` (segmented alike) at `dst_start`.
    pub fn copy_to(&self, encoder: &mut wgpu::CommandEncoder, start: u64, dst: &OpvBuffers, dst_start: u64, count: u64) {
        let seg = dst.segment;
        let mut done = 0;
        for (k, off, n) in self.pieces(start, count) {
            // Split again where the destination's segments end.
            let mut m = 0;
            while m < n {
                let at = dst_start + done + m;
                let len = (n - m).min(seg - at % seg);
                encoder.copy_buffer_to_buffer(&self.segments[k], (off + m) * 4, &dst.segments[(at / seg) as usize], (at % seg) * 4, len * 4);
                m += len;
            }
            done += n;
        }
    }

    /// Reads floats `start..start + count` back.
    pub fn read(&self, ctx: &super::GpuContext, start: u64, count: u64) -> Result<Vec<f32>, super::GpuError> {
        let mut out = Vec::with_capacity(count as usize);
        for (k, off, n) in self.pieces(start, count) {
            out.extend(super::readback::read_buffer::<f32>(ctx, &self.segments[k], off * 4, n as usize)?);
        }
        Ok(out)
    }
}

//! Per-stage GPU time from timestamp queries, on hardware adapters that support them.
//!
//! Each stage is one compute pass; its begin/end timestamps are resolved into a buffer in the
//! stage's own command buffer and read after the queue drains. Elsewhere the caller uses
//! wall time around the stage's host work, submit and a drained queue. Software adapters
//! get wall time too: on llvmpipe the injection pass's timestamps read 2 ms for work that
//! measurably takes ~95 ms of wall time, so they cannot be trusted there.

use super::readback::read_buffer;
use super::{GpuContext, GpuError};

pub const STAGES: u32 = 3;
pub const INJECT: u32 = 0;
pub const PROPAGATE: u32 = 1;
pub const MARCH: u32 = 2;

pub struct StageTimer {
    query_set: wgpu::QuerySet,
    resolve: wgpu::Buffer,
    period_ns: f64,
}

impl StageTimer {
    /// None without TIMESTAMP_QUERY, on a software (CPU) adapter, or when
    /// `FOGSMITH_TIMING=wall` asks for wall time.
    pub fn new(ctx: &GpuContext) -> Option<Self> {
        let software = ctx.adapter_info.device_type == wgpu::DeviceType::Cpu;
        if !ctx.supports_timestamps() || software || std::env::var("FOGSMITH_TIMING").is_ok_and(|v| v == "wall") {
            return None;
        }
        let query_set = ctx.device.create_query_set(&wgpu::QuerySetDescriptor {
            label: Some("stage timestamps"),
            ty: wgpu::QueryType::Timestamp,
            count: 2 * STAGES,
        });
        let resolve = ctx.device.create_buffer(&wgpu::BufferDescriptor {
            label: Some("stage timestamps"),
            size: wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT * STAGES as u64,
            usage: wgpu::BufferUsages::QUERY_RESOLVE | wgpu::BufferUsages::COPY_SRC,
            mapped_at_creation: false,
        });
        Some(Self { query_set, resolve, period_ns: ctx.queue.get_timestamp_period() as f64 })
    }

    pub fn writes(&self, stage: u32) -> wgpu::ComputePassTimestampWrites<'_> {
        wgpu::ComputePassTimestampWrites {
            query_set: &self.query_set,
            beginning_of_pass_write_index: Some(2 * stage),
            end_of_pass_write_index: Some(2 * stage + 1),
        }
    }

    /// Records the resolve of `stage`'s timestamps; call after its pass ends.
    pub fn resolve(&self, encoder: &mut wgpu::CommandEncoder, stage: u32) {
        encoder.resolve_query_set(&self.query_set, 2 * stage..2 * stage + 2, &self.resolve, offset(stage));
    }

    /// Milliseconds between `stage`'s timestamps, once its work has completed.
    pub fn read_ms(&self, ctx: &GpuContext, stage: u32) -> Result<f64, GpuError> {
        let t: Vec<u64> = read_buffer(ctx, &self.resolve, offset(stage), 2)?;
        Ok(t[1].saturating_sub(t[0]) as f64 * self.period_ns / 1e6)
    }
}

fn offset(stage: u32) -> u64 {
    wgpu::QUERY_RESOLVE_BUFFER_ALIGNMENT * stage as u64
}

/// Encodes one work item of `stage` with `timer`'s timestamp writes, if any, resolves them,
/// and submits it; returns what `encode` returns.
pub fn submit<'t, R>(
    ctx: &GpuContext,
    timer: Option<&'t StageTimer>,
    stage: u32,
    encode: impl FnOnce(&mut wgpu::CommandEncoder, Option<wgpu::ComputePassTimestampWrites<'t>>) -> R,
) -> R {
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    let result = encode(&mut encoder, timer.map(|t| t.writes(stage)));
    if let Some(t) = timer {
        t.resolve(&mut encoder, stage);
    }
    ctx.queue.submit([encoder.finish()]);
    result
}

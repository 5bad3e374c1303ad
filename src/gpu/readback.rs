//! Copies GPU buffers and textures back to the CPU.

use super::{GpuContext, GpuError};
use bytemuck::Pod;

/// Reads `count` elements of `T` starting at byte `offset` of `buffer` (which needs COPY_SRC).
pub fn read_buffer<T: Pod>(
    ctx: &GpuContext,
    buffer: &wgpu::Buffer,
    offset: u64,
    count: usize,
) -> Result<Vec<T>, GpuError> {
    let size = (count * std::mem::size_of::<T>()) as u64;
    if size == 0 {
        return Ok(Vec::new());
    }
    let staging = staging_buffer(ctx, size);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encoder.copy_buffer_to_buffer(buffer, offset, &staging, 0, size);
    ctx.queue.submit([encoder.finish()]);
    let bytes = map_read(ctx, &staging)?;
    Ok(bytemuck::pod_collect_to_vec(&bytes))
}

/// Reads a whole 2D or 3D texture of `texel_bytes`-sized texels, rows unpadded.
pub fn read_texture<T: Pod>(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    extent: [u32; 3],
    texel_bytes: u32,
) -> Result<Vec<T>, GpuError> {
    read_texture_region(ctx, texture, wgpu::Origin3d::ZERO, extent, texel_bytes)
}

/// Reads the `[width, height, depth]` texels of `texture` from `origin`, rows unpadded.
pub fn read_texture_region<T: Pod>(
    ctx: &GpuContext,
    texture: &wgpu::Texture,
    origin: wgpu::Origin3d,
    [width, height, depth]: [u32; 3],
    texel_bytes: u32,
) -> Result<Vec<T>, GpuError> {
    let row = width * texel_bytes;
    let padded_row = row.div_ceil(wgpu::COPY_BYTES_PER_ROW_ALIGNMENT) * wgpu::COPY_BYTES_PER_ROW_ALIGNMENT;
    let staging = staging_buffer(ctx, padded_row as u64 * height as u64 * depth as u64);
    let mut encoder = ctx.device.create_command_encoder(&Default::default());
    encoder.copy_texture_to_buffer(
        wgpu::TexelCopyTextureInfo { texture, mip_level: 0, origin, aspect: wgpu::TextureAspect::All },
        wgpu::TexelCopyBufferInfo {
            buffer: &staging,
            layout: wgpu::TexelCopyBufferLayout {
                offset: 0,
                bytes_per_row: Some(padded_row),
                rows_per_image: Some(height),
            },
        },
        wgpu::Extent3d { width, height, depth_or_array_layers: depth },
    );
    ctx.queue.submit([encoder.finish()]);
    let bytes = map_read(ctx, &staging)?;
    let mut out = Vec::with_capacity((row as usize / std::mem::size_of::<T>()) * (height * depth) as usize);
    for chunk in bytes.chunks_exact(padded_row as usize) {
        out.extend_from_slice(&bytemuck::pod_collect_to_vec::<u8, T>(&chunk[..row as usize]));
    }
    Ok(out)
}

fn staging_buffer(ctx: &GpuContext, size: u64) -> wgpu::Buffer {
    ctx.device.create_buffer(&wgpu::BufferDescriptor {
        label: Some("readback"),
        size,
        usage: wgpu::BufferUsages::MAP_READ | wgpu::BufferUsages::COPY_DST,
        mapped_at_creation: false,
    })
}

fn map_read(ctx: &GpuContext, staging: &wgpu::Buffer) -> Result<Vec<u8>, GpuError> {
    let (tx, rx) = std::sync::mpsc::channel();
    staging.map_async(wgpu::MapMode::Read, .., move |r| {
        let _ = tx.send(r);
    });
    ctx.wait()?;
    rx.recv().map_err(|e| GpuError::Readback(e.to_string()))?.map_err(|e| GpuError::Readback(e.to_string()))?;
    let bytes = staging.get_mapped_range(..).map_err(|e| GpuError::Readback(e.to_string()))?.to_vec();
    staging.unmap();
    Ok(bytes)
}

//! Buffer helpers shared by the stages and the scheduler, so that no stage depends on the
//! scheduler for them.

/// A storage buffer holding `bytes`, which may also be written and copied from. An empty
/// `bytes` gets a zeroed buffer, since bindings must not be empty.
pub(super) fn storage_buffer(device: &wgpu::Device, label: &str, bytes: &[u8]) -> wgpu::Buffer {
    use wgpu::util::DeviceExt;
    let padded;
    let contents = if bytes.is_empty() {
        padded = [0u8; 256];
        &padded[..]
    } else {
        bytes
    };
    device.create_buffer_init(&wgpu::util::BufferInitDescriptor {
        label: Some(label),
        contents,
        usage: wgpu::BufferUsages::STORAGE | wgpu::BufferUsages::COPY_DST | wgpu::BufferUsages::COPY_SRC,
    })
}

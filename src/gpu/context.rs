//! The device the pipeline runs on: either opened headlessly (CLI, tests, benchmarks) or
//! borrowed from the editor's egui-wgpu renderer, so the editor and the pipeline share one.

use super::GpuError;

/// A wgpu device and queue plus what the pipeline needs to know about the adapter.
#[derive(Clone)]
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    pub adapter_info: wgpu::AdapterInfo,
    pub limits: wgpu::Limits,
    pub features: wgpu::Features,
}

/// Features the pipeline uses where the adapter has them; every device it runs on (headless or
/// the editor's) requests the same ones, so both compute the same values.
pub const OPTIONAL_FEATURES: wgpu::Features = wgpu::Features::TIMESTAMP_QUERY.union(wgpu::Features::FLOAT32_FILTERABLE);

impl GpuContext {
    /// Opens the best adapter without a window. Vulkan is preferred: on machines with only
    /// Mesa's llvmpipe the GL backend returns wrong results for 3D storage textures, so GL
    /// is used only when no other backend has an adapter, and llvmpipe on GL is refused
    /// unless asked for. `FOGSMITH_BACKEND=vulkan|gl|metal|dx12` overrides the choice.
    pub fn new_headless() -> Result<Self, GpuError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        let forced = std::env::var("FOGSMITH_BACKEND").ok();
        desc.backends = match forced.as_deref() {
            Some("vulkan") => wgpu::Backends::VULKAN,
            Some("gl") => wgpu::Backends::GL,
            Some("metal") => wgpu::Backends::METAL,
            Some("dx12") => wgpu::Backends::DX12,
            _ => wgpu::Backends::all(),
        };
        let instance = wgpu::Instance::new(desc);
        let adapters = pollster::block_on(instance.enumerate_adapters(wgpu::Backends::all()));
        let adapter = adapters
            .into_iter()
            .filter(|a| a.get_downlevel_capabilities().flags.contains(wgpu::DownlevelFlags::COMPUTE_SHADERS))
            .max_by_key(|a| adapter_rank(&a.get_info()))
            .ok_or(GpuError::NoAdapter)?;
        let info = adapter.get_info();
        if refuses_unasked(info.backend, info.device_type, forced.is_some()) {
            return Err(GpuError::SoftwareGlOnly { adapter: info.name });
        }
        let features = adapter.features() & OPTIONAL_FEATURES;
        let limits = adapter.limits();
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("fogsmith"),
            required_features: features,
            required_limits: limits.clone(),
            experimental_features: wgpu::ExperimentalFeatures::disabled(),
            memory_hints: wgpu::MemoryHints::Performance,
            trace: wgpu::Trace::Off,
        }))
        .map_err(|e| GpuError::Device { adapter: info.name.clone(), message: e.to_string() })?;
        Ok(Self { device, queue, adapter_info: info, limits, features })
    }

    /// Wraps a device opened elsewhere (the editor's egui-wgpu device).
    pub fn from_device(device: wgpu::Device, queue: wgpu::Queue, adapter_info: wgpu::AdapterInfo) -> Self {
        let limits = device.limits();
        let features = device.features();
        Self { device, queue, adapter_info, limits, features }
    }

    /// "name (backend, device type)".
    pub fn adapter_summary(&self) -> String {
        format!("{} ({:?}, {:?})", self.adapter_info.name, self.adapter_info.backend, self.adapter_info.device_type)
    }

    /// Bytes one storage binding may hold: the binding limit, capped by the buffer limit.
    pub fn max_binding_bytes(&self) -> u64 {
        self.limits.max_storage_buffer_binding_size.min(self.limits.max_buffer_size)
    }

    pub fn supports_timestamps(&self) -> bool {
        self.features.contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// The device's memory in bytes, where known: a CPU adapter (software rasteriser) uses
    /// the host's RAM. wgpu does not report the memory of GPUs; there allocation failures
    /// are the limit.
    pub fn memory_bytes(&self) -> Option<u64> {
        if self.adapter_info.device_type != wgpu::DeviceType::Cpu {
            return None;
        }
        let info = std::fs::read_to_string("/proc/meminfo").ok()?;
        let line = info.lines().find(|l| l.starts_with("MemTotal:"))?;
        let kib: u64 = line.split_whitespace().nth(1)?.parse().ok()?;
        Some(kib * 1024)
    }

    /// Largest grid edge the adapter can hold as a 3D texture.
    pub fn max_grid_edge(&self) -> u32 {
        self.limits.max_texture_dimension_3d
    }

    /// Blocks until all submitted work has finished.
    pub fn wait(&self) -> Result<(), GpuError> {
        self.device.poll(wgpu::PollType::wait_indefinitely()).map(|_| ()).map_err(|e| GpuError::Readback(e.to_string()))
    }
}

/// Whether the best adapter is one that gives wrong volumes and was not asked for by name:
/// llvmpipe's GL driver, chosen when Mesa's Vulkan driver is missing, loses 3D storage-texture
/// writes beyond the first layer.
fn refuses_unasked(backend: wgpu::Backend, device_type: wgpu::DeviceType, backend_forced: bool) -> bool {
    !backend_forced && backend == wgpu::Backend::Gl && device_type == wgpu::DeviceType::Cpu
}

/// Higher is better: real GPUs first, then Vulkan software rasterisers, GL last.
pub fn adapter_rank(info: &wgpu::AdapterInfo) -> u32 {
    let device = match info.device_type {
        wgpu::DeviceType::DiscreteGpu => 40,
        wgpu::DeviceType::IntegratedGpu => 30,
        wgpu::DeviceType::VirtualGpu => 20,
        wgpu::DeviceType::Cpu => 10,
        wgpu::DeviceType::Other => 5,
    };
    let backend = match info.backend {
        wgpu::Backend::Vulkan | wgpu::Backend::Metal | wgpu::Backend::Dx12 => 2,
        wgpu::Backend::Gl => 0,
        _ => 1,
    };
    // A GL adapter never outranks a native one, whatever its device type.
    if backend == 0 {
        device / 10
    } else {
        device * 10 + backend
    }
}

#[cfg(test)]
mod tests {
    use super::refuses_unasked;

    #[test]
    fn only_an_unasked_software_gl_adapter_is_refused() {
        use wgpu::{Backend, DeviceType};
        assert!(refuses_unasked(Backend::Gl, DeviceType::Cpu, false));
        assert!(!refuses_unasked(Backend::Gl, DeviceType::Cpu, true), "FOGSMITH_BACKEND=gl still gets it");
        assert!(!refuses_unasked(Backend::Vulkan, DeviceType::Cpu, false));
        assert!(!refuses_unasked(Backend::Gl, DeviceType::IntegratedGpu, false));
    }
}

use thiserror::Error;

/// What can go wrong in the GPU pipeline. Every message says how to fix it.
#[derive(Debug, Error)]
pub enum GpuError {
    #[error(
        "no GPU adapter found (wgpu saw none on Vulkan, Metal, DX12 or GL). On Debian/Ubuntu run ./setup.sh, which installs \
         Mesa's software Vulkan driver (mesa-vulkan-drivers libvulkan1); elsewhere install your GPU's Vulkan driver"
    )]
    NoAdapter,
    #[error(
        "the only adapter found is {adapter} on GL, whose 3D storage-texture writes are lost beyond the first layer \
         (every volume would be wrong). On Debian/Ubuntu run ./setup.sh, which installs Mesa's software Vulkan driver \
         (mesa-vulkan-drivers libvulkan1); set FOGSMITH_BACKEND=gl to use this adapter anyway"
    )]
    SoftwareGlOnly { adapter: String },
    #[error("could not open the GPU device on adapter {adapter}: {message}")]
    Device { adapter: String, message: String },
    #[error("{what} needs {needed} but the adapter {adapter} allows at most {limit}; {suggestion}")]
    Limit { what: String, needed: u64, limit: u64, adapter: String, suggestion: String },
    #[error("GPU readback failed: {0}")]
    Readback(String),
    #[error("GPU validation error in {stage}: {message}")]
    Validation { stage: &'static str, message: String },
    #[error("invalid request: {0}")]
    Invalid(String),
    #[error("cancelled")]
    Cancelled,
}

/// Catches wgpu validation errors of one update as a typed error instead of a panic.
pub(super) struct ErrorScope(wgpu::ErrorScopeGuard);

impl ErrorScope {
    pub(super) fn push(device: &wgpu::Device) -> Self {
        Self(device.push_error_scope(wgpu::ErrorFilter::Validation))
    }

    pub(super) fn pop(self, stage: &'static str) -> Result<(), GpuError> {
        match pollster::block_on(self.0.pop()) {
            Some(e) => Err(GpuError::Validation { stage, message: e.to_string() }),
            None => Ok(()),
        }
    }
}

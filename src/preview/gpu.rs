//! The wgpu device a preview runs on, headless. The backend follows
//! `WGPU_BACKEND` (`vulkan` in the tests and CI: on the GL fallback some
//! formats are missing and 2-D arrays read back as zeros, see
//! `../shared/TOOLCHAIN.md`), the adapter `WGPU_ADAPTER_NAME`.

use super::PreviewError;

/// An adapter, its device and queue.
pub struct Gpu {
    pub adapter: wgpu::Adapter,
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
}

impl Gpu {
    /// Opens the adapter the environment names, or the default one.
    pub fn new() -> Result<Gpu, PreviewError> {
        let instance = wgpu::Instance::new(wgpu::InstanceDescriptor::new_without_display_handle_from_env());
        let adapter = pollster::block_on(wgpu::util::initialize_adapter_from_env_or_default(&instance, None)).map_err(|e| PreviewError::NoAdapter(e.to_string()))?;
        let (device, queue) = pollster::block_on(adapter.request_device(&wgpu::DeviceDescriptor {
            label: Some("sky preview"),
            required_features: wgpu::Features::empty(),
            required_limits: wgpu::Limits::default(),
            ..Default::default()
        }))
        .map_err(|e| PreviewError::Device(e.to_string()))?;
        Ok(Gpu { adapter, device, queue })
    }

    /// The adapter's name and backend, for reports.
    pub fn describe(&self) -> String {
        let info = self.adapter.get_info();
        format!("{} ({:?}, {:?})", info.name, info.backend, info.device_type)
    }

    /// Runs `f` and turns a validation error it caused into a
    /// [`PreviewError::Validation`] naming `what`.
    pub fn checked<T>(&self, what: &'static str, f: impl FnOnce() -> T) -> Result<T, PreviewError> {
        let scope = self.device.push_error_scope(wgpu::ErrorFilter::Validation);
        let value = f();
        match pollster::block_on(scope.pop()) {
            Some(e) => Err(PreviewError::Validation { what, message: e.to_string() }),
            None => Ok(value),
        }
    }
}

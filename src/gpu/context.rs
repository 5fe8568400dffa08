//! The wgpu device the kernels run on: natively Vulkan (on a machine without a GPU, Mesa's
//! lavapipe, whose adapter is named "llvmpipe"), in the browser WebGPU.

use std::sync::{Arc, Mutex};

use thiserror::Error;

/// Why no device could be had.
#[derive(Debug, Error)]
pub enum GpuError {
    #[error("no GPU adapter ({0}); natively wgpu needs a Vulkan driver, e.g. Debian's mesa-vulkan-drivers (lavapipe)")]
    NoAdapter(String),
    #[error("the adapter {adapter} refused a device: {reason}")]
    NoDevice { adapter: String, reason: String },
    #[error("{what} is {value}, beyond this device's limit {limit} (wgpu `Limits::{limit_name}`)")]
    TooLarge { what: String, value: u64, limit: u64, limit_name: &'static str },
    #[error("the kernel {kernel} did not compile on this device: {reason}")]
    Kernel { kernel: &'static str, reason: String },
    #[error("the GPU device failed: {0}")]
    Failed(String),
}

/// An adapter's device and queue, and what the adapter is.
pub struct GpuContext {
    pub device: wgpu::Device,
    pub queue: wgpu::Queue,
    info: wgpu::AdapterInfo,
    /// The first sign that the device can no longer be trusted (its loss, an error no scope
    /// caught, a readback that failed): after it nothing it computes is used.
    fault: Arc<Mutex<Option<String>>>,
}

/// Keeps the first fault only: later ones follow from it.
pub(crate) fn record(fault: &Mutex<Option<String>>, why: String) {
    let mut f = fault.lock().unwrap_or_else(|e| e.into_inner());
    f.get_or_insert(why);
}

/// The backends the GPU stepper uses: Vulkan natively (the only native backend compiled in),
/// WebGPU in the browser (WebGL2 has no compute).
fn backends() -> wgpu::Backends {
    if cfg!(target_arch = "wasm32") {
        wgpu::Backends::BROWSER_WEBGPU
    } else {
        wgpu::Backends::VULKAN
    }
}

impl GpuContext {
    /// The first adapter wgpu offers for compute, and a device with the default limits (what
    /// every WebGPU implementation guarantees, so that what passes here runs in the page).
    pub async fn request() -> Result<Self, GpuError> {
        let mut desc = wgpu::InstanceDescriptor::new_without_display_handle();
        desc.backends = backends();
        let instance = wgpu::Instance::new(desc);
        let options = wgpu::RequestAdapterOptions {
            power_preference: wgpu::PowerPreference::HighPerformance,
            ..Default::default()
        };
        let adapter = instance.request_adapter(&options).await.map_err(|e| GpuError::NoAdapter(e.to_string()))?;
        let info = adapter.get_info();
        // Natively, timestamp queries where the adapter has them (`bench --gpu` times each
        // dispatch with them); nothing else beyond WebGPU's defaults.
        let required_features = if cfg!(target_arch = "wasm32") {
            wgpu::Features::empty()
        } else {
            adapter.features() & wgpu::Features::TIMESTAMP_QUERY
        };
        let descriptor =
            wgpu::DeviceDescriptor { label: Some("monolayer gpu"), required_features, ..Default::default() };
        let (device, queue) = adapter
            .request_device(&descriptor)
            .await
            .map_err(|e| GpuError::NoDevice { adapter: info.name.clone(), reason: e.to_string() })?;
        let fault = Arc::new(Mutex::new(None));
        let lost = fault.clone();
        device.set_device_lost_callback(move |reason, message| {
            record(
                &lost,
                format!(
                    "the device was lost ({reason:?}{})",
                    if message.is_empty() { String::new() } else { format!(": {message}") }
                ),
            )
        });
        // In a browser an error no scope caught would only reach the console: it is a fault
        // of the device for the page, which then steps on the CPU engine. Natively wgpu's own
        // handler stays, which panics: a validation error there is a bug for the tests to show.
        #[cfg(target_arch = "wasm32")]
        {
            let uncaptured = fault.clone();
            device
                .on_uncaptured_error(Arc::new(move |e: wgpu::Error| record(&uncaptured, format!("a GPU error: {e}"))));
        }
        Ok(GpuContext { device, queue, info, fault })
    }

    /// Why the device can no longer be trusted, if it cannot: its loss, an uncaptured error (in
    /// a browser), or a readback that failed.
    pub fn fault(&self) -> Option<String> {
        self.fault.lock().unwrap_or_else(|e| e.into_inner()).clone()
    }

    /// Where faults are recorded, for a future that outlives the borrow of the context (a
    /// readback that did not map records itself there); the first one recorded is kept.
    pub(crate) fn fault_handle(&self) -> Arc<Mutex<Option<String>>> {
        self.fault.clone()
    }

    /// Destroys the device, as a driver reset or an unplugged GPU would: its loss callback
    /// fires and every later readback fails (the browser tests' forced loss).
    pub fn destroy(&self) {
        self.device.destroy();
    }

    /// [`GpuContext::request`], blocking (native only: a browser cannot block).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn new() -> Result<Self, GpuError> {
        pollster::block_on(Self::request())
    }

    /// Blocks until every submitted dispatch has finished (native only; for tests, diagnostics
    /// and timing: the stepper itself never waits inside a step).
    #[cfg(not(target_arch = "wasm32"))]
    pub fn wait(&self) {
        self.device.poll(wgpu::PollType::wait_indefinitely()).expect("the device finishes its work");
    }

    /// The adapter's name ("llvmpipe (LLVM 15.0.6, 256 bits)" on lavapipe).
    pub fn adapter_name(&self) -> &str {
        &self.info.name
    }

    /// Name, backend, device type and driver, for logs and benchmarks: on lavapipe the device
    /// type is `Cpu`, so every time measured there is a CPU figure.
    pub fn describe(&self) -> String {
        let i = &self.info;
        format!("{} ({:?}, {:?}, driver {} {})", i.name, i.backend, i.device_type, i.driver, i.driver_info)
    }

    pub fn device_type(&self) -> wgpu::DeviceType {
        self.info.device_type
    }

    /// Whether the device writes timestamps around compute passes (natively, where the adapter
    /// can).
    pub fn has_timestamps(&self) -> bool {
        self.device.features().contains(wgpu::Features::TIMESTAMP_QUERY)
    }

    /// Whether the adapter is a CPU device (lavapipe, SwiftShader): its times are CPU figures.
    pub fn runs_on_cpu(&self) -> bool {
        self.info.device_type == wgpu::DeviceType::Cpu
    }
}

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
    /// The device can no longer be trusted: lost, an error no scope caught, a readback that did
    /// not map, or a state read back that is not one. Nothing it computed after that is used.
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

/// Keeps the first fault only: later ones follow from it (a loss, reported later than the
/// errors it causes, replaces it: [`GpuContext::request`]).
pub(crate) fn record(fault: &Mutex<Option<String>>, why: String) {
    let mut f = fault.lock().unwrap_or_else(|e| e.into_inner());
    f.get_or_insert(why);
}

/// The fault recorded first, if any.
fn first(fault: &Mutex<Option<String>>) -> Option<String> {
    fault.lock().unwrap_or_else(|e| e.into_inner()).clone()
}

/// Records `why` as a fault of the device and returns the error of the fault recorded: when a
/// lost device makes a readback fail, the loss is what the error names, not the readback.
/// wgpu reports a loss (a destroyed device's too) on the poll that finds the queue empty, so
/// natively every submission is waited for first.
pub(crate) fn fail(device: &wgpu::Device, fault: &Mutex<Option<String>>, why: String) -> GpuError {
    record(fault, why.clone());
    #[cfg(not(target_arch = "wasm32"))]
    {
        // Its own failure, if any, is the fault recorded already or the loss it reports.
        let _ = caught::quietly(|| device.poll(wgpu::PollType::wait_indefinitely()));
    }
    #[cfg(target_arch = "wasm32")]
    let _ = device;
    GpuError::Failed(first(fault).unwrap_or(why))
}

/// The error of the fault recorded, if there is one: once the device failed, nothing it
/// computes is used.
pub(crate) fn check(fault: &Mutex<Option<String>>) -> Result<(), GpuError> {
    first(fault).map_or(Ok(()), |why| Err(GpuError::Failed(why)))
}

/// Blocks until the submission (every one, with `None`) has finished on the device; an error
/// if the device failed, now or before (native only: a browser cannot block).
///
/// wgpu 30's `Device::poll` panics, natively, when the driver reports the device lost while it
/// waits (every device error there is fatal to wgpu; only a timeout or a wrong submission index
/// is returned): that panic is caught here and becomes the device's fault.
#[cfg(not(target_arch = "wasm32"))]
pub(crate) fn wait_for(
    device: &wgpu::Device,
    fault: &Mutex<Option<String>>,
    submission: Option<wgpu::SubmissionIndex>,
) -> Result<(), GpuError> {
    let poll = || device.poll(wgpu::PollType::Wait { submission_index: submission, timeout: None });
    polled(device, fault, poll)
}

/// What [`wait_for`] makes of `poll`, a wait on `device`: its panic or its error is the
/// device's fault. Apart so that a test can hand it the panic of a lost device, which a
/// destroyed device does not raise (wgpu marks it lost without asking the driver).
#[cfg(not(target_arch = "wasm32"))]
fn polled(
    device: &wgpu::Device,
    fault: &Mutex<Option<String>>,
    poll: impl FnOnce() -> Result<wgpu::PollStatus, wgpu::PollError>,
) -> Result<(), GpuError> {
    match caught::quietly(poll) {
        Ok(Ok(_)) => check(fault),
        Ok(Err(e)) => Err(fail(device, fault, format!("waiting for the device: {e}"))),
        Err(panic) => Err(fail(device, fault, format!("waiting for the device: {panic}"))),
    }
}

/// A wait that meets a lost device is an error and the device's fault, not a panic.
#[cfg(all(test, not(target_arch = "wasm32")))]
mod tests {
    use super::*;

    #[test]
    fn a_wait_that_panics_on_a_lost_device_is_its_fault() {
        let ctx = match GpuContext::new() {
            Ok(ctx) => ctx,
            Err(e) if std::env::var("CI").is_ok_and(|v| v == "true") => panic!("CI=true: no adapter: {e}"),
            Err(_) => return,
        };
        ctx.wait().expect("a device that did not fail");
        // What wgpu's `Device::poll` panics with when the driver reports the device lost.
        let lost =
            || -> Result<wgpu::PollStatus, wgpu::PollError> { panic!("Error in Device::poll: Parent device is lost") };
        let error = polled(&ctx.device, &ctx.fault, lost).expect_err("a lost device");
        assert!(matches!(&error, GpuError::Failed(why) if why.contains("Parent device is lost")), "{error}");
        assert!(ctx.fault().is_some_and(|f| f.contains("Parent device is lost")), "{:?}", ctx.fault());
        // Once failed, the device is not waited on as if it had not.
        let again = ctx.wait().expect_err("a device that failed");
        assert_eq!(again.to_string(), error.to_string());
    }
}

/// Panics caught without a word on stderr: for wgpu's calls that panic where a device failed
/// (`wait_for`), whose message becomes the device's fault, printed once by whoever reports it.
#[cfg(not(target_arch = "wasm32"))]
mod caught {
    use std::cell::Cell;
    use std::panic::{catch_unwind, AssertUnwindSafe};
    use std::sync::Once;

    thread_local! {
        /// Whether this thread is inside [`quietly`], whose panics are not printed.
        static QUIET: Cell<bool> = const { Cell::new(false) };
    }

    /// `f()`, or the message of its panic. The process's panic hook is wrapped once, the first
    /// time: a panic on a thread inside `quietly` is not printed, every other one goes to the
    /// hook that was there before, as it would have.
    pub fn quietly<T>(f: impl FnOnce() -> T) -> Result<T, String> {
        static HOOK: Once = Once::new();
        HOOK.call_once(|| {
            let before = std::panic::take_hook();
            std::panic::set_hook(Box::new(move |info| {
                if !QUIET.with(Cell::get) {
                    before(info)
                }
            }));
        });
        let was = QUIET.with(|q| q.replace(true));
        // Unwind-safe in what matters: wgpu panics after its own call returned, holding no
        // lock of ours or its own, and the device it panicked about is used no more.
        let result = catch_unwind(AssertUnwindSafe(f));
        QUIET.with(|q| q.set(was));
        result.map_err(|payload| {
            payload
                .downcast_ref::<String>()
                .cloned()
                .or_else(|| payload.downcast_ref::<&str>().map(|s| s.to_string()))
                .unwrap_or_else(|| "a panic without a message".into())
                .trim()
                .to_string()
        })
    }

    #[cfg(test)]
    mod tests {
        use super::quietly;

        #[test]
        fn a_panic_inside_is_its_message_and_a_value_passes_through() {
            assert_eq!(quietly(|| 7), Ok(7));
            let e = quietly(|| -> u32 { panic!("wgpu error: the device is lost") });
            assert_eq!(e, Err("wgpu error: the device is lost".to_string()));
            // Not left quiet: a later panic outside reaches the hook as before.
            assert!(!super::QUIET.with(std::cell::Cell::get));
        }
    }
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
        // The loss replaces a fault recorded before it: wgpu reports it only once the queue is
        // empty, so the errors of what was made on the lost device meanwhile (a readback's
        // buffer that is invalid) come first, and the loss is what explains them.
        device.set_device_lost_callback(move |reason, message| {
            let why = format!(
                "the device was lost ({reason:?}{})",
                if message.is_empty() { String::new() } else { format!(": {message}") }
            );
            *lost.lock().unwrap_or_else(|e| e.into_inner()) = Some(why);
        });
        // An error no scope caught is a fault of the device: in a browser it would only reach
        // the console (the page then steps on the CPU engine); natively wgpu's own handler
        // would panic, and a device destroyed or lost under a run raises one at its next
        // readback (a staging buffer it can no longer make). Every readback after a fault
        // fails with it (`readback::read_words`), so a validation error of a kernel still
        // fails the test or stops the run that meets it, with its message.
        let uncaptured = fault.clone();
        device.on_uncaptured_error(Arc::new(move |e: wgpu::Error| record(&uncaptured, format!("a GPU error: {e}"))));
        Ok(GpuContext { device, queue, info, fault })
    }

    /// Why the device can no longer be trusted, if it cannot: its loss, an uncaptured error, or
    /// a readback that failed.
    pub fn fault(&self) -> Option<String> {
        first(&self.fault)
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
    /// and timing: the stepper itself never waits inside a step). An error if the device
    /// failed, now or before.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn wait(&self) -> Result<(), GpuError> {
        wait_for(&self.device, &self.fault, None)
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

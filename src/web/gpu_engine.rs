//! `WebGpuEngine`: the page's GPU engine, the model stepped on WebGPU compute in f32 by
//! [`crate::gpu::GpuRun`] (the kernels the native tests compare with the CPU core
//! stage by stage). It runs in the page's worker, steps without reading back, and hands the
//! state to the worker's [`WebSim`] only when the page draws or measures, so that everything
//! drawn and read out comes from the same `analysis` code as on the CPU engine.
//!
//! The worker's loop: `submit(n)` records up to n steps in one submission (at most
//! `check_every`, none across the switch to activity) after those under way, up to
//! `in_flight_max` of them, so the device steps the next while the last is checked; `check()`
//! resolves once the oldest ran and its faults were read (one small readback, queued behind it
//! and awaited from the event loop: a browser cannot block); `download()` queues the readback
//! of the state the submissions under way end at and resolves to it, which `WebSim::adopt`
//! takes once they are accepted. An edit of the tissue (a slider, a brush, a removed cell) is
//! made on the `WebSim` and uploaded again.

use std::cell::RefCell;
use std::rc::Rc;

use wasm_bindgen::prelude::*;

use super::binding::js_err;

use super::sim::{GpuState, WebSim};
use crate::gpu::{compile, GpuContext, GpuRun, GpuRunError, Kernel, Pipelines, IN_FLIGHT};

struct Engine {
    ctx: GpuContext,
    run: RefCell<Option<GpuRun>>,
    /// The kernels compiled so far by `compile_next`, in the order of `Kernel::ALL`, until the
    /// first upload takes them.
    compiled: RefCell<Vec<wgpu::ComputePipeline>>,
}

impl Engine {
    fn with_run<T>(&self, f: impl FnOnce(&mut GpuRun) -> T) -> Result<T, JsError> {
        let mut run = self.run.borrow_mut();
        let run = run.as_mut().ok_or_else(|| JsError::new("the GPU engine has no tissue yet: upload one"))?;
        Ok(f(run))
    }
}

/// The model stepped on WebGPU compute ([`GpuRun`]), handing its state to a [`WebSim`] to draw
/// and measure.
#[wasm_bindgen]
pub struct WebGpuEngine(Rc<Engine>);

#[wasm_bindgen]
impl WebGpuEngine {
    /// A WebGPU device for compute, in a window or a worker. Rejects, saying why, where WebGPU
    /// is missing or refuses a device (the page then steps on the CPU engine).
    pub async fn create() -> Result<WebGpuEngine, JsError> {
        let ctx = GpuContext::request().await.map_err(js_err)?;
        Ok(WebGpuEngine(Rc::new(Engine { ctx, run: RefCell::new(None), compiled: RefCell::default() })))
    }

    /// The adapter's name, backend, device type and driver.
    pub fn adapter(&self) -> String {
        self.0.ctx.describe()
    }

    /// Whether the adapter is a CPU device (SwiftShader): its speed is a CPU's.
    pub fn runs_on_cpu(&self) -> bool {
        self.0.ctx.runs_on_cpu()
    }

    /// The kernels there are.
    pub fn kernels(&self) -> u32 {
        Kernel::ALL.len() as u32
    }

    /// The kernels still to compile (`compile_next`).
    pub fn kernels_left(&self) -> u32 {
        let done = if self.0.run.borrow().is_some() { Kernel::ALL.len() } else { self.0.compiled.borrow().len() };
        (Kernel::ALL.len() - done) as u32
    }

    /// Compiles the next kernel and resolves, to the kernels left, once the device has taken
    /// it (the browser compiles in its GPU process): the page shows the progress between calls.
    /// Rejects naming a kernel the device refuses.
    pub async fn compile_next(&self) -> Result<u32, JsError> {
        let engine = self.0.clone();
        let Some(&kernel) = Kernel::ALL.get(Kernel::ALL.len() - self.kernels_left() as usize) else {
            return Ok(0);
        };
        let pipeline = compile(&engine.ctx, kernel).await.map_err(js_err)?;
        engine.compiled.borrow_mut().push(pipeline);
        Ok(self.kernels_left())
    }

    /// Uploads the simulation's tissue (its parameters, substrate and cells), the first time
    /// with the kernels `compile_next` compiled, or compiling them all at once where it did
    /// not finish. Throws, naming the device limit, for a tissue too large for it.
    pub fn upload(&self, sim: &WebSim) -> Result<(), JsError> {
        let m = sim.monolayer();
        let mut run = self.0.run.borrow_mut();
        match run.as_mut() {
            Some(r) => r.upload(&self.0.ctx, m).map_err(js_err),
            None => {
                let compiled = std::mem::take(&mut *self.0.compiled.borrow_mut());
                let pipelines = if compiled.len() == Kernel::ALL.len() {
                    Pipelines::from_compiled(compiled)
                } else {
                    Pipelines::new(&self.0.ctx)
                };
                *run = Some(GpuRun::with_pipelines(&self.0.ctx, pipelines, m).map_err(js_err)?);
                Ok(())
            }
        }
    }

    /// Records up to `n` steps in one submission after those under way and returns how many
    /// (at most `check_every`, none across the switch to activity; 0 with `n` = 0); `check`
    /// settles them in turn. Throws with `in_flight_max` submissions under way.
    pub fn submit(&self, n: u32) -> Result<u32, JsError> {
        self.0.with_run(|r| {
            if r.in_flight() >= IN_FLIGHT {
                return Err(JsError::new(
                    "submit: as many submissions as may be are under way: check the oldest first",
                ));
            }
            Ok(r.submit(&self.0.ctx, n as u64) as u32)
        })?
    }

    /// Submissions under way at most.
    pub fn in_flight_max(&self) -> u32 {
        IN_FLIGHT as u32
    }

    /// Submissions under way, not yet checked.
    pub fn in_flight(&self) -> Result<u32, JsError> {
        self.0.with_run(|r| r.in_flight() as u32)
    }

    /// The step the submissions under way end at.
    pub fn submitted_to(&self) -> Result<f64, JsError> {
        self.0.with_run(|r| r.submitted_to() as f64)
    }

    /// Resolves once the oldest submission under way ran and its faults were read: to true if
    /// its steps were taken, false if they were put back to be taken again (a solve needed more
    /// recorded iterations, or a cell more storage: both are then given), with the submissions
    /// after it. Rejects on a fault of the model (φ out of range, a cell lost), the state back
    /// at the start of the submission, naming the steps and the cell.
    ///
    /// A failure of the device itself (lost, a GPU error, a readback that did not map) also
    /// rejects; [`WebGpuEngine::device_fault`] then says what happened, and the page goes on on
    /// the CPU engine from the last state it holds.
    pub async fn check(&self) -> Result<bool, JsError> {
        let engine = self.0.clone();
        let readback = engine.run.borrow_mut().as_mut().and_then(|r| r.next_faults());
        let Some(readback) = readback else { return Ok(true) };
        let faults = readback.await.map_err(js_err)?;
        let settled = engine.with_run(|r| r.settle(&engine.ctx, &faults))?;
        match settled {
            Ok(taken) => Ok(taken),
            Err(GpuRunError::BeyondCapacity { .. }) => {
                // The state of the start of the submission, uploaded again with room for the
                // patches it has now (GpuRun::regrow, which blocks, natively).
                let m = engine.with_run(|r| r.download(&engine.ctx))?.await.map_err(js_err)?;
                engine.with_run(|r| r.upload(&engine.ctx, &m))?.map_err(js_err)?;
                Ok(false)
            }
            Err(e) => Err(js_err(e)),
        }
    }

    /// Queues the readback of the state the submissions under way end at (`submitted_to`;
    /// the state itself with none under way) and resolves to it, for `WebSim::adopt` once
    /// those submissions are accepted.
    pub fn download(&self) -> Result<js_sys::Promise, JsError> {
        let pending = self.0.with_run(|r| r.download(&self.0.ctx))?;
        Ok(wasm_bindgen_futures::future_to_promise(async move {
            let m = pending.await.map_err(|e| JsValue::from(js_err(e)))?;
            Ok(JsValue::from(GpuState(m)))
        }))
    }

    /// Why the device can no longer be trusted (lost, an uncaptured GPU error, a readback that
    /// did not map), or nothing while it can.
    pub fn device_fault(&self) -> Option<String> {
        self.0.ctx.fault()
    }

    /// Destroys the device, as a driver reset would (the browser tests force a loss with it).
    pub fn destroy_device(&self) {
        self.0.ctx.destroy();
    }

    /// Steps taken and checked.
    pub fn step_count(&self) -> Result<f64, JsError> {
        self.0.with_run(|r| r.step_count() as f64)
    }

    /// The CG iterations recorded per friction solve now (they follow what the solves need).
    pub fn solve_iterations(&self) -> Result<u32, JsError> {
        self.0.with_run(|r| r.gpu().solve_iterations as u32)
    }
}

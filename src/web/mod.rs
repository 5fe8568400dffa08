//! The browser demo: a thin `#[wasm_bindgen]` layer over the same [`crate::Monolayer`] the native
//! tests run, and the wgpu drawing of its fields.
//!
//! - [`view`]: the per-site and per-cell data the shaders draw, built from the core's fields;
//! - [`measure`]: what the page reads out (holes from void sites, packing fraction);
//! - `sim` (wasm32): `WebSim`, the simulation object the page drives (step, parameters, brushes);
//! - `render` (wasm32): `Renderer`, wgpu on WebGPU or WebGL2, with the shaders of `shaders/`;
//! - `gpu_engine` (wasm32, feature `gpu`): `WebGpuEngine`, the model stepped on WebGPU compute
//!   (`crate::gpu`), handing its state to a `WebSim` to draw and measure.
//!
//! `view` and `measure` are plain Rust, built and unit-tested natively like the rest of the
//! crate; only the binding and the GPU need the browser.

pub mod measure;
pub mod playback;
pub mod readouts;
pub mod version;
pub mod view;

#[cfg(all(target_arch = "wasm32", feature = "gpu"))]
pub mod gpu_engine;
#[cfg(target_arch = "wasm32")]
pub mod player;
#[cfg(target_arch = "wasm32")]
pub mod render;
#[cfg(target_arch = "wasm32")]
pub mod sim;

/// An error of the core as the exception a binding throws to the page.
#[cfg(target_arch = "wasm32")]
pub(crate) fn js_err(e: impl std::fmt::Display) -> wasm_bindgen::JsError {
    wasm_bindgen::JsError::new(&e.to_string())
}

/// Runs once when the module is instantiated: a Rust panic then reaches the console with its
/// message, and the page (which wraps every call) shows it instead of freezing silently.
#[cfg(target_arch = "wasm32")]
#[wasm_bindgen::prelude::wasm_bindgen(start)]
pub fn start() {
    console_error_panic_hook::set_once();
}

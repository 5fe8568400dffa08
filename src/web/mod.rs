//! The browser demo's binding (wasm32 only): a thin `#[wasm_bindgen]` layer over the same
//! [`crate::Monolayer`] the native tests run, and the wgpu drawing of its fields.
//!
//! - [`sim`]: `WebSim`, the simulation object the page drives (step, parameters, brushes, stats);
//! - [`measure`]: what the page reads out (holes from void sites, packing fraction);
//! - [`view`]: the per-site and per-cell data the shaders draw, built from the core's fields;
//! - [`render`]: `Renderer`, wgpu on WebGPU or WebGL2, with the shaders of `shaders/`.

pub mod measure;
pub mod render;
pub mod sim;
pub mod view;

use wasm_bindgen::prelude::*;

/// Runs once when the module is instantiated: a Rust panic then reaches the console with its
/// message, and the page (which wraps every call) shows it instead of freezing silently.
#[wasm_bindgen(start)]
pub fn start() {
    console_error_panic_hook::set_once();
}

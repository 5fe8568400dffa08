//! The browser demo: a thin `#[wasm_bindgen]` layer over the same [`crate::Monolayer`] the native
//! tests run, and the wgpu drawing of its fields.
//!
//! - `view`: the per-site and per-cell data the shaders draw, built from the core's fields
//!   ([`FieldKind`]);
//! - `measure`: what the page reads out (holes from void sites, packing fraction;
//!   [`tissue_stats`]);
//! - `readouts`: the readout log the page downloads, and its run record ([`run_record_json`]);
//! - `playback`: a native run's frames opened in the page ([`Playback`]);
//! - `history`: the live tissue's saved states and the replays of "What if?" ([`History`],
//!   [`Watch`]);
//! - `raster`: a view as one pixel per site, for the page's Canvas 2D renderer ([`site_colours`]);
//! - `version`: the code version the page names ([`code_version`]);
//! - `sim` (wasm32): `WebSim`, the simulation object the page drives (step, parameters, brushes);
//! - `render` (wasm32): `Renderer`, wgpu on WebGPU or WebGL2, with the shaders of `shaders/`
//!   (and what the page's Canvas 2D renderer reads of a view where neither exists);
//! - `player` (wasm32): `WebPlayback`, the binding of `playback`;
//! - `binding` (wasm32): what the bindings share (the start hook, the error they throw, the
//!   threads the core runs on, the readout of a tissue and the marks drawn on it);
//! - `gpu_engine` (wasm32, feature `gpu`): `WebGpuEngine`, the model stepped on WebGPU compute
//!   (`crate::gpu`), handing its state to a `WebSim` to draw and measure.
//!
//! All but the bindings are plain Rust, built and unit-tested natively like the rest of the
//! crate; only the bindings and the GPU need the browser. The modules are private: the page
//! reaches the bindings through wasm-bindgen's exports, the tests what is re-exported here.

mod history;
mod measure;
mod playback;
mod raster;
mod readouts;
mod version;
mod view;

#[cfg(target_arch = "wasm32")]
mod binding;
#[cfg(all(target_arch = "wasm32", feature = "gpu"))]
mod gpu_engine;
#[cfg(target_arch = "wasm32")]
mod player;
#[cfg(target_arch = "wasm32")]
mod render;
#[cfg(target_arch = "wasm32")]
mod sim;

pub use history::{History, Nucleation, Saved, Verdict, Watch, KEPT, LEAD, MARGIN, SAVE_EVERY};
pub use measure::{tissue_stats, TissueStats};
pub use playback::{Playback, RunInfo};
pub use raster::{bar_colours, site_colours};
pub use readouts::{run_record_json, ReadoutLog, Row, ROW_EVERY};
pub use version::code_version;
pub use view::{FieldKind, Segment, View, ViewBuilder};

// The bindings the page's JavaScript drives (wasm32), named here for Rust as well.
#[cfg(target_arch = "wasm32")]
pub use binding::{DefectMark, Readout, SpiralMark};
#[cfg(all(target_arch = "wasm32", feature = "gpu"))]
pub use gpu_engine::WebGpuEngine;
#[cfg(target_arch = "wasm32")]
pub use player::WebPlayback;
#[cfg(target_arch = "wasm32")]
pub use render::{Layout, Renderer, WebView};
#[cfg(all(target_arch = "wasm32", feature = "gpu"))]
pub use sim::GpuState;
#[cfg(target_arch = "wasm32")]
pub use sim::{CoreCopy, ReplayVerdict, ReplayWatch, RewindPoint, SavedState, WebSim};
// The threaded core's `initThreadPool(n)`: rayon's pool on n Web Workers sharing this memory.
#[cfg(all(target_arch = "wasm32", feature = "threads"))]
pub use wasm_bindgen_rayon::init_thread_pool;

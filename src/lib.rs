//! # monolayer
//!
//! The active-nematic multi-phase-field model of epithelial monolayers of Pinto, Rozman &
//! Yeomans, "Spontaneous hole formation in cell monolayers emerges from collective cell motion".
//! Every cell is its own phase field on a patch of a periodic lattice; cells push on each other
//! (free energy), pull along their long axis (extensile activity) and feel friction from the
//! substrate and from each other.
//!
//! The physics compiles for `wasm32-unknown-unknown` and natively with the same bits for the same
//! seed: no threads, files or clocks inside it. Native extras (threads, files, the CLI) sit
//! behind the `parallel` and `cli` features.
//!
//! Six layers, each a folder; imports go downwards only (model ← analysis, formats, gpu ← run,
//! web) and no files import each other around a circle, which `tests/layers.rs` checks:
//!
//! - [`model`]: the physics core, one module per concept of the paper;
//! - [`analysis`]: the paper's measurements, pure, for both faces (live and offline);
//! - [`formats`]: the file formats both faces write and read (run.json, frame files, relaxed
//!   states, the code version), pure: bytes, no files;
//! - `gpu` (feature `gpu`): the model's stages as wgpu compute kernels, f32, beside `analysis`
//!   (imports only `model`);
//! - `run` (native, feature `cli`): files, runs, sweeps, the offline analysis, plots;
//! - [`web`]: the browser demo's view (native and wasm32), its binding and wgpu renderer (wasm32).
//!
//! The public API is curated, layer by layer: each layer's modules are private and its
//! `mod.rs` re-exports what the other layers, the `monolayer` binary, the tests and the page
//! use (`monolayer::model::FrictionSolver`, `monolayer::analysis::HoleTracker`,
//! `monolayer::run::RunDir`), so a file can move inside its layer without breaking a caller.
//! The core's few types are re-exported here too.
//!
//! A tissue relaxed, made active and measured (a small box; the paper's is
//! [`Params::default`]); `examples/` has longer programs:
//!
//! ```
//! use monolayer::analysis::Analysis;
//! use monolayer::{Monolayer, Params};
//!
//! let p = Params { box_size: 40, n_cells: 8, relax_steps: 100, active_steps: 20, ..Params::default() };
//! let mut m = Monolayer::new(p.clone(), 1)?;
//! m.advance(p.total_steps())?;
//! m.evaluate_now()?; // velocities for this φ, not the last step's
//! let mut a = Analysis::new(&p);
//! a.measure(&m);
//! let s = a.summary();
//! assert!(s.packing_fraction > 0.5 && s.mean_speed > 0.0);
//! # Ok::<(), monolayer::SimError>(())
//! ```

pub mod analysis;
pub mod formats;
pub mod model;

// The GPU stepper's stages on wgpu compute (feature `gpu`).
#[cfg(feature = "gpu")]
pub mod gpu;

// Files, runs and the command line (feature `cli`, native only: its dependencies are not built
// for wasm32).
#[cfg(all(feature = "cli", not(target_arch = "wasm32")))]
pub mod run;

// The browser demo (see `www/`): what it draws and measures, and on wasm32 its binding and
// wgpu drawing.
pub mod web;

pub use model::{Monolayer, Params, Phase, SimError, State};

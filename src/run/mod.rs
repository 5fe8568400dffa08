//! Native only (feature `cli`): everything that touches files, clocks and the terminal.
//!
//! - [`bench`](mod@bench): `monolayer bench`, stage by stage, and the two-thread ceiling;
//! - [`config`]: parameters from config files, `--set` and `--grid`, the one KEY=VALUE parser;
//! - [`error`]: the errors of this layer, by cause ([`RunError`]);
//! - [`files`]: frames, checkpoints and `run.json`, the writer and the reader of each together;
//! - [`runner`]: one run's protocol on disk (relaxation, activity, frames, checkpoints, resume);
//! - [`sweep`]: a grid of runs, one per core, resumable, its summary and regime map;
//! - [`figures`]: `monolayer figures`, the paper's figures from one plan of runs, here or on Slurm;
//! - [`offline`]: `monolayer analyze`, the tables of a run's frames; [`plots`]: its figures;
//! - [`forecast`]: `monolayer forecast`, thinning, matched chance and the held-out hole forecast.
//!
//! Uses `model` and `analysis`; nothing below it uses this layer.

pub mod bench;
pub mod config;
pub mod error;
pub mod figures;
pub mod files;
pub mod forecast;
pub mod offline;
pub mod plots;
pub mod runner;
pub mod sweep;

pub use error::{RunError, RunResult};

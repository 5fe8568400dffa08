//! Native only (feature `cli`): everything that touches files, clocks and the terminal.
//!
//! - `bench`: `monolayer bench`, stage by stage, and the two-thread ceiling ([`bench()`]);
//! - `console`: every line printed, a closed stdout or stderr a stop and not a panic ([`out`],
//!   [`note`]);
//! - `config`: parameters from config files, `--set` and `--grid`, the one KEY=VALUE parser
//!   ([`load_params`]);
//! - `error`: the errors of this layer, by cause ([`RunError`]);
//! - `files`: frames, checkpoints and `run.json`, the writer and the reader of each together;
//! - `branch`: `monolayer branch`, a new run from a run's state at a frame with parameters
//!   changed ([`create_branch`]);
//! - `runner`: one run's protocol on disk (relaxation, activity, frames, checkpoints, resume;
//!   [`RunDir`]);
//! - `sweep`: a grid of runs, one per core, resumable, its summary and regime map
//!   ([`SweepSpec`], [`run_sweep`]);
//! - [`figures`]: `monolayer figures`, the paper's figures from one plan of runs, here or on Slurm;
//! - `offline`: `monolayer analyze`, the tables of a run's frames ([`analyze_run`]); `plots`: its
//!   figures;
//! - `forecast`: `monolayer forecast`, thinning, matched chance and the held-out hole forecast
//!   ([`forecast()`]);
//! - `intervene`: `monolayer intervene`, branches before each nucleation with the motion changed,
//!   and the share that still tear ([`intervene()`]); `pool`: simulations one per core.
//!
//! Uses `model`, `analysis`, `formats` and `gpu`; nothing below it uses this layer. The modules
//! are private but for [`figures`], a pipeline of its own; what the binary and the tests use is
//! re-exported here.

mod bench;
mod branch;
mod config;
mod console;
mod csv;
mod error;
pub mod figures;
mod files;
mod forecast;
mod intervene;
mod offline;
mod plots;
mod pool;
mod runner;
mod sweep;

#[cfg(feature = "gpu")]
pub use bench::bench_gpu;
pub use bench::{bench, bench_analysis, BenchOptions};
pub use branch::{branch_params, create_branch, BranchOptions};
pub use config::{check_distinct, load_params, load_params_over, parse_assignment};
pub use console::{note, out, out_text, output_closed, Report};
pub use error::{RunError, RunResult};
pub use files::{
    checkpoint_path, frame_path, kept_checkpoint_path, read_checkpoint, read_frame, read_run_frame, replaceable,
    write_atomic, write_checkpoint, write_frame, write_run_checkpoint, Frame, RunFrames, RunLock,
};
pub use forecast::forecast;
pub use intervene::{intervene, Arm, InterveneOptions};
pub use offline::analyze_run;
pub use plots::Background;
pub use runner::{
    cgroup_room, check_frame_interval, check_memory, check_memory_of, check_memory_of_jobs, memory_estimate,
    parse_memory_limit_mb, stop_gracefully_on_signals, stop_signal, Event, RunDir,
};
pub use sweep::{
    jobs_of_runs, measure_existing, run_sweep, steps_to_run, sweep, tables, write_tables, Job, Output, RunSummary,
    Shard, SweepOptions, SweepSpec,
};

//! Parameter sweeps (`monolayer sweep`): a grid of runs, one simulation per core, each in its own
//! directory and analysed; resumable; a summary with one row per run and the regime map of the
//! paper's Fig. 3d. One stage per file, in order: `spec` (the sweep as given and the runs it
//! expands to), `pool` (the runs, one per core), `summary` (each run measured), `tables` (the
//! summary and the regime criterion), `map` (the regime map's figure), and `command` (the
//! `sweep` command, from its options to its tables and map, written together).

mod command;
mod map;
mod pool;
mod spec;
mod summary;
mod tables;

pub use command::{sweep, write_tables, SweepOptions};
pub use pool::{run_sweep, steps_to_run, Output};
pub use spec::{Job, Shard, SweepSpec};
pub use summary::{jobs_of_runs, measure_existing, RunSummary};
pub use tables::tables;

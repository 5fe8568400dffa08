//! The file formats, one home for each, shared by the two faces that write and read them:
//! `run` (native: `monolayer run`, `analyze`, `relaxed-state`) and `web` (the page's downloads,
//! the runs it opens, its shipped states). Pure: bytes and strings in and out, no files, so the
//! same code builds for wasm32; `run::files` adds the files (atomic writes, locks, the reader's
//! checks that name the path).
//!
//! - [`run_record`]: `run.json`, the record of a run ([`run_record::RunRecord`]);
//! - [`frame_file`]: frame files (`frames/frame_<step>.npz`), named by [`frame_file_name`];
//! - [`snapshot`]: a relaxed state as bytes (`www/assets/*.bin`, the page's confluent start);
//! - [`version`]: the code version every file records.
//!
//! Uses only `model`; `run` and `web` use it, nothing below them does (tested by
//! `tests/layers.rs`).

pub mod frame_file;
pub mod run_record;
pub mod snapshot;
pub mod version;

/// The name of the frame file of `step` in a run's `frames/` directory: `frame_0011000.npz`.
pub fn frame_file_name(step: u64) -> String {
    format!("frame_{step:07}.npz")
}

//! The file formats, one home for each, shared by the two faces that write and read them:
//! `run` (native: `monolayer run`, `analyze`, `relaxed-state`) and `web` (the page's downloads,
//! the runs it opens, its shipped states). Pure: bytes and strings in and out, no files, so the
//! same code builds for wasm32; `run::files` adds the files (atomic writes, locks, the reader's
//! checks that name the path).
//!
//! - `run_record`: `run.json`, the record of a run ([`RunRecord`]);
//! - `frame_file`: frame files (`frames/frame_<step>.npz`, [`encode_frame`], [`decode_frame`]),
//!   named by [`frame_file_name`];
//! - [`snapshot`]: a relaxed state as bytes (`www/assets/*.bin`, the page's confluent start);
//! - `version`: the code version every file records ([`code_version`]);
//! - `error`: what is wrong with a file's bytes, by cause ([`FormatError`]).
//!
//! Uses only `model`; `run` and `web` use it, nothing below them does (tested by
//! `tests/layers.rs`). The modules are private but for [`snapshot`], whose functions (`encode`,
//! `decode`, the keys) read best under its name; the rest is re-exported here.

mod error;
mod frame_file;
mod run_record;
pub mod snapshot;
mod version;

pub use error::{FormatError, FormatResult};
pub use frame_file::{
    check_finite, check_npz_headers, decode_frame, decode_frame_of_box, encode_frame, frame_bytes, frame_file_name,
    max_array_values, FrameData,
};
pub use run_record::{BranchOrigin, Engine, ParamChange, RunRecord, RunStatus, FORMAT, FORMAT_VERSION};
pub use version::{code_version, CRATE_VERSION, GIT_COMMIT};

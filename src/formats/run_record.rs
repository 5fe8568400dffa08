//! `run.json`, the record of a run: enough to reproduce it and to continue it. One type, written
//! by `monolayer run` (`run::files`, which adds the file, its atomic write and the strict
//! reader) and by the page for its downloads (`web::readouts`), so that both write the same keys
//! and the same `version`.

use serde::{Deserialize, Serialize};

use super::error::FormatError;
use super::version::code_version;
use crate::model::{Params, Perturbation, STORE_NAME};

/// The status of the page's downloads: `stopped: …` with this reason.
pub const PAGE_DOWNLOAD: &str = "the state of the browser page, downloaded";

/// Identifies the files of this program and the version of their layout.
pub const FORMAT: &str = "monolayer-run";
/// The version of that layout this program writes and reads.
pub const FORMAT_VERSION: u32 = 1;

/// How a run stands, as `run.json` records it: `"running"`, `"finished"`, `"failed: …"` or
/// `"stopped: …"` with the reason.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub enum RunStatus {
    /// Started and not ended (or killed).
    #[default]
    Running,
    Finished,
    /// The simulation itself failed (unstable, the friction solve did not converge): a result,
    /// the same on every rerun, so it is kept and not retried.
    Failed(String),
    /// The machine stopped it (a full disk, another IO error): the run itself is sound and
    /// continues from its checkpoint when run again.
    Stopped(String),
}

impl RunStatus {
    /// Ended for good: nothing more will run.
    pub fn is_complete(&self) -> bool {
        matches!(self, RunStatus::Finished | RunStatus::Failed(_))
    }

    pub fn blew_up(&self) -> bool {
        matches!(self, RunStatus::Failed(_))
    }
}

impl std::fmt::Display for RunStatus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RunStatus::Running => f.write_str("running"),
            RunStatus::Finished => f.write_str("finished"),
            RunStatus::Failed(why) => write!(f, "failed: {why}"),
            RunStatus::Stopped(why) => write!(f, "stopped: {why}"),
        }
    }
}

impl std::str::FromStr for RunStatus {
    type Err = FormatError;
    fn from_str(s: &str) -> Result<Self, FormatError> {
        match s {
            "running" => Ok(RunStatus::Running),
            "finished" => Ok(RunStatus::Finished),
            // Records written before `stopped` existed called an IO error `failed` too; an IO
            // error's text ends in its OS error code, which no simulation error has.
            _ if s.starts_with("failed: ") && s.contains("(os error ") => Ok(RunStatus::Stopped(s[8..].into())),
            _ if s.starts_with("failed: ") => Ok(RunStatus::Failed(s[8..].into())),
            _ if s.starts_with("stopped: ") => Ok(RunStatus::Stopped(s[9..].into())),
            _ => Err(FormatError::UnknownStatus(s.into())),
        }
    }
}

impl Serialize for RunStatus {
    fn serialize<S: serde::Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        s.collect_str(self)
    }
}

impl<'de> Deserialize<'de> for RunStatus {
    fn deserialize<D: serde::Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        String::deserialize(d)?.parse().map_err(serde::de::Error::custom)
    }
}

/// What steps a run: the CPU core (the reference, the same bits on every machine and thread
/// count), or the GPU stepper in f32 (`gpu::stepper::GpuRun`, feature `gpu`), whose runs agree
/// with the CPU's within f32 rounding step by step and are compared with them statistically
/// (docs/gpu.md).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Engine {
    Cpu,
    Gpu,
}

impl Engine {
    /// As `run.json` records it.
    pub fn name(self) -> &'static str {
        match self {
            Engine::Cpu => "cpu",
            Engine::Gpu => "gpu-f32",
        }
    }

    /// As `--engine` takes it.
    pub fn flag(self) -> &'static str {
        match self {
            Engine::Cpu => "cpu",
            Engine::Gpu => "gpu",
        }
    }

    pub fn parse(s: &str) -> Result<Self, FormatError> {
        match s {
            "cpu" => Ok(Engine::Cpu),
            "gpu" | "gpu-f32" => Ok(Engine::Gpu),
            other => Err(FormatError::UnknownEngine(other.into())),
        }
    }
}

fn storage_before_the_field() -> String {
    "f64".into()
}

/// The engine of records written before the GPU engine existed.
fn engine_before_the_field() -> String {
    Engine::Cpu.name().into()
}

/// What `run.json` records: enough to reproduce the run and to continue it.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct RunRecord {
    pub format: String,
    pub format_version: u32,
    /// Version of this program that wrote the run: the crate version and the git commit
    /// ([`code_version`]), the same string on both writers.
    pub version: String,
    /// The precision the cells' fields were stored in ([`STORE_NAME`]). A run continues only in
    /// the precision it started in. Records without it were written before f32 storage existed,
    /// by builds that stored f64.
    #[serde(default = "storage_before_the_field")]
    pub storage: String,
    /// The engine that steps the run ([`Engine`]): "cpu", the reference, or "gpu-f32"
    /// (feature `gpu`). A run continues only on the engine it started on. Empty: not recorded,
    /// and not written (the page's downloads, [`RunRecord::of_page`]); read back as "cpu", as
    /// records written before the field existed are.
    #[serde(default = "engine_before_the_field", skip_serializing_if = "String::is_empty")]
    pub engine: String,
    pub seed: u64,
    /// Steps between frames in the active phase.
    pub frame_interval: u64,
    pub status: RunStatus,
    /// Last step with a frame (None before the first).
    pub last_frame_step: Option<u64>,
    /// Every checkpoint kept (`DIR/checkpoints/`, one per frame and the end of the relaxation),
    /// not only the last: the states `monolayer branch` starts from without replaying the run.
    /// Absent (false) in records that keep only the last.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub keep_checkpoints: bool,
    /// Where the run was branched from (`monolayer branch`); absent for a run from the random
    /// disks.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub branch: Option<BranchOrigin>,
    pub params: Params,
}

/// Where a branched run comes from: its parent's state at a step, with parameters changed and φ
/// perturbed as recorded here. The branch's own steps continue the parent's count (its first
/// frame is the parent's `step`).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct BranchOrigin {
    /// The parent run's directory, as resolved when the branch was made.
    pub parent: String,
    /// The `version` of the parent's run.json.
    pub parent_version: String,
    /// The parent's step the branch starts from: one at which the parent wrote a frame.
    pub step: u64,
    /// Every parameter given a value, with the parent's value and the branch's.
    pub changes: Vec<ParamChange>,
    /// The noise added to φ at the start, if any.
    pub perturbation: Option<Perturbation>,
    /// Where the parent's state at `step` came from: a kept checkpoint, or the steps replayed
    /// from an earlier state (checked bit for bit against the parent's frame at `step`).
    pub source: String,
}

/// One parameter of a branch: its name, the parent's value and the branch's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ParamChange {
    pub key: String,
    pub parent: serde_json::Value,
    pub branch: serde_json::Value,
}

impl RunRecord {
    /// The record of a new native run (`monolayer run`), on the CPU engine until
    /// `runner::RunDir::with_engine` says otherwise.
    pub fn new(params: Params, seed: u64, frame_interval: u64) -> Self {
        RunRecord {
            format: FORMAT.into(),
            format_version: FORMAT_VERSION,
            version: code_version(),
            storage: STORE_NAME.into(),
            engine: engine_before_the_field(),
            seed,
            frame_interval,
            status: RunStatus::Running,
            last_frame_step: None,
            keep_checkpoints: false,
            branch: None,
            params,
        }
    }

    /// The record of the page's download (its Download button): the current state as a run of
    /// one frame at `step`, which `monolayer analyze` reads with the frame file beside it. It
    /// names no engine, as it never has (the page may step on either).
    pub fn of_page(params: Params, seed: u64, step: u64) -> Self {
        RunRecord {
            engine: String::new(),
            frame_interval: 1,
            status: RunStatus::Stopped(PAGE_DOWNLOAD.into()),
            last_frame_step: Some(step),
            ..RunRecord::new(params, seed, 1)
        }
    }

    /// The step of the run's first frame, from which its frames follow every `frame_interval`
    /// steps: the end of the relaxation (with no relaxation, one frame interval into the
    /// activity, as no frame is written before the first step), or the step a branch starts at
    /// (its own first frame). The page's download holds only the frame of its last step. Every
    /// reader of a run's frames checks that they start here: a run whose first frames are missing
    /// would be measured as a shorter one.
    pub fn first_frame_step(&self) -> u64 {
        if self.status == RunStatus::Stopped(PAGE_DOWNLOAD.into()) {
            return self.last_frame_step.unwrap_or(0);
        }
        if let Some(b) = &self.branch {
            return b.step;
        }
        match self.params.relax_steps {
            0 => self.frame_interval,
            relax => relax,
        }
    }

    /// `run.json` as `monolayer run` writes it: pretty-printed in the fields' order, a newline
    /// at the end.
    pub fn to_json(&self) -> String {
        let mut s = serde_json::to_string_pretty(self).expect("a run record serialises");
        s.push('\n');
        s
    }

    /// `run.json` as the page writes it: the same record with every table's keys in
    /// alphabetical order (the page's downloads always were; readers do not care, a byte
    /// comparison of two downloads does), a newline at the end.
    pub fn to_json_sorted(&self) -> String {
        let value = serde_json::to_value(self).expect("a run record serialises");
        let mut s = serde_json::to_string_pretty(&value).expect("a JSON value serialises");
        s.push('\n');
        s
    }
}

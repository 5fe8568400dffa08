//! The errors of this layer, by cause. Each one's `Display` is the message the user reads on
//! stderr (`error: …`), word for word as before the errors had types: tests and the docs match
//! parts of it.

use std::path::{Path, PathBuf};

use crate::formats::FormatError;
use crate::model::{ParamError, SimError};

/// What went wrong in a command of this layer.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The operating system refused a file or directory operation: `PATH: the OS's message`.
    #[error("{}: {source}", path.display())]
    Io {
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// A file or directory that is there but not what it must be (its kind, its size, its
    /// content): `PATH: what is wrong`.
    #[error("{}: {message}", path.display())]
    File { path: PathBuf, message: String },
    /// Text that does not parse (a config or sweep file, a KEY=VALUE, a list of names); the
    /// message names where.
    #[error("{0}")]
    Parse(String),
    /// A sweep that is not consistent (its seeds, grid, points or base): `sweep: what is wrong`.
    #[error("sweep: {0}")]
    Sweep(String),
    /// A plot that could not be drawn: `plot: the backend's error`.
    #[error("plot: {0}")]
    Plot(String),
    /// An option or a value outside what it takes: `NAME VALUE: must be ALLOWED`.
    #[error("{name} {value}: must be {allowed}")]
    Invalid { name: String, value: String, allowed: String },
    /// Parameters [`Params::validate`](crate::model::Params::validate) refuses.
    #[error(transparent)]
    Params(#[from] ParamError),
    /// The simulation failed.
    #[error(transparent)]
    Simulation(#[from] SimError),
    /// The GPU (its adapter, device, or a fault of its stepper).
    #[error("{0}")]
    Gpu(String),
    /// SIGTERM or SIGINT stopped the command: `stopped by SIGNAL…`, with what continues it.
    #[error("stopped by {signal}{detail}")]
    Interrupted { signal: &'static str, detail: String },
    /// A run went unstable: the error, and where its last good state and its last periodic
    /// checkpoint are.
    #[error(
        "{source}\n  the last good state is in {} (the last periodic one in {})",
        last_good.display(),
        checkpoint.display()
    )]
    Unstable {
        #[source]
        source: Box<RunError>,
        last_good: PathBuf,
        checkpoint: PathBuf,
    },
    /// Writing a run's files failed, not the run: it continues from its last checkpoint.
    #[error(
        "{source}\n  the run itself is sound: once this is fixed, `run --resume {}` (or the same sweep again) \
         continues it from its last checkpoint",
        dir.display()
    )]
    Resumable {
        #[source]
        source: Box<RunError>,
        dir: PathBuf,
    },
    /// Another error, with what was being done: `CONTEXT: the error`.
    #[error("{context}: {source}")]
    Context {
        context: String,
        #[source]
        source: Box<RunError>,
    },
    /// Options that do not make a command as given, beyond one value's range: two that set one
    /// parameter, a grid axis or a point's key given twice, a frame interval past the active
    /// phase, an output path an `#SBATCH` line cannot hold, a whole plan without `--yes`.
    #[error("{0}")]
    Options(String),
    /// A directory that holds a run other than the one asked for, or a run already: `DIR why`.
    #[error("{} {why}", dir.display())]
    OtherRun { dir: PathBuf, why: String },
    /// Two frame files of one run hold the same step.
    #[error(
        "{} and {} both hold step {step}: remove what this run did not write ({}; its own is {})",
        first.display(),
        second.display(),
        foreign.join(", "),
        own.display()
    )]
    DuplicateFrames { first: PathBuf, second: PathBuf, step: u64, foreign: Vec<String>, own: PathBuf },
    /// A simulation larger than the memory the process may use.
    #[error(
        "box_size = {box_size}, n_cells = {n_cells} need about {need_mb} MB{held}, more than {limit} \
         ({limit_mb} MB): lower box_size or n_cells"
    )]
    Memory { box_size: usize, n_cells: usize, need_mb: u64, held: String, limit: &'static str, limit_mb: u64 },
    /// A relaxed-state file (`--from-relaxed`) that cannot be read or is not the relaxation
    /// asked for: `--from-relaxed FILE: what is wrong`.
    #[error("--from-relaxed {0}")]
    FromRelaxed(String),
    /// Runs of a sweep that could not run, one line each (`NAME: error`, or the runs another
    /// process is writing).
    #[error("{}", .0.join("\n"))]
    Jobs(Vec<String>),
    /// Runs of a sweep stopped by an error of the machine, not of the run (left out of its
    /// tables): their names and errors.
    #[error(
        "{} run(s) stopped by an error that is not theirs (left out of regimes.csv):\n{}\nfix it, then run the \
         same command again: they continue from their checkpoints",
        .0.len(),
        .0.join("\n")
    )]
    Stopped(Vec<String>),
    /// The figures asked for runs of their plan that are not finished: how many of `total`, in
    /// `dir`, the first names with their status.
    #[error(
        "{} of the plan's {total} runs in {} are not finished: {}; run them first (`monolayer figures --stage runs` \
         with the same --scale, --only and --set, or the Slurm array)",
        missing.len(),
        dir.display(),
        first_five(missing)
    )]
    Unfinished { missing: Vec<String>, total: usize, dir: PathBuf },
    /// A forecast over runs in which no hole nucleates after their first frame: nothing to fit.
    #[error(
        "no hole nucleates after the first frame of any of the {runs} run(s) given ({nucleations} nucleation(s) in \
         all, none with a frame before it): there is nothing to fit or score, and nothing is written; give runs \
         in which holes open (a lower χ or a higher ζ: the regime map, docs/calibration.md)"
    )]
    NothingToForecast { runs: usize, nucleations: usize },
    /// A held-out forecast over runs of fewer than two seeds.
    #[error("the runs have {0} seed(s): leaving one seed out needs runs of at least two seeds")]
    TooFewSeeds(usize),
    /// `sbatch` could not be run or refused a script.
    #[error("{0}")]
    Slurm(String),
    /// A pool of worker threads could not be made.
    #[error(transparent)]
    Threads(#[from] rayon::ThreadPoolBuildError),
    /// The handlers of SIGTERM and SIGINT could not be installed.
    #[error("signal handler: {0}")]
    SignalHandler(#[source] std::io::Error),
    /// The default parameters could not be written as TOML.
    #[error(transparent)]
    Toml(#[from] toml::ser::Error),
    /// An option or argument that takes a list, given none: `NAME: give at least one NEED`.
    #[error("{name}: give at least one {need}")]
    Empty { name: &'static str, need: &'static str },
    /// A path option the operating system cannot resolve: `NAME PATH: the OS's message`.
    #[error("{name} {}: {source}", path.display())]
    OptionPath {
        name: &'static str,
        path: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The path of this program, which the Slurm jobs run, cannot be found.
    #[error("the path of this program: {0}")]
    CurrentExe(#[source] std::io::Error),
    /// `--snapshot STEP` names a step of no frame of the run: its `frames/` directory.
    #[error("--snapshot {step}: no frame of that step in {}", frames.display())]
    NoFrame { step: u64, frames: PathBuf },
    /// A directory given as a sweep's `--out` whose `runs/` cannot be read.
    #[error("{}: {source} (a sweep's runs are in OUT/runs; give --out of a sweep)", runs.display())]
    NotASweep {
        runs: PathBuf,
        #[source]
        source: std::io::Error,
    },
    /// The time of a run of the plan's sizes could not be measured: L, N and why.
    #[error("timing a run at L = {l}, N = {n}: {why}")]
    Timing { l: usize, n: usize, why: String },
    /// A worker thread panicked.
    #[error("panicked")]
    Panicked,
    /// A file's bytes that `crate::formats` refuses (a frame, a status, an engine), or a frame
    /// it could not encode.
    #[error(transparent)]
    Format(#[from] FormatError),
}

/// The first five of `names`, joined, with `, …` when there are more.
fn first_five(names: &[String]) -> String {
    let shown: Vec<&str> = names.iter().take(5).map(String::as_str).collect();
    format!("{}{}", shown.join(", "), if names.len() > shown.len() { ", …" } else { "" })
}

/// A result of this layer.
pub type RunResult<T> = Result<T, RunError>;

impl RunError {
    /// An I/O error on `path`.
    pub fn io(path: &Path, source: std::io::Error) -> Self {
        RunError::Io { path: path.to_path_buf(), source }
    }

    /// What is wrong with the file or directory `path`.
    pub fn file(path: &Path, message: impl std::fmt::Display) -> Self {
        RunError::File { path: path.to_path_buf(), message: message.to_string() }
    }

    /// `name value: must be allowed`.
    pub fn invalid(name: impl Into<String>, value: impl std::fmt::Display, allowed: impl Into<String>) -> Self {
        RunError::Invalid { name: name.into(), value: value.to_string(), allowed: allowed.into() }
    }

    /// This error prefixed by `context` (`CONTEXT: error`).
    pub fn context(self, context: impl Into<String>) -> Self {
        RunError::Context { context: context.into(), source: Box::new(self) }
    }

    /// A GPU error, as its message.
    pub fn gpu(e: impl std::fmt::Display) -> Self {
        RunError::Gpu(e.to_string())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn messages_are_the_old_strings() {
        let p = Path::new("/x/run.json");
        let io = std::io::Error::new(std::io::ErrorKind::NotFound, "gone");
        assert_eq!(RunError::io(p, io).to_string(), "/x/run.json: gone");
        assert_eq!(RunError::file(p, "not valid JSON").to_string(), "/x/run.json: not valid JSON");
        assert_eq!(RunError::invalid("--jobs", 0, "≥ 1").to_string(), "--jobs 0: must be ≥ 1");
        assert_eq!(RunError::Parse("boom".into()).context("run a").to_string(), "run a: boom");
        let stop = RunError::Interrupted { signal: "SIGTERM", detail: ": again".into() };
        assert_eq!(stop.to_string(), "stopped by SIGTERM: again");
    }

    /// The variants that replaced one-off messages print what the messages printed, each
    /// compared here with the format it replaced.
    #[test]
    fn the_former_one_off_messages_are_unchanged() {
        let dir = Path::new("/x/runs/a");
        let why = "was run with other parameters or seed than this sweep gives it: use another --out";
        assert_eq!(
            RunError::OtherRun { dir: dir.into(), why: why.into() }.to_string(),
            format!(
                "{} was run with other parameters or seed than this sweep gives it: use another --out",
                dir.display()
            )
        );
        let (first, second, own) = (dir.join("f_1.npz"), dir.join("f_2.npz"), dir.join("frames/f_1.npz"));
        let foreign = vec![second.display().to_string()];
        let step = 1000;
        assert_eq!(
            RunError::DuplicateFrames {
                first: first.clone(),
                second: second.clone(),
                step,
                foreign: foreign.clone(),
                own: own.clone()
            }
            .to_string(),
            format!(
                "{} and {} both hold step {step}: remove what this run did not write ({}; its own is {})",
                first.display(),
                second.display(),
                foreign.join(", "),
                own.display()
            )
        );
        let (held, what) = (" for the 2 simulations held at once".to_string(), "MemAvailable");
        assert_eq!(
            RunError::Memory { box_size: 140, n_cells: 100, need_mb: 300, held: held.clone(), limit: what, limit_mb: 200 }
                .to_string(),
            format!(
                "box_size = {}, n_cells = {} need about {} MB{held}, more than {what} ({} MB): lower box_size or n_cells",
                140, 100, 300, 200
            )
        );
        assert_eq!(RunError::FromRelaxed("f.bin: no".into()).to_string(), "--from-relaxed f.bin: no");
        let lines = vec!["a: one".to_string(), "b: two".to_string()];
        assert_eq!(RunError::Jobs(lines.clone()).to_string(), lines.join("\n"));
        assert_eq!(
            RunError::Stopped(lines.clone()).to_string(),
            format!(
                "{} run(s) stopped by an error that is not theirs (left out of regimes.csv):\n{}\nfix it, then run the \
                 same command again: they continue from their checkpoints",
                lines.len(),
                lines.join("\n")
            )
        );
        for n in [2, 5, 7] {
            let missing: Vec<String> = (0..n).map(|k| format!("run{k} (not started)")).collect();
            let shown: Vec<&str> = missing.iter().take(5).map(String::as_str).collect();
            let old = format!(
                "{} of the plan's {} runs in {} are not finished: {}{}; run them first (`monolayer figures --stage runs` with the same --scale, --only and --set, or the Slurm array)",
                missing.len(),
                9,
                dir.display(),
                shown.join(", "),
                if missing.len() > shown.len() { ", …" } else { "" }
            );
            assert_eq!(RunError::Unfinished { missing, total: 9, dir: dir.into() }.to_string(), old);
        }
        assert_eq!(
            RunError::TooFewSeeds(1).to_string(),
            "the runs have 1 seed(s): leaving one seed out needs runs of at least two seeds"
        );
        let e = std::io::Error::other("refused");
        assert_eq!(RunError::SignalHandler(e).to_string(), "signal handler: refused");
    }

    /// The variants that replaced the texts converted into a catch-all message print what those
    /// texts printed, each compared here with the format it replaced.
    #[test]
    fn the_former_catch_all_messages_are_unchanged() {
        assert_eq!(RunError::Empty { name: "--chi", need: "value" }.to_string(), "--chi: give at least one value");
        assert_eq!(
            RunError::Empty { name: "RUN_DIR", need: "run directory" }.to_string(),
            "RUN_DIR: give at least one run directory"
        );
        let out = Path::new("/x/out");
        let e = || std::io::Error::other("refused");
        assert_eq!(
            RunError::OptionPath { name: "--out", path: out.into(), source: e() }.to_string(),
            format!("--out {}: {}", out.display(), e())
        );
        assert_eq!(RunError::CurrentExe(e()).to_string(), format!("the path of this program: {}", e()));
        let frames = Path::new("/x/run/frames");
        assert_eq!(
            RunError::NoFrame { step: 7000, frames: frames.into() }.to_string(),
            format!("--snapshot {}: no frame of that step in {}", 7000, frames.display())
        );
        let runs = out.join("runs");
        assert_eq!(
            RunError::NotASweep { runs: runs.clone(), source: e() }.to_string(),
            format!("{}: {} (a sweep's runs are in OUT/runs; give --out of a sweep)", runs.display(), e())
        );
        let last = "box_size = 8: must be ≥ 16";
        assert_eq!(
            RunError::Timing {
                l: 400,
                n: 600,
                why: format!("every job of this size and the defaults failed ({last})")
            }
            .to_string(),
            format!(
                "timing a run at L = {}, N = {}: every job of this size and the defaults failed ({last})",
                400, 600
            )
        );
        assert_eq!(
            RunError::Timing { l: 400, n: 600, why: "no seed of 1–10 starts".into() }.to_string(),
            format!("timing a run at L = {}, N = {}: no seed of 1–10 starts", 400, 600)
        );
        assert_eq!(RunError::Panicked.to_string(), "panicked");
        let f = FormatError::UnknownEngine("tpu".into());
        assert_eq!(RunError::Format(f).to_string(), "engine \"tpu\": must be cpu or gpu");
        // Parameters refused in a context: what `format!("{context}: {e}")` printed.
        let p = ParamError { name: "zeta", value: "-1".into(), allowed: "must be ≥ 0".into() };
        let text = format!("--set: {p}");
        assert_eq!(RunError::Params(p).context("--set").to_string(), text);
        // The one-off texts now typed as existing variants.
        assert_eq!(RunError::invalid("--jobs", 0, "≥ 1").to_string(), "--jobs 0: must be ≥ 1");
    }
}

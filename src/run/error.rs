//! The errors of this layer, by cause. Each one's `Display` is the message the user reads on
//! stderr (`error: …`), word for word as before the errors had types: tests and the docs match
//! parts of it.

use std::path::{Path, PathBuf};

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
    /// A message built in a shape of its own (several causes listed, a plot backend's error).
    #[error("{0}")]
    Message(String),
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

/// The messages of the layers below that report errors as text (`crate::formats`).
impl From<String> for RunError {
    fn from(message: String) -> Self {
        RunError::Message(message)
    }
}

impl From<&str> for RunError {
    fn from(message: &str) -> Self {
        RunError::Message(message.to_string())
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
        assert_eq!(RunError::from("boom").context("run a").to_string(), "run a: boom");
        let stop = RunError::Interrupted { signal: "SIGTERM", detail: ": again".into() };
        assert_eq!(stop.to_string(), "stopped by SIGTERM: again");
    }
}

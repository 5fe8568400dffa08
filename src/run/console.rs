//! The terminal: every line the commands print goes through here, so that a closed stdout or
//! stderr (`monolayer … | head -0`) is a stop asked for, not a panic. Rust ignores SIGPIPE, so a
//! write to a closed pipe fails with EPIPE (and `println!` panics on it); here it stops the
//! command as the signal would have: a run records `stopped: signal SIGPIPE` at its next step
//! and resumes later, and the process ends with 141 (128 + SIGPIPE), as a shell reports a
//! writer the signal ended.

use std::fmt::Display;
use std::io::Write;
use std::sync::atomic::{AtomicBool, Ordering};

use crate::run::error::RunError;

static CLOSED: AtomicBool = AtomicBool::new(false);

/// What a long command (`sweep`, `intervene`) reports as it goes, for the binary to show: a line,
/// or its progress.
pub enum Report {
    Line(String),
    /// `steps` of the `of` steps to run have run, and `done` of the `runs` runs (or branches)
    /// have ended.
    Progress {
        steps: u64,
        of: u64,
        done: usize,
        runs: usize,
    },
}

/// Whether a write to stdout or stderr found it closed (EPIPE): the process is to stop.
pub fn output_closed() -> bool {
    CLOSED.load(Ordering::SeqCst)
}

/// Writes `line` and a newline to `stream`; a broken pipe is recorded in `closed` as a stop
/// asked for.
fn write_line(mut stream: impl Write, line: impl Display, closed: &AtomicBool) -> std::io::Result<()> {
    let written = writeln!(stream, "{line}").and_then(|_| stream.flush());
    if let Err(e) = &written {
        if e.kind() == std::io::ErrorKind::BrokenPipe {
            closed.store(true, Ordering::SeqCst);
        }
    }
    written
}

/// A line of a command's result on stdout (the files written, a fingerprint, a table). A closed
/// stdout stops the command: the error says so, and the process ends with 141.
pub fn out(line: impl Display) -> Result<(), RunError> {
    write_line(std::io::stdout().lock(), line, &CLOSED).map_err(|e| match e.kind() {
        std::io::ErrorKind::BrokenPipe => RunError::Interrupted {
            signal: "SIGPIPE",
            detail: ": stdout was closed (a broken pipe); what was written is complete".into(),
        },
        _ => RunError::Io { path: "stdout".into(), source: e },
    })
}

/// Text of a command's result on stdout as it is, with no newline added ([`out`]).
pub fn out_text(text: &str) -> Result<(), RunError> {
    out(text.strip_suffix('\n').unwrap_or(text))
}

/// A line on stderr that nothing depends on (progress, a warning, the final error): never
/// fails. A closed stderr asks the process to stop, as a closed stdout does: a run stops at its
/// next step with `stopped: signal SIGPIPE`.
pub fn note(line: impl Display) {
    let _ = write_line(std::io::stderr().lock(), line, &CLOSED);
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A write to a pipe whose reader is gone asks for the stop, and only a broken pipe does.
    #[test]
    fn a_broken_pipe_is_a_stop_and_other_errors_are_not() {
        struct Failing(std::io::ErrorKind);
        impl Write for Failing {
            fn write(&mut self, _: &[u8]) -> std::io::Result<usize> {
                Err(self.0.into())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        let closed = AtomicBool::new(false);
        assert!(write_line(Failing(std::io::ErrorKind::StorageFull), "x", &closed).is_err());
        assert!(!closed.load(Ordering::SeqCst));
        assert!(write_line(Failing(std::io::ErrorKind::BrokenPipe), "x", &closed).is_err());
        assert!(closed.load(Ordering::SeqCst));
    }
}

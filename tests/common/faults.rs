//! What the reliability tests share (tests/reliability_*.rs): small runs, the checks of a
//! refusal, a run's record edited by hand, a run as a kill leaves it, a full disk by
//! `ulimit -f`, a child process caught in the act.

use std::fs;
use std::path::Path;
use std::process::{Command, Output};
use std::time::Duration;

use monolayer::formats::RunRecord;
use monolayer::run::{checkpoint_path, write_checkpoint};
use monolayer::Monolayer;

use super::{arg, monolayer, stderr};

/// A small quick protocol: 6 cells on a 48×48 box, on one thread, relaxation to step 100.
pub const SMALL_RUN: [&str; 10] =
    ["run", "--quiet", "--threads", "1", "--set", "box_size=48", "--set", "n_cells=6", "--relax-steps", "100"];

/// The tiny box of the input checks.
pub const TINY: [&str; 6] = ["--set", "box_size=48", "--set", "n_cells=10", "--relax-steps", "20"];

/// A sweep of two small runs, ζ = 0.2 and 0.4, frames every 50 steps from step 100 to 200.
pub const SPEC: &str = r#"
seeds = [1]
frame_interval = 50
[base]
box_size = 48
n_cells = 6
relax_steps = 100
active_steps = 100
[grid]
zeta = [0.2, 0.4]
"#;

/// The same sweep as command-line options (after `sweep --out OUT`).
pub const SWEEP_ARGS: [&str; 12] = [
    "--grid",
    "zeta=0.2,0.4",
    "--frame-interval",
    "50",
    "--set",
    "box_size=48",
    "--set",
    "n_cells=6",
    "--set",
    "relax_steps=100",
    "--set",
    "active_steps=100",
];

/// [`SMALL_RUN`] for `active_steps`, frames every 50 steps.
pub fn small(out: &Path, active_steps: u64, extra: &[&str]) -> Output {
    let steps = active_steps.to_string();
    let mut args = SMALL_RUN.to_vec();
    args.extend(["--steps", &steps, "--frame-interval", "50", "--out", arg(out)]);
    args.extend_from_slice(extra);
    monolayer(&args)
}

/// `monolayer analyze RUN --out OUT`.
pub fn analyzed(run: &Path, out: &Path) -> Output {
    monolayer(&["analyze", arg(run), "--out", arg(out)])
}

pub fn ok(o: &Output) {
    assert!(o.status.success(), "{}", stderr(o));
}

/// Refused as the command line refuses: status 2, every expected text in the error, no panic.
pub fn refused(o: &Output, expect: &[&str]) {
    assert_eq!(o.status.code(), Some(2), "{}", stderr(o));
    for e in expect {
        assert!(stderr(o).contains(e), "expected “{e}” in: {}", stderr(o));
    }
    assert!(!stderr(o).contains("panicked"), "{}", stderr(o));
}

/// A refusal within a minute, with every expected text in its error.
pub fn refused_within(args: &[&str], env: &[(&str, &str)], expect: &[&str]) {
    refused(&super::monolayer_within(60, args, env), expect);
}

/// The `monolayer` binary under a file-size limit, the way a full disk looks to it: every write
/// past `blocks_of_512` blocks fails (with the signal that would kill it ignored, as a full
/// disk sends none).
pub fn with_file_size_limit(blocks_of_512: u32, args: &[&str]) -> Output {
    let script = format!("trap '' XFSZ; ulimit -f {blocks_of_512}; exec \"$0\" \"$@\"");
    Command::new("sh").arg("-c").arg(script).arg(super::BIN).args(args).output().expect("sh runs")
}

/// Edits `DIR/run.json` as a user's editor would.
pub fn edit_record(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join("run.json");
    let mut v: serde_json::Value = serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut v);
    fs::write(&path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

/// The run in `dir` as if killed right after its checkpoint of `step`: checkpoint at `step`, the
/// record still running, the frames after `step` left as they were.
pub fn killed_at(dir: &Path, step: u64) {
    let record = RunRecord::load(dir).unwrap();
    let mut m = Monolayer::new(record.params.clone(), record.seed).unwrap();
    m.advance(step).unwrap();
    write_checkpoint(&m, &checkpoint_path(dir)).unwrap();
    edit_record(dir, |v| {
        v["status"] = "running".into();
        v["last_frame_step"] = step.into();
    });
}

/// Waits until `path` exists, however long that takes (no test depends on the machine's speed):
/// the child ending before it writes the file is the failure.
pub fn wait_for_file(child: &mut std::process::Child, path: &Path, what: &str) {
    while !path.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("{what} ended ({status}) before writing {}", path.display());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// Waits until the child has installed its handler of `signal` (its number; SigCgt in
/// /proc/PID/status), so that the signal sent next is caught, not fatal: the child ending
/// first is the failure.
pub fn wait_for_handler(child: &mut std::process::Child, signal: u32) {
    let status = format!("/proc/{}/status", child.id());
    loop {
        if let Some(s) = child.try_wait().unwrap() {
            panic!("the child ended ({s}) before it caught signal {signal}");
        }
        let caught = fs::read_to_string(&status).ok().and_then(|text| {
            let mask = text.lines().find_map(|l| l.strip_prefix("SigCgt:"))?.trim().to_string();
            u64::from_str_radix(&mask, 16).ok()
        });
        if caught.is_some_and(|mask| mask & (1 << (signal - 1)) != 0) {
            return;
        }
        std::thread::sleep(Duration::from_millis(1));
    }
}

/// Sends `signal` (`TERM`, `INT`) to the child.
pub fn send(child: &std::process::Child, signal: &str) {
    let sent = Command::new("kill").args([&format!("-{signal}"), &child.id().to_string()]).status().unwrap();
    assert!(sent.success(), "kill -{signal}");
}

/// Every file of `dir` (not its folders) by name, with its bytes: a set of outputs compared whole.
pub fn files_of(dir: &Path) -> std::collections::BTreeMap<String, Vec<u8>> {
    fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.is_file())
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), fs::read(&p).unwrap()))
        .collect()
}

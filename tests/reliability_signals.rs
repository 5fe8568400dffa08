//! Signals and closed pipes: SIGTERM and SIGINT (Slurm's time limit, `scancel`, Ctrl-C) stop a
//! command after the step under way, with what continues it; a closed stdout or stderr
//! (`… | head -0`) is a stop too, never a panic. Each test sends the real signal or closes the
//! real pipe, and fails without its fix.

mod common;

use std::fs;
use std::path::Path;
use std::process::{Output, Stdio};

use common::faults::{ok, send, wait_for_file, wait_for_handler, SMALL_RUN, SWEEP_ARGS};
use common::{arg, monolayer, stderr};
use monolayer::formats::{RunRecord, RunStatus};
use monolayer::run::{checkpoint_path, frame_path};

/// SIGTERM and SIGINT, sent for real to a running `monolayer run`, stop it
/// after the step under way with `stopped: signal …` and the shell's status (143, 130); the
/// resume ends with the same bits as a run never stopped.
#[test]
fn a_signal_stops_a_run_gracefully_and_it_resumes_to_the_same_bits() {
    let dir = tempfile::tempdir().unwrap();
    let args = |out: &Path| -> Vec<String> {
        let mut v: Vec<String> = SMALL_RUN.iter().map(|s| s.to_string()).collect();
        v.extend(["--steps", "3000", "--frame-interval", "50", "--out", arg(out)].map(String::from));
        v
    };
    let whole = dir.path().join("whole");
    ok(&monolayer(&args(&whole).iter().map(String::as_str).collect::<Vec<_>>()));
    for (signal, status) in [("TERM", 143), ("INT", 130)] {
        let run = dir.path().join(signal);
        let mut child =
            common::command().args(args(&run)).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
        // Once it is in its active phase (a frame written), the signal.
        wait_for_file(&mut child, &frame_path(&run, 200), "the run");
        send(&child, signal);
        let o = child.wait_with_output().unwrap();
        assert_eq!(o.status.code(), Some(status), "SIG{signal}: {}", stderr(&o));
        assert!(stderr(&o).contains(&format!("stopped by SIG{signal}")), "{}", stderr(&o));
        let record = RunRecord::load(&run).unwrap();
        assert_eq!(record.status, RunStatus::Stopped(format!("signal SIG{signal}")), "SIG{signal}");
        assert!(record.last_frame_step.unwrap() < 3100, "SIG{signal}: it stopped early");
        ok(&monolayer(&["run", "--quiet", "--resume", arg(&run)]));
        for step in [200, 1600, 3100] {
            let (a, b) = (frame_path(&whole, step), frame_path(&run, step));
            assert!(fs::read(a).unwrap() == fs::read(b).unwrap(), "SIG{signal}: frame {step} differs");
        }
        assert!(fs::read(checkpoint_path(&whole)).unwrap() == fs::read(checkpoint_path(&run)).unwrap());
    }
}

/// In a sweep: SIGTERM stops the run under way (`stopped: signal SIGTERM`),
/// starts no other, exits 143; the same command again finishes both.
#[test]
fn a_signal_stops_a_sweep_and_the_same_command_finishes_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    // The shared small sweep, its active phase long enough to be stopped part way.
    let mut args = vec!["sweep", "--quiet", "--jobs", "1", "--out", arg(&out)];
    args.extend_from_slice(&SWEEP_ARGS[..SWEEP_ARGS.len() - 1]);
    args.push("active_steps=3000");
    assert_eq!(SWEEP_ARGS[SWEEP_ARGS.len() - 1], "active_steps=100");
    let mut child = common::command().args(&args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    let first = out.join("runs/zeta0.2_seed1");
    wait_for_file(&mut child, &frame_path(&first, 200), "the sweep");
    send(&child, "TERM");
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(143), "{}", stderr(&o));
    assert!(stderr(&o).contains("stopped by SIGTERM"), "{}", stderr(&o));
    assert_eq!(RunRecord::load(&first).unwrap().status, RunStatus::Stopped("signal SIGTERM".into()));
    assert!(!out.join("runs/zeta0.4_seed1").exists(), "no run starts after the signal");
    ok(&monolayer(&args));
    for run in ["zeta0.2_seed1", "zeta0.4_seed1"] {
        assert_eq!(RunRecord::load(&out.join("runs").join(run)).unwrap().status, RunStatus::Finished);
    }
}

/// SIGTERM while `figures --stage figures` draws: it stops with 143, as the docs say, and
/// moves no figure into place; the same command again draws them.
#[test]
fn a_signal_stops_the_figures_stage_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let figs = dir.path().join("f");
    let args = |stage: &'static str| -> Vec<String> {
        ["figures", "--only", "S3", "--quiet", "--jobs", "1", "--set", "relax_steps=50", "--set", "active_steps=1000"]
            .iter()
            .map(|s| s.to_string())
            .chain(["--stage".into(), stage.into(), "--out".into(), arg(&figs).into()])
            .collect()
    };
    ok(&monolayer(&args("runs").iter().map(String::as_str).collect::<Vec<_>>()));
    let mut child =
        common::command().args(args("figures")).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
    // Caught from the start, the signal comes while the runs' frames (21 each) are measured.
    wait_for_handler(&mut child, 15);
    send(&child, "TERM");
    let o = child.wait_with_output().unwrap();
    assert_eq!(o.status.code(), Some(143), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("stopped by SIGTERM") && stderr(&o).contains("the same command again"),
        "{}",
        stderr(&o)
    );
    let drawn: Vec<_> = fs::read_dir(&figs).unwrap().map(|e| e.unwrap().file_name()).filter(|n| n != "runs").collect();
    assert!(drawn.is_empty(), "written despite the signal: {drawn:?}");
    ok(&monolayer(&args("figures").iter().map(String::as_str).collect::<Vec<_>>()));
    assert!(figs.join("figures.md").is_file());
}

/// `args` run with its stdout a pipe whose reader is gone (`… | head -0`), and its stderr too
/// with `both` (`… |& head -0`): every write fails, from the first. What it wrote to stderr
/// otherwise.
fn with_output_closed(args: &[&str], both: bool) -> Output {
    let closed = || {
        let (reader, writer) = std::io::pipe().unwrap();
        drop(reader);
        Stdio::from(writer)
    };
    let mut command = common::command();
    command.args(args).stdout(closed());
    if both {
        command.stderr(closed());
    }
    command.output().unwrap()
}

/// Status 141 (128 + SIGPIPE, as a shell reports a writer the signal ended), not a panic (101).
fn stopped_by_the_pipe(o: &Output) {
    assert_eq!(o.status.code(), Some(141), "{:?}: {}", o.status, stderr(o));
    assert!(!stderr(o).contains("panicked"), "{}", stderr(o));
}

/// A closed stdout or stderr stops `run` as SIGPIPE would: `stopped: signal SIGPIPE`, status
/// 141, never a panic (101) with the record left `running`; the resume ends the run. `analyze`,
/// `sweep`, `forecast`, `bench` and `params` end with 141 too, what they write written whole.
#[test]
fn a_closed_output_is_a_stop_not_a_panic() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    let args = [&SMALL_RUN[..], &["--steps", "3000", "--frame-interval", "50", "--out", arg(&run)]].concat();
    stopped_by_the_pipe(&with_output_closed(&args, true));
    let record = RunRecord::load(&run).unwrap();
    assert_eq!(record.status, RunStatus::Stopped("signal SIGPIPE".into()));
    assert!(record.last_frame_step.is_some_and(|s| s < 3100), "{record:?}");
    // A resume that cannot say it resumes stops at once.
    stopped_by_the_pipe(&with_output_closed(&["run", "--quiet", "--resume", arg(&run)], true));
    assert_eq!(RunRecord::load(&run).unwrap().last_frame_step, record.last_frame_step);
    ok(&monolayer(&["run", "--quiet", "--resume", arg(&run)]));
    assert_eq!(RunRecord::load(&run).unwrap().status, RunStatus::Finished);

    // The files are written before their paths are printed.
    let out = dir.path().join("a");
    stopped_by_the_pipe(&with_output_closed(&["analyze", arg(&run), "--out", arg(&out)], false));
    assert!(out.join("frames.csv").is_file());
    let sweep = dir.path().join("s");
    let args = [&["sweep", "--quiet", "--jobs", "1", "--out", arg(&sweep)][..], &SWEEP_ARGS].concat();
    stopped_by_the_pipe(&with_output_closed(&args, false));
    assert!(sweep.join("summary.csv").is_file());
    let (a, b) = (dir.path().join("fa"), dir.path().join("fb"));
    for (run, seed) in [(&a, "1"), (&b, "2")] {
        ok(&common::small_run(run, "60", &["--seed", seed]));
        common::tear_open_a_hole(run, 3, 330);
    }
    let forecast = dir.path().join("f");
    stopped_by_the_pipe(&with_output_closed(&["forecast", arg(&a), arg(&b), "--out", arg(&forecast)], false));
    assert!(forecast.join("forecast.csv").is_file());
    let bench =
        ["bench", "--steps", "2", "--blocks", "1", "--chi", "0.1", "--relax-steps", "5", "--set", "box_size=48"];
    stopped_by_the_pipe(&with_output_closed(&[&bench[..], &["--set", "n_cells=6"]].concat(), false));
    stopped_by_the_pipe(&with_output_closed(&["params"], false));
    // A sweep that cannot say what it starts starts nothing.
    let quiet = dir.path().join("q");
    let args = [&["sweep", "--quiet", "--jobs", "1", "--out", arg(&quiet)][..], &SWEEP_ARGS].concat();
    stopped_by_the_pipe(&with_output_closed(&args, true));
    assert!(!quiet.join("runs/zeta0.2_seed1/run.json").exists());
}

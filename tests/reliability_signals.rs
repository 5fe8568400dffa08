//! Signals and closed pipes: SIGTERM and SIGINT (Slurm's time limit, `scancel`, Ctrl-C) stop a
//! command after the step under way, with what continues it; a closed stdout or stderr
//! (`… | head -0`) is a stop too, never a panic. Each test sends the real signal or closes the
//! real pipe, and fails without its fix.

mod common;

use std::fs;
use std::path::Path;
use std::process::Stdio;

use common::faults::{ok, send, wait_for_file, SMALL_RUN};
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
    let args = [
        "sweep",
        "--quiet",
        "--jobs",
        "1",
        "--out",
        arg(&out),
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
        "active_steps=3000",
    ];
    let mut child = common::command().args(args).stdout(Stdio::null()).stderr(Stdio::piped()).spawn().unwrap();
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

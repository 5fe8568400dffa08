//! The command line as a user drives it: errors, frames, resume, and a run that blows up.

mod common;

use std::path::Path;

use common::{monolayer, stderr};

/// A small, quick version of the protocol.
const SMALL: [&str; 10] =
    ["--set", "box_size=60", "--set", "n_cells=18", "--relax-steps", "200", "--chi", "0.01", "--threads", "2"];

#[test]
fn bad_parameters_are_refused_with_their_name_and_range() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("run");
    let out = out.to_str().unwrap();
    let o = monolayer(&["run", "--set", "dt=0", "--out", out]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("`dt`") && stderr(&o).contains("(0, 0.5]"), "{}", stderr(&o));
    assert!(!Path::new(out).exists(), "nothing may be written for a bad config");

    let o = monolayer(&["run", "--set", "zeta_typo=1", "--out", out]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("zeta_typo"), "{}", stderr(&o));

    let cfg = dir.path().join("bad.toml");
    std::fs::write(&cfg, "n_cells = 300\n").unwrap();
    let o = monolayer(&["run", "--config", cfg.to_str().unwrap(), "--out", out]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("`n_cells`"), "{}", stderr(&o));

    let o = monolayer(&["run", "--config", "/no/such/file.toml", "--out", out]);
    assert!(stderr(&o).contains("/no/such/file.toml"), "{}", stderr(&o));
}

/// A run interrupted after its checkpoint and resumed writes the same final frame and checkpoint,
/// bit for bit, as a run that went straight through.
#[test]
fn resume_continues_bit_identically() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    let run = |out: &Path, steps: &str| {
        let mut args =
            vec!["run", "--quiet", "--frame-interval", "50", "--steps", steps, "--out", out.to_str().unwrap()];
        args.extend(SMALL);
        let o = monolayer(&args);
        assert!(o.status.success(), "{}", stderr(&o));
    };
    run(&a, "100");
    // b stops at step 250, as if killed there; its record says the run was meant to go on.
    run(&b, "50");
    let record = b.join("run.json");
    let text = std::fs::read_to_string(&record).unwrap();
    std::fs::write(&record, text.replace("\"active_steps\": 50", "\"active_steps\": 100")).unwrap();
    let o = monolayer(&["run", "--quiet", "--resume", b.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(stderr(&o).contains("resuming"), "{}", stderr(&o));
    for f in ["checkpoint.npz", "frames/frame_0000300.npz", "frames/frame_0000250.npz"] {
        let (x, y) = (std::fs::read(a.join(f)).unwrap(), std::fs::read(b.join(f)).unwrap());
        assert!(x == y, "{f} differs after resume");
    }
    let record: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(b.join("run.json")).unwrap()).unwrap();
    assert_eq!(record["status"], "finished");
    assert_eq!(record["last_frame_step"], 300);
    // An existing run is never overwritten.
    let o = monolayer(&["run", "--out", a.to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--resume"), "{}", stderr(&o));
}

/// Resuming something that is not a run says what is wrong.
#[test]
fn resume_refuses_foreign_directories() {
    let dir = tempfile::tempdir().unwrap();
    let o = monolayer(&["run", "--resume", dir.path().to_str().unwrap()]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("run.json"), "{}", stderr(&o));
    std::fs::write(dir.path().join("run.json"), "{\"format\": \"something-else\"}").unwrap();
    let o = monolayer(&["run", "--resume", dir.path().to_str().unwrap()]);
    assert!(stderr(&o).contains("not a record of this program"), "{}", stderr(&o));
}

/// A run that goes unstable stops, says when and where, and keeps the last good state. (Presence
/// weights: under the default subdomain weights this overdriven tissue stops on a cell stretched
/// across the box instead, another stop with the same guarantees.)
#[test]
fn instability_stops_with_step_cell_and_last_good_state() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("blowup");
    let mut args = vec!["run", "--quiet", "--steps", "2000", "--zeta", "8", "--set", "q_magnitude=2"];
    args.extend(["--set", "friction_weights=presence", "--out"]);
    args.push(out.to_str().unwrap());
    args.extend(SMALL);
    let o = monolayer(&args);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let e = stderr(&o);
    assert!(e.contains("unstable at step") && e.contains("cell") && e.contains("phi"), "{e}");
    assert!(out.join("last_good_state.npz").exists());
    let record = std::fs::read_to_string(out.join("run.json")).unwrap();
    assert!(record.contains("failed: unstable"), "{record}");
}

/// A cell whose patch can no longer follow it (here one relaxed cell with a margin of 9 sites
/// needs a 44-site patch on a 40-site box at the first active step) stops the run, and the last good state is the state from before that step: the same
/// cells and step as the checkpoint written when relaxation ended, not a half re-laid one.
#[test]
fn a_lost_cell_stops_with_the_state_from_before_its_step() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("lost");
    let o = monolayer(&[
        "run",
        "--quiet",
        "--set",
        "box_size=40",
        "--set",
        "n_cells=1",
        "--set",
        "patch_margin=9",
        "--set",
        "relax_patch_size=38",
        "--relax-steps",
        "1000",
        "--steps",
        "50",
        "--out",
        out.to_str().unwrap(),
    ]);
    let e = stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("step 1000: cell 0 spans the box") && e.contains("the state before this step is kept"), "{e}");
    let saved = monolayer::run::read_checkpoint(&out.join("last_good_state.npz"), 40).unwrap();
    let relaxed = monolayer::run::read_checkpoint(&out.join("checkpoint.npz"), 40).unwrap();
    assert_eq!((saved.step, relaxed.step), (1000, 1000));
    assert!(saved.cells == relaxed.cells, "the last good state is not the state before the failed step");
}

/// `monolayer sweep` from the command line: a small grid, its tables and plot; a bad grid value
/// refused before anything is written.
#[test]
fn sweep_from_the_command_line() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sweep");
    let o = monolayer(&[
        "sweep",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
        "--grid",
        "zeta=0.2,0.4",
        "--seeds",
        "1,2",
        "--set",
        "box_size=48",
        "--set",
        "n_cells=6",
        "--set",
        "relax_steps=100",
        "--set",
        "active_steps=100",
        "--frame-interval",
        "50",
        "--jobs",
        "2",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert_eq!(summary.lines().count(), 5, "{summary}");
    assert!(summary.lines().nth(1).unwrap().starts_with("zeta0.2_seed1,0.2,1,"), "{summary}");
    let regimes = std::fs::read_to_string(out.join("regimes.csv")).unwrap();
    assert_eq!(regimes.lines().count(), 3, "{regimes}");
    assert!(stderr(&o).contains("runs took"), "{}", stderr(&o));

    let bad = dir.path().join("bad");
    let o = monolayer(&["sweep", "--out", bad.to_str().unwrap(), "--grid", "zeta=0.3,99"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("zeta = 99") && stderr(&o).contains("[−10, 10]"), "{}", stderr(&o));
    assert!(!bad.exists());
}

/// `monolayer sweep --point`: listed points instead of a grid, named like grid runs; then
/// `--tables-only` with one point more measures what exists and runs nothing.
#[test]
fn sweep_of_points_and_its_tables_alone() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("points");
    let small = ["--set", "box_size=48", "--set", "n_cells=6", "--set", "relax_steps=100", "--set", "active_steps=100"];
    let run = |extra: &[&str]| {
        let mut args = vec!["sweep", "--quiet", "--out", out.to_str().unwrap(), "--frame-interval", "50"];
        args.extend_from_slice(&small);
        args.extend_from_slice(&["--point", "chi=0.1,zeta=0.2", "--point", "chi=0.01,zeta=0.4"]);
        args.extend_from_slice(extra);
        monolayer(&args)
    };
    let o = run(&["--jobs", "2"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let summary = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    let names: Vec<&str> = summary.lines().skip(1).map(|l| l.split(',').next().unwrap()).collect();
    assert_eq!(names, ["chi0.1_zeta0.2_seed1", "chi0.01_zeta0.4_seed1"], "{summary}");
    assert!(out.join("regime_map.png").exists());

    std::fs::remove_file(out.join("summary.csv")).unwrap();
    let o = run(&["--tables-only", "--point", "chi=0.001,zeta=0.4"]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(
        stderr(&o).contains("2 of 3 runs have a directory") && stderr(&o).contains("2 of them ended"),
        "{}",
        stderr(&o)
    );
    assert_eq!(std::fs::read_to_string(out.join("summary.csv")).unwrap(), summary);
    assert!(!out.join("runs/chi0.001_zeta0.4_seed1").exists(), "--tables-only ran a simulation");

    let o = run(&["--point", "chi=0.01"]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("the same parameters"), "{}", stderr(&o));
}

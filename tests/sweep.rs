//! Parameter sweeps on small boxes: every run done once, resumable, summarised, refused early when
//! the sweep is bad.

mod common;

use std::path::Path;
use std::sync::atomic::{AtomicU64, Ordering};

use monolayer::formats::{RunRecord, RunStatus};
use monolayer::run::{checkpoint_path, frame_path, run_sweep, steps_to_run, write_checkpoint, write_tables, SweepSpec};
use monolayer::Monolayer;

const SPEC: &str = r#"
seeds = [1]
frame_interval = 50
[base]
box_size = 48
n_cells = 6
relax_steps = 100
active_steps = 150
[grid]
chi = [0.1, 0.01]
zeta = [0.2, 0.4]
"#;

fn sweep(out: &Path) -> (Vec<monolayer::run::RunSummary>, u64) {
    let spec: SweepSpec = toml::from_str(SPEC).unwrap();
    let jobs = spec.jobs().unwrap();
    let steps = AtomicU64::new(0);
    let summaries = run_sweep(&jobs, spec.frame_interval, out, 2, None, &|s, _, _| {
        steps.fetch_max(s, Ordering::Relaxed);
    })
    .unwrap();
    (summaries, steps.load(Ordering::Relaxed))
}

#[test]
fn a_sweep_runs_every_point_once_and_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    let (first, steps) = sweep(out);
    assert_eq!(first.len(), 4);
    assert!(steps >= 4 * 200, "{steps} steps for 4 runs of 250 (the watcher sees every 100th)");
    for s in &first {
        assert_eq!(s.status, RunStatus::Finished, "{}", s.name);
        assert_eq!(s.steps, 250);
        assert!(s.velocity_correlation_length.is_some());
    }
    // The speeds are the runs' own: at each ζ the lower substrate friction moves faster, and at
    // each χ the stronger activity does.
    let speed = |name: &str| first.iter().find(|s| s.name == name).map(|s| s.mean_speed).expect(name);
    for zeta in ["0.2", "0.4"] {
        let (stiff, soft) = (speed(&format!("chi0.1_zeta{zeta}_seed1")), speed(&format!("chi0.01_zeta{zeta}_seed1")));
        assert!(soft > stiff, "ζ = {zeta}: speed {soft} at χ = 0.01, {stiff} at χ = 0.1");
    }
    for chi in ["0.1", "0.01"] {
        let (weak, strong) = (speed(&format!("chi{chi}_zeta0.2_seed1")), speed(&format!("chi{chi}_zeta0.4_seed1")));
        assert!(strong > weak, "χ = {chi}: speed {strong} at ζ = 0.4, {weak} at ζ = 0.2");
    }
    let files = write_tables(out, &first).unwrap();
    let summary = std::fs::read_to_string(out.join("summary.csv")).unwrap();
    assert_eq!(summary.lines().count(), 5, "{summary}");
    assert!(summary.starts_with("run,chi,zeta,seed,status"), "{summary}");
    assert!(out.join("regimes.csv").exists() && out.join("regime_map.png").exists(), "{files:?}");

    // Run again: nothing left to do, same tables.
    let spec: SweepSpec = toml::from_str(SPEC).unwrap();
    assert_eq!(steps_to_run(&spec.jobs().unwrap(), out, None), 0);
    let (again, steps) = sweep(out);
    assert_eq!(steps, 0);
    assert_eq!(monolayer::run::tables(&again), monolayer::run::tables(&first));

    // A run killed at step 150: its checkpoint and frames up to there, its record still
    // "running". The sweep resumes it from the checkpoint to the same bits.
    let victim = out.join("runs").join("chi0.01_zeta0.4_seed1");
    let final_checkpoint = std::fs::read(checkpoint_path(&victim)).unwrap();
    let mut record = RunRecord::load(&victim).unwrap();
    let mut m = Monolayer::new(record.params.clone(), record.seed).unwrap();
    m.advance(150).unwrap();
    write_checkpoint(&m, &checkpoint_path(&victim)).unwrap();
    for step in [200, 250] {
        std::fs::remove_file(frame_path(&victim, step)).unwrap();
    }
    record.status = RunStatus::Running;
    record.last_frame_step = Some(150);
    record.save(&victim).unwrap();
    let spec: SweepSpec = toml::from_str(SPEC).unwrap();
    assert_eq!(steps_to_run(&spec.jobs().unwrap(), out, None), 100);
    let (redone, steps) = sweep(out);
    assert!((100..200).contains(&steps), "resumed at 150, not restarted ({steps} steps)");
    assert_eq!(std::fs::read(checkpoint_path(&victim)).unwrap(), final_checkpoint, "not bit-identical");
    assert_eq!(monolayer::run::tables(&redone), monolayer::run::tables(&first));
}

#[test]
fn a_bad_sweep_is_refused_before_anything_runs() {
    let spec: SweepSpec = toml::from_str("[grid]\nchi = [0.1, -1.0]\n").unwrap();
    let e = spec.jobs().unwrap_err().to_string();
    assert!(e.contains("chi = -1") && e.contains("xi_substrate"), "{e}");
    // As a user meets it: refused, and nothing written where the sweep would go.
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("sweep");
    let o = common::command()
        .args(["sweep", "--quiet", "--grid", "chi=0.1,-1.0", "--set", "box_size=48", "--set", "n_cells=6", "--out"])
        .arg(&out)
        .output()
        .unwrap();
    let e = common::stderr(&o);
    assert_eq!(o.status.code(), Some(2), "{e}");
    assert!(e.contains("xi_substrate"), "{e}");
    assert!(!out.exists() && std::fs::read_dir(dir.path()).unwrap().next().is_none(), "the refused sweep wrote files");
}

#[test]
fn a_sweep_refuses_runs_made_with_other_parameters() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    sweep(out);
    let changed: SweepSpec = toml::from_str(&SPEC.replace("active_steps = 150", "active_steps = 160")).unwrap();
    let e = run_sweep(&changed.jobs().unwrap(), 50, out, 1, None, &|_, _, _| {}).unwrap_err().to_string();
    assert!(e.contains("other parameters"), "{e}");
}

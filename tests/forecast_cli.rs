//! `monolayer forecast` as a user drives it: runs of two seeds give every table and figure; one
//! seed, or a run not finished, is refused with nothing written.

mod common;

use std::path::Path;

use common::{lines, monolayer, stderr};

/// A small, quick run: 18 cells on a 60×60 box, relaxation to step 300, 60 active steps with a
/// frame every 10 (7 frames).
fn small_run(out: &Path, seed: &str) {
    let o = monolayer(&[
        "run",
        "--quiet",
        "--set",
        "box_size=60",
        "--set",
        "n_cells=18",
        "--relax-steps",
        "300",
        "--steps",
        "60",
        "--frame-interval",
        "10",
        "--threads",
        "1",
        "--seed",
        seed,
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
}

#[test]
fn forecast_writes_its_tables_for_two_seeds_and_refuses_one() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    small_run(&a, "1");
    small_run(&b, "2");

    let lone = dir.path().join("lone");
    let o = monolayer(&["forecast", a.to_str().unwrap(), "--out", lone.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("at least two seeds"), "{}", stderr(&o));
    assert!(!lone.exists(), "nothing written when refused");

    let out = dir.path().join("out");
    let o = monolayer(&["forecast", a.to_str().unwrap(), b.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    for name in [
        "thinning.csv",
        "baseline.csv",
        "baseline_summary.csv",
        "forecast_folds.csv",
        "forecast.csv",
        "forecast_roc.png",
        "forecast_roc.svg",
    ] {
        assert!(out.join(name).is_file(), "{name} missing");
    }
    let folds = lines(&out.join("forecast_folds.csv"));
    assert!(folds[0].starts_with("held_out_seed,predictor,horizon,subset,auc"), "{folds:?}");
    // Two seeds, three single predictors (the combination needs a tear to fit), 3 horizons,
    // 2 subsets: a row each, every site of the run's sub-grid scored.
    assert_eq!(folds.len(), 1 + 2 * 3 * 3 * 2, "{folds:?}");
    let sites: usize = folds[1].split(',').nth(8).unwrap().parse().unwrap();
    assert!(sites > 0 && sites <= 30 * 30 * 2, "frames 0 and 1 of the sub-grid: {sites}");
}

#[test]
fn forecast_refuses_a_run_that_has_not_finished_unless_partial() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    small_run(&a, "1");
    small_run(&b, "2");
    let record = b.join("run.json");
    let text = std::fs::read_to_string(&record).unwrap().replace("\"finished\"", "\"running\"");
    std::fs::write(&record, text).unwrap();
    let out = dir.path().join("out");
    let o = monolayer(&["forecast", a.to_str().unwrap(), b.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(!o.status.success());
    assert!(stderr(&o).contains("has not finished") && stderr(&o).contains("--partial"), "{}", stderr(&o));
    assert!(!out.exists());
    let o = monolayer(&[
        "forecast",
        a.to_str().unwrap(),
        b.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--partial",
        "--quiet",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert!(out.join("forecast.csv").is_file());
}

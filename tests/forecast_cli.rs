//! `monolayer forecast` as a user drives it: runs of two seeds give every table and figure; one
//! seed, or a run not finished, is refused with nothing written.

mod common;

use std::path::{Path, PathBuf};

use common::{lines, monolayer, small_run, stderr, tear_open_a_hole};

/// Two finished small runs (60 active steps, 7 frames) of seeds 1 and 2 in `dir`, each with a
/// hole opened by hand at its fourth frame (a run this short opens none by itself, and without
/// one there is nothing to fit or score).
fn two_runs(dir: &Path) -> (PathBuf, PathBuf) {
    let (a, b) = (dir.join("a"), dir.join("b"));
    for (out, seed) in [(&a, "1"), (&b, "2")] {
        let o = small_run(out, "60", &["--seed", seed]);
        assert!(o.status.success(), "{}", stderr(&o));
        tear_open_a_hole(out, 3, 330);
    }
    (a, b)
}

#[test]
fn forecast_writes_its_tables_for_two_seeds_and_refuses_one() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = two_runs(dir.path());

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
    // Two seeds, 3 horizons, 2 subsets: a row each for the three single predictors, and for
    // the combination where it can be fitted, at the horizons within which the other seed's
    // hole opens after a scored frame (3 and 5 frames; none within 1), every site of the run's
    // sub-grid scored.
    assert_eq!(folds.len(), 1 + 2 * (3 * 2 + 2 * 4 * 2), "{folds:?}");
    let sites: usize = folds[1].split(',').nth(8).unwrap().parse().unwrap();
    assert!(sites > 0 && sites <= 30 * 30 * 2, "frames 0 and 1 of the sub-grid: {sites}");
}

#[test]
fn forecast_refuses_a_run_that_has_not_finished_unless_partial() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = two_runs(dir.path());
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

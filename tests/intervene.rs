//! `monolayer intervene` as a user drives it, on the page's persistent-hole tissue (80², 33 cells,
//! ζ = 2.5, χ = 0.001: its first hole opens about 1,200 active steps in): each arm's branches
//! change exactly one parameter, the replicas tear where the parent tore, the tear detector
//! agrees with `analyze` on a branch's frames, an interrupted experiment continues to the same
//! tables, and bad input is refused by name.

mod common;

use std::fs;
use std::path::{Path, PathBuf};

use common::{lines, monolayer, stderr};
use monolayer::formats::RunRecord;

/// The parent: 1,500 relaxation and 1,500 active steps, a frame every 100, checkpoints kept.
fn parent(dir: &Path) -> PathBuf {
    let out = dir.join("persistent");
    let o = monolayer(&[
        "run",
        "--set",
        "box_size=80",
        "--set",
        "n_cells=33",
        "--set",
        "gamma=0.06",
        "--chi",
        "0.001",
        "--zeta",
        "2.5",
        "--relax-steps",
        "1500",
        "--steps",
        "1500",
        "--frame-interval",
        "100",
        "--keep-checkpoints",
        "--quiet",
        "--out",
        out.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    out
}

/// `intervene` on `parent` into `out`: leads 1 and 2, 2 frames after, 2 replicas, 2 jobs, unless
/// `extra` gives its own.
fn intervene(parent: &Path, out: &Path, extra: &[&str]) -> std::process::Output {
    let mut args = vec!["intervene", parent.to_str().unwrap(), "--out", out.to_str().unwrap(), "--quiet"];
    for (flag, default) in [("--leads", "1,2"), ("--after", "2"), ("--replicas", "2"), ("--jobs", "2")] {
        if !extra.contains(&flag) {
            args.extend([flag, default]);
        }
    }
    args.extend_from_slice(extra);
    monolayer(&args)
}

/// The rows of a CSV as maps from its header's names.
fn rows(path: &Path) -> Vec<std::collections::HashMap<String, String>> {
    let all = lines(path);
    let header: Vec<String> = all[0].split(',').map(String::from).collect();
    all[1..].iter().map(|l| header.iter().cloned().zip(l.split(',').map(String::from)).collect()).collect()
}

#[test]
fn the_intervention_runs_every_arm_and_the_replicas_tear_where_the_parent_tore() {
    let tmp = tempfile::tempdir().unwrap();
    let p = parent(tmp.path());
    let out = tmp.path().join("iv");
    let o = intervene(&p, &out, &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let cases = rows(&out.join("intervention_cases.csv"));
    assert!(!cases.is_empty(), "the parent tore: cases to branch");
    // Every branch changes exactly what its arm names, and the replicas only φ.
    let mut seen = 0;
    for run in fs::read_dir(out.join("branches/persistent")).unwrap().flatten() {
        let name = run.file_name().to_string_lossy().into_owned();
        let record = RunRecord::load(&run.path()).unwrap();
        let origin = record.branch.expect("a branch records its origin");
        let changed: Vec<String> = origin.changes.iter().map(|c| format!("{}={}", c.key, c.branch)).collect();
        let expect: &[&str] = match name.split_once('_').unwrap().1 {
            "control1" | "control2" => &[],
            "activity-off" => &["zeta=0.0"],
            "activity-halved" => &["zeta=1.25"],
            "friction-x10" => &["xi_substrate=0.01"],
            "local-flows" => &["xi_substrate=1.0"],
            other => panic!("an arm not asked for: {other}"),
        };
        assert_eq!(changed, expect, "{name}");
        assert_eq!(origin.perturbation.is_some(), name.contains("control"), "{name}");
        seen += 1;
    }
    assert_eq!(seen, 6 * cases.iter().map(|c| &c["branch_step"]).collect::<std::collections::BTreeSet<_>>().len());
    // At one frame before, a 10⁻⁶ perturbation does not move a tear: the replicas tear within R.
    let summary = rows(&out.join("intervention.csv"));
    let control =
        summary.iter().find(|r| r["arm"] == "control" && r["k"] == "1" && r["sites"] == "nucleation").unwrap();
    assert_eq!(control["tear_share"], "1.0000", "{control:?}");
    for r in summary.iter().filter(|r| r["arm"] != "control" && r["sites"] == "nucleation") {
        assert!(!r["prevented"].is_empty(), "prevented share read against the replicas: {r:?}");
    }
    // By point: one parent, one point, so each row is the whole table's at the nucleation sites.
    let by_point = rows(&out.join("intervention_by_point.csv"));
    let nucleation: Vec<_> = summary.iter().filter(|r| r["sites"] == "nucleation").collect();
    assert_eq!(by_point.len(), nucleation.len());
    for r in nucleation {
        let b = by_point.iter().find(|b| b["arm"] == r["arm"] && b["k"] == r["k"]).unwrap();
        assert_eq!((&b["chi"], &b["zeta"]), (&"0.001".to_string(), &"2.5".to_string()), "{b:?}");
        assert_eq!((&b["nucleations"], &b["tear_share"]), (&r["cases"], &r["tear_share"]), "{b:?} against {r:?}");
    }
    assert!(out.join("intervention.png").is_file() && out.join("intervention.svg").is_file());
    let traces = rows(&out.join("intervention_trace_summary.csv"));
    let speed = |arm: &str| {
        traces.iter().find(|r| r["arm"] == arm && r["k"] == "2" && r["offset"] == "1").unwrap()["mean_speed"]
            .parse::<f64>()
            .unwrap()
    };
    assert!(speed("activity-off") < 0.5 * speed("control"), "no active force, slower tissue");
}

#[test]
fn the_tear_detector_agrees_with_analyze_on_a_branchs_frames() {
    let tmp = tempfile::tempdir().unwrap();
    let p = parent(tmp.path());
    let out = tmp.path().join("iv");
    let o = intervene(&p, &out, &["--arms", "control", "--leads", "2", "--replicas", "1"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let cases = rows(&out.join("intervention_cases.csv"));
    let outcomes = rows(&out.join("intervention_outcomes.csv"));
    for case in &cases {
        let branch =
            out.join(format!("branches/persistent/at{:07}_control1", case["branch_step"].parse::<u64>().unwrap()));
        let analysis = tmp.path().join(format!("analysis-{}", case["case"]));
        let a = monolayer(&["analyze", branch.to_str().unwrap(), "--out", analysis.to_str().unwrap()]);
        assert!(a.status.success(), "{}", stderr(&a));
        // analyze's holes that nucleated after the branch's first frame (not fragments), by step.
        let first = case["branch_step"].parse::<f64>().unwrap() * 0.1;
        let holes = rows(&analysis.join("holes.csv"));
        let (x, y) = (case["x"].parse::<f64>().unwrap(), case["y"].parse::<f64>().unwrap());
        let near = |h: &std::collections::HashMap<String, String>| {
            let (hx, hy) = (h["nucleation_x"].parse::<f64>().unwrap(), h["nucleation_y"].parse::<f64>().unwrap());
            let d = |a: f64, b: f64| (a - b).abs().min(80.0 - (a - b).abs());
            d(hx, x).hypot(d(hy, y)) <= 8.0
        };
        let analyzed = holes
            .iter()
            .filter(|h| h["split_from"].is_empty() && h["nucleation_time"].parse::<f64>().unwrap() > first && near(h))
            .map(|h| (h["nucleation_time"].parse::<f64>().unwrap() * 10.0).round() as u64)
            .min();
        let outcome = outcomes.iter().find(|o| o["case"] == case["case"] && o["site"] == "0").unwrap();
        let detected = outcome["tear_step"].parse::<u64>().ok();
        assert_eq!(detected, analyzed, "case {case:?}: the detector and analyze");
        assert!(detected.is_some(), "the replica tore where the parent did");
    }
}

#[test]
fn an_interrupted_intervention_continues_to_the_same_tables() {
    let tmp = tempfile::tempdir().unwrap();
    let p = parent(tmp.path());
    let out = tmp.path().join("iv");
    let args = ["--arms", "control,activity-off", "--leads", "1", "--replicas", "1"];
    assert!(intervene(&p, &out, &args).status.success());
    let before = fs::read_to_string(out.join("intervention_outcomes.csv")).unwrap();
    // A branch killed before its record was written, and one stopped part way.
    let branches: Vec<PathBuf> =
        fs::read_dir(out.join("branches/persistent")).unwrap().flatten().map(|e| e.path()).collect();
    fs::remove_file(branches[0].join("run.json")).unwrap();
    let record = branches[1].join("run.json");
    let stopped = fs::read_to_string(&record).unwrap().replace("\"finished\"", "\"stopped: signal SIGTERM\"");
    fs::write(&record, stopped).unwrap();
    let o = intervene(&p, &out, &args);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(fs::read_to_string(out.join("intervention_outcomes.csv")).unwrap(), before);
    let o = intervene(&p, &out, &[&args[..], &["--tables-only"]].concat());
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(fs::read_to_string(out.join("intervention_outcomes.csv")).unwrap(), before);
}

#[test]
fn bad_input_is_refused_by_name_and_runs_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let p = parent(tmp.path());
    let out = tmp.path().join("iv");
    let ps = p.to_str().unwrap();
    for (args, expect) in [
        (vec!["--arms", "activity-off"], "--arms must include control"),
        (vec!["--arms", "control,magic"], "invalid value 'magic' for '--arms <ARMS>'"),
        (vec!["--leads", "0"], "--leads"),
        (vec!["--leads", "1,1"], "listed twice"),
        (vec!["--replicas", "0"], "--replicas 0"),
    ] {
        let o = intervene(&p, &out, &args);
        assert!(!o.status.success(), "{args:?}");
        assert!(stderr(&o).contains(expect), "{args:?}: {}", stderr(&o));
    }
    let o = monolayer(&["intervene", ps, ps, "--out", out.to_str().unwrap()]);
    assert!(stderr(&o).contains("are the same run"), "{}", stderr(&o));
    let text = fs::read_to_string(p.join("run.json")).unwrap().replace("\"finished\"", "\"running\"");
    fs::write(p.join("run.json"), text).unwrap();
    let o = intervene(&p, &out, &[]);
    assert!(stderr(&o).contains("has not finished"), "{}", stderr(&o));
    assert!(!out.join("branches").exists(), "nothing run");
}

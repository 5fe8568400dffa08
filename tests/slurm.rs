//! `monolayer figures --slurm` against a real Slurm cluster (`scripts/slurm-cluster.sh start`):
//! the `smoke` scale submitted through sbatch, its job array run to completion, the figures job
//! started after it, and every CSV the same bytes as a local run's.
//!
//! Without a cluster the test says so and passes, unless `CI=true` or `MONOLAYER_SLURM_TEST=1`,
//! where a missing cluster fails it (`.ci/run` starts one).

mod common;

use common::{csv_files, monolayer};
use std::collections::BTreeMap;
use std::process::{Command, Output};
use std::time::{Duration, Instant};

fn text(o: &Output) -> (String, String) {
    (String::from_utf8_lossy(&o.stdout).into_owned(), String::from_utf8_lossy(&o.stderr).into_owned())
}

/// Whether a node is up (idle, mixed or allocated).
fn cluster_up() -> bool {
    Command::new("sinfo").args(["-h", "-o", "%T"]).output().is_ok_and(|o| {
        o.status.success()
            && String::from_utf8_lossy(&o.stdout).lines().any(|l| {
                let l = l.trim_end_matches(['*', '~', '#']);
                l == "idle" || l == "mixed" || l == "allocated"
            })
    })
}

/// `squeue` states of the jobs (array tasks as `ID_K`), terminal ones included while Slurm keeps
/// them (MinJobAge).
fn states(ids: &str) -> BTreeMap<String, String> {
    let o =
        Command::new("squeue").args(["-h", "-t", "all", "-j", ids, "-o", "%i %T %r"]).output().expect("squeue runs");
    String::from_utf8_lossy(&o.stdout)
        .lines()
        .filter_map(|l| {
            let mut w = l.split_whitespace();
            Some((w.next()?.to_string(), w.collect::<Vec<_>>().join(" ")))
        })
        .collect()
}

#[test]
#[ignore = "the smoke scale twice, minutes: scripts/test.sh runs it (cargo test --release -- --include-ignored)"]
fn the_smoke_scale_through_sbatch_gives_the_local_runs_csvs() {
    let required =
        std::env::var("CI").is_ok_and(|v| v == "true") || std::env::var("MONOLAYER_SLURM_TEST").is_ok_and(|v| v == "1");
    if !cluster_up() {
        assert!(!required, "no Slurm node is up (sinfo): `sudo bash scripts/slurm-cluster.sh start` starts one");
        eprintln!("skipped: no Slurm cluster (sudo bash scripts/slurm-cluster.sh start)");
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let local = dir.path().join("local");
    let cluster = dir.path().join("slurm");

    let t = Instant::now();
    let o = monolayer(&["figures", "--scale", "smoke", "--out", local.to_str().unwrap(), "--jobs", "2", "--quiet"]);
    assert!(o.status.success(), "local: {}", text(&o).1);
    eprintln!("smoke scale locally: {:.0} s", t.elapsed().as_secs_f64());

    let t = Instant::now();
    let o =
        monolayer(&["figures", "--scale", "smoke", "--out", cluster.to_str().unwrap(), "--slurm", "--throttle", "2"]);
    let (out, err) = text(&o);
    assert!(o.status.success(), "--slurm: {err}");
    let id = |key: &str| {
        out.lines().find_map(|l| l.strip_prefix(key)).unwrap_or_else(|| panic!("no {key} in {out}")).to_string()
    };
    let (runs, figures) = (id("runs_job_id="), id("figures_job_id="));
    let script = std::fs::read_to_string(cluster.join("slurm/runs.sbatch")).unwrap();
    let tasks: usize = script
        .lines()
        .find_map(|l| l.strip_prefix("#SBATCH --array=0-"))
        .and_then(|r| r.split('%').next())
        .and_then(|n| n.parse::<usize>().ok())
        .expect("an --array line")
        + 1;

    // Until the figures job has ended; every state seen is kept (Slurm forgets finished jobs).
    let ids = format!("{runs},{figures}");
    let mut seen: BTreeMap<String, String> = BTreeMap::new();
    // A hang guard, not a speed check: it fails only when no job has changed state for 30
    // minutes (a job stuck pending or running), however long the whole takes.
    let hang = Duration::from_secs(30 * 60);
    let mut last_change = (Instant::now(), BTreeMap::new());
    loop {
        let now = states(&ids);
        if now != last_change.1 {
            last_change = (Instant::now(), now.clone());
        }
        seen.extend(now.clone());
        if now.iter().any(|(_, s)| s.starts_with("FAILED") || s.starts_with("CANCELLED") || s.starts_with("TIMEOUT"))
            || now.get(&figures).is_some_and(|s| s.contains("DependencyNeverSatisfied"))
        {
            let _ = Command::new("scancel").arg(&figures).status();
            let log = std::fs::read_dir(cluster.join("slurm"))
                .map(|d| d.filter_map(|e| e.ok()).map(|e| e.path().display().to_string()).collect::<Vec<_>>().join(" "))
                .unwrap_or_default();
            panic!("a job failed: {now:?} (logs: {log})");
        }
        // afterok: the figures job runs only once every array task has completed.
        let done = seen.get(&figures).is_some_and(|s| s.starts_with("COMPLETED"));
        // Or it ended and Slurm forgot it between two polls: judged by its output below.
        let forgotten = seen.contains_key(&figures) && !now.contains_key(&figures);
        if done || forgotten && cluster.join("figures.md").exists() {
            break;
        }
        assert!(last_change.0.elapsed() < hang, "hung: no job changed state in {} min: {now:?}", hang.as_secs() / 60);
        std::thread::sleep(Duration::from_millis(500));
    }
    eprintln!("smoke scale through Slurm: {:.0} s, {tasks} array tasks", t.elapsed().as_secs_f64());

    // Every task ran and wrote its own log; none is left or failed.
    for k in 0..tasks {
        let log = cluster.join(format!("slurm/run-{runs}_{k}.out"));
        assert!(log.exists(), "{} missing", log.display());
        if let Some(s) = seen.get(&format!("{runs}_{k}")) {
            assert!(s.starts_with("COMPLETED"), "task {k}: {s}");
        }
    }
    assert!(cluster.join(format!("slurm/figures-{figures}.out")).exists());
    assert!(
        cluster.join("figures.md").exists() && cluster.join("fig3d.png").exists() && cluster.join("figS1.svg").exists()
    );
    let (a, b) = (csv_files(&local), csv_files(&cluster));
    assert!(a.len() >= 12, "{:?}", a.keys());
    assert_eq!(a.keys().collect::<Vec<_>>(), b.keys().collect::<Vec<_>>());
    for (name, text) in &a {
        assert!(text == &b[name], "{name} differs between the local and the Slurm runs");
    }
}

//! Resources: memory, disk and cores. Every command that simulates estimates what it will hold
//! at once before it starts (all its jobs, not one) and refuses beyond what the machine leaves;
//! a full disk stops a run cleanly, as the machine's error and not the run's, and the run
//! resumes to the same bits; counts of threads and jobs are bounded. Each test reproduces a
//! defect and fails without its fix.

mod common;

use std::fs;
use std::path::Path;
use std::process::Command;

use common::faults::{ok, refused, refused_within, with_file_size_limit, SMALL_RUN, SPEC, SWEEP_ARGS, TINY};
use common::{arg, monolayer, stderr};
use monolayer::formats::{RunRecord, RunStatus};
use monolayer::run::{checkpoint_path, kept_checkpoint_path, memory_estimate, run_sweep, tables, RunDir, SweepSpec};
use monolayer::Params;

// ---- Memory ----

/// `relaxed-state`, `bench` and `figures` (its `--dry-run` estimate too) check the memory a
/// simulation needs before allocating it, as `run` does, reading MONOLAYER_MEMORY_LIMIT_MB.
#[test]
fn every_command_that_simulates_checks_the_memory_first() {
    let dir = tempfile::tempdir().unwrap();
    let limit = [("MONOLAYER_MEMORY_LIMIT_MB", "1")];
    let expect = ["box_size = 48, n_cells = 10 need about", "more than MONOLAYER_MEMORY_LIMIT_MB (1 MB)"];
    let out = dir.path().join("relaxed.bin");
    refused_within(&[&["relaxed-state", "--out", arg(&out)][..], &TINY].concat(), &limit, &expect);
    assert!(!out.exists());
    let bench = ["bench", "--steps", "2", "--blocks", "1", "--chi", "0.1", "--relax-steps", "5"];
    refused_within(&[&bench[..], &TINY[..4]].concat(), &limit, &expect);
    let figures = dir.path().join("f");
    for dry in [&["--dry-run"][..], &[]] {
        let args = [&["figures", "--quiet", "--only", "1c", "--out", arg(&figures)][..], dry].concat();
        refused_within(&args, &limit, &["more than MONOLAYER_MEMORY_LIMIT_MB (1 MB)"]);
    }
    assert!(!figures.join("runs").exists());
}

/// `MONOLAYER_MEMORY_LIMIT_MB` that cannot be read is named, 2⁴⁴ MB no longer
/// wraps to 0, RLIMIT_AS is consulted (a run refused, not aborted), and `fingerprint` checks.
#[test]
fn the_memory_check_reads_its_variable_and_the_process_limits() {
    use monolayer::run::{cgroup_room, parse_memory_limit_mb};
    let fingerprint = |env: Option<&str>, limit_kb: Option<u64>, size: &str| {
        let ulimit = limit_kb.map(|k| format!("ulimit -v {k}; ")).unwrap_or_default();
        let mut c = Command::new("sh");
        c.arg("-c").arg(format!("{ulimit}exec \"$0\" \"$@\"")).arg(common::BIN);
        c.args(["fingerprint", "--total-steps", "1", "--set", size, "--set", "n_cells=6"]);
        if let Some(v) = env {
            c.env("MONOLAYER_MEMORY_LIMIT_MB", v);
        }
        c.output().unwrap()
    };
    for bad in ["abc", "100MB", "-5", "1.5", "0", ""] {
        let o = fingerprint(Some(bad), None, "box_size=48");
        refused(&o, &["MONOLAYER_MEMORY_LIMIT_MB", "whole number of megabytes"]);
    }
    ok(&fingerprint(Some("17592186044416"), None, "box_size=48"));
    refused(&fingerprint(Some("1"), None, "box_size=48"), &["more than MONOLAYER_MEMORY_LIMIT_MB (1 MB)"]);
    // ulimit -v: refused with the limit named, where it used to abort on allocation.
    let o = fingerprint(None, Some(1_000_000), "box_size=2000");
    refused(&o, &["RLIMIT_AS"]);
    assert_eq!(parse_memory_limit_mb("17592186044416").unwrap(), u64::MAX);
    assert_eq!(cgroup_room("max\n", Some("5")), None);
    assert_eq!(cgroup_room("1073741824\n", Some("73741824\n")), Some(1_000_000_000));
    assert_eq!(cgroup_room("9223372036854771712", None), None, "cgroup v1's 'no limit'");
}

/// The memory check of `sweep` and `figures` counts what their jobs hold at once, as `bench`
/// does: two runs under a limit that holds one are refused with `--jobs 2` (they were
/// accepted, and took twice the limit), and run with `--jobs 1`.
#[test]
fn the_memory_check_counts_the_runs_held_at_once() {
    let dir = tempfile::tempdir().unwrap();
    let one = memory_estimate(&Params { box_size: 48, n_cells: 6, ..Params::default() });
    let limit = (one + one / 2) >> 20;
    let env = [("MONOLAYER_MEMORY_LIMIT_MB", limit.to_string())];
    let env: Vec<(&str, &str)> = env.iter().map(|(k, v)| (*k, v.as_str())).collect();
    let out = dir.path().join("s");
    let sweep =
        |jobs: &'static str| [&["sweep", "--quiet", "--jobs", jobs, "--out", arg(&out)][..], &SWEEP_ARGS].concat();
    refused_within(&sweep("2"), &env, &["for the 2 simulations run at once (--jobs 2", "lower"]);
    assert!(!out.join("runs/zeta0.2_seed1").exists(), "a run was started");
    ok(&common::monolayer_within(120, &sweep("1"), &env));

    let smoke = memory_estimate(&Params { box_size: 48, n_cells: 10, ..Params::default() });
    let limit = ((smoke + smoke / 2) >> 20).to_string();
    let env = [("MONOLAYER_MEMORY_LIMIT_MB", limit.as_str())];
    let figures = |jobs: &str| {
        let figs = dir.path().join("f");
        ["figures", "--dry-run", "--quiet", "--only", "S3", "--jobs", jobs, "--out"]
            .map(String::from)
            .into_iter()
            .chain([arg(&figs).to_string()])
            .collect::<Vec<String>>()
    };
    let args = figures("2");
    refused_within(&args.iter().map(String::as_str).collect::<Vec<_>>(), &env, &["simulations run at once (--jobs 2"]);
    let args = figures("1");
    ok(&common::monolayer_within(120, &args.iter().map(String::as_str).collect::<Vec<_>>(), &env));
}

// ---- Disk ----

/// A run whose file cannot be written (here a directory is in the way of the checkpoint it
/// keeps at step 150; a full disk is the same to the program) is recorded as stopped, not as
/// blown up, is left out of the regime map, and runs to its end when the sweep runs again.
#[test]
fn a_sweep_retries_runs_stopped_by_an_io_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    let spec: SweepSpec = toml::from_str(SPEC).unwrap();
    let jobs = spec.jobs().unwrap();
    // The run started (its record and first checkpoint written), keeping its checkpoints.
    let run = out.join("runs").join(&jobs[1].name);
    drop(RunDir::create(&run, jobs[1].params.clone(), jobs[1].seed, 50).unwrap().keep_checkpoints().unwrap());
    // In the way at 150, and at 200 for the sweep run again before the way is cleared.
    for step in [150, 200] {
        fs::create_dir_all(kept_checkpoint_path(&run, step).join("in_the_way")).unwrap();
    }
    let first = run_sweep(&jobs, 50, out, 2, None, &|_, _, _| {}).unwrap();
    assert_eq!(first[0].status, RunStatus::Finished);
    let stopped = |s: &RunStatus| matches!(s, RunStatus::Stopped(why) if why.contains("checkpoint_0000150.npz"));
    assert!(stopped(&first[1].status), "{:?}", first[1]);
    assert!(!first[1].blew_up());
    let (summary, regimes) = tables(&first);
    assert!(summary.contains("\"stopped: "), "{summary}");
    assert!(regimes.lines().count() == 2 && !regimes.contains("\n0.4,"), "no regime from a stopped run: {regimes}");
    // From the command line: tried again, stopped again, and said so with the way out.
    let file = dir.path().join("sweep.toml");
    fs::write(&file, SPEC).unwrap();
    let o = monolayer(&["sweep", arg(&file), "--quiet", "--out", arg(out)]);
    refused(&o, &["1 run(s) stopped", "zeta0.4_seed1", "run the same command again"]);

    for step in [150, 200] {
        fs::remove_dir_all(kept_checkpoint_path(&run, step)).unwrap();
    }
    let again = run_sweep(&jobs, 50, out, 2, None, &|_, _, _| {}).unwrap();
    assert!(again.iter().all(|s| s.status == RunStatus::Finished), "{again:?}");
    assert_eq!(again[1].steps, 200);
    // Records of earlier versions called an IO error a failure: read as stopped, so retried.
    let old: RunStatus = "failed: x/frames/.frame.tmp: No space left on device (os error 28)".parse().unwrap();
    assert!(matches!(old, RunStatus::Stopped(_)));
    let unstable: RunStatus = "failed: unstable at step 3: cell 1 has phi = 2".parse().unwrap();
    assert!(unstable.blew_up());
}

/// A full disk while a run writes: an error naming the file, the run resumable, and no stray
/// "ZipWriter drop failed" on stderr.
#[test]
fn a_full_disk_stops_a_run_cleanly() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("full");
    let o = with_file_size_limit(8, &[&SMALL_RUN[..], &["--steps", "100", "--out", arg(&run)]].concat());
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(stderr(&o).contains("File too large"), "{}", stderr(&o));
    assert!(!stderr(&o).contains("ZipWriter"), "{}", stderr(&o));
    assert!(stderr(&o).contains("--resume"), "the way on: {}", stderr(&o));
    assert!(matches!(RunRecord::load(&run).unwrap().status, RunStatus::Stopped(_)));
    // Space again: the run goes on from its checkpoint to its end.
    ok(&monolayer(&["run", "--quiet", "--resume", arg(&run)]));
    let record = RunRecord::load(&run).unwrap();
    assert_eq!((record.status, record.last_frame_step), (RunStatus::Finished, Some(100)));
}

/// A tmpfs of a given size mounted on a fresh directory, unmounted when dropped; None (with a
/// message) where this process may not mount one, and a failure under `CI=true`, where `.ci/run`
/// runs the tests as root.
struct TmpFs {
    dir: tempfile::TempDir,
}

impl TmpFs {
    fn mount(size: &str) -> Option<TmpFs> {
        let dir = tempfile::tempdir().unwrap();
        let o = Command::new("mount")
            .args(["-t", "tmpfs", "-o", &format!("size={size}"), "tmpfs", arg(dir.path())])
            .output();
        match o {
            Ok(o) if o.status.success() => Some(TmpFs { dir }),
            other => {
                let why = match other {
                    Ok(o) => stderr(&o),
                    Err(e) => e.to_string(),
                };
                assert!(std::env::var("CI").as_deref() != Ok("true"), "CI=true: cannot mount a tmpfs: {why}");
                eprintln!("skipped: cannot mount a tmpfs here (needs root): {why}");
                None
            }
        }
    }

    fn path(&self) -> &Path {
        self.dir.path()
    }

    fn resize(&self, size: &str) {
        let o = Command::new("mount").args(["-o", &format!("remount,size={size}"), arg(self.path())]).output().unwrap();
        assert!(o.status.success(), "{}", stderr(&o));
    }
}

impl Drop for TmpFs {
    fn drop(&mut self) {
        let _ = Command::new("umount").arg(self.path()).output();
    }
}

/// The full-disk reproduction on a real tmpfs, at several disk sizes (the disk
/// fills at the checkpoint, at a frame or at the record): every run stops, resumes once there is
/// space, and ends with the same bits as a run that never stopped.
#[test]
fn a_full_disk_at_any_write_resumes_to_the_same_bits() {
    let args = |out: &Path| -> Vec<String> {
        let sm = "--threads 1 --quiet --set box_size=48 --set n_cells=10 --relax-steps 200 --steps 1500";
        let more = "--frame-interval 50 --seed 2 --zeta 0.4 --out";
        let mut v: Vec<String> = format!("run {sm} {more}").split(' ').map(String::from).collect();
        v.push(arg(out).to_string());
        v
    };
    let run = |out: &Path| {
        let a = args(out);
        monolayer(&a.iter().map(String::as_str).collect::<Vec<_>>())
    };
    let reference = tempfile::tempdir().unwrap();
    let whole = reference.path().join("r");
    ok(&run(&whole));
    let files = |dir: &Path| {
        let mut v: Vec<_> = fs::read_dir(dir.join("frames")).unwrap().map(|e| e.unwrap().path()).collect();
        v.sort();
        v.push(checkpoint_path(dir));
        v
    };
    for size in ["600k", "350k", "1100k"] {
        let Some(disk) = TmpFs::mount(size) else { return };
        let stopped = disk.path().join("r");
        let o = run(&stopped);
        assert_eq!(o.status.code(), Some(2), "size {size}: {}", stderr(&o));
        assert!(stderr(&o).contains("No space left on device"), "size {size}: {}", stderr(&o));
        disk.resize("256m");
        let o = monolayer(&["run", "--quiet", "--resume", arg(&stopped)]);
        assert!(o.status.success(), "size {size}: the resume failed: {}", stderr(&o));
        let (a, b) = (files(&whole), files(&stopped));
        assert_eq!(a.len(), b.len(), "size {size}");
        for (x, y) in a.iter().zip(&b) {
            assert!(fs::read(x).unwrap() == fs::read(y).unwrap(), "size {size}: {} differs", y.display());
        }
        let record = RunRecord::load(&stopped).unwrap();
        assert_eq!((record.status, record.last_frame_step), (RunStatus::Finished, Some(1700)), "size {size}");
    }
}

// ---- Cores and cluster tasks ----

/// `figures --jobs` has the bound of `--threads` and `sweep --jobs`.
#[test]
fn figures_jobs_are_bounded() {
    let o = monolayer(&["figures", "--jobs", "1000", "--dry-run", "--out", "/nonexistent/never"]);
    refused(&o, &["--jobs 1000: must be in [1, "]);
}

/// The estimate steps a stable stand-in where the plan's first job blows up
/// (at γ = 0.04 the φ guard stops every run within 22 steps), and `--dry-run` needs no `--slurm`.
#[test]
fn the_estimate_survives_a_plan_whose_first_job_blows_up() {
    use monolayer::run::figures::{Figure, Plan, Scale, Speed};
    let plan = Plan::new(Scale::Smoke, &[Figure::Fig1c], &["gamma=0.04".to_string()], &[]).unwrap();
    let first = &plan.jobs[0];
    assert_eq!(first.params.gamma, 0.04, "the first job is the unstable γ = 0.04");
    let speed = Speed::measure(&[first], 100, 30).unwrap();
    assert_eq!(speed.sizes.len(), 1);
    assert!(speed.sizes[0].1 .0 > 0.0 && speed.sizes[0].1 .1 > 0.0, "{:?}", speed.sizes);
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("figs");
    let o = monolayer(&["figures", "--only", "S3", "--dry-run", "--quiet", "--out", arg(&out)]);
    ok(&o);
    assert!(stderr(&o).contains("estimate:") && stderr(&o).contains("dry run"), "{}", stderr(&o));
    assert!(!out.join("runs").exists(), "a dry run runs nothing");
    let o = monolayer(&["figures", "--only", "S3", "--slurm", "--dry-run", "--out", arg(&out)]);
    ok(&o);
    assert!(String::from_utf8_lossy(&o.stdout).contains("runs.sbatch"));
    let o = monolayer(&["figures", "--set", "gamma=0.04", "--only", "1c", "--dry-run", "--out", arg(&out)]);
    ok(&o);
}

/// A 1-based Slurm array runs every shard; an array that is not contiguous
/// is refused with what to do, naming the variables Slurm set.
#[test]
fn one_based_slurm_arrays_run_every_shard() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let sweep = |id: &str, extra: &[(&str, &str)]| {
        let mut c = common::command();
        c.args(["sweep", "--quiet", "--out", arg(&out), "--grid", "zeta=0.2,0.4", "--frame-interval", "50"]);
        c.args(["--set", "box_size=48", "--set", "n_cells=6", "--set", "relax_steps=50", "--set", "active_steps=50"]);
        c.env("SLURM_ARRAY_TASK_ID", id).env("SLURM_ARRAY_TASK_COUNT", "2");
        for (k, v) in extra {
            c.env(k, v);
        }
        c.output().unwrap()
    };
    ok(&sweep("2", &[("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_MAX", "2")]));
    assert!(out.join("runs/zeta0.4_seed1/run.json").exists());
    assert!(!out.join("runs/zeta0.2_seed1").exists(), "task 2 of 1-2 is the second shard");
    ok(&sweep("1", &[("SLURM_ARRAY_TASK_MIN", "1"), ("SLURM_ARRAY_TASK_MAX", "2")]));
    assert!(out.join("runs/zeta0.2_seed1/run.json").exists());
    let o = sweep("2", &[]);
    refused(&o, &["SLURM_ARRAY_TASK_ID = 2", "--shard K/N"]);
    let o = sweep("4", &[("SLURM_ARRAY_TASK_MIN", "0"), ("SLURM_ARRAY_TASK_MAX", "4")]);
    refused(&o, &["not one of a contiguous array"]);
}

//! What a demanding user does to a run: two writers in one directory, a full disk, a kill at the
//! wrong moment, a hand-edited record, damaged or foreign frames, absurd numbers. Each test here
//! reproduces one defect and fails without its fix.

mod common;

use std::fs;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::Duration;

use common::npz::{edit_npz, npy, read_npz, replace_npz_entry, write_npz, Npy};
use common::{arg, lines, monolayer, stderr};
use monolayer::formats::{RunRecord, RunStatus};
use monolayer::run::{
    checkpoint_path, frame_path, memory_estimate, run_sweep, tables, write_atomic, write_checkpoint, RunDir, RunFrames,
    RunLock, SweepSpec,
};
use monolayer::{Monolayer, Params};

/// A small quick protocol: 6 cells on a 48×48 box, on one thread, relaxation to step 100.
const SMALL_RUN: [&str; 10] =
    ["run", "--quiet", "--threads", "1", "--set", "box_size=48", "--set", "n_cells=6", "--relax-steps", "100"];

/// Waits until `path` exists, however long that takes (no test depends on the machine's speed):
/// the child ending before it writes the file is the failure.
fn wait_for_file(child: &mut std::process::Child, path: &Path, what: &str) {
    while !path.exists() {
        if let Some(status) = child.try_wait().unwrap() {
            panic!("{what} ended ({status}) before writing {}", path.display());
        }
        std::thread::sleep(Duration::from_millis(20));
    }
}

/// [`SMALL_RUN`] for `active_steps`, frames every 50 steps.
fn small(out: &Path, active_steps: u64, extra: &[&str]) -> Output {
    let steps = active_steps.to_string();
    let mut args = SMALL_RUN.to_vec();
    args.extend(["--steps", &steps, "--frame-interval", "50", "--out", arg(out)]);
    args.extend_from_slice(extra);
    monolayer(&args)
}

fn ok(o: &Output) {
    assert!(o.status.success(), "{}", stderr(o));
}

fn refused(o: &Output, expect: &[&str]) {
    assert_eq!(o.status.code(), Some(2), "{}", stderr(o));
    for e in expect {
        assert!(stderr(o).contains(e), "expected “{e}” in: {}", stderr(o));
    }
    assert!(!stderr(o).contains("panicked"), "{}", stderr(o));
}

/// The `monolayer` binary under a file-size limit, the way a full disk looks to it: every write
/// past `kb` KiB fails (with the signal that would kill it ignored, as a full disk sends none).
fn with_file_size_limit(blocks_of_512: u32, args: &[&str]) -> Output {
    let script = format!("trap '' XFSZ; ulimit -f {blocks_of_512}; exec \"$0\" \"$@\"");
    Command::new("sh").arg("-c").arg(script).arg(common::BIN).args(args).output().expect("sh runs")
}

fn edit_record(dir: &Path, edit: impl FnOnce(&mut serde_json::Value)) {
    let path = dir.join("run.json");
    let mut v: serde_json::Value = serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
    edit(&mut v);
    fs::write(&path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
}

/// The run in `dir` as if killed right after its checkpoint of `step`: checkpoint at `step`, the
/// record still running, the frames after `step` left as they were.
fn killed_at(dir: &Path, step: u64) {
    let record = RunRecord::load(dir).unwrap();
    let mut m = Monolayer::new(record.params.clone(), record.seed).unwrap();
    m.advance(step).unwrap();
    write_checkpoint(&m, &checkpoint_path(dir)).unwrap();
    edit_record(dir, |v| {
        v["status"] = "running".into();
        v["last_frame_step"] = step.into();
    });
}

// ---- 1. One writer per run directory ----

/// A second writer is refused with the directory and the process that holds it, and the lock
/// goes with its holder however it ends (here `kill -9`).
#[test]
fn a_second_writer_is_refused_and_the_lock_dies_with_its_holder() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("race");
    let mut first = common::command()
        .args(["run", "--quiet", "--threads", "1", "--set", "box_size=48", "--set", "n_cells=6"])
        .args(["--relax-steps", "1000000", "--steps", "0", "--out", arg(&run)])
        .stderr(Stdio::null())
        .spawn()
        .unwrap();
    // Until its record exists, however long that takes: a run that ends without one fails.
    while !run.join("run.json").exists() {
        if let Some(status) = first.try_wait().unwrap() {
            panic!("the first run ended ({status}) without writing its record");
        }
        std::thread::sleep(Duration::from_millis(20));
    }
    let o = monolayer(&["run", "--quiet", "--resume", arg(&run)]);
    refused(&o, &[arg(&run), &format!("process {}", first.id()), "one writer per directory"]);
    // The race: the same --out at once. Whichever check meets it, it is refused.
    let o = small(&run, 100, &["--zeta", "0.5"]);
    refused(&o, &[arg(&run)]);
    // In this process too: the lock is the OS's, not a file's existence.
    let e = RunLock::acquire(&run).unwrap_err().to_string();
    assert!(e.contains(&format!("process {}", first.id())), "{e}");
    first.kill().unwrap();
    first.wait().unwrap();
    let _lock = RunLock::acquire(&run).expect("a killed holder's lock is released");
}

// ---- 2. Duplicate sweep jobs ----

#[test]
fn a_sweep_with_duplicate_jobs_is_refused() {
    for (text, expect) in [
        ("seeds = [1, 1]\n", "`seeds` lists 1 twice"),
        ("[grid]\nzeta = [0.3, 0.3]\n", "grid `zeta` lists 0.3 twice"),
        ("[grid]\nzeta = [0.3, 0.30]\n", "grid `zeta` lists 0.3 twice"),
    ] {
        let spec: SweepSpec = toml::from_str(text).unwrap();
        let e = spec.jobs().unwrap_err().to_string();
        assert!(e.contains(expect), "{text}: {e}");
    }
    let o = monolayer(&["sweep", "--out", "/nonexistent/never", "--seeds", "2,2"]);
    refused(&o, &["`seeds` lists 2 twice"]);
}

// ---- 3. An IO error is not a blow-up, and is retried ----

const SPEC: &str = r#"
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

/// A run whose frame cannot be written (here a directory is in the way; a full disk is the same
/// to the program) is recorded as stopped, not as blown up, is left out of the regime map, and
/// runs to its end when the sweep runs again.
#[test]
fn a_sweep_retries_runs_stopped_by_an_io_error() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    let spec: SweepSpec = toml::from_str(SPEC).unwrap();
    let jobs = spec.jobs().unwrap();
    let blocked = frame_path(&out.join("runs").join(&jobs[1].name), 150);
    fs::create_dir_all(blocked.join("in_the_way")).unwrap();
    let first = run_sweep(&jobs, 50, out, 2, None, &|_, _, _| {}).unwrap();
    assert_eq!(first[0].status, RunStatus::Finished);
    assert!(matches!(&first[1].status, RunStatus::Stopped(why) if why.contains("frame_0000150.npz")), "{:?}", first[1]);
    assert!(!first[1].blew_up());
    let (summary, regimes) = tables(&first);
    assert!(summary.contains("\"stopped: "), "{summary}");
    assert!(regimes.lines().count() == 2 && !regimes.contains("\n0.4,"), "no regime from a stopped run: {regimes}");
    // From the command line: tried again, stopped again, and said so with the way out.
    let file = dir.path().join("sweep.toml");
    fs::write(&file, SPEC).unwrap();
    let o = monolayer(&["sweep", arg(&file), "--quiet", "--out", arg(out)]);
    refused(&o, &["1 run(s) stopped", "zeta0.4_seed1", "run the same command again"]);

    fs::remove_dir_all(&blocked).unwrap();
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

// ---- 4. frame_interval 0 in run.json ----

#[test]
fn a_record_with_frame_interval_zero_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    ok(&small(&run, 50, &[]));
    edit_record(&run, |v| v["frame_interval"] = 0.into());
    refused(&monolayer(&["run", "--quiet", "--resume", arg(&run)]), &["run.json", "`frame_interval` = 0"]);
}

// ---- 5. run --resume --analyze after a kill ----

/// Killed after the frame of step 200 but before its checkpoint: the resumed `--analyze` measures
/// that frame once, and its tables are those of a fresh `analyze`.
#[test]
fn resume_analyze_after_a_kill_measures_each_frame_once() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    ok(&small(&run, 150, &["--analyze"]));
    killed_at(&run, 150);
    ok(&monolayer(&["run", "--quiet", "--analyze", "--resume", arg(&run)]));
    let out = dir.path().join("fresh");
    ok(&monolayer(&["analyze", arg(&run), "--out", arg(&out)]));
    for table in ["frames.csv", "correlations.csv", "hole_probability.csv", "holes.csv"] {
        assert_eq!(lines(&run.join("analysis").join(table)), lines(&out.join(table)), "{table}");
    }
    assert_eq!(lines(&out.join("frames.csv")).len(), 1 + 4);
}

// ---- 6. Unchecked numbers ----

#[test]
fn absurd_numbers_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let o = monolayer(&["run", "--steps", "18446744073709551615", "--out", arg(&run)]);
    refused(&o, &["`active_steps`", "1000000000"]);
    refused(&monolayer(&["run", "--threads", "100000", "--out", arg(&run)]), &["--threads 100000", "must be in [1, "]);
    refused(
        &monolayer(&["sweep", "--jobs", "100000", "--out", arg(&dir.path().join("s"))]),
        &["--jobs 100000", "must be in [1, "],
    );
    assert!(!run.exists());

    // The memory a run needs is estimated before it starts, and a run past the bound refused.
    let huge = Params { box_size: 4096, n_cells: 100_000, ..Params::default() };
    huge.validate().unwrap();
    assert!(memory_estimate(&huge) > 8 << 30, "{} bytes", memory_estimate(&huge));
    assert!(memory_estimate(&Params::default()) < 64 << 20);
    let o = common::command()
        .args(["run", "--set", "box_size=4096", "--set", "n_cells=100000", "--out", arg(&run)])
        .env("MONOLAYER_MEMORY_LIMIT_MB", "4000")
        .output()
        .unwrap();
    refused(&o, &["need about", "MB, more than MONOLAYER_MEMORY_LIMIT_MB (4000 MB)"]);
    assert!(!run.exists());
}

/// A checkpoint whose step this run never writes one at, or before its last frame, is refused.
#[test]
fn a_checkpoint_of_the_wrong_step_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    ok(&small(&run, 100, &[]));
    edit_record(&run, |v| v["status"] = "running".into());
    let saved = fs::read(checkpoint_path(&run)).unwrap();
    for (step, expect) in [
        (-5, "a step is ≥ 0"),
        (1_000_000_000, "not a step this run writes a checkpoint at"),
        (10, "not a step this run writes a checkpoint at"),
        (150, "before the run's last frame (step 200"),
    ] {
        fs::write(checkpoint_path(&run), &saved).unwrap();
        edit_npz(&checkpoint_path(&run), "step", |a| {
            if let Npy::I(a) = a {
                a.fill(step)
            }
        });
        refused(&monolayer(&["run", "--quiet", "--resume", arg(&run)]), &[expect]);
    }
}

/// Killed between the last checkpoint and run.json: the resumed run records its last frame.
#[test]
fn resume_brings_the_last_frame_step_up_to_date() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    ok(&small(&run, 100, &[]));
    edit_record(&run, |v| {
        v["status"] = "running".into();
        v["last_frame_step"] = 150.into();
    });
    ok(&monolayer(&["run", "--quiet", "--resume", arg(&run)]));
    let record = RunRecord::load(&run).unwrap();
    assert_eq!((record.status, record.last_frame_step), (RunStatus::Finished, Some(200)));
}

// ---- 7. Errors that name the parameter ----

#[test]
fn bad_values_are_refused_with_their_parameter() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    refused(&small(&run, 10, &["--set", "zeta=abc"]), &["parameter `zeta` = \"abc\": must be a finite number"]);
    refused(&small(&run, 10, &["--set", "zeta=1e999"]), &["parameter `zeta` = inf"]);
    refused(&small(&run, 10, &["--set", "zeta=NaN"]), &["parameter `zeta` = NaN"]);
    refused(&small(&run, 10, &["--set", "patch_margin=1000"]), &["`patch_margin` = 1000: must be in [2, 32]"]);
    let cfg = dir.path().join("c.toml");
    fs::write(&cfg, "zeta = \"abc\"\n").unwrap();
    refused(&monolayer(&["run", "--config", arg(&cfg), "--out", arg(&run)]), &["c.toml", "parameter `zeta`"]);
    assert!(!run.exists());
    let o = monolayer(&["sweep", "--out", arg(&run), "--grid", "zeta=0.3,abc"]);
    refused(&o, &["zeta = abc", "parameter `zeta` = \"abc\""]);
}

// ---- 8. A run killed before its first periodic checkpoint ----

/// A run's start is checkpointed, so a run killed during relaxation resumes, to the same bits as
/// a run that was never stopped; a directory without a checkpoint (earlier versions) is met by
/// advice that leads out.
#[test]
fn a_run_killed_during_relaxation_resumes() {
    let dir = tempfile::tempdir().unwrap();
    let (straight, killed) = (dir.path().join("straight"), dir.path().join("killed"));
    ok(&small(&straight, 50, &[]));
    let params = RunRecord::load(&straight).unwrap().params;
    drop(RunDir::create(&killed, params, 1, 50).unwrap());
    ok(&monolayer(&["run", "--quiet", "--resume", arg(&killed)]));
    for f in ["checkpoint.npz", "frames/frame_0000150.npz"] {
        assert!(fs::read(straight.join(f)).unwrap() == fs::read(killed.join(f)).unwrap(), "{f} differs");
    }
    fs::remove_file(checkpoint_path(&killed)).unwrap();
    let o = monolayer(&["run", "--quiet", "--resume", arg(&killed)]);
    refused(&o, &["no checkpoint", "delete"]);
    assert!(!stderr(&o).contains("--resume"), "{}", stderr(&o));
    let o = small(&killed, 50, &[]);
    refused(&o, &["before its first checkpoint", "delete it"]);
    assert!(!stderr(&o).contains("--resume"), "{}", stderr(&o));
}

// ---- 9. analyze refuses frames it cannot trust ----

fn analyzed(run: &Path, out: &Path) -> Output {
    monolayer(&["analyze", arg(run), "--out", arg(out)])
}

#[test]
fn analyze_refuses_damaged_foreign_and_duplicate_frames() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    ok(&small(&run, 100, &[]));
    let out = dir.path().join("out");
    let frame = frame_path(&run, 150);
    let saved = fs::read(&frame).unwrap();

    edit_npz(&frame, "velocity", |a| {
        if let Npy::F(a) = a {
            a[[3, 4, 0]] = f64::NAN
        }
    });
    refused(&analyzed(&run, &out), &["frame_0000150.npz", "array `velocity` holds NaN"]);
    fs::write(&frame, &saved).unwrap();
    edit_npz(&frame, "time", |a| {
        if let Npy::F(a) = a {
            a.fill(f64::INFINITY)
        }
    });
    refused(&analyzed(&run, &out), &["array `time` holds inf"]);

    // Half the cells: a frame of another run, not a tissue with holes where the cells were.
    fs::write(&frame, &saved).unwrap();
    let mut arrays = read_npz(&frame);
    for (name, a) in arrays.iter_mut() {
        let keep = match name.as_str() {
            "phi_offsets" => 4,
            "centres" | "areas" | "q_hat" | "shape_tensor" | "patches" => 3,
            _ => continue,
        };
        match a {
            Npy::I(x) => *x = x.slice_axis(ndarray::Axis(0), (0..keep).into()).to_owned(),
            Npy::F(x) => *x = x.slice_axis(ndarray::Axis(0), (0..keep).into()).to_owned(),
            Npy::U(_) => unreachable!("a frame holds no bytes"),
        }
    }
    let offsets = match &arrays.iter().find(|(n, _)| n == "phi_offsets").unwrap().1 {
        Npy::I(x) => x[[3]] as usize,
        Npy::F(_) | Npy::U(_) => unreachable!(),
    };
    for (name, a) in arrays.iter_mut() {
        if let (true, Npy::F(x)) = (name == "phi", a) {
            *x = x.slice_axis(ndarray::Axis(0), (0..offsets).into()).to_owned();
        }
    }
    write_npz(&frame, &arrays);
    refused(&analyzed(&run, &out), &["frame_0000150.npz", "holds 3 cells, the run has n_cells = 6"]);
    fs::write(&frame, &saved).unwrap();

    // The same step under two names.
    fs::copy(&frame, run.join("frames").join("frame_150.npz")).unwrap();
    refused(&analyzed(&run, &out), &["frame_150.npz", "frame_0000150.npz", "both hold step 150"]);
    assert!(!out.exists());
    fs::remove_file(run.join("frames").join("frame_150.npz")).unwrap();
    ok(&analyzed(&run, &out));
    assert_eq!(RunFrames::open(&run).unwrap().frames.len(), 3);
}

/// Two writers of one file at once (`analyze` beside `run --analyze` writing the same tables):
/// neither fails for the other's temporary file.
#[test]
fn concurrent_writers_of_one_file_do_not_collide() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("frames.csv");
    std::thread::scope(|s| {
        for t in 0..4 {
            let path = &path;
            s.spawn(move || {
                for k in 0..40 {
                    let text = format!("writer {t}, write {k}\n").repeat(200);
                    write_atomic(path, |w| {
                        use std::io::Write;
                        w.write_all(text.as_bytes()).map_err(|e| monolayer::run::RunError::io(path, e))
                    })
                    .unwrap_or_else(|e| panic!("writer {t}: {e}"));
                }
            });
        }
    });
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1, "no temporary file left");
}

// ---- 10. The smaller ones ----

#[test]
fn a_sweep_rerun_with_another_frame_interval_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path();
    let spec: SweepSpec = toml::from_str(SPEC).unwrap();
    let jobs = spec.jobs().unwrap();
    run_sweep(&jobs[..1], 50, out, 1, None, &|_, _, _| {}).unwrap();
    let e = run_sweep(&jobs, 25, out, 1, None, &|_, _, _| {}).unwrap_err().to_string();
    assert!(e.contains("frame interval of 50, this sweep asks for 25"), "{e}");
}

#[test]
fn resume_refuses_parameter_options() {
    let dir = tempfile::tempdir().unwrap();
    for extra in [["--set", "zeta=0.5"], ["--zeta", "0.5"], ["--frame-interval", "7"], ["--steps", "9"]] {
        let o = monolayer(&["run", "--resume", arg(dir.path()), extra[0], extra[1]]);
        refused(&o, &["--resume", extra[0]]);
    }
}

/// A full disk while `analyze` writes leaves no partial set of tables.
#[test]
fn a_full_disk_during_analyze_leaves_no_partial_tables() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    ok(&small(&run, 100, &[]));
    let out = dir.path().join("out");
    let o = with_file_size_limit(16, &["analyze", arg(&run), "--out", arg(&out)]);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    let left: Vec<_> = fs::read_dir(&out).map(|d| d.map(|e| e.unwrap().file_name()).collect()).unwrap_or_default();
    assert!(left.is_empty(), "a partial set: {left:?}");
    ok(&analyzed(&run, &out));
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

/// The estimate steps a stable stand-in where the plan's first job blows up
/// (at γ = 0.04 the φ guard stops every run within 22 steps), and `--dry-run` needs no `--slurm`.
#[test]
fn the_estimate_survives_a_plan_whose_first_job_blows_up() {
    use monolayer::run::figures::{Figure, Plan, Scale, Speed};
    let plan = Plan::new(Scale::Smoke, &[Figure::Fig1c], &["gamma=0.04".to_string()]).unwrap();
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

/// A run.json with a parameter removed is refused, naming the key.
#[test]
fn a_record_missing_a_parameter_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &["--zeta", "0.4"]));
    edit_record(&run, |v| {
        v["params"].as_object_mut().unwrap().remove("zeta");
        v["status"] = "running".into();
    });
    let e = RunRecord::load(&run).unwrap_err().to_string();
    assert!(e.contains("`params.zeta` is missing"), "{e}");
    refused(&monolayer(&["run", "--quiet", "--resume", arg(&run)]), &["run.json", "`params.zeta` is missing"]);
}

/// A run continues only in the storage precision it started in. A record written
/// before the field existed reads as f64 (every build before it stored f64).
#[test]
fn a_run_resumes_only_in_its_own_storage_precision() {
    use monolayer::model::STORE_NAME;
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    assert_eq!(RunRecord::load(&run).unwrap().storage, STORE_NAME, "run.json records the precision");
    let other = if STORE_NAME == "f64" { "f32" } else { "f64" };
    edit_record(&run, |v| {
        v["storage"] = other.into();
        v["status"] = "running".into();
    });
    refused(&monolayer(&["run", "--quiet", "--resume", arg(&run)]), &["run.json", &format!("in {other} (`storage`)")]);
    edit_record(&run, |v| {
        v.as_object_mut().unwrap().remove("storage");
    });
    assert_eq!(RunRecord::load(&run).unwrap().storage, "f64", "a record without the field is an f64 run's");
}

/// Grids that set one parameter twice (directly, or through `chi`) or list
/// values equal as numbers are refused.
#[test]
fn grids_that_set_a_parameter_twice_are_refused() {
    for (text, expect) in [
        ("[grid]\nchi = [0.1]\nxi_substrate = [0.1, 0.5]\n", "both `chi` and `xi_substrate`"),
        ("[base]\nchi = 0.1\n[grid]\nxi_substrate = [0.5]\n", "both `chi` and `xi_substrate`"),
        ("[grid]\nzeta = [1, 1.0]\n", "grid `zeta` lists 1 twice (1 and 1.0 are one value"),
        ("[grid]\nactive_steps = [100, 1e2]\n", "grid `active_steps` lists 100 twice"),
    ] {
        let spec: SweepSpec = toml::from_str(text).unwrap();
        let e = spec.jobs().unwrap_err().to_string();
        assert!(e.contains(expect), "{text}: {e}");
    }
    let o = monolayer(&["sweep", "--out", "/nonexistent/never", "--grid", "chi=0.1", "--grid", "xi_substrate=0.5"]);
    refused(&o, &["both `chi` and `xi_substrate`"]);
    let o = monolayer(&["sweep", "--out", "/nonexistent/never", "--grid", "zeta=1,1.0"]);
    refused(&o, &["grid `zeta` lists 1 twice"]);
    let o = monolayer(&["sweep", "--out", "/nonexistent/never", "--grid", "zeta=1", "--grid", "zeta=2"]);
    refused(&o, &["`zeta` is already a grid axis"]);
}

/// `figures --jobs` has the bound of `--threads` and `sweep --jobs`.
#[test]
fn figures_jobs_are_bounded() {
    let o = monolayer(&["figures", "--jobs", "1000", "--dry-run", "--out", "/nonexistent/never"]);
    refused(&o, &["--jobs 1000: must be in [1, "]);
}

/// An `.npz` header declaring a huge shape is refused before anything is
/// allocated, in `analyze` (a frame) and in `--resume` (the checkpoint); no abort.
#[test]
fn huge_npz_headers_are_refused_before_allocating() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    let frame = frame_path(&run, 150);
    replace_npz_entry(&frame, "phi", &npy("<f8", &[10_000_000_000], &[0; 64]));
    let o = analyzed(&run, &dir.path().join("a"));
    refused(&o, &["frame_0000150.npz", "array `phi`", "damaged"]);
    edit_record(&run, |v| v["status"] = "running".into());
    replace_npz_entry(&checkpoint_path(&run), "warm_start", &npy("<f8", &[100_000, 100_000, 2], &[0; 64]));
    let o = monolayer(&["run", "--quiet", "--resume", arg(&run)]);
    refused(&o, &["checkpoint.npz", "array `warm_start`", "damaged"]);
    // A shape whose product overflows u64.
    replace_npz_entry(&checkpoint_path(&run), "warm_start", &npy("<f8", &[u64::MAX, 4], &[0; 64]));
    refused(&monolayer(&["run", "--quiet", "--resume", arg(&run)]), &["array `warm_start`"]);
}

/// A FIFO named as a frame is refused, not read (which would hang).
#[test]
fn a_fifo_among_the_frames_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    let fifo = frame_path(&run, 1000);
    common::make_fifo(&fifo);
    refused(&analyzed(&run, &dir.path().join("a")), &["frame_0001000.npz", "not a regular file"]);
}

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
        let sent = Command::new("kill").args([&format!("-{signal}"), &child.id().to_string()]).status().unwrap();
        assert!(sent.success());
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

/// Structure and type errors of TOML and JSON name the key and the line.
#[test]
fn file_errors_name_the_key_and_the_line() {
    let dir = tempfile::tempdir().unwrap();
    let sweep = |text: &str| {
        let path = dir.path().join("s.toml");
        fs::write(&path, text).unwrap();
        SweepSpec::from_file(&path).unwrap_err().to_string()
    };
    for (text, expect) in [
        ("seeds = \"1\"\n", "s.toml, line 1: key `seeds`: invalid type"),
        ("seeds = [1]\nframe_interval = -5\n", "s.toml, line 2: key `frame_interval`: invalid value: integer `-5`"),
        ("[grid]\nzeta = [0.3]\nzeta = [0.4]\n", "s.toml, line 3: duplicate key `zeta`"),
        ("[grid]\nzeta = [0.3\n", "s.toml, line 2: "),
    ] {
        let e = sweep(text);
        assert!(e.contains(expect), "{text:?}: {e}");
    }
    let config = dir.path().join("c.toml");
    fs::write(&config, "zeta = 0.3\nbox_size = 99999999999999999999\n").unwrap();
    let e = monolayer::run::load_params(Some(&config), &[]).unwrap_err().to_string();
    assert!(e.contains("c.toml, line 2: key `box_size`: ") && e.contains("too large"), "{e}");
    let e = monolayer::run::load_params(None, &["active_steps=1e19".into()]).unwrap_err().to_string();
    assert!(e.contains("`active_steps`") && e.contains("too large"), "{e}");
    let run = dir.path().join("r");
    RunRecord::new(Params { box_size: 48, n_cells: 6, ..Params::default() }, 1, 50).save(&run).unwrap_or_else(|_| {
        fs::create_dir_all(&run).unwrap();
        RunRecord::new(Params { box_size: 48, n_cells: 6, ..Params::default() }, 1, 50).save(&run).unwrap()
    });
    edit_record(&run, |v| v["seed"] = (-1).into());
    let e = RunRecord::load(&run).unwrap_err().to_string();
    assert!(e.contains("`seed`") && e.contains("line "), "{e}");
}

/// An `--out` an `#SBATCH` line cannot hold is refused, naming what is wrong.
#[test]
fn slurm_scripts_refuse_paths_sbatch_cannot_hold() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["a b", "100%", "line\nbreak", "q\"uote"] {
        let out = dir.path().join(name);
        let o = monolayer(&["figures", "--only", "S3", "--slurm", "--dry-run", "--out", arg(&out)]);
        refused(&o, &["--out", "an #SBATCH line cannot hold"]);
    }
}

/// `.lock` is never followed through a symbolic link.
#[test]
fn the_lock_is_not_followed_through_a_symlink() {
    let dir = tempfile::tempdir().unwrap();
    let victim = dir.path().join("precious.txt");
    fs::write(&victim, "keep me").unwrap();
    let run = dir.path().join("r");
    fs::create_dir_all(&run).unwrap();
    std::os::unix::fs::symlink(&victim, run.join(RunLock::FILE)).unwrap();
    let e = RunLock::acquire(&run).unwrap_err().to_string();
    assert!(e.contains("symbolic link"), "{e}");
    assert_eq!(fs::read_to_string(&victim).unwrap(), "keep me");
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

/// Absurd but finite inputs are refused.
#[test]
fn absurd_finite_inputs_are_refused() {
    use monolayer::formats::snapshot::{decode, encode};
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    // A frame with φ = 1e300 (analysed into NaN before).
    edit_npz(&frame_path(&run, 150), "phi", |a| match a {
        Npy::F(a) => a[[0]] = 1e300,
        Npy::I(_) | Npy::U(_) => unreachable!(),
    });
    refused(&analyzed(&run, &dir.path().join("a")), &["frame_0000150.npz", "`phi`"]);
    // φ = 3 is finite and small, and still no φ a run leaves.
    edit_npz(&frame_path(&run, 150), "phi", |a| match a {
        Npy::F(a) => a[[0]] = 3.0,
        Npy::I(_) | Npy::U(_) => unreachable!(),
    });
    refused(&analyzed(&run, &dir.path().join("a")), &["frame_0000150.npz", "φ = 3"]);
    // A checkpoint whose substrate map is ≤ 0.
    edit_record(&run, |v| v["status"] = "running".into());
    edit_npz(&checkpoint_path(&run), "substrate", |a| match a {
        Npy::F(a) => a[[3, 4]] = -1.0,
        Npy::I(_) | Npy::U(_) => unreachable!(),
    });
    refused(&monolayer(&["run", "--quiet", "--resume", arg(&run)]), &["`substrate`", "> 0"]);
    // The relaxed-state decoder: NaN, a 0-wide patch, a step past any run.
    let p = Params { box_size: 48, n_cells: 6, ..Params::default() };
    let state = Monolayer::new(p.clone(), 1).unwrap().state();
    assert!(decode(&encode(&state, 7), 7, 48).is_ok());
    let mut nan = state.clone();
    nan.cells[0].1[5] = f64::NAN;
    let mut narrow = state.clone();
    narrow.cells[0].0.w = 0;
    let mut late = state.clone();
    late.step = u64::MAX;
    let mut soft = state.clone();
    soft.substrate[0] = 0.0;
    for (what, s) in [("NaN", nan), ("0-wide", narrow), ("u64::MAX", late), ("substrate 0", soft)] {
        assert!(decode(&encode(&s, 7), 7, 48).is_err(), "{what} accepted");
    }
    // A 200,000-value grid is refused before its runs are validated one by one.
    let values: Vec<String> = (0..200_000).map(|i| format!("{}", 0.1 + i as f64 * 1e-6)).collect();
    let spec: SweepSpec = toml::from_str(&format!("[grid]\nzeta = [{}]\n", values.join(","))).unwrap();
    assert!(spec.jobs().unwrap_err().to_string().contains("more than a sweep's 100000 runs"));
}

/// Temporaries of writers killed with -9 (`.staging.PID.N` in the analysis
/// directory, `.NAME.PID.N.tmp` in a figures directory) are cleaned on the next start; a living
/// writer's are left.
#[test]
fn stale_temporaries_of_dead_writers_are_cleaned() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    let analysis = dir.path().join("a");
    let dead = analysis.join(".staging.999999999.0");
    let alive = analysis.join(format!(".staging.{}.0", std::process::id()));
    fs::create_dir_all(&dead).unwrap();
    fs::create_dir_all(&alive).unwrap();
    fs::write(dead.join("frames.csv"), "x").unwrap();
    ok(&analyzed(&run, &analysis));
    assert!(!dead.exists() && alive.exists());
    let figs = dir.path().join("f");
    fs::create_dir_all(&figs).unwrap();
    let stale = figs.join(".figures.md.999999999.3.tmp");
    fs::write(&stale, "x").unwrap();
    let _ = monolayer(&["figures", "--only", "S3", "--stage", "figures", "--out", arg(&figs)]);
    assert!(!stale.exists());
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
    assert!(Command::new("kill").args(["-TERM", &child.id().to_string()]).status().unwrap().success());
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

// ---- Outputs renamed into place ----

fn is_fifo(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_fifo())
}

fn relaxed_state(out: &Path) -> Output {
    monolayer(&[
        "relaxed-state",
        "--set",
        "box_size=48",
        "--set",
        "n_cells=10",
        "--relax-steps",
        "50",
        "--out",
        arg(out),
    ])
}

/// A rename replaces whatever is at its target: an output path that is a FIFO (or a device, or a
/// link to one) is refused and left as it is; a link to a regular file is written through.
#[test]
fn an_output_that_is_not_a_regular_file_is_refused_and_kept() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo");
    common::make_fifo(&fifo);
    refused(&relaxed_state(&fifo), &[arg(&fifo), "a FIFO", "not a regular file"]);
    assert!(is_fifo(&fifo), "the FIFO was replaced");

    let link = dir.path().join("link");
    std::os::unix::fs::symlink(&fifo, &link).unwrap();
    refused(&relaxed_state(&link), &[arg(&link), "a symbolic link to a FIFO"]);
    assert!(fs::symlink_metadata(&link).unwrap().file_type().is_symlink() && is_fifo(&fifo));

    let dangling = dir.path().join("dangling");
    std::os::unix::fs::symlink(dir.path().join("nothing"), &dangling).unwrap();
    refused(&relaxed_state(&dangling), &[arg(&dangling), "symbolic link to nothing"]);

    let file = dir.path().join("state.bin");
    fs::write(&file, "old").unwrap();
    let to_file = dir.path().join("to_file");
    std::os::unix::fs::symlink(&file, &to_file).unwrap();
    ok(&relaxed_state(&to_file));
    assert!(fs::symlink_metadata(&to_file).unwrap().file_type().is_symlink(), "the link was replaced");
    assert!(fs::read(&file).unwrap().len() > 100, "the state was not written through the link");

    // `analyze` moves its tables in as one set: a FIFO among them is refused before any is moved.
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    let analysis = dir.path().join("a");
    fs::create_dir_all(&analysis).unwrap();
    let holes = analysis.join("holes.csv");
    common::make_fifo(&holes);
    refused(&analyzed(&run, &analysis), &[arg(&holes), "a FIFO"]);
    assert!(is_fifo(&holes));
    let left: Vec<_> = fs::read_dir(&analysis).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, ["holes.csv"], "files moved in beside the refused one");
}

// ---- Tables of the runs a sweep directory holds ----

/// `sweep --tables-only` given no grid measures every run in OUT/runs with the parameters its
/// run.json records, the grid values read from the runs' names.
#[test]
fn tables_only_without_a_grid_measures_the_runs_in_the_directory() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let sweep = |extra: &[&str]| {
        let mut args = vec!["sweep", "--quiet", "--jobs", "1", "--out", arg(&out)];
        args.extend_from_slice(extra);
        monolayer(&args)
    };
    ok(&sweep(&[
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
    ]));
    let before = (lines(&out.join("summary.csv")), lines(&out.join("regimes.csv")));
    assert_eq!(before.0.len(), 3, "{:?}", before.0);
    let o = sweep(&["--tables-only"]);
    ok(&o);
    assert!(stderr(&o).contains("2 runs in"), "{}", stderr(&o));
    let after = (lines(&out.join("summary.csv")), lines(&out.join("regimes.csv")));
    assert_eq!(after.0.len(), 3, "{:?}", after.0);
    assert!(after.0[0].starts_with("run,zeta,seed,"), "{}", after.0[0]);
    assert!(after.0[1].starts_with("zeta0.2_seed1,0.2,1,") && after.0[2].starts_with("zeta0.4_seed1,0.4,1,"));
    assert_eq!(after, before, "the tables changed");
}

// ---- A checkpoint belongs to its parameters ----

/// A run whose run.json was edited after it stopped is refused on resume, naming the parameter,
/// where it would have continued one trajectory under another's parameters; a checkpoint written
/// before checkpoints held their parameters still resumes.
#[test]
fn a_resume_under_edited_parameters_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 100, &[]));
    killed_at(&run, 150);
    let saved = fs::read_to_string(run.join("run.json")).unwrap();
    let resume = || monolayer(&["run", "--quiet", "--resume", arg(&run)]);
    for (key, value) in [("gamma", serde_json::json!(0.07)), ("relax_steps", 50.into()), ("seed", 2.into())] {
        edit_record(&run, |v| match key {
            "seed" => v["seed"] = value.clone(),
            _ => v["params"][key] = value.clone(),
        });
        refused(&resume(), &[&format!("`{key}` = {value}"), "checkpoint.npz", "run.json"]);
        fs::write(run.join("run.json"), &saved).unwrap();
    }
    // A longer run continues the same trajectory.
    edit_record(&run, |v| v["params"]["active_steps"] = 150.into());
    ok(&resume());
    assert!(frame_path(&run, 250).exists());
    killed_at(&run, 150);
    let mut arrays = read_npz(&checkpoint_path(&run));
    arrays.retain(|(name, _)| name != "run_params");
    write_npz(&checkpoint_path(&run), &arrays);
    ok(&resume());
    assert_eq!(RunRecord::load(&run).unwrap().status, RunStatus::Finished);
}

// ---- One value per parameter ----

/// A parameter given twice, by a flag and `--set` or by a sweep's base and its grid, is refused
/// by name in either order, where one of the two used to be dropped unsaid.
#[test]
fn a_parameter_set_twice_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("r");
    // Small, so that a regression that starts the run ends soon.
    let tiny = ["--set", "box_size=48", "--set", "n_cells=6", "--set", "relax_steps=5"];
    for args in [
        ["--chi", "0.1", "--set", "xi_substrate=0.5", "--steps", "5"],
        ["--set", "xi_substrate=0.5", "--chi", "0.1", "--steps", "5"],
        ["--zeta", "0.3", "--set", "zeta=0.4", "--steps", "5"],
        ["--set", "active_steps=10", "--steps", "20", "--zeta", "0.3"],
    ] {
        let mut run = vec!["run", "--quiet", "--frame-interval", "5", "--out", arg(&out)];
        run.extend(tiny);
        run.extend(args);
        let key = args.iter().find_map(|a| a.split_once('=')).unwrap().0;
        refused(&monolayer(&run), &[&format!("`{key}`"), "give one of them"]);
        assert!(!out.exists(), "{args:?}: a run was started");
    }
    let sweep = dir.path().join("s");
    let mut args = vec!["sweep", "--quiet", "--jobs", "1", "--frame-interval", "5", "--out", arg(&sweep)];
    args.extend(tiny);
    args.extend(["--set", "active_steps=5", "--grid", "gamma=0.06", "--set", "gamma=0.08"]);
    refused(&monolayer(&args), &["`gamma`", "[base]", "the grid"]);
    let file = dir.path().join("s.toml");
    let base = "frame_interval = 5\n[base]\nbox_size = 48\nn_cells = 6\nrelax_steps = 5\nactive_steps = 5\n";
    fs::write(&file, format!("{base}gamma = 0.08\n[[points]]\ngamma = 0.06\nzeta = 0.3\n")).unwrap();
    refused(
        &monolayer(&["sweep", arg(&file), "--quiet", "--jobs", "1", "--out", arg(&sweep)]),
        &["`gamma`", "the points"],
    );
    assert!(!sweep.exists(), "a sweep was started");
}

// ---- Frames a run did not write ----

/// Two files of one step: the error says to remove the one whose name this run does not write,
/// not its own.
#[test]
fn a_duplicate_step_names_the_file_the_run_did_not_write() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    let foreign = run.join("frames").join("frame_150.npz");
    fs::copy(frame_path(&run, 150), &foreign).unwrap();
    let e = RunFrames::open(&run).unwrap_err().to_string();
    let own = frame_path(&run, 150);
    assert!(e.contains(&format!("did not write ({}; its own is {})", foreign.display(), own.display())), "{e}");
}

/// Frames missing in the middle of a run would be measured as one frame interval; refused,
/// naming the steps, as is a frame off the run's schedule.
#[test]
fn analyze_refuses_a_gap_in_the_frames() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 150, &[]));
    let out = dir.path().join("a");
    let off = run.join("frames").join("frame_0000175.npz");
    fs::copy(frame_path(&run, 150), &off).unwrap();
    refused(&analyzed(&run, &out), &["frame_0000175.npz", "not a frame interval after", "frame_interval = 50"]);
    fs::remove_file(&off).unwrap();
    for step in [150, 200] {
        fs::remove_file(frame_path(&run, step)).unwrap();
    }
    refused(&analyzed(&run, &out), &["frames missing at steps 150, 200", "frame_interval = 50"]);
    assert!(!out.exists());
}

/// NaN or inf in any array of a frame, the ones the analysis recomputes from φ included, is
/// refused naming the file and the array.
#[test]
fn analyze_refuses_nan_in_every_array_of_a_frame() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    let out = dir.path().join("a");
    let frame = frame_path(&run, 150);
    let saved = fs::read(&frame).unwrap();
    for (array, value) in [("phi_sum", f64::NAN), ("centres", f64::NAN), ("areas", f64::INFINITY)] {
        edit_npz(&frame, array, |a| match a {
            Npy::F(a) => *a.iter_mut().nth(3).unwrap() = value,
            _ => panic!("{array} is not f64"),
        });
        refused(&analyzed(&run, &out), &["frame_0000150.npz", &format!("array `{array}` holds {value}")]);
        fs::write(&frame, &saved).unwrap();
    }
    ok(&analyzed(&run, &out));
}

// ---- Temporaries of a killed sweep ----

/// A sweep's tables are written through temporaries in OUT; those of a sweep killed with -9
/// are removed by the next one, a living writer's are left.
#[test]
fn a_sweep_removes_the_temporaries_of_dead_writers() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    fs::create_dir_all(&out).unwrap();
    let dead = out.join(".summary.csv.999999999.0.tmp");
    let alive = out.join(format!(".regimes.csv.{}.0.tmp", std::process::id()));
    fs::write(&dead, "x").unwrap();
    fs::write(&alive, "x").unwrap();
    ok(&monolayer(&["sweep", "--out", arg(&out), "--tables-only", "--grid", "zeta=0.2"]));
    assert!(!dead.exists() && alive.exists());
}

// ---- Inputs, limits and the errors that name them ----

/// The tiny box of these tests.
const TINY: [&str; 6] = ["--set", "box_size=48", "--set", "n_cells=10", "--relax-steps", "20"];

/// A refusal within a minute, with every expected text in its error.
fn refused_within(args: &[&str], env: &[(&str, &str)], expect: &[&str]) {
    refused(&common::monolayer_within(60, args, env), expect);
}

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

/// Every flag that names an input file refuses a FIFO (or a link to one) before opening it,
/// where it used to block for ever; a config file past its size limit is refused by size.
#[test]
fn input_files_that_are_not_regular_files_are_refused() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo");
    common::make_fifo(&fifo);
    let link = dir.path().join("link.toml");
    std::os::unix::fs::symlink(&fifo, &link).unwrap();
    let relaxed = dir.path().join("relaxed.bin");
    for input in [&fifo, &link] {
        let f = arg(input);
        let out = dir.path().join("out");
        for args in [
            vec!["run", "--quiet", "--config", f, "--out", arg(&out)],
            vec!["fingerprint", "--config", f, "--total-steps", "1"],
            vec!["relaxed-state", "--config", f, "--out", arg(&relaxed)],
            vec!["sweep", "--quiet", f, "--out", arg(&out)],
            [&["bench", "--steps", "2", "--blocks", "1", "--from-relaxed", f][..], &TINY[..4]].concat(),
        ] {
            refused_within(&args, &[], &[f, "is a FIFO, not a regular file"]);
        }
        assert!(!out.exists());
    }
    // A run whose record or checkpoint is a FIFO: resume and analyze refuse it.
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    let record = run.join("run.json");
    fs::rename(&record, dir.path().join("run.json")).unwrap();
    common::make_fifo(&record);
    refused_within(&["run", "--quiet", "--resume", arg(&run)], &[], &["run.json", "not a regular file"]);
    refused_within(&["analyze", arg(&run)], &[], &["run.json", "not a regular file"]);
    fs::remove_file(&record).unwrap();
    fs::rename(dir.path().join("run.json"), &record).unwrap();
    fs::remove_file(checkpoint_path(&run)).unwrap();
    common::make_fifo(&checkpoint_path(&run));
    refused_within(&["run", "--quiet", "--resume", arg(&run)], &[], &["checkpoint.npz", "not a regular file"]);
    // A config file of 2 MiB is no config file.
    let big = dir.path().join("big.toml");
    fs::write(&big, format!("zeta = 0.4\n{}", "# padding\n".repeat(210_000))).unwrap();
    refused_within(
        &["fingerprint", "--config", arg(&big), "--total-steps", "1"],
        &[],
        &["big.toml", "1048576 bytes at most"],
    );
}

/// Documented bounds enforced: `--total-steps` at most 10⁹, a frame interval no longer than the
/// active phase, friction coefficients in a finite range (ξ_cell = 0, the dry limit, kept).
#[test]
fn bounds_of_steps_intervals_and_frictions_are_enforced() {
    let dir = tempfile::tempdir().unwrap();
    refused_within(
        &[&["fingerprint", "--total-steps", "1000000001"][..], &TINY].concat(),
        &[],
        &["--total-steps 1000000001", "[0, 1000000000]"],
    );
    let out = dir.path().join("r");
    let run = [&SMALL_RUN[..], &["--steps", "50", "--frame-interval", "1000000000000", "--out", arg(&out)]].concat();
    refused_within(&run, &[], &["--frame-interval 1000000000000", "active_steps = 50"]);
    assert!(!out.exists());
    let sweep = [
        &["sweep", "--quiet", "--set", "active_steps=50", "--frame-interval", "51", "--out", arg(&out)][..],
        &TINY[..4],
    ]
    .concat();
    refused_within(&sweep, &[], &["--frame-interval 51", "active_steps = 50"]);
    for (set, name) in [
        ("xi_substrate=1e-300", "xi_substrate"),
        ("xi_substrate=1e300", "xi_substrate"),
        ("xi_cell=1e300", "xi_cell"),
        ("xi_cell=1e-9", "xi_cell"),
        ("xi_relax=1e-300", "xi_relax"),
    ] {
        let args = [&["fingerprint", "--total-steps", "1", "--set", set][..], &TINY].concat();
        refused_within(&args, &[], &[&format!("parameter `{name}`"), "[1e-6, 1e3]"]);
    }
    let dry = Params { xi_cell: 0.0, ..Params::default() };
    assert!(dry.validate().is_ok());
    for chi in [0.001, 0.01, 0.1, 1.0] {
        let mut p = Params::default();
        p.set_chi(chi);
        assert!(p.validate().is_ok(), "χ = {chi}");
    }
}

/// Errors that name their file and say what is wrong: an empty patch or a cell count off in a
/// checkpoint, a wrong value in a config file (its line and column), a `.lock` that is a FIFO.
#[test]
fn damaged_checkpoints_configs_and_locks_are_named() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    let checkpoint = checkpoint_path(&run);
    let saved = fs::read(&checkpoint).unwrap();
    edit_npz(&checkpoint, "patches", |a| match a {
        Npy::I(a) => a[[0, 2]] = 0,
        _ => panic!("patches are integers"),
    });
    refused_within(&["run", "--quiet", "--resume", arg(&run)], &[], &["checkpoint.npz: cell 0: patch at", "is 0×"]);
    // A checkpoint of before it held its parameters, with one cell too many for run.json.
    fs::write(&checkpoint, &saved).unwrap();
    let arrays: Vec<(String, Npy)> = read_npz(&checkpoint).into_iter().filter(|(n, _)| n != "run_params").collect();
    write_npz(&checkpoint, &arrays);
    edit_record(&run, |v| v["params"]["n_cells"] = 5.into());
    refused_within(&["run", "--quiet", "--resume", arg(&run)], &[], &["checkpoint.npz: ", "checkpoint has 6 cells"]);
    edit_record(&run, |v| v["params"]["n_cells"] = 6.into());
    let lock = run.join(RunLock::FILE);
    fs::remove_file(&lock).unwrap();
    common::make_fifo(&lock);
    refused_within(&["run", "--quiet", "--resume", arg(&run)], &[], &[".lock", "is a FIFO, not a regular file"]);
    let config = dir.path().join("c.toml");
    fs::write(&config, "zeta = 0.3\n  xi_substrate = \"abc\"\n").unwrap();
    let e = monolayer::run::load_params(Some(&config), &[]).unwrap_err().to_string();
    assert!(e.contains("c.toml, line 2, column 18: parameter `xi_substrate`"), "{e}");
    let e = monolayer::run::load_params(Some(&config), &["xi_substrate=0.1".into(), "zeta=abc".into()])
        .unwrap_err()
        .to_string();
    assert!(e.starts_with("--set: parameter `zeta`"), "{e}");
}

/// A sweep that finds some of its runs held by another writer (the same sweep started twice)
/// says so, naming the holder, and why it writes no tables.
#[test]
fn a_sweep_beside_another_names_the_holder_of_its_runs() {
    let dir = tempfile::tempdir().unwrap();
    let spec: SweepSpec = toml::from_str(
        "seeds = [1, 2]\nframe_interval = 10\n[base]\nbox_size = 48\nn_cells = 10\nrelax_steps = 10\nactive_steps = 10\n",
    )
    .unwrap();
    let jobs = spec.jobs().unwrap();
    let held = dir.path().join("runs").join(&jobs[0].name);
    fs::create_dir_all(&held).unwrap();
    let _lock = RunLock::acquire(&held).unwrap();
    let e = run_sweep(&jobs, 10, dir.path(), 1, None, &|_, _, _| {}).unwrap_err().to_string();
    let pid = std::process::id();
    assert!(e.contains(&format!("being written by process {pid}")) && e.contains("summary.csv"), "{e}");
    assert!(e.contains(&jobs[0].name) && !e.contains(&jobs[1].name), "{e}");
}

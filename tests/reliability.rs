//! What a demanding user does to a run: two writers in one directory, a full disk, a kill at the
//! wrong moment, a hand-edited record, damaged or foreign frames, absurd numbers. Each test here
//! reproduces one defect of issue 16 and fails without its fix.

mod common;

use std::fs;
use std::path::Path;
use std::process::{Command, Output, Stdio};
use std::time::Duration;

use common::{arg, lines, monolayer, stderr};
use monolayer::run::files::{
    checkpoint_path, frame_path, write_atomic, write_checkpoint, RunFrames, RunLock, RunRecord, RunStatus,
};
use monolayer::run::runner::{memory_estimate, RunDir};
use monolayer::run::sweep::{run_sweep, tables, SweepSpec};
use monolayer::{Monolayer, Params};
use ndarray::{ArrayD, IxDyn};
use ndarray_npy::{NpzReader, NpzWriter};

/// A small quick protocol: 6 cells on a 48×48 box, on one thread, relaxation to step 100.
const SMALL_RUN: [&str; 10] =
    ["run", "--quiet", "--threads", "1", "--set", "box_size=48", "--set", "n_cells=6", "--relax-steps", "100"];

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
    Command::new("sh").arg("-c").arg(script).arg(env!("CARGO_BIN_EXE_monolayer")).args(args).output().expect("sh runs")
}

/// Every array of an `.npz`, as i64 or f64 arrays by name.
enum Npy {
    I(ArrayD<i64>),
    F(ArrayD<f64>),
}

fn read_npz(path: &Path) -> Vec<(String, Npy)> {
    let mut z = NpzReader::new(fs::File::open(path).unwrap()).unwrap();
    let names = z.names().unwrap();
    names
        .into_iter()
        .map(|n| {
            let name = n.trim_end_matches(".npy").to_string();
            let a = match z.by_name::<ndarray::OwnedRepr<i64>, IxDyn>(&name) {
                Ok(a) => Npy::I(a),
                Err(_) => Npy::F(z.by_name::<ndarray::OwnedRepr<f64>, IxDyn>(&name).unwrap()),
            };
            (name, a)
        })
        .collect()
}

fn write_npz(path: &Path, arrays: &[(String, Npy)]) {
    let mut z = NpzWriter::new_compressed(fs::File::create(path).unwrap());
    for (name, a) in arrays {
        match a {
            Npy::I(a) => z.add_array(name.as_str(), a).unwrap(),
            Npy::F(a) => z.add_array(name.as_str(), a).unwrap(),
        }
    }
    z.finish().unwrap();
}

/// Rewrites one array of an `.npz` file.
fn edit_npz(path: &Path, name: &str, edit: impl FnOnce(&mut Npy)) {
    let mut arrays = read_npz(path);
    edit(&mut arrays.iter_mut().find(|(n, _)| n == name).unwrap_or_else(|| panic!("no array {name}")).1);
    write_npz(path, &arrays);
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
    let mut first = Command::new(env!("CARGO_BIN_EXE_monolayer"))
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
    // The race of issue 16: the same --out at once. Whichever check meets it, it is refused.
    let o = small(&run, 100, &["--zeta", "0.5"]);
    refused(&o, &[arg(&run)]);
    // In this process too: the lock is the OS's, not a file's existence.
    let e = RunLock::acquire(&run).unwrap_err();
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
        let e = spec.jobs().unwrap_err();
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
    let o = Command::new(env!("CARGO_BIN_EXE_monolayer"))
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
        }
    }
    let offsets = match &arrays.iter().find(|(n, _)| n == "phi_offsets").unwrap().1 {
        Npy::I(x) => x[[3]] as usize,
        Npy::F(_) => unreachable!(),
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
                        w.write_all(text.as_bytes()).map_err(|e| e.to_string())
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
    let e = run_sweep(&jobs, 25, out, 1, None, &|_, _, _| {}).unwrap_err();
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

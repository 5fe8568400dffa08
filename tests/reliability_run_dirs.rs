//! Run directories: one writer each, never overwritten, continued only as what they are, and
//! read only whole. What a demanding user does to them (two writers at once, a kill at the
//! wrong moment, a hand-edited record, frames deleted or slipped in) is refused by name, and
//! nothing is counted as a result that was not measured. Each test reproduces a defect and
//! fails without its fix.

mod common;

use std::fs;
use std::process::Stdio;
use std::time::Duration;

use common::faults::{analyzed, edit_record, killed_at, ok, refused, small, SPEC, SWEEP_ARGS};
use common::npz::{edit_npz, read_npz, write_npz, Npy};
use common::{arg, lines, monolayer, stderr};
use monolayer::formats::{RunRecord, RunStatus};
use monolayer::run::{
    checkpoint_path, frame_path, run_sweep, write_run_checkpoint, RunDir, RunFrames, RunLock, SweepSpec,
};
use monolayer::Monolayer;

// ---- One writer ----

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

/// A run directory without its run.json (a kill between the checkpoint of the start and the
/// record, or a record deleted) is not a place for a new run: `run --out` there is refused,
/// saying why and what to do, and leaves the checkpoint and the frames as they were. A directory
/// holding anything else is refused too. A sweep whose own run was killed so, at its start,
/// starts it again.
#[test]
fn a_new_run_is_never_written_over_a_run_without_its_record() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    fs::remove_file(run.join("run.json")).unwrap();
    let checkpoint = fs::read(checkpoint_path(&run)).unwrap();
    let frame = fs::read(frame_path(&run, 100)).unwrap();
    let o = small(&run, 100, &["--zeta", "0.3"]);
    refused(&o, &[arg(&run), "no run.json", "nothing here was changed", "delete", "another --out"]);
    assert!(fs::read(checkpoint_path(&run)).unwrap() == checkpoint, "the checkpoint was changed");
    assert!(fs::read(frame_path(&run, 100)).unwrap() == frame, "a frame was changed");
    assert!(!run.join("run.json").exists());
    // A directory of anything else.
    let other = dir.path().join("other");
    fs::create_dir_all(&other).unwrap();
    fs::write(other.join("notes.txt"), "mine").unwrap();
    refused(&small(&other, 50, &[]), &["is not empty (notes.txt)", "choose another --out"]);
    assert_eq!(fs::read_dir(&other).unwrap().count(), 1, "something was written beside notes.txt");
    // What a start that wrote nothing leaves is no run: an empty frames/ and a .lock.
    let empty = dir.path().join("empty");
    fs::create_dir_all(empty.join("frames")).unwrap();
    fs::write(empty.join(RunLock::FILE), "").unwrap();
    ok(&small(&empty, 50, &[]));
    // A sweep's run killed between its first checkpoint and its record starts again.
    let out = dir.path().join("s");
    let spec: SweepSpec = toml::from_str(SPEC).unwrap();
    let jobs = spec.jobs().unwrap();
    let killed = out.join("runs").join(&jobs[0].name);
    drop(RunDir::create(&killed, jobs[0].params.clone(), jobs[0].seed, 50).unwrap());
    fs::remove_file(killed.join("run.json")).unwrap();
    let summaries = run_sweep(&jobs, 50, &out, 1, None, &|_, _, _| {}).unwrap();
    assert!(summaries.iter().all(|s| s.status == RunStatus::Finished && s.steps == 200), "{summaries:?}");
}

/// Two sweeps of one OUT at once: each takes up the runs the other had under way once they
/// are let go of, so both end with the tables of every run (where each refused to write any).
#[test]
fn two_sweeps_of_one_out_both_write_every_run_s_tables() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let args = [&["sweep", "--quiet", "--jobs", "1", "--seeds", "1,2", "--out", arg(&out)][..], &SWEEP_ARGS].concat();
    let spawn = || common::command().args(&args).stdout(Stdio::piped()).stderr(Stdio::piped()).spawn().unwrap();
    let (first, second) = (spawn(), spawn());
    for o in [first.wait_with_output().unwrap(), second.wait_with_output().unwrap()] {
        ok(&o);
        assert!(String::from_utf8_lossy(&o.stdout).contains("summary.csv"), "{}", stderr(&o));
    }
    let summary = lines(&out.join("summary.csv"));
    assert_eq!(summary.len(), 1 + 4, "{summary:?}");
    assert!(summary[1..].iter().all(|l| l.contains("\"finished\"")), "{summary:?}");
}

/// In one process: a run held by another writer is taken up once it is let go of (here when
/// the other run of the sweep has finished), done by then or not.
#[test]
fn a_sweep_waits_for_the_runs_another_writer_holds() {
    let dir = tempfile::tempdir().unwrap();
    let spec: SweepSpec = toml::from_str(
        "seeds = [1, 2]\nframe_interval = 10\n[base]\nbox_size = 48\nn_cells = 10\nrelax_steps = 10\nactive_steps = 10\n",
    )
    .unwrap();
    let jobs = spec.jobs().unwrap();
    let runs = dir.path().join("runs");
    let held = runs.join(&jobs[0].name);
    fs::create_dir_all(&held).unwrap();
    let lock = RunLock::acquire(&held).unwrap();
    let other = runs.join(&jobs[1].name);
    let summaries = std::thread::scope(|s| {
        let sweep = s.spawn(|| run_sweep(&jobs, 10, dir.path(), 1, None, &|_, _, _| {}));
        while !RunRecord::load(&other).is_ok_and(|r| r.status == RunStatus::Finished) {
            assert!(!sweep.is_finished(), "the sweep ended without waiting: {:?}", sweep.join());
            std::thread::sleep(Duration::from_millis(20));
        }
        drop(lock);
        sweep.join().unwrap()
    })
    .unwrap();
    assert_eq!(summaries.len(), 2);
    assert!(summaries.iter().all(|s| s.status == RunStatus::Finished), "{summaries:?}");
}

/// A sweep run again over its OUT with another frame interval is refused: its runs would
/// continue on another schedule of frames.
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

// ---- Continued only as what it is ----

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

/// An edit of run.json's box or frame interval is named on resume as any other parameter is,
/// not taken for a damaged checkpoint (its lattice, its step off the schedule).
#[test]
fn a_resume_after_editing_the_box_or_the_frame_interval_names_the_key() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 100, &[]));
    edit_record(&run, |v| v["status"] = "running".into());
    let saved = fs::read_to_string(run.join("run.json")).unwrap();
    let resume = || monolayer(&["run", "--quiet", "--resume", arg(&run)]);
    for (key, value) in [("box_size", 40), ("box_size", 140)] {
        edit_record(&run, |v| v["params"][key] = value.into());
        refused(&resume(), &[&format!("`{key}` = {value} there"), &format!("{key} = 48"), "run.json"]);
        fs::write(run.join("run.json"), &saved).unwrap();
    }
    edit_record(&run, |v| v["frame_interval"] = 30.into());
    refused(&resume(), &["`frame_interval` = 30 there", "frame_interval = 50", "run.json edited"]);
    fs::write(run.join("run.json"), &saved).unwrap();
    ok(&resume());
}

/// The engine edited in run.json (cpu ↔ gpu-f32) is refused on resume by name, the status
/// unchanged: the checkpoint records the engine that stepped it.
#[test]
fn an_engine_edited_in_the_record_is_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 100, &[]));
    edit_record(&run, |v| v["status"] = "stopped: signal SIGTERM".into());
    let resume = || monolayer(&["run", "--quiet", "--resume", arg(&run)]);
    edit_record(&run, |v| v["engine"] = "gpu-f32".into());
    refused(&resume(), &["`engine` = \"gpu-f32\" there", "engine = \"cpu\"", "restore `engine`"]);
    assert_eq!(RunRecord::load(&run).unwrap().status, RunStatus::Stopped("signal SIGTERM".into()));
    // The other way: a checkpoint of the GPU engine under a record edited to the CPU's.
    let mut record = RunRecord::load(&run).unwrap();
    let state = monolayer::run::read_checkpoint(&checkpoint_path(&run), 48).unwrap();
    let m = Monolayer::from_state(record.params.clone(), record.seed, state).unwrap();
    record.engine = "gpu-f32".into();
    write_run_checkpoint(&m, &checkpoint_path(&run), &record).unwrap();
    edit_record(&run, |v| v["engine"] = "cpu".into());
    refused(&resume(), &["`engine` = \"cpu\" there", "engine = \"gpu-f32\""]);
    assert_eq!(RunRecord::load(&run).unwrap().status, RunStatus::Stopped("signal SIGTERM".into()));
}

/// A healthy run of the GPU engine that cannot have its GPU (no adapter, or a build without
/// the GPU kernels) is `stopped:` (resumable), not `failed:` (a permanent result), and the
/// reason is printed once.
#[test]
fn a_gpu_run_without_its_gpu_is_stopped_not_failed() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 100, &[]));
    killed_at(&run, 150);
    let mut record = RunRecord::load(&run).unwrap();
    record.engine = "gpu-f32".into();
    record.status = RunStatus::Stopped("signal SIGTERM".into());
    record.save(&run).unwrap();
    let state = monolayer::run::read_checkpoint(&checkpoint_path(&run), 48).unwrap();
    let m = Monolayer::from_state(record.params.clone(), record.seed, state).unwrap();
    write_run_checkpoint(&m, &checkpoint_path(&run), &record).unwrap();
    // No Vulkan driver for the loader to find: no adapter, in a build with the GPU engine.
    let o = common::command()
        .args(["run", "--quiet", "--resume", arg(&run)])
        .env("VK_ICD_FILENAMES", "/nonexistent.json")
        .env("VK_DRIVER_FILES", "/nonexistent.json")
        .output()
        .unwrap();
    let why = if cfg!(feature = "gpu") { "no GPU adapter" } else { "built without the GPU kernels" };
    refused(&o, &[why, "--resume"]);
    assert_eq!(stderr(&o).matches(why).count(), 1, "printed more than once: {}", stderr(&o));
    let status = RunRecord::load(&run).unwrap().status;
    assert!(matches!(&status, RunStatus::Stopped(s) if s.contains(why)), "{status:?}");
}

/// A record with `frame_interval` = 0 is refused by name.
#[test]
fn a_record_with_frame_interval_zero_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    ok(&small(&run, 50, &[]));
    edit_record(&run, |v| v["frame_interval"] = 0.into());
    refused(&monolayer(&["run", "--quiet", "--resume", arg(&run)]), &["run.json", "`frame_interval` = 0"]);
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

// ---- Read only whole ----

/// A sweep whose run lost a frame (its first, one in the middle, its last) does not count that
/// run as a shorter one: `sweep --tables-only` and `figures` refuse it, naming the run and the
/// step, and leave the tables as they were; no `no_holes` is written for it.
#[test]
fn a_run_with_a_frame_missing_is_never_counted_as_measured() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let sweep =
        |extra: &[&str]| monolayer(&[&["sweep", "--quiet", "--jobs", "1", "--out", arg(&out)][..], extra].concat());
    ok(&sweep(&SWEEP_ARGS));
    let tables = || (fs::read(out.join("summary.csv")).unwrap(), fs::read(out.join("regimes.csv")).unwrap());
    let before = tables();
    let run = out.join("runs/zeta0.4_seed1");
    for step in [100, 150, 200] {
        let frame = frame_path(&run, step);
        let saved = fs::read(&frame).unwrap();
        fs::remove_file(&frame).unwrap();
        for extra in [&["--tables-only"][..], &[&["--tables-only"][..], &SWEEP_ARGS].concat()] {
            let o = sweep(extra);
            refused(&o, &["zeta0.4_seed1", "no table written", "frames missing at step", &step.to_string()]);
            assert!(tables() == before, "the tables were rewritten");
        }
        fs::write(&frame, saved).unwrap();
    }
    // Every frame gone, where the record says there are some.
    let frames = run.join("frames");
    fs::rename(&frames, dir.path().join("away")).unwrap();
    refused(&sweep(&["--tables-only"]), &["zeta0.4_seed1", "no frame files", "last_frame_step"]);
    fs::rename(dir.path().join("away"), &frames).unwrap();
    ok(&sweep(&["--tables-only"]));
    assert!(tables() == before);

    // The figures read the same way.
    let figs = dir.path().join("f");
    let figures = |stage: &str| {
        monolayer(&[
            "figures",
            "--only",
            "S3",
            "--quiet",
            "--jobs",
            "1",
            "--stage",
            stage,
            "--out",
            arg(&figs),
            "--set",
            "relax_steps=50",
            "--set",
            "active_steps=100",
        ])
    };
    ok(&figures("runs"));
    let run = fs::read_dir(figs.join("runs")).unwrap().next().unwrap().unwrap().path();
    let record = RunRecord::load(&run).unwrap();
    fs::remove_file(frame_path(&run, record.params.relax_steps)).unwrap();
    let o = figures("figures");
    refused(&o, &[arg(&run), "frames missing at step 50"]);
    assert!(!figs.join("figures.md").exists(), "figures drawn from a run with a frame missing");
}

/// `analyze` refuses a run missing its first or its last frames (it measured up to the last
/// one present) and a directory named like a frame (it skipped it).
#[test]
fn analyze_refuses_a_run_missing_its_first_or_last_frames() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 100, &[]));
    let out = dir.path().join("a");
    for (step, expect) in [(100, "frames missing at step 100 before"), (200, "frames missing at step 200 after")] {
        let frame = frame_path(&run, step);
        let saved = fs::read(&frame).unwrap();
        fs::remove_file(&frame).unwrap();
        refused(&analyzed(&run, &out), &[expect, "restore them"]);
        fs::write(&frame, saved).unwrap();
    }
    let named = frame_path(&run, 250);
    fs::create_dir_all(&named).unwrap();
    refused(&analyzed(&run, &out), &["frame_0000250.npz", "is a directory, not a regular file: not a frame"]);
    fs::remove_dir(&named).unwrap();
    assert!(!out.exists());
    ok(&analyzed(&run, &out));
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

//! Run directories: one writer each, never overwritten, continued only as what they are, and
//! read only whole. What a demanding user does to them (two writers at once, a kill at the
//! wrong moment, a hand-edited record, frames deleted or slipped in) is refused by name, and
//! nothing is counted as a result that was not measured. Each test reproduces a defect and
//! fails without its fix.

mod common;

use std::fs;
use std::process::Stdio;
use std::time::Duration;

use common::faults::{analyzed, edit_record, killed_at, ok, refused, small, SPEC};
use common::npz::{edit_npz, read_npz, write_npz, Npy};
use common::{arg, lines, monolayer, stderr};
use monolayer::formats::{RunRecord, RunStatus};
use monolayer::run::{checkpoint_path, frame_path, run_sweep, RunDir, RunFrames, RunLock, SweepSpec};

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

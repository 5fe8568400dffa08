//! `monolayer branch`: a new run from a run's state at a frame. A branch that changes nothing
//! continues its parent bit for bit (from a kept checkpoint, and replayed from the random disks);
//! a branch records exactly the parameters it changes; bad parents and bad requests are refused
//! by name, and nothing is written for them.

mod common;

use std::fs;
use std::path::Path;

use common::monolayer;
use monolayer::formats::RunRecord;
use monolayer::model::Perturbation;
use monolayer::run::{create_branch, read_frame, BranchOptions, RunDir};

/// A finished run of the paper's full size, short: 300 relaxation and 600 active steps, a frame
/// every 200 (so frames at 300, 500, 700 and 900).
fn parent(dir: &Path, keep: bool) {
    let mut args = vec![
        "run",
        "--relax-steps",
        "300",
        "--steps",
        "600",
        "--frame-interval",
        "200",
        "--quiet",
        "--out",
        dir.to_str().unwrap(),
    ];
    if keep {
        args.push("--keep-checkpoints");
    }
    let out = monolayer(&args);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
}

fn branch(args: &[&str]) -> std::process::Output {
    let mut all = vec!["branch", "--quiet"];
    all.extend_from_slice(args);
    monolayer(&all)
}

fn frame_bytes(dir: &Path, step: u64) -> Vec<u8> {
    fs::read(dir.join("frames").join(format!("frame_{step:07}.npz"))).unwrap()
}

fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

#[test]
fn a_branch_with_no_change_reproduces_the_parents_next_frames_bit_for_bit() {
    let tmp = tempfile::tempdir().unwrap();
    let (kept, replayed) = (tmp.path().join("kept"), tmp.path().join("replayed"));
    parent(&kept, true);
    parent(&replayed, false);
    assert!(kept.join("checkpoints/checkpoint_0000500.npz").exists());
    assert!(!replayed.join("checkpoints").exists());
    for (p, source) in [(&kept, "kept checkpoint"), (&replayed, "replayed from step 0")] {
        let b = tmp.path().join(format!("{}-branch", p.file_name().unwrap().to_string_lossy()));
        let o = branch(&[p.to_str().unwrap(), "--at", "500", "--out", b.to_str().unwrap()]);
        assert!(o.status.success(), "{}", stderr(&o));
        for step in [500, 700, 900] {
            assert_eq!(frame_bytes(&b, step), frame_bytes(p, step), "{source}: frame {step}");
        }
        let r = RunRecord::load(&b).unwrap();
        let origin = r.branch.as_ref().unwrap();
        assert!(origin.source.starts_with(source), "{}", origin.source);
        assert_eq!((origin.step, origin.changes.len(), r.first_frame_step()), (500, 0, 500));
        assert_eq!(r.params, RunRecord::load(p).unwrap().params, "no change: the parent's parameters");
        // `analyze` reads a branch as any run: its frames start at the branch's step.
        let a = monolayer(&["analyze", b.to_str().unwrap()]);
        assert!(a.status.success(), "{}", stderr(&a));
    }
}

#[test]
fn a_branch_changes_exactly_the_parameters_its_record_names() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("parent");
    parent(&p, true);
    let b = tmp.path().join("off");
    let o = branch(&[
        p.to_str().unwrap(),
        "--at",
        "500",
        "--set",
        "zeta=0",
        "--steps",
        "200",
        "--out",
        b.to_str().unwrap(),
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let (parent_record, r) = (RunRecord::load(&p).unwrap(), RunRecord::load(&b).unwrap());
    let changes = &r.branch.as_ref().unwrap().changes;
    assert_eq!(changes.len(), 1);
    assert_eq!(
        (changes[0].key.as_str(), changes[0].parent.as_f64(), changes[0].branch.as_f64()),
        ("zeta", Some(0.5), Some(0.0))
    );
    let json = |r: &RunRecord| serde_json::to_value(&r.params).unwrap();
    let (a, c) = (json(&parent_record), json(&r));
    let differ: Vec<&String> = a.as_object().unwrap().keys().filter(|k| a[k.as_str()] != c[k.as_str()]).collect();
    assert_eq!(differ, ["active_steps", "zeta"], "only ζ and the length differ");
    assert_eq!(r.params.total_steps(), 700);
    // The same φ at the branch's step (its frame is measured under ζ = 0: other velocities),
    // and another trajectory after it.
    let (mine, theirs) = (
        read_frame(&b.join("frames/frame_0000500.npz"), 140).unwrap(),
        read_frame(&p.join("frames/frame_0000500.npz"), 140).unwrap(),
    );
    assert_eq!(mine.data.cells, theirs.data.cells);
    assert_ne!(mine.data.velocity, theirs.data.velocity, "no active force: other velocities");
    assert_ne!(frame_bytes(&b, 700), frame_bytes(&p, 700));
}

#[test]
fn a_perturbed_replica_starts_within_its_amplitude_and_departs() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("parent");
    parent(&p, true);
    let b = tmp.path().join("replica");
    let options = BranchOptions {
        parent: p.clone(),
        at: 500,
        sets: vec![],
        steps: Some(200),
        frame_interval: None,
        perturbation: Some(Perturbation { seed: 1, amplitude: 1e-6 }),
        out: b.clone(),
    };
    let mut run = create_branch(&options, &mut |_, _| {}).unwrap();
    let (mine, theirs) = (
        read_frame(&b.join("frames/frame_0000500.npz"), 140).unwrap(),
        read_frame(&p.join("frames/frame_0000500.npz"), 140).unwrap(),
    );
    let largest = mine
        .data
        .cells
        .iter()
        .zip(&theirs.data.cells)
        .flat_map(|(a, b)| a.1.iter().zip(&b.1))
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max);
    assert!(largest > 0.0 && largest <= 1e-6, "{largest}");
    assert_eq!(run.record.branch.as_ref().unwrap().perturbation, options.perturbation);
    run.execute(false, &mut |_, _| {}).unwrap();
    assert_ne!(frame_bytes(&b, 700), frame_bytes(&p, 700));
}

#[test]
fn a_branch_that_stopped_resumes_as_any_run() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("parent");
    parent(&p, true);
    let b = tmp.path().join("branch");
    let options = BranchOptions {
        parent: p.clone(),
        at: 300,
        sets: vec![],
        steps: None,
        frame_interval: None,
        perturbation: None,
        out: b.clone(),
    };
    // Made (first frame, checkpoint and record written), then dropped before a step: as if killed.
    drop(create_branch(&options, &mut |_, _| {}).unwrap());
    let mut run = RunDir::resume(&b).unwrap();
    run.execute(false, &mut |_, _| {}).unwrap();
    for step in [300, 500, 700, 900] {
        assert_eq!(frame_bytes(&b, step), frame_bytes(&p, step), "frame {step}");
    }
}

#[test]
fn bad_parents_and_requests_are_refused_by_name_and_write_nothing() {
    let tmp = tempfile::tempdir().unwrap();
    let p = tmp.path().join("parent");
    parent(&p, true);
    let ps = p.to_str().unwrap();
    let out = tmp.path().join("out");
    let os = out.to_str().unwrap();
    for (args, expect) in [
        (vec![ps, "--at", "600"], "--at 600: must be a step at which the run wrote a frame: 300 to 900, every 200"),
        (vec![ps, "--at", "100"], "--at 100"),
        (vec![ps, "--at", "1100"], "--at 1100"),
        (vec![ps, "--at", "500", "--set", "zeta_typo=0"], "unknown parameter `zeta_typo`"),
        (vec![ps, "--at", "500", "--set", "n_cells=10"], "cannot change `n_cells`"),
        (vec![ps, "--at", "500", "--set", "zeta=0", "--set", "zeta=0.1"], "`zeta` is given twice"),
        (vec![ps, "--at", "500", "--set", "zeta=99"], "parameter `zeta`"),
        (vec![ps, "--at", "500", "--perturb", "1", "--perturb-amplitude", "0.5"], "perturbation amplitude = 0.5"),
        (vec![ps, "--at", "500", "--steps", "0"], "--steps 0"),
        (vec![ps, "--at", "900"], "the run ends there"),
        (vec![tmp.path().to_str().unwrap(), "--at", "500"], "no such file (is this a run directory?)"),
    ] {
        let mut all = args.clone();
        all.extend(["--out", os]);
        let o = branch(&all);
        assert!(!o.status.success(), "{args:?} was accepted");
        assert!(stderr(&o).contains(expect), "{args:?}: {}", stderr(&o));
        assert!(!out.exists(), "{args:?} wrote {}", out.display());
    }
    // An unfinished parent: its record says it is still running.
    let unfinished = tmp.path().join("unfinished");
    copy_run(&p, &unfinished);
    let text = fs::read_to_string(unfinished.join("run.json")).unwrap().replace("\"finished\"", "\"running\"");
    fs::write(unfinished.join("run.json"), text).unwrap();
    let o = branch(&[unfinished.to_str().unwrap(), "--at", "500", "--out", os]);
    assert!(stderr(&o).contains("has not finished (status \"running\")"), "{}", stderr(&o));
    // A foreign parent: its frame at the step is not what its state gives (another build's
    // arithmetic, or a file changed).
    let foreign = tmp.path().join("foreign");
    copy_run(&p, &foreign);
    fs::copy(p.join("frames/frame_0000700.npz"), foreign.join("frames/frame_0000500.npz")).unwrap();
    let o = branch(&[foreign.to_str().unwrap(), "--at", "500", "--out", os]);
    assert!(stderr(&o).contains("does not give this frame bit for bit"), "{}", stderr(&o));
    assert!(!out.exists());
    // An output that holds something.
    fs::create_dir_all(&out).unwrap();
    fs::write(out.join("x"), "").unwrap();
    let o = branch(&[ps, "--at", "500", "--out", os]);
    assert!(stderr(&o).contains("is not empty"), "{}", stderr(&o));
}

fn copy_run(from: &Path, to: &Path) {
    for sub in ["", "frames", "checkpoints"] {
        fs::create_dir_all(to.join(sub)).unwrap();
        for e in fs::read_dir(from.join(sub)).unwrap().flatten() {
            if e.file_type().unwrap().is_file() && e.file_name() != ".lock" {
                fs::copy(e.path(), to.join(sub).join(e.file_name())).unwrap();
            }
        }
    }
}

//! Branch a run's state: the same tissue stepped on once as it was and once with its activity
//! switched off (ζ = 0), from the exact state of one frame. Prints the tissue's mean speed in both
//! after each frame: the motion stops where the activity does.
//!
//!   cargo run --release --example branch
//!
//! `monolayer branch RUN_DIR --at STEP --set zeta=0 --out DIR` does the same from the command
//! line (docs/cli.md); `monolayer intervene` does it before every hole of many runs.

use std::path::Path;

use monolayer::analysis::Analysis;
use monolayer::run::{create_branch, read_frame, BranchOptions, RunDir, RunFrames};
use monolayer::Params;

/// The mean speed of each frame of the run in `dir`.
fn speeds(dir: &Path) -> Result<Vec<(u64, f64)>, Box<dyn std::error::Error>> {
    let run = RunFrames::open(dir)?;
    let mut a = Analysis::new(&run.record.params);
    let mut out = Vec::new();
    for (step, path) in &run.frames {
        let frame = read_frame(path, run.record.params.box_size)?;
        a.measure_cells(frame.data.cell_views(), &frame.data.velocity);
        out.push((*step, a.summary().mean_speed));
    }
    Ok(out)
}

/// A parent (33 cells on 80², ζ = 2.5, checkpoints kept) and two branches of it at step 600, one
/// as it was and one with ζ = 0; returns each branch's speeds.
#[allow(clippy::type_complexity)]
fn compare(dir: &Path) -> Result<(Vec<(u64, f64)>, Vec<(u64, f64)>), Box<dyn std::error::Error>> {
    let p = Params { box_size: 80, n_cells: 33, zeta: 2.5, relax_steps: 400, active_steps: 600, ..Params::default() };
    let parent = dir.join("parent");
    let mut run = RunDir::create(&parent, p, 1, 100)?.keep_checkpoints()?;
    run.execute(false, &mut |_, _| {})?;
    let branch = |name: &str, sets: Vec<String>| -> Result<Vec<(u64, f64)>, Box<dyn std::error::Error>> {
        let out = dir.join(name);
        let options = BranchOptions {
            parent: parent.clone(),
            at: 600,
            sets,
            steps: Some(400),
            frame_interval: None,
            perturbation: None,
            out: out.clone(),
        };
        create_branch(&options, &mut |_, _| {})?.execute(false, &mut |_, _| {})?;
        speeds(&out)
    };
    Ok((branch("as-it-was", vec![])?, branch("activity-off", vec!["zeta=0".into()])?))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = std::env::temp_dir().join(format!("monolayer-branch-{}", std::process::id()));
    let (same, off) = compare(&dir)?;
    println!("{:>6} {:>12} {:>12}", "step", "as it was", "ζ = 0");
    for ((step, a), (_, b)) in same.iter().zip(&off) {
        println!("{step:>6} {a:>12.5} {b:>12.5}");
    }
    println!("(mean speed Σ|Σφv|/ΣΣφ in sites per time unit; the branches are in {})", dir.display());
    Ok(())
}

#[test]
fn switching_activity_off_stops_the_motion() {
    let dir = tempfile::tempdir().unwrap();
    let (same, off) = compare(dir.path()).unwrap();
    assert_eq!(same.len(), 5, "frames at 600, 700, …, 1000");
    for ((_, a), (_, b)) in same.iter().zip(&off).skip(1) {
        assert!(*b < 0.2 * a, "{b} against {a}");
    }
}

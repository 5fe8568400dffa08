//! `monolayer analyze` and `run --analyze` as a user drives them: the tables and plots of a run,
//! and the refusals (with nothing written) of what is not a complete run of this program.

mod common;

use std::fs;
use std::path::Path;

use common::{lines, monolayer, quick_run, small_run, stderr};

/// The tables have a row per frame (and per hole), the plots are real PNG and SVG files, and
/// `run --analyze` writes the same tables as `analyze` afterwards.
#[test]
fn analyze_writes_tables_and_plots_like_run_analyze() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let o = small_run(&run, "30", &["--analyze"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let live = run.join("analysis");
    let live_frames = lines(&live.join("frames.csv"));
    let live_snapshots = fs::read_dir(&live).unwrap().filter(|e| {
        let name = e.as_ref().unwrap().file_name();
        name.to_string_lossy().starts_with("snapshot_")
    });
    assert_eq!(live_snapshots.count(), 2, "one snapshot (PNG and SVG) replaced frame by frame");

    let out = dir.path().join("offline");
    let o = monolayer(&["analyze", run.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    let frames = lines(&out.join("frames.csv"));
    assert_eq!(frames.len(), 1 + 4, "header and four frames: {frames:?}");
    assert!(frames[0].starts_with("step,time,packing_fraction"));
    assert!(frames[1].starts_with("300,30,") && frames[4].starts_with("330,33,"), "{frames:?}");
    assert_eq!(frames, live_frames, "run --analyze and analyze agree");
    // The packing fraction is the share of sites with Σφ ≥ ½, recomputed here from each frame file.
    for row in &frames[1..] {
        let mut cols = row.split(',');
        let step: u64 = cols.next().unwrap().parse().unwrap();
        let packing: f64 = cols.nth(1).unwrap().parse().unwrap();
        let l = 60;
        let frame = monolayer::run::read_frame(&monolayer::run::frame_path(&run, step), l).unwrap();
        let mut sum = vec![0.0; l * l];
        for (p, phi) in &frame.data.cells {
            for b in 0..p.h {
                for a in 0..p.w {
                    sum[(p.y0 + b) % l * l + (p.x0 + a) % l] += phi[p.idx(a, b)];
                }
            }
        }
        let direct = sum.iter().filter(|&&s| s >= 0.5).count() as f64 / (l * l) as f64;
        assert!((packing - direct).abs() < 1e-6, "step {step}: packing {packing}, Σφ ≥ ½ on {direct} of the box");
    }
    let holes = lines(&out.join("holes.csv"));
    assert!(holes[0].starts_with("id,nucleation_time,closing_time,lifetime,fate"));
    assert!(lines(&out.join("hole_precursors.csv"))[0].starts_with("hole,frames_before,spiral_core_distance"));
    let probability = lines(&out.join("hole_probability.csv"));
    assert!(probability[0].starts_with("strain_rate_bin_low,") && probability.len() > 1, "{probability:?}");
    assert_eq!(lines(&out.join("correlations.csv")).len(), 1 + 4 * 31, "r = 0..=30 for each frame");
    // One snapshot: the first hole's nucleation frame, or the last frame.
    let snapshots: Vec<String> = fs::read_dir(&out)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .filter(|n| n.starts_with("snapshot_") && n.ends_with(".png"))
        .collect();
    assert_eq!(snapshots.len(), 1, "{snapshots:?}");
    let snapshot = snapshots[0].trim_end_matches(".png").to_string();
    for name in ["hole_area", "correlations", snapshot.as_str()] {
        let png = fs::read(out.join(format!("{name}.png"))).unwrap();
        assert_eq!(&png[..8], b"\x89PNG\r\n\x1a\n", "{name}.png");
        let svg = fs::read_to_string(out.join(format!("{name}.svg"))).unwrap();
        assert!(svg.contains("<svg") && svg.trim_end().ends_with("</svg>"), "{name}.svg");
    }
    // The snapshot of another frame on request; a step without a frame is refused.
    let o = monolayer(&[
        "analyze",
        run.to_str().unwrap(),
        "--out",
        out.to_str().unwrap(),
        "--snapshot",
        "320",
        "--field",
        "active-force-divergence",
    ]);
    assert!(o.status.success(), "{}", stderr(&o));
    let svg = fs::read_to_string(out.join("snapshot_0000320.svg")).unwrap();
    assert!(svg.contains("step 320") && svg.contains("∇·f^a"), "the chosen frame over the chosen field");
    let o = monolayer(&["analyze", run.to_str().unwrap(), "--out", out.to_str().unwrap(), "--snapshot", "325"]);
    assert_eq!(o.status.code(), Some(2));
    assert!(stderr(&o).contains("--snapshot 325"), "{}", stderr(&o));

    // A run stopped after two frames and resumed with --analyze picks up the frames it has.
    let resumed = dir.path().join("resumed");
    let o = small_run(&resumed, "10", &["--analyze"]);
    assert!(o.status.success(), "{}", stderr(&o));
    let record = resumed.join("run.json");
    let text = fs::read_to_string(&record).unwrap();
    fs::write(&record, text.replace("\"active_steps\": 10", "\"active_steps\": 30")).unwrap();
    let o = monolayer(&["run", "--quiet", "--analyze", "--resume", resumed.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(lines(&resumed.join("analysis").join("frames.csv")), live_frames, "resumed and straight runs agree");
    let snapshots = fs::read_dir(resumed.join("analysis")).unwrap().filter(|e| {
        let name = e.as_ref().unwrap().file_name();
        name.to_string_lossy().starts_with("snapshot_")
    });
    assert_eq!(snapshots.count(), 2, "the snapshot of the first run was replaced");

    // A run in progress: a frame being written is a hidden temporary file, not read.
    fs::write(run.join("frames").join(".frame_0000340.npz.tmp"), b"half a frame").unwrap();
    let o = monolayer(&["analyze", run.to_str().unwrap(), "--out", out.to_str().unwrap()]);
    assert!(o.status.success(), "{}", stderr(&o));
    assert_eq!(lines(&out.join("frames.csv")).len(), 5);
}

/// Every way a directory can fail to be an analysable run is named, and nothing is written.
#[test]
fn analyze_refuses_what_is_not_a_complete_run_and_writes_nothing() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    let o = small_run(&run, "30", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    let record = fs::read_to_string(run.join("run.json")).unwrap();

    let check = |target: &Path, expect: &str| {
        let out = dir.path().join("out");
        let o = monolayer(&["analyze", target.to_str().unwrap(), "--out", out.to_str().unwrap()]);
        assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
        assert!(stderr(&o).contains(expect), "expected “{expect}” in: {}", stderr(&o));
        assert!(!out.exists(), "nothing may be written when analyze fails");
    };
    check(&dir.path().join("missing"), "no such directory");

    let empty = dir.path().join("empty");
    fs::create_dir(&empty).unwrap();
    check(&empty, "is this a run directory?");

    let foreign = dir.path().join("foreign");
    fs::create_dir(&foreign).unwrap();
    fs::write(foreign.join("run.json"), "{\"name\": \"something else\"}").unwrap();
    check(&foreign, "not a record of this program");

    let future = dir.path().join("future");
    fs::create_dir_all(future.join("frames")).unwrap();
    fs::write(future.join("run.json"), record.replace("\"format_version\": 1", "\"format_version\": 99")).unwrap();
    check(&future, "`format_version` = 99: this program reads format_version 1");

    let unstarted = dir.path().join("unstarted");
    fs::create_dir_all(unstarted.join("frames")).unwrap();
    let running =
        record.replace("\"finished\"", "\"running\"").replace("\"last_frame_step\": 330", "\"last_frame_step\": null");
    fs::write(unstarted.join("run.json"), running).unwrap();
    check(&unstarted, "no frames yet");
    // A record of frames whose files are gone.
    fs::write(unstarted.join("run.json"), &record).unwrap();
    check(&unstarted, "no frame files, but run.json records frames from step 300 to step 330");

    // A damaged frame among good ones: named, and nothing written for the good ones either.
    let damaged = dir.path().join("damaged");
    fs::create_dir_all(damaged.join("frames")).unwrap();
    fs::write(damaged.join("run.json"), &record).unwrap();
    for step in [300, 310, 320] {
        let name = format!("frame_{step:07}.npz");
        fs::copy(run.join("frames").join(&name), damaged.join("frames").join(&name)).unwrap();
    }
    fs::write(damaged.join("frames").join("frame_0000330.npz"), b"not an npz").unwrap();
    check(&damaged, "frame_0000330.npz");

    // A frame of another lattice size (another run's frame copied in).
    let other = dir.path().join("other");
    let o = quick_run(&other, 50, 12, "50", "10", &[]);
    assert!(o.status.success(), "{}", stderr(&o));
    fs::copy(other.join("frames").join("frame_0000060.npz"), damaged.join("frames").join("frame_0000330.npz")).unwrap();
    check(&damaged, "a 50×50 lattice, the run's run.json has box_size = 60");
}

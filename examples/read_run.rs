//! Read a run's frames and measure them: what `monolayer analyze` does, in a few lines of the
//! library. Prints, per frame, the packing fraction, the void regions, the holes by the
//! nucleation criterion and the tissue's mean speed.
//!
//!   cargo run --release --example read_run -- runs/first     # a run made by `monolayer run`
//!   cargo run --release --example read_run                   # makes a small run first
//!
//! The frames are NumPy `.npz` files (docs/formats.md): Python reads them with `numpy.load`.

use std::path::{Path, PathBuf};

use monolayer::analysis::Analysis;
use monolayer::run::{read_frame, RunDir, RunFrames};
use monolayer::Params;

/// A small finished run in `dir`: 33 cells on 80², 300 relaxation and 500 active steps, a frame
/// every 100.
fn small_run(dir: &Path) -> Result<(), Box<dyn std::error::Error>> {
    let p = Params { box_size: 80, n_cells: 33, relax_steps: 300, active_steps: 500, ..Params::default() };
    let mut run = RunDir::create(dir, p, 1, 100)?;
    run.execute(false, &mut |_, _| {})?;
    Ok(())
}

/// Measures every frame of the run in `dir`; returns the number of frames.
fn measure(dir: &Path) -> Result<usize, Box<dyn std::error::Error>> {
    let run = RunFrames::open(dir)?;
    let p = &run.record.params;
    println!(
        "{}: {} frames, L = {}, N = {}, status {}",
        dir.display(),
        run.frames.len(),
        p.box_size,
        p.n_cells,
        run.record.status
    );
    println!("{:>7} {:>8} {:>6} {:>6} {:>10}", "step", "packing", "voids", "holes", "mean speed");
    let mut a = Analysis::new(p);
    for (step, path) in &run.frames {
        let frame = read_frame(path, p.box_size)?;
        a.measure_cells(frame.data.cell_views(), &frame.data.velocity);
        let s = a.summary();
        println!("{step:>7} {:>8.4} {:>6} {:>6} {:>10.5}", s.packing_fraction, s.void_regions, s.holes, s.mean_speed);
    }
    Ok(run.frames.len())
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let dir = match std::env::args_os().nth(1) {
        Some(d) => PathBuf::from(d),
        None => {
            let dir = std::env::temp_dir().join(format!("monolayer-read-run-{}", std::process::id()));
            small_run(&dir)?;
            dir
        }
    };
    measure(&dir)?;
    Ok(())
}

#[test]
fn a_small_run_reads_back_frame_by_frame() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("run");
    small_run(&run).unwrap();
    assert_eq!(measure(&run).unwrap(), 6, "frames at 300, 400, …, 800");
}

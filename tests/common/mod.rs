//! Helpers shared by the integration tests.
#![allow(dead_code)]

pub mod faults;
pub mod npz;

use std::sync::OnceLock;

use monolayer::model::Patch;
use monolayer::{Monolayer, Params, State};
use num_complex::Complex64 as C64;

/// The paper's full size after its full 10,000-step relaxation (seed 1): the page's shipped
/// state, which tests/relaxed_state.rs holds, bit for bit, to what the core relaxes now (so that
/// the relaxation is computed in one test, not once per test binary). Loaded once per binary,
/// with its forces and velocities evaluated.
pub fn relaxed_full_size() -> &'static Monolayer {
    static RELAXED: OnceLock<Monolayer> = OnceLock::new();
    RELAXED.get_or_init(|| {
        let p = Params::default();
        let file = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("www/assets/relaxed-paper-seed1.bin");
        let bytes = std::fs::read(&file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
        let state = monolayer::formats::snapshot::decode_relaxed(&bytes, &p, 1)
            .unwrap_or_else(|e| panic!("{}: {e} (tests/relaxed_state.rs says how to remake it)", file.display()));
        let mut m = Monolayer::from_saved(p.clone(), 1, state).expect("the shipped state fits the defaults");
        // A state carries φ, not the forces and velocities of its last step: evaluated here for
        // the tests that read them (the trajectory is the same with or without it).
        m.evaluate_now().expect("the shipped state evaluates");
        assert_eq!(m.step_count(), p.relax_steps, "{} is not at the end of the relaxation", file.display());
        m
    })
}

/// A monolayer with hand-made cells (each φ on a w×h patch, unpadded, row by row).
pub fn with_cells(params: Params, cells: Vec<(Patch, Vec<f64>)>, step: u64) -> Monolayer {
    let l = params.box_size;
    let cells = cells
        .into_iter()
        .map(|(p, interior)| {
            let mut padded = vec![0.0; p.padded_len()];
            for b in 0..p.h {
                for a in 0..p.w {
                    padded[p.idx(a, b)] = interior[b * p.w + a];
                }
            }
            (p, padded)
        })
        .collect();
    let zero = vec![C64::new(0.0, 0.0); l * l];
    let state = State { step, cells, warm_start: zero.clone(), corrector_shift: zero, substrate: vec![1.0; l * l] };
    Monolayer::from_state(params, 1, state).expect("valid hand-made state")
}

/// A smooth disk or ellipse φ on a w×h patch: semi-axes (a, b), long axis at angle θ.
pub fn ellipse(w: usize, h: usize, a: f64, b: f64, theta: f64) -> Vec<f64> {
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let (c, s) = (theta.cos(), theta.sin());
    let mut phi = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            let (dx, dy) = (i as f64 - cx, j as f64 - cy);
            let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
            let r = ((u / a).powi(2) + (v / b).powi(2)).sqrt();
            // Interface width ~ λ/2 = 1 site, like the relaxed profile.
            phi[j * w + i] = 1.0 / (1.0 + ((r - 1.0) * a.min(b)).exp());
        }
    }
    phi
}

/// All φ of all cells, bit for bit.
pub fn phi_bits(m: &Monolayer) -> Vec<u64> {
    m.cells().iter().flat_map(|c| c.phi().padded()).map(f64::to_bits).collect()
}

// ---- The command line as a user drives it ----

/// The path of the `monolayer` binary Cargo built for these tests.
pub const BIN: &str = env!("CARGO_BIN_EXE_monolayer");

/// A command that runs the `monolayer` binary, for a test that sets more than its arguments.
pub fn command() -> std::process::Command {
    std::process::Command::new(BIN)
}

/// Runs the `monolayer` binary with `args`.
pub fn monolayer(args: &[&str]) -> std::process::Output {
    command().args(args).output().expect("the binary runs")
}

pub fn stderr(o: &std::process::Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// A path as an argument.
pub fn arg(p: &std::path::Path) -> &str {
    p.to_str().expect("a UTF-8 path")
}

/// The lines of a text file, naming the file if it cannot be read.
pub fn lines(path: &std::path::Path) -> Vec<String> {
    std::fs::read_to_string(path)
        .unwrap_or_else(|e| panic!("{}: {e}", path.display()))
        .lines()
        .map(String::from)
        .collect()
}

/// The CSV files of a directory by name, with their text: two runs' tables compared whole.
pub fn csv_files(dir: &std::path::Path) -> std::collections::BTreeMap<String, String> {
    std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .filter(|p| p.extension().is_some_and(|x| x == "csv"))
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read_to_string(&p).unwrap()))
        .collect()
}

/// Runs the `monolayer` binary with `args` (and `env`), killing it if it has not ended within
/// `seconds`: a command that blocks (reading a FIFO) fails its test instead of hanging it.
pub fn monolayer_within(seconds: u64, args: &[&str], env: &[(&str, &str)]) -> std::process::Output {
    use std::process::{Command, Stdio};
    let mut child = Command::new(BIN)
        .args(args)
        .envs(env.iter().copied())
        .stdin(Stdio::piped())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("the binary runs");
    // No input: its stdin is a pipe closed at once.
    drop(child.stdin.take());
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(seconds);
    while child.try_wait().expect("wait").is_none() {
        if std::time::Instant::now() > deadline {
            let _ = child.kill();
            let _ = child.wait();
            panic!("monolayer {} did not end within {seconds} s (blocked?)", args.join(" "));
        }
        std::thread::sleep(std::time::Duration::from_millis(20));
    }
    child.wait_with_output().expect("its output")
}

/// A FIFO at `path`, made with `mkfifo`.
pub fn make_fifo(path: &std::path::Path) {
    let made = std::process::Command::new("mkfifo").arg(path).status().expect("mkfifo runs");
    assert!(made.success(), "mkfifo {}", path.display());
}

/// A small, quick run: 18 cells on a 60×60 box on one thread, relaxation to step 300, then
/// `steps` active steps with a frame every 10; `extra` flags after these.
pub fn small_run(out: &std::path::Path, steps: &str, extra: &[&str]) -> std::process::Output {
    quick_run(out, 60, 18, "300", steps, extra)
}

/// A quick run of `n_cells` cells on a `box_size`² box on one thread: relaxation to step
/// `relax_steps`, then `steps` active steps with a frame every 10; `extra` flags after these.
pub fn quick_run(
    out: &std::path::Path,
    box_size: usize,
    n_cells: usize,
    relax_steps: &str,
    steps: &str,
    extra: &[&str],
) -> std::process::Output {
    let (box_size, n_cells) = (format!("box_size={box_size}"), format!("n_cells={n_cells}"));
    let mut args = vec![
        "run",
        "--quiet",
        "--set",
        &box_size,
        "--set",
        &n_cells,
        "--relax-steps",
        relax_steps,
        "--steps",
        steps,
        "--frame-interval",
        "10",
        "--threads",
        "1",
        "--out",
        arg(out),
    ];
    args.extend_from_slice(extra);
    monolayer(&args)
}

/// Opens a hole by hand in the run in `run`: cell `cell` is taken out (its φ set to 0) of every
/// frame from `from_step` on, so that a void of about a cell's area appears in that frame, with
/// frames before it: what `forecast` needs to fit and score, which the small runs here do not
/// tear open by themselves in so few steps.
pub fn tear_open_a_hole(run: &std::path::Path, cell: usize, from_step: u64) {
    let record = monolayer::formats::RunRecord::load(run).expect("a run");
    let last = record.last_frame_step.expect("frames");
    for step in (from_step..=last).step_by(record.frame_interval as usize) {
        let path = monolayer::run::frame_path(run, step);
        let offsets = match &npz::read_npz(&path).into_iter().find(|(n, _)| n == "phi_offsets").expect("offsets").1 {
            npz::Npy::I(o) => (o[[cell]] as usize, o[[cell + 1]] as usize),
            _ => panic!("phi_offsets are integers"),
        };
        npz::edit_npz(&path, "phi", |a| match a {
            npz::Npy::F(phi) => phi.as_slice_mut().expect("contiguous")[offsets.0..offsets.1].fill(0.0),
            _ => panic!("φ is real"),
        });
    }
}

//! Property tests of everything that reads the user's text or the disk: parameters from
//! `--set` and config files; frames and checkpoints cut short or with a bit flipped; run
//! directories with frames missing anywhere; checkpoints with values out of range. None may
//! panic; a damaged file is refused or reads as exactly what was written, and a run that is not
//! whole is refused by every reader. A few dozen cases each, so that the suite stays quick.

mod common;

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::OnceLock;

use common::npz::{npy, replace_npz_entry};
use monolayer::formats::RunRecord;
use monolayer::run::{load_params, read_checkpoint, read_frame, write_checkpoint, write_frame};
use monolayer::{Monolayer, Params};
use proptest::prelude::*;

const NAMES: [&str; 8] =
    ["zeta", "box_size", "n_cells", "passive_force", "active_steps", "dt", "patch_margin", "no_such_parameter"];

fn config() -> ProptestConfig {
    ProptestConfig { cases: 48, failure_persistence: None, ..ProptestConfig::default() }
}

/// A value as a user might type it: numbers in every spelling, words, TOML, junk.
fn value() -> impl Strategy<Value = String> {
    prop_oneof![
        any::<f64>().prop_map(|x| x.to_string()),
        any::<i64>().prop_map(|x| x.to_string()),
        Just("1e999".to_string()),
        Just(".5".to_string()),
        Just("NaN".to_string()),
        Just("-inf".to_string()),
        Just("grad_mu".to_string()),
        Just("[1, 2]".to_string()),
        Just("{ a = 1 }".to_string()),
        "[ -~]{0,12}",
    ]
}

/// A small lattice, so that a case is quick.
fn small() -> Params {
    Params { box_size: 40, n_cells: 4, ..Params::default() }
}

/// One frame and one checkpoint of a small monolayer, written once.
fn files() -> &'static (tempfile::TempDir, PathBuf, PathBuf) {
    static FILES: OnceLock<(tempfile::TempDir, PathBuf, PathBuf)> = OnceLock::new();
    FILES.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let mut m = Monolayer::new(small(), 1).unwrap();
        m.advance(3).unwrap();
        m.evaluate_now().unwrap();
        let (frame, checkpoint) = (dir.path().join("frame.npz"), dir.path().join("checkpoint.npz"));
        write_frame(&mut m, &frame).unwrap();
        write_checkpoint(&m, &checkpoint).unwrap();
        (dir, frame, checkpoint)
    })
}

/// The bytes of `original` cut at a fraction `cut` of its length (none past 1) with the bit at
/// fraction `flip` of its bits flipped.
fn damaged(original: &Path, cut: f64, flip: Option<f64>, name: &str) -> (tempfile::TempDir, PathBuf) {
    let mut bytes = fs::read(original).unwrap();
    bytes.truncate((cut * bytes.len() as f64) as usize);
    if let Some(bit) = flip.map(|f| (f * 8.0 * bytes.len() as f64) as usize).filter(|b| b / 8 < bytes.len()) {
        bytes[bit / 8] ^= 1 << (bit % 8);
    }
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join(name);
    fs::write(&path, bytes).unwrap();
    (dir, path)
}

proptest! {
    #![proptest_config(config())]

    /// `--set KEY=VALUE` with any value: parameters, or an error that names the key.
    #[test]
    fn set_never_panics_and_names_the_key(key in proptest::sample::select(&NAMES[..]), v in value()) {
        let arg = format!("{key}={v}");
        match load_params(None, std::slice::from_ref(&arg)) {
            Ok(p) => { let _ = p.validate(); }
            Err(e) => { let e = e.to_string(); prop_assert!(e.contains(key), "{arg}: {e}") }
        }
    }

    /// A config file of any text: parameters, or an error that names the file.
    #[test]
    fn config_files_never_panic(lines in proptest::collection::vec((proptest::sample::select(&NAMES[..]), value()), 0..4),
                                junk in "[ -~\n]{0,40}") {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("c.toml");
        let text: String = lines.iter().map(|(k, v)| format!("{k} = {v}\n")).collect::<String>() + &junk;
        fs::write(&path, &text).unwrap();
        if let Err(e) = load_params(Some(&path), &[]).map_err(|e| e.to_string()) {
            prop_assert!(e.contains("c.toml"), "{text:?}: {e}");
        }
    }

    /// A run record cut short or with a bit flipped is refused or read, never a panic (every
    /// command that opens a run reads it first).
    #[test]
    fn damaged_run_records_never_panic(cut in 0.0f64..1.3, flip in proptest::option::of(0.0f64..1.0)) {
        let dir = tempfile::tempdir().unwrap();
        RunRecord::new(small(), 1, 10).save(dir.path()).unwrap();
        let (_damaged, path) = damaged(&dir.path().join("run.json"), cut, flip, "run.json");
        if let Ok(r) = RunRecord::load(path.parent().unwrap()) {
            prop_assert!(r.frame_interval >= 1 && r.params.validate().is_ok());
        }
    }

    /// A frame cut short or with a bit flipped is refused, or reads as the frame written.
    #[test]
    fn damaged_frames_are_refused(cut in 0.0f64..1.3, flip in proptest::option::of(0.0f64..1.0)) {
        let (_, frame, _) = files();
        let good = read_frame(frame, small().box_size).unwrap();
        let (_dir, path) = damaged(frame, cut, flip, "frame_0000003.npz");
        if let Ok(f) = read_frame(&path, small().box_size) {
            prop_assert_eq!(f.data, good.data);
        }
    }

    /// A checkpoint cut short or with a bit flipped is refused, or reads as the state written
    /// (and then continues like it).
    #[test]
    fn damaged_checkpoints_are_refused(cut in 0.0f64..1.3, flip in proptest::option::of(0.0f64..1.0)) {
        let (_, _, checkpoint) = files();
        let good = read_checkpoint(checkpoint, small().box_size).unwrap();
        let (_dir, path) = damaged(checkpoint, cut, flip, "checkpoint.npz");
        if let Ok(s) = read_checkpoint(&path, small().box_size) {
            prop_assert_eq!(s.step, good.step);
            prop_assert!(s.cells == good.cells && s.warm_start == good.warm_start && s.substrate == good.substrate);
            prop_assert!(Monolayer::from_saved(small(), 1, s).is_ok());
        }
    }

    /// Any shape in any array's `.npy` header (an 80 GB one once aborted the process) is
    /// refused before it is allocated, or read and checked as any frame is.
    #[test]
    fn any_npz_header_shape_is_refused_or_read(
        array in prop::sample::select(vec!["phi", "patches", "velocity", "phi_offsets", "q_hat", "step"]),
        shape in prop::collection::vec(prop_oneof![0u64..50, any::<u64>(), Just(1u64 << 33)], 0..4),
        data in 0usize..200,
    ) {
        let (_, frame, checkpoint) = files();
        let dir = tempfile::tempdir().unwrap();
        let descr = if ["patches", "phi_offsets", "step"].contains(&array) { "<i8" } else { "<f8" };
        let bytes = npy(descr, &shape, &vec![0; data]);
        for (original, read) in [(frame, 0), (checkpoint, 1)] {
            let path = dir.path().join("x.npz");
            fs::copy(original, &path).unwrap();
            let entry = if read == 1 && array == "phi" { "phi_padded" } else { array };
            replace_npz_entry(&path, entry, &bytes);
            // Never a panic, never an abort: an error or a checked read.
            let _ = if read == 0 { read_frame(&path, small().box_size).map(|_| ()) } else { read_checkpoint(&path, small().box_size).map(|_| ()) };
        }
    }

    /// Sweep files of any structure (keys, tables and values shuffled from fragments, duplicates
    /// and unclosed brackets among them) are read or refused with the file and a line; none
    /// panics.
    #[test]
    fn sweep_files_of_any_structure_are_read_or_refused_with_a_line(
        lines in prop::collection::vec(prop::sample::select(vec![
            "seeds = [1, 2]", "seeds = \"1\"", "seeds = [-1]", "frame_interval = 50", "frame_interval = -5",
            "frame_interval = 1e3", "[base]", "[grid]", "[[points]]", "zeta = [0.3, 0.5]", "zeta = 0.4",
            "zeta = [0.3", "chi = [0.1]", "xi_substrate = [0.5]", "box_size = 99999999999999999999",
            "active_steps = 1e19", "nonsense", "x = { a = 1 }", "", "# a comment",
        ]), 0..8),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("s.toml");
        fs::write(&path, lines.join("\n")).unwrap();
        match monolayer::run::SweepSpec::from_file(&path) {
            Ok(spec) => {
                if let Err(e) = spec.jobs().map_err(|e| e.to_string()) {
                    prop_assert!(e.starts_with("sweep") || e.contains("parameter"), "{}", e);
                }
            }
            Err(e) => { let e = e.to_string(); prop_assert!(e.contains("s.toml, line ") || e.contains("s.toml:"), "{}", e) }
        }
    }

    /// A run record with any set of parameters removed is refused, naming one that is missing;
    /// with none removed it reads as written.
    #[test]
    fn run_records_missing_any_parameters_are_refused_by_name(
        remove in prop::collection::vec(any::<prop::sample::Index>(), 0..4),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let record = RunRecord::new(small(), 1, 10);
        record.save(dir.path()).unwrap();
        let path = dir.path().join("run.json");
        let mut v: serde_json::Value = serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
        let keys: Vec<String> = v["params"].as_object().unwrap().keys().cloned().collect();
        let removed: Vec<String> = remove.iter().map(|i| i.get(&keys).clone()).collect();
        for k in &removed {
            v["params"].as_object_mut().unwrap().remove(k);
        }
        fs::write(&path, serde_json::to_string(&v).unwrap()).unwrap();
        match RunRecord::load(dir.path()).map_err(|e| e.to_string()) {
            Ok(r) => prop_assert!(removed.is_empty() && r.params == small()),
            Err(e) => prop_assert!(removed.iter().any(|k| e.contains(&format!("`params.{k}` is missing"))), "{}", e),
        }
    }

    /// The relaxed-state decoder, given a valid file with any bytes changed (and the checksum
    /// made right again, as a hostile file would), refuses it or yields a state a run can hold:
    /// finite, patches on the lattice, a step within a run's.
    #[test]
    fn relaxed_states_with_any_bytes_changed_are_refused_or_sane(
        edits in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 1..6),
    ) {
        use monolayer::formats::snapshot::{decode, encode};
        let (_, _, checkpoint) = files();
        let state = read_checkpoint(checkpoint, small().box_size).unwrap();
        let mut bytes = encode(&state, 7);
        let body = bytes.len() - 8;
        for (at, value) in &edits {
            bytes[at.index(body)] = *value;
        }
        // FNV-1a, as the format's checksum.
        let sum = bytes[..body].iter().fold(0xcbf29ce484222325u64, |h, &b| (h ^ b as u64).wrapping_mul(0x100000001b3));
        bytes[body..].copy_from_slice(&sum.to_le_bytes());
        if let Ok(s) = decode(&bytes, 7, small().box_size) {
            let l = small().box_size;
            prop_assert!(s.step <= 2_000_000_000);
            prop_assert!(s.cells.iter().all(|(p, phi)| p.w >= 1 && p.h >= 1 && p.w < l && p.h < l && phi.iter().all(|v| v.is_finite())));
            prop_assert!(s.substrate.iter().all(|&v| v.is_finite() && v > 0.0));
        }
    }
}

/// The parameters a hand edit of `run.json` may change, with `seed`.
const EDITED: [&str; 8] = ["zeta", "gamma", "kappa", "mu", "xi_substrate", "xi_cell", "q_magnitude", "seed"];

/// What a special input file is made as.
#[derive(Clone, Copy, Debug)]
enum Special {
    Fifo,
    LinkToFifo,
    Directory,
}

fn make_special(path: &Path, kind: Special) {
    match kind {
        Special::Fifo => common::make_fifo(path),
        Special::LinkToFifo => {
            let target = path.with_extension("fifo");
            common::make_fifo(&target);
            std::os::unix::fs::symlink(&target, path).unwrap();
        }
        Special::Directory => fs::create_dir(path).unwrap(),
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 12, failure_persistence: None, ..ProptestConfig::default() })]

    /// A checkpoint holds the seed and parameters it was stepped with: `run.json` edited since,
    /// in any of them, is refused naming the one edited.
    #[test]
    fn a_record_edited_against_its_checkpoint_is_refused(
        key in proptest::sample::select(&EDITED[..]),
        factor in 0.5f64..0.95,
    ) {
        use monolayer::run::RunDir;
        let dir = tempfile::tempdir().unwrap();
        drop(RunDir::create(dir.path(), small(), 1, 10).unwrap());
        let path = RunRecord::path(dir.path());
        let mut v: serde_json::Value = serde_json::from_str(&fs::read_to_string(&path).unwrap()).unwrap();
        if key == "seed" {
            v["seed"] = (2 + (factor * 100.0) as u64).into();
        } else {
            let x = v["params"][key].as_f64().unwrap();
            v["params"][key] = (x * factor).into();
        }
        fs::write(&path, serde_json::to_string_pretty(&v).unwrap()).unwrap();
        // A process spawned by a test running beside this one holds a copy of the lock's
        // descriptor from its fork to its exec: wait that moment out.
        let mut resumed = RunDir::resume(dir.path());
        for _ in 0..100 {
            match &resumed {
                Err(e) if e.to_string().contains("is writing this run directory") => {
                    std::thread::sleep(std::time::Duration::from_millis(20));
                    resumed = RunDir::resume(dir.path());
                }
                _ => break,
            }
        }
        match resumed {
            Ok(_) => prop_assert!(false, "{key} edited, and the run resumed"),
            Err(e) => { let e = e.to_string(); prop_assert!(e.contains(&format!("`{key}`")) && e.contains("checkpoint"), "{}", e) }
        }
    }

    /// Every flag that names an input file refuses a FIFO, a link to one or a directory, naming
    /// it, without opening it (which would block on a FIFO).
    #[test]
    fn special_files_for_every_input_flag_are_refused(
        flag in 0usize..8,
        kind in proptest::sample::select(&[Special::Fifo, Special::LinkToFifo, Special::Directory][..]),
    ) {
        let dir = tempfile::tempdir().unwrap();
        let (input, run) = (dir.path().join("input"), dir.path().join("run"));
        let out = dir.path().join("out");
        let (i, r, o) = (input.to_str().unwrap(), run.to_str().unwrap(), out.to_str().unwrap());
        let tiny = ["--set", "box_size=48", "--set", "n_cells=10"];
        let (args, named): (Vec<&str>, &Path) = match flag {
            0 => (vec!["run", "--quiet", "--config", i, "--out", o], &input),
            1 => (vec!["fingerprint", "--config", i, "--total-steps", "1"], &input),
            2 => (vec!["relaxed-state", "--config", i, "--out", o], &input),
            3 => (vec!["sweep", "--quiet", i, "--out", o], &input),
            4 => ([&["bench", "--steps", "2", "--blocks", "1", "--relax-steps", "5", "--from-relaxed", i][..], &tiny].concat(), &input),
            5 => (vec!["run", "--quiet", "--resume", r], &run),
            6 => (vec!["analyze", r], &run),
            _ => (vec!["forecast", r, r, "--out", o], &run),
        };
        let special = if named == run.as_path() {
            fs::create_dir(&run).unwrap();
            run.join("run.json")
        } else {
            input.clone()
        };
        make_special(&special, kind);
        let o = common::monolayer_within(60, &args, &[]);
        let e = String::from_utf8_lossy(&o.stderr).into_owned();
        prop_assert_eq!(o.status.code(), Some(2), "{}", e);
        prop_assert!(e.contains(special.to_str().unwrap()) && e.contains("not a regular file"), "{:?}: {}", kind, e);
        prop_assert!(!e.contains("panicked") && !out.exists(), "{}", e);
    }
}

// ---- Run directories with frames missing, states out of range ----

/// A small finished run (frames at steps 20, 30, …, 70) in OUT/runs/r, written once.
fn finished_run() -> &'static (tempfile::TempDir, PathBuf) {
    static RUN: OnceLock<(tempfile::TempDir, PathBuf)> = OnceLock::new();
    RUN.get_or_init(|| {
        let dir = tempfile::tempdir().unwrap();
        let run = dir.path().join("runs").join("r");
        let params = Params { relax_steps: 20, active_steps: 50, ..small() };
        let mut r = monolayer::run::RunDir::create(&run, params, 1, 10).unwrap();
        r.execute(false, &mut |_, _| {}).unwrap();
        (dir, run)
    })
}

/// A copy of the files of the run directory `from` (its record, checkpoint and frames) in `to`.
fn copy_run(from: &Path, to: &Path) {
    fs::create_dir_all(to.join("frames")).unwrap();
    for name in ["run.json", "checkpoint.npz"] {
        fs::copy(from.join(name), to.join(name)).unwrap();
    }
    for entry in fs::read_dir(from.join("frames")).unwrap() {
        let path = entry.unwrap().path();
        fs::copy(&path, to.join("frames").join(path.file_name().unwrap())).unwrap();
    }
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, failure_persistence: None, ..ProptestConfig::default() })]

    /// Frames missing anywhere (the first, the last, any in between, several, all): every reader
    /// of a run's frames refuses the run, naming the first step missing, and writes nothing;
    /// none counts it as a shorter run.
    #[test]
    fn readers_refuse_a_run_with_frames_missing_anywhere(
        gone in proptest::collection::btree_set(0usize..6, 1..=6),
    ) {
        use monolayer::run::{analyze_run, jobs_of_runs, measure_existing, Background, RunFrames};
        let (_, run) = finished_run();
        let dir = tempfile::tempdir().unwrap();
        let copy = dir.path().join("runs").join("r");
        copy_run(run, &copy);
        let steps: Vec<u64> = gone.iter().map(|&k| 20 + 10 * k as u64).collect();
        for step in &steps {
            fs::remove_file(monolayer::run::frame_path(&copy, *step)).unwrap();
        }
        // The first step missing is named (with every frame gone: that the record has some).
        let names = |e: &str| if steps.len() == 6 { e.contains("no frame files") } else { e.contains(&format!(" {}", steps[0])) };
        let e = RunFrames::open(&copy).unwrap_err().to_string();
        prop_assert!(names(&e), "{:?}: {}", steps, e);
        let e = RunFrames::open_if_any(&copy).unwrap_err().to_string();
        prop_assert!(names(&e), "{:?}: {}", steps, e);
        let jobs = jobs_of_runs(dir.path()).unwrap();
        let e = measure_existing(&jobs, dir.path()).unwrap_err().to_string();
        prop_assert!(names(&e) && e.contains("run r"), "{:?}: {}", steps, e);
        let out = dir.path().join("analysis");
        let e = analyze_run(&copy, Some(&out), None, Background::StrainRate).unwrap_err().to_string();
        prop_assert!(names(&e) && !out.exists(), "{:?}: {}", steps, e);
    }

    /// A checkpoint with any value of φ put anywhere in its patches is refused where a run
    /// never leaves one (beyond [phi_min, phi_max], or not 0 on the ring around a patch),
    /// naming the value, and read otherwise; a substrate factor ≤ 0 is refused as it is read.
    #[test]
    fn checkpoints_with_values_out_of_range_are_refused(
        at in 0.0f64..1.0,
        value in prop_oneof![-1e6f64..-0.5, -0.5f64..1.5, 1.5f64..1e6, Just(0.0), Just(-0.5), Just(1.5)],
        substrate in prop_oneof![Just(None), (-1e3f64..=0.0).prop_map(Some)],
    ) {
        let (_, _, checkpoint) = files();
        let p = small();
        let state = read_checkpoint(checkpoint, p.box_size).unwrap();
        let len: usize = state.cells.iter().map(|(_, phi)| phi.len()).sum();
        let k = ((at * len as f64) as usize).min(len - 1);
        // The cell, and the padded site, of the k-th value.
        let (mut cell, mut rest) = (0, k);
        while rest >= state.cells[cell].1.len() {
            rest -= state.cells[cell].1.len();
            cell += 1;
        }
        let patch = state.cells[cell].0;
        let (a, b) = (rest % (patch.w + 2), rest / (patch.w + 2));
        let ring = a == 0 || b == 0 || a == patch.w + 1 || b == patch.h + 1;
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("checkpoint.npz");
        fs::copy(checkpoint, &path).unwrap();
        common::npz::edit_npz(&path, "phi_padded", |arr| match arr {
            common::npz::Npy::F(arr) => arr.as_slice_mut().unwrap()[k] = value,
            _ => unreachable!("φ is real"),
        });
        if let Some(s) = substrate {
            common::npz::edit_npz(&path, "substrate", |arr| match arr {
                common::npz::Npy::F(arr) => arr.as_slice_mut().unwrap()[k % (p.box_size * p.box_size)] = s,
                _ => unreachable!("the substrate is real"),
            });
            let e = read_checkpoint(&path, p.box_size).unwrap_err().to_string();
            prop_assert!(e.contains("`substrate`") && e.contains("> 0"), "{}", e);
            return Ok(());
        }
        let read = read_checkpoint(&path, p.box_size).unwrap();
        let outside = !(p.phi_min..=p.phi_max).contains(&value) || (ring && value != 0.0);
        match Monolayer::from_saved(p, 1, read) {
            Ok(_) => prop_assert!(!outside, "φ = {} at {} (ring: {}) was taken", value, k, ring),
            Err(e) => {
                let e = e.to_string();
                prop_assert!(outside, "φ = {} at {} refused: {}", value, k, e);
                prop_assert!(e.contains(&format!("cell {cell}: φ = {value}")) && e.contains("a damaged state"), "{}", e);
            }
        }
    }
}

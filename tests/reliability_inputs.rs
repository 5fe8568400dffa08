//! Inputs: every value, file and state given to a command is checked before anything is
//! computed or written, and a refusal names the parameter or the file and what it takes.
//! Parameters out of range or given twice, damaged or foreign frames, checkpoints and
//! snapshots out of range, special files, runs given twice. Each test reproduces a defect and
//! fails without its fix.

mod common;

use std::fs;

use common::faults::{analyzed, edit_record, ok, refused, refused_within, small, SMALL_RUN, TINY};
use common::npz::{edit_npz, npy, read_npz, replace_npz_entry, write_npz, Npy};
use common::{arg, monolayer, stderr};
use monolayer::formats::{snapshot, RunRecord};
use monolayer::run::{checkpoint_path, frame_path, memory_estimate, RunFrames, RunLock, SweepSpec};
use monolayer::{Monolayer, Params};

// ---- Parameters ----

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

/// Step counts, thread and job counts beyond their bounds, and a run beyond the memory, are
/// refused before anything is written.
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

/// `bench --steps` is bounded as every other step count is (it was not at all).
#[test]
fn bench_steps_are_bounded_as_every_step_count() {
    let bench =
        ["bench", "--blocks", "1", "--chi", "0.1", "--relax-steps", "5", "--set", "box_size=48", "--set", "n_cells=6"];
    for steps in ["1000000001", "0"] {
        refused_within(
            &[&bench[..], &["--steps", steps]].concat(),
            &[],
            &[&format!("--steps {steps}"), "[1, 1000000000]"],
        );
    }
}

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

/// A parameter given twice by one flag (`--set gamma=0.06 --set gamma=0.07`), or by a flag of
/// `bench` and `--set` (`--zeta 0.1 --set zeta=0.5`, or `--chi`, whose default sets ξ_s), is
/// refused by name in every command, where one value used to be taken silently.
#[test]
fn a_parameter_given_twice_is_refused_in_every_command() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("o");
    let twice = ["--set", "gamma=0.06", "--set", "gamma=0.07"];
    let expect = ["--set gamma=0.06 and --set gamma=0.07 both set `gamma`", "give one of them"];
    for command in [
        vec!["run", "--quiet", "--out", arg(&out)],
        vec!["fingerprint", "--total-steps", "1"],
        vec!["relaxed-state", "--out", arg(&out)],
        vec!["sweep", "--quiet", "--out", arg(&out)],
        vec!["figures", "--dry-run", "--only", "S3", "--out", arg(&out)],
        vec!["bench", "--steps", "2", "--blocks", "1"],
    ] {
        refused_within(&[&command[..], &TINY[..4], &twice].concat(), &[], &expect);
    }
    assert!(!out.exists());
    let bench = [&["bench", "--steps", "2", "--blocks", "1"][..], &TINY[..4]].concat();
    refused_within(
        &[&bench[..], &["--zeta", "0.1", "--set", "zeta=0.5"]].concat(),
        &[],
        &["--zeta 0.1 and --set zeta=0.5"],
    );
    refused_within(
        &[&bench[..], &["--set", "xi_substrate=0.5"]].concat(),
        &[],
        &["--chi 0.1,0.001 and --set xi_substrate=0.5"],
    );
    refused_within(
        &[&bench[..], &["--set", "relax_steps=5"]].concat(),
        &[],
        &["--relax-steps 3000 and --set relax_steps=5"],
    );
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

/// A sweep that lists a seed or a grid value twice is refused.
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

/// `run --resume` takes no option that would change the run: the run keeps its own.
#[test]
fn resume_refuses_parameter_options() {
    let dir = tempfile::tempdir().unwrap();
    for extra in [["--set", "zeta=0.5"], ["--zeta", "0.5"], ["--frame-interval", "7"], ["--steps", "9"]] {
        let o = monolayer(&["run", "--resume", arg(dir.path()), extra[0], extra[1]]);
        refused(&o, &["--resume", extra[0]]);
    }
}

/// Messages say what was given, briefly: a stability bound broken by `--set gamma=1e308` names
/// γ, not the Δt it was left at; numbers far from 1 print as 1e308, not 309 digits; a record of
/// another format version names the version, not `Some(2)`.
#[test]
fn messages_name_what_was_given_in_few_words() {
    let dir = tempfile::tempdir().unwrap();
    let fingerprint =
        |set: &str| monolayer(&[&["fingerprint", "--total-steps", "1", "--set", set][..], &TINY].concat());
    for (set, expect) in [
        ("gamma=1e308", "parameter `gamma` = 1e308: J₀·2γλ·8·Δt = inf must be < 2"),
        ("zeta=1e300", "parameter `zeta` = 1e300: must be in [−10, 10]"),
        ("xi_substrate=1e-300", "parameter `xi_substrate` = 1e-300: must be in [1e-6, 1e3]"),
    ] {
        let o = fingerprint(set);
        refused(&o, &[expect]);
        assert!(!stderr(&o).contains("00000000"), "a number in full: {}", stderr(&o));
    }
    let o = monolayer(&[&["fingerprint", "--total-steps", "1", "--chi", "1e300"][..], &TINY].concat());
    refused(&o, &["parameter `xi_substrate` = 1e300"]);
    assert!(!stderr(&o).contains("00000000"), "{}", stderr(&o));
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    edit_record(&run, |v| v["format_version"] = 2.into());
    let e = RunRecord::load(&run).unwrap_err().to_string();
    assert!(e.contains("`format_version` = 2: this program reads format_version 1") && !e.contains("Some"), "{e}");
    edit_record(&run, |v| {
        v.as_object_mut().unwrap().remove("format_version");
    });
    let e = RunRecord::load(&run).unwrap_err().to_string();
    assert!(e.contains("no `format_version`"), "{e}");
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

// ---- Frames, checkpoints and snapshots ----

/// `analyze` refuses a frame with NaN or inf, one of another run (half the cells), and two
/// files of one step, writing nothing.
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

/// A checkpoint with φ beyond [phi_min, phi_max] somewhere, or a φ other than 0 on the ring
/// around a patch, is refused by name on resume, the status unchanged: it used to run, into a
/// `failed: unstable` recorded as the run's result, or silently onto another trajectory. A
/// relaxed state out of range is refused as `bench --from-relaxed` reads it.
#[test]
fn states_with_phi_out_of_range_are_refused_by_name() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    edit_record(&run, |v| v["status"] = "stopped: signal SIGTERM".into());
    let checkpoint = checkpoint_path(&run);
    let saved = fs::read(&checkpoint).unwrap();
    for (index, value, expect) in [
        (500, 3.0, "φ = 3 at padded site"),
        (500, -0.75, "φ = -0.75 at padded site"),
        (0, 0.25, "φ = 0.25 on the ring"),
    ] {
        fs::write(&checkpoint, &saved).unwrap();
        edit_npz(&checkpoint, "phi_padded", |a| match a {
            Npy::F(a) => a[[index]] = value,
            _ => panic!("φ is real"),
        });
        let o = monolayer(&["run", "--quiet", "--resume", arg(&run)]);
        refused(&o, &["checkpoint.npz", expect, "a damaged state"]);
        let record = RunRecord::load(&run).unwrap();
        assert_eq!(record.status.to_string(), "stopped: signal SIGTERM", "the status changed");
    }
    fs::write(&checkpoint, &saved).unwrap();
    ok(&monolayer(&["run", "--quiet", "--resume", arg(&run)]));

    // A relaxed state (the page's, `bench --from-relaxed`).
    let file = dir.path().join("relaxed.bin");
    let relax = ["--set", "box_size=48", "--set", "n_cells=10", "--relax-steps", "50"];
    ok(&monolayer(&[&["relaxed-state", "--out", arg(&file)][..], &relax].concat()));
    let p = Params { box_size: 48, n_cells: 10, relax_steps: 50, ..Params::default() };
    let mut state = snapshot::decode_relaxed(&fs::read(&file).unwrap(), &p, 1).unwrap();
    let bench = [&["bench", "--steps", "2", "--blocks", "1", "--chi", "0.1", "--from-relaxed", arg(&file)][..], &relax]
        .concat();
    ok(&monolayer(&bench));
    let ring = state.cells[0].1.len() - 1;
    state.cells[0].1[ring] = 0.5;
    fs::write(&file, snapshot::encode(&state, snapshot::relaxation_key(&p, 1))).unwrap();
    refused(&monolayer(&bench), &["--from-relaxed", "relaxed.bin", "φ = 0.5 on the ring"]);
    assert!(Monolayer::from_saved(p, 1, state).is_err());
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

/// `forecast a a`, `a ./a/` or a symbolic link to `a`: one run directory, counted once, and
/// said so (its nucleations and its seed were counted once per name).
#[test]
fn forecast_counts_a_run_given_twice_once() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    for (run, seed) in [(&a, "1"), (&b, "2")] {
        ok(&small(run, 50, &["--seed", seed]));
    }
    let link = dir.path().join("link");
    std::os::unix::fs::symlink(&a, &link).unwrap();
    let dotted = format!("{}/./", arg(&a));
    let out = dir.path().join("f");
    let o = monolayer(&["forecast", arg(&a), arg(&a), &dotted, arg(&link), arg(&b), "--out", arg(&out)]);
    let err = stderr(&o);
    assert_eq!(err.matches("a: seed 1,").count(), 1, "{err}");
    assert_eq!(err.matches("counted once").count(), 3, "{err}");
    assert!(err.contains(&format!("{} is the run {} again", arg(&link), arg(&a))), "{err}");
    let o = monolayer(&["forecast", arg(&a), arg(&a), "--out", arg(&out)]);
    refused(&o, &["the runs have 1 seed(s)", "counted once"]);
    assert_eq!(stderr(&o).matches("a: seed 1,").count(), 1, "{}", stderr(&o));
}

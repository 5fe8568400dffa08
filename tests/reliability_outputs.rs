//! Outputs: nothing half-written on disk, and every set of outputs whole. Each file is written
//! under a temporary name and renamed; the tables and plots of `analyze`, `forecast` and
//! `figures` are staged and moved in together; nothing is renamed over what is not a regular
//! file; an output that cannot be written is refused before anything is computed; the tables
//! of a sweep are never emptied or written from part of it; a result that was not measured is
//! not written. Each test reproduces a defect and fails without its fix.

mod common;

use std::fs;
use std::path::Path;
use std::process::Output;

use common::faults::{analyzed, files_of, ok, refused, refused_within, small, with_file_size_limit, SWEEP_ARGS};
use common::{arg, lines, monolayer, small_run, stderr, tear_open_a_hole};
use monolayer::run::write_atomic;

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
                        w.write_all(text.as_bytes()).map_err(|e| monolayer::run::RunError::io(path, e))
                    })
                    .unwrap_or_else(|e| panic!("writer {t}: {e}"));
                }
            });
        }
    });
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1, "no temporary file left");
}

fn is_fifo(path: &Path) -> bool {
    use std::os::unix::fs::FileTypeExt;
    fs::symlink_metadata(path).is_ok_and(|m| m.file_type().is_fifo())
}

fn relaxed_state(out: &Path) -> Output {
    monolayer(&[
        "relaxed-state",
        "--set",
        "box_size=48",
        "--set",
        "n_cells=10",
        "--relax-steps",
        "50",
        "--out",
        arg(out),
    ])
}

/// A rename replaces whatever is at its target: an output path that is a FIFO (or a device, or a
/// link to one) is refused and left as it is; a link to a regular file is written through.
#[test]
fn an_output_that_is_not_a_regular_file_is_refused_and_kept() {
    let dir = tempfile::tempdir().unwrap();
    let fifo = dir.path().join("fifo");
    common::make_fifo(&fifo);
    refused(&relaxed_state(&fifo), &[arg(&fifo), "a FIFO", "not a regular file"]);
    assert!(is_fifo(&fifo), "the FIFO was replaced");

    let link = dir.path().join("link");
    std::os::unix::fs::symlink(&fifo, &link).unwrap();
    refused(&relaxed_state(&link), &[arg(&link), "a symbolic link to a FIFO"]);
    assert!(fs::symlink_metadata(&link).unwrap().file_type().is_symlink() && is_fifo(&fifo));

    let dangling = dir.path().join("dangling");
    std::os::unix::fs::symlink(dir.path().join("nothing"), &dangling).unwrap();
    refused(&relaxed_state(&dangling), &[arg(&dangling), "symbolic link to nothing"]);

    let file = dir.path().join("state.bin");
    fs::write(&file, "old").unwrap();
    let to_file = dir.path().join("to_file");
    std::os::unix::fs::symlink(&file, &to_file).unwrap();
    ok(&relaxed_state(&to_file));
    assert!(fs::symlink_metadata(&to_file).unwrap().file_type().is_symlink(), "the link was replaced");
    assert!(fs::read(&file).unwrap().len() > 100, "the state was not written through the link");

    // `analyze` moves its tables in as one set: a FIFO among them is refused before any is moved.
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    let analysis = dir.path().join("a");
    fs::create_dir_all(&analysis).unwrap();
    let holes = analysis.join("holes.csv");
    common::make_fifo(&holes);
    refused(&analyzed(&run, &analysis), &[arg(&holes), "a FIFO"]);
    assert!(is_fifo(&holes));
    let left: Vec<_> = fs::read_dir(&analysis).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, ["holes.csv"], "files moved in beside the refused one");
}

/// An output's name and directory are checked before anything is computed: a name of 245–255
/// bytes is written (its temporary name used to be too long, after the computation), a longer
/// one and a directory that does not exist are refused at once, naming them (not the temporary).
#[test]
fn output_names_and_directories_are_checked_before_anything_is_computed() {
    let dir = tempfile::tempdir().unwrap();
    let long = dir.path().join(format!("{}.bin", "n".repeat(251)));
    ok(&relaxed_state(&long));
    assert!(long.is_file());
    assert_eq!(fs::read_dir(dir.path()).unwrap().count(), 1, "a temporary was left");
    // Refused before the relaxation, which would take minutes.
    let forever = ["--set", "box_size=48", "--set", "n_cells=10", "--relax-steps", "100000000"];
    let longer = dir.path().join(format!("{}.bin", "n".repeat(252)));
    refused_within(
        &[&["relaxed-state", "--out", arg(&longer)][..], &forever].concat(),
        &[],
        &["a file name of 256 bytes", "255"],
    );
    let missing = dir.path().join("missing/deeper");
    let o = common::monolayer_within(
        60,
        &[&["relaxed-state", "--out", arg(&missing.join("f.bin"))][..], &forever].concat(),
        &[],
    );
    refused(&o, &[&format!("{}: no such directory", missing.display())]);
    assert!(!stderr(&o).contains(".f.bin."), "named by its temporary: {}", stderr(&o));
}

/// `--out` of `analyze` or `forecast` over a file is refused before any run is read or scored,
/// naming the option and the file (it failed at the end, naming a staging directory or with a
/// raw error of the OS).
#[test]
fn an_out_that_is_a_file_is_refused_before_anything_is_computed() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    for (run, seed) in [(&a, "1"), (&b, "2")] {
        ok(&small(run, 50, &["--seed", seed]));
    }
    let file = dir.path().join("file");
    fs::write(&file, "mine").unwrap();
    let o = monolayer(&["forecast", arg(&a), arg(&b), "--out", arg(&file)]);
    refused(&o, &[arg(&file), "--out: is a file, not a directory"]);
    assert!(!stderr(&o).contains("seed 1"), "the runs were scored first: {}", stderr(&o));
    let o = analyzed(&a, &file);
    refused(&o, &[arg(&file), "--out: is a file, not a directory"]);
    assert!(!stderr(&o).contains(".staging"), "{}", stderr(&o));
    assert_eq!(fs::read_to_string(&file).unwrap(), "mine");
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

/// Every file of `dir` overwritten with a marker: the previous set, told apart from a new one.
fn mark_previous(dir: &Path) {
    for name in files_of(dir).keys() {
        fs::write(dir.join(name), "previous set\n").unwrap();
    }
}

fn all_previous(dir: &Path) -> bool {
    files_of(dir).values().all(|bytes| bytes == b"previous set\n")
}

/// A full disk while `forecast` or `figures` writes leaves the previous set whole: the new
/// tables are not moved in beside the previous figures.
#[test]
fn forecast_and_figures_write_their_outputs_as_one_set() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    for (run, seed) in [(&a, "1"), (&b, "2")] {
        ok(&small_run(run, "60", &["--seed", seed]));
        tear_open_a_hole(run, 3, 330);
    }
    let out = dir.path().join("f");
    let forecast = ["forecast", arg(&a), arg(&b), "--quiet", "--out", arg(&out)];
    ok(&monolayer(&forecast));
    assert!(out.join("forecast_roc.png").is_file() && out.join("fig1b_1.png").is_file());
    mark_previous(&out);
    let o = with_file_size_limit(16, &forecast);
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(all_previous(&out), "a mix of two sets: {:?}", files_of(&out).keys());
    assert_eq!(fs::read_dir(&out).unwrap().count(), files_of(&out).len(), "a staging directory was left");

    let figs = dir.path().join("figs");
    let figures = |stage: &'static str| {
        let args = ["figures", "--only", "S3", "--quiet", "--jobs", "1", "--set", "relax_steps=50"];
        [&args[..], &["--set", "active_steps=100", "--stage", stage, "--out", arg(&figs)]].concat()
    };
    ok(&monolayer(&figures("all")));
    mark_previous(&figs);
    let o = with_file_size_limit(16, &figures("figures"));
    assert_eq!(o.status.code(), Some(2), "{}", stderr(&o));
    assert!(all_previous(&figs), "a mix of two sets: {:?}", files_of(&figs).keys());
}

/// `analyze --snapshot STEP` replaces the snapshot of the set it writes into: the previous
/// step's PNG and SVG go with it (they were left beside the new ones).
#[test]
fn analyze_replaces_the_previous_snapshot() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 100, &[]));
    let out = dir.path().join("a");
    let snapshots = || {
        let mut v: Vec<String> = fs::read_dir(&out)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|n| n.starts_with("snapshot_"))
            .collect();
        v.sort();
        v
    };
    ok(&monolayer(&["analyze", arg(&run), "--out", arg(&out), "--snapshot", "200"]));
    assert_eq!(snapshots(), ["snapshot_0000200.png", "snapshot_0000200.svg"]);
    ok(&monolayer(&["analyze", arg(&run), "--out", arg(&out), "--snapshot", "150"]));
    assert_eq!(snapshots(), ["snapshot_0000150.png", "snapshot_0000150.svg"]);
}

/// Temporaries of writers killed with -9 (`.staging.PID.N` in the analysis
/// directory, `.NAME.PID.N.tmp` in a figures directory) are cleaned on the next start; a living
/// writer's are left.
#[test]
fn stale_temporaries_of_dead_writers_are_cleaned() {
    let dir = tempfile::tempdir().unwrap();
    let run = dir.path().join("r");
    ok(&small(&run, 50, &[]));
    let analysis = dir.path().join("a");
    let dead = analysis.join(".staging.999999999.0");
    let alive = analysis.join(format!(".staging.{}.0", std::process::id()));
    fs::create_dir_all(&dead).unwrap();
    fs::create_dir_all(&alive).unwrap();
    fs::write(dead.join("frames.csv"), "x").unwrap();
    ok(&analyzed(&run, &analysis));
    assert!(!dead.exists() && alive.exists());
    let figs = dir.path().join("f");
    fs::create_dir_all(&figs).unwrap();
    let stale = figs.join(".figures.md.999999999.3.tmp");
    fs::write(&stale, "x").unwrap();
    let _ = monolayer(&["figures", "--only", "S3", "--stage", "figures", "--out", arg(&figs)]);
    assert!(!stale.exists());
}

/// A sweep's tables are written through temporaries in OUT; those of a sweep killed with -9
/// are removed by the next one (even one that has no run to tabulate), a living writer's are
/// left.
#[test]
fn a_sweep_removes_the_temporaries_of_dead_writers() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    fs::create_dir_all(&out).unwrap();
    let dead = out.join(".summary.csv.999999999.0.tmp");
    let alive = out.join(format!(".regimes.csv.{}.0.tmp", std::process::id()));
    fs::write(&dead, "x").unwrap();
    fs::write(&alive, "x").unwrap();
    refused(&monolayer(&["sweep", "--out", arg(&out), "--tables-only", "--grid", "zeta=0.2"]), &["no run"]);
    assert!(!dead.exists() && alive.exists());
}

// ---- A sweep's tables ----

/// `sweep --tables-only` given no grid measures every run in OUT/runs with the parameters its
/// run.json records, the grid values read from the runs' names.
#[test]
fn tables_only_without_a_grid_measures_the_runs_in_the_directory() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let sweep = |extra: &[&str]| {
        let mut args = vec!["sweep", "--quiet", "--jobs", "1", "--out", arg(&out)];
        args.extend_from_slice(extra);
        monolayer(&args)
    };
    ok(&sweep(&SWEEP_ARGS));
    let before = (lines(&out.join("summary.csv")), lines(&out.join("regimes.csv")));
    assert_eq!(before.0.len(), 3, "{:?}", before.0);
    let o = sweep(&["--tables-only"]);
    ok(&o);
    assert!(stderr(&o).contains("2 runs in"), "{}", stderr(&o));
    let after = (lines(&out.join("summary.csv")), lines(&out.join("regimes.csv")));
    assert_eq!(after.0.len(), 3, "{:?}", after.0);
    assert!(after.0[0].starts_with("run,zeta,seed,"), "{}", after.0[0]);
    assert!(after.0[1].starts_with("zeta0.2_seed1,0.2,1,") && after.0[2].starts_with("zeta0.4_seed1,0.4,1,"));
    assert_eq!(after, before, "the tables changed");
}

/// `sweep --tables-only` never empties the tables: with no run in OUT/runs, or a grid that
/// matches none, it is refused and the tables are left as they are. A lone shard writes no
/// tables of its own runs only; the shard that ends the sweep writes them.
#[test]
fn the_tables_of_a_sweep_are_never_emptied_or_written_from_part_of_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("s");
    let sweep =
        |extra: &[&str]| monolayer(&[&["sweep", "--quiet", "--jobs", "1", "--out", arg(&out)][..], extra].concat());
    ok(&sweep(&SWEEP_ARGS));
    let tables = || (fs::read(out.join("summary.csv")).unwrap(), fs::read(out.join("regimes.csv")).unwrap());
    let before = tables();
    refused(&sweep(&["--tables-only", "--grid", "zeta=0.7"]), &["no run", "left as they are"]);
    assert!(tables() == before, "the tables were emptied");
    let runs = out.join("runs");
    fs::rename(&runs, dir.path().join("away")).unwrap();
    fs::create_dir(&runs).unwrap();
    refused(&sweep(&["--tables-only"]), &["no run", "left as they are"]);
    assert!(tables() == before, "the tables were emptied");

    let sharded = dir.path().join("sharded");
    let shard = |k: &str| {
        monolayer(
            &[&["sweep", "--quiet", "--jobs", "1", "--shard", k, "--out", arg(&sharded)][..], &SWEEP_ARGS].concat(),
        )
    };
    let o = shard("0/2");
    ok(&o);
    assert!(stderr(&o).contains("shard 0/2") && stderr(&o).contains("--tables-only"), "{}", stderr(&o));
    assert!(!sharded.join("summary.csv").exists(), "tables of one shard's runs");
    ok(&shard("1/2"));
    assert_eq!(lines(&sharded.join("summary.csv")).len(), 1 + 2);
}

// ---- Nothing counted that was not measured ----

/// `forecast` over runs in which no hole opens after their first frame has nothing to fit: it
/// says so and writes nothing (it wrote an empty model and header-only tables, and exited 0).
#[test]
fn a_forecast_with_nothing_to_fit_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let (a, b) = (dir.path().join("a"), dir.path().join("b"));
    for (run, seed) in [(&a, "1"), (&b, "2")] {
        ok(&small(run, 50, &["--seed", seed]));
    }
    let out = dir.path().join("f");
    let o = monolayer(&["forecast", arg(&a), arg(&b), "--out", arg(&out)]);
    refused(&o, &["no hole nucleates after the first frame", "2 run(s)", "nothing to fit", "nothing is written"]);
    assert!(!out.exists(), "written: {:?}", fs::read_dir(&out).map(|d| d.count()));
}

/// An `--out` an `#SBATCH` line cannot hold is refused, naming what is wrong.
#[test]
fn slurm_scripts_refuse_paths_sbatch_cannot_hold() {
    let dir = tempfile::tempdir().unwrap();
    for name in ["a b", "100%", "line\nbreak", "q\"uote"] {
        let out = dir.path().join(name);
        let o = monolayer(&["figures", "--only", "S3", "--slurm", "--dry-run", "--out", arg(&out)]);
        refused(&o, &["--out", "an #SBATCH line cannot hold"]);
    }
}

//! `monolayer sweep`: the sweep assembled from what the command line gives, its runs run (or only
//! measured, `--tables-only`), and its tables written; the binary only parses the arguments and
//! shows what this reports.

use std::path::{Path, PathBuf};
use std::time::Instant;

use super::map::plot_regime_map;
use super::pool::{run_sweep, steps_to_run, Output};
use super::spec::{Shard, SweepSpec};
use super::summary::{jobs_of_runs, measure_existing, RunSummary};
use super::tables::{regime_map, tables};
use crate::formats::RunStatus;
use crate::run::config::{check_distinct, parse_assignment};
use crate::run::console::Report;
use crate::run::error::RunError;
use crate::run::files::write_atomic;
use crate::run::runner::{check_frame_interval, stop_signal};

/// What `monolayer sweep` was asked for.
#[derive(Clone, Debug, Default)]
pub struct SweepOptions {
    /// The sweep file (TOML), if any.
    pub file: Option<PathBuf>,
    /// The sweep's directory: runs in `OUT/runs/`, tables in `OUT`.
    pub out: PathBuf,
    /// `--grid KEY=V1,V2,…`, `--point K1=V1,…`, `--set KEY=VALUE`, as given.
    pub grid: Vec<String>,
    pub points: Vec<String>,
    pub sets: Vec<String>,
    pub seeds: Option<Vec<u64>>,
    pub frame_interval: Option<u64>,
    pub keep_checkpoints: bool,
    /// Run nothing: measure what is in `OUT/runs/`.
    pub tables_only: bool,
    /// Simulations at a time.
    pub jobs: usize,
    /// This process's share of the runs (a Slurm array task's), if any.
    pub shard: Option<Shard>,
}

impl SweepOptions {
    /// Whether anything describes a sweep (a file, a grid, points, settings, seeds, an interval):
    /// `--tables-only` with none measures every run in `OUT/runs/` as its record says.
    fn names_a_sweep(&self) -> bool {
        self.file.is_some()
            || !self.grid.is_empty()
            || !self.points.is_empty()
            || !self.sets.is_empty()
            || self.seeds.is_some()
            || self.frame_interval.is_some()
    }

    /// The sweep these options describe.
    fn spec(&self) -> Result<SweepSpec, RunError> {
        let mut spec = match &self.file {
            Some(f) => SweepSpec::from_file(f)?,
            None => SweepSpec { seeds: vec![1], frame_interval: 1000, ..SweepSpec::default() },
        };
        check_distinct("--set", &self.sets)?;
        for s in &self.sets {
            let (k, v) = parse_assignment("--set", s)?;
            spec.base.insert(k, v);
        }
        for g in &self.grid {
            spec.add_grid(g)?;
        }
        for p in &self.points {
            spec.add_point(p)?;
        }
        if let Some(seeds) = &self.seeds {
            spec.seeds = seeds.clone();
        }
        if let Some(fi) = self.frame_interval {
            spec.frame_interval = fi;
        }
        spec.keep_checkpoints |= self.keep_checkpoints;
        Ok(spec)
    }
}

/// `monolayer sweep`: returns the tables written (none where a shard leaves them to the one that
/// ends the sweep).
pub fn sweep(o: &SweepOptions, report: &(dyn Fn(Report) + Sync)) -> Result<Vec<PathBuf>, RunError> {
    let line = |text: String| report(Report::Line(text));
    if o.tables_only && !o.names_a_sweep() {
        let summaries = measure_existing(&jobs_of_runs(&o.out)?, &o.out)?;
        line(format!(
            "sweep --tables-only: {} runs in {}, {} of them ended",
            summaries.len(),
            o.out.join("runs").display(),
            ended(&summaries)
        ));
        return write_tables(&o.out, &summaries);
    }
    let spec = o.spec()?;
    let jobs = spec.jobs()?;
    if let Some(fi) = o.frame_interval {
        for job in &jobs {
            check_frame_interval("--frame-interval", fi, &job.params)
                .map_err(|e| e.context(format!("run {}", job.name)))?;
        }
    }
    if o.tables_only {
        let summaries = measure_existing(&jobs, &o.out)?;
        line(format!(
            "sweep --tables-only: {} of {} runs have a directory in {}, {} of them ended",
            summaries.len(),
            jobs.len(),
            o.out.join("runs").display(),
            ended(&summaries)
        ));
        return write_tables(&o.out, &summaries);
    }
    let mine = jobs.iter().enumerate().filter(|(i, _)| o.shard.is_none_or(|s| i % s.count == s.index)).count();
    let todo = steps_to_run(&jobs, &o.out, o.shard);
    line(format!(
        "sweep: {} runs ({mine} in this shard), {todo} steps to run, {} at a time, into {}",
        jobs.len(),
        o.jobs,
        o.out.display()
    ));
    let start = Instant::now();
    let output = Output { frame_interval: spec.frame_interval, keep_checkpoints: spec.keep_checkpoints };
    let summaries = run_sweep(&jobs, output, &o.out, o.jobs, o.shard, &|steps, done, runs| {
        report(Report::Progress { steps, of: todo, done, runs })
    })?;
    let written = match o.shard {
        // A shard's tables would hold its own runs only: the shard that ends the sweep writes them.
        Some(s) if ended(&summaries) < jobs.len() => {
            line(format!(
                "shard {}/{}: its runs are done; {} of the sweep's {} runs have ended, so summary.csv and the regime \
                 map are not written (they would leave the others out): the shard that ends the sweep writes them, or \
                 `sweep … --tables-only` once every shard is done",
                s.index,
                s.count,
                ended(&summaries),
                jobs.len()
            ));
            Vec::new()
        }
        _ => write_tables(&o.out, &summaries)?,
    };
    stopped_runs(&summaries)?;
    let wall = start.elapsed().as_secs_f64();
    let run_time: f64 = summaries.iter().map(|s| s.run_seconds).sum();
    line(format!(
        "sweep done in {wall:.0} s; runs took {run_time:.0} s together ({:.2} runs' worth of time per second of wall time)",
        run_time / wall.max(1e-9)
    ));
    Ok(written)
}

fn ended(summaries: &[RunSummary]) -> usize {
    summaries.iter().filter(|s| s.status.is_complete()).count()
}

/// The error for runs the machine or a signal stopped part way, which the same command again
/// continues.
fn stopped_runs(summaries: &[RunSummary]) -> Result<(), RunError> {
    let stopped: Vec<String> = summaries
        .iter()
        .filter_map(|s| match &s.status {
            RunStatus::Stopped(why) => Some(format!("  {}: {}", s.name, why.lines().next().unwrap_or(""))),
            _ => None,
        })
        .collect();
    if let Some((name, _)) = stop_signal() {
        return Err(RunError::Interrupted {
            signal: name,
            detail: format!(
                ": {} run(s) stopped part way; the same command again continues them from their checkpoints, and \
                 the runs not yet started",
                stopped.len()
            ),
        });
    }
    if !stopped.is_empty() {
        return Err(RunError::Stopped(stopped));
    }
    Ok(())
}

/// Writes `OUT/summary.csv`, `OUT/regimes.csv` (and the regime map plot where the grid has χ
/// and ζ); returns the files written. Refused for no run at all.
pub fn write_tables(out: &Path, summaries: &[RunSummary]) -> Result<Vec<PathBuf>, RunError> {
    // A sweep takes no lock on OUT (several shards write these tables), so only the temporaries
    // of writers no longer alive are taken.
    crate::run::files::remove_dead_temporaries(out);
    // Tables of no run would replace the tables of the runs measured before with headers.
    if summaries.is_empty() {
        return Err(RunError::file(
            &out.join("runs"),
            "no run of this sweep is there to measure: summary.csv and the regime map are left as they are (is \
             --out the sweep's, with its grid?)",
        ));
    }
    let (runs, regimes) = tables(summaries);
    let mut written = Vec::new();
    for (name, text) in [("summary.csv", runs), ("regimes.csv", regimes)] {
        let path = out.join(name);
        write_atomic(&path, |w| {
            use std::io::Write;
            w.write_all(text.as_bytes()).map_err(|e| RunError::io(&path, e))
        })?;
        written.push(path);
    }
    written.extend(plot_regime_map(&out.join("regime_map"), &regime_map(summaries))?);
    Ok(written)
}

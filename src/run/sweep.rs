//! Parameter sweeps (`monolayer sweep`): a grid of runs, one simulation per core, each in its own
//! directory and analysed; resumable; a summary with one row per run and the regime map of the
//! paper's Fig. 3d.
//!
//! A sweep file:
//! ```toml
//! seeds = [1, 2, 3]          # every grid point runs once per seed
//! frame_interval = 1000      # optional (default 1000)
//! [base]                     # any parameter (names of `monolayer params`); defaults fill the rest
//! active_steps = 100000
//! [grid]                     # lists: their Cartesian product is run; `chi` sets ξ_s = χ ξ_cell
//! chi = [0.1, 0.01, 0.001]
//! zeta = [0.3, 0.4, 0.5]
//! ```
//!
//! Points that are not a grid (the paper's regime-map set, say) are listed instead as
//! `[[points]]` tables, or `--point chi=0.1,zeta=0.5` on the command line; every point takes the
//! grid's product if there is one too. All points set the same parameters.

use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use serde::Deserialize;

use crate::analysis::{classify, counted_holes, fitted_lifetime, FrameSummary, HoleCounting, Regime};
use crate::formats::{RunRecord, RunStatus};
use crate::model::Params;
use crate::run::config::{number, params_from_table, parse_assignment, parse_list};
use crate::run::error::RunError;
use crate::run::files::RunFrames;
use crate::run::files::{checkpoint_path, read_checkpoint, write_atomic, RunLock};
use crate::run::offline::RunAnalysis;
use crate::run::runner::{Event, RunDir};

/// A sweep as written in its file (or assembled from the command line).
#[derive(Clone, Debug, Default, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct SweepSpec {
    #[serde(default)]
    pub base: toml::Table,
    #[serde(default)]
    pub grid: toml::Table,
    /// Single points, each a table of parameter values, run instead of the empty point the grid
    /// starts from.
    #[serde(default)]
    pub points: Vec<toml::Table>,
    #[serde(default = "default_seeds")]
    pub seeds: Vec<u64>,
    #[serde(default = "default_frame_interval")]
    pub frame_interval: u64,
    /// Every run keeps every checkpoint (`run --keep-checkpoints`), the states
    /// `monolayer branch` starts from.
    #[serde(default)]
    pub keep_checkpoints: bool,
}

/// The most runs one sweep takes (the paper's whole plan is 1,002).
pub const MAX_RUNS: usize = 100_000;

fn default_seeds() -> Vec<u64> {
    vec![1]
}

fn default_frame_interval() -> u64 {
    1000
}

/// One run of the sweep.
#[derive(Clone, Debug, PartialEq)]
pub struct Job {
    /// Directory name under `OUT/runs/`, e.g. `chi0.01_zeta0.3_seed1`.
    pub name: String,
    /// The grid values of this run, in grid order, as text.
    pub values: Vec<(String, String)>,
    pub params: Params,
    pub seed: u64,
}

fn value_text(v: &toml::Value) -> String {
    match v {
        toml::Value::String(s) => s.clone(),
        other => other.to_string(),
    }
}

impl SweepSpec {
    pub fn from_file(path: &Path) -> Result<Self, RunError> {
        let text = crate::run::files::read_text_input(path, "a sweep file")?;
        crate::run::config::from_toml(&text, &path.display().to_string())
    }

    /// `KEY=V1,V2,…` from the command line into the grid (values in TOML syntax; bare words
    /// are strings).
    pub fn add_grid(&mut self, arg: &str) -> Result<(), RunError> {
        let (k, values) = parse_list("--grid", arg)?;
        if self.grid.contains_key(&k) {
            return Err(RunError::Options(format!(
                "--grid {arg}: `{k}` is already a grid axis (give its values in one --grid {k}=V1,V2,…)"
            )));
        }
        self.grid.insert(k, toml::Value::Array(values));
        Ok(())
    }

    /// `K1=V1,K2=V2,…` from the command line as one point (values in TOML syntax, one each).
    pub fn add_point(&mut self, arg: &str) -> Result<(), RunError> {
        let mut point = toml::Table::new();
        for pair in arg.split(',') {
            let (k, v) = parse_assignment("--point", pair)?;
            if point.insert(k.clone(), v).is_some() {
                return Err(RunError::Options(format!("--point {arg}: sets `{k}` twice")));
            }
        }
        self.points.push(point);
        Ok(())
    }

    /// The listed points as (key, value) lists in key order, or the one empty point; checked:
    /// every point sets the same keys, and none that the grid varies (a point listed twice is
    /// refused by [`Self::jobs`], as two runs of one name).
    fn starting_points(&self) -> Result<Vec<Vec<(String, toml::Value)>>, RunError> {
        let Some(first) = self.points.first() else { return Ok(vec![Vec::new()]) };
        let keys: Vec<&String> = first.keys().collect();
        if keys.is_empty() {
            return Err(RunError::Sweep("a point sets no parameter".into()));
        }
        if let Some(k) = keys.iter().find(|k| self.grid.contains_key(k.as_str())) {
            return Err(RunError::Sweep(format!("`{k}` is set both by the points and by the grid")));
        }
        let mut out = Vec::new();
        for p in &self.points {
            if p.keys().collect::<Vec<_>>() != keys {
                let names = |t: &toml::Table| t.keys().cloned().collect::<Vec<_>>().join(", ");
                return Err(RunError::Sweep(format!(
                    "every point must set the same parameters: {} against {}",
                    names(first),
                    names(p)
                )));
            }
            out.push(p.iter().map(|(k, v)| (k.clone(), v.clone())).collect());
        }
        Ok(out)
    }

    /// Every run of the sweep, each one's parameters validated: a bad sweep fails here, before
    /// anything runs, naming the run and the parameter.
    pub fn jobs(&self) -> Result<Vec<Job>, RunError> {
        if self.seeds.is_empty() {
            return Err(RunError::Sweep("`seeds` is empty".into()));
        }
        if self.frame_interval == 0 {
            return Err(RunError::Sweep("`frame_interval` must be ≥ 1".into()));
        }
        // Two jobs of one name would share a directory, and the tables would count them twice.
        if self.seeds.len() > MAX_RUNS {
            return Err(RunError::Sweep(format!("{} seeds, more than a sweep's {MAX_RUNS} runs", self.seeds.len())));
        }
        let mut seen = std::collections::HashSet::new();
        if let Some(seed) = self.seeds.iter().find(|s| !seen.insert(**s)) {
            return Err(RunError::Sweep(format!("`seeds` lists {seed} twice")));
        }
        let mut axes: Vec<(String, Vec<toml::Value>)> = Vec::new();
        for (k, v) in &self.grid {
            let values = match v {
                toml::Value::Array(a) if !a.is_empty() => a.clone(),
                toml::Value::Array(_) => return Err(RunError::Sweep(format!("grid `{k}` is an empty list"))),
                other => vec![other.clone()],
            };
            if values.len() > MAX_RUNS {
                return Err(RunError::Sweep(format!(
                    "grid `{k}` lists {} values, more than a sweep's {MAX_RUNS} runs",
                    values.len()
                )));
            }
            // Equal as numbers is equal (`zeta = [1, 1.0]`): two runs of one point.
            let mut seen = std::collections::HashMap::new();
            for v in &values {
                let id = match number(k, v) {
                    Ok(x) => format!("{}", x + 0.0),
                    Err(_) => value_text(v),
                };
                if let Some(first) = seen.insert(id, v) {
                    let (a, b) = (value_text(first), value_text(v));
                    return Err(RunError::Sweep(format!(
                        "grid `{k}` lists {a} twice ({a} and {b} are one value: two identical runs)"
                    )));
                }
            }
            axes.push((k.clone(), values));
        }
        // `chi` sets ξ_s = χ·ξ_cell: beside `xi_substrate` one of the two would be overridden
        // silently, and the run named and tabled by the other.
        let sets = |key: &str| {
            self.base.contains_key(key)
                || self.grid.contains_key(key)
                || self.points.iter().any(|p| p.contains_key(key))
        };
        if sets("chi") && sets("xi_substrate") {
            return Err(RunError::Sweep(
                "sets both `chi` and `xi_substrate` (χ sets ξ_s = χ·ξ_cell, so one would override \
                        the other): give one of them"
                    .into(),
            ));
        }
        // A grid or point value replaces the base's: one of the two would be dropped unsaid.
        if let Some(k) =
            self.base.keys().find(|k| self.grid.contains_key(*k) || self.points.iter().any(|p| p.contains_key(*k)))
        {
            let by = if self.grid.contains_key(k) { "the grid" } else { "the points" };
            return Err(RunError::Sweep(format!(
                "`{k}` is set both by [base] (or --set) and by {by}, whose value would replace the base's: give \
                 it in one of them"
            )));
        }
        let runs = axes
            .iter()
            .try_fold(self.points.len().max(1).saturating_mul(self.seeds.len()), |n, (_, v)| n.checked_mul(v.len()))
            .filter(|&n| n <= MAX_RUNS);
        if runs.is_none() {
            return Err(RunError::Sweep(format!(
                "more than {MAX_RUNS} runs (the paper's whole plan is 1,002): split it into several sweeps"
            )));
        }
        let mut points = self.starting_points()?;
        for (k, values) in &axes {
            points = points
                .into_iter()
                .flat_map(|p| {
                    values.iter().map(move |v| {
                        let mut q = p.clone();
                        q.push((k.clone(), v.clone()));
                        q
                    })
                })
                .collect();
        }
        let mut jobs = Vec::new();
        let mut names = std::collections::HashMap::new();
        for point in &points {
            let mut table = self.base.clone();
            let mut chi = table.remove("chi");
            for (k, v) in point {
                if k == "chi" {
                    chi = Some(v.clone());
                } else {
                    table.insert(k.clone(), v.clone());
                }
            }
            let label: Vec<(String, String)> = point.iter().map(|(k, v)| (k.clone(), value_text(v))).collect();
            let describe = || {
                let s: Vec<String> = label.iter().map(|(k, v)| format!("{k} = {v}")).collect();
                if s.is_empty() {
                    "the base run".to_string()
                } else {
                    s.join(", ")
                }
            };
            let origin = format!("sweep, run {}", describe());
            let mut params = params_from_table(&table, &origin)?;
            if let Some(c) = chi {
                params.set_chi(number("chi", &c).map_err(|e| e.context(origin.as_str()))?);
            }
            params.validate().map_err(|e| RunError::from(e).context(format!("sweep, run {}", describe())))?;
            for &seed in &self.seeds {
                let mut name: String = label.iter().map(|(k, v)| format!("{k}{v}_")).collect();
                name = name.replace(['/', ' ', '"'], "");
                name.push_str(&format!("seed{seed}"));
                if let Some(&other) = names.get(&name) {
                    let other: &Job = &jobs[other];
                    return Err(RunError::Sweep(format!(
                        "runs {:?} and {:?} would share the directory {name}",
                        other.values, label
                    )));
                }
                names.insert(name.clone(), jobs.len());
                jobs.push(Job { name, values: label.clone(), params: params.clone(), seed });
            }
        }
        Ok(jobs)
    }
}

/// A shard of a sweep: run `index` of every `count` jobs (a Slurm job array sets
/// `--shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Shard {
    pub index: usize,
    pub count: usize,
}

impl std::str::FromStr for Shard {
    type Err = RunError;
    fn from_str(s: &str) -> Result<Self, RunError> {
        let bad = || RunError::Parse(format!("--shard {s}: expected K/N with 0 ≤ K < N"));
        let (k, n) = s.split_once('/').ok_or_else(bad)?;
        let (index, count) = (k.trim().parse().map_err(|_| bad())?, n.trim().parse().map_err(|_| bad())?);
        if count == 0 || index >= count {
            return Err(bad());
        }
        Ok(Shard { index, count })
    }
}

/// One row of the summary: what a run did.
#[derive(Clone, Debug, Default)]
pub struct RunSummary {
    pub name: String,
    pub values: Vec<(String, String)>,
    pub seed: u64,
    /// Finished, failed (blew up), stopped by an IO error (retried when the sweep runs again),
    /// or running (a shard that did not get to it).
    pub status: RunStatus,
    pub steps: u64,
    /// Time units of the active phase the frames cover (first to last frame).
    pub active_time: f64,
    /// Holes counted as families (`HoleCounting::Families`, the regime criterion's count).
    pub holes_nucleated: usize,
    pub max_hole_area: usize,
    pub time_with_hole_open: f64,
    /// (duration, closed) of each hole counted as a family: closed holes' lifetimes, and for
    /// open ones the time they were seen.
    pub lifetimes: Vec<(f64, bool)>,
    /// The same with every tracked void region a hole of its own (`HoleCounting::Regions`).
    pub region_lifetimes: Vec<(f64, bool)>,
    pub mean_speed: f64,
    /// µm/h per site per time unit, from the run's `time_unit_seconds`.
    pub microns_per_hour: f64,
    pub velocity_correlation_length: Option<f64>,
    pub nematic_correlation_length: Option<f64>,
    /// Minimum packing fraction (sites with Σφ ≥ ½) over the frames with no hole open.
    pub min_packing_without_hole: Option<f64>,
    /// The other reading of the paper's packing fraction (docs/reading.md §7): the minimum
    /// share of sites that are not void (Σφ ≥ 0.01) over the frames with no hole open.
    pub min_nonvoid_without_hole: Option<f64>,
    /// The most void regions of any size in one frame while a hole is open: 1 where, as the
    /// paper says, "no other gaps appear in the monolayer" once a hole has formed.
    pub max_void_regions_with_hole: usize,
    /// Cells' aspect ratio (shape tensor): the per-frame mean and 90th percentile, averaged
    /// over the frames.
    pub aspect_ratio_mean: Option<f64>,
    pub aspect_ratio_p90: Option<f64>,
    /// The most holes open in one frame, and the share of frames with more than one open.
    pub max_holes_open: usize,
    pub fraction_multiple_holes: f64,
    /// Wall time of the run in this invocation of the sweep (0 when it was done already).
    pub run_seconds: f64,
}

impl RunSummary {
    pub fn blew_up(&self) -> bool {
        self.status.blew_up()
    }
}

fn minimum(v: impl Iterator<Item = f64>) -> Option<f64> {
    v.fold(None, |m: Option<f64>, x| Some(m.map_or(x, |m| m.min(x))))
}

/// The paper's "when no hole is present the packing fraction is always above 95 % and, when a
/// hole is formed, no other gaps appear" measured over a run's frames, under both readings of
/// the packing fraction (docs/reading.md §7).
#[derive(Clone, Copy, Debug, PartialEq)]
struct PackingReadings {
    /// Covered: the share of sites with Σφ ≥ ½, least over the frames with no hole open.
    min_covered_without_hole: Option<f64>,
    /// Not void: the share of sites with Σφ ≥ 0.01, least over the same frames.
    min_nonvoid_without_hole: Option<f64>,
    /// The most void regions of any size in one frame with a hole open (1: no other gap).
    max_void_regions_with_hole: usize,
}

impl PackingReadings {
    /// From each frame's open holes (as tracked) and its summary.
    fn of<'a>(frames: impl Iterator<Item = (usize, &'a FrameSummary)> + Clone) -> Self {
        let without_hole = frames.clone().filter(|(open, _)| *open == 0).map(|(_, f)| f);
        PackingReadings {
            min_covered_without_hole: minimum(without_hole.clone().map(|f| f.packing_fraction)),
            min_nonvoid_without_hole: minimum(without_hole.map(|f| 1.0 - f.void_fraction)),
            max_void_regions_with_hole: frames
                .filter(|(open, _)| *open > 0)
                .map(|(_, f)| f.void_regions)
                .max()
                .unwrap_or(0),
        }
    }
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    (n > 0).then(|| s / n as f64)
}

/// Measures the frames of the run in `dir`: every frame its record says it wrote, or none for a
/// run that wrote none (it failed or stopped before its first). A frame missing anywhere is
/// refused, naming the run, rather than counted as a run that ended there.
pub fn summarize(job: &Job, dir: &Path) -> Result<RunSummary, RunError> {
    let record = RunRecord::load(dir)?;
    let mut s = RunSummary {
        name: job.name.clone(),
        values: job.values.clone(),
        seed: job.seed,
        status: record.status.clone(),
        ..RunSummary::default()
    };
    let Some(run) = RunFrames::open_if_any(dir)? else { return Ok(s) };
    let p = &run.record.params;
    s.status = run.record.status.clone();
    s.microns_per_hour = p.microns_per_hour();
    let mut ra = RunAnalysis::new(p);
    for frame in run.read() {
        let frame = frame?;
        ra.push_frame(&frame);
        s.steps = frame.data.step;
    }
    let first = ra.frames.first().map(|f| f.time).unwrap_or(0.0);
    let last = ra.frames.last().map(|f| f.time).unwrap_or(0.0);
    s.active_time = last - first;
    let counted = |counting| -> Vec<(f64, bool)> {
        counted_holes(&ra.tracker.holes, last, counting).iter().map(|h| (h.duration, h.closed)).collect()
    };
    s.lifetimes = counted(HoleCounting::Families);
    s.region_lifetimes = counted(HoleCounting::Regions);
    s.holes_nucleated = s.lifetimes.len();
    s.max_hole_area = ra.tracker.holes.iter().map(|h| h.max_area()).max().unwrap_or(0);
    // The frames sample the active phase evenly: the share of them with a hole open is the share
    // of its time.
    let with_hole = ra.frames.iter().filter(|f| f.open_holes > 0).count() as f64;
    s.time_with_hole_open = s.active_time * with_hole / ra.frames.len().max(1) as f64;
    s.mean_speed = mean(ra.frames.iter().map(|f| f.summary.mean_speed)).unwrap_or(0.0);
    s.aspect_ratio_mean = mean(ra.frames.iter().filter_map(|f| f.summary.aspect_ratio_mean));
    s.aspect_ratio_p90 = mean(ra.frames.iter().filter_map(|f| f.summary.aspect_ratio_p90));
    s.max_holes_open = ra.frames.iter().map(|f| f.open_holes).max().unwrap_or(0);
    let multiple = ra.frames.iter().filter(|f| f.open_holes > 1).count() as f64;
    s.fraction_multiple_holes = multiple / ra.frames.len().max(1) as f64;
    s.velocity_correlation_length = mean(ra.frames.iter().filter_map(|f| f.summary.velocity_correlation_length));
    s.nematic_correlation_length = mean(ra.frames.iter().filter_map(|f| f.summary.nematic_correlation_length));
    let packing = PackingReadings::of(ra.frames.iter().map(|f| (f.open_holes, &f.summary)));
    s.min_packing_without_hole = packing.min_covered_without_hole;
    s.min_nonvoid_without_hole = packing.min_nonvoid_without_hole;
    s.max_void_regions_with_hole = packing.max_void_regions_with_hole;
    Ok(s)
}

/// How one run directory stands before the sweep touches it.
enum Start {
    Done,
    Resume,
    Fresh,
}

/// The run's record if `dir` holds one, checked against the job: a sweep never continues a run
/// made with other parameters, seed or frame interval.
fn existing_record(job: &Job, dir: &Path, frame_interval: u64) -> Result<Option<RunRecord>, RunError> {
    if !RunRecord::path(dir).exists() {
        return Ok(None);
    }
    let record = RunRecord::load(dir)?;
    if record.params != job.params || record.seed != job.seed {
        return Err(RunError::OtherRun {
            dir: dir.to_path_buf(),
            why: "was run with other parameters or seed than this sweep gives it: use another --out".into(),
        });
    }
    if record.frame_interval != frame_interval {
        return Err(RunError::OtherRun {
            dir: dir.to_path_buf(),
            why: format!(
                "was run with a frame interval of {}, this sweep asks for {frame_interval}: use the same \
                 --frame-interval, or another --out",
                record.frame_interval
            ),
        });
    }
    Ok(Some(record))
}

fn start_of(job: &Job, dir: &Path, frame_interval: u64) -> Result<Start, RunError> {
    let Some(record) = existing_record(job, dir, frame_interval)? else {
        clear_an_unrecorded_start(job, dir)?;
        return Ok(Start::Fresh);
    };
    if record.status.is_complete() {
        Ok(Start::Done)
    } else if checkpoint_path(dir).exists() {
        Ok(Start::Resume)
    } else {
        // Killed before its first checkpoint (runs of earlier versions): nothing to keep.
        fs::remove_file(RunRecord::path(dir)).map_err(|e| RunError::io(dir, e))?;
        Ok(Start::Fresh)
    }
}

/// A run of the sweep killed between the checkpoint of its start and its record leaves that
/// checkpoint alone: the state of step 0, the random disks, which the run writes again as it
/// starts. It is removed; anything more in a directory without a record is left for
/// [`RunDir::create_locked`] to refuse, naming it.
fn clear_an_unrecorded_start(job: &Job, dir: &Path) -> Result<(), RunError> {
    let checkpoint = checkpoint_path(dir);
    let at_start = checkpoint.is_file() && read_checkpoint(&checkpoint, job.params.box_size).is_ok_and(|s| s.step == 0);
    if at_start {
        fs::remove_file(&checkpoint).map_err(|e| RunError::io(&checkpoint, e))?;
    }
    Ok(())
}

/// Why a job of a sweep did not run.
enum JobError {
    /// Another process holds the run's lock (its process id, when the lock file says).
    Held(Option<u32>),
    Other(RunError),
}

impl From<RunError> for JobError {
    fn from(e: RunError) -> Self {
        JobError::Other(e)
    }
}

/// Runs (or resumes, or skips when done) one job in `OUT/runs/NAME`, single-threaded, holding
/// the directory's lock from before it looks at the directory (taken as `lock` says).
fn execute_job(job: &Job, dir: &Path, output: Output, lock: Lock, on_step: &(dyn Fn() + Sync)) -> Result<(), JobError> {
    let frame_interval = output.frame_interval;
    fs::create_dir_all(dir).map_err(|e| RunError::io(dir, e))?;
    let lock = match lock {
        Lock::IfFree => RunLock::try_acquire(dir)?.map_err(JobError::Held)?,
        Lock::Wait => wait_for_lock(dir, &job.name)?,
    };
    let run = match start_of(job, dir, frame_interval)? {
        Start::Done => return Ok(()),
        Start::Resume => RunDir::resume_locked(lock, dir)?,
        Start::Fresh => {
            job.params.validate().map_err(RunError::from)?;
            crate::run::runner::check_memory(&job.params)?;
            let m = crate::model::Monolayer::new(job.params.clone(), job.seed).map_err(RunError::from)?;
            RunDir::create_locked(lock, dir, m, frame_interval)?
        }
    };
    let mut run = if output.keep_checkpoints { run.keep_checkpoints()? } else { run };
    // A failed simulation is a result of the sweep (it blew up), and a stopped one is retried
    // when the sweep runs again: both are in its run.json, and the summary reports them.
    let _ = run.execute(false, &mut |_, e| {
        if *e == Event::Step {
            on_step()
        }
    });
    Ok(())
}

/// Steps still to run for `job` in `dir` (0 when done).
fn remaining_steps(job: &Job, dir: &Path) -> u64 {
    match RunRecord::load(dir) {
        Ok(r) if r.status.is_complete() => 0,
        Ok(r) => job.params.total_steps().saturating_sub(r.last_frame_step.unwrap_or(0)),
        Err(_) => job.params.total_steps(),
    }
}

/// What every run of a sweep writes: a frame every `frame_interval` active steps, and with
/// `keep_checkpoints` every checkpoint kept.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Output {
    pub frame_interval: u64,
    pub keep_checkpoints: bool,
}

impl From<u64> for Output {
    /// A frame every `frame_interval` steps, only the last checkpoint kept.
    fn from(frame_interval: u64) -> Self {
        Output { frame_interval, keep_checkpoints: false }
    }
}

/// How a worker takes a run's lock.
#[derive(Clone, Copy, PartialEq, Eq)]
enum Lock {
    /// At once, or the run is left for later (another writer has it).
    IfFree,
    /// Once its holder lets go of it, however long that takes (a signal stops the wait).
    Wait,
}

/// The workers of a sweep and what they share: the progress counters, the errors, the runs
/// found held by another writer, and each run's wall time.
struct Crew<'a> {
    runs_dir: &'a Path,
    output: Output,
    workers: usize,
    total: usize,
    progress: &'a (dyn Fn(u64, usize, usize) + Sync),
    done: AtomicUsize,
    steps: AtomicUsize,
    errors: Mutex<Vec<String>>,
    held: Mutex<Vec<&'a Job>>,
    seconds: Mutex<std::collections::HashMap<String, f64>>,
}

impl<'a> Crew<'a> {
    /// Runs `jobs` on the workers, each on one thread; the runs another writer holds are set
    /// aside in `held` when `lock` is [`Lock::IfFree`].
    fn run(&self, jobs: &[&'a Job], lock: Lock) {
        let next = AtomicUsize::new(0);
        std::thread::scope(|scope| {
            for _ in 0..self.workers.max(1).min(jobs.len().max(1)) {
                scope.spawn(|| {
                    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build().expect("a one-thread pool");
                    // After SIGTERM or SIGINT no run starts; those under way stop after their step.
                    while crate::run::runner::stop_signal().is_none() {
                        let Some(&job) = jobs.get(next.fetch_add(1, Ordering::SeqCst)) else { break };
                        self.run_one(&pool, job, lock);
                    }
                });
            }
        });
    }

    fn run_one(&self, pool: &rayon::ThreadPool, job: &'a Job, lock: Lock) {
        let dir = self.runs_dir.join(&job.name);
        let on_step = || {
            let s = self.steps.fetch_add(1, Ordering::Relaxed) as u64 + 1;
            if s.is_multiple_of(100) {
                (self.progress)(s, self.done.load(Ordering::Relaxed), self.total);
            }
        };
        let t = std::time::Instant::now();
        match pool.install(|| execute_job(job, &dir, self.output, lock, &on_step)) {
            Ok(()) => {}
            Err(JobError::Held(_)) if lock == Lock::IfFree => {
                self.held.lock().expect("no panics hold it").push(job);
                return;
            }
            Err(JobError::Held(pid)) => self.errors.lock().expect("no panics hold it").push(format!(
                "{}: stopped while waiting for {} to let go of it; the same command again takes it up",
                job.name,
                holder(pid)
            )),
            Err(JobError::Other(e)) => {
                self.errors.lock().expect("no panics hold it").push(format!("{}: {e}", job.name))
            }
        }
        self.seconds.lock().expect("no panics hold it").insert(job.name.clone(), t.elapsed().as_secs_f64());
        let d = self.done.fetch_add(1, Ordering::SeqCst) + 1;
        (self.progress)(self.steps.load(Ordering::Relaxed) as u64, d, self.total);
    }
}

/// The writer holding a lock, as the error names it.
fn holder(pid: Option<u32>) -> String {
    pid.map(|p| format!("process {p}")).unwrap_or_else(|| "another process".into())
}

/// Takes the lock of the run in `dir` once its holder lets go of it (said once, on stderr), or
/// gives up on SIGTERM or SIGINT with the holder as the error.
fn wait_for_lock(dir: &Path, name: &str) -> Result<RunLock, JobError> {
    let mut said = false;
    loop {
        match RunLock::try_acquire(dir)? {
            Ok(lock) => return Ok(lock),
            Err(pid) if crate::run::runner::stop_signal().is_some() => return Err(JobError::Held(pid)),
            Err(pid) if !said => {
                said = true;
                crate::run::console::note(format_args!(
                    "waiting for {} to let go of run {name} (another sweep of this --out, it seems): the tables \
                     are written once every run is in",
                    holder(pid)
                ));
            }
            Err(_) => {}
        }
        std::thread::sleep(std::time::Duration::from_millis(200));
    }
}

/// Runs every job of `shard` (all by default) on `workers` threads, one simulation each, then
/// summarises every job of the sweep that has output. `progress(steps_done, runs_done)`.
pub fn run_sweep(
    jobs: &[Job],
    output: impl Into<Output>,
    out: &Path,
    workers: usize,
    shard: Option<Shard>,
    progress: &(dyn Fn(u64, usize, usize) + Sync),
) -> Result<Vec<RunSummary>, RunError> {
    let output = output.into();
    let frame_interval = output.frame_interval;
    let runs_dir = out.join("runs");
    fs::create_dir_all(&runs_dir).map_err(|e| RunError::io(&runs_dir, e))?;
    // Check every existing directory against its job before any work starts.
    for job in jobs {
        existing_record(job, &runs_dir.join(&job.name), frame_interval)?;
    }
    let mine: Vec<&Job> =
        jobs.iter().enumerate().filter(|(i, _)| shard.is_none_or(|s| i % s.count == s.index)).map(|(_, j)| j).collect();
    // What the workers hold at once, before any starts: the largest runs left, one per worker.
    let left = mine.iter().filter(|j| remaining_steps(j, &runs_dir.join(&j.name)) > 0).map(|j| &j.params);
    crate::run::runner::check_memory_of_jobs(left, workers)?;
    let crew = Crew {
        runs_dir: &runs_dir,
        output,
        workers,
        total: mine.len(),
        progress,
        done: AtomicUsize::new(0),
        steps: AtomicUsize::new(0),
        errors: Mutex::new(Vec::new()),
        held: Mutex::new(Vec::new()),
        seconds: Mutex::new(std::collections::HashMap::new()),
    };
    crew.run(&mine, Lock::IfFree);
    // Runs another writer (another sweep of OUT) had under way are taken up once it lets go of
    // them: done by then, they are only measured; left part way, they are continued here. So
    // two sweeps of one OUT both end with the tables of every run.
    let held: Vec<&Job> = std::mem::take(&mut *crew.held.lock().expect("no panics hold it"));
    if crate::run::runner::stop_signal().is_none() {
        crew.run(&held, Lock::Wait);
    }
    let Crew { errors, seconds, .. } = crew;
    let errors = errors.into_inner().expect("no panics hold it");
    if !errors.is_empty() {
        return Err(RunError::Jobs(errors));
    }
    let seconds = seconds.into_inner().expect("no panics hold it");
    let mut summaries = measure_existing(jobs, out)?;
    for s in &mut summaries {
        s.run_seconds = seconds.get(&s.name).copied().unwrap_or(0.0);
    }
    Ok(summaries)
}

/// Measures every run of `jobs` that has a directory in `OUT/runs/`, finished or not, running
/// nothing (`sweep --tables-only`, and the end of every sweep). A run still being written is
/// read as far as its frames go: each frame is renamed into place whole.
pub fn measure_existing(jobs: &[Job], out: &Path) -> Result<Vec<RunSummary>, RunError> {
    let runs_dir = out.join("runs");
    let mut summaries = Vec::new();
    for job in jobs {
        let dir = runs_dir.join(&job.name);
        if RunRecord::path(&dir).exists() {
            summaries
                .push(summarize(job, &dir).map_err(|e| e.context(format!("run {} (no table written)", job.name)))?);
        }
    }
    Ok(summaries)
}

/// The runs in `OUT/runs/` as jobs, for `sweep --tables-only` given no grid: each run with the
/// seed and parameters its `run.json` records, and the grid values its directory name carries
/// (`chi0.1_zeta0.5_seed1`, as [`SweepSpec::jobs`] names runs) where every name reads so with the
/// same keys; otherwise the parameters in which the runs differ.
pub fn jobs_of_runs(out: &Path) -> Result<Vec<Job>, RunError> {
    let runs_dir = out.join("runs");
    let entries = fs::read_dir(&runs_dir).map_err(|e| RunError::NotASweep { runs: runs_dir.clone(), source: e })?;
    let mut runs = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| RunError::io(&runs_dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let dir = entry.path();
        // Hidden entries are writers' temporaries; a run linked in from another sweep counts.
        if name.starts_with('.') || !RunRecord::path(&dir).is_file() {
            continue;
        }
        runs.push((name, RunRecord::load(&dir)?));
    }
    let named: Option<Vec<Vec<(String, String)>>> = runs.iter().map(|(n, r)| values_from_name(n, r)).collect();
    let same_keys =
        |v: &Vec<Vec<(String, String)>>| v.windows(2).all(|w| w[0].iter().map(|x| &x.0).eq(w[1].iter().map(|x| &x.0)));
    let values = match named {
        Some(v) if same_keys(&v) => v,
        _ => values_that_differ(&runs),
    };
    let mut jobs: Vec<Job> = runs
        .into_iter()
        .zip(values)
        .map(|((name, record), values)| Job { name, values, params: record.params, seed: record.seed })
        .collect();
    // The order a grid runs in: by each value, numbers as numbers, then by seed.
    jobs.sort_by(|a, b| {
        let key = |j: &Job| -> Vec<(f64, String)> {
            j.values.iter().map(|(_, v)| (v.parse::<f64>().unwrap_or(f64::NAN), v.clone())).collect()
        };
        let order = key(a)
            .iter()
            .zip(key(b).iter())
            .map(|(x, y)| x.0.total_cmp(&y.0).then_with(|| x.1.cmp(&y.1)))
            .find(|o| o.is_ne());
        order.unwrap_or(std::cmp::Ordering::Equal).then(a.seed.cmp(&b.seed)).then_with(|| a.name.cmp(&b.name))
    });
    Ok(jobs)
}

/// The grid values in a run's directory name, each checked against the run's record: a number
/// must equal the recorded parameter (`chi` the recorded ξ_s/ξ_cell as the sweep sets it), a word
/// the recorded one. None where the name does not read so.
fn values_from_name(name: &str, record: &RunRecord) -> Option<Vec<(String, String)>> {
    let table = serde_json::to_value(&record.params).ok()?;
    let table = table.as_object()?;
    let mut keys: Vec<&str> = table.keys().map(String::as_str).chain(["chi"]).collect();
    // `phi_min` before a hypothetical `phi`: the longest key that fits.
    keys.sort_by_key(|k| std::cmp::Reverse(k.len()));
    let end = format!("seed{}", record.seed);
    let mut rest = name;
    let mut values = Vec::new();
    while rest != end {
        let found = keys.iter().filter(|k| rest.starts_with(**k)).find_map(move |&k| {
            let after = &rest[k.len()..];
            let (shown, len) = match table.get(k) {
                Some(serde_json::Value::String(word)) => {
                    let written = word.replace(['/', ' ', '"'], "");
                    after.starts_with(&format!("{written}_")).then(|| (word.clone(), written.len()))?
                }
                recorded => {
                    let len = after.find('_')?;
                    let x: f64 = after[..len].parse().ok()?;
                    let matches = match recorded {
                        None => {
                            let mut p = record.params.clone();
                            p.set_chi(x);
                            p.xi_substrate == record.params.xi_substrate
                        }
                        Some(v) => v.as_f64() == Some(x),
                    };
                    matches.then(|| (after[..len].to_string(), len))?
                }
            };
            Some(((k.to_string(), shown), &after[len + 1..]))
        });
        let (value, next) = found?;
        values.push(value);
        rest = next;
    }
    Some(values)
}

/// Each run's values of the parameters in which the runs differ, by name.
fn values_that_differ(runs: &[(String, RunRecord)]) -> Vec<Vec<(String, String)>> {
    let tables: Vec<serde_json::Map<String, serde_json::Value>> = runs
        .iter()
        .map(|(_, r)| match serde_json::to_value(&r.params) {
            Ok(serde_json::Value::Object(t)) => t,
            _ => unreachable!("parameters serialise as a table"),
        })
        .collect();
    let Some(first) = tables.first() else { return Vec::new() };
    let keys: Vec<&String> = first.keys().filter(|k| tables.iter().any(|t| t.get(*k) != first.get(*k))).collect();
    let text = |v: Option<&serde_json::Value>| match v {
        Some(serde_json::Value::String(s)) => s.clone(),
        Some(v) => v.to_string(),
        None => String::new(),
    };
    tables.iter().map(|t| keys.iter().map(|k| (k.to_string(), text(t.get(*k)))).collect()).collect()
}

/// Total steps the sweep still has to run (for the progress bar).
pub fn steps_to_run(jobs: &[Job], out: &Path, shard: Option<Shard>) -> u64 {
    jobs.iter()
        .enumerate()
        .filter(|(i, _)| shard.is_none_or(|s| i % s.count == s.index))
        .map(|(_, j)| remaining_steps(j, &out.join("runs").join(&j.name)))
        .sum()
}

/// A grid point (all seeds pooled) and its regime.
#[derive(Clone, Debug)]
pub struct RegimePoint {
    pub values: Vec<(String, String)>,
    pub runs: usize,
    pub blew_up: usize,
    pub holes: usize,
    pub fitted_lifetime: Option<f64>,
    pub active_time: f64,
    pub regime: Regime,
    /// The fit and regime with every tracked void region counted as a hole.
    pub fitted_lifetime_regions: Option<f64>,
    pub regime_regions: Regime,
}

/// Pools the seeds of every grid point.
pub fn regime_map(summaries: &[RunSummary]) -> Vec<RegimePoint> {
    let mut points: Vec<RegimePoint> = Vec::new();
    // Per point: the holes counted as families, and as regions.
    type Pooled = (Vec<(f64, bool)>, Vec<(f64, bool)>);
    let mut pooled: Vec<Pooled> = Vec::new();
    // Only runs that ended count: a run stopped by the machine, or not yet run, says nothing of
    // the regime.
    for s in summaries.iter().filter(|s| s.status.is_complete()) {
        let k = match points.iter().position(|p| p.values == s.values) {
            Some(k) => k,
            None => {
                points.push(RegimePoint {
                    values: s.values.clone(),
                    runs: 0,
                    blew_up: 0,
                    holes: 0,
                    fitted_lifetime: None,
                    active_time: 0.0,
                    regime: Regime::NoHoles,
                    fitted_lifetime_regions: None,
                    regime_regions: Regime::NoHoles,
                });
                pooled.push((Vec::new(), Vec::new()));
                points.len() - 1
            }
        };
        let p = &mut points[k];
        p.runs += 1;
        p.blew_up += s.blew_up() as usize;
        p.holes += s.holes_nucleated;
        p.active_time = p.active_time.max(s.active_time);
        pooled[k].0.extend(&s.lifetimes);
        pooled[k].1.extend(&s.region_lifetimes);
    }
    for (p, (families, regions)) in points.iter_mut().zip(&pooled) {
        p.fitted_lifetime = fitted_lifetime(families);
        p.regime = classify(families, p.active_time);
        p.fitted_lifetime_regions = fitted_lifetime(regions);
        p.regime_regions = classify(regions, p.active_time);
    }
    points
}

fn opt(v: Option<f64>) -> String {
    v.map(|x| format!("{x:.6}")).unwrap_or_default()
}

/// `summary.csv` (one row per run) and `regimes.csv` (one row per grid point).
pub fn tables(summaries: &[RunSummary]) -> (String, String) {
    let keys: Vec<String> =
        summaries.first().map(|s| s.values.iter().map(|v| v.0.clone()).collect()).unwrap_or_default();
    let mut runs = String::from("run,");
    for k in &keys {
        runs += &format!("{k},");
    }
    runs += "seed,status,blew_up,steps,active_time,holes_nucleated,max_hole_area,time_with_hole_open,\
             hole_lifetimes,max_holes_open,fraction_multiple_holes,mean_speed,mean_speed_um_per_h,\
             mean_speed_um_per_h_at_3.6s,mean_speed_um_per_h_at_5s,velocity_correlation_length,\
             nematic_correlation_length,min_packing_fraction_without_hole,min_nonvoid_fraction_without_hole,\
             max_void_regions_with_hole,aspect_ratio_mean,aspect_ratio_p90,region_lifetimes\n";
    let list = |l: &[(f64, bool)]| -> String {
        l.iter().map(|(t, closed)| format!("{t:.1}{}", if *closed { "" } else { "+" })).collect::<Vec<_>>().join(";")
    };
    for s in summaries {
        let status = s.status.to_string().lines().next().unwrap_or("").replace(',', ";");
        let _ = write!(runs, "{},", s.name);
        for (_, v) in &s.values {
            let _ = write!(runs, "{v},");
        }
        let _ = writeln!(
            runs,
            "{},\"{}\",{},{},{:.1},{},{},{:.1},{},{},{:.4},{:.6},{:.3},{:.3},{:.3},{},{},{},{},{},{},{},{}",
            s.seed,
            status,
            s.blew_up(),
            s.steps,
            s.active_time,
            s.holes_nucleated,
            s.max_hole_area,
            s.time_with_hole_open,
            list(&s.lifetimes),
            s.max_holes_open,
            s.fraction_multiple_holes,
            s.mean_speed,
            s.mean_speed * s.microns_per_hour,
            s.mean_speed * 3600.0 / 3.6,
            s.mean_speed * 3600.0 / 5.0,
            opt(s.velocity_correlation_length),
            opt(s.nematic_correlation_length),
            opt(s.min_packing_without_hole),
            opt(s.min_nonvoid_without_hole),
            s.max_void_regions_with_hole,
            opt(s.aspect_ratio_mean),
            opt(s.aspect_ratio_p90),
            list(&s.region_lifetimes)
        );
    }
    let mut regimes = String::new();
    for k in &keys {
        regimes += &format!("{k},");
    }
    regimes += "runs,blew_up,holes,fitted_lifetime,active_time,regime,fitted_lifetime_regions,regime_regions\n";
    let fit =
        |t: Option<f64>| t.map(|t| if t.is_finite() { format!("{t:.1}") } else { "inf".into() }).unwrap_or_default();
    for p in regime_map(summaries) {
        for (_, v) in &p.values {
            let _ = write!(regimes, "{v},");
        }
        let _ = writeln!(
            regimes,
            "{},{},{},{},{:.1},{},{},{}",
            p.runs,
            p.blew_up,
            p.holes,
            fit(p.fitted_lifetime),
            p.active_time,
            p.regime.name(),
            fit(p.fitted_lifetime_regions),
            p.regime_regions.name()
        );
    }
    (runs, regimes)
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

/// The regime map like the paper's Fig. 3d, χ (log scale) against ζ: red circles no holes, blue
/// squares only short-lived, green triangles short- and long-lived; a cross where a run blew up.
/// Drawn only when the grid varies both `chi` and `zeta`.
fn plot_regime_map(base: &Path, points: &[RegimePoint]) -> Result<Vec<PathBuf>, RunError> {
    use crate::run::plots::{both_of, plot_err, regime_marker, Draw, FONT};
    use plotters::coord::Shift;
    use plotters::prelude::*;

    let get = |p: &RegimePoint, k: &str| p.values.iter().find(|v| v.0 == k).and_then(|v| v.1.parse::<f64>().ok());
    let xy: Vec<(f64, f64, Regime, bool)> =
        points.iter().filter_map(|p| Some((get(p, "chi")?, get(p, "zeta")?, p.regime, p.blew_up > 0))).collect();
    if xy.len() < 2 || xy.iter().any(|p| p.0 <= 0.0) {
        return Ok(Vec::new());
    }
    struct Map(Vec<(f64, f64, Regime, bool)>);
    impl Draw for Map {
        fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>) -> Result<(), RunError> {
            root.fill(&WHITE).map_err(plot_err)?;
            let f = |g: fn(f64, f64) -> f64, i: fn(&(f64, f64, Regime, bool)) -> f64, init| {
                self.0.iter().map(i).fold(init, g)
            };
            let (x0, x1) = (f(f64::min, |p| p.0, f64::MAX) / 2.0, f(f64::max, |p| p.0, 0.0) * 2.0);
            let (y0, y1) = (f(f64::min, |p| p.1, f64::MAX), f(f64::max, |p| p.1, f64::MIN));
            let pad = ((y1 - y0) * 0.15).max(0.05);
            let mut chart = ChartBuilder::on(root)
                .caption("Regime map", (FONT, 22))
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(50)
                .build_cartesian_2d((x0..x1).log_scale(), (y0 - pad)..(y1 + pad))
                .map_err(plot_err)?;
            chart.configure_mesh().x_desc("χ = ξ_s / ξ_cell").y_desc("ζ").draw().map_err(plot_err)?;
            for &(x, y, regime, blew_up) in &self.0 {
                regime_marker(&mut chart, (x, y), regime, blew_up)?;
            }
            Ok(())
        }
    }
    both_of(base, (640, 480), &Map(xy))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The regime criterion pools the holes counted as families; the regions' fit is reported
    /// beside it. One long hole whose fragments break off and close (the pattern of the
    /// low-friction runs): persistent as a family, short-lived as regions.
    #[test]
    fn regimes_pool_families_and_report_regions_beside() {
        let run = |seed| RunSummary {
            name: format!("chi0.001_seed{seed}"),
            values: vec![("chi".into(), "0.001".into())],
            seed,
            status: RunStatus::Finished,
            active_time: 10_000.0,
            holes_nucleated: 1,
            lifetimes: vec![(8_000.0, false)],
            region_lifetimes: vec![(8_000.0, false), (100.0, true), (200.0, true), (300.0, true)],
            ..RunSummary::default()
        };
        let map = regime_map(&[run(1), run(2)]);
        assert_eq!(map.len(), 1);
        let p = &map[0];
        assert_eq!((p.runs, p.holes), (2, 2));
        assert_eq!((p.fitted_lifetime, p.regime), (Some(f64::INFINITY), Regime::ShortAndLongLived));
        // Regions: 17,200 time units over 6 closed holes.
        assert_eq!(p.fitted_lifetime_regions, Some(17_200.0 / 6.0));
        assert_eq!(p.regime_regions, Regime::OnlyShortLived);
        let (summary, regimes) = tables(&[run(1)]);
        assert!(summary.lines().next().unwrap().ends_with(",region_lifetimes"), "{summary}");
        assert!(summary.lines().nth(1).unwrap().ends_with(",8000.0+;100.0;200.0;300.0"), "{summary}");
        assert!(regimes.contains(",regime,fitted_lifetime_regions,regime_regions\n"), "{regimes}");
        assert!(regimes.contains(",short_and_long_lived,2866.7,only_short_lived\n"), "{regimes}");
    }

    /// Both packing readings count only the frames with no hole open; the gaps beside a hole
    /// count every void region of the frames with one open.
    #[test]
    fn packing_readings_keep_frames_with_and_without_a_hole_apart() {
        let frame = |packing_fraction, void_fraction, void_regions| FrameSummary {
            packing_fraction,
            void_fraction,
            void_regions,
            holes: 0,
            largest_void: 0,
            plus_half_defects: 0,
            minus_half_defects: 0,
            spiral_cores: 0,
            max_strain_rate: 0.0,
            velocity_correlation_length: None,
            nematic_correlation_length: None,
            aspect_ratio_mean: None,
            aspect_ratio_p90: None,
            mean_speed: 0.0,
        };
        // No hole: a tissue with small gaps at its vertices (covered 0.93, not void 0.999),
        // then one nearly whole; a hole open with two other gaps beside it (its own low
        // packing is not counted).
        let frames = [(0, frame(0.93, 0.001, 2)), (0, frame(0.97, 0.0, 0)), (1, frame(0.70, 0.2, 3))];
        let r = PackingReadings::of(frames.iter().map(|(o, f)| (*o, f)));
        assert_eq!(r.min_covered_without_hole, Some(0.93));
        assert_eq!(r.min_nonvoid_without_hole, Some(1.0 - 0.001));
        assert_eq!(r.max_void_regions_with_hole, 3);
        let never = PackingReadings::of(frames[2..].iter().map(|(o, f)| (*o, f)));
        assert_eq!((never.min_covered_without_hole, never.min_nonvoid_without_hole), (None, None));
    }

    /// A run's directory name read back into the grid values its sweep gave it, each checked
    /// against the record; a name that does not read so gives none.
    #[test]
    fn grid_values_are_read_back_from_run_names() {
        let mut spec: SweepSpec = toml::from_str("seeds = [2]\n[grid]\nchi = [0.001]\nzeta = [0.3]\n").unwrap();
        spec.add_grid("passive_force=phi_grad_mu").unwrap();
        spec.add_grid("n_cells=40").unwrap();
        for job in spec.jobs().unwrap() {
            let record = RunRecord::new(job.params.clone(), job.seed, 50);
            assert_eq!(values_from_name(&job.name, &record), Some(job.values.clone()), "{}", job.name);
            assert_eq!(values_from_name(&job.name.replace("zeta0.3", "zeta0.4"), &record), None);
            assert_eq!(values_from_name(&job.name.replace("seed2", "seed3"), &record), None);
        }
        let (a, mut b) = (Params::default(), Params::default());
        b.gamma = 0.07;
        let runs = [("x".to_string(), RunRecord::new(a, 1, 50)), ("y".to_string(), RunRecord::new(b, 1, 50))];
        let differ = values_that_differ(&runs);
        assert_eq!(differ[1], [("gamma".to_string(), "0.07".to_string())]);
    }

    #[test]
    fn grid_expands_validates_and_names() {
        let mut spec: SweepSpec =
            toml::from_str("seeds = [1, 2]\n[base]\nactive_steps = 10\n[grid]\nchi = [0.1, 0.01]\n").unwrap();
        spec.add_grid("zeta=0.3,0.5").unwrap();
        let jobs = spec.jobs().unwrap();
        assert_eq!(jobs.len(), 8);
        assert_eq!(jobs[0].name, "chi0.1_zeta0.3_seed1");
        assert!((jobs[0].params.xi_substrate - 0.1).abs() < 1e-15);
        assert_eq!(jobs[0].params.active_steps, 10);
        let bad: SweepSpec = toml::from_str("[grid]\nzeta = [0.3, 40.0]\n").unwrap();
        let e = bad.jobs().unwrap_err().to_string();
        assert!(e.contains("zeta = 40") && e.contains("`zeta`"), "{e}");
        let typo: SweepSpec = toml::from_str("[grid]\nzetta = [0.3]\n").unwrap();
        assert!(typo.jobs().unwrap_err().to_string().contains("zetta"));
        assert!(toml::from_str::<SweepSpec>("sedes = [1]\n").is_err());
        assert_eq!("2/4".parse::<Shard>().unwrap(), Shard { index: 2, count: 4 });
    }

    #[test]
    fn points_are_listed_runs_named_like_grid_runs() {
        let mut spec: SweepSpec = toml::from_str("seeds = [1, 2]\n[[points]]\nchi = 0.1\nzeta = 0.5\n").unwrap();
        spec.add_point("chi=0.001,zeta=0.3").unwrap();
        let jobs = spec.jobs().unwrap();
        let names: Vec<&str> = jobs.iter().map(|j| j.name.as_str()).collect();
        assert_eq!(
            names,
            ["chi0.1_zeta0.5_seed1", "chi0.1_zeta0.5_seed2", "chi0.001_zeta0.3_seed1", "chi0.001_zeta0.3_seed2"]
        );
        assert!((jobs[2].params.xi_substrate - 0.001).abs() < 1e-15 && jobs[2].params.zeta == 0.3);
        // With a grid, every point takes its product.
        spec.add_grid("gamma=0.05,0.06").unwrap();
        assert_eq!(spec.jobs().unwrap()[0].name, "chi0.1_zeta0.5_gamma0.05_seed1");
        assert_eq!(spec.jobs().unwrap().len(), 8);
        // Refused, each naming why.
        let err = |spec: &SweepSpec| spec.jobs().unwrap_err().to_string();
        let mut overlap = spec.clone();
        overlap.add_grid("zeta=0.3").unwrap();
        assert!(err(&overlap).contains("`zeta` is set both"), "{}", err(&overlap));
        let mut uneven = spec.clone();
        uneven.add_point("chi=0.01").unwrap();
        assert!(err(&uneven).contains("the same parameters"), "{}", err(&uneven));
        let mut twice = spec.clone();
        twice.add_point("chi=0.1,zeta=0.5").unwrap();
        assert!(err(&twice).contains("would share the directory chi0.1_zeta0.5_gamma0.05_seed1"), "{}", err(&twice));
        let empty = || toml::from_str::<SweepSpec>("").unwrap();
        assert!(empty().add_point("chi=0.1,chi=0.2").unwrap_err().to_string().contains("twice"));
        let mut bad = empty();
        bad.add_point("chi=0.1,zeta=40").unwrap();
        assert!(err(&bad).contains("zeta"), "{}", err(&bad));
        assert!("4/4".parse::<Shard>().is_err());
    }
}

//! The sweep's runs, one per core: each run directory checked against its job, then started,
//! continued from its checkpoint or left as done; runs another writer holds are waited for.

use std::fs;
use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::Mutex;

use super::spec::{Job, Shard};
use super::summary::{measure_existing, RunSummary};
use crate::formats::RunRecord;
use crate::run::error::RunError;
use crate::run::files::{checkpoint_path, read_checkpoint, RunLock};
use crate::run::pool::each_on_one_core;
use crate::run::runner::{Event, RunDir};

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
        each_on_one_core(jobs, self.workers, |_, &job| {
            self.run_one(job, lock);
            Ok(())
        });
    }

    fn run_one(&self, job: &'a Job, lock: Lock) {
        let dir = self.runs_dir.join(&job.name);
        let on_step = || {
            let s = self.steps.fetch_add(1, Ordering::Relaxed) as u64 + 1;
            if s.is_multiple_of(100) {
                (self.progress)(s, self.done.load(Ordering::Relaxed), self.total);
            }
        };
        let t = std::time::Instant::now();
        match execute_job(job, &dir, self.output, lock, &on_step) {
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

/// Total steps the sweep still has to run (for the progress bar).
pub fn steps_to_run(jobs: &[Job], out: &Path, shard: Option<Shard>) -> u64 {
    jobs.iter()
        .enumerate()
        .filter(|(i, _)| shard.is_none_or(|s| i % s.count == s.index))
        .map(|(_, j)| remaining_steps(j, &out.join("runs").join(&j.name)))
        .sum()
}

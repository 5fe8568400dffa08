//! The runs, the second stage of `monolayer figures`: the plan's runs through the sweep
//! machinery (`OUT/runs/NAME`, one per core, resumable, single-threaded so that a Slurm task and
//! a laptop give the same bits), what they will cost before they start, and, for the stages
//! after, the finished runs with their records ([`Runs`]). On a cluster [`super::slurm`] runs
//! them instead, as a job array of `--stage runs` tasks.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use super::plan::Plan;
use crate::formats::RunRecord;
use crate::model::{Monolayer, Params};
use crate::run::error::RunError;
use crate::run::sweep::{run_sweep, steps_to_run, Job, Shard};

/// This process's share of the plan (all of it, or a Slurm array task's `--shard K/N`), with the
/// steps each of its runs still has in `OUT/runs/`, read once.
pub struct Share<'p> {
    /// The runs of the share, in the plan's order.
    pub mine: Vec<&'p Job>,
    /// Those with steps left, with how many.
    pub todo: Vec<(&'p Job, u64)>,
}

impl<'p> Share<'p> {
    /// The runs of `shard` and the steps they have left in `out`.
    pub fn of(plan: &'p Plan, out: &Path, shard: Option<Shard>) -> Share<'p> {
        let mine: Vec<&Job> = plan
            .jobs
            .iter()
            .enumerate()
            .filter(|(i, _)| shard.is_none_or(|s| i % s.count == s.index))
            .map(|(_, j)| j)
            .collect();
        let todo = mine
            .iter()
            .map(|&j| (j, steps_to_run(std::slice::from_ref(j), out, None)))
            .filter(|&(_, left)| left > 0)
            .collect();
        Share { mine, todo }
    }

    /// The steps the share has left.
    pub fn steps(&self) -> u64 {
        self.todo.iter().map(|&(_, left)| left).sum()
    }

    /// Estimated core-seconds of the steps the share has left, at `speed`.
    pub fn core_seconds(&self, speed: &Speed) -> f64 {
        self.todo.iter().map(|&(job, left)| speed.core_seconds(job, left)).sum()
    }
}

/// Before the estimate, which steps a simulation of every size in the plan one at a time (and
/// would abort where one does not fit): the largest must fit, as every run must; and the runs
/// the share has left, `workers` at a time, must fit together.
pub fn check_memory(plan: &Plan, share: &Share, workers: usize) -> Result<(), RunError> {
    if let Some(job) = plan.jobs.iter().max_by_key(|j| crate::run::runner::memory_estimate(&j.params)) {
        job.params.validate().map_err(RunError::from)?;
        crate::run::runner::check_memory(&job.params)?;
    }
    crate::run::runner::check_memory_of_jobs(share.todo.iter().map(|(job, _)| &job.params), workers)
}

/// A duration of core time in the unit that reads best.
pub fn hours(seconds: f64) -> String {
    let h = seconds / 3600.0;
    if h >= 48.0 {
        format!("{:.0} hours (≈ {:.1} days)", h, h / 24.0)
    } else if h >= 1.0 {
        format!("{h:.1} hours")
    } else {
        format!("{:.1} minutes", seconds / 60.0)
    }
}

/// Milliseconds per step on one thread, measured on a short run of each lattice size the plan
/// uses: (L, N) → (relaxation, active).
#[derive(Clone, Debug)]
pub struct Speed {
    pub sizes: Vec<((usize, usize), (f64, f64))>,
}

impl Speed {
    /// Times `steps` relaxation and `steps` active steps at each (L, N) of `jobs`, at the plan's
    /// lowest friction (the costliest solve), after `warm_up` untimed steps of each (the first
    /// steps from the small initial disks, and the first solves from rest, cost more than the
    /// rest of a run). The tissue is not yet confluent this early, so this is an estimate, not a
    /// bound; it is what the machine does now, not what a README says.
    pub fn measure(jobs: &[&Job], warm_up: u64, steps: u64) -> Result<Speed, RunError> {
        let mut sizes: Vec<((usize, usize), (f64, f64))> = Vec::new();
        let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
        for job in jobs {
            let key = (job.params.box_size, job.params.n_cells);
            if sizes.iter().any(|s| s.0 == key) {
                continue;
            }
            // What is timed is the cost of a step, not the physics: a job that blows up this early
            // (γ = 0.04 does within 22 relaxation steps) gives way to the next job of its
            // size, and failing all, to the default physics at that size. A run that blows up is
            // a result of the runs (`failed: …`), never a failure of the estimate.
            let mut candidates: Vec<Params> = jobs
                .iter()
                .filter(|j| (j.params.box_size, j.params.n_cells) == key)
                .map(|j| j.params.clone())
                .collect();
            candidates.push(Params {
                box_size: key.0,
                n_cells: key.1,
                radius: job.params.radius,
                relax_patch_size: job.params.relax_patch_size,
                patch_margin: job.params.patch_margin,
                ..Params::default()
            });
            let mut last = String::new();
            let mut timed = None;
            for p in candidates {
                match time_steps(&pool, p, warm_up, steps) {
                    Ok(t) => {
                        timed = Some(t);
                        break;
                    }
                    Err(e) => last = e.to_string(),
                }
            }
            let timed = timed.ok_or_else(|| RunError::Timing {
                l: key.0,
                n: key.1,
                why: format!("every job of this size and the defaults failed ({last})"),
            })?;
            sizes.push((key, timed));
        }
        Ok(Speed { sizes })
    }

    /// Estimated core-seconds of `left` steps still to run of `job` (of its relaxation first).
    pub fn core_seconds(&self, job: &Job, left: u64) -> f64 {
        let done = job.params.total_steps() - left;
        let relax_left = job.params.relax_steps.saturating_sub(done);
        let (r, a) = self
            .sizes
            .iter()
            .find(|s| s.0 == (job.params.box_size, job.params.n_cells))
            .map(|s| s.1)
            .unwrap_or((0.0, 0.0));
        1e-3 * (relax_left as f64 * r + (left - relax_left) as f64 * a)
    }
}

/// (relaxation, active) ms per step of `p` at χ = 0.001, after `warm_up` untimed steps of each.
fn time_steps(pool: &rayon::ThreadPool, mut p: Params, warm_up: u64, steps: u64) -> Result<(f64, f64), RunError> {
    p.relax_steps = warm_up + steps;
    if p.xi_cell == 0.0 {
        p.xi_cell = 1.0;
    }
    p.set_chi(0.001);
    // Some seeds cannot place their disks at the paper's density: take the first that can.
    let mut m = (1..=10).find_map(|seed| Monolayer::new(p.clone(), seed).ok()).ok_or_else(|| RunError::Timing {
        l: p.box_size,
        n: p.n_cells,
        why: "no seed of 1–10 starts".into(),
    })?;
    let mut timed = |n: u64| -> Result<f64, RunError> {
        let t = Instant::now();
        pool.install(|| m.advance(n)).map_err(RunError::from)?;
        Ok(1e3 * t.elapsed().as_secs_f64() / n as f64)
    };
    timed(warm_up)?;
    let relax = timed(steps)?;
    timed(warm_up.min(10))?;
    let active = timed(steps)?;
    Ok((relax, active))
}

/// Runs the share through the sweep machinery, `workers` at a time, with a bar over all its
/// steps (a line per finished run when `quiet`).
pub fn execute(plan: &Plan, share: &Share, out: &Path, workers: usize, quiet: bool) -> Result<(), RunError> {
    let jobs: Vec<Job> = share.mine.iter().map(|j| (*j).clone()).collect();
    let bar = if quiet {
        ProgressBar::hidden()
    } else {
        let bar = ProgressBar::new(share.steps());
        bar.set_style(
            ProgressStyle::with_template("{msg:>12} [{bar:40}] {pos}/{len} steps  {per_sec}  ETA {eta}")
                .expect("template")
                .progress_chars("=> "),
        );
        bar
    };
    bar.set_message(format!("runs 0/{}", jobs.len()));
    let start = Instant::now();
    let reported = AtomicUsize::new(0);
    let summaries = run_sweep(&jobs, plan.frame_interval, out, workers, None, &|s, done, total| {
        bar.set_position(s);
        bar.set_message(format!("runs {done}/{total}"));
        if quiet && reported.fetch_max(done, Ordering::Relaxed) < done {
            crate::run::console::note(format_args!("{done}/{total} runs done, {:.0} s", start.elapsed().as_secs_f64()));
        }
    })?;
    bar.finish();
    let wall = start.elapsed().as_secs_f64();
    let run_time: f64 = summaries.iter().map(|s| s.run_seconds).sum();
    let failed: Vec<&str> = summaries.iter().filter(|s| s.blew_up()).map(|s| s.name.as_str()).collect();
    crate::run::console::note(format_args!(
        "runs done in {wall:.0} s ({:.2} core-hours of runs){}",
        run_time / 3600.0,
        if failed.is_empty() { String::new() } else { format!("; unstable, stopped early: {}", failed.join(", ")) }
    ));
    Ok(())
}

/// What the runs stage hands on: every run of the plan, finished, with its directory and record
/// (in the plan's order).
pub struct Runs<'p> {
    pub plan: &'p Plan,
    /// `OUT/runs/NAME` of each job of the plan.
    pub dirs: Vec<PathBuf>,
    pub records: Vec<RunRecord>,
}

/// The plan's runs in `out/runs`, each finished with the parameters and seed the plan gives it;
/// refuses, naming them, when runs are missing or unfinished (the figures would silently be
/// drawn from fewer runs).
pub fn finished<'p>(plan: &'p Plan, out: &Path) -> Result<Runs<'p>, RunError> {
    let runs_dir = out.join("runs");
    let mut missing = Vec::new();
    let mut dirs = Vec::new();
    let mut records = Vec::new();
    for job in &plan.jobs {
        let dir = runs_dir.join(&job.name);
        match RunRecord::load(&dir) {
            Ok(r) if r.status.is_complete() => {
                if r.params != job.params || r.seed != job.seed {
                    return Err(RunError::OtherRun {
                        dir,
                        why:
                            "was run with other parameters or seed than this plan gives it (another scale or --set?): \
                              use another --out"
                                .into(),
                    });
                }
                records.push(r);
            }
            Ok(r) => missing.push(format!("{} ({})", job.name, r.status)),
            Err(_) => missing.push(format!("{} (not started)", job.name)),
        }
        dirs.push(dir);
    }
    if !missing.is_empty() {
        return Err(RunError::Unfinished { missing, total: plan.jobs.len(), dir: runs_dir });
    }
    Ok(Runs { plan, dirs, records })
}

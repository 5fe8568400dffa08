//! `monolayer figures`: the plan, its estimate, then the runs (here or as Slurm jobs) and the
//! figures.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use indicatif::{ProgressBar, ProgressStyle};

use super::slurm::{self, SlurmOptions};
use super::{make_figures, Figure, Plan, Scale, Speed, Stage};
use crate::run::error::RunError;
use crate::run::sweep::{run_sweep, steps_to_run, Job, Shard};

/// What the command line asked for.
#[derive(Clone, Debug)]
pub struct FiguresOptions {
    pub out: PathBuf,
    pub scale: Scale,
    /// `--only` as given.
    pub only: Option<String>,
    pub sets: Vec<String>,
    pub jobs: usize,
    pub yes: bool,
    pub stage: Stage,
    pub shard: Option<Shard>,
    pub quiet: bool,
    pub slurm: bool,
    pub dry_run: bool,
    pub throttle: usize,
    pub partition: Option<String>,
}

fn hours(seconds: f64) -> String {
    let h = seconds / 3600.0;
    if h >= 48.0 {
        format!("{:.0} hours (≈ {:.1} days)", h, h / 24.0)
    } else if h >= 1.0 {
        format!("{h:.1} hours")
    } else {
        format!("{:.1} minutes", seconds / 60.0)
    }
}

/// Runs `monolayer figures`; the files written are printed, the rest goes to stderr.
pub fn figures(o: &FiguresOptions) -> Result<(), RunError> {
    let figures = match &o.only {
        Some(list) => Figure::parse_list(list)?,
        None => Figure::ALL.to_vec(),
    };
    if o.jobs == 0 {
        return Err("--jobs 0: must be ≥ 1".into());
    }
    let plan = Plan::new(o.scale, &figures, &o.sets)?;
    if !o.dry_run {
        crate::run::files::remove_dead_temporaries(&o.out);
    }
    let mine: Vec<&Job> = plan
        .jobs
        .iter()
        .enumerate()
        .filter(|(i, _)| o.shard.is_none_or(|s| i % s.count == s.index))
        .map(|(_, j)| j)
        .collect();
    if o.stage == Stage::Figures {
        return draw(&plan, &o.out, o.jobs);
    }
    // Before the estimate, which steps a simulation of every size in the plan (and would abort
    // where one does not fit): the largest must fit, as every run must.
    if let Some(job) = plan.jobs.iter().max_by_key(|j| crate::run::runner::memory_estimate(&j.params)) {
        job.params.validate().map_err(RunError::from)?;
        crate::run::runner::check_memory(&job.params)?;
    }
    let todo: Vec<&Job> =
        mine.iter().copied().filter(|j| steps_to_run(std::slice::from_ref(*j), &o.out, None) > 0).collect();
    let steps: u64 = todo.iter().map(|j| steps_to_run(std::slice::from_ref(*j), &o.out, None)).sum();
    let ids: Vec<&str> = figures.iter().map(|f| f.id()).collect();
    eprintln!(
        "figures (scale {}): {} need {} runs{}; {} to run, {} steps",
        o.scale.name(),
        ids.join(", "),
        plan.jobs.len(),
        o.shard.map(|s| format!(" ({} in shard {}/{})", mine.len(), s.index, s.count)).unwrap_or_default(),
        todo.len(),
        steps
    );
    // The longest run and the whole plan, for the estimate and for Slurm's time limits.
    let every: Vec<&Job> = plan.jobs.iter().collect();
    let sample: Vec<&Job> = if todo.is_empty() && !o.slurm { Vec::new() } else { every.clone() };
    let speed = Speed::measure(&sample, 100, 30)?;
    for ((l, n), (r, a)) in &speed.sizes {
        eprintln!(
            "  measured on one thread at L = {l}, N = {n}: {r:.2} ms/step relaxing, {a:.2} ms/step active (χ = 0.001)"
        );
    }
    if o.slurm {
        return submit(&plan, o, &speed);
    }
    let core_seconds = speed.core_seconds(&todo, &o.out);
    let workers = o.jobs.min(todo.len().max(1));
    if !todo.is_empty() {
        eprintln!(
            "  estimate: {:.2} core-hours, about {} on {} core(s) (measured before the tissue is confluent: runs with holes cost more)",
            core_seconds / 3600.0,
            hours(core_seconds / workers as f64),
            workers
        );
    }
    if o.dry_run {
        eprintln!("dry run: nothing run or written");
        return Ok(());
    }
    // A shard is a Slurm array task's share of the plan: only the whole plan here is refused.
    if matches!(o.scale, Scale::Paper | Scale::Evidence) && !o.yes && o.shard.is_none() && !todo.is_empty() {
        return Err(RunError::Message(format!(
            "--scale {} runs {} simulations here, about {} on {} core(s): refused without --yes; \
             on a cluster, --slurm submits them as a job array (--slurm --dry-run prints the scripts)",
            o.scale.name(),
            todo.len(),
            hours(core_seconds / workers as f64),
            workers
        )));
    }
    if !todo.is_empty() {
        execute(&plan, &mine, o, steps)?;
    }
    if let Some((name, _)) = crate::run::runner::stop_signal() {
        return Err(RunError::Message(format!(
            "stopped by {name}: the same command again continues the runs from their checkpoints"
        )));
    }
    if o.stage == Stage::All {
        draw(&plan, &o.out, o.jobs)?;
    }
    Ok(())
}

fn draw(plan: &Plan, out: &Path, workers: usize) -> Result<(), RunError> {
    let t = Instant::now();
    let written = make_figures(plan, out, workers)?;
    for path in &written {
        println!("{}", path.display());
    }
    eprintln!("figures drawn in {:.1} s: {}", t.elapsed().as_secs_f64(), out.join("figures.md").display());
    Ok(())
}

/// The runs through the sweep machinery, with a bar over all their steps.
fn execute(plan: &Plan, mine: &[&Job], o: &FiguresOptions, steps: u64) -> Result<(), RunError> {
    let jobs: Vec<Job> = mine.iter().map(|j| (*j).clone()).collect();
    let bar = if o.quiet {
        ProgressBar::hidden()
    } else {
        let bar = ProgressBar::new(steps);
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
    let summaries = run_sweep(&jobs, plan.frame_interval, &o.out, o.jobs, None, &|s, done, total| {
        bar.set_position(s);
        bar.set_message(format!("runs {done}/{total}"));
        if o.quiet && reported.fetch_max(done, Ordering::Relaxed) < done {
            eprintln!("{done}/{total} runs done, {:.0} s", start.elapsed().as_secs_f64());
        }
    })?;
    bar.finish();
    let wall = start.elapsed().as_secs_f64();
    let run_time: f64 = summaries.iter().map(|s| s.run_seconds).sum();
    let failed: Vec<&str> = summaries.iter().filter(|s| s.blew_up()).map(|s| s.name.as_str()).collect();
    eprintln!(
        "runs done in {wall:.0} s ({:.2} core-hours of runs){}",
        run_time / 3600.0,
        if failed.is_empty() { String::new() } else { format!("; unstable, stopped early: {}", failed.join(", ")) }
    );
    Ok(())
}

fn submit(plan: &Plan, o: &FiguresOptions, speed: &Speed) -> Result<(), RunError> {
    if o.stage != Stage::All || o.shard.is_some() {
        return Err("--slurm submits the whole plan: it takes neither --stage nor --shard".into());
    }
    // The jobs may start in another directory: every path they see is absolute.
    let out = std::path::absolute(&o.out).map_err(|e| format!("--out {}: {e}", o.out.display()))?;
    // `#SBATCH --output=…` takes no quotes: a space ends the option, Slurm expands `%`, and a
    // newline would make the rest of the path a command.
    for (what, text) in [("--out", out.display().to_string()), ("--partition", o.partition.clone().unwrap_or_default())]
    {
        if let Some(c) = text.chars().find(|c| c.is_whitespace() || c.is_control() || "%\"'\\$`".contains(*c)) {
            return Err(RunError::Message(format!(
                "{what} {text:?}: holds {c:?}, which an #SBATCH line cannot hold (spaces, %, quotes, $, `, \\ and \
                 control characters): choose one without"
            )));
        }
    }
    let binary = std::env::current_exe().map_err(|e| format!("the path of this program: {e}"))?;
    let all: Vec<&Job> = plan.jobs.iter().collect();
    let total = speed.core_seconds(&all, Path::new("/nonexistent"));
    let longest =
        all.iter().map(|j| speed.core_seconds(std::slice::from_ref(j), Path::new("/nonexistent"))).fold(0.0, f64::max);
    let opts = SlurmOptions {
        throttle: o.throttle,
        partition: o.partition.clone(),
        binary,
        only: o.only.clone(),
        longest_run_seconds: longest,
        total_seconds: total,
    };
    eprintln!(
        "  estimate: {:.2} core-hours in all, the longest run {}; {} array task(s), {} at a time",
        total / 3600.0,
        hours(longest),
        slurm::array_tasks(plan),
        o.throttle
    );
    if o.dry_run {
        let (runs, figures, submit) = slurm::scripts(plan, &out, &opts);
        println!("# ---- {}/slurm/runs.sbatch\n{runs}", out.display());
        println!("# ---- {}/slurm/figures.sbatch\n{figures}", out.display());
        println!("# ---- {}/slurm/submit.sh\n{submit}", out.display());
        eprintln!("dry run: nothing written or submitted");
        return Ok(());
    }
    for path in slurm::write_scripts(plan, &out, &opts)? {
        println!("{}", path.display());
    }
    let (runs, figures) = slurm::submit(&out)?;
    eprintln!(
        "submitted: job array {runs} (runs), job {figures} (figures, after the array succeeds); \
         `squeue -j {runs},{figures}` to watch; logs in {}/slurm/; figures.md appears in {} at the end",
        out.display(),
        out.display()
    );
    println!("runs_job_id={runs}\nfigures_job_id={figures}");
    Ok(())
}

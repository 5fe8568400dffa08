//! `monolayer figures`: the paper's figures from one plan of runs (docs/cli.md, "figures"), in
//! five stages, a file each, each taking the previous stage's output and returning its own:
//!
//! 1. `plan`: the runs every figure needs, their union, each figure's points ([`Plan`]);
//! 2. `runs`: the estimate ([`Speed`]), then the runs through the sweep machinery (or, with
//!    `--slurm`, as a job array: `slurm`); hands on the finished runs with their records (`Runs`);
//! 3. `measures`: every run measured once (`Measures`);
//! 4. `draw`: `plan.csv` and each figure as PNG and SVG beside a CSV of exactly what is drawn
//!    (`Drawn`; the plots themselves in `plot`);
//! 5. `report`: `OUT/figures.md`, each figure beside what the paper says.
//!
//! This file is the command that runs them in order: `--stage runs` stops after the runs,
//! `--stage figures` starts from runs that must all be there. The stages' modules are private;
//! the plan's types, the estimate and the command are re-exported here.

mod draw;
mod measures;
mod plan;
mod plot;
mod report;
mod runs;
mod slurm;

use std::path::{Path, PathBuf};
use std::time::Instant;

pub use plan::{
    Figure, Friction, Plan, Point, PointSelection, Scale, ScaleSpec, S1_BOX, S1_INITIAL_GAP, UNSTATED_ZETA,
};
pub use runs::Speed;

use crate::run::error::RunError;
use crate::run::sweep::{Job, Shard};

/// What `figures` does.
#[derive(Clone, Copy, Debug, PartialEq, Eq, clap::ValueEnum)]
pub enum Stage {
    /// The runs, then the figures.
    All,
    /// Only the runs (a Slurm array task).
    Runs,
    /// Only the figures, from runs that must all be there (the Slurm aggregation job).
    Figures,
}

/// What the command line asked for.
#[derive(Clone, Debug)]
pub struct FiguresOptions {
    pub out: PathBuf,
    pub scale: Scale,
    /// `--only` as given.
    pub only: Option<String>,
    pub sets: Vec<String>,
    /// `--point` as given: only the plan's points one of these matches.
    pub points: Vec<String>,
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

/// Runs `monolayer figures`; the files written are printed, the rest goes to stderr.
pub fn figures(o: &FiguresOptions) -> Result<(), RunError> {
    let figures = match &o.only {
        Some(list) => Figure::parse_list(list)?,
        None => Figure::ALL.to_vec(),
    };
    if o.jobs == 0 {
        return Err(RunError::invalid("--jobs", 0, "≥ 1"));
    }
    // 1. The plan.
    let plan = Plan::new(o.scale, &figures, &o.sets, &o.points)?;
    if !o.dry_run {
        crate::run::files::remove_dead_temporaries(&o.out);
    }
    if o.stage == Stage::Figures {
        return draw_figures(&plan, &o.out, o.jobs);
    }
    // 2. The runs: what they will cost, then here or on Slurm.
    let share = runs::Share::of(&plan, &o.out, o.shard);
    // On Slurm each task runs one; here `--jobs` at a time.
    runs::check_memory(&plan, &share, if o.slurm { 1 } else { o.jobs })?;
    note_plan(o, &figures, &plan, &share);
    // The longest run and the whole plan, for the estimate and for Slurm's time limits.
    let sample: Vec<&Job> = if share.todo.is_empty() && !o.slurm { Vec::new() } else { plan.jobs.iter().collect() };
    let speed = Speed::measure(&sample, 100, 30)?;
    for ((l, n), (r, a)) in &speed.sizes {
        crate::run::console::note(format_args!(
            "  measured on one thread at L = {l}, N = {n}: {r:.2} ms/step relaxing, {a:.2} ms/step active (χ = 0.001)"
        ));
    }
    if o.slurm {
        return submit_to_slurm(o, &plan, &speed);
    }
    if !may_run_here(o, &share, &speed)? {
        return Ok(());
    }
    if !share.todo.is_empty() {
        runs::execute(&plan, &share, &o.out, o.jobs, o.quiet)?;
    }
    if let Some((name, _)) = crate::run::runner::stop_signal() {
        return Err(RunError::Interrupted {
            signal: name,
            detail: ": the same command again continues the runs from their checkpoints".into(),
        });
    }
    if o.stage == Stage::All {
        draw_figures(&plan, &o.out, o.jobs)?;
    }
    Ok(())
}

/// The plan in a line: its figures, its runs, this shard's share, and the steps to run.
fn note_plan(o: &FiguresOptions, figures: &[Figure], plan: &Plan, share: &runs::Share) {
    let ids: Vec<&str> = figures.iter().map(|f| f.id()).collect();
    crate::run::console::note(format_args!(
        "figures (scale {}): {} need {} runs{}; {} to run, {} steps",
        o.scale.name(),
        ids.join(", "),
        plan.jobs.len(),
        o.shard.map(|s| format!(" ({} in shard {}/{})", share.mine.len(), s.index, s.count)).unwrap_or_default(),
        share.todo.len(),
        share.steps()
    ));
}

/// The whole plan as a Slurm job array (`--slurm`), which takes neither `--stage` nor `--shard`.
fn submit_to_slurm(o: &FiguresOptions, plan: &Plan, speed: &Speed) -> Result<(), RunError> {
    if o.stage != Stage::All || o.shard.is_some() {
        return Err(RunError::Options("--slurm submits the whole plan: it takes neither --stage nor --shard".into()));
    }
    let request = slurm::SlurmRequest {
        out: &o.out,
        only: o.only.as_deref(),
        throttle: o.throttle,
        partition: o.partition.as_deref(),
        dry_run: o.dry_run,
    };
    slurm::run_on_slurm(plan, &request, speed)
}

/// The estimate of the runs here; whether they may run: not in a dry run (false), and the
/// evidence and paper scales only with `--yes` or as a shard (an error that says so).
fn may_run_here(o: &FiguresOptions, share: &runs::Share, speed: &Speed) -> Result<bool, RunError> {
    let core_seconds = share.core_seconds(speed);
    let workers = o.jobs.min(share.todo.len().max(1));
    if !share.todo.is_empty() {
        crate::run::console::note(format_args!(
            "  estimate: {:.2} core-hours, about {} on {} core(s) (measured before the tissue is confluent: runs with holes cost more)",
            core_seconds / 3600.0,
            runs::hours(core_seconds / workers as f64),
            workers
        ));
    }
    if o.dry_run {
        crate::run::console::note(format_args!("dry run: nothing run or written"));
        return Ok(false);
    }
    // A shard is a Slurm array task's share of the plan: only the whole plan here is refused.
    if matches!(o.scale, Scale::Paper | Scale::Evidence) && !o.yes && o.shard.is_none() && !share.todo.is_empty() {
        return Err(RunError::Options(format!(
            "--scale {} runs {} simulations here, about {} on {} core(s): refused without --yes; \
             on a cluster, --slurm submits them as a job array (--slurm --dry-run prints the scripts)",
            o.scale.name(),
            share.todo.len(),
            runs::hours(core_seconds / workers as f64),
            workers
        )));
    }
    Ok(true)
}

/// Stages 2 (the runs, all finished) to 5 from the runs in `out/runs`: the figures, their CSVs,
/// `plan.csv` and `figures.md` into `out` as one set (a full disk or a signal leaves the previous
/// set as it was), each file's path printed. SIGTERM or SIGINT stops it between runs measured and
/// before the set is moved in.
fn draw_figures(plan: &Plan, out: &Path, workers: usize) -> Result<(), RunError> {
    let t = Instant::now();
    crate::run::files::check_output_dir("--out", out)?;
    let finished = runs::finished(plan, out)?;
    let measured = measures::measure(finished, workers)?;
    let files = crate::run::files::write_set(
        out,
        |_| false,
        |stage| {
            let drawn = draw::draw(measured, stage)?;
            let md = report::write(&drawn, stage)?;
            stop_if_signalled()?;
            Ok(drawn.files.into_iter().chain([md]).collect())
        },
    )?;
    for path in &files {
        crate::run::console::out(path.display())?;
    }
    crate::run::console::note(format!(
        "figures drawn in {:.1} s: {}",
        t.elapsed().as_secs_f64(),
        out.join("figures.md").display()
    ));
    Ok(())
}

/// The error of a stop asked for by SIGTERM or SIGINT while the figures are drawn: nothing is
/// moved into place, and the same command again draws them.
pub(crate) fn stop_if_signalled() -> Result<(), RunError> {
    match crate::run::runner::stop_signal() {
        Some((signal, _)) => Err(RunError::Interrupted {
            signal,
            detail: ": no figure was written; the same command again draws them".into(),
        }),
        None => Ok(()),
    }
}

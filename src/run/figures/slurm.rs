//! `monolayer figures --slurm`: the plan as two sbatch scripts a user can read and edit, a job
//! array over the runs (throttled with `%N`, one output file per task) and an aggregation job that
//! starts after the whole array succeeded (`afterok`) and draws the figures; and their submission.
//!
//! Each array task runs its share of the runs through the same sweep machinery as a local
//! `figures`, one run at a time on one thread, so the cluster's runs are the same bits as a
//! laptop's and the aggregation writes the same CSVs.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};
use std::process::Command;

use super::plan::Plan;
use super::runs::{hours, Speed};
use crate::run::error::RunError;
use crate::run::files::write_text;
use crate::run::sweep::Job;

/// What `--slurm` was given besides the plan.
#[derive(Clone, Debug)]
pub struct SlurmRequest<'a> {
    /// `--out` as given.
    pub out: &'a Path,
    /// `--only` as given, passed on.
    pub only: Option<&'a str>,
    pub throttle: usize,
    pub partition: Option<&'a str>,
    pub dry_run: bool,
}

/// `monolayer figures --slurm`: the plan's runs and the figures as Slurm jobs, with time limits
/// from the estimate `speed`; with `dry_run` the scripts are printed, else written and submitted.
pub fn run_on_slurm(plan: &Plan, r: &SlurmRequest, speed: &Speed) -> Result<(), RunError> {
    // The jobs may start in another directory: every path they see is absolute.
    let out = std::path::absolute(r.out).map_err(|e| RunError::OptionPath {
        name: "--out",
        path: r.out.to_path_buf(),
        source: e,
    })?;
    // `#SBATCH --output=…` takes no quotes: a space ends the option, Slurm expands `%`, and a
    // newline would make the rest of the path a command.
    for (what, text) in
        [("--out", out.display().to_string()), ("--partition", r.partition.unwrap_or_default().to_string())]
    {
        if let Some(c) = text.chars().find(|c| c.is_whitespace() || c.is_control() || "%\"'\\$`".contains(*c)) {
            return Err(RunError::Options(format!(
                "{what} {text:?}: holds {c:?}, which an #SBATCH line cannot hold (spaces, %, quotes, $, `, \\ and \
                 control characters): choose one without"
            )));
        }
    }
    let binary = std::env::current_exe().map_err(RunError::CurrentExe)?;
    // Every run from its start: the cluster runs the whole plan.
    let whole = |j: &Job| speed.core_seconds(j, j.params.total_steps());
    let total: f64 = plan.jobs.iter().map(whole).sum();
    let longest = plan.jobs.iter().map(whole).fold(0.0, f64::max);
    let opts = SlurmOptions {
        throttle: r.throttle,
        partition: r.partition.map(str::to_string),
        binary,
        only: r.only.map(str::to_string),
        longest_run_seconds: longest,
        total_seconds: total,
    };
    crate::run::console::note(format_args!(
        "  estimate: {:.2} core-hours in all, the longest run {}; {} array task(s), {} at a time",
        total / 3600.0,
        hours(longest),
        array_tasks(plan),
        r.throttle
    ));
    if r.dry_run {
        let (runs, figures, submit) = scripts(plan, &out, &opts);
        crate::run::console::out(format_args!("# ---- {}/slurm/runs.sbatch\n{runs}", out.display()))?;
        crate::run::console::out(format_args!("# ---- {}/slurm/figures.sbatch\n{figures}", out.display()))?;
        crate::run::console::out(format_args!("# ---- {}/slurm/submit.sh\n{submit}", out.display()))?;
        crate::run::console::note(format_args!("dry run: nothing written or submitted"));
        return Ok(());
    }
    for path in write_scripts(plan, &out, &opts)? {
        crate::run::console::out(format_args!("{}", path.display()))?;
    }
    let (runs, figures) = submit(&out)?;
    crate::run::console::note(format_args!(
        "submitted: job array {runs} (runs), job {figures} (figures, after the array succeeds); \
         `squeue -j {runs},{figures}` to watch; logs in {}/slurm/; figures.md appears in {} at the end",
        out.display(),
        out.display()
    ));
    crate::run::console::out(format_args!("runs_job_id={runs}\nfigures_job_id={figures}"))?;
    Ok(())
}

/// Slurm's default MaxArraySize is 1001 (indices 0–1000): more runs than that share tasks.
pub const MAX_ARRAY_TASKS: usize = 1000;

#[derive(Clone, Debug)]
pub struct SlurmOptions {
    /// Array tasks running at once (`--array=0-N%throttle`).
    pub throttle: usize,
    pub partition: Option<String>,
    /// The `monolayer` binary the jobs run (absolute).
    pub binary: PathBuf,
    /// `--only` as given, passed on.
    pub only: Option<String>,
    /// Estimated seconds of the longest run: the tasks' time limit is set from it.
    pub longest_run_seconds: f64,
    /// Estimated seconds of the whole plan on one core (the aggregation's limit is a share).
    pub total_seconds: f64,
}

/// A word for bash, single-quoted where needed.
pub fn quote(s: &str) -> String {
    if !s.is_empty() && s.chars().all(|c| c.is_ascii_alphanumeric() || "-_./=:,+@%".contains(c)) {
        s.to_string()
    } else {
        format!("'{}'", s.replace('\'', r"'\''"))
    }
}

/// `D-HH:MM:SS` for `--time`.
fn slurm_time(seconds: f64) -> String {
    let s = seconds.ceil().max(60.0) as u64;
    format!("{}-{:02}:{:02}:{:02}", s / 86400, (s % 86400) / 3600, (s % 3600) / 60, s % 60)
}

/// The array's size: one task per run up to Slurm's default limit.
pub fn array_tasks(plan: &Plan) -> usize {
    plan.jobs.len().clamp(1, MAX_ARRAY_TASKS)
}

/// The arguments every job passes to `monolayer figures` besides its stage.
fn common_args(plan: &Plan, out: &Path, o: &SlurmOptions) -> String {
    let mut a = format!(
        "{} figures --scale {} --out {}",
        quote(&o.binary.display().to_string()),
        plan.scale.name(),
        quote(&out.display().to_string())
    );
    if let Some(only) = &o.only {
        let _ = write!(a, " --only {}", quote(only));
    }
    for s in &plan.sets {
        let _ = write!(a, " --set {}", quote(s));
    }
    for p in &plan.selected {
        let _ = write!(a, " --point {}", quote(p));
    }
    a
}

/// (`runs.sbatch`, `figures.sbatch`, `submit.sh`) for the plan with its output in `out`
/// (absolute: the jobs may start anywhere).
pub fn scripts(plan: &Plan, out: &Path, o: &SlurmOptions) -> (String, String, String) {
    let tasks = array_tasks(plan);
    let per_task = plan.jobs.len().div_ceil(tasks);
    let logs = out.join("slurm");
    let partition = o.partition.as_ref().map(|p| format!("#SBATCH --partition={p}\n")).unwrap_or_default();
    let common = common_args(plan, out, o);
    let runs = format!(
        "#!/bin/bash\n\
         # monolayer figures, scale `{scale}`: the {n} runs of the plan as a job array, {share}\n\
         # on one core. Edit freely (partition, account, the %N throttle, time);\n\
         # `bash submit.sh` submits this and figures.sbatch.\n\
         # A task that is killed resumes its run from the last checkpoint when run again.\n\
         #SBATCH --job-name=monolayer-runs\n\
         #SBATCH --array=0-{last}%{throttle}\n\
         #SBATCH --ntasks=1\n\
         #SBATCH --cpus-per-task=1\n\
         #SBATCH --time={time}\n\
         #SBATCH --output={logs}/run-%A_%a.out\n\
         {partition}\
         set -euo pipefail\n\
         exec {common} --stage runs --shard \"${{SLURM_ARRAY_TASK_ID}}/{tasks}\" --jobs 1 --quiet\n",
        scale = plan.scale.name(),
        n = plan.jobs.len(),
        share = if per_task == 1 {
            "one run per task".to_string()
        } else {
            format!(
                "task K running runs K, K + {tasks}, K + {}, … ({per_task} at most), one after the other",
                2 * tasks
            )
        },
        last = tasks - 1,
        throttle = o.throttle.max(1),
        // Twice the estimate (it is measured before the tissue is confluent) and ten minutes more.
        time = slurm_time(per_task as f64 * o.longest_run_seconds * 2.0 + 600.0),
        logs = logs.display(),
    );
    // Measuring every frame of every run costs about 1 % of running them; two cores, which every
    // node has, halve it.
    let figures = format!(
        "#!/bin/bash\n\
         # monolayer figures, scale `{scale}`: draws the figures, their CSVs and figures.md into\n\
         # {out} once every run is done (submit.sh starts it with --dependency=afterok on the array).\n\
         #SBATCH --job-name=monolayer-figures\n\
         #SBATCH --ntasks=1\n\
         #SBATCH --cpus-per-task=2\n\
         #SBATCH --time={time}\n\
         #SBATCH --output={logs}/figures-%j.out\n\
         {partition}\
         set -euo pipefail\n\
         exec {common} --stage figures --jobs \"${{SLURM_CPUS_PER_TASK:-1}}\"\n",
        scale = plan.scale.name(),
        out = out.display(),
        time = slurm_time(o.total_seconds * 0.01 + 1800.0),
        logs = logs.display(),
    );
    let submit = "#!/bin/bash\n\
         # Submits the runs' job array, then the figures job to start when every task has succeeded.\n\
         set -euo pipefail\n\
         cd \"$(dirname \"$0\")\"\n\
         runs=$(sbatch --parsable runs.sbatch)\n\
         runs=${runs%%;*}\n\
         figures=$(sbatch --parsable --dependency=afterok:\"$runs\" figures.sbatch)\n\
         figures=${figures%%;*}\n\
         echo \"runs: job array $runs; figures: job $figures (after the array succeeds)\"\n"
        .to_string();
    (runs, figures, submit)
}

/// Writes the scripts into `out/slurm/`; returns their paths.
pub fn write_scripts(plan: &Plan, out: &Path, o: &SlurmOptions) -> Result<Vec<PathBuf>, RunError> {
    let dir = out.join("slurm");
    std::fs::create_dir_all(&dir).map_err(|e| RunError::io(&dir, e))?;
    let (runs, figures, submit) = scripts(plan, out, o);
    let mut written = Vec::new();
    for (name, text) in [("runs.sbatch", runs), ("figures.sbatch", figures), ("submit.sh", submit)] {
        let path = dir.join(name);
        write_text(&path, &text)?;
        written.push(path);
    }
    Ok(written)
}

/// Submits the array, then the figures job depending on it; returns their job ids.
pub fn submit(out: &Path) -> Result<(String, String), RunError> {
    let dir = out.join("slurm");
    let sbatch = |args: &[&str]| -> Result<String, RunError> {
        let o = Command::new("sbatch").args(args).current_dir(&dir).output().map_err(|e| {
            RunError::Slurm(format!(
                "sbatch: {e} (is this a Slurm login node? --dry-run prints the scripts without submitting)"
            ))
        })?;
        if !o.status.success() {
            return Err(RunError::Slurm(format!(
                "sbatch {}: {}",
                args.join(" "),
                String::from_utf8_lossy(&o.stderr).trim()
            )));
        }
        let id = String::from_utf8_lossy(&o.stdout).trim().to_string();
        // --parsable prints `id` or `id;cluster`.
        Ok(id.split(';').next().unwrap_or("").to_string())
    };
    let runs = sbatch(&["--parsable", "runs.sbatch"])?;
    let figures = sbatch(&["--parsable", &format!("--dependency=afterok:{runs}"), "figures.sbatch"])?;
    Ok((runs, figures))
}

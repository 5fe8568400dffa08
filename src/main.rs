//! `monolayer`, the command line: parses the arguments and hands each command to the library
//! (`monolayer::run`): run and resume, branch, sweep, figures, analyze, forecast, intervene, bench,
//! params, fingerprint, relaxed-state.

use std::io::Write;
use std::path::PathBuf;
use std::process::ExitCode;
use std::time::Instant;

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use monolayer::formats::{snapshot, Engine};
use monolayer::model::{number_text, Perturbation, MAX_STEPS};
use monolayer::run::figures::{FiguresOptions, Scale, Stage};
use monolayer::run::{
    analyze_run, bench_analysis, check_frame_interval, check_memory, check_memory_of, create_branch, load_params,
    load_params_over, note, out, out_text, parse_assignment, replaceable, stop_gracefully_on_signals, stop_signal,
    write_atomic, Arm, Background, BenchOptions, BranchOptions, Event, InterveneOptions, Report, RunDir, RunError,
    Shard, SweepOptions,
};
use monolayer::{Monolayer, Params, Phase};

#[derive(Parser)]
#[command(version, about = "Active-nematic multi-phase-field monolayers that tear open (Pinto, Rozman & Yeomans)")]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Subcommand)]
enum Command {
    /// Run the protocol: relaxation, then activity with cell–cell friction; frames to --out.
    Run(RunArgs),
    /// Milliseconds per step at full size for χ = 0.1 and χ = 0.001 (ζ = 0.5), stage by stage.
    Bench(BenchArgs),
    /// Print the default parameters as a TOML config file.
    Params,
    /// Step from the random disks and print the state's fingerprint as JSON (to compare the
    /// WebAssembly core with this one, bit for bit).
    Fingerprint(FingerprintArgs),
    /// Relax a tissue from the random disks (the protocol's relaxation) and write the confluent
    /// state as a snapshot the browser demo starts from (www/assets/); with --advance, the state
    /// that many active steps later (the page's paper tissue, a short time before a hole).
    RelaxedState(RelaxedStateArgs),
    /// Run a grid of parameters (χ, ζ, γ, any parameter, seeds), one simulation per core,
    /// resumable; summary.csv and the regime map.
    Sweep(SweepArgs),
    /// Measure a run's frames: holes, defects, spiral cores, strain rate, correlations; tables
    /// and plots to DIR/analysis. With --bench: time the measurements at full size.
    Analyze(AnalyzeArgs),
    /// The paper's figures (1c, 1d, 2, 3a–d, S1–S3) from one plan of runs, each as PNG and SVG
    /// beside its CSV, and DIR/figures.md; here (one run per core, resumable) or with --slurm as a
    /// job array and an aggregation job. See docs/cli.md, "figures".
    Figures(FiguresArgs),
    /// Do holes come from collective motion or from a tissue that thinned first? For runs of
    /// several seeds: each nucleation's thinning, the precursors against sites of the same
    /// thinning, and a forecast of where a hole opens next (strain rate, spiral core, thinning,
    /// and their combination) scored on each seed's runs with the combination fitted on the other
    /// seeds. Tables and the ROC figure to --out (docs/figures.md, "Forecast").
    Forecast(ForecastArgs),
    /// Start a new run from a run's exact state at one of its frames and step it with
    /// parameters changed (--set) and φ perturbed (--perturb, for replicas). With no change it
    /// continues the parent's trajectory bit for bit. See docs/cli.md, "branch".
    Branch(BranchArgs),
    /// Does a tissue still tear with its motion switched off? For every nucleation of the runs
    /// and each lead k, the parent's state k frames before is branched with activity off,
    /// halved, substrate friction ×10, flows made local (χ = 1), and into perturbed replicas;
    /// the share of branches that tear within R of the site (and of matched sites that thinned
    /// as much) with bootstrap intervals, tables and a figure to --out. Resumable. See
    /// docs/figures.md, "Intervention".
    Intervene(InterveneArgs),
}

#[derive(Args)]
struct InterveneArgs {
    /// Finished runs (CPU engine, ideally made with --keep-checkpoints), e.g. a sweep's OUT/runs/*.
    #[arg(required = true, value_name = "RUN_DIR")]
    runs: Vec<PathBuf>,
    /// Where the branches (OUT/branches/) and the tables and figure go.
    #[arg(long)]
    out: PathBuf,
    /// Frames before each nucleation at which branches start.
    #[arg(long, value_delimiter = ',', default_value = "1,2,3,5")]
    leads: Vec<usize>,
    /// Frames after the nucleation within which a branch's tear counts.
    #[arg(long, default_value_t = monolayer::analysis::AFTER)]
    after: usize,
    /// Perturbed replicas (the control) per branch point.
    #[arg(long, default_value_t = monolayer::analysis::REPLICAS)]
    replicas: usize,
    /// The arms, as a list (control must be one).
    #[arg(
        long,
        value_delimiter = ',',
        default_value = "control,activity-off,activity-halved,friction-x10,local-flows"
    )]
    arms: Vec<Arm>,
    /// Simulations at a time, one per core (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Print the plan and its cost in steps and core-hours (timed here); run and write nothing.
    #[arg(long)]
    dry_run: bool,
    /// Run nothing: score the branches that have ended and write the tables.
    #[arg(long, conflicts_with = "dry_run")]
    tables_only: bool,
    /// No progress bar.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args)]
struct BranchArgs {
    /// The parent run's directory (finished, on the CPU engine).
    #[arg(value_name = "RUN_DIR")]
    parent: PathBuf,
    /// The parent's step to start from: one at which it wrote a frame. Its state there is its
    /// kept checkpoint (`run --keep-checkpoints`) or is replayed from the latest state before it.
    #[arg(long, value_name = "STEP")]
    at: u64,
    /// A parameter changed from the parent's value, TOML syntax: --set zeta=0 (repeatable; `chi`
    /// sets xi_substrate = χ·xi_cell).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Steps to run from --at (default: to the parent's end).
    #[arg(long)]
    steps: Option<u64>,
    /// Steps between frames (default: the parent's).
    #[arg(long)]
    frame_interval: Option<u64>,
    /// Add seeded uniform noise to φ at the start (a replica): the generator's seed.
    #[arg(long, value_name = "SEED")]
    perturb: Option<u64>,
    /// The noise's amplitude (with --perturb).
    #[arg(long, default_value_t = 1e-6, requires = "perturb", value_name = "A")]
    perturb_amplitude: f64,
    /// The branch's directory (new or empty); `run --resume DIR` continues it like any run.
    #[arg(long)]
    out: PathBuf,
    /// Worker threads (results do not depend on it); default: all cores.
    #[arg(long)]
    threads: Option<usize>,
    /// No progress bar; a line per frame instead.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args)]
struct ForecastArgs {
    /// Run directories (as given to `run --out`, or a sweep's OUT/runs/*), at least two seeds.
    #[arg(required = true, value_name = "RUN_DIR")]
    dirs: Vec<PathBuf>,
    /// Where to write the tables and the figure.
    #[arg(long)]
    out: PathBuf,
    /// Also score runs that have not finished (their frames so far).
    #[arg(long)]
    partial: bool,
    /// No line per run read.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args)]
struct FiguresArgs {
    /// Output directory: the runs in DIR/runs/, the figures, plan.csv and figures.md in DIR.
    #[arg(long)]
    out: PathBuf,
    /// How many runs, how long, how large (`--dry-run` prints the plan and its cost, timed here).
    #[arg(long, default_value = "smoke")]
    scale: Scale,
    /// Only these figures and their runs: --only 1c,3d,S1 (1c, 1d, 2, 3ab, 3c, 3d, S1, S2, S3,
    /// mechanism).
    #[arg(long, value_name = "LIST")]
    only: Option<String>,
    /// A parameter for every run, over the scale's: --set q_magnitude=0.4.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Only the figures' points this matches, repeatable: --point chi=0.01,zeta=0.5 --point zeta=0.3
    /// (keys chi, zeta, gamma; a key not given matches any value; default: every point).
    #[arg(long = "point", value_name = "KEY=VALUE,…")]
    point: Vec<String>,
    /// Simulations at a time, one per core (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Run the whole `paper` or `evidence` scale on this machine (days or a day of core time: it
    /// is refused without this; a --shard, as a Slurm array task runs, is not).
    #[arg(long)]
    yes: bool,
    /// What to do of the plan.
    #[arg(long, default_value = "all")]
    stage: Stage,
    /// Run only every N-th run of the plan starting at K (K/N), as a Slurm array task does.
    #[arg(long, value_name = "K/N")]
    shard: Option<Shard>,
    /// No progress bar; a line per finished run.
    #[arg(long)]
    quiet: bool,
    /// Write DIR/slurm/{runs.sbatch, figures.sbatch, submit.sh} and submit them: a job array over
    /// the runs and the figures job after it (afterok).
    #[arg(long)]
    slurm: bool,
    /// Print the plan and its estimate (with --slurm, the scripts too); run, write and submit
    /// nothing.
    #[arg(long)]
    dry_run: bool,
    /// With --slurm: array tasks running at once (the %N of --array).
    #[arg(long, default_value_t = 16, requires = "slurm")]
    throttle: usize,
    /// With --slurm: the partition to submit to (default: the cluster's).
    #[arg(long, requires = "slurm")]
    partition: Option<String>,
}

#[derive(Args)]
struct AnalyzeArgs {
    /// The run's output directory (as given to `run --out`).
    #[arg(required_unless_present = "bench")]
    dir: Option<PathBuf>,
    /// Where to write the tables and plots (default: DIR/analysis).
    #[arg(long)]
    out: Option<PathBuf>,
    /// Step of the frame drawn in the snapshot (default: the first hole's nucleation, else the
    /// last frame).
    #[arg(long, value_name = "STEP")]
    snapshot: Option<u64>,
    /// Field coloured under the snapshot.
    #[arg(long, default_value = "strain-rate")]
    field: Background,
    /// Instead of a run: time the live measurements of one full-size frame, and `analyze` over
    /// --bench-frames full-size frames written to a temporary directory.
    #[arg(long, conflicts_with_all = ["dir", "out", "snapshot", "field"])]
    bench: bool,
    /// Frames analysed by --bench.
    #[arg(long, default_value_t = 100, requires = "bench")]
    bench_frames: u64,
}

#[derive(Args)]
struct FingerprintArgs {
    #[command(flatten)]
    params: ParamArgs,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Steps from the start of the protocol (relaxation included) before the fingerprint.
    #[arg(long)]
    total_steps: u64,
}

#[derive(Args)]
struct RelaxedStateArgs {
    #[command(flatten)]
    params: ParamArgs,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Active steps to run past the relaxation before saving (0: the end of the relaxation,
    /// which serves every activity and friction; later states continue only under exactly
    /// these parameters).
    #[arg(long, default_value_t = 0, value_parser = clap::value_parser!(u64).range(0..=MAX_STEPS))]
    advance: u64,
    /// The snapshot file to write (atomically).
    #[arg(long)]
    out: PathBuf,
}

#[derive(Args)]
struct ParamArgs {
    /// TOML file of parameters (names as printed by `monolayer params`); defaults fill the rest.
    #[arg(long)]
    config: Option<PathBuf>,
    /// Override one parameter, TOML syntax: --set zeta=0.4 --set passive_force=phi_grad_mu.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Friction ratio χ = ξ_s/ξ_cell (sets xi_substrate).
    #[arg(long)]
    chi: Option<f64>,
    /// Activity ζ.
    #[arg(long)]
    zeta: Option<f64>,
    /// Active steps after relaxation (the paper: 100000).
    #[arg(long)]
    steps: Option<u64>,
    /// Relaxation steps (the paper: 10000).
    #[arg(long)]
    relax_steps: Option<u64>,
}

/// Refuses a `--set` of a parameter that a flag sets too: whichever is applied last would win
/// unsaid. `flags` are (flag, the parameter it sets, its value where it is given).
fn refuse_flag_beside_set(sets: &[String], flags: &[(&str, &str, Option<String>)]) -> Result<(), RunError> {
    for s in sets {
        let (k, _) = parse_assignment("--set", s)?;
        if let Some((flag, _, Some(v))) = flags.iter().find(|f| f.1 == k && f.2.is_some()) {
            return Err(RunError::Options(format!(
                "{flag} {v} and --set {s} both set `{k}`{}: give one of them",
                if *flag == "--chi" { " (--chi sets xi_substrate = χ·xi_cell)" } else { "" }
            )));
        }
    }
    Ok(())
}

impl ParamArgs {
    fn params(&self) -> Result<Params, RunError> {
        refuse_flag_beside_set(
            &self.set,
            &[
                ("--chi", "xi_substrate", self.chi.map(|v| v.to_string())),
                ("--zeta", "zeta", self.zeta.map(|v| v.to_string())),
                ("--steps", "active_steps", self.steps.map(|v| v.to_string())),
                ("--relax-steps", "relax_steps", self.relax_steps.map(|v| v.to_string())),
            ],
        )?;
        let mut p = load_params(self.config.as_deref(), &self.set)?;
        if let Some(z) = self.zeta {
            p.zeta = z;
        }
        if let Some(c) = self.chi {
            if !(c.is_finite() && c > 0.0) {
                return Err(RunError::invalid("--chi", number_text(c), "a finite number > 0"));
            }
            p.set_chi(c);
        }
        if let Some(s) = self.steps {
            p.active_steps = s;
        }
        if let Some(s) = self.relax_steps {
            p.relax_steps = s;
        }
        p.validate()?;
        Ok(p)
    }
}

#[derive(Args)]
struct RunArgs {
    #[command(flatten)]
    params: ParamArgs,
    /// Random seed of the initial cell positions.
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Output directory (created; must not hold a run already).
    #[arg(long, default_value = "runs/default")]
    out: PathBuf,
    /// Steps between frames in the active phase (default 1000); at most the active steps.
    #[arg(long)]
    frame_interval: Option<u64>,
    /// Worker threads (results do not depend on it); default: all cores.
    #[arg(long)]
    threads: Option<usize>,
    /// Continue the run in this directory from its last checkpoint (with its own parameters,
    /// seed and frame interval, which no option changes).
    #[arg(
        long,
        value_name = "DIR",
        conflicts_with_all = ["out", "seed", "frame_interval", "config", "set", "chi", "zeta", "steps", "relax_steps"]
    )]
    resume: Option<PathBuf>,
    /// No progress bar (for batch jobs); a line per frame instead.
    #[arg(long)]
    quiet: bool,
    /// Analyse every frame as it is written (tables and plots in OUT/analysis, as `analyze`).
    #[arg(long)]
    analyze: bool,
    /// Keep every checkpoint (OUT/checkpoints/, one per frame, about 1 MB each at full size), not
    /// only the last: the states `monolayer branch` starts from without replaying the run.
    #[arg(long)]
    keep_checkpoints: bool,
    /// What steps the run: cpu (the reference, the same bits everywhere) or gpu (the GPU
    /// stepper in f32 on a Vulkan adapter; a build with --features gpu). A resumed run keeps
    /// the engine it started on (default: cpu for a new run).
    #[arg(long, value_parser = ["cpu", "gpu"])]
    engine: Option<String>,
}

#[derive(Args)]
struct SweepArgs {
    /// Sweep file (TOML: `seeds`, `frame_interval`, `[base]` parameters, `[grid]` lists); see
    /// docs/cli.md, "sweep". Without it, the grid comes from --grid.
    file: Option<PathBuf>,
    /// Output directory: one run per grid point and seed in OUT/runs/, summary.csv,
    /// regimes.csv and regime_map.png/svg in OUT.
    #[arg(long, default_value = "runs/sweep")]
    out: PathBuf,
    /// A grid axis: --grid chi=0.1,0.01,0.001 --grid zeta=0.3,0.5 (any parameter by name).
    #[arg(long = "grid", value_name = "KEY=V1,V2,..")]
    grid: Vec<String>,
    /// Run nothing: measure the runs already in OUT/runs (finished or part way) and write the
    /// tables and the regime map, which counts only the runs that ended. For a look at a sweep
    /// that is still running, or a map over runs made by several sweeps. Given no sweep (no FILE,
    /// --grid, --point, --set, --seeds or --frame-interval): every run in OUT/runs, with the
    /// parameters its run.json records.
    #[arg(long)]
    tables_only: bool,
    /// One point instead of a grid (repeatable; every point sets the same parameters):
    /// --point chi=0.1,zeta=0.5 --point chi=0.001,zeta=0.3. With --grid, each point takes its product.
    #[arg(long = "point", value_name = "K1=V1,K2=V2,..")]
    point: Vec<String>,
    /// A parameter for every run: --set active_steps=20000.
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Seeds (each grid point runs once per seed): --seeds 1,2,3.
    #[arg(long, value_delimiter = ',')]
    seeds: Option<Vec<u64>>,
    /// Steps between frames.
    #[arg(long)]
    frame_interval: Option<u64>,
    /// Every run keeps every checkpoint (as `run --keep-checkpoints`): the states `monolayer
    /// branch` starts from.
    #[arg(long)]
    keep_checkpoints: bool,
    /// Simulations at a time, one per core (default: all cores).
    #[arg(long)]
    jobs: Option<usize>,
    /// Run only every N-th job starting at K (K/N); under a Slurm job array it defaults to
    /// $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT.
    #[arg(long, value_name = "K/N")]
    shard: Option<Shard>,
    /// No progress bar; a line per finished run.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args)]
struct BenchArgs {
    /// Active steps timed per friction ratio (at most 10⁹).
    #[arg(long, default_value_t = 200)]
    steps: u64,
    /// Relaxation steps before timing (a confluent tissue).
    #[arg(long, default_value_t = 3000)]
    relax_steps: u64,
    /// Worker threads; a list (e.g. `1,2`) times each count on the same trajectory, block by
    /// block in turn, and reports the speed-ups over the first.
    #[arg(long, value_delimiter = ',', default_value = "1")]
    threads: Vec<usize>,
    /// Timed blocks per friction ratio: the steps are split into this many, so that the best
    /// and the median block can be told from the mean on a machine whose speed drifts.
    #[arg(long, default_value_t = 10)]
    blocks: u64,
    #[arg(long, default_value_t = 1)]
    seed: u64,
    /// Friction ratios χ = ξ_s/ξ_cell timed in turn.
    #[arg(long, value_delimiter = ',', default_value = "0.1,0.001")]
    chi: Vec<f64>,
    /// Activity of the timed steps (default 0.5).
    #[arg(long)]
    zeta: Option<f64>,
    /// Any other parameter, e.g. --set friction_weights=subdomain (repeatable).
    #[arg(long = "set", value_name = "KEY=VALUE")]
    set: Vec<String>,
    /// Start from this relaxed state (written by `relaxed-state`, e.g. the page's
    /// www/assets/relaxed-paper-seed1.bin) instead of relaxing: the steps the page times, on
    /// the same trajectory. Its parameters are --relax-steps, --seed and --set (checked against
    /// the file's key); the relaxation is then not timed.
    #[arg(long, value_name = "FILE")]
    from_relaxed: Option<std::path::PathBuf>,
    /// Time the GPU engine instead, on the adapter found (a build with --features gpu): its
    /// kernels, steps and runs, the laptop projection and the page's hand-off per row of
    /// readouts. Uses --relax-steps, --seed, --set and ζ; --steps is the number of timed
    /// dispatches per kernel.
    #[arg(long)]
    gpu: bool,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    // The commands that run simulations stop gracefully on SIGTERM and SIGINT.
    if matches!(
        cli.command,
        Command::Run(_) | Command::Sweep(_) | Command::Figures(_) | Command::Branch(_) | Command::Intervene(_)
    ) {
        if let Err(e) = stop_gracefully_on_signals() {
            note(format_args!("error: {e}"));
            return ExitCode::from(2);
        }
    }
    let result = match cli.command {
        Command::Run(a) => a
            .threads
            .map(|n| check_threads("--threads", n))
            .transpose()
            .and_then(|threads| with_threads(threads, || run(&a))),
        Command::Bench(a) => bench(&a),
        Command::Params => toml::to_string(&Params::default()).map_err(RunError::from).and_then(|s| out_text(&s)),
        Command::Fingerprint(a) => fingerprint(&a),
        Command::RelaxedState(a) => relaxed_state(&a),
        Command::Sweep(a) => sweep(&a),
        Command::Analyze(a) => with_threads(Some(1), || analyze(&a)),
        Command::Figures(a) => figures(a),
        Command::Forecast(a) => with_threads(Some(1), || forecast(&a)),
        Command::Intervene(a) => intervene(&a),
        Command::Branch(a) => a
            .threads
            .map(|n| check_threads("--threads", n))
            .transpose()
            .and_then(|threads| with_threads(threads, || branch(&a))),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            note(format_args!("error: {e}"));
            // 128 + the signal, as a shell reports a process the signal ended.
            match stop_signal() {
                Some((_, sig)) => ExitCode::from(128 + sig as u8),
                None => ExitCode::from(2),
            }
        }
    }
}

fn cores() -> usize {
    std::thread::available_parallelism().map(|n| n.get()).unwrap_or(1)
}

/// A count of threads or simulations at a time: at least 1, and at most 4 per core (results do
/// not depend on it, and past the cores more only share them).
fn check_threads(flag: &str, n: usize) -> Result<usize, RunError> {
    let max = 4 * cores();
    if n == 0 || n > max {
        return Err(RunError::invalid(flag, n, format!("in [1, {max}] (4 × the {} cores here)", cores())));
    }
    Ok(n)
}

fn with_threads(threads: Option<usize>, f: impl FnOnce() -> Result<(), RunError> + Send) -> Result<(), RunError> {
    match threads {
        None => f(),
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map_err(|e| RunError::from(e).context(format!("--threads {n}")))?
            .install(f),
    }
}

fn run(a: &RunArgs) -> Result<(), RunError> {
    let run = match &a.resume {
        Some(dir) => {
            let run = RunDir::resume(dir)?;
            note(format_args!("resuming {} at step {}", dir.display(), run.monolayer.step_count()));
            run
        }
        None => {
            let params = a.params.params()?;
            if let Some(fi) = a.frame_interval {
                check_frame_interval("--frame-interval", fi, &params)?;
            }
            RunDir::create(&a.out, params, a.seed, a.frame_interval.unwrap_or(1000))?
        }
    };
    let engine = match &a.engine {
        Some(e) => Engine::parse(e)?,
        None => Engine::parse(&run.record.engine)?,
    };
    let run = run.with_engine(engine)?;
    let mut run = if a.keep_checkpoints { run.keep_checkpoints()? } else { run };
    execute(&mut run, a.analyze, a.quiet)
}

/// Steps `run` to its end with a progress bar (or, `quiet`, a line per frame).
fn execute(run: &mut RunDir, analyze: bool, quiet: bool) -> Result<(), RunError> {
    let total = run.monolayer.params().total_steps();
    let bar = progress_bar(total, run.monolayer.step_count(), quiet);
    let (start, start_step) = (Instant::now(), run.monolayer.step_count());
    let outcome = run.execute(analyze, &mut |m, event| match event {
        Event::Step => {
            bar.set_message(match m.phase() {
                Phase::Relaxation => "relaxing",
                Phase::Active => "active",
            });
            // The GPU engine reports once per submission, the CPU once per step.
            bar.set_position(m.step_count());
        }
        Event::Frame if quiet => {
            let s = m.step_count();
            let rate = (s - start_step) as f64 / start.elapsed().as_secs_f64();
            note(format_args!("step {s}/{total}: frame written ({rate:.0} steps/s)"));
        }
        Event::Frame => {}
        Event::AnalysisFailed(e) if bar.is_hidden() => {
            note(format_args!("warning: analysis of step {}: {e}", m.step_count()))
        }
        Event::AnalysisFailed(e) => bar.println(format!("warning: analysis of step {}: {e}", m.step_count())),
    });
    match outcome {
        Ok(()) => {
            bar.finish();
            note(format_args!("done: {} steps in {}", run.monolayer.step_count(), run.dir.display()));
            Ok(())
        }
        Err(e) => {
            bar.abandon();
            Err(e)
        }
    }
}

/// `branch RUN_DIR --at STEP …`: the branch made (its parent's state replayed if need be), then
/// run to its end.
fn branch(a: &BranchArgs) -> Result<(), RunError> {
    let options = BranchOptions {
        parent: a.parent.clone(),
        at: a.at,
        sets: a.set.clone(),
        steps: a.steps,
        frame_interval: a.frame_interval,
        perturbation: a.perturb.map(|seed| Perturbation { seed, amplitude: a.perturb_amplitude }),
        out: a.out.clone(),
    };
    let replay = progress_bar(0, 0, a.quiet);
    replay.set_message("replaying");
    let made = Instant::now();
    let mut run = create_branch(&options, &mut |done, of| {
        replay.set_length(of);
        replay.set_position(done);
    })?;
    replay.finish_and_clear();
    let origin = run.record.branch.as_ref().expect("a branch records its origin");
    let changes: Vec<String> =
        origin.changes.iter().map(|c| format!("{} {} -> {}", c.key, c.parent, c.branch)).collect();
    note(format_args!(
        "branch of {} at step {} ({}, made in {:.0} ms); {}{}; to step {} in {}",
        origin.parent,
        origin.step,
        origin.source,
        made.elapsed().as_secs_f64() * 1e3,
        if changes.is_empty() { "no change".to_string() } else { changes.join(", ") },
        origin
            .perturbation
            .map(|p| format!(", φ perturbed (seed {}, amplitude {:e})", p.seed, p.amplitude))
            .unwrap_or_default(),
        run.monolayer.params().total_steps(),
        run.dir.display()
    ));
    execute(&mut run, false, a.quiet)
}

fn progress_bar(total: u64, done: u64, quiet: bool) -> ProgressBar {
    if quiet {
        return ProgressBar::hidden();
    }
    let bar = ProgressBar::new(total);
    bar.set_style(
        ProgressStyle::with_template("{msg:>10} [{bar:40}] {pos}/{len} steps  {per_sec}  ETA {eta}")
            .expect("template")
            .progress_chars("=> "),
    );
    bar.set_position(done);
    bar.reset_eta();
    bar
}

fn sweep(a: &SweepArgs) -> Result<(), RunError> {
    let options = SweepOptions {
        file: a.file.clone(),
        out: a.out.clone(),
        grid: a.grid.clone(),
        points: a.point.clone(),
        sets: a.set.clone(),
        seeds: a.seeds.clone(),
        frame_interval: a.frame_interval,
        keep_checkpoints: a.keep_checkpoints,
        tables_only: a.tables_only,
        jobs: match a.jobs {
            Some(n) => check_threads("--jobs", n)?,
            None => cores(),
        },
        shard: match a.shard {
            Some(s) => Some(s),
            None => Shard::of_slurm_array()?,
        },
    };
    let bar = progress_bar(0, 0, a.quiet || a.tables_only);
    let start = Instant::now();
    let reported = std::sync::atomic::AtomicUsize::new(0);
    let written = monolayer::run::sweep(&options, &|r| match r {
        Report::Progress { done, runs, .. }
            if a.quiet && reported.fetch_max(done, std::sync::atomic::Ordering::Relaxed) < done =>
        {
            note(format_args!("{done}/{runs} runs done, {:.0} s", start.elapsed().as_secs_f64()))
        }
        other => show(&bar, other, "runs"),
    });
    bar.finish_and_clear();
    for path in written? {
        out(path.display())?;
    }
    Ok(())
}

/// Shows a long command's report: a line above the bar (or alone), its progress on the bar.
fn show(bar: &ProgressBar, report: Report, what: &str) {
    match report {
        Report::Line(line) if bar.is_hidden() => note(line),
        Report::Line(line) => bar.println(line),
        Report::Progress { steps, of, done, runs } => {
            bar.set_length(of);
            bar.set_position(steps);
            bar.set_message(format!("{what} {done}/{runs}"));
        }
    }
}

fn figures(a: FiguresArgs) -> Result<(), RunError> {
    if a.throttle == 0 {
        return Err(RunError::invalid("--throttle", 0, "≥ 1"));
    }
    monolayer::run::figures::figures(&FiguresOptions {
        out: a.out,
        scale: a.scale,
        only: a.only,
        sets: a.set,
        points: a.point,
        jobs: match a.jobs {
            Some(n) => check_threads("--jobs", n)?,
            None => cores(),
        },
        yes: a.yes,
        stage: a.stage,
        shard: a.shard,
        quiet: a.quiet,
        slurm: a.slurm,
        dry_run: a.dry_run,
        throttle: a.throttle,
        partition: a.partition,
    })
}

fn fingerprint(a: &FingerprintArgs) -> Result<(), RunError> {
    if a.total_steps > MAX_STEPS {
        return Err(RunError::invalid(
            "--total-steps",
            a.total_steps,
            format!("in [0, {}] (relaxation included)", MAX_STEPS),
        ));
    }
    let params = a.params.params()?;
    params.validate()?;
    check_memory(&params)?;
    let mut m = Monolayer::new(params, a.seed)?;
    m.advance(a.total_steps)?;
    out(format_args!("{{\"step\": {}, \"fingerprint\": \"{:016x}\"}}", m.step_count(), m.fingerprint()))?;
    Ok(())
}

fn relaxed_state(a: &RelaxedStateArgs) -> Result<(), RunError> {
    // Before the relaxation, which may take long: the write would refuse it at the end.
    replaceable(&a.out)?;
    let params = a.params.params()?;
    check_memory(&params)?;
    let steps = params.relax_steps + a.advance;
    let key = snapshot::key_at(&params, a.seed, steps).expect("at or past the end of the relaxation");
    let mut m = Monolayer::new(params, a.seed)?;
    let bar = progress_bar(steps, 0, false);
    bar.set_message("relaxing");
    for _ in 0..steps {
        if m.step_count() == m.params().relax_steps {
            bar.set_message("active");
        }
        let step = m.step_count();
        m.step().map_err(|e| RunError::from(e).context(format!("at step {step}")))?;
        bar.inc(1);
    }
    bar.finish_and_clear();
    let bytes = snapshot::encode(&m.state(), key);
    write_atomic(&a.out, |w| w.write_all(&bytes).map_err(|e| RunError::io(&a.out, e)))?;
    note(format_args!(
        "{}: step {steps}, {} cells, {} bytes, key {key:016x}, fingerprint {:016x}",
        a.out.display(),
        m.cells().len(),
        bytes.len(),
        m.fingerprint()
    ));
    Ok(())
}

fn bench(a: &BenchArgs) -> Result<(), RunError> {
    if a.threads.is_empty() {
        return Err(RunError::Parse("--threads: give at least one count".into()));
    }
    for &n in &a.threads {
        check_threads("--threads", n)?;
    }
    // Bounded as every other step count is.
    if a.steps == 0 || a.steps > MAX_STEPS {
        return Err(RunError::invalid("--steps", a.steps, format!("in [1, {MAX_STEPS}]")));
    }
    // `--chi` and `--relax-steps` set their parameters whether given or not (their defaults).
    let chis: Vec<String> = a.chi.iter().map(|c| number_text(*c)).collect();
    refuse_flag_beside_set(
        &a.set,
        &[
            ("--zeta", "zeta", a.zeta.map(number_text)),
            ("--chi", "xi_substrate", Some(chis.join(","))),
            ("--relax-steps", "relax_steps", Some(a.relax_steps.to_string())),
        ],
    )?;
    let params = load_params_over(&[format!("zeta={}", a.zeta.unwrap_or(0.5))], &a.set)?;
    Params { relax_steps: a.relax_steps, ..params.clone() }.validate()?;
    // The relaxed state, a copy per thread count timed, and two more for the ceiling.
    let ceiling = a.threads.contains(&1) && a.threads.contains(&2);
    let copies = if a.gpu { 1 } else { 1 + a.threads.len() as u64 + if ceiling { 2 } else { 0 } };
    check_memory_of(&params, copies)?;
    if a.gpu {
        return bench_gpu(&params, a);
    }
    let options = BenchOptions {
        params,
        chis: a.chi.clone(),
        steps: a.steps,
        relax_steps: a.relax_steps,
        threads: a.threads.clone(),
        blocks: a.blocks,
        seed: a.seed,
        from_relaxed: a.from_relaxed.clone(),
    };
    monolayer::run::bench(&options)
}

#[cfg(feature = "gpu")]
fn bench_gpu(params: &Params, a: &BenchArgs) -> Result<(), RunError> {
    monolayer::run::bench_gpu(params, a.relax_steps, a.seed, a.steps as usize, monolayer::web::ROW_EVERY)
}

#[cfg(not(feature = "gpu"))]
fn bench_gpu(_: &Params, _: &BenchArgs) -> Result<(), RunError> {
    Err(RunError::Gpu(
        "--gpu: this binary was built without the GPU kernels: cargo build --release --features gpu".into(),
    ))
}

/// `intervene RUN_DIR… --out OUT`.
fn intervene(a: &InterveneArgs) -> Result<(), RunError> {
    let options = InterveneOptions {
        runs: a.runs.clone(),
        out: a.out.clone(),
        leads: a.leads.clone(),
        after: a.after,
        replicas: a.replicas,
        arms: a.arms.clone(),
        jobs: match a.jobs {
            Some(n) => check_threads("--jobs", n)?,
            None => cores(),
        },
        dry_run: a.dry_run,
        tables_only: a.tables_only,
    };
    let bar = progress_bar(0, 0, a.quiet || a.dry_run || a.tables_only);
    let written = monolayer::run::intervene(&options, &|r| show(&bar, r, "branches"));
    bar.finish_and_clear();
    for path in written? {
        out(path.display())?;
    }
    Ok(())
}

/// `forecast DIR… --out OUT`.
fn forecast(a: &ForecastArgs) -> Result<(), RunError> {
    let quiet = a.quiet;
    let progress = |line: &str| {
        if !quiet {
            note(line);
        }
    };
    let warn = |line: &str| note(format_args!("warning: {line}"));
    for path in monolayer::run::forecast(&a.dirs, &a.out, a.partial, progress, warn)? {
        out(path.display())?;
    }
    Ok(())
}

/// `analyze DIR`, or with --bench the timings of the measurements at full size.
fn analyze(a: &AnalyzeArgs) -> Result<(), RunError> {
    if a.bench {
        return bench_analysis(a.bench_frames);
    }
    let dir = a.dir.as_deref().expect("clap requires DIR without --bench");
    for path in analyze_run(dir, a.out.as_deref(), a.snapshot, a.field)? {
        out(path.display())?;
    }
    Ok(())
}

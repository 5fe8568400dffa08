//! `monolayer`: run the paper's protocol at full size, continue a run, measure speed.

use std::fs;
use std::path::{Path, PathBuf};
use std::process::ExitCode;
use std::time::Instant;

use clap::{Args, Parser, Subcommand};
use indicatif::{ProgressBar, ProgressStyle};

use monolayer::io::{frame_path, load_params, read_checkpoint, write_checkpoint, write_frame, RunRecord};
use monolayer::{Monolayer, Params, Phase, SimError};

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

impl ParamArgs {
    fn params(&self) -> Result<Params, String> {
        let mut p = load_params(self.config.as_deref(), &self.set)?;
        if let Some(z) = self.zeta {
            p.zeta = z;
        }
        if let Some(c) = self.chi {
            if !(c.is_finite() && c > 0.0) {
                return Err(format!("--chi {c}: must be a finite number > 0"));
            }
            p.set_chi(c);
        }
        if let Some(s) = self.steps {
            p.active_steps = s;
        }
        if let Some(s) = self.relax_steps {
            p.relax_steps = s;
        }
        p.validate().map_err(|e| e.to_string())?;
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
    /// Steps between frames in the active phase.
    #[arg(long, default_value_t = 1000)]
    frame_interval: u64,
    /// Worker threads (results do not depend on it); default: all cores.
    #[arg(long)]
    threads: Option<usize>,
    /// Continue the run in this directory from its last checkpoint (ignores parameter options).
    #[arg(long, value_name = "DIR", conflicts_with_all = ["out", "seed"])]
    resume: Option<PathBuf>,
    /// No progress bar (for batch jobs); a line per frame instead.
    #[arg(long)]
    quiet: bool,
}

#[derive(Args)]
struct BenchArgs {
    /// Active steps timed per friction ratio.
    #[arg(long, default_value_t = 200)]
    steps: u64,
    /// Relaxation steps before timing (a confluent tissue).
    #[arg(long, default_value_t = 3000)]
    relax_steps: u64,
    /// Worker threads.
    #[arg(long, default_value_t = 1)]
    threads: usize,
    #[arg(long, default_value_t = 1)]
    seed: u64,
}

fn main() -> ExitCode {
    let cli = Cli::parse();
    let result = match cli.command {
        Command::Run(a) => with_threads(a.threads, || run(&a)),
        Command::Bench(a) => with_threads(Some(a.threads), || bench(&a)),
        Command::Params => toml::to_string(&Params::default()).map(|s| print!("{s}")).map_err(|e| e.to_string()),
        Command::Fingerprint(a) => fingerprint(&a),
    };
    match result {
        Ok(()) => ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e}");
            ExitCode::from(2)
        }
    }
}

fn with_threads(threads: Option<usize>, f: impl FnOnce() -> Result<(), String> + Send) -> Result<(), String> {
    match threads {
        None => f(),
        Some(0) => Err("--threads 0: must be ≥ 1".into()),
        Some(n) => rayon::ThreadPoolBuilder::new()
            .num_threads(n)
            .build()
            .map_err(|e| format!("--threads {n}: {e}"))?
            .install(f),
    }
}

fn run(a: &RunArgs) -> Result<(), String> {
    let (dir, mut record, mut m) = match &a.resume {
        Some(dir) => {
            let record = RunRecord::load(dir)?;
            let ck = dir.join("checkpoint.npz");
            let state = read_checkpoint(&ck, record.params.box_size)?;
            let m = Monolayer::from_state(record.params.clone(), record.seed, state).map_err(|e| e.to_string())?;
            eprintln!("resuming {} at step {}", dir.display(), m.step_count());
            (dir.clone(), record, m)
        }
        None => {
            let params = a.params.params()?;
            if a.frame_interval == 0 {
                return Err("--frame-interval 0: must be ≥ 1".into());
            }
            if RunRecord::path(&a.out).exists() {
                return Err(format!(
                    "{} already holds a run: continue it with --resume {0}, or choose another --out",
                    a.out.display()
                ));
            }
            fs::create_dir_all(a.out.join("frames")).map_err(|e| format!("{}: {e}", a.out.display()))?;
            let record = RunRecord::new(params.clone(), a.seed, a.frame_interval);
            record.save(&a.out)?;
            let m = Monolayer::new(params, a.seed).map_err(|e| e.to_string())?;
            (a.out.clone(), record, m)
        }
    };
    fs::create_dir_all(dir.join("frames")).map_err(|e| format!("{}: {e}", dir.display()))?;
    let outcome = protocol(&mut m, &dir, &mut record, a.quiet);
    record.status = match &outcome {
        Ok(()) => "finished".into(),
        Err(e) => format!("failed: {e}"),
    };
    record.save(&dir)?;
    outcome.map(|()| eprintln!("done: {} steps in {}", m.step_count(), dir.display()))
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

/// Steps to the end of the protocol, writing a frame and a checkpoint every frame interval of
/// the active phase (and a checkpoint when relaxation ends).
fn protocol(m: &mut Monolayer, dir: &Path, record: &mut RunRecord, quiet: bool) -> Result<(), String> {
    let p = m.params().clone();
    let total = p.total_steps();
    let bar = progress_bar(total, m.step_count(), quiet);
    let checkpoint = dir.join("checkpoint.npz");
    let save = |m: &mut Monolayer, record: &mut RunRecord, frame: bool| -> Result<(), String> {
        if frame {
            m.evaluate_now().map_err(|e| e.to_string())?;
            write_frame(m, &frame_path(dir, m.step_count()))?;
            record.last_frame_step = Some(m.step_count());
        }
        write_checkpoint(m, &checkpoint)?;
        record.save(dir)
    };
    let start = Instant::now();
    let start_step = m.step_count();
    while m.step_count() < total {
        let phase = m.phase();
        bar.set_message(match phase {
            Phase::Relaxation => "relaxing",
            Phase::Active => "active",
        });
        if let Err(e) = m.step() {
            bar.abandon();
            let last_good = dir.join("last_good_state.npz");
            write_checkpoint(m, &last_good)?;
            return Err(failure_message(&e, &last_good));
        }
        bar.inc(1);
        let s = m.step_count();
        let relaxed = s == p.relax_steps;
        let frame = s >= p.relax_steps && (s - p.relax_steps) % record.frame_interval == 0;
        if frame || relaxed {
            save(m, record, frame)?;
            if quiet && frame {
                let rate = (s - start_step) as f64 / start.elapsed().as_secs_f64();
                eprintln!("step {s}/{total}: frame written ({rate:.0} steps/s)");
            }
        }
    }
    bar.finish();
    Ok(())
}

fn failure_message(e: &SimError, last_good: &Path) -> String {
    format!("{e}\n  the last good state is in {} (the last periodic one in checkpoint.npz)", last_good.display())
}

fn fingerprint(a: &FingerprintArgs) -> Result<(), String> {
    let params = a.params.params()?;
    let mut m = Monolayer::new(params, a.seed).map_err(|e| e.to_string())?;
    m.advance(a.total_steps).map_err(|e| e.to_string())?;
    println!("{{\"step\": {}, \"fingerprint\": \"{:016x}\"}}", m.step_count(), m.fingerprint());
    Ok(())
}

fn bench(a: &BenchArgs) -> Result<(), String> {
    println!(
        "full size (N = 100, L = 140), {} thread(s), {} relaxation steps then {} timed active steps",
        a.threads, a.relax_steps, a.steps
    );
    // The benchmark point: ζ = 0.5 at χ = 0.1 and χ = 0.001.
    let base = Params { relax_steps: a.relax_steps, zeta: 0.5, ..Params::default() };
    let mut relaxed = Monolayer::new(base.clone(), a.seed).map_err(|e| e.to_string())?;
    let t = Instant::now();
    relaxed.advance(a.relax_steps).map_err(|e| e.to_string())?;
    println!(
        "relaxation: {:.3} ms/step\n{}",
        1e3 * t.elapsed().as_secs_f64() / a.relax_steps.max(1) as f64,
        relaxed.counters().report()
    );
    for chi in [0.1, 0.001] {
        let mut m = relaxed.clone();
        let mut p = base.clone();
        p.set_chi(chi);
        m.set_params(p).map_err(|e| e.to_string())?;
        // The first solve starts from rest; time the steady state.
        m.advance(5).map_err(|e| e.to_string())?;
        m.counters_mut().reset();
        let t = Instant::now();
        let r = m.advance(a.steps);
        let done = m.counters().steps.max(1);
        println!(
            "χ = {chi}, ζ = {}: {:.3} ms/step over {done} steps{}\n{}",
            m.params().zeta,
            1e3 * t.elapsed().as_secs_f64() / done as f64,
            r.err().map(|e| format!(" (stopped: {e})")).unwrap_or_default(),
            m.counters().report()
        );
    }
    Ok(())
}

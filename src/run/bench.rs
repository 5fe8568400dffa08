//! `monolayer bench` and `monolayer analyze --bench`: where the time goes at full size.
//!
//! A shared machine's speed can drift by 1.4× from one minute to the next, so every comparison
//! is made inside one run, block by block in turn on the same trajectory: each thread count on
//! its own copy of the state, and two independent one-thread simulations side by side, which is
//! the most two threads can give on the machine (they share its caches and memory bandwidth). The
//! two-thread speed-up is reported as a fraction of that ceiling.

use std::fs;
use std::path::{Path, PathBuf};
use std::time::Instant;

use crate::analysis::Analysis;
use crate::formats::{snapshot, RunRecord};
use crate::model::{Monolayer, Params};
use crate::run::console::out;
use crate::run::error::RunError;
use crate::run::files::{frame_path, write_frame};
use crate::run::offline::analyze_run;
use crate::run::plots::Background;

/// What `bench` times.
#[derive(Clone, Debug)]
pub struct BenchOptions {
    /// The parameters of the timed active steps (box, cells, conventions); χ is set per entry of
    /// `chis`.
    pub params: Params,
    pub chis: Vec<f64>,
    pub steps: u64,
    pub relax_steps: u64,
    pub threads: Vec<usize>,
    pub blocks: u64,
    pub seed: u64,
    /// A relaxed-state file to start from instead of relaxing (see `relaxed_start`).
    pub from_relaxed: Option<PathBuf>,
}

fn pool(n: usize) -> Result<rayon::ThreadPool, RunError> {
    rayon::ThreadPoolBuilder::new()
        .num_threads(n)
        .build()
        .map_err(|e| RunError::from(e).context(format!("--threads {n}")))
}

/// The median of a few timings (the mean of the middle two for an even count).
pub fn median(v: &[f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let mut v = v.to_vec();
    v.sort_by(f64::total_cmp);
    let h = v.len() / 2;
    if v.len() % 2 == 1 {
        v[h]
    } else {
        0.5 * (v[h - 1] + v[h])
    }
}

fn best(v: &[f64]) -> f64 {
    v.iter().copied().fold(f64::INFINITY, f64::min)
}

/// Times the relaxation, then for every χ the active steps on each thread count, and (when the
/// thread counts include 1 and 2) the ceiling of two independent one-thread simulations.
pub fn bench(o: &BenchOptions) -> Result<(), RunError> {
    check_options(o)?;
    let pools = o.threads.iter().map(|&n| pool(n)).collect::<Result<Vec<_>, _>>()?;
    let ceiling = o.threads.contains(&1) && o.threads.contains(&2);
    let p = &o.params;
    out(format_args!(
        "N = {}, L = {}, friction weights {:?}, |Q̂| = {}, ζ = {}: {} relaxation steps, then {} timed active steps in {} blocks, thread(s): {:?}{}",
        p.n_cells,
        p.box_size,
        p.friction_weights,
        p.q_magnitude,
        p.zeta,
        o.relax_steps,
        o.steps,
        o.blocks,
        o.threads,
        if ceiling { ", and two one-thread simulations side by side (the ceiling)" } else { "" }
    ))?;
    let base = Params { relax_steps: o.relax_steps, ..p.clone() };
    let (relaxed, relax_ms) = relaxed_tissue(o, &base, &pools[0])?;
    for &chi in &o.chis {
        let mut p = base.clone();
        p.set_chi(chi);
        let timed = time_blocks(o, &pools, &relaxed, &p, ceiling)?;
        report(o, chi, &timed, relax_ms)?;
        if let Some(e) = timed.stopped {
            return Err(e.context(format!("χ = {chi}: stopped")));
        }
    }
    Ok(())
}

/// Thread counts ≥ 1, blocks in [1, steps], at least one χ.
fn check_options(o: &BenchOptions) -> Result<(), RunError> {
    if o.threads.is_empty() || o.threads.contains(&0) {
        return Err(RunError::Options(format!("--threads {:?}: every count must be ≥ 1", o.threads)));
    }
    if o.blocks == 0 || o.blocks > o.steps {
        return Err(RunError::invalid("--blocks", o.blocks, format!("in [1, --steps = {}]", o.steps)));
    }
    if o.chis.is_empty() {
        return Err(RunError::Empty { name: "--chi", need: "value" });
    }
    Ok(())
}

/// The relaxed tissue the active steps start from: read from `--from-relaxed` (not timed), or
/// relaxed here on the first thread count, with its ms per step.
fn relaxed_tissue(
    o: &BenchOptions,
    base: &Params,
    pool: &rayon::ThreadPool,
) -> Result<(Monolayer, Option<f64>), RunError> {
    if let Some(file) = &o.from_relaxed {
        let m = relaxed_start(file, base, o.seed)?;
        out(format_args!("relaxation: read from {} (step {}), not timed", file.display(), m.step_count()))?;
        return Ok((m, None));
    }
    let mut m = Monolayer::new(base.clone(), o.seed).map_err(RunError::from)?;
    let t = Instant::now();
    pool.install(|| m.advance(o.relax_steps)).map_err(RunError::from)?;
    let relax_ms = 1e3 * t.elapsed().as_secs_f64() / o.relax_steps.max(1) as f64;
    out(format_args!("relaxation, {} thread(s): {relax_ms:.3} ms/step\n{}", o.threads[0], m.counters().report()))?;
    Ok((m, Some(relax_ms)))
}

/// One χ's timings: per thread count its copy of the tissue, its ms per step block by block and
/// its total seconds; the side-by-side pair's ms per step (the ceiling); the error that stopped
/// the blocks, if one did.
struct Timed {
    runs: Vec<Monolayer>,
    block_ms: Vec<Vec<f64>>,
    seconds: Vec<f64>,
    pair_ms: Vec<f64>,
    stopped: Option<RunError>,
}

/// The active steps of parameters `p` in `o.blocks` blocks, each block taken in turn by every
/// thread count (and by the pair, with `ceiling`), so that a drift of the machine's speed meets
/// them all alike.
fn time_blocks(
    o: &BenchOptions,
    pools: &[rayon::ThreadPool],
    relaxed: &Monolayer,
    p: &Params,
    ceiling: bool,
) -> Result<Timed, RunError> {
    let start = |pool: &rayon::ThreadPool| -> Result<Monolayer, RunError> {
        let mut m = relaxed.clone();
        m.set_params(p.clone()).map_err(RunError::from)?;
        // The first solve starts from rest; time the steady state.
        pool.install(|| m.advance(5)).map_err(RunError::from)?;
        m.counters_mut().reset();
        Ok(m)
    };
    // One copy per thread count; they follow the same trajectory (the bits do not depend on the
    // thread count), so block k costs each the same work.
    let runs = pools.iter().map(start).collect::<Result<Vec<_>, _>>()?;
    let one = pool(1)?;
    let mut pair = if ceiling { vec![start(&one)?, start(&one)?] } else { Vec::new() };
    let mut t = Timed {
        runs,
        block_ms: vec![Vec::new(); pools.len()],
        seconds: vec![0.0; pools.len()],
        pair_ms: Vec::new(),
        stopped: None,
    };
    'blocks: for k in 0..o.blocks {
        let steps = o.steps * (k + 1) / o.blocks - o.steps * k / o.blocks;
        for (((m, pool), times), total) in t.runs.iter_mut().zip(pools).zip(&mut t.block_ms).zip(&mut t.seconds) {
            let clock = Instant::now();
            let r = pool.install(|| m.advance(steps));
            *total += clock.elapsed().as_secs_f64();
            if let Err(e) = r {
                t.stopped = Some(RunError::from(e));
                break 'blocks;
            }
            times.push(1e3 * clock.elapsed().as_secs_f64() / steps as f64);
        }
        if ceiling {
            let clock = Instant::now();
            if let Err(e) = side_by_side(&mut pair, steps) {
                t.stopped = Some(e);
                break 'blocks;
            }
            t.pair_ms.push(1e3 * clock.elapsed().as_secs_f64() / steps as f64);
        }
    }
    Ok(t)
}

/// `steps` steps of each simulation of `pair`, each on a thread of its own, at the same time.
fn side_by_side(pair: &mut [Monolayer], steps: u64) -> Result<(), RunError> {
    let results: Vec<Result<(), RunError>> = std::thread::scope(|s| {
        let handles: Vec<_> = pair
            .iter_mut()
            .map(|m| {
                s.spawn(move || {
                    let one = pool(1)?;
                    one.install(|| m.advance(steps)).map_err(RunError::from)
                })
            })
            .collect();
        handles.into_iter().map(|h| h.join().unwrap_or_else(|_| Err(RunError::Panicked))).collect()
    });
    results.into_iter().find(|r| r.is_err()).unwrap_or(Ok(()))
}

/// One χ's lines: each thread count's ms per step with its stages, the paper-length projection,
/// the speed-ups over the first thread count, and the fraction of the ceiling two threads reach.
fn report(o: &BenchOptions, chi: f64, t: &Timed, relax_ms: Option<f64>) -> Result<(), RunError> {
    for (((m, times), threads), total) in t.runs.iter().zip(&t.block_ms).zip(&o.threads).zip(&t.seconds) {
        let c = m.counters();
        out(format_args!(
            "χ = {chi}, ζ = {}, {threads} thread(s): {:.3} ms/step over {} steps; blocks: median {:.3}, best {:.3}\n{}",
            m.params().zeta,
            1e3 * total / c.steps.max(1) as f64,
            c.steps,
            median(times),
            best(times),
            c.report()
        ))?;
    }
    let first = &t.block_ms[0];
    if let (Some(relax_ms), true) = (relax_ms.filter(|_| o.relax_steps > 0), !first.is_empty()) {
        out(format_args!("  {}", paper_length_line(o.threads[0], relax_ms, median(first))))?;
    }
    for (times, threads) in t.block_ms.iter().zip(&o.threads).skip(1) {
        let ratios: Vec<f64> = first.iter().zip(times).map(|(t0, t)| t0 / t).collect();
        out(format_args!(
            "  speed-up of {threads} over {} thread(s): median block {:.2}×, best blocks {:.2}×",
            o.threads[0],
            median(&ratios),
            best(first) / best(times)
        ))?;
    }
    let i1 = o.threads.iter().position(|&n| n == 1);
    let i2 = o.threads.iter().position(|&n| n == 2);
    if let (Some(i1), Some(i2), true) = (i1, i2, !t.pair_ms.is_empty() && t.pair_ms.len() == first.len()) {
        // Two simulations side by side make two steps in one pair block: their throughput over
        // one simulation alone is the most any split of one simulation could reach.
        let ceilings: Vec<f64> = t.block_ms[i1].iter().zip(&t.pair_ms).map(|(t1, tp)| 2.0 * t1 / tp).collect();
        let speedups: Vec<f64> = t.block_ms[i1].iter().zip(&t.block_ms[i2]).map(|(t1, t2)| t1 / t2).collect();
        let fractions: Vec<f64> = speedups.iter().zip(&ceilings).map(|(s, c)| s / c).collect();
        out(format_args!(
            "  ceiling (two one-thread simulations side by side): median block {:.2}×; two threads reach {:.2} of it (median block)",
            median(&ceilings),
            median(&fractions)
        ))?;
    }
    Ok(())
}

/// The relaxed state in `file` (the format of `monolayer relaxed-state`), checked against the key
/// of `params` and `seed`: a file made with other relaxation parameters is refused, naming it.
pub fn relaxed_start(file: &Path, params: &Params, seed: u64) -> Result<Monolayer, RunError> {
    // A relaxed state holds less than the simulation it starts: a larger file is not one.
    let max = crate::run::runner::memory_estimate(params);
    let bytes = crate::run::files::read_input(file, "a relaxed state (--from-relaxed)", max)
        .map_err(|e| RunError::FromRelaxed(e.to_string()))?;
    let state = snapshot::decode_relaxed(&bytes, params, seed).map_err(|e| {
        RunError::FromRelaxed(format!(
            "{}: {e} (give the relaxation's parameters: --relax-steps, --seed, --set box_size=…, n_cells=…, gamma=…)",
            file.display()
        ))
    })?;
    Monolayer::from_saved(params.clone(), seed, state)
        .map_err(|e| RunError::from(e).context(format!("--from-relaxed {}", file.display())))
}

/// Wall time of a run of `relax_steps` relaxation and `active_steps` active steps, in minutes,
/// from the time per step of each phase.
pub fn projected_minutes(relax_ms: f64, active_ms: f64, relax_steps: u64, active_steps: u64) -> f64 {
    (relax_ms * relax_steps as f64 + active_ms * active_steps as f64) / 60e3
}

/// The paper-length projection (the defaults' 10,000 relaxation and 100,000 active steps, the
/// protocol of every figure run) from the relaxation's time per step and the active steps' median
/// block; both phases on `threads` thread(s), which is one core when it is 1.
fn paper_length_line(threads: usize, relax_ms: f64, active_ms: f64) -> String {
    let d = Params::default();
    let total = projected_minutes(relax_ms, active_ms, d.relax_steps, d.active_steps);
    let where_ = if threads == 1 { "one core".to_string() } else { format!("{threads} threads") };
    format!(
        "paper-length run ({} relaxation + {} active steps) on {where_}, projected: {total:.1} min \
         (relaxation {:.1} min at {relax_ms:.3} ms/step, activity {:.1} min at {active_ms:.3} ms/step)",
        d.relax_steps,
        d.active_steps,
        projected_minutes(relax_ms, 0.0, d.relax_steps, 0),
        projected_minutes(0.0, active_ms, 0, d.active_steps),
    )
}

/// Times [`Analysis::measure`] on a full-size active state, and `analyze` over `frames` frames
/// of it written to a temporary run directory (removed afterwards).
pub fn bench_analysis(frames: u64) -> Result<(), RunError> {
    let p = Params { relax_steps: 3000, zeta: 0.5, ..Params::default() };
    let mut m = Monolayer::new(p.clone(), 1).map_err(RunError::from)?;
    m.advance(p.relax_steps + 20).map_err(RunError::from)?;
    m.evaluate_now().map_err(RunError::from)?;
    let mut analysis = Analysis::new(m.params());
    analysis.measure(&m);
    let reps = 200;
    let t = Instant::now();
    for _ in 0..reps {
        analysis.measure(&m);
    }
    let ms = 1e3 * t.elapsed().as_secs_f64() / reps as f64;
    out(format_args!("measurements of one full-size frame (N = {}, L = {}): {ms:.2} ms", p.n_cells, p.box_size))?;
    let dir = std::env::temp_dir().join(format!("monolayer-analysis-bench-{}", std::process::id()));
    let result = write_and_analyze(&mut m, &dir, frames);
    let _ = fs::remove_dir_all(&dir);
    result
}

fn write_and_analyze(m: &mut Monolayer, dir: &Path, frames: u64) -> Result<(), RunError> {
    fs::create_dir_all(dir.join("frames")).map_err(|e| RunError::io(dir, e))?;
    RunRecord::new(m.params().clone(), 1, 10).save(dir)?;
    for _ in 0..frames {
        m.advance(10).map_err(RunError::from)?;
        m.evaluate_now().map_err(RunError::from)?;
        let path = frame_path(dir, m.step_count());
        write_frame(m, &path)?;
    }
    let t = Instant::now();
    let written = analyze_run(dir, None, None, Background::StrainRate)?;
    out(format_args!(
        "analyze over {frames} full-size frames: {:.2} s ({} files written)",
        t.elapsed().as_secs_f64(),
        written.len()
    ))?;
    Ok(())
}

/// `monolayer bench --gpu`: the GPU kernels, timed one by one at the given size from
/// a relaxed tissue a few active steps on: the adapter, ms per dispatch (the median of `repeats`
/// submissions, each waited for) and the bytes each must move at the least; then the stages up
/// to the friction solve's right-hand side, a Heun step without a friction solve (relaxation)
/// and one with it (the active phase, on fixed patches), each in one submission; last, the
/// page's hand-off to the CPU for a row of readouts, one every `row_every` active steps (the
/// page's `ROW_EVERY`, passed in by the CLI: run/ and web/ are sibling layers, tests/layers.rs).
#[cfg(feature = "gpu")]
pub fn bench_gpu(params: &Params, relax_steps: u64, seed: u64, repeats: usize, row_every: u64) -> Result<(), RunError> {
    use crate::gpu::{GpuContext, GpuMonolayer, Kernel};
    let ctx = GpuContext::new().map_err(RunError::gpu)?;
    out(format_args!("adapter: {}", ctx.describe()))?;
    if ctx.runs_on_cpu() {
        out(format_args!("a CPU device: every time below is a CPU figure, not a GPU's"))?;
    }
    let p = Params { relax_steps, ..params.clone() };
    let mut m = Monolayer::new(p.clone(), seed).map_err(RunError::from)?;
    m.advance(relax_steps + 5).map_err(RunError::from)?;
    let mut gpu = GpuMonolayer::new(&ctx, &m).map_err(RunError::gpu)?;
    let time = |gpu: &GpuMonolayer, kernels: &[Kernel]| -> Result<f64, RunError> {
        gpu.run(&ctx, kernels);
        ctx.wait().map_err(RunError::gpu)?;
        let times = (0..repeats.max(1))
            .map(|_| {
                let t = Instant::now();
                gpu.run(&ctx, kernels);
                ctx.wait().map_err(RunError::gpu)?;
                Ok(1e3 * t.elapsed().as_secs_f64())
            })
            .collect::<Result<Vec<f64>, RunError>>()?;
        Ok(median(&times))
    };
    out(format_args!(
        "N = {}, L = {}, {relax_steps} relaxation steps and 5 active on the CPU, then the median of {repeats} dispatches:",
        p.n_cells, p.box_size
    ))?;
    for k in Kernel::ALL {
        let b = k.compulsory_bytes(gpu.state());
        out(format_args!(
            "  {:<18} {:>8.3} ms/dispatch  {:>6.2} MB",
            format!("{k:?}"),
            time(&gpu, &[k])?,
            b as f64 / 1e6
        ))?;
    }
    let bytes = |gpu: &GpuMonolayer, kernels: &[Kernel]| {
        kernels.iter().map(|k| k.compulsory_bytes(gpu.state())).sum::<u64>() as f64 / 1e6
    };
    // The kernels timed one by one leave the state meaningless (a CG step without its α, a
    // corrector without its predictor): the sequences start again from the uploaded state.
    gpu.upload(&ctx, &m).map_err(RunError::gpu)?;
    // The step without a friction solve is timed on this active state as it stands: its
    // dispatches and bytes are those of a relaxation step.
    for (what, kernels) in [
        ("up to the friction solve's right-hand side", &Kernel::FRICTION_SUMS[..]),
        ("one Heun step without a friction solve", &Kernel::step(None)[..]),
    ] {
        out(format_args!(
            "{what}: {} dispatches, {:.3} ms in one submission, {:.2} MB at the least",
            kernels.len(),
            time(&gpu, kernels)?,
            bytes(&gpu, kernels)
        ))?;
    }
    // Steps with the friction solve and the patches following the cells (`Monolayer::step`),
    // from the uploaded state on (each timed step is a step of the same run); the iterations the
    // solves took decide the dispatches that work, the rest return at once.
    gpu.upload(&ctx, &m).map_err(RunError::gpu)?;
    let step = gpu.step_kernels();
    let ms = time(&gpu, &step)?;
    let solve = gpu.read_solve(&ctx).map_err(RunError::gpu)?;
    let taken = solve.iterations[0].max(solve.iterations[1]) as usize;
    // The dispatches that work: the step with only the iterations the solve took recorded (the
    // recorded ones after them return at once), which is also what the recorded count tends to.
    let working_kernels = Kernel::whole_step(Some((gpu.preconditioner, taken)));
    let working = working_kernels.len();
    out(format_args!(
        "one step with the friction solve and the patches following: {} dispatches recorded ({} CG iterations per solve), {ms:.3} ms in one submission; \
         the last solve took {taken} iterations (residual {:.2e}{}), so about {working} dispatches worked, {:.2} MB at the least",
        step.len(),
        gpu.solve_iterations,
        solve.residual(),
        if solve.converged() { "" } else { ", NOT CONVERGED" },
        bytes(&gpu, &working_kernels)
    ))?;
    let working_bytes = bytes(&gpu, &working_kernels);

    // A run as the page's GPU engine takes it (gpu::stepper::GpuRun): submissions of 50 steps,
    // each checked by one readback, the recorded iterations following what the solves need.
    let mut run = crate::gpu::GpuRun::new(&ctx, &m).map_err(RunError::gpu)?;
    let recorded = run.gpu().solve_iterations;
    // Enough submissions for the recorded iterations to settle (the rule lowers them only after
    // `LOWER_AFTER` in a row asked for fewer), then the timed ones.
    let settle = u64::from(crate::gpu::LOWER_AFTER) + 1;
    run.advance(&ctx, settle * run.check_every).map_err(RunError::gpu)?;
    // Blocks of two submissions, alternating IN_FLIGHT of them under way with one at a time
    // (what keeping the next under way saves), each way's time the mean of its two blocks.
    let steps = 2 * run.check_every;
    let mut ms = [0.0; 2];
    for in_flight in [crate::gpu::IN_FLIGHT, 1, crate::gpu::IN_FLIGHT, 1] {
        run.max_in_flight = in_flight;
        let t = Instant::now();
        run.advance(&ctx, steps).map_err(RunError::gpu)?;
        ms[usize::from(in_flight == 1)] += 1e3 * t.elapsed().as_secs_f64() / (2 * steps) as f64;
    }
    let [per_step, one_at_a_time] = ms;
    let adapted = run.gpu().solve_iterations;
    let recorded_list = run.gpu().step_kernels();
    let recorded_now = recorded_list.len();
    out(format_args!(
        "a GPU run (GpuRun, checked every {} steps, {} submissions under way): {per_step:.3} ms per step over 2 × {steps} \
         steps ({one_at_a_time:.3} ms over 2 × {steps} alternated with them, one submission at a time); the recorded CG iterations went \
         from {recorded} to {adapted} per solve, {recorded_now} dispatches recorded per step",
        run.check_every,
        crate::gpu::IN_FLIGHT
    ))?;
    let stages: Vec<String> =
        by_stage(&recorded_list, &vec![1.0; recorded_now]).iter().map(|(f, n)| format!("{f} {n}")).collect();
    out(format_args!("dispatches recorded per step by stage (shaders/): {}", stages.join(", ")))?;
    let coarse: u64 = recorded_list
        .iter()
        .filter(|&&k| matches!(k, Kernel::MgCoarseCycle | Kernel::MgSetUpCoarse))
        .map(|k| k.serial_steps(run.gpu().state()))
        .sum();
    out(format_args!(
        "at the {taken} iterations the solve took: {} dispatches per step; longest serial chain per step (loop \
         iterations one after another on one invocation, Kernel::serial_steps): {} as recorded, {coarse} of them in \
         the coarse levels",
        working,
        crate::gpu::serial_chain(&recorded_list, run.gpu().state())
    ))?;
    // Each dispatch timed on the device, in its own pass between two timestamps: one step from
    // the uploaded state, the recorded list.
    gpu.upload(&ctx, &m).map_err(RunError::gpu)?;
    match gpu.time_kernels(&ctx, &recorded_list).map_err(RunError::gpu)? {
        Some(ms) => {
            let stages: Vec<String> =
                by_stage(&recorded_list, &ms).iter().map(|(f, t)| format!("{f} {t:.3}")).collect();
            out(format_args!(
                "device time of one step by stage (timestamps around each dispatch), ms: {}; {:.3} in all",
                stages.join(", "),
                ms.iter().sum::<f64>()
            ))?;
        }
        None => out(format_args!("device time by stage: timestamps unsupported on this adapter"))?,
    }
    // Every recorded dispatch is launched, the ones after convergence too; the bytes and the
    // serial steps are those of the dispatches that work.
    let working_chain = crate::gpu::serial_chain(&working_kernels, gpu.state());
    out(format_args!("{}", projection_line(&LaptopProjection::of(recorded_now, working_bytes, working_chain))))?;
    out(format_args!("{}", hand_off_line(&time_hand_off(&ctx, &run, repeats)?, row_every)))?;
    Ok(())
}

/// What the page's worker does on the CPU for each row of readouts of its GPU engine
/// (`web::WebSim::adopt`), ms, each the median of its repeats.
#[cfg(feature = "gpu")]
#[derive(Clone, Copy, Debug, PartialEq)]
struct HandOff {
    /// The state read back and rebuilt as a CPU monolayer (`GpuRun::download`).
    download: f64,
    /// Its velocities and Q̂ evaluated (`Monolayer::evaluate_now`): the download carries φ only.
    evaluate: f64,
    /// The row's measures (`Analysis::measure_in`, `Detail::Tissue`: what `web::ReadoutLog::measure`
    /// runs, called here directly as run/ does not use web/).
    measure: f64,
}

#[cfg(feature = "gpu")]
fn time_hand_off(ctx: &crate::gpu::GpuContext, run: &crate::gpu::GpuRun, repeats: usize) -> Result<HandOff, RunError> {
    let mut times = [vec![], vec![], vec![]];
    let mut analysis = Analysis::new(run.params());
    for _ in 0..repeats.max(1) {
        let t = Instant::now();
        let mut m = run.download_now(ctx).map_err(RunError::gpu)?;
        times[0].push(1e3 * t.elapsed().as_secs_f64());
        let t = Instant::now();
        m.evaluate_now()?;
        times[1].push(1e3 * t.elapsed().as_secs_f64());
        let t = Instant::now();
        analysis.measure_in(&m, crate::analysis::Detail::Tissue);
        times[2].push(1e3 * t.elapsed().as_secs_f64());
    }
    Ok(HandOff { download: median(&times[0]), evaluate: median(&times[1]), measure: median(&times[2]) })
}

/// The hand-off's cost and the pace it allows the page's GPU engine: one hand-off every
/// `row_every` active steps, while the submissions already under way keep the device busy.
#[cfg(feature = "gpu")]
fn hand_off_line(h: &HandOff, row_every: u64) -> String {
    let ms = h.download + h.evaluate + h.measure;
    format!(
        "the page's hand-off per row of readouts (every {row_every} active steps; web::WebSim::adopt): download {:.2} ms, \
         evaluation {:.2}, measures {:.2}: {ms:.2} ms on this host's CPU, which keeps up with the GPU engine up to \
         {:.0} steps/s",
        h.download,
        h.evaluate,
        h.measure,
        1e3 * row_every as f64 / ms
    )
}

/// Each kernel's value added up by its stage (its file in `shaders/`), in the order the stages
/// first appear.
#[cfg(feature = "gpu")]
fn by_stage(kernels: &[crate::gpu::Kernel], values: &[f64]) -> Vec<(&'static str, f64)> {
    let mut out: Vec<(&str, f64)> = Vec::new();
    for (k, v) in kernels.iter().zip(values) {
        match out.iter_mut().find(|(f, _)| *f == k.shader_file()) {
            Some((_, sum)) => *sum += v,
            None => out.push((k.shader_file(), *v)),
        }
    }
    out
}

/// A laptop GPU's time per full-size step, projected from the counts of a step (what works
/// in it), with the assumed costs below. Not a measurement: no GPU was at hand (docs/gpu.md).
/// Only `bench --gpu` prints it (and the tests check it).
#[cfg(any(feature = "gpu", test))]
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct LaptopProjection {
    pub dispatches: usize,
    pub megabytes: f64,
    /// The longest chain of serial steps along the step (`gpu::kernels::serial_chain`).
    pub serial_steps: u64,
    /// Fastest and slowest, in ms per step: the device's time or the host's encoding, whichever
    /// is longer (the host encodes the next submission while the device runs this one).
    pub ms: (f64, f64),
}

/// Launch and dependency cost of one dispatch within a compute pass on a laptop GPU, µs.
#[cfg(any(feature = "gpu", test))]
pub const DISPATCH_US: (f64, f64) = (2.0, 10.0);
/// Memory bandwidth, GB/s: a discrete laptop GPU, an integrated one.
#[cfg(any(feature = "gpu", test))]
pub const BANDWIDTH_GB_S: (f64, f64) = (200.0, 60.0);
/// One serial step of an invocation (a loop iteration with its loads from cache, or a barrier
/// phase), µs.
#[cfg(any(feature = "gpu", test))]
pub const SERIAL_STEP_US: (f64, f64) = (0.05, 0.5);
/// The host's cost of encoding one dispatch (pipeline, bind group, dispatch), µs.
#[cfg(any(feature = "gpu", test))]
pub const ENCODE_US: (f64, f64) = (0.5, 2.0);

#[cfg(any(feature = "gpu", test))]
impl LaptopProjection {
    pub fn of(dispatches: usize, megabytes: f64, serial_steps: u64) -> Self {
        let at = |i: usize| {
            let [launch, gb_s, serial, encode] = [
                [DISPATCH_US.0, BANDWIDTH_GB_S.0, SERIAL_STEP_US.0, ENCODE_US.0],
                [DISPATCH_US.1, BANDWIDTH_GB_S.1, SERIAL_STEP_US.1, ENCODE_US.1],
            ][i];
            let device = dispatches as f64 * launch / 1e3 + megabytes / gb_s + serial_steps as f64 * serial / 1e3;
            device.max(dispatches as f64 * encode / 1e3)
        };
        LaptopProjection { dispatches, megabytes, serial_steps, ms: (at(0), at(1)) }
    }
}

/// The line `bench --gpu` prints, labelled as a projection.
#[cfg(any(feature = "gpu", test))]
pub fn projection_line(p: &LaptopProjection) -> String {
    format!(
        "PROJECTION for a laptop GPU, not a measurement: {} dispatches × {}–{} µs, {:.1} MB at {}–{} GB/s, \
         {} serial steps × {}–{} µs (host encoding {}–{} µs per dispatch, overlapped): {:.1}–{:.1} ms per step \
         ({:.0}–{:.0} steps/s)",
        p.dispatches,
        DISPATCH_US.0,
        DISPATCH_US.1,
        p.megabytes,
        BANDWIDTH_GB_S.0,
        BANDWIDTH_GB_S.1,
        p.serial_steps,
        SERIAL_STEP_US.0,
        SERIAL_STEP_US.1,
        ENCODE_US.0,
        ENCODE_US.1,
        p.ms.0,
        p.ms.1,
        1e3 / p.ms.1,
        1e3 / p.ms.0
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn median_of_odd_and_even_counts() {
        assert_eq!(median(&[3.0, 1.0, 2.0]), 2.0);
        assert_eq!(median(&[4.0, 1.0, 2.0, 3.0]), 2.5);
        assert!(median(&[]).is_nan());
    }

    #[test]
    fn the_laptop_projection_adds_dispatches_bytes_and_serial_steps() {
        // 100 dispatches at 2–10 µs = 0.2–1.0 ms; 60 MB at 200–60 GB/s = 0.3–1.0 ms;
        // 10,000 serial steps at 0.05–0.5 µs = 0.5–5.0 ms; encoding 0.05–0.2 ms, overlapped.
        let p = LaptopProjection::of(100, 60.0, 10_000);
        assert!((p.ms.0 - 1.0).abs() < 1e-12 && (p.ms.1 - 7.0).abs() < 1e-12, "{p:?}");
        let line = projection_line(&p);
        assert!(line.starts_with("PROJECTION for a laptop GPU, not a measurement"), "{line}");
        assert!(line.contains("1.0–7.0 ms per step (143–1000 steps/s)"), "{line}");
        // Where encoding takes longer than the device, it sets the pace.
        let host_bound = LaptopProjection::of(10_000, 0.0, 0);
        assert!((host_bound.ms.1 - 100.0).abs() < 1e-9, "{host_bound:?}");
    }

    #[cfg(feature = "gpu")]
    #[test]
    fn the_hand_off_keeps_up_with_a_row_every_so_many_steps() {
        // 1 + 2.5 + 1.5 = 5 ms per row, a row every 10 steps: 2,000 steps/s.
        let line = hand_off_line(&HandOff { download: 1.0, evaluate: 2.5, measure: 1.5 }, 10);
        assert!(line.contains("download 1.00 ms, evaluation 2.50, measures 1.50: 5.00 ms"), "{line}");
        assert!(line.ends_with("up to 2000 steps/s"), "{line}");
    }

    #[test]
    fn the_paper_length_projection_adds_both_phases() {
        // 10,000 steps at 3 ms and 100,000 at 6 ms: 30 s + 600 s = 10.5 min.
        assert!((projected_minutes(3.0, 6.0, 10_000, 100_000) - 10.5).abs() < 1e-12);
        let line = paper_length_line(1, 3.0, 6.0);
        assert!(line.contains("on one core, projected: 10.5 min (relaxation 0.5 min"), "{line}");
        assert!(line.contains("activity 10.0 min at 6.000 ms/step"), "{line}");
        assert!(paper_length_line(2, 3.0, 6.0).contains("on 2 threads"));
    }

    /// A tiny bench runs through every branch (thread counts, the ceiling) and refuses bad
    /// options by name.
    #[test]
    fn a_small_bench_runs_and_bad_options_are_refused() {
        let params = Params { box_size: 40, n_cells: 4, zeta: 0.5, ..Params::default() };
        let o = BenchOptions {
            params,
            chis: vec![0.01],
            steps: 4,
            relax_steps: 20,
            threads: vec![1, 2],
            blocks: 2,
            seed: 1,
            from_relaxed: None,
        };
        bench(&o).unwrap();
        let e = bench(&BenchOptions { blocks: 9, ..o.clone() }).unwrap_err().to_string();
        assert!(e.contains("--blocks"), "{e}");
        let e = bench(&BenchOptions { threads: vec![0], ..o.clone() }).unwrap_err().to_string();
        assert!(e.contains("--threads"), "{e}");
        let e = bench(&BenchOptions { chis: vec![], ..o.clone() }).unwrap_err().to_string();
        assert!(e.contains("--chi"), "{e}");
    }

    /// --from-relaxed starts from the file's state, exactly what relaxing gives, and refuses a
    /// file made with other relaxation parameters or saved at another step, naming the file.
    #[test]
    fn a_relaxed_start_is_the_relaxation_and_a_foreign_file_is_refused() {
        use crate::formats::snapshot::relaxation_key;
        let p = Params { box_size: 40, n_cells: 4, relax_steps: 20, ..Params::default() };
        let mut relaxed = Monolayer::new(p.clone(), 3).unwrap();
        relaxed.advance(20).unwrap();
        let dir = tempfile::tempdir().unwrap();
        let file = dir.path().join("r.bin");
        fs::write(&file, snapshot::encode(&relaxed.state(), relaxation_key(&p, 3))).unwrap();
        let start = relaxed_start(&file, &p, 3).unwrap();
        assert_eq!(start.fingerprint(), relaxed.fingerprint());
        let e = relaxed_start(&file, &Params { gamma: 0.07, ..p.clone() }, 3).err().unwrap().to_string();
        assert!(e.contains("--from-relaxed") && e.contains("r.bin"), "{e}");
        assert!(relaxed_start(&file, &p, 4).is_err(), "another seed");
        let mut later = relaxed.clone();
        later.advance(1).unwrap();
        fs::write(&file, snapshot::encode(&later.state(), relaxation_key(&p, 3))).unwrap();
        let e = relaxed_start(&file, &p, 3).err().unwrap().to_string();
        assert!(e.contains("saved at step 21"), "{e}");
        bench(&BenchOptions {
            params: Params { zeta: 0.5, ..p.clone() },
            chis: vec![0.01],
            steps: 2,
            relax_steps: 20,
            threads: vec![1],
            blocks: 1,
            seed: 3,
            from_relaxed: Some(dir.path().join("missing.bin")),
        })
        .unwrap_err();
    }
}

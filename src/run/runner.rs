//! A run on disk: the protocol stepped to its end in an output directory, with a frame and a
//! checkpoint every frame interval, the run record kept current, optional live analysis, and a
//! failure that keeps the last good state. `monolayer run` and `monolayer sweep` both use it.

use std::fs;
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use crate::formats::{Engine, RunRecord, RunStatus};
use crate::model::{Monolayer, Params, STORE_NAME};
use crate::run::error::RunError;
use crate::run::files::{
    check_checkpoint_params, checkpoint_path, frame_path, keep_checkpoint, read_checkpoint, remove_stale_temporaries,
    write_frame, write_run_checkpoint, RunLock, CHECKPOINT, KEPT_CHECKPOINTS, LAST_GOOD_STATE,
};
use crate::run::offline::LiveRun;

/// What the protocol reports to whoever watches it (a progress bar, a sweep).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Event {
    /// A step was taken.
    Step,
    /// A frame (and checkpoint) was written.
    Frame,
    /// The live analysis of the frame just written failed; the simulation goes on (its frames
    /// can be analysed later with `monolayer analyze`).
    AnalysisFailed(String),
}

/// Why the protocol stopped early.
enum Stop {
    /// The simulation failed: a result of the run.
    Simulation(RunError),
    /// The machine's problem, not the run's, which goes on from its checkpoint once it is
    /// fixed: writing its files failed, or its GPU did (none found, or it failed under the run).
    Machine(RunError),
    /// SIGTERM or SIGINT (Slurm, Ctrl-C): the step under way was finished; the run goes on from its
    /// checkpoint.
    Signal(&'static str),
}

static SIGTERM_SEEN: AtomicBool = AtomicBool::new(false);
static SIGINT_SEEN: AtomicBool = AtomicBool::new(false);

/// Turns SIGTERM and SIGINT into a graceful stop for this process: a run finishes the step under
/// way, records `stopped: signal …` and returns (then [`stop_signal`] says which); a second
/// signal of the same kind ends the process at once, as the first would have.
pub fn stop_gracefully_on_signals() -> Result<(), RunError> {
    use signal_hook::consts::{SIGINT, SIGTERM};
    for (sig, seen) in [(SIGTERM, &SIGTERM_SEEN), (SIGINT, &SIGINT_SEEN)] {
        // The default action first, armed by the flag the second handler sets.
        signal_hook::flag::register_conditional_default(sig, seen).map_err(signal_handler)?;
        signal_hook::flag::register(sig, seen).map_err(signal_handler)?;
    }
    Ok(())
}

fn signal_handler(e: std::io::Error) -> RunError {
    RunError::SignalHandler(e)
}

/// The signal that asked this process to stop, if one did: (name, number). A closed stdout or
/// stderr is SIGPIPE's (`run::console`): Rust ignores the signal, and the write that
/// found the pipe closed asks for the stop instead.
pub fn stop_signal() -> Option<(&'static str, i32)> {
    if SIGTERM_SEEN.load(Ordering::SeqCst) {
        Some(("SIGTERM", 15))
    } else if SIGINT_SEEN.load(Ordering::SeqCst) {
        Some(("SIGINT", 2))
    } else if crate::run::console::output_closed() {
        Some(("SIGPIPE", 13))
    } else {
        None
    }
}

/// Bytes a run of `params` needs at most, roughly (within about 1.5× of the peak measured): the
/// lattice fields and the friction solver's hierarchy per site, and each cell's fields on its
/// patch, the relaxation patch or a cell stretched to 1.5 diameters, whichever is larger.
pub fn memory_estimate(params: &Params) -> u64 {
    // Measured: about 340 bytes per site at L = 128 and 512 (peak RSS of `fingerprint`).
    const BYTES_PER_SITE: u64 = 400;
    const FIELDS_PER_CELL_SITE: u64 = 11;
    let sites = (params.box_size * params.box_size) as u64;
    let stretched = (3.0 * params.radius).ceil() as u64 + 2 * params.patch_margin as u64;
    let side = (params.relax_patch_size as u64).max(stretched) + 2;
    sites * BYTES_PER_SITE + params.n_cells as u64 * side * side * FIELDS_PER_CELL_SITE * 8 + (16 << 20)
}

/// `MONOLAYER_MEMORY_LIMIT_MB` read: a whole number of megabytes ≥ 1, or an error naming it.
pub fn parse_memory_limit_mb(text: &str) -> Result<u64, RunError> {
    match text.trim().parse::<u64>() {
        Ok(mb) if mb >= 1 => Ok(mb.saturating_mul(1 << 20)),
        _ => Err(RunError::invalid(
            "MONOLAYER_MEMORY_LIMIT_MB =",
            format!("{text:?}"),
            "a whole number of megabytes ≥ 1, e.g. 4096",
        )),
    }
}

/// What a cgroup leaves: its `memory.max` (v2: a number or `max`; v1's `memory.limit_in_bytes`
/// says "none" with a number near 2⁶³) less its `memory.current` (v1: `memory.usage_in_bytes`).
pub fn cgroup_room(max: &str, current: Option<&str>) -> Option<u64> {
    let max: u64 = max.trim().parse().ok().filter(|&m| m < 1 << 60)?;
    let current: u64 = current.and_then(|c| c.trim().parse().ok()).unwrap_or(0);
    Some(max.saturating_sub(current))
}

/// The smallest room the cgroups of this process leave (a Slurm `--mem`, a container): v2's
/// `memory.max` and v1's `memory.limit_in_bytes` of its cgroup and every one above it.
fn cgroup_limit() -> Option<u64> {
    let own = fs::read_to_string("/proc/self/cgroup").ok()?;
    let mut least: Option<u64> = None;
    for line in own.lines() {
        let mut parts = line.splitn(3, ':');
        let (_, controllers, path) = (parts.next()?, parts.next()?, parts.next()?);
        let (base, max, current) = match controllers {
            "" => ("/sys/fs/cgroup".to_string(), "memory.max", "memory.current"),
            c if c.split(',').any(|c| c == "memory") => {
                ("/sys/fs/cgroup/memory".to_string(), "memory.limit_in_bytes", "memory.usage_in_bytes")
            }
            _ => continue,
        };
        let mut dir = PathBuf::from(format!("{base}{}", path.trim_end_matches('/')));
        loop {
            if let Ok(m) = fs::read_to_string(dir.join(max)) {
                let c = fs::read_to_string(dir.join(current)).ok();
                if let Some(room) = cgroup_room(&m, c.as_deref()) {
                    least = Some(least.map_or(room, |l| l.min(room)));
                }
            }
            if dir.as_os_str().len() <= base.len() || !dir.pop() {
                break;
            }
        }
    }
    least
}

/// What RLIMIT_AS (`ulimit -v`) leaves this process: the limit less its address space now.
fn address_space_limit() -> Option<u64> {
    let mut r = libc::rlimit { rlim_cur: 0, rlim_max: 0 };
    // SAFETY: getrlimit writes the struct it is given and nothing else.
    if unsafe { libc::getrlimit(libc::RLIMIT_AS, &mut r) } != 0 || r.rlim_cur == libc::RLIM_INFINITY {
        return None;
    }
    let status = fs::read_to_string("/proc/self/status").unwrap_or_default();
    let used_kb: u64 = status
        .lines()
        .find_map(|l| l.strip_prefix("VmSize:"))
        .and_then(|v| v.trim().trim_end_matches("kB").trim().parse().ok())
        .unwrap_or(0);
    // rlim_t is u64 on 64-bit Linux, narrower elsewhere.
    #[allow(clippy::unnecessary_cast)]
    let limit = r.rlim_cur as u64;
    Some(limit.saturating_sub(used_kb.saturating_mul(1024)))
}

/// The memory a run may use, and what sets it: the least of `MONOLAYER_MEMORY_LIMIT_MB` (else
/// Linux's MemAvailable), the room of the process's cgroups and of its RLIMIT_AS; None where
/// none is known. An unreadable `MONOLAYER_MEMORY_LIMIT_MB` is an error.
fn memory_limit() -> Result<Option<(u64, &'static str)>, RunError> {
    let mut limits: Vec<(u64, &'static str)> = Vec::new();
    match std::env::var("MONOLAYER_MEMORY_LIMIT_MB") {
        Ok(v) => limits.push((parse_memory_limit_mb(&v)?, "MONOLAYER_MEMORY_LIMIT_MB")),
        Err(std::env::VarError::NotUnicode(v)) => {
            return Err(RunError::invalid(
                "MONOLAYER_MEMORY_LIMIT_MB =",
                format!("{v:?}"),
                "a whole number of megabytes ≥ 1",
            ))
        }
        Err(std::env::VarError::NotPresent) => {
            let available = fs::read_to_string("/proc/meminfo").ok().and_then(|info| {
                info.lines()
                    .find_map(|l| l.strip_prefix("MemAvailable:"))?
                    .trim()
                    .trim_end_matches("kB")
                    .trim()
                    .parse::<u64>()
                    .ok()
            });
            if let Some(kb) = available {
                limits.push((kb.saturating_mul(1024), "the memory available"));
            }
        }
    }
    if let Some(room) = cgroup_limit() {
        limits.push((room, "what this process's cgroup leaves (memory.max)"));
    }
    if let Some(room) = address_space_limit() {
        limits.push((room, "what RLIMIT_AS (ulimit -v) leaves"));
    }
    Ok(limits.into_iter().min_by_key(|l| l.0))
}

/// Refuses a run that would not fit in memory, before it starts, with what it would need.
pub fn check_memory(params: &Params) -> Result<(), RunError> {
    check_memory_of(params, 1)
}

/// [`check_memory`] for `copies` simulations of `params` held at once (`bench` keeps one per
/// thread count it times).
pub fn check_memory_of(params: &Params, copies: u64) -> Result<(), RunError> {
    let need = memory_estimate(params).saturating_mul(copies.max(1));
    let held = if copies > 1 { format!(" for the {copies} simulations held at once") } else { String::new() };
    check_need(params, need, held)
}

/// [`check_memory`] for the simulations a sweep (or `figures`) runs at once, `workers` at a
/// time: the sum of the `workers` largest of `params`, the runs with steps left.
pub fn check_memory_of_jobs<'a>(params: impl IntoIterator<Item = &'a Params>, workers: usize) -> Result<(), RunError> {
    let mut largest: Vec<(u64, &Params)> = params.into_iter().map(|p| (memory_estimate(p), p)).collect();
    largest.sort_by_key(|(need, _)| std::cmp::Reverse(*need));
    largest.truncate(workers.max(1));
    let Some(&(_, first)) = largest.first() else { return Ok(()) };
    let need = largest.iter().fold(0u64, |sum, (n, _)| sum.saturating_add(*n));
    let at_once = largest.len();
    let held = if at_once > 1 {
        format!(" for the {at_once} simulations run at once (--jobs {workers}; fewer at a time need less)")
    } else {
        String::new()
    };
    check_need(first, need, held)
}

/// Refuses `need` bytes beyond the memory this process may use, naming the largest simulation
/// (`params`) and what the bytes are for (`held`).
fn check_need(params: &Params, need: u64, held: String) -> Result<(), RunError> {
    match memory_limit()? {
        Some((limit, what)) if need > limit => Err(RunError::Memory {
            box_size: params.box_size,
            n_cells: params.n_cells,
            need_mb: need >> 20,
            held,
            limit: what,
            limit_mb: limit >> 20,
        }),
        _ => Ok(()),
    }
}

/// Refuses a frame interval (given as `flag`) longer than the active phase of `params`: such a
/// run writes no frame of its activity, only the one at the end of the relaxation. A run of no
/// active steps has no interval to check.
pub fn check_frame_interval(flag: &str, frame_interval: u64, params: &Params) -> Result<(), RunError> {
    if frame_interval == 0 {
        return Err(RunError::invalid(flag, 0, "≥ 1"));
    }
    if params.active_steps > 0 && frame_interval > params.active_steps {
        return Err(RunError::Options(format!(
            "{flag} {frame_interval}: larger than active_steps = {}, so the run would write no frame of its \
             active phase: give a frame interval in [1, {0}]",
            params.active_steps
        )));
    }
    Ok(())
}

/// A run directory with its record and the simulation it holds, and the directory's lock: one
/// writer per directory, for as long as this value lives.
pub struct RunDir {
    pub dir: PathBuf,
    pub record: RunRecord,
    pub monolayer: Monolayer,
    _lock: RunLock,
}

impl RunDir {
    /// Starts a new run in `dir` (created), refusing a directory that holds a run already.
    ///
    /// ```
    /// use monolayer::run::{RunDir, RunFrames};
    /// use monolayer::Params;
    ///
    /// let dir = std::env::temp_dir().join(format!("monolayer-doc-run-{}", std::process::id()));
    /// let p = Params { box_size: 40, n_cells: 8, relax_steps: 100, active_steps: 100, ..Params::default() };
    /// RunDir::create(&dir, p.clone(), 1, 50)?.execute(false, &mut |_, _| {})?;
    /// // Frames from the end of relaxation: steps 100, 150 and 200, read back whole.
    /// assert_eq!(RunFrames::open(&dir)?.frames.len(), 3);
    /// assert!(RunDir::create(&dir, p, 1, 50).is_err()); // never written over
    /// # std::fs::remove_dir_all(&dir).ok();
    /// # Ok::<(), monolayer::run::RunError>(())
    /// ```
    pub fn create(dir: &Path, params: Params, seed: u64, frame_interval: u64) -> Result<Self, RunError> {
        if frame_interval == 0 {
            return Err(RunError::invalid("frame interval", 0, "≥ 1"));
        }
        params.validate()?;
        check_memory(&params)?;
        check_new_run_dir(dir)?;
        let monolayer = Monolayer::new(params, seed)?;
        fs::create_dir_all(dir.join("frames")).map_err(|e| RunError::io(dir, e))?;
        let lock = RunLock::acquire(dir)?;
        Self::create_locked(lock, dir, monolayer, frame_interval)
    }

    /// [`RunDir::create`] in a directory whose lock the caller holds.
    pub fn create_locked(
        lock: RunLock,
        dir: &Path,
        monolayer: Monolayer,
        frame_interval: u64,
    ) -> Result<Self, RunError> {
        let record = RunRecord::new(monolayer.params().clone(), monolayer.seed(), frame_interval);
        Self::create_from(lock, dir, monolayer, record)
    }

    /// A new run in `dir` (whose lock the caller holds) from `monolayer` at any step and the
    /// record it is to keep. A branch ([`RunRecord::branch`]) starts on a frame: that frame is
    /// written first, measured under the branch's parameters.
    pub fn create_from(
        lock: RunLock,
        dir: &Path,
        mut monolayer: Monolayer,
        mut record: RunRecord,
    ) -> Result<Self, RunError> {
        // Checked again under the lock: another writer may have started here meanwhile.
        check_new_run_dir(dir)?;
        fs::create_dir_all(dir.join("frames")).map_err(|e| RunError::io(dir, e))?;
        remove_stale_temporaries(dir);
        remove_stale_temporaries(&dir.join("frames"));
        remove_stale_temporaries(&dir.join(KEPT_CHECKPOINTS));
        let step = monolayer.step_count();
        if record.branch.is_some() {
            monolayer.evaluate_now()?;
            write_frame(&mut monolayer, &frame_path(dir, step))?;
            record.last_frame_step = Some(step);
        }
        // A checkpoint of the start, before the record: a run killed at any point after its
        // record exists can be resumed.
        write_run_checkpoint(&monolayer, &checkpoint_path(dir), &record)?;
        if record.keep_checkpoints {
            keep_checkpoint(dir, step)?;
        }
        record.save(dir)?;
        Ok(RunDir { dir: dir.to_path_buf(), record, monolayer, _lock: lock })
    }

    /// Opens the run in `dir` at its last checkpoint.
    pub fn resume(dir: &Path) -> Result<Self, RunError> {
        // Refuse what is not a run before putting a lock file into it.
        RunRecord::load(dir)?;
        let lock = RunLock::acquire(dir)?;
        Self::resume_locked(lock, dir)
    }

    /// [`RunDir::resume`] in a directory whose lock the caller holds.
    pub fn resume_locked(lock: RunLock, dir: &Path) -> Result<Self, RunError> {
        let mut record = RunRecord::load(dir)?;
        if record.storage != STORE_NAME {
            return Err(RunError::file(
                &RunRecord::path(dir),
                format!(
                    "the run stores the cells' fields in {} (`storage`), this build in {STORE_NAME}: it would \
                     continue on another trajectory; resume it with a build of the run's precision \
                     (docs/performance.md, \"Storage precision\")",
                    record.storage
                ),
            ));
        }
        let checkpoint = checkpoint_path(dir);
        if !checkpoint.exists() {
            return Err(RunError::file(
                &checkpoint,
                format!(
                    "no checkpoint: the run stopped before it wrote one, so there is nothing to continue; delete {} \
                     and start the run again with --out",
                    dir.display()
                ),
            ));
        }
        // The record's parameters first: an edited key is named, not blamed on the checkpoint.
        check_checkpoint_params(&checkpoint, &record)?;
        let state = read_checkpoint(&checkpoint, record.params.box_size)?;
        let (p, fi, step) = (&record.params, record.frame_interval, state.step);
        let scheduled =
            step == 0 || step == p.relax_steps || (step > p.relax_steps && (step - p.relax_steps).is_multiple_of(fi));
        if step > p.total_steps() || !scheduled {
            return Err(RunError::file(
                &checkpoint,
                format!(
                    "step {step} is not a step this run writes a checkpoint at (0, then relax_steps = {}, then \
                     every frame_interval = {fi} to {}, as run.json says): not this run's checkpoint, or run.json \
                     edited",
                    p.relax_steps,
                    p.total_steps()
                ),
            ));
        }
        if let Some(last) = record.last_frame_step.filter(|&last| step < last) {
            return Err(RunError::file(
                &checkpoint,
                format!(
                    "step {step} is before the run's last frame (step {last} in run.json): not this run's checkpoint"
                ),
            ));
        }
        // A frame is written before the checkpoint of its step: a kill between that checkpoint
        // and run.json leaves the record's last frame behind.
        if step >= p.relax_steps && frame_path(dir, step).exists() {
            record.last_frame_step = Some(step);
        }
        let monolayer = Monolayer::from_saved(record.params.clone(), record.seed, state)
            .map_err(|e| RunError::from(e).context(checkpoint.display().to_string()))?;
        fs::create_dir_all(dir.join("frames")).map_err(|e| RunError::io(dir, e))?;
        remove_stale_temporaries(dir);
        remove_stale_temporaries(&dir.join("frames"));
        remove_stale_temporaries(&dir.join(KEPT_CHECKPOINTS));
        Ok(RunDir { dir: dir.to_path_buf(), record, monolayer, _lock: lock })
    }

    /// Keeps every checkpoint from now on (`DIR/checkpoints/`), recorded in `run.json`; a run
    /// that keeps them already is left as it is.
    pub fn keep_checkpoints(mut self) -> Result<Self, RunError> {
        if !self.record.keep_checkpoints {
            self.record.keep_checkpoints = true;
            self.record.save(&self.dir)?;
        }
        Ok(self)
    }

    /// The engine that steps this run. A new run (no step taken yet) takes `engine`; a resumed
    /// one must ask for the engine it started on, which its record names.
    pub fn with_engine(mut self, engine: Engine) -> Result<Self, RunError> {
        let recorded = Engine::parse(&self.record.engine)?;
        if recorded == engine {
            return Ok(self);
        }
        if self.monolayer.step_count() > 0 || self.record.last_frame_step.is_some() {
            return Err(RunError::file(
                &RunRecord::path(&self.dir),
                format!(
                    "the run was stepped by the {} engine (`engine`), not {}: it would continue on another \
                     trajectory; resume it with --engine {}",
                    recorded.name(),
                    engine.name(),
                    recorded.flag()
                ),
            ));
        }
        if engine == Engine::Gpu && !cfg!(feature = "gpu") {
            return Err(no_gpu());
        }
        self.record.engine = engine.name().into();
        self.record.save(&self.dir)?;
        Ok(self)
    }

    /// Steps to the end of the protocol, writing a frame and a checkpoint every frame interval
    /// of the active phase (and a checkpoint when relaxation ends), then records how it ended.
    /// With `analyze`, `DIR/analysis` is brought up to date at every frame.
    pub fn execute(&mut self, analyze: bool, watch: &mut dyn FnMut(&Monolayer, &Event)) -> Result<(), RunError> {
        let mut live = match analyze {
            true => Some(LiveRun::start(&self.dir, self.monolayer.params(), self.monolayer.step_count())?),
            false => None,
        };
        let outcome = match Engine::parse(&self.record.engine) {
            Ok(Engine::Cpu) => self.protocol(live.as_mut(), watch),
            Ok(Engine::Gpu) => self.protocol_gpu(live.as_mut(), watch),
            Err(e) => Err(Stop::Simulation(RunError::Format(e))),
        };
        self.record.status = match &outcome {
            Ok(()) => RunStatus::Finished,
            Err(Stop::Simulation(e)) => RunStatus::Failed(e.to_string()),
            Err(Stop::Machine(e)) => RunStatus::Stopped(e.to_string()),
            Err(Stop::Signal(name)) => RunStatus::Stopped(format!("signal {name}")),
        };
        let saved = self.record.save(&self.dir);
        match outcome {
            Ok(()) => saved,
            Err(Stop::Simulation(e)) => Err(e),
            Err(Stop::Signal(signal)) => Err(RunError::Interrupted {
                signal,
                detail: format!(
                    " at step {}: `run --resume {}` (or the same sweep again) continues it from its last checkpoint",
                    self.monolayer.step_count(),
                    self.dir.display()
                ),
            }),
            Err(Stop::Machine(e)) => Err(RunError::Resumable { source: Box::new(e), dir: self.dir.clone() }),
        }
    }

    fn protocol(&mut self, live: Option<&mut LiveRun>, watch: &mut dyn FnMut(&Monolayer, &Event)) -> Result<(), Stop> {
        self.drive(live, watch, |m| m.step().map_err(|e| Stop::Simulation(e.into())))
    }

    /// The protocol on the GPU: steps to each step that writes something (the end of the
    /// relaxation, a frame), the state downloaded there into the run's monolayer, which writes
    /// it as the CPU's protocol does. A fault of the model stops the run with the state before
    /// the failing submission as its last good state (`failed: …`). A failure of the device
    /// (lost, an error no scope caught, a readback that failed, a state read back that is not
    /// one) is the machine's: the monolayer keeps the last state taken from the device, and
    /// the run is `stopped: GPU …`, to go on from its last checkpoint.
    #[cfg(feature = "gpu")]
    fn protocol_gpu(
        &mut self,
        live: Option<&mut LiveRun>,
        watch: &mut dyn FnMut(&Monolayer, &Event),
    ) -> Result<(), Stop> {
        use crate::gpu::{GpuRun, GpuRunError};
        let p = self.monolayer.params().clone();
        let total = p.total_steps();
        let fi = self.record.frame_interval;
        // No adapter, a device refused or too small: the machine's lack, not the run's; the run
        // is stopped, and continues where a GPU is.
        let machine = |e: crate::gpu::GpuError| Stop::Machine(RunError::gpu(e).context("--engine gpu"));
        let mut lose = LostGpu::from_env().map_err(Stop::Machine)?;
        let ctx = crate::gpu::GpuContext::new().map_err(machine)?;
        let mut run = GpuRun::new(&ctx, &self.monolayer).map_err(machine)?;
        let device_failed = |e: GpuRunError| Stop::Machine(RunError::gpu(e));
        self.drive(live, watch, |m| {
            let s = run.step_count();
            // The next step that writes, at most one check's worth of steps ahead (so that a
            // signal or the progress bar is seen between submissions).
            let next =
                if s < p.relax_steps { p.relax_steps } else { p.relax_steps + ((s - p.relax_steps) / fi + 1) * fi };
            let to = next.min(total).min(s + run.check_every);
            lose.at(&ctx, LossPoint::BeforeSteps, s);
            let stepped = run.advance(&ctx, to - s);
            // Nothing more is read from a device that failed: `m` keeps the last state taken
            // from it.
            if let Err(e @ GpuRunError::Device { .. }) = stepped {
                return Err(device_failed(e));
            }
            lose.at(&ctx, LossPoint::BeforeDownload, run.step_count());
            *m = run.download_now(&ctx).map_err(|e| device_failed(GpuRunError::device(run.step_count(), e)))?;
            stepped.map_err(|e| Stop::Simulation(RunError::gpu(e)))
        })
    }

    /// The protocol's loop, whichever engine steps: `advance` takes the monolayer one or more
    /// steps, leaving in it the state to write (on a failure of the simulation, the last good
    /// one, which is written aside; on one of the machine, the last state it holds); between
    /// calls a signal stops the run, and every frame or checkpoint due is written.
    fn drive(
        &mut self,
        mut live: Option<&mut LiveRun>,
        watch: &mut dyn FnMut(&Monolayer, &Event),
        mut advance: impl FnMut(&mut Monolayer) -> Result<(), Stop>,
    ) -> Result<(), Stop> {
        let total = self.monolayer.params().total_steps();
        let (m, dir, record) = (&mut self.monolayer, &self.dir, &mut self.record);
        while m.step_count() < total {
            if let Some((name, _)) = stop_signal() {
                return Err(Stop::Signal(name));
            }
            match advance(m) {
                Ok(()) => {}
                Err(Stop::Simulation(e)) => return Err(unstable(m, dir, record, e)),
                Err(stop) => return Err(stop),
            }
            watch(m, &Event::Step);
            write_scheduled(m, dir, record, live.as_deref_mut(), watch)?;
        }
        Ok(())
    }

    /// A run of the GPU engine in a build without it: the build's lack, not the run's; the run
    /// is stopped, and continues in a build with the GPU kernels.
    #[cfg(not(feature = "gpu"))]
    fn protocol_gpu(&mut self, _: Option<&mut LiveRun>, _: &mut dyn FnMut(&Monolayer, &Event)) -> Result<(), Stop> {
        Err(Stop::Machine(no_gpu()))
    }
}

/// Where a run of the GPU engine loses its device on demand ([`LostGpu`]).
#[cfg(feature = "gpu")]
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum LossPoint {
    /// Right before the steps from the step given are submitted: the check of their faults
    /// fails, as under a driver reset while the device steps.
    BeforeSteps,
    /// Once the run has stepped to the step given, before the state there is read back: the
    /// download fails.
    BeforeDownload,
}

/// A GPU lost on demand, for the tests of what a run does then (tests/gpu.rs, docs/gpu-testing.md):
/// `MONOLAYER_TEST_LOSE_GPU=steps@STEP` or `download@STEP` destroys the run's device
/// (`wgpu::Device::destroy`, which wgpu reports as a loss) at that [`LossPoint`], the first
/// time the run is there at STEP or later. Only the tests set it.
#[cfg(feature = "gpu")]
struct LostGpu(Option<(LossPoint, u64)>);

#[cfg(feature = "gpu")]
impl LostGpu {
    const VAR: &'static str = "MONOLAYER_TEST_LOSE_GPU";

    /// The loss asked for by [`Self::VAR`], if any; a value that is not one is refused, so that
    /// a test cannot pass by losing nothing.
    fn from_env() -> Result<Self, RunError> {
        let text = match std::env::var(Self::VAR) {
            Err(std::env::VarError::NotPresent) => return Ok(LostGpu(None)),
            Err(std::env::VarError::NotUnicode(v)) => v.to_string_lossy().into_owned(),
            Ok(text) => text,
        };
        let loss = text.split_once('@').and_then(|(point, step)| {
            let point = match point {
                "steps" => LossPoint::BeforeSteps,
                "download" => LossPoint::BeforeDownload,
                _ => return None,
            };
            Some((point, step.parse().ok()?))
        });
        match loss {
            Some(loss) => Ok(LostGpu(Some(loss))),
            None => {
                Err(RunError::invalid(format!("{} =", Self::VAR), format!("{text:?}"), "steps@STEP or download@STEP"))
            }
        }
    }

    /// Destroys the device if the run is at the point asked for, at its step or later; once.
    fn at(&mut self, ctx: &crate::gpu::GpuContext, point: LossPoint, step: u64) {
        if self.0.is_some_and(|(p, from)| p == point && step >= from) {
            self.0 = None;
            ctx.destroy();
        }
    }
}

/// A run that went unstable: `m` (its last good state) is written to `last_good_state.npz`
/// and the error names it beside the last periodic checkpoint.
fn unstable(m: &Monolayer, dir: &Path, record: &RunRecord, e: RunError) -> Stop {
    let last_good = dir.join(LAST_GOOD_STATE);
    if let Err(io) = write_run_checkpoint(m, &last_good, record) {
        return Stop::Machine(io);
    }
    Stop::Simulation(RunError::Unstable { source: Box::new(e), last_good, checkpoint: checkpoint_path(dir) })
}

/// What the protocol writes at the monolayer's step, if anything: a frame every frame interval
/// of the active phase (with the live analysis), a checkpoint with it and at the end of the
/// relaxation, and the record.
fn write_scheduled(
    m: &mut Monolayer,
    dir: &Path,
    record: &mut RunRecord,
    live: Option<&mut LiveRun>,
    watch: &mut dyn FnMut(&Monolayer, &Event),
) -> Result<(), Stop> {
    let p = m.params().clone();
    let s = m.step_count();
    let frame = s >= p.relax_steps && (s - p.relax_steps).is_multiple_of(record.frame_interval);
    if frame {
        m.evaluate_now().map_err(|e| Stop::Simulation(e.into()))?;
        write_frame(m, &frame_path(dir, s)).map_err(Stop::Machine)?;
        if let Some(Err(e)) = live.map(|live| live.frame(m)) {
            watch(m, &Event::AnalysisFailed(e.to_string()));
        }
    }
    if frame || s == p.relax_steps {
        write_run_checkpoint(m, &checkpoint_path(dir), record).map_err(Stop::Machine)?;
        if record.keep_checkpoints {
            keep_checkpoint(dir, s).map_err(Stop::Machine)?;
        }
        // The record's last frame advances only once the checkpoint of its step is safely
        // written: a failed checkpoint write (a full disk) leaves the record at the previous
        // checkpoint, which `--resume` continues from.
        if frame {
            record.last_frame_step = Some(s);
        }
        record.save(dir).map_err(Stop::Machine)?;
        if frame {
            watch(m, &Event::Frame);
        }
    }
    Ok(())
}

/// Refuses to start a new run in `dir` unless it is new, empty, or holds only what a start that
/// wrote nothing leaves (a `.lock`, an empty `frames/`, temporaries): a new run would replace the
/// checkpoint and the first frames of whatever is there and leave the rest mixed in. The error
/// says how to continue the run that is there, or where to write instead.
fn check_new_run_dir(dir: &Path) -> Result<(), RunError> {
    if RunRecord::path(dir).exists() {
        return Err(already_a_run(dir));
    }
    let held = match fs::read_dir(dir) {
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
        Err(e) => return Err(RunError::io(dir, e)),
        Ok(entries) => entries.flatten().map(|e| e.path()).filter(|p| !left_by_an_empty_start(p)).collect::<Vec<_>>(),
    };
    if held.is_empty() {
        return Ok(());
    }
    let mut names: Vec<String> =
        held.iter().filter_map(|p| p.file_name()).map(|n| n.to_string_lossy().into()).collect();
    names.sort();
    let shown = if names.len() > 5 { format!("{}, …", names[..5].join(", ")) } else { names.join(", ") };
    let of_a_run = names.iter().any(|n| n == CHECKPOINT || n == "frames" || n == LAST_GOOD_STATE);
    let why = if of_a_run {
        format!(
            "holds the files of a run ({shown}) but no run.json: a run killed before it wrote its record, which \
             cannot be resumed without it; nothing here was changed: delete {} to start it again, or choose \
             another --out",
            dir.display()
        )
    } else {
        format!("is not empty ({shown}): a new run is written into a new or empty directory; choose another --out")
    };
    Err(RunError::OtherRun { dir: dir.to_path_buf(), why })
}

/// What a start that wrote nothing leaves in a run directory: its lock file, temporaries of
/// writes it did not finish, and a `frames/` holding nothing else.
fn left_by_an_empty_start(path: &Path) -> bool {
    let name = path.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_default();
    let temporary = |n: &str| n.starts_with('.') && n.ends_with(".tmp");
    match name.as_str() {
        RunLock::FILE => true,
        n if temporary(n) => true,
        "frames" => fs::read_dir(path)
            .is_ok_and(|entries| entries.flatten().all(|e| temporary(&e.file_name().to_string_lossy()))),
        _ => false,
    }
}

fn already_a_run(dir: &Path) -> RunError {
    let why = if checkpoint_path(dir).exists() {
        format!("already holds a run: continue it with --resume {}, or choose another --out", dir.display())
    } else {
        "already holds a run that stopped before its first checkpoint: delete it to start again, or choose another \
         --out"
            .to_string()
    };
    RunError::OtherRun { dir: dir.to_path_buf(), why }
}

/// `--engine gpu` in a build without feature `gpu`.
fn no_gpu() -> RunError {
    RunError::Gpu(
        "--engine gpu: this binary was built without the GPU kernels: cargo build --release --features gpu".into(),
    )
}

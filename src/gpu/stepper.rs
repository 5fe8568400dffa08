//! Many steps on the GPU, as `Monolayer::advance` takes them: the switch from relaxation to
//! activity at `relax_steps`, and the faults checked after every submission of a few dozen
//! steps with one small readback, the state put back to the start of that submission when one
//! is found (the CPU's rule: an unstable run stops, naming when and where, and keeps its last
//! good state).
//!
//! The same code on both targets: a submission is recorded at once ([`GpuRun::submit`]), its
//! faults arrive as a future ([`GpuRun::next_faults`]) that a browser awaits from its event
//! loop and a native caller blocks on ([`GpuRun::advance`]), and [`GpuRun::settle`] decides. Up
//! to [`IN_FLIGHT`] submissions are under way at once, so that the device steps the next while
//! the host reads the last one's faults; a submission put back takes the ones after it along,
//! their readbacks with them.

use crate::gpu::buffers::{patch_storage, GpuPatch, Layout, PatchFault, Slot, SolveScalars, NO_FAULT};
use crate::gpu::context::{GpuContext, GpuError};
use crate::gpu::iterations::{steps_per_submission, AfterFailure, IterationRule};
use crate::gpu::kernels::{GpuMonolayer, Pipelines};
use crate::gpu::readback::read_words;
use crate::model::{Monolayer, Params, Patch, Phase, State};
use num_complex::Complex64 as C64;
use std::collections::VecDeque;
use std::future::Future;
use std::pin::Pin;

/// Why a GPU run stopped; the state is back at the start of the steps named.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GpuRunError {
    #[error("in steps {from}..{to}: cell {cell}'s φ left [phi_min, phi_max] (first at padded index {site}); the state is back at step {from}")]
    Unstable { from: u64, to: u64, cell: usize, site: u32 },
    #[error("in steps {from}..{to}: cell {cell} lost its patch ({why}); the state is back at step {from}")]
    CellLost { from: u64, to: u64, cell: usize, why: &'static str },
    #[error("in steps {from}..{to}: cell {cell}'s patch outgrew its GPU storage; the state is back at step {from}, to be uploaded again with more room")]
    BeyondCapacity { from: u64, to: u64, cell: usize },
    #[error("at step {from}: the state could not be uploaded again with more room: {reason}")]
    Regrow { from: u64, reason: String },
    #[error("in steps {from}..{to}: {count} friction solves missed their tolerance in the recorded iterations; the state is back at step {from}")]
    Friction { from: u64, to: u64, count: u32 },
    #[error("in steps {from}..{to}: {count} friction solves met their tolerance on the CG's own residual but not on the true one, F − C u (f32 drift); the state is back at step {from}")]
    Inaccurate { from: u64, to: u64, count: u32 },
    /// The device failed (lost, an error no scope caught, a readback that did not map or a
    /// state read back that is not one): the machine's problem, not the model's. Nothing it
    /// computed after step `from` is used; the last state taken from it is the last good one.
    #[error("GPU device failed after step {from}: {reason}")]
    Device { from: u64, reason: String },
}

impl GpuRunError {
    /// The device's failure `e`, met after step `from`.
    pub fn device(from: u64, e: GpuError) -> Self {
        let reason = match e {
            GpuError::Failed(why) => why,
            other => other.to_string(),
        };
        GpuRunError::Device { from, reason }
    }
}

/// The sticky faults of one submission, read back together.
#[derive(Clone, Debug)]
pub struct Faults {
    /// The submission they are of (`Pending::id`).
    pub submission: u64,
    /// Per cell, the first padded index where φ left its range, or [`NO_FAULT`].
    pub range: Vec<u32>,
    /// Per cell, a [`PatchFault`] code.
    pub patch: Vec<u32>,
    pub solve: SolveScalars,
}

impl Faults {
    /// The first fault, in the order the CPU would meet them (φ's range is checked inside the
    /// step, the patches after it, the solves' count is the GPU's own).
    fn error(&self, from: u64, to: u64) -> Option<GpuRunError> {
        if let Some((cell, &site)) = self.range.iter().enumerate().find(|(_, &f)| f != NO_FAULT) {
            return Some(GpuRunError::Unstable { from, to, cell, site });
        }
        for (cell, &code) in self.patch.iter().enumerate() {
            let why = match PatchFault::from_code(code) {
                Some(PatchFault::Moved) => continue,
                Some(PatchFault::BeyondCapacity) => return Some(GpuRunError::BeyondCapacity { from, to, cell }),
                Some(PatchFault::Vanished) => "vanished: no site above the presence threshold",
                Some(PatchFault::SpansTheBox) => "its patch would span the box",
                None => "an unknown fault code",
            };
            return Some(GpuRunError::CellLost { from, to, cell, why });
        }
        if self.solve.unconverged > 0 {
            return Some(GpuRunError::Friction { from, to, count: self.solve.unconverged });
        }
        (self.solve.inaccurate > 0).then_some(GpuRunError::Inaccurate { from, to, count: self.solve.inaccurate })
    }
}

/// The CPU monolayer at `step` of a download's words: each cell's patch and its φ (the storage
/// the patch names within the per-cell array, rounded from f32), and the warm start. What is
/// not a state (a patch outside the box or pointing past the array, what `Monolayer::from_state`
/// refuses) is an error saying why, not a panic: a device that failed can return anything.
/// Values are not checked: the kernels check φ at every step (a fault puts the state back),
/// and a download is the state as it is on the device, which may hold φ out of range (one
/// uploaded so, as a test does; in a browser, one queued behind a submission that is then put
/// back, and never used).
fn downloaded_state(
    params: Params,
    seed: u64,
    step: u64,
    substrate: Vec<f64>,
    patches: &[u32],
    phi: &[u32],
    u: &[u32],
) -> Result<Monolayer, String> {
    let l = params.box_size;
    // The buffer holds whole `GpuPatch`es, made so by `DeviceState::upload`, whatever the device
    // wrote into them.
    let patches: &[GpuPatch] = bytemuck::cast_slice(patches);
    let mut cells: Vec<(Patch, Vec<f64>)> = Vec::with_capacity(patches.len());
    for (i, p) in patches.iter().enumerate() {
        let patch = p.patch();
        // Within the box first (as `Monolayer::from_state` asks), so that the padded length
        // below cannot overflow; then within the array.
        let in_box = patch.x0 < l && patch.y0 < l && patch.w < l && patch.h < l;
        let end = p.offset as usize + patch.padded_len();
        if !in_box || end > phi.len() {
            return Err(format!(
                "cell {i}: patch {patch:?} at offset {} does not fit the box ({l}) and the array ({} values)",
                p.offset,
                phi.len()
            ));
        }
        cells.push((patch, patch_storage(*p, phi).iter().map(|&v| f32::from_bits(v) as f64).collect()));
    }
    let u: Vec<f32> = u.iter().map(|&w| f32::from_bits(w)).collect();
    let warm_start: Vec<C64> = u.chunks_exact(2).map(|c| C64::new(c[0] as f64, c[1] as f64)).collect();
    // The GPU's corrector starts from its predictor's solution alone (docs/gpu.md).
    let corrector_shift = vec![C64::new(0.0, 0.0); warm_start.len()];
    let state = State { step, cells, warm_start, corrector_shift, substrate };
    Monolayer::from_state(params, seed, state).map_err(|e| e.to_string())
}

/// The per-cell and lattice buffers a step changes, of which a copy keeps the state at the
/// start of each submission.
const KEPT: [Slot; 3] = [Slot::Phi, Slot::Patches, Slot::MeanVelocity];

/// Submissions under way at most: the one whose faults are being read, and the next, which
/// the device steps meanwhile. Each keeps its own copy of the state at its start.
pub const IN_FLIGHT: usize = 2;

/// The faults of a submission, on their way back.
pub type FaultsReadback = Pin<Box<dyn Future<Output = Result<Faults, GpuError>>>>;

/// A submission not settled yet: its steps, the state at their start kept in copy
/// [`kept_copy`], and the readback of its faults, queued right behind it, until
/// [`GpuRun::next_faults`] hands it out.
struct Pending {
    /// Which submission (increasing); [`Faults::submission`] names it.
    id: u64,
    from: u64,
    to: u64,
    faults: Option<FaultsReadback>,
}

/// Which copy of the state a submission keeps: consecutive submissions, the ones under way
/// together, take different copies.
fn kept_copy(submission: u64) -> usize {
    (submission % IN_FLIGHT as u64) as usize
}

/// Which way [`GpuRun::copy_kept`] copies.
#[derive(Clone, Copy)]
enum Keep {
    Store,
    Restore,
}

/// A monolayer stepped on the GPU from a CPU state.
pub struct GpuRun {
    gpu: GpuMonolayer,
    params: Params,
    seed: u64,
    /// Steps taken and checked.
    step: u64,
    /// The submissions not yet settled, oldest first.
    pending: VecDeque<Pending>,
    /// The id of the next submission.
    next_id: u64,
    substrate: Vec<f64>,
    xi_s: Vec<f64>,
    /// Per submission in flight, the state at its start ([`KEPT`]).
    kept: Vec<Vec<wgpu::Buffer>>,
    /// Steps between fault checks (each check one readback of a few hundred bytes).
    pub check_every: u64,
    /// Submissions [`Self::advance`] keeps under way, 1 to [`IN_FLIGHT`] (default
    /// [`IN_FLIGHT`]; the same steps either way).
    pub max_in_flight: usize,
    /// Whether the recorded solve iterations follow what the solves need ([`Self::settle`]).
    pub adapt_iterations: bool,
    /// How they follow it; made from the recorded count when first needed, and again when the
    /// count was set from outside.
    rule: Option<IterationRule>,
}

/// The recorded solve iterations, when adapted ([`IterationRule`]), stay within these
/// multiples of the preconditioner's default ([`GpuMonolayer::set_preconditioner`]): a quarter
/// of it (the multigrid's 30 → 7; a warm-started solve inside a run takes 3–5) to eight times.
const FEWEST_ITERATIONS: f64 = 0.25;
const MOST_ITERATIONS: usize = 8;

fn kept_buffers(ctx: &GpuContext, gpu: &GpuMonolayer) -> Vec<Vec<wgpu::Buffer>> {
    let one = || {
        KEPT.iter()
            .map(|&s| {
                ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("kept"),
                    size: gpu.state().buffer(s).size(),
                    usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            })
            .collect()
    };
    (0..IN_FLIGHT).map(|_| one()).collect()
}

impl GpuRun {
    /// Uploads the monolayer's state, in its current phase.
    pub fn new(ctx: &GpuContext, m: &Monolayer) -> Result<Self, GpuError> {
        Self::with_pipelines(ctx, Pipelines::new(ctx), m)
    }

    /// [`Self::new`] with pipelines compiled beforehand ([`crate::gpu::compile`]).
    pub fn with_pipelines(ctx: &GpuContext, pipelines: Pipelines, m: &Monolayer) -> Result<Self, GpuError> {
        let gpu = GpuMonolayer::with_pipelines(ctx, pipelines, m)?;
        let kept = kept_buffers(ctx, &gpu);
        Ok(GpuRun {
            gpu,
            params: m.params().clone(),
            seed: m.seed(),
            step: m.step_count(),
            pending: VecDeque::new(),
            next_id: 0,
            substrate: m.lattice().substrate.clone(),
            xi_s: m.lattice().xi_s.clone(),
            kept,
            check_every: 50,
            max_in_flight: IN_FLIGHT,
            adapt_iterations: true,
            rule: None,
        })
    }

    /// Replaces the state by the monolayer's (its parameters, substrate and cells may have
    /// changed), keeping the compiled kernels; each cell's storage is sized anew from its patch.
    pub fn upload(&mut self, ctx: &GpuContext, m: &Monolayer) -> Result<(), GpuError> {
        self.upload_in(ctx, m, Layout::of(m))
    }

    /// [`Self::upload`] in a given layout (tests: a capacity the patches soon outgrow).
    pub fn upload_in(&mut self, ctx: &GpuContext, m: &Monolayer, layout: Layout) -> Result<(), GpuError> {
        self.gpu.upload_in(ctx, m, layout)?;
        self.kept = kept_buffers(ctx, &self.gpu);
        self.params = m.params().clone();
        self.seed = m.seed();
        self.step = m.step_count();
        // Whatever was under way ran on the buffers replaced: its faults settle nothing.
        self.pending.clear();
        self.substrate = m.lattice().substrate.clone();
        self.xi_s = m.lattice().xi_s.clone();
        Ok(())
    }

    pub fn step_count(&self) -> u64 {
        self.step
    }

    /// The step the submissions under way end at (the steps taken, if none is).
    pub fn submitted_to(&self) -> u64 {
        self.pending.back().map_or(self.step, |p| p.to)
    }

    /// Submissions under way, not yet settled (at most [`IN_FLIGHT`]).
    pub fn in_flight(&self) -> usize {
        self.pending.len()
    }

    pub fn params(&self) -> &Params {
        &self.params
    }

    pub fn gpu(&self) -> &GpuMonolayer {
        &self.gpu
    }

    /// The GPU's own settings: the recorded solve iterations and the preconditioner.
    pub fn gpu_mut(&mut self) -> &mut GpuMonolayer {
        &mut self.gpu
    }

    fn phase_at(&self, step: u64) -> Phase {
        if step < self.params.relax_steps {
            Phase::Relaxation
        } else {
            Phase::Active
        }
    }

    /// Keeps the state, then records up to `n` steps in one submission after those under way:
    /// at most `check_every`, and none across the switch to activity, with the readback of
    /// their faults right behind them ([`Self::next_faults`]). Returns the steps submitted, 0
    /// if there is nothing to submit (`n` = 0).
    ///
    /// # Panics
    /// If [`IN_FLIGHT`] submissions are under way already (settle the oldest first).
    pub fn submit(&mut self, ctx: &GpuContext, n: u64) -> u64 {
        assert!(self.pending.len() < IN_FLIGHT, "at most {IN_FLIGHT} submissions under way: settle the oldest first");
        let from = self.submitted_to();
        let phase = self.phase_at(from);
        if self.gpu.state().params.active != (phase == Phase::Active) as u32 {
            self.gpu.state_mut().set_phase(ctx, &self.params, phase, &self.xi_s);
        }
        let one = self.gpu.step_kernels();
        let mut steps = steps_per_submission(self.check_every.max(1).min(n), one.len());
        if phase == Phase::Relaxation {
            steps = steps.min(self.params.relax_steps - from);
        }
        if steps == 0 {
            return 0;
        }
        let id = self.next_id;
        self.next_id += 1;
        // Queue writes land after the submissions before and before this one: each submission
        // starts with no faults, and its readback, queued next, sees its own.
        self.gpu.state().reset_faults(ctx);
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("steps") });
        self.copy_kept(&mut encoder, kept_copy(id), Keep::Store);
        for _ in 0..steps {
            self.gpu.encode(&mut encoder, &one);
        }
        ctx.queue.submit([encoder.finish()]);
        let faults = Some(Box::pin(self.read_faults(ctx, id)) as FaultsReadback);
        self.pending.push_back(Pending { id, from, to: from + steps, faults });
        steps
    }

    /// The readback of the faults of the oldest submission under way not handed out yet, for
    /// [`Self::settle`] once it resolves; `None` if there is none.
    pub fn next_faults(&mut self) -> Option<FaultsReadback> {
        self.pending.iter_mut().find_map(|p| p.faults.take())
    }

    /// The iteration rule, in step with the recorded count (made anew if it was set from
    /// outside, or the preconditioner changed).
    fn rule(&mut self) -> &mut IterationRule {
        let (default, recorded) = (self.gpu.preconditioner.default_iterations(), self.gpu.solve_iterations);
        let fewest = ((default as f64 * FEWEST_ITERATIONS) as usize).max(1);
        let most = MOST_ITERATIONS * default;
        let stale = self.rule.as_ref().is_none_or(|r| r.recorded != recorded || r.most != most);
        if stale {
            self.rule = Some(IterationRule::new(recorded, fewest, most));
        }
        self.rule.as_mut().expect("made above")
    }

    /// Copies the state aside into copy `index` (before a submission) or back from it (after a
    /// fault).
    fn copy_kept(&self, encoder: &mut wgpu::CommandEncoder, index: usize, keep: Keep) {
        for (&slot, kept) in KEPT.iter().zip(&self.kept[index]) {
            let live = self.gpu.state().buffer(slot);
            let (from, to) = match keep {
                Keep::Store => (live, kept),
                Keep::Restore => (kept, live),
            };
            encoder.copy_buffer_to_buffer(from, 0, to, 0, kept.size());
        }
    }

    /// The sticky faults as they are after the last submission: one readback. An error if the
    /// device failed (lost, or the readback did not map): nothing it computed is used then.
    fn read_faults(
        &self,
        ctx: &GpuContext,
        submission: u64,
    ) -> impl Future<Output = Result<Faults, GpuError>> + 'static {
        let s = self.gpu.state();
        let words = read_words(ctx, &[s.buffer(Slot::Fault), s.buffer(Slot::PatchFault), s.buffer(Slot::Solve)]);
        async move {
            // Three buffers asked for, three read: `read_words` returns a vector per buffer.
            let [range, patch, solve]: [Vec<u32>; 3] = words.await?.try_into().expect("three buffers read");
            Ok(Faults { submission, range, patch, solve: *bytemuck::from_bytes(bytemuck::cast_slice(&solve)) })
        }
    }

    /// Takes the faults of the oldest submission under way: accepts its steps (`Ok(true)`), or
    /// on a fault puts the state kept at their start back, and the submissions after it with
    /// it (they stepped from a state not taken). Faults of a submission already put back so
    /// settle nothing (`Ok(false)`). A solve that missed its tolerance within the recorded
    /// iterations, while they may still grow (`adapt_iterations`), grows them and asks for the
    /// same steps again (`Ok(false)`): a solve that converges gives the same bits whatever the
    /// iterations recorded after it, so the run is the one a larger count would have made.
    /// Otherwise the error says what happened. After accepted steps the count follows what the
    /// solves took (`IterationRule`: lowered slowly, never back to a count that failed lately).
    pub fn settle(&mut self, ctx: &GpuContext, faults: &Faults) -> Result<bool, GpuRunError> {
        if self.pending.front().is_none_or(|p| p.id != faults.submission) {
            return Ok(false);
        }
        let settling = self.pending.pop_front().expect("checked above");
        let (from, to) = (settling.from, settling.to);
        let adapts = self.adapt_iterations && self.gpu.solve().is_some();
        let error = match faults.error(from, to) {
            None => {
                if adapts {
                    let rule = self.rule();
                    rule.accepted(faults.solve.most_iterations as usize);
                    self.gpu.solve_iterations = rule.recorded;
                }
                self.step = to;
                return Ok(true);
            }
            Some(e @ GpuRunError::Friction { .. }) if adapts => match self.rule().failed() {
                AfterFailure::Retry(n) => {
                    self.gpu.solve_iterations = n;
                    None
                }
                AfterFailure::GiveUp => Some(e),
            },
            Some(e) => Some(e),
        };
        // Queued behind the submissions put back with this one, so it is their end it replaces.
        self.pending.clear();
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("restore") });
        self.copy_kept(&mut encoder, kept_copy(settling.id), Keep::Restore);
        ctx.queue.submit([encoder.finish()]);
        error.map_or(Ok(false), Err)
    }

    /// The state on the device after every step submitted so far, as a CPU monolayer (φ
    /// rounded from f32), at [`Self::submitted_to`]: one readback, queued now. With
    /// submissions under way it is their end, to be used once they are accepted. An error if
    /// the device failed, or if what it returned is not a state as every accepted step leaves
    /// one (`downloaded_state`).
    pub fn download(&self, ctx: &GpuContext) -> impl Future<Output = Result<Monolayer, GpuError>> + 'static {
        let s = self.gpu.state();
        let words = read_words(ctx, &[s.buffer(Slot::Patches), s.buffer(Slot::Phi), s.buffer(Slot::MeanVelocity)]);
        let (params, seed, step, substrate) =
            (self.params.clone(), self.seed, self.submitted_to(), self.substrate.clone());
        async move {
            // Three buffers asked for, three read: `read_words` returns a vector per buffer.
            let [patches, phi, u]: [Vec<u32>; 3] = words.await?.try_into().expect("three buffers read");
            downloaded_state(params, seed, step, substrate, &patches, &phi, &u)
                .map_err(|why| GpuError::Failed(format!("the state it returned is not valid: {why}")))
        }
    }

    /// `n` steps, blocking (native): submissions of at most `check_every` steps, each checked,
    /// [`IN_FLIGHT`] under way at once. A cell that outgrows its storage is met as the CPU would
    /// never meet it: the state of the start of that submission is uploaded again with room for
    /// the patches it has then, and the steps are taken again. On any other fault the state is
    /// back at the start of the submission and the error names its steps and the cell. A device
    /// that fails is [`GpuRunError::Device`], after the last steps accepted; the submissions
    /// under way are dropped with it, and nothing more is read from the device.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn advance(&mut self, ctx: &GpuContext, n: u64) -> Result<(), GpuRunError> {
        let end = self.submitted_to() + n;
        let mut regrown_at = None;
        while self.step < end {
            while self.in_flight() < self.max_in_flight.clamp(1, IN_FLIGHT) {
                if self.submit(ctx, end - self.submitted_to()) == 0 {
                    break;
                }
            }
            // With steps left and fewer than `max_in_flight` under way, `submit` took at least
            // one step; every readback handed out here is settled below or dropped with all the
            // submissions under way (a device failure), so the oldest still has its own.
            let readback = self.next_faults().expect("a submission is under way while steps are left");
            let faults = pollster::block_on(readback).map_err(|e| self.device_failed(e))?;
            match self.settle(ctx, &faults) {
                Err(GpuRunError::BeyondCapacity { from, .. }) if regrown_at != Some(from) => {
                    regrown_at = Some(from);
                    self.regrow(ctx)?;
                }
                result => {
                    result?;
                }
            }
        }
        Ok(())
    }

    /// The device failed: the submissions under way are dropped (nothing they computed is
    /// used, and their readbacks would fail too), the steps taken stay those accepted.
    #[cfg(not(target_arch = "wasm32"))]
    fn device_failed(&mut self, e: GpuError) -> GpuRunError {
        self.pending.clear();
        GpuRunError::device(self.step, e)
    }

    /// Uploads the state again, each cell's storage sized anew from its patch now (blocking;
    /// native). The browser's engine does the same with [`Self::download`] awaited. A download
    /// that fails is the device's failure ([`GpuRunError::Device`]); a state the device cannot
    /// hold, [`GpuRunError::Regrow`].
    #[cfg(not(target_arch = "wasm32"))]
    pub fn regrow(&mut self, ctx: &GpuContext) -> Result<(), GpuRunError> {
        let m = self.download_now(ctx).map_err(|e| self.device_failed(e))?;
        self.upload(ctx, &m).map_err(|e| GpuRunError::Regrow { from: self.step, reason: e.to_string() })
    }

    /// [`Self::download`], blocking (native). An error if the device failed: natively a failed
    /// device ends the run (wgpu has no device to go on with, and the CPU engine cannot
    /// continue a GPU run's record), which resumes from its last checkpoint.
    #[cfg(not(target_arch = "wasm32"))]
    pub fn download_now(&self, ctx: &GpuContext) -> Result<Monolayer, GpuError> {
        pollster::block_on(self.download(ctx))
    }
}

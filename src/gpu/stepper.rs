//! Many steps on the GPU, as `Monolayer::advance` takes them: the switch from relaxation to
//! activity at `relax_steps`, and the faults checked every so many steps with one small
//! readback, the state put back to the last check when one is found (the CPU's rule: an
//! unstable run stops, naming when and where, and keeps its last good state).
//!
//! Native only for now: the checks block on the device (in a browser they would map
//! asynchronously, which the page's worker is to do).

use crate::gpu::buffers::{PatchFault, Slot, NO_FAULT};
use crate::gpu::context::GpuContext;
use crate::gpu::kernels::{GpuMonolayer, Kernel};
use crate::model::lattice::Patch;
use crate::model::monolayer::{Monolayer, Phase, State};
use crate::model::params::Params;
use num_complex::Complex64 as C64;

/// Why a GPU run stopped; the state is back at the start of the steps named.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
pub enum GpuRunError {
    #[error("in steps {from}..{to}: cell {cell}'s φ left [phi_min, phi_max] (first at padded index {site}); the state is back at step {from}")]
    Unstable { from: u64, to: u64, cell: usize, site: u32 },
    #[error("in steps {from}..{to}: cell {cell} lost its patch ({why}); the state is back at step {from}")]
    CellLost { from: u64, to: u64, cell: usize, why: &'static str },
    #[error("in steps {from}..{to}: {count} friction solves missed their tolerance in the recorded iterations; the state is back at step {from}")]
    Friction { from: u64, to: u64, count: u32 },
}

/// The per-cell and lattice buffers a step changes and the copies that keep the last check's
/// state.
const KEPT: [Slot; 3] = [Slot::Phi, Slot::Patches, Slot::MeanVelocity];

/// A monolayer stepped on the GPU from a CPU state.
pub struct GpuRun {
    gpu: GpuMonolayer,
    params: Params,
    seed: u64,
    step: u64,
    substrate: Vec<f64>,
    xi_s: Vec<f64>,
    kept: Vec<wgpu::Buffer>,
    /// Steps between fault checks (each check one readback of a few hundred bytes).
    pub check_every: u64,
}

impl GpuRun {
    /// Uploads the monolayer's state, in its current phase.
    pub fn new(ctx: &GpuContext, m: &Monolayer) -> Result<Self, crate::gpu::GpuError> {
        let gpu = GpuMonolayer::new(ctx, m)?;
        let kept = KEPT
            .iter()
            .map(|&s| {
                ctx.device.create_buffer(&wgpu::BufferDescriptor {
                    label: Some("kept"),
                    size: gpu.state().buffer(s).size(),
                    usage: wgpu::BufferUsages::COPY_SRC | wgpu::BufferUsages::COPY_DST,
                    mapped_at_creation: false,
                })
            })
            .collect();
        Ok(GpuRun {
            gpu,
            params: m.params().clone(),
            seed: m.seed(),
            step: m.step_count(),
            substrate: m.lattice().substrate.clone(),
            xi_s: m.lattice().xi_s.clone(),
            kept,
            check_every: 50,
        })
    }

    pub fn step_count(&self) -> u64 {
        self.step
    }

    pub fn gpu(&self) -> &GpuMonolayer {
        &self.gpu
    }

    fn phase_at(&self, step: u64) -> Phase {
        if step < self.params.relax_steps {
            Phase::Relaxation
        } else {
            Phase::Active
        }
    }

    /// `n` steps: in submissions of at most `check_every` steps that do not cross into the
    /// active phase, each followed by a check of the faults. On a fault the state is put back to
    /// the start of that submission and the error names its steps and the cell.
    pub fn advance(&mut self, ctx: &GpuContext, n: u64) -> Result<(), GpuRunError> {
        let end = self.step + n;
        while self.step < end {
            let phase = self.phase_at(self.step);
            if self.gpu.state().params.active != (phase == Phase::Active) as u32 {
                self.gpu.state_mut().set_phase(ctx, &self.params, phase, &self.xi_s);
            }
            let mut batch = self.check_every.max(1).min(end - self.step);
            if phase == Phase::Relaxation {
                batch = batch.min(self.params.relax_steps - self.step);
            }
            self.submit(ctx, batch);
            self.check(ctx, self.step, self.step + batch)?;
            self.step += batch;
        }
        Ok(())
    }

    /// Keeps the state, then records `steps` steps, all in one submission.
    fn submit(&self, ctx: &GpuContext, steps: u64) {
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("steps") });
        for (&slot, kept) in KEPT.iter().zip(&self.kept) {
            encoder.copy_buffer_to_buffer(self.gpu.state().buffer(slot), 0, kept, 0, kept.size());
        }
        let one = [self.gpu.step_kernels(), Kernel::MOVE_PATCHES.to_vec()].concat();
        for _ in 0..steps {
            self.gpu.encode(&mut encoder, &one);
        }
        ctx.queue.submit([encoder.finish()]);
    }

    /// Reads the sticky faults; on one, puts the kept state back and says what happened.
    fn check(&self, ctx: &GpuContext, from: u64, to: u64) -> Result<(), GpuRunError> {
        let faults = self.gpu.read_u32(ctx, Slot::Fault);
        let patch_faults = self.gpu.read_u32(ctx, Slot::PatchFault);
        let solve = self.gpu.read_solve(ctx);
        let error = if let Some((cell, &site)) = faults.iter().enumerate().find(|(_, &f)| f != NO_FAULT) {
            Some(GpuRunError::Unstable { from, to, cell, site })
        } else if let Some((cell, why)) = patch_faults.iter().enumerate().find_map(|(i, &f)| {
            let why = match PatchFault::from_code(f) {
                Some(PatchFault::Moved) => return None,
                Some(PatchFault::Vanished) => "vanished: no site above the presence threshold",
                Some(PatchFault::SpansTheBox) => "its patch would span the box",
                Some(PatchFault::BeyondCapacity) => "its patch outgrew the GPU storage; upload again",
                None => "an unknown code",
            };
            Some((i, why))
        }) {
            Some(GpuRunError::CellLost { from, to, cell, why })
        } else if solve.unconverged > 0 {
            Some(GpuRunError::Friction { from, to, count: solve.unconverged })
        } else {
            None
        };
        let Some(error) = error else { return Ok(()) };
        let mut encoder = ctx.device.create_command_encoder(&wgpu::CommandEncoderDescriptor { label: Some("restore") });
        for (&slot, kept) in KEPT.iter().zip(&self.kept) {
            encoder.copy_buffer_to_buffer(kept, 0, self.gpu.state().buffer(slot), 0, kept.size());
        }
        ctx.queue.submit([encoder.finish()]);
        self.gpu.state().reset_faults(ctx);
        Err(error)
    }

    /// The state on the device as a CPU monolayer (φ rounded from f32; a readback).
    pub fn download(&self, ctx: &GpuContext) -> Monolayer {
        let patches = self.gpu.read_patches(ctx);
        let phi = self.gpu.read(ctx, Slot::Phi);
        let u = self.gpu.read(ctx, Slot::MeanVelocity);
        let cells: Vec<(Patch, Vec<f64>)> = patches
            .iter()
            .map(|p| (p.patch(), crate::gpu::buffers::patch_storage(*p, &phi).iter().map(|&v| v as f64).collect()))
            .collect();
        let warm_start = u.chunks_exact(2).map(|c| C64::new(c[0] as f64, c[1] as f64)).collect();
        let state = State { step: self.step, cells, warm_start, substrate: self.substrate.clone() };
        Monolayer::from_state(self.params.clone(), self.seed, state).expect("the GPU's state is a valid state")
    }
}

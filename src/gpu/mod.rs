//! The GPU stepper's stages on wgpu compute, f32, beside the CPU core that stays the
//! reference: a device (`context`, [`GpuContext`]), the state the kernels read and write on it
//! (`buffers`), and the kernels of one step (`kernels`, [`Kernel`]), each mirroring its CPU
//! module one to one:
//!
//! | kernel (`shaders/`)                  | CPU                                   | paper           |
//! |--------------------------------------|---------------------------------------|-----------------|
//! | `gather.wgsl` `lattice_sums`         | `model::monolayer` `gather` (Σφ, Σφ²) | Eq. S2, S4      |
//! | `shape.wgsl` `area_and_shape`        | `model::shape` (Q_i, Q̂_i), `free_energy::area` (A_i) | Eq. 5, S3 |
//! | `free_energy.wgsl` `chemical_potential` | `FreeEnergy::chemical_potential`   | Eqs. S1–S3 (μ_i)|
//! | `forces.wgsl` `force_density`        | `model::forces::force_density`        | Eqs. 3, 4       |
//! | `gather.wgsl` `friction_sums`        | `model::monolayer` gathers of n and F | Eq. 2 (Σ_j)     |
//! | `friction.wgsl` `cg_*`, `friction_pull`, `friction_check` | `model::friction` (`FrictionSolver`) | Eq. 2 |
//! | `multigrid.wgsl` `mg_*`, `cg_update_restrict` | `model::multigrid` (the preconditioner) | —      |
//! | `motion.wgsl` `velocity_and_rate`    | `model::motion::velocity_and_rate`    | Eq. 1           |
//! | `monolayer.wgsl` `predict`, `correct`| `model::monolayer` `Then` (Heun)      | —               |
//! | `cell.wgsl` `move_patch`             | `Monolayer::update_patches`, `Cell::relayout` | Sec. A  |
//!
//! Every sum runs in a fixed order (no float atomics), so two runs on the same adapter and
//! driver give the same bits. Nothing is read back inside a step: [`GpuMonolayer::read`] is for
//! tests and diagnostics. [`GpuMonolayer::step`] takes a whole Heun step on fixed patches in one
//! submission, with the friction solve of Eq. 2 (conjugate gradients preconditioned by the
//! CPU's aggregation multigrid, its scalars and stop flags on the device) where the phase has
//! one, then the patches following the cells; [`GpuRun`] (`stepper`) takes many steps with the
//! faults checked between submissions, natively and in the page's worker
//! (`web::gpu_engine`), its readbacks futures (`readback`) (docs/gpu.md).
//!
//! A layer beside `analysis`: it imports only `model` (tested by `tests/layers.rs`). The modules
//! are private; what `run`, `web` and the tests use is re-exported here.

mod buffers;
mod context;
mod iterations;
mod kernels;
mod readback;
mod stepper;

pub use buffers::{patch_storage, DeviceState, GpuPatch, Layout, PatchFault, Slot, SolveScalars, NO_FAULT};
pub use context::{GpuContext, GpuError};
pub use iterations::LOWER_AFTER;
pub use kernels::{compile, serial_chain, GpuMonolayer, Kernel, Pipelines, Preconditioner};
pub use stepper::{GpuRun, GpuRunError, IN_FLIGHT};

//! The physics core: the model of Pinto, Rozman & Yeomans, one module per concept, in the order
//! of one evaluation of the right-hand side:
//!
//! `params` (every knob) → `init` (random disks) → `free_energy` (μ_i) → `shape` (Q_i, Q̂_i) →
//! `forces` (f^p, f^a) → `friction` (Eq. 2 on the lattice, preconditioned by `multigrid`) →
//! `motion` (v_i, ∂_t φ_i), driven by `monolayer` ([`Monolayer`]: Heun steps, the protocol,
//! patches, stability checks).
//!
//! `lattice` and `cell` hold the geometry, `counters` the time per stage, `par` the
//! deterministic parallel loops, `error` what can go wrong, `hash` the one hash (FNV-1a) of
//! fingerprints and of the relaxed states' keys and checksums (`formats::snapshot`),
//! `precision` the type the cells' per-site fields are stored in, `sum` the order of every sum
//! over sites, `perturb` the seeded noise a branched run's replicas start with. Nothing here touches files, clocks or threads directly (threads only through
//! `par`, behind the `parallel` feature), so the core compiles for `wasm32-unknown-unknown`
//! with the same bits. It imports nothing from `analysis`, `formats`, `gpu`, `run` or `web`
//! (tested by `tests/layers.rs`).
//!
//! The modules are private; what the other layers, the binary and the tests use is re-exported
//! here, each item with its one-line summary.

mod cell;
mod counters;
mod error;
mod forces;
mod free_energy;
mod friction;
mod hash;
mod init;
mod lattice;
mod monolayer;
mod motion;
// Crate-visible for the GPU kernels, which write its constants into their WGSL.
pub(crate) mod multigrid;
mod par;
mod params;
mod perturb;
mod precision;
mod shape;
mod sum;

pub use cell::{Cell, PatchField};
pub use counters::{Counters, Stage};
pub use error::SimError;
pub use forces::force_density;
pub use free_energy::FreeEnergy;
pub use friction::{FrictionProblem, FrictionSolver, SolveError, SolveStats};
pub(crate) use hash::fnv1a;
pub use lattice::{row_neighbourhood, Neighbourhood, Patch, Run, Runs};
pub use monolayer::{LatticeFields, Monolayer, Phase, State};
pub use motion::friction_weight;
pub use multigrid::Multigrid;
pub use params::{
    number_text, Advection, FrictionWeights, Laplacian, ParamError, Params, PassiveForce, MAX_BOX_SIZE, MAX_STEPS,
};
pub use perturb::{Perturbation, MAX_PERTURBATION};
pub use precision::{load, Real, Store, STORE_NAME};
pub use shape::{axis_angle, gradient, shape_tensor};

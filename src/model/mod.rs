//! The physics core: the model of Pinto, Rozman & Yeomans, one module per concept, in the order
//! of one evaluation of the right-hand side:
//!
//! [`params`] (every knob) → [`init`] (random disks) → [`free_energy`] (μ_i) → [`shape`]
//! (Q_i, Q̂_i) → [`forces`] (f^p, f^a) → [`friction`] (Eq. 2 on the lattice, preconditioned by
//! [`multigrid`]) → [`motion`] (v_i, ∂_t φ_i), driven by [`monolayer`] (Heun steps, the
//! protocol, patches, stability checks).
//!
//! [`lattice`] and [`cell`] hold the geometry, [`counters`] the time per stage, [`par`] the
//! deterministic parallel loops, [`error`] what can go wrong, `hash` the one hash (FNV-1a) of
//! fingerprints and of the relaxed states' keys and checksums (`formats::snapshot`),
//! [`precision`] the type the cells' per-site fields are stored in, [`sum`] the order of every
//! sum over sites. Nothing here touches files, clocks or threads directly (threads only through
//! [`par`], behind the `parallel` feature), so the core compiles for `wasm32-unknown-unknown`
//! with the same bits. It imports nothing from `analysis`, `formats`, `gpu`, `run` or `web`
//! (tested by `tests/layers.rs`).

pub mod cell;
pub mod counters;
pub mod error;
pub mod forces;
pub mod free_energy;
pub mod friction;
pub(crate) mod hash;
pub mod init;
pub mod lattice;
pub mod monolayer;
pub mod motion;
pub mod multigrid;
pub mod par;
pub mod params;
pub mod precision;
pub mod shape;
pub mod sum;

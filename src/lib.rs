//! # monolayer
//!
//! The active-nematic multi-phase-field model of epithelial monolayers of Pinto, Rozman &
//! Yeomans, "Spontaneous hole formation in cell monolayers emerges from collective cell motion".
//! Every cell is its own phase field on a patch of a periodic lattice; cells push on each other
//! (free energy), pull along their long axis (extensile activity) and feel friction from the
//! substrate and from each other.
//!
//! The physics compiles for `wasm32-unknown-unknown` and natively with the same bits for the same
//! seed: no threads, files or clocks inside it. Native extras (threads, files, the CLI) sit
//! behind the `parallel` and `cli` features.
//!
//! Module per concept, in the order of one evaluation:
//! [`params`] → [`init`] → [`free_energy`] → [`shape`] → [`forces`] → [`friction`] → [`motion`],
//! driven by [`monolayer`]; [`lattice`] and [`cell`] hold the geometry, [`counters`] the timings.

pub mod analysis;
pub mod cell;
pub mod counters;
pub mod error;
pub mod forces;
pub mod free_energy;
pub mod friction;
pub mod init;
pub mod lattice;
pub mod monolayer;
pub mod motion;
pub mod multigrid;
pub mod par;
pub mod params;
pub mod shape;

#[cfg(feature = "cli")]
pub mod io;
#[cfg(feature = "cli")]
pub mod runner;
#[cfg(feature = "cli")]
pub mod sweep;

/// The browser demo's binding and wgpu drawing (see `www/`).
#[cfg(target_arch = "wasm32")]
pub mod web;

pub use error::SimError;
pub use monolayer::{Monolayer, Phase, State};
pub use params::Params;

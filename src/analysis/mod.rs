//! The paper's measurements of the monolayer (Sec. A–D, docs/reading.md §6), apart from the dynamics:
//! the same code measures the running simulation (live, in the browser) and a run's frames
//! (offline, `monolayer analyze`).
//!
//! - `fields`: the coarse-grained fields A(x) = Σ_i a_i φ_i (velocity, active force, nematic),
//!   their periodic sliding-window mean, the strain rate ε̇ = ∇·v/2, ∇·f^a;
//! - `defects`: ±½ defects of the smoothed nematic field, +½ orientation (Vromans & Giomi);
//! - `spirals`: spiral cores, +1 points of the smoothed velocity with ∇·v > 0;
//! - `elongation`: each cell's aspect ratio from its shape tensor;
//! - `holes`: void regions, the packing fraction, and holes followed from frame to frame;
//! - `correlations`: C_v(r), C_Q(r) of the unsmoothed fields by FFT, correlation lengths;
//! - `nucleation`: P(hole | ε̇), the probability that a site opens into a new hole;
//! - `precursors`: spiral cores, +½ defects and strain near a hole in the frames before it opens;
//! - `winding`: plaquette winding numbers (the paper's 8-neighbour test, with the sites that
//!   flag one defect merged) and sub-site core positions, shared by defects and spirals;
//! - `alignment`: the mechanism's unmeasured claims: antiparallel +½ pairs, cells tangential
//!   to a hole's edge, no holes at −½ defects;
//! - `regime`: the paper's regime criterion (Fig. 3c–d) from hole lifetimes;
//! - `thinning`: the least Σφ and the void share about a site: how thin the tissue is there;
//! - `forecast`: the precursors against sites of the same thinning, and a forecast of where a
//!   hole nucleates next, scored on runs it never saw;
//! - `intervention`: a branched run followed for tears at watched sites, and the experiment's
//!   statistics (bootstrap intervals, the share of tears an arm prevents);
//! - `frame`: one frame measured ([`Analysis`], which owns every buffer: after the first call,
//!   measuring a frame allocates nothing), its scalar readings ([`FrameSummary`]).
//!
//! The modules are private; what the other layers and the tests use is re-exported here.
//!
//! Reading a run's frames, its tables and plots are native and live in `run`.

mod alignment;
mod correlations;
mod defects;
mod elongation;
mod fields;
mod forecast;
mod frame;
mod holes;
mod intervention;
mod nucleation;
mod precursors;
mod regime;
mod spirals;
mod thinning;
mod winding;

pub use alignment::{boundary_sites, tangential_angles, AWAY_RADII, BORDER_RADII};
pub use correlations::{correlation_length, Correlator};
pub use defects::{Defect, DefectFinder};
pub use fields::{divergence, window_mean, CoarseFields};
pub use forecast::{
    caught_in_top, forecast_samples, matched_baseline, matched_sites, roc_auc, roc_curve, score_field, thinning_before,
    BaselineRow, Features, FrameFeatures, Logistic, Nucleation, Predictor, RunHistory, Sample, ThinningRow,
    BASELINE_SITES, HORIZONS, LOOKAHEAD, SHIPPED_MODEL,
};
pub use frame::{Analysis, Detail, FrameSummary};
pub use holes::{
    counted_holes, nucleation_area, periodic_distance, CountedHole, Hole, HoleCounting, HoleTracker, VoidRegion,
    VoidRegions,
};
pub use intervention::{
    bootstrap_interval, mean_at, prevented_share, SiteReading, TearWatch, WatchedFrame, AFTER, BOOTSTRAP_RESAMPLES,
    INTERVENTION_SEED, LEADS, REPLICAS, REPLICA_AMPLITUDE,
};
pub use nucleation::{
    best_collapse_exponent, binomial_fit, collapse_scatter, least_squares_fit, ExponentialFit, HoleProbability,
    STRAIN_RATE_BIN,
};
pub use precursors::{FramePoints, Precursor, Precursors, CHANCE_SITES, DEPTH};
pub use regime::{classify, fitted_lifetime, Regime};
pub use spirals::{PlusOne, SpiralFinder};
pub use thinning::{covered_about, least_within};

//! What the page reports about the tissue, from Σ_i φ_i, with the analysis module's definitions
//! (the same as the offline analysis): a void site has Σφ < 0.01; void sites that touch
//! (4-neighbours, periodic) form a region; a region counts as a hole above the nucleation area
//! πR²/4 (a quarter of a cell); the packing fraction is the fraction of sites with Σφ ≥ ½.

use crate::analysis::holes::{nucleation_area, VoidRegions};

/// Holes and coverage of one Σφ field.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct TissueStats {
    /// Void regions above the nucleation area πR²/4.
    pub holes: u32,
    /// All void sites (lattice units: Δx = 1, so µm² at Δx ≈ 1 µm).
    pub void_area: u32,
    /// Fraction of sites with Σφ ≥ ½.
    pub packing: f64,
}

/// Measures Σφ on the L×L lattice; `regions` keeps its buffers between frames.
pub fn tissue_stats(phi_sum: &[f64], l: usize, radius: f64, regions: &mut VoidRegions) -> TissueStats {
    regions.find(phi_sum, l);
    TissueStats {
        holes: regions.count_above(nucleation_area(radius)) as u32,
        void_area: regions.regions.iter().map(|r| r.area as u32).sum(),
        packing: regions.packing_fraction,
    }
}

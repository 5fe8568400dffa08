//! The conditional probability of a hole given the local strain rate, P(hole | ε̇) (paper Fig. 2,
//! docs/reading.md §6): for every site of every frame, in bins of ε̇ of width Δε̇ = 0.000125, how many
//! sites there were (N_ε̇) and how many of them lie in a hole that nucleates in the next frame
//! (N_hole,ε̇); P = N_hole,ε̇ / N_ε̇. The paper's exclusion: "if a hole grows above a threshold size,
//! corresponding to half of a single cell area, lattice sites are not counted … until the hole
//! closes". Once a hole has grown above πR²/2, no frame is counted until it has closed, as a
//! family ([`super::holes::HoleCounting::Families`]): its fragments and the holes that joined it
//! closed too. A hole that shrinks back below πR²/2 is still excluded.

use std::collections::BTreeMap;

use super::holes::{HoleTracker, VoidRegions};

/// The paper's bin width Δε̇.
pub const STRAIN_RATE_BIN: f64 = 0.000125;

/// Half a cell's area, πR²/2: the size above which a hole excludes the frames until it closes.
pub fn half_cell_area(radius: f64) -> f64 {
    0.5 * std::f64::consts::PI * radius * radius
}

/// Counts of sites and of sites that open into a new hole, per strain-rate bin.
#[derive(Clone, Debug, Default)]
pub struct HoleProbability {
    /// Bin index k (ε̇ in [k Δε̇, (k+1) Δε̇)) → (N_ε̇, N_hole,ε̇).
    pub bins: BTreeMap<i64, (u64, u64)>,
    /// Frames counted and frames skipped (a large hole open).
    pub frames_counted: u64,
    pub frames_skipped: u64,
    /// ε̇ of the previous frame, and whether it is to be skipped.
    previous: Vec<f64>,
    previous_skipped: Option<bool>,
    new_hole_label: Vec<bool>,
}

impl HoleProbability {
    /// Takes the next frame: its strain rate, its void regions, and the hole tracker already
    /// updated with them (which says which regions nucleated). The previous frame's sites are
    /// counted against this frame's new holes.
    pub fn push(&mut self, strain_rate: &[f64], voids: &VoidRegions, tracker: &HoleTracker, radius: f64) {
        if let Some(skipped) = self.previous_skipped {
            if skipped {
                self.frames_skipped += 1;
            } else {
                self.frames_counted += 1;
                self.new_hole_label.clear();
                self.new_hole_label.resize(voids.regions.len(), false);
                for r in tracker.nucleated_regions() {
                    self.new_hole_label[r] = true;
                }
                for (e, &label) in self.previous.iter().zip(&voids.labels) {
                    let bin = (e / STRAIN_RATE_BIN).floor() as i64;
                    let entry = self.bins.entry(bin).or_insert((0, 0));
                    entry.0 += 1;
                    if label != u32::MAX && self.new_hole_label[label as usize] {
                        entry.1 += 1;
                    }
                }
            }
        }
        let large_open = tracker.large_family_open(half_cell_area(radius));
        self.previous.clear();
        self.previous.extend_from_slice(strain_rate);
        self.previous_skipped = Some(large_open);
    }

    /// (ε̇ at the bin's lower edge, N_ε̇, N_hole,ε̇, P) for every bin with a site in it.
    pub fn table(&self) -> impl Iterator<Item = (f64, u64, u64, f64)> + '_ {
        self.bins.iter().map(|(&k, &(n, h))| (k as f64 * STRAIN_RATE_BIN, n, h, h as f64 / n as f64))
    }
}

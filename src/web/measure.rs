//! What the page reports about the tissue, from Σ_i φ_i, with the analysis module's definitions
//! (the same as the offline analysis): a void site has Σφ < 0.01; void sites that touch
//! (4-neighbours, periodic) form a region; a region counts as a hole above the nucleation area
//! πR²/4 (a quarter of a cell); the packing fraction is the fraction of sites with Σφ ≥ ½.

use crate::analysis::{nucleation_area, VoidRegions};

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

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::Analysis;
    use crate::model::{Monolayer, Params};

    #[test]
    fn holes_are_void_regions_above_a_quarter_cell_joined_across_the_edges() {
        let l = 20;
        let mut phi_sum = vec![1.0; l * l];
        let mut set = |x: usize, y: usize, v: f64| phi_sum[y * l + x] = v;
        for y in 2..5 {
            for x in 2..5 {
                set(x, y, 0.0); // 9 sites: a hole (πR²/4 = π for R = 2)
            }
        }
        set(15, 15, 0.005); // 1 site: a gap, not a hole
        for y in 10..12 {
            set(19, y, 0.0); // 2 + 2 sites on either side of the periodic edge: one hole of 4
            set(0, y, 0.0);
        }
        set(8, 8, 0.3); // neither void nor covered
        let mut regions = VoidRegions::default();
        let s = tissue_stats(&phi_sum, l, 2.0, &mut regions);
        assert_eq!(s, TissueStats { holes: 2, void_area: 14, packing: (400.0 - 15.0) / 400.0 });
        // A larger cell (πR²/4 ≈ 7.1 for R = 3): only the 9-site region is a hole.
        assert_eq!(tissue_stats(&phi_sum, l, 3.0, &mut regions).holes, 1);
    }

    #[test]
    fn a_tissue_measures_as_the_offline_analysis_does() {
        let p = Params { box_size: 40, n_cells: 5, relax_steps: 40, ..Params::default() };
        let mut m = Monolayer::new(p, 3).unwrap();
        m.advance(20).unwrap(); // half-relaxed disks: void between them
        let mut a = Analysis::new(m.params());
        a.measure(&m);
        let summary = a.summary();
        let (l, r) = (m.params().box_size, m.params().radius);
        let s = tissue_stats(m.phi_sum(), l, r, &mut VoidRegions::default());
        assert_eq!(s.holes as usize, summary.holes);
        assert!(s.holes > 0, "no hole between half-relaxed disks: the test proves little");
        assert_eq!(s.packing, summary.packing_fraction);
        assert_eq!(s.void_area as f64, (summary.void_fraction * (l * l) as f64).round());
    }
}

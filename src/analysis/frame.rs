//! One frame measured: [`Analysis`] owns every buffer (after the first call, measuring a frame
//! allocates nothing) and measures the tissue at a step, as deeply as [`Detail`] asks;
//! [`FrameSummary`] is the frame's scalar readings, the row the tables and the page share.

use num_complex::Complex64 as C64;

use super::alignment::cell_centroid;
use super::correlations::{correlation_length, Correlator};
use super::defects::{Defect, DefectFinder};
use super::elongation::{cell_aspect_ratio, mean_and_p90};
use super::fields::{divergence, strain_rate, CoarseFields};
use super::holes::{nucleation_area, VoidRegions};
use super::spirals::{PlusOne, SpiralFinder};
use crate::model::{axis_angle, shape_tensor, Monolayer, Params, Patch, Real};

/// The scalar measurements of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FrameSummary {
    /// Fraction of sites with Σφ ≥ ½.
    pub packing_fraction: f64,
    /// Fraction of void sites (Σφ < 0.01).
    pub void_fraction: f64,
    /// Connected void regions of any size.
    pub void_regions: usize,
    /// Void regions larger than πR²/4: holes by the nucleation criterion.
    pub holes: usize,
    /// Area of the largest void region, in sites.
    pub largest_void: usize,
    pub plus_half_defects: usize,
    pub minus_half_defects: usize,
    pub spiral_cores: usize,
    /// max over sites of ε̇ = ∇·v/2 of the smoothed velocity.
    pub max_strain_rate: f64,
    /// First crossings of 1/e by C_v and C_Q (None: not within L/2).
    pub velocity_correlation_length: Option<f64>,
    pub nematic_correlation_length: Option<f64>,
    /// Mean and 90th percentile of the cells' aspect ratios (the `elongation` module).
    pub aspect_ratio_mean: Option<f64>,
    pub aspect_ratio_p90: Option<f64>,
    /// Σ_x |Σ_i φ_i v_i| / Σ_x Σ_i φ_i: the tissue's mean speed, in sites per time unit.
    pub mean_speed: f64,
}

/// How much of a frame to measure.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Detail {
    /// Everything.
    Full,
    /// What the page's readouts show (holes and void area, packing, mean speed, ±½ defects,
    /// spiral cores): the cells' aspect ratios and axes, ∇·f^a and the correlations are left
    /// out (about half the cost at full size, docs/performance.md), and reported as not measured
    /// (`None` in [`FrameSummary`], NaN in `active_force_divergence`, empty vectors).
    Tissue,
}

/// Every measurement of one frame, with the buffers it needs (allocated once per lattice size).
#[derive(Debug)]
pub struct Analysis {
    pub l: usize,
    /// Cell radius R.
    pub radius: f64,
    /// Half-width of the smoothing window, R rounded: the window is 2R + 1 sites a side.
    pub half_window: usize,
    /// ζ of the active force (the run's, also while relaxing).
    pub zeta: f64,
    /// The unsmoothed fields of Eq. S4 (Σφ included).
    pub raw: CoarseFields,
    /// The same after the sliding-window mean (Σφ copied unsmoothed).
    pub smooth: CoarseFields,
    /// ε̇ = ∇·v/2 of the smoothed velocity.
    pub strain_rate: Vec<f64>,
    /// ∇·f^a of the smoothed active force.
    pub active_force_divergence: Vec<f64>,
    /// ±½ defects of the smoothed nematic field.
    pub defects: Vec<Defect>,
    /// +1 points of the smoothed velocity; the spiral cores are those with ∇·v > 0.
    pub plus_ones: Vec<PlusOne>,
    /// Void regions and packing fraction of Σφ.
    pub voids: VoidRegions,
    /// Each cell's aspect ratio, in cell order (`elongation::cell_aspect_ratio`).
    pub aspect_ratios: Vec<f64>,
    /// Each cell's centroid and elongation axis angle (main axis of its shape tensor), in cell
    /// order, for the tangential alignment at holes ([`tangential_angles`](super::tangential_angles)).
    pub cell_axes: Vec<(f64, f64, f64)>,
    /// The same, sorted, for the frame's percentile (kept so that no frame allocates).
    aspect_sorted: Vec<f64>,
    /// C_v(r), C_Q(r) for r = 0..=L/2 (unsmoothed fields).
    pub velocity_correlation: Vec<f64>,
    pub nematic_correlation: Vec<f64>,
    /// The typical |∇·v| scale below which a +1 point counts as divergence-free.
    divergence_scale: f64,
    defect_finder: DefectFinder,
    spiral_finder: SpiralFinder,
    correlator: Correlator,
    row: Vec<f64>,
    tmp: Vec<f64>,
}

impl Analysis {
    /// Buffers for the lattice and cells of these parameters.
    pub fn new(params: &Params) -> Self {
        let l = params.box_size;
        let half_window = params.radius.round() as usize;
        assert!(2 * half_window < l, "the 2R×2R window must fit the box");
        Analysis {
            l,
            radius: params.radius,
            half_window,
            zeta: params.zeta,
            raw: CoarseFields::new(l),
            smooth: CoarseFields::new(l),
            strain_rate: vec![0.0; l * l],
            active_force_divergence: vec![0.0; l * l],
            defects: Vec::new(),
            plus_ones: Vec::new(),
            voids: VoidRegions::default(),
            aspect_ratios: Vec::new(),
            cell_axes: Vec::new(),
            aspect_sorted: Vec::new(),
            velocity_correlation: Vec::new(),
            nematic_correlation: Vec::new(),
            divergence_scale: 0.0,
            defect_finder: DefectFinder::default(),
            spiral_finder: SpiralFinder::default(),
            correlator: Correlator::new(l),
            row: Vec::new(),
            tmp: Vec::new(),
        }
    }

    /// Measures the current state of a simulation (velocities of its last evaluation). The
    /// active force is the run's ζ times −Q̂_i·∇φ_i, also while relaxing (where the dynamics
    /// has it off), so that it shows where activity would pull.
    pub fn measure(&mut self, m: &Monolayer) {
        self.measure_in(m, Detail::Full);
    }

    /// [`Self::measure`] to the given detail.
    pub fn measure_in(&mut self, m: &Monolayer, detail: Detail) {
        assert_eq!(m.params().box_size, self.l, "analysis built for another lattice size");
        self.zeta = m.params().zeta;
        self.raw.clear();
        self.aspect_ratios.clear();
        self.cell_axes.clear();
        for c in m.cells() {
            let (vx, vy) = c.velocity();
            self.raw.add_cell(c.patch(), c.phi().data, c.q_hat(), self.zeta, Some((vx.data, vy.data)));
            if detail == Detail::Full {
                self.aspect_ratios.extend(cell_aspect_ratio(c.patch(), c.phi().data));
                self.push_axis(c.patch(), c.phi().data);
            }
        }
        self.derive(detail);
    }

    /// Measures cells given as (patch, φ on the padded patch, Q̂) with the coarse-grained
    /// velocity Σ_i φ_i v_i as a lattice array: what a frame file holds.
    pub fn measure_cells<'a>(&mut self, cells: impl Iterator<Item = (Patch, &'a [f64], [f64; 2])>, velocity: &[C64]) {
        assert_eq!(velocity.len(), self.l * self.l, "velocity field of another lattice size");
        self.raw.clear();
        self.aspect_ratios.clear();
        self.cell_axes.clear();
        for (patch, phi, q_hat) in cells {
            self.raw.add_cell(patch, phi, q_hat, self.zeta, None);
            self.aspect_ratios.extend(cell_aspect_ratio(patch, phi));
            self.push_axis(patch, phi);
        }
        self.raw.set_velocity(velocity);
        self.derive(Detail::Full);
    }

    fn push_axis<T: Real>(&mut self, patch: Patch, phi: &[T]) {
        if let Some((x, y)) = cell_centroid(patch, phi, self.l) {
            self.cell_axes.push((x, y, axis_angle(shape_tensor(patch, phi))));
        }
    }

    /// Everything that follows from the raw fields and the cells' aspect ratios.
    fn derive(&mut self, detail: Detail) {
        let l = self.l;
        self.aspect_sorted.clear();
        self.aspect_sorted.extend_from_slice(&self.aspect_ratios);
        self.aspect_sorted.sort_by(f64::total_cmp);
        self.smooth.smooth_from(&self.raw, self.half_window, &mut self.row, &mut self.tmp);
        let s = &self.smooth;
        strain_rate(&s.vx, &s.vy, &mut self.strain_rate, l);
        if detail == Detail::Full {
            divergence(&s.fx, &s.fy, &mut self.active_force_divergence, l, 1.0);
        } else {
            self.active_force_divergence.fill(f64::NAN);
        }
        self.defect_finder.find(&s.qxx, &s.qxy, l, &mut self.defects);
        self.spiral_finder.find(&s.vx, &s.vy, &self.strain_rate, l, &mut self.plus_ones);
        // ε̇ of the +1 points is compared with the field's own typical |ε̇|.
        self.divergence_scale = self.strain_rate.iter().map(|e| e.abs()).sum::<f64>() / (l * l) as f64;
        for p in &mut self.plus_ones {
            // `find` averaged ε̇ = ∇·v/2; report ∇·v.
            p.divergence *= 2.0;
        }
        self.voids.find(&self.raw.phi_sum, l);
        if detail == Detail::Full {
            self.correlator.correlate(&self.raw.vx, &self.raw.vy, &mut self.velocity_correlation);
            self.correlator.correlate(&self.raw.qxx, &self.raw.qxy, &mut self.nematic_correlation);
        } else {
            self.velocity_correlation.clear();
            self.nematic_correlation.clear();
        }
    }

    /// The spiral cores: +1 points of the smoothed velocity with ∇·v > 0.
    pub fn spiral_cores(&self) -> impl Iterator<Item = &PlusOne> {
        let scale = 2.0 * self.divergence_scale;
        self.plus_ones.iter().filter(move |p| p.is_spiral_core(scale))
    }

    /// The scalar measurements of the last frame measured.
    pub fn summary(&self) -> FrameSummary {
        let v = &self.voids;
        let aspect = mean_and_p90(&self.aspect_sorted);
        let mass: f64 = self.raw.phi_sum.iter().sum();
        let flux: f64 = self.raw.vx.iter().zip(&self.raw.vy).map(|(x, y)| x.hypot(*y)).sum();
        FrameSummary {
            packing_fraction: v.packing_fraction,
            void_fraction: v.void_fraction,
            void_regions: v.regions.len(),
            holes: v.count_above(nucleation_area(self.radius)),
            largest_void: v.regions.iter().map(|r| r.area).max().unwrap_or(0),
            plus_half_defects: self.defects.iter().filter(|d| d.twice_charge > 0).count(),
            minus_half_defects: self.defects.iter().filter(|d| d.twice_charge < 0).count(),
            spiral_cores: self.spiral_cores().count(),
            max_strain_rate: self.strain_rate.iter().copied().fold(f64::NEG_INFINITY, f64::max),
            velocity_correlation_length: correlation_length(&self.velocity_correlation),
            nematic_correlation_length: correlation_length(&self.nematic_correlation),
            aspect_ratio_mean: aspect.map(|a| a.0),
            aspect_ratio_p90: aspect.map(|a| a.1),
            mean_speed: if mass > 0.0 { flux / mass } else { 0.0 },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The page's readouts' detail measures what it keeps to the bits of the full analysis,
    /// and reports what it leaves out as not measured rather than as a stale value.
    #[test]
    fn the_tissue_detail_keeps_its_measures_and_marks_the_rest_unmeasured() {
        let p = Params { box_size: 60, n_cells: 18, relax_steps: 300, zeta: 1.0, ..Params::default() };
        let mut m = Monolayer::new(p, 3).unwrap();
        m.advance(500).unwrap(); // active: velocities, defects
        m.evaluate_now().unwrap();
        let mut full = Analysis::new(m.params());
        full.measure(&m);
        let f = full.summary();
        // The same buffers, measured in full first, so that a stale value would show.
        let mut lean = Analysis::new(m.params());
        lean.measure(&m);
        lean.measure_in(&m, Detail::Tissue);
        let t = lean.summary();
        assert_eq!(
            (t.packing_fraction, t.void_fraction, t.void_regions, t.holes, t.largest_void),
            (f.packing_fraction, f.void_fraction, f.void_regions, f.holes, f.largest_void)
        );
        assert_eq!(
            (t.plus_half_defects, t.minus_half_defects, t.spiral_cores),
            (f.plus_half_defects, f.minus_half_defects, f.spiral_cores)
        );
        assert_eq!(
            (t.mean_speed.to_bits(), t.max_strain_rate.to_bits()),
            (f.mean_speed.to_bits(), f.max_strain_rate.to_bits())
        );
        assert!(f.plus_half_defects + f.minus_half_defects > 0, "no defect: the test proves little");
        assert!(f.aspect_ratio_mean.is_some() && f.velocity_correlation_length.is_some());
        assert_eq!((t.aspect_ratio_mean, t.aspect_ratio_p90), (None, None));
        assert_eq!((t.velocity_correlation_length, t.nematic_correlation_length), (None, None));
        assert!(lean.cell_axes.is_empty() && lean.aspect_ratios.is_empty());
        assert!(lean.active_force_divergence.iter().all(|d| d.is_nan()));
    }
}

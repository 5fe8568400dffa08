//! Does the tissue still tear when the motion is switched off? A branch of a run starts from the
//! parent's exact state a few frames before a nucleation with one thing changed (`monolayer
//! intervene`, docs/figures.md, "Intervention"); this module follows the branch's frames for
//! tears at watched sites, and holds the statistics of the experiment.
//!
//! A tear at a site is a hole that nucleates within R of it, as the hole tracker of `analyze`
//! and the forecast define one ([`HoleTracker::nucleated_holes`]). The tracker carries on from
//! the parent's, as it stood at the frame the branch starts from, so that a hole the parent
//! already follows is not counted as new in the branch.

use rand_chacha::rand_core::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::holes::{periodic_distance, HoleTracker};
use super::precursors::max_within;
use super::thinning::least_within;
use super::Analysis;

/// Frames before a nucleation at which the branches start (the k of the experiment).
pub const LEADS: [usize; 4] = [1, 2, 3, 5];
/// Frames after the parent's nucleation within which a branch's tear counts: the window of a
/// branch started k frames before is k + `AFTER` frames.
pub const AFTER: usize = 5;
/// Perturbed copies of the parent's state per branch point: their tear share is how predictable
/// the tear is from the state (the ceiling every other arm is read against).
pub const REPLICAS: usize = 3;
/// The amplitude of the replicas' perturbation of φ.
pub const REPLICA_AMPLITUDE: f64 = 1e-6;
/// Resamples of the bootstrap intervals.
pub const BOOTSTRAP_RESAMPLES: usize = 4000;
/// Seed of the bootstrap's generator (and of the matched sites' draw).
pub const INTERVENTION_SEED: u64 = 0x1A7E_2E7E_0000_0049;

/// One watched site in one frame: the least Σφ within R (thinning) and the largest strain rate
/// within R/2 (Fig. 1d's local measure).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct SiteReading {
    pub least: f64,
    pub strain_rate: f64,
}

/// One frame of a branch as watched: its step, the tissue's mean speed and the velocity's
/// correlation length (how far the flows reach), and each watched site's reading.
#[derive(Clone, Debug, PartialEq)]
pub struct WatchedFrame {
    pub step: u64,
    pub mean_speed: f64,
    pub velocity_correlation_length: Option<f64>,
    pub sites: Vec<SiteReading>,
}

/// A branch followed frame by frame for tears at its watched sites.
#[derive(Clone, Debug)]
pub struct TearWatch {
    tracker: HoleTracker,
    sites: Vec<(f64, f64)>,
    l: usize,
    radius: f64,
    /// For each watched site, the step of the first frame in which a hole nucleated within R of
    /// it (None: none so far).
    pub first_tear: Vec<Option<u64>>,
    pub frames: Vec<WatchedFrame>,
}

impl TearWatch {
    /// Watches `sites` ((x, y) on the L×L box) with the parent's `tracker` as it stood after the
    /// frame the branch starts from.
    pub fn new(tracker: HoleTracker, sites: Vec<(f64, f64)>, l: usize, radius: f64) -> Self {
        let first_tear = vec![None; sites.len()];
        TearWatch { tracker, sites, l, radius, first_tear, frames: Vec::new() }
    }

    /// The branch's first frame, measured in `a`: the parent's φ (its tracker has seen it), read
    /// but not tracked again.
    pub fn start(&mut self, a: &Analysis, step: u64) {
        self.read(a, step);
    }

    /// A later frame of the branch, measured in `a`, at simulation time `time`.
    pub fn push(&mut self, a: &Analysis, time: f64, step: u64) {
        self.tracker.update(&a.voids, time);
        for h in self.tracker.nucleated_holes() {
            let (_, _, hx, hy) = self.tracker.holes[h].history[0];
            for (site, first) in self.sites.iter().zip(self.first_tear.iter_mut()) {
                if first.is_none() && periodic_distance(hx, hy, site.0, site.1, self.l) <= self.radius {
                    *first = Some(step);
                }
            }
        }
        self.read(a, step);
    }

    fn read(&mut self, a: &Analysis, step: u64) {
        let (l, r) = (self.l, self.radius);
        let sites = self
            .sites
            .iter()
            .map(|&(x, y)| SiteReading {
                least: least_within(&a.raw.phi_sum, l, x, y, r),
                strain_rate: max_within(&a.strain_rate, l, x, y, r / 2.0),
            })
            .collect();
        let s = a.summary();
        self.frames.push(WatchedFrame {
            step,
            mean_speed: s.mean_speed,
            velocity_correlation_length: s.velocity_correlation_length,
            sites,
        });
    }
}

/// The percentile interval (`level`, e.g. 0.95) of `stat` over `resamples` bootstrap resamples
/// of `units` units (each resample is the units' indices drawn with replacement), from a
/// ChaCha8 generator seeded with `seed`. Resamples where `stat` is undefined are left out; None
/// if fewer than half remain, or with no units.
pub fn bootstrap_interval(
    units: usize,
    resamples: usize,
    seed: u64,
    level: f64,
    mut stat: impl FnMut(&[usize]) -> Option<f64>,
) -> Option<(f64, f64)> {
    if units == 0 || resamples == 0 {
        return None;
    }
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let mut draw = vec![0usize; units];
    let mut values = Vec::with_capacity(resamples);
    for _ in 0..resamples {
        for d in draw.iter_mut() {
            *d = (rng.next_u64() % units as u64) as usize;
        }
        if let Some(v) = stat(&draw).filter(|v| v.is_finite()) {
            values.push(v);
        }
    }
    if values.len() * 2 < resamples {
        return None;
    }
    values.sort_by(f64::total_cmp);
    let tail = (1.0 - level) / 2.0;
    let at = |q: f64| values[((q * (values.len() - 1) as f64).round() as usize).min(values.len() - 1)];
    Some((at(tail), at(1.0 - tail)))
}

/// The mean of `values` at `indices` (a bootstrap resample, or every index).
pub fn mean_at(values: &[f64], indices: &[usize]) -> Option<f64> {
    (!indices.is_empty()).then(|| indices.iter().map(|&i| values[i]).sum::<f64>() / indices.len() as f64)
}

/// The share of the tears the control replicas make that an arm prevents, 1 − p_arm/p_same, over
/// the units at `indices` (None where the replicas make none).
pub fn prevented_share(arm: &[f64], control: &[f64], indices: &[usize]) -> Option<f64> {
    let (same, arm) = (mean_at(control, indices)?, mean_at(arm, indices)?);
    (same > 0.0).then(|| 1.0 - arm / same)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::VoidRegions;
    use crate::model::Params;

    /// Σφ = 1 everywhere but for void disks of radius 3 at `holes`, on a 40×40 box.
    fn voids(holes: &[(f64, f64)]) -> VoidRegions {
        let l = 40;
        let mut p = vec![1.0; l * l];
        for y in 0..l {
            for x in 0..l {
                if holes.iter().any(|&(hx, hy)| periodic_distance(x as f64, y as f64, hx, hy, l) <= 3.0) {
                    p[y * l + x] = 0.0;
                }
            }
        }
        let mut v = VoidRegions::default();
        v.find(&p, l);
        v
    }

    fn analysis_with(holes: &[(f64, f64)]) -> Analysis {
        let params = Params { box_size: 40, n_cells: 4, radius: 4.0, ..Params::default() };
        let mut a = Analysis::new(&params);
        a.voids = voids(holes);
        a.raw.phi_sum = (0..40 * 40)
            .map(|k| {
                let (x, y) = ((k % 40) as f64, (k / 40) as f64);
                if holes.iter().any(|&(hx, hy)| periodic_distance(x, y, hx, hy, 40) <= 3.0) {
                    0.0
                } else {
                    1.0
                }
            })
            .collect();
        a
    }

    #[test]
    fn a_tear_counts_within_r_of_a_site_and_not_a_hole_the_parent_already_had() {
        // The parent's tracker already follows a hole at (5, 5).
        let mut parent = HoleTracker::new(4.0);
        parent.update(&voids(&[(5.0, 5.0)]), 0.0);
        let sites = vec![(5.0, 6.0), (20.0, 20.0), (31.0, 20.0)];
        let mut w = TearWatch::new(parent, sites, 40, 4.0);
        w.start(&analysis_with(&[(5.0, 5.0)]), 100);
        w.push(&analysis_with(&[(5.0, 5.0)]), 1.0, 200);
        assert_eq!(w.first_tear, vec![None, None, None], "an old hole is no tear");
        // A new hole 3 sites from the second site (within R = 4), 9 from the third.
        w.push(&analysis_with(&[(5.0, 5.0), (23.0, 20.0)]), 2.0, 300);
        assert_eq!(w.first_tear, vec![None, Some(300), None]);
        w.push(&analysis_with(&[(5.0, 5.0), (23.0, 20.0), (31.0, 21.0)]), 3.0, 400);
        assert_eq!(w.first_tear, vec![None, Some(300), Some(400)], "the first tear is kept");
        assert_eq!(w.frames.len(), 4);
        assert_eq!(w.frames[2].sites[1].least, 0.0, "void within R of the torn site");
        assert_eq!(w.frames[0].sites[1].least, 1.0);
    }

    #[test]
    fn the_bootstrap_brackets_the_mean_and_shrinks_with_more_units() {
        let few: Vec<f64> = (0..10).map(|i| (i % 2) as f64).collect();
        let many: Vec<f64> = (0..1000).map(|i| (i % 2) as f64).collect();
        let all = |v: &[f64]| (0..v.len()).collect::<Vec<_>>();
        let (lo, hi) = bootstrap_interval(few.len(), 2000, 1, 0.95, |d| mean_at(&few, d)).unwrap();
        assert!(lo < 0.5 && hi > 0.5, "{lo} {hi}");
        let (lo2, hi2) = bootstrap_interval(many.len(), 2000, 1, 0.95, |d| mean_at(&many, d)).unwrap();
        assert!(hi2 - lo2 < (hi - lo) / 5.0, "{lo2} {hi2} against {lo} {hi}");
        assert!((lo2 - 0.469).abs() < 0.02 && (hi2 - 0.531).abs() < 0.02, "1.96·0.5/√1000 = 0.031: {lo2} {hi2}");
        assert_eq!(mean_at(&few, &all(&few)), Some(0.5));
        assert_eq!(bootstrap_interval(0, 100, 1, 0.95, |d| mean_at(&few, d)), None);
    }

    #[test]
    fn the_prevented_share_is_read_against_the_replicas() {
        let control = [1.0, 1.0, 0.5, 0.0];
        let off = [0.0, 1.0, 0.0, 0.0];
        let idx = [0, 1, 2, 3];
        // p_same = 2.5/4, p_off = 1/4: 1 − 0.4 = 0.6 of the tears prevented.
        assert!((prevented_share(&off, &control, &idx).unwrap() - 0.6).abs() < 1e-12);
        assert_eq!(prevented_share(&off, &control, &[3]), None, "no tear to prevent");
    }
}

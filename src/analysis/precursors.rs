//! What precedes a hole (paper Figs. 1c–d and S2): for each hole that nucleates, in each of the
//! frames up to [`DEPTH`] before (0 is the nucleation frame), the distance from the hole's
//! nucleation centroid to the nearest spiral core and to the nearest and second-nearest +½
//! defects, in units of R, and the largest strain rate within R/2 of that centroid over the
//! frame's largest (the paper's per-frame normalisation). With them, for the mechanism's claims
//! ([`super::alignment`]): the angle between the two nearest +½ defects' orientations, and the
//! distance to the nearest −½ defect.
//!
//! **Chance.** At a nucleation, frame 0 is nearly a spiral core by construction (an opening hole
//! is a source of the flow). Each curve therefore has a baseline: the same measures about
//! [`CHANCE_SITES`] random sites of every frame (uniform on the box, from a ChaCha8 generator
//! seeded with [`CHANCE_SEED`], so the same frames give the same sites), kept for each
//! nucleation in the same frames before it as its own rows ([`Precursors::chance`]).
use std::collections::VecDeque;

use rand_chacha::rand_core::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::alignment::polar_angle_between;
use super::holes::{periodic_distance, HoleTracker};
use super::Analysis;

/// Frames before nucleation that are looked back on.
pub const DEPTH: usize = 10;
/// Random sites per frame for the chance baseline.
pub const CHANCE_SITES: usize = 16;
/// Seed of the chance baseline's generator.
pub const CHANCE_SEED: u64 = 0x5EED_C4A7_CE00_0023;

/// One hole (or one random site), one frame before its nucleation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Precursor {
    pub hole: usize,
    pub frames_before: usize,
    /// Distance to the nearest spiral core / R (None: no spiral core in that frame).
    pub spiral_core: Option<f64>,
    /// Distances to the nearest and second-nearest +½ defects / R.
    pub plus_half: [Option<f64>; 2],
    /// Angle (radians, [0, π]) between the orientations of those two +½ defects: π antiparallel.
    pub plus_half_angle: Option<f64>,
    /// Distance to the nearest −½ defect / R.
    pub minus_half: Option<f64>,
    /// max ε̇ within R/2 of the nucleation centroid / max ε̇ over the box.
    pub strain_rate: f64,
}

/// The points and strain rate of one frame: what the precursor measures read about a site.
#[derive(Clone, Debug, Default)]
pub struct FramePoints {
    pub spiral_cores: Vec<(f64, f64)>,
    /// (x, y, orientation ψ).
    pub plus_half: Vec<(f64, f64, f64)>,
    pub minus_half: Vec<(f64, f64)>,
    /// ε̇ = ∇·v/2 of the smoothed velocity, per site.
    pub strain_rate: Vec<f64>,
}

impl FramePoints {
    /// Takes the frame just measured by `a`, reusing the buffers.
    pub fn take(&mut self, a: &Analysis) {
        self.spiral_cores.clear();
        self.spiral_cores.extend(a.spiral_cores().map(|p| (p.x, p.y)));
        self.plus_half.clear();
        self.plus_half.extend(a.defects.iter().filter(|d| d.twice_charge > 0).map(|d| (d.x, d.y, d.orientation)));
        self.minus_half.clear();
        self.minus_half.extend(a.defects.iter().filter(|d| d.twice_charge < 0).map(|d| (d.x, d.y)));
        self.strain_rate.clone_from(&a.strain_rate);
    }

    /// The distance from (cx, cy) to the nearest spiral core / R.
    pub fn nearest_spiral_core(&self, cx: f64, cy: f64, l: usize, r: f64) -> Option<f64> {
        nearest(&self.spiral_cores, cx, cy, l, r)
    }

    /// The measures about (cx, cy), as a row of hole `hole`, `k` frames before.
    pub fn measure(&self, hole: usize, k: usize, cx: f64, cy: f64, l: usize, r: f64) -> Precursor {
        let mut d: Vec<(f64, f64)> =
            self.plus_half.iter().map(|&(x, y, psi)| (periodic_distance(x, y, cx, cy, l) / r, psi)).collect();
        d.sort_by(|a, b| a.0.total_cmp(&b.0));
        let near = max_within(&self.strain_rate, l, cx, cy, 0.5 * r);
        let all = self.strain_rate.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        Precursor {
            hole,
            frames_before: k,
            spiral_core: self.nearest_spiral_core(cx, cy, l, r),
            plus_half: [d.first().map(|p| p.0), d.get(1).map(|p| p.0)],
            plus_half_angle: match (d.first(), d.get(1)) {
                (Some(a), Some(b)) if a.1.is_finite() && b.1.is_finite() => Some(polar_angle_between(a.1, b.1)),
                _ => None,
            },
            minus_half: nearest(&self.minus_half, cx, cy, l, r),
            strain_rate: near / all,
        }
    }
}

/// The distance from (cx, cy) to the nearest of `pts` / R.
fn nearest(pts: &[(f64, f64)], cx: f64, cy: f64, l: usize, r: f64) -> Option<f64> {
    pts.iter().map(|&(x, y)| periodic_distance(x, y, cx, cy, l) / r).min_by(f64::total_cmp)
}

/// One frame's points and its random sites.
#[derive(Clone, Debug, Default)]
struct Past {
    points: FramePoints,
    chance: Vec<(f64, f64)>,
}

/// Keeps the last [`DEPTH`] + 1 frames and measures each nucleation against them.
#[derive(Clone, Debug)]
pub struct Precursors {
    past: VecDeque<Past>,
    rng: ChaCha8Rng,
    /// Per nucleation and frame before it, the measures about the nucleation centroid.
    pub rows: Vec<Precursor>,
    /// The same about each of the [`CHANCE_SITES`] random sites of the same frames, with the
    /// nucleation's hole and frames before.
    pub chance: Vec<Precursor>,
}

impl Default for Precursors {
    fn default() -> Self {
        Precursors {
            past: VecDeque::new(),
            rng: ChaCha8Rng::seed_from_u64(CHANCE_SEED),
            rows: Vec::new(),
            chance: Vec::new(),
        }
    }
}

impl Precursors {
    /// Takes the frame just measured by `a`, after `tracker` was updated with its voids.
    pub fn push(&mut self, a: &Analysis, tracker: &HoleTracker) {
        // Reuse the oldest frame's buffers for the newest.
        let mut now = if self.past.len() > DEPTH { self.past.pop_back().expect("non-empty") } else { Past::default() };
        now.points.take(a);
        let (l, r) = (a.l, a.radius);
        let lf = l as f64;
        now.chance.clear();
        for _ in 0..CHANCE_SITES {
            let x = uniform(&mut self.rng) * lf;
            let y = uniform(&mut self.rng) * lf;
            now.chance.push((x, y));
        }
        self.past.push_front(now);
        for h in tracker.nucleated_holes() {
            let &(_, _, cx, cy) = &tracker.holes[h].history[0];
            let id = tracker.holes[h].id;
            for (k, past) in self.past.iter().enumerate() {
                self.rows.push(past.points.measure(id, k, cx, cy, l, r));
                for &(x, y) in &past.chance {
                    self.chance.push(past.points.measure(id, k, x, y, l, r));
                }
            }
        }
    }
}

/// A uniform number in [0, 1) from 53 random bits: the same on every platform.
fn uniform(rng: &mut ChaCha8Rng) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// The largest value of `f` at sites within `radius` of (cx, cy) on the periodic box.
pub fn max_within(f: &[f64], l: usize, cx: f64, cy: f64, radius: f64) -> f64 {
    let li = l as i64;
    let reach = radius.ceil() as i64 + 1;
    let (x0, y0) = (cx.round() as i64, cy.round() as i64);
    let mut best = f64::NEG_INFINITY;
    for y in y0 - reach..=y0 + reach {
        for x in x0 - reach..=x0 + reach {
            if (x as f64 - cx).hypot(y as f64 - cy) <= radius {
                best = best.max(f[(y.rem_euclid(li) * li + x.rem_euclid(li)) as usize]);
            }
        }
    }
    best
}

//! What precedes a hole (paper Figs. 1c–d and S2): for each hole that nucleates, in each of the
//! frames up to [`DEPTH`] before (0 is the nucleation frame), the distance from the hole's
//! nucleation centroid to the nearest spiral core and to the nearest and second-nearest +½
//! defects, in units of R, and the largest strain rate within R/2 of that centroid over the
//! frame's largest (the paper's per-frame normalisation).

use std::collections::VecDeque;

use super::holes::{periodic_distance, HoleTracker};
use super::Analysis;

/// Frames before nucleation that are looked back on.
pub const DEPTH: usize = 10;

/// One hole, one frame before its nucleation.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Precursor {
    pub hole: usize,
    pub frames_before: usize,
    /// Distance to the nearest spiral core / R (None: no spiral core in that frame).
    pub spiral_core: Option<f64>,
    /// Distances to the nearest and second-nearest +½ defects / R.
    pub plus_half: [Option<f64>; 2],
    /// max ε̇ within R/2 of the nucleation centroid / max ε̇ over the box.
    pub strain_rate: f64,
}

/// The points and strain rate of one frame.
#[derive(Clone, Debug, Default)]
struct Past {
    spiral_cores: Vec<(f64, f64)>,
    plus_half: Vec<(f64, f64)>,
    strain_rate: Vec<f64>,
}

/// Keeps the last [`DEPTH`] + 1 frames and measures each nucleation against them.
#[derive(Clone, Debug, Default)]
pub struct Precursors {
    past: VecDeque<Past>,
    pub rows: Vec<Precursor>,
}

impl Precursors {
    /// Takes the frame just measured by `a`, after `tracker` was updated with its voids.
    pub fn push(&mut self, a: &Analysis, tracker: &HoleTracker) {
        // Reuse the oldest frame's buffers for the newest.
        let mut now = if self.past.len() > DEPTH { self.past.pop_back().expect("non-empty") } else { Past::default() };
        now.spiral_cores.clear();
        now.spiral_cores.extend(a.spiral_cores().map(|p| (p.x, p.y)));
        now.plus_half.clear();
        now.plus_half.extend(a.defects.iter().filter(|d| d.twice_charge > 0).map(|d| (d.x, d.y)));
        now.strain_rate.clone_from(&a.strain_rate);
        self.past.push_front(now);
        let (l, r) = (a.l, a.radius);
        for h in tracker.nucleated_holes() {
            let &(_, _, cx, cy) = &tracker.holes[h].history[0];
            for (k, past) in self.past.iter().enumerate() {
                let mut d: Vec<f64> =
                    past.plus_half.iter().map(|&(x, y)| periodic_distance(x, y, cx, cy, l) / r).collect();
                d.sort_by(f64::total_cmp);
                let spiral = past
                    .spiral_cores
                    .iter()
                    .map(|&(x, y)| periodic_distance(x, y, cx, cy, l) / r)
                    .min_by(f64::total_cmp);
                let near = max_within(&past.strain_rate, l, cx, cy, 0.5 * r);
                let all = past.strain_rate.iter().copied().fold(f64::NEG_INFINITY, f64::max);
                self.rows.push(Precursor {
                    hole: tracker.holes[h].id,
                    frames_before: k,
                    spiral_core: spiral,
                    plus_half: [d.first().copied(), d.get(1).copied()],
                    strain_rate: near / all,
                });
            }
        }
    }
}

/// The largest value of `f` at sites within `radius` of (cx, cy) on the periodic box.
fn max_within(f: &[f64], l: usize, cx: f64, cy: f64, radius: f64) -> f64 {
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

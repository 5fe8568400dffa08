//! The conditional probability of a hole given the local strain rate, P(hole | ε̇) (paper Fig. 2,
//! docs/reading.md §6): for every site of every frame, in bins of ε̇ of width Δε̇ = 0.000125, how many
//! sites there were (N_ε̇) and how many of them lie in a hole that nucleates in the next frame
//! (N_hole,ε̇); P = N_hole,ε̇ / N_ε̇. A site already void in its frame is not counted: it cannot
//! open, and counting it would put sub-threshold voids that grow into a hole at P → 1. The paper's exclusion: "if a hole grows above a threshold size,
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
    /// The previous frame's void sites: already open, they cannot open into a hole.
    previous_void: Vec<bool>,
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
                for ((e, &label), &was_void) in self.previous.iter().zip(&voids.labels).zip(&self.previous_void) {
                    if was_void {
                        continue;
                    }
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
        self.previous_void.clear();
        self.previous_void.extend(voids.labels.iter().map(|&l| l != u32::MAX));
        self.previous_skipped = Some(large_open);
    }

    /// (ε̇ at the bin's lower edge, N_ε̇, N_hole,ε̇, P) for every bin with a site in it.
    pub fn table(&self) -> impl Iterator<Item = (f64, u64, u64, f64)> + '_ {
        self.bins.iter().map(|(&k, &(n, h))| (k as f64 * STRAIN_RATE_BIN, n, h, h as f64 / n as f64))
    }
}

/// An exponential P = A·exp(b ε̇) fitted to the bins, with standard errors.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ExponentialFit {
    pub ln_a: f64,
    /// The coefficient of the exponential (the paper's Fig. 2 inset).
    pub b: f64,
    pub se_ln_a: f64,
    pub se_b: f64,
}

/// Least squares on ln P over the bins with a hole site, weighted by N_hole (the inverse of the
/// variance of ln P̂ ≈ 1/N_hole for small P), over (ε̇, N_ε̇, N_hole,ε̇) bins. The standard
/// errors are those of the weighted fit with the variances known (1/N_hole); None with fewer
/// than two bins with holes at two distinct ε̇.
pub fn least_squares_fit(bins: &[(f64, u64, u64)]) -> Option<ExponentialFit> {
    let pts: Vec<(f64, f64, f64)> = bins
        .iter()
        .filter(|b| b.1 > 0 && b.2 > 0)
        .map(|&(x, n, h)| (x, (h as f64 / n as f64).ln(), h as f64))
        .collect();
    let line = weighted_line(&pts)?;
    Some(ExponentialFit {
        ln_a: line.intercept,
        b: line.slope,
        se_ln_a: (1.0 / line.weight + line.mean_x * line.mean_x / line.sxx).sqrt(),
        se_b: (1.0 / line.sxx).sqrt(),
    })
}

/// A straight line y = intercept + slope·x fitted by weighted least squares.
struct WeightedLine {
    intercept: f64,
    slope: f64,
    /// The weighted mean of x, the sum of the weights and Σ w (x − x̄)²: the fit's errors.
    mean_x: f64,
    weight: f64,
    sxx: f64,
}

/// The weighted least-squares line through (x, y, weight) points; None with fewer than two
/// points or one x for all.
fn weighted_line(pts: &[(f64, f64, f64)]) -> Option<WeightedLine> {
    if pts.len() < 2 {
        return None;
    }
    let sw: f64 = pts.iter().map(|p| p.2).sum();
    let mx = pts.iter().map(|p| p.2 * p.0).sum::<f64>() / sw;
    let my = pts.iter().map(|p| p.2 * p.1).sum::<f64>() / sw;
    let sxx: f64 = pts.iter().map(|p| p.2 * (p.0 - mx) * (p.0 - mx)).sum();
    if sxx <= 0.0 {
        return None;
    }
    let sxy: f64 = pts.iter().map(|p| p.2 * (p.0 - mx) * (p.1 - my)).sum();
    let slope = sxy / sxx;
    Some(WeightedLine { intercept: my - slope * mx, slope, mean_x: mx, weight: sw, sxx })
}

/// Binomial maximum likelihood over every bin: N_hole,ε̇ of N_ε̇ sites opened, each with
/// probability P(ε̇) = A·exp(b ε̇) (< 1), by Newton's method from the least-squares fit (or a
/// flat P), with step halving; the standard errors from the inverse of the observed information.
/// Bins without holes count (they pull P down), unlike in [`least_squares_fit`]. None without a
/// hole site, without two distinct ε̇, or if it does not converge.
pub fn binomial_fit(bins: &[(f64, u64, u64)]) -> Option<ExponentialFit> {
    let total_h: u64 = bins.iter().map(|b| b.2).sum();
    let total_n: u64 = bins.iter().map(|b| b.1).sum();
    if total_h == 0 || bins.iter().filter(|b| b.1 > 0).count() < 2 {
        return None;
    }
    // ε̇ centred on its site-weighted mean, for a well-conditioned Newton step.
    let x0 = bins.iter().map(|b| b.0 * b.1 as f64).sum::<f64>() / total_n as f64;
    let loglik = |a: f64, b: f64| -> Option<f64> {
        let mut l = 0.0;
        for &(x, n, h) in bins {
            let eta = a + b * (x - x0);
            let p = eta.exp();
            if p >= 1.0 {
                return None;
            }
            l += h as f64 * eta + (n - h) as f64 * (-p).ln_1p();
        }
        Some(l)
    };
    let (mut a, mut b) = match least_squares_fit(bins) {
        Some(f) if loglik(f.ln_a + f.b * x0, f.b).is_some() => (f.ln_a + f.b * x0, f.b),
        _ => ((total_h as f64 / total_n as f64).ln(), 0.0),
    };
    let mut l = loglik(a, b)?;
    let info = |a: f64, b: f64| {
        let (mut ga, mut gb, mut haa, mut hab, mut hbb) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(x, n, h) in bins {
            let u = x - x0;
            let p = (a + b * u).exp();
            let g = (h as f64 - n as f64 * p) / (1.0 - p);
            let w = (n - h) as f64 * p / ((1.0 - p) * (1.0 - p));
            ga += g;
            gb += g * u;
            haa += w;
            hab += w * u;
            hbb += w * u * u;
        }
        (ga, gb, haa, hab, hbb)
    };
    for _ in 0..200 {
        let (ga, gb, haa, hab, hbb) = info(a, b);
        let det = haa * hbb - hab * hab;
        if det <= 0.0 || !det.is_finite() {
            return None;
        }
        let (da, db) = ((hbb * ga - hab * gb) / det, (haa * gb - hab * ga) / det);
        let mut step = 1.0;
        let mut moved = false;
        while step > 1e-10 {
            if let Some(l1) = loglik(a + step * da, b + step * db) {
                if l1 >= l - 1e-12 * l.abs() {
                    (a, b, l) = (a + step * da, b + step * db, l1);
                    moved = true;
                    break;
                }
            }
            step *= 0.5;
        }
        let small = (step * da).abs() < 1e-12 * (1.0 + a.abs()) && (step * db).abs() < 1e-10 * (1.0 + b.abs());
        if !moved || small {
            let (_, _, haa, hab, hbb) = info(a, b);
            let det = haa * hbb - hab * hab;
            if det <= 0.0 {
                return None;
            }
            // Var of (α, b) with α = ln A + b x0: ln A = α − b x0.
            let (vaa, vab, vbb) = (hbb / det, -hab / det, haa / det);
            let var_ln_a = vaa - 2.0 * x0 * vab + x0 * x0 * vbb;
            return Some(ExponentialFit { ln_a: a - b * x0, b, se_ln_a: var_ln_a.max(0.0).sqrt(), se_b: vbb.sqrt() });
        }
    }
    None
}

/// How well the exponential's coefficients b of several (χ, ζ) collapse on one curve of
/// x = χ^a/ζ (the paper's inset: a = 0.1): the standard deviation of ln b about the least-squares
/// line in ln x (ln x = a ln χ − ln ζ), with two degrees of freedom taken by the line. A power
/// law b ∝ x^k collapses to zero; `None` with fewer than three points or one x for all.
pub fn collapse_scatter(points: &[(f64, f64, f64)], a: f64) -> Option<f64> {
    if points.len() < 3 {
        return None;
    }
    let pts: Vec<(f64, f64, f64)> =
        points.iter().map(|&(chi, zeta, b)| (a * chi.ln() - zeta.ln(), b.ln(), 1.0)).collect();
    let line = weighted_line(&pts)?;
    let ss: f64 = pts.iter().map(|p| (p.1 - line.intercept - line.slope * p.0).powi(2)).sum();
    Some((ss / (pts.len() as f64 - 2.0)).sqrt())
}

/// The exponent a of χ^a/ζ, on a grid of steps of 0.01 over [0, 1], whose collapse scatters
/// least ([`collapse_scatter`]), with that scatter.
pub fn best_collapse_exponent(points: &[(f64, f64, f64)]) -> Option<(f64, f64)> {
    (0..=100)
        .filter_map(|k| {
            let a = k as f64 / 100.0;
            collapse_scatter(points, a).map(|s| (a, s))
        })
        .min_by(|p, q| p.1.total_cmp(&q.1))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Bins drawn exactly from P = 0.001·exp(2000 ε̇) with many sites: both fits recover it.
    #[test]
    fn both_fits_recover_an_exponential() {
        let bins: Vec<(f64, u64, u64)> = (0..10)
            .map(|k| {
                let x = k as f64 * STRAIN_RATE_BIN;
                let n = 10_000_000u64;
                let p = 0.001 * (2000.0 * x).exp();
                (x, n, (p * n as f64).round() as u64)
            })
            .collect();
        for f in [least_squares_fit(&bins).unwrap(), binomial_fit(&bins).unwrap()] {
            assert!((f.b - 2000.0).abs() < 5.0 && (f.ln_a - 0.001f64.ln()).abs() < 0.01, "{f:?}");
            assert!(f.se_b > 0.0 && f.se_b < 50.0 && f.se_ln_a > 0.0, "{f:?}");
        }
    }

    /// Few hole sites: the binomial fit counts the bins without holes, least squares cannot.
    #[test]
    fn the_binomial_fit_counts_bins_without_holes() {
        let bins = [(0.0, 1000, 1), (0.001, 1000, 0), (0.002, 1000, 10), (0.003, 1000, 0)];
        let ls = least_squares_fit(&bins).unwrap();
        let ml = binomial_fit(&bins).unwrap();
        assert!(ls.b > ml.b, "empty bins pull the binomial coefficient down: {ls:?} {ml:?}");
        assert!(ml.se_b.is_finite() && ml.se_b > 0.0);
        assert_eq!(least_squares_fit(&bins[..2]), None);
        assert_eq!(binomial_fit(&[(0.0, 10, 0), (0.1, 10, 0)]), None);
    }

    #[test]
    fn the_collapse_finds_the_exponent_of_a_power_law_in_chi_to_the_a_over_zeta() {
        // b = 900 (χ^0.25/ζ)^1.5 on a 3 × 3 grid: a = 0.25 collapses exactly, the paper's 0.1
        // and ζ alone do not.
        let mut points = Vec::new();
        for chi in [0.01f64, 0.005, 0.001] {
            for zeta in [0.3f64, 0.4, 0.5] {
                points.push((chi, zeta, 900.0 * (chi.powf(0.25) / zeta).powf(1.5)));
            }
        }
        assert!(collapse_scatter(&points, 0.25).unwrap() < 1e-12);
        let (s0, s1) = (collapse_scatter(&points, 0.0).unwrap(), collapse_scatter(&points, 0.1).unwrap());
        assert!(s0 > s1 && s1 > 0.05, "{s0} {s1}");
        let (a, s) = best_collapse_exponent(&points).unwrap();
        assert!((a - 0.25).abs() < 1e-9 && s < 1e-12, "{a} {s}");
        assert_eq!(collapse_scatter(&points[..2], 0.1), None);
    }
}

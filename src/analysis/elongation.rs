//! How elongated each cell is: the aspect ratio read off its shape tensor.
//!
//! The shape tensor of Eq. 5 is the traceless part of the gradient tensor
//! G_i = ∫ ∇φ_i ∇φ_iᵀ; with its trace T_i = ∫ |∇φ_i|², G_i's eigenvalues are
//! g± = T_i/2 ± |Q_i|. For a cell with a thin interface of uniform profile, G_i is the profile's
//! constant times ∮ n nᵀ ds over the cell's outline (n the outward normal), so g+/g− depends
//! only on the outline's shape. The aspect ratio reported is that of the ellipse with the same
//! ratio g+/g−: exact for elliptical cells, a monotone measure of elongation for any other.
//! For an ellipse of semi-axes a ≥ b (a along x), with h(t) = √(a² sin²t + b² cos²t),
//!   ∮ n_y² ds = ∫₀^{2π} a² sin²t / h dt,   ∮ n_x² ds = ∫₀^{2π} b² cos²t / h dt,
//! whose ratio rises from 1 (a circle) like (a/b)²/ln(a/b) for long rods.

use crate::model::{row_neighbourhood, shape_tensor, Patch, Real};

/// Largest aspect ratio reported: beyond it g+/g− is too flat to resolve on a lattice.
pub const MAX_ASPECT_RATIO: f64 = 50.0;

/// T = ∫ |∇φ|² over the patch, with the central differences of [`shape_tensor`].
pub fn gradient_trace<T: Real>(patch: Patch, phi: &[T]) -> f64 {
    let mut t = 0.0;
    for b in 0..patch.h {
        t += row_neighbourhood(phi, patch, b).gradients().map(|(gx, gy)| gx * gx + gy * gy).sum::<f64>();
    }
    t
}

/// Quadrature points of the ellipse integrals: the trapezoid rule on a smooth periodic integrand
/// converges geometrically, and 512 points resolve it to 1e-12 up to k = 50.
const POINTS: usize = 512;
/// Aspect ratios tabulated once (log-spaced in [1, MAX_ASPECT_RATIO]) to bracket an inversion.
const GRID: usize = 256;

/// What every inversion reuses: (sin²t, cos²t) at the quadrature points, and the ratio on a grid
/// of k. Computed once per process, so a frame's hundred inversions cost a few integrals each.
struct Tables {
    samples: Vec<(f64, f64)>,
    grid: Vec<(f64, f64)>,
}

fn tables() -> &'static Tables {
    static TABLES: std::sync::OnceLock<Tables> = std::sync::OnceLock::new();
    TABLES.get_or_init(|| {
        let samples: Vec<(f64, f64)> = (0..POINTS)
            .map(|j| {
                let t = (j as f64 + 0.5) * std::f64::consts::TAU / POINTS as f64;
                let (s, c) = (libm::sin(t), libm::cos(t));
                (s * s, c * c)
            })
            .collect();
        let grid = (0..GRID)
            .map(|i| {
                let k = libm::pow(MAX_ASPECT_RATIO, i as f64 / (GRID - 1) as f64);
                (k, ratio_from(&samples, k))
            })
            .collect();
        Tables { samples, grid }
    })
}

fn ratio_from(samples: &[(f64, f64)], k: f64) -> f64 {
    let (mut along, mut across) = (0.0, 0.0);
    for &(s2, c2) in samples {
        let h = (k * k * s2 + c2).sqrt();
        across += k * k * s2 / h;
        along += c2 / h;
    }
    across / along
}

/// g+/g− of the outline of an ellipse with aspect ratio k ≥ 1 (see the module's doc).
pub fn ellipse_eigenvalue_ratio(k: f64) -> f64 {
    ratio_from(&tables().samples, k)
}

/// The aspect ratio of a cell from its gradient tensor's trace T and shape tensor Q:
/// the k ≥ 1 with [`ellipse_eigenvalue_ratio`]\(k) = (T/2 + |Q|)/(T/2 − |Q|), bracketed on the
/// tabulated grid and refined by regula falsi (Illinois). 1 for a round cell;
/// [`MAX_ASPECT_RATIO`] at most; None for a cell with no gradient.
pub fn aspect_ratio(trace: f64, q: [f64; 2]) -> Option<f64> {
    let q = (q[0] * q[0] + q[1] * q[1]).sqrt();
    if trace.is_nan() || trace <= 0.0 || !q.is_finite() {
        return None;
    }
    let (hi, lo) = (0.5 * trace + q, 0.5 * trace - q);
    let t = tables();
    let last = t.grid[GRID - 1];
    if lo <= 0.0 || hi / lo >= last.1 {
        return Some(MAX_ASPECT_RATIO);
    }
    let target = hi / lo;
    let i = t.grid.partition_point(|g| g.1 <= target).clamp(1, GRID - 1);
    let ((mut a, mut fa), (mut b, mut fb)) =
        ((t.grid[i - 1].0, t.grid[i - 1].1 - target), (t.grid[i].0, t.grid[i].1 - target));
    let mut side = 0;
    for _ in 0..100 {
        if b - a <= 1e-14 * b {
            break;
        }
        let c = (a * fb - b * fa) / (fb - fa);
        let fc = ellipse_eigenvalue_ratio(c) - target;
        if fc == 0.0 {
            return Some(c);
        }
        if (fc < 0.0) == (fa < 0.0) {
            (a, fa) = (c, fc);
            if side == -1 {
                fb *= 0.5;
            }
            side = -1;
        } else {
            (b, fb) = (c, fc);
            if side == 1 {
                fa *= 0.5;
            }
            side = 1;
        }
    }
    Some(if fa.abs() < fb.abs() { a } else { b })
}

/// The aspect ratio of one cell given as its patch and φ.
pub fn cell_aspect_ratio<T: Real>(patch: Patch, phi: &[T]) -> Option<f64> {
    aspect_ratio(gradient_trace(patch, phi), shape_tensor(patch, phi))
}

/// Mean and 90th percentile (nearest rank) of aspect ratios given in ascending order; None
/// when empty.
pub fn mean_and_p90(values: &[f64]) -> Option<(f64, f64)> {
    if values.is_empty() {
        return None;
    }
    debug_assert!(values.is_sorted_by(|a, b| a <= b), "mean_and_p90 takes sorted values");
    let mean = values.iter().sum::<f64>() / values.len() as f64;
    let rank = (0.9 * values.len() as f64).ceil() as usize;
    Some((mean, values[rank.clamp(1, values.len()) - 1]))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth ellipse (tanh profile of width 2, the model's interface) with semi-axes (a, b)
    /// rotated by θ, on a padded patch of side w.
    fn ellipse(w: usize, a: f64, b: f64, theta: f64) -> (Patch, Vec<f64>) {
        let patch = Patch { x0: 0, y0: 0, w, h: w };
        let mut phi = vec![0.0; patch.padded_len()];
        let c = (w as f64 - 1.0) / 2.0;
        for y in 0..w {
            for x in 0..w {
                let (dx, dy) = (x as f64 - c, y as f64 - c);
                let (u, v) = (dx * theta.cos() + dy * theta.sin(), -dx * theta.sin() + dy * theta.cos());
                // Signed distance to the outline to first order, (r − 1)/|∇r|, so that the
                // interface has the same width all round.
                let r = (u * u / (a * a) + v * v / (b * b)).sqrt().max(1e-9);
                let grad = ((u / (a * a)).powi(2) + (v / (b * b)).powi(2)).sqrt() / r;
                let d = (r - 1.0) / grad.max(1e-9);
                phi[patch.idx(x, y)] = 0.5 * (1.0 - (d / 2.0).tanh());
            }
        }
        (patch, phi)
    }

    #[test]
    fn the_ellipse_relation_starts_at_one_and_rises() {
        assert!((ellipse_eigenvalue_ratio(1.0) - 1.0).abs() < 1e-12);
        let r: Vec<f64> = [1.5, 2.0, 3.0, 5.0, 10.0].iter().map(|&k| ellipse_eigenvalue_ratio(k)).collect();
        assert!(r.windows(2).all(|w| w[1] > w[0]), "{r:?}");
        // For long rods, ∮ n_y² ≈ 4a and ∮ n_x² ≈ 4b ln(4a/b) / ... : the ratio grows faster than k.
        assert!(r[4] > 10.0, "{r:?}");
        // The inversion returns the ratio it was given.
        for k in [1.0, 1.7, 3.2, 7.5] {
            let g = ellipse_eigenvalue_ratio(k);
            let got = aspect_ratio(1.0 + g, [0.5 * (g - 1.0), 0.0]).unwrap();
            assert!((got - k).abs() < 1e-9, "{k}: {got}");
        }
    }

    #[test]
    fn round_cells_have_aspect_ratio_one_and_ellipses_their_own() {
        let (p, phi) = ellipse(48, 8.0, 8.0, 0.0);
        let round = cell_aspect_ratio(p, &phi).unwrap();
        assert!((round - 1.0).abs() < 0.02, "{round}");
        for (a, b, theta) in [(12.0, 6.0, 0.0), (12.0, 6.0, 0.7), (15.0, 5.0, -1.2)] {
            let (p, phi) = ellipse(64, a, b, theta);
            let k = cell_aspect_ratio(p, &phi).unwrap();
            assert!((k / (a / b) - 1.0).abs() < 0.06, "a/b = {}, measured {k}", a / b);
        }
    }

    #[test]
    fn no_gradient_no_ratio_and_percentiles_by_rank() {
        let p = Patch { x0: 0, y0: 0, w: 8, h: 8 };
        assert_eq!(cell_aspect_ratio(p, &vec![0.0; p.padded_len()]), None);
        let mut v: Vec<f64> = (1..=10).map(f64::from).collect();
        v.reverse();
        v.sort_by(f64::total_cmp);
        assert_eq!(mean_and_p90(&v), Some((5.5, 9.0)));
        assert_eq!(mean_and_p90(&[]), None);
    }
}

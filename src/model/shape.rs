//! The shape tensor of Eq. 5 and its normalisation: the nematic axis of each cell.
//!
//!   Q_i = −∫ [∇φ_i ∇φ_iᵀ − ½ Tr(∇φ_i ∇φ_iᵀ)],  i.e.  Q_xx = −½ ∫ (∂_xφ² − ∂_yφ²),  Q_xy = −∫ ∂_xφ ∂_yφ.
//!
//! A cell elongated along x has its long flat sides facing ±y, so ∂_yφ dominates and Q_xx > 0:
//! the main axis of Q lies along the elongation. Only the direction θ_i matters:
//!   Q̂_i = m (Q_xx, Q_xy) / √(Q_xx² + Q_xy² + ε²) → m (cos 2θ_i, sin 2θ_i),
//! with m = `q_magnitude` (½: the unit-order nematic tensor n n − I/2; 2: the paper's
//! "normalised by 0.5|Q|" read literally) and ε = `q_epsilon`, below which a nearly round cell
//! fades to no direction instead of flipping between arbitrary ones.

use crate::model::lattice::{row_neighbourhood, Patch};
use crate::model::precision::{load, Real};
use crate::model::sum::{combine, LANES};

/// Central-difference gradient of a padded field (row stride s) at padded index i.
#[inline(always)]
pub fn gradient<T: Real>(f: &[T], i: usize, s: usize) -> (f64, f64) {
    (0.5 * (load(f[i + 1]) - load(f[i - 1])), 0.5 * (load(f[i + s]) - load(f[i - s])))
}

/// (Q_xx, Q_xy) of Eq. 5 over the patch (central differences).
pub fn shape_tensor<T: Real>(patch: Patch, phi: &[T]) -> [f64; 2] {
    // LANES partial sums per component, site k of every row going to partial sum k mod LANES
    // (`sum`), so that the loop runs in SIMD lanes; the order is fixed, so the bits are too.
    let (mut qxx, mut qxy) = ([0.0; LANES], [0.0; LANES]);
    let mut add = |k: usize, (gx, gy): (f64, f64)| {
        qxx[k] -= 0.5 * (gx * gx - gy * gy);
        qxy[k] -= gx * gy;
    };
    for b in 0..patch.h {
        let f = row_neighbourhood(phi, patch, b);
        let (xp, xm, yp, ym) = (f.xp, f.xm, f.yp, f.ym);
        let whole = xp.len() - xp.len() % LANES;
        let gradient = |k: usize| (0.5 * (load(xp[k]) - load(xm[k])), 0.5 * (load(yp[k]) - load(ym[k])));
        for c in (0..whole).step_by(LANES) {
            for k in 0..LANES {
                add(k, gradient(c + k));
            }
        }
        for k in whole..xp.len() {
            add(k - whole, gradient(k));
        }
    }
    [combine(qxx), combine(qxy)]
}

/// Q̂ = m Q / √(|Q|² + ε²).
pub fn normalise(q: [f64; 2], magnitude: f64, epsilon: f64) -> [f64; 2] {
    let norm = (q[0] * q[0] + q[1] * q[1] + epsilon * epsilon).sqrt();
    [magnitude * q[0] / norm, magnitude * q[1] / norm]
}

/// Angle θ ∈ (−π/2, π/2] of the main axis of (Q_xx, Q_xy).
pub fn axis_angle(q: [f64; 2]) -> f64 {
    0.5 * libm::atan2(q[1], q[0])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A smooth ellipse with semi-axes (a, b) rotated by θ, on a padded patch.
    pub(crate) fn ellipse(patch: Patch, a: f64, b: f64, theta: f64) -> Vec<f64> {
        let mut phi = vec![0.0; patch.padded_len()];
        let (cx, cy) = (patch.w as f64 / 2.0, patch.h as f64 / 2.0);
        let (c, s) = (theta.cos(), theta.sin());
        for j in 0..patch.h {
            for i in 0..patch.w {
                let (dx, dy) = (i as f64 - cx, j as f64 - cy);
                let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
                let r = ((u / a).powi(2) + (v / b).powi(2)).sqrt();
                phi[patch.idx(i, j)] = 1.0 / (1.0 + ((r - 1.0) * a.min(b)).exp());
            }
        }
        phi
    }

    #[test]
    fn main_axis_follows_the_long_axis() {
        let patch = Patch { x0: 0, y0: 0, w: 40, h: 40 };
        for deg in [0.0f64, 30.0, 60.0, 90.0, 135.0, -20.0] {
            let th = deg.to_radians();
            let q = shape_tensor(patch, &ellipse(patch, 11.0, 6.0, th));
            let got = axis_angle(q);
            let mut d = (got - th).rem_euclid(std::f64::consts::PI);
            if d > std::f64::consts::FRAC_PI_2 {
                d -= std::f64::consts::PI;
            }
            assert!(d.abs() < 0.02, "θ = {deg}°: axis at {}°", got.to_degrees());
        }
        let q = shape_tensor(patch, &ellipse(patch, 11.0, 6.0, 0.0));
        assert!(q[0] > 0.0, "elongated along x gives Q_xx > 0");
    }

    #[test]
    fn normalised_has_the_chosen_magnitude_and_fades_when_round() {
        let q = normalise([3.0, 4.0], 0.5, 1e-6);
        assert!(((q[0] * q[0] + q[1] * q[1]).sqrt() - 0.5).abs() < 1e-9);
        let tiny = normalise([1e-5, 0.0], 2.0, 1e-2);
        assert!(tiny[0] < 0.01);
        let patch = Patch { x0: 0, y0: 0, w: 30, h: 30 };
        let round = shape_tensor(patch, &ellipse(patch, 8.0, 8.0, 0.0));
        assert!(round[0].abs() < 1e-9 && round[1].abs() < 1e-9, "{round:?}");
    }
}

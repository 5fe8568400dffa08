//! Force densities on each cell (Eqs. 3 and 4).
//!
//!   passive  f^p_i = −∇μ_i        (`PassiveForce::GradMu`, as printed)
//!            f^p_i = −φ_i ∇μ_i    (`PassiveForce::PhiGradMu`, the usual phase-field form)
//!   active   f^a_i = −ζ Q̂_i · ∇φ_i
//!
//! With ζ > 0 (extensile) and Q̂ along the long axis, the active force at a tip points outwards:
//! at the right tip of a cell elongated along x, ∂_xφ < 0 and f^a_x = −ζ Q̂_xx ∂_xφ > 0.

use multiversion::multiversion;

use crate::model::lattice::{row_mut, row_neighbourhood, Patch};
use crate::model::params::PassiveForce;
use crate::model::precision::{load, Real};

/// f_i = f^p_i + f^a_i at every site of the patch. μ is read with zero outside the patch (its
/// halo), where φ_i is below the presence threshold by the patch margin.
#[allow(clippy::too_many_arguments)]
#[multiversion(targets("x86_64+avx2"))]
pub fn force_density<T: Real>(
    patch: Patch,
    phi: &[T],
    mu: &[T],
    q_hat: [f64; 2],
    zeta: f64,
    passive: PassiveForce,
    fx: &mut [T],
    fy: &mut [T],
) {
    let (qxx, qxy) = (q_hat[0], q_hat[1]);
    let phi_weighted = passive == PassiveForce::PhiGradMu;
    for b in 0..patch.h {
        let (p, m) = (row_neighbourhood(phi, patch, b), row_neighbourhood(mu, patch, b));
        let out = row_mut(fx, patch, b).iter_mut().zip(row_mut(fy, patch, b).iter_mut());
        let grads = m.gradients().zip(p.gradients()).zip(p.c);
        for ((ox, oy), (((mx, my), (px, py)), &c)) in out.zip(grads) {
            let weight = if phi_weighted { load(c) } else { 1.0 };
            *ox = T::from_f64(-weight * mx - zeta * (qxx * px + qxy * py));
            *oy = T::from_f64(-weight * my - zeta * (qxy * px - qxx * py));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::shape::{normalise, shape_tensor};

    fn ellipse_x(patch: Patch) -> Vec<f64> {
        let mut phi = vec![0.0; patch.padded_len()];
        for j in 0..patch.h {
            for i in 0..patch.w {
                let (dx, dy) = (i as f64 - 20.0, j as f64 - 15.0);
                let r = ((dx / 12.0).powi(2) + (dy / 6.0).powi(2)).sqrt();
                phi[patch.idx(i, j)] = 1.0 / (1.0 + ((r - 1.0) * 6.0).exp());
            }
        }
        phi
    }

    #[test]
    fn extensile_activity_pulls_the_tips_outwards() {
        let patch = Patch { x0: 0, y0: 0, w: 40, h: 30 };
        let phi = ellipse_x(patch);
        let q = normalise(shape_tensor(patch, &phi), 0.5, 1e-2);
        let mu = vec![0.0; patch.padded_len()];
        let (mut fx, mut fy) = (vec![0.0; phi.len()], vec![0.0; phi.len()]);
        force_density(patch, &phi, &mu, q, 1.0, PassiveForce::GradMu, &mut fx, &mut fy);
        // Right tip (x ≈ 32), left tip (x ≈ 8): pushed outwards along x.
        assert!(fx[patch.idx(32, 15)] > 0.0);
        assert!(fx[patch.idx(8, 15)] < 0.0);
        // Flanks (y ≈ 9 and 21): pulled inwards, towards the axis.
        assert!(fy[patch.idx(20, 21)] < 0.0);
        assert!(fy[patch.idx(20, 9)] > 0.0);
        // Contractile activity reverses it.
        force_density(patch, &phi, &mu, q, -1.0, PassiveForce::GradMu, &mut fx, &mut fy);
        assert!(fx[patch.idx(32, 15)] < 0.0);
        // An active dipole exerts no net force on the cell: what remains is φ ≈ 5e-5 at the patch edge.
        let big = Patch { x0: 0, y0: 0, w: 64, h: 54 };
        let mut phi = vec![0.0; big.padded_len()];
        for j in 0..big.h {
            for i in 0..big.w {
                let (dx, dy) = (i as f64 - 32.0, j as f64 - 27.0);
                let r = ((dx / 12.0).powi(2) + (dy / 6.0).powi(2)).sqrt();
                phi[big.idx(i, j)] = 1.0 / (1.0 + ((r - 1.0) * 6.0).exp());
            }
        }
        let mu = vec![0.0; phi.len()];
        let (mut fx, mut fy) = (vec![0.0; phi.len()], vec![0.0; phi.len()]);
        force_density(big, &phi, &mu, q, 1.0, PassiveForce::GradMu, &mut fx, &mut fy);
        let (sx, sy): (f64, f64) = (fx.iter().sum(), fy.iter().sum());
        let total: f64 = fx.iter().chain(&fy).map(|f| f.abs()).sum();
        assert!(total > 1.0 && sx.abs() + sy.abs() < 1e-5 * total, "net active force ({sx}, {sy}) of {total}");
    }

    #[test]
    fn passive_force_is_minus_grad_mu() {
        let patch = Patch { x0: 0, y0: 0, w: 6, h: 5 };
        let phi = vec![0.5; patch.padded_len()];
        let mut mu = vec![0.0; patch.padded_len()];
        for j in 0..patch.h {
            for i in 0..patch.w {
                mu[patch.idx(i, j)] = 2.0 * i as f64 + 3.0 * j as f64;
            }
        }
        let (mut fx, mut fy) = (vec![0.0; phi.len()], vec![0.0; phi.len()]);
        force_density(patch, &phi, &mu, [0.0, 0.0], 0.0, PassiveForce::GradMu, &mut fx, &mut fy);
        assert_eq!((fx[patch.idx(2, 2)], fy[patch.idx(2, 2)]), (-2.0, -3.0));
        force_density(patch, &phi, &mu, [0.0, 0.0], 0.0, PassiveForce::PhiGradMu, &mut fx, &mut fy);
        assert_eq!((fx[patch.idx(2, 2)], fy[patch.idx(2, 2)]), (-1.0, -1.5));
    }
}

//! The equation of motion (Eq. 1) on each patch, given the lattice friction fields:
//!
//!   v_i(x) = [f_i(x) + ξ_c S(x)] / [ξ_s(x) + ξ_c N(x)]        (Eq. 2, see [`crate::model::friction`])
//!   ∂_t φ_i = −v_i · ∇φ_i − J₀ μ_i                           (Eq. 1)
//!
//! The division is a product with the mobility 1/[ξ_s + ξ_c N], computed once per lattice site.
//!
//! During relaxation ξ_c = 0 and ξ_s is replaced by ξ_relax, so v_i = f_i / ξ_relax.

use multiversion::multiversion;
use num_complex::Complex64 as C64;

use crate::model::lattice::{Neighbourhood, Patch};
use crate::model::params::{Advection, FrictionWeights};
use crate::model::precision::{load, Real};

/// The weight w_j(x) with which cell j counts in the friction sum of Eq. 2 (docs/reading.md §4).
#[inline(always)]
pub fn friction_weight(kind: FrictionWeights, phi: f64, threshold: f64) -> f64 {
    match kind {
        // φ undershoots 0 and overshoots 1 near interfaces; unclamped, n could vanish or turn
        // negative at the edge of a hole.
        FrictionWeights::Phi => phi.clamp(0.0, 1.0),
        FrictionWeights::Presence => {
            if phi > threshold {
                1.0
            } else {
                0.0
            }
        }
        // Called only on the sites of the cell's patch: there it is defined, so it counts.
        FrictionWeights::Subdomain => 1.0,
    }
}

/// Lattice fields the velocity of every cell is built from.
pub struct Drag<'a> {
    /// 1/[ξ_s(x) + ξ_c N(x)].
    pub mobility: &'a [f64],
    /// ξ_c S(x), x and y as re and im.
    pub pull: &'a [C64],
}

/// The cell's fields on its patch that this stage reads and writes.
pub struct MotionFields<'a, T = f64> {
    pub phi: &'a [T],
    pub mu: &'a [T],
    pub fx: &'a [T],
    pub fy: &'a [T],
    /// Where v_i goes, if it is to be kept (Heun's predictor does not keep it: the corrector's
    /// replaces it before anything reads it, and not writing it saves two of the pass's nine
    /// streams).
    pub velocity: Option<(&'a mut [T], &'a mut [T])>,
    pub rate: &'a mut [T],
}

/// v_i (if kept) and ∂_t φ_i at every site of the patch.
#[multiversion(targets("x86_64+avx2"))]
pub fn velocity_and_rate<T: Real>(
    patch: Patch,
    c: MotionFields<T>,
    drag: &Drag,
    l: usize,
    j0: f64,
    advection: Advection,
) {
    match (c.velocity.is_some(), advection) {
        (true, Advection::Central) => rates::<T, true, false>(patch, c, drag, l, j0),
        (true, Advection::Upwind) => rates::<T, true, true>(patch, c, drag, l, j0),
        (false, Advection::Central) => rates::<T, false, false>(patch, c, drag, l, j0),
        (false, Advection::Upwind) => rates::<T, false, true>(patch, c, drag, l, j0),
    }
}

/// The pass itself, one copy per choice, so that no choice is tested site by site and each loop
/// runs in SIMD lanes.
#[inline(always)]
fn rates<T: Real, const KEEP_V: bool, const UPWIND: bool>(
    patch: Patch,
    c: MotionFields<T>,
    drag: &Drag,
    l: usize,
    j0: f64,
) {
    let MotionFields { phi, mu, fx, fy, velocity, rate } = c;
    let (vx_all, vy_all) = velocity.unwrap_or_default();
    for run in patch.runs(l) {
        let len = run.len;
        let f = Neighbourhood::new(phi, patch, run.b, run.a0, len);
        let mobility = &drag.mobility[run.global..][..len];
        let pull = &drag.pull[run.global..][..len];
        let (mu, fx, fy) = (&mu[run.padded..][..len], &fx[run.padded..][..len], &fy[run.padded..][..len]);
        let rate = &mut rate[run.padded..][..len];
        let (vx_out, vy_out) = if KEEP_V {
            (&mut vx_all[run.padded..][..len], &mut vy_all[run.padded..][..len])
        } else {
            (&mut [][..], &mut [][..])
        };
        for k in 0..len {
            let vx = (load(fx[k]) + pull[k].re) * mobility[k];
            let vy = (load(fy[k]) + pull[k].im) * mobility[k];
            if KEEP_V {
                vx_out[k] = T::from_f64(vx);
                vy_out[k] = T::from_f64(vy);
            }
            let (gx, gy) = if UPWIND {
                let c = load(f.c[k]);
                (
                    if vx > 0.0 { c - load(f.xm[k]) } else { load(f.xp[k]) - c },
                    if vy > 0.0 { c - load(f.ym[k]) } else { load(f.yp[k]) - c },
                )
            } else {
                f.gradient(k)
            };
            rate[k] = T::from_f64(-(vx * gx + vy * gy) - j0 * load(mu[k]));
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn uniform_velocity_translates_a_profile() {
        // φ = x on a patch, f = (ξ, 0) with denominator ξ: v = (1, 0) and ∂_t φ = −1.
        let patch = Patch { x0: 0, y0: 0, w: 5, h: 3 };
        let l = 8;
        let mut phi = vec![0.0; patch.padded_len()];
        for b in 0..patch.h + 2 {
            for a in 0..patch.w + 2 {
                phi[b * patch.stride() + a] = a as f64;
            }
        }
        let n = phi.len();
        let mu = vec![0.0; n];
        let fx = vec![2.0; n];
        let fy = vec![0.0; n];
        let (mut vx, mut vy, mut rate) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        let mobility = vec![0.5; l * l];
        let pull = vec![C64::new(0.0, 0.0); l * l];
        for adv in [Advection::Central, Advection::Upwind] {
            velocity_and_rate(
                patch,
                MotionFields {
                    phi: &phi,
                    mu: &mu,
                    fx: &fx,
                    fy: &fy,
                    velocity: Some((&mut vx, &mut vy)),
                    rate: &mut rate,
                },
                &Drag { mobility: &mobility, pull: &pull },
                l,
                1.0,
                adv,
            );
            let i = patch.idx(2, 1);
            assert_eq!((vx[i], vy[i], rate[i]), (1.0, 0.0, -1.0));
        }
    }

    /// Eq. 1 site by site with everything non-trivial: μ ≠ 0, J₀ = 0.7, a pull, and a profile
    /// φ = a² + 2b² (padded coordinates) whose backward, central and forward differences all
    /// differ (2a − 1, 2a, 2a + 1 along x), under a velocity that changes sign across the patch.
    /// Expected ∂_t φ = −v·∇φ − J₀ μ in closed form, with ∇φ taken from the upwind side (against
    /// v) for `Upwind`. A wrong sign or factor of J₀ μ, a J₀ dropped, downwind for upwind, or
    /// one-sided differences for central all miss it.
    #[test]
    fn rate_is_minus_advection_minus_j0_mu() {
        let patch = Patch { x0: 0, y0: 0, w: 6, h: 5 };
        let l = 8;
        let n = patch.padded_len();
        let (mut phi, mut mu, mut fx, mut fy) = (vec![0.0; n], vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        for v in 0..patch.h + 2 {
            for u in 0..patch.w + 2 {
                let (i, uf, vf) = (v * patch.stride() + u, u as f64, v as f64);
                phi[i] = uf * uf + 2.0 * vf * vf;
                mu[i] = 0.3 + 0.1 * uf - 0.2 * vf;
                fx[i] = uf - 3.5;
                fy[i] = 2.0 - vf;
            }
        }
        let mobility = vec![0.5; l * l];
        let pull = vec![C64::new(0.25, -0.5); l * l];
        let j0 = 0.7;
        for adv in [Advection::Central, Advection::Upwind] {
            let (mut vx, mut vy, mut rate) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
            velocity_and_rate(
                patch,
                MotionFields {
                    phi: &phi,
                    mu: &mu,
                    fx: &fx,
                    fy: &fy,
                    velocity: Some((&mut vx, &mut vy)),
                    rate: &mut rate,
                },
                &Drag { mobility: &mobility, pull: &pull },
                l,
                j0,
                adv,
            );
            let mut signs = [0; 4];
            for b in 0..patch.h {
                for a in 0..patch.w {
                    let (u, v) = ((a + 1) as f64, (b + 1) as f64);
                    let (wx, wy) = (0.5 * (u - 3.5 + 0.25), 0.5 * (2.0 - v - 0.5));
                    let (gx, gy) = match adv {
                        Advection::Central => (2.0 * u, 4.0 * v),
                        Advection::Upwind => (
                            if wx > 0.0 { 2.0 * u - 1.0 } else { 2.0 * u + 1.0 },
                            if wy > 0.0 { 4.0 * v - 2.0 } else { 4.0 * v + 2.0 },
                        ),
                    };
                    let want = -(wx * gx + wy * gy) - j0 * (0.3 + 0.1 * u - 0.2 * v);
                    let i = patch.idx(a, b);
                    assert_eq!((vx[i], vy[i]), (wx, wy), "{adv:?} v at ({a}, {b})");
                    assert!((rate[i] - want).abs() < 1e-12, "{adv:?} at ({a}, {b}): {} want {want}", rate[i]);
                    signs[usize::from(wx > 0.0)] += 1;
                    signs[2 + usize::from(wy > 0.0)] += 1;
                }
            }
            assert!(signs.iter().all(|&k| k > 0), "v must change sign along both axes: {signs:?}");
        }
    }

    #[test]
    fn weights_are_clamped_or_counted() {
        assert_eq!(friction_weight(FrictionWeights::Phi, 1.2, 0.01), 1.0);
        assert_eq!(friction_weight(FrictionWeights::Phi, -0.1, 0.01), 0.0);
        assert_eq!(friction_weight(FrictionWeights::Phi, 0.3, 0.01), 0.3);
        assert_eq!(friction_weight(FrictionWeights::Presence, 0.02, 0.01), 1.0);
        assert_eq!(friction_weight(FrictionWeights::Presence, 0.005, 0.01), 0.0);
        assert_eq!(friction_weight(FrictionWeights::Subdomain, 0.0, 0.01), 1.0);
        assert_eq!(friction_weight(FrictionWeights::Subdomain, -0.02, 0.01), 1.0);
    }
}

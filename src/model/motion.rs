//! The equation of motion (Eq. 1) on each patch, given the lattice friction fields:
//!
//!   v_i(x) = [f_i(x) + ξ_c S(x)] / [ξ_s(x) + ξ_c N(x)]        (Eq. 2, see [`crate::model::friction`])
//!   ∂_t φ_i = −v_i · ∇φ_i − J₀ μ_i                           (Eq. 1)
//!
//! The division is a product with the mobility 1/[ξ_s + ξ_c N], computed once per lattice site.
//!
//! During relaxation ξ_c = 0 and ξ_s is replaced by ξ_relax, so v_i = f_i / ξ_relax.

use num_complex::Complex64 as C64;

use crate::model::lattice::{Neighbourhood, Patch};
use crate::model::params::{Advection, FrictionWeights};

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

/// The cell's fields on its patch that this stage reads, and what it writes.
pub struct MotionFields<'a> {
    pub phi: &'a [f64],
    pub mu: &'a [f64],
    pub fx: &'a [f64],
    pub fy: &'a [f64],
    pub out: Output<'a>,
}

/// What the pass writes. Heun's update is taken site by site as the rate is known, so the
/// patch fields are streamed once per evaluation instead of twice. Only the interior of each
/// patch is written: the halos stay zero.
pub enum Output<'a> {
    /// v_i and ∂_t φ_i.
    Rate { vx: &'a mut [f64], vy: &'a mut [f64], rate: &'a mut [f64] },
    /// Heun's predictor: k1 = ∂_t φ_i and next = φ_i + Δt k1. No v: the corrector's replaces it
    /// before anything reads it.
    Predict { dt: f64, k1: &'a mut [f64], next: &'a mut [f64] },
    /// Heun's corrector: v_i and next = φ_0 + ½Δt (k1 + ∂_t φ_i).
    Correct {
        dt: f64,
        phi0: &'a [f64],
        k1: &'a [f64],
        vx: &'a mut [f64],
        vy: &'a mut [f64],
        next: &'a mut [f64],
        lo: f64,
        hi: f64,
    },
}

/// v_i and ∂_t φ_i at every site of the patch, written as `c.out` says. Returns whether some
/// corrected φ is not finite or lies outside [lo, hi] (always false for the other outputs).
pub fn velocity_and_rate(patch: Patch, c: MotionFields, drag: &Drag, l: usize, j0: f64, advection: Advection) -> bool {
    let (phi, mu_all, fx_all, fy_all, mut out) = (c.phi, c.mu, c.fx, c.fy, c.out);
    let mut outside = false;
    for run in patch.runs(l) {
        let len = run.len;
        let f = Neighbourhood::new(phi, patch, run.b, run.a0, len);
        let mobility = &drag.mobility[run.global..][..len];
        let pull = &drag.pull[run.global..][..len];
        let (mu, fx, fy) = (&mu_all[run.padded..][..len], &fx_all[run.padded..][..len], &fy_all[run.padded..][..len]);
        let at = |k: usize| {
            let vx = (fx[k] + pull[k].re) * mobility[k];
            let vy = (fy[k] + pull[k].im) * mobility[k];
            let (gx, gy) = match advection {
                Advection::Central => f.gradient(k),
                Advection::Upwind => (
                    if vx > 0.0 { f.c[k] - f.xm[k] } else { f.xp[k] - f.c[k] },
                    if vy > 0.0 { f.c[k] - f.ym[k] } else { f.yp[k] - f.c[k] },
                ),
            };
            (vx, vy, -(vx * gx + vy * gy) - j0 * mu[k])
        };
        let i = run.padded;
        match &mut out {
            Output::Rate { vx, vy, rate } => {
                let (vx, vy, rate) = (&mut vx[i..][..len], &mut vy[i..][..len], &mut rate[i..][..len]);
                for k in 0..len {
                    (vx[k], vy[k], rate[k]) = at(k);
                }
            }
            Output::Predict { dt, k1, next } => {
                let (dt, k1, next) = (*dt, &mut k1[i..][..len], &mut next[i..][..len]);
                for k in 0..len {
                    let (_, _, r) = at(k);
                    k1[k] = r;
                    next[k] = f.c[k] + dt * r;
                }
            }
            Output::Correct { dt, phi0, k1, vx, vy, next, lo, hi } => {
                let (half, lo, hi) = (0.5 * *dt, *lo, *hi);
                let (p0, k1) = (&phi0[i..][..len], &k1[i..][..len]);
                let (vx, vy, next) = (&mut vx[i..][..len], &mut vy[i..][..len], &mut next[i..][..len]);
                for k in 0..len {
                    let r;
                    (vx[k], vy[k], r) = at(k);
                    let v = p0[k] + half * (k1[k] + r);
                    next[k] = v;
                    outside |= !(v >= lo && v <= hi);
                }
            }
        }
    }
    outside
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
                    out: Output::Rate { vx: &mut vx, vy: &mut vy, rate: &mut rate },
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

    /// Heun's outputs are the rate's: the predictor's and corrector's φ are the plain update
    /// formulas bit for bit, only the interior is written, and an out-of-range φ' is seen.
    #[test]
    fn heun_outputs_follow_the_rate() {
        let patch = Patch { x0: 6, y0: 1, w: 5, h: 4 };
        let (l, n, s) = (8, patch.padded_len(), patch.stride());
        let interior = |i: usize| (1..=patch.w).contains(&(i % s)) && (1..=patch.h).contains(&(i / s));
        let field =
            |k: f64| -> Vec<f64> { (0..n).map(|i| if interior(i) { (k * i as f64).sin() } else { 0.0 }).collect() };
        let (phi, mu, fx, fy, phi0, k1) = (field(0.3), field(0.7), field(1.1), field(1.9), field(2.3), field(2.9));
        let mobility: Vec<f64> = (0..l * l).map(|x| 0.5 + 0.01 * x as f64).collect();
        let pull: Vec<C64> = (0..l * l).map(|x| C64::new((0.2 * x as f64).cos(), (0.5 * x as f64).sin())).collect();
        let drag = Drag { mobility: &mobility, pull: &pull };
        let f = [&phi[..], &mu, &fx, &fy];
        fn run(f: [&[f64]; 4], out: Output, drag: &Drag, patch: Patch, l: usize) -> bool {
            let fields = MotionFields { phi: f[0], mu: f[1], fx: f[2], fy: f[3], out };
            velocity_and_rate(patch, fields, drag, l, 0.3, Advection::Central)
        }
        let (mut vx, mut vy, mut rate) = (vec![0.0; n], vec![0.0; n], vec![0.0; n]);
        assert!(!run(f, Output::Rate { vx: &mut vx, vy: &mut vy, rate: &mut rate }, &drag, patch, l));
        let (mut k, mut next) = (vec![0.0; n], vec![0.0; n]);
        assert!(!run(f, Output::Predict { dt: 0.1, k1: &mut k, next: &mut next }, &drag, patch, l));
        assert_eq!(k, rate);
        for i in 0..n {
            assert_eq!(next[i], if interior(i) { phi[i] + 0.1 * rate[i] } else { 0.0 });
        }
        let (mut cvx, mut cvy) = (vec![0.0; n], vec![0.0; n]);
        for (lo, hi, outside) in [(-0.5, 0.5, true), (-10.0, 10.0, false)] {
            let out =
                Output::Correct { dt: 0.1, phi0: &phi0, k1: &k1, vx: &mut cvx, vy: &mut cvy, next: &mut next, lo, hi };
            assert_eq!(run(f, out, &drag, patch, l), outside);
        }
        assert_eq!((&cvx, &cvy), (&vx, &vy));
        for i in 0..n {
            assert_eq!(next[i], if interior(i) { phi0[i] + 0.05 * (k1[i] + rate[i]) } else { 0.0 });
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

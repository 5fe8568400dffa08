//! The free energy F = F_CH + F_area + F_rep (Supplementary Eqs. S1–S3) and its functional
//! derivative μ_i = δF/δφ_i (docs/reading.md §2):
//!
//!   μ_i = (γ/λ)·8 φ_i(1−φ_i)(1−2φ_i) − 2γλ ∇²φ_i − (4μ/πR²)(1 − A_i/πR²) φ_i
//!         + (c κ/λ) φ_i Σ_{j≠i} φ_j²,
//!
//! with A_i = ∫ φ_i², the area term read as squared, and c = `repulsion_factor` (4 as printed).

use multiversion::multiversion;

use crate::model::lattice::{Neighbourhood, Patch};
use crate::model::params::{Laplacian, Params};
use crate::model::precision::{load, Real};
use crate::model::sum::sum_of;

/// The coefficients of μ_i, derived once from the parameters.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FreeEnergy {
    /// 8γ/λ: bulk double well.
    pub bulk: f64,
    /// 2γλ: gradient term.
    pub gradient: f64,
    /// 4μ/πR²: area constraint.
    pub area: f64,
    /// πR².
    pub target_area: f64,
    /// cκ/λ: repulsion.
    pub repulsion: f64,
    pub laplacian: Laplacian,
}

impl FreeEnergy {
    pub fn new(p: &Params) -> Self {
        FreeEnergy {
            bulk: 8.0 * p.gamma / p.lambda,
            gradient: 2.0 * p.gamma * p.lambda,
            area: 4.0 * p.mu / p.target_area(),
            target_area: p.target_area(),
            repulsion: p.repulsion_factor * p.kappa / p.lambda,
            laplacian: p.laplacian,
        }
    }

    /// μ_i at every site of the patch. `others_phi2(i)` is Σ_j φ_j² on the lattice at the
    /// lattice index of padded site i, all cells included (this cell's own φ_i² is taken out
    /// here); `area` is A_i.
    pub fn chemical_potential<T: Real>(
        &self,
        patch: Patch,
        phi: &[T],
        area: f64,
        sum_phi2: &[f64],
        l: usize,
        mu: &mut [T],
    ) {
        let area_term = self.area * (1.0 - area / self.target_area);
        chemical_potential_on_runs(self, area_term, patch, phi, sum_phi2, l, mu);
    }
}

/// The loop of [`FreeEnergy::chemical_potential`] over the patch's runs, given the cell's area
/// term; a free function so that it can be compiled also for AVX2 (`multiversion`, which takes
/// no methods: the same bits, docs/performance.md).
#[multiversion(targets("x86_64+avx2"))]
fn chemical_potential_on_runs<T: Real>(
    fe: &FreeEnergy,
    area_term: f64,
    patch: Patch,
    phi: &[T],
    sum_phi2: &[f64],
    l: usize,
    mu: &mut [T],
) {
    let (bulk, gradient, repulsion, kind) = (fe.bulk, fe.gradient, fe.repulsion, fe.laplacian);
    for run in patch.runs(l) {
        let len = run.len;
        let f = Neighbourhood::new(phi, patch, run.b, run.a0, len);
        let g = &sum_phi2[run.global..][..len];
        let out = &mut mu[run.padded..][..len];
        for k in 0..len {
            let c = load(f.c[k]);
            let lap = laplacian(kind, &f, k);
            out[k] = T::from_f64(
                bulk * c * (1.0 - c) * (1.0 - 2.0 * c) - gradient * lap - area_term * c
                    + repulsion * c * (g[k] - c * c),
            );
        }
    }
}

/// The discrete Laplacian at site k of a run.
#[inline(always)]
pub fn laplacian<T: Real>(kind: Laplacian, f: &Neighbourhood<T>, k: usize) -> f64 {
    let nn = load(f.xm[k]) + load(f.xp[k]) + load(f.ym[k]) + load(f.yp[k]);
    match kind {
        Laplacian::FivePoint => nn - 4.0 * load(f.c[k]),
        Laplacian::NinePoint => {
            let diag = load(f.xm_ym[k]) + load(f.xp_ym[k]) + load(f.xm_yp[k]) + load(f.xp_yp[k]);
            (4.0 * nn + diag - 20.0 * load(f.c[k])) / 6.0
        }
    }
}

/// A_i = Σ φ_i² over the patch (in the lanes of `sum`).
pub fn area<T: Real>(phi: &[T]) -> f64 {
    sum_of(phi, |v| load(v) * load(v))
}

/// The free energy of one cell alone (F_CH + F_area, no repulsion), with the gradient squared
/// by forward differences: used by tests to check that μ is its derivative.
#[cfg(test)]
fn single_cell_energy(p: &Params, patch: Patch, phi: &[f64]) -> f64 {
    let s = patch.stride();
    let mut ch = 0.0;
    // Sum over the padded patch including the halo, so that every bond is counted.
    for b in 0..patch.h + 1 {
        for a in 0..patch.w + 1 {
            let i = b * s + a;
            let c = phi[i];
            let gx = phi[i + 1] - c;
            let gy = phi[i + s] - c;
            ch += 4.0 * c * c * (1.0 - c) * (1.0 - c) + p.lambda * p.lambda * (gx * gx + gy * gy);
        }
    }
    let a = area(phi) / p.target_area();
    p.gamma / p.lambda * ch + p.mu * (1.0 - a) * (1.0 - a)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// μ must be the derivative of F: compare with finite differences of the energy.
    #[test]
    fn mu_is_the_functional_derivative() {
        let p = Params { radius: 3.0, ..Params::default() };
        let patch = Patch { x0: 0, y0: 0, w: 12, h: 12 };
        let l = 32;
        let mut phi = vec![0.0; patch.padded_len()];
        for b in 0..12 {
            for a in 0..12 {
                let r = ((a as f64 - 5.5).powi(2) + (b as f64 - 5.0).powi(2)).sqrt();
                phi[patch.idx(a, b)] = 1.0 / (1.0 + (r - 3.2).exp()) + 0.01 * ((a * b) as f64).sin();
            }
        }
        let fe = FreeEnergy::new(&p);
        // Σφ² of this cell alone: the repulsion term vanishes.
        let mut sum_phi2 = vec![0.0; l * l];
        for b in 0..12 {
            for a in 0..12 {
                sum_phi2[b * l + a] = phi[patch.idx(a, b)].powi(2);
            }
        }
        let mut mu = vec![0.0; patch.padded_len()];
        fe.chemical_potential(patch, &phi, area(&phi), &sum_phi2, l, &mut mu);
        let h = 1e-6;
        for (a, b) in [(5, 5), (2, 7), (8, 3), (0, 0), (11, 6)] {
            let i = patch.idx(a, b);
            let mut up = phi.clone();
            up[i] += h;
            let mut dn = phi.clone();
            dn[i] -= h;
            let fd = (single_cell_energy(&p, patch, &up) - single_cell_energy(&p, patch, &dn)) / (2.0 * h);
            assert!((fd - mu[i]).abs() < 1e-6 * (1.0 + fd.abs()), "site ({a},{b}): δF/δφ {fd} vs μ {}", mu[i]);
        }
    }

    /// Both stencils are exact for quadratics: ∇²(x² + 3y² + xy) = 8, and a sign or weight error
    /// in either shows up here.
    #[test]
    fn laplacians_are_exact_for_quadratics() {
        let patch = Patch { x0: 0, y0: 0, w: 6, h: 5 };
        let mut f = vec![0.0; patch.padded_len()];
        for b in 0..patch.h + 2 {
            for a in 0..patch.w + 2 {
                let (x, y) = (a as f64, b as f64);
                f[b * patch.stride() + a] = x * x + 3.0 * y * y + x * y;
            }
        }
        for kind in [Laplacian::FivePoint, Laplacian::NinePoint] {
            for b in 0..patch.h {
                let n = crate::model::lattice::row_neighbourhood(&f, patch, b);
                for k in 0..patch.w {
                    assert!((laplacian(kind, &n, k) - 8.0).abs() < 1e-9, "{kind:?} at ({k}, {b})");
                }
            }
        }
    }

    #[test]
    fn repulsion_counts_only_the_other_cells() {
        let p = Params::default();
        let fe = FreeEnergy::new(&p);
        let patch = Patch { x0: 0, y0: 0, w: 3, h: 3 };
        let l = 16;
        let mut phi = vec![0.0_f64; patch.padded_len()];
        let i = patch.idx(1, 1);
        phi[i] = 0.5;
        let mut sum_phi2 = vec![0.0; l * l];
        sum_phi2[l + 1] = 0.25 + 0.36; // itself, and another cell with φ_j = 0.6
        let mut mu_with = vec![0.0; patch.padded_len()];
        fe.chemical_potential(patch, &phi, 0.25, &sum_phi2, l, &mut mu_with);
        sum_phi2[l + 1] = 0.25;
        let mut mu_alone = vec![0.0; patch.padded_len()];
        fe.chemical_potential(patch, &phi, 0.25, &sum_phi2, l, &mut mu_alone);
        // (cκ/λ) φ_i φ_j² = 4·0.5/2 · 0.5 · 0.36
        assert!((mu_with[i] - mu_alone[i] - 0.18).abs() < 1e-12);
    }
}

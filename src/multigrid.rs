//! Aggregation multigrid: the preconditioner of the friction solve (`friction`).
//!
//! The friction operator C is a weighted graph Laplacian on the lattice (bond weights
//! ξ_c n(x) n(x′) between 8-neighbours, a mass ξ_s(x) n(x) per site). Where n varies by a
//! factor 2–3 across the tissue, as it does when every present cell counts in the friction sum,
//! no diagonal scaling of a constant-coefficient (FFT) inverse maps both the local stiffness and
//! the soft rigid-translation mode right, and CG needed 70 iterations per solve at χ = 0.001.
//! Multigrid sees n at every scale: each level aggregates 2×2 sites of the one below
//! (periodic; an odd side leaves a one-site-wide last block), its operator is the Galerkin
//! product Pᵀ A P with P piecewise constant — so a uniform translation is represented exactly on
//! every level and holes stay holes — and the coarsest level (side ≤ 6) is solved by Cholesky.
//! One symmetric V-cycle with damped Jacobi smoothing is a symmetric positive definite
//! preconditioner for CG.

use num_complex::Complex64 as C64;

use crate::par;

const ZERO: C64 = C64 { re: 0.0, im: 0.0 };

/// The 8 neighbour offsets, in the order of [`Level::off`].
const DIRS: [(isize, isize); 8] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)];

/// Coarsening stops at this side; the level is then solved exactly.
const COARSEST_SIDE: usize = 6;

/// Factor on every coarse correction. Piecewise-constant interpolation stores too much energy
/// in the coarse vectors, so a plain correction falls short; over-correcting makes up for it
/// (Vaněk's classic remedy for unsmoothed aggregation). Any value in (0, 2) keeps the cycle
/// symmetric positive definite. Measured at full size, iterations per solve at χ = 0.1 and
/// χ = 0.001: 1.0 → 7.1 and 18.7; 1.4 → 6.7 and 11.6; 1.5 → 7.3 and 10.7; 1.8 → 9.2 and 10.2.
const OVER_CORRECTION: f64 = 1.5;

/// Levels at least this wide split their stencil products across threads.
const PARALLEL_SIDE: usize = 64;

/// `Level::coarse_dir` value for a bond inside one aggregate.
const SAME: u8 = 8;

/// Damped Jacobi weight: the operators are weakly diagonally dominant M-matrices on every
/// level (Galerkin aggregation keeps that), so D⁻¹A has its spectrum in [0, 2) and 2/3 keeps the
/// smoother convergent while damping the highest modes.
const OMEGA: f64 = 2.0 / 3.0;

/// Smoothing sweeps before and after each coarse correction (equal, so the cycle is symmetric).
/// Measured at full size with presence weights: 1 sweep takes 18.7 CG iterations per solve at
/// χ = 0.001 and 25 ms per step, 2 sweeps 15.5 iterations but 31 ms.
const SWEEPS: usize = 1;

fn dir_index(dx: isize, dy: isize) -> usize {
    DIRS.iter().position(|&d| d == (dx, dy)).expect("a neighbour direction")
}

/// One level: a 9-point stencil with variable coefficients on an m×m periodic grid.
#[derive(Clone, Debug, Default)]
struct Level {
    m: usize,
    diag: Vec<f64>,
    /// Coefficient of the neighbour in direction `DIRS[k]`, per site.
    off: Vec<[f64; 8]>,
    /// Index of the neighbour in direction `DIRS[k]`, per site (periodic).
    nb: Vec<[u32; 8]>,
    /// The aggregate (site of the next coarser level) each site belongs to.
    agg: Vec<u32>,
    /// Per site and direction: where the bond lands on the coarser level, the index into
    /// `DIRS` of the neighbouring aggregate, or `SAME` when both ends share an aggregate.
    coarse_dir: Vec<[u8; 8]>,
    /// Sites that take part (n > 0 on the finest level; any such site below, on coarser ones).
    active: Vec<bool>,
    /// Solution, right-hand side and work space of this level during a cycle.
    x: Vec<C64>,
    b: Vec<C64>,
    t: Vec<C64>,
}

impl Level {
    fn with_side(m: usize) -> Self {
        let n = m * m;
        let nb: Vec<[u32; 8]> = (0..n)
            .map(|x| {
                let (i, j) = ((x % m) as isize, (x / m) as isize);
                DIRS.map(|(dx, dy)| {
                    let (ni, nj) = ((i + dx).rem_euclid(m as isize), (j + dy).rem_euclid(m as isize));
                    (nj as usize * m + ni as usize) as u32
                })
            })
            .collect();
        let mc = m.div_ceil(2);
        let agg = (0..n).map(|x| ((x / m / 2) * mc + (x % m) / 2) as u32).collect();
        let coarse_dir = (0..n)
            .map(|x| {
                let (i, j) = (x % m, x / m);
                std::array::from_fn(|k| {
                    let (dx, dy) = DIRS[k];
                    let y = nb[x][k] as usize;
                    // Adjacent sites fall in the same aggregate or in the next one their way.
                    let cdx = if (y % m) / 2 == i / 2 { 0 } else { dx.signum() };
                    let cdy = if (y / m) / 2 == j / 2 { 0 } else { dy.signum() };
                    if (cdx, cdy) == (0, 0) {
                        SAME
                    } else {
                        dir_index(cdx, cdy) as u8
                    }
                })
            })
            .collect();
        Level {
            m,
            nb,
            agg,
            coarse_dir,
            diag: vec![0.0; n],
            off: vec![[0.0; 8]; n],
            active: vec![false; n],
            x: vec![ZERO; n],
            b: vec![ZERO; n],
            t: vec![ZERO; n],
        }
    }

    fn neighbour(&self, x: usize, k: usize) -> usize {
        self.nb[x][k] as usize
    }

    /// out = A v. Each site's output is its own, so the rows split across threads without
    /// changing a bit; only the large levels are worth splitting.
    fn apply(&self, v: &[C64], out: &mut [C64]) {
        let site = |x: usize| {
            let (a, nb) = (&self.off[x], &self.nb[x]);
            let mut s = v[x] * self.diag[x];
            for k in 0..8 {
                s += v[nb[k] as usize] * a[k];
            }
            s
        };
        if self.m < PARALLEL_SIDE {
            for (x, o) in out.iter_mut().enumerate() {
                *o = site(x);
            }
            return;
        }
        let chunk = self.m * par::band_rows(self.m);
        par::for_each_chunk_mut(out, chunk, |k, band| {
            for (i, o) in band.iter_mut().enumerate() {
                *o = site(k * chunk + i);
            }
        });
    }

    /// One damped Jacobi sweep on A x = b (x starting from zero when `from_zero`).
    fn smooth(&mut self, from_zero: bool) {
        if from_zero {
            for ((x, b), (d, a)) in self.x.iter_mut().zip(&self.b).zip(self.diag.iter().zip(&self.active)) {
                *x = if *a { b * (OMEGA / d) } else { ZERO };
            }
            return;
        }
        let mut t = std::mem::take(&mut self.t);
        self.apply(&self.x, &mut t);
        for (((x, b), t), (d, a)) in self.x.iter_mut().zip(&self.b).zip(&t).zip(self.diag.iter().zip(&self.active)) {
            if *a {
                *x += (b - t) * (OMEGA / d);
            }
        }
        self.t = t;
    }

    /// The Galerkin coarse level Pᵀ A P, P constant on 2×2 aggregates of active sites.
    fn coarsen(&self, coarse: &mut Level) {
        coarse.diag.fill(0.0);
        coarse.off.fill([0.0; 8]);
        coarse.active.fill(false);
        for x in 0..self.m * self.m {
            if !self.active[x] {
                continue;
            }
            let c = self.agg[x] as usize;
            coarse.active[c] = true;
            coarse.diag[c] += self.diag[x];
            for (a, t) in self.off[x].iter().zip(&self.coarse_dir[x]) {
                if *t == SAME {
                    coarse.diag[c] += a;
                } else {
                    coarse.off[c][*t as usize] += a;
                }
            }
        }
        for (d, a) in coarse.diag.iter_mut().zip(&coarse.active) {
            if !*a {
                *d = 1.0;
            }
        }
    }

    /// coarse.b = Pᵀ (b − A x): the residual summed over each aggregate.
    fn restrict_residual(&mut self, coarse: &mut Level) {
        let mut t = std::mem::take(&mut self.t);
        self.apply(&self.x, &mut t);
        coarse.b.fill(ZERO);
        for (x, a) in self.active.iter().enumerate() {
            if *a {
                coarse.b[self.agg[x] as usize] += self.b[x] - t[x];
            }
        }
        self.t = t;
    }

    /// x += P coarse.x.
    fn prolong(&mut self, coarse: &Level) {
        for ((x, a), c) in self.x.iter_mut().zip(&self.active).zip(&self.agg) {
            if *a {
                *x += coarse.x[*c as usize] * OVER_CORRECTION;
            }
        }
    }
}

/// Dense Cholesky factor of the coarsest level (row-major lower triangle).
#[derive(Clone, Debug, Default)]
struct Coarsest {
    n: usize,
    l: Vec<f64>,
}

impl Coarsest {
    fn factor(&mut self, level: &Level) {
        let n = level.m * level.m;
        self.n = n;
        self.l.clear();
        self.l.resize(n * n, 0.0);
        let a = &mut self.l;
        for x in 0..n {
            a[x * n + x] += level.diag[x];
            for (k, c) in level.off[x].iter().enumerate() {
                a[x * n + level.neighbour(x, k)] += c;
            }
        }
        for c in 0..n {
            let mut d = a[c * n + c];
            for k in 0..c {
                d -= a[c * n + k] * a[c * n + k];
            }
            // The level is positive definite (ξ_s > 0 on active sites; identity elsewhere).
            let d = d.max(f64::MIN_POSITIVE).sqrt();
            a[c * n + c] = d;
            for r in c + 1..n {
                let mut s = a[r * n + c];
                for k in 0..c {
                    s -= a[r * n + k] * a[c * n + k];
                }
                a[r * n + c] = s / d;
            }
        }
    }

    fn solve(&self, level: &mut Level) {
        let (n, l) = (self.n, &self.l);
        let x = &mut level.x;
        x.copy_from_slice(&level.b);
        for r in 0..n {
            let mut s = x[r];
            for k in 0..r {
                s -= x[k] * l[r * n + k];
            }
            x[r] = s / l[r * n + r];
        }
        for r in (0..n).rev() {
            let mut s = x[r];
            for k in r + 1..n {
                s -= x[k] * l[k * n + r];
            }
            x[r] = s / l[r * n + r];
        }
    }
}

/// The level hierarchy, rebuilt for every solve (n changes every evaluation).
#[derive(Clone, Debug, Default)]
pub struct Multigrid {
    levels: Vec<Level>,
    coarsest: Coarsest,
}

impl Multigrid {
    pub fn new(l: usize) -> Self {
        let mut levels = vec![Level::with_side(l)];
        let mut m = l;
        while m > COARSEST_SIDE {
            m = m.div_ceil(2);
            levels.push(Level::with_side(m));
        }
        Multigrid { levels, coarsest: Coarsest::default() }
    }

    /// Sets up the hierarchy for C with bond weights ξ_c n(x) n(x′) and diagonal `diag`
    /// (zero where n = 0, the sites outside the solve).
    pub fn setup(&mut self, n: &[f64], diag: &[f64], xi_c: f64) {
        let fine = &mut self.levels[0];
        for x in 0..fine.m * fine.m {
            let active = diag[x] > 0.0;
            fine.active[x] = active;
            fine.diag[x] = if active { diag[x] } else { 1.0 };
            let nb = &fine.nb[x];
            fine.off[x] = if active { std::array::from_fn(|k| -xi_c * n[x] * n[nb[k] as usize]) } else { [0.0; 8] };
        }
        for k in 1..self.levels.len() {
            let (fine, coarse) = self.levels.split_at_mut(k);
            fine[k - 1].coarsen(&mut coarse[0]);
        }
        self.coarsest.factor(self.levels.last().expect("at least one level"));
    }

    /// z = M r: one symmetric V-cycle from zero.
    pub fn precondition(&mut self, r: &[C64], z: &mut [C64]) {
        self.levels[0].b.copy_from_slice(r);
        let last = self.levels.len() - 1;
        for k in 0..last {
            let (fine, coarse) = self.levels.split_at_mut(k + 1);
            let level = &mut fine[k];
            for s in 0..SWEEPS {
                level.smooth(s == 0);
            }
            level.restrict_residual(&mut coarse[0]);
        }
        self.coarsest.solve(&mut self.levels[last]);
        for k in (0..last).rev() {
            let (fine, coarse) = self.levels.split_at_mut(k + 1);
            let level = &mut fine[k];
            level.prolong(&coarse[0]);
            for _ in 0..SWEEPS {
                level.smooth(false);
            }
        }
        z.copy_from_slice(&self.levels[0].x);
    }
}

/// Test fixtures shared with the friction solve's tests.
#[cfg(test)]
pub(crate) mod fixtures {
    /// Presence-like weights: 1 inside cells, 2–3 along a network of edges, 0 in a hole.
    pub(crate) fn edge_network(l: usize) -> Vec<f64> {
        (0..l * l)
            .map(|x| {
                let (i, j) = (x % l, x / l);
                let d2 = (i as f64 - 9.0).powi(2) + (j as f64 - 11.0).powi(2);
                if d2 < 20.0 {
                    0.0
                } else {
                    1.0 + (i % 7 < 2) as u8 as f64 + (j % 9 < 3) as u8 as f64
                }
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::fixtures::edge_network;
    use super::*;

    fn fine_diag(n: &[f64], l: usize, xi_s: f64, xi_c: f64) -> Vec<f64> {
        let level = Level::with_side(l);
        (0..l * l)
            .map(|x| {
                let nn: f64 = level.nb[x].iter().map(|&y| n[y as usize]).sum();
                if n[x] > 0.0 {
                    n[x] * (xi_s + xi_c * nn)
                } else {
                    0.0
                }
            })
            .collect()
    }

    fn field(l: usize, seed: u64) -> Vec<C64> {
        // A small deterministic pseudo-random field (an LCG is enough for a test vector).
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let mut next = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..l * l).map(|_| C64::new(next(), next())).collect()
    }

    fn setup(l: usize) -> (Multigrid, Vec<f64>) {
        let n = edge_network(l);
        let diag = fine_diag(&n, l, 0.001, 1.0);
        let mut mg = Multigrid::new(l);
        mg.setup(&n, &diag, 1.0);
        (mg, n)
    }

    fn dot(a: &[C64], b: &[C64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x.re * y.re + x.im * y.im).sum()
    }

    #[test]
    fn levels_halve_down_to_the_coarsest_side() {
        let sides: Vec<usize> = Multigrid::new(140).levels.iter().map(|l| l.m).collect();
        assert_eq!(sides, [140, 70, 35, 18, 9, 5]);
        let sides: Vec<usize> = Multigrid::new(80).levels.iter().map(|l| l.m).collect();
        assert_eq!(sides, [80, 40, 20, 10, 5]);
    }

    /// The coarse operator is Pᵀ A P: applied to any coarse vector it equals restricting A
    /// applied to the vector's piecewise-constant interpolation, across periodic edges and odd
    /// sides. A uniform vector (a rigid translation) gets Pᵀ(ξ_s n): friction with the substrate
    /// only, on every level.
    #[test]
    fn coarse_levels_are_galerkin_products() {
        let l = 35; // odd: the last aggregate in each direction is one site wide
        let (mg, _) = setup(l);
        let (fine, coarse) = (&mg.levels[0], &mg.levels[1]);
        let vc = field(coarse.m, 3);
        let mut vf = vec![ZERO; l * l];
        for x in 0..l * l {
            if fine.active[x] {
                vf[x] = vc[fine.agg[x] as usize];
            }
        }
        let mut af = vec![ZERO; l * l];
        fine.apply(&vf, &mut af);
        let mut expected = vec![ZERO; coarse.m * coarse.m];
        for x in 0..l * l {
            if fine.active[x] {
                expected[fine.agg[x] as usize] += af[x];
            }
        }
        let mut got = vec![ZERO; coarse.m * coarse.m];
        coarse.apply(&vc, &mut got);
        for c in 0..coarse.m * coarse.m {
            if coarse.active[c] {
                assert!((got[c] - expected[c]).norm() < 1e-12, "aggregate {c}: {} vs {}", got[c], expected[c]);
            }
        }
    }

    /// CG needs a symmetric positive definite preconditioner: ⟨M a, b⟩ = ⟨a, M b⟩ and ⟨M a, a⟩ > 0.
    #[test]
    fn v_cycle_is_symmetric_positive_definite() {
        let l = 40;
        let (mut mg, n) = setup(l);
        let mask =
            |v: Vec<C64>| -> Vec<C64> { v.into_iter().zip(&n).map(|(z, n)| if *n > 0.0 { z } else { ZERO }).collect() };
        let (a, b) = (mask(field(l, 1)), mask(field(l, 2)));
        let (mut ma, mut mb) = (vec![ZERO; l * l], vec![ZERO; l * l]);
        mg.precondition(&a, &mut ma);
        mg.precondition(&b, &mut mb);
        let (ab, ba) = (dot(&ma, &b), dot(&a, &mb));
        assert!((ab - ba).abs() < 1e-10 * ab.abs().max(1.0), "⟨Ma, b⟩ = {ab}, ⟨a, Mb⟩ = {ba}");
        assert!(dot(&ma, &a) > 0.0 && dot(&mb, &b) > 0.0);
    }

    /// The rigid translation is the soft mode at low friction (C·1 = ξ_s n): one V-cycle maps
    /// its residual back to a uniform field, so it is (nearly) an eigenvector of the
    /// preconditioned operator, which the diagonally scaled FFT inverse could not manage where
    /// n ≠ 1. (The over-correction scales it, uniformly: CG does not mind a scale.)
    #[test]
    fn v_cycle_maps_a_rigid_translation_to_a_uniform_field() {
        let l = 40;
        let (mut mg, n) = setup(l);
        let r: Vec<C64> = n.iter().map(|n| C64::new(0.001 * n, 0.0)).collect();
        let mut z = vec![ZERO; l * l];
        mg.precondition(&r, &mut z);
        let active: Vec<f64> = z.iter().zip(&n).filter(|(_, n)| **n > 0.0).map(|(z, _)| z.re).collect();
        let mean = active.iter().sum::<f64>() / active.len() as f64;
        let spread = active.iter().map(|v| (v - mean).abs()).fold(0.0, f64::max);
        assert!(mean > 0.5, "mean {mean}");
        assert!(spread < 0.05 * mean, "spread {spread} about the mean {mean}");
        assert!(z.iter().all(|z| z.im.abs() < 1e-12));
    }
}

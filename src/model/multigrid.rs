//! Aggregation multigrid: the preconditioner of the friction solve (`friction`).
//!
//! The friction operator C is a weighted graph Laplacian on the lattice (bond weights
//! ξ_c n(x) n(x′) between 8-neighbours, a mass ξ_s(x) n(x) per site). Where n varies by a
//! factor 2–3 across the tissue, as it does when every present cell counts in the friction sum,
//! no diagonal scaling of a constant-coefficient (FFT) inverse maps both the local stiffness and
//! the soft rigid-translation mode right, and CG needed 70 iterations per solve at χ = 0.001.
//! (docs/performance.md has the history.) Multigrid sees n at every scale: each level aggregates 2×2 sites of the one below
//! (periodic; an odd side leaves a one-site-wide last block), its operator is the Galerkin
//! product Pᵀ A P with P piecewise constant — so a uniform translation is represented exactly on
//! every level and holes stay holes — and the coarsest level (side ≤ 6) is solved by Cholesky.
//! One symmetric W-cycle with damped Jacobi smoothing is a symmetric positive definite
//! preconditioner for CG.
//!
//! Layout, for speed: every level is a 9-point stencil stored as its diagonal and the four
//! "forward" bonds of each site (`FORWARD`); the other four are the neighbours' forward bonds
//! (A is symmetric), so a product streams through rows with no index tables, one array per
//! coefficient so that the loops run in SIMD lanes. Sites outside the solve (n = 0) have a zero
//! diagonal and zero bonds: the finest level *is* C, which CG applies through
//! [`Multigrid::apply`].
//!
//! Precision: the hierarchy is built in f64 (the Galerkin sums cancel down to the small mass
//! ξ_s n), then stored in [`Real`] = f32 for the cycle, which is only a preconditioner: CG's own
//! product and vectors stay f64, so the solution meets the stated residual all the same. f32
//! halves the memory the cycle streams and doubles its SIMD lanes.
//!
//! Threads: the hierarchy is built whenever n changes, on one thread (split into row bands it
//! took longer, see `par`), beside the per-cell force stage that the other threads run
//! (`monolayer`); it is then read-only, and the cycles of the two velocity components run side
//! by side, each with its own [`CycleWork`].

use std::ops::{Add, Mul, Sub};

use crate::model::sum::sum_pairs;

/// The precision of the multigrid cycle (see the module's notes).
pub type Real = f32;

/// The bonds stored per site, (dx, dy) with y the row: east, north-west, north, north-east.
/// Index k here is entry k + 1 of a [`Stencil`].
const FORWARD: [(isize, isize); 4] = [(1, 0), (-1, 1), (0, 1), (1, 1)];

/// A site's diagonal coefficient, then its bonds to x + FORWARD[k].
type Stencil = [f64; 5];
const DIAG: usize = 0;
const EAST: usize = 1;
const NORTH_WEST: usize = 2;
const NORTH: usize = 3;
const NORTH_EAST: usize = 4;

/// The eight neighbour directions, and (0, 0) last: the order of [`direction`] and
/// `ALL_AS_FORWARD` (which the tests check against it).
#[cfg(test)]
const ALL: [(isize, isize); 9] = [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1), (0, 0)];

/// Where the bond in direction `ALL[d]` is stored: the stencil entry, and whether it is the
/// neighbour's (the direction is the opposite of a forward one). (0, 0) maps to the diagonal.
const ALL_AS_FORWARD: [(usize, bool); 9] = [
    (NORTH_EAST, true),
    (NORTH, true),
    (NORTH_WEST, true),
    (EAST, true),
    (EAST, false),
    (NORTH_WEST, false),
    (NORTH, false),
    (NORTH_EAST, false),
    (DIAG, false),
];

/// The index into `ALL` of (dx, dy), each in {−1, 0, 1}.
const fn direction(dx: isize, dy: isize) -> usize {
    match (dx, dy) {
        (0, 0) => 8,
        _ => {
            let d = (dy + 1) * 3 + dx + 1;
            (if d > 4 { d - 1 } else { d }) as usize
        }
    }
}

/// i + d on a periodic side m, d in {−1, 0, 1}.
#[inline]
fn step(i: usize, d: isize, m: usize) -> usize {
    match d {
        -1 => prev(i, m),
        1 => next(i, m),
        _ => i,
    }
}

/// Coarsening stops at this side; the level is then solved exactly.
pub const COARSEST_SIDE: usize = 6;

/// Factor on every coarse correction. Piecewise-constant interpolation stores too much energy
/// in the coarse vectors, so a plain correction falls short; over-correcting makes up for it
/// (Vaněk's classic remedy for unsmoothed aggregation). Any value in (0, 2) keeps the cycle
/// symmetric positive definite; 1.5 is the measured optimum with a margin
/// (docs/performance.md, "Multigrid: what was measured").
pub const OVER_CORRECTION: f64 = 1.5;

/// Coarse corrections per visit of every level but the finest: 1 is a V-cycle, 2 a W-cycle.
/// Unsmoothed aggregation loses accuracy level by level; visiting the coarse levels twice makes
/// up for it at little cost, since they hold a third of the sites (the cycles compared are in
/// docs/performance.md).
pub const COARSE_CORRECTIONS: usize = 2;

/// Damped Jacobi weight: the operators are weakly diagonally dominant M-matrices on every
/// level (Galerkin aggregation keeps that), so D⁻¹A has its spectrum in [0, 2) and 2/3 keeps the
/// smoother convergent while damping the highest modes. One sweep before and one after each
/// coarse correction, equal so that the cycle is symmetric (a second sweep saves iterations but
/// costs more time than it saves: docs/performance.md).
pub const OMEGA: f64 = 2.0 / 3.0;

#[inline]
fn prev(i: usize, m: usize) -> usize {
    if i == 0 {
        m - 1
    } else {
        i - 1
    }
}

#[inline]
fn next(i: usize, m: usize) -> usize {
    if i + 1 == m {
        0
    } else {
        i + 1
    }
}

/// Row r of an m×m field.
#[inline]
fn row_of<T>(a: &[T], r: usize, m: usize) -> &[T] {
    &a[r * m..][..m]
}

/// Row j of C v in C's own form, diag·v − ξ_c n Σ_{N8} n v, in either precision. The
/// 8-neighbour sum is the column sums of n v over three rows, summed across three columns,
/// less the centre; `column` is work space of one row.
#[allow(clippy::too_many_arguments)]
#[inline]
fn weights_row<T>(n: &[T], diag: &[T], xi_c: T, v: &[T], m: usize, j: usize, out: &mut [T], column: &mut [T])
where
    T: Copy + Add<Output = T> + Sub<Output = T> + Mul<Output = T>,
{
    let (jm, jp) = (prev(j, m), next(j, m));
    let (vm, v0, vp) = (row_of(v, jm, m), row_of(v, j, m), row_of(v, jp, m));
    let (nm, n0, np) = (row_of(n, jm, m), row_of(n, j, m), row_of(n, jp, m));
    let d = row_of(diag, j, m);
    let (out, column) = (&mut out[..m], &mut column[..m]);
    // out: above and below; column: above, centre and below.
    for i in 0..m {
        out[i] = nm[i] * vm[i] + np[i] * vp[i];
        column[i] = out[i] + n0[i] * v0[i];
    }
    let site = |o: T, i: usize, left: T, right: T| d[i] * v0[i] - xi_c * n0[i] * (o + (left + right));
    out[0] = site(out[0], 0, column[m - 1], column[1]);
    for i in 1..m - 1 {
        out[i] = site(out[i], i, column[i - 1], column[i + 1]);
    }
    out[m - 1] = site(out[m - 1], m - 1, column[m - 2], column[0]);
}

/// One level: the operator on an m×m periodic grid.
#[derive(Clone, Debug, Default)]
struct Level {
    m: usize,
    /// Per site: the diagonal, then the bonds to x + FORWARD[k]. Built here by the setup;
    /// empty on the finest level, which keeps C's own form (`weights`).
    stencil: Vec<Stencil>,
    /// The same in the cycle's precision, one array per coefficient (what the products read).
    coefficients: [Vec<Real>; 5],
    /// ω/diagonal on sites in the solve, 0 elsewhere: the damped Jacobi step, which also keeps
    /// the sites outside at zero.
    jacobi: Vec<Real>,
    /// OVER_CORRECTION on the sites in the solve, 0 elsewhere: P's weights, over-corrected.
    prolongation: Vec<Real>,
    /// On the finest level, the operator's own form instead of its bonds: the bond between x
    /// and x′ is −ξ_c n(x) n(x′), so a product reads n once instead of four bond arrays.
    weights: Option<Weights>,
}

/// C itself: its diagonal, and its bonds as weights, −ξ_c n(x) n(x′) between 8-neighbours.
#[derive(Clone, Debug, Default)]
struct Weights {
    /// n on the sites in the solve, 0 elsewhere.
    n: Vec<f64>,
    /// n (ξ_s + ξ_c N), 0 where n = 0 (the sites outside the solve).
    diag: Vec<f64>,
    xi_c: f64,
    /// n in the cycle's precision.
    n_real: Vec<Real>,
}

/// Solution, right-hand side and residual of one level during a cycle (the finest level's
/// solution and right-hand side are the caller's).
#[derive(Clone, Debug, Default)]
struct Work {
    x: Vec<Real>,
    b: Vec<Real>,
    t: Vec<Real>,
    /// One row of work space for the products.
    column: Vec<Real>,
}

/// The work space of one cycle at a time: one per velocity component, so that the two can run
/// on two threads over the same hierarchy.
#[derive(Clone, Debug, Default)]
pub struct CycleWork {
    levels: Vec<Work>,
    /// The finest level's right-hand side and solution in the cycle's precision.
    r: Vec<Real>,
    z: Vec<Real>,
    /// The coarsest level's solve, in f64.
    coarsest: Vec<f64>,
}

impl CycleWork {
    /// Where the caller puts r, in the cycle's precision, for [`Multigrid::precondition`]
    /// (CG writes it in the pass that updates r, so that r is not read once more to convert it).
    pub fn residual_mut(&mut self) -> &mut [Real] {
        &mut self.r
    }

    /// z = M r of the last [`Multigrid::precondition`].
    pub fn preconditioned(&self) -> &[Real] {
        &self.z
    }
}

impl Level {
    fn with_side(m: usize) -> Self {
        let n = m * m;
        Level {
            m,
            stencil: vec![[0.0; 5]; n],
            coefficients: std::array::from_fn(|_| vec![0.0; n]),
            jacobi: vec![0.0; n],
            prolongation: vec![0.0; n],
            weights: None,
        }
    }

    fn coarse_side(&self) -> usize {
        self.m.div_ceil(2)
    }

    #[cfg(test)]
    /// The aggregate (site of the next coarser level) that site x belongs to.
    fn aggregate(&self, x: usize) -> usize {
        (x / self.m / 2) * self.coarse_side() + (x % self.m) / 2
    }

    #[cfg(test)]
    fn in_solve(&self, x: usize) -> bool {
        self.diagonal(x) > 0.0
    }

    /// The diagonal coefficient of site x, in whichever form the level keeps.
    #[inline]
    fn diagonal(&self, x: usize) -> f64 {
        match &self.weights {
            Some(w) => w.diag[x],
            None => self.stencil[x][DIAG],
        }
    }

    /// A v in f64 from the stencil as built (the reference for the tests).
    #[cfg(test)]
    fn apply_exact(&self, v: &[f64]) -> Vec<f64> {
        let m = self.m;
        if let Some(w) = &self.weights {
            let (mut out, mut column) = (vec![0.0; m * m], vec![0.0; m]);
            for (j, row) in out.chunks_mut(m).enumerate() {
                weights_row(&w.n, &w.diag, w.xi_c, v, m, j, row, &mut column);
            }
            return out;
        }
        let mut out: Vec<f64> = (0..m * m).map(|x| self.stencil[x][DIAG] * v[x]).collect();
        for x in 0..m * m {
            let (i, j) = (x % m, x / m);
            for (k, &(dx, dy)) in FORWARD.iter().enumerate() {
                let y = step(j, dy, m) * m + step(i, dx, m);
                let b = self.stencil[x][1 + k];
                out[x] += b * v[y];
                out[y] += b * v[x];
            }
        }
        out
    }

    /// Row j of A v, in three passes over the row: the bonds within the column, those to the
    /// column on the right, those to the column on the left. Each pass is a straight loop over
    /// independent sites, so it runs in SIMD lanes; the wrapped end site of each shifted pass is
    /// added on its own.
    #[inline]
    fn stencil_row(&self, v: &[Real], j: usize, out: &mut [Real]) {
        let m = self.m;
        let (jm, jp) = (prev(j, m), next(j, m));
        let (vm, v0, vp) = (row_of(v, jm, m), row_of(v, j, m), row_of(v, jp, m));
        let [d, e, nw, n, ne] = self.coefficients.each_ref().map(|c| row_of(c, j, m));
        let [_, _, nw_s, n_s, ne_s] = self.coefficients.each_ref().map(|c| row_of(c, jm, m));
        let out = &mut out[..m];
        // Centre, north and south (the north bond of the site below).
        for i in 0..m {
            out[i] = d[i] * v0[i] + (n[i] * vp[i] + n_s[i] * vm[i]);
        }
        // Right-hand column: east, north-east, and south-east (the north-west bond of the site
        // to the south-east).
        for i in 0..m - 1 {
            out[i] += e[i] * v0[i + 1] + (ne[i] * vp[i + 1] + nw_s[i + 1] * vm[i + 1]);
        }
        out[m - 1] += e[m - 1] * v0[0] + (ne[m - 1] * vp[0] + nw_s[0] * vm[0]);
        // Left-hand column: north-west, west (the east bond of the site to the west) and
        // south-west (the north-east bond of the site to the south-west).
        for i in 1..m {
            out[i] += nw[i] * vp[i - 1] + (e[i - 1] * v0[i - 1] + ne_s[i - 1] * vm[i - 1]);
        }
        out[0] += nw[0] * vp[m - 1] + (e[m - 1] * v0[m - 1] + ne_s[m - 1] * vm[m - 1]);
    }

    /// Row j of A v, in the level's own form; `column` is work space of one row.
    #[inline]
    fn product_row(&self, v: &[Real], j: usize, out: &mut [Real], column: &mut [Real]) {
        match &self.weights {
            Some(w) => {
                let (diag, xi_c) = (&self.coefficients[DIAG], w.xi_c as Real);
                weights_row(&w.n_real, diag, xi_c, v, self.m, j, out, column)
            }
            None => self.stencil_row(v, j, out),
        }
    }

    /// out = A v.
    #[cfg(test)]
    fn apply(&self, v: &[Real], out: &mut [Real]) {
        let mut column = vec![0.0; self.m];
        for (j, row) in out.chunks_mut(self.m).enumerate() {
            self.product_row(v, j, row, &mut column);
        }
    }

    /// t = b − A x.
    fn residual(&self, x: &[Real], b: &[Real], t: &mut [Real], column: &mut [Real]) {
        let m = self.m;
        for (j, row) in t.chunks_mut(m).enumerate() {
            self.product_row(x, j, row, column);
            for (t, b) in row.iter_mut().zip(row_of(b, j, m)) {
                *t = b - *t;
            }
        }
    }

    /// coarse_b = Pᵀ (b − A x): the residual summed over each aggregate, a pair of rows at a
    /// time (the residual itself is not kept); `scratch` holds at least two rows.
    fn restrict_residual(&self, x: &[Real], b: &[Real], coarse_b: &mut [Real], scratch: &mut [Real]) {
        let (m, mc) = (self.m, self.coarse_side());
        let (t, column) = scratch[..2 * m].split_at_mut(m);
        for (jc, coarse_row) in coarse_b.chunks_mut(mc).enumerate() {
            coarse_row.fill(0.0);
            for j in (2 * jc..2 * jc + 2).filter(|&j| j < m) {
                self.product_row(x, j, t, column);
                let b = row_of(b, j, m);
                let (pairs, odd) = t.split_at(m & !1);
                for ((c, t), b) in coarse_row.iter_mut().zip(pairs.chunks_exact(2)).zip(b.chunks_exact(2)) {
                    *c += (b[0] - t[0]) + (b[1] - t[1]);
                }
                if let Some(t) = odd.first() {
                    coarse_row[mc - 1] += b[m - 1] - t;
                }
            }
        }
    }

    /// x = ω D⁻¹ b: one damped Jacobi sweep from zero.
    fn smooth_from_zero(&self, x: &mut [Real], b: &[Real]) {
        for ((x, b), w) in x.iter_mut().zip(b).zip(&self.jacobi) {
            *x = b * w;
        }
    }

    /// x += ω D⁻¹ (b − A x), with t as work space.
    fn smooth(&self, x: &mut [Real], b: &[Real], t: &mut [Real], column: &mut [Real]) {
        self.residual(x, b, t, column);
        for ((x, t), w) in x.iter_mut().zip(&*t).zip(&self.jacobi) {
            *x += t * w;
        }
    }

    /// x += P coarse_x on the sites in the solve, over-corrected.
    fn prolong(&self, coarse_x: &[Real], x: &mut [Real]) {
        let (m, mc) = (self.m, self.coarse_side());
        for (j, row) in x.chunks_mut(m).enumerate() {
            let coarse_row = row_of(coarse_x, j / 2, mc);
            let w = row_of(&self.prolongation, j, m);
            // Whole pairs as fixed-size chunks (so the loop is straight-line code), then the
            // odd side's one-site-wide last aggregate.
            let (pairs, odd) = row.split_at_mut(m & !1);
            for ((pair, w), c) in pairs.chunks_exact_mut(2).zip(w.chunks_exact(2)).zip(coarse_row) {
                pair[0] += c * w[0];
                pair[1] += c * w[1];
            }
            if let Some(x) = odd.first_mut() {
                *x += coarse_row[mc - 1] * w[m - 1];
            }
        }
    }

    /// The bond from site (i, j) to its neighbour in direction `FORWARD[k]`.
    #[inline]
    fn forward_bond(&self, i: usize, j: usize, k: usize) -> f64 {
        match &self.weights {
            Some(w) => {
                let (m, (dx, dy)) = (self.m, FORWARD[k]);
                -w.xi_c * w.n[j * m + i] * w.n[step(j, dy, m) * m + step(i, dx, m)]
            }
            None => self.stencil[j * self.m + i][1 + k],
        }
    }

    /// Row j's diagonal coefficients, and its bonds to x + FORWARD[k] as `bonds[k]`: the values
    /// of [`Self::diagonal`] and [`Self::forward_bond`], a row at a time.
    fn bond_rows(&self, j: usize, diag: &mut [f64], bonds: &mut [Vec<f64>; 4]) {
        let m = self.m;
        match &self.weights {
            Some(w) => {
                diag.copy_from_slice(row_of(&w.diag, j, m));
                let (here, above) = (row_of(&w.n, j, m), row_of(&w.n, next(j, m), m));
                // Each bond as forward_bond forms it: (−ξ_c n(x)) n(x′).
                let bond = |i: usize, far: f64| -w.xi_c * here[i] * far;
                let [east, north_west, north, north_east] = bonds;
                for i in 0..m {
                    let (left, right) = (prev(i, m), next(i, m));
                    east[i] = bond(i, here[right]);
                    north_west[i] = bond(i, above[left]);
                    north[i] = bond(i, above[i]);
                    north_east[i] = bond(i, above[right]);
                }
            }
            None => {
                for (i, s) in row_of(&self.stencil, j, m).iter().enumerate() {
                    diag[i] = s[DIAG];
                    for (k, b) in bonds.iter_mut().enumerate() {
                        b[i] = s[1 + k];
                    }
                }
            }
        }
    }

    /// The Galerkin coarse level Pᵀ A P, P constant on 2×2 aggregates: every fine bond lands
    /// on its aggregate's diagonal (both ends inside: twice, once from each end) or on the
    /// coarse bond between the two aggregates it joins. Forward fine bonds never point down a
    /// row, so those of coarse row jc land in coarse row jc: the rows are independent.
    fn coarsen(&self, coarse: &mut Level) {
        if self.m.is_multiple_of(2) {
            self.coarsen_even(coarse);
        } else {
            self.coarsen_any(coarse);
        }
        coarse.finish();
    }

    /// [`Self::coarsen`] for any side, site by site: each fine bond's place on the coarse
    /// level found from where it points (the reference; odd sides take it).
    fn coarsen_any(&self, coarse: &mut Level) {
        let (m, mc) = (self.m, self.coarse_side());
        // Whether a step d from offset p inside an aggregate of width w leaves it.
        let leaves = |p: usize, d: isize, w: usize| -> isize {
            if (0..w as isize).contains(&(p as isize + d)) {
                0
            } else {
                d
            }
        };
        for (jc, row) in coarse.stencil.chunks_mut(mc).enumerate() {
            row.fill([0.0; 5]);
            let height = 2.min(m - 2 * jc);
            for j in 2 * jc..2 * jc + height {
                for i in 0..m {
                    let ic = i / 2;
                    let width = 2.min(m - 2 * ic);
                    row[ic][DIAG] += self.diagonal(j * m + i);
                    for (k, &(dx, dy)) in FORWARD.iter().enumerate() {
                        let b = self.forward_bond(i, j, k);
                        let (cdx, cdy) = (leaves(i % 2, dx, width), leaves(j - 2 * jc, dy, height));
                        match ALL_AS_FORWARD[direction(cdx, cdy)] {
                            (DIAG, _) => row[ic][DIAG] += 2.0 * b,
                            (c, false) => row[ic][c] += b,
                            // Only (−1, 0): the east bond of the aggregate to the west.
                            (c, true) => row[prev(ic, mc)][c] += b,
                        }
                    }
                }
            }
        }
    }

    /// [`Self::coarsen`] for an even side, where every aggregate is 2×2: each coarse
    /// coefficient written out as the sum of the fine diagonals and bonds that land on it, in
    /// the order [`Self::coarsen_any`] adds them (rows, then sites, then FORWARD's bonds), so
    /// the bits are the same; the aggregates of a row are then independent, a straight loop.
    /// Site (p, q) of an aggregate has diagonal d_pq and bonds E_pq, NW_pq, N_pq, NE_pq; a bond
    /// inside the aggregate lands twice on its diagonal, the others on the coarse bond between
    /// the two aggregates (NW_00 on the east bond of the aggregate to the west).
    fn coarsen_even(&self, coarse: &mut Level) {
        let (m, mc) = (self.m, self.m / 2);
        let mut diag = [vec![0.0; m], vec![0.0; m]];
        let mut bonds: [[Vec<f64>; 4]; 2] = std::array::from_fn(|_| std::array::from_fn(|_| vec![0.0; m]));
        for (jc, row) in coarse.stencil.chunks_mut(mc).enumerate() {
            for q in 0..2 {
                self.bond_rows(2 * jc + q, &mut diag[q], &mut bonds[q]);
            }
            let ([d0, d1], [[e0, nw0, n0, ne0], [e1, nw1, n1, ne1]]) = (&diag, &bonds);
            for (ic, out) in row.iter_mut().enumerate() {
                let (a, z) = (2 * ic, 2 * ic + 1);
                let diagonal = 0.0
                    + d0[a]
                    + 2.0 * e0[a]
                    + 2.0 * n0[a]
                    + 2.0 * ne0[a]
                    + d0[z]
                    + 2.0 * nw0[z]
                    + 2.0 * n0[z]
                    + d1[a]
                    + 2.0 * e1[a]
                    + d1[z];
                // The next aggregate's NW_00 comes after this one's sites in its row, except
                // across the periodic edge, where it is the row's first site.
                let east = if ic + 1 < mc {
                    0.0 + e0[z] + ne0[z] + nw0[z + 1] + e1[z]
                } else {
                    0.0 + nw0[0] + e0[z] + ne0[z] + e1[z]
                };
                let north = 0.0 + n1[a] + ne1[a] + nw1[z] + n1[z];
                *out = [diagonal, east, 0.0 + nw1[a], north, 0.0 + ne1[z]];
            }
        }
    }

    /// Copies the stencil into one array per coefficient and sets the Jacobi steps.
    fn finish(&mut self) {
        let m = self.m;
        let stencil = &self.stencil;
        for (k, c) in self.coefficients.iter_mut().enumerate() {
            for (c, s) in c.iter_mut().zip(&stencil[..m * m]) {
                *c = s[k] as Real;
            }
        }
        self.set_steps();
    }

    /// The Jacobi steps and prolongation weights, from the diagonal.
    fn set_steps(&mut self) {
        let mut jacobi = std::mem::take(&mut self.jacobi);
        let mut prolongation = std::mem::take(&mut self.prolongation);
        for (x, (w, p)) in jacobi.iter_mut().zip(&mut prolongation).enumerate() {
            let d = self.diagonal(x);
            *w = if d > 0.0 { (OMEGA / d) as Real } else { 0.0 };
            *p = if d > 0.0 { OVER_CORRECTION as Real } else { 0.0 };
        }
        (self.jacobi, self.prolongation) = (jacobi, prolongation);
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
        let (m, n) = (level.m, level.m * level.m);
        self.n = n;
        self.l.clear();
        self.l.resize(n * n, 0.0);
        let a = &mut self.l;
        for x in 0..n {
            // Sites outside the solve get an identity row: their right-hand side is zero.
            let d = level.diagonal(x);
            a[x * n + x] += if d > 0.0 { d } else { 1.0 };
            let (i, j) = (x % m, x / m);
            for (k, &(dx, dy)) in FORWARD.iter().enumerate() {
                let y = step(j, dy, m) * m + step(i, dx, m);
                let b = level.forward_bond(i, j, k);
                a[x * n + y] += b;
                a[y * n + x] += b;
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

    /// x = A⁻¹ b, through `scratch` in f64.
    fn solve(&self, x_out: &mut [Real], b: &[Real], scratch: &mut Vec<f64>) {
        let (n, l) = (self.n, &self.l);
        scratch.clear();
        scratch.extend(b.iter().map(|&b| b as f64));
        let x = scratch;
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
        for (o, x) in x_out.iter_mut().zip(x.iter()) {
            *o = *x as Real;
        }
    }
}

/// The level hierarchy, rebuilt for every solve (n changes every evaluation).
#[derive(Clone, Debug, Default)]
pub struct Multigrid {
    levels: Vec<Level>,
    coarsest: Coarsest,
}

/// The sides of the levels for an L × L lattice, finest first: ⌈m/2⌉ per level while the side
/// exceeds `COARSEST_SIDE` (the GPU's hierarchy, `gpu::buffers::Hierarchy`, is the same).
pub fn level_sides(l: usize) -> Vec<usize> {
    let mut sides = vec![l];
    while let Some(&m) = sides.last().filter(|&&m| m > COARSEST_SIDE) {
        sides.push(m.div_ceil(2));
    }
    sides
}

impl Multigrid {
    pub fn new(l: usize) -> Self {
        let mut levels: Vec<Level> = level_sides(l).into_iter().map(Level::with_side).collect();
        levels[0].stencil = Vec::new();
        Multigrid { levels, coarsest: Coarsest::default() }
    }

    /// Work space for one cycle at a time over this hierarchy.
    pub fn work(&self) -> CycleWork {
        let levels = self
            .levels
            .iter()
            .enumerate()
            .map(|(k, level)| {
                let n = level.m * level.m;
                // The finest level's solution and right-hand side are the caller's.
                let own = if k == 0 { 0 } else { n };
                Work { x: vec![0.0; own], b: vec![0.0; own], t: vec![0.0; n], column: vec![0.0; level.m] }
            })
            .collect();
        let n = self.levels[0].m * self.levels[0].m;
        CycleWork { levels, r: vec![0.0; n], z: vec![0.0; n], coarsest: Vec::new() }
    }

    /// Sets up the hierarchy for C = diag(n (ξ_s + ξ_c N)) − ξ_c diag(n) A₈ diag(n), given n,
    /// N = Σ_{N8} n and ξ_s on the lattice. Sites with n = 0 are outside the solve: their
    /// diagonal and bonds are zero.
    pub fn setup(&mut self, n: &[f64], n_nb: &[f64], xi_s: &[f64], xi_c: f64) {
        // The finest level keeps C's own form: its diagonal, and n for the bonds.
        let fine = &mut self.levels[0];
        let mut w = fine.weights.take().unwrap_or_default();
        w.xi_c = xi_c;
        w.diag.clear();
        w.diag.extend(
            n.iter().zip(n_nb).zip(xi_s).map(|((&n, &nb), &xs)| if n > 0.0 { n * (xs + xi_c * nb) } else { 0.0 }),
        );
        w.n.clear();
        w.n.extend(n.iter().zip(&w.diag).map(|(n, d)| if *d > 0.0 { *n } else { 0.0 }));
        w.n_real.clear();
        w.n_real.extend(w.n.iter().map(|&n| n as Real));
        for (c, d) in fine.coefficients[DIAG].iter_mut().zip(&w.diag) {
            *c = *d as Real;
        }
        fine.weights = Some(w);
        fine.set_steps();
        for k in 1..self.levels.len() {
            let (fine, coarse) = self.levels.split_at_mut(k);
            fine[k - 1].coarsen(&mut coarse[0]);
        }
        self.coarsest.factor(self.levels.last().expect("at least one level"));
    }

    /// C's diagonal as set up, zero on the sites outside the solve.
    pub fn diagonal(&self) -> &[f64] {
        &self.levels[0].weights.as_ref().expect("set up").diag
    }

    /// out = C v, the finest level's operator (zero on the sites outside the solve); `column`
    /// is work space of one row. Returns ⟨v, C v⟩ (summed row by row), which CG needs next,
    /// while the rows are at hand.
    pub fn apply(&self, v: &[f64], out: &mut [f64], column: &mut [f64]) -> f64 {
        let (fine, m) = (&self.levels[0], self.levels[0].m);
        let w = fine.weights.as_ref().expect("set up");
        let mut dot = 0.0;
        for (j, row) in out.chunks_mut(m).enumerate() {
            weights_row(&w.n, &w.diag, w.xi_c, v, m, j, row, column);
            dot += sum_pairs(row, row_of(v, j, m), |a, b| a * b);
        }
        dot
    }

    /// z = M r for the r in `work` (`CycleWork::residual_mut`): one symmetric cycle from
    /// zero, left in `work` (`CycleWork::preconditioned`) in the cycle's precision, which CG
    /// reads as it updates its direction (a copy in f64 would only add a pass). Returns ⟨r, z⟩
    /// (summed in f64), which CG needs next.
    pub fn precondition(&self, work: &mut CycleWork) -> f64 {
        let (rr, mut zz) = (std::mem::take(&mut work.r), std::mem::take(&mut work.z));
        let mut fine = std::mem::take(&mut work.levels[0]);
        self.cycle(work, 0, &mut zz, &rr, &mut fine.t, &mut fine.column);
        let dot = sum_pairs(&zz, &rr, |z, r| z as f64 * r as f64);
        (work.r, work.z, work.levels[0]) = (rr, zz, fine);
        dot
    }

    /// x ≈ A_k⁻¹ b from zero on level k: a smoothing sweep, coarse corrections, a smoothing sweep.
    /// `t` and `column` are work space of the level (a field and a row).
    #[allow(clippy::too_many_arguments)]
    fn cycle(&self, work: &mut CycleWork, k: usize, x: &mut [Real], b: &[Real], t: &mut [Real], column: &mut [Real]) {
        if k + 1 == self.levels.len() {
            self.coarsest.solve(x, b, &mut work.coarsest);
            return;
        }
        let level = &self.levels[k];
        let mut coarse = std::mem::take(&mut work.levels[k + 1]);
        level.smooth_from_zero(x, b);
        let corrections = if k == 0 { 1 } else { COARSE_CORRECTIONS };
        for _ in 0..corrections {
            level.restrict_residual(x, b, &mut coarse.b, t);
            self.cycle(work, k + 1, &mut coarse.x, &coarse.b, &mut coarse.t, &mut coarse.column);
            level.prolong(&coarse.x, x);
        }
        level.smooth(x, b, t, column);
        work.levels[k + 1] = coarse;
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

    fn field(l: usize, seed: u64) -> Vec<f64> {
        // A small deterministic pseudo-random field (an LCG is enough for a test vector).
        let mut s = seed.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
        let mut next = || {
            s = s.wrapping_mul(6364136223846793005).wrapping_add(1442695040888963407);
            (s >> 11) as f64 / (1u64 << 53) as f64 - 0.5
        };
        (0..l * l).map(|_| next()).collect()
    }

    fn setup(l: usize) -> (Multigrid, Vec<f64>) {
        let n = edge_network(l);
        let mut nn = vec![0.0; l * l];
        crate::model::lattice::neighbour_sum8(&n, &mut nn, l);
        let mut mg = Multigrid::new(l);
        mg.setup(&n, &nn, &vec![0.001; l * l], 1.0);
        (mg, n)
    }

    fn dot(a: &[f64], b: &[f64]) -> f64 {
        a.iter().zip(b).map(|(x, y)| x * y).sum()
    }

    /// M r in f64, and the ⟨r, M r⟩ the cycle returned.
    fn preconditioned(mg: &Multigrid, work: &mut CycleWork, r: &[f64]) -> (Vec<f64>, f64) {
        for (a, b) in work.residual_mut().iter_mut().zip(r) {
            *a = *b as Real;
        }
        let rz = mg.precondition(work);
        (work.preconditioned().iter().map(|&z| z as f64).collect(), rz)
    }

    #[test]
    fn direction_tables_agree() {
        for (d, &(dx, dy)) in ALL.iter().enumerate() {
            assert_eq!(direction(dx, dy), d);
            let (k, backward) = ALL_AS_FORWARD[d];
            if d == 8 {
                assert_eq!(k, DIAG);
            } else {
                let f = if backward { (-dx, -dy) } else { (dx, dy) };
                assert_eq!(FORWARD[k - 1], f, "direction {d}");
            }
        }
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
        let mut vf = vec![0.0; l * l];
        for x in 0..l * l {
            if fine.in_solve(x) {
                vf[x] = vc[fine.aggregate(x)];
            }
        }
        let af = fine.apply_exact(&vf);
        let mut expected = vec![0.0; coarse.m * coarse.m];
        for x in 0..l * l {
            if fine.in_solve(x) {
                expected[fine.aggregate(x)] += af[x];
            }
        }
        let got = coarse.apply_exact(&vc);
        for c in 0..coarse.m * coarse.m {
            if coarse.in_solve(c) {
                assert!((got[c] - expected[c]).abs() < 1e-12, "aggregate {c}: {} vs {}", got[c], expected[c]);
            }
        }
    }

    /// On an even side the coarse level is written out per aggregate (`coarsen_even`); it must
    /// be the site-by-site construction's bit for bit, from C's own form (the finest level) and
    /// from a stencil (the level below), across the periodic edges and with a hole.
    #[test]
    fn even_sides_coarsen_to_the_same_bits() {
        // Weights and ξ_c whose products round, so that an order of addition shows in the bits.
        let l = 40;
        let n: Vec<f64> = edge_network(l).iter().zip(field(l, 5)).map(|(n, r)| n * (1.0 + 0.3 * r)).collect();
        let mut nn = vec![0.0; l * l];
        crate::model::lattice::neighbour_sum8(&n, &mut nn, l);
        let mut mg = Multigrid::new(l);
        mg.setup(&n, &nn, &field(l, 6).iter().map(|r| 0.001 * (1.5 + r)).collect::<Vec<_>>(), 0.7);
        for k in 0..2 {
            let (fine, coarse) = (&mg.levels[k], &mg.levels[k + 1]);
            assert!(fine.m.is_multiple_of(2));
            assert_eq!(fine.weights.is_some(), k == 0);
            let mut reference = Level::with_side(coarse.m);
            fine.coarsen_any(&mut reference);
            let bits = |l: &Level| l.stencil.iter().flatten().map(|c| c.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(coarse), bits(&reference), "level {k} to {}", k + 1);
            assert!(coarse.stencil.iter().any(|s| s[DIAG] == 0.0), "the hole reaches level {}", k + 1);
        }
    }

    /// The cycle's own products (in f32) agree with the stencils as built (f64), on the finest
    /// level (C's own form) and below (the bond arrays), to f32 rounding.
    #[test]
    fn cycle_products_match_the_stencils() {
        let l = 35;
        let (mg, _) = setup(l);
        for level in &mg.levels[..3] {
            let n = level.m * level.m;
            let v = field(level.m, 7);
            let exact = level.apply_exact(&v);
            let v32: Vec<Real> = v.iter().map(|&v| v as Real).collect();
            let mut got = vec![0.0; n];
            level.apply(&v32, &mut got);
            let scale = exact.iter().fold(0.0f64, |a, b| a.max(b.abs()));
            for x in 0..n {
                assert!((got[x] as f64 - exact[x]).abs() < 1e-5 * scale, "side {}, site {x}", level.m);
            }
        }
    }

    /// CG needs a symmetric positive definite preconditioner: ⟨M a, b⟩ = ⟨a, M b⟩ and ⟨M a, a⟩ > 0.
    #[test]
    fn cycle_is_symmetric_positive_definite() {
        let l = 40;
        let (mg, n) = setup(l);
        let mut work = mg.work();
        let mask =
            |v: Vec<f64>| -> Vec<f64> { v.into_iter().zip(&n).map(|(z, n)| if *n > 0.0 { z } else { 0.0 }).collect() };
        let (a, b) = (mask(field(l, 1)), mask(field(l, 2)));
        let (ma, aa) = preconditioned(&mg, &mut work, &a);
        let (mb, bb) = preconditioned(&mg, &mut work, &b);
        let (ab, ba) = (dot(&ma, &b), dot(&a, &mb));
        // The returned ⟨r, M r⟩ is the product of the z the work space holds with r as the
        // cycle saw it (in its precision).
        let rounded = |v: &[f64]| -> Vec<f64> { v.iter().map(|&x| x as Real as f64).collect() };
        let lane_dot = |a: &[f64], b: &[f64]| sum_pairs(a, b, |x, y| x * y);
        assert_eq!((aa, bb), (lane_dot(&ma, &rounded(&a)), lane_dot(&mb, &rounded(&b))));
        // Symmetric up to the cycle's f32 rounding, which adds up over the levels (4e-5 here);
        // CG does not mind: it takes as many iterations as with the cycle in f64.
        assert!((ab - ba).abs() < 2e-4 * ab.abs().max(1.0), "⟨Ma, b⟩ = {ab}, ⟨a, Mb⟩ = {ba}");
        assert!(dot(&ma, &a) > 0.0 && dot(&mb, &b) > 0.0);
    }

    /// The rigid translation is the soft mode at low friction (C·1 = ξ_s n): one cycle maps
    /// its residual back to a uniform field, so it is (nearly) an eigenvector of the
    /// preconditioned operator, which the diagonally scaled FFT inverse could not manage where
    /// n ≠ 1. (The over-correction scales it, uniformly: CG does not mind a scale.)
    #[test]
    fn cycle_maps_a_rigid_translation_to_a_uniform_field() {
        let l = 40;
        let (mg, n) = setup(l);
        let r: Vec<f64> = n.iter().map(|n| 0.001 * n).collect();
        let (z, _) = preconditioned(&mg, &mut mg.work(), &r);
        let active: Vec<f64> = z.iter().zip(&n).filter(|(_, n)| **n > 0.0).map(|(z, _)| *z).collect();
        let mean = active.iter().sum::<f64>() / active.len() as f64;
        let spread = active.iter().map(|v| (v - mean).abs()).fold(0.0, f64::max);
        assert!(mean > 0.5, "mean {mean}");
        assert!(spread < 0.05 * mean, "spread {spread} about the mean {mean}");
        assert!(z.iter().zip(&n).all(|(z, n)| *n > 0.0 || *z == 0.0), "sites outside the solve stay at zero");
    }
}

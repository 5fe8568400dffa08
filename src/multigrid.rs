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
//! One symmetric W-cycle with damped Jacobi smoothing is a symmetric positive definite
//! preconditioner for CG.
//!
//! Layout, for speed: every level is a 9-point stencil stored as its diagonal and the four
//! "forward" bonds of each site ([`FORWARD`]); the other four are the neighbours' forward bonds
//! (A is symmetric), so a product streams through rows with no index tables. Sites outside the
//! solve (n = 0) have a zero diagonal and zero bonds: the finest level *is* C, which CG applies
//! through [`Multigrid::apply`]. Every pass writes each output site once from a fixed sum, so the
//! passes split into row bands across threads without changing a bit.

use num_complex::Complex64 as C64;

use crate::par;

const ZERO: C64 = C64 { re: 0.0, im: 0.0 };

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

/// The eight neighbour directions, and (0, 0) last.
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
const COARSEST_SIDE: usize = 6;

/// Factor on every coarse correction. Piecewise-constant interpolation stores too much energy
/// in the coarse vectors, so a plain correction falls short; over-correcting makes up for it
/// (Vaněk's classic remedy for unsmoothed aggregation). Any value in (0, 2) keeps the cycle
/// symmetric positive definite. Measured at full size with the V-cycle, iterations per solve at
/// χ = 0.1 and χ = 0.001: 1.0 → 7.1 and 18.7; 1.4 → 6.7 and 11.6; 1.5 → 7.3 and 10.7; 1.8 → 9.2
/// and 10.2. With the W-cycle at χ = 0.001: 1.3 → 8.9, 1.5 → 8.3, 1.7 → 8.0; but with three
/// corrections per level 1.7 diverges, so 1.5 keeps a margin.
const OVER_CORRECTION: f64 = 1.5;

/// Coarse corrections per visit of every level but the finest: 1 is a V-cycle, 2 a W-cycle.
/// Unsmoothed aggregation loses accuracy level by level; visiting the coarse levels twice makes
/// up for it at little cost (they hold a third of the sites). Measured at full size, χ = 0.001:
/// 10.7 iterations per warm-started solve with the V-cycle, 8.3 with the W-cycle (18 → 12 from a
/// cold start); three corrections gain no more.
const COARSE_CORRECTIONS: usize = 2;

/// Levels at least this wide split their passes across threads.
const PARALLEL_SIDE: usize = 64;

/// Damped Jacobi weight: the operators are weakly diagonally dominant M-matrices on every
/// level (Galerkin aggregation keeps that), so D⁻¹A has its spectrum in [0, 2) and 2/3 keeps the
/// smoother convergent while damping the highest modes. One sweep before and one after each
/// coarse correction (equal, so the cycle is symmetric): measured at full size with presence
/// weights, 2 sweeps saved 17 % of the iterations at χ = 0.001 but cost 24 % more time.
const OMEGA: f64 = 2.0 / 3.0;

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

/// Runs `f(row, values)` over the rows of an m×m field, in bands across threads when m is large.
fn for_rows<T: Send>(out: &mut [T], m: usize, f: impl Fn(usize, &mut [T]) + Sync + Send) {
    if m < PARALLEL_SIDE {
        for (j, row) in out.chunks_mut(m).enumerate() {
            f(j, row);
        }
        return;
    }
    let rows = par::band_rows(m);
    par::for_each_chunk_mut(out, rows * m, |k, band| {
        for (r, row) in band.chunks_mut(m).enumerate() {
            f(k * rows + r, row);
        }
    });
}

/// One level: the operator on an m×m periodic grid.
#[derive(Clone, Debug, Default)]
struct Level {
    m: usize,
    stencil: Vec<Stencil>,
    /// ω/diagonal on sites in the solve, 0 elsewhere: the damped Jacobi step, which also keeps
    /// the sites outside at zero.
    jacobi: Vec<f64>,
}

/// Solution, right-hand side and residual of one level during a cycle (the finest level's
/// solution and right-hand side are the caller's).
#[derive(Clone, Debug, Default)]
struct Work {
    x: Vec<C64>,
    b: Vec<C64>,
    t: Vec<C64>,
}

impl Work {
    fn with_len(n: usize, coarse: bool) -> Self {
        let own = if coarse { n } else { 0 };
        Work { x: vec![ZERO; own], b: vec![ZERO; own], t: vec![ZERO; n] }
    }
}

impl Level {
    fn with_side(m: usize) -> Self {
        Level { m, stencil: vec![[0.0; 5]; m * m], jacobi: vec![0.0; m * m] }
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
        self.stencil[x][DIAG] > 0.0
    }

    /// Row j of A v, in three passes over the row: the bonds within the column, those to the
    /// column on the right, those to the column on the left. Each pass is a straight loop with
    /// independent sites (no index tables, no bounds checks), so the sums of neighbouring sites
    /// overlap in the pipeline; the wrapped end site of each shifted pass is added on its own.
    #[inline]
    fn apply_row(&self, v: &[C64], j: usize, out: &mut [C64]) {
        let m = self.m;
        let jm = prev(j, m);
        let row = |r: usize| &v[r * m..][..m];
        let (vm, v0, vp) = (row(jm), row(j), row(next(j, m)));
        let s0 = &self.stencil[j * m..][..m];
        let sm = &self.stencil[jm * m..][..m];
        let out = &mut out[..m];
        // Centre, north (x + (0, 1)) and south (the north bond of the site below).
        for (o, ((s, sm), (v0, (vp, vm)))) in
            out.iter_mut().zip(s0.iter().zip(sm).zip(v0.iter().zip(vp.iter().zip(vm))))
        {
            *o = v0 * s[DIAG] + (vp * s[NORTH] + vm * sm[NORTH]);
        }
        // Right-hand column: east, north-east, and south-east (the north-west bond of the site
        // to the south-east).
        let right = |s: &Stencil, sm_right: &Stencil, v0_right: C64, vp_right: C64, vm_right: C64| {
            v0_right * s[EAST] + (vp_right * s[NORTH_EAST] + vm_right * sm_right[NORTH_WEST])
        };
        for (o, ((s, sm_r), (v0_r, (vp_r, vm_r)))) in
            out[..m - 1].iter_mut().zip(s0.iter().zip(&sm[1..]).zip(v0[1..].iter().zip(vp[1..].iter().zip(&vm[1..]))))
        {
            *o += right(s, sm_r, *v0_r, *vp_r, *vm_r);
        }
        out[m - 1] += right(&s0[m - 1], &sm[0], v0[0], vp[0], vm[0]);
        // Left-hand column: north-west, west (the east bond of the site to the west) and
        // south-west (the north-east bond of the site to the south-west).
        let left = |s: &Stencil, s_left: &Stencil, sm_left: &Stencil, v0_left: C64, vp_left: C64, vm_left: C64| {
            vp_left * s[NORTH_WEST] + (v0_left * s_left[EAST] + vm_left * sm_left[NORTH_EAST])
        };
        for (o, ((s, (s_l, sm_l)), (v0_l, (vp_l, vm_l)))) in
            out[1..].iter_mut().zip(s0[1..].iter().zip(s0.iter().zip(sm)).zip(v0.iter().zip(vp.iter().zip(vm))))
        {
            *o += left(s, s_l, sm_l, *v0_l, *vp_l, *vm_l);
        }
        out[0] += left(&s0[0], &s0[m - 1], &sm[m - 1], v0[m - 1], vp[m - 1], vm[m - 1]);
    }

    /// out = A v.
    fn apply(&self, v: &[C64], out: &mut [C64]) {
        for_rows(out, self.m, |j, row| self.apply_row(v, j, row));
    }

    /// t = b − A x.
    fn residual(&self, x: &[C64], b: &[C64], t: &mut [C64]) {
        let m = self.m;
        for_rows(t, m, |j, row| {
            self.apply_row(x, j, row);
            for (t, b) in row.iter_mut().zip(&b[j * m..][..m]) {
                *t = b - *t;
            }
        });
    }

    /// x = ω D⁻¹ b: one damped Jacobi sweep from zero.
    fn smooth_from_zero(&self, x: &mut [C64], b: &[C64]) {
        let m = self.m;
        for_rows(x, m, |j, row| {
            for ((x, b), w) in row.iter_mut().zip(&b[j * m..][..m]).zip(&self.jacobi[j * m..][..m]) {
                *x = b * *w;
            }
        });
    }

    /// x += ω D⁻¹ (b − A x), with t as work space.
    fn smooth(&self, x: &mut [C64], b: &[C64], t: &mut [C64]) {
        self.residual(x, b, t);
        let m = self.m;
        for_rows(x, m, |j, row| {
            for ((x, t), w) in row.iter_mut().zip(&t[j * m..][..m]).zip(&self.jacobi[j * m..][..m]) {
                *x += t * *w;
            }
        });
    }

    /// coarse_b = Pᵀ t: the fine values summed over each aggregate.
    fn restrict(&self, t: &[C64], coarse_b: &mut [C64]) {
        let (m, mc) = (self.m, self.coarse_side());
        for_rows(coarse_b, mc, |jc, row| {
            row.fill(ZERO);
            for j in (2 * jc..2 * jc + 2).filter(|&j| j < m) {
                for (i, t) in t[j * m..][..m].iter().enumerate() {
                    row[i / 2] += t;
                }
            }
        });
    }

    /// x += P coarse_x on the sites in the solve, over-corrected.
    fn prolong(&self, coarse_x: &[C64], x: &mut [C64]) {
        let (m, mc) = (self.m, self.coarse_side());
        for_rows(x, m, |j, row| {
            let c = &coarse_x[(j / 2) * mc..][..mc];
            for (i, (x, w)) in row.iter_mut().zip(&self.jacobi[j * m..][..m]).enumerate() {
                if *w > 0.0 {
                    *x += c[i / 2] * OVER_CORRECTION;
                }
            }
        });
    }

    /// The bond between site (i, j) and its neighbour in direction `ALL[d]`.
    #[inline]
    fn bond(&self, i: usize, j: usize, d: usize) -> f64 {
        let m = self.m;
        let (k, backward) = ALL_AS_FORWARD[d];
        if backward {
            let (dx, dy) = ALL[d];
            self.stencil[step(j, dy, m) * m + step(i, dx, m)][k]
        } else {
            self.stencil[j * m + i][k]
        }
    }

    /// The Galerkin coarse level Pᵀ A P, P constant on 2×2 aggregates. Each coarse site gathers
    /// its own entries (its aggregate's diagonals and inner bonds, and the bonds leaving it in the
    /// four forward coarse directions), so coarse rows are independent.
    fn coarsen(&self, coarse: &mut Level) {
        let m = self.m;
        let mc = self.coarse_side();
        for_rows(&mut coarse.stencil, mc, |jc, row| {
            for (ic, s) in row.iter_mut().enumerate() {
                *s = [0.0; 5];
                for j in (2 * jc..2 * jc + 2).filter(|&j| j < m) {
                    for i in (2 * ic..2 * ic + 2).filter(|&i| i < m) {
                        let x = j * m + i;
                        s[DIAG] += self.stencil[x][DIAG];
                        for (d, &(dx, dy)) in ALL[..8].iter().enumerate() {
                            // Which way the bond leaves the aggregate, if it does; bonds
                            // leaving backwards are the other aggregate's forward ones.
                            let cdx = if step(i, dx, m) / 2 == ic { 0 } else { dx };
                            let cdy = if step(j, dy, m) / 2 == jc { 0 } else { dy };
                            let (k, backward) = ALL_AS_FORWARD[direction(cdx, cdy)];
                            if !backward {
                                s[k] += self.bond(i, j, d);
                            }
                        }
                    }
                }
            }
        });
        coarse.set_jacobi();
    }

    fn set_jacobi(&mut self) {
        let m = self.m;
        let stencil = &self.stencil;
        for_rows(&mut self.jacobi, m, |j, row| {
            for (w, s) in row.iter_mut().zip(&stencil[j * m..][..m]) {
                *w = if s[DIAG] > 0.0 { OMEGA / s[DIAG] } else { 0.0 };
            }
        });
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
            let d = level.stencil[x][DIAG];
            a[x * n + x] += if d > 0.0 { d } else { 1.0 };
            let (i, j) = ((x % m) as isize, (x / m) as isize);
            for (k, (dx, dy)) in FORWARD.iter().enumerate() {
                let y = ((j + dy).rem_euclid(m as isize) * m as isize + (i + dx).rem_euclid(m as isize)) as usize;
                let b = level.stencil[x][1 + k];
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

    fn solve(&self, x: &mut [C64], b: &[C64]) {
        let (n, l) = (self.n, &self.l);
        x.copy_from_slice(b);
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
    work: Vec<Work>,
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
        let work = levels.iter().enumerate().map(|(k, lv)| Work::with_len(lv.m * lv.m, k > 0)).collect();
        Multigrid { levels, work, coarsest: Coarsest::default() }
    }

    /// Sets up the hierarchy for C with bond weights −ξ_c n(x) n(x′) and diagonal `diag`
    /// (zero where n = 0, the sites outside the solve).
    pub fn setup(&mut self, n: &[f64], diag: &[f64], xi_c: f64) {
        let fine = &mut self.levels[0];
        let m = fine.m;
        for_rows(&mut fine.stencil, m, |j, row| {
            for (i, s) in row.iter_mut().enumerate() {
                let x = j * m + i;
                *s = [0.0; 5];
                if diag[x] > 0.0 {
                    s[DIAG] = diag[x];
                    for (k, (dx, dy)) in FORWARD.iter().enumerate() {
                        let ni = (i as isize + dx).rem_euclid(m as isize) as usize;
                        let nj = (j as isize + dy).rem_euclid(m as isize) as usize;
                        let y = nj * m + ni;
                        if diag[y] > 0.0 {
                            s[1 + k] = -xi_c * n[x] * n[y];
                        }
                    }
                }
            }
        });
        fine.set_jacobi();
        for k in 1..self.levels.len() {
            let (fine, coarse) = self.levels.split_at_mut(k);
            fine[k - 1].coarsen(&mut coarse[0]);
        }
        self.coarsest.factor(self.levels.last().expect("at least one level"));
    }

    /// out = C v, the finest level's operator (zero on the sites outside the solve).
    pub fn apply(&self, v: &[C64], out: &mut [C64]) {
        self.levels[0].apply(v, out);
    }

    /// z = M r: one symmetric cycle from zero.
    pub fn precondition(&mut self, r: &[C64], z: &mut [C64]) {
        let mut t = std::mem::take(&mut self.work[0].t);
        self.cycle(0, z, r, &mut t);
        self.work[0].t = t;
    }

    /// x ≈ A_k⁻¹ b from zero on level k: a smoothing sweep, coarse corrections, a smoothing sweep.
    fn cycle(&mut self, k: usize, x: &mut [C64], b: &[C64], t: &mut [C64]) {
        if k + 1 == self.levels.len() {
            self.coarsest.solve(x, b);
            return;
        }
        let mut coarse = std::mem::take(&mut self.work[k + 1]);
        self.levels[k].smooth_from_zero(x, b);
        let corrections = if k == 0 { 1 } else { COARSE_CORRECTIONS };
        for _ in 0..corrections {
            self.levels[k].residual(x, b, t);
            self.levels[k].restrict(t, &mut coarse.b);
            self.cycle(k + 1, &mut coarse.x, &coarse.b, &mut coarse.t);
            self.levels[k].prolong(&coarse.x, x);
        }
        self.levels[k].smooth(x, b, t);
        self.work[k + 1] = coarse;
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
        let mut nn = vec![0.0; l * l];
        crate::lattice::neighbour_sum8(n, &mut nn, l);
        (0..l * l)
            .map(|x| {
                let nn = nn[x];
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
        let mut vf = vec![ZERO; l * l];
        for x in 0..l * l {
            if fine.in_solve(x) {
                vf[x] = vc[fine.aggregate(x)];
            }
        }
        let mut af = vec![ZERO; l * l];
        fine.apply(&vf, &mut af);
        let mut expected = vec![ZERO; coarse.m * coarse.m];
        for x in 0..l * l {
            if fine.in_solve(x) {
                expected[fine.aggregate(x)] += af[x];
            }
        }
        let mut got = vec![ZERO; coarse.m * coarse.m];
        coarse.apply(&vc, &mut got);
        for c in 0..coarse.m * coarse.m {
            if coarse.in_solve(c) {
                assert!((got[c] - expected[c]).norm() < 1e-12, "aggregate {c}: {} vs {}", got[c], expected[c]);
            }
        }
    }

    /// CG needs a symmetric positive definite preconditioner: ⟨M a, b⟩ = ⟨a, M b⟩ and ⟨M a, a⟩ > 0.
    #[test]
    fn cycle_is_symmetric_positive_definite() {
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

    /// The rigid translation is the soft mode at low friction (C·1 = ξ_s n): one cycle maps
    /// its residual back to a uniform field, so it is (nearly) an eigenvector of the
    /// preconditioned operator, which the diagonally scaled FFT inverse could not manage where
    /// n ≠ 1. (The over-correction scales it, uniformly: CG does not mind a scale.)
    #[test]
    fn cycle_maps_a_rigid_translation_to_a_uniform_field() {
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

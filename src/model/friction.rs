//! Substrate and cell–cell friction: the force balance of Eq. 2, solved on the lattice.
//!
//! Per cell i and site x (docs/reading.md §4):
//!   ξ_s v_i(x) + ξ_c Σ_{x'∈N8(x)} Σ_j w_j(x') [v_i(x) − v_j(x')] = f_i(x).
//! With n = Σ_j w_j, V = Σ_j w_j v_j, F = Σ_j w_j f_j, N = Σ_{N8} n and S = Σ_{N8} V, every cell's
//! velocity follows once V is known,
//!   v_i(x) = [f_i(x) + ξ_c S(x)] / [ξ_s(x) + ξ_c N(x)],
//! and V solves one two-component lattice equation, [ξ_s + ξ_c N] V − ξ_c n S = F.
//!
//! It is solved for the local mean velocity u = V/n, in which it is symmetric:
//!   C u = F,  C = diag(n (ξ_s + ξ_c N)) − ξ_c diag(n) A₈ diag(n)   (A₈: 8-neighbour adjacency),
//! positive definite on the sites with n > 0 (u = 0 elsewhere). In u, a uniform translation is the
//! soft mode (C·1 = ξ_s n), as for the constant-coefficient operator K = C|_{n≡1}; in V it would
//! be V ∝ n, which no level of a preconditioner represents exactly.
//!
//! The screening length √(3ξ_c/ξ_s) is 55 sites at χ = 0.001, as large as the box: a few
//! relaxation sweeps would quietly add friction and kill the long-range flows that make holes.
//! C is solved to a stated relative residual ‖F − C u‖/‖F‖ by conjugate gradients, warm-started
//! from the last solution (Heun's corrector from the predictor's plus the last step's corrector
//! shift, [`FrictionSolver::shift_to_corrector`]), preconditioned by one W-cycle of aggregation multigrid
//! (`multigrid`), whose coarse levels see n, holes included (why not an FFT preconditioner:
//! docs/performance.md).
//! C is real, so the two components (x, y) are two independent real systems over one
//! multigrid hierarchy: each runs its own CG, on its own thread where two are available, and
//! stops at ‖F_c − C u_c‖ ≤ tolerance·‖F‖/√2, so that together they meet the stated residual.
//! Neither depends on the other or on the thread count, so the bits do not either.

use num_complex::Complex64 as C64;

use crate::model::lattice::{neighbour_sum8, neighbour_sum8_row};
use crate::model::multigrid::{CycleWork, Multigrid, Real};
use crate::model::par;
use crate::model::sum::{combine, LANES};

const ZERO: C64 = C64 { re: 0.0, im: 0.0 };

/// What a solve did.
#[derive(Clone, Copy, Debug, Default, PartialEq)]
pub struct SolveStats {
    pub iterations: usize,
    /// ‖F − C u‖ / ‖F‖ at the end.
    pub residual: f64,
}

/// The solve did not reach its tolerance, or met a non-finite number.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[error("friction solve: relative residual {residual:.2e} after {iterations} iterations (tolerance {tolerance:.1e}){detail}")]
pub struct SolveError {
    pub iterations: usize,
    pub residual: f64,
    pub tolerance: f64,
    pub detail: &'static str,
}

/// Inputs of one solve, all on the L×L lattice.
pub struct FrictionProblem<'a> {
    /// n(x) = Σ_j w_j(x).
    pub weight: &'a [f64],
    /// F(x) = Σ_j w_j(x) f_j(x), x and y components as re and im.
    pub force: &'a [C64],
    /// ξ_s(x).
    pub xi_s: &'a [f64],
    /// ξ_cell.
    pub xi_c: f64,
    pub tolerance: f64,
    pub max_iterations: usize,
}

/// Work arrays and the last solution (the warm start of the next solve).
#[derive(Clone, Debug)]
pub struct FrictionSolver {
    l: usize,
    /// The preconditioner, set up for every new operator.
    mg: Multigrid,
    /// N(x) = Σ_{N8} n.
    pub weight_nb: Vec<f64>,
    /// 1/[ξ_s(x) + ξ_c N(x)]: every cell's velocity is its force plus the pull, times this
    /// (one division per site of the lattice instead of two per site of every patch).
    pub mobility: Vec<f64>,
    /// The x and y components' CG.
    components: [Component; 2],
    /// u = V/n: the solution, and the warm start of the next solve.
    pub mean_velocity: Vec<C64>,
    /// u(corrector) − u(predictor) of the last Heun step. Within a step the operator is the
    /// same (subdomain weights: n follows the patches, which move only between steps) and F
    /// moves smoothly, so the corrector's solution is the predictor's plus nearly this shift:
    /// with it the corrector's initial residual is about 13× smaller (docs/performance.md,
    /// "The corrector's guess").
    pub corrector_shift: Vec<C64>,
    /// The predictor's solution of the step under way, from which the shift is measured.
    predictor_solution: Vec<C64>,
    /// A copy of the warm start while an out-of-step evaluation runs (see [`Self::hold_warm_start`]).
    held: Vec<C64>,
    /// ξ_c S(x), S = Σ_{N8} V with V = n u: the pull of the neighbouring cells on every cell at x.
    pub pull: Vec<C64>,
    /// The n, ξ_s and ξ_c the hierarchy was last built for (ξ_c `None` before the first
    /// [`Self::prepare`]): an unchanged operator is not built again (with subdomain weights n
    /// changes only when the patches move, after each step, so Heun's corrector solves with the
    /// predictor's hierarchy).
    built_n: Vec<f64>,
    built_xi_s: Vec<f64>,
    built_xi_c: Option<f64>,
}

impl FrictionSolver {
    pub fn new(l: usize) -> Self {
        let n = l * l;
        let mg = Multigrid::new(l);
        FrictionSolver {
            l,
            weight_nb: vec![0.0; n],
            mobility: vec![0.0; n],
            components: std::array::from_fn(|_| Component::new(l, &mg)),
            mean_velocity: vec![ZERO; n],
            corrector_shift: vec![ZERO; n],
            predictor_solution: vec![ZERO; n],
            held: vec![ZERO; n],
            pull: vec![ZERO; n],
            built_n: Vec::new(),
            built_xi_s: Vec::new(),
            built_xi_c: None,
            mg,
        }
    }

    /// Forgets the warm start and the corrector shift.
    pub fn reset(&mut self) {
        self.mean_velocity.fill(ZERO);
        self.corrector_shift.fill(ZERO);
    }

    /// Before Heun's corrector solves: keeps the predictor's solution, and starts the corrector
    /// from it plus the last step's shift.
    pub fn shift_to_corrector(&mut self) {
        let (u, kept) = (&mut self.mean_velocity, &mut self.predictor_solution);
        for ((u, kept), &d) in u.iter_mut().zip(kept.iter_mut()).zip(&self.corrector_shift) {
            *kept = *u;
            *u += d;
        }
    }

    /// After Heun's corrector solved: the shift its solution made from the predictor's, for
    /// the next step's corrector.
    pub fn record_corrector_shift(&mut self) {
        let (d, u) = (&mut self.corrector_shift, &self.mean_velocity);
        for ((d, &u), &p) in d.iter_mut().zip(u).zip(&self.predictor_solution) {
            *d = u - p;
        }
    }

    /// Keeps the initial guess of the next solve aside, so that an evaluation outside the
    /// stepping (a frame, a live view) does not change the trajectory (the corrector shift is
    /// changed only by Heun's corrector).
    pub fn hold_warm_start(&mut self) {
        self.held.copy_from_slice(&self.mean_velocity);
    }

    /// Puts back what [`Self::hold_warm_start`] kept.
    pub fn release_warm_start(&mut self) {
        self.mean_velocity.copy_from_slice(&self.held);
    }

    /// [`Self::prepare`], then [`Self::solve_prepared`].
    pub fn solve(&mut self, pb: &FrictionProblem) -> Result<SolveStats, SolveError> {
        self.prepare(pb.weight, pb.xi_s, pb.xi_c);
        self.solve_prepared(pb.force, pb.tolerance, pb.max_iterations)
    }

    /// Sets up the operator C for n, ξ_s and ξ_c (unless it is the one last set up): N, the
    /// mobility and the multigrid hierarchy. It needs n but not the forces, so the monolayer
    /// runs it beside the per-cell force stage.
    pub fn prepare(&mut self, weight: &[f64], xi_s: &[f64], xi_c: f64) {
        if self.built_xi_c == Some(xi_c) && self.built_n == weight && self.built_xi_s == xi_s {
            return;
        }
        neighbour_sum8(weight, &mut self.weight_nb, self.l);
        for ((mob, &xs), &nb) in self.mobility.iter_mut().zip(xi_s).zip(&self.weight_nb) {
            *mob = 1.0 / (xs + xi_c * nb);
        }
        self.mg.setup(weight, &self.weight_nb, xi_s, xi_c);
        self.built_n.clear();
        self.built_n.extend_from_slice(weight);
        self.built_xi_s.clear();
        self.built_xi_s.extend_from_slice(xi_s);
        self.built_xi_c = Some(xi_c);
    }

    /// Solves C u = F for the operator last prepared, then the pull ξ_c S; `self.mean_velocity`
    /// on entry is the initial guess.
    pub fn solve_prepared(
        &mut self,
        force: &[C64],
        tolerance: f64,
        max_iterations: usize,
    ) -> Result<SolveStats, SolveError> {
        let xi_c = self.built_xi_c.expect("FrictionSolver::prepare runs before a solve");
        let stats = self.pcg(force, tolerance, max_iterations);
        self.pull_from_solution(xi_c);
        stats
    }

    /// Both components' CG, side by side: each loads its part of F and of the initial guess,
    /// and stops at ‖F_c − C u_c‖ ≤ tolerance·‖F‖/√2.
    fn pcg(&mut self, force: &[C64], tolerance: f64, max_iterations: usize) -> Result<SolveStats, SolveError> {
        let (mg, u) = (&self.mg, &self.mean_velocity);
        let [cx, cy] = &mut self.components;
        let run = |c: &mut Component, imaginary: bool| {
            // Each part a closure of its own, so that the loading loop is compiled for it (a
            // function pointer was an indirect call per site: 5 % of a step).
            let diag = mg.diagonal();
            let b_norm =
                if imaginary { c.load(force, u, diag, |z| z.im) } else { c.load(force, u, diag, |z| z.re) }.sqrt();
            let outcome = if b_norm == 0.0 {
                c.x.fill(0.0);
                Outcome { iterations: 0, residual_sq: 0.0, failure: None }
            } else if !b_norm.is_finite() {
                Outcome { iterations: 0, residual_sq: f64::NAN, failure: Some(": the force density is not finite") }
            } else {
                c.pcg(mg, tolerance * b_norm / std::f64::consts::SQRT_2, max_iterations)
            };
            (outcome, b_norm)
        };
        let ((ox, b_norm), (oy, _)) = par::join(|| run(cx, false), || run(cy, true));
        let iterations = ox.iterations.max(oy.iterations);
        let residual = if b_norm == 0.0 { 0.0 } else { (ox.residual_sq + oy.residual_sq).sqrt() / b_norm };
        match ox.failure.or(oy.failure) {
            None => Ok(SolveStats { iterations, residual }),
            Some(detail) => Err(SolveError { iterations, residual, tolerance, detail }),
        }
    }

    /// u from the two components, and the pull ξ_c S with S = Σ_{N8} V, V = n u, in one pass
    /// split into row bands. Each band forms V row by row as S first needs it, in a ring of three
    /// rows, so V is never stored whole (the same bits as storing it).
    fn pull_from_solution(&mut self, xi_c: f64) {
        let l = self.l;
        let (n, [cx, cy]) = (&self.built_n, &self.components);
        let velocity_row = |y: usize, out: &mut [C64]| {
            let (ux, uy, n) = (&cx.x[y * l..][..l], &cy.x[y * l..][..l], &n[y * l..][..l]);
            for (v, ((&ux, &uy), &n)) in out.iter_mut().zip(ux.iter().zip(uy).zip(n)) {
                *v = C64::new(ux, uy) * n;
            }
        };
        let rows = par::band_rows(l);
        par::for_each_chunk_pair_mut(&mut self.mean_velocity, &mut self.pull, rows * l, |band, u, pull| {
            let y0 = band * rows;
            let mut ring = vec![ZERO; 3 * l];
            let slot = |y: usize| (y % 3) * l..(y % 3 + 1) * l;
            // Rows y − 1 and y of V, as y + l − 1 and y + l, so that no index goes below zero.
            velocity_row((y0 + l - 1) % l, &mut ring[slot(y0 + l - 1)]);
            velocity_row(y0, &mut ring[slot(y0 + l)]);
            for (k, (u, pull)) in u.chunks_mut(l).zip(pull.chunks_mut(l)).enumerate() {
                let y = y0 + k;
                velocity_row((y + 1) % l, &mut ring[slot(y + l + 1)]);
                let row = |y: usize| &ring[slot(y)];
                neighbour_sum8_row([row(y + l - 1), row(y + l), row(y + l + 1)], pull);
                for (p, (u, (&ux, &uy))) in
                    pull.iter_mut().zip(u.iter_mut().zip(cx.x[y * l..][..l].iter().zip(&cy.x[y * l..][..l])))
                {
                    *p *= xi_c;
                    *u = C64::new(ux, uy);
                }
            }
        });
    }

    /// ‖F − C u‖/‖F‖ of the current solution for the problem last solved (for tests).
    pub fn relative_residual(&mut self) -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for c in &mut self.components {
            self.mg.apply(&c.x, &mut c.q, &mut c.column);
            num += c.rhs.iter().zip(&c.q).map(|(b, q)| (b - q).powi(2)).sum::<f64>();
            den += dot(&c.rhs, &c.rhs);
        }
        (num / den).sqrt()
    }
}

/// How one component's CG ended.
struct Outcome {
    iterations: usize,
    /// ‖F_c − C u_c‖².
    residual_sq: f64,
    /// Why it stopped short of the target, if it did.
    failure: Option<&'static str>,
}

/// Right-hand side, solution and CG vectors of one velocity component.
#[derive(Clone, Debug)]
struct Component {
    rhs: Vec<f64>,
    /// The solution; on entry to [`Component::pcg`], the initial guess.
    x: Vec<f64>,
    r: Vec<f64>,
    p: Vec<f64>,
    q: Vec<f64>,
    /// One row of work space for C's product.
    column: Vec<f64>,
    work: CycleWork,
}

impl Component {
    fn new(l: usize, mg: &Multigrid) -> Self {
        let v = || vec![0.0; l * l];
        Component { rhs: v(), x: v(), r: v(), p: v(), q: v(), column: vec![0.0; l], work: mg.work() }
    }

    /// rhs = part(F) and x = part(u) on the sites in the solve, 0 elsewhere; returns ‖F‖² over
    /// those sites, both parts (each component computes it, so that neither waits for the
    /// other: the same sum in the same order in both, the same bits).
    #[inline(always)]
    fn load(&mut self, force: &[C64], u: &[C64], diag: &[f64], part: impl Fn(C64) -> f64) -> f64 {
        // One pass, in blocks of the sum's lanes: site k adds to lane k mod LANES, as
        // `sum_pairs` does, so the norm has its bits; each site's values are selected, not
        // branched on, so that the block runs in SIMD lanes.
        let site = |rhs: &mut f64, sol: &mut f64, f: C64, guess: C64, d: f64| {
            let inside = d > 0.0;
            *rhs = if inside { part(f) } else { 0.0 };
            *sol = if inside { part(guess) } else { 0.0 };
            if inside {
                f.norm_sqr()
            } else {
                0.0
            }
        };
        let mut acc = [0.0; LANES];
        let n = diag.len();
        let whole = n - n % LANES;
        let (rhs, x) = (&mut self.rhs[..n], &mut self.x[..n]);
        let blocks = rhs[..whole].chunks_exact_mut(LANES).zip(x[..whole].chunks_exact_mut(LANES));
        let inputs =
            force[..whole].chunks_exact(LANES).zip(u[..whole].chunks_exact(LANES)).zip(diag.chunks_exact(LANES));
        for ((rhs, x), ((f, g), d)) in blocks.zip(inputs) {
            for k in 0..LANES {
                acc[k] += site(&mut rhs[k], &mut x[k], f[k], g[k], d[k]);
            }
        }
        let tail = (rhs[whole..].iter_mut().zip(&mut x[whole..]))
            .zip(force[whole..n].iter().zip(&u[whole..n]).zip(&diag[whole..]));
        for (acc, ((rhs, x), ((&f, &g), &d))) in acc.iter_mut().zip(tail) {
            *acc += site(rhs, x, f, g, d);
        }
        combine(acc)
    }

    /// Conjugate gradients on C x = rhs, preconditioned by one multigrid cycle, until
    /// ‖rhs − C x‖ ≤ target. The step x += α p is taken in the pass that next updates p (or at
    /// the end), which reads p anyway: one pass over the vectors fewer per iteration.
    fn pcg(&mut self, mg: &Multigrid, target: f64, max_iterations: usize) -> Outcome {
        let target_sq = target * target;
        let done = |iterations, residual_sq, failure| Outcome { iterations, residual_sq, failure };
        mg.apply(&self.x, &mut self.q, &mut self.column);
        self.r.copy_from_slice(&self.rhs);
        let mut rr = subtract_scaled(&mut self.r, self.work.residual_mut(), &self.q, 1.0);
        if rr <= target_sq {
            return done(0, rr, None);
        }
        let mut rz = mg.precondition(&mut self.work);
        for (p, z) in self.p.iter_mut().zip(self.work.preconditioned()) {
            *p = *z as f64;
        }
        for it in 1..=max_iterations {
            let alpha = rz / mg.apply(&self.p, &mut self.q, &mut self.column);
            if !alpha.is_finite() {
                return done(it, rr, Some(": breakdown (non-finite step)"));
            }
            rr = subtract_scaled(&mut self.r, self.work.residual_mut(), &self.q, alpha);
            if rr <= target_sq {
                for (x, p) in self.x.iter_mut().zip(&self.p) {
                    *x += p * alpha;
                }
                return done(it, rr, None);
            }
            let rz_new = mg.precondition(&mut self.work);
            let beta = rz_new / rz;
            rz = rz_new;
            for ((x, p), z) in self.x.iter_mut().zip(self.p.iter_mut()).zip(self.work.preconditioned()) {
                *x += *p * alpha;
                *p = *z as f64 + *p * beta;
            }
        }
        done(max_iterations, rr, Some(""))
    }
}

/// r ← r − α q, and r in the cycle's precision, in one pass; returns ‖r‖² (summed in the
/// lanes of `sum`).
#[inline]
fn subtract_scaled(r: &mut [f64], r_cycle: &mut [Real], q: &[f64], alpha: f64) -> f64 {
    let mut acc = [0.0; LANES];
    let whole = r.len() - r.len() % LANES;
    let (r_whole, r_tail) = r.split_at_mut(whole);
    let (rc_whole, rc_tail) = r_cycle.split_at_mut(whole);
    let (q_whole, q_tail) = q.split_at(whole);
    let lanes = r_whole.chunks_exact_mut(LANES).zip(rc_whole.chunks_exact_mut(LANES)).zip(q_whole.chunks_exact(LANES));
    for ((r, rc), q) in lanes {
        for k in 0..LANES {
            r[k] -= q[k] * alpha;
            acc[k] += r[k] * r[k];
            rc[k] = r[k] as Real;
        }
    }
    for (k, ((r, rc), q)) in r_tail.iter_mut().zip(rc_tail).zip(q_tail).enumerate() {
        *r -= q * alpha;
        acc[k] += *r * *r;
        *rc = *r as Real;
    }
    combine(acc)
}

/// Σ a·b in site order.
fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(a, b)| a * b).sum()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Loading a component keeps each part on the sites in the solve and 0 elsewhere, and its
    /// ‖F‖² has the bits of the lanes' sum (`sum_pairs`), on a lattice whose site count leaves a
    /// tail after the lanes' blocks (6² = 4·8 + 4) as on one that does not (4²).
    #[test]
    fn loading_masks_the_parts_and_sums_the_norm_in_the_lanes_order() {
        for l in [6, 4] {
            let mg = Multigrid::new(l);
            let mut c = Component::new(l, &mg);
            let k = l * l;
            let force: Vec<C64> = (0..k).map(|i| C64::new(1.0 / (3.0 + i as f64), 1.1 * (i as f64).sqrt())).collect();
            let u: Vec<C64> = (0..k).map(|i| C64::new(-(i as f64), 0.5 * i as f64)).collect();
            let diag: Vec<f64> = (0..k).map(|i| if i % 3 == 1 { 0.0 } else { 1.0 + i as f64 }).collect();
            let term = |f: C64, d: f64| if d > 0.0 { f.norm_sqr() } else { 0.0 };
            let norm = c.load(&force, &u, &diag, |z| z.im);
            let expected = crate::model::sum::sum_pairs(&force, &diag, term);
            assert_eq!(norm.to_bits(), expected.to_bits(), "l = {l}");
            // The fixture tells orders apart: summed one term after another it rounds otherwise.
            let sequential = force.iter().zip(&diag).fold(0.0, |s, (&f, &d)| s + term(f, d));
            assert_ne!(norm.to_bits(), sequential.to_bits(), "l = {l}: pick terms that round");
            for i in 0..k {
                let (rhs, x) = if diag[i] > 0.0 { (force[i].im, u[i].im) } else { (0.0, 0.0) };
                assert_eq!((c.rhs[i], c.x[i]), (rhs, x), "l = {l}, site {i}");
            }
        }
    }

    fn problem_fields(l: usize, with_hole: bool) -> (Vec<f64>, Vec<C64>) {
        let mut n = vec![1.0; l * l];
        let mut f = vec![ZERO; l * l];
        for y in 0..l {
            for x in 0..l {
                let (xf, yf) = (x as f64 / l as f64, y as f64 / l as f64);
                let i = y * l + x;
                f[i] = C64::new(
                    (2.0 * std::f64::consts::PI * yf).sin() + 0.3 * (6.0 * std::f64::consts::PI * xf).cos(),
                    (4.0 * std::f64::consts::PI * xf).sin(),
                );
                if with_hole {
                    let d2 = (x as f64 - 10.0).powi(2) + (y as f64 - 12.0).powi(2);
                    n[i] = if d2 < 16.0 { 0.0 } else { (0.6 + 0.5 * (0.7 * x as f64).sin().abs()).min(1.1) };
                    f[i] *= n[i];
                }
            }
        }
        (n, f)
    }

    #[test]
    fn residual_below_tolerance_with_holes_and_low_friction() {
        let l = 40;
        let (n, f) = problem_fields(l, true);
        let xi_s = vec![0.001; l * l];
        let mut s = FrictionSolver::new(l);
        let pb =
            FrictionProblem { weight: &n, force: &f, xi_s: &xi_s, xi_c: 1.0, tolerance: 1e-10, max_iterations: 500 };
        let st = s.solve(&pb).unwrap();
        assert!(st.residual <= 1e-10);
        assert!(s.relative_residual() <= 1e-9);
        // The warm start makes the same solve free.
        let st2 = s.solve(&pb).unwrap();
        assert!(st2.iterations <= 1, "{st2:?}");
        // Sites with no cell carry no velocity.
        assert_eq!(s.mean_velocity[12 * l + 10], ZERO);
        // V = n u solves the original (unsymmetrised) balance [ξ_s + ξ_c N] V − ξ_c n S = F
        // (ξ_c = 1 here, so the pull is S).
        for x in 0..l * l {
            let v = s.mean_velocity[x] * n[x];
            let lhs = v * (xi_s[x] + s.weight_nb[x]) - s.pull[x] * n[x];
            assert!((lhs - f[x]).norm() < 1e-7, "site {x}: {lhs} vs {}", f[x]);
        }
    }

    /// Every present cell counted makes n 2–3 along cell edges. The multigrid preconditioner
    /// solves such a tissue with a hole at χ = 0.001 from a cold start in few iterations (the
    /// diagonally scaled FFT preconditioner it replaced needed 71 per warm-started solve at full
    /// size); the count is deterministic (13 here; 18 with a V-cycle instead of the W-cycle, 17
    /// without the over-correction), so this guards the preconditioner's quality.
    #[test]
    fn multigrid_converges_quickly_on_edge_networks() {
        let l = 70;
        let (_, f) = problem_fields(l, false);
        let n = crate::model::multigrid::fixtures::edge_network(l);
        let f: Vec<C64> = f.iter().zip(&n).map(|(f, n)| f * n).collect();
        let xi_s = vec![0.001; l * l];
        let mut s = FrictionSolver::new(l);
        let pb =
            FrictionProblem { weight: &n, force: &f, xi_s: &xi_s, xi_c: 1.0, tolerance: 1e-5, max_iterations: 500 };
        let st = s.solve(&pb).unwrap();
        assert!(st.iterations <= 15, "{st:?}");
    }

    fn problem<'a>(n: &'a [f64], f: &'a [C64], xi_s: &'a [f64], xi_c: f64) -> FrictionProblem<'a> {
        FrictionProblem { weight: n, force: f, xi_s, xi_c, tolerance: 1e-8, max_iterations: 500 }
    }

    #[test]
    fn a_changed_operator_is_set_up_again() {
        // The solver skips the setup when n, ξ_s and ξ_c are those of its last solve; any change
        // must rebuild, so that a reused solver agrees bit for bit with a fresh one.
        let l = 24;
        let (n1, f) = problem_fields(l, true);
        let n2: Vec<f64> = n1.iter().enumerate().map(|(x, n)| if x % 7 == 0 { n * 1.5 } else { *n }).collect();
        let (xi_a, xi_b) = (vec![0.001; l * l], vec![0.01; l * l]);
        let mut reused = FrictionSolver::new(l);
        reused.solve(&problem(&n1, &f, &xi_a, 1.0)).unwrap();
        // n, then ξ_s, then ξ_c changes; the last solve repeats the one before it, so the
        // hierarchy is reused there.
        let changes = [(&n2, &xi_a, 1.0), (&n2, &xi_b, 1.0), (&n2, &xi_b, 0.5), (&n2, &xi_b, 0.5)];
        for (n, xi_s, xi_c) in changes {
            let pb = problem(n, &f, xi_s, xi_c);
            reused.reset();
            let a = reused.solve(&pb).unwrap();
            let mut fresh = FrictionSolver::new(l);
            let b = fresh.solve(&pb).unwrap();
            assert_eq!(a, b);
            let bits = |v: &[C64]| v.iter().flat_map(|z| [z.re.to_bits(), z.im.to_bits()]).collect::<Vec<_>>();
            assert_eq!(bits(&reused.mean_velocity), bits(&fresh.mean_velocity));
            assert_eq!(bits(&reused.pull), bits(&fresh.pull));
        }
    }

    /// Subdomain weights: n(x) = the number of rectangular patches (wrapping at the edges) that
    /// cover x, 0 to 4 here, with an uncovered stretch (a hole no patch reaches).
    fn subdomain_counts(l: usize) -> Vec<f64> {
        let patches = [(3, 5, 24, 20), (20, 2, 22, 26), (30, 18, 19, 25), (8, 22, 26, 14), (33, 30, 16, 16)];
        let mut n = vec![0.0; l * l];
        for &(x0, y0, w, h) in &patches {
            for b in 0..h {
                for a in 0..w {
                    n[((y0 + b) % l) * l + (x0 + a) % l] += 1.0;
                }
            }
        }
        n
    }

    /// With subdomain weights C is still a symmetric operator: ⟨a, C b⟩ = ⟨C a, b⟩ for
    /// arbitrary a, b, and positive on the covered sites.
    #[test]
    fn subdomain_operator_is_symmetric_and_positive() {
        let l = 40;
        let n = subdomain_counts(l);
        assert!(n.contains(&0.0) && n.contains(&3.0), "the fixture must have holes and overlaps");
        let mut nn = vec![0.0; l * l];
        neighbour_sum8(&n, &mut nn, l);
        let mut mg = Multigrid::new(l);
        mg.setup(&n, &nn, &vec![0.001; l * l], 1.0);
        let vec_of = |k: f64| -> Vec<f64> {
            (0..l * l).map(|x| if n[x] > 0.0 { (0.37 * k * x as f64).sin() + 0.1 * k } else { 0.0 }).collect()
        };
        let (a, b) = (vec_of(1.0), vec_of(2.3));
        let (mut ca, mut cb, mut col) = (vec![0.0; l * l], vec![0.0; l * l], vec![0.0; l]);
        let a_ca = mg.apply(&a, &mut ca, &mut col);
        mg.apply(&b, &mut cb, &mut col);
        let (x, y) = (dot(&a, &cb), dot(&ca, &b));
        assert!((x - y).abs() <= 1e-12 * x.abs().max(y.abs()), "⟨a, Cb⟩ = {x}, ⟨Ca, b⟩ = {y}");
        assert!(a_ca > 0.0);
    }

    /// A rigid translation passes through the cell–cell friction: if every cell pushes with
    /// f_j = ξ_s u₀ on its whole subdomain (so F = ξ_s n u₀), all cells move with u₀ and the
    /// cell–cell term vanishes; each cell's velocity [f + ξ_c S]/[ξ_s + ξ_c N] is u₀ too.
    #[test]
    fn rigid_translation_passes_through_with_subdomain_weights() {
        let l = 40;
        let n = subdomain_counts(l);
        let (xi_s, u0) = (0.001, C64::new(0.03, -0.02));
        let f: Vec<C64> = n.iter().map(|n| u0 * (xi_s * n)).collect();
        let xis = vec![xi_s; l * l];
        let mut s = FrictionSolver::new(l);
        let pb =
            FrictionProblem { weight: &n, force: &f, xi_s: &xis, xi_c: 1.0, tolerance: 1e-11, max_iterations: 500 };
        s.solve(&pb).unwrap();
        for (x, &nx) in n.iter().enumerate() {
            let expected = if nx > 0.0 { u0 } else { ZERO };
            assert!((s.mean_velocity[x] - expected).norm() < 1e-8, "site {x}: u = {}", s.mean_velocity[x]);
            if nx > 0.0 {
                let v = (u0 * xi_s + s.pull[x]) * s.mobility[x];
                assert!((v - u0).norm() < 1e-8, "site {x}: a cell moves with {v}");
            }
        }
    }
}

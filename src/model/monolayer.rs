//! The monolayer: N cells on the periodic lattice, stepped by Heun's predictor–corrector through
//! the paper's protocol (relaxation, then activity with cell–cell friction).
//!
//! One evaluation of the right-hand side R(φ) runs these stages (see [`crate::model::counters`]):
//! 1. gather Σ_j φ_j² onto the lattice (for the repulsion term), and n = Σ_j w_j (the friction
//!    weights);
//! 2. per cell: A_i and μ_i ([`crate::model::free_energy`]), then Q_i, Q̂_i ([`crate::model::shape`]) and f_i
//!    ([`crate::model::forces`]); beside them, on one thread, the friction operator is set up
//!    for n (it does not need the forces);
//! 3. gather F = Σ_j w_j f_j, and the friction solve for V ([`crate::model::friction`]) — both
//!    active phase only;
//! 4. per cell: v_i and ∂_t φ_i ([`crate::model::motion`]), then the cell's Heun update.
//!
//! A step is φ* = φ + Δt R(φ), φ' = φ + ½Δt [R(φ) + R(φ*)], then the patches follow the cells.
//! The per-cell stages of 2 and of 4 run cell by cell in one parallel loop each, so that a patch
//! is still in cache for its second stage (9 % fewer last-level misses per step than stage by
//! stage) and the threads meet twice per evaluation instead of four times; the counters still
//! time every stage ([`Counters::time_laps`]).

use std::ops::Range;

use multiversion::multiversion;
use num_complex::Complex64 as C64;

use crate::model::cell::Cell;
use crate::model::counters::{Counters, Laps, Stage};
use crate::model::error::SimError;
use crate::model::forces::force_density;
use crate::model::free_energy::{area, FreeEnergy};
use crate::model::friction::{FrictionSolver, SolveStats};
use crate::model::hash::{fnv1a_continue, FNV1A_START};
use crate::model::init::random_disks;
use crate::model::lattice::{wrap, Patch};
use crate::model::motion::{friction_weight, velocity_and_rate, Drag, MotionFields};
use crate::model::par;
use crate::model::params::{FrictionWeights, Params};
use crate::model::precision::{load, Real, Store};
use crate::model::shape::{normalise, shape_tensor};

const ZERO: C64 = C64 { re: 0.0, im: 0.0 };

/// Which part of the protocol a step belongs to.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Phase {
    /// ζ = 0, ξ_cell = 0, v = f/ξ_relax, square patches of fixed size.
    Relaxation,
    /// Activity ζ, friction ξ_s and ξ_cell, adaptive patches.
    Active,
}

impl Phase {
    /// ζ and ξ_cell as this phase has them: the relaxation has neither activity nor cell–cell
    /// friction. Both engines read them here.
    pub(crate) fn zeta_and_xi_cell(self, p: &Params) -> (f64, f64) {
        match self {
            Phase::Active => (p.zeta, p.xi_cell),
            Phase::Relaxation => (0.0, 0.0),
        }
    }
}

/// Fields on the whole L×L lattice, row-major (index y·L + x).
#[derive(Clone, Debug)]
pub struct LatticeFields {
    /// Σ_j φ_j².
    pub sum_phi2: Vec<f64>,
    /// n(x) = Σ_j w_j(x), the friction weights.
    pub weight: Vec<f64>,
    /// F(x) = Σ_j w_j f_j.
    pub force: Vec<C64>,
    /// 1/ξ_s(x) (active, without cell–cell friction) or 1/ξ_relax (relaxation); with cell–cell
    /// friction the solver's [`FrictionSolver::mobility`] takes its place.
    pub mobility: Vec<f64>,
    /// Zero, never written: the pull without cell–cell friction (with it, [`FrictionSolver::pull`]).
    pub pull: Vec<C64>,
    /// Per-site multiplier of ξ_s (soft < 1 < stiff substrate); 1 everywhere by default.
    pub substrate: Vec<f64>,
    /// ξ_s(x) = xi_substrate × substrate(x).
    pub xi_s: Vec<f64>,
    /// Σ_i φ_i, filled on request.
    pub phi_sum: Vec<f64>,
    /// Σ_i φ_i v_i (Eq. S4), filled on request.
    pub velocity: Vec<C64>,
}

impl LatticeFields {
    fn new(l: usize) -> Self {
        let n = l * l;
        LatticeFields {
            sum_phi2: vec![0.0; n],
            weight: vec![0.0; n],
            force: vec![ZERO; n],
            mobility: vec![0.0; n],
            pull: vec![ZERO; n],
            substrate: vec![1.0; n],
            xi_s: vec![0.0; n],
            phi_sum: vec![0.0; n],
            velocity: vec![ZERO; n],
        }
    }
}

/// What an evaluation does to each cell once its rate R(φ) is known.
#[derive(Clone, Copy, Debug)]
enum Then {
    /// Nothing (an evaluation outside the stepping).
    Nothing,
    /// Heun's predictor: keep φ_n and R(φ_n), then φ* = φ_n + Δt R(φ_n).
    Predict { dt: f64 },
    /// Heun's corrector, φ' = φ_n + ½Δt [R(φ_n) + R(φ*)], then the check that φ' is in
    /// [lo, hi].
    Correct { dt: f64, lo: f64, hi: f64 },
}

impl Then {
    fn apply(self, c: &mut Cell) {
        match self {
            Then::Nothing => {}
            Then::Predict { dt } => {
                // φ_n and R(φ_n) are kept by swapping buffers, not copying them; the stale
                // buffers left in φ and R are overwritten whole, φ here and R by the
                // corrector's evaluation (its padding stays zero in both).
                std::mem::swap(&mut c.phi0, &mut c.phi);
                std::mem::swap(&mut c.k1, &mut c.rate);
                predict(&mut c.phi, &c.phi0, &c.k1, dt);
            }
            Then::Correct { dt, lo, hi } => {
                correct(&mut c.phi, &c.phi0, &c.k1, &c.rate, dt);
                c.fault = first_out_of_range(c, lo, hi);
            }
        }
    }
}

/// Heun's predictor, φ* = φ_n + Δt k₁ (compiled also for AVX2, the same bits).
#[multiversion(targets("x86_64+avx2"))]
fn predict(phi: &mut [Store], phi0: &[Store], k1: &[Store], dt: f64) {
    for ((phi, &p0), &k) in phi.iter_mut().zip(phi0).zip(k1) {
        *phi = Store::from_f64(load(p0) + dt * load(k));
    }
}

/// Heun's corrector, φ' = φ_n + ½Δt (k₁ + k₂) (compiled also for AVX2, the same bits).
#[multiversion(targets("x86_64+avx2"))]
fn correct(phi: &mut [Store], phi0: &[Store], k1: &[Store], k2: &[Store], dt: f64) {
    let half = 0.5 * dt;
    for ((phi, &p0), (&k1, &k2)) in phi.iter_mut().zip(phi0).zip(k1.iter().zip(k2)) {
        *phi = Store::from_f64(load(p0) + half * (load(k1) + load(k2)));
    }
}

/// Everything a checkpoint must hold to continue bit for bit.
#[derive(Clone, Debug, PartialEq)]
pub struct State {
    pub step: u64,
    /// Each cell's patch and φ on its padded storage.
    pub cells: Vec<(Patch, Vec<f64>)>,
    /// u = V/n of the last friction solve: the next solve's warm start.
    pub warm_start: Vec<C64>,
    /// u(corrector) − u(predictor) of the last step: added to the next corrector's guess.
    pub corrector_shift: Vec<C64>,
    pub substrate: Vec<f64>,
}

impl State {
    /// Checks each cell's φ as every step leaves it (`check_saved_phi`): a state read from a
    /// file (a checkpoint, a relaxed state) beyond that is damaged. A cell whose φ does not fit
    /// its patch is left to [`Monolayer::from_state`], which refuses it.
    pub fn check(&self, params: &Params) -> Result<(), SimError> {
        let fits = |(patch, phi): &&(Patch, Vec<f64>)| phi.len() == patch.padded_len();
        for (i, (patch, phi)) in self.cells.iter().enumerate().filter(|(_, c)| fits(c)) {
            check_saved_phi(i, patch, phi, params)?;
        }
        Ok(())
    }
}

/// The simulated monolayer.
#[derive(Clone, Debug)]
pub struct Monolayer {
    params: Params,
    seed: u64,
    step: u64,
    cells: Vec<Cell>,
    free_energy: FreeEnergy,
    lattice: LatticeFields,
    solver: FrictionSolver,
    counters: Counters,
    last_solve: SolveStats,
}

/// Σφ² on the lattice, and with `weights` also n = Σ_j w_j, in one walk over the patches. One
/// loop per reading, each with its reading a constant, so that none tests it site by site.
fn lattice_sums(cells: &[Cell], lat: &mut LatticeFields, p: &Params, weights: bool) {
    let (l, threshold) = (p.box_size, p.presence_threshold);
    let (phi2, n) = (&mut lat.sum_phi2, &mut lat.weight);
    let mut with_weights = |kind| {
        gather_pair((phi2, n), (0.0, 0.0), cells, l, |c, r, phi2, n| {
            add_each(phi2, c.phi[r.clone()].iter().map(|&p| load(p) * load(p)));
            add_each(n, c.phi[r].iter().map(|&p| friction_weight(kind, load(p), threshold)));
        })
    };
    match (weights, p.friction_weights) {
        (false, _) => {
            gather(phi2, 0.0, cells, l, |c, r, out| add_each(out, c.phi[r].iter().map(|&p| load(p) * load(p))))
        }
        (true, FrictionWeights::Phi) => with_weights(FrictionWeights::Phi),
        (true, FrictionWeights::Presence) => with_weights(FrictionWeights::Presence),
        (true, FrictionWeights::Subdomain) => with_weights(FrictionWeights::Subdomain),
    }
}

/// Each cell's area, μ, shape, Q̂ and force density, cell by cell in one loop, so that each patch
/// is still in cache for its forces, with ζ and ξ_cell as the phase has them
/// ([`Phase::zeta_and_xi_cell`]). The friction operator needs n but not the forces: with cell–cell
/// friction (ξ_cell > 0) it is set up beside this loop, on one thread while
/// the others take the cells (and takes cells itself once done).
fn cell_forces(
    cells: &mut [Cell],
    lat: &LatticeFields,
    solver: &mut FrictionSolver,
    fe: FreeEnergy,
    p: &Params,
    (zeta, xi_c): (f64, f64),
    laps: &Laps<3>,
) {
    let (l, q_mag, q_eps, passive) = (p.box_size, p.q_magnitude, p.q_epsilon, p.passive_force);
    let sum_phi2 = &lat.sum_phi2;
    let mut per_cell = || {
        par::for_each_mut(cells, |_, c| {
            laps.lap(0, || {
                c.area = area(&c.phi);
                fe.chemical_potential(c.patch, &c.phi, c.area, sum_phi2, l, &mut c.mu);
            });
            laps.lap(1, || {
                c.shape = shape_tensor(c.patch, &c.phi);
                c.q_hat = normalise(c.shape, q_mag, q_eps);
                force_density(c.patch, &c.phi, &c.mu, c.q_hat, zeta, passive, &mut c.fx, &mut c.fy);
            });
        })
    };
    if xi_c > 0.0 {
        let (n, xi_s) = (&lat.weight, &lat.xi_s);
        par::join(|| laps.lap(2, || solver.prepare(n, xi_s, xi_c)), per_cell);
    } else {
        per_cell();
    }
}

/// F = Σ_j w_j f_j on the lattice, the friction solve's right-hand side.
fn force_sum(cells: &[Cell], force: &mut [C64], p: &Params) {
    let (l, weights, threshold) = (p.box_size, p.friction_weights, p.presence_threshold);
    gather(force, ZERO, cells, l, |c, r, out| {
        let (phi, fx, fy) = (&c.phi[r.clone()], &c.fx[r.clone()], &c.fy[r]);
        let sites = phi.iter().zip(fx.iter().zip(fy));
        let add = |kind| {
            add_each(
                out,
                sites.map(|(&p, (&x, &y))| {
                    let w = friction_weight(kind, load(p), threshold);
                    C64::new(w * load(x), w * load(y))
                }),
            )
        };
        match weights {
            FrictionWeights::Phi => add(FrictionWeights::Phi),
            FrictionWeights::Presence => add(FrictionWeights::Presence),
            FrictionWeights::Subdomain => add(FrictionWeights::Subdomain),
        }
    })
}

/// The mobility without cell–cell friction: 1/ξ_s(x) when active, 1/ξ_relax in relaxation.
fn substrate_mobility(lat: &mut LatticeFields, p: &Params, active: bool) {
    if active {
        for (mob, xs) in lat.mobility.iter_mut().zip(&lat.xi_s) {
            *mob = 1.0 / xs;
        }
    } else {
        lat.mobility.fill(1.0 / p.xi_relax);
    }
}

/// Each cell's velocity and rate R(φ), then its `then` (Heun's update) as soon as its rate is
/// known, while its patch is in cache: no cell's update reads another's fields.
fn motion(cells: &mut [Cell], drag: &Drag, p: &Params, then: Then, laps: &Laps<2>) {
    let (l, j0, advection) = (p.box_size, p.j0, p.advection);
    let keep_velocity = !matches!(then, Then::Predict { .. });
    par::for_each_mut(cells, |_, c| {
        laps.lap(0, || {
            let fields = MotionFields {
                phi: &c.phi,
                mu: &c.mu,
                fx: &c.fx,
                fy: &c.fy,
                velocity: keep_velocity.then_some((&mut c.vx, &mut c.vy)),
                rate: &mut c.rate,
            };
            velocity_and_rate(c.patch, fields, drag, l, j0, advection);
        });
        laps.lap(1, || then.apply(c));
    })
}

/// Adds every cell's values onto the lattice array `out`: `add(cell, padded, run)` adds the
/// cell's values at the padded patch sites `padded` onto the lattice run `run` of the same
/// length, which it receives as slices so that its loop runs in SIMD lanes without bounds checks.
/// Each thread owns a band of rows and visits the cells in order, so every site sums in cell
/// order.
fn gather<T>(out: &mut [T], zero: T, cells: &[Cell], l: usize, add: impl Fn(&Cell, Range<usize>, &mut [T]) + Sync)
where
    T: Copy + Send + Sync,
{
    let rows = par::band_rows(l);
    par::for_each_chunk_mut(out, rows * l, |band, chunk| {
        chunk.fill(zero);
        for_each_run(cells, band * rows, chunk.len() / l, l, |cell, padded, run| add(cell, padded, &mut chunk[run]));
    });
}

/// [`gather`] onto two lattice arrays in one walk over the patches.
fn gather_pair<A, B>(
    (a, b): (&mut [A], &mut [B]),
    (zero_a, zero_b): (A, B),
    cells: &[Cell],
    l: usize,
    add: impl Fn(&Cell, Range<usize>, &mut [A], &mut [B]) + Sync,
) where
    A: Copy + Send + Sync,
    B: Copy + Send + Sync,
{
    let rows = par::band_rows(l);
    par::for_each_chunk_pair_mut(a, b, rows * l, |band, a, b| {
        a.fill(zero_a);
        b.fill(zero_b);
        for_each_run(cells, band * rows, a.len() / l, l, |cell, padded, run| {
            add(cell, padded, &mut a[run.clone()], &mut b[run])
        });
    });
}

/// Calls `visit(cell, padded, run)` for every run of every cell's patch within the `rows` lattice
/// rows from `y0`, cell by cell in order: `padded` indexes the cell's padded storage, `run` the
/// band (of `rows` rows from y0).
fn for_each_run(
    cells: &[Cell],
    y0: usize,
    rows: usize,
    l: usize,
    mut visit: impl FnMut(&Cell, Range<usize>, Range<usize>),
) {
    for cell in cells {
        let p = cell.patch;
        for gy in y0..y0 + rows {
            let Some(b) = p.row_of(gy, l) else { continue };
            for run in p.row_runs(b, l).into_iter().flatten() {
                let start = (gy - y0) * l + run.global % l;
                visit(cell, run.padded..run.padded + run.len, start..start + run.len);
            }
        }
    }
}

/// `out += value` site by site over a run.
#[inline(always)]
fn add_each<T: Copy + std::ops::AddAssign>(out: &mut [T], values: impl Iterator<Item = T>) {
    for (o, v) in out.iter_mut().zip(values) {
        *o += v;
    }
}

impl Monolayer {
    /// The protocol's start: random disks of radius R/2, seeded. Invalid parameters are
    /// refused by name:
    ///
    /// ```
    /// use monolayer::{Monolayer, Params};
    ///
    /// let p = Params { box_size: 40, n_cells: 8, ..Params::default() };
    /// let m = Monolayer::new(p.clone(), 7)?;
    /// assert_eq!(m.step_count(), 0);
    /// // The same seed, the same bits.
    /// assert_eq!(m.fingerprint(), Monolayer::new(p.clone(), 7)?.fingerprint());
    /// let err = Monolayer::new(Params { n_cells: 0, ..p }, 7).err().unwrap();
    /// assert!(err.to_string().contains("n_cells"));
    /// # Ok::<(), monolayer::SimError>(())
    /// ```
    pub fn new(params: Params, seed: u64) -> Result<Self, SimError> {
        params.validate()?;
        let cells = random_disks(&params, seed)?;
        Ok(Self::with_cells(params, seed, cells, 0))
    }

    fn with_cells(params: Params, seed: u64, cells: Vec<Cell>, step: u64) -> Self {
        let l = params.box_size;
        let mut m = Monolayer {
            free_energy: FreeEnergy::new(&params),
            lattice: LatticeFields::new(l),
            solver: FrictionSolver::new(l),
            counters: Counters::default(),
            last_solve: SolveStats::default(),
            params,
            seed,
            step,
            cells,
        };
        m.update_substrate();
        m
    }

    /// Continues from a checkpointed state.
    pub fn from_state(params: Params, seed: u64, state: State) -> Result<Self, SimError> {
        params.validate()?;
        let l = params.box_size;
        if state.cells.len() != params.n_cells {
            return Err(SimError::Invalid(format!(
                "checkpoint has {} cells, parameters say n_cells = {}",
                state.cells.len(),
                params.n_cells
            )));
        }
        if [&state.warm_start, &state.corrector_shift].iter().any(|v| v.len() != l * l)
            || state.substrate.len() != l * l
        {
            return Err(SimError::Invalid(format!("checkpoint lattice is not {l}×{l}")));
        }
        let mut cells = Vec::with_capacity(state.cells.len());
        for (i, (patch, phi)) in state.cells.into_iter().enumerate() {
            let ok = patch.x0 < l && patch.y0 < l && patch.w < l && patch.h < l && phi.len() == patch.padded_len();
            if !ok {
                return Err(SimError::Invalid(format!("checkpoint cell {i}: patch {patch:?} does not fit the box")));
            }
            cells.push(Cell::new(patch, phi));
        }
        let mut m = Self::with_cells(params, seed, cells, state.step);
        m.lattice.substrate = state.substrate;
        m.update_substrate();
        m.solver.mean_velocity = state.warm_start;
        m.solver.corrector_shift = state.corrector_shift;
        Ok(m)
    }

    /// [`Monolayer::from_state`] of a state read from a file (a checkpoint, a relaxed state),
    /// checked first as every step leaves one ([`State::check`]): stepped, a damaged state
    /// would fail as if the run had gone unstable, or go on along another trajectory unsaid.
    pub fn from_saved(params: Params, seed: u64, state: State) -> Result<Self, SimError> {
        state.check(&params)?;
        Self::from_state(params, seed, state)
    }

    /// A copy of everything needed to continue bit for bit.
    pub fn state(&self) -> State {
        State {
            step: self.step,
            cells: self.cells.iter().map(|c| (c.patch, c.phi.iter().map(|&v| load(v)).collect())).collect(),
            warm_start: self.solver.mean_velocity.clone(),
            corrector_shift: self.solver.corrector_shift.clone(),
            substrate: self.lattice.substrate.clone(),
        }
    }

    pub fn params(&self) -> &Params {
        &self.params
    }

    pub fn seed(&self) -> u64 {
        self.seed
    }

    /// Steps taken since the random disks (relaxation included).
    pub fn step_count(&self) -> u64 {
        self.step
    }

    /// Phase of the next step.
    pub fn phase(&self) -> Phase {
        if self.step < self.params.relax_steps {
            Phase::Relaxation
        } else {
            Phase::Active
        }
    }

    pub fn cells(&self) -> &[Cell] {
        &self.cells
    }

    /// u = V/n of the last friction solve, the next solve's initial guess (zero before the
    /// first; `State::warm_start` without the copy).
    pub fn warm_start(&self) -> &[C64] {
        &self.solver.mean_velocity
    }

    pub fn lattice(&self) -> &LatticeFields {
        &self.lattice
    }

    pub fn counters(&self) -> &Counters {
        &self.counters
    }

    pub fn counters_mut(&mut self) -> &mut Counters {
        &mut self.counters
    }

    /// Iterations and residual of the last friction solve.
    pub fn last_solve(&self) -> SolveStats {
        self.last_solve
    }

    /// Changes parameters between steps. The lattice size and the number of cells are fixed.
    pub fn set_params(&mut self, params: Params) -> Result<(), SimError> {
        params.validate()?;
        if params.box_size != self.params.box_size || params.n_cells != self.params.n_cells {
            return Err(SimError::Invalid(
                "box_size and n_cells cannot change in a running simulation: start a new one".into(),
            ));
        }
        self.free_energy = FreeEnergy::new(&params);
        self.params = params;
        self.update_substrate();
        Ok(())
    }

    /// Sets the per-site multiplier of ξ_s (L² values, each finite and > 0).
    pub fn set_substrate(&mut self, map: &[f64]) -> Result<(), SimError> {
        let l = self.params.box_size;
        if map.len() != l * l {
            return Err(SimError::Invalid(format!("substrate map has {} values, the lattice {}", map.len(), l * l)));
        }
        if let Some((i, v)) = map.iter().enumerate().find(|(_, v)| !(v.is_finite() && **v > 0.0)) {
            return Err(SimError::Invalid(format!(
                "substrate map at site ({}, {}) = {v}: must be finite and > 0",
                i % l,
                i / l
            )));
        }
        self.lattice.substrate.copy_from_slice(map);
        self.update_substrate();
        Ok(())
    }

    fn update_substrate(&mut self) {
        let xi = self.params.xi_substrate;
        for (x, m) in self.lattice.xi_s.iter_mut().zip(&self.lattice.substrate) {
            *x = xi * m;
        }
    }

    /// A 64-bit FNV-1a hash of the step and of every bit of every φ_i with its patch: two
    /// simulations agree bit for bit exactly when their fingerprints do (up to hash collisions).
    /// Used to compare the WebAssembly core with the native one.
    pub fn fingerprint(&self) -> u64 {
        let mut h = FNV1A_START;
        let mut eat = |v: u64| h = fnv1a_continue(h, &v.to_le_bytes());
        eat(self.step);
        for c in &self.cells {
            let p = c.patch;
            for v in [p.x0, p.y0, p.w, p.h] {
                eat(v as u64);
            }
            for &v in &c.phi {
                eat(load(v).to_bits());
            }
        }
        h
    }

    /// Σ_i φ_i on the lattice.
    pub fn phi_sum(&mut self) -> &[f64] {
        let l = self.params.box_size;
        gather(&mut self.lattice.phi_sum, 0.0, &self.cells, l, |c, r, out| {
            add_each(out, c.phi[r].iter().map(|&p| load(p)))
        });
        &self.lattice.phi_sum
    }

    /// The coarse-grained velocity Σ_i φ_i v_i (Eq. S4) as of the last evaluation.
    pub fn velocity_field(&mut self) -> &[C64] {
        let l = self.params.box_size;
        gather(&mut self.lattice.velocity, ZERO, &self.cells, l, |c, r, out| {
            let (phi, vx, vy) = (&c.phi[r.clone()], &c.vx[r.clone()], &c.vy[r]);
            let sites = phi.iter().zip(vx.iter().zip(vy));
            add_each(out, sites.map(|(&p, (&x, &y))| C64::new(load(p) * load(x), load(p) * load(y))));
        });
        &self.lattice.velocity
    }

    /// Evaluates forces and velocities for the current φ without stepping (fills every
    /// per-cell field and the lattice fields). The trajectory is the same with or without it.
    pub fn evaluate_now(&mut self) -> Result<(), SimError> {
        self.solver.hold_warm_start();
        let r = self.evaluate(self.phase(), Then::Nothing);
        self.solver.release_warm_start();
        r
    }

    /// Runs `n` steps, stopping at the first error.
    pub fn advance(&mut self, n: u64) -> Result<(), SimError> {
        for _ in 0..n {
            self.step()?;
        }
        Ok(())
    }

    /// One Heun step of the protocol.
    pub fn step(&mut self) -> Result<(), SimError> {
        let phase = self.phase();
        self.heun(phase)?;
        self.step += 1;
        self.counters.steps += 1;
        let mut counters = std::mem::take(&mut self.counters);
        let r = counters.time(Stage::Patches, || self.update_patches(phase));
        self.counters = counters;
        if r.is_err() {
            // No patch has moved yet: the state is put back to the start of the step, which the
            // error names, so that what is saved as the last good state is a state the
            // simulation passed through. (The friction solver's warm start, a first guess, is
            // the failed step's.)
            self.restore();
            self.step -= 1;
            self.counters.steps -= 1;
        }
        r
    }

    /// Heun's predictor and corrector with the range check, on the patches as they are: the
    /// part of [`Monolayer::step`] before the patches follow the cells. On an error every φ is
    /// back at the start of the step.
    fn heun(&mut self, phase: Phase) -> Result<(), SimError> {
        let dt = self.params.dt;
        let (lo, hi) = (self.params.phi_min, self.params.phi_max);
        self.evaluate(phase, Then::Predict { dt })?;
        if let Err(e) = self.evaluate(phase, Then::Correct { dt, lo, hi }) {
            self.restore();
            return Err(e);
        }
        if let Some((i, (a, b, v))) = self.cells.iter().enumerate().find_map(|(i, c)| c.fault.map(|f| (i, f))) {
            let l = self.params.box_size;
            let (x, y) = self.cells[i].patch.global_xy(a, b, l);
            self.restore();
            return Err(SimError::Unstable {
                step: self.step,
                cell: i,
                x,
                y,
                quantity: "phi",
                value: v,
                min: lo,
                max: hi,
            });
        }
        Ok(())
    }

    /// A test hook, not part of the protocol: one Heun step (predictor, corrector, range check)
    /// exactly as [`Monolayer::step`] takes it, but with the patches left where they are and the
    /// step count unchanged. The GPU stepper's patches do not move yet; this is the CPU step to
    /// compare it with (tests/gpu.rs). The state it leaves is one `step` never reaches.
    #[doc(hidden)]
    pub fn step_on_fixed_patches(&mut self) -> Result<(), SimError> {
        let phase = self.phase();
        self.heun(phase)
    }

    /// Puts every φ back to the start of the failed step.
    fn restore(&mut self) {
        par::for_each_mut(&mut self.cells, |_, c| c.phi.copy_from_slice(&c.phi0));
    }

    /// One evaluation of the rates R(φ) at the current φ, each cell's `then` applied as soon as
    /// its rate is known. The stages in order: the lattice sums, each cell's μ and forces, the
    /// drag (the friction solve, or the substrate's mobility alone), each cell's velocity and rate.
    fn evaluate(&mut self, phase: Phase, then: Then) -> Result<(), SimError> {
        let p = &self.params;
        let active = phase == Phase::Active;
        let (zeta, xi_c) = phase.zeta_and_xi_cell(p);
        let friction = xi_c > 0.0;
        let corrector = matches!(then, Then::Correct { .. });
        let fe = self.free_energy;
        let (counters, cells, lat, solver) = (&mut self.counters, &mut self.cells, &mut self.lattice, &mut self.solver);

        // With subdomain weights n counts the patches over each site, and the patches move only
        // between steps: the corrector keeps the predictor's n.
        let n_is_current = corrector && p.friction_weights == FrictionWeights::Subdomain;
        counters.time(Stage::Gather, || lattice_sums(cells, lat, p, friction && !n_is_current));
        counters.time_laps([Stage::ChemicalPotential, Stage::Forces, Stage::FrictionSolve], |laps| {
            cell_forces(cells, lat, solver, fe, p, (zeta, xi_c), laps)
        });

        let drag = if friction {
            counters.time(Stage::Gather, || force_sum(cells, &mut lat.force, p));
            let (tolerance, max_iterations) = (p.friction_tolerance, p.friction_max_iterations);
            let stats = counters
                .time(Stage::FrictionSolve, || {
                    if corrector {
                        solver.shift_to_corrector();
                    }
                    let stats = solver.solve_prepared(&lat.force, tolerance, max_iterations)?;
                    if corrector {
                        solver.record_corrector_shift();
                    }
                    Ok(stats)
                })
                .map_err(|source| SimError::Friction { step: self.step, source })?;
            counters.solves += 1;
            counters.iterations += stats.iterations as u64;
            counters.max_residual = counters.max_residual.max(stats.residual);
            self.last_solve = stats;
            Drag { mobility: &solver.mobility, pull: &solver.pull }
        } else {
            substrate_mobility(lat, p, active);
            Drag { mobility: &lat.mobility, pull: &lat.pull }
        };

        counters.time_laps([Stage::Velocity, Stage::Update], |laps| motion(cells, &drag, p, then, laps));
        Ok(())
    }

    /// Relaxation: fixed square patches re-centred on each cell. Active: each side sits
    /// `patch_margin` sites beyond the last site with φ > `presence_threshold` (paper Sec. A).
    /// Every cell's new patch is found first; only if each has one do they move, so that on an
    /// error every cell is still on the patch its φ₀ (the start of the step) was stored on.
    fn update_patches(&mut self, phase: Phase) -> Result<(), SimError> {
        let p = &self.params;
        let l = p.box_size;
        let (size, margin, thr) = (p.relax_patch_size, p.patch_margin, p.presence_threshold);
        par::for_each_mut(&mut self.cells, |_, c| {
            c.lost = None;
            let old = c.patch;
            let new = match phase {
                Phase::Relaxation => {
                    let (ca, cb) = c.local_centre();
                    let half = (size / 2) as i64;
                    Patch {
                        x0: wrap(old.x0 as i64 + ca.round() as i64 - half, l),
                        y0: wrap(old.y0 as i64 + cb.round() as i64 - half, l),
                        w: size,
                        h: size,
                    }
                }
                Phase::Active => {
                    let Some((a0, a1, b0, b1)) = c.support(thr) else {
                        c.lost = Some(format!("vanished: no site has φ > {thr}"));
                        return;
                    };
                    let (w, h) = (a1 - a0 + 1 + 2 * margin, b1 - b0 + 1 + 2 * margin);
                    if w >= l || h >= l {
                        c.lost = Some(format!("spans the box: its patch would be {w}×{h} on a {l}×{l} lattice"));
                        return;
                    }
                    Patch {
                        x0: wrap(old.x0 as i64 + a0 as i64 - margin as i64, l),
                        y0: wrap(old.y0 as i64 + b0 as i64 - margin as i64, l),
                        w,
                        h,
                    }
                }
            };
            c.next = new;
        });
        if let Some((cell, what)) = self.cells.iter().enumerate().find_map(|(i, c)| c.lost.clone().map(|w| (i, w))) {
            // Named, like an instability, by the step it started from (the state `step` puts back).
            return Err(SimError::CellLost { step: self.step - 1, cell, what });
        }
        par::for_each_mut(&mut self.cells, |_, c| c.relayout(c.next, l));
        Ok(())
    }
}

/// The first site (a, b, value) of the patch where φ is not finite or outside [lo, hi].
fn first_out_of_range(c: &Cell, lo: f64, hi: f64) -> Option<(usize, usize, f64)> {
    let p = c.patch;
    for b in 0..p.h {
        let row = &c.phi[p.idx(0, b)..][..p.w];
        if let Some(a) = row.iter().position(|&v| !(load(v) >= lo && load(v) <= hi)) {
            return Some((a, b, load(row[a])));
        }
    }
    None
}

/// Checks a saved cell's φ (a checkpoint's, a relaxed state's) as every step leaves it: within
/// [`Params::phi_min`, `Params::phi_max`] (a step beyond fails the run), and 0 on the one-site
/// ring around its patch, which the stencils read as the world outside the cell. A state
/// beyond either is damaged: stepped, it would fail as if the run went unstable, or follow
/// another trajectory without a word.
fn check_saved_phi(cell: usize, patch: &Patch, phi: &[f64], params: &Params) -> Result<(), SimError> {
    let (w, h) = (patch.w + 2, patch.h + 2);
    let (lo, hi) = (params.phi_min, params.phi_max);
    for (k, &v) in phi.iter().enumerate() {
        let (a, b) = (k % w, k / w);
        let ring = a == 0 || b == 0 || a == w - 1 || b == h - 1;
        if ring && v != 0.0 {
            return Err(SimError::Invalid(format!(
                "cell {cell}: φ = {v} on the ring around its patch (padded site ({a}, {b}), index {k}), \
                 where every state holds 0: a damaged state"
            )));
        }
        if !(lo..=hi).contains(&v) {
            return Err(SimError::Invalid(format!(
                "cell {cell}: φ = {v} at padded site ({a}, {b}) (index {k}), outside [phi_min, phi_max] = \
                 [{lo}, {hi}] where every step leaves it: a damaged state"
            )));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A cell whose φ is a smooth ellipse (semi-axes `a` along x, `b` along y) centred in its patch.
    fn ellipse_cell(patch: Patch, a: f64, b: f64) -> Cell {
        let mut phi = vec![0.0; patch.padded_len()];
        let (cx, cy) = ((patch.w as f64 - 1.0) / 2.0, (patch.h as f64 - 1.0) / 2.0);
        for j in 0..patch.h {
            for i in 0..patch.w {
                let r = (((i as f64 - cx) / a).powi(2) + ((j as f64 - cy) / b).powi(2)).sqrt();
                phi[patch.idx(i, j)] = 1.0 / (1.0 + ((r - 1.0) * a.min(b)).exp());
            }
        }
        Cell::new(patch, phi)
    }

    /// The active phase's patch rule (paper Sec. A): after a step each side of every patch sits
    /// exactly `patch_margin` sites beyond the last site with φ > `presence_threshold`, wherever
    /// the patch was before (here too large for one cell, too small for the other).
    #[test]
    fn active_patches_are_the_support_plus_the_margin() {
        let p = Params { box_size: 64, n_cells: 2, relax_steps: 0, ..Params::default() };
        let (m_, thr) = (p.patch_margin, p.presence_threshold);
        let cells = vec![
            ellipse_cell(Patch { x0: 60, y0: 2, w: 30, h: 30 }, 6.0, 5.0),
            ellipse_cell(Patch { x0: 20, y0: 30, w: 24, h: 18 }, 9.0, 6.0),
        ];
        let mut m = Monolayer::with_cells(p, 1, cells, 0);
        let before: Vec<Patch> = m.cells.iter().map(|c| c.patch).collect();
        m.step().unwrap();
        for (i, c) in m.cells.iter().enumerate() {
            let p = c.patch;
            assert_ne!(p, before[i], "cell {i}: the patch should have been re-laid");
            assert_eq!(c.support(thr), Some((m_, p.w - 1 - m_, m_, p.h - 1 - m_)), "cell {i}: patch {p:?}");
        }
    }

    /// A cell whose patch cannot follow it (it would span the box) stops the run with the state
    /// from the start of the failed step, every cell on its old patch (including a cell whose
    /// patch would have moved), and the step count of that state.
    #[test]
    fn a_lost_cell_leaves_the_state_from_before_the_step() {
        let p = Params { box_size: 40, n_cells: 2, relax_steps: 0, ..Params::default() };
        let cells = vec![
            ellipse_cell(Patch { x0: 2, y0: 2, w: 20, h: 20 }, 5.0, 5.0),
            ellipse_cell(Patch { x0: 1, y0: 24, w: 38, h: 12 }, 16.0, 4.0),
        ];
        let mut m = Monolayer::with_cells(p, 1, cells, 7);
        let before = m.state();
        match m.step() {
            Err(SimError::CellLost { step: 7, cell: 1, what }) => assert!(what.contains("spans the box"), "{what}"),
            other => panic!("expected cell 1 lost at step 7, got {other:?}"),
        }
        let after = m.state();
        assert_eq!(after.step, before.step);
        assert!(after.cells == before.cells, "the saved state is not the one before the step");
        // A step from there fails the same way (nothing was half done).
        assert!(matches!(m.step(), Err(SimError::CellLost { step: 7, cell: 1, .. })));
    }

    /// The active phase at the browser page's size, bit for bit: 300 active steps after the
    /// page's 1,500 relaxation steps, seed 1, the defaults otherwise (χ = 0.001, ζ = 0.5). The
    /// constant is what
    ///
    ///   monolayer fingerprint --set box_size=80 --set n_cells=33 --set gamma=0.06 \
    ///     --relax-steps 1500 --total-steps 1800
    ///
    /// prints (from a build of the same storage precision: `f32-storage` has its own constant).
    /// A change of these bits is a deliberate edit of this constant, with its reason in the
    /// commit. Run without the `parallel` feature too (scripts/test.sh), so it also guards the
    /// serial path the browser takes, and in f32 there.
    #[test]
    fn page_size_active_phase_fingerprint() {
        let p = Params { box_size: 80, n_cells: 33, gamma: 0.06, relax_steps: 1500, ..Params::default() };
        assert_eq!((p.zeta, p.xi_substrate / p.xi_cell), (0.5, 0.001));
        let mut m = Monolayer::new(p, 1).unwrap();
        m.advance(1800).unwrap();
        assert_eq!(m.step_count(), 1800);
        let expected = match crate::model::precision::STORE_NAME {
            "f64" => "698b0538f7e476ec",
            _ => "8aa26f6a292755e3",
        };
        assert_eq!(format!("{:016x}", m.fingerprint()), expected);
    }
}

//! The GPU stages (src/gpu/, shaders/) against the CPU core, from the same state, on a real
//! Vulkan driver: natively wgpu's Vulkan backend, which on a machine without a GPU is Mesa's
//! lavapipe ("llvmpipe", a CPU device). Without an adapter the tests say so and pass; with
//! CI=true they fail instead (.ci/run installs mesa-vulkan-drivers).
//!
//! Tolerances. The GPU works in f32, the CPU in f64, so the CPU's value is the exact one to
//! within 2⁻⁵³ and the GPU's error is f32 rounding. The standard bound for an expression
//! evaluated in floating point is |computed − exact| ≤ k·u·p̃, with u = 2⁻²⁴ the unit roundoff of
//! f32, k the number of roundings along the longest path of the expression (its depth, the
//! rounding of each input to f32 included) and p̃ the same expression evaluated with every
//! input, coefficient and operation replaced by its absolute value (so cancellation does not
//! shrink the scale). Each check below computes p̃ per site or per cell from the CPU's f64
//! values, and k from the kernel's expression; inputs that are themselves GPU results (Σφ², A_i,
//! μ_i, Q̂_i, f_i) carry their own bound into the next stage. The bounds are tight enough that a
//! sign or a weight wrong in a kernel fails them by orders of magnitude (tried, one at a time,
//! then reverted: the repulsion term's sign in free_energy.wgsl, Q_xy's in shape.wgsl, the
//! active f_y's in forces.wgsl, F_y's and the presence test in gather.wgsl; the J₀μ term's sign
//! in motion.wgsl, 5.8 × 10⁵ times its bound; R(φ*)'s sign in the corrector of monolayer.wgsl,
//! which passes every stage and the predictor and fails the step by 461 times; docs/gpu.md has
//! the figures).

#![cfg(feature = "gpu")]

mod common;

use std::sync::OnceLock;
use std::time::Instant;

use monolayer::gpu::{
    patch_storage, GpuContext, GpuError, GpuMonolayer, GpuRun, GpuRunError, Kernel, Layout, PatchFault, Pipelines,
    Preconditioner, Slot, NO_FAULT,
};
use monolayer::model::{
    friction_weight, Advection, FreeEnergy, FrictionProblem, FrictionSolver, FrictionWeights, Laplacian, Multigrid,
    PassiveForce, Patch,
};
use monolayer::{Monolayer, Params, Phase};

/// The unit roundoff of f32.
const U: f64 = f32::EPSILON as f64 / 2.0;

/// Values the GPU may flush to zero (f32 subnormals): an absolute floor under every bound.
const FLUSHED: f64 = f32::MIN_POSITIVE as f64;

/// The adapter, or None (and a note) where there is none; with CI=true its absence fails.
fn context() -> Option<GpuContext> {
    match GpuContext::new() {
        Ok(ctx) => {
            eprintln!("GPU adapter: {}", ctx.describe());
            Some(ctx)
        }
        Err(e) if std::env::var("CI").is_ok_and(|v| v == "true") => {
            panic!("CI=true: the GPU tests need an adapter: {e}")
        }
        Err(e) => {
            eprintln!("skipping the GPU test: {e}");
            None
        }
    }
}

/// A reduced tissue (18 cells on 60²), relaxed and 40 steps into the active phase: adaptive
/// patches of different sizes, some across the periodic edges, activity on.
fn reduced_tissue() -> &'static Monolayer {
    static TISSUE: OnceLock<Monolayer> = OnceLock::new();
    TISSUE.get_or_init(|| {
        let p = Params { box_size: 60, n_cells: 18, relax_steps: 400, xi_substrate: 0.01, ..Params::default() };
        let mut m = Monolayer::new(p, 3).expect("valid parameters");
        m.advance(440).expect("the reduced tissue steps");
        m
    })
}

/// The CPU's evaluation of the stages at the monolayer's current state, on a copy.
fn evaluated(m: &Monolayer) -> Monolayer {
    let mut m = m.clone();
    m.evaluate_now().expect("the CPU evaluates");
    m
}

/// A per-site or per-cell comparison: the worst ratio |gpu − cpu| / bound, and where.
#[derive(Default)]
struct Worst {
    ratio: f64,
    at: String,
    checked: usize,
}

impl Worst {
    fn check(&mut self, gpu: f32, cpu: f64, bound: f64, at: impl FnOnce() -> String) {
        let ratio = (gpu as f64 - cpu).abs() / (bound + FLUSHED);
        self.checked += 1;
        if ratio > self.ratio || ratio.is_nan() {
            self.ratio = if ratio.is_nan() { f64::INFINITY } else { ratio };
            self.at = format!("{}: GPU {gpu}, CPU {cpu}, bound {bound:e}", at());
        }
    }

    fn assert_within(&self, what: &str) {
        eprintln!("{what}: {} values, worst error {:.3} of its bound ({})", self.checked, self.ratio, self.at);
        assert!(self.checked > 0, "{what}: nothing compared");
        assert!(self.ratio <= 1.0, "{what}: beyond its f32 bound at {}", self.at);
    }
}

/// Patches that cover lattice site `site` (how many terms its lattice sums add).
fn covering(patches: &[Patch], site: usize, l: usize) -> usize {
    covering_cells(patches, site, l).count()
}

/// The cells whose patch covers lattice site `site`, in cell order, each with the site's
/// padded index in its patch.
fn covering_cells(patches: &[Patch], site: usize, l: usize) -> impl Iterator<Item = (usize, usize)> + '_ {
    let (x, y) = (site % l, site / l);
    patches.iter().enumerate().filter_map(move |(i, p)| {
        let (a, b) = ((x + l - p.x0) % l, (y + l - p.y0) % l);
        (a < p.w && b < p.h).then(|| (i, p.idx(a, b)))
    })
}

/// Roundings in a per-cell sum of n terms: invocation t adds ⌈n/64⌉ terms in sequence (the
/// first onto zero, exactly), then six halving levels add the 64 partial sums: one to spare.
fn reduction_depth(n: usize) -> f64 {
    (n.div_ceil(64) + 6) as f64
}

/// What the GPU computed, read back.
struct GpuFields {
    sum_phi: Vec<f32>,
    sum_phi2: Vec<f32>,
    area: Vec<f32>,
    mu: Vec<f32>,
    shape: Vec<f32>,
    q_hat: Vec<f32>,
    fx: Vec<f32>,
    fy: Vec<f32>,
    weight: Vec<f32>,
    force: Vec<f32>,
    /// v_i, (x, y) per padded site.
    velocity: Vec<f32>,
    rate: Vec<f32>,
}

fn gpu_fields(ctx: &GpuContext, m: &Monolayer) -> (GpuMonolayer, GpuFields) {
    let gpu = GpuMonolayer::new(ctx, m).expect("the monolayer fits the device");
    // The stages up to n and F, then v and the rate (which are the CPU's only where it has no
    // friction solve; `compare_stages` checks them there).
    gpu.run(ctx, &[&Kernel::FRICTION_SUMS[..], &[Kernel::VelocityAndRate]].concat());
    let read = |s| gpu.read(ctx, s).unwrap();
    let fields = GpuFields {
        sum_phi: read(Slot::SumPhi),
        sum_phi2: read(Slot::SumPhi2),
        area: read(Slot::Area),
        mu: read(Slot::Mu),
        shape: read(Slot::Shape),
        q_hat: read(Slot::QHat),
        fx: read(Slot::Fx),
        fy: read(Slot::Fy),
        weight: read(Slot::Weight),
        force: read(Slot::Force),
        velocity: read(Slot::Velocity),
        rate: read(Slot::Rate),
    };
    (gpu, fields)
}

/// One state evaluated by both engines: the CPU's f64 fields and the GPU's f32 ones.
struct Case {
    cpu: Monolayer,
    gpu: GpuMonolayer,
    g: GpuFields,
    patches: Vec<Patch>,
    /// Σφ as the CPU gathers it.
    sum_phi: Vec<f64>,
}

impl Case {
    fn new(ctx: &GpuContext, m: &Monolayer) -> Self {
        let mut cpu = evaluated(m);
        let (gpu, g) = gpu_fields(ctx, &cpu);
        let patches = cpu.cells().iter().map(|c| c.patch()).collect();
        let sum_phi = cpu.phi_sum().to_vec();
        Case { cpu, gpu, g, patches, sum_phi }
    }

    fn l(&self) -> usize {
        self.cpu.params().box_size
    }

    /// Roundings in the lattice sums at a site covered by n patches: each φ rounded once to
    /// f32 (which counts twice in φ²), squared once, then n − 1 additions in cell order.
    fn lattice_depth(&self, site: usize) -> f64 {
        covering(&self.patches, site, self.l()) as f64 + 2.0
    }

    /// Roundings in A_i: its terms as in the lattice sums (3), then the per-cell reduction.
    fn area_depth(&self, i: usize) -> f64 {
        3.0 + reduction_depth(self.patches[i].padded_len())
    }
}

/// Every stage's GPU result against the CPU's, each within its f32 bound. Where the CPU has no
/// friction solve, v_i and the rate too, whose bounds it returns (else None).
fn compare_stages(ctx: &GpuContext, m: &Monolayer) -> Option<Vec<Vec<f64>>> {
    let case = Case::new(ctx, m);
    check_lattice_sums(&case);
    check_areas(&case);
    let mu_bounds = check_chemical_potential(&case);
    let q_hat_bounds = check_shape(&case);
    let force_bounds = check_forces(&case, &mu_bounds, &q_hat_bounds);
    let p = case.cpu.params();
    // The CPU gathers n and F only where it solves Eq. 2: active, with cell–cell friction.
    if case.cpu.phase() == Phase::Active && p.xi_cell > 0.0 {
        check_friction_sums(&case, &force_bounds);
        None
    } else {
        Some(check_motion(&case, &mu_bounds, &force_bounds))
    }
}

/// The mobility the CPU uses without a friction solve: 1/ξ_relax, or 1/ξ_s(x) when active.
fn mobility(m: &Monolayer, site: usize) -> f64 {
    match m.phase() {
        Phase::Relaxation => 1.0 / m.params().xi_relax,
        Phase::Active => 1.0 / m.lattice().xi_s[site],
    }
}

/// v = m f and R = −(v_x g_x + v_y g_y) − J₀ μ (g the gradient of φ, central or upwind), where
/// there is no friction solve. v carries m times f's bound, plus two roundings of |v| (m's to
/// f32, the product's). The rate carries v's bounds times |g|~ (the gradient's p̃: ½(|φ₊| + |φ₋|)
/// central, |φ| + the larger neighbour upwind) and J₀ times μ's bound, plus 8 roundings of its
/// own p̃ |v_x| |g_x|~ + |v_y| |g_y|~ + J₀|μ| (input, difference, half, two products, sum, J₀μ,
/// difference: 8). Upwind, a v within its bound of 0 may take the other side on the GPU: then
/// 2 × v's bound × |the two one-sided differences| more. Returns the rate's bound at every padded
/// site of every cell (zero on the halo).
fn check_motion(case: &Case, mu_bounds: &[Vec<f64>], force_bounds: &[Vec<(f64, f64)>]) -> Vec<Vec<f64>> {
    let p = case.cpu.params();
    let (l, j0, upwind) = (p.box_size, p.j0.abs(), p.advection == Advection::Upwind);
    let layout = &case.gpu.state().layout;
    let (mut velocity, mut rate) = (Worst::default(), Worst::default());
    let mut all_bounds = Vec::new();
    for (i, c) in case.cpu.cells().iter().enumerate() {
        let (patch, phi, cmu, crate_) =
            (c.patch(), c.phi().padded(), c.chemical_potential().padded(), c.rate().padded());
        let (cvx, cvy) = c.velocity();
        // v is (x, y) per padded site, from the cell's offset.
        let gv = &case.g.velocity[2 * layout.patches[i].offset as usize..];
        let grate = layout.cell(i, &case.g.rate);
        let s = patch.stride();
        let mut bounds = vec![0.0; patch.padded_len()];
        for b in 0..patch.h {
            for a in 0..patch.w {
                let j = patch.idx(a, b);
                let (gx, gy) = patch.global_xy(a, b, l);
                let m = mobility(&case.cpu, gy * l + gx);
                let (vx, vy) = (cvx.get(j), cvy.get(j));
                let (fbx, fby) = force_bounds[i][j];
                let (bvx, bvy) = (m * fbx + 2.0 * U * vx.abs(), m * fby + 2.0 * U * vy.abs());
                let (mut ax, mut ay) = abs_gradient(&phi, j, s);
                let mut flips = 0.0;
                if upwind {
                    let v = phi[j].abs();
                    ax = v + phi[j - 1].abs().max(phi[j + 1].abs());
                    ay = v + phi[j - s].abs().max(phi[j + s].abs());
                    let (dx, dy) = (
                        (phi[j + 1] - 2.0 * phi[j] + phi[j - 1]).abs(),
                        (phi[j + s] - 2.0 * phi[j] + phi[j - s]).abs(),
                    );
                    flips += if vx.abs() <= bvx { 2.0 * bvx * dx } else { 0.0 };
                    flips += if vy.abs() <= bvy { 2.0 * bvy * dy } else { 0.0 };
                }
                let own = vx.abs() * ax + vy.abs() * ay + j0 * cmu[j].abs();
                let bound = bvx * ax + bvy * ay + j0 * mu_bounds[i][j] + 8.0 * U * own + flips;
                let at = || format!("cell {i} site ({a}, {b})");
                velocity.check(gv[2 * j], vx, bvx, at);
                velocity.check(gv[2 * j + 1], vy, bvy, at);
                rate.check(grate[j], crate_[j], bound, at);
                bounds[j] = bound;
            }
        }
        for (j, (&g, &c)) in grate.iter().zip(&crate_).enumerate() {
            if bounds[j] == 0.0 {
                assert_eq!((g as f64, c), (0.0, 0.0), "cell {i}: the rate's halo at padded index {j}");
            }
        }
        all_bounds.push(bounds);
    }
    velocity.assert_within("v_i");
    rate.assert_within("∂_t φ_i");
    all_bounds
}

/// Σφ and Σφ²: positive terms, so p̃ is the sum itself; k = n + 2 (`Case::lattice_depth`).
fn check_lattice_sums(case: &Case) {
    let l = case.l();
    let (mut s1, mut s2) = (Worst::default(), Worst::default());
    let cpu2 = &case.cpu.lattice().sum_phi2;
    for (site, (&cpu1, &cpu2)) in case.sum_phi.iter().zip(cpu2).enumerate() {
        let k = case.lattice_depth(site);
        let at = || format!("site ({}, {})", site % l, site / l);
        s1.check(case.g.sum_phi[site], cpu1, k * U * cpu1.abs(), at);
        s2.check(case.g.sum_phi2[site], cpu2, k * U * cpu2, at);
    }
    s1.assert_within("Σφ");
    s2.assert_within("Σφ²");
}

/// A_i = Σ φ² over the padded patch: positive terms, k = 3 + the reduction's depth.
fn check_areas(case: &Case) {
    let mut area = Worst::default();
    for (i, c) in case.cpu.cells().iter().enumerate() {
        area.check(case.g.area[i], c.area(), case.area_depth(i) * U * c.area(), || format!("cell {i}"));
    }
    area.assert_within("A_i");
}

/// μ_i = bulk·c(1−c)(1−2c) − gradient·∇²c − area·(1 − A/πR²)·c + repulsion·c·(Σφ² − c²), with
/// p̃ = bulk·|c|(1+|c|)(1+2|c|) + gradient·|∇²|~ + area·(1 + A/πR²)|c| + repulsion·|c|(Σφ² + c²)
/// (|∇²|~: the stencil with absolute weights). The longest path has 9 roundings (input, three
/// products and a subtraction in the bulk term, then four additions); 16 leaves room for the
/// compiler's order of the four terms. The GPU's own A_i and Σφ² come in with their bounds
/// through the area and repulsion terms. Returns the bound at every padded site of every cell
/// (zero on the halo, where both are zero).
fn check_chemical_potential(case: &Case) -> Vec<Vec<f64>> {
    let p = case.cpu.params();
    let fe = FreeEnergy::new(p);
    let l = p.box_size;
    let mut mu = Worst::default();
    let mut all_bounds = Vec::new();
    for (i, c) in case.cpu.cells().iter().enumerate() {
        let (patch, cpu_mu) = (c.patch(), c.chemical_potential().padded());
        let gpu_mu = case.gpu.state().layout.cell(i, &case.g.mu);
        let a_ratio = c.area() / fe.target_area;
        let mut bounds = vec![0.0; patch.padded_len()];
        for b in 0..patch.h {
            for a in 0..patch.w {
                let j = patch.idx(a, b);
                let v = c.phi().get(j).abs();
                let (gx, gy) = patch.global_xy(a, b, l);
                let site = gy * l + gx;
                let sum2 = case.cpu.lattice().sum_phi2[site];
                let scale = fe.bulk * v * (1.0 + v) * (1.0 + 2.0 * v)
                    + fe.gradient * abs_laplacian(p.laplacian, patch, &c.phi().padded(), j)
                    + fe.area * (1.0 + a_ratio) * v
                    + fe.repulsion * v * (sum2 + v * v);
                let inherited =
                    fe.area * a_ratio * v * case.area_depth(i) + fe.repulsion * v * sum2 * case.lattice_depth(site);
                bounds[j] = U * (16.0 * scale + inherited);
            }
        }
        for (j, (&gm, &cm)) in gpu_mu.iter().zip(&cpu_mu).enumerate() {
            mu.check(gm, cm, bounds[j], || format!("cell {i} padded index {j}"));
        }
        all_bounds.push(bounds);
    }
    mu.assert_within("μ_i");
    all_bounds
}

/// The Laplacian's stencil at padded index j with every weight and value made positive.
fn abs_laplacian(kind: Laplacian, patch: Patch, phi: &[f64], j: usize) -> f64 {
    let s = patch.stride();
    let v = phi[j].abs();
    let nn = phi[j - 1].abs() + phi[j + 1].abs() + phi[j - s].abs() + phi[j + s].abs();
    match kind {
        Laplacian::FivePoint => nn + 4.0 * v,
        Laplacian::NinePoint => {
            let diag = phi[j - s - 1].abs() + phi[j - s + 1].abs() + phi[j + s - 1].abs() + phi[j + s + 1].abs();
            (4.0 * nn + diag + 20.0 * v) / 6.0
        }
    }
}

/// ½(|f₊| + |f₋|) along x and along y at padded index j: p̃ of a central difference.
fn abs_gradient(f: &[f64], j: usize, s: usize) -> (f64, f64) {
    (0.5 * (f[j + 1].abs() + f[j - 1].abs()), 0.5 * (f[j + s].abs() + f[j - s].abs()))
}

/// Q_xx = −Σ ½(g_x² − g_y²), Q_xy = −Σ g_x g_y, g = ½ (φ₊ − φ₋): p̃ puts m = ½(|φ₊| + |φ₋|) in
/// place of each g. Roundings: input, difference, product, the ±, then the reduction.
/// Q̂ = m Q / √(|Q|² + ε²): a change δQ moves it by at most 2m|δQ|/√(|Q|² + ε²); its own
/// arithmetic (squares, sum, root, product, quotient) adds 8 roundings of m. Returns each
/// cell's bound on Q̂.
fn check_shape(case: &Case) -> Vec<f64> {
    let p = case.cpu.params();
    let (mut shape, mut q_hat) = (Worst::default(), Worst::default());
    let mut q_hat_bounds = Vec::new();
    for (i, c) in case.cpu.cells().iter().enumerate() {
        let patch = c.patch();
        let (mut sxx, mut sxy) = (0.0, 0.0);
        for b in 0..patch.h {
            for a in 0..patch.w {
                let (mx, my) = abs_gradient(&c.phi().padded(), patch.idx(a, b), patch.stride());
                sxx += 0.5 * (mx * mx + my * my);
                sxy += mx * my;
            }
        }
        let k = 4.0 + reduction_depth(patch.w * patch.h);
        let (bxx, bxy) = (k * U * sxx, k * U * sxy);
        let (q, g) = (c.shape_tensor(), &case.g.shape);
        shape.check(g[2 * i], q[0], bxx, || format!("cell {i} Q_xx"));
        shape.check(g[2 * i + 1], q[1], bxy, || format!("cell {i} Q_xy"));
        let norm = (q[0] * q[0] + q[1] * q[1] + p.q_epsilon * p.q_epsilon).sqrt();
        let bound = 2.0 * p.q_magnitude * (bxx + bxy) / norm + 8.0 * U * p.q_magnitude;
        let (qh, g) = (c.q_hat(), &case.g.q_hat);
        q_hat.check(g[2 * i], qh[0], bound, || format!("cell {i} Q̂_xx"));
        q_hat.check(g[2 * i + 1], qh[1], bound, || format!("cell {i} Q̂_xy"));
        q_hat_bounds.push(bound);
    }
    shape.assert_within("Q_i");
    q_hat.assert_within("Q̂_i");
    q_hat_bounds
}

/// f_x = −w·½(μ₊ − μ₋) − ζ(Q̂_xx ∂_xφ + Q̂_xy ∂_yφ), f_y likewise: the GPU's μ and Q̂ carry their
/// bounds in (weighted as they enter), and the expression's own roundings (input, difference,
/// product, sum, product, difference: 6; 8 with room) apply to its p̃. Returns the bounds on
/// (f_x, f_y) at every padded site of every cell (zero on the halo).
fn check_forces(case: &Case, mu_bounds: &[Vec<f64>], q_hat_bounds: &[f64]) -> Vec<Vec<(f64, f64)>> {
    let p = case.cpu.params();
    let zeta = if case.cpu.phase() == Phase::Active { p.zeta.abs() } else { 0.0 };
    let weighted = p.passive_force == PassiveForce::PhiGradMu;
    let layout = &case.gpu.state().layout;
    let mut force = Worst::default();
    let mut all_bounds = Vec::new();
    for (i, c) in case.cpu.cells().iter().enumerate() {
        let (patch, phi, cmu) = (c.patch(), c.phi().padded(), c.chemical_potential().padded());
        let mut bounds = vec![(0.0, 0.0); patch.padded_len()];
        let (cfx, cfy) = c.force();
        let (gfx, gfy) = (layout.cell(i, &case.g.fx), layout.cell(i, &case.g.fy));
        let (mb, qb, qh) = (&mu_bounds[i], q_hat_bounds[i], c.q_hat());
        let s = patch.stride();
        for b in 0..patch.h {
            for a in 0..patch.w {
                let j = patch.idx(a, b);
                let w = if weighted { phi[j].abs() } else { 1.0 };
                let (px, py) = abs_gradient(&phi, j, s);
                let (ux, uy) = abs_gradient(&cmu, j, s);
                let active = zeta * (qh[0].abs() + qh[1].abs()) * (px + py);
                let from_q_hat = zeta * qb * (px + py);
                let bx = w * 0.5 * (mb[j + 1] + mb[j - 1]) + from_q_hat + 8.0 * U * (w * ux + active);
                let by = w * 0.5 * (mb[j + s] + mb[j - s]) + from_q_hat + 8.0 * U * (w * uy + active);
                let at = || format!("cell {i} site ({a}, {b})");
                force.check(gfx[j], cfx.get(j), bx, at);
                force.check(gfy[j], cfy.get(j), by, at);
                bounds[j] = (bx, by);
            }
        }
        all_bounds.push(bounds);
    }
    force.assert_within("f_i");
    all_bounds
}

/// n = Σ_j w_j and F = Σ_j w_j f_j, in cell order, with w_j of `motion::friction_weight`. w is
/// φ clamped (rounded once), or exactly 0 or 1; a presence weight may flip where φ lies within
/// rounding of the threshold, which adds the whole term (none did here). Each term of F carries
/// the GPU's f bound times |w|; then the product and n − 1 additions: k = n + 2 on Σ|w f|.
fn check_friction_sums(case: &Case, force_bounds: &[Vec<(f64, f64)>]) {
    let p = case.cpu.params();
    let (l, thr) = (p.box_size, p.presence_threshold);
    let lattice = case.cpu.lattice();
    let (mut weight, mut force) = (Worst::default(), Worst::default());
    for site in 0..l * l {
        let (mut w_sum, mut wf_sum, mut from_f, mut flips, mut n) = (0.0, 0.0, (0.0, 0.0), (0.0, 0.0, 0.0), 0.0);
        for (i, j) in covering_cells(&case.patches, site, l) {
            let c = &case.cpu.cells()[i];
            let (v, fx, fy) = (c.phi().get(j), c.force().0.get(j), c.force().1.get(j));
            let w = friction_weight(p.friction_weights, v, thr);
            let near = p.friction_weights == FrictionWeights::Presence && (v - thr).abs() <= 4.0 * U * thr;
            if near {
                flips = (flips.0 + 1.0, flips.1 + fx.abs(), flips.2 + fy.abs());
            }
            n += 1.0;
            w_sum += w;
            wf_sum += w * (fx.abs() + fy.abs());
            let (bx, by) = force_bounds[i][j];
            from_f = (from_f.0 + w * bx, from_f.1 + w * by);
        }
        let k = n + 2.0;
        let at = || format!("site ({}, {})", site % l, site / l);
        weight.check(case.g.weight[site], lattice.weight[site], k * U * w_sum + flips.0, at);
        let (gx, gy) = (case.g.force[2 * site], case.g.force[2 * site + 1]);
        let cpu = lattice.force[site];
        force.check(gx, cpu.re, from_f.0 + k * U * wf_sum + flips.1, at);
        force.check(gy, cpu.im, from_f.1 + k * U * wf_sum + flips.2, at);
    }
    weight.assert_within("n = Σ w_j");
    force.assert_within("F = Σ w_j f_j");
}

#[test]
fn the_adapter_is_found_and_named() {
    let Some(ctx) = context() else { return };
    assert!(!ctx.adapter_name().is_empty());
}

#[test]
fn stages_match_the_cpu_on_a_reduced_tissue() {
    let Some(ctx) = context() else { return };
    let m = reduced_tissue();
    let l = m.params().box_size;
    assert_eq!(m.phase(), Phase::Active);
    // The case the lattice index must get right: a patch across the periodic edge.
    let wraps = m.cells().iter().filter(|c| c.patch().x0 + c.patch().w > l || c.patch().y0 + c.patch().h > l).count();
    assert!(wraps > 0, "no patch crosses the periodic edge: the fixture does not test the wrap");
    compare_stages(&ctx, m);
}

/// The other readings of the model (nine-point Laplacian, f^p = −φ∇μ, Q̂ magnitude 2, the φ and
/// presence friction weights) and the relaxation phase (ζ = 0 on the GPU too).
#[test]
fn stages_match_the_cpu_under_the_other_readings() {
    let Some(ctx) = context() else { return };
    let base = reduced_tissue().params().clone();
    let readings = [
        Params {
            laplacian: Laplacian::NinePoint,
            passive_force: PassiveForce::PhiGradMu,
            q_magnitude: 2.0,
            friction_weights: FrictionWeights::Phi,
            ..base.clone()
        },
        Params { friction_weights: FrictionWeights::Presence, ..base.clone() },
        // Active without cell–cell friction: no friction solve, v = f/ξ_s(x) (and upwind).
        Params { xi_cell: 0.0, ..base.clone() },
        Params { xi_cell: 0.0, advection: Advection::Upwind, ..base },
    ];
    for p in readings {
        let mut m = reduced_tissue().clone();
        m.set_params(p).expect("valid parameters");
        compare_stages(&ctx, &m);
    }
    let r = relaxing_tissue();
    assert_eq!(r.phase(), Phase::Relaxation);
    compare_stages(&ctx, r).expect("relaxation has no friction solve");
    let mut upwind = r.clone();
    upwind.set_params(Params { advection: Advection::Upwind, ..r.params().clone() }).expect("valid parameters");
    compare_stages(&ctx, &upwind);
}

/// A reduced tissue in relaxation (18 cells on 60², 200 of its 1,000 relaxation steps on).
fn relaxing_tissue() -> &'static Monolayer {
    static TISSUE: OnceLock<Monolayer> = OnceLock::new();
    TISSUE.get_or_init(|| {
        let relaxing = Params { box_size: 60, n_cells: 18, relax_steps: 1000, ..Params::default() };
        let mut r = Monolayer::new(relaxing, 5).expect("valid parameters");
        r.advance(200).expect("the tissue relaxes");
        r
    })
}

/// Whether padded index j of a patch is an interior site (not the halo).
fn interior(patch: Patch, j: usize) -> bool {
    let (col, row) = (j % patch.stride(), j / patch.stride());
    (1..=patch.w).contains(&col) && (1..=patch.h).contains(&row)
}

/// Every cell's padded φ as one f64 vector per cell.
fn phis(m: &Monolayer) -> Vec<Vec<f64>> {
    m.cells().iter().map(|c| c.phi().padded()).collect()
}

/// One Heun step in relaxation, all on the GPU in one submission (`GpuMonolayer::step`: 14
/// dispatches, nothing read back), against the CPU's step on the same fixed patches
/// (`Monolayer::step_on_fixed_patches`), in three checks:
///
/// 1. The predictor φ* = φ + Δt R(φ): Δt × the rate's bound (`check_motion`, from the stage
///    bounds) + 3 roundings of |φ| + Δt|R| (input, product, sum).
/// 2. The stages at the CPU's φ*, from which the GPU's R(φ*) would differ by its stage bounds
///    if its φ* were the CPU's; it is not, by up to δ (the worst bound of check 1), and R moves
///    by at most C·δ, C the linearised sensitivity of R to a change of φ of size δ everywhere:
///    C = J₀ C_μ + max(|v_x| + |v_y|) + m C_μ max(|g_x|~ + |g_y|~), with C_μ bounding |δμ|/δ
///    (bulk·max|1 − 6φ + 6φ²| + 8·2γλ (the five-point stencil's absolute weights) + the area
///    term with δA_i ≤ 2δΣ|φ_i| + the repulsion with δΣφ² ≤ 2δΣ_j|φ_j|); second order in δ
///    (10⁻¹⁴) is left out.
/// 3. The corrector φ' = φ_n + ½Δt (R(φ_n) + R(φ*)): ½Δt × (both rates' bounds + C·δ) + 4
///    roundings of |φ_n| + ½Δt(|R(φ_n)| + |R(φ*)|). No cell leaves φ's range on either.
///
/// Then the same step again from a second upload, bit for bit.
#[test]
fn one_relaxation_step_matches_the_cpu() {
    let Some(ctx) = context() else { return };
    let r = relaxing_tissue();
    let p = r.params().clone();
    let (l, dt) = (p.box_size, p.dt);
    let k1_bounds = compare_stages(&ctx, r).expect("relaxation has no friction solve");
    let start = evaluated(r);

    // 1. The predictor.
    let mut gpu = GpuMonolayer::new(&ctx, r).expect("the monolayer fits the device");
    gpu.run(&ctx, &[&Kernel::RATE[..], &[Kernel::Predict]].concat());
    let g_pred = gpu.read(&ctx, Slot::Phi).unwrap();
    let layout = gpu.state().layout.clone();
    let mut predicted = Worst::default();
    let mut cpu_pred = Vec::new();
    let mut delta: f64 = 0.0;
    for (i, c) in start.cells().iter().enumerate() {
        let (phi, k1) = (c.phi().padded(), c.rate().padded());
        // As `Then::Predict` computes it, so these are the CPU's bits.
        let star: Vec<f64> = phi.iter().zip(&k1).map(|(&p0, &k)| p0 + dt * k).collect();
        for (j, (&g, &want)) in layout.cell(i, &g_pred).iter().zip(&star).enumerate() {
            let bound = dt * k1_bounds[i][j] + 3.0 * U * (phi[j].abs() + dt * k1[j].abs());
            predicted.check(g, want, bound, || format!("cell {i} padded index {j}"));
            delta = delta.max(bound);
        }
        cpu_pred.push(star);
    }
    predicted.assert_within("Heun's predictor φ*");

    // 2. The stages at the CPU's φ*, and R's sensitivity to the GPU's φ* being off by δ.
    let mut state = r.state();
    for ((_, phi), star) in state.cells.iter_mut().zip(&cpu_pred) {
        phi.copy_from_slice(star);
    }
    let at_star = Monolayer::from_state(p.clone(), r.seed(), state).expect("the predicted state loads");
    let k2_bounds = compare_stages(&ctx, &at_star).expect("relaxation has no friction solve");
    let star = evaluated(&at_star);
    let c = sensitivity(&start).max(sensitivity(&star));
    eprintln!("δ = {delta:e} on φ*, C = {c:.2}: R(φ*) off by up to {:e} from it", c * delta);

    // 3. The whole step.
    let mut cpu = r.clone();
    cpu.step_on_fixed_patches().expect("the CPU steps");
    gpu.upload(&ctx, r).expect("the monolayer fits the device");
    gpu.step_on_fixed_patches(&ctx);
    let (g_phi, faults) = (gpu.read(&ctx, Slot::Phi).unwrap(), gpu.read_u32(&ctx, Slot::Fault).unwrap());
    let mut stepped = Worst::default();
    for (i, cell) in cpu.cells().iter().enumerate() {
        assert_eq!((cell.fault(), faults[i]), (None, NO_FAULT), "cell {i}: φ out of range");
        let (phi0, k1, k2) =
            (start.cells()[i].phi().padded(), start.cells()[i].rate().padded(), star.cells()[i].rate().padded());
        for (j, (&g, &want)) in layout.cell(i, &g_phi).iter().zip(&cell.phi().padded()).enumerate() {
            let own = phi0[j].abs() + 0.5 * dt * (k1[j].abs() + k2[j].abs());
            // On the halo both keep φ = 0 exactly: R is written zero there.
            let from_delta = if interior(cell.patch(), j) { c * delta } else { 0.0 };
            let bound = 0.5 * dt * (k1_bounds[i][j] + k2_bounds[i][j] + from_delta) + 4.0 * U * own;
            stepped.check(g, want, bound, || format!("cell {i} padded index {j}"));
        }
    }
    stepped.assert_within("one Heun step, φ'");
    let moved = phis(&cpu)
        .iter()
        .zip(phis(r))
        .map(|(a, b)| a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max))
        .fold(0.0, f64::max);
    eprintln!("the step moved φ by up to {moved:e} (L = {l})");
    assert!(moved > 1e3 * delta, "the step must move φ by far more than the tolerance");

    // The same step from a second upload: the same bits, and the ms of a step on this adapter.
    let again = GpuMonolayer::new(&ctx, r).expect("the monolayer fits the device");
    again.step_on_fixed_patches(&ctx);
    let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
    assert_eq!(bits(&again.read(&ctx, Slot::Phi).unwrap()), bits(&g_phi), "two GPU steps differ");
    eprintln!(
        "one step: {:.3} ms in one submission of {} dispatches (median of 21)",
        median_ms(&ctx, &again, &Kernel::step(None)),
        Kernel::step(None).len()
    );
}

/// C of `one_relaxation_step_matches_the_cpu`: how much R(φ) can move, per unit, when every φ_i
/// moves by at most one unit (linearised; relaxation's readings: five-point Laplacian, f = −∇μ,
/// ζ = 0), from an evaluated state's maxima.
fn sensitivity(m: &Monolayer) -> f64 {
    let p = m.params();
    assert_eq!(
        (p.laplacian, p.passive_force, m.phase()),
        (Laplacian::FivePoint, PassiveForce::GradMu, Phase::Relaxation)
    );
    let fe = FreeEnergy::new(p);
    let (mut phi_max, mut v_max, mut g_max, mut sum_abs_max, mut area_max): (f64, f64, f64, f64, f64) =
        (0.0, 0.0, 0.0, 0.0, 0.0);
    let l = p.box_size;
    let mut sum_abs = vec![0.0; l * l];
    for c in m.cells() {
        let (patch, phi) = (c.patch(), c.phi().padded());
        let (vx, vy) = c.velocity();
        sum_abs_max = sum_abs_max.max(phi.iter().map(|v| v.abs()).sum());
        area_max = area_max.max(c.area());
        for b in 0..patch.h {
            for a in 0..patch.w {
                let j = patch.idx(a, b);
                let (ax, ay) = abs_gradient(&phi, j, patch.stride());
                phi_max = phi_max.max(phi[j].abs());
                v_max = v_max.max(vx.get(j).abs() + vy.get(j).abs());
                g_max = g_max.max(ax + ay);
                let (gx, gy) = patch.global_xy(a, b, l);
                sum_abs[gy * l + gx] += phi[j].abs();
            }
        }
    }
    let lattice_abs = sum_abs.iter().cloned().fold(0.0, f64::max);
    let sum2_max = m.lattice().sum_phi2.iter().cloned().fold(0.0, f64::max);
    let f = phi_max;
    let bulk_slope = 1.0 + 6.0 * f + 6.0 * f * f;
    let c_mu = fe.bulk * bulk_slope
        + 8.0 * fe.gradient
        + fe.area * (1.0 + area_max / fe.target_area)
        + fe.area / fe.target_area * f * 2.0 * sum_abs_max
        + fe.repulsion * (sum2_max + 3.0 * f * f)
        + fe.repulsion * f * 2.0 * lattice_abs;
    let mobility = 1.0 / p.xi_relax;
    p.j0.abs() * c_mu + v_max + mobility * c_mu * g_max
}

/// Fixed summation orders: two uploads of the same state, evaluated apart, give the same bits
/// in every buffer.
#[test]
fn two_runs_give_the_same_bits() {
    let Some(ctx) = context() else { return };
    assert_repeats(&ctx, reduced_tissue());
}

fn assert_repeats(ctx: &GpuContext, m: &Monolayer) {
    let bits = |f: &GpuFields| -> Vec<u32> {
        [&f.sum_phi, &f.sum_phi2, &f.area, &f.mu, &f.shape, &f.q_hat, &f.fx, &f.fy, &f.weight, &f.force]
            .iter()
            .flat_map(|v| v.iter().map(|x| x.to_bits()))
            .collect()
    };
    let (_, first) = gpu_fields(ctx, m);
    let (gpu, second) = gpu_fields(ctx, m);
    assert_eq!(bits(&first), bits(&second), "two GPU runs differ");
    // And a third evaluation of the same device state, after the second.
    gpu.evaluate(ctx);
    assert_eq!(gpu.read(ctx, Slot::Mu).unwrap(), second.mu);
    assert_eq!(gpu.read(ctx, Slot::QHat).unwrap(), second.q_hat);
}

/// The paper's size (100 cells on 140², relaxed, then 20 active steps): every stage against
/// the CPU, two runs with the same bits, and the time of each dispatch on this adapter (on
/// lavapipe a CPU figure).
#[test]
#[ignore = "full size, minutes: scripts/test.sh runs it (cargo test --release -- --include-ignored)"]
fn stages_match_the_cpu_at_full_size() {
    let Some(ctx) = context() else { return };
    let mut m = common::relaxed_full_size().clone();
    m.advance(20).expect("the tissue steps");
    compare_stages(&ctx, &m);
    assert_repeats(&ctx, &m);
    let (iterations, _) = check_friction_solve(&ctx, &m, Preconditioner::Multigrid);
    let cold = cold_start(&m);
    let (cold_iterations, cpu_iterations) = check_friction_solve(&ctx, &cold, Preconditioner::Multigrid);
    assert!(cold_iterations <= cpu_iterations + 3, "{cold_iterations} iterations against the CPU's {cpu_iterations}");
    let (jacobi_iterations, _) = check_friction_solve(&ctx, &cold, Preconditioner::Jacobi);
    eprintln!("with Jacobi from u = 0: {jacobi_iterations} iterations");
    eprintln!("the friction solve at full size: {iterations} iterations from the CPU's warm start, {cold_iterations} from u = 0");
    let gpu = GpuMonolayer::new(&ctx, &m).expect("the monolayer fits the device");
    for k in Kernel::ALL {
        eprintln!("{k:?}: {:.3} ms per dispatch (median of 21)", median_ms(&ctx, &gpu, &[k]));
    }
    eprintln!(
        "all {} kernels: {:.3} ms per submission (median of 21)",
        Kernel::ALL.len(),
        median_ms(&ctx, &gpu, &Kernel::ALL)
    );
}

/// `monolayer bench --gpu` names the adapter, says when its times are CPU figures, and times
/// every kernel with its bytes and the page's hand-off.
#[test]
fn bench_gpu_names_the_adapter_and_times_every_kernel() {
    let Some(ctx) = context() else { return };
    // A small tissue (8 cells on 40², packed about as the paper's 100 on 140²): the GPU run the
    // bench times is 650 steps at any size, and on a CPU device (lavapipe) their time grows with
    // the box (half of 60²'s here).
    let small = ["--set", "box_size=40", "--set", "n_cells=8", "--relax-steps", "200", "--steps", "5"];
    let out = common::monolayer(&[&["bench", "--gpu"][..], &small].concat());
    let text = String::from_utf8_lossy(&out.stdout);
    assert!(out.status.success(), "{}", common::stderr(&out));
    assert!(text.contains(&format!("adapter: {}", ctx.adapter_name())), "{text}");
    assert_eq!(text.contains("CPU figure"), ctx.runs_on_cpu(), "{text}");
    for k in Kernel::ALL {
        assert!(text.contains(&format!("{k:?}")) && text.contains("ms/dispatch"), "{k:?} missing: {text}");
    }
    assert!(text.contains(&format!("{} dispatches", Kernel::FRICTION_SUMS.len())), "{text}");
    assert!(
        text.contains(&format!("one Heun step without a friction solve: {} dispatches", Kernel::step(None).len())),
        "{text}"
    );
    assert!(text.contains("PROJECTION for a laptop GPU, not a measurement"), "{text}");
    assert!(text.contains("a GPU run (GpuRun, checked every 50 steps, 2 submissions under way)"), "{text}");
    assert!(text.contains("one submission at a time"), "{text}");
    let stages = text.lines().find(|l| l.starts_with("dispatches recorded per step by stage")).expect("the stages");
    assert!(stages.contains("gather.wgsl") && !stages.contains('?'), "a kernel without its shader file: {stages}");
    assert!(text.contains("longest serial chain per step"), "{text}");
    // The device's time per stage where it has timestamps (lavapipe has), else said so.
    let timed = text.lines().find(|l| l.starts_with("device time")).expect("the device times");
    if ctx.has_timestamps() {
        let stages: Vec<&str> = timed.split(": ").nth(1).unwrap().split("; ").next().unwrap().split(", ").collect();
        assert_eq!(stages.len(), 9, "one time per shader file: {timed}");
        for stage in stages {
            let ms: f64 = stage.rsplit(' ').next().unwrap().parse().unwrap_or_else(|_| panic!("{timed}"));
            assert!(ms > 0.0 && ms.is_finite(), "{timed}");
        }
    } else {
        assert!(timed.contains("timestamps unsupported"), "{timed}");
    }
    // The page's hand-off, a row of readouts every ROW_EVERY active steps.
    let hand_off = text.lines().find(|l| l.starts_with("the page's hand-off")).expect("the hand-off");
    assert!(hand_off.contains(&format!("every {} active steps", monolayer::web::ROW_EVERY)), "{hand_off}");
    let pace: f64 = hand_off.rsplit("up to ").next().unwrap().trim_end_matches(" steps/s").parse().unwrap();
    assert!(pace > 0.0 && pace.is_finite(), "{hand_off}");
}

/// The median wall time of submitting `kernels` and waiting for them, after one warm-up.
fn median_ms(ctx: &GpuContext, gpu: &GpuMonolayer, kernels: &[Kernel]) -> f64 {
    gpu.run(ctx, kernels);
    ctx.wait().unwrap();
    let mut times: Vec<f64> = (0..21)
        .map(|_| {
            let t = Instant::now();
            gpu.run(ctx, kernels);
            ctx.wait().unwrap();
            t.elapsed().as_secs_f64() * 1e3
        })
        .collect();
    times.sort_by(f64::total_cmp);
    times[times.len() / 2]
}

/// The corrector's range check: φ pushed far out of [φ_min, φ_max] at the centre of three
/// patches (above in two, below in one) stays out after the step on both engines, and the GPU's
/// per-cell fault names the same first site as the CPU's, and no fault in the other cells.
#[test]
fn the_range_check_flags_the_cpus_sites() {
    let Some(ctx) = context() else { return };
    let r = relaxing_tissue();
    let mut state = r.state();
    let bad = [(2, 3.0), (7, 2.5), (11, -2.0)];
    for &(i, v) in &bad {
        let (patch, phi) = &mut state.cells[i];
        phi[patch.idx(patch.w / 2, patch.h / 2)] = v;
    }
    let mut cpu = Monolayer::from_state(r.params().clone(), r.seed(), state).expect("the state loads");
    let gpu = GpuMonolayer::new(&ctx, &cpu).expect("the monolayer fits the device");
    let err = cpu.step_on_fixed_patches().expect_err("φ leaves its range");
    assert!(err.to_string().contains("phi"), "{err}");
    gpu.step_on_fixed_patches(&ctx);
    let faults = gpu.read_u32(&ctx, Slot::Fault).unwrap();
    for (i, c) in cpu.cells().iter().enumerate() {
        let want = c.fault().map_or(NO_FAULT, |(a, b, _)| c.patch().idx(a, b) as u32);
        assert_eq!(faults[i], want, "cell {i}: GPU fault at padded index {}, CPU {:?}", faults[i], c.fault());
        assert_eq!(want != NO_FAULT, bad.iter().any(|&(k, _)| k == i), "cell {i}: {:?}", c.fault());
    }
}

/// C u = n (ξ_s + ξ_c N) u − ξ_c n Σ_{N8} n u in f64 (an independent reading of Eq. 2's
/// operator, `model::friction`), 0 where n = 0; n, u as (x, y) pairs per site.
fn friction_operator(n: &[f64], u: &[[f64; 2]], xi_s: &[f64], xi_c: f64, l: usize) -> Vec<[f64; 2]> {
    let at = |x: usize, dx: isize, dy: isize| periodic_neighbour(x, dx, dy, l);
    (0..l * l)
        .map(|x| {
            if n[x] <= 0.0 {
                return [0.0, 0.0];
            }
            let (mut nb, mut s) = (0.0, [0.0, 0.0]);
            for dy in -1..=1 {
                for dx in -1..=1 {
                    if (dx, dy) != (0, 0) {
                        let y = at(x, dx, dy);
                        nb += n[y];
                        s[0] += n[y] * u[y][0];
                        s[1] += n[y] * u[y][1];
                    }
                }
            }
            let d = n[x] * (xi_s[x] + xi_c * nb);
            [d * u[x][0] - xi_c * n[x] * s[0], d * u[x][1] - xi_c * n[x] * s[1]]
        })
        .collect()
}

/// Site x + (dx, dy) of the periodic L × L lattice.
fn periodic_neighbour(x: usize, dx: isize, dy: isize, l: usize) -> usize {
    let (i, j) = ((x % l) as isize, (x / l) as isize);
    let (i, j) = ((i + dx).rem_euclid(l as isize) as usize, (j + dy).rem_euclid(l as isize) as usize);
    j * l + i
}

/// ‖F − C u‖/‖F‖ in f64.
fn true_residual(n: &[f64], f: &[[f64; 2]], u: &[[f64; 2]], xi_s: &[f64], xi_c: f64, l: usize) -> f64 {
    let cu = friction_operator(n, u, xi_s, xi_c, l);
    let (mut num, mut den) = (0.0, 0.0);
    for (f, c) in f.iter().zip(&cu) {
        num += (f[0] - c[0]).powi(2) + (f[1] - c[1]).powi(2);
        den += f[0] * f[0] + f[1] * f[1];
    }
    (num / den).sqrt()
}

fn pairs(v: &[f32]) -> Vec<[f64; 2]> {
    v.chunks_exact(2).map(|p| [p[0] as f64, p[1] as f64]).collect()
}

/// The tissue with the friction solve's warm start cleared: u = 0, so CG has to iterate.
fn cold_start(m: &Monolayer) -> Monolayer {
    let mut state = m.state();
    state.warm_start.iter_mut().for_each(|u| *u = Default::default());
    Monolayer::from_state(m.params().clone(), m.seed(), state).expect("the state loads")
}

/// One multigrid application on the GPU (the set-up of level 1 with the first restriction, the
/// coarser levels with the coarsest inverse and the first cycle, the last sweep) against the
/// CPU's cycle (`Multigrid::precondition`) on the same n and r: z within f32 rounding of the
/// CPU's. The solve's iteration counts alone would hide a weaker preconditioner (a coarse
/// solve with a lost term still converges, a few iterations later).
#[test]
fn a_multigrid_application_matches_the_cpus_cycle() {
    let Some(ctx) = context() else { return };
    let cold = cold_start(reduced_tissue());
    let p = cold.params().clone();
    let l = p.box_size;
    let gpu = GpuMonolayer::new(&ctx, &cold).expect("the monolayer fits the device");
    let mut kernels = vec![Kernel::CgStart];
    kernels.extend_from_slice(Preconditioner::Multigrid.first_application());
    gpu.run(&ctx, &[&Kernel::FRICTION_SUMS[..], &kernels].concat());
    let n: Vec<f64> = gpu.read(&ctx, Slot::Weight).unwrap().iter().map(|&v| v as f64).collect();
    let vectors = gpu.read(&ctx, Slot::CgVectors).unwrap();
    let section = |k: usize| &vectors[2 * k * l * l..2 * (k + 1) * l * l];
    let (r, z_gpu) = (section(0), section(4));

    let n_nb: Vec<f64> = (0..l * l)
        .map(|x| {
            let ring = (-1..=1).flat_map(|dy| (-1..=1).map(move |dx| (dx, dy))).filter(|&d| d != (0, 0));
            ring.map(|(dx, dy)| n[periodic_neighbour(x, dx, dy, l)]).sum()
        })
        .collect();
    let mut mg = Multigrid::new(l);
    mg.setup(&n, &n_nb, &cold.lattice().xi_s, p.xi_cell);
    let mut worst: f64 = 0.0;
    let mut scale: f64 = 0.0;
    for c in 0..2 {
        let mut work = mg.work();
        for (w, pair) in work.residual_mut().iter_mut().zip(r.chunks(2)) {
            *w = pair[c] as _;
        }
        mg.precondition(&mut work);
        for (cpu, pair) in work.preconditioned().iter().zip(z_gpu.chunks(2)) {
            worst = worst.max((*cpu as f64 - pair[c] as f64).abs());
            scale = scale.max((*cpu as f64).abs());
        }
    }
    eprintln!("z = M r: GPU against the CPU's cycle, max |Δz| = {worst:.3e} of max |z| = {scale:.3e}");
    assert!(scale > 0.0, "the cycle must give a nonzero z from r = F");
    assert!(worst <= 1e-4 * scale, "the GPU's cycle differs from the CPU's: {worst:e} of {scale:e}");
}

/// The friction solve of Eq. 2 on the GPU (shaders/friction.wgsl), from the CPU's warm start
/// and from a cold start (u = 0, so that CG iterates): its solution u meets the CPU's relative tolerance on the true residual ‖F − C u‖/‖F‖,
/// computed here in f64 from the GPU's own n and F; it is as close to an exact solve (the CPU's
/// at 10⁻¹⁰) as the CPU's own solve at the same tolerance; the mobility is 1/[ξ_s + ξ_c N]
/// within f32 rounding; and the pull is ξ_c Σ_{N8} n u of the GPU's u within f32 rounding.
#[test]
fn the_friction_solve_meets_the_cpus_tolerance() {
    let Some(ctx) = context() else { return };
    let warm = reduced_tissue();
    let cold = cold_start(warm);
    for pc in [Preconditioner::Multigrid, Preconditioner::Jacobi] {
        let (warm_iterations, _) = check_friction_solve(&ctx, warm, pc);
        let (cold_iterations, cpu_iterations) = check_friction_solve(&ctx, &cold, pc);
        assert!(cold_iterations > 0, "from u = 0 CG must iterate");
        assert!(warm_iterations <= cold_iterations);
        if pc == Preconditioner::Multigrid {
            // The same cycle as the CPU's: about as many iterations (the GPU asks half the
            // tolerance of its recursive residual, `RECURSIVE_RESIDUAL_MARGIN`).
            assert!(
                cold_iterations <= cpu_iterations + 3,
                "{cold_iterations} iterations against the CPU's {cpu_iterations}"
            );
        }
    }
}

/// One solve's checks with the given preconditioner; returns its iterations and the CPU's at the
/// same tolerance.
fn check_friction_solve(ctx: &GpuContext, m: &Monolayer, pc: Preconditioner) -> (u32, u32) {
    eprintln!("{pc:?}:");
    let p = m.params().clone();
    let (l, xi_c, tol) = (p.box_size, p.xi_cell, p.friction_tolerance);
    let mut gpu = GpuMonolayer::new(ctx, m).expect("the monolayer fits the device");
    gpu.set_preconditioner(pc);
    assert!(gpu.state().solves_friction);
    gpu.run(
        ctx,
        &[&Kernel::FRICTION_SUMS[..], &Kernel::friction_solve(gpu.preconditioner, gpu.solve_iterations)].concat(),
    );
    let solve = gpu.read_solve(ctx).unwrap();
    eprintln!("GPU friction solve: {solve:?}");
    assert!(solve.converged(), "the GPU solve did not converge in {} iterations: {solve:?}", gpu.solve_iterations);
    let n: Vec<f64> = gpu.read(ctx, Slot::Weight).unwrap().iter().map(|&v| v as f64).collect();
    let f = pairs(&gpu.read(ctx, Slot::Force).unwrap());
    let u = pairs(&gpu.read(ctx, Slot::MeanVelocity).unwrap());
    let xi_s = &m.lattice().xi_s;
    let residual = true_residual(&n, &f, &u, xi_s, xi_c, l);
    eprintln!(
        "true residual of the GPU's u: {residual:.3e} (its own CG residual {:.3e}, tolerance {tol:e})",
        solve.residual()
    );
    assert!(residual <= tol, "the GPU's solution misses the tolerance: {residual:e} > {tol:e}");
    for (x, (&n, u)) in n.iter().zip(&u).enumerate() {
        if n == 0.0 {
            assert_eq!(*u, [0.0, 0.0], "site {x} is outside the solve and must keep u = 0");
        }
    }

    // Against an exact solve of the CPU's n and F, and the CPU's own solve at its tolerance.
    let cpu = evaluated(m);
    let lat = cpu.lattice();
    let solve_cpu = |tolerance: f64| {
        let mut s = FrictionSolver::new(l);
        s.mean_velocity.copy_from_slice(m.warm_start());
        let pb =
            FrictionProblem { weight: &lat.weight, force: &lat.force, xi_s, xi_c, tolerance, max_iterations: 10_000 };
        let stats = s.solve(&pb).expect("the CPU solves");
        (s, stats)
    };
    let (exact, _) = solve_cpu(1e-10);
    let (own, own_stats) = solve_cpu(tol);
    let distance = |u: &[[f64; 2]]| -> f64 {
        let (mut num, mut den) = (0.0, 0.0);
        for (a, b) in u.iter().zip(&exact.mean_velocity) {
            num += (a[0] - b.re).powi(2) + (a[1] - b.im).powi(2);
            den += b.norm_sqr();
        }
        (num / den).sqrt()
    };
    let own_u: Vec<[f64; 2]> = own.mean_velocity.iter().map(|z| [z.re, z.im]).collect();
    let (d_gpu, d_cpu) = (distance(&u), distance(&own_u));
    eprintln!(
        "‖u − u_exact‖/‖u_exact‖: GPU {d_gpu:.3e} ({} iterations), CPU at the same tolerance {d_cpu:.3e} ({} iterations)",
        solve.iterations[0].max(solve.iterations[1]),
        own_stats.iterations
    );

    // The mobility and the pull from the GPU's n and u, within f32 rounding.
    let drag = gpu.read(ctx, Slot::Drag).unwrap();
    let mut mobility = Worst::default();
    let mut pull = Worst::default();
    for x in 0..l * l {
        let (i, j) = (x % l, x / l);
        let (mut sum_n, mut s, mut s_abs) = (0.0, [0.0, 0.0], [0.0, 0.0]);
        for dy in [l - 1, 0, 1] {
            for dx in [l - 1, 0, 1] {
                if (dx, dy) != (0, 0) {
                    let y = ((j + dy) % l) * l + (i + dx) % l;
                    sum_n += n[y];
                    for c in 0..2 {
                        s[c] += n[y] * u[y][c];
                        s_abs[c] += (n[y] * u[y][c]).abs();
                    }
                }
            }
        }
        let total = xi_s[x] + xi_c * sum_n;
        let at = || format!("site ({i}, {j})");
        // ξ_s rounded, N's sum (exact for whole-patch weights, 9 roundings at most), ξ_c N, the
        // sum, the division: 12 roundings of 1/total.
        mobility.check(drag[4 * x + 2], 1.0 / total, 12.0 * U / total, at);
        // Eight products and seven sums, ξ_c's product: 10 roundings of ξ_c Σ|n u|.
        for c in 0..2 {
            pull.check(drag[4 * x + c], xi_c * s[c], 10.0 * U * xi_c * s_abs[c], at);
        }
    }
    mobility.assert_within("mobility 1/[ξ_s + ξ_c N]");
    pull.assert_within("pull ξ_c S");
    (solve.iterations[0].max(solve.iterations[1]), own_stats.iterations as u32)
}

/// The largest |a − b| over every padded site of every cell, a the GPU's φ in its layout.
fn max_phi_difference(layout: &monolayer::gpu::Layout, gpu: &[f32], cpu: &Monolayer) -> f64 {
    cpu.cells()
        .iter()
        .enumerate()
        .flat_map(|(i, c)| {
            let g = layout.cell(i, gpu).to_vec();
            c.phi().padded().into_iter().zip(g).map(|(c, g)| (g as f64 - c).abs())
        })
        .fold(0.0, f64::max)
}

/// One active Heun step with cell–cell friction on fixed patches, GPU against CPU: both solve
/// Eq. 2 twice (predictor, corrector) to the same relative tolerance by different methods
/// (Jacobi CG in f32 here, multigrid CG in f64 there), so their steps differ by more than f32
/// rounding: by what the tolerance leaves free in u. The measure of that is the CPU's own step at
/// the tolerance against its step with both solves at 10⁻⁸: the GPU's step must be as close to
/// the tight step as 4 times that plus 8 roundings of φ in f32 (and far closer than the step
/// moves φ), from the warm start and from a cold one. No cell leaves φ's range; the solves
/// converged. Two uploads step to the same bits.
#[test]
fn one_active_step_with_friction_matches_the_cpu() {
    let Some(ctx) = context() else { return };
    let warm = reduced_tissue();
    let cold = cold_start(warm);
    for (what, m) in [("warm start", warm), ("cold start", &cold)] {
        let step_cpu = |tolerance: f64| {
            let mut c = m.clone();
            let p = Params { friction_tolerance: tolerance, ..m.params().clone() };
            c.set_params(p).expect("valid tolerance");
            c.step_on_fixed_patches().expect("the CPU steps");
            c
        };
        let (cpu, tight) = (step_cpu(m.params().friction_tolerance), step_cpu(1e-8));
        let gpu = GpuMonolayer::new(&ctx, m).expect("the monolayer fits the device");
        gpu.step_on_fixed_patches(&ctx);
        let solve = gpu.read_solve(&ctx).unwrap();
        assert!(solve.converged(), "{what}: the corrector's solve did not converge: {solve:?}");
        let (g_phi, faults) = (gpu.read(&ctx, Slot::Phi).unwrap(), gpu.read_u32(&ctx, Slot::Fault).unwrap());
        assert!(faults.iter().all(|&f| f == NO_FAULT), "{what}: φ left its range on the GPU");
        let layout = &gpu.state().layout;
        let d_gpu = max_phi_difference(layout, &g_phi, &tight);
        let start: Vec<f32> = layout.flatten(m.cells().iter().map(|c| c.phi().data));
        let moved = max_phi_difference(layout, &start, &tight);
        let d_cpu = max_phi_difference(layout, &layout.flatten(cpu.cells().iter().map(|c| c.phi().data)), &tight);
        let d_gpu_cpu = max_phi_difference(layout, &g_phi, &cpu);
        // φ itself in f32: the step's own rounding (4 roundings of |φ|, as in the relaxation
        // step's bound, doubled for the two solves' f32 residuals).
        let phi_max = start.iter().fold(0.0f64, |a, &v| a.max((v as f64).abs()));
        let rounding = 8.0 * U * phi_max;
        let bound = 4.0 * d_cpu + rounding;
        eprintln!(
            "{what}: max |φ' − φ'_tight|: GPU {d_gpu:.3e}, CPU at the tolerance {d_cpu:.3e}, bound 4 × that + \
             {rounding:.2e} = {bound:.2e}; GPU − CPU {d_gpu_cpu:.3e}; the step moved φ by {moved:.3e}; \
             corrector's solve: {} iterations",
            solve.iterations[0].max(solve.iterations[1])
        );
        assert!(d_gpu <= bound, "{what}: the GPU step is {d_gpu:e} from the tight one (bound {bound:e})");
        assert!(d_gpu <= 1e-2 * moved, "{what}: the GPU step must be far closer than the step is long");
        // Fixed orders in every sum of the solve: a second upload steps to the same bits.
        let again = GpuMonolayer::new(&ctx, m).expect("the monolayer fits the device");
        again.step_on_fixed_patches(&ctx);
        let bits = |v: Vec<f32>| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
        for slot in [Slot::Phi, Slot::MeanVelocity, Slot::Drag] {
            assert_eq!(
                bits(again.read(&ctx, slot).unwrap()),
                bits(gpu.read(&ctx, slot).unwrap()),
                "{what}: two GPU steps differ in {slot:?}"
            );
        }
    }
}

/// The GPU's φ of every cell on the lattice (0 where its patch does not reach), read with the
/// patches as they are on the device.
fn gpu_phi_on_lattice(ctx: &GpuContext, gpu: &GpuMonolayer, l: usize) -> Vec<Vec<f64>> {
    let (patches, phi) = (gpu.read_patches(ctx).unwrap(), gpu.read(ctx, Slot::Phi).unwrap());
    patches.iter().map(|gp| on_lattice(gp.patch(), patch_storage(*gp, &phi), l)).collect()
}

/// Every cell's φ on the lattice (0 where its patch does not reach).
fn phi_on_lattice(m: &Monolayer) -> Vec<Vec<f64>> {
    let l = m.params().box_size;
    m.cells().iter().map(|c| on_lattice(c.patch(), &c.phi().padded(), l)).collect()
}

/// The largest |a_i(x) − b_i(x)| over every cell i and lattice site x.
fn max_distance(a: &[Vec<f64>], b: &[Vec<f64>]) -> f64 {
    a.iter().zip(b).flat_map(|(a, b)| a.iter().zip(b).map(|(u, v)| (u - v).abs())).fold(0.0, f64::max)
}

/// A padded patch's interior on the L × L lattice, 0 elsewhere.
fn on_lattice<T: Copy + Into<f64>>(p: Patch, padded: &[T], l: usize) -> Vec<f64> {
    let mut out = vec![0.0; l * l];
    for b in 0..p.h {
        for a in 0..p.w {
            let (gx, gy) = p.global_xy(a, b, l);
            out[gy * l + gx] = padded[p.idx(a, b)].into();
        }
    }
    out
}

/// The same tissue with every patch moved by `shift` sites along x and y (the cells stay where
/// they are on the lattice) and grown by `grow` sites on every side.
fn repatched(m: &Monolayer, shift: usize, grow: usize) -> Monolayer {
    let l = m.params().box_size;
    let mut state = m.state();
    for (patch, phi) in &mut state.cells {
        let old = *patch;
        let new = Patch {
            x0: (old.x0 + 2 * l - shift - grow) % l,
            y0: (old.y0 + 2 * l - shift - grow) % l,
            w: old.w + 2 * grow,
            h: old.h + 2 * grow,
        };
        let lattice = on_lattice(old, phi, l);
        let mut moved = vec![0.0; new.padded_len()];
        for b in 0..new.h {
            for a in 0..new.w {
                let (gx, gy) = new.global_xy(a, b, l);
                moved[new.idx(a, b)] = lattice[gy * l + gx];
            }
        }
        (*patch, *phi) = (new, moved);
    }
    Monolayer::from_state(m.params().clone(), m.seed(), state).expect("the repatched state loads")
}

/// Whether a cell's next patch is a tie that f32 may decide otherwise than the CPU's f64: in
/// relaxation, a coordinate of its centre (`Cell::local_centre`, which is rounded) within 10⁻⁴ of
/// a half-integer (the initial cells are symmetric disks, whose centre is a half-integer up to
/// rounding); when active, a site with φ within 10⁻⁵ of the presence threshold (`Cell::support`).
fn undecided(c: &monolayer::model::Cell, phase: Phase, threshold: f64) -> bool {
    let (p, phi) = (c.patch(), c.phi().padded());
    let sites = || (0..p.h).flat_map(move |b| (0..p.w).map(move |a| (a, b)));
    match phase {
        Phase::Relaxation => {
            let (mut s, mut sa, mut sb) = (0.0, 0.0, 0.0);
            for (a, b) in sites() {
                let v = phi[p.idx(a, b)].max(0.0);
                (s, sa, sb) = (s + v, sa + v * a as f64, sb + v * b as f64);
            }
            [sa / s, sb / s].iter().any(|x| (x.fract() - 0.5).abs() < 1e-4)
        }
        Phase::Active => sites().any(|(a, b)| (phi[p.idx(a, b)] - threshold).abs() < 1e-5),
    }
}

/// The patches follow the cells as on the CPU (`Monolayer::update_patches`, shaders/cell.wgsl):
/// one step from a relaxing tissue (re-centred squares) and from an active one (the support
/// plus the margin), every cell's patch on the GPU is the CPU's after its `step` unless the
/// CPU's decision was a tie within f32 rounding (`undecided`, at most a quarter of the cells),
/// some of them moved, none faulted; and φ was carried over exactly: the GPU's φ after the step with patches
/// is, site by site on the lattice, bit for bit its φ after the same step on fixed patches
/// (the relayout is a copy), and zero on the halo.
#[test]
fn patches_follow_the_cells_as_on_the_cpu() {
    let Some(ctx) = context() else { return };
    // A settled tissue's patches rarely move in one step, so each cell starts off its patch:
    // shifted by 2 sites in relaxation (the step re-centres it), with 2 sites more on every side
    // when active (the step fits it to its support again).
    let relaxing = repatched(relaxing_tissue(), 2, 0);
    let active = repatched(reduced_tissue(), 0, 2);
    for (what, m) in [("relaxation", &relaxing), ("active", &active)] {
        let l = m.params().box_size;
        let mut cpu = m.clone();
        cpu.step().expect("the CPU steps");
        assert_eq!(cpu.phase(), m.phase(), "{what}: the step must stay within its phase");
        let fixed = GpuMonolayer::new(&ctx, m).expect("the monolayer fits the device");
        fixed.step_on_fixed_patches(&ctx);
        let before = gpu_phi_on_lattice(&ctx, &fixed, l);
        let moving = GpuMonolayer::new(&ctx, m).expect("the monolayer fits the device");
        moving.step(&ctx);
        let patches = moving.read_patches(&ctx).unwrap();
        let faults = moving.read_u32(&ctx, Slot::PatchFault).unwrap();
        let phi = moving.read(&ctx, Slot::Phi).unwrap();
        let mut moved = 0;
        // φ after the step, before the patches move: where the CPU's f64 decision is a tie
        // to within f32 rounding, the GPU may take the other side.
        let mut fixed_cpu = m.clone();
        fixed_cpu.step_on_fixed_patches().expect("the CPU steps");
        let mut ties = 0;
        for (i, (gp, c)) in patches.iter().zip(cpu.cells()).enumerate() {
            assert_eq!(PatchFault::from_code(faults[i]), Some(PatchFault::Moved), "{what}: cell {i}");
            if gp.patch() != c.patch() {
                let tie = undecided(&fixed_cpu.cells()[i], m.phase(), m.params().presence_threshold);
                assert!(tie, "{what}: cell {i}'s patch {:?} differs from the CPU's {:?}", gp.patch(), c.patch());
                ties += 1;
            }
            moved += (gp.patch() != m.cells()[i].patch()) as usize;
            let storage = patch_storage(*gp, &phi);
            let carried = on_lattice(gp.patch(), storage, l);
            for (site, (&got, &want)) in carried.iter().zip(&before[i]).enumerate() {
                let (x, y) = (site % l, site / l);
                let inside =
                    (x + l - gp.x0 as usize) % l < gp.w as usize && (y + l - gp.y0 as usize) % l < gp.h as usize;
                if inside {
                    assert_eq!(got.to_bits(), want.to_bits(), "{what}: cell {i} at ({x}, {y})");
                }
            }
            for (j, v) in storage.iter().enumerate() {
                if !interior(gp.patch(), j) {
                    assert_eq!(*v, 0.0, "{what}: cell {i}'s halo at padded index {j}");
                }
            }
        }
        eprintln!(
            "{what}: {moved} of {} patches moved or resized, as on the CPU but {ties} decided by a tie",
            patches.len()
        );
        assert!(ties * 4 <= patches.len(), "{what}: {ties} ties are too many to be ties");
        assert!(moved > 0, "{what}: no patch moved, so the test shows nothing");
    }
}

/// The paper's tissue (100 cells on 140², relaxed, then 20 active steps) stepped 100 times by
/// both engines, each with its own friction solve (GPU: multigrid CG in f32; CPU: in f64) and
/// its own patches: the GPU's φ stays within 10⁻⁴ of the CPU's at every site of every cell (on
/// the lattice, whatever the patches), no cell faults, every solve of the last step converged,
/// and the patches are the CPU's but for a few ties (`undecided`).
#[test]
#[ignore = "full size, minutes: scripts/test.sh runs it (cargo test --release -- --include-ignored)"]
fn a_hundred_steps_at_full_size_stay_near_the_cpu() {
    let Some(ctx) = context() else { return };
    let mut m = common::relaxed_full_size().clone();
    m.advance(20).expect("the tissue steps");
    let l = m.params().box_size;
    let gpu = GpuMonolayer::new(&ctx, &m).expect("the monolayer fits the device");
    let mut cpu = m.clone();
    let t = Instant::now();
    for _ in 0..100 {
        gpu.step(&ctx);
    }
    ctx.wait().unwrap();
    let gpu_ms = t.elapsed().as_secs_f64() * 10.0;
    cpu.advance(100).expect("the CPU steps");
    let solve = gpu.read_solve(&ctx).unwrap();
    assert!(solve.converged(), "the last solve did not converge: {solve:?}");
    let faults = gpu.read_u32(&ctx, Slot::Fault).unwrap();
    assert!(faults.iter().all(|&f| f == NO_FAULT), "φ left its range on the GPU");
    let patch_faults = gpu.read_u32(&ctx, Slot::PatchFault).unwrap();
    assert!(patch_faults.iter().all(|&f| f == PatchFault::Moved as u32), "a patch fault: {patch_faults:?}");
    let patches = gpu.read_patches(&ctx).unwrap();
    let differ = patches.iter().zip(cpu.cells()).filter(|(g, c)| g.patch() != c.patch()).count();
    let (gpu_phi, cpu_phi) = (gpu_phi_on_lattice(&ctx, &gpu, l), phi_on_lattice(&cpu));
    let (worst, moved) = (max_distance(&gpu_phi, &cpu_phi), max_distance(&cpu_phi, &phi_on_lattice(&m)));
    eprintln!(
        "100 steps: max |φ_GPU − φ_CPU| = {worst:.3e}; φ moved by up to {moved:.3e}; \
         {differ} of {} patches differ; the last solve took {} iterations; {gpu_ms:.1} ms per GPU step",
        patches.len(),
        solve.iterations[0].max(solve.iterations[1])
    );
    assert!(worst <= 1e-4, "the GPU drifted {worst:e} from the CPU in 100 steps");
    assert!(differ * 10 <= patches.len(), "{differ} patches differ from the CPU's");
}

/// A GPU run (`gpu::stepper::GpuRun`) from a fresh reduced tissue through the end of relaxation
/// into activity, in submissions of 25 steps checked between them: it takes the CPU's steps
/// (the same step count and phase; φ on the lattice within 10⁻⁴ of the CPU's after 60 steps,
/// each engine with its own friction solve and patches).
#[test]
fn a_gpu_run_crosses_into_activity_as_the_cpu() {
    let Some(ctx) = context() else { return };
    let p = Params { box_size: 60, n_cells: 18, relax_steps: 40, xi_substrate: 0.01, ..Params::default() };
    let m = Monolayer::new(p, 3).expect("valid parameters");
    let mut run = GpuRun::new(&ctx, &m).expect("the monolayer fits the device");
    run.check_every = 25;
    run.advance(&ctx, 60).expect("the GPU steps");
    let mut cpu = m.clone();
    cpu.advance(60).expect("the CPU steps");
    let got = run.download_now(&ctx).unwrap();
    assert_eq!((got.step_count(), got.phase()), (cpu.step_count(), cpu.phase()));
    assert_eq!(got.phase(), Phase::Active);
    let worst = max_distance(&phi_on_lattice(&got), &phi_on_lattice(&cpu));
    eprintln!("60 steps across the phase switch: max |φ_GPU − φ_CPU| = {worst:.3e}");
    assert!(worst <= 1e-4, "{worst:e}");
}

/// A GPU run whose cells outgrow their storage: an active tissue uploaded with room for no
/// more than its largest patch, the first cell whose patch grows beyond it faults
/// (`BeyondCapacity`, a fault the CPU never meets); `advance` puts that submission back,
/// uploads the state again with room for the patches it has then, and takes the steps again,
/// so the run ends where the CPU's does.
#[test]
fn a_gpu_run_regrows_its_storage_and_goes_on_as_the_cpu() {
    let Some(ctx) = context() else { return };
    let m = reduced_tissue();
    let mut run = GpuRun::new(&ctx, m).expect("the monolayer fits the device");
    let tight = Layout::with_capacity(m, 0);
    let capacity = tight.max_padded;
    run.upload_in(&ctx, m, tight).expect("the monolayer fits the device");
    run.check_every = 10;
    run.advance(&ctx, 60).expect("the GPU steps, regrowing its storage");
    let regrown = run.gpu().state().layout.max_padded;
    let mut cpu = m.clone();
    cpu.advance(60).expect("the CPU steps");
    let got = run.download_now(&ctx).unwrap();
    let worst = max_distance(&phi_on_lattice(&got), &phi_on_lattice(&cpu));
    eprintln!("tight storage: capacity {capacity} → {regrown} values per cell; after 60 steps max |φ_GPU − φ_CPU| = {worst:.3e}");
    assert!(regrown > capacity, "the storage was never regrown ({capacity} values per cell): the test proves nothing");
    assert_eq!(got.step_count(), cpu.step_count());
    assert!(worst <= 1e-4, "{worst:e}");
}

/// The recorded solve iterations follow what the solves need: a run that starts with far too
/// few meets unconverged solves, puts those steps back, doubles the count and takes them again;
/// one that starts with many halves them while the solves take under a third. Either way the
/// run is bit for bit the run of a fixed, ample count, since iterations recorded after a
/// solve converged return at once.
#[test]
fn the_recorded_iterations_adapt_without_changing_a_bit() {
    let Some(ctx) = context() else { return };
    let m = reduced_tissue();
    let run = |iterations: usize, adapt: bool| {
        let mut run = GpuRun::new(&ctx, m).expect("the monolayer fits the device");
        run.gpu_mut().solve_iterations = iterations;
        run.adapt_iterations = adapt;
        run.check_every = 10;
        run.advance(&ctx, 40).expect("the GPU steps");
        (run.gpu().solve_iterations, run.download_now(&ctx).unwrap())
    };
    let (fixed, reference) = run(60, false);
    let (grown, from_few) = run(1, true);
    let (shrunk, from_many) = run(60, true);
    eprintln!("recorded iterations: fixed {fixed}; from 1 → {grown}; from 60 → {shrunk}");
    assert!(grown > 1, "too few iterations were never raised");
    assert!(shrunk < 60, "ample iterations were never lowered");
    assert!(phi_bits(&from_few) == phi_bits(&reference), "raising the iterations changed the run");
    assert!(phi_bits(&from_many) == phi_bits(&reference), "lowering the iterations changed the run");
}

/// Every cell's φ, padded, as bits, cell after cell: two runs that agree here made the same run.
fn phi_bits(m: &Monolayer) -> Vec<u64> {
    m.cells().iter().flat_map(|c| c.phi().padded().into_iter().map(f64::to_bits)).collect()
}

/// A fault stops a GPU run: φ pushed out of its range in one cell makes `advance` fail naming
/// the cell and the steps, with the state back at their start, bit for bit as uploaded.
#[test]
fn a_gpu_run_stops_on_a_fault_and_keeps_the_last_good_state() {
    let Some(ctx) = context() else { return };
    let r = relaxing_tissue();
    let mut state = r.state();
    let (patch, phi) = &mut state.cells[7];
    phi[patch.idx(patch.w / 2, patch.h / 2)] = 3.0;
    let bad = Monolayer::from_state(r.params().clone(), r.seed(), state).expect("the state loads");
    let mut run = GpuRun::new(&ctx, &bad).expect("the monolayer fits the device");
    run.check_every = 4;
    let before = run.download_now(&ctx).unwrap();
    let err = run.advance(&ctx, 10).expect_err("φ leaves its range");
    eprintln!("{err}");
    assert!(
        matches!(err, GpuRunError::Unstable { from, to: _, cell: 7, site: _ } if from == r.step_count()),
        "{err:?}"
    );
    assert_eq!(run.step_count(), r.step_count());
    let after = run.download_now(&ctx).unwrap();
    for (a, b) in after.cells().iter().zip(before.cells()) {
        assert_eq!(a.patch(), b.patch());
    }
    assert!(phi_bits(&after) == phi_bits(&before), "the state after the fault must be the one before it");
}

/// A NaN in φ stops a GPU run as a value out of range does: the range check reads a value's
/// bits (`is_finite` in shaders/model.wgsl), not only comparisons a compiler may fold.
#[test]
fn a_nan_in_phi_stops_a_gpu_run_and_keeps_the_last_good_state() {
    let Some(ctx) = context() else { return };
    let r = relaxing_tissue();
    for poison in [f64::NAN, f64::INFINITY] {
        let mut state = r.state();
        let (patch, phi) = &mut state.cells[7];
        phi[patch.idx(patch.w / 2, patch.h / 2)] = poison;
        let bad = Monolayer::from_state(r.params().clone(), r.seed(), state).expect("the state loads");
        let mut run = GpuRun::new(&ctx, &bad).expect("the monolayer fits the device");
        run.check_every = 4;
        let err = run.advance(&ctx, 10).expect_err("a non-finite φ stops the run");
        assert!(matches!(err, GpuRunError::Unstable { from, .. } if from == r.step_count()), "{poison}: {err:?}");
        assert_eq!(run.step_count(), r.step_count());
    }
}

/// A NaN in the friction solve's right-hand side never passes for convergence: the stop test
/// reads the residual's bits, so the solve ends unconverged and the step is put back.
#[test]
fn a_nan_in_the_friction_solve_is_not_convergence() {
    let Some(ctx) = context() else { return };
    let m = reduced_tissue();
    let gpu = GpuMonolayer::new(&ctx, m).expect("the monolayer fits the device");
    gpu.run(&ctx, &Kernel::FRICTION_SUMS);
    let n = gpu.read(&ctx, Slot::Weight).unwrap();
    let site = (0..n.len()).max_by(|&a, &b| n[a].total_cmp(&n[b])).expect("sites");
    let nan = [f32::NAN, 0.0];
    ctx.queue.write_buffer(gpu.state().buffer(Slot::Force), (site * 8) as u64, bytemuck::cast_slice(&nan));
    gpu.run(&ctx, &Kernel::friction_solve(gpu.preconditioner, gpu.solve_iterations));
    let solve = gpu.read_solve(&ctx).unwrap();
    assert!(!solve.converged(), "a NaN in F converged: {solve:?}");
    assert!(solve.unconverged >= 1, "the unconverged solve was not counted: {solve:?}");
}

/// The true residual is checked after every solve: a solve whose own (recursive) residual met
/// its target while u no longer solves C u = F (u disturbed at one site after the iterations,
/// as f32 drift would) is counted as inaccurate; an undisturbed one is not.
#[test]
fn the_true_residual_is_checked_after_the_solve() {
    let Some(ctx) = context() else { return };
    let m = reduced_tissue();
    let gpu = GpuMonolayer::new(&ctx, m).expect("the monolayer fits the device");
    let solve = Kernel::friction_solve(gpu.preconditioner, gpu.solve_iterations);
    let (iterate, check) = solve.split_at(solve.len() - 2);
    assert_eq!(check, [Kernel::FrictionPull, Kernel::FrictionCheck]);
    gpu.run(&ctx, &[&Kernel::FRICTION_SUMS[..], &solve].concat());
    let clean = gpu.read_solve(&ctx).unwrap();
    assert!(clean.converged() && clean.inaccurate == 0, "an undisturbed solve: {clean:?}");
    gpu.run(&ctx, &[&Kernel::FRICTION_SUMS[..], iterate].concat());
    let n = gpu.read(&ctx, Slot::Weight).unwrap();
    let site = (0..n.len()).max_by(|&a, &b| n[a].total_cmp(&n[b])).expect("sites");
    let u = gpu.read(&ctx, Slot::MeanVelocity).unwrap();
    let kicked = [u[2 * site] + 1.0, u[2 * site + 1]];
    ctx.queue.write_buffer(gpu.state().buffer(Slot::MeanVelocity), (site * 8) as u64, bytemuck::cast_slice(&kicked));
    gpu.run(&ctx, check);
    let disturbed = gpu.read_solve(&ctx).unwrap();
    assert!(disturbed.converged(), "the CG's own residual still met its target: {disturbed:?}");
    assert!(disturbed.inaccurate >= 1, "a u that misses the tolerance passed the true-residual check: {disturbed:?}");
}

/// `monolayer run --engine gpu`: the run's protocol stepped on the GPU, its frames and
/// checkpoints written from the state downloaded at their steps. The record names the engine,
/// the state at the end is the CPU run's within 10⁻⁴, and a resume on the other engine is
/// refused, naming the engine it started on.
#[test]
fn a_run_on_the_gpu_engine_writes_the_cpus_frames() {
    let Some(_ctx) = context() else { return };
    let tmp = tempfile::tempdir().expect("a temporary directory");
    let small = ["--set", "box_size=60", "--set", "n_cells=18", "--relax-steps", "40", "--steps", "30"];
    let small =
        [&small[..], &["--set", "xi_substrate=0.01", "--frame-interval", "10", "--quiet", "--seed", "3"]].concat();
    let (gpu_dir, cpu_dir) = (tmp.path().join("gpu"), tmp.path().join("cpu"));
    for (dir, engine) in [(&gpu_dir, "gpu"), (&cpu_dir, "cpu")] {
        let out = common::monolayer(&[&["run", "--engine", engine, "--out", common::arg(dir)][..], &small].concat());
        assert!(out.status.success(), "{engine}: {}", common::stderr(&out));
    }
    let record = std::fs::read_to_string(gpu_dir.join("run.json")).expect("run.json");
    assert!(record.contains("\"engine\": \"gpu-f32\""), "{record}");
    for step in [40, 50, 60, 70] {
        assert!(gpu_dir.join(format!("frames/frame_{step:07}.npz")).exists(), "frame {step} missing");
    }
    let end = |dir: &std::path::Path| {
        let state = monolayer::run::read_checkpoint(&dir.join("checkpoint.npz"), 60).expect("a checkpoint");
        let p = Params { box_size: 60, n_cells: 18, relax_steps: 40, xi_substrate: 0.01, ..Params::default() };
        Monolayer::from_state(p, 3, state).expect("the checkpoint loads")
    };
    let (gpu, cpu) = (end(&gpu_dir), end(&cpu_dir));
    assert_eq!(gpu.step_count(), 70);
    let worst = max_distance(&phi_on_lattice(&gpu), &phi_on_lattice(&cpu));
    eprintln!("monolayer run --engine gpu: 70 steps, max |φ_GPU − φ_CPU| = {worst:.3e}");
    assert!(worst <= 1e-4, "{worst:e}");
    let out = common::monolayer(&["run", "--resume", common::arg(&gpu_dir), "--engine", "cpu"]);
    assert!(!out.status.success());
    assert!(common::stderr(&out).contains("stepped by the gpu-f32 engine"), "{}", common::stderr(&out));
}

/// A run of the GPU engine, stopped part way, that finds no adapter when resumed (the loader
/// given no Vulkan driver) is stopped again, not failed: the reason is printed once and
/// recorded as `stopped: …`, and with its adapter the run then goes on to its end.
#[test]
fn a_gpu_run_resumed_without_an_adapter_stays_resumable() {
    let Some(_ctx) = context() else { return };
    let tmp = tempfile::tempdir().expect("a temporary directory");
    let run = tmp.path().join("gpu");
    let args = ["--set", "box_size=60", "--set", "n_cells=18", "--relax-steps", "40", "--steps", "20"];
    let more = ["--frame-interval", "10", "--quiet", "--engine", "gpu", "--out", common::arg(&run)];
    let out = common::monolayer(&[&["run"][..], &args, &more].concat());
    assert!(out.status.success(), "{}", common::stderr(&out));
    // Stopped at its last frame, with 20 more active steps to go.
    let record = run.join("run.json");
    let text = std::fs::read_to_string(&record).expect("run.json");
    let stopped = text
        .replace("\"finished\"", "\"stopped: signal SIGTERM\"")
        .replace("\"active_steps\": 20", "\"active_steps\": 40");
    std::fs::write(&record, stopped).expect("run.json written");
    let resume = common::command()
        .args(["run", "--quiet", "--resume", common::arg(&run)])
        .env("VK_ICD_FILENAMES", "/nonexistent.json")
        .env("VK_DRIVER_FILES", "/nonexistent.json")
        .output()
        .expect("the binary runs");
    let err = common::stderr(&resume);
    assert_eq!(resume.status.code(), Some(2), "{err}");
    assert_eq!(err.matches("no GPU adapter").count(), 1, "{err}");
    assert!(err.contains("--resume"), "{err}");
    let status = monolayer::formats::RunRecord::load(&run).expect("the record").status;
    assert!(
        matches!(&status, monolayer::formats::RunStatus::Stopped(why) if why.contains("no GPU adapter")),
        "{status:?}"
    );
    let out = common::monolayer(&["run", "--quiet", "--resume", common::arg(&run)]);
    assert!(out.status.success(), "{}", common::stderr(&out));
    let record = monolayer::formats::RunRecord::load(&run).expect("the record");
    assert_eq!((record.status, record.last_frame_step), (monolayer::formats::RunStatus::Finished, Some(80)));
}

/// The kernels compiled one at a time, each awaited (as the page does, to show progress), make
/// the same run as the kernels compiled together: the same pipelines in the same order.
#[test]
fn kernels_compiled_one_at_a_time_make_the_same_run() {
    let Some(ctx) = context() else { return };
    let m = reduced_tissue();
    let compiled: Vec<_> = Kernel::ALL
        .iter()
        .map(|&k| pollster::block_on(monolayer::gpu::compile(&ctx, k)).expect("every kernel compiles"))
        .collect();
    let mut one_by_one = GpuRun::with_pipelines(&ctx, Pipelines::from_compiled(compiled), m).expect("it fits");
    let mut together = GpuRun::new(&ctx, m).expect("it fits");
    for run in [&mut one_by_one, &mut together] {
        run.check_every = 5;
        run.advance(&ctx, 10).expect("the GPU steps");
    }
    let bits = |run: &GpuRun| phi_bits(&run.download_now(&ctx).unwrap());
    assert!(bits(&one_by_one) == bits(&together), "the kernels compiled one at a time stepped otherwise");
}

/// Submissions kept under way while the last one's faults are read give the run of one
/// submission at a time, bit for bit, through the switch to activity and the solves' adapting
/// iterations (the next submission is recorded before the last one's count was settled).
#[test]
fn submissions_under_way_together_make_the_run_of_one_at_a_time() {
    let Some(ctx) = context() else { return };
    let r = relaxing_tissue();
    let run = |in_flight: usize| {
        let mut run = GpuRun::new(&ctx, r).expect("the monolayer fits the device");
        run.check_every = 3;
        run.max_in_flight = in_flight;
        let steps = r.params().relax_steps - r.step_count() + 20;
        run.advance(&ctx, steps).expect("the GPU steps");
        assert_eq!(run.step_count(), r.step_count() + steps);
        phi_bits(&run.download_now(&ctx).unwrap())
    };
    assert!(run(monolayer::gpu::IN_FLIGHT) == run(1), "submissions under way together changed the run");
}

/// A device lost under a run (destroyed, as a driver reset or an unplugged GPU would lose it)
/// is an error of the device everywhere the native path meets it, never a panic: the steps
/// under way are dropped, the steps taken stay those accepted before the loss, and every later
/// readback, download and wait says the device was lost.
#[test]
fn a_lost_device_is_an_error_of_the_run_not_a_panic() {
    let Some(ctx) = context() else { return };
    let m = reduced_tissue();
    let mut run = GpuRun::new(&ctx, m).expect("the monolayer fits the device");
    run.check_every = 5;
    run.advance(&ctx, 10).expect("the GPU steps");
    let taken = run.step_count();
    ctx.destroy();
    let err = run.advance(&ctx, 10).expect_err("a lost device cannot step");
    eprintln!("{err}");
    assert!(
        matches!(&err, GpuRunError::Device { from, reason } if *from == taken && reason.contains("lost")),
        "{err:?}"
    );
    assert!(err.to_string().starts_with("GPU device failed"), "{err}");
    assert_eq!((run.step_count(), run.in_flight()), (taken, 0));
    let lost = |what: &str, e: Option<GpuError>| {
        let e = e.unwrap_or_else(|| panic!("{what} of a lost device succeeded"));
        assert!(matches!(&e, GpuError::Failed(why) if why.contains("lost")), "{what}: {e:?}");
    };
    lost("a download", run.download_now(&ctx).err());
    lost("a wait", ctx.wait().err());
    lost("a readback", run.gpu().read_solve(&ctx).err());
    assert!(ctx.fault().is_some_and(|f| f.contains("lost")), "{:?}", ctx.fault());
}

/// `monolayer run --engine gpu` that loses its device, while it steps or as it reads the state
/// of a frame back, is stopped, not failed and not a panic: exit status 2, the reason printed
/// once, `stopped: GPU device failed …` in run.json, the checkpoint of its last frame kept;
/// `run --resume` then takes it to its end.
#[test]
fn a_gpu_run_that_loses_its_device_is_stopped_and_resumes() {
    let Some(_ctx) = context() else { return };
    let tmp = tempfile::tempdir().expect("a temporary directory");
    let args = ["--set", "box_size=60", "--set", "n_cells=18", "--relax-steps", "40", "--steps", "30"];
    // Frames at 40, 50, 60 and 70: lost as the steps from 50 are submitted, or once the run
    // stepped to 60 and before that state is read back; either way frame 50 is the last.
    for loss in ["steps@50", "download@60"] {
        let run = tmp.path().join(loss.replace('@', "-"));
        let more = ["--frame-interval", "10", "--quiet", "--engine", "gpu", "--out", common::arg(&run)];
        let out = common::command()
            .args([&["run"][..], &args, &more].concat())
            .env("MONOLAYER_TEST_LOSE_GPU", loss)
            .output()
            .expect("the binary runs");
        let err = common::stderr(&out);
        eprintln!("{loss}: {err}");
        assert_eq!(out.status.code(), Some(2), "{loss}: {err}");
        assert!(!err.contains("panicked"), "{loss}: {err}");
        assert_eq!(err.matches("GPU device failed").count(), 1, "{loss}: {err}");
        assert!(err.contains("--resume"), "{loss}: {err}");
        let record = monolayer::formats::RunRecord::load(&run).expect("the record");
        assert!(
            matches!(&record.status, monolayer::formats::RunStatus::Stopped(why)
                if why.starts_with("GPU device failed") && why.contains("lost")),
            "{loss}: {:?}",
            record.status
        );
        assert_eq!(record.last_frame_step, Some(50), "{loss}");
        let state = monolayer::run::read_checkpoint(&run.join("checkpoint.npz"), 60).expect("a checkpoint");
        assert_eq!(state.step, 50, "{loss}");
        assert!(!run.join("frames/frame_0000060.npz").exists(), "{loss}: a frame of the lost device");
        let out = common::monolayer(&["run", "--quiet", "--resume", common::arg(&run)]);
        assert!(out.status.success(), "{loss}: {}", common::stderr(&out));
        let record = monolayer::formats::RunRecord::load(&run).expect("the record");
        assert_eq!((record.status, record.last_frame_step), (monolayer::formats::RunStatus::Finished, Some(70)));
    }
}

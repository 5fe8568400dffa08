//! The model's equations checked on small hand-made configurations: relaxation of one cell,
//! pair forces, the shape tensor and active force, and the friction solve.

mod common;

use common::{ellipse, with_cells};
use monolayer::model::{Advection, FrictionProblem, FrictionSolver, FrictionWeights, PassiveForce, Patch};
use monolayer::{Monolayer, Params};
use num_complex::Complex64 as C64;
use rustfft::FftPlanner;

fn small(n_cells: usize, l: usize) -> Params {
    Params { box_size: l, n_cells, relax_steps: 0, ..Params::default() }
}

/// Net force Σ_x f_i(x) on each cell.
fn net_forces(m: &Monolayer) -> Vec<[f64; 2]> {
    m.cells()
        .iter()
        .map(|c| {
            let (fx, fy) = c.force();
            [fx.interior().iter().sum(), fy.interior().iter().sum()]
        })
        .collect()
}

/// A lone cell started as a disk of radius R/2 grows to a round cell of area close to πR².
/// Tolerance 5 %: the Cahn–Hilliard line tension (Laplace pressure ~ γ/R) balances the area
/// constraint (4μ/πR²) slightly below target; measured A = 0.974 πR² with φ = 1.04 inside, the
/// same from 2,500 steps on. A wrong sign or factor in the area term lands far outside (μ with
/// the wrong sign shrinks the cell away; without its square the cell never stops growing).
#[test]
fn a_single_cell_relaxes_to_a_round_cell_of_area_near_pi_r_squared() {
    let mut p = small(1, 48);
    p.relax_steps = 10_000;
    let mut m = Monolayer::new(p.clone(), 3).unwrap();
    m.advance(4000).unwrap();
    m.evaluate_now().unwrap();
    let cell = &m.cells()[0];
    let ratio = cell.area() / p.target_area();
    assert!((ratio - 1.0).abs() < 0.05, "A / πR² = {ratio}");
    // Round: |Q| tiny next to the interface's ∫|∇φ|² (≈ 2πR/6 ≈ 8); measured 4e-5 at 4,000 steps.
    let q = cell.shape_tensor();
    let qn = (q[0] * q[0] + q[1] * q[1]).sqrt();
    assert!(qn < 1e-3, "|Q| = {qn}");
    // At rest: measured max |v| ≈ 7e-8 (from 0.002 while growing).
    let (vx, vy) = cell.velocity();
    let vmax = vx.interior().iter().chain(vy.interior().iter()).fold(0.0f64, |a, v| a.max(v.abs()));
    assert!(vmax < 1e-5, "max |v| = {vmax}");
}

/// Two overlapping disks of different radii (8 and 6.5), placed off any symmetry axis of the
/// box, so that no reflection maps one onto the other. With the usual form −φ_i∇μ_i the
/// repulsion gives equal and opposite net forces (Newton's third law, which holds because μ_i is
/// the derivative of one translation-invariant F: it would fail for a force not of this form,
/// e.g. −φ_i²∇μ_i, or a repulsion term in μ that is not δF/δφ_i) pushing them apart along the
/// line of their centres. With the printed form −∇μ_i each cell's net force vanishes (it
/// integrates to a boundary term): the cells can only deform, not push each other as a whole;
/// site by site it is the −φ_i∇μ_i force divided by φ_i.
#[test]
fn pair_forces_are_equal_and_opposite() {
    // Patches large enough that φ ≈ 1e-4 at their edges (the boundary terms of the sums).
    let (big, small_w) = (38, 34);
    let cells = vec![
        (Patch { x0: 10, y0: 20, w: big, h: big }, ellipse(big, big, 8.0, 8.0, 0.0)),
        (Patch { x0: 24, y0: 26, w: small_w, h: small_w }, ellipse(small_w, small_w, 6.5, 6.5, 0.0)),
    ];
    // Centres (28.5, 38.5) and (40.5, 42.5): 12.6 apart, 1.9 sites of overlap.
    let line = [12.0f64, 4.0];
    let run = |passive| {
        let p = Params { passive_force: passive, zeta: 0.0, ..small(2, 80) };
        let mut m = with_cells(p, cells.clone(), 0);
        m.evaluate_now().unwrap();
        m
    };
    let (phi_form, printed) = (run(PassiveForce::PhiGradMu), run(PassiveForce::GradMu));
    // −φ_i∇μ_i: equal, opposite, repulsive, along the line of centres.
    let f = net_forces(&phi_form);
    let scale = f[0][0].hypot(f[0][1]);
    let sum = [f[0][0] + f[1][0], f[0][1] + f[1][1]];
    assert!(scale > 1e-2, "the overlap must repel: {f:?}");
    let along = (f[0][0] * line[0] + f[0][1] * line[1]) / (scale * line[0].hypot(line[1]));
    eprintln!("−φ∇μ: net forces {f:?}, sum {sum:?}, cos(f₀, c₁ − c₀) = {along}");
    // Measured: |f₀ + f₁| = 1.4e-3 |f₀| (central differences keep the third law only to
    // O(Δx²)); with −φ_i²∇μ_i instead, or a repulsion φ_i²Σφ_j² in μ_i (not δF/δφ_i), 1.4e-2.
    assert!(sum[0].hypot(sum[1]) < 5e-3 * scale, "not opposite: {f:?}");
    assert!(along < -0.999, "not repulsive along the line of centres: cos = {along}, {f:?}");
    // −∇μ_i: no net force on either cell (up to the boundary terms, μ at the patch edge).
    let total: f64 = printed
        .cells()
        .iter()
        .map(|c| c.force().0.interior().iter().chain(c.force().1.interior().iter()).map(|v| v.abs()).sum::<f64>())
        .sum();
    for fi in net_forces(&printed) {
        assert!(fi[0].abs() + fi[1].abs() < 1e-5 * total, "net −∇μ force {fi:?} of Σ|f| = {total}");
    }
    // The same μ in both: f(−φ∇μ) = φ f(−∇μ) site by site.
    for (a, b) in phi_form.cells().iter().zip(printed.cells()) {
        let (phi, (ax, ay), (bx, by)) = (a.phi().interior(), a.force(), b.force());
        for (k, ((ax, ay), (bx, by))) in
            ax.interior().iter().zip(ay.interior()).zip(bx.interior().iter().zip(by.interior())).enumerate()
        {
            assert!((ax - phi[k] * bx).abs() + (ay - phi[k] * by).abs() < 1e-12 * scale, "site {k}");
        }
    }
}

/// Eq. 1 through the stepping itself: one step of Δt = 1e-4 from an ellipse out of equilibrium
/// (μ ≠ 0, relaxation: v = f/ξ_relax) moves φ by Δt (−v·∇φ − J₀μ) up to O(Δt²), with J₀ = 0.6
/// and ∇φ as the chosen scheme takes it, computed here from the cell's own φ, μ and v before the
/// step. The test also checks that it can tell the alternatives apart: the rate with J₀ = 1, the
/// other advection scheme and downwind differences all miss by more than ten times the error.
#[test]
fn one_step_follows_eq_1_with_its_j0_and_advection_scheme() {
    let (w, l, dt, j0) = (31, 48, 1e-4, 0.6);
    for adv in [Advection::Central, Advection::Upwind] {
        let p = Params { relax_steps: 10, relax_patch_size: w, dt, j0, xi_relax: 0.5, advection: adv, ..small(1, l) };
        let patch = Patch { x0: 8, y0: 8, w, h: w };
        let mut m = with_cells(p, vec![(patch, ellipse(w, w, 9.0, 6.0, 0.4))], 0);
        m.evaluate_now().unwrap();
        let c = &m.cells()[0];
        let (phi, mu, (vx, vy)) = (c.phi(), c.chemical_potential(), c.velocity());
        let (phi0, mu, vx, vy) = (phi.padded(), mu.padded(), vx.padded(), vy.padded());
        m.step().unwrap();
        assert_eq!(m.cells()[0].patch(), patch, "the patch moved");
        let phi1 = m.cells()[0].phi().padded();
        let s = patch.stride();
        // Rate with J₀ = `j`, and ∇φ from `side`: 0 central, 1 upwind, −1 downwind.
        let rate = |i: usize, j: f64, side: i32| {
            let d = |v: f64, step: usize| {
                let (back, fwd) = (phi0[i] - phi0[i - step], phi0[i + step] - phi0[i]);
                match side {
                    0 => 0.5 * (back + fwd),
                    1 if v > 0.0 => back,
                    1 => fwd,
                    _ if v > 0.0 => fwd,
                    _ => back,
                }
            };
            -(vx[i] * d(vx[i], 1) + vy[i] * d(vy[i], s)) - j * mu[i]
        };
        let side = if adv == Advection::Upwind { 1 } else { 0 };
        let (mut err, mut scale, mut wrong) = (0.0f64, 0.0f64, [0.0f64; 3]);
        for b in 1..w - 1 {
            for a in 1..w - 1 {
                let i = patch.idx(a, b);
                let got = (phi1[i] - phi0[i]) / dt;
                let want = rate(i, j0, side);
                err = err.max((got - want).abs());
                scale = scale.max(want.abs());
                for (k, alt) in [rate(i, 1.0, side), rate(i, j0, 1 - side), rate(i, j0, -1)].into_iter().enumerate() {
                    wrong[k] = wrong[k].max((got - alt).abs());
                }
            }
        }
        eprintln!("{adv:?}: error {err:.2e} of {scale:.2e}; J₀ = 1, other scheme, downwind miss by {wrong:?}");
        assert!(err < 1e-3 * scale, "{adv:?}: Eq. 1 misses by {err} (largest rate {scale})");
        assert!(wrong.iter().all(|&x| x > 10.0 * err), "{adv:?}: the alternatives are not told apart: {wrong:?}");
    }
}

/// An ellipse's Q̂ points along its long axis; extensile activity pulls its tips outward and
/// contractile activity pushes them in.
#[test]
fn shape_axis_and_extensile_tips() {
    let (w, h) = (44, 44);
    for deg in [0.0f64, 35.0, 90.0, 120.0] {
        let th = deg.to_radians();
        let phi = ellipse(w, h, 13.0, 6.0, th);
        let run = |zeta: f64| {
            let p = Params { zeta, q_magnitude: 0.5, ..small(1, 64) };
            let mut m = with_cells(p, vec![(Patch { x0: 5, y0: 5, w, h }, phi.clone())], 0);
            m.evaluate_now().unwrap();
            m
        };
        let active = run(1.0);
        let passive = run(0.0);
        let q = active.cells()[0].q_hat();
        let angle = 0.5 * q[1].atan2(q[0]);
        let mut d = (angle - th).rem_euclid(std::f64::consts::PI);
        if d > std::f64::consts::FRAC_PI_2 {
            d -= std::f64::consts::PI;
        }
        assert!(d.abs() < 0.01, "θ = {deg}°: Q̂ axis at {}°", angle.to_degrees());
        assert!(((q[0] * q[0] + q[1] * q[1]).sqrt() - 0.5).abs() < 0.01, "|Q̂| = {q:?}");
        // Active force at the tip (a site on the long axis, 12 sites out): outward along the axis.
        let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
        let (tx, ty) = ((cx + 12.0 * th.cos()).round() as usize, (cy + 12.0 * th.sin()).round() as usize);
        let fa = |m: &Monolayer| {
            let (fx, fy) = m.cells()[0].force();
            (fx.at(tx, ty), fy.at(tx, ty))
        };
        let (ax, ay) = fa(&active);
        let (px, py) = fa(&passive);
        let outward = (ax - px) * th.cos() + (ay - py) * th.sin();
        assert!(outward > 0.0, "θ = {deg}°: active force at the tip points inwards ({outward})");
        let (cxf, cyf) = fa(&run(-1.0));
        assert!((cxf - px) * th.cos() + (cyf - py) * th.sin() < 0.0, "contractile must reverse it");
    }
}

fn symbol(l: usize, xi_s: f64, xi_c: f64, kx: usize, ky: usize) -> f64 {
    let c = |k: usize| (2.0 * std::f64::consts::PI * k as f64 / l as f64).cos();
    let (cx, cy) = (c(kx), c(ky));
    xi_s + 8.0 * xi_c - xi_c * (2.0 * cx + 2.0 * cy + 4.0 * cx * cy)
}

/// With n ≡ 1 and uniform ξ_s the friction equation has constant coefficients: its exact
/// solution by FFT (rustfft, independent of the solver's own FFT) must match, in one iteration.
#[test]
fn friction_solve_is_exact_for_a_full_uniform_tissue() {
    let l = 40;
    let (xi_s, xi_c) = (0.001, 1.0);
    let force: Vec<C64> = (0..l * l)
        .map(|i| {
            let (x, y) = ((i % l) as f64, (i / l) as f64);
            C64::new((0.3 * x).sin() + (0.15 * y).cos(), (0.45 * x + 0.2 * y).sin() * 0.5)
        })
        .collect();
    let weight = vec![1.0; l * l];
    let xis = vec![xi_s; l * l];
    let mut solver = FrictionSolver::new(l);
    let pb =
        FrictionProblem { weight: &weight, force: &force, xi_s: &xis, xi_c, tolerance: 1e-12, max_iterations: 200 };
    solver.solve(&pb).unwrap();
    // Exact: Û(k) = F̂(k) / λ(k).
    let mut planner = FftPlanner::<f64>::new();
    let (fwd, inv) = (planner.plan_fft_forward(l), planner.plan_fft_inverse(l));
    let mut u = force.clone();
    let transform = |u: &mut Vec<C64>, f: &std::sync::Arc<dyn rustfft::Fft<f64>>| {
        for row in u.chunks_exact_mut(l) {
            f.process(row);
        }
        let mut col = vec![C64::new(0.0, 0.0); l];
        for x in 0..l {
            for y in 0..l {
                col[y] = u[y * l + x];
            }
            f.process(&mut col);
            for y in 0..l {
                u[y * l + x] = col[y];
            }
        }
    };
    transform(&mut u, &fwd);
    for ky in 0..l {
        for kx in 0..l {
            u[ky * l + kx] /= symbol(l, xi_s, xi_c, kx, ky) * (l * l) as f64;
        }
    }
    transform(&mut u, &inv);
    let scale = u.iter().map(|z| z.norm()).fold(0.0, f64::max);
    // n ≡ 1, so V = n u is u.
    let err = u.iter().zip(&solver.mean_velocity).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
    assert!(err < 1e-9 * scale, "max error {err} of {scale}");
}

/// With ξ_cell = 0 there is no coupling: every cell moves with v_i = f_i / ξ_s(x), including
/// where the substrate map makes ξ_s vary.
#[test]
fn without_cell_friction_velocity_is_force_over_substrate_friction() {
    let (w, h) = (30, 30);
    let cells = vec![(Patch { x0: 3, y0: 4, w, h }, ellipse(w, h, 10.0, 6.0, 0.4))];
    let p = Params { xi_cell: 0.0, xi_substrate: 0.2, zeta: 0.4, ..small(1, 48) };
    let mut m = with_cells(p, cells, 0);
    let map: Vec<f64> = (0..48 * 48).map(|i| if i % 48 < 20 { 0.5 } else { 3.0 }).collect();
    m.set_substrate(&map).unwrap();
    m.evaluate_now().unwrap();
    let c = &m.cells()[0];
    let ((fx, fy), (vx, vy)) = (c.force(), c.velocity());
    let mut checked = 0;
    for b in 0..h {
        for a in 0..w {
            let x = 3 + a;
            let xi = 0.2 * if x < 20 { 0.5 } else { 3.0 };
            assert!((vx.at(a, b) - fx.at(a, b) / xi).abs() < 1e-14);
            assert!((vy.at(a, b) - fy.at(a, b) / xi).abs() < 1e-14);
            checked += (fx.at(a, b).abs() > 1e-6) as usize;
        }
    }
    assert!(checked > 100);
}

/// During relaxation (no activity, no cell–cell friction) every cell moves with v_i = f_i / ξ_relax,
/// whatever ξ_s and ξ_cell are set to for the active phase.
#[test]
fn relaxation_velocity_is_force_over_relaxation_friction() {
    let (w, h) = (30, 30);
    let cells = vec![(Patch { x0: 3, y0: 4, w, h }, ellipse(w, h, 10.0, 6.0, 0.4))];
    let p = Params { relax_steps: 100, xi_relax: 2.5, xi_substrate: 0.01, zeta: 0.5, ..small(1, 48) };
    let mut m = with_cells(p, cells, 0);
    m.evaluate_now().unwrap();
    let c = &m.cells()[0];
    let ((fx, fy), (vx, vy)) = (c.force(), c.velocity());
    let mut moving = 0;
    for b in 0..h {
        for a in 0..w {
            assert!((vx.at(a, b) - fx.at(a, b) / 2.5).abs() < 1e-14);
            assert!((vy.at(a, b) - fy.at(a, b) / 2.5).abs() < 1e-14);
            moving += (vx.at(a, b).abs() > 1e-6) as usize;
        }
    }
    assert!(moving > 50);
}

/// Bad parameters are refused before anything runs, naming the parameter.
#[test]
fn bad_parameters_name_themselves() {
    for (p, name) in [
        (Params { xi_substrate: -1.0, ..Params::default() }, "xi_substrate"),
        (Params { n_cells: 400, ..Params::default() }, "n_cells"),
        (Params { q_magnitude: 0.0, ..Params::default() }, "q_magnitude"),
        (Params { box_size: 8, ..Params::default() }, "box_size"),
    ] {
        let e = Monolayer::new(p, 1).unwrap_err().to_string();
        assert!(e.contains(&format!("`{name}`")), "{e}");
    }
}

/// Eq. 2 cell by cell: every cell's velocity, as the stepping computes it, satisfies
///   ξ_s v_i(x) + ξ_c Σ_{x′∈N8(x)} Σ_j w_j(x′) [v_i(x) − v_j(x′)] = f_i(x)
/// at every site of its patch, for each reading of "j at x′" (φ-weighted, present, subdomain),
/// with w_j computed here from its definition and summed directly over the cells (not through
/// the lattice fields the solver uses). A wrong factor in the mobility 1/(ξ_s + ξ_c N) or in the
/// pull ξ_c S, a sign, or a weight of the wrong reading breaks it.
#[test]
fn every_cell_velocity_satisfies_the_friction_balance() {
    for weights in [FrictionWeights::Phi, FrictionWeights::Presence, FrictionWeights::Subdomain] {
        friction_balance_holds(weights);
    }
}

fn friction_balance_holds(weights: FrictionWeights) {
    let (l, w, h) = (64, 30, 30);
    let cells = vec![
        (Patch { x0: 10, y0: 10, w, h }, ellipse(w, h, 8.0, 6.0, 0.3)),
        (Patch { x0: 22, y0: 15, w, h }, ellipse(w, h, 7.0, 6.0, -0.5)),
    ];
    let (xi_s, xi_c) = (0.05, 0.7);
    let p = Params {
        xi_substrate: xi_s,
        xi_cell: xi_c,
        zeta: 0.4,
        friction_tolerance: 1e-11,
        friction_weights: weights,
        ..small(2, l)
    };
    let threshold = p.presence_threshold;
    let mut m = with_cells(p, cells, 0);
    m.evaluate_now().unwrap();
    // Every cell's weight and velocity on the lattice (zero off its patch).
    let maps: Vec<(Vec<f64>, Vec<[f64; 2]>)> = m
        .cells()
        .iter()
        .map(|c| {
            let (pt, phi, (vx, vy)) = (c.patch(), c.phi(), c.velocity());
            let (mut wgt, mut vel) = (vec![0.0; l * l], vec![[0.0; 2]; l * l]);
            for b in 0..pt.h {
                for a in 0..pt.w {
                    let x = (pt.y0 + b) * l + pt.x0 + a;
                    let phi = phi.at(a, b);
                    wgt[x] = match weights {
                        FrictionWeights::Phi => phi.clamp(0.0, 1.0),
                        FrictionWeights::Presence => f64::from(u8::from(phi > threshold)),
                        FrictionWeights::Subdomain => 1.0,
                    };
                    vel[x] = [vx.at(a, b), vy.at(a, b)];
                }
            }
            (wgt, vel)
        })
        .collect();
    let mut scale: f64 = 0.0;
    let mut worst: f64 = 0.0;
    for (i, c) in m.cells().iter().enumerate() {
        let (pt, (fx, fy)) = (c.patch(), c.force());
        for b in 1..pt.h - 1 {
            for a in 1..pt.w - 1 {
                let (gx, gy) = (pt.x0 + a, pt.y0 + b);
                let vi = maps[i].1[gy * l + gx];
                let mut lhs = [xi_s * vi[0], xi_s * vi[1]];
                for (dx, dy) in [(-1, -1), (0, -1), (1, -1), (-1, 0), (1, 0), (-1, 1), (0, 1), (1, 1)] {
                    let y = (gy as i64 + dy) as usize * l + (gx as i64 + dx) as usize;
                    for (wj, vj) in &maps {
                        lhs[0] += xi_c * wj[y] * (vi[0] - vj[y][0]);
                        lhs[1] += xi_c * wj[y] * (vi[1] - vj[y][1]);
                    }
                }
                let f = [fx.at(a, b), fy.at(a, b)];
                scale = scale.max(f[0].abs()).max(f[1].abs());
                worst = worst.max((lhs[0] - f[0]).abs()).max((lhs[1] - f[1]).abs());
            }
        }
    }
    assert!(scale > 1e-3, "the cells must carry forces: {scale}");
    assert!(worst < 1e-7 * scale, "{weights:?}: Eq. 2 misses by {worst} (largest force {scale})");
}

/// Heun's predictor–corrector is second order: halving Δt cuts the error at a fixed time about
/// fourfold. A lone cell growing from its initial disk, φ compared at t = 4 after steps of
/// Δt = 0.1, 0.05 and 0.025. Measured ratio 4.10; it falls to 2.02 with the predictor alone
/// (forward Euler) and to 1.88 with the corrector's ½Δt made 0.55Δt.
#[test]
fn heun_steps_converge_at_second_order() {
    let phi_at = |dt: f64| {
        let mut p = small(1, 48);
        p.relax_steps = 10_000;
        p.dt = dt;
        let mut m = Monolayer::new(p, 3).unwrap();
        m.advance((4.0 / dt).round() as u64).unwrap();
        m.state().cells.remove(0)
    };
    let [(p1, a), (p2, b), (p3, c)] = [0.1, 0.05, 0.025].map(phi_at);
    assert!(p1 == p2 && p2 == p3, "the patch moved: {p1:?} {p2:?} {p3:?}");
    let diff = |x: &[f64], y: &[f64]| x.iter().zip(y).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max);
    let (coarse, fine) = (diff(&a, &b), diff(&b, &c));
    let ratio = coarse / fine;
    assert!((3.3..4.7).contains(&ratio), "error ratio {ratio} ({coarse:.2e} → {fine:.2e}): not second order");
}

/// Heun's corrector counts the friction weights n = Σ_j w_j at φ* for the readings that depend
/// on φ, and keeps the predictor's n for subdomain weights, which depend only on the patches
/// (they move between steps, not within one). Both halves checked on one tissue over fixed
/// patches: for subdomain weights a recount at the new φ gives n's bits again; for φ weights
/// the corrector's n is not the predictor's (a corrector that kept it would leave it so).
#[test]
fn the_correctors_friction_weights_follow_phi_unless_they_count_patches() {
    let (l, w, h) = (64, 30, 30);
    let cells = || {
        vec![
            (Patch { x0: 10, y0: 10, w, h }, ellipse(w, h, 8.0, 6.0, 0.3)),
            (Patch { x0: 22, y0: 15, w, h }, ellipse(w, h, 7.0, 6.0, -0.5)),
        ]
    };
    let tissue = |weights| {
        let p = Params { xi_substrate: 0.05, xi_cell: 0.7, zeta: 0.4, friction_weights: weights, ..small(2, l) };
        with_cells(p, cells(), 0)
    };

    let mut m = tissue(FrictionWeights::Subdomain);
    m.evaluate_now().unwrap();
    let before = m.lattice().weight.clone();
    m.step_on_fixed_patches().unwrap();
    assert!(m.lattice().weight == before, "subdomain weights: the corrector's n is not the predictor's");
    m.evaluate_now().unwrap();
    assert!(m.lattice().weight == before, "subdomain weights: n moved with φ on fixed patches");

    let mut m = tissue(FrictionWeights::Phi);
    m.evaluate_now().unwrap();
    let predictor_n = m.lattice().weight.clone();
    m.step_on_fixed_patches().unwrap();
    assert!(m.lattice().weight != predictor_n, "φ weights: the corrector kept the predictor's n");
}

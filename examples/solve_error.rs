//! How far the friction solve's tolerance, and how its corrector starts, move the trajectory,
//! measured against the time step's own error (docs/performance.md, "The corrector's guess").
//!
//! Full size, the defaults (χ = 0.001, ζ = 0.5), seed 1: 3,000 relaxation steps at Δt = 0.1,
//! then T time units of activity from that one state, with Δt, the tolerance and the corrector's
//! initial guess varied. Printed for T = 20 and 100: the largest |ΔΣφ| over the box against
//! Δt = 0.0125 at tolerance 1e-10 (the reference: the time step's error and the solve's
//! together), against Δt = 0.1 at 1e-10 (the solve's error alone), and the iterations per
//! solve.
//!
//!   cargo run --release --example solve_error
//!
//! "without the shift" starts every corrector from the predictor's solution alone, as the core
//! did before 2026-12-04: the state is passed through `State` with its corrector shift zeroed
//! before each step, which leaves everything else bit for bit (tests/full_size.rs,
//! `resume_from_checkpoint_is_bit_identical`).

use monolayer::{Monolayer, Params};

const RELAX_STEPS: u64 = 3_000;
const TIMES: [f64; 2] = [20.0, 100.0];

struct Variant {
    name: &'static str,
    dt: f64,
    tolerance: f64,
    shift: bool,
}

/// Σφ at each of `TIMES`, and the mean iterations per solve.
fn run(relaxed: &Monolayer, v: &Variant) -> (Vec<Vec<f64>>, f64) {
    let mut m = relaxed.clone();
    let p = Params { dt: v.dt, friction_tolerance: v.tolerance, ..m.params().clone() };
    m.set_params(p.clone()).expect("valid parameters");
    let (mut solves, mut iterations) = (0u64, 0u64);
    let mut sums = Vec::new();
    let mut steps_done = 0u64;
    for t in TIMES {
        let until = (t / v.dt).round() as u64;
        while steps_done < until {
            if !v.shift {
                let mut state = m.state();
                state.corrector_shift.iter_mut().for_each(|d| *d = Default::default());
                m = Monolayer::from_state(p.clone(), m.seed(), state).expect("the same state");
            }
            let before = m.counters().clone();
            m.step().expect("the run stays stable");
            let after = m.counters();
            solves += after.solves - before.solves;
            iterations += after.iterations - before.iterations;
            steps_done += 1;
        }
        sums.push(m.phi_sum().to_vec());
    }
    (sums, iterations as f64 / solves.max(1) as f64)
}

fn max_difference(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| (x - y).abs()).fold(0.0, f64::max)
}

fn main() {
    let p = Params::default();
    let mut relaxed = Monolayer::new(Params { relax_steps: RELAX_STEPS, ..p.clone() }, 1).expect("valid defaults");
    relaxed.advance(RELAX_STEPS).expect("relaxation runs");
    eprintln!("relaxed {RELAX_STEPS} steps; χ = {}, ζ = {}", p.xi_substrate / p.xi_cell, p.zeta);

    let reference = Variant { name: "Δt 0.0125, 1e-10", dt: 0.0125, tolerance: 1e-10, shift: true };
    let exact = Variant { name: "Δt 0.1, 1e-10", dt: 0.1, tolerance: 1e-10, shift: true };
    let variants = [
        Variant { name: "Δt 0.1, 1e-5, with the shift", dt: 0.1, tolerance: 1e-5, shift: true },
        Variant { name: "Δt 0.1, 1e-5, without the shift", dt: 0.1, tolerance: 1e-5, shift: false },
        Variant { name: "Δt 0.1, 1e-4, with the shift (the default)", dt: 0.1, tolerance: 1e-4, shift: true },
        Variant { name: "Δt 0.1, 1e-4, without the shift", dt: 0.1, tolerance: 1e-4, shift: false },
    ];
    let (ref_sums, ref_its) = run(&relaxed, &reference);
    eprintln!("{}: done", reference.name);
    let (exact_sums, exact_its) = run(&relaxed, &exact);
    eprintln!("{}: done", exact.name);

    let header: Vec<String> = TIMES.iter().map(|t| format!("T = {t}: vs reference | vs Δt 0.1 at 1e-10")).collect();
    println!("| variant | {} | iterations per solve |", header.join(" | "));
    println!("|---|{}---|", "---|---|".repeat(TIMES.len()));
    let row = |name: &str, sums: &[Vec<f64>], its: f64, vs_exact: bool| {
        let cells: Vec<String> = (0..TIMES.len())
            .map(|k| {
                let e =
                    if vs_exact { format!("{:.1e}", max_difference(&sums[k], &exact_sums[k])) } else { "—".into() };
                format!("{:.1e} | {e}", max_difference(&sums[k], &ref_sums[k]))
            })
            .collect();
        println!("| {name} | {} | {its:.2} |", cells.join(" | "));
    };
    row(reference.name, &ref_sums, ref_its, true);
    row(exact.name, &exact_sums, exact_its, false);
    for v in &variants {
        let (sums, its) = run(&relaxed, v);
        row(v.name, &sums, its, true);
    }
}

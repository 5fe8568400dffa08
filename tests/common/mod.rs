//! Helpers shared by the integration tests.
#![allow(dead_code)]

use std::sync::OnceLock;

use monolayer::lattice::Patch;
use monolayer::{Monolayer, Params, State};
use num_complex::Complex64 as C64;
use rustfft::FftPlanner;

/// The paper's full size after its full 10,000-step relaxation (seed 1), computed once per test
/// binary.
pub fn relaxed_full_size() -> &'static Monolayer {
    static RELAXED: OnceLock<Monolayer> = OnceLock::new();
    RELAXED.get_or_init(|| {
        let p = Params::default();
        let mut m = Monolayer::new(p.clone(), 1).expect("valid defaults");
        m.advance(p.relax_steps).expect("relaxation runs");
        m
    })
}

/// A monolayer with hand-made cells (each φ on a w×h patch, unpadded, row by row).
pub fn with_cells(params: Params, cells: Vec<(Patch, Vec<f64>)>, step: u64) -> Monolayer {
    let l = params.box_size;
    let cells = cells
        .into_iter()
        .map(|(p, interior)| {
            let mut padded = vec![0.0; p.padded_len()];
            for b in 0..p.h {
                for a in 0..p.w {
                    padded[p.idx(a, b)] = interior[b * p.w + a];
                }
            }
            (p, padded)
        })
        .collect();
    let zero = vec![C64::new(0.0, 0.0); l * l];
    let state = State { step, cells, warm_start: zero.clone(), corrector_shift: zero, substrate: vec![1.0; l * l] };
    Monolayer::from_state(params, 1, state).expect("valid hand-made state")
}

/// A smooth disk or ellipse φ on a w×h patch: semi-axes (a, b), long axis at angle θ.
pub fn ellipse(w: usize, h: usize, a: f64, b: f64, theta: f64) -> Vec<f64> {
    let (cx, cy) = ((w as f64 - 1.0) / 2.0, (h as f64 - 1.0) / 2.0);
    let (c, s) = (theta.cos(), theta.sin());
    let mut phi = vec![0.0; w * h];
    for j in 0..h {
        for i in 0..w {
            let (dx, dy) = (i as f64 - cx, j as f64 - cy);
            let (u, v) = (c * dx + s * dy, -s * dx + c * dy);
            let r = ((u / a).powi(2) + (v / b).powi(2)).sqrt();
            // Interface width ~ λ/2 = 1 site, like the relaxed profile.
            phi[j * w + i] = 1.0 / (1.0 + ((r - 1.0) * a.min(b)).exp());
        }
    }
    phi
}

/// Periodic, radially binned autocorrelation C(r) = ⟨v(x)·v(x + r)⟩ / ⟨v·v⟩ of a vector field
/// (components as re and im), by FFT; bins of width 1.
pub fn correlation(field: &[C64], l: usize) -> Vec<f64> {
    let mut planner = FftPlanner::<f64>::new();
    let fwd = planner.plan_fft_forward(l);
    let inv = planner.plan_fft_inverse(l);
    let fft2 = |data: &mut Vec<C64>, f: &std::sync::Arc<dyn rustfft::Fft<f64>>| {
        for row in data.chunks_exact_mut(l) {
            f.process(row);
        }
        let mut t = vec![C64::new(0.0, 0.0); l * l];
        for y in 0..l {
            for x in 0..l {
                t[x * l + y] = data[y * l + x];
            }
        }
        for row in t.chunks_exact_mut(l) {
            f.process(row);
        }
        for y in 0..l {
            for x in 0..l {
                data[y * l + x] = t[x * l + y];
            }
        }
    };
    // Each real component separately: Σ_x a(x) a(x + r) = IFFT(|â|²).
    let mut total = vec![0.0; l * l];
    for comp in 0..2 {
        let mut d: Vec<C64> = field.iter().map(|z| C64::new(if comp == 0 { z.re } else { z.im }, 0.0)).collect();
        fft2(&mut d, &fwd);
        for z in d.iter_mut() {
            *z = C64::new(z.norm_sqr(), 0.0);
        }
        fft2(&mut d, &inv);
        for (t, z) in total.iter_mut().zip(&d) {
            *t += z.re;
        }
    }
    let zero = total[0];
    let bins = l / 2;
    let (mut sum, mut count) = (vec![0.0; bins], vec![0usize; bins]);
    for y in 0..l {
        for x in 0..l {
            let dx = x.min(l - x) as f64;
            let dy = y.min(l - y) as f64;
            let r = (dx * dx + dy * dy).sqrt().round() as usize;
            if r < bins {
                sum[r] += total[y * l + x] / zero;
                count[r] += 1;
            }
        }
    }
    sum.iter().zip(&count).map(|(s, &c)| s / c.max(1) as f64).collect()
}

/// First r at which C(r) drops below 1/e (linear interpolation between bins).
pub fn correlation_length(c: &[f64]) -> f64 {
    let target = (-1.0f64).exp();
    for r in 1..c.len() {
        if c[r] < target {
            return (r - 1) as f64 + (c[r - 1] - target) / (c[r - 1] - c[r]);
        }
    }
    c.len() as f64
}

/// All φ of all cells, bit for bit.
pub fn phi_bits(m: &Monolayer) -> Vec<u64> {
    m.cells().iter().flat_map(|c| c.phi().data.iter().map(|v| v.to_bits())).collect()
}

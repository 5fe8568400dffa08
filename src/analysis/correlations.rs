//! Velocity and nematic correlations (paper Eqs. S5, S6) of the unsmoothed coarse-grained fields:
//!
//!   C_v(r) = ⟨v(x)·v(x′)⟩ / ⟨v·v⟩,    C_Q(r) = ⟨Q(x):Q(x′)⟩ / ⟨Q:Q⟩,   r = |x − x′|,
//!
//! averaged over all pairs of sites on the periodic box, binned by r rounded to the nearest site
//! (minimum-image distances, r ≤ L/2, where every direction is sampled). As printed, the means
//! are not subtracted. Both are periodic autocorrelations, computed by FFT (`rustfft`): with
//! z = a_x + i a_y, Re IFFT(|FFT z|²)(r) = Σ_x a(x)·a(x + r); for the traceless symmetric Q,
//! Q:Q′ = 2(Q_xx Q′_xx + Q_xy Q′_xy), and the 2 cancels in the ratio.
//!
//! The correlation length is where C first drops below 1/e, linearly interpolated between bins.

use std::sync::Arc;

use num_complex::Complex64 as C64;
use rustfft::{Fft, FftPlanner};

/// Correlation functions with their FFT plans and buffers, for one lattice size.
pub struct Correlator {
    l: usize,
    forward: Arc<dyn Fft<f64>>,
    inverse: Arc<dyn Fft<f64>>,
    buf: Vec<C64>,
    scratch: Vec<C64>,
    /// Radial bin of each lattice displacement (u16::MAX beyond L/2).
    bin: Vec<u16>,
    count: Vec<usize>,
}

impl std::fmt::Debug for Correlator {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Correlator").field("l", &self.l).finish_non_exhaustive()
    }
}

impl Correlator {
    pub fn new(l: usize) -> Self {
        let mut planner = FftPlanner::new();
        let forward = planner.plan_fft_forward(l);
        let inverse = planner.plan_fft_inverse(l);
        let scratch_len = forward.get_inplace_scratch_len().max(inverse.get_inplace_scratch_len());
        let bins = l / 2 + 1;
        let mut bin = vec![u16::MAX; l * l];
        let mut count = vec![0; bins];
        for y in 0..l {
            for x in 0..l {
                let (dx, dy) = (x.min(l - x) as f64, y.min(l - y) as f64);
                let r = dx.hypot(dy).round() as usize;
                if r < bins {
                    bin[y * l + x] = r as u16;
                    count[r] += 1;
                }
            }
        }
        Correlator {
            l,
            forward,
            inverse,
            buf: vec![C64::new(0.0, 0.0); l * l],
            scratch: vec![C64::new(0.0, 0.0); scratch_len],
            bin,
            count,
        }
    }

    /// Number of radial bins, r = 0, 1, …, L/2.
    pub fn bins(&self) -> usize {
        self.count.len()
    }

    /// C(r) of the 2-component field (ax, ay), normalised by C(0), into `out` (resized to
    /// [`Self::bins`]). A field that is zero everywhere has no correlation: `out` is all NaN.
    pub fn correlate(&mut self, ax: &[f64], ay: &[f64], out: &mut Vec<f64>) {
        let l = self.l;
        for ((z, &a), &b) in self.buf.iter_mut().zip(ax).zip(ay) {
            *z = C64::new(a, b);
        }
        // Rows, transpose, rows: the 2-D transform (transposed).
        self.forward.process_with_scratch(&mut self.buf, &mut self.scratch);
        transpose(&mut self.buf, l);
        self.forward.process_with_scratch(&mut self.buf, &mut self.scratch);
        for z in self.buf.iter_mut() {
            *z = C64::new(z.norm_sqr(), 0.0);
        }
        self.inverse.process_with_scratch(&mut self.buf, &mut self.scratch);
        transpose(&mut self.buf, l);
        self.inverse.process_with_scratch(&mut self.buf, &mut self.scratch);
        out.clear();
        out.resize(self.bins(), 0.0);
        for (z, &b) in self.buf.iter().zip(&self.bin) {
            if b != u16::MAX {
                out[b as usize] += z.re;
            }
        }
        let zero = self.buf[0].re;
        for (o, &n) in out.iter_mut().zip(&self.count) {
            *o /= n as f64 * zero;
        }
    }
}

/// In-place transpose of a square L×L array.
fn transpose(a: &mut [C64], l: usize) {
    for y in 0..l {
        for x in y + 1..l {
            a.swap(y * l + x, x * l + y);
        }
    }
}

/// The first r at which C(r) drops below 1/e, interpolated linearly between the bins on either
/// side; None if it never does within the bins (or C is not a number).
pub fn correlation_length(c: &[f64]) -> Option<f64> {
    let target = (-1.0f64).exp();
    (1..c.len()).find(|&r| c[r] < target).map(|r| (r - 1) as f64 + (c[r - 1] - target) / (c[r - 1] - c[r]))
}

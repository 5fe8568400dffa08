//! A small two-dimensional FFT whose every bit is the same natively and in WebAssembly.
//!
//! Why not `rustfft`: its twiddle factors come from the platform's `cos`/`sin` (glibc natively,
//! a musl-derived libm in wasm). Measured on this project's machine, the two disagree in the last
//! bit for 6 % of the angles 2πk/n with n ≤ 1024, and it picks SIMD algorithms by CPU. The
//! friction solve applies this FFT inside a Krylov iteration, so any bit of difference would
//! make the native and browser trajectories part. Here the twiddles come from the pure-Rust
//! `libm` crate on every target, and the algorithm (a Stockham autosort, any length, prime
//! factors by direct sums) is the same everywhere. It is tested against `rustfft`.

use num_complex::Complex64 as C64;

/// Forward and inverse FFTs of an L×L complex array stored row by row.
#[derive(Clone, Debug)]
pub struct Fft2 {
    l: usize,
    factors: Vec<usize>,
    /// W_L^j = exp(−2πi j / L), j = 0..L.
    twiddles: Vec<C64>,
    scratch: Vec<C64>,
    work: Vec<C64>,
}

fn prime_factors(mut n: usize) -> Vec<usize> {
    let mut f = Vec::new();
    // Radix 4 first: fewer passes than two radix-2 passes.
    while n % 4 == 0 {
        f.push(4);
        n /= 4;
    }
    let mut p = 2;
    while n > 1 {
        while n % p == 0 {
            f.push(p);
            n /= p;
        }
        p += 1;
    }
    f
}

impl Fft2 {
    pub fn new(l: usize) -> Self {
        let twiddles = (0..l)
            .map(|j| {
                let a = -2.0 * core::f64::consts::PI * j as f64 / l as f64;
                C64::new(libm::cos(a), libm::sin(a))
            })
            .collect();
        Fft2 { l, factors: prime_factors(l), twiddles, scratch: vec![C64::new(0.0, 0.0); l * l], work: Vec::new() }
    }

    pub fn len(&self) -> usize {
        self.l
    }

    pub fn is_empty(&self) -> bool {
        self.l == 0
    }

    /// cos(2π j / L), from the same table the transform uses.
    pub fn cos_table(&self, j: usize) -> f64 {
        self.twiddles[j % self.l].re
    }

    /// In-place forward transform, X(k) = Σ_x x(x) exp(−2πi k·x / L), unnormalised.
    pub fn forward(&mut self, data: &mut [C64]) {
        self.forward_transposed(data);
        transpose(data, &mut self.scratch, self.l);
        data.copy_from_slice(&self.scratch);
    }

    /// In-place inverse transform, unnormalised (forward then inverse multiplies by L²).
    pub fn inverse(&mut self, data: &mut [C64]) {
        transpose(data, &mut self.scratch, self.l);
        data.copy_from_slice(&self.scratch);
        self.inverse_transposed(data);
    }

    /// Forward transform leaving the spectrum transposed: on return `data[kx·L + ky]` holds
    /// X(kx, ky). Saves two transposes when the caller only multiplies by a symmetric symbol
    /// and transforms back with [`Fft2::inverse_transposed`].
    pub fn forward_transposed(&mut self, data: &mut [C64]) {
        let l = self.l;
        assert_eq!(data.len(), l * l);
        // Along y for every x: the elements are whole rows, L lanes each.
        self.columns(data);
        transpose(data, &mut self.scratch, l);
        // Along x for every ky.
        self.columns_scratch();
        data.copy_from_slice(&self.scratch);
    }

    /// Inverse of [`Fft2::forward_transposed`] (unnormalised): takes `data[kx·L + ky]`, returns
    /// the field in natural order `data[y·L + x]`.
    pub fn inverse_transposed(&mut self, data: &mut [C64]) {
        let l = self.l;
        assert_eq!(data.len(), l * l);
        // The inverse is conj ∘ forward ∘ conj, pass by pass.
        for z in data.iter_mut() {
            *z = z.conj();
        }
        self.columns(data);
        transpose(data, &mut self.scratch, l);
        self.columns_scratch();
        for (d, z) in data.iter_mut().zip(&self.scratch) {
            *d = z.conj();
        }
    }

    /// One-dimensional transforms along the slow index of `data`, every lane at once. (Lanes
    /// could be split across threads, but a pass takes ~0.1 ms at L = 140: waking the workers
    /// cost more than it saved, measured.)
    fn columns(&mut self, data: &mut [C64]) {
        let mut work = std::mem::take(&mut self.work);
        work.resize(data.len(), C64::new(0.0, 0.0));
        stockham(&self.factors, &self.twiddles, data, &mut work, self.l);
        self.work = work;
    }

    fn columns_scratch(&mut self) {
        let mut s = std::mem::take(&mut self.scratch);
        self.columns(&mut s);
        self.scratch = s;
    }
}

/// dst = srcᵀ for L×L arrays, in cache-sized tiles.
fn transpose(src: &[C64], dst: &mut [C64], l: usize) {
    const TILE: usize = 16;
    for y0 in (0..l).step_by(TILE) {
        for x0 in (0..l).step_by(TILE) {
            for y in y0..(y0 + TILE).min(l) {
                for x in x0..(x0 + TILE).min(l) {
                    dst[x * l + y] = src[y * l + x];
                }
            }
        }
    }
}

/// Stockham autosort FFT of n = Π factors elements, each element `width` contiguous lanes
/// transformed independently. Decimation in frequency: stage with radix p and stride s writes
/// y[q + s(p·i + k)] = W_{n/s}^{i·k} Σ_r x[q + s(i + m·r)] ω_p^{r·k}, m = n/(s·p).
fn stockham(factors: &[usize], tw: &[C64], x: &mut [C64], y: &mut [C64], width: usize) {
    let n = tw.len();
    let mut s = 1;
    let mut in_x = true;
    for &p in factors {
        let m = n / (s * p);
        let (src, dst): (&[C64], &mut [C64]) = if in_x { (&*x, &mut *y) } else { (&*y, &mut *x) };
        let omega: Vec<C64> = (0..p).map(|j| tw[j * (n / p)]).collect();
        for i in 0..m {
            // W_{n/s}^{i·k} = W_n^{i·k·s}, hoisted out of the lane loops.
            let w: Vec<C64> = (0..p).map(|k| tw[(i * k * s) % n]).collect();
            for q in 0..s {
                let src_row = |r: usize| (q + s * (i + m * r)) * width;
                let dst_row = |k: usize| (q + s * (p * i + k)) * width;
                butterfly(p, &omega, &w, src, dst, src_row, dst_row, width);
            }
        }
        s *= p;
        in_x = !in_x;
    }
    if !in_x {
        x.copy_from_slice(&y[..x.len()]);
    }
}

/// One radix-p butterfly over `width` lanes: dst row k = w_k Σ_r ω^{rk} src row r.
#[allow(clippy::too_many_arguments)]
#[inline]
fn butterfly(
    p: usize,
    omega: &[C64],
    w: &[C64],
    src: &[C64],
    dst: &mut [C64],
    src_row: impl Fn(usize) -> usize,
    dst_row: impl Fn(usize) -> usize,
    width: usize,
) {
    match p {
        2 => {
            let a = &src[src_row(0)..][..width];
            let b = &src[src_row(1)..][..width];
            let (d0, d1) = (dst_row(0), dst_row(1));
            let w1 = w[1];
            for j in 0..width {
                let (u, v) = (a[j], b[j]);
                dst[d0 + j] = u + v;
                dst[d1 + j] = (u - v) * w1;
            }
        }
        4 => {
            let a0 = &src[src_row(0)..][..width];
            let a1 = &src[src_row(1)..][..width];
            let a2 = &src[src_row(2)..][..width];
            let a3 = &src[src_row(3)..][..width];
            let d = [dst_row(0), dst_row(1), dst_row(2), dst_row(3)];
            let mi = |z: C64| C64::new(z.im, -z.re); // −i·z, ω₄ = −i
            for j in 0..width {
                let (s02, d02) = (a0[j] + a2[j], a0[j] - a2[j]);
                let (s13, d13) = (a1[j] + a3[j], mi(a1[j] - a3[j]));
                dst[d[0] + j] = s02 + s13;
                dst[d[1] + j] = (d02 + d13) * w[1];
                dst[d[2] + j] = (s02 - s13) * w[2];
                dst[d[3] + j] = (d02 - d13) * w[3];
            }
        }
        3 | 5 | 7 => {
            // Odd primes: outputs k and p − k share the sums S_r = a_r + a_{p−r} and
            // differences D_r = a_r − a_{p−r}:  y_k = A_k − iB_k,  y_{p−k} = A_k + iB_k with
            // A_k = a_0 + Σ_r cos(2πrk/p) S_r and B_k = Σ_r sin(2πrk/p) D_r, r = 1..(p−1)/2.
            let h = (p - 1) / 2;
            let rows: [usize; 7] = std::array::from_fn(|r| if r < p { src_row(r) } else { 0 });
            let outs: [usize; 7] = std::array::from_fn(|k| if k < p { dst_row(k) } else { 0 });
            // ω^{rk} = cos θ − i sin θ, so cos θ = Re ω^{rk} and sin θ = −Im ω^{rk}.
            let mut cs = [[0.0f64; 3]; 3];
            let mut sn = [[0.0f64; 3]; 3];
            for k in 1..=h {
                for r in 1..=h {
                    let om = omega[(r * k) % p];
                    cs[k - 1][r - 1] = om.re;
                    sn[k - 1][r - 1] = -om.im;
                }
            }
            let mut sum = [C64::new(0.0, 0.0); 3];
            let mut dif = [C64::new(0.0, 0.0); 3];
            for j in 0..width {
                let a0 = src[rows[0] + j];
                let mut y0 = a0;
                for r in 1..=h {
                    let (u, v) = (src[rows[r] + j], src[rows[p - r] + j]);
                    sum[r - 1] = u + v;
                    dif[r - 1] = u - v;
                    y0 += sum[r - 1];
                }
                dst[outs[0] + j] = y0;
                for k in 1..=h {
                    let (mut ar, mut ai, mut br, mut bi) = (a0.re, a0.im, 0.0, 0.0);
                    for r in 0..h {
                        ar += cs[k - 1][r] * sum[r].re;
                        ai += cs[k - 1][r] * sum[r].im;
                        br += sn[k - 1][r] * dif[r].re;
                        bi += sn[k - 1][r] * dif[r].im;
                    }
                    // −iB = (bi, −br), +iB = (−bi, br)
                    dst[outs[k] + j] = C64::new(ar + bi, ai - br) * w[k];
                    dst[outs[p - k] + j] = C64::new(ar - bi, ai + br) * w[p - k];
                }
            }
        }
        _ => {
            for k in 0..p {
                let o = dst_row(k);
                dst[o..o + width].copy_from_slice(&src[src_row(0)..][..width]);
                for r in 1..p {
                    let om = omega[(r * k) % p];
                    let a = &src[src_row(r)..][..width];
                    for (d, &v) in dst[o..o + width].iter_mut().zip(a) {
                        *d += v * om;
                    }
                }
                if k != 0 {
                    let wk = w[k];
                    for d in dst[o..o + width].iter_mut() {
                        *d *= wk;
                    }
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use rustfft::FftPlanner;

    fn reference_fft2(data: &[C64], l: usize) -> Vec<C64> {
        let mut planner = FftPlanner::<f64>::new();
        let f = planner.plan_fft_forward(l);
        let mut a = data.to_vec();
        for row in a.chunks_exact_mut(l) {
            f.process(row);
        }
        let mut t = vec![C64::new(0.0, 0.0); l * l];
        for y in 0..l {
            for x in 0..l {
                t[x * l + y] = a[y * l + x];
            }
        }
        for row in t.chunks_exact_mut(l) {
            f.process(row);
        }
        let mut out = vec![C64::new(0.0, 0.0); l * l];
        for y in 0..l {
            for x in 0..l {
                out[y * l + x] = t[x * l + y];
            }
        }
        out
    }

    fn test_field(l: usize) -> Vec<C64> {
        (0..l * l).map(|i| C64::new(((i * 37) % 17) as f64 - 8.0, ((i * 11) % 13) as f64 * 0.25)).collect()
    }

    #[test]
    fn matches_rustfft_for_many_sizes() {
        for l in [16, 20, 21, 35, 49, 64, 70, 96, 140] {
            let data = test_field(l);
            let expect = reference_fft2(&data, l);
            let mut got = data.clone();
            let mut fft = Fft2::new(l);
            fft.forward(&mut got);
            let scale = expect.iter().map(|z| z.norm()).fold(0.0, f64::max);
            let err = got.iter().zip(&expect).map(|(a, b)| (a - b).norm()).fold(0.0, f64::max);
            assert!(err < 1e-12 * scale * (l as f64), "L = {l}: error {err}");
        }
    }

    #[test]
    fn inverse_undoes_forward() {
        let l = 30;
        let data = test_field(l);
        let mut fft = Fft2::new(l);
        let mut z = data.clone();
        fft.forward(&mut z);
        fft.inverse(&mut z);
        for (a, b) in z.iter().zip(&data) {
            assert!((a / (l * l) as f64 - b).norm() < 1e-12);
        }
    }

    #[test]
    fn transposed_spectrum_round_trips() {
        let l = 35;
        let data = test_field(l);
        let expect = reference_fft2(&data, l);
        let mut fft = Fft2::new(l);
        let mut z = data.clone();
        fft.forward_transposed(&mut z);
        for kx in 0..l {
            for ky in 0..l {
                assert!((z[kx * l + ky] - expect[ky * l + kx]).norm() < 1e-9);
            }
        }
        fft.inverse_transposed(&mut z);
        for (a, b) in z.iter().zip(&data) {
            assert!((a / (l * l) as f64 - b).norm() < 1e-12);
        }
    }

    #[test]
    fn factors_multiply_back() {
        for n in [2, 7, 12, 140, 97, 128] {
            assert_eq!(prime_factors(n).iter().product::<usize>(), n);
        }
    }
}

//! Coarse-grained fields of the monolayer (paper Sec. A, Eq. S4) and what is derived from them.
//!
//!   A(x) = Σ_i a_i(x) φ_i(x)
//!
//! for the velocity (a_i = v_i), the active force (a_i = f^a_i = −ζ Q̂_i·∇φ_i, Eq. 4) and the
//! nematic field (a_i = Q̂_i, constant over the cell: "Q_i(x) ≡ Q_i"). Then the periodic sliding
//! window mean, the isotropic strain rate ε̇ = ∇·v/2 and the divergence of the active force, all
//! on the periodic L×L lattice, row-major (index y·L + x), components stored apart.

use num_complex::Complex64 as C64;

use crate::model::{gradient, load, Patch, Real};

/// The lattice fields of Eq. S4, one array per component.
#[derive(Clone, Debug)]
pub struct CoarseFields {
    pub l: usize,
    /// Σ_i φ_i.
    pub phi_sum: Vec<f64>,
    /// Σ_i φ_i v_i.
    pub vx: Vec<f64>,
    pub vy: Vec<f64>,
    /// Σ_i φ_i f^a_i.
    pub fx: Vec<f64>,
    pub fy: Vec<f64>,
    /// Σ_i φ_i Q̂_i: (Q_xx, Q_xy) of the traceless symmetric tensor.
    pub qxx: Vec<f64>,
    pub qxy: Vec<f64>,
}

impl CoarseFields {
    pub fn new(l: usize) -> Self {
        let z = || vec![0.0; l * l];
        CoarseFields { l, phi_sum: z(), vx: z(), vy: z(), fx: z(), fy: z(), qxx: z(), qxy: z() }
    }

    /// Zeroes every field (the start of a gather).
    pub fn clear(&mut self) {
        for f in self.components_mut() {
            f.fill(0.0);
        }
        self.phi_sum.fill(0.0);
    }

    /// The six smoothed components: velocity, active force, nematic.
    fn components_mut(&mut self) -> [&mut Vec<f64>; 6] {
        [&mut self.vx, &mut self.vy, &mut self.fx, &mut self.fy, &mut self.qxx, &mut self.qxy]
    }

    /// Adds one cell: φ_i on its padded patch storage, its Q̂_i, and optionally its velocity v_i
    /// (padded like φ). Frames store only Σ_i φ_i v_i; they set it with [`Self::set_velocity`].
    /// The active force is recomputed from φ_i and Q̂_i exactly as
    /// [`force_density`](crate::model::force_density) does, so live and offline analyses agree.
    pub fn add_cell<T: Real>(&mut self, patch: Patch, phi: &[T], q_hat: [f64; 2], zeta: f64, v: Option<(&[T], &[T])>) {
        let l = self.l;
        let s = patch.stride();
        let [qxx, qxy] = q_hat;
        for b in 0..patch.h {
            for run in patch.row_runs(b, l).into_iter().flatten() {
                for k in 0..run.len {
                    let (i, g) = (run.padded + k, run.global + k);
                    let p = load(phi[i]);
                    // Central differences, as the dynamics takes ∇φ_i (the halo is φ = 0).
                    let (px, py) = gradient(phi, i, s);
                    self.phi_sum[g] += p;
                    self.fx[g] -= p * zeta * (qxx * px + qxy * py);
                    self.fy[g] -= p * zeta * (qxy * px - qxx * py);
                    self.qxx[g] += p * qxx;
                    self.qxy[g] += p * qxy;
                    if let Some((vx, vy)) = v {
                        self.vx[g] += p * load(vx[i]);
                        self.vy[g] += p * load(vy[i]);
                    }
                }
            }
        }
    }

    /// Sets the coarse-grained velocity from a lattice array (v_x, v_y as re, im).
    pub fn set_velocity(&mut self, v: &[C64]) {
        for ((x, y), z) in self.vx.iter_mut().zip(self.vy.iter_mut()).zip(v) {
            *x = z.re;
            *y = z.im;
        }
    }

    /// Every component of `src` smoothed by [`window_mean`] into `self` (Σφ is copied as is: it
    /// is read unsmoothed, for the void test).
    pub fn smooth_from(&mut self, src: &CoarseFields, half: usize, row: &mut Vec<f64>, tmp: &mut Vec<f64>) {
        self.phi_sum.copy_from_slice(&src.phi_sum);
        let (l, srcs) = (self.l, [&src.vx, &src.vy, &src.fx, &src.fy, &src.qxx, &src.qxy]);
        for (dst, s) in self.components_mut().into_iter().zip(srcs) {
            window_mean(s, dst, tmp, row, l, half);
        }
    }
}

/// Periodic sliding-window mean over the (2h+1)×(2h+1) sites centred on each site, in O(L²)
/// whatever h: a running sum along each row, then a running sum of whole rows down the columns
/// (row-wise, so it stays in cache). `tmp` (L² long) and `row` (L long) are scratch.
///
/// The paper's window is "2R×2R"; with h = R it spans 2R + 1 sites, centred, so that smoothing
/// does not shift the field by half a site (an even window has no centre site).
pub fn window_mean(src: &[f64], dst: &mut [f64], tmp: &mut Vec<f64>, row: &mut Vec<f64>, l: usize, h: usize) {
    assert!(2 * h < l, "window of {} sites does not fit the {l}×{l} box", 2 * h + 1);
    assert_eq!(src.len(), l * l);
    tmp.resize(l * l, 0.0);
    let n = (2 * h + 1) as f64;
    // Horizontal sums, along each row extended by h sites of wrap on either side (`row`).
    row.resize(l + 2 * h, 0.0);
    for y in 0..l {
        let s = &src[y * l..][..l];
        row[..h].copy_from_slice(&s[l - h..]);
        row[h..h + l].copy_from_slice(s);
        row[h + l..].copy_from_slice(&s[..h]);
        let t = &mut tmp[y * l..][..l];
        let mut acc: f64 = row[..=2 * h].iter().sum();
        for x in 0..l {
            t[x] = acc;
            if x + 1 < l {
                acc += row[x + 2 * h + 1] - row[x];
            }
        }
    }
    row.truncate(l);
    // Vertical sums of the horizontal sums, a whole row at a time.
    row.fill(0.0);
    for k in 0..=2 * h {
        let r = (k + l - h) % l;
        for (a, t) in row.iter_mut().zip(&tmp[r * l..][..l]) {
            *a += t;
        }
    }
    let inv = 1.0 / (n * n);
    for y in 0..l {
        for (d, a) in dst[y * l..][..l].iter_mut().zip(row.iter()) {
            *d = a * inv;
        }
        let (add, sub) = ((y + h + 1) % l, (y + l - h) % l);
        for x in 0..l {
            row[x] += tmp[add * l + x] - tmp[sub * l + x];
        }
    }
}

/// ∇·(ax, ay) by central differences on the periodic lattice, times `scale`.
pub fn divergence(ax: &[f64], ay: &[f64], out: &mut [f64], l: usize, scale: f64) {
    for y in 0..l {
        let (up, dn) = (((y + 1) % l) * l, ((y + l - 1) % l) * l);
        for x in 0..l {
            let (r, lf) = ((x + 1) % l, (x + l - 1) % l);
            let d = 0.5 * (ax[y * l + r] - ax[y * l + lf]) + 0.5 * (ay[up + x] - ay[dn + x]);
            out[y * l + x] = scale * d;
        }
    }
}

/// The isotropic strain rate ε̇ = ∇·v / 2 of a (smoothed) velocity field.
pub fn strain_rate(vx: &[f64], vy: &[f64], out: &mut [f64], l: usize) {
    divergence(vx, vy, out, l, 0.5);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn window_mean_of_a_constant_is_the_constant() {
        let l = 12;
        let src = vec![3.5; l * l];
        let mut dst = vec![0.0; l * l];
        window_mean(&src, &mut dst, &mut Vec::new(), &mut Vec::new(), l, 4);
        assert!(dst.iter().all(|&v| (v - 3.5).abs() < 1e-12));
    }

    #[test]
    fn divergence_of_a_linear_source() {
        // v = (x, y) locally: ∇·v = 2 away from the periodic seam.
        let l = 10;
        let vx: Vec<f64> = (0..l * l).map(|i| (i % l) as f64).collect();
        let vy: Vec<f64> = (0..l * l).map(|i| (i / l) as f64).collect();
        let mut out = vec![0.0; l * l];
        strain_rate(&vx, &vy, &mut out, l);
        assert!((out[5 * l + 5] - 1.0).abs() < 1e-12);
    }
}

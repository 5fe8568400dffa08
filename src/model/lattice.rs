//! The periodic L×L lattice and the rectangular patches that cells live on.
//!
//! A patch is a w×h window of the lattice whose origin may sit anywhere: it wraps around the
//! periodic edges. Its storage has a one-site ring of zeros around it (the halo), so that every
//! stencil in the kernels reads φ ≡ 0 outside the patch without a bounds test.

use crate::model::precision::{load, Real};
use std::ops::Add;

/// A w×h window of the periodic L×L lattice, with origin (x0, y0) ∈ [0, L)².
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Patch {
    pub x0: usize,
    pub y0: usize,
    pub w: usize,
    pub h: usize,
}

/// A contiguous piece of one patch row that is also contiguous on the lattice.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Run {
    /// Patch row.
    pub b: usize,
    /// First patch column.
    pub a0: usize,
    /// Index of the first site in the padded patch storage.
    pub padded: usize,
    /// Index of the first site on the lattice (gy·L + gx).
    pub global: usize,
    /// Lattice row gy.
    pub gy: usize,
    pub len: usize,
}

impl Patch {
    /// Row stride of the padded storage.
    #[inline]
    pub fn stride(&self) -> usize {
        self.w + 2
    }

    /// Length of the padded storage, halo included.
    #[inline]
    pub fn padded_len(&self) -> usize {
        (self.w + 2) * (self.h + 2)
    }

    /// Index in the padded storage of patch site (a, b), 0 ≤ a < w, 0 ≤ b < h.
    #[inline]
    pub fn idx(&self, a: usize, b: usize) -> usize {
        (b + 1) * (self.w + 2) + a + 1
    }

    /// Lattice coordinates of patch site (a, b).
    #[inline]
    pub fn global_xy(&self, a: usize, b: usize, l: usize) -> (usize, usize) {
        ((self.x0 + a) % l, (self.y0 + b) % l)
    }

    /// The runs of patch row b: one, or two where the row wraps around the lattice edge.
    #[inline]
    pub fn row_runs(&self, b: usize, l: usize) -> [Option<Run>; 2] {
        let gy = (self.y0 + b) % l;
        let first = self.w.min(l - self.x0);
        let padded = self.idx(0, b);
        let r0 = Run { b, a0: 0, padded, global: gy * l + self.x0, gy, len: first };
        let r1 = (first < self.w).then_some(Run {
            b,
            a0: first,
            padded: padded + first,
            global: gy * l,
            gy,
            len: self.w - first,
        });
        [Some(r0), r1]
    }

    /// Every run of the patch, row by row.
    #[inline]
    pub fn runs(&self, l: usize) -> Runs<'_> {
        Runs { patch: self, l, b: 0, pending: None }
    }

    /// Whether lattice row gy falls in the patch, and at which patch row.
    #[inline]
    pub fn row_of(&self, gy: usize, l: usize) -> Option<usize> {
        let b = (gy + l - self.y0) % l;
        (b < self.h).then_some(b)
    }
}

/// The runs of a patch row by row ([`Patch::runs`]). A plain iterator rather than a `flat_map`
/// over [`Patch::row_runs`]: the per-cell stages take it once per run, and the flattening
/// adapter was not inlined (9.6 % of a relaxation step in `perf`).
pub struct Runs<'a> {
    patch: &'a Patch,
    l: usize,
    b: usize,
    /// The second run of the last row, where it wraps around the lattice edge.
    pending: Option<Run>,
}

impl Iterator for Runs<'_> {
    type Item = Run;

    #[inline]
    fn next(&mut self) -> Option<Run> {
        if let Some(r) = self.pending.take() {
            return Some(r);
        }
        if self.b >= self.patch.h {
            return None;
        }
        let [first, second] = self.patch.row_runs(self.b, self.l);
        self.b += 1;
        self.pending = second;
        first
    }
}

/// A run of `len` sites of a padded patch field and their eight neighbours, each an exact-length
/// slice: loops over them carry no bounds checks and vectorise. `ym` is the row at y − 1.
pub struct Neighbourhood<'a, T = f64> {
    pub c: &'a [T],
    pub xm: &'a [T],
    pub xp: &'a [T],
    pub ym: &'a [T],
    pub yp: &'a [T],
    pub xm_ym: &'a [T],
    pub xp_ym: &'a [T],
    pub xm_yp: &'a [T],
    pub xp_yp: &'a [T],
}

impl<'a, T: Real> Neighbourhood<'a, T> {
    /// Sites (a0 .. a0 + len, b) of the patch, in the padded storage `f`.
    #[inline(always)]
    pub fn new(f: &'a [T], patch: Patch, b: usize, a0: usize, len: usize) -> Self {
        let s = patch.stride();
        // Patch row b is padded row b + 1; patch column a is padded column a + 1.
        let at = |row: usize, col: usize| &f[row * s + a0 + col..][..len];
        Neighbourhood {
            c: at(b + 1, 1),
            xm: at(b + 1, 0),
            xp: at(b + 1, 2),
            ym: at(b, 1),
            yp: at(b + 2, 1),
            xm_ym: at(b, 0),
            xp_ym: at(b, 2),
            xm_yp: at(b + 2, 0),
            xp_yp: at(b + 2, 2),
        }
    }

    /// Central-difference gradient at site k of the run.
    #[inline(always)]
    pub fn gradient(&self, k: usize) -> (f64, f64) {
        (0.5 * (load(self.xp[k]) - load(self.xm[k])), 0.5 * (load(self.yp[k]) - load(self.ym[k])))
    }

    /// The same at every site of the run, in order: zipped slices, so a loop over them carries
    /// no bounds checks and runs in SIMD lanes.
    #[inline(always)]
    pub fn gradients(&self) -> impl Iterator<Item = (f64, f64)> + '_ {
        let x = self.xp.iter().zip(self.xm);
        let y = self.yp.iter().zip(self.ym);
        x.zip(y).map(|((&xp, &xm), (&yp, &ym))| (0.5 * (load(xp) - load(xm)), 0.5 * (load(yp) - load(ym))))
    }
}

/// A whole patch row (the `w` interior sites of row b) as a [`Neighbourhood`].
#[inline]
pub fn row_neighbourhood<T: Real>(f: &[T], patch: Patch, b: usize) -> Neighbourhood<'_, T> {
    Neighbourhood::new(f, patch, b, 0, patch.w)
}

/// The interior sites of patch row b in the padded storage `f`, mutably.
#[inline]
pub fn row_mut<T>(f: &mut [T], patch: Patch, b: usize) -> &mut [T] {
    let i = patch.idx(0, b);
    &mut f[i..i + patch.w]
}

/// Periodic wrap of a signed coordinate.
#[inline]
pub fn wrap(x: i64, l: usize) -> usize {
    x.rem_euclid(l as i64) as usize
}

/// dst(x) = Σ over the 8 neighbours x' of x of src(x'), periodic. This is the sum over N(x) in
/// Eq. 2 of the paper.
pub fn neighbour_sum8<T: Copy + Add<Output = T>>(src: &[T], dst: &mut [T], l: usize) {
    debug_assert_eq!(src.len(), l * l);
    debug_assert_eq!(dst.len(), l * l);
    let row = |y: usize| &src[y * l..][..l];
    for (y, out) in dst.chunks_mut(l).enumerate() {
        neighbour_sum8_row([row((y + l - 1) % l), row(y), row((y + 1) % l)], out);
    }
}

/// One row of [`neighbour_sum8`], given the rows above, at and below it.
#[inline]
pub fn neighbour_sum8_row<T: Copy + Add<Output = T>>([up, mid, dn]: [&[T]; 3], out: &mut [T]) {
    let l = out.len();
    // Column sums of the three rows, then a horizontal 3-sum, minus the centre.
    let col = |x: usize| up[x] + mid[x] + dn[x];
    let vert = |x: usize| up[x] + dn[x];
    out[0] = col(l - 1) + vert(0) + col(1);
    for (x, o) in out.iter_mut().enumerate().take(l - 1).skip(1) {
        *o = col(x - 1) + vert(x) + col(x + 1);
    }
    out[l - 1] = col(l - 2) + vert(l - 1) + col(0);
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn runs_cover_the_patch_once_and_wrap() {
        let l = 10;
        let p = Patch { x0: 7, y0: 8, w: 5, h: 4 };
        let mut hits = vec![0; l * l];
        let mut count = 0;
        for r in p.runs(l) {
            for k in 0..r.len {
                let (gx, gy) = p.global_xy(r.a0 + k, r.b, l);
                assert_eq!(r.global + k, gy * l + gx);
                assert_eq!(r.padded + k, p.idx(r.a0 + k, r.b));
                hits[r.global + k] += 1;
                count += 1;
            }
        }
        assert_eq!(count, 20);
        assert!(hits.iter().all(|&h| h <= 1));
        // Row by row, a wrapped row's two runs in order: the order the per-cell sums keep.
        let order: Vec<(usize, usize)> = p.runs(l).map(|r| (r.b, r.a0)).collect();
        assert_eq!(order, [(0, 0), (0, 3), (1, 0), (1, 3), (2, 0), (2, 3), (3, 0), (3, 3)]);
        assert_eq!(p.row_of(8, l), Some(0));
        assert_eq!(p.row_of(1, l), Some(3));
        assert_eq!(p.row_of(2, l), None);
    }

    #[test]
    fn neighbour_sum_is_periodic_and_excludes_centre() {
        let l = 6;
        let mut src = vec![0.0; l * l];
        src[0] = 1.0; // corner site (0, 0)
        let mut dst = vec![0.0; l * l];
        neighbour_sum8(&src, &mut dst, l);
        assert_eq!(dst[0], 0.0);
        let expect = [(1, 0), (5, 0), (0, 1), (0, 5), (1, 1), (5, 5), (1, 5), (5, 1)];
        for (x, y) in expect {
            assert_eq!(dst[y * l + x], 1.0, "({x},{y})");
        }
        assert_eq!(dst.iter().sum::<f64>(), 8.0);
    }
}

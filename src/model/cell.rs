//! One cell: its phase field φ_i on a patch of the lattice, and the per-site quantities the
//! dynamics computes on that patch (μ_i, f_i, v_i, dφ_i/dt).

use crate::model::lattice::Patch;
use crate::model::precision::{load, Real, Store};

/// A read-only view of one per-cell field on its patch (no copy).
#[derive(Clone, Copy, Debug)]
pub struct PatchField<'a, T = Store> {
    pub patch: Patch,
    /// Padded storage: (w + 2) × (h + 2), row-major, one-site ring of zeros.
    pub data: &'a [T],
}

impl<T: Real> PatchField<'_, T> {
    /// Value at patch site (a, b).
    #[inline]
    pub fn at(&self, a: usize, b: usize) -> f64 {
        load(self.data[self.patch.idx(a, b)])
    }

    /// Value at padded index i (as [`Patch::idx`] gives it).
    #[inline]
    pub fn get(&self, i: usize) -> f64 {
        load(self.data[i])
    }

    /// The whole padded storage as f64 (exact).
    pub fn padded(&self) -> Vec<f64> {
        self.data.iter().map(|&v| load(v)).collect()
    }

    /// The w×h interior, row by row, without the halo.
    pub fn interior(&self) -> Vec<f64> {
        let p = self.patch;
        (0..p.h).flat_map(|b| (0..p.w).map(move |a| (a, b))).map(|(a, b)| self.at(a, b)).collect()
    }
}

/// A cell's phase field and the fields the dynamics derives from it on its patch.
#[derive(Clone, Debug)]
pub struct Cell {
    pub(crate) patch: Patch,
    /// φ_i.
    pub(crate) phi: Vec<Store>,
    /// φ_i at the start of the step (Heun), and the last good state if a step fails.
    pub(crate) phi0: Vec<Store>,
    /// dφ_i/dt of the predictor evaluation.
    pub(crate) k1: Vec<Store>,
    /// dφ_i/dt of the latest evaluation.
    pub(crate) rate: Vec<Store>,
    /// μ_i = δF/δφ_i.
    pub(crate) mu: Vec<Store>,
    /// f_i = f^p_i + f^a_i.
    pub(crate) fx: Vec<Store>,
    pub(crate) fy: Vec<Store>,
    /// v_i.
    pub(crate) vx: Vec<Store>,
    pub(crate) vy: Vec<Store>,
    scratch: Vec<Store>,
    /// A_i = ∫ φ_i².
    pub(crate) area: f64,
    /// Q_i = (Q_xx, Q_xy) of Eq. 5, unnormalised.
    pub(crate) shape: [f64; 2],
    /// Q̂_i, normalised (see [`crate::model::shape`]).
    pub(crate) q_hat: [f64; 2],
    /// The first patch site (a, b) and value where φ_i left its allowed range in the last step.
    pub(crate) fault: Option<(usize, usize, f64)>,
    /// Why the patch could not follow the cell in the last step.
    pub(crate) lost: Option<String>,
    /// The patch the cell moves to once every cell has one (see `Monolayer::update_patches`).
    pub(crate) next: Patch,
}

impl Cell {
    /// A cell with the given φ (padded storage of `patch`).
    pub fn new(patch: Patch, phi: Vec<f64>) -> Self {
        let n = patch.padded_len();
        assert_eq!(phi.len(), n, "phi must fill the padded patch");
        let z = || vec![Store::default(); n];
        Cell {
            patch,
            phi: phi.into_iter().map(Store::from_f64).collect(),
            phi0: z(),
            k1: z(),
            rate: z(),
            mu: z(),
            fx: z(),
            fy: z(),
            vx: z(),
            vy: z(),
            scratch: Vec::new(),
            area: 0.0,
            shape: [0.0; 2],
            q_hat: [0.0; 2],
            fault: None,
            lost: None,
            next: patch,
        }
    }

    pub fn patch(&self) -> Patch {
        self.patch
    }

    fn view<'a>(&'a self, data: &'a [Store]) -> PatchField<'a> {
        PatchField { patch: self.patch, data }
    }

    /// φ_i.
    pub fn phi(&self) -> PatchField<'_> {
        self.view(&self.phi)
    }

    /// μ_i of the last evaluation.
    pub fn chemical_potential(&self) -> PatchField<'_> {
        self.view(&self.mu)
    }

    /// f_i = f^p_i + f^a_i of the last evaluation, x and y components.
    pub fn force(&self) -> (PatchField<'_>, PatchField<'_>) {
        (self.view(&self.fx), self.view(&self.fy))
    }

    /// v_i of the last evaluation, x and y components.
    pub fn velocity(&self) -> (PatchField<'_>, PatchField<'_>) {
        (self.view(&self.vx), self.view(&self.vy))
    }

    /// ∂_t φ_i of the last evaluation (Eq. 1).
    pub fn rate(&self) -> PatchField<'_> {
        self.view(&self.rate)
    }

    /// The first patch site (a, b) and value where φ_i left its allowed range in the last step's
    /// corrector, if any.
    pub fn fault(&self) -> Option<(usize, usize, f64)> {
        self.fault
    }

    /// A_i = ∫ φ_i² as of the last evaluation.
    pub fn area(&self) -> f64 {
        self.area
    }

    /// Q̂_i = (Q̂_xx, Q̂_xy) as of the last evaluation.
    pub fn q_hat(&self) -> [f64; 2] {
        self.q_hat
    }

    /// Q_i = (Q_xx, Q_xy) of Eq. 5 before normalisation.
    pub fn shape_tensor(&self) -> [f64; 2] {
        self.shape
    }

    /// Centre of mass Σ x φ / Σ φ on the lattice, in [0, L)². Computed in the patch's own
    /// unwrapped frame: for a cell that fits its patch this is exactly the circular mean on the
    /// periodic box, without trigonometry.
    pub fn centre(&self, l: usize) -> [f64; 2] {
        let (ca, cb) = self.local_centre();
        let wrapf = |v: f64| {
            let r = v.rem_euclid(l as f64);
            if r >= l as f64 {
                0.0
            } else {
                r
            }
        };
        [wrapf(self.patch.x0 as f64 + ca), wrapf(self.patch.y0 as f64 + cb)]
    }

    /// Centre of mass in patch coordinates.
    pub(crate) fn local_centre(&self) -> (f64, f64) {
        let p = self.patch;
        let (mut s, mut sa, mut sb) = (0.0, 0.0, 0.0);
        for b in 0..p.h {
            for a in 0..p.w {
                let v = load(self.phi[p.idx(a, b)]).max(0.0);
                s += v;
                sa += v * a as f64;
                sb += v * b as f64;
            }
        }
        if s > 0.0 {
            (sa / s, sb / s)
        } else {
            (p.w as f64 / 2.0, p.h as f64 / 2.0)
        }
    }

    /// Bounding box (a_min, a_max, b_min, b_max) of the sites with φ_i > threshold.
    pub(crate) fn support(&self, threshold: f64) -> Option<(usize, usize, usize, usize)> {
        let p = self.patch;
        let mut bb: Option<(usize, usize, usize, usize)> = None;
        for b in 0..p.h {
            let row = &self.phi[p.idx(0, b)..][..p.w];
            let first = row.iter().position(|&v| load(v) > threshold);
            if let Some(a0) = first {
                let a1 = row.iter().rposition(|&v| load(v) > threshold).unwrap_or(a0);
                bb = Some(match bb {
                    None => (a0, a1, b, b),
                    Some((x0, x1, y0, _)) => (x0.min(a0), x1.max(a1), y0, b),
                });
            }
        }
        bb
    }

    /// Moves or resizes the patch, keeping φ where the old and new patches overlap (zero
    /// elsewhere). The other per-site buffers are resized, not copied: they are recomputed at
    /// the next evaluation.
    pub(crate) fn relayout(&mut self, new: Patch, l: usize) {
        if new == self.patch {
            return;
        }
        let old = self.patch;
        self.scratch.clear();
        self.scratch.resize(new.padded_len(), Store::default());
        for b in 0..new.h {
            let gy = (new.y0 + b) % l;
            let Some(ob) = old.row_of(gy, l) else { continue };
            for a in 0..new.w {
                let gx = (new.x0 + a) % l;
                let oa = (gx + l - old.x0) % l;
                if oa < old.w {
                    self.scratch[new.idx(a, b)] = self.phi[old.idx(oa, ob)];
                }
            }
        }
        std::mem::swap(&mut self.phi, &mut self.scratch);
        self.patch = new;
        let n = new.padded_len();
        for buf in [
            &mut self.phi0,
            &mut self.k1,
            &mut self.rate,
            &mut self.mu,
            &mut self.fx,
            &mut self.fy,
            &mut self.vx,
            &mut self.vy,
        ] {
            buf.clear();
            buf.resize(n, Store::default());
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square_cell(l: usize) -> Cell {
        let p = Patch { x0: l - 3, y0: 1, w: 8, h: 6 };
        let mut phi = vec![0.0; p.padded_len()];
        for b in 1..5 {
            for a in 2..6 {
                phi[p.idx(a, b)] = 1.0;
            }
        }
        Cell::new(p, phi)
    }

    #[test]
    fn centre_wraps_across_the_edge() {
        let l = 20;
        let c = square_cell(l);
        // Occupied columns 2..6 of a patch starting at x0 = 17: lattice x = 19, 0, 1, 2.
        let [cx, cy] = c.centre(l);
        assert!((cx - 0.5).abs() < 1e-12, "{cx}");
        assert!((cy - 3.5).abs() < 1e-12, "{cy}");
    }

    #[test]
    fn relayout_keeps_phi_on_the_lattice() {
        let l = 20;
        let mut c = square_cell(l);
        let before: f64 = c.phi.iter().map(|&v| load(v)).sum();
        let moved = Patch { x0: 18, y0: 0, w: 10, h: 9 };
        c.relayout(moved, l);
        assert_eq!(c.phi.iter().map(|&v| load(v)).sum::<f64>(), before);
        assert_eq!(c.centre(l), [0.5, 3.5]);
        // Lattice x = 19, 0, 1, 2 are patch columns 1..=4; rows y = 2..=5.
        assert_eq!(c.support(0.5), Some((1, 4, 2, 5)));
    }
}

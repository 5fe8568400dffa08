//! A small seeded perturbation of every cell's φ: the replicas of a branched run start from their
//! parent's state with one of these added, and how often they still do what the parent did
//! measures how predictable the tissue is from its state (docs/figures.md, "Intervention").

use rand_chacha::rand_core::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use serde::{Deserialize, Serialize};

use crate::model::error::SimError;
use crate::model::monolayer::State;

/// The largest amplitude taken: beyond it the "perturbation" would be a change of the state.
pub const MAX_PERTURBATION: f64 = 0.1;

/// Uniform noise in [−amplitude, amplitude) added to φ at every site of every cell's patch,
/// drawn from a ChaCha8 generator seeded with `seed` (cells in order, rows then columns).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Perturbation {
    pub seed: u64,
    pub amplitude: f64,
}

impl Perturbation {
    /// Checks the amplitude: finite and in (0, [`MAX_PERTURBATION`]].
    pub fn validate(&self) -> Result<(), SimError> {
        let a = self.amplitude;
        if !(a.is_finite() && a > 0.0 && a <= MAX_PERTURBATION) {
            return Err(SimError::Invalid(format!(
                "perturbation amplitude = {a}: must be in (0, {MAX_PERTURBATION}] (a small perturbation of φ)"
            )));
        }
        Ok(())
    }

    /// Adds the noise to `state`'s φ. The padding ring of each patch stays zero (the stencils
    /// read it as the outside of the patch).
    pub fn apply(&self, state: &mut State) -> Result<(), SimError> {
        self.validate()?;
        let mut rng = ChaCha8Rng::seed_from_u64(self.seed);
        for (patch, phi) in &mut state.cells {
            for b in 0..patch.h {
                for a in 0..patch.w {
                    phi[patch.idx(a, b)] += self.amplitude * (2.0 * uniform(&mut rng) - 1.0);
                }
            }
        }
        Ok(())
    }
}

/// A uniform number in [0, 1) from 53 random bits: the same on every platform.
fn uniform(rng: &mut ChaCha8Rng) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::model::{Monolayer, Params};

    fn state() -> State {
        let p = Params { box_size: 40, n_cells: 4, relax_steps: 20, ..Params::default() };
        let mut m = Monolayer::new(p, 1).unwrap();
        m.advance(20).unwrap();
        m.state()
    }

    #[test]
    fn noise_is_bounded_seeded_and_leaves_the_padding_zero() {
        let before = state();
        let p = Perturbation { seed: 7, amplitude: 1e-6 };
        let mut once = before.clone();
        p.apply(&mut once).unwrap();
        let mut again = before.clone();
        p.apply(&mut again).unwrap();
        assert_eq!(once, again, "the same seed gives the same bits");
        let mut other = before.clone();
        Perturbation { seed: 8, ..p }.apply(&mut other).unwrap();
        assert_ne!(once, other, "another seed gives other noise");
        let (mut sum, mut n, mut largest) = (0.0, 0usize, 0.0f64);
        for ((patch, b), (_, a)) in before.cells.iter().zip(&once.cells) {
            for (k, (x, y)) in b.iter().zip(a).enumerate() {
                let (col, row) = (k % (patch.w + 2), k / (patch.w + 2));
                let ring = col == 0 || row == 0 || col == patch.w + 1 || row == patch.h + 1;
                if ring {
                    assert_eq!(*y, 0.0, "the padding ring stays zero");
                } else {
                    let d = y - x;
                    assert!(d.abs() <= 1e-6, "{d}");
                    largest = largest.max(d.abs());
                    sum += d;
                    n += 1;
                }
            }
        }
        assert!(largest > 0.9e-6, "uses the whole amplitude: {largest}");
        assert!((sum / n as f64).abs() < 1e-8, "centred on zero: {}", sum / n as f64);
        assert_eq!(once.warm_start, before.warm_start, "only φ changes");
    }

    #[test]
    fn amplitudes_outside_the_range_are_refused_by_name() {
        for a in [0.0, -1e-6, 0.5, f64::NAN] {
            let e = Perturbation { seed: 1, amplitude: a }.apply(&mut state()).unwrap_err().to_string();
            assert!(e.contains("perturbation amplitude") && e.contains("(0, 0.1]"), "{e}");
        }
    }
}

//! The protocol's initial condition: N disks of radius R/2 at random centres (paper Sec. Model).

use rand_chacha::rand_core::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use crate::model::cell::Cell;
use crate::model::error::SimError;
use crate::model::lattice::{wrap, Patch};
use crate::model::params::Params;

/// A uniform number in [0, 1) from 53 random bits: the same on every platform.
fn uniform(rng: &mut ChaCha8Rng) -> f64 {
    (rng.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
}

/// Random centres, drawn one after the other and redrawn while closer than `min_distance` to one
/// already placed (periodic distance), so that the initial disks do not overlap.
fn random_centres(rng: &mut ChaCha8Rng, n: usize, l: usize, min_distance: f64) -> Result<Vec<(f64, f64)>, SimError> {
    const MAX_TRIES: usize = 10_000;
    let lf = l as f64;
    let periodic = |d: f64| {
        let d = d.abs();
        d.min(lf - d)
    };
    let mut centres: Vec<(f64, f64)> = Vec::with_capacity(n);
    for i in 0..n {
        let free = |c: (f64, f64)| {
            centres.iter().all(|&(x, y): &(f64, f64)| {
                let (dx, dy) = (periodic(c.0 - x), periodic(c.1 - y));
                dx * dx + dy * dy >= min_distance * min_distance
            })
        };
        let c = (0..MAX_TRIES).map(|_| (uniform(rng) * lf, uniform(rng) * lf)).find(|&c| free(c)).ok_or_else(|| {
            SimError::Invalid(format!(
                "could not place initial disk {i} of {n} at least {min_distance} sites from the others in \
                     {MAX_TRIES} tries: lower n_cells, initial_radius_fraction or initial_gap"
            ))
        })?;
        centres.push(c);
    }
    Ok(centres)
}

/// N sharp disks (φ = 1 inside radius r₀ = `initial_radius_fraction`·R, 0 outside) at random
/// centres that keep the disks apart (≥ 2r₀ + `initial_gap` between centres), each on a square
/// patch of `relax_patch_size` centred on it. The Cahn–Hilliard term smooths the edges within the
/// first steps.
///
/// Why apart: two disks that overlap, or nearly touch, start with a large area deficit each, and
/// the area constraint (strength 4μ/πR² = 0.4 at the paper's values) then inflates φ inside them
/// past the stability bound 1.5 within 30–70 steps, long before their interfaces have grown.
/// Measured on seeds 1–20 at full size (and at L = 80 with 33 cells): a gap of 0 to 3 sites
/// relaxes every seed; 4 sites (2λ) is beyond what random sequential placement can fill at the
/// paper's density, it fell back to overlaps, and 8 of 20 seeds blew up.
pub fn random_disks(p: &Params, seed: u64) -> Result<Vec<Cell>, SimError> {
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let l = p.box_size;
    let size = p.relax_patch_size;
    let r0 = p.initial_radius_fraction * p.radius;
    Ok(random_centres(&mut rng, p.n_cells, l, 2.0 * r0 + p.initial_gap)?
        .into_iter()
        .map(|(cx, cy)| {
            let (fx, fy) = (cx.floor(), cy.floor());
            let half = (size / 2) as i64;
            let patch = Patch { x0: wrap(fx as i64 - half, l), y0: wrap(fy as i64 - half, l), w: size, h: size };
            // Centre in patch coordinates.
            let (lx, ly) = (cx - fx + half as f64, cy - fy + half as f64);
            let mut phi = vec![0.0; patch.padded_len()];
            for b in 0..size {
                for a in 0..size {
                    let (dx, dy) = (a as f64 - lx, b as f64 - ly);
                    if dx * dx + dy * dy <= r0 * r0 {
                        phi[patch.idx(a, b)] = 1.0;
                    }
                }
            }
            Cell::new(patch, phi)
        })
        .collect())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn seeded_disks_are_reproducible_and_sized() {
        let p = Params::default();
        let a = random_disks(&p, 7).unwrap();
        let b = random_disks(&p, 7).unwrap();
        let c = random_disks(&p, 8).unwrap();
        assert_eq!(a.len(), 100);
        assert!(a.iter().zip(&b).all(|(x, y)| x.patch == y.patch && x.phi == y.phi));
        assert!(a.iter().zip(&c).any(|(x, y)| x.patch != y.patch));
        for cell in &a {
            let area: f64 = cell.phi.iter().map(|&v| crate::model::precision::load(v)).sum();
            // π (R/2)² = 50.3 sites, give or take the lattice.
            assert!((area - 50.3).abs() < 8.0, "{area}");
        }
    }
}

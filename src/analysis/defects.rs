//! ±½ topological defects of the (smoothed) nematic field (paper Sec. A, docs/reading.md §6).
//!
//! The director angle θ = ½ atan2(Q_xy, Q_xx) turns by ±π around a ±½ defect. The paper flags
//! the sites whose 8-neighbour ring winds; the sites that flag one defect are the corners of the
//! plaquette that holds it, so the defect is found as that plaquette ([`super::winding`]) and
//! placed sub-site at the zero of Q inside it. A +½ defect has a direction (a comet: the director wraps round
//! its head and runs straight out of its tail). Following Vromans & Giomi, Soft Matter 12, 6490
//! (2016), it is the direction of ∇·Q near the core,
//!
//!   ψ = atan2(⟨∂_x Q_xy − ∂_y Q_xx⟩, ⟨∂_x Q_xx + ∂_y Q_xy⟩),
//!
//! averaged over the 5×5 sites about the core. For the ideal defect θ = φ/2 + θ₀ (φ the polar
//! angle about the core), ∇·Q ∝ (cos 2θ₀, sin 2θ₀)/r everywhere, so ψ = 2θ₀: the side where the
//! director is radial, the tail. The paper draws "a line pointing towards the tail".

use std::f64::consts::PI;

use super::winding::{core_position, plaquette_charges};

/// One ±½ defect.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Defect {
    /// Position on the periodic box, in lattice units.
    pub x: f64,
    pub y: f64,
    /// +1 for a +½ defect, −1 for a −½ defect (charge × 2).
    pub twice_charge: i8,
    /// For +½: the angle ψ ∈ (−π, π] of the direction from the head to the tail. NaN for −½.
    pub orientation: f64,
}

impl Defect {
    pub fn charge(&self) -> f64 {
        0.5 * self.twice_charge as f64
    }
}

/// Finds the ±½ defects of a Q field (Q_xx, Q_xy on the L×L lattice) with reusable buffers.
#[derive(Clone, Debug, Default)]
pub struct DefectFinder {
    theta: Vec<f64>,
    charge: Vec<i8>,
}

impl DefectFinder {
    /// The defects of (qxx, qxy), written to `out` (cleared first): one per plaquette around
    /// which the director turns by ±π, at the zero of Q within it.
    pub fn find(&mut self, qxx: &[f64], qxy: &[f64], l: usize, out: &mut Vec<Defect>) {
        self.theta.clear();
        self.theta.extend(qxx.iter().zip(qxy).map(|(&a, &b)| 0.5 * libm::atan2(b, a)));
        self.charge.resize(l * l, 0);
        plaquette_charges(&self.theta, PI, 2, &mut self.charge, l);
        out.clear();
        for (k, &c) in self.charge.iter().enumerate() {
            // Four steps of at most π/2 each cannot turn by more than π: c is −1, 0 or 1.
            if c == 0 {
                continue;
            }
            let (x, y) = core_position(qxx, qxy, k % l, k / l, l);
            let orientation = if c > 0 { plus_half_orientation(qxx, qxy, l, x, y) } else { f64::NAN };
            out.push(Defect { x, y, twice_charge: c, orientation });
        }
    }
}

/// ψ of a +½ defect at (x, y): the direction of ∇·Q (central differences) summed over the 5×5
/// sites nearest the core (Vromans & Giomi 2016).
pub fn plus_half_orientation(qxx: &[f64], qxy: &[f64], l: usize, x: f64, y: f64) -> f64 {
    let li = l as i64;
    let at = |f: &[f64], x: i64, y: i64| f[(y.rem_euclid(li) * li + x.rem_euclid(li)) as usize];
    let (cx, cy) = (x.round() as i64, y.round() as i64);
    let (mut px, mut py) = (0.0, 0.0);
    for j in cy - 2..=cy + 2 {
        for i in cx - 2..=cx + 2 {
            let dxx = 0.5 * (at(qxx, i + 1, j) - at(qxx, i - 1, j));
            let dyx = 0.5 * (at(qxx, i, j + 1) - at(qxx, i, j - 1));
            let dxy = 0.5 * (at(qxy, i + 1, j) - at(qxy, i - 1, j));
            let dyy = 0.5 * (at(qxy, i, j + 1) - at(qxy, i, j - 1));
            px += dxx + dyy;
            py += dxy - dyx;
        }
    }
    libm::atan2(py, px)
}

//! Spiral cores of the (smoothed) velocity field (paper Fig. 1b, docs/reading.md §6): the +1 points of
//! the field (its angle winds once around them) where the divergence is positive, i.e. flows
//! that spiral outwards and stretch the tissue. A vortex (∇·v = 0) or an inward spiral (a sink)
//! is a +1 point but not a spiral core.

use std::f64::consts::PI;

use super::winding::{core_position, plaquette_charges};

/// One +1 point of the velocity field.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct PlusOne {
    pub x: f64,
    pub y: f64,
    /// ∇·v averaged over the four sites that flag the point.
    pub divergence: f64,
}

impl PlusOne {
    /// Whether this +1 point is a spiral core: ∇·v > 0, above the rounding noise of a
    /// divergence-free vortex (a millionth of the field's typical |∇·v| scale).
    pub fn is_spiral_core(&self, scale: f64) -> bool {
        self.divergence > 1e-6 * scale
    }
}

/// Finds the +1 points of a velocity field with reusable buffers.
#[derive(Clone, Debug, Default)]
pub struct SpiralFinder {
    angle: Vec<f64>,
    charge: Vec<i8>,
}

impl SpiralFinder {
    /// The +1 points of (vx, vy), written to `out` (cleared first): the plaquettes around which
    /// the velocity turns once counter-clockwise, placed at the zero of v inside them, with the
    /// divergence field `div` averaged over the plaquette's four corners (the sites whose
    /// 8-neighbour rings flag it).
    pub fn find(&mut self, vx: &[f64], vy: &[f64], div: &[f64], l: usize, out: &mut Vec<PlusOne>) {
        self.angle.clear();
        self.angle.extend(vx.iter().zip(vy).map(|(&x, &y)| libm::atan2(y, x)));
        self.charge.resize(l * l, 0);
        plaquette_charges(&self.angle, 2.0 * PI, 1, &mut self.charge, l);
        out.clear();
        for (k, &c) in self.charge.iter().enumerate() {
            if c != 1 {
                continue;
            }
            let (x0, y0) = (k % l, k / l);
            let (x1, y1) = ((x0 + 1) % l, (y0 + 1) % l);
            let d = 0.25 * (div[y0 * l + x0] + div[y0 * l + x1] + div[y1 * l + x0] + div[y1 * l + x1]);
            let (x, y) = core_position(vx, vy, x0, y0, l);
            out.push(PlusOne { x, y, divergence: d });
        }
    }
}

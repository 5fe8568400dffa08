//! The paper's mechanism claims that no figure of it measures, as numbers:
//!
//! - **antiparallel +½ pairs** ("two +1/2 topological defects … moving in the vicinity of each
//!   other in an antiparallel relative orientation"): the angle between the orientations ψ of
//!   the two +½ defects nearest a nucleation, [`polar_angle_between`] ∈ [0, π] (π: antiparallel,
//!   0: parallel; π/2 on average for independent orientations), in the frames before it
//!   (`precursors`), against the same pair about random sites of the same frames;
//! - **tangential alignment** ("aligning cells tangentially along the tissue–hole interface"):
//!   for every cell whose centroid lies within [`BORDER_RADII`] R of an open hole's boundary, the
//!   angle between its elongation axis and the boundary's local tangent,
//!   [`tangential_angles`] ∈ [0, π/2] (0: tangential, π/2: radial, π/4 on average for random
//!   axes), against the same angle for the cells farther than [`AWAY_RADII`] R from every hole;
//! - **−½ defects** ("we do not see hole formation at −1/2 defects"): the distance from a
//!   nucleation to the nearest −½ defect against the nearest +½ (`precursors`).
//!
//! Pure functions of positions and angles: the same code runs in the browser.

use std::f64::consts::{FRAC_PI_2, PI};

use super::holes::periodic_distance;
use crate::model::{load, Patch, Real};

/// A cell borders a hole when its centroid lies within this many R of the hole's boundary (a
/// cell's centroid sits about R from its own edge).
pub const BORDER_RADII: f64 = 1.5;
/// A cell is away from holes when its centroid is farther than this many R from every hole.
pub const AWAY_RADII: f64 = 3.0;

/// The angle between two polar directions (radians), in [0, π].
pub fn polar_angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(2.0 * PI);
    d.min(2.0 * PI - d)
}

/// The angle between two axes (directions modulo π), in [0, π/2].
pub fn axis_angle_between(a: f64, b: f64) -> f64 {
    let d = (a - b).rem_euclid(PI);
    d.min(PI - d)
}

/// The φ-weighted centroid of a cell on the periodic L×L box (None if φ is zero everywhere).
pub fn cell_centroid<T: Real>(patch: Patch, phi: &[T], l: usize) -> Option<(f64, f64)> {
    let (mut m, mut sx, mut sy) = (0.0, 0.0, 0.0);
    for b in 0..patch.h {
        for a in 0..patch.w {
            let f = load(phi[patch.idx(a, b)]);
            m += f;
            sx += f * a as f64;
            sy += f * b as f64;
        }
    }
    if m <= 0.0 {
        return None;
    }
    let lf = l as f64;
    Some(((patch.x0 as f64 + sx / m).rem_euclid(lf), (patch.y0 as f64 + sy / m).rem_euclid(lf)))
}

/// The boundary sites of the void regions selected by `open` (indexed by region label): their
/// void sites with a 4-neighbour outside the region, appended to `out` (cleared first).
pub fn boundary_sites(labels: &[u32], open: &[bool], l: usize, out: &mut Vec<(f64, f64)>) {
    out.clear();
    let li = l as i64;
    for (k, &lab) in labels.iter().enumerate() {
        if lab == u32::MAX || !open.get(lab as usize).copied().unwrap_or(false) {
            continue;
        }
        let (x, y) = ((k % l) as i64, (k / l) as i64);
        let edge = [(1, 0), (-1, 0), (0, 1), (0, -1)].iter().any(|&(dx, dy)| {
            let j = ((y + dy).rem_euclid(li) * li + (x + dx).rem_euclid(li)) as usize;
            labels[j] != lab
        });
        if edge {
            out.push((x as f64, y as f64));
        }
    }
}

/// For cells given as (x, y, elongation axis angle), the angle between each axis and the local
/// tangent of the nearest boundary site (the tangent is perpendicular to the line from that site
/// to the centroid, the boundary's normal there): pushed to `near` for the cells within
/// `border` of the boundary, to `away` for those farther than `away_from`. Nothing without a
/// boundary.
pub fn tangential_angles(
    cells: &[(f64, f64, f64)],
    boundary: &[(f64, f64)],
    l: usize,
    border: f64,
    away_from: f64,
    near: &mut Vec<f64>,
    away: &mut Vec<f64>,
) {
    if boundary.is_empty() {
        return;
    }
    let lf = l as f64;
    let wrap = |d: f64| d - lf * (d / lf).round();
    for &(cx, cy, axis) in cells {
        let (d, bx, by) = boundary
            .iter()
            .map(|&(bx, by)| (periodic_distance(cx, cy, bx, by, l), bx, by))
            .min_by(|a, b| a.0.total_cmp(&b.0))
            .expect("a boundary site");
        if d > border && d <= away_from {
            continue;
        }
        let normal = libm::atan2(wrap(cy - by), wrap(cx - bx));
        let angle = axis_angle_between(axis, normal + FRAC_PI_2);
        if d <= border {
            near.push(angle);
        } else {
            away.push(angle);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn angles_between_directions_and_axes() {
        assert!((polar_angle_between(0.1, 0.1 + PI) - PI).abs() < 1e-12);
        assert!((polar_angle_between(3.0, -3.0) - (2.0 * PI - 6.0)).abs() < 1e-12);
        assert!(polar_angle_between(1.0, 1.0).abs() < 1e-12);
        assert!((axis_angle_between(0.0, PI) - 0.0).abs() < 1e-12);
        assert!((axis_angle_between(0.2, 0.2 + FRAC_PI_2) - FRAC_PI_2).abs() < 1e-12);
        assert!((axis_angle_between(-1.5, 1.5) - (PI - 3.0)).abs() < 1e-12);
    }

    #[test]
    fn a_centroid_across_the_periodic_edge() {
        let l = 20;
        let patch = Patch { x0: 18, y0: 5, w: 4, h: 2 };
        let mut phi = vec![0.0; patch.padded_len()];
        for b in 0..2 {
            for a in 0..4 {
                phi[patch.idx(a, b)] = 1.0;
            }
        }
        let (x, y) = cell_centroid(patch, &phi, l).unwrap();
        // Columns 18, 19, 0, 1: the centroid at 19.5 + 0.5 = 20 ≡ 0.
        assert!((x - 19.5).abs() < 1e-12 && (y - 5.5).abs() < 1e-12, "({x}, {y})");
        assert_eq!(cell_centroid(patch, &vec![0.0; patch.padded_len()], l), None);
    }

    /// A round hole of radius 10 with cells about it: tangential cells give 0, radial ones π/2;
    /// a cell far away goes to the other list.
    #[test]
    fn cells_around_a_round_hole() {
        let l = 100;
        let (hx, hy, hr) = (40.0, 40.0, 10.0);
        let labels: Vec<u32> = (0..l * l)
            .map(|k| {
                let (x, y) = ((k % l) as f64, (k / l) as f64);
                if (x - hx).hypot(y - hy) <= hr {
                    0
                } else {
                    u32::MAX
                }
            })
            .collect();
        let mut boundary = Vec::new();
        boundary_sites(&labels, &[true], l, &mut boundary);
        assert!(boundary.len() > 40 && boundary.iter().all(|&(x, y)| ((x - hx).hypot(y - hy) - hr).abs() < 1.5));
        let ring: Vec<f64> = (0..12).map(|k| k as f64 * PI / 6.0).collect();
        let at = |phi: f64, axis: f64| (hx + 18.0 * phi.cos(), hy + 18.0 * phi.sin(), axis);
        let tangential: Vec<_> = ring.iter().map(|&p| at(p, p + FRAC_PI_2)).collect();
        let radial: Vec<_> = ring.iter().map(|&p| at(p, p)).collect();
        let (mut near, mut away) = (Vec::new(), Vec::new());
        tangential_angles(&tangential, &boundary, l, 12.0, 24.0, &mut near, &mut away);
        assert_eq!(near.len(), 12);
        assert!(near.iter().all(|&a| a < 0.15), "{near:?}");
        near.clear();
        tangential_angles(&radial, &boundary, l, 12.0, 24.0, &mut near, &mut away);
        assert!(near.iter().all(|&a| a > FRAC_PI_2 - 0.15), "{near:?}");
        assert!(away.is_empty());
        tangential_angles(&[(90.0, 90.0, 0.3)], &boundary, l, 12.0, 24.0, &mut near, &mut away);
        assert_eq!(away.len(), 1);
        // No hole, no angle.
        tangential_angles(&tangential, &[], l, 12.0, 24.0, &mut near, &mut away);
        assert_eq!((near.len(), away.len()), (12, 1));
    }
}

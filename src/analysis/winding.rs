//! Topological charges on the lattice, shared by the nematic defects and the spiral cores.
//!
//! The paper flags a defect at a site x when the field winds around the 8 neighbours of x. That
//! ring is the boundary of the four plaquettes (unit squares of the lattice) that meet at x, and
//! each step of the ring is a lattice edge, so the ring's turn is the sum of the turns around
//! those four plaquettes (interior edges cancel). A singularity therefore lives in one plaquette,
//! and the (up to four) sites whose rings flag it are its corners: merging them is taking the
//! plaquette. This also keeps two defects in neighbouring plaquettes apart, where merging flagged
//! sites would fuse them, and the charges of all plaquettes sum to exactly zero on the torus.
//!
//! Within its plaquette the core is placed sub-site where the bilinear interpolant of the field
//! vanishes (the field of a smoothed defect goes to zero linearly at the core).

/// Turn of `angle` around each plaquette, in units of 2π, times `denominator` and rounded: ±1
/// for a ±½ nematic defect (period π, denominator 2) or a ±1 vector singularity (period 2π,
/// denominator 1). `out[y·L + x]` is the plaquette with corners (x, y) and (x+1, y+1), wrapping.
/// Each step's difference is folded by `period` into [−period/2, period/2].
pub fn plaquette_charges(angle: &[f64], period: f64, denominator: i32, out: &mut [i8], l: usize) {
    let half = 0.5 * period;
    // Angles of neighbouring sites differ by less than a period: one fold brings them into range.
    let wrap = |d: f64| {
        if d > half {
            d - period
        } else if d < -half {
            d + period
        } else {
            d
        }
    };
    let scale = denominator as f64 / (2.0 * std::f64::consts::PI);
    for y in 0..l {
        let r0 = &angle[y * l..][..l];
        let r1 = &angle[((y + 1) % l) * l..][..l];
        let o = &mut out[y * l..][..l];
        for x in 0..l {
            let x1 = if x + 1 == l { 0 } else { x + 1 };
            // Counter-clockwise (y up): (x, y) → (x+1, y) → (x+1, y+1) → (x, y+1) → (x, y).
            let turn = wrap(r0[x1] - r0[x]) + wrap(r1[x1] - r0[x1]) + wrap(r1[x] - r1[x1]) + wrap(r0[x] - r1[x]);
            let q = turn * scale;
            // The turn is a whole number of periods up to rounding: round to nearest.
            o[x] = (q + 0.5 * q.signum()) as i8;
        }
    }
}

/// The paper's flag: the winding around the 8 neighbours of each site, from the plaquette
/// charges (the sum of the four plaquettes meeting at the site). The finders use the plaquettes
/// themselves; the test below holds this sum to the direct eight-neighbour winding.
#[cfg(test)]
fn ring_charges(plaquette: &[i8], out: &mut [i8], l: usize) {
    for y in 0..l {
        let yd = (y + l - 1) % l;
        for x in 0..l {
            let xl = (x + l - 1) % l;
            out[y * l + x] =
                plaquette[y * l + x] + plaquette[y * l + xl] + plaquette[yd * l + x] + plaquette[yd * l + xl];
        }
    }
}

/// Where in plaquette (x, y) the bilinear interpolant of the field (a, b) vanishes, as lattice
/// coordinates in [0, L); the plaquette centre if Newton's method does not settle inside it.
pub fn core_position(a: &[f64], b: &[f64], x: usize, y: usize, l: usize) -> (f64, f64) {
    let (x1, y1) = ((x + 1) % l, (y + 1) % l);
    let corners = |f: &[f64]| [f[y * l + x], f[y * l + x1], f[y1 * l + x], f[y1 * l + x1]];
    let (fa, fb) = (corners(a), corners(b));
    // f(u, v) = f00 (1−u)(1−v) + f10 u(1−v) + f01 (1−u) v + f11 u v.
    let eval = |f: &[f64; 4], u: f64, v: f64| {
        let val = f[0] * (1.0 - u) * (1.0 - v) + f[1] * u * (1.0 - v) + f[2] * (1.0 - u) * v + f[3] * u * v;
        let du = (f[1] - f[0]) * (1.0 - v) + (f[3] - f[2]) * v;
        let dv = (f[2] - f[0]) * (1.0 - u) + (f[3] - f[1]) * u;
        (val, du, dv)
    };
    let (mut u, mut v) = (0.5, 0.5);
    let mut settled = false;
    for _ in 0..20 {
        let (ra, au, av) = eval(&fa, u, v);
        let (rb, bu, bv) = eval(&fb, u, v);
        let det = au * bv - av * bu;
        if det.abs() < 1e-300 || !det.is_finite() {
            break;
        }
        let du = (ra * bv - av * rb) / det;
        let dv = (au * rb - ra * bu) / det;
        u -= du;
        v -= dv;
        if !(-0.5..=1.5).contains(&u) || !(-0.5..=1.5).contains(&v) {
            break;
        }
        if du.abs() + dv.abs() < 1e-10 {
            settled = (0.0..=1.0).contains(&u) && (0.0..=1.0).contains(&v);
            break;
        }
    }
    if !settled {
        (u, v) = (0.5, 0.5);
    }
    let lf = l as f64;
    ((x as f64 + u).rem_euclid(lf), (y as f64 + v).rem_euclid(lf))
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::f64::consts::PI;

    /// The plaquette sum equals the turn around the 8 neighbours taken directly, site by site.
    #[test]
    fn ring_charges_are_the_direct_eight_neighbour_winding() {
        let l = 12;
        // A +1 and a −1 vector singularity, and some noise-free smooth variation.
        let angle: Vec<f64> = (0..l * l)
            .map(|k| {
                let (x, y) = ((k % l) as f64, (k / l) as f64);
                let a = (y - 3.3).atan2(x - 4.6) - (y - 8.2).atan2(x - 7.7) + 0.3 * (x * 0.5).sin();
                (a + PI).rem_euclid(2.0 * PI) - PI
            })
            .collect();
        let mut plaq = vec![0i8; l * l];
        plaquette_charges(&angle, 2.0 * PI, 1, &mut plaq, l);
        let mut ring = vec![0i8; l * l];
        ring_charges(&plaq, &mut ring, l);
        let li = l as i64;
        let ring8 = [(1, 0), (1, 1), (0, 1), (-1, 1), (-1, 0), (-1, -1), (0, -1), (1, -1), (1, 0)];
        for y in 0..li {
            for x in 0..li {
                let at =
                    |(dx, dy): (i64, i64)| angle[((y + dy).rem_euclid(li) * li + (x + dx).rem_euclid(li)) as usize];
                let turn: f64 = ring8.windows(2).map(|w| (at(w[1]) - at(w[0]) + PI).rem_euclid(2.0 * PI) - PI).sum();
                let direct = (turn / (2.0 * PI)).round() as i8;
                assert_eq!(ring[(y * li + x) as usize], direct, "site ({x}, {y})");
            }
        }
        assert_eq!(plaq[3 * l + 4], 1);
        assert_eq!(plaq[8 * l + 7], -1);
        assert_eq!(plaq.iter().map(|&q| q as i32).sum::<i32>(), 0, "charges cancel on the torus");
    }

    #[test]
    fn core_of_a_linear_field_is_its_zero() {
        let l = 8;
        let (x0, y0) = (3.3, 5.8);
        let a: Vec<f64> = (0..l * l).map(|k| (k % l) as f64 - x0 + 0.2 * ((k / l) as f64 - y0)).collect();
        let b: Vec<f64> = (0..l * l).map(|k| (k / l) as f64 - y0).collect();
        let (x, y) = core_position(&a, &b, 3, 5, l);
        assert!((x - x0).abs() < 1e-9 && (y - y0).abs() < 1e-9, "({x}, {y})");
    }
}

//! How thin the tissue is about a site: the least Σφ within a radius, and the share of void
//! sites there. The paper's argument for collective motion rests on the tissue *not* thinning
//! before a hole ("when no hole is present the packing fraction is always above 95 %"), so every
//! precursor of a hole is read beside these two numbers (docs/figures-precursors.md, "Thinning").
//!
//! Sites are the lattice points (x, y) = (i, j); a site is within `radius` of a point when their
//! periodic distance is at most `radius` (the same disc as the strain rate's "within R/2").

use super::holes::{COVERED_THRESHOLD, VOID_THRESHOLD};

/// Least Σφ within R/2 at or above which a site counts as still covered: thinning has not begun
/// where the hole will open (the subset where the paper's mechanism is tested).
pub const COVERED_CORE_FRACTION: f64 = 0.5;

/// The offsets (dx, dy) of the lattice sites within `radius` of a lattice site.
pub fn disc_offsets(radius: f64) -> Vec<(i64, i64)> {
    let reach = radius.floor() as i64;
    let mut out = Vec::new();
    for dy in -reach..=reach {
        for dx in -reach..=reach {
            if ((dx * dx + dy * dy) as f64) <= radius * radius {
                out.push((dx, dy));
            }
        }
    }
    out
}

/// Calls `f` with Σφ at every site within `radius` of the point (cx, cy) on the periodic L×L box.
fn for_each_within(phi_sum: &[f64], l: usize, cx: f64, cy: f64, radius: f64, mut f: impl FnMut(f64)) {
    let li = l as i64;
    let reach = radius.ceil() as i64 + 1;
    let (x0, y0) = (cx.round() as i64, cy.round() as i64);
    for y in y0 - reach..=y0 + reach {
        for x in x0 - reach..=x0 + reach {
            if (x as f64 - cx).hypot(y as f64 - cy) <= radius {
                f(phi_sum[(y.rem_euclid(li) * li + x.rem_euclid(li)) as usize]);
            }
        }
    }
}

/// The least Σφ at the sites within `radius` of (cx, cy); +∞ if no site is that near.
pub fn least_within(phi_sum: &[f64], l: usize, cx: f64, cy: f64, radius: f64) -> f64 {
    let mut least = f64::INFINITY;
    for_each_within(phi_sum, l, cx, cy, radius, |p| least = least.min(p));
    least
}

/// The share of void sites (Σφ < [`VOID_THRESHOLD`]) within `radius` of (cx, cy).
pub fn void_share_within(phi_sum: &[f64], l: usize, cx: f64, cy: f64, radius: f64) -> f64 {
    let (mut void, mut all) = (0usize, 0usize);
    for_each_within(phi_sum, l, cx, cy, radius, |p| {
        all += 1;
        void += usize::from(p < VOID_THRESHOLD);
    });
    if all == 0 {
        0.0
    } else {
        void as f64 / all as f64
    }
}

/// Whether the tissue is still covered about (cx, cy): the least Σφ within R/2 is at least ½
/// (`COVERED_CORE_FRACTION` of R, `COVERED_THRESHOLD` of Σφ).
pub fn covered_about(phi_sum: &[f64], l: usize, cx: f64, cy: f64, radius: f64) -> bool {
    least_within(phi_sum, l, cx, cy, COVERED_CORE_FRACTION * radius) >= COVERED_THRESHOLD
}

/// The least Σφ within a disc about every site of a sub-grid: `sites` are lattice indices, the
/// disc given by [`disc_offsets`]; written to `out` in the order of `sites`.
pub fn least_on_sites(phi_sum: &[f64], l: usize, sites: &[usize], disc: &[(i64, i64)], out: &mut Vec<f64>) {
    let li = l as i64;
    out.clear();
    out.extend(sites.iter().map(|&s| {
        let (x, y) = ((s % l) as i64, (s / l) as i64);
        disc.iter()
            .map(|&(dx, dy)| phi_sum[((y + dy).rem_euclid(li) * li + (x + dx).rem_euclid(li)) as usize])
            .fold(f64::INFINITY, f64::min)
    }));
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 40×40 tissue at Σφ = 1 with a thin patch (Σφ = 0.3) at (10, 10) of radius 3 and a
    /// void patch (0) of radius 2 at (39, 39), straddling the periodic corner.
    fn frame() -> (Vec<f64>, usize) {
        let l = 40;
        let mut p = vec![1.0; l * l];
        for y in 0..l {
            for x in 0..l {
                let d = super::super::holes::periodic_distance(x as f64, y as f64, 10.0, 10.0, l);
                if d <= 3.0 {
                    p[y * l + x] = 0.3;
                }
                if super::super::holes::periodic_distance(x as f64, y as f64, 39.0, 39.0, l) <= 2.0 {
                    p[y * l + x] = 0.0;
                }
            }
        }
        (p, l)
    }

    #[test]
    fn the_least_sum_sees_a_thin_patch_only_within_reach() {
        let (p, l) = frame();
        assert_eq!(least_within(&p, l, 10.0, 10.0, 1.0), 0.3);
        // 8 sites away: the patch's edge (3) is 5 away, within 6 but not within 4.
        assert_eq!(least_within(&p, l, 18.0, 10.0, 6.0), 0.3);
        assert_eq!(least_within(&p, l, 18.0, 10.0, 4.0), 1.0);
        // Across the periodic edge: (0, 0), within 1.5 of (1, 1), is 1.41 from (39, 39).
        assert_eq!(least_within(&p, l, 1.0, 1.0, 1.5), 0.0);
        assert_eq!(least_within(&p, l, 1.0, 1.0, 1.0), 1.0);
        assert!(covered_about(&p, l, 18.0, 10.0, 8.0));
        assert!(!covered_about(&p, l, 12.0, 10.0, 8.0), "the thin patch is within R/2 = 4");
    }

    #[test]
    fn the_void_share_counts_void_sites_of_the_disc() {
        let (p, l) = frame();
        // The void disc of radius 2 is 13 sites; a disc of radius 2 about its centre is all void.
        assert_eq!(void_share_within(&p, l, 39.0, 39.0, 2.0), 1.0);
        // A disc of radius 4 about it: 13 of 49 sites.
        assert!((void_share_within(&p, l, 39.0, 39.0, 4.0) - 13.0 / 49.0).abs() < 1e-12);
        assert_eq!(void_share_within(&p, l, 10.0, 10.0, 4.0), 0.0, "thin is not void");
    }

    #[test]
    fn the_sub_grid_minimum_agrees_with_the_point_minimum() {
        let (p, l) = frame();
        let disc = disc_offsets(5.0);
        assert_eq!(disc.len(), 81);
        let sites: Vec<usize> = (0..l * l).step_by(7).collect();
        let mut out = Vec::new();
        least_on_sites(&p, l, &sites, &disc, &mut out);
        for (&s, &m) in sites.iter().zip(&out) {
            assert_eq!(m, least_within(&p, l, (s % l) as f64, (s / l) as f64, 5.0), "site {s}");
        }
    }
}

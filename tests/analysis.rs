//! The measurements (src/analysis) on synthetic fields with known answers, and on the relaxed
//! full-size tissue.

mod common;

use std::f64::consts::{FRAC_PI_2, FRAC_PI_4, PI};

use monolayer::analysis::{
    boundary_sites, correlation_length, divergence, periodic_distance, tangential_angles, window_mean, Analysis,
    Correlator, Defect, DefectFinder, HoleProbability, HoleTracker, PlusOne, Precursor, Precursors, SpiralFinder,
    VoidRegions, AWAY_RADII, BORDER_RADII, CHANCE_SITES, STRAIN_RATE_BIN,
};
use monolayer::model::{force_density, PassiveForce, Patch};
use monolayer::Params;
use num_complex::Complex64 as C64;

/// A deterministic pseudo-random number in [−1, 1) (no RNG crate needed for test fields).
fn noise(k: usize, seed: u64) -> f64 {
    let mut z = (k as u64).wrapping_add(seed.wrapping_mul(0x9E37_79B9_7F4A_7C15));
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^= z >> 31;
    (z >> 11) as f64 / (1u64 << 52) as f64 - 1.0
}

/// Minimum-image displacement from c to a on a periodic axis of length l.
fn delta(a: f64, c: f64, l: usize) -> f64 {
    let lf = l as f64;
    let d = (a - c).rem_euclid(lf);
    if d > lf / 2.0 {
        d - lf
    } else {
        d
    }
}

/// Q = (cos 2θ, sin 2θ) with θ = s·φ/2 + θ₀ about (cx, cy): a defect of charge s/2.
fn nematic_defect(l: usize, cx: f64, cy: f64, s: f64, theta0: f64) -> (Vec<f64>, Vec<f64>) {
    let mut qxx = vec![0.0; l * l];
    let mut qxy = vec![0.0; l * l];
    for y in 0..l {
        for x in 0..l {
            let phi = delta(y as f64, cy, l).atan2(delta(x as f64, cx, l));
            let th = 0.5 * s * phi + theta0;
            qxx[y * l + x] = (2.0 * th).cos();
            qxy[y * l + x] = (2.0 * th).sin();
        }
    }
    (qxx, qxy)
}

fn angle_diff(a: f64, b: f64) -> f64 {
    (a - b + PI).rem_euclid(2.0 * PI) - PI
}

/// A +½ defect at a known off-lattice position in four orientations: one defect there, pointing
/// towards its tail (ψ = 2θ₀), placed within a quarter of a site in the raw field (a unit
/// director field does not vanish at the core: the bilinear zero is approximate) and within a
/// tenth after the 2R×2R smoothing (which makes Q vanish linearly at the core).
#[test]
fn plus_half_defect_position_and_orientation() {
    let l = 64;
    let (cx, cy) = (31.3, 28.6);
    for theta0 in [0.0, FRAC_PI_4, FRAC_PI_2, 3.0 * FRAC_PI_4] {
        let (qxx, qxy) = nematic_defect(l, cx, cy, 1.0, theta0);
        let (mut sxx, mut sxy) = (vec![0.0; l * l], vec![0.0; l * l]);
        let (mut tmp, mut row) = (Vec::new(), Vec::new());
        window_mean(&qxx, &mut sxx, &mut tmp, &mut row, l, 8);
        window_mean(&qxy, &mut sxy, &mut tmp, &mut row, l, 8);
        for (name, fxx, fxy, tol) in [("raw", &qxx, &qxy, 0.25), ("smoothed", &sxx, &sxy, 0.1)] {
            let mut out = Vec::new();
            DefectFinder::default().find(fxx, fxy, l, &mut out);
            // The field is not periodic: its seam, far from the core, has defects of its own.
            let near: Vec<_> = out.iter().filter(|d| periodic_distance(d.x, d.y, cx, cy, l) < 12.0).collect();
            assert_eq!(near.len(), 1, "θ₀ = {theta0}, {name}: {near:?}");
            let d = near[0];
            assert_eq!(d.twice_charge, 1, "θ₀ = {theta0}, {name}");
            let err = periodic_distance(d.x, d.y, cx, cy, l);
            assert!(err < tol, "θ₀ = {theta0}, {name}: at ({}, {}), {err} from the core", d.x, d.y);
            let want = 2.0 * theta0;
            assert!(
                angle_diff(d.orientation, want).abs() < 0.05,
                "θ₀ = {theta0}, {name}: orientation {} want {want}",
                d.orientation
            );
        }
    }
}

/// A −½ defect: found, with charge −½, at its position, and no orientation claimed.
#[test]
fn minus_half_defect() {
    let l = 64;
    let (cx, cy) = (20.7, 40.2);
    let (qxx, qxy) = nematic_defect(l, cx, cy, -1.0, 0.3);
    let mut out = Vec::new();
    DefectFinder::default().find(&qxx, &qxy, l, &mut out);
    let near: Vec<_> = out.iter().filter(|d| periodic_distance(d.x, d.y, cx, cy, l) < 12.0).collect();
    assert_eq!(near.len(), 1, "{near:?}");
    assert_eq!(near[0].twice_charge, -1);
    assert_eq!(near[0].charge(), -0.5);
    assert!(periodic_distance(near[0].x, near[0].y, cx, cy, l) < 0.25, "{:?}", near[0]);
    assert!(near[0].orientation.is_nan());
}

/// A +½ and a −½ defect at known off-lattice sites in one field on the torus: θ = ½ arg(r − r₊)
/// − ½ arg(r − r₋). The pair's far field is nearly uniform, so the box's seams carry no defect:
/// exactly two are found, each with its charge, at its site, the +½ pointing as the −½'s far
/// field turns it (ψ = −arg(r₊ − r₋)). A sign error in the winding, charges assigned to the
/// wrong core, or a spurious defect all fail it; the sum of the charges alone (zero on any
/// torus, by construction) could not.
#[test]
fn a_plus_and_minus_half_pair_is_found_with_charges_and_positions() {
    let l = 64;
    let (plus, minus) = ((27.3, 30.6), (37.7, 33.2));
    let (mut qxx, mut qxy) = (vec![0.0; l * l], vec![0.0; l * l]);
    for y in 0..l {
        for x in 0..l {
            let arg = |c: (f64, f64)| (y as f64 - c.1).atan2(x as f64 - c.0);
            let th = 0.5 * arg(plus) - 0.5 * arg(minus);
            qxx[y * l + x] = (2.0 * th).cos();
            qxy[y * l + x] = (2.0 * th).sin();
        }
    }
    let mut out = Vec::new();
    DefectFinder::default().find(&qxx, &qxy, l, &mut out);
    assert_eq!(out.len(), 2, "{out:?}");
    let p = out.iter().find(|d| d.twice_charge == 1).expect("a +½ defect");
    let m = out.iter().find(|d| d.twice_charge == -1).expect("a −½ defect");
    let (dp, dm) = (periodic_distance(p.x, p.y, plus.0, plus.1, l), periodic_distance(m.x, m.y, minus.0, minus.1, l));
    let want = -(plus.1 - minus.1).atan2(plus.0 - minus.0);
    eprintln!("+½ {dp:.3} from its site, orientation {} (want {want}); −½ {dm:.3} from its site", p.orientation);
    assert!(dp < 0.25 && dm < 0.25, "{out:?}");
    assert!(angle_diff(p.orientation, want).abs() < 0.1, "orientation {} want {want}", p.orientation);
    assert!(m.orientation.is_nan());
}

/// The analysis's active force (`CoarseFields::add_cell`, Eq. S4 with a_i = f^a_i) is
/// Σ_i φ_i f^a_i with f^a_i exactly as the dynamics computes it (`forces::force_density` with
/// μ = 0), site by site, for two elongated cells; and the sign and size of ∇·f^a: for a field
/// that vanishes away from the seams, central differences give exactly
///   Σ (x − c)² ∇·F = −2 Σ (x − c) F_x,
/// and the window mean keeps first moments, so the smoothed divergence's second moments are fixed
/// by the raw field. For an extensile cell along x, f^a pulls the tips outwards
/// (Σ (x − c) F_x > 0) and the flanks in: Σ (x − c)² ∇·f^a < 0 < Σ (y − c)² ∇·f^a.
#[test]
fn the_analysis_active_force_is_the_dynamics_one() {
    let l = 128;
    let p = Params { box_size: l, n_cells: 2, relax_steps: 0, zeta: 0.7, ..Params::default() };
    let (w, h) = (40, 30);
    let cells = vec![
        (Patch { x0: 20, y0: 20, w, h }, common::ellipse(w, h, 13.0, 6.0, 0.0)),
        (Patch { x0: 70, y0: 80, w, h }, common::ellipse(w, h, 12.0, 7.0, 0.6)),
    ];
    let mut m = common::with_cells(p.clone(), cells, 0);
    m.evaluate_now().unwrap();
    let mut a = Analysis::new(&p);
    a.measure(&m);
    // Σ_i φ_i f^a_i from forces.rs.
    let (mut fx, mut fy) = (vec![0.0; l * l], vec![0.0; l * l]);
    for c in m.cells() {
        let (pt, phi) = (c.patch(), c.phi().padded());
        let mu = vec![0.0; phi.len()];
        let (mut ax, mut ay) = (vec![0.0; phi.len()], vec![0.0; phi.len()]);
        force_density(pt, &phi, &mu, c.q_hat(), p.zeta, PassiveForce::GradMu, &mut ax, &mut ay);
        for b in 0..pt.h {
            for k in 0..pt.w {
                let (i, g) = (pt.idx(k, b), (pt.y0 + b) * l + pt.x0 + k);
                fx[g] += phi[i] * ax[i];
                fy[g] += phi[i] * ay[i];
            }
        }
    }
    let scale = fx.iter().chain(&fy).fold(0.0f64, |s, v| s.max(v.abs()));
    let worst = (0..l * l).map(|g| (fx[g] - a.raw.fx[g]).abs().max((fy[g] - a.raw.fy[g]).abs())).fold(0.0, f64::max);
    assert!(scale > 1e-2 && worst < 1e-12 * scale, "analysis f^a differs by {worst} of {scale}");
    // ∇·f^a of the first cell (centre (39.5, 34.5), along x): rows 0..64 hold all of its smoothed
    // field (rows 12..58) and none of the second cell's (rows 72..118).
    let (cx, cy) = (39.5, 34.5);
    let (mut div_xx, mut div_yy, mut fx_x, mut fy_y) = (0.0, 0.0, 0.0, 0.0);
    for y in 0..l / 2 {
        for x in 0..l {
            let (dx, dy, g) = (x as f64 - cx, y as f64 - cy, y * l + x);
            div_xx += dx * dx * a.active_force_divergence[g];
            div_yy += dy * dy * a.active_force_divergence[g];
            fx_x += dx * fx[g];
            fy_y += dy * fy[g];
        }
    }
    eprintln!("Σ(x−c)²∇·f = {div_xx}, Σ(y−c)²∇·f = {div_yy}; Σ(x−c)F_x = {fx_x}, Σ(y−c)F_y = {fy_y}");
    assert!(fx_x > 0.0 && fy_y < 0.0, "extensile: tips pulled out, flanks in ({fx_x}, {fy_y})");
    assert!((div_xx + 2.0 * fx_x).abs() < 1e-9 * fx_x.abs(), "Σ(x−c)²∇·f = {div_xx}, −2Σ(x−c)F_x = {}", -2.0 * fx_x);
    assert!((div_yy + 2.0 * fy_y).abs() < 1e-9 * fy_y.abs(), "Σ(y−c)²∇·f = {div_yy}, −2Σ(y−c)F_y = {}", -2.0 * fy_y);
}

/// v = g(r) R(α) r̂ about (cx, cy): |α| < π/2 spirals outwards (∇·v > 0), |α| > π/2 inwards.
fn swirl(l: usize, cx: f64, cy: f64, alpha: f64) -> (Vec<f64>, Vec<f64>) {
    let mut vx = vec![0.0; l * l];
    let mut vy = vec![0.0; l * l];
    for y in 0..l {
        for x in 0..l {
            let (dx, dy) = (delta(x as f64, cx, l), delta(y as f64, cy, l));
            let r = dx.hypot(dy);
            let g = r * (-(r / 10.0).powi(2)).exp();
            let phi = dy.atan2(dx) + alpha;
            vx[y * l + x] = g * phi.cos();
            vy[y * l + x] = g * phi.sin();
        }
    }
    (vx, vy)
}

/// Source spirals and sink vortices (inward spirals), turning either way, are all +1 points;
/// only the sources are spiral cores.
#[test]
fn source_spiral_is_a_core_and_sink_vortex_is_not() {
    let l = 64;
    let (cx, cy) = (33.4, 30.8);
    for (alpha, is_core) in [(FRAC_PI_4, true), (3.0 * FRAC_PI_4, false), (-FRAC_PI_4, true), (-3.0 * FRAC_PI_4, false)]
    {
        let (vx, vy) = swirl(l, cx, cy, alpha);
        let mut div = vec![0.0; l * l];
        divergence(&vx, &vy, &mut div, l, 1.0);
        let scale = div.iter().map(|d| d.abs()).sum::<f64>() / (l * l) as f64;
        let mut out = Vec::new();
        SpiralFinder::default().find(&vx, &vy, &div, l, &mut out);
        let near: Vec<_> = out.iter().filter(|p| periodic_distance(p.x, p.y, cx, cy, l) < 12.0).collect();
        assert_eq!(near.len(), 1, "α = {alpha}: {near:?}");
        assert!(periodic_distance(near[0].x, near[0].y, cx, cy, l) < 0.1, "α = {alpha}: {:?}", near[0]);
        assert_eq!(near[0].is_spiral_core(scale), is_core, "α = {alpha}: {:?}", near[0]);
    }
}

/// Σφ = 1 except in the given disks (centre x, y, radius), where it is 0.
fn tissue_with_holes(l: usize, disks: &[(f64, f64, f64)]) -> Vec<f64> {
    (0..l * l)
        .map(|k| {
            let (x, y) = ((k % l) as f64, (k / l) as f64);
            let inside = disks.iter().any(|&(cx, cy, r)| delta(x, cx, l).hypot(delta(y, cy, l)) <= r);
            if inside {
                0.0
            } else {
                1.0
            }
        })
        .collect()
}

/// A hole across the corner of the periodic box is one region with the disk's area and its
/// centroid on the box, and it nucleates (area > πR²/4).
#[test]
fn hole_across_the_periodic_edges() {
    let l = 140;
    let (cx, cy, r) = (0.5, 139.2, 6.0);
    let phi_sum = tissue_with_holes(l, &[(cx, cy, r)]);
    let mut voids = VoidRegions::default();
    voids.find(&phi_sum, l);
    assert_eq!(voids.regions.len(), 1, "{:?}", voids.regions);
    let region = voids.regions[0];
    assert_eq!(region.area, phi_sum.iter().filter(|&&s| s < 0.01).count());
    assert!(region.area > 100 && region.area < 120, "{}", region.area);
    assert!(periodic_distance(region.x, region.y, cx, cy, l) < 0.3, "{region:?}");
    assert!((voids.void_fraction - region.area as f64 / (l * l) as f64).abs() < 1e-15);
    assert!((voids.packing_fraction - (1.0 - voids.void_fraction)).abs() < 1e-15);
    let mut tracker = HoleTracker::new(8.0);
    tracker.update(&voids, 100.0);
    assert_eq!(tracker.holes.len(), 1);
    assert_eq!(tracker.holes[0].history, vec![(100.0, region.area, region.x, region.y)]);
}

/// Two holes that grow into each other: one continues, the other closes as merged into it.
#[test]
fn two_holes_merge() {
    let l = 140;
    let mut voids = VoidRegions::default();
    let mut tracker = HoleTracker::new(8.0);
    let frames = [
        vec![(40.0, 70.0, 5.0), (53.0, 70.0, 5.0)],
        vec![(40.0, 70.0, 5.5), (53.0, 70.0, 5.5)],
        vec![(40.0, 70.0, 7.0), (53.0, 70.0, 7.0)],
        vec![(46.0, 70.0, 9.0)],
    ];
    for (t, disks) in frames.iter().enumerate() {
        voids.find(&tissue_with_holes(l, disks), l);
        tracker.update(&voids, t as f64);
    }
    let h = &tracker.holes;
    assert_eq!(h.len(), 2, "{h:?}");
    assert_eq!(h[0].closed, None);
    assert_eq!(h[0].history.len(), 4);
    assert_eq!(h[1].closed, Some(2.0), "merged at the third frame");
    assert_eq!(h[1].merged_into, Some(0));
    assert_eq!(h[1].lifetime(), Some(2.0));
    assert_eq!(h[1].fate(), "merged");
    assert_eq!(h[0].history[2].1, tissue_with_holes(l, &frames[2]).iter().filter(|&&s| s == 0.0).count());
}

/// A hole that shrinks below the nucleation area stays open until its last void site is gone;
/// a void never larger than πR²/4 is not a hole.
#[test]
fn a_hole_closes() {
    let l = 140;
    let mut voids = VoidRegions::default();
    let mut tracker = HoleTracker::new(8.0);
    let small = (100.0, 20.0, 2.0);
    let frames = [vec![small], vec![(60.0, 60.0, 6.0), small], vec![(60.5, 60.0, 2.5)], vec![], vec![small]];
    for (t, disks) in frames.iter().enumerate() {
        voids.find(&tissue_with_holes(l, disks), l);
        tracker.update(&voids, 10.0 * t as f64);
    }
    let h = &tracker.holes;
    assert_eq!(h.len(), 1, "{h:?}");
    assert_eq!(h[0].nucleated, 10.0);
    assert_eq!(h[0].closed, Some(30.0));
    assert_eq!(h[0].lifetime(), Some(20.0));
    assert_eq!(h[0].fate(), "closed");
    assert_eq!(h[0].history.len(), 2);
    assert!(h[0].history[1].1 < 50, "shrunk below πR²/4 and still followed");
    assert_eq!(tracker.open().count(), 0);
}

/// A hole that breaks in two: the larger part keeps its identity, the other becomes a new hole.
#[test]
fn a_hole_splits() {
    let l = 140;
    let mut voids = VoidRegions::default();
    let mut tracker = HoleTracker::new(8.0);
    let frames = [vec![(70.0, 70.0, 10.0)], vec![(64.0, 70.0, 6.5), (77.0, 70.0, 5.0)]];
    for (t, disks) in frames.iter().enumerate() {
        voids.find(&tissue_with_holes(l, disks), l);
        tracker.update(&voids, t as f64);
    }
    let h = &tracker.holes;
    assert_eq!(h.len(), 2, "{h:?}");
    assert!(h[0].history[1].2 < 70.0, "the larger part (left) continues hole 0");
    assert_eq!(h[1].split_from, Some(0));
    assert_eq!(h[1].nucleated, 1.0);
}

/// P(hole | ε̇): the sites of a strained patch that opens into a hole in the next frame count as
/// hole sites in their strain-rate bin; a frame with a hole larger than half a cell open is not
/// counted, and a split-off or continuing hole is not a new one.
#[test]
fn hole_probability_counts_the_sites_that_open_next() {
    let l = 140;
    let a_small = (40.0, 40.0, 5.0);
    let a_large = (40.0, 40.0, 10.0);
    let b = (100.0, 100.0, 5.0);
    let strained: Vec<f64> =
        tissue_with_holes(l, &[a_small]).iter().map(|&s| if s == 0.0 { 0.0011 } else { 0.0 }).collect();
    let calm = vec![0.0; l * l];
    let frames = [(vec![], &strained), (vec![a_small], &calm), (vec![a_large], &calm), (vec![a_large, b], &calm)];
    let mut voids = VoidRegions::default();
    let mut tracker = HoleTracker::new(8.0);
    let mut p = HoleProbability::default();
    for (t, (disks, strain)) in frames.iter().enumerate() {
        voids.find(&tissue_with_holes(l, disks), l);
        tracker.update(&voids, t as f64);
        p.push(strain, &voids, &tracker, 8.0);
    }
    let a_sites = strained.iter().filter(|&&e| e > 0.0).count() as u64;
    assert!(a_sites > 50 && a_sites < 100, "{a_sites}");
    assert_eq!((p.frames_counted, p.frames_skipped), (2, 1), "the frame with hole A at r = 10 is skipped");
    let bin = (0.0011 / STRAIN_RATE_BIN).floor() as i64;
    assert_eq!(p.bins[&bin], (a_sites, a_sites), "every strained site opened into hole A");
    let all = (l * l) as u64;
    assert_eq!(
        p.bins[&0],
        (2 * all - 2 * a_sites, 0),
        "no unstrained site did; hole B was not counted, nor hole A's sites, void in frame 1"
    );
    assert_eq!(p.bins.len(), 2);
    let rows: Vec<_> = p.table().collect();
    assert_eq!(rows[1].3, 1.0);
    assert!((rows[1].0 - bin as f64 * STRAIN_RATE_BIN).abs() < 1e-15);
}

/// A site already void in its frame is not counted: a sub-threshold void that grows into a hole
/// in the next frame would otherwise count as strained sites that "opened", at P → 1.
#[test]
fn hole_probability_does_not_count_sites_already_void() {
    let l = 140;
    let seed_void = (40.0, 40.0, 2.0); // 13 sites: below πR²/4 ≈ 50, not a hole
    let hole = (40.0, 40.0, 5.0);
    let strained: Vec<f64> =
        tissue_with_holes(l, &[hole]).iter().map(|&s| if s == 0.0 { 0.0011 } else { 0.0 }).collect();
    let mut voids = VoidRegions::default();
    let mut tracker = HoleTracker::new(8.0);
    let mut p = HoleProbability::default();
    for (t, disks) in [vec![seed_void], vec![hole]].iter().enumerate() {
        voids.find(&tissue_with_holes(l, disks), l);
        tracker.update(&voids, t as f64);
        p.push(&strained, &voids, &tracker, 8.0);
    }
    let hole_sites = strained.iter().filter(|&&e| e > 0.0).count() as u64;
    let already = tissue_with_holes(l, &[seed_void]).iter().filter(|&&s| s == 0.0).count() as u64;
    assert_eq!(already, 13);
    let bin = (0.0011 / STRAIN_RATE_BIN).floor() as i64;
    assert_eq!(p.bins[&bin], (hole_sites - already, hole_sites - already));
}

/// Fig. 2's exclusion as the paper words it: once a hole has grown above half a cell, no frame
/// counts "until the hole closes", also after it has shrunk back below πR²/2; the frame after it
/// closed counts again, and the hole that opens next is a new one.
#[test]
fn hole_probability_excludes_frames_until_a_large_hole_closes() {
    let l = 140;
    let small = (40.0, 40.0, 5.0);
    let large = (40.0, 40.0, 10.0);
    let b = (100.0, 100.0, 5.0);
    // πR²/4 ≈ 50 < a disk of radius 5 (≈ 81 sites) < πR²/2 ≈ 101 < a disk of radius 10.
    let frames: [Vec<(f64, f64, f64)>; 6] = [vec![], vec![small], vec![large], vec![small], vec![], vec![b]];
    let strain: Vec<f64> = tissue_with_holes(l, &[b]).iter().map(|&s| if s == 0.0 { 0.0011 } else { 0.0 }).collect();
    let mut voids = VoidRegions::default();
    let mut tracker = HoleTracker::new(8.0);
    let mut p = HoleProbability::default();
    for (t, disks) in frames.iter().enumerate() {
        voids.find(&tissue_with_holes(l, disks), l);
        tracker.update(&voids, t as f64);
        p.push(&strain, &voids, &tracker, 8.0);
    }
    // Counted: frames 0, 1 and 4; skipped: 2 (A large) and 3 (A shrunk below πR²/2, still open).
    assert_eq!((p.frames_counted, p.frames_skipped), (3, 2), "frame 3 must be skipped: hole A has not closed");
    let bin = (0.0011 / STRAIN_RATE_BIN).floor() as i64;
    let b_sites = strain.iter().filter(|&&e| e > 0.0).count() as u64;
    assert_eq!(p.bins[&bin], (3 * b_sites, b_sites), "B opens after A closed and counts");
}

/// Before a hole: the distances from its nucleation centroid to the spiral core and the two
/// nearest +½ defects (in R; −½ defects ignored) and the strain rate near it over the frame's
/// largest, in the frame of nucleation and the frames before.
#[test]
fn precursors_of_a_hole() {
    let p = Params::default();
    let (l, r) = (p.box_size, p.radius);
    let mut a = Analysis::new(&p);
    let mut tracker = HoleTracker::new(r);
    let mut pre = Precursors::default();
    let defect = |x, y, q| Defect { x, y, twice_charge: q, orientation: 0.0 };
    // Frame 0: a spiral core on the future hole, +½ defects 1 R and 2 R away, a −½ closer.
    a.plus_ones = vec![PlusOne { x: 50.0, y: 50.0, divergence: 1.0 }, PlusOne { x: 90.0, y: 90.0, divergence: -1.0 }];
    a.defects = vec![defect(58.0, 50.0, 1), defect(50.0, 50.0 + 2.0 * r, 1), defect(52.0, 50.0, -1)];
    a.strain_rate = vec![0.0; l * l];
    a.strain_rate[50 * l + 51] = 2.0;
    a.strain_rate[100 * l + 100] = 4.0;
    a.voids.find(&tissue_with_holes(l, &[]), l);
    tracker.update(&a.voids, 0.0);
    pre.push(&a, &tracker);
    assert!(pre.rows.is_empty());
    // Frame 1: the hole opens there; the spiral core has moved R/2 away, strain is flat.
    a.plus_ones = vec![PlusOne { x: 54.0, y: 50.0, divergence: 1.0 }];
    a.defects.clear();
    a.strain_rate = vec![1.0; l * l];
    a.voids.find(&tissue_with_holes(l, &[(50.0, 50.0, 6.0)]), l);
    tracker.update(&a.voids, 1.0);
    pre.push(&a, &tracker);
    assert_eq!(pre.rows.len(), 2, "{:?}", pre.rows);
    let (now, before) = (pre.rows[0], pre.rows[1]);
    assert_eq!((now.hole, now.frames_before, before.frames_before), (0, 0, 1));
    assert!((now.spiral_core.unwrap() - 0.5).abs() < 1e-9, "{now:?}");
    assert_eq!(now.plus_half, [None, None]);
    assert_eq!(now.strain_rate, 1.0);
    assert!(before.spiral_core.unwrap() < 1e-9, "the sink at (90, 90) is not a spiral core: {before:?}");
    assert!((before.plus_half[0].unwrap() - 1.0).abs() < 1e-9 && (before.plus_half[1].unwrap() - 2.0).abs() < 1e-9);
    assert_eq!(before.strain_rate, 0.5);
    // The −½ defect 2 sites away; the two +½ of frame 0 both point along x: parallel.
    assert!((before.minus_half.unwrap() - 2.0 / r).abs() < 1e-9, "{before:?}");
    assert_eq!(before.plus_half_angle, Some(0.0));
    assert_eq!((now.minus_half, now.plus_half_angle), (None, None));
    // The chance baseline: CHANCE_SITES random sites in each of the same two frames, measured alike.
    assert_eq!(pre.chance.len(), 2 * CHANCE_SITES);
    assert!(pre.chance.iter().all(|c| c.hole == 0 && c.frames_before <= 1));
    let frame1: Vec<_> = pre.chance.iter().filter(|c| c.frames_before == 0).collect();
    assert_eq!(frame1.len(), CHANCE_SITES);
    assert!(frame1.iter().all(|c| c.strain_rate == 1.0 && c.plus_half == [None, None]));
    // Random sites are mostly far from the one spiral core: their mean distance is many R.
    let mean = frame1.iter().map(|c| c.spiral_core.unwrap()).sum::<f64>() / CHANCE_SITES as f64;
    assert!(mean > 2.0, "the chance baseline sits near the core: {mean}");
    // Seeded: the same frames give the same baseline.
    let again = {
        let mut pre2 = Precursors::default();
        let mut t2 = HoleTracker::new(r);
        let mut b = Analysis::new(&p);
        b.plus_ones = a.plus_ones.clone();
        b.strain_rate = vec![1.0; l * l];
        b.voids.find(&tissue_with_holes(l, &[]), l);
        t2.update(&b.voids, 0.0);
        pre2.push(&b, &t2);
        b.voids.find(&tissue_with_holes(l, &[(50.0, 50.0, 6.0)]), l);
        t2.update(&b.voids, 1.0);
        pre2.push(&b, &t2);
        pre2.chance
    };
    let sites = |c: &[Precursor]| c.iter().map(|c| c.spiral_core).collect::<Vec<_>>();
    assert_eq!(sites(&again)[..CHANCE_SITES], sites(&pre.chance)[..CHANCE_SITES]);
}

/// The antiparallel +½ pair: two comets facing each other about a nucleation site give π, and
/// the random sites of the same frame see the same pair (the nearest two of only two).
#[test]
fn antiparallel_plus_half_pair_at_a_nucleation() {
    let p = Params::default();
    let (l, r) = (p.box_size, p.radius);
    let mut a = Analysis::new(&p);
    let mut tracker = HoleTracker::new(r);
    let mut pre = Precursors::default();
    let defect = |x, y, psi| Defect { x, y, twice_charge: 1, orientation: psi };
    a.defects = vec![defect(45.0, 50.0, 0.3), defect(55.0, 50.0, 0.3 - std::f64::consts::PI)];
    a.strain_rate = vec![1.0; l * l];
    a.voids.find(&tissue_with_holes(l, &[]), l);
    tracker.update(&a.voids, 0.0);
    pre.push(&a, &tracker);
    a.voids.find(&tissue_with_holes(l, &[(50.0, 50.0, 6.0)]), l);
    tracker.update(&a.voids, 1.0);
    pre.push(&a, &tracker);
    let before = pre.rows.iter().find(|p| p.frames_before == 1).unwrap();
    assert!((before.plus_half_angle.unwrap() - std::f64::consts::PI).abs() < 1e-12, "{before:?}");
    assert!((before.plus_half[0].unwrap() - 5.0 / r).abs() < 1e-9);
    assert!(pre.chance.iter().all(|c| (c.plus_half_angle.unwrap() - std::f64::consts::PI).abs() < 1e-12));
}

/// A smooth ellipse (tanh interface of width 2) with semi-axes (a, b), its long axis at angle
/// θ, centred at (cx, cy): a cell's (patch, φ on the padded patch).
fn elliptic_cell(cx: f64, cy: f64, a: f64, b: f64, theta: f64) -> (Patch, Vec<f64>) {
    let w = 2 * (a.ceil() as usize + 4);
    let (x0, y0) = (cx.round() as usize - w / 2, cy.round() as usize - w / 2);
    let patch = Patch { x0, y0, w, h: w };
    let mut phi = vec![0.0; patch.padded_len()];
    for j in 0..w {
        for i in 0..w {
            let (dx, dy) = ((x0 + i) as f64 - cx, (y0 + j) as f64 - cy);
            let (u, v) = (dx * theta.cos() + dy * theta.sin(), -dx * theta.sin() + dy * theta.cos());
            let r = (u * u / (a * a) + v * v / (b * b)).sqrt().max(1e-9);
            let grad = ((u / (a * a)).powi(2) + (v / (b * b)).powi(2)).sqrt() / r;
            let d = (r - 1.0) / grad.max(1e-9);
            phi[patch.idx(i, j)] = 0.5 * (1.0 - (d / 2.0).tanh());
        }
    }
    (patch, phi)
}

/// Tangential alignment on a synthetic hole: elliptic cells about a round hole, long axes along
/// the boundary, measured from their φ (centroid and shape tensor) give angles near 0 to the
/// tangent; the same cells turned radial give angles near π/2.
#[test]
fn cells_tangential_to_a_hole_measure_zero_and_radial_ones_a_right_angle() {
    let p = Params::default();
    let l = p.box_size;
    let (hx, hy, hr) = (70.0, 70.0, 10.0);
    let labels: Vec<u32> =
        (0..l * l).map(|k| if ((k % l) as f64 - hx).hypot((k / l) as f64 - hy) <= hr { 0 } else { u32::MAX }).collect();
    let mut boundary = Vec::new();
    boundary_sites(&labels, &[true], l, &mut boundary);
    let velocity = vec![C64::new(0.0, 0.0); l * l];
    for (turn, expect_tangential) in [(FRAC_PI_2, true), (0.0, false)] {
        let cells: Vec<(Patch, Vec<f64>)> = (0..12)
            .map(|k| {
                let t = k as f64 * PI / 6.0;
                elliptic_cell(hx + 20.0 * t.cos(), hy + 20.0 * t.sin(), 9.0, 4.0, t + turn)
            })
            .collect();
        let mut a = Analysis::new(&p);
        a.measure_cells(cells.iter().map(|(patch, phi)| (*patch, phi.as_slice(), [0.0, 0.0])), &velocity);
        assert_eq!(a.cell_axes.len(), 12);
        let (mut near, mut away) = (Vec::new(), Vec::new());
        tangential_angles(
            &a.cell_axes,
            &boundary,
            l,
            BORDER_RADII * p.radius,
            AWAY_RADII * p.radius,
            &mut near,
            &mut away,
        );
        assert_eq!((near.len(), away.len()), (12, 0), "{:?}", a.cell_axes);
        if expect_tangential {
            // The nearest boundary site is a lattice site: its normal is off by up to ~0.13 rad.
            assert!(near.iter().all(|&x| x < 0.2), "tangential cells: {near:?}");
        } else {
            assert!(near.iter().all(|&x| x > FRAC_PI_2 - 0.2), "radial cells: {near:?}");
        }
    }
}

/// The O(L²) sliding window equals the brute-force (2h+1)² window sum, periodic.
#[test]
fn smoothing_matches_a_brute_force_window_sum() {
    for (l, h) in [(30, 4), (40, 8), (17, 8)] {
        let src: Vec<f64> = (0..l * l).map(|k| noise(k, l as u64)).collect();
        let mut fast = vec![0.0; l * l];
        window_mean(&src, &mut fast, &mut Vec::new(), &mut Vec::new(), l, h);
        let hi = h as i64;
        let li = l as i64;
        for y in 0..li {
            for x in 0..li {
                let mut sum = 0.0;
                for dy in -hi..=hi {
                    for dx in -hi..=hi {
                        sum += src[((y + dy).rem_euclid(li) * li + (x + dx).rem_euclid(li)) as usize];
                    }
                }
                let brute = sum / ((2 * h + 1) * (2 * h + 1)) as f64;
                let got = fast[(y * li + x) as usize];
                assert!((got - brute).abs() < 1e-12, "L = {l}, h = {h}, ({x}, {y}): {got} vs {brute}");
            }
        }
    }
}

/// The FFT correlation equals the pair average over the periodic box, bin by bin.
#[test]
fn correlation_matches_the_pair_average() {
    let l = 20;
    let ax: Vec<f64> = (0..l * l).map(|k| noise(k, 1)).collect();
    let ay: Vec<f64> = (0..l * l).map(|k| noise(k, 2)).collect();
    let mut c = Vec::new();
    Correlator::new(l).correlate(&ax, &ay, &mut c);
    let bins = l / 2 + 1;
    let (mut sum, mut count) = (vec![0.0; bins], vec![0usize; bins]);
    let li = l as i64;
    for dy in 0..li {
        for dx in 0..li {
            let (mx, my) = (dx.min(li - dx) as f64, dy.min(li - dy) as f64);
            let r = mx.hypot(my).round() as usize;
            if r >= bins {
                continue;
            }
            for k in 0..l * l {
                let (x, y) = (k as i64 % li, k as i64 / li);
                let j = (((y + dy) % li) * li + (x + dx) % li) as usize;
                sum[r] += ax[k] * ax[j] + ay[k] * ay[j];
            }
            count[r] += l * l;
        }
    }
    let norm = sum[0] / count[0] as f64;
    for r in 0..bins {
        let brute = sum[r] / count[r] as f64 / norm;
        assert!((c[r] - brute).abs() < 1e-10, "r = {r}: {} vs {brute}", c[r]);
    }
    assert!((c[0] - 1.0).abs() < 1e-12);
}

/// J₀ by its power series (enough terms for z < 6).
fn bessel_j0(z: f64) -> f64 {
    let mut term = 1.0;
    let mut sum = 1.0;
    for k in 1..40 {
        term *= -(z * z / 4.0) / (k * k) as f64;
        sum += term;
    }
    sum
}

/// A plane wave v = (cos kx, 0) has C_v(r) = J₀(kr) once averaged over directions, so its
/// correlation length is the first root of J₀(z) = 1/e (z ≈ 1.752) over k.
#[test]
fn correlation_length_of_a_plane_wave() {
    let l = 140;
    let k = 2.0 * PI * 5.0 / l as f64;
    let ax: Vec<f64> = (0..l * l).map(|i| (k * (i % l) as f64).cos()).collect();
    let ay = vec![0.0; l * l];
    let mut c = Vec::new();
    Correlator::new(l).correlate(&ax, &ay, &mut c);
    for r in [2usize, 4, 6, 8, 10] {
        assert!((c[r] - bessel_j0(k * r as f64)).abs() < 0.03, "r = {r}: {} vs J₀ {}", c[r], bessel_j0(k * r as f64));
    }
    // First root of J₀(z) = 1/e by bisection.
    let (mut lo, mut hi) = (1.0, 2.4);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if bessel_j0(mid) > (-1.0f64).exp() {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    let want = lo / k;
    let got = correlation_length(&c).expect("crosses 1/e");
    assert!((got - want).abs() < 0.03 * want, "length {got}, want {want}");
    // A field correlated over the whole box never crosses: no length is claimed.
    let flat = vec![1.0; l * l];
    Correlator::new(l).correlate(&flat, &ay, &mut c);
    assert_eq!(correlation_length(&c), None);
}

/// The relaxed full-size tissue (paper: > 95 % packed, no gaps) has no void and no hole, and
/// defects; the measurement allocates nothing once warmed up. (That the ±½ charges sum to zero is
/// not checked: plaquette windings sum to zero on a torus by construction, whatever the finder
/// does. `a_plus_and_minus_half_pair_is_found_with_charges_and_positions` guards the charges.)
#[test]
#[ignore = "full size, minutes: scripts/test.sh runs it (cargo test --release -- --include-ignored)"]
fn relaxed_full_size_is_packed() {
    let m = common::relaxed_full_size();
    let mut a = Analysis::new(m.params());
    a.measure(m);
    let s = a.summary();
    assert!(s.packing_fraction > 0.95, "packing fraction {}", s.packing_fraction);
    assert_eq!(s.void_regions, 0);
    assert_eq!(s.holes, 0);
    assert!(!a.defects.is_empty(), "a disordered tissue has defects");
    assert!(a.defects.iter().all(|d| d.x >= 0.0 && d.x < 140.0 && d.y >= 0.0 && d.y < 140.0));
    assert_eq!(a.velocity_correlation.len(), 71);
    assert!((a.velocity_correlation[0] - 1.0).abs() < 1e-12);
    // The coarse-grained velocity equals the simulation's own Σφ_i v_i.
    let mut m2 = m.clone();
    let v = m2.velocity_field().to_vec();
    let worst = v
        .iter()
        .enumerate()
        .map(|(k, z)| (z.re - a.raw.vx[k]).abs().max((z.im - a.raw.vy[k]).abs()))
        .fold(0.0, f64::max);
    assert!(worst < 1e-12, "velocity field differs by {worst}");
    // Steady state: a second measurement reuses every buffer.
    let ptrs = (a.raw.vx.as_ptr(), a.strain_rate.as_ptr(), a.defects.as_ptr(), a.voids.labels.as_ptr());
    let caps = (a.defects.capacity(), a.plus_ones.capacity(), a.velocity_correlation.capacity());
    a.measure(m);
    assert_eq!(ptrs, (a.raw.vx.as_ptr(), a.strain_rate.as_ptr(), a.defects.as_ptr(), a.voids.labels.as_ptr()));
    assert_eq!(caps, (a.defects.capacity(), a.plus_ones.capacity(), a.velocity_correlation.capacity()));
}

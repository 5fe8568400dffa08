//! The sweep's tables: `summary.csv` (a row per run) and `regimes.csv` (a row per grid point, the
//! paper's Fig. 3d criterion), as text; `command` writes them with the regime map.

use std::fmt::Write as _;

use super::summary::RunSummary;
use crate::analysis::{classify, fitted_lifetime, Regime};
use crate::run::csv;

/// A grid point (all seeds pooled) and its regime.
#[derive(Clone, Debug)]
pub struct RegimePoint {
    pub values: Vec<(String, String)>,
    pub runs: usize,
    pub blew_up: usize,
    pub holes: usize,
    pub fitted_lifetime: Option<f64>,
    pub active_time: f64,
    pub regime: Regime,
    /// The fit and regime with every tracked void region counted as a hole.
    pub fitted_lifetime_regions: Option<f64>,
    pub regime_regions: Regime,
}

/// Pools the seeds of every grid point.
pub fn regime_map(summaries: &[RunSummary]) -> Vec<RegimePoint> {
    let mut points: Vec<RegimePoint> = Vec::new();
    // Per point: the holes counted as families, and as regions.
    type Pooled = (Vec<(f64, bool)>, Vec<(f64, bool)>);
    let mut pooled: Vec<Pooled> = Vec::new();
    // Only runs that ended count: a run stopped by the machine, or not yet run, says nothing of
    // the regime.
    for s in summaries.iter().filter(|s| s.status.is_complete()) {
        let k = match points.iter().position(|p| p.values == s.values) {
            Some(k) => k,
            None => {
                points.push(RegimePoint {
                    values: s.values.clone(),
                    runs: 0,
                    blew_up: 0,
                    holes: 0,
                    fitted_lifetime: None,
                    active_time: 0.0,
                    regime: Regime::NoHoles,
                    fitted_lifetime_regions: None,
                    regime_regions: Regime::NoHoles,
                });
                pooled.push((Vec::new(), Vec::new()));
                points.len() - 1
            }
        };
        let p = &mut points[k];
        p.runs += 1;
        p.blew_up += s.blew_up() as usize;
        p.holes += s.holes_nucleated;
        p.active_time = p.active_time.max(s.active_time);
        pooled[k].0.extend(&s.lifetimes);
        pooled[k].1.extend(&s.region_lifetimes);
    }
    for (p, (families, regions)) in points.iter_mut().zip(&pooled) {
        p.fitted_lifetime = fitted_lifetime(families);
        p.regime = classify(families, p.active_time);
        p.fitted_lifetime_regions = fitted_lifetime(regions);
        p.regime_regions = classify(regions, p.active_time);
    }
    points
}

/// `summary.csv` (one row per run) and `regimes.csv` (one row per grid point).
pub fn tables(summaries: &[RunSummary]) -> (String, String) {
    let keys: Vec<String> =
        summaries.first().map(|s| s.values.iter().map(|v| v.0.clone()).collect()).unwrap_or_default();
    let mut runs = String::from("run,");
    for k in &keys {
        runs += &format!("{k},");
    }
    runs += "seed,status,blew_up,steps,active_time,holes_nucleated,max_hole_area,time_with_hole_open,\
             hole_lifetimes,max_holes_open,fraction_multiple_holes,mean_speed,mean_speed_um_per_h,\
             mean_speed_um_per_h_at_3.6s,mean_speed_um_per_h_at_5s,velocity_correlation_length,\
             nematic_correlation_length,min_packing_fraction_without_hole,min_nonvoid_fraction_without_hole,\
             max_void_regions_with_hole,aspect_ratio_mean,aspect_ratio_p90,region_lifetimes\n";
    let list = |l: &[(f64, bool)]| -> String {
        l.iter().map(|(t, closed)| format!("{t:.1}{}", if *closed { "" } else { "+" })).collect::<Vec<_>>().join(";")
    };
    for s in summaries {
        let status = s.status.to_string().lines().next().unwrap_or("").replace(',', ";");
        let _ = write!(runs, "{},", s.name);
        for (_, v) in &s.values {
            let _ = write!(runs, "{v},");
        }
        let _ = writeln!(
            runs,
            "{},\"{}\",{},{},{:.1},{},{},{:.1},{},{},{:.4},{:.6},{:.3},{:.3},{:.3},{},{},{},{},{},{},{},{}",
            s.seed,
            status,
            s.blew_up(),
            s.steps,
            s.active_time,
            s.holes_nucleated,
            s.max_hole_area,
            s.time_with_hole_open,
            list(&s.lifetimes),
            s.max_holes_open,
            s.fraction_multiple_holes,
            s.mean_speed,
            s.mean_speed * s.microns_per_hour,
            s.mean_speed * 3600.0 / 3.6,
            s.mean_speed * 3600.0 / 5.0,
            csv::cell(s.velocity_correlation_length, 6),
            csv::cell(s.nematic_correlation_length, 6),
            csv::cell(s.min_packing_without_hole, 6),
            csv::cell(s.min_nonvoid_without_hole, 6),
            s.max_void_regions_with_hole,
            csv::cell(s.aspect_ratio_mean, 6),
            csv::cell(s.aspect_ratio_p90, 6),
            list(&s.region_lifetimes)
        );
    }
    let mut regimes = String::new();
    for k in &keys {
        regimes += &format!("{k},");
    }
    regimes += "runs,blew_up,holes,fitted_lifetime,active_time,regime,fitted_lifetime_regions,regime_regions\n";
    let fit =
        |t: Option<f64>| t.map(|t| if t.is_finite() { format!("{t:.1}") } else { "inf".into() }).unwrap_or_default();
    for p in regime_map(summaries) {
        for (_, v) in &p.values {
            let _ = write!(regimes, "{v},");
        }
        let _ = writeln!(
            regimes,
            "{},{},{},{},{:.1},{},{},{}",
            p.runs,
            p.blew_up,
            p.holes,
            fit(p.fitted_lifetime),
            p.active_time,
            p.regime.name(),
            fit(p.fitted_lifetime_regions),
            p.regime_regions.name()
        );
    }
    (runs, regimes)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::RunStatus;

    /// The regime criterion pools the holes counted as families; the regions' fit is reported
    /// beside it. One long hole whose fragments break off and close (the pattern of the
    /// low-friction runs): persistent as a family, short-lived as regions.
    #[test]
    fn regimes_pool_families_and_report_regions_beside() {
        let run = |seed| RunSummary {
            name: format!("chi0.001_seed{seed}"),
            values: vec![("chi".into(), "0.001".into())],
            seed,
            status: RunStatus::Finished,
            active_time: 10_000.0,
            holes_nucleated: 1,
            lifetimes: vec![(8_000.0, false)],
            region_lifetimes: vec![(8_000.0, false), (100.0, true), (200.0, true), (300.0, true)],
            ..RunSummary::default()
        };
        let map = regime_map(&[run(1), run(2)]);
        assert_eq!(map.len(), 1);
        let p = &map[0];
        assert_eq!((p.runs, p.holes), (2, 2));
        assert_eq!((p.fitted_lifetime, p.regime), (Some(f64::INFINITY), Regime::ShortAndLongLived));
        // Regions: 17,200 time units over 6 closed holes.
        assert_eq!(p.fitted_lifetime_regions, Some(17_200.0 / 6.0));
        assert_eq!(p.regime_regions, Regime::OnlyShortLived);
        let (summary, regimes) = tables(&[run(1)]);
        assert!(summary.lines().next().unwrap().ends_with(",region_lifetimes"), "{summary}");
        assert!(summary.lines().nth(1).unwrap().ends_with(",8000.0+;100.0;200.0;300.0"), "{summary}");
        assert!(regimes.contains(",regime,fitted_lifetime_regions,regime_regions\n"), "{regimes}");
        assert!(regimes.contains(",short_and_long_lived,2866.7,only_short_lived\n"), "{regimes}");
    }
}

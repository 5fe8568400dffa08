//! `monolayer forecast RUN_DIR…`: the paper's argument put to a test. Every nucleation's local
//! thinning in the frames before it; each precursor measure against sites of the same thinning
//! (and against random sites); and a forecast of where a hole nucleates next, scored on the
//! runs of each seed with the combination fitted on the other seeds only (leave one seed out).
//! The measures are `analysis::forecast`'s; this file reads the runs and writes the tables and
//! the ROC figure (docs/figures.md, "Forecast").

use std::collections::BTreeSet;
use std::fmt::Write as _;
use std::io::Write as _;
use std::path::{Path, PathBuf};

use plotters::prelude::*;

use super::files::{check_output_dir, read_run_frame, write_atomic, write_set, RunFrames};
use super::plots::{both_of, plot_err, Draw, FONT, PALETTE};
use crate::analysis::{
    caught_in_top, forecast_samples, matched_baseline, roc_auc, roc_curve, Analysis, BaselineRow, Features,
    HoleTracker, Logistic, Precursor, Predictor, RunHistory, Sample, ThinningRow, DEPTH, HORIZONS,
};
use crate::formats::RunStatus;
use crate::run::error::RunError;

/// The fit sees every tearing site and one in this many of the others; the intercept is
/// corrected by ln of it, and no ranking depends on it.
const NEGATIVE_THINNING: usize = 4;
/// The horizon (an index into [`HORIZONS`]) of the ROC figure and of the page's model.
pub const SHOWN_HORIZON: usize = 1;

/// One run, reduced to what the forecast needs.
struct RunData {
    name: String,
    seed: u64,
    params: crate::model::Params,
    /// (step, path) of every frame, in order.
    frames: Vec<(u64, PathBuf)>,
    history: RunHistory,
    samples: Vec<Sample>,
    thinning: Vec<ThinningRow>,
    baseline: Vec<BaselineRow>,
}

/// All sites or only those still covered (least Σφ within R/2 ≥ ½).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Subset {
    All,
    Covered,
}

impl Subset {
    const BOTH: [Subset; 2] = [Subset::All, Subset::Covered];
    fn name(self) -> &'static str {
        match self {
            Subset::All => "all",
            Subset::Covered => "covered",
        }
    }
    fn keeps(self, s: &Sample) -> bool {
        self == Subset::All || s.covered
    }
}

/// Reads and measures one run's frames (finished runs only unless `partial`).
fn measure_run(dir: &Path, partial: bool) -> Result<RunData, RunError> {
    let run = RunFrames::open(dir)?;
    let record = &run.record;
    if !partial && record.status != RunStatus::Finished {
        return Err(RunError::file(
            dir,
            format!("the run has not finished ({}); --partial scores the frames written so far", record.status),
        ));
    }
    let params = &record.params;
    let mut a = Analysis::new(params);
    let mut tracker = HoleTracker::new(params.radius);
    let mut history = RunHistory::new(params.box_size, params.radius);
    for frame in run.read() {
        let frame = frame?;
        let step = frame.data.step;
        a.measure_cells(frame.data.cell_views(), &frame.data.velocity);
        tracker.update(&a.voids, frame.data.time);
        history.push(&a, &tracker, step);
    }
    let thinning = crate::analysis::thinning_before(&history, DEPTH);
    let baseline = matched_baseline(&history, DEPTH);
    let samples = forecast_samples(&history);
    // The frames' fields are no longer needed; the nucleations and the sub-grid are.
    history.frames = Vec::new();
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| dir.display().to_string());
    Ok(RunData {
        name,
        seed: record.seed,
        params: params.clone(),
        frames: run.frames.clone(),
        history,
        samples,
        thinning,
        baseline,
    })
}

/// One held-out score: a predictor on the runs of one seed.
#[derive(Clone, Debug)]
struct FoldScore {
    seed: u64,
    predictor: Predictor,
    horizon: usize,
    subset: Subset,
    auc: Option<f64>,
    caught: usize,
    counted: usize,
    positives: usize,
    sites: usize,
}

/// The training pairs of `runs` for one horizon and subset.
fn training(runs: &[&RunData], hi: usize, subset: Subset) -> Vec<(Features, bool)> {
    let mut out = Vec::new();
    let mut negatives = 0usize;
    for r in runs {
        for s in r.samples.iter().filter(|s| subset.keeps(s)) {
            let y = s.labels[hi];
            if !y {
                negatives += 1;
                if !negatives.is_multiple_of(NEGATIVE_THINNING) {
                    continue;
                }
            }
            out.push((s.inputs(), y));
        }
    }
    out
}

/// The combination fitted on `runs`, its intercept corrected for the thinned negatives.
fn fit(runs: &[&RunData], hi: usize, subset: Subset) -> Option<Logistic> {
    let mut m = Logistic::fit(&training(runs, hi, subset))?;
    m.weights[0] -= (NEGATIVE_THINNING as f64).ln();
    Some(m)
}

/// Leave one seed out: for each seed, the combination is fitted on the other seeds' runs and
/// every predictor scored on this seed's runs. Returns the scores and, for the ROC figure, the
/// held-out (score, tear) pairs pooled over folds at [`SHOWN_HORIZON`] per subset and predictor.
#[allow(clippy::type_complexity)]
fn cross_validate(runs: &[RunData]) -> (Vec<FoldScore>, Vec<Vec<Vec<(f64, bool)>>>) {
    let seeds: BTreeSet<u64> = runs.iter().map(|r| r.seed).collect();
    let mut scores = Vec::new();
    let mut pooled = vec![vec![Vec::new(); Predictor::ALL.len()]; Subset::BOTH.len()];
    for &seed in &seeds {
        let train: Vec<&RunData> = runs.iter().filter(|r| r.seed != seed).collect();
        let test: Vec<&RunData> = runs.iter().filter(|r| r.seed == seed).collect();
        for (hi, &horizon) in HORIZONS.iter().enumerate() {
            for (si, subset) in Subset::BOTH.into_iter().enumerate() {
                let model = fit(&train, hi, subset);
                for (pi, predictor) in Predictor::ALL.into_iter().enumerate() {
                    if predictor == Predictor::Combined && model.is_none() {
                        continue;
                    }
                    let mut scored = Vec::new();
                    let (mut caught, mut counted) = (0, 0);
                    for r in &test {
                        let all: Vec<f64> = r.samples.iter().map(|s| predictor.score(s, model.as_ref())).collect();
                        let (c, n) = caught_in_top(&r.history, &r.samples, &all, horizon, |s| subset.keeps(s));
                        caught += c;
                        counted += n;
                        scored.extend(
                            r.samples
                                .iter()
                                .zip(&all)
                                .filter(|(s, _)| subset.keeps(s))
                                .map(|(s, &v)| (v, s.labels[hi])),
                        );
                    }
                    let positives = scored.iter().filter(|p| p.1).count();
                    let sites = scored.len();
                    let auc = roc_auc(&mut scored);
                    if hi == SHOWN_HORIZON {
                        pooled[si][pi].extend_from_slice(&scored);
                    }
                    scores.push(FoldScore { seed, predictor, horizon, subset, auc, caught, counted, positives, sites });
                }
            }
        }
    }
    // Each fold's pairs came sorted by their own fold; the curve needs them sorted together.
    for per_subset in &mut pooled {
        for pairs in per_subset.iter_mut() {
            pairs.sort_by(|a, b| a.0.total_cmp(&b.0));
        }
    }
    (scores, pooled)
}

/// Mean and standard deviation (n − 1) of `v`; the deviation is None below two values.
fn mean_sd(v: &[f64]) -> (f64, Option<f64>) {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    let sd = (v.len() > 1).then(|| (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt());
    (m, sd)
}

fn fmt_opt(v: Option<f64>) -> String {
    v.map(|x| format!("{x:.4}")).unwrap_or_default()
}

/// A precursor measure: its name, how to read it from a row, and the direction the paper's
/// claim predicts (+1: larger at a nucleation than by chance, −1: smaller).
type Measure = (&'static str, fn(&Precursor) -> Option<f64>, f64);

const MEASURES: [Measure; 6] = [
    ("spiral_core_distance", |p| p.spiral_core, -1.0),
    ("strain_rate_over_max", |p| Some(p.strain_rate), 1.0),
    ("plus_half_nearest", |p| p.plus_half[0], -1.0),
    ("plus_half_second", |p| p.plus_half[1], -1.0),
    ("minus_half_nearest", |p| p.minus_half, 1.0),
    ("plus_half_pair_angle", |p| p.plus_half_angle, 1.0),
];

fn mean_of(rows: &[Precursor], get: fn(&Precursor) -> Option<f64>) -> Option<f64> {
    let v: Vec<f64> = rows.iter().filter_map(get).filter(|x| x.is_finite()).collect();
    (!v.is_empty()).then(|| v.iter().sum::<f64>() / v.len() as f64)
}

/// The tables and the figure, as (file name, contents) and the figure's base path.
fn tables(runs: &[RunData], scores: &[FoldScore], model: Option<&Logistic>) -> Vec<(&'static str, String)> {
    let mut thinning = String::from("run,seed,hole,frames_before,least_sum_within_r,void_share_within_r,covered\n");
    for r in runs {
        for t in &r.thinning {
            let _ = writeln!(
                thinning,
                "{},{},{},{},{:.4},{:.4},{}",
                r.name, r.seed, t.hole, t.frames_before, t.least, t.void_share, t.covered
            );
        }
    }
    let mut baseline = String::from(
        "run,seed,hole,frames_before,covered,least_sum_within_r,matched_candidates,measure,site,matched_mean,random_mean\n",
    );
    for r in runs {
        for b in &r.baseline {
            for (name, get, _) in MEASURES {
                let _ = writeln!(
                    baseline,
                    "{},{},{},{},{},{:.4},{},{name},{},{},{}",
                    r.name,
                    r.seed,
                    b.thinning.hole,
                    b.thinning.frames_before,
                    b.thinning.covered,
                    b.thinning.least,
                    b.candidates,
                    fmt_opt(get(&b.site)),
                    fmt_opt(mean_of(&b.matched, get)),
                    fmt_opt(mean_of(&b.random, get)),
                );
            }
        }
    }
    let mut folds =
        String::from("held_out_seed,predictor,horizon,subset,auc,caught_in_top_1pc,nucleations,tearing_sites,sites\n");
    for s in scores {
        let _ = writeln!(
            folds,
            "{},{},{},{},{},{},{},{},{}",
            s.seed,
            s.predictor.name(),
            s.horizon,
            s.subset.name(),
            fmt_opt(s.auc),
            s.caught,
            s.counted,
            s.positives,
            s.sites
        );
    }
    let mut model_txt = String::new();
    if let Some(m) = model {
        let _ = writeln!(
            model_txt,
            "# The combination fitted on every run given, horizon {} frames, all sites; inputs (analysis::forecast::model_inputs): strain rate over the frame's largest, spiral-core distance / R capped, ln(least sum of phi within R + 0.01)\nmean = {:?}\nscale = {:?}\nweights = {:?}",
            HORIZONS[SHOWN_HORIZON], m.mean, m.scale, m.weights
        );
    }
    vec![
        ("thinning.csv", thinning),
        ("baseline.csv", baseline),
        ("baseline_summary.csv", baseline_summary(runs)),
        ("forecast_folds.csv", folds),
        ("forecast.csv", forecast_summary(scores)),
        ("forecast_model.txt", model_txt),
    ]
}

/// Per measure, frames before and subset: the mean at the sites, at matched and at random
/// sites over nucleations; the per-run mean difference site − matched, its mean and seed spread
/// (SD over runs), and in how many runs it has the claimed sign.
fn baseline_summary(runs: &[RunData]) -> String {
    let mut out = String::from(
        "measure,frames_before,subset,nucleations,runs,site_mean,matched_mean,random_mean,\
         site_minus_matched,seed_spread,runs_in_claimed_direction,beats_matched_by_more_than_spread\n",
    );
    for (name, get, sign) in MEASURES {
        for k in 0..=DEPTH {
            for subset in Subset::BOTH {
                let keep =
                    |b: &&BaselineRow| b.thinning.frames_before == k && (subset == Subset::All || b.thinning.covered);
                let (mut site, mut matched, mut random, mut per_run) = (Vec::new(), Vec::new(), Vec::new(), Vec::new());
                for r in runs {
                    let mut diffs = Vec::new();
                    for b in r.baseline.iter().filter(keep) {
                        let (s, m, q) = (get(&b.site), mean_of(&b.matched, get), mean_of(&b.random, get));
                        if let (Some(s), Some(m)) = (s, m) {
                            site.push(s);
                            matched.push(m);
                            diffs.push(s - m);
                        }
                        random.extend(q);
                    }
                    if !diffs.is_empty() {
                        per_run.push(diffs.iter().sum::<f64>() / diffs.len() as f64);
                    }
                }
                if site.is_empty() {
                    continue;
                }
                let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
                let (d, spread) = mean_sd(&per_run);
                let agree = per_run.iter().filter(|&&x| x * sign > 0.0).count();
                let beats = spread.is_some_and(|s| d * sign > s);
                let _ = writeln!(
                    out,
                    "{name},{k},{},{},{},{:.4},{:.4},{},{:.4},{},{agree},{beats}",
                    subset.name(),
                    site.len(),
                    per_run.len(),
                    mean(&site),
                    mean(&matched),
                    if random.is_empty() { String::new() } else { format!("{:.4}", mean(&random)) },
                    d,
                    fmt_opt(spread),
                );
            }
        }
    }
    out
}

/// Per predictor, horizon and subset: the held-out AUC and share caught in the top 1 %, mean
/// and SD over the held-out seeds; and the combination's gain over thinning alone, per seed.
fn forecast_summary(scores: &[FoldScore]) -> String {
    let mut out = String::from(
        "predictor,horizon,subset,seeds,auc_mean,auc_sd,caught_share_mean,caught_share_sd,nucleations,\
         gain_over_thinning_mean,gain_over_thinning_sd\n",
    );
    for subset in Subset::BOTH {
        for &horizon in &HORIZONS {
            for predictor in Predictor::ALL {
                let rows: Vec<&FoldScore> = scores
                    .iter()
                    .filter(|s| s.subset == subset && s.horizon == horizon && s.predictor == predictor)
                    .collect();
                let aucs: Vec<f64> = rows.iter().filter_map(|s| s.auc).collect();
                if aucs.is_empty() {
                    continue;
                }
                let shares: Vec<f64> =
                    rows.iter().filter(|s| s.counted > 0).map(|s| s.caught as f64 / s.counted as f64).collect();
                let gains: Vec<f64> = rows
                    .iter()
                    .filter_map(|s| {
                        let t = scores.iter().find(|t| {
                            t.seed == s.seed
                                && t.subset == subset
                                && t.horizon == horizon
                                && t.predictor == Predictor::Thinning
                        })?;
                        Some(s.auc? - t.auc?)
                    })
                    .collect();
                let (a, asd) = mean_sd(&aucs);
                let (c, csd) = if shares.is_empty() { (f64::NAN, None) } else { mean_sd(&shares) };
                let (g, gsd) = if gains.is_empty() { (f64::NAN, None) } else { mean_sd(&gains) };
                let _ = writeln!(
                    out,
                    "{},{horizon},{},{},{a:.4},{},{},{},{},{},{}",
                    predictor.name(),
                    subset.name(),
                    aucs.len(),
                    fmt_opt(asd),
                    if c.is_nan() { String::new() } else { format!("{c:.4}") },
                    fmt_opt(csd),
                    rows.iter().map(|s| s.counted).sum::<usize>(),
                    if g.is_nan() { String::new() } else { format!("{g:.4}") },
                    fmt_opt(gsd),
                );
            }
        }
    }
    out
}

/// The ROC curves of the held-out scores at [`SHOWN_HORIZON`], all sites and covered sites.
struct RocFigure<'a> {
    pooled: &'a [Vec<Vec<(f64, bool)>>],
    scores: &'a [FoldScore],
}

impl Draw for RocFigure<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, plotters::coord::Shift>) -> Result<(), RunError> {
        root.fill(&WHITE).map_err(plot_err)?;
        let panels = root.split_evenly((1, 2));
        let horizon = HORIZONS[SHOWN_HORIZON];
        for (si, (panel, subset)) in panels.iter().zip(Subset::BOTH).enumerate() {
            let mut chart = ChartBuilder::on(panel)
                .caption(
                    format!("Held-out ROC, a hole within R in {horizon} frames ({} sites)", subset.name()),
                    (FONT, 18),
                )
                .margin(12)
                .x_label_area_size(40)
                .y_label_area_size(50)
                .build_cartesian_2d(0.0..1.0, 0.0..1.0)
                .map_err(plot_err)?;
            chart
                .configure_mesh()
                .x_desc("false-positive rate")
                .y_desc("true-positive rate")
                .draw()
                .map_err(plot_err)?;
            chart.draw_series(LineSeries::new(vec![(0.0, 0.0), (1.0, 1.0)], BLACK.mix(0.3))).map_err(plot_err)?;
            for (pi, predictor) in Predictor::ALL.into_iter().enumerate() {
                let sorted = &self.pooled[si][pi];
                if sorted.is_empty() {
                    continue;
                }
                let aucs: Vec<f64> = self
                    .scores
                    .iter()
                    .filter(|s| s.subset == subset && s.horizon == horizon && s.predictor == predictor)
                    .filter_map(|s| s.auc)
                    .collect();
                let (m, sd) = mean_sd(&aucs);
                let c = PALETTE[pi];
                chart
                    .draw_series(LineSeries::new(roc_curve(sorted, 400), c.stroke_width(2)))
                    .map_err(plot_err)?
                    .label(format!(
                        "{}: AUC {m:.3} ± {}",
                        predictor.name(),
                        sd.map(|s| format!("{s:.3}")).unwrap_or("–".into())
                    ))
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
            }
            chart
                .configure_series_labels()
                .position(SeriesLabelPosition::LowerRight)
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .label_font((FONT, 13))
                .draw()
                .map_err(plot_err)?;
        }
        Ok(())
    }
}

/// `monolayer forecast DIR… --out OUT`: measures every run (all frames read before anything is
/// written), scores the forecast leaving one seed out, and writes the tables and the ROC figure
/// to `out` as one set. `progress` is told each run as it is read, `warn` what is left out (a
/// run given twice). Returns the files written.
pub fn forecast(
    dirs: &[PathBuf],
    out: &Path,
    partial: bool,
    progress: impl Fn(&str),
    warn: impl Fn(&str),
) -> Result<Vec<PathBuf>, RunError> {
    if dirs.is_empty() {
        return Err(RunError::Empty { name: "RUN_DIR", need: "run directory" });
    }
    check_output_dir("--out", out)?;
    let mut runs = Vec::with_capacity(dirs.len());
    for d in distinct_runs(dirs, &warn)? {
        let r = measure_run(d, partial)?;
        progress(&format!(
            "{}: seed {}, {} nucleations, {} scored sites",
            r.name,
            r.seed,
            r.history.nucleations.len(),
            r.samples.len()
        ));
        runs.push(r);
    }
    let seeds: BTreeSet<u64> = runs.iter().map(|r| r.seed).collect();
    if seeds.len() < 2 {
        return Err(RunError::TooFewSeeds(seeds.len()));
    }
    check_something_to_fit(&runs)?;
    let (scores, pooled) = cross_validate(&runs);
    let all: Vec<&RunData> = runs.iter().collect();
    let model = fit(&all, SHOWN_HORIZON, Subset::All);
    let is_fig1b = |name: &str| name.starts_with("fig1b_");
    write_set(out, is_fig1b, |stage| {
        let mut written = Vec::new();
        for (name, text) in tables(&runs, &scores, model.as_ref()) {
            let path = stage.join(name);
            write_atomic(&path, |w| w.write_all(text.as_bytes()).map_err(|e| RunError::io(&path, e)))?;
            written.push(path);
        }
        let roc = RocFigure { pooled: &pooled, scores: &scores };
        written.extend(both_of(&stage.join("forecast_roc"), (1400, 650), &roc)?);
        written.extend(fig1b(&runs, stage)?);
        Ok(written)
    })
}

/// The run directories given, each once: two names of one directory (`a` and `./a/`, a symbolic
/// link to it) would count its nucleations, and its seed, twice. A directory given again is
/// left out, and `warn` told so.
fn distinct_runs<'a>(dirs: &'a [PathBuf], warn: &impl Fn(&str)) -> Result<Vec<&'a PathBuf>, RunError> {
    let mut seen: Vec<(PathBuf, &PathBuf)> = Vec::new();
    for d in dirs {
        let real = std::fs::canonicalize(d).map_err(|e| RunError::io(d, e))?;
        match seen.iter().find(|(r, _)| *r == real) {
            Some((_, first)) => warn(&format!(
                "{} is the run {} again (both are {}): counted once",
                d.display(),
                first.display(),
                real.display()
            )),
            None => seen.push((real, d)),
        }
    }
    Ok(seen.into_iter().map(|(_, d)| d).collect())
}

/// Refuses runs in which no hole nucleates with a frame before it: no site would be labelled as
/// tearing, so there would be nothing to fit and nothing to score, only empty tables.
fn check_something_to_fit(runs: &[RunData]) -> Result<(), RunError> {
    let tearing = runs.iter().flat_map(|r| &r.samples).any(|s| s.labels.iter().any(|&l| l));
    if tearing {
        return Ok(());
    }
    Err(RunError::NothingToForecast {
        runs: runs.len(),
        nucleations: runs.iter().map(|r| r.history.nucleations.len()).sum(),
    })
}

/// Nucleations drawn as the paper's Fig. 1b.
const FIG1B_NUCLEATIONS: usize = 3;

/// Fig. 1b one frame before [`FIG1B_NUCLEATIONS`] nucleations: those whose site was still
/// covered then first, in the order of the runs given, then the others.
fn fig1b(runs: &[RunData], out: &Path) -> Result<Vec<PathBuf>, RunError> {
    let mut chosen: Vec<(&RunData, &ThinningRow)> = Vec::new();
    for covered in [true, false] {
        for r in runs {
            for t in r.thinning.iter().filter(|t| t.frames_before == 1 && t.covered == covered) {
                if chosen.len() < FIG1B_NUCLEATIONS {
                    chosen.push((r, t));
                }
            }
        }
    }
    let mut written = Vec::new();
    for (i, (r, t)) in chosen.into_iter().enumerate() {
        let n = r.history.nucleations.iter().find(|n| n.hole == t.hole).expect("a nucleation of the run");
        let (step, path) = &r.frames[n.frame - 1];
        let frame = read_run_frame(path, *step, &r.params)?;
        let mut a = Analysis::new(&r.params);
        a.measure_cells(frame.data.cell_views(), &frame.data.velocity);
        let caption = format!(
            "{}, hole {}: step {step}, one frame before it nucleates at ({:.0}, {:.0}); least Σφ within R {:.2}{}",
            r.name,
            t.hole,
            n.x,
            n.y,
            t.least,
            if t.covered { ", still covered" } else { "" }
        );
        written.extend(super::plots::nucleation_fields(
            &out.join(format!("fig1b_{}", i + 1)),
            &a,
            (n.x, n.y),
            caption,
        )?);
    }
    Ok(written)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_seed_spread_is_the_sample_deviation() {
        let (m, sd) = mean_sd(&[1.0, 2.0, 3.0]);
        assert_eq!((m, sd), (2.0, Some(1.0)));
        assert_eq!(mean_sd(&[4.0]).1, None);
    }
}

//! The figures, the fourth stage of `monolayer figures`: each figure's table and plot from the
//! measured runs, for the points the plan gives it, in its order.
//!
//! The tables are the figures' data exactly as drawn, written with fixed precision in the plan's
//! order, so that two executions of the same runs (here and on a cluster) give the same bytes.
//! The plots are drawn by [`super::plot`].

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::measures::{Measures, RunData};
use super::plan::{same, Figure, Friction, Plan, Point};
use super::plot::{self, Marker, Panel, Series};
use crate::analysis::{classify, correlation_length, fitted_lifetime, Precursor, Regime, DEPTH};
use crate::run::error::RunError;
use crate::run::files::write_text;

/// What the figures stage hands on: the measures it drew from, and each figure drawn, with every
/// file written (`plan.csv` first, then each figure's in the plan's order).
pub struct Drawn<'p> {
    pub measures: Measures<'p>,
    pub figures: Vec<Made>,
    pub files: Vec<PathBuf>,
}

/// Writes `plan.csv` (which run serves which figure) and draws every figure of the plan into
/// `out`: its CSV(s), PNG and SVG.
pub fn draw<'p>(measures: Measures<'p>, out: &Path) -> Result<Drawn<'p>, RunError> {
    let plan = measures.plan;
    let mut files = Vec::new();
    let plan_path = out.join("plan.csv");
    write_text(&plan_path, &plan.table())?;
    files.push(plan_path);
    let mut figures = Vec::new();
    for &f in &plan.figures {
        let made = figure(&measures, f, out)?;
        files.extend(made.files.iter().cloned());
        figures.push(made);
    }
    Ok(Drawn { measures, figures, files })
}

/// A figure drawn: its files and what `figures.md` says about it.
#[derive(Clone, Debug)]
pub struct Made {
    pub figure: Figure,
    pub files: Vec<PathBuf>,
    /// Runs used and how they were chosen.
    pub runs: String,
    /// The numbers measured, one line each.
    pub measured: Vec<String>,
}

/// Mean and standard error of the mean (0 for fewer than two values).
pub fn mean_sem(v: &[f64]) -> (f64, f64) {
    if v.is_empty() {
        return (f64::NAN, f64::NAN);
    }
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    if v.len() < 2 {
        return (m, 0.0);
    }
    let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / (n - 1.0);
    (m, (var / n).sqrt())
}

fn num(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.6}")
    } else if x.is_nan() {
        String::new()
    } else {
        "inf".into()
    }
}

fn is_chi(p: &Point, chi: f64) -> bool {
    matches!(p.friction, Friction::Chi(c) if same(c, chi))
}

/// The χ of a point, None for the dry limit.
fn chi_of(p: &Point) -> Option<f64> {
    match p.friction {
        Friction::Chi(c) => Some(c),
        Friction::Dry => None,
    }
}

/// The position of `x` among the distinct values of `values` in their order (a colour or a
/// marker per value).
fn rank(values: impl Iterator<Item = f64>, x: f64) -> usize {
    let mut seen: Vec<f64> = Vec::new();
    for v in values {
        if !seen.contains(&v) {
            seen.push(v);
        }
    }
    seen.iter().position(|&v| v == x).unwrap_or(0)
}

fn seeds_note(plan: &Plan, figure: Figure) -> String {
    let mut seeds: Vec<u64> = plan.runs_of(figure).map(|(j, _)| j.seed).collect();
    seeds.sort();
    seeds.dedup();
    let runs = plan.runs_of(figure).count();
    let s = match (seeds.first(), seeds.last()) {
        (Some(a), Some(b)) if a != b => format!("seeds {a}–{b}"),
        (Some(a), _) => format!("seed {a}"),
        _ => "no seeds".into(),
    };
    format!("{runs} runs ({s} per point)")
}

/// Draws one figure and writes its table(s).
fn figure(m: &Measures, figure: Figure, out: &Path) -> Result<Made, RunError> {
    let base = out.join(figure.stem());
    let mut made = Made { figure, files: Vec::new(), runs: seeds_note(m.plan, figure), measured: Vec::new() };
    match figure {
        Figure::Fig1c | Figure::Fig1d | Figure::FigS2 | Figure::Mechanism => {
            precursor_figure(m, figure, &base, &mut made)?
        }
        Figure::Fig2 => fig2(m, &base, &mut made)?,
        Figure::Fig3ab => holes_figure(m, figure, &base, &mut made)?,
        Figure::Fig3c => fig3c(m, &base, &mut made)?,
        Figure::Fig3d => fig3d(m, &base, &mut made)?,
        Figure::FigS1 => fig_s1(m, &base, &mut made)?,
        Figure::FigS3 => holes_figure(m, figure, &base, &mut made)?,
    }
    Ok(made)
}

fn csv(base: &Path, suffix: &str, text: &str, made: &mut Made) -> Result<(), RunError> {
    let path = PathBuf::from(format!("{}{suffix}.csv", base.display()));
    write_text(&path, text)?;
    made.files.push(path);
    Ok(())
}

/// Figs. 1c, 1d and S2: a precursor measure against frames before nucleation, one curve per χ,
/// averaged over every hole of every run at that χ.
fn precursor_figure(m: &Measures, figure: Figure, base: &Path, made: &mut Made) -> Result<(), RunError> {
    let plan = m.plan;
    // Each measure with the sign of (measure − chance) the paper's claim predicts.
    let columns: Vec<(&str, &str, Column, f64)> = match figure {
        Figure::Fig1c => {
            vec![("spiral_core_distance_over_r", "distance to the nearest spiral core / R", |p| p.spiral_core, -1.0)]
        }
        Figure::Fig1d => vec![(
            "max_strain_rate_within_r_half_over_max",
            "max ε̇ within R/2 / max ε̇",
            |p| Some(p.strain_rate).filter(|v| v.is_finite()),
            1.0,
        )],
        Figure::Mechanism => vec![
            (
                "plus_half_pair_angle_degrees",
                "angle between the two nearest +½ orientations (°)",
                |p| p.plus_half_angle.map(f64::to_degrees),
                1.0,
            ),
            // The claim is that holes do not open at −½ defects: not nearer than chance.
            ("nearest_minus_half_distance_over_r", "distance to the nearest −½ defect / R", |p| p.minus_half, 1.0),
        ],
        _ => vec![
            ("nearest_plus_half_distance_over_r", "distance to the nearest +½ defect / R", |p| p.plus_half[0], -1.0),
            (
                "second_plus_half_distance_over_r",
                "distance to the second nearest +½ defect / R",
                |p| p.plus_half[1],
                -1.0,
            ),
        ],
    };
    let mut text = String::from("chi,frames_before,holes");
    for (name, _, _, _) in &columns {
        let _ = write!(text, ",{name}_samples,{name}_mean,{name}_sem,{name}_chance_mean,{name}_chance_sem");
    }
    text.push('\n');
    let mut panels: Vec<Panel> =
        columns.iter().map(|(_, desc, _, _)| Panel::new("", "frames before nucleation (t − t_hole)", desc)).collect();
    for (k, point) in plan.points_of(figure).iter().enumerate() {
        let Some(chi) = chi_of(point) else { continue };
        let sel = m.select(figure, |p| is_chi(p, chi));
        if sel.is_empty() {
            continue;
        }
        let holes: usize = sel.iter().map(|r| r.precursors.iter().filter(|p| p.frames_before == 0).count()).sum();
        let mut line = Vec::new();
        for (c, (_, _, column, _)) in columns.iter().enumerate() {
            let mut series = Series::new(format!("χ = {chi} ({holes} holes)"), k);
            series.line = true;
            // Chance: the same measure about random sites of the same frames.
            let mut chance = Series::new(format!("χ = {chi}, chance"), k);
            chance.line = true;
            chance.marker = Marker::Faint;
            for before in 0..=DEPTH {
                let v = pooled_at(&sel, *column, before, false);
                let (m, e) = mean_sem(&v);
                let (mc, ec) = mean_sem(&pooled_at(&sel, *column, before, true));
                if c == 0 {
                    line.push(format!("{chi},{before},{holes}"));
                }
                let _ = write!(line[before], ",{},{},{},{},{}", v.len(), num(m), num(e), num(mc), num(ec));
                if mc.is_finite() {
                    chance.push(0.0 - before as f64, mc, ec);
                }
                // A χ without holes has no curve: the paper draws it at zero, which reads as a
                // hole at the defect; here it is absent, and the legend says why.
                if m.is_finite() {
                    series.push(0.0 - before as f64, m, e);
                }
            }
            if holes == 0 {
                series.label = format!("χ = {chi}: no hole in {} runs (not drawn)", sel.len());
            }
            panels[c].series.push(series);
            if !chance.points.is_empty() {
                panels[c].series.push(chance);
            }
        }
        for l in line {
            text += &l;
            text.push('\n');
        }
        let at0: Vec<String> =
            columns.iter().map(|(_, desc, column, sign)| precursor_line(&sel, desc, *column, *sign)).collect();
        made.measured.push(if holes == 0 {
            format!("χ = {chi}: no hole nucleated in {} runs (no curve; the paper draws such a χ at zero)", sel.len())
        } else {
            format!("χ = {chi}: {holes} holes in {} runs; {}", sel.len(), at0.join("; "))
        });
    }
    let titles: &[&str] = match figure {
        Figure::Fig1c => &["Fig. 1c: nearest spiral core before a hole"],
        Figure::Fig1d => &["Fig. 1d: strain rate at the nucleation site"],
        Figure::Mechanism => &["Antiparallel +½ pairs (180°: antiparallel)", "−½ defects near a nucleation"],
        _ => &["Fig. S2a: nearest +½ defect", "Fig. S2b: second nearest +½ defect"],
    };
    for (p, t) in panels.iter_mut().zip(titles) {
        // ζ is not in the paper's caption: the one used goes into the title.
        p.title = format!("{t} (ζ = {})", plan.base.zeta);
        p.y_from_zero = true;
        p.x_range = Some((-(DEPTH as f64) - 0.5, 0.5));
    }
    if figure == Figure::Mechanism {
        panels.push(alignment_panel(m, base, made)?);
    }
    csv(base, "", &text, made)?;
    made.files.extend(plot::panels(base, &panels)?);
    Ok(())
}

type Column = fn(&Precursor) -> Option<f64>;

/// One measure's values over `rows` at `before` frames before nucleation.
fn at_frame(rows: &[Precursor], column: Column, before: usize) -> Vec<f64> {
    rows.iter().filter(|p| p.frames_before == before).filter_map(column).collect()
}

/// The same over every nucleation of the runs `sel` (`chance`: over their random sites).
fn pooled_at(sel: &[&RunData], column: Column, before: usize, chance: bool) -> Vec<f64> {
    sel.iter().flat_map(|r| at_frame(if chance { &r.chance } else { &r.precursors }, column, before)).collect()
}

/// The report's line for one precursor measure over the runs `sel`: mean ± s.e. over
/// nucleations beside chance at 0, 1 and [`DEPTH`] frames before, and the seed spread: in how
/// many runs (each its own mean against its own chance, one frame before) the difference has
/// the sign the paper's claim predicts (`sign`: −1 nearer, +1 larger than chance).
fn precursor_line(sel: &[&RunData], desc: &str, column: Column, sign: f64) -> String {
    let pooled = |before: usize, chance: bool| mean_sem(&pooled_at(sel, column, before, chance));
    let frame = |before: usize| {
        let ((m, e), (c, ec)) = (pooled(before, false), pooled(before, true));
        format!("{} ± {} (chance {} ± {})", fmt(m), fmt(e), fmt(c), fmt(ec))
    };
    let diffs: Vec<f64> = sel
        .iter()
        .filter_map(|r| {
            let (m, _) = mean_sem(&at_frame(&r.precursors, column, 1));
            let (c, _) = mean_sem(&at_frame(&r.chance, column, 1));
            Some(m - c).filter(|d| d.is_finite())
        })
        .collect();
    let agree = diffs.iter().filter(|d| **d * sign > 0.0).count();
    format!(
        "{desc}: {} at nucleation, {} one frame before, {} {DEPTH} frames before; one frame before, {} than chance in {agree} of {} runs with a nucleation",
        frame(0),
        frame(1),
        frame(DEPTH),
        if sign < 0.0 { "nearer" } else { "larger" },
        diffs.len()
    )
}

/// The mechanism's tangential alignment: per χ, the mean angle between a cell's elongation axis
/// and the nearest hole boundary's tangent, for the cells bordering a hole and for the cells away
/// from holes (45°: random axes), with its table.
fn alignment_panel(m: &Measures, base: &Path, made: &mut Made) -> Result<Panel, RunError> {
    let plan = m.plan;
    use crate::analysis::{AWAY_RADII, BORDER_RADII};
    let mut text = String::from("chi,where,cell_frames,mean_angle_degrees,sem_degrees\n");
    let mut panel = Panel::new(
        &format!("Cells at a hole's edge (0°: tangential, 45°: random; ζ = {})", plan.base.zeta),
        "log10 χ",
        "angle between the cell axis and the hole's tangent (°)",
    );
    panel.y_from_zero = true;
    panel.hline = Some(45.0);
    panel.hline_label = "random axes (45°)".into();
    let mut near_s = Series::new(format!("cells within {BORDER_RADII} R of a hole"), 0);
    let mut away_s = Series::new(format!("cells farther than {AWAY_RADII} R"), 1);
    away_s.marker = Marker::Faint;
    for chi in plan.points_of(Figure::Mechanism).iter().filter_map(chi_of) {
        let sel = m.select(Figure::Mechanism, |p| is_chi(p, chi));
        if sel.is_empty() {
            continue;
        }
        let deg = |v: &[f64]| v.iter().map(|a| a.to_degrees()).collect::<Vec<f64>>();
        let near: Vec<f64> = sel.iter().flat_map(|r| deg(&r.alignment.0)).collect();
        let away: Vec<f64> = sel.iter().flat_map(|r| deg(&r.alignment.1)).collect();
        let (mn, en) = mean_sem(&near);
        let (ma, ea) = mean_sem(&away);
        let _ = writeln!(text, "{chi},bordering_a_hole,{},{},{}", near.len(), num(mn), num(en));
        let _ = writeln!(text, "{chi},away_from_holes,{},{},{}", away.len(), num(ma), num(ea));
        if mn.is_finite() {
            near_s.push(chi.log10(), mn, en);
        }
        if ma.is_finite() {
            away_s.push(chi.log10(), ma, ea);
        }
        made.measured.push(format!(
            "χ = {chi}: cells bordering a hole {}° ± {}° ({} cell-frames), away from holes {}° ± {}° ({}); 45° is random (the standard errors treat cell-frames as independent: they are not)",
            fmt(mn),
            fmt(en),
            near.len(),
            fmt(ma),
            fmt(ea),
            away.len()
        ));
    }
    panel.series.push(near_s);
    panel.series.push(away_s);
    csv(base, "_alignment", &text, made)?;
    Ok(panel)
}

pub fn fmt(x: f64) -> String {
    if x.is_nan() {
        "–".into()
    } else if x.is_infinite() {
        "∞".into()
    } else if x != 0.0 && (x.abs() < 1e-2 || x.abs() >= 1e4) {
        format!("{x:.3e}")
    } else {
        format!("{x:.3}")
    }
}

/// Fig. 2: P(hole | ε̇) per (χ, ζ), pooled over runs, with exponential fits; beside it the
/// paper's inset: the fitted coefficient against χ^0.1/ζ.
fn fig2(m: &Measures, base: &Path, made: &mut Made) -> Result<(), RunError> {
    use crate::analysis::{best_collapse_exponent, binomial_fit, collapse_scatter, least_squares_fit, STRAIN_RATE_BIN};
    let mut text =
        String::from("chi,zeta,strain_rate_low,strain_rate_high,sites,sites_opening_into_a_new_hole,probability\n");
    let mut fits = String::from(
        "chi,zeta,chi_0.1_over_zeta,bins_with_holes,hole_sites,\
         binomial_amplitude,binomial_coefficient,binomial_coefficient_se,\
         least_squares_amplitude,least_squares_coefficient,least_squares_coefficient_se,\
         runs_with_holes,binomial_coefficient_jackknife_se,least_squares_coefficient_jackknife_se\n",
    );
    let mut panel = Panel::new("Fig. 2: P(hole | ε̇)", "strain rate ε̇", "P(hole | ε̇)");
    panel.log_y = true;
    // The paper's inset, drawn beside the main panel, where it hides no points.
    let mut inset =
        Panel::new("Fig. 2 inset: the coefficient b", "χ^0.1 / ζ", "b (binomial ML) ± jackknife s.e. over runs");
    let mut inset_series = Series::new("", 0);
    // (χ, ζ, b) of each fit, binomial and least squares, for the collapse.
    let mut coefficients: [Vec<(f64, f64, f64)>; 2] = [Vec::new(), Vec::new()];
    let points = m.plan.points_of(Figure::Fig2);
    for point in points {
        let Some(chi) = chi_of(point) else { continue };
        let zeta = point.zeta;
        let (ci, zi) = (rank(points.iter().filter_map(chi_of), chi), rank(points.iter().map(|p| p.zeta), zeta));
        let sel = m.select(Figure::Fig2, |p| is_chi(p, chi) && same(p.zeta, zeta));
        if sel.is_empty() {
            continue;
        }
        let bins = pooled_probability(sel.iter().copied());
        let mut pts = Vec::new();
        let mut counts = Vec::new();
        for (&k, &(n, h)) in &bins {
            let lo = k as f64 * STRAIN_RATE_BIN;
            let p = h as f64 / n as f64;
            let _ = writeln!(text, "{chi},{zeta},{lo:.6},{:.6},{n},{h},{p:.6e}", lo + STRAIN_RATE_BIN);
            pts.push((lo, p, h as f64));
            counts.push((lo, n, h));
        }
        // χ = 0.01 empty, 0.005 faint, 0.001 filled, as in the paper; a colour per ζ.
        let marker = [Marker::Empty, Marker::Faint, Marker::Filled][ci];
        let mut s = Series::new(format!("χ = {chi}, ζ = {zeta}"), zi);
        s.marker = marker;
        for &(x, p, _) in pts.iter().filter(|p| p.1 > 0.0) {
            s.push(x, p, 0.0);
        }
        panel.series.push(s);
        let x = chi.powf(0.1) / zeta;
        let holes = pts.iter().filter(|p| p.2 > 0.0).count();
        let hole_sites: u64 = counts.iter().map(|c| c.2).sum();
        let ml = binomial_fit(&counts);
        let ls = least_squares_fit(&counts);
        for (list, f) in coefficients.iter_mut().zip([ml, ls]) {
            list.extend(f.map(|f| (chi, zeta, f.b)));
        }
        let cols = |f: Option<crate::analysis::ExponentialFit>| {
            f.map(|f| format!("{:.6e},{:.6e},{:.6e}", f.ln_a.exp(), f.b, f.se_b)).unwrap_or_else(|| ",,".into())
        };
        let with_holes = sel.iter().filter(|r| r.probability.values().any(|b| b.1 > 0)).count();
        let jk = |fit: CoefficientFit| jackknife_coefficient_se(&sel, fit);
        let (jk_ml, jk_ls) = (jk(binomial_fit), jk(least_squares_fit));
        let _ = writeln!(
            fits,
            "{chi},{zeta},{x:.6},{holes},{hole_sites},{},{},{with_holes},{},{}",
            cols(ml),
            cols(ls),
            jk_ml.map(|v| format!("{v:.6e}")).unwrap_or_default(),
            jk_ls.map(|v| format!("{v:.6e}")).unwrap_or_default()
        );
        let shown = |f: Option<crate::analysis::ExponentialFit>| {
            f.map(|f| format!("P = {} · exp(({} ± {}) ε̇)", fmt(f.ln_a.exp()), fmt(f.b), fmt(f.se_b)))
                .unwrap_or_else(|| "too few bins with holes".into())
        };
        let jk_text = match (jk_ml, jk_ls) {
            (Some(m), Some(q)) => format!("jackknife s.e. over runs of b: {} (binomial), {} (least squares)", fmt(m), fmt(q)),
            _ => format!("{with_holes} run(s) with hole sites: no jackknife over runs; the fits' own s.e. treat sites as independent"),
        };
        made.measured.push(format!(
            "χ = {chi}, ζ = {zeta} ({} runs, {hole_sites} hole sites in {holes} bins): binomial ML {}; least squares on ln P {}; {jk_text}",
            sel.len(),
            shown(ml),
            shown(ls)
        ));
        if let Some(f) = ml {
            let xs: Vec<f64> = pts.iter().filter(|p| p.1 > 0.0).map(|p| p.0).collect();
            let (x0, x1) = (xs.iter().copied().fold(f64::MAX, f64::min), xs.iter().copied().fold(f64::MIN, f64::max));
            let mut line = Series::new("", zi);
            line.marker = Marker::None;
            line.line = true;
            for t in 0..=20 {
                let e = x0 + (x1 - x0) * t as f64 / 20.0;
                line.push(e, (f.ln_a + f.b * e).exp(), 0.0);
            }
            panel.series.push(line);
            // The jackknife over runs; a point with one run with holes has none and is
            // drawn without an error bar (its binomial s.e. is in the fits' table).
            inset_series.push(x, f.b, jk_ml.unwrap_or(0.0));
        }
    }
    inset.series.push(inset_series);
    for (fit, points) in ["binomial ML", "least squares"].iter().zip(&coefficients) {
        let at = |a: f64| collapse_scatter(points, a).map_or("–".into(), fmt);
        if let Some((best, s)) = best_collapse_exponent(points) {
            made.measured.push(format!(
                "The inset's collapse ({fit}, {} points): ln b scatters by {} about a power law in χ^0.1/ζ, by {} in 1/ζ alone; the least scatter, {}, is at χ^a/ζ with a = {best:.2}",
                points.len(),
                at(0.1),
                at(0.0),
                fmt(s)
            ));
        }
    }
    csv(base, "", &text, made)?;
    csv(base, "_fits", &fits, made)?;
    made.files.extend(plot::panels(base, &[panel, inset])?);
    Ok(())
}

/// Fig. 2's bins of several runs added up: strain-rate bin → (sites, sites opening into a hole).
fn pooled_probability<'a>(runs: impl Iterator<Item = &'a RunData>) -> BTreeMap<i64, (u64, u64)> {
    let mut bins: BTreeMap<i64, (u64, u64)> = BTreeMap::new();
    for r in runs {
        for (&k, &(n, h)) in &r.probability {
            let e = bins.entry(k).or_insert((0, 0));
            e.0 += n;
            e.1 += h;
        }
    }
    bins
}

/// A fit of P(hole | ε̇) to (ε̇, sites, hole sites) bins.
type CoefficientFit = fn(&[(f64, u64, u64)]) -> Option<crate::analysis::ExponentialFit>;

/// The jackknife standard error over runs of a fit's coefficient b: each run left out in turn,
/// the others' bins pooled and fitted; √((n − 1)/n Σ (b₋ᵢ − b̄)²) over the n runs with hole sites
/// (a run without holes moves no fit's numerator but still counts its sites: it is left out in
/// turn too). None unless at least two runs have hole sites and every leave-one-out fit exists.
pub fn jackknife_coefficient_se(runs: &[&RunData], fit: CoefficientFit) -> Option<f64> {
    use crate::analysis::STRAIN_RATE_BIN;
    if runs.iter().filter(|r| r.probability.values().any(|b| b.1 > 0)).count() < 2 {
        return None;
    }
    let mut bs = Vec::with_capacity(runs.len());
    for leave in 0..runs.len() {
        let others = runs.iter().enumerate().filter(|&(i, _)| i != leave).map(|(_, r)| *r);
        let bins = pooled_probability(others);
        let counts: Vec<(f64, u64, u64)> =
            bins.iter().map(|(&k, &(n, h))| (k as f64 * STRAIN_RATE_BIN, n, h)).collect();
        bs.push(fit(&counts)?.b);
    }
    let n = bs.len() as f64;
    let mean = bs.iter().sum::<f64>() / n;
    Some(((n - 1.0) / n * bs.iter().map(|b| (b - mean).powi(2)).sum::<f64>()).sqrt())
}

/// Kaplan–Meier survival of (x, closed) with censoring: (x, at risk, closed there, S after).
pub fn survival(mut d: Vec<(f64, bool)>) -> Vec<(f64, usize, usize, f64)> {
    d.sort_by(|a, b| a.0.total_cmp(&b.0).then(b.1.cmp(&a.1)));
    let mut out = Vec::new();
    let mut s = 1.0;
    let mut i = 0;
    while i < d.len() {
        let x = d[i].0;
        let at_risk = d.len() - i;
        let mut closed = 0;
        while i < d.len() && d[i].0 == x {
            closed += d[i].1 as usize;
            i += 1;
        }
        if closed > 0 {
            s *= 1.0 - closed as f64 / at_risk as f64;
            out.push((x, at_risk, closed, s));
        }
    }
    out
}

/// Fig. 3c: the survival of holes against τ/t_total per (χ, ζ), with the exponential of the
/// fitted lifetime (maximum likelihood, open holes censored: the regime criterion's fit).
fn fig3c(m: &Measures, base: &Path, made: &mut Made) -> Result<(), RunError> {
    let mut text = String::from("chi,zeta,tau_over_total,at_risk,closed,survival\n");
    let mut fits = String::from("chi,zeta,runs,holes,closed,t_total,fitted_lifetime,fitted_lifetime_over_total\n");
    let mut panel = Panel::new("Fig. 3c: hole survival", "τ_hole / t_total", "survival probability");
    panel.y_from_zero = true;
    let points = m.plan.points_of(Figure::Fig3c);
    for point in points {
        let Some(chi) = chi_of(point) else { continue };
        let zeta = point.zeta;
        let (ci, zi) = (rank(points.iter().filter_map(chi_of), chi), rank(points.iter().map(|p| p.zeta), zeta));
        let sel = m.select(Figure::Fig3c, |p| is_chi(p, chi) && same(p.zeta, zeta));
        if sel.is_empty() {
            continue;
        }
        let t_total = sel.iter().map(|r| r.active_time).fold(0.0, f64::max);
        let lifetimes: Vec<(f64, bool)> =
            sel.iter().flat_map(|r| r.holes.iter()).map(|h| (h.duration, h.closed)).collect();
        let scaled: Vec<(f64, bool)> =
            lifetimes.iter().map(|&(t, c)| (if t_total > 0.0 { t / t_total } else { 0.0 }, c)).collect();
        let km = survival(scaled);
        let mut s = Series::new(format!("χ = {chi}, ζ = {zeta}"), zi);
        s.marker = [Marker::Empty, Marker::Filled][ci];
        s.push(0.0, 1.0, 0.0);
        for &(x, n, c, sv) in &km {
            let _ = writeln!(text, "{chi},{zeta},{x:.6},{n},{c},{sv:.6}");
            s.push(x, sv, 0.0);
        }
        panel.series.push(s);
        let closed = lifetimes.iter().filter(|l| l.1).count();
        let tau = fitted_lifetime(&lifetimes);
        let over = tau.map(|t| if t_total > 0.0 { t / t_total } else { f64::NAN });
        let _ = writeln!(
            fits,
            "{chi},{zeta},{},{},{closed},{t_total:.3},{},{}",
            sel.len(),
            lifetimes.len(),
            tau.map(num).unwrap_or_default(),
            over.map(num).unwrap_or_default()
        );
        if let Some(o) = over.filter(|o| o.is_finite() && *o > 0.0) {
            let mut line = Series::new("", zi);
            line.marker = Marker::None;
            line.line = true;
            for t in 0..=40 {
                let x = t as f64 / 40.0;
                line.push(x, (-x / o).exp(), 0.0);
            }
            panel.series.push(line);
        }
        made.measured.push(format!(
            "χ = {chi}, ζ = {zeta} ({} runs): {} holes, {closed} closed; fitted lifetime τ_h = {} time units = {} t_total",
            sel.len(),
            lifetimes.len(),
            tau.map(fmt).unwrap_or_else(|| "– (no holes)".into()),
            over.map(fmt).unwrap_or_else(|| "–".into())
        ));
    }
    csv(base, "", &text, made)?;
    csv(base, "_fits", &fits, made)?;
    made.files.extend(plot::panels(base, &[panel])?);
    Ok(())
}

/// Fig. 3d: the regime of every (χ, ζ), seeds pooled, by the paper's criterion.
fn fig3d(m: &Measures, base: &Path, made: &mut Made) -> Result<(), RunError> {
    let mut text = String::from("chi,zeta,runs,failed,holes,fitted_lifetime,t_total,regime\n");
    let mut cells = Vec::new();
    for point in m.plan.points_of(Figure::Fig3d) {
        let Some(chi) = chi_of(point) else { continue };
        let zeta = point.zeta;
        let sel = m.select(Figure::Fig3d, |p| is_chi(p, chi) && same(p.zeta, zeta));
        if sel.is_empty() {
            continue;
        }
        let lifetimes: Vec<(f64, bool)> =
            sel.iter().flat_map(|r| r.holes.iter()).map(|h| (h.duration, h.closed)).collect();
        let t_total = sel.iter().map(|r| r.active_time).fold(0.0, f64::max);
        let regime = classify(&lifetimes, t_total);
        let failed = sel.iter().filter(|r| r.failed()).count();
        let tau = fitted_lifetime(&lifetimes);
        let _ = writeln!(
            text,
            "{chi},{zeta},{},{failed},{},{},{t_total:.3},{}",
            sel.len(),
            lifetimes.len(),
            tau.map(num).unwrap_or_default(),
            regime.name()
        );
        cells.push((chi, zeta, regime, failed > 0));
        made.measured.push(format!(
            "χ = {chi}, ζ = {zeta}: {} ({} holes in {} runs{}; τ_h = {})",
            match regime {
                Regime::NoHoles => "no holes",
                Regime::OnlyShortLived => "only short-lived",
                Regime::ShortAndLongLived => "short- and long-lived",
            },
            lifetimes.len(),
            sel.len(),
            if failed > 0 { format!(", {failed} failed") } else { String::new() },
            tau.map(fmt).unwrap_or_else(|| "–".into())
        ));
    }
    csv(base, "", &text, made)?;
    made.files.extend(plot::regime_map(base, &cells)?);
    Ok(())
}

/// Which runs of a figure make one point of a curve.
type Pick = Box<dyn Fn(&Point) -> bool>;

/// Figs. 3a–b (against ζ, a curve per χ) and S3 (against γ): the largest hole over the box and
/// the number of holes per run, mean and standard error over runs.
fn holes_figure(m: &Measures, figure: Figure, base: &Path, made: &mut Made) -> Result<(), RunError> {
    let plan = m.plan;
    let s3 = figure == Figure::FigS3;
    let points = plan.points_of(figure);
    // S3 varies γ at one χ and ζ: its one curve is named by them.
    let s3_label = points.first().map(|p| format!("χ = {}, ζ = {}", p.friction.label(), p.zeta)).unwrap_or_default();
    let mut text = String::from(if s3 { "gamma" } else { "chi,zeta" });
    text += ",runs,failed,max_hole_area_over_box_mean,max_hole_area_over_box_sem,holes_mean,holes_sem\n";
    let (xd, t) = if s3 { (format!("γ ({s3_label})"), "Fig. S3") } else { ("ζ".to_string(), "Fig. 3") };
    let mut area = Panel::new(&format!("{t}a: largest hole"), &xd, "max hole area / L²");
    let mut count = Panel::new(&format!("{t}b: number of holes"), &xd, "holes per run");
    area.y_from_zero = true;
    count.y_from_zero = true;
    let groups: Vec<(String, Vec<(f64, Pick)>)> = if s3 {
        vec![(
            s3_label,
            points
                .iter()
                .map(|p| {
                    let g = p.gamma;
                    (g, Box::new(move |p: &Point| same(p.gamma, g)) as Pick)
                })
                .collect(),
        )]
    } else {
        // A curve per χ (the plan's points run through ζ at each χ in turn), a point per ζ.
        let mut groups: Vec<(String, Vec<(f64, Pick)>)> = Vec::new();
        for point in points {
            let Some(chi) = chi_of(point) else { continue };
            let z = point.zeta;
            let label = format!("χ = {chi}");
            let pick = Box::new(move |p: &Point| is_chi(p, chi) && same(p.zeta, z)) as Pick;
            match groups.last_mut() {
                Some((last, xs)) if *last == label => xs.push((z, pick)),
                _ => groups.push((label, vec![(z, pick)])),
            }
        }
        groups
    };
    for (k, (label, xs)) in groups.iter().enumerate() {
        let mut sa = Series::new(label.clone(), k);
        let mut sc = Series::new(label.clone(), k);
        sa.line = true;
        sc.line = true;
        let mut line = Vec::new();
        for (x, pick) in xs {
            let sel = m.select(figure, pick);
            if sel.is_empty() {
                continue;
            }
            let areas: Vec<f64> =
                sel.iter().map(|r| r.holes.iter().map(|h| h.max_area).max().unwrap_or(0) as f64 / r.box_area).collect();
            let counts: Vec<f64> = sel.iter().map(|r| r.holes.len() as f64).collect();
            let (ma, ea) = mean_sem(&areas);
            let (mc, ec) = mean_sem(&counts);
            let failed = sel.iter().filter(|r| r.failed()).count();
            if !s3 {
                text += &format!("{},", label.trim_start_matches("χ = "));
            }
            let _ = writeln!(text, "{x},{},{failed},{},{},{},{}", sel.len(), num(ma), num(ea), num(mc), num(ec));
            sa.push(*x, ma, ea);
            sc.push(*x, mc, ec);
            line.push(format!(
                "{} = {x}: {} ± {} of the box, {} ± {} holes",
                if s3 { "γ" } else { "ζ" },
                fmt(ma),
                fmt(ea),
                fmt(mc),
                fmt(ec)
            ));
        }
        made.measured.push(format!("{label} ({} runs per point): {}", plan_seeds(plan, figure), line.join("; ")));
        area.series.push(sa);
        count.series.push(sc);
    }
    csv(base, "", &text, made)?;
    made.files.extend(plot::panels(base, &[area, count])?);
    Ok(())
}

fn plan_seeds(plan: &Plan, figure: Figure) -> u64 {
    plan.runs_of(figure).map(|(j, _)| j.seed).max().unwrap_or(0)
}

/// Fig. S1: C_v(r) and C_Q(r) after the whole run, averaged over seeds, per χ and the dry limit.
fn fig_s1(m: &Measures, base: &Path, made: &mut Made) -> Result<(), RunError> {
    let plan = m.plan;
    let mut text = String::from("chi,r,velocity_correlation,nematic_correlation\n");
    let mut lengths = String::from("chi,runs,velocity_correlation_length,nematic_correlation_length\n");
    let size =
        plan.runs_of(Figure::FigS1).next().map(|(j, _)| (j.params.box_size, j.params.n_cells)).unwrap_or_default();
    let title = |what: &str| format!("Fig. S1: {what} (ζ = {}, L = {}, N = {})", plan.base.zeta, size.0, size.1);
    let mut cv_panel = Panel::new(&title("velocity"), "r (sites)", "C_v(r)");
    let mut cq_panel = Panel::new(&title("nematic"), "r (sites)", "C_Q(r)");
    cv_panel.hline = Some((-1.0f64).exp());
    cq_panel.hline = Some((-1.0f64).exp());
    for (k, fr) in plan.points_of(Figure::FigS1).iter().map(|p| p.friction).enumerate() {
        let sel = m.select(Figure::FigS1, |p| match (p.friction, fr) {
            (Friction::Chi(a), Friction::Chi(b)) => same(a, b),
            (Friction::Dry, Friction::Dry) => true,
            _ => false,
        });
        let sel: Vec<&RunData> = sel.into_iter().filter(|r| !r.correlations.0.is_empty()).collect();
        if sel.is_empty() {
            continue;
        }
        let bins = sel.iter().map(|r| r.correlations.0.len()).min().unwrap_or(0);
        let n = sel.len() as f64;
        let mean = |f: fn(&RunData) -> &Vec<f64>| -> Vec<f64> {
            (0..bins).map(|r| sel.iter().map(|d| f(d)[r]).sum::<f64>() / n).collect()
        };
        let cv = mean(|d| &d.correlations.0);
        let cq = mean(|d| &d.correlations.1);
        let label = match fr {
            Friction::Chi(c) => format!("χ = {c}"),
            Friction::Dry => "dry (ξ_cell = 0, ξ_s = 1)".into(),
        };
        for r in 0..bins {
            let _ = writeln!(text, "{},{r},{:.6},{:.6}", fr.label(), cv[r], cq[r]);
        }
        let (lv, lq) = (correlation_length(&cv), correlation_length(&cq));
        let o = |v: Option<f64>| v.map(num).unwrap_or_default();
        let _ = writeln!(lengths, "{},{},{},{}", fr.label(), sel.len(), o(lv), o(lq));
        let shown = |v: Option<f64>| v.map(fmt).unwrap_or_else(|| "> L/2".into());
        made.measured.push(format!(
            "{label} ({} runs): correlation lengths (1/e) ℓ_v = {} sites, ℓ_Q = {} sites (R = {})",
            sel.len(),
            shown(lv),
            shown(lq),
            plan.base.radius
        ));
        let mut sv = Series::new(label.clone(), k);
        let mut sq = Series::new(label, k);
        sv.line = true;
        sq.line = true;
        sv.marker = Marker::None;
        sq.marker = Marker::None;
        for r in 0..bins {
            sv.push(r as f64, cv[r], 0.0);
            sq.push(r as f64, cq[r], 0.0);
        }
        cv_panel.series.push(sv);
        cq_panel.series.push(sq);
    }
    csv(base, "", &text, made)?;
    csv(base, "_lengths", &lengths, made)?;
    made.files.extend(plot::panels(base, &[cv_panel, cq_panel])?);
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::RunStatus;

    #[test]
    fn survival_counts_censored_holes_at_risk() {
        // Closed at 1 and 3, one censored at 2: S = 2/3 after 1, then 0 after 3.
        let s = survival(vec![(3.0, true), (1.0, true), (2.0, false)]);
        assert_eq!(s.len(), 2);
        assert!((s[0].3 - 2.0 / 3.0).abs() < 1e-12 && s[1].3 == 0.0, "{s:?}");
    }

    fn run_with_spiral_cores(at_hole: &[(usize, f64)], at_random: &[(usize, f64)]) -> RunData {
        let row = |&(frames_before, d): &(usize, f64)| Precursor {
            hole: 0,
            frames_before,
            spiral_core: Some(d),
            plus_half: [None, None],
            plus_half_angle: None,
            minus_half: None,
            strain_rate: f64::NAN,
        };
        RunData {
            status: RunStatus::Finished,
            frames: 100,
            active_time: 1e4,
            box_area: 1.96e4,
            holes: Vec::new(),
            precursors: at_hole.iter().map(row).collect(),
            chance: at_random.iter().map(row).collect(),
            alignment: (Vec::new(), Vec::new()),
            probability: BTreeMap::new(),
            correlations: (Vec::new(), Vec::new()),
        }
    }

    /// Three runs drawn from P = 0.001·exp(b ε̇) with b = 1,000, 2,000, 3,000: the jackknife
    /// over runs sees their spread, far above the pooled fit's own error, which treats every
    /// site as independent; one run with holes has no jackknife.
    #[test]
    fn the_jackknife_over_runs_sees_the_spread_between_runs() {
        let run_with = |b: f64| {
            let mut r = run_with_spiral_cores(&[], &[]);
            for k in 0..10i64 {
                let x = k as f64 * crate::analysis::STRAIN_RATE_BIN;
                let n = 1_000_000u64;
                r.probability.insert(k, (n, (0.001 * (b * x).exp() * n as f64).round() as u64));
            }
            r
        };
        let (a, b, c) = (run_with(1000.0), run_with(2000.0), run_with(3000.0));
        let runs = [&a, &b, &c];
        let jk = jackknife_coefficient_se(&runs, crate::analysis::binomial_fit).unwrap();
        // Leave-one-out coefficients near 2,500, 2,000, 1,500: √(2/3 · 500,000) ≈ 577.
        assert!(jk > 400.0 && jk < 750.0, "{jk}");
        let mut pooled = BTreeMap::new();
        for r in runs {
            for (&k, &(n, h)) in &r.probability {
                let e: &mut (u64, u64) = pooled.entry(k).or_default();
                e.0 += n;
                e.1 += h;
            }
        }
        let counts: Vec<(f64, u64, u64)> =
            pooled.iter().map(|(&k, &(n, h))| (k as f64 * crate::analysis::STRAIN_RATE_BIN, n, h)).collect();
        let own = crate::analysis::binomial_fit(&counts).unwrap().se_b;
        assert!(jk > 5.0 * own, "{jk} against the fit's own {own}");
        let empty = run_with_spiral_cores(&[], &[]);
        assert_eq!(jackknife_coefficient_se(&[&a, &empty], crate::analysis::binomial_fit), None);
    }

    #[test]
    fn precursor_line_counts_runs_by_their_own_chance_one_frame_before() {
        // Run a: the core is nearer than its chance one frame before (1 against 5); run b: farther
        // (6 against 5), though it is nearer at nucleation; run c has no nucleation.
        let a = run_with_spiral_cores(&[(0, 0.5), (1, 1.0)], &[(0, 5.0), (1, 4.0), (1, 6.0)]);
        let b = run_with_spiral_cores(&[(0, 0.5), (1, 6.0)], &[(0, 5.0), (1, 5.0)]);
        let c = run_with_spiral_cores(&[], &[]);
        let line = precursor_line(&[&a, &b, &c, &a], "d", |p| p.spiral_core, -1.0);
        assert!(line.contains("nearer than chance in 2 of 3 runs"), "{line}");
        let larger = precursor_line(&[&a, &b, &a], "d", |p| p.spiral_core, 1.0);
        assert!(larger.contains("larger than chance in 1 of 3 runs"), "{larger}");
        // Pooled one frame before: (1 + 6) / 2 against (4 + 6 + 5) / 3.
        let pooled = precursor_line(&[&a, &b], "d", |p| p.spiral_core, -1.0);
        assert!(pooled.contains("3.500 ± 2.500 (chance 5.000 ± 0.577) one frame before"), "{pooled}");
    }
}

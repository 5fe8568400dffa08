//! The report, the last stage of `monolayer figures`: `figures.md`, each figure drawn beside what
//! the paper says about it, with the parameters used where the paper states none, and the
//! numbers measured.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use super::draw::{Drawn, Made};
use super::plan::{Figure, Plan, S1_INITIAL_GAP};
use crate::model::Params;
use crate::run::error::RunError;
use crate::run::files::write_text;

/// Writes `out/figures.md` from the figures drawn; returns its path.
pub fn write(drawn: &Drawn, out: &Path) -> Result<PathBuf, RunError> {
    let md = out.join("figures.md");
    write_text(&md, &markdown(drawn))?;
    Ok(md)
}

/// (title, the paper's statement, the parameters used here).
fn about(figure: Figure, plan: &Plan) -> (&'static str, &'static str, String) {
    let zeta = plan.base.zeta;
    let s1_box = plan
        .spec
        .correlation_box
        .map(|(l, n)| format!("L = {l}, N = {n} (the paper's 120² box with the same 100 cells, a denser tissue: the text shrinks the box \"to make sure that no holes are formed\"; initial gap {S1_INITIAL_GAP} sites so the disks fit)"))
        .unwrap_or_else(|| format!("the scale's box, L = {}, N = {}", plan.base.box_size, plan.base.n_cells));
    // The γ of Fig. S3's points, as the plan gives them.
    let gammas: Vec<f64> = plan.points_of(Figure::FigS3).iter().map(|p| p.gamma).collect();
    match figure {
        Figure::Fig1c => (
            "Fig. 1c: distance from the hole to the nearest spiral core before nucleation",
            "“just before the hole forms, both the peak strain in the monolayer and the nearest spiral core localise near the nucleation point (within approximately one cell diameter).” The paper draws simulations without holes (χ = 0.1, 0.05) at zero distance; here a χ without holes has no curve, and its legend says so. At χ = 0.01 few holes form.",
            format!("χ ∈ {{0.1, 0.05, 0.01, 0.005, 0.001}}, ζ = {zeta} (the paper states no ζ: the default). Mean ± standard error over every hole of every run at that χ; x is minus the number of frames before the hole's first frame. The faint line beside each curve is chance: the same measure about 16 random sites (seeded ChaCha8) of each of the same frames."),
        ),
        Figure::Fig1d => (
            "Fig. 1d: the largest strain rate near the nucleation site before nucleation",
            "“Normalised maximum strain rate in an area of radius R/2 around the location of hole nucleation … The normalization is per time-frame”; the peak strain localises at the nucleation point just before the hole forms.",
            format!("As Fig. 1c: χ ∈ {{0.1, 0.05, 0.01, 0.005, 0.001}}, ζ = {zeta}; max ε̇ within R/2 of the hole's nucleation centroid over the frame's max ε̇. The faint line beside each curve is chance: the same measure about 16 random sites (seeded ChaCha8) of each of the same frames."),
        ),
        Figure::Fig2 => (
            "Fig. 2: P(hole | ε̇) with exponential fits; inset: the coefficients against χ^0.1/ζ",
            "“P(hole|ε̇), for different activities and substrate frictions, is well fitted by an exponential … the coefficient of the exponential decreases with activity and increases with substrate friction … plotted against χ^0.1/ζ, collapsing the points onto the same curve.” Empty symbols χ = 0.01, faint χ = 0.005, full χ = 0.001.",
            "χ ∈ {0.01, 0.005, 0.001} × ζ ∈ {0.3, 0.4, 0.5} (Fig. 2 names no ζ values: Fig. 3c's), bins of Δε̇ = 0.000125 pooled over the runs; once a hole has grown above half a cell (πR²/2), no frame is counted until it (its family) has closed. Two fits of P = A·exp(b ε̇), each with its standard error: binomial maximum likelihood over every bin (N_hole,ε̇ of N_ε̇ sites opened with probability P; bins without holes count; errors from the observed information), drawn as the lines and plotted in the inset as b ± se; and least squares on ln P over the bins with holes, weighted by N_hole (≈ 1/var ln P̂), in the table beside it.".into(),
        ),
        Figure::Fig3ab => (
            "Fig. 3a–b: largest hole area and number of holes against ζ",
            "“As either the activity increases or substrate friction decreases, the maximum area of holes increases … the total number of holes integrated over the whole simulation varies non-monotonically with activity and substrate friction.”",
            "χ ∈ {0.1, 0.01, 0.001} × ζ ∈ {0.3, 0.4, 0.5}; the largest hole of each run over the box area L² (the paper's normalisation is not stated), and its number of holes; mean ± standard error over runs.".into(),
        ),
        Figure::Fig3c => (
            "Fig. 3c: hole survival with exponential fits",
            "“The survival probabilities … are well fitted by an exponential distribution … above a given value of activity, there are holes that are able to last the entire duration of the simulation.” Empty symbols χ = 0.005, full χ = 0.001.",
            "χ ∈ {0.005, 0.001} × ζ ∈ {0.3, 0.4, 0.5}; Kaplan–Meier survival of τ_hole/t_total (holes open at the end censored), t_total the time from the first to the last frame; the line is exp(−τ/τ_h) with τ_h the maximum-likelihood lifetime (Σ durations / holes closed), the same fit as the regime criterion.".into(),
        ),
        Figure::Fig3d => (
            "Fig. 3d: the regime map",
            "“If this time-scale is larger than a given threshold, τ_t > 0.5 t_total … the probability of forming persistent holes is non-negligible.” Red circles: no holes; blue squares: only short-lived; green triangles: short- and long-lived.",
            "χ ∈ {0.1, 0.05, 0.01, 0.005, 0.001} × ζ ∈ {0.3, 0.4, 0.5}, seeds pooled; a cross marks a point where a run failed (went unstable).".into(),
        ),
        Figure::FigS1 => (
            "Fig. S1: velocity and nematic correlations, with the dry limit",
            "“in the dry model correlations in the velocity and nematic director decay quickly, with a correlation length of the order of the single cell (r < 8). As we approach the wet model regime, these correlations increase as the substrate friction ξ_s is decreased.” Dry: ξ_cell = 0, ξ_s = 1; a 120² box, 3 samples, after 100,000 steps.",
            format!("χ ∈ {{0.1, 0.01, 0.001}} and the dry limit, ζ = {zeta} (not stated: the default), {s1_box}; C(r) of each run's last frame, unsmoothed, averaged over the runs; the length is the first crossing of 1/e."),
        ),
        Figure::FigS2 => (
            "Fig. S2: distances to the two nearest +½ defects before nucleation",
            "“While the hole does not always nucleate precisely between the defects, it remains consistently closer to two defects, with both defects typically located within approximately two cell diameters.” The paper draws simulations without holes (χ = 0.1, 0.05) at zero distance; here a χ without holes has no curve, and its legend says so.",
            format!("As Fig. 1c: χ ∈ {{0.1, 0.05, 0.01, 0.005, 0.001}}, ζ = {zeta}; distances over R. The faint line beside each curve is chance: the same measure about 16 random sites (seeded ChaCha8) of each of the same frames."),
        ),
        Figure::Mechanism => (
            "The mechanism: antiparallel +½ pairs, −½ defects, cells tangential to a hole",
            "“two +1/2 topological defects in the nematic field moving in the vicinity of each other in an antiparallel relative orientation”; “aligning cells tangentially along the tissue–hole interface”; “we do not see hole formation at −1/2 defects in the simulations.” (The paper shows no figure of these.)",
            format!("As Fig. 1c: χ ∈ {{0.1, 0.05, 0.01, 0.005, 0.001}}, ζ = {zeta}. Panel 1: the angle between the orientations (head to tail) of the two +½ defects nearest the nucleation centroid (180° antiparallel, 90° on average for independent orientations); its chance line is the same for the two +½ nearest each of 16 random sites of the same frames. Panel 2: the distance to the nearest −½ defect, over R, with chance (compare Fig. S2's nearest +½). Panel 3: for every cell whose centroid lies within 1.5 R of an open hole's boundary, the angle between its elongation axis (shape tensor) and the tangent of the nearest boundary site, against cells farther than 3 R from every hole, in every frame with a hole open."),
        ),
        Figure::FigS3 => (
            "Fig. S3: largest hole area and number of holes against γ",
            "“as γ increases, both the average number and the average maximum area of holes decrease.” χ = 0.001, ζ = 0.3.",
            format!("γ ∈ {gammas:?} (the paper gives no values; its text increases γ: the default 0.06 and above), χ = 0.001, ζ = 0.3; normalised as Fig. 3a."),
        ),
    }
}

/// A parameter's value as `monolayer params` writes it.
fn name(v: &impl serde::Serialize) -> String {
    serde_json::to_string(v).unwrap_or_default().trim_matches('"').to_string()
}

fn markdown(drawn: &Drawn) -> String {
    let plan = drawn.measures.plan;
    let b = &plan.base;
    let failed: Vec<&str> =
        plan.jobs.iter().zip(&drawn.measures.runs).filter(|(_, r)| r.failed()).map(|(j, _)| j.name.as_str()).collect();
    let mut s = String::new();
    let _ = writeln!(s, "# The paper's figures, reproduced (scale `{}`)\n", plan.scale.name());
    let _ = writeln!(
        s,
        "Pinto, Rozman & Yeomans, *Spontaneous hole formation in cell monolayers emerges from collective cell motion*, \
         drawn by `monolayer figures` from {} runs in `runs/` (one per point and seed; a run serves every figure \
         that needs it: `plan.csv`). Each figure is a PNG and an SVG beside the CSV of what it draws.\n",
        plan.jobs.len()
    );
    let spec = &plan.spec;
    let _ = writeln!(
        s,
        "- Scale `{}`: L = {}, N = {}, R = {}, {} relaxation and {} active steps, a frame every {} steps; \
         {} seed(s) per point for Figs. 1c–d, 3a–b, 3d, S2, S3 (the paper: 10), {} for Figs. 2 and 3c (100), {} for S1 (3).",
        plan.scale.name(),
        b.box_size,
        b.n_cells,
        b.radius,
        b.relax_steps,
        b.active_steps,
        plan.frame_interval,
        spec.few,
        spec.many,
        spec.correlations
    );
    let _ = writeln!(
        s,
        "- Parameters not varied are the defaults of `monolayer params` (γ = {}, ξ_cell = {}, friction weights `{}`, \
         passive force `{}`){}. ζ is each figure's own, given with it below; where the paper states none (Figs. 1c–d, \
         S1, S2, `mechanism`) it is ζ = {} (`figures::UNSTATED_ZETA`; the default of `run` is {}).",
        b.gamma,
        b.xi_cell,
        name(&b.friction_weights),
        name(&b.passive_force),
        if plan.sets.is_empty() { String::new() } else { format!(", with --set {}", plan.sets.join(" --set ")) },
        b.zeta,
        Params::default().zeta
    );
    if !plan.selected.is_empty() {
        let _ = writeln!(
            s,
            "- Only part of each figure's points: those `--point {}` matches; the figures draw nothing of the rest.",
            plan.selected.join("` or `--point ")
        );
    }
    if failed.is_empty() {
        let _ = writeln!(s, "- Every run finished.\n");
    } else {
        let _ = writeln!(
            s,
            "- {} run(s) went unstable and stopped early; their frames up to then are counted: {}.\n",
            failed.len(),
            failed.join(", ")
        );
    }
    for m in &drawn.figures {
        figure_section(&mut s, m, plan);
    }
    s
}

/// One figure's section: its picture, its files, what the paper says, how it was measured here
/// (and at which points, if `--point` chose some), and the numbers.
fn figure_section(s: &mut String, m: &Made, plan: &Plan) {
    let (title, paper, here) = about(m.figure, plan);
    let stem = m.figure.stem();
    let _ = writeln!(s, "## {title}\n");
    let _ = writeln!(s, "![{title}]({stem}.png)\n");
    let files: Vec<String> = m
        .files
        .iter()
        .filter_map(|p| p.file_name().map(|n| n.to_string_lossy().into_owned()))
        .filter(|n| n.ends_with(".csv"))
        .map(|n| format!("[{n}]({n})"))
        .collect();
    // The SVG is written beside the PNG, but not linked: a copy of the report may keep only
    // the PNGs (docs/evidence/ does), and a link must not lead nowhere.
    let _ = writeln!(s, "Files: {}, and `{stem}.svg` beside the PNG.\n", files.join(", "));
    let _ = writeln!(s, "**The paper:** {paper}\n");
    let _ = writeln!(s, "**Here:** {here} {}.\n", m.runs);
    if !plan.selected.is_empty() {
        let points: Vec<String> = plan
            .points_of(m.figure)
            .iter()
            .map(|p| format!("(χ = {}, ζ = {}, γ = {})", p.friction.label(), p.zeta, p.gamma))
            .collect();
        let _ = writeln!(s, "**Drawn at the selected points only** (`--point`): {}.\n", points.join(", "));
    }
    let _ = writeln!(s, "**Measured:**\n");
    for line in &m.measured {
        let _ = writeln!(s, "- {line}");
    }
    s.push('\n');
}

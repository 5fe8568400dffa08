//! The plan, the first stage of `monolayer figures`: the runs every figure needs and their union.
//!
//! Every figure names the parameter points it needs and how many seeds (the paper's counts at the
//! `paper` scale); the plan is their union, so a run at χ = 0.001, ζ = 0.3, seed 1 made for Fig. 3d
//! also serves Figs. 1c, 2, 3c and S3. Each figure's points are kept in the order it draws them,
//! so the later stages read them here instead of deriving them again. Every run's parameters are
//! validated here, before anything runs; nothing here touches a file.

use std::collections::BTreeSet;

use crate::model::Params;
use crate::run::config::{load_params_over, number, parse_assignments};
use crate::run::error::RunError;
use crate::run::sweep::Job;

/// How many runs, how long, how large.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, clap::ValueEnum)]
pub enum Scale {
    /// Proves the pipeline, not the physics: tiny boxes, few steps, one seed.
    Smoke,
    /// Full size, a few seeds and half the paper's active steps.
    Standard,
    /// The paper's protocol (10,000 relaxation and 100,000 active steps, a frame every 1,000)
    /// with the fewest seeds a verdict needs: 4 per point for Figs. 2 and 3c, 3 elsewhere
    /// (the χ = 0.01 points at ζ = 0.4 and 0.5 included).
    Evidence,
    /// The paper's counts: 10 simulations of 100 frames per point (100 for Figs. 2 and 3c): a
    /// cluster's work.
    Paper,
}

impl Scale {
    pub const ALL: [Scale; 4] = [Scale::Smoke, Scale::Standard, Scale::Evidence, Scale::Paper];

    pub fn name(self) -> &'static str {
        match self {
            Scale::Smoke => "smoke",
            Scale::Standard => "standard",
            Scale::Evidence => "evidence",
            Scale::Paper => "paper",
        }
    }

    /// What the scale sets: parameter overrides (before the user's `--set`) and seed counts.
    pub fn spec(self) -> ScaleSpec {
        match self {
            // 10 cells of R = 8 on 48² is the paper's density (N πR² ≈ L²). So small a box cannot
            // hold a stretched cell for long (it comes to span the box after ~1,000 active steps
            // at ζ = 0.5), and 200 relaxation steps leave gaps that close under activity: holes
            // enough to exercise every figure's code, not physics. 50-step frames give the
            // precursor figures 10 frames of history.
            Scale::Smoke => ScaleSpec {
                overrides: &["box_size=48", "n_cells=10", "relax_steps=200", "active_steps=1000"],
                frame_interval: 50,
                few: 1,
                many: 2,
                correlations: 1,
                correlation_box: None,
            },
            Scale::Standard => ScaleSpec {
                overrides: &["relax_steps=10000", "active_steps=50000"],
                frame_interval: 1000,
                few: 2,
                many: 4,
                correlations: 2,
                correlation_box: Some(S1_BOX),
            },
            Scale::Evidence => ScaleSpec {
                overrides: &["relax_steps=10000", "active_steps=100000"],
                frame_interval: 1000,
                few: 3,
                many: 4,
                correlations: 3,
                correlation_box: Some(S1_BOX),
            },
            Scale::Paper => ScaleSpec {
                overrides: &["relax_steps=10000", "active_steps=100000"],
                frame_interval: 1000,
                few: 10,
                many: 100,
                correlations: 3,
                correlation_box: Some(S1_BOX),
            },
        }
    }
}

/// Fig. S1's box: "we reduce the system size to 120 × 120 lattice sites to make sure that no holes
/// are formed", with the same 100 cells (a denser tissue, 1.4 cells' areas per box area). The
/// paper's density, 73 cells, would not stop holes; only crowding the same cells does.
pub const S1_BOX: (usize, usize) = (120, 100);
/// The initial gap between S1's disks: 100 disks of radius R/2 with the default gap of 2 sites
/// would need 55 % of 120² to be placed apart (the placement asks for at most 50 %); a gap of
/// 1 needs 44 % (gaps of 0–3 sites relax every seed tested, `model::init::random_disks`).
pub const S1_INITIAL_GAP: f64 = 1.0;

/// The settings of a scale.
#[derive(Clone, Debug)]
pub struct ScaleSpec {
    pub overrides: &'static [&'static str],
    pub frame_interval: u64,
    /// Seeds for Figs. 1c–d, 3a–b, 3d, S2, S3 (the paper: 10).
    pub few: u64,
    /// Seeds for Figs. 2 and 3c (the paper: 100).
    pub many: u64,
    /// Seeds for Fig. S1 (the paper: 3).
    pub correlations: u64,
    /// (L, N) of Fig. S1's runs (the paper: a 120² box); None: the scale's box.
    pub correlation_box: Option<(usize, usize)>,
}

/// A figure of the paper.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash)]
pub enum Figure {
    Fig1c,
    Fig1d,
    Fig2,
    Fig3ab,
    Fig3c,
    Fig3d,
    FigS1,
    FigS2,
    FigS3,
    /// The mechanism's claims no figure of the paper measures: antiparallel +½
    /// pairs, no holes at −½ defects, cells tangential to a hole's edge.
    Mechanism,
}

impl Figure {
    pub const ALL: [Figure; 10] = [
        Figure::Fig1c,
        Figure::Fig1d,
        Figure::Fig2,
        Figure::Fig3ab,
        Figure::Fig3c,
        Figure::Fig3d,
        Figure::FigS1,
        Figure::FigS2,
        Figure::FigS3,
        Figure::Mechanism,
    ];

    /// Its name on the command line and the stem of its files (`fig1c.png`, `fig1c.csv`).
    pub fn id(self) -> &'static str {
        match self {
            Figure::Fig1c => "1c",
            Figure::Fig1d => "1d",
            Figure::Fig2 => "2",
            Figure::Fig3ab => "3ab",
            Figure::Fig3c => "3c",
            Figure::Fig3d => "3d",
            Figure::FigS1 => "S1",
            Figure::FigS2 => "S2",
            Figure::FigS3 => "S3",
            Figure::Mechanism => "mechanism",
        }
    }

    pub fn stem(self) -> String {
        format!("fig{}", self.id())
    }

    /// `--only 1c,3d,S1` (3a and 3b are one figure of two panels).
    pub fn parse_list(s: &str) -> Result<Vec<Figure>, RunError> {
        let mut out = BTreeSet::new();
        for part in s.split(',').map(str::trim).filter(|p| !p.is_empty()) {
            let p = part.trim_start_matches("fig").trim_start_matches("Fig");
            let f = match p.to_ascii_lowercase().as_str() {
                "3a" | "3b" | "3a-b" => Some(Figure::Fig3ab),
                q => Figure::ALL.into_iter().find(|f| f.id().to_ascii_lowercase() == q),
            };
            out.insert(f.ok_or_else(|| {
                RunError::Parse(format!("--only {part}: not a figure; the figures are 1c, 1d, 2, 3a, 3b (drawn together as 3ab), 3c, 3d, S1, S2, S3, mechanism"))
            })?);
        }
        if out.is_empty() {
            return Err(RunError::Parse(
                "--only: name at least one figure (1c, 1d, 2, 3ab, 3c, 3d, S1, S2, S3, mechanism)".into(),
            ));
        }
        Ok(out.into_iter().collect())
    }
}

/// The friction of a run: a ratio χ = ξ_s/ξ_cell, or the dry limit ξ_cell = 0, ξ_s = 1 (Fig. S1).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Friction {
    Chi(f64),
    Dry,
}

impl Friction {
    pub fn label(self) -> String {
        match self {
            Friction::Chi(c) => format!("{c}"),
            Friction::Dry => "dry".into(),
        }
    }
}

/// ζ of the figures whose ζ the paper does not state (Figs. 1c–d, S1, S2), unless the user's
/// `--set zeta=…` says otherwise: the lowest of the paper's three, as the figures had it while
/// it was the parameters' default (now ζ = 0.5, where `run` opens holes soonest).
pub const UNSTATED_ZETA: f64 = 0.3;

/// Two values of a point's parameter are the same (written the same in decimal, read back within
/// rounding).
pub(super) fn same(a: f64, b: f64) -> bool {
    (a - b).abs() <= 1e-12 * a.abs().max(b.abs())
}

/// A parameter point of the plan; the rest of the parameters are the scale's base.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Point {
    pub friction: Friction,
    pub zeta: f64,
    pub gamma: f64,
    /// (L, N), or None for the base's.
    pub size: Option<(usize, usize)>,
}

/// The χ and ζ the paper's figures name (captions of Figs. 1–3, S1–S3).
pub const CHI_REGIMES: [f64; 5] = [0.1, 0.05, 0.01, 0.005, 0.001];
pub const CHI_FIG2: [f64; 3] = [0.01, 0.005, 0.001];
pub const CHI_FIG3AB: [f64; 3] = [0.1, 0.01, 0.001];
pub const CHI_FIG3C: [f64; 2] = [0.005, 0.001];
pub const CHI_S1: [f64; 3] = [0.1, 0.01, 0.001];
pub const ZETAS: [f64; 3] = [0.3, 0.4, 0.5];
/// Fig. S3 varies γ at χ = 0.001, ζ = 0.3 without giving the values. The text "increase\[s\] the
/// elasticity of the monolayer through the surface tension": the default 0.06 and above. (Below
/// it, at γ = 0.04, the paper's half-size initial disks overshoot the φ guard `phi_max` = 1.5 in
/// the first relaxation steps; docs/cli.md, "S3's surface tensions".)
pub const GAMMAS_S3: [f64; 4] = [0.06, 0.08, 0.1, 0.12];

/// The plan: every run once, and which figures use it.
#[derive(Clone, Debug)]
pub struct Plan {
    pub scale: Scale,
    /// What the scale sets (its seed counts and S1's box, for the report).
    pub spec: ScaleSpec,
    pub base: Params,
    pub frame_interval: u64,
    pub figures: Vec<Figure>,
    pub jobs: Vec<Job>,
    /// Per job, its point and the figures it serves.
    pub points: Vec<(Point, Vec<Figure>)>,
    /// Per figure of `figures`, its points in the order it draws them (a curve or a bar each).
    pub figure_points: Vec<(Figure, Vec<Point>)>,
    /// The user's `--set` overrides, as given (passed on to Slurm tasks).
    pub sets: Vec<String>,
    /// The user's `--point` selections, as given (passed on to Slurm tasks); empty: every point.
    pub selected: Vec<String>,
}

/// `--point chi=0.01,zeta=0.5`: keeps the plan's points with these values (keys `chi`, which also
/// takes `dry`, `zeta` and `gamma`; a key not given matches every value), so a figure can be
/// drawn from part of its grid.
#[derive(Clone, Debug, PartialEq)]
pub struct PointSelection {
    text: String,
    friction: Option<Friction>,
    zeta: Option<f64>,
    gamma: Option<f64>,
}

impl PointSelection {
    pub fn parse(text: &str) -> Result<PointSelection, RunError> {
        let mut sel = PointSelection { text: text.to_string(), friction: None, zeta: None, gamma: None };
        for (key, value) in parse_assignments("--point", text)? {
            let real = || number(&key, &value).map_err(|e| e.context(format!("--point {text}")));
            match key.as_str() {
                "chi" if value.as_str() == Some("dry") => sel.friction = Some(Friction::Dry),
                "chi" => sel.friction = Some(Friction::Chi(real()?)),
                "zeta" => sel.zeta = Some(real()?),
                "gamma" => sel.gamma = Some(real()?),
                _ => {
                    return Err(RunError::Parse(format!(
                        "--point {text}: `{key}` is not a key of the figures' points (chi, zeta, gamma)"
                    )))
                }
            }
        }
        Ok(sel)
    }

    fn matches(&self, p: &Point) -> bool {
        let friction = match (self.friction, p.friction) {
            (None, _) | (Some(Friction::Dry), Friction::Dry) => true,
            (Some(Friction::Chi(a)), Friction::Chi(b)) => same(a, b),
            _ => false,
        };
        friction && self.zeta.is_none_or(|z| same(z, p.zeta)) && self.gamma.is_none_or(|g| same(g, p.gamma))
    }
}

/// `wanted` with only the points one of `selections` matches (all of them if there are none); a
/// selection that matches none of the figures' points is refused with the points there are.
fn select(
    wanted: Vec<(Point, u64, Figure)>,
    selections: &[PointSelection],
) -> Result<Vec<(Point, u64, Figure)>, RunError> {
    if selections.is_empty() {
        return Ok(wanted);
    }
    if let Some(unmatched) = selections.iter().find(|s| !wanted.iter().any(|(p, _, _)| s.matches(p))) {
        let mut there: Vec<String> = Vec::new();
        for (p, _, _) in &wanted {
            let t = format!("chi={},zeta={},gamma={}", p.friction.label(), p.zeta, p.gamma);
            if !there.contains(&t) {
                there.push(t);
            }
        }
        return Err(RunError::Parse(format!(
            "--point {}: no point of these figures matches; their points are {}",
            unmatched.text,
            there.join(" ")
        )));
    }
    Ok(wanted.into_iter().filter(|(p, _, _)| selections.iter().any(|s| s.matches(p))).collect())
}

/// The points each of `figures` draws (the paper's captions), with how many seeds each takes
/// at this scale, in the order the figures draw them; `zeta0` and `gamma0` are the base's, for
/// the figures whose caption states neither.
fn wanted_points(figures: &[Figure], spec: &ScaleSpec, zeta0: f64, gamma0: f64) -> Vec<(Point, u64, Figure)> {
    let mut wanted: Vec<(Point, u64, Figure)> = Vec::new();
    // Every χ of `chis` at every ζ of `zetas` (γ the base's, the base's size), `seeds` each.
    let grid = |f: Figure, chis: &[f64], zetas: &[f64], seeds: u64| -> Vec<(Point, u64, Figure)> {
        let point = |chi, zeta| Point { friction: Friction::Chi(chi), zeta, gamma: gamma0, size: None };
        chis.iter().flat_map(|&chi| zetas.iter().map(move |&zeta| (point(chi, zeta), seeds, f))).collect()
    };
    for &f in figures {
        let points = match f {
            // The paper does not state ζ for Figs. 1c–d and S2: the base's (UNSTATED_ZETA unless
            // `--set zeta=…`).
            Figure::Fig1c | Figure::Fig1d | Figure::FigS2 | Figure::Mechanism => {
                grid(f, &CHI_REGIMES, &[zeta0], spec.few)
            }
            Figure::Fig2 => grid(f, &CHI_FIG2, &ZETAS, spec.many),
            Figure::Fig3ab => grid(f, &CHI_FIG3AB, &ZETAS, spec.few),
            Figure::Fig3c => grid(f, &CHI_FIG3C, &ZETAS, spec.many),
            Figure::Fig3d => grid(f, &CHI_REGIMES, &ZETAS, spec.few),
            Figure::FigS1 => CHI_S1
                .iter()
                .map(|&chi| Friction::Chi(chi))
                .chain([Friction::Dry])
                .map(|friction| {
                    let point = Point { friction, zeta: zeta0, gamma: gamma0, size: spec.correlation_box };
                    (point, spec.correlations, f)
                })
                .collect(),
            Figure::FigS3 => GAMMAS_S3
                .iter()
                .map(|&gamma| (Point { friction: Friction::Chi(0.001), zeta: 0.3, gamma, size: None }, spec.few, f))
                .collect(),
        };
        wanted.extend(points);
    }
    wanted
}

impl Plan {
    /// The runs `figures` need at `scale`, with `sets` (`KEY=VALUE`) over the scale's base, at
    /// the points one of `selected` (`--point`) matches, or at all of them if it is empty.
    /// Every run's parameters are validated here, before anything runs.
    pub fn new(scale: Scale, figures: &[Figure], sets: &[String], selected: &[String]) -> Result<Plan, RunError> {
        let spec = scale.spec();
        let mut scale_sets: Vec<String> = vec![format!("zeta={UNSTATED_ZETA}")];
        scale_sets.extend(spec.overrides.iter().map(|s| s.to_string()));
        let base = load_params_over(&scale_sets, sets)?;
        base.validate().map_err(|e| RunError::from(e).context("--set"))?;
        let selections = selected.iter().map(|t| PointSelection::parse(t)).collect::<Result<Vec<_>, _>>()?;
        let wanted = select(wanted_points(figures, &spec, base.zeta, base.gamma), &selections)?;
        let mut jobs: Vec<Job> = Vec::new();
        let mut points: Vec<(Point, Vec<Figure>)> = Vec::new();
        let mut figure_points: Vec<(Figure, Vec<Point>)> = figures.iter().map(|&f| (f, Vec::new())).collect();
        for (point, seeds, figure) in wanted {
            if let Some((_, of)) = figure_points.iter_mut().find(|(f, _)| *f == figure) {
                if !of.contains(&point) {
                    of.push(point);
                }
            }
            let params = point_params(&base, &point)?;
            for seed in 1..=seeds {
                let name = run_name(&point, &params, seed);
                // A run two figures share is one job, listed for both.
                match jobs.iter().position(|j| j.name == name) {
                    Some(k) => {
                        if !points[k].1.contains(&figure) {
                            points[k].1.push(figure);
                        }
                    }
                    None => {
                        jobs.push(Job { name, values: point_values(&point, &params), params: params.clone(), seed });
                        points.push((point, vec![figure]));
                    }
                }
            }
        }
        Ok(Plan {
            scale,
            frame_interval: spec.frame_interval,
            spec,
            base,
            figures: figures.to_vec(),
            jobs,
            points,
            figure_points,
            sets: sets.to_vec(),
            selected: selected.to_vec(),
        })
    }

    /// The points of `figure`, in the order it draws them (none for a figure not in the plan).
    pub fn points_of(&self, figure: Figure) -> &[Point] {
        self.figure_points.iter().find(|(f, _)| *f == figure).map_or(&[], |(_, p)| p.as_slice())
    }

    /// The runs that serve `figure`, with their points.
    pub fn runs_of(&self, figure: Figure) -> impl Iterator<Item = (&Job, &Point)> + '_ {
        self.jobs.iter().zip(&self.points).filter(move |(_, (_, f))| f.contains(&figure)).map(|(j, (p, _))| (j, p))
    }

    /// `plan.csv`: one row per run, what it is and which figures use it.
    pub fn table(&self) -> String {
        let mut s = String::from("run,chi,zeta,gamma,box_size,n_cells,seed,relax_steps,active_steps,figures\n");
        for (j, (p, figs)) in self.jobs.iter().zip(&self.points) {
            let f: Vec<&str> = figs.iter().map(|f| f.id()).collect();
            s += &format!(
                "{},{},{},{},{},{},{},{},{},{}\n",
                j.name,
                p.friction.label(),
                p.zeta,
                p.gamma,
                j.params.box_size,
                j.params.n_cells,
                j.seed,
                j.params.relax_steps,
                j.params.active_steps,
                f.join(" ")
            );
        }
        s
    }
}

/// The base with a point's values.
fn point_params(base: &Params, p: &Point) -> Result<Params, RunError> {
    let mut q = base.clone();
    q.zeta = p.zeta;
    q.gamma = p.gamma;
    match p.friction {
        Friction::Chi(c) => q.set_chi(c),
        Friction::Dry => {
            // The paper's dry limit (Fig. S1): ξ_cell = 0 with ξ_s = 1.
            q.xi_cell = 0.0;
            q.xi_substrate = 1.0;
        }
    }
    if let Some((l, n)) = p.size {
        q.box_size = l;
        q.n_cells = n;
        // S1's crowded box: the disks must fit apart (a smaller gap given by --set stays).
        q.initial_gap = q.initial_gap.min(S1_INITIAL_GAP);
    }
    q.validate().map_err(|e| {
        RunError::from(e).context(format!("figures, run at χ = {}, ζ = {}", p.friction.label(), p.zeta))
    })?;
    Ok(q)
}

fn point_values(p: &Point, params: &Params) -> Vec<(String, String)> {
    vec![
        ("chi".into(), p.friction.label()),
        ("zeta".into(), format!("{}", p.zeta)),
        ("gamma".into(), format!("{}", p.gamma)),
        ("box_size".into(), format!("{}", params.box_size)),
    ]
}

/// One name per distinct run: the same point and seed in two figures is one directory.
fn run_name(p: &Point, params: &Params, seed: u64) -> String {
    let friction = match p.friction {
        Friction::Chi(c) => format!("chi{c}"),
        Friction::Dry => "dry".into(),
    };
    format!("{friction}_zeta{}_gamma{}_L{}_seed{seed}", p.zeta, p.gamma, params.box_size)
}

//! Does collective motion tell where the tissue tears, beyond where it has already thinned?
//! (docs/figures.md, "Forecast"; thinning and matched chance in docs/figures-precursors.md).
//!
//! A run's frames are kept as [`RunHistory`]: per frame the precursor points and strain rate
//! ([`FramePoints`]), Σφ, and the local thinning on a sub-grid of sites; and every nucleation
//! (its frame and site). From it, with the whole run known (a site's future is part of its
//! baseline):
//!
//! - [`thinning_before`]: the least Σφ within R of each nucleation site and its void share, in
//!   each of the frames before;
//! - [`matched_baseline`]: each precursor measure at the site beside the same measure at sites
//!   of the same frame **with the same local thinning** (least Σφ within R within
//!   ±[`MATCH_TOLERANCE`]) that do not nucleate in the next [`LOOKAHEAD`] frames, and at uniform
//!   random sites (the older chance line, which a thinning site beats by construction);
//! - [`forecast_samples`]: every covered-or-thinning site of the sub-grid in every frame, with
//!   three features (the strain rate, the distance to the nearest spiral core, the least Σφ
//!   within R) and whether a hole nucleates within R of it in the next 1, 3 and 5 frames;
//! - the scores: [`Predictor`], a [`Logistic`] combination, [`roc_auc`], [`caught_in_top`].
//!
//! Pure and allocation-bounded: the page scores its live frame with the same code
//! ([`score_field`]).

use rand_chacha::rand_core::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;

use super::holes::{periodic_distance, HoleTracker, COVERED_THRESHOLD, VOID_THRESHOLD};
use super::precursors::{FramePoints, Precursor};
use super::thinning::{
    covered_about, disc_offsets, least_on_sites, least_within, void_share_within, COVERED_CORE_FRACTION,
};
use super::Analysis;

/// Forecast horizons, in frames: does a hole nucleate within R in the next 1, 3 or 5 frames?
pub const HORIZONS: [usize; 3] = [1, 3, 5];
/// A matched site's least Σφ within R is within this of the nucleation site's.
pub const MATCH_TOLERANCE: f64 = 0.1;
/// Frames after its own frame in which a matched site must not nucleate (as many as the
/// precursors look back on).
pub const LOOKAHEAD: usize = super::precursors::DEPTH;
/// Matched sites, and random sites, drawn per nucleation and frame.
pub const BASELINE_SITES: usize = 16;
/// Seed of the baselines' generator.
pub const BASELINE_SEED: u64 = 0x5EED_7A1C_4ED0_0038;
/// The sub-grid of scored sites: every `SITE_STRIDE`-th site along each axis.
pub const SITE_STRIDE: usize = 2;
/// Share of a frame's scored sites that a forecast raises the alarm at.
pub const TOP_SHARE: f64 = 0.01;

/// One frame of a run, as the forecast reads it.
#[derive(Clone, Debug, Default)]
pub struct FrameFeatures {
    pub step: u64,
    pub points: FramePoints,
    /// Σφ per lattice site.
    pub phi_sum: Vec<f64>,
    /// The least Σφ within R, and within R/2, at each site of [`RunHistory::sites`].
    pub least: Vec<f64>,
    pub least_core: Vec<f64>,
}

/// A hole's birth: the frame (index into [`RunHistory::frames`]) and its nucleation centroid.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Nucleation {
    pub hole: usize,
    pub frame: usize,
    pub x: f64,
    pub y: f64,
}

/// A run's frames and nucleations, in order.
#[derive(Clone, Debug)]
pub struct RunHistory {
    pub l: usize,
    pub radius: f64,
    /// Lattice indices of the scored sub-grid.
    pub sites: Vec<usize>,
    pub frames: Vec<FrameFeatures>,
    pub nucleations: Vec<Nucleation>,
    disc: Vec<(i64, i64)>,
    core_disc: Vec<(i64, i64)>,
}

impl RunHistory {
    pub fn new(l: usize, radius: f64) -> Self {
        RunHistory {
            l,
            radius,
            sites: sub_grid(l),
            frames: Vec::new(),
            nucleations: Vec::new(),
            disc: disc_offsets(radius),
            core_disc: disc_offsets(COVERED_CORE_FRACTION * radius),
        }
    }

    /// Takes the frame just measured by `a`, after `tracker` was updated with its voids.
    pub fn push(&mut self, a: &Analysis, tracker: &HoleTracker, step: u64) {
        assert_eq!(a.l, self.l, "a frame of another lattice size");
        let mut f = FrameFeatures { step, ..FrameFeatures::default() };
        f.points.take(a);
        f.phi_sum.clone_from(&a.raw.phi_sum);
        least_on_sites(&f.phi_sum, self.l, &self.sites, &self.disc, &mut f.least);
        least_on_sites(&f.phi_sum, self.l, &self.sites, &self.core_disc, &mut f.least_core);
        let frame = self.frames.len();
        for h in tracker.nucleated_holes() {
            let (_, _, x, y) = tracker.holes[h].history[0];
            self.nucleations.push(Nucleation { hole: tracker.holes[h].id, frame, x, y });
        }
        self.frames.push(f);
    }

    /// Whether a hole nucleates within R of (x, y) in frames `from..=to`.
    fn nucleates_near(&self, x: f64, y: f64, from: usize, to: usize) -> bool {
        self.nucleations
            .iter()
            .any(|n| n.frame >= from && n.frame <= to && periodic_distance(n.x, n.y, x, y, self.l) <= self.radius)
    }

    fn site_xy(&self, s: usize) -> (f64, f64) {
        ((s % self.l) as f64, (s / self.l) as f64)
    }

    /// The farthest any point is from a site on the periodic box, in R: the distance a frame
    /// without a spiral core gives.
    pub fn no_core_distance(&self) -> f64 {
        no_core_distance(self.l, self.radius)
    }
}

/// Every [`SITE_STRIDE`]-th site along each axis.
pub fn sub_grid(l: usize) -> Vec<usize> {
    (0..l).step_by(SITE_STRIDE).flat_map(|y| (0..l).step_by(SITE_STRIDE).map(move |x| y * l + x)).collect()
}

/// The largest periodic distance on the L×L box over R.
pub fn no_core_distance(l: usize, radius: f64) -> f64 {
    (l as f64 / 2.0) * std::f64::consts::SQRT_2 / radius
}

/// The thinning about one nucleation site, `frames_before` frames before it.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ThinningRow {
    pub hole: usize,
    pub frames_before: usize,
    /// Least Σφ within R of the site.
    pub least: f64,
    /// Share of void sites within R.
    pub void_share: f64,
    /// Least Σφ within R/2 at least ½: thinning had not reached the site.
    pub covered: bool,
}

/// For every nucleation and k = 0..=`depth` frames before it (as far as the run reaches back).
pub fn thinning_before(h: &RunHistory, depth: usize) -> Vec<ThinningRow> {
    let (l, r) = (h.l, h.radius);
    let mut rows = Vec::new();
    for n in &h.nucleations {
        for k in 0..=depth.min(n.frame) {
            let p = &h.frames[n.frame - k].phi_sum;
            rows.push(ThinningRow {
                hole: n.hole,
                frames_before: k,
                least: least_within(p, l, n.x, n.y, r),
                void_share: void_share_within(p, l, n.x, n.y, r),
                covered: covered_about(p, l, n.x, n.y, r),
            });
        }
    }
    rows
}

/// The precursor measures at a nucleation site and at its two baselines, one frame before.
#[derive(Clone, Debug)]
pub struct BaselineRow {
    pub thinning: ThinningRow,
    pub site: Precursor,
    /// Sites of the frame with the same local thinning that do not nucleate in the next
    /// [`LOOKAHEAD`] frames: how many there were, and the measures at up to
    /// [`BASELINE_SITES`] of them.
    pub candidates: usize,
    pub matched: Vec<Precursor>,
    /// Uniform random sites of the sub-grid (the older chance line).
    pub random: Vec<Precursor>,
}

/// For every nucleation and k = 0..=`depth` frames before it, the measures at the site and at
/// its matched and random sites (drawn from a ChaCha8 generator seeded with
/// `BASELINE_SEED`, so the same run gives the same sites).
pub fn matched_baseline(h: &RunHistory, depth: usize) -> Vec<BaselineRow> {
    let mut rng = ChaCha8Rng::seed_from_u64(BASELINE_SEED);
    let thinning = thinning_before(h, depth);
    let (l, r) = (h.l, h.radius);
    let mut rows = Vec::with_capacity(thinning.len());
    let mut pool = Vec::new();
    for t in thinning {
        let n = h.nucleations.iter().find(|n| n.hole == t.hole).expect("a nucleation of the run");
        let frame = n.frame - t.frames_before;
        let f = &h.frames[frame];
        let candidates = matched_pool(h, frame, t.least, &|_| true, &mut pool);
        let matched = draw(&mut rng, &mut pool, BASELINE_SITES)
            .iter()
            .map(|&s| {
                let (x, y) = h.site_xy(s);
                f.points.measure(t.hole, t.frames_before, x, y, l, r)
            })
            .collect();
        let random = (0..BASELINE_SITES)
            .map(|_| {
                let s = h.sites[(rng.next_u64() % h.sites.len() as u64) as usize];
                let (x, y) = h.site_xy(s);
                f.points.measure(t.hole, t.frames_before, x, y, l, r)
            })
            .collect();
        rows.push(BaselineRow {
            site: f.points.measure(t.hole, t.frames_before, n.x, n.y, l, r),
            thinning: t,
            candidates,
            matched,
            random,
        });
    }
    rows
}

/// The sites of the sub-grid in frame `frame` that thinned as much as a site whose least Σφ
/// within R is `least` (within ±[`MATCH_TOLERANCE`]) and that do not nucleate within R in the
/// next [`LOOKAHEAD`] frames, and that `keep` keeps (a lattice index), into `pool` (lattice
/// indices); returns how many there are.
fn matched_pool(
    h: &RunHistory,
    frame: usize,
    least: f64,
    keep: &dyn Fn(usize) -> bool,
    pool: &mut Vec<usize>,
) -> usize {
    let f = &h.frames[frame];
    pool.clear();
    for (i, &s) in h.sites.iter().enumerate() {
        if (f.least[i] - least).abs() > MATCH_TOLERANCE || !keep(s) {
            continue;
        }
        let (x, y) = h.site_xy(s);
        if !h.nucleates_near(x, y, frame + 1, frame + LOOKAHEAD) {
            pool.push(s);
        }
    }
    pool.len()
}

/// Up to `count` matched sites (`matched_pool`) of frame `frame` for a site whose least Σφ
/// within R is `least`, among those `keep` keeps (lattice indices), drawn without replacement
/// from `rng`, as (x, y): the matched chance the forecast compares a nucleation site with.
pub fn matched_sites(
    h: &RunHistory,
    frame: usize,
    least: f64,
    keep: &dyn Fn(usize) -> bool,
    rng: &mut ChaCha8Rng,
    count: usize,
) -> Vec<(f64, f64)> {
    let mut pool = Vec::new();
    matched_pool(h, frame, least, keep, &mut pool);
    draw(rng, &mut pool, count).iter().map(|&s| h.site_xy(s)).collect()
}

/// Up to `k` entries of `pool` drawn without replacement (a partial Fisher–Yates shuffle).
fn draw<'a>(rng: &mut ChaCha8Rng, pool: &'a mut [usize], k: usize) -> &'a [usize] {
    let k = k.min(pool.len());
    for i in 0..k {
        let j = i + (rng.next_u64() % (pool.len() - i) as u64) as usize;
        pool.swap(i, j);
    }
    &pool[..k]
}

/// The three inputs of the combination, in the order of [`Logistic`]'s weights.
pub type Features = [f64; 3];

/// The combination reads a spiral core's distance up to this many R: beyond two cell diameters
/// the core is no nearer than at a random site (docs/figures-precursors.md, Fig. 1c).
pub const CORE_DISTANCE_CAP: f64 = 4.0;

/// The combination's inputs from a site's measures: ε̇ over the frame's largest (Fig. 1d's
/// normalisation, comparable across runs and activities), the spiral core's distance capped at
/// [`CORE_DISTANCE_CAP`], and ln(least Σφ within R + the void threshold), so that the approach to
/// a void is not squeezed into the last hundredth of the range. Fixed before the held-out seeds
/// were read (docs/figures-precursors.md).
pub fn model_inputs(strain_rate: f64, frame_max_strain_rate: f64, core: f64, least: f64) -> Features {
    let e = if frame_max_strain_rate > 0.0 { strain_rate / frame_max_strain_rate } else { 0.0 };
    [e, core.min(CORE_DISTANCE_CAP), (least.max(0.0) + VOID_THRESHOLD).ln()]
}

/// One scored site of one frame.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Sample {
    /// Index into [`RunHistory::frames`].
    pub frame: u32,
    /// Lattice index.
    pub site: u32,
    /// ε̇ at the site, and the frame's largest ε̇.
    pub strain_rate: f64,
    pub frame_max_strain_rate: f64,
    /// Distance to the nearest spiral core / R (`no_core_distance` without one).
    pub core: f64,
    /// Least Σφ within R.
    pub least: f64,
    /// Least Σφ within R/2 at least ½.
    pub covered: bool,
    /// A hole nucleates within R in the next [`HORIZONS`] frames.
    pub labels: [bool; 3],
}

impl Sample {
    /// The combination's inputs (`model_inputs`).
    pub fn inputs(&self) -> Features {
        model_inputs(self.strain_rate, self.frame_max_strain_rate, self.core, self.least)
    }
}

/// Every sub-grid site that is not void itself, in every frame whose [`HORIZONS`] all lie
/// within the run.
pub fn forecast_samples(h: &RunHistory) -> Vec<Sample> {
    let longest = HORIZONS[HORIZONS.len() - 1];
    let (l, r) = (h.l, h.radius);
    let mut out = Vec::new();
    for (t, f) in h.frames.iter().enumerate() {
        if t + longest >= h.frames.len() {
            break;
        }
        let max = f.points.strain_rate.iter().copied().fold(f64::NEG_INFINITY, f64::max);
        for (i, &s) in h.sites.iter().enumerate() {
            if f.phi_sum[s] < VOID_THRESHOLD {
                continue;
            }
            let (x, y) = h.site_xy(s);
            let core = f.points.nearest_spiral_core(x, y, l, r).unwrap_or(h.no_core_distance());
            out.push(Sample {
                frame: t as u32,
                site: s as u32,
                strain_rate: f.points.strain_rate[s],
                frame_max_strain_rate: max,
                core,
                least: f.least[i],
                covered: f.least_core[i] >= COVERED_THRESHOLD,
                labels: HORIZONS.map(|k| h.nucleates_near(x, y, t + 1, t + k)),
            });
        }
    }
    out
}

/// The forecasts compared.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub enum Predictor {
    /// (a) The smoothed strain rate ε̇ at the site (Fig. 2's field): higher, likelier.
    StrainRate,
    /// (b) The distance to the nearest spiral core: nearer, likelier.
    SpiralCore,
    /// (c) The least Σφ within R: thinner, likelier.
    Thinning,
    /// (d) A logistic regression on (a)–(c), fitted on other runs.
    Combined,
}

impl Predictor {
    pub const ALL: [Predictor; 4] =
        [Predictor::StrainRate, Predictor::SpiralCore, Predictor::Thinning, Predictor::Combined];

    pub fn name(self) -> &'static str {
        match self {
            Predictor::StrainRate => "strain_rate",
            Predictor::SpiralCore => "spiral_core",
            Predictor::Thinning => "thinning",
            Predictor::Combined => "combined",
        }
    }

    /// The score of a site; higher means a tear is likelier. The single features' signs are
    /// the hypotheses' own, fixed before looking (nothing is fitted); `Combined` needs a model.
    pub fn score(self, s: &Sample, model: Option<&Logistic>) -> f64 {
        match self {
            Predictor::StrainRate => s.strain_rate,
            Predictor::SpiralCore => -s.core,
            Predictor::Thinning => -s.least,
            Predictor::Combined => model.expect("the combined predictor needs a fitted model").linear(&s.inputs()),
        }
    }
}

/// The combination the page draws (its forecast field): fitted by `monolayer forecast` on the 18
/// paper-length runs of docs/figures-precursors.md ("Thinning, matched chance and the forecast"), a
/// nucleation within R in the next 3 frames (3,000 steps), all sites; the numbers are those of
/// docs/evidence/forecast/forecast_model.txt, which a test holds them to.
pub const SHIPPED_MODEL: Logistic = Logistic {
    mean: [-0.00697343980094324, 3.655877436803038, -0.892125735047249],
    scale: [0.31724060383930314, 0.7416987616920563, 0.9040575761687477],
    weights: [-8.999196897781783, 1.1660915618090621, -0.4202569395593224, -0.4976739373979643],
};

/// P(tear | features) = 1 / (1 + exp(−(w₀ + Σ w_k (f_k − m_k)/s_k))), features standardised by
/// the training set's mean m and standard deviation s.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Logistic {
    pub mean: Features,
    pub scale: Features,
    /// Intercept, then one weight per standardised feature.
    pub weights: [f64; 4],
}

/// Ridge on the feature weights, per sample: keeps the fit finite when a feature separates the
/// classes, far below what moves a fit of many sites.
const RIDGE: f64 = 1e-6;

impl Logistic {
    /// The maximum-likelihood fit (Newton's method) to (features, tears); None without both
    /// classes.
    pub fn fit(samples: &[(Features, bool)]) -> Option<Logistic> {
        let n = samples.len() as f64;
        let positives = samples.iter().filter(|s| s.1).count();
        if positives == 0 || positives == samples.len() {
            return None;
        }
        let mut mean = [0.0; 3];
        for (f, _) in samples {
            for k in 0..3 {
                mean[k] += f[k] / n;
            }
        }
        let mut scale = [0.0; 3];
        for (f, _) in samples {
            for k in 0..3 {
                scale[k] += (f[k] - mean[k]).powi(2) / n;
            }
        }
        let scale = scale.map(|v| if v > 0.0 { v.sqrt() } else { 1.0 });
        let mut model =
            Logistic { mean, scale, weights: [(positives as f64 / (n - positives as f64)).ln(), 0.0, 0.0, 0.0] };
        for _ in 0..100 {
            let mut grad = [0.0; 4];
            let mut hess = [[0.0; 4]; 4];
            for (f, y) in samples {
                let z = model.standardised(f);
                let p = sigmoid(model.linear(f));
                let w = p * (1.0 - p);
                let g = f64::from(u8::from(*y)) - p;
                for i in 0..4 {
                    grad[i] += g * z[i];
                    for j in 0..4 {
                        hess[i][j] += w * z[i] * z[j];
                    }
                }
            }
            for i in 1..4 {
                grad[i] -= RIDGE * n * model.weights[i];
                hess[i][i] += RIDGE * n;
            }
            let step = solve4(hess, grad)?;
            // Newton's step, halved until the penalised likelihood does not fall: rare tears
            // and a strongly separating input make the full step overshoot.
            let before = model.penalised_log_likelihood(samples);
            let mut t = 1.0;
            loop {
                let mut trial = model;
                for (w, d) in trial.weights.iter_mut().zip(step) {
                    *w += t * d;
                }
                let after = trial.penalised_log_likelihood(samples);
                if after >= before - 1e-12 * before.abs() {
                    model = trial;
                    break;
                }
                t *= 0.5;
                if t < 1e-12 {
                    return Some(model);
                }
            }
            if step.iter().all(|d| (t * d).abs() < 1e-10) {
                return Some(model);
            }
        }
        Some(model)
    }

    /// Σ log P(observed) − the ridge: what [`Self::fit`] climbs.
    fn penalised_log_likelihood(&self, samples: &[(Features, bool)]) -> f64 {
        let n = samples.len() as f64;
        let ll: f64 = samples
            .iter()
            .map(|(f, y)| {
                let z = self.linear(f);
                // log σ(z) = −log(1 + e^{−z}), log(1 − σ(z)) = −log(1 + e^{z}), stably.
                let softplus = |x: f64| if x > 0.0 { x + (-x).exp().ln_1p() } else { x.exp().ln_1p() };
                if *y {
                    -softplus(-z)
                } else {
                    -softplus(z)
                }
            })
            .sum();
        ll - 0.5 * RIDGE * n * self.weights[1..].iter().map(|w| w * w).sum::<f64>()
    }

    /// (1, standardised features).
    fn standardised(&self, f: &Features) -> [f64; 4] {
        [
            1.0,
            (f[0] - self.mean[0]) / self.scale[0],
            (f[1] - self.mean[1]) / self.scale[1],
            (f[2] - self.mean[2]) / self.scale[2],
        ]
    }

    /// The log-odds of a tear.
    pub fn linear(&self, f: &Features) -> f64 {
        let z = self.standardised(f);
        (0..4).map(|i| self.weights[i] * z[i]).sum()
    }

    pub fn probability(&self, f: &Features) -> f64 {
        sigmoid(self.linear(f))
    }
}

fn sigmoid(x: f64) -> f64 {
    1.0 / (1.0 + (-x).exp())
}

/// Solves a 4×4 linear system by Gaussian elimination with partial pivoting; None if singular.
fn solve4(mut a: [[f64; 4]; 4], mut b: [f64; 4]) -> Option<[f64; 4]> {
    for c in 0..4 {
        let p = (c..4).max_by(|&i, &j| a[i][c].abs().total_cmp(&a[j][c].abs()))?;
        if a[p][c].abs() < 1e-300 {
            return None;
        }
        a.swap(c, p);
        b.swap(c, p);
        let (pivot_row, pivot_b) = (a[c], b[c]);
        for (row, rhs) in a.iter_mut().zip(b.iter_mut()).skip(c + 1) {
            let m = row[c] / pivot_row[c];
            for (x, p) in row.iter_mut().zip(pivot_row).skip(c) {
                *x -= m * p;
            }
            *rhs -= m * pivot_b;
        }
    }
    let mut x = [0.0; 4];
    for c in (0..4).rev() {
        x[c] = (b[c] - (c + 1..4).map(|k| a[c][k] * x[k]).sum::<f64>()) / a[c][c];
    }
    Some(x)
}

/// The area under the ROC curve of (score, tear) pairs: the chance that a tearing site scores
/// above a site that does not, ties counting half (the Mann–Whitney U over the two counts).
/// None without both classes. Sorts `scored`.
pub fn roc_auc(scored: &mut [(f64, bool)]) -> Option<f64> {
    scored.sort_by(|a, b| a.0.total_cmp(&b.0));
    let pos = scored.iter().filter(|s| s.1).count() as f64;
    let neg = scored.len() as f64 - pos;
    if pos == 0.0 || neg == 0.0 {
        return None;
    }
    let mut rank_sum = 0.0;
    let mut i = 0;
    while i < scored.len() {
        let mut j = i;
        while j < scored.len() && scored[j].0 == scored[i].0 {
            j += 1;
        }
        // Ranks i+1..=j share their mean.
        let mean_rank = (i + 1 + j) as f64 / 2.0;
        rank_sum += mean_rank * scored[i..j].iter().filter(|s| s.1).count() as f64;
        i = j;
    }
    Some((rank_sum - pos * (pos + 1.0) / 2.0) / (pos * neg))
}

/// The ROC curve of sorted-by-[`roc_auc`] pairs, as (false-positive rate, true-positive rate)
/// at about `points` thresholds, from (0, 0) to (1, 1).
pub fn roc_curve(sorted: &[(f64, bool)], points: usize) -> Vec<(f64, f64)> {
    let pos = sorted.iter().filter(|s| s.1).count().max(1) as f64;
    let neg = (sorted.len() as f64 - sorted.iter().filter(|s| s.1).count() as f64).max(1.0);
    let every = (sorted.len() / points.max(1)).max(1);
    let (mut tp, mut fp) = (0.0, 0.0);
    let mut out = vec![(0.0, 0.0)];
    for (i, s) in sorted.iter().rev().enumerate() {
        if s.1 {
            tp += 1.0;
        } else {
            fp += 1.0;
        }
        if (i + 1) % every == 0 {
            out.push((fp / neg, tp / pos));
        }
    }
    out.push((1.0, 1.0));
    out
}

/// How many nucleations a forecast catches `horizon` frames ahead: a nucleation is caught when,
/// in the frame `horizon` frames before it, a scored site within R of its site is among the
/// `TOP_SHARE` highest scores of that frame. `samples` are one run's, in frame order, with
/// their `scores`; `keep` selects the subset scored (all sites, or the covered ones), and only
/// nucleations whose own site is in the subset at that frame count. Returns (caught, counted).
pub fn caught_in_top(
    h: &RunHistory,
    samples: &[Sample],
    scores: &[f64],
    horizon: usize,
    keep: impl Fn(&Sample) -> bool,
) -> (usize, usize) {
    let (mut caught, mut counted) = (0, 0);
    let mut start = 0;
    let mut frame_scores = Vec::new();
    while start < samples.len() {
        let t = samples[start].frame;
        let end = start + samples[start..].iter().take_while(|s| s.frame == t).count();
        let idx: Vec<usize> = (start..end).filter(|&i| keep(&samples[i])).collect();
        start = end;
        let t = t as usize;
        let due: Vec<&Nucleation> = h.nucleations.iter().filter(|n| n.frame == t + horizon).collect();
        if due.is_empty() || idx.is_empty() {
            continue;
        }
        frame_scores.clear();
        frame_scores.extend(idx.iter().map(|&i| scores[i]));
        frame_scores.sort_by(|a, b| b.total_cmp(a));
        let top = ((TOP_SHARE * idx.len() as f64).ceil() as usize).max(1);
        let threshold = frame_scores[top - 1];
        for n in due {
            let near: Vec<usize> = idx
                .iter()
                .copied()
                .filter(|&i| {
                    let (x, y) = h.site_xy(samples[i].site as usize);
                    periodic_distance(x, y, n.x, n.y, h.l) <= h.radius
                })
                .collect();
            let own = nearest_sample(h, samples, &idx, n.x, n.y);
            if !own.is_some_and(|i| keep(&samples[i])) || near.is_empty() {
                continue;
            }
            counted += 1;
            if near.iter().any(|&i| scores[i] >= threshold) {
                caught += 1;
            }
        }
    }
    (caught, counted)
}

/// The sample (of `idx`) nearest (x, y), if one is within a sub-grid spacing.
fn nearest_sample(h: &RunHistory, samples: &[Sample], idx: &[usize], x: f64, y: f64) -> Option<usize> {
    idx.iter()
        .copied()
        .map(|i| {
            let (sx, sy) = h.site_xy(samples[i].site as usize);
            (i, periodic_distance(sx, sy, x, y, h.l))
        })
        .filter(|p| p.1 <= SITE_STRIDE as f64)
        .min_by(|a, b| a.1.total_cmp(&b.1))
        .map(|p| p.0)
}

/// The forecast over the lattice for the frame just measured by `a`: the probability that a
/// hole nucleates within R of each site in the model's horizon, at every site (sites are
/// scored on the sub-grid and each takes its sub-grid cell's value); void sites get 0, as they
/// have already torn. `out` is L×L.
pub fn score_field(a: &Analysis, model: &Logistic, out: &mut Vec<f64>) {
    let (l, r) = (a.l, a.radius);
    let phi = &a.raw.phi_sum;
    let cores: Vec<(f64, f64)> = a.spiral_cores().map(|p| (p.x, p.y)).collect();
    let disc = disc_offsets(r);
    let sites = sub_grid(l);
    let mut least = Vec::new();
    least_on_sites(phi, l, &sites, &disc, &mut least);
    out.clear();
    out.resize(l * l, 0.0);
    let far = no_core_distance(l, r);
    let max = a.strain_rate.iter().copied().fold(f64::NEG_INFINITY, f64::max);
    let per_row = l.div_ceil(SITE_STRIDE);
    for (i, &s) in sites.iter().enumerate() {
        let (x, y) = ((s % l) as f64, (s / l) as f64);
        let core = cores.iter().map(|&(cx, cy)| periodic_distance(cx, cy, x, y, l) / r).fold(far, f64::min);
        let p = model.probability(&model_inputs(a.strain_rate[s], max, core, least[i]));
        let (gx, gy) = (i % per_row, i / per_row);
        for y in gy * SITE_STRIDE..((gy + 1) * SITE_STRIDE).min(l) {
            for x in gx * SITE_STRIDE..((gx + 1) * SITE_STRIDE).min(l) {
                out[y * l + x] = if phi[y * l + x] < VOID_THRESHOLD { 0.0 } else { p };
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The page's model is the one `monolayer forecast` wrote for the record, to the bit.
    #[test]
    fn the_shipped_model_is_the_recorded_fit() {
        let text = include_str!("../../docs/evidence/forecast/forecast_model.txt");
        let read = |key: &str| -> Vec<f64> {
            let line = text.lines().find(|l| l.starts_with(key)).unwrap_or_else(|| panic!("{key} missing"));
            let list = line.split_once('[').unwrap().1.trim_end_matches(']');
            list.split(',').map(|v| v.trim().parse().unwrap()).collect()
        };
        assert_eq!(read("mean"), SHIPPED_MODEL.mean);
        assert_eq!(read("scale"), SHIPPED_MODEL.scale);
        assert_eq!(read("weights"), SHIPPED_MODEL.weights);
        assert!(text.contains("horizon 3 frames"));
    }

    #[test]
    fn the_auc_is_the_chance_a_tearing_site_outscores_one_that_does_not() {
        // Perfect, reversed, all tied.
        assert_eq!(roc_auc(&mut [(0.1, false), (0.2, false), (0.9, true)]), Some(1.0));
        assert_eq!(roc_auc(&mut [(0.1, true), (0.2, false), (0.9, false)]), Some(0.0));
        assert_eq!(roc_auc(&mut [(0.5, true), (0.5, false), (0.5, false)]), Some(0.5));
        // 2 tearing, 3 not: 0.3 beats 0.1 and 0.2, loses to 0.4 (2 of 3); 0.4 beats 0.1 and
        // 0.2 and ties 0.4 (2.5 of 3).
        let auc = roc_auc(&mut [(0.1, false), (0.2, false), (0.3, true), (0.4, true), (0.4, false)]).unwrap();
        assert!((auc - (2.0 + 2.5) / 6.0).abs() < 1e-12, "{auc}");
        assert_eq!(roc_auc(&mut [(0.1, true)]), None);
    }

    #[test]
    fn the_roc_curve_runs_from_corner_to_corner_above_the_diagonal_for_a_good_score() {
        let mut s: Vec<(f64, bool)> = (0..1000).map(|i| (i as f64, i % 10 == 0 && i > 500)).collect();
        roc_auc(&mut s);
        let c = roc_curve(&s, 50);
        assert_eq!((c[0], *c.last().unwrap()), ((0.0, 0.0), (1.0, 1.0)));
        assert!(c.windows(2).all(|w| w[1].0 >= w[0].0 && w[1].1 >= w[0].1));
        assert!(c.iter().all(|p| p.1 >= p.0 - 1e-12));
    }

    #[test]
    fn the_logistic_fit_recovers_known_weights_and_ignores_a_useless_feature() {
        // Tears drawn with log-odds −3 + 2 x₀ − x₂ at uniform features; x₁ carries nothing.
        let mut samples = Vec::new();
        let mut rng = ChaCha8Rng::seed_from_u64(7);
        for _ in 0..40_000 {
            let u = |rng: &mut ChaCha8Rng| (rng.next_u64() >> 11) as f64 / (1u64 << 53) as f64;
            let f = [u(&mut rng) * 4.0 - 2.0, u(&mut rng) * 4.0 - 2.0, u(&mut rng) * 4.0 - 2.0];
            let p = sigmoid(-3.0 + 2.0 * f[0] - f[2]);
            samples.push((f, u(&mut rng) < p));
        }
        let m = Logistic::fit(&samples).unwrap();
        // Back to raw units: w_k / s_k.
        let raw: Vec<f64> = (0..3).map(|k| m.weights[k + 1] / m.scale[k]).collect();
        assert!((raw[0] - 2.0).abs() < 0.15 && raw[1].abs() < 0.1 && (raw[2] + 1.0).abs() < 0.1, "{raw:?}");
        let intercept = m.weights[0] - (0..3).map(|k| m.weights[k + 1] * m.mean[k] / m.scale[k]).sum::<f64>();
        assert!((intercept + 3.0).abs() < 0.15, "{intercept}");
        assert!(Logistic::fit(&[([0.0; 3], false), ([1.0; 3], false)]).is_none());
    }

    /// A synthetic run on a 32×32 box: a tissue (Σφ = 1) that thins at (8, 8) from frame 3
    /// and nucleates there at frame 6; a spiral core sits at (24, 24) throughout.
    fn history() -> RunHistory {
        let l = 32;
        let mut h = RunHistory::new(l, 4.0);
        for t in 0..10usize {
            let mut f = FrameFeatures { step: t as u64 * 1000, ..FrameFeatures::default() };
            f.phi_sum = vec![1.0; l * l];
            if t >= 3 {
                for y in 6..=10 {
                    for x in 6..=10 {
                        f.phi_sum[y * l + x] = if t >= 6 { 0.0 } else { 0.3 };
                    }
                }
            }
            f.points.strain_rate = vec![0.0; l * l];
            f.points.strain_rate[8 * l + 8] = 0.01 * t as f64;
            f.points.spiral_cores = vec![(24.0, 24.0)];
            least_on_sites(&f.phi_sum, l, &h.sites, &h.disc, &mut f.least);
            least_on_sites(&f.phi_sum, l, &h.sites, &h.core_disc, &mut f.least_core);
            h.frames.push(f);
        }
        h.nucleations.push(Nucleation { hole: 0, frame: 6, x: 8.0, y: 8.0 });
        h
    }

    #[test]
    fn thinning_is_read_in_each_frame_before_the_nucleation() {
        let rows = thinning_before(&history(), 10);
        assert_eq!(rows.len(), 7, "frames 6 back to 0");
        let by_k = |k: usize| rows.iter().find(|r| r.frames_before == k).unwrap();
        assert_eq!((by_k(0).least, by_k(0).void_share > 0.5, by_k(0).covered), (0.0, true, false));
        assert_eq!((by_k(1).least, by_k(1).void_share, by_k(1).covered), (0.3, 0.0, false));
        assert_eq!((by_k(4).least, by_k(4).covered), (1.0, true));
    }

    #[test]
    fn matched_sites_share_the_thinning_and_never_nucleate_soon() {
        let h = history();
        let rows = matched_baseline(&h, 10);
        let one_before = rows.iter().find(|r| r.thinning.frames_before == 1).unwrap();
        // One frame before (frame 5), the site's least Σφ within R is 0.3: matched sites lie
        // within R of the thin patch but not within R of the nucleation site.
        assert!(one_before.candidates > 0 && !one_before.matched.is_empty());
        for m in &one_before.matched {
            assert_eq!(m.frames_before, 1);
        }
        assert!(one_before.candidates < h.sites.len() / 4, "only sites near the thin patch match");
        // Four frames before (frame 2) the tissue is whole everywhere: every site matches but
        // those near the coming nucleation.
        let four = rows.iter().find(|r| r.thinning.frames_before == 4).unwrap();
        let near = h.sites.iter().filter(|&&s| {
            let (x, y) = h.site_xy(s);
            periodic_distance(x, y, 8.0, 8.0, h.l) <= h.radius
        });
        assert_eq!(four.candidates, h.sites.len() - near.count());
        assert_eq!((four.matched.len(), four.random.len()), (BASELINE_SITES, BASELINE_SITES));
        // The same run, the same sites.
        let again = matched_baseline(&h, 10);
        assert_eq!(again[3].matched, rows[3].matched);
    }

    #[test]
    fn samples_label_the_sites_that_tear_within_each_horizon() {
        let h = history();
        let s = forecast_samples(&h);
        // Frames 0..=4 have all horizons inside the run (10 frames, longest horizon 5).
        assert_eq!(s.iter().map(|x| x.frame).max(), Some(4));
        let at = |t: u32, site: usize| s.iter().find(|x| x.frame == t && x.site as usize == site).unwrap();
        let centre = 8 * h.l + 8;
        assert_eq!(at(4, centre).labels, [false, true, true], "tears at frame 6: 2 frames ahead");
        assert_eq!(at(0, centre).labels, [false, false, false]);
        assert_eq!(at(1, centre).labels, [false, false, true]);
        assert!(!at(4, centre).covered && at(0, centre).covered);
        let far = 24 * h.l + 24;
        assert_eq!(at(4, far).labels, [false; 3]);
        assert_eq!(at(4, far).core, 0.0, "on the spiral core");
        assert_eq!(at(4, far).inputs()[1], 0.0);
        assert_eq!(at(4, centre).inputs()[0], 1.0, "the frame's largest strain rate");
        assert_eq!(at(4, centre).inputs()[2], (0.3f64 + VOID_THRESHOLD).ln());
        assert_eq!(at(0, centre).inputs()[1], CORE_DISTANCE_CAP);
    }

    #[test]
    fn a_forecast_on_the_thinning_catches_the_nucleation_and_the_strain_rate_catches_it_too() {
        let h = history();
        let s = forecast_samples(&h);
        for (p, expect) in [(Predictor::Thinning, 1), (Predictor::StrainRate, 1), (Predictor::SpiralCore, 0)] {
            let scores: Vec<f64> = s.iter().map(|x| p.score(x, None)).collect();
            let (caught, counted) = caught_in_top(&h, &s, &scores, 3, |_| true);
            assert_eq!((caught, counted), (expect, 1), "{p:?}");
        }
        // On covered sites the nucleation site, thin from frame 3, is not counted 3 frames
        // ahead (frame 3); 5 frames ahead (frame 1) it is.
        let scores: Vec<f64> = s.iter().map(|x| Predictor::Thinning.score(x, None)).collect();
        assert_eq!(caught_in_top(&h, &s, &scores, 3, |x| x.covered), (0, 0));
        assert_eq!(caught_in_top(&h, &s, &scores, 5, |x| x.covered).1, 1);
    }
}

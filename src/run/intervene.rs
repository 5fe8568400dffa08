//! `monolayer intervene RUN_DIR… --out DIR`: the paper's argument tested by intervention. For
//! every nucleation of the runs given and every lead k ([`LEADS`]), the parent's exact state k
//! frames before the nucleation is branched into arms ([`Arm`]): perturbed replicas of the
//! parent (how predictable the tear is), activity off, activity halved, substrate friction ×10
//! and flows made local (χ = 1). Each branch runs k + [`AFTER`] frames; a tear is a hole that
//! nucleates within R of the site in that window, at the nucleation site and at matched sites
//! that thinned as much and held (docs/figures.md, "Intervention").
//!
//! Stages: the plan (read each parent's frames, its nucleations, matched sites and the hole
//! tracker at each branch point), the branches (resumable, one per core, each a run directory in
//! `OUT/branches/`), and the scores and tables, written as one set.

use std::collections::BTreeMap;
use std::fmt::Write as _;
use std::fs;
use std::path::{Path, PathBuf};

use plotters::prelude::*;
use rand_chacha::rand_core::SeedableRng;
use rand_chacha::ChaCha8Rng;

use super::branch::{create_branch, BranchOptions};
use super::console::Report;
use super::files::{check_frame, read_frame, write_text, RunFrames};
use super::plots::{both_of, plot_err, Draw, FONT, PALETTE};
use super::pool::each_on_one_core;
use super::runner::{Event, RunDir};
use crate::analysis::{
    bootstrap_interval, matched_sites, mean_at, prevented_share, Analysis, HoleTracker, RunHistory, TearWatch, AFTER,
    BASELINE_SITES, BOOTSTRAP_RESAMPLES, INTERVENTION_SEED, LEADS, REPLICAS, REPLICA_AMPLITUDE,
};
use crate::formats::{Engine, RunRecord, RunStatus};
use crate::model::{Monolayer, Params, Perturbation};
use crate::run::csv;
use crate::run::error::RunError;

/// χ = ξ_s/ξ_cell of the local-flows arm: the paper's "χ ∼ 1, correlations smaller than a cell".
pub const LOCAL_CHI: f64 = 1.0;
/// The substrate friction's factor in its arm: χ moved a decade, into the no-hole regime.
pub const FRICTION_FACTOR: f64 = 10.0;
/// The confidence of the bootstrap intervals.
pub const LEVEL: f64 = 0.95;

/// What a branch changes: one parameter, or (the replicas) nothing but φ at the 10⁻⁶ level.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, clap::ValueEnum)]
pub enum Arm {
    /// The parent's parameters, φ perturbed at 10⁻⁶ (`--replicas` of them): p_same, the ceiling.
    Control,
    /// ζ = 0: passive forces and friction as they were, no active stress.
    ActivityOff,
    /// ζ/2: the dose response.
    ActivityHalved,
    /// ξ_s × 10 (`FRICTION_FACTOR`): the paper's control parameter, towards the no-hole regime.
    #[value(name = "friction-x10")]
    FrictionTenfold,
    /// ξ_s = ξ_cell, χ = 1 (`LOCAL_CHI`): flows screened within a cell, the cells as active as
    /// before.
    LocalFlows,
}

impl Arm {
    pub const ALL: [Arm; 5] =
        [Arm::Control, Arm::ActivityOff, Arm::ActivityHalved, Arm::FrictionTenfold, Arm::LocalFlows];

    pub fn name(self) -> &'static str {
        match self {
            Arm::Control => "control",
            Arm::ActivityOff => "activity-off",
            Arm::ActivityHalved => "activity-halved",
            Arm::FrictionTenfold => "friction-x10",
            Arm::LocalFlows => "local-flows",
        }
    }

    /// The one `--set` this arm gives a branch of a run with parameters `p` (None: the replicas).
    pub fn change(self, p: &Params) -> Option<String> {
        match self {
            Arm::Control => None,
            Arm::ActivityOff => Some("zeta=0".into()),
            Arm::ActivityHalved => Some(format!("zeta={}", p.zeta / 2.0)),
            Arm::FrictionTenfold => Some(format!("xi_substrate={}", p.xi_substrate * FRICTION_FACTOR)),
            Arm::LocalFlows => Some(format!("xi_substrate={}", p.xi_cell * LOCAL_CHI)),
        }
    }

    /// Branches of this arm per branch point.
    fn copies(self, replicas: usize) -> usize {
        if self == Arm::Control {
            replicas
        } else {
            1
        }
    }
}

/// How the experiment is run.
#[derive(Clone, Debug)]
pub struct InterveneOptions {
    pub runs: Vec<PathBuf>,
    pub out: PathBuf,
    /// Frames before each nucleation at which branches start.
    pub leads: Vec<usize>,
    /// Frames after the nucleation within which a tear counts.
    pub after: usize,
    pub replicas: usize,
    pub arms: Vec<Arm>,
    /// Simulations at a time.
    pub jobs: usize,
    /// Plan, estimate and print; run and write nothing.
    pub dry_run: bool,
    /// Run nothing: score the branches that have ended.
    pub tables_only: bool,
}

impl Default for InterveneOptions {
    fn default() -> Self {
        InterveneOptions {
            runs: Vec::new(),
            out: PathBuf::from("intervention"),
            leads: LEADS.to_vec(),
            after: AFTER,
            replicas: REPLICAS,
            arms: Arm::ALL.to_vec(),
            jobs: 1,
            dry_run: false,
            tables_only: false,
        }
    }
}

/// A parent run, read: its frames' steps, its history (nucleations, the sub-grid's thinning) and
/// the hole tracker as it stood after each frame a branch starts from.
struct Parent {
    dir: PathBuf,
    name: String,
    record: RunRecord,
    steps: Vec<u64>,
    trackers: BTreeMap<usize, HoleTracker>,
}

/// One nucleation and lead: the branch point and the sites watched there.
#[derive(Clone, Debug)]
struct Case {
    parent: usize,
    hole: usize,
    nucleation_step: u64,
    x: f64,
    y: f64,
    k: usize,
    /// The frame (index into the parent's) and step the branches start from.
    frame: usize,
    step: u64,
    /// Least Σφ within R of the site at the branch point, and whether it was still covered.
    least: f64,
    covered: bool,
    matched: Vec<(f64, f64)>,
}

impl Case {
    fn window_end(&self, fi: u64, after: usize) -> u64 {
        self.step + (self.k + after) as u64 * fi
    }
}

/// One branch to run: a parent's state at `step`, one arm (and replica), to step `end`.
#[derive(Clone, Debug, PartialEq, Eq, PartialOrd, Ord)]
struct Job {
    parent: usize,
    step: u64,
    arm: Arm,
    replica: usize,
    end: u64,
}

impl Job {
    fn dir(&self, out: &Path, parents: &[Parent]) -> PathBuf {
        let arm = match self.arm {
            Arm::Control => format!("control{}", self.replica),
            a => a.name().to_string(),
        };
        out.join("branches").join(&parents[self.parent].name).join(format!("at{:07}_{arm}", self.step))
    }
}

/// The plan: parents, cases and the branches they need.
struct Plan {
    parents: Vec<Parent>,
    cases: Vec<Case>,
    jobs: Vec<Job>,
    /// Nucleations too early in their run for a lead (no frame k before them).
    skipped: usize,
}

/// Reads one parent: finished, on the CPU engine, not itself a branch; every frame measured.
fn read_parent(dir: &Path) -> Result<(Parent, RunHistory), RunError> {
    let run = RunFrames::open(dir)?;
    let record = run.record.clone();
    if record.status != RunStatus::Finished {
        return Err(RunError::file(
            dir,
            format!("the run has not finished ({}): finish it first (`monolayer run --resume`)", record.status),
        ));
    }
    if Engine::parse(&record.engine)? != Engine::Cpu {
        return Err(RunError::file(dir, "a run of the GPU engine: branches continue CPU runs only"));
    }
    if record.branch.is_some() {
        return Err(RunError::file(dir, "a branch itself: give the run it was branched from"));
    }
    let p = &record.params;
    let mut a = Analysis::new(p);
    let mut tracker = HoleTracker::new(p.radius);
    let mut history = RunHistory::new(p.box_size, p.radius);
    let mut trackers = BTreeMap::new();
    for (i, (step, path)) in run.frames.iter().enumerate() {
        let frame = read_frame(path, p.box_size)?;
        check_frame(&frame, p)?;
        a.measure_cells(frame.data.cell_views(), &frame.data.velocity);
        tracker.update(&a.voids, frame.data.time);
        history.push(&a, &tracker, *step);
        trackers.insert(i, tracker.clone());
    }
    let name = dir.file_name().map(|n| n.to_string_lossy().into_owned()).unwrap_or_else(|| "run".into());
    let steps = run.frames.iter().map(|f| f.0).collect();
    Ok((Parent { dir: dir.to_path_buf(), name, record, steps, trackers }, history))
}

/// The cases of one parent: every nucleation and lead with a frame that far before it, with
/// [`BASELINE_SITES`] matched sites drawn (seeded) from the sites that thinned as much and held:
/// the forecast's matched chance, less the sites inside a hole already open, which cannot tear
/// again.
fn cases_of(index: usize, parent: &Parent, history: &RunHistory, leads: &[usize]) -> (Vec<Case>, usize) {
    let mut rng = ChaCha8Rng::seed_from_u64(INTERVENTION_SEED);
    let (l, r) = (history.l, history.radius);
    let (mut cases, mut skipped) = (Vec::new(), 0);
    for n in &history.nucleations {
        for &k in leads {
            let Some(frame) = n.frame.checked_sub(k) else {
                skipped += 1;
                continue;
            };
            let phi_sum = &history.frames[frame].phi_sum;
            let least = crate::analysis::least_within(phi_sum, l, n.x, n.y, r);
            cases.push(Case {
                parent: index,
                hole: n.hole,
                nucleation_step: parent.steps[n.frame],
                x: n.x,
                y: n.y,
                k,
                frame,
                step: parent.steps[frame],
                least,
                covered: crate::analysis::covered_about(phi_sum, l, n.x, n.y, r),
                matched: matched_sites(
                    history,
                    frame,
                    least,
                    &|site| !parent.trackers[&frame].in_open_hole(site),
                    &mut rng,
                    BASELINE_SITES,
                ),
            });
        }
    }
    (cases, skipped)
}

/// Reads every parent and lays out the cases and the branches.
fn plan(o: &InterveneOptions, say: &mut dyn FnMut(String)) -> Result<Plan, RunError> {
    let mut seen: BTreeMap<PathBuf, PathBuf> = BTreeMap::new();
    let (mut parents, mut cases, mut skipped) = (Vec::new(), Vec::new(), 0);
    for dir in &o.runs {
        let real = fs::canonicalize(dir).map_err(|e| RunError::io(dir, e))?;
        if let Some(first) = seen.insert(real.clone(), dir.clone()) {
            return Err(RunError::Options(format!(
                "{} and {} are the same run ({}): give each run once",
                first.display(),
                dir.display(),
                real.display()
            )));
        }
        let (parent, history) = read_parent(dir)?;
        if parents.iter().any(|p: &Parent| p.name == parent.name) {
            return Err(RunError::Options(format!(
                "two runs are named {}: their branches would share OUT/branches/{0}; give runs of distinct names",
                parent.name
            )));
        }
        let (mut c, s) = cases_of(parents.len(), &parent, &history, &o.leads);
        say(format!("{}: {} nucleations, {} cases", dir.display(), history.nucleations.len(), c.len()));
        cases.append(&mut c);
        skipped += s;
        parents.push(parent);
    }
    // Each branch runs to the end of the longest window that starts at its point.
    let mut ends: BTreeMap<(usize, u64, Arm, usize), u64> = BTreeMap::new();
    for c in &cases {
        let fi = parents[c.parent].record.frame_interval;
        for &arm in &o.arms {
            for replica in 1..=arm.copies(o.replicas) {
                let end = ends.entry((c.parent, c.step, arm, replica)).or_insert(0);
                *end = (*end).max(c.window_end(fi, o.after));
            }
        }
    }
    // The trackers of branch points only.
    for (i, p) in parents.iter_mut().enumerate() {
        p.trackers.retain(|f, _| cases.iter().any(|c| c.parent == i && c.frame == *f));
    }
    let jobs =
        ends.into_iter().map(|((parent, step, arm, replica), end)| Job { parent, step, arm, replica, end }).collect();
    Ok(Plan { parents, cases, jobs, skipped })
}

/// Steps still to run for `job` (None: nothing, it has ended): all of it, or what its directory
/// has not run yet (0 for one stopped at its end, which still has its record to finish).
fn steps_left(job: &Job, dir: &Path) -> Option<u64> {
    match RunRecord::load(dir) {
        Ok(r) if r.status.is_complete() && r.params.total_steps() >= job.end => None,
        Ok(r) => Some(job.end - r.last_frame_step.unwrap_or(job.step).min(job.end)),
        Err(_) => Some(job.end - job.step),
    }
}

/// Runs (or resumes, or extends, or skips) one branch. A directory without `run.json` is a branch
/// this command started and that was killed before it was made: it is made again.
fn run_job(job: &Job, parent: &Parent, dir: &Path, on_step: &(dyn Fn() + Sync)) -> Result<RunStatus, RunError> {
    let changes: Vec<String> = job.arm.change(&parent.record.params).into_iter().collect();
    let mut run = if RunRecord::path(dir).exists() {
        let mut record = RunRecord::load(dir)?;
        let origin = record.branch.as_ref().ok_or_else(|| RunError::file(dir, "not a branch: not this command's"))?;
        let given: Vec<String> = origin.changes.iter().map(|c| format!("{}={}", c.key, c.branch)).collect();
        if origin.step != job.step || given.len() != changes.len() {
            return Err(RunError::file(
                dir,
                "a branch of another point or arm: not this experiment's (another --out?)",
            ));
        }
        if record.status.is_complete() && record.params.total_steps() >= job.end {
            return Ok(record.status);
        }
        if record.params.total_steps() < job.end {
            // A longer window than the branch was made for: the same trajectory, extended.
            record.params.active_steps += job.end - record.params.total_steps();
            record.status = RunStatus::Stopped("extended".into());
            record.save(dir)?;
        }
        RunDir::resume(dir)?
    } else {
        if dir.exists() {
            fs::remove_dir_all(dir).map_err(|e| RunError::io(dir, e))?;
        }
        let options = BranchOptions {
            parent: parent.dir.clone(),
            at: job.step,
            sets: changes,
            steps: Some(job.end - job.step),
            frame_interval: None,
            perturbation: (job.arm == Arm::Control)
                .then_some(Perturbation { seed: job.replica as u64, amplitude: REPLICA_AMPLITUDE }),
            out: dir.to_path_buf(),
        };
        create_branch(&options, &mut |_, _| {})?
    };
    match run.execute(false, &mut |_, e| {
        if *e == Event::Step {
            on_step()
        }
    }) {
        Ok(()) => Ok(RunStatus::Finished),
        Err(e) if run.record.status.blew_up() => {
            let _ = e;
            Ok(run.record.status.clone())
        }
        Err(e) => Err(e),
    }
}

/// One watched site's outcome in one branch.
#[derive(Clone, Debug)]
struct Outcome {
    case: usize,
    arm: Arm,
    replica: usize,
    /// 0: the nucleation site; 1…: the matched sites.
    site: usize,
    tear_step: Option<u64>,
    /// Torn within the window (None: the branch failed before the window ended without a tear).
    tore: Option<bool>,
}

/// One frame of one branch at a case's nucleation site.
#[derive(Clone, Debug)]
struct TraceRow {
    case: usize,
    arm: Arm,
    replica: usize,
    offset: usize,
    least: f64,
    strain_rate: f64,
    mean_speed: f64,
    velocity_correlation_length: Option<f64>,
}

/// Follows one finished branch's frames for tears at every site its cases watch.
fn score_job(
    job: &Job,
    cases: &[(usize, &Case)],
    parent: &Parent,
    dir: &Path,
    after: usize,
) -> Result<(Vec<Outcome>, Vec<TraceRow>), RunError> {
    let p = &parent.record.params;
    let fi = parent.record.frame_interval;
    let frame = cases[0].1.frame;
    let mut sites = Vec::new();
    let mut first_site = Vec::new();
    for (_, c) in cases {
        first_site.push(sites.len());
        sites.push((c.x, c.y));
        sites.extend_from_slice(&c.matched);
    }
    let tracker = parent.trackers.get(&frame).expect("a tracker at every branch point").clone();
    let mut watch = TearWatch::new(tracker, sites, p.box_size, p.radius);
    let run = RunFrames::open(dir)?;
    let branch_params = &run.record.params;
    let mut a = Analysis::new(branch_params);
    let mut last = job.step;
    for (step, path) in run.frames.iter().filter(|f| f.0 <= job.end) {
        let frame = read_frame(path, p.box_size)?;
        check_frame(&frame, branch_params)?;
        a.measure_cells(frame.data.cell_views(), &frame.data.velocity);
        if *step == job.step {
            watch.start(&a, *step);
        } else {
            watch.push(&a, frame.data.time, *step);
        }
        last = *step;
    }
    let (mut outcomes, mut trace) = (Vec::new(), Vec::new());
    for ((ci, c), &first) in cases.iter().zip(&first_site) {
        let end = c.window_end(fi, after);
        for s in 0..=c.matched.len() {
            let tear_step = watch.first_tear[first + s].filter(|&t| t <= end);
            let tore = if tear_step.is_some() {
                Some(true)
            } else if last >= end {
                Some(false)
            } else {
                None
            };
            outcomes.push(Outcome { case: *ci, arm: job.arm, replica: job.replica, site: s, tear_step, tore });
        }
        for (offset, f) in watch.frames.iter().enumerate().filter(|(_, f)| f.step <= end) {
            trace.push(TraceRow {
                case: *ci,
                arm: job.arm,
                replica: job.replica,
                offset,
                least: f.sites[first].least,
                strain_rate: f.sites[first].strain_rate,
                mean_speed: f.mean_speed,
                velocity_correlation_length: f.velocity_correlation_length,
            });
        }
    }
    Ok((outcomes, trace))
}

/// One row of the summary: an arm at a lead, at nucleation or matched sites.
#[derive(Clone, Debug)]
struct Share {
    arm: Arm,
    k: usize,
    matched: bool,
    units: usize,
    seeds: usize,
    share: f64,
    interval: Option<(f64, f64)>,
    seed_sd: Option<f64>,
    prevented: Option<f64>,
    prevented_interval: Option<(f64, f64)>,
}

/// Per case, the share of an arm's branches that tore at the nucleation site (or, `matched`, the
/// share over its matched sites); None where nothing was decided.
fn unit_shares(cases: &[Case], outcomes: &[Outcome], arm: Arm, matched: bool) -> Vec<Option<f64>> {
    let mut sums = vec![(0.0, 0usize); cases.len()];
    for o in outcomes.iter().filter(|o| o.arm == arm && (o.site > 0) == matched) {
        if let Some(t) = o.tore {
            sums[o.case].0 += f64::from(u8::from(t));
            sums[o.case].1 += 1;
        }
    }
    sums.into_iter().map(|(s, n)| (n > 0).then(|| s / n as f64)).collect()
}

fn summarise(plan: &Plan, outcomes: &[Outcome], o: &InterveneOptions) -> Vec<Share> {
    let mut rows = Vec::new();
    let seed_of = |c: &Case| plan.parents[c.parent].record.seed;
    for &matched in &[false, true] {
        let control = unit_shares(&plan.cases, outcomes, Arm::Control, matched);
        for &arm in &o.arms {
            let shares = unit_shares(&plan.cases, outcomes, arm, matched);
            for &k in &o.leads {
                let units: Vec<usize> =
                    (0..plan.cases.len()).filter(|&i| plan.cases[i].k == k && shares[i].is_some()).collect();
                let values: Vec<f64> = units.iter().map(|&i| shares[i].unwrap_or(0.0)).collect();
                let all: Vec<usize> = (0..values.len()).collect();
                let share = mean_at(&values, &all).unwrap_or(f64::NAN);
                let seed = INTERVENTION_SEED ^ (k as u64) << 8 ^ arm as u64;
                let interval =
                    bootstrap_interval(values.len(), BOOTSTRAP_RESAMPLES, seed, LEVEL, |d| mean_at(&values, d));
                let mut per_seed: BTreeMap<u64, (f64, usize)> = BTreeMap::new();
                for (&i, v) in units.iter().zip(&values) {
                    let e = per_seed.entry(seed_of(&plan.cases[i])).or_insert((0.0, 0));
                    e.0 += v;
                    e.1 += 1;
                }
                let seed_means: Vec<f64> = per_seed.values().map(|(s, n)| s / *n as f64).collect();
                let (prevented, prevented_interval) = if arm != Arm::Control && !matched {
                    let paired: Vec<usize> = units.iter().copied().filter(|&i| control[i].is_some()).collect();
                    let a: Vec<f64> = paired.iter().map(|&i| shares[i].unwrap_or(0.0)).collect();
                    let c: Vec<f64> = paired.iter().map(|&i| control[i].unwrap_or(0.0)).collect();
                    let idx: Vec<usize> = (0..paired.len()).collect();
                    (
                        prevented_share(&a, &c, &idx),
                        bootstrap_interval(paired.len(), BOOTSTRAP_RESAMPLES, seed ^ 1, LEVEL, |d| {
                            prevented_share(&a, &c, d)
                        }),
                    )
                } else {
                    (None, None)
                };
                rows.push(Share {
                    arm,
                    k,
                    matched,
                    units: values.len(),
                    seeds: seed_means.len(),
                    share,
                    interval,
                    seed_sd: sd(&seed_means),
                    prevented,
                    prevented_interval,
                });
            }
        }
    }
    rows
}

/// The standard deviation (n − 1), None below two values.
fn sd(v: &[f64]) -> Option<f64> {
    let n = v.len() as f64;
    let m = v.iter().sum::<f64>() / n;
    (v.len() > 1).then(|| (v.iter().map(|x| (x - m).powi(2)).sum::<f64>() / (n - 1.0)).sqrt())
}

fn interval_cells(i: Option<(f64, f64)>) -> String {
    i.map(|(lo, hi)| format!("{lo:.4},{hi:.4}")).unwrap_or_else(|| ",".into())
}

fn cases_csv(plan: &Plan) -> String {
    let mut s = String::from(
        "case,run,seed,chi,zeta,hole,nucleation_step,x,y,k,branch_step,least_within_r,covered,matched_sites\n",
    );
    for (i, c) in plan.cases.iter().enumerate() {
        let p = &plan.parents[c.parent];
        let params = &p.record.params;
        let _ = writeln!(
            s,
            "{i},{},{},{},{},{},{},{:.2},{:.2},{},{},{:.4},{},{}",
            p.name,
            p.record.seed,
            params.chi(),
            params.zeta,
            c.hole,
            c.nucleation_step,
            c.x,
            c.y,
            c.k,
            c.step,
            c.least,
            u8::from(c.covered),
            c.matched.len()
        );
    }
    s
}

/// Per parameter point (χ, ζ) of the parents, arm and lead: the nucleations and the mean over
/// them of the share of their branches that tore at the site, as `intervention.csv` takes it
/// over all points (its `nucleation` rows; too few per point for intervals).
fn by_point_csv(plan: &Plan, outcomes: &[Outcome], o: &InterveneOptions) -> String {
    let point = |c: &Case| {
        let p = &plan.parents[c.parent].record.params;
        (p.chi(), p.zeta)
    };
    let mut points: Vec<(f64, f64)> = plan.cases.iter().map(point).collect();
    points.sort_by(|a, b| a.partial_cmp(b).expect("finite parameters"));
    points.dedup();
    let mut s = String::from("chi,zeta,arm,k,nucleations,tear_share\n");
    for &arm in &o.arms {
        let shares = unit_shares(&plan.cases, outcomes, arm, false);
        for &(chi, zeta) in &points {
            for &k in &o.leads {
                let values: Vec<f64> = (0..plan.cases.len())
                    .filter(|&i| plan.cases[i].k == k && point(&plan.cases[i]) == (chi, zeta))
                    .filter_map(|i| shares[i])
                    .collect();
                let all: Vec<usize> = (0..values.len()).collect();
                let share = csv::cell(mean_at(&values, &all), 4);
                let _ = writeln!(s, "{chi},{zeta},{},{k},{},{share}", arm.name(), values.len());
            }
        }
    }
    s
}

fn outcomes_csv(plan: &Plan, outcomes: &[Outcome]) -> String {
    let mut s = String::from("case,run,seed,k,arm,replica,site,x,y,tore,tear_step\n");
    for o in outcomes {
        let c = &plan.cases[o.case];
        let p = &plan.parents[c.parent];
        let (x, y) = if o.site == 0 { (c.x, c.y) } else { c.matched[o.site - 1] };
        let tore = match o.tore {
            Some(t) => u8::from(t).to_string(),
            None => "undecided".into(),
        };
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{x:.2},{y:.2},{tore},{}",
            o.case,
            p.name,
            p.record.seed,
            c.k,
            o.arm.name(),
            o.replica,
            o.site,
            o.tear_step.map(|t| t.to_string()).unwrap_or_default()
        );
    }
    s
}

fn traces_csv(plan: &Plan, trace: &[TraceRow]) -> String {
    let mut s = String::from(
        "case,run,k,arm,replica,offset,step,least_within_r,strain_rate_within_half_r,mean_speed,velocity_correlation_length\n",
    );
    for t in trace {
        let c = &plan.cases[t.case];
        let fi = plan.parents[c.parent].record.frame_interval;
        let _ = writeln!(
            s,
            "{},{},{},{},{},{},{},{:.5},{:.6},{:.6},{}",
            t.case,
            plan.parents[c.parent].name,
            c.k,
            t.arm.name(),
            t.replica,
            t.offset,
            c.step + t.offset as u64 * fi,
            t.least,
            t.strain_rate,
            t.mean_speed,
            csv::cell(t.velocity_correlation_length, 4)
        );
    }
    s
}

fn summary_csv(rows: &[Share]) -> String {
    let mut s = String::from(
        "arm,k,sites,cases,seeds,tear_share,ci_low,ci_high,seed_sd,prevented,prevented_ci_low,prevented_ci_high\n",
    );
    for r in rows {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{:.4},{},{},{},{}",
            r.arm.name(),
            r.k,
            if r.matched { "matched" } else { "nucleation" },
            r.units,
            r.seeds,
            r.share,
            interval_cells(r.interval),
            csv::cell(r.seed_sd, 4),
            csv::cell(r.prevented, 4),
            interval_cells(r.prevented_interval)
        );
    }
    s
}

/// Per arm, lead and frame after the branch point: the median least Σφ within R of the
/// nucleation site, the mean strain rate within R/2 there, the mean speed and the velocity's
/// correlation length: the motion stopping while the thinning stays.
fn trace_summary_csv(plan: &Plan, trace: &[TraceRow], o: &InterveneOptions) -> String {
    let mut s = String::from(
        "arm,k,offset,branches,median_least_within_r,mean_strain_rate_within_half_r,mean_speed,mean_velocity_correlation_length\n",
    );
    for &arm in &o.arms {
        for &k in &o.leads {
            for offset in 0..=k + o.after {
                let rows: Vec<&TraceRow> =
                    trace.iter().filter(|t| t.arm == arm && t.offset == offset && plan.cases[t.case].k == k).collect();
                if rows.is_empty() {
                    continue;
                }
                let mut least: Vec<f64> = rows.iter().map(|t| t.least).collect();
                least.sort_by(f64::total_cmp);
                let n = rows.len() as f64;
                let mean = |f: &dyn Fn(&TraceRow) -> f64| rows.iter().map(|t| f(t)).sum::<f64>() / n;
                let lengths: Vec<f64> = rows.iter().filter_map(|t| t.velocity_correlation_length).collect();
                let _ = writeln!(
                    s,
                    "{},{k},{offset},{},{:.5},{:.6},{:.6},{}",
                    arm.name(),
                    rows.len(),
                    least[least.len() / 2],
                    mean(&|t| t.strain_rate),
                    mean(&|t| t.mean_speed),
                    csv::cell((!lengths.is_empty()).then(|| lengths.iter().sum::<f64>() / lengths.len() as f64), 4)
                );
            }
        }
    }
    s
}

/// The figure: the tear share against the lead for each arm, at nucleation sites and at matched
/// sites, with the bootstrap intervals.
struct SharesFigure<'a>(&'a [Share], &'a [Arm]);

impl Draw for SharesFigure<'_> {
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, plotters::coord::Shift>) -> Result<(), RunError> {
        root.fill(&WHITE).map_err(plot_err)?;
        let panels = root.split_evenly((1, 2));
        let kmax = self.0.iter().map(|r| r.k).max().unwrap_or(1) as f64 + 0.5;
        for (panel, matched) in panels.iter().zip([false, true]) {
            let title =
                if matched { "Matched sites (thinned as much, held in the parent)" } else { "Nucleation sites" };
            let mut chart = ChartBuilder::on(panel)
                .caption(title, (FONT, 20))
                .margin(14)
                .x_label_area_size(44)
                .y_label_area_size(56)
                .build_cartesian_2d(0.5..kmax, 0.0..1.05)
                .map_err(plot_err)?;
            chart
                .configure_mesh()
                .x_desc("frames before the nucleation the branch starts (k)")
                .y_desc("share of branches that tear within R")
                .draw()
                .map_err(plot_err)?;
            for (ai, &arm) in self.1.iter().enumerate() {
                let c = PALETTE[ai % PALETTE.len()];
                let rows: Vec<&Share> =
                    self.0.iter().filter(|r| r.arm == arm && r.matched == matched && r.units > 0).collect();
                let dx = (ai as f64 - 2.0) * 0.04;
                let pts: Vec<(f64, f64)> = rows.iter().map(|r| (r.k as f64 + dx, r.share)).collect();
                chart
                    .draw_series(LineSeries::new(pts.clone(), c.stroke_width(2)))
                    .map_err(plot_err)?
                    .label(arm.name())
                    .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 20, y)], c.stroke_width(2)));
                chart.draw_series(pts.iter().map(|&p| Circle::new(p, 4, c.filled()))).map_err(plot_err)?;
                chart
                    .draw_series(rows.iter().filter_map(|r| {
                        r.interval.map(|(lo, hi)| {
                            PathElement::new(vec![(r.k as f64 + dx, lo), (r.k as f64 + dx, hi)], c.stroke_width(1))
                        })
                    }))
                    .map_err(plot_err)?;
            }
            chart
                .configure_series_labels()
                .background_style(WHITE.mix(0.8))
                .border_style(BLACK)
                .label_font((FONT, 14))
                .position(SeriesLabelPosition::UpperRight)
                .draw()
                .map_err(plot_err)?;
        }
        Ok(())
    }
}

/// `monolayer intervene`: plans, runs the branches (unless `tables_only` or `dry_run`), scores
/// them and writes the tables and the figure into `out` as one set. Returns the files written.
pub fn intervene(o: &InterveneOptions, report: &(dyn Fn(Report) + Sync)) -> Result<Vec<PathBuf>, RunError> {
    check_options(o)?;
    let plan = plan(o, &mut |line| report(Report::Line(line)))?;
    if plan.cases.is_empty() {
        return Err(RunError::Options(
            "no nucleation with a frame that far before it in these runs: nothing to branch".into(),
        ));
    }
    let dirs: Vec<PathBuf> = plan.jobs.iter().map(|j| j.dir(&o.out, &plan.parents)).collect();
    let left: Vec<Option<u64>> = plan.jobs.iter().zip(&dirs).map(|(j, d)| steps_left(j, d)).collect();
    let total: u64 = left.iter().flatten().sum();
    let all: u64 = plan.jobs.iter().map(|j| j.end - j.step).sum();
    report(Report::Line(format!(
        "{} cases ({} nucleations × leads {:?}; {} too early in their runs), {} branches of {} steps in all, {} still to run",
        plan.cases.len(),
        plan.cases.iter().filter(|c| c.k == o.leads[0]).count(),
        o.leads,
        plan.skipped,
        plan.jobs.len(),
        all,
        total
    )));
    if o.dry_run {
        report(Report::Line(estimate(&plan, &left, o)?));
        return Ok(Vec::new());
    }
    if !o.tables_only && left.iter().any(Option::is_some) {
        run_branches(&plan, &dirs, &left, o, report)?;
    }
    score_and_write(&plan, &dirs, o, report)
}

fn check_options(o: &InterveneOptions) -> Result<(), RunError> {
    if o.runs.is_empty() {
        return Err(RunError::Options("give at least one run directory".into()));
    }
    if o.leads.is_empty() || o.leads.contains(&0) || o.leads.iter().any(|&k| k > 100) {
        return Err(RunError::invalid("--leads", format!("{:?}", o.leads), "frames in [1, 100], at least one"));
    }
    let mut sorted = o.leads.clone();
    sorted.sort_unstable();
    sorted.dedup();
    if sorted.len() != o.leads.len() {
        return Err(RunError::Options(format!("--leads {:?}: a lead is listed twice", o.leads)));
    }
    if o.after > 100 {
        return Err(RunError::invalid("--after", o.after, "frames in [0, 100]"));
    }
    if !(1..=100).contains(&o.replicas) {
        return Err(RunError::invalid("--replicas", o.replicas, "in [1, 100]"));
    }
    if !o.arms.contains(&Arm::Control) {
        return Err(RunError::Options(
            "--arms must include control: the replicas' tear share is what every other arm is read against".into(),
        ));
    }
    Ok(())
}

/// The dry run's estimate: ms per step of each arm, timed on the first branch point's state
/// (20 steps after 5 untimed), times the steps left.
fn estimate(plan: &Plan, left: &[Option<u64>], o: &InterveneOptions) -> Result<String, RunError> {
    let first = &plan.jobs[0];
    let parent = &plan.parents[first.parent];
    let kept = super::files::kept_checkpoint_path(&parent.dir, first.step);
    let state = if kept.exists() {
        super::files::read_checkpoint(&kept, parent.record.params.box_size)?
    } else {
        return Ok(format!(
            "no estimate: {} keeps no checkpoint at step {} (run the parents with --keep-checkpoints; otherwise every \
             branch replays its parent from the start)",
            parent.dir.display(),
            first.step
        ));
    };
    let pool = rayon::ThreadPoolBuilder::new().num_threads(1).build()?;
    let mut ms: BTreeMap<Arm, f64> = BTreeMap::new();
    for &arm in &o.arms {
        let (params, _) = super::branch::branch_params(
            &parent.record.params,
            &arm.change(&parent.record.params).into_iter().collect::<Vec<_>>(),
        )?;
        let mut m = Monolayer::from_state(params, parent.record.seed, state.clone())?;
        pool.install(|| m.advance(5))?;
        let t = std::time::Instant::now();
        pool.install(|| m.advance(20))?;
        ms.insert(arm, t.elapsed().as_secs_f64() * 1e3 / 20.0);
    }
    let seconds: f64 = plan.jobs.iter().zip(left).map(|(j, n)| n.unwrap_or(0) as f64 * ms[&j.arm] * 1e-3).sum();
    let per_arm: Vec<String> = ms.iter().map(|(a, t)| format!("{} {t:.1}", a.name())).collect();
    let replays = plan
        .jobs
        .iter()
        .filter(|j| !super::files::kept_checkpoint_path(&plan.parents[j.parent].dir, j.step).exists())
        .count();
    Ok(format!(
        "estimate: {:.1} core-hours, about {:.1} h on {} core(s) (ms per step: {}; timed here now, on {}'s state at step \
         {}){}",
        seconds / 3600.0,
        seconds / 3600.0 / o.jobs as f64,
        o.jobs,
        per_arm.join(", "),
        parent.name,
        first.step,
        if replays > 0 {
            format!("; {replays} branches start where their parent kept no checkpoint and replay it first (not counted)")
        } else {
            String::new()
        }
    ))
}

fn run_branches(
    plan: &Plan,
    dirs: &[PathBuf],
    left: &[Option<u64>],
    o: &InterveneOptions,
    report: &(dyn Fn(Report) + Sync),
) -> Result<(), RunError> {
    let total: u64 = left.iter().flatten().sum();
    let steps = std::sync::atomic::AtomicU64::new(0);
    let done = std::sync::atomic::AtomicUsize::new(0);
    let order: Vec<usize> = (0..plan.jobs.len()).filter(|&i| left[i].is_some()).collect();
    let results = each_on_one_core(&order, o.jobs, |_, &i| {
        let job = &plan.jobs[i];
        let on_step = || {
            let s = steps.fetch_add(1, std::sync::atomic::Ordering::Relaxed) + 1;
            if s.is_multiple_of(200) {
                let done = done.load(std::sync::atomic::Ordering::Relaxed);
                report(Report::Progress { steps: s, of: total, done, runs: order.len() });
            }
        };
        let r = run_job(job, &plan.parents[job.parent], &dirs[i], &on_step);
        done.fetch_add(1, std::sync::atomic::Ordering::Relaxed);
        r.map_err(|e| e.context(dirs[i].display().to_string()))
    });
    if let Some((name, _)) = super::runner::stop_signal() {
        return Err(RunError::Interrupted {
            signal: name,
            detail: ": the same command again continues the branches from their checkpoints".into(),
        });
    }
    let errors: Vec<String> = results.into_iter().flatten().filter_map(|r| r.err()).map(|e| e.to_string()).collect();
    if !errors.is_empty() {
        return Err(RunError::Jobs(errors));
    }
    Ok(())
}

fn score_and_write(
    plan: &Plan,
    dirs: &[PathBuf],
    o: &InterveneOptions,
    report: &(dyn Fn(Report) + Sync),
) -> Result<Vec<PathBuf>, RunError> {
    // The cases each branch serves.
    let mut served: Vec<Vec<(usize, &Case)>> = vec![Vec::new(); plan.jobs.len()];
    for (ci, c) in plan.cases.iter().enumerate() {
        for (ji, j) in plan.jobs.iter().enumerate() {
            if j.parent == c.parent && j.step == c.step {
                served[ji].push((ci, c));
            }
        }
    }
    let ended: Vec<usize> =
        (0..plan.jobs.len()).filter(|&i| RunRecord::load(&dirs[i]).is_ok_and(|r| r.status.is_complete())).collect();
    report(Report::Line(format!("scoring {} of {} branches (those that ended)", ended.len(), plan.jobs.len())));
    let scored = each_on_one_core(&ended, o.jobs, |_, &i| {
        let job = &plan.jobs[i];
        score_job(job, &served[i], &plan.parents[job.parent], &dirs[i], o.after)
            .map_err(|e| e.context(dirs[i].display().to_string()))
    });
    let (mut outcomes, mut trace) = (Vec::new(), Vec::new());
    for r in scored.into_iter().flatten() {
        let (mut a, mut b) = r?;
        outcomes.append(&mut a);
        trace.append(&mut b);
    }
    outcomes.sort_by_key(|x| (x.case, x.arm, x.replica, x.site));
    trace.sort_by_key(|x| (x.case, x.arm, x.replica, x.offset));
    let shares = summarise(plan, &outcomes, o);
    // Every output is rewritten whole each time: none is left over from an earlier set.
    super::files::write_set(
        &o.out,
        |_| false,
        |stage| {
            let mut written = Vec::new();
            for (name, text) in [
                ("intervention.csv", summary_csv(&shares)),
                ("intervention_cases.csv", cases_csv(plan)),
                ("intervention_by_point.csv", by_point_csv(plan, outcomes.as_slice(), o)),
                ("intervention_outcomes.csv", outcomes_csv(plan, &outcomes)),
                ("intervention_traces.csv", traces_csv(plan, &trace)),
                ("intervention_trace_summary.csv", trace_summary_csv(plan, &trace, o)),
            ] {
                let path = stage.join(name);
                write_text(&path, &text)?;
                written.push(path);
            }
            written.extend(both_of(&stage.join("intervention"), (1400, 620), &SharesFigure(&shares, &o.arms))?);
            Ok(written)
        },
    )
}

//! The measures, the third stage of `monolayer figures`: every finished run measured once, in
//! parallel, into what the figures need of it ([`RunData`]), by the same code as `monolayer
//! analyze` ([`crate::run::offline::RunAnalysis`]).

use std::collections::BTreeMap;
use std::path::Path;

use rayon::prelude::*;

use super::plan::{Figure, Plan, Point};
use super::runs::Runs;
use crate::analysis::{counted_holes, CountedHole, HoleCounting, Precursor};
use crate::formats::{RunRecord, RunStatus};
use crate::run::error::RunError;
use crate::run::files::RunFrames;
use crate::run::offline::RunAnalysis;

/// What the figures need of one run.
#[derive(Clone, Debug)]
pub struct RunData {
    pub status: RunStatus,
    pub frames: usize,
    /// Time from the first to the last frame (the run's t_total, as in the sweep's regime map).
    pub active_time: f64,
    pub box_area: f64,
    /// The run's holes, counted as the regime criterion counts them (families).
    pub holes: Vec<CountedHole>,
    pub precursors: Vec<Precursor>,
    /// The precursors' chance baseline: random sites of the same frames.
    pub chance: Vec<Precursor>,
    /// Tangential alignment ([`crate::analysis::alignment`]): every angle (radians) between a
    /// cell's axis and the nearest hole boundary's tangent, over the frames with a hole open, for
    /// the cells bordering a hole and the cells away from holes.
    pub alignment: (Vec<f64>, Vec<f64>),
    /// Strain-rate bin → (sites, sites opening into a new hole), Fig. 2.
    pub probability: BTreeMap<i64, (u64, u64)>,
    /// C_v(r), C_Q(r) of the last frame: the paper's Fig. S1 takes them after the whole run.
    pub correlations: (Vec<f64>, Vec<f64>),
}

impl RunData {
    pub fn failed(&self) -> bool {
        self.status.blew_up()
    }
}

/// What the measures stage hands on: the plan and each of its runs measured, in the plan's order.
pub struct Measures<'p> {
    pub plan: &'p Plan,
    pub runs: Vec<RunData>,
}

impl<'p> Measures<'p> {
    /// The runs of `figure` whose point `pick` chooses, in the plan's order.
    pub fn select(&self, figure: Figure, pick: impl Fn(&Point) -> bool) -> Vec<&RunData> {
        self.plan
            .points
            .iter()
            .zip(&self.runs)
            .filter(|((p, figs), _)| figs.contains(&figure) && pick(p))
            .map(|(_, r)| r)
            .collect()
    }
}

/// Measures every run, `workers` at a time.
pub fn measure<'p>(runs: Runs<'p>, workers: usize) -> Result<Measures<'p>, RunError> {
    let pool = rayon::ThreadPoolBuilder::new().num_threads(workers.max(1)).build()?;
    let data = pool.install(|| {
        runs.dirs.par_iter().zip(&runs.records).map(|(dir, record)| measure_run(dir, record)).collect::<Result<_, _>>()
    })?;
    Ok(Measures { plan: runs.plan, runs: data })
}

fn measure_run(dir: &Path, record: &RunRecord) -> Result<RunData, RunError> {
    super::stop_if_signalled()?;
    let p = &record.params;
    let mut data = RunData {
        status: record.status.clone(),
        frames: 0,
        active_time: 0.0,
        box_area: (p.box_size * p.box_size) as f64,
        holes: Vec::new(),
        precursors: Vec::new(),
        chance: Vec::new(),
        alignment: (Vec::new(), Vec::new()),
        probability: BTreeMap::new(),
        correlations: (Vec::new(), Vec::new()),
    };
    // A run that failed before its first frame has nothing to measure; it still counts as run.
    // Frames missing where its record says there are some are refused, naming the run.
    let Some(run) = RunFrames::open_if_any(dir)? else { return Ok(data) };
    let mut ra = RunAnalysis::new(p);
    for frame in run.read() {
        ra.push_frame(&frame?);
    }
    let (first, last) = (ra.frames.first().map_or(0.0, |f| f.time), ra.frames.last().map_or(0.0, |f| f.time));
    data.frames = ra.frames.len();
    data.active_time = last - first;
    data.holes = counted_holes(&ra.tracker.holes, last, HoleCounting::Families);
    data.precursors = ra.precursors.rows.clone();
    data.chance = ra.precursors.chance.clone();
    for (_, near, away) in &ra.alignment {
        data.alignment.0.extend_from_slice(near);
        data.alignment.1.extend_from_slice(away);
    }
    data.probability = ra.hole_probability.bins.clone();
    if let Some(f) = ra.frames.last() {
        data.correlations = (f.velocity_correlation.clone(), f.nematic_correlation.clone());
    }
    Ok(data)
}

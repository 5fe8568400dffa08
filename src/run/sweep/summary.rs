//! What each run of a sweep did: its frames measured into one row of `summary.csv`, and the
//! runs found in `OUT/runs/` read back as the sweep's jobs (`--tables-only`).

use std::fs;
use std::path::Path;

use super::spec::Job;
use crate::analysis::{counted_holes, FrameSummary, HoleCounting};
use crate::formats::{RunRecord, RunStatus};
use crate::run::error::RunError;
use crate::run::files::RunFrames;
use crate::run::offline::RunAnalysis;

/// One row of the summary: what a run did.
#[derive(Clone, Debug, Default)]
pub struct RunSummary {
    pub name: String,
    pub values: Vec<(String, String)>,
    pub seed: u64,
    /// Finished, failed (blew up), stopped by an IO error (retried when the sweep runs again),
    /// or running (a shard that did not get to it).
    pub status: RunStatus,
    pub steps: u64,
    /// Time units of the active phase the frames cover (first to last frame).
    pub active_time: f64,
    /// Holes counted as families (`HoleCounting::Families`, the regime criterion's count).
    pub holes_nucleated: usize,
    pub max_hole_area: usize,
    pub time_with_hole_open: f64,
    /// (duration, closed) of each hole counted as a family: closed holes' lifetimes, and for
    /// open ones the time they were seen.
    pub lifetimes: Vec<(f64, bool)>,
    /// The same with every tracked void region a hole of its own (`HoleCounting::Regions`).
    pub region_lifetimes: Vec<(f64, bool)>,
    pub mean_speed: f64,
    /// µm/h per site per time unit, from the run's `time_unit_seconds`.
    pub microns_per_hour: f64,
    pub velocity_correlation_length: Option<f64>,
    pub nematic_correlation_length: Option<f64>,
    /// Minimum packing fraction (sites with Σφ ≥ ½) over the frames with no hole open.
    pub min_packing_without_hole: Option<f64>,
    /// The other reading of the paper's packing fraction (docs/reading.md §7): the minimum
    /// share of sites that are not void (Σφ ≥ 0.01) over the frames with no hole open.
    pub min_nonvoid_without_hole: Option<f64>,
    /// The most void regions of any size in one frame while a hole is open: 1 where, as the
    /// paper says, "no other gaps appear in the monolayer" once a hole has formed.
    pub max_void_regions_with_hole: usize,
    /// Cells' aspect ratio (shape tensor): the per-frame mean and 90th percentile, averaged
    /// over the frames.
    pub aspect_ratio_mean: Option<f64>,
    pub aspect_ratio_p90: Option<f64>,
    /// The most holes open in one frame, and the share of frames with more than one open.
    pub max_holes_open: usize,
    pub fraction_multiple_holes: f64,
    /// Wall time of the run in this invocation of the sweep (0 when it was done already).
    pub run_seconds: f64,
}

impl RunSummary {
    pub fn blew_up(&self) -> bool {
        self.status.blew_up()
    }
}

fn minimum(v: impl Iterator<Item = f64>) -> Option<f64> {
    v.fold(None, |m: Option<f64>, x| Some(m.map_or(x, |m| m.min(x))))
}

/// The paper's "when no hole is present the packing fraction is always above 95 % and, when a
/// hole is formed, no other gaps appear" measured over a run's frames, under both readings of
/// the packing fraction (docs/reading.md §7).
#[derive(Clone, Copy, Debug, PartialEq)]
struct PackingReadings {
    /// Covered: the share of sites with Σφ ≥ ½, least over the frames with no hole open.
    min_covered_without_hole: Option<f64>,
    /// Not void: the share of sites with Σφ ≥ 0.01, least over the same frames.
    min_nonvoid_without_hole: Option<f64>,
    /// The most void regions of any size in one frame with a hole open (1: no other gap).
    max_void_regions_with_hole: usize,
}

impl PackingReadings {
    /// From each frame's open holes (as tracked) and its summary.
    fn of<'a>(frames: impl Iterator<Item = (usize, &'a FrameSummary)> + Clone) -> Self {
        let without_hole = frames.clone().filter(|(open, _)| *open == 0).map(|(_, f)| f);
        PackingReadings {
            min_covered_without_hole: minimum(without_hole.clone().map(|f| f.packing_fraction)),
            min_nonvoid_without_hole: minimum(without_hole.map(|f| 1.0 - f.void_fraction)),
            max_void_regions_with_hole: frames
                .filter(|(open, _)| *open > 0)
                .map(|(_, f)| f.void_regions)
                .max()
                .unwrap_or(0),
        }
    }
}

fn mean(v: impl Iterator<Item = f64>) -> Option<f64> {
    let (s, n) = v.fold((0.0, 0usize), |(s, n), x| (s + x, n + 1));
    (n > 0).then(|| s / n as f64)
}

/// Measures the frames of the run in `dir`: every frame its record says it wrote, or none for a
/// run that wrote none (it failed or stopped before its first). A frame missing anywhere is
/// refused, naming the run, rather than counted as a run that ended there.
pub fn summarize(job: &Job, dir: &Path) -> Result<RunSummary, RunError> {
    let record = RunRecord::load(dir)?;
    let mut s = RunSummary {
        name: job.name.clone(),
        values: job.values.clone(),
        seed: job.seed,
        status: record.status.clone(),
        ..RunSummary::default()
    };
    let Some(run) = RunFrames::open_if_any(dir)? else { return Ok(s) };
    let p = &run.record.params;
    s.status = run.record.status.clone();
    s.microns_per_hour = p.microns_per_hour();
    let mut ra = RunAnalysis::new(p);
    for frame in run.read() {
        let frame = frame?;
        ra.push_frame(&frame);
        s.steps = frame.data.step;
    }
    let first = ra.frames.first().map(|f| f.time).unwrap_or(0.0);
    let last = ra.frames.last().map(|f| f.time).unwrap_or(0.0);
    s.active_time = last - first;
    let counted = |counting| -> Vec<(f64, bool)> {
        counted_holes(&ra.tracker.holes, last, counting).iter().map(|h| (h.duration, h.closed)).collect()
    };
    s.lifetimes = counted(HoleCounting::Families);
    s.region_lifetimes = counted(HoleCounting::Regions);
    s.holes_nucleated = s.lifetimes.len();
    s.max_hole_area = ra.tracker.holes.iter().map(|h| h.max_area()).max().unwrap_or(0);
    // The frames sample the active phase evenly: the share of them with a hole open is the share
    // of its time.
    let with_hole = ra.frames.iter().filter(|f| f.open_holes > 0).count() as f64;
    s.time_with_hole_open = s.active_time * with_hole / ra.frames.len().max(1) as f64;
    s.mean_speed = mean(ra.frames.iter().map(|f| f.summary.mean_speed)).unwrap_or(0.0);
    s.aspect_ratio_mean = mean(ra.frames.iter().filter_map(|f| f.summary.aspect_ratio_mean));
    s.aspect_ratio_p90 = mean(ra.frames.iter().filter_map(|f| f.summary.aspect_ratio_p90));
    s.max_holes_open = ra.frames.iter().map(|f| f.open_holes).max().unwrap_or(0);
    let multiple = ra.frames.iter().filter(|f| f.open_holes > 1).count() as f64;
    s.fraction_multiple_holes = multiple / ra.frames.len().max(1) as f64;
    s.velocity_correlation_length = mean(ra.frames.iter().filter_map(|f| f.summary.velocity_correlation_length));
    s.nematic_correlation_length = mean(ra.frames.iter().filter_map(|f| f.summary.nematic_correlation_length));
    let packing = PackingReadings::of(ra.frames.iter().map(|f| (f.open_holes, &f.summary)));
    s.min_packing_without_hole = packing.min_covered_without_hole;
    s.min_nonvoid_without_hole = packing.min_nonvoid_without_hole;
    s.max_void_regions_with_hole = packing.max_void_regions_with_hole;
    Ok(s)
}

/// Measures every run of `jobs` that has a directory in `OUT/runs/`, finished or not, running
/// nothing (`sweep --tables-only`, and the end of every sweep). A run still being written is
/// read as far as its frames go: each frame is renamed into place whole.
pub fn measure_existing(jobs: &[Job], out: &Path) -> Result<Vec<RunSummary>, RunError> {
    let runs_dir = out.join("runs");
    let mut summaries = Vec::new();
    for job in jobs {
        let dir = runs_dir.join(&job.name);
        if RunRecord::path(&dir).exists() {
            summaries
                .push(summarize(job, &dir).map_err(|e| e.context(format!("run {} (no table written)", job.name)))?);
        }
    }
    Ok(summaries)
}

/// The runs in `OUT/runs/` as jobs, for `sweep --tables-only` given no grid: each run with the
/// seed and parameters its `run.json` records, and the grid values its directory name carries
/// (`chi0.1_zeta0.5_seed1`, as [`SweepSpec::jobs`](super::SweepSpec::jobs) names runs) where every name reads so with the
/// same keys; otherwise the parameters in which the runs differ.
pub fn jobs_of_runs(out: &Path) -> Result<Vec<Job>, RunError> {
    let runs_dir = out.join("runs");
    let entries = fs::read_dir(&runs_dir).map_err(|e| RunError::NotASweep { runs: runs_dir.clone(), source: e })?;
    let mut runs = Vec::new();
    for entry in entries {
        let entry = entry.map_err(|e| RunError::io(&runs_dir, e))?;
        let name = entry.file_name().to_string_lossy().into_owned();
        let dir = entry.path();
        // Hidden entries are writers' temporaries; a run linked in from another sweep counts.
        if name.starts_with('.') || !RunRecord::path(&dir).is_file() {
            continue;
        }
        runs.push((name, RunRecord::load(&dir)?));
    }
    let named: Option<Vec<Vec<(String, String)>>> = runs.iter().map(|(n, r)| values_from_name(n, r)).collect();
    let same_keys =
        |v: &Vec<Vec<(String, String)>>| v.windows(2).all(|w| w[0].iter().map(|x| &x.0).eq(w[1].iter().map(|x| &x.0)));
    let values = match named {
        Some(v) if same_keys(&v) => v,
        _ => values_that_differ(&runs),
    };
    let mut jobs: Vec<Job> = runs
        .into_iter()
        .zip(values)
        .map(|((name, record), values)| Job { name, values, params: record.params, seed: record.seed })
        .collect();
    // The order a grid runs in: by each value, numbers as numbers, then by seed.
    jobs.sort_by(|a, b| {
        let key = |j: &Job| -> Vec<(f64, String)> {
            j.values.iter().map(|(_, v)| (v.parse::<f64>().unwrap_or(f64::NAN), v.clone())).collect()
        };
        let order = key(a)
            .iter()
            .zip(key(b).iter())
            .map(|(x, y)| x.0.total_cmp(&y.0).then_with(|| x.1.cmp(&y.1)))
            .find(|o| o.is_ne());
        order.unwrap_or(std::cmp::Ordering::Equal).then(a.seed.cmp(&b.seed)).then_with(|| a.name.cmp(&b.name))
    });
    Ok(jobs)
}

/// The grid values in a run's directory name, each checked against the run's record: a number
/// must equal the recorded parameter (`chi` the recorded ξ_s/ξ_cell as the sweep sets it), a word
/// the recorded one. None where the name does not read so.
fn values_from_name(name: &str, record: &RunRecord) -> Option<Vec<(String, String)>> {
    let table = serde_json::to_value(&record.params).ok()?;
    let table = table.as_object()?;
    let mut keys: Vec<&str> = table.keys().map(String::as_str).chain(["chi"]).collect();
    // `phi_min` before a hypothetical `phi`: the longest key that fits.
    keys.sort_by_key(|k| std::cmp::Reverse(k.len()));
    let end = format!("seed{}", record.seed);
    let mut rest = name;
    let mut values = Vec::new();
    while rest != end {
        let found = keys.iter().filter(|k| rest.starts_with(**k)).find_map(move |&k| {
            let after = &rest[k.len()..];
            let (shown, len) = match table.get(k) {
                Some(serde_json::Value::String(word)) => {
                    let written = word.replace(['/', ' ', '"'], "");
                    after.starts_with(&format!("{written}_")).then(|| (word.clone(), written.len()))?
                }
                recorded => {
                    let len = after.find('_')?;
                    let x: f64 = after[..len].parse().ok()?;
                    let matches = match recorded {
                        None => {
                            let mut p = record.params.clone();
                            p.set_chi(x);
                            p.xi_substrate == record.params.xi_substrate
                        }
                        Some(v) => v.as_f64() == Some(x),
                    };
                    matches.then(|| (after[..len].to_string(), len))?
                }
            };
            Some(((k.to_string(), shown), &after[len + 1..]))
        });
        let (value, next) = found?;
        values.push(value);
        rest = next;
    }
    Some(values)
}

/// Each run's values of the parameters in which the runs differ, by name.
fn values_that_differ(runs: &[(String, RunRecord)]) -> Vec<Vec<(String, String)>> {
    let tables: Vec<serde_json::Map<String, serde_json::Value>> = runs
        .iter()
        .map(|(_, r)| match serde_json::to_value(&r.params) {
            Ok(serde_json::Value::Object(t)) => t,
            _ => unreachable!("parameters serialise as a table"),
        })
        .collect();
    let Some(first) = tables.first() else { return Vec::new() };
    let keys: Vec<&String> = first.keys().filter(|k| tables.iter().any(|t| t.get(*k) != first.get(*k))).collect();
    let text = |v: Option<&serde_json::Value>| match v {
        Some(serde_json::Value::String(s)) => s.clone(),
        Some(v) => v.to_string(),
        None => String::new(),
    };
    tables.iter().map(|t| keys.iter().map(|k| (k.to_string(), text(t.get(*k)))).collect()).collect()
}

#[cfg(test)]
mod tests {
    use super::super::spec::SweepSpec;
    use super::*;
    use crate::model::Params;

    /// Both packing readings count only the frames with no hole open; the gaps beside a hole
    /// count every void region of the frames with one open.
    #[test]
    fn packing_readings_keep_frames_with_and_without_a_hole_apart() {
        let frame = |packing_fraction, void_fraction, void_regions| FrameSummary {
            packing_fraction,
            void_fraction,
            void_regions,
            holes: 0,
            largest_void: 0,
            plus_half_defects: 0,
            minus_half_defects: 0,
            spiral_cores: 0,
            max_strain_rate: 0.0,
            velocity_correlation_length: None,
            nematic_correlation_length: None,
            aspect_ratio_mean: None,
            aspect_ratio_p90: None,
            mean_speed: 0.0,
        };
        // No hole: a tissue with small gaps at its vertices (covered 0.93, not void 0.999),
        // then one nearly whole; a hole open with two other gaps beside it (its own low
        // packing is not counted).
        let frames = [(0, frame(0.93, 0.001, 2)), (0, frame(0.97, 0.0, 0)), (1, frame(0.70, 0.2, 3))];
        let r = PackingReadings::of(frames.iter().map(|(o, f)| (*o, f)));
        assert_eq!(r.min_covered_without_hole, Some(0.93));
        assert_eq!(r.min_nonvoid_without_hole, Some(1.0 - 0.001));
        assert_eq!(r.max_void_regions_with_hole, 3);
        let never = PackingReadings::of(frames[2..].iter().map(|(o, f)| (*o, f)));
        assert_eq!((never.min_covered_without_hole, never.min_nonvoid_without_hole), (None, None));
    }

    /// A run's directory name read back into the grid values its sweep gave it, each checked
    /// against the record; a name that does not read so gives none.
    #[test]
    fn grid_values_are_read_back_from_run_names() {
        let mut spec: SweepSpec = toml::from_str("seeds = [2]\n[grid]\nchi = [0.001]\nzeta = [0.3]\n").unwrap();
        spec.add_grid("passive_force=phi_grad_mu").unwrap();
        spec.add_grid("n_cells=40").unwrap();
        for job in spec.jobs().unwrap() {
            let record = RunRecord::new(job.params.clone(), job.seed, 50);
            assert_eq!(values_from_name(&job.name, &record), Some(job.values.clone()), "{}", job.name);
            assert_eq!(values_from_name(&job.name.replace("zeta0.3", "zeta0.4"), &record), None);
            assert_eq!(values_from_name(&job.name.replace("seed2", "seed3"), &record), None);
        }
        let (a, mut b) = (Params::default(), Params::default());
        b.gamma = 0.07;
        let runs = [("x".to_string(), RunRecord::new(a, 1, 50)), ("y".to_string(), RunRecord::new(b, 1, 50))];
        let differ = values_that_differ(&runs);
        assert_eq!(differ[1], [("gamma".to_string(), "0.07".to_string())]);
    }
}

//! The analysis of a whole run: every frame measured in order, holes followed across frames,
//! and the tables and plots written to `DIR/analysis/` (docs/cli.md, "analyze"; the tables in docs/formats.md).
//!
//! Nothing is written until every frame has been read and measured, so a run that cannot be
//! analysed (missing, foreign, another format version, a damaged frame) leaves no output.

use std::fmt::Write as _;
use std::io::Write;
use std::path::{Path, PathBuf};

use super::files::{read_run_frame, Frame, RunFrames};
use super::plots::{self, Background};
use crate::analysis::{
    boundary_sites, correlation_length, tangential_angles, Analysis, FrameSummary, HoleProbability, HoleTracker,
    Precursors, AWAY_RADII, BORDER_RADII,
};
use crate::model::{Monolayer, Params};
use crate::run::csv;
use crate::run::error::RunError;
use crate::run::files::{check_output_dir, frame_path, write_atomic, write_set};

/// What a frame contributes to the tables.
#[derive(Clone, Debug)]
pub struct FrameRecord {
    pub step: u64,
    pub time: f64,
    pub summary: FrameSummary,
    /// Holes open after this frame (tracked, so including those shrunk below πR²/4).
    pub open_holes: usize,
    pub velocity_correlation: Vec<f64>,
    pub nematic_correlation: Vec<f64>,
    /// (kind, x, y, orientation or ∇·v) of every defect and spiral core.
    pub points: Vec<(&'static str, f64, f64, f64)>,
}

/// The measurements of a run so far.
#[derive(Debug)]
pub struct RunAnalysis {
    pub analysis: Analysis,
    pub tracker: HoleTracker,
    pub frames: Vec<FrameRecord>,
    pub hole_probability: HoleProbability,
    pub precursors: Precursors,
    /// Tangential alignment at holes ([`crate::analysis::alignment`]): per frame with a hole
    /// open, (step, angles of the cells bordering a hole, angles of the cells away from holes).
    pub alignment: Vec<(u64, Vec<f64>, Vec<f64>)>,
    boundary: Vec<(f64, f64)>,
}

impl RunAnalysis {
    pub fn new(params: &Params) -> Self {
        RunAnalysis {
            analysis: Analysis::new(params),
            tracker: HoleTracker::new(params.radius),
            frames: Vec::new(),
            hole_probability: HoleProbability::default(),
            precursors: Precursors::default(),
            alignment: Vec::new(),
            boundary: Vec::new(),
        }
    }

    /// Measures the next frame from a file.
    pub fn push_frame(&mut self, frame: &Frame) {
        self.analysis.measure_cells(frame.data.cell_views(), &frame.data.velocity);
        self.record(frame.data.step, frame.data.time);
    }

    /// Measures the next frame from the running simulation (after `evaluate_now`).
    pub fn push_monolayer(&mut self, m: &Monolayer) {
        self.analysis.measure(m);
        self.record(m.step_count(), m.step_count() as f64 * m.params().dt);
    }

    fn record(&mut self, step: u64, time: f64) {
        let a = &self.analysis;
        self.tracker.update(&a.voids, time);
        self.hole_probability.push(&a.strain_rate, &a.voids, &self.tracker, a.radius);
        self.precursors.push(a, &self.tracker);
        boundary_sites(&a.voids.labels, &self.tracker.open_regions(), a.l, &mut self.boundary);
        if !self.boundary.is_empty() {
            let (mut near, mut away) = (Vec::new(), Vec::new());
            let r = a.radius;
            tangential_angles(
                &a.cell_axes,
                &self.boundary,
                a.l,
                BORDER_RADII * r,
                AWAY_RADII * r,
                &mut near,
                &mut away,
            );
            self.alignment.push((step, near, away));
        }
        let mut points: Vec<(&'static str, f64, f64, f64)> = a
            .defects
            .iter()
            .map(|d| (if d.twice_charge > 0 { "plus_half" } else { "minus_half" }, d.x, d.y, d.orientation))
            .collect();
        points.extend(a.spiral_cores().map(|p| ("spiral_core", p.x, p.y, p.divergence)));
        self.frames.push(FrameRecord {
            step,
            time,
            summary: a.summary(),
            open_holes: self.tracker.open().count(),
            velocity_correlation: a.velocity_correlation.clone(),
            nematic_correlation: a.nematic_correlation.clone(),
            points,
        });
    }

    /// The step of the frame drawn in the snapshot: the first hole's nucleation if any, else
    /// the last frame.
    pub fn snapshot_step(&self) -> Option<u64> {
        let nucleation = self.tracker.holes.first().map(|h| h.nucleated);
        nucleation
            .and_then(|t| self.frames.iter().find(|f| f.time == t).map(|f| f.step))
            .or_else(|| self.frames.last().map(|f| f.step))
    }

    /// The tables, as (file name, CSV text).
    pub fn tables(&self) -> Vec<(&'static str, String)> {
        let (holes, areas) = self.holes_tables();
        vec![
            ("frames.csv", self.frames_table()),
            ("hole_precursors.csv", precursor_table(&self.precursors.rows)),
            ("hole_precursors_chance.csv", precursor_table(&self.precursors.chance)),
            ("hole_alignment.csv", self.alignment_table()),
            ("hole_probability.csv", self.probability_table()),
            ("holes.csv", holes),
            ("hole_areas.csv", areas),
            ("correlations.csv", self.correlations_table()),
            ("defects_and_spirals.csv", self.points_table()),
        ]
    }

    /// `frames.csv`: a row of measures per frame.
    fn frames_table(&self) -> String {
        let mut frames = String::from(
            "step,time,packing_fraction,void_fraction,void_regions,holes_open,largest_void_area,plus_half_defects,\
             minus_half_defects,spiral_cores,max_strain_rate,velocity_correlation_length,nematic_correlation_length,\
             mean_speed,aspect_ratio_mean,aspect_ratio_p90\n",
        );
        for f in &self.frames {
            let s = &f.summary;
            let _ = writeln!(
                frames,
                "{},{},{:.6},{:.6},{},{},{},{},{},{},{:.6e},{},{},{:.6},{},{}",
                f.step,
                time(f.time),
                s.packing_fraction,
                s.void_fraction,
                s.void_regions,
                f.open_holes,
                s.largest_void,
                s.plus_half_defects,
                s.minus_half_defects,
                s.spiral_cores,
                s.max_strain_rate,
                csv::cell(s.velocity_correlation_length, 6),
                csv::cell(s.nematic_correlation_length, 6),
                s.mean_speed,
                csv::cell(s.aspect_ratio_mean, 6),
                csv::cell(s.aspect_ratio_p90, 6)
            );
        }
        frames
    }

    /// `holes.csv` (a row per hole) and `hole_areas.csv` (a row per hole and frame).
    fn holes_tables(&self) -> (String, String) {
        let mut holes = String::from(
            "id,nucleation_time,closing_time,lifetime,fate,frames_open,max_area,nucleation_area,\
             nucleation_x,nucleation_y,split_from,merged_into\n",
        );
        let mut areas = String::from("id,time,area,centroid_x,centroid_y\n");
        for h in &self.tracker.holes {
            let (t0, a0, x0, y0) = h.history[0];
            let id = |v: Option<usize>| v.map(|x| x.to_string()).unwrap_or_default();
            let _ = writeln!(
                holes,
                "{},{},{},{},{},{},{},{},{:.3},{:.3},{},{}",
                h.id,
                time(t0),
                h.closed.map(|c| time(c).to_string()).unwrap_or_default(),
                h.lifetime().map(|v| time(v).to_string()).unwrap_or_default(),
                h.fate(),
                h.history.len(),
                h.max_area(),
                a0,
                x0,
                y0,
                id(h.split_from),
                id(h.merged_into)
            );
            for &(t, a, x, y) in &h.history {
                let _ = writeln!(areas, "{},{},{},{:.3},{:.3}", h.id, time(t), a, x, y);
            }
        }
        (holes, areas)
    }

    /// `correlations.csv`: C_v(r) and C_Q(r) per frame.
    fn correlations_table(&self) -> String {
        let mut corr = String::from("step,r,velocity_correlation,nematic_correlation\n");
        for f in &self.frames {
            for (r, (cv, cq)) in f.velocity_correlation.iter().zip(&f.nematic_correlation).enumerate() {
                let _ = writeln!(corr, "{},{r},{cv:.6},{cq:.6}", f.step);
            }
        }
        corr
    }

    /// `defects_and_spirals.csv`: every ±½ defect and spiral core per frame.
    fn points_table(&self) -> String {
        let mut points = String::from("step,kind,x,y,orientation_or_divergence\n");
        for f in &self.frames {
            for &(kind, x, y, v) in &f.points {
                let _ = writeln!(points, "{},{kind},{x:.3},{y:.3},{v:.6}", f.step);
            }
        }
        points
    }

    /// `hole_probability.csv`: P(hole | ε̇) by strain-rate bin.
    fn probability_table(&self) -> String {
        let mut probability =
            String::from("strain_rate_bin_low,strain_rate_bin_high,sites,sites_opening_into_a_new_hole,probability\n");
        for (lo, n, h, p) in self.hole_probability.table() {
            let hi = lo + crate::analysis::STRAIN_RATE_BIN;
            let _ = writeln!(probability, "{lo:.6},{hi:.6},{n},{h},{p:.6e}");
        }
        probability
    }

    /// `hole_alignment.csv`: the cells' mean angle to a hole's tangent, bordering holes and away.
    fn alignment_table(&self) -> String {
        let mut alignment = String::from("step,cells,where,mean_angle_to_tangent\n");
        for (step, near, away) in &self.alignment {
            for (kind, v) in [("bordering_a_hole", near), ("away_from_holes", away)] {
                if !v.is_empty() {
                    let m = v.iter().sum::<f64>() / v.len() as f64;
                    let _ = writeln!(alignment, "{step},{},{kind},{m:.6}", v.len());
                }
            }
        }
        alignment
    }

    /// C_v(r) and C_Q(r) averaged over the frames measured.
    pub fn mean_correlations(&self) -> (Vec<f64>, Vec<f64>) {
        let n = self.frames.len().max(1) as f64;
        let bins = self.frames.first().map(|f| f.velocity_correlation.len()).unwrap_or(0);
        let mut cv = vec![0.0; bins];
        let mut cq = vec![0.0; bins];
        for f in &self.frames {
            for r in 0..bins {
                cv[r] += f.velocity_correlation[r] / n;
                cq[r] += f.nematic_correlation[r] / n;
            }
        }
        (cv, cq)
    }

    /// Writes the tables and plots into `out` (created) as one set ([`write_set`]): a full disk
    /// leaves the previous set, not a mix, and the snapshot of another step it held is removed.
    /// `snapshot` is the frame to draw over `field`, measured afresh.
    pub fn write(
        &self,
        out: &Path,
        snapshot: Option<&Frame>,
        field: Background,
        params: &Params,
    ) -> Result<Vec<PathBuf>, RunError> {
        let is_snapshot =
            |name: &str| name.starts_with("snapshot_") && (name.ends_with(".png") || name.ends_with(".svg"));
        write_set(out, is_snapshot, |stage| self.write_into(stage, snapshot, field, params))
    }

    fn write_into(
        &self,
        out: &Path,
        snapshot: Option<&Frame>,
        field: Background,
        params: &Params,
    ) -> Result<Vec<PathBuf>, RunError> {
        let mut written = Vec::new();
        for (name, text) in self.tables() {
            let path = out.join(name);
            write_atomic(&path, |w| w.write_all(text.as_bytes()).map_err(|e| RunError::io(&path, e)))?;
            written.push(path);
        }
        written.extend(plots::hole_areas(&out.join("hole_area"), &self.tracker.holes)?);
        let (cv, cq) = self.mean_correlations();
        let lengths = (correlation_length(&cv), correlation_length(&cq));
        written.extend(plots::correlations(&out.join("correlations"), &cv, &cq, lengths, self.frames.len())?);
        if let Some(frame) = snapshot {
            let mut a = Analysis::new(params);
            a.measure_cells(frame.data.cell_views(), &frame.data.velocity);
            let base = out.join(snapshot_name(frame.data.step));
            written.extend(plots::snapshot(&base, frame, &a, field)?);
        }
        Ok(written)
    }
}

/// `monolayer analyze DIR`: every complete frame of the run in `dir`, written to `out`
/// (default `DIR/analysis`), the snapshot (of `snapshot_step`, or chosen) drawn over `field`.
/// Returns the files written. Reads and measures everything before writing anything.
pub fn analyze_run(
    dir: &Path,
    out: Option<&Path>,
    snapshot_step: Option<u64>,
    field: Background,
) -> Result<Vec<PathBuf>, RunError> {
    let out = out.map(Path::to_path_buf).unwrap_or_else(|| dir.join("analysis"));
    check_output_dir("--out", &out)?;
    let run = RunFrames::open(dir)?;
    let params = &run.record.params;
    let mut ra = RunAnalysis::new(params);
    let kept = measure_frames(&mut ra, &run, snapshot_step)?;
    let chosen = match snapshot_step {
        Some(s) => kept.ok_or_else(|| RunError::NoFrame { step: s, frames: dir.join("frames") })?,
        None => snapshot_frame(&ra, dir, params)?.expect("at least one frame"),
    };
    ra.write(&out, Some(&chosen), field, params)
}

/// Measures the run's frames in order; returns the frame of `keep` if it was among them.
fn measure_frames(ra: &mut RunAnalysis, run: &RunFrames, keep: Option<u64>) -> Result<Option<Frame>, RunError> {
    let mut kept = None;
    for frame in run.read() {
        let frame = frame?;
        ra.push_frame(&frame);
        if Some(frame.data.step) == keep {
            kept = Some(frame);
        }
    }
    Ok(kept)
}

/// The frame [`RunAnalysis::snapshot_step`] chooses, read from the run's directory.
fn snapshot_frame(ra: &RunAnalysis, dir: &Path, params: &Params) -> Result<Option<Frame>, RunError> {
    ra.snapshot_step().map(|s| read_run_frame(&frame_path(dir, s), s, params)).transpose()
}

/// `run --analyze`: the analysis kept up to date as frames are written.
#[derive(Debug)]
pub struct LiveRun {
    ra: RunAnalysis,
    dir: PathBuf,
    params: Params,
}

impl LiveRun {
    /// Starts on the run in `dir` at step `step`, measuring the frames it already has up to
    /// there (a resumed run). Frames after `step` were written before a kill that came before
    /// their checkpoint: the run writes them again, and measures them then.
    pub fn start(dir: &Path, params: &Params, step: u64) -> Result<Self, RunError> {
        let mut ra = RunAnalysis::new(params);
        if let Some(mut run) = RunFrames::open_if_any(dir)? {
            run.frames.retain(|(s, _)| *s <= step);
            measure_frames(&mut ra, &run, None)?;
        }
        Ok(LiveRun { ra, dir: dir.to_path_buf(), params: params.clone() })
    }

    /// Measures the state whose frame was just written and rewrites `DIR/analysis` (the snapshot
    /// follows the last frame until a hole nucleates; the one it replaces goes with the old set).
    pub fn frame(&mut self, m: &Monolayer) -> Result<(), RunError> {
        self.ra.push_monolayer(m);
        let snapshot = snapshot_frame(&self.ra, &self.dir, &self.params)?;
        let out = self.dir.join("analysis");
        self.ra.write(&out, snapshot.as_ref(), Background::StrainRate, &self.params)?;
        Ok(())
    }
}

/// File name (without extension) of the snapshot of a step.
fn snapshot_name(step: u64) -> String {
    format!("snapshot_{step:07}")
}

/// A time as CSV: step × Δt rounded to 1e-9, so 31 prints as 31, not 31.000000000000004.
fn time(t: f64) -> f64 {
    (t * 1e9).round() / 1e9
}

/// `hole_precursors.csv` or its chance baseline: a row per hole and frame before it.
fn precursor_table(rows: &[crate::analysis::Precursor]) -> String {
    let mut t = String::from(
        "hole,frames_before,spiral_core_distance_over_r,plus_half_distance_over_r,\
         second_plus_half_distance_over_r,max_strain_rate_within_r_half_over_max,\
         plus_half_pair_angle,minus_half_distance_over_r\n",
    );
    for p in rows {
        let _ = writeln!(
            t,
            "{},{},{},{},{},{:.6},{},{}",
            p.hole,
            p.frames_before,
            csv::cell(p.spiral_core, 6),
            csv::cell(p.plus_half[0], 6),
            csv::cell(p.plus_half[1], 6),
            p.strain_rate,
            csv::cell(p.plus_half_angle, 6),
            csv::cell(p.minus_half, 6)
        );
    }
    t
}

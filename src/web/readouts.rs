//! The page's readouts over time, for its Download button: a row every [`ROW_EVERY`] active
//! steps since the tissue was made (a Reset makes a new one), measured by the analysis module
//! as offline ([`Analysis::summary`]), and the CSV with a header naming the code version, the
//! seed and the parameters. With it the page writes the current state as a frame file
//! ([`crate::formats::encode_frame`]) and a `run.json` that `monolayer analyze` accepts.

use crate::analysis::{Analysis, Detail, HoleTracker};
use crate::formats::RunRecord;
use crate::model::{Monolayer, SimError};

use super::history::Nucleation;
use super::version::code_version;

/// Active steps between two rows (10 steps = one time unit at the default Δt = 0.1).
pub const ROW_EVERY: u64 = 10;

/// The CSV's columns, in order.
pub const COLUMNS: &str = "step,time,time_s,holes,void_area,packing,mean_speed,plus_half_defects,\
minus_half_defects,spiral_cores,zeta,chi,gamma,n_cells";

/// One row: the readouts of one state.
#[derive(Clone, Debug, PartialEq)]
pub struct Row {
    /// Steps since the random disks, relaxation included.
    pub step: u64,
    /// Time since activity started, in time units ((step − relax_steps)·Δt).
    pub time: f64,
    /// The same in seconds (× time_unit_seconds).
    pub time_s: f64,
    /// Void regions above πR²/4.
    pub holes: usize,
    /// Void sites (Σφ < 0.01), in lattice units (µm² at Δx ≈ 1 µm).
    pub void_area: usize,
    /// Fraction of sites with Σφ ≥ ½.
    pub packing: f64,
    /// Σ|Σφv| / ΣΣφ, sites per time unit (velocities of the last step's evaluation).
    pub mean_speed: f64,
    pub plus_half: usize,
    pub minus_half: usize,
    pub spiral_cores: usize,
    /// The sliders' parameters at this row (they may change during a run).
    pub zeta: f64,
    pub chi: f64,
    pub gamma: f64,
    pub n_cells: usize,
}

/// The rows since the tissue was made, and the analysis that measures them.
#[derive(Default)]
pub struct ReadoutLog {
    pub rows: Vec<Row>,
    analysis: Option<Analysis>,
    /// The holes followed from row to row, as `analyze` follows them from frame to frame.
    pub tracker: Option<HoleTracker>,
    /// The step of the last row the tracker took (a resumed log's tracker has taken its first).
    tracked: Option<u64>,
    /// Every hole that nucleated, at its first row (fragments of an open one are not new).
    pub nucleations: Vec<Nucleation>,
}

impl ReadoutLog {
    /// Whether the state of `m` is due a row: active, a multiple of [`ROW_EVERY`] steps since
    /// activity started, and not recorded yet.
    fn due(&self, m: &Monolayer) -> bool {
        let (step, relax) = (m.step_count(), m.params().relax_steps);
        step >= relax && (step - relax) % ROW_EVERY == 0 && self.rows.last().is_none_or(|r| r.step != step)
    }

    /// Measures the state of `m` as a row (whether due or not).
    pub fn measure(&mut self, m: &Monolayer) -> Row {
        let p = m.params();
        if self.analysis.as_ref().is_none_or(|a| a.l != p.box_size) {
            self.analysis = Some(Analysis::new(p));
        }
        let a = self.analysis.as_mut().expect("made above");
        a.measure_in(m, Detail::Tissue);
        let s = a.summary();
        let time = m.step_count().saturating_sub(p.relax_steps) as f64 * p.dt;
        Row {
            step: m.step_count(),
            time,
            time_s: time * p.time_unit_seconds,
            holes: s.holes,
            void_area: a.voids.regions.iter().map(|r| r.area).sum(),
            packing: s.packing_fraction,
            mean_speed: s.mean_speed,
            plus_half: s.plus_half_defects,
            minus_half: s.minus_half_defects,
            spiral_cores: s.spiral_cores,
            zeta: p.zeta,
            chi: p.chi(),
            gamma: p.gamma,
            n_cells: m.cells().len(),
        }
    }

    /// A log that goes on from a saved state whose row `tracker` has taken already (a replay
    /// of the page's "What if?"): its rows start again, its holes carry on.
    pub fn resumed(tracker: Option<HoleTracker>, step: u64) -> Self {
        ReadoutLog { tracked: tracker.is_some().then_some(step), tracker, ..Self::default() }
    }

    /// Records a row if the state of `m` is due one, and the holes that nucleated at it.
    pub fn record_if_due(&mut self, m: &Monolayer) {
        if !self.due(m) {
            return;
        }
        let row = self.measure(m);
        let (step, time) = (row.step, row.time);
        self.rows.push(row);
        if self.tracked == Some(step) {
            return;
        }
        self.tracked = Some(step);
        let voids = &self.analysis.as_ref().expect("measured above").voids;
        let tracker = self.tracker.get_or_insert_with(|| HoleTracker::new(m.params().radius));
        tracker.update(voids, time);
        for h in tracker.nucleated_holes() {
            let (_, _, x, y) = tracker.holes[h].history[0];
            self.nucleations.push(Nucleation { step, x, y });
        }
    }

    /// Steps from `step` to the next state due a row: the end of the relaxation, then every
    /// [`ROW_EVERY`] active steps (the GPU engine stops its submissions there).
    pub fn steps_to_next_row(step: u64, relax: u64) -> u64 {
        if step < relax {
            relax - step
        } else {
            ROW_EVERY - (step - relax) % ROW_EVERY
        }
    }

    /// Runs `n` steps of `m`, stopping at each state due a row to record it. On an error the
    /// state before the failing step is kept, with the rows up to it.
    pub fn advance(&mut self, m: &mut Monolayer, n: u64) -> Result<(), SimError> {
        let mut left = n;
        while left > 0 {
            let k = left.min(Self::steps_to_next_row(m.step_count(), m.params().relax_steps));
            m.advance(k)?;
            left -= k;
            self.record_if_due(m);
        }
        Ok(())
    }

    /// The CSV: a header of `#` lines (code version, seed, every parameter, what the columns
    /// mean), the columns, then a row per recorded state and, when the current state of `m` is
    /// not the last row, a last row for it: the last row is what the page shows.
    pub fn csv(&mut self, m: &Monolayer) -> String {
        let p = m.params();
        let mut out = String::new();
        out.push_str(&format!("# monolayer browser page readouts; code version {}\n", code_version()));
        out.push_str(&format!("# seed {}\n", m.seed()));
        let params = serde_json::to_string(p).expect("parameters serialise");
        out.push_str(&format!("# parameters at download (zeta, chi, gamma, n_cells per row): {params}\n"));
        out.push_str(&format!(
            "# a row every {ROW_EVERY} active steps since the tissue was made, and the state at download; time in \
             time units since activity started ((step - {}) * dt, dt = {}) and in seconds \
             (time_unit_seconds = {}); void_area in sites (um^2 at dx = 1 um); holes are void regions \
             (sum phi < 0.01) larger than pi R^2 / 4; packing is the fraction of sites with sum phi >= 1/2; \
             mean_speed in sites per time unit\n",
            p.relax_steps, p.dt, p.time_unit_seconds
        ));
        out.push_str(COLUMNS);
        out.push('\n');
        let last = (self.rows.last().map(|r| r.step) != Some(m.step_count())).then(|| self.measure(m));
        for r in self.rows.iter().chain(&last) {
            out.push_str(&format!(
                "{},{},{},{},{},{},{},{},{},{},{},{},{},{}\n",
                r.step,
                r.time,
                r.time_s,
                r.holes,
                r.void_area,
                r.packing,
                r.mean_speed,
                r.plus_half,
                r.minus_half,
                r.spiral_cores,
                r.zeta,
                r.chi,
                r.gamma,
                r.n_cells
            ));
        }
        out
    }
}

/// A `run.json` for the current state of `m` as a run of one frame, in the format of the native
/// runs (the one [`RunRecord`], [`RunRecord::of_page`], written with its keys in alphabetical
/// order as the page always wrote it): with the frame file in `DIR/frames/`
/// (`formats::frame_file_name`), `monolayer analyze DIR` reads it.
pub fn run_record_json(m: &Monolayer) -> String {
    RunRecord::of_page(m.params().clone(), m.seed(), m.step_count()).to_json_sorted()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::{nucleation_area, VoidRegions};
    use crate::model::Params;
    use crate::web::measure::tissue_stats;

    #[test]
    fn rows_fall_every_row_every_active_steps_and_match_the_live_readouts() {
        let p = Params { box_size: 40, n_cells: 4, relax_steps: 7, ..Params::default() };
        let mut m = Monolayer::new(p, 2).unwrap();
        let mut log = ReadoutLog::default();
        log.advance(&mut m, 3).unwrap();
        assert!(log.rows.is_empty(), "no row while relaxing");
        log.advance(&mut m, 4 + 2 * ROW_EVERY + 3).unwrap();
        let steps: Vec<u64> = log.rows.iter().map(|r| r.step).collect();
        assert_eq!(steps, [7, 7 + ROW_EVERY, 7 + 2 * ROW_EVERY]);
        // The same stepping, bit for bit, as without the rows.
        let mut plain = Monolayer::new(m.params().clone(), 2).unwrap();
        plain.advance(m.step_count()).unwrap();
        assert_eq!(plain.fingerprint(), m.fingerprint());
        let csv = log.csv(&m);
        let lines: Vec<&str> = csv.lines().filter(|l| !l.starts_with('#')).collect();
        assert_eq!(lines[0], COLUMNS);
        assert_eq!(lines.len(), 1 + 3 + 1, "three rows and the current state");
        let last: Vec<&str> = lines[4].split(',').collect();
        assert_eq!(last.len(), COLUMNS.split(',').count());
        assert_eq!(last[0], m.step_count().to_string());
        let radius = m.params().radius;
        let s = tissue_stats(m.phi_sum(), 40, radius, &mut Default::default());
        assert_eq!(last[3].parse::<u32>().unwrap(), s.holes);
        assert_eq!(last[4].parse::<u32>().unwrap(), s.void_area);
        assert_eq!(last[5].parse::<f64>().unwrap(), s.packing);
        assert!(csv.contains(&format!("code version {}", code_version())));
        assert!(csv.contains("# seed 2\n"));
        assert!(csv.contains("\"box_size\":40"));
    }

    /// The readouts' tracker: each hole once, at its first row, at its region's centroid.
    #[test]
    fn the_readouts_record_each_hole_once_at_its_first_row_where_it_is() {
        // Half-relaxed disks: void between them, holes by the nucleation criterion.
        let p = Params { box_size: 40, n_cells: 5, relax_steps: 20, ..Params::default() };
        let mut m = Monolayer::new(p, 4).unwrap();
        m.advance(20).unwrap();
        let mut log = ReadoutLog::default();
        log.record_if_due(&m);
        let mut regions = VoidRegions::default();
        regions.find(m.phi_sum(), 40);
        let area = nucleation_area(m.params().radius);
        let mut holes: Vec<(f64, f64)> =
            regions.regions.iter().filter(|r| r.area as f64 > area).map(|r| (r.x, r.y)).collect();
        assert!(!holes.is_empty(), "no hole between half-relaxed disks: the test proves little");
        let mut found: Vec<(f64, f64)> = log.nucleations.iter().map(|n| (n.x, n.y)).collect();
        holes.sort_by(|a, b| a.partial_cmp(b).unwrap());
        found.sort_by(|a, b| a.partial_cmp(b).unwrap());
        assert_eq!(found, holes);
        assert!(log.nucleations.iter().all(|n| n.step == 20));
        // The same row again, then the same state a row later: the holes go on, none is new.
        log.record_if_due(&m);
        let mut state = m.state();
        state.step += ROW_EVERY;
        log.record_if_due(&Monolayer::from_state(m.params().clone(), m.seed(), state).unwrap());
        assert_eq!(log.rows.len(), 2);
        assert_eq!(log.nucleations.len(), holes.len());
    }
}

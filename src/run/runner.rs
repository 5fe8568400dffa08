//! A run on disk: the protocol stepped to its end in an output directory, with a frame and a
//! checkpoint every frame interval, the run record kept current, optional live analysis, and a
//! failure that keeps the last good state. `monolayer run` and `monolayer sweep` both use it.

use std::fs;
use std::path::{Path, PathBuf};

use crate::model::monolayer::Monolayer;
use crate::model::params::Params;
use crate::run::files::{frame_path, read_checkpoint, write_checkpoint, write_frame, RunRecord};
use crate::run::offline::LiveRun;

/// What the protocol reports to whoever watches it (a progress bar, a sweep).
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum Event {
    /// A step was taken.
    Step,
    /// A frame (and checkpoint) was written.
    Frame,
    /// The live analysis of the frame just written failed; the simulation goes on (its frames
    /// can be analysed later with `monolayer analyze`).
    AnalysisFailed(String),
}

/// A run directory with its record and the simulation it holds.
pub struct RunDir {
    pub dir: PathBuf,
    pub record: RunRecord,
    pub monolayer: Monolayer,
}

impl RunDir {
    /// Starts a new run in `dir` (created), refusing a directory that holds a run already.
    pub fn create(dir: &Path, params: Params, seed: u64, frame_interval: u64) -> Result<Self, String> {
        if frame_interval == 0 {
            return Err("frame interval 0: must be ≥ 1".into());
        }
        params.validate().map_err(|e| e.to_string())?;
        if RunRecord::path(dir).exists() {
            return Err(format!(
                "{} already holds a run: continue it with --resume {0}, or choose another --out",
                dir.display()
            ));
        }
        let monolayer = Monolayer::new(params.clone(), seed).map_err(|e| e.to_string())?;
        fs::create_dir_all(dir.join("frames")).map_err(|e| format!("{}: {e}", dir.display()))?;
        let record = RunRecord::new(params, seed, frame_interval);
        record.save(dir)?;
        Ok(RunDir { dir: dir.to_path_buf(), record, monolayer })
    }

    /// Opens the run in `dir` at its last checkpoint.
    pub fn resume(dir: &Path) -> Result<Self, String> {
        let record = RunRecord::load(dir)?;
        let checkpoint = dir.join("checkpoint.npz");
        if !checkpoint.exists() {
            return Err(format!("{}: no checkpoint yet; start the run again", checkpoint.display()));
        }
        let state = read_checkpoint(&checkpoint, record.params.box_size)?;
        let monolayer = Monolayer::from_state(record.params.clone(), record.seed, state).map_err(|e| e.to_string())?;
        fs::create_dir_all(dir.join("frames")).map_err(|e| format!("{}: {e}", dir.display()))?;
        Ok(RunDir { dir: dir.to_path_buf(), record, monolayer })
    }

    /// Steps to the end of the protocol, writing a frame and a checkpoint every frame interval
    /// of the active phase (and a checkpoint when relaxation ends), then records how it ended.
    /// With `analyze`, `DIR/analysis` is brought up to date at every frame.
    pub fn execute(&mut self, analyze: bool, watch: &mut dyn FnMut(&Monolayer, &Event)) -> Result<(), String> {
        let mut live = if analyze { Some(LiveRun::start(&self.dir, self.monolayer.params())?) } else { None };
        let outcome = self.protocol(live.as_mut(), watch);
        self.record.status = match &outcome {
            Ok(()) => "finished".into(),
            Err(e) => format!("failed: {e}"),
        };
        self.record.save(&self.dir)?;
        outcome
    }

    fn protocol(
        &mut self,
        mut live: Option<&mut LiveRun>,
        watch: &mut dyn FnMut(&Monolayer, &Event),
    ) -> Result<(), String> {
        let p = self.monolayer.params().clone();
        let total = p.total_steps();
        let checkpoint = self.dir.join("checkpoint.npz");
        let (m, dir, record) = (&mut self.monolayer, &self.dir, &mut self.record);
        while m.step_count() < total {
            if let Err(e) = m.step() {
                let last_good = dir.join("last_good_state.npz");
                write_checkpoint(m, &last_good)?;
                return Err(format!(
                    "{e}\n  the last good state is in {} (the last periodic one in checkpoint.npz)",
                    last_good.display()
                ));
            }
            watch(m, &Event::Step);
            let s = m.step_count();
            let frame = s >= p.relax_steps && (s - p.relax_steps) % record.frame_interval == 0;
            if frame {
                m.evaluate_now().map_err(|e| e.to_string())?;
                write_frame(m, &frame_path(dir, s))?;
                record.last_frame_step = Some(s);
                if let Some(Err(e)) = live.as_deref_mut().map(|live| live.frame(m)) {
                    watch(m, &Event::AnalysisFailed(e));
                }
            }
            if frame || s == p.relax_steps {
                write_checkpoint(m, &checkpoint)?;
                record.save(dir)?;
                if frame {
                    watch(m, &Event::Frame);
                }
            }
        }
        Ok(())
    }
}

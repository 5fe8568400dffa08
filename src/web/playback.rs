//! A run's frames in the page: the files the user dropped or picked (`run.json` and
//! `frame_*.npz`, read in the page, nothing uploaded), each frame checked on its own so that a bad
//! one is reported and skipped, and the frame shown drawn by the same [`ViewBuilder`] and measured
//! by the same analysis as the live tissue. Plain Rust, tested natively; `sim::WebPlayback` is
//! its binding.

use crate::analysis::VoidRegions;
use crate::model::State;
use crate::model::{Monolayer, Params};

use super::measure::{tissue_stats, TissueStats};
use super::view::{FieldKind, View, ViewBuilder};
use crate::formats::{decode_frame, FrameData, FORMAT, FORMAT_VERSION};

/// What the page needs of a run's `run.json` (`formats::run_record::RunRecord`).
#[derive(Clone, Debug, PartialEq)]
pub struct RunInfo {
    pub params: Params,
    pub seed: u64,
    /// The code version that wrote the run.
    pub version: String,
}

/// Reads a `run.json`'s text (`name` for the messages), as `monolayer analyze` checks it.
pub fn parse_run_json(name: &str, text: &str) -> Result<RunInfo, String> {
    let e = |why: String| format!("{name}: {why}");
    let v: serde_json::Value = serde_json::from_str(text).map_err(|x| e(format!("not valid JSON: {x}")))?;
    if v.get("format").and_then(|f| f.as_str()) != Some(FORMAT) {
        return Err(e(format!("not a record of this program (no \"format\": \"{FORMAT}\")")));
    }
    let fv = v.get("format_version").and_then(|f| f.as_u64());
    if fv != Some(FORMAT_VERSION as u64) {
        return Err(e(format!("format_version {fv:?}, this page reads {FORMAT_VERSION}")));
    }
    let params: Params = serde_json::from_value(v.get("params").cloned().unwrap_or_default())
        .map_err(|x| e(format!("`params`: {x}")))?;
    params.validate().map_err(|x| e(x.to_string()))?;
    let seed = v.get("seed").and_then(|s| s.as_u64()).ok_or_else(|| e("no `seed`".into()))?;
    let version = v.get("version").and_then(|s| s.as_str()).unwrap_or("unknown").to_string();
    Ok(RunInfo { params, seed, version })
}

/// The frames of one run, one shown at a time.
pub struct Playback {
    /// The run's record, or `None` when only frames were given (the native defaults are then
    /// assumed for everything the frames do not hold: R, ζ, Δt, …).
    pub info: Option<RunInfo>,
    /// The state of the frame shown, as a simulation (for the cells' outlines and axes).
    m: Option<Monolayer>,
    frame: Option<FrameData>,
    keys: Vec<u32>,
    view: ViewBuilder,
    regions: VoidRegions,
    pub stats: TissueStats,
}

impl Playback {
    /// A playback of the run whose `run.json` is `run_json` (name, text), if given.
    pub fn new(run_json: Option<(&str, &str)>) -> Result<Self, String> {
        let info = run_json.map(|(name, text)| parse_run_json(name, text)).transpose()?;
        Ok(Playback {
            info,
            m: None,
            frame: None,
            keys: Vec::new(),
            view: ViewBuilder::default(),
            regions: VoidRegions::default(),
            stats: TissueStats::default(),
        })
    }

    fn expect(&self) -> Option<(usize, usize)> {
        self.info.as_ref().map(|i| (i.params.box_size, i.params.n_cells))
    }

    /// The parameters a frame is shown with: the run's, or the defaults at the frame's size.
    fn params_for(&self, f: &FrameData) -> Params {
        match &self.info {
            Some(i) => i.params.clone(),
            None => Params { box_size: f.l, n_cells: f.cells.len(), ..Params::default() },
        }
    }

    /// Reads a frame file and checks it against the run: its step, or what is wrong with it.
    pub fn check(&self, name: &str, bytes: &[u8]) -> Result<u64, String> {
        let f = decode_frame(name, bytes, self.expect()).map_err(|e| e.to_string())?;
        self.params_for(&f).validate().map_err(|e| format!("{name}: {e}"))?;
        Ok(f.step)
    }

    /// Shows a frame: its cells become the state drawn, its arrays what the analysis reads.
    pub fn show(&mut self, name: &str, bytes: &[u8]) -> Result<(), String> {
        let f = decode_frame(name, bytes, self.expect()).map_err(|e| e.to_string())?;
        let params = self.params_for(&f);
        let l = f.l;
        let seed = self.info.as_ref().map_or(0, |i| i.seed);
        let state = State {
            step: f.step,
            cells: f.cells.clone(),
            warm_start: vec![Default::default(); l * l],
            corrector_shift: vec![Default::default(); l * l],
            substrate: vec![1.0; l * l],
        };
        let mut m = Monolayer::from_state(params, seed, state).map_err(|e| format!("{name}: {e}"))?;
        // Fills each cell's shape tensor and Q̂ from its φ (the outlines' axes); the velocities
        // drawn and analysed are the frame's own.
        m.evaluate_now().map_err(|e| format!("{name}: {e}"))?;
        let r = m.params().radius;
        self.stats = tissue_stats(m.phi_sum(), l, r, &mut self.regions);
        self.keys = (1..=f.cells.len() as u32).collect();
        self.m = Some(m);
        self.frame = Some(f);
        Ok(())
    }

    /// The frame shown, as a simulation (None before the first [`Playback::show`]).
    pub fn monolayer(&self) -> Option<&Monolayer> {
        self.m.as_ref()
    }

    pub fn frame(&self) -> Option<&FrameData> {
        self.frame.as_ref()
    }

    /// What the renderer draws of the frame shown for `field`.
    pub fn view(&mut self, field: FieldKind, dpr: f32) -> Option<&View> {
        let m = self.m.as_mut()?;
        Some(self.view.build_from(m, &self.keys, field, dpr, self.frame.as_ref()))
    }

    /// ±½ defects and spiral cores as last drawn.
    pub fn builder(&self) -> &ViewBuilder {
        &self.view
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::analysis::Analysis;
    use crate::formats::encode_frame;

    fn run_json(p: &Params, seed: u64) -> String {
        serde_json::json!({"format": "monolayer-run", "format_version": 1, "version": "x", "seed": seed,
            "frame_interval": 10, "status": "finished", "last_frame_step": 0, "params": p})
        .to_string()
    }

    #[test]
    fn a_frame_shows_with_the_analysis_of_its_own_arrays() {
        let p = Params { box_size: 40, n_cells: 5, relax_steps: 40, ..Params::default() };
        let mut m = Monolayer::new(p.clone(), 3).unwrap();
        m.advance(20).unwrap(); // half-relaxed disks: holes between them
        let bytes = encode_frame(&mut m).unwrap();
        let mut play = Playback::new(Some(("run.json", &run_json(&p, 3)))).unwrap();
        assert_eq!(play.check("frame_0000020.npz", &bytes), Ok(20));
        play.show("frame_0000020.npz", &bytes).unwrap();
        // The offline analysis of the same frame.
        let f = decode_frame("f", &bytes, None).unwrap();
        let mut a = Analysis::new(&p);
        a.measure_cells(f.cell_views(), &f.velocity);
        let s = a.summary();
        assert!(s.holes > 0, "no holes: the test proves little");
        assert_eq!(play.stats.holes as usize, s.holes);
        assert_eq!(play.stats.packing, s.packing_fraction);
        let view = play.view(FieldKind::Director, 1.0).unwrap().clone();
        assert_eq!(view.l, 40);
        assert_eq!(play.builder().defects, a.defects);
        play.view(FieldKind::StrainRate, 1.0).unwrap();
        let cores: Vec<_> = a.spiral_cores().copied().collect();
        assert_eq!(play.builder().spiral_cores, cores);
        // The cells drawn are the frame's (two largest φ per site).
        assert_eq!(play.monolayer().unwrap().step_count(), 20);
    }

    #[test]
    fn foreign_frames_and_records_are_refused_by_name() {
        let p = Params { box_size: 40, n_cells: 5, relax_steps: 40, ..Params::default() };
        let mut m = Monolayer::new(p.clone(), 3).unwrap();
        let bytes = encode_frame(&mut m).unwrap();
        let other = Params { n_cells: 6, ..p.clone() };
        let play = Playback::new(Some(("run.json", &run_json(&other, 3)))).unwrap();
        let e = play.check("frame_0000000.npz", &bytes).unwrap_err();
        assert!(e.starts_with("frame_0000000.npz: ") && e.contains("n_cells = 6"), "{e}");
        let e = Playback::new(Some(("run.json", "{\"format\": \"other\"}"))).err().unwrap();
        assert!(e.starts_with("run.json: not a record"), "{e}");
        // Without run.json: the frame's own size, the defaults for the rest.
        let mut play = Playback::new(None).unwrap();
        play.show("frame_0000000.npz", &bytes).unwrap();
        assert_eq!(play.monolayer().unwrap().params().n_cells, 5);
    }
}
